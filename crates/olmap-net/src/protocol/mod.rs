//! The wire protocol: key expressions ([`Keys`]), the payload envelope ([`seal`],
//! [`open`]) and the messages inside it ([`RecordMessage`], [`Digest`], [`FetchRequest`]).
//! The crate documentation lays the whole protocol out.

mod digest;
mod frame;
mod keys;
mod occupancy;
mod record;

pub use digest::{Digest, FetchRequest, RobotHoldings, MAX_FETCH};
pub use frame::{open, seal, Kind, ENVELOPE_BYTES, MAGIC, VERSION};
pub use keys::{check_name, Keys};
pub use occupancy::{as_keys, occupancy_list, put_keys, MAX_VOXELS};
pub use record::RecordMessage;

/// A little-endian reader over a message body that never reads past its end.
pub(crate) struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Reader { bytes, pos: 0 }
    }

    pub(crate) fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    pub(crate) fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        if n > self.remaining() {
            return Err(format!(
                "{what}: {n} bytes wanted at byte {}, {} left",
                self.pos,
                self.remaining()
            ));
        }
        let out = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    pub(crate) fn u16(&mut self, what: &str) -> Result<u16, String> {
        Ok(u16::from_le_bytes(
            self.take(2, what)?.try_into().expect("2"),
        ))
    }

    pub(crate) fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(
            self.take(4, what)?.try_into().expect("4"),
        ))
    }

    /// A count of items of `each` bytes, refused when the rest cannot hold them.
    pub(crate) fn count(&mut self, each: usize, cap: usize, what: &str) -> Result<usize, String> {
        let n = self.u32(what)? as usize;
        if n > cap {
            return Err(format!("{n} {what}, over the cap of {cap}"));
        }
        if n.saturating_mul(each) > self.remaining() {
            return Err(format!(
                "{n} {what} announced but only {} bytes follow",
                self.remaining()
            ));
        }
        Ok(n)
    }

    pub(crate) fn name(&mut self, what: &str) -> Result<String, String> {
        let n = self.u16(what)? as usize;
        let bytes = self.take(n, what)?;
        let s = std::str::from_utf8(bytes).map_err(|_| format!("{what} is not UTF-8"))?;
        check_name(s).map_err(|e| format!("{what}: {e}"))?;
        Ok(s.to_string())
    }

    pub(crate) fn finish(&self, what: &str) -> Result<(), String> {
        if self.remaining() != 0 {
            return Err(format!(
                "{} bytes left over after the {what}",
                self.remaining()
            ));
        }
        Ok(())
    }
}

pub(crate) fn put_name(out: &mut Vec<u8>, name: &str) {
    let bytes = &name.as_bytes()[..name.len().min(u16::MAX as usize)];
    out.extend_from_slice(&(bytes.len() as u16).to_le_bytes());
    out.extend_from_slice(bytes);
}
