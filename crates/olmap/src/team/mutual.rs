//! Mutual localisation: the relative pose of two robots that see each other's beacon at the
//! same time (thesis §3.3.1, (3.8)-(3.13)), the distractor test of §3.3.2 and the error
//! model of §3.5 ((3.36)-(3.37)).
//!
//! Geometry (thesis Figure 3.5): robot A's scanner is the origin, its heading the x axis.
//! Each robot carries its beacon `d` metres straight ahead of its scanner. A sees B's
//! beacon at range `a`, bearing `alpha`; B sees A's beacon at range `b`, bearing `beta`
//! (bearings in each observer's own frame, positive to the left). In the complex plane,
//! `C = d + b e^{iθ} = a e^{iα} + d e^{i(θ-β)}` gives B's scanner position (3.13) and
//! heading `θ - β + π`, with `e^{iθ} = (a e^{iα} - d) / (b - d e^{-iβ})` (3.12).

use nalgebra::Complex;

use crate::error::{Error, Result};
use crate::geometry::wrap_angle;

/// A two-way observation: A saw B's beacon at `(a, alpha)`, B saw A's at `(b, beta)`, both
/// beacons `d` ahead of their scanners.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MutualObservation {
    /// Range from A's scanner to B's beacon, metres.
    pub a: f64,
    /// Bearing of B's beacon from A, radians.
    pub alpha: f64,
    /// Range from B's scanner to A's beacon, metres.
    pub b: f64,
    /// Bearing of A's beacon from B, radians.
    pub beta: f64,
    /// Beacon offset ahead of the scanner, metres (0 for beacons above the scanner).
    pub d: f64,
}

impl MutualObservation {
    /// The 3D variant (thesis §6.3.3): beacons straight above the scanners, observed in
    /// 3D at `(range, bearing, elevation)`; the observations are projected onto the floor
    /// plane (horizontal range `range · cos(elevation)`) and `d = 0`.
    pub fn from_3d(
        a_range: f64,
        a_bearing: f64,
        a_elevation: f64,
        b_range: f64,
        b_bearing: f64,
        b_elevation: f64,
    ) -> Self {
        MutualObservation {
            a: a_range * a_elevation.cos(),
            alpha: a_bearing,
            b: b_range * b_elevation.cos(),
            beta: b_bearing,
            d: 0.0,
        }
    }
}

/// B's scanner pose in A's scanner frame, and the two beacon separations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MutualFix {
    /// B's position, x, metres.
    pub x: f64,
    /// B's position, y, metres.
    pub y: f64,
    /// B's heading, radians in `(-π, π]`.
    pub heading: f64,
    /// Beacon separation as A sees it (3.8), metres.
    pub s1: f64,
    /// Beacon separation as B sees it (3.9), metres.
    pub s2: f64,
}

/// Parameters of [`mutual_pose`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MutualParams {
    /// Largest accepted `|s1 - s2|`, metres (default 0.02, thesis §3.3.2): a larger one
    /// means one robot saw a distractor, not the other's beacon.
    pub max_separation_mismatch: f64,
}

impl Default for MutualParams {
    fn default() -> Self {
        MutualParams {
            max_separation_mismatch: 0.02,
        }
    }
}

/// Why a mutual observation gave no pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MutualReject {
    /// The two separations disagree: a distractor.
    #[error("beacon separations disagree by {mismatch:.3} m (> {limit:.3} m): a distractor, not a beacon")]
    Distractor {
        /// `|s1 - s2|`, metres.
        mismatch: f64,
        /// The limit, metres.
        limit: f64,
    },
    /// The geometry has no solution (ranges not positive, or a zero denominator in (3.12)).
    #[error("degenerate geometry: {0}")]
    Degenerate(String),
}

/// The beacon separations (3.8) and (3.9): `s1` from A's observation, `s2` from B's.
pub fn separations(o: &MutualObservation) -> (f64, f64) {
    let s = |r: f64, ang: f64| {
        (o.d * o.d + r * r - 2.0 * r * o.d * ang.cos())
            .max(0.0)
            .sqrt()
    };
    (s(o.a, o.alpha), s(o.b, o.beta))
}

/// B's pose in A's frame from a two-way observation, (3.12)-(3.13), after the distractor
/// test.
///
/// ```
/// use olmap::team::{mutual_pose, MutualObservation, MutualParams};
/// // B 4 m ahead of A, facing A: each sees the other's beacon (0.07 m ahead) dead ahead.
/// let o = MutualObservation { a: 4.0 - 0.07, alpha: 0.0, b: 4.0 - 0.07, beta: 0.0, d: 0.07 };
/// let fix = mutual_pose(&o, &MutualParams::default()).unwrap();
/// assert!((fix.x - 4.0).abs() < 1e-12 && fix.y.abs() < 1e-12);
/// assert!((fix.heading.abs() - std::f64::consts::PI).abs() < 1e-12);
/// ```
pub fn mutual_pose(
    o: &MutualObservation,
    params: &MutualParams,
) -> Result<MutualFix, MutualReject> {
    let finite = [o.a, o.alpha, o.b, o.beta, o.d]
        .iter()
        .all(|v| v.is_finite());
    if !finite || o.a <= 0.0 || o.b <= 0.0 || o.d < 0.0 {
        return Err(MutualReject::Degenerate(format!(
            "ranges must be positive and finite and d >= 0: {o:?}"
        )));
    }
    let (s1, s2) = separations(o);
    let mismatch = (s1 - s2).abs();
    if mismatch > params.max_separation_mismatch {
        return Err(MutualReject::Distractor {
            mismatch,
            limit: params.max_separation_mismatch,
        });
    }
    let ea = Complex::from_polar(1.0, o.alpha);
    let eb = Complex::from_polar(1.0, o.beta);
    let d = Complex::new(o.d, 0.0);
    let den12 = Complex::new(o.b, 0.0) - d * eb.conj();
    let den13 = eb * o.b - d;
    if den12.norm() < 1e-12 || den13.norm() < 1e-12 {
        return Err(MutualReject::Degenerate(
            "a zero denominator in (3.12)/(3.13)".into(),
        ));
    }
    let e_theta = (ea * o.a - d) / den12;
    let c = (ea * eb * (o.a * o.b) - d * d) / den13;
    let heading = wrap_angle(e_theta.arg() - o.beta + std::f64::consts::PI);
    Ok(MutualFix {
        x: c.re,
        y: c.im,
        heading,
        s1,
        s2,
    })
}

/// The thesis' bound on the position error of [`mutual_pose`] (3.36)-(3.37): the sum of
/// the moduli of the terms of (3.36) with `Δα = w / a`, i.e. `Δa + w + (a / b) Δd`, for a
/// range error `range_error`, a beacon of apparent width `beacon_width` and an offset error
/// `offset_error` (metres). Independent of the separation when `a ≈ b` (§3.5).
pub fn expected_position_error(
    o: &MutualObservation,
    range_error: f64,
    beacon_width: f64,
    offset_error: f64,
) -> Result<f64> {
    if !(o.a > 0.0 && o.b > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "expected_position_error needs positive ranges, got a = {}, b = {}",
            o.a, o.b
        )));
    }
    Ok(range_error + beacon_width + o.a / o.b * offset_error)
}

/// Mutual localisation from the two robots' 2D scans taken at the same time: the
/// retroreflective beacons of radius `radius` found in each scan (see
/// [`crate::beacon::detect_circles_reflective`]) are paired, every pair is tried, and the
/// one whose beacon separations agree best (and within the distractor limit) gives B's pose
/// in A's scanner frame. Scans are in each robot's scanner frame; beacons sit `d` ahead.
pub fn mutual_from_scans(
    scan_a: &crate::cloud::LaserScan,
    scan_b: &crate::cloud::LaserScan,
    radius: f64,
    d: f64,
    detect: &crate::beacon::ReflectiveParams,
    params: &MutualParams,
) -> Result<MutualFix, MutualReject> {
    let found_a = crate::beacon::detect_circles_reflective(scan_a, radius, detect);
    let found_b = crate::beacon::detect_circles_reflective(scan_b, radius, detect);
    if found_a.is_empty() || found_b.is_empty() {
        return Err(MutualReject::Degenerate(format!(
            "no beacon pair: {} beacon(s) in A's scan, {} in B's",
            found_a.len(),
            found_b.len()
        )));
    }
    let mut best: Option<(f64, MutualFix)> = None;
    let mut closest_mismatch = f64::INFINITY;
    for da in &found_a {
        for db in &found_b {
            let o = MutualObservation {
                a: da.range(),
                alpha: da.bearing(),
                b: db.range(),
                beta: db.bearing(),
                d,
            };
            let (s1, s2) = separations(&o);
            let mismatch = (s1 - s2).abs();
            closest_mismatch = closest_mismatch.min(mismatch);
            if let Ok(fix) = mutual_pose(&o, params) {
                if best.as_ref().is_none_or(|(m, _)| mismatch < *m) {
                    best = Some((mismatch, fix));
                }
            }
        }
    }
    best.map(|(_, fix)| fix).ok_or(MutualReject::Distractor {
        mismatch: closest_mismatch,
        limit: params.max_separation_mismatch,
    })
}
