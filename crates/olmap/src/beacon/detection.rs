//! The [`Detection`] record shared by the circle detectors.

use nalgebra::Point2;

/// A circle of the requested radius found in a scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Centre of the circle in the sensor frame (x forward, y left), metres.
    pub center: Point2<f64>,
    /// Root mean square distance of the circle's returns to its circumference, metres
    /// (how each detector picks "the circle's returns" is documented with the detector).
    pub rms: f64,
    /// Number of returns on the circle.
    pub returns: usize,
    /// How sure the detector is, in `[0, 1]`. The least-squares and retroreflective
    /// detectors multiply the circle's *coverage* (returns found / beams that the circle
    /// should have intercepted at that range and bearing, at most 1) by the fit quality
    /// `exp(-(rms / max_rms)^2)`; the Hough detector uses the peak's votes over the votes
    /// a fully visible circle at that range would collect, at most 1.
    pub confidence: f64,
}

impl Detection {
    /// Range of the centre from the sensor, metres.
    pub fn range(&self) -> f64 {
        self.center.coords.norm()
    }

    /// Bearing of the centre, radians from x toward y.
    pub fn bearing(&self) -> f64 {
        self.center.y.atan2(self.center.x)
    }
}

/// Keeps the best of detections whose centres are closer than `min_separation` (best =
/// highest confidence, then lowest rms) and sorts the rest by bearing.
pub(crate) fn merge_duplicates(mut found: Vec<Detection>, min_separation: f64) -> Vec<Detection> {
    found.sort_by(|a, b| {
        b.confidence
            .total_cmp(&a.confidence)
            .then(a.rms.total_cmp(&b.rms))
    });
    let mut kept: Vec<Detection> = Vec::with_capacity(found.len());
    for d in found {
        if kept
            .iter()
            .all(|k| (k.center - d.center).norm() >= min_separation)
        {
            kept.push(d);
        }
    }
    kept.sort_by(|a, b| a.bearing().total_cmp(&b.bearing()));
    kept
}

/// Number of beams of the scan whose angle lies within `half_width` of `bearing`.
pub(crate) fn beams_within(
    angle_min: f64,
    increment: f64,
    len: usize,
    bearing: f64,
    half_width: f64,
) -> usize {
    if len == 0 || increment == 0.0 || !half_width.is_finite() {
        return 0;
    }
    // Beam k sits at angle_min + k increment: count the k in range, clipped to the scan.
    let a = (bearing - half_width - angle_min) / increment;
    let b = (bearing + half_width - angle_min) / increment;
    let lo = a.min(b).ceil().max(0.0);
    let hi = a.max(b).floor().min(len as f64 - 1.0);
    if hi >= lo {
        (hi - lo) as usize + 1
    } else {
        0
    }
}
