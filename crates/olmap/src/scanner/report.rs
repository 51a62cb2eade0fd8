//! [`ScannerConvertReport`]: the typed result of `olmap scanner convert --json`, a raw
//! mirror-scanner log turned into a cloud.

use serde::{Deserialize, Serialize};

use super::ConvertStats;

/// Beams dropped by the conversion, by reason.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DroppedReport {
    /// Beams with no return.
    pub no_return: usize,
    /// Beams that missed the mirror.
    pub outside_mirror: usize,
    /// Beams on the mirror edge.
    pub edge_on: usize,
    /// Beams blocked by the scanner's body.
    pub blocked: usize,
    /// Returns beyond the maximum range.
    pub beyond_max_range: usize,
    /// Returns below the minimum range.
    pub below_min_range: usize,
    /// Beams outside the elevation window.
    pub outside_elevation: usize,
    /// Mixed pixels removed.
    pub mixed_pixels: usize,
}

/// The summary of converting a raw log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScannerConvertReport {
    /// The raw log.
    pub input: String,
    /// The cloud written.
    pub output: String,
    /// The scanner mounting's name.
    pub mounting: String,
    /// Sweeps in the log.
    pub sweeps: usize,
    /// Beams in the log.
    pub beams: usize,
    /// Points written.
    pub points: usize,
    /// Beams dropped, by reason.
    pub dropped: DroppedReport,
    /// Triggers that disagree with the tick count.
    pub trigger_mismatches: usize,
    /// Whether each beam was converted at its own time within the sweep.
    pub within_sweep_correction: bool,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl ScannerConvertReport {
    /// The report of a conversion with statistics `s`.
    pub fn new(
        input: &str,
        output: &str,
        mounting: &str,
        s: &ConvertStats,
        within_sweep_correction: bool,
        seconds: f64,
    ) -> Self {
        ScannerConvertReport {
            input: input.to_string(),
            output: output.to_string(),
            mounting: mounting.to_string(),
            sweeps: s.sweeps,
            beams: s.beams,
            points: s.points,
            dropped: DroppedReport {
                no_return: s.no_return,
                outside_mirror: s.outside_mirror,
                edge_on: s.edge_on,
                blocked: s.blocked,
                beyond_max_range: s.beyond_max_range,
                below_min_range: s.below_min_range,
                outside_elevation: s.outside_elevation,
                mixed_pixels: s.mixed_pixels,
            },
            trigger_mismatches: s.trigger_mismatches,
            within_sweep_correction,
            seconds,
        }
    }
}
