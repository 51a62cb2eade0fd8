//! The exact global search: branch and bound over rotations and translations together
//! ([`super::SearchMode::Exact`]).
//!
//! The poses are those of the exhaustive search (Algorithm 7): rotation indices `j` (angle
//! `angle0 + j dθ`, `dθ = resolution / R`) and translation indices `i` (`t0 + i resolution`).
//! A node of level `l` is a dyadic block of translations `[n 2^l, (n + 1) 2^l)` on every
//! searched translation axis and a dyadic block of rotations `[m 2^r, (m + 1) 2^r)` on every
//! searched rotation axis, `r = l - ROTATION_LAG` (at least 0).
//!
//! **Bound.** Rotate the scan by the centre of the node's rotation block. A rotation of the
//! block differs from the centre by at most `θ = Σ (2^r - 1) dθ / 2` (one term per searched
//! axis; the geodesic distance between rotations obeys the triangle inequality), so it moves
//! a voxel centre `c` by at most `|c| θ`: with `m = max |c| θ`, every pose of the node puts
//! the voxel in a finest cell of the box that starts at `floor((p - m) / cell) + n 2^l` and
//! is `2^l + diff` cells wide (`diff` covers `2m`; a yaw-only search moves no voxel in z).
//! Level `l`'s bound grid marks a cell occupied if ANY cell of that box is, free if ALL
//! are (a max pool over a sliding window, not the aligned downsample of the pyramid). A
//! voxel can score at most 2 (may hit), -1 (free everywhere) or 0, so the sum over the scan
//! never underestimates the score `2 hits - conflicts` of any pose of the node. To bound
//! the memory, a level's grid samples the windows every `2^(w - STRIDE_SLACK)` cells (at
//! most `2^l`) on an axis where they are about `2^w` cells wide, the block plus the rotation
//! margins (the window then grows by less than a sample). Leaves are scored exactly on
//! the finest grid with the arithmetic of the other searches.
//!
//! **Search.** The roots (every rotation block and translation block of the coarsest
//! level, the first with at most [`ROOT_TRANSLATIONS`] translation blocks and
//! [`ROOT_NODES`] roots) are bounded and processed best first, each depth first with
//! children best first; a node is pruned when its bound is below the best score found so
//! far, so the best pose of the finest lattice is always reached (ties go to the lowest
//! pose index, as in the exhaustive search, whatever the number of threads).
//!
//! **Ambiguity.** The exhaustive search clusters the poses scoring at least `keep_ratio`
//! of the best greedily in score order: a pose starts a cluster unless it lies within
//! `ambiguity_distance` and `ambiguity_angle` of an earlier cluster's head. Cluster `k + 1`'s
//! head is therefore the best pose outside the first `k` heads' neighbourhoods, which is
//! what each further pass searches for (nodes wholly inside a neighbourhood are skipped,
//! and `keep_ratio` of the best is a floor for the pruning), until none is left. The
//! ambiguity and candidates are those of the exhaustive search, counted up to
//! [`EXACT_MAX_AMBIGUITY`].

mod grid;

use std::sync::atomic::{AtomicI64, AtomicUsize, Ordering};
use std::time::Instant;

use nalgebra::{Point3, Rotation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use self::grid::{BitGrid, PairGrid};
use super::lattice::{
    finish, no_overlap, prepare, region_counts, threshold, Alignment, Cand, Lattice, LevelReport,
    Scored,
};
use super::params::SearchParams;
use super::score::DenseGrid;
use super::target::SearchTarget;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::rotation_from_yaw_pitch_roll;
use crate::occupancy::OccupancyList;

/// The coarsest level has at most this many translation blocks.
const ROOT_TRANSLATIONS: u64 = 64;
/// The roots (rotation blocks times translation blocks) number at most this many, when
/// 16 levels allow it. Without it, a small window over three rotation axes made every
/// rotation a root. On the car pair in a ±2° / ±0.3 m six-degree-of-freedom window the
/// search took 25 / 24 / 34 / 42 s with at most 1,000 / 10,000 / 100,000 / any roots.
const ROOT_NODES: u64 = 10_000;
/// Memory allowed for all the bound grids together.
const GRID_BUDGET_BYTES: usize = 1 << 30;
/// A level's grid samples its windows every `2^(w - STRIDE_SLACK)` cells on an axis where
/// the window is about `2^w` cells wide (every cell on narrow axes).
const STRIDE_SLACK: u32 = 2;
/// Rotation blocks are `2^ROTATION_LAG` times narrower (in steps) than translation blocks
/// (in cells) at the same level: the two finest levels bound single rotations exactly. On
/// the 3DTK pair 1 -> 0 the first pass took 75 s with 0, 48 s with 2, 50 s with 3 and
/// 53 s with 4 (2 cores).
const ROTATION_LAG: u32 = 2;
/// The exact search counts clusters (its [`Alignment::ambiguity`]) up to this many: each
/// takes a pass, and a scene with more distinct solutions is ambiguous whatever their
/// number. Below the cap the count is that of the exhaustive search.
pub const EXACT_MAX_AMBIGUITY: usize = 16;

/// One level's bound: the window grids and how scan voxels map onto them.
struct Level {
    /// Rotation level `r` of the nodes.
    rot_level: u32,
    /// Metres added on each side of a voxel's centre for the rotation block.
    margin: [f64; 3],
    /// Window grids sample every `2^shift` cells.
    shift: [u32; 3],
    /// Occupied-if-any and free-if-all windows, interleaved.
    cells: PairGrid,
}

impl Level {
    /// The score bound of a voxel whose window starts in cell `q` (sampled).
    #[inline(always)]
    fn value(&self, q: [i64; 3]) -> i64 {
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

/// A node found worth expanding: its bound, rotation block and translation block.
#[derive(Debug, Clone, Copy)]
struct Block {
    /// The node's score bound.
    bound: i64,
    /// Rotation block indices.
    rot: [i32; 3],
    /// Translation block indices.
    trans: [i32; 3],
}

impl Block {
    /// Best bound first; ties by (rotation block, translation block), lexicographically.
    fn best_first(&self, other: &Block) -> std::cmp::Ordering {
        other
            .bound
            .cmp(&self.bound)
            .then((self.rot, self.trans).cmp(&(other.rot, other.trans)))
    }
}

/// A child kept for expansion: the block and the slot of its per-voxel values.
#[derive(Debug, Clone, Copy)]
struct Kid {
    /// Bound and blocks.
    block: Block,
    /// Where its per-voxel values are in the level's buffer.
    slot: usize,
}

/// Per-thread scratch, counts and the best pose found.
struct Worker {
    keys: Vec<[i64; 3]>,
    /// Per level: the rotation block whose keys `level_keys` holds. Nodes that share a
    /// rotation block share their keys, and depth first visits them one after another.
    keys_of: Vec<Option<[i32; 3]>>,
    /// Per level: the keys of the rotation block `keys_of`.
    level_keys: Vec<Vec<[i64; 3]>>,
    /// Per level: the children kept (bound, rotation block, translation block, slot).
    kids: Vec<Vec<Kid>>,
    /// Per level: the children's per-voxel values, `scan.len()` per slot.
    vals: Vec<Vec<i8>>,
    /// Per level: suffix sums of the values of the node being expanded.
    rest: Vec<Vec<i64>>,
    /// Per level: the voxel order of the node being expanded.
    order: Vec<Vec<u32>>,
    /// The children of one rotation being bounded.
    live: Vec<Child>,
    /// The per-voxel values of the roots of one rotation block.
    root_vals: Vec<i8>,
    best: Option<Scored>,
    bounded: Vec<usize>,
    passed: Vec<usize>,
}

/// A child being bounded: translation block, its sampled offset, the running sum and hits,
/// and where its per-voxel values go.
struct Child {
    t: [i32; 3],
    offset: [i64; 3],
    sum: i64,
    hits: u32,
    slot: usize,
}

/// Half the width of a rotation block of level `r`, in finest angular steps: the block
/// covers `2^r` steps, and its centre is this far from its first and last.
fn half_steps(r: u32) -> f64 {
    ((1u64 << r) - 1) as f64 / 2.0
}

impl Child {
    fn new(t: [i32; 3], offset: [i64; 3], slot: usize) -> Self {
        Child {
            t,
            offset,
            sum: 0,
            hits: 0,
            slot,
        }
    }
}

/// A score below every real one (a pass's floor and best before anything is found), with
/// room left below it so that sums cannot overflow.
const NO_SCORE: i64 = i64::MIN / 4;

/// Voxels summed between two tests of the cut.
const CHUNK: usize = 32;

/// A cluster head of an earlier pass: its neighbourhood is searched no more.
struct Head {
    t: Vector3<f64>,
    rot: UnitQuaternion<f64>,
}

struct Bnb<'a> {
    scan: &'a [Point3<f64>],
    lattice: &'a Lattice,
    levels: Vec<Level>,
    n_r: [i32; 3],
    n_t: [i32; 3],
    searched_t: [bool; 3],
    searched_r: [bool; 3],
    top: u32,
    ambiguity_distance: f64,
    ambiguity_angle: f64,
}

/// One pass: the best pose outside the heads' neighbourhoods scoring at least `floor`.
struct Pass<'a> {
    bnb: &'a Bnb<'a>,
    heads: &'a [Head],
    floor: i64,
    best: AtomicI64,
}

impl Bnb<'_> {
    /// Half the angular width of a rotation block of level `r`, per searched axis.
    fn half_width(&self, r: u32) -> f64 {
        half_steps(r) * self.lattice.dtheta(0)
    }

    /// The rotation at the centre of block `rb` of level `r`.
    fn centre(&self, rb: [i32; 3], r: u32) -> Rotation3<f64> {
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
    fn fill_keys(&self, rb: [i32; 3], level: u32, out: &mut Vec<[i64; 3]>) {
        let lv = &self.levels[level as usize];
        let rot = self.centre(rb, lv.rot_level);
        let (t0, cell) = (self.lattice.t0, self.lattice.finest);
        out.clear();
        out.extend(self.scan.iter().map(|c| {
            // The formula of `key_of` (`v - 0.0` is `v`, so the same keys at margin 0).
            let p = rot * c.coords + t0;
            let k = |v: f64, m: f64, s: u32| -> i64 { (((v - m) / cell).floor() as i64) >> s };
            [
                k(p.x, lv.margin[0], lv.shift[0]),
                k(p.y, lv.margin[1], lv.shift[1]),
                k(p.z, lv.margin[2], lv.shift[2]),
            ]
        }));
    }

    /// The sampled offset of translation block `tb` at `level`.
    #[inline]
    fn offset(&self, tb: [i32; 3], level: u32) -> [i64; 3] {
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
    fn bound_children(
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
    fn split(block: [i32; 3], level: u32, count: [i32; 3], searched: [bool; 3]) -> Vec<[i32; 3]> {
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

    fn rot_children(&self, rb: [i32; 3], level: u32) -> Vec<[i32; 3]> {
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
    fn t_range(&self, tb: [i32; 3], level: u32) -> [(i32, i32); 3] {
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

impl Pass<'_> {
    fn cut(&self) -> i64 {
        self.best.load(Ordering::Relaxed).max(self.floor)
    }

    /// Whether every pose of the node lies in some head's neighbourhood.
    fn node_excluded(&self, rb: [i32; 3], tb: [i32; 3], level: u32) -> bool {
        if self.heads.is_empty() {
            return false;
        }
        let b = self.bnb;
        let r = b.levels[level as usize].rot_level;
        let rot = UnitQuaternion::from_rotation_matrix(&b.centre(rb, r));
        let theta = b.half_width(r) * b.searched_r.iter().filter(|s| **s).count() as f64;
        let range = b.t_range(tb, level);
        let l = b.lattice;
        let eps = 1e-9;
        self.heads.iter().any(|h| {
            if (h.rot.inverse() * rot).angle() + theta > b.ambiguity_angle - eps {
                return false;
            }
            (0..8).all(|corner: usize| {
                let idx = [0, 1, 2].map(|i| {
                    if corner >> i & 1 == 0 {
                        range[i].0
                    } else {
                        range[i].1
                    }
                });
                let t = l.t0 + Vector3::new(idx[0] as f64, idx[1] as f64, idx[2] as f64) * l.finest;
                (h.t - t).norm() <= b.ambiguity_distance - eps
            })
        })
    }

    /// Whether a lattice pose lies in some head's neighbourhood (the test of `finish`).
    fn pose_excluded(&self, c: &Cand) -> bool {
        if self.heads.is_empty() {
            return false;
        }
        let pose = self.bnb.lattice.pose(c, 0);
        self.heads.iter().any(|h| {
            (h.t - pose.translation()).norm() <= self.bnb.ambiguity_distance
                && (h.rot.inverse() * pose.rotation()).angle() <= self.bnb.ambiguity_angle
        })
    }

    fn record(&self, w: &mut Worker, f: Scored) {
        let better = match w.best {
            None => true,
            Some(b) => f.score > b.score || (f.score == b.score && f.cand < b.cand),
        };
        if better {
            w.best = Some(f);
        }
        self.best.fetch_max(f.score, Ordering::Relaxed);
    }

    /// Depth first below a node that passed, whose per-voxel values are `vals`.
    fn expand(&self, w: &mut Worker, rb: [i32; 3], tb: [i32; 3], level: u32, vals: &[i8]) {
        let b = self.bnb;
        let n = b.scan.len();
        let cl = level - 1;
        // Voxels that can lose most first (the parent's 2s, then 0s, then -1s), so that a
        // child falls below the cut after as few lookups as possible: one counting pass,
        // then one placing pass (values are 2, 0 or -1).
        let group = |v: i8| -> usize {
            match v {
                2 => 0,
                0 => 1,
                _ => 2,
            }
        };
        let mut count = [0usize; 3];
        for &v in vals {
            count[group(v)] += 1;
        }
        let mut order = std::mem::take(&mut w.order[level as usize]);
        order.clear();
        order.resize(n, 0);
        let mut at = [0, count[0], count[0] + count[1]];
        for (i, &v) in vals.iter().enumerate() {
            let g = group(v);
            order[at[g]] = i as u32;
            at[g] += 1;
        }
        // The sum over `order[i..]`: the 2s left, then the -1s left.
        let mut rest = std::mem::take(&mut w.rest[level as usize]);
        rest.clear();
        rest.extend(
            (0..=n).map(|i| 2 * count[0].saturating_sub(i) as i64 - (n - i).min(count[2]) as i64),
        );
        let mut kids = std::mem::take(&mut w.kids[cl as usize]);
        kids.clear();
        let mut buf = std::mem::take(&mut w.vals[cl as usize]);
        let t_kids = Bnb::split(tb, level, b.n_t, b.searched_t);
        let r_kids = b.rot_children(rb, level);
        buf.resize(n * t_kids.len() * r_kids.len(), 0);
        let mut live = std::mem::take(&mut w.live);
        for (ri, &rk) in r_kids.iter().enumerate() {
            let mut keys = std::mem::take(&mut w.level_keys[cl as usize]);
            if w.keys_of[cl as usize] != Some(rk) {
                b.fill_keys(rk, cl, &mut keys);
                w.keys_of[cl as usize] = Some(rk);
            }
            live.clear();
            for (ti, &tk) in t_kids.iter().enumerate() {
                if cl > 0 && self.node_excluded(rk, tk, cl) {
                    continue;
                }
                live.push(Child::new(tk, b.offset(tk, cl), ri * t_kids.len() + ti));
            }
            w.bounded[cl as usize] += live.len();
            b.bound_children(cl, &keys, &order, vals, &rest, &mut live, &mut buf, || {
                self.cut()
            });
            let cut = self.cut();
            for c in &live {
                if c.sum < cut {
                    continue;
                }
                if cl == 0 {
                    let cand = Cand { r: rk, t: c.t };
                    if !self.pose_excluded(&cand) {
                        w.passed[0] += 1;
                        self.record(
                            w,
                            Scored {
                                score: c.sum,
                                hits: c.hits,
                                cand,
                            },
                        );
                    }
                } else {
                    kids.push(Kid {
                        block: Block {
                            bound: c.sum,
                            rot: rk,
                            trans: c.t,
                        },
                        slot: c.slot,
                    });
                }
            }
            w.level_keys[cl as usize] = keys;
        }
        w.live = live;
        kids.sort_unstable_by(|a, b| a.block.best_first(&b.block));
        for &Kid {
            block:
                Block {
                    bound,
                    rot: rk,
                    trans: tk,
                },
            slot,
        } in &kids
        {
            if bound < self.cut() {
                break;
            }
            w.passed[cl as usize] += 1;
            self.expand(w, rk, tk, cl, &buf[slot * n..(slot + 1) * n]);
        }
        w.kids[cl as usize] = kids;
        w.vals[cl as usize] = buf;
        w.rest[level as usize] = rest;
        w.order[level as usize] = order;
    }

    /// Runs the pass: the best pose found, with the per-level counts.
    fn run(&self, new_worker: &(dyn Fn() -> Worker + Sync)) -> Vec<Worker> {
        let b = self.bnb;
        let top = b.top;
        let r_top = b.levels[top as usize].rot_level;
        let blocks = |n: [i32; 3], searched: [bool; 3], shift: u32| -> Vec<[i32; 3]> {
            let c = [0, 1, 2].map(|i| {
                if searched[i] {
                    ((n[i] as i64 + (1 << shift) - 1) >> shift) as i32
                } else {
                    1
                }
            });
            let mut v = Vec::new();
            for x in 0..c[0] {
                for y in 0..c[1] {
                    for z in 0..c[2] {
                        v.push([x, y, z]);
                    }
                }
            }
            v
        };
        let n = b.scan.len();
        let twos = vec![2i8; n];
        // The sum of `twos` over `i..`.
        let all_rest: Vec<i64> = (0..=n).map(|i| 2 * (n - i) as i64).collect();
        let rot_roots = blocks(b.n_r, b.searched_r, r_top);
        let t_roots = blocks(b.n_t, b.searched_t, top);
        let identity: Vec<u32> = (0..n as u32).collect();
        // The bound of root block `tb` for the keys in `w.keys`, with its per-voxel values
        // in `vals` (a buffer the size of the scan); `None` once it falls below `cut`.
        let bound_root = |w: &mut Worker, tb: [i32; 3], vals: &mut [i8], cut: i64| {
            let mut live = std::mem::take(&mut w.live);
            live.clear();
            live.push(Child::new(tb, b.offset(tb, top), 0));
            b.bound_children(
                top,
                &w.keys,
                &identity,
                &twos,
                &all_rest,
                &mut live,
                vals,
                || cut,
            );
            let bound = live.first().map(|c| (c.sum, c.hits));
            w.live = live;
            bound
        };
        let mut roots: Vec<Block> = rot_roots
            .par_iter()
            .map_init(new_worker, |w, rb| {
                b.fill_keys(*rb, top, &mut w.keys);
                let mut buf = std::mem::take(&mut w.root_vals);
                buf.resize(n, 0);
                let kept = t_roots
                    .iter()
                    .filter(|tb| !self.node_excluded(*rb, **tb, top))
                    .filter_map(|tb| {
                        let (s, _) = bound_root(w, *tb, &mut buf, self.floor)?;
                        (s >= self.floor).then_some(Block {
                            bound: s,
                            rot: *rb,
                            trans: *tb,
                        })
                    })
                    .collect::<Vec<_>>();
                w.root_vals = buf;
                kept
            })
            .flatten()
            .collect();
        roots.sort_unstable_by(Block::best_first);
        let n_roots = rot_roots.len() * t_roots.len();
        let next = AtomicUsize::new(0);
        let threads = rayon::current_num_threads().max(1);
        let mut workers: Vec<Worker> = (0..threads)
            .into_par_iter()
            .map(|_| {
                let mut w = new_worker();
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&Block {
                        bound,
                        rot: rb,
                        trans: tb,
                    }) = roots.get(i)
                    else {
                        break;
                    };
                    if bound < self.cut() {
                        break;
                    }
                    w.passed[top as usize] += 1;
                    b.fill_keys(rb, top, &mut w.keys);
                    let mut vals = std::mem::take(&mut w.root_vals);
                    vals.resize(n, 0);
                    let root = bound_root(&mut w, tb, &mut vals, i64::MIN);
                    if let Some((s, h)) = root {
                        if top == 0 {
                            let c = Cand { r: rb, t: tb };
                            if !self.pose_excluded(&c) {
                                self.record(
                                    &mut w,
                                    Scored {
                                        score: s,
                                        hits: h,
                                        cand: c,
                                    },
                                );
                            }
                        } else {
                            self.expand(&mut w, rb, tb, top, &vals);
                        }
                    }
                    w.root_vals = vals;
                }
                w
            })
            .collect();
        workers[0].bounded[top as usize] += n_roots;
        workers
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
    let searched_t = [true, true, l.searched_t[2]];
    let searched_r = l.searched_r;
    let roots_at = |level: u32| -> u64 {
        (0..3)
            .map(|i| (n_t[i] as u64).div_ceil(1 << level))
            .product()
    };
    let rot_roots_at = |level: u32| -> u64 {
        let r = level.saturating_sub(ROTATION_LAG);
        (0..3)
            .filter(|&i| searched_r[i])
            .map(|i| (n_r[i] as u64).div_ceil(1 << r))
            .product()
    };
    let mut top = 0u32;
    while (roots_at(top) > ROOT_TRANSLATIONS
        || roots_at(top).saturating_mul(rot_roots_at(top)) > ROOT_NODES)
        && top < 16
    {
        top += 1;
    }
    let scan = &problem.scan[0];
    let rho = scan.iter().map(|c| c.coords.norm()).fold(0.0, f64::max);
    let yaw_only = searched_r == [true, false, false];
    let cell = l.finest;
    // Each level's rotation level, margins, window widths, sampling shifts and taps.
    struct Shape {
        rot_level: u32,
        margin: [f64; 3],
        shift: [u32; 3],
        taps: [usize; 3],
    }
    let shapes: Vec<Shape> = (0..=top)
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
        .collect();
    let too_big = || {
        Error::InvalidArgument(
            "the exact search's bound grids do not fit in memory; use the multi-resolution search"
                .into(),
        )
    };
    let align = shapes.iter().flat_map(|s| s.shift).max().unwrap_or(0);
    let free_map = problem.free[0];
    let (fine_occ, fine_free) =
        fine_grids(target.pyramid.base(), free_map, align).ok_or_else(too_big)?;
    let mut budget = GRID_BUDGET_BYTES
        .checked_sub(fine_occ.bytes() + fine_free.as_ref().map_or(0, BitGrid::bytes))
        .ok_or_else(too_big)?;
    // Aligned downsamples by shift vector, built by halving one axis at a time.
    let mut aligned: std::collections::BTreeMap<[u32; 3], (BitGrid, Option<BitGrid>)> =
        std::collections::BTreeMap::new();
    aligned.insert([0; 3], (fine_occ, fine_free));
    let mut levels = Vec::with_capacity(shapes.len());
    for shape in &shapes {
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
    let grid_seconds = start.elapsed().as_secs_f64();
    let bnb = Bnb {
        scan,
        lattice: l,
        levels,
        n_r,
        n_t,
        searched_t,
        searched_r,
        top,
        ambiguity_distance: params.ambiguity_distance,
        ambiguity_angle: params.ambiguity_angle,
    };
    let n_levels = top as usize + 1;
    let new_worker = || Worker {
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
    };
    let mut heads: Vec<Head> = Vec::new();
    let mut found: Vec<Scored> = Vec::new();
    let mut bounded = vec![0usize; n_levels];
    let mut passed = vec![0usize; n_levels];
    let mut floor = NO_SCORE;
    while found.len() < EXACT_MAX_AMBIGUITY {
        let pass = Pass {
            bnb: &bnb,
            heads: &heads,
            floor,
            best: AtomicI64::new(NO_SCORE),
        };
        let workers = pass.run(&new_worker);
        for w in &workers {
            for lv in 0..n_levels {
                bounded[lv] += w.bounded[lv];
                passed[lv] += w.passed[lv];
            }
        }
        let best = workers.iter().filter_map(|w| w.best).reduce(|a, b| {
            if b.score > a.score || (b.score == a.score && b.cand < a.cand) {
                b
            } else {
                a
            }
        });
        let Some(best) = best else { break };
        if found.is_empty() {
            if best.hits == 0 {
                found.push(best);
                break;
            }
            floor = threshold(best.score, params.keep_ratio);
        }
        let pose = l.pose(&best.cand, 0);
        heads.push(Head {
            t: pose.translation(),
            rot: pose.rotation(),
        });
        found.push(best);
    }
    let reports: Vec<LevelReport> = (0..n_levels)
        .rev()
        .map(|lv| LevelReport {
            level: lv,
            resolution: l.cell(lv),
            angular_step: l.dtheta(bnb.levels[lv].rot_level as usize),
            scan_voxels: scan.len(),
            evaluated: bounded[lv],
            passed: passed[lv],
            survivors: passed[lv],
            best_overlap: if lv == 0 {
                found.first().map_or(0, |s| s.hits as u64)
            } else {
                0
            },
            seconds: if lv == top as usize {
                grid_seconds
            } else if lv == 0 {
                start.elapsed().as_secs_f64() - grid_seconds
            } else {
                0.0
            },
        })
        .collect();
    let mut a = match found.first() {
        Some(s) if s.hits > 0 => finish(&problem, params, &found, reports, start),
        _ => no_overlap(&problem, reports, start),
    };
    a.exact = true;
    Ok(a)
}
