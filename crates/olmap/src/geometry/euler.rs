//! ZYX Euler angles (yaw, pitch, roll) to and from rotation matrices.

use nalgebra::{Matrix3, Rotation3};

/// The rotation `R = Rz(yaw) Ry(pitch) Rx(roll)` (angles in radians).
///
/// ```
/// use olmap::geometry::{rotation_from_yaw_pitch_roll, yaw_pitch_roll_from_rotation};
/// let r = rotation_from_yaw_pitch_roll(0.3, -0.2, 0.1);
/// let (y, p, ro) = yaw_pitch_roll_from_rotation(&r);
/// assert!((y - 0.3).abs() < 1e-12 && (p + 0.2).abs() < 1e-12 && (ro - 0.1).abs() < 1e-12);
/// ```
pub fn rotation_from_yaw_pitch_roll(yaw: f64, pitch: f64, roll: f64) -> Rotation3<f64> {
    let (sy, cy) = yaw.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sr, cr) = roll.sin_cos();
    // Rz(yaw) * Ry(pitch) * Rx(roll), written out.
    let m = Matrix3::new(
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        -sp,
        cp * sr,
        cp * cr,
    );
    Rotation3::from_matrix_unchecked(m)
}

/// The ZYX Euler angles `(yaw, pitch, roll)` of a rotation, in radians:
/// `yaw = atan2(R10, R00)`, `pitch = -asin(R20)`, `roll = atan2(R21, R22)`.
///
/// Yaw and roll are in `(-pi, pi]`, pitch in `[-pi/2, pi/2]`. At pitch = +-90 degrees
/// (gimbal lock) yaw and roll are not unique; the formulas above still return finite values.
pub fn yaw_pitch_roll_from_rotation(r: &Rotation3<f64>) -> (f64, f64, f64) {
    let m = r.matrix();
    let yaw = m[(1, 0)].atan2(m[(0, 0)]);
    let pitch = -m[(2, 0)].clamp(-1.0, 1.0).asin();
    let roll = m[(2, 1)].atan2(m[(2, 2)]);
    (yaw, pitch, roll)
}

/// Wraps an angle (radians) into `(-pi, pi]`.
pub fn wrap_angle(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let w = a.rem_euclid(TAU);
    if w > PI {
        w - TAU
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_nalgebra_convention() {
        // nalgebra's from_euler_angles(roll, pitch, yaw) is also Rz * Ry * Rx.
        for &(y, p, r) in &[(0.1, 0.2, 0.3), (-2.5, 1.2, -0.7), (3.0, -1.4, 2.9)] {
            let ours = rotation_from_yaw_pitch_roll(y, p, r);
            let theirs = Rotation3::from_euler_angles(r, p, y);
            assert!((ours.matrix() - theirs.matrix()).abs().max() < 1e-12);
            let (y2, p2, r2) = yaw_pitch_roll_from_rotation(&ours);
            assert!((y - y2).abs() < 1e-12 && (p - p2).abs() < 1e-12 && (r - r2).abs() < 1e-12);
        }
    }

    #[test]
    fn elementary_rotations() {
        // A pure yaw of 90 degrees takes x to y.
        let r = rotation_from_yaw_pitch_roll(std::f64::consts::FRAC_PI_2, 0.0, 0.0);
        let v = r * nalgebra::Vector3::x();
        assert!((v - nalgebra::Vector3::y()).norm() < 1e-12);
        // A positive pitch takes x towards -z (nose down): Ry(p) * x = (cos p, 0, -sin p).
        let r = rotation_from_yaw_pitch_roll(0.0, 0.3, 0.0);
        let v = r * nalgebra::Vector3::x();
        assert!((v.z + 0.3f64.sin()).abs() < 1e-12);
    }

    #[test]
    fn wrap() {
        use std::f64::consts::PI;
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(0.5) - 0.5).abs() < 1e-15);
        assert!((wrap_angle(-0.5 - 4.0 * PI) + 0.5).abs() < 1e-12);
    }
}
