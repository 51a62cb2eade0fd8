//! The per-robot scan store of thesis §6.3.2 and its synchronisation.
//!
//! "In order for robots to operate in an ad hoc manner in an environment lacking wireless
//! access points each robot stores a list of all occupancy lists along with their time
//! stamp and which robot recorded them. Whenever robots are within wireless networking
//! range of each other they synchronise their occupancy list data stores." (Ryde, §6.3.2.)
//! The thesis also argues for keeping the raw data rather than irreversibly merged maps,
//! so that later (off-line, loop-closing) map building can use every scan.
//!
//! A [`ScanStore`] is that list: a set of [`StoredScan`] records keyed by
//! `(robot, seq)` — the robot that recorded the scan and its scan number — each holding
//! the time stamp, the odometry pose, the cloud in the robot frame and the beacon
//! sightings ([`StoredSighting`]) the robot made at that scan, plus the robots' names.
//! A record is immutable once recorded: the same key always means the same scan, so two
//! stores that disagree about a key are an error, never silently resolved.
//!
//! Synchronisation is set union ([`ScanStore::merge`], [`ScanStore::sync`]). Because the
//! records are keyed and immutable, merging is idempotent, commutative and associative:
//! whichever robots meet in whichever order, once the same records have reached two stores
//! the stores are identical (and write identical bytes). Two records are *identical* when
//! every number in them has the same bit pattern (so `-0.0` and `0.0` differ, and a NaN
//! intensity equals itself); anything else under the same key is a conflict.
//!
//! The file format is documented on [`ScanStore::write`] (public, as this module is not).
//!
//! The store is written with [`crate::file::write_atomic`]: a temporary file beside the
//! target is renamed into place when complete.

use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use std::path::Path;

use nalgebra::{Point3, Quaternion, UnitQuaternion, Vector3};

use crate::cloud::PointCloud;
use crate::error::{Error, Location, ParseError, Result};
use crate::file::crc32::Crc32;
use crate::file::cursor::ByteCursor;
use crate::geometry::Pose;

/// The 8 bytes every scan-store file starts with.
pub const STORE_MAGIC: &[u8; 8] = b"OLSTORE\n";
/// The scan-store file version this olmap writes and reads.
pub const STORE_VERSION: u32 = 1;
const FORMAT: &str = "olmap scan store";
/// Largest deviation of a stored quaternion's norm from 1.
const QUATERNION_TOLERANCE: f64 = 1e-6;
const ATTR_INTENSITY: u8 = 1;
const ATTR_NORMALS: u8 = 2;
const ATTR_COLORS: u8 = 4;
/// Bytes of the smallest possible record (no odometry, sightings or points).
const MIN_RECORD: u64 = 4 + 4 + 8 + 1 + 4 + 24 + 1 + 8;
/// Bytes of one stored sighting.
const SIGHTING_BYTES: u64 = 4 + 24 + 24 + 1;

/// One beacon sighting made by the robot when it took the scan.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredSighting {
    /// The robot seen.
    pub target: u32,
    /// Measured range to the target's beacon, metres.
    pub range: f64,
    /// Measured bearing (0 ahead, positive left), radians.
    pub bearing: f64,
    /// Measured elevation, radians.
    pub elevation: f64,
    /// The target's beacon centre in the observer's robot frame, metres.
    pub beacon: Point3<f64>,
    /// Whether the target saw this robot at the same time too.
    pub mutual: bool,
}

/// One scan as a robot records it: the record of the thesis' scan store.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredScan {
    /// The robot that recorded the scan (first half of the key).
    pub robot: u32,
    /// The robot's scan number, its stop (second half of the key).
    pub seq: u32,
    /// Time stamp, seconds.
    pub time: f64,
    /// Odometry `T_odom_robot` when the scan was taken, if the robot had it.
    pub odometry: Option<Pose>,
    /// The scan in the robot frame (origin on the floor), with the sensor origin set.
    pub cloud: PointCloud,
    /// The beacon sightings the robot made at this scan, in target order.
    pub sightings: Vec<StoredSighting>,
}

/// A robot's store of scan records (thesis §6.3.2), mergeable with other robots' stores.
///
/// "Each robot stores a list of all occupancy lists along with their time stamp and which
/// robot recorded them. Whenever robots are within wireless networking range of each other
/// they synchronise their occupancy list data stores." Here the records are the raw scans
/// ([`StoredScan`], keyed by `(robot, seq)` and never changed once recorded), and
/// synchronising is set union ([`ScanStore::merge`], [`ScanStore::sync`]): idempotent,
/// commutative and associative, so stores that have received the same records are
/// identical whatever the order of the meetings. Records are compared bit for bit; a
/// different record under a key already held is a conflict and an error. One store is one
/// file ([`ScanStore::write`], [`ScanStore::read`]). (`==` on stores is the derived field
/// comparison, for tests; merging uses the bitwise identity.)
///
/// ```
/// use olmap::cloud::PointCloud;
/// use olmap::team::{ScanStore, StoredScan};
/// use nalgebra::Point3;
/// let scan = |robot, seq| StoredScan {
///     robot, seq, time: seq as f64 * 10.0, odometry: None,
///     cloud: PointCloud::from_points(vec![Point3::new(1.0, 2.0, 0.5)]),
///     sightings: Vec::new(),
/// };
/// // Each robot holds its own scans...
/// let mut a = ScanStore::new();
/// a.insert(scan(0, 0))?;
/// a.insert(scan(0, 1))?;
/// let mut b = ScanStore::new();
/// b.insert(scan(1, 0))?;
/// // ...until they meet: each receives what it lacks.
/// assert_eq!(ScanStore::sync(&mut a, &mut b)?, (1, 2));
/// assert_eq!(a, b);
/// assert_eq!(a.len(), 3);
/// // Meeting again changes nothing.
/// assert_eq!(ScanStore::sync(&mut a, &mut b)?, (0, 0));
/// // A store is one file and reads back identical.
/// let path = std::env::temp_dir().join(format!("olmap-doc-{}.olstore", std::process::id()));
/// a.write(&path)?;
/// assert_eq!(ScanStore::read(&path)?, a);
/// # std::fs::remove_file(&path).ok();
/// # Ok::<(), olmap::Error>(())
/// ```
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ScanStore {
    scans: BTreeMap<(u32, u32), StoredScan>,
    names: BTreeMap<u32, String>,
}

impl ScanStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records a scan. Returns `Ok(true)` when it was new, `Ok(false)` when an identical
    /// record (same bits) was already there, and an error when a different record has the
    /// same `(robot, seq)` key or the record holds a non-finite time, pose, sighting or
    /// position (the store is unchanged on error).
    pub fn insert(&mut self, scan: StoredScan) -> Result<bool> {
        check_scan(&scan).map_err(|reason| {
            Error::InvalidArgument(format!(
                "scan {} of robot {}: {reason}",
                scan.seq, scan.robot
            ))
        })?;
        let key = (scan.robot, scan.seq);
        if let Some(old) = self.scans.get(&key) {
            return if same_scan(old, &scan) {
                Ok(false)
            } else {
                Err(self.conflict(old, &scan))
            };
        }
        self.scans.insert(key, scan);
        Ok(true)
    }

    /// Names a robot. Naming it again with the same name is fine; another name, or an
    /// empty one, is an error.
    pub fn set_robot_name(&mut self, robot: u32, name: &str) -> Result<()> {
        check_name(name)
            .map_err(|reason| Error::InvalidArgument(format!("name of robot {robot}: {reason}")))?;
        match self.names.get(&robot) {
            Some(old) if old != name => Err(Error::InvalidArgument(format!(
                "robot {robot} is already named '{old}', cannot rename it '{name}'"
            ))),
            Some(_) => Ok(()),
            None => {
                self.names.insert(robot, name.to_string());
                Ok(())
            }
        }
    }

    /// The robot's name, or `robot{N}` when the store does not know it.
    pub fn robot_name(&self, robot: u32) -> String {
        self.names
            .get(&robot)
            .cloned()
            .unwrap_or_else(|| format!("robot{robot}"))
    }

    /// The record of scan `seq` of `robot`.
    pub fn get(&self, robot: u32, seq: u32) -> Option<&StoredScan> {
        self.scans.get(&(robot, seq))
    }

    /// Every record in key order (by robot, then scan number).
    pub fn iter(&self) -> impl Iterator<Item = &StoredScan> {
        self.scans.values()
    }

    /// Number of records.
    pub fn len(&self) -> usize {
        self.scans.len()
    }

    /// Whether the store holds no record.
    pub fn is_empty(&self) -> bool {
        self.scans.is_empty()
    }

    /// The robots that recorded at least one scan in the store, ascending.
    pub fn robots(&self) -> Vec<u32> {
        let mut out: Vec<u32> = Vec::new();
        for &(r, _) in self.scans.keys() {
            if out.last() != Some(&r) {
                out.push(r);
            }
        }
        out
    }

    /// The records of one robot in scan-number order.
    pub fn scans_of(&self, robot: u32) -> impl Iterator<Item = &StoredScan> {
        self.scans
            .range((robot, 0)..=(robot, u32::MAX))
            .map(|(_, s)| s)
    }

    /// The keys `(robot, seq)` that `other` holds and `self` lacks: what `self` must
    /// receive to catch up with `other`. Ascending.
    pub fn missing_from(&self, other: &ScanStore) -> Vec<(u32, u32)> {
        other
            .scans
            .keys()
            .filter(|k| !self.scans.contains_key(k))
            .copied()
            .collect()
    }

    /// Adds every record and robot name of `other` that `self` lacks; returns the number of
    /// records added. On any conflict (a different record under a key both hold, or two
    /// names for one robot) returns an error and leaves `self` unchanged.
    pub fn merge(&mut self, other: &ScanStore) -> Result<usize> {
        self.check_compatible(other)?;
        Ok(self.absorb(other))
    }

    /// Two robots meet: each receives the records and names it lacks. Returns how many
    /// records `a` and `b` received. On any conflict neither store changes.
    pub fn sync(a: &mut ScanStore, b: &mut ScanStore) -> Result<(usize, usize)> {
        a.check_compatible(b)?;
        let to_a = a.absorb(b);
        // `a` now holds the union; `b` receives exactly what it lacked.
        let to_b = b.absorb(a);
        Ok((to_a, to_b))
    }

    /// Writes the store as one file, atomically (a temporary file beside `path` is renamed
    /// into place when complete). Same store, same bytes.
    ///
    /// # File format (version 1)
    /// One file holds a whole store, conventionally named `*.olstore`. All numbers are
    /// little-endian; `f32`/`f64` are IEEE 754, written bit for bit, so a store read back is
    /// identical to the one written.
    /// ```text
    /// magic      8 bytes  "OLSTORE\n"
    /// version    u32      1
    /// names      u32      number of named robots, then per robot in ascending id order:
    ///              robot u32, length u32 (>= 1), UTF-8 name bytes
    /// records    u64      number of scan records, then per record in ascending (robot, seq) order:
    ///   robot      u32
    ///   seq        u32      the robot's scan number
    ///   time       f64      seconds, finite
    ///   odometry   u8       0 = none, 1 = present, then T_odom_robot as
    ///              tx ty tz f64, then the unit quaternion i j k w f64 (|q| within 1e-6 of 1)
    ///   sightings  u32      count, then per sighting:
    ///              target u32, range f64, bearing f64, elevation f64,
    ///              beacon x y z f64 (in the observer's robot frame), mutual u8 (0 or 1)
    ///   origin     3 x f64  the sensor origin in the robot frame
    ///   attributes u8       bit 0 intensity, bit 1 normals, bit 2 colours (other bits 0)
    ///   points     u64      count n, then
    ///              n x (x y z f32)                 positions, finite
    ///              n x f32                         intensity, if bit 0
    ///              n x (nx ny nz f32)              normals, if bit 1
    ///              n x (r g b u8)                  colours, if bit 2
    /// crc32      u32      CRC-32 (IEEE) of every byte before it
    /// ```
    /// Nothing may follow the checksum. The reader checks every count against the bytes left
    /// before allocating, the ordering of names and records, every flag, that positions,
    /// poses, times and sightings are finite, and the checksum; any violation is an
    /// [`Error::Read`] naming the file, with the byte offset where one applies.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::file::write_atomic(path.as_ref(), FORMAT, |w| self.write_to(w))
    }

    /// Reads a store file; any problem is an [`Error::Read`] naming the file.
    pub fn read(path: impl AsRef<Path>) -> Result<ScanStore> {
        crate::file::parse_file(path.as_ref(), FORMAT, Self::read_from)
    }

    /// Writes the store to a stream in the file format of [`ScanStore::write`].
    pub fn write_to<W: Write>(&self, mut w: W) -> std::io::Result<()> {
        let mut crc = Crc32::default();
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
        for scan in self.scans.values() {
            encode_scan(scan, &mut buf)?;
            crc.update(&buf);
            w.write_all(&buf)?;
            buf.clear();
        }
        crc.update(&buf);
        buf.extend_from_slice(&crc.finish().to_le_bytes());
        w.write_all(&buf)
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

    /// A store with only `robot`'s own records and name: what the robot holds before it
    /// has met anyone.
    pub fn robot_store(&self, robot: u32) -> ScanStore {
        ScanStore {
            scans: self
                .scans
                .range((robot, 0)..=(robot, u32::MAX))
                .map(|(k, s)| (*k, s.clone()))
                .collect(),
            names: self
                .names
                .get(&robot)
                .map(|n| (robot, n.clone()))
                .into_iter()
                .collect(),
        }
    }

    /// An error unless every key and robot name `other` shares with `self` agrees.
    fn check_compatible(&self, other: &ScanStore) -> Result<()> {
        for (robot, name) in &other.names {
            if let Some(mine) = self.names.get(robot) {
                if mine != name {
                    return Err(Error::InvalidArgument(format!(
                        "the stores name robot {robot} differently: '{mine}' and '{name}'"
                    )));
                }
            }
        }
        // Walk the smaller store's keys.
        let (small, large) = if self.scans.len() <= other.scans.len() {
            (self, other)
        } else {
            (other, self)
        };
        for (key, a) in &small.scans {
            if let Some(b) = large.scans.get(key) {
                if !same_scan(a, b) {
                    let (mine, theirs) = if std::ptr::eq(small, self) {
                        (a, b)
                    } else {
                        (b, a)
                    };
                    return Err(self.conflict(mine, theirs));
                }
            }
        }
        Ok(())
    }

    /// Adds what `self` lacks from a compatible store; the number of records added.
    fn absorb(&mut self, other: &ScanStore) -> usize {
        for (robot, name) in &other.names {
            self.names.entry(*robot).or_insert_with(|| name.clone());
        }
        let mut added = 0;
        for (key, scan) in &other.scans {
            if let std::collections::btree_map::Entry::Vacant(e) = self.scans.entry(*key) {
                e.insert(scan.clone());
                added += 1;
            }
        }
        added
    }

    fn conflict(&self, mine: &StoredScan, theirs: &StoredScan) -> Error {
        let what = if mine.time.to_bits() != theirs.time.to_bits() {
            format!("time {} s against {} s", mine.time, theirs.time)
        } else if !same_option_pose(&mine.odometry, &theirs.odometry) {
            "the odometry differs".to_string()
        } else if !same_sightings(&mine.sightings, &theirs.sightings) {
            "the sightings differ".to_string()
        } else {
            format!(
                "the clouds differ ({} and {} points)",
                mine.cloud.len(),
                theirs.cloud.len()
            )
        };
        Error::InvalidArgument(format!(
            "conflicting records for scan {} of robot {} ({}): {what}",
            mine.seq,
            mine.robot,
            self.robot_name(mine.robot)
        ))
    }
}

// ---- checks shared by `insert` and the reader ----

fn check_name(name: &str) -> std::result::Result<(), String> {
    if name.is_empty() {
        return Err("a robot name must not be empty".into());
    }
    Ok(())
}

fn finite3(v: [f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn check_time(t: f64) -> std::result::Result<(), String> {
    if t.is_finite() {
        Ok(())
    } else {
        Err(format!("time {t} is not finite"))
    }
}

fn check_pose(t: &Vector3<f64>, q: &Quaternion<f64>) -> std::result::Result<(), String> {
    if !finite3([t.x, t.y, t.z]) || !q.coords.iter().all(|x| x.is_finite()) {
        return Err("the odometry pose is not finite".into());
    }
    let norm = q.norm();
    if (norm - 1.0).abs() > QUATERNION_TOLERANCE {
        return Err(format!(
            "the odometry rotation is not a unit quaternion (norm {norm})"
        ));
    }
    Ok(())
}

fn check_sighting(s: &StoredSighting) -> std::result::Result<(), String> {
    if s.range.is_finite()
        && s.bearing.is_finite()
        && s.elevation.is_finite()
        && finite3([s.beacon.x, s.beacon.y, s.beacon.z])
    {
        Ok(())
    } else {
        Err(format!("the sighting of robot {} is not finite", s.target))
    }
}

fn check_origin(o: &Point3<f64>) -> std::result::Result<(), String> {
    if finite3([o.x, o.y, o.z]) {
        Ok(())
    } else {
        Err("the sensor origin is not finite".into())
    }
}

fn check_point(i: usize, p: &Point3<f32>) -> std::result::Result<(), String> {
    if p.x.is_finite() && p.y.is_finite() && p.z.is_finite() {
        Ok(())
    } else {
        Err(format!("point {i} is not finite"))
    }
}

fn check_scan(s: &StoredScan) -> std::result::Result<(), String> {
    check_time(s.time)?;
    if let Some(p) = &s.odometry {
        check_pose(&p.translation(), p.rotation().quaternion())?;
    }
    for g in &s.sightings {
        check_sighting(g)?;
    }
    check_origin(&s.cloud.origin())?;
    for (i, p) in s.cloud.points().iter().enumerate() {
        check_point(i, p)?;
    }
    Ok(())
}

// ---- bit-exact comparison ----

fn same_f64(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits()
}

fn same_f32s(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

fn same_option_pose(a: &Option<Pose>, b: &Option<Pose>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => {
            let (ta, tb) = (a.translation(), b.translation());
            let (qa, qb) = (a.rotation(), b.rotation());
            ta.iter().zip(tb.iter()).all(|(x, y)| same_f64(*x, *y))
                && qa
                    .coords
                    .iter()
                    .zip(qb.coords.iter())
                    .all(|(x, y)| same_f64(*x, *y))
        }
        _ => false,
    }
}

fn same_sightings(a: &[StoredSighting], b: &[StoredSighting]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            x.target == y.target
                && x.mutual == y.mutual
                && same_f64(x.range, y.range)
                && same_f64(x.bearing, y.bearing)
                && same_f64(x.elevation, y.elevation)
                && x.beacon
                    .iter()
                    .zip(y.beacon.iter())
                    .all(|(p, q)| same_f64(*p, *q))
        })
}

fn same_cloud(a: &PointCloud, b: &PointCloud) -> bool {
    let (oa, ob) = (a.origin(), b.origin());
    oa.iter().zip(ob.iter()).all(|(x, y)| same_f64(*x, *y))
        && a.len() == b.len()
        && a.points()
            .iter()
            .zip(b.points())
            .all(|(p, q)| same_f32s(p.coords.as_slice(), q.coords.as_slice()))
        && match (a.intensity(), b.intensity()) {
            (None, None) => true,
            (Some(x), Some(y)) => same_f32s(x, y),
            _ => false,
        }
        && match (a.normals(), b.normals()) {
            (None, None) => true,
            (Some(x), Some(y)) => {
                x.len() == y.len()
                    && x.iter()
                        .zip(y)
                        .all(|(u, v)| same_f32s(u.as_slice(), v.as_slice()))
            }
            _ => false,
        }
        && a.colors() == b.colors()
}

fn same_scan(a: &StoredScan, b: &StoredScan) -> bool {
    a.robot == b.robot
        && a.seq == b.seq
        && same_f64(a.time, b.time)
        && same_option_pose(&a.odometry, &b.odometry)
        && same_sightings(&a.sightings, &b.sightings)
        && same_cloud(&a.cloud, &b.cloud)
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

fn decode_store(data: &[u8]) -> Result<ScanStore, ParseError> {
    let mut r = ByteCursor::new(data);
    if r.take(8, "magic")? != STORE_MAGIC {
        return Err(at(0, "not an olmap scan store (bad magic bytes)"));
    }
    let version = r.u32("version")?;
    if version != STORE_VERSION {
        return Err(ParseError::Unsupported(format!(
            "scan store version {version} (this reader knows {STORE_VERSION})"
        )));
    }
    let n_names = r.u32("name count")?;
    let n_names = check_count(&r, n_names as u64, 9, "robot names")?;
    let mut names = BTreeMap::new();
    for _ in 0..n_names {
        let pos = r.pos();
        let robot = r.u32("robot id")?;
        if names.keys().next_back().is_some_and(|&last| robot <= last) {
            return Err(at(pos, "robot names are not in ascending robot order"));
        }
        let len = r.u32("name length")?;
        let len = check_count(&r, len as u64, 1, "name bytes")?;
        let name_pos = r.pos();
        let bytes = r.take(len, "robot name")?;
        let name = std::str::from_utf8(bytes)
            .map_err(|_| at(name_pos, format!("the name of robot {robot} is not UTF-8")))?;
        check_name(name).map_err(|e| at(name_pos, e))?;
        names.insert(robot, name.to_string());
    }
    let n_records = r.u64("record count")?;
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
            "checksum mismatch (stored {stored:08x}, computed {computed:08x}): the file is damaged"
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

fn decode_scan(r: &mut ByteCursor<'_>) -> Result<StoredScan, ParseError> {
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
