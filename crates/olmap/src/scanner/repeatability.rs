//! The repeatability check of thesis §4.5: two scans taken from the same pose should
//! coincide; the distribution of each point's distance to the closest point of the other
//! scan measures the scanner's repeatability.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use serde::Serialize;

use crate::cloud::PointCloud;
use crate::error::{Error, Result};

/// Options of [`repeatability`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RepeatabilityParams {
    /// Histogram bin width for the mode, metres (default 0.002).
    pub bin_width: f64,
    /// Distance above which a point counts as a discrepancy, metres (default 0.02, the
    /// thesis' figure).
    pub threshold: f64,
}

impl Default for RepeatabilityParams {
    fn default() -> Self {
        RepeatabilityParams {
            bin_width: 0.002,
            threshold: 0.02,
        }
    }
}

/// The closest-point distance distribution from scan A to scan B.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RepeatabilityReport {
    /// Points of A measured.
    pub points: usize,
    /// Mean distance, metres.
    pub mean: f64,
    /// Median distance, metres.
    pub median: f64,
    /// Centre of the most populated histogram bin, metres.
    pub mode: f64,
    /// Largest distance, metres.
    pub max: f64,
    /// Share of points farther than the threshold (0..1).
    pub share_above: f64,
    /// The threshold used, metres.
    pub threshold: f64,
}

/// For every point of `a`, the distance to the closest point of `b` (a KD-tree over
/// `b`), summarised. Both scans must be non-empty and in the same frame.
pub fn repeatability(
    a: &PointCloud,
    b: &PointCloud,
    params: &RepeatabilityParams,
) -> Result<RepeatabilityReport> {
    if a.is_empty() || b.is_empty() {
        return Err(Error::InvalidArgument(
            "repeatability: both scans need points".into(),
        ));
    }
    if !(params.bin_width.is_finite()
        && params.bin_width > 0.0
        && params.threshold.is_finite()
        && params.threshold >= 0.0)
    {
        return Err(Error::InvalidArgument(format!(
            "repeatability: bin width must be a finite number > 0 m and threshold a finite \
             number >= 0 m, got {} and {}",
            params.bin_width, params.threshold
        )));
    }
    let coords: Vec<[f64; 3]> = b
        .points()
        .iter()
        .map(|p| [p.x as f64, p.y as f64, p.z as f64])
        .collect();
    let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&coords)
        .map_err(|e| Error::InvalidArgument(format!("repeatability: cannot index scan B: {e}")))?;
    let mut d: Vec<f64> = a
        .points()
        .iter()
        .map(|p| {
            tree.query(&[p.x as f64, p.y as f64, p.z as f64])
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute()
                .distance
                .sqrt()
        })
        .collect();
    d.sort_by(f64::total_cmp);
    let n = d.len();
    let median = if n % 2 == 1 {
        d[n / 2]
    } else {
        0.5 * (d[n / 2 - 1] + d[n / 2])
    };
    let max = d[n - 1];
    // Saturating: a bin of 1e-20 m asks for more than `usize::MAX` bins (capped below).
    let bins = ((max / params.bin_width) as usize)
        .saturating_add(1)
        .min(1 << 20);
    let mut hist = vec![0usize; bins];
    for &x in &d {
        hist[((x / params.bin_width) as usize).min(bins - 1)] += 1;
    }
    let best = (0..bins)
        .max_by_key(|&i| (hist[i], std::cmp::Reverse(i)))
        .unwrap_or(0);
    Ok(RepeatabilityReport {
        points: n,
        mean: d.iter().sum::<f64>() / n as f64,
        median,
        mode: (best as f64 + 0.5) * params.bin_width,
        max,
        share_above: d.iter().filter(|&&x| x > params.threshold).count() as f64 / n as f64,
        threshold: params.threshold,
    })
}
