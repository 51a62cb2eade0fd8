//! Registration: the global search, the ICP refinement, and an honest verdict.

use std::borrow::Cow;
use std::time::Instant;

use super::consistency::Consistency;
use super::icp::{IcpParams, IcpResult, IcpTarget};
use super::lattice::{Alignment, Candidate};
use super::search::global_search;
use super::target::SearchTarget;
use super::verdict::{
    agreement_doubts, look_alike_doubts, map_surface_doubts, refinement_doubts, search_doubts,
    uniqueness_doubts, upright_look_doubts, window_doubts, TrustThresholds,
};
use super::verify::{
    starts, upright_look, upright_starts, upright_starts_after, verify, GlobalChecks, MapSurfaces,
    RefineAgainst, Verification,
};
use super::{levels_for_clouds, SearchParams};
use crate::cloud::PointCloud;
use crate::error::Result;
use crate::geometry::Pose;

/// Parameters of [`register`] and [`super::localize`]. The default refines with ICP.
#[derive(Debug, Clone)]
pub struct RegisterParams {
    /// The global search.
    pub search: SearchParams,
    /// The refinement; `None` skips it.
    pub refine: Option<IcpParams>,
    /// The trust tests.
    pub trust: TrustThresholds,
}

impl Default for RegisterParams {
    fn default() -> Self {
        RegisterParams {
            search: SearchParams::default(),
            refine: Some(IcpParams::default()),
            trust: TrustThresholds::default(),
        }
    }
}

/// The outcome of a registration.
#[derive(Debug, Clone)]
pub struct Registration {
    /// The final `T_target_source` (refined when refinement ran and converged).
    pub pose: Pose,
    /// The global search's result.
    pub search: Alignment,
    /// The refinement's result.
    pub refinement: Option<IcpResult>,
    /// How the two scans agree where both looked, at the refined pose (computed when the
    /// refinement ran; see [`super::consistency`]).
    pub consistency: Option<Consistency>,
    /// The search's best and strongest rivals, refined and scored ([`super::verify`]);
    /// `None` when the search failed its own tests or refinement is off.
    pub verification: Option<Verification>,
    /// Whether every trust test passed (the rule: [`super::verdict`]).
    pub trusted: bool,
    /// The trust tests that failed, in words.
    pub doubts: Vec<String>,
    /// Wall time of the whole registration, seconds: from the call to its answer, the
    /// search target's preparation included for [`register`] and [`super::localize`] (not
    /// for the functions given a prepared target, nor for [`super::Localizer::localize`]).
    pub seconds: f64,
}

/// How far, in finest search cells, the refinement after a search looks for
/// correspondences at first: ICP's starting distance is capped at this many cells (but not
/// below its final distance). The search's pose is within about a cell of the overlap
/// optimum; a wider first gate lets structure the target lacks pull a correct match into
/// another minimum. In the simulated lab a scan overlapping the map by 30 % was found by
/// the search to 0.09°, then moved 0.21 m and 2.4° along a row of desks by ICP starting at
/// 2 m; starting at 0.5 m it ended 6 mm from the truth.
pub const REFINE_REACH_CELLS: f64 = 5.0;

/// The refinement parameters after a search at `resolution`: the starting distance capped
/// at [`REFINE_REACH_CELLS`] cells.
pub(super) fn refinement_after_search(p: &IcpParams, resolution: f64) -> IcpParams {
    let mut p = p.clone();
    p.max_distance_start = p
        .max_distance_start
        .min((REFINE_REACH_CELLS * resolution).max(p.max_distance_end));
    p
}

/// What the refinement and the agreement check work against: the prepared target (its
/// finest level and free space) and its points (cropped around each hypothesis).
pub(super) struct Against<'a> {
    pub(super) target: &'a SearchTarget,
    /// Made only when a hypothesis is refined (a map's voxel centres cost a pass).
    pub(super) points: &'a dyn Fn() -> Cow<'a, PointCloud>,
    /// The points already prepared for ICP, when the caller keeps them.
    pub(super) prepared: Option<&'a IcpTarget>,
    /// The surface of a map's points for the agreement counts, prepared with the map
    /// (`None`: the points are not a map's voxel centres).
    pub(super) surfaces: Option<&'a MapSurfaces>,
    /// Whether `target` is a map with the free space its scans saw through (a global
    /// match then also passes [`super::verdict::map_surface_doubts`]).
    pub(super) map_free_space: bool,
}

pub(super) fn finish(
    source: &PointCloud,
    against: Against<'_>,
    search: Alignment,
    extra: &dyn Fn(&Alignment) -> Result<Vec<Candidate>>,
    params: &RegisterParams,
    start: Instant,
    on_edge: OnWindowEdge,
) -> Result<Registration> {
    let resolution = against.target.resolution();
    // A search that already fails its own tests is not refined: ICP cannot make a barely
    // overlapping match trustworthy, and skipping it saves the most expensive part of
    // every hopeless attempt (map building tries many).
    let mut doubts = search_doubts(&search, &params.trust);
    // Without a refinement nothing is skipped (and the verdict has no window test).
    if let (OnWindowEdge::Widen { inner }, true, true) =
        (on_edge, doubts.is_empty(), params.refine.is_some())
    {
        // Only when every hypothesis the verification would refine starts there: then the
        // verdict would doubt whichever won (its start on the edge), or only a refinement
        // moving farther than the search's cell (which the verdict holds to a closer
        // agreement) could reach the inner part.
        // (The first start is the search's best.)
        let shift = params.trust.max_refine_shift_cells * resolution;
        let best = widen_doubts(&search.pose, &params.search, inner, shift);
        let outside = |p: &Pose| !widen_doubts(p, &params.search, inner, shift).is_empty();
        if !best.is_empty() && starts(&search).iter().skip(1).all(|c| outside(&c.pose)) {
            doubts.extend(best);
        }
    }
    let verification = match (&params.refine, search.overlap > 0 && doubts.is_empty()) {
        (Some(p), true) => {
            let icp = refinement_after_search(p, resolution);
            let reach = icp.max_distance_start;
            let points = (against.points)();
            let extra = extra(&search)?;
            Some(verify(
                source,
                against.target,
                RefineAgainst {
                    points: &points,
                    prepared: against.prepared,
                    surfaces: against.surfaces,
                },
                &search,
                &extra,
                &icp,
                reach,
                match params.search.region {
                    super::Region::Window { .. } => {
                        Some((&params.search.prior, params.search.ambiguity_distance))
                    }
                    _ => None,
                },
                matches!(params.search.region, super::Region::Global).then_some(GlobalChecks {
                    min_agreement: params.trust.min_agreement,
                    min_refutation: params.trust.min_refutation,
                    map_free_space: against.map_free_space,
                }),
            )?)
        }
        _ => None,
    };
    let (pose, refinement, consistency) = match &verification {
        Some(v) => {
            let w = v.winner();
            let global = matches!(params.search.region, super::Region::Global);
            doubts.extend(uniqueness_doubts(v, &params.trust, global));
            if global && against.map_free_space {
                doubts.extend(map_surface_doubts(v, &params.trust));
            }
            doubts.extend(look_alike_doubts(v, global));
            doubts.extend(refinement_doubts(
                &w.start,
                &w.refinement,
                w.consistency.agreement(),
                resolution,
                params.search.dof,
                &params.trust,
            ));
            doubts.extend(agreement_doubts(
                &w.consistency,
                &params.trust,
                against.map_free_space,
            ));
            doubts.extend(upright_look_doubts(w, &params.trust));
            let mut edge = window_doubts(&w.start.pose, &params.search);
            let moved = (w.pose().translation() - w.start.pose.translation()).norm();
            if edge.is_empty() && moved > params.trust.max_refine_shift_cells * resolution {
                // A refinement that moved farther than the search's cell may have left the
                // window the search kept to.
                edge = window_doubts(&w.pose(), &params.search);
            }
            doubts.extend(edge);
            (w.pose(), Some(w.refinement.clone()), Some(w.consistency))
        }
        None => (search.pose, None, None),
    };
    Ok(Registration {
        pose,
        trusted: doubts.is_empty(),
        doubts,
        search,
        refinement,
        consistency,
        verification,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Registers `source` onto `target` with no initial guess (unless `params.search` sets a
/// window around a prior): the multi-resolution search, then point-to-plane ICP on the
/// points, then the trust tests. Returns `T_target_source` and the evidence.
///
/// Same input, same output, bit for bit, whatever the number of threads.
pub fn register(
    source: &PointCloud,
    target: &PointCloud,
    params: &RegisterParams,
) -> Result<Registration> {
    let start = Instant::now();
    params.search.validate()?;
    let levels = levels_for_clouds(source, target, &params.search);
    let t = SearchTarget::from_cloud(target, params.search.resolution, levels)?;
    let mut r = register_looking_beside(source, &t, target, params)?;
    // The whole registration, the target's preparation included.
    r.seconds = start.elapsed().as_secs_f64();
    Ok(r)
}

/// [`register_to`] with the upright look's search ([`upright_look`]) run beside the first
/// search when more than one thread is free and a refinement will verify its poses: the
/// first search's coarse levels leave a core idle, and the look would otherwise run after
/// it. The same starts as [`upright_starts`] takes, so the same result (a look whose first
/// search fails its own tests is wasted: a one-shot registration is not a mapper's many
/// hopeless tries).
fn register_looking_beside(
    source: &PointCloud,
    target: &SearchTarget,
    refine_target: &PointCloud,
    params: &RegisterParams,
) -> Result<Registration> {
    if params.refine.is_none() || rayon::current_num_threads() < 2 {
        return register_to(source, target, refine_target, params);
    }
    let start = Instant::now();
    let (search, look) = rayon::join(
        || global_search(source, target, &params.search),
        || upright_look(source, target, &params.search),
    );
    let (search, look) = (search?, look?);
    finish(
        source,
        Against {
            target,
            points: &|| Cow::Borrowed(refine_target),
            prepared: None,
            surfaces: None,
            map_free_space: false,
        },
        search,
        &|s: &Alignment| {
            Ok(look
                .as_ref()
                .map_or_else(Vec::new, |l| upright_starts_after(l, &params.search, s)))
        },
        params,
        start,
        OnWindowEdge::Refine,
    )
}

/// [`register`] against a prepared search target (e.g. a growing map), refining against
/// `refine_target` (points in the target frame).
pub fn register_to(
    source: &PointCloud,
    target: &SearchTarget,
    refine_target: &PointCloud,
    params: &RegisterParams,
) -> Result<Registration> {
    register_to_split(source, source, target, refine_target, params)
}

/// [`register_to`] searching with `search_source` and refining with `refine_source` (the
/// same scan, e.g. cut to a height band for the search, whole for ICP, where the floor
/// and ceiling fix the height the band leaves free).
pub fn register_to_split(
    search_source: &PointCloud,
    refine_source: &PointCloud,
    target: &SearchTarget,
    refine_target: &PointCloud,
    params: &RegisterParams,
) -> Result<Registration> {
    register_to_prepared(
        search_source,
        refine_source,
        target,
        refine_target,
        None,
        params,
    )
}

/// What a registration in a [`super::Region::Window`] does when the search's best pose lies
/// on the window's edge (the optimum may lie outside it).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum OnWindowEdge {
    /// Refine and verify as usual; the verdict doubts a winner that started on the edge.
    #[default]
    Refine,
    /// Skip the refinement and the verification when the search's best pose lies on the
    /// window's edge, or so far from the prior in x or y that no refinement moving it by at
    /// most [`super::TrustThresholds::max_refine_shift_cells`] could bring it within
    /// `inner` times the window's half-width (`inner` = 1: the edge alone): the result is
    /// the search's, untrusted, with the reason as its doubt. For a caller that searches a
    /// wider window next and trusts only a match in the inner part of a window (the
    /// mapper's growing odometry windows): refining a pose it will search again is the
    /// most expensive part of the attempt. Without a refinement (`refine: None`) it is
    /// [`OnWindowEdge::Refine`].
    Widen {
        /// The inner part of the window, as a fraction of its half-width in x and y.
        inner: f64,
    },
}

/// The doubt of [`OnWindowEdge::Widen`] about a hypothesis starting at `pose`, if any;
/// `shift` is the largest refinement move the verdict accepts, metres.
fn widen_doubts(pose: &Pose, params: &SearchParams, inner: f64, shift: f64) -> Vec<String> {
    let mut doubts = window_doubts(pose, params);
    if let (true, super::Region::Window { xy, .. }) = (doubts.is_empty(), params.region) {
        let d = pose.translation() - params.prior.translation();
        let reach = inner * xy + shift;
        if d.x.abs() > reach || d.y.abs() > reach {
            doubts.push(format!(
                "the search's best pose lies outside the inner {:.0} % of the window by more \
                 than a refinement may move it ({:+.2}, {:+.2} m from the prior; window \
                 ±{xy:.2} m): a wider window searches there",
                100.0 * inner,
                d.x,
                d.y
            ));
        }
    }
    doubts
}

/// [`register_to_split`] with the refinement's target points already prepared for ICP
/// when `prepared` is given (made from `refine_target` with `params.refine`'s target
/// parameters): what a mapper that registers many scans against one map keeps between
/// registrations. A target prepared with other parameters is not used (the points are
/// prepared again). Without one, ICP runs on the target points near the hypotheses (the
/// search's poses widened by the refinement's reach); with one, on all the points it was
/// prepared from: the two agree wherever a correspondence can reach, and may differ by
/// normals at the crop's edge.
pub fn register_to_prepared(
    search_source: &PointCloud,
    refine_source: &PointCloud,
    target: &SearchTarget,
    refine_target: &PointCloud,
    prepared: Option<&IcpTarget>,
    params: &RegisterParams,
) -> Result<Registration> {
    register_to_prepared_or_widen(
        search_source,
        refine_source,
        target,
        refine_target,
        prepared,
        params,
        OnWindowEdge::Refine,
    )
}

/// [`register_to_prepared`], saying what to do when a window search's best pose lies on
/// the window's edge ([`OnWindowEdge`]).
pub fn register_to_prepared_or_widen(
    search_source: &PointCloud,
    refine_source: &PointCloud,
    target: &SearchTarget,
    refine_target: &PointCloud,
    prepared: Option<&IcpTarget>,
    params: &RegisterParams,
    on_edge: OnWindowEdge,
) -> Result<Registration> {
    register_preparing(
        search_source,
        refine_source,
        target,
        refine_target,
        &|| Ok(prepared),
        params,
        on_edge,
    )
}

/// [`register_to_prepared_or_widen`] with the refinement's prepared target made by
/// `prepare` while the search runs (a mapper whose map just grew builds its k-d tree, on
/// one thread, beside the search).
pub(crate) fn register_preparing<'p>(
    search_source: &PointCloud,
    refine_source: &PointCloud,
    target: &SearchTarget,
    refine_target: &PointCloud,
    prepare: &(dyn Fn() -> Result<Option<&'p IcpTarget>> + Sync),
    params: &RegisterParams,
    on_edge: OnWindowEdge,
) -> Result<Registration> {
    let start = Instant::now();
    let (search, prepared) = rayon::join(
        || global_search(search_source, target, &params.search),
        prepare,
    );
    let (search, prepared) = (search?, prepared?);
    finish(
        refine_source,
        Against {
            target,
            points: &|| Cow::Borrowed(refine_target),
            prepared,
            surfaces: None,
            map_free_space: false,
        },
        search,
        &|s: &Alignment| upright_starts(search_source, target, &params.search, s),
        params,
        start,
        on_edge,
    )
}
