//! Free space at OctoMap's semantics: [`LogOddsMap`], a voxel map that tells **unknown**,
//! **free** and **occupied** apart (what planners such as MoveIt and Nav2 need).
//!
//! Occupancy lists ([`crate::occupancy::OccupancyList`], the thesis' representation) keep
//! occupied voxels only and stay the default for alignment. A log-odds map also keeps
//! every voxel a ray passed through, with OctoMap's probabilistic update
//! ([`LogOddsModel`]: hit 0.7, miss 0.4, clamping 0.1192-0.971, threshold 0.5, by
//! default) and OctoMap's scan insertion ([`LogOddsMap::insert_scan`]), so that the same
//! scans, poses, resolution and model give the same classification as an OctoMap
//! `OcTree`. It is written as an OctoMap `.bt` tree with its free nodes
//! ([`LogOddsMap::write_bt`]), which OctoMap's tools and `octovis` read.
//!
//! Differences from OctoMap, all deliberate:
//! * storage is a hash of 4 x 4 x 4 bricks of `f32` log-odds rather than a pointer octree
//!   (about 4 bytes per voxel in free space, no pointer per node), with no
//!   multi-resolution queries and no pruning in memory; the arithmetic is OctoMap's (`f32`
//!   sums clamped after each update, one update per voxel per scan, in scan order), so
//!   the map is the same for any thread count;
//! * keys are limited to OctoMap's 16-bit range (±32,768 voxels per axis, ±1.6 km at
//!   0.05 m), so every map can be written as a `.bt`; a ray whose endpoint (or cut point)
//!   lies outside is skipped whole, as OctoMap skips it;
//! * the voxel traversal is olmap's exact one ([`crate::occupancy::VoxelRay`]); OctoMap's
//!   stepping differs on rays through voxel corners and edges, so a few voxels near such
//!   rays are classified differently.

mod bricks;
mod insert;
mod model;
mod pipeline;

pub use insert::{LogOddsInsertStats, MAX_BRICKS};
pub use model::{logit, LogOddsModel};
pub use pipeline::{run_free_space, FreeSpaceJob, FreeSpaceReport, FreeSpaceRun};

use std::path::Path;

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use self::bricks::{join, split, Bricks, BRICK_VOXELS};
use self::model::{is_unknown, F32Model, UNKNOWN};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Pose, VoxelKey};

/// What a log-odds map knows about a voxel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VoxelState {
    /// Never observed.
    Unknown,
    /// Observed, with an occupancy probability below the threshold.
    Free,
    /// Observed, with an occupancy probability at or above the threshold.
    Occupied,
}

/// What a [`LogOddsMap`] holds and the memory it takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct LogOddsStats {
    /// Known (observed) voxels.
    pub voxels: usize,
    /// Known voxels classified occupied.
    pub occupied: usize,
    /// Known voxels classified free.
    pub free: usize,
    /// Bricks of 4 x 4 x 4 voxels allocated.
    pub bricks: usize,
    /// Bytes held by the map's storage (bricks and their index).
    pub memory_bytes: usize,
}

impl LogOddsStats {
    /// Bytes per known voxel (0 for an empty map).
    pub fn bytes_per_voxel(&self) -> f64 {
        if self.voxels == 0 {
            0.0
        } else {
            self.memory_bytes as f64 / self.voxels as f64
        }
    }
}

/// A 3D log-odds occupancy map with free space, at OctoMap's semantics (see the module
/// documentation).
///
/// ```
/// use olmap::cloud::PointCloud;
/// use olmap::geometry::{Pose, VoxelKey};
/// use olmap::occupancy::{LogOddsMap, LogOddsModel, VoxelState};
/// use nalgebra::Point3;
/// let mut map = LogOddsMap::new(0.1, LogOddsModel::default()).unwrap();
/// let scan = PointCloud::from_points(vec![Point3::new(0.45, 0.05, 0.05)]);
/// map.insert_scan(&scan, &Pose::identity()).unwrap();
/// let s = map.stats();
/// assert_eq!((s.voxels, s.occupied, s.free), (5, 1, 4));
/// // One hit: log-odds logit(0.7) = 0.847, probability 0.7.
/// let p = map.probability(&VoxelKey::new(4, 0, 0)).unwrap();
/// assert!((p - 0.7).abs() < 1e-3);
/// assert_eq!(map.state(&VoxelKey::new(2, 0, 0)), VoxelState::Free);
/// ```
#[derive(Clone)]
pub struct LogOddsMap {
    resolution: f64,
    model: LogOddsModel,
    f32_model: F32Model,
    bricks: Bricks,
    voxels: usize,
    /// [`MAX_BRICKS`], lowered by tests.
    brick_limit: usize,
}

impl std::fmt::Debug for LogOddsMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogOddsMap")
            .field("resolution", &self.resolution)
            .field("model", &self.model)
            .field("voxels", &self.voxels)
            .finish()
    }
}

impl LogOddsMap {
    /// An empty map of `resolution` metres per voxel edge with a sensor model. A
    /// resolution that is not positive and finite, or a bad model
    /// ([`LogOddsModel::validate`]), is [`Error::InvalidArgument`].
    pub fn new(resolution: f64, model: LogOddsModel) -> Result<Self> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "resolution must be a positive number of metres, got {resolution}"
            )));
        }
        model.validate()?;
        Ok(LogOddsMap {
            resolution,
            model,
            f32_model: model.f32_model(),
            bricks: Bricks::default(),
            voxels: 0,
            brick_limit: MAX_BRICKS,
        })
    }

    /// Scans placed at their poses (`T_map_sensor`) ray traced into a new map of
    /// `resolution` metres with OctoMap's default sensor model, rays cut at `max_range`
    /// metres: a mapping run's map that keeps its free space, for localising in
    /// ([`crate::align::Localizer::with_free_space`] through [`LogOddsMap::write_bt`] and
    /// [`crate::occupancy::read_map`]). The same scans give the same map in any order of
    /// threads.
    pub fn of_placed_scans<'a>(
        resolution: f64,
        max_range: f64,
        scans: impl IntoIterator<Item = (&'a PointCloud, &'a Pose)>,
    ) -> Result<Self> {
        let mut map = LogOddsMap::new(
            resolution,
            LogOddsModel {
                max_range,
                ..Default::default()
            },
        )?;
        for (cloud, pose) in scans {
            map.insert_scan(cloud, pose)?;
        }
        Ok(map)
    }

    /// Voxel edge, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// The sensor model.
    pub fn model(&self) -> &LogOddsModel {
        &self.model
    }

    /// Known voxels.
    pub fn len(&self) -> usize {
        self.voxels
    }

    /// Whether no voxel was observed.
    pub fn is_empty(&self) -> bool {
        self.voxels == 0
    }

    fn raw(&self, key: &VoxelKey) -> f32 {
        split(*key)
            .and_then(|(id, i)| self.bricks.get(id).map(|b| b[i]))
            .unwrap_or(UNKNOWN)
    }

    fn classify(&self, v: f32) -> VoxelState {
        if is_unknown(v) {
            VoxelState::Unknown
        } else if v >= self.f32_model.threshold {
            VoxelState::Occupied
        } else {
            VoxelState::Free
        }
    }

    /// The state of a voxel.
    pub fn state(&self, key: &VoxelKey) -> VoxelState {
        self.classify(self.raw(key))
    }

    /// The state of the voxel holding a point (metres, map frame).
    pub fn state_at(&self, p: &Point3<f64>) -> VoxelState {
        VoxelKey::from_point(p, self.resolution)
            .map(|k| self.state(&k))
            .unwrap_or(VoxelState::Unknown)
    }

    /// A voxel's log-odds, `None` when unknown.
    pub fn log_odds(&self, key: &VoxelKey) -> Option<f64> {
        let v = self.raw(key);
        (!is_unknown(v)).then(|| f64::from(v))
    }

    /// A voxel's occupancy probability, `None` when unknown.
    pub fn probability(&self, key: &VoxelKey) -> Option<f64> {
        self.log_odds(key).map(|l| 1.0 / (1.0 + (-l).exp()))
    }

    /// Every known voxel and its state, brick by brick (in no set order).
    pub fn voxels(&self) -> impl Iterator<Item = (VoxelKey, VoxelState)> + '_ {
        self.bricks.iter().flat_map(move |(id, brick)| {
            brick
                .iter()
                .enumerate()
                .filter(|(_, &v)| !is_unknown(v))
                .map(move |(i, &v)| (join(id, i), self.classify(v)))
        })
    }

    /// What the map holds and its memory.
    pub fn stats(&self) -> LogOddsStats {
        let mut occupied = 0;
        for (_, brick) in self.bricks.iter() {
            occupied += brick
                .iter()
                .filter(|&&v| !is_unknown(v) && v >= self.f32_model.threshold)
                .count();
        }
        LogOddsStats {
            voxels: self.voxels,
            occupied,
            free: self.voxels - occupied,
            bricks: self.bricks.len(),
            memory_bytes: self.bricks.memory_bytes(),
        }
    }

    /// The occupied voxels as an occupancy list (count 1 each, as a `.bt` tree read as a
    /// map gives them) and the free ones as the map's [`crate::occupancy::FreeSpace`]: what
    /// a localisation in this map ([`crate::align::Localizer::with_free_space`]) takes.
    pub fn occupancy_and_free(
        &self,
    ) -> Result<(crate::occupancy::OccupancyList, crate::occupancy::FreeSpace)> {
        let mut occupied = crate::occupancy::OccupancyList::new(self.resolution)?;
        for (k, s) in self.voxels() {
            if s == VoxelState::Occupied {
                occupied.set(k, 1)?;
            }
        }
        Ok((occupied, crate::occupancy::FreeSpace::of_log_odds(self)))
    }

    /// Gives back spare capacity (after the last insertion).
    pub fn shrink_to_fit(&mut self) {
        self.bricks.shrink_to_fit();
    }

    /// Writes the map as an OctoMap `.bt` tree with its free and occupied voxels
    /// (maximum likelihood, pruned: eight children of one state become one leaf), the file
    /// complete or not at all (every key is within OctoMap's range). Memory while writing:
    /// 8 bytes per known voxel (their sorted Morton codes) and the file's bytes.
    pub fn write_bt(&self, path: &Path) -> Result<crate::io::octomap_bt::BtStats> {
        let voxels = Counted {
            inner: self.voxels().map(|(k, s)| (k, s == VoxelState::Occupied)),
            left: self.voxels,
        };
        crate::io::octomap_bt::write_classified_path(path, self.resolution, voxels)
    }
}

/// An iterator of known length (the writer reserves its codes from the size hint).
struct Counted<I> {
    inner: I,
    left: usize,
}

impl<I: Iterator> Iterator for Counted<I> {
    type Item = I::Item;
    fn next(&mut self) -> Option<I::Item> {
        self.left = self.left.saturating_sub(1);
        self.inner.next()
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        (self.left, Some(self.left))
    }
}

const _: () = assert!(BRICK_VOXELS == 64, "the insertion masks are u64");

#[cfg(test)]
mod tests;
