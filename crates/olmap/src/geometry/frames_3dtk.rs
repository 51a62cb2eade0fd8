//! Conversions between 3DTK's left-handed centimetre frame and olmap's right-handed metres.
//!
//! 3DTK (slam6D) stores points and poses in a scanner frame that is **left-handed, y up,
//! z forward, x to the right, in centimetres**. olmap uses right-handed metres with x forward,
//! y left, z up. The change of axes is `P = [[0,0,1],[-1,0,0],[0,1,0]]`:
//! `x_rh = z_lh/100`, `y_rh = -x_lh/100`, `z_rh = y_lh/100` (the mapping of 3DTK's own
//! `toRieglMat()`); rotations convert as `R_rh = P R_lh P^T` (a proper rotation although
//! `det P = -1`) and translations as `t_rh = P t_lh / 100`.

use nalgebra::{Matrix3, Matrix4, Point3, Vector3};

use super::pose::Pose;
use crate::error::Result;

fn p_matrix() -> Matrix3<f64> {
    Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
}

/// A 3DTK point (left-handed cm) in olmap's right-handed metres.
///
/// ```
/// use olmap::geometry::point_rh_m_from_3dtk_cm;
/// // 100 cm to the right (x_lh), 50 cm up (y_lh), 300 cm ahead (z_lh):
/// let p = point_rh_m_from_3dtk_cm([100.0, 50.0, 300.0]);
/// assert_eq!((p.x, p.y, p.z), (3.0, -1.0, 0.5));
/// ```
pub fn point_rh_m_from_3dtk_cm(p: [f64; 3]) -> Point3<f64> {
    Point3::new(p[2] / 100.0, -p[0] / 100.0, p[1] / 100.0)
}

/// The inverse of [`point_rh_m_from_3dtk_cm`].
pub fn point_3dtk_cm_from_rh_m(p: &Point3<f64>) -> [f64; 3] {
    [-p.y * 100.0, p.z * 100.0, p.x * 100.0]
}

/// A 3DTK pose matrix (4x4, left-handed, translation in cm) as an olmap [`Pose`].
///
/// The rotation block is checked to be a rotation within `tolerance` (see
/// [`Pose::from_matrix4`]); 3DTK writes six significant digits, so `1e-4` is a good value.
pub fn pose_rh_m_from_3dtk_cm(m_lh_cm: &Matrix4<f64>, tolerance: f64) -> Result<Pose> {
    let p = p_matrix();
    let r_lh: Matrix3<f64> = m_lh_cm.fixed_view::<3, 3>(0, 0).into_owned();
    let t_lh = Vector3::new(m_lh_cm[(0, 3)], m_lh_cm[(1, 3)], m_lh_cm[(2, 3)]);
    let r_rh = p * r_lh * p.transpose();
    let t_rh = p * t_lh / 100.0;
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&r_rh);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&t_rh);
    for c in 0..4 {
        m[(3, c)] = m_lh_cm[(3, c)];
    }
    Pose::from_matrix4(&m, tolerance)
}

/// An olmap [`Pose`] as a 3DTK pose matrix (4x4, left-handed, translation in cm).
pub fn pose_3dtk_cm_from_rh_m(pose: &Pose) -> Matrix4<f64> {
    let p = p_matrix();
    let r_rh = *pose.rotation_matrix().matrix();
    let r_lh = p.transpose() * r_rh * p;
    let t_lh = p.transpose() * pose.translation() * 100.0;
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&r_lh);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&t_lh);
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_conversion_agrees_with_point_conversion() {
        // Transforming points in 3DTK's frame and then converting must equal converting and
        // then applying the converted pose.
        let pose_rh = Pose::from_xyz_ypr(1.5, 0.03, -0.09, 0.0125, 0.013, 0.0044);
        let m_lh = pose_3dtk_cm_from_rh_m(&pose_rh);
        let back = pose_rh_m_from_3dtk_cm(&m_lh, 1e-9).unwrap();
        assert!((back.to_matrix4() - pose_rh.to_matrix4()).abs().max() < 1e-12);
        let p_lh = [120.0, -35.0, 870.0];
        let moved_lh = m_lh * nalgebra::Vector4::new(p_lh[0], p_lh[1], p_lh[2], 1.0);
        let a = point_rh_m_from_3dtk_cm([moved_lh.x, moved_lh.y, moved_lh.z]);
        let b = pose_rh.transform_point(&point_rh_m_from_3dtk_cm(p_lh));
        assert!((a - b).norm() < 1e-12);
        let q = point_3dtk_cm_from_rh_m(&point_rh_m_from_3dtk_cm(p_lh));
        assert!((0..3).all(|i| (q[i] - p_lh[i]).abs() < 1e-9));
    }
}
