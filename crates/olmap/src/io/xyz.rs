//! Plain-text XYZ point lists (`.xyz`, `.txt`, `.dat`, `.asc`, `.pts`).
//!
//! One point per line, `x y z` in metres, separated by whitespace, commas or semicolons;
//! numbers may use exponent notation (`2.84217e-14`). Further columns are ignored. Lines
//! starting with `#` and empty lines are skipped. As in 3DTK's `readASCII`, up to
//! [`MAX_HEADER_LINES`] unparseable lines are tolerated *before* the first point (header
//! lines such as `360 x 225` or `//X Y Z`); after the first point an unparseable line is an
//! error naming its line number. This reads OctoMap's `scan.dat` and most exports of
//! CloudCompare and MeshLab. The sensor origin is taken to be `(0, 0, 0)`.

use std::io::{BufRead, Write};

use super::{finite_point, CloudFormat, LoadedCloud, ReadReport};
use crate::cloud::PointCloud;
use crate::error::ParseError;
use crate::file::text::{fields, for_each_line, is_blank_or_comment, parse_f64};

/// How many unparseable lines may precede the first point.
pub const MAX_HEADER_LINES: usize = 10;

/// Parses the first three fields of a line as numbers.
pub(crate) fn first_three(line: &str) -> Option<[f64; 3]> {
    let mut it = fields(line);
    let mut p = [0.0; 3];
    for v in &mut p {
        *v = parse_f64(it.next()?.as_bytes())?;
    }
    Some(p)
}

/// Reads an XYZ text stream; `convert` maps the three numbers of each line to metres in
/// olmap's frame (identity for XYZ, the 3DTK conversion for `.3d`), and `keep` may reject a
/// point (counted as invalid).
pub(crate) fn read_with<R: BufRead>(
    reader: R,
    format: CloudFormat,
    mut keep: impl FnMut(&[f64; 3]) -> bool,
    convert: impl Fn([f64; 3]) -> [f64; 3],
) -> Result<LoadedCloud, ParseError> {
    let mut report = ReadReport::new(format);
    report.fields = vec!["x".into(), "y".into(), "z".into()];
    let mut points = Vec::new();
    let mut started = false;
    let mut any_line = false;
    for_each_line(reader, |line_no, line| {
        any_line = true;
        if is_blank_or_comment(line) {
            return Ok(());
        }
        match first_three(line) {
            Some(raw) => {
                started = true;
                report.records += 1;
                if !keep(&raw) {
                    report.dropped_invalid += 1;
                } else if let Some(p) = finite_point(convert(raw), &mut report) {
                    points.push(p);
                }
                Ok(())
            }
            None if !started && report.header_lines_skipped < MAX_HEADER_LINES => {
                report.header_lines_skipped += 1;
                Ok(())
            }
            None => Err(ParseError::line(
                line_no,
                format!(
                    "expected at least three numbers 'x y z', found '{}'",
                    truncate(line, 60)
                ),
            )),
        }
    })?;
    if !any_line {
        return Err(ParseError::Empty);
    }
    if !started {
        return Err(ParseError::Malformed(
            "no point found (no line starts with three numbers)".into(),
        ));
    }
    Ok(LoadedCloud {
        cloud: PointCloud::from_points(points),
        report,
    })
}

pub(crate) fn truncate(s: &str, n: usize) -> String {
    if s.chars().count() <= n {
        s.to_string()
    } else {
        format!("{}...", s.chars().take(n).collect::<String>())
    }
}

/// Reads an XYZ text stream.
pub fn read<R: BufRead>(reader: R) -> Result<LoadedCloud, ParseError> {
    read_with(reader, CloudFormat::Xyz, |_| true, |p| p)
}

/// Writes `x y z` lines (shortest round-trip decimal form: reading back is exact).
/// Attributes and the sensor origin are not stored.
pub fn write<W: Write>(mut w: W, cloud: &PointCloud) -> std::io::Result<()> {
    let mut line = String::with_capacity(64);
    for p in cloud.points() {
        line.clear();
        use std::fmt::Write as _;
        let _ = writeln!(line, "{} {} {}", p.x, p.y, p.z);
        w.write_all(line.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_mixed_separators_comments_and_header() {
        let text = "360 x 225\n//X Y Z\n# comment\n\n1,2,3\n4 5 6 7 8\n-1e-2;2.5E1;3\nnan 0 0\r\n";
        let l = read(text.as_bytes()).unwrap();
        assert_eq!(l.cloud.len(), 3);
        assert_eq!(l.report.header_lines_skipped, 2);
        assert_eq!(l.report.dropped_non_finite, 1);
        assert_eq!(l.report.records, 4);
        assert_eq!(l.cloud.points()[2], nalgebra::Point3::new(-0.01, 25.0, 3.0));
    }

    #[test]
    fn errors() {
        assert!(matches!(read(&b""[..]), Err(ParseError::Empty)));
        let e = read(&b"1 2 3\n4 five 6\n"[..]).unwrap_err();
        assert!(e.to_string().contains("line 2"), "{e}");
        let many_headers = "h\n".repeat(11) + "1 2 3\n";
        assert!(read(many_headers.as_bytes()).is_err());
        assert!(read(&b"# only a comment\n"[..]).is_err());
    }
}
