//! Argument helpers shared by the subcommands.

use std::io::IsTerminal;

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use olmap::align::Dof;
use olmap::geometry::Pose;

/// Parses `N` comma-separated finite numbers.
pub fn parse_numbers<const N: usize>(s: &str, what: &str) -> anyhow::Result<[f64; N]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{what}: '{s}' is not a comma-separated list of numbers"))?;
    if v.len() != N || v.iter().any(|x| !x.is_finite()) {
        bail!("{what}: expected {N} finite numbers separated by commas, got '{s}'");
    }
    Ok(v.try_into().expect("length checked"))
}

/// Parses a pose `x,y,z,yaw,pitch,roll` (metres, degrees).
pub fn parse_pose(s: &str, what: &str) -> anyhow::Result<Pose> {
    let v = parse_numbers::<6>(s, what)?;
    Ok(Pose::from_xyz_ypr(
        v[0],
        v[1],
        v[2],
        v[3].to_radians(),
        v[4].to_radians(),
        v[5].to_radians(),
    ))
}

/// A progress bar with ETA on stderr, hidden when stderr is not a terminal or `quiet`.
pub fn progress(len: u64, what: &str, quiet: bool) -> ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} ({elapsed}, eta {eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

/// Sets the number of worker threads (0: one per core), capped at the machine's parallelism
/// ([`olmap::limits::thread_count`]) with a warning on stderr when the cap acts.
pub fn set_threads(threads: usize) -> anyhow::Result<()> {
    let count = olmap::limits::thread_count(threads);
    if let Some(note) = count.note() {
        eprintln!("warning: --threads: {note}");
    }
    if count.threads > 0 {
        rayon::ThreadPoolBuilder::new()
            .num_threads(count.threads)
            .build_global()
            .context("cannot set the number of threads")?;
    }
    Ok(())
}

/// Progress bars for a library pipeline's stages: one bar per stage, shown while it runs
/// (hidden when `quiet` or stderr is not a terminal).
pub struct StageBars {
    quiet: bool,
    current: Option<(olmap::progress::Stage, ProgressBar)>,
}

impl StageBars {
    /// No bar yet.
    pub fn new(quiet: bool) -> Self {
        StageBars {
            quiet,
            current: None,
        }
    }

    /// Moves the bar of `stage` to `done` of `total`, starting it (and clearing the last
    /// stage's) when the stage changes.
    pub fn update(&mut self, stage: olmap::progress::Stage, done: usize, total: usize) {
        if self.current.as_ref().map(|c| c.0) != Some(stage) {
            self.finish();
            self.current = Some((stage, progress(total as u64, stage.label(), self.quiet)));
        }
        if let Some((_, bar)) = &self.current {
            bar.set_position(done as u64);
        }
    }

    /// Clears the last bar.
    pub fn finish(&mut self) {
        if let Some((_, bar)) = self.current.take() {
            bar.finish_and_clear();
        }
    }
}

/// Degrees of freedom on the command line.
#[derive(Clone, Copy, ValueEnum)]
pub enum DofArg {
    /// x, y, yaw (z, roll, pitch from the prior: guess or odometry).
    XyYaw,
    /// x, y, z, yaw (roll, pitch from the prior: gravity-aligned robots).
    XyzYaw,
    /// All six; roll and pitch within --max-tilt of the prior.
    #[value(name = "6dof")]
    SixDof,
}

/// The degrees of freedom a registration searches (`olmap align`, `localize`, `map`).
#[derive(Args)]
pub struct DofArgs {
    /// Degrees of freedom searched by each registration.
    #[arg(long, value_enum, default_value = "xyz-yaw")]
    pub dof: DofArg,
    /// 6dof: largest roll and pitch searched away from the prior, degrees.
    #[arg(long, default_value_t = 15.0)]
    pub max_tilt: f64,
}

impl DofArgs {
    /// The library's degrees of freedom.
    pub fn dof(&self) -> Dof {
        match self.dof {
            DofArg::XyYaw => Dof::XyYaw,
            DofArg::XyzYaw => Dof::XyzYaw,
            DofArg::SixDof => Dof::SixDof {
                max_tilt: self.max_tilt.to_radians(),
            },
        }
    }
}

/// The worker-thread count of a command.
#[derive(Args)]
pub struct ThreadsArgs {
    /// Worker threads (0: one per core; at most the machine's cores, more are capped with
    /// a warning).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}
