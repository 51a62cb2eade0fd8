//! The PCD header: its `KEY values...` lines up to `DATA`, parsed and checked against each
//! other into a [`Header`].

use std::io::BufRead;
use std::str::FromStr;

use super::{shown, Scalar};
use crate::error::ParseError;
use crate::file::header::HeaderLines;

/// Longest header line accepted (a guard against binary garbage without line ends).
const MAX_HEADER_LINE: u64 = 1 << 20;
/// The header keys, for error messages.
const KEYS: &str = "VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT, VIEWPOINT, POINTS or DATA";

/// The three ways of storing the points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum DataEncoding {
    Ascii,
    Binary,
    BinaryCompressed,
}

impl DataEncoding {
    pub(super) fn name(self) -> &'static str {
        match self {
            DataEncoding::Ascii => "ascii",
            DataEncoding::Binary => "binary",
            DataEncoding::BinaryCompressed => "binary_compressed",
        }
    }
}

/// One field of the header.
#[derive(Debug, Clone)]
pub(super) struct Field {
    pub(super) name: String,
    pub(super) scalar: Scalar,
    pub(super) count: usize,
    /// Byte offset of the field within a packed record.
    pub(super) offset: usize,
}

impl Field {
    /// Bytes of the field in one record (checked not to overflow when the header was read).
    pub(super) fn bytes(&self) -> usize {
        self.scalar.size() * self.count
    }
}

/// Which fields (indices into the header's fields) hold what the cloud keeps.
#[derive(Debug, Clone, Copy)]
pub(super) struct Roles {
    pub(super) xyz: [usize; 3],
    pub(super) intensity: Option<usize>,
    pub(super) normals: Option<[usize; 3]>,
    pub(super) rgb: Option<usize>,
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
pub(super) struct Header {
    pub(super) fields: Vec<Field>,
    pub(super) roles: Roles,
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) points: u64,
    pub(super) viewpoint: [f64; 7],
    pub(super) encoding: DataEncoding,
    /// Bytes of one packed record.
    pub(super) record_size: usize,
    /// Line number of the `DATA` line.
    pub(super) data_line: usize,
    /// Byte offset of the point data in the stream.
    pub(super) data_offset: u64,
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
pub(super) fn read_header<R: BufRead>(reader: &mut R) -> Result<Header, ParseError> {
    let mut raw = RawHeader::default();
    let mut lines = HeaderLines::new(reader, MAX_HEADER_LINE, "not a PCD header");
    loop {
        let Some(line) = lines.next_line()? else {
            let read = lines.lines();
            return Err(if read == 0 {
                ParseError::Empty
            } else {
                ParseError::Truncated(format!(
                    "the header ends after {read} lines without a DATA line"
                ))
            });
        };
        let line_no = line.number;
        let text = line.text("header line is not text (invalid UTF-8 bytes)")?;
        if line.is_comment() {
            continue;
        }
        let mut tokens = text.split_ascii_whitespace();
        let Some(key) = tokens.next() else { continue };
        let values: Vec<&str> = tokens.collect();
        if let Some(encoding) = raw.add(line_no, key, &values)? {
            return raw.finish(line_no, line.end, encoding);
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
    let mut v = [0.0f64; 7];
    for (slot, s) in v.iter_mut().zip(values) {
        *slot = s.parse().map_err(|_| err())?;
    }
    if !v.iter().all(|x| x.is_finite()) {
        return Err(ParseError::line(
            line,
            format!(
                "VIEWPOINT: expected finite numbers (the sensor pose), found '{}'",
                shown(&values.join(" "))
            ),
        ));
    }
    let q_norm = v[3..].iter().map(|x| x * x).sum::<f64>().sqrt();
    if q_norm <= 1e-6 {
        return Err(ParseError::line(
            line,
            format!(
                "VIEWPOINT: the rotation quaternion qw qx qy qz is zero ('{}'): not a rotation \
                 (the identity is 1 0 0 0)",
                shown(&values[3..].join(" "))
            ),
        ));
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

#[cfg(test)]
mod tests {
    use crate::error::ParseError;
    use crate::io::pcd::read;
    use crate::io::pcd::tests::{header_error, GOOD_HEAD};
    use nalgebra::Point3;

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
}
