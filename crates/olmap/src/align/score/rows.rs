//! Scoring a whole box of translations at once: the scan's overlap as a correlation.
//!
//! When the poses of one rotation fill a box of translations (the coarsest level of a
//! global search, the exhaustive search), scoring them one by one reads the same cells
//! again and again. Here each scan voxel instead adds a row of the map to a row of
//! per-translation counters: the map's cells are bytes with the y axis fastest, so for a
//! fixed x and z translation the cells that a voxel meets over every y translation are
//! contiguous, and the additions are plain loops over `u16` that the compiler vectorises.

use super::cells::CellGrid;

/// The most bytes a row grid of one level may take (occupied and free together).
const MAX_BYTES: i64 = 1 << 28;

/// A level's cells as bytes, y fastest: `[(x * dz + z) * dy + y]`.
#[derive(Debug)]
pub(crate) struct RowGrid {
    min: [i64; 3],
    dims: [i64; 3],
    occupied: Vec<u8>,
    /// Empty when the level has no free space.
    free: Vec<u8>,
}

impl RowGrid {
    /// The row grid of a level's cells, or `None` above [`MAX_BYTES`].
    pub fn new(cells: &CellGrid) -> Option<Self> {
        let (min, dims) = (cells.min(), cells.dims());
        let n = dims[0].checked_mul(dims[1])?.checked_mul(dims[2])?;
        let with_free = cells.has_free_space();
        if n.checked_mul(1 + with_free as i64)? > MAX_BYTES {
            return None;
        }
        let mut occupied = vec![0u8; n as usize];
        let mut free = vec![0u8; if with_free { n as usize } else { 0 }];
        let mut i = 0;
        for x in 0..dims[0] {
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    let s = cells.state_at([x, y, z]);
                    occupied[i] = (s & 1) as u8;
                    if with_free {
                        free[i] = (s >> 1) as u8;
                    }
                    i += 1;
                }
            }
        }
        Some(RowGrid {
            min,
            dims,
            occupied,
            free,
        })
    }

    /// Hits and conflicts (as [`CellGrid::score`] counts them) of the scan keys `base`
    /// moved by every translation of the box `[lo, lo + n)`, indexed
    /// `((tx * nz) + tz) * ny + ty`. `None` when `base` has more voxels than a `u16`
    /// counter holds.
    pub fn score_box(&self, base: &[[i64; 3]], lo: [i64; 3], n: [usize; 3]) -> Option<Scores> {
        if base.len() > u16::MAX as usize {
            return None;
        }
        let [nx, ny, nz] = n;
        let mut hits = vec![0u16; nx * ny * nz];
        let mut conflicts = vec![0u16; if self.free.is_empty() { 0 } else { hits.len() }];
        let [dx, dy, dz] = self.dims;
        for b in base {
            // The cell this voxel meets at the box's first translation.
            let rel = [0, 1, 2].map(|i| b[i] + lo[i] - self.min[i]);
            // The y translations that stay inside the grid.
            let ty0 = (-rel[1]).clamp(0, ny as i64) as usize;
            let ty1 = (dy - rel[1]).clamp(0, ny as i64) as usize;
            if ty0 >= ty1 {
                continue;
            }
            for tx in 0..nx {
                let x = rel[0] + tx as i64;
                if x < 0 || x >= dx {
                    continue;
                }
                for tz in 0..nz {
                    let z = rel[2] + tz as i64;
                    if z < 0 || z >= dz {
                        continue;
                    }
                    // The first cell inside the grid (`rel[1] + ty0 >= 0`).
                    let row = ((x * dz + z) * dy + rel[1] + ty0 as i64) as usize;
                    let len = ty1 - ty0;
                    let at = (tx * nz + tz) * ny + ty0;
                    add_row(&mut hits[at..at + len], &self.occupied[row..row + len]);
                    if !self.free.is_empty() {
                        add_row(&mut conflicts[at..at + len], &self.free[row..row + len]);
                    }
                }
            }
        }
        Some(Scores { n, hits, conflicts })
    }
}

/// `acc[i] += row[i]`, written for the vectoriser.
#[inline(always)]
fn add_row(acc: &mut [u16], row: &[u8]) {
    for (a, &r) in acc.iter_mut().zip(row) {
        *a += r as u16;
    }
}

/// The counts of a box of translations.
pub(crate) struct Scores {
    n: [usize; 3],
    hits: Vec<u16>,
    conflicts: Vec<u16>,
}

impl Scores {
    /// Hits and conflicts of translation `t` (box-relative, inside the box).
    #[inline]
    pub fn get(&self, t: [usize; 3]) -> (u32, u32) {
        let i = (t[0] * self.n[2] + t[2]) * self.n[1] + t[1];
        let c = self.conflicts.get(i).copied().unwrap_or(0);
        (self.hits[i] as u32, c as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::align::score::cells::tests::lcg;
    use crate::align::score::DenseGrid;
    use crate::geometry::VoxelKey;
    use crate::occupancy::OccupancyList;

    /// Every translation of boxes inside, across and beyond the grid scores as the
    /// one-pose-at-a-time path does.
    #[test]
    fn box_scores_equal_the_cell_grid_scores() {
        let mut s = 5u64;
        let mut level = OccupancyList::new(0.2).unwrap();
        for _ in 0..300 {
            let k = [lcg(&mut s) % 17 - 4, lcg(&mut s) % 11 - 2, lcg(&mut s) % 7];
            level
                .set(VoxelKey::new(k[0] as i32, k[1] as i32, k[2] as i32), 1)
                .unwrap();
        }
        let mut free = DenseGrid::empty([-6, -3, -2], [14, 10, 8]).unwrap();
        for _ in 0..700 {
            free.set(
                lcg(&mut s) % 21 - 6,
                lcg(&mut s) % 14 - 3,
                lcg(&mut s) % 11 - 2,
            );
        }
        let base: Vec<[i64; 3]> = (0..120)
            .map(|_| {
                [
                    lcg(&mut s) % 26 - 13,
                    lcg(&mut s) % 20 - 10,
                    lcg(&mut s) % 12 - 6,
                ]
            })
            .collect();
        for with_free in [false, true] {
            let cells = CellGrid::new(&level, with_free.then_some(&free)).unwrap();
            let rows = RowGrid::new(&cells).unwrap();
            for (lo, n) in [([-9, -8, -3], [19, 17, 7]), ([2, -1, 0], [3, 30, 1])] {
                let scores = rows.score_box(&base, lo, n).unwrap();
                let mut ts = Vec::new();
                for x in 0..n[0] {
                    for y in 0..n[1] {
                        for z in 0..n[2] {
                            ts.push([x, y, z]);
                        }
                    }
                }
                let moved: Vec<[i32; 3]> = ts
                    .iter()
                    .map(|t| [0, 1, 2].map(|i| (lo[i] + t[i] as i64) as i32))
                    .collect();
                let expected = cells.score(&base, &moved);
                for (t, e) in ts.iter().zip(&expected) {
                    assert_eq!(scores.get(*t), *e, "box {lo:?} + {t:?}, free {with_free}");
                }
                assert!(expected.iter().any(|e| e.0 > 0));
            }
        }
    }
}
