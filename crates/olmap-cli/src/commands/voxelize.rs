//! `olmap voxelize`: build an occupancy list from point clouds.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context};
use clap::Args;
use olmap::geometry::{Pose, PoseList};
use olmap::io::{self, ReadOptions};
use olmap::occupancy::{
    self, InsertStats, OccupancyList, PositionBuckets, SensorModel, VoxelizeReport, MAX_COUNT,
};

use crate::args::{parse_pose, progress, set_threads, ThreadsArgs};

/// Arguments of `olmap voxelize`.
///
/// Each cloud is placed in the map by its pose (from `--poses` or `--pose`, identity
/// otherwise) and integrated either by its endpoints (default: every point adds 1 to its
/// voxel) or with `--ray-trace` (each scan is one observation: its endpoint voxels gain
/// `--hit`, stored voxels its rays pass through lose `--miss`).
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
    /// Ray tracing: count added to an endpoint voxel, once per scan.
    #[arg(long, default_value_t = 1)]
    pub hit: u16,
    /// Ray tracing: count removed from a voxel a ray passes through, once per scan.
    #[arg(long, default_value_t = 1)]
    pub miss: u16,
    /// Counts never exceed this (at most 1023).
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

fn stem(p: &Path) -> String {
    p.file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}

/// The pose of each cloud.
fn poses_for(a: &VoxelizeArgs) -> anyhow::Result<Vec<Pose>> {
    if let Some(p) = &a.pose {
        return Ok(vec![parse_pose(p, "--pose")?; a.clouds.len()]);
    }
    let Some(files) = &a.poses else {
        return Ok(vec![Pose::identity(); a.clouds.len()]);
    };
    let mut list = PoseList::default();
    for f in files.split(',') {
        list.poses.extend(olmap::io::read_poses(f)?.poses);
    }
    let mut out = Vec::new();
    for c in &a.clouds {
        let name = c
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let found = list.get(&name).or_else(|| list.get(&stem(c)));
        match found {
            Some(p) => out.push(*p),
            None if list.len() == a.clouds.len() => {
                // Pair by order.
                out.push(list.poses[out.len()].pose);
            }
            None => bail!(
                "no pose named '{}' or '{}' in {files} (names: {})",
                name,
                stem(c),
                list.poses
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
    Ok(out)
}

/// Runs the command.
pub fn run(a: &VoxelizeArgs) -> anyhow::Result<ExitCode> {
    set_threads(a.threads.threads)?;
    let start = Instant::now();
    if occupancy::MapFormat::from_path(&a.output).is_none() {
        bail!(
            "{}: the output must be a map file (.olm or .bt)",
            a.output.display()
        );
    }
    let poses = poses_for(a)?;
    let model = SensorModel {
        hit: a.hit,
        miss: a.miss,
        max_count: a.max_count,
        max_range: a.max_range,
    };
    let mut map = OccupancyList::new(a.resolution)?;
    let read = ReadOptions {
        uos_valid_only: a.threedtk_valid,
        ..Default::default()
    };
    let bar = progress(a.clouds.len() as u64, "voxelize", a.json);
    let mut total = InsertStats::default();
    let mut points = 0usize;
    let mut buckets = PositionBuckets::new(a.bucket_radius)?;
    let mut skipped_clouds = 0usize;
    for (path, pose) in a.clouds.iter().zip(&poses) {
        let cloud = io::read_cloud_with(path, &read)?.cloud;
        if a.bucket_radius > 0.0 && !buckets.admit(&pose.transform_point(&cloud.origin())) {
            skipped_clouds += 1;
            bar.inc(1);
            continue;
        }
        points += cloud.len();
        if a.ray_trace {
            let s = map
                .insert_scan(&cloud, pose, &model)
                .with_context(|| format!("{}", path.display()))?;
            total.rays += s.rays;
            total.truncated += s.truncated;
            total.skipped += s.skipped;
            total.voxels_traversed += s.voxels_traversed;
            total.removed_voxels += s.removed_voxels;
        } else {
            total.skipped += map.add_points(&cloud, pose, 1) as u64;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    map.shrink_to_fit();
    occupancy::write_map(&a.output, &map)?;
    let seconds = start.elapsed().as_secs_f64();
    let stats = map.stats();
    if a.json {
        let v = VoxelizeReport {
            output: a.output.display().to_string(),
            clouds: a.clouds.len(),
            clouds_skipped_by_buckets: skipped_clouds,
            points,
            resolution: a.resolution,
            ray_trace: a.ray_trace,
            voxels: stats.voxels,
            skipped_points: total.skipped,
            truncated_rays: total.truncated,
            voxels_traversed: total.voxels_traversed,
            bytes_per_voxel: stats.bytes_per_voxel(),
            seconds,
        };
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "{} clouds, {} points -> {} voxels at {} m{} in {:.2} s -> {}",
            a.clouds.len(),
            points,
            stats.voxels,
            a.resolution,
            if a.ray_trace { " (ray traced)" } else { "" },
            seconds,
            a.output.display()
        );
        if skipped_clouds > 0 {
            println!(
                "  {skipped_clouds} clouds skipped: taken within {} m of an earlier one",
                a.bucket_radius
            );
        }
        if total.skipped > 0 {
            println!(
                "  {} points skipped (non-finite or outside the map's key range)",
                total.skipped
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
