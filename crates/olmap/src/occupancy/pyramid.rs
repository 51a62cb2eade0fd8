//! Downsampling (thesis Algorithm 4) and the multi-resolution [`Pyramid`].

use super::list::OccupancyList;
use super::packed::{entry_count, entry_key, pack_key, unpack_key};
use super::raytrace::{InsertStats, SensorModel};
use super::table::VoxelTable;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Pose, VoxelKey};

#[inline]
fn parent(k: VoxelKey, f: i32) -> VoxelKey {
    VoxelKey::new(k.x.div_euclid(f), k.y.div_euclid(f), k.z.div_euclid(f))
}

impl OccupancyList {
    /// The list at `factor` times coarser resolution (thesis Algorithm 4): key `k` goes to
    /// `floor(k / factor)`; a coarse voxel's count is the **largest** count among its fine
    /// voxels.
    ///
    /// The thesis only needs occupancy at coarse levels; taking the maximum (rather than
    /// the sum) keeps counts unsaturated, makes `downsample(a)` then `downsample(b)` equal
    /// `downsample(a * b)` exactly, and lets a [`Pyramid`] update a coarse voxel from its
    /// eight children when a scan changes the fine level.
    ///
    /// ```
    /// use olmap::occupancy::OccupancyList;
    /// use olmap::geometry::VoxelKey;
    /// let mut fine = OccupancyList::new(0.05).unwrap();
    /// fine.set(VoxelKey::new(-1, 0, 0), 3).unwrap();
    /// fine.set(VoxelKey::new(-2, 1, 1), 5).unwrap();
    /// let coarse = fine.downsample(2).unwrap();
    /// assert_eq!(coarse.resolution(), 0.1);
    /// assert_eq!(coarse.len(), 1);
    /// assert_eq!(coarse.count(VoxelKey::new(-1, 0, 0)), 5);
    /// ```
    pub fn downsample(&self, factor: u32) -> Result<OccupancyList> {
        if factor == 0 || factor > 1 << 16 {
            return Err(Error::InvalidArgument(format!(
                "downsampling factor must be between 1 and 65536, got {factor}"
            )));
        }
        let f = factor as i32;
        let mut out =
            OccupancyList::with_capacity(self.resolution() * factor as f64, self.len() / 2)?;
        for e in self.table.entries() {
            let p = parent(unpack_key(entry_key(e)), f);
            let c = entry_count(e);
            let k = pack_key(p).expect("a coarser key is in range");
            out.table.update(k, |old| old.max(c));
        }
        Ok(out)
    }
}

/// An occupancy list with cached coarser copies at factors 1, 2, 4, ..., 2^(levels-1).
///
/// Map building adds scans one by one; [`Pyramid::insert_scan`] updates only the coarse
/// voxels above the fine voxels the scan changed, so the pyramid never has to be rebuilt.
///
/// ```
/// use olmap::cloud::PointCloud;
/// use olmap::geometry::Pose;
/// use olmap::occupancy::{OccupancyList, Pyramid, SensorModel};
/// use nalgebra::Point3;
/// let mut pyramid = Pyramid::new(OccupancyList::new(0.05).unwrap(), 5).unwrap();
/// let scan = PointCloud::from_points(vec![Point3::new(2.0, 0.3, 0.1), Point3::new(2.0, -0.3, 0.1)]);
/// pyramid.insert_scan(&scan, &Pose::identity(), &SensorModel::default()).unwrap();
/// assert_eq!(pyramid.level(0).len(), 2);
/// assert_eq!(pyramid.level(4).resolution(), 0.8);
/// assert_eq!(pyramid.level(4).len(), 2); // x = 2.0 m is in the coarse cell 2, y spans cells -1 and 0
/// ```
#[derive(Debug, Clone)]
pub struct Pyramid {
    levels: Vec<OccupancyList>,
}

impl Pyramid {
    /// Builds `levels` levels (at least 1) from a base list.
    pub fn new(base: OccupancyList, levels: usize) -> Result<Self> {
        if levels == 0 || levels > 17 {
            return Err(Error::InvalidArgument(format!(
                "a pyramid needs 1 to 17 levels, got {levels}"
            )));
        }
        let mut v = vec![base];
        for i in 1..levels {
            let next = v[i - 1].downsample(2)?;
            v.push(next);
        }
        Ok(Pyramid { levels: v })
    }

    /// The pyramid from level `k` up (level `k` becomes the base), copied; `None` when
    /// `k` is not a level.
    pub(crate) fn above(&self, k: usize) -> Option<Pyramid> {
        (k < self.levels.len()).then(|| Pyramid {
            levels: self.levels[k..].to_vec(),
        })
    }

    /// Number of levels.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Level `i` (factor `2^i`).
    ///
    /// # Panics
    /// If `i >= self.levels()`.
    pub fn level(&self, i: usize) -> &OccupancyList {
        &self.levels[i]
    }

    /// The finest level.
    pub fn base(&self) -> &OccupancyList {
        &self.levels[0]
    }

    /// Downsampling factor of level `i`.
    pub fn factor(i: usize) -> u32 {
        1 << i
    }

    /// Integrates a scan into the finest level (see [`OccupancyList::insert_scan`]) and
    /// updates the coarse levels above the voxels it changed.
    pub fn insert_scan(
        &mut self,
        cloud: &PointCloud,
        t_map_sensor: &Pose,
        model: &SensorModel,
    ) -> Result<InsertStats> {
        let (stats, changed) = self.levels[0].insert_scan_tracked(cloud, t_map_sensor, model)?;
        self.propagate(changed);
        Ok(stats)
    }

    /// Adds another list's counts to the finest level and updates the coarse levels.
    pub fn merge(&mut self, other: &OccupancyList) -> Result<()> {
        self.levels[0].merge(other)?;
        self.propagate(other.table.entries().map(entry_key).collect());
        Ok(())
    }

    /// Recomputes, level by level, the parents of the changed keys from their 8 children.
    fn propagate(&mut self, mut changed: Vec<u64>) {
        for i in 1..self.levels.len() {
            let mut parents: Vec<u64> = changed
                .iter()
                .map(|&k| pack_key(parent(unpack_key(k), 2)).expect("in range"))
                .collect();
            parents.sort_unstable();
            parents.dedup();
            let (finer, coarser) = self.levels.split_at_mut(i);
            let (finer, coarse) = (&finer[i - 1].table, &mut coarser[0].table);
            for &p in &parents {
                let k = unpack_key(p);
                let mut best = 0;
                for dx in 0..2 {
                    for dy in 0..2 {
                        for dz in 0..2 {
                            let child = VoxelKey::new(2 * k.x + dx, 2 * k.y + dy, 2 * k.z + dz);
                            if let Some(c) = pack_key(child) {
                                best = best.max(finer.get(c));
                            }
                        }
                    }
                }
                coarse_set(coarse, p, best);
            }
            changed = parents;
        }
    }
}

fn coarse_set(table: &mut VoxelTable, key: u64, count: u16) {
    table.update(key, |_| count);
}
