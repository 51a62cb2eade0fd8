//! OMG CDR (XCDR version 1), the wire encoding of ROS 2 messages.
//!
//! A serialised message starts with a 4-byte encapsulation header: `00 00` (big-endian
//! plain CDR) or `00 01` (little-endian), then two option bytes. Every primitive is
//! aligned to its own size (8-byte types to 8) counted from the end of that header.
//! Strings are a `uint32` length that includes a terminating NUL, then the bytes;
//! sequences are a `uint32` count then the elements; fixed arrays are the elements alone.

/// What went wrong while decoding CDR bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    /// The bytes end before the value does.
    #[error("the message ends early: {what} needs {need} bytes at offset {at}, {have} left")]
    Truncated {
        /// The value being read.
        what: &'static str,
        /// Bytes needed.
        need: usize,
        /// Offset in the payload (after the encapsulation header).
        at: usize,
        /// Bytes left.
        have: usize,
    },
    /// The encapsulation header names an encoding other than plain CDR.
    #[error("unsupported CDR encapsulation {0:#06x} (plain CDR, 0x0000 or 0x0001, expected)")]
    Encapsulation(u16),
    /// A string is not valid UTF-8 or lacks its terminating NUL.
    #[error("a string at offset {at} is malformed: {reason}")]
    BadString {
        /// Offset of the string's length.
        at: usize,
        /// What is wrong.
        reason: &'static str,
    },
    /// A length or count larger than the bytes that remain could hold.
    #[error("a {what} of {count} elements at offset {at} cannot fit in the {have} bytes left")]
    CountTooLarge {
        /// What was being counted.
        what: &'static str,
        /// The count the message claims.
        count: u64,
        /// Offset of the count.
        at: usize,
        /// Bytes left.
        have: usize,
    },
}

/// A cursor over one CDR-encoded message.
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    body: &'a [u8],
    pos: usize,
    little: bool,
}

macro_rules! read_prim {
    ($name:ident, $t:ty, $n:expr) => {
        #[doc = concat!("Reads an aligned `", stringify!($t), "`.")]
        pub fn $name(&mut self) -> Result<$t, CdrError> {
            let b = self.take_aligned::<$n>(stringify!($t))?;
            Ok(if self.little {
                <$t>::from_le_bytes(b)
            } else {
                <$t>::from_be_bytes(b)
            })
        }
    };
}

impl<'a> CdrReader<'a> {
    /// A reader over a whole serialised message, encapsulation header included.
    pub fn new(message: &'a [u8]) -> Result<Self, CdrError> {
        if message.len() < 4 {
            return Err(CdrError::Truncated {
                what: "the encapsulation header",
                need: 4,
                at: 0,
                have: message.len(),
            });
        }
        let kind = u16::from_be_bytes([message[0], message[1]]);
        let little = match kind {
            0x0000 => false,
            0x0001 => true,
            other => return Err(CdrError::Encapsulation(other)),
        };
        Ok(CdrReader {
            body: &message[4..],
            pos: 0,
            little,
        })
    }

    /// Whether the payload is little-endian.
    pub fn is_little_endian(&self) -> bool {
        self.little
    }

    /// The offset in the payload (after the encapsulation header).
    pub fn position(&self) -> usize {
        self.pos
    }

    /// Bytes not yet read.
    pub fn remaining(&self) -> usize {
        self.body.len() - self.pos
    }

    /// Skips padding up to a multiple of `n`.
    pub fn align(&mut self, n: usize) -> Result<(), CdrError> {
        let pad = (n - self.pos % n) % n;
        if pad > self.remaining() {
            return Err(CdrError::Truncated {
                what: "alignment padding",
                need: pad,
                at: self.pos,
                have: self.remaining(),
            });
        }
        self.pos += pad;
        Ok(())
    }

    fn take_aligned<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], CdrError> {
        self.align(N)?;
        let bytes = self.bytes(N, what)?;
        let mut out = [0u8; N];
        out.copy_from_slice(bytes);
        Ok(out)
    }

    /// The next `n` raw bytes (no alignment).
    pub fn bytes(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], CdrError> {
        if n > self.remaining() {
            return Err(CdrError::Truncated {
                what,
                need: n,
                at: self.pos,
                have: self.remaining(),
            });
        }
        let out = &self.body[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    read_prim!(u16, u16, 2);
    read_prim!(u32, u32, 4);
    read_prim!(u64, u64, 8);
    read_prim!(i16, i16, 2);
    read_prim!(i32, i32, 4);
    read_prim!(i64, i64, 8);
    read_prim!(f32, f32, 4);
    read_prim!(f64, f64, 8);

    /// Reads one byte.
    pub fn u8(&mut self) -> Result<u8, CdrError> {
        Ok(self.bytes(1, "uint8")?[0])
    }

    /// Reads a signed byte.
    pub fn i8(&mut self) -> Result<i8, CdrError> {
        Ok(self.u8()? as i8)
    }

    /// Reads a boolean (any non-zero byte is true).
    pub fn bool(&mut self) -> Result<bool, CdrError> {
        Ok(self.u8()? != 0)
    }

    /// Reads a sequence length and checks that that many elements of at least `min_size`
    /// bytes each (at least 1) can fit in what is left, so a corrupt count never drives an
    /// allocation.
    pub fn count(&mut self, what: &'static str, min_size: usize) -> Result<usize, CdrError> {
        let at = self.pos;
        let n = self.u32()? as u64;
        if n.saturating_mul(min_size.max(1) as u64) > self.remaining() as u64 {
            return Err(CdrError::CountTooLarge {
                what,
                count: n,
                at,
                have: self.remaining(),
            });
        }
        Ok(n as usize)
    }

    /// Reads a string (`uint32` length including the NUL, bytes, NUL).
    pub fn string(&mut self) -> Result<&'a str, CdrError> {
        let at = self.pos;
        let n = self.count("string", 1)?;
        let raw = self.bytes(n, "string")?;
        // A zero length is tolerated as the empty string (some writers emit it).
        let text = match raw.split_last() {
            None => &[][..],
            Some((0, text)) => text,
            Some(_) => {
                return Err(CdrError::BadString {
                    at,
                    reason: "no terminating NUL",
                })
            }
        };
        std::str::from_utf8(text).map_err(|_| CdrError::BadString {
            at,
            reason: "not UTF-8",
        })
    }

    /// Reads a `uint8[]` sequence as a slice of the message.
    pub fn byte_sequence(&mut self) -> Result<&'a [u8], CdrError> {
        let n = self.count("uint8 sequence", 1)?;
        self.bytes(n, "uint8 sequence")
    }

    /// Reads a `float32[]` sequence.
    pub fn f32_sequence(&mut self) -> Result<Vec<f32>, CdrError> {
        let n = self.count("float32 sequence", 4)?;
        (0..n).map(|_| self.f32()).collect()
    }

    /// Reads `N` consecutive `float64`s.
    pub fn f64_array<const N: usize>(&mut self) -> Result<[f64; N], CdrError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64()?;
        }
        Ok(out)
    }
}

/// Builds a little-endian CDR message (encapsulation header `00 01 00 00`).
#[derive(Debug, Clone, Default)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

macro_rules! write_prim {
    ($name:ident, $t:ty) => {
        #[doc = concat!("Writes an aligned `", stringify!($t), "`.")]
        pub fn $name(&mut self, v: $t) {
            self.align(std::mem::size_of::<$t>());
            self.buf.extend_from_slice(&v.to_le_bytes());
        }
    };
}

impl CdrWriter {
    /// An empty little-endian message.
    pub fn new() -> Self {
        CdrWriter {
            buf: vec![0, 1, 0, 0],
        }
    }

    /// Pads with zeros to a multiple of `n` (counted after the encapsulation header).
    pub fn align(&mut self, n: usize) {
        let pos = self.buf.len() - 4;
        let pad = (n - pos % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    write_prim!(u16, u16);
    write_prim!(u32, u32);
    write_prim!(u64, u64);
    write_prim!(i32, i32);
    write_prim!(f32, f32);
    write_prim!(f64, f64);

    /// Writes one byte.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// Writes a boolean.
    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    /// Writes a string with its terminating NUL.
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// Writes raw bytes (no alignment).
    pub fn bytes(&mut self, b: &[u8]) {
        self.buf.extend_from_slice(b);
    }

    /// The message bytes.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_values_read_back_with_their_alignment() {
        let mut w = CdrWriter::new();
        w.u8(7);
        w.f64(1.5);
        w.string("odom");
        w.u16(3);
        w.f32(-2.25);
        let bytes = w.finish();
        // u8 at 0, f64 padded to 8, string length at 16, "odom\0" 20..25, u16 at 26, f32 at 28.
        assert_eq!(bytes.len(), 4 + 32);
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.u8().unwrap(), 7);
        assert_eq!(r.f64().unwrap(), 1.5);
        assert_eq!(r.string().unwrap(), "odom");
        assert_eq!(r.u16().unwrap(), 3);
        assert_eq!(r.f32().unwrap(), -2.25);
        assert_eq!(r.remaining(), 0);
    }

    #[test]
    fn big_endian_payloads_read_too() {
        let bytes = [0, 0, 0, 0, 0, 0, 0, 2, 0x3f, 0x80, 0, 0];
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.u32().unwrap(), 2);
        assert_eq!(r.f32().unwrap(), 1.0);
    }

    #[test]
    fn a_count_past_the_end_is_refused_before_allocating() {
        let bytes = [0, 1, 0, 0, 0xff, 0xff, 0xff, 0x7f];
        let mut r = CdrReader::new(&bytes).unwrap();
        assert!(matches!(
            r.f32_sequence(),
            Err(CdrError::CountTooLarge {
                count: 0x7fff_ffff,
                ..
            })
        ));
        let mut r = CdrReader::new(&[0, 1, 0, 0, 9, 0, 0, 0, b'a']).unwrap();
        assert!(matches!(r.string(), Err(CdrError::CountTooLarge { .. })));
        assert!(matches!(
            CdrReader::new(&[0, 7, 0, 0]),
            Err(CdrError::Encapsulation(7))
        ));
    }
}
