//! Rotating-mirror 3D laser scanners (thesis §4.3): their geometry and their raw logs.
//!
//! A 2D laser scanner (a SICK LMS 200) sweeps its beam through a plane; a mirror turning
//! about an axis in front of it (or above it, for the enhanced scanner) tilts that plane to
//! a new elevation for every sweep, so the sweeps together cover 3D.
//!
//! ## Frames and angles
//! * **2D scanner frame** (subscript L): origin at the 2D scanner's optical centre, x
//!   toward the mirror (the centre of the scanner's fan), y to the left in the scan plane,
//!   z completing a right-handed frame. A beam leaves at the scan angle `theta` measured
//!   from x toward y: direction `(cos theta, sin theta, 0)`.
//! * **Mirror**: a flat mirror turning about the axis parallel to y through `(d, 0, 0)`,
//!   `d` = [`MirrorGeometry::mirror_offset`]. The **mirror angle** `alpha` is the angle
//!   between L's x axis and the mirror surface's line in the xz plane, measured from x
//!   toward z: the mirror surface contains y and `(cos alpha, 0, sin alpha)` and its normal
//!   is `(sin alpha, 0, -cos alpha)`. At `alpha = 0` the mirror is edge on (the beams run
//!   along its surface); at `alpha = 45°` it sends the beams straight up; at `alpha = 90°`
//!   it faces the scanner and sends the beams back into it.
//! * **Reflected elevation** `phi = 2 alpha` (the reflected ray turns twice as fast as the
//!   mirror, thesis (4.7)). A beam at `theta` (with `cos theta > 0`) meets the mirror on its
//!   axis line at `(d, d tan theta, 0)` whatever `alpha` is, after travelling
//!   `d / cos theta`; the reflected ray leaves with direction
//!   `(cos theta cos phi, sin theta, cos theta sin phi)`. A measured range `r` (the whole
//!   optical path) therefore maps to thesis equation (4.10):
//!   `p_L = ((r cos theta - d) cos phi + d, r sin theta, (r cos theta - d) sin phi)`.
//! * **Sensor frame** (subscript S, the frame of the 3D scan): origin at the 2D scanner's
//!   optical centre. With [`Mounting::Standard`] (mirror in front, 2D scanner horizontal) it
//!   is the 2D scanner frame: `p_S = p_L`. With [`Mounting::Enhanced`] the 2D scanner faces
//!   up into the mirror above it and its frame is turned -90° about y (thesis §4.3.3, "the
//!   resulting point cloud is rotated 90° about the y-axis"):
//!   `p_S = R_y(-90°) p_L = (-z_L, y_L, x_L)`, so L's x (toward the mirror) is S's +z (up),
//!   L's z is S's -x (backward), and y is shared. The mirror axis is then the horizontal
//!   line parallel to S's y at height `d`; the reflected plane turns about it, the edge-on
//!   blind spot points straight up and the reflected beam points forward (+x_S) at
//!   `phi = 270°`.
//! * **Mirror time**: the mirror turns at constant speed,
//!   `alpha(t) = start_phase + 2 pi t / period`. A single-sided mirror only reflects on its
//!   front half-turn, `sin alpha > 0` (`phi` runs once through a full turn); a
//!   double-sided one reflects on both and gives two 3D scans per revolution.
//!
//! Beams that do not reach the mirror (`|theta|` above [`MirrorGeometry::theta_limit`]),
//! beams that meet the mirror nearly edge on ([`MirrorGeometry::edge_on_margin`]) and
//! beams reflected back toward the scanner (`phi` within [`MirrorGeometry::back_margin`] of
//! 180°) give no measurement: [`MirrorGeometry::reflects`].

mod convert;
mod error_model;
mod pixel_mixing;
mod raw_log;
mod repeatability;
mod report;
mod triangulation;

pub use convert::{convert_log, ConvertParams, ConvertStats, ConvertedScan, EncoderHistory};
pub use error_model::{cartesian_error, digitisation_error, update_rate_error};
pub use pixel_mixing::{mixed_pixels, MixedPixelParams, RangeImage};
pub use raw_log::{MirrorEvent, MirrorEventKind, MirrorLog, Sweep};
pub use repeatability::{repeatability, RepeatabilityParams, RepeatabilityReport};
pub use report::{DroppedReport, ScannerConvertReport};
pub use triangulation::{
    intersect_ray_plane, optimal_baseline, triangulate_2d, triangulate_pixel,
    triangulation_range_error, LaserPlane, PinholeIntrinsics, Ray,
};

use nalgebra::{Point3, Rotation3, Vector3};

use crate::error::{Error, Result};

/// How the 2D scanner and the mirror sit on the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mounting {
    /// First generation (§4.3.1): the 2D scanner horizontal, the mirror in front of it;
    /// the sensor frame is the 2D scanner frame.
    Standard,
    /// Enhanced scanner (§4.3.3): the 2D scanner faces up into the mirror above it; the
    /// sensor frame is the 2D scanner frame turned -90° about y (`p_S = (-z_L, y_L, x_L)`).
    Enhanced,
}

impl Mounting {
    /// The name used in raw logs (`standard`, `enhanced`).
    pub fn name(self) -> &'static str {
        match self {
            Mounting::Standard => "standard",
            Mounting::Enhanced => "enhanced",
        }
    }

    /// Parses [`Mounting::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "standard" => Some(Mounting::Standard),
            "enhanced" => Some(Mounting::Enhanced),
            _ => None,
        }
    }
}

/// The geometry of a rotating-mirror scanner: everything needed to turn its raw log into
/// points (see the [module documentation](self) for the frames and angles).
#[derive(Debug, Clone, PartialEq)]
pub struct MirrorGeometry {
    /// Standard or enhanced mounting.
    pub mounting: Mounting,
    /// `d`: distance from the 2D scanner's optical centre to the mirror axis, metres.
    pub mirror_offset: f64,
    /// Reflecting sides of the mirror: 1 (front half-turn only) or 2.
    pub sides: u8,
    /// Encoder ticks per mirror revolution (gearing `r_g` times teeth `b`, thesis (4.8)).
    /// Tick `k` is at mirror angle `2 pi k / ticks_per_revolution`.
    pub ticks_per_revolution: u32,
    /// Mirror angle at which the once-per-revolution trigger fires, radians.
    pub trigger_angle: f64,
    /// Scan angle of the 2D scanner's first beam, radians.
    pub scan_angle_min: f64,
    /// Angle between consecutive beams of the 2D scanner, radians.
    pub scan_angle_step: f64,
    /// Beams per 2D sweep.
    pub scan_beams: usize,
    /// Beams with `|theta|` above this (radians, below 90°) miss the mirror.
    pub theta_limit: f64,
    /// Beams are dropped while the mirror is within this angle of edge on
    /// (`|sin alpha| < sin(edge_on_margin)`), radians.
    pub edge_on_margin: f64,
    /// Beams are dropped when reflected within this angle of straight back into the
    /// scanner (`|phi - 180°| < back_margin`), radians.
    pub back_margin: f64,
    /// Largest range the 2D scanner reports, metres.
    pub max_range: f64,
}

/// Where a beam leaves the mirror (sensor frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MirrorBeam {
    /// The point where the beam meets the mirror, sensor frame.
    pub origin: Point3<f64>,
    /// Unit direction of the reflected beam, sensor frame.
    pub direction: Vector3<f64>,
    /// Path length from the 2D scanner to the mirror, `d / cos theta`, metres.
    pub path_to_mirror: f64,
}

impl MirrorGeometry {
    /// The first-generation scanner (§4.3.1-4.3.2): LMS 200 horizontal, 180° at 1° (181
    /// beams) of which ±60° reach the mirror, 8 m range (millimetre mode), mirror axis 0.1 m
    /// in front of the scanner, double-sided mirror, encoder of `r_g b = 25 x 14 = 350`
    /// ticks per revolution, trigger at mirror angle 0.3 rad, edge-on margin 5°, back
    /// margin 15°.
    pub fn standard() -> Self {
        MirrorGeometry {
            mounting: Mounting::Standard,
            mirror_offset: 0.1,
            sides: 2,
            ticks_per_revolution: 25 * 14,
            trigger_angle: 0.3,
            scan_angle_min: -90f64.to_radians(),
            scan_angle_step: 1f64.to_radians(),
            scan_beams: 181,
            theta_limit: 60f64.to_radians(),
            edge_on_margin: 5f64.to_radians(),
            back_margin: 15f64.to_radians(),
            max_range: 8.0,
        }
    }

    /// The enhanced scanner (§4.3.3): LMS 200 facing up, 180° at 1°, ±65° reaching the
    /// mirror (thesis (4.11): 25° < theta < 155° in the scanner's own 0-180° convention),
    /// 8 m range, mirror axis 0.1 m above the scanner, double-sided mirror on a stepper
    /// motor of 400 half-steps per revolution (the encoder ticks), trigger at mirror angle
    /// 0.3 rad, edge-on margin 5°, back margin 15°.
    pub fn enhanced() -> Self {
        MirrorGeometry {
            mounting: Mounting::Enhanced,
            ticks_per_revolution: 400,
            theta_limit: 65f64.to_radians(),
            ..Self::standard()
        }
    }

    /// Checks that the values make sense (positive sizes, 1 or 2 sides, a theta limit
    /// below 90°).
    pub fn validate(&self) -> Result<()> {
        let bad = |what: &str| Err(Error::InvalidArgument(format!("mirror geometry: {what}")));
        if !(self.mirror_offset.is_finite() && self.mirror_offset >= 0.0) {
            return bad("mirror_offset must be finite and >= 0");
        }
        if self.sides != 1 && self.sides != 2 {
            return bad("sides must be 1 or 2");
        }
        if self.ticks_per_revolution == 0 {
            return bad("ticks_per_revolution must be > 0");
        }
        let angles_ok = self.trigger_angle.is_finite()
            && self.scan_angle_min.is_finite()
            && self.scan_angle_step.is_finite()
            && self.scan_angle_step > 0.0;
        if !angles_ok {
            return bad("trigger and scan angles must be finite, the step > 0");
        }
        if self.scan_beams == 0 {
            return bad("scan_beams must be > 0");
        }
        if !(self.theta_limit > 0.0 && self.theta_limit < std::f64::consts::FRAC_PI_2) {
            return bad("theta_limit must be in (0, pi/2)");
        }
        if !(self.edge_on_margin >= 0.0 && self.back_margin >= 0.0) {
            return bad("margins must be >= 0");
        }
        if self.max_range.is_nan() || self.max_range <= 0.0 {
            return bad("max_range must be > 0");
        }
        Ok(())
    }

    /// Scan angle `theta` of beam `i` of a sweep.
    pub fn scan_angle(&self, i: usize) -> f64 {
        self.scan_angle_min + i as f64 * self.scan_angle_step
    }

    /// The reflected elevation `phi = 2 alpha` for a mirror angle `alpha`.
    pub fn reflected_elevation(mirror_angle: f64) -> f64 {
        2.0 * mirror_angle
    }

    /// `R_S_L`: the rotation from the 2D scanner frame into the sensor frame.
    pub fn scanner_to_sensor(&self) -> Rotation3<f64> {
        match self.mounting {
            Mounting::Standard => Rotation3::identity(),
            Mounting::Enhanced => {
                Rotation3::from_axis_angle(&Vector3::y_axis(), -std::f64::consts::FRAC_PI_2)
            }
        }
    }

    /// Whether the beam at scan angle `theta` is reflected into the world at mirror angle
    /// `alpha` (it reaches the mirror, the mirror is not near edge on, the beam is not sent
    /// back into the scanner, and a single-sided mirror shows its front).
    pub fn reflects(&self, theta: f64, mirror_angle: f64) -> bool {
        if !(theta.abs() <= self.theta_limit && theta.cos() > 0.0) {
            return false;
        }
        let s = mirror_angle.sin();
        if s.abs() < self.edge_on_margin.sin() || (self.sides == 1 && s <= 0.0) {
            return false;
        }
        let phi = Self::reflected_elevation(mirror_angle);
        let from_back = crate::geometry::wrap_angle(phi - std::f64::consts::PI).abs();
        from_back >= self.back_margin
    }

    /// The reflected beam (sensor frame) for scan angle `theta` at mirror angle `alpha`,
    /// `None` when [`MirrorGeometry::reflects`] says the beam gives no measurement.
    pub fn beam(&self, theta: f64, mirror_angle: f64) -> Option<MirrorBeam> {
        if !self.reflects(theta, mirror_angle) {
            return None;
        }
        let d = self.mirror_offset;
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = Self::reflected_elevation(mirror_angle).sin_cos();
        let r = self.scanner_to_sensor();
        Some(MirrorBeam {
            origin: r * Point3::new(d, d * st / ct, 0.0),
            direction: r * Vector3::new(ct * cp, st, ct * sp),
            path_to_mirror: d / ct,
        })
    }

    /// Thesis equation (4.10), in the sensor frame: the point measured at range `r` (the
    /// whole optical path), scan angle `theta` and mirror angle `alpha`.
    pub fn point(&self, range: f64, theta: f64, mirror_angle: f64) -> Point3<f64> {
        let d = self.mirror_offset;
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = Self::reflected_elevation(mirror_angle).sin_cos();
        let q = range * ct - d;
        self.scanner_to_sensor() * Point3::new(q * cp + d, range * st, q * sp)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Reflects `u` across the plane through the mirror axis at mirror angle `alpha`.
    fn reflect(u: Vector3<f64>, alpha: f64) -> Vector3<f64> {
        let n = Vector3::new(alpha.sin(), 0.0, -alpha.cos());
        u - 2.0 * u.dot(&n) * n
    }

    #[test]
    fn beam_is_the_mirror_reflection_and_matches_4_10() {
        let mut g = MirrorGeometry::standard();
        g.sides = 2;
        g.edge_on_margin = 0.0;
        g.back_margin = 0.0;
        for &alpha in &[0.1, 0.5, 1.0, 1.4, 2.0, 2.9, -0.7, 4.0] {
            for &theta in &[-1.0, -0.3, 0.0, 0.2, 0.9] {
                let b = g.beam(theta, alpha).unwrap();
                let u = Vector3::new(theta.cos(), theta.sin(), 0.0);
                // The incoming beam meets the mirror plane at the origin of the reflection.
                let hit = Point3::origin() + u * b.path_to_mirror;
                assert!((hit - b.origin).norm() < 1e-12);
                let n = Vector3::new(alpha.sin(), 0.0, -alpha.cos());
                assert!((hit - Point3::new(g.mirror_offset, 0.0, 0.0)).dot(&n).abs() < 1e-12);
                assert!((reflect(u, alpha) - b.direction).norm() < 1e-12);
                // Equation (4.10) is the unfolded point at the whole path length.
                for &s in &[0.5, 3.0] {
                    let r = b.path_to_mirror + s;
                    let p = g.point(r, theta, alpha);
                    assert!((p - (b.origin + b.direction * s)).norm() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn enhanced_frame_faces_up() {
        let g = MirrorGeometry::enhanced();
        let r = g.scanner_to_sensor();
        assert!((r * Vector3::x() - Vector3::z()).norm() < 1e-12);
        assert!((r * Vector3::z() + Vector3::x()).norm() < 1e-12);
        // phi = 270 deg (alpha = 135 deg) sends the centre beam forward.
        let b = g.beam(0.0, 0.75 * PI).unwrap();
        assert!((b.direction - Vector3::x()).norm() < 1e-12);
        assert!((b.origin - Point3::new(0.0, 0.0, g.mirror_offset)).norm() < 1e-12);
    }

    #[test]
    fn blind_beams() {
        let mut g = MirrorGeometry::standard();
        assert!(!g.reflects(0.0, 0.01)); // edge on
        assert!(!g.reflects(0.0, PI / 2.0)); // back into the scanner
        assert!(!g.reflects(1.2, 0.5)); // misses the mirror
        assert!(g.reflects(0.0, 0.5) && g.reflects(0.0, 0.5 + PI));
        g.sides = 1;
        assert!(g.reflects(0.0, 0.5) && !g.reflects(0.0, 0.5 + PI));
    }
}
