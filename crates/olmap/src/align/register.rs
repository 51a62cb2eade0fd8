//! Registration: the global search, the ICP refinement, and an honest verdict.

use std::time::Instant;

use super::icp::{refine, IcpParams, IcpResult};
use super::lattice::Alignment;
use super::search::global_search;
use super::target::SearchTarget;
use super::{levels_for_clouds, SearchParams};
use crate::cloud::PointCloud;
use crate::error::Result;
use crate::geometry::{Aabb, Pose};
use crate::occupancy::OccupancyList;

/// When a registration is trusted. A result is trusted only if every test passes; the
/// failed ones are listed in [`Registration::doubts`].
///
/// The defaults come from the shared real data (README of the data folder): correct
/// global matches of the 3DTK and car pairs overlap 22-37 % of the scan's voxels at the
/// finest level, unrelated scenes (car against 3DTK, OctoMap's scan.dat against 3DTK)
/// 2-4 %. Significance alone is not enough: a scan placed anywhere in a huge sparse map
/// (the outdoor car scene) scores z > 100 by chance because the search keeps the best of
/// hundreds of thousands of poses.
#[derive(Debug, Clone, PartialEq)]
pub struct TrustThresholds {
    /// Smallest overlap fraction at the finest search level (default 0.10).
    pub min_overlap_fraction: f64,
    /// Smallest significance z-score (default 10).
    pub min_significance: f64,
    /// Largest ambiguity (distinct solutions; default 1).
    pub max_ambiguity: usize,
    /// Smallest ICP inlier fraction (default 0.3).
    pub min_inlier_fraction: f64,
    /// Largest move of the refinement away from the search's pose, in finest cells
    /// (default 3): a larger move means the search's cell was not the refined optimum's.
    pub max_refine_shift_cells: f64,
}

impl Default for TrustThresholds {
    fn default() -> Self {
        TrustThresholds {
            min_overlap_fraction: 0.10,
            min_significance: 10.0,
            max_ambiguity: 1,
            min_inlier_fraction: 0.3,
            max_refine_shift_cells: 3.0,
        }
    }
}

/// Parameters of [`register`] and [`localize`]. The default refines with ICP.
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
    /// Whether every trust test passed.
    pub trusted: bool,
    /// The trust tests that failed, in words.
    pub doubts: Vec<String>,
    /// Wall time of the whole registration, seconds.
    pub seconds: f64,
}

fn verdict(
    search: &Alignment,
    refinement: Option<&IcpResult>,
    resolution: f64,
    t: &TrustThresholds,
) -> Vec<String> {
    let mut doubts = Vec::new();
    if search.overlap_fraction < t.min_overlap_fraction {
        doubts.push(format!(
            "overlap fraction {:.3} < {:.3}",
            search.overlap_fraction, t.min_overlap_fraction
        ));
    }
    if search.significance < t.min_significance {
        doubts.push(format!(
            "significance {:.1} < {:.1}",
            search.significance, t.min_significance
        ));
    }
    if search.ambiguity > t.max_ambiguity {
        doubts.push(format!(
            "{} distinct solutions score within the keep ratio of the best",
            search.ambiguity
        ));
    }
    if let Some(r) = refinement {
        if !r.converged {
            doubts.push("the refinement did not converge".into());
        }
        if r.inlier_fraction < t.min_inlier_fraction {
            doubts.push(format!(
                "refinement inlier fraction {:.3} < {:.3}",
                r.inlier_fraction, t.min_inlier_fraction
            ));
        }
        let shift = (r.pose.translation() - search.pose.translation()).norm();
        if shift > t.max_refine_shift_cells * resolution {
            doubts.push(format!(
                "the refinement moved {shift:.3} m from the search's pose (> {:.0} cells)",
                t.max_refine_shift_cells
            ));
        }
    }
    doubts
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
fn refinement_after_search(p: &IcpParams, resolution: f64) -> IcpParams {
    let mut p = p.clone();
    p.max_distance_start = p
        .max_distance_start
        .min((REFINE_REACH_CELLS * resolution).max(p.max_distance_end));
    p
}

fn finish(
    source: &PointCloud,
    refine_target: impl FnOnce() -> PointCloud,
    search: Alignment,
    resolution: f64,
    params: &RegisterParams,
    start: Instant,
) -> Result<Registration> {
    // A search that already fails its own tests is not refined: ICP cannot make an
    // ambiguous or barely overlapping match trustworthy, and skipping it saves the most
    // expensive part of every hopeless attempt (map building tries many).
    let search_doubts = verdict(&search, None, resolution, &params.trust);
    let refinement = match (
        &params.refine,
        search.overlap > 0 && search_doubts.is_empty(),
    ) {
        (Some(p), true) => Some(refine(
            source,
            &refine_target(),
            &search.pose,
            &refinement_after_search(p, resolution),
        )?),
        _ => None,
    };
    let pose = match &refinement {
        Some(r) if r.converged => r.pose,
        _ => search.pose,
    };
    let doubts = verdict(&search, refinement.as_ref(), resolution, &params.trust);
    Ok(Registration {
        pose,
        trusted: doubts.is_empty(),
        doubts,
        search,
        refinement,
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
    params.search.validate()?;
    let levels = levels_for_clouds(source, target, &params.search);
    let t = SearchTarget::from_cloud(target, params.search.resolution, levels)?;
    register_to(source, &t, target, params)
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
    let source = refine_source;
    let start = Instant::now();
    let search = global_search(search_source, target, &params.search)?;
    let res = target.pyramid().base().resolution();
    // Refine against the part of the target the source can reach from the search's pose
    // (a large map is mostly out of reach; ICP's cost grows with its target).
    let reach = params
        .refine
        .as_ref()
        .map_or(0.0, |p| refinement_after_search(p, res).max_distance_start);
    let crop = |pose: &Pose| {
        let b = source.transformed(pose).bounding_box()?;
        let m = nalgebra::Vector3::repeat(reach);
        Some(Aabb::new(b.min - m, b.max + m))
    };
    let reachable = crop(&search.pose);
    finish(
        source,
        || match reachable {
            Some(b) => refine_target.crop_box(&b),
            None => refine_target.clone(),
        },
        search,
        res,
        params,
        start,
    )
}

/// Localises a scan in a prior map: the search against the map (no free space is known
/// for a map file, so the score is the plain overlap), then ICP against the map's voxel
/// centres. The search's finest resolution is the map's.
pub fn localize(
    source: &PointCloud,
    map: &OccupancyList,
    params: &RegisterParams,
) -> Result<Registration> {
    let start = Instant::now();
    // The search runs at the map's resolution (the target's); the parameters say so too,
    // so that their check is of the value in use.
    let mut search_params = params.search.clone();
    search_params.resolution = map.resolution();
    search_params.validate()?;
    let extent = map
        .stats()
        .bbox
        .map_or(nalgebra::Vector3::zeros(), |b| b.extent());
    let levels = search_params.levels_for_source(map.resolution(), extent, source);
    let target = SearchTarget::from_map(map.clone(), levels)?;
    let search = global_search(source, &target, &search_params)?;
    finish(
        source,
        || map.to_cloud(),
        search,
        map.resolution(),
        params,
        start,
    )
}
