//! `olmap grid2d`: build a 2D occupancy grid from planar laser scans and write it as a ROS
//! map (PGM + YAML).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::grid2d::{run_grid2d, Grid2dJob, SensorModel2d};

/// Arguments of `olmap grid2d`.
///
/// Each scan is placed by the pose whose name is the scan file's stem (`scan007.csv` takes
/// the pose `scan007`; the full file name is tried too), read from an olmap pose list as
/// `T_world_sensor`: the scanner's pose in the map, planar (yaw only; z, pitch and roll are
/// ignored by projecting the beams onto the map plane). Every beam is ray traced: cells it
/// crosses become more likely free, the cell of its return more likely occupied (thesis
/// §3.3.3). The map is written as MAP.pgm and MAP.yaml (ROS map_server: 0 occupied, 254
/// free, 205 unknown; occupied_thresh 0.65, free_thresh 0.196).
#[derive(Args)]
pub struct Grid2dArgs {
    /// 2D laser scans (olmap laser-scan CSV files), in the sensor frame.
    #[arg(required = true)]
    pub scans: Vec<PathBuf>,
    /// Pose list (olmap pose-list text) with one pose `T_world_sensor` per scan, named by
    /// the scan file's stem.
    #[arg(long, value_name = "POSES.txt")]
    pub poses: PathBuf,
    /// Output image (.pgm); the YAML file is written beside it with the extension .yaml.
    #[arg(short, long, value_name = "MAP.pgm")]
    pub output: PathBuf,
    /// Cell edge, metres.
    #[arg(long, default_value_t = 0.05)]
    pub resolution: f64,
    /// Position buckets: skip a scan taken within this distance (metres) of a scan already
    /// integrated, whatever its heading (thesis §3.3.3; 0 keeps every scan).
    #[arg(long, default_value_t = 0.0, value_name = "M")]
    pub bucket_radius: f64,
    /// Returns farther than this, and beams with no return, only clear free space up to
    /// this range, metres.
    #[arg(long, default_value_t = 8.0)]
    pub max_range: f64,
    /// Occupancy one return gives a cell of prior 0.5 (the sensor model's hit likelihood,
    /// thesis (3.16)); above 0.65 one return makes a cell occupied in the image.
    #[arg(long, default_value_t = 0.7, value_name = "P")]
    pub hit: f64,
    /// Occupancy one beam passing through gives a cell of prior 0.5; with the default 0.3 a
    /// cell needs two passes (from two scans) to be free in the image (below 0.196), with a
    /// value below 0.196 one pass is enough.
    #[arg(long, default_value_t = 0.3, value_name = "P")]
    pub pass: f64,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command.
pub fn run(a: &Grid2dArgs) -> anyhow::Result<ExitCode> {
    let d = SensorModel2d::default();
    let model = SensorModel2d::from_probabilities(
        a.hit,
        a.pass,
        SensorModel2d::probability(d.l_min),
        SensorModel2d::probability(d.l_max),
        a.max_range,
    )?;
    let run = run_grid2d(&Grid2dJob {
        scans: a.scans.clone(),
        poses: a.poses.clone(),
        output: a.output.clone(),
        resolution: a.resolution,
        bucket_radius: a.bucket_radius,
        model,
    })?;
    let r = &run.report;
    if a.json {
        println!("{}", serde_json::to_string_pretty(r)?);
    } else {
        println!(
            "{} scans ({} integrated) -> {} x {} cells at {} m in {:.2} s -> {} + {}",
            r.scans,
            r.scans_integrated,
            r.width,
            r.height,
            r.resolution,
            r.seconds,
            a.output.display(),
            r.yaml
        );
        if r.scans_skipped_by_buckets > 0 {
            println!(
                "  {} scans skipped: taken within {} m of an earlier one",
                r.scans_skipped_by_buckets, a.bucket_radius
            );
        }
        let c = &r.cells;
        println!(
            "  {:<10}{} free, {} occupied, {} unknown",
            "cells", c.free, c.occupied, c.unknown
        );
        let ([x0, y0], [x1, y1]) = (r.extent.min, r.extent.max);
        println!(
            "  {:<10}x {x0:.3} .. {x1:.3} m, y {y0:.3} .. {y1:.3} m",
            "extent"
        );
    }
    Ok(ExitCode::SUCCESS)
}
