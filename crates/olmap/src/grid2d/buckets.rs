//! The position-bucket rule of thesis §3.3.3 for 2D grids: integrate a scan only when it
//! was taken from a new position, whatever its heading.
//!
//! A laser scanner's errors depend mostly on where it stands, so scans from one spot are
//! not independent and integrating them all would make the grid ever more certain of the
//! same errors. As in the thesis (after Konolige 1997, with position rather than pose
//! buckets), a scan is integrated only when its sensor position lies at least
//! `bucket_radius` from every position integrated before; the rest are discarded. The
//! positions are remembered by [`PositionBuckets`] (the 3D maps' buckets), here with the
//! sensor position projected onto the map plane.

use nalgebra::Point3;

use super::grid::{InsertStats, OccupancyGrid2d};
use super::sensor_model::SensorModel2d;
use crate::cloud::LaserScan;
use crate::error::Result;
use crate::geometry::Pose;
use crate::occupancy::PositionBuckets;

impl OccupancyGrid2d {
    /// Inserts the scan as [`OccupancyGrid2d::insert_scan`] does if its sensor position
    /// (x, y) is at least the buckets' radius from every position admitted before, and
    /// then remembers that position (also if the grid then cannot grow); returns `None` (grid untouched) for a scan from a
    /// position already integrated, whatever its heading.
    ///
    /// ```
    /// use olmap::cloud::LaserScan;
    /// use olmap::geometry::Pose;
    /// use olmap::grid2d::{OccupancyGrid2d, SensorModel2d};
    /// use olmap::occupancy::PositionBuckets;
    /// let scan = LaserScan {
    ///     angle_min: 0.0, angle_increment: 0.1, range_min: 0.0, range_max: 8.0,
    ///     ranges: vec![2.0; 10], intensities: None, time: 0.0,
    /// };
    /// let model = SensorModel2d::default();
    /// let mut grid = OccupancyGrid2d::new(0.05).unwrap();
    /// let mut buckets = PositionBuckets::new(0.5).unwrap();
    /// let at = |x: f64, yaw: f64| Pose::from_xyz_ypr(x, 0.0, 0.0, yaw, 0.0, 0.0);
    /// assert!(grid.insert_scan_bucketed(&scan, &at(0.0, 0.0), &model, &mut buckets).unwrap().is_some());
    /// // Turning on the spot gives no new position: skipped.
    /// assert!(grid.insert_scan_bucketed(&scan, &at(0.1, 1.5), &model, &mut buckets).unwrap().is_none());
    /// assert!(grid.insert_scan_bucketed(&scan, &at(1.0, 0.0), &model, &mut buckets).unwrap().is_some());
    /// ```
    pub fn insert_scan_bucketed(
        &mut self,
        scan: &LaserScan,
        t_world_sensor: &Pose,
        model: &SensorModel2d,
        buckets: &mut PositionBuckets,
    ) -> Result<Option<InsertStats>> {
        let t = t_world_sensor.translation();
        let position = Point3::new(t.x, t.y, 0.0);
        // Bad input is refused before the position is remembered.
        Self::check_inputs(scan, t_world_sensor, model)?;
        if !buckets.admit(&position) {
            return Ok(None);
        }
        self.insert_scan(scan, t_world_sensor, model).map(Some)
    }
}
