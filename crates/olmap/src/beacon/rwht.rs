//! The range-weighted Hough transform for circles of known radius (thesis §2.4.1), the
//! baseline the least-squares detector is compared with.

use nalgebra::Point2;

use super::detection::{merge_duplicates, Detection};
use super::fit::circle_residual;
use crate::cloud::LaserScan;

/// Most accumulator cells [`detect_circles_rwht`] allocates; a scan whose extent would
/// need more gets coarser cells.
const MAX_CELLS: usize = 1 << 24;

/// Parameters of [`detect_circles_rwht`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RwhtParams {
    /// Accumulator cell size, metres (default 0.02).
    pub cell: f64,
    /// A peak must collect at least this fraction of the best peak's votes (default 0.5).
    pub min_fraction: f64,
    /// A peak must collect at least this fraction of the votes of a fully visible circle,
    /// about `2 R / angle_increment` whatever its range (thanks to the range weighting)
    /// (default 0.25).
    pub min_support: f64,
    /// Most circles reported, strongest first (default 10).
    pub max_peaks: usize,
    /// Half-width, in cells, of the neighbourhood whose votes average into the refined
    /// centre (default 2: 5 x 5 cells).
    pub refine_cells: usize,
    /// Returns within `R + member_tolerance` of a refined centre are the circle's: they
    /// give its `returns` and `rms`, metres (default 0.05).
    pub member_tolerance: f64,
}

impl Default for RwhtParams {
    fn default() -> Self {
        RwhtParams {
            cell: 0.02,
            min_fraction: 0.5,
            min_support: 0.25,
            max_peaks: 10,
            refine_cells: 2,
            member_tolerance: 0.05,
        }
    }
}

/// Finds circles of known `radius` by the range-weighted Hough transform (§2.4.1, after
/// Forsberg et al. 1995); returns them sorted by bearing.
///
/// * **Accumulator.** A 2D grid of candidate centres, `cell` metres square, over the
///   bounding box of the scan's returns grown by `R` (cells grow if that would exceed
///   2^24 cells).
/// * **Votes.** Each return votes for every cell on the circle of radius `R` around it,
///   but only on the half of that circle facing away from the sensor (a circle seen from
///   the sensor lies behind its returns; the near half would be hidden by the circle
///   itself). Each cell gets at most one vote per return, of weight equal to the return's
///   range `r`: beams `dθ` apart hit a surface at range `r` about `r dθ` apart, so the
///   weight undoes the `1/r` fall of point density and near walls no longer drown far
///   circles.
/// * **Peaks.** Cells that are maxima of their 3 x 3 neighbourhood with at least
///   `min_fraction` of the best cell's votes and `min_support` of a full circle's votes;
///   the strongest first, dropping any within `R` of a stronger one, at most `max_peaks`.
/// * **Centre.** The vote-weighted mean of the cell centres within `refine_cells` of the
///   peak.
///
/// `rms` and `returns` describe the returns within `R + member_tolerance` of the centre;
/// the confidence is the peak's votes over a full circle's (`2 asin(R / c) c /
/// angle_increment` at centre range `c`), at most 1. Like any Hough transform it always
/// answers with the strongest peaks, circles or not.
///
/// ```
/// use olmap::beacon::{detect_circles_rwht, RwhtParams};
/// use olmap::cloud::LaserScan;
/// let (radius, cx) = (0.125, 2.0);
/// let step = 0.5f64.to_radians();
/// let ranges = (0..81)
///     .map(|i| {
///         let a = -20f64.to_radians() + i as f64 * step;
///         let disc = radius * radius - (cx * a.sin()).powi(2);
///         if disc >= 0.0 { (cx * a.cos() - disc.sqrt()) as f32 } else { f32::INFINITY }
///     })
///     .collect();
/// let scan = LaserScan {
///     angle_min: -20f64.to_radians(),
///     angle_increment: step,
///     range_min: 0.0,
///     range_max: 8.0,
///     ranges,
///     intensities: None,
///     time: 0.0,
/// };
/// let found = detect_circles_rwht(&scan, radius, &RwhtParams::default());
/// assert!((found[0].center.x - cx).abs() < 0.02);
/// assert!(found[0].center.y.abs() < 0.02);
/// ```
pub fn detect_circles_rwht(scan: &LaserScan, radius: f64, params: &RwhtParams) -> Vec<Detection> {
    let step = scan.angle_increment.abs();
    if !radius.is_finite()
        || radius <= 0.0
        || !params.cell.is_finite()
        || params.cell <= 0.0
        || !step.is_finite()
        || step <= 0.0
    {
        return Vec::new();
    }
    let returns = valid_returns(scan);
    if returns.is_empty() {
        return Vec::new();
    }
    let mut acc = Accumulator::covering(&returns, radius, params.cell);
    acc.vote(&returns, radius);
    let full = 2.0 * radius / step;
    let Some(peaks) = acc.peaks(params, full) else {
        return Vec::new();
    };
    let found = detections_at_peaks(&acc, peaks, &returns, radius, step, full, params);
    merge_duplicates(found, radius)
}

/// A valid return: its point, range and bearing.
type Return = (Point2<f64>, f64, f64);

/// The scan's valid returns, in beam order.
fn valid_returns(scan: &LaserScan) -> Vec<Return> {
    (0..scan.len())
        .filter(|&i| scan.is_valid(i))
        .map(|i| {
            let r = scan.ranges[i] as f64;
            let a = scan.angle(i);
            (Point2::new(r * a.cos(), r * a.sin()), r, a)
        })
        .collect()
}

/// The Hough accumulator: range-weighted votes for candidate centres on a square grid.
struct Accumulator {
    /// The votes, row by row (`y * nx + x`).
    acc: Vec<f32>,
    /// Cells along x.
    nx: usize,
    /// Cells along y.
    ny: usize,
    /// The corner of cell `(0, 0)`.
    min: Point2<f64>,
    /// Cell size, metres.
    cell: f64,
}

impl Accumulator {
    /// An empty accumulator over the bounding box of `returns` (not empty) grown by the
    /// radius and two cells, its cells `cell` metres square, doubled until there are at
    /// most [`MAX_CELLS`].
    fn covering(returns: &[Return], radius: f64, cell: f64) -> Self {
        let grow = radius + 2.0 * cell;
        let (mut min, mut max) = (returns[0].0, returns[0].0);
        for (p, _, _) in returns {
            min = min.inf(p);
            max = max.sup(p);
        }
        let min = min - nalgebra::Vector2::new(grow, grow);
        let max = max + nalgebra::Vector2::new(grow, grow);
        let mut cell = cell;
        // Saturating: a radius of 1e20 m asks for more than `usize::MAX` cells at first.
        let dims = |cell: f64| {
            (
                (((max.x - min.x) / cell).ceil() as usize).saturating_add(1),
                (((max.y - min.y) / cell).ceil() as usize).saturating_add(1),
            )
        };
        let (mut nx, mut ny) = dims(cell);
        while nx.saturating_mul(ny) > MAX_CELLS {
            cell *= 2.0;
            (nx, ny) = dims(cell);
        }
        Accumulator {
            acc: vec![0.0f32; nx * ny],
            nx,
            ny,
            min,
            cell,
        }
    }

    /// Each return votes, with its range as weight, once per cell along the far half of
    /// the circle of `radius` around it.
    fn vote(&mut self, returns: &[Return], radius: f64) {
        let (nx, min, cell) = (self.nx, self.min, self.cell);
        let samples = ((std::f64::consts::PI * radius / (0.5 * cell)).ceil() as usize).max(2);
        for &(p, r, a) in returns {
            let mut last = usize::MAX;
            for k in 0..=samples {
                let beta = a - std::f64::consts::FRAC_PI_2
                    + std::f64::consts::PI * k as f64 / samples as f64;
                let cx = ((p.x + radius * beta.cos() - min.x) / cell) as usize;
                let cy = ((p.y + radius * beta.sin() - min.y) / cell) as usize;
                // Rounding can put a vote of a huge circle one cell past the grid.
                if cx >= nx || cy >= self.ny {
                    continue;
                }
                let idx = cy * nx + cx;
                if idx != last {
                    self.acc[idx] += r as f32;
                    last = idx;
                }
            }
        }
    }

    /// The 3 x 3 local maxima above the thresholds (`full`: a full circle's votes) as
    /// `(votes, x, y)`, strongest first; `None` when no cell can pass.
    fn peaks(&self, params: &RwhtParams, full: f64) -> Option<Vec<(f32, usize, usize)>> {
        let (acc, nx, ny) = (&self.acc, self.nx, self.ny);
        let best = acc.iter().copied().fold(0.0f32, f32::max) as f64;
        let threshold = (params.min_fraction * best).max(params.min_support * full);
        if best <= 0.0 || best < threshold {
            return None;
        }
        let mut peaks: Vec<(f32, usize, usize)> = Vec::new();
        for y in 1..ny.saturating_sub(1) {
            for x in 1..nx.saturating_sub(1) {
                let v = acc[y * nx + x];
                if (v as f64) < threshold {
                    continue;
                }
                let mut is_max = true;
                'n: for dy in 0..3 {
                    for dx in 0..3 {
                        let j = (y + dy - 1) * nx + (x + dx - 1);
                        let earlier = j < y * nx + x;
                        let w = acc[j];
                        if (earlier && w >= v) || (!earlier && w > v) {
                            is_max = false;
                            break 'n;
                        }
                    }
                }
                if is_max {
                    peaks.push((v, x, y));
                }
            }
        }
        peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
        Some(peaks)
    }

    /// The vote-weighted mean of the cell centres within `k` cells of cell `(x, y)`.
    fn refined_centre(&self, x: usize, y: usize, k: isize) -> Point2<f64> {
        let (nx, ny, min, cell) = (self.nx, self.ny, self.min, self.cell);
        let (mut sw, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for dy in -k..=k {
            for dx in -k..=k {
                let (cx, cy) = (x as isize + dx, y as isize + dy);
                if cx < 0 || cy < 0 || cx >= nx as isize || cy >= ny as isize {
                    continue;
                }
                let w = self.acc[cy as usize * nx + cx as usize] as f64;
                sw += w;
                sx += w * (min.x + (cx as f64 + 0.5) * cell);
                sy += w * (min.y + (cy as f64 + 0.5) * cell);
            }
        }
        Point2::new(sx / sw, sy / sw)
    }
}

/// A detection per peak, strongest first, at most `max_peaks`, skipping any within
/// `radius` of one already found.
fn detections_at_peaks(
    acc: &Accumulator,
    peaks: Vec<(f32, usize, usize)>,
    returns: &[Return],
    radius: f64,
    step: f64,
    full: f64,
    params: &RwhtParams,
) -> Vec<Detection> {
    let mut found: Vec<Detection> = Vec::new();
    let k = params.refine_cells as isize;
    for (votes, x, y) in peaks {
        if found.len() >= params.max_peaks {
            break;
        }
        let center = acc.refined_centre(x, y, k);
        if found.iter().any(|d| (d.center - center).norm() < radius) {
            continue;
        }
        found.push(describe(
            center,
            votes,
            returns,
            radius,
            step,
            full,
            params.member_tolerance,
        ));
    }
    found
}

/// The detection at `center`: the RMS and count of the returns within `radius +
/// tolerance`, and the peak's `votes` over a full circle's at the centre's range.
fn describe(
    center: Point2<f64>,
    votes: f32,
    returns: &[Return],
    radius: f64,
    step: f64,
    full: f64,
    tolerance: f64,
) -> Detection {
    let members: Vec<f64> = returns
        .iter()
        .map(|(p, _, _)| circle_residual(p, &center, radius))
        .filter(|e| *e <= tolerance)
        .collect();
    let rms = if members.is_empty() {
        f64::INFINITY
    } else {
        (members.iter().map(|e| e * e).sum::<f64>() / members.len() as f64).sqrt()
    };
    let c = center.coords.norm();
    let expected = if c > radius {
        2.0 * (radius / c).asin() * c / step
    } else {
        full
    };
    Detection {
        center,
        rms,
        returns: members.len(),
        confidence: (votes as f64 / expected).clamp(0.0, 1.0),
    }
}
