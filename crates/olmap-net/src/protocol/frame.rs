//! The envelope every olmap-net payload travels in: magic, version, kind, length and a
//! CRC-32, checked before anything inside is read.

use crate::error::BadMessage;

/// The 4 bytes every olmap-net payload starts with.
pub const MAGIC: &[u8; 4] = b"OLNT";
/// The wire-format version this olmap writes and reads.
pub const VERSION: u8 = 1;
/// Bytes around a payload's body: magic 4, version 1, kind 1, reserved 2, length 4, CRC 4.
pub const ENVELOPE_BYTES: usize = 16;

/// What a payload holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Kind {
    /// One scan record ([`crate::protocol::RecordMessage`]).
    Record = 1,
    /// What a node holds ([`crate::protocol::Digest`]).
    Digest = 2,
    /// A request for records ([`crate::protocol::FetchRequest`]).
    Fetch = 3,
    /// A node's status, JSON ([`crate::status::NodeStatus`]).
    Status = 4,
}

impl Kind {
    fn from_byte(b: u8) -> Option<Kind> {
        match b {
            1 => Some(Kind::Record),
            2 => Some(Kind::Digest),
            3 => Some(Kind::Fetch),
            4 => Some(Kind::Status),
            _ => None,
        }
    }
}

/// Wraps `body` in the envelope:
/// ```text
/// magic    4 bytes "OLNT"
/// version  u8      1
/// kind     u8      1 record, 2 digest, 3 fetch, 4 status
/// reserved u16     0
/// length   u32     bytes of the body
/// body     length bytes
/// crc      u32     CRC-32 (IEEE) of every byte before it
/// ```
/// All numbers little-endian.
pub fn seal(kind: Kind, body: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(body.len() + ENVELOPE_BYTES);
    out.extend_from_slice(MAGIC);
    out.push(VERSION);
    out.push(kind as u8);
    out.extend_from_slice(&0u16.to_le_bytes());
    // A body over 4 GiB is refused by every receiver's size cap long before this.
    out.extend_from_slice(&(body.len().min(u32::MAX as usize) as u32).to_le_bytes());
    out.extend_from_slice(body);
    let crc = olmap::file::crc32::crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// Checks a payload's envelope against the kind expected on its key and the size cap, and
/// returns its body. Checks, in order: size, magic, version, kind, length, checksum.
pub fn open(payload: &[u8], expected: Kind, max_bytes: usize) -> Result<&[u8], BadMessage> {
    if payload.len() > max_bytes {
        return Err(BadMessage::Oversized {
            bytes: payload.len(),
            max: max_bytes,
        });
    }
    if payload.len() < ENVELOPE_BYTES {
        return Err(BadMessage::Truncated(format!(
            "{} bytes, shorter than the {ENVELOPE_BYTES}-byte envelope",
            payload.len()
        )));
    }
    if &payload[..4] != MAGIC {
        return Err(BadMessage::Magic);
    }
    if payload[4] != VERSION {
        return Err(BadMessage::Version(payload[4]));
    }
    match Kind::from_byte(payload[5]) {
        Some(k) if k == expected => {}
        other => {
            return Err(BadMessage::Kind {
                got: other.map_or_else(
                    || format!("unknown kind {}", payload[5]),
                    |k| format!("{k:?}"),
                ),
                expected,
            })
        }
    }
    let length = u32::from_le_bytes(payload[8..12].try_into().expect("4 bytes")) as usize;
    if length != payload.len() - ENVELOPE_BYTES {
        return Err(BadMessage::Truncated(format!(
            "the envelope announces {length} body bytes, {} are there",
            payload.len() - ENVELOPE_BYTES
        )));
    }
    let end = payload.len() - 4;
    let stored = u32::from_le_bytes(payload[end..].try_into().expect("4 bytes"));
    let computed = olmap::file::crc32::crc32(&payload[..end]);
    if stored != computed {
        return Err(BadMessage::Checksum { stored, computed });
    }
    Ok(&payload[12..end])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sealed_body_opens_and_any_flipped_byte_is_refused() {
        let body = b"some body bytes".to_vec();
        let sealed = seal(Kind::Digest, &body);
        assert_eq!(open(&sealed, Kind::Digest, 1 << 20).unwrap(), &body[..]);
        for i in 0..sealed.len() {
            let mut bad = sealed.clone();
            bad[i] ^= 0x10;
            assert!(open(&bad, Kind::Digest, 1 << 20).is_err(), "byte {i}");
        }
        assert!(matches!(
            open(&sealed, Kind::Record, 1 << 20),
            Err(BadMessage::Kind { .. })
        ));
        assert!(matches!(
            open(&sealed, Kind::Digest, 10),
            Err(BadMessage::Oversized { .. })
        ));
        assert!(matches!(
            open(&sealed[..sealed.len() - 1], Kind::Digest, 1 << 20),
            Err(BadMessage::Truncated(_))
        ));
    }
}
