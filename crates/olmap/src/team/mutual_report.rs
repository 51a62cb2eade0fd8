//! [`MutualReport`]: the typed result of `olmap mutual --json`, the relative pose of two
//! robots from a two-way beacon sighting with its expected position error.

use serde::{Deserialize, Serialize};

use super::{expected_position_error, MutualFix, MutualObservation};
use crate::Result;

/// B's pose in A's frame and the error bound (3.37).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MutualReport {
    /// B's position, x, metres.
    pub x_m: f64,
    /// B's position, y, metres.
    pub y_m: f64,
    /// B's heading, degrees.
    pub heading_deg: f64,
    /// Beacon separation as A sees it, metres.
    pub s1_m: f64,
    /// Beacon separation as B sees it, metres.
    pub s2_m: f64,
    /// The expected position error bound (3.37), metres.
    pub expected_error_m: f64,
}

impl MutualReport {
    /// The report of `fix`, made from the observation `o`, with the error bound for a
    /// range error `range_error` and an apparent beacon width `beacon_width` (metres, no
    /// offset error).
    pub fn new(
        fix: &MutualFix,
        o: &MutualObservation,
        range_error: f64,
        beacon_width: f64,
    ) -> Result<Self> {
        let bound = expected_position_error(o, range_error, beacon_width, 0.0)?;
        Ok(MutualReport {
            x_m: fix.x,
            y_m: fix.y,
            heading_deg: fix.heading.to_degrees(),
            s1_m: fix.s1,
            s2_m: fix.s2,
            expected_error_m: bound,
        })
    }
}

/// The observation a fix found in two scans stands for, for the error bound: both ranges
/// the fix's distance (the separations' geometry makes `a ~ b ~` the distance), bearings
/// 0, beacon offset `d`.
pub fn observation_of_fix(fix: &MutualFix, d: f64) -> MutualObservation {
    let dist = (fix.x * fix.x + fix.y * fix.y).sqrt();
    MutualObservation {
        a: dist,
        alpha: 0.0,
        b: dist,
        beta: 0.0,
        d,
    }
}
