//! The team map built live, record by record, as a team's records arrive over a network:
//! each record is linked to the records held (sightings at the same moment), cleared of
//! the robots it saw, and placed by the [`IncrementalMapper`].

use std::collections::HashMap;

use super::mapper::{nearest_in_time, poses_of, sighting_links, team_scan_input, TeamParams};
use super::store::StoredScan;
use crate::error::Result;
use crate::geometry::PoseList;
use crate::mapping::{IncrementalMapper, PlacedScan, ScanLink, ScanOutcome, TeamLinks};
use crate::occupancy::OccupancyList;

/// A team map built a record at a time ([`LiveTeam::add`]), for a mapper that must answer
/// while records arrive. The links, clearing and registration of [`super::map_team`], made
/// with the records held when each arrives, and each scan placed against the map as it is
/// then (plus retries of waiting scans), not best overlap first over all records: run
/// [`super::map_team`] on the same records for the offline answer. The map frame is the
/// first record given; odometry predicts a robot's scan from its placed scan nearest in
/// `seq`.
///
/// ```
/// use olmap::team::{LiveTeam, TeamParams};
/// use olmap::sim::{simulate, SimConfig, WorldKind};
///
/// let config = SimConfig { world: WorldKind::Lab, robots: 1, stops: 2, ..Default::default() };
/// let store = simulate(&config, |_, _| {}).unwrap().to_store().unwrap();
/// let mut team = LiveTeam::new(TeamParams::default()).unwrap();
/// for scan in store.iter() {
///     team.add(scan, &store.robot_name(scan.robot)).unwrap();
/// }
/// assert_eq!(team.placements().len(), 2);
/// assert_eq!(team.poses().len(), 2);
/// ```
pub struct LiveTeam {
    params: TeamParams,
    mapper: IncrementalMapper,
    /// Each record given, without its cloud (the mapper holds that): for the sighting
    /// links of later records.
    held: Vec<StoredScan>,
    /// The odometry frame of each robot: robots in the order they first appeared.
    frames: HashMap<u32, usize>,
    /// The index of each record held, by `(robot, seq)`.
    index: HashMap<(u32, u32), usize>,
    /// Points of seen robots cleared so far.
    cleared_points: usize,
    /// Two-way sightings that failed the distractor test.
    rejected_mutual: usize,
}

impl LiveTeam {
    /// An empty live team map.
    pub fn new(params: TeamParams) -> Result<Self> {
        let settings = TeamLinks {
            frame: Vec::new(),
            links: Vec::new(),
            beacon_mount: params.beacon_mount,
            locus_slack: params.locus_slack,
            mutual_window: params.mutual_window,
            hold_unlinked: params.sightings,
        };
        Ok(LiveTeam {
            mapper: IncrementalMapper::with_team(params.map.clone(), settings)?,
            params,
            held: Vec::new(),
            frames: HashMap::new(),
            index: HashMap::new(),
            cleared_points: 0,
            rejected_mutual: 0,
        })
    }

    /// Adds a record of robot `robot_name` (its scan is named `ROBOT/scanNNN`, as in
    /// [`super::map_team`]): links it to the records held taken at the same moment by the
    /// robots it saw or that saw it, and places it (or holds it; see [`ScanOutcome`]).
    /// A record whose key is already held is an error; so is one the mapper cannot take
    /// (see [`IncrementalMapper::add_linked_scan`]), which is then not held.
    pub fn add(&mut self, scan: &StoredScan, robot_name: &str) -> Result<ScanOutcome> {
        if self.index_of(scan.robot, scan.seq).is_some() {
            return Err(crate::error::Error::InvalidArgument(format!(
                "record ({}, {}) was given to the live team map twice",
                scan.robot, scan.seq
            )));
        }
        let n = self.held.len();
        let (links, rejected) = if self.params.sightings {
            self.links_of(scan, n)
        } else {
            (Vec::new(), 0)
        };
        let (input, removed) = team_scan_input(scan, robot_name, &self.params)?;
        let next = self.frames.len();
        let frame = self.frames.get(&scan.robot).copied().unwrap_or(next);
        let outcome = self
            .mapper
            .add_linked_scan(input, frame, u64::from(scan.seq), links)?;
        // Taken: only now is the record held (indices stay those of the mapper).
        self.frames.entry(scan.robot).or_insert(next);
        self.cleared_points += removed;
        self.rejected_mutual += rejected;
        self.index.insert((scan.robot, scan.seq), n);
        self.held.push(StoredScan {
            cloud: Default::default(),
            ..scan.clone()
        });
        Ok(outcome)
    }

    /// The links of new record `scan` (index `n`) to the records held: its sightings of
    /// robots whose scan at that moment is held, and the held scans' sightings of its
    /// robot for which it is the nearest in time; and how many two-way sightings failed the
    /// distractor test. Nearest among the records held when it arrives: a nearer record
    /// arriving later is linked too (the batch mapper links only the nearest).
    fn links_of(&self, scan: &StoredScan, n: usize) -> (Vec<ScanLink>, usize) {
        let gap = self.params.max_time_gap;
        let times = || self.held.iter().map(|h| (h.robot, h.time)).enumerate();
        let mut links = Vec::new();
        let mut rejected = 0;
        let mut keep = |i: usize, l: ScanLink| {
            if i == n {
                links.push(l);
            }
        };
        for g in &scan.sightings {
            if let Some(t) = nearest_in_time(times(), g.target, scan.time, gap) {
                let target = &self.held[t];
                rejected += usize::from(!sighting_links(
                    (n, scan),
                    g,
                    (t, target),
                    &self.params,
                    &mut keep,
                ));
            }
        }
        for (o, h) in self.held.iter().enumerate() {
            // Only a record within the time gap can have the new one as its nearest.
            if (h.time - scan.time).abs() > gap {
                continue;
            }
            for g in h.sightings.iter().filter(|g| g.target == scan.robot) {
                let with_new = times().chain(std::iter::once((n, (scan.robot, scan.time))));
                if nearest_in_time(with_new, scan.robot, h.time, gap) == Some(n) {
                    rejected += usize::from(!sighting_links(
                        (o, h),
                        g,
                        (n, scan),
                        &self.params,
                        &mut keep,
                    ));
                }
            }
        }
        (links, rejected)
    }

    /// Retries up to `max` waiting scans ([`IncrementalMapper::retry_waiting`]); returns the
    /// `(robot, seq)` of those placed.
    pub fn retry_waiting(&mut self, max: usize) -> Result<Vec<(u32, u32)>> {
        let placed = self.mapper.retry_waiting(max)?;
        Ok(placed.iter().map(|p| self.key(p.index)).collect())
    }

    /// Whether some waiting scan may place now.
    pub fn has_due(&self) -> bool {
        self.mapper.has_due()
    }

    /// `(robot, seq)` of the record given as number `index`.
    pub fn key(&self, index: usize) -> (u32, u32) {
        let h = &self.held[index];
        (h.robot, h.seq)
    }

    /// The index of record `(robot, seq)` if held.
    pub fn index_of(&self, robot: u32, seq: u32) -> Option<usize> {
        self.index.get(&(robot, seq)).copied()
    }

    /// Records given so far.
    pub fn len(&self) -> usize {
        self.held.len()
    }

    /// Whether no record was given yet.
    pub fn is_empty(&self) -> bool {
        self.held.is_empty()
    }

    /// The placed scans, in joining order.
    pub fn placements(&self) -> &[PlacedScan] {
        self.mapper.placements()
    }

    /// The placed scans' poses, named `ROBOT/scanNNN`, in joining order.
    pub fn poses(&self) -> PoseList {
        poses_of(self.mapper.placements())
    }

    /// The fused map of the placed scans ([`IncrementalMapper::map`]).
    pub fn map(&mut self) -> Result<&OccupancyList> {
        self.mapper.map()
    }

    /// The incremental mapper underneath (waiting scans, registrations, ...).
    pub fn mapper(&self) -> &IncrementalMapper {
        &self.mapper
    }

    /// Points of seen robots cleared from the records so far.
    pub fn cleared_points(&self) -> usize {
        self.cleared_points
    }

    /// Two-way sightings that failed the distractor test so far.
    pub fn rejected_mutual(&self) -> usize {
        self.rejected_mutual
    }
}
