//! Occupancy lists: sparse hashed 3D voxel maps of integer log-odds counts (thesis §5.3.1).
//!
//! * [`OccupancyList`]: voxel key -> count, only positive counts stored; built from clouds
//!   (endpoints) or by ray tracing scans ([`OccupancyList::insert_scan`], thesis
//!   Algorithm 2 with exact voxel traversal [`VoxelRay`]);
//! * queries ([`OccupancyList::cast_ray`], [`OccupancyList::segment_is_free`],
//!   [`OccupancyList::occupied_within`]), filters, merging, transforms, statistics and map entropy (thesis (7.4));
//! * [`PositionBuckets`] (thesis §3.3.3): integrate scans from new positions only;
//! * downsampling (thesis Algorithm 4) and the incremental [`Pyramid`];
//! * overlap of a scan with a map (thesis (5.7)), plain and weighted;
//! * files: `.olm` (olmap's exact binary format) and OctoMap `.bt` via [`read_map`] /
//!   [`write_map`];
//! * free space at OctoMap's semantics, as an option: [`LogOddsMap`] (unknown / free /
//!   occupied, log-odds with clamping, `.bt` export with free nodes).
//!
//! Memory: one `u64` per hash slot holds the key and the count (see the `packed` layout),
//! 10-15 bytes per stored voxel.

mod buckets;
mod file;
mod free;
mod list;
mod logodds;
mod olm;
mod overlap;
pub(crate) mod packed;
mod pyramid;
mod query;
mod query_report;
mod raytrace;
mod report;
mod table;
mod voxelize;

pub use buckets::PositionBuckets;
pub use file::{read_map, read_map_from, write_map, LoadedMap, MapFormat, MAX_BT_VOXELS};
pub use free::{FreeBox, FreeSpace};
pub use list::{OccupancyList, OccupancyStats};
pub use logodds::{
    logit, run_free_space, FreeSpaceJob, FreeSpaceReport, FreeSpaceRun, LogOddsInsertStats,
    LogOddsMap, LogOddsModel, LogOddsStats, VoxelState, MAX_BRICKS,
};
pub use olm::{OLM_MAGIC, OLM_VERSION};
pub use packed::{KEY_MAX, KEY_MIN, MAX_COUNT};
pub use pyramid::Pyramid;
pub use query::RayHit;
pub use query_report::{
    AtReport, QueryReport, RadiusReport, RayHitReport, RayMissReport, SegmentReport, VoxelReport,
};
pub use raytrace::{InsertStats, SensorModel, VoxelRay};
pub use report::{describe_file, FileError, FileInfo, MapInfo, OctreeReport, VoxelizeReport};
pub use voxelize::{cloud_poses, run_voxelize, CloudPoses, VoxelizeJob, VoxelizeRun};
