//! Scoring the candidate poses of one lattice level (thesis §5.3.3), and the uniform
//! start over a region: what the multi-resolution and the exhaustive searches share.
//!
//! Poses sharing a rotation are evaluated together: the scan's voxel centres are rotated
//! once, `floor((R c + t0) / cell)` is computed once, and every translation of the group
//! is an integer offset of those keys (§5.3.3): a chunk of translations per pass over the
//! scan ([`CellGrid`]), or, when they fill a box (the coarsest level of a global search),
//! the whole box at once as a correlation of rows ([`RowGrid`]). Groups run in parallel;
//! every ordering and tie is resolved by the pose indices, so the result is the same for
//! any number of threads.

use nalgebra::{Point3, Rotation3};
use rayon::prelude::*;

use super::lattice::{key_of, rank, region_counts, threshold, Cand, Lattice, Problem, Scored};
use super::params::{Dof, Locus, Region, SearchParams};
use super::score::DenseGrid;
use super::target::SearchCells;
use crate::error::Result;
use crate::geometry::VoxelKey;
use crate::occupancy::{OccupancyList, Pyramid};

/// Scores every candidate, in candidate order.
pub(super) fn evaluate(problem: &Problem, cands: &[Cand], level: usize) -> Vec<Scored> {
    if cands.is_empty() {
        // Nothing to score: no grid is made (nor a part counted against the level).
        return Vec::new();
    }
    let l = &problem.lattice;
    let cell = l.cell(level);
    let scan = &problem.scan[level];
    let map = problem.levels[level];
    let free = problem.free[level];
    // Group by rotation (sorted: deterministic). Every caller's candidates come sorted.
    debug_assert!(cands.is_sorted(), "candidates must come sorted");
    let groups: Vec<([i32; 3], Vec<[i32; 3]>)> = cands
        .chunk_by(|a, b| a.r == b.r)
        .map(|g| (g[0].r, g.iter().map(|c| c.t).collect()))
        .collect();
    let boxes: Vec<Option<TranslationBox>> = groups.iter().map(|(_, ts)| dense_box(ts)).collect();
    // The lookups the row grid would replace: every boxed group's poses, each voxel.
    let boxed_lookups: u64 = groups
        .iter()
        .zip(&boxes)
        .filter(|(_, b)| b.is_some())
        .map(|((_, ts), _)| (ts.len() * scan.len()) as u64)
        .sum();
    let rows = match boxed_lookups {
        0 => None,
        n => problem.target.rows(level, n),
    };
    let cells = match rows {
        Some(_) => problem.target.cells(level).map(SearchCells::Whole),
        None => problem
            .target
            .cells_reaching(level, reach(l, scan, &groups, level)),
    };
    let cells = cells.as_deref();
    let scored: Vec<Vec<Scored>> = groups
        .par_iter()
        .zip(&boxes)
        .map(|((r, ts), bx)| {
            let rot = group_rotation(l, *r, level);
            let base: Vec<[i64; 3]> = scan.iter().map(|c| key_of(&rot, c, l.t0, cell)).collect();
            let by_box = rows
                .zip(bx.as_ref())
                .and_then(|(g, b)| Some((g.score_box(&base, b.lo, b.n)?, b.lo)));
            let counts: Vec<(u32, u32)> = match (by_box, cells) {
                (Some((scores, lo)), _) => ts
                    .iter()
                    .map(|t| scores.get([0, 1, 2].map(|i| (t[i] as i64 - lo[i]) as usize)))
                    .collect(),
                (None, Some(g)) => g.score(&base, ts),
                (None, None) => ts
                    .iter()
                    .map(|t| count_hashed(&base, *t, map, free))
                    .collect(),
            };
            ts.iter()
                .zip(counts)
                .map(|(t, (hits, conflicts))| Scored {
                    score: 2 * hits as i64 - conflicts as i64,
                    hits,
                    cand: Cand { r: *r, t: *t },
                })
                .collect()
        })
        .collect();
    scored.into_iter().flatten().collect()
}

/// The rotation of the candidates with rotation index `r` at `level`.
fn group_rotation(l: &Lattice, r: [i32; 3], level: usize) -> Rotation3<f64> {
    let [yaw, pitch, roll] = l.angles(&Cand { r, t: [0, 0, 0] }, level);
    crate::geometry::rotation_from_yaw_pitch_roll(yaw, pitch, roll)
}

/// A key box holding every key the groups look up at `level`: per group, the scan's
/// bounding box turned by the group's rotation (its eight corners) and moved by the
/// group's translations, with a cell to spare on each side for rounding.
fn reach(
    l: &Lattice,
    scan: &[Point3<f64>],
    groups: &[([i32; 3], Vec<[i32; 3]>)],
    level: usize,
) -> ([i64; 3], [i64; 3]) {
    if scan.is_empty() {
        return ([0; 3], [0; 3]);
    }
    let cell = l.cell(level);
    let mut smin = Point3::from([f64::INFINITY; 3]);
    let mut smax = Point3::from([f64::NEG_INFINITY; 3]);
    for p in scan {
        smin = smin.inf(p);
        smax = smax.sup(p);
    }
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for (r, ts) in groups {
        let rot = group_rotation(l, *r, level);
        let mut kmin = [i64::MAX; 3];
        let mut kmax = [i64::MIN; 3];
        for corner in 0..8 {
            let c = Point3::new(
                if corner & 1 == 0 { smin.x } else { smax.x },
                if corner & 2 == 0 { smin.y } else { smax.y },
                if corner & 4 == 0 { smin.z } else { smax.z },
            );
            let k = key_of(&rot, &c, l.t0, cell);
            for i in 0..3 {
                kmin[i] = kmin[i].min(k[i]);
                kmax[i] = kmax[i].max(k[i]);
            }
        }
        for t in ts {
            for i in 0..3 {
                lo[i] = lo[i].min(kmin[i] - 1 + t[i] as i64);
                hi[i] = hi[i].max(kmax[i] + 1 + t[i] as i64);
            }
        }
    }
    (lo, hi)
}

/// The translations of a rotation group as a box: its first corner and size.
struct TranslationBox {
    lo: [i64; 3],
    n: [usize; 3],
}

/// The bounding box of a group's translations when scoring the whole box beats scoring them
/// one by one: enough of them ([`MIN_BOX_POSES`]), filling at least half the box.
fn dense_box(ts: &[[i32; 3]]) -> Option<TranslationBox> {
    if ts.len() < MIN_BOX_POSES {
        return None;
    }
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for t in ts {
        for i in 0..3 {
            lo[i] = lo[i].min(t[i] as i64);
            hi[i] = hi[i].max(t[i] as i64);
        }
    }
    let n = [0, 1, 2].map(|i| (hi[i] - lo[i] + 1) as usize);
    (n[0] * n[1] * n[2] <= 2 * ts.len()).then_some(TranslationBox { lo, n })
}

/// The fewest poses of one rotation scored as a box.
const MIN_BOX_POSES: usize = 64;

/// Hits and conflicts of the keys moved by `t`, looked up in the hash table (for levels too
/// large for [`CellGrid`]).
fn count_hashed(
    base: &[[i64; 3]],
    t: [i32; 3],
    map: &OccupancyList,
    free: Option<&DenseGrid>,
) -> (u32, u32) {
    let (mut hits, mut conflicts) = (0u32, 0u32);
    let key = |v: i64| i32::try_from(v).ok();
    for b in base {
        let (x, y, z) = (b[0] + t[0] as i64, b[1] + t[1] as i64, b[2] + t[2] as i64);
        let occupied = match (key(x), key(y), key(z)) {
            (Some(x), Some(y), Some(z)) => map.count(VoxelKey::new(x, y, z)) > 0,
            _ => false,
        };
        if occupied {
            hits += 1;
        } else if free.is_some_and(|f| f.contains(x, y, z)) {
            conflicts += 1;
        }
    }
    (hits, conflicts)
}

/// What scoring one level gives.
pub(super) struct LevelScores {
    /// The poses within `keep_ratio` of the best, best first.
    pub(super) passed: Vec<Scored>,
    /// Up to `hypotheses` distinct poses below the cut, best first (see [`distinct_heads`]).
    pub(super) heads: Vec<Scored>,
    /// The best pose's hits.
    pub(super) best_hits: u32,
    /// Poses evaluated.
    pub(super) evaluated: usize,
}

/// Evaluates the candidates of a level and ranks the ones within `keep_ratio` of the best;
/// also keeps up to `hypotheses` distinct poses below the cut ([`distinct_heads`]).
pub(super) fn score_level(
    problem: &Problem,
    params: &SearchParams,
    cands: &[Cand],
    level: usize,
    keep_ratio: f64,
    hypotheses: usize,
) -> LevelScores {
    let mut scored = evaluate(problem, cands, level);
    let evaluated = scored.len();
    let best = scored.iter().map(|s| s.score).max().unwrap_or(0);
    let cut = threshold(best, keep_ratio);
    // Only the poses that pass are ranked: at the coarsest level they are a few hundred
    // of a few hundred thousand.
    let (mut passed, below): (Vec<Scored>, Vec<Scored>) =
        scored.drain(..).partition(|s| s.score >= cut);
    rank(&mut passed);
    let best_hits = passed.first().map_or(0, |s| s.hits);
    let heads = match passed.first() {
        Some(b) if hypotheses > 0 => distinct_heads(problem, params, b, below, level, hypotheses),
        _ => Vec::new(),
    };
    LevelScores {
        passed,
        heads,
        best_hits,
        evaluated,
    }
}

/// How many of a level's best poses below the cut are looked at for distinct hypotheses.
const HEAD_POOL: usize = 4096;

/// Up to `k` poses of `pool` with a positive score, best first, each farther than the
/// level's distinctness from `best` and from every earlier one: `ambiguity_distance` or two
/// cells, `ambiguity_angle` or two angular steps, whichever is larger. Greedy in score
/// order over the best [`HEAD_POOL`] of the pool.
fn distinct_heads(
    problem: &Problem,
    params: &SearchParams,
    best: &Scored,
    mut pool: Vec<Scored>,
    level: usize,
    k: usize,
) -> Vec<Scored> {
    pool.retain(|s| s.score > 0);
    if pool.len() > HEAD_POOL {
        pool.select_nth_unstable_by(HEAD_POOL - 1, |a, b| {
            b.score.cmp(&a.score).then(a.cand.cmp(&b.cand))
        });
        pool.truncate(HEAD_POOL);
    }
    rank(&mut pool);
    let l = &problem.lattice;
    let dist = params.ambiguity_distance.max(2.0 * l.cell(level));
    let angle = params.ambiguity_angle.max(2.0 * l.dtheta(level));
    let far = |a: &crate::geometry::Pose, b: &crate::geometry::Pose| {
        (a.translation() - b.translation()).norm() > dist
            || a.rotation().angle_to(&b.rotation()) > angle
    };
    let mut taken = vec![l.pose(&best.cand, level)];
    let mut heads = Vec::new();
    for s in pool {
        let p = l.pose(&s.cand, level);
        if taken.iter().all(|t| far(t, &p)) {
            taken.push(p);
            heads.push(s);
            if heads.len() == k {
                break;
            }
        }
    }
    heads
}

/// Memory per pose of a level, bytes: the candidate (24), its translation in its
/// rotation group (12), its score (40) and the flattened scores (40), rounded up.
const BYTES_PER_POSE: f64 = 128.0;

/// The uniform start over the region at `level`; [`crate::Error::TooLarge`] when its
/// memory estimate exceeds [`crate::limits::MAX_ESTIMATE_BYTES`] (a window of 1e5 m, a
/// tilt range of 1e9 degrees), before anything is allocated.
pub(super) fn initial_candidates(
    problem: &Problem,
    params: &SearchParams,
    target: &Pyramid,
    level: usize,
) -> Result<Vec<Cand>> {
    let l = &problem.lattice;
    let dth = l.dtheta(level);
    let count = |extent: f64, step: f64| ((extent / step).ceil() as i32).max(0).saturating_add(1);
    let Some(([nyaw, ntilt, _], [nx, ny, nz])) = region_counts(problem, params, target, level)
    else {
        let ntilt = match params.dof {
            Dof::SixDof { max_tilt } => count(2.0 * max_tilt, dth),
            _ => 1,
        };
        let Region::Locus(locus) = params.region else {
            unreachable!("region_counts covers the other regions")
        };
        let cell = l.cell(level);
        let k = 2.0 * (locus.slack / cell).round() + 1.0;
        let kz = if l.searched_t[2] { k } else { 1.0 };
        let poses = locus.samples(cell, dth) as f64 * k * k * kz * (ntilt as f64).powi(2);
        check_start(poses, level, l.cell(level))?;
        return Ok(locus_candidates(l, &locus, level, ntilt));
    };
    let poses = [nx, ny, nz, nyaw, ntilt, ntilt]
        .iter()
        .map(|&n| n.max(0) as f64)
        .product::<f64>();
    check_start(poses, level, l.cell(level))?;
    let mut out = Vec::with_capacity(poses as usize);
    for a in 0..nyaw {
        for b in 0..ntilt {
            for g in 0..ntilt {
                for x in 0..nx {
                    for y in 0..ny {
                        for z in 0..nz {
                            out.push(Cand {
                                r: [a, b, g],
                                t: [x, y, z],
                            });
                        }
                    }
                }
            }
        }
    }
    Ok(out)
}

/// Refuses a uniform start of `poses` poses whose memory estimate is over the limit.
fn check_start(poses: f64, level: usize, cell: f64) -> Result<()> {
    crate::limits::check_memory(
        || {
            format!(
                "the search's uniform start ({poses:.3e} poses at level {level}, {cell} m \
                 cells; a smaller window, tilt range or target, or more levels, ask for fewer)"
            )
        },
        poses * BYTES_PER_POSE,
    )
}

/// The start of a locus search at `level`: the lattice poses nearest to samples of the
/// locus (every `t` step of the level's angular step, or finer along a wide circle), with
/// `slack` cells around them in x, y and z, and every tilt index.
fn locus_candidates(l: &Lattice, locus: &Locus, level: usize, ntilt: i32) -> Vec<Cand> {
    let cell = l.cell(level);
    let dth = l.dtheta(level);
    let k = locus.slack_cells(cell) as i32;
    let kz = if l.searched_t[2] { k } else { 0 };
    let n = locus.samples(cell, dth);
    let mut out = Vec::new();
    for s in 0..n {
        let t = s as f64 * std::f64::consts::TAU / n as f64;
        let p = locus.pose_at(t).translation();
        let index = |v: f64, o: f64| ((v - o) / cell).round() as i32;
        let yaw = ((t - l.angle0[0]) / dth).round() as i32;
        let (ix, iy) = (index(p.x, l.t0.x), index(p.y, l.t0.y));
        let iz = if l.searched_t[2] {
            index(p.z, l.t0.z)
        } else {
            0
        };
        for b in 0..ntilt {
            for g in 0..ntilt {
                for dx in -k..=k {
                    for dy in -k..=k {
                        for dz in -kz..=kz {
                            out.push(Cand {
                                r: [yaw, b, g],
                                t: [ix + dx, iy + dy, iz + dz],
                            });
                        }
                    }
                }
            }
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}
