//! The Polygon File Format (PLY, "Stanford triangle format").
//!
//! PLY was described by Greg Turk (Stanford, 1994) to store polygonal models as a list of
//! *elements*, each with a count and a list of typed *properties*. A file is a text header
//! followed by the data of every element in the order the header declares them:
//!
//! ```text
//! ply
//! format binary_little_endian 1.0      (or ascii / binary_big_endian)
//! comment written by olmap
//! element vertex 2
//! property float x                     (property <type> <name>)
//! property float y
//! property float z
//! property list uchar float extra      (property list <count type> <item type> <name>)
//! end_header
//! <data>
//! ```
//!
//! Scalar types are `char`/`int8`, `uchar`/`uint8`, `short`/`int16`, `ushort`/`uint16`,
//! `int`/`int32`, `uint`/`uint32`, `float`/`float32` and `double`/`float64`. In `ascii`
//! files each element instance is one line of whitespace-separated numbers (a list is its
//! count followed by its items); in binary files instances are packed records in the
//! declared byte order, a list being its count followed by its items.
//!
//! # What this reader takes from a file
//! Only the `vertex` element is read; it must have `x`, `y` and `z` (any numeric type).
//! Property names are matched case-insensitively:
//! * intensity: the first of `intensity`, `scalar_intensity` (CloudCompare writes
//!   `scalar_Intensity`) or `reflectance`;
//! * normals: `nx ny nz`, or PCL's `normal_x normal_y normal_z` (all three needed);
//! * colours: `red green blue`, or `diffuse_red diffuse_green diffuse_blue` (all three
//!   needed). `uchar` is taken as is; other integer types are clamped to 0..=255; floating
//!   point colours are taken to be in 0..=1 and scaled to 0..=255 (rounded, clamped).
//!
//! Every other vertex property, list properties included, is skipped.
//! [`ReadReport::fields`] lists all the vertex properties the header declares.
//!
//! # Quirks handled
//! * Elements declared before `vertex` (a `face` element first, say) are skipped in all
//!   three encodings, also when they have list properties; elements after `vertex` are not
//!   read at all (reading stops after the last vertex).
//! * CRLF line ends (Windows tools) in the header and in ascii data; blank lines are
//!   ignored; `comment` and `obj_info` lines may appear anywhere in the header.
//! * Points with a NaN or infinite coordinate (also after conversion to `f32`) are dropped
//!   and counted in [`ReadReport::dropped_non_finite`].
//! * The sensor origin: olmap writes `comment olmap origin <x> <y> <z>` and reads it back;
//!   other comments are ignored and the origin is (0, 0, 0) without one.
//! * Hostile input: counts in the header are never trusted for allocation (memory grows
//!   only with data actually read), arithmetic on them is checked, and a file shorter than
//!   its header announces gives [`ParseError::Truncated`]. The reader never panics.
//!
//! # Writer
//! [`write()`] writes `binary_little_endian` (the default) or `ascii` with `float` x, y, z,
//! then `float intensity`, `float nx ny nz` and `uchar red green blue` where the cloud has
//! them. Ascii floats use Rust's shortest round-trip form (`{}`; the origin comment uses
//! `{:?}`, which keeps huge and tiny `f64` short), so both encodings read back bit for bit.
//!
//! # Speed
//! Binary vertex records without list properties are read in 1 MiB chunks and decoded
//! column by column; `float` x y z take no detour through `f64`. Ascii lines are read into
//! one reused buffer and split without allocating; the time goes into `str::parse`.

use std::io::{self, BufRead, Read, Write};

use nalgebra::{Point3, Vector3};

use super::{finite_point, CloudFormat, LoadedCloud, PlyEncoding, ReadReport};
use crate::cloud::PointCloud;
use crate::error::{Location, ParseError};

/// Longest header line accepted (a longer one means this is not a PLY header).
const MAX_HEADER_LINE: u64 = 64 * 1024;
/// Bytes of binary vertex records read and decoded at a time.
const CHUNK_BYTES: usize = 1 << 20;
/// Points reserved up front at most, whatever the header claims.
const INITIAL_CAPACITY: u64 = 1 << 16;
/// Bytes of output buffered by the writer before a `write_all`.
const WRITE_CHUNK: usize = 1 << 16;

/// Names accepted for the intensity property (compared case-insensitively).
const INTENSITY_NAMES: [&str; 3] = ["intensity", "scalar_intensity", "reflectance"];
/// Name triples accepted for normals.
const NORMAL_NAMES: [[&str; 3]; 2] = [["nx", "ny", "nz"], ["normal_x", "normal_y", "normal_z"]];
/// Name triples accepted for colours.
const COLOR_NAMES: [[&str; 3]; 2] = [
    ["red", "green", "blue"],
    ["diffuse_red", "diffuse_green", "diffuse_blue"],
];

// ---------------------------------------------------------------------------------------
// Header model
// ---------------------------------------------------------------------------------------

/// The encoding of the data after the header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
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

    fn name(self) -> &'static str {
        match self {
            Encoding::Ascii => "ascii",
            Encoding::BinaryLe => "binary_little_endian",
            Encoding::BinaryBe => "binary_big_endian",
        }
    }
}

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
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
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes a binary value from the start of `b` (NaN if `b` is too short, which the
    /// callers rule out). Every type converts to `f64` exactly.
    #[inline(always)]
    fn decode<const BE: bool>(self, b: &[u8]) -> f64 {
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
    fn parse_text(self, s: &str) -> Option<f64> {
        match self {
            Scalar::F32 => s.parse::<f32>().ok().map(f64::from),
            _ => s.parse::<f64>().ok(),
        }
    }
}

/// The type of a property.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

/// One `property` line.
#[derive(Debug, Clone)]
struct Property {
    name: String,
    kind: Kind,
}

/// One `element` line and its properties.
#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
    /// The header line declaring it (for error messages).
    line: usize,
}

impl Element {
    /// The size of one binary record, or `None` if a property is a list (or the size
    /// overflows, which no real file does).
    fn fixed_size(&self) -> Option<usize> {
        self.props.iter().try_fold(0usize, |acc, p| match p.kind {
            Kind::Scalar(s) => acc.checked_add(s.size()),
            Kind::List { .. } => None,
        })
    }
}

/// The parsed header.
#[derive(Debug)]
struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    origin: Point3<f64>,
    /// Number of the `end_header` line.
    end_line: usize,
    /// Byte offset of the first data byte in the stream.
    data_start: u64,
}

// ---------------------------------------------------------------------------------------
// Header parsing
// ---------------------------------------------------------------------------------------

/// Reads one header line (at most [`MAX_HEADER_LINE`] bytes) into `buf`; returns its
/// length in bytes, 0 at the end of the stream.
fn read_header_line<R: BufRead>(
    r: &mut R,
    buf: &mut Vec<u8>,
    line_no: usize,
) -> Result<u64, ParseError> {
    buf.clear();
    let n = (&mut *r).take(MAX_HEADER_LINE).read_until(b'\n', buf)?;
    if n as u64 == MAX_HEADER_LINE && buf.last() != Some(&b'\n') {
        return Err(ParseError::line(
            line_no,
            format!(
                "header line longer than {} KiB: expected a PLY header line",
                MAX_HEADER_LINE / 1024
            ),
        ));
    }
    Ok(n as u64)
}

/// Splits bytes at ASCII whitespace, skipping empty pieces.
#[inline]
fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(u8::is_ascii_whitespace)
        .filter(|t| !t.is_empty())
}

/// Whether a header line is a `comment` or `obj_info` line (free text, maybe not UTF-8).
fn is_free_text(line: &[u8]) -> bool {
    matches!(tokens(line).next(), Some(b"comment") | Some(b"obj_info"))
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
fn parse_header<R: BufRead>(r: &mut R) -> Result<Header, ParseError> {
    let mut buf = Vec::with_capacity(128);
    let mut bytes = read_header_line(r, &mut buf, 1)?;
    if bytes == 0 {
        return Err(ParseError::Empty);
    }
    if buf.trim_ascii() != b"ply" {
        return Err(ParseError::line(
            1,
            "expected 'ply' (the PLY magic) as the first line",
        ));
    }
    let mut line_no = 1;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut origin = Point3::origin();
    loop {
        line_no += 1;
        let n = read_header_line(r, &mut buf, line_no)?;
        bytes += n;
        if n == 0 {
            return Err(ParseError::Truncated(format!(
                "the header ends after line {} without 'end_header'",
                line_no - 1
            )));
        }
        if is_free_text(&buf) {
            if let Some(o) = std::str::from_utf8(&buf).ok().and_then(olmap_origin) {
                origin = o;
            }
            continue;
        }
        let text = std::str::from_utf8(&buf)
            .map_err(|_| ParseError::line(line_no, "header line is not text (invalid UTF-8)"))?;
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
                    data_start: bytes,
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

/// A short printable form of some bytes for error messages.
fn clip(bytes: &[u8]) -> String {
    let s = String::from_utf8_lossy(&bytes[..bytes.len().min(40)]).into_owned();
    if bytes.len() > 40 {
        s + "..."
    } else {
        s
    }
}

// ---------------------------------------------------------------------------------------
// Mapping vertex properties onto cloud attributes
// ---------------------------------------------------------------------------------------

/// Slots of the per-vertex values the cloud keeps.
const X: usize = 0;
const INTENSITY: usize = 3;
const NORMAL: usize = 4;
const COLOR: usize = 7;
const SLOTS: usize = 10;

/// Which vertex property feeds which slot.
#[derive(Debug)]
struct Plan {
    /// Index of the vertex element.
    vertex: usize,
    /// For every vertex property, the slot it fills.
    slot_of: Vec<Option<usize>>,
    intensity: bool,
    normals: bool,
    colors: bool,
    /// Per colour channel: whether its type is floating point (0..1 scale).
    color_float: [bool; 3],
}

/// Index of the first scalar property whose name is one of `names` (case-insensitive).
fn find_scalar(props: &[Property], names: &[&str]) -> Option<usize> {
    props.iter().position(|p| {
        matches!(p.kind, Kind::Scalar(_)) && names.iter().any(|n| p.name.eq_ignore_ascii_case(n))
    })
}

/// Indices of a triple of scalar properties, the first triple of `candidates` complete.
fn find_triple(props: &[Property], candidates: &[[&str; 3]]) -> Option<[usize; 3]> {
    candidates.iter().find_map(|names| {
        Some([
            find_scalar(props, &names[..1])?,
            find_scalar(props, &names[1..2])?,
            find_scalar(props, &names[2..])?,
        ])
    })
}

/// The scalar type of a property (callers pass scalar properties only).
fn scalar_of(p: &Property) -> Scalar {
    match p.kind {
        Kind::Scalar(s) => s,
        Kind::List { item, .. } => item,
    }
}

impl Plan {
    fn new(header: &Header) -> Result<Plan, ParseError> {
        let vertex = header
            .elements
            .iter()
            .position(|e| e.name == "vertex")
            .ok_or_else(|| {
                ParseError::line(
                    header.end_line,
                    "expected an 'element vertex' line before end_header",
                )
            })?;
        let el = &header.elements[vertex];
        let mut slot_of = vec![None; el.props.len()];
        for (axis, name) in ["x", "y", "z"].into_iter().enumerate() {
            let Some(i) = el
                .props
                .iter()
                .position(|p| p.name.eq_ignore_ascii_case(name))
            else {
                return Err(ParseError::line(
                    el.line,
                    format!("element 'vertex' has no property '{name}': expected x, y and z"),
                ));
            };
            if matches!(el.props[i].kind, Kind::List { .. }) {
                return Err(ParseError::line(
                    el.line,
                    format!("vertex property '{name}' is a list: expected a number"),
                ));
            }
            slot_of[i] = Some(X + axis);
        }
        let mut plan = Plan {
            vertex,
            slot_of,
            intensity: false,
            normals: false,
            colors: false,
            color_float: [false; 3],
        };
        if let Some(i) = find_scalar(&el.props, &INTENSITY_NAMES) {
            plan.claim(i, INTENSITY);
            plan.intensity = true;
        }
        if let Some(idx) = find_triple(&el.props, &NORMAL_NAMES) {
            for (k, i) in idx.into_iter().enumerate() {
                plan.claim(i, NORMAL + k);
            }
            plan.normals = true;
        }
        if let Some(idx) = find_triple(&el.props, &COLOR_NAMES) {
            for (k, i) in idx.into_iter().enumerate() {
                plan.claim(i, COLOR + k);
                plan.color_float[k] = scalar_of(&el.props[i]).is_float();
            }
            plan.colors = true;
        }
        Ok(plan)
    }

    /// Routes property `i` to `slot` unless it already feeds x, y or z.
    fn claim(&mut self, i: usize, slot: usize) {
        if let Some(s @ None) = self.slot_of.get_mut(i) {
            *s = Some(slot);
        }
    }

    /// The slot property `i` fills, if any.
    #[inline]
    fn slot(&self, i: usize) -> Option<usize> {
        self.slot_of.get(i).copied().flatten()
    }
}

/// Collects the points and attributes while reading.
struct Builder {
    points: Vec<Point3<f32>>,
    intensity: Option<Vec<f32>>,
    normals: Option<Vec<Vector3<f32>>>,
    colors: Option<Vec<[u8; 3]>>,
    color_float: [bool; 3],
    report: ReadReport,
}

impl Builder {
    fn new(plan: &Plan, count: u64, report: ReadReport) -> Self {
        let cap = count.min(INITIAL_CAPACITY) as usize;
        Builder {
            points: Vec::with_capacity(cap),
            intensity: plan.intensity.then(|| Vec::with_capacity(cap)),
            normals: plan.normals.then(|| Vec::with_capacity(cap)),
            colors: plan.colors.then(|| Vec::with_capacity(cap)),
            color_float: plan.color_float,
            report,
        }
    }

    /// Adds one vertex from its slot values, unless a coordinate is not finite.
    #[inline]
    fn push(&mut self, s: &[f64; SLOTS]) {
        let Some(p) = finite_point([s[X], s[X + 1], s[X + 2]], &mut self.report) else {
            return;
        };
        self.points.push(p);
        if let Some(v) = &mut self.intensity {
            v.push(s[INTENSITY] as f32);
        }
        if let Some(v) = &mut self.normals {
            v.push(Vector3::new(
                s[NORMAL] as f32,
                s[NORMAL + 1] as f32,
                s[NORMAL + 2] as f32,
            ));
        }
        if let Some(v) = &mut self.colors {
            let f = self.color_float;
            v.push([
                color_byte(s[COLOR], f[0]),
                color_byte(s[COLOR + 1], f[1]),
                color_byte(s[COLOR + 2], f[2]),
            ]);
        }
    }

    /// Removes the points from index `start` on that have a non-finite coordinate (with
    /// their attributes), counting them.
    fn drop_non_finite_from(&mut self, start: usize) {
        let finite = |p: &Point3<f32>| p.x.is_finite() && p.y.is_finite() && p.z.is_finite();
        let Some(tail) = self.points.get(start..) else {
            return;
        };
        if tail.iter().all(finite) {
            return;
        }
        let keep: Vec<bool> = tail.iter().map(finite).collect();
        self.report.dropped_non_finite += keep.iter().filter(|k| !**k).count() as u64;
        compact_from(&mut self.points, start, &keep);
        if let Some(v) = &mut self.intensity {
            compact_from(v, start, &keep);
        }
        if let Some(v) = &mut self.normals {
            compact_from(v, start, &keep);
        }
        if let Some(v) = &mut self.colors {
            compact_from(v, start, &keep);
        }
    }

    fn finish(self, origin: Point3<f64>) -> Result<LoadedCloud, ParseError> {
        let mut cloud = PointCloud::from_points(self.points).with_origin(origin);
        let attach = |r: crate::error::Result<()>| {
            r.map_err(|e| ParseError::Malformed(format!("internal: {e}")))
        };
        attach(cloud.set_intensity(self.intensity))?;
        attach(cloud.set_normals(self.normals))?;
        attach(cloud.set_colors(self.colors))?;
        Ok(LoadedCloud {
            cloud,
            report: self.report,
        })
    }
}

/// Keeps the elements of `v[start..]` whose flag in `keep` is set, in order.
fn compact_from<T: Copy>(v: &mut Vec<T>, start: usize, keep: &[bool]) {
    let mut w = start;
    for (r, &k) in (start..v.len()).zip(keep) {
        if k {
            if let Some(&x) = v.get(r) {
                if let Some(slot) = v.get_mut(w) {
                    *slot = x;
                }
            }
            w += 1;
        }
    }
    v.truncate(w);
}

/// Converts a colour channel value to a byte: floats are on a 0..1 scale, integers are
/// clamped (`as u8` saturates and maps NaN to 0).
#[inline]
fn color_byte(v: f64, is_float: bool) -> u8 {
    if is_float {
        (v * 255.0).round() as u8
    } else {
        v as u8
    }
}

// ---------------------------------------------------------------------------------------
// Reading
// ---------------------------------------------------------------------------------------

/// Reads a PLY point cloud (the `vertex` element) from a stream.
///
/// Accepts the `ascii`, `binary_little_endian` and `binary_big_endian` encodings; see the
/// [module documentation](self) for the properties understood and the quirks handled.
/// Never panics, whatever the input.
///
/// ```
/// let text = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n\
///              property float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n";
/// let loaded = olmap::io::ply::read(&text[..]).unwrap();
/// assert_eq!(loaded.cloud.len(), 2);
/// assert_eq!(loaded.report.encoding, "ascii");
/// ```
pub fn read<R: BufRead>(mut reader: R) -> Result<LoadedCloud, ParseError> {
    let header = parse_header(&mut reader)?;
    let plan = Plan::new(&header)?;
    let vertex = &header.elements[plan.vertex];
    let mut report = ReadReport::new(CloudFormat::Ply);
    report.encoding = header.encoding.name().to_owned();
    report.records = vertex.count;
    report.fields = vertex.props.iter().map(|p| p.name.clone()).collect();
    let mut builder = Builder::new(&plan, vertex.count, report);
    match header.encoding {
        Encoding::Ascii => read_ascii(reader, &header, &plan, &mut builder)?,
        Encoding::BinaryLe => read_binary::<false, R>(reader, &header, &plan, &mut builder)?,
        Encoding::BinaryBe => read_binary::<true, R>(reader, &header, &plan, &mut builder)?,
    }
    builder.finish(header.origin)
}

// ----- binary ---------------------------------------------------------------------------

/// A binary stream that counts the bytes it has delivered.
struct BinInput<R> {
    r: R,
    /// Offset of the next byte in the stream.
    pos: u64,
}

impl<R: BufRead> BinInput<R> {
    /// Fills `buf` as far as the stream allows; returns the bytes read (short at the end).
    fn fill(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let mut got = 0;
        while got < buf.len() {
            match self.r.read(&mut buf[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        self.pos += got as u64;
        Ok(got)
    }

    /// Skips up to `n` bytes; returns how many were skipped (fewer at the end).
    fn skip(&mut self, n: u64) -> io::Result<u64> {
        let mut left = n;
        while left > 0 {
            let avail = match self.r.fill_buf() {
                Ok(b) => b.len(),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if avail == 0 {
                break;
            }
            let k = (avail as u64).min(left) as usize;
            self.r.consume(k);
            left -= k as u64;
        }
        let done = n - left;
        self.pos += done;
        Ok(done)
    }

    /// Reads one value of type `ty`; `None` at the end of the stream.
    #[inline]
    fn value<const BE: bool>(&mut self, ty: Scalar) -> io::Result<Option<f64>> {
        let mut b = [0u8; 8];
        let b = &mut b[..ty.size()];
        let got = self.fill(b)?;
        Ok((got == b.len()).then(|| ty.decode::<BE>(b)))
    }
}

/// Where a binary record is being read, for messages.
struct At<'a> {
    element: &'a Element,
    instance: u64,
}

impl At<'_> {
    fn truncated(&self, prop: &str) -> ParseError {
        ParseError::Truncated(format!(
            "element '{}' ({} instances announced): the data ends inside instance {}, \
             property '{prop}'",
            self.element.name, self.element.count, self.instance
        ))
    }
}

/// Reads a list count and checks it is a whole non-negative number.
fn list_count<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    ty: Scalar,
    at: &At<'_>,
    prop: &str,
) -> Result<u64, ParseError> {
    let start = input.pos;
    let c = input.value::<BE>(ty)?.ok_or_else(|| at.truncated(prop))?;
    if c < 0.0 {
        return Err(ParseError::at(
            Location::Byte(start),
            format!(
                "element '{}' instance {}: list '{prop}' has a negative count {c}",
                at.element.name, at.instance
            ),
        ));
    }
    Ok(c as u64)
}

/// Skips one list property's items.
fn skip_list<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    count_ty: Scalar,
    item: Scalar,
    at: &At<'_>,
    prop: &str,
) -> Result<(), ParseError> {
    let n = list_count::<BE, R>(input, count_ty, at, prop)?;
    let bytes = n
        .checked_mul(item.size() as u64)
        .ok_or_else(|| at.truncated(prop))?;
    if input.skip(bytes)? < bytes {
        return Err(at.truncated(prop));
    }
    Ok(())
}

/// Skips every instance of an element that is not read.
fn skip_binary_element<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    el: &Element,
) -> Result<(), ParseError> {
    if let Some(size) = el.fixed_size() {
        let total = el.count.checked_mul(size as u64);
        let skipped = match total {
            Some(t) => input.skip(t)?,
            None => input.skip(u64::MAX)?,
        };
        if total != Some(skipped) {
            return Err(ParseError::Truncated(format!(
                "element '{}' announces {} instances of {size} bytes, but the data ends after \
                 {} bytes",
                el.name, el.count, skipped
            )));
        }
        return Ok(());
    }
    // With a list property every instance holds at least one byte, so this loop ends
    // with the data whatever the count claims.
    for instance in 0..el.count {
        let at = At {
            element: el,
            instance,
        };
        for p in &el.props {
            match p.kind {
                Kind::Scalar(s) => {
                    if input.skip(s.size() as u64)? < s.size() as u64 {
                        return Err(at.truncated(&p.name));
                    }
                }
                Kind::List { count, item } => skip_list::<BE, R>(input, count, item, &at, &p.name)?,
            }
        }
    }
    Ok(())
}

/// Reads the binary data: skips the elements before `vertex`, then reads the vertices.
fn read_binary<const BE: bool, R: BufRead>(
    reader: R,
    header: &Header,
    plan: &Plan,
    out: &mut Builder,
) -> Result<(), ParseError> {
    let mut input = BinInput {
        r: reader,
        pos: header.data_start,
    };
    for el in &header.elements[..plan.vertex] {
        skip_binary_element::<BE, R>(&mut input, el)?;
    }
    let vertex = &header.elements[plan.vertex];
    match vertex.fixed_size() {
        Some(size) => read_fixed_vertices::<BE, R>(&mut input, vertex, size, plan, out),
        None => read_list_vertices::<BE, R>(&mut input, vertex, plan, out),
    }
}

/// Fixed-size vertex records: read in large chunks and decoded in place.
fn read_fixed_vertices<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    vertex: &Element,
    size: usize,
    plan: &Plan,
    out: &mut Builder,
) -> Result<(), ParseError> {
    let layout = RecordLayout::new(vertex, plan);
    let per_chunk = (CHUNK_BYTES / size).max(1) as u64;
    let first = vertex.count.min(per_chunk) as usize;
    let mut buf = vec![0u8; first * size];
    let mut done = 0u64;
    while done < vertex.count {
        let n = (vertex.count - done).min(per_chunk) as usize;
        let chunk = &mut buf[..n * size];
        let got = input.fill(chunk)?;
        if got < chunk.len() {
            return Err(ParseError::Truncated(format!(
                "the header announces {} vertices of {size} bytes, but the data ends after \
                 {} complete vertices",
                vertex.count,
                done + (got / size) as u64
            )));
        }
        layout.decode::<BE>(chunk, size, out);
        done += n as u64;
    }
    Ok(())
}

/// A value's place in a fixed-size binary record.
#[derive(Debug, Clone, Copy)]
struct Field {
    off: usize,
    ty: Scalar,
}

impl Field {
    /// Stands for a value the record lacks (reads as NaN); never used for kept slots.
    const ABSENT: Field = Field {
        off: usize::MAX,
        ty: Scalar::U8,
    };

    #[inline(always)]
    fn read<const BE: bool>(self, rec: &[u8]) -> f64 {
        rec.get(self.off..)
            .map_or(f64::NAN, |b| self.ty.decode::<BE>(b))
    }

    /// Reads a colour channel (see [`color_byte`]); `uchar` is taken as is.
    #[inline(always)]
    fn color<const BE: bool>(self, rec: &[u8]) -> u8 {
        match self.ty {
            Scalar::U8 => rec.get(self.off).copied().unwrap_or(0),
            ty => color_byte(self.read::<BE>(rec), ty.is_float()),
        }
    }
}

/// Where the kept values lie in a fixed-size binary vertex record. Records are decoded
/// column by column (all x y z of a chunk, then all intensities, ...), which keeps every
/// loop free of branches other than the type dispatch.
struct RecordLayout {
    /// Per slot, the property feeding it.
    at: [Option<Field>; SLOTS],
}

impl RecordLayout {
    fn new(vertex: &Element, plan: &Plan) -> Self {
        let mut at = [None; SLOTS];
        let mut off = 0;
        for (i, p) in vertex.props.iter().enumerate() {
            let ty = scalar_of(p);
            if let Some(slot) = plan.slot(i).and_then(|s| at.get_mut(s)) {
                *slot = Some(Field { off, ty });
            }
            off += ty.size();
        }
        RecordLayout { at }
    }

    fn field(&self, slot: usize) -> Field {
        self.at
            .get(slot)
            .copied()
            .flatten()
            .unwrap_or(Field::ABSENT)
    }

    fn triple(&self, first: usize) -> [Field; 3] {
        [
            self.field(first),
            self.field(first + 1),
            self.field(first + 2),
        ]
    }

    /// Decodes a chunk of records into the builder, dropping non-finite points.
    fn decode<const BE: bool>(&self, chunk: &[u8], size: usize, out: &mut Builder) {
        let recs = || chunk.chunks_exact(size);
        let start = out.points.len();
        let [x, y, z] = self.triple(X);
        if [x, y, z].iter().all(|f| f.ty == Scalar::F32) {
            // The common case: no detour through f64.
            out.points.extend(recs().map(|r| {
                Point3::new(
                    f32_at::<BE>(r, x.off),
                    f32_at::<BE>(r, y.off),
                    f32_at::<BE>(r, z.off),
                )
            }));
        } else {
            out.points.extend(recs().map(|r| {
                Point3::new(
                    x.read::<BE>(r) as f32,
                    y.read::<BE>(r) as f32,
                    z.read::<BE>(r) as f32,
                )
            }));
        }
        if let Some(v) = &mut out.intensity {
            let f = self.field(INTENSITY);
            v.extend(recs().map(|r| f.read::<BE>(r) as f32));
        }
        if let Some(v) = &mut out.normals {
            let [a, b, c] = self.triple(NORMAL);
            v.extend(recs().map(|r| {
                Vector3::new(
                    a.read::<BE>(r) as f32,
                    b.read::<BE>(r) as f32,
                    c.read::<BE>(r) as f32,
                )
            }));
        }
        if let Some(v) = &mut out.colors {
            let [a, b, c] = self.triple(COLOR);
            v.extend(recs().map(|r| [a.color::<BE>(r), b.color::<BE>(r), c.color::<BE>(r)]));
        }
        out.drop_non_finite_from(start);
    }
}

/// The `float` at byte `off` of a record (NaN past its end, which callers rule out).
#[inline(always)]
fn f32_at<const BE: bool>(rec: &[u8], off: usize) -> f32 {
    match rec.get(off..).and_then(<[u8]>::first_chunk) {
        Some(a) if BE => f32::from_be_bytes(*a),
        Some(a) => f32::from_le_bytes(*a),
        None => f32::NAN,
    }
}

/// Vertex records with list properties: read property by property.
fn read_list_vertices<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    vertex: &Element,
    plan: &Plan,
    out: &mut Builder,
) -> Result<(), ParseError> {
    let mut slots = [0.0f64; SLOTS];
    for instance in 0..vertex.count {
        let at = At {
            element: vertex,
            instance,
        };
        for (i, p) in vertex.props.iter().enumerate() {
            match p.kind {
                Kind::Scalar(ty) => {
                    let v = input
                        .value::<BE>(ty)?
                        .ok_or_else(|| at.truncated(&p.name))?;
                    if let Some(s) = plan.slot(i).and_then(|s| slots.get_mut(s)) {
                        *s = v;
                    }
                }
                Kind::List { count, item } => skip_list::<BE, R>(input, count, item, &at, &p.name)?,
            }
        }
        out.push(&slots);
    }
    Ok(())
}

// ----- ascii ----------------------------------------------------------------------------

/// The data lines of an ascii file, read into one reused buffer.
struct Lines<R> {
    r: R,
    buf: Vec<u8>,
    /// 1-based number of the line in `buf` (counting the header).
    line_no: usize,
}

impl<R: BufRead> Lines<R> {
    /// Advances to the next line that is not blank; `false` at the end of the stream.
    fn next_line(&mut self) -> Result<bool, ParseError> {
        loop {
            self.buf.clear();
            if self.r.read_until(b'\n', &mut self.buf)? == 0 {
                return Ok(false);
            }
            self.line_no += 1;
            if !self.buf.trim_ascii().is_empty() {
                return Ok(true);
            }
        }
    }
}

/// Reads the ascii data: skips the lines of the elements before `vertex`, then parses one
/// vertex per line.
fn read_ascii<R: BufRead>(
    reader: R,
    header: &Header,
    plan: &Plan,
    out: &mut Builder,
) -> Result<(), ParseError> {
    let mut lines = Lines {
        r: reader,
        buf: Vec::with_capacity(256),
        line_no: header.end_line,
    };
    for el in &header.elements[..plan.vertex] {
        if el.props.is_empty() {
            continue;
        }
        for done in 0..el.count {
            if !lines.next_line()? {
                return Err(ParseError::Truncated(format!(
                    "element '{}' announces {} lines, but the file ends after {done}",
                    el.name, el.count
                )));
            }
        }
    }
    let vertex = &header.elements[plan.vertex];
    let mut slots = [0.0f64; SLOTS];
    for instance in 0..vertex.count {
        if !lines.next_line()? {
            return Err(ParseError::Truncated(format!(
                "the header announces {} vertices, but the file ends after {instance}",
                vertex.count
            )));
        }
        parse_vertex_line(&lines.buf, vertex, plan, &mut slots).map_err(|reason| {
            ParseError::line(lines.line_no, format!("vertex {instance}: {reason}"))
        })?;
        out.push(&slots);
    }
    Ok(())
}

/// Parses one ascii vertex line into the slots; the error says what was expected.
fn parse_vertex_line(
    line: &[u8],
    vertex: &Element,
    plan: &Plan,
    slots: &mut [f64; SLOTS],
) -> Result<(), String> {
    let line = std::str::from_utf8(line).map_err(|_| "not text (invalid UTF-8 bytes)")?;
    let mut toks = line.split_ascii_whitespace();
    let mut next = |what: &str, name: &str, ty: Scalar| -> Result<f64, String> {
        let t = toks
            .next()
            .ok_or_else(|| format!("the line ends before {what} '{name}'"))?;
        ty.parse_text(t).ok_or_else(|| {
            format!(
                "expected a number for {what} '{name}', found '{}'",
                clip(t.as_bytes())
            )
        })
    };
    for (i, p) in vertex.props.iter().enumerate() {
        match p.kind {
            Kind::Scalar(ty) => {
                let v = next("property", &p.name, ty)?;
                if let Some(s) = plan.slot(i).and_then(|s| slots.get_mut(s)) {
                    *s = v;
                }
            }
            Kind::List { count, item } => {
                let c = next("the item count of list", &p.name, count)?;
                if !(c >= 0.0 && c.fract() == 0.0) {
                    return Err(format!("list '{}' has an invalid item count {c}", p.name));
                }
                for _ in 0..c as u64 {
                    next("an item of list", &p.name, item)?;
                }
            }
        }
    }
    match toks.next() {
        None => Ok(()),
        Some(t) => Err(format!(
            "more values than the {} properties declared (extra '{}')",
            vertex.props.len(),
            clip(t.as_bytes())
        )),
    }
}

// ---------------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------------

/// Writes a cloud as PLY: `binary_little_endian` or `ascii`, `float` x y z, then
/// `float intensity`, `float nx ny nz` and `uchar red green blue` where present, and the
/// sensor origin in a `comment olmap origin x y z` line. Reading the result back gives
/// the same cloud, bit for bit, in both encodings.
///
/// ```
/// use olmap::cloud::PointCloud;
/// use olmap::io::{ply, PlyEncoding};
/// let cloud = PointCloud::from_points(vec![nalgebra::Point3::new(0.1, 0.2, 0.3)]);
/// let mut bytes = Vec::new();
/// ply::write(&mut bytes, &cloud, PlyEncoding::Ascii).unwrap();
/// assert_eq!(ply::read(&bytes[..]).unwrap().cloud, cloud);
/// ```
pub fn write<W: Write>(mut w: W, cloud: &PointCloud, encoding: PlyEncoding) -> io::Result<()> {
    w.write_all(header_text(cloud, encoding).as_bytes())?;
    match encoding {
        PlyEncoding::BinaryLittleEndian => write_binary(&mut w, cloud)?,
        PlyEncoding::Ascii => write_ascii(&mut w, cloud)?,
    }
    w.flush()
}

/// The header the writer puts before the data.
fn header_text(cloud: &PointCloud, encoding: PlyEncoding) -> String {
    let o = cloud.origin();
    let format = match encoding {
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
        PlyEncoding::Ascii => "ascii",
    };
    let mut h = format!(
        "ply\nformat {format} 1.0\ncomment written by olmap\n\
         comment olmap origin {:?} {:?} {:?}\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n",
        o.x,
        o.y,
        o.z,
        cloud.len()
    );
    if cloud.intensity().is_some() {
        h.push_str("property float intensity\n");
    }
    if cloud.normals().is_some() {
        h.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if cloud.colors().is_some() {
        h.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    h.push_str("end_header\n");
    h
}

/// The attributes of point `i` (neutral values where an attribute list is short, which
/// the [`PointCloud`] invariant rules out).
type Attrs = (Option<f32>, Option<Vector3<f32>>, Option<[u8; 3]>);

fn attrs(cloud: &PointCloud, i: usize) -> Attrs {
    (
        cloud.intensity().map(|v| v.get(i).copied().unwrap_or(0.0)),
        cloud
            .normals()
            .map(|v| v.get(i).copied().unwrap_or_else(Vector3::zeros)),
        cloud.colors().map(|v| v.get(i).copied().unwrap_or([0; 3])),
    )
}

fn write_binary<W: Write>(w: &mut W, cloud: &PointCloud) -> io::Result<()> {
    let mut buf = Vec::with_capacity(WRITE_CHUNK + 64);
    for (i, p) in cloud.points().iter().enumerate() {
        for v in [p.x, p.y, p.z] {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        let (intensity, normal, color) = attrs(cloud, i);
        if let Some(v) = intensity {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(n) = normal {
            for v in [n.x, n.y, n.z] {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
        if let Some(c) = color {
            buf.extend_from_slice(&c);
        }
        if buf.len() >= WRITE_CHUNK {
            w.write_all(&buf)?;
            buf.clear();
        }
    }
    w.write_all(&buf)
}

fn write_ascii<W: Write>(w: &mut W, cloud: &PointCloud) -> io::Result<()> {
    use std::fmt::Write as _;
    let mut buf = String::with_capacity(WRITE_CHUNK + 256);
    for (i, p) in cloud.points().iter().enumerate() {
        let _ = write!(buf, "{} {} {}", p.x, p.y, p.z);
        let (intensity, normal, color) = attrs(cloud, i);
        if let Some(v) = intensity {
            let _ = write!(buf, " {v}");
        }
        if let Some(n) = normal {
            let _ = write!(buf, " {} {} {}", n.x, n.y, n.z);
        }
        if let Some(c) = color {
            let _ = write!(buf, " {} {} {}", c[0], c[1], c[2]);
        }
        buf.push('\n');
        if buf.len() >= WRITE_CHUNK {
            w.write_all(buf.as_bytes())?;
            buf.clear();
        }
    }
    w.write_all(buf.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A cloud with awkward values (extremes, subnormals, non-representable decimals).
    fn sample(intensity: bool, normals: bool, colors: bool) -> PointCloud {
        let xs: [f32; 8] = [
            0.1,
            -2.5e-3,
            f32::MAX,
            f32::MIN_POSITIVE,
            1e-45,
            -123456.79,
            1.0 / 3.0,
            0.0,
        ];
        let n = xs.len();
        let points = (0..n)
            .map(|i| Point3::new(xs[i], xs[(i + 3) % n], -xs[(i + 5) % n]))
            .collect();
        let mut c = PointCloud::from_points(points).with_origin(Point3::new(
            0.1 + 0.2,
            -1e-300,
            12345.678901234567,
        ));
        if intensity {
            c.set_intensity(Some(xs.iter().map(|v| v * 0.7).collect()))
                .unwrap();
        }
        if normals {
            let v = (0..n)
                .map(|i| Vector3::new(xs[i].sin(), (i as f32).cos(), -0.25))
                .collect();
            c.set_normals(Some(v)).unwrap();
        }
        if colors {
            let v = (0..n)
                .map(|i| {
                    [
                        i as u8 * 30,
                        255 - i as u8,
                        if i % 2 == 0 { 0 } else { 255 },
                    ]
                })
                .collect();
            c.set_colors(Some(v)).unwrap();
        }
        c
    }

    fn to_bytes(cloud: &PointCloud, enc: PlyEncoding) -> Vec<u8> {
        let mut out = Vec::new();
        write(&mut out, cloud, enc).unwrap();
        out
    }

    #[test]
    fn round_trips_are_bit_exact() {
        for enc in [PlyEncoding::BinaryLittleEndian, PlyEncoding::Ascii] {
            for mask in 0..8 {
                let cloud = sample(mask & 1 != 0, mask & 2 != 0, mask & 4 != 0);
                let loaded = read(&to_bytes(&cloud, enc)[..]).unwrap();
                assert_eq!(loaded.cloud, cloud, "{enc:?} mask {mask}");
                for (a, b) in loaded.cloud.points().iter().zip(cloud.points()) {
                    assert_eq!(a.x.to_bits(), b.x.to_bits());
                }
                assert_eq!(loaded.report.records, cloud.len() as u64);
                assert_eq!(loaded.report.dropped_non_finite, 0);
                assert_eq!(&loaded.report.fields[..3], ["x", "y", "z"]);
                let want = match enc {
                    PlyEncoding::Ascii => "ascii",
                    PlyEncoding::BinaryLittleEndian => "binary_little_endian",
                };
                assert_eq!(loaded.report.encoding, want);
            }
        }
    }

    #[test]
    fn non_finite_points_are_dropped_with_their_attributes() {
        let nan = f32::NAN;
        let pts = vec![
            Point3::new(1.0, 2.0, 3.0),
            Point3::new(nan, 0.0, 0.0),
            Point3::new(4.0, f32::INFINITY, 6.0),
            Point3::new(7.0, 8.0, 9.0),
        ];
        let mut cloud = PointCloud::from_points(pts);
        cloud.set_intensity(Some(vec![1.0, 2.0, 3.0, 4.0])).unwrap();
        cloud
            .set_colors(Some(vec![[1, 1, 1], [2, 2, 2], [3, 3, 3], [4, 4, 4]]))
            .unwrap();
        let keep = cloud.gather(&[0, 3]);
        for enc in [PlyEncoding::BinaryLittleEndian, PlyEncoding::Ascii] {
            let loaded = read(&to_bytes(&cloud, enc)[..]).unwrap();
            assert_eq!(loaded.cloud, keep, "{enc:?}");
            assert_eq!(loaded.report.records, 4);
            assert_eq!(loaded.report.dropped_non_finite, 2);
        }
        // Doubles beyond the f32 range are dropped too.
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\n\
            property double x\nproperty double y\nproperty double z\n\
            property float intensity\nend_header\n"
            .to_vec();
        for (p, i) in [([1e300f64, 0.0, 0.0], 5.0f32), ([0.5, 0.25, -1.0], 6.0)] {
            for v in p {
                b.extend_from_slice(&v.to_le_bytes());
            }
            b.extend_from_slice(&i.to_le_bytes());
        }
        let loaded = read(&b[..]).unwrap();
        assert_eq!(loaded.cloud.points(), [Point3::new(0.5, 0.25, -1.0)]);
        assert_eq!(loaded.cloud.intensity().unwrap(), [6.0]);
        assert_eq!(loaded.report.dropped_non_finite, 1);
    }

    #[test]
    fn empty_cloud_round_trips() {
        let cloud = PointCloud::new().with_origin(Point3::new(1.0, 2.0, 3.0));
        for enc in [PlyEncoding::BinaryLittleEndian, PlyEncoding::Ascii] {
            assert_eq!(read(&to_bytes(&cloud, enc)[..]).unwrap().cloud, cloud);
        }
    }

    #[test]
    fn writer_header_is_as_documented() {
        let bytes = to_bytes(&sample(true, true, true), PlyEncoding::BinaryLittleEndian);
        let text = String::from_utf8_lossy(&bytes);
        let header: Vec<&str> = text.lines().take_while(|l| *l != "end_header").collect();
        assert_eq!(
            header,
            [
                "ply",
                "format binary_little_endian 1.0",
                "comment written by olmap",
                "comment olmap origin 0.30000000000000004 -1e-300 12345.678901234567",
                "element vertex 8",
                "property float x",
                "property float y",
                "property float z",
                "property float intensity",
                "property float nx",
                "property float ny",
                "property float nz",
                "property uchar red",
                "property uchar green",
                "property uchar blue",
            ]
        );
    }

    /// Big-endian doubles, with a `face` element (list properties) before `vertex` and an
    /// element after it whose data is missing (it must not be read).
    fn big_endian_with_faces() -> Vec<u8> {
        let mut b = b"ply\nformat binary_big_endian 1.0\ncomment made by hand\n\
            element face 2\nproperty list uchar int vertex_indices\nproperty uchar flags\n\
            element vertex 3\nproperty double x\nproperty double y\nproperty double z\n\
            property uchar red\nproperty uchar green\nproperty uchar blue\n\
            element edge 7\nproperty int vertex1\nproperty int vertex2\nend_header\n"
            .to_vec();
        for face in [&[0i32, 1, 2][..], &[2, 1, 0, 1]] {
            b.push(face.len() as u8);
            for &i in face {
                b.extend_from_slice(&i.to_be_bytes());
            }
            b.push(0xAB);
        }
        for (p, c) in [
            ([1.5f64, -2.0, 3.25], [255u8, 0, 7]),
            ([0.0, 1e3, -0.5], [1, 2, 3]),
            ([-7.75, 8.0, 9.5], [10, 20, 30]),
        ] {
            for v in p {
                b.extend_from_slice(&v.to_be_bytes());
            }
            b.extend_from_slice(&c);
        }
        b
    }

    #[test]
    fn big_endian_doubles_after_a_face_element() {
        let loaded = read(&big_endian_with_faces()[..]).unwrap();
        let c = &loaded.cloud;
        assert_eq!(
            c.points(),
            [
                Point3::new(1.5, -2.0, 3.25),
                Point3::new(0.0, 1e3, -0.5),
                Point3::new(-7.75, 8.0, 9.5)
            ]
        );
        assert_eq!(c.colors().unwrap(), [[255, 0, 7], [1, 2, 3], [10, 20, 30]]);
        assert!(c.intensity().is_none() && c.normals().is_none());
        assert_eq!(c.origin(), Point3::origin());
        assert_eq!(loaded.report.encoding, "binary_big_endian");
        assert_eq!(
            loaded.report.fields,
            ["x", "y", "z", "red", "green", "blue"]
        );
    }

    #[test]
    fn cloudcompare_style_ascii_with_crlf() {
        let text = "ply\r\nformat ascii 1.0\r\ncomment Created by CloudCompare v2.12.4\r\n\
            comment Created 2024-05-01T10:00:00\r\nobj_info Generated by CloudCompare!\r\n\
            element vertex 4\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\n\
            property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n\
            property float scalar_Intensity\r\nend_header\r\n\
            1.5 2.5 -3.25 255 128 0 0.75\r\n\
            -1 0 1e2 0 0 0 12\r\n\
            nan 1 2 3 4 5 6\r\n\
            4 1e39 6 9 9 9 -1.5\r\n";
        let loaded = read(text.as_bytes()).unwrap();
        let c = &loaded.cloud;
        assert_eq!(
            c.points(),
            [Point3::new(1.5, 2.5, -3.25), Point3::new(-1.0, 0.0, 100.0)]
        );
        assert_eq!(c.colors().unwrap(), [[255, 128, 0], [0, 0, 0]]);
        assert_eq!(c.intensity().unwrap(), [0.75, 12.0]);
        assert_eq!(loaded.report.records, 4);
        assert_eq!(loaded.report.dropped_non_finite, 2);
        assert_eq!(
            loaded.report.fields,
            ["x", "y", "z", "red", "green", "blue", "scalar_Intensity"]
        );
    }

    #[test]
    fn list_property_in_the_middle_of_binary_vertices() {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n\
            property float x\nproperty list uchar float extra\nproperty float y\n\
            property float z\nproperty double reflectance\nproperty float nx\n\
            property float ny\nproperty float nz\nend_header\n"
            .to_vec();
        let rows: [(f32, &[f32], f32, f32, f64); 3] = [
            (1.0, &[9.0, 8.0], 2.0, 3.0, 0.5),
            (4.0, &[], 5.0, 6.0, 1.5),
            (7.0, &[1.0, 2.0, 3.0, 4.0, 5.0], 8.0, 9.0, 2.5),
        ];
        for (x, list, y, z, r) in rows {
            b.extend_from_slice(&x.to_le_bytes());
            b.push(list.len() as u8);
            for v in list {
                b.extend_from_slice(&v.to_le_bytes());
            }
            for v in [y, z] {
                b.extend_from_slice(&v.to_le_bytes());
            }
            b.extend_from_slice(&r.to_le_bytes());
            for v in [0.0f32, 0.0, 1.0] {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        let loaded = read(&b[..]).unwrap();
        let c = &loaded.cloud;
        assert_eq!(
            c.points(),
            [
                Point3::new(1.0, 2.0, 3.0),
                Point3::new(4.0, 5.0, 6.0),
                Point3::new(7.0, 8.0, 9.0)
            ]
        );
        assert_eq!(c.intensity().unwrap(), [0.5, 1.5, 2.5]);
        assert_eq!(c.normals().unwrap(), [Vector3::z(); 3]);
        // The same data with a byte missing is truncated.
        b.pop();
        assert!(matches!(read(&b[..]), Err(ParseError::Truncated(_))));
    }

    #[test]
    fn ascii_lists_before_and_inside_vertices() {
        let text = "ply\nformat ascii 1.0\nelement face 2\nproperty list uchar int idx\n\
            element vertex 2\nproperty list int float junk\nproperty short x\n\
            property ushort y\nproperty char z\nproperty float red\nproperty float green\n\
            property float blue\nend_header\n3 0 1 2\n\n4 0 1 2 3\n\
            2 0.5 0.25 1 2 -3 1.0 0.5 2\n0 -1 65535 127 -1 0 0.1\n";
        let c = read(text.as_bytes()).unwrap().cloud;
        assert_eq!(
            c.points(),
            [
                Point3::new(1.0, 2.0, -3.0),
                Point3::new(-1.0, 65535.0, 127.0)
            ]
        );
        assert_eq!(c.colors().unwrap(), [[255, 128, 255], [0, 0, 26]]);
    }

    #[test]
    fn integer_colours_are_clamped() {
        let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n\
            property float y\nproperty float z\nproperty int red\nproperty ushort green\n\
            property char blue\nend_header\n0 0 0 -5 300 100\n";
        let c = read(text.as_bytes()).unwrap().cloud;
        assert_eq!(c.colors().unwrap(), [[0, 255, 100]]);
    }

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

    fn header_with(body: &str) -> Vec<u8> {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
             property float z\nend_header\n{body}"
        )
        .into_bytes()
    }

    fn invalid_at_line(r: Result<LoadedCloud, ParseError>) -> usize {
        match r {
            Err(ParseError::Invalid {
                at: Location::Line(n),
                ..
            }) => n,
            other => panic!("expected a line error, got {other:?}"),
        }
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

    #[test]
    fn bad_ascii_data_is_an_error_naming_the_line() {
        assert_eq!(invalid_at_line(read(&header_with("1 2 x\n")[..])), 8);
        assert_eq!(invalid_at_line(read(&header_with("1 2\n")[..])), 8);
        assert_eq!(invalid_at_line(read(&header_with("\n1 2 3 4\n")[..])), 9);
        assert!(matches!(
            read(&header_with("")[..]),
            Err(ParseError::Truncated(_))
        ));
    }

    /// Replaces text in the header of a PLY file, leaving the data as it is.
    fn edit_header(file: &[u8], from: &str, to: &str) -> Vec<u8> {
        let end = b"end_header\n";
        let split = file.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&file[..split]).unwrap();
        let mut out = header.replacen(from, to, 1).into_bytes();
        out.extend_from_slice(&file[split..]);
        out
    }

    #[test]
    fn truncated_and_lying_binary_data() {
        let full = to_bytes(&sample(true, true, true), PlyEncoding::BinaryLittleEndian);
        for cut in [1, 5, 27] {
            let r = read(&full[..full.len() - cut]);
            assert!(
                matches!(r, Err(ParseError::Truncated(_))),
                "cut {cut}: {r:?}"
            );
        }
        // A header claiming 10^12 vertices over a few bytes of data.
        let r = read(&edit_header(&full, "vertex 8", "vertex 1000000000000")[..]);
        assert!(matches!(r, Err(ParseError::Truncated(_))), "{r:?}");
        // The same in front of the vertices, with and without list properties.
        let be = big_endian_with_faces();
        for (from, to) in [
            ("face 2", "face 1000000000000"),
            ("face 2", "face 18446744073709551615"),
            ("vertex 3", "vertex 99999999999999"),
        ] {
            let r = read(&edit_header(&be, from, to)[..]);
            assert!(
                matches!(r, Err(ParseError::Truncated(_))),
                "{from} -> {to}: {r:?}"
            );
        }
        let fixed = "ply\nformat binary_little_endian 1.0\nelement pad 1000000000000\n\
            property double a\nelement vertex 1\nproperty float x\nproperty float y\n\
            property float z\nend_header\n0123456789";
        assert!(matches!(
            read(fixed.as_bytes()),
            Err(ParseError::Truncated(_))
        ));
    }

    #[test]
    fn negative_binary_list_count_is_an_error() {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement face 1\n\
            property list char int idx\nelement vertex 0\nproperty float x\n\
            property float y\nproperty float z\nend_header\n"
            .to_vec();
        let start = b.len() as u64;
        b.push(0xFF);
        match read(&b[..]) {
            Err(ParseError::Invalid {
                at: Location::Byte(n),
                ..
            }) => assert_eq!(n, start),
            other => panic!("{other:?}"),
        }
    }

    /// Applies byte mutations: (kind, position, value).
    fn mutate(bytes: &mut Vec<u8>, ops: &[(u8, usize, u8)]) {
        for &(kind, pos, val) in ops {
            let at = if bytes.is_empty() {
                0
            } else {
                pos % bytes.len()
            };
            match kind {
                0 if !bytes.is_empty() => bytes[at] ^= val.max(1),
                1 => bytes.insert(at, val),
                2 if !bytes.is_empty() => {
                    bytes.remove(at);
                }
                3 => bytes.truncate(at),
                _ => {}
            }
        }
    }

    fn seeds() -> [Vec<u8>; 3] {
        let cloud = sample(true, true, true);
        [
            to_bytes(&cloud, PlyEncoding::BinaryLittleEndian),
            to_bytes(&cloud, PlyEncoding::Ascii),
            big_endian_with_faces(),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(600))]

        #[test]
        fn mutated_files_never_panic(
            seed in 0usize..3,
            ops in prop::collection::vec((0u8..4, any::<usize>(), any::<u8>()), 1..6),
        ) {
            let mut bytes = seeds()[seed].clone();
            mutate(&mut bytes, &ops);
            let _ = read(&bytes[..]);
        }

        #[test]
        fn random_bytes_after_the_magic_never_panic(
            tail in prop::collection::vec(any::<u8>(), 0..300),
        ) {
            let mut bytes = b"ply\n".to_vec();
            bytes.extend_from_slice(&tail);
            let _ = read(&bytes[..]);
        }
    }
}
