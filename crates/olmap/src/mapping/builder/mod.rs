//! Map building from many scans: the thesis' batch mapper (best overlap first, §6.4.1)
//! and a sequential (online) mapper, with optional odometry priors.

use std::time::Instant;

use super::links::{Placement, ScanLink, TeamLinks};
use crate::align::{register_to_split, Region, RegisterParams, Registration, SearchTarget};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Aabb, Pose};
use crate::occupancy::{OccupancyList, PositionBuckets, SensorModel};

/// One scan to place.
#[derive(Debug, Clone)]
pub struct ScanInput {
    /// Its name (file stem), used in pose files and reports.
    pub name: String,
    /// The points, in the sensor frame.
    pub cloud: PointCloud,
    /// Its odometry pose `T_world_scan` in any fixed world frame, if known: only the
    /// motion between scans is used.
    pub odometry: Option<Pose>,
}

/// The order in which scans join the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapMode {
    /// Every round aligns all remaining scans to the map and adds the best one (thesis
    /// §6.4.1): scans that overlap the map little wait until the map has grown to them.
    Batch,
    /// Scans join in the given order, each aligned to the map so far (online use).
    Sequential,
}

/// Parameters of [`build_map`].
#[derive(Debug, Clone)]
pub struct MapParams {
    /// Registration (search, refinement, trust) of each scan against the map.
    pub register: RegisterParams,
    /// Batch or sequential.
    pub mode: MapMode,
    /// Index of the scan that defines the map frame (default 0).
    pub first: usize,
    /// With odometry: the first search window around the predicted pose, `(xy, z, yaw)`
    /// in metres, metres, radians (default 0.5 m, 0.3 m, 10°). A window whose result is
    /// not trusted is doubled, twice, then the search goes global: degraded odometry is
    /// never trusted blindly.
    pub odometry_window: (f64, f64, f64),
    /// Fusion: the sensor model of the ray-traced fused map.
    pub sensor: SensorModel,
    /// Fusion: skip a scan taken within this distance of an already fused one (position
    /// buckets, thesis §3.3.3; 0 = off).
    pub bucket_radius: f64,
    /// Cleaning: drop fused voxels with a count below this (pixel mixing, thesis §4.4.1;
    /// default 1 keeps all).
    pub min_count: u16,
    /// Voxel of the point map the refinement aligns to, metres (default 0.05).
    pub refine_map_voxel: f64,
    /// With odometry: a global result farther than this from the odometry prediction is
    /// not trusted, metres: the larger of this and 25 % of the odometry path length from
    /// the scan it was predicted from (default 2 m). Odometry is not trusted blindly, nor is a
    /// global match that contradicts it by tens of metres (a repetitive building).
    pub odometry_tolerance: f64,
    /// Keep each placed scan's own ray-traced occupancy list, in its sensor frame, in
    /// [`MapBuild::scan_maps`] (the thesis' scan-pose pairs, so the map can be rebuilt
    /// when poses change; default true; costs one more ray trace and the lists' memory).
    pub keep_scan_maps: bool,
    /// Register with only the points whose height in their own scan frame lies in
    /// `[z_min, z_max]` (e.g. above the floor and below the ceiling: flat floors and
    /// ceilings match anywhere and make the search ambiguous; thesis §5.4, §6.4.2 use a
    /// sub-ceiling band). The fused map keeps every point. Default `None` (all points).
    pub register_band: Option<(f64, f64)>,
}

impl Default for MapParams {
    fn default() -> Self {
        MapParams {
            register: RegisterParams::default(),
            mode: MapMode::Batch,
            first: 0,
            odometry_window: (0.5, 0.3, 10f64.to_radians()),
            sensor: SensorModel::default(),
            bucket_radius: 0.0,
            min_count: 1,
            refine_map_voxel: 0.05,
            odometry_tolerance: 2.0,
            keep_scan_maps: true,
            register_band: None,
        }
    }
}

/// A scan placed in the map.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedScan {
    /// Index in the input.
    pub index: usize,
    /// Its name.
    pub name: String,
    /// `T_map_scan`.
    pub pose: Pose,
    /// When it joined (0 = the frame scan).
    pub order: usize,
    /// Overlap fraction of its search (1 for the frame scan).
    pub overlap_fraction: f64,
    /// Significance of its search.
    pub significance: f64,
    /// ICP inlier fraction, if refined.
    pub inlier_fraction: Option<f64>,
    /// Whether its final search was global (no usable odometry window).
    pub global: bool,
    /// What placed it: the frame, odometry, a global search or a sighting.
    pub via: Placement,
}

/// A scan that could not be placed, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct RejectedScan {
    /// Index in the input.
    pub index: usize,
    /// Its name.
    pub name: String,
    /// The failed trust tests of its best registration.
    pub reasons: Vec<String>,
}

/// A placed scan's own occupancy list and its pose: what the map can be rebuilt from.
#[derive(Debug, Clone)]
pub struct ScanMap {
    /// The scan's name.
    pub name: String,
    /// `T_map_scan`.
    pub pose: Pose,
    /// The scan ray traced alone, in its sensor frame (counts, free space cleared).
    pub voxels: OccupancyList,
}

/// Rebuilds a fused map from scan-pose pairs: each scan's list moved to its pose (voxel
/// centres re-binned, so a voxel can shift by one cell) and the counts added. Use it after
/// changing poses; [`build_map`]'s own fused map ray traces the points instead (exact).
///
/// ```
/// use olmap::geometry::Pose;
/// use olmap::mapping::{fuse_scan_maps, ScanMap};
/// use olmap::occupancy::OccupancyList;
/// # use nalgebra::Point3;
/// let mut voxels = OccupancyList::new(0.1).unwrap();
/// voxels.set(voxels.key_of(&Point3::new(1.05, 0.05, 0.05)).unwrap(), 2).unwrap();
/// let scans = [ScanMap { name: "a".into(), pose: Pose::from_xyz_ypr(1.0, 0.0, 0.0, 0.0, 0.0, 0.0), voxels }];
/// let map = fuse_scan_maps(&scans).unwrap();
/// assert_eq!(map.count_at(&Point3::new(2.05, 0.05, 0.05)), 2);
/// ```
pub fn fuse_scan_maps(scans: &[ScanMap]) -> Result<OccupancyList> {
    let Some(first) = scans.first() else {
        return Err(Error::InvalidArgument("no scan maps to fuse".into()));
    };
    let mut map = OccupancyList::new(first.voxels.resolution())?;
    for s in scans {
        map.merge(&s.voxels.transformed(&s.pose))?;
    }
    Ok(map)
}

/// The result of [`build_map`].
#[derive(Debug, Clone)]
pub struct MapBuild {
    /// The fused, ray-traced, cleaned occupancy list.
    pub map: OccupancyList,
    /// Scans in the order they joined.
    pub placed: Vec<PlacedScan>,
    /// Scans left out.
    pub rejected: Vec<RejectedScan>,
    /// Each placed scan's own occupancy list with its pose, in joining order (empty unless
    /// [`MapParams::keep_scan_maps`]).
    pub scan_maps: Vec<ScanMap>,
    /// Registrations run (a measure of work: the batch mapper reuses results whose map
    /// region did not change).
    pub registrations: usize,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Map entropy (thesis (7.4), nats) after each placed scan was fused, in joining order,
    /// with `p0 = 0.5`, one log-odds unit per count and `V = 0`: the volume term is one
    /// constant for a whole run, so the curve's shape and differences are (7.4)'s.
    pub entropy_after_scan: Vec<f64>,
}

/// A batch mapper's cached registration: the result, what found it, and the scan's
/// footprint in the map at the result.
type CacheEntry = (Registration, Placement, Option<Aabb>);

/// Linked scans whose links are searched per scan and attempt (the strongest first).
const MAX_LINK_SEARCHES: usize = 2;

/// How many stale scans the batch mapper retries before looking for a trusted result.
const RETRY_GROUP: usize = 4;

struct State<'a> {
    scans: &'a [ScanInput],
    /// The clouds registration uses: the scans' points, cut to
    /// [`MapParams::register_band`] when set.
    clouds: Vec<std::borrow::Cow<'a, PointCloud>>,
    params: &'a MapParams,
    team: &'a TeamLinks,
    target: SearchTarget,
    refine_map: PointCloud,
    poses: Vec<Option<Pose>>,
    registrations: usize,
    /// Union of the placed scans' footprints.
    map_box: Option<Aabb>,
}

fn footprint(cloud: &PointCloud, pose: &Pose) -> Option<Aabb> {
    cloud.transformed(pose).bounding_box()
}

fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    (0..3).all(|i| a.min[i] <= b.max[i] && b.min[i] <= a.max[i])
}

impl State<'_> {
    /// The odometry prediction of scan `s` from the placed scan of its frame fewest scans
    /// away in the input (input order is capture order: odometry drifts with every move,
    /// so the scan nearest in position may be many moves and tens of degrees of drift
    /// away), and the odometry path length between the two.
    fn predict(&self, s: usize) -> Option<(Pose, f64)> {
        let odo_s = self.scans[s].odometry?;
        let p = self.predicts_from(s)?;
        let pose_p = self.poses[p].expect("placed");
        let odo_p = self.scans[p].odometry.expect("filtered");
        let motion = odo_p.inverse() * odo_s;
        Some((pose_p * motion, self.path_length(p, s)))
    }

    /// The placed scan [`State::predict`] predicts scan `s` from.
    fn predicts_from(&self, s: usize) -> Option<usize> {
        self.scans[s].odometry?;
        self.poses
            .iter()
            .enumerate()
            .filter(|(i, p)| p.is_some() && self.team.frame[*i] == self.team.frame[s])
            .filter(|(i, _)| self.scans[*i].odometry.is_some())
            .map(|(i, _)| i)
            .min_by_key(|&i| (i.abs_diff(s), i))
    }

    /// The odometry path length between scans `a` and `b` of one frame: the moves between
    /// the frame's scans with odometry, in input order.
    fn path_length(&self, a: usize, b: usize) -> f64 {
        let (lo, hi) = (a.min(b), a.max(b));
        let frame = self.team.frame[a];
        let mut last: Option<Pose> = None;
        let mut length = 0.0;
        for i in lo..=hi {
            if self.team.frame[i] != frame {
                continue;
            }
            if let Some(odo) = self.scans[i].odometry {
                if let Some(prev) = last {
                    length += (odo.translation() - prev.translation()).norm();
                }
                last = Some(odo);
            }
        }
        length
    }

    /// Registers scan `s` against the map. First along the loci of its sightings of or by
    /// placed scans (mutual first). Then, with an odometry prediction: in windows around it
    /// that double twice, then one as wide as the odometry tolerance; a global search only
    /// when `allow_global` (the batch mapper's last resort: the odometry may be wrong).
    /// Without odometry: globally. Returns the best registration and what found it.
    fn register(&mut self, s: usize, allow_global: bool) -> Result<(Registration, Placement)> {
        let mut best: Option<(Registration, Placement)> = None;
        let keep = |best: &mut Option<(Registration, Placement)>, r: Registration, via| {
            if best
                .as_ref()
                .is_none_or(|b| r.search.overlap > b.0.search.overlap)
            {
                *best = Some((r, via));
            }
        };
        let mut links: Vec<ScanLink> = self.team.links[s]
            .iter()
            .filter(|l| self.poses[l.other()].is_some())
            .cloned()
            .collect();
        // The strongest link per linked scan (a mutual one subsumes the two loci).
        links.sort_by_key(|l| (l.other(), l.rank()));
        links.dedup_by_key(|l| l.other());
        links.sort_by_key(|l| (l.rank(), l.other()));
        for link in links.iter().take(MAX_LINK_SEARCHES) {
            let other_pose = self.poses[link.other()].expect("filtered");
            let (region, prior) = link.region(&other_pose, self.team);
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
                return Ok((r, via));
            }
            keep(&mut best, r, via);
        }
        let mut params = self.params.register.clone();
        let prediction = self.predict(s);
        if let Some((prior, distance)) = prediction {
            let (xy, z, yaw) = self.params.odometry_window;
            let tolerance = self.odometry_tolerance(distance);
            let mut windows: Vec<f64> = vec![1.0, 2.0, 4.0];
            if tolerance > 4.0 * xy {
                windows.push(tolerance / xy);
            }
            params.search.prior = prior;
            for grow in windows {
                params.search.region = Region::Window {
                    xy: xy * grow,
                    z: z * grow,
                    yaw: (yaw * grow).min(std::f64::consts::PI),
                };
                let mut r = self.run(s, &params)?;
                check_odometry(&mut r, &prior, tolerance);
                if r.trusted {
                    return Ok((r, Placement::Odometry));
                }
                keep(&mut best, r, Placement::Odometry);
            }
            if !allow_global {
                return Ok(best.expect("at least one window"));
            }
        } else if !allow_global && !links.is_empty() {
            // Linked but no odometry in its frame yet: the loci were the search.
            return Ok(best.expect("at least one link"));
        }
        params.search.region = Region::Global;
        let mut r = self.run(s, &params)?;
        if let Some((prior, distance)) = prediction {
            check_odometry(&mut r, &prior, self.odometry_tolerance(distance));
        }
        match best {
            Some(b) if !r.trusted && b.0.search.overlap > r.search.overlap => Ok(b),
            _ => Ok((r, Placement::Global)),
        }
    }

    /// [`State::register`] with the scan's footprint at the result: a batch cache entry.
    fn attempt(&mut self, s: usize, allow_global: bool) -> Result<CacheEntry> {
        let (r, via) = self.register(s, allow_global)?;
        let fp = footprint(&self.clouds[s], &r.pose);
        Ok((r, via, fp))
    }

    /// Registers scan `s` in a window (the first odometry window) around `prior`: the
    /// confirmation of a cached result before the scan joins the map.
    fn register_near(&mut self, s: usize, prior: Pose) -> Result<Registration> {
        let mut params = self.params.register.clone();
        let (xy, z, yaw) = self.params.odometry_window;
        params.search.prior = prior;
        params.search.region = Region::Window { xy, z, yaw };
        let mut r = self.run(s, &params)?;
        if let Some((predicted, distance)) = self.predict(s) {
            check_odometry(&mut r, &predicted, self.odometry_tolerance(distance));
        }
        Ok(r)
    }

    /// One registration of scan `s` against the map (searching with its registration
    /// cloud, refining with the whole scan), counted.
    fn run(&mut self, s: usize, params: &RegisterParams) -> Result<Registration> {
        self.registrations += 1;
        register_to_split(
            &self.clouds[s],
            &self.scans[s].cloud,
            &self.target,
            &self.refine_map,
            params,
        )
    }

    /// How far a match may be from an odometry prediction made over `distance` metres.
    fn odometry_tolerance(&self, distance: f64) -> f64 {
        self.params.odometry_tolerance.max(0.25 * distance)
    }

    /// The overlap fraction of scan `s` at `pose` with the map as it is now (finest level):
    /// a cheap update of a cached result's score after the map grew.
    fn overlap_fraction_at(&self, list: &OccupancyList, pose: &Pose) -> Result<f64> {
        let n = list.len().max(1) as f64;
        Ok(self.target.pyramid().base().overlap(list, pose)? as f64 / n)
    }

    /// How near scan `s` probably is to the placed scans, smaller first: with odometry,
    /// `(false, metres)` from its predicted position to the nearest placed scan; without,
    /// `(true, index gap)` to the nearest placed scan in the input (usually capture order).
    fn nearness(&self, s: usize) -> (bool, f64) {
        let placed = self
            .poses
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.map(|p| (i, p)));
        match self.predict(s) {
            Some((prior, _)) => (
                false,
                placed
                    .map(|(_, p)| (p.translation() - prior.translation()).norm())
                    .fold(f64::INFINITY, f64::min),
            ),
            None => (
                true,
                placed
                    .map(|(i, _)| i.abs_diff(s) as f64)
                    .fold(f64::INFINITY, f64::min),
            ),
        }
    }

    /// Whether odometry puts scan `s` clearly outside the map so far (its predicted
    /// footprint, widened by every window and tolerance, misses the map's box): no search
    /// can succeed yet, so the batch mapper does not spend one.
    fn far_from_map(&self, s: usize) -> bool {
        if self.unlinked(s) {
            return true;
        }
        let (Some((prior, distance)), Some(map)) = (self.predict(s), self.map_box) else {
            return false;
        };
        let Some(fp) = footprint(&self.clouds[s], &prior) else {
            return false;
        };
        let margin = (4.0 * self.params.odometry_window.0).max(self.odometry_tolerance(distance));
        let widened = Aabb::new(
            fp.min - nalgebra::Vector3::repeat(margin),
            fp.max + nalgebra::Vector3::repeat(margin),
        );
        !overlaps(&widened, &map)
    }

    /// Whether scan `s` waits for a link ([`TeamLinks::hold_unlinked`]): no scan of its
    /// robot is placed and none of its links leads to a placed scan. Such a scan is never
    /// searched: a robot joins the map through a sighting only (a global match of a whole
    /// robot in a symmetric building can be a mirror image).
    fn unlinked(&self, s: usize) -> bool {
        self.team.hold_unlinked
            && !(0..self.scans.len())
                .any(|i| self.poses[i].is_some() && self.team.frame[i] == self.team.frame[s])
            && !self.team.links[s]
                .iter()
                .any(|l| self.poses[l.other()].is_some())
    }

    fn place(&mut self, s: usize, pose: Pose) -> Result<()> {
        let cloud = &self.clouds[s];
        if let Some(fp) = footprint(cloud, &pose) {
            self.map_box = Some(self.map_box.map_or(fp, |b| b.union(&fp)));
        }
        self.target.add_scan(cloud, &pose)?;
        // ICP refines against the whole scans (the floor fixes the height a band leaves free).
        self.refine_map
            .extend_from(&self.scans[s].cloud.transformed(&pose));
        self.refine_map = self
            .refine_map
            .voxel_downsample(self.params.refine_map_voxel)?;
        self.poses[s] = Some(pose);
        Ok(())
    }
}

/// Distrusts a registration farther than `tolerance` metres from the odometry prediction
/// `prior` (a window search snaps to coarse cells and can end past its nominal edge).
fn check_odometry(r: &mut Registration, prior: &Pose, tolerance: f64) {
    let off = (r.pose.translation() - prior.translation()).norm();
    if r.trusted && off > tolerance {
        r.trusted = false;
        r.doubts.push(format!(
            "the match is {off:.2} m from the odometry prediction (tolerance {tolerance:.2} m)"
        ));
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

fn placed_record(
    index: usize,
    name: &str,
    order: usize,
    r: &Registration,
    via: Placement,
) -> PlacedScan {
    PlacedScan {
        index,
        name: name.to_string(),
        pose: r.pose,
        order,
        overlap_fraction: r.search.overlap_fraction,
        significance: r.search.significance,
        inlier_fraction: r.refinement.as_ref().map(|f| f.inlier_fraction),
        global: via == Placement::Global,
        via,
    }
}

/// Builds a map from scans: places them (batch or sequential, see [`MapMode`]), then fuses
/// the placed scans by ray tracing into one occupancy list (with optional position buckets
/// and low-count cleaning). `progress(done, total)` is called as scans are placed.
pub fn build_map(
    scans: &[ScanInput],
    params: &MapParams,
    progress: impl FnMut(usize, usize),
) -> Result<MapBuild> {
    build_map_linked(scans, params, &TeamLinks::none(scans.len()), progress)
}

/// [`build_map`] for a team: scans taken by several robots (each with its own odometry
/// frame, `team.frame`) and linked by sightings (`team.links`, thesis (6.2)-(6.4)). A scan
/// with a link to a placed scan is searched along the link's locus first (a mutual link:
/// a small window around the pose it gives), which is faster than a global search and
/// cannot match elsewhere; odometry windows (within its robot's frame) and global
/// searches follow as in [`build_map`]. [`PlacedScan::via`] records what placed each scan.
pub fn build_map_linked(
    scans: &[ScanInput],
    params: &MapParams,
    team: &TeamLinks,
    mut progress: impl FnMut(usize, usize),
) -> Result<MapBuild> {
    let start = Instant::now();
    if scans.is_empty() {
        return Err(Error::InvalidArgument("no scans to map".into()));
    }
    if team.frame.len() != scans.len()
        || team.links.len() != scans.len()
        || team
            .links
            .iter()
            .flatten()
            .any(|l| l.other() >= scans.len())
    {
        return Err(Error::InvalidArgument(format!(
            "the team links describe {} / {} scans (or link past them), not {}",
            team.frame.len(),
            team.links.len(),
            scans.len()
        )));
    }
    if params.first >= scans.len() {
        return Err(Error::InvalidArgument(format!(
            "the first scan index {} is out of range ({} scans)",
            params.first,
            scans.len()
        )));
    }
    let res = params.register.search.resolution;
    let first = &scans[params.first];
    let extent = first
        .cloud
        .bounding_box()
        .map_or(nalgebra::Vector3::zeros(), |b| b.extent());
    let range = first
        .cloud
        .stats()
        .range
        .map_or(params.register.search.max_range, |r| r.max);
    let levels = params.register.search.levels_for(extent * 2.0, range);
    let clouds = scans
        .iter()
        .map(|s| match params.register_band {
            Some((lo, hi)) => std::borrow::Cow::Owned(s.cloud.z_band(lo, hi)),
            None => std::borrow::Cow::Borrowed(&s.cloud),
        })
        .collect();
    let mut state = State {
        scans,
        clouds,
        params,
        team,
        target: SearchTarget::from_scans(&[], res, levels)?,
        refine_map: PointCloud::new(),
        poses: vec![None; scans.len()],
        registrations: 0,
        map_box: None,
    };
    state.place(params.first, Pose::identity())?;
    let mut placed = vec![PlacedScan {
        index: params.first,
        name: first.name.clone(),
        pose: Pose::identity(),
        order: 0,
        overlap_fraction: 1.0,
        significance: f64::INFINITY,
        inlier_fraction: None,
        global: false,
        via: Placement::Frame,
    }];
    progress(1, scans.len());
    let mut last_doubts: Vec<Option<Vec<String>>> = vec![None; scans.len()];
    match params.mode {
        MapMode::Sequential => {
            for s in (0..scans.len()).filter(|&s| s != params.first) {
                let (r, via) = state.register(s, true)?;
                if r.trusted {
                    state.place(s, r.pose)?;
                    placed.push(placed_record(s, &scans[s].name, placed.len(), &r, via));
                } else {
                    last_doubts[s] = Some(r.doubts.clone());
                }
                progress(placed.len(), scans.len());
            }
        }
        MapMode::Batch => {
            // Cached registrations of unplaced scans with their footprints in the map, and
            // how many scans were placed when each was computed.
            let mut cache: Vec<Option<CacheEntry>> = vec![None; scans.len()];
            let mut attempted_at = vec![usize::MAX; scans.len()];
            // Scans odometry places outside the map so far, and those searched anyway once.
            let mut far = vec![false; scans.len()];
            let mut forced = vec![false; scans.len()];
            // Cached results whose score was refreshed at their pose after the map grew
            // (confirmed by a window search before the scan joins), and the scans' voxels.
            let mut provisional = vec![false; scans.len()];
            let mut voxels: Vec<Option<OccupancyList>> = vec![None; scans.len()];
            let best_trusted = |cache: &[Option<CacheEntry>], unplaced: &[usize]| {
                unplaced
                    .iter()
                    .filter_map(|&s| cache[s].as_ref().filter(|c| c.0.trusted).map(|c| (s, c)))
                    .max_by(|a, b| {
                        (a.1 .0.search.overlap_fraction, a.1 .0.search.significance)
                            .partial_cmp(&(
                                b.1 .0.search.overlap_fraction,
                                b.1 .0.search.significance,
                            ))
                            .unwrap_or(std::cmp::Ordering::Equal)
                            .then(b.0.cmp(&a.0))
                    })
                    .map(|(s, _)| s)
            };
            loop {
                let unplaced: Vec<usize> = (0..scans.len())
                    .filter(|&s| state.poses[s].is_none())
                    .collect();
                if unplaced.is_empty() {
                    break;
                }
                for &s in &unplaced {
                    if attempted_at[s] == usize::MAX {
                        attempted_at[s] = 0;
                    }
                }
                let placed_now = placed.len();
                for &s in &unplaced {
                    if cache[s].is_none() && !(far[s] && attempted_at[s] == placed_now) {
                        far[s] = state.far_from_map(s);
                        attempted_at[s] = placed_now;
                        if !far[s] {
                            cache[s] = Some(state.attempt(s, false)?);
                        }
                    }
                }
                let mut best = best_trusted(&cache, &unplaced);
                if best.is_none() {
                    // Nothing trusted: retry every scan last tried against a smaller map
                    // (all of them: stopping at the first trusted one let a false match in
                    // the synthetic hall win over the true, better one).
                    // Input order is usually capture order, so scans next (by index) to
                    // placed ones go first, a few at a time, the best of a group winning:
                    // each retry round costs a few searches, not one per unplaced scan.
                    let mut stale: Vec<usize> = unplaced
                        .iter()
                        .copied()
                        .filter(|&s| attempted_at[s] < placed_now)
                        .collect();
                    let keys: Vec<(bool, f64)> = stale.iter().map(|&s| state.nearness(s)).collect();
                    let mut by_key: Vec<(usize, (bool, f64))> =
                        stale.iter().copied().zip(keys).collect();
                    by_key.sort_by(|a, b| {
                        (a.1 .0, a.1 .1, a.0)
                            .partial_cmp(&(b.1 .0, b.1 .1, b.0))
                            .unwrap_or(std::cmp::Ordering::Equal)
                    });
                    stale = by_key.into_iter().map(|(s, _)| s).collect();
                    for group in stale.chunks(RETRY_GROUP) {
                        for &s in group {
                            far[s] = state.far_from_map(s);
                            attempted_at[s] = placed_now;
                            if !far[s] {
                                cache[s] = Some(state.attempt(s, false)?);
                            }
                        }
                        best = best_trusted(&cache, &unplaced);
                        if best.is_some() {
                            break;
                        }
                    }
                }
                if best.is_none() {
                    // Last resort before giving up: odometry may be wrong, search anyway.
                    let last_resort: Vec<usize> = unplaced
                        .iter()
                        .copied()
                        .filter(|&s| far[s] && !forced[s] && !state.unlinked(s))
                        .collect();
                    for s in last_resort {
                        forced[s] = true;
                        far[s] = false;
                        cache[s] = Some(state.attempt(s, true)?);
                    }
                    best = best_trusted(&cache, &unplaced);
                }
                let Some(s) = best else {
                    for &u in &unplaced {
                        last_doubts[u] = cache[u].as_ref().map(|c| c.0.doubts.clone());
                    }
                    break;
                };
                let (r, via, fp) = cache[s].take().expect("chosen from the cache");
                let (r, via, fp) = if provisional[s] {
                    provisional[s] = false;
                    let confirmed = state.register_near(s, r.pose)?;
                    if !confirmed.trusted {
                        let fpc = footprint(&state.clouds[s], &confirmed.pose);
                        cache[s] = Some((confirmed, via, fpc));
                        continue;
                    }
                    let fpc = footprint(&state.clouds[s], &confirmed.pose);
                    (confirmed, via, fpc)
                } else {
                    (r, via, fp)
                };
                state.place(s, r.pose)?;
                placed.push(placed_record(s, &scans[s].name, placed.len(), &r, via));
                progress(placed.len(), scans.len());
                // Scans linked to this one and not yet trusted search along their new loci
                // next round.
                for &u in &unplaced {
                    let trusted = cache[u].as_ref().is_some_and(|c| c.0.trusted);
                    if u != s && !trusted && team.links[u].iter().any(|l| l.other() == s) {
                        cache[u] = None;
                        provisional[u] = false;
                    }
                }
                // Scans of the same robot that now predict from this one (fewer moves, less
                // drift) search again around the better prediction: a result found around a
                // prediction many moves old can be a look-alike place metres away.
                for &u in &unplaced {
                    let by_odometry = cache[u]
                        .as_ref()
                        .is_some_and(|c| !matches!(c.1, Placement::Sighting { .. }));
                    if u != s && by_odometry && state.predicts_from(u) == Some(s) {
                        cache[u] = None;
                        provisional[u] = false;
                    }
                }
                // Trusted results whose map region changed get their score refreshed at
                // their pose (cheap) and are confirmed before joining; untrusted ones are
                // retried only when nothing trusted is left.
                for &u in &unplaced {
                    let touched = match (&cache[u], &fp) {
                        (Some((ru, _, Some(fu))), Some(fs)) => ru.trusted && overlaps(fu, fs),
                        _ => false,
                    };
                    if touched {
                        if voxels[u].is_none() {
                            voxels[u] = Some(OccupancyList::from_cloud(&state.clouds[u], res)?);
                        }
                        let list = voxels[u].as_ref().expect("just set");
                        let entry = cache[u].as_mut().expect("touched");
                        entry.0.search.overlap_fraction =
                            state.overlap_fraction_at(list, &entry.0.pose)?;
                        provisional[u] = true;
                    }
                }
            }
        }
    }
    let rejected = (0..scans.len())
        .filter(|&s| state.poses[s].is_none())
        .map(|s| RejectedScan {
            index: s,
            name: scans[s].name.clone(),
            reasons: last_doubts[s]
                .clone()
                .filter(|d| !d.is_empty())
                .unwrap_or_else(|| vec!["no trusted alignment to the map".into()]),
        })
        .collect();
    // Fuse the placed scans by ray tracing, in the order they joined.
    let mut map = OccupancyList::new(res)?;
    let mut buckets = PositionBuckets::new(params.bucket_radius)?;
    let mut scan_maps = Vec::new();
    let mut entropy_after_scan = Vec::with_capacity(placed.len());
    for p in &placed {
        let cloud = &scans[p.index].cloud;
        if params.keep_scan_maps {
            let mut voxels = OccupancyList::new(res)?;
            voxels.insert_scan(cloud, &Pose::identity(), &params.sensor)?;
            voxels.shrink_to_fit();
            scan_maps.push(ScanMap {
                name: p.name.clone(),
                pose: p.pose,
                voxels,
            });
        }
        let admitted =
            params.bucket_radius <= 0.0 || buckets.admit(&p.pose.transform_point(&cloud.origin()));
        if admitted {
            map.insert_scan(cloud, &p.pose, &params.sensor)?;
        }
        entropy_after_scan.push(map.entropy(0.5, Some(0.0), 1.0)?);
    }
    if params.min_count > 1 {
        map = map.threshold(params.min_count);
    }
    map.shrink_to_fit();
    Ok(MapBuild {
        map,
        placed,
        rejected,
        scan_maps,
        registrations: state.registrations,
        seconds: start.elapsed().as_secs_f64(),
        entropy_after_scan,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A robot drives a 5 m square and comes back near its start: the last scan is 0.5 m
    /// from the first by odometry but four moves from it, one move from the fourth.
    #[test]
    fn odometry_predicts_from_the_fewest_moves_not_the_nearest_position() {
        let corners = [(0.0, 0.0), (5.0, 0.0), (5.0, 5.0), (0.0, 5.0), (0.3, 0.4)];
        let scans: Vec<ScanInput> = corners
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| ScanInput {
                name: format!("s{i}"),
                cloud: PointCloud::new(),
                odometry: Some(Pose::from_xyz_ypr(x, y, 0.0, 0.0, 0.0, 0.0)),
            })
            .collect();
        let params = MapParams::default();
        let team = TeamLinks::none(scans.len());
        let mut state = State {
            scans: &scans,
            clouds: scans
                .iter()
                .map(|s| std::borrow::Cow::Borrowed(&s.cloud))
                .collect(),
            params: &params,
            team: &team,
            target: SearchTarget::from_scans(&[], 0.1, 1).unwrap(),
            refine_map: PointCloud::new(),
            poses: vec![None; scans.len()],
            registrations: 0,
            map_box: None,
        };
        state.poses[0] = Some(Pose::identity());
        state.poses[3] = Some(Pose::from_xyz_ypr(0.2, 5.1, 0.0, 0.0, 0.0, 0.0));
        assert_eq!(state.predicts_from(4), Some(3));
        let (predicted, path) = state.predict(4).unwrap();
        // From scan 3's placed pose by the one move in between (5.0 m, 4.6 m of it in y).
        assert!((predicted.translation() - nalgebra::Vector3::new(0.5, 0.5, 0.0)).norm() < 1e-9);
        assert!((path - (0.3f64.hypot(4.6))).abs() < 1e-9);
        // The path length counts every move between two scans, not their distance.
        assert!((state.path_length(0, 4) - (5.0 + 5.0 + 5.0 + 0.3f64.hypot(4.6))).abs() < 1e-9);
    }
}
