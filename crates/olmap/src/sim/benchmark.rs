//! The thesis' global localisation benchmark (§5.4): "locating the 7000 voxel scan within
//! the 200,000 voxel map takes 5 seconds on a 2GHz processor" (an office of about 200 m^2
//! mapped at 0.02 m, the robot completely lost: the whole area and every heading).

use nalgebra::Point3;

use super::rng::SimRng;
use super::robot::RobotModel;
use super::scanners::MirrorScanner;
use super::worlds::{free_spot, office};
use crate::align::{Dof, Region, SearchParams};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::occupancy::OccupancyList;

/// A global localisation problem with its ground truth.
#[derive(Debug, Clone)]
pub struct LocalisationBenchmark {
    /// The prior map (endpoints of the map scans at their true poses).
    pub map: OccupancyList,
    /// The scan to localise, in its sensor frame.
    pub scan: PointCloud,
    /// The true `T_map_sensor`.
    pub truth: Pose,
    /// The search: the whole map, every heading, no prior (x, y and heading searched; the
    /// sensor's height above the floor is known, as for the thesis' wheeled robots).
    pub params: SearchParams,
    /// Floor area covered by the map, m^2.
    pub area_m2: f64,
    /// Scan voxels at the map's resolution (the search uses at most
    /// `params.max_scan_voxels` of them, evenly spaced).
    pub scan_voxels: usize,
}

/// Map resolution of the benchmark (the thesis' 0.02 m).
pub const THESIS_RESOLUTION: f64 = 0.02;

/// The thesis benchmark in a simulated office (the west 14 x 15 m of
/// [`super::office`], 210 m^2): `map_scans` scans of the enhanced mirror scanner at random
/// free spots make the map, one more is the scan to localise. Points between 0.2 m and
/// 2.2 m above the floor are kept (floor and ceiling removed, thesis §5.4), voxelised at
/// 0.02 m. With 16 map scans (seed 7) the map has 187,730 voxels; the scan has about
/// 11,600 voxels, of which the search uses an even subsample of at most 7,000 (5,799).
pub fn thesis_localisation(seed: u64, map_scans: usize) -> Result<LocalisationBenchmark> {
    let world = office(seed);
    let (x_max, y_max) = (14.0, 15.0);
    let band = (0.2, 2.2);
    let robot = RobotModel::default();
    let scanner = MirrorScanner::enhanced();
    let mut rng = SimRng::new(seed ^ 0x7e515);
    let mut spots = Vec::new();
    while spots.len() < map_scans + 1 {
        let (x, y) = free_spot(&world, &mut rng, 0.4)
            .ok_or_else(|| Error::InvalidArgument("no free spot in the office".into()))?;
        if x > 0.5 && x < x_max - 0.5 && y > 0.5 && y < y_max - 0.5 {
            let yaw = rng.range(-std::f64::consts::PI, std::f64::consts::PI);
            spots.push(Pose::from_xyz_ypr(x, y, 0.0, yaw, 0.0, 0.0) * robot.sensor_pose());
        }
    }
    let keep = |p: &Point3<f64>| {
        p.z >= band.0 && p.z <= band.1 && p.x >= 0.0 && p.x <= x_max && p.y >= 0.0 && p.y <= y_max
    };
    // The sensor-frame points of a scan taken at `pose` that fall in the band and the area.
    let take = |i: usize, pose: &Pose| {
        let cloud = scanner.scan(&world, &[], pose, seed, i as u64);
        let kept = cloud
            .points()
            .iter()
            .filter(|p| keep(&pose.transform_point(&p.cast())))
            .copied()
            .collect();
        PointCloud::from_points(kept)
    };
    let mut map = OccupancyList::new(THESIS_RESOLUTION)?;
    for (i, pose) in spots[..map_scans].iter().enumerate() {
        map.add_points(&take(i, pose), pose, 1);
    }
    let truth = spots[map_scans];
    let scan = take(map_scans, &truth);
    let scan_voxels = OccupancyList::from_cloud(&scan, THESIS_RESOLUTION)?.len();
    let params = SearchParams {
        resolution: THESIS_RESOLUTION,
        dof: Dof::XyYaw,
        region: Region::Global,
        prior: Pose::from_xyz_ypr(0.0, 0.0, truth.translation().z, 0.0, 0.0, 0.0),
        max_scan_voxels: 7000,
        max_range: scanner.noise.max_range,
        ..Default::default()
    };
    Ok(LocalisationBenchmark {
        map,
        scan,
        truth,
        params,
        area_m2: x_max * y_max,
        scan_voxels,
    })
}
