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
//!   ([`kiddo`]) is built once over the target points. [`IcpTarget`] keeps a prepared
//!   target for many refinements ([`refine_to`]). A mapper's map is indexed in 4 m column
//!   tiles instead, a tree each, and brought up to date after each placement by indexing
//!   again only the tiles the new scan changed and forgetting only the normals it reached
//!   (`tiles.rs`; the answers are those of one tree over the whole map).
//! * **Loose, then tight.** The schedule first runs to convergence at ten times the
//!   epsilons, optionally on a source downsampled [`IcpParams::coarse_voxel_factor`] times
//!   coarser (off by default), then continues on the source at [`IcpParams::source_voxel`]
//!   to the epsilons; the statistics use that source. The last stage is reserved a fifth of
//!   [`IcpParams::max_iterations`] (below five iterations there is one stage).
//! * **Extrapolation** (Besl & McKay 1992, "accelerated ICP"). When two consecutive updates
//!   at the same distance point within about 18° of each other (in the centred, scaled
//!   coordinates below) and the second is `r < 1` times the first, the estimate moves by
//!   `min(1 / (1 - r), 4)` times the update: the sum of the geometric series the steps are
//!   following. Never twice in a row; the trust region applies after it; convergence and
//!   settling are judged on the plain update. The fixed point is unchanged.
//! * **Target normals.** The target's own normals are used when it has them; otherwise each
//!   target point's normal (computed when a correspondence first needs it, then kept) is the
//!   eigenvector of the smallest eigenvalue of the covariance of
//!   its [`IcpParams::normal_k`] nearest neighbours (PCA). With the eigenvalues sorted
//!   `λ0 ≤ λ1 ≤ λ2`, neighbourhoods whose planarity `(λ1 - λ0) / λ2` is below
//!   [`IcpParams::min_planarity`] (lines, corners, clutter) get no normal and are never
//!   used as correspondences.
//! * **Correspondences and residuals.** Each source point `p`, mapped by the current estimate
//!   `T`, is paired with its nearest target point `q` (normal `n`) if that lies within the
//!   current maximum correspondence distance `d`. The residual is the point-to-plane distance
//!   `r = n · (T p - q)` (Chen & Medioni 1991).
//!   The k-d tree is asked for the four nearest target points and they are kept with `R`,
//!   the farthest one's distance; after the mapped point moved by `δ`, every other target
//!   point is at least `R - δ` away, so while the nearest of the four is closer than that
//!   it is the nearest of all (triangle inequality): later iterations, whose updates move
//!   points by millimetres, skip most queries with exactly the same correspondences, and a
//!   hypothesis' finishing stage starts from what its first stage kept (when that stage
//!   ran on the full source, the default).
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
//! * P. J. Besl, N. D. McKay, *A method for registration of 3-D shapes*, IEEE PAMI 14(2),
//!   1992 (the accelerated ICP).

mod degeneracy;
mod nearest;
mod params;
mod reduce;
mod solve;
mod target;
mod tiles;

use std::time::Instant;

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};

pub use self::degeneracy::Degeneracy;
use self::nearest::NearestCache;
pub(crate) use self::nearest::NearestMemory;
pub use self::params::{IcpParams, NormalNeighbourhood, RobustKernel};
use self::reduce::{accumulate, statistics, Statistics};
use self::solve::solve;
pub(crate) use self::target::IcpSource;
pub use self::target::IcpTarget;
use self::target::{Source, Target};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::Pose;

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
    /// Unweighted `Σ J₀ J₀ᵀ` over the inliers at the final pose, with
    /// `J₀ = (q × n, n)` for an inlier mapped to `q` in the target frame with target normal
    /// `n`: the Gauss-Newton matrix of the point-to-plane residuals for a small motion
    /// `(ω, v)` applied on the left about the target frame's origin (rotation first). See
    /// [`IcpResult::edge_information`] for it as a pose-graph edge's information.
    pub hessian: Matrix6<f64>,
    /// Inliers at the final pose (`inlier_fraction` times the source points used).
    pub inliers: usize,
    /// Wall-clock time of the call, seconds (preprocessing included).
    pub seconds: f64,
    /// Where its last run of the schedule ended: what [`finish_coarse`] resumes from.
    pub(crate) ended: StageEnd,
}

#[cfg(test)]
impl IcpResult {
    /// A refinement that stayed at `pose`, converged or not (for tests of what weighs
    /// refined hypotheses).
    pub(crate) fn at(pose: Pose, converged: bool) -> IcpResult {
        IcpResult {
            pose,
            converged,
            iterations: 0,
            inlier_rms: 0.0,
            inlier_fraction: 1.0,
            correspondences: 0,
            degeneracy: Degeneracy::unconstrained(),
            hessian: Matrix6::zeros(),
            inliers: 0,
            seconds: 0.0,
            ended: StageEnd {
                d: 0.0,
                stopped: false,
            },
        }
    }
}

/// Where a run of the schedule ended ([`IcpResult::ended`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StageEnd {
    /// The correspondence distance reached, metres.
    d: f64,
    /// Ended by too few correspondences or unsolvable normal equations.
    stopped: bool,
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
    check_initial(initial)?;
    let prepared = IcpTarget::new(target, params)?;
    refine_from(source, &prepared, initial, params, started)
}

/// [`refine`] against a target prepared once ([`IcpTarget`]): the same result as [`refine`]
/// on the cloud it was prepared from, without preparing it again.
///
/// # Errors
/// As [`refine`], and [`Error::InvalidArgument`] when `target` was prepared with other
/// target parameters ([`IcpTarget::prepared_for`]).
pub fn refine_to(
    source: &PointCloud,
    target: &IcpTarget,
    initial: &Pose,
    params: &IcpParams,
) -> Result<IcpResult> {
    let started = Instant::now();
    params.validate()?;
    check_initial(initial)?;
    if !target.prepared_for(params) {
        return Err(Error::InvalidArgument(
            "ICP: the target was prepared with other target parameters (voxel, normals, \
             normal_k or planarity) than this refinement's"
                .into(),
        ));
    }
    refine_from(source, target, initial, params, started)
}

/// A non-finite initial pose is an error.
fn check_initial(initial: &Pose) -> Result<()> {
    if initial.to_matrix4().iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::InvalidArgument(
            "ICP: the initial pose is not finite".into(),
        ))
    }
}

/// How far [`refine_prepared`] goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Depth {
    /// The thin stage (when the source has one), then the full source: [`refine`].
    Full,
    /// The thin stage alone (the full source when there is none), to
    /// [`COARSE_EPSILON_FACTOR`] times the epsilons, with its statistics: enough to compare
    /// hypotheses at the search's resolution.
    Coarse,
    /// The full source alone from the final distance: what [`Depth::Full`] adds to a
    /// converged [`Depth::Coarse`] result (start from its pose).
    Finish,
    /// The full source alone from distance `d` with the full epsilons: what [`Depth::Full`]
    /// adds to an unconverged [`Depth::Coarse`] result of a source with no thin stage, that
    /// ended at `d` (start from its pose; see [`finish_coarse`]).
    Resume(f64),
}

/// Extrapolation of a steady run of steps (see [`schedule`]): consecutive Gauss-Newton
/// updates at most this far apart in direction (cosine; about 18°)...
const ACCEL_MIN_COSINE: f64 = 0.95;

/// ... move the estimate by at most this many times the last update.
const ACCEL_MAX_FACTOR: f64 = 4.0;

/// The thin stage converges at this many times the epsilons (the full source finishes).
pub(crate) const COARSE_EPSILON_FACTOR: f64 = 10.0;

/// The refinement proper (parameters checked, target prepared).
fn refine_from(
    source: &PointCloud,
    target: &IcpTarget,
    initial: &Pose,
    params: &IcpParams,
    started: Instant,
) -> Result<IcpResult> {
    let src = IcpSource::new(source, params)?;
    let mut memory = NearestMemory::new(&src);
    Ok(refine_prepared(
        &src,
        target,
        initial,
        params,
        Depth::Full,
        0,
        started,
        &mut memory,
    ))
}

/// Poses a refinement stops at (see [`refine_unless_joining`]): an earlier refinement's
/// results, and how near (metres, radians) counts as joining one of them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Joins<'a> {
    /// The poses.
    pub(crate) poses: &'a [Pose],
    /// Translation tolerance, metres.
    pub(crate) translation: f64,
    /// Rotation tolerance, radians.
    pub(crate) rotation: f64,
}

impl Joins<'_> {
    /// No pose to join.
    const NONE: Joins<'static> = Joins {
        poses: &[],
        translation: 0.0,
        rotation: 0.0,
    };

    /// Whether `pose` lies within the tolerances of one of the poses.
    fn joined(&self, pose: &Isometry3<f64>) -> bool {
        self.poses.iter().any(|p| {
            let p = p.isometry();
            (p.translation.vector - pose.translation.vector).norm() <= self.translation
                && p.rotation.angle_to(&pose.rotation) <= self.rotation
        })
    }
}

/// [`refine_to`] with the source prepared too (parameters and initial pose already
/// checked), to `depth`; `spent` iterations were already spent on this refinement (by the
/// [`Depth::Coarse`] run a [`Depth::Finish`] continues; 0 otherwise): the stages together
/// run at most [`IcpParams::max_iterations`]. `memory` keeps the sources' nearest target
/// points for the next stage of the same refinement (against the same target).
#[allow(clippy::too_many_arguments)]
pub(crate) fn refine_prepared(
    src: &IcpSource,
    target: &IcpTarget,
    initial: &Pose,
    params: &IcpParams,
    depth: Depth,
    spent: usize,
    started: Instant,
    memory: &mut NearestMemory,
) -> IcpResult {
    match refine_unless_joining(
        src,
        target,
        initial,
        params,
        depth,
        spent,
        started,
        memory,
        Joins::NONE,
    ) {
        Some(r) => r,
        // Without a pose to join, no refinement gives up.
        None => unreachable!("a refinement with no pose to join ended by joining one"),
    }
}

/// [`refine_prepared`] that gives up (`None`) as soon as its first stage's estimate (the
/// thin stage, what [`Depth::Coarse`] runs) comes within the tolerances of one of `joins`'
/// poses, the start included: a verification's rival that
/// runs into a hypothesis already refined ends there (its refinement from that point on is
/// the earlier one's again, and the verification would drop it as the same solution).
#[allow(clippy::too_many_arguments)]
pub(crate) fn refine_unless_joining(
    src: &IcpSource,
    target: &IcpTarget,
    initial: &Pose,
    params: &IcpParams,
    depth: Depth,
    spent: usize,
    started: Instant,
    memory: &mut NearestMemory,
    joins: Joins<'_>,
) -> Option<IcpResult> {
    let tgt = target.inner.as_ref();
    let mut pose = *initial.isometry();
    let mut converged = false;
    let mut iterations = 0;
    // Nothing to resume when no schedule runs (no target or no source point).
    let mut ended = StageEnd {
        d: params.max_distance_start,
        stopped: true,
    };
    let thin = src.coarse.as_ref();
    // Each source remembers its points' nearest target points from pass to pass.
    memory.fit(src, tgt.map_or(0, |t| t.points.len()));
    let NearestMemory {
        fine: fine_cache,
        thin: thin_cache,
        ..
    } = memory;
    let (last, last_is_thin) = match (depth, thin) {
        (Depth::Coarse, Some(t)) => (t, true),
        _ => (&src.fine, false),
    };
    // The full source's last iterations are reserved a fifth of the budget (with fewer
    // than five iterations there is no thin stage).
    let reserve = params.max_iterations / 5;
    if let (Some(tgt), false) = (tgt, src.fine.points.is_empty()) {
        if let Depth::Finish | Depth::Resume(_) = depth {
            let budget = params.max_iterations.saturating_sub(spent).max(1);
            let from = match depth {
                Depth::Resume(d) => d,
                _ => params.max_distance_end,
            };
            let s = schedule(
                &src.fine,
                tgt,
                pose,
                from,
                params,
                1.0,
                budget,
                fine_cache,
                Joins::NONE,
            );
            (pose, converged, iterations) = (s.pose, s.converged, s.iterations);
            ended = s.end();
        } else if depth == Depth::Full && reserve == 0 {
            let s = schedule(
                &src.fine,
                tgt,
                pose,
                params.max_distance_start,
                params,
                1.0,
                params.max_iterations,
                fine_cache,
                Joins::NONE,
            );
            (pose, converged, iterations) = (s.pose, s.converged, s.iterations);
            ended = s.end();
        } else {
            let (first_src, first_cache) = match thin {
                Some(t) => (t, &mut *thin_cache),
                None => (&src.fine, &mut *fine_cache),
            };
            let first = schedule(
                first_src,
                tgt,
                pose,
                params.max_distance_start,
                params,
                COARSE_EPSILON_FACTOR,
                params.max_iterations - reserve,
                first_cache,
                joins,
            );
            if first.joined {
                return None;
            }
            (pose, converged, iterations) = (first.pose, first.converged, first.iterations);
            ended = first.end();
            // A first stage that found too few correspondences (or no solution) ends it.
            if depth == Depth::Full && !first.stopped {
                let budget = params.max_iterations - iterations;
                let s = schedule(
                    &src.fine,
                    tgt,
                    pose,
                    first.d,
                    params,
                    1.0,
                    budget,
                    fine_cache,
                    Joins::NONE,
                );
                (pose, converged) = (s.pose, s.converged);
                ended = s.end();
                iterations += s.iterations;
            }
        }
    }

    // Statistics and degeneracy at the final pose and distance.
    let last_cache = if last_is_thin { thin_cache } else { fine_cache };
    let Statistics {
        inlier_rms,
        inlier_fraction,
        correspondences,
        degeneracy,
        hessian,
        inliers,
    } = statistics(last, tgt, &pose, params, last_cache);
    if correspondences < 6 {
        converged = false;
    }

    Some(IcpResult {
        pose: Pose::from_isometry(pose),
        converged,
        iterations,
        inlier_rms,
        inlier_fraction,
        correspondences,
        degeneracy,
        hessian,
        inliers,
        seconds: started.elapsed().as_secs_f64(),
        ended,
    })
}

/// What [`Depth::Full`] from `initial` gives, from `coarse`, the [`Depth::Coarse`] result
/// from `initial` that `memory` was used for: a converged one is finished on the full
/// source from its pose ([`Depth::Finish`]); an unconverged one of a source with no thin
/// stage is where the full refinement's first stage ends too (the same source, start and
/// schedule), so it is resumed from there ([`Depth::Resume`]; one that stopped for lack of
/// correspondences is the full result already); otherwise the full refinement runs from
/// `initial` (also with fewer than five iterations in all, when `Depth::Full` has a single
/// stage). The same result as [`Depth::Full`] from the start (up to which of two target
/// points exactly equidistant from a source point is taken: the memory differs), without
/// running the first stage twice (an unconverged rival of a verification ran 40 + 50
/// iterations).
pub(crate) fn finish_coarse(
    src: &IcpSource,
    target: &IcpTarget,
    initial: &Pose,
    coarse: &IcpResult,
    params: &IcpParams,
    memory: &mut NearestMemory,
) -> IcpResult {
    let started = Instant::now();
    // With fewer than five iterations `Depth::Full` has one stage at the full epsilons:
    // nothing of a first stage carries over.
    let staged = params.max_iterations / 5 > 0;
    let resume = match (coarse.converged, src.coarse.is_none()) {
        (true, _) if staged => Depth::Finish,
        (false, true) if staged && coarse.ended.stopped => return coarse.clone(),
        (false, true) if staged => Depth::Resume(coarse.ended.d),
        _ => {
            return refine_prepared(
                src,
                target,
                initial,
                params,
                Depth::Full,
                0,
                started,
                memory,
            )
        }
    };
    let mut f = refine_prepared(
        src,
        target,
        &coarse.pose,
        params,
        resume,
        coarse.iterations,
        started,
        memory,
    );
    f.iterations += coarse.iterations;
    f.seconds += coarse.seconds;
    f
}

impl Settled {
    /// Where it ended, for [`IcpResult::ended`].
    fn end(&self) -> StageEnd {
        StageEnd {
            d: self.d,
            stopped: self.stopped,
        }
    }
}

/// Where a run of the schedule ended.
struct Settled {
    pose: Isometry3<f64>,
    /// The correspondence distance reached.
    d: f64,
    converged: bool,
    iterations: usize,
    /// Ended by too few correspondences or unsolvable normal equations.
    stopped: bool,
    /// Ended by coming within the tolerances of a pose to join ([`Joins`]).
    joined: bool,
}

/// The Gauss-Newton iterations with the shrinking correspondence distance (module
/// documentation), from `pose` at distance `d`, on `src`, with the epsilons scaled by
/// `eps_scale`, for at most `max_iterations`; `cache` remembers `src`'s nearest target
/// points. It ends as soon as the estimate joins one of `joins`' poses.
#[allow(clippy::too_many_arguments)]
fn schedule(
    src: &Source,
    tgt: &Target,
    mut pose: Isometry3<f64>,
    mut d: f64,
    params: &IcpParams,
    eps_scale: f64,
    max_iterations: usize,
    cache: &mut NearestCache,
    joins: Joins<'_>,
) -> Settled {
    let (eps_t, eps_r) = (
        params.translation_epsilon * eps_scale,
        params.rotation_epsilon * eps_scale,
    );
    let mut converged = false;
    let mut iterations = 0;
    let min_matches =
        ((params.min_correspondence_fraction * src.points.len() as f64).ceil() as usize).max(6);
    let mut two_back: Option<Isometry3<f64>> = None;
    let mut previous: Option<(Vector6<f64>, f64)> = None;
    let mut stopped = false;
    let mut joined = false;
    for _ in 0..max_iterations {
        if joins.joined(&pose) {
            joined = true;
            break;
        }
        iterations += 1;
        let at_end = d <= params.max_distance_end;
        let centre = pose * src.centroid;
        let acc = accumulate(src, tgt, &pose, d, params, false, cache);
        if acc.matched < min_matches {
            stopped = true;
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
            stopped = true;
            break;
        };
        // The update in the centred, scaled coordinates: `w_scaled = ω · L`, `v` = motion of
        // the centroid. `step` is how far it moves points at the RMS radius (about).
        let (mut w_scaled, mut v) = (
            Vector3::new(delta[0], delta[1], delta[2]),
            Vector3::new(delta[3], delta[4], delta[5]),
        );
        let step = w_scaled.norm().max(v.norm());
        // The convergence and settling tests judge the Gauss-Newton update itself.
        let (gn_v, gn_omega) = (v.norm(), w_scaled.norm() / src.radius);
        // Steps that keep their direction and shrink by a steady ratio `r` (correspondences
        // sliding along surfaces) are the terms of a geometric series: the estimate moves by
        // the series' sum, `1 / (1 - r)` times the step (at most `ACCEL_MAX_FACTOR`), as in
        // Besl and McKay's accelerated ICP. The fixed point is unchanged; only fewer
        // iterations reach it.
        let gn = Vector6::new(w_scaled.x, w_scaled.y, w_scaled.z, v.x, v.y, v.z);
        let mut factor = 1.0;
        if let Some((prev, prev_d)) = previous {
            let (a, b) = (gn.norm(), prev.norm());
            if prev_d == d && a > 0.0 && b > 0.0 {
                let (r, cos) = (a / b, gn.dot(&prev) / (a * b));
                if cos >= ACCEL_MIN_COSINE && r < 1.0 {
                    factor = (1.0 / (1.0 - r)).min(ACCEL_MAX_FACTOR);
                }
            }
        }
        // After a jump the next step is no term of the same series.
        previous = (factor == 1.0).then_some((gn, d));
        w_scaled *= factor;
        v *= factor;
        // Trust region: no step moves the points by more than the correspondence distance.
        let moved = w_scaled.norm().max(v.norm());
        if moved > d {
            w_scaled *= d / moved;
            v *= d / moved;
        }
        let step = step.min(d);
        let omega = w_scaled / src.radius;
        let rot = UnitQuaternion::from_scaled_axis(omega);
        let t = centre.coords + v - rot * centre.coords;
        let before = pose;
        pose = Isometry3::from_parts(Translation3::from(t), rot) * pose;
        if at_end && gn_v < eps_t && gn_omega < eps_r {
            converged = true;
            break;
        }
        // A two-step cycle (nearest neighbours flipping between two sets) at the final
        // distance is as settled as the estimate gets.
        if at_end {
            if let Some(back) = two_back {
                let diff = back.inverse() * pose;
                if diff.translation.vector.norm() < eps_t && diff.rotation.angle() < eps_r {
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
    Settled {
        pose,
        d,
        converged,
        iterations,
        stopped,
        joined,
    }
}

impl IcpResult {
    /// The registration as a pose-graph edge `target → source` (measurement `self.pose`):
    /// its information over the graph's residual (translation first, then rotation; see
    /// [`crate::graph`]), `B H Bᵀ · scale / σ²` with `H` = [`IcpResult::hessian`], σ the
    /// inlier RMS residual (at least `sigma_floor`) and `B` the change from a left motion
    /// about the target origin to the graph's right perturbation of the source's pose
    /// ([`edge_information_from`]). `scale` (< 1) accounts for neighbouring points' errors
    /// being correlated (the points are not independent measurements).
    pub fn edge_information(&self, sigma_floor: f64, scale: f64) -> Matrix6<f64> {
        let s = self.inlier_rms.max(sigma_floor);
        edge_information_from(&self.hessian, &self.pose) * (scale / (s * s))
    }
}

/// `B H Bᵀ`: a point-to-plane Gauss-Newton matrix `H` over `(ω, v)` (a motion applied on
/// the left of `t_target_source`, about the target origin; [`IcpResult::hessian`])
/// expressed over the pose graph's residual of an edge `target → source` with measurement
/// `t_target_source` (`e = (R_iᵀ (p_j − p_i) − t, Log(Rᵀ R_iᵀ R_j))`, translation first).
/// For a point with normal `n` mapped to `q = R p + t`, the residual changes by `n · e_t`
/// and `(Rᵀ (q − t) × Rᵀ n) · e_r`, so `B = [[0, I], [Rᵀ, −Rᵀ [t]×]]`.
pub fn edge_information_from(hessian: &Matrix6<f64>, t_target_source: &Pose) -> Matrix6<f64> {
    let iso = t_target_source.isometry();
    let rt = iso.rotation.to_rotation_matrix().matrix().transpose();
    let t = iso.translation.vector;
    let mut b = Matrix6::<f64>::zeros();
    b.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&nalgebra::Matrix3::identity());
    b.fixed_view_mut::<3, 3>(3, 0).copy_from(&rt);
    b.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(-rt * t.cross_matrix()));
    let m = b * hessian * b.transpose();
    (m + m.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix3, Point3};

    use super::target::plane_normal;
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

    /// The edge information is the Gauss-Newton matrix of the point-to-plane residuals over
    /// the pose graph's residual: checked against central differences of the residuals of
    /// points on planes, the source pose moved by the graph's right perturbation.
    #[test]
    fn edge_information_matches_numerical_differentiation() {
        let t = Pose::from_xyz_ypr(1.5, -2.0, 0.3, 0.7, 0.1, -0.2);
        let mut rng = Rng(7);
        // Source points (source frame) and the target plane each lies on (normal, offset).
        let mut pairs = Vec::new();
        let mut hessian = Matrix6::<f64>::zeros();
        for _ in 0..40 {
            let p = Point3::new(4.0 * rng.gauss(), 4.0 * rng.gauss(), 1.0 + rng.gauss());
            let n = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()).normalize();
            let q = t.transform_point(&p);
            let a = q.coords.cross(&n);
            let j = nalgebra::Vector6::new(a.x, a.y, a.z, n.x, n.y, n.z);
            hessian += j * j.transpose();
            pairs.push((p, n, n.dot(&q.coords)));
        }
        let info = edge_information_from(&hessian, &t);
        // The source pose whose graph residual against measurement `t` is `e`.
        let moved = |e: &nalgebra::Vector6<f64>| {
            let iso = t.isometry();
            let tr = iso.translation.vector + Vector3::new(e[0], e[1], e[2]);
            let rot =
                iso.rotation * UnitQuaternion::from_scaled_axis(Vector3::new(e[3], e[4], e[5]));
            Pose::from_isometry(Isometry3::from_parts(Translation3::from(tr), rot))
        };
        let h = 1e-6;
        let mut numeric = Matrix6::<f64>::zeros();
        for (p, n, d) in &pairs {
            let mut j = nalgebra::Vector6::zeros();
            for k in 0..6 {
                let mut e = nalgebra::Vector6::zeros();
                e[k] = h;
                let plus = n.dot(&moved(&e).transform_point(p).coords) - d;
                e[k] = -h;
                let minus = n.dot(&moved(&e).transform_point(p).coords) - d;
                j[k] = (plus - minus) / (2.0 * h);
            }
            numeric += j * j.transpose();
        }
        let err = (info - numeric).abs().max();
        assert!(err < 1e-5 * numeric.abs().max(), "{info}\n{numeric}");
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

    /// Normals from each target voxel's 3 × 3 × 3 block recover the same motions as the
    /// nearest points' within the noise (1 cm of noise, the bounds of the test above).
    #[test]
    fn voxel_block_normals_recover_known_motion_with_noise() {
        let scene = structured_scene();
        let params = IcpParams {
            normal_neighbourhood: NormalNeighbourhood::VoxelBlock,
            ..Default::default()
        };
        for (k, truth) in motions().iter().enumerate() {
            let (source, target) = scene_pair(&scene, truth, 0.01, 21 + k as u64);
            let res = refine(&source, &target, &Pose::identity(), &params).unwrap();
            let e = PoseError::between(&res.pose, truth);
            assert!(res.converged, "{res:?}");
            assert!(e.translation_m < 0.01, "#{k}: {e:?}");
            assert!(e.rotation_deg < 0.1, "#{k}: {e:?}");
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

    /// A refinement given poses to join stops (`None`) once its estimate comes within the
    /// tolerances of one, and is the plain refinement when it never comes near one.
    #[test]
    fn a_refinement_stops_where_it_joins_an_earlier_result() {
        let truth = Pose::from_xyz_ypr(0.15, -0.1, 0.02, 0.05, 0.01, 0.0);
        let (source, target) = scene_pair(&structured_scene(), &truth, 0.005, 7);
        let params = IcpParams::default();
        let prepared = IcpTarget::new(&target, &params).unwrap();
        let src = IcpSource::new(&source, &params).unwrap();
        let run = |joins: Joins<'_>| {
            let mut memory = NearestMemory::new(&src);
            refine_unless_joining(
                &src,
                &prepared,
                &Pose::identity(),
                &params,
                Depth::Coarse,
                0,
                Instant::now(),
                &mut memory,
                joins,
            )
        };
        let plain = run(Joins::NONE).unwrap();
        assert!(plain.converged);
        assert!((plain.pose.translation() - truth.translation()).norm() < 0.01);
        // The earlier result it runs into (2 cm and 0.5° around the truth).
        let earlier = [truth];
        let joined = run(Joins {
            poses: &earlier,
            translation: 0.02,
            rotation: 0.5f64.to_radians(),
        });
        assert!(joined.is_none());
        // A pose it never comes near changes nothing.
        let elsewhere = [Pose::from_xyz_ypr(2.0, 2.0, 0.0, 1.0, 0.0, 0.0)];
        let apart = run(Joins {
            poses: &elsewhere,
            translation: 0.1,
            rotation: 1f64.to_radians(),
        })
        .unwrap();
        assert_eq!(apart.pose, plain.pose);
        assert_eq!(apart.iterations, plain.iterations);
        // Nor does the same pose with tolerances too tight to reach (the estimate
        // converges about a millimetre from the truth in this noisy scene).
        let strict = run(Joins {
            poses: &earlier,
            translation: 1e-6,
            rotation: 1e-6,
        })
        .unwrap();
        assert_eq!(strict.pose, plain.pose);
    }

    /// A target prepared once gives every refinement exactly what preparing it again would
    /// (its normals, computed on first use, depend on the target alone), and refuses a
    /// refinement with other target parameters.
    #[test]
    fn a_prepared_target_gives_the_same_refinements() {
        let truth = Pose::from_xyz_ypr(0.15, -0.1, 0.02, 0.05, 0.01, 0.0);
        let (source, target) = scene_pair(&structured_scene(), &truth, 0.005, 7);
        let params = IcpParams::default();
        let prepared = IcpTarget::new(&target, &params).unwrap();
        assert!(!prepared.is_empty() && prepared.prepared_for(&params));
        let starts = [
            Pose::identity(),
            Pose::from_xyz_ypr(0.3, 0.0, 0.0, 0.0, 0.0, 0.0),
            Pose::from_xyz_ypr(0.0, -0.2, 0.0, 0.1, 0.0, 0.0),
        ];
        for start in &starts {
            let once = refine(&source, &target, start, &params).unwrap();
            let kept = refine_to(&source, &prepared, start, &params).unwrap();
            assert_eq!(once.pose, kept.pose);
            assert_eq!(once.iterations, kept.iterations);
            assert_eq!(once.inlier_rms.to_bits(), kept.inlier_rms.to_bits());
            assert!(kept.converged);
            assert!((kept.pose.translation() - truth.translation()).norm() < 0.01);
        }
        let other = IcpParams {
            normal_k: 12,
            ..Default::default()
        };
        assert!(!prepared.prepared_for(&other));
        assert!(matches!(
            refine_to(&source, &prepared, &Pose::identity(), &other),
            Err(Error::InvalidArgument(_))
        ));
    }

    /// The thin stage is a start, not the answer: refining with it ends where refining on
    /// the full source alone ends (to well under a millimetre; both stop when an update
    /// moves the points by less than 0.1 mm), from a start 0.3 m and 6° off.
    #[test]
    fn the_thin_stage_ends_where_the_full_source_alone_ends() {
        let truth = Pose::from_xyz_ypr(0.2, 0.15, 0.03, 0.1, 0.02, -0.01);
        let (source, target) = scene_pair(&structured_scene(), &truth, 0.01, 3);
        let thin = IcpParams {
            coarse_voxel_factor: 3.0,
            ..Default::default()
        };
        let full_only = IcpParams {
            coarse_voxel_factor: 1.0,
            ..Default::default()
        };
        let a = refine(&source, &target, &Pose::identity(), &thin).unwrap();
        let b = refine(&source, &target, &Pose::identity(), &full_only).unwrap();
        assert!(a.converged && b.converged, "{a:?} {b:?}");
        assert!(
            (a.pose.translation() - b.pose.translation()).norm() < 5e-4,
            "{:?} vs {:?}",
            a.pose,
            b.pose
        );
        assert!(a.pose.rotation().angle_to(&b.pose.rotation()) < 1e-4);
        assert!((a.pose.translation() - truth.translation()).norm() < 0.01);
    }

    /// Finishing a first stage ([`finish_coarse`]) gives what the full refinement from the
    /// start gives, to the bit: converged first stages (finished), unconverged ones of a
    /// source with no thin stage (resumed), ones that stopped (no overlap), with a thin
    /// source (refined again from the start), and with four iterations in all (a single
    /// stage).
    #[test]
    fn finishing_a_first_stage_is_the_full_refinement() {
        let truth = Pose::from_xyz_ypr(0.3, -0.25, 0.2, deg(5.0), deg(-5.0), deg(4.0));
        let (source, target) = scene_pair(&structured_scene(), &truth, 0.01, 5);
        let far = source.transformed(&Pose::from_xyz_ypr(60.0, 0.0, 0.0, 0.0, 0.0, 0.0));
        let same = |a: &IcpResult, b: &IcpResult| {
            (
                a.pose,
                a.converged,
                a.iterations,
                a.correspondences,
                a.inliers,
            ) == (
                b.pose,
                b.converged,
                b.iterations,
                b.correspondences,
                b.inliers,
            ) && (a.inlier_rms, a.hessian, &a.degeneracy)
                == (b.inlier_rms, b.hessian, &b.degeneracy)
        };
        // Already aligned, from the final distance: a first stage that converges within
        // four iterations (where the full refinement has a single stage).
        let aligned = source.transformed(&truth);
        let (mut kinds, mut single) = ((0, 0, 0), 0);
        for (cloud, max_iterations, factor, start) in [
            (&source, 50, 1.0, 2.0),
            (&source, 12, 1.0, 2.0),
            (&source, 6, 1.0, 2.0),
            (&source, 4, 1.0, 2.0),
            (&aligned, 4, 1.0, 0.4),
            (&far, 50, 1.0, 2.0),
            (&source, 12, 3.0, 2.0),
        ] {
            let params = IcpParams {
                max_iterations,
                max_distance_start: start,
                coarse_voxel_factor: factor,
                ..Default::default()
            };
            let src = IcpSource::new(cloud, &params).unwrap();
            let tgt = IcpTarget::new(&target, &params).unwrap();
            let run = |depth: Depth, memory: &mut NearestMemory| {
                refine_prepared(
                    &src,
                    &tgt,
                    &Pose::identity(),
                    &params,
                    depth,
                    0,
                    Instant::now(),
                    memory,
                )
            };
            let mut memory = NearestMemory::new(&src);
            let coarse = run(Depth::Coarse, &mut memory);
            let finished =
                finish_coarse(&src, &tgt, &Pose::identity(), &coarse, &params, &mut memory);
            let full = run(Depth::Full, &mut NearestMemory::new(&src));
            assert!(
                same(&finished, &full),
                "{max_iterations} {factor}: {finished:?}\n{full:?}"
            );
            match (coarse.converged, coarse.ended.stopped) {
                (true, _) if max_iterations < 5 => single += 1,
                (true, _) => kinds.0 += 1,
                (false, false) => kinds.1 += 1,
                (false, true) => kinds.2 += 1,
            }
        }
        // Each way of finishing was taken.
        assert!(kinds.0 > 0 && kinds.1 > 0 && kinds.2 > 0, "{kinds:?}");
        assert_eq!(single, 1);
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
            IcpParams {
                coarse_voxel_factor: 0.5,
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
        // Both ways of estimating the target normals (the 3DTK scans have none).
        let block = IcpParams {
            normal_neighbourhood: NormalNeighbourhood::VoxelBlock,
            ..Default::default()
        };
        for (params, how) in [(IcpParams::default(), "nearest"), (block, "voxel block")] {
            for (s, t, reference) in pairs {
                for (k, dp) in perturbations.iter().enumerate() {
                    let initial = reference * *dp;
                    let res = refine(&scans[s], &scans[t], &initial, &params).unwrap();
                    let e = PoseError::between(&res.pose, &reference);
                    report(
                        &format!("3dtk {s:03} -> {t:03} start #{k} ({how})"),
                        &res,
                        &e,
                    );
                    assert!(res.converged);
                    assert!(e.dx_m.abs() < 0.05 && e.dy_m.abs() < 0.05, "{e:?}");
                    assert!(e.yaw_deg.abs() < 1.0, "{e:?}");
                    assert!(e.dz_m.abs() < 0.15, "{e:?}");
                    assert!(e.pitch_deg.abs() < 3.0 && e.roll_deg.abs() < 3.0, "{e:?}");
                }
            }
        }
    }
}
