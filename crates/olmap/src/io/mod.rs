//! Reading and writing point clouds and poses in the formats robots and tools produce.
//!
//! | format | extensions | read | write | notes |
//! |---|---|---|---|---|
//! | PCD v0.7 (PCL) | `.pcd` | ascii, binary, binary_compressed | all three | [`pcd`] |
//! | PLY | `.ply` | ascii, binary LE/BE | binary LE, ascii | [`ply`] |
//! | XYZ text | `.xyz .txt .dat .asc .pts` | yes | yes | [`xyz`] |
//! | 3DTK "uos" | `.3d` | yes (to RH metres) | yes | [`uos`] |
//! | CSV point table | `.csv` | yes | yes | [`csv`] |
//! | KITTI velodyne | `.bin` | yes | yes | [`kitti`] |
//! | OctoMap ScanGraph | `.graph` | yes | yes | [`scan_graph`] |
//! | LAS/LAZ (feature `las`) | `.las .laz` | LAS 1.0-1.4, LAZ, COPC (to a local origin) | LAS 1.2, LAZ | [`las`] |
//!
//! Any of them may be bzip2-compressed (`scan.dat.bz2`): the reader decompresses on the fly
//! and picks the format from the inner extension. Where the extension is unknown, the
//! content decides for the formats with a signature (PLY, PCD, LAS). Poses: [`slam6d`] (3DTK
//! `.pose` and `.frames`), [`csv::read_pose_table`] (libpointmatcher `carCloudList.csv`) and
//! [`crate::geometry::PoseList`] (olmap's pose list).
//!
//! Every reader drops points with a non-finite coordinate and counts them in
//! [`ReadReport::dropped_non_finite`]. Writers write to a temporary file beside the target
//! and rename it into place, so a failed write never leaves a half-written file.

#[cfg(feature = "bag")]
pub mod bag;
pub mod carmen;
pub mod csv;
mod discover;
pub mod kitti;
#[cfg(feature = "las")]
pub mod las;
pub mod octomap_bt;
pub mod pcd;
pub mod ply;
mod poses;
mod report;
pub mod scan_graph;
pub mod slam6d;
pub mod uos;
pub mod xyz;

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

pub use discover::{is_cloud_file, scan_files};
pub use poses::{file_stem_name, read_poses, read_poses_with};
pub use report::{convert_cloud_file, CloudInfo, ConvertJob, ConvertReport, OrganizedSize};

use crate::cloud::PointCloud;
use crate::error::{Error, ParseError, Result};
use crate::file::{open_buffered, write_atomic};

/// The point-cloud file formats olmap knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CloudFormat {
    /// PCL's Point Cloud Data format, version 0.7.
    Pcd,
    /// The Polygon File Format (Stanford).
    Ply,
    /// Plain text, one point per line: `x y z [ignored columns]`.
    Xyz,
    /// 3DTK's "uos" `.3d` text format (left-handed centimetres, converted on read).
    Uos,
    /// A CSV point table with or without a header (libpointmatcher style).
    Csv,
    /// KITTI velodyne scans: little-endian float32 records `x y z intensity`.
    KittiBin,
    /// OctoMap's binary ScanGraph (`.graph`): scans with their poses.
    ScanGraph,
    /// ASPRS LAS and LASzip-compressed LAZ (`.las`, `.laz`), aerial and mobile lidar in a
    /// map frame; read relative to a local origin ([`ReadReport::local_origin`]). Needs the
    /// `las` feature.
    Las,
}

impl CloudFormat {
    /// Every format, in the order of the module table.
    pub const ALL: [CloudFormat; 8] = [
        CloudFormat::Pcd,
        CloudFormat::Ply,
        CloudFormat::Xyz,
        CloudFormat::Uos,
        CloudFormat::Csv,
        CloudFormat::KittiBin,
        CloudFormat::ScanGraph,
        CloudFormat::Las,
    ];

    /// A short human name.
    pub fn name(self) -> &'static str {
        match self {
            CloudFormat::Pcd => "PCD",
            CloudFormat::Ply => "PLY",
            CloudFormat::Xyz => "XYZ text",
            CloudFormat::Uos => "3DTK .3d",
            CloudFormat::Csv => "CSV point table",
            CloudFormat::KittiBin => "KITTI .bin",
            CloudFormat::ScanGraph => "OctoMap ScanGraph",
            CloudFormat::Las => "LAS/LAZ",
        }
    }

    /// The file extensions (lower case, no dot) that select this format.
    pub fn extensions(self) -> &'static [&'static str] {
        match self {
            CloudFormat::Pcd => &["pcd"],
            CloudFormat::Ply => &["ply"],
            CloudFormat::Xyz => &["xyz", "txt", "dat", "asc", "pts"],
            CloudFormat::Uos => &["3d"],
            CloudFormat::Csv => &["csv"],
            CloudFormat::KittiBin => &["bin"],
            CloudFormat::ScanGraph => &["graph"],
            CloudFormat::Las => &["las", "laz"],
        }
    }

    /// The format selected by an extension (case-insensitive, no dot).
    pub fn from_extension(ext: &str) -> Option<Self> {
        let ext = ext.to_ascii_lowercase();
        Self::ALL
            .into_iter()
            .find(|f| f.extensions().contains(&ext.as_str()))
    }

    /// Parses a user-facing format name (`pcd`, `ply`, `xyz`, `3d`, `csv`, `kitti`, `graph`,
    /// `las`, `laz`).
    pub fn from_name(name: &str) -> Option<Self> {
        match name.to_ascii_lowercase().as_str() {
            "kitti" => Some(CloudFormat::KittiBin),
            "uos" | "3dtk" => Some(CloudFormat::Uos),
            "scangraph" => Some(CloudFormat::ScanGraph),
            other => Self::from_extension(other),
        }
    }

    fn list_extensions() -> String {
        Self::ALL
            .iter()
            .flat_map(|f| f.extensions().iter().map(|e| format!(".{e}")))
            .collect::<Vec<_>>()
            .join(" ")
    }
}

impl std::fmt::Display for CloudFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Options for reading clouds.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Read as this format whatever the file name says.
    pub format: Option<CloudFormat>,
    /// 3DTK `.3d` only: keep only returns with 20 cm <= range < 3270 cm (drops the near-sensor
    /// echoes and the max-range sentinel; see the data README §1.3). Off by default: the file
    /// is read as it is.
    pub uos_valid_only: bool,
    /// Compressed (`.bz2`) files only: the most bytes the file may decompress to. `None`
    /// (the default) applies [`max_decompressed_bytes`]: [`DECOMPRESSION_RATIO`] times the
    /// compressed size, at least [`DECOMPRESSED_FLOOR_BYTES`]. A file that decompresses to
    /// more is refused with [`Error::TooLarge`] as soon as the limit is passed, so a small
    /// "decompression bomb" costs neither the memory nor the time it asks for.
    pub max_decompressed_bytes: Option<u64>,
}

/// The least a compressed file may always decompress to, whatever its size: 32 MiB (about
/// a second of parsing; the largest scans in the shared data are 2-3 MB of text).
pub const DECOMPRESSED_FLOOR_BYTES: u64 = 32 << 20;

/// How many times its own size a compressed file may decompress to: 64. Real point clouds
/// compress 2-10 times with bzip2 (the OctoMap `scan.dat.bz2`: 2.9 times); a file of
/// zeros compresses more than a million times.
pub const DECOMPRESSION_RATIO: u64 = 64;

/// The default limit on what a compressed file of `compressed` bytes may decompress to:
/// `max(DECOMPRESSION_RATIO × compressed, DECOMPRESSED_FLOOR_BYTES)`.
///
/// ```
/// use olmap::io::{max_decompressed_bytes, DECOMPRESSED_FLOOR_BYTES};
/// assert_eq!(max_decompressed_bytes(1426), DECOMPRESSED_FLOOR_BYTES);
/// assert_eq!(max_decompressed_bytes(819_611), 64 * 819_611);
/// ```
pub fn max_decompressed_bytes(compressed: u64) -> u64 {
    compressed
        .saturating_mul(DECOMPRESSION_RATIO)
        .max(DECOMPRESSED_FLOOR_BYTES)
}

/// What a reader found in a file besides the points.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadReport {
    /// The format read.
    pub format: CloudFormat,
    /// The encoding within the format (`ascii`, `binary`, `binary_compressed`,
    /// `binary_little_endian`, ...), empty where the format has one encoding.
    pub encoding: String,
    /// Point records in the file (before any point was dropped).
    pub records: u64,
    /// Points dropped because a coordinate was NaN or infinite.
    pub dropped_non_finite: u64,
    /// Points dropped by a validity filter asked for in [`ReadOptions`].
    pub dropped_invalid: u64,
    /// The per-point fields the file declares (`x`, `y`, `z`, `intensity`, ...).
    pub fields: Vec<String>,
    /// `(width, height)` of an organised cloud (PCD with `HEIGHT` > 1).
    pub organized: Option<(u32, u32)>,
    /// Unparseable lines skipped at the top of a text file (3DTK tolerates up to 10).
    pub header_lines_skipped: usize,
    /// The compression the file was wrapped in (`bzip2`), if any.
    pub compression: Option<&'static str>,
    /// LAS/LAZ: the point in the file's frame that the cloud's `(0, 0, 0)` stands for, so
    /// that file coordinates = cloud points + `local_origin` (subtracted in double precision
    /// before the points became `f32`; the module `io::las` says how it is chosen). `None`
    /// for the formats read as they are.
    pub local_origin: Option<[f64; 3]>,
}

impl ReadReport {
    /// An empty report for a format.
    pub fn new(format: CloudFormat) -> Self {
        ReadReport {
            format,
            encoding: String::new(),
            records: 0,
            dropped_non_finite: 0,
            dropped_invalid: 0,
            fields: Vec::new(),
            organized: None,
            header_lines_skipped: 0,
            compression: None,
            local_origin: None,
        }
    }
}

/// A cloud read from a file, with the reader's report.
#[derive(Debug, Clone)]
pub struct LoadedCloud {
    /// The points.
    pub cloud: PointCloud,
    /// What the reader found.
    pub report: ReadReport,
}

/// Encodings of the PCD writer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PcdEncoding {
    /// Human-readable text.
    Ascii,
    /// Packed little-endian records (PCL's default for `savePCDFileBinary`).
    #[default]
    Binary,
    /// LZF-compressed structure-of-arrays.
    BinaryCompressed,
}

/// Encodings of the PLY writer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PlyEncoding {
    /// `binary_little_endian 1.0`.
    #[default]
    BinaryLittleEndian,
    /// `ascii 1.0`.
    Ascii,
}

/// Options for writing clouds.
#[derive(Debug, Clone, Default)]
pub struct WriteOptions {
    /// Write this format whatever the file name says.
    pub format: Option<CloudFormat>,
    /// Encoding of PCD files.
    pub pcd_encoding: PcdEncoding,
    /// Encoding of PLY files.
    pub ply_encoding: PlyEncoding,
    /// LAS/LAZ only: the local origin added back to the points, so that file coordinates =
    /// points + this (it is also the header's offset); `None` is `(0, 0, 0)`.
    /// [`convert_cloud_file`] sets it to the input's [`ReadReport::local_origin`] when unset.
    pub las_local_origin: Option<[f64; 3]>,
    /// LAS/LAZ only: compress with LASzip (LAZ). `None`: [`write_cloud`] compresses `.laz`
    /// files, [`write_cloud_to`] writes uncompressed LAS.
    pub laz: Option<bool>,
}

/// Reads a point cloud, choosing the format from the file name (and content where needed).
///
/// ```no_run
/// let loaded = olmap::io::read_cloud("scan000.3d")?;
/// println!("{} points, {} dropped", loaded.cloud.len(), loaded.report.dropped_non_finite);
/// # Ok::<(), olmap::Error>(())
/// ```
pub fn read_cloud(path: impl AsRef<Path>) -> Result<LoadedCloud> {
    read_cloud_with(path, &ReadOptions::default())
}

/// Reads a point cloud with options.
///
/// With the `bag` feature, a path of the form `BAG#TOPIC@INDEX` that is not an existing
/// file names one scan message of a ROS 2 bag ([`bag::ScanSpec`]): the cloud in the
/// message's frame.
pub fn read_cloud_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedCloud> {
    let path = path.as_ref();
    #[cfg(feature = "bag")]
    if let Some(spec) = path
        .to_str()
        .filter(|_| !path.exists())
        .and_then(bag::ScanSpec::parse)
    {
        return spec.read().map(|s| s.loaded());
    }
    let mut reader = open_buffered(path)?;
    let compression = if has_extension(path, "bz2") || starts_with(&mut reader, path, b"BZh")? {
        Some("bzip2")
    } else {
        None
    };
    let inner_name: PathBuf = if compression.is_some() && has_extension(path, "bz2") {
        path.with_extension("")
    } else {
        path.to_path_buf()
    };
    let mut loaded = match compression {
        None => {
            let format = match options.format {
                Some(f) => f,
                None => detect_format(&inner_name, &mut reader, path)?,
            };
            match format {
                // LAZ needs to seek: read the file in place rather than through memory.
                #[cfg(feature = "las")]
                CloudFormat::Las => las::read_seekable(reader),
                _ => read_cloud_from(reader, format, options),
            }
            .map_err(|e| Error::read(path, format.name(), e))?
        }
        Some(_) => {
            let compressed = reader.get_ref().metadata().map_or(0, |m| m.len());
            let limit = options
                .max_decompressed_bytes
                .unwrap_or_else(|| max_decompressed_bytes(compressed));
            let mut inner = decompress(reader, path, limit)?;
            let format = match options.format {
                Some(f) => f,
                None => detect_format(&inner_name, &mut inner, path)?,
            };
            read_cloud_from(inner, format, options)
                .map_err(|e| Error::read(path, format.name(), decompression_limit(e, compressed)))?
        }
    };
    loaded.report.compression = compression;
    Ok(loaded)
}

/// The decompressed stream of a bzip2 file, refusing to produce more than `limit` bytes.
#[cfg(feature = "bzip2")]
fn decompress<R: BufRead>(reader: R, _path: &Path, limit: u64) -> Result<impl BufRead> {
    Ok(bzip2_capped(reader, limit))
}

/// A bzip2 decoder over `reader` producing at most `limit` bytes, buffered.
#[cfg(feature = "bzip2")]
fn bzip2_capped<R: BufRead>(reader: R, limit: u64) -> impl BufRead {
    BufReader::with_capacity(
        1 << 18,
        CappedReader {
            inner: bzip2::bufread::MultiBzDecoder::new(reader),
            produced: 0,
            limit,
        },
    )
}

#[cfg(not(feature = "bzip2"))]
fn decompress<R: BufRead>(
    _reader: R,
    path: &Path,
    _limit: u64,
) -> Result<BufReader<CappedReader<std::io::Empty>>> {
    Err(Error::UnknownFormat {
        path: path.to_path_buf(),
        reason: "bzip2-compressed, but olmap was built without the `bzip2` feature".into(),
    })
}

/// Reads a compressed cloud of a known format from a stream, with the same limit on the
/// decompressed bytes as [`read_cloud_with`] (the stream's compressed size is taken to be
/// `compressed`; see [`max_decompressed_bytes`]). Errors carry no path.
#[cfg(feature = "bzip2")]
pub fn read_bzip2_cloud_from<R: BufRead>(
    reader: R,
    compressed: u64,
    format: CloudFormat,
    options: &ReadOptions,
) -> Result<LoadedCloud, ParseError> {
    let limit = options
        .max_decompressed_bytes
        .unwrap_or_else(|| max_decompressed_bytes(compressed));
    let inner = bzip2_capped(reader, limit);
    let mut loaded =
        read_cloud_from(inner, format, options).map_err(|e| decompression_limit(e, compressed))?;
    loaded.report.compression = Some("bzip2");
    Ok(loaded)
}

/// A text stream opened from a file that may be compressed: gzip (`.gz` or the gzip magic
/// bytes) or bzip2 (`.bz2` or `BZh`), decompressed on the fly and capped at
/// [`max_decompressed_bytes`] of the compressed size. Returns the stream, the compression's
/// name (if any) and the file's size on disk. Used by the log readers ([`carmen`]).
pub(crate) fn open_text(path: &Path) -> Result<(Box<dyn BufRead>, Option<&'static str>, u64)> {
    let mut reader = open_buffered(path)?;
    let size = reader.get_ref().metadata().map_or(0, |m| m.len());
    let limit = max_decompressed_bytes(size);
    if has_extension(path, "gz") || starts_with(&mut reader, path, &[0x1f, 0x8b])? {
        return Ok((gzip_capped(reader, path, limit)?, Some("gzip"), size));
    }
    if has_extension(path, "bz2") || starts_with(&mut reader, path, b"BZh")? {
        #[cfg(feature = "bzip2")]
        return Ok((Box::new(bzip2_capped(reader, limit)), Some("bzip2"), size));
        #[cfg(not(feature = "bzip2"))]
        return Err(Error::UnknownFormat {
            path: path.to_path_buf(),
            reason: "bzip2-compressed, but olmap was built without the `bzip2` feature".into(),
        });
    }
    Ok((Box::new(reader), None, size))
}

/// A gzip decoder (all members) over `reader` producing at most `limit` bytes, buffered.
#[cfg(feature = "gzip")]
fn gzip_capped<R: BufRead + 'static>(
    reader: R,
    _path: &Path,
    limit: u64,
) -> Result<Box<dyn BufRead>> {
    Ok(Box::new(BufReader::with_capacity(
        1 << 18,
        CappedReader {
            inner: flate2::bufread::MultiGzDecoder::new(reader),
            produced: 0,
            limit,
        },
    )))
}

#[cfg(not(feature = "gzip"))]
fn gzip_capped<R: BufRead + 'static>(
    _reader: R,
    path: &Path,
    _limit: u64,
) -> Result<Box<dyn BufRead>> {
    Err(Error::UnknownFormat {
        path: path.to_path_buf(),
        reason: "gzip-compressed, but olmap was built without the `gzip` feature".into(),
    })
}

/// A reader that refuses to produce more than `limit` bytes: past it, a read fails with
/// [`DecompressionLimit`] (the stream's end exactly at the limit is fine).
struct CappedReader<R> {
    inner: R,
    produced: u64,
    limit: u64,
}

/// The error a [`CappedReader`] fails with.
#[derive(Debug)]
struct DecompressionLimit {
    limit: u64,
}

impl std::fmt::Display for DecompressionLimit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "decompresses to more than {} bytes", self.limit)
    }
}

impl std::error::Error for DecompressionLimit {}

impl<R: std::io::Read> std::io::Read for CappedReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if buf.is_empty() {
            return Ok(0);
        }
        if self.produced >= self.limit {
            // One byte more than the limit is too many; the end of the stream is not.
            let mut probe = [0u8; 1];
            return match self.inner.read(&mut probe)? {
                0 => Ok(0),
                _ => Err(std::io::Error::other(DecompressionLimit {
                    limit: self.limit,
                })),
            };
        }
        let room = (self.limit - self.produced).min(buf.len() as u64) as usize;
        let n = self.inner.read(&mut buf[..room])?;
        self.produced += n as u64;
        Ok(n)
    }
}

/// Turns a parser's read failure caused by a [`CappedReader`] into [`ParseError::TooLarge`]
/// (other errors pass through).
pub(crate) fn decompression_limit(e: ParseError, compressed: u64) -> ParseError {
    let limit = match &e {
        ParseError::Io(io) => io
            .get_ref()
            .and_then(|inner| inner.downcast_ref::<DecompressionLimit>())
            .map(|d| d.limit),
        _ => None,
    };
    match limit {
        Some(limit) => ParseError::TooLarge {
            what: format!(
                "the compressed data ({compressed} bytes compressed) decompresses to more than {limit} \
                 bytes"
            ),
            limit: format!(
                "{limit} bytes decompressed: {DECOMPRESSION_RATIO} times the compressed size, at \
                 least {} MiB, unless ReadOptions::max_decompressed_bytes says otherwise",
                DECOMPRESSED_FLOOR_BYTES >> 20
            ),
        },
        None => e,
    }
}

/// Reads a cloud of a known format from a stream (no file name needed).
///
/// ```
/// use olmap::io::{read_cloud_from, CloudFormat, ReadOptions};
/// let text = b"# x y z\n1 2 3\n4 5 6\n";
/// let loaded = read_cloud_from(&text[..], CloudFormat::Xyz, &ReadOptions::default()).unwrap();
/// assert_eq!(loaded.cloud.len(), 2);
/// ```
pub fn read_cloud_from<R: BufRead>(
    reader: R,
    format: CloudFormat,
    options: &ReadOptions,
) -> Result<LoadedCloud, ParseError> {
    match format {
        CloudFormat::Pcd => pcd::read(reader),
        CloudFormat::Ply => ply::read(reader),
        CloudFormat::Xyz => xyz::read(reader),
        CloudFormat::Uos => uos::read(reader, options.uos_valid_only),
        CloudFormat::Csv => csv::read(reader),
        CloudFormat::KittiBin => kitti::read(reader),
        CloudFormat::ScanGraph => scan_graph::read(reader),
        #[cfg(feature = "las")]
        CloudFormat::Las => las::read(reader),
        #[cfg(not(feature = "las"))]
        CloudFormat::Las => Err(ParseError::Unsupported(NO_LAS.into())),
    }
}

/// Why LAS/LAZ cannot be read or written without the `las` feature.
#[cfg(not(feature = "las"))]
const NO_LAS: &str = "LAS/LAZ: olmap was built without the `las` feature";

/// The format [`write_cloud`] would write `path` in: `options.format`, or the one its
/// extension names. Callers check it before long work, so that a bad output name fails
/// before anything is computed or written.
pub fn output_format(path: &Path, options: &WriteOptions) -> Result<CloudFormat> {
    if let Some(f) = options.format {
        return Ok(f);
    }
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    CloudFormat::from_extension(ext).ok_or_else(|| Error::UnknownFormat {
        path: path.to_path_buf(),
        reason: format!(
            "cannot tell the output format from the extension '{ext}'; known: {}",
            CloudFormat::list_extensions()
        ),
    })
}

/// Writes a point cloud, choosing the format from the file name (or `options.format`).
/// The file appears complete or not at all.
pub fn write_cloud(
    path: impl AsRef<Path>,
    cloud: &PointCloud,
    options: &WriteOptions,
) -> Result<()> {
    let path = path.as_ref();
    let format = output_format(path, options)?;
    let laz_by_name;
    let options = if format == CloudFormat::Las && options.laz.is_none() {
        laz_by_name = WriteOptions {
            laz: Some(has_extension(path, "laz")),
            ..options.clone()
        };
        &laz_by_name
    } else {
        options
    };
    write_atomic(path, format.name(), |w| {
        write_cloud_to(w, cloud, format, options)
    })
}

/// Writes a cloud in a given format to a stream.
pub fn write_cloud_to<W: Write>(
    w: W,
    cloud: &PointCloud,
    format: CloudFormat,
    options: &WriteOptions,
) -> std::io::Result<()> {
    match format {
        CloudFormat::Pcd => pcd::write(w, cloud, options.pcd_encoding),
        CloudFormat::Ply => ply::write(w, cloud, options.ply_encoding),
        CloudFormat::Xyz => xyz::write(w, cloud),
        CloudFormat::Uos => uos::write(w, cloud),
        CloudFormat::Csv => csv::write(w, cloud),
        CloudFormat::KittiBin => kitti::write(w, cloud),
        CloudFormat::ScanGraph => scan_graph::write(w, cloud),
        #[cfg(feature = "las")]
        CloudFormat::Las => las::write(
            w,
            cloud,
            options.las_local_origin.unwrap_or([0.0; 3]),
            options.laz.unwrap_or(false),
        ),
        #[cfg(not(feature = "las"))]
        CloudFormat::Las => Err(std::io::Error::new(std::io::ErrorKind::Unsupported, NO_LAS)),
    }
}

/// Tells the format of a file from its name, and from its first bytes where the name does
/// not settle it.
pub fn detect_format_of_path(path: impl AsRef<Path>) -> Result<CloudFormat> {
    let path = path.as_ref();
    let mut reader = open_buffered(path)?;
    detect_format(path, &mut reader, path)
}

fn detect_format<R: BufRead>(name: &Path, reader: &mut R, path: &Path) -> Result<CloudFormat> {
    let head = reader.fill_buf().map_err(|e| Error::io(path, e))?;
    let head = &head[..head.len().min(64)];
    // Signatures win over extensions: a PLY saved as .txt is still a PLY.
    if head.starts_with(b"LASF") {
        return Ok(CloudFormat::Las);
    }
    if head.starts_with(b"ply") && head.get(3).is_some_and(|c| *c == b'\n' || *c == b'\r') {
        return Ok(CloudFormat::Ply);
    }
    let looks_pcd =
        head.starts_with(b"# .PCD") || head.starts_with(b"VERSION") || head.starts_with(b"FIELDS");
    let ext = name.extension().and_then(|e| e.to_str()).unwrap_or("");
    match CloudFormat::from_extension(ext) {
        Some(CloudFormat::Xyz) | Some(CloudFormat::Csv) | None if looks_pcd => Ok(CloudFormat::Pcd),
        Some(f) => Ok(f),
        None => Err(Error::UnknownFormat {
            path: path.to_path_buf(),
            reason: if ext.eq_ignore_ascii_case("bt") || ext.eq_ignore_ascii_case("ot") {
                "an OctoMap octree map, not a point cloud".into()
            } else if ext.is_empty() {
                format!(
                    "no extension and no known signature; known extensions: {} (optionally + .bz2)",
                    CloudFormat::list_extensions()
                )
            } else {
                format!(
                    "extension '.{ext}' is not a known point-cloud format and the content has no known signature; known: {} (optionally + .bz2)",
                    CloudFormat::list_extensions()
                )
            },
        }),
    }
}

fn has_extension(path: &Path, ext: &str) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case(ext))
}

fn starts_with<R: BufRead>(reader: &mut R, path: &Path, magic: &[u8]) -> Result<bool> {
    let head = reader.fill_buf().map_err(|e| Error::io(path, e))?;
    Ok(head.starts_with(magic))
}

/// Converts a point to single precision and keeps it if all three coordinates are finite
/// (also after the conversion: 1e300 does not fit an f32), counting the ones dropped.
#[inline]
pub(crate) fn finite_point(p: [f64; 3], report: &mut ReadReport) -> Option<nalgebra::Point3<f32>> {
    let q = nalgebra::Point3::new(p[0] as f32, p[1] as f32, p[2] as f32);
    if q.x.is_finite() && q.y.is_finite() && q.z.is_finite() {
        Some(q)
    } else {
        report.dropped_non_finite += 1;
        None
    }
}
