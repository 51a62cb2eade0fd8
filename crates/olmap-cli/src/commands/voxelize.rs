//! `olmap voxelize`: build an occupancy list from point clouds.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::io::ReadOptions;
use olmap::occupancy::{run_voxelize, CloudPoses, SensorModel, VoxelizeJob, MAX_COUNT};

use crate::args::{parse_pose, set_threads, StageBars, ThreadsArgs};

/// Arguments of `olmap voxelize`.
///
/// Each cloud is placed in the map by its pose (from `--poses` or `--pose`, identity
/// otherwise) and integrated either by its endpoints (default: every point adds `--hit`, 1,
/// to its voxel) or with `--ray-trace` (each scan is one observation: its endpoint voxels
/// gain `--hit`, stored voxels its rays pass through lose `--miss`). Counts stop at
/// `--max-count` either way.
#[derive(Args)]
pub struct VoxelizeArgs {
    /// Point-cloud files (any format `olmap info` reads), in the sensor frame.
    #[arg(required = true)]
    pub clouds: Vec<PathBuf>,
    /// Output map (.olm, or OctoMap .bt: occupancy only).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Voxel edge, metres.
    #[arg(long, default_value_t = 0.05)]
    pub resolution: f64,
    /// Integrate with the ray-trace sensor model (free space along every ray).
    #[arg(long)]
    pub ray_trace: bool,
    /// Ray tracing: rays longer than this are cut (free space only), metres.
    #[arg(long, default_value_t = 30.0)]
    pub max_range: f64,
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
    let job = VoxelizeJob {
        clouds: a.clouds.clone(),
        output: a.output.clone(),
        resolution: a.resolution,
        ray_trace: a.ray_trace,
        sensor: SensorModel {
            hit: a.hit,
            miss: a.miss,
            max_count: a.max_count,
            max_range: a.max_range,
        },
        poses,
        bucket_radius: a.bucket_radius,
        read: ReadOptions {
            uos_valid_only: a.threedtk_valid,
            ..Default::default()
        },
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
