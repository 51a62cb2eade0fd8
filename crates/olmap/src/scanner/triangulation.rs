//! The camera and laser-line triangulation scanner (thesis Appendix A) and the range error
//! of triangulation (§4.2.1, (4.1)-(4.6)).
//!
//! A laser line projector casts a plane of light; a camera beside it sees the line where the
//! plane meets the world. Each lit pixel defines a camera ray; its intersection with the
//! laser plane is the 3D point. The plane is measured once from three points on it (the
//! thesis: two lit points on a wall and the laser aperture).
//!
//! Camera frame: the usual pinhole convention, z along the optical axis, x to the right
//! of the image and y down it; pixel `(u, v)` (column, row) maps to the direction
//! `((u - cx) / fx, (v - cy) / fy, 1)`.

use nalgebra::{Point3, Unit, Vector3};

use crate::error::{Error, Result};
use crate::geometry::Pose;

/// A plane `n . p = offset` with unit normal `n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaserPlane {
    /// Unit normal.
    pub normal: Unit<Vector3<f64>>,
    /// `n . p` for every point `p` of the plane, metres.
    pub offset: f64,
}

impl LaserPlane {
    /// The plane through three measured points; an error when they are (nearly)
    /// collinear (the cross product of the two edges is below `1e-12` of their lengths'
    /// product).
    pub fn from_points(a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> Result<Self> {
        let (u, v) = (b - a, c - a);
        let n = u.cross(&v);
        let scale = u.norm() * v.norm();
        if !(n.norm() > 1e-12 * scale && scale > 0.0) {
            return Err(Error::InvalidArgument(
                "laser plane: the three points are collinear or coincide".into(),
            ));
        }
        let normal = Unit::new_normalize(n);
        Ok(LaserPlane {
            normal,
            offset: normal.dot(&a.coords),
        })
    }

    /// Signed distance of `p` from the plane (positive on the normal's side), metres.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        self.normal.dot(&p.coords) - self.offset
    }
}

/// A half-line `origin + t direction`, `t >= 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Start of the ray.
    pub origin: Point3<f64>,
    /// Unit direction.
    pub direction: Unit<Vector3<f64>>,
}

/// Pinhole camera intrinsics, pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeIntrinsics {
    /// Focal length along the image columns (x), pixels.
    pub fx: f64,
    /// Focal length along the image rows (y), pixels.
    pub fy: f64,
    /// Principal point column, pixels.
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
}

impl PinholeIntrinsics {
    /// Unit direction (camera frame) of the ray through pixel `(u, v)` (column, row).
    pub fn direction(&self, u: f64, v: f64) -> Unit<Vector3<f64>> {
        Unit::new_normalize(Vector3::new(
            (u - self.cx) / self.fx,
            (v - self.cy) / self.fy,
            1.0,
        ))
    }

    /// The pixel `(u, v)` a camera-frame point projects to; `None` behind the camera
    /// (`z <= 0`).
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64)> {
        (p.z > 0.0).then(|| (self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }

    /// The ray (in the frame of `t_frame_camera`) through pixel `(u, v)` of a camera at
    /// pose `t_frame_camera`.
    pub fn ray(&self, t_frame_camera: &Pose, u: f64, v: f64) -> Ray {
        Ray {
            origin: t_frame_camera.transform_point(&Point3::origin()),
            direction: Unit::new_normalize(
                t_frame_camera.transform_vector(&self.direction(u, v).into_inner()),
            ),
        }
    }
}

/// Where a ray meets a plane; `None` when it runs parallel to the plane (within `1e-12`)
/// or meets it behind its origin.
pub fn intersect_ray_plane(ray: &Ray, plane: &LaserPlane) -> Option<Point3<f64>> {
    let denom = plane.normal.dot(&ray.direction);
    if denom.abs() < 1e-12 {
        return None;
    }
    let t = -plane.distance(&ray.origin) / denom;
    (t >= 0.0).then(|| ray.origin + ray.direction.into_inner() * t)
}

/// The 3D point seen at pixel `(u, v)` of a camera at `t_frame_camera` on the laser
/// plane (both in the same frame): the thesis' "intersecting the camera ray with the laser
/// plane".
pub fn triangulate_pixel(
    intrinsics: &PinholeIntrinsics,
    t_frame_camera: &Pose,
    plane: &LaserPlane,
    u: f64,
    v: f64,
) -> Option<Point3<f64>> {
    intersect_ray_plane(&intrinsics.ray(t_frame_camera, u, v), plane)
}

/// Thesis (4.1)-(4.2): the point `(x, y)` seen from the origin at angle `beta` and from
/// `(0, s)` at angle `alpha` (angles from the x axis toward y),
/// `x = s / (tan beta - tan alpha)`, `y = x tan beta`; `None` for parallel sight lines.
pub fn triangulate_2d(baseline: f64, alpha: f64, beta: f64) -> Option<(f64, f64)> {
    let den = beta.tan() - alpha.tan();
    if den.abs() < 1e-300 || !den.is_finite() {
        return None;
    }
    let x = baseline / den;
    Some((x, x * beta.tan()))
}

/// Thesis (4.6): the range error `dx = (s / 2 + 2 x^2 / s) d alpha` of triangulating a
/// point at range `x` on the perpendicular bisector of a baseline `s` when each sight
/// angle errs by `d alpha` in opposite senses (the sum of both angles' sensitivities).
/// It grows with the square of the range.
///
/// ```
/// use olmap::scanner::{optimal_baseline, triangulation_range_error};
/// let e = triangulation_range_error(4.0, 0.5, 1e-3);
/// assert!((e - (0.25 + 64.0) * 1e-3).abs() < 1e-15);
/// // The baseline s = 2x minimises it.
/// let best = triangulation_range_error(4.0, optimal_baseline(4.0), 1e-3);
/// assert!(best < triangulation_range_error(4.0, 7.0, 1e-3));
/// assert!(best < triangulation_range_error(4.0, 9.0, 1e-3));
/// ```
pub fn triangulation_range_error(range: f64, baseline: f64, angle_error: f64) -> f64 {
    (baseline / 2.0 + 2.0 * range * range / baseline) * angle_error
}

/// The baseline minimising (4.6) for a range `x`: `s = 2 x`.
pub fn optimal_baseline(range: f64) -> f64 {
    2.0 * range
}
