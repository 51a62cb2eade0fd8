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
    /// The live team instead (feature `net`): five processes on loopback — the robots
    /// replaying their stops at 1 stop/s and a mapper — every node losing 20 % of what it
    /// sends, the mapper killed (SIGKILL) half way and restarted on its store; then the
    /// error table of the mapper's map and the network figures. Writes into OUT/live/
    /// (several minutes: the mapper re-maps the team as records arrive).
    #[arg(long)]
    pub live: bool,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap demo`.
pub fn run(args: &DemoArgs) -> anyhow::Result<ExitCode> {
    if args.live {
        return run_live(args);
    }
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

/// `olmap demo --live`.
#[cfg(feature = "net")]
fn run_live(args: &DemoArgs) -> anyhow::Result<ExitCode> {
    use olmap_net::demo::{run_live_demo, LiveDemoConfig};
    let mut cfg = LiveDemoConfig::new(std::env::current_exe()?, args.out.join("live"));
    cfg.robots = args.robots;
    cfg.scans_per_robot = args.scans_per_robot;
    cfg.seed = args.seed;
    let json = args.json;
    let r = run_live_demo(&cfg, |stage| {
        if !json {
            eprintln!("demo --live: {stage}");
        }
    })?;
    if json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(ExitCode::SUCCESS);
    }
    let t = &r.team;
    let f = |k: &str| t[k].as_f64().unwrap_or(f64::NAN);
    println!(
        "olmap demo --live: {} robots x {} stops as {} processes on loopback, 20 % message loss, \
         the mapper killed half way (restarted with {} of {} records)",
        args.robots,
        args.scans_per_robot,
        args.robots + 1,
        r.mapper_resumed_with
            .map_or("?".to_string(), |n| n.to_string()),
        r.records
    );
    println!(
        "  {:<6} {:>11} {:>8} {:>9} {:>7} {:>9} {:>7}",
        "map", "placed", "mean m", "median m", "max m", ">0.3 m", ">1 m"
    );
    println!(
        "  {:<6} {:>5}/{:<5} {:>8.3} {:>9.3} {:>7.3} {:>8.1}% {:>6.1}%",
        "live",
        t["placed"].as_u64().unwrap_or(0),
        t["scans"].as_u64().unwrap_or(0),
        f("mean_m"),
        f("median_m"),
        f("max_m"),
        100.0 * f("share_above_0.3_m"),
        100.0 * f("share_above_1_m")
    );
    println!(
        "  mapper's store: {}/{} records; {:.1} KiB per scan sent; {} records recovered by anti-entropy; {} messages dropped by the injected faults",
        r.mapper_records,
        r.records,
        r.bytes_per_scan / 1024.0,
        r.records_recovered,
        r.fault_dropped
    );
    if let Some([p50, p95, max]) = r.latency_ms {
        println!("  publish->placement latency after the restart: p50 {p50:.0} ms, p95 {p95:.0} ms, max {max:.0} ms");
    }
    println!(
        "  written to {} in {:.0} s",
        r.live.display(),
        r.total_seconds
    );
    Ok(ExitCode::SUCCESS)
}

/// `olmap demo --live` without the `net` feature.
#[cfg(not(feature = "net"))]
fn run_live(_: &DemoArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("this olmap was built without the `net` feature: no live demo")
}
