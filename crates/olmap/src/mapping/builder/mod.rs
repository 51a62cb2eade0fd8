//! Map building from many scans: the thesis' batch mapper (best overlap first, §6.4.1),
//! a sequential mapper, and an incremental mapper that takes scans one at a time
//! ([`IncrementalMapper`]), with optional odometry priors and sightings.

mod batch;
mod fuse;
mod incremental;
mod linked;
mod odometry_error;
mod register;
mod sequential;
mod state;

use std::borrow::Cow;
use std::time::Instant;

pub use fuse::fuse_scan_maps;
pub use incremental::{IncrementalMapper, ScanOutcome};

use super::links::{Placement, TeamLinks};
use super::posegraph::{refine_placed, GraphRefineParams, GraphRefinement};
use crate::align::{RegisterParams, Registration};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::occupancy::{OccupancyList, SensorModel};
use state::State;

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
    /// Scans are given one at a time, in the given order, to an [`IncrementalMapper`]:
    /// each is placed against the map as it is then, or waits and is retried once the map
    /// has grown (before the next scan is given). What a live mapper does as a robot
    /// delivers its scans, run offline. The frame scan must be the first
    /// ([`MapParams::first`] 0); [`MapParams::graph`] refines the poses at the end.
    Incremental,
}

/// Parameters of [`build_map`].
#[derive(Debug, Clone)]
pub struct MapParams {
    /// Registration (search, refinement, trust) of each scan against the map.
    pub register: RegisterParams,
    /// Batch, sequential or incremental.
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
    /// After placing, make the poses consistent with a pose graph of pairwise
    /// registrations and odometry ([`crate::mapping::posegraph`]); the map is fused at the
    /// refined poses and [`MapBuild::graph`] holds the graph. Default `None` (off).
    pub graph: Option<GraphRefineParams>,
}

impl MapParams {
    /// Checks every parameter against its documented range ([`Error::InvalidArgument`]
    /// naming the parameter and the valid range): the registration's search
    /// ([`crate::align::SearchParams::validate`]) and refinement, the sensor model, the
    /// odometry window (yaw at most 180°), the bucket radius, the point-map voxel, the
    /// odometry tolerance and the registration band (`z_min < z_max`).
    pub fn validate(&self) -> Result<()> {
        self.register.search.validate()?;
        if let Some(icp) = &self.register.refine {
            icp.validate()?;
        }
        self.sensor.validate()?;
        let bad = |what: String| Err(Error::InvalidArgument(format!("map parameters: {what}")));
        let non_negative = |name: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                bad(format!("{name} must be a finite number >= 0, got {v}"))
            }
        };
        let (xy, z, yaw) = self.odometry_window;
        non_negative("odometry_window xy (m)", xy)?;
        non_negative("odometry_window z (m)", z)?;
        if !(0.0..=std::f64::consts::PI).contains(&yaw) {
            return bad(format!(
                "odometry_window yaw must be 0 to 180 degrees, got {} degrees",
                yaw.to_degrees()
            ));
        }
        non_negative("bucket_radius (m)", self.bucket_radius)?;
        non_negative("odometry_tolerance (m)", self.odometry_tolerance)?;
        if !(self.refine_map_voxel.is_finite() && self.refine_map_voxel > 0.0) {
            return bad(format!(
                "refine_map_voxel must be a finite number > 0 m, got {}",
                self.refine_map_voxel
            ));
        }
        if let Some((lo, hi)) = self.register_band {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return bad(format!(
                    "register_band needs finite heights z_min < z_max, got {lo} .. {hi}"
                ));
            }
        }
        if let Some(g) = &self.graph {
            g.validate()?;
        }
        Ok(())
    }
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
            graph: None,
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
    /// The pose-graph refinement of the placed poses, when [`MapParams::graph`] asked for
    /// it (the poses in `placed` are then the refined ones).
    pub graph: Option<GraphRefinement>,
}

/// The mappers' running record: the scans placed so far, in joining order, and the doubts
/// of each scan's last untrusted registration.
struct Placing {
    placed: Vec<PlacedScan>,
    last_doubts: Vec<Option<Vec<String>>>,
}

/// The record of unplaced scan `index`: the doubts of its last untrusted registration, or
/// a plain reason when it has none.
fn rejected_scan(index: usize, name: &str, doubts: &Option<Vec<String>>) -> RejectedScan {
    RejectedScan {
        index,
        name: name.to_string(),
        reasons: doubts
            .clone()
            .filter(|d| !d.is_empty())
            .unwrap_or_else(|| vec!["no trusted alignment to the map".into()]),
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

/// The record of the scan that defines the map frame (placed first, at the identity).
fn frame_record(index: usize, name: &str) -> PlacedScan {
    PlacedScan {
        index,
        name: name.to_string(),
        pose: Pose::identity(),
        order: 0,
        overlap_fraction: 1.0,
        significance: f64::INFINITY,
        inlier_fraction: None,
        global: false,
        via: Placement::Frame,
    }
}

/// The number of search pyramid levels for a map framed by scan `first`: the level rule
/// [`crate::align::SearchParams::levels_for_source`] applied to twice the frame scan's extent and
/// its largest range (the parameter's maximum range when the scan has none).
fn levels_from_extent(first: &ScanInput, params: &MapParams) -> usize {
    let extent = first
        .cloud
        .bounding_box()
        .map_or(nalgebra::Vector3::zeros(), |b| b.extent());
    let search = &params.register.search;
    search.levels_for_source(search.resolution, extent * MAP_EXTENT_FACTOR, &first.cloud)
}

/// How far the map is expected to grow beyond its first scan: the search pyramid is sized
/// for a target this many times the first scan's bounding box.
const MAP_EXTENT_FACTOR: f64 = 2.0;

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
    check_inputs(scans, params, team)?;
    if params.mode == MapMode::Incremental {
        return incremental::map_in_order(scans, params, team, progress);
    }
    let first = &scans[params.first];
    let mut state = State::new(
        Cow::Borrowed(scans),
        Cow::Borrowed(params),
        Cow::Borrowed(team),
    )?;
    state.place(params.first, Pose::identity())?;
    let mut placing = Placing {
        placed: vec![frame_record(params.first, &first.name)],
        last_doubts: vec![None; scans.len()],
    };
    progress(1, scans.len());
    match params.mode {
        MapMode::Sequential => sequential::place_in_order(&mut state, &mut placing, &mut progress)?,
        MapMode::Batch => batch::place_best_first(&mut state, &mut placing, &mut progress)?,
        MapMode::Incremental => unreachable!("handled above"),
    }
    let Placing {
        mut placed,
        last_doubts,
    } = placing;
    let graph = match &params.graph {
        Some(g) => {
            let refined = refine_placed(scans, team, &placed, g)?;
            for (p, pose) in placed.iter_mut().zip(&refined.poses) {
                p.pose = *pose;
            }
            Some(refined)
        }
        None => None,
    };
    let rejected = (0..scans.len())
        .filter(|&s| state.poses[s].is_none())
        .map(|s| rejected_scan(s, &scans[s].name, &last_doubts[s]))
        .collect();
    let fused = fuse::fuse_placed(scans, &placed, params)?;
    Ok(MapBuild {
        map: fused.map,
        placed,
        rejected,
        scan_maps: fused.scan_maps,
        registrations: state.registrations.into_inner(),
        seconds: start.elapsed().as_secs_f64(),
        entropy_after_scan: fused.entropy_after_scan,
        graph,
    })
}

/// The input errors of [`build_map_linked`]: no scans, team links that do not describe
/// the scans, a frame scan index out of range.
fn check_inputs(scans: &[ScanInput], params: &MapParams, team: &TeamLinks) -> Result<()> {
    params.validate()?;
    if scans.is_empty() {
        return Err(Error::EmptyInput {
            what: "the scans to map".into(),
        });
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
    Ok(())
}
