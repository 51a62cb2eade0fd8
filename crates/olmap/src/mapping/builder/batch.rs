//! The batch mapper of thesis §6.4.1 ([`super::MapMode::Batch`]): every round aligns the
//! remaining scans to the map and adds the best one, so scans that overlap the map little
//! wait until it has grown to them. Results whose map region did not change are reused.

use rayon::prelude::*;

use super::register::Found;
use super::state::{footprint, overlaps, State};
use super::{placed_record, Placing};
use crate::align::Registration;
use crate::error::Result;
use crate::geometry::Aabb;
use crate::mapping::links::Placement;
use crate::occupancy::OccupancyList;

/// How many stale scans the batch mapper retries before looking for a trusted result.
const RETRY_GROUP: usize = 4;

/// A batch mapper's cached registration: the result, what found it, and the scan's
/// footprint in the map at the result.
struct Candidate {
    /// The registration.
    registration: Registration,
    /// What found it.
    via: Placement,
    /// The scan's box in the map at the registration's pose.
    footprint: Option<Aabb>,
}

/// What the batch mapper knows about one scan not yet placed.
struct Pending {
    /// Its cached registration, if any.
    cached: Option<Candidate>,
    /// How many scans were placed when it was last tried (`usize::MAX` before its first
    /// round).
    attempted_at: usize,
    /// Whether odometry places it outside the map so far, or reaches back so far that it
    /// waits for a scan predicted over a shorter path ([`Batch::some_short`]).
    far: bool,
    /// Whether it was searched anyway once (the last resort).
    forced: bool,
    /// Whether its cached (trusted) score was refreshed at its pose after the map grew: it
    /// is confirmed by a window search before it joins.
    provisional: bool,
    /// The scan's voxels, for those refreshes.
    voxels: Option<OccupancyList>,
}

impl Pending {
    fn new() -> Self {
        Pending {
            cached: None,
            attempted_at: usize::MAX,
            far: false,
            forced: false,
            provisional: false,
            voxels: None,
        }
    }

    /// Whether its cached registration is trusted.
    fn trusted(&self) -> bool {
        self.cached.as_ref().is_some_and(|c| c.registration.trusted)
    }

    /// Drops its cached registration: it searches again next round.
    fn forget(&mut self) {
        self.cached = None;
        self.provisional = false;
    }
}

/// The batch mapper at work: the map state and every scan's [`Pending`] record.
struct Batch<'s, 'a> {
    state: &'s mut State<'a>,
    pending: Vec<Pending>,
}

/// Places scans best overlap first until every scan is placed or none can be trusted; the
/// doubts of the scans left over go to `placing`.
pub(super) fn place_best_first(
    state: &mut State<'_>,
    placing: &mut Placing,
    progress: &mut impl FnMut(usize, usize),
) -> Result<()> {
    let n = state.scans.len();
    let mut batch = Batch {
        state,
        pending: (0..n).map(|_| Pending::new()).collect(),
    };
    loop {
        let unplaced: Vec<usize> = (0..n).filter(|&s| batch.state.poses[s].is_none()).collect();
        if unplaced.is_empty() {
            break;
        }
        for &s in &unplaced {
            if batch.pending[s].attempted_at == usize::MAX {
                batch.pending[s].attempted_at = 0;
            }
        }
        let Some(s) = batch.choose(&unplaced, placing.placed.len())? else {
            for &u in &unplaced {
                placing.last_doubts[u] = batch.pending[u]
                    .cached
                    .as_ref()
                    .map(|c| c.registration.doubts.clone());
            }
            break;
        };
        let Some(chosen) = batch.confirm(s, placing.placed.len())? else {
            continue;
        };
        let r = &chosen.registration;
        batch.state.place(s, r.pose)?;
        let name = &batch.state.scans[s].name;
        let record = placed_record(s, name, placing.placed.len(), r, chosen.via);
        placing.placed.push(record);
        progress(placing.placed.len(), n);
        batch.after_placing(s, chosen.footprint.as_ref(), &unplaced)?;
    }
    Ok(())
}

/// [`State::register`] with the scan's footprint at the result: a cache entry.
fn attempt(state: &State<'_>, s: usize, allow_global: bool) -> Result<Candidate> {
    let Found { registration, via } = state.register(s, allow_global)?;
    let footprint = footprint(state.cloud(s), &registration.pose);
    Ok(Candidate {
        registration,
        via,
        footprint,
    })
}

impl Batch<'_, '_> {
    /// The unplaced scan whose cached result is the best trusted one (largest overlap
    /// fraction, then significance, then smallest index).
    fn best_trusted(&self, unplaced: &[usize]) -> Option<usize> {
        unplaced
            .iter()
            .filter_map(|&s| {
                self.pending[s]
                    .cached
                    .as_ref()
                    .filter(|c| c.registration.trusted)
                    .map(|c| (s, c))
            })
            .max_by(|a, b| {
                let (ra, rb) = (&a.1.registration.search, &b.1.registration.search);
                (ra.overlap_fraction, ra.significance)
                    .partial_cmp(&(rb.overlap_fraction, rb.significance))
                    .unwrap_or(std::cmp::Ordering::Equal)
                    .then(b.0.cmp(&a.0))
            })
            .map(|(s, _)| s)
    }

    /// Registers the scans `list` (except those odometry puts outside the map) and caches
    /// the results. The registrations are independent (each reads the map as it is), so
    /// they run in parallel; the results, and which error is returned, do not depend on the
    /// number of threads.
    fn try_scans(&mut self, list: &[usize], unplaced: &[usize], placed_now: usize) -> Result<()> {
        let mut search = Vec::with_capacity(list.len());
        let mut some_short = None;
        for &s in list {
            let far = self.state.far_from_map(s)
                || (self.long(s) && *some_short.get_or_insert_with(|| self.some_short(unplaced)));
            self.pending[s].far = far;
            self.pending[s].attempted_at = placed_now;
            if !far {
                search.push(s);
            }
        }
        self.attempt_all(&search, false)
    }

    /// Whether a scan with no placed sighting is predicted by odometry over so long a path
    /// ([`State::long_prediction`]) that its widest window would search a whole stretch of
    /// building.
    fn long(&self, s: usize) -> bool {
        self.state.placed_links(s).is_empty() && self.state.long_prediction(s).is_some()
    }

    /// Whether any scan of `unplaced` has an odometry prediction that is not
    /// [`Batch::long`]: while one has, the long ones wait and the map first grows along the
    /// robots' paths toward them. In a corridor the wide window finds a look-alike stretch:
    /// a simulated 72 m corridor ring with the thesis' degraded odometry had the middle of
    /// one long side trusted in the middle of the other, 13 m off, and 26 scans followed
    /// it. When every unplaced scan's path is long (input order far from capture order, as
    /// in a hall given in interleaved order) nothing waits, and the searches, verdict and
    /// rounds decide as before. Asked once per round's list (each answer costs a
    /// prediction per scan).
    fn some_short(&self, unplaced: &[usize]) -> bool {
        unplaced
            .iter()
            .any(|&t| self.state.predict(t).is_some() && !self.long(t))
    }

    /// [`attempt`] on every scan of `list` in parallel; each result replaces the scan's
    /// cached one (the first error, in `list` order, is returned after all ran).
    fn attempt_all(&mut self, list: &[usize], allow_global: bool) -> Result<()> {
        let state = &*self.state;
        if let (Some(icp), false) = (&state.params.register.refine, list.is_empty()) {
            state.prepared_map(icp)?;
        }
        let found: Vec<Result<Candidate>> = list
            .par_iter()
            .map(|&s| attempt(state, s, allow_global))
            .collect();
        let mut first_error = None;
        for (&s, f) in list.iter().zip(found) {
            match f {
                Ok(c) => self.pending[s].cached = Some(c),
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
        first_error.map_or(Ok(()), Err)
    }

    /// One round's choice, with `placed_now` scans placed: searches the scans without a
    /// cached result (a far one once per map size), then, when nothing is trusted, the
    /// stale scans ([`Batch::retry_stale`]) and then the far ones regardless of odometry.
    fn choose(&mut self, unplaced: &[usize], placed_now: usize) -> Result<Option<usize>> {
        let due: Vec<usize> = unplaced
            .iter()
            .copied()
            .filter(|&s| {
                let p = &self.pending[s];
                p.cached.is_none() && !(p.far && p.attempted_at == placed_now)
            })
            .collect();
        self.try_scans(&due, unplaced, placed_now)?;
        let mut best = self.best_trusted(unplaced);
        if best.is_none() {
            best = self.retry_stale(unplaced, placed_now)?;
        }
        if best.is_none() {
            // Last resort before giving up: odometry may be wrong, search anyway.
            let last_resort: Vec<usize> = unplaced
                .iter()
                .copied()
                .filter(|&s| {
                    let p = &self.pending[s];
                    p.far && !p.forced && !self.state.unlinked(s)
                })
                .collect();
            for &s in &last_resort {
                self.pending[s].forced = true;
                self.pending[s].far = false;
            }
            self.attempt_all(&last_resort, true)?;
            best = self.best_trusted(unplaced);
        }
        Ok(best)
    }

    /// Nothing trusted: retries every scan last tried against a smaller map (all of them:
    /// stopping at the first trusted one let a false match in the synthetic hall win over
    /// the true, better one). Input order is usually capture order, so scans next (by
    /// index) to placed ones go first, a few at a time, the best of a group winning: each
    /// retry round costs a few searches, not one per unplaced scan.
    fn retry_stale(&mut self, unplaced: &[usize], placed_now: usize) -> Result<Option<usize>> {
        let mut stale: Vec<usize> = unplaced
            .iter()
            .copied()
            .filter(|&s| self.pending[s].attempted_at < placed_now)
            .collect();
        let keys: Vec<(bool, f64)> = stale.iter().map(|&s| self.state.nearness(s)).collect();
        let mut by_key: Vec<(usize, (bool, f64))> = stale.iter().copied().zip(keys).collect();
        by_key.sort_by(|a, b| {
            (a.1 .0, a.1 .1, a.0)
                .partial_cmp(&(b.1 .0, b.1 .1, b.0))
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        stale = by_key.into_iter().map(|(s, _)| s).collect();
        let mut best = None;
        for group in stale.chunks(RETRY_GROUP) {
            self.try_scans(group, unplaced, placed_now)?;
            best = self.best_trusted(unplaced);
            if best.is_some() {
                break;
            }
        }
        Ok(best)
    }

    /// Takes the chosen scan's cached result (`placed_now` scans placed); a provisional one
    /// is confirmed by a window search first, a global match found against a smaller map by
    /// a global search, and one that fails goes back to the cache (`None`: choose again).
    fn confirm(&mut self, s: usize, placed_now: usize) -> Result<Option<Candidate>> {
        let c = self.pending[s]
            .cached
            .take()
            .expect("chosen from the cache");
        let provisional = std::mem::take(&mut self.pending[s].provisional);
        // A scan placed by a two-way sighting alone has nothing the map could confirm.
        if matches!(c.via, Placement::MutualSighting { .. }) {
            return Ok(Some(c));
        }
        // A global match is confirmed globally once the map has grown: the place where the
        // scan truly is may have been mapped since, anywhere, and a window round the cached
        // pose cannot see it (simulated office seed 1, robot 2 without odometry: scan003's
        // match against a smaller map was a look-alike 5.06 m away and turned 180°, which a
        // window confirmed after the map grew, while a global search against the grown
        // map finds the truth and trusts it).
        let checked =
            if matches!(c.via, Placement::Global) && self.pending[s].attempted_at < placed_now {
                self.pending[s].attempted_at = placed_now;
                attempt(self.state, s, true)?
            } else if provisional {
                let confirmed = self.state.register_near(s, c.registration.pose)?;
                Candidate {
                    footprint: footprint(self.state.cloud(s), &confirmed.pose),
                    registration: confirmed,
                    via: c.via,
                }
            } else {
                return Ok(Some(c));
            };
        if !checked.registration.trusted {
            self.pending[s].cached = Some(checked);
            return Ok(None);
        }
        Ok(Some(checked))
    }

    /// After scan `s` joined with footprint `fp`: the cached results its placing made
    /// stale are dropped or refreshed.
    fn after_placing(&mut self, s: usize, fp: Option<&Aabb>, unplaced: &[usize]) -> Result<()> {
        // Scans linked to this one and not yet trusted search along their new loci next
        // round.
        for &u in unplaced {
            let trusted = self.pending[u].trusted();
            if u != s && !trusted && self.state.team.links[u].iter().any(|l| l.other() == s) {
                self.pending[u].forget();
            }
        }
        // Scans of the same robot that now predict from this one (fewer moves, less drift)
        // search again around the better prediction: a result found around a prediction
        // many moves old can be a look-alike place metres away.
        for &u in unplaced {
            let by_odometry = self.pending[u]
                .cached
                .as_ref()
                .is_some_and(|c| c.via.linked_scan().is_none());
            if u != s && by_odometry && self.state.predicts_from(u) == Some(s) {
                self.pending[u].forget();
            }
        }
        // Trusted results whose map region changed get their score refreshed at their pose
        // (cheap) and are confirmed before joining; untrusted ones are retried only when
        // nothing trusted is left.
        for &u in unplaced {
            let touched = match (&self.pending[u].cached, fp) {
                (
                    Some(Candidate {
                        registration,
                        footprint: Some(fu),
                        ..
                    }),
                    Some(fs),
                ) => registration.trusted && overlaps(fu, fs),
                _ => false,
            };
            if touched {
                self.refresh(u)?;
            }
        }
        Ok(())
    }

    /// Refreshes scan `u`'s cached score at its pose against the map as it is now and marks
    /// the result provisional.
    fn refresh(&mut self, u: usize) -> Result<()> {
        let res = self.state.params.register.search.resolution;
        let pending = &mut self.pending[u];
        if pending.voxels.is_none() {
            pending.voxels = Some(OccupancyList::from_cloud(self.state.cloud(u), res)?);
        }
        let list = pending.voxels.as_ref().expect("just set");
        let entry = pending.cached.as_mut().expect("touched");
        entry.registration.search.overlap_fraction = self
            .state
            .overlap_fraction_at(list, &entry.registration.pose)?;
        pending.provisional = true;
        Ok(())
    }
}
