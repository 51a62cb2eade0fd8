//! Depth images ray cast into an occupancy list (thesis Figure 5.6).

use nalgebra::Vector3;
use rayon::prelude::*;

use super::check_size;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::occupancy::OccupancyList;
use image::{Rgb, RgbImage};

/// A camera in its own frame: x forward, y left, z up. Pixel `(u, v)` has `u` to the right
/// and `v` down, row 0 at the top; its ray passes through the pixel's centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Camera {
    /// A pinhole camera looking along +x with a horizontal field of view `fov_x` radians
    /// (in `(0, pi)`) and square pixels.
    Pinhole {
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
        /// Horizontal field of view, radians.
        fov_x: f64,
    },
    /// A cylindrical panorama: columns sweep the azimuth from +pi (left edge, looking
    /// backwards over the left) to -pi, rows the elevation from `+fov_y / 2` (top) to
    /// `-fov_y / 2`; the centre column looks along +x.
    Panoramic {
        /// Image width in pixels (columns over the full turn).
        width: u32,
        /// Image height in pixels.
        height: u32,
        /// Vertical field of view, radians, in `(0, pi]`.
        fov_y: f64,
    },
}

impl Camera {
    /// Width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        match *self {
            Camera::Pinhole { width, height, .. } | Camera::Panoramic { width, height, .. } => {
                (width, height)
            }
        }
    }

    /// The unit ray of pixel `(u, v)` in the camera frame.
    pub fn ray(&self, u: u32, v: u32) -> Vector3<f64> {
        let (w, h) = self.size();
        let (cu, cv) = (
            u as f64 + 0.5 - w as f64 / 2.0,
            v as f64 + 0.5 - h as f64 / 2.0,
        );
        match *self {
            Camera::Pinhole { fov_x, .. } => {
                let f = (w as f64 / 2.0) / (fov_x / 2.0).tan();
                Vector3::new(f, -cu, -cv).normalize()
            }
            Camera::Panoramic { fov_y, .. } => {
                let az = -cu / w as f64 * std::f64::consts::TAU;
                let el = -cv / h as f64 * fov_y;
                let (sa, ca) = az.sin_cos();
                let (se, ce) = el.sin_cos();
                Vector3::new(ce * ca, ce * sa, se)
            }
        }
    }

    fn check(&self) -> Result<()> {
        let (w, h) = self.size();
        check_size(w, h)?;
        let ok = match *self {
            Camera::Pinhole { fov_x, .. } => fov_x > 0.0 && fov_x < std::f64::consts::PI,
            Camera::Panoramic { fov_y, .. } => fov_y > 0.0 && fov_y <= std::f64::consts::PI,
        };
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidArgument(format!(
                "camera field of view out of range: {self:?}"
            )))
        }
    }
}

/// Ranges seen by a camera, row by row from the top.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Range along each pixel's ray to where it enters the first occupied voxel, metres;
    /// NaN where the ray meets nothing within the maximum range.
    pub ranges: Vec<f32>,
    /// The maximum range the rays were cast to.
    pub max_range: f64,
}

impl DepthImage {
    /// The range at pixel `(u, v)`, `None` for no hit or outside the image.
    pub fn range(&self, u: u32, v: u32) -> Option<f64> {
        if u >= self.width || v >= self.height {
            return None;
        }
        let r = self.ranges[(v * self.width + u) as usize];
        (!r.is_nan()).then_some(r as f64)
    }

    /// Pixels with a hit.
    pub fn hits(&self) -> usize {
        self.ranges.iter().filter(|r| !r.is_nan()).count()
    }

    /// A grey picture as in the thesis: near surfaces light, far ones dark (linear in
    /// range from 0 to the farthest hit), no hit dark blue.
    pub fn to_image(&self) -> RgbImage {
        let far = self
            .ranges
            .iter()
            .filter(|r| !r.is_nan())
            .fold(0.0f64, |m, &r| m.max(r as f64))
            .max(1e-9);
        RgbImage::from_fn(self.width, self.height, |u, v| match self.range(u, v) {
            Some(r) => {
                let g = (235.0 * (1.0 - r / far).clamp(0.0, 1.0) + 20.0) as u8;
                Rgb([g, g, g])
            }
            None => Rgb([10, 10, 40]),
        })
    }
}

/// Ray casts every pixel of `camera`, placed in the map at `t_map_camera`, into the map up
/// to `max_range` metres, stopping at the first voxel with a count of at least `min_count`
/// ([`OccupancyList::cast_ray`]). Rows are cast in parallel.
///
/// ```
/// use olmap::occupancy::OccupancyList;
/// use olmap::geometry::{Pose, VoxelKey};
/// use olmap::render::{render_depth, Camera};
/// let mut map = OccupancyList::new(0.1).unwrap();
/// for y in -20..20 { for z in -20..20 { map.set(VoxelKey::new(30, y, z), 1).unwrap(); } }
/// let cam = Camera::Pinhole { width: 9, height: 9, fov_x: 1.0 };
/// let depth = render_depth(&map, &Pose::identity(), &cam, 10.0, 1).unwrap();
/// assert!((depth.range(4, 4).unwrap() - 3.0).abs() < 1e-9);
/// ```
pub fn render_depth(
    map: &OccupancyList,
    t_map_camera: &Pose,
    camera: &Camera,
    max_range: f64,
    min_count: u16,
) -> Result<DepthImage> {
    camera.check()?;
    if !(max_range.is_finite() && max_range > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "maximum range must be > 0 m, got {max_range}"
        )));
    }
    let origin = t_map_camera.transform_point(&nalgebra::Point3::origin());
    if !origin.iter().all(|v| v.is_finite()) {
        return Err(Error::InvalidArgument(format!(
            "the camera position must be finite, got {origin}"
        )));
    }
    let bounds = map.key_bounds();
    let (w, h) = camera.size();
    let rows: Vec<Vec<f32>> = (0..h)
        .into_par_iter()
        .map(|v| {
            (0..w)
                .map(|u| {
                    let dir = t_map_camera.transform_vector(&camera.ray(u, v));
                    let n = dir.norm();
                    if !(n.is_finite() && n > 0.0) {
                        return f32::NAN;
                    }
                    match map.cast_ray_in(&origin, &dir, max_range, min_count, bounds.as_ref()) {
                        Some(hit) => hit.distance as f32,
                        None => f32::NAN,
                    }
                })
                .collect()
        })
        .collect();
    Ok(DepthImage {
        width: w,
        height: h,
        ranges: rows.concat(),
        max_range,
    })
}
