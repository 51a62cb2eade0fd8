//! Cost evaluators in named conventions, so that a graph's cost can be compared with the
//! numbers other solvers publish. Each is `1/2 sum r^T Omega r` over all edges, with no
//! robust kernel; they differ in the residual `r` of an edge i -> j with measurement
//! `(t_ij, q_ij)`:
//!
//! | convention | SE(3) residual | SE(2) residual |
//! |---|---|---|
//! | [`CostConvention::Ceres`] | `[R_i^T (p_j - p_i) - t_ij ; 2 vec(q_ij^-1 q_i^-1 q_j)]` (the quaternion taken with `w >= 0`) | `[R_i^T (p_j - p_i) - t_ij ; wrap(theta_j - theta_i - theta_ij)]` (Ceres' `pose_graph_2d`) |
//! | [`CostConvention::Log`] | `[R_i^T (p_j - p_i) - t_ij ; Log(R_ij^T R_i^T R_j)]` (what olmap's solver minimises) | the same as Ceres |
//!
//! `Ceres` is the convention of the published benchmark costs (the shared data's README §5:
//! parking-garage 8,362.72 at the file's values, sphere2500 1,292,303; both reproduced by
//! this evaluator). Ceres' own `pose_graph_3d` example code takes the rotation error on the
//! other side, `2 vec(q_ij (q_i^-1 q_j)^-1)`; with an isotropic rotation information
//! (parking-garage) that is the same number, with sphere2500's anisotropic one it is not
//! (1,292,384 at the file's values). The two SE(3) conventions here agree to third order in
//! the rotation error (`2 sin(a/2)` against `a`). GTSAM's published numbers use the SE(3)
//! logarithm of `T_ij^-1 T_i^-1 T_j`, whose translation part is rotated into the
//! measurement's frame and coupled with the rotation: not the same number (parking-garage
//! 0.6246 in GTSAM's against 0.6348 in Ceres').

use nalgebra::{SVector, Vector2};
use serde::{Deserialize, Serialize};

use super::lie::{Group, S2, S3};
use super::model::{Measurement, NodePose, PoseGraph};
use crate::geometry::wrap_angle;

/// A residual convention for [`cost`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CostConvention {
    /// The Ceres pose-graph convention of the published benchmark costs (parking-garage
    /// 8,362.72 -> 0.6348): quaternion error `2 vec(q_ij^-1 q_i^-1 q_j)`.
    Ceres,
    /// The solver's own residual (rotation error as a rotation vector).
    Log,
}

impl CostConvention {
    /// The convention's name in reports (`ceres`, `log`).
    pub fn name(self) -> &'static str {
        match self {
            CostConvention::Ceres => "ceres",
            CostConvention::Log => "log",
        }
    }
}

fn s3(p: &NodePose) -> S3 {
    let p = p.to_pose();
    S3 {
        p: p.translation(),
        q: p.rotation(),
    }
}

fn s2(p: &NodePose) -> S2 {
    match p {
        NodePose::Se2(p) => S2 {
            p: Vector2::new(p.x, p.y),
            th: p.theta,
        },
        NodePose::Se3(p) => {
            let t = p.translation();
            S2 {
                p: Vector2::new(t.x, t.y),
                th: p.yaw_pitch_roll().0,
            }
        }
    }
}

/// The cost `1/2 sum r^T Omega r` of a graph at its current poses in a convention (no
/// robust kernels), summed in edge order.
pub fn cost(graph: &PoseGraph, convention: CostConvention) -> f64 {
    let mut total = 0.0;
    for e in graph.edges() {
        let (Some(a), Some(b)) = (graph.node(e.from), graph.node(e.to)) else {
            continue;
        };
        let chi2 = match &e.measurement {
            Measurement::Se3 { t_i_j, information } => {
                let (xi, xj) = (s3(&a.pose), s3(&b.pose));
                let m = S3 {
                    p: t_i_j.translation(),
                    q: t_i_j.rotation(),
                };
                let r: SVector<f64, 6> = match convention {
                    CostConvention::Log => S3::residual(&xi, &xj, &m),
                    CostConvention::Ceres => {
                        let et = xi.q.inverse() * (xj.p - xi.p) - m.p;
                        let dq = (m.q.inverse() * xi.q.inverse() * xj.q).into_inner();
                        let v = if dq.w < 0.0 { -dq.imag() } else { dq.imag() } * 2.0;
                        SVector::<f64, 6>::new(et.x, et.y, et.z, v.x, v.y, v.z)
                    }
                };
                (r.transpose() * information * r)[0]
            }
            Measurement::Se2 { t_i_j, information } => {
                let (xi, xj) = (s2(&a.pose), s2(&b.pose));
                let m = S2 {
                    p: Vector2::new(t_i_j.x, t_i_j.y),
                    th: t_i_j.theta,
                };
                let mut r = S2::residual(&xi, &xj, &m);
                r[2] = wrap_angle(r[2]);
                (r.transpose() * information * r)[0]
            }
        };
        total += chi2;
    }
    0.5 * total
}
