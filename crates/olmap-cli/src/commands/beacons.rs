//! `olmap beacons`: find circular beacons of known radius in a 2D laser scan.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use olmap::beacon::{
    detect_circles_lsq, detect_circles_reflective, detect_circles_rwht, BeaconsReport, Detection,
    LsqParams, ReflectiveParams, RwhtParams,
};
use olmap::cloud::LaserScan;

/// How to find the circles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Least squares on the range data (thesis §2.4.2).
    Lsq,
    /// Range-weighted Hough transform (thesis §2.4.1).
    Rwht,
    /// Runs of retroreflective (bright) returns (thesis §2.4.3).
    Reflective,
}

impl Method {
    fn name(self) -> &'static str {
        match self {
            Method::Lsq => "lsq",
            Method::Rwht => "rwht",
            Method::Reflective => "reflective",
        }
    }
}

/// Arguments of `olmap beacons`.
#[derive(Args)]
pub struct BeaconsArgs {
    /// The 2D scan: olmap laser-scan CSV, or JSON with ROS LaserScan field names (.json).
    pub scan: PathBuf,
    /// Radius of the beacons, metres.
    #[arg(long, default_value_t = 0.125)]
    pub radius: f64,
    /// Detection method.
    #[arg(long, value_enum, default_value_t = Method::Lsq)]
    pub method: Method,
    /// Largest RMS distance of a circle's returns to its circumference, metres (lsq and
    /// reflective; default 0.01 as in the thesis, about twice the scanner's range noise).
    #[arg(long)]
    pub max_rms: Option<f64>,
    /// Intensity at or above which a return counts as retroreflective (reflective).
    #[arg(long, default_value_t = 1.0)]
    pub intensity_threshold: f64,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command.
pub fn run(args: &BeaconsArgs) -> anyhow::Result<ExitCode> {
    if !(args.radius.is_finite() && args.radius > 0.0) {
        bail!(
            "--radius must be a positive number of metres, got {}",
            args.radius
        );
    }
    let scan = LaserScan::read_path(&args.scan)?;
    if args.method == Method::Reflective && scan.intensities.is_none() {
        bail!(
            "{}: the scan has no intensities; --method reflective needs them",
            args.scan.display()
        );
    }
    let found: Vec<Detection> = match args.method {
        Method::Lsq => {
            let mut p = LsqParams::default();
            if let Some(m) = args.max_rms {
                p.max_rms = m;
            }
            detect_circles_lsq(&scan, args.radius, &p)
        }
        Method::Reflective => {
            let mut p = ReflectiveParams {
                intensity_threshold: args.intensity_threshold,
                ..ReflectiveParams::default()
            };
            if let Some(m) = args.max_rms {
                p.max_rms = m;
            }
            detect_circles_reflective(&scan, args.radius, &p)
        }
        Method::Rwht => detect_circles_rwht(&scan, args.radius, &RwhtParams::default()),
    };
    let shown = args.scan.display().to_string();
    if args.json {
        let v = BeaconsReport::new(&shown, args.method.name(), args.radius, scan.len(), &found);
        println!(
            "{}",
            serde_json::to_string_pretty(&v).context("writing JSON")?
        );
    } else {
        println!(
            "{shown}: {} circle(s) of radius {} m by {} in {} beams",
            found.len(),
            args.radius,
            args.method.name(),
            scan.len()
        );
        if !found.is_empty() {
            println!(
                "  {:>8} {:>8} {:>8} {:>9} {:>8} {:>7} {:>10}",
                "x [m]", "y [m]", "range", "bearing°", "rms [m]", "returns", "confidence"
            );
        }
        for d in &found {
            println!(
                "  {:>8.3} {:>8.3} {:>8.3} {:>9.2} {:>8.4} {:>7} {:>10.2}",
                d.center.x,
                d.center.y,
                d.range(),
                d.bearing().to_degrees(),
                d.rms,
                d.returns,
                d.confidence
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
