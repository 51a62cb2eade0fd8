//! Simulated robots: body and beacon solids, stop-and-scan trajectories, odometry with
//! systematic and random error.

use nalgebra::Point3;

use super::rng::SimRng;
use super::shape::{Material, Object, Shape, ROBOT_ID_BASE};
use super::world::World;
use crate::geometry::{wrap_angle, Pose};

/// Where a robot's retroreflective beacon is mounted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BeaconMount {
    /// A vertical cylinder above the 3D scanner (thesis §6.3.3, Figure 6.4): seen by the
    /// other robots' 3D scanners.
    Above,
    /// A thin cylinder `offset` metres in front of the 2D scanner, at its height (thesis
    /// §3.3.1: 0.07 m in the experiments): seen by the other robots' 2D scanners.
    Front {
        /// Distance from the 2D scanner's origin along the robot's x axis, metres.
        offset: f64,
    },
}

/// A robot's shape and where its sensors and beacon sit, in the robot (base) frame: origin
/// on the floor under the robot's centre, x forward, z up.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotModel {
    /// Body cylinder radius, metres (default 0.25).
    pub body_radius: f64,
    /// Body cylinder height, metres (default 0.45).
    pub body_height: f64,
    /// Height of the 3D scanner's origin above the floor, metres (default 0.6).
    pub sensor_height: f64,
    /// Height of the 2D scanner's plane above the floor, metres (default 0.3).
    pub scanner2d_height: f64,
    /// The beacon's mount (default above the 3D scanner).
    pub beacon: BeaconMount,
    /// Beacon radius, metres (default 0.05: a 0.1 m cylinder is visible to 10 m, §3.2).
    pub beacon_radius: f64,
    /// Beacon length, metres (default 0.3).
    pub beacon_length: f64,
}

impl Default for RobotModel {
    fn default() -> Self {
        RobotModel {
            body_radius: 0.25,
            body_height: 0.45,
            sensor_height: 0.6,
            scanner2d_height: 0.3,
            beacon: BeaconMount::Above,
            beacon_radius: 0.05,
            beacon_length: 0.3,
        }
    }
}

impl RobotModel {
    /// A robot for 2D mutual localisation (thesis §3.3.1): a low body (0.25 m, below the 2D
    /// scanner at 0.3 m, like a Pioneer with its laser on top) and a retroreflective
    /// cylinder of radius 0.05 m `offset` metres ahead of the 2D scanner, at its height.
    pub fn front_beacon(offset: f64) -> Self {
        RobotModel {
            body_height: 0.25,
            scanner2d_height: 0.3,
            beacon: BeaconMount::Front { offset },
            beacon_radius: 0.05,
            ..Default::default()
        }
    }

    /// The 3D scanner's pose in the robot frame, `T_robot_sensor`.
    pub fn sensor_pose(&self) -> Pose {
        Pose::from_xyz_ypr(0.0, 0.0, self.sensor_height, 0.0, 0.0, 0.0)
    }

    /// The 2D scanner's pose in the robot frame.
    pub fn scanner2d_pose(&self) -> Pose {
        Pose::from_xyz_ypr(0.0, 0.0, self.scanner2d_height, 0.0, 0.0, 0.0)
    }

    /// The beacon's centre (on its axis, half way up) in the robot frame.
    pub fn beacon_center(&self) -> Point3<f64> {
        match self.beacon {
            BeaconMount::Above => {
                Point3::new(0.0, 0.0, self.beacon_base() + 0.5 * self.beacon_length)
            }
            BeaconMount::Front { offset } => Point3::new(offset, 0.0, self.scanner2d_height),
        }
    }

    fn beacon_base(&self) -> f64 {
        match self.beacon {
            // A short mast: 0.1 m above the scanner's origin.
            BeaconMount::Above => self.sensor_height + 0.1,
            BeaconMount::Front { .. } => self.scanner2d_height - 0.5 * self.beacon_length,
        }
    }

    /// The robot's solids at `t_world_robot` (body and beacon), with the id
    /// `ROBOT_ID_BASE + index`: what the other robots' scanners see.
    pub fn objects(&self, index: usize, t_world_robot: &Pose) -> Vec<Object> {
        let id = ROBOT_ID_BASE + index as u32;
        let at = |p: Point3<f64>| t_world_robot.transform_point(&p);
        let beacon_axis = self.beacon_center();
        vec![
            Object {
                shape: Shape::Cylinder {
                    base: at(Point3::origin()),
                    radius: self.body_radius,
                    height: self.body_height,
                },
                material: Material::ROBOT,
                id,
            },
            Object {
                shape: Shape::Cylinder {
                    base: at(Point3::new(
                        beacon_axis.x,
                        beacon_axis.y,
                        self.beacon_base(),
                    )),
                    radius: self.beacon_radius,
                    height: self.beacon_length,
                },
                material: Material::BEACON,
                id,
            },
        ]
    }
}

/// Odometry error: systematic (scale and heading drift) and random (per stop), applied to
/// each relative motion between stops. Odometry starts at the identity (each robot's own
/// frame), as a real robot's does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryNoise {
    /// Systematic distance scale error (0.02 = the robot reports 2 % more than it drove).
    pub scale_error: f64,
    /// Systematic heading drift, radians per metre driven.
    pub yaw_drift_per_m: f64,
    /// Random translation error per stop, standard deviation per axis, metres.
    pub sigma_xy: f64,
    /// Random heading error per stop, standard deviation, radians.
    pub sigma_yaw: f64,
}

impl OdometryNoise {
    /// Perfect odometry.
    pub fn none() -> Self {
        OdometryNoise {
            scale_error: 0.0,
            yaw_drift_per_m: 0.0,
            sigma_xy: 0.0,
            sigma_yaw: 0.0,
        }
    }

    /// A wheeled robot on a good floor: 2 % scale error, 0.5°/m drift, 2 cm and 1° per stop.
    pub fn typical() -> Self {
        OdometryNoise {
            scale_error: 0.02,
            yaw_drift_per_m: 0.5f64.to_radians(),
            sigma_xy: 0.02,
            sigma_yaw: 1f64.to_radians(),
        }
    }

    /// The thesis' artificially degraded odometry (§6.5.1): errors of about 0.5 m in
    /// position and 10° in heading on each motion between scans.
    pub fn degraded() -> Self {
        OdometryNoise {
            scale_error: 0.05,
            yaw_drift_per_m: 2f64.to_radians(),
            sigma_xy: 0.35,
            sigma_yaw: 10f64.to_radians(),
        }
    }

    /// Odometry that drifts strongly but is locally fair: a 5 % scale error and 2°/m of
    /// heading drift (the rates issue 23 degrades the 2D logs' odometry by, here as a
    /// bias), plus 7.5 cm and 3° at random per stop. Over a 72 m loop the heading drifts
    /// by some 140°, so odometry alone ends metres off: what a loop closure has to undo.
    pub fn drifting() -> Self {
        OdometryNoise {
            scale_error: 0.05,
            yaw_drift_per_m: 2f64.to_radians(),
            sigma_xy: 0.075,
            sigma_yaw: 3f64.to_radians(),
        }
    }

    /// The measured motion for a true planar motion `T_prev_next`.
    pub fn corrupt(&self, motion: &Pose, rng: &mut SimRng) -> Pose {
        let t = motion.translation();
        let (yaw, _, _) = motion.yaw_pitch_roll();
        let dist = (t.x * t.x + t.y * t.y).sqrt();
        let s = 1.0 + self.scale_error;
        Pose::from_xyz_ypr(
            s * t.x + rng.gauss(self.sigma_xy),
            s * t.y + rng.gauss(self.sigma_xy),
            0.0,
            yaw + self.yaw_drift_per_m * dist + rng.gauss(self.sigma_yaw),
            0.0,
            0.0,
        )
    }
}

/// How robots move between stops.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionModel {
    /// Shortest and longest drive between two stops, metres (default 1-2 m).
    pub step: (f64, f64),
    /// Spread of the heading change at each stop, radians (default 35°).
    pub turn_sigma: f64,
    /// Space kept between the body and any obstacle, metres (default 0.15).
    pub margin: f64,
    /// Smallest distance between two robots' stops at the same time, metres (default 1).
    pub robot_spacing: f64,
}

impl Default for MotionModel {
    fn default() -> Self {
        MotionModel {
            step: (1.0, 2.0),
            turn_sigma: 35f64.to_radians(),
            margin: 0.15,
            robot_spacing: 1.0,
        }
    }
}

/// Plans stop-and-scan trajectories for `robots` robots of `stops` stops each: random
/// walks with heading persistence through free space (the body plus margin keeps clear
/// of everything up to 1 m high), starting at free spots. `free_spot` draws a start
/// position. In a world with a [route](World::route) the robots drive round it instead
/// (see [`follow_route`]). Returns `T_world_robot` per robot per stop (planar: z = 0,
/// yaw only), or `None` when there is no room.
pub fn plan_trajectories(
    world: &World,
    model: &RobotModel,
    motion: &MotionModel,
    robots: usize,
    stops: usize,
    rng: &mut SimRng,
    mut free_spot: impl FnMut(&World, &mut SimRng, f64) -> Option<(f64, f64)>,
) -> Option<Vec<Vec<Pose>>> {
    let clearance = model.body_radius + motion.margin;
    let band = (0.05, model.body_height.max(1.0));
    if world.route().len() >= 2 {
        return follow_route(world, model, motion, robots, stops, rng);
    }
    let mut states: Vec<(f64, f64, f64)> = Vec::with_capacity(robots);
    for _ in 0..robots {
        let mut placed = None;
        for _ in 0..200 {
            let (x, y) = free_spot(world, rng, clearance)?;
            if states.iter().all(|&(ox, oy, _)| {
                ((ox - x).powi(2) + (oy - y).powi(2)).sqrt() >= motion.robot_spacing
            }) {
                placed = Some((x, y, rng.range(-std::f64::consts::PI, std::f64::consts::PI)));
                break;
            }
        }
        states.push(placed?);
    }
    let mut out: Vec<Vec<Pose>> = vec![Vec::with_capacity(stops); robots];
    let pose = |&(x, y, yaw): &(f64, f64, f64)| Pose::from_xyz_ypr(x, y, 0.0, yaw, 0.0, 0.0);
    for (r, s) in states.iter().enumerate() {
        out[r].push(pose(s));
    }
    for _ in 1..stops {
        let mut next: Vec<(f64, f64, f64)> = Vec::with_capacity(robots);
        for r in 0..robots {
            let (x, y, yaw) = states[r];
            let mut chosen = None;
            for attempt in 0..60 {
                // Persist in heading; widen the turn when boxed in.
                let turn = if attempt < 30 {
                    rng.gauss(motion.turn_sigma)
                } else {
                    rng.range(-std::f64::consts::PI, std::f64::consts::PI)
                };
                let h = yaw + turn;
                let len = rng.range(motion.step.0, motion.step.1);
                let (nx, ny) = (x + len * h.cos(), y + len * h.sin());
                let apart = next
                    .iter()
                    .chain(states[r + 1..].iter())
                    .all(|&(ox, oy, _)| {
                        ((ox - nx).powi(2) + (oy - ny).powi(2)).sqrt() >= motion.robot_spacing
                    });
                if apart && world.path_is_clear((x, y), (nx, ny), clearance, band.0, band.1) {
                    chosen = Some((nx, ny, h));
                    break;
                }
            }
            // Boxed in: turn on the spot and scan again.
            let s = chosen.unwrap_or((x, y, yaw + rng.range(2.0, 4.0)));
            let wrapped = (s.0, s.1, wrap_angle(s.2));
            next.push(wrapped);
            out[r].push(pose(&wrapped));
        }
        states = next;
    }
    Some(out)
}

/// Sideways spread of a stop about a route's centre line, metres (clamped to twice this).
const ROUTE_LATERAL_SIGMA: f64 = 0.1;
/// Spread of a stop's heading about the route's direction, radians (5°).
const ROUTE_HEADING_SIGMA: f64 = 0.087;

/// Trajectories round a world's closed [route](World::route): robot `r` starts
/// `r / robots` of the way round, facing along it, and drives a random
/// [`MotionModel::step`] along the route between stops, each stop a little off the centre
/// line (σ 0.1 m) and its heading a little off the route's (σ 5°), kept clear of
/// everything like a random walk's (on the centre line facing along it when the jittered
/// spot is not clear). `None` when a stop on the centre line itself is not clear.
pub fn follow_route(
    world: &World,
    model: &RobotModel,
    motion: &MotionModel,
    robots: usize,
    stops: usize,
    rng: &mut SimRng,
) -> Option<Vec<Vec<Pose>>> {
    let corners = world.route();
    let n = corners.len();
    let segment = |i: usize| {
        let (a, b) = (corners[i], corners[(i + 1) % n]);
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        (a, (dx * dx + dy * dy).sqrt(), dy.atan2(dx))
    };
    let total: f64 = (0..n).map(|i| segment(i).1).sum();
    if total.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    // The point and direction `s` metres along the route (wrapping round).
    let at = |s: f64| {
        let mut s = s.rem_euclid(total);
        for i in 0..n {
            let (a, len, heading) = segment(i);
            if s <= len || i == n - 1 {
                let s = s.min(len);
                return (a.0 + s * heading.cos(), a.1 + s * heading.sin(), heading);
            }
            s -= len;
        }
        unreachable!("the segments cover the route")
    };
    let clearance = model.body_radius + motion.margin;
    let band = (0.05, model.body_height.max(1.0));
    let clear = |x: f64, y: f64| world.is_clear(x, y, clearance, band.0, band.1);
    let mut out = Vec::with_capacity(robots);
    for r in 0..robots {
        let mut s = total * r as f64 / robots as f64;
        let mut poses = Vec::with_capacity(stops);
        for k in 0..stops {
            if k > 0 {
                s += rng.range(motion.step.0, motion.step.1);
            }
            let (x, y, heading) = at(s);
            let side = rng
                .gauss(ROUTE_LATERAL_SIGMA)
                .clamp(-2.0 * ROUTE_LATERAL_SIGMA, 2.0 * ROUTE_LATERAL_SIGMA);
            let turn = rng.gauss(ROUTE_HEADING_SIGMA);
            let (jx, jy) = (x - side * heading.sin(), y + side * heading.cos());
            let (x, y, yaw) = if clear(jx, jy) {
                (jx, jy, heading + turn)
            } else if clear(x, y) {
                (x, y, heading)
            } else {
                return None;
            };
            poses.push(Pose::from_xyz_ypr(x, y, 0.0, wrap_angle(yaw), 0.0, 0.0));
        }
        out.push(poses);
    }
    Some(out)
}

/// Odometry poses for a true trajectory: the first at the identity, each next one the
/// previous composed with the corrupted true motion.
pub fn odometry_for(truth: &[Pose], noise: &OdometryNoise, rng: &mut SimRng) -> Vec<Pose> {
    let mut out = Vec::with_capacity(truth.len());
    let mut current = Pose::identity();
    for (k, t) in truth.iter().enumerate() {
        if k > 0 {
            let motion = truth[k - 1].inverse() * *t;
            current = current * noise.corrupt(&motion, rng);
        }
        out.push(current);
    }
    out
}
