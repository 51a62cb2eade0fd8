//! The trust verdict of a registration: one documented rule over the evidence of the
//! search, the hypothesis verification, the refinement and the agreement of the two scans,
//! with every failed test said in words
//! ([`Registration::doubts`](super::Registration::doubts)).
//!
//! # The rule
//! A registration is **trusted** when all of these hold ([`TrustThresholds`] holds the
//! numbers):
//!
//! 1. **Overlap**: at least `min_overlap_fraction` of the scan's voxels coincide with the
//!    target's at the search's pose (finest level).
//! 2. **Significance**: the overlap is `min_significance` standard deviations above what as
//!    many voxels dropped at random would give (thesis (5.4)-(5.5)). In man-made places this
//!    test alone is weak: floors, ceilings and walls at common heights make unrelated
//!    places overlap, and the trust suite's unrelated pairs reach z = 30-150, so its
//!    false-positive rate on its own is high (see the closing numbers in
//!    [`TrustThresholds`]); it never decides alone.
//! 3. **Uniqueness**, measured on the refined hypotheses ([`super::verify`]): the search's
//!    best and its strongest distinct rivals (other cluster heads, the best solution
//!    farther than `ambiguity_distance` / `ambiguity_angle`, carried through every level:
//!    [`super::Alignment::runner_up`]) are each refined; rivals the refinement brings into
//!    an earlier one's basin (3 cells or 3°) are the same answer and dropped. The one that
//!    fits best wins, and every remaining distinct rival must be **refuted**: its fit
//!    (supported voxels, minus contradicted ones, a surface of one scan where the other
//!    saw through, weighted 8) must fall short of the winner's by at least
//!    `min_refutation` standard deviations of a count
//!    ([`super::verify::Verification::refutation`]). A repeated room, a row of identical
//!    desks or a symmetric hall gives a rival that fits as well as the winner and is not
//!    refuted; an answer whose rival the free space rules out is unique. Nor may a
//!    distinct rival that the scans support at least half as well
//!    ([`super::verify::CLEANER_MIN_SUPPORT`]) be contradicted by `min_refutation`
//!    standard deviations *less* than the winner
//!    ([`super::verify::Verification::cleaner_rival`]; global searches only): the fit
//!    trades one contradiction for eight supports, and along a corridor a look-alike that
//!    overlaps more can win on support while standing hundreds of voxels in the other
//!    scan's free space. The other way round, such a rival must be contradicted by at
//!    least `min_refutation` standard deviations *more* than the winner: one the scans
//!    do not contradict is ruled out only by overlapping less, which along a corridor or
//!    among repeated rooms says where more of the scans overlap, not where the robot was
//!    (simulated office without odometry: a corridor scan trusted 5.2 m along it, its
//!    rival as clean at 0.73 of its support). On the trust suite (seeds 4, 7, 11, 13) the
//!    test refused 3 trusted-wrong answers (unrelated places and opposite corridors, rivals
//!    from 2.6 σ cleaner to 4.0 σ dirtier) and one right answer to a pair with one right
//!    answer (a scan against one from the same place, whose rival 6.2 m away and turned
//!    180° contradicted nothing at 0.77 of its support), besides right answers in scenes
//!    that repeat.
//!
//!    A global search in a place that repeats many times over (the aisles of a warehouse)
//!    can have dozens of distinct near-best poses ([`super::Alignment::ambiguity`]) with the
//!    truth anywhere among them: each of its listed poses that no refined hypothesis
//!    reached is counted where the search put it, and refined beside the others when that
//!    count could beat the winner ([`super::verify::Origin::Screened`]); a search with more
//!    such poses than it lists (32: [`super::Alignment::candidates`])
//!    is doubted outright.
//!
//!    The search's own score gap (best over best distinct, [`super::Alignment::runner_up_ratio`])
//!    and the spread of near-best poses ([`super::Alignment::spread`]) are reported but not
//!    tested: on the trust suite the right answers of furnished rooms have search rivals
//!    at 63-99 % of the best score, which the refined free-space test tells apart.
//! 4. **Refinement**: ICP converged, kept at least `min_inlier_fraction` of the points as
//!    inliers, and ended within `max_refine_shift_cells` cells of the search's pose, or,
//!    farther, at a pose where the scans agree at `min_upright_agreement`. The search scores
//!    voxel overlap on a lattice, and where things repeat along a corridor its best can lie
//!    0.4-1 m from the optimum ICP reaches from a nearby start (simulated corridor ring,
//!    thesis-degraded odometry: the search's best 1 m off at agreement 0.896, the refined
//!    pose 1 cm from the truth at 0.999, the search's lattice scoring it 2.4 % below its
//!    best): a refined pose the search did not propose is a second look, held to the same
//!    closer agreement as the upright look's (test 6), and in a window it must not have
//!    left the window (test 7).
//! 5. **Observability**: every searched degree of freedom is constrained by the surfaces: no
//!    eigen-direction of the point-to-plane information matrix that involves a searched axis
//!    is weaker than [`IcpParams::weak_fraction`](super::icp::IcpParams::weak_fraction) of
//!    the strongest (a corridor leaves its length free, a floor leaves x, y and heading
//!    free, two walls leave the height free); the free axes are named.
//! 6. **Agreement**: where both scans looked, they agree: at least `min_agreement` of each
//!    scan's surface voxels that the other observed are supported by its surfaces rather
//!    than lying in its free space ([`super::consistency`]). A mirror image, an unrelated
//!    place or a wrong room leaves surfaces hanging in the other scan's open space.
//!    Nor may *both* scans leave more than `max_two_sided_disagreement` of their observed
//!    surface in the other's free space in patches larger than a thing that moves (a
//!    person, a chair, a door): a door, glass or a stray edge leaves one scan's structure
//!    there, a wrong pose both (two rooms laid over each other).
//!    A winner that only the upright look found ([`super::verify::Origin::UprightLook`]: the
//!    search again with floors and ceilings thinned, whose best poses are verified beside
//!    the search's own) must agree at `min_upright_agreement`: a second look at other
//!    evidence is a second chance for a look-alike, and on the trust suite (seeds 4, 7,
//!    11) the look's right answers agreed at 0.995-1.00 and its wrong ones (unrelated
//!    places, pairs overlapping 5-10 %, a symmetric hall) at 0.85-0.95. So must a winner
//!    that only the screening of many look-alikes refined ([`super::verify::Origin::Screened`]):
//!    in the warehouse such a winner 151 m from the truth (turned 180°) beat the other
//!    look-alikes by 8 σ and agreed at 0.962, while the right answers there agreed at
//!    0.997-0.998; the more look-alikes are refined, the better the best wrong one fits
//!    by chance.
//! 7. **Window edge**: in a window search the chosen pose is not on the window's edge (the
//!    optimum may lie outside; the mapper widens the window).
//!
//! Tests 1-3 (the search's part) are checked first; a search that fails them is not
//! refined (ICP cannot make an ambiguous or barely overlapping match trustworthy, and
//! skipping it saves the most expensive part of every hopeless attempt).
//!
//! # Calibration
//! The thresholds were chosen on the trust suite ([`crate::sim::trust_cases`]: unrelated
//! places, identical rooms, rows of desks, corridors, symmetric halls, floors, two walls,
//! low overlap, pieces of scans, outliers, partial views; `olmap bench --trust`) with
//! seeds 1-3 and checked on held-out seeds and on the real pairs of the shared data (3DTK,
//! the outdoor car scans, unrelated real scenes, a mirrored 3DTK scan).

use super::consistency::Consistency;
use super::icp::IcpResult;
use super::lattice::{Alignment, Candidate};
use super::params::{Dof, Region, SearchParams};
use super::verify::{Hypothesis, Origin, Verification};
use crate::geometry::Pose;

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
    /// Smallest refutation of the distinct runner-up, in standard deviations of the fit gap
    /// to the winner (default 4; see
    /// [`super::verify::Verification::refutation`]); in a global search also the margin,
    /// in standard deviations of the contradicted counts, by which a rival supported at
    /// least half as well must be contradicted less (it then doubts the winner) or more
    /// (else it does too) than the winner (rule item 3).
    pub min_refutation: f64,
    /// Smallest ICP inlier fraction (default 0.4: the real pairs keep 0.62-0.85, right
    /// matches of scans with half their points random outliers 0.46-0.52).
    pub min_inlier_fraction: f64,
    /// Largest move of the refinement away from the search's pose, in finest cells
    /// (default 3): a larger move means the search's cell was not the refined optimum's,
    /// trusted only where the scans agree at `min_upright_agreement` (rule item 4).
    pub max_refine_shift_cells: f64,
    /// Smallest agreement of the two scans where both looked (default 0.85: the real pairs
    /// agree at 0.89-1.00 on both sides, a mirror image of a 3DTK scan at 0.81).
    pub min_agreement: f64,
    /// Smallest agreement of a winner found only by the upright look, or refined farther
    /// than `max_refine_shift_cells` from its start (default 0.97; rule items 6 and 4).
    /// The real pairs are found by the search itself; one that needed the look and agreed
    /// at 0.89-0.97 would be reported, untrusted.
    pub min_upright_agreement: f64,
    /// Largest share of each scan's observed surface that may lie where the other saw
    /// through, in patches larger than a thing that moves
    /// ([`super::consistency::SideAgreement::fixed_contradicted`]: wider than
    /// [`super::consistency::MOVABLE_WIDTH`] or taller than
    /// [`super::consistency::MOVABLE_HEIGHT`]), when *both* scans have such patches
    /// (default 0.03; rule item 6). A door, glass or a scanner's stray edges put structure
    /// of one scan in the other's free space, seldom of both: the right real pairs (3DTK
    /// both ways, the car) leave at most 1.4 % on their cleaner side counting every
    /// contradicted voxel, 3-11 % on the other; right simulated pairs at most 1.0 % (half
    /// their points random outliers). A wrong pose that lays two rooms over each other
    /// leaves both scans' walls in the other's open space (trust suite seed 1: two
    /// unrelated rooms' corners, 6.1 % and 4.8 % in large patches). People who walked
    /// about leave person-sized patches on both sides (3-6 people a scan: 3.5-11 %), which
    /// do not count (counting them, 4 of 6 right pairs with 4 people a scan were refused;
    /// not counting them, a symmetric hall's near twin at 3.4 % is no longer). Not applied against a map that keeps its free space: many scans' rays
    /// make it, and a right real match leaves up to 2.9 % there (3DTK scan 2 in a 0.05 m
    /// `.bt` of scan 1).
    pub max_two_sided_disagreement: f64,
}

impl Default for TrustThresholds {
    fn default() -> Self {
        TrustThresholds {
            min_overlap_fraction: 0.10,
            min_significance: 10.0,
            min_refutation: 4.0,
            min_inlier_fraction: 0.4,
            max_refine_shift_cells: 3.0,
            min_agreement: 0.85,
            min_upright_agreement: 0.97,
            max_two_sided_disagreement: 0.03,
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
    doubts
}

/// Doubts about the uniqueness of the verified winner (test 3): a distinct rival that
/// the scans do not refute.
/// The cleaner-rival test applies to searches over every pose only (`global`): in a window
/// or a sighting's locus the prior already rules out far look-alikes.
pub(super) fn uniqueness_doubts(
    v: &Verification,
    t: &TrustThresholds,
    global: bool,
) -> Vec<String> {
    let mut doubts = Vec::new();
    let apart = |i: usize| {
        let (best, rival) = (v.winner().pose(), v.hypotheses[i].pose());
        let d = (rival.translation() - best.translation()).norm();
        (d, rival.rotation().angle_to(&best.rotation()).to_degrees())
    };
    if let Some(i) = v.runner_up {
        let z = v.refutation();
        if z < t.min_refutation {
            let (d, a) = apart(i);
            let (fw, fr) = (v.winner().fit, v.hypotheses[i].fit);
            doubts.push(format!(
                "a distinct solution {d:.2} m and {a:.0}° away fits nearly as well (fit {fr:.0} \
                 against {fw:.0}; gap {z:.1} < {:.1} σ): the place repeats or is symmetric",
                t.min_refutation
            ));
        }
    }
    if let Some((i, z)) = v.cleaner_rival().filter(|_| global) {
        let (d, a) = apart(i);
        let (cw, cr) = (v.winner().contradicted(), v.hypotheses[i].contradicted());
        if z >= t.min_refutation {
            doubts.push(format!(
                "a distinct solution {d:.2} m and {a:.0}° away leaves far fewer surfaces where \
                 the other scan saw through ({cr} against {cw} voxels; {z:.1} ≥ {:.1} σ): the \
                 match may lay a look-alike place over the true one",
                t.min_refutation
            ));
        } else if z > -t.min_refutation {
            doubts.push(format!(
                "a distinct solution {d:.2} m and {a:.0}° away, supported at least half as \
                 well, is contradicted hardly more than the winner ({cr} against {cw} \
                 surface voxels where the other scan saw through: {:+.1} σ, under +{:.1} \
                 σ): nothing in the scans rules it out, only how much of them overlaps (a \
                 corridor or a place that repeats)",
                -z, t.min_refutation
            ));
        }
    }
    doubts
}

/// Doubts about a global match in a map that keeps its free space (test 3 on the map's
/// surfaces): a distinct rival the map's surfaces alone do not refute by
/// `min_refutation` ([`super::verify::surface_refutation`]).
///
/// The map's free space refutes look-alikes that lay the scan's surfaces where the map's
/// scans saw through, and among look-alikes the surfaces cannot tell apart it leaves the
/// one it contradicts least. When the scan's own place is not in the map (a robot beyond
/// the mapped part, a map built by other robots) that one is a look-alike too, and fits as
/// cleanly as a right answer: in the demo lab (4 robots x 10 stops, seeds 1, 3, 4), each
/// robot's scans localised globally in a map of the other robots' scans at their team
/// poses were trusted 15-24 m and 90-180° off 8 times in 94 (agreement 0.87-0.99: such a
/// place repeats the scan's to the desk), where the map without its free space doubted
/// all 8 (a distinct solution fitting nearly as well). So a global match is trusted only
/// where the map's surfaces single it out, as in a map without free space (whose search
/// ranks the look-alikes: [`super::Localizer::localize`]); the free space then refuses
/// what it contradicts (a window that leaves out the true pose, a look-alike the surfaces
/// prefer). The same 94: trusted 42 -> 20, wrong 8 -> 1 (the map without free space: 12
/// trusted, none wrong).
pub(super) fn map_surface_doubts(v: &Verification, t: &TrustThresholds) -> Vec<String> {
    let w = v.winner();
    let least = v
        .rivals
        .iter()
        .map(|&i| (i, super::verify::surface_refutation(w, &v.hypotheses[i])))
        .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    let Some((i, z)) = least.filter(|(_, z)| *z < t.min_refutation) else {
        return Vec::new();
    };
    let (best, rival) = (w.pose(), v.hypotheses[i].pose());
    let d = (rival.translation() - best.translation()).norm();
    let a = rival.rotation().angle_to(&best.rotation()).to_degrees();
    vec![format!(
        "a distinct solution {d:.2} m and {a:.0}° away fits the map's surfaces nearly as well \
         (gap {z:.1} < {:.1} σ without the map's free space): only where the map saw through \
         tells them apart, and a scan of a place the map does not hold matches a look-alike \
         that way",
        t.min_refutation
    )]
}

/// Doubts about a global search with more distinct near-best poses than its verification
/// could examine (test 3): the heads beyond the search's list
/// ([`super::verify::Unverified::unlisted`]) were neither refined nor screened, and in a
/// place that repeats that often the truth may be among them.
pub(super) fn look_alike_doubts(v: &Verification, global: bool) -> Vec<String> {
    let u = v.unverified;
    if !global || u.unlisted == 0 {
        return Vec::new();
    }
    vec![format!(
        "the search found at least {} distinct poses scoring near its best, {} more than \
         the verification examines: the place repeats too often to tell which is right",
        u.heads, u.unlisted
    )]
}

/// Doubts about the refinement (tests 4-5); `agreement` is the scans' at the refined pose,
/// `dof` says which axes were searched.
pub(super) fn refinement_doubts(
    start: &Candidate,
    r: &IcpResult,
    agreement: f64,
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
    let shift = (r.pose.translation() - start.pose.translation()).norm();
    if shift > t.max_refine_shift_cells * resolution && agreement < t.min_upright_agreement {
        doubts.push(format!(
            "the refinement moved {shift:.3} m from the search's pose (> {:.0} cells), and \
             the scans agree there at {agreement:.3} < {:.2}: a pose the search did not \
             propose needs a closer agreement",
            t.max_refine_shift_cells, t.min_upright_agreement
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
/// `map_free_space`: the target is a map that keeps its free space (its free space is many
/// scans' rays, OctoMap's clamped log-odds: the two-sided part is not applied).
pub(super) fn agreement_doubts(
    c: &Consistency,
    t: &TrustThresholds,
    map_free_space: bool,
) -> Vec<String> {
    let a = c.agreement();
    if a >= t.min_agreement {
        return match map_free_space {
            true => Vec::new(),
            false => two_sided_doubts(c, t).into_iter().collect(),
        };
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

/// The doubt of test 6's two-sided part: both scans leave more than
/// `max_two_sided_disagreement` of their observed surface where the other saw through
/// (`None` when either side is cleaner, or only one side was counted).
fn two_sided_doubts(c: &Consistency, t: &TrustThresholds) -> Option<String> {
    let target = c.target?;
    let (ds, dt) = (c.source.fixed_disagreement(), target.fixed_disagreement());
    (ds.min(dt) > t.max_two_sided_disagreement).then(|| {
        format!(
            "both scans leave structure where the other saw through ({:.1} % of the scan's \
             observed surface, {:.1} % of the target's, in patches larger than a thing that \
             moves; both > {:.1} %): people, doors or glass leave one scan's surfaces in the \
             other's open space, a wrong pose both scans' walls",
            100.0 * ds,
            100.0 * dt,
            100.0 * t.max_two_sided_disagreement
        )
    })
}

/// Doubts about a winner found only by the upright look or a look-alike screening (test 6,
/// its stricter part).
pub(super) fn upright_look_doubts(w: &Hypothesis, t: &TrustThresholds) -> Vec<String> {
    let a = w.consistency.agreement();
    if a >= t.min_upright_agreement {
        return Vec::new();
    }
    let found = match w.origin {
        Origin::UprightLook => {
            "only the search on upright structure (floors thinned) found this pose"
        }
        Origin::Screened => {
            "this pose was one of many near-best look-alikes of the search, refined only after \
             a screening"
        }
        _ => return Vec::new(),
    };
    vec![format!(
        "{found}, and the scans agree there at {a:.3} < {:.2}: a second look needs a closer \
         agreement (a look-alike place agrees at 0.85-0.97)",
        t.min_upright_agreement
    )]
}

/// How far inside a window's edge, in finest cells, the search's pose must lie in x and y.
pub const WINDOW_EDGE_CELLS: f64 = 1.0;

/// Which of `(ωx, ωy, ωz, vx, vy, vz)` a search explores: roll, pitch, yaw, x, y, z.
pub(super) fn searched_axes(dof: Dof) -> [bool; 6] {
    match dof {
        Dof::XyYaw => [false, false, true, true, true, false],
        Dof::XyzYaw => [false, false, true, true, true, true],
        Dof::SixDof { .. } => [true; 6],
    }
}

/// Doubts about where the chosen pose lies in a window search (test 7). A pose on or near
/// the window's edge may be the best of the window only because the optimum lies outside
/// it (the odometry drifted farther than the window allows), and the refinement then only
/// reaches the truncated slope of that optimum. So in x and y the search's pose must lie
/// at least [`WINDOW_EDGE_CELLS`] finest cells (at most half the window) inside the
/// window; in z and heading it must not be the window's first or last lattice pose. The
/// caller widens the window. `start` is the chosen hypothesis' search pose (a lattice
/// pose). A look-alike inside the window while the truth lies outside is not an edge
/// case: the uniqueness test sees it only if the truth's peak reaches into the window,
/// which is why the mapper's windows grow before it trusts a match near an edge.
pub(super) fn window_doubts(start: &Pose, params: &SearchParams) -> Vec<String> {
    let Region::Window { xy, z, yaw } = params.region else {
        return Vec::new();
    };
    // The window's lattice runs from `-half` to the first step at or past `+half` (see
    // the lattice's bounds): its first and last poses are the edge.
    let eps_t = 0.01 * params.resolution;
    // Within `margin` of the edge (a pose exactly one cell inside is not on it).
    let on_edge = |d: f64, half: f64, margin: f64| half > 0.0 && d.abs() >= half - margin;
    let margin_xy = (WINDOW_EDGE_CELLS * params.resolution)
        .min(0.5 * xy)
        .max(2.0 * eps_t)
        - eps_t;
    let d = start.translation() - params.prior.translation();
    let mut edges = Vec::new();
    for (name, v) in [("x", d.x), ("y", d.y)] {
        if on_edge(v, xy, margin_xy) {
            edges.push(format!("{name} {v:+.2} m"));
        }
    }
    if !matches!(params.dof, Dof::XyYaw) && on_edge(d.z, z, eps_t) {
        edges.push(format!("z {:+.2} m", d.z));
    }
    if yaw < std::f64::consts::PI {
        let (y0, _, _) = params.prior.yaw_pitch_roll();
        let (y1, _, _) = start.yaw_pitch_roll();
        let dy = (y1 - y0 + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        if on_edge(dy, yaw, 1e-6) {
            edges.push(format!("heading {:+.1}°", dy.to_degrees()));
        }
    }
    if edges.is_empty() {
        return Vec::new();
    }
    vec![format!(
        "the best pose lies on or within {margin_xy:.2} m of the edge of the search window \
         ({} from the prior; window ±{xy:.2} m, ±{:.0}°): the optimum may lie outside it",
        edges.join(", "),
        yaw.to_degrees()
    )]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::align::verify::Unverified;

    /// A verification with no hypothesis refined: only its look-alike counts matter here.
    fn verification(unverified: Unverified) -> Verification {
        Verification {
            hypotheses: Vec::new(),
            chosen: 0,
            runner_up: None,
            rivals: Vec::new(),
            unverified,
        }
    }

    /// A global search with heads it did not list is doubted, saying how many; one whose
    /// every head was listed (screened or refined) is not, nor a window search (its prior
    /// rules out far look-alikes).
    #[test]
    fn a_global_match_among_more_look_alikes_than_listed_is_doubted() {
        let many = verification(Unverified {
            heads: 40,
            listed: 3,
            unlisted: 8,
        });
        let doubts = look_alike_doubts(&many, true);
        assert_eq!(doubts.len(), 1);
        assert!(doubts[0].contains("40 distinct poses") && doubts[0].contains("8 more"));
        assert!(look_alike_doubts(&many, false).is_empty());
        let listed = verification(Unverified {
            heads: 29,
            listed: 25,
            unlisted: 0,
        });
        assert!(look_alike_doubts(&listed, true).is_empty());
    }

    /// A refined hypothesis at `x` metres whose two scans' sides count `supported` and
    /// `contradicted` voxels.
    fn counted(x: f64, supported: u64, contradicted: u64) -> Hypothesis {
        let pose = Pose::from_xyz_ypr(x, 0.0, 0.0, 0.0, 0.0, 0.0);
        let start = Candidate {
            pose,
            overlap: 100,
            score: 100,
        };
        crate::align::verify::counted_hypothesis(start, pose, supported, contradicted)
    }

    /// The winner at 0 and one distinct rival 3.2 m along.
    fn against(winner: Hypothesis, rival: Hypothesis) -> Verification {
        Verification {
            hypotheses: vec![winner, rival],
            chosen: 0,
            runner_up: Some(1),
            rivals: vec![1],
            unverified: Unverified::default(),
        }
    }

    /// A global match with a distinct rival supported at least half as well and not
    /// contradicted `min_refutation` σ more is doubted, though the fit refutes the rival
    /// (the simulated office seed 4, robot 3: a corridor scan trusted 5.2 m along it,
    /// winner and rival 4 contradicted voxels each); a rival contradicted that much more,
    /// one supported less than half as well, or a window search is not.
    #[test]
    fn a_rival_as_clean_as_the_winner_is_refuted_only_by_its_contradictions() {
        let t = TrustThresholds::default();
        let says = |v: &Verification, global: bool| {
            uniqueness_doubts(v, &t, global)
                .iter()
                .any(|d| d.contains("hardly more"))
        };
        let clean = against(counted(0.0, 13_765, 4), counted(3.2, 10_087, 4));
        assert!(
            clean.refutation() >= t.min_refutation,
            "the fit alone refutes it"
        );
        assert!(says(&clean, true));
        assert!(!says(&clean, false));
        // (4 − 160) / sqrt(165) = −12 σ: the rival's contradictions refute it.
        let dirty = against(counted(0.0, 13_765, 4), counted(3.2, 10_087, 160));
        assert!(!says(&dirty, true));
        let thin = against(counted(0.0, 13_765, 4), counted(3.2, 6_000, 0));
        assert!(!says(&thin, true));
    }

    /// `counted` with its sides apart: the scan's voxels against the map (`source`: its
    /// supported and contradicted, the latter where the map saw through) and the map's
    /// against the scan's free space (`target`).
    fn sided(x: f64, source: (u64, u64), target: (u64, u64)) -> Hypothesis {
        let mut h = counted(x, source.0, source.1);
        h.consistency.target = Some(crate::align::consistency::SideAgreement {
            supported: target.0,
            contradicted: target.1,
            ..Default::default()
        });
        h.fit = crate::align::verify::fit(&h.consistency);
        h
    }

    /// In a map with free space a global match needs the map's surfaces to single it out:
    /// a look-alike the surfaces fit as well, refuted only by its voxels in the map's
    /// free space, doubts the winner (the demo lab: a scan of a place the map did not hold
    /// trusted 16.6 m off on the look-alike the free space contradicted least); a rival the
    /// surfaces refute too does not.
    #[test]
    fn a_global_match_in_a_map_with_free_space_needs_its_surfaces_to_single_it_out() {
        let t = TrustThresholds::default();
        let winner = || sided(0.0, (10_000, 150), (9_000, 10));
        let look_alike = against(winner(), sided(9.1, (10_200, 900), (9_100, 12)));
        assert!(
            look_alike.refutation() >= t.min_refutation,
            "free space refutes it"
        );
        assert!(uniqueness_doubts(&look_alike, &t, true).is_empty());
        let doubts = map_surface_doubts(&look_alike, &t);
        assert_eq!(doubts.len(), 1);
        assert!(doubts[0].contains("9.10 m") && doubts[0].contains("map's surfaces"));
        let refuted = against(winner(), sided(9.1, (6_000, 900), (5_000, 300)));
        assert!(map_surface_doubts(&refuted, &t).is_empty());
    }

    /// A refinement that ended 5 cells from its search start is doubted for the move only
    /// where the scans agree below `min_upright_agreement`; one within 3 cells never is.
    #[test]
    fn a_far_refinement_is_doubted_only_below_the_closer_agreement() {
        let t = TrustThresholds::default();
        let start = Candidate {
            pose: Pose::identity(),
            overlap: 100,
            score: 200,
        };
        let at = |x: f64| IcpResult::at(Pose::from_xyz_ypr(x, 0.0, 0.0, 0.0, 0.0, 0.0), true);
        let moved = |r: &IcpResult, agreement: f64| {
            refinement_doubts(&start, r, agreement, 0.1, Dof::XyzYaw, &t)
                .iter()
                .any(|d| d.contains("moved"))
        };
        assert!(moved(&at(0.5), 0.969));
        assert!(!moved(&at(0.5), t.min_upright_agreement));
        assert!(!moved(&at(0.25), 0.5));
    }
    /// Structure in the other scan's open space on one side only (what moved between two
    /// scans, glass) is not doubted as long as the agreement holds, nor are patches the
    /// size of a person or a door on both sides (people who walked about); structure on
    /// both sides above `max_two_sided_disagreement` is (two rooms laid over each other,
    /// the trust suite's unrelated pair: 6.1 % and 4.8 %), except against a map that keeps
    /// its free space (many scans' rays). The numbers are counts of real and simulated
    /// pairs.
    #[test]
    fn structure_in_the_other_scan_s_open_space_on_both_sides_is_doubted() {
        use crate::align::consistency::{Consistency, SideAgreement};
        let t = TrustThresholds::default();
        // Supported and contradicted voxels, half the supported ones upright, every
        // contradicted one upright, `fixed` of them in patches larger than a thing that moves.
        let side = |supported: u64, contradicted: u64, fixed: u64| SideAgreement {
            supported,
            contradicted,
            upright_supported: supported / 2,
            upright_contradicted: contradicted,
            fixed_contradicted: fixed,
            upright_fixed_contradicted: fixed,
        };
        let counted = |s: SideAgreement, target: Option<SideAgreement>| Consistency {
            source: s,
            target,
            resolution: 0.1,
        };
        // 3DTK 002->000: 11 % of the scan's upright surface (a 2 x 2.4 m patch among
        // others), 0.3 % of the target's.
        let one_sided = counted(side(8_522, 525, 459), Some(side(4_772, 7, 0)));
        assert!(one_sided.agreement() >= t.min_agreement);
        assert!(agreement_doubts(&one_sided, &t, false).is_empty());
        // Trust suite seed 1, unrelated pair 6: a floor-to-ceiling strip and a 3 m wall.
        let both = counted(side(6_888, 223, 223), Some(side(9_018, 364, 232)));
        assert!(both.agreement() >= t.min_agreement);
        let doubts = agreement_doubts(&both, &t, false);
        assert_eq!(doubts.len(), 1, "{doubts:?}");
        assert!(doubts[0].starts_with("both scans leave structure"));
        assert!(agreement_doubts(&both, &t, true).is_empty());
        // People who walked about in both scans: as much seen through, in person-sized
        // patches.
        let people = counted(side(6_888, 223, 0), Some(side(9_018, 364, 0)));
        assert!(agreement_doubts(&people, &t, false).is_empty());
        // Without the target's side (a map without points) there is no second side.
        assert!(agreement_doubts(&counted(side(6_888, 223, 223), None), &t, false).is_empty());
    }
}
