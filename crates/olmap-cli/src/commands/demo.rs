//! `olmap demo`: the main job on built-in generated data.
//!
//! Simulates a team of robots in the lab world (thesis §6.5: four robots with rotating-
//! mirror 3D scanners and beacons, stop-and-scan, odometry with error), writes the dataset,
//! then has every robot build its own map from its scans and odometry (batch mapper,
//! registration in the 0.1-2.8 m band) and compares every scan pose with the ground truth.
//! The cooperative team mapper (sightings joining the robots' maps) takes over this
//! pipeline when it exists; until then each robot maps alone, in its own frame.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{ensure, Context};
use clap::Args;
use olmap::geometry::PoseList;
use olmap::io::sim_dataset::{read_dataset, write_dataset};
use olmap::mapping::{build_map, evaluate, MapParams};
use olmap::occupancy;
use olmap::sim::{simulate, SimConfig, WorldKind};
use serde_json::json;

use crate::args::progress;

/// Arguments of `olmap demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Folder for the generated files (created if missing; a dataset left there by an
    /// earlier demo is replaced).
    #[arg(long, default_value = "olmap-demo")]
    pub out: PathBuf,
    /// Robots in the team.
    #[arg(long, default_value_t = 4)]
    pub robots: usize,
    /// Stop-and-scan positions per robot.
    #[arg(long, default_value_t = 10)]
    pub scans_per_robot: usize,
    /// Seed of the simulation (the same seed gives the same dataset).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Removes `dir` only if it is a dataset an earlier demo wrote (its manifest reads as one).
fn clear_old_dataset(dir: &Path) -> anyhow::Result<()> {
    if !dir.exists() {
        return Ok(());
    }
    read_dataset(dir).with_context(|| {
        format!(
            "{} exists and is not an olmap dataset; not touching it",
            dir.display()
        )
    })?;
    std::fs::remove_dir_all(dir).with_context(|| format!("cannot remove {}", dir.display()))
}

/// Runs `olmap demo`.
pub fn run(args: &DemoArgs) -> anyhow::Result<ExitCode> {
    ensure!(
        args.robots >= 1 && args.scans_per_robot >= 2,
        "the demo needs at least one robot and two scans per robot"
    );
    let start = Instant::now();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let config = SimConfig {
        world: WorldKind::Lab,
        seed: args.seed,
        robots: args.robots,
        stops: args.scans_per_robot,
        ..Default::default()
    };
    let total = (args.robots * args.scans_per_robot) as u64;
    let bar = progress(total, "simulate", args.json);
    let data = simulate(&config, |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    let dataset_dir = args.out.join("dataset");
    clear_old_dataset(&dataset_dir)?;
    write_dataset(&dataset_dir, &data)?;
    let sim_seconds = start.elapsed().as_secs_f64();

    let params = MapParams {
        register_band: Some((0.1, 2.8)),
        keep_scan_maps: false,
        ..Default::default()
    };
    let bar = progress(total, "map", args.json);
    let mut rows = Vec::new();
    for (r, robot) in data.robots.iter().enumerate() {
        let scans = robot.scan_inputs();
        let done_before = (r * args.scans_per_robot) as u64;
        let built = build_map(&scans, &params, |done, _| {
            bar.set_position(done_before + done as u64)
        })?;
        let map_path = args.out.join(format!("{}.olm", robot.name));
        occupancy::write_map(&map_path, &built.map)?;
        ensure!(
            occupancy::read_map(&map_path)?.map == built.map,
            "{}: the map read back differs",
            map_path.display()
        );
        let mut estimate = PoseList::default();
        for p in &built.placed {
            estimate.push(p.name.clone(), p.pose);
        }
        let poses_path = args.out.join(format!("{}_poses.txt", robot.name));
        estimate.write_path(&poses_path)?;
        let mut truth = PoseList::default();
        for (k, t) in robot.truth.iter().enumerate() {
            truth.push(format!("scan{k:03}"), *t);
        }
        let eval = evaluate(&estimate, &truth)?;
        rows.push((robot.name.clone(), built, eval, map_path));
    }
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    let mutual = data.sightings.iter().filter(|s| s.mutual).count();
    if args.json {
        let robots: Vec<_> = rows
            .iter()
            .map(|(name, built, eval, path)| {
                json!({
                    "name": name,
                    "placed": built.placed.len(),
                    "scans": args.scans_per_robot,
                    "map": path.display().to_string(),
                    "voxels": built.map.len(),
                    "translation_error_m": {"mean": eval.summary.translation_m[0],
                        "median": eval.summary.translation_m[1], "max": eval.summary.translation_m[2]},
                    "rotation_error_deg": {"mean": eval.summary.rotation_deg[0],
                        "median": eval.summary.rotation_deg[1], "max": eval.summary.rotation_deg[2]},
                    "seconds": built.seconds,
                })
            })
            .collect();
        let v = json!({
            "dataset": dataset_dir.display().to_string(),
            "world": "lab",
            "seed": args.seed,
            "points": data.robots.iter().flat_map(|r| r.scans.iter().map(|s| s.len())).sum::<usize>(),
            "sightings": data.sightings.len(),
            "mutual_sightings": mutual,
            "robots": robots,
            "simulate_seconds": sim_seconds,
            "seconds": seconds,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "olmap demo: {} robots x {} stops in a simulated 20 x 20 m lab (seed {}), enhanced \
             rotating-mirror scanners, odometry with error",
            args.robots, args.scans_per_robot, args.seed
        );
        println!(
            "  dataset -> {} ({} sightings, {} of them mutual) in {:.1} s\n",
            dataset_dir.display(),
            data.sightings.len(),
            mutual,
            sim_seconds
        );
        println!(
            "  each robot maps alone (batch mapper, odometry windows, 0.1-2.8 m registration band):"
        );
        println!(
            "  {:<8} {:>7} {:>9} {:>12} {:>11} {:>11} {:>8}",
            "robot", "placed", "voxels", "mean err m", "max err m", "max deg", "time s"
        );
        for (name, built, eval, _) in &rows {
            println!(
                "  {:<8} {:>3}/{:<3} {:>9} {:>12.3} {:>11.3} {:>11.2} {:>8.1}",
                name,
                built.placed.len(),
                args.scans_per_robot,
                built.map.len(),
                eval.summary.translation_m[0],
                eval.summary.translation_m[2],
                eval.summary.rotation_deg[2],
                built.seconds
            );
        }
        println!(
            "\n  maps and poses (each in its robot's first-scan frame) in {}; done in {seconds:.1} s",
            args.out.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}
