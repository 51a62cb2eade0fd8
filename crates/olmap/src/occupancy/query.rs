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

/// The key box of a list's stored voxels, for walks that stop once they leave it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct KeyBounds {
    lo: [i64; 3],
    hi: [i64; 3],
}

/// Keys beyond this (in voxels from the origin) do not fit a [`VoxelKey`]: a walk never
/// starts or ends there.
const FAR_KEY: f64 = i32::MAX as f64;

/// Where a walk from `a` to `b` starts and ends, as fractions of the segment: the segment
/// itself when both ends lie near the map, else cut to the stored voxels' box (nothing
/// lies outside it). `None` when the segment misses the box.
fn walk_span(a: &Point3<f64>, b: &Point3<f64>, r: f64, k: &KeyBounds) -> Option<(f64, f64)> {
    let key = |p: &Point3<f64>, i: usize| (p[i] / r).floor();
    let outside = (0..3).any(|i| {
        let v = key(a, i);
        v < k.lo[i] as f64 || v > k.hi[i] as f64
    });
    let far = (0..3).any(|i| key(b, i).abs() >= FAR_KEY);
    if !outside && !far {
        return Some((0.0, 1.0));
    }
    // Slab clipping of the segment against the box of the stored voxels' cubes, in
    // halves so that `b - a` cannot overflow (ends at ±1e308 m).
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for i in 0..3 {
        let (lo, hi) = (k.lo[i] as f64 * r, (k.hi[i] + 1) as f64 * r);
        let half = 0.5 * b[i] - 0.5 * a[i];
        if half == 0.0 {
            if a[i] < lo || a[i] > hi {
                return None;
            }
            continue;
        }
        let (u, v) = (
            (0.5 * lo - 0.5 * a[i]) / half,
            (0.5 * hi - 0.5 * a[i]) / half,
        );
        t0 = t0.max(u.min(v));
        t1 = t1.min(u.max(v));
    }
    if t0 > t1 {
        return None;
    }
    Some((if outside { t0 } else { 0.0 }, if far { t1 } else { 1.0 }))
}

impl OccupancyList {
    /// The key box of the stored voxels, `None` when the list is empty.
    pub(crate) fn key_bounds(&self) -> Option<KeyBounds> {
        let mut lo = [i64::MAX; 3];
        let mut hi = [i64::MIN; 3];
        for (k, _) in self.iter() {
            for (i, v) in [k.x, k.y, k.z].into_iter().enumerate() {
                lo[i] = lo[i].min(v as i64);
                hi[i] = hi[i].max(v as i64);
            }
        }
        (!self.is_empty()).then_some(KeyBounds { lo, hi })
    }

    /// The voxels from `a` to `b` in order with the segment fraction where each is entered,
    /// until `stop` says so: only the part of the segment that can meet a stored voxel is
    /// walked (see [`walk_span`], [`VoxelRay::past_box`]), so a segment of 1e15 m costs no
    /// more than one across the map, and its keys never leave the representable range.
    fn walk(
        &self,
        a: &Point3<f64>,
        b: &Point3<f64>,
        bounds: Option<&KeyBounds>,
        mut stop: impl FnMut(VoxelKey, f64) -> bool,
    ) {
        let Some(k) = bounds else { return };
        let r = self.resolution();
        let Some((t0, t1)) = walk_span(a, b, r, k) else {
            return;
        };
        let at = |t: f64| {
            if t == 0.0 {
                *a
            } else if t == 1.0 {
                *b
            } else {
                Point3::from(a.coords * (1.0 - t) + b.coords * t)
            }
        };
        let mut ray = VoxelRay::new(&at(t0), &at(t1), r);
        while !ray.past_box(k.lo, k.hi) {
            let Some(key) = ray.next() else { return };
            let entry = if (t0, t1) == (0.0, 1.0) {
                ray.entry()
            } else {
                t0 + ray.entry() * (t1 - t0)
            };
            if stop(key, entry) {
                return;
            }
        }
    }

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
        Ok(self.cast_ray_in(
            origin,
            direction,
            max_range,
            min_count,
            self.key_bounds().as_ref(),
        ))
    }

    /// [`OccupancyList::cast_ray`] with checked arguments and the list's
    /// [`OccupancyList::key_bounds`] computed once (a depth image casts a ray per pixel).
    pub(crate) fn cast_ray_in(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        max_range: f64,
        min_count: u16,
        bounds: Option<&KeyBounds>,
    ) -> Option<RayHit> {
        let dir = direction / direction.norm();
        let mut max_range = max_range;
        let mut end = origin + dir * max_range;
        if let (Some(k), false) = (bounds, end.iter().all(|v| v.is_finite())) {
            // A range of 1e308 m overflows: walk as far as the box's far corner instead.
            let r = self.resolution();
            let corner = |i: usize| {
                let (lo, hi) = (k.lo[i] as f64 * r, (k.hi[i] + 1) as f64 * r);
                (origin[i] - lo).abs().max((origin[i] - hi).abs())
            };
            max_range = Vector3::new(corner(0), corner(1), corner(2)).norm() + r;
            end = origin + dir * max_range;
        }
        let min_count = min_count.max(1);
        let mut hit = None;
        self.walk(origin, &end, bounds, |key, entry| {
            let count = self.count(key);
            if count >= min_count {
                let distance = entry.max(0.0) * max_range;
                hit = Some(RayHit {
                    key,
                    count,
                    distance,
                    point: origin + dir * distance,
                });
            }
            hit.is_some()
        });
        hit
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
        let mut free = true;
        self.walk(a, b, self.key_bounds().as_ref(), |k, _| {
            free = self.count(k) < min_count;
            !free
        });
        Ok(free)
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
