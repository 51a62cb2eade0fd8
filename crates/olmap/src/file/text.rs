//! Helpers shared by the text formats: line iteration with a cap on the length of a line,
//! field splitting, number parsing.

use std::io::{BufRead, Read};

use crate::error::ParseError;

/// The longest line a text reader accepts, its `\n` included: 1 MiB. No text format olmap
/// reads has lines anywhere near it (a point is tens of bytes, a mirror-log sweep of a
/// thousand beams about 20 KiB), so a longer line is not text of the format (a binary file,
/// `/dev/zero`), and reading stops there instead of growing one line without bound.
pub const MAX_LINE_BYTES: u64 = 1 << 20;

/// Appends the next line of `reader` (its `\n` included, if any) to `buf` and returns its
/// length in bytes, 0 at the end of the stream. `line_no` is the 1-based number of the line
/// being read, for the error when the line reaches [`MAX_LINE_BYTES`] without its end.
pub(crate) fn read_line_capped<R: BufRead>(
    reader: &mut R,
    buf: &mut Vec<u8>,
    line_no: usize,
) -> Result<usize, ParseError> {
    let start = buf.len();
    let n = reader
        .by_ref()
        .take(MAX_LINE_BYTES)
        .read_until(b'\n', buf)?;
    if n as u64 == MAX_LINE_BYTES && buf[start..].last() != Some(&b'\n') {
        return Err(line_too_long(line_no));
    }
    Ok(n)
}

/// The error for a line of [`MAX_LINE_BYTES`] or more.
pub(crate) fn line_too_long(line_no: usize) -> ParseError {
    ParseError::line(
        line_no,
        format!(
            "longer than {} MiB without a line end: not a line of text",
            MAX_LINE_BYTES >> 20
        ),
    )
}

/// Calls `f(line_number, line)` for every line of a stream (1-based numbers, line end and a
/// trailing `\r` removed). Stops at the first error. A line that is not UTF-8, or longer
/// than [`MAX_LINE_BYTES`], is an error naming the line.
pub(crate) fn for_each_line<R: BufRead>(
    mut reader: R,
    mut f: impl FnMut(usize, &str) -> Result<(), ParseError>,
) -> Result<(), ParseError> {
    let mut buf = Vec::with_capacity(256);
    let mut line_no = 0usize;
    loop {
        buf.clear();
        let n = read_line_capped(&mut reader, &mut buf, line_no + 1)?;
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

/// serde_json's message without its trailing " at line L column C", for errors that give
/// the line (and column) themselves.
pub(crate) fn json_message(e: &serde_json::Error) -> String {
    let text = e.to_string();
    let tail = format!(" at line {} column {}", e.line(), e.column());
    text.strip_suffix(&tail).unwrap_or(&text).to_string()
}
