//! The trust verdict of a registration: one documented rule over the evidence of the
//! search, the refinement and the agreement of the two scans, with every failed test said
//! in words ([`Registration::doubts`](super::Registration::doubts)).
//!
//! # The rule
//! A registration is **trusted** when all of these hold ([`TrustThresholds`] holds the
//! numbers):
//!
//! 1. **Overlap**: at least `min_overlap_fraction` of the scan's voxels coincide with the
//!    target's at the finest level.
//! 2. **Significance**: the overlap is `min_significance` standard deviations above what as
//!    many voxels dropped at random would give (thesis (5.4)-(5.5)). In man-made places this
//!    test alone is weak (floors, ceilings and walls at common heights make unrelated
//!    places overlap: the suite's unrelated pairs reach z = 30-150), so it never decides
//!    alone.
//! 3. **Uniqueness**: the best solution *distinct* from the best (beyond the refinement's
//!    reach: `ambiguity_distance` / `ambiguity_angle`, 1 m / 10° by default) scores at most
//!    `max_runner_up_ratio` of the best, and at most `max_ambiguity` clusters score within
//!    `keep_ratio` of it. A repeated room, a row of identical desks or a symmetric hall
//!    shows up as a runner-up of nearly the best score.
//! 4. **Refinement**: ICP converged, kept at least `min_inlier_fraction` of the points as
//!    inliers, and ended within `max_refine_shift_cells` cells of the search's pose.
//! 5. **Observability**: every searched degree of freedom is constrained by the surfaces: no
//!    eigen-direction of the point-to-plane information matrix that involves a searched axis
//!    is weaker than [`IcpParams::weak_fraction`](super::icp::IcpParams::weak_fraction) of
//!    the strongest (a corridor leaves its length free, a floor leaves x, y and heading
//!    free, two walls leave the height free).
//! 6. **Agreement**: where both scans looked, they agree: at least `min_agreement` of each
//!    scan's surface voxels that the other observed are supported by its surfaces rather
//!    than lying in its free space ([`super::consistency`]). A mirror image, an unrelated
//!    place or a wrong room leaves surfaces hanging in the other scan's open space.
//!
//! Tests 1-3 are checked first; a search that fails them is not refined (ICP cannot make
//! an ambiguous or barely overlapping match trustworthy, and skipping it saves the most
//! expensive part of every hopeless attempt).
//!
//! # Calibration
//! The thresholds were chosen on the trust suite ([`crate::sim::trust_cases`]: unrelated
//! places, identical rooms, rows of desks, corridors, symmetric halls, floors, two walls,
//! low overlap, pieces of scans, outliers, partial views; `olmap bench --trust`) and checked
//! against the real pairs of the shared data (3DTK, the outdoor car scans). See
//! [`TrustThresholds`] for each number and the measured false-positive rates.

use super::consistency::Consistency;
use super::icp::IcpResult;
use super::lattice::Alignment;
use super::params::Dof;

/// When a registration is trusted: the numbers of the rule in the [module
/// documentation](self). A result is trusted only if every test passes; the failed ones
/// are listed in [`super::Registration::doubts`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrustThresholds {
    /// Smallest overlap fraction at the finest search level (default 0.10). Correct matches
    /// of the real pairs overlap 22-37 %, unrelated real scenes 2-4 %.
    pub min_overlap_fraction: f64,
    /// Smallest significance z-score (default 10).
    pub min_significance: f64,
    /// Largest ambiguity (distinct solutions within `keep_ratio` of the best; default 1).
    pub max_ambiguity: usize,
    /// Largest score of the best distinct solution as a fraction of the best's (default
    /// 0.75).
    pub max_runner_up_ratio: f64,
    /// Smallest ICP inlier fraction (default 0.3).
    pub min_inlier_fraction: f64,
    /// Largest move of the refinement away from the search's pose, in finest cells
    /// (default 3): a larger move means the search's cell was not the refined optimum's.
    pub max_refine_shift_cells: f64,
    /// Smallest agreement of the two scans where both looked (default 0.8).
    pub min_agreement: f64,
}

impl Default for TrustThresholds {
    fn default() -> Self {
        TrustThresholds {
            min_overlap_fraction: 0.10,
            min_significance: 10.0,
            max_ambiguity: 1,
            max_runner_up_ratio: 0.75,
            min_inlier_fraction: 0.3,
            max_refine_shift_cells: 3.0,
            min_agreement: 0.8,
        }
    }
}

/// Doubts about a search alone (tests 1-3).
pub(super) fn search_doubts(search: &Alignment, t: &TrustThresholds) -> Vec<String> {
    let mut doubts = Vec::new();
    if search.overlap_fraction < t.min_overlap_fraction {
        doubts.push(format!(
            "only {:.1} % of the scan's voxels meet the target's (< {:.0} %)",
            100.0 * search.overlap_fraction,
            100.0 * t.min_overlap_fraction
        ));
    }
    if search.significance < t.min_significance {
        doubts.push(format!(
            "the overlap is not significant (z = {:.1} < {:.1})",
            search.significance, t.min_significance
        ));
    }
    if search.ambiguity > t.max_ambiguity {
        doubts.push(format!(
            "{} distinct solutions score within the keep ratio of the best",
            search.ambiguity
        ));
    }
    let ratio = search.runner_up_ratio();
    if ratio > t.max_runner_up_ratio && search.ambiguity <= t.max_ambiguity {
        if let Some(u) = &search.runner_up {
            let d = (u.pose.translation() - search.pose.translation()).norm();
            let a = u.pose.rotation().angle_to(&search.pose.rotation()).to_degrees();
            doubts.push(format!(
                "a distinct solution {d:.2} m and {a:.0}° away scores {:.0} % of the best \
                 (> {:.0} %): the place repeats or is symmetric",
                100.0 * ratio,
                100.0 * t.max_runner_up_ratio
            ));
        }
    }
    doubts
}

/// Doubts about the refinement (tests 4-5); `dof` says which axes were searched.
pub(super) fn refinement_doubts(
    search: &Alignment,
    r: &IcpResult,
    resolution: f64,
    dof: Dof,
    t: &TrustThresholds,
) -> Vec<String> {
    let mut doubts = Vec::new();
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
    let free = r.degeneracy.free_searched_axes(searched_axes(dof));
    if !free.is_empty() {
        doubts.push(format!(
            "the surfaces leave {} unconstrained (a corridor, a plane or too few walls)",
            free.join(" and ")
        ));
    }
    doubts
}

/// Doubts about the agreement of the two scans (test 6).
pub(super) fn agreement_doubts(c: &Consistency, t: &TrustThresholds) -> Vec<String> {
    let a = c.agreement();
    if a >= t.min_agreement {
        return Vec::new();
    }
    let (side, s) = match c.target {
        Some(ts) if ts.agreement() < c.source.agreement() => ("target's", ts),
        _ => ("scan's", c.source),
    };
    vec![format!(
        "the scans disagree where both looked: {:.0} % of the {side} observed surface lies where \
         the other saw through (agreement {a:.2} < {:.2})",
        100.0 * (1.0 - s.agreement()),
        t.min_agreement
    )]
}

/// Which of `(ωx, ωy, ωz, vx, vy, vz)` a search explores: roll, pitch, yaw, x, y, z.
pub(super) fn searched_axes(dof: Dof) -> [bool; 6] {
    match dof {
        Dof::XyYaw => [false, false, true, true, true, false],
        Dof::XyzYaw => [false, false, true, true, true, true],
        Dof::SixDof { .. } => [true; 6],
    }
}
