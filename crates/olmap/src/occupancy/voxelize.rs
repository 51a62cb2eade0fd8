//! [`run_voxelize`]: the `olmap voxelize` pipeline — point-cloud files placed by their
//! poses and integrated into one occupancy list (endpoints or ray tracing), written as a
//! map file.

use std::path::PathBuf;
use std::time::Instant;

use super::VoxelizeReport;
use super::{write_map, InsertStats, MapFormat, OccupancyList, PositionBuckets, SensorModel};
use crate::error::{Error, Result};
use crate::geometry::{Pose, PoseList};
use crate::io::{self, file_stem_name, ReadOptions};
use crate::progress::{Progress, Stage};

/// Where the clouds' poses `T_map_scan` come from.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum CloudPoses {
    /// Every cloud at the identity.
    #[default]
    Identity,
    /// One pose for every cloud.
    All(Pose),
    /// Pose files of any kind [`io::read_poses`] reads, merged in order; a cloud takes the
    /// pose named by its file name or stem, else (when the counts agree) the one in its
    /// position.
    Files(Vec<PathBuf>),
}

/// The pose of each cloud file. A cloud without a pose in the files is
/// [`Error::NotFound`], naming the names the files hold.
pub fn cloud_poses(poses: &CloudPoses, clouds: &[PathBuf]) -> Result<Vec<Pose>> {
    let files = match poses {
        CloudPoses::Identity => return Ok(vec![Pose::identity(); clouds.len()]),
        CloudPoses::All(p) => return Ok(vec![*p; clouds.len()]),
        CloudPoses::Files(files) => files,
    };
    let mut list = PoseList::default();
    for f in files {
        list.poses.extend(io::read_poses(f)?.poses);
    }
    let mut out = Vec::new();
    for c in clouds {
        let name = c
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let stem = file_stem_name(c);
        match list.get(&name).or_else(|| list.get(&stem)) {
            Some(p) => out.push(*p),
            // Pair by order.
            None if list.len() == clouds.len() => out.push(list.poses[out.len()].pose),
            None => {
                let names: Vec<&str> = list.poses.iter().map(|p| p.name.as_str()).collect();
                let files: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
                return Err(Error::NotFound {
                    what: format!(
                        "a pose named '{name}' or '{stem}' in {} (names: {})",
                        files.join(","),
                        names.join(", ")
                    ),
                });
            }
        }
    }
    Ok(out)
}

/// What to voxelise and where the map goes.
#[derive(Debug, Clone)]
pub struct VoxelizeJob {
    /// The point-cloud files, in their sensor frames.
    pub clouds: Vec<PathBuf>,
    /// The map file (`.olm` or `.bt`).
    pub output: PathBuf,
    /// Voxel edge, metres.
    pub resolution: f64,
    /// Integrate with the ray-trace sensor model (else every endpoint adds `sensor.hit`).
    pub ray_trace: bool,
    /// The sensor model: with ray tracing all of it; for endpoints, every point adds
    /// `hit` to its voxel and counts stop at `max_count` (`miss` and `max_range` need rays).
    pub sensor: SensorModel,
    /// The clouds' poses.
    pub poses: CloudPoses,
    /// Position buckets: skip a cloud within this distance of one already integrated,
    /// metres (0: keep every cloud).
    pub bucket_radius: f64,
    /// How the files are read.
    pub read: ReadOptions,
}

/// What [`run_voxelize`] built.
#[derive(Debug, Clone)]
pub struct VoxelizeRun {
    /// The map (also written to [`VoxelizeJob::output`]).
    pub map: OccupancyList,
    /// Its report.
    pub report: VoxelizeReport,
}

/// Runs a [`VoxelizeJob`] ([`Stage::Voxelize`] progress per cloud): an output that is not a
/// map file, that cannot be written (no such folder, not writable, a folder), or a bad
/// sensor model is refused before anything is read; an error inserting a
/// cloud names it, and so does a point whose voxel key is outside the representable range
/// ([`OccupancyList::check_keys`]: too fine a resolution for the clouds' extent).
pub fn run_voxelize(job: &VoxelizeJob, progress: Progress<'_>) -> Result<VoxelizeRun> {
    let start = Instant::now();
    MapFormat::of_output(&job.output)?;
    crate::file::check_output(&job.output, "map")?;
    job.sensor.validate()?;
    if job.sensor.hit == 0 && !job.ray_trace {
        return Err(Error::InvalidArgument(
            "endpoints need a hit of at least 1: a hit of 0 adds nothing to the map".into(),
        ));
    }
    let poses = cloud_poses(&job.poses, &job.clouds)?;
    let mut map = OccupancyList::new(job.resolution)?;
    let mut total = InsertStats::default();
    let mut points = 0usize;
    let mut buckets = PositionBuckets::new(job.bucket_radius)?;
    let mut skipped_clouds = 0usize;
    let n = job.clouds.len();
    for (i, (path, pose)) in job.clouds.iter().zip(&poses).enumerate() {
        let cloud = io::read_cloud_with(path, &job.read)?.cloud;
        if job.bucket_radius > 0.0 && !buckets.admit(&pose.transform_point(&cloud.origin())) {
            skipped_clouds += 1;
            progress(Stage::Voxelize, i + 1, n);
            continue;
        }
        points += cloud.len();
        map.check_keys(&cloud, pose, &path.display().to_string())?;
        if job.ray_trace {
            let s = map
                .insert_scan(&cloud, pose, &job.sensor)
                .map_err(|e| Error::InvalidArgument(format!("{}: {e}", path.display())))?;
            total.rays += s.rays;
            total.truncated += s.truncated;
            total.skipped += s.skipped;
            total.voxels_traversed += s.voxels_traversed;
            total.removed_voxels += s.removed_voxels;
        } else {
            total.skipped += map.add_points(&cloud, pose, job.sensor.hit) as u64;
        }
        progress(Stage::Voxelize, i + 1, n);
    }
    if !job.ray_trace {
        // Saturating additions then one clamp: the same as clamping after every cloud.
        map.clamp_counts(job.sensor.max_count);
    }
    map.shrink_to_fit();
    write_map(&job.output, &map)?;
    let stats = map.stats();
    let report = VoxelizeReport {
        output: job.output.display().to_string(),
        clouds: n,
        clouds_skipped_by_buckets: skipped_clouds,
        points,
        resolution: job.resolution,
        ray_trace: job.ray_trace,
        voxels: stats.voxels,
        skipped_points: total.skipped,
        truncated_rays: total.truncated,
        voxels_traversed: total.voxels_traversed,
        bytes_per_voxel: stats.bytes_per_voxel(),
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok(VoxelizeRun { map, report })
}
