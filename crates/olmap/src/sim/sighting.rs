//! Sightings: robots seeing each other's beacons (thesis §3.3.1, §6.3.3), with field of
//! view, range limit, occlusion and measurement noise; two-way sightings are mutual.

use nalgebra::{Point3, Vector3};

use super::rng::SimRng;
use super::robot::{BeaconMount, RobotModel};
use super::shape::{Object, ROBOT_ID_BASE};
use super::world::World;
use crate::geometry::Pose;

/// What a robot's beacon detector sees: the 3D scanner for a beacon above it, the 2D
/// scanner for a beacon in front.
#[derive(Debug, Clone, PartialEq)]
pub struct SightingModel {
    /// Farthest detection, metres (default 8, the thesis' truncation).
    pub max_range: f64,
    /// Horizontal field of view, full angle, radians, centred on the robot's x axis
    /// (default 270°: a mirror scanner sees around but not behind through its own mast).
    pub fov: f64,
    /// Lowest and highest elevation seen, radians (default -60° to +60°).
    pub elevation: (f64, f64),
    /// Range noise, standard deviation, metres (default 0.01, §3.5).
    pub range_sigma: f64,
    /// Bearing and elevation noise, standard deviation, radians (default 0.25°).
    pub angle_sigma: f64,
}

impl Default for SightingModel {
    fn default() -> Self {
        SightingModel {
            max_range: 8.0,
            fov: 270f64.to_radians(),
            elevation: (-60f64.to_radians(), 60f64.to_radians()),
            range_sigma: 0.01,
            angle_sigma: 0.25f64.to_radians(),
        }
    }
}

/// One robot seeing another's beacon.
#[derive(Debug, Clone, PartialEq)]
pub struct Sighting {
    /// The robot that saw.
    pub observer: usize,
    /// The robot seen.
    pub target: usize,
    /// The stop (scan number) both robots were at.
    pub stop: usize,
    /// Time, seconds.
    pub time: f64,
    /// Measured range from the observer's detecting sensor to the beacon's axis, metres.
    pub range: f64,
    /// Measured bearing in the observer's frame (0 ahead, positive left), radians.
    pub bearing: f64,
    /// Measured elevation above the detecting sensor's horizontal plane, radians.
    pub elevation: f64,
    /// The beacon's centre in the observer's robot frame, from the measurements.
    pub beacon: Point3<f64>,
    /// Whether the target saw the observer at the same stop too.
    pub mutual: bool,
}

/// The detecting sensor's origin in the robot frame.
fn detector(model: &RobotModel) -> Point3<f64> {
    match model.beacon {
        BeaconMount::Above => model.sensor_pose().transform_point(&Point3::origin()),
        BeaconMount::Front { .. } => model.scanner2d_pose().transform_point(&Point3::origin()),
    }
}

/// The sightings at one stop: every ordered pair (observer, target) where the target's
/// beacon is in the observer's field of view and range and the line of sight to it is not
/// blocked by the world or another robot. `poses[k]` is robot k's true `T_world_robot`;
/// `objects` holds every robot's solids (from [`RobotModel::objects`]).
#[allow(clippy::too_many_arguments)]
pub fn sightings_at(
    world: &World,
    model: &RobotModel,
    sm: &SightingModel,
    poses: &[Pose],
    objects: &[Object],
    stop: usize,
    time: f64,
    seed: u64,
) -> Vec<Sighting> {
    let n = poses.len();
    let det = detector(model);
    let mut seen = vec![vec![false; n]; n];
    let mut out = Vec::new();
    for a in 0..n {
        let others: Vec<Object> = objects
            .iter()
            .filter(|o| o.id != ROBOT_ID_BASE + a as u32)
            .cloned()
            .collect();
        let origin = poses[a].transform_point(&det);
        for b in 0..n {
            if a == b {
                continue;
            }
            let target = poses[b].transform_point(&model.beacon_center());
            let Some(local) = true_observation(&poses[a], &det, &target, sm) else {
                continue;
            };
            let dir: Vector3<f64> = (target - origin).normalize();
            let dist = (target - origin).norm();
            let visible = world
                .cast_with(&others, &origin, &dir, dist + 1.0)
                .is_some_and(|h| {
                    // The beacon's own surface (a slanted ray meets it up to r / cos(elevation)
                    // before the axis), not the target's body or anything in front.
                    h.id == ROBOT_ID_BASE + b as u32
                        && h.distance >= dist - 2.0 * model.beacon_radius
                });
            if !visible {
                continue;
            }
            seen[a][b] = true;
            let mut rng = SimRng::for_item(seed, 0x5167_0000 + stop as u64, (a * n + b) as u64);
            let (r, bearing, elev) = local;
            let r = r + rng.gauss(sm.range_sigma);
            let bearing = bearing + rng.gauss(sm.angle_sigma);
            let elev = elev + rng.gauss(sm.angle_sigma);
            let beacon = det
                + Vector3::new(
                    r * elev.cos() * bearing.cos(),
                    r * elev.cos() * bearing.sin(),
                    r * elev.sin(),
                );
            out.push(Sighting {
                observer: a,
                target: b,
                stop,
                time,
                range: r,
                bearing,
                elevation: elev,
                beacon,
                mutual: false,
            });
        }
    }
    for s in &mut out {
        s.mutual = seen[s.target][s.observer];
    }
    out
}

/// Range, bearing and elevation of `target` (world) from the detector at `det` (robot
/// frame) of a robot at `pose`, if within the model's range and field of view.
fn true_observation(
    pose: &Pose,
    det: &Point3<f64>,
    target: &Point3<f64>,
    sm: &SightingModel,
) -> Option<(f64, f64, f64)> {
    let local = pose.inverse().transform_point(target) - det;
    let r = local.norm();
    let horizontal = (local.x * local.x + local.y * local.y).sqrt();
    let bearing = local.y.atan2(local.x);
    let elevation = local.z.atan2(horizontal);
    (r <= sm.max_range
        && bearing.abs() <= 0.5 * sm.fov
        && elevation >= sm.elevation.0
        && elevation <= sm.elevation.1)
        .then_some((r, bearing, elevation))
}
