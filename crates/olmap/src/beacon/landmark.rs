//! The robot's pose change from landmarks (beacons) seen from two poses (thesis §2.5,
//! Algorithm 1): the rotation from the lines joining them, the translation from their
//! centroids, the ambiguity of indistinguishable landmarks and the speed limits that
//! resolve it (2.16)-(2.19), and the error estimates (2.23)-(2.25).
//!
//! Landmarks are points in the robot's (sensor's) plane frame, x forward and y left,
//! metres; a pose change is a [`Pose2`] `T_before_after`, the robot's pose at the later
//! observation expressed in its frame at the earlier one, so that a landmark seen at `a`
//! after the move was at `T_before_after * a` before it.
//!
//! ```
//! use nalgebra::Point2;
//! use olmap::beacon::landmark::{pose_change_from_landmarks, Pose2};
//! // Two beacons; the robot drives 0.5 m forward and turns 10° left.
//! let before = [Point2::new(3.0, 1.0), Point2::new(3.0, -1.0)];
//! let motion = Pose2::new(0.5, 0.0, 10f64.to_radians());
//! let after: Vec<Point2<f64>> = before.iter().map(|p| motion.inverse().transform_point(p)).collect();
//! let found = pose_change_from_landmarks(&before, &after).unwrap();
//! assert!((found.pose.x - 0.5).abs() < 1e-12 && found.pose.y.abs() < 1e-12);
//! assert!((found.pose.theta - 10f64.to_radians()).abs() < 1e-12);
//! ```

use std::ops::Mul;

use nalgebra::{Point2, Vector2, Vector3};

use crate::error::{Error, Result};
use crate::geometry::{wrap_angle, Pose};

/// A rigid transform of the plane `T_a_b`: `p_a = R(theta) p_b + (x, y)`, with `R(theta)`
/// the rotation (2.5) by `theta` radians from x toward y.
///
/// olmap's [`Pose`] is 3D; a `Pose2` is the planar case, converted with
/// [`Pose2::to_pose`] (z = 0, yaw = theta) and [`Pose2::from_pose`] (drops z, pitch and
/// roll).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose2 {
    /// Translation along x, metres.
    pub x: f64,
    /// Translation along y, metres.
    pub y: f64,
    /// Rotation, radians (positive from x toward y), in `(-pi, pi]` when produced here.
    pub theta: f64,
}

impl Pose2 {
    /// A transform from its translation and rotation.
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Pose2 { x, y, theta }
    }

    /// The identity.
    pub fn identity() -> Self {
        Pose2::default()
    }

    /// Maps a point of frame b into frame a.
    pub fn transform_point(&self, p: &Point2<f64>) -> Point2<f64> {
        let (s, c) = self.theta.sin_cos();
        Point2::new(c * p.x - s * p.y + self.x, s * p.x + c * p.y + self.y)
    }

    /// The inverse transform `T_b_a`.
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2 {
            x: -(c * self.x + s * self.y),
            y: -(-s * self.x + c * self.y),
            theta: wrap_angle(-self.theta),
        }
    }

    /// Length of the translation, metres.
    pub fn distance(&self) -> f64 {
        self.x.hypot(self.y)
    }

    /// The 3D pose with z = 0 and yaw = theta.
    pub fn to_pose(&self) -> Pose {
        Pose::from_xyz_ypr(self.x, self.y, 0.0, self.theta, 0.0, 0.0)
    }

    /// The planar part of a 3D pose: x, y and yaw (z, pitch and roll are dropped).
    pub fn from_pose(pose: &Pose) -> Pose2 {
        let t: Vector3<f64> = pose.translation();
        let (yaw, _, _) = pose.yaw_pitch_roll();
        Pose2::new(t.x, t.y, yaw)
    }
}

impl Mul for Pose2 {
    type Output = Pose2;

    /// Composition: `T_a_b * T_b_c = T_a_c`.
    #[allow(clippy::suspicious_arithmetic_impl)] // rotations compose by adding angles
    fn mul(self, rhs: Pose2) -> Pose2 {
        let p = self.transform_point(&Point2::new(rhs.x, rhs.y));
        Pose2::new(p.x, p.y, wrap_angle(self.theta + rhs.theta))
    }
}

/// The result of [`pose_change_from_landmarks`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandmarkPose {
    /// `T_before_after`: the robot's pose at the later observation in its frame at the
    /// earlier one.
    pub pose: Pose2,
    /// Root mean square distance between the earlier landmarks and the later ones mapped by
    /// `pose`, metres: 0 for exact data; for two landmarks half the change of their
    /// separation.
    pub rms: f64,
    /// How many landmarks were used.
    pub landmarks: usize,
}

/// The robot's pose change from the same landmarks observed at two times: `before[k]` and
/// `after[k]` are landmark `k` in the robot frame before and after the move (thesis §2.5).
///
/// The rotation is the change of direction of the lines joining the landmarks and the
/// translation the displacement of their centroid once rotated. With two landmarks the
/// rotation is exactly the change of angle of the line joining them; with three or more it
/// is the least-squares rotation (2D Procrustes / Kabsch: `atan2(sum a' x b', sum a' . b')`
/// over the centred landmarks, which weights each joining line by its length), which for
/// two landmarks reduces to the same thing. The result minimises the squared distances
/// `|before[k] - T after[k]|^2`.
///
/// Errors ([`Error::InvalidArgument`]): the two lists differ in length, hold fewer than two
/// landmarks or non-finite coordinates, or either list's landmarks all coincide (closer
/// than 1 µm to their centroid: the rotation is then undefined).
pub fn pose_change_from_landmarks(
    before: &[Point2<f64>],
    after: &[Point2<f64>],
) -> Result<LandmarkPose> {
    if before.len() != after.len() {
        return Err(Error::InvalidArgument(format!(
            "landmark lists differ in length: {} before, {} after",
            before.len(),
            after.len()
        )));
    }
    let n = before.len();
    if n < 2 {
        return Err(Error::InvalidArgument(format!(
            "a pose change needs at least two landmarks, got {n}"
        )));
    }
    if before
        .iter()
        .chain(after)
        .any(|p| !p.x.is_finite() || !p.y.is_finite())
    {
        return Err(Error::InvalidArgument(
            "landmark coordinates must be finite".into(),
        ));
    }
    let centroid = |ps: &[Point2<f64>]| {
        ps.iter().fold(Vector2::zeros(), |s, p| s + p.coords) / ps.len() as f64
    };
    let (cb, ca) = (centroid(before), centroid(after));
    let (mut dot, mut cross, mut spread_b, mut spread_a) = (0.0, 0.0, 0.0f64, 0.0f64);
    for (b, a) in before.iter().zip(after) {
        let (b, a) = (b.coords - cb, a.coords - ca);
        dot += a.dot(&b);
        cross += a.x * b.y - a.y * b.x;
        spread_b = spread_b.max(b.norm());
        spread_a = spread_a.max(a.norm());
    }
    const MIN_SPREAD: f64 = 1e-6;
    if spread_b < MIN_SPREAD || spread_a < MIN_SPREAD {
        return Err(Error::InvalidArgument(
            "the landmarks coincide: the rotation is undefined".into(),
        ));
    }
    let theta = cross.atan2(dot);
    let (s, c) = theta.sin_cos();
    let t = cb - Vector2::new(c * ca.x - s * ca.y, s * ca.x + c * ca.y);
    let pose = Pose2::new(t.x, t.y, theta);
    let rms = (before
        .iter()
        .zip(after)
        .map(|(b, a)| (b - pose.transform_point(a)).norm_squared())
        .sum::<f64>()
        / n as f64)
        .sqrt();
    Ok(LandmarkPose {
        pose,
        rms,
        landmarks: n,
    })
}

/// The angle a circle of `radius` subtends at `range` from the sensor (range to its
/// nearest point), `2 asin(R / (r + R))` (2.16), radians.
pub fn subtended_angle(radius: f64, range: f64) -> f64 {
    2.0 * (radius / (range + radius)).asin()
}

/// The time a scanner sweeping at `scan_frequency` (Hz) takes to sweep across a circle of
/// `radius` at `range`, `2 theta / (pi f)` with `theta` from (2.16) (2.17), seconds.
pub fn time_to_span(radius: f64, range: f64, scan_frequency: f64) -> f64 {
    2.0 * subtended_angle(radius, range) / (std::f64::consts::PI * scan_frequency)
}

/// The fastest the robot may drive while it detects a circle of `radius` at `range`
/// (2.18): the distance driven while the scan spans the target must stay under
/// `tolerance` (the detection threshold, 0.01 m in the thesis):
/// `v < tolerance pi f / (4 asin(R / (r + R)))`, metres per second. With f = 10 Hz,
/// R = 0.1225 m, r = 4 m and tolerance 0.01 m this is 2.6 m/s.
///
/// ```
/// use olmap::beacon::landmark::{max_rotation_speed, max_translation_speed};
/// assert!((max_translation_speed(0.1225, 4.0, 10.0, 0.01) - 2.64).abs() < 0.01);
/// assert!((max_rotation_speed(0.1225, 4.0, 10.0, 0.01) - 0.66).abs() < 0.01);
/// ```
pub fn max_translation_speed(radius: f64, range: f64, scan_frequency: f64, tolerance: f64) -> f64 {
    tolerance * std::f64::consts::PI * scan_frequency / (4.0 * (radius / (range + radius)).asin())
}

/// The fastest the robot may turn while it detects a circle of `radius` at `range` (2.19):
/// turning at `omega` moves the target sideways at `omega r`, so
/// `omega < tolerance pi f / (4 r asin(R / (r + R)))`, radians per second (0.7 rad/s for
/// the values of [`max_translation_speed`]).
pub fn max_rotation_speed(radius: f64, range: f64, scan_frequency: f64, tolerance: f64) -> f64 {
    max_translation_speed(radius, range, scan_frequency, tolerance) / range
}

/// How far the robot can have moved between two landmark observations: the thesis'
/// resolution of the ambiguity of indistinguishable landmarks (§2.5: "the limited speed of
/// the robot and fast updates means that the 180° change required for ambiguity would never
/// happen between updates").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    /// Largest speed, metres per second.
    pub max_speed: f64,
    /// Largest turn rate, radians per second.
    pub max_turn_rate: f64,
    /// Time between the two observations, seconds.
    pub dt: f64,
}

impl MotionLimits {
    /// Limits from a speed, a turn rate and the time between observations.
    pub fn new(max_speed: f64, max_turn_rate: f64, dt: f64) -> Self {
        MotionLimits {
            max_speed,
            max_turn_rate,
            dt,
        }
    }

    /// The limits (2.18)-(2.19) under which a circle of `radius` at `range` is still
    /// detected by a scanner at `scan_frequency` with detection threshold `tolerance`
    /// (faster motion smears the target and localisation fails anyway), over `dt`.
    pub fn for_beacons(
        radius: f64,
        range: f64,
        scan_frequency: f64,
        tolerance: f64,
        dt: f64,
    ) -> Self {
        MotionLimits {
            max_speed: max_translation_speed(radius, range, scan_frequency, tolerance),
            max_turn_rate: max_rotation_speed(radius, range, scan_frequency, tolerance),
            dt,
        }
    }

    /// Whether a pose change stays within the limits.
    pub fn allows(&self, change: &Pose2) -> bool {
        change.distance() <= self.max_speed * self.dt
            && wrap_angle(change.theta).abs() <= self.max_turn_rate * self.dt
    }
}

/// Which earlier landmark each later one is, and the pose change it implies; the result
/// of [`match_landmarks`].
#[derive(Debug, Clone, PartialEq)]
pub struct Correspondence {
    /// `(before index, after index)` pairs, in the order of the after indices.
    pub pairs: Vec<(usize, usize)>,
    /// The pose change from the matched landmarks.
    pub pose: LandmarkPose,
    /// How many other assignments were also consistent (residual within tolerance and
    /// motion within the limits); 0 means the choice is unambiguous.
    pub alternatives: usize,
}

/// Most landmarks [`match_landmarks`] enumerates the assignments of.
pub const MAX_MATCH_LANDMARKS: usize = 8;

/// Matches indistinguishable landmarks seen before and after a move and returns the pose
/// change (thesis §2.5).
///
/// Every assignment of the smaller list's landmarks to distinct landmarks of the larger
/// list (with at least two pairs) is tried: its pose change comes from
/// [`pose_change_from_landmarks`]. An assignment is *consistent* when the landmarks' RMS
/// misfit is at most `tolerance` metres (the separations between landmarks are preserved;
/// with three or more asymmetric landmarks this alone picks the right one) and the motion
/// is within `limits` (with two landmarks both assignments preserve the separation; the
/// wrong one turns the robot by about 180° about the midpoint, which the speed limits
/// (2.18)-(2.19) rule out). The consistent assignment with the smallest misfit wins, ties
/// going to the smaller rotation; `alternatives` counts the other consistent ones.
///
/// Errors ([`Error::InvalidArgument`]): fewer than two landmarks in either list, more than
/// [`MAX_MATCH_LANDMARKS`], coincident landmarks, or no consistent assignment.
///
/// ```
/// use nalgebra::Point2;
/// use olmap::beacon::landmark::{match_landmarks, MotionLimits, Pose2};
/// let before = [Point2::new(4.0, 1.0), Point2::new(4.0, -1.0)];
/// let motion = Pose2::new(0.1, 0.02, 0.05);
/// // Seen again after the move, listed the other way round.
/// let after: Vec<Point2<f64>> = before.iter().rev().map(|p| motion.inverse().transform_point(p)).collect();
/// let limits = MotionLimits::new(0.5, 0.7, 0.5);
/// let m = match_landmarks(&before, &after, &limits, 0.02).unwrap();
/// assert_eq!(m.pairs, vec![(1, 0), (0, 1)]);
/// assert!((m.pose.pose.theta - 0.05).abs() < 1e-12);
/// assert_eq!(m.alternatives, 0);
/// ```
pub fn match_landmarks(
    before: &[Point2<f64>],
    after: &[Point2<f64>],
    limits: &MotionLimits,
    tolerance: f64,
) -> Result<Correspondence> {
    let (nb, na) = (before.len(), after.len());
    if nb < 2 || na < 2 {
        return Err(Error::InvalidArgument(format!(
            "matching needs at least two landmarks each time, got {nb} before and {na} after"
        )));
    }
    if nb > MAX_MATCH_LANDMARKS || na > MAX_MATCH_LANDMARKS {
        return Err(Error::InvalidArgument(format!(
            "at most {MAX_MATCH_LANDMARKS} landmarks can be matched, got {nb} before and {na} after"
        )));
    }
    // Assign each landmark of the smaller list to a distinct one of the larger.
    let swap = na > nb;
    let (small, large) = if swap {
        (before, after)
    } else {
        (after, before)
    };
    let mut best: Option<Correspondence> = None;
    let mut consistent = 0usize;
    let mut error: Option<Error> = None;
    let mut chosen = Vec::with_capacity(small.len());
    let mut used = vec![false; large.len()];
    enumerate(
        &mut chosen,
        &mut used,
        small.len(),
        &mut |assignment: &[usize]| {
            // pairs as (before, after)
            let pairs: Vec<(usize, usize)> = assignment
                .iter()
                .enumerate()
                .map(|(s, &l)| if swap { (s, l) } else { (l, s) })
                .collect();
            let b: Vec<Point2<f64>> = pairs.iter().map(|p| before[p.0]).collect();
            let a: Vec<Point2<f64>> = pairs.iter().map(|p| after[p.1]).collect();
            let pose = match pose_change_from_landmarks(&b, &a) {
                Ok(p) => p,
                Err(e) => {
                    error.get_or_insert(e);
                    return;
                }
            };
            if pose.rms > tolerance || !limits.allows(&pose.pose) {
                return;
            }
            consistent += 1;
            let key = (pose.rms, pose.pose.theta.abs());
            let better = match &best {
                None => true,
                Some(c) => {
                    let old = (c.pose.rms, c.pose.pose.theta.abs());
                    key.0 < old.0 - 1e-12 || ((key.0 - old.0).abs() <= 1e-12 && key.1 < old.1)
                }
            };
            if better {
                let mut pairs = pairs;
                pairs.sort_by_key(|p| p.1);
                best = Some(Correspondence {
                    pairs,
                    pose,
                    alternatives: 0,
                });
            }
        },
    );
    match best {
        Some(mut c) => {
            c.alternatives = consistent - 1;
            Ok(c)
        }
        None => Err(error.unwrap_or_else(|| {
            Error::InvalidArgument(format!(
                "no assignment of the landmarks fits within {tolerance} m and the motion limits"
            ))
        })),
    }
}

/// Calls `visit` with every injective assignment of `k` items to `used.len()` slots.
fn enumerate(
    chosen: &mut Vec<usize>,
    used: &mut [bool],
    k: usize,
    visit: &mut dyn FnMut(&[usize]),
) {
    if chosen.len() == k {
        visit(chosen);
        return;
    }
    for j in 0..used.len() {
        if !used[j] {
            used[j] = true;
            chosen.push(j);
            enumerate(chosen, used, k, visit);
            chosen.pop();
            used[j] = false;
        }
    }
}

/// The rotation error of a pose change from two landmarks `separation` apart whose ranges
/// are off by `range_error` (2.23), far-field approximation: `sqrt(2) AA' / AB`, radians.
pub fn rotation_error(separation: f64, range_error: f64) -> f64 {
    std::f64::consts::SQRT_2 * range_error / separation
}

/// The position error due to range errors (2.24): `sqrt(2) (AA' / AB) OM`, metres, for
/// landmarks `separation` (AB) apart, their midpoint `distance` (OM) away and range error
/// `range_error` (AA'). Targets 2 m apart at 4 m with 1 cm range error give 0.03 m.
pub fn position_error_from_range(distance: f64, separation: f64, range_error: f64) -> f64 {
    rotation_error(separation, range_error) * distance
}

/// The position error due to bearing errors (2.25): `sigma_x = OM sigma_theta`, metres,
/// for landmarks whose midpoint is `distance` (OM) away and bearing error `bearing_error`
/// (radians; about 0.009 for the SICK LMS 200, giving 0.03 m at 4 m).
pub fn position_error_from_bearing(distance: f64, bearing_error: f64) -> f64 {
    distance * bearing_error
}

/// The expected position error of one landmark observation: (2.24) and (2.25) added in
/// quadrature, metres. A pose change compares two observations, each with this error, so
/// its own error is about `sqrt(2)` times larger.
///
/// ```
/// use olmap::beacon::landmark::localisation_error;
/// let e = localisation_error(4.0, 2.0, 0.01, 0.0);
/// assert!((e - 0.0283).abs() < 1e-4);
/// ```
pub fn localisation_error(
    distance: f64,
    separation: f64,
    range_error: f64,
    bearing_error: f64,
) -> f64 {
    position_error_from_range(distance, separation, range_error)
        .hypot(position_error_from_bearing(distance, bearing_error))
}
