//! The clouds prepared for ICP: the filtered, downsampled source with its moments, and the
//! downsampled target with its normals (given or PCA) and k-d tree.

use std::borrow::Cow;
use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use rayon::prelude::*;

use super::IcpParams;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};

/// The source after filtering, in f64, with its centroid and RMS radius.
pub(super) struct Source {
    pub(super) points: Vec<Point3<f64>>,
    pub(super) centroid: Point3<f64>,
    /// RMS distance from the centroid (at least 1 mm).
    pub(super) radius: f64,
    /// Covariance of the points (about the centroid).
    pub(super) cov: Matrix3<f64>,
}

pub(super) fn prepare_source(source: &PointCloud, params: &IcpParams) -> Result<Source> {
    let mut cloud = Cow::Borrowed(source);
    if let Some(r) = params.source_max_range {
        cloud = Cow::Owned(cloud.range_band(0.0, r));
    }
    if params.source_voxel > 0.0 {
        cloud = Cow::Owned(cloud.voxel_downsample(params.source_voxel)?);
    }
    let points: Vec<Point3<f64>> = cloud
        .points()
        .iter()
        .map(|p| p.cast::<f64>())
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    let n = points.len().max(1) as f64;
    let centroid = Point3::from(points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n);
    let ms = points
        .iter()
        .map(|p| (p - centroid).norm_squared())
        .sum::<f64>()
        / n;
    let cov = points.iter().fold(Matrix3::zeros(), |c, p| {
        let d = p - centroid;
        c + d * d.transpose()
    }) / n;
    Ok(Source {
        points,
        centroid,
        cov,
        radius: ms.sqrt().max(1e-3),
    })
}

/// The downsampled target with its normals (zero where none is usable) and k-d tree.
pub(super) struct Target {
    pub(super) points: Vec<Point3<f64>>,
    pub(super) normals: Vec<Vector3<f64>>,
    pub(super) tree: ImmutableKdTree<f64, 3>,
}

impl Target {
    /// `None` when the target has no point or no usable normal.
    pub(super) fn new(target: &PointCloud, params: &IcpParams) -> Result<Option<Self>> {
        let cloud = if params.target_voxel > 0.0 {
            Cow::Owned(target.voxel_downsample(params.target_voxel)?)
        } else {
            Cow::Borrowed(target)
        };
        let given = if params.use_target_normals {
            cloud.normals()
        } else {
            None
        };
        let mut points = Vec::with_capacity(cloud.len());
        let mut normals_in = Vec::new();
        for (i, p) in cloud.points().iter().enumerate() {
            let p = p.cast::<f64>();
            if p.iter().all(|v| v.is_finite()) {
                points.push(p);
                if let Some(ns) = given {
                    normals_in.push(ns[i].cast::<f64>());
                }
            }
        }
        if points.is_empty() {
            return Ok(None);
        }
        let coords: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&coords).map_err(|e| {
            Error::InvalidArgument(format!("ICP: cannot index the target points: {e}"))
        })?;
        let normals = if given.is_some() {
            normals_in
                .iter()
                .map(|n| {
                    let len = n.norm();
                    if len.is_finite() && len > 0.5 {
                        n / len
                    } else {
                        Vector3::zeros()
                    }
                })
                .collect()
        } else {
            estimate_normals(&coords, &tree, params.normal_k, params.min_planarity)
        };
        if normals.iter().all(|n| *n == Vector3::zeros()) {
            return Ok(None);
        }
        Ok(Some(Target {
            points,
            normals,
            tree,
        }))
    }
}

/// PCA normals of the `k` nearest neighbours; zero where the neighbourhood is not planar
/// enough.
fn estimate_normals(
    coords: &[[f64; 3]],
    tree: &ImmutableKdTree<f64, 3>,
    k: usize,
    min_planarity: f64,
) -> Vec<Vector3<f64>> {
    let k = NonZeroUsize::new(k.min(coords.len()).max(1)).expect("at least 1");
    coords
        .par_iter()
        .map(|c| {
            let nn = tree
                .query(c)
                .nearest_n::<SquaredEuclidean<f64>>(k)
                .execute();
            if nn.len() < 3 {
                return Vector3::zeros();
            }
            let pts: Vec<Vector3<f64>> = nn
                .iter()
                .map(|r| {
                    let q = coords[r.item as usize];
                    Vector3::new(q[0], q[1], q[2])
                })
                .collect();
            let mean = pts.iter().fold(Vector3::zeros(), |s, p| s + p) / pts.len() as f64;
            let mut cov = Matrix3::zeros();
            for p in &pts {
                let d = p - mean;
                cov += d * d.transpose();
            }
            plane_normal(&(cov / pts.len() as f64), min_planarity)
        })
        .collect()
}

/// The unit normal of a covariance matrix (eigenvector of the smallest eigenvalue), or zero
/// when the planarity `(λ1 - λ0) / λ2` is below `min_planarity`.
pub(super) fn plane_normal(cov: &Matrix3<f64>, min_planarity: f64) -> Vector3<f64> {
    let eig = SymmetricEigen::new(*cov);
    let ev = eig.eigenvalues;
    // nalgebra does not sort the eigenvalues: order them ourselves.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| ev[a].total_cmp(&ev[b]));
    let (l0, l1, l2) = (ev[order[0]], ev[order[1]], ev[order[2]]);
    if l2.is_nan() || l2 <= 0.0 || (l1 - l0) / l2 < min_planarity {
        return Vector3::zeros();
    }
    let n = eig.eigenvectors.column(order[0]).into_owned();
    let len = n.norm();
    if len.is_finite() && len > 0.0 {
        n / len
    } else {
        Vector3::zeros()
    }
}
