//! Scan insertion into a [`LogOddsMap`] at OctoMap's semantics
//! (`OccupancyOcTree::insertPointCloud` with `computeUpdate`, neither lazy nor discretised).
//!
//! For every point of a scan: the voxels a ray passes through from the sensor's voxel up
//! to, but not including, the endpoint's voxel are observed free; the endpoint's voxel is
//! observed occupied if the point is within the maximum range. A ray longer than the range
//! is cut there and observes free space only (its last voxel, the one at the cut, is not
//! updated). Each voxel is updated once per scan, and a voxel that is some ray's endpoint
//! is not also freed by the scan.
//!
//! How: the rays are walked in parallel chunks; each chunk marks the voxels it saw in
//! per-brick bit masks (one `u64` for free, one for hit, per touched brick of 64 voxels;
//! consecutive steps of a ray mostly stay in one brick, so most marks are one OR). The
//! chunks' masks are OR-ed together and then applied brick by brick. Bitwise OR does not
//! depend on the order, so the map is the same for any thread count.

use rayon::prelude::*;

use super::bricks::{split, BrickId, IdMap};
use std::sync::atomic::{AtomicUsize, Ordering};

use super::bricks::Bricks;
use super::model::is_unknown;
use super::LogOddsMap;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Pose, VoxelKey};
use crate::occupancy::VoxelRay;

/// The most bricks (of 4 x 4 x 4 voxels, 256 bytes each) a [`LogOddsMap`] may hold:
/// 2^23 = 8,388,608, about 537 million voxels and 2.2 GiB with the index. A scan that would
/// take a map beyond it is refused with [`Error::TooLarge`] before the map changes, and the
/// marking of one scan stops once its fresh bricks (counted over all threads) pass what
/// the map has left: memory stays bounded whatever a scan holds (a few far points with no
/// maximum range walk long rays through fresh bricks).
pub const MAX_BRICKS: usize = 1 << 23;

/// What one scan insertion into a [`LogOddsMap`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct LogOddsInsertStats {
    /// Rays cast (points of the scan).
    pub rays: u64,
    /// Rays cut at the maximum range (no endpoint hit).
    pub truncated: u64,
    /// Points skipped: non-finite, or with a voxel outside the representable range.
    pub skipped: u64,
    /// Voxel steps walked by all rays together.
    pub voxels_traversed: u64,
    /// Distinct voxels updated as occupied.
    pub occupied_updates: u64,
    /// Distinct voxels updated as free.
    pub free_updates: u64,
    /// Voxels observed for the first time.
    pub new_voxels: u64,
}

impl LogOddsInsertStats {
    /// Adds another insertion's counts to these.
    pub fn add(&mut self, o: &LogOddsInsertStats) {
        self.rays += o.rays;
        self.truncated += o.truncated;
        self.skipped += o.skipped;
        self.voxels_traversed += o.voxels_traversed;
        self.occupied_updates += o.occupied_updates;
        self.free_updates += o.free_updates;
        self.new_voxels += o.new_voxels;
    }
}

/// The voxels of one brick a scan saw free and hit.
#[derive(Clone, Copy)]
struct Mask {
    id: BrickId,
    free: u64,
    hit: u64,
}

/// The budget of fresh bricks (not yet in the map) all chunks of one scan may record
/// together: each chunk counts the fresh bricks it records in one shared counter (a brick
/// several chunks touch is counted by each, so a scan may be refused a little before the
/// map's limit), and marking stops everywhere once the count passes the budget.
struct Budget<'a> {
    existing: &'a Bricks,
    fresh: AtomicUsize,
    allowed: usize,
}

/// The marks of a chunk of rays.
struct Marks<'a> {
    index: IdMap<u32>,
    masks: Vec<Mask>,
    last_id: BrickId,
    last: usize,
    budget: &'a Budget<'a>,
    /// The budget was exceeded: marking stopped, the scan will be refused.
    overflow: bool,
    stats: LogOddsInsertStats,
}

impl<'a> Marks<'a> {
    fn new(budget: &'a Budget<'a>) -> Self {
        Marks {
            index: IdMap::default(),
            masks: Vec::new(),
            last_id: u64::MAX,
            last: 0,
            budget,
            overflow: false,
            stats: LogOddsInsertStats::default(),
        }
    }

    /// The index of brick `id`'s mask, created when needed; `None` when creating it would
    /// pass the budget (then `overflow` is set). `count` is false when merging marks that
    /// were counted when they were made.
    #[inline]
    fn slot(&mut self, id: BrickId, count: bool) -> Option<usize> {
        if id != self.last_id {
            if count && !self.index.contains_key(&id) && self.budget.existing.get(id).is_none() {
                let b = self.budget;
                if b.fresh.fetch_add(1, Ordering::Relaxed) >= b.allowed {
                    self.overflow = true;
                    return None;
                }
            }
            let next = self.masks.len() as u32;
            let i = *self.index.entry(id).or_insert(next);
            if i == next {
                self.masks.push(Mask {
                    id,
                    free: 0,
                    hit: 0,
                });
            }
            self.last_id = id;
            self.last = i as usize;
        }
        Some(self.last)
    }

    #[inline]
    fn mark(&mut self, key: VoxelKey, hit: bool) {
        if let Some((id, bit)) = split(key) {
            let Some(i) = self.slot(id, true) else {
                return;
            };
            let m = &mut self.masks[i];
            if hit {
                m.hit |= 1 << bit;
            } else {
                m.free |= 1 << bit;
            }
        }
    }

    fn merge(self, other: Marks<'a>) -> Marks<'a> {
        let (mut big, small) = if self.masks.len() >= other.masks.len() {
            (self, other)
        } else {
            (other, self)
        };
        big.overflow |= small.overflow;
        for m in &small.masks {
            let Some(i) = big.slot(m.id, false) else {
                unreachable!("merging is not counted")
            };
            big.masks[i].free |= m.free;
            big.masks[i].hit |= m.hit;
        }
        let s = small.stats;
        big.stats.rays += s.rays;
        big.stats.truncated += s.truncated;
        big.stats.skipped += s.skipped;
        big.stats.voxels_traversed += s.voxels_traversed;
        big
    }
}

impl LogOddsMap {
    /// Integrates one scan (see the module documentation of
    /// [`crate::occupancy::LogOddsMap`] for the semantics: OctoMap's `insertPointCloud`).
    ///
    /// `cloud` is in the sensor frame (its origin is where rays start) and `t_map_sensor`
    /// places it in the map. A sensor origin outside the map's key range (OctoMap's,
    /// ±32,768 voxels per axis) is [`Error::InvalidArgument`], and a scan that would take
    /// the map beyond [`MAX_BRICKS`] is [`Error::TooLarge`]; either changes nothing. A
    /// point whose voxel (or whose cut point, beyond the maximum range) is outside the key
    /// range is skipped with its whole ray, as OctoMap skips it. Work is spread over the rayon
    /// thread pool; the map does not depend on the number of threads.
    ///
    /// ```
    /// use olmap::cloud::PointCloud;
    /// use olmap::geometry::Pose;
    /// use olmap::occupancy::{LogOddsMap, LogOddsModel, VoxelState};
    /// use nalgebra::Point3;
    /// let mut map = LogOddsMap::new(0.1, LogOddsModel::default()).unwrap();
    /// let wall = PointCloud::from_points(vec![Point3::new(1.05, 0.05, 0.05)]);
    /// map.insert_scan(&wall, &Pose::identity()).unwrap();
    /// assert_eq!(map.state_at(&Point3::new(1.05, 0.05, 0.05)), VoxelState::Occupied);
    /// assert_eq!(map.state_at(&Point3::new(0.55, 0.05, 0.05)), VoxelState::Free);
    /// assert_eq!(map.state_at(&Point3::new(1.55, 0.05, 0.05)), VoxelState::Unknown);
    /// ```
    pub fn insert_scan(
        &mut self,
        cloud: &PointCloud,
        t_map_sensor: &Pose,
    ) -> Result<LogOddsInsertStats> {
        let res = self.resolution;
        let origin = t_map_sensor.transform_point(&cloud.origin());
        if VoxelKey::from_point(&origin, res).and_then(split).is_none() {
            return Err(Error::InvalidArgument(format!(
                "the sensor origin {origin} is outside the map's representable range"
            )));
        }
        let iso = *t_map_sensor.isometry();
        let max_range = self.model.max_range;
        let limit = self.brick_limit;
        let budget = Budget {
            existing: &self.bricks,
            fresh: AtomicUsize::new(0),
            allowed: limit.saturating_sub(self.bricks.len()),
        };
        let budget = &budget;
        let threads = rayon::current_num_threads().max(1);
        let chunk = (cloud.len() / (4 * threads)).clamp(1024, 1 << 16);
        let marks = cloud
            .points()
            .par_chunks(chunk)
            .map(|points| {
                let mut marks = Marks::new(budget);
                for p in points {
                    if marks.overflow || budget.fresh.load(Ordering::Relaxed) > budget.allowed {
                        marks.overflow = true;
                        break;
                    }
                    marks.stats.rays += 1;
                    let end = iso.transform_point(&p.cast::<f64>());
                    let d = end - origin;
                    let r = d.norm();
                    if !r.is_finite() {
                        marks.stats.skipped += 1;
                        continue;
                    }
                    let (end, hit) = if r > max_range {
                        marks.stats.truncated += 1;
                        (origin + d * (max_range / r), false)
                    } else {
                        (end, true)
                    };
                    let Some(end_key) =
                        VoxelKey::from_point(&end, res).filter(|k| split(*k).is_some())
                    else {
                        marks.stats.skipped += 1;
                        continue;
                    };
                    let ray = VoxelRay::new(&origin, &end, res);
                    let free = ray.remaining().saturating_sub(1);
                    marks.stats.voxels_traversed += free + 1;
                    for key in ray.take(free as usize) {
                        marks.mark(key, false);
                    }
                    if hit {
                        marks.mark(end_key, true);
                    }
                }
                marks
            })
            .reduce(|| Marks::new(budget), Marks::merge);
        let fresh = marks
            .masks
            .iter()
            .filter(|m| self.bricks.get(m.id).is_none())
            .count();
        if marks.overflow || self.bricks.len() + fresh > limit {
            return Err(Error::TooLarge {
                what: format!(
                    "a scan of {} points whose rays cross more voxels than the free-space map \
                     may hold (it has {} bricks of 4x4x4 voxels, the scan adds {}{})",
                    cloud.len(),
                    self.bricks.len(),
                    fresh,
                    if marks.overflow { " and more" } else { "" }
                ),
                limit: format!(
                    "{limit} bricks of 256 bytes: use a coarser resolution or a maximum range"
                ),
            });
        }
        let mut stats = marks.stats;
        let q = self.f32_model;
        for m in &marks.masks {
            let free = m.free & !m.hit;
            stats.occupied_updates += u64::from(m.hit.count_ones());
            stats.free_updates += u64::from(free.count_ones());
            let brick = self.bricks.get_or_insert(m.id);
            for (mut bits, delta) in [(m.hit, q.hit), (free, q.miss)] {
                while bits != 0 {
                    let i = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let v = brick[i];
                    stats.new_voxels += u64::from(is_unknown(v));
                    brick[i] = q.update(v, delta);
                }
            }
        }
        self.voxels += stats.new_voxels as usize;
        Ok(stats)
    }
}
