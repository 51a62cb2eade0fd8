//! 2D occupancy grids built from planar laser scans (thesis §3.3.3), and their exchange
//! with ROS `map_server` maps (PGM image + YAML).
//!
//! * [`OccupancyGrid2d`] ([`grid`]): a log-odds grid that grows to hold every scan;
//!   [`OccupancyGrid2d::insert_scan`] ray traces each beam with [`bresenham`] and applies the
//!   Bayesian update (3.22) in log-odds form (3.28) with a [`SensorModel2d`];
//! * [`OccupancyGrid2d::insert_scan_bucketed`] ([`buckets`]): the position-bucket rule, only
//!   scans from new positions are integrated, whatever the heading;
//! * [`TrinaryGrid`], [`write_ros_map`] and [`read_ros_map`] ([`ros_map`]): the free /
//!   occupied / unknown map of ROS `map_saver` and `map_server`;
//! * [`navigation_grid`] ([`navigation`]): the free / occupied / unknown grid a planner needs,
//!   from a 3D occupancy list and its scan poses (thesis §7.3).
//!
//! ```
//! use olmap::cloud::LaserScan;
//! use olmap::geometry::Pose;
//! use olmap::grid2d::{OccupancyGrid2d, SensorModel2d, Trinary};
//!
//! // Three beams from a sensor at (1, 1) looking along +x: no return, a return at
//! // 2.04 m, and one too short to use.
//! let scan = LaserScan {
//!     angle_min: -0.1,
//!     angle_increment: 0.1,
//!     range_min: 0.05,
//!     range_max: 8.0,
//!     ranges: vec![f32::INFINITY, 2.04, 0.01],
//!     intensities: None,
//!     time: 0.0,
//! };
//! let mut grid = OccupancyGrid2d::new(0.1).unwrap();
//! let model = SensorModel2d::default();
//! let pose = Pose::from_xyz_ypr(1.0, 1.0, 0.0, 0.0, 0.0, 0.0);
//! grid.insert_scan(&scan, &pose, &model).unwrap();
//! assert!(grid.occupancy(3.04, 1.0) > 0.6); // the return
//! assert!(grid.occupancy(2.0, 1.0) < 0.4); // the free space before it
//! assert_eq!(grid.occupancy(-5.0, 1.0), 0.5); // never seen
//! let map = grid.to_trinary(Default::default());
//! assert_eq!(map.at_world(3.04, 1.0), Some(Trinary::Occupied));
//! ```

pub mod buckets;
pub mod grid;
pub mod navigation;
mod pipeline;
pub mod raytrace;
pub mod report;
pub mod ros_map;
pub mod sensor_model;
pub mod trinary;

pub use grid::{InsertStats, OccupancyGrid2d};
pub use navigation::{navigation_grid, NavGridParams, MAX_NAV_RAY_STEPS};
pub use pipeline::{run_grid2d, Grid2dJob, Grid2dRun};
pub use raytrace::{bresenham, Bresenham};
pub use report::{CellsReport, ExtentReport, Grid2dReport, NavgridReport};
pub use ros_map::{check_ros_map_output, read_ros_map, write_ros_map};
pub use sensor_model::SensorModel2d;
pub use trinary::{CellCounts, Thresholds, Trinary, TrinaryGrid};
