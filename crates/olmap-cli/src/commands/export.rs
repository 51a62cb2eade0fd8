//! `olmap export`: a map written as another map format, a cloud of voxel centres or a
//! Rerun recording.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use clap::Args;
use olmap::io::{self, WriteOptions};
use olmap::occupancy::{self, MapFormat};

/// Arguments of `olmap export`.
#[derive(Args)]
pub struct ExportArgs {
    /// Input map (.olm or OctoMap .bt).
    pub map: PathBuf,
    /// Output: a map file (.olm, .bt), a point cloud of voxel centres with counts as intensity
    /// (.ply .pcd .xyz .csv ...), an MCAP file for Foxglove and rosbag2 tools (.mcap:
    /// /olmap/map as sensor_msgs/PointCloud2 in frame `map`, x y z float32 + intensity =
    /// count; with --poses, /olmap/path as nav_msgs/Path per robot and /tf map -> scan), or a
    /// Rerun recording (.rrd: voxels coloured by height, scan positions and robot paths from
    /// --poses; needs the `rerun` cargo feature).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Keep only voxels with at least this count.
    #[arg(long, default_value_t = 1)]
    pub min_count: u16,
    /// Point-cloud output: colour the voxel centres by height (blue low, red high) for 3D
    /// viewers (PLY, PCD keep the colours).
    #[arg(long)]
    pub colour_by_height: bool,
    /// MCAP and Rerun output: scan poses (pose list, e.g. team_poses.txt) written as one path
    /// per robot (the name's part before `/`) and, in MCAP, as /tf frames.
    #[arg(long)]
    pub poses: Option<PathBuf>,
}

/// Runs `olmap export`.
pub fn run(a: &ExportArgs) -> anyhow::Result<ExitCode> {
    olmap::file::check_output(&a.output, "export")?;
    let map = occupancy::read_map(&a.map)?.map.threshold(a.min_count);
    let is_mcap = a
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
    if is_mcap {
        let poses = a
            .poses
            .as_ref()
            .map(olmap::geometry::PoseList::read_path)
            .transpose()?;
        let cloud = map.to_cloud();
        olmap::io::bag::write_map_mcap(
            &a.output,
            &olmap::io::bag::MapBag {
                cloud: &cloud,
                poses: poses.as_ref(),
                stamp: Default::default(),
            },
        )?;
    } else if super::rrd::is_rrd(&a.output) {
        let poses = a
            .poses
            .as_ref()
            .map(olmap::geometry::PoseList::read_path)
            .transpose()?;
        super::rrd::write_rrd(&a.output, &map, poses.as_ref())?;
    } else if a.poses.is_some() {
        bail!(
            "{}: --poses is written only into an MCAP file (.mcap) or a Rerun recording (.rrd)",
            a.output.display()
        );
    } else if MapFormat::from_path(&a.output).is_some() {
        occupancy::write_map(&a.output, &map)?;
    } else {
        let cloud = if a.colour_by_height {
            olmap::render::height_coloured_cloud(&map, None)
        } else {
            map.to_cloud()
        };
        io::write_cloud(&a.output, &cloud, &WriteOptions::default())?;
    }
    println!("{} voxels -> {}", map.len(), a.output.display());
    Ok(ExitCode::SUCCESS)
}
