//! `.olm`: olmap's own compact binary file for occupancy lists.
//!
//! Layout, all integers little-endian:
//! ```text
//! magic       8 bytes   "OLMAP\0\r\n"   (the CR LF catches text-mode transfers)
//! version     u32       1
//! resolution  f64       voxel edge in metres, finite and > 0
//! voxels      u64       number of stored voxels
//! keys        voxels x LEB128 varint: the packed keys in ascending order, each stored as
//!                       the difference from the previous one (the first from 0)
//! counts      voxels x LEB128 varint: the count of each voxel, 1..=1023, in key order
//! crc32       u32       CRC-32 (IEEE) of every byte before it
//! ```
//! A packed key is `((x + 2^17) << 36) | ((y + 2^17) << 18) | (z + 2^17)`: sorted packed keys
//! walk along z first, so most differences are small and take one or two bytes; counts
//! are mostly 1-2 and take one byte. A file of a scan is about 3-5 bytes per voxel.
//! Saving then loading gives back exactly the same list; nothing after the checksum is
//! allowed.

use std::io::{BufRead, Write};
use std::path::Path;

use super::list::{check_resolution, OccupancyList};
use super::packed::{entry_count, entry_key, MAX_COUNT};
use super::table::VoxelTable;
use crate::error::{Location, ParseError, Result};
use crate::file::crc32::Crc32;
use crate::file::cursor::StreamCursor;

/// The 8 bytes every `.olm` file starts with.
pub const OLM_MAGIC: &[u8; 8] = b"OLMAP\0\r\n";
const VERSION: u32 = 1;
const MAX_PACKED_KEY: u64 = (1 << 54) - 1;
/// Keys reserved up front at most (512 KiB); beyond that the vector grows as keys arrive.
const INITIAL_KEYS: u64 = 1 << 16;

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

impl OccupancyList {
    /// Writes the list as `.olm`.
    pub fn write_olm<W: Write>(&self, mut w: W) -> std::io::Result<()> {
        let mut entries: Vec<u64> = self.table.entries().collect();
        entries.sort_unstable();
        let mut out = Vec::with_capacity(32 + entries.len() * 4);
        out.extend_from_slice(OLM_MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&self.resolution().to_le_bytes());
        out.extend_from_slice(&(entries.len() as u64).to_le_bytes());
        let mut prev = 0u64;
        for &e in &entries {
            put_varint(&mut out, entry_key(e) - prev);
            prev = entry_key(e);
        }
        for &e in &entries {
            put_varint(&mut out, entry_count(e) as u64);
        }
        let mut crc = Crc32::default();
        crc.update(&out);
        out.extend_from_slice(&crc.finish().to_le_bytes());
        w.write_all(&out)
    }

    /// Reads a `.olm` stream. The stream is read as it comes (never held whole in memory),
    /// and nothing is allocated for voxels the stream does not hold: a header announcing
    /// 10^12 voxels over a few bytes ends as [`ParseError::Truncated`] at the first missing
    /// byte, with memory in proportion to the bytes read.
    pub fn read_olm<R: BufRead>(reader: R) -> Result<OccupancyList, ParseError> {
        let mut r = StreamCursor::new(reader);
        if r.at_end()? {
            return Err(ParseError::Empty);
        }
        if &r.array::<8>("magic")? != OLM_MAGIC {
            return Err(ParseError::at(
                Location::Byte(0),
                "not an .olm file (bad magic bytes)",
            ));
        }
        let version = r.u32("version")?;
        if version != VERSION {
            return Err(ParseError::Unsupported(format!(
                ".olm version {version} (this reader knows {VERSION})"
            )));
        }
        let resolution = r.f64("resolution")?;
        check_resolution(resolution).map_err(|e| {
            ParseError::at(
                Location::Byte(12),
                e.to_string().replace("invalid argument: ", ""),
            )
        })?;
        let n = r.u64("voxel count")?;
        // Reserve for what a small file could hold at most; beyond that the vector grows
        // with the keys actually read (each takes a byte at least).
        let mut keys = Vec::with_capacity(n.min(INITIAL_KEYS) as usize);
        let mut key = 0u64;
        for i in 0..n {
            let at = r.pos();
            let d = r.varint("key")?;
            if i > 0 && d == 0 {
                return Err(ParseError::at(
                    Location::Byte(at),
                    "keys are not strictly increasing",
                ));
            }
            key = key
                .checked_add(d)
                .filter(|&k| k <= MAX_PACKED_KEY)
                .ok_or_else(|| {
                    ParseError::at(Location::Byte(at), "key outside the representable range")
                })?;
            keys.push(key);
        }
        // Every key was read: the table is sized by voxels that are there.
        let mut table = VoxelTable::with_capacity(keys.len());
        for &k in &keys {
            let at = r.pos();
            let c = r.varint("count")?;
            if c == 0 || c > MAX_COUNT as u64 {
                return Err(ParseError::at(
                    Location::Byte(at),
                    format!("count {c} outside 1..={MAX_COUNT}"),
                ));
            }
            table.update(k, |_| c as u16);
        }
        let computed = r.crc();
        let stored = r.u32("checksum")?;
        if computed != stored {
            return Err(ParseError::Malformed(format!(
                "checksum mismatch (stored {stored:08x}, computed {computed:08x}): the file is damaged"
            )));
        }
        let end = r.pos();
        let rest = r.count_rest()?;
        if rest != 0 {
            return Err(ParseError::Malformed(format!(
                "{rest} unexpected bytes after the checksum (which ends at byte {end})"
            )));
        }
        let mut list = OccupancyList::new(resolution).expect("checked");
        list.table = table;
        Ok(list)
    }

    /// Writes a `.olm` file atomically.
    pub fn write_olm_path(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::file::write_atomic(path.as_ref(), "olmap .olm", |w| self.write_olm(w))
    }

    /// Reads a `.olm` file.
    pub fn read_olm_path(path: impl AsRef<Path>) -> Result<OccupancyList> {
        crate::file::parse_file(path.as_ref(), "olmap .olm", Self::read_olm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::VoxelKey;

    fn sample() -> OccupancyList {
        let mut l = OccupancyList::new(0.05).unwrap();
        for (i, k) in [
            (-131072, -131072, -131072),
            (0, 0, 0),
            (0, 0, 1),
            (5, -3, 2),
            (131071, 131071, 131071),
        ]
        .into_iter()
        .enumerate()
        {
            l.set(VoxelKey::new(k.0, k.1, k.2), [1, 2, 1023, 7, 300][i])
                .unwrap();
        }
        l
    }

    #[test]
    fn round_trip_is_exact() {
        let l = sample();
        let mut buf = Vec::new();
        l.write_olm(&mut buf).unwrap();
        let back = OccupancyList::read_olm(&buf[..]).unwrap();
        assert_eq!(back, l);
        assert_eq!(back.sorted(), l.sorted());
        let empty = OccupancyList::new(0.1).unwrap();
        let mut buf = Vec::new();
        empty.write_olm(&mut buf).unwrap();
        assert_eq!(OccupancyList::read_olm(&buf[..]).unwrap(), empty);
    }

    #[test]
    fn damage_is_detected() {
        let mut buf = Vec::new();
        sample().write_olm(&mut buf).unwrap();
        for i in 0..buf.len() {
            let mut bad = buf.clone();
            bad[i] ^= 0x10;
            assert!(
                OccupancyList::read_olm(&bad[..]).is_err(),
                "flip at byte {i} went unnoticed"
            );
        }
        for cut in 0..buf.len() {
            assert!(OccupancyList::read_olm(&buf[..cut]).is_err());
        }
        let mut longer = buf.clone();
        longer.push(0);
        assert!(OccupancyList::read_olm(&longer[..]).is_err());
    }
}
