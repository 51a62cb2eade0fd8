//! Fitting a circle of known radius to returns: the thesis' polar quadratic fit
//! (2.13)-(2.15) and a geometric (distance to the circumference) refinement.

use nalgebra::{Matrix2, Matrix3, Point2, Vector2, Vector3};

/// The result of [`fit_circle_polar`]: the quadratic `r = a0 + a1 t + a2 t^2` in
/// `t = bearing - reference` and the circle centre it implies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolarFit {
    /// Range of the circle centre, `c = a0 - a1^2 / (4 a2) + R` (2.15), metres.
    pub range: f64,
    /// Bearing of the circle centre, `alpha = reference - a1 / (2 a2)` (2.15), radians.
    pub bearing: f64,
    /// The quadratic's coefficients `[a0, a1, a2]` (metres, metres per radian, metres per
    /// radian squared).
    pub coefficients: [f64; 3],
    /// The bearing the quadratic is expanded about (the mean bearing of the samples).
    pub reference: f64,
}

impl PolarFit {
    /// The centre in Cartesian sensor coordinates.
    pub fn center(&self) -> Point2<f64> {
        let (s, c) = self.bearing.sin_cos();
        Point2::new(self.range * c, self.range * s)
    }
}

/// Fits the thesis' quadratic in polar coordinates (2.13)-(2.15) to returns on a circle of
/// known `radius`: range as a quadratic in bearing, least squares on the range (2.14); the
/// quadratic's minimum gives the bearing of the centre and its range plus the radius the
/// centre's range.
///
/// `samples` are `(bearing, range)` pairs (radians, metres). Returns `None` with fewer than
/// three samples, when the normal equations are singular, when the quadratic opens
/// downward (no minimum: not a convex surface seen from outside) or when its minimum falls
/// outside the samples' bearings (the fit is then an extrapolation).
///
/// The quadratic is the second-order Taylor expansion (2.10) of the circle, so the range
/// is slightly biased (the true profile steepens toward the tangents); [`refine_circle`]
/// removes that bias.
///
/// ```
/// use olmap::beacon::fit_circle_polar;
/// // Exact returns of a 0.125 m circle centred 2 m away at bearing 0.1 rad.
/// let (c, alpha, radius) = (2.0f64, 0.1f64, 0.125f64);
/// let samples: Vec<(f64, f64)> = (-5..=5)
///     .map(|k| {
///         let phi = k as f64 * 0.01;
///         let r = c * phi.cos() - (radius * radius - (c * phi.sin()).powi(2)).sqrt();
///         (alpha + phi, r)
///     })
///     .collect();
/// let fit = fit_circle_polar(&samples, radius).unwrap();
/// assert!((fit.bearing - alpha).abs() < 1e-9);
/// assert!((fit.range - c).abs() < 0.01);
/// ```
pub fn fit_circle_polar(samples: &[(f64, f64)], radius: f64) -> Option<PolarFit> {
    let n = samples.len();
    if n < 3 {
        return None;
    }
    let reference = samples.iter().map(|s| s.0).sum::<f64>() / n as f64;
    let (lo, hi) = samples
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
            (lo.min(s.0), hi.max(s.0))
        });
    // Scale the bearings to [-1, 1] so the normal equations are well conditioned.
    let scale = (hi - reference).max(reference - lo);
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    let mut m = Matrix3::zeros();
    let mut v = Vector3::zeros();
    for &(theta, r) in samples {
        let u = (theta - reference) / scale;
        let row = Vector3::new(1.0, u, u * u);
        m += row * row.transpose();
        v += row * r;
    }
    let b = m.cholesky()?.solve(&v);
    let (a0, a1, a2) = (b[0], b[1] / scale, b[2] / (scale * scale));
    if a2.is_nan() || a2 <= 0.0 {
        return None;
    }
    let offset = -a1 / (2.0 * a2);
    let bearing = reference + offset;
    if bearing < lo || bearing > hi {
        return None;
    }
    let range = a0 - a1 * a1 / (4.0 * a2) + radius;
    if !range.is_finite() || range <= radius {
        return None;
    }
    Some(PolarFit {
        range,
        bearing,
        coefficients: [a0, a1, a2],
        reference,
    })
}

/// Signed distance of `p` from the circumference of the circle (`center`, `radius`):
/// positive outside the circle, negative inside.
pub fn circle_residual(p: &Point2<f64>, center: &Point2<f64>, radius: f64) -> f64 {
    (p - center).norm() - radius
}

/// Refines the centre of a circle of known `radius` through `points` by Gauss-Newton on the
/// sum of squared distances to the circumference, starting at `start`, for at most
/// `iterations` steps (stopping early once a step is below 1e-7 m). Steps are clamped to
/// `radius`, and the start is returned unchanged when the problem is degenerate (fewer than
/// two points).
///
/// ```
/// use nalgebra::Point2;
/// use olmap::beacon::refine_circle;
/// let truth = Point2::new(3.0, 1.0);
/// let points: Vec<Point2<f64>> = (0..7)
///     .map(|k| {
///         let a = 2.6 + 0.15 * k as f64;
///         truth + nalgebra::Vector2::new(a.cos(), a.sin()) * 0.125
///     })
///     .collect();
/// let c = refine_circle(&points, 0.125, Point2::new(2.98, 1.01), 10);
/// assert!((c - truth).norm() < 1e-9);
/// ```
pub fn refine_circle(
    points: &[Point2<f64>],
    radius: f64,
    start: Point2<f64>,
    iterations: usize,
) -> Point2<f64> {
    let mut c = start;
    if points.len() < 2 {
        return c;
    }
    for _ in 0..iterations {
        let mut jtj = Matrix2::zeros();
        let mut jte = Vector2::zeros();
        for p in points {
            let d = p - c;
            let dist = d.norm();
            if dist < 1e-12 {
                continue;
            }
            // e = |p - c| - R, de/dc = -(p - c) / |p - c|.
            let j = -d / dist;
            let e = dist - radius;
            jtj += j * j.transpose();
            jte += j * e;
        }
        let Some(inv) = jtj.try_inverse() else {
            break;
        };
        let mut step = -(inv * jte);
        let len = step.norm();
        if !len.is_finite() {
            break;
        }
        if len > radius {
            step *= radius / len;
        }
        c += step;
        if len < 1e-7 {
            break;
        }
    }
    c
}

/// [`fit_circle_polar`], or, when the quadratic has no usable minimum (a short, noisy arc
/// whose curvature the range noise hides: a 15 cm beacon's visible arc bulges only 2-3 cm,
/// as much as 1-2 cm of noise), a flat start: the centre `radius` behind the nearest
/// return at the samples' mean bearing, for [`refine_circle`] to finish. `None` with fewer
/// than three samples.
pub fn fit_circle_polar_or_flat(samples: &[(f64, f64)], radius: f64) -> Option<PolarFit> {
    if let Some(fit) = fit_circle_polar(samples, radius) {
        return Some(fit);
    }
    if samples.len() < 3 {
        return None;
    }
    let n = samples.len() as f64;
    let bearing = samples.iter().map(|s| s.0).sum::<f64>() / n;
    let nearest = samples.iter().map(|s| s.1).fold(f64::INFINITY, f64::min);
    (nearest.is_finite() && bearing.is_finite()).then_some(PolarFit {
        range: nearest + radius,
        bearing,
        coefficients: [nearest, 0.0, 0.0],
        reference: bearing,
    })
}
