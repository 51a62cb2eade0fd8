//! Bit grids for the bounds of the exact search: cells of a key box as bits, each (x, y)
//! column's z cells packed in whole `u64` words, with the two operations the bounds need:
//! halving (2-cell blocks merged: any set, or all set) and windowing (each cell replaced by
//! the merge of the `taps` cells starting at it, on every axis).
//!
//! "Any" merges build occupancy bounds (a cell is set if any cell of its block or window
//! is occupied); "all" merges build free-space bounds (set only if every cell is free).
//! Cells outside a grid are clear, so an "all" merge touching the outside is clear: a
//! cell nobody saw is never assumed free.

/// Set bits over the key box `[lo, lo + dims)`.
#[derive(Debug, Clone)]
pub(super) struct BitGrid {
    pub(super) lo: [i64; 3],
    pub(super) dims: [usize; 3],
    /// `u64` words per (x, y) column.
    words: usize,
    bits: Vec<u64>,
}

/// The even bits of `w` (0, 2, ..., 62) packed into the low 32 bits.
#[inline]
fn compact_even(w: u64) -> u64 {
    let mut x = w & 0x5555_5555_5555_5555;
    x = (x | (x >> 1)) & 0x3333_3333_3333_3333;
    x = (x | (x >> 2)) & 0x0F0F_0F0F_0F0F_0F0F;
    x = (x | (x >> 4)) & 0x00FF_00FF_00FF_00FF;
    x = (x | (x >> 8)) & 0x0000_FFFF_0000_FFFF;
    (x | (x >> 16)) & 0x0000_0000_FFFF_FFFF
}

/// The word and bit of cell `k` in a grid over `[lo, lo + dims)` with `words` words per
/// (x, y) column; `None` outside the box.
#[inline(always)]
fn locate(lo: [i64; 3], dims: [usize; 3], words: usize, k: [i64; 3]) -> Option<(usize, u64)> {
    let dx = (k[0] - lo[0]) as u64;
    let dy = (k[1] - lo[1]) as u64;
    let dz = (k[2] - lo[2]) as u64;
    // Negative differences wrap to huge values and fail these tests too.
    (dx < dims[0] as u64 && dy < dims[1] as u64 && dz < dims[2] as u64).then(|| {
        let w = (dx as usize * dims[1] + dy as usize) * words + (dz >> 6) as usize;
        (w, dz & 63)
    })
}

/// Bits `[from, from + 64)` of a little-endian multiword column (bits past its end clear).
#[inline]
fn word_at(col: &[u64], from: i64) -> u64 {
    let get = |i: i64| -> u64 {
        if i >= 0 && (i as usize) < col.len() {
            col[i as usize]
        } else {
            0
        }
    };
    let (w, b) = (from.div_euclid(64), from.rem_euclid(64) as u32);
    if b == 0 {
        get(w)
    } else {
        (get(w) >> b) | (get(w + 1) << (64 - b))
    }
}

impl BitGrid {
    /// An all-clear grid, or `None` when it would hold more than `max_bytes`.
    pub(super) fn zeros(lo: [i64; 3], dims: [usize; 3], max_bytes: usize) -> Option<Self> {
        let words = dims[2].div_ceil(64);
        let len = dims[0].checked_mul(dims[1])?.checked_mul(words)?;
        if len.checked_mul(8)? > max_bytes {
            return None;
        }
        Some(BitGrid {
            lo,
            dims,
            words,
            bits: vec![0; len],
        })
    }

    /// Bytes held.
    pub(super) fn bytes(&self) -> usize {
        self.bits.len() * 8
    }

    #[inline]
    fn column(&self, x: usize, y: usize) -> &[u64] {
        let c = (x * self.dims[1] + y) * self.words;
        &self.bits[c..c + self.words]
    }

    #[inline]
    fn column_mut(&mut self, x: usize, y: usize) -> &mut [u64] {
        let c = (x * self.dims[1] + y) * self.words;
        &mut self.bits[c..c + self.words]
    }

    /// Whether cell `k` is set (clear outside the box).
    #[cfg(test)]
    pub(super) fn get(&self, k: [i64; 3]) -> bool {
        locate(self.lo, self.dims, self.words, k).is_some_and(|(w, b)| self.bits[w] >> b & 1 == 1)
    }

    /// Sets cell `k` (ignored outside the box).
    #[inline]
    pub(super) fn set(&mut self, k: [i64; 3]) {
        if let Some((w, b)) = locate(self.lo, self.dims, self.words, k) {
            self.bits[w] |= 1 << b;
        }
    }

    /// Sets the cells `valid` (z indices in the box) of column `(x, y)` (box indices) from
    /// a little-endian bit array: cell `z` takes bit `start + z`.
    pub(super) fn set_column_from(
        &mut self,
        x: usize,
        y: usize,
        src: &[u64],
        start: i64,
        valid: std::ops::Range<usize>,
    ) {
        let col = self.column_mut(x, y);
        for (j, w) in col.iter_mut().enumerate() {
            let (a, b) = (64 * j, 64 * j + 64);
            let (from, to) = (valid.start.max(a), valid.end.min(b));
            if from >= to {
                continue;
            }
            let v = word_at(src, start + a as i64);
            let width = (to - from) as u32;
            let mask = if width == 64 {
                u64::MAX
            } else {
                ((1u64 << width) - 1) << (from - a)
            };
            *w |= v & mask;
        }
    }

    /// Blocks of 2 cells merged on the `axes` set: cell `c` of the result covers cells
    /// `2c` and `2c + 1`. The box's low corner must be even on those axes.
    pub(super) fn halve(&self, axes: [bool; 3], any: bool, max_bytes: usize) -> Option<Self> {
        debug_assert!(
            (0..3).all(|i| !axes[i] || self.lo[i] % 2 == 0),
            "lo must be even to halve"
        );
        let lo = [0, 1, 2].map(|i| if axes[i] { self.lo[i] / 2 } else { self.lo[i] });
        let dims = [0, 1, 2].map(|i| {
            if axes[i] {
                self.dims[i].div_ceil(2)
            } else {
                self.dims[i]
            }
        });
        let mut out = BitGrid::zeros(lo, dims, max_bytes)?;
        let merge = |a: u64, b: u64| if any { a | b } else { a & b };
        let empty = vec![0u64; self.words];
        for x in 0..dims[0] {
            for y in 0..dims[1] {
                let src = |dx: usize, dy: usize| -> &[u64] {
                    let (sx, sy) = (
                        if axes[0] { 2 * x + dx } else { x },
                        if axes[1] { 2 * y + dy } else { y },
                    );
                    if sx < self.dims[0] && sy < self.dims[1] {
                        self.column(sx, sy)
                    } else {
                        &empty
                    }
                };
                // Unmerged axes read the same column twice: merging is idempotent.
                let (hx, hy) = (axes[0] as usize, axes[1] as usize);
                let cols = [src(0, 0), src(0, hy), src(hx, 0), src(hx, hy)];
                let outc = out.column_mut(x, y);
                let read = |j: usize| -> u64 {
                    let at = |c: &[u64]| c.get(j).copied().unwrap_or(0);
                    merge(
                        merge(at(cols[0]), at(cols[1])),
                        merge(at(cols[2]), at(cols[3])),
                    )
                };
                if axes[2] {
                    for (j, w) in outc.iter_mut().enumerate() {
                        let (a, b) = (read(2 * j), read(2 * j + 1));
                        let (a, b) = (merge(a, a >> 1), merge(b, b >> 1));
                        *w = compact_even(a) | compact_even(b) << 32;
                    }
                } else {
                    for (j, w) in outc.iter_mut().enumerate() {
                        *w = read(j);
                    }
                }
            }
        }
        out.clear_tail();
        Some(out)
    }

    /// Windows of `taps` cells merged: cell `c` of the result covers cells
    /// `[c, c + taps)` (per axis) of this grid. The result's box starts `taps - 1` cells
    /// lower, so that every window touching this box has its cell. `None` when the result
    /// and the z pass together would hold more than `max_bytes`.
    pub(super) fn window(&self, taps: [usize; 3], any: bool, max_bytes: usize) -> Option<Self> {
        let grow = taps.map(|t| t.max(1) - 1);
        let lo = [0, 1, 2].map(|i| self.lo[i] - grow[i] as i64);
        let dims = [0, 1, 2].map(|i| self.dims[i] + grow[i]);
        // z first, into the final column height.
        let mut zpass = BitGrid::zeros(
            [lo[0] + grow[0] as i64, lo[1] + grow[1] as i64, lo[2]],
            [self.dims[0], self.dims[1], dims[2]],
            max_bytes,
        )?;
        for x in 0..self.dims[0] {
            for y in 0..self.dims[1] {
                let src = self.column(x, y);
                let words = zpass.words;
                let dst = zpass.column_mut(x, y);
                for (j, w) in dst.iter_mut().enumerate().take(words) {
                    // Result bit z covers source bits z - grow .. z - grow + taps - 1, i.e.
                    // the source shifted up by u = 0 .. grow.
                    let mut v = if any { 0 } else { u64::MAX };
                    for u in 0..=grow[2] as i64 {
                        let s = word_at(src, 64 * j as i64 - u);
                        v = if any { v | s } else { v & s };
                    }
                    *w = v;
                }
            }
        }
        zpass.clear_tail();
        // Then x and y: result column c merges source columns c - grow .. c. Both passes
        // are held at once, and the result is at least as large as the z pass.
        let mut out = BitGrid::zeros(lo, dims, max_bytes.checked_sub(zpass.bytes())?)?;
        let words = out.words;
        let mut acc = vec![0u64; words];
        for x in 0..dims[0] {
            for y in 0..dims[1] {
                acc.fill(if any { 0 } else { u64::MAX });
                'taps: for ux in 0..=grow[0] {
                    for uy in 0..=grow[1] {
                        let (sx, sy) = (x as i64 - ux as i64, y as i64 - uy as i64);
                        if sx < 0
                            || sy < 0
                            || sx as usize >= self.dims[0]
                            || sy as usize >= self.dims[1]
                        {
                            if any {
                                continue;
                            }
                            acc.fill(0);
                            break 'taps;
                        }
                        let col = zpass.column(sx as usize, sy as usize);
                        for (a, c) in acc.iter_mut().zip(col) {
                            *a = if any { *a | c } else { *a & c };
                        }
                    }
                }
                out.column_mut(x, y).copy_from_slice(&acc);
            }
        }
        out.clear_tail();
        Some(out)
    }

    /// Clears the bits past `dims[2]` in every column's last word.
    fn clear_tail(&mut self) {
        let used = self.dims[2] % 64;
        if used == 0 || self.words == 0 {
            return;
        }
        let mask = (1u64 << used) - 1;
        let words = self.words;
        for c in self.bits.chunks_mut(words) {
            c[words - 1] &= mask;
        }
    }
}

/// An occupancy grid and a free-space grid over the same box, their words interleaved so
/// that one lookup reads both from the same cache line.
#[derive(Debug, Clone)]
pub(super) struct PairGrid {
    lo: [i64; 3],
    dims: [usize; 3],
    words: usize,
    /// `[occupied, free]` word pairs.
    pairs: Vec<[u64; 2]>,
}

impl PairGrid {
    /// Interleaves `occ` and `free` (clear everywhere when `None`). The two grids must
    /// share their box.
    pub(super) fn new(occ: BitGrid, free: Option<BitGrid>) -> Self {
        let pairs = match &free {
            Some(f) => {
                assert!(
                    f.lo == occ.lo && f.dims == occ.dims,
                    "grids over different boxes"
                );
                occ.bits
                    .iter()
                    .zip(&f.bits)
                    .map(|(&o, &f)| [o, f])
                    .collect()
            }
            None => occ.bits.iter().map(|&o| [o, 0]).collect(),
        };
        PairGrid {
            lo: occ.lo,
            dims: occ.dims,
            words: occ.words,
            pairs,
        }
    }

    /// Bytes held.
    pub(super) fn bytes(&self) -> usize {
        self.pairs.len() * 16
    }

    /// The bound of a voxel in cell `k`: 2 if the cell is occupied, -1 if free, else 0
    /// (0 outside the box).
    #[inline(always)]
    pub(super) fn value(&self, k: [i64; 3]) -> i64 {
        match locate(self.lo, self.dims, self.words, k) {
            Some((w, b)) => {
                let [o, f] = self.pairs[w];
                if o >> b & 1 == 1 {
                    2
                } else {
                    -((f >> b & 1) as i64)
                }
            }
            None => 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(cells: &[[i64; 3]], k: [i64; 3]) -> bool {
        cells.contains(&k)
    }

    fn grid_of(cells: &[[i64; 3]], lo: [i64; 3], dims: [usize; 3]) -> BitGrid {
        let mut g = BitGrid::zeros(lo, dims, 1 << 30).unwrap();
        for c in cells {
            g.set(*c);
        }
        g
    }

    /// Cells of a small irregular set, including a fully set 4x4x4 block (for "all").
    fn cells() -> Vec<[i64; 3]> {
        let mut v = Vec::new();
        for x in -4..0 {
            for y in 2..6 {
                for z in 60..64 {
                    v.push([x, y, z]);
                }
            }
        }
        let mut s = 7u64;
        for _ in 0..300 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let r = |b: u32| ((s >> b) % 11) as i64;
            v.push([r(5) - 6, r(17) - 1, r(29) * 13 - 10]);
        }
        v
    }

    #[test]
    fn halving_and_windows_match_their_definitions() {
        let cells = cells();
        let (lo, dims) = ([-6i64, -2, -10], [12usize, 14, 150]);
        let g = grid_of(&cells, lo, dims);
        let inside = |k: [i64; 3]| (0..3).all(|i| k[i] >= lo[i] && k[i] < lo[i] + dims[i] as i64);
        for any in [true, false] {
            for axes in [[true, true, true], [true, true, false], [false, true, true]] {
                let h = g.halve(axes, any, 1 << 30).unwrap();
                for x in h.lo[0] - 1..h.lo[0] + h.dims[0] as i64 + 1 {
                    for y in h.lo[1] - 1..h.lo[1] + h.dims[1] as i64 + 1 {
                        for z in h.lo[2] - 1..h.lo[2] + h.dims[2] as i64 + 1 {
                            let span =
                                |i: usize, c: i64| if axes[i] { 2 * c..=2 * c + 1 } else { c..=c };
                            let mut members = Vec::new();
                            for a in span(0, x) {
                                for b in span(1, y) {
                                    for c in span(2, z) {
                                        members.push([a, b, c]);
                                    }
                                }
                            }
                            let want = if any {
                                members.iter().any(|m| naive(&cells, *m))
                            } else {
                                members.iter().all(|m| inside(*m) && naive(&cells, *m))
                            };
                            assert_eq!(
                                h.get([x, y, z]),
                                want,
                                "halve {axes:?} any {any} at {x} {y} {z}"
                            );
                        }
                    }
                }
            }
            for taps in [[1usize, 1, 1], [3, 2, 1], [2, 2, 5], [1, 4, 70]] {
                let w = g.window(taps, any, 1 << 30).unwrap();
                assert_eq!(w.lo, [0, 1, 2].map(|i| lo[i] - taps[i] as i64 + 1));
                for x in w.lo[0] - 1..w.lo[0] + w.dims[0] as i64 + 1 {
                    for y in w.lo[1] - 1..w.lo[1] + w.dims[1] as i64 + 1 {
                        for z in w.lo[2] - 1..w.lo[2] + w.dims[2] as i64 + 1 {
                            let mut members = Vec::new();
                            for a in 0..taps[0] as i64 {
                                for b in 0..taps[1] as i64 {
                                    for c in 0..taps[2] as i64 {
                                        members.push([x + a, y + b, z + c]);
                                    }
                                }
                            }
                            let want = if any {
                                members.iter().any(|m| naive(&cells, *m))
                            } else {
                                members.iter().all(|m| inside(*m) && naive(&cells, *m))
                            };
                            assert_eq!(
                                w.get([x, y, z]),
                                want,
                                "window {taps:?} any {any} at {x} {y} {z}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn pair_values_read_both_grids() {
        let occ = cells();
        // Free: a shifted copy, overlapping the occupied cells in places (occupied wins).
        let free: Vec<[i64; 3]> = occ.iter().map(|c| [c[0] + 1, c[1], c[2] - 3]).collect();
        let (lo, dims) = ([-6i64, -2, -10], [12usize, 14, 150]);
        let with_free = PairGrid::new(grid_of(&occ, lo, dims), Some(grid_of(&free, lo, dims)));
        let without = PairGrid::new(grid_of(&occ, lo, dims), None);
        let inside = |k: [i64; 3]| (0..3).all(|i| k[i] >= lo[i] && k[i] < lo[i] + dims[i] as i64);
        for x in lo[0] - 1..lo[0] + dims[0] as i64 + 1 {
            for y in lo[1] - 1..lo[1] + dims[1] as i64 + 1 {
                for z in lo[2] - 1..lo[2] + dims[2] as i64 + 1 {
                    let k = [x, y, z];
                    let o = inside(k) && naive(&occ, k);
                    let f = inside(k) && naive(&free, k);
                    let want = if o { 2 } else { -(f as i64) };
                    assert_eq!(with_free.value(k), want, "at {k:?}");
                    assert_eq!(without.value(k), if o { 2 } else { 0 }, "at {k:?}");
                }
            }
        }
    }

    #[test]
    fn columns_copy_from_any_bit_offset() {
        let src: Vec<u64> = (0..5u64)
            .map(|i| i.wrapping_mul(0x9E37_79B9_7F4A_7C15))
            .collect();
        let mut g = BitGrid::zeros([0, 0, 0], [1, 1, 130], 1 << 20).unwrap();
        g.set_column_from(0, 0, &src, 37 - 5, 5..120);
        for z in 0..130u64 {
            let b = 37 - 5 + z;
            let want = (5..120).contains(&z) && src[(b / 64) as usize] >> (b % 64) & 1 == 1;
            assert_eq!(g.get([0, 0, z as i64]), want, "bit {z}");
        }
        assert!(!g.get([0, 0, 130]));
    }
}
