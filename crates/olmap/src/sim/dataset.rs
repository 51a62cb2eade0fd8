//! A whole simulated run: a world, a team of robots driving stop-and-scan trajectories,
//! their scans, odometry and sightings (thesis §3.4.1, §6.5).

use serde_json::json;

use super::rng::{mix64, SimRng};
use super::robot::{odometry_for, plan_trajectories, MotionModel, OdometryNoise, RobotModel};
use super::scanners::{MirrorScanner, PlanarScanner, SpinningLidar};
use super::sighting::{sightings_at, Sighting, SightingModel};
use super::world::World;
use super::worlds::{free_spot, WorldKind};
use crate::cloud::{LaserScan, PointCloud};
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::scanner::MirrorLog;

/// The 3D scanner every robot carries.
#[derive(Debug, Clone)]
pub enum Scanner3d {
    /// The thesis' rotating-mirror scanner.
    Mirror(MirrorScanner),
    /// A multi-beam spinning lidar.
    Lidar(SpinningLidar),
}

/// What to simulate.
#[derive(Debug, Clone)]
pub struct SimConfig {
    /// The world generator.
    pub world: WorldKind,
    /// Seed of everything random: the same seed gives the same dataset.
    pub seed: u64,
    /// Number of robots (default 4, like §6.5).
    pub robots: usize,
    /// Stops (scans) per robot (default 20).
    pub stops: usize,
    /// Time between stops, seconds (default 10).
    pub stop_interval: f64,
    /// The robots' shape, sensor and beacon placement.
    pub robot: RobotModel,
    /// How robots move between stops.
    pub motion: MotionModel,
    /// Odometry error.
    pub odometry: OdometryNoise,
    /// The 3D scanner (default the enhanced mirror scanner).
    pub scanner: Scanner3d,
    /// A 2D scanner too, if set.
    pub scanner2d: Option<PlanarScanner>,
    /// Keep the mirror scanner's raw logs (only with [`Scanner3d::Mirror`]).
    pub raw_logs: bool,
    /// Beacon detection.
    pub sighting: SightingModel,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            world: WorldKind::Lab,
            seed: 1,
            robots: 4,
            stops: 20,
            stop_interval: 10.0,
            robot: RobotModel::default(),
            motion: MotionModel::default(),
            odometry: OdometryNoise::typical(),
            scanner: Scanner3d::Mirror(MirrorScanner::enhanced()),
            scanner2d: None,
            raw_logs: false,
            sighting: SightingModel::default(),
        }
    }
}

impl Scanner3d {
    /// Beams fired per 3D scan (the most points a scan can hold).
    pub fn beams_per_scan(&self) -> f64 {
        match self {
            Scanner3d::Mirror(m) => m.sweeps() as f64 * m.geometry.scan_beams as f64,
            Scanner3d::Lidar(l) => l.azimuths() as f64 * l.beams as f64,
        }
    }
}

/// Bytes a simulated 3D point takes in memory: its coordinates and intensity.
const BYTES_PER_SIM_POINT: f64 = 16.0;
/// Bytes of a raw mirror log per beam: its range.
const BYTES_PER_RAW_BEAM: f64 = 4.0;
/// Bytes per stop and robot besides the scans: poses, odometry, sightings.
const BYTES_PER_SIM_STOP: f64 = 512.0;

impl SimConfig {
    /// The memory a simulation of this size holds at once, bytes (every scan of every
    /// robot at every stop, at most one point per beam): what [`simulate`] checks against
    /// [`crate::limits::MAX_ESTIMATE_BYTES`] before planning anything.
    pub fn memory_estimate(&self) -> f64 {
        let beams = self.scanner.beams_per_scan();
        let raw = if self.raw_logs {
            BYTES_PER_RAW_BEAM
        } else {
            0.0
        };
        let planar = self.scanner2d.as_ref().map_or(0.0, |p| p.beams() as f64) * 8.0;
        self.robots as f64
            * self.stops as f64
            * (beams * (BYTES_PER_SIM_POINT + raw) + planar + BYTES_PER_SIM_STOP)
    }

    /// Every parameter as JSON, for the dataset manifest.
    pub fn parameters(&self) -> serde_json::Value {
        let r = &self.robot;
        let o = &self.odometry;
        let m = &self.motion;
        let s = &self.sighting;
        json!({
            "robots": self.robots,
            "stops": self.stops,
            "stop_interval_s": self.stop_interval,
            "robot": {
                "body_radius_m": r.body_radius, "body_height_m": r.body_height,
                "sensor_height_m": r.sensor_height, "scanner2d_height_m": r.scanner2d_height,
                "beacon": format!("{:?}", r.beacon), "beacon_radius_m": r.beacon_radius,
                "beacon_length_m": r.beacon_length,
            },
            "motion": {
                "step_m": [m.step.0, m.step.1], "turn_sigma_rad": m.turn_sigma,
                "margin_m": m.margin, "robot_spacing_m": m.robot_spacing,
            },
            "odometry_noise": {
                "scale_error": o.scale_error, "yaw_drift_rad_per_m": o.yaw_drift_per_m,
                "sigma_xy_m": o.sigma_xy, "sigma_yaw_rad": o.sigma_yaw,
            },
            "scanner": format!("{:?}", self.scanner),
            "scanner2d": self.scanner2d.as_ref().map(|p| format!("{p:?}")),
            "raw_logs": self.raw_logs,
            "sighting": {
                "max_range_m": s.max_range, "fov_rad": s.fov,
                "elevation_rad": [s.elevation.0, s.elevation.1],
                "range_sigma_m": s.range_sigma, "angle_sigma_rad": s.angle_sigma,
            },
        })
    }
}

/// One simulated robot's data.
#[derive(Debug, Clone)]
pub struct SimRobot {
    /// Its name (`robot0`, ...).
    pub name: String,
    /// True `T_world_robot` per stop.
    pub truth: Vec<Pose>,
    /// Odometry `T_odom_robot` per stop (the first is the identity).
    pub odometry: Vec<Pose>,
    /// 3D scans in the robot frame (sensor origin set), per stop.
    pub scans: Vec<PointCloud>,
    /// 2D scans per stop (empty without a 2D scanner).
    pub scans2d: Vec<LaserScan>,
    /// Raw mirror logs per stop (empty unless requested).
    pub raw_logs: Vec<MirrorLog>,
}

impl SimRobot {
    /// The robot's scans as map-building input (`scanNNN` names, odometry priors).
    pub fn scan_inputs(&self) -> Vec<crate::mapping::ScanInput> {
        self.scans
            .iter()
            .enumerate()
            .map(|(k, cloud)| crate::mapping::ScanInput {
                name: format!("scan{k:03}"),
                cloud: cloud.clone(),
                odometry: Some(self.odometry[k]),
            })
            .collect()
    }
}

/// A simulated run.
#[derive(Debug, Clone)]
pub struct SimDataset {
    /// What was simulated.
    pub config: SimConfig,
    /// The world.
    pub world: World,
    /// The robots.
    pub robots: Vec<SimRobot>,
    /// Every sighting, by stop.
    pub sightings: Vec<Sighting>,
}

/// Runs a simulation: builds the world, plans the robots' trajectories, and at every stop
/// scans from each robot (the others are in view as solids with their beacons) and records
/// the sightings. `progress(done, total)` counts scans.
///
/// ```
/// use olmap::sim::{simulate, SimConfig, WorldKind, Scanner3d, SpinningLidar};
/// let config = SimConfig {
///     world: WorldKind::BoxRoom,
///     robots: 2,
///     stops: 2,
///     scanner: Scanner3d::Lidar(SpinningLidar::default()),
///     ..Default::default()
/// };
/// let data = simulate(&config, |_, _| {}).unwrap();
/// assert_eq!(data.robots.len(), 2);
/// assert!(data.robots[0].scans[1].len() > 1000);
/// assert_eq!(data.robots[1].odometry[0], olmap::geometry::Pose::identity());
/// ```
pub fn simulate(config: &SimConfig, mut progress: impl FnMut(usize, usize)) -> Result<SimDataset> {
    if config.robots == 0 || config.stops == 0 {
        return Err(Error::InvalidArgument(
            "a simulation needs at least one robot and one stop".into(),
        ));
    }
    crate::limits::check_memory(
        || {
            format!(
                "a simulation of {} robots x {} stops ({:.0} beams per scan)",
                config.robots,
                config.stops,
                config.scanner.beams_per_scan()
            )
        },
        config.memory_estimate(),
    )?;
    let seed = config.seed;
    let world = config.world.build(seed);
    let mut rng = SimRng::new(mix64(seed ^ 0x7472_616a));
    let truth = plan_trajectories(
        &world,
        &config.robot,
        &config.motion,
        config.robots,
        config.stops,
        &mut rng,
        free_spot,
    )
    .ok_or_else(|| {
        Error::InvalidArgument(format!(
            "could not find room for {} robots in the {} world",
            config.robots,
            config.world.name()
        ))
    })?;
    let mut robots: Vec<SimRobot> = truth
        .into_iter()
        .enumerate()
        .map(|(r, t)| {
            let mut orng = SimRng::new(mix64(seed ^ (0x6f64_6f00 + r as u64)));
            SimRobot {
                name: format!("robot{r}"),
                odometry: odometry_for(&t, &config.odometry, &mut orng),
                truth: t,
                scans: Vec::new(),
                scans2d: Vec::new(),
                raw_logs: Vec::new(),
            }
        })
        .collect();
    let total = config.robots * config.stops;
    let sensor = config.robot.sensor_pose();
    let sensor2d = config.robot.scanner2d_pose();
    let mut sightings = Vec::new();
    for k in 0..config.stops {
        let time = k as f64 * config.stop_interval;
        let poses: Vec<Pose> = robots.iter().map(|r| r.truth[k]).collect();
        let objects: Vec<_> = poses
            .iter()
            .enumerate()
            .flat_map(|(r, p)| config.robot.objects(r, p))
            .collect();
        for r in 0..config.robots {
            let own = super::shape::ROBOT_ID_BASE + r as u32;
            let extra: Vec<_> = objects.iter().filter(|o| o.id != own).cloned().collect();
            let stream = (r * config.stops + k) as u64;
            let t_world_sensor = poses[r] * sensor;
            let cloud = match &config.scanner {
                Scanner3d::Mirror(m) if config.raw_logs => {
                    let (cloud, log) = m.scan_raw(&world, &extra, &t_world_sensor, seed, stream);
                    robots[r].raw_logs.push(log);
                    cloud
                }
                Scanner3d::Mirror(m) => m.scan(&world, &extra, &t_world_sensor, seed, stream),
                Scanner3d::Lidar(l) => l.scan(&world, &extra, &t_world_sensor, seed, stream),
            };
            robots[r].scans.push(cloud.transformed(&sensor));
            if let Some(p) = &config.scanner2d {
                let mut scan = p.scan(
                    &world,
                    &extra,
                    &(poses[r] * sensor2d),
                    seed,
                    stream | 1 << 40,
                );
                scan.time = time;
                robots[r].scans2d.push(scan);
            }
            progress(k * config.robots + r + 1, total);
        }
        sightings.extend(sightings_at(
            &world,
            &config.robot,
            &config.sighting,
            &poses,
            &objects,
            k,
            time,
            seed,
        ));
    }
    Ok(SimDataset {
        config: config.clone(),
        world,
        robots,
        sightings,
    })
}
