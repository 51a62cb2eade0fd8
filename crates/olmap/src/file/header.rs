//! The text header of a file format, read line by line: PCD's `KEY values` lines up to
//! `DATA`, PLY's lines up to `end_header`, OctoMap `.bt`'s up to `data`.
//!
//! [`HeaderLines`] reads one line at a time from a [`BufRead`] into a reused buffer, with a
//! cap on the bytes of a line (a binary file without line ends is not read whole into
//! memory), numbers the lines from 1, counts the bytes consumed (where the data after the
//! header starts), and hands out each line without its `\n` or `\r\n` end. It stops reading
//! where the caller stops asking, so after the end marker the stream is at the first data
//! byte. What a line means (keywords, end marker, which errors to give at the end of the
//! stream) stays with the format.

use std::io::{BufRead, Read};

use crate::error::ParseError;

/// Reads the lines of a text header from a stream, each at most `max_line` bytes long.
pub(crate) struct HeaderLines<'r, R> {
    reader: &'r mut R,
    buf: Vec<u8>,
    max_line: u64,
    too_long: &'static str,
    lines: usize,
    bytes: u64,
}

/// One header line: its number (1-based), its bytes without the `\n` or `\r\n` end, and
/// where it ends in the stream.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeaderLine<'a> {
    /// The line's number, counting from 1 at the start of the stream.
    pub number: usize,
    /// The line without its end (maybe not UTF-8).
    pub bytes: &'a [u8],
    /// The bytes of the stream up to and including this line's end: after the end marker,
    /// the offset of the first data byte.
    pub end: u64,
}

impl<'r, R: BufRead> HeaderLines<'r, R> {
    /// Reads header lines from `reader`. A line that reaches `max_line` bytes without its
    /// `\n` is an error at that line: `header line longer than <max_line>: <too_long>` (the
    /// size in KiB, or in MiB when it is a whole number of them).
    pub fn new(reader: &'r mut R, max_line: u64, too_long: &'static str) -> Self {
        HeaderLines {
            reader,
            buf: Vec::with_capacity(256),
            max_line,
            too_long,
            lines: 0,
            bytes: 0,
        }
    }

    /// The next line; `None` at the end of the stream (nothing is consumed then).
    pub fn next_line(&mut self) -> Result<Option<HeaderLine<'_>>, ParseError> {
        self.buf.clear();
        let n = (&mut *self.reader)
            .take(self.max_line)
            .read_until(b'\n', &mut self.buf)? as u64;
        if n == 0 {
            return Ok(None);
        }
        self.lines += 1;
        self.bytes += n;
        if n == self.max_line && self.buf.last() != Some(&b'\n') {
            return Err(ParseError::line(
                self.lines,
                format!(
                    "header line longer than {}: {}",
                    size_name(self.max_line),
                    self.too_long
                ),
            ));
        }
        let line = self.buf.strip_suffix(b"\n").unwrap_or(&self.buf);
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        Ok(Some(HeaderLine {
            number: self.lines,
            bytes: line,
            end: self.bytes,
        }))
    }

    /// The lines read so far (the number of the last one).
    pub fn lines(&self) -> usize {
        self.lines
    }
}

impl<'a> HeaderLine<'a> {
    /// The line as text, or an error at the line with `not_text` as its reason.
    pub fn text(self, not_text: &'static str) -> Result<&'a str, ParseError> {
        std::str::from_utf8(self.bytes).map_err(|_| ParseError::line(self.number, not_text))
    }

    /// The words of the line: its pieces between runs of ASCII whitespace.
    pub fn words(self) -> impl Iterator<Item = &'a [u8]> {
        self.bytes
            .split(u8::is_ascii_whitespace)
            .filter(|w| !w.is_empty())
    }

    /// Whether the line is a `#` comment (its first byte that is not whitespace is `#`).
    pub fn is_comment(self) -> bool {
        self.bytes.trim_ascii_start().starts_with(b"#")
    }
}

/// A line-length cap for messages: `1 MiB`, `64 KiB`.
fn size_name(bytes: u64) -> String {
    if bytes >= 1 << 20 && bytes.is_multiple_of(1 << 20) {
        format!("{} MiB", bytes >> 20)
    } else {
        format!("{} KiB", bytes / 1024)
    }
}

/// A short printable form of some bytes for error messages: the first 40 bytes (lossy
/// UTF-8), then `...` if there were more.
pub(crate) fn clip(bytes: &[u8]) -> String {
    let s = String::from_utf8_lossy(&bytes[..bytes.len().min(40)]).into_owned();
    if bytes.len() > 40 {
        s + "..."
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Location;

    /// Lines as `(number, bytes)`.
    type Numbered = Vec<(usize, Vec<u8>)>;

    /// Every line of `text`, and the end of the last one, or the error.
    fn all_lines(text: &[u8], max_line: u64) -> Result<(Numbered, u64), ParseError> {
        let mut r = text;
        let mut lines = HeaderLines::new(&mut r, max_line, "expected a header line");
        let mut out = Vec::new();
        let mut end = 0;
        while let Some(line) = lines.next_line()? {
            out.push((line.number, line.bytes.to_vec()));
            end = line.end;
        }
        Ok((out, end))
    }

    #[test]
    fn numbers_lines_trims_their_ends_and_counts_bytes() {
        let (lines, bytes) = all_lines(b"ply\r\nformat x\n\n  # c\r\r\nlast", 64).unwrap();
        let expected: [(usize, &[u8]); 5] = [
            (1, b"ply"),
            (2, b"format x"),
            (3, b""),
            (4, b"  # c\r"),
            (5, b"last"),
        ];
        assert_eq!(lines.len(), expected.len());
        for ((n, b), (en, eb)) in lines.iter().zip(expected) {
            assert_eq!((*n, &b[..]), (en, eb));
        }
        assert_eq!(bytes, 27);
        assert_eq!(all_lines(b"", 64).unwrap().0.len(), 0);
    }

    #[test]
    fn stops_after_the_line_asked_for() {
        let mut r = &b"head\nDATA\n\x00\x01binary"[..];
        let mut lines = HeaderLines::new(&mut r, 64, "x");
        let mut end = 0;
        while let Some(line) = lines.next_line().unwrap() {
            if line.bytes == b"DATA" {
                end = line.end;
                break;
            }
        }
        assert_eq!(end, 10);
        assert_eq!(lines.lines(), 2);
        assert_eq!(r, b"\x00\x01binary");
    }

    #[test]
    fn a_line_at_the_cap_without_its_end_is_an_error_at_that_line() {
        // 9 bytes and the '\n': within a cap of 10.
        assert!(all_lines(b"ok\n123456789\n", 10).is_ok());
        for (cap, size) in [(10u64, "0 KiB"), (64 * 1024, "64 KiB"), (1 << 20, "1 MiB")] {
            let mut text = b"ok\n".to_vec();
            text.extend(std::iter::repeat_n(b'a', cap as usize));
            match all_lines(&text, cap) {
                Err(ParseError::Invalid {
                    at: Location::Line(2),
                    reason,
                }) => assert_eq!(
                    reason,
                    format!("header line longer than {size}: expected a header line")
                ),
                other => panic!("{other:?}"),
            }
        }
    }

    #[test]
    fn text_words_and_comments() {
        let line = HeaderLine {
            number: 7,
            bytes: b" \tsize  12 \x0c",
            end: 0,
        };
        assert_eq!(line.text("not text").unwrap(), " \tsize  12 \x0c");
        assert_eq!(line.words().collect::<Vec<_>>(), [&b"size"[..], b"12"]);
        assert!(!line.is_comment());
        let comment = HeaderLine {
            number: 8,
            bytes: b"  #\xff",
            end: 0,
        };
        assert!(comment.is_comment());
        match comment.text("not text") {
            Err(ParseError::Invalid {
                at: Location::Line(8),
                reason,
            }) => assert_eq!(reason, "not text"),
            other => panic!("{other:?}"),
        }
        assert_eq!(clip(b"short"), "short");
        assert_eq!(clip(&[b'a'; 41]), format!("{}...", "a".repeat(40)));
    }
}
