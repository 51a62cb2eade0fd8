//! `olmap mutual`: the relative pose of two robots from a two-way beacon sighting.

use std::process::ExitCode;

use clap::Args;
use olmap::team::{expected_position_error, mutual_pose, MutualObservation, MutualParams};
use serde_json::json;

/// Arguments of `olmap mutual`.
#[derive(Args)]
pub struct MutualArgs {
    /// Range from robot A's scanner to B's beacon, metres.
    #[arg(long)]
    pub a: f64,
    /// Bearing of B's beacon as A sees it, degrees (positive to the left).
    #[arg(long, allow_hyphen_values = true)]
    pub alpha: f64,
    /// Range from robot B's scanner to A's beacon, metres.
    #[arg(long)]
    pub b: f64,
    /// Bearing of A's beacon as B sees it, degrees.
    #[arg(long, allow_hyphen_values = true)]
    pub beta: f64,
    /// Beacon offset ahead of each scanner, metres (0 for beacons above the scanners).
    #[arg(long, default_value_t = 0.07)]
    pub offset: f64,
    /// Largest accepted difference of the two beacon separations, metres (distractor
    /// test, thesis §3.3.2).
    #[arg(long, default_value_t = 0.02)]
    pub max_mismatch: f64,
    /// Range error for the error bound (3.37), metres.
    #[arg(long, default_value_t = 0.02)]
    pub range_error: f64,
    /// Apparent beacon width for the error bound (3.37), metres.
    #[arg(long, default_value_t = 0.1)]
    pub beacon_width: f64,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap mutual`.
pub fn run(m: &MutualArgs) -> anyhow::Result<ExitCode> {
    let o = MutualObservation {
        a: m.a,
        alpha: m.alpha.to_radians(),
        b: m.b,
        beta: m.beta.to_radians(),
        d: m.offset,
    };
    let params = MutualParams {
        max_separation_mismatch: m.max_mismatch,
    };
    let fix = mutual_pose(&o, &params)?;
    let bound = expected_position_error(&o, m.range_error, m.beacon_width, 0.0)?;
    if m.json {
        let v = json!({
            "x_m": fix.x, "y_m": fix.y, "heading_deg": fix.heading.to_degrees(),
            "s1_m": fix.s1, "s2_m": fix.s2, "expected_error_m": bound,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "B in A's frame: x {:.4} m, y {:.4} m, heading {:.3} deg (separations {:.4} / {:.4} m; expected position error <= {:.3} m)",
            fix.x,
            fix.y,
            fix.heading.to_degrees(),
            fix.s1,
            fix.s2,
            bound
        );
    }
    Ok(ExitCode::SUCCESS)
}
