//! Error metrics between an estimated pose and a reference pose.

use super::euler::wrap_angle;
use super::pose::Pose;

/// How far an estimated pose is from a reference pose.
///
/// Translation errors are differences of the translation parts (in the parent frame of
/// both poses); the rotation error is the angle of `R_ref^T R_est`; the per-axis angle
/// errors are wrapped differences of the ZYX Euler angles (estimate minus reference).
///
/// ```
/// use olmap::geometry::{Pose, PoseError};
/// let reference = Pose::from_xyz_ypr(1.0, 0.0, 0.0, 0.0, 0.0, 0.0);
/// let estimate = Pose::from_xyz_ypr(1.03, 0.04, 0.0, 2f64.to_radians(), 0.0, 0.0);
/// let e = PoseError::between(&estimate, &reference);
/// assert!((e.translation_m - 0.05).abs() < 1e-12);
/// assert!((e.rotation_deg - 2.0).abs() < 1e-9);
/// assert!((e.yaw_deg - 2.0).abs() < 1e-9);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseError {
    /// Euclidean distance between the two translations, metres.
    pub translation_m: f64,
    /// Per-axis translation difference (estimate - reference), metres.
    pub dx_m: f64,
    /// See `dx_m`.
    pub dy_m: f64,
    /// See `dx_m`.
    pub dz_m: f64,
    /// Angle of the relative rotation `R_ref^T R_est`, degrees, in `[0, 180]`.
    pub rotation_deg: f64,
    /// Yaw difference (estimate - reference), degrees, wrapped to `(-180, 180]`.
    pub yaw_deg: f64,
    /// Pitch difference, degrees.
    pub pitch_deg: f64,
    /// Roll difference, degrees, wrapped.
    pub roll_deg: f64,
}

impl PoseError {
    /// The error of `estimate` against `reference`.
    pub fn between(estimate: &Pose, reference: &Pose) -> Self {
        let d = estimate.translation() - reference.translation();
        let rel = reference.rotation().inverse() * estimate.rotation();
        let (ye, pe, re) = estimate.yaw_pitch_roll();
        let (yr, pr, rr) = reference.yaw_pitch_roll();
        PoseError {
            translation_m: d.norm(),
            dx_m: d.x,
            dy_m: d.y,
            dz_m: d.z,
            rotation_deg: rel.angle().to_degrees(),
            yaw_deg: wrap_angle(ye - yr).to_degrees(),
            pitch_deg: wrap_angle(pe - pr).to_degrees(),
            roll_deg: wrap_angle(re - rr).to_degrees(),
        }
    }
}
