//! The clouds prepared for ICP: the filtered, downsampled source with its moments, and the
//! downsampled target with its normals (given or PCA) and k-d tree.

use std::borrow::Cow;
use std::num::NonZeroUsize;
use std::sync::OnceLock;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use rustc_hash::FxHashMap;

use super::{IcpParams, NormalNeighbourhood};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::VoxelKey;

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
    normal_neighbourhood: NormalNeighbourhood,
    min_planarity: f64,
}

impl Preparation {
    fn of(params: &IcpParams) -> Self {
        Preparation {
            target_voxel: params.target_voxel,
            use_target_normals: params.use_target_normals,
            normal_k: params.normal_k,
            normal_neighbourhood: params.normal_neighbourhood,
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
    /// metres (a [`crate::cloud::VoxelMerge`]'s): when the target voxel is the same or
    /// divides it a whole number of times, the downsampling would change nothing and is
    /// skipped (each finer voxel lies inside one of the cloud's, so it holds at most that
    /// voxel's point).
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
    /// PCA of the point's neighbourhood, computed on first use (zero where the
    /// neighbourhood is not planar enough).
    Estimated {
        neighbourhood: Neighbourhood,
        min_planarity: f64,
        cache: Vec<OnceLock<Vector3<f64>>>,
    },
}

/// The target points an estimated normal is the PCA of.
pub(super) enum Neighbourhood {
    /// The `k` nearest ([`NormalNeighbourhood::Nearest`]).
    Nearest(NonZeroUsize),
    /// Those in the 3 × 3 × 3 voxels of `voxel` metres around the point's own
    /// ([`NormalNeighbourhood::VoxelBlock`]); `cells`: each voxel's point.
    VoxelBlock {
        voxel: f64,
        cells: FxHashMap<VoxelKey, u32>,
    },
}

/// Fewest points of a neighbourhood that give a normal.
const MIN_NORMAL_POINTS: usize = 3;

/// Targets of at least this many points build their k-d tree on the rayon pool (kiddo's
/// parallel construction; the tree, and so every answer, is the same as a serial build's).
/// Only maps reach it: a mapper's whole map, which is indexed again after every placement
/// (a quarter of the time of the large warehouse's incremental map building), and the map
/// a scan is localised in. 250 warehouse lidar scans mapped incrementally: 228.7 s with
/// serial trees, 217.0 s with this threshold, the same poses and map byte for byte; `olmap
/// demo` within its run-to-run spread (kiddo's own default threshold, 2^18).
const PARALLEL_TREE_POINTS: usize = 262_144;

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
        // The voxel the points are one per (none: any number per voxel).
        let (cloud, one_per) = match downsampled_at {
            Some(v) if nests(params.target_voxel, v) => (Cow::Borrowed(target), Some(v)),
            _ if params.target_voxel > 0.0 => (
                Cow::Owned(target.voxel_downsample(params.target_voxel)?),
                Some(params.target_voxel),
            ),
            _ => (Cow::Borrowed(target), None),
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
        let tree = ImmutableKdTree::<f64, 3>::builder()
            .with_parallel_construction_threshold(PARALLEL_TREE_POINTS)
            .build_from_slice(&coords)
            .map_err(|e| {
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
            let neighbourhood = match (params.normal_neighbourhood, one_per) {
                (NormalNeighbourhood::VoxelBlock, Some(voxel)) => Neighbourhood::VoxelBlock {
                    voxel,
                    cells: voxel_cells(&points, voxel),
                },
                _ => Neighbourhood::Nearest(
                    NonZeroUsize::new(params.normal_k.min(points.len()).max(1))
                        .expect("at least 1"),
                ),
            };
            Normals::Estimated {
                neighbourhood,
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
                neighbourhood,
                min_planarity,
                cache,
            } => *cache[i].get_or_init(|| self.estimate_normal(i, neighbourhood, *min_planarity)),
        }
    }

    /// PCA normal of target point `i` from its neighbourhood; zero where the neighbourhood
    /// has fewer than [`MIN_NORMAL_POINTS`] points or is not planar enough.
    fn estimate_normal(
        &self,
        i: usize,
        neighbourhood: &Neighbourhood,
        min_planarity: f64,
    ) -> Vector3<f64> {
        let c = self.points[i];
        // The `k` nearest points as they are, or a block's (at most 27) relative to the
        // point itself (precision far from the origin).
        let mut near: Vec<Vector3<f64>> = Vec::with_capacity(28);
        match neighbourhood {
            Neighbourhood::Nearest(k) => {
                let nn = self
                    .tree
                    .query(&[c.x, c.y, c.z])
                    .nearest_n::<SquaredEuclidean<f64>>(*k)
                    .execute();
                near.extend(nn.iter().map(|r| self.points[r.item as usize].coords));
            }
            Neighbourhood::VoxelBlock { voxel, cells } => {
                let Some(key) = VoxelKey::from_point(&c, *voxel) else {
                    return Vector3::zeros();
                };
                // The point itself even where rounding put it in a neighbour's voxel.
                near.push(Vector3::zeros());
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            // (Past the key range there is no voxel.)
                            let (Some(x), Some(y), Some(z)) = (
                                key.x.checked_add(dx),
                                key.y.checked_add(dy),
                                key.z.checked_add(dz),
                            ) else {
                                continue;
                            };
                            if let Some(&j) = cells.get(&VoxelKey::new(x, y, z)) {
                                if j as usize != i {
                                    near.push(self.points[j as usize] - c);
                                }
                            }
                        }
                    }
                }
            }
        }
        if near.len() < MIN_NORMAL_POINTS {
            return Vector3::zeros();
        }
        let n = near.len() as f64;
        let mean = near.iter().sum::<Vector3<f64>>() / n;
        let mut cov = Matrix3::zeros();
        for d in &near {
            let d = d - mean;
            cov += d * d.transpose();
        }
        plane_normal(&(cov / n), min_planarity)
    }
}

/// Whether voxels of `fine` metres nest in voxels of `coarse` metres (0 or the same size,
/// or `coarse` a whole multiple of `fine`): then downsampling a cloud of one point per
/// coarse voxel at `fine` keeps every point. (With 0.1 m and 0.07 m it would not: the
/// 0.07 m voxel [0.07, 0.14) spans two 0.1 m voxels.)
fn nests(fine: f64, coarse: f64) -> bool {
    if fine <= 0.0 || fine == coarse {
        return true;
    }
    let ratio = coarse / fine;
    ratio >= 1.0 && (ratio - ratio.round()).abs() < 1e-9
}

/// Each voxel's point (of `voxel` metres; points are one per voxel, the first kept where
/// rounding put two in one).
fn voxel_cells(points: &[Point3<f64>], voxel: f64) -> FxHashMap<VoxelKey, u32> {
    let mut cells = FxHashMap::default();
    cells.reserve(points.len());
    for (i, p) in points.iter().enumerate() {
        if let Some(k) = VoxelKey::from_point(p, voxel) {
            cells.entry(k).or_insert(i as u32);
        }
    }
    cells
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::VoxelMerge;
    use crate::geometry::Pose;
    use crate::sim::SimRng;

    /// A floor and a wall, every 10 cm, and a point alone far from both.
    fn floor_wall_and_a_stray() -> PointCloud {
        let mut points = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let (a, b) = (0.05 + i as f32 * 0.1, 0.05 + j as f32 * 0.1);
                points.push(Point3::new(a, b + 0.1, 0.05));
                points.push(Point3::new(a, 0.05, b));
            }
        }
        points.push(Point3::new(5.05, 5.05, 5.05));
        PointCloud::from_points(points)
    }

    /// Block normals: the floor's point up, the wall's across, none for the stray point
    /// (fewer than three points in its block) nor where floor meets wall (not a plane).
    #[test]
    fn voxel_block_normals_follow_the_surfaces() {
        let cloud = floor_wall_and_a_stray();
        let params = IcpParams {
            normal_neighbourhood: NormalNeighbourhood::VoxelBlock,
            ..Default::default()
        };
        let prepared = IcpTarget::of_voxel_centroids(&cloud, &params, 0.1).unwrap();
        let t = prepared.inner.as_ref().unwrap();
        assert!(matches!(
            &t.normals,
            Normals::Estimated {
                neighbourhood: Neighbourhood::VoxelBlock { .. },
                ..
            }
        ));
        let index_of = |p: Point3<f64>| t.points.iter().position(|q| (q - p).norm() < 1e-6);
        let floor = index_of(Point3::new(1.05, 1.15, 0.05)).unwrap();
        let wall = index_of(Point3::new(1.05, 0.05, 1.05)).unwrap();
        let stray = index_of(Point3::new(5.05, 5.05, 5.05)).unwrap();
        assert!(t.normal(floor).z.abs() > 0.999, "{}", t.normal(floor));
        assert!(t.normal(wall).y.abs() > 0.999, "{}", t.normal(wall));
        assert_eq!(t.normal(stray), Vector3::zeros());
        // On the line where the floor meets the wall the block holds both: no plane.
        let corner = index_of(Point3::new(1.05, 0.15, 0.05)).unwrap();
        let n = t.normal(corner);
        assert!(
            n == Vector3::zeros() || n.z.abs() < 0.999 && n.y.abs() < 0.999,
            "{n}"
        );
    }

    /// A target that is not one point per voxel (no downsampling) takes the nearest
    /// points whatever was asked.
    #[test]
    fn voxel_block_needs_a_voxelised_target() {
        let params = IcpParams {
            target_voxel: 0.0,
            normal_neighbourhood: NormalNeighbourhood::VoxelBlock,
            ..Default::default()
        };
        let prepared = IcpTarget::new(&floor_wall_and_a_stray(), &params).unwrap();
        let t = prepared.inner.as_ref().unwrap();
        assert!(matches!(
            &t.normals,
            Normals::Estimated {
                neighbourhood: Neighbourhood::Nearest(_),
                ..
            }
        ));
    }

    /// Downsampling a merge's centroids at a voxel that divides the merge's changes nothing
    /// (each finer voxel lies inside one of the merge's): what lets a map merged at 0.1 m
    /// skip the 0.05 m downsampling of the ICP target. A voxel that does not divide it is
    /// downsampled.
    #[test]
    fn centroids_downsampled_finer_are_unchanged() {
        assert!(nests(0.05, 0.1) && nests(0.05, 0.05) && nests(0.025, 0.1) && nests(0.0, 0.1));
        assert!(!nests(0.07, 0.1) && !nests(0.1, 0.05));
        let mut merge = VoxelMerge::new(0.1).unwrap();
        let mut rng = SimRng::new(7);
        let points: Vec<Point3<f32>> = (0..20_000)
            .map(|_| {
                let (x, y, z) = (
                    rng.range(-3.0, 3.0),
                    rng.range(-3.0, 3.0),
                    rng.range(0.0, 2.0),
                );
                Point3::new(x, y, z).cast::<f32>()
            })
            .collect();
        merge
            .add(&PointCloud::from_points(points), &Pose::identity())
            .unwrap();
        let cloud = merge.cloud();
        let finer = cloud.voxel_downsample(0.05).unwrap();
        assert_eq!(finer.points(), cloud.points());
        let params = IcpParams::default();
        let skipped = IcpTarget::of_voxel_centroids(&cloud, &params, 0.1).unwrap();
        let downsampled = IcpTarget::new(&cloud, &params).unwrap();
        assert_eq!(
            skipped.inner.as_ref().unwrap().points,
            downsampled.inner.as_ref().unwrap().points
        );
    }

    /// A target large enough to build its tree in parallel answers every nearest-point
    /// query exactly as a serially built tree does (same points, same order, same
    /// distances): what keeps a mapper's results the same whether its map crossed the
    /// threshold or not.
    #[test]
    fn a_tree_built_in_parallel_answers_as_a_serial_one() {
        let mut rng = SimRng::new(11);
        let n = PARALLEL_TREE_POINTS + 1_000;
        let coords: Vec<[f64; 3]> = (0..n)
            .map(|_| {
                [
                    rng.range(-20.0, 20.0),
                    rng.range(-20.0, 20.0),
                    rng.range(0.0, 3.0),
                ]
            })
            .collect();
        let cloud = PointCloud::from_points(
            coords
                .iter()
                .map(|c| Point3::new(c[0], c[1], c[2]).cast::<f32>())
                .collect(),
        );
        let params = IcpParams {
            target_voxel: 0.0,
            ..Default::default()
        };
        let prepared = IcpTarget::new(&cloud, &params).unwrap();
        let t = prepared.inner.as_ref().unwrap();
        assert!(t.points.len() >= PARALLEL_TREE_POINTS);
        let pts: Vec<[f64; 3]> = t.points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let serial = ImmutableKdTree::<f64, 3>::builder()
            .with_serial_construction()
            .build_from_slice(&pts)
            .unwrap();
        let k = std::num::NonZeroUsize::new(4).unwrap();
        for _ in 0..2_000 {
            let q = [
                rng.range(-21.0, 21.0),
                rng.range(-21.0, 21.0),
                rng.range(-0.5, 3.5),
            ];
            let a = t
                .tree
                .query(&q)
                .nearest_n::<SquaredEuclidean<f64>>(k)
                .within(0.25)
                .execute();
            let b = serial
                .query(&q)
                .nearest_n::<SquaredEuclidean<f64>>(k)
                .within(0.25)
                .execute();
            let a: Vec<(u32, f64)> = a.iter().map(|x| (x.item, x.distance)).collect();
            let b: Vec<(u32, f64)> = b.iter().map(|x| (x.item, x.distance)).collect();
            assert_eq!(a, b, "query {q:?}");
        }
    }
}
