//! [`run_free_space`]: `olmap voxelize --free-space` — point-cloud files placed by their
//! poses, inserted into a [`LogOddsMap`] at OctoMap's semantics, written as an OctoMap
//! `.bt` tree with free and occupied nodes.

use std::path::PathBuf;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::{LogOddsInsertStats, LogOddsMap, LogOddsModel};
use crate::error::{Error, Result};
use crate::file::{write_atomic, OutputSet};
use crate::io::{self, ReadOptions};
use crate::occupancy::{cloud_poses, CloudPoses, MapFormat};
use crate::progress::{Progress, Stage};

/// What to insert and where the map goes.
#[derive(Debug, Clone)]
pub struct FreeSpaceJob {
    /// The point-cloud files, in their sensor frames (each cloud's origin is its sensor).
    pub clouds: Vec<PathBuf>,
    /// The map file: an OctoMap `.bt` (the only format here that holds free space).
    pub output: PathBuf,
    /// Voxel edge, metres.
    pub resolution: f64,
    /// The sensor model (OctoMap's by default).
    pub model: LogOddsModel,
    /// The clouds' poses.
    pub poses: CloudPoses,
    /// How the files are read.
    pub read: ReadOptions,
    /// Also write the clouds with their poses as an OctoMap ScanGraph (`.graph`), the input
    /// of OctoMap's `graph2tree`, to compare with OctoMap on the same data (the clouds are
    /// then kept in memory until the end).
    pub scan_graph: Option<PathBuf>,
}

/// What [`run_free_space`] did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FreeSpaceReport {
    /// The `.bt` file written.
    pub output: String,
    /// Clouds inserted.
    pub clouds: usize,
    /// Points of the clouds.
    pub points: usize,
    /// Voxel edge, metres.
    pub resolution: f64,
    /// The hit, miss, clamping and threshold probabilities used.
    pub prob_hit: f64,
    /// See [`LogOddsModel::prob_miss`].
    pub prob_miss: f64,
    /// See [`LogOddsModel::clamp_min`].
    pub clamp_min: f64,
    /// See [`LogOddsModel::clamp_max`].
    pub clamp_max: f64,
    /// See [`LogOddsModel::occupancy_threshold`].
    pub occupancy_threshold: f64,
    /// The maximum range, metres; `None` for no limit.
    pub max_range: Option<f64>,
    /// Known voxels.
    pub voxels: usize,
    /// Voxels classified occupied.
    pub occupied: usize,
    /// Voxels classified free.
    pub free: usize,
    /// Bytes held by the map (bricks and index).
    pub memory_bytes: usize,
    /// Bytes per known voxel.
    pub bytes_per_voxel: f64,
    /// The insertions' counts, all clouds together.
    pub insertion: LogOddsInsertStats,
    /// Seconds spent inserting (reading and writing files excluded).
    pub insert_seconds: f64,
    /// Nodes of the `.bt` tree written.
    pub bt_nodes: u64,
    /// Free leaves of the tree (pruned: one leaf may stand for many voxels).
    pub bt_free_leaves: u64,
    /// Occupied leaves of the tree.
    pub bt_occupied_leaves: u64,
    /// Wall time of the whole job, seconds.
    pub seconds: f64,
}

/// What [`run_free_space`] built.
#[derive(Debug, Clone)]
pub struct FreeSpaceRun {
    /// The map (also written to [`FreeSpaceJob::output`]).
    pub map: LogOddsMap,
    /// Its report.
    pub report: FreeSpaceReport,
}

/// Runs a [`FreeSpaceJob`] ([`Stage::Voxelize`] progress per cloud). An output that is not
/// a `.bt` file or cannot be written, a bad resolution or model, or a pose file that lacks a
/// cloud is refused before any cloud is read; an error inserting a cloud names it.
///
/// ```no_run
/// use olmap::occupancy::{run_free_space, CloudPoses, FreeSpaceJob, LogOddsModel};
/// let job = FreeSpaceJob {
///     clouds: vec!["scan.pcd".into()],
///     output: "free.bt".into(),
///     resolution: 0.05,
///     model: LogOddsModel::default(),
///     poses: CloudPoses::Identity,
///     read: Default::default(),
///     scan_graph: None,
/// };
/// let run = run_free_space(&job, &mut |_, _, _| {}).unwrap();
/// println!("{} free, {} occupied voxels", run.report.free, run.report.occupied);
/// ```
pub fn run_free_space(job: &FreeSpaceJob, progress: Progress<'_>) -> Result<FreeSpaceRun> {
    let start = Instant::now();
    if MapFormat::from_path(&job.output) != Some(MapFormat::OctomapBt) {
        return Err(Error::InvalidArgument(format!(
            "{}: a map with free space is written as an OctoMap .bt file (.olm holds occupied \
             voxels only)",
            job.output.display()
        )));
    }
    // The map and the scan graph appear together or not at all.
    let mut outputs = OutputSet::new();
    outputs.file(&job.output, "OctoMap .bt")?;
    if let Some(g) = &job.scan_graph {
        outputs.file(g, "OctoMap ScanGraph")?;
    }
    let mut map = LogOddsMap::new(job.resolution, job.model)?;
    let poses = cloud_poses(&job.poses, &job.clouds)?;
    let mut total = LogOddsInsertStats::default();
    let mut points = 0usize;
    let mut insert_seconds = 0.0;
    let n = job.clouds.len();
    let mut kept = Vec::new();
    for (i, (path, pose)) in job.clouds.iter().zip(&poses).enumerate() {
        let cloud = io::read_cloud_with(path, &job.read)?.cloud;
        points += cloud.len();
        let t = Instant::now();
        let s = map.insert_scan(&cloud, pose).map_err(|e| match e {
            // The kind stays; the message names the cloud.
            Error::TooLarge { what, limit } => Error::TooLarge {
                what: format!("{}: {what}", path.display()),
                limit,
            },
            e => Error::InvalidArgument(format!("{}: {e}", path.display())),
        })?;
        insert_seconds += t.elapsed().as_secs_f64();
        total.add(&s);
        if job.scan_graph.is_some() {
            kept.push((*pose, cloud));
        }
        progress(Stage::Voxelize, i + 1, n);
    }
    if let Some(g) = &job.scan_graph {
        write_atomic(&outputs.path(g)?, "OctoMap ScanGraph", |w| {
            io::scan_graph::write_nodes(w, kept.iter().map(|(p, c)| (*p, c)))
        })?;
    }
    map.shrink_to_fit();
    let bt = map.write_bt(&outputs.path(&job.output)?)?;
    outputs.commit()?;
    let stats = map.stats();
    let m = job.model;
    let report = FreeSpaceReport {
        output: job.output.display().to_string(),
        clouds: n,
        points,
        resolution: job.resolution,
        prob_hit: m.prob_hit,
        prob_miss: m.prob_miss,
        clamp_min: m.clamp_min,
        clamp_max: m.clamp_max,
        occupancy_threshold: m.occupancy_threshold,
        max_range: m.max_range.is_finite().then_some(m.max_range),
        voxels: stats.voxels,
        occupied: stats.occupied,
        free: stats.free,
        memory_bytes: stats.memory_bytes,
        bytes_per_voxel: stats.bytes_per_voxel(),
        insertion: total,
        insert_seconds,
        bt_nodes: bt.nodes,
        bt_free_leaves: bt.free_leaves,
        bt_occupied_leaves: bt.occupied_leaves,
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok(FreeSpaceRun { map, report })
}
