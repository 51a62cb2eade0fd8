//! Position buckets (thesis §3.3.3): integrate a scan only from a new position.
//!
//! Range errors depend mostly on where the sensor stands, so repeated scans from one spot
//! are not independent observations: integrating them all would make the map ever more
//! certain of the same errors. The thesis keeps only data from new positions, whatever the
//! heading ("better to discard possibly useful data than risk irrevocably damaging the map").

use nalgebra::Point3;

use crate::error::{Error, Result};

/// Remembers the sensor positions already integrated.
///
/// ```
/// use olmap::occupancy::PositionBuckets;
/// use nalgebra::Point3;
/// let mut buckets = PositionBuckets::new(0.5).unwrap();
/// assert!(buckets.admit(&Point3::new(0.0, 0.0, 0.0)));
/// assert!(!buckets.admit(&Point3::new(0.3, 0.0, 0.0))); // same position: skipped
/// assert!(buckets.admit(&Point3::new(1.0, 0.0, 0.0)));
/// ```
#[derive(Debug, Clone)]
pub struct PositionBuckets {
    radius: f64,
    positions: Vec<Point3<f64>>,
}

impl PositionBuckets {
    /// Buckets of the given radius, metres.
    pub fn new(radius: f64) -> Result<Self> {
        if !(radius.is_finite() && radius >= 0.0) {
            return Err(Error::InvalidArgument(format!(
                "position bucket radius must be >= 0 m, got {radius}"
            )));
        }
        Ok(PositionBuckets {
            radius,
            positions: Vec::new(),
        })
    }

    /// Whether a scan taken at `position` should be integrated: true (and the position is
    /// remembered) when no earlier admitted scan was taken within the radius.
    pub fn admit(&mut self, position: &Point3<f64>) -> bool {
        let r2 = self.radius * self.radius;
        if self
            .positions
            .iter()
            .any(|p| (p - position).norm_squared() < r2)
        {
            return false;
        }
        self.positions.push(*position);
        true
    }

    /// Positions admitted so far.
    pub fn positions(&self) -> &[Point3<f64>] {
        &self.positions
    }
}
