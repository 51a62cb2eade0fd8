//! The PLY header: the `ply` magic, `format`, `element` and `property` lines up to
//! `end_header`, and the types they declare.

use std::io::BufRead;

use nalgebra::Point3;

use crate::error::ParseError;
use crate::file::header::{clip, HeaderLine, HeaderLines};

/// Longest header line accepted (a longer one means this is not a PLY header).
const MAX_HEADER_LINE: u64 = 64 * 1024;

/// The encoding of the data after the header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Encoding {
    Ascii,
    BinaryLe,
    BinaryBe,
}

impl Encoding {
    fn parse(s: &str) -> Option<Self> {
        match s {
            "ascii" => Some(Encoding::Ascii),
            "binary_little_endian" => Some(Encoding::BinaryLe),
            "binary_big_endian" => Some(Encoding::BinaryBe),
            _ => None,
        }
    }

    pub(super) fn name(self) -> &'static str {
        match self {
            Encoding::Ascii => "ascii",
            Encoding::BinaryLe => "binary_little_endian",
            Encoding::BinaryBe => "binary_big_endian",
        }
    }
}

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

/// Decodes one number of type `$t` from the first bytes of `$b` in the byte order `BE`.
macro_rules! decode_as {
    ($t:ty, $b:expr) => {
        match $b.first_chunk() {
            Some(a) if BE => <$t>::from_be_bytes(*a) as f64,
            Some(a) => <$t>::from_le_bytes(*a) as f64,
            None => f64::NAN,
        }
    };
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// Bytes in a binary file.
    pub(super) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    pub(super) fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes a binary value from the start of `b` (NaN if `b` is too short, which the
    /// callers rule out). Every type converts to `f64` exactly.
    #[inline(always)]
    pub(super) fn decode<const BE: bool>(self, b: &[u8]) -> f64 {
        match self {
            Scalar::I8 => decode_as!(i8, b),
            Scalar::U8 => decode_as!(u8, b),
            Scalar::I16 => decode_as!(i16, b),
            Scalar::U16 => decode_as!(u16, b),
            Scalar::I32 => decode_as!(i32, b),
            Scalar::U32 => decode_as!(u32, b),
            Scalar::F32 => decode_as!(f32, b),
            Scalar::F64 => decode_as!(f64, b),
        }
    }

    /// Parses an ascii token. `float` properties are parsed in single precision so that
    /// the value is the correctly rounded `f32` (no double rounding through `f64`).
    #[inline]
    pub(super) fn parse_text(self, s: &str) -> Option<f64> {
        match self {
            Scalar::F32 => s.parse::<f32>().ok().map(f64::from),
            _ => s.parse::<f64>().ok(),
        }
    }
}

/// The type of a property.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

/// One `property` line.
#[derive(Debug, Clone)]
pub(super) struct Property {
    pub(super) name: String,
    pub(super) kind: Kind,
}

/// One `element` line and its properties.
#[derive(Debug, Clone)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: u64,
    pub(super) props: Vec<Property>,
    /// The header line declaring it (for error messages).
    pub(super) line: usize,
}

impl Element {
    /// The size of one binary record, or `None` if a property is a list (or the size
    /// overflows, which no real file does).
    pub(super) fn fixed_size(&self) -> Option<usize> {
        self.props.iter().try_fold(0usize, |acc, p| match p.kind {
            Kind::Scalar(s) => acc.checked_add(s.size()),
            Kind::List { .. } => None,
        })
    }
}

/// The parsed header.
#[derive(Debug)]
pub(super) struct Header {
    pub(super) encoding: Encoding,
    pub(super) elements: Vec<Element>,
    pub(super) origin: Point3<f64>,
    /// Number of the `end_header` line.
    pub(super) end_line: usize,
    /// Byte offset of the first data byte in the stream.
    pub(super) data_start: u64,
}

// ---------------------------------------------------------------------------------------
// Header parsing
// ---------------------------------------------------------------------------------------

/// Whether a header line is a `comment` or `obj_info` line (free text, maybe not UTF-8).
fn is_free_text(line: HeaderLine<'_>) -> bool {
    matches!(line.words().next(), Some(b"comment") | Some(b"obj_info"))
}

/// The origin from `comment olmap origin <x> <y> <z>`, if this is such a line.
fn olmap_origin(text: &str) -> Option<Point3<f64>> {
    let mut t = text.split_ascii_whitespace();
    if (t.next(), t.next(), t.next()) != (Some("comment"), Some("olmap"), Some("origin")) {
        return None;
    }
    let mut xyz = [0.0f64; 3];
    for v in &mut xyz {
        *v = t.next()?.parse().ok().filter(|v: &f64| v.is_finite())?;
    }
    t.next().is_none().then(|| Point3::from(xyz))
}

/// Parses a scalar type name at a header line.
fn scalar_type(name: &str, line_no: usize) -> Result<Scalar, ParseError> {
    Scalar::parse(name).ok_or_else(|| {
        ParseError::line(
            line_no,
            format!(
                "unknown property type '{name}': expected char, uchar, short, ushort, int, \
                 uint, float, double (or int8, uint8, int16, uint16, int32, uint32, float32, \
                 float64)"
            ),
        )
    })
}

/// Parses the arguments of a `property` line.
fn parse_property(args: &[&str], line_no: usize) -> Result<Property, ParseError> {
    match args {
        ["list", count, item, name] => {
            let count = scalar_type(count, line_no)?;
            if count.is_float() {
                return Err(ParseError::line(
                    line_no,
                    "a list count type must be an integer type (uchar, int, ...)",
                ));
            }
            let item = scalar_type(item, line_no)?;
            Ok(Property {
                name: (*name).to_owned(),
                kind: Kind::List { count, item },
            })
        }
        ["list", ..] => Err(ParseError::line(
            line_no,
            "expected 'property list <count type> <item type> <name>'",
        )),
        [ty, name] => Ok(Property {
            name: (*name).to_owned(),
            kind: Kind::Scalar(scalar_type(ty, line_no)?),
        }),
        _ => Err(ParseError::line(
            line_no,
            "expected 'property <type> <name>' or 'property list <count type> <item type> <name>'",
        )),
    }
}

/// Parses the arguments of an `element` line.
fn parse_element(args: &[&str], line_no: usize) -> Result<Element, ParseError> {
    let [name, count] = args else {
        return Err(ParseError::line(
            line_no,
            "expected 'element <name> <count>'",
        ));
    };
    let count = count.parse::<u64>().map_err(|_| {
        ParseError::line(
            line_no,
            format!("element '{name}': expected a non-negative whole count, found '{count}'"),
        )
    })?;
    Ok(Element {
        name: (*name).to_owned(),
        count,
        props: Vec::new(),
        line: line_no,
    })
}

/// Parses the arguments of a `format` line.
fn parse_format(args: &[&str], line_no: usize) -> Result<Encoding, ParseError> {
    let [enc, version] = args else {
        return Err(ParseError::line(
            line_no,
            "expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0'",
        ));
    };
    let encoding = Encoding::parse(enc).ok_or_else(|| {
        ParseError::line(
            line_no,
            format!(
                "unknown format '{enc}': expected ascii, binary_little_endian or \
                 binary_big_endian"
            ),
        )
    })?;
    if version.parse::<f64>().ok() != Some(1.0) {
        return Err(ParseError::line(
            line_no,
            format!("unsupported PLY version '{version}': expected 1.0"),
        ));
    }
    Ok(encoding)
}

/// Reads the header, leaving `r` at the first data byte.
pub(super) fn parse_header<R: BufRead>(r: &mut R) -> Result<Header, ParseError> {
    let mut lines = HeaderLines::new(r, MAX_HEADER_LINE, "expected a PLY header line");
    let Some(first) = lines.next_line()? else {
        return Err(ParseError::Empty);
    };
    if first.bytes.trim_ascii() != b"ply" {
        return Err(ParseError::line(
            1,
            "expected 'ply' (the PLY magic) as the first line",
        ));
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut origin = Point3::origin();
    loop {
        let Some(line) = lines.next_line()? else {
            return Err(ParseError::Truncated(format!(
                "the header ends after line {} without 'end_header'",
                lines.lines()
            )));
        };
        let line_no = line.number;
        if is_free_text(line) {
            if let Some(o) = std::str::from_utf8(line.bytes).ok().and_then(olmap_origin) {
                origin = o;
            }
            continue;
        }
        let text = line.text("header line is not text (invalid UTF-8)")?;
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        let Some((&keyword, args)) = words.split_first() else {
            continue; // blank line
        };
        match keyword {
            "format" if encoding.is_some() => {
                return Err(ParseError::line(line_no, "a second 'format' line"));
            }
            "format" => encoding = Some(parse_format(args, line_no)?),
            "element" if encoding.is_none() => {
                return Err(ParseError::line(
                    line_no,
                    "expected a 'format' line before the first element",
                ));
            }
            "element" => elements.push(parse_element(args, line_no)?),
            "property" => {
                let prop = parse_property(args, line_no)?;
                let el = elements.last_mut().ok_or_else(|| {
                    ParseError::line(line_no, "expected an 'element' line before 'property'")
                })?;
                el.props.push(prop);
            }
            "end_header" => {
                let encoding = encoding.ok_or_else(|| {
                    ParseError::line(line_no, "expected a 'format' line before 'end_header'")
                })?;
                return Ok(Header {
                    encoding,
                    elements,
                    origin,
                    end_line: line_no,
                    data_start: line.end,
                });
            }
            other => {
                return Err(ParseError::line(
                    line_no,
                    format!(
                        "unknown header keyword '{}': expected format, comment, obj_info, \
                         element, property or end_header",
                        clip(other.as_bytes())
                    ),
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::error::ParseError;
    use crate::io::ply::read;
    use crate::io::ply::tests::invalid_at_line;
    use nalgebra::Point3;

    #[test]
    fn other_comments_leave_the_origin_at_zero() {
        let text = "ply\nformat ascii 1.0\ncomment olmap origin 1 2\ncomment origin 1 2 3\n\
            element vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
            end_header\n1 2 3\n";
        assert_eq!(
            read(text.as_bytes()).unwrap().cloud.origin(),
            Point3::origin()
        );
    }

    #[test]
    fn bad_headers_are_errors_naming_the_line() {
        assert!(matches!(read(&b""[..]), Err(ParseError::Empty)));
        assert_eq!(invalid_at_line(read(&b"plyx\nformat ascii 1.0\n"[..])), 1);
        assert_eq!(invalid_at_line(read(&b"\x00\x01\x02"[..])), 1);
        let cases: [(&str, usize); 10] = [
            ("ply\nformat binary_middle_endian 1.0\nend_header\n", 2),
            ("ply\nformat ascii 2.0\nend_header\n", 2),
            (
                "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\n",
                4,
            ),
            ("ply\nformat ascii 1.0\nelement vertex -1\n", 3),
            ("ply\nformat ascii 1.0\nproperty float x\n", 3),
            ("ply\nelement vertex 1\n", 2),
            (
                "ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\n",
                4,
            ),
            ("ply\nformat ascii 1.0\nbanana\n", 3),
            ("ply\nformat ascii 1.0\nelement face 0\nend_header\n", 4),
            (
                "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                 end_header\n1 2\n",
                3,
            ),
        ];
        for (text, line) in cases {
            assert_eq!(invalid_at_line(read(text.as_bytes())), line, "{text:?}");
        }
        let no_end = read(&b"ply\nformat ascii 1.0\nelement vertex 1\n"[..]);
        assert!(matches!(no_end, Err(ParseError::Truncated(_))));
    }
}
