//! The nodes of the exact search and their bounds: blocks of rotations and translations,
//! the per-thread scratch, and [`Bnb`], which turns a node into its scan keys, sampled
//! offsets, children and bounds.

use nalgebra::{Point3, Rotation3, UnitQuaternion, Vector3};

use super::bound::Level;
use crate::align::lattice::{cell_index, Lattice, Scored};
use crate::geometry::rotation_from_yaw_pitch_roll;

/// A node found worth expanding: its bound, rotation block and translation block.
#[derive(Debug, Clone, Copy)]
pub(super) struct Block {
    /// The node's score bound.
    pub(super) bound: i64,
    /// Rotation block indices.
    pub(super) rot: [i32; 3],
    /// Translation block indices.
    pub(super) trans: [i32; 3],
}

impl Block {
    /// Best bound first; ties by (rotation block, translation block), lexicographically.
    pub(super) fn best_first(&self, other: &Block) -> std::cmp::Ordering {
        other
            .bound
            .cmp(&self.bound)
            .then((self.rot, self.trans).cmp(&(other.rot, other.trans)))
    }
}

/// A child kept for expansion: the block and the slot of its per-voxel values.
#[derive(Debug, Clone, Copy)]
pub(super) struct Kid {
    /// Bound and blocks.
    pub(super) block: Block,
    /// Where its per-voxel values are in the level's buffer.
    pub(super) slot: usize,
}

/// Per-thread scratch, counts and the best pose found.
pub(super) struct Worker {
    pub(super) keys: Vec<[i64; 3]>,
    /// Per level: the rotation block whose keys `level_keys` holds. Nodes that share a
    /// rotation block share their keys, and depth first visits them one after another.
    pub(super) keys_of: Vec<Option<[i32; 3]>>,
    /// Per level: the keys of the rotation block `keys_of`.
    pub(super) level_keys: Vec<Vec<[i64; 3]>>,
    /// Per level: the children kept (bound, rotation block, translation block, slot).
    pub(super) kids: Vec<Vec<Kid>>,
    /// Per level: the children's per-voxel values, `scan.len()` per slot.
    pub(super) vals: Vec<Vec<i8>>,
    /// Per level: suffix sums of the values of the node being expanded.
    pub(super) rest: Vec<Vec<i64>>,
    /// Per level: the voxel order of the node being expanded.
    pub(super) order: Vec<Vec<u32>>,
    /// The children of one rotation being bounded.
    pub(super) live: Vec<Child>,
    /// The per-voxel values of the roots of one rotation block.
    pub(super) root_vals: Vec<i8>,
    pub(super) best: Option<Scored>,
    pub(super) bounded: Vec<usize>,
    pub(super) passed: Vec<usize>,
}

impl Worker {
    /// Empty scratch and zero counts for a search of `n_levels` levels.
    pub(super) fn new(n_levels: usize) -> Self {
        Worker {
            keys: Vec::new(),
            keys_of: vec![None; n_levels],
            level_keys: vec![Vec::new(); n_levels],
            kids: vec![Vec::new(); n_levels],
            vals: vec![Vec::new(); n_levels],
            rest: vec![Vec::new(); n_levels],
            order: vec![Vec::new(); n_levels],
            live: Vec::new(),
            root_vals: Vec::new(),
            best: None,
            bounded: vec![0; n_levels],
            passed: vec![0; n_levels],
        }
    }
}

/// A child being bounded: translation block, its sampled offset, the running sum and hits,
/// and where its per-voxel values go.
pub(super) struct Child {
    pub(super) t: [i32; 3],
    pub(super) offset: [i64; 3],
    pub(super) sum: i64,
    pub(super) hits: u32,
    pub(super) slot: usize,
}

/// Half the width of a rotation block of level `r`, in finest angular steps: the block
/// covers `2^r` steps, and its centre is this far from its first and last.
pub(super) fn half_steps(r: u32) -> f64 {
    ((1u64 << r) - 1) as f64 / 2.0
}

impl Child {
    pub(super) fn new(t: [i32; 3], offset: [i64; 3], slot: usize) -> Self {
        Child {
            t,
            offset,
            sum: 0,
            hits: 0,
            slot,
        }
    }
}

/// Voxels summed between two tests of the cut.
const CHUNK: usize = 32;

/// A cluster head of an earlier pass: its neighbourhood is searched no more.
pub(super) struct Head {
    pub(super) t: Vector3<f64>,
    pub(super) rot: UnitQuaternion<f64>,
}

pub(super) struct Bnb<'a> {
    pub(super) scan: &'a [Point3<f64>],
    pub(super) lattice: &'a Lattice,
    pub(super) levels: Vec<Level>,
    pub(super) n_r: [i32; 3],
    pub(super) n_t: [i32; 3],
    pub(super) searched_t: [bool; 3],
    pub(super) searched_r: [bool; 3],
    pub(super) top: u32,
    pub(super) ambiguity_distance: f64,
    pub(super) ambiguity_angle: f64,
}

impl Bnb<'_> {
    /// Half the angular width of a rotation block of level `r`, per searched axis.
    pub(super) fn half_width(&self, r: u32) -> f64 {
        half_steps(r) * self.lattice.dtheta(0)
    }

    /// The rotation at the centre of block `rb` of level `r`.
    pub(super) fn centre(&self, rb: [i32; 3], r: u32) -> Rotation3<f64> {
        let l = self.lattice;
        let d = l.dtheta(0);
        let h = half_steps(r);
        let a = [0, 1, 2].map(|i| {
            let steps = ((rb[i] as i64) << r) as f64 + if self.searched_r[i] { h } else { 0.0 };
            l.angle0[i] + steps * d
        });
        rotation_from_yaw_pitch_roll(a[0], a[1], a[2])
    }

    /// The scan's window starts for the nodes of rotation block `rb` at `level`, in the
    /// level's sampled cells.
    pub(super) fn fill_keys(&self, rb: [i32; 3], level: u32, out: &mut Vec<[i64; 3]>) {
        let lv = &self.levels[level as usize];
        let rot = self.centre(rb, lv.rot_level);
        let (t0, cell) = (self.lattice.t0, self.lattice.finest);
        out.clear();
        out.extend(self.scan.iter().map(|c| {
            // The formula of `key_of` (`v - 0.0` is `v`, so the same keys at margin 0).
            let p = rot * c.coords + t0;
            let k = |v: f64, m: f64, s: u32| -> i64 { cell_index(v - m, cell) >> s };
            [
                k(p.x, lv.margin[0], lv.shift[0]),
                k(p.y, lv.margin[1], lv.shift[1]),
                k(p.z, lv.margin[2], lv.shift[2]),
            ]
        }));
    }

    /// The sampled offset of translation block `tb` at `level`.
    #[inline]
    pub(super) fn offset(&self, tb: [i32; 3], level: u32) -> [i64; 3] {
        let lv = &self.levels[level as usize];
        [0, 1, 2].map(|i| {
            if self.searched_t[i] {
                (tb[i] as i64) << (level - lv.shift[i])
            } else {
                0
            }
        })
    }

    /// Bounds (scores at level 0) of the translation blocks `live` at `level`, for the
    /// keys of one rotation block, a chunk of voxels at a time for all of them together:
    /// their windows are neighbours in the grids.
    ///
    /// `parent` holds the per-voxel values of the parent node (upper bounds for every pose
    /// below it too) and `rest[i]` the sum of `parent` over `order[i..]`. A voxel's value is
    /// the smaller of its own and its parent's; voxels are read in `order`, and a block is
    /// dropped as soon as what it has summed plus the parent's values of the voxels left
    /// falls below `cut()`. Each block's values go to `buf[slot * n..]`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn bound_children(
        &self,
        level: u32,
        keys: &[[i64; 3]],
        order: &[u32],
        parent: &[i8],
        rest: &[i64],
        live: &mut Vec<Child>,
        buf: &mut [i8],
        cut: impl Fn() -> i64,
    ) {
        let lv = &self.levels[level as usize];
        let n = keys.len();
        let mut pos = 0;
        while pos < n && !live.is_empty() {
            let end = (pos + CHUNK).min(n);
            let cut = cut();
            live.retain_mut(|c| {
                let o = c.offset;
                let out = &mut buf[c.slot * n..(c.slot + 1) * n];
                for &i in &order[pos..end] {
                    let i = i as usize;
                    let k = keys[i];
                    let v = lv.value([k[0] + o[0], k[1] + o[1], k[2] + o[2]]);
                    // At the leaves the value is exact (never above the parent's).
                    let v = if level == 0 {
                        v
                    } else {
                        v.min(parent[i] as i64)
                    };
                    c.sum += v;
                    c.hits += (v == 2) as u32;
                    out[i] = v as i8;
                }
                c.sum + rest[end] >= cut
            });
            pos = end;
        }
    }

    /// The children of a block of `level` (indices at `level - 1`) on the searched axes.
    pub(super) fn split(
        block: [i32; 3],
        level: u32,
        count: [i32; 3],
        searched: [bool; 3],
    ) -> Vec<[i32; 3]> {
        let half = |i: usize| -> Vec<i32> {
            if !searched[i] {
                return vec![block[i]];
            }
            let first = 2 * block[i];
            let mut v = vec![first];
            if ((first + 1) as i64) << (level - 1) < count[i] as i64 {
                v.push(first + 1);
            }
            v
        };
        let (xs, ys, zs) = (half(0), half(1), half(2));
        let mut out = Vec::with_capacity(xs.len() * ys.len() * zs.len());
        for &x in &xs {
            for &y in &ys {
                for &z in &zs {
                    out.push([x, y, z]);
                }
            }
        }
        out
    }

    pub(super) fn rot_children(&self, rb: [i32; 3], level: u32) -> Vec<[i32; 3]> {
        let (r, cr) = (
            self.levels[level as usize].rot_level,
            self.levels[level as usize - 1].rot_level,
        );
        if cr == r {
            vec![rb]
        } else {
            Self::split(rb, r, self.n_r, self.searched_r)
        }
    }

    /// Block `b` of `level` as index ranges per axis (clipped to the region).
    pub(super) fn t_range(&self, tb: [i32; 3], level: u32) -> [(i32, i32); 3] {
        [0, 1, 2].map(|i| {
            if self.searched_t[i] {
                let a = tb[i] << level;
                (a, ((tb[i] + 1) << level).min(self.n_t[i]) - 1)
            } else {
                (0, 0)
            }
        })
    }
}
