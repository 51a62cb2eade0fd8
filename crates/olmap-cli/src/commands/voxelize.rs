//! `olmap voxelize`: build an occupancy list from point clouds.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::io::ReadOptions;
use olmap::occupancy::{
    run_free_space, run_voxelize, CloudPoses, FreeSpaceJob, LogOddsModel, SensorModel, VoxelizeJob,
    MAX_COUNT,
};

use crate::args::{parse_pose, set_threads, StageBars, ThreadsArgs};

/// Arguments of `olmap voxelize`.
///
/// Each cloud is placed in the map by its pose (from `--poses` or `--pose`, identity
/// otherwise) and integrated either by its endpoints (default: every point adds `--hit`, 1,
/// to its voxel) or with `--ray-trace` (each scan is one observation: its endpoint voxels
/// gain `--hit`, stored voxels its rays pass through lose `--miss`). Counts stop at
/// `--max-count` either way.
///
/// With `--free-space` the map also keeps free voxels, at OctoMap's semantics (log-odds:
/// `--prob-hit` 0.7 at a ray's endpoint, `--prob-miss` 0.4 along it, clamped to
/// `--clamp-min` 0.1192 .. `--clamp-max` 0.971; occupied at or above
/// `--occupancy-threshold` 0.5), and is written as an OctoMap `.bt` tree with free and
/// occupied nodes, which OctoMap's tools and octovis read.
#[derive(Args)]
pub struct VoxelizeArgs {
    /// Point-cloud files (any format `olmap info` reads), in the sensor frame.
    #[arg(required = true)]
    pub clouds: Vec<PathBuf>,
    /// Output map (.olm, or OctoMap .bt: occupancy only; with --free-space, .bt with free
    /// nodes).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Voxel edge, metres.
    #[arg(long, default_value_t = 0.05)]
    pub resolution: f64,
    /// Integrate with the ray-trace sensor model (free space along every ray).
    #[arg(long)]
    pub ray_trace: bool,
    /// Keep free space too, at OctoMap's semantics (unknown / free / occupied; log-odds
    /// with clamping); the output must be .bt.
    #[arg(long, conflicts_with_all = ["ray_trace", "bucket_radius", "hit", "miss", "max_count"])]
    pub free_space: bool,
    /// Rays longer than this are cut (free space only), metres. Default: 30 with
    /// --ray-trace; no limit with --free-space (as OctoMap's default).
    #[arg(long, value_name = "M")]
    pub max_range: Option<f64>,
    /// --free-space: probability that a ray's endpoint voxel is occupied, in (0.5, 1).
    #[arg(long, default_value_t = 0.7, requires = "free_space")]
    pub prob_hit: f64,
    /// --free-space: probability that a voxel a ray passed through is occupied, in
    /// (0, 0.5).
    #[arg(long, default_value_t = 0.4, requires = "free_space")]
    pub prob_miss: f64,
    /// --free-space: lower clamping probability, in (0, occupancy threshold].
    #[arg(long, default_value_t = 0.1192, requires = "free_space")]
    pub clamp_min: f64,
    /// --free-space: upper clamping probability, in [occupancy threshold, 1).
    #[arg(long, default_value_t = 0.971, requires = "free_space")]
    pub clamp_max: f64,
    /// --free-space: a known voxel at or above this probability is occupied.
    #[arg(long, default_value_t = 0.5, requires = "free_space")]
    pub occupancy_threshold: f64,
    /// --free-space: also write the clouds with their poses as an OctoMap ScanGraph
    /// (.graph), the input of OctoMap's `graph2tree`, to compare with OctoMap on the same
    /// data.
    #[arg(long, value_name = "FILE", requires = "free_space")]
    pub scan_graph: Option<PathBuf>,
    /// Count added to an endpoint voxel: once per scan with ray tracing, once per point
    /// otherwise.
    #[arg(long, default_value_t = 1)]
    pub hit: u16,
    /// Ray tracing: count removed from a voxel a ray passes through, once per scan.
    #[arg(long, default_value_t = 1)]
    pub miss: u16,
    /// Counts never exceed this (1 to 1023), with or without ray tracing.
    #[arg(long, default_value_t = MAX_COUNT)]
    pub max_count: u16,
    /// Poses `T_map_scan` of the clouds: an olmap pose list, a CSV pose table, or 3DTK
    /// .frames/.pose files given once per cloud (comma-separated). Matched to clouds by file
    /// name or stem, else in order when the counts agree.
    #[arg(long, value_name = "FILE[,FILE...]", conflicts_with = "pose")]
    pub poses: Option<String>,
    /// One pose for all clouds: `x,y,z,yaw,pitch,roll` (metres, degrees).
    #[arg(long, value_name = "X,Y,Z,YAW,PITCH,ROLL", allow_hyphen_values = true)]
    pub pose: Option<String>,
    /// Position buckets: skip a cloud whose sensor position is within this distance (metres)
    /// of a cloud already integrated (thesis §3.3.3; 0 keeps every cloud).
    #[arg(long, default_value_t = 0.0, value_name = "M")]
    pub bucket_radius: f64,
    /// 3DTK .3d input: keep only returns between 20 cm and 3270 cm.
    #[arg(long = "3dtk-valid")]
    pub threedtk_valid: bool,
    #[command(flatten)]
    pub threads: ThreadsArgs,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command.
pub fn run(a: &VoxelizeArgs) -> anyhow::Result<ExitCode> {
    set_threads(a.threads.threads)?;
    let poses = match (&a.pose, &a.poses) {
        (Some(p), _) => CloudPoses::All(parse_pose(p, "--pose")?),
        (None, Some(files)) => CloudPoses::Files(files.split(',').map(PathBuf::from).collect()),
        (None, None) => CloudPoses::Identity,
    };
    let read = ReadOptions {
        uos_valid_only: a.threedtk_valid,
        ..Default::default()
    };
    if a.free_space {
        return run_free(a, poses, read);
    }
    let job = VoxelizeJob {
        clouds: a.clouds.clone(),
        output: a.output.clone(),
        resolution: a.resolution,
        ray_trace: a.ray_trace,
        sensor: SensorModel {
            hit: a.hit,
            miss: a.miss,
            max_count: a.max_count,
            max_range: a.max_range.unwrap_or(30.0),
        },
        poses,
        bucket_radius: a.bucket_radius,
        read,
    };
    let mut bars = StageBars::new(a.json);
    let run = run_voxelize(&job, &mut |stage, done, total| {
        bars.update(stage, done, total)
    })?;
    bars.finish();
    let r = &run.report;
    if a.json {
        println!("{}", serde_json::to_string_pretty(r)?);
    } else {
        println!(
            "{} clouds, {} points -> {} voxels at {} m{} in {:.2} s -> {}",
            r.clouds,
            r.points,
            r.voxels,
            r.resolution,
            if r.ray_trace { " (ray traced)" } else { "" },
            r.seconds,
            a.output.display()
        );
        if r.clouds_skipped_by_buckets > 0 {
            println!(
                "  {} clouds skipped: taken within {} m of an earlier one",
                r.clouds_skipped_by_buckets, a.bucket_radius
            );
        }
        if r.skipped_points > 0 {
            println!(
                "  {} points skipped (non-finite or outside the map's key range)",
                r.skipped_points
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `--free-space`: a log-odds map written as `.bt`.
fn run_free(a: &VoxelizeArgs, poses: CloudPoses, read: ReadOptions) -> anyhow::Result<ExitCode> {
    let job = FreeSpaceJob {
        clouds: a.clouds.clone(),
        output: a.output.clone(),
        resolution: a.resolution,
        model: LogOddsModel {
            prob_hit: a.prob_hit,
            prob_miss: a.prob_miss,
            clamp_min: a.clamp_min,
            clamp_max: a.clamp_max,
            occupancy_threshold: a.occupancy_threshold,
            max_range: a.max_range.unwrap_or(f64::INFINITY),
        },
        poses,
        read,
        scan_graph: a.scan_graph.clone(),
    };
    let mut bars = StageBars::new(a.json);
    let run = run_free_space(&job, &mut |stage, done, total| {
        bars.update(stage, done, total)
    })?;
    bars.finish();
    let r = &run.report;
    if a.json {
        println!("{}", serde_json::to_string_pretty(r)?);
    } else {
        println!(
            "{} clouds, {} points -> {} known voxels at {} m ({} occupied, {} free) in {:.2} s \
             (insertion {:.2} s) -> {}",
            r.clouds,
            r.points,
            r.voxels,
            r.resolution,
            r.occupied,
            r.free,
            r.seconds,
            r.insert_seconds,
            a.output.display()
        );
        println!(
            "  memory {:.1} MiB ({:.2} bytes per known voxel); .bt tree: {} nodes, {} free and \
             {} occupied leaves",
            r.memory_bytes as f64 / (1 << 20) as f64,
            r.bytes_per_voxel,
            r.bt_nodes,
            r.bt_free_leaves,
            r.bt_occupied_leaves
        );
        if r.insertion.skipped > 0 {
            println!(
                "  {} points skipped (non-finite or outside the map's key range)",
                r.insertion.skipped
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
