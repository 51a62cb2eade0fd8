//! Reading a PLY file: the entry point and the ascii data.

use std::io::BufRead;

use super::binary::read_binary;
use super::header::{parse_header, Element, Encoding, Header, Kind, Scalar};
use super::vertex::{Builder, Plan, SLOTS};
use crate::error::ParseError;
use crate::file::header::clip;
use crate::file::text::read_line_capped;
use crate::io::{CloudFormat, LoadedCloud, ReadReport};

/// Reads a PLY point cloud (the `vertex` element) from a stream.
///
/// Accepts the `ascii`, `binary_little_endian` and `binary_big_endian` encodings; see the
/// [module documentation](super) for the properties understood and the quirks handled.
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
            if read_line_capped(&mut self.r, &mut self.buf, self.line_no + 1)? == 0 {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::ply::tests::invalid_at_line;
    use nalgebra::Point3;

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

    fn header_with(body: &str) -> Vec<u8> {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
             property float z\nend_header\n{body}"
        )
        .into_bytes()
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
}
