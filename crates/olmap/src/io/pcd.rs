//! PCD, the Point Cloud Data format of the Point Cloud Library (PCL), version 0.7.
//!
//! Source: the PCD v0.7 specification (PCL documentation, "The PCD (Point Cloud Data) file
//! format") and the behaviour of PCL's `pcd_io.cpp`, which is what real files follow.
//!
//! A PCD file is a text header, one `KEY values...` per line, ending with the `DATA` line;
//! the point data follows straight after that line's `\n`:
//!
//! ```text
//! # .PCD v0.7 - Point Cloud Data file format
//! VERSION 0.7
//! FIELDS x y z intensity
//! SIZE 4 4 4 4
//! TYPE F F F F
//! COUNT 1 1 1 1
//! WIDTH 2
//! HEIGHT 1
//! VIEWPOINT 0 0 0 1 0 0 0
//! POINTS 2
//! DATA ascii
//! 1.5 2 3 17
//! 4 5 6 12
//! ```
//!
//! * `FIELDS` names the per-point fields; `SIZE` gives their size in bytes (1, 2, 4 or 8),
//!   `TYPE` their kind (`I` signed integer, `U` unsigned integer, `F` floating point, only
//!   with size 4 or 8) and `COUNT` how many values each field has (`fpfh` has 33).
//! * `WIDTH` × `HEIGHT` is the number of points; `HEIGHT` > 1 marks an *organised* cloud (an
//!   image-like grid, in which PCL stores missing returns as NaN points). `POINTS` repeats the
//!   product.
//! * `VIEWPOINT tx ty tz qw qx qy qz` is the sensor pose.
//! * `DATA ascii`: one point per line, values separated by whitespace. `DATA binary`: packed
//!   little-endian records, the fields in order (record size Σ size·count). `DATA
//!   binary_compressed`: a little-endian `u32` compressed size, a `u32` uncompressed size and
//!   one LZF block (see [`crate::file::lzf`]) of the data rearranged field by field
//!   (structure of arrays: all the values of the first field, then of the second, ...).
//!
//! ## What the reader takes from a file
//! * `x y z` (any numeric type) are the positions; points with a NaN or infinite coordinate
//!   are dropped and counted in [`ReadReport::dropped_non_finite`];
//! * `intensity` (that exact name, any numeric type) becomes the cloud's intensity;
//! * `normal_x normal_y normal_z` (all three) become the normals;
//! * `rgb` or `rgba` (4 bytes of any type) become the colours: the 4 bytes read as a
//!   little-endian `u32` hold `0x00RRGGBB` (the alpha byte of `rgba` is ignored);
//! * the `VIEWPOINT` translation becomes the cloud's origin (its rotation is not kept).
//!
//! Every other field (`curvature`, `label`, `fpfh`, PCL's `_` padding, ...) is skipped; all
//! the names appear in [`ReadReport::fields`].
//!
//! ## Quirks handled
//! * `VERSION` may be `0.7`, `.7`, or the older `.6`/`.5` (or absent); `COLUMNS` is read as
//!   `FIELDS`; `COUNT` defaults to 1, `HEIGHT` to 1, `POINTS` to `WIDTH` × `HEIGHT`, `WIDTH` to
//!   `POINTS` (when `HEIGHT` is 1), `VIEWPOINT` to the identity; ascii files may omit `SIZE`
//!   and `TYPE` (then every field is `F 4`). Keys are case-insensitive, `#` lines are comments.
//! * Organised clouds full of NaN points are normal; the report keeps `(WIDTH, HEIGHT)` in
//!   [`ReadReport::organized`] although the points returned are only the finite ones.
//! * In ascii files an `rgb` value of type `F` may be written either as the integer
//!   `0x00RRGGBB` (what PCL writes) or as the float whose bits hold it; an integer token is
//!   taken as the packed integer. `nan`, `NaN`, `inf` are accepted everywhere; blank lines
//!   are skipped; lines after the announced points are ignored.
//! * `binary_compressed` files often carry bytes after the LZF block; they are ignored, as
//!   are bytes after the last record of `binary` files.
//!
//! Nothing in a header is trusted: the sizes are checked for overflow, and no buffer is
//! sized from the header's counts before the bytes are there, so a header that claims
//! 10¹² points above a few bytes of data gives [`ParseError::Truncated`], not an
//! out-of-memory abort. No input makes the reader panic.
//!
//! ## What the writer writes
//! `x y z` (`F 4`), then `intensity` (`F 4`), `normal_x normal_y normal_z` (`F 4`) and `rgb`
//! (`U 4`, `0x00RRGGBB`) when the cloud has them; `WIDTH` = the number of points, `HEIGHT` 1,
//! `VIEWPOINT` = the origin with the identity rotation. Ascii values are written in their
//! shortest round-trip form, so every encoding reads back bit for bit.

use std::io::{self, BufRead, Read, Write};
use std::str::FromStr;

use nalgebra::{Point3, Vector3};

use super::{finite_point, CloudFormat, LoadedCloud, PcdEncoding, ReadReport};
use crate::cloud::PointCloud;
use crate::error::{Location, ParseError};
use crate::file::lzf;

/// Longest header line accepted (a guard against binary garbage without line ends).
const MAX_HEADER_LINE: u64 = 1 << 20;
/// Bytes of binary data read and decoded at a time.
const CHUNK_BYTES: usize = 1 << 20;
/// Points reserved up front at most; beyond that the vectors grow as points arrive.
const INITIAL_CAPACITY: u64 = 1 << 16;
/// The header keys, for error messages.
const KEYS: &str = "VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT, VIEWPOINT, POINTS or DATA";

// ---------------------------------------------------------------------------------------
// Reading
// ---------------------------------------------------------------------------------------

/// Reads a PCD file (any of the three encodings) from a stream.
///
/// The stream is read up to the end of the point data; trailing bytes are not looked at.
/// Errors name the header line (for header and ascii problems) and what was expected there.
///
/// ```
/// let pcd = b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 2\n\
///             DATA ascii\n1 2 3\nnan 0 0\n";
/// let loaded = olmap::io::pcd::read(&pcd[..]).unwrap();
/// assert_eq!(loaded.cloud.len(), 1);
/// assert_eq!(loaded.report.dropped_non_finite, 1);
/// ```
pub fn read<R: BufRead>(mut reader: R) -> Result<LoadedCloud, ParseError> {
    let header = read_header(&mut reader)?;
    let mut report = ReadReport::new(CloudFormat::Pcd);
    report.encoding = header.encoding.name().to_string();
    report.records = header.points;
    report.fields = header.fields.iter().map(|f| f.name.clone()).collect();
    if header.height > 1 {
        report.organized = Some((header.width, header.height));
    }
    let mut builder = CloudBuilder::new(&header.roles, header.points.min(INITIAL_CAPACITY));
    match header.encoding {
        DataEncoding::Ascii => read_ascii(&mut reader, &header, &mut builder, &mut report)?,
        DataEncoding::Binary => read_binary(&mut reader, &header, &mut builder, &mut report)?,
        DataEncoding::BinaryCompressed => {
            read_compressed(&mut reader, &header, &mut builder, &mut report)?
        }
    }
    let v = &header.viewpoint;
    let cloud = builder.finish(Point3::new(v[0], v[1], v[2]))?;
    Ok(LoadedCloud { cloud, report })
}

/// The three ways of storing the points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DataEncoding {
    Ascii,
    Binary,
    BinaryCompressed,
}

impl DataEncoding {
    fn name(self) -> &'static str {
        match self {
            DataEncoding::Ascii => "ascii",
            DataEncoding::Binary => "binary",
            DataEncoding::BinaryCompressed => "binary_compressed",
        }
    }
}

/// The numeric type of a field's values (`TYPE` letter and `SIZE` together).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    /// The scalar of a `TYPE` letter (upper case) and `SIZE`, if the pair is valid.
    fn new(kind: u8, size: usize) -> Option<Scalar> {
        Some(match (kind, size) {
            (b'I', 1) => Scalar::I8,
            (b'U', 1) => Scalar::U8,
            (b'I', 2) => Scalar::I16,
            (b'U', 2) => Scalar::U16,
            (b'I', 4) => Scalar::I32,
            (b'U', 4) => Scalar::U32,
            (b'I', 8) => Scalar::I64,
            (b'U', 8) => Scalar::U64,
            (b'F', 4) => Scalar::F32,
            (b'F', 8) => Scalar::F64,
            _ => return None,
        })
    }

    /// Bytes per value.
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    /// The little-endian value at `pos` of `buf`, as a double (0 where `buf` is too short,
    /// which the callers rule out).
    #[inline]
    fn read(self, buf: &[u8], pos: usize) -> f64 {
        match self {
            Scalar::I8 => f64::from(i8::from_le_bytes(bytes_at(buf, pos))),
            Scalar::U8 => f64::from(u8::from_le_bytes(bytes_at(buf, pos))),
            Scalar::I16 => f64::from(i16::from_le_bytes(bytes_at(buf, pos))),
            Scalar::U16 => f64::from(u16::from_le_bytes(bytes_at(buf, pos))),
            Scalar::I32 => f64::from(i32::from_le_bytes(bytes_at(buf, pos))),
            Scalar::U32 => f64::from(u32::from_le_bytes(bytes_at(buf, pos))),
            Scalar::I64 => i64::from_le_bytes(bytes_at(buf, pos)) as f64,
            Scalar::U64 => u64::from_le_bytes(bytes_at(buf, pos)) as f64,
            Scalar::F32 => f64::from(f32::from_le_bytes(bytes_at(buf, pos))),
            Scalar::F64 => f64::from_le_bytes(bytes_at(buf, pos)),
        }
    }

    /// Parses an ascii value of this type. `F 4` values are parsed as `f32` directly (going
    /// through `f64` could round twice and miss the written value).
    #[inline]
    fn parse(self, token: &[u8]) -> Option<f64> {
        let s = std::str::from_utf8(token).ok()?;
        match self {
            Scalar::F32 => s.parse::<f32>().ok().map(f64::from),
            _ => s.parse::<f64>().ok(),
        }
    }
}

/// `N` bytes of `buf` from `pos`, zeros where `buf` is too short.
#[inline]
fn bytes_at<const N: usize>(buf: &[u8], pos: usize) -> [u8; N] {
    let mut out = [0u8; N];
    if let Some(src) = buf.get(pos..pos.saturating_add(N)) {
        out.copy_from_slice(src);
    }
    out
}

/// One field of the header.
#[derive(Debug, Clone)]
struct Field {
    name: String,
    scalar: Scalar,
    count: usize,
    /// Byte offset of the field within a packed record.
    offset: usize,
}

impl Field {
    /// Bytes of the field in one record (checked not to overflow when the header was read).
    fn bytes(&self) -> usize {
        self.scalar.size() * self.count
    }
}

/// Which fields (indices into the header's fields) hold what the cloud keeps.
#[derive(Debug, Clone, Copy)]
struct Roles {
    xyz: [usize; 3],
    intensity: Option<usize>,
    normals: Option<[usize; 3]>,
    rgb: Option<usize>,
}

impl Roles {
    /// Finds the fields by name (the first of equal names); `Err` names a missing
    /// coordinate.
    fn find(fields: &[Field]) -> Result<Roles, &'static str> {
        let index = |name: &str| fields.iter().position(|f| f.name == name);
        let xyz = [
            index("x").ok_or("x")?,
            index("y").ok_or("y")?,
            index("z").ok_or("z")?,
        ];
        let normals = match (index("normal_x"), index("normal_y"), index("normal_z")) {
            (Some(a), Some(b), Some(c)) => Some([a, b, c]),
            _ => None,
        };
        let rgb = index("rgb")
            .or_else(|| index("rgba"))
            .filter(|&i| fields[i].scalar.size() == 4);
        Ok(Roles {
            xyz,
            intensity: index("intensity"),
            normals,
            rgb,
        })
    }
}

/// A validated header.
#[derive(Debug, Clone)]
struct Header {
    fields: Vec<Field>,
    roles: Roles,
    width: u32,
    height: u32,
    points: u64,
    viewpoint: [f64; 7],
    encoding: DataEncoding,
    /// Bytes of one packed record.
    record_size: usize,
    /// Line number of the `DATA` line.
    data_line: usize,
    /// Byte offset of the point data in the stream.
    data_offset: u64,
}

/// A header value with the line it came from.
#[derive(Debug, Clone)]
struct Entry<T> {
    line: usize,
    value: T,
}

/// The header keys seen so far, parsed but not yet checked against each other.
#[derive(Debug, Default)]
struct RawHeader {
    version: Option<Entry<()>>,
    fields: Option<Entry<Vec<String>>>,
    sizes: Option<Entry<Vec<usize>>>,
    types: Option<Entry<Vec<u8>>>,
    counts: Option<Entry<Vec<usize>>>,
    width: Option<Entry<u32>>,
    height: Option<Entry<u32>>,
    viewpoint: Option<Entry<[f64; 7]>>,
    points: Option<Entry<u64>>,
}

/// Reads header lines up to and including `DATA`, leaving the reader at the first data byte.
fn read_header<R: BufRead>(reader: &mut R) -> Result<Header, ParseError> {
    let mut raw = RawHeader::default();
    let mut buf = Vec::with_capacity(256);
    let mut line_no = 0usize;
    let mut offset = 0u64;
    loop {
        buf.clear();
        let n = reader
            .by_ref()
            .take(MAX_HEADER_LINE)
            .read_until(b'\n', &mut buf)?;
        if n == 0 {
            return Err(if line_no == 0 {
                ParseError::Empty
            } else {
                ParseError::Truncated(format!(
                    "the header ends after {line_no} lines without a DATA line"
                ))
            });
        }
        line_no += 1;
        offset += n as u64;
        if n as u64 == MAX_HEADER_LINE && !buf.ends_with(b"\n") {
            return Err(ParseError::line(
                line_no,
                "header line longer than 1 MiB: not a PCD header",
            ));
        }
        let line = std::str::from_utf8(&buf).map_err(|_| {
            ParseError::line(line_no, "header line is not text (invalid UTF-8 bytes)")
        })?;
        let mut tokens = line.split_ascii_whitespace();
        let Some(key) = tokens.next() else { continue };
        if key.starts_with('#') {
            continue;
        }
        let values: Vec<&str> = tokens.collect();
        if let Some(encoding) = raw.add(line_no, key, &values)? {
            return raw.finish(line_no, offset, encoding);
        }
    }
}

impl RawHeader {
    /// Takes one header line; returns the encoding when the line is `DATA`.
    fn add(
        &mut self,
        line: usize,
        key: &str,
        values: &[&str],
    ) -> Result<Option<DataEncoding>, ParseError> {
        let upper = key.to_ascii_uppercase();
        match upper.as_str() {
            "VERSION" => set(
                &mut self.version,
                line,
                "VERSION",
                parse_version(line, values)?,
            ),
            "FIELDS" | "COLUMNS" => set(
                &mut self.fields,
                line,
                "FIELDS",
                parse_fields(line, values)?,
            ),
            "SIZE" => set(&mut self.sizes, line, "SIZE", parse_sizes(line, values)?),
            "TYPE" => set(&mut self.types, line, "TYPE", parse_types(line, values)?),
            "COUNT" => set(&mut self.counts, line, "COUNT", parse_counts(line, values)?),
            "WIDTH" => set(
                &mut self.width,
                line,
                "WIDTH",
                parse_one(
                    line,
                    "WIDTH",
                    values,
                    "a whole number of points up to 4294967295",
                )?,
            ),
            "HEIGHT" => set(
                &mut self.height,
                line,
                "HEIGHT",
                parse_one(
                    line,
                    "HEIGHT",
                    values,
                    "a whole number of rows up to 4294967295",
                )?,
            ),
            "POINTS" => set(
                &mut self.points,
                line,
                "POINTS",
                parse_one(line, "POINTS", values, "a whole number of points")?,
            ),
            "VIEWPOINT" => set(
                &mut self.viewpoint,
                line,
                "VIEWPOINT",
                parse_viewpoint(line, values)?,
            ),
            "DATA" => return parse_data(line, values).map(Some),
            _ => {
                return Err(ParseError::line(
                    line,
                    format!("unknown header key '{}'; expected {KEYS}", shown(key)),
                ))
            }
        }?;
        Ok(None)
    }

    /// Checks the keys against each other once `DATA` has been seen.
    fn finish(
        self,
        data_line: usize,
        data_offset: u64,
        encoding: DataEncoding,
    ) -> Result<Header, ParseError> {
        let _ = self.version;
        let Some(names) = self.fields else {
            return Err(ParseError::line(
                data_line,
                "FIELDS: missing; the header must name the fields before DATA",
            ));
        };
        let n = names.value.len();
        let binary = encoding != DataEncoding::Ascii;
        let sizes = per_field(self.sizes, "SIZE", n, binary, 4)?;
        let types = per_field(self.types, "TYPE", n, binary, b'F')?;
        let counts = per_field(self.counts, "COUNT", n, false, 1)?;
        let mut fields = Vec::with_capacity(n);
        let mut record_size = 0usize;
        for (i, name) in names.value.into_iter().enumerate() {
            let scalar = Scalar::new(types.value[i], sizes.value[i]).ok_or_else(|| {
                ParseError::line(
                    types.line,
                    format!(
                        "TYPE: F (floating point) needs SIZE 4 or 8, but field '{}' has SIZE {}",
                        shown(&name),
                        sizes.value[i]
                    ),
                )
            })?;
            let count = counts.value[i];
            let bytes = scalar.size().checked_mul(count);
            let offset = record_size;
            record_size = bytes
                .and_then(|b| record_size.checked_add(b))
                .ok_or_else(|| ParseError::line(counts.line, "COUNT: the record size overflows"))?;
            fields.push(Field {
                name,
                scalar,
                count,
                offset,
            });
        }
        let roles = Roles::find(&fields).map_err(|missing| {
            ParseError::line(
                names.line,
                format!("FIELDS: expected the fields x, y and z, '{missing}' is missing"),
            )
        })?;
        let (width, height, points) = dimensions(self.width, self.height, self.points, data_line)?;
        Ok(Header {
            fields,
            roles,
            width,
            height,
            points,
            viewpoint: self
                .viewpoint
                .map_or([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], |e| e.value),
            encoding,
            record_size,
            data_line,
            data_offset,
        })
    }
}

/// Stores a header value, refusing a key given twice.
fn set<T>(slot: &mut Option<Entry<T>>, line: usize, key: &str, value: T) -> Result<(), ParseError> {
    if let Some(previous) = slot {
        return Err(ParseError::line(
            line,
            format!("{key}: given twice (first on line {})", previous.line),
        ));
    }
    *slot = Some(Entry { line, value });
    Ok(())
}

/// A per-field list (`SIZE`, `TYPE`, `COUNT`) checked to have one entry per field, or the
/// default for every field when absent and not `required`.
fn per_field<T: Clone>(
    entry: Option<Entry<Vec<T>>>,
    key: &str,
    n: usize,
    required: bool,
    default: T,
) -> Result<Entry<Vec<T>>, ParseError> {
    match entry {
        Some(e) if e.value.len() != n => Err(ParseError::line(
            e.line,
            format!(
                "{key}: expected {n} values (one per field in FIELDS), found {}",
                e.value.len()
            ),
        )),
        Some(e) => Ok(e),
        None if required => Err(ParseError::Malformed(format!(
            "{key}: missing; binary data needs the {} of every field",
            key.to_ascii_lowercase()
        ))),
        None => Ok(Entry {
            line: 0,
            value: vec![default; n],
        }),
    }
}

/// `WIDTH`, `HEIGHT` and `POINTS` with their defaults, checked to agree.
fn dimensions(
    width: Option<Entry<u32>>,
    height: Option<Entry<u32>>,
    points: Option<Entry<u64>>,
    data_line: usize,
) -> Result<(u32, u32, u64), ParseError> {
    let height = height.map_or(1, |e| e.value);
    let width = match (&width, &points) {
        (Some(w), _) => w.value,
        (None, Some(p)) if height == 1 => u32::try_from(p.value).map_err(|_| {
            ParseError::line(
                p.line,
                "POINTS: more than 4294967295 points without a WIDTH",
            )
        })?,
        _ => {
            return Err(ParseError::line(
                data_line,
                "WIDTH: missing; the header must give WIDTH (or POINTS) before DATA",
            ))
        }
    };
    let product = u64::from(width) * u64::from(height);
    match points {
        Some(p) if p.value != product => Err(ParseError::line(
            p.line,
            format!(
                "POINTS: {} but WIDTH × HEIGHT = {width} × {height} = {product}: the header lies \
                 about the number of points",
                p.value
            ),
        )),
        _ => Ok((width, height, product)),
    }
}

/// A token for an error message, cut short when long.
fn shown(token: &str) -> String {
    const MAX: usize = 40;
    if token.chars().count() <= MAX {
        token.to_string()
    } else {
        let mut s: String = token.chars().take(MAX).collect();
        s.push('…');
        s
    }
}

fn parse_version(line: usize, values: &[&str]) -> Result<(), ParseError> {
    match values {
        [v] if matches!(*v, "0.7" | ".7" | "0.6" | ".6" | "0.5" | ".5") => Ok(()),
        _ => Err(ParseError::line(
            line,
            format!(
                "VERSION: expected 0.7 (or the older .6 or .5), found '{}'",
                shown(&values.join(" "))
            ),
        )),
    }
}

fn parse_fields(line: usize, values: &[&str]) -> Result<Vec<String>, ParseError> {
    if values.is_empty() {
        return Err(ParseError::line(
            line,
            "FIELDS: expected at least one field name",
        ));
    }
    Ok(values.iter().map(|s| s.to_string()).collect())
}

fn parse_sizes(line: usize, values: &[&str]) -> Result<Vec<usize>, ParseError> {
    values
        .iter()
        .enumerate()
        .map(|(i, v)| match v.parse::<usize>() {
            Ok(s @ (1 | 2 | 4 | 8)) => Ok(s),
            _ => Err(ParseError::line(
                line,
                format!(
                    "SIZE: expected 1, 2, 4 or 8 (bytes per value) for field {}, found '{}'",
                    i + 1,
                    shown(v)
                ),
            )),
        })
        .collect()
}

fn parse_types(line: usize, values: &[&str]) -> Result<Vec<u8>, ParseError> {
    values
        .iter()
        .enumerate()
        .map(|(i, v)| match v.to_ascii_uppercase().as_str() {
            "I" => Ok(b'I'),
            "U" => Ok(b'U'),
            "F" => Ok(b'F'),
            _ => Err(ParseError::line(
                line,
                format!(
                    "TYPE: expected I (signed), U (unsigned) or F (floating point) for field {}, \
                     found '{}'",
                    i + 1,
                    shown(v)
                ),
            )),
        })
        .collect()
}

fn parse_counts(line: usize, values: &[&str]) -> Result<Vec<usize>, ParseError> {
    values
        .iter()
        .enumerate()
        .map(|(i, v)| match v.parse::<usize>() {
            Ok(c) if c >= 1 => Ok(c),
            _ => Err(ParseError::line(
                line,
                format!(
                    "COUNT: expected a whole number >= 1 for field {}, found '{}'",
                    i + 1,
                    shown(v)
                ),
            )),
        })
        .collect()
}

fn parse_one<T: FromStr>(
    line: usize,
    key: &str,
    values: &[&str],
    what: &str,
) -> Result<T, ParseError> {
    match values {
        [v] => v.parse().map_err(|_| {
            ParseError::line(
                line,
                format!("{key}: expected {what}, found '{}'", shown(v)),
            )
        }),
        _ => Err(ParseError::line(
            line,
            format!("{key}: expected one value ({what}), found {}", values.len()),
        )),
    }
}

fn parse_viewpoint(line: usize, values: &[&str]) -> Result<[f64; 7], ParseError> {
    let err = || {
        ParseError::line(
            line,
            format!(
                "VIEWPOINT: expected 7 numbers (tx ty tz qw qx qy qz), found '{}'",
                shown(&values.join(" "))
            ),
        )
    };
    if values.len() != 7 {
        return Err(err());
    }
    let mut v = [0.0; 7];
    for (slot, s) in v.iter_mut().zip(values) {
        *slot = s.parse().map_err(|_| err())?;
    }
    Ok(v)
}

fn parse_data(line: usize, values: &[&str]) -> Result<DataEncoding, ParseError> {
    let found = values.join(" ");
    match found.to_ascii_lowercase().as_str() {
        "ascii" => Ok(DataEncoding::Ascii),
        "binary" => Ok(DataEncoding::Binary),
        "binary_compressed" => Ok(DataEncoding::BinaryCompressed),
        _ => Err(ParseError::line(
            line,
            format!(
                "DATA: expected ascii, binary or binary_compressed, found '{}'",
                shown(&found)
            ),
        )),
    }
}

/// The vectors of the cloud being read.
struct CloudBuilder {
    points: Vec<Point3<f32>>,
    intensity: Option<Vec<f32>>,
    normals: Option<Vec<Vector3<f32>>>,
    colors: Option<Vec<[u8; 3]>>,
}

impl CloudBuilder {
    fn new(roles: &Roles, capacity: u64) -> Self {
        let cap = usize::try_from(capacity).unwrap_or(0);
        CloudBuilder {
            points: Vec::with_capacity(cap),
            intensity: roles.intensity.map(|_| Vec::with_capacity(cap)),
            normals: roles.normals.map(|_| Vec::with_capacity(cap)),
            colors: roles.rgb.map(|_| Vec::with_capacity(cap)),
        }
    }

    /// Appends a point; the attributes the cloud does not carry are ignored.
    #[inline]
    fn push(&mut self, p: Point3<f32>, intensity: f32, normal: Vector3<f32>, rgb: u32) {
        self.points.push(p);
        if let Some(v) = &mut self.intensity {
            v.push(intensity);
        }
        if let Some(v) = &mut self.normals {
            v.push(normal);
        }
        if let Some(v) = &mut self.colors {
            v.push(unpack_rgb(rgb));
        }
    }

    fn finish(self, origin: Point3<f64>) -> Result<PointCloud, ParseError> {
        let mut cloud = PointCloud::from_points(self.points).with_origin(origin);
        let attach = |e: crate::Error| ParseError::Malformed(e.to_string());
        cloud.set_intensity(self.intensity).map_err(attach)?;
        cloud.set_normals(self.normals).map_err(attach)?;
        cloud.set_colors(self.colors).map_err(attach)?;
        Ok(cloud)
    }
}

/// `0x00RRGGBB` to `[r, g, b]`.
#[inline]
fn unpack_rgb(v: u32) -> [u8; 3] {
    [(v >> 16) as u8, (v >> 8) as u8, v as u8]
}

/// `[r, g, b]` to `0x00RRGGBB`.
#[inline]
fn pack_rgb(c: [u8; 3]) -> u32 {
    u32::from(c[0]) << 16 | u32::from(c[1]) << 8 | u32::from(c[2])
}

/// Where the first value of a field of point `i` lies in a buffer: `base + i * stride`.
#[derive(Debug, Clone, Copy)]
struct Accessor {
    base: usize,
    stride: usize,
    scalar: Scalar,
}

impl Accessor {
    #[inline]
    fn value(self, buf: &[u8], i: usize) -> f64 {
        self.scalar.read(buf, self.base + i * self.stride)
    }

    /// The 4 bytes of the value as a little-endian `u32` (for `rgb`).
    #[inline]
    fn bits(self, buf: &[u8], i: usize) -> u32 {
        u32::from_le_bytes(bytes_at(buf, self.base + i * self.stride))
    }
}

/// The accessors of the fields the cloud keeps.
#[derive(Debug, Clone, Copy)]
struct Plan {
    xyz: [Accessor; 3],
    intensity: Option<Accessor>,
    normals: Option<[Accessor; 3]>,
    rgb: Option<Accessor>,
}

impl Plan {
    fn new(roles: &Roles, accessor: impl Fn(usize) -> Accessor) -> Plan {
        Plan {
            xyz: roles.xyz.map(&accessor),
            intensity: roles.intensity.map(&accessor),
            normals: roles.normals.map(|n| n.map(&accessor)),
            rgb: roles.rgb.map(&accessor),
        }
    }

    /// Packed records (`DATA binary`): point `i` is the `i`-th record of the buffer.
    fn packed(header: &Header) -> Plan {
        Plan::new(&header.roles, |f| Accessor {
            base: header.fields[f].offset,
            stride: header.record_size,
            scalar: header.fields[f].scalar,
        })
    }

    /// Structure of arrays (`DATA binary_compressed`) of `points` points: field `f` starts at
    /// `points × offset(f)`.
    fn columns(header: &Header, points: usize) -> Plan {
        Plan::new(&header.roles, |f| Accessor {
            base: points * header.fields[f].offset,
            stride: header.fields[f].bytes(),
            scalar: header.fields[f].scalar,
        })
    }

    /// Decodes points `0..n` of `buf`, keeping the finite ones.
    fn decode(&self, buf: &[u8], n: usize, out: &mut CloudBuilder, report: &mut ReadReport) {
        let numeric = self
            .xyz
            .iter()
            .chain(&self.intensity)
            .chain(self.normals.iter().flatten());
        if numeric.into_iter().all(|a| a.scalar == Scalar::F32) {
            // The usual case, compiled without the per-value type dispatch.
            self.decode_as::<true>(buf, n, out, report);
        } else {
            self.decode_as::<false>(buf, n, out, report);
        }
    }

    /// [`Plan::decode`]; with `ALL_F32` every numeric field is known to be `F 4`.
    #[inline(always)]
    fn decode_as<const ALL_F32: bool>(
        &self,
        buf: &[u8],
        n: usize,
        out: &mut CloudBuilder,
        report: &mut ReadReport,
    ) {
        let value = |a: Accessor, i: usize| {
            if ALL_F32 {
                f64::from(f32::from_le_bytes(bytes_at(buf, a.base + i * a.stride)))
            } else {
                a.value(buf, i)
            }
        };
        for i in 0..n {
            let xyz = self.xyz.map(|a| value(a, i));
            let Some(p) = finite_point(xyz, report) else {
                continue;
            };
            let intensity = self.intensity.map_or(0.0, |a| value(a, i) as f32);
            let normal = self.normals.map_or_else(Vector3::zeros, |n| {
                Vector3::new(
                    value(n[0], i) as f32,
                    value(n[1], i) as f32,
                    value(n[2], i) as f32,
                )
            });
            let rgb = self.rgb.map_or(0, |a| a.bits(buf, i));
            out.push(p, intensity, normal, rgb);
        }
    }
}

/// Reads up to `want` bytes (fewer only at the end of the stream) into `buf`. The buffer
/// grows as bytes arrive, so a size claimed by a header allocates nothing that is not there.
fn fill_up_to<R: BufRead>(reader: &mut R, buf: &mut Vec<u8>, want: usize) -> io::Result<()> {
    buf.clear();
    while buf.len() < want {
        let available = match reader.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if available.is_empty() {
            break;
        }
        let n = available.len().min(want - buf.len());
        buf.extend_from_slice(&available[..n]);
        reader.consume(n);
    }
    Ok(())
}

/// `POINTS × record size` in bytes, or an error when it overflows.
fn data_bytes(header: &Header) -> Result<u64, ParseError> {
    header
        .points
        .checked_mul(header.record_size as u64)
        .ok_or_else(|| {
            ParseError::Malformed(format!(
                "POINTS × record size = {} × {} bytes overflows",
                header.points, header.record_size
            ))
        })
}

/// `DATA binary`: packed records, read and decoded a chunk at a time.
fn read_binary<R: BufRead>(
    reader: &mut R,
    header: &Header,
    out: &mut CloudBuilder,
    report: &mut ReadReport,
) -> Result<(), ParseError> {
    let total = data_bytes(header)?;
    let record = header.record_size;
    let per_chunk = (CHUNK_BYTES / record).max(1);
    let plan = Plan::packed(header);
    let mut buf = Vec::new();
    let mut remaining = header.points;
    let mut done = 0u64;
    while remaining > 0 {
        // Both fit: n <= per_chunk, and n * record <= max(CHUNK_BYTES, record).
        let n = remaining.min(per_chunk as u64) as usize;
        let want = n * record;
        fill_up_to(reader, &mut buf, want)?;
        if buf.len() < want {
            return Err(ParseError::Truncated(format!(
                "binary data: expected {total} bytes ({} points × {record} bytes) after the \
                 header, found {}",
                header.points,
                done + buf.len() as u64
            )));
        }
        plan.decode(&buf, n, out, report);
        done += want as u64;
        remaining -= n as u64;
    }
    Ok(())
}

/// `DATA binary_compressed`: two sizes and an LZF block of the fields as columns.
fn read_compressed<R: BufRead>(
    reader: &mut R,
    header: &Header,
    out: &mut CloudBuilder,
    report: &mut ReadReport,
) -> Result<(), ParseError> {
    let mut buf = Vec::new();
    fill_up_to(reader, &mut buf, 8)?;
    if buf.len() < 8 {
        return Err(ParseError::Truncated(format!(
            "binary_compressed: expected the 8-byte block sizes after the header, found {} bytes",
            buf.len()
        )));
    }
    let compressed = u32::from_le_bytes(bytes_at(&buf, 0));
    let uncompressed = u32::from_le_bytes(bytes_at(&buf, 4));
    let expected = data_bytes(header)?;
    if u64::from(uncompressed) != expected {
        return Err(ParseError::at(
            Location::Byte(header.data_offset + 4),
            format!(
                "binary_compressed: the block holds {uncompressed} bytes uncompressed, but \
                 POINTS × record size = {} × {} = {expected}",
                header.points, header.record_size
            ),
        ));
    }
    fill_up_to(reader, &mut buf, compressed as usize)?;
    if buf.len() < compressed as usize {
        return Err(ParseError::Truncated(format!(
            "binary_compressed: expected an LZF block of {compressed} bytes, found {}",
            buf.len()
        )));
    }
    let data = lzf::decompress(&buf, uncompressed as usize).map_err(|e| {
        ParseError::at(
            Location::Byte(header.data_offset + 8),
            format!("binary_compressed: {e}"),
        )
    })?;
    // `points <= uncompressed` (records are at least 3 bytes), so it fits a usize.
    let points = header.points as usize;
    Plan::columns(header, points).decode(&data, points, out, report);
    Ok(())
}

/// What an ascii token feeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Coord(usize),
    Intensity,
    Normal(usize),
    Rgb,
    Skip,
}

/// How to read one ascii token.
#[derive(Debug, Clone, Copy)]
struct TokenSpec {
    role: Role,
    scalar: Scalar,
    field: usize,
}

/// The values of one ascii line.
#[derive(Debug, Clone, Copy, Default)]
struct AsciiPoint {
    xyz: [f64; 3],
    intensity: f32,
    normal: [f32; 3],
    rgb: u32,
}

impl AsciiPoint {
    /// Parses a token into its slot; `None` if it is not a number of the field's type.
    #[inline]
    fn take(&mut self, spec: TokenSpec, token: &[u8]) -> Option<()> {
        match spec.role {
            Role::Rgb => self.rgb = parse_rgb(token, spec.scalar)?,
            role => {
                let v = spec.scalar.parse(token)?;
                match role {
                    Role::Coord(k) => self.xyz[k] = v,
                    Role::Intensity => self.intensity = v as f32,
                    Role::Normal(k) => self.normal[k] = v as f32,
                    Role::Rgb | Role::Skip => {}
                }
            }
        }
        Some(())
    }
}

/// An ascii colour: the packed integer (what PCL writes, also for `TYPE F`), or for `F`
/// fields the float whose bits hold it.
fn parse_rgb(token: &[u8], scalar: Scalar) -> Option<u32> {
    let s = std::str::from_utf8(token).ok()?;
    if let Ok(v) = s.parse::<i64>() {
        // I 4 colours are negative when the alpha byte is set: keep the low 32 bits.
        return Some(v as u32);
    }
    match scalar {
        Scalar::F32 => s.parse::<f32>().ok().map(f32::to_bits),
        _ => None,
    }
}

/// The token specs of an ascii line: one per value (fields with `COUNT` n give n tokens).
fn token_specs(header: &Header) -> Vec<TokenSpec> {
    let roles = &header.roles;
    let role_of = |f: usize| {
        if let Some(k) = roles.xyz.iter().position(|&i| i == f) {
            Role::Coord(k)
        } else if roles.intensity == Some(f) {
            Role::Intensity
        } else if let Some(k) = roles.normals.and_then(|n| n.iter().position(|&i| i == f)) {
            Role::Normal(k)
        } else if roles.rgb == Some(f) {
            Role::Rgb
        } else {
            Role::Skip
        }
    };
    let mut specs = Vec::new();
    for (f, field) in header.fields.iter().enumerate() {
        for k in 0..field.count {
            specs.push(TokenSpec {
                role: if k == 0 { role_of(f) } else { Role::Skip },
                scalar: field.scalar,
                field: f,
            });
        }
    }
    specs
}

/// `DATA ascii`: one point per line.
fn read_ascii<R: BufRead>(
    reader: &mut R,
    header: &Header,
    out: &mut CloudBuilder,
    report: &mut ReadReport,
) -> Result<(), ParseError> {
    let specs = token_specs(header);
    let mut line = Vec::with_capacity(256);
    let mut line_no = header.data_line;
    let mut found = 0u64;
    while found < header.points {
        line.clear();
        if reader.read_until(b'\n', &mut line)? == 0 {
            return Err(ParseError::Truncated(format!(
                "ascii data: the header announces {} points, found {found}",
                header.points
            )));
        }
        line_no += 1;
        let mut values = AsciiPoint::default();
        let mut tokens = 0usize;
        for token in line
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty())
        {
            if let Some(&spec) = specs.get(tokens) {
                values.take(spec, token).ok_or_else(|| {
                    ParseError::line(
                        line_no,
                        format!(
                            "field '{}': expected a number, found '{}'",
                            header.fields[spec.field].name,
                            shown(&String::from_utf8_lossy(token))
                        ),
                    )
                })?;
            }
            tokens += 1;
        }
        if tokens == 0 {
            continue;
        }
        if tokens != specs.len() {
            return Err(ParseError::line(
                line_no,
                format!(
                    "expected {} values (one per field value of FIELDS), found {tokens}",
                    specs.len()
                ),
            ));
        }
        found += 1;
        if let Some(p) = finite_point(values.xyz, report) {
            let [nx, ny, nz] = values.normal;
            out.push(p, values.intensity, Vector3::new(nx, ny, nz), values.rgb);
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------------

/// Writes a cloud as PCD v0.7 in the given encoding.
///
/// Fields: `x y z`, then `intensity`, `normal_x normal_y normal_z` and `rgb` where the cloud
/// has them. Every encoding reads back bit for bit with [`read`].
///
/// ```
/// use olmap::cloud::PointCloud;
/// use olmap::io::{pcd, PcdEncoding};
/// use nalgebra::Point3;
/// let cloud = PointCloud::from_points(vec![Point3::new(0.1, 0.2, 0.3)]);
/// let mut bytes = Vec::new();
/// pcd::write(&mut bytes, &cloud, PcdEncoding::Ascii).unwrap();
/// assert!(bytes.ends_with(b"DATA ascii\n0.1 0.2 0.3\n"));
/// assert_eq!(pcd::read(&bytes[..]).unwrap().cloud, cloud);
/// ```
pub fn write<W: Write>(mut w: W, cloud: &PointCloud, encoding: PcdEncoding) -> io::Result<()> {
    let columns = columns(cloud);
    write_header(&mut w, cloud, &columns, encoding)?;
    match encoding {
        PcdEncoding::Ascii => write_ascii(&mut w, cloud.len(), &columns)?,
        PcdEncoding::Binary => write_binary(&mut w, cloud.len(), &columns)?,
        PcdEncoding::BinaryCompressed => write_compressed(&mut w, cloud.len(), &columns)?,
    }
    w.flush()
}

/// One written field: every value is 4 bytes.
#[derive(Debug, Clone, Copy)]
enum Column<'a> {
    Coord(&'a [Point3<f32>], usize),
    Intensity(&'a [f32]),
    Normal(&'a [Vector3<f32>], usize),
    Rgb(&'a [[u8; 3]]),
}

impl Column<'_> {
    fn name(self) -> &'static str {
        match self {
            Column::Coord(_, k) => ["x", "y", "z"][k],
            Column::Intensity(_) => "intensity",
            Column::Normal(_, k) => ["normal_x", "normal_y", "normal_z"][k],
            Column::Rgb(_) => "rgb",
        }
    }

    fn is_float(self) -> bool {
        !matches!(self, Column::Rgb(_))
    }

    /// The 4 bytes of point `i` as a `u32` (float bits, or the packed colour).
    #[inline]
    fn word(self, i: usize) -> u32 {
        match self {
            Column::Coord(p, k) => p[i][k].to_bits(),
            Column::Intensity(v) => v[i].to_bits(),
            Column::Normal(n, k) => n[i][k].to_bits(),
            Column::Rgb(c) => pack_rgb(c[i]),
        }
    }
}

/// The columns written for a cloud, in file order.
fn columns(cloud: &PointCloud) -> Vec<Column<'_>> {
    let mut cols: Vec<Column> = (0..3).map(|k| Column::Coord(cloud.points(), k)).collect();
    if let Some(v) = cloud.intensity() {
        cols.push(Column::Intensity(v));
    }
    if let Some(n) = cloud.normals() {
        cols.extend((0..3).map(|k| Column::Normal(n, k)));
    }
    if let Some(c) = cloud.colors() {
        cols.push(Column::Rgb(c));
    }
    cols
}

fn write_header<W: Write>(
    w: &mut W,
    cloud: &PointCloud,
    columns: &[Column],
    encoding: PcdEncoding,
) -> io::Result<()> {
    let n = u32::try_from(cloud.len()).map_err(|_| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            "PCD holds at most 4294967295 points",
        )
    })?;
    let list = |f: &dyn Fn(Column) -> &'static str| {
        columns.iter().map(|&c| f(c)).collect::<Vec<_>>().join(" ")
    };
    let o = cloud.origin();
    let data = match encoding {
        PcdEncoding::Ascii => "ascii",
        PcdEncoding::Binary => "binary",
        PcdEncoding::BinaryCompressed => "binary_compressed",
    };
    write!(
        w,
        "# .PCD v0.7 - Point Cloud Data file format\n\
         VERSION 0.7\n\
         FIELDS {}\n\
         SIZE {}\n\
         TYPE {}\n\
         COUNT {}\n\
         WIDTH {n}\n\
         HEIGHT 1\n\
         VIEWPOINT {} {} {} 1 0 0 0\n\
         POINTS {n}\n\
         DATA {data}\n",
        list(&|c| c.name()),
        list(&|_| "4"),
        list(&|c| if c.is_float() { "F" } else { "U" }),
        list(&|_| "1"),
        o.x,
        o.y,
        o.z,
    )
}

fn write_ascii<W: Write>(w: &mut W, n: usize, columns: &[Column]) -> io::Result<()> {
    use std::fmt::Write as _;
    let mut text = String::with_capacity(CHUNK_BYTES + 1024);
    for i in 0..n {
        for (k, col) in columns.iter().enumerate() {
            if k > 0 {
                text.push(' ');
            }
            let word = col.word(i);
            if col.is_float() {
                let _ = write!(text, "{}", f32::from_bits(word));
            } else {
                let _ = write!(text, "{word}");
            }
        }
        text.push('\n');
        if text.len() >= CHUNK_BYTES {
            w.write_all(text.as_bytes())?;
            text.clear();
        }
    }
    w.write_all(text.as_bytes())
}

fn write_binary<W: Write>(w: &mut W, n: usize, columns: &[Column]) -> io::Result<()> {
    let record = 4 * columns.len();
    let per_chunk = (CHUNK_BYTES / record).max(1);
    let mut buf = Vec::with_capacity(per_chunk * record);
    for start in (0..n).step_by(per_chunk) {
        buf.clear();
        for i in start..(start + per_chunk).min(n) {
            for col in columns {
                buf.extend_from_slice(&col.word(i).to_le_bytes());
            }
        }
        w.write_all(&buf)?;
    }
    Ok(())
}

fn write_compressed<W: Write>(w: &mut W, n: usize, columns: &[Column]) -> io::Result<()> {
    let mut soa = Vec::with_capacity(n * 4 * columns.len());
    for col in columns {
        for i in 0..n {
            soa.extend_from_slice(&col.word(i).to_le_bytes());
        }
    }
    let packed = lzf::compress(&soa);
    let too_big = |_| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            "binary_compressed PCD data is limited to 4 GiB; use binary",
        )
    };
    let uncompressed = u32::try_from(soa.len()).map_err(too_big)?;
    let compressed = u32::try_from(packed.len()).map_err(too_big)?;
    w.write_all(&compressed.to_le_bytes())?;
    w.write_all(&uncompressed.to_le_bytes())?;
    w.write_all(&packed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const ALL: [PcdEncoding; 3] = [
        PcdEncoding::Ascii,
        PcdEncoding::Binary,
        PcdEncoding::BinaryCompressed,
    ];

    /// A cloud with awkward values (long decimal forms, tiny, huge, negative zero).
    fn sample(n: usize, intensity: bool, normals: bool, colors: bool) -> PointCloud {
        let f = |i: usize, k: usize| -> f32 {
            let t = (i * 3 + k) as f32;
            match (i + k) % 5 {
                0 => t / 3.0,
                1 => -t * 0.1 - 1e-7,
                2 => 1e20 / (t + 1.0),
                3 => (t * 0.37).sin() * 1e-30,
                _ => -0.0,
            }
        };
        let points = (0..n)
            .map(|i| Point3::new(f(i, 0), f(i, 1), f(i, 2)))
            .collect();
        let mut cloud = PointCloud::from_points(points).with_origin(Point3::new(0.1, -2.5, 1e-3));
        if intensity {
            let v = (0..n).map(|i| f(i, 7) * 3.0).collect();
            cloud.set_intensity(Some(v)).unwrap();
        }
        if normals {
            let v = (0..n)
                .map(|i| Vector3::new(f(i, 3), f(i, 4), f(i, 5)))
                .collect();
            cloud.set_normals(Some(v)).unwrap();
        }
        if colors {
            let v = (0..n)
                .map(|i| [i as u8, (i * 7) as u8, 255 - (i % 256) as u8])
                .collect();
            cloud.set_colors(Some(v)).unwrap();
        }
        cloud
    }

    fn encode(cloud: &PointCloud, encoding: PcdEncoding) -> Vec<u8> {
        let mut bytes = Vec::new();
        write(&mut bytes, cloud, encoding).unwrap();
        bytes
    }

    /// Bit patterns, so that -0.0 and 0.0 differ.
    fn bits(cloud: &PointCloud) -> Vec<u32> {
        let mut v: Vec<u32> = cloud
            .points()
            .iter()
            .flat_map(|p| p.coords.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
            .collect();
        if let Some(i) = cloud.intensity() {
            v.extend(i.iter().map(|x| x.to_bits()));
        }
        if let Some(n) = cloud.normals() {
            v.extend(
                n.iter()
                    .flat_map(|n| n.iter().map(|x| x.to_bits()).collect::<Vec<_>>()),
            );
        }
        v
    }

    #[test]
    fn round_trips_every_encoding_and_attribute_set() {
        for encoding in ALL {
            for mask in 0..8 {
                for n in [0, 1, 257] {
                    let cloud = sample(n, mask & 1 != 0, mask & 2 != 0, mask & 4 != 0);
                    let bytes = encode(&cloud, encoding);
                    let loaded = read(&bytes[..])
                        .unwrap_or_else(|e| panic!("{encoding:?} mask {mask} n {n}: {e}"));
                    assert_eq!(loaded.cloud, cloud, "{encoding:?} mask {mask} n {n}");
                    assert_eq!(bits(&loaded.cloud), bits(&cloud));
                    let r = &loaded.report;
                    assert_eq!(r.records, n as u64);
                    assert_eq!(r.dropped_non_finite, 0);
                    assert_eq!(r.organized, None);
                    assert_eq!(r.format, CloudFormat::Pcd);
                    assert_eq!(r.fields[..3], ["x", "y", "z"]);
                }
            }
        }
    }

    #[test]
    fn writes_the_documented_header() {
        let cloud = sample(2, true, true, true);
        let bytes = encode(&cloud, PcdEncoding::Binary);
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.starts_with(
            "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n\
             FIELDS x y z intensity normal_x normal_y normal_z rgb\n\
             SIZE 4 4 4 4 4 4 4 4\nTYPE F F F F F F F U\nCOUNT 1 1 1 1 1 1 1 1\n\
             WIDTH 2\nHEIGHT 1\nVIEWPOINT 0.1 -2.5 0.001 1 0 0 0\nPOINTS 2\nDATA binary\n"
        ));
        let loaded = read(&bytes[..]).unwrap();
        assert_eq!(loaded.report.encoding, "binary");
        assert_eq!(
            loaded.report.fields,
            [
                "x",
                "y",
                "z",
                "intensity",
                "normal_x",
                "normal_y",
                "normal_z",
                "rgb"
            ]
        );
        assert_eq!(loaded.cloud.origin(), Point3::new(0.1, -2.5, 1e-3));
    }

    #[test]
    fn reads_an_organised_ascii_cloud_with_nans() {
        let text = "# .PCD v0.7 - Point Cloud Data file format\n\
            VERSION .7\n\
            FIELDS x y z rgb\n\
            SIZE 4 4 4 4\n\
            TYPE F F F F\n\
            COUNT 1 1 1 1\n\
            WIDTH 3\n\
            HEIGHT 2\n\
            VIEWPOINT 1 2 3 1 0 0 0\n\
            POINTS 6\n\
            DATA ascii\n\
            1 2 3 16711680\n\
            nan nan nan 0\n\
            \n\
            4.5 -5 6e2 4.808e+06\n\
            NaN 1 1 0\n\
            1 inf 1 0\r\n\
            7 8 9 255\n\
            this line is past the announced points and ignored\n";
        let loaded = read(text.as_bytes()).unwrap();
        let r = &loaded.report;
        assert_eq!(r.encoding, "ascii");
        assert_eq!(r.records, 6);
        assert_eq!(r.organized, Some((3, 2)));
        assert_eq!(r.dropped_non_finite, 3);
        assert_eq!(r.fields, ["x", "y", "z", "rgb"]);
        let c = &loaded.cloud;
        assert_eq!(
            c.points(),
            [
                Point3::new(1.0, 2.0, 3.0),
                Point3::new(4.5, -5.0, 600.0),
                Point3::new(7.0, 8.0, 9.0)
            ]
        );
        let float_rgb = unpack_rgb(4.808e+06f32.to_bits());
        assert_eq!(c.colors().unwrap(), [[255, 0, 0], float_rgb, [0, 0, 255]]);
        assert_eq!(c.origin(), Point3::new(1.0, 2.0, 3.0));
        assert!(c.intensity().is_none() && c.normals().is_none());
    }

    #[test]
    fn accepts_old_and_minimal_headers() {
        // No VERSION, SIZE, TYPE, COUNT, WIDTH, HEIGHT or VIEWPOINT; COLUMNS for FIELDS.
        let loaded =
            read(&b"COLUMNS x y z intensity\nPOINTS 2\nDATA ascii\n1 2 3 4\n5 6 7 8\n"[..])
                .unwrap();
        assert_eq!(loaded.cloud.len(), 2);
        assert_eq!(loaded.cloud.intensity().unwrap(), [4.0, 8.0]);
        assert_eq!(loaded.cloud.origin(), Point3::origin());
        let loaded = read(&b"version 0.6\nfields x y z\nwidth 1\ndata ascii\n1 2 3\n"[..]).unwrap();
        assert_eq!(loaded.cloud.len(), 1);
    }

    /// Little-endian bytes of one record of the mixed-type layout below.
    struct Mixed {
        x: f64,
        y: i16,
        z: u8,
        intensity: u16,
        rgb: f32,
        normal: [f32; 3],
        curvature: f32,
        fpfh: [f32; 33],
        label: i32,
    }

    fn mixed_header(n: usize, data: &str) -> String {
        format!(
            "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n\
             FIELDS x y z intensity rgb normal_x normal_y normal_z curvature fpfh label\n\
             SIZE 8 2 1 2 4 4 4 4 4 4 4\nTYPE F I U U F F F F F F I\n\
             COUNT 1 1 1 1 1 1 1 1 1 33 1\nWIDTH {n}\nHEIGHT 1\n\
             VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
        )
    }

    fn mixed_points(n: usize) -> Vec<Mixed> {
        (0..n)
            .map(|i| Mixed {
                x: if i == 2 { f64::NAN } else { i as f64 + 0.25 },
                y: -(i as i16) * 300,
                z: (i * 40) as u8,
                intensity: 1000 + i as u16,
                rgb: f32::from_bits(pack_rgb([i as u8, 2, 200])),
                normal: [0.0, i as f32, -1.0],
                curvature: 0.5,
                fpfh: [i as f32 + 100.0; 33],
                label: -7,
            })
            .collect()
    }

    /// Each field of a record as bytes, in header order.
    fn mixed_fields(m: &Mixed) -> Vec<Vec<u8>> {
        let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<_>>();
        vec![
            m.x.to_le_bytes().to_vec(),
            m.y.to_le_bytes().to_vec(),
            vec![m.z],
            m.intensity.to_le_bytes().to_vec(),
            m.rgb.to_le_bytes().to_vec(),
            f32s(&m.normal[..1]),
            f32s(&m.normal[1..2]),
            f32s(&m.normal[2..]),
            f32s(&[m.curvature]),
            f32s(&m.fpfh),
            m.label.to_le_bytes().to_vec(),
        ]
    }

    fn check_mixed(loaded: &LoadedCloud, n: usize) {
        let points = mixed_points(n);
        let kept: Vec<&Mixed> = points.iter().filter(|m| m.x.is_finite()).collect();
        let c = &loaded.cloud;
        assert_eq!(c.len(), kept.len());
        assert_eq!(loaded.report.dropped_non_finite, 1);
        assert_eq!(loaded.report.records, n as u64);
        assert_eq!(loaded.report.fields.len(), 11);
        for (k, m) in kept.iter().enumerate() {
            let p = c.points()[k];
            assert_eq!(p, Point3::new(m.x as f32, f32::from(m.y), f32::from(m.z)));
            assert_eq!(c.intensity().unwrap()[k], f32::from(m.intensity));
            assert_eq!(c.normals().unwrap()[k], Vector3::from(m.normal));
            assert_eq!(c.colors().unwrap()[k], unpack_rgb(m.rgb.to_bits()));
        }
    }

    #[test]
    fn reads_binary_with_mixed_types_and_extra_fields() {
        let n = 5;
        let mut bytes = mixed_header(n, "binary").into_bytes();
        for m in mixed_points(n) {
            bytes.extend(mixed_fields(&m).concat());
        }
        check_mixed(&read(&bytes[..]).unwrap(), n);
        // Trailing bytes after the records are not looked at.
        bytes.extend_from_slice(b"trailing");
        check_mixed(&read(&bytes[..]).unwrap(), n);
    }

    #[test]
    fn reads_compressed_with_mixed_types_and_extra_fields() {
        let n = 4;
        let records: Vec<Vec<Vec<u8>>> = mixed_points(n).iter().map(mixed_fields).collect();
        let mut soa = Vec::new();
        for f in 0..11 {
            for r in &records {
                soa.extend_from_slice(&r[f]);
            }
        }
        let packed = lzf::compress(&soa);
        let mut bytes = mixed_header(n, "binary_compressed").into_bytes();
        bytes.extend((packed.len() as u32).to_le_bytes());
        bytes.extend((soa.len() as u32).to_le_bytes());
        bytes.extend(&packed);
        check_mixed(&read(&bytes[..]).unwrap(), n);
    }

    #[test]
    fn reads_ascii_with_mixed_types_and_extra_fields() {
        let n = 3;
        let mut text = mixed_header(n, "ascii");
        for m in mixed_points(n) {
            let fpfh: Vec<String> = m.fpfh.iter().map(|v| v.to_string()).collect();
            text += &format!(
                "{} {} {} {} {} {} {} {} {} {} {}\n",
                m.x,
                m.y,
                m.z,
                m.intensity,
                m.rgb.to_bits(),
                m.normal[0],
                m.normal[1],
                m.normal[2],
                m.curvature,
                fpfh.join(" "),
                m.label
            );
        }
        check_mixed(&read(text.as_bytes()).unwrap(), n);
    }

    #[test]
    fn tolerates_bytes_after_the_compressed_block() {
        let cloud = sample(100, true, false, true);
        let mut bytes = encode(&cloud, PcdEncoding::BinaryCompressed);
        bytes.extend_from_slice(&[0xde, 0xad, 0xbe, 0xef, 0, 0, 0, 1, 2, 3]);
        bytes.extend(std::iter::repeat_n(0u8, 4096));
        let loaded = read(&bytes[..]).unwrap();
        assert_eq!(loaded.cloud, cloud);
        assert_eq!(loaded.report.encoding, "binary_compressed");
    }

    #[test]
    fn reads_an_empty_compressed_cloud() {
        let text = b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nPOINTS 0\n\
                     DATA binary_compressed\n\0\0\0\0\0\0\0\0";
        let loaded = read(&text[..]).unwrap();
        assert!(loaded.cloud.is_empty());
        assert_eq!(loaded.report.records, 0);
    }

    const GOOD_HEAD: &str =
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\n";

    fn header_error(text: &str) -> (usize, String) {
        match read(text.as_bytes()) {
            Err(ParseError::Invalid {
                at: Location::Line(n),
                reason,
            }) => (n, reason),
            other => panic!("expected a line error for {text:?}, got {other:?}"),
        }
    }

    #[test]
    fn rejects_bad_headers_with_the_key_and_line() {
        let cases: [(&str, usize, &str); 14] = [
            ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 3\n", 3, "SIZE"),
            ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F Q\n", 3, "TYPE"),
            (
                "FIELDS x y z\nSIZE 4 4 2\nTYPE F F F\nWIDTH 1\nDATA binary\n",
                3,
                "TYPE",
            ),
            (
                "FIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nDATA binary\n",
                1,
                "'z' is missing",
            ),
            (
                "FIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nDATA binary\n",
                2,
                "SIZE",
            ),
            (
                "FIELDS x y z\nSIZE 4 4 4\nTYPE F F\nWIDTH 1\nDATA binary\n",
                3,
                "TYPE",
            ),
            (
                "FIELDS x y z\nCOUNT 1 1 1 1\nWIDTH 1\nDATA ascii\n",
                2,
                "COUNT",
            ),
            ("FIELDS x y z\nCOUNT 1 0 1\n", 2, "COUNT"),
            (
                "FIELDS x y z\nWIDTH 3\nHEIGHT 2\nPOINTS 5\nDATA ascii\n",
                4,
                "lies",
            ),
            ("FIELDS x y z\nWIDTH -3\n", 2, "WIDTH"),
            (
                "FIELDS x y z\nWIDTH 3\nVIEWPOINT 0 0 0 1 0 0\n",
                3,
                "VIEWPOINT",
            ),
            ("VERSION 0.8\n", 1, "VERSION"),
            ("FIELDS x y z\nWIDTH 1\nDATA zip\n", 3, "DATA"),
            ("FIELDS x y z\nFOO 1\n", 2, "FOO"),
        ];
        for (text, line, needle) in cases {
            let (n, reason) = header_error(text);
            assert_eq!(n, line, "{text:?}: {reason}");
            assert!(reason.contains(needle), "{text:?}: {reason}");
        }
        let (n, reason) = header_error("FIELDS x y z\nFIELDS x y z\n");
        assert_eq!(n, 2);
        assert!(reason.contains("twice"), "{reason}");
    }

    #[test]
    fn rejects_empty_and_header_only_input() {
        assert!(matches!(read(&b""[..]), Err(ParseError::Empty)));
        assert!(matches!(
            read(GOOD_HEAD.as_bytes()),
            Err(ParseError::Truncated(_))
        ));
        assert!(matches!(
            read(&b"# just a comment\n\n"[..]),
            Err(ParseError::Truncated(_))
        ));
        // Binary data without SIZE cannot be read.
        assert!(read(&b"FIELDS x y z\nWIDTH 1\nDATA binary\n0123456789ab"[..]).is_err());
    }

    #[test]
    fn rejects_truncated_binary_with_the_byte_counts() {
        let cloud = sample(10, false, false, false);
        let bytes = encode(&cloud, PcdEncoding::Binary);
        match read(&bytes[..bytes.len() - 5]) {
            Err(ParseError::Truncated(msg)) => {
                assert!(msg.contains("expected 120 bytes"), "{msg}");
                assert!(msg.contains("found 115"), "{msg}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn header_claiming_huge_counts_is_truncated_not_oom() {
        for data in ["binary", "ascii", "binary_compressed"] {
            let text = format!(
                "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1000000\nHEIGHT 1000000\n\
                 POINTS 1000000000000\nDATA {data}\n0123456789abcdef"
            );
            let err = read(text.as_bytes()).unwrap_err();
            assert!(
                matches!(err, ParseError::Truncated(_) | ParseError::Invalid { .. }),
                "{data}: {err:?}"
            );
        }
        // A record size that overflows.
        let text = "FIELDS x y z\nSIZE 4 4 8\nTYPE F F U\nCOUNT 1 1 2305843009213693951\n\
                    WIDTH 4294967295\nHEIGHT 4294967295\nDATA binary\n";
        assert!(read(text.as_bytes()).is_err());
        let text = "FIELDS x y z\nSIZE 4 4 8\nTYPE F F U\nCOUNT 1 1 2305843009213693950\n\
                    WIDTH 4294967295\nHEIGHT 4294967295\nDATA binary\n";
        assert!(read(text.as_bytes()).is_err());
        // A huge single record with little data.
        let text = "FIELDS x y z\nSIZE 4 4 8\nTYPE F F U\nCOUNT 1 1 200000000000\n\
                    WIDTH 1\nDATA binary\n0123";
        assert!(matches!(
            read(text.as_bytes()),
            Err(ParseError::Truncated(_))
        ));
    }

    #[test]
    fn rejects_lying_points() {
        // POINTS and WIDTH agree but promise more than the data holds.
        let cloud = sample(3, false, false, false);
        for encoding in ALL {
            let bytes = encode(&cloud, encoding);
            let text = String::from_utf8_lossy(&bytes)
                .replace("WIDTH 3", "WIDTH 4")
                .replace("POINTS 3", "POINTS 4");
            let patched: Vec<u8> = if encoding == PcdEncoding::Ascii {
                text.into_bytes()
            } else {
                let split = bytes.windows(5).position(|w| w == b"DATA ").unwrap();
                let head = String::from_utf8_lossy(&bytes[..split])
                    .replace("WIDTH 3", "WIDTH 4")
                    .replace("POINTS 3", "POINTS 4");
                [head.as_bytes(), &bytes[split..]].concat()
            };
            let err = read(&patched[..]).unwrap_err();
            match encoding {
                PcdEncoding::BinaryCompressed => assert!(
                    matches!(
                        err,
                        ParseError::Invalid {
                            at: Location::Byte(_),
                            ..
                        }
                    ),
                    "{err:?}"
                ),
                _ => assert!(matches!(err, ParseError::Truncated(_)), "{err:?}"),
            }
        }
    }

    #[test]
    fn rejects_bad_ascii_values() {
        let bad = [
            ("1 2 x\n1 2 3\n", 10),
            ("1 2 3 4\n1 2 3\n", 10),
            ("1 2 3\n1 2\n", 11),
            ("1 2 3\n1 2 0x10\n", 11),
        ];
        for (data, line) in bad {
            let text = format!("{GOOD_HEAD}DATA ascii\n{data}");
            let (n, reason) = header_error(&text);
            assert_eq!(n, line, "{data:?}: {reason}");
        }
        let text = format!("{GOOD_HEAD}DATA ascii\n1 2 3\n");
        assert!(matches!(
            read(text.as_bytes()),
            Err(ParseError::Truncated(_))
        ));
        let (_, reason) = header_error(&format!("{GOOD_HEAD}DATA ascii\n1 2 abc\n1 2 3\n"));
        assert!(
            reason.contains("field 'z'") && reason.contains("abc"),
            "{reason}"
        );
    }

    #[test]
    fn rejects_a_wrong_uncompressed_size() {
        let cloud = sample(4, false, false, false);
        let mut bytes = encode(&cloud, PcdEncoding::BinaryCompressed);
        let at = bytes
            .windows(18)
            .position(|w| w == b"binary_compressed\n")
            .unwrap()
            + 18;
        bytes[at + 4] ^= 1;
        assert!(read(&bytes[..]).is_err());
        let mut bytes = encode(&cloud, PcdEncoding::BinaryCompressed);
        bytes.truncate(at + 10);
        assert!(matches!(read(&bytes[..]), Err(ParseError::Truncated(_))));
    }

    /// A byte-level change to a file.
    #[derive(Debug, Clone)]
    enum Mutation {
        Flip(usize, u8),
        Insert(usize, u8),
        Delete(usize),
        Truncate(usize),
    }

    fn mutation() -> impl Strategy<Value = Mutation> {
        prop_oneof![
            (any::<usize>(), 0u8..8).prop_map(|(i, b)| Mutation::Flip(i, b)),
            (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Insert(i, b)),
            any::<usize>().prop_map(Mutation::Delete),
            any::<usize>().prop_map(Mutation::Truncate),
        ]
    }

    fn mutate(mut bytes: Vec<u8>, mutations: &[Mutation]) -> Vec<u8> {
        for m in mutations {
            let len = bytes.len().max(1);
            match *m {
                Mutation::Flip(i, b) if !bytes.is_empty() => bytes[i % len] ^= 1 << b,
                Mutation::Insert(i, b) => bytes.insert(i % (bytes.len() + 1), b),
                Mutation::Delete(i) if !bytes.is_empty() => {
                    bytes.remove(i % len);
                }
                Mutation::Truncate(i) => bytes.truncate(i % (bytes.len() + 1)),
                _ => {}
            }
        }
        bytes
    }

    proptest! {
        #[test]
        fn prop_mutated_files_never_panic(
            encoding in prop_oneof![
                Just(PcdEncoding::Ascii),
                Just(PcdEncoding::Binary),
                Just(PcdEncoding::BinaryCompressed),
            ],
            mask in 0u8..8,
            mutations in prop::collection::vec(mutation(), 1..6),
        ) {
            let cloud = sample(20, mask & 1 != 0, mask & 2 != 0, mask & 4 != 0);
            let bytes = mutate(encode(&cloud, encoding), &mutations);
            let _ = read(&bytes[..]);
        }

        #[test]
        fn prop_random_data_after_a_valid_header_never_panics(
            data in prop_oneof![Just("ascii"), Just("binary"), Just("binary_compressed")],
            points in prop_oneof![0u64..50, any::<u32>().prop_map(u64::from)],
            tail in prop::collection::vec(any::<u8>(), 0..2000),
        ) {
            let mut bytes = format!(
                "FIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nWIDTH {points}\nPOINTS {points}\n\
                 DATA {data}\n"
            )
            .into_bytes();
            bytes.extend_from_slice(&tail);
            if let Ok(loaded) = read(&bytes[..]) {
                prop_assert_eq!(loaded.report.records, points);
            }
        }

        #[test]
        fn prop_random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..500)) {
            let _ = read(&bytes[..]);
        }

        #[test]
        fn prop_round_trip_arbitrary_floats(
            values in prop::collection::vec(
                (any::<f32>(), any::<f32>(), any::<f32>(), any::<f32>()), 0..40),
        ) {
            let finite: Vec<_> = values
                .into_iter()
                .filter(|v| v.0.is_finite() && v.1.is_finite() && v.2.is_finite() && !v.3.is_nan())
                .collect();
            let mut cloud = PointCloud::from_points(
                finite.iter().map(|v| Point3::new(v.0, v.1, v.2)).collect());
            cloud.set_intensity(Some(finite.iter().map(|v| v.3).collect())).unwrap();
            for encoding in ALL {
                let loaded = read(&encode(&cloud, encoding)[..]).unwrap();
                prop_assert_eq!(bits(&loaded.cloud), bits(&cloud));
            }
        }
    }
}
