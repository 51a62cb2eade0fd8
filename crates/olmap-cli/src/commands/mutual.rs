//! `olmap mutual`: the relative pose of two robots from a two-way beacon sighting.

use std::process::ExitCode;

use clap::Args;
use olmap::team::{
    mutual_from_scans, mutual_pose, observation_of_fix, MutualObservation, MutualParams,
    MutualReport,
};

/// Arguments of `olmap mutual`: either the four measurements, or the two robots' 2D scans
/// (CSV or JSON) taken at the same time, in which the retroreflective beacons are found.
#[derive(Args)]
pub struct MutualArgs {
    /// Range from robot A's scanner to B's beacon, metres.
    #[arg(long, required_unless_present = "scans")]
    pub a: Option<f64>,
    /// Bearing of B's beacon as A sees it, degrees (positive to the left).
    #[arg(long, allow_hyphen_values = true, required_unless_present = "scans")]
    pub alpha: Option<f64>,
    /// Range from robot B's scanner to A's beacon, metres.
    #[arg(long, required_unless_present = "scans")]
    pub b: Option<f64>,
    /// Bearing of A's beacon as B sees it, degrees.
    #[arg(long, allow_hyphen_values = true, required_unless_present = "scans")]
    pub beta: Option<f64>,
    /// Robot A's and robot B's 2D scans (LaserScan CSV or JSON with intensities): find the
    /// beacons in them instead of giving the measurements.
    #[arg(long, num_args = 2, value_names = ["SCAN_A", "SCAN_B"], conflicts_with_all = ["a", "alpha", "b", "beta"])]
    pub scans: Option<Vec<std::path::PathBuf>>,
    /// Beacon radius for --scans, metres.
    #[arg(long, default_value_t = 0.05)]
    pub radius: f64,
    /// Largest RMS of a beacon fit for --scans, metres (about twice the range noise).
    #[arg(long, default_value_t = 0.02)]
    pub max_rms: f64,
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
    let params = MutualParams {
        max_separation_mismatch: m.max_mismatch,
    };
    let (fix, o) = match &m.scans {
        Some(paths) => {
            let read = |p: &std::path::PathBuf| olmap::cloud::LaserScan::read_path(p);
            let (sa, sb) = (read(&paths[0])?, read(&paths[1])?);
            let detect = olmap::beacon::ReflectiveParams {
                max_rms: m.max_rms,
                ..Default::default()
            };
            let fix = mutual_from_scans(&sa, &sb, m.radius, m.offset, &detect, &params)?;
            let o = observation_of_fix(&fix, m.offset);
            (fix, o)
        }
        None => {
            let need = |v: Option<f64>, name: &str| {
                v.ok_or_else(|| anyhow::anyhow!("--{name} is needed without --scans"))
            };
            let o = MutualObservation {
                a: need(m.a, "a")?,
                alpha: need(m.alpha, "alpha")?.to_radians(),
                b: need(m.b, "b")?,
                beta: need(m.beta, "beta")?.to_radians(),
                d: m.offset,
            };
            (mutual_pose(&o, &params)?, o)
        }
    };
    let r = MutualReport::new(&fix, &o, m.range_error, m.beacon_width)?;
    if m.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "B in A's frame: x {:.4} m, y {:.4} m, heading {:.3} deg (separations {:.4} / {:.4} m; expected position error <= {:.3} m)",
            r.x_m, r.y_m, r.heading_deg, r.s1_m, r.s2_m, r.expected_error_m
        );
    }
    Ok(ExitCode::SUCCESS)
}
