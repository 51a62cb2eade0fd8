//! `olmap scanner`: tools for a rotating-mirror 3D scanner (thesis §4.3-4.5): convert its
//! raw log to a point cloud, check the repeatability of two scans.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context};
use clap::{Args, Subcommand};
use olmap::io::{self, WriteOptions};
use olmap::scanner::{
    convert_log, repeatability, ConvertParams, MirrorLog, RepeatabilityParams, ScannerConvertReport,
};

/// Arguments of `olmap scanner`.
#[derive(Args)]
pub struct ScannerArgs {
    /// What to do.
    #[command(subcommand)]
    pub command: ScannerCommand,
}

/// The `olmap scanner` subcommands.
#[derive(Subcommand)]
pub enum ScannerCommand {
    /// Convert a raw mirror-scanner log (olmap mirror log v1) into a 3D point cloud in the
    /// sensor frame: mirror angle interpolated in the encoder history (4.9), phi advancing
    /// within each sweep, (4.10), blind readings removed.
    Convert(ConvertRawArgs),
    /// Closest-point distances between two scans from the same pose (thesis §4.5): mean,
    /// median, mode and the share above a threshold.
    Repeatability(RepeatabilityArgs),
}

/// Arguments of `olmap scanner convert`.
#[derive(Args)]
pub struct ConvertRawArgs {
    /// The raw log.
    pub input: PathBuf,
    /// The cloud to write (format from the extension: .pcd, .ply, .xyz, ...).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Remove mixed pixels (range discontinuities along theta and phi, §4.4.1).
    #[arg(long)]
    pub filter_mixed: bool,
    /// Convert every beam of a sweep at the sweep's timestamp (no within-sweep correction).
    #[arg(long)]
    pub no_sweep_correction: bool,
    /// Longest range kept, metres (default: the log header's max_range).
    #[arg(long)]
    pub max_range: Option<f64>,
    /// Shortest range kept, metres.
    #[arg(long, default_value_t = 0.0)]
    pub min_range: f64,
    /// Print a JSON report.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `olmap scanner repeatability`.
#[derive(Args)]
pub struct RepeatabilityArgs {
    /// The first scan (any cloud format).
    pub a: PathBuf,
    /// The second scan, same frame.
    pub b: PathBuf,
    /// Distance counted as a discrepancy, metres.
    #[arg(long, default_value_t = 0.02)]
    pub threshold: f64,
    /// Histogram bin width for the mode, metres.
    #[arg(long, default_value_t = 0.002)]
    pub bin: f64,
    /// Print a JSON report.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap scanner`.
pub fn run(a: &ScannerArgs) -> anyhow::Result<ExitCode> {
    match &a.command {
        ScannerCommand::Convert(c) => convert(c),
        ScannerCommand::Repeatability(r) => repeat(r),
    }
}

fn convert(a: &ConvertRawArgs) -> anyhow::Result<ExitCode> {
    let start = Instant::now();
    olmap::file::check_output(&a.output, "point cloud")?;
    if let Some(m) = a.max_range {
        if !(m.is_finite() && m > 0.0) {
            bail!("--max-range must be a positive number of metres, got {m}");
        }
    }
    if !(a.min_range.is_finite() && a.min_range >= 0.0) {
        bail!("--min-range must be a non-negative number of metres");
    }
    let log = MirrorLog::read_path(&a.input)?;
    let params = ConvertParams {
        within_sweep_correction: !a.no_sweep_correction,
        max_range: a.max_range,
        min_range: a.min_range,
        filter_mixed: a.filter_mixed,
        ..ConvertParams::default()
    };
    let out =
        convert_log(&log, &params).with_context(|| format!("converting {}", a.input.display()))?;
    io::write_cloud(&a.output, &out.cloud, &WriteOptions::default())?;
    let s = out.stats;
    let seconds = start.elapsed().as_secs_f64();
    if a.json {
        let v = ScannerConvertReport::new(
            &a.input.display().to_string(),
            &a.output.display().to_string(),
            log.header.mounting.name(),
            &s,
            params.within_sweep_correction,
            seconds,
        );
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "{} ({} mounting, {} sweeps, {} beams) -> {} ({} points) in {:.2} s",
            a.input.display(),
            log.header.mounting.name(),
            s.sweeps,
            s.beams,
            a.output.display(),
            s.points,
            seconds
        );
        println!(
            "dropped: {} no return, {} outside the mirror, {} edge on, {} blocked, {} beyond \
             max range, {} below min range, {} mixed pixels",
            s.no_return,
            s.outside_mirror,
            s.edge_on,
            s.blocked,
            s.beyond_max_range,
            s.below_min_range,
            s.mixed_pixels
        );
        if s.trigger_mismatches > 0 {
            println!(
                "warning: {} trigger(s) disagree with the tick count (missed ticks?)",
                s.trigger_mismatches
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn repeat(a: &RepeatabilityArgs) -> anyhow::Result<ExitCode> {
    let ca = io::read_cloud(&a.a)?.cloud;
    let cb = io::read_cloud(&a.b)?.cloud;
    let params = RepeatabilityParams {
        bin_width: a.bin,
        threshold: a.threshold,
    };
    let r = repeatability(&ca, &cb, &params)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{} points of {} against {}: mean {:.4} m, median {:.4} m, mode {:.4} m, max \
             {:.4} m, {:.2} % above {} m",
            r.points,
            a.a.display(),
            a.b.display(),
            r.mean,
            r.median,
            r.mode,
            r.max,
            100.0 * r.share_above,
            r.threshold
        );
    }
    Ok(ExitCode::SUCCESS)
}
