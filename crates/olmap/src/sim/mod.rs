//! The built-in simulator: indoor worlds of solids, ray-cast scanners (rotating-mirror 3D,
//! 2D, multi-beam lidar), robots with beacons and odometry, sightings between robots, and
//! datasets on disk (thesis §3.4.1, §4.3-4.4, §6.5). It gives olmap a default dataset with
//! ground truth for the parts of the mission no public data covers.

mod benchmark;
mod dataset;
mod demo;
pub mod files;
mod report;
mod rng;
mod robot;
mod scanners;
mod shape;
mod sighting;
mod to_store;
mod trust_suite;
mod world;
mod worlds;

pub use benchmark::{thesis_localisation, LocalisationBenchmark, THESIS_RESOLUTION};
pub use dataset::{simulate, Scanner3d, SimConfig, SimDataset, SimRobot};
pub use demo::{run_demo, DemoConfig, DemoReport, DemoRun};
pub use files::{check_dataset_output, read_dataset, write_dataset, DatasetOnDisk, SkippedInput};
pub use report::SimulateReport;
pub use rng::{mix64, SimRng};
pub use robot::{
    follow_route, odometry_for, plan_trajectories, BeaconMount, MotionModel, OdometryNoise,
    RobotModel,
};
pub use scanners::{
    MirrorScanner, PlanarScanner, RangeNoise, SpinningLidar, RETRO_INTENSITY, RETRO_MAX_INCIDENCE,
};
pub use shape::{Hit, Material, Object, Shape, RAY_EPSILON, ROBOT_ID_BASE};
pub use sighting::{sightings_at, Sighting, SightingModel};
pub use trust_suite::{
    pose_error, trust_case, trust_cases, Answer, TrustCase, TrustScene, RIGHT_ROTATION,
    RIGHT_TRANSLATION,
};
pub use world::{room_shell, World};
pub use worlds::{
    box_room, corridor, corridor_ring, desk_hall, floor_only, free_spot, lab, office,
    symmetric_hall, twin_rooms, two_walls, WorldKind,
};
