//! Planar (2D) mapping with loop closure: the pipeline for 2D laser logs such as the
//! CARMEN logs of the classic SLAM benchmarks (`io::carmen`).
//!
//! A planar scan is what it is: points in the scan plane, poses in x-y-yaw. The 3D
//! pipeline's voxel search and point-to-plane refinement see nothing in such a scan but the
//! plane's normal; here every stage works in the plane:
//!
//! * [`icp`]: point-to-line ICP with normals in the plane, reporting how well each
//!   direction is held (the Hessian) so corridors are recognised;
//! * [`correlative`]: an exhaustive windowed search on a blurred image of the target that
//!   also measures ambiguity (best vs best distinct local maximum);
//! * [`mapper`]: [`PlanarMapper::add_scan`] places scans one at a time (odometry guess,
//!   registration onto the last scans, an SE(2) pose graph with odometry, registration and
//!   loop-closure edges under a robust kernel, re-solved after each closure);
//! * [`odometry`]: the seeded noise model that degrades a log's corrected poses into
//!   odometry, and the matching edge information;
//! * [`pipeline`]: [`run_planar_log`], a log in, poses, graph and an error report out.

pub mod correlative;
pub mod icp;
pub mod mapper;
pub mod odometry;
mod pipeline;

pub use correlative::{CorrelativeMatch, CorrelativeParams, ScoreGrid};
pub use icp::{LineTarget, PlanarIcpParams, PlanarIcpResult};
pub use mapper::{
    ClosureAttempt, ClosureParams, Placement, PlacementSource, PlanarMapParams, PlanarMapper,
    RegistrationGate,
};
pub use odometry::OdometryNoise;
pub use pipeline::{
    planar_errors, run_planar_log, InjectedClosure, PlanarErrors, PlanarLogJob, PlanarLogReport,
    RejectedClosure,
};
