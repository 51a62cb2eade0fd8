//! `olmap map`: a map built from many scans through the library's
//! [`olmap::mapping::run_map_job`].

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use clap::{Args, ValueEnum};
use olmap::align::icp::IcpParams;
use olmap::align::{RegisterParams, SearchParams};
use olmap::io::{self, ReadOptions};
use olmap::mapping::{run_map_job, MapJob, MapMode, MapParams, OdometrySource};
use olmap::occupancy::{MapFormat, SensorModel};

use crate::args::{set_threads, DofArgs, StageBars, ThreadsArgs};

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
    #[command(flatten)]
    pub dof: DofArgs,
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
    #[command(flatten)]
    pub threads: ThreadsArgs,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The mapping parameters the arguments ask for.
fn map_params(a: &MapArgs) -> anyhow::Result<MapParams> {
    let dof = a.dof.dof();
    Ok(MapParams {
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
                    bail!("--register-band: ZMIN must be below ZMAX, got {s}");
                }
                Some((lo, hi))
            }
            None => None,
        },
        ..Default::default()
    })
}

/// Runs `olmap map`.
pub fn run(a: &MapArgs) -> anyhow::Result<ExitCode> {
    set_threads(a.threads.threads)?;
    MapFormat::of_output(&a.output)?;
    let job = MapJob {
        scans: io::scan_files(&a.scans, a.list.as_deref())?,
        odometry: match a.odometry.as_deref() {
            None => OdometrySource::None,
            Some("3dtk") => OdometrySource::Sidecar3dtk,
            Some(file) => OdometrySource::File(file.into()),
        },
        read: ReadOptions {
            uos_valid_only: a.threedtk_valid,
            ..Default::default()
        },
        first: a.first.clone(),
        params: map_params(a)?,
        output: a.output.clone(),
        poses_out: a.poses_out.clone(),
        scans_out: a.scans_out.clone(),
        report: a.report.clone(),
    };
    let mut bars = StageBars::new(a.json);
    let run = run_map_job(&job, &mut |stage, done, total| {
        bars.update(stage, done, total)
    })?;
    bars.finish();
    let (built, report) = (&run.build, &run.report);
    if a.json {
        println!("{}", serde_json::to_string_pretty(report)?);
    } else {
        println!(
            "{} of {} scans placed ({} registrations) in {:.2} s -> {} voxels at {} m -> {}",
            built.placed.len(),
            report.scans,
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
