//! Map voxels as a point cloud coloured by height, for 3D viewers (CloudCompare, MeshLab
//! open the PLY files [`crate::io::write_cloud`] writes with its colours).

use super::colour::height_colour;
use crate::cloud::PointCloud;
use crate::occupancy::OccupancyList;

/// The voxel centres of `map` (sorted by key, counts as intensity, as
/// [`OccupancyList::to_cloud`]) with colours from [`height_colour`], the lowest voxel
/// blue and the highest red; heights outside `band` (when given) are clamped to its ends.
///
/// ```
/// use olmap::occupancy::OccupancyList;
/// use olmap::geometry::VoxelKey;
/// use olmap::render::{height_coloured_cloud, height_colour};
/// let mut map = OccupancyList::new(0.1).unwrap();
/// map.set(VoxelKey::new(0, 0, 0), 2).unwrap();
/// map.set(VoxelKey::new(0, 0, 20), 1).unwrap();
/// let cloud = height_coloured_cloud(&map, None);
/// assert_eq!(cloud.colors().unwrap(), &[height_colour(0.0).0, height_colour(1.0).0]);
/// ```
pub fn height_coloured_cloud(map: &OccupancyList, band: Option<(f64, f64)>) -> PointCloud {
    let mut cloud = map.to_cloud();
    let (lo, hi) = band.unwrap_or_else(|| {
        cloud
            .points()
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
                (l.min(p.z as f64), h.max(p.z as f64))
            })
    });
    let span = (hi - lo).max(1e-9);
    let colours = cloud
        .points()
        .iter()
        .map(|p| height_colour((p.z as f64 - lo) / span).0)
        .collect();
    cloud
        .set_colors(Some(colours))
        .expect("one colour per point");
    cloud
}
