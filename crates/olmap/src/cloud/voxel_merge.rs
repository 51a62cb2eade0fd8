//! A voxel-grid downsampling that grows: clouds are added one at a time and each voxel's
//! point stays the centroid of every point that fell in it, without passing over the
//! points already merged again.

use nalgebra::{Point3, Vector3};
use rustc_hash::FxHashMap;

use super::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Pose, VoxelKey};

/// Clouds merged on a voxel grid: one point per voxel, the centroid of the points added to
/// it (the same points as [`PointCloud::voxel_downsample`] of all the added clouds moved
/// and concatenated, up to rounding: the voxel of a point is taken from its moved position
/// in f64, not from an f32 copy, so a point within rounding of a voxel face may fall on the
/// other side). Normals are averaged as long as every cloud added to a non-empty merge has
/// them (an empty merge takes them from the next cloud, as [`PointCloud::extend_from`]
/// does); intensity and colours are not kept. Voxels keep the order in which they were
/// first filled.
#[derive(Debug, Clone)]
pub(crate) struct VoxelMerge {
    resolution: f64,
    index: FxHashMap<VoxelKey, u32>,
    sums: Vec<(Vector3<f64>, u32)>,
    /// Normal sums, `None` once a cloud without normals was added.
    normals: Option<Vec<Vector3<f64>>>,
}

impl VoxelMerge {
    /// An empty merge on voxels of `resolution` metres.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `resolution` is not a positive, finite number.
    pub(crate) fn new(resolution: f64) -> Result<Self> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "voxel size must be a positive number of metres, got {resolution}"
            )));
        }
        Ok(VoxelMerge {
            resolution,
            index: FxHashMap::default(),
            sums: Vec::new(),
            normals: Some(Vec::new()),
        })
    }

    /// Adds `cloud`'s points moved by `pose`. Nothing is added when a point's voxel index
    /// does not fit (an error naming the point, as [`PointCloud::voxel_downsample`]).
    pub(crate) fn add(&mut self, cloud: &PointCloud, pose: &Pose) -> Result<()> {
        let moved: Vec<Point3<f64>> = cloud
            .points()
            .iter()
            .map(|p| pose.transform_point(&p.cast::<f64>()))
            .collect();
        let mut keys = Vec::with_capacity(moved.len());
        for (i, p) in moved.iter().enumerate() {
            let key = VoxelKey::from_point(p, self.resolution).ok_or_else(|| {
                crate::geometry::key_range_error(
                    "voxel merging",
                    i,
                    p,
                    self.resolution,
                    i32::MAX as i64,
                )
            })?;
            keys.push(key);
        }
        if self.sums.is_empty() {
            // An empty merge takes its attributes from the next cloud.
            self.normals = Some(Vec::new());
        }
        let normals = match (&mut self.normals, cloud.normals()) {
            (Some(sums), Some(given)) => Some((sums, given)),
            _ => {
                self.normals = None;
                None
            }
        };
        let rotation = pose.rotation();
        let mut normals = normals;
        for (i, (key, p)) in keys.into_iter().zip(&moved).enumerate() {
            let slot = *self.index.entry(key).or_insert_with(|| {
                self.sums.push((Vector3::zeros(), 0));
                if let Some((sums, _)) = normals.as_mut() {
                    sums.push(Vector3::zeros());
                }
                (self.sums.len() - 1) as u32
            }) as usize;
            let s = &mut self.sums[slot];
            s.0 += p.coords;
            s.1 += 1;
            if let Some((sums, given)) = normals.as_mut() {
                sums[slot] += rotation * given[i].cast::<f64>();
            }
        }
        Ok(())
    }

    /// The merged points (and normals, when every added cloud had them), origin at zero.
    pub(crate) fn cloud(&self) -> PointCloud {
        let points = self
            .sums
            .iter()
            .map(|(s, n)| Point3::from(s / *n as f64).cast::<f32>())
            .collect();
        let mut out = PointCloud::from_points(points);
        if let (Some(sums), false) = (&self.normals, self.sums.is_empty()) {
            let normals = sums
                .iter()
                .map(|n| {
                    n.try_normalize(1e-12)
                        .unwrap_or_else(Vector3::zeros)
                        .cast::<f32>()
                })
                .collect();
            out.set_normals(Some(normals))
                .expect("one normal per merged point");
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;

    /// A wall with normals, every 3 cm.
    fn wall() -> PointCloud {
        let mut points = Vec::new();
        for i in 0..30 {
            for j in 0..20 {
                points.push(Point3::new(
                    1.0013,
                    i as f32 * 0.03 + 0.0011,
                    j as f32 * 0.03 + 0.0017,
                ));
            }
        }
        let n = points.len();
        let mut c = PointCloud::from_points(points);
        c.set_normals(Some(vec![Vector3::new(-1.0, 0.0, 0.0); n]))
            .unwrap();
        c
    }

    /// Merging clouds one at a time gives the points and normals of downsampling them all
    /// together.
    #[test]
    fn merging_one_at_a_time_is_downsampling_all_together() {
        let poses = [
            Pose::identity(),
            Pose::from_xyz_ypr(0.013, 0.2, 0.01, 0.3, 0.0, 0.0),
            Pose::from_xyz_ypr(-0.4, 0.05, 0.0, -0.2, 0.0, 0.0),
        ];
        let mut merge = VoxelMerge::new(0.05).unwrap();
        let mut all = PointCloud::new();
        for p in &poses {
            merge.add(&wall(), p).unwrap();
            all.extend_from(&wall().transformed(p));
        }
        let merged = merge.cloud();
        let expected = all.voxel_downsample(0.05).unwrap();
        assert_eq!(merged.len(), expected.len());
        for (i, (a, b)) in merged.points().iter().zip(expected.points()).enumerate() {
            assert!((a - b).norm() < 1e-5, "point {i}: {a:?} vs {b:?}");
            let (na, nb) = (merged.normals().unwrap()[i], expected.normals().unwrap()[i]);
            assert!((na - nb).norm() < 1e-5, "normal {i}: {na:?} vs {nb:?}");
        }
        // A cloud without normals drops them.
        merge
            .add(
                &PointCloud::from_points(vec![Point3::new(0.0, 0.0, 0.0)]),
                &poses[0],
            )
            .unwrap();
        assert!(merge.cloud().normals().is_none());
        assert_eq!(merge.cloud().len(), expected.len() + 1);
    }

    /// An empty merge takes its normals from the next cloud, as `extend_from` does.
    #[test]
    fn an_empty_merge_takes_the_next_clouds_normals() {
        let mut merge = VoxelMerge::new(0.05).unwrap();
        merge.add(&PointCloud::new(), &Pose::identity()).unwrap();
        merge.add(&wall(), &Pose::identity()).unwrap();
        assert!(merge.cloud().normals().is_some());
    }

    /// A point whose voxel index does not fit is an error and adds nothing.
    #[test]
    fn a_point_out_of_range_adds_nothing() {
        let mut merge = VoxelMerge::new(0.05).unwrap();
        let bad = PointCloud::from_points(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1e30, 0.0, 0.0),
        ]);
        assert!(merge.add(&bad, &Pose::identity()).is_err());
        assert!(merge.cloud().is_empty());
        assert!(VoxelMerge::new(0.0).is_err());
    }
}
