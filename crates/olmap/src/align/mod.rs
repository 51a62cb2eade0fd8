//! Scan alignment: global search with no initial guess (thesis §5.3), significance, and
//! refinement.

mod dense;
mod params;
mod search;
mod significance;
mod target;

pub use params::{Dof, Region, SearchParams};
pub use search::{exhaustive_search, global_search, Alignment, Candidate, LevelReport};
pub use significance::significance;
pub use target::{SearchTarget, FREE_SPACE_MARGIN};

use crate::cloud::PointCloud;
use crate::error::Result;

/// Global search of `source` against a `target` cloud: the target is voxelised (endpoints)
/// at `params.resolution` into a pyramid of `params.levels` levels with its free space ray
/// traced from its origin, then [`global_search`] runs. Returns `T_target_source`.
pub fn align_clouds(
    source: &PointCloud,
    target: &PointCloud,
    params: &SearchParams,
) -> Result<Alignment> {
    let target = SearchTarget::from_cloud(target, params.resolution, params.levels)?;
    global_search(source, &target, params)
}
