//! Bounds-checked readers of little-endian values for the binary formats: [`ByteCursor`]
//! over a byte slice, [`StreamCursor`] over a stream (the file is never held whole in
//! memory, and nothing is allocated for bytes that are not there).

use std::io::{BufRead, ErrorKind};

use crate::error::{Location, ParseError};
use crate::file::crc32::Crc32;

/// Reads little-endian values from a slice; running past the end is
/// [`ParseError::Truncated`] naming what was being read and where.
pub(crate) struct ByteCursor<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> ByteCursor<'a> {
    /// A cursor at the start of `data`.
    pub fn new(data: &'a [u8]) -> Self {
        ByteCursor { data, pos: 0 }
    }

    /// A cursor over `data` starting at byte `pos` (positions stay those of `data`).
    pub fn new_at(data: &'a [u8], pos: usize) -> Self {
        ByteCursor {
            data,
            pos: pos.min(data.len()),
        }
    }

    /// Bytes consumed so far.
    pub fn pos(&self) -> usize {
        self.pos
    }

    /// Bytes left.
    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ParseError> {
        if self.remaining() < n {
            return Err(ParseError::Truncated(format!(
                "{what} at byte {} needs {n} bytes, only {} left",
                self.pos,
                self.remaining()
            )));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    /// The next fixed-size array of bytes.
    pub fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], ParseError> {
        Ok(self.take(N, what)?.try_into().expect("N bytes taken"))
    }

    /// A little-endian `u32`.
    pub fn u32(&mut self, what: &str) -> Result<u32, ParseError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    /// A little-endian `u64`.
    pub fn u64(&mut self, what: &str) -> Result<u64, ParseError> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }

    /// A little-endian `f64`.
    pub fn f64(&mut self, what: &str) -> Result<f64, ParseError> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }
}

/// Reads little-endian values from a [`BufRead`], counting the bytes consumed and keeping
/// a running CRC-32 of them; running past the end of the stream is
/// [`ParseError::Truncated`] naming what was being read and where.
pub(crate) struct StreamCursor<R> {
    reader: R,
    pos: u64,
    crc: Crc32,
}

impl<R: BufRead> StreamCursor<R> {
    /// A cursor at the start of `reader` (byte 0).
    pub fn new(reader: R) -> Self {
        StreamCursor {
            reader,
            pos: 0,
            crc: Crc32::default(),
        }
    }

    /// Bytes consumed so far.
    pub fn pos(&self) -> u64 {
        self.pos
    }

    /// The CRC-32 of every byte consumed so far.
    pub fn crc(&self) -> u32 {
        self.crc.finish()
    }

    /// Whether the stream has ended (nothing is consumed).
    pub fn at_end(&mut self) -> Result<bool, ParseError> {
        Ok(self.buffer()?.is_empty())
    }

    /// The reader's buffered bytes (empty at the end of the stream).
    fn buffer(&mut self) -> Result<&[u8], ParseError> {
        loop {
            match self.reader.fill_buf() {
                Ok(_) => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(e.into()),
            }
        }
        Ok(self.reader.fill_buf()?)
    }

    /// Marks `n` buffered bytes as read.
    fn consume(&mut self, n: usize) {
        if let Ok(buf) = self.reader.fill_buf() {
            self.crc.update(&buf[..n.min(buf.len())]);
        }
        self.reader.consume(n);
        self.pos += n as u64;
    }

    fn truncated(&self, what: &str, start: u64, needed: u64) -> ParseError {
        let needed = match needed {
            1 => "1 byte".to_string(),
            n => format!("{n} bytes"),
        };
        ParseError::Truncated(if self.pos == start {
            format!("the file ends at byte {start}, where the {what} ({needed}) should start")
        } else {
            format!(
                "the file ends at byte {}, inside the {what} ({needed}) that starts at byte \
                 {start}",
                self.pos
            )
        })
    }

    /// Fills `out` from the stream.
    pub fn fill(&mut self, out: &mut [u8], what: &str) -> Result<(), ParseError> {
        let start = self.pos;
        let mut got = 0;
        while got < out.len() {
            let buf = self.buffer()?;
            if buf.is_empty() {
                return Err(self.truncated(what, start, out.len() as u64));
            }
            let n = buf.len().min(out.len() - got);
            out[got..got + n].copy_from_slice(&buf[..n]);
            self.consume(n);
            got += n;
        }
        Ok(())
    }

    /// Replaces `buf`'s contents with the next `len` bytes, growing it as they arrive
    /// (nothing is reserved for bytes that are not there); `false` when the stream ends
    /// first (`buf` then holds what there was).
    pub fn read_vec(&mut self, buf: &mut Vec<u8>, len: u64) -> Result<bool, ParseError> {
        buf.clear();
        while (buf.len() as u64) < len {
            let chunk = self.buffer()?;
            if chunk.is_empty() {
                return Ok(false);
            }
            let n = chunk
                .len()
                .min((len - buf.len() as u64).min(usize::MAX as u64) as usize);
            buf.extend_from_slice(&chunk[..n]);
            self.consume(n);
        }
        Ok(true)
    }

    /// Fills `out` from the stream; `false` when the stream ends first.
    pub fn read_exact_or_end(&mut self, out: &mut [u8]) -> Result<bool, ParseError> {
        let mut got = 0;
        while got < out.len() {
            let buf = self.buffer()?;
            if buf.is_empty() {
                return Ok(false);
            }
            let n = buf.len().min(out.len() - got);
            out[got..got + n].copy_from_slice(&buf[..n]);
            self.consume(n);
            got += n;
        }
        Ok(true)
    }

    /// The next fixed-size array of bytes.
    pub fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], ParseError> {
        let mut out = [0u8; N];
        self.fill(&mut out, what)?;
        Ok(out)
    }

    /// A little-endian `u32`.
    pub fn u32(&mut self, what: &str) -> Result<u32, ParseError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    /// A little-endian `u64`.
    pub fn u64(&mut self, what: &str) -> Result<u64, ParseError> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }

    /// A little-endian `f64`.
    pub fn f64(&mut self, what: &str) -> Result<f64, ParseError> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    /// An unsigned LEB128 varint of at most 10 bytes.
    pub fn varint(&mut self, what: &str) -> Result<u64, ParseError> {
        let start = self.pos;
        // Fast path: the whole varint is in the buffer.
        let buf = self.buffer()?;
        if buf.len() >= 10 {
            let mut v = 0u64;
            for (k, &b) in buf[..10].iter().enumerate() {
                v |= ((b & 0x7F) as u64) << (7 * k);
                if b & 0x80 == 0 {
                    self.consume(k + 1);
                    return Ok(v);
                }
            }
            return Err(ParseError::at(
                Location::Byte(start),
                format!("{what}: varint longer than 10 bytes"),
            ));
        }
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.array::<1>(what)?[0];
            v |= ((b & 0x7F) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(ParseError::at(
            Location::Byte(start),
            format!("{what}: varint longer than 10 bytes"),
        ))
    }

    /// Reads the rest of the stream, returning how many bytes it held.
    pub fn count_rest(&mut self) -> Result<u64, ParseError> {
        let mut total = 0u64;
        loop {
            let n = self.buffer()?.len();
            if n == 0 {
                return Ok(total);
            }
            self.consume(n);
            total += n as u64;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stream_cursor_reads_what_byte_cursor_reads() {
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&7u32.to_le_bytes());
        bytes.extend_from_slice(&(-2.5f64).to_le_bytes());
        bytes.extend_from_slice(&[0xAC, 0x02]); // 300
        bytes.extend_from_slice(&u64::MAX.to_le_bytes());
        // A reader that hands out one byte at a time exercises the slow paths.
        let one_at_a_time = std::io::BufReader::with_capacity(1, &bytes[..]);
        for mut c in [
            StreamCursor::new(Box::new(&bytes[..]) as Box<dyn BufRead>),
            StreamCursor::new(Box::new(one_at_a_time) as Box<dyn BufRead>),
        ] {
            assert_eq!(c.u32("a").unwrap(), 7);
            assert_eq!(c.f64("b").unwrap(), -2.5);
            assert_eq!(c.varint("c").unwrap(), 300);
            assert_eq!(c.pos(), 14);
            assert_eq!(c.crc(), crate::file::crc32::crc32(&bytes[..14]));
            assert!(!c.at_end().unwrap());
            assert_eq!(c.u64("d").unwrap(), u64::MAX);
            assert!(c.at_end().unwrap());
            match c.u32("node id") {
                Err(ParseError::Truncated(m)) => {
                    assert!(m.contains("byte 22") && m.contains("node id"), "{m}")
                }
                other => panic!("{other:?}"),
            }
            assert_eq!(c.count_rest().unwrap(), 0);
        }
        let long = [0xFFu8; 12];
        assert!(StreamCursor::new(&long[..]).varint("v").is_err());
        assert!(
            StreamCursor::new(std::io::BufReader::with_capacity(1, &long[..]))
                .varint("v")
                .is_err()
        );
    }
}
