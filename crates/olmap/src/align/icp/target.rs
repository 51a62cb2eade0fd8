//! The clouds prepared for ICP: the filtered, downsampled source with its moments, and the
//! downsampled target with its normals (given or PCA) and k-d tree.

use std::borrow::Cow;
use std::num::NonZeroUsize;
use std::sync::OnceLock;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use rustc_hash::{FxHashMap, FxHashSet};

use super::tiles::{tile_gap, tree_nearest, Near, TileKey, Tiles};
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
            inner: Target::new(target, params, None, false)?,
            prepared_with: Preparation::of(params),
        })
    }

    /// [`IcpTarget::new`] for a cloud that is already one point per voxel of `voxel`
    /// metres (a [`crate::cloud::VoxelMerge`]'s): when the target voxel is the same or
    /// divides it a whole number of times, the downsampling would change nothing and is
    /// skipped (each finer voxel lies inside one of the cloud's, so it holds at most that
    /// voxel's point).
    ///
    /// The points are indexed in column tiles ([`super::tiles`]), so that
    /// [`IcpTarget::updated`] can follow a map that grows: a mapper's map.
    pub(crate) fn of_map(target: &PointCloud, params: &IcpParams, voxel: f64) -> Result<Self> {
        params.validate()?;
        Ok(IcpTarget {
            inner: Target::new(target, params, Some(voxel), true)?,
            prepared_with: Preparation::of(params),
        })
    }

    /// `self` (made by [`IcpTarget::of_map`]) brought up to `target`, the map's points now:
    /// the same cloud with points appended and some moved (a
    /// [`crate::cloud::VoxelMerge`]'s after more scans were merged: voxels keep their
    /// order, centroids move). Only the tiles that gained or moved a point are indexed
    /// again, and a kept estimated normal is forgotten only when a moved or new point may
    /// lie within its neighbourhood's reach (see `forget_normals_near`: a few that would
    /// not have changed go too, and are computed again the same); the points are updated
    /// in place. The result answers as [`IcpTarget::of_map`] of `target` would
    /// (up to which of two exactly equidistant points is taken). Anything else (another
    /// preparation, fewer points, a target not made by [`IcpTarget::of_map`], a block
    /// normal's voxel changed by a moved point) is prepared afresh.
    pub(crate) fn updated(
        self,
        target: &PointCloud,
        params: &IcpParams,
        voxel: f64,
    ) -> Result<Self> {
        params.validate()?;
        if self.prepared_for(params) && nests(params.target_voxel, voxel) {
            if let Some(mut inner) = self.inner {
                if inner.follow(target, params)? {
                    return Ok(IcpTarget {
                        inner: Some(inner),
                        prepared_with: self.prepared_with,
                    });
                }
            }
        }
        IcpTarget::of_map(target, params, voxel)
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
    /// neighbourhood is not planar enough), kept with the neighbourhood's reach (no point
    /// farther than it from the point took part: [`Target::follow`] forgets the normal
    /// when a point within it moved or arrived).
    Estimated {
        neighbourhood: Neighbourhood,
        min_planarity: f64,
        cache: Vec<OnceLock<(Vector3<f64>, f64)>>,
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
/// Only maps reach it: the map a scan is localised in (a mapper's map is indexed in tiles
/// instead, [`IcpTarget::of_map`], each built serially and the tiles in parallel). When
/// the mappers still built one tree of their whole map after every placement, 250
/// warehouse lidar scans mapped incrementally took 228.7 s with serial trees and 217.0 s
/// with this threshold, the same poses and map byte for byte (kiddo's own default
/// threshold, 2^18).
const PARALLEL_TREE_POINTS: usize = 262_144;

/// The downsampled target with its normals and its index.
pub(super) struct Target {
    pub(super) points: Vec<Point3<f64>>,
    normals: Normals,
    index: PointIndex,
}

/// How a target's points are indexed.
enum PointIndex {
    /// One k-d tree over every point (items: point indices).
    Whole(ImmutableKdTree<f64, 3>),
    /// Column tiles, a tree each: a map that grows ([`IcpTarget::of_map`]).
    Tiled(Tiles),
}

impl Target {
    /// `None` when the target has no finite point; `downsampled_at`: the voxel `target`
    /// was already downsampled at, if any; `tiled`: indexed in tiles, not one tree.
    fn new(
        target: &PointCloud,
        params: &IcpParams,
        downsampled_at: Option<f64>,
        tiled: bool,
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
        let index = if tiled {
            PointIndex::Tiled(Tiles::new(&points)?)
        } else {
            let coords: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
            PointIndex::Whole(
                ImmutableKdTree::<f64, 3>::builder()
                    .with_parallel_construction_threshold(PARALLEL_TREE_POINTS)
                    .build_from_slice(&coords)
                    .map_err(|e| {
                        Error::InvalidArgument(format!("ICP: cannot index the target points: {e}"))
                    })?,
            )
        };
        let normals = if given.is_some() {
            Normals::Given(normals_in.iter().map(unit_or_zero).collect())
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
            index,
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
            } => {
                cache[i]
                    .get_or_init(|| self.estimate_normal(i, neighbourhood, *min_planarity))
                    .0
            }
        }
    }

    /// The `n` target points nearest `q`, nearest first, only those within `max_distance2`
    /// (squared metres) when given.
    pub(super) fn nearest(
        &self,
        q: &Point3<f64>,
        n: NonZeroUsize,
        max_distance2: Option<f64>,
    ) -> Vec<Near> {
        match &self.index {
            PointIndex::Whole(tree) => tree_nearest(tree, q, n, max_distance2),
            PointIndex::Tiled(tiles) => tiles.nearest(q, n, max_distance2),
        }
    }

    /// Brings the target up to `cloud` (see [`IcpTarget::updated`]); `false` (nothing
    /// changed) when it cannot follow and must be prepared afresh.
    fn follow(&mut self, cloud: &PointCloud, params: &IcpParams) -> Result<bool> {
        let PointIndex::Tiled(tiles) = &mut self.index else {
            return Ok(false);
        };
        let old_len = self.points.len();
        let incoming = cloud.points();
        if incoming.len() < old_len || !incoming.iter().all(|p| p.iter().all(|v| v.is_finite())) {
            return Ok(false);
        }
        let given = match (&self.normals, params.use_target_normals, cloud.normals()) {
            (Normals::Given(_), true, Some(ns)) => Some(ns),
            (Normals::Estimated { .. }, false, _) | (Normals::Estimated { .. }, true, None) => None,
            _ => return Ok(false),
        };
        let given_now = |i: usize| given.map(|ns| unit_or_zero(&ns[i].cast::<f64>()));
        // What changed, checked before anything is changed (the points are updated in
        // place: no second copy of a map's points).
        let moved: Vec<u32> = (0..old_len)
            .filter(|&i| {
                incoming[i].cast::<f64>() != self.points[i]
                    || matches!(&self.normals, Normals::Given(ns) if Some(ns[i]) != given_now(i))
            })
            .map(|i| i as u32)
            .collect();
        if moved.is_empty() && incoming.len() == old_len {
            return Ok(true);
        }
        match &self.normals {
            Normals::Estimated {
                neighbourhood: Neighbourhood::Nearest(k),
                ..
            } => {
                // Fewer points than `normal_k` (a map's first scans): every normal's
                // neighbourhood changes size.
                if k.get() < params.normal_k && incoming.len() > k.get() {
                    return Ok(false);
                }
            }
            Normals::Estimated {
                neighbourhood: Neighbourhood::VoxelBlock { voxel, .. },
                ..
            } => {
                // A point that moved into another voxel changes the block map's key.
                let key = |p: &Point3<f64>| VoxelKey::from_point(p, *voxel);
                if moved.iter().any(|&i| {
                    key(&self.points[i as usize]) != key(&incoming[i as usize].cast::<f64>())
                }) {
                    return Ok(false);
                }
            }
            Normals::Given(_) => {}
        }
        let moved: Vec<(u32, Point3<f64>)> = moved
            .into_iter()
            .map(|i| {
                let p = &mut self.points[i as usize];
                let was = *p;
                *p = incoming[i as usize].cast::<f64>();
                (i, was)
            })
            .collect();
        self.points
            .extend(incoming[old_len..].iter().map(|p| p.cast::<f64>()));
        match &mut self.normals {
            Normals::Given(ns) => {
                for &(i, _) in &moved {
                    ns[i as usize] = given_now(i as usize).expect("given normals");
                }
                ns.extend((old_len..incoming.len()).map(|i| given_now(i).expect("given normals")));
            }
            Normals::Estimated {
                neighbourhood,
                cache,
                ..
            } => {
                if let Neighbourhood::VoxelBlock { voxel, cells } = neighbourhood {
                    for (i, p) in self.points.iter().enumerate().skip(old_len) {
                        if let Some(k) = VoxelKey::from_point(p, *voxel) {
                            cells.entry(k).or_insert(i as u32);
                        }
                    }
                }
                // The positions a neighbourhood may have gained or lost.
                let mut changed: Vec<[f64; 3]> =
                    Vec::with_capacity(2 * moved.len() + self.points.len() - old_len);
                for &(i, was) in &moved {
                    let p = self.points[i as usize];
                    changed.push([was.x, was.y, was.z]);
                    changed.push([p.x, p.y, p.z]);
                    cache[i as usize].take();
                }
                changed.extend(self.points[old_len..].iter().map(|p| [p.x, p.y, p.z]));
                cache.extend((old_len..self.points.len()).map(|_| OnceLock::new()));
                // (The tiles still hold the old membership: the points that moved have
                // no normal kept, the new ones none yet.)
                forget_normals_near(cache, &self.points, tiles, &changed, neighbourhood)?;
            }
        }
        tiles.update(&self.points, old_len, &moved)?;
        Ok(true)
    }

    /// PCA normal of target point `i` from its neighbourhood; zero where the neighbourhood
    /// has fewer than [`MIN_NORMAL_POINTS`] points or is not planar enough. With it, the
    /// neighbourhood's reach: no point farther from the point took part, nor would have
    /// had it been nearer (the `k`-th nearest's distance, infinite when every point took
    /// part; for a block, the farthest a point of the 3 × 3 × 3 voxels can be).
    fn estimate_normal(
        &self,
        i: usize,
        neighbourhood: &Neighbourhood,
        min_planarity: f64,
    ) -> (Vector3<f64>, f64) {
        let c = self.points[i];
        // The `k` nearest points as they are, or a block's (at most 27) relative to the
        // point itself (precision far from the origin).
        let mut near: Vec<Vector3<f64>> = Vec::with_capacity(28);
        let reach = match neighbourhood {
            Neighbourhood::Nearest(k) => {
                let nn = self.nearest(&c, *k, None);
                near.extend(nn.iter().map(|r| self.points[r.item as usize].coords));
                if nn.len() < k.get() || self.points.len() <= k.get() {
                    f64::INFINITY
                } else {
                    nn.iter().map(|r| r.distance).fold(0.0, f64::max).sqrt()
                }
            }
            Neighbourhood::VoxelBlock { voxel, cells } => {
                let Some(key) = VoxelKey::from_point(&c, *voxel) else {
                    return (Vector3::zeros(), f64::INFINITY);
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
                // The point lies in its voxel, a block point within the next one out.
                2.0 * 3f64.sqrt() * voxel
            }
        };
        if near.len() < MIN_NORMAL_POINTS {
            return (Vector3::zeros(), reach);
        }
        let n = near.len() as f64;
        let mean = near.iter().sum::<Vector3<f64>>() / n;
        let mut cov = Matrix3::zeros();
        for d in &near {
            let d = d - mean;
            cov += d * d.transpose();
        }
        (plane_normal(&(cov / n), min_planarity), reach)
    }
}

/// Slack on a normal's reach against rounding (metres): a point this much beyond the
/// reach still counts as inside it.
const REACH_SLACK: f64 = 1e-6;

/// Side of the cells [`forget_normals_near`] marks around changed points (metres): at
/// least a normal's usual reach (the 10 nearest of a 0.05 m map lie within about 0.15 m).
const CHANGE_CELL: f64 = 0.25;

/// Forgets every kept normal of `points` whose neighbourhood's reach includes one of
/// `changed` (positions where a point arrived, left or moved to). A normal whose reach is
/// at most the cell size is forgotten when a changed point lies in its cell or one next to
/// it (which every changed point within the reach does: some normals are forgotten that
/// would have stayed the same, and are computed again, the same); a longer reach asks a
/// tree of the changed points. Tiles farther from every changed point's tile than each of
/// their normals' reach are skipped.
fn forget_normals_near(
    cache: &mut [OnceLock<(Vector3<f64>, f64)>],
    points: &[Point3<f64>],
    tiles: &Tiles,
    changed: &[[f64; 3]],
    neighbourhood: &Neighbourhood,
) -> Result<()> {
    let side = match neighbourhood {
        Neighbourhood::VoxelBlock { voxel, .. } => CHANGE_CELL.max(2.0 * 3f64.sqrt() * voxel),
        Neighbourhood::Nearest(_) => CHANGE_CELL,
    } + REACH_SLACK;
    let cell = |c: &[f64; 3]| c.map(|v| (v / side).floor() as i64);
    let mut cells: Vec<[i64; 3]> = changed.iter().map(cell).collect();
    cells.sort_unstable();
    cells.dedup();
    let mut marked: FxHashSet<[i64; 3]> = FxHashSet::default();
    marked.reserve(27 * cells.len());
    for c in &cells {
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    marked.insert([c[0] + dx, c[1] + dy, c[2] + dz]);
                }
            }
        }
    }
    let mut changed_tiles: Vec<TileKey> = changed
        .iter()
        .map(|c| super::tiles::tile_of(&Point3::new(c[0], c[1], c[2])))
        .collect();
    changed_tiles.sort_unstable();
    changed_tiles.dedup();
    // Made only if some normal reaches farther than a cell.
    let mut far: Option<ImmutableKdTree<f64, 3>> = None;
    for (key, members) in tiles.each() {
        let reach = members
            .iter()
            .filter_map(|&m| cache[m as usize].get().map(|c| c.1))
            .fold(f64::NEG_INFINITY, f64::max);
        if reach < 0.0 || changed_tiles.iter().all(|&c| tile_gap(key, c) > reach) {
            continue;
        }
        for &m in members {
            let Some(&(_, r)) = cache[m as usize].get() else {
                continue;
            };
            let p = points[m as usize];
            let forget = if r + REACH_SLACK <= side {
                marked.contains(&cell(&[p.x, p.y, p.z]))
            } else {
                if far.is_none() {
                    far = Some(ImmutableKdTree::<f64, 3>::new_from_slice(changed).map_err(
                        |e| {
                            Error::InvalidArgument(format!(
                                "ICP: cannot index the map's change: {e}"
                            ))
                        },
                    )?);
                }
                let nearest = far
                    .as_ref()
                    .expect("made above")
                    .query(&[p.x, p.y, p.z])
                    .nearest_one::<SquaredEuclidean<f64>>()
                    .execute();
                nearest.distance.sqrt() <= r + REACH_SLACK
            };
            if forget {
                cache[m as usize].take();
            }
        }
    }
    Ok(())
}

/// `n` scaled to unit length, or zero when it is not finite or shorter than a half.
fn unit_or_zero(n: &Vector3<f64>) -> Vector3<f64> {
    let len = n.norm();
    if len.is_finite() && len > 0.5 {
        n / len
    } else {
        Vector3::zeros()
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
        let prepared = IcpTarget::of_map(&cloud, &params, 0.1).unwrap();
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
        let skipped = IcpTarget::of_map(&cloud, &params, 0.1).unwrap();
        let downsampled = IcpTarget::new(&cloud, &params).unwrap();
        assert_eq!(
            skipped.inner.as_ref().unwrap().points,
            downsampled.inner.as_ref().unwrap().points
        );
    }

    /// A scan of a 12 x 12 m room (floor, walls, a pillar) seen from `(x, y)`: points within
    /// 7 m, jittered by 1 cm, with normals.
    fn room_scan(rng: &mut SimRng, x: f64, y: f64) -> PointCloud {
        let mut points = Vec::new();
        let mut normals = Vec::new();
        for _ in 0..12_000 {
            let (u, v) = (rng.range(-6.0, 6.0), rng.range(0.0, 3.0));
            let (p, n) = match rng.range(0.0, 6.0) as u32 {
                0 | 1 => (
                    Point3::new(u, rng.range(-6.0, 6.0), 0.0),
                    Vector3::new(0.0, 0.0, 1.0),
                ),
                2 => (Point3::new(-6.0, u, v), Vector3::new(1.0, 0.0, 0.0)),
                3 => (Point3::new(6.0, u, v), Vector3::new(-1.0, 0.0, 0.0)),
                4 => (Point3::new(u, 6.0, v), Vector3::new(0.0, -1.0, 0.0)),
                _ => (
                    Point3::new(1.0 + 0.3 * u.cos(), 0.5 + 0.3 * u.sin(), v),
                    Vector3::new(u.cos(), u.sin(), 0.0),
                ),
            };
            if (p.x - x).hypot(p.y - y) < 7.0 {
                let jitter = Vector3::new(
                    rng.range(-0.01, 0.01),
                    rng.range(-0.01, 0.01),
                    rng.range(-0.01, 0.01),
                );
                points.push((p + jitter).cast::<f32>());
                normals.push(n.cast::<f32>());
            }
        }
        let mut cloud = PointCloud::from_points(points);
        cloud.set_normals(Some(normals)).unwrap();
        cloud
    }

    /// A map target brought up to a growing merge scan by scan answers exactly as one made
    /// afresh from the merge: the same points, the same nearest points, and the same
    /// normals, estimated ones included that were computed before the map changed and kept
    /// (the neighbourhood of k nearest and of voxel blocks) or given by the scans.
    #[test]
    fn a_map_target_brought_up_to_date_answers_as_one_made_afresh() {
        for (neighbourhood, use_target_normals) in [
            (NormalNeighbourhood::Nearest, false),
            (NormalNeighbourhood::VoxelBlock, false),
            (NormalNeighbourhood::Nearest, true),
        ] {
            let params = IcpParams {
                normal_neighbourhood: neighbourhood,
                use_target_normals,
                ..Default::default()
            };
            let mut rng = SimRng::new(5);
            let mut merge = VoxelMerge::new(0.05).unwrap();
            let mut kept: Option<IcpTarget> = None;
            for (x, y) in [
                (-3.0, -3.0),
                (-1.0, -2.5),
                (2.0, -1.0),
                (3.0, 3.0),
                (-2.0, 2.5),
            ] {
                let scan = room_scan(&mut rng, x, y);
                let pose = Pose::from_xyz_ypr(x * 0.01, 0.0, 0.0, 0.0, 0.0, 0.0);
                merge
                    .add(&scan.transformed(&pose.inverse()), &pose)
                    .unwrap();
                let cloud = merge.cloud();
                let was_kept = kept.is_some();
                let target = match kept.take() {
                    Some(t) => t.updated(&cloud, &params, 0.05).unwrap(),
                    None => IcpTarget::of_map(&cloud, &params, 0.05).unwrap(),
                };
                let fresh = IcpTarget::of_map(&cloud, &params, 0.05).unwrap();
                let (t, f) = (
                    target.inner.as_ref().unwrap(),
                    fresh.inner.as_ref().unwrap(),
                );
                assert_eq!(t.points, f.points);
                // Brought up to date, not made afresh: normals known before the scan and
                // out of its reach are kept, those within it forgotten.
                if let (Normals::Estimated { cache, .. }, true) = (&t.normals, was_kept) {
                    let known = cache.iter().filter(|c| c.get().is_some()).count();
                    assert!(
                        known > 0 && known < cache.len(),
                        "{known} of {}",
                        cache.len()
                    );
                }
                for i in 0..t.points.len() {
                    assert_eq!(t.normal(i), f.normal(i), "normal {i} ({neighbourhood:?})");
                }
                let k = NonZeroUsize::new(4).unwrap();
                for _ in 0..2_000 {
                    let q = Point3::new(
                        rng.range(-7.0, 7.0),
                        rng.range(-7.0, 7.0),
                        rng.range(-0.5, 3.5),
                    );
                    assert_eq!(t.nearest(&q, k, Some(0.25)), f.nearest(&q, k, Some(0.25)));
                }
                // Every normal is now known: the next scan must forget those it changes.
                kept = Some(target);
            }
        }
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
            let PointIndex::Whole(tree) = &t.index else {
                panic!("one tree");
            };
            let a = tree
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
