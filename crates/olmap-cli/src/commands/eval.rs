//! `olmap eval`: estimated poses judged against reference poses.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::io;
use olmap::mapping::{evaluate, EvalReport};

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
pub fn run(a: &EvalArgs) -> anyhow::Result<ExitCode> {
    let est = io::read_poses(&a.poses)?;
    let reference = io::read_poses(&a.reference)?;
    let e = evaluate(&est, &reference)?;
    let s = &e.summary;
    if a.json {
        let v = EvalReport::from(&e);
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
