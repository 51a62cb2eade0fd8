//! Adapters from simulated data to what the pipelines consume: a simulated run or a dataset
//! on disk becomes a [`ScanStore`] of every robot's records. The simulator is the top
//! producer: these live here so that [`crate::team`] never imports the simulator.

use std::collections::BTreeMap;

use super::files::{DatasetOnDisk, SkippedInput};
use super::{Sighting, SimDataset};
use crate::cloud::PointCloud;
use crate::error::{Error, ParseError, Result};
use crate::geometry::{Pose, PoseList};
use crate::team::{scan_name, ScanStore, StoredScan, StoredSighting};

impl SimDataset {
    /// One store holding every robot's records of a simulated run: robot `r`'s scan at
    /// stop `k` becomes record `(r, k)` with its odometry, its cloud and the sightings
    /// robot `r` made at stop `k` (in target order); the time stamp is the sightings' time,
    /// or `k` times the configured stop interval for a scan without sightings.
    ///
    /// ```
    /// use olmap::sim::{simulate, Scanner3d, SimConfig, SpinningLidar, WorldKind};
    /// use olmap::team::ScanStore;
    /// let lidar = SpinningLidar { beams: 8, azimuth_step: 4f64.to_radians(), ..Default::default() };
    /// let config = SimConfig {
    ///     world: WorldKind::BoxRoom, robots: 2, stops: 2,
    ///     scanner: Scanner3d::Lidar(lidar), ..Default::default()
    /// };
    /// let data = simulate(&config, |_, _| {})?;
    /// let all = data.to_store()?;
    /// assert_eq!(all.len(), 4);
    /// assert_eq!(all.robot_name(1), "robot1");
    /// // Before meeting anyone, robot 0 holds only its own two scans.
    /// assert_eq!(all.robot_store(0).len(), 2);
    /// # Ok::<(), olmap::Error>(())
    /// ```
    pub fn to_store(&self) -> Result<ScanStore> {
        let counts: Vec<usize> = self.robots.iter().map(|r| r.scans.len()).collect();
        let groups = group_sightings(&self.sightings, &counts)
            .map_err(|reason| Error::InvalidArgument(format!("simulated dataset: {reason}")))?;
        let mut store = ScanStore::new();
        for (r, robot) in self.robots.iter().enumerate() {
            let id = index_u32(r, "robot index")?;
            store.set_robot_name(id, &robot.name)?;
            for (k, cloud) in robot.scans.iter().enumerate() {
                store.insert(make_record(
                    id,
                    k,
                    cloud.clone(),
                    robot.odometry.get(k).copied(),
                    groups.get(&(r, k)).map_or(&[][..], |v| &v[..]),
                    self.config.stop_interval,
                )?)?;
            }
        }
        Ok(store)
    }
}

impl DatasetOnDisk {
    /// One store holding every robot's records of a dataset on disk (see
    /// [`SimDataset::to_store`]); the scans are read from their PCD files with
    /// [`crate::io::read_cloud`], the time step is the manifest's `stop_interval_s`.
    pub fn to_store(&self) -> Result<ScanStore> {
        self.store(false).map(|(store, _)| store)
    }

    /// [`DatasetOnDisk::to_store`] leaving out every scan that cannot be read (with its
    /// sightings), listed with the reason: one bad file does not stop a team run.
    pub fn to_store_skipping(&self) -> Result<(ScanStore, Vec<SkippedInput>)> {
        self.store(true)
    }

    fn store(&self, skip: bool) -> Result<(ScanStore, Vec<SkippedInput>)> {
        let mut skipped = Vec::new();
        let counts: Vec<usize> = self.manifest.robots.iter().map(|r| r.scans.len()).collect();
        let groups = group_sightings(&self.sightings, &counts).map_err(|reason| Error::Read {
            path: self.dir.join(&self.manifest.sightings),
            format: "sightings CSV",
            source: ParseError::Malformed(reason),
        })?;
        let mut store = ScanStore::new();
        for (r, files) in self.manifest.robots.iter().enumerate() {
            let id = index_u32(r, "robot index")?;
            store.set_robot_name(id, &files.name)?;
            for (k, path) in self.scan_paths(r).iter().enumerate() {
                let cloud = match crate::io::read_cloud(path) {
                    Ok(loaded) => loaded.cloud,
                    Err(e) if skip => {
                        skipped.push(SkippedInput {
                            path: path.display().to_string(),
                            reason: e.to_string(),
                        });
                        continue;
                    }
                    Err(e) => return Err(e),
                };
                let odometry = self
                    .odometry
                    .get(r)
                    .and_then(|list| list.poses.get(k))
                    .map(|p| p.pose);
                store.insert(make_record(
                    id,
                    k,
                    cloud,
                    odometry,
                    groups.get(&(r, k)).map_or(&[][..], |v| &v[..]),
                    self.manifest.stop_interval_s,
                )?)?;
            }
        }
        Ok((store, skipped))
    }
}

fn index_u32(i: usize, what: &str) -> Result<u32> {
    u32::try_from(i).map_err(|_| Error::InvalidArgument(format!("{what} {i} exceeds u32")))
}

type SightingGroups<'a> = BTreeMap<(usize, usize), Vec<&'a Sighting>>;

/// Sightings grouped by (observer, stop), each group in target order; checks the indices
/// against the robots' scan counts.
fn group_sightings<'a>(
    sightings: &'a [Sighting],
    scan_counts: &[usize],
) -> std::result::Result<SightingGroups<'a>, String> {
    let mut groups: SightingGroups<'a> = BTreeMap::new();
    for s in sightings {
        let n = scan_counts.len();
        if s.observer >= n || s.target >= n {
            return Err(format!(
                "sighting of robot {} by robot {}: there are {n} robots",
                s.target, s.observer
            ));
        }
        if s.stop >= scan_counts[s.observer] {
            return Err(format!(
                "sighting by robot {} at stop {}: the robot has {} scans",
                s.observer, s.stop, scan_counts[s.observer]
            ));
        }
        groups.entry((s.observer, s.stop)).or_default().push(s);
    }
    for g in groups.values_mut() {
        g.sort_by_key(|s| s.target);
    }
    Ok(groups)
}

fn make_record(
    robot: u32,
    k: usize,
    cloud: PointCloud,
    odometry: Option<Pose>,
    sightings: &[&Sighting],
    stop_interval: f64,
) -> Result<StoredScan> {
    let stored = sightings
        .iter()
        .map(|s| {
            Ok(StoredSighting {
                target: index_u32(s.target, "robot index")?,
                range: s.range,
                bearing: s.bearing,
                elevation: s.elevation,
                beacon: s.beacon,
                mutual: s.mutual,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(StoredScan {
        robot,
        seq: index_u32(k, "scan number")?,
        time: sightings
            .first()
            .map_or(k as f64 * stop_interval, |s| s.time),
        odometry,
        cloud,
        sightings: stored,
    })
}

impl SimDataset {
    /// The ground truth `T_world_scan` of every scan, named as the team map names them
    /// ([`crate::team::scan_name`] in `store`, the store made by [`SimDataset::to_store`]).
    pub fn truth_list(&self, store: &ScanStore) -> PoseList {
        let mut truth = PoseList::default();
        for (r, robot) in self.robots.iter().enumerate() {
            for (k, t) in robot.truth.iter().enumerate() {
                truth.push(scan_name(store, r as u32, k as u32), *t);
            }
        }
        truth
    }
}

impl DatasetOnDisk {
    /// The ground truth of every scan on disk, named as the team map names them (see
    /// [`SimDataset::truth_list`]).
    pub fn truth_list(&self, store: &ScanStore) -> PoseList {
        let mut truth = PoseList::default();
        for (r, list) in self.truth.iter().enumerate() {
            for (k, p) in list.poses.iter().enumerate() {
                truth.push(scan_name(store, r as u32, k as u32), p.pose);
            }
        }
        truth
    }
}
