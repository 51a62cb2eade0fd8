//! Map building from many scans: the thesis' batch mapper (best overlap first, §6.4.1)
//! and a sequential (online) mapper, with optional odometry priors.

use std::time::Instant;

use crate::align::{register_to, Region, RegisterParams, Registration, SearchTarget};
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

/// The result of [`build_map`].
#[derive(Debug, Clone)]
pub struct MapBuild {
    /// The fused, ray-traced, cleaned occupancy list.
    pub map: OccupancyList,
    /// Scans in the order they joined.
    pub placed: Vec<PlacedScan>,
    /// Scans left out.
    pub rejected: Vec<RejectedScan>,
    /// Registrations run (a measure of work: the batch mapper reuses results whose map
    /// region did not change).
    pub registrations: usize,
    /// Wall time, seconds.
    pub seconds: f64,
}

struct State<'a> {
    scans: &'a [ScanInput],
    params: &'a MapParams,
    target: SearchTarget,
    refine_map: PointCloud,
    poses: Vec<Option<Pose>>,
    registrations: usize,
}

fn footprint(cloud: &PointCloud, pose: &Pose) -> Option<Aabb> {
    cloud.transformed(pose).bounding_box()
}

fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    (0..3).all(|i| a.min[i] <= b.max[i] && b.min[i] <= a.max[i])
}

impl State<'_> {
    /// The odometry prediction of scan `s` from the placed scan nearest to it in input order.
    fn predict(&self, s: usize) -> Option<Pose> {
        let odo_s = self.scans[s].odometry?;
        let (p, pose_p) = self
            .poses
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.map(|p| (i, p)))
            .filter(|(i, _)| self.scans[*i].odometry.is_some())
            .min_by_key(|(i, _)| (i.abs_diff(s), *i))?;
        let odo_p = self.scans[p].odometry.expect("filtered");
        Some(pose_p * odo_p.inverse() * odo_s)
    }

    /// Registers scan `s` against the map: in growing windows around the odometry
    /// prediction, then globally. Returns the registration and whether it was global.
    fn register(&mut self, s: usize) -> Result<(Registration, bool)> {
        let mut params = self.params.register.clone();
        let mut last = None;
        if let Some(prior) = self.predict(s) {
            let (xy, z, yaw) = self.params.odometry_window;
            for grow in [1.0, 2.0, 4.0] {
                params.search.prior = prior;
                params.search.region = Region::Window {
                    xy: xy * grow,
                    z: z * grow,
                    yaw: (yaw * grow).min(std::f64::consts::PI),
                };
                self.registrations += 1;
                let r = register_to(
                    &self.scans[s].cloud,
                    &self.target,
                    &self.refine_map,
                    &params,
                )?;
                if r.trusted {
                    return Ok((r, false));
                }
                last = Some(r);
            }
            params.search.prior = prior;
        }
        params.search.region = Region::Global;
        self.registrations += 1;
        let r = register_to(
            &self.scans[s].cloud,
            &self.target,
            &self.refine_map,
            &params,
        )?;
        if !r.trusted {
            if let Some(l) = last {
                if l.search.overlap > r.search.overlap {
                    return Ok((l, false));
                }
            }
        }
        Ok((r, true))
    }

    fn place(&mut self, s: usize, pose: Pose) -> Result<()> {
        let cloud = &self.scans[s].cloud;
        self.target.add_scan(cloud, &pose)?;
        self.refine_map.extend_from(&cloud.transformed(&pose));
        self.refine_map = self
            .refine_map
            .voxel_downsample(self.params.refine_map_voxel)?;
        self.poses[s] = Some(pose);
        Ok(())
    }
}

fn placed_record(
    index: usize,
    name: &str,
    order: usize,
    r: &Registration,
    global: bool,
) -> PlacedScan {
    PlacedScan {
        index,
        name: name.to_string(),
        pose: r.pose,
        order,
        overlap_fraction: r.search.overlap_fraction,
        significance: r.search.significance,
        inlier_fraction: r.refinement.as_ref().map(|f| f.inlier_fraction),
        global,
    }
}

/// Builds a map from scans: places them (batch or sequential, see [`MapMode`]), then fuses
/// the placed scans by ray tracing into one occupancy list (with optional position buckets
/// and low-count cleaning). `progress(done, total)` is called as scans are placed.
pub fn build_map(
    scans: &[ScanInput],
    params: &MapParams,
    mut progress: impl FnMut(usize, usize),
) -> Result<MapBuild> {
    let start = Instant::now();
    if scans.is_empty() {
        return Err(Error::InvalidArgument("no scans to map".into()));
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
    let mut state = State {
        scans,
        params,
        target: SearchTarget::from_scans(&[], res, levels)?,
        refine_map: PointCloud::new(),
        poses: vec![None; scans.len()],
        registrations: 0,
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
    }];
    progress(1, scans.len());
    let mut last_doubts: Vec<Option<Vec<String>>> = vec![None; scans.len()];
    match params.mode {
        MapMode::Sequential => {
            for s in (0..scans.len()).filter(|&s| s != params.first) {
                let (r, global) = state.register(s)?;
                if r.trusted {
                    state.place(s, r.pose)?;
                    placed.push(placed_record(s, &scans[s].name, placed.len(), &r, global));
                } else {
                    last_doubts[s] = Some(r.doubts.clone());
                }
                progress(placed.len(), scans.len());
            }
        }
        MapMode::Batch => {
            // Cached registrations of unplaced scans with their footprints in the map.
            let mut cache: Vec<Option<(Registration, bool, Option<Aabb>)>> =
                vec![None; scans.len()];
            loop {
                let unplaced: Vec<usize> = (0..scans.len())
                    .filter(|&s| state.poses[s].is_none())
                    .collect();
                if unplaced.is_empty() {
                    break;
                }
                for &s in &unplaced {
                    if cache[s].is_none() {
                        let (r, global) = state.register(s)?;
                        let fp = footprint(&scans[s].cloud, &r.pose);
                        cache[s] = Some((r, global, fp));
                    }
                }
                // The best trusted candidate: overlap, then significance, then index.
                let best = unplaced
                    .iter()
                    .filter_map(|&s| cache[s].as_ref().filter(|c| c.0.trusted).map(|c| (s, c)))
                    .max_by(|a, b| {
                        (a.1 .0.search.overlap, a.1 .0.search.significance)
                            .partial_cmp(&(b.1 .0.search.overlap, b.1 .0.search.significance))
                            .unwrap_or(std::cmp::Ordering::Equal)
                            .then(b.0.cmp(&a.0))
                    })
                    .map(|(s, _)| s);
                let Some(s) = best else {
                    for &u in &unplaced {
                        last_doubts[u] = cache[u].as_ref().map(|c| c.0.doubts.clone());
                    }
                    break;
                };
                let (r, global, fp) = cache[s].take().expect("chosen from the cache");
                state.place(s, r.pose)?;
                placed.push(placed_record(s, &scans[s].name, placed.len(), &r, global));
                progress(placed.len(), scans.len());
                // Reuse results whose map region did not change; retry the untrusted.
                for &u in &unplaced {
                    let stale = match (&cache[u], &fp) {
                        (Some((ru, _, Some(fu))), Some(fs)) => !ru.trusted || overlaps(fu, fs),
                        _ => true,
                    };
                    if stale {
                        cache[u] = None;
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
    for p in &placed {
        let cloud = &scans[p.index].cloud;
        if params.bucket_radius > 0.0 && !buckets.admit(&p.pose.transform_point(&cloud.origin())) {
            continue;
        }
        map.insert_scan(cloud, &p.pose, &params.sensor)?;
    }
    if params.min_count > 1 {
        map = map.threshold(params.min_count);
    }
    map.shrink_to_fit();
    Ok(MapBuild {
        map,
        placed,
        rejected,
        registrations: state.registrations,
        seconds: start.elapsed().as_secs_f64(),
    })
}
