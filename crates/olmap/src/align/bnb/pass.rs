//! One pass of the exact search: the best pose outside the earlier cluster heads'
//! neighbourhoods, roots bounded in parallel, then each expanded depth first by a pool of
//! workers sharing the best score found.

use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, AtomicUsize, Ordering};

use nalgebra::{UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::node::{Block, Bnb, Child, Head, Kid, Worker};
use crate::align::lattice::{Cand, Scored};

/// A score below every real one (a pass's floor and best before anything is found), with
/// room left below it so that sums cannot overflow.
pub(super) const NO_SCORE: i64 = i64::MIN / 4;

/// The work the passes of one search may do, shared by them: voxel bounds (a node's
/// bound reads each scan voxel once), up to a limit.
pub(super) struct Budget {
    pub(super) spent: AtomicU64,
    pub(super) limit: u64,
    pub(super) exhausted: AtomicBool,
}

impl Budget {
    /// A budget of `limit` voxel bounds.
    pub(super) fn new(limit: u64) -> Self {
        Budget {
            spent: AtomicU64::new(0),
            limit,
            exhausted: AtomicBool::new(false),
        }
    }

    /// Counts `n` more voxel bounds; marks the budget exhausted past the limit.
    fn spend(&self, n: u64) {
        if self.spent.fetch_add(n, Ordering::Relaxed).saturating_add(n) > self.limit {
            self.exhausted.store(true, Ordering::Relaxed);
        }
    }

    /// Whether the limit was passed (the search stops and reports it).
    pub(super) fn exhausted(&self) -> bool {
        self.exhausted.load(Ordering::Relaxed)
    }
}

/// One pass: the best pose outside the heads' neighbourhoods scoring at least `floor`.
pub(super) struct Pass<'a> {
    pub(super) bnb: &'a Bnb<'a>,
    pub(super) heads: &'a [Head],
    pub(super) floor: i64,
    pub(super) best: AtomicI64,
    pub(super) budget: &'a Budget,
}

impl Pass<'_> {
    /// The score a node must reach to be kept; above every score once the budget is
    /// exhausted, so that every worker unwinds at once.
    fn cut(&self) -> i64 {
        if self.budget.exhausted() {
            return i64::MAX;
        }
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
            self.budget.spend((live.len() * n) as u64);
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
    pub(super) fn run(&self, new_worker: &(dyn Fn() -> Worker + Sync)) -> Vec<Worker> {
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
        self.budget
            .spend((rot_roots.len() * t_roots.len() * n) as u64);
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
