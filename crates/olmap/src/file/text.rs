//! Helpers shared by the text formats: line iteration, field splitting, number parsing.

use std::io::BufRead;

use crate::error::ParseError;

/// Calls `f(line_number, line)` for every line of a stream (1-based numbers, line end and a
/// trailing `\r` removed). Stops at the first error. A line that is not UTF-8 is an error
/// naming the line.
pub(crate) fn for_each_line<R: BufRead>(
    mut reader: R,
    mut f: impl FnMut(usize, &str) -> Result<(), ParseError>,
) -> Result<(), ParseError> {
    let mut buf = Vec::with_capacity(256);
    let mut line_no = 0usize;
    loop {
        buf.clear();
        let n = reader.read_until(b'\n', &mut buf)?;
        if n == 0 {
            return Ok(());
        }
        line_no += 1;
        let mut bytes = &buf[..];
        if let Some(rest) = bytes.strip_suffix(b"\n") {
            bytes = rest;
        }
        if let Some(rest) = bytes.strip_suffix(b"\r") {
            bytes = rest;
        }
        let line = std::str::from_utf8(bytes)
            .map_err(|_| ParseError::line(line_no, "not text (invalid UTF-8 bytes)"))?;
        f(line_no, line)?;
    }
}

/// Splits a line into fields separated by whitespace, commas or semicolons (runs of
/// separators count as one, so `1 , 2` gives two fields).
#[inline]
pub(crate) fn fields(line: &str) -> impl Iterator<Item = &str> {
    line.split(|c: char| c.is_ascii_whitespace() || c == ',' || c == ';')
        .filter(|s| !s.is_empty())
}

/// Parses a decimal number (exponent notation, `nan`, `inf` accepted).
#[inline]
pub(crate) fn parse_f64(bytes: &[u8]) -> Option<f64> {
    std::str::from_utf8(bytes).ok()?.trim().parse::<f64>().ok()
}

/// Whether a line holds nothing to parse: empty, blank, or a `#` comment.
#[inline]
pub(crate) fn is_blank_or_comment(line: &str) -> bool {
    let t = line.trim_start();
    t.is_empty() || t.starts_with('#')
}
