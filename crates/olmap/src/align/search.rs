//! The search entry point: picks the search mode ([`SearchMode`]) and runs it. The
//! searches themselves live in their own modules (the multi-resolution loop in
//! `multires`, the exact branch and bound in `bnb`, the exhaustive reference in
//! `exhaustive`), all on the shared core of `lattice`.

use super::lattice::Alignment;
use super::params::{Region, SearchMode, SearchParams};
use super::target::SearchTarget;
use crate::cloud::PointCloud;
use crate::error::Result;

/// Global alignment with no initial guess: the multi-resolution search of a `source` scan
/// (sensor frame, its points) against a target. Returns `T_target_source`.
///
/// The target's pyramid fixes the finest resolution and the number of levels.
///
/// Despite its name it runs every region of `params` (global, window around a prior,
/// locus) and every mode: [`SearchMode::Exact`] runs the exact branch and bound, except
/// for a locus region, which falls back to the multi-resolution search. [`search`] is the
/// same function under a name that says so.
pub fn global_search(
    source: &PointCloud,
    target: &SearchTarget,
    params: &SearchParams,
) -> Result<Alignment> {
    if params.search == SearchMode::Exact && !matches!(params.region, Region::Locus(_)) {
        return super::bnb::exact_search(source, target, params);
    }
    super::multires::multires_search(source, target, params)
}

/// The search `params` ask for (region and mode) of a `source` scan against a target:
/// [`global_search`] under a name that does not suggest a global region. Returns
/// `T_target_source`.
pub fn search(
    source: &PointCloud,
    target: &SearchTarget,
    params: &SearchParams,
) -> Result<Alignment> {
    global_search(source, target, params)
}
