//! Robot clearing (thesis §6.5.1): before a scan joins a map, the points on the robots it
//! saw are removed, so that robots are not mapped as furniture.

use crate::cloud::PointCloud;
use crate::error::{Error, Result};

/// How far below the floor the cleared cylinder starts, metres (range noise).
const FLOOR_SLACK: f64 = 0.1;

/// The cylinder cleared around each sighted robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClearingParams {
    /// Cylinder radius, metres (default 0.2, the thesis' value; use the robots' body
    /// radius plus a margin, e.g. 0.35 m for the simulator's 0.25 m bodies).
    pub radius: f64,
    /// Cylinder height above the floor (the scan frame's z = 0), metres (default 2).
    pub height: f64,
}

impl Default for ClearingParams {
    fn default() -> Self {
        ClearingParams {
            radius: 0.2,
            height: 2.0,
        }
    }
}

/// Removes from `cloud` (in a scan frame with z = 0 on the floor) every point inside a
/// vertical cylinder of `params.radius` and `params.height` standing on the floor (from
/// 0.1 m below it, for range noise) at each
/// `(x, y)` of `robots` (the sighted robots' positions in the same frame). Returns the kept
/// points and how many were removed; attributes stay with their points.
///
/// ```
/// use nalgebra::Point3;
/// use olmap::cloud::PointCloud;
/// use olmap::team::{clear_robots, ClearingParams};
/// let cloud = PointCloud::from_points(vec![
///     Point3::new(2.0, 0.0, 0.5),  // on a robot standing at (2.1, 0)
///     Point3::new(2.0, 0.0, 2.5),  // above it (a ceiling lamp)
///     Point3::new(5.0, 1.0, 0.5),  // a wall
/// ]);
/// let (kept, removed) = clear_robots(&cloud, &[(2.1, 0.0)], &ClearingParams::default()).unwrap();
/// assert_eq!((kept.len(), removed), (2, 1));
/// ```
pub fn clear_robots(
    cloud: &PointCloud,
    robots: &[(f64, f64)],
    params: &ClearingParams,
) -> Result<(PointCloud, usize)> {
    if !(params.radius >= 0.0 && params.radius.is_finite() && params.height.is_finite()) {
        return Err(Error::InvalidArgument(format!(
            "robot clearing needs a finite radius >= 0 and a finite height, got {params:?}"
        )));
    }
    let r2 = params.radius * params.radius;
    let kept = cloud.select(|_, p| {
        let (x, y, z) = (p.x as f64, p.y as f64, p.z as f64);
        // From a little below the floor (range noise) to the cylinder's top.
        !(z >= -FLOOR_SLACK && z <= params.height)
            || robots
                .iter()
                .all(|&(rx, ry)| (x - rx).powi(2) + (y - ry).powi(2) > r2)
    });
    let removed = cloud.len() - kept.len();
    Ok((kept, removed))
}
