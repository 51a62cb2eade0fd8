//! Filters on point clouds: range band, box, height band and voxel-grid downsampling.

use nalgebra::{Point3, Vector3};
use rustc_hash::FxHashMap;

use super::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Aabb, VoxelKey};

impl PointCloud {
    /// The points whose distance from the sensor origin is in `[min, max]` metres.
    pub fn range_band(&self, min: f64, max: f64) -> PointCloud {
        let o = self.origin();
        let min2 = if min > 0.0 {
            min * min
        } else {
            f64::NEG_INFINITY
        };
        let max2 = max * max.abs();
        self.select(|_, p| {
            let d2 = (p.cast::<f64>() - o).norm_squared();
            d2 >= min2 && d2 <= max2
        })
    }

    /// The points inside an axis-aligned box (boundaries included).
    pub fn crop_box(&self, aabb: &Aabb) -> PointCloud {
        self.select(|_, p| aabb.contains(&p.cast()))
    }

    /// The points whose height z is in `[z_min, z_max]` metres.
    pub fn z_band(&self, z_min: f64, z_max: f64) -> PointCloud {
        self.select(|_, p| {
            let z = p.z as f64;
            z >= z_min && z <= z_max
        })
    }

    /// Voxel-grid downsampling: one point per occupied voxel of edge `resolution` metres, at
    /// the centroid of the voxel's points. Intensities and colours are averaged; normals are
    /// averaged and renormalised. Output order is the order in which voxels are first met,
    /// so the result is deterministic. A point whose voxel key does not fit an `i32` (3 m at
    /// 1 nm) is an error naming it ([`crate::geometry::key_range_error`]), never a dropped
    /// point.
    ///
    /// ```
    /// use olmap::cloud::PointCloud;
    /// use nalgebra::Point3;
    /// let cloud = PointCloud::from_points(vec![
    ///     Point3::new(0.01, 0.01, 0.01),
    ///     Point3::new(0.03, 0.01, 0.01),
    ///     Point3::new(0.51, 0.0, 0.0),
    /// ]);
    /// let down = cloud.voxel_downsample(0.1).unwrap();
    /// assert_eq!(down.len(), 2);
    /// assert!((down.points()[0].x - 0.02).abs() < 1e-6);
    /// ```
    pub fn voxel_downsample(&self, resolution: f64) -> Result<PointCloud> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "voxel size must be a positive number of metres, got {resolution}"
            )));
        }
        #[derive(Default, Clone)]
        struct Acc {
            sum: Vector3<f64>,
            intensity: f64,
            normal: Vector3<f64>,
            color: [u32; 3],
            n: u32,
        }
        let mut index: FxHashMap<VoxelKey, usize> = FxHashMap::default();
        let mut accs: Vec<Acc> = Vec::new();
        let intensity = self.intensity();
        let normals = self.normals();
        let colors = self.colors();
        for (i, p) in self.points().iter().enumerate() {
            let pd = p.cast::<f64>();
            let Some(key) = VoxelKey::from_point(&pd, resolution) else {
                return Err(crate::geometry::key_range_error(
                    "voxel downsampling",
                    i,
                    &pd,
                    resolution,
                    i32::MAX as i64,
                ));
            };
            let slot = *index.entry(key).or_insert_with(|| {
                accs.push(Acc::default());
                accs.len() - 1
            });
            let a = &mut accs[slot];
            a.sum += pd.coords;
            a.n += 1;
            if let Some(v) = intensity {
                a.intensity += v[i] as f64;
            }
            if let Some(v) = normals {
                a.normal += v[i].cast::<f64>();
            }
            if let Some(v) = colors {
                for (sum, &c) in a.color.iter_mut().zip(&v[i]) {
                    *sum += c as u32;
                }
            }
        }
        let points = accs
            .iter()
            .map(|a| Point3::from(a.sum / a.n as f64).cast::<f32>())
            .collect();
        let mut out = PointCloud::from_points(points).with_origin(self.origin());
        if intensity.is_some() {
            out.set_intensity(Some(
                accs.iter()
                    .map(|a| (a.intensity / a.n as f64) as f32)
                    .collect(),
            ))?;
        }
        if normals.is_some() {
            out.set_normals(Some(
                accs.iter()
                    .map(|a| {
                        a.normal
                            .try_normalize(1e-12)
                            .unwrap_or_else(Vector3::zeros)
                            .cast::<f32>()
                    })
                    .collect(),
            ))?;
        }
        if colors.is_some() {
            out.set_colors(Some(
                accs.iter()
                    .map(|a| {
                        let n = a.n;
                        [0, 1, 2].map(|c| ((a.color[c] + n / 2) / n) as u8)
                    })
                    .collect(),
            ))?;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud() -> PointCloud {
        let mut c = PointCloud::from_points(vec![
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(-0.05, 0.0, 2.0),
            Point3::new(0.0, 3.0, -1.0),
        ]);
        c.set_intensity(Some(vec![1.0, 2.0, 3.0])).unwrap();
        c
    }

    #[test]
    fn bands_keep_attributes_in_step() {
        let c = cloud();
        let r = c.range_band(1.5, 5.0);
        assert_eq!(r.len(), 2);
        assert_eq!(r.intensity().unwrap(), &[2.0, 3.0]);
        let z = c.z_band(-0.5, 0.5);
        assert_eq!(z.points(), &[Point3::new(1.0, 0.0, 0.0)]);
        let b = c.crop_box(&Aabb::new(
            Point3::new(-1.0, -1.0, -1.0),
            Point3::new(0.0, 4.0, 3.0),
        ));
        assert_eq!(b.intensity().unwrap(), &[2.0, 3.0]);
    }

    #[test]
    fn downsample_uses_floor_for_negative_coordinates() {
        // -0.05 and +0.05 are in different 0.1 m voxels.
        let c = PointCloud::from_points(vec![
            Point3::new(-0.05, 0.0, 0.0),
            Point3::new(0.05, 0.0, 0.0),
        ]);
        assert_eq!(c.voxel_downsample(0.1).unwrap().len(), 2);
        assert!(c.voxel_downsample(0.0).is_err());
        assert!(c.voxel_downsample(f64::NAN).is_err());
    }

    #[test]
    fn downsample_averages_attributes() {
        let mut c = PointCloud::from_points(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.05, 0.0, 0.0),
        ]);
        c.set_intensity(Some(vec![1.0, 3.0])).unwrap();
        c.set_colors(Some(vec![[0, 10, 255], [2, 20, 255]]))
            .unwrap();
        c.set_normals(Some(vec![
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        ]))
        .unwrap();
        let d = c.voxel_downsample(1.0).unwrap();
        assert_eq!(d.len(), 1);
        assert_eq!(d.intensity().unwrap(), &[2.0]);
        assert_eq!(d.colors().unwrap(), &[[1, 15, 255]]);
        assert!((d.normals().unwrap()[0].norm() - 1.0).abs() < 1e-6);
    }
}
