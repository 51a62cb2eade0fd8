//! Fusing placed scans into one map: ray tracing the scans at their poses (with position
//! buckets, the entropy curve and each scan's own list), and rebuilding a map from
//! scan-pose pairs ([`fuse_scan_maps`]).

use super::{MapParams, PlacedScan, ScanInput, ScanMap};
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::occupancy::{OccupancyList, PositionBuckets};

/// Rebuilds a fused map from scan-pose pairs: each scan's list moved to its pose (voxel
/// centres re-binned, so a voxel can shift by one cell) and the counts added. Use it after
/// changing poses; [`build_map`]'s own fused map ray traces the points instead (exact).
///
/// [`build_map`]: super::build_map
///
/// ```
/// use olmap::geometry::Pose;
/// use olmap::mapping::{fuse_scan_maps, ScanMap};
/// use olmap::occupancy::OccupancyList;
/// # use nalgebra::Point3;
/// let mut voxels = OccupancyList::new(0.1).unwrap();
/// voxels.set(voxels.key_of(&Point3::new(1.05, 0.05, 0.05)).unwrap(), 2).unwrap();
/// let scans = [ScanMap { name: "a".into(), pose: Pose::from_xyz_ypr(1.0, 0.0, 0.0, 0.0, 0.0, 0.0), voxels }];
/// let map = fuse_scan_maps(&scans).unwrap();
/// assert_eq!(map.count_at(&Point3::new(2.05, 0.05, 0.05)), 2);
/// ```
pub fn fuse_scan_maps(scans: &[ScanMap]) -> Result<OccupancyList> {
    let Some(first) = scans.first() else {
        return Err(Error::InvalidArgument("no scan maps to fuse".into()));
    };
    let mut map = OccupancyList::new(first.voxels.resolution())?;
    for s in scans {
        map.merge(&s.voxels.transformed(&s.pose))?;
    }
    Ok(map)
}

/// The placed scans fused into one map.
pub(super) struct Fused {
    /// The fused, ray-traced, cleaned occupancy list.
    pub(super) map: OccupancyList,
    /// Each placed scan's own list with its pose (empty unless
    /// [`MapParams::keep_scan_maps`]).
    pub(super) scan_maps: Vec<ScanMap>,
    /// The map's entropy after each placed scan.
    pub(super) entropy_after_scan: Vec<f64>,
}

/// Fuses the placed scans by ray tracing, in the order they joined.
pub(super) fn fuse_placed(
    scans: &[ScanInput],
    placed: &[PlacedScan],
    params: &MapParams,
) -> Result<Fused> {
    let res = params.register.search.resolution;
    let mut map = OccupancyList::new(res)?;
    let mut buckets = PositionBuckets::new(params.bucket_radius)?;
    let mut scan_maps = Vec::new();
    let mut entropy_after_scan = Vec::with_capacity(placed.len());
    for p in placed {
        let cloud = &scans[p.index].cloud;
        if params.keep_scan_maps {
            let mut voxels = OccupancyList::new(res)?;
            voxels.insert_scan(cloud, &Pose::identity(), &params.sensor)?;
            voxels.shrink_to_fit();
            scan_maps.push(ScanMap {
                name: p.name.clone(),
                pose: p.pose,
                voxels,
            });
        }
        let admitted =
            params.bucket_radius <= 0.0 || buckets.admit(&p.pose.transform_point(&cloud.origin()));
        if admitted {
            map.insert_scan(cloud, &p.pose, &params.sensor)?;
        }
        entropy_after_scan.push(map.entropy(0.5, Some(0.0), 1.0)?);
    }
    if params.min_count > 1 {
        map = map.threshold(params.min_count);
    }
    map.shrink_to_fit();
    Ok(Fused {
        map,
        scan_maps,
        entropy_after_scan,
    })
}
