//! The scan-store file (`*.olstore`, `*.store`): the binary writer and reader of a whole
//! [`ScanStore`] (magic, version, names, records each framed with its own CRC-32), format
//! on [`ScanStore::write`]. Version 1 (one CRC-32 over the whole file) is still read.

use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use std::path::Path;

use nalgebra::{Point3, Quaternion, UnitQuaternion, Vector3};

use super::checks::{
    check_name, check_origin, check_point, check_pose, check_sighting, check_time,
};
use super::{ScanStore, StoredScan, StoredSighting};
use crate::cloud::PointCloud;
use crate::error::{Error, Location, ParseError, Result};
use crate::file::crc32::Crc32;
use crate::file::cursor::ByteCursor;
use crate::geometry::Pose;

/// The 8 bytes every scan-store file starts with.
pub const STORE_MAGIC: &[u8; 8] = b"OLSTORE\n";
/// The scan-store file version this olmap writes (it reads this one and version 1).
pub const STORE_VERSION: u32 = 2;
/// The first version: no per-record checksums (read, never written).
pub(super) const STORE_VERSION_1: u32 = 1;
/// The 8 bytes that open every record frame of a version-2 store: after damage, a salvage
/// reader finds the next record by them.
pub const RECORD_MARKER: &[u8; 8] = b"OLRECORD";
/// Bytes of a record frame around its body: marker, length, CRC-32.
pub(super) const FRAME_OVERHEAD: usize = 8 + 8 + 4;
pub(super) const FORMAT: &str = "olmap scan store";
const ATTR_INTENSITY: u8 = 1;
const ATTR_NORMALS: u8 = 2;
const ATTR_COLORS: u8 = 4;
/// Bytes of the smallest possible record body (no odometry, sightings or points).
pub(super) const MIN_RECORD: u64 = 4 + 4 + 8 + 1 + 4 + 24 + 1 + 8;
/// Bytes of one stored sighting.
const SIGHTING_BYTES: u64 = 4 + 24 + 24 + 1;

impl ScanStore {
    /// Writes the store as one file, atomically (a temporary file beside `path` is renamed
    /// into place when complete). Same store, same bytes.
    ///
    /// # File format (version 2)
    /// One file holds a whole store, conventionally named `*.olstore` (`team.store` in a
    /// team run's folder). All numbers are little-endian; `f32`/`f64` are IEEE 754, written
    /// bit for bit, so a store read back is identical to the one written. Every record
    /// carries its own checksum, so that damage costs only the records it touches: the
    /// reader names the damaged record and its byte offset, and a salvage reader
    /// ([`ScanStore::read_salvaged`]) recovers every other record.
    /// ```text
    /// magic      8 bytes  "OLSTORE\n"
    /// version    u32      2
    /// names      u32      number of named robots, then per robot in ascending id order:
    ///              robot u32, length u32 (>= 1), UTF-8 name bytes
    /// records    u64      number of scan records
    /// header crc u32      CRC-32 (IEEE) of every byte before it
    /// then per record, in ascending (robot, seq) order, one frame:
    ///   marker   8 bytes  "OLRECORD"
    ///   length   u64      bytes of the body
    ///   body     length bytes:
    ///     robot      u32
    ///     seq        u32      the robot's scan number
    ///     time       f64      seconds, finite
    ///     odometry   u8       0 = none, 1 = present, then T_odom_robot as
    ///                tx ty tz f64, then the unit quaternion i j k w f64 (|q| within 1e-6 of 1)
    ///     sightings  u32      count, then per sighting:
    ///                target u32, range f64, bearing f64, elevation f64,
    ///                beacon x y z f64 (in the observer's robot frame), mutual u8 (0 or 1)
    ///     origin     3 x f64  the sensor origin in the robot frame
    ///     attributes u8       bit 0 intensity, bit 1 normals, bit 2 colours (other bits 0)
    ///     points     u64      count n, then
    ///                n x (x y z f32)                 positions, finite
    ///                n x f32                         intensity, if bit 0
    ///                n x (nx ny nz f32)              normals, if bit 1
    ///                n x (r g b u8)                  colours, if bit 2
    ///   crc      u32      CRC-32 (IEEE) of the length and the body
    /// ```
    /// Nothing may follow the last record. The reader checks the header's checksum, then
    /// per record the marker, that the length fits the file, the checksum, and that the
    /// body fills the length exactly; every count against the bytes left before
    /// allocating, the ordering of names and records, every flag, that positions, poses,
    /// times and sightings are finite. Any violation is an [`Error::Read`] naming the file
    /// with the byte offset (for a damaged record: where its frame starts, and its index).
    ///
    /// # Version 1 (read, no longer written)
    /// The same header without its checksum, the record bodies back to back without frames,
    /// and one CRC-32 of every byte before it at the end: one damaged byte anywhere and the
    /// whole file is refused (its salvage reader can only return unverified records).
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::file::write_atomic(path.as_ref(), FORMAT, |w| self.write_to(w))
    }

    /// Reads a store file; any problem is an [`Error::Read`] naming the file.
    pub fn read(path: impl AsRef<Path>) -> Result<ScanStore> {
        crate::file::parse_file(path.as_ref(), FORMAT, Self::read_from)
    }

    /// Writes the store to a stream in the file format of [`ScanStore::write`].
    pub fn write_to<W: Write>(&self, mut w: W) -> std::io::Result<()> {
        let mut buf = Vec::with_capacity(1 << 16);
        buf.extend_from_slice(STORE_MAGIC);
        buf.extend_from_slice(&STORE_VERSION.to_le_bytes());
        buf.extend_from_slice(&len_u32(self.names.len())?.to_le_bytes());
        for (&robot, name) in &self.names {
            buf.extend_from_slice(&robot.to_le_bytes());
            buf.extend_from_slice(&len_u32(name.len())?.to_le_bytes());
            buf.extend_from_slice(name.as_bytes());
        }
        buf.extend_from_slice(&(self.scans.len() as u64).to_le_bytes());
        let crc = crate::file::crc32::crc32(&buf);
        buf.extend_from_slice(&crc.to_le_bytes());
        w.write_all(&buf)?;
        for scan in self.scans.values() {
            buf.clear();
            buf.extend_from_slice(RECORD_MARKER);
            buf.extend_from_slice(&[0; 8]);
            encode_scan(scan, &mut buf)?;
            let length = (buf.len() - 16) as u64;
            buf[8..16].copy_from_slice(&length.to_le_bytes());
            let mut crc = Crc32::default();
            crc.update(&buf[8..]);
            buf.extend_from_slice(&crc.finish().to_le_bytes());
            w.write_all(&buf)?;
        }
        Ok(())
    }

    /// Reads a store from a stream in the file format (no path attached to errors).
    pub fn read_from<R: BufRead>(mut reader: R) -> Result<ScanStore, ParseError> {
        let mut data = Vec::new();
        reader.read_to_end(&mut data)?;
        if data.is_empty() {
            return Err(ParseError::Empty);
        }
        decode_store(&data)
    }
}

impl StoredScan {
    /// The record's body in the store file's encoding (the `body` of a record frame on
    /// [`ScanStore::write`]): what crosses the network in `olmap-net`. Same record, same
    /// bytes; [`StoredScan::decode_record`] reads it back identical.
    pub fn encode_record(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(64 + self.cloud.len() * 12);
        // Counts above u32 (4 G sightings) cannot occur in a checked record; a record
        // that held them would fail to decode, never be misread.
        if encode_scan(self, &mut out).is_err() {
            out.clear();
        }
        out
    }

    /// Reads a record body written by [`StoredScan::encode_record`]: every count checked
    /// against the bytes present before allocating, every number finite, nothing left
    /// over; any problem is a [`ParseError`] with its byte offset.
    pub fn decode_record(bytes: &[u8]) -> Result<StoredScan, ParseError> {
        let frame = Frame {
            body_start: 0,
            body_end: bytes.len(),
            end: bytes.len(),
        };
        decode_body(bytes, &frame)
    }
}

// ---- encoding ----

fn len_u32(n: usize) -> std::io::Result<u32> {
    u32::try_from(n).map_err(|_| std::io::Error::other(format!("{n} entries exceed the u32 count")))
}

fn put_f64s(out: &mut Vec<u8>, values: &[f64]) {
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

fn encode_scan(s: &StoredScan, out: &mut Vec<u8>) -> std::io::Result<()> {
    out.extend_from_slice(&s.robot.to_le_bytes());
    out.extend_from_slice(&s.seq.to_le_bytes());
    out.extend_from_slice(&s.time.to_le_bytes());
    match &s.odometry {
        None => out.push(0),
        Some(p) => {
            out.push(1);
            let t = p.translation();
            let q = p.rotation();
            put_f64s(out, &[t.x, t.y, t.z, q.i, q.j, q.k, q.w]);
        }
    }
    out.extend_from_slice(&len_u32(s.sightings.len())?.to_le_bytes());
    for g in &s.sightings {
        out.extend_from_slice(&g.target.to_le_bytes());
        put_f64s(
            out,
            &[
                g.range,
                g.bearing,
                g.elevation,
                g.beacon.x,
                g.beacon.y,
                g.beacon.z,
            ],
        );
        out.push(u8::from(g.mutual));
    }
    let c = &s.cloud;
    let o = c.origin();
    put_f64s(out, &[o.x, o.y, o.z]);
    let mut attributes = 0u8;
    if c.intensity().is_some() {
        attributes |= ATTR_INTENSITY;
    }
    if c.normals().is_some() {
        attributes |= ATTR_NORMALS;
    }
    if c.colors().is_some() {
        attributes |= ATTR_COLORS;
    }
    out.push(attributes);
    out.extend_from_slice(&(c.len() as u64).to_le_bytes());
    out.reserve(c.len() * 31);
    for p in c.points() {
        for v in p.coords.iter() {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    if let Some(v) = c.intensity() {
        for x in v {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    if let Some(v) = c.normals() {
        for n in v {
            for x in n.iter() {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
    if let Some(v) = c.colors() {
        for rgb in v {
            out.extend_from_slice(rgb);
        }
    }
    Ok(())
}

// ---- decoding ----

fn at(pos: usize, reason: impl Into<String>) -> ParseError {
    ParseError::at(Location::Byte(pos as u64), reason)
}

/// Refuses a count of items of at least `each` bytes that the rest of the file cannot hold.
fn check_count(r: &ByteCursor<'_>, count: u64, each: u64, what: &str) -> Result<usize, ParseError> {
    let need = count.checked_mul(each);
    match need {
        Some(need) if need <= r.remaining() as u64 => Ok(count as usize),
        _ => Err(ParseError::Truncated(format!(
            "{count} {what} announced before byte {} but only {} bytes follow",
            r.pos(),
            r.remaining()
        ))),
    }
}

fn f64s<const N: usize>(r: &mut ByteCursor<'_>, what: &str) -> Result<[f64; N], ParseError> {
    let mut v = [0.0; N];
    for x in &mut v {
        *x = r.f64(what)?;
    }
    Ok(v)
}

fn f32_at(r: &mut ByteCursor<'_>, what: &str) -> Result<f32, ParseError> {
    Ok(f32::from_le_bytes(r.array(what)?))
}

fn flag(r: &mut ByteCursor<'_>, what: &str) -> Result<bool, ParseError> {
    let pos = r.pos();
    match r.array::<1>(what)?[0] {
        0 => Ok(false),
        1 => Ok(true),
        b => Err(at(pos, format!("{what}: {b} is neither 0 nor 1"))),
    }
}

/// Magic, version and names: the part of the header both versions share.
pub(super) fn decode_names(
    r: &mut ByteCursor<'_>,
) -> Result<(u32, BTreeMap<u32, String>), ParseError> {
    if r.take(8, "magic")? != STORE_MAGIC {
        return Err(at(0, "not an olmap scan store (bad magic bytes)"));
    }
    let version = r.u32("version")?;
    if version != STORE_VERSION && version != STORE_VERSION_1 {
        return Err(ParseError::Unsupported(format!(
            "scan store version {version} (this reader knows {STORE_VERSION_1} and {STORE_VERSION})"
        )));
    }
    let n_names = r.u32("name count")?;
    let n_names = check_count(r, n_names as u64, 9, "robot names")?;
    let mut names = BTreeMap::new();
    for _ in 0..n_names {
        let pos = r.pos();
        let robot = r.u32("robot id")?;
        if names.keys().next_back().is_some_and(|&last| robot <= last) {
            return Err(at(pos, "robot names are not in ascending robot order"));
        }
        let len = r.u32("name length")?;
        let len = check_count(r, len as u64, 1, "name bytes")?;
        let name_pos = r.pos();
        let bytes = r.take(len, "robot name")?;
        let name = std::str::from_utf8(bytes)
            .map_err(|_| at(name_pos, format!("the name of robot {robot} is not UTF-8")))?;
        check_name(name).map_err(|e| at(name_pos, e))?;
        names.insert(robot, name.to_string());
    }
    Ok((version, names))
}

pub(super) fn decode_store(data: &[u8]) -> Result<ScanStore, ParseError> {
    let mut r = ByteCursor::new(data);
    let (version, names) = decode_names(&mut r).map_err(|e| {
        // In a version-2 file a header that does not parse is a damaged one (its checksum
        // cannot even be found); elsewhere the error says what is wrong.
        let v2 = data.get(8..12) == Some(&STORE_VERSION.to_le_bytes()[..])
            && data.starts_with(STORE_MAGIC);
        if v2 {
            at(0, format!("the header is damaged: {e}"))
        } else {
            e
        }
    })?;
    let n_records = r.u64("record count")?;
    if version == STORE_VERSION_1 {
        return decode_v1(data, r, names, n_records);
    }
    let header_end = r.pos();
    let stored = r.u32("header checksum")?;
    let computed = crate::file::crc32::crc32(&data[..header_end]);
    if computed != stored {
        return Err(at(
            0,
            format!(
                "the header (bytes 0..{}) is damaged: checksum mismatch (stored {stored:08x}, \
                 computed {computed:08x})",
                r.pos()
            ),
        ));
    }
    let min_frame = MIN_RECORD + FRAME_OVERHEAD as u64;
    let n_records = check_count(&r, n_records, min_frame, "scan records")?;
    let mut scans = BTreeMap::new();
    let mut pos = r.pos();
    for index in 0..n_records {
        let frame =
            check_frame(data, pos).map_err(|fault| fault.error(index as u64, pos, data.len()))?;
        let scan = decode_body(data, &frame).map_err(|e| in_record(e, index as u64, pos))?;
        let key = (scan.robot, scan.seq);
        if scans.keys().next_back().is_some_and(|&last| key <= last) {
            return Err(at(
                pos,
                format!(
                    "record {index}: scan {} of robot {} is out of key order (or repeated)",
                    scan.seq, scan.robot
                ),
            ));
        }
        scans.insert(key, scan);
        pos = frame.end;
    }
    if pos != data.len() {
        return Err(at(
            pos,
            format!(
                "{} unexpected bytes after the last of {n_records} records",
                data.len() - pos
            ),
        ));
    }
    Ok(ScanStore { scans, names })
}

/// Version 1: record bodies back to back, one CRC-32 of the whole file at the end.
fn decode_v1(
    data: &[u8],
    mut r: ByteCursor<'_>,
    names: BTreeMap<u32, String>,
    n_records: u64,
) -> Result<ScanStore, ParseError> {
    let n_records = check_count(&r, n_records, MIN_RECORD, "scan records")?;
    let mut scans = BTreeMap::new();
    for _ in 0..n_records {
        let pos = r.pos();
        let scan = decode_scan(&mut r)?;
        let key = (scan.robot, scan.seq);
        if scans.keys().next_back().is_some_and(|&last| key <= last) {
            return Err(at(
                pos,
                format!(
                    "record of scan {} of robot {} is out of key order (or repeated)",
                    scan.seq, scan.robot
                ),
            ));
        }
        scans.insert(key, scan);
    }
    let body_end = r.pos();
    let stored = r.u32("checksum")?;
    let computed = crate::file::crc32::crc32(&data[..body_end]);
    if computed != stored {
        return Err(ParseError::Malformed(format!(
            "checksum mismatch (stored {stored:08x}, computed {computed:08x}): the file is \
             damaged somewhere (a version-1 store has one checksum for the whole file; \
             `olmap store salvage` recovers what still reads)"
        )));
    }
    if r.remaining() != 0 {
        return Err(ParseError::Malformed(format!(
            "{} unexpected bytes after the checksum",
            r.remaining()
        )));
    }
    Ok(ScanStore { scans, names })
}

/// Where a verified record frame lies in the file.
#[derive(Debug, Clone, Copy)]
pub(super) struct Frame {
    /// First byte of the body.
    pub body_start: usize,
    /// One past the body's last byte.
    pub body_end: usize,
    /// One past the frame's last byte (its checksum).
    pub end: usize,
}

/// Why no verified frame starts at a position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum FrameFault {
    /// The 8 marker bytes are not there.
    NoMarker,
    /// The length runs past the end of the file.
    Overrun,
    /// The checksum does not match.
    Checksum {
        /// One past the frame's last byte, as its length says.
        end: usize,
    },
}

impl FrameFault {
    /// The reader's error for record `index` whose frame should start at `pos`.
    fn error(self, index: u64, pos: usize, len: usize) -> ParseError {
        match self {
            FrameFault::NoMarker if pos >= len => ParseError::Truncated(format!(
                "record {index} should start at byte {pos}, the end of the file"
            )),
            FrameFault::NoMarker => at(
                pos,
                format!("record {index}: no record marker: the record is damaged"),
            ),
            FrameFault::Overrun => ParseError::Truncated(format!(
                "record {index} at byte {pos} runs past the end of the file at byte {len} (the \
                 file was cut, or the record's length is damaged)"
            )),
            FrameFault::Checksum { end } => at(
                pos,
                format!("record {index} (bytes {pos}..{end}) is damaged: checksum mismatch"),
            ),
        }
    }
}

/// The frame starting at `pos`, if its marker, length and checksum hold.
pub(super) fn check_frame(data: &[u8], pos: usize) -> Result<Frame, FrameFault> {
    let rest = data.get(pos..).unwrap_or(&[]);
    if rest.len() < 8 || &rest[..8] != RECORD_MARKER {
        return Err(FrameFault::NoMarker);
    }
    if rest.len() < 16 {
        return Err(FrameFault::Overrun);
    }
    let length = u64::from_le_bytes(rest[8..16].try_into().expect("8 bytes"));
    let body_len = usize::try_from(length)
        .ok()
        .filter(|&n| n <= rest.len().saturating_sub(FRAME_OVERHEAD))
        .ok_or(FrameFault::Overrun)?;
    let body_end = pos + 16 + body_len;
    let end = body_end + 4;
    let stored = u32::from_le_bytes(data[body_end..end].try_into().expect("4 bytes"));
    if crate::file::crc32::crc32(&data[pos + 8..body_end]) != stored {
        return Err(FrameFault::Checksum { end });
    }
    Ok(Frame {
        body_start: pos + 16,
        body_end,
        end,
    })
}

/// Decodes a verified frame's body, which must fill it exactly.
pub(super) fn decode_body(data: &[u8], frame: &Frame) -> Result<StoredScan, ParseError> {
    let mut r = ByteCursor::new_at(&data[..frame.body_end], frame.body_start);
    let scan = decode_scan(&mut r)?;
    if r.remaining() != 0 {
        return Err(at(
            r.pos(),
            format!(
                "{} bytes of the record are left over after its content",
                r.remaining()
            ),
        ));
    }
    Ok(scan)
}

/// Names the record in a content error found inside a verified frame.
fn in_record(e: ParseError, index: u64, pos: usize) -> ParseError {
    match e {
        ParseError::Invalid { at, reason } => ParseError::Invalid {
            at,
            reason: format!("record {index} (at byte {pos}): {reason}"),
        },
        ParseError::Truncated(m) => at(pos, format!("record {index}: the content ends early: {m}")),
        other => other,
    }
}

pub(super) fn decode_scan(r: &mut ByteCursor<'_>) -> Result<StoredScan, ParseError> {
    let robot = r.u32("robot id")?;
    let seq = r.u32("scan number")?;
    let pos = r.pos();
    let time = r.f64("time")?;
    check_time(time).map_err(|e| at(pos, e))?;
    let odometry = if flag(r, "odometry flag")? {
        let pos = r.pos();
        let [tx, ty, tz, i, j, k, w] = f64s::<7>(r, "odometry pose")?;
        let t = Vector3::new(tx, ty, tz);
        let q = Quaternion::new(w, i, j, k);
        check_pose(&t, &q).map_err(|e| at(pos, e))?;
        Some(Pose::from_parts(t, UnitQuaternion::new_unchecked(q)))
    } else {
        None
    };
    let n = r.u32("sighting count")?;
    let n = check_count(r, n as u64, SIGHTING_BYTES, "sightings")?;
    let mut sightings = Vec::with_capacity(n);
    for _ in 0..n {
        let pos = r.pos();
        let target = r.u32("sighting target")?;
        let [range, bearing, elevation, x, y, z] = f64s::<6>(r, "sighting")?;
        let s = StoredSighting {
            target,
            range,
            bearing,
            elevation,
            beacon: Point3::new(x, y, z),
            mutual: flag(r, "mutual flag")?,
        };
        check_sighting(&s).map_err(|e| at(pos, e))?;
        sightings.push(s);
    }
    let pos = r.pos();
    let origin = Point3::from(f64s::<3>(r, "sensor origin")?);
    check_origin(&origin).map_err(|e| at(pos, e))?;
    let pos = r.pos();
    let attributes = r.array::<1>("attribute flags")?[0];
    if attributes & !(ATTR_INTENSITY | ATTR_NORMALS | ATTR_COLORS) != 0 {
        return Err(at(
            pos,
            format!("unknown attribute flags {attributes:#04x}"),
        ));
    }
    let mut per_point = 12u64;
    if attributes & ATTR_INTENSITY != 0 {
        per_point += 4;
    }
    if attributes & ATTR_NORMALS != 0 {
        per_point += 12;
    }
    if attributes & ATTR_COLORS != 0 {
        per_point += 3;
    }
    let n = r.u64("point count")?;
    let n = check_count(r, n, per_point, "points")?;
    let mut points = Vec::with_capacity(n);
    for i in 0..n {
        let pos = r.pos();
        let p = Point3::new(
            f32_at(r, "point")?,
            f32_at(r, "point")?,
            f32_at(r, "point")?,
        );
        check_point(i, &p).map_err(|e| at(pos, e))?;
        points.push(p);
    }
    let mut cloud = PointCloud::from_points(points).with_origin(origin);
    let attach = |e: Error| ParseError::Malformed(e.to_string());
    if attributes & ATTR_INTENSITY != 0 {
        let v = (0..n)
            .map(|_| f32_at(r, "intensity"))
            .collect::<Result<Vec<_>, _>>()?;
        cloud.set_intensity(Some(v)).map_err(attach)?;
    }
    if attributes & ATTR_NORMALS != 0 {
        let v = (0..n)
            .map(|_| {
                Ok(Vector3::new(
                    f32_at(r, "normal")?,
                    f32_at(r, "normal")?,
                    f32_at(r, "normal")?,
                ))
            })
            .collect::<Result<Vec<_>, ParseError>>()?;
        cloud.set_normals(Some(v)).map_err(attach)?;
    }
    if attributes & ATTR_COLORS != 0 {
        let v = (0..n)
            .map(|_| r.array::<3>("colour"))
            .collect::<Result<Vec<_>, _>>()?;
        cloud.set_colors(Some(v)).map_err(attach)?;
    }
    Ok(StoredScan {
        robot,
        seq,
        time,
        odometry,
        cloud,
        sightings,
    })
}
