//! A bounds-checked reader over a byte slice, for the binary formats.

use crate::error::{Location, ParseError};

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

    /// An unsigned LEB128 varint of at most 10 bytes.
    pub fn varint(&mut self, what: &str) -> Result<u64, ParseError> {
        let start = self.pos;
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.array::<1>(what)?[0];
            v |= ((b & 0x7F) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(ParseError::at(
            Location::Byte(start as u64),
            format!("{what}: varint longer than 10 bytes"),
        ))
    }
}
