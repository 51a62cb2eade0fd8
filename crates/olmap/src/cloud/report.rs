//! Serialisable pieces of cloud summaries: a bounding box and a range distribution as
//! JSON objects (`{"min": [x, y, z], "max": [x, y, z]}`, `{"min", "max", "mean",
//! "median"}`), shared by the reports of `olmap info` and others.

use serde::{Deserialize, Serialize};

use super::RangeStats;
use crate::geometry::Aabb;

/// A bounding box as JSON: its corners as `[x, y, z]` arrays, metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoxReport {
    /// The lower corner.
    pub min: [f64; 3],
    /// The upper corner.
    pub max: [f64; 3],
}

impl BoxReport {
    /// The corners of `b`.
    pub fn new(b: &Aabb) -> Self {
        BoxReport {
            min: [b.min.x, b.min.y, b.min.z],
            max: [b.max.x, b.max.y, b.max.z],
        }
    }

    /// `max - min` per axis, as [`Aabb::extent`] computes it.
    pub fn extent(&self) -> [f64; 3] {
        [
            self.max[0] - self.min[0],
            self.max[1] - self.min[1],
            self.max[2] - self.min[2],
        ]
    }
}

/// The distribution of point ranges as JSON, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RangeReport {
    /// Smallest range.
    pub min: f64,
    /// Largest range.
    pub max: f64,
    /// Mean range.
    pub mean: f64,
    /// Median range.
    pub median: f64,
}

impl From<RangeStats> for RangeReport {
    fn from(r: RangeStats) -> Self {
        RangeReport {
            min: r.min,
            max: r.max,
            mean: r.mean,
            median: r.median,
        }
    }
}
