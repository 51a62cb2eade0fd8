//! `olmap demo`: the main job on built-in generated data, through the library's
//! [`olmap::sim::run_demo`]: simulate a team in the lab world, map it as a team and every
//! robot alone, compare both with the ground truth, write maps, poses and reports.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::sim::{run_demo, DemoConfig};

use crate::args::StageBars;

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

/// Runs `olmap demo`.
pub fn run(args: &DemoArgs) -> anyhow::Result<ExitCode> {
    let config = DemoConfig {
        out: args.out.clone(),
        robots: args.robots,
        scans_per_robot: args.scans_per_robot,
        seed: args.seed,
    };
    let mut bars = StageBars::new(args.json);
    let demo = run_demo(&config, &mut |stage, done, total| {
        bars.update(stage, done, total)
    })?;
    bars.finish();
    let r = &demo.report;
    if args.json {
        println!("{}", serde_json::to_string_pretty(r)?);
    } else {
        println!(
            "olmap demo: {} robots x {} stops in a simulated 20 x 20 m lab (seed {}), enhanced \
             rotating-mirror scanners, odometry degraded to ~0.5 m / 10° per move (thesis §6.5)",
            args.robots, args.scans_per_robot, args.seed
        );
        println!(
            "  dataset -> {} ({} sightings, {} of them mutual) in {:.1} s\n",
            demo.dataset_dir.display(),
            r.sightings,
            r.mutual_sightings,
            r.simulate_seconds
        );
        println!(
            "  position error of every scan against the ground truth, team vs each robot alone:"
        );
        print!("{}", super::team::table(&demo.run, &args.out));
        println!("  done in {:.1} s", r.total_seconds);
    }
    Ok(ExitCode::SUCCESS)
}
