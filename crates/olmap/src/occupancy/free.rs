//! Free space known about a map: where the rays of the scans that built it passed.
//!
//! An occupancy list keeps only where surfaces are. A map that also says where its scans
//! saw through lets a localisation in it check both sides of a pose: a scan's surfaces
//! that would lie in the map's free space contradict it (what `align` checks between two
//! scans, each with its rays). OctoMap trees written with free nodes (`olmap voxelize
//! --free-space`, OctoMap's own maps) carry it as free leaves: cubes of voxels, most of
//! one voxel, some pruned into larger cubes.

use crate::error::{Error, Result};
use crate::geometry::VoxelKey;
use crate::occupancy::{LogOddsMap, VoxelState};

/// A box of free voxels, `lo` to `hi` inclusive on every axis (an OctoMap free leaf is a
/// cube; a coarsened one may be any box).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FreeBox {
    /// The lowest corner voxel.
    pub lo: VoxelKey,
    /// The highest corner voxel (≥ `lo` on every axis).
    pub hi: VoxelKey,
}

impl FreeBox {
    /// The voxels the box holds.
    pub fn voxels(&self) -> u64 {
        let d = |a: i32, b: i32| (i64::from(b) - i64::from(a) + 1) as u64;
        d(self.lo.x, self.hi.x) * d(self.lo.y, self.hi.y) * d(self.lo.z, self.hi.z)
    }
}

/// The free space known about a map, at the map's voxel edge: boxes of free voxels.
///
/// Memory: 24 bytes a box (a `.bt` tree's free leaf is one box).
///
/// ```
/// use olmap::geometry::VoxelKey;
/// use olmap::occupancy::FreeSpace;
/// let free = FreeSpace::from_voxels(0.1, [VoxelKey::new(0, 0, 0), VoxelKey::new(1, 0, 0)]).unwrap();
/// assert_eq!(free.voxels(), 2);
/// // At twice the voxel edge both voxels fall in one cell.
/// assert_eq!(free.coarsened(2).unwrap().voxels(), 1);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct FreeSpace {
    resolution: f64,
    boxes: Vec<FreeBox>,
}

impl FreeSpace {
    /// No free space known, at voxel edge `resolution` (metres, finite and > 0).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a resolution that is not finite and positive.
    pub fn new(resolution: f64) -> Result<Self> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "free space resolution must be finite and > 0 (got {resolution})"
            )));
        }
        Ok(FreeSpace {
            resolution,
            boxes: Vec::new(),
        })
    }

    /// Free space made of single voxels.
    ///
    /// # Errors
    /// As [`FreeSpace::new`].
    pub fn from_voxels(resolution: f64, keys: impl IntoIterator<Item = VoxelKey>) -> Result<Self> {
        let mut free = Self::new(resolution)?;
        free.boxes = keys.into_iter().map(|k| FreeBox { lo: k, hi: k }).collect();
        Ok(free)
    }

    /// The free voxels of a log-odds map (those it classifies free).
    pub fn of_log_odds(map: &LogOddsMap) -> Self {
        let keys = map
            .voxels()
            .filter(|(_, s)| *s == VoxelState::Free)
            .map(|(k, _)| k);
        Self::from_voxels(map.resolution(), keys).expect("a log-odds map's resolution is valid")
    }

    /// Adds a box of free voxels.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `hi` is below `lo` on an axis.
    pub fn push(&mut self, lo: VoxelKey, hi: VoxelKey) -> Result<()> {
        if hi.x < lo.x || hi.y < lo.y || hi.z < lo.z {
            return Err(Error::InvalidArgument(format!(
                "a free box's high corner {hi:?} is below its low corner {lo:?}"
            )));
        }
        self.boxes.push(FreeBox { lo, hi });
        Ok(())
    }

    /// The voxel edge, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Checks that the free space is at a map's voxel edge (`resolution`, metres, up to a
    /// relative 1e-9).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming both edges when it is not.
    pub fn check_resolution(&self, resolution: f64) -> Result<()> {
        if (self.resolution - resolution).abs() > 1e-9 * resolution {
            return Err(Error::InvalidArgument(format!(
                "the free space's voxel edge ({} m) is not the map's ({resolution} m)",
                self.resolution
            )));
        }
        Ok(())
    }

    /// The boxes.
    pub fn boxes(&self) -> &[FreeBox] {
        &self.boxes
    }

    /// Free voxels (boxes are not checked for overlap: a voxel in two boxes counts twice).
    pub fn voxels(&self) -> u64 {
        self.boxes
            .iter()
            .fold(0u64, |n, b| n.saturating_add(b.voxels()))
    }

    /// Whether no free voxel is known.
    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// The same free space at `factor` times the voxel edge (a power of two, as a map is
    /// coarsened by [`crate::occupancy::OccupancyList::downsample`]): a coarse cell is free
    /// when any of its voxels is (a ray crossed it). Boxes that fall on the same coarse
    /// cells are kept once (at a factor of 1 the boxes are kept as they are).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `factor` is not a power of two of at most 2^16.
    pub fn coarsened(&self, factor: u32) -> Result<Self> {
        if !factor.is_power_of_two() || factor > 1 << 16 {
            return Err(Error::InvalidArgument(format!(
                "a free space is coarsened by a power of two up to 65536 (got {factor})"
            )));
        }
        if factor == 1 {
            return Ok(self.clone());
        }
        let shift = factor.trailing_zeros();
        let mut boxes: Vec<FreeBox> = self
            .boxes
            .iter()
            .map(|b| FreeBox {
                lo: shifted(b.lo, shift),
                hi: shifted(b.hi, shift),
            })
            .collect();
        boxes.sort_unstable();
        boxes.dedup();
        Ok(FreeSpace {
            resolution: self.resolution * f64::from(factor),
            boxes,
        })
    }

    /// The key box holding every free voxel at `2^shift` times the voxel edge, `None` when
    /// none is known.
    pub(crate) fn key_box_at(&self, shift: u32) -> Option<([i64; 3], [i64; 3])> {
        let mut lo = [i64::MAX; 3];
        let mut hi = [i64::MIN; 3];
        for b in &self.boxes {
            let (l, h) = (cell(b.lo, shift), cell(b.hi, shift));
            for i in 0..3 {
                lo[i] = lo[i].min(l[i]);
                hi[i] = hi[i].max(h[i]);
            }
        }
        (!self.boxes.is_empty()).then_some((lo, hi))
    }

    /// Calls `f(x, y, z_lo, z_hi)` with every column of cells at `2^shift` times the voxel
    /// edge that holds free voxels: cells `(x, y, z_lo..=z_hi)` (a cell in several boxes more
    /// than once). A box is one call per `(x, y)`, so filling a grid a run of bits at a time
    /// costs the box's columns, not its cells.
    pub(crate) fn for_each_column_at(&self, shift: u32, mut f: impl FnMut(i64, i64, i64, i64)) {
        for b in &self.boxes {
            let (l, h) = (cell(b.lo, shift), cell(b.hi, shift));
            for x in l[0]..=h[0] {
                for y in l[1]..=h[1] {
                    f(x, y, l[2], h[2]);
                }
            }
        }
    }
}

/// A key's cell at `2^shift` times the voxel edge.
fn cell(k: VoxelKey, shift: u32) -> [i64; 3] {
    [k.x, k.y, k.z].map(|v| i64::from(v) >> shift)
}

fn shifted(k: VoxelKey, shift: u32) -> VoxelKey {
    VoxelKey::new(k.x >> shift, k.y >> shift, k.z >> shift)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarsening_keeps_every_cell_that_holds_a_free_voxel_once() {
        let mut free = FreeSpace::new(0.05).unwrap();
        free.push(VoxelKey::new(-3, 0, 0), VoxelKey::new(-1, 1, 1))
            .unwrap();
        free.push(VoxelKey::new(-4, 0, 0), VoxelKey::new(-4, 0, 0))
            .unwrap();
        let c = free.coarsened(4).unwrap();
        assert!((c.resolution() - 0.2).abs() < 1e-12);
        // Keys -4..-1 fall in coarse cell -1 (floor division), 0..1 in 0.
        assert_eq!(
            c.boxes(),
            &[FreeBox {
                lo: VoxelKey::new(-1, 0, 0),
                hi: VoxelKey::new(-1, 0, 0)
            }]
        );
        let mut cells = Vec::new();
        free.for_each_column_at(1, |x, y, z0, z1| cells.extend((z0..=z1).map(|z| [x, y, z])));
        cells.sort_unstable();
        cells.dedup();
        assert_eq!(cells, vec![[-2, 0, 0], [-1, 0, 0]]);
        assert_eq!(free.key_box_at(1), Some(([-2, 0, 0], [-1, 0, 0])));
        assert!(free.coarsened(3).is_err());
        assert!(free
            .push(VoxelKey::new(1, 0, 0), VoxelKey::new(0, 0, 0))
            .is_err());
    }
}
