//! Scan alignment: global search with no initial guess (thesis §5.3), significance, and
//! refinement.

mod bnb;
mod consistency;
mod evaluate;
mod exhaustive;
pub mod icp;
mod lattice;
mod localize;
mod multires;
mod params;
mod register;
pub(crate) use register::register_preparing;
mod report;
mod score;
mod search;
mod significance;
mod target;
pub mod verdict;
pub mod verify;

pub use bnb::{EXACT_MAX_AMBIGUITY, EXACT_MAX_WORK};
pub use consistency::{
    consistency, consistency_seen, source_view, Consistency, SideAgreement,
    MIN_CONTRADICTED_NEIGHBOURS, MIN_SURFACE_NEIGHBOURS, MIN_UPRIGHT_SEEN, MOVABLE_HEIGHT,
    MOVABLE_WIDTH,
};
pub use exhaustive::exhaustive_search;
pub use lattice::{Alignment, Candidate, LevelReport};
pub use localize::{localize, localize_in, working_factor, Localizer};
pub use params::{Dof, Locus, Region, SearchMode, SearchParams, MAX_LEVELS};
pub use register::{
    register, register_to, register_to_prepared, register_to_prepared_or_widen, register_to_split,
    OnWindowEdge, RegisterParams, Registration, REFINE_REACH_CELLS,
};
pub use report::{
    matrix_rows, AgreementJson, AlignmentReport, DegeneracyJson, HypothesisJson, LevelJson,
    Matrix4Rows, RefinementReport, SearchReport, UniquenessReport,
};
pub use search::{global_search, search};
pub use significance::significance;
pub use target::{SearchTarget, FREE_SPACE_MARGIN, MAP_FREE_CLEARANCE_CELLS};
pub use verdict::TrustThresholds;

use crate::cloud::PointCloud;
use crate::error::Result;

/// Global search of `source` against a `target` cloud: the target is voxelised (endpoints)
/// at `params.resolution` into a pyramid (levels: [`SearchParams::levels_for_source`]) with its
/// free space ray traced from its origin, then [`global_search`] runs. Returns
/// `T_target_source`.
pub fn align_clouds(
    source: &PointCloud,
    target: &PointCloud,
    params: &SearchParams,
) -> Result<Alignment> {
    params.validate()?;
    let levels = levels_for_clouds(source, target, params);
    let target = SearchTarget::from_cloud(target, params.resolution, levels)?;
    global_search(source, &target, params)
}

/// The number of levels for a source and a target cloud (the target built at
/// `params.resolution`): [`SearchParams::levels_for_source`].
pub(crate) fn levels_for_clouds(
    source: &PointCloud,
    target: &PointCloud,
    params: &SearchParams,
) -> usize {
    let extent = target
        .bounding_box()
        .map_or(nalgebra::Vector3::zeros(), |b| b.extent());
    params.levels_for_source(params.resolution, extent, source)
}
