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
//! ambiguity and candidates are those of the exhaustive search, listed up to
//! [`EXACT_MAX_AMBIGUITY`] and counted up to one more (standing for "more than that").

mod bound;
mod grid;
mod node;
mod pass;

use std::sync::atomic::AtomicI64;
use std::time::Instant;

use self::bound::{build_levels, level_shapes};
use self::node::{Bnb, Head, Worker};
use self::pass::{Budget, Pass, NO_SCORE};
use super::lattice::{
    finish, no_overlap, prepare, region_counts, threshold, Alignment, Lattice, LevelReport, Scored,
};
use super::params::SearchParams;
use super::target::SearchTarget;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};

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
/// The default of [`SearchParams::exact_max_work`]: the most work the exact search does
/// before it gives up with [`Error::TooLarge`], in voxel bounds (one node bounded over one
/// scan voxel). On targets where every pose scores alike (a scan of a floor against a
/// floor) no bound prunes and the search would run for hours. The hardest real pair, 3DTK
/// scan001 against scan000 (global, x-y-z-yaw), bounds 36.5 million nodes of 2,516 voxels:
/// 9.2e10, a fifth of this.
pub const EXACT_MAX_WORK: u64 = 500_000_000_000;
/// The exact search lists clusters (its [`Alignment::candidates`]) up to this many and
/// counts them (its [`Alignment::ambiguity`]) up to one more, which stands for "more than
/// this": each takes a pass, and a scene with more distinct solutions is ambiguous
/// whatever their number. Up to the cap the count is that of the exhaustive search.
pub const EXACT_MAX_AMBIGUITY: usize = 16;

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
    let top = top_level(n_r, n_t, searched_r);
    check_roots(n_r, n_t, searched_r, top)?;
    let scan = &problem.scan[0];
    let shapes = level_shapes(l, scan, top, searched_t, searched_r);
    let levels = build_levels(&shapes, target.pyramid.base(), problem.free[0])?;
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
    let budget = Budget::new(params.exact_max_work);
    let (found, bounded, passed) = passes(&bnb, params, n_levels, &budget);
    if budget.exhausted() {
        return Err(Error::TooLarge {
            what: format!(
                "the exact search gave up after bounding {} nodes ({:.2e} voxel bounds): \
                 too many poses score alike for the bounds to prune (a flat or repetitive \
                 scene); use the multi-resolution search, a window, or a larger \
                 exact_max_work",
                bounded.iter().sum::<usize>(),
                budget.spent.load(std::sync::atomic::Ordering::Relaxed) as f64
            ),
            limit: format!("{:.2e} voxel bounds", params.exact_max_work as f64),
        });
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
        Some(s) if s.hits > 0 => finish(&problem, params, &found, &[], reports, start),
        _ => no_overlap(&problem, reports, start),
    };
    // Past the cap the count stays one above it ("more than the cap") and the list stops
    // at the cap: the heads beyond it are unlisted, as a capped list of the other searches'.
    a.candidates.truncate(EXACT_MAX_AMBIGUITY);
    a.exact = true;
    Ok(a)
}

/// The coarsest level: the first with at most [`ROOT_TRANSLATIONS`] translation blocks and
/// [`ROOT_NODES`] roots (at most 16), for `n_r` rotations and `n_t` translations.
fn top_level(n_r: [i32; 3], n_t: [i32; 3], searched_r: [bool; 3]) -> u32 {
    // Saturating products: a window of 1e20 m has 2^31 translations per axis.
    let roots_at = |level: u32| -> u64 {
        (0..3)
            .map(|i| (n_t[i] as u64).div_ceil(1 << level))
            .fold(1, u64::saturating_mul)
    };
    let rot_roots_at = |level: u32| -> u64 {
        let r = level.saturating_sub(ROTATION_LAG);
        (0..3)
            .filter(|&i| searched_r[i])
            .map(|i| (n_r[i] as u64).div_ceil(1 << r))
            .fold(1, u64::saturating_mul)
    };
    let mut top = 0u32;
    while (roots_at(top) > ROOT_TRANSLATIONS
        || roots_at(top).saturating_mul(rot_roots_at(top)) > ROOT_NODES)
        && top < 16
    {
        top += 1;
    }
    top
}

/// Refuses a region whose roots at the coarsest level (at most 16) do not fit in memory
/// (a window of 1e9 m: the roots are listed before they are bounded).
fn check_roots(n_r: [i32; 3], n_t: [i32; 3], searched_r: [bool; 3], top: u32) -> Result<()> {
    let r = top.saturating_sub(ROTATION_LAG);
    let blocks = |n: i32, shift: u32| (n.max(1) as f64 / (1u64 << shift) as f64).ceil();
    let roots: f64 = (0..3).map(|i| blocks(n_t[i], top)).product::<f64>()
        * (0..3)
            .filter(|&i| searched_r[i])
            .map(|i| blocks(n_r[i], r))
            .product::<f64>();
    // A root is a block (rotation, translation and bound: 32 bytes) and its listing.
    crate::limits::check_memory(
        || format!("the exact search's {roots:.3e} root blocks"),
        roots * 64.0,
    )
}

/// The passes (see the module documentation): the best pose of each cluster, best first,
/// up to one more than [`EXACT_MAX_AMBIGUITY`], with the nodes bounded and passed per level.
fn passes(
    bnb: &Bnb,
    params: &SearchParams,
    n_levels: usize,
    budget: &Budget,
) -> (Vec<Scored>, Vec<usize>, Vec<usize>) {
    let l: &Lattice = bnb.lattice;
    let new_worker = || Worker::new(n_levels);
    let mut heads: Vec<Head> = Vec::new();
    let mut found: Vec<Scored> = Vec::new();
    let mut bounded = vec![0usize; n_levels];
    let mut passed = vec![0usize; n_levels];
    let mut floor = NO_SCORE;
    // One pass past the cap: a head beyond it says there are more than the cap.
    while found.len() <= EXACT_MAX_AMBIGUITY {
        let pass = Pass {
            bnb,
            heads: &heads,
            floor,
            best: AtomicI64::new(NO_SCORE),
            budget,
        };
        let workers = pass.run(&new_worker);
        for w in &workers {
            for lv in 0..n_levels {
                bounded[lv] += w.bounded[lv];
                passed[lv] += w.passed[lv];
            }
        }
        if budget.exhausted() {
            break;
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
    (found, bounded, passed)
}
