//! The incremental mapper: scans are given one at a time (as a robot or a live team
//! delivers them), each is placed against the map as it is then, scans that cannot be
//! placed yet wait and are retried when the map has grown, and the pose graph can make the
//! placed poses consistent at any time.

use std::borrow::Cow;

use super::sequential::try_place;
use super::state::State;
use super::{
    frame_record, fuse, rejected_scan, MapBuild, MapParams, PlacedScan, Placing, RejectedScan,
    ScanInput,
};
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::mapping::links::{ScanLink, TeamLinks};
use crate::mapping::posegraph::{refine_placed, GraphRefineParams, GraphRefinement};
use crate::occupancy::OccupancyList;

/// What became of a scan given to [`IncrementalMapper::add_scan`].
#[derive(Debug, Clone, PartialEq)]
pub enum ScanOutcome {
    /// It joined the map.
    Placed(PlacedScan),
    /// It is held: nothing placed it yet (the reasons say why). It is retried by
    /// [`IncrementalMapper::retry_waiting`] once the map has grown or it gained a link.
    Waiting(RejectedScan),
}

/// A map built a scan at a time (online use of the thesis' mapper): each scan
/// given is registered against the map as it is (along its sightings first, then in
/// odometry windows that grow, globally only when it has neither), joins the map when the
/// registration is trusted, and otherwise waits. The first scan given defines the map
/// frame.
///
/// Scans are placed in the order they arrive, so the result depends on that order (not on
/// the number of threads); [`super::build_map`] in batch mode (best overlap first) is the
/// offline answer for the same scans.
///
/// ```
/// use olmap::mapping::{IncrementalMapper, MapParams, ScanOutcome};
/// use olmap::sim::{simulate, SimConfig, WorldKind};
///
/// let config = SimConfig { world: WorldKind::Lab, robots: 1, stops: 2, ..Default::default() };
/// let robot = simulate(&config, |_, _| {}).unwrap().robots.remove(0);
/// let mut mapper = IncrementalMapper::new(MapParams::default()).unwrap();
/// for scan in robot.scan_inputs() {
///     let outcome = mapper.add_scan(scan).unwrap();
///     assert!(matches!(outcome, ScanOutcome::Placed(_)), "{outcome:?}");
/// }
/// // The second scan where the simulator put it, in the first scan's frame.
/// let truth = robot.truth[0].inverse() * robot.truth[1];
/// let placed = mapper.pose(1).unwrap();
/// assert!((placed.translation() - truth.translation()).norm() < 0.1);
/// ```
pub struct IncrementalMapper {
    /// The parameters (`first` unused: the first scan given is the frame).
    params: MapParams,
    /// The team's settings (beacon mount, slack, windows, holding unlinked robots).
    settings: TeamLinks,
    /// The map and the scans, from the first scan on.
    state: Option<State<'static>>,
    placing: Placing,
    /// How many scans were placed when each scan was last tried (`None`: never, or its
    /// links changed since).
    attempted_at: Vec<Option<usize>>,
    /// Failed attempts of each scan since it last gained a link (spaces its retries).
    failures: Vec<usize>,
    /// The fused map of the first `fused_count` placed scans.
    fused: Option<OccupancyList>,
    fused_count: usize,
}

impl IncrementalMapper {
    /// A mapper for one robot: every scan in one odometry frame, no sightings.
    pub fn new(params: MapParams) -> Result<Self> {
        Self::with_team(params, TeamLinks::none(0))
    }

    /// A mapper for a team: `settings` gives the beacon mount, locus slack, mutual window
    /// and whether robots join only through sightings ([`TeamLinks::hold_unlinked`]); its
    /// `frame` and `links` must be empty (each scan brings its own, see
    /// [`IncrementalMapper::add_linked_scan`]).
    pub fn with_team(params: MapParams, settings: TeamLinks) -> Result<Self> {
        params.validate()?;
        if !settings.frame.is_empty() || !settings.links.is_empty() {
            return Err(Error::InvalidArgument(
                "an incremental mapper starts with no scans: the team settings must have no \
                 frames or links"
                    .into(),
            ));
        }
        Ok(IncrementalMapper {
            params: MapParams { first: 0, ..params },
            settings,
            state: None,
            placing: Placing {
                placed: Vec::new(),
                last_doubts: Vec::new(),
            },
            attempted_at: Vec::new(),
            failures: Vec::new(),
            fused: None,
            fused_count: 0,
        })
    }

    /// Adds a scan of the single robot ([`IncrementalMapper::add_linked_scan`] in frame 0
    /// without links, its capture order the order given).
    pub fn add_scan(&mut self, scan: ScanInput) -> Result<ScanOutcome> {
        let capture = self.attempted_at.len() as u64;
        self.add_linked_scan(scan, 0, capture, Vec::new())
    }

    /// Adds a scan taken in odometry frame `frame` (one per robot), `capture`-th in its
    /// frame (e.g. the robot's scan number: scans may arrive out of order; odometry
    /// predicts a scan from the placed scan of its frame nearest in capture order), with
    /// `links`: sightings tying it to scans given before (by their index, the order they
    /// were given; each link's reverse is added to the other scan, which is then retried).
    /// Places it when its registration is trusted; the first scan given defines the map
    /// frame. A scan with an odometry prediction or a link is never searched globally (a
    /// look-alike place can win a global search); one with neither is, unless its robot
    /// waits for a sighting. Nor is one whose odometry path back to the nearest placed
    /// scan of its robot is over 8 m (with the default windows) searched in a window that
    /// wide: it waits for a nearer scan to be placed.
    ///
    /// Once this returns `Ok`, the mapper holds the scan (placed or waiting; a registration
    /// that fails, e.g. on coordinates past the map's key range, leaves it waiting with the
    /// error as its reason). An `Err` means it was not taken: a link to a scan not given,
    /// or a first scan that cannot frame a map.
    pub fn add_linked_scan(
        &mut self,
        scan: ScanInput,
        frame: usize,
        capture: u64,
        links: Vec<ScanLink>,
    ) -> Result<ScanOutcome> {
        let n = self.attempted_at.len();
        if let Some(l) = links.iter().find(|l| l.other() >= n) {
            return Err(Error::InvalidArgument(format!(
                "scan {}: a link points at scan {}, but only {n} scans were given before",
                scan.name,
                l.other()
            )));
        }
        let Some(state) = self.state.as_mut() else {
            return self.start(scan, frame, links);
        };
        for l in &links {
            self.attempted_at[l.other()] = None;
            self.failures[l.other()] = 0;
        }
        let s = state.push_scan(scan, frame, capture, links);
        self.placing.last_doubts.push(None);
        self.attempted_at.push(None);
        self.failures.push(0);
        self.attempt_or_doubt(s);
        Ok(self.outcome(s))
    }

    /// The first scan: it defines the map frame and sizes the search pyramid. Nothing is
    /// kept when it fails.
    fn start(
        &mut self,
        scan: ScanInput,
        frame: usize,
        links: Vec<ScanLink>,
    ) -> Result<ScanOutcome> {
        let mut team = self.settings.clone();
        team.frame.push(frame);
        team.links.push(links);
        let mut state = State::new(
            Cow::Owned(vec![scan]),
            Cow::Owned(self.params.clone()),
            Cow::Owned(team),
        )?;
        // Scans arrive one at a time, each waiting for the last: the odometry windows
        // start where each robot's recent odometry errors say the truth lies.
        state.learn_odometry_errors();
        state.place(0, Pose::identity())?;
        self.placing
            .placed
            .push(frame_record(0, &state.scans[0].name));
        self.placing.last_doubts.push(None);
        self.attempted_at.push(Some(0));
        self.failures.push(0);
        self.state = Some(state);
        Ok(self.outcome(0))
    }

    /// [`Self::attempt`], an error becoming the scan's doubt (it stays waiting, and is
    /// retried only once the map has grown: see [`Self::due`]).
    fn attempt_or_doubt(&mut self, s: usize) -> bool {
        match self.attempt(s) {
            Ok(placed) => placed,
            Err(e) => {
                self.placing.last_doubts[s] = Some(vec![format!("registration failed: {e}")]);
                false
            }
        }
    }

    /// One attempt to place unplaced scan `s`, remembered in [`Self::attempted_at`]. When
    /// it is placed, the waiting scans linked to it are due again.
    fn attempt(&mut self, s: usize) -> Result<bool> {
        let state = self.state.as_mut().expect("started");
        self.attempted_at[s] = Some(self.placing.placed.len());
        self.failures[s] += 1;
        if state.unlinked(s) {
            self.placing.last_doubts[s] = Some(vec![format!(
                "no sighting ties {}'s robot to the map yet",
                state.scans[s].name
            )]);
            return Ok(false);
        }
        // A scan with a placed sighting is searched along it even when its odometry says
        // it lies outside the map (degraded odometry can say so wrongly).
        let linked = !state.placed_links(s).is_empty();
        if !linked && state.far_from_map(s) {
            self.placing.last_doubts[s] =
                Some(vec!["odometry puts it outside the map so far".to_string()]);
            return Ok(false);
        }
        // Nor does it search a window as wide as a long odometry path's tolerance: without
        // a global search to compare with, a look-alike in that window would be trusted.
        // It waits for a scan nearer in capture order to be placed (or for a link).
        if let Some(path) = (!linked).then(|| state.long_prediction(s)).flatten() {
            self.placing.last_doubts[s] = Some(vec![format!(
                "its odometry reaches back {path:.1} m to the nearest placed scan of its \
                 robot: too far to search without look-alikes; it waits for a nearer one"
            )]);
            return Ok(false);
        }
        let global = !linked && state.predict(s).is_none();
        let placed = try_place(state, &mut self.placing, s, global)?;
        if placed {
            self.attempted_at[s] = Some(self.placing.placed.len());
            for l in &state.team.links[s] {
                if state.poses[l.other()].is_none() {
                    self.attempted_at[l.other()] = None;
                    self.failures[l.other()] = 0;
                }
            }
        }
        Ok(placed)
    }

    /// The outcome of scan `s` as it stands.
    fn outcome(&self, s: usize) -> ScanOutcome {
        match self.placing.placed.iter().rev().find(|p| p.index == s) {
            Some(p) => ScanOutcome::Placed(p.clone()),
            None => ScanOutcome::Waiting(self.rejected(s)),
        }
    }

    fn rejected(&self, s: usize) -> RejectedScan {
        let state = self.state.as_ref().expect("started");
        rejected_scan(s, &state.scans[s].name, &self.placing.last_doubts[s])
    }

    /// Retries up to `max` waiting scans that may place now (see [`Self::due`]), those
    /// nearest the map first; returns the ones placed. Call it when no new scan is queued:
    /// each retry costs a registration. A registration that fails leaves the scan waiting
    /// with the error as its reason.
    pub fn retry_waiting(&mut self, max: usize) -> Result<Vec<PlacedScan>> {
        let Some(state) = self.state.as_ref() else {
            return Ok(Vec::new());
        };
        let mut due: Vec<(usize, (bool, f64))> = (0..state.scans.len())
            .filter(|&s| self.due(state, s))
            .map(|s| (s, state.nearness(s)))
            .collect();
        due.sort_by(|a, b| {
            a.1.partial_cmp(&b.1)
                .unwrap_or(std::cmp::Ordering::Equal)
                .then(a.0.cmp(&b.0))
        });
        let mut placed = Vec::new();
        for (s, _) in due.into_iter().take(max) {
            if self.attempt_or_doubt(s) {
                placed.push(self.placing.placed.last().expect("just placed").clone());
            }
        }
        Ok(placed)
    }

    /// Whether some waiting scan would be retried by [`IncrementalMapper::retry_waiting`].
    pub fn has_due(&self) -> bool {
        let Some(state) = self.state.as_ref() else {
            return false;
        };
        (0..state.scans.len()).any(|s| self.due(state, s))
    }

    /// Whether waiting scan `s` is worth another attempt: it gained a link, or a scan
    /// linked to it was placed, since its last one; or odometry predicts it from a placed
    /// scan (window searches) and the map grew since by as many scans as it failed
    /// attempts (a scan that keeps failing is retried less and less often); or the map at
    /// least doubled since (a scan with neither a prediction nor a new link is searched
    /// along its links or globally: costly, so retried a logarithmic number of times).
    fn due(&self, state: &State<'static>, s: usize) -> bool {
        if state.poses[s].is_some() {
            return false;
        }
        let now = self.placing.placed.len();
        match self.attempted_at[s] {
            None => true,
            Some(a) if state.predicts_from(s).is_some() => now >= a + self.failures[s].max(1),
            Some(a) => now >= 2 * a.max(1),
        }
    }

    /// The scans given so far, in the order given (their indices).
    pub fn scans(&self) -> &[ScanInput] {
        self.state.as_ref().map_or(&[], |s| &s.scans)
    }

    /// `T_map_scan` of scan `s` once placed.
    pub fn pose(&self, s: usize) -> Option<Pose> {
        self.state.as_ref()?.poses.get(s).copied().flatten()
    }

    /// The placed scans in joining order (poses as placed, or as the last
    /// [`IncrementalMapper::optimise`] left them).
    pub fn placements(&self) -> &[PlacedScan] {
        &self.placing.placed
    }

    /// The scans waiting, with why.
    pub fn waiting(&self) -> Vec<RejectedScan> {
        let Some(state) = self.state.as_ref() else {
            return Vec::new();
        };
        (0..state.scans.len())
            .filter(|&s| state.poses[s].is_none())
            .map(|s| self.rejected(s))
            .collect()
    }

    /// Registrations run so far.
    pub fn registrations(&self) -> usize {
        self.state.as_ref().map_or(0, |s| {
            s.registrations.load(std::sync::atomic::Ordering::Relaxed)
        })
    }

    /// The fused map of the placed scans (ray traced at their poses with the sensor model;
    /// scans placed since the last call are fused now). No position buckets or count
    /// cleaning: [`IncrementalMapper::into_build`] applies those.
    pub fn map(&mut self) -> Result<&OccupancyList> {
        if self.fused.is_none() {
            self.fused = Some(OccupancyList::new(self.params.register.search.resolution)?);
        }
        let map = self.fused.as_mut().expect("just set");
        if let Some(state) = self.state.as_ref() {
            // One scan at a time, counted as it is fused: a failure keeps what was fused.
            while self.fused_count < self.placing.placed.len() {
                let p = &self.placing.placed[self.fused_count];
                map.insert_scan(&state.scans[p.index].cloud, &p.pose, &self.params.sensor)?;
                self.fused_count += 1;
            }
        }
        Ok(map)
    }

    /// Makes the placed poses consistent with a pose graph of pairwise registrations,
    /// odometry and mutual sightings ([`refine_placed`]), then rebuilds the map (search
    /// target, refinement points, fused map) at the refined poses: later scans are placed
    /// against the corrected map.
    pub fn optimise(&mut self, graph: &GraphRefineParams) -> Result<GraphRefinement> {
        let Some(state) = self.state.as_mut() else {
            return Err(Error::EmptyInput {
                what: "the incremental map (no scan given yet)".into(),
            });
        };
        let refined = refine_placed(&state.scans, &state.team, &self.placing.placed, graph)?;
        for (p, pose) in self.placing.placed.iter_mut().zip(&refined.poses) {
            p.pose = *pose;
        }
        let placed: Vec<(usize, Pose)> = self
            .placing
            .placed
            .iter()
            .map(|p| (p.index, p.pose))
            .collect();
        state.rebuild(&placed)?;
        self.fused = None;
        self.fused_count = 0;
        Ok(refined)
    }

    /// The result in [`super::build_map`]'s form: the placed scans (placed as they came,
    /// not best overlap first) fused by ray tracing in joining order (buckets, cleaning and
    /// scan maps as the parameters say), the waiting scans as rejected. `graph` is `None`
    /// (call [`IncrementalMapper::optimise`] first; [`MapParams::graph`] is not used here)
    /// and `seconds` 0 (the time was spent scan by scan).
    pub fn into_build(self) -> Result<MapBuild> {
        let Some(state) = self.state.as_ref() else {
            return Err(Error::EmptyInput {
                what: "the incremental map (no scan given yet)".into(),
            });
        };
        let fused = fuse::fuse_placed(&state.scans, &self.placing.placed, &self.params)?;
        Ok(MapBuild {
            map: fused.map,
            rejected: self.waiting(),
            placed: self.placing.placed.clone(),
            scan_maps: fused.scan_maps,
            registrations: self.registrations(),
            seconds: 0.0,
            entropy_after_scan: fused.entropy_after_scan,
            graph: None,
        })
    }
}

/// [`super::build_map_linked`] in [`super::MapMode::Incremental`]: the scans given to an
/// [`IncrementalMapper`] in input order (capture order = input index), each with its links
/// to the scans given before (the mapper adds their reverses), the waiting scans retried
/// after each until none is due; then the graph refinement when asked for, and the fused
/// map. The inputs were checked by the caller.
pub(super) fn map_in_order(
    scans: &[ScanInput],
    params: &MapParams,
    team: &TeamLinks,
    mut progress: impl FnMut(usize, usize),
) -> Result<MapBuild> {
    let start = std::time::Instant::now();
    if params.first != 0 {
        return Err(Error::InvalidArgument(format!(
            "incremental mapping takes the scans in the order given and frames the map with \
             the first of them: put {} first in the input instead of naming it as the frame",
            scans[params.first].name
        )));
    }
    let settings = TeamLinks {
        frame: Vec::new(),
        links: Vec::new(),
        ..team.clone()
    };
    let mut mapper = IncrementalMapper::with_team(params.clone(), settings)?;
    let n = scans.len();
    for (s, scan) in scans.iter().enumerate() {
        let links: Vec<ScanLink> = team.links[s]
            .iter()
            .filter(|l| l.other() < s)
            .cloned()
            .collect();
        mapper.add_linked_scan(scan.clone(), team.frame[s], s as u64, links)?;
        // Each round either places a scan or leaves every scan it tried not due (due
        // scans need the map to have grown since their last attempt): at most n rounds.
        for _ in 0..n {
            if !mapper.has_due() || mapper.retry_waiting(n)?.is_empty() {
                break;
            }
        }
        progress(mapper.placements().len(), n);
    }
    let graph = match &params.graph {
        Some(g) => Some(mapper.optimise(g)?),
        None => None,
    };
    let registrations = mapper.registrations();
    let mut build = mapper.into_build()?;
    build.graph = graph;
    build.registrations = registrations;
    build.seconds = start.elapsed().as_secs_f64();
    Ok(build)
}
