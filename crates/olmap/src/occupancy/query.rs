//! Map queries a planner or a script needs: ray casts, voxels near a point and free-space
//! tests along segments, all answered from the occupancy list alone.

use nalgebra::{Point3, Vector3};

use super::list::OccupancyList;
use super::raytrace::VoxelRay;
use crate::error::{Error, Result};
use crate::geometry::VoxelKey;

/// The first occupied voxel met by a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// The voxel.
    pub key: VoxelKey,
    /// Its count.
    pub count: u16,
    /// Distance (metres) from the ray's origin to where the ray enters the voxel (0 when the
    /// origin is inside it).
    pub distance: f64,
    /// The entry point, `origin + distance * direction`.
    pub point: Point3<f64>,
}

fn check_point(what: &str, p: &Point3<f64>) -> Result<()> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::InvalidArgument(format!(
            "{what} must be finite, got {p}"
        )))
    }
}

impl OccupancyList {
    /// Casts a ray from `origin` along `direction` (any non-zero length; normalised here) up
    /// to `max_range` metres, walking the voxels in order (Amanatides & Woo, the traversal of
    /// [`super::VoxelRay`]), and returns the first voxel whose count is at least `min_count`
    /// (at least 1), or `None` when the ray leaves the range first. The distance is to the
    /// voxel's boundary where the ray enters it, so it is within one voxel diagonal of the
    /// surface the voxel stands for.
    ///
    /// ```
    /// use olmap::occupancy::OccupancyList;
    /// use olmap::geometry::VoxelKey;
    /// use nalgebra::{Point3, Vector3};
    /// let mut map = OccupancyList::new(0.1).unwrap();
    /// map.set(VoxelKey::new(20, 0, 0), 3).unwrap(); // x in [2.0, 2.1)
    /// let hit = map
    ///     .cast_ray(&Point3::new(0.05, 0.05, 0.05), &Vector3::x(), 10.0, 1)
    ///     .unwrap()
    ///     .unwrap();
    /// assert_eq!(hit.key, VoxelKey::new(20, 0, 0));
    /// assert!((hit.distance - 1.95).abs() < 1e-9);
    /// assert!(map.cast_ray(&Point3::new(0.05, 0.05, 0.05), &-Vector3::x(), 10.0, 1).unwrap().is_none());
    /// ```
    pub fn cast_ray(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        max_range: f64,
        min_count: u16,
    ) -> Result<Option<RayHit>> {
        check_point("ray origin", origin)?;
        let n = direction.norm();
        if !(n.is_finite() && n > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "ray direction must be finite and non-zero, got {direction}"
            )));
        }
        if !(max_range.is_finite() && max_range >= 0.0) {
            return Err(Error::InvalidArgument(format!(
                "ray range must be finite and >= 0 m, got {max_range}"
            )));
        }
        let dir = direction / n;
        let end = origin + dir * max_range;
        let min_count = min_count.max(1);
        let mut ray = VoxelRay::new(origin, &end, self.resolution());
        while let Some(key) = ray.next() {
            let count = self.count(key);
            if count >= min_count {
                let distance = ray.entry().max(0.0) * max_range;
                return Ok(Some(RayHit {
                    key,
                    count,
                    distance,
                    point: origin + dir * distance,
                }));
            }
        }
        Ok(None)
    }

    /// Whether the segment from `a` to `b` crosses no voxel with a count of at least
    /// `min_count` (at least 1), the voxels of both ends included.
    ///
    /// ```
    /// use olmap::occupancy::OccupancyList;
    /// use olmap::geometry::VoxelKey;
    /// use nalgebra::Point3;
    /// let mut map = OccupancyList::new(0.1).unwrap();
    /// map.set(VoxelKey::new(5, 0, 0), 1).unwrap();
    /// let (a, b) = (Point3::new(0.05, 0.05, 0.05), Point3::new(1.05, 0.05, 0.05));
    /// assert!(!map.segment_is_free(&a, &b, 1).unwrap());
    /// assert!(map.segment_is_free(&a, &Point3::new(0.45, 0.05, 0.05), 1).unwrap());
    /// ```
    pub fn segment_is_free(
        &self,
        a: &Point3<f64>,
        b: &Point3<f64>,
        min_count: u16,
    ) -> Result<bool> {
        check_point("segment start", a)?;
        check_point("segment end", b)?;
        let min_count = min_count.max(1);
        Ok(VoxelRay::new(a, b, self.resolution()).all(|k| self.count(k) < min_count))
    }

    /// The stored voxels whose centres lie within `radius` metres of `center`, sorted by key.
    /// Walks the keys of the ball's bounding cube or the whole list, whichever is smaller.
    ///
    /// ```
    /// use olmap::occupancy::OccupancyList;
    /// use olmap::geometry::VoxelKey;
    /// use nalgebra::Point3;
    /// let mut map = OccupancyList::new(0.1).unwrap();
    /// map.set(VoxelKey::new(0, 0, 0), 1).unwrap();
    /// map.set(VoxelKey::new(10, 0, 0), 1).unwrap();
    /// let near = map.occupied_within(&Point3::new(0.05, 0.05, 0.05), 0.5).unwrap();
    /// assert_eq!(near, vec![(VoxelKey::new(0, 0, 0), 1)]);
    /// ```
    pub fn occupied_within(
        &self,
        center: &Point3<f64>,
        radius: f64,
    ) -> Result<Vec<(VoxelKey, u16)>> {
        check_point("query centre", center)?;
        if !(radius.is_finite() && radius >= 0.0) {
            return Err(Error::InvalidArgument(format!(
                "query radius must be finite and >= 0 m, got {radius}"
            )));
        }
        let r = self.resolution();
        let inside = |k: VoxelKey| (k.center(r) - center).norm_squared() <= radius * radius;
        let lo = (center.coords - Vector3::repeat(radius)) / r;
        let hi = (center.coords + Vector3::repeat(radius)) / r;
        let span: f64 = (0..3)
            .map(|a| hi[a].floor() - lo[a].floor() + 1.0)
            .product();
        let mut out: Vec<(VoxelKey, u16)> = if span <= self.len() as f64 {
            let mut v = Vec::new();
            let (l, h) = (lo.map(|x| x.floor() as i64), hi.map(|x| x.floor() as i64));
            for z in l.z..=h.z {
                for y in l.y..=h.y {
                    for x in l.x..=h.x {
                        let (Ok(x), Ok(y), Ok(z)) =
                            (i32::try_from(x), i32::try_from(y), i32::try_from(z))
                        else {
                            continue;
                        };
                        let k = VoxelKey::new(x, y, z);
                        let c = self.count(k);
                        if c > 0 && inside(k) {
                            v.push((k, c));
                        }
                    }
                }
            }
            v
        } else {
            self.iter().filter(|&(k, _)| inside(k)).collect()
        };
        out.sort_unstable_by_key(|&(k, _)| k);
        Ok(out)
    }
}
