//! The bound grids of the exact search: per level, the occupied-if-any and free-if-all
//! windows over the finest map (see the module documentation of `bnb`), built from
//! aligned downsamples within the memory budget.

use nalgebra::Point3;

use super::grid::{BitGrid, PairGrid};
use super::node::half_steps;
use super::{GRID_BUDGET_BYTES, ROTATION_LAG, STRIDE_SLACK};
use crate::align::lattice::Lattice;
use crate::align::score::DenseGrid;
use crate::error::{Error, Result};
use crate::occupancy::OccupancyList;

/// One level's bound: the window grids and how scan voxels map onto them.
pub(super) struct Level {
    /// Rotation level `r` of the nodes.
    pub(super) rot_level: u32,
    /// Metres added on each side of a voxel's centre for the rotation block.
    pub(super) margin: [f64; 3],
    /// Window grids sample every `2^shift` cells.
    pub(super) shift: [u32; 3],
    /// Occupied-if-any and free-if-all windows, interleaved.
    pub(super) cells: PairGrid,
}

impl Level {
    /// The score bound of a voxel whose window starts in cell `q` (sampled).
    #[inline(always)]
    pub(super) fn value(&self, q: [i64; 3]) -> i64 {
        self.cells.value(q)
    }
}

/// The finest map and its free space as bit grids over one box whose low corner is a
/// multiple of `2^align` on every axis.
fn fine_grids(
    occ: &OccupancyList,
    free: Option<&DenseGrid>,
    align: u32,
) -> Option<(BitGrid, Option<BitGrid>)> {
    let (mut lo, mut hi) = DenseGrid::key_box(occ).or_else(|| free.map(DenseGrid::bounds))?;
    if let Some(f) = free {
        let (a, b) = f.bounds();
        for i in 0..3 {
            lo[i] = lo[i].min(a[i]);
            hi[i] = hi[i].max(b[i]);
        }
    }
    let lo = lo.map(|v| (v >> align) << align);
    let dims = [0, 1, 2].map(|i| (hi[i] - lo[i] + 1) as usize);
    let mut g = BitGrid::zeros(lo, dims, GRID_BUDGET_BYTES)?;
    for (k, _) in occ.iter() {
        g.set([k.x as i64, k.y as i64, k.z as i64]);
    }
    let f = match free {
        None => None,
        Some(f) => {
            let mut fg = BitGrid::zeros(lo, dims, GRID_BUDGET_BYTES - g.bytes())?;
            let (a, b) = f.bounds();
            let fd = [0, 1, 2].map(|i| (b[i] - a[i] + 1) as usize);
            let off = [0, 1, 2].map(|i| (a[i] - lo[i]) as usize);
            for x in 0..fd[0] {
                for y in 0..fd[1] {
                    let start = ((x * fd[1] + y) * fd[2]) as i64 - off[2] as i64;
                    fg.set_column_from(
                        x + off[0],
                        y + off[1],
                        f.words(),
                        start,
                        off[2]..off[2] + fd[2],
                    );
                }
            }
            Some(fg)
        }
    };
    Some((g, f))
}

/// Each level's rotation level, margins, window widths, sampling shifts and taps.
pub(super) struct Shape {
    /// Rotation level of the nodes.
    pub(super) rot_level: u32,
    /// Metres added on each side of a voxel's centre for the rotation block.
    pub(super) margin: [f64; 3],
    /// Window grids sample every `2^shift` cells.
    pub(super) shift: [u32; 3],
    /// Window taps per axis, in samples.
    pub(super) taps: [usize; 3],
}

/// The shape of every level `0..=top` of the bound: the rotation margins of a `scan`
/// (finest voxel centres) on lattice `l` and the window sampling.
pub(super) fn level_shapes(
    l: &Lattice,
    scan: &[Point3<f64>],
    top: u32,
    searched_t: [bool; 3],
    searched_r: [bool; 3],
) -> Vec<Shape> {
    let rho = scan.iter().map(|c| c.coords.norm()).fold(0.0, f64::max);
    let yaw_only = searched_r == [true, false, false];
    let cell = l.finest;
    (0..=top)
        .map(|level| {
            let rot_level = level.saturating_sub(ROTATION_LAG);
            let axes = searched_r.iter().filter(|s| **s).count() as f64;
            let theta = half_steps(rot_level) * l.dtheta(0) * axes;
            let m = if theta > 0.0 { rho * theta + 1e-9 } else { 0.0 };
            let margin = [m, m, if yaw_only { 0.0 } else { m }];
            let mut shift = [0u32; 3];
            let mut taps = [1usize; 3];
            for i in 0..3 {
                let diff = if margin[i] > 0.0 {
                    (2.0 * margin[i] / cell + 1e-6).floor() as usize + 1
                } else {
                    0
                };
                let block = if searched_t[i] { 1usize << level } else { 1 };
                let width = block + diff;
                let wide = usize::BITS - 1 - width.leading_zeros();
                let s = wide.saturating_sub(STRIDE_SLACK);
                shift[i] = if searched_t[i] { s.min(level) } else { 0 };
                let step = 1usize << shift[i];
                taps[i] = (width + step - 2) / step + 1;
            }
            Shape {
                rot_level,
                margin,
                shift,
                taps,
            }
        })
        .collect()
}

/// The bound grids of the levels of `shapes` over the finest map `occupied` and its free
/// space `free_map`, within [`GRID_BUDGET_BYTES`]; an error when they do not fit.
pub(super) fn build_levels(
    shapes: &[Shape],
    occupied: &OccupancyList,
    free_map: Option<&DenseGrid>,
) -> Result<Vec<Level>> {
    let too_big = || Error::TooLarge {
        what: "the exact search's bound grids".into(),
        limit: format!("{GRID_BUDGET_BYTES} bytes; use the multi-resolution search"),
    };
    let align = shapes.iter().flat_map(|s| s.shift).max().unwrap_or(0);
    let (fine_occ, fine_free) = fine_grids(occupied, free_map, align).ok_or_else(too_big)?;
    let mut budget = GRID_BUDGET_BYTES
        .checked_sub(fine_occ.bytes() + fine_free.as_ref().map_or(0, BitGrid::bytes))
        .ok_or_else(too_big)?;
    // Aligned downsamples by shift vector, built by halving one axis at a time.
    let mut aligned: std::collections::BTreeMap<[u32; 3], (BitGrid, Option<BitGrid>)> =
        std::collections::BTreeMap::new();
    aligned.insert([0; 3], (fine_occ, fine_free));
    let mut levels = Vec::with_capacity(shapes.len());
    for shape in shapes {
        let want = shape.shift;
        let mut have = [0u32; 3];
        for axis in 0..3 {
            while have[axis] < want[axis] {
                let mut next = have;
                next[axis] += 1;
                if !aligned.contains_key(&next) {
                    let (o, f) = &aligned[&have];
                    let mut axes = [false; 3];
                    axes[axis] = true;
                    let o2 = o.halve(axes, true, budget).ok_or_else(too_big)?;
                    budget -= o2.bytes();
                    let f2 = match f {
                        Some(f) => {
                            let g = f.halve(axes, false, budget).ok_or_else(too_big)?;
                            budget -= g.bytes();
                            Some(g)
                        }
                        None => None,
                    };
                    aligned.insert(next, (o2, f2));
                }
                have = next;
            }
        }
        let (o, f) = &aligned[&want];
        let occ = o.window(shape.taps, true, budget).ok_or_else(too_big)?;
        budget -= occ.bytes();
        let free = match f {
            Some(f) => {
                let g = f.window(shape.taps, false, budget).ok_or_else(too_big)?;
                budget -= g.bytes();
                Some(g)
            }
            None => None,
        };
        // Interleaving copies both grids (twice the occupied grid's bytes) before they go;
        // without free space the pairs take twice the bytes of the occupied grid alone.
        let pair_bytes = 2 * occ.bytes();
        if pair_bytes > budget {
            return Err(too_big());
        }
        if free.is_none() {
            budget -= occ.bytes();
        }
        let cells = PairGrid::new(occ, free);
        debug_assert_eq!(cells.bytes(), pair_bytes);
        levels.push(Level {
            rot_level: shape.rot_level,
            margin: shape.margin,
            shift: shape.shift,
            cells,
        });
    }
    drop(aligned);
    Ok(levels)
}
