//! The [`PointCloud`] type.

use nalgebra::{Point3, Vector3};

use crate::error::{Error, Result};
use crate::geometry::{Aabb, Pose};

/// A set of 3D points with optional per-point attributes and the sensor origin.
///
/// Invariant: every attribute that is present has exactly one entry per point.
///
/// ```
/// use olmap::cloud::PointCloud;
/// use olmap::geometry::Pose;
/// use nalgebra::Point3;
/// let mut cloud = PointCloud::new();
/// cloud.push(Point3::new(1.0, 0.0, 0.0));
/// cloud.push(Point3::new(5.0, 0.0, 0.5));
/// // Keep returns between 2 m and 10 m from the sensor.
/// let far = cloud.range_band(2.0, 10.0);
/// assert_eq!(far.len(), 1);
/// // Move the cloud into a map frame where the sensor sits at (10, 0, 0).
/// let in_map = far.transformed(&Pose::from_xyz_ypr(10.0, 0.0, 0.0, 0.0, 0.0, 0.0));
/// assert_eq!(in_map.points()[0], Point3::new(15.0, 0.0, 0.5));
/// assert_eq!(in_map.origin(), Point3::new(10.0, 0.0, 0.0));
/// ```
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    points: Vec<Point3<f32>>,
    intensity: Option<Vec<f32>>,
    normals: Option<Vec<Vector3<f32>>>,
    colors: Option<Vec<[u8; 3]>>,
    origin: Point3<f64>,
}

impl PointCloud {
    /// An empty cloud with the sensor at the origin.
    pub fn new() -> Self {
        Self::default()
    }

    /// A cloud of positions only, sensor at the origin.
    pub fn from_points(points: Vec<Point3<f32>>) -> Self {
        PointCloud {
            points,
            ..Self::default()
        }
    }

    /// An empty cloud with room for `n` points.
    pub fn with_capacity(n: usize) -> Self {
        Self::from_points(Vec::with_capacity(n))
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The positions, metres.
    pub fn points(&self) -> &[Point3<f32>] {
        &self.points
    }

    /// Per-point intensity (reflectance), if the source had it. Units are the sensor's.
    pub fn intensity(&self) -> Option<&[f32]> {
        self.intensity.as_deref()
    }

    /// Per-point unit surface normals, if the source had them.
    pub fn normals(&self) -> Option<&[Vector3<f32>]> {
        self.normals.as_deref()
    }

    /// Per-point RGB colours, if the source had them.
    pub fn colors(&self) -> Option<&[[u8; 3]]> {
        self.colors.as_deref()
    }

    /// The sensor origin in the cloud's frame (where the rays start).
    pub fn origin(&self) -> Point3<f64> {
        self.origin
    }

    /// Sets the sensor origin.
    pub fn set_origin(&mut self, origin: Point3<f64>) {
        self.origin = origin;
    }

    /// Builder form of [`PointCloud::set_origin`].
    pub fn with_origin(mut self, origin: Point3<f64>) -> Self {
        self.origin = origin;
        self
    }

    fn check_len(&self, what: &str, n: usize) -> Result<()> {
        if n != self.points.len() {
            return Err(Error::InvalidArgument(format!(
                "{what} has {n} entries but the cloud has {} points",
                self.points.len()
            )));
        }
        Ok(())
    }

    /// Attaches intensities (one per point).
    pub fn set_intensity(&mut self, intensity: Option<Vec<f32>>) -> Result<()> {
        if let Some(v) = &intensity {
            self.check_len("intensity", v.len())?;
        }
        self.intensity = intensity;
        Ok(())
    }

    /// Attaches normals (one per point).
    pub fn set_normals(&mut self, normals: Option<Vec<Vector3<f32>>>) -> Result<()> {
        if let Some(v) = &normals {
            self.check_len("normals", v.len())?;
        }
        self.normals = normals;
        Ok(())
    }

    /// Attaches colours (one per point).
    pub fn set_colors(&mut self, colors: Option<Vec<[u8; 3]>>) -> Result<()> {
        if let Some(v) = &colors {
            self.check_len("colours", v.len())?;
        }
        self.colors = colors;
        Ok(())
    }

    /// Appends a point. Clouds with attributes need [`PointCloud::push_with`].
    ///
    /// # Panics
    /// If the cloud carries attributes (their lengths would no longer match).
    pub fn push(&mut self, p: Point3<f32>) {
        assert!(
            self.intensity.is_none() && self.normals.is_none() && self.colors.is_none(),
            "PointCloud::push on a cloud with attributes; use push_with"
        );
        self.points.push(p);
    }

    /// Appends a point with the attributes the cloud carries (`None` where absent).
    /// Attributes the cloud does not carry are ignored; missing ones the cloud carries get
    /// a neutral value (intensity 0, zero normal, black).
    pub fn push_with(
        &mut self,
        p: Point3<f32>,
        intensity: Option<f32>,
        normal: Option<Vector3<f32>>,
        color: Option<[u8; 3]>,
    ) {
        self.points.push(p);
        if let Some(v) = &mut self.intensity {
            v.push(intensity.unwrap_or(0.0));
        }
        if let Some(v) = &mut self.normals {
            v.push(normal.unwrap_or_else(Vector3::zeros));
        }
        if let Some(v) = &mut self.colors {
            v.push(color.unwrap_or([0, 0, 0]));
        }
    }

    /// A cloud of the points whose index passes `keep`, attributes kept in step.
    pub fn select(&self, mut keep: impl FnMut(usize, &Point3<f32>) -> bool) -> PointCloud {
        let idx: Vec<usize> = self
            .points
            .iter()
            .enumerate()
            .filter(|(i, p)| keep(*i, p))
            .map(|(i, _)| i)
            .collect();
        self.gather(&idx)
    }

    /// A cloud of the points at the given indices (in that order).
    ///
    /// # Panics
    /// If an index is out of bounds.
    pub fn gather(&self, idx: &[usize]) -> PointCloud {
        PointCloud {
            points: idx.iter().map(|&i| self.points[i]).collect(),
            intensity: self
                .intensity
                .as_ref()
                .map(|v| idx.iter().map(|&i| v[i]).collect()),
            normals: self
                .normals
                .as_ref()
                .map(|v| idx.iter().map(|&i| v[i]).collect()),
            colors: self
                .colors
                .as_ref()
                .map(|v| idx.iter().map(|&i| v[i]).collect()),
            origin: self.origin,
        }
    }

    /// The cloud expressed in another frame: with `pose = T_new_old`, every point, normal and
    /// the sensor origin are mapped into the new frame.
    pub fn transformed(&self, pose: &Pose) -> PointCloud {
        let iso = pose.isometry().cast::<f32>();
        PointCloud {
            points: self
                .points
                .iter()
                .map(|p| pose.transform_point_f32(p))
                .collect(),
            intensity: self.intensity.clone(),
            normals: self
                .normals
                .as_ref()
                .map(|v| v.iter().map(|n| iso.rotation * n).collect()),
            colors: self.colors.clone(),
            origin: pose.transform_point(&self.origin),
        }
    }

    /// Appends another cloud (assumed to be in the same frame). An attribute is kept only if
    /// both clouds carry it (otherwise it is dropped from the result); the origin stays this
    /// cloud's.
    pub fn extend_from(&mut self, other: &PointCloud) {
        fn merge<T: Clone>(a: &mut Option<Vec<T>>, b: &Option<Vec<T>>) {
            match (a.as_mut(), b) {
                (Some(a), Some(b)) => a.extend_from_slice(b),
                _ => *a = None,
            }
        }
        let was_empty = self.points.is_empty();
        if was_empty {
            // An empty cloud adopts the other's attributes.
            self.intensity = other.intensity.as_ref().map(|_| Vec::new());
            self.normals = other.normals.as_ref().map(|_| Vec::new());
            self.colors = other.colors.as_ref().map(|_| Vec::new());
        }
        self.points.extend_from_slice(&other.points);
        merge(&mut self.intensity, &other.intensity);
        merge(&mut self.normals, &other.normals);
        merge(&mut self.colors, &other.colors);
    }

    /// Concatenates several clouds (see [`PointCloud::extend_from`]); the origin is the first
    /// cloud's.
    pub fn concatenate<'a>(clouds: impl IntoIterator<Item = &'a PointCloud>) -> PointCloud {
        let mut it = clouds.into_iter();
        let Some(first) = it.next() else {
            return PointCloud::new();
        };
        let mut out = first.clone();
        for c in it {
            out.extend_from(c);
        }
        out
    }

    /// The bounding box of the points, or `None` when empty.
    pub fn bounding_box(&self) -> Option<Aabb> {
        Aabb::from_points(&self.points)
    }

    /// Distance of each point from the sensor origin, metres.
    pub fn ranges(&self) -> Vec<f64> {
        let o = self.origin;
        self.points
            .iter()
            .map(|p| (p.cast::<f64>() - o).norm())
            .collect()
    }

    /// Mutable access to the positions (attributes stay attached to their indices).
    pub fn points_mut(&mut self) -> &mut [Point3<f32>] {
        &mut self.points
    }
}
