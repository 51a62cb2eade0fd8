//! Point clouds and the filters users apply to them.
//!
//! A [`PointCloud`] stores positions in single precision (metres, in the cloud's own frame),
//! optional per-point intensity, normals and colours, and the sensor origin in that frame.
//! Filters return new clouds and keep every attribute in step with the positions.

mod filters;
mod laser_scan;
mod point_cloud;
mod report;
mod stats;
mod voxel_merge;

pub use laser_scan::LaserScan;
pub use point_cloud::PointCloud;
pub use report::{BoxReport, RangeReport};
pub use stats::{CloudStats, RangeStats};
pub(crate) use voxel_merge::VoxelMerge;
