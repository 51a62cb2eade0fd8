//! The multi-resolution overlap search (thesis Algorithms 3, 5, 6; §6.4.2 Algorithm 8) and
//! the exhaustive reference search (Algorithm 7).
//!
//! Poses live on a lattice that refines with the levels. At level `l` the cell is
//! `resolution * 2^l` and the angular step `dθ = cell / R` (thesis (5.6)); a pose is
//! `t = t0 + i * cell` (integer `i` per axis) and `angle = angle0 + j * dθ`. Halving the
//! cell halves both steps, so a pose `(i, j)` at one level is `(2i, 2j)` at the next, and
//! its resampling (Algorithm 6: ±half a cell, ±dθ) is `(2i + {-1, 0, 1}, 2j + {-1, 0, 1})`.
//! Poses sharing a rotation are evaluated together: the scan's voxel centres are rotated
//! once, `floor((R c + t0) / cell)` is computed once, and every translation of the group
//! is an integer offset of those keys (§5.3.3): a chunk of translations per pass over the
//! scan ([`CellGrid`]), or, when they fill a box (the coarsest level of a global search),
//! the whole box at once as a correlation of rows ([`RowGrid`]). Groups run in parallel; every ordering
//! and tie is resolved by the pose indices, so the result is the same for any number of
//! threads.

use std::sync::OnceLock;
use std::time::Instant;

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::cells::CellGrid;
use super::dense::DenseGrid;
use super::params::{Dof, Locus, Region, SearchMode, SearchParams};
use super::rows::RowGrid;
use super::significance::significance;
use super::target::SearchTarget;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Pose, VoxelKey};
use crate::occupancy::{OccupancyList, Pyramid};

/// One pose of the lattice: rotation indices (yaw, pitch, roll) and translation indices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(super) struct Cand {
    pub(super) r: [i32; 3],
    pub(super) t: [i32; 3],
}

/// A scored pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// `T_target_source`.
    pub pose: Pose,
    /// Overlap (voxels) at the finest level.
    pub overlap: u64,
}

/// What one level of the search did.
#[derive(Debug, Clone, PartialEq)]
pub struct LevelReport {
    /// Level index (0 = finest).
    pub level: usize,
    /// Voxel edge at this level, metres.
    pub resolution: f64,
    /// Angular step at this level, radians.
    pub angular_step: f64,
    /// Scan voxels used at this level.
    pub scan_voxels: usize,
    /// Poses evaluated.
    pub evaluated: usize,
    /// Poses that passed `keep_ratio` of the best.
    pub passed: usize,
    /// Poses kept for the next level (after the cap).
    pub survivors: usize,
    /// The best overlap at this level.
    pub best_overlap: u64,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// The result of a global search.
#[derive(Debug, Clone, PartialEq)]
pub struct Alignment {
    /// The best pose `T_target_source`.
    pub pose: Pose,
    /// Its overlap `|L ∩ M|` at the finest level (voxels).
    pub overlap: u64,
    /// Its ranking score: `2 * overlap - conflicts` when the target knows free space (see
    /// [`SearchTarget`]), else `2 * overlap`; the searches maximise it.
    pub score: i64,
    /// Scan voxels at the finest level.
    pub scan_voxels: u64,
    /// `overlap / scan_voxels`.
    pub overlap_fraction: f64,
    /// z-score of the overlap under the hypergeometric model (5.4)-(5.5), with `V` the
    /// target's bounding volume in finest cells.
    pub significance: f64,
    /// Distinct solutions: clusters of finest-level poses scoring at least `keep_ratio` of
    /// the best, poses closer than `ambiguity_distance` / `ambiguity_angle` to a better one
    /// joining its cluster (1 = unique).
    pub ambiguity: usize,
    /// The best few poses (one per cluster, best first).
    pub candidates: Vec<Candidate>,
    /// Per-level counts and timings, coarsest first.
    pub levels: Vec<LevelReport>,
    /// Whether the survivor cap cut a level.
    pub guard_acted: bool,
    /// Poses evaluated over all levels (for the exact search: nodes bounded, leaves
    /// included; the count depends on the thread timing, the result does not).
    pub evaluated: usize,
    /// Wall time of the whole search, seconds.
    pub seconds: f64,
    /// Whether the result is guaranteed: the best pose of the finest lattice over the whole
    /// region, with `ambiguity` and `candidates` those of [`exhaustive_search`] (the exact
    /// search counts clusters up to [`super::EXACT_MAX_AMBIGUITY`]). Set by the exact search
    /// ([`super::SearchMode::Exact`]) and the exhaustive search; the multi-resolution
    /// search prunes heuristically and sets it false. Its resampling can also step a few
    /// cells or angular steps past the region's ends, outside this lattice (a global
    /// search's heading index past `2π / dθ`), and there score a little higher than the
    /// exact optimum.
    pub exact: bool,
}

/// Everything the lattice needs to turn indices into poses.
pub(super) struct Lattice {
    pub(super) t0: Vector3<f64>,
    pub(super) angle0: [f64; 3],
    pub(super) finest: f64,
    pub(super) range: f64,
    pub(super) searched_t: [bool; 3],
    pub(super) searched_r: [bool; 3],
}

impl Lattice {
    pub(super) fn cell(&self, level: usize) -> f64 {
        self.finest * (1u64 << level) as f64
    }

    pub(super) fn dtheta(&self, level: usize) -> f64 {
        self.cell(level) / self.range
    }

    fn angles(&self, c: &Cand, level: usize) -> [f64; 3] {
        let d = self.dtheta(level);
        [0, 1, 2].map(|i| self.angle0[i] + c.r[i] as f64 * d)
    }

    pub(super) fn pose(&self, c: &Cand, level: usize) -> Pose {
        let [yaw, pitch, roll] = self.angles(c, level);
        let cell = self.cell(level);
        let t = self.t0 + Vector3::new(c.t[0] as f64, c.t[1] as f64, c.t[2] as f64) * cell;
        Pose::from_xyz_ypr(t.x, t.y, t.z, yaw, pitch, roll)
    }

    /// Algorithm 6: the poses around `c` at the next finer level.
    fn children(&self, c: &Cand, out: &mut Vec<Cand>) {
        let span = |searched: bool| if searched { -1..=1 } else { 0..=0 };
        for a in span(self.searched_r[0]) {
            for b in span(self.searched_r[1]) {
                for g in span(self.searched_r[2]) {
                    for x in span(self.searched_t[0]) {
                        for y in span(self.searched_t[1]) {
                            for z in span(self.searched_t[2]) {
                                out.push(Cand {
                                    r: [2 * c.r[0] + a, 2 * c.r[1] + b, 2 * c.r[2] + g],
                                    t: [2 * c.t[0] + x, 2 * c.t[1] + y, 2 * c.t[2] + z],
                                });
                            }
                        }
                    }
                }
            }
        }
    }
}

/// The scan and the target prepared for searching.
pub(super) struct Problem<'a> {
    /// Scan voxel centres per level (sensor frame).
    pub(super) scan: Vec<Vec<Point3<f64>>>,
    /// Per level, built when first needed: the dense cells, or `None` when the box is too
    /// large (the hash table of `levels` and the free grid answer instead).
    cells: Vec<OnceLock<Option<CellGrid>>>,
    /// Per level, built when first needed: the cells as rows for scoring boxes of
    /// translations.
    rows: Vec<OnceLock<Option<RowGrid>>>,
    levels: Vec<&'a OccupancyList>,
    pub(super) free: Vec<Option<&'a DenseGrid>>,
    pub(super) lattice: Lattice,
    /// Finest-level target voxels and bounding volume in cells.
    map_voxels: u64,
    map_cells: f64,
}

fn check(params: &SearchParams) -> Result<()> {
    let bad = |what: &str| Err(Error::InvalidArgument(what.to_string()));
    if !(params.resolution.is_finite() && params.resolution > 0.0) {
        return bad("search resolution must be > 0 m");
    }
    if params.levels > 12 {
        return bad("search levels must be 0 (automatic) to 12");
    }
    if !(params.keep_ratio > 0.0 && params.keep_ratio <= 1.0) {
        return bad("keep_ratio must be in (0, 1]");
    }
    if params.max_scan_voxels == 0 {
        return bad("max_scan_voxels must be positive");
    }
    if !(params.max_range.is_finite() && params.max_range > 0.0) {
        return bad("max_range must be > 0 m");
    }
    if let Region::Window { xy, z, yaw } = params.region {
        if [xy, z, yaw].iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return bad("window half-widths must be >= 0");
        }
    }
    if let Region::Locus(l) = params.region {
        let values = [
            l.center[0],
            l.center[1],
            l.center[2],
            l.radius,
            l.phase,
            l.slack,
        ];
        if values.iter().any(|v| !v.is_finite()) || l.radius < 0.0 || l.slack < 0.0 {
            return bad("a locus needs a finite centre and phase, radius >= 0 and slack >= 0");
        }
    }
    if let Dof::SixDof { max_tilt } = params.dof {
        if !(max_tilt.is_finite() && max_tilt >= 0.0) {
            return bad("max_tilt must be >= 0");
        }
    }
    Ok(())
}

/// Evenly spaced voxel centres (at most `max`) of a list, in key order.
fn centres(list: &OccupancyList, max: usize) -> Vec<Point3<f64>> {
    let sorted = list.sorted();
    let step = sorted.len().div_ceil(max).max(1);
    sorted
        .iter()
        .step_by(step)
        .map(|(k, _)| list.center(*k))
        .collect()
}

pub(super) fn prepare<'a>(
    source: &PointCloud,
    target: &'a SearchTarget,
    params: &SearchParams,
) -> Result<Problem<'a>> {
    check(params)?;
    let pyramid = &target.pyramid;
    let res = pyramid.base().resolution();
    let scan_cloud = source.range_band(0.0, params.max_range);
    if scan_cloud.is_empty() {
        return Err(Error::InvalidArgument(format!(
            "the source has no point within {} m of its sensor",
            params.max_range
        )));
    }
    let bbox = pyramid
        .base()
        .stats()
        .bbox
        .ok_or_else(|| Error::InvalidArgument("the target is empty".into()))?;
    let base_scan = OccupancyList::from_cloud(&scan_cloud, res)?;
    let mut scan = Vec::with_capacity(pyramid.levels());
    for level in 0..pyramid.levels() {
        let l = base_scan.downsample(1 << level)?;
        scan.push(centres(&l, params.max_scan_voxels));
    }
    let reach = scan_cloud.stats().range.map_or(params.max_range, |r| r.max);
    let range = reach.clamp(res, params.max_range);
    let prior = &params.prior;
    let pt = prior.translation();
    let (yaw_p, pitch_p, roll_p) = prior.yaw_pitch_roll();
    let tilt = match params.dof {
        Dof::SixDof { max_tilt } => Some(max_tilt),
        _ => None,
    };
    // A locus fixes the height (beacon height on a flat floor, thesis §6.3.3).
    let search_z = !matches!(params.dof, Dof::XyYaw) && !matches!(params.region, Region::Locus(_));
    let (t0, angle0_yaw) = match params.region {
        Region::Global => (
            Vector3::new(
                bbox.min.x,
                bbox.min.y,
                if search_z { bbox.min.z } else { pt.z },
            ),
            0.0,
        ),
        Region::Window { xy, z, yaw } => (
            Vector3::new(pt.x - xy, pt.y - xy, if search_z { pt.z - z } else { pt.z }),
            yaw_p - yaw,
        ),
        // The lattice is anchored at the locus's centre: a fixed position (6.2) is a
        // lattice point at every level.
        Region::Locus(l) => (Vector3::new(l.center[0], l.center[1], l.center[2]), 0.0),
    };
    let lattice = Lattice {
        t0,
        angle0: [
            angle0_yaw,
            pitch_p - tilt.unwrap_or(0.0),
            roll_p - tilt.unwrap_or(0.0),
        ],
        finest: res,
        range,
        searched_t: [true, true, search_z],
        searched_r: [true, tilt.is_some(), tilt.is_some()],
    };
    let e = bbox.extent();
    Ok(Problem {
        scan,
        cells: (0..pyramid.levels()).map(|_| OnceLock::new()).collect(),
        rows: (0..pyramid.levels()).map(|_| OnceLock::new()).collect(),
        levels: (0..pyramid.levels()).map(|l| pyramid.level(l)).collect(),
        free: target.free.iter().map(Option::as_ref).collect(),
        lattice,
        map_voxels: pyramid.base().len() as u64,
        map_cells: (e.x / res).max(1.0) * (e.y / res).max(1.0) * (e.z / res).max(1.0),
    })
}

/// The level a locus search starts at (cells 4x the finest).
const LOCUS_START_LEVEL: usize = 2;

/// The share of the best score a locus search keeps at its coarse levels (at most
/// [`SearchParams::keep_ratio`]; the finest level and the ambiguity test use that). A
/// locus has one free parameter, so keeping more poses is cheap, and 80 % lost the true
/// heading of a robot sharing 15 % of its scan with the map (found 1.25° off, which the
/// rest of its robot inherited); 50 % kept it.
const LOCUS_KEEP_RATIO: f64 = 0.5;

/// A scored pose: ranking score `2 * hits - conflicts`, the hits, the pose.
pub(super) type Scored = (i64, u32, Cand);

/// Scores every candidate, in candidate order.
fn evaluate(problem: &Problem, cands: &[Cand], level: usize) -> Vec<Scored> {
    let l = &problem.lattice;
    let cell = l.cell(level);
    let scan = &problem.scan[level];
    let cells = problem.cells[level]
        .get_or_init(|| CellGrid::new(problem.levels[level], problem.free[level]))
        .as_ref();
    let map = problem.levels[level];
    let free = problem.free[level];
    // Group by rotation (sorted: deterministic). Every caller's candidates come sorted.
    debug_assert!(cands.is_sorted(), "candidates must come sorted");
    let groups: Vec<([i32; 3], Vec<[i32; 3]>)> = cands
        .chunk_by(|a, b| a.r == b.r)
        .map(|g| (g[0].r, g.iter().map(|c| c.t).collect()))
        .collect();
    let boxes: Vec<Option<TranslationBox>> = groups.iter().map(|(_, ts)| dense_box(ts)).collect();
    let rows = match (cells, boxes.iter().any(Option::is_some)) {
        (Some(c), true) => problem.rows[level].get_or_init(|| RowGrid::new(c)).as_ref(),
        _ => None,
    };
    let scored: Vec<Vec<Scored>> = groups
        .par_iter()
        .zip(&boxes)
        .map(|((r, ts), bx)| {
            let probe = Cand {
                r: *r,
                t: [0, 0, 0],
            };
            let [yaw, pitch, roll] = l.angles(&probe, level);
            let rot = crate::geometry::rotation_from_yaw_pitch_roll(yaw, pitch, roll);
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
                .map(|(t, (hits, conflicts))| {
                    (
                        2 * hits as i64 - conflicts as i64,
                        hits,
                        Cand { r: *r, t: *t },
                    )
                })
                .collect()
        })
        .collect();
    scored.into_iter().flatten().collect()
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

/// The cell of a scan voxel centre `c` rotated by `rot` and moved by `t0`: the one formula
/// every search uses, so that they score a pose bit for bit alike.
#[inline]
pub(super) fn key_of(
    rot: &nalgebra::Rotation3<f64>,
    c: &Point3<f64>,
    t0: Vector3<f64>,
    cell: f64,
) -> [i64; 3] {
    let p = rot * c.coords + t0;
    [
        (p.x / cell).floor() as i64,
        (p.y / cell).floor() as i64,
        (p.z / cell).floor() as i64,
    ]
}

/// The lowest score that survives: `keep_ratio` of the best for a positive best, the same
/// margin below it otherwise.
pub(super) fn threshold(best: i64, keep_ratio: f64) -> i64 {
    best - ((1.0 - keep_ratio) * best.abs() as f64).floor() as i64
}

/// Evaluates the candidates of a level and ranks the ones within `keep_ratio` of the best:
/// those poses, best first, the best pose's hits, and how many poses were evaluated.
fn score_level(
    problem: &Problem,
    cands: &[Cand],
    level: usize,
    keep_ratio: f64,
) -> (Vec<Scored>, u32, usize) {
    let mut scored = evaluate(problem, cands, level);
    let evaluated = scored.len();
    let best = scored.iter().map(|s| s.0).max().unwrap_or(0);
    let cut = threshold(best, keep_ratio);
    // Only the poses that pass are ranked: at the coarsest level they are a few hundred
    // of a few hundred thousand.
    scored.retain(|s| s.0 >= cut);
    rank(&mut scored);
    let best_hits = scored.first().map_or(0, |s| s.1);
    (scored, best_hits, evaluated)
}

/// Best first; ties by lattice index (deterministic).
pub(super) fn rank(scored: &mut [Scored]) {
    scored.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.2.cmp(&b.2)));
}

fn angle_between(a: &Pose, b: &Pose) -> f64 {
    (a.rotation().inverse() * b.rotation()).angle()
}

pub(super) fn finish(
    problem: &Problem,
    params: &SearchParams,
    scored: &[Scored],
    levels: Vec<LevelReport>,
    start: Instant,
) -> Alignment {
    let l = &problem.lattice;
    let (best_score, best_hits, best) = scored[0];
    let cut = threshold(best_score, params.keep_ratio);
    // Cluster the finest-level poses within keep_ratio of the best.
    let mut heads: Vec<Candidate> = Vec::new();
    for (_, hits, c) in scored.iter().take_while(|(s, _, _)| *s >= cut) {
        let pose = l.pose(c, 0);
        let near = heads.iter().any(|h| {
            (h.pose.translation() - pose.translation()).norm() <= params.ambiguity_distance
                && angle_between(&h.pose, &pose) <= params.ambiguity_angle
        });
        if !near {
            heads.push(Candidate {
                pose,
                overlap: *hits as u64,
            });
        }
    }
    let n = problem.scan[0].len() as u64;
    let overlap = best_hits as u64;
    let ambiguity = heads.len().max(1);
    heads.truncate(10);
    if heads.is_empty() {
        heads.push(Candidate {
            pose: l.pose(&best, 0),
            overlap,
        });
    }
    let evaluated = levels.iter().map(|r| r.evaluated).sum();
    let guard_acted = levels.iter().any(|r| r.survivors < r.passed);
    Alignment {
        pose: l.pose(&best, 0),
        overlap,
        score: best_score,
        scan_voxels: n,
        overlap_fraction: if n > 0 {
            overlap as f64 / n as f64
        } else {
            0.0
        },
        significance: significance(overlap, n, problem.map_voxels, problem.map_cells),
        ambiguity,
        candidates: heads,
        levels,
        guard_acted,
        evaluated,
        seconds: start.elapsed().as_secs_f64(),
        exact: false,
    }
}

pub(super) fn level_report(
    problem: &Problem,
    level: usize,
    evaluated: usize,
    passed: usize,
    survivors: usize,
    best: u32,
    t: Instant,
) -> LevelReport {
    LevelReport {
        level,
        resolution: problem.lattice.cell(level),
        angular_step: problem.lattice.dtheta(level),
        scan_voxels: problem.scan[level].len(),
        evaluated,
        passed,
        survivors,
        best_overlap: best as u64,
        seconds: t.elapsed().as_secs_f64(),
    }
}

/// Global alignment with no initial guess: the multi-resolution search of a `source` scan
/// (sensor frame, its points) against a target. Returns `T_target_source`.
///
/// The target's pyramid fixes the finest resolution and the number of levels.
pub fn global_search(
    source: &PointCloud,
    target: &SearchTarget,
    params: &SearchParams,
) -> Result<Alignment> {
    if params.search == SearchMode::Exact && !matches!(params.region, Region::Locus(_)) {
        return super::bnb::exact_search(source, target, params);
    }
    let start = Instant::now();
    let problem = prepare(source, target, params)?;
    let top = match params.region {
        // One parameter is cheap to sample finely: a locus search starts at the level of
        // 4-cell voxels, where a pose's score already tells true from false (the coarsest
        // levels blur a nearby robot's surroundings into a few cells).
        Region::Locus(_) => (target.pyramid.levels() - 1).min(LOCUS_START_LEVEL),
        _ => target.pyramid.levels() - 1,
    };
    let mut cands = initial_candidates(&problem, params, &target.pyramid, top);
    let mut reports = Vec::new();
    for level in (0..=top).rev() {
        let t = Instant::now();
        let keep = match params.region {
            Region::Locus(_) if level > 0 => params.keep_ratio.min(LOCUS_KEEP_RATIO),
            _ => params.keep_ratio,
        };
        let (scored, best_hits, evaluated) = score_level(&problem, &cands, level, keep);
        let passed = scored.len();
        if best_hits == 0 {
            reports.push(level_report(&problem, level, evaluated, passed, 0, 0, t));
            return Ok(no_overlap(&problem, reports, start));
        }
        if level == 0 {
            reports.push(level_report(
                &problem, level, evaluated, passed, passed, best_hits, t,
            ));
            return Ok(finish(&problem, params, &scored, reports, start));
        }
        let survivors = passed.min(params.survivor_cap());
        reports.push(level_report(
            &problem, level, evaluated, passed, survivors, best_hits, t,
        ));
        let mut next = Vec::with_capacity(survivors * 27);
        for (_, _, c) in &scored[..survivors] {
            problem.lattice.children(c, &mut next);
        }
        next.sort_unstable();
        next.dedup();
        cands = next;
    }
    unreachable!("the loop returns at level 0")
}

pub(super) fn no_overlap(problem: &Problem, levels: Vec<LevelReport>, start: Instant) -> Alignment {
    let evaluated = levels.iter().map(|r| r.evaluated).sum();
    Alignment {
        pose: Pose::identity(),
        overlap: 0,
        score: 0,
        scan_voxels: problem.scan[0].len() as u64,
        overlap_fraction: 0.0,
        significance: 0.0,
        ambiguity: 0,
        candidates: Vec::new(),
        levels,
        guard_acted: false,
        evaluated,
        seconds: start.elapsed().as_secs_f64(),
        exact: false,
    }
}

/// The uniform start over the region at `level`.
fn initial_candidates(
    problem: &Problem,
    params: &SearchParams,
    target: &Pyramid,
    level: usize,
) -> Vec<Cand> {
    let l = &problem.lattice;
    let Some(([nyaw, ntilt, _], [nx, ny, nz])) = region_counts(problem, params, target, level)
    else {
        let dth = l.dtheta(level);
        let count = |extent: f64, step: f64| ((extent / step).ceil() as i32).max(0) + 1;
        let ntilt = match params.dof {
            Dof::SixDof { max_tilt } => count(2.0 * max_tilt, dth),
            _ => 1,
        };
        let Region::Locus(locus) = params.region else {
            unreachable!("region_counts covers the other regions")
        };
        return locus_candidates(l, &locus, level, ntilt);
    };
    let mut out = Vec::with_capacity((nx * ny * nz * nyaw * ntilt * ntilt).max(0) as usize);
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
    out
}

/// The lattice indices of the region at `level`: rotation counts (yaw, pitch, roll) and
/// translation counts (x, y, z); indices run from 0 to the count. `None` for a locus.
pub(super) fn region_counts(
    problem: &Problem,
    params: &SearchParams,
    target: &Pyramid,
    level: usize,
) -> Option<([i32; 3], [i32; 3])> {
    let l = &problem.lattice;
    let cell = l.cell(level);
    let dth = l.dtheta(level);
    let count = |extent: f64, step: f64| ((extent / step).ceil() as i32).max(0) + 1;
    let ext = target
        .base()
        .stats()
        .bbox
        .map_or(Vector3::zeros(), |b| b.extent());
    let ntilt = match params.dof {
        Dof::SixDof { max_tilt } => count(2.0 * max_tilt, dth),
        _ => 1,
    };
    let (nx, ny, nz, nyaw) = match params.region {
        Region::Global => (
            count(ext.x, cell),
            count(ext.y, cell),
            count(ext.z, cell),
            ((std::f64::consts::TAU / dth).ceil() as i32).max(1),
        ),
        Region::Window { xy, z, yaw } => (
            count(2.0 * xy, cell),
            count(2.0 * xy, cell),
            count(2.0 * z, cell),
            count(2.0 * yaw, dth),
        ),
        Region::Locus(_) => return None,
    };
    let nz = if l.searched_t[2] { nz } else { 1 };
    Some(([nyaw, ntilt, ntilt], [nx, ny, nz]))
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

/// Algorithm 7: every lattice pose of the region at the finest level of `target`, the slow
/// and sure reference for testing [`global_search`].
pub fn exhaustive_search(
    source: &PointCloud,
    target: &SearchTarget,
    params: &SearchParams,
) -> Result<Alignment> {
    let start = Instant::now();
    let problem = prepare(source, target, params)?;
    let t = Instant::now();
    let cands = initial_candidates(&problem, params, &target.pyramid, 0);
    let (scored, best_hits, evaluated) = score_level(&problem, &cands, 0, params.keep_ratio);
    let passed = scored.len();
    let reports = vec![level_report(
        &problem, 0, evaluated, passed, passed, best_hits, t,
    )];
    if best_hits == 0 {
        return Ok(no_overlap(&problem, reports, start));
    }
    let mut a = finish(&problem, params, &scored, reports, start);
    a.exact = true;
    Ok(a)
}
