//! The clouds prepared for ICP: the filtered, downsampled source with its moments, and the
//! downsampled target with its normals (given or PCA) and k-d tree.

use std::borrow::Cow;
use std::num::NonZeroUsize;
use std::sync::OnceLock;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

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

/// The source prepared for ICP once: the points at `source_voxel` and, when it pays, the
/// thinner points at `coarse_voxel_factor · source_voxel` the schedule starts on
/// ([`IcpParams::coarse_voxel_factor`]).
pub(crate) struct IcpSource {
    pub(super) fine: Source,
    pub(super) coarse: Option<Source>,
}

/// Fewest points of a thin source worth a stage of its own.
const MIN_COARSE_POINTS: usize = 200;

impl IcpSource {
    /// Filters and downsamples `source` with `params` (range, voxels).
    pub(crate) fn new(source: &PointCloud, params: &IcpParams) -> Result<Self> {
        let cloud = match params.source_max_range {
            Some(r) => Cow::Owned(source.range_band(0.0, r)),
            None => Cow::Borrowed(source),
        };
        let fine = source_at(&cloud, params.source_voxel)?;
        let coarse = if params.source_voxel > 0.0 && params.coarse_voxel_factor > 1.0 {
            let c = source_at(&cloud, params.source_voxel * params.coarse_voxel_factor)?;
            (c.points.len() >= MIN_COARSE_POINTS && 2 * c.points.len() <= fine.points.len())
                .then_some(c)
        } else {
            None
        };
        Ok(IcpSource { fine, coarse })
    }
}

/// The finite points of `cloud` downsampled at `voxel` (0: all), with their moments.
fn source_at(cloud: &PointCloud, voxel: f64) -> Result<Source> {
    let down = if voxel > 0.0 {
        Cow::Owned(cloud.voxel_downsample(voxel)?)
    } else {
        Cow::Borrowed(cloud)
    };
    let points: Vec<Point3<f64>> = down
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

/// A target prepared for ICP: downsampled once, indexed once (k-d tree), its normals taken
/// from the cloud or estimated by PCA when a correspondence first needs them and kept. Build
/// it once and pass it to [`super::refine_to`] for every refinement against the same cloud
/// (the hypotheses of one registration, every scan registered against one map): each pays
/// only for its own source points and the target normals it touches.
///
/// ```
/// use olmap::align::icp::{refine_to, IcpParams, IcpTarget};
/// use olmap::cloud::PointCloud;
/// use olmap::geometry::Pose;
/// use nalgebra::Point3;
///
/// // A floor and two walls, every 10 cm.
/// let mut points = Vec::new();
/// for i in 0..40 {
///     for j in 0..30 {
///         let (a, b) = (i as f32 * 0.1, j as f32 * 0.1);
///         points.push(Point3::new(a, b + 0.1, 0.0));
///         points.push(Point3::new(a, 0.0, b));
///         points.push(Point3::new(0.0, a, b));
///     }
/// }
/// let map = PointCloud::from_points(points);
/// let params = IcpParams::default();
/// let prepared = IcpTarget::new(&map, &params).unwrap();
/// for dx in [0.05, -0.08] {
///     let truth = Pose::from_xyz_ypr(dx, 0.04, 0.0, 0.01, 0.0, 0.0);
///     let scan = map.transformed(&truth.inverse());
///     let r = refine_to(&scan, &prepared, &Pose::identity(), &params).unwrap();
///     assert!(r.converged);
///     assert!((r.pose.translation() - truth.translation()).norm() < 1e-3);
/// }
/// ```
pub struct IcpTarget {
    /// `None` when the target has no finite point.
    pub(super) inner: Option<Target>,
    /// The preparation's parameters (voxel, normal source, `k`, planarity).
    prepared_with: Preparation,
}

/// The parameters a target was prepared with.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Preparation {
    target_voxel: f64,
    use_target_normals: bool,
    normal_k: usize,
    min_planarity: f64,
}

impl Preparation {
    fn of(params: &IcpParams) -> Self {
        Preparation {
            target_voxel: params.target_voxel,
            use_target_normals: params.use_target_normals,
            normal_k: params.normal_k,
            min_planarity: params.min_planarity,
        }
    }
}

impl std::fmt::Debug for IcpTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("IcpTarget")
            .field("points", &self.len())
            .field("prepared_with", &self.prepared_with)
            .finish()
    }
}

impl IcpTarget {
    /// Prepares `target` with `params`' target voxel, normal source, `normal_k` and
    /// planarity threshold (the other parameters belong to each refinement).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for parameters outside their documented ranges.
    pub fn new(target: &PointCloud, params: &IcpParams) -> Result<Self> {
        params.validate()?;
        Ok(IcpTarget {
            inner: Target::new(target, params, None)?,
            prepared_with: Preparation::of(params),
        })
    }

    /// [`IcpTarget::new`] for a cloud that is already one point per voxel of `voxel`
    /// metres (a [`crate::cloud::VoxelMerge`]'s): when the target voxel is the same, the
    /// downsampling would change nothing and is skipped.
    pub(crate) fn of_voxel_centroids(
        target: &PointCloud,
        params: &IcpParams,
        voxel: f64,
    ) -> Result<Self> {
        params.validate()?;
        Ok(IcpTarget {
            inner: Target::new(target, params, Some(voxel))?,
            prepared_with: Preparation::of(params),
        })
    }

    /// Points after downsampling.
    pub fn len(&self) -> usize {
        self.inner.as_ref().map_or(0, |t| t.points.len())
    }

    /// Whether no point is left.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether refining with `params` may use this target (it was prepared with the same
    /// target voxel, normal source, `normal_k` and planarity threshold).
    pub fn prepared_for(&self, params: &IcpParams) -> bool {
        self.prepared_with == Preparation::of(params)
    }
}

/// Where a target point's normal comes from.
pub(super) enum Normals {
    /// The cloud's own, unit length (zero where unusable).
    Given(Vec<Vector3<f64>>),
    /// PCA of the `k` nearest target points, computed on first use (zero where the
    /// neighbourhood is not planar enough).
    Estimated {
        k: NonZeroUsize,
        min_planarity: f64,
        cache: Vec<OnceLock<Vector3<f64>>>,
    },
}

/// The downsampled target with its normals and k-d tree.
pub(super) struct Target {
    pub(super) points: Vec<Point3<f64>>,
    normals: Normals,
    pub(super) tree: ImmutableKdTree<f64, 3>,
}

impl Target {
    /// `None` when the target has no finite point; `downsampled_at`: the voxel `target`
    /// was already downsampled at, if any.
    fn new(
        target: &PointCloud,
        params: &IcpParams,
        downsampled_at: Option<f64>,
    ) -> Result<Option<Self>> {
        let cloud = if params.target_voxel > 0.0 && downsampled_at != Some(params.target_voxel) {
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
            Normals::Given(
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
                    .collect(),
            )
        } else {
            Normals::Estimated {
                k: NonZeroUsize::new(params.normal_k.min(points.len()).max(1)).expect("at least 1"),
                min_planarity: params.min_planarity,
                cache: (0..points.len()).map(|_| OnceLock::new()).collect(),
            }
        };
        Ok(Some(Target {
            points,
            normals,
            tree,
        }))
    }

    /// The unit normal of target point `i` (zero where none is usable). An estimated normal
    /// is a function of the target alone, so computing it on first use gives the same value
    /// whichever thread asks first.
    pub(super) fn normal(&self, i: usize) -> Vector3<f64> {
        match &self.normals {
            Normals::Given(n) => n[i],
            Normals::Estimated {
                k,
                min_planarity,
                cache,
            } => *cache[i].get_or_init(|| self.estimate_normal(i, *k, *min_planarity)),
        }
    }

    /// PCA normal of target point `i` from its `k` nearest neighbours; zero where the
    /// neighbourhood is not planar enough.
    fn estimate_normal(&self, i: usize, k: NonZeroUsize, min_planarity: f64) -> Vector3<f64> {
        let c = self.points[i];
        let nn = self
            .tree
            .query(&[c.x, c.y, c.z])
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute();
        if nn.len() < 3 {
            return Vector3::zeros();
        }
        let mut mean = Vector3::zeros();
        for r in &nn {
            mean += self.points[r.item as usize].coords;
        }
        mean /= nn.len() as f64;
        let mut cov = Matrix3::zeros();
        for r in &nn {
            let d = self.points[r.item as usize].coords - mean;
            cov += d * d.transpose();
        }
        plane_normal(&(cov / nn.len() as f64), min_planarity)
    }
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
