//! `.olm`: olmap's own compact binary file for occupancy lists.
//!
//! Layout (version 2), all integers little-endian:
//! ```text
//! magic       8 bytes   "OLMAP\0\r\n"   (the CR LF catches text-mode transfers)
//! version     u32       2
//! resolution  f64       voxel edge in metres, finite and > 0
//! voxels      u64       number of stored voxels
//! chunk       u32       voxels per chunk (>= 1; the last chunk may hold fewer)
//! header crc  u32       CRC-32 (IEEE) of every byte before it
//! then ceil(voxels / chunk) chunks, each:
//!   length    u32       bytes of the payload
//!   payload   keys      the chunk's voxels' packed keys in ascending order as LEB128
//!                       varints, each the difference from the previous key in the file
//!                       (the very first from 0)
//!             counts    the count of each of the chunk's voxels, 1..=1023, as varints
//!   crc       u32       CRC-32 (IEEE) of the length and the payload
//! ```
//! A packed key is `((x + 2^17) << 36) | ((y + 2^17) << 18) | (z + 2^17)`: sorted packed keys
//! walk along z first, so most differences are small and take one or two bytes; counts
//! are mostly 1-2 and take one byte. A file of a scan is about 3-5 bytes per voxel; the
//! chunks (1024 voxels each as written) add 8 bytes per chunk. Saving then loading gives
//! back exactly the same list; nothing after the last chunk is allowed.
//!
//! The checksums per chunk locate damage: a damaged file is refused with the byte offset
//! of the damaged chunk (or header), its index and the voxels it held.
//!
//! Version 1 (still read, no longer written): the same header up to `voxels`, then all the
//! keys, all the counts, and one CRC-32 of every byte before it; a damaged file is refused
//! but the damage cannot be located.

use std::io::{BufRead, Write};
use std::path::Path;

use super::list::{check_resolution, OccupancyList};
use super::packed::{entry_count, entry_key, MAX_COUNT};
use super::table::VoxelTable;
use crate::error::{Location, ParseError, Result};
use crate::file::crc32::{crc32, Crc32};
use crate::file::cursor::StreamCursor;

/// The 8 bytes every `.olm` file starts with.
pub const OLM_MAGIC: &[u8; 8] = b"OLMAP\0\r\n";
/// The `.olm` version this olmap writes (it reads versions 1 and 2).
pub const OLM_VERSION: u32 = 2;
const VERSION_1: u32 = 1;
/// Voxels per chunk as written.
const CHUNK_VOXELS: usize = 1024;
/// The most bytes a varint takes.
const MAX_VARINT: u64 = 10;
const MAX_PACKED_KEY: u64 = (1 << 54) - 1;

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Keys reserved up front at most (512 KiB); beyond that the vector grows as keys arrive.
const INITIAL_KEYS: u64 = 1 << 16;

/// Where varints come from: the file's stream, or a chunk's payload read whole. Byte
/// offsets are the file's.
trait Varints {
    /// The file offset of the next byte.
    fn offset(&self) -> u64;
    /// The next LEB128 varint (at most 10 bytes).
    fn varint(&mut self, what: &str) -> Result<u64, ParseError>;
}

impl<R: BufRead> Varints for StreamCursor<R> {
    fn offset(&self) -> u64 {
        self.pos()
    }
    fn varint(&mut self, what: &str) -> Result<u64, ParseError> {
        StreamCursor::varint(self, what)
    }
}

/// A chunk's payload, read whole, whose first byte is byte `base` of the file.
struct Payload<'a> {
    data: &'a [u8],
    pos: usize,
    base: u64,
}

impl Payload<'_> {
    fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }
}

impl Varints for Payload<'_> {
    fn offset(&self) -> u64 {
        self.base + self.pos as u64
    }
    fn varint(&mut self, what: &str) -> Result<u64, ParseError> {
        let start = self.offset();
        let mut v = 0u64;
        for k in 0..MAX_VARINT as usize {
            let Some(&b) = self.data.get(self.pos) else {
                return Err(ParseError::at(
                    Location::Byte(start),
                    format!("{what}: the chunk ends inside a varint"),
                ));
            };
            self.pos += 1;
            v |= ((b & 0x7F) as u64) << (7 * k);
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(ParseError::at(
            Location::Byte(start),
            format!("{what}: varint longer than {MAX_VARINT} bytes"),
        ))
    }
}

/// Reads `n` keys as varint differences, continuing from `key`; `base` is the index of
/// the first of them in the file (for messages).
fn read_keys(
    r: &mut impl Varints,
    n: u64,
    key: &mut u64,
    base: u64,
    keys: &mut Vec<u64>,
) -> Result<(), ParseError> {
    for i in 0..n {
        let at = r.offset();
        let d = r.varint("key")?;
        if base + i > 0 && d == 0 {
            return Err(ParseError::at(
                Location::Byte(at),
                "keys are not strictly increasing",
            ));
        }
        *key = key
            .checked_add(d)
            .filter(|&k| k <= MAX_PACKED_KEY)
            .ok_or_else(|| {
                ParseError::at(Location::Byte(at), "key outside the representable range")
            })?;
        keys.push(*key);
    }
    Ok(())
}

/// Reads one count per key into `table`.
fn read_counts(
    r: &mut impl Varints,
    keys: &[u64],
    table: &mut VoxelTable,
) -> Result<(), ParseError> {
    for &k in keys {
        let at = r.offset();
        let c = r.varint("count")?;
        if c == 0 || c > MAX_COUNT as u64 {
            return Err(ParseError::at(
                Location::Byte(at),
                format!("count {c} outside 1..={MAX_COUNT}"),
            ));
        }
        table.update(k, |_| c as u16);
    }
    Ok(())
}

/// The resolution checked, or an error at its byte (12).
fn resolution_at_12(resolution: f64) -> Result<(), ParseError> {
    check_resolution(resolution).map_err(|e| {
        ParseError::at(
            Location::Byte(12),
            e.to_string().replace("invalid argument: ", ""),
        )
    })
}

/// Version 1: all keys, all counts, one checksum of the whole file. Read as it streams:
/// memory grows with the keys actually read, whatever `n` claims.
fn read_v1<R: BufRead>(r: &mut StreamCursor<R>, n: u64) -> Result<VoxelTable, ParseError> {
    let mut keys = Vec::with_capacity(n.min(INITIAL_KEYS) as usize);
    read_keys(r, n, &mut 0, 0, &mut keys)?;
    // Every key was read: the table is sized by voxels that are there.
    let mut table = VoxelTable::with_capacity(keys.len());
    read_counts(r, &keys, &mut table)?;
    let computed = r.crc();
    let stored = r.u32("checksum")?;
    if computed != stored {
        return Err(ParseError::Malformed(format!(
            "checksum mismatch (stored {stored:08x}, computed {computed:08x}): the file is \
             damaged somewhere (a version-1 .olm has one checksum for the whole file)"
        )));
    }
    let end = r.pos();
    let rest = r.count_rest()?;
    if rest != 0 {
        return Err(ParseError::Malformed(format!(
            "{rest} unexpected bytes after the checksum (which ends at byte {end})"
        )));
    }
    Ok(table)
}

/// Version 2: the header's checksum, then chunk by chunk, each with its own checksum.
/// Read as it streams: a chunk's payload is read (as its bytes arrive) and checked before
/// it is decoded, and memory grows with the voxels actually read, whatever `n` claims.
fn read_v2<R: BufRead>(
    r: &mut StreamCursor<R>,
    n: u64,
    resolution: f64,
) -> Result<VoxelTable, ParseError> {
    let chunk = r.u32("chunk size")? as u64;
    let computed = r.crc();
    let stored = r.u32("header checksum")?;
    if computed != stored {
        return Err(ParseError::at(
            Location::Byte(0),
            format!(
                "the header (bytes 0..{}) is damaged: checksum mismatch (stored {stored:08x}, \
                 computed {computed:08x})",
                r.pos()
            ),
        ));
    }
    resolution_at_12(resolution)?;
    if chunk == 0 && n > 0 {
        return Err(ParseError::at(Location::Byte(28), "chunk size 0"));
    }
    let chunks = if n == 0 { 0 } else { n.div_ceil(chunk) };
    let mut keys = Vec::with_capacity(chunk.min(n).min(INITIAL_KEYS) as usize);
    let mut table = VoxelTable::with_capacity(n.min(INITIAL_KEYS) as usize);
    let mut payload = Vec::new();
    let mut key = 0u64;
    for c in 0..chunks {
        let first = c * chunk;
        let m = chunk.min(n - first);
        let start = r.pos();
        let voxels = format!("voxels {first}..{}", first + m);
        let damaged = |reason: String| {
            ParseError::at(
                Location::Byte(start),
                format!("chunk {c} ({voxels}) is damaged: {reason}"),
            )
        };
        let cut_short = |len: u64| {
            damaged(format!(
                "its length {len} runs past the end of the file (cut short, or damaged)"
            ))
        };
        let len_bytes = r.array::<4>("chunk length")?;
        let len = u32::from_le_bytes(len_bytes) as u64;
        let (lo, hi) = (2 * m, 2 * MAX_VARINT * m);
        if len < lo || len > hi {
            return Err(damaged(format!(
                "its length {len} is impossible for {m} voxels"
            )));
        }
        if !r.read_vec(&mut payload, len)? {
            return Err(cut_short(len));
        }
        let mut stored = [0u8; 4];
        if !r.read_exact_or_end(&mut stored)? {
            return Err(cut_short(len));
        }
        let mut crc = Crc32::default();
        crc.update(&len_bytes);
        crc.update(&payload);
        if crc.finish() != u32::from_le_bytes(stored) {
            return Err(ParseError::at(
                Location::Byte(start),
                format!(
                    "chunk {c} ({voxels}, bytes {start}..{}) is damaged: checksum mismatch",
                    start + 4 + len + 4
                ),
            ));
        }
        let mut body = Payload {
            data: &payload,
            pos: 0,
            base: start + 4,
        };
        keys.clear();
        read_keys(&mut body, m, &mut key, first, &mut keys)?;
        read_counts(&mut body, &keys, &mut table)?;
        if body.remaining() != 0 {
            return Err(ParseError::at(
                Location::Byte(body.offset()),
                format!(
                    "chunk {c}: {} bytes left over after its voxels",
                    body.remaining()
                ),
            ));
        }
    }
    let end = r.pos();
    let rest = r.count_rest()?;
    if rest != 0 {
        return Err(ParseError::at(
            Location::Byte(end),
            format!("{rest} unexpected bytes after the last chunk"),
        ));
    }
    Ok(table)
}

impl OccupancyList {
    /// Writes the list as `.olm` (version 2).
    pub fn write_olm<W: Write>(&self, mut w: W) -> std::io::Result<()> {
        let mut entries: Vec<u64> = self.table.entries().collect();
        entries.sort_unstable();
        let mut out = Vec::with_capacity(40 + entries.len() * 4);
        out.extend_from_slice(OLM_MAGIC);
        out.extend_from_slice(&OLM_VERSION.to_le_bytes());
        out.extend_from_slice(&self.resolution().to_le_bytes());
        out.extend_from_slice(&(entries.len() as u64).to_le_bytes());
        out.extend_from_slice(&(CHUNK_VOXELS as u32).to_le_bytes());
        let crc = crc32(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        let mut prev = 0u64;
        for chunk in entries.chunks(CHUNK_VOXELS) {
            let start = out.len();
            out.extend_from_slice(&[0; 4]);
            for &e in chunk {
                put_varint(&mut out, entry_key(e) - prev);
                prev = entry_key(e);
            }
            for &e in chunk {
                put_varint(&mut out, entry_count(e) as u64);
            }
            let len = (out.len() - start - 4) as u32;
            out[start..start + 4].copy_from_slice(&len.to_le_bytes());
            let crc = crc32(&out[start..]);
            out.extend_from_slice(&crc.to_le_bytes());
        }
        w.write_all(&out)
    }

    /// Reads a `.olm` stream (version 2, or the older version 1). Damage is refused with
    /// its byte offset: the damaged chunk (index, voxels, bytes) or the header. The stream
    /// is read as it comes (never held whole in memory), and nothing is allocated for
    /// voxels it does not hold: a header announcing 10^12 voxels over a few bytes ends at
    /// the first missing byte, with memory in proportion to the bytes read.
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
        if version != OLM_VERSION && version != VERSION_1 {
            return Err(ParseError::Unsupported(format!(
                ".olm version {version} (this reader knows {VERSION_1} and {OLM_VERSION})"
            )));
        }
        let resolution = r.f64("resolution")?;
        let n = r.u64("voxel count")?;
        let table = if version == VERSION_1 {
            resolution_at_12(resolution)?;
            read_v1(&mut r, n)?
        } else {
            read_v2(&mut r, n, resolution)?
        };
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

    /// The version-1 bytes of a list (the old writer, for the reader's sake).
    fn v1_bytes(l: &OccupancyList) -> Vec<u8> {
        let mut entries: Vec<u64> = l.table.entries().collect();
        entries.sort_unstable();
        let mut out = Vec::new();
        out.extend_from_slice(OLM_MAGIC);
        out.extend_from_slice(&1u32.to_le_bytes());
        out.extend_from_slice(&l.resolution().to_le_bytes());
        out.extend_from_slice(&(entries.len() as u64).to_le_bytes());
        let mut prev = 0;
        for &e in &entries {
            put_varint(&mut out, entry_key(e) - prev);
            prev = entry_key(e);
        }
        for &e in &entries {
            put_varint(&mut out, entry_count(e) as u64);
        }
        let crc = crc32(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// A list of `n` voxels along a line, counts 1..=7.
    fn line(n: i32) -> OccupancyList {
        let mut l = OccupancyList::new(0.1).unwrap();
        for i in 0..n {
            l.set(
                VoxelKey::new(i % 300 - 150, i / 300, (i * 7) % 11),
                (i % 7 + 1) as u32,
            )
            .unwrap();
        }
        l
    }

    #[test]
    fn version_1_files_still_read() {
        for l in [sample(), line(3000), OccupancyList::new(0.2).unwrap()] {
            let back = OccupancyList::read_olm(&v1_bytes(&l)[..]).unwrap();
            assert_eq!(back, l);
        }
        let mut bad = v1_bytes(&sample());
        let last = bad.len() - 6;
        bad[last] ^= 1;
        let err = OccupancyList::read_olm(&bad[..]).unwrap_err().to_string();
        assert!(err.contains("checksum"), "{err}");
    }

    #[test]
    fn audit_damaged_map_is_refused_with_the_offset() {
        // 3000 voxels: three chunks (1024, 1024, 952).
        let l = line(3000);
        let mut buf = Vec::new();
        l.write_olm(&mut buf).unwrap();
        assert_eq!(OccupancyList::read_olm(&buf[..]).unwrap(), l);
        // Find the chunks: header 36 bytes, then length-prefixed chunks.
        let mut starts = Vec::new();
        let mut pos = 36;
        while pos < buf.len() {
            starts.push(pos);
            let len = u32::from_le_bytes(buf[pos..pos + 4].try_into().unwrap()) as usize;
            pos += 4 + len + 4;
        }
        assert_eq!(pos, buf.len());
        assert_eq!(starts.len(), 3);
        // One bad byte in the middle of the second chunk: refused, naming chunk 1, its
        // voxels and the byte where it starts.
        let mut bad = buf.clone();
        bad[(starts[1] + starts[2]) / 2] ^= 0x40;
        let err = OccupancyList::read_olm(&bad[..]).unwrap_err();
        match &err {
            ParseError::Invalid {
                at: Location::Byte(b),
                reason,
            } => {
                assert_eq!(*b as usize, starts[1]);
                assert!(reason.contains("chunk 1 (voxels 1024..2048"), "{reason}");
                assert!(reason.contains("checksum"), "{reason}");
            }
            e => panic!("not located: {e}"),
        }
        // The header, at byte 0.
        let mut bad = buf.clone();
        bad[20] ^= 1;
        let err = OccupancyList::read_olm(&bad[..]).unwrap_err().to_string();
        assert!(err.starts_with("byte 0: the header"), "{err}");
        // Cut inside the last chunk.
        let err = OccupancyList::read_olm(&buf[..buf.len() - 10])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(&format!("byte {}: chunk 2", starts[2])),
            "{err}"
        );
    }
}
