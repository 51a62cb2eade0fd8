//! The cells a search level looks up, laid out for the scoring loop.
//!
//! Occupancy and free space share one key box and one array: with free space known each
//! cell has two bits in the same word (bit 0 occupied, bit 1 free), so a scan voxel costs
//! one memory read whether it hits or not; without it, one bit per cell. Poses that share a
//! rotation are scored together, a chunk of translations per pass over the scan: each
//! voxel's cell index is computed once and the chunk's translations are integer offsets of
//! it, which keeps the reads of one voxel within a few cache lines.

use super::dense::DenseGrid;
use crate::occupancy::OccupancyList;

/// How many translations one pass over the scan scores.
const CHUNK: usize = 16;

/// Occupied (and free) cells of one search level over a dense key box.
#[derive(Debug, Clone)]
pub(crate) struct CellGrid {
    min: [i64; 3],
    dims: [i64; 3],
    /// Index steps per axis: `[dy * dz, dz, 1]`.
    stride: [i64; 3],
    /// Two bits per cell (free space known) or one.
    two_bits: bool,
    words: Vec<u64>,
}

/// Spreads the 32 bits of `v` to the even bits of a `u64`.
#[inline]
fn spread(v: u32) -> u64 {
    let mut x = v as u64;
    x = (x | x << 16) & 0x0000_ffff_0000_ffff;
    x = (x | x << 8) & 0x00ff_00ff_00ff_00ff;
    x = (x | x << 4) & 0x0f0f_0f0f_0f0f_0f0f;
    x = (x | x << 2) & 0x3333_3333_3333_3333;
    (x | x << 1) & 0x5555_5555_5555_5555
}

impl CellGrid {
    /// The cells of a level and its free space over [`CellGrid::whole_box`], or `None` when
    /// the level is empty or the box is too large for a dense array
    /// ([`DenseGrid::MAX_CELLS`]).
    pub fn new(level: &OccupancyList, free: Option<&DenseGrid>) -> Option<Self> {
        let (lo, hi) = Self::whole_box(level, free)?;
        Self::over(level, free, lo, hi)
    }

    /// The key box of a level's voxels and its free space together (`None` when the level
    /// is empty): where every lookup that can hit or conflict lands.
    pub fn whole_box(
        level: &OccupancyList,
        free: Option<&DenseGrid>,
    ) -> Option<([i64; 3], [i64; 3])> {
        let (mut lo, mut hi) = DenseGrid::key_box(level)?;
        if let Some(free) = free {
            let (flo, fhi) = free.bounds();
            for i in 0..3 {
                lo[i] = lo[i].min(flo[i]);
                hi[i] = hi[i].max(fhi[i]);
            }
        }
        Some((lo, hi))
    }

    /// The cells of a level and its free space inside the key box `[lo, hi]` (cells
    /// outside it score as empty), or `None` when the box is empty or too large. Scores of
    /// keys that all lie in `[lo, hi]` or outside [`CellGrid::whole_box`] equal those of
    /// [`CellGrid::new`].
    pub fn over(
        level: &OccupancyList,
        free: Option<&DenseGrid>,
        lo: [i64; 3],
        hi: [i64; 3],
    ) -> Option<Self> {
        let occupied = DenseGrid::over(level, lo, hi)?;
        let Some(free) = free else {
            return Some(Self::one_bit(occupied));
        };
        let windowed;
        let free = if free.bounds() == (lo, hi) {
            free
        } else {
            windowed = free.window(lo, hi)?;
            &windowed
        };
        let (o, f) = (occupied.words(), free.words());
        let mut words = Vec::with_capacity(2 * o.len());
        for (&o, &f) in o.iter().zip(f) {
            // A cell is never both: occupied wins, as in the scoring rule.
            let f = f & !o;
            words.push(spread(o as u32) | spread(f as u32) << 1);
            words.push(spread((o >> 32) as u32) | spread((f >> 32) as u32) << 1);
        }
        let mut g = Self::one_bit(occupied);
        g.words = words;
        g.two_bits = true;
        Some(g)
    }

    /// Whether the key box `[lo, hi]` lies inside this grid's box.
    pub fn covers(&self, lo: [i64; 3], hi: [i64; 3]) -> bool {
        (0..3).all(|i| lo[i] >= self.min[i] && hi[i] < self.min[i] + self.dims[i])
    }

    fn one_bit(grid: DenseGrid) -> Self {
        let (lo, hi) = grid.bounds();
        let dims = [0, 1, 2].map(|i| hi[i] - lo[i] + 1);
        CellGrid {
            min: lo,
            dims,
            stride: [dims[1] * dims[2], dims[2], 1],
            two_bits: false,
            words: grid.into_words(),
        }
    }

    /// Hits and conflicts of the scan keys `base` moved by each translation of `ts`, in
    /// the order of `ts`: a hit is a moved key on an occupied cell, a conflict one on a
    /// free cell.
    pub fn score(&self, base: &[[i64; 3]], ts: &[[i32; 3]]) -> Vec<(u32, u32)> {
        let mut out = Vec::with_capacity(ts.len());
        for chunk in ts.chunks(CHUNK) {
            let mut hits = [0u32; CHUNK];
            let mut conflicts = [0u32; CHUNK];
            let mut offset = [0i64; CHUNK];
            let moves = self.moves(chunk, &mut offset);
            for &b in base {
                if self.two_bits {
                    self.add_key::<true>(b, &moves, &mut hits, &mut conflicts);
                } else {
                    self.add_key::<false>(b, &moves, &mut hits, &mut conflicts);
                }
            }
            out.extend(hits.into_iter().zip(conflicts).take(chunk.len()));
        }
        out
    }

    /// The key box's first corner.
    pub fn min(&self) -> [i64; 3] {
        self.min
    }

    /// Cells per axis.
    pub fn dims(&self) -> [i64; 3] {
        self.dims
    }

    /// Whether free space is known (two bits per cell).
    pub fn has_free_space(&self) -> bool {
        self.two_bits
    }

    /// The state of the cell `rel` cells from [`CellGrid::min`] (inside the box): bit 0
    /// occupied, bit 1 free.
    pub fn state_at(&self, rel: [i64; 3]) -> u32 {
        let i = rel[0] * self.stride[0] + rel[1] * self.stride[1] + rel[2];
        if self.two_bits {
            self.state::<true>(i)
        } else {
            self.state::<false>(i)
        }
    }

    /// The state bits of cell index `i` (inside the box).
    #[inline(always)]
    fn state<const TWO: bool>(&self, i: i64) -> u32 {
        let i = i as u64;
        if TWO {
            (self.words[(i >> 5) as usize] >> ((i & 31) << 1)) as u32 & 3
        } else {
            (self.words[(i >> 6) as usize] >> (i & 63)) as u32 & 1
        }
    }

    /// The translations `ts` as index offsets (written to `offset`, as long as `ts`) and
    /// their bounding box.
    fn moves<'a>(&self, ts: &'a [[i32; 3]], offset: &'a mut [i64]) -> Moves<'a> {
        let mut lo = [i64::MAX; 3];
        let mut hi = [i64::MIN; 3];
        for (o, t) in offset.iter_mut().zip(ts) {
            let t = t.map(i64::from);
            *o = t[0] * self.stride[0] + t[1] * self.stride[1] + t[2];
            for i in 0..3 {
                lo[i] = lo[i].min(t[i]);
                hi[i] = hi[i].max(t[i]);
            }
        }
        Moves {
            ts,
            offset: &offset[..ts.len()],
            lo,
            hi,
        }
    }

    /// Adds the hits and conflicts of the key `b` moved by each of `moves` to `hits[j]` and
    /// `conflicts[j]` (`j` indexing the translations).
    #[inline(always)]
    fn add_key<const TWO: bool>(
        &self,
        b: [i64; 3],
        moves: &Moves,
        hits: &mut [u32],
        conflicts: &mut [u32],
    ) {
        let (lo, hi) = (moves.lo, moves.hi);
        let rel = [0, 1, 2].map(|i| b[i] - self.min[i]);
        let inside = (0..3).all(|i| rel[i] + lo[i] >= 0 && rel[i] + hi[i] < self.dims[i]);
        if inside {
            let at = rel[0] * self.stride[0] + rel[1] * self.stride[1] + rel[2];
            for ((o, h), c) in moves.offset.iter().zip(hits).zip(conflicts) {
                let s = self.state::<TWO>(at + o);
                *h += s & 1;
                if TWO {
                    *c += s >> 1;
                }
            }
            return;
        }
        let outside = (0..3).any(|i| rel[i] + hi[i] < 0 || rel[i] + lo[i] >= self.dims[i]);
        if outside {
            return;
        }
        // Straddling the box's edge: test each translation.
        for ((t, h), c) in moves.ts.iter().zip(hits).zip(conflicts) {
            let k = [0, 1, 2].map(|i| rel[i] + t[i] as i64);
            if (0..3).all(|i| k[i] >= 0 && k[i] < self.dims[i]) {
                let s = self.state::<TWO>(k[0] * self.stride[0] + k[1] * self.stride[1] + k[2]);
                *h += s & 1;
                if TWO {
                    *c += s >> 1;
                }
            }
        }
    }
}

/// Translations prepared for [`CellGrid::add_key`]: each as an index offset, and their
/// bounding box.
struct Moves<'a> {
    ts: &'a [[i32; 3]],
    offset: &'a [i64],
    lo: [i64; 3],
    hi: [i64; 3],
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geometry::VoxelKey;

    /// A pseudo-random sequence (no dependency on the simulator's generator).
    pub(crate) fn lcg(s: &mut u64) -> i64 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*s >> 33) as i64
    }

    #[test]
    fn spread_puts_each_bit_at_twice_its_place() {
        let v = 0b1011_0000_0000_0000_0000_0000_0000_0001u32;
        let s = spread(v);
        for b in 0..32 {
            assert_eq!(s >> (2 * b) & 1, (v >> b) as u64 & 1);
            assert_eq!(s >> (2 * b + 1) & 1, 0);
        }
    }

    /// The chunked, offset-based scores equal a lookup of every moved key, with and
    /// without free space, for translations inside, across and outside the box's edges.
    #[test]
    fn scores_equal_one_lookup_per_moved_key() {
        let mut s = 11u64;
        let mut level = OccupancyList::new(0.1).unwrap();
        for _ in 0..400 {
            let k = [lcg(&mut s) % 20 - 5, lcg(&mut s) % 13, lcg(&mut s) % 9 - 3];
            level
                .set(VoxelKey::new(k[0] as i32, k[1] as i32, k[2] as i32), 1)
                .unwrap();
        }
        // Free space over a box larger than the level's on some axes and smaller on one.
        let mut free = DenseGrid::empty([-8, -2, -1], [16, 15, 4]).unwrap();
        for _ in 0..900 {
            free.set(
                lcg(&mut s) % 25 - 8,
                lcg(&mut s) % 18 - 2,
                lcg(&mut s) % 6 - 1,
            );
        }
        let (lo, hi) = DenseGrid::key_box(&level).unwrap();
        let occupied = DenseGrid::over(&level, lo, hi).unwrap();
        let base: Vec<[i64; 3]> = (0..150)
            .map(|_| {
                [
                    lcg(&mut s) % 30 - 10,
                    lcg(&mut s) % 24 - 6,
                    lcg(&mut s) % 14 - 6,
                ]
            })
            .collect();
        let ts: Vec<[i32; 3]> = (0..70)
            .map(|_| {
                [
                    (lcg(&mut s) % 21 - 10) as i32,
                    (lcg(&mut s) % 21 - 10) as i32,
                    (lcg(&mut s) % 9 - 4) as i32,
                ]
            })
            .collect();
        for with_free in [false, true] {
            let grid = CellGrid::new(&level, with_free.then_some(&free)).unwrap();
            let got = grid.score(&base, &ts);
            for (t, g) in ts.iter().zip(&got) {
                let (mut hits, mut conflicts) = (0, 0);
                for b in &base {
                    let k = [0, 1, 2].map(|i| b[i] + t[i] as i64);
                    if occupied.contains(k[0], k[1], k[2]) {
                        hits += 1;
                    } else if with_free && free.contains(k[0], k[1], k[2]) {
                        conflicts += 1;
                    }
                }
                assert_eq!(*g, (hits, conflicts), "translation {t:?}, free {with_free}");
            }
            assert!(got.iter().any(|g| g.0 > 0), "the test must hit something");
            if with_free {
                assert!(got.iter().any(|g| g.1 > 0), "and conflict somewhere");
            }
        }
    }

    /// A grid over any box holding every moved key scores as the whole grid, with and
    /// without free space: the box the searches build when their candidates reach a small
    /// part of a large target.
    #[test]
    fn a_grid_over_the_reached_box_scores_as_the_whole() {
        let mut s = 3u64;
        let mut level = OccupancyList::new(0.1).unwrap();
        for _ in 0..3000 {
            let k = [
                lcg(&mut s) % 90 - 40,
                lcg(&mut s) % 70 - 20,
                lcg(&mut s) % 20 - 5,
            ];
            level
                .set(VoxelKey::new(k[0] as i32, k[1] as i32, k[2] as i32), 1)
                .unwrap();
        }
        let mut free = DenseGrid::empty([-50, -30, -8], [60, 55, 20]).unwrap();
        for _ in 0..20000 {
            free.set(
                lcg(&mut s) % 111 - 50,
                lcg(&mut s) % 86 - 30,
                lcg(&mut s) % 29 - 8,
            );
        }
        let base: Vec<[i64; 3]> = (0..200)
            .map(|_| [lcg(&mut s) % 12, lcg(&mut s) % 9 - 3, lcg(&mut s) % 6 - 2])
            .collect();
        let ts: Vec<[i32; 3]> = (0..40)
            .map(|_| {
                [
                    (lcg(&mut s) % 5) as i32,
                    (lcg(&mut s) % 7 - 3) as i32,
                    (lcg(&mut s) % 3) as i32,
                ]
            })
            .collect();
        // The reached box: every base key moved by every translation.
        let mut lo = [i64::MAX; 3];
        let mut hi = [i64::MIN; 3];
        for b in &base {
            for t in &ts {
                for i in 0..3 {
                    lo[i] = lo[i].min(b[i] + t[i] as i64);
                    hi[i] = hi[i].max(b[i] + t[i] as i64);
                }
            }
        }
        for with_free in [false, true] {
            let free = with_free.then_some(&free);
            let whole = CellGrid::new(&level, free).unwrap();
            let want = whole.score(&base, &ts);
            assert!(want.iter().any(|g| g.0 > 0), "the test must hit something");
            for (plo, phi) in [
                (lo, hi),
                ([lo[0] - 3, lo[1], lo[2] - 1], [hi[0], hi[1] + 2, hi[2]]),
            ] {
                let part = CellGrid::over(&level, free, plo, phi).unwrap();
                assert!(part.covers(lo, hi) && !whole.covers([-60, 0, 0], [0, 0, 0]));
                assert_eq!(
                    part.score(&base, &ts),
                    want,
                    "box {plo:?}..{phi:?}, free {with_free}"
                );
            }
        }
    }
}
