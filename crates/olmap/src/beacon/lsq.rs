//! The thesis' least-squares circle detector for range data (§2.4.2, Figure 2.9).

use std::ops::RangeInclusive;

use nalgebra::Point2;

use super::detection::{beams_within, merge_duplicates, Detection};
use super::fit::{circle_residual, fit_circle_polar, refine_circle, PolarFit};
use crate::cloud::LaserScan;
use crate::geometry::wrap_angle;

/// Parameters of [`detect_circles_lsq`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LsqParams {
    /// Largest root mean square score of a hypothesis for it to become a candidate, metres
    /// (default 0.05). The hypothesis behind the beam nearest the centre is off by up to
    /// half a beam step sideways (3.5 cm at 8 m with 0.5° beams), so this is looser than
    /// `max_rms`; it only prunes, the fit decides.
    pub max_score: f64,
    /// Distance from a hypothesised circle's circumference beyond which a return counts as
    /// not belonging to it, metres (default 0.05). In the score, such a return, whether in
    /// front of the circle (something occluding it: the thesis does not detect occluded
    /// targets) or behind it (impossible if the circle were solid), and a beam with no
    /// return, all count as this distance, so a handful of them sink a hypothesis.
    pub outlier_distance: f64,
    /// Fewest returns on a circle (default 3: the quadratic fit needs three, §2.4.3).
    pub min_returns: usize,
    /// Largest root mean square distance of the returns to the fitted circle, metres
    /// (default 0.01, Algorithm 1). Set it to about twice the scanner's range noise.
    pub max_rms: f64,
    /// Beams passing within this distance of the tangent of the fitted circle may have
    /// missed it (the centre is uncertain) and are not required to hit it, metres
    /// (default 0.02); beams farther inside must hit it.
    pub edge_margin: f64,
    /// How much farther than the circle's nearest point the returns just beside its
    /// silhouette (the first beam past each tangent, unless it grazed the circle within
    /// `edge_margin`) must be, in radii (default 2: behind the circle's far side). A free-standing cylinder has its background behind it;
    /// a flat wall seen head-on, or the two faces of a box corner, continue past the
    /// silhouette of any circle fitted to them. 0 disables the test.
    pub edge_depth: f64,
    /// Gauss-Newton steps of the known-radius geometric fit after the polar fit (default
    /// 5); 0 keeps the thesis' polar fit alone, whose range is biased by the quadratic
    /// approximation (a few millimetres for a 0.125 m circle).
    pub refine_iterations: usize,
}

impl Default for LsqParams {
    fn default() -> Self {
        LsqParams {
            max_score: 0.05,
            outlier_distance: 0.05,
            min_returns: 3,
            max_rms: 0.01,
            edge_margin: 0.02,
            edge_depth: 2.0,
            refine_iterations: 5,
        }
    }
}

/// The valid returns of a scan, precomputed once.
struct Beams<'a> {
    scan: &'a LaserScan,
    valid: Vec<bool>,
    range: Vec<f64>,
    point: Vec<Point2<f64>>,
}

impl<'a> Beams<'a> {
    fn new(scan: &'a LaserScan) -> Self {
        let n = scan.len();
        let mut valid = vec![false; n];
        let mut range = vec![0.0; n];
        let mut point = vec![Point2::origin(); n];
        for i in 0..n {
            if scan.is_valid(i) {
                let r = scan.ranges[i] as f64;
                let (s, c) = scan.angle(i).sin_cos();
                valid[i] = true;
                range[i] = r;
                point[i] = Point2::new(r * c, r * s);
            }
        }
        Beams {
            scan,
            valid,
            range,
            point,
        }
    }

    /// Indices of the beams within `half_width` of `bearing`, clipped to the scan (possibly
    /// empty).
    fn around(&self, bearing: f64, half_width: f64) -> RangeInclusive<usize> {
        let n = self.scan.len();
        let inc = self.scan.angle_increment;
        let a = (bearing - half_width - self.scan.angle_min) / inc;
        let b = (bearing + half_width - self.scan.angle_min) / inc;
        let lo = a.min(b).ceil().max(0.0);
        let hi = a.max(b).floor().min(n as f64 - 1.0);
        if hi < lo {
            #[allow(clippy::reversed_empty_ranges)]
            return 1..=0;
        }
        lo as usize..=hi as usize
    }
}

/// Finds circles of known `radius` in a scan by the thesis' range-data least-squares method
/// (§2.4.2); returns them sorted by bearing.
///
/// 1. **Hypotheses.** For every valid beam `i` at range `r_i`, a circle is hypothesised
///    centred on the beam at range `r_i + R` (the return is the circle's nearest point).
///    It spans the beams within the window angle `asin(R / (R + r_i))` (2.6) of beam `i`
///    (at least one beam each side).
/// 2. **Score.** The mean squared distance of those beams' returns to the hypothesised
///    circumference, each distance capped at `outlier_distance`, and a beam with no
///    return (or outside the scan) counted at the cap (see [`LsqParams::outlier_distance`]).
/// 3. **Candidates.** Beams whose score is at most `max_score^2` and is the smallest within
///    their own window.
/// 4. **Fit.** Returns of the candidate's window (one beam wider) within `outlier_distance`
///    of its circle are fitted by the polar quadratic (2.13)-(2.15)
///    ([`fit_circle_polar`](super::fit_circle_polar)); the returns within `3 max_rms` of
///    that circle and within its window are fitted again, then refined by
///    `refine_iterations` Gauss-Newton steps of the distance to the circumference
///    ([`refine_circle`](super::refine_circle)).
/// 5. **Test.** Around the final centre, every beam passing more than `edge_margin` inside
///    the circle's tangent must hit the circle: its capped distance enters the RMS
///    whatever it is; beams nearer the tangent enter only when their return lies within
///    `3 max_rms` of the circle. `returns` counts the beams whose return lies within
///    `3 max_rms`. A circle with fewer than `min_returns` returns or an RMS above `max_rms`
///    is dropped.
///    The first beam past each tangent must not return nearer than `edge_depth` radii
///    behind the circle's nearest point (see [`LsqParams::edge_depth`]).
/// 6. **Duplicates.** Of circles whose centres are closer than `R`, the most confident is
///    kept.
///
/// The work is `O(n w)` for `n` beams and windows of `w` beams. An empty list comes back
/// for scans with fewer than three beams, a zero angle increment or a radius that is not
/// positive.
pub fn detect_circles_lsq(scan: &LaserScan, radius: f64, params: &LsqParams) -> Vec<Detection> {
    let n = scan.len();
    let step = scan.angle_increment.abs();
    if n < 3 || !step.is_finite() || step <= 0.0 || radius.is_nan() || radius <= 0.0 {
        return Vec::new();
    }
    let beams = Beams::new(scan);
    let cap = params.outlier_distance.max(0.0);
    let cap2 = cap * cap;
    let limit = params.max_score * params.max_score;

    // Steps 1-2: score every hypothesis.
    let mut score = vec![f64::INFINITY; n];
    let mut width = vec![0usize; n];
    for i in 0..n {
        if !beams.valid[i] {
            continue;
        }
        let r = beams.range[i];
        let c = r + radius;
        let center = beams.point[i] * (c / r);
        let w = (((radius / c).asin() / step).floor() as usize).max(1);
        width[i] = w;
        let terms = (2 * w + 1) as f64;
        let budget = limit * terms;
        let mut sum = 0.0;
        for k in 0..=2 * w {
            let j = i + k;
            let d2 = if j < w || j - w >= n || !beams.valid[j - w] {
                cap2
            } else {
                circle_residual(&beams.point[j - w], &center, radius)
                    .abs()
                    .min(cap)
                    .powi(2)
            };
            sum += d2;
            if sum > budget {
                break; // Over the threshold already: cannot be a candidate.
            }
        }
        score[i] = sum / terms;
    }

    // Step 3: local minima under the threshold; steps 4-5 for each.
    let mut found = Vec::new();
    for i in 0..n {
        if score[i].is_nan() || score[i] > limit {
            continue;
        }
        let w = width[i];
        let lo = i.saturating_sub(w);
        let hi = (i + w).min(n - 1);
        let is_min =
            (lo..i).all(|j| score[i] < score[j]) && (i + 1..=hi).all(|j| score[i] <= score[j]);
        if !is_min {
            continue;
        }
        if let Some(d) = fit_candidate(&beams, i, w, radius, params) {
            found.push(d);
        }
    }
    merge_duplicates(found, radius)
}

/// Steps 4-5 of [`detect_circles_lsq`] for the hypothesis behind beam `i`.
fn fit_candidate(
    beams: &Beams,
    i: usize,
    w: usize,
    radius: f64,
    params: &LsqParams,
) -> Option<Detection> {
    let cap = params.outlier_distance.max(0.0);
    let gate = 3.0 * params.max_rms;
    let first = first_fit(beams, i, w, radius, cap)?;
    let (second, center) = second_fit(beams, first, radius, gate, params);
    // The test around the final centre.
    let seen = Silhouette::of(center, second.bearing, radius, params.edge_margin)?;
    if seen.core_outside(beams) {
        // Part of the circle's core lies outside the scan: it cannot be verified.
        return None;
    }
    let (sum, terms, returns) = seen.score(beams, radius, cap, gate, params)?;
    seen.detection(beams, sum, terms, returns, params)
}

/// The first polar fit, on the returns of the window of beam `i` (`w` beams each side,
/// one more) within `cap` of the hypothesis; `None` when it fails or its bearing strays
/// beyond the window.
fn first_fit(beams: &Beams, i: usize, w: usize, radius: f64, cap: f64) -> Option<PolarFit> {
    let scan = beams.scan;
    let n = scan.len();
    let step = scan.angle_increment.abs();
    let r = beams.range[i];
    let hypothesis = beams.point[i] * ((r + radius) / r);
    let lo = i.saturating_sub(w + 1);
    let hi = (i + w + 1).min(n - 1);
    let samples: Vec<(f64, f64)> = (lo..=hi)
        .filter(|&j| {
            beams.valid[j] && circle_residual(&beams.point[j], &hypothesis, radius).abs() <= cap
        })
        .map(|j| (scan.angle(j), beams.range[j]))
        .collect();
    let first = fit_circle_polar(&samples, radius)?;
    if (first.bearing - scan.angle(i)).abs() > (radius / (r + radius)).asin() + step {
        return None;
    }
    Some(first)
}

/// The second polar fit, on the returns within `gate` of the first circle and within its
/// window (the first fit when it fails), and the centre after the geometric refinement.
fn second_fit(
    beams: &Beams,
    first: PolarFit,
    radius: f64,
    gate: f64,
    params: &LsqParams,
) -> (PolarFit, Point2<f64>) {
    let scan = beams.scan;
    let center = first.center();
    let half = (radius / first.range).asin();
    let inliers: Vec<usize> = beams
        .around(first.bearing, half)
        .filter(|&j| {
            beams.valid[j] && circle_residual(&beams.point[j], &center, radius).abs() <= gate
        })
        .collect();
    let samples: Vec<(f64, f64)> = inliers
        .iter()
        .map(|&j| (scan.angle(j), beams.range[j]))
        .collect();
    let second = fit_circle_polar(&samples, radius).unwrap_or(first);
    let points: Vec<Point2<f64>> = inliers.iter().map(|&j| beams.point[j]).collect();
    let center = if params.refine_iterations > 0 && points.len() >= 2 {
        refine_circle(&points, radius, second.center(), params.refine_iterations)
    } else {
        second.center()
    };
    (second, center)
}

/// The fitted circle as the scanner sees it.
struct Silhouette {
    /// The centre.
    center: Point2<f64>,
    /// Range of the centre.
    c: f64,
    /// Bearing of the centre (unwrapped near the fit's bearing).
    bearing: f64,
    /// Half the angle the circle spans.
    half: f64,
    /// Half the angle of the core: the beams more than `edge_margin` inside the tangents.
    core: f64,
}

impl Silhouette {
    /// The silhouette of the circle of `radius` at `center`; `None` when the centre is
    /// not finite or the sensor lies inside the circle.
    fn of(center: Point2<f64>, fit_bearing: f64, radius: f64, edge_margin: f64) -> Option<Self> {
        let c = center.coords.norm();
        if c.is_nan() || c <= radius {
            return None;
        }
        let bearing = fit_bearing + wrap_angle(center.y.atan2(center.x) - fit_bearing);
        let half = (radius / c).asin();
        let core = ((radius - edge_margin).max(0.0) / c).asin();
        Some(Silhouette {
            center,
            c,
            bearing,
            half,
            core,
        })
    }

    /// Whether part of the core lies outside the scan (more than half a beam step beyond
    /// its first or last beam).
    fn core_outside(&self, beams: &Beams) -> bool {
        let scan = beams.scan;
        let n = scan.len();
        let step = scan.angle_increment.abs();
        let (bearing, core) = (self.bearing, self.core);
        let (first_angle, last_angle) = (scan.angle(0), scan.angle(n - 1));
        let (scan_lo, scan_hi) = (first_angle.min(last_angle), first_angle.max(last_angle));
        bearing - core < scan_lo - 0.5 * step || bearing + core > scan_hi + 0.5 * step
    }

    /// Step 5's test of the beams around the silhouette: the sum of the squared residuals
    /// entering the RMS, their number, and the number of returns on the circle; `None`
    /// when a beam rules the circle out.
    fn score(
        &self,
        beams: &Beams,
        radius: f64,
        cap: f64,
        gate: f64,
        params: &LsqParams,
    ) -> Option<(f64, usize, usize)> {
        let scan = beams.scan;
        let step = scan.angle_increment.abs();
        let (center, c, bearing, half) = (self.center, self.c, self.bearing, self.half);
        let core_range = beams.around(bearing, self.core);
        let beside_range = c - radius + params.edge_depth * radius;
        let (mut sum, mut terms, mut returns) = (0.0, 0usize, 0usize);
        for j in beams.around(bearing, half + step) {
            let offset = scan.angle(j) - bearing;
            let valid = beams.valid[j];
            if offset.abs() > half {
                // Just outside the silhouette: the circle must stand out from what is beside
                // it (a wall seen head-on or the faces of a box corner continue there).
                // (A return on the circle within `edge_margin` grazed it: the centre is
                // uncertain by about that much.)
                let grazes = valid
                    && circle_residual(&beams.point[j], &center, radius).abs()
                        <= params.edge_margin;
                if valid && !grazes && beams.range[j] < beside_range {
                    return None;
                }
                continue;
            }
            // Where the beam meets the circle's near side.
            let along = c * offset.cos();
            let across = c * offset.sin();
            let surface = along - (radius * radius - across * across).max(0.0).sqrt();
            let residual = valid.then(|| circle_residual(&beams.point[j], &center, radius).abs());
            let inlier = residual.is_some_and(|e| e <= gate);
            let in_front = valid && beams.range[j] < surface - gate;
            if core_range.contains(&j) {
                if valid && beams.range[j] < surface - cap {
                    return None; // Occluded or not a circle: not verifiable.
                }
                let e = residual.unwrap_or(cap).min(cap);
                sum += e * e;
                terms += 1;
            } else if in_front {
                // A return in front of the circle's edge: the surface there is flatter than
                // the circle (or something occludes it).
                return None;
            } else if inlier {
                let e = residual.unwrap_or(0.0);
                sum += e * e;
                terms += 1;
            }
            if inlier {
                returns += 1;
            }
        }
        Some((sum, terms, returns))
    }

    /// The detection from step 5's score; `None` with too few returns or too large an RMS.
    fn detection(
        &self,
        beams: &Beams,
        sum: f64,
        terms: usize,
        returns: usize,
        params: &LsqParams,
    ) -> Option<Detection> {
        let scan = beams.scan;
        let n = scan.len();
        if returns < params.min_returns.max(3) || terms == 0 {
            return None;
        }
        let rms = (sum / terms as f64).sqrt();
        if rms.is_nan() || rms > params.max_rms {
            return None;
        }
        let expected = beams_within(
            scan.angle_min,
            scan.angle_increment,
            n,
            self.bearing,
            self.half,
        )
        .max(1);
        let coverage = (returns as f64 / expected as f64).min(1.0);
        let quality = if params.max_rms > 0.0 {
            (-(rms / params.max_rms).powi(2)).exp()
        } else {
            1.0
        };
        Some(Detection {
            center: self.center,
            rms,
            returns,
            confidence: (coverage * quality).clamp(0.0, 1.0),
        })
    }
}
