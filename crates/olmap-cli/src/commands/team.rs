//! `olmap team`: cooperative mapping of a multi-robot dataset (thesis §6.4-6.5) through the
//! library's team pipeline ([`olmap::team::run_team_pipeline`]), and the summary table
//! `olmap demo` prints too.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use olmap::mapping::posegraph::GraphRefineParams;
use olmap::sim::read_dataset;
use olmap::team::report::ErrorSummaryReport;
use olmap::team::{run_team_pipeline, ScanStore, TeamJob, TeamParams, TeamRun};

use crate::args::StageBars;

/// Arguments of `olmap team`.
#[derive(Args)]
pub struct TeamArgs {
    /// A dataset folder written by `olmap simulate` (manifest.json, robotN/, sightings.csv;
    /// a scan or pose file that cannot be read is skipped with a warning), or one or more
    /// scan-store files (`.store`, e.g. what `olmap robot` / `olmap mapper` hold, exported),
    /// merged into one.
    #[arg(required = true, num_args = 1..)]
    pub inputs: Vec<PathBuf>,
    /// With store files: the dataset folder that holds the ground truth to evaluate against.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Output folder (created if missing): team.olm / .ply / .bt, team_poses.txt,
    /// team.store, report.json, report.html (and solo/ with --solo).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Also map every robot alone (same mapper, no sightings) and compare.
    #[arg(long)]
    pub solo: bool,
    /// Do not clear the robots a scan saw (thesis §6.5.1) before it joins the map.
    #[arg(long)]
    pub no_clearing: bool,
    /// After placing, make the joint map's poses consistent with a pose graph: every scan
    /// registered again against its 4 nearest placed neighbours (within 6 m), mutual
    /// sightings with the thesis' error model (3.37), odometry (σ 0.1 m + 35 % of the
    /// distance, 2° + 10°/m), solved under a robust kernel; the map is fused at the refined
    /// poses and the report's `graph` says what it did.
    #[arg(long)]
    pub graph: bool,
    /// Print the JSON report instead of the summary table.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap team`.
pub fn run(args: &TeamArgs) -> anyhow::Result<ExitCode> {
    let (store, truth) = match args.inputs.as_slice() {
        [dir] if dir.is_dir() => {
            if args.truth.is_some() {
                anyhow::bail!("--truth is for store files: a dataset folder carries its own truth");
            }
            dataset_store(dir)?
        }
        files => {
            let mut store = ScanStore::new();
            for f in files {
                if f.is_dir() {
                    anyhow::bail!(
                        "{} is a folder: give one dataset folder, or scan-store files",
                        f.display()
                    );
                }
                store
                    .merge(&ScanStore::read(f)?)
                    .map_err(|e| anyhow::anyhow!("merging {}: {e}", f.display()))?;
            }
            // Truth for the scans the dataset holds, named as the team map names them
            // (the stores of robots replaying it use the dataset's robot names).
            let truth = match &args.truth {
                Some(dir) => dataset_store(dir)?.1,
                None => None,
            };
            (store, truth)
        }
    };
    if truth.is_none() {
        eprintln!("warning: without every robot's ground truth the maps are not evaluated");
    }
    let mut params = TeamParams::default();
    if args.no_clearing {
        params.clearing = None;
    }
    if args.graph {
        params.map.graph = Some(GraphRefineParams::default());
    }
    let mut bars = StageBars::new(args.json);
    let run = run_team_pipeline(
        &TeamJob {
            store: &store,
            truth: truth.as_ref(),
            params: &params,
            out: &args.out,
            solo: args.solo,
        },
        &mut |stage, done, total| bars.update(stage, done, total),
    )?;
    bars.finish();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&run.report)?);
    } else {
        print!("{}", table(&run, &args.out));
    }
    Ok(ExitCode::SUCCESS)
}

/// A dataset folder's store and (when every robot has it) ground truth.
fn dataset_store(dir: &Path) -> anyhow::Result<(ScanStore, Option<olmap::geometry::PoseList>)> {
    let data = read_dataset(dir)?;
    let (store, skipped_scans) = data.to_store_skipping()?;
    for s in data.skipped.iter().chain(&skipped_scans) {
        eprintln!("warning: skipped {}: {}", s.path, s.reason);
    }
    let truth = data.has_truth().then(|| data.truth_list(&store));
    Ok((store, truth))
}

/// One row of the error table.
fn row(what: &str, s: Option<&ErrorSummaryReport>) -> String {
    match s {
        Some(s) => format!(
            "  {:<6} {:>5}/{:<5} {:>8.3} {:>9.3} {:>7.3} {:>8.1}% {:>6.1}%\n",
            what,
            s.placed,
            s.scans,
            s.mean_m,
            s.median_m,
            s.max_m,
            100.0 * s.share_above_gross,
            100.0 * s.share_above_large,
        ),
        None => String::new(),
    }
}

/// The summary table of a team run written to `out`.
pub fn table(run: &TeamRun, out: &Path) -> String {
    let report = &run.report;
    let (team, solo) = (
        report.evaluation.team.as_ref(),
        report.evaluation.solo.as_ref(),
    );
    let mut table = format!(
        "  {:<6} {:>11} {:>8} {:>9} {:>7} {:>9} {:>7}\n",
        "map", "placed", "mean m", "median m", "max m", ">0.3 m", ">1 m"
    );
    table.push_str(&row("team", team));
    table.push_str(&row("solo", solo));
    if team.is_none() {
        table.push_str(&format!(
            "  team: {}/{} scans placed (no ground truth to compare)\n",
            run.team.build.placed.len(),
            report.scans
        ));
    }
    let by: Vec<String> = report
        .links
        .iter()
        .map(|l| format!("{} {}", l.count, l.equation))
        .collect();
    table.push_str(&format!(
        "  sightings linked scans: {}; {} points of seen robots cleared\n",
        by.join(", "),
        report.cleared_points
    ));
    for f in &report.frames {
        table.push_str(&format!(
            "  {:<8} {}/{} scans in the joint map, joined by {}\n",
            f.robot,
            f.placed,
            f.scans,
            f.linked_by.as_deref().unwrap_or("nothing (mapped alone)")
        ));
    }
    if let Some(r) = report.evaluation.gross_error_ratio_solo_over_team {
        table.push_str(&format!("  gross errors (> 0.3 m), solo / team: {r:.1}x\n"));
    } else if let (Some(t), Some(s)) = (team, solo) {
        if t.share_above_gross == 0.0 {
            table.push_str(&format!(
                "  gross errors (> 0.3 m): team none, solo {:.1}%\n",
                100.0 * s.share_above_gross
            ));
        }
    }
    let html = run
        .html
        .as_ref()
        .and_then(|p| p.file_name())
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    table.push_str(&format!(
        "  written to {} (report.json, {html})\n",
        out.display()
    ));
    table
}
