//! Integer voxel keys: which cell of a regular grid a point falls in.

use nalgebra::Point3;

use crate::error::Error;

/// The integer cell `floor(coord / resolution)` of a point, per axis.
///
/// Floor, not truncation: a point at x = -0.01 m with 0.1 m voxels is in cell -1.
///
/// ```
/// use olmap::geometry::VoxelKey;
/// use nalgebra::Point3;
/// let k = VoxelKey::from_point(&Point3::new(-0.01, 0.25, 0.0), 0.1).unwrap();
/// assert_eq!(k, VoxelKey::new(-1, 2, 0));
/// assert!((k.center(0.1) - Point3::new(-0.05, 0.25, 0.05)).norm() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct VoxelKey {
    /// Cell index along x.
    pub x: i32,
    /// Cell index along y.
    pub y: i32,
    /// Cell index along z.
    pub z: i32,
}

impl VoxelKey {
    /// A key from its three indices.
    pub const fn new(x: i32, y: i32, z: i32) -> Self {
        VoxelKey { x, y, z }
    }

    /// The cell holding `p` at `resolution` metres, or `None` when a coordinate is not finite
    /// or its index does not fit in an `i32`.
    #[inline]
    pub fn from_point(p: &Point3<f64>, resolution: f64) -> Option<Self> {
        let f = |c: f64| {
            let k = (c / resolution).floor();
            (k.is_finite() && k >= i32::MIN as f64 && k <= i32::MAX as f64).then_some(k as i32)
        };
        Some(VoxelKey::new(f(p.x)?, f(p.y)?, f(p.z)?))
    }

    /// The centre of the cell, `(key + 0.5) * resolution`.
    pub fn center(&self, resolution: f64) -> Point3<f64> {
        Point3::new(
            (self.x as f64 + 0.5) * resolution,
            (self.y as f64 + 0.5) * resolution,
            (self.z as f64 + 0.5) * resolution,
        )
    }
}

/// The error for point `index` at `p` (metres) whose voxel key at `resolution` lies outside
/// `±max_key` voxels per axis: [`Error::TooLarge`] naming `what` (the cloud), the point,
/// its key and the extent the key range allows, never a silent wrap or drop.
///
/// ```
/// use olmap::geometry::key_range_error;
/// use nalgebra::Point3;
/// let e = key_range_error("scan000.3d", 7, &Point3::new(3.0, 0.0, 0.0), 1e-9, 131_071);
/// let text = e.to_string();
/// assert!(text.contains("point 7") && text.contains("scan000.3d"), "{text}");
/// ```
pub fn key_range_error(
    what: &str,
    index: usize,
    p: &Point3<f64>,
    resolution: f64,
    max_key: i64,
) -> Error {
    let key = p.coords.map(|c| (c / resolution).floor());
    Error::TooLarge {
        what: format!(
            "{what}: point {index} at ({}, {}, {}) m has the voxel key ({:.0}, {:.0}, {:.0}) at \
             {resolution} m, outside the representable keys (use a coarser resolution, or \
             bring the points nearer the origin)",
            p.x, p.y, p.z, key.x, key.y, key.z
        ),
        limit: format!(
            "±{max_key} voxels per axis, ±{:.6} m at {resolution} m",
            max_key as f64 * resolution
        ),
    }
}
