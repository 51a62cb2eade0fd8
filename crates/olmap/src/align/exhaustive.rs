//! The exhaustive reference search (thesis Algorithm 7): every lattice pose of the region
//! at the finest level.

use std::time::Instant;

use super::evaluate::{initial_candidates, score_level, LevelScores};
use super::lattice::{finish, level_report, no_overlap, prepare, Alignment};
use super::params::SearchParams;
use super::target::SearchTarget;
use crate::cloud::PointCloud;
use crate::error::Result;

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
    let cands = initial_candidates(&problem, params, &target.pyramid, 0)?;
    let LevelScores {
        passed: scored,
        heads,
        best_hits,
        evaluated,
    } = score_level(&problem, params, &cands, 0, params.keep_ratio, 1);
    let passed = scored.len();
    let reports = vec![level_report(
        &problem, 0, evaluated, passed, passed, best_hits, t,
    )];
    if best_hits == 0 {
        return Ok(no_overlap(&problem, reports, start));
    }
    let mut a = finish(&problem, params, &scored, &heads, reports, start);
    a.exact = true;
    Ok(a)
}
