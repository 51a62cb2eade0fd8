//! The multi-resolution overlap search (thesis Algorithms 3, 5, 6; §6.4.2 Algorithm 8):
//! the uniform start at the coarsest level, then at each finer level the survivors'
//! resampled children (Algorithm 6), down to the finest.

use std::time::Instant;

use super::evaluate::{initial_candidates, score_level, LevelScores};
use super::lattice::{finish, level_report, no_overlap, prepare, Alignment};
use super::params::{Region, SearchParams};
use super::target::SearchTarget;
use crate::cloud::PointCloud;
use crate::error::Result;

/// The level a locus search starts at (cells 4x the finest).
const LOCUS_START_LEVEL: usize = 2;

/// Children per survivor to reserve room for: the resampling (Algorithm 6) of the three
/// axes of a four-degree-of-freedom search (x, y, yaw; z adds a factor 3, six degrees of
/// freedom a factor 27). Only a capacity hint: the vector grows when more come.
const CHILDREN_PER_SURVIVOR: usize = 27;

/// The share of the best score a locus search keeps at its coarse levels (at most
/// [`SearchParams::keep_ratio`]; the finest level and the ambiguity test use that). A
/// locus has one free parameter, so keeping more poses is cheap, and 80 % lost the true
/// heading of a robot sharing 15 % of its scan with the map (found 1.25° off, which the
/// rest of its robot inherited); 50 % kept it.
const LOCUS_KEEP_RATIO: f64 = 0.5;

/// The multi-resolution search of a `source` scan (sensor frame, its points) against a
/// target, over any region (global, window or locus). Returns `T_target_source`.
///
/// The target's pyramid fixes the finest resolution and the number of levels.
pub(super) fn multires_search(
    source: &PointCloud,
    target: &SearchTarget,
    params: &SearchParams,
) -> Result<Alignment> {
    let start = Instant::now();
    let problem = prepare(source, target, params)?;
    let top = match params.region {
        // One parameter is cheap to sample finely: a locus search starts at the level of
        // 4-cell voxels, where a pose's score already tells true from false (the coarsest
        // levels blur a nearby robot's surroundings into a few cells).
        Region::Locus(_) => (target.pyramid.levels() - 1).min(LOCUS_START_LEVEL),
        _ => target.pyramid.levels() - 1,
    };
    let mut cands = initial_candidates(&problem, params, &target.pyramid, top)?;
    let mut reports = Vec::new();
    for level in (0..=top).rev() {
        let t = Instant::now();
        let keep = match params.region {
            Region::Locus(_) if level > 0 => params.keep_ratio.min(LOCUS_KEEP_RATIO),
            _ => params.keep_ratio,
        };
        let LevelScores {
            passed: scored,
            heads,
            best_hits,
            evaluated,
        } = score_level(
            &problem,
            params,
            &cands,
            level,
            keep,
            params.distinct_hypotheses,
        );
        let passed = scored.len();
        if best_hits == 0 {
            reports.push(level_report(&problem, level, evaluated, passed, 0, 0, t));
            return Ok(no_overlap(&problem, reports, start));
        }
        if level == 0 {
            reports.push(level_report(
                &problem, level, evaluated, passed, passed, best_hits, t,
            ));
            return Ok(finish(&problem, params, &scored, &heads, reports, start));
        }
        let survivors = passed.min(params.survivor_cap());
        reports.push(level_report(
            &problem, level, evaluated, passed, survivors, best_hits, t,
        ));
        let mut next = Vec::with_capacity(survivors * CHILDREN_PER_SURVIVOR);
        for s in scored[..survivors].iter().chain(&heads) {
            problem.lattice.children(&s.cand, level, &mut next);
        }
        next.sort_unstable();
        next.dedup();
        cands = next;
    }
    unreachable!("the loop returns at level 0")
}
