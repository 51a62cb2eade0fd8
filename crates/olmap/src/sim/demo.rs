//! [`run_demo`]: `olmap demo`, the main job on built-in generated data. Simulates a team of
//! robots in the lab world (thesis §6.5: rotating-mirror 3D scanners and beacons,
//! stop-and-scan, odometry degraded to about 0.5 m / 10°), writes the dataset, merges the
//! robots' own stores as they would when they meet, and runs the team pipeline with every
//! robot alone for comparison.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use super::files::{read_dataset, write_dataset_into};
use super::{simulate, OdometryNoise, SimConfig, WorldKind};
use crate::error::{Error, Result};
use crate::file::OutputSet;
use crate::progress::{Progress, Stage};
use crate::team::{
    declare_team_outputs, team_run_into, ScanStore, TeamJob, TeamParams, TeamReport, TeamRun,
};

/// What the demo runs.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoConfig {
    /// Folder for everything it writes (the dataset in `dataset/`).
    pub out: PathBuf,
    /// Robots in the team (at least 1).
    pub robots: usize,
    /// Stop-and-scan positions per robot (at least 2).
    pub scans_per_robot: usize,
    /// Seed of the simulation.
    pub seed: u64,
}

impl Default for DemoConfig {
    /// Four robots, ten stops each, seed 1, into `olmap-demo`.
    fn default() -> Self {
        DemoConfig {
            out: PathBuf::from("olmap-demo"),
            robots: 4,
            scans_per_robot: 10,
            seed: 1,
        }
    }
}

/// The demo's report: the team report and what was simulated.
#[derive(Debug, Clone, Serialize)]
pub struct DemoReport {
    /// The team run's report (as in `OUT/report.json`).
    #[serde(flatten)]
    pub team: TeamReport,
    /// The dataset folder.
    pub dataset: String,
    /// The simulated world.
    pub world: String,
    /// The simulation's seed.
    pub seed: u64,
    /// Sightings between robots.
    pub sightings: usize,
    /// Of them, mutual (both robots saw each other).
    pub mutual_sightings: usize,
    /// Time to simulate and write the dataset, seconds.
    pub simulate_seconds: f64,
    /// Time of the whole demo, seconds.
    pub total_seconds: f64,
}

/// What [`run_demo`] produced.
#[derive(Debug, Clone)]
pub struct DemoRun {
    /// The report.
    pub report: DemoReport,
    /// The team run behind it.
    pub run: TeamRun,
    /// Where the dataset was written.
    pub dataset_dir: PathBuf,
}

/// Refuses to replace `dir` unless it is missing or a dataset an earlier demo wrote (its
/// manifest reads as one).
fn check_old_dataset(dir: &Path) -> Result<()> {
    if !dir.exists() {
        return Ok(());
    }
    read_dataset(dir).map_err(|e| {
        Error::InvalidArgument(format!(
            "{} exists and is not an olmap dataset; not touching it: {e}",
            dir.display()
        ))
    })?;
    Ok(())
}

impl SimConfig {
    /// The demo's team: the lab world, the thesis' degraded odometry (§6.5), `robots`
    /// robots of `stops` stops each, drawn from `seed` (the demo itself: seed 1, 4 x 10).
    /// Benchmarks and the live demo simulate the same team from it.
    pub fn demo_lab(seed: u64, robots: usize, stops: usize) -> Self {
        SimConfig {
            world: WorldKind::Lab,
            seed,
            robots,
            stops,
            odometry: OdometryNoise::degraded(),
            ..Default::default()
        }
    }
}

/// Runs the demo ([`Stage::Simulate`], then the team pipeline's stages). Every output is
/// checked before simulating, and the dataset and the team run's files are written as one
/// [`OutputSet`]: a failed or killed demo leaves the older demo's outputs (or nothing),
/// never a mixture.
pub fn run_demo(config: &DemoConfig, progress: Progress<'_>) -> Result<DemoRun> {
    if config.robots < 1 || config.scans_per_robot < 2 {
        return Err(Error::InvalidArgument(
            "the demo needs at least one robot and two scans per robot".into(),
        ));
    }
    let start = Instant::now();
    let mut set = OutputSet::new();
    declare_team_outputs(&mut set, &config.out, true)?;
    let dataset_dir = config.out.join("dataset");
    check_old_dataset(&dataset_dir)?;
    set.dir(&dataset_dir, "dataset folder")?;
    let sim = SimConfig::demo_lab(config.seed, config.robots, config.scans_per_robot);
    let data = simulate(&sim, |done, total| progress(Stage::Simulate, done, total))?;
    write_dataset_into(&set.path(&dataset_dir)?, &data)?;
    let simulate_seconds = start.elapsed().as_secs_f64();

    // Every robot's own store, merged as the robots would when they meet (§6.3.2).
    let all = data.to_store()?;
    let mut store = ScanStore::new();
    for r in all.robots() {
        store.merge(&all.robot_store(r))?;
    }
    if store != all {
        return Err(Error::InvalidArgument(
            "the merged robot stores differ from the whole".into(),
        ));
    }
    let truth = data.truth_list(&store);
    let run = team_run_into(
        &mut set,
        &TeamJob {
            store: &store,
            truth: Some(&truth),
            params: &TeamParams::default(),
            out: &config.out,
            solo: true,
        },
        progress,
    )?;
    set.commit()?;
    let report = DemoReport {
        team: run.report.clone(),
        dataset: dataset_dir.display().to_string(),
        world: "lab".into(),
        seed: config.seed,
        sightings: data.sightings.len(),
        mutual_sightings: data.sightings.iter().filter(|s| s.mutual).count(),
        simulate_seconds,
        total_seconds: start.elapsed().as_secs_f64(),
    };
    Ok(DemoRun {
        report,
        run,
        dataset_dir,
    })
}
