//! The exact global search: per rotation, branch and bound over translations
//! ([`super::SearchMode::Exact`]).
//!
//! The poses are those of the exhaustive search (Algorithm 7): rotation indices `j` (angle
//! `angle0 + j dθ`, `dθ = resolution / R`) and translation indices `i` (`t0 + i resolution`).
//! For one rotation the scan's voxels fall in finest cells `b`; a node of level `l` is a
//! dyadic block of translations `[n 2^l, (n + 1) 2^l)` on every searched translation axis.
//!
//! **Bound.** For every translation of the block, a voxel's cell `b + t` lies in the window
//! `[(c + n) 2^l, (c + n + 2) 2^l)` with `c = floor(b / 2^l)`. Level `l` of the bound grids
//! marks a coarse cell occupied if ANY finest cell of its `2^(l+1)`-window is (a max pool
//! over a sliding window of twice the block, sampled every `2^l` cells: never below any
//! translation's overlap), and free if ALL are. A voxel's score over the block is at most
//! 2 (may hit), -1 (free everywhere) or 0, so `Σ count(c) value(c + n)` over the scan's
//! distinct coarse cells bounds the score `2 hits - conflicts` of every pose in the node;
//! voxels sharing a coarse cell are looked up once. Leaves are scored exactly on the finest
//! grid, with the same arithmetic as the other searches.
//!
//! **Search.** Every rotation of the finest grid is bounded at its coarsest translation
//! blocks; rotations are processed best bound first, each depth first with children best
//! first, and nodes whose bound is below `keep_ratio` of the best score so far are pruned
//! (whole rotations included). Every pose scoring at least `keep_ratio` of the final best is
//! reached and recorded, so the result (pose, ambiguity, candidates) is that of the
//! exhaustive search, whatever the number of threads; only the count of nodes bounded
//! depends on timing.
//!
//! **Cost.** Pruning needs bounds below the best score. On scans whose finest-level overlap
//! is a small part of the scan (noisy 2 cm voxels, free-space conflicts) the bounds of
//! blocks a few cells wide stay above it and most leaves are scored: the exact search is
//! then orders of magnitude slower than the multi-resolution one (see README).

use std::sync::atomic::{AtomicI64, AtomicUsize, Ordering};
use std::time::Instant;

use nalgebra::Point3;
use rayon::prelude::*;

use super::dense::DenseGrid;
use super::params::SearchParams;
use super::search::{
    finish, key_of, no_overlap, prepare, rank, region_counts, threshold, Alignment, Cand, Lattice,
    LevelReport, Scored,
};
use super::target::SearchTarget;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::occupancy::OccupancyList;

/// Each rotation's roots are the translation blocks of the smallest level with at most
/// this many blocks.
const ROOTS_PER_ROTATION: u64 = 64;
/// Memory allowed for the finest grid.
const GRID_BUDGET_BYTES: usize = 1 << 30;

/// The finest map level and its free space as bits over their key box (z bits of an
/// (x, y) column in whole words).
struct FineGrid {
    lo: [i64; 3],
    dims: [usize; 3],
    /// u64 words per (x, y) column of z bits.
    words: usize,
    occ: Vec<u64>,
    /// Empty when no free space is known.
    free: Vec<u64>,
}

impl FineGrid {
    /// The grid of a map (and its free space), or `None` when it does not fit the memory
    /// budget.
    fn new(occ: &OccupancyList, free: Option<&DenseGrid>) -> Option<Self> {
        let mut lo = [i64::MAX; 3];
        let mut hi = [i64::MIN; 3];
        let mut grow = |k: [i64; 3]| {
            for i in 0..3 {
                lo[i] = lo[i].min(k[i]);
                hi[i] = hi[i].max(k[i]);
            }
        };
        for (k, _) in occ.iter() {
            grow([k.x as i64, k.y as i64, k.z as i64]);
        }
        if let Some(f) = free {
            let (a, b) = f.bounds();
            grow(a);
            grow(b);
        }
        if lo[0] > hi[0] {
            return None;
        }
        let dims = [0, 1, 2].map(|i| (hi[i] - lo[i] + 1) as usize);
        let words = dims[2].div_ceil(64);
        let len = dims[0].checked_mul(dims[1])?.checked_mul(words)?;
        let grids = if free.is_some() { 2 } else { 1 };
        if len.checked_mul(grids * 8)? > GRID_BUDGET_BYTES {
            return None;
        }
        let mut g = FineGrid {
            lo,
            dims,
            words,
            occ: vec![0u64; len],
            free: Vec::new(),
        };
        for (k, _) in occ.iter() {
            if let Some((w, b)) = g.index(k.x as i64, k.y as i64, k.z as i64) {
                g.occ[w] |= 1 << b;
            }
        }
        if let Some(f) = free {
            let mut bits = vec![0u64; len];
            f.for_each_set(|x, y, z| {
                if let Some((w, b)) = g.index(x, y, z) {
                    bits[w] |= 1 << b;
                }
            });
            g.free = bits;
        }
        Some(g)
    }

    #[inline]
    fn index(&self, x: i64, y: i64, z: i64) -> Option<(usize, u32)> {
        let dx = (x - self.lo[0]) as u64;
        let dy = (y - self.lo[1]) as u64;
        let dz = (z - self.lo[2]) as u64;
        // Negative differences wrap to huge values and fail these tests too.
        if dx < self.dims[0] as u64 && dy < self.dims[1] as u64 && dz < self.dims[2] as u64 {
            let col = (dx as usize * self.dims[1] + dy as usize) * self.words;
            Some((col + (dz / 64) as usize, (dz % 64) as u32))
        } else {
            None
        }
    }

    /// The score of a voxel in cell `(x, y, z)`: 2 if occupied, -1 if free, else 0.
    #[inline]
    fn value(&self, x: i64, y: i64, z: i64) -> i64 {
        match self.index(x, y, z) {
            Some((w, b)) if self.occ[w] >> b & 1 == 1 => 2,
            Some((w, b)) if !self.free.is_empty() && self.free[w] >> b & 1 == 1 => -1,
            _ => 0,
        }
    }
}

/// Level `l` of the bound for the translation blocks: cell `c` (coarse key, `k >> l` on
/// the searched translation axes, the finest key on the others) is occupied if any finest
/// cell of the window `[c 2^l, (c + 2) 2^l)` is (a max pool of width `2^(l+1)`, sampled
/// every `2^l` cells), free if all are.
struct CoarseLevel {
    shift: [u32; 3],
    lo: [i64; 3],
    dims: [u64; 3],
    occ: Vec<u64>,
    /// Empty when no free space is known.
    free: Vec<u64>,
}

impl CoarseLevel {
    fn new(fine: &FineGrid, level: u32, searched: [bool; 3]) -> Option<Self> {
        let shift = searched.map(|s| if s { level } else { 0 });
        let widen = searched.map(|s| if s { 1 } else { 0 });
        let fine_hi = [0, 1, 2].map(|i| fine.lo[i] + fine.dims[i] as i64 - 1);
        let lo = [0, 1, 2].map(|i| (fine.lo[i] >> shift[i]) - widen[i]);
        let hi = [0, 1, 2].map(|i| fine_hi[i] >> shift[i]);
        let dims = [0, 1, 2].map(|i| (hi[i] - lo[i] + 1) as u64);
        let cells = dims[0].checked_mul(dims[1])?.checked_mul(dims[2])?;
        let mut g = CoarseLevel {
            shift,
            lo,
            dims,
            occ: vec![0; cells.div_ceil(64) as usize],
            free: Vec::new(),
        };
        let has_free = !fine.free.is_empty();
        // Free cells per aligned block, to find the blocks that are all free.
        let mut free_count = if has_free {
            vec![0u32; cells as usize]
        } else {
            Vec::new()
        };
        let block: u32 = 1 << (shift[0] + shift[1] + shift[2]);
        for x in 0..fine.dims[0] {
            for y in 0..fine.dims[1] {
                let col = (x * fine.dims[1] + y) * fine.words;
                for w in 0..fine.words {
                    let (o, f) = (
                        fine.occ[col + w],
                        if has_free { fine.free[col + w] } else { 0 },
                    );
                    let mut bits = o | f;
                    while bits != 0 {
                        let b = bits.trailing_zeros();
                        bits &= bits - 1;
                        let k = [
                            fine.lo[0] + x as i64,
                            fine.lo[1] + y as i64,
                            fine.lo[2] + (w * 64) as i64 + b as i64,
                        ];
                        let c = [0, 1, 2].map(|i| k[i] >> shift[i]);
                        if o >> b & 1 == 1 {
                            for dx in 0..=widen[0] {
                                for dy in 0..=widen[1] {
                                    for dz in 0..=widen[2] {
                                        if let Some(i) = g.index(c[0] - dx, c[1] - dy, c[2] - dz) {
                                            g.occ[i / 64] |= 1 << (i % 64);
                                        }
                                    }
                                }
                            }
                        } else if let Some(i) = g.index(c[0], c[1], c[2]) {
                            free_count[i] += 1;
                        }
                    }
                }
            }
        }
        if has_free {
            let mut free = vec![0u64; g.occ.len()];
            for x in 0..dims[0] as i64 {
                for y in 0..dims[1] as i64 {
                    for z in 0..dims[2] as i64 {
                        let c = [lo[0] + x, lo[1] + y, lo[2] + z];
                        let all = (0..=widen[0]).all(|dx| {
                            (0..=widen[1]).all(|dy| {
                                (0..=widen[2]).all(|dz| {
                                    g.index(c[0] + dx, c[1] + dy, c[2] + dz)
                                        .is_some_and(|i| free_count[i] == block)
                                })
                            })
                        });
                        if all {
                            let i = g.index(c[0], c[1], c[2]).expect("inside");
                            free[i / 64] |= 1 << (i % 64);
                        }
                    }
                }
            }
            g.free = free;
        }
        Some(g)
    }

    #[inline]
    fn index(&self, x: i64, y: i64, z: i64) -> Option<usize> {
        let dx = (x - self.lo[0]) as u64;
        let dy = (y - self.lo[1]) as u64;
        let dz = (z - self.lo[2]) as u64;
        (dx < self.dims[0] && dy < self.dims[1] && dz < self.dims[2])
            .then(|| ((dx * self.dims[1] + dy) * self.dims[2] + dz) as usize)
    }

    #[inline]
    fn value(&self, x: i64, y: i64, z: i64) -> i64 {
        match self.index(x, y, z) {
            Some(i) if self.occ[i / 64] >> (i % 64) & 1 == 1 => 2,
            Some(i) if !self.free.is_empty() && self.free[i / 64] >> (i % 64) & 1 == 1 => -1,
            _ => 0,
        }
    }
}

/// A rotation's scan: finest keys, and per level the coarse keys with their counts.
struct Rotated {
    keys: Vec<[i64; 3]>,
    coarse: Vec<Vec<([i64; 3], u32)>>,
}

/// Per-thread scratch and results.
struct Worker {
    packed: Vec<u64>,
    kids: Vec<Vec<(i64, [i32; 3])>>,
    found: Vec<Scored>,
    bounded: Vec<usize>,
    passed: Vec<usize>,
}

struct Bnb<'a> {
    scan: &'a [Point3<f64>],
    fine: FineGrid,
    coarse: Vec<CoarseLevel>,
    lattice: &'a Lattice,
    n_t: [i32; 3],
    searched: [bool; 3],
    top: u32,
    best: AtomicI64,
    prune_ratio: f64,
}

impl Bnb<'_> {
    fn cut(&self) -> i64 {
        threshold(self.best.load(Ordering::Relaxed), self.prune_ratio)
    }

    fn rotated(&self, r: [i32; 3], w: &mut Worker) -> Rotated {
        let l = self.lattice;
        let d = l.dtheta(0);
        let a = [0, 1, 2].map(|i| l.angle0[i] + r[i] as f64 * d);
        let rot = crate::geometry::rotation_from_yaw_pitch_roll(a[0], a[1], a[2]);
        let keys: Vec<[i64; 3]> = self
            .scan
            .iter()
            .map(|c| key_of(&rot, c, l.t0, l.finest))
            .collect();
        let mut coarse = vec![Vec::new(); self.top as usize + 1];
        for (level, out) in coarse.iter_mut().enumerate().skip(1) {
            let g = &self.coarse[level];
            let shifted = |k: &[i64; 3]| [0, 1, 2].map(|i| k[i] >> g.shift[i]);
            let mut lo = [i64::MAX; 3];
            for k in &keys {
                let c = shifted(k);
                for i in 0..3 {
                    lo[i] = lo[i].min(c[i]);
                }
            }
            // 21 bits per axis: scans span far fewer cells.
            w.packed.clear();
            w.packed.extend(keys.iter().map(|k| {
                let c = shifted(k);
                let o = [0, 1, 2].map(|i| ((c[i] - lo[i]) as u64).min((1 << 21) - 1));
                o[0] << 42 | o[1] << 21 | o[2]
            }));
            w.packed.sort_unstable();
            let mask = (1u64 << 21) - 1;
            for chunk in w.packed.chunk_by(|a, b| a == b) {
                let p = chunk[0];
                let c = [
                    lo[0] + (p >> 42) as i64,
                    lo[1] + (p >> 21 & mask) as i64,
                    lo[2] + (p & mask) as i64,
                ];
                out.push((c, chunk.len() as u32));
            }
        }
        Rotated { keys, coarse }
    }

    /// The bound of translation block `t` at `level` (>= 1).
    fn bound(&self, rs: &Rotated, level: u32, t: [i32; 3]) -> i64 {
        let g = &self.coarse[level as usize];
        let (tx, ty, tz) = (t[0] as i64, t[1] as i64, t[2] as i64);
        rs.coarse[level as usize]
            .iter()
            .map(|(c, n)| *n as i64 * g.value(c[0] + tx, c[1] + ty, c[2] + tz))
            .sum()
    }

    /// The exact score and hits of the pose at translation `t`, or `None` once it cannot
    /// reach `cut`.
    fn leaf(&self, rs: &Rotated, t: [i32; 3], cut: i64) -> Option<(i64, u32)> {
        let (tx, ty, tz) = (t[0] as i64, t[1] as i64, t[2] as i64);
        let n = rs.keys.len();
        let (mut sum, mut hits) = (0i64, 0u32);
        for (idx, k) in rs.keys.iter().enumerate() {
            let v = self.fine.value(k[0] + tx, k[1] + ty, k[2] + tz);
            sum += v;
            hits += (v == 2) as u32;
            if idx % 256 == 255 && sum + 2 * ((n - idx - 1) as i64) < cut {
                return None;
            }
        }
        Some((sum, hits))
    }

    fn children(&self, t: [i32; 3], level: u32) -> impl Iterator<Item = [i32; 3]> + '_ {
        let half = move |i: usize| {
            let s = self.searched[i];
            let first = if s { 2 * t[i] } else { 0 };
            let second =
                (s && ((2 * t[i] + 1) << (level - 1)) < self.n_t[i]).then_some(2 * t[i] + 1);
            std::iter::once(first).chain(second)
        };
        half(0).flat_map(move |x| half(1).flat_map(move |y| half(2).map(move |z| [x, y, z])))
    }

    /// Depth first below translation block `t` at `level` of rotation `r`.
    fn expand(&self, r: [i32; 3], rs: &Rotated, t: [i32; 3], level: u32, w: &mut Worker) {
        let cl = level - 1;
        if cl == 0 {
            for c in self.children(t, level) {
                w.bounded[0] += 1;
                let cut = self.cut();
                if let Some((score, hits)) = self.leaf(rs, c, cut) {
                    if score >= cut {
                        w.passed[0] += 1;
                        self.best.fetch_max(score, Ordering::Relaxed);
                        w.found.push((score, hits, Cand { r, t: c }));
                        if w.found.len() > 4096 {
                            let cut = self.cut();
                            w.found.retain(|s| s.0 >= cut);
                        }
                    }
                }
            }
            return;
        }
        let mut kids = std::mem::take(&mut w.kids[cl as usize]);
        kids.clear();
        let cut = self.cut();
        for c in self.children(t, level) {
            w.bounded[cl as usize] += 1;
            let b = self.bound(rs, cl, c);
            if b >= cut {
                kids.push((b, c));
            }
        }
        kids.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        for &(b, c) in &kids {
            if b < self.cut() {
                break;
            }
            w.passed[cl as usize] += 1;
            self.expand(r, rs, c, cl, w);
        }
        w.kids[cl as usize] = kids;
    }
}

/// The exact search (see the module documentation). Locus regions are not handled here.
pub(super) fn exact_search(
    source: &PointCloud,
    target: &SearchTarget,
    params: &SearchParams,
) -> Result<Alignment> {
    let start = Instant::now();
    let problem = prepare(source, target, params)?;
    let (n_r, n_t) = region_counts(&problem, params, &target.pyramid, 0).ok_or_else(|| {
        Error::InvalidArgument("the exact search needs a global or window region".into())
    })?;
    let l = &problem.lattice;
    let searched = [true, true, l.searched_t[2]];
    // Roots: translation blocks of the smallest level with at most ROOTS_PER_ROTATION.
    let roots_at = |level: u32| -> u64 {
        (0..3)
            .map(|i| (n_t[i] as u64).div_ceil(1 << level))
            .product()
    };
    let mut top = 1u32;
    while roots_at(top) > ROOTS_PER_ROTATION && top < 16 {
        top += 1;
    }
    let too_big = || {
        Error::InvalidArgument(
            "the exact search's map grids do not fit in memory; use the multi-resolution search"
                .into(),
        )
    };
    let fine = FineGrid::new(target.pyramid.base(), problem.free[0]).ok_or_else(too_big)?;
    let coarse = (0..=top)
        .map(|level| {
            if level == 0 {
                // Unused: leaves are scored on the finest grid.
                Ok(CoarseLevel {
                    shift: [0; 3],
                    lo: [0; 3],
                    dims: [0; 3],
                    occ: Vec::new(),
                    free: Vec::new(),
                })
            } else {
                CoarseLevel::new(&fine, level, searched).ok_or_else(too_big)
            }
        })
        .collect::<Result<Vec<_>>>()?;
    let scan = &problem.scan[0];
    let bnb = Bnb {
        scan,
        fine,
        coarse,
        lattice: l,
        n_t,
        searched,
        top,
        best: AtomicI64::new(i64::MIN / 4),
        prune_ratio: params.keep_ratio,
    };
    let levels = top as usize + 1;
    let new_worker = || Worker {
        packed: Vec::new(),
        kids: vec![Vec::new(); levels],
        found: Vec::new(),
        bounded: vec![0; levels],
        passed: vec![0; levels],
    };
    let rotations: Vec<[i32; 3]> = (0..n_r[0])
        .flat_map(|a| (0..n_r[1]).flat_map(move |b| (0..n_r[2]).map(move |g| [a, b, g])))
        .collect();
    let roots: Vec<[i32; 3]> = (0..(n_t[0] as u32).div_ceil(1 << top) as i32)
        .flat_map(|x| {
            (0..(n_t[1] as u32).div_ceil(1 << top) as i32).flat_map(move |y| {
                (0..(n_t[2] as u32).div_ceil(1 << top) as i32).map(move |z| [x, y, z])
            })
        })
        .collect();
    let roots: Vec<[i32; 3]> = if searched[2] {
        roots
    } else {
        roots.into_iter().map(|t| [t[0], t[1], 0]).collect()
    };
    // Order the rotations by their best root bound.
    let t_roots = Instant::now();
    let mut order: Vec<(i64, [i32; 3])> = rotations
        .par_iter()
        .map_init(new_worker, |w, r| {
            let rs = bnb.rotated(*r, w);
            let b = roots
                .iter()
                .map(|t| bnb.bound(&rs, top, *t))
                .max()
                .unwrap_or(0);
            (b, *r)
        })
        .collect();
    order.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    let root_seconds = t_roots.elapsed().as_secs_f64();
    let next = AtomicUsize::new(0);
    let threads = rayon::current_num_threads().max(1);
    let workers: Vec<Worker> = (0..threads)
        .into_par_iter()
        .map(|_| {
            let mut w = new_worker();
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(b, r)) = order.get(i) else {
                    break;
                };
                if b < bnb.cut() {
                    break;
                }
                let rs = bnb.rotated(r, &mut w);
                let mut tops: Vec<(i64, [i32; 3])> = roots
                    .iter()
                    .map(|t| (bnb.bound(&rs, top, *t), *t))
                    .collect();
                w.bounded[top as usize] += tops.len();
                tops.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
                for (b, t) in tops {
                    if b < bnb.cut() {
                        break;
                    }
                    w.passed[top as usize] += 1;
                    bnb.expand(r, &rs, t, top, &mut w);
                }
            }
            w
        })
        .collect();
    let best = bnb.best.load(Ordering::Relaxed);
    let cut = threshold(best, params.keep_ratio);
    let mut scored: Vec<Scored> = workers
        .iter()
        .flat_map(|w| w.found.iter().copied())
        .filter(|s| s.0 >= cut)
        .collect();
    rank(&mut scored);
    let reports: Vec<LevelReport> = (0..levels)
        .rev()
        .map(|lv| {
            let sum = |f: fn(&Worker) -> &Vec<usize>| workers.iter().map(|w| f(w)[lv]).sum();
            let passed: usize = sum(|w| &w.passed);
            LevelReport {
                level: lv,
                resolution: l.cell(lv),
                angular_step: l.dtheta(0),
                scan_voxels: scan.len(),
                evaluated: sum(|w| &w.bounded),
                passed,
                survivors: passed,
                best_overlap: if lv == 0 {
                    scored.first().map_or(0, |s| s.1 as u64)
                } else {
                    0
                },
                seconds: if lv == top as usize {
                    root_seconds
                } else if lv == 0 {
                    start.elapsed().as_secs_f64() - root_seconds
                } else {
                    0.0
                },
            }
        })
        .collect();
    let mut a = match scored.first() {
        Some(s) if s.1 > 0 => finish(&problem, params, &scored, reports, start),
        _ => no_overlap(&problem, reports, start),
    };
    a.evaluated += rotations.len() * roots.len();
    a.exact = true;
    Ok(a)
}
