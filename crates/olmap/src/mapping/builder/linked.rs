//! Team mapping: searching a scan along the sightings that link it to placed scans
//! (thesis (6.2)-(6.4)), the link trust test, and holding back robots no link reaches yet.

use super::register::{keep_better, Found};
use super::state::State;
use crate::align::{consistency, Region, Registration};
use crate::error::Result;
use crate::geometry::Pose;
use crate::mapping::links::{Placement, ScanLink};

/// Linked scans whose links are searched per scan and attempt (the strongest first).
const MAX_LINK_SEARCHES: usize = 2;

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
            if r.trusted {
                return Ok(Some(Found {
                    registration: r,
                    via,
                }));
            }
            if let ScanLink::Mutual { other, .. } = link {
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
            && !(0..self.scans.len())
                .any(|i| self.poses[i].is_some() && self.team.frame[i] == self.team.frame[s])
            && !self.team.links[s]
                .iter()
                .any(|l| self.poses[l.other()].is_some())
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
