//! `olmap team`: cooperative mapping of a multi-robot dataset (thesis §6.4-6.5), and the
//! pipeline `olmap demo` shares: merge the robots' scan stores, map as a team (sightings
//! confining the searches, seen robots cleared), optionally map every robot alone, compare
//! both with the ground truth, write the joint map, poses and a JSON report.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{ensure, Context};
use clap::Args;
use olmap::geometry::{Pose, PoseList};
use olmap::io::{self, WriteOptions};
use olmap::mapping::{evaluate, mean_median_max, position_histogram, Evaluation, Placement};
use olmap::occupancy;
use olmap::sim::read_dataset;
use olmap::team::{map_solo, map_team, scan_name, ScanStore, TeamMap, TeamParams};
use serde_json::{json, Value};

use crate::args::progress;

/// Arguments of `olmap team`.
#[derive(Args)]
pub struct TeamArgs {
    /// A dataset folder written by `olmap simulate` (manifest.json, robotN/, sightings.csv).
    pub dataset: PathBuf,
    /// Output folder (created if missing): team.olm / .ply / .bt, team_poses.txt,
    /// team.store, report.json (and solo/ with --solo).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Also map every robot alone (same mapper, no sightings) and compare.
    #[arg(long)]
    pub solo: bool,
    /// Do not clear the robots a scan saw (thesis §6.5.1) before it joins the map.
    #[arg(long)]
    pub no_clearing: bool,
    /// Print the JSON report instead of the summary table.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap team`.
pub fn run(args: &TeamArgs) -> anyhow::Result<ExitCode> {
    let data = read_dataset(&args.dataset)?;
    let store = data.to_store()?;
    let mut truth = PoseList::default();
    for (r, list) in data.truth.iter().enumerate() {
        for (k, p) in list.poses.iter().enumerate() {
            truth.push(scan_name(&store, r as u32, k as u32), p.pose);
        }
    }
    let mut params = TeamParams::default();
    if args.no_clearing {
        params.clearing = None;
    }
    let report = run_pipeline(
        &store,
        Some(&truth),
        &params,
        &args.out,
        args.solo,
        args.json,
    )?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report.json)?);
    } else {
        print!("{}", report.table);
    }
    Ok(ExitCode::SUCCESS)
}

/// What the pipeline produced: the JSON report (also written to `report.json`) and the
/// summary table.
pub struct PipelineReport {
    /// The report.
    pub json: Value,
    /// The table, ready to print.
    pub table: String,
}

/// Errors of one run against the truth, pooled: position errors in metres.
fn errors_m(e: &Evaluation) -> Vec<f64> {
    e.scans.iter().map(|s| s.error.translation_m).collect()
}

fn summary_json(errors: &[f64], placed: usize, scans: usize) -> Value {
    let n = errors.len().max(1) as f64;
    let share = |th: f64| errors.iter().filter(|e| **e > th).count() as f64 / n;
    let [mean, median, max] = mean_median_max(errors.to_vec());
    json!({
        "scans": scans,
        "placed": placed,
        "compared": errors.len(),
        "mean_m": mean,
        "median_m": median,
        "max_m": max,
        "share_above_0.3_m": share(0.3),
        "share_above_1_m": share(1.0),
        // Figure 6.11: bars of 0.1 m to 2 m, then everything beyond.
        "histogram": position_histogram(errors, 0.1, 2.0)
            .iter()
            .map(|b| json!({"from_m": b.from, "to_m": if b.to.is_finite() { json!(b.to) } else { json!(null) }, "count": b.count}))
            .collect::<Vec<_>>(),
    })
}

fn pose_json(p: &Pose) -> Value {
    let t = p.translation();
    let (yaw, pitch, roll) = p.yaw_pitch_roll();
    json!({"x": t.x, "y": t.y, "z": t.z, "yaw_deg": yaw.to_degrees(),
           "pitch_deg": pitch.to_degrees(), "roll_deg": roll.to_degrees()})
}

/// Writes the joint map as .olm, .ply (voxel centres coloured by height) and .bt, checking the .olm reads back.
fn write_maps(out: &Path, stem: &str, map: &olmap::occupancy::OccupancyList) -> anyhow::Result<()> {
    let olm = out.join(format!("{stem}.olm"));
    occupancy::write_map(&olm, map)?;
    ensure!(
        occupancy::read_map(&olm)?.map == *map,
        "{}: the map read back differs",
        olm.display()
    );
    occupancy::write_map(out.join(format!("{stem}.bt")), map)?;
    // Voxel centres coloured by height, counts as intensity: CloudCompare and MeshLab
    // show the colours.
    io::write_cloud(
        out.join(format!("{stem}.ply")),
        &olmap::render::height_coloured_cloud(map, None),
        &WriteOptions::default(),
    )?;
    Ok(())
}

/// The shared pipeline of `olmap team` and `olmap demo`.
pub fn run_pipeline(
    store: &ScanStore,
    truth: Option<&PoseList>,
    params: &TeamParams,
    out: &Path,
    solo: bool,
    quiet: bool,
) -> anyhow::Result<PipelineReport> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let total = store.len() as u64;
    let bar = progress(total, "team map", quiet);
    let team = map_team(store, params, |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    write_maps(out, "team", &team.build.map)?;
    let team_poses = team.poses();
    team_poses.write_path(out.join("team_poses.txt"))?;
    store.write(out.join("team.store"))?;

    let team_eval = truth.map(|t| evaluate(&team_poses, t)).transpose()?;
    let mut solo_runs: Vec<(u32, TeamMap, Option<Evaluation>)> = Vec::new();
    if solo {
        let bar = progress(total, "solo maps", quiet);
        let runs = map_solo(store, params, |done, _| bar.set_position(done as u64))?;
        bar.finish_and_clear();
        let dir = out.join("solo");
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        for (r, m) in runs {
            let name = store.robot_name(r);
            occupancy::write_map(dir.join(format!("{name}.olm")), &m.build.map)?;
            let poses = m.poses();
            poses.write_path(dir.join(format!("{name}_poses.txt")))?;
            let e = truth.map(|t| evaluate(&poses, t)).transpose()?;
            solo_runs.push((r, m, e));
        }
    }

    let name_of = |i: usize| {
        let (r, s) = team.keys[i];
        scan_name(store, r, s)
    };
    let placements: Vec<Value> = team
        .build
        .placed
        .iter()
        .map(|p| {
            let linked = match &p.via {
                Placement::Sighting { other, .. } => json!(name_of(*other)),
                _ => Value::Null,
            };
            let error = team_eval
                .as_ref()
                .and_then(|e| e.scans.iter().find(|s| s.name == p.name))
                .map(|s| json!({"position_m": s.error.translation_m, "rotation_deg": s.error.rotation_deg}));
            json!({"scan": p.name, "order": p.order, "placed_by": p.via.label(), "linked_scan": linked,
                   "overlap_fraction": p.overlap_fraction,
                   "significance": if p.significance.is_finite() { json!(p.significance) } else { Value::Null },
                   "pose": pose_json(&p.pose), "error": error})
        })
        .collect();
    let frames: Vec<Value> = team
        .frames
        .iter()
        .map(|f| {
            json!({"robot": f.name, "placed": f.placed, "scans": f.scans, "linked_by": f.linked_by,
                   "t_map_odom": f.pose.as_ref().map(pose_json)})
        })
        .collect();
    let mut relative = Vec::new();
    for a in &team.frames {
        for b in team.frames.iter().filter(|b| b.robot > a.robot) {
            if let Some(t) = team.relative(a.robot, b.robot) {
                relative.push(json!({"from": a.name, "to": b.name, "t_from_to": pose_json(&t)}));
            }
        }
    }
    let placed_team = team.build.placed.len();
    let team_summary = team_eval
        .as_ref()
        .map(|e| summary_json(&errors_m(e), placed_team, store.len()));
    let solo_errors: Vec<f64> = solo_runs
        .iter()
        .filter_map(|(_, _, e)| e.as_ref())
        .flat_map(errors_m)
        .collect();
    let solo_placed: usize = solo_runs.iter().map(|(_, m, _)| m.build.placed.len()).sum();
    let solo_summary =
        (solo && truth.is_some()).then(|| summary_json(&solo_errors, solo_placed, store.len()));
    let gross = |s: &Value| s["share_above_0.3_m"].as_f64().unwrap_or(0.0);
    let ratio = match (&team_summary, &solo_summary) {
        (Some(t), Some(s)) if gross(t) > 0.0 => json!(gross(s) / gross(t)),
        _ => Value::Null,
    };
    let report = json!({
        "format": "olmap-team-report",
        "version": 1,
        "scans": store.len(),
        "robots": store.robots().iter().map(|&r| store.robot_name(r)).collect::<Vec<_>>(),
        "links": team.links.iter().map(|(eq, n)| json!({"equation": eq, "count": n})).collect::<Vec<_>>(),
        "rejected_mutual_sightings": team.rejected_mutual,
        "cleared_points": team.cleared_points,
        "registrations": team.build.registrations,
        "seconds": team.build.seconds,
        "entropy_after_scan": team.build.entropy_after_scan,
        "voxels": team.build.map.len(),
        "resolution_m": team.build.map.resolution(),
        "frames": frames,
        "relative_frames": relative,
        "placements": placements,
        "rejected": team.build.rejected.iter().map(|r| json!({"scan": r.name, "reasons": r.reasons})).collect::<Vec<_>>(),
        "alone": team.alone.iter().map(|(r, m)| json!({"robot": store.robot_name(*r), "placed": m.placed.len()})).collect::<Vec<_>>(),
        "evaluation": {
            "team": team_summary,
            "solo": solo_summary,
            "solo_per_robot": solo_runs.iter().map(|(r, m, e)| json!({
                "robot": store.robot_name(*r),
                "placed": m.build.placed.len(),
                "summary": e.as_ref().map(|e| summary_json(&errors_m(e), m.build.placed.len(), m.keys.len())),
            })).collect::<Vec<_>>(),
            "gross_error_ratio_solo_over_team": ratio,
            "note": "errors relative to each map's first scan (team: the first robot's first scan; solo: each robot's own first scan); gross = position error > 0.3 m",
        },
        "files": {"map": ["team.olm", "team.ply", "team.bt"], "poses": "team_poses.txt", "store": "team.store"},
    });
    let path = out.join("report.json");
    olmap::file::write_atomic(&path, "JSON", |w| {
        serde_json::to_writer_pretty(&mut *w, &report).map_err(std::io::Error::other)
    })?;
    let html_path = write_html(store, &team, &solo_runs, &report, &path)?;

    let mut table = String::new();
    let row = |what: &str, s: &Option<Value>| match s {
        Some(s) => format!(
            "  {:<6} {:>5}/{:<5} {:>8.3} {:>9.3} {:>7.3} {:>8.1}% {:>6.1}%\n",
            what,
            s["placed"].as_u64().unwrap_or(0),
            s["scans"].as_u64().unwrap_or(0),
            s["mean_m"].as_f64().unwrap_or(0.0),
            s["median_m"].as_f64().unwrap_or(0.0),
            s["max_m"].as_f64().unwrap_or(0.0),
            100.0 * gross(s),
            100.0 * s["share_above_1_m"].as_f64().unwrap_or(0.0),
        ),
        None => String::new(),
    };
    table.push_str(&format!(
        "  {:<6} {:>11} {:>8} {:>9} {:>7} {:>9} {:>7}\n",
        "map", "placed", "mean m", "median m", "max m", ">0.3 m", ">1 m"
    ));
    table.push_str(&row("team", &team_summary));
    table.push_str(&row("solo", &solo_summary));
    if team_summary.is_none() {
        table.push_str(&format!(
            "  team: {placed_team}/{} scans placed (no ground truth to compare)\n",
            store.len()
        ));
    }
    let by: Vec<String> = team
        .links
        .iter()
        .map(|(eq, n)| format!("{n} {eq}"))
        .collect();
    table.push_str(&format!(
        "  sightings linked scans: {}; {} points of seen robots cleared\n",
        by.join(", "),
        team.cleared_points
    ));
    for f in &team.frames {
        table.push_str(&format!(
            "  {:<8} {}/{} scans in the joint map, joined by {}\n",
            f.name,
            f.placed,
            f.scans,
            f.linked_by.as_deref().unwrap_or("nothing (mapped alone)")
        ));
    }
    if let Some(r) = ratio.as_f64() {
        table.push_str(&format!("  gross errors (> 0.3 m), solo / team: {r:.1}x\n"));
    } else if let (Some(t), Some(s)) = (&team_summary, &solo_summary) {
        if gross(t) == 0.0 {
            table.push_str(&format!(
                "  gross errors (> 0.3 m): team none, solo {:.1}%\n",
                100.0 * gross(s)
            ));
        }
    }
    table.push_str(&format!(
        "  written to {} (report.json, {})\n",
        out.display(),
        html_path
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
    ));
    Ok(PipelineReport {
        json: report,
        table,
    })
}

/// The HTML report beside `report.json`: top views of the team map and of every robot's
/// own map, the error histogram, the entropy per scan, parameters and timings.
fn write_html(
    store: &ScanStore,
    team: &TeamMap,
    solo_runs: &[(u32, TeamMap, Option<Evaluation>)],
    report: &Value,
    json_path: &Path,
) -> anyhow::Result<std::path::PathBuf> {
    use super::html;
    let mut page = olmap::report::HtmlReport::new("olmap team report");
    let eval = &report["evaluation"];
    let num = |v: &Value| v.as_f64().map_or("-".to_string(), |x| format!("{x:.3}"));
    let percent = |v: &Value| {
        v.as_f64()
            .map_or("-".to_string(), |x| format!("{:.1}", 100.0 * x))
    };
    html::parameters(
        &mut page,
        &[
            ("scans", store.len().to_string()),
            ("robots", store.robots().len().to_string()),
            (
                "placed in the joint map",
                team.build.placed.len().to_string(),
            ),
            ("registrations", team.build.registrations.to_string()),
            ("voxels", team.build.map.len().to_string()),
            ("resolution (m)", team.build.map.resolution().to_string()),
            (
                "team mapping time (s)",
                format!("{:.2}", team.build.seconds),
            ),
            (
                "solo mapping time (s)",
                format!(
                    "{:.2}",
                    solo_runs
                        .iter()
                        .map(|(_, m, _)| m.build.seconds)
                        .sum::<f64>()
                ),
            ),
            (
                "points of seen robots cleared",
                team.cleared_points.to_string(),
            ),
            (
                "team mean / median / max error (m)",
                format!(
                    "{} / {} / {}",
                    num(&eval["team"]["mean_m"]),
                    num(&eval["team"]["median_m"]),
                    num(&eval["team"]["max_m"])
                ),
            ),
            (
                "solo mean / median / max error (m)",
                format!(
                    "{} / {} / {}",
                    num(&eval["solo"]["mean_m"]),
                    num(&eval["solo"]["median_m"]),
                    num(&eval["solo"]["max_m"])
                ),
            ),
            (
                "scans off by more than 0.3 m, team / solo (%)",
                format!(
                    "{} / {}",
                    percent(&eval["team"]["share_above_0.3_m"]),
                    percent(&eval["solo"]["share_above_0.3_m"])
                ),
            ),
            (
                "gross errors (> 0.3 m), solo / team",
                // No ratio when the team has no gross error.
                num(&eval["gross_error_ratio_solo_over_team"]),
            ),
        ],
    );
    page.heading("Team map");
    let robot_of = |i: usize| team.keys[i].0;
    html::top_view(
        &mut page,
        "The joint map of the team, in the first robot's first scan frame",
        &team.build.map,
        html::paths(&team.build, robot_of),
    )?;
    if !solo_runs.is_empty() {
        page.heading("Every robot alone");
        for (r, m, _) in solo_runs {
            let caption = format!(
                "{} mapping alone, in its own first scan's frame",
                store.robot_name(*r)
            );
            html::top_view(
                &mut page,
                &caption,
                &m.build.map,
                html::paths(&m.build, |_| *r),
            )?;
        }
    }
    html::error_histogram(&mut page, &eval["team"], &eval["solo"])?;
    html::entropy(&mut page, &team.build)?;
    page.heading("Report (report.json)");
    page.json(report);
    html::write_beside(&page, json_path)
}
