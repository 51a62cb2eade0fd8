//! Robust point-to-plane ICP in six degrees of freedom: [`refine`].
//!
//! Given a source scan, a target scan and an initial guess of `T_target_source`, [`refine`]
//! finds the rigid transform that puts the source points onto the target's surfaces. It is
//! a local method: it needs a guess inside the basin of convergence (roughly, most source
//! points within [`IcpParams::max_distance_start`] of their true surface) and is meant to
//! polish the result of a coarse global search.
//!
//! ## Method
//! * **Preprocessing.** Source points beyond [`IcpParams::source_max_range`] from the source's
//!   sensor origin are dropped, then both clouds are voxel-downsampled (source
//!   [`IcpParams::source_voxel`], target [`IcpParams::target_voxel`]): this evens out the
//!   density of scanners, which is very high near the sensor, and bounds the cost. A k-d tree
//!   ([`kiddo`]) is built once over the target points.
//! * **Target normals.** The target's own normals are used when it has them; otherwise each
//!   target point's normal is the eigenvector of the smallest eigenvalue of the covariance of
//!   its [`IcpParams::normal_k`] nearest neighbours (PCA). With the eigenvalues sorted
//!   `λ0 ≤ λ1 ≤ λ2`, neighbourhoods whose planarity `(λ1 - λ0) / λ2` is below
//!   [`IcpParams::min_planarity`] (lines, corners, clutter) get no normal and are never
//!   used as correspondences.
//! * **Correspondences and residuals.** Each source point `p`, mapped by the current estimate
//!   `T`, is paired with its nearest target point `q` (normal `n`) if that lies within the
//!   current maximum correspondence distance `d`. The residual is the point-to-plane distance
//!   `r = n · (T p - q)` (Chen & Medioni 1991).
//! * **Linearisation** (Low 2004). A small motion `δ = (ω, v)` applied on the left,
//!   `T ← exp(δ) T`, changes the residual to first order by `((T p - c) × n) · ω + n · v`.
//!   The rotation acts about `c`, the centroid of the mapped source points, rather than the
//!   frame origin, which may lie far away: this decouples rotation from translation and keeps
//!   the normal equations well conditioned. The rotation coordinates are scaled by `L`, the RMS
//!   distance of the source points from their centroid, so that all six unknowns are metres
//!   of displacement. The weighted Gauss-Newton normal equations `(Σ w J Jᵀ) δ = -Σ w r J` are
//!   solved by Cholesky with a Levenberg damping of `1e-6` of the mean diagonal (it leaves the
//!   fixed point unchanged and keeps unobservable directions from jumping); if the
//!   factorisation fails the damping grows a hundredfold at a time. A step that would move
//!   the points by more than `d` is shortened to `d` (a trust region). The update rotates by
//!   `ω` about `c`, then translates by `v`.
//! * **Robust kernel.** Iteratively reweighted least squares with Tukey's biweight
//!   `w(r) = (1 - (r/s)²)²` for `|r| < s`, else 0 (or Huber's `w = min(1, s/|r|)`), with scale
//!   `s = kernel_scale · d`: the kernel narrows together with the correspondence distance.
//! * **Schedule.** `d` starts at [`IcpParams::max_distance_start`]. Whenever an update moves
//!   the points by less than [`IcpParams::settle_fraction`]` · d` (the estimate has settled
//!   at this distance), `d` is multiplied by [`IcpParams::distance_decay`], down to
//!   [`IcpParams::max_distance_end`]. Large distances pull a poor guess in (even when few
//!   correspondences are right at first), smaller ones then keep only the matching surface.
//!   Shrinking only once settled gives a 15-degree initial error the iterations it needs
//!   without slowing down a good guess.
//! * **Convergence.** The refinement has converged when, at the final distance, an update moves
//!   the centroid of the source points by less than [`IcpParams::translation_epsilon`] and
//!   rotates by less than [`IcpParams::rotation_epsilon`]. It stops unconverged after
//!   [`IcpParams::max_iterations`], when fewer correspondences than
//!   `max(6, min_correspondence_fraction · source points)` are found, or when the normal
//!   equations cannot be solved; the best estimate so far is returned in all cases.
//! * **Determinism.** Correspondences and normal-equation sums are computed in parallel over
//!   fixed-size chunks of source points (rayon) and the chunk sums are added in chunk order,
//!   so the result is bit-identical for any number of threads.
//!
//! ## Degeneracy
//! Some scenes do not determine all six degrees of freedom: in a straight corridor the scan can
//! slide along the corridor, on a flat floor it can slide and turn in the plane. ICP then
//! returns *a* minimum, and the estimate along the free directions is only as good as the
//! initial guess (or drifts). At the final estimate [`refine`] builds the unweighted
//! point-to-plane information matrix `(1/N) Σ J Jᵀ` over the `N` inliers, with rotations
//! about the inliers' centroid, each scaled by the RMS distance of the inliers from its axis.
//! In these units a unit step along any direction moves the points by one metre RMS, and the
//! eigenvalue is the mean squared change of residual it causes: between 0 (the points slide
//! along their surfaces) and 1 (every point moves straight off its surface). The
//! eigen-decomposition, its condition number and the directions whose eigenvalue is small
//! compared with the largest are reported in [`Degeneracy`].
//!
//! ## References
//! * Y. Chen, G. Medioni, *Object modeling by registration of multiple range images*, 1991.
//! * K.-L. Low, *Linear least-squares optimization for point-to-plane ICP surface
//!   registration*, UNC TR04-004, 2004.
//! * J. Zhang, M. Kaess, S. Singh, *On degeneracy of optimization-based state estimation
//!   problems*, ICRA 2016.

use std::borrow::Cow;
use std::num::NonZeroUsize;
use std::time::Instant;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
    Vector6,
};
use rayon::prelude::*;

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::Pose;

/// Source points per parallel work item. The chunk sums are added in chunk order, so results
/// do not depend on the number of threads; the value only trades scheduling overhead against
/// load balance.
const CHUNK: usize = 256;

/// Names of the six coordinates `(ωx, ωy, ωz, vx, vy, vz)` used in [`Degeneracy::weak`].
const AXIS_NAMES: [&str; 6] = [
    "rotation about x",
    "rotation about y",
    "rotation about z",
    "translation along x",
    "translation along y",
    "translation along z",
];

/// The robust kernel that down-weights large point-to-plane residuals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RobustKernel {
    /// Tukey's biweight: `w = (1 - (r/s)²)²` for `|r| < s`, else 0. Residuals beyond the scale
    /// are ignored entirely (redescending), which suits scans with moving objects and
    /// non-overlapping parts.
    #[default]
    Tukey,
    /// Huber: `w = 1` for `|r| ≤ s`, else `s / |r|`. Convex, so it never ignores a residual.
    Huber,
}

impl RobustKernel {
    /// The IRLS weight of residual `r` at scale `s`.
    fn weight(self, r: f64, s: f64) -> f64 {
        let a = r.abs();
        match self {
            RobustKernel::Tukey => {
                if a < s {
                    let u = r / s;
                    let t = 1.0 - u * u;
                    t * t
                } else {
                    0.0
                }
            }
            RobustKernel::Huber => {
                if a <= s {
                    1.0
                } else {
                    s / a
                }
            }
        }
    }
}

/// Parameters of [`refine`]. All distances are in metres, angles in radians.
///
/// The defaults were chosen on two kinds of real data: outdoor 3D scans (ranges 1.6-74 m,
/// libpointmatcher's car pair, refined from the identity with an initial error of 20 cm and
/// 15 degrees) and indoor-ish scans of a pitching 2D scanner (ranges 0.2-32 m, 3DTK's
/// example scans, from 0.3 m and 3 degrees off). See the module tests for the outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct IcpParams {
    /// Voxel edge for downsampling the source, metres; `0` keeps every point. Default `0.05`.
    /// Scanners sample near surfaces far more densely than far ones; the voxel grid evens this
    /// out while keeping the near, precise returns in the majority. Coarser voxels (0.1-0.2 m)
    /// are faster but weight far, noisier returns more: on the 3DTK pairs the weakly
    /// determined height then drifts by a few centimetres.
    pub source_voxel: f64,
    /// Voxel edge for downsampling the target, metres; `0` keeps every point. Default `0.05`:
    /// nearest target points then lie within a few centimetres of the surface under a source
    /// point, and PCA normals of `normal_k` neighbours describe patches of ~15-20 cm.
    pub target_voxel: f64,
    /// Source points farther than this from the source's sensor origin are dropped before
    /// downsampling, metres; `None` (default) keeps all.
    pub source_max_range: Option<f64>,
    /// Use the target's own normals when it has them (default `true`); otherwise, or when it
    /// has none, normals are estimated by PCA.
    pub use_target_normals: bool,
    /// Neighbours (including the point itself) for PCA normals. Default `10`.
    pub normal_k: usize,
    /// Minimum planarity `(λ1 - λ0) / λ2` of a neighbourhood for its PCA normal to be used, in
    /// `[0, 1]`. Default `0.2`: rejects lines (scan-line fragments, poles) and scattered
    /// clutter (vegetation), keeps walls, ground and the faces of objects.
    pub min_planarity: f64,
    /// Maximum correspondence distance (point to nearest target point) at the first
    /// iteration, metres. Default `2.0`: pulls in rotations of 15-20 degrees on outdoor
    /// scans, where points 10 m away start metres off.
    pub max_distance_start: f64,
    /// Maximum correspondence distance at the end of the schedule, metres; convergence is
    /// tested, and the inlier statistics and the degeneracy are computed, at this distance.
    /// Default `0.4`. It must stay well above the residuals of real scans (3-5 cm RMS for
    /// the test data, with systematic distortions): a tight final gate keeps only a subset of
    /// each surface and biases the pose (by 1-2 cm on the car pair at 0.2 m).
    pub max_distance_end: f64,
    /// Factor in `(0, 1]` by which the correspondence distance shrinks once the estimate has
    /// settled at the current one. Default `0.7` (2 m to 0.4 m in five steps).
    pub distance_decay: f64,
    /// The estimate has settled at distance `d` when an update moves the points (the
    /// centroid, or points at the RMS radius by the rotation) by less than
    /// `settle_fraction · d`. Default `0.03` (6 cm at 2 m, 1.2 cm at 0.4 m): shrinking while
    /// the estimate still moves by centimetres per iteration leaves a large rotation to be
    /// finished at the small distance, slowly. Values `>= 1` shrink the distance after every
    /// iteration (a purely geometric schedule).
    pub settle_fraction: f64,
    /// Robust kernel. Default [`RobustKernel::Tukey`].
    pub kernel: RobustKernel,
    /// Kernel scale as a fraction of the current correspondence distance (`s = kernel_scale
    /// · d`). Default `0.5` (20 cm at the final distance). Also the inlier threshold of the
    /// statistics: an inlier is a correspondence with `|r| < s`.
    pub kernel_scale: f64,
    /// Maximum number of Gauss-Newton iterations. Default `50`.
    pub max_iterations: usize,
    /// Convergence threshold on the motion of the source centroid in one update, metres.
    /// Default `1e-4`.
    pub translation_epsilon: f64,
    /// Convergence threshold on the rotation angle of one update, radians. Default `1e-5`.
    pub rotation_epsilon: f64,
    /// An iteration with fewer correspondences than `max(6, fraction · source points)` stops
    /// the refinement (unconverged). Default `0.05`.
    pub min_correspondence_fraction: f64,
    /// A direction is reported weak ([`Degeneracy::weak`]) when its eigenvalue is below this
    /// fraction of the largest, in `[0, 1]`. Default `0.02`: the free translation along a
    /// straight corridor scores about 0.001, the weakest directions of the real test pairs
    /// 0.13-0.35.
    pub weak_fraction: f64,
    /// Directions of the update whose eigenvalue (of the normal equations, in the same
    /// centred and scaled coordinates) is below this fraction of the largest are not moved
    /// at all ("solution remapping", Zhang, Kaess and Singh, ICRA 2016): a degenerate
    /// direction keeps the initial pose's value instead of sliding on noise, and the rest
    /// converges. In `[0, 1)`; default `0.02`, like [`IcpParams::weak_fraction`]: below the
    /// real pairs' weakest directions (0.13-0.35), above a corridor's free axis (~0.001) and
    /// the free height of scans cut to a height band (~0.013); `0` disables it.
    pub degenerate_fraction: f64,
}

impl Default for IcpParams {
    fn default() -> Self {
        IcpParams {
            source_voxel: 0.05,
            target_voxel: 0.05,
            source_max_range: None,
            use_target_normals: true,
            normal_k: 10,
            min_planarity: 0.2,
            max_distance_start: 2.0,
            max_distance_end: 0.4,
            distance_decay: 0.7,
            settle_fraction: 0.03,
            kernel: RobustKernel::Tukey,
            kernel_scale: 0.5,
            max_iterations: 50,
            translation_epsilon: 1e-4,
            rotation_epsilon: 1e-5,
            min_correspondence_fraction: 0.05,
            weak_fraction: 0.02,
            degenerate_fraction: 0.02,
        }
    }
}

impl IcpParams {
    /// Checks that every parameter is in its documented range.
    pub fn validate(&self) -> Result<()> {
        fn bad(msg: String) -> Result<()> {
            Err(Error::InvalidArgument(format!("ICP parameters: {msg}")))
        }
        let non_negative = |name: &str, v: f64| -> Result<()> {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                bad(format!("{name} must be a finite number >= 0, got {v}"))
            }
        };
        let positive = |name: &str, v: f64| -> Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                bad(format!("{name} must be a finite number > 0, got {v}"))
            }
        };
        let unit = |name: &str, v: f64| -> Result<()> {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                bad(format!("{name} must be in [0, 1], got {v}"))
            }
        };
        non_negative("source_voxel", self.source_voxel)?;
        non_negative("target_voxel", self.target_voxel)?;
        if let Some(r) = self.source_max_range {
            positive("source_max_range", r)?;
        }
        if self.normal_k < 3 {
            return bad(format!(
                "normal_k must be at least 3, got {}",
                self.normal_k
            ));
        }
        unit("min_planarity", self.min_planarity)?;
        positive("max_distance_start", self.max_distance_start)?;
        positive("max_distance_end", self.max_distance_end)?;
        if self.max_distance_end > self.max_distance_start {
            return bad(format!(
                "max_distance_end ({}) must not exceed max_distance_start ({})",
                self.max_distance_end, self.max_distance_start
            ));
        }
        if !(self.distance_decay > 0.0 && self.distance_decay <= 1.0) {
            return bad(format!(
                "distance_decay must be in (0, 1], got {}",
                self.distance_decay
            ));
        }
        positive("settle_fraction", self.settle_fraction)?;
        positive("kernel_scale", self.kernel_scale)?;
        if self.max_iterations == 0 {
            return bad("max_iterations must be at least 1".into());
        }
        non_negative("translation_epsilon", self.translation_epsilon)?;
        non_negative("rotation_epsilon", self.rotation_epsilon)?;
        unit(
            "min_correspondence_fraction",
            self.min_correspondence_fraction,
        )?;
        unit("weak_fraction", self.weak_fraction)?;
        if !(0.0..1.0).contains(&self.degenerate_fraction) {
            return bad(format!(
                "degenerate_fraction must be in [0, 1), got {}",
                self.degenerate_fraction
            ));
        }
        Ok(())
    }
}

/// How well the final alignment constrains each of the six degrees of freedom.
///
/// From the unweighted point-to-plane information matrix `(1/N) Σ J Jᵀ` over the `N` inliers
/// at the final estimate, in the coordinates `(ωx·Lx, ωy·Ly, ωz·Lz, vx, vy, vz)`: `ω` rotates
/// about the target frame's axes through the inliers' centroid, `Lk` is the RMS distance of
/// the inliers from axis `k`, and `v` translates along the target frame's axes. A unit step
/// in these coordinates moves the inliers by one metre RMS; the eigenvalue of a direction is
/// the mean squared residual change that step causes, in `[0, 1]` for the coordinate axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Degeneracy {
    /// The eigenvalues, ascending.
    pub eigenvalues: [f64; 6],
    /// `eigenvectors[i]` is the unit eigenvector of `eigenvalues[i]` in the coordinates
    /// `(ωx·Lx, ωy·Ly, ωz·Lz, vx, vy, vz)`, signed so that its largest component is positive.
    pub eigenvectors: [[f64; 6]; 6],
    /// `max / min` eigenvalue (infinite when the smallest is zero).
    pub condition: f64,
    /// The directions whose eigenvalue is below [`IcpParams::weak_fraction`] of the largest,
    /// weakest first, each named by its dominant component and that component's magnitude,
    /// e.g. `"translation along x (0.98)"`.
    pub weak: Vec<String>,
}

impl Degeneracy {
    /// The report for no data at all: every direction unconstrained.
    fn unconstrained() -> Self {
        let mut eigenvectors = [[0.0; 6]; 6];
        for (i, v) in eigenvectors.iter_mut().enumerate() {
            v[i] = 1.0;
        }
        Degeneracy {
            eigenvalues: [0.0; 6],
            eigenvectors,
            condition: f64::INFINITY,
            weak: AXIS_NAMES.iter().map(|n| format!("{n} (1.00)")).collect(),
        }
    }

    /// Eigen-decomposition of a normalised information matrix.
    fn from_information(m: &Matrix6<f64>, weak_fraction: f64) -> Self {
        let eig = SymmetricEigen::new(*m);
        // nalgebra does not sort the eigenvalues.
        let mut order: [usize; 6] = [0, 1, 2, 3, 4, 5];
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let mut eigenvalues = [0.0; 6];
        let mut eigenvectors = [[0.0; 6]; 6];
        for (k, &i) in order.iter().enumerate() {
            eigenvalues[k] = eig.eigenvalues[i].max(0.0);
            let col = eig.eigenvectors.column(i);
            let dominant = (0..6)
                .max_by(|&a, &b| col[a].abs().total_cmp(&col[b].abs()))
                .unwrap_or(0);
            let sign = if col[dominant] < 0.0 { -1.0 } else { 1.0 };
            for j in 0..6 {
                eigenvectors[k][j] = sign * col[j];
            }
        }
        let (min, max) = (eigenvalues[0], eigenvalues[5]);
        let condition = if min > 0.0 { max / min } else { f64::INFINITY };
        let weak = (0..6)
            .filter(|&k| eigenvalues[k] < weak_fraction * max || max <= 0.0)
            .map(|k| {
                let v = &eigenvectors[k];
                let j = (0..6)
                    .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
                    .unwrap_or(0);
                format!("{} ({:.2})", AXIS_NAMES[j], v[j].abs())
            })
            .collect();
        Degeneracy {
            eigenvalues,
            eigenvectors,
            condition,
            weak,
        }
    }
}

/// The outcome of [`refine`]. A failed refinement is reported here (`converged == false`), not
/// as an error.
#[derive(Debug, Clone, PartialEq)]
pub struct IcpResult {
    /// The refined `T_target_source` (the best estimate so far when not converged).
    pub pose: Pose,
    /// Whether the updates fell below the convergence thresholds at the final correspondence
    /// distance.
    pub converged: bool,
    /// Iterations run (correspondence passes, including one that stopped the refinement for
    /// lack of correspondences).
    pub iterations: usize,
    /// RMS point-to-plane residual of the inliers at the final pose and distance, metres.
    pub inlier_rms: f64,
    /// Inliers divided by the number of source points used (after range filter and
    /// downsampling).
    pub inlier_fraction: f64,
    /// Source points with a target neighbour (that has a normal) within the final
    /// correspondence distance, at the final pose.
    pub correspondences: usize,
    /// How well the final alignment constrains each degree of freedom.
    pub degeneracy: Degeneracy,
    /// Wall-clock time of the call, seconds (preprocessing included).
    pub seconds: f64,
}

/// Refines `T_target_source` by robust point-to-plane ICP, starting from `initial`.
///
/// On return `result.pose` maps source points onto the target's surfaces. See the
/// [module documentation](self) for the method and [`IcpParams`] for the knobs.
///
/// Empty clouds (before or after filtering), a target without usable normals, too few
/// correspondences in any iteration, or unsolvable normal equations are not errors: the result
/// has `converged == false` and holds the best estimate so far (`initial` if no update was
/// made).
///
/// ```
/// use olmap::align::icp::{refine, IcpParams};
/// use olmap::cloud::PointCloud;
/// use olmap::geometry::Pose;
/// use nalgebra::Point3;
///
/// // The corner of a room (floor and two walls), sampled every 10 cm.
/// let mut points = Vec::new();
/// for i in 0..40 {
///     for j in 0..30 {
///         let (a, b) = (i as f32 * 0.1, j as f32 * 0.1);
///         points.push(Point3::new(a, b + 0.1, 0.0));
///         points.push(Point3::new(a, 0.0, b));
///         points.push(Point3::new(0.0, a, b));
///     }
/// }
/// let target = PointCloud::from_points(points);
/// // The same scene seen by a sensor that moved 12 cm and turned 2 degrees.
/// let truth = Pose::from_xyz_ypr(0.1, -0.06, 0.03, 2f64.to_radians(), 0.0, 0.0);
/// let source = target.transformed(&truth.inverse());
///
/// let result = refine(&source, &target, &Pose::identity(), &IcpParams::default()).unwrap();
/// assert!(result.converged);
/// assert!((result.pose.translation() - truth.translation()).norm() < 1e-3);
/// assert!(result.pose.rotation().angle_to(&truth.rotation()) < 1e-4);
/// // Three orthogonal planes pin all six degrees of freedom.
/// assert!(result.degeneracy.weak.is_empty());
/// ```
///
/// # Errors
/// [`Error::InvalidArgument`] for parameters outside their documented ranges
/// ([`IcpParams::validate`]) or a non-finite initial pose.
pub fn refine(
    source: &PointCloud,
    target: &PointCloud,
    initial: &Pose,
    params: &IcpParams,
) -> Result<IcpResult> {
    let started = Instant::now();
    params.validate()?;
    if !initial.to_matrix4().iter().all(|v| v.is_finite()) {
        return Err(Error::InvalidArgument(
            "ICP: the initial pose is not finite".into(),
        ));
    }

    let src = prepare_source(source, params)?;
    let tgt = Target::new(target, params)?;
    let mut pose = *initial.isometry();

    let mut converged = false;
    let mut iterations = 0;
    if let (Some(tgt), false) = (&tgt, src.points.is_empty()) {
        let min_matches =
            ((params.min_correspondence_fraction * src.points.len() as f64).ceil() as usize).max(6);
        let mut d = params.max_distance_start;
        let mut two_back: Option<Isometry3<f64>> = None;
        for _ in 0..params.max_iterations {
            iterations += 1;
            let at_end = d <= params.max_distance_end;
            let centre = pose * src.centroid;
            let acc = accumulate(
                &src.points,
                tgt,
                &pose,
                d,
                centre,
                src.radius,
                params,
                false,
            );
            if acc.matched < min_matches {
                break;
            }
            // RMS distance of the (moved) source from each axis through its centre: the
            // scale at which the degenerate directions are judged, as in `Degeneracy`.
            let cov = pose.rotation.to_rotation_matrix()
                * src.cov
                * pose.rotation.to_rotation_matrix().transpose();
            let axis_rms = Vector3::from_fn(|k, _| (cov.trace() - cov[(k, k)]).max(1e-6).sqrt());
            let Some(delta) = solve(
                &acc.h,
                &acc.g,
                params.degenerate_fraction,
                &(axis_rms / src.radius),
            ) else {
                break;
            };
            // The update in the centred, scaled coordinates: `w_scaled = ω · L`, `v` = motion of
            // the centroid. `step` is how far it moves points at the RMS radius (about).
            let (mut w_scaled, mut v) = (
                Vector3::new(delta[0], delta[1], delta[2]),
                Vector3::new(delta[3], delta[4], delta[5]),
            );
            let mut step = w_scaled.norm().max(v.norm());
            // Trust region: no step moves the points by more than the correspondence distance.
            if step > d {
                w_scaled *= d / step;
                v *= d / step;
                step = d;
            }
            let omega = w_scaled / src.radius;
            let rot = UnitQuaternion::from_scaled_axis(omega);
            let t = centre.coords + v - rot * centre.coords;
            let before = pose;
            pose = Isometry3::from_parts(Translation3::from(t), rot) * pose;
            if at_end
                && v.norm() < params.translation_epsilon
                && omega.norm() < params.rotation_epsilon
            {
                converged = true;
                break;
            }
            // A two-step cycle (nearest neighbours flipping between two sets) at the final
            // distance is as settled as the estimate gets.
            if at_end {
                if let Some(p2) = two_back {
                    let back: Isometry3<f64> = p2;
                    let diff = back.inverse() * pose;
                    if diff.translation.vector.norm() < params.translation_epsilon
                        && diff.rotation.angle() < params.rotation_epsilon
                    {
                        converged = true;
                        break;
                    }
                }
            }
            two_back = Some(before);
            // Schedule: shrink the distance once the estimate has settled at this one.
            if step < params.settle_fraction * d || params.settle_fraction >= 1.0 {
                d = (d * params.distance_decay).max(params.max_distance_end);
            }
        }
    }

    // Statistics and degeneracy at the final pose and distance.
    let (inlier_rms, inlier_fraction, correspondences, degeneracy) = match &tgt {
        Some(tgt) if !src.points.is_empty() => {
            let d = params.max_distance_end;
            let centre = pose * src.centroid;
            let acc = accumulate(&src.points, tgt, &pose, d, centre, src.radius, params, true);
            let rms = if acc.inliers > 0 {
                (acc.sum_r2 / acc.inliers as f64).sqrt()
            } else {
                0.0
            };
            let fraction = acc.inliers as f64 / src.points.len() as f64;
            (
                rms,
                fraction,
                acc.matched,
                acc.degeneracy(params.weak_fraction),
            )
        }
        _ => (0.0, 0.0, 0, Degeneracy::unconstrained()),
    };
    if correspondences < 6 {
        converged = false;
    }

    Ok(IcpResult {
        pose: Pose::from_isometry(pose),
        converged,
        iterations,
        inlier_rms,
        inlier_fraction,
        correspondences,
        degeneracy,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// The source after filtering, in f64, with its centroid and RMS radius.
struct Source {
    points: Vec<Point3<f64>>,
    centroid: Point3<f64>,
    /// RMS distance from the centroid (at least 1 mm).
    radius: f64,
    /// Covariance of the points (about the centroid).
    cov: Matrix3<f64>,
}

fn prepare_source(source: &PointCloud, params: &IcpParams) -> Result<Source> {
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
struct Target {
    points: Vec<Point3<f64>>,
    normals: Vec<Vector3<f64>>,
    tree: ImmutableKdTree<f64, 3>,
}

impl Target {
    /// `None` when the target has no point or no usable normal.
    fn new(target: &PointCloud, params: &IcpParams) -> Result<Option<Self>> {
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
fn plane_normal(cov: &Matrix3<f64>, min_planarity: f64) -> Vector3<f64> {
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

/// Sums over correspondences. Added chunk by chunk in a fixed order.
#[derive(Clone)]
struct Acc {
    /// Weighted Gauss-Newton matrix `Σ w J Jᵀ` (centred, scaled coordinates).
    h: Matrix6<f64>,
    /// `Σ w r J`.
    g: Vector6<f64>,
    /// Correspondences within the distance whose target point has a normal.
    matched: usize,
    /// Of those, the ones with `|r| <` the kernel scale.
    inliers: usize,
    /// `Σ r²` over inliers.
    sum_r2: f64,
    /// Unweighted `Σ J₀ J₀ᵀ` over inliers with `J₀ = (p × n, n)` about the frame origin
    /// (final pass only).
    info: Matrix6<f64>,
    /// `Σ p` over inliers (final pass only).
    sum_p: Vector3<f64>,
    /// `Σ p pᵀ` over inliers (final pass only).
    sum_ppt: Matrix3<f64>,
}

impl Acc {
    fn zero() -> Self {
        Acc {
            h: Matrix6::zeros(),
            g: Vector6::zeros(),
            matched: 0,
            inliers: 0,
            sum_r2: 0.0,
            info: Matrix6::zeros(),
            sum_p: Vector3::zeros(),
            sum_ppt: Matrix3::zeros(),
        }
    }

    fn add(&mut self, o: &Acc) {
        self.h += o.h;
        self.g += o.g;
        self.matched += o.matched;
        self.inliers += o.inliers;
        self.sum_r2 += o.sum_r2;
        self.info += o.info;
        self.sum_p += o.sum_p;
        self.sum_ppt += o.sum_ppt;
    }

    /// The degeneracy report from the final pass's inlier moments: the information matrix is
    /// moved from the origin to the inlier centroid `c` (`(p - c) × n = p × n - [c]× n`), each
    /// rotation coordinate is scaled by the RMS distance of the inliers from that axis through
    /// `c`, and the whole is divided by the inlier count.
    fn degeneracy(&self, weak_fraction: f64) -> Degeneracy {
        if self.inliers < 6 {
            return Degeneracy::unconstrained();
        }
        let n = self.inliers as f64;
        let c = self.sum_p / n;
        let mut s = Matrix6::<f64>::identity();
        s.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-c.cross_matrix()));
        let mut m = s * self.info * s.transpose() / n;
        // Covariance of the inliers; the mean squared distance from axis k is its trace minus
        // its k-th diagonal element.
        let cov = self.sum_ppt / n - c * c.transpose();
        let mut scale = [1.0; 6];
        for (k, sk) in scale.iter_mut().take(3).enumerate() {
            *sk = 1.0 / (cov.trace() - cov[(k, k)]).max(1e-6).sqrt();
        }
        for i in 0..6 {
            for j in 0..6 {
                m[(i, j)] *= scale[i] * scale[j];
            }
        }
        Degeneracy::from_information(&m, weak_fraction)
    }
}

/// One pass over the source: correspondences at distance `d` for the pose `pose`, and the
/// normal-equation sums linearised about `centre` with rotation scaled by `radius`.
#[allow(clippy::too_many_arguments)]
fn accumulate(
    points: &[Point3<f64>],
    tgt: &Target,
    pose: &Isometry3<f64>,
    d: f64,
    centre: Point3<f64>,
    radius: f64,
    params: &IcpParams,
    final_pass: bool,
) -> Acc {
    let d2 = d * d;
    let scale = params.kernel_scale * d;
    let kernel = params.kernel;
    let partial: Vec<Acc> = points
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut acc = Acc::zero();
            for p in chunk {
                let q = pose * p;
                let nn = tgt
                    .tree
                    .query(&[q.x, q.y, q.z])
                    .nearest_one::<SquaredEuclidean<f64>>()
                    .execute();
                if nn.distance.is_nan() || nn.distance > d2 {
                    continue;
                }
                let i = nn.item as usize;
                let n = tgt.normals[i];
                if n == Vector3::zeros() {
                    continue;
                }
                let r = n.dot(&(q - tgt.points[i]));
                acc.matched += 1;
                let w = kernel.weight(r, scale);
                if w > 0.0 {
                    let a = (q - centre).cross(&n) / radius;
                    let j = Vector6::new(a.x, a.y, a.z, n.x, n.y, n.z);
                    acc.h += (w * j) * j.transpose();
                    acc.g += (w * r) * j;
                }
                if r.abs() < scale {
                    acc.inliers += 1;
                    acc.sum_r2 += r * r;
                    if final_pass {
                        let a = q.coords.cross(&n);
                        let j = Vector6::new(a.x, a.y, a.z, n.x, n.y, n.z);
                        acc.info += j * j.transpose();
                        acc.sum_p += q.coords;
                        acc.sum_ppt += q.coords * q.coords.transpose();
                    }
                }
            }
            acc
        })
        .collect();
    let mut total = Acc::zero();
    for a in &partial {
        total.add(a);
    }
    total
}

/// Solves `(H + μ I) δ = -g` by Cholesky with `μ = 1e-6 · mean diagonal`, growing `μ` a
/// hundredfold while the factorisation fails. `None` when nothing works. When some
/// eigenvalue of `H` is below `degenerate_fraction` of the largest, solves in the span of
/// the well-determined eigenvectors only (no motion along the degenerate ones). The
/// eigenvalues are compared with each rotation coordinate rescaled by `axis_scale` (the RMS
/// distance of the points from that axis over the common radius), so that a unit step in
/// any coordinate moves the points by about the same amount.
fn solve(
    h: &Matrix6<f64>,
    g: &Vector6<f64>,
    degenerate_fraction: f64,
    axis_scale: &Vector3<f64>,
) -> Option<Vector6<f64>> {
    let mean_diag = h.trace() / 6.0;
    if !(mean_diag.is_finite() && mean_diag > 0.0 && g.iter().all(|v| v.is_finite())) {
        return None;
    }
    if degenerate_fraction > 0.0 {
        // δ = A u with A = diag(1 / axis_scale, 1, 1, 1): u moves points by metres RMS.
        let a = Vector6::new(
            1.0 / axis_scale.x,
            1.0 / axis_scale.y,
            1.0 / axis_scale.z,
            1.0,
            1.0,
            1.0,
        );
        let hu = Matrix6::from_fn(|i, j| a[i] * h[(i, j)] * a[j]);
        let gu = g.component_mul(&a);
        let eig = hu.symmetric_eigen();
        let max = eig.eigenvalues.max();
        let floor = degenerate_fraction * max;
        if max > 0.0 && eig.eigenvalues.iter().any(|&l| l < floor) {
            let mut u = Vector6::zeros();
            for (i, &l) in eig.eigenvalues.iter().enumerate() {
                if l >= floor {
                    let v = eig.eigenvectors.column(i);
                    u -= v * (v.dot(&gu) / l);
                }
            }
            let x = u.component_mul(&a);
            return x.iter().all(|v| v.is_finite()).then_some(x);
        }
    }
    let mut mu = 1e-6 * mean_diag;
    for _ in 0..8 {
        let a = h + Matrix6::identity() * mu;
        if let Some(chol) = a.cholesky() {
            let x = -chol.solve(g);
            if x.iter().all(|v| v.is_finite()) {
                return Some(x);
            }
        }
        mu *= 100.0;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{PoseError, PoseList};
    use crate::io::{self, ReadOptions};

    /// SplitMix64: a tiny deterministic generator for test scenes.
    struct Rng(u64);

    impl Rng {
        fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }

        /// Uniform in `[0, 1)`.
        fn uniform(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }

        /// Standard normal (Box-Muller).
        fn gauss(&mut self) -> f64 {
            let u = 1.0 - self.uniform();
            let v = self.uniform();
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        }
    }

    /// A planar rectangle `origin + a·u + b·v`, `a ∈ [0, |u|]`, `b ∈ [0, |v|]`.
    struct Patch {
        origin: Vector3<f64>,
        u: Vector3<f64>,
        v: Vector3<f64>,
    }

    impl Patch {
        fn new(origin: [f64; 3], u: [f64; 3], v: [f64; 3]) -> Self {
            Patch {
                origin: Vector3::from(origin),
                u: Vector3::from(u),
                v: Vector3::from(v),
            }
        }
    }

    /// The five visible faces (no bottom) of a box with corner `min` and edges `size`,
    /// turned by `yaw` about the vertical through `min`.
    fn box_faces(min: [f64; 3], size: [f64; 3], yaw: f64) -> Vec<Patch> {
        let r = Matrix3::new(
            yaw.cos(),
            -yaw.sin(),
            0.0,
            yaw.sin(),
            yaw.cos(),
            0.0,
            0.0,
            0.0,
            1.0,
        );
        let o = Vector3::from(min);
        let (ex, ey, ez) = (
            r * Vector3::x() * size[0],
            r * Vector3::y() * size[1],
            Vector3::z() * size[2],
        );
        let p = |origin: Vector3<f64>, u: Vector3<f64>, v: Vector3<f64>| Patch { origin, u, v };
        vec![
            p(o, ex, ez),
            p(o + ey, ex, ez),
            p(o, ey, ez),
            p(o + ex, ey, ez),
            p(o + ez, ex, ey),
        ]
    }

    /// Samples `density` points per square metre (on average) uniformly on each patch, with
    /// Gaussian noise of standard deviation `noise` metres along every axis.
    fn sample(patches: &[Patch], density: f64, noise: f64, seed: u64) -> Vec<Point3<f64>> {
        let mut rng = Rng(seed);
        let mut out = Vec::new();
        for patch in patches {
            let area = patch.u.cross(&patch.v).norm();
            let n = (area * density).round() as usize;
            for _ in 0..n {
                let (a, b) = (rng.uniform(), rng.uniform());
                let mut p = patch.origin + a * patch.u + b * patch.v;
                if noise > 0.0 {
                    p += Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * noise;
                }
                out.push(Point3::from(p));
            }
        }
        out
    }

    /// A room corner (floor and two walls, 12 m x 12 m x 3 m) with four boxes.
    fn structured_scene() -> Vec<Patch> {
        let mut patches = vec![
            Patch::new([-6.0, -6.0, 0.0], [12.0, 0.0, 0.0], [0.0, 12.0, 0.0]),
            Patch::new([-6.0, -6.0, 0.0], [0.0, 12.0, 0.0], [0.0, 0.0, 3.0]),
            Patch::new([-6.0, -6.0, 0.0], [12.0, 0.0, 0.0], [0.0, 0.0, 3.0]),
        ];
        patches.extend(box_faces([1.0, 2.0, 0.0], [1.0, 0.8, 1.2], 0.0));
        patches.extend(box_faces([-3.0, 1.0, 0.0], [0.6, 1.5, 0.9], 0.5));
        patches.extend(box_faces([2.5, -3.0, 0.0], [1.6, 0.5, 2.0], -0.3));
        patches.extend(box_faces([-2.0, -2.5, 0.0], [0.8, 0.8, 0.5], 1.0));
        patches
    }

    /// Target cloud (in the target frame) and source cloud (an independent sample of the same
    /// scene, expressed in the source frame: `p_source = truth⁻¹ p_target`).
    fn scene_pair(
        patches: &[Patch],
        truth: &Pose,
        noise: f64,
        seed: u64,
    ) -> (PointCloud, PointCloud) {
        let to_cloud = |pts: Vec<Point3<f64>>| {
            PointCloud::from_points(pts.iter().map(|p| p.cast::<f32>()).collect())
        };
        let target = to_cloud(sample(patches, 200.0, noise, seed));
        let inv = truth.inverse();
        let source = to_cloud(
            sample(patches, 200.0, noise, seed ^ 0xABCD_EF01)
                .iter()
                .map(|p| inv.transform_point(p))
                .collect(),
        );
        (source, target)
    }

    fn deg(v: f64) -> f64 {
        v.to_radians()
    }

    fn motions() -> Vec<Pose> {
        vec![
            Pose::from_xyz_ypr(0.3, -0.25, 0.2, deg(5.0), deg(-5.0), deg(4.0)),
            Pose::from_xyz_ypr(-0.2, 0.3, -0.3, deg(-4.0), deg(3.0), deg(-5.0)),
            Pose::from_xyz_ypr(0.1, 0.05, 0.0, deg(2.0), deg(0.5), deg(-1.0)),
        ]
    }

    #[test]
    fn recovers_known_motion_noise_free() {
        let scene = structured_scene();
        for (k, truth) in motions().iter().enumerate() {
            let (source, target) = scene_pair(&scene, truth, 0.0, 11 + k as u64);
            let res = refine(&source, &target, &Pose::identity(), &IcpParams::default()).unwrap();
            let e = PoseError::between(&res.pose, truth);
            eprintln!(
                "noise-free #{k}: {:.2} mm / {:.4} deg, {} it, rms {:.2} mm, inliers {:.3}, {:.3} s",
                e.translation_m * 1e3,
                e.rotation_deg,
                res.iterations,
                res.inlier_rms * 1e3,
                res.inlier_fraction,
                res.seconds
            );
            assert!(res.converged, "{res:?}");
            assert!(e.translation_m < 1e-3, "{e:?}");
            assert!(e.rotation_deg < 0.01, "{e:?}");
            assert!(res.degeneracy.weak.is_empty(), "{:?}", res.degeneracy);
        }
    }

    #[test]
    fn recovers_known_motion_with_noise() {
        let scene = structured_scene();
        for (k, truth) in motions().iter().enumerate() {
            let (source, target) = scene_pair(&scene, truth, 0.01, 21 + k as u64);
            let res = refine(&source, &target, &Pose::identity(), &IcpParams::default()).unwrap();
            let e = PoseError::between(&res.pose, truth);
            eprintln!(
                "1 cm noise #{k}: {:.2} mm / {:.4} deg, {} it, rms {:.2} mm, inliers {:.3}, {:.3} s",
                e.translation_m * 1e3,
                e.rotation_deg,
                res.iterations,
                res.inlier_rms * 1e3,
                res.inlier_fraction,
                res.seconds
            );
            assert!(res.converged, "{res:?}");
            assert!(e.translation_m < 0.01, "{e:?}");
            assert!(e.rotation_deg < 0.1, "{e:?}");
        }
    }

    #[test]
    fn uses_given_target_normals() {
        // Exact normals on the target: the floor and the walls of a room corner.
        let truth = Pose::from_xyz_ypr(0.1, -0.05, 0.05, deg(2.0), deg(-1.0), deg(1.0));
        let scene = structured_scene();
        let (source, target) = scene_pair(&scene[..3], &truth, 0.0, 5);
        let normals = target
            .points()
            .iter()
            .map(|p| {
                if p.z.abs() < 1e-6 {
                    Vector3::z()
                } else if (p.x + 6.0).abs() < 1e-5 {
                    Vector3::x()
                } else {
                    Vector3::y()
                }
            })
            .collect();
        let mut with_normals = target.clone();
        with_normals.set_normals(Some(normals)).unwrap();
        let params = IcpParams::default();
        let res = refine(&source, &with_normals, &Pose::identity(), &params).unwrap();
        let e = PoseError::between(&res.pose, &truth);
        assert!(
            res.converged && e.translation_m < 1e-3 && e.rotation_deg < 0.01,
            "{e:?}"
        );
        // Without any downsampling the given normals are used as they are.
        let raw = IcpParams {
            source_voxel: 0.0,
            target_voxel: 0.0,
            ..Default::default()
        };
        let res = refine(&source, &with_normals, &Pose::identity(), &raw).unwrap();
        let e = PoseError::between(&res.pose, &truth);
        assert!(
            res.converged && e.translation_m < 1e-3 && e.rotation_deg < 0.01,
            "{e:?}"
        );
    }

    #[test]
    fn corridor_is_weak_along_its_axis() {
        // Two parallel walls and a floor, 40 m long along x, 3 m wide.
        let scene = vec![
            Patch::new([-20.0, -1.5, 0.0], [40.0, 0.0, 0.0], [0.0, 3.0, 0.0]),
            Patch::new([-20.0, -1.5, 0.0], [40.0, 0.0, 0.0], [0.0, 0.0, 2.5]),
            Patch::new([-20.0, 1.5, 0.0], [40.0, 0.0, 0.0], [0.0, 0.0, 2.5]),
        ];
        let truth = Pose::from_xyz_ypr(0.0, 0.1, -0.05, deg(1.0), deg(0.5), deg(-0.5));
        let (source, target) = scene_pair(&scene, &truth, 0.0, 3);
        let res = refine(&source, &target, &Pose::identity(), &IcpParams::default()).unwrap();
        let dg = &res.degeneracy;
        eprintln!("corridor: {dg:?}");
        assert!(
            dg.weak.iter().any(|w| w.starts_with("translation along x")),
            "{dg:?}"
        );
        assert!(
            !dg.weak
                .iter()
                .any(|w| w.starts_with("translation along y")
                    || w.starts_with("translation along z")),
            "{dg:?}"
        );
        assert_eq!(dg.weak.len(), 1, "{dg:?}");
        // The weakest eigenvector is (almost) a pure translation along x.
        assert!(dg.eigenvectors[0][3] > 0.99, "{dg:?}");
        assert!(dg.condition > 100.0, "{dg:?}");
        // The constrained directions are recovered.
        let e = PoseError::between(&res.pose, &truth);
        assert!(
            e.dy_m.abs() < 1e-3 && e.dz_m.abs() < 1e-3 && e.rotation_deg < 0.01,
            "{e:?}"
        );
    }

    #[test]
    fn bit_identical_for_any_thread_count() {
        let truth = motions()[0];
        let (source, target) = scene_pair(&structured_scene(), &truth, 0.01, 7);
        let params = IcpParams::default();
        let global = refine(&source, &target, &Pose::identity(), &params).unwrap();
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let other = pool
                .install(|| refine(&source, &target, &Pose::identity(), &params))
                .unwrap();
            assert_eq!(global.pose, other.pose, "{threads} threads");
            assert_eq!(global.iterations, other.iterations);
            assert_eq!(global.inlier_rms.to_bits(), other.inlier_rms.to_bits());
            assert_eq!(global.degeneracy, other.degeneracy);
        }
    }

    #[test]
    fn empty_clouds_and_no_overlap_are_not_errors() {
        let (source, target) = scene_pair(&structured_scene(), &Pose::identity(), 0.0, 1);
        let initial = Pose::from_xyz_ypr(0.1, 0.0, 0.0, 0.0, 0.0, 0.0);
        let params = IcpParams::default();
        for (s, t) in [(&PointCloud::new(), &target), (&source, &PointCloud::new())] {
            let res = refine(s, t, &initial, &params).unwrap();
            assert!(!res.converged);
            assert_eq!(res.pose, initial);
            assert_eq!(res.correspondences, 0);
            assert_eq!(res.degeneracy.weak.len(), 6);
        }
        // A range filter that keeps nothing.
        let none = IcpParams {
            source_max_range: Some(1e-3),
            ..Default::default()
        };
        let res = refine(&source, &target, &initial, &none).unwrap();
        assert!(!res.converged && res.pose == initial && res.iterations == 0);
        // A target with many duplicate points and no downsampling still works.
        let mut dup = target.clone();
        for _ in 0..500 {
            dup.push(Point3::new(1.0, 1.0, 0.0));
        }
        let raw = IcpParams {
            target_voxel: 0.0,
            ..Default::default()
        };
        let res = refine(&source, &dup, &initial, &raw).unwrap();
        assert!(
            res.converged && res.pose.translation().norm() < 1e-3,
            "{res:?}"
        );
        // Far apart: no correspondences at all; the initial pose comes back.
        let far = Pose::from_xyz_ypr(100.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let res = refine(&source, &target, &far, &params).unwrap();
        assert!(!res.converged);
        assert_eq!(res.pose, far);
        assert_eq!(res.iterations, 1);
    }

    #[test]
    fn rejects_bad_parameters() {
        let (source, target) = scene_pair(&structured_scene(), &Pose::identity(), 0.0, 1);
        let bad = [
            IcpParams {
                source_voxel: -1.0,
                ..Default::default()
            },
            IcpParams {
                max_distance_end: 3.0,
                ..Default::default()
            },
            IcpParams {
                settle_fraction: 0.0,
                ..Default::default()
            },
            IcpParams {
                weak_fraction: 1.5,
                ..Default::default()
            },
            IcpParams {
                distance_decay: 0.0,
                ..Default::default()
            },
            IcpParams {
                normal_k: 2,
                ..Default::default()
            },
            IcpParams {
                max_iterations: 0,
                ..Default::default()
            },
            IcpParams {
                kernel_scale: f64::NAN,
                ..Default::default()
            },
            IcpParams {
                source_max_range: Some(0.0),
                ..Default::default()
            },
        ];
        for p in &bad {
            assert!(matches!(
                refine(&source, &target, &Pose::identity(), p),
                Err(Error::InvalidArgument(_))
            ));
        }
        let nan = Pose::from_xyz_ypr(f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0);
        assert!(refine(&source, &target, &nan, &IcpParams::default()).is_err());
    }

    #[test]
    fn huber_kernel_also_converges() {
        let truth = motions()[2];
        let (source, target) = scene_pair(&structured_scene(), &truth, 0.005, 9);
        let params = IcpParams {
            kernel: RobustKernel::Huber,
            ..Default::default()
        };
        let res = refine(&source, &target, &Pose::identity(), &params).unwrap();
        let e = PoseError::between(&res.pose, &truth);
        assert!(
            res.converged && e.translation_m < 0.01 && e.rotation_deg < 0.1,
            "{e:?}"
        );
    }

    #[test]
    fn plane_normal_takes_the_smallest_eigenvalue() {
        // Points spread in x and y, flat in z: the normal is ±z whatever order nalgebra
        // returns the eigenvalues in.
        let cov = Matrix3::new(4.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1e-6);
        let n = plane_normal(&cov, 0.2);
        assert!((n.z.abs() - 1.0).abs() < 1e-9);
        let cov = Matrix3::new(1e-6, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 4.0);
        assert!((plane_normal(&cov, 0.2).x.abs() - 1.0).abs() < 1e-9);
        // A line is rejected.
        let cov = Matrix3::new(4.0, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-6);
        assert_eq!(plane_normal(&cov, 0.2), Vector3::zeros());
    }

    fn report(name: &str, res: &IcpResult, e: &PoseError) {
        eprintln!(
            "{name}: |dt| {:.1} cm (dx {:.1}, dy {:.1}, dz {:.1} cm), rot {:.3} deg \
             (yaw {:.3}, pitch {:.3}, roll {:.3}); converged {}, {} it, inlier rms {:.1} mm, \
             inliers {:.3}, {} corr, cond {:.1}, weak {:?}, {:.3} s",
            e.translation_m * 100.0,
            e.dx_m * 100.0,
            e.dy_m * 100.0,
            e.dz_m * 100.0,
            e.rotation_deg,
            e.yaw_deg,
            e.pitch_deg,
            e.roll_deg,
            res.converged,
            res.iterations,
            res.inlier_rms * 1e3,
            res.inlier_fraction,
            res.correspondences,
            res.degeneracy.condition,
            res.degeneracy.weak,
            res.seconds
        );
    }

    #[test]
    fn real_car_pair_from_identity() {
        let Some(dir) = crate::test_data::dir() else {
            return;
        };
        let car = dir.join("libpointmatcher_car");
        let target = io::read_cloud(car.join("car_cloud400.csv")).unwrap().cloud;
        let source = io::read_cloud(car.join("car_cloud401.csv")).unwrap().cloud;
        assert!(target.normals().is_some());
        let table = io::csv::read_pose_table_path(car.join("carCloudList.csv")).unwrap();
        let reference = *table.get("car_cloud401.csv").unwrap();
        let res = refine(&source, &target, &Pose::identity(), &IcpParams::default()).unwrap();
        let e = PoseError::between(&res.pose, &reference);
        report("car 401 -> 400", &res, &e);
        assert!(res.converged);
        assert!(e.translation_m < 0.05, "{e:?}");
        assert!(e.rotation_deg < 0.5, "{e:?}");
    }

    #[test]
    fn real_3dtk_pairs_from_perturbed_reference() {
        let Some(dir) = crate::test_data::dir() else {
            return;
        };
        let dat = dir.join("3dtk_dat");
        let opts = ReadOptions {
            uos_valid_only: true,
            ..Default::default()
        };
        let scan = |n: &str| {
            io::read_cloud_with(dat.join(format!("scan{n}.3d")), &opts)
                .unwrap()
                .cloud
        };
        let scans = [scan("000"), scan("001"), scan("002")];
        let refs = PoseList::read_path(dat.join("reference_poses_rh_m.txt")).unwrap();
        let t_000 = |n: &str| *refs.get(n).unwrap();
        let pairs = [
            (1usize, 0usize, t_000("001")),
            (2, 0, t_000("002")),
            (2, 1, t_000("001").inverse() * t_000("002")),
        ];
        let perturbations = [
            Pose::from_xyz_ypr(0.3, 0.0, 0.0, deg(3.0), 0.0, 0.0),
            Pose::from_xyz_ypr(0.0, -0.3, 0.0, deg(-3.0), 0.0, 0.0),
            Pose::from_xyz_ypr(-0.2, 0.2, 0.1, deg(3.0), 0.0, 0.0),
        ];
        for (s, t, reference) in pairs {
            for (k, dp) in perturbations.iter().enumerate() {
                let initial = reference * *dp;
                let res = refine(&scans[s], &scans[t], &initial, &IcpParams::default()).unwrap();
                let e = PoseError::between(&res.pose, &reference);
                report(&format!("3dtk {s:03} -> {t:03} start #{k}"), &res, &e);
                assert!(res.converged);
                assert!(e.dx_m.abs() < 0.05 && e.dy_m.abs() < 0.05, "{e:?}");
                assert!(e.yaw_deg.abs() < 1.0, "{e:?}");
                assert!(e.dz_m.abs() < 0.15, "{e:?}");
                assert!(e.pitch_deg.abs() < 3.0 && e.roll_deg.abs() < 3.0, "{e:?}");
            }
        }
    }
}
