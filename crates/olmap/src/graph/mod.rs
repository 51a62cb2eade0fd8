//! Pose graphs: nodes are poses (SE(2) or SE(3)), edges relative measurements with an
//! information matrix and a robust kernel; a sparse Levenberg-Marquardt solver on the
//! manifold makes all poses agree. This is the back end of map building with loop
//! closure: the mapper adds a node per scan and an edge per odometry step, registration,
//! sighting or loop closure, solves (warm-started from the last solution) and reads back
//! the poses and which edges the kernels rejected.
//!
//! * [`PoseGraph`] ([`model`]): nodes, fixed nodes (the gauge), edges ([`EdgeKind`],
//!   [`Measurement`] `T_i_j` with its information, [`Kernel`]: none, Huber, Cauchy or
//!   dynamic covariance scaling);
//! * [`PoseGraph::optimise`] ([`solve`]): Levenberg-Marquardt with analytic Jacobians
//!   (right perturbation, `lie.rs`) and a block-sparse Cholesky with a minimum-degree ordering
//!   (`sparse.rs`); optional chordal initialisation ([`Init::Chordal`], `init.rs`); a
//!   [`SolveReport`] with an [`EdgeReport`] per edge (residual, chi2, weight, outlier);
//! * [`cost`]: the cost in a named convention (Ceres' or the solver's own), to compare with
//!   published numbers;
//! * [`g2o`]: reading and writing g2o files; [`run_graph_optimise`] and [`describe_g2o`]:
//!   the `olmap graph` pipelines.
//!
//! The solver is deterministic: the ordering breaks ties by node index, linearisation runs
//! in parallel but every sum runs in edge order, so any thread count gives the same bytes.
//!
//! ```
//! use olmap::geometry::Pose;
//! use olmap::graph::{EdgeKind, Init, Kernel, PoseGraph, SolveParams, Space};
//! use nalgebra::Matrix6;
//!
//! // A square of four poses with odometry and one loop closure.
//! let mut g = PoseGraph::new(Space::Se3);
//! let step = Pose::from_xyz_ypr(1.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0);
//! let mut guess = Pose::identity();
//! for id in 0..4 {
//!     g.add_node_se3(id, guess).unwrap();
//!     // Odometry that over-turns a little: the guesses drift.
//!     guess = guess * step * Pose::from_xyz_ypr(0.0, 0.0, 0.0, 0.05, 0.0, 0.0);
//! }
//! let info = Matrix6::identity() * 100.0;
//! for id in 0..3 {
//!     g.add_edge_se3(id, id + 1, EdgeKind::Odometry, step, info, Kernel::None).unwrap();
//! }
//! g.add_edge_se3(3, 0, EdgeKind::LoopClosure, step, info, Kernel::Dcs(10.0)).unwrap();
//! let report = g.optimise(&SolveParams { init: Init::Chordal, ..Default::default() }).unwrap();
//! assert!(report.converged && report.final_cost < 1e-9);
//! assert_eq!(report.gauge_nodes, vec![0]); // no fixed node: the first holds the gauge
//! let p2 = g.pose(2).unwrap().translation();
//! assert!((p2 - nalgebra::Vector3::new(1.0, 1.0, 0.0)).norm() < 1e-6);
//! ```

pub mod cost;
pub mod g2o;
pub(crate) mod init;
pub(crate) mod lie;
pub mod model;
mod pipeline;
pub mod solve;
pub(crate) mod sparse;

pub use cost::{cost, CostConvention};
pub use g2o::{parse_g2o, read_g2o, write_g2o, write_g2o_to};
pub use model::{
    Edge, EdgeKind, Kernel, Measurement, Node, NodeId, NodePose, PoseGraph, Se2, Space,
    OUTLIER_WEIGHT,
};
pub use pipeline::{
    describe_g2o, run_graph_optimise, DownWeightedEdge, GraphInfo, GraphOptimiseJob,
    GraphOptimiseReport,
};
pub use solve::{EdgeReport, Init, SolveParams, SolveReport};
