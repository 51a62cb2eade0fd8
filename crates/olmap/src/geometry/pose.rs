//! The rigid transform type [`Pose`].

use std::fmt;
use std::ops::Mul;

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Point3, Rotation3, Translation3, UnitQuaternion, Vector3,
};

use super::euler::{rotation_from_yaw_pitch_roll, yaw_pitch_roll_from_rotation};
use crate::error::{Error, Result};

/// A rigid transform `T_a_b` of 3D space (rotation then translation): `p_a = R p_b + t`.
///
/// `Pose` is a thin wrapper over nalgebra's [`Isometry3<f64>`] that adds olmap's
/// conventions: ZYX Euler angles, row-major 3x4 / 4x4 matrices as they appear in files,
/// and a checked conversion from matrices read from disk.
///
/// ```
/// use olmap::geometry::Pose;
/// use nalgebra::Point3;
/// // The scanner sits 1 m ahead of the robot and is turned 90 degrees to the left.
/// let t_robot_scanner = Pose::from_xyz_ypr(1.0, 0.0, 0.0, 90f64.to_radians(), 0.0, 0.0);
/// // A return 2 m in front of the scanner is 2 m to the left of the scanner in the robot frame.
/// let p = t_robot_scanner.transform_point(&Point3::new(2.0, 0.0, 0.0));
/// assert!((p - Point3::new(1.0, 2.0, 0.0)).norm() < 1e-12);
/// // Composition and inverse.
/// let identity = t_robot_scanner.inverse() * t_robot_scanner;
/// assert!(identity.translation().norm() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    iso: Isometry3<f64>,
}

impl Default for Pose {
    fn default() -> Self {
        Self::identity()
    }
}

impl Pose {
    /// The identity transform.
    pub fn identity() -> Self {
        Pose {
            iso: Isometry3::identity(),
        }
    }

    /// A pose from an nalgebra isometry.
    pub fn from_isometry(iso: Isometry3<f64>) -> Self {
        Pose { iso }
    }

    /// A pose from a translation and a rotation.
    pub fn from_parts(translation: Vector3<f64>, rotation: UnitQuaternion<f64>) -> Self {
        Pose {
            iso: Isometry3::from_parts(Translation3::from(translation), rotation),
        }
    }

    /// A pose from a translation and a rotation matrix (assumed orthonormal).
    pub fn from_rotation_translation(rotation: &Rotation3<f64>, translation: Vector3<f64>) -> Self {
        Self::from_parts(translation, UnitQuaternion::from_rotation_matrix(rotation))
    }

    /// A pose from a translation (metres) and ZYX Euler angles (radians).
    pub fn from_xyz_ypr(x: f64, y: f64, z: f64, yaw: f64, pitch: f64, roll: f64) -> Self {
        Self::from_rotation_translation(
            &rotation_from_yaw_pitch_roll(yaw, pitch, roll),
            Vector3::new(x, y, z),
        )
    }

    /// A pure translation.
    pub fn from_translation(t: Vector3<f64>) -> Self {
        Self::from_parts(t, UnitQuaternion::identity())
    }

    /// A pose from a row-major 3x4 matrix `[r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz]`
    /// as found in pose files.
    ///
    /// The 3x3 block must be a rotation up to `tolerance` (max absolute deviation of
    /// `R^T R` from the identity, and `det R > 0`); files store rotations with a few decimals,
    /// so the block is projected onto the nearest rotation (polar decomposition).
    pub fn from_row_major_3x4(m: &[f64; 12], tolerance: f64) -> Result<Self> {
        let r = Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
        let t = Vector3::new(m[3], m[7], m[11]);
        Self::from_matrix_parts(&r, t, tolerance)
    }

    /// A pose from a 4x4 homogeneous matrix; see [`Pose::from_row_major_3x4`] for the check.
    /// The bottom row must be `0 0 0 1` (to `tolerance`).
    pub fn from_matrix4(m: &Matrix4<f64>, tolerance: f64) -> Result<Self> {
        let bottom = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)] - 1.0];
        if bottom.iter().any(|v| !v.is_finite() || v.abs() > tolerance) {
            return Err(Error::InvalidArgument(format!(
                "the bottom row of a rigid transform must be 0 0 0 1, found {} {} {} {}",
                m[(3, 0)],
                m[(3, 1)],
                m[(3, 2)],
                m[(3, 3)]
            )));
        }
        let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
        let t = Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
        Self::from_matrix_parts(&r, t, tolerance)
    }

    fn from_matrix_parts(r: &Matrix3<f64>, t: Vector3<f64>, tolerance: f64) -> Result<Self> {
        if r.iter().chain(t.iter()).any(|v| !v.is_finite()) {
            return Err(Error::InvalidArgument(
                "transform contains a non-finite number".into(),
            ));
        }
        let deviation = (r.transpose() * r - Matrix3::identity()).abs().max();
        if deviation > tolerance || r.determinant() <= 0.0 {
            return Err(Error::InvalidArgument(format!(
                "not a rotation matrix (|R^T R - I| = {deviation:.3e}, det = {:.6}; tolerance {tolerance:.1e})",
                r.determinant()
            )));
        }
        // Nearest rotation in the Frobenius sense (polar decomposition by SVD).
        let svd = r.svd(true, true);
        let (u, v_t) = (svd.u.expect("requested"), svd.v_t.expect("requested"));
        let mut d = Matrix3::identity();
        d[(2, 2)] = (u * v_t).determinant().signum();
        let rot = Rotation3::from_matrix_unchecked(u * d * v_t);
        Ok(Self::from_rotation_translation(&rot, t))
    }

    /// The underlying nalgebra isometry.
    pub fn isometry(&self) -> &Isometry3<f64> {
        &self.iso
    }

    /// The translation part `t`.
    pub fn translation(&self) -> Vector3<f64> {
        self.iso.translation.vector
    }

    /// The rotation part as a unit quaternion.
    pub fn rotation(&self) -> UnitQuaternion<f64> {
        self.iso.rotation
    }

    /// The rotation part as a 3x3 rotation matrix.
    pub fn rotation_matrix(&self) -> Rotation3<f64> {
        self.iso.rotation.to_rotation_matrix()
    }

    /// ZYX Euler angles `(yaw, pitch, roll)` in radians.
    pub fn yaw_pitch_roll(&self) -> (f64, f64, f64) {
        yaw_pitch_roll_from_rotation(&self.rotation_matrix())
    }

    /// The 4x4 homogeneous matrix.
    pub fn to_matrix4(&self) -> Matrix4<f64> {
        self.iso.to_homogeneous()
    }

    /// The row-major 3x4 matrix `[r00 r01 r02 tx r10 ... tz]`.
    pub fn to_row_major_3x4(&self) -> [f64; 12] {
        let m = self.to_matrix4();
        let mut out = [0.0; 12];
        for r in 0..3 {
            for c in 0..4 {
                out[4 * r + c] = m[(r, c)];
            }
        }
        out
    }

    /// The inverse transform `T_b_a` of `T_a_b`.
    pub fn inverse(&self) -> Self {
        Pose {
            iso: self.iso.inverse(),
        }
    }

    /// Maps a point of frame b into frame a.
    pub fn transform_point(&self, p: &Point3<f64>) -> Point3<f64> {
        self.iso.transform_point(p)
    }

    /// Maps a single-precision point (the storage type of clouds), computing in f64.
    pub fn transform_point_f32(&self, p: &Point3<f32>) -> Point3<f32> {
        let q = self.iso.transform_point(&p.cast::<f64>());
        q.cast::<f32>()
    }

    /// Rotates a direction vector (no translation).
    pub fn transform_vector(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.iso.rotation * v
    }
}

impl Mul for Pose {
    type Output = Pose;
    /// Composition: `T_a_b * T_b_c = T_a_c`.
    fn mul(self, rhs: Pose) -> Pose {
        Pose {
            iso: self.iso * rhs.iso,
        }
    }
}

impl Mul<&Pose> for &Pose {
    type Output = Pose;
    fn mul(self, rhs: &Pose) -> Pose {
        Pose {
            iso: self.iso * rhs.iso,
        }
    }
}

impl From<Isometry3<f64>> for Pose {
    fn from(iso: Isometry3<f64>) -> Self {
        Pose { iso }
    }
}

impl fmt::Display for Pose {
    /// `t=(x, y, z) m, yaw/pitch/roll = a/b/c deg`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = self.translation();
        let (y, p, r) = self.yaw_pitch_roll();
        write!(
            f,
            "t=({:.4}, {:.4}, {:.4}) m, yaw/pitch/roll = {:.3}/{:.3}/{:.3} deg",
            t.x,
            t.y,
            t.z,
            y.to_degrees(),
            p.to_degrees(),
            r.to_degrees()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn composition_is_associative_and_inverse_cancels() {
        let a = Pose::from_xyz_ypr(1.0, 2.0, 3.0, 0.3, -0.2, 0.1);
        let b = Pose::from_xyz_ypr(-0.5, 0.2, 0.0, -1.0, 0.4, 0.9);
        let c = Pose::from_xyz_ypr(0.0, 0.0, 2.0, 2.0, 0.0, -0.3);
        let p = Point3::new(0.3, -1.2, 4.0);
        let left = ((a * b) * c).transform_point(&p);
        let right = (a * (b * c)).transform_point(&p);
        assert!((left - right).norm() < 1e-12);
        let back = (a.inverse() * a).transform_point(&p);
        assert!((back - p).norm() < 1e-12);
        // T_a_b * T_b_c applies T_b_c first.
        let seq = a.transform_point(&b.transform_point(&p));
        assert!((seq - (a * b).transform_point(&p)).norm() < 1e-12);
    }

    #[test]
    fn matrix_round_trip() {
        let a = Pose::from_xyz_ypr(1.0, 2.0, 3.0, 0.3, -0.2, 0.1);
        let m = a.to_row_major_3x4();
        let b = Pose::from_row_major_3x4(&m, 1e-9).unwrap();
        assert!((a.to_matrix4() - b.to_matrix4()).abs().max() < 1e-12);
        let c = Pose::from_matrix4(&a.to_matrix4(), 1e-9).unwrap();
        assert!((a.to_matrix4() - c.to_matrix4()).abs().max() < 1e-12);
    }

    #[test]
    fn rejects_non_rotations() {
        let mut m = Pose::identity().to_row_major_3x4();
        m[0] = 2.0;
        assert!(Pose::from_row_major_3x4(&m, 1e-3).is_err());
        // A reflection is not a rotation.
        let mut m = Pose::identity().to_row_major_3x4();
        m[0] = -1.0;
        assert!(Pose::from_row_major_3x4(&m, 1e-3).is_err());
        let mut m = Pose::identity().to_row_major_3x4();
        m[3] = f64::NAN;
        assert!(Pose::from_row_major_3x4(&m, 1e-3).is_err());
    }

    #[test]
    fn six_decimal_rotation_is_projected() {
        // Rows as printed with six decimals are slightly off orthonormal.
        let m = [
            0.999837, -0.012424, 0.013111, 1.56796, 0.012480, 0.999913, -0.004217, 0.036331,
            -0.013058, 0.004380, 0.999905, -0.090831,
        ];
        let p = Pose::from_row_major_3x4(&m, 1e-4).unwrap();
        let r = p.rotation_matrix();
        assert!(
            (r.matrix().transpose() * r.matrix() - Matrix3::identity())
                .abs()
                .max()
                < 1e-12
        );
        assert!((r.matrix()[(0, 1)] + 0.012424).abs() < 1e-5);
    }
}
