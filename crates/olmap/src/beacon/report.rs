//! [`BeaconsReport`]: the typed result of `olmap beacons --json`, the circles found in one
//! 2D scan.

use serde::{Deserialize, Serialize};

use super::Detection;

/// One circle found, in the sensor frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectionReport {
    /// Centre, x (forward), metres.
    pub x: f64,
    /// Centre, y (left), metres.
    pub y: f64,
    /// Range of the centre, metres.
    pub range: f64,
    /// Bearing of the centre, degrees (positive to the left).
    pub bearing_deg: f64,
    /// RMS distance of the returns to the circumference, metres.
    pub rms: f64,
    /// Returns on the circle.
    pub returns: usize,
    /// The detector's confidence in `[0, 1]`.
    pub confidence: f64,
}

impl From<&Detection> for DetectionReport {
    fn from(d: &Detection) -> Self {
        DetectionReport {
            x: d.center.x,
            y: d.center.y,
            range: d.range(),
            bearing_deg: d.bearing().to_degrees(),
            rms: d.rms,
            returns: d.returns,
            confidence: d.confidence,
        }
    }
}

/// The circles found in a scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BeaconsReport {
    /// The scan file.
    pub path: String,
    /// The detection method (`lsq`, `rwht`, `reflective`).
    pub method: String,
    /// Beacon radius, metres.
    pub radius: f64,
    /// Beams in the scan.
    pub beams: usize,
    /// The circles found.
    pub detections: Vec<DetectionReport>,
}

impl BeaconsReport {
    /// The report of `found` in the scan `path` of `beams` beams, by `method` at `radius`.
    pub fn new(path: &str, method: &str, radius: f64, beams: usize, found: &[Detection]) -> Self {
        BeaconsReport {
            path: path.to_string(),
            method: method.to_string(),
            radius,
            beams,
            detections: found.iter().map(DetectionReport::from).collect(),
        }
    }
}
