//! `olmap navgrid`: the navigation grid a planner needs (thesis §7.3) from a map and its
//! scan poses, written as a ROS map.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use clap::Args;
use olmap::geometry::{Pose, PoseList};
use olmap::grid2d::{navigation_grid, write_ros_map, NavGridParams, NavgridReport};

use super::render::{parse_band, read};

/// Arguments of `olmap navgrid`.
#[derive(Args)]
pub struct NavgridArgs {
    /// The map (.olm or OctoMap .bt).
    pub map: PathBuf,
    /// The scan poses (pose list, e.g. written by `olmap map --poses-out`): rays are traced
    /// from their positions.
    #[arg(long, value_name = "FILE")]
    pub poses: PathBuf,
    /// The robot-height band, metres: voxels with centres in it are obstacles.
    #[arg(
        long,
        value_name = "ZMIN,ZMAX",
        default_value = "0.1,1.2",
        allow_hyphen_values = true
    )]
    pub band: String,
    /// Output PGM image (the ROS map_server YAML is written beside it).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Cell size, metres (default: the map's resolution).
    #[arg(long)]
    pub resolution: Option<f64>,
    /// Rays from a scan position reach at most this far, metres.
    #[arg(long, default_value_t = 30.0)]
    pub max_range: f64,
    /// Only voxels with at least this count are obstacles.
    #[arg(long, default_value_t = 1)]
    pub min_count: u16,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap navgrid`.
pub fn run(a: &NavgridArgs) -> anyhow::Result<ExitCode> {
    olmap::grid2d::check_ros_map_output(&a.output)?;
    let map = read(&a.map)?;
    let poses: Vec<Pose> = PoseList::read_path(&a.poses)?
        .poses
        .iter()
        .map(|p| p.pose)
        .collect();
    let params = NavGridParams {
        resolution: a.resolution,
        band: parse_band(&a.band, "--band")?,
        max_range: a.max_range,
        min_count: a.min_count,
        ..NavGridParams::default()
    };
    let grid = navigation_grid(&map, &poses, &params)?;
    if grid.width == 0 {
        bail!(
            "{}: no voxel in the band and no pose: nothing to grid",
            a.map.display()
        );
    }
    let yaml = write_ros_map(&a.output, &grid)?;
    let r = NavgridReport::new(
        &grid,
        poses.len(),
        &a.output.display().to_string(),
        &yaml.display().to_string(),
    );
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{} x {} cells at {} m from {} poses: {} free, {} occupied, {} unknown -> {} + {}",
            r.width,
            r.height,
            r.resolution_m,
            r.poses,
            r.free,
            r.occupied,
            r.unknown,
            r.pgm,
            r.yaml
        );
    }
    Ok(ExitCode::SUCCESS)
}
