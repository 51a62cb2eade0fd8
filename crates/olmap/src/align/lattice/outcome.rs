//! What a search returns ([`Alignment`], [`Candidate`], [`LevelReport`]) and how the scored
//! poses become one: the survival threshold, the ranking, the ambiguity clusters.

use std::time::Instant;

use super::{Cand, Problem};
use crate::align::params::SearchParams;
use crate::align::significance::significance;
use crate::geometry::Pose;

/// A scored pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// `T_target_source`.
    pub pose: Pose,
    /// Overlap (voxels) at the finest level.
    pub overlap: u64,
    /// Ranking score at the finest level (see [`Alignment::score`]).
    pub score: i64,
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
    /// [`crate::align::SearchTarget`]), else `2 * overlap`; the searches maximise it.
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
    /// The best solution *distinct* from the best (farther than `ambiguity_distance` or
    /// `ambiguity_angle`: beyond the refinement's reach), whatever its score; `None` when no
    /// distinct pose with a positive score was scored at the finest level. The
    /// multi-resolution search carries the best few distinct hypotheses of every level down
    /// to the finest (see [`crate::align::SearchParams::distinct_hypotheses`]), so the
    /// runner-up is measured even when it falls below `keep_ratio` of the best; the exact
    /// search only knows the runner-ups within `keep_ratio`.
    pub runner_up: Option<Candidate>,
    /// Half the range, along target x, y, z (metres) and heading (radians), of the
    /// finest-level poses scoring at least `keep_ratio` of the best, around the best: how far
    /// near-best solutions spread along each axis (a corridor spreads along its length).
    pub spread: [f64; 4],
    /// Scan voxels at the finest level that land where the target saw through (0 when the
    /// target knows no free space): `2 * overlap - score`.
    pub conflicts: u64,
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
    /// region, with `ambiguity` and `candidates` those of [`crate::align::exhaustive_search`] (the exact
    /// search lists clusters up to [`crate::align::EXACT_MAX_AMBIGUITY`] and counts one more
    /// when there are more). Set by the exact search
    /// ([`crate::align::SearchMode::Exact`]) and the exhaustive search; the multi-resolution
    /// search prunes heuristically and sets it false. Its resampling can also step a few
    /// cells or angular steps past the region's ends, outside this lattice (a global
    /// search's heading index past `2π / dθ`), and there score a little higher than the
    /// exact optimum.
    pub exact: bool,
}

impl Alignment {
    /// The runner-up's score as a fraction of the best's ([`Alignment::runner_up`]; 0 when
    /// there is none or the best does not score above 0).
    pub fn runner_up_ratio(&self) -> f64 {
        match &self.runner_up {
            Some(u) if self.score > 0 => (u.score as f64 / self.score as f64).max(0.0),
            _ => 0.0,
        }
    }
}

/// A scored pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Scored {
    /// The ranking score `2 * hits - conflicts`.
    pub(crate) score: i64,
    /// Scan voxels landing in occupied cells.
    pub(crate) hits: u32,
    /// The pose.
    pub(crate) cand: Cand,
}

/// The most candidates (cluster heads) an [`Alignment`] lists. A global verification
/// screens every listed head beyond its refined hypotheses' reach
/// ([`crate::align::verify::unverified_look_alikes`]) and doubts a match with more heads
/// than this: the trust suite's right answers had up to 29 (rows of desks, symmetric
/// halls), a warehouse scan among look-alike aisles 29.
pub(crate) const MAX_CANDIDATES: usize = 32;

/// The lowest score that survives: `keep_ratio` of the best for a positive best, the same
/// margin below it otherwise.
pub(crate) fn threshold(best: i64, keep_ratio: f64) -> i64 {
    best - ((1.0 - keep_ratio) * best.abs() as f64).floor() as i64
}

/// Best first; ties by lattice index (deterministic).
pub(crate) fn rank(scored: &mut [Scored]) {
    scored.sort_unstable_by(|a, b| b.score.cmp(&a.score).then(a.cand.cmp(&b.cand)));
}

fn angle_between(a: &Pose, b: &Pose) -> f64 {
    (a.rotation().inverse() * b.rotation()).angle()
}

/// Whether two poses are distinct solutions: farther apart than `ambiguity_distance` or
/// `ambiguity_angle`.
pub(crate) fn distinct(a: &Pose, b: &Pose, params: &SearchParams) -> bool {
    (a.translation() - b.translation()).norm() > params.ambiguity_distance
        || angle_between(a, b) > params.ambiguity_angle
}

/// The finished search: `scored` holds the finest-level poses within `keep_ratio` of the
/// best, ranked; `others` any further finest-level poses scored (in any order), where the
/// runner-up is looked for too.
pub(crate) fn finish(
    problem: &Problem,
    params: &SearchParams,
    scored: &[Scored],
    others: &[Scored],
    levels: Vec<LevelReport>,
    start: Instant,
) -> Alignment {
    let l = &problem.lattice;
    let Scored {
        score: best_score,
        hits: best_hits,
        cand: best,
    } = scored[0];
    let cut = threshold(best_score, params.keep_ratio);
    // Cluster the finest-level poses within keep_ratio of the best.
    let mut heads: Vec<Candidate> = Vec::new();
    for s in scored.iter().take_while(|s| s.score >= cut) {
        let pose = l.pose(&s.cand, 0);
        let near = heads.iter().any(|h| {
            (h.pose.translation() - pose.translation()).norm() <= params.ambiguity_distance
                && angle_between(&h.pose, &pose) <= params.ambiguity_angle
        });
        if !near {
            heads.push(Candidate {
                pose,
                overlap: s.hits as u64,
                score: s.score,
            });
        }
    }
    let best_pose = l.pose(&best, 0);
    let runner_up = heads.get(1).copied().or_else(|| {
        others
            .iter()
            .filter(|s| s.score > 0)
            .map(|s| (s, l.pose(&s.cand, 0)))
            .filter(|(_, p)| distinct(p, &best_pose, params))
            .max_by(|(a, _), (b, _)| a.score.cmp(&b.score).then(b.cand.cmp(&a.cand)))
            .map(|(s, pose)| Candidate {
                pose,
                overlap: s.hits as u64,
                score: s.score,
            })
    });
    let spread = spread_around(
        &best_pose,
        scored
            .iter()
            .take_while(|s| s.score >= cut)
            .map(|s| l.pose(&s.cand, 0)),
    );
    let n = problem.scan[0].len() as u64;
    let overlap = best_hits as u64;
    let ambiguity = heads.len().max(1);
    heads.truncate(MAX_CANDIDATES);
    if heads.is_empty() {
        heads.push(Candidate {
            pose: best_pose,
            overlap,
            score: best_score,
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
        runner_up,
        spread,
        conflicts: (2 * best_hits as i64 - best_score).max(0) as u64,
        levels,
        guard_acted,
        evaluated,
        seconds: start.elapsed().as_secs_f64(),
        exact: false,
    }
}

/// Half the range of `poses` around `best` along x, y, z and heading.
fn spread_around(best: &Pose, poses: impl Iterator<Item = Pose>) -> [f64; 4] {
    let mut out = [0.0f64; 4];
    let (yaw0, _, _) = best.yaw_pitch_roll();
    let t0 = best.translation();
    let (mut lo, mut hi) = ([0.0f64; 4], [0.0f64; 4]);
    for p in poses {
        let d = p.translation() - t0;
        let dyaw = crate::geometry::wrap_angle(p.yaw_pitch_roll().0 - yaw0);
        for (i, v) in [d.x, d.y, d.z, dyaw].into_iter().enumerate() {
            lo[i] = lo[i].min(v);
            hi[i] = hi[i].max(v);
        }
    }
    for i in 0..4 {
        out[i] = 0.5 * (hi[i] - lo[i]);
    }
    out
}

pub(crate) fn level_report(
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

pub(crate) fn no_overlap(problem: &Problem, levels: Vec<LevelReport>, start: Instant) -> Alignment {
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
        runner_up: None,
        spread: [0.0; 4],
        conflicts: 0,
        levels,
        guard_acted: false,
        evaluated,
        seconds: start.elapsed().as_secs_f64(),
        exact: false,
    }
}
