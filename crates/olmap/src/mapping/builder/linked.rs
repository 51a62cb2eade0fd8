//! Team mapping: searching a scan along the sightings that link it to placed scans
//! (thesis (6.2)-(6.4)), the link trust test, and holding back robots no link reaches yet.

use super::register::{keep_better, Found};
use super::state::State;
use crate::align::verify::{refutation, same_solution};
use crate::align::{consistency, Region, RegisterParams, Registration};
use crate::error::Result;
use crate::geometry::Pose;
use crate::mapping::links::{Placement, ScanLink};

/// Linked scans whose links are searched per scan and attempt (the strongest first).
const MAX_LINK_SEARCHES: usize = 2;

/// A trusted match of a sighting is looked at again in a window this many times as wide in
/// x and y as a two-way sighting's (`State::wider_look_vetoes`; ±1.2 m around the default
/// ±0.3 m).
pub const MUTUAL_CONFIRM_GROWTH: f64 = 4.0;

impl State<'_> {
    /// The links of scan `s` to placed scans: the strongest per linked scan (a mutual one
    /// subsumes the two loci), strongest first.
    pub(super) fn placed_links(&self, s: usize) -> Vec<ScanLink> {
        let mut links: Vec<ScanLink> = self.team.links[s]
            .iter()
            .filter(|l| self.poses[l.other()].is_some())
            .cloned()
            .collect();
        links.sort_by_key(|l| (l.other(), l.rank()));
        links.dedup_by_key(|l| l.other());
        links.sort_by_key(|l| (l.rank(), l.other()));
        links
    }

    /// Searches scan `s` along the first [`MAX_LINK_SEARCHES`] of `links`: the first
    /// trusted result, or `None` with the untrusted ones offered to `best`.
    pub(super) fn search_links(
        &self,
        s: usize,
        links: &[ScanLink],
        best: &mut Option<Found>,
    ) -> Result<Option<Found>> {
        // Whether this scan would join its robot to the map (the wider look and the
        // sighting-alone placement are for that scan only).
        let joining = !self.robot_placed(s);
        for link in links.iter().take(MAX_LINK_SEARCHES) {
            let other_pose = self.poses[link.other()].expect("filtered");
            let (region, prior) = link.region(&other_pose, &self.team);
            let mut params = self.params.register.clone();
            params.search.region = region;
            params.search.prior = prior;
            let mut r = self.run(s, &params)?;
            check_link(&mut r, &region, &prior, self.team.locus_slack);
            let via = Placement::Sighting {
                equation: link.equation(),
                other: link.other(),
            };
            // A sighting's window or locus is narrow: a match that joins its robot to the
            // map is looked at once more from farther out.
            let vetoed = r.trusted && joining && self.wider_look_vetoes(s, &params, &mut r)?;
            if r.trusted {
                return Ok(Some(Found {
                    registration: r,
                    via,
                }));
            }
            // The sighting alone places a scan only when it joins its robot to the map: a
            // placed robot's later scan has its odometry windows to try next, and the
            // sighting alone put one 0.5-1.0 m off where the sighting was that wrong (lab
            // seed 6) while odometry placed it right.
            if let (ScanLink::Mutual { other, .. }, false, true) = (link, vetoed, joining) {
                if let Some(alone) = self.mutual_alone(s, &prior, &r)? {
                    return Ok(Some(Found {
                        registration: alone,
                        via: Placement::MutualSighting { other: *other },
                    }));
                }
            }
            keep_better(best, r, via);
        }
        Ok(None)
    }

    /// Whether a search around a sighting's trusted match `r` finds a distinct pose that
    /// fits the map clearly better (its fit refutes `r`'s by the verdict's
    /// [`TrustThresholds::min_refutation`]) and agrees with it at least as well; if so `r`
    /// is distrusted, saying why. The search: for a two-way sighting, its window
    /// [`MUTUAL_CONFIRM_GROWTH`] times as wide in x and y (twice in heading); for a one-way
    /// sighting (a locus: a position or a circle), a window around the match as large as
    /// that (the two-way window's size from [`TeamLinks::mutual_window`]).
    ///
    /// Only for a scan that joins its robot to the map (none of its robot's scans placed
    /// yet): there the sighting is the only tie, and a wrong one puts the whole robot where
    /// it says. A later scan of a placed robot meets its own robot's scans in the map, which
    /// see most of what it sees: a pose a wrong sighting suggests leaves their surfaces in
    /// its open space and fails the agreement (lab seeds 1, 2, 6, a later scan's sighting
    /// moved 0.5 or 1.0 m: placed right by its odometry window). The look costs a window
    /// search: in the live map's benchmark (`olmap bench --net`) the publish→placement
    /// p95 was 0.35-0.42 s without it, 0.66-0.67 s with it for every sighting match, and
    /// 0.49-0.52 s with it for joining scans only.
    ///
    /// Why: the window or locus is the sighting's uncertainty (±0.3 m; 0.1 m off a locus),
    /// so nothing outside it competes with a match inside it. When the sighting is wrong
    /// by more (a failed sensor, a beacon mistaken for another), a look-alike near the
    /// wrong pose can be the best of the window, refined without a rival and trusted. In
    /// the simulated lab (seed 1, two robots) a two-way sighting shifted 1.0 m placed the
    /// scan 1.0 m off as a trusted match (overlap 13 %, agreement 0.894); the truth, 1 m
    /// away, fits the map better by 8σ. Seed 2, a one-way sighting (6.3) whose observed
    /// beacon was moved 0.5 m: placed 0.62 m off, trusted. A look-alike that fits about as
    /// well as the match (rows of desks) does not veto it: resolving that ambiguity is
    /// what the sighting is for. Not done for an untrusted match, before the sighting alone
    /// places the scan (`mutual_alone`): there the map is often ambiguous along a wall, and
    /// its best fit lies 0.3-0.5 m from a right sighting too (lab seed 1), so a wider look
    /// would refuse right sightings.
    ///
    /// [`TrustThresholds::min_refutation`]: crate::align::TrustThresholds::min_refutation
    /// [`TeamLinks::mutual_window`]: crate::mapping::TeamLinks::mutual_window
    fn wider_look_vetoes(
        &self,
        s: usize,
        params: &RegisterParams,
        r: &mut Registration,
    ) -> Result<bool> {
        // The window to widen and its centre: a two-way sighting's own; for a locus, the
        // two-way size around the match.
        let ((xy, z, yaw), centre, around) = match params.search.region {
            Region::Window { xy, z, yaw } => ((xy, z, yaw), params.search.prior, "two-way"),
            Region::Locus(_) => (self.team.mutual_window, r.pose, "one-way"),
            Region::Global => return Ok(false),
        };
        let mut wide = params.clone();
        wide.search.region = Region::Window {
            xy: MUTUAL_CONFIRM_GROWTH * xy,
            z,
            yaw: (2.0 * yaw).min(std::f64::consts::PI),
        };
        wide.search.prior = centre;
        let w = self.run(s, &wide)?;
        let (Some(wv), Some(rv)) = (&w.verification, &r.verification) else {
            return Ok(false);
        };
        let (won, ours) = (wv.winner(), rv.winner());
        let resolution = self.target.resolution();
        if same_solution(&won.pose(), &r.pose, resolution) {
            return Ok(false);
        }
        // A count that only grows with overlap does not veto: the better pose must also
        // agree with the map at least as well (a look-alike overlapping more of the map at
        // its edge can out-count a right match there).
        let margin = refutation(won, ours);
        if margin < params.trust.min_refutation
            || won.consistency.agreement() < ours.consistency.agreement()
        {
            return Ok(false);
        }
        let d = won.pose().translation() - r.pose.translation();
        r.trusted = false;
        r.doubts.push(format!(
            "a search {MUTUAL_CONFIRM_GROWTH:.0} times as wide around the {around} sighting \
             finds a pose {:.2} m from this match that fits the map better by {margin:.1}σ: \
             the sighting or the match is wrong",
            d.norm()
        ));
        Ok(true)
    }

    /// A two-way sighting's pose `prior` for scan `s` when its map search `r` (in the
    /// sighting's window) was not trusted: accepted as [`Placement::MutualSighting`] when
    /// the map does not contradict it there — the scan's surfaces at `prior` agree with
    /// the map where the map looked ([`consistency`], at least the trust rule's
    /// `min_agreement`; a scan the map never saw agrees) — and the search was not refused
    /// for a contradiction of its own. The result is `r` moved to `prior`, trusted, without
    /// doubts (they only said that the map could not confirm the sighting), with the
    /// agreement at `prior`.
    fn mutual_alone(
        &self,
        s: usize,
        prior: &Pose,
        r: &Registration,
    ) -> Result<Option<Registration>> {
        let trust = &self.params.register.trust;
        if r.consistency
            .as_ref()
            .is_some_and(|c| c.agreement() < trust.min_agreement)
        {
            return Ok(None);
        }
        let c = consistency(self.cloud(s), &self.target, None, prior)?;
        if c.agreement() < trust.min_agreement {
            return Ok(None);
        }
        let mut alone = r.clone();
        alone.pose = *prior;
        alone.trusted = true;
        alone.doubts.clear();
        alone.consistency = Some(c);
        Ok(Some(alone))
    }

    /// Whether scan `s` waits for a link ([`TeamLinks::hold_unlinked`]): no scan of its
    /// robot is placed and none of its links leads to a placed scan. Such a scan is never
    /// searched: a robot joins the map through a sighting only (a global match of a whole
    /// robot in a symmetric building can be a mirror image).
    ///
    /// [`TeamLinks::hold_unlinked`]: crate::mapping::TeamLinks::hold_unlinked
    pub(super) fn unlinked(&self, s: usize) -> bool {
        self.team.hold_unlinked
            && !self.robot_placed(s)
            && !self.team.links[s]
                .iter()
                .any(|l| self.poses[l.other()].is_some())
    }

    /// Whether a scan of scan `s`'s robot (its odometry frame) is placed.
    fn robot_placed(&self, s: usize) -> bool {
        (0..self.scans.len())
            .any(|i| self.poses[i].is_some() && self.team.frame[i] == self.team.frame[s])
    }
}

/// Distrusts a registration that a link's search let drift away from the link: more than
/// twice the slack plus 0.1 m from its locus (at the found heading), or out of a mutual
/// link's window (the pyramid's resampling can walk a pose a coarse cell past the start,
/// e.g. along a row of identical desks).
fn check_link(r: &mut Registration, region: &Region, prior: &Pose, slack: f64) {
    let p = r.pose.translation();
    let (off, limit) = match region {
        Region::Locus(l) => {
            let on = l.pose_at(r.pose.yaw_pitch_roll().0).translation();
            ((p.xy() - on.xy()).norm(), 2.0 * slack + 0.1)
        }
        Region::Window { xy, .. } => ((p.xy() - prior.translation().xy()).norm(), *xy),
        Region::Global => return,
    };
    if r.trusted && off > limit {
        r.trusted = false;
        r.doubts.push(format!(
            "the match is {off:.2} m from the sighting's constraint (limit {limit:.2} m)"
        ));
    }
}
