//! `olmap map` and `olmap eval`: building maps from many scans, and judging poses.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use olmap::align::icp::IcpParams;
use olmap::align::{Dof, RegisterParams, SearchParams};
use olmap::geometry::{Pose, PoseList};
use olmap::io::{self, slam6d, CloudFormat, ReadOptions};
use olmap::mapping::{build_map, evaluate, MapMode, MapParams, ScanInput};
use olmap::occupancy::{self, MapFormat, SensorModel};
use serde_json::json;

use super::align::DofArg;
use crate::args::{progress, set_threads};

/// Mapping modes on the command line.
#[derive(Clone, Copy, ValueEnum)]
pub enum ModeArg {
    /// Best overlap first (thesis §6.4.1): robust to scans in any order.
    Batch,
    /// In the given order (online).
    Sequential,
}

/// Arguments of `olmap map`.
#[derive(Args)]
pub struct MapArgs {
    /// Scans (any point-cloud format) or folders of scans (every cloud file in them, by
    /// name; a 3DTK folder holds scanNNN.3d files).
    pub scans: Vec<PathBuf>,
    /// A text file listing scan paths, one per line (relative to the file's folder).
    #[arg(long, value_name = "FILE")]
    pub list: Option<PathBuf>,
    /// Odometry `T_world_scan`: a pose file (pose list or CSV pose table, matched by scan
    /// name or in order), or `3dtk` to read each scan's sibling .pose file.
    #[arg(long, value_name = "FILE|3dtk")]
    pub odometry: Option<String>,
    /// Output map (.olm or .bt).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write the scan poses `T_map_scan` as a pose list.
    #[arg(long, value_name = "FILE")]
    pub poses_out: Option<PathBuf>,
    /// Write each placed scan's own occupancy list (sensor frame) as NAME.olm into this
    /// folder, with their poses in poses.txt: the scan-pose pairs the map can be rebuilt
    /// from when poses change.
    #[arg(long, value_name = "DIR")]
    pub scans_out: Option<PathBuf>,
    /// Write a JSON report (placed and rejected scans, reasons, timings) and, beside it with
    /// the extension `.html`, a self-contained HTML report (top view of the map with the
    /// scan path, map entropy after each scan, tables).
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    /// Batch (default) or sequential.
    #[arg(long, value_enum, default_value = "batch")]
    pub mode: ModeArg,
    /// Voxel edge of the map and of the finest search level, metres.
    #[arg(long, default_value_t = 0.1)]
    pub resolution: f64,
    /// Degrees of freedom of each registration.
    #[arg(long, value_enum, default_value = "xyz-yaw")]
    pub dof: DofArg,
    /// The scan defining the map frame (name or file stem; default the first).
    #[arg(long)]
    pub first: Option<String>,
    /// Ignore points farther than this from their sensor, metres (search and fusion).
    #[arg(long, default_value_t = 30.0)]
    pub max_range: f64,
    /// Fusion: skip scans taken within this distance of an already fused one (0: off).
    #[arg(long, default_value_t = 0.0)]
    pub bucket_radius: f64,
    /// Cleaning: drop voxels with a count below this (pixel mixing).
    #[arg(long, default_value_t = 1)]
    pub min_count: u16,
    /// Register with only the points between these heights in each scan's own frame,
    /// metres, e.g. `0.1,2.8` to leave out the floor and the ceiling (flat surfaces match
    /// anywhere and make the search ambiguous). The map keeps every point.
    #[arg(long, value_name = "ZMIN,ZMAX")]
    pub register_band: Option<String>,
    /// 3DTK .3d input: keep only returns between 20 cm and 3270 cm.
    #[arg(long = "3dtk-valid")]
    pub threedtk_valid: bool,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

fn is_cloud_file(p: &Path) -> bool {
    p.is_file()
        && p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
            CloudFormat::from_extension(e).is_some() || e.eq_ignore_ascii_case("bz2")
        })
}

fn scan_paths(a: &MapArgs) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in &a.scans {
        if p.is_dir() {
            let mut files: Vec<PathBuf> = std::fs::read_dir(p)
                .with_context(|| format!("cannot list {}", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| is_cloud_file(f))
                .collect();
            // A 3DTK folder also holds text files that are not scans.
            if files
                .iter()
                .any(|f| f.extension().is_some_and(|e| e == "3d"))
            {
                files.retain(|f| f.extension().is_some_and(|e| e == "3d"));
            }
            files.sort();
            out.extend(files);
        } else {
            out.push(p.clone());
        }
    }
    if let Some(list) = &a.list {
        let text = std::fs::read_to_string(list)
            .with_context(|| format!("cannot read {}", list.display()))?;
        let base = list.parent().unwrap_or(Path::new("."));
        for line in text
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
        {
            out.push(base.join(line));
        }
    }
    if out.is_empty() {
        bail!("no scans given (paths, folders or --list)");
    }
    Ok(out)
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}

fn odometry(a: &MapArgs, paths: &[PathBuf]) -> anyhow::Result<Vec<Option<Pose>>> {
    match a.odometry.as_deref() {
        None => Ok(vec![None; paths.len()]),
        Some("3dtk") => paths
            .iter()
            .map(|p| Ok(Some(slam6d::read_pose_path(p.with_extension("pose"))?)))
            .collect(),
        Some(file) => {
            let mut list = PoseList::default();
            super::poses::read_any(Path::new(file), false, &mut list)?;
            let by_order = list.len() == paths.len();
            paths
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let found = list
                        .get(&stem(p))
                        .or_else(|| by_order.then(|| &list.poses[i].pose));
                    found
                        .copied()
                        .map(Some)
                        .with_context(|| format!("{file}: no odometry pose for {}", stem(p)))
                })
                .collect()
        }
    }
}

/// Runs `olmap map`.
pub fn run_map(a: &MapArgs) -> anyhow::Result<ExitCode> {
    set_threads(a.threads)?;
    if MapFormat::from_path(&a.output).is_none() {
        bail!(
            "{}: the output must be a map file (.olm or .bt)",
            a.output.display()
        );
    }
    let paths = scan_paths(a)?;
    let odo = odometry(a, &paths)?;
    let read = ReadOptions {
        uos_valid_only: a.threedtk_valid,
        ..Default::default()
    };
    let bar = progress(paths.len() as u64, "read", a.json);
    let mut scans = Vec::with_capacity(paths.len());
    for (p, o) in paths.iter().zip(odo) {
        scans.push(ScanInput {
            name: stem(p),
            cloud: io::read_cloud_with(p, &read)?.cloud,
            odometry: o,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    let first = match &a.first {
        Some(name) => scans
            .iter()
            .position(|s| &s.name == name)
            .with_context(|| format!("--first {name}: no scan of that name"))?,
        None => 0,
    };
    let dof = match a.dof {
        DofArg::XyYaw => Dof::XyYaw,
        DofArg::XyzYaw => Dof::XyzYaw,
        DofArg::SixDof => Dof::six_dof(),
    };
    let params = MapParams {
        register: RegisterParams {
            search: SearchParams {
                resolution: a.resolution,
                dof,
                max_range: a.max_range,
                ..Default::default()
            },
            refine: Some(IcpParams::default()),
            trust: Default::default(),
        },
        mode: match a.mode {
            ModeArg::Batch => MapMode::Batch,
            ModeArg::Sequential => MapMode::Sequential,
        },
        first,
        sensor: SensorModel {
            max_range: a.max_range,
            ..Default::default()
        },
        bucket_radius: a.bucket_radius,
        min_count: a.min_count,
        keep_scan_maps: a.scans_out.is_some(),
        register_band: match &a.register_band {
            Some(s) => {
                let [lo, hi] = crate::args::parse_numbers::<2>(s, "--register-band")?;
                if lo >= hi {
                    anyhow::bail!("--register-band: ZMIN must be below ZMAX, got {s}");
                }
                Some((lo, hi))
            }
            None => None,
        },
        ..Default::default()
    };
    let bar = progress(scans.len() as u64, "map", a.json);
    let built = build_map(&scans, &params, |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    occupancy::write_map(&a.output, &built.map)?;
    let mut poses = PoseList::default();
    for p in &built.placed {
        poses.push(p.name.clone(), p.pose);
    }
    if let Some(out) = &a.poses_out {
        poses.write_path(out)?;
    }
    if let Some(dir) = &a.scans_out {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
        for s in &built.scan_maps {
            s.voxels
                .write_olm_path(dir.join(format!("{}.olm", s.name)))?;
        }
        poses.write_path(dir.join("poses.txt"))?;
    }
    let report = json!({
        "output": a.output.display().to_string(),
        "scans": scans.len(),
        "placed": built.placed.iter().map(|p| {
            let t = p.pose.translation();
            let (y, pi, r) = p.pose.yaw_pitch_roll();
            json!({"name": p.name, "order": p.order, "xyz_m": [t.x, t.y, t.z],
                   "yaw_pitch_roll_deg": [y.to_degrees(), pi.to_degrees(), r.to_degrees()],
                   "overlap_fraction": p.overlap_fraction,
                   "significance": if p.significance.is_finite() { json!(p.significance) } else { json!(null) },
                   "inlier_fraction": p.inlier_fraction, "global_search": p.global})
        }).collect::<Vec<_>>(),
        "rejected": built.rejected.iter().map(|r| json!({"name": r.name, "reasons": r.reasons})).collect::<Vec<_>>(),
        "registrations": built.registrations,
        "voxels": built.map.len(),
        "resolution": a.resolution,
        "seconds": built.seconds,
    });
    if let Some(path) = &a.report {
        olmap::file::write_atomic(path, "JSON report", |w| {
            serde_json::to_writer_pretty(&mut *w, &report).map_err(std::io::Error::other)
        })?;
        write_map_html(&built, scans.len(), a, &report, path)?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "{} of {} scans placed ({} registrations) in {:.2} s -> {} voxels at {} m -> {}",
            built.placed.len(),
            scans.len(),
            built.registrations,
            built.seconds,
            built.map.len(),
            a.resolution,
            a.output.display()
        );
        for p in &built.placed {
            let t = p.pose.translation();
            let (y, _, _) = p.pose.yaw_pitch_roll();
            println!(
                "  {:<20} #{:<3} ({:.3}, {:.3}, {:.3}) m, yaw {:.2} deg, overlap {:.0} %",
                p.name,
                p.order,
                t.x,
                t.y,
                t.z,
                y.to_degrees(),
                100.0 * p.overlap_fraction
            );
        }
        for r in &built.rejected {
            println!("  {:<20} REJECTED: {}", r.name, r.reasons.join("; "));
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Arguments of `olmap eval`.
#[derive(Args)]
pub struct EvalArgs {
    /// Estimated poses (pose list, CSV pose table, or 3DTK .frames/.pose).
    #[arg(long)]
    pub poses: PathBuf,
    /// Reference poses (same formats).
    #[arg(long)]
    pub reference: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap eval`.
pub fn run_eval(a: &EvalArgs) -> anyhow::Result<ExitCode> {
    let mut est = PoseList::default();
    super::poses::read_any(&a.poses, false, &mut est)?;
    let mut reference = PoseList::default();
    super::poses::read_any(&a.reference, false, &mut reference)?;
    let e = evaluate(&est, &reference)?;
    let s = &e.summary;
    if a.json {
        let v = json!({
            "frame": e.frame,
            "scans": e.scans.iter().map(|x| json!({"name": x.name, "translation_m": x.error.translation_m,
                "rotation_deg": x.error.rotation_deg, "dxyz_m": [x.error.dx_m, x.error.dy_m, x.error.dz_m],
                "dyaw_pitch_roll_deg": [x.error.yaw_deg, x.error.pitch_deg, x.error.roll_deg]})).collect::<Vec<_>>(),
            "missing": e.missing,
            "summary": {"scans": s.scans,
                "translation_m": {"mean": s.translation_m[0], "median": s.translation_m[1], "max": s.translation_m[2]},
                "rotation_deg": {"mean": s.rotation_deg[0], "median": s.rotation_deg[1], "max": s.rotation_deg[2]},
                "share_above_m": s.share_above_m.iter().map(|(t, f)| json!({"threshold": t, "share": f})).collect::<Vec<_>>(),
                "share_above_deg": s.share_above_deg.iter().map(|(t, f)| json!({"threshold": t, "share": f})).collect::<Vec<_>>()},
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(ExitCode::SUCCESS);
    }
    println!("frame: {} (both lists expressed relative to it)", e.frame);
    println!(
        "{:<20} {:>9} {:>9} {:>8} {:>8} {:>8} {:>8}",
        "scan", "trans [m]", "rot [deg]", "dx", "dy", "dz", "dyaw"
    );
    for x in &e.scans {
        println!(
            "{:<20} {:>9.4} {:>9.3} {:>8.4} {:>8.4} {:>8.4} {:>8.3}",
            x.name,
            x.error.translation_m,
            x.error.rotation_deg,
            x.error.dx_m,
            x.error.dy_m,
            x.error.dz_m,
            x.error.yaw_deg
        );
    }
    println!(
        "translation: mean {:.4}, median {:.4}, max {:.4} m; rotation: mean {:.3}, median {:.3}, max {:.3} deg",
        s.translation_m[0], s.translation_m[1], s.translation_m[2], s.rotation_deg[0], s.rotation_deg[1], s.rotation_deg[2]
    );
    for (t, f) in &s.share_above_m {
        print!("  > {t} m: {:.0} %", 100.0 * f);
    }
    println!();
    if !e.missing.is_empty() {
        println!("no reference for: {}", e.missing.join(", "));
    }
    Ok(ExitCode::SUCCESS)
}

/// The HTML report of `olmap map --report` beside the JSON one.
fn write_map_html(
    built: &olmap::mapping::MapBuild,
    scans: usize,
    a: &MapArgs,
    report: &serde_json::Value,
    json_path: &Path,
) -> anyhow::Result<()> {
    use super::html;
    let mut page = olmap::report::HtmlReport::new("olmap map report");
    html::parameters(
        &mut page,
        &[
            ("output", a.output.display().to_string()),
            ("scans", scans.to_string()),
            ("placed", built.placed.len().to_string()),
            ("rejected", built.rejected.len().to_string()),
            ("registrations", built.registrations.to_string()),
            ("voxels", built.map.len().to_string()),
            ("resolution (m)", a.resolution.to_string()),
            ("max range (m)", a.max_range.to_string()),
            ("mapping time (s)", format!("{:.2}", built.seconds)),
        ],
    );
    page.heading("Map");
    html::top_view(&mut page, "The map", &built.map, html::paths(built, |_| 0))?;
    html::entropy(&mut page, built)?;
    page.heading("Placed scans");
    let rows: Vec<Vec<String>> = built
        .placed
        .iter()
        .map(|p| {
            let t = p.pose.translation();
            vec![
                p.order.to_string(),
                p.name.clone(),
                format!("{:.3}, {:.3}, {:.3}", t.x, t.y, t.z),
                format!("{:.1}", p.pose.yaw_pitch_roll().0.to_degrees()),
                format!("{:.3}", p.overlap_fraction),
                p.via.label().to_string(),
            ]
        })
        .collect();
    page.table(
        &[
            "order",
            "scan",
            "x, y, z (m)",
            "yaw (°)",
            "overlap",
            "placed by",
        ],
        &rows,
    );
    if !built.rejected.is_empty() {
        page.heading("Rejected scans");
        let rows: Vec<Vec<String>> = built
            .rejected
            .iter()
            .map(|r| vec![r.name.clone(), r.reasons.join("; ")])
            .collect();
        page.table(&["scan", "reasons"], &rows);
    }
    page.heading("Report (JSON)");
    page.json(report);
    html::write_beside(&page, json_path)?;
    Ok(())
}
