//! Circles wrapped in retroreflective tape: runs of bright returns, each fitted in polar
//! coordinates (thesis §2.4.3).

use nalgebra::Point2;

use super::detection::{beams_within, merge_duplicates, Detection};
use super::fit::{circle_residual, fit_circle_polar_or_flat, refine_circle};
use crate::cloud::LaserScan;
use crate::geometry::wrap_angle;

/// Incidence angle beyond which retroreflective tape stops returning bright light
/// (50°, thesis §3.2); only the part of a taped cylinder within it shows up bright.
const RETRO_INCIDENCE_LIMIT: f64 = 50.0 * std::f64::consts::PI / 180.0;

/// Parameters of [`detect_circles_reflective`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReflectiveParams {
    /// Intensity at or above which a return is retroreflective (default 1.0: diffuse
    /// surfaces return at most 1, the simulator's tape returns 2).
    pub intensity_threshold: f64,
    /// Fewest bright returns in a run (default 3: the quadratic fit needs three; the
    /// thesis discards fewer, §2.4.3).
    pub min_returns: usize,
    /// Largest root mean square distance of the run's returns to the fitted circle, metres
    /// (default 0.01, Algorithm 1); rejects bright things that are not circles of the
    /// radius.
    pub max_rms: f64,
    /// Gauss-Newton steps of the known-radius geometric fit after the polar fit (default
    /// 5; 0 keeps the thesis' polar fit alone).
    pub refine_iterations: usize,
}

impl Default for ReflectiveParams {
    fn default() -> Self {
        ReflectiveParams {
            intensity_threshold: 1.0,
            min_returns: 3,
            max_rms: 0.01,
            refine_iterations: 5,
        }
    }
}

/// Finds retroreflective circles of known `radius` in a scan with intensities (§2.4.3);
/// returns them sorted by bearing (none for a scan without intensities).
///
/// A *run* is a maximal sequence of beams whose returns are valid and at least
/// `intensity_threshold` bright; beams with no return inside a run do not end it, a dim
/// return does, and so does a jump of more than `radius` between consecutive bright
/// returns (two beacons overlapping in bearing). Each run of at least `min_returns`
/// returns is fitted by the polar quadratic (2.13)-(2.15) and refined geometrically; its
/// RMS is over all of the run's returns, and runs with an RMS above `max_rms` (or no
/// quadratic minimum) are dropped. Circles closer than `radius` are merged. The
/// confidence's coverage counts the beams within the part of the circle facing the sensor
/// at less than 50° incidence, the part that returns bright light.
///
/// ```
/// use olmap::beacon::{detect_circles_reflective, ReflectiveParams};
/// use olmap::cloud::LaserScan;
/// let (radius, cx) = (0.125, 2.0);
/// let step = 1f64.to_radians();
/// let (mut ranges, mut intensities) = (Vec::new(), Vec::new());
/// for i in 0..41 {
///     let a = -20f64.to_radians() + i as f64 * step;
///     let disc = radius * radius - (cx * a.sin()).powi(2);
///     if disc >= 0.0 {
///         ranges.push((cx * a.cos() - disc.sqrt()) as f32);
///         intensities.push(2.0);
///     } else {
///         ranges.push(5.0);
///         intensities.push(0.5);
///     }
/// }
/// let scan = LaserScan {
///     angle_min: -20f64.to_radians(),
///     angle_increment: step,
///     range_min: 0.0,
///     range_max: 8.0,
///     ranges,
///     intensities: Some(intensities),
///     time: 0.0,
/// };
/// let found = detect_circles_reflective(&scan, radius, &ReflectiveParams::default());
/// assert_eq!(found.len(), 1);
/// assert!((found[0].center.x - cx).abs() < 1e-3);
/// ```
pub fn detect_circles_reflective(
    scan: &LaserScan,
    radius: f64,
    params: &ReflectiveParams,
) -> Vec<Detection> {
    let Some(intensities) = scan.intensities.as_ref() else {
        return Vec::new();
    };
    if radius.is_nan() || radius <= 0.0 || scan.angle_increment == 0.0 {
        return Vec::new();
    }
    let n = scan.len().min(intensities.len());
    let mut found = Vec::new();
    let mut run: Vec<usize> = Vec::new();
    let mut last: Option<Point2<f64>> = None;
    // Beams with their bright flag, then a sentinel that ends the last run.
    let beams = (0..n)
        .filter(|&i| scan.is_valid(i)) // No return: does not end a run.
        .map(|i| {
            let r = scan.ranges[i] as f64;
            let (s, c) = scan.angle(i).sin_cos();
            let bright = intensities[i] as f64 >= params.intensity_threshold;
            (i, Point2::new(r * c, r * s), bright)
        })
        .chain(std::iter::once((n, Point2::origin(), false)));
    for (i, point, bright) in beams {
        let jump = bright && last.is_some_and(|a: Point2<f64>| (point - a).norm() > radius);
        if (!bright || jump) && !run.is_empty() {
            if let Some(d) = fit_run(scan, &run, radius, params) {
                found.push(d);
            }
            run.clear();
        }
        if bright {
            run.push(i);
            last = Some(point);
        } else {
            last = None;
        }
    }
    merge_duplicates(found, radius)
}

/// Fits one run of bright returns.
fn fit_run(
    scan: &LaserScan,
    run: &[usize],
    radius: f64,
    params: &ReflectiveParams,
) -> Option<Detection> {
    if run.len() < params.min_returns.max(3) {
        return None;
    }
    let samples: Vec<(f64, f64)> = run
        .iter()
        .map(|&j| (scan.angle(j), scan.ranges[j] as f64))
        .collect();
    let fit = fit_circle_polar_or_flat(&samples, radius)?;
    let points: Vec<Point2<f64>> = samples
        .iter()
        .map(|&(a, r)| Point2::new(r * a.cos(), r * a.sin()))
        .collect();
    let center = if params.refine_iterations > 0 {
        refine_circle(&points, radius, fit.center(), params.refine_iterations)
    } else {
        fit.center()
    };
    let rms = (points
        .iter()
        .map(|p| circle_residual(p, &center, radius).powi(2))
        .sum::<f64>()
        / points.len() as f64)
        .sqrt();
    if rms.is_nan() || rms > params.max_rms {
        return None;
    }
    let c = center.coords.norm();
    if c.is_nan() || c <= radius {
        return None;
    }
    // In the scan's angle convention (the fit's bearing), not atan2's.
    let bearing = fit.bearing + wrap_angle(center.y.atan2(center.x) - fit.bearing);
    let bright_half = (radius * RETRO_INCIDENCE_LIMIT.sin() / c).asin();
    let expected = beams_within(
        scan.angle_min,
        scan.angle_increment,
        scan.len(),
        bearing,
        bright_half,
    )
    .max(1);
    let coverage = (run.len() as f64 / expected as f64).min(1.0);
    let quality = if params.max_rms > 0.0 {
        (-(rms / params.max_rms).powi(2)).exp()
    } else {
        1.0
    };
    Some(Detection {
        center,
        rms,
        returns: run.len(),
        confidence: (coverage * quality).clamp(0.0, 1.0),
    })
}
