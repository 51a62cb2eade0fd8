//! A dense bit grid over a map level's bounding box: membership in one array read.

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use crate::occupancy::OccupancyList;

/// Items per task of [`DenseGrid::par_set`].
const PAR_SET_CHUNK: usize = 2048;

/// Occupied cells of an occupancy list as bits over its bounding box of keys, for
/// lookups without hashing (the search's inner loop). Built only when the box is small
/// enough ([`DenseGrid::MAX_CELLS`]).
#[derive(Debug, Clone)]
pub(crate) struct DenseGrid {
    min: [i64; 3],
    dims: [u64; 3],
    bits: Vec<u64>,
}

impl DenseGrid {
    /// The largest box, in cells, worth a dense grid (2^31 bits = 256 MiB).
    pub const MAX_CELLS: u64 = 1 << 31;

    /// The voxels of a list with a count above zero, over their key box, or `None` when
    /// there are none or the box holds more than `max_cells` cells.
    pub fn occupied(list: &OccupancyList, max_cells: u64) -> Option<Self> {
        let occupied = || list.iter().filter(|(_, c)| *c > 0);
        let (lo, hi) = Self::box_of(occupied())?;
        let cells = (0..3).try_fold(1u64, |n, i| n.checked_mul((hi[i] - lo[i] + 1) as u64))?;
        if cells > max_cells {
            return None;
        }
        let mut g = Self::empty(lo, hi)?;
        for (k, _) in occupied() {
            g.set(k.x as i64, k.y as i64, k.z as i64);
        }
        Some(g)
    }

    /// The smallest key box `[lo, hi]` holding every voxel of a list (`None` when empty).
    pub fn key_box(list: &OccupancyList) -> Option<([i64; 3], [i64; 3])> {
        Self::box_of(list.iter())
    }

    /// The smallest key box `[lo, hi]` holding every voxel of `voxels` (`None` when empty).
    fn box_of(
        voxels: impl Iterator<Item = (crate::geometry::VoxelKey, u16)>,
    ) -> Option<([i64; 3], [i64; 3])> {
        let mut lo = [i64::MAX; 3];
        let mut hi = [i64::MIN; 3];
        let mut any = false;
        for (k, _) in voxels {
            any = true;
            for (i, v) in [k.x, k.y, k.z].into_iter().enumerate() {
                lo[i] = lo[i].min(v as i64);
                hi[i] = hi[i].max(v as i64);
            }
        }
        any.then_some((lo, hi))
    }

    /// The voxels of a list over the key box `[lo, hi]` (voxels outside it are left out),
    /// or `None` when the box is too large.
    pub fn over(list: &OccupancyList, lo: [i64; 3], hi: [i64; 3]) -> Option<Self> {
        let mut g = Self::empty(lo, hi)?;
        for (k, _) in list.iter() {
            g.set(k.x as i64, k.y as i64, k.z as i64);
        }
        Some(g)
    }

    /// An all-clear grid over the key box `[lo, hi]`, or `None` when it is too large.
    pub fn empty(lo: [i64; 3], hi: [i64; 3]) -> Option<Self> {
        if (0..3).any(|i| hi[i] < lo[i]) {
            return None;
        }
        let dims = [0, 1, 2].map(|i| (hi[i] - lo[i] + 1) as u64);
        let cells = dims[0].checked_mul(dims[1])?.checked_mul(dims[2])?;
        if cells > Self::MAX_CELLS {
            return None;
        }
        Some(DenseGrid {
            min: lo,
            dims,
            bits: vec![0; cells.div_ceil(64) as usize],
        })
    }

    /// The key box `[lo, hi]` covered.
    pub fn bounds(&self) -> ([i64; 3], [i64; 3]) {
        let hi = [0, 1, 2].map(|i| self.min[i] + self.dims[i] as i64 - 1);
        (self.min, hi)
    }

    /// A grid covering both this box and `[lo, hi]`, with the same cells set, or `None` when
    /// the union is too large.
    pub fn grown(&self, lo: [i64; 3], hi: [i64; 3]) -> Option<Self> {
        let (a, b) = self.bounds();
        let (nlo, nhi) = (
            [0, 1, 2].map(|i| a[i].min(lo[i])),
            [0, 1, 2].map(|i| b[i].max(hi[i])),
        );
        if nlo == a && nhi == b {
            return Some(self.clone());
        }
        self.window(nlo, nhi)
    }

    /// A grid over the key box `[lo, hi]` with this grid's cells inside it set (cells of
    /// `[lo, hi]` outside this grid's box are clear), or `None` when `[lo, hi]` is empty or
    /// too large. Copies a run of bits per `(x, y)` column, a word at a time.
    pub fn window(&self, lo: [i64; 3], hi: [i64; 3]) -> Option<Self> {
        let mut g = Self::empty(lo, hi)?;
        let (a, b) = self.bounds();
        let from = [0, 1, 2].map(|i| a[i].max(lo[i]));
        let to = [0, 1, 2].map(|i| b[i].min(hi[i]));
        if (0..3).any(|i| to[i] < from[i]) {
            return Some(g);
        }
        let run = (to[2] - from[2] + 1) as u64;
        for x in from[0]..=to[0] {
            for y in from[1]..=to[1] {
                // Both corners lie in both boxes.
                let (Some(src), Some(dst)) = (self.index(x, y, from[2]), g.index(x, y, from[2]))
                else {
                    unreachable!("the column's first cell lies in both boxes")
                };
                copy_bits(&self.bits, src, &mut g.bits, dst, run);
            }
        }
        Some(g)
    }

    /// The bits: cell `(x, y, z)` of the box is bit `((x - lo.x) * dy + (y - lo.y)) * dz +
    /// (z - lo.z)` (dims `[dx, dy, dz]` from [`DenseGrid::bounds`]), little endian.
    pub fn words(&self) -> &[u64] {
        &self.bits
    }

    /// The bits, laid out as [`DenseGrid::words`] describes.
    pub fn into_words(self) -> Vec<u64> {
        self.bits
    }

    /// Marks a cell (ignored outside the box).
    #[inline]
    pub fn set(&mut self, x: i64, y: i64, z: i64) {
        if let Some(i) = self.index(x, y, z) {
            self.bits[(i / 64) as usize] |= 1 << (i % 64);
        }
    }

    /// Marks cells `(x, y, z0..=z1)` (the part inside the box), a word at a time.
    pub fn set_column(&mut self, x: i64, y: i64, z0: i64, z1: i64) {
        self.column(x, y, z0, z1, |w, mask| *w |= mask);
    }

    /// Clears cells `(x, y, z0..=z1)` (the part inside the box), a word at a time.
    pub fn clear_column(&mut self, x: i64, y: i64, z0: i64, z1: i64) {
        self.column(x, y, z0, z1, |w, mask| *w &= !mask);
    }

    /// Applies `op(word, mask)` to the words holding cells `(x, y, z0..=z1)` clipped to the
    /// box, `mask` marking the column's bits in each.
    fn column(&mut self, x: i64, y: i64, z0: i64, z1: i64, op: impl Fn(&mut u64, u64)) {
        let last = self.min[2] + self.dims[2] as i64 - 1;
        let (z0, z1) = (z0.max(self.min[2]), z1.min(last));
        let (Some(first), true) = (self.index(x, y, z0), z0 <= z1) else {
            return;
        };
        let end = first + (z1 - z0) as u64 + 1;
        let mut at = first;
        while at < end {
            let (w, s) = ((at / 64) as usize, at % 64);
            let n = (end - at).min(64 - s);
            let mask = if n == 64 {
                u64::MAX
            } else {
                ((1u64 << n) - 1) << s
            };
            op(&mut self.bits[w], mask);
            at += n;
        }
    }

    /// Clears a cell (ignored outside the box).
    #[inline]
    pub fn clear(&mut self, x: i64, y: i64, z: i64) {
        if let Some(i) = self.index(x, y, z) {
            self.bits[(i / 64) as usize] &= !(1 << (i % 64));
        }
    }

    #[inline]
    fn index(&self, x: i64, y: i64, z: i64) -> Option<u64> {
        let dx = (x - self.min[0]) as u64;
        let dy = (y - self.min[1]) as u64;
        let dz = (z - self.min[2]) as u64;
        // Negative differences wrap to huge values and fail these tests too.
        (dx < self.dims[0] && dy < self.dims[1] && dz < self.dims[2])
            .then(|| (dx * self.dims[1] + dy) * self.dims[2] + dz)
    }

    /// Whether the cell is occupied.
    #[inline]
    pub fn contains(&self, x: i64, y: i64, z: i64) -> bool {
        self.index(x, y, z)
            .is_some_and(|i| self.bits[(i / 64) as usize] >> (i % 64) & 1 == 1)
    }

    /// How many cells of the 3 x 3 x 3 block centred on `(x, y, z)` are occupied (the
    /// centre included; cells outside the box count as clear). Nine reads of three
    /// neighbouring bits, one per `(x, y)` column, instead of 27 lookups.
    #[inline]
    pub fn block_count(&self, x: i64, y: i64, z: i64) -> u32 {
        let dz = (z - self.min[2]) as i128;
        let (z0, z1) = ((dz - 1).max(0), (dz + 1).min(self.dims[2] as i128 - 1));
        if z1 < z0 {
            return 0;
        }
        let n = (z1 - z0 + 1) as u32;
        let z0 = z0 as u64;
        let mut count = 0;
        for cx in x - 1..=x + 1 {
            let ix = (cx - self.min[0]) as u64;
            if ix >= self.dims[0] {
                continue;
            }
            for cy in y - 1..=y + 1 {
                let iy = (cy - self.min[1]) as u64;
                if iy >= self.dims[1] {
                    continue;
                }
                let at = (ix * self.dims[1] + iy) * self.dims[2] + z0;
                count += read_bits(&self.bits, at, n).count_ones();
            }
        }
        count
    }

    /// Sets cells from several threads at once: `visit` runs for every item of `items` in
    /// parallel and marks cells through the [`SharedCells`] it is given.
    pub fn par_set<T: Sync>(&mut self, items: &[T], visit: impl Fn(&[T], &SharedCells) + Sync) {
        let words: Vec<AtomicU64> = std::mem::take(&mut self.bits)
            .into_iter()
            .map(AtomicU64::new)
            .collect();
        let shared = SharedCells { grid: self, words };
        items
            .par_chunks(PAR_SET_CHUNK)
            .for_each(|chunk| visit(chunk, &shared));
        let bits = shared
            .words
            .into_iter()
            .map(AtomicU64::into_inner)
            .collect();
        self.bits = bits;
    }

    /// Bytes held.
    #[allow(dead_code)]
    pub fn memory_bytes(&self) -> usize {
        self.bits.len() * 8
    }
}

/// ORs `len` bits of `src` starting at bit `from` into `dst` starting at bit `to`, 64 at a
/// time (bit `i` of a slice is bit `i % 64` of word `i / 64`).
fn copy_bits(src: &[u64], from: u64, dst: &mut [u64], to: u64, len: u64) {
    let mut done = 0;
    while done < len {
        let n = (len - done).min(64) as u32;
        let v = read_bits(src, from + done, n);
        let at = to + done;
        let (w, s) = ((at / 64) as usize, (at % 64) as u32);
        dst[w] |= v << s;
        if s > 0 && s + n > 64 {
            dst[w + 1] |= v >> (64 - s);
        }
        done += n as u64;
    }
}

/// `n` (1 to 64) bits of `words` from bit `at`, in the low bits of the result.
fn read_bits(words: &[u64], at: u64, n: u32) -> u64 {
    let (w, s) = ((at / 64) as usize, (at % 64) as u32);
    let mut v = words[w] >> s;
    if s > 0 && s + n > 64 {
        v |= words[w + 1] << (64 - s);
    }
    if n < 64 {
        v &= (1u64 << n) - 1;
    }
    v
}

/// A [`DenseGrid`] that many threads mark at once ([`DenseGrid::par_set`]).
pub(crate) struct SharedCells<'a> {
    grid: &'a DenseGrid,
    words: Vec<AtomicU64>,
}

impl SharedCells<'_> {
    /// Marks a cell (ignored outside the box). A cell already marked costs a plain read:
    /// rays share the cells near their origin, and an atomic write there would make the
    /// threads fight over those cache lines.
    #[inline]
    pub fn set(&self, x: i64, y: i64, z: i64) {
        if let Some(i) = self.grid.index(x, y, z) {
            let word = &self.words[(i / 64) as usize];
            let bit = 1 << (i % 64);
            if word.load(Ordering::Relaxed) & bit == 0 {
                word.fetch_or(bit, Ordering::Relaxed);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::align::score::cells::tests::lcg;

    /// A window copies exactly the cells inside both boxes, whatever the bit offsets of
    /// the columns (boxes shifted, shrunk, grown and disjoint; columns shorter and longer
    /// than a word).
    #[test]
    fn windows_hold_exactly_the_cells_inside_both_boxes() {
        let mut s = 5u64;
        for (lo, hi) in [([-3, 2, -70], [9, 7, 61]), ([0, 0, 0], [4, 3, 9])] {
            let mut g = DenseGrid::empty(lo, hi).unwrap();
            let span = [0, 1, 2].map(|i| hi[i] - lo[i] + 1);
            for _ in 0..2000 {
                let k = [0, 1, 2].map(|i| lo[i] + lcg(&mut s) % span[i]);
                g.set(k[0], k[1], k[2]);
            }
            let windows = [
                (lo, hi),
                (
                    [lo[0] + 1, lo[1] - 2, lo[2] + 5],
                    [hi[0] - 2, hi[1] + 1, hi[2] + 40],
                ),
                ([lo[0] - 4, lo[1], lo[2] - 63], [hi[0], hi[1], lo[2] + 1]),
                ([hi[0] + 1, lo[1], lo[2]], [hi[0] + 3, hi[1], hi[2]]),
            ];
            for (wlo, whi) in windows {
                let w = g.window(wlo, whi).unwrap();
                assert_eq!(w.bounds(), (wlo, whi));
                for x in wlo[0] - 1..=whi[0] + 1 {
                    for y in wlo[1] - 1..=whi[1] + 1 {
                        for z in wlo[2] - 1..=whi[2] + 1 {
                            let inside =
                                (0..3).all(|i| [x, y, z][i] >= wlo[i] && [x, y, z][i] <= whi[i]);
                            assert_eq!(
                                w.contains(x, y, z),
                                inside && g.contains(x, y, z),
                                "cell {x} {y} {z} of window {wlo:?}..{whi:?}"
                            );
                        }
                    }
                }
            }
        }
    }

    /// Setting and clearing a column marks exactly the cells one by one would, whatever
    /// the column's bit offset and length (within a word, across words, longer than a
    /// word) and wherever it leaves the box.
    #[test]
    fn columns_set_and_clear_exactly_their_cells_inside_the_box() {
        let mut s = 11u64;
        let (lo, hi) = ([-2, 1, -70], [3, 4, 61]);
        let mut by_column = DenseGrid::empty(lo, hi).unwrap();
        let mut by_cell = DenseGrid::empty(lo, hi).unwrap();
        for round in 0..3000 {
            let x = lo[0] - 1 + lcg(&mut s) % 8;
            let y = lo[1] - 1 + lcg(&mut s) % 6;
            let z0 = lo[2] - 5 + lcg(&mut s) % 140;
            let z1 = z0 + lcg(&mut s) % (if round % 3 == 0 { 150 } else { 9 }) - 1;
            let set = lcg(&mut s) % 3 != 0;
            if set {
                by_column.set_column(x, y, z0, z1);
            } else {
                by_column.clear_column(x, y, z0, z1);
            }
            for z in z0..=z1 {
                if set {
                    by_cell.set(x, y, z);
                } else {
                    by_cell.clear(x, y, z);
                }
            }
        }
        assert!(by_cell.words().iter().any(|w| *w != 0));
        assert_eq!(by_column.words(), by_cell.words());
    }
}
