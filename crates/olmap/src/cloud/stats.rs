//! Summary statistics of a point cloud.

use nalgebra::Point3;

use super::PointCloud;
use crate::geometry::Aabb;

/// Distribution of the distances of points from the sensor origin, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeStats {
    /// Smallest range.
    pub min: f64,
    /// Largest range.
    pub max: f64,
    /// Mean range.
    pub mean: f64,
    /// Median range (lower median for an even count).
    pub median: f64,
}

/// Summary of a cloud, as printed by `olmap info`.
#[derive(Debug, Clone, PartialEq)]
pub struct CloudStats {
    /// Number of points.
    pub points: usize,
    /// Bounding box, `None` for an empty cloud.
    pub bbox: Option<Aabb>,
    /// Mean position, `None` for an empty cloud.
    pub centroid: Option<Point3<f64>>,
    /// Ranges from the sensor origin, `None` for an empty cloud.
    pub range: Option<RangeStats>,
    /// Smallest and largest intensity, if the cloud has intensities and points.
    pub intensity_range: Option<(f32, f32)>,
    /// Whether normals are present.
    pub has_normals: bool,
    /// Whether colours are present.
    pub has_colors: bool,
}

impl PointCloud {
    /// Computes the summary statistics.
    ///
    /// ```
    /// use olmap::cloud::PointCloud;
    /// use nalgebra::Point3;
    /// let c = PointCloud::from_points(vec![Point3::new(3.0, 4.0, 0.0), Point3::new(1.0, 0.0, 0.0)]);
    /// let s = c.stats();
    /// assert_eq!(s.points, 2);
    /// assert_eq!(s.range.unwrap().max, 5.0);
    /// ```
    pub fn stats(&self) -> CloudStats {
        let n = self.len();
        let range = if n == 0 {
            None
        } else {
            let mut r = self.ranges();
            let mean = r.iter().sum::<f64>() / n as f64;
            let mid = (n - 1) / 2;
            let (_, median, _) = r.select_nth_unstable_by(mid, f64::total_cmp);
            let median = *median;
            let (min, max) = r
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            Some(RangeStats {
                min,
                max,
                mean,
                median,
            })
        };
        let centroid = (n > 0).then(|| {
            let sum = self
                .points()
                .iter()
                .fold(nalgebra::Vector3::<f64>::zeros(), |acc, p| {
                    acc + p.coords.cast::<f64>()
                });
            Point3::from(sum / n as f64)
        });
        let intensity_range = self.intensity().filter(|v| !v.is_empty()).map(|v| {
            v.iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                })
        });
        CloudStats {
            points: n,
            bbox: self.bounding_box(),
            centroid,
            range,
            intensity_range,
            has_normals: self.normals().is_some(),
            has_colors: self.colors().is_some(),
        }
    }
}
