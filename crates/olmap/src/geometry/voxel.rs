//! Integer voxel keys: which cell of a regular grid a point falls in.

use nalgebra::Point3;

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
