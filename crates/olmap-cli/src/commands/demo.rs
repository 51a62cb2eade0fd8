//! `olmap demo`: the main job on built-in generated data.
//!
//! Simulates a team of robots in the lab world (thesis §6.5: four robots with rotating-
//! mirror 3D scanners and beacons, stop-and-scan, odometry degraded to about 0.5 m / 10°),
//! writes the dataset, merges the robots' scan stores, maps them as a team (sightings
//! confining the searches, seen robots cleared) and every robot alone, compares both with
//! the ground truth (the thesis' Figure 6.11 in the report) and writes the joint map
//! (`team.olm`, `.ply`, `.bt`), the poses and `report.json`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{ensure, Context};
use clap::Args;
use olmap::geometry::PoseList;
use olmap::sim::{read_dataset, write_dataset};
use olmap::sim::{simulate, OdometryNoise, SimConfig, WorldKind};
use olmap::team::{scan_name, ScanStore, TeamParams};
use serde_json::json;

use super::team::run_pipeline;
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
        odometry: OdometryNoise::degraded(),
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

    // Every robot's own store, merged as the robots would when they meet (§6.3.2).
    let all = data.to_store()?;
    let mut store = ScanStore::new();
    for r in all.robots() {
        store.merge(&all.robot_store(r))?;
    }
    ensure!(
        store == all,
        "the merged robot stores differ from the whole"
    );
    let mut truth = PoseList::default();
    for (r, robot) in data.robots.iter().enumerate() {
        for (k, t) in robot.truth.iter().enumerate() {
            truth.push(scan_name(&store, r as u32, k as u32), *t);
        }
    }
    let report = run_pipeline(
        &store,
        Some(&truth),
        &TeamParams::default(),
        &args.out,
        true,
        args.json,
    )?;
    let seconds = start.elapsed().as_secs_f64();
    let mutual = data.sightings.iter().filter(|s| s.mutual).count();
    if args.json {
        let mut v = report.json;
        v["dataset"] = json!(dataset_dir.display().to_string());
        v["world"] = json!("lab");
        v["seed"] = json!(args.seed);
        v["sightings"] = json!(data.sightings.len());
        v["mutual_sightings"] = json!(mutual);
        v["simulate_seconds"] = json!(sim_seconds);
        v["total_seconds"] = json!(seconds);
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "olmap demo: {} robots x {} stops in a simulated 20 x 20 m lab (seed {}), enhanced \
             rotating-mirror scanners, odometry degraded to ~0.5 m / 10° per move (thesis §6.5)",
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
            "  position error of every scan against the ground truth, team vs each robot alone:"
        );
        print!("{}", report.table);
        println!("  done in {seconds:.1} s");
    }
    Ok(ExitCode::SUCCESS)
}
