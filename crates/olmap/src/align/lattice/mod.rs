//! The pose lattice every search shares, and the shared core the searches build on: the
//! prepared problem ([`Problem`]), scored candidates, ranking and the finished
//! [`Alignment`].
//!
//! Poses live on a lattice that refines with the levels. At level `l` the cell is
//! `resolution * 2^l` and the angular step `dθ = cell / R` (thesis (5.6)); a pose is
//! `t = t0 + i * cell` (integer `i` per axis) and `angle = angle0 + j * dθ`. Halving the
//! cell halves both steps, so a pose `(i, j)` at one level is `(2i, 2j)` at the next, and
//! its resampling (Algorithm 6: ±half a cell, ±dθ) is `(2i + {-1, 0, 1}, 2j + {-1, 0, 1})`.
//!
//! This module depends on the scoring kernels only; the searches (multi-resolution,
//! exhaustive, exact) depend on it and never on one another's loops.

mod outcome;
mod problem;

use nalgebra::{Point3, Vector3};

use crate::geometry::Pose;

pub(crate) use self::outcome::{
    distinct, finish, level_report, no_overlap, rank, threshold, Scored,
};
pub use self::outcome::{Alignment, Candidate, LevelReport};
pub(crate) use self::problem::{prepare, region_counts, Problem};

/// One pose of the lattice: rotation indices (yaw, pitch, roll) and translation indices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) struct Cand {
    pub(crate) r: [i32; 3],
    pub(crate) t: [i32; 3],
}

/// Everything the lattice needs to turn indices into poses.
pub(crate) struct Lattice {
    pub(crate) t0: Vector3<f64>,
    pub(crate) angle0: [f64; 3],
    pub(crate) finest: f64,
    pub(crate) range: f64,
    pub(crate) searched_t: [bool; 3],
    pub(crate) searched_r: [bool; 3],
    /// A window's extent from `t0` along x, y, z and from `angle0` along each angle (`None`
    /// for an angle that wraps or a region without bounds): children of a level that fall
    /// a whole step outside it are not searched, so that the window means
    /// what it says (without it the resampling of an edge pose creeps outwards by almost
    /// one coarse cell).
    pub(crate) bounds: Option<([f64; 3], [Option<f64>; 3])>,
}

impl Lattice {
    pub(crate) fn cell(&self, level: usize) -> f64 {
        self.finest * (1u64 << level) as f64
    }

    pub(crate) fn dtheta(&self, level: usize) -> f64 {
        self.cell(level) / self.range
    }

    pub(crate) fn angles(&self, c: &Cand, level: usize) -> [f64; 3] {
        let d = self.dtheta(level);
        [0, 1, 2].map(|i| self.angle0[i] + c.r[i] as f64 * d)
    }

    pub(crate) fn pose(&self, c: &Cand, level: usize) -> Pose {
        let [yaw, pitch, roll] = self.angles(c, level);
        let cell = self.cell(level);
        let t = self.t0 + Vector3::new(c.t[0] as f64, c.t[1] as f64, c.t[2] as f64) * cell;
        Pose::from_xyz_ypr(t.x, t.y, t.z, yaw, pitch, roll)
    }

    /// Whether `c` at `level` lies within the window (less than one step outside it).
    fn in_bounds(&self, c: &Cand, level: usize) -> bool {
        let Some((t, r)) = &self.bounds else {
            return true;
        };
        let cell = self.cell(level);
        let dth = self.dtheta(level);
        let inside = |i: i32, step: f64, extent: f64| {
            let v = i as f64 * step;
            v > -step && v < extent + step
        };
        (0..3).all(|a| inside(c.t[a], cell, t[a]))
            && (0..3).all(|a| r[a].is_none_or(|e| inside(c.r[a], dth, e)))
    }

    /// Algorithm 6: the poses around `c` at the next finer level (`c` is at `level`;
    /// children outside the window are left out).
    pub(crate) fn children(&self, c: &Cand, level: usize, out: &mut Vec<Cand>) {
        let before = out.len();
        let span = |searched: bool| if searched { -1..=1 } else { 0..=0 };
        for a in span(self.searched_r[0]) {
            for b in span(self.searched_r[1]) {
                for g in span(self.searched_r[2]) {
                    for x in span(self.searched_t[0]) {
                        for y in span(self.searched_t[1]) {
                            for z in span(self.searched_t[2]) {
                                out.push(Cand {
                                    r: [2 * c.r[0] + a, 2 * c.r[1] + b, 2 * c.r[2] + g],
                                    t: [2 * c.t[0] + x, 2 * c.t[1] + y, 2 * c.t[2] + z],
                                });
                            }
                        }
                    }
                }
            }
        }
        if self.bounds.is_some() && level > 0 {
            let mut k = before;
            for i in before..out.len() {
                if self.in_bounds(&out[i], level - 1) {
                    out[k] = out[i];
                    k += 1;
                }
            }
            out.truncate(k);
        }
    }
}

/// Keys of moved scan voxels are clamped to `±KEY_CLAMP` cells: far outside every grid
/// (whose keys fit in an `i32`), yet far from `i64` overflow when the scoring adds
/// translations and subtracts box corners. A prior 1e20 m away would otherwise make
/// `floor` saturate at `i64::MAX` and the next addition overflow.
pub(crate) const KEY_CLAMP: f64 = (1u64 << 40) as f64;

/// `floor(v / cell)` as a key, clamped to [`KEY_CLAMP`] (NaN gives 0).
///
/// The floor is taken by truncating and stepping down below a negative fraction, the same
/// value as `f64::floor` for every clamped input (integers up to 2^40 convert exactly):
/// without SSE4.1 in the build target `floor` is a libm call, and the search's scoring
/// makes three per scan voxel and rotation (5 % of a six-degree-of-freedom alignment's
/// samples).
#[inline]
pub(crate) fn cell_index(v: f64, cell: f64) -> i64 {
    let x = (v / cell).clamp(-KEY_CLAMP, KEY_CLAMP);
    let k = x as i64;
    if (k as f64) > x {
        k - 1
    } else {
        k
    }
}

/// The cell of a scan voxel centre `c` rotated by `rot` and moved by `t0`: the one formula
/// every search uses, so that they score a pose bit for bit alike.
#[inline]
pub(crate) fn key_of(
    rot: &nalgebra::Rotation3<f64>,
    c: &Point3<f64>,
    t0: Vector3<f64>,
    cell: f64,
) -> [i64; 3] {
    let p = rot * c.coords + t0;
    [
        cell_index(p.x, cell),
        cell_index(p.y, cell),
        cell_index(p.z, cell),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The truncating floor equals `f64::floor` then the clamp, on integers, halves,
    /// values a rounding step either side of integers, both signs, far values, infinities
    /// and NaN.
    #[test]
    fn cell_index_is_the_clamped_floor() {
        let mut values = vec![0.0, -0.0, f64::INFINITY, f64::NEG_INFINITY, f64::NAN];
        for k in [
            -1e13, -3e9, -70.0, -2.0, -1.0, 0.0, 1.0, 5.0, 123456.0, 2e12, 1.1e12,
        ] {
            for v in [
                k,
                k + 0.5,
                k - 0.5,
                k * (1.0 + f64::EPSILON),
                k * (1.0 - f64::EPSILON),
            ] {
                values.extend([
                    v,
                    f64::from_bits(v.to_bits() + 1),
                    f64::from_bits(v.to_bits().saturating_sub(1)),
                ]);
            }
        }
        for v in values {
            for cell in [1.0, 0.1, 0.05, 12.8] {
                let want = (v / cell).floor().clamp(-KEY_CLAMP, KEY_CLAMP) as i64;
                assert_eq!(cell_index(v, cell), want, "{v} / {cell}");
            }
        }
    }
}
