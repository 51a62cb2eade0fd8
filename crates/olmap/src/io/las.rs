//! LAS and LAZ point clouds (`.las`, `.laz`): LAS 1.0 to 1.4, LASzip-compressed LAZ, COPC
//! (`.copc.laz`) and files with extra bytes, read and written with the pure-Rust `las`
//! crate (feature `las`).
//!
//! # Local origin
//! A LAS file stores each coordinate as a 32-bit integer `N` with a scale and an offset per
//! axis: `file coordinate = N × scale + offset`, usually in a projected map frame (UTM, a
//! state plane) whose values are 10⁵ to 10⁷ m. Single precision cannot hold those: at
//! 6,724,186 m (a UTM northing) neighbouring `f32` values are 0.5 m apart. The reader
//! therefore moves the points to a **local origin** before they become `f32`:
//!
//! > cloud points = file coordinates − [`ReadReport::local_origin`]
//!
//! Per axis, the local origin is
//! * the header's offset, when the header's bounding box lies within [`NEAR_OFFSET_M`] of it
//!   (the offset is already a local origin: olmap's own files, most tiles in a local frame);
//! * otherwise the centre of the header's bounding box rounded to whole units (metres in a
//!   metric frame), moved onto the file's grid (the offset plus a whole number of scale
//!   steps `N₀`);
//! * the offset, when the header's bounding box is empty or not finite.
//!
//! The local coordinate is computed from the integer difference `N − N₀`, exactly: where the
//! scale is the reciprocal of a whole number (0.01, 0.001, ...) it is `(N − N₀) / (1/scale)`,
//! the correctly rounded decimal, so the same point read from different files (LAS or LAZ,
//! or rewritten by olmap) gives the same `f32` bit for bit. A file whose scale or offset is
//! not finite is read without a local origin (`0` on that axis; its points are usually
//! dropped as non-finite).
//!
//! # What is kept
//! x, y, z (metres or whatever unit the file's frame uses; see its CRS), the intensity (as
//! `f32`, the file's 16-bit value) and, for point formats with colour, the RGB colour as 8
//! bits: the high byte of the 16-bit values, or the values themselves when no channel of
//! any point exceeds 255 (files that store 8-bit colour). Every other field the point format
//! declares (return numbers, classification, GPS time, NIR, waveform packets, extra bytes)
//! is listed in [`ReadReport::fields`] but not kept: [`PointCloud`] has no place for them.
//! LAS has no sensor origin: the cloud's origin is the local origin (`(0, 0, 0)` in the
//! cloud's frame). Points with a non-finite coordinate are dropped and counted.
//!
//! # Bad and hostile files
//! The header is checked against the file's size before any point is read: an uncompressed
//! file must hold every point record its header announces, a LAZ file at most
//! [`MAX_LAZ_POINTS_PER_BYTE`] points per byte of point data, a LAZ chunk table at most one
//! chunk per byte, and every extended VLR must fit in the file. A header claiming 10¹² points
//! in a small file is refused with [`ParseError::Truncated`] before anything is allocated.
//! In layered LAZ (point formats 6 to 10) every chunk's layer sizes must fit before the
//! chunk table (LASzip allocates them before reading). The LASzip decoder itself panics on
//! some corrupt compressed data: the reader catches that and returns
//! [`ParseError::Malformed`] (the panic hook still runs: the default one prints the panic
//! on stderr).
//!
//! # Writing
//! LAS 1.2, point format 0 (x y z intensity), or 2 when the cloud has colours (8-bit
//! colours stored as 16 bits, `c × 257`); LAZ (LASzip) when asked for (`.laz`). Scale
//! [`WRITE_SCALE_M`] (1 mm) on every axis and offset = the local origin given, so that
//! file coordinates = points + local origin. Every point is a single return
//! (return 1 of 1), classification 0 ("created, never classified"); intensities are
//! rounded and clamped to `0..=65535`. Normals, the sensor origin and the creation date are
//! not written (the output is the same bytes for the same cloud). A point that LAS cannot
//! hold at 1 mm (not finite, or beyond ±2,147,483.647 m of the local origin) is an error.
//!
//! Round trip: points on the millimetre grid (every point read from a LAS file whose scale
//! is 0.001 or 0.01, …) within [`NEAR_OFFSET_M`] of the local origin come back bit for bit;
//! other points move by at most half a millimetre.
//!
//! ```
//! use olmap::io::{las, CloudFormat};
//! use olmap::cloud::PointCloud;
//! use nalgebra::Point3;
//! let cloud = PointCloud::from_points(vec![Point3::new(1.25, -0.5, 3.0)]);
//! let mut bytes = Vec::new();
//! // File coordinates: the points plus a UTM-sized local origin.
//! las::write(&mut bytes, &cloud, [500_000.0, 5_400_000.0, 0.0], false).unwrap();
//! let loaded = las::read(&bytes[..]).unwrap();
//! assert_eq!(loaded.report.format, CloudFormat::Las);
//! assert_eq!(loaded.report.local_origin, Some([500_000.0, 5_400_000.0, 0.0]));
//! assert_eq!(loaded.cloud.points(), cloud.points());
//! ```

use std::io::{BufRead, Cursor, Read, Seek, SeekFrom, Write};

use las::point::Format;
use las::{Header, PointDataBuilder, Reader, Transform, Vector, Writer};

use super::{finite_point, CloudFormat, LoadedCloud, ReadReport};
use crate::cloud::PointCloud;
use crate::error::{Location, ParseError};

/// The scale of every axis in files olmap writes: 0.001 (millimetres where the frame is in
/// metres), finer than any lidar's noise; ±2,147 km around the local origin fit.
pub const WRITE_SCALE_M: f64 = 0.001;

/// Scale steps per metre in files olmap writes (`1 / WRITE_SCALE_M`).
const STEPS_PER_M: f64 = 1000.0;

/// How far (on each axis, in the file's units) the header's bounding box may reach from the
/// header's offset for the offset to serve as the local origin: 8192. Within it an `f32`
/// rounds by at most 0.25 mm (its spacing below 8192 m is 0.49 mm).
pub const NEAR_OFFSET_M: f64 = 8192.0;

/// The most points a LAZ header may announce per byte of compressed point data: 256.
/// LASzip stores a million identical points in 7-12 kB (80-140 points per byte, measured
/// with point formats 0, 1, 3, 6 and 7); real lidar takes 1-5 bytes per point. More points
/// per byte than this means the header lies (or the file was cut short), and decoding what
/// is not there would take time for nothing.
pub const MAX_LAZ_POINTS_PER_BYTE: u64 = 256;

/// The most bytes [`read`] takes from a stream: 4 GiB (LAZ needs a seekable source, so a
/// stream is read into memory first). Files read by path through
/// [`crate::io::read_cloud_with`] have no such limit.
pub const MAX_STREAM_BYTES: u64 = 4 << 30;

/// Points decoded (or encoded) per batch.
const BATCH: usize = 1 << 16;

/// The length of a LAS 1.4 extended VLR's header, bytes.
const EVLR_HEADER_LEN: u64 = 60;

/// Reads a LAS or LAZ file from a stream, which is read into memory first (at most
/// [`MAX_STREAM_BYTES`]).
pub fn read<R: BufRead>(mut reader: R) -> Result<LoadedCloud, ParseError> {
    let mut bytes = Vec::new();
    reader
        .by_ref()
        .take(MAX_STREAM_BYTES + 1)
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_STREAM_BYTES {
        return Err(ParseError::TooLarge {
            what: "a LAS/LAZ stream of more than 4 GiB".into(),
            limit: format!(
                "{MAX_STREAM_BYTES} bytes read into memory from a stream; read the file by its \
                 path instead"
            ),
        });
    }
    read_seekable(Cursor::new(bytes))
}

/// Reads a LAS or LAZ file from a seekable source (a file), without reading it into memory.
pub fn read_seekable<R>(mut source: R) -> Result<LoadedCloud, ParseError>
where
    R: Read + Seek + Send + Sync + 'static,
{
    let size = source.seek(SeekFrom::End(0))?;
    if size == 0 {
        return Err(ParseError::Empty);
    }
    let chunks_end = check_sizes(&mut source, size)?;
    source.seek(SeekFrom::Start(0))?;
    let fence = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(u64::MAX));
    let source = Fenced {
        inner: source,
        at: 0,
        fence: fence.clone(),
    };
    let mut reader = guarded(|| Reader::new(source))?.map_err(header_error)?;
    if let Some(end) = chunks_end {
        // The header, VLRs and chunk table are read: from here on only the chunks.
        fence.store(end, std::sync::atomic::Ordering::Relaxed);
    }
    let header = reader.header().clone();
    let n = header.number_of_points();
    let bounds = header.bounds();
    let t = header.transforms();
    let axes = [
        Axis::new(t.x, bounds.min.x, bounds.max.x),
        Axis::new(t.y, bounds.min.y, bounds.max.y),
        Axis::new(t.z, bounds.min.z, bounds.max.z),
    ];
    let mut report = ReadReport::new(CloudFormat::Las);
    report.encoding = encoding(&header);
    report.fields = fields(&header);
    report.local_origin = Some(axes.map(|a| a.origin()));

    // Checked above: an uncompressed file holds its `n` records; a LAZ file is only known
    // to hold them when they decode: reserve for 4 bytes a point (real lidar takes 1-5),
    // beyond that the vectors grow as points come.
    let format = *header.point_format();
    let reserve = if format.is_compressed {
        n.min(size / 4)
    } else {
        n
    };
    let reserve = usize::try_from(reserve).unwrap_or(usize::MAX);
    let mut points = Vec::with_capacity(reserve);
    let mut intensity = Vec::with_capacity(reserve);
    let mut colors: Option<Vec<[u16; 3]>> = format.has_color.then(|| Vec::with_capacity(reserve));
    let mut data = PointDataBuilder::new().for_header(&header).build();
    while report.records < n {
        let got = guarded(|| reader.fill_points(BATCH as u64, &mut data))?
            .map_err(|e| point_error(e, report.records, n, format.is_compressed))?;
        if got == 0 {
            break;
        }
        let mut rgb = data.rgb();
        for (((x, y), z), i) in data
            .x_raw()
            .zip(data.y_raw())
            .zip(data.z_raw())
            .zip(data.intensity())
        {
            let c = rgb.as_mut().and_then(|it| it.next());
            let p = [axes[0].local(x), axes[1].local(y), axes[2].local(z)];
            if let Some(p) = finite_point(p, &mut report) {
                points.push(p);
                intensity.push(f32::from(i));
                if let (Some(colors), Some((r, g, b))) = (colors.as_mut(), c) {
                    colors.push([r, g, b]);
                }
            }
        }
        report.records += got;
    }
    if report.records < n {
        return Err(ParseError::Truncated(format!(
            "the point data ends after {} of the {n} points the header announces",
            report.records
        )));
    }
    let mut cloud = PointCloud::from_points(points);
    cloud
        .set_intensity(Some(intensity))
        .expect("one intensity per point");
    if let Some(colors) = colors {
        cloud
            .set_colors(Some(eight_bit(&colors)))
            .expect("one colour per point");
    }
    Ok(LoadedCloud { cloud, report })
}

/// Writes `cloud` as LAS (LAZ when `compressed`) with file coordinates = points +
/// `local_origin` (see the module documentation for the layout).
///
/// # Errors
/// [`std::io::ErrorKind::InvalidInput`] naming the point when a point does not fit at
/// [`WRITE_SCALE_M`] (not finite, or beyond ±2,147,483.647 m of the local origin) or the
/// local origin is not finite; the writer's own error otherwise.
pub fn write<W: Write>(
    mut w: W,
    cloud: &PointCloud,
    local_origin: [f64; 3],
    compressed: bool,
) -> std::io::Result<()> {
    w.write_all(&to_bytes(cloud, local_origin, compressed)?)
}

/// The bytes of the file [`write`] writes (the LAS writer needs to seek back to its header).
fn to_bytes(
    cloud: &PointCloud,
    local_origin: [f64; 3],
    compressed: bool,
) -> std::io::Result<Vec<u8>> {
    if !local_origin.iter().all(|v| v.is_finite()) {
        return Err(invalid_input(format!(
            "the LAS local origin must be finite, got {local_origin:?}"
        )));
    }
    // Every point is checked before the `las` writer exists: dropping it unclosed makes it
    // close itself, and it panics when that fails.
    for (i, p) in cloud.points().iter().enumerate() {
        for (name, v) in [("x", p.x), ("y", p.y), ("z", p.z)] {
            let steps = (f64::from(v) * STEPS_PER_M).round();
            if !(steps >= f64::from(i32::MIN) && steps <= f64::from(i32::MAX)) {
                return Err(invalid_input(format!(
                    "point {i}: {name} = {v} m is not finite or beyond ±2,147,483.647 m of the \
                     local origin: LAS cannot hold it at a 1 mm scale"
                )));
            }
        }
    }
    let colors = cloud.colors();
    let mut format = Format::new(if colors.is_some() { 2 } else { 0 }).map_err(las_io)?;
    format.is_compressed = compressed;
    let axis = |offset| Transform {
        scale: WRITE_SCALE_M,
        offset,
    };
    let transforms = Vector {
        x: axis(local_origin[0]),
        y: axis(local_origin[1]),
        z: axis(local_origin[2]),
    };
    let mut builder = las::Builder::from((1, 2));
    builder.point_format = format;
    builder.transforms = transforms;
    builder.generating_software = "olmap".into();
    builder.system_identifier = "olmap".into();
    let header = builder.into_header().map_err(las_io)?;
    let mut writer = Writer::new(Cursor::new(Vec::new()), header).map_err(las_io)?;
    let record_len = usize::from(format.len());
    for (b, batch) in cloud.points().chunks(BATCH).enumerate() {
        let mut bytes = Vec::with_capacity(batch.len() * record_len);
        for (j, p) in batch.iter().enumerate() {
            let i = b * BATCH + j;
            for v in [p.x, p.y, p.z] {
                // In range: checked above.
                let steps = (f64::from(v) * STEPS_PER_M).round() as i32;
                bytes.extend_from_slice(&steps.to_le_bytes());
            }
            let inten = cloud.intensity().map_or(0.0, |v| v[i]);
            // `as` saturates (NaN becomes 0).
            bytes.extend_from_slice(&(inten.round() as u16).to_le_bytes());
            // Return 1 of 1; classification 0; scan angle 0; user data 0; point source 0.
            bytes.extend_from_slice(&[0b0000_1001, 0, 0, 0, 0, 0]);
            if let Some(colors) = colors {
                for c in colors[i] {
                    bytes.extend_from_slice(&(u16::from(c) * 257).to_le_bytes());
                }
            }
        }
        let data = PointDataBuilder::new()
            .with_format(format)
            .with_transforms(transforms)
            .build_from_bytes(bytes)
            .map_err(las_io)?;
        writer.write_points(&data).map_err(las_io)?;
    }
    Ok(writer.into_inner().map_err(las_io)?.into_inner())
}

/// How one axis's integers become local coordinates.
#[derive(Debug, Clone, Copy)]
struct Axis {
    scale: f64,
    offset: f64,
    /// The local origin in scale steps from the offset (`N₀`).
    base: i64,
    /// `1 / scale` when it is a whole number: dividing by it gives the exact decimal.
    divisor: Option<f64>,
    /// Whether the scale and the offset are finite.
    finite: bool,
}

impl Axis {
    /// The axis of transform `t`, whose header bounds are `min..=max`.
    fn new(t: Transform, min: f64, max: f64) -> Axis {
        let finite = t.scale.is_finite() && t.offset.is_finite();
        let inverse = 1.0 / t.scale;
        let whole = inverse.round();
        let divisor =
            (finite && (1.0..=1e15).contains(&whole) && (inverse - whole).abs() <= 1e-9 * whole)
                .then_some(whole);
        let near = |v: f64| (v - t.offset).abs() <= NEAR_OFFSET_M;
        let base = if finite
            && t.scale != 0.0
            && min.is_finite()
            && max.is_finite()
            && min <= max
            && !(near(min) && near(max))
        {
            let centre = ((min + max) / 2.0).round();
            // Honest bounds are within the i32 range of steps; `as` saturates anyway.
            ((centre - t.offset) / t.scale)
                .round()
                .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i64
        } else {
            0
        };
        Axis {
            scale: t.scale,
            offset: t.offset,
            base,
            divisor,
            finite,
        }
    }

    /// `steps` scale steps as a length (exact below 2⁵³ steps).
    fn length(&self, steps: i64) -> f64 {
        let steps = steps as f64;
        match self.divisor {
            Some(d) => steps / d,
            None => steps * self.scale,
        }
    }

    /// The local coordinate of the integer `n`.
    fn local(&self, n: i32) -> f64 {
        if self.finite {
            self.length(i64::from(n) - self.base)
        } else {
            f64::from(n) * self.scale + self.offset
        }
    }

    /// The local origin in the file's frame.
    fn origin(&self) -> f64 {
        if self.finite {
            self.offset + self.length(self.base)
        } else {
            0.0
        }
    }
}

/// Runs a call into the `las` crate, turning a panic into [`ParseError::Malformed`]: its
/// LASzip decoder (laz 0.13) panics on some corrupt compressed data (an assertion in the
/// arithmetic decoder, an index out of range) that no check of the header can foresee
/// ([`crate::guard`]).
fn guarded<T>(call: impl FnOnce() -> T) -> Result<T, ParseError> {
    crate::guard::guarded(call).map_err(|why| {
        ParseError::Malformed(format!(
            "corrupt LAS/LAZ data (the LASzip decoder failed: {why})"
        ))
    })
}

/// Checks the header's claims against the file's `size` before the `las` crate reads it
/// (it allocates what the header announces): the point records, the LAZ chunk table, the
/// layered LAZ chunks and the extended VLRs must fit. Returns where the chunks of layered
/// LAZ end (see [`Fenced`]).
fn check_sizes<R: Read + Seek>(source: &mut R, size: u64) -> Result<Option<u64>, ParseError> {
    source.seek(SeekFrom::Start(0))?;
    let raw = las::raw::Header::read_from(source.by_ref()).map_err(header_error)?;
    let n = match raw.large_file {
        Some(large) if raw.number_of_point_records == 0 => large.number_of_point_records,
        _ => u64::from(raw.number_of_point_records),
    };
    let start = u64::from(raw.offset_to_point_data);
    if start > size {
        return Err(ParseError::Truncated(format!(
            "the point data should start at byte {start} but the file has {size} bytes"
        )));
    }
    let compressed = raw.point_data_record_format & 0x80 != 0;
    let record_len = u64::from(raw.point_data_record_length);
    let mut fence = None;
    if !compressed {
        let need = n.checked_mul(record_len).and_then(|b| b.checked_add(start));
        if need.is_none_or(|need| need > size) {
            return Err(ParseError::Truncated(format!(
                "the header announces {n} points of {record_len} bytes from byte {start}, but \
                 the file has {size} bytes"
            )));
        }
    } else {
        let room = size - start;
        if n > room.saturating_mul(MAX_LAZ_POINTS_PER_BYTE) {
            return Err(ParseError::Truncated(format!(
                "the header announces {n} points but the file has {room} bytes of compressed \
                 point data (olmap accepts at most {MAX_LAZ_POINTS_PER_BYTE} points per byte)"
            )));
        }
        let vlrs = VlrSpan {
            // Where the `las` crate reads them: after the version's whole header, even when
            // the header claims to be shorter (then its size only shifts the offsets).
            first: u64::from(raw.header_size.max(raw.version.header_size())),
            count: raw.number_of_variable_length_records,
            end: start,
        };
        let items = laszip_items(source, vlrs, raw.point_data_record_format, record_len)?;
        let table = check_chunk_table(source, start, size)?;
        if let Some(items) = items {
            let evlrs = raw
                .evlr
                .map(|e| e.start_of_first_evlr)
                .filter(|&e| e > start);
            let end = table.or(evlrs).unwrap_or(size).min(size);
            if check_layers(source, &items, start, end, n)? {
                fence = Some(end);
            }
        }
    }
    if let Some(evlr) = raw.evlr {
        let mut at = evlr.start_of_first_evlr;
        for i in 0..evlr.number_of_evlrs {
            let fits = at
                .checked_add(EVLR_HEADER_LEN)
                .is_some_and(|end| end <= size);
            if !fits {
                return Err(ParseError::Truncated(format!(
                    "extended VLR {i} of {} should start at byte {at} but the file has {size} \
                     bytes",
                    evlr.number_of_evlrs
                )));
            }
            source.seek(SeekFrom::Start(at + 20))?;
            let len = read_u64(source)?;
            let end = (at + EVLR_HEADER_LEN).checked_add(len);
            match end {
                Some(end) if end <= size => at = end,
                _ => {
                    return Err(ParseError::Truncated(format!(
                        "extended VLR {i} at byte {at} announces {len} bytes but the file has \
                         {size}"
                    )))
                }
            }
        }
    }
    Ok(fence)
}

/// Where a file's VLRs lie: `count` of them from byte `first`, ending by byte `end`.
#[derive(Debug, Clone, Copy)]
struct VlrSpan {
    first: u64,
    count: u32,
    end: u64,
}

/// The length of a VLR's header, bytes.
const VLR_HEADER_LEN: u64 = 54;

/// The record length of LAS point formats 0 to 10 without extra bytes.
const FORMAT_LEN: [u64; 11] = [20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67];

/// One item of a LASzip VLR: type, size in bytes, compressor version.
#[derive(Debug, Clone, Copy)]
struct LazItem {
    kind: u16,
    size: u16,
    version: u16,
}

/// The items of the LASzip VLR (`None` when there is none: the `las` crate says so),
/// checked against the point records as LASzip itself does not: every item of a fixed type
/// has that type's size, and the items fill the record exactly. A mismatch, no item at all
/// or a size sum beyond 16 bits makes LASzip panic.
fn laszip_items<R: Read + Seek>(
    source: &mut R,
    vlrs: VlrSpan,
    format: u8,
    record_len: u64,
) -> Result<Option<Vec<LazItem>>, ParseError> {
    let number = format & 0x3f;
    let Some(&base_len) = FORMAT_LEN.get(usize::from(number)) else {
        return Err(ParseError::Unsupported(format!(
            "point format {number} (compressed): LAS defines formats 0 to 10"
        )));
    };
    if record_len < base_len {
        return Err(ParseError::Malformed(format!(
            "point records of {record_len} bytes are shorter than point format {number}'s \
             {base_len}"
        )));
    }
    let mut at = vlrs.first;
    for _ in 0..vlrs.count {
        if at + VLR_HEADER_LEN > vlrs.end {
            break; // the `las` crate reports the VLRs that do not fit
        }
        source.seek(SeekFrom::Start(at))?;
        let mut head = [0u8; VLR_HEADER_LEN as usize];
        source.read_exact(&mut head)?;
        let user = &head[2..18];
        let record_id = u16::from_le_bytes([head[18], head[19]]);
        let len = u64::from(u16::from_le_bytes([head[20], head[21]]));
        if user.starts_with(b"laszip encoded") && record_id == 22204 {
            let mut data = vec![0u8; len as usize];
            source.read_exact(&mut data)?;
            return check_items(&data, record_len).map(Some);
        }
        at += VLR_HEADER_LEN + len;
    }
    Ok(None)
}

/// The item list of a LASzip VLR's data (from byte 32), checked (see [`laszip_items`]).
fn check_items(data: &[u8], record_len: u64) -> Result<Vec<LazItem>, ParseError> {
    let bad = |reason: String| ParseError::Malformed(format!("LASzip VLR: {reason}"));
    let Some(count) = data.get(32..34) else {
        return Err(bad(format!(
            "{} bytes, too short for its item list",
            data.len()
        )));
    };
    let count = usize::from(u16::from_le_bytes([count[0], count[1]]));
    let Some(raw) = data.get(34..34 + 6 * count) else {
        return Err(bad(format!(
            "{count} items announced in {} bytes",
            data.len()
        )));
    };
    let word = |b: &[u8], i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
    let items: Vec<LazItem> = raw
        .chunks_exact(6)
        .map(|b| LazItem {
            kind: word(b, 0),
            size: word(b, 2),
            version: word(b, 4),
        })
        .collect();
    let mut total = 0u64;
    for item in &items {
        // Point10, GPS time, RGB12, wave packet 1.3, Point14, RGB14, RGBNIR14, wave packet 1.4.
        let fixed = match item.kind {
            6 => Some(20),
            7 | 12 => Some(8),
            8 | 11 => Some(6),
            9 | 13 => Some(29),
            10 => Some(30),
            _ => None, // extra bytes (0, 14): any size; unknown types: LASzip refuses them
        };
        if let Some(fixed) = fixed.filter(|&f| f != item.size) {
            return Err(bad(format!(
                "item type {} has {} bytes, expected {fixed}",
                item.kind, item.size
            )));
        }
        total += u64::from(item.size);
    }
    if total != record_len {
        return Err(bad(format!(
            "its items hold {total} bytes per point but the point records have {record_len}"
        )));
    }
    // Items of version 3 and 4 are decoded as layered chunks, whatever the compressor says:
    // only the layered compressor (3) lays its chunks out so.
    let compressor = word(data, 0);
    if items.first().is_some_and(|i| matches!(i.version, 3 | 4)) && compressor != 3 {
        return Err(bad(format!(
            "items of version {} need the layered compressor (3), not {compressor}",
            items[0].version
        )));
    }
    Ok(items)
}

/// The chunk table's offset, found as LASzip finds it (the offset written at the start of
/// the point data, or the one in the file's last 8 bytes), after checking its chunk count
/// (one chunk per byte of the file at most: LASzip reserves memory for them all).
fn check_chunk_table<R: Read + Seek>(
    source: &mut R,
    start: u64,
    size: u64,
) -> Result<Option<u64>, ParseError> {
    if start.saturating_add(8) > size {
        return Ok(None); // LASzip fails to read the offset itself
    }
    source.seek(SeekFrom::Start(start))?;
    let mut table = read_u64(source)?;
    if table <= start || table > i64::MAX as u64 {
        source.seek(SeekFrom::Start(size - 8))?;
        table = read_u64(source)?;
        if table <= start || table > i64::MAX as u64 {
            return Ok(None); // no chunk table: LASzip reads the chunks in order
        }
    }
    if table.saturating_add(8) > size {
        return Ok(None); // LASzip fails to read it itself
    }
    source.seek(SeekFrom::Start(table + 4))?;
    let mut count = [0u8; 4];
    source.read_exact(&mut count)?;
    let chunks = u64::from(u32::from_le_bytes(count));
    if chunks > size {
        return Err(ParseError::at(
            Location::Byte(table + 4),
            format!("the LAZ chunk table announces {chunks} chunks in a file of {size} bytes"),
        ));
    }
    Ok(Some(table))
}

/// Checks the chunks of layered LAZ (point formats 6 to 10, LASzip items of version 3 and
/// 4), for LASzip allocates each layer's announced size (up to 4 GiB) before it reads it:
/// every layer must fit in the bytes left, and the chunks must hold the `n` points the
/// header announces (past them LASzip would take what follows for another chunk). The
/// chunks follow each other from `start + 8` up to `end` (the chunk table): in each, the
/// first point's raw record, the chunk's point count (u32), one u32 size per layer, then
/// the layers. Returns whether the chunks were layered (and checked).
fn check_layers<R: Read + Seek>(
    source: &mut R,
    items: &[LazItem],
    start: u64,
    end: u64,
    n: u64,
) -> Result<bool, ParseError> {
    if !items.first().is_some_and(|i| matches!(i.version, 3 | 4)) {
        return Ok(false); // point-wise chunks: no sizes to trust
    }
    let mut layers = 0u64;
    for item in items {
        layers += match item.kind {
            10 => 9, // xy and channel, z, classification, flags, intensity, angle, user, source, time
            11 | 13 => 1,
            12 => 2,                    // RGB and NIR
            14 => u64::from(item.size), // one layer per extra byte
            _ => return Ok(false),      // LASzip refuses the mix itself
        };
    }
    let record_len: u64 = items.iter().map(|i| u64::from(i.size)).sum();
    let head = record_len + 4 + 4 * layers;
    let mut at = start + 8;
    let mut sizes = vec![0u8; 4 * layers as usize];
    let mut points = 0u64;
    while at.saturating_add(head) <= end {
        source.seek(SeekFrom::Start(at + record_len))?;
        let mut count = [0u8; 4];
        source.read_exact(&mut count)?;
        points += u64::from(u32::from_le_bytes(count));
        source.read_exact(&mut sizes)?;
        let mut next = at + head;
        for (i, b) in sizes.chunks_exact(4).enumerate() {
            let layer = u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
            if layer > end - next {
                return Err(ParseError::at(
                    Location::Byte(at + record_len + 4 + 4 * i as u64),
                    format!(
                        "LAZ layer {i} of the chunk at byte {at} announces {layer} bytes but \
                         only {} remain before the chunk table",
                        end - next
                    ),
                ));
            }
            next += layer;
        }
        at = next;
    }
    if points < n {
        return Err(ParseError::Truncated(format!(
            "the header announces {n} points but the LAZ chunks hold {points}"
        )));
    }
    Ok(true)
}

/// A source that ends at a fence once it is set: what LASzip reads of layered LAZ past the
/// chunks checked by [`check_layers`]. LASzip starts a new chunk where its chunk table
/// says the last one ended; a corrupt table makes it take the chunk table and the extended
/// VLRs for a chunk, and allocate the layer sizes it finds there (up to 4 GiB each) before
/// reading them. Behind the fence the first point of such a chunk is already missing.
struct Fenced<R> {
    inner: R,
    /// The position in `inner`.
    at: u64,
    /// Where reading stops (`u64::MAX`: nowhere), shared with the caller.
    fence: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl<R: Read> Read for Fenced<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let fence = self.fence.load(std::sync::atomic::Ordering::Relaxed);
        let room = fence.saturating_sub(self.at);
        let len = usize::try_from(room).map_or(buf.len(), |r| r.min(buf.len()));
        let got = self.inner.read(&mut buf[..len])?;
        self.at += got as u64;
        Ok(got)
    }
}

impl<R: Seek> Seek for Fenced<R> {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        self.at = self.inner.seek(to)?;
        Ok(self.at)
    }
}

fn read_u64<R: Read>(source: &mut R) -> Result<u64, ParseError> {
    let mut b = [0u8; 8];
    source.read_exact(&mut b)?;
    Ok(u64::from_le_bytes(b))
}

/// The reader's error for a header the `las` crate refuses.
fn header_error(e: las::Error) -> ParseError {
    match e {
        las::Error::InvalidFileSignature(sig) => ParseError::Malformed(format!(
            "not a LAS file: it starts with {sig:?}, expected the signature 'LASF'"
        )),
        las::Error::Io(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            ParseError::Truncated("the file ends inside its header or VLRs".into())
        }
        las::Error::Io(e) => ParseError::Io(e),
        e @ (las::Error::InvalidPointFormatNumber(_)
        | las::Error::InvalidPointFormat(_)
        | las::Error::UnsupportedFeature { .. }
        | las::Error::UnsupportedFormat { .. }) => ParseError::Unsupported(e.to_string()),
        e => ParseError::Malformed(format!("bad LAS header: {e}")),
    }
}

/// The reader's error for points `done..` of `n` that could not be read.
fn point_error(e: las::Error, done: u64, n: u64, compressed: bool) -> ParseError {
    match e {
        las::Error::Io(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            ParseError::Truncated(format!(
                "the point data ends after at most {done} of the {n} points the header announces"
            ))
        }
        e if compressed => ParseError::at(
            Location::Point(done),
            format!("the LAZ point data does not decompress: {e}"),
        ),
        e => ParseError::at(Location::Point(done), e.to_string()),
    }
}

fn invalid_input(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// A `las` crate error as an I/O error (writers return those).
fn las_io(e: las::Error) -> std::io::Error {
    match e {
        las::Error::Io(e) => e,
        e => std::io::Error::other(e),
    }
}

/// `LAS 1.2, point format 1` or `LAZ 1.4, point format 7, COPC`.
fn encoding(header: &Header) -> String {
    let format = header.point_format();
    let mut base = *format;
    base.is_compressed = false;
    base.extra_bytes = 0;
    let number = base.to_u8().map_or("?".to_string(), |n| n.to_string());
    let mut s = format!(
        "{} {}, point format {number}",
        if format.is_compressed { "LAZ" } else { "LAS" },
        header.version()
    );
    if header
        .all_vlrs()
        .any(|v| v.user_id == "copc" && v.record_id == 1)
    {
        s.push_str(", COPC");
    }
    s
}

/// The per-point fields the point format declares, extra bytes by their names.
fn fields(header: &Header) -> Vec<String> {
    let format = header.point_format();
    let mut out: Vec<String> = [
        "x",
        "y",
        "z",
        "intensity",
        "return_number",
        "number_of_returns",
        "scan_direction",
        "edge_of_flight_line",
        "classification",
        "scan_angle",
        "user_data",
        "point_source_id",
    ]
    .map(String::from)
    .to_vec();
    if format.is_extended {
        out.push("scanner_channel".into());
    }
    if format.has_gps_time {
        out.push("gps_time".into());
    }
    if format.has_color {
        out.extend(["red", "green", "blue"].map(String::from));
    }
    if format.has_nir {
        out.push("nir".into());
    }
    if format.has_waveform {
        out.push("wave_packet".into());
    }
    // Extra bytes: the names in the Extra Bytes VLR (192-byte descriptors, name at 4..36).
    let mut named = Vec::new();
    for vlr in header.all_vlrs() {
        if vlr.user_id == "LASF_Spec" && vlr.record_id == 4 {
            for d in vlr.data.chunks_exact(192) {
                let name = String::from_utf8_lossy(&d[4..36]);
                named.push(name.trim_end_matches('\0').trim().to_string());
            }
        }
    }
    if format.extra_bytes > 0 && named.is_empty() {
        named.push(format!("extra_bytes[{}]", format.extra_bytes));
    }
    out.extend(named);
    out
}

/// 16-bit LAS colours as 8 bits: the high byte, or the values themselves when none exceeds
/// 255 (a file storing 8-bit colour).
fn eight_bit(colors: &[[u16; 3]]) -> Vec<[u8; 3]> {
    let sixteen = colors.iter().flatten().any(|&c| c > 255);
    colors
        .iter()
        .map(|c| c.map(|v| if sixteen { (v >> 8) as u8 } else { v as u8 }))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    /// Points on the millimetre grid within 8.1 km of the origin (`n` <= 1000), with
    /// intensities and colours.
    fn mm_cloud(n: usize) -> PointCloud {
        let points = (0..n as i64)
            .map(|i| {
                let mm = |k: i64| (k as f64 / 1000.0) as f32;
                Point3::new(mm(i * 7919 - 40_000), mm(-i * 8111), mm(i * 13 - 500))
            })
            .collect();
        let mut cloud = PointCloud::from_points(points);
        cloud
            .set_intensity(Some((0..n).map(|i| (i * 37 % 65536) as f32).collect()))
            .unwrap();
        cloud
            .set_colors(Some(
                (0..n)
                    .map(|i| [i as u8, (255 - i % 256) as u8, 7])
                    .collect(),
            ))
            .unwrap();
        cloud
    }

    fn round_trip(cloud: &PointCloud, origin: [f64; 3], compressed: bool) -> LoadedCloud {
        let mut bytes = Vec::new();
        write(&mut bytes, cloud, origin, compressed).unwrap();
        read(&bytes[..]).unwrap()
    }

    #[test]
    fn millimetre_points_round_trip_exactly() {
        let cloud = mm_cloud(1000);
        for compressed in [false, true] {
            for origin in [[0.0; 3], [635_000.0, 6_724_186.0, 120.0]] {
                let back = round_trip(&cloud, origin, compressed);
                assert_eq!(back.report.local_origin, Some(origin));
                assert_eq!(back.report.records, 1000);
                assert_eq!(
                    back.cloud.points(),
                    cloud.points(),
                    "{origin:?} {compressed}"
                );
                assert_eq!(back.cloud.intensity(), cloud.intensity());
                assert_eq!(back.cloud.colors(), cloud.colors());
                let kind = if compressed { "LAZ 1.2" } else { "LAS 1.2" };
                assert_eq!(back.report.encoding, format!("{kind}, point format 2"));
            }
        }
    }

    #[test]
    fn other_points_move_by_at_most_half_a_millimetre() {
        let points: Vec<_> = (0..500)
            .map(|i| {
                let t = i as f32 * 0.123_456_7;
                Point3::new(t.sin() * 900.0, t.cos() * 1234.5678, t * 0.01)
            })
            .collect();
        let mut cloud = PointCloud::from_points(points);
        cloud
            .set_intensity(Some((0..500).map(|i| i as f32 * 0.7 - 3.0).collect()))
            .unwrap();
        let back = round_trip(&cloud, [0.0; 3], false);
        assert!(back.cloud.colors().is_none());
        for (a, b) in cloud.points().iter().zip(back.cloud.points()) {
            // Half the 1 mm step, plus the f32 spacing near 1234 m (0.12 mm).
            assert!((a - b).abs().max() <= 0.0005 + 0.000_13, "{a} {b}");
        }
        let inten = back.cloud.intensity().unwrap();
        assert_eq!(inten[0], 0.0); // -3 clamped
        assert_eq!(inten[499], (499.0f32 * 0.7 - 3.0).round());
    }

    #[test]
    fn unrepresentable_points_are_refused() {
        for p in [
            Point3::new(0.0, 3.0e38, 0.0),
            Point3::new(f32::NAN, 0.0, 0.0),
        ] {
            let cloud = PointCloud::from_points(vec![Point3::origin(), p]);
            let e = write(Vec::new(), &cloud, [0.0; 3], false).unwrap_err();
            assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
            assert!(e.to_string().contains("point 1"), "{e}");
        }
        let e = write(Vec::new(), &PointCloud::new(), [f64::NAN, 0.0, 0.0], false).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
    }

    #[test]
    fn empty_cloud_round_trips() {
        for compressed in [false, true] {
            let back = round_trip(&PointCloud::new(), [1.0, 2.0, 3.0], compressed);
            assert!(back.cloud.is_empty());
            assert_eq!(back.report.records, 0);
            assert_eq!(back.report.local_origin, Some([1.0, 2.0, 3.0]));
        }
    }

    #[test]
    fn far_bounds_move_the_local_origin_to_their_centre() {
        let t = Transform {
            scale: 0.01,
            offset: 0.0,
        };
        let a = Axis::new(t, 6_724_172.52, 6_724_199.99);
        assert_eq!(a.origin(), 6_724_186.0);
        assert_eq!(a.local(672_418_600 + 123), 1.23);
        // Bounds near the offset keep it.
        let near = Axis::new(t, -100.0, 8000.0);
        assert_eq!((near.origin(), near.local(-5)), (0.0, -0.05));
        // No bounds (an empty file): the offset.
        let none = Axis::new(t, f64::INFINITY, f64::NEG_INFINITY);
        assert_eq!(none.origin(), 0.0);
        // A scale that is no whole fraction multiplies.
        let odd = Axis::new(
            Transform {
                scale: 0.3,
                offset: 5.0,
            },
            0.0,
            1.0,
        );
        assert_eq!((odd.origin(), odd.local(10)), (5.0, 10.0 * 0.3));
    }

    /// A LAS 1.4 file of `n` points written by the `las` crate in point `format` with
    /// `extra` extra bytes, LAZ when `compressed`.
    fn las14(format: u8, extra: u16, n: usize, compressed: bool) -> Vec<u8> {
        let mut f = Format::new(format).unwrap();
        f.extra_bytes = extra;
        f.is_compressed = compressed;
        let mut builder = las::Builder::from((1, 4));
        builder.point_format = f;
        let axis = |offset| Transform {
            scale: 0.01,
            offset,
        };
        builder.transforms = Vector {
            x: axis(500_000.0),
            y: axis(5_400_000.0),
            z: axis(0.0),
        };
        let header = builder.into_header().unwrap();
        let mut writer = Writer::new(Cursor::new(Vec::new()), header).unwrap();
        for i in 0..n {
            let v = i as u16;
            writer
                .write_point(las::Point {
                    x: 500_000.0 + i as f64 * 0.01,
                    y: 5_400_000.0 - (i % 977) as f64,
                    z: (i % 13) as f64 * 0.5,
                    intensity: v,
                    return_number: 1,
                    number_of_returns: 1,
                    gps_time: Some(i as f64 * 1e-5),
                    color: f.has_color.then_some(las::Color::new(v, v / 2, 7)),
                    nir: f.has_nir.then_some(v / 3),
                    extra_bytes: (0..extra)
                        .map(|k| (i as u16).wrapping_add(k) as u8)
                        .collect(),
                    ..Default::default()
                })
                .unwrap();
        }
        writer.into_inner().unwrap().into_inner()
    }

    #[test]
    fn layered_laz_reads_like_its_las() {
        // 120,000 points: three LASzip chunks of at most 50,000.
        for (format, extra) in [(6, 0), (7, 3), (8, 1)] {
            let las = read(&las14(format, extra, 120_000, false)[..]).unwrap();
            let laz = read(&las14(format, extra, 120_000, true)[..]).unwrap();
            assert_eq!(laz.cloud.len(), 120_000);
            assert_eq!(laz.cloud, las.cloud, "format {format}");
            assert_eq!(laz.report.local_origin, las.report.local_origin);
            assert_eq!(
                laz.report.encoding,
                format!("LAZ 1.4, point format {format}")
            );
            // Bounds within 8192 m of the offset: the offset is the local origin.
            assert_eq!(laz.report.local_origin, Some([500_000.0, 5_400_000.0, 0.0]));
            assert_eq!(laz.cloud.points()[1199], Point3::new(11.99, -222.0, 1.5));
        }
    }

    #[test]
    fn a_layer_larger_than_the_file_is_refused_before_it_is_allocated() {
        let mut bytes = las14(7, 0, 10, true);
        let start = u32::from_le_bytes(bytes[96..100].try_into().unwrap()) as usize;
        // The first chunk: the chunk table offset (8), the first point (36), the count (4),
        // then the layer sizes; the z layer is the second.
        let z = start + 8 + 36 + 4 + 4;
        bytes[z..z + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        let e = read(&bytes[..]).unwrap_err();
        assert!(
            matches!(e, ParseError::Invalid { at: Location::Byte(b), .. } if b == z as u64),
            "{e}"
        );
    }

    #[test]
    fn bad_headers_are_typed_errors() {
        let mut bytes = Vec::new();
        write(&mut bytes, &mm_cloud(10), [0.0; 3], false).unwrap();
        // Point count at byte 107 (LAS 1.2): ten records become 10^9.
        let mut lying = bytes.clone();
        lying[107..111].copy_from_slice(&1_000_000_000u32.to_le_bytes());
        assert!(matches!(read(&lying[..]), Err(ParseError::Truncated(_))));
        assert!(matches!(
            read(&bytes[..bytes.len() - 1]),
            Err(ParseError::Truncated(_))
        ));
        assert!(matches!(read(&bytes[..100]), Err(ParseError::Truncated(_))));
        assert!(matches!(read(&b""[..]), Err(ParseError::Empty)));
        let e = read(&b"PK\x03\x04 not a las file at all"[..]).unwrap_err();
        assert!(e.to_string().contains("LASF"), "{e}");
    }
}
