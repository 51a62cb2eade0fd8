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
//! The file format is documented on [`ScanStore::write`] (public, as this module is not):
//! simple, versioned, little-endian, each record framed with a marker, its length and its
//! own CRC-32 (version 2), so that a damaged byte costs the record it is in, not the
//! store. [`ScanStore::read`] refuses any damage, naming the record and its byte offset;
//! [`ScanStore::read_salvaged`] recovers every record whose checksum holds and reports
//! the damaged stretches ([`SalvageReport`]). Version-1 files (one CRC-32 for the whole
//! file) are still read. Files as a front end sees them: [`store_info`],
//! [`merge_store_files`], [`salvage_store_file`] (`olmap store info | merge | salvage`).
//! Live stores may move to an embedded database; this file stays the export and
//! interchange format.
//!
//! The store is written with [`crate::file::write_atomic`]: a temporary file beside the
//! target is renamed into place when complete.

mod checks;
mod codec;
mod identity;
mod inspect;
mod salvage;

use std::collections::BTreeMap;

use nalgebra::Point3;

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use checks::{check_name, check_scan};
pub use codec::{RECORD_MARKER, STORE_MAGIC, STORE_VERSION};
use identity::{same_option_pose, same_scan, same_sightings};
pub use inspect::{
    merge_store_files, salvage_store_file, store_info, StoreInfo, StoreMergeInput,
    StoreMergeReport, StoreRobotInfo, StoreSalvageReport,
};
pub use salvage::{SalvageReport, StoreDamage};

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
