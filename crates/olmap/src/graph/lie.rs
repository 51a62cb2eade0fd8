//! The solver's states, residuals and analytic Jacobians on SE(2) and SE(3).
//!
//! **Perturbation**: right (body frame). A state `X = (p, R)` is updated by a tangent step
//! `d = (dp, dtheta)` (translation first, as in g2o's information matrices) as
//! `X [+] d = (p + R dp, R Exp(dtheta))`.
//!
//! **Residual** of an edge i -> j with measurement `(t_ij, R_ij)`, translation first:
//! * SE(3): `r = [ R_i^T (p_j - p_i) - t_ij ; Log(R_ij^T R_i^T R_j) ]`;
//! * SE(2): `r = [ R_i^T (p_j - p_i) - t_ij ; wrap(theta_j - theta_i - theta_ij) ]`.
//!
//! The rotation error is the rotation vector of `T_ij^-1 T_i^-1 T_j`'s rotation (g2o's and
//! GTSAM's frame: the information matrix's rotation block is read in the measurement's
//! frame). The Ceres pose-graph convention of the published benchmark costs uses
//! `2 vec(q_ij^-1 q_i^-1 q_j)` there: the same rotation with `2 sin(angle / 2)` for the
//! angle, so both costs agree to third order in the residual angle (see [`super::cost`],
//! which evaluates both).

use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, UnitQuaternion, Vector2, Vector3};

use crate::geometry::wrap_angle;

/// A solver state: the pose of one node (also the type of a measurement).
pub(crate) trait Group<const D: usize>: Copy + Send + Sync {
    /// The residual of an edge i -> j with measurement `m` (see the module doc).
    fn residual(xi: &Self, xj: &Self, m: &Self) -> SVector<f64, D>;
    /// The residual and its Jacobians with respect to right perturbations of `xi` and `xj`.
    fn linearize(
        xi: &Self,
        xj: &Self,
        m: &Self,
    ) -> (SVector<f64, D>, SMatrix<f64, D, D>, SMatrix<f64, D, D>);
    /// `self [+] d`.
    fn retract(&self, d: &SVector<f64, D>) -> Self;
}

/// An SE(3) state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct S3 {
    pub p: Vector3<f64>,
    pub q: UnitQuaternion<f64>,
}

/// An SE(2) state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct S2 {
    pub p: Vector2<f64>,
    pub th: f64,
}

pub(crate) fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The rotation vector of a unit quaternion (angle in [0, pi]), exact for small angles.
pub(crate) fn log_quat(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let q = q.quaternion();
    let (mut w, mut v) = (q.w, q.imag());
    if w < 0.0 {
        w = -w;
        v = -v;
    }
    let s = v.norm();
    if s < 1e-10 {
        // angle = 2 atan2(s, w) ~ 2 s / w (1 - s^2 / (3 w^2)).
        return v * (2.0 / w) * (1.0 - s * s / (3.0 * w * w));
    }
    v * (2.0 * s.atan2(w) / s)
}

/// The inverse of SO(3)'s right Jacobian at `phi`: `Log(Exp(phi) Exp(d)) ~ phi + Jr^-1(phi) d`.
pub(crate) fn right_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
    let k = skew(phi);
    let t2 = phi.norm_squared();
    let c = if t2 < 1e-8 {
        // 1/t^2 - (1 + cos t) / (2 t sin t) = 1/12 + t^2/720 + ...
        1.0 / 12.0 + t2 / 720.0
    } else {
        let t = t2.sqrt();
        1.0 / t2 - (1.0 + t.cos()) / (2.0 * t * t.sin())
    };
    Matrix3::identity() + k * 0.5 + k * k * c
}

impl Group<6> for S3 {
    fn residual(xi: &S3, xj: &S3, m: &S3) -> SVector<f64, 6> {
        let qi_inv = xi.q.inverse();
        let et = qi_inv * (xj.p - xi.p) - m.p;
        let er = log_quat(&(m.q.inverse() * xi.q.inverse() * xj.q));
        SVector::<f64, 6>::new(et.x, et.y, et.z, er.x, er.y, er.z)
    }

    fn linearize(
        xi: &S3,
        xj: &S3,
        m: &S3,
    ) -> (SVector<f64, 6>, SMatrix<f64, 6, 6>, SMatrix<f64, 6, 6>) {
        let ri_t = xi.q.inverse().to_rotation_matrix().into_inner();
        let d = ri_t * (xj.p - xi.p);
        let et = d - m.p;
        let er = log_quat(&(m.q.inverse() * xi.q.inverse() * xj.q));
        let jr_inv = right_jacobian_inverse(&er);
        let r_rel = (xi.q.inverse() * xj.q).to_rotation_matrix().into_inner();
        let mut ji = SMatrix::<f64, 6, 6>::zeros();
        let mut jj = SMatrix::<f64, 6, 6>::zeros();
        // d et / d dp_i = -I; d et / d dtheta_i = [d]x (R_i^T -> Exp(-dtheta) R_i^T).
        ji.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(-Matrix3::identity()));
        ji.fixed_view_mut::<3, 3>(0, 3).copy_from(&skew(&d));
        // d er / d dtheta_i = -Jr^-1(er) R_j^T R_i (R_i^T -> Exp(-d) R_i^T, moved to the right).
        ji.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(-jr_inv * r_rel.transpose()));
        // d et / d dp_j = R_i^T R_j; d er / d dtheta_j = Jr^-1(er).
        jj.fixed_view_mut::<3, 3>(0, 0).copy_from(&r_rel);
        jj.fixed_view_mut::<3, 3>(3, 3).copy_from(&jr_inv);
        let r = SVector::<f64, 6>::new(et.x, et.y, et.z, er.x, er.y, er.z);
        (r, ji, jj)
    }

    fn retract(&self, d: &SVector<f64, 6>) -> S3 {
        let dp = Vector3::new(d[0], d[1], d[2]);
        let dth = Vector3::new(d[3], d[4], d[5]);
        let q = self.q * UnitQuaternion::from_scaled_axis(dth);
        S3 {
            p: self.p + self.q * dp,
            q: UnitQuaternion::new_normalize(q.into_inner()),
        }
    }
}

fn rot2(th: f64) -> Matrix2<f64> {
    let (s, c) = th.sin_cos();
    Matrix2::new(c, -s, s, c)
}

impl Group<3> for S2 {
    fn residual(xi: &S2, xj: &S2, m: &S2) -> SVector<f64, 3> {
        let et = rot2(xi.th).transpose() * (xj.p - xi.p) - m.p;
        SVector::<f64, 3>::new(et.x, et.y, wrap_angle(xj.th - xi.th - m.th))
    }

    fn linearize(
        xi: &S2,
        xj: &S2,
        m: &S2,
    ) -> (SVector<f64, 3>, SMatrix<f64, 3, 3>, SMatrix<f64, 3, 3>) {
        let ri_t = rot2(xi.th).transpose();
        let d = ri_t * (xj.p - xi.p);
        let et = d - m.p;
        let r = SVector::<f64, 3>::new(et.x, et.y, wrap_angle(xj.th - xi.th - m.th));
        let r_rel = rot2(xj.th - xi.th);
        #[rustfmt::skip]
        let ji = SMatrix::<f64, 3, 3>::new(
            -1.0, 0.0, d.y,
            0.0, -1.0, -d.x,
            0.0, 0.0, -1.0,
        );
        #[rustfmt::skip]
        let jj = SMatrix::<f64, 3, 3>::new(
            r_rel[(0, 0)], r_rel[(0, 1)], 0.0,
            r_rel[(1, 0)], r_rel[(1, 1)], 0.0,
            0.0, 0.0, 1.0,
        );
        (r, ji, jj)
    }

    fn retract(&self, d: &SVector<f64, 3>) -> S2 {
        S2 {
            p: self.p + rot2(self.th) * Vector2::new(d[0], d[1]),
            th: wrap_angle(self.th + d[2]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central differences of the residual along each tangent direction of `xi` and `xj`.
    fn numeric<const D: usize, G: Group<D>>(
        xi: &G,
        xj: &G,
        m: &G,
    ) -> (SMatrix<f64, D, D>, SMatrix<f64, D, D>) {
        let h = 1e-6;
        let mut ji = SMatrix::<f64, D, D>::zeros();
        let mut jj = SMatrix::<f64, D, D>::zeros();
        for k in 0..D {
            let mut d = SVector::<f64, D>::zeros();
            d[k] = h;
            let dp = G::residual(&xi.retract(&d), xj, m);
            let dm = G::residual(&xi.retract(&-d), xj, m);
            ji.set_column(k, &((dp - dm) / (2.0 * h)));
            let dp = G::residual(xi, &xj.retract(&d), m);
            let dm = G::residual(xi, &xj.retract(&-d), m);
            jj.set_column(k, &((dp - dm) / (2.0 * h)));
        }
        (ji, jj)
    }

    fn s3(p: [f64; 3], axis_angle: [f64; 3]) -> S3 {
        S3 {
            p: Vector3::from(p),
            q: UnitQuaternion::from_scaled_axis(Vector3::from(axis_angle)),
        }
    }

    #[test]
    fn se3_jacobians_match_numerical_differentiation() {
        // Small, medium and large residual rotations (up to 2.5 rad), general positions.
        let cases = [
            (
                s3([0.0; 3], [0.0; 3]),
                s3([1.0, 0.2, -0.1], [0.01, 0.02, 0.3]),
                s3([1.0, 0.2, -0.1], [0.01, 0.02, 0.3]),
            ),
            (
                s3([1.0, -2.0, 0.5], [0.3, -0.2, 1.0]),
                s3([3.0, 1.0, -1.0], [-0.5, 0.4, 2.0]),
                s3([0.5, 0.5, 0.1], [0.1, 0.2, 0.3]),
            ),
            (
                s3([-4.0, 2.0, 1.0], [2.0, 0.5, -0.3]),
                s3([0.0, 0.0, 3.0], [-1.0, -1.5, 0.2]),
                s3([1.0, 2.0, 3.0], [0.9, -0.8, 0.7]),
            ),
        ];
        for (xi, xj, m) in cases {
            let (r, ji, jj) = S3::linearize(&xi, &xj, &m);
            assert!((r - S3::residual(&xi, &xj, &m)).norm() < 1e-12);
            let (ni, nj) = numeric::<6, S3>(&xi, &xj, &m);
            // Central differences with h = 1e-6 are good to ~1e-8 on O(1) entries.
            assert!((ji - ni).abs().max() < 1e-6, "J_i\n{ji}\nnumeric\n{ni}");
            assert!((jj - nj).abs().max() < 1e-6, "J_j\n{jj}\nnumeric\n{nj}");
        }
    }

    #[test]
    fn se2_jacobians_match_numerical_differentiation() {
        let cases = [
            (
                S2 {
                    p: Vector2::new(0.0, 0.0),
                    th: 0.0,
                },
                S2 {
                    p: Vector2::new(1.0, 0.5),
                    th: 0.3,
                },
                S2 {
                    p: Vector2::new(0.9, 0.4),
                    th: 0.2,
                },
            ),
            (
                S2 {
                    p: Vector2::new(-3.0, 2.0),
                    th: 2.5,
                },
                S2 {
                    p: Vector2::new(1.0, -4.0),
                    th: -2.9,
                },
                S2 {
                    p: Vector2::new(2.0, 1.0),
                    th: 1.0,
                },
            ),
        ];
        for (xi, xj, m) in cases {
            let (r, ji, jj) = S2::linearize(&xi, &xj, &m);
            assert!((r - S2::residual(&xi, &xj, &m)).norm() < 1e-12);
            let (ni, nj) = numeric::<3, S2>(&xi, &xj, &m);
            assert!((ji - ni).abs().max() < 1e-6, "J_i\n{ji}\nnumeric\n{ni}");
            assert!((jj - nj).abs().max() < 1e-6, "J_j\n{jj}\nnumeric\n{nj}");
        }
    }

    #[test]
    fn log_quat_inverts_exp_up_to_pi() {
        for v in [
            [1e-12, 0.0, 0.0],
            [0.1, -0.2, 0.3],
            [0.0, 3.0, 0.0],
            [1.0, 1.0, -2.5],
        ] {
            let v = Vector3::from(v);
            let q = UnitQuaternion::from_scaled_axis(v);
            assert!((log_quat(&q) - v).norm() < 1e-12, "{v}");
            // The other sign of the same rotation gives the same vector.
            let neg = UnitQuaternion::new_unchecked(-q.into_inner());
            assert!((log_quat(&neg) - v).norm() < 1e-12);
        }
    }
}
