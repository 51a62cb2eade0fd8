//! `olmap align` and `olmap localize`: global registration with no initial guess.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use olmap::align::icp::IcpParams;
use olmap::align::verify::Origin;
use olmap::align::{
    self, Localizer, Region, RegisterParams, Registration, SearchMode, SearchParams,
};
use olmap::cloud::PointCloud;
use olmap::geometry::Pose;
use olmap::io::{self, ReadOptions};
use olmap::occupancy::{self, MapFormat};

use crate::args::{parse_numbers, parse_pose, set_threads, DofArgs, ThreadsArgs};

/// `--search`.
#[derive(Clone, Copy, ValueEnum)]
pub enum SearchArg {
    /// The multi-resolution search (thesis Algorithms 3, 5, 6).
    Multires,
    /// The exact branch-and-bound search.
    Exact,
}

/// Arguments shared by `align` and `localize`.
#[derive(Args)]
pub struct AlignArgs {
    /// The scan to place (any point-cloud format; in its sensor frame).
    pub source: PathBuf,
    /// What to place it in: a point cloud, or a map (.olm, .bt) for localisation. A `.bt`
    /// tree with free nodes (`olmap voxelize --free-space`, OctoMap's own maps) also says
    /// where its scans saw through, and a scan is checked against that too: build maps to
    /// localise in that way, above all when a --window may leave out the true pose.
    /// Globally (no --window) a match in such a map is trusted only where the map's
    /// surfaces alone single it out: its free space refutes look-alikes, but a scan of a
    /// place the map does not hold would otherwise be trusted on the look-alike it
    /// contradicts least.
    pub target: PathBuf,
    /// Finest voxel edge of the search, metres. A map finer than this is localised in at
    /// its pyramid level closest to it without exceeding it (its voxel edge doubled as
    /// often as that allows: a 0.025 m map at 0.1 m, a 0.03 m map at 0.06 m), a map at or
    /// above it at its own voxel edge.
    #[arg(long, default_value_t = 0.1)]
    pub resolution: f64,
    /// Pyramid levels (0: automatic, coarsest at least 16x the finest).
    #[arg(long, default_value_t = 0)]
    pub levels: usize,
    #[command(flatten)]
    pub dof: DofArgs,
    /// A prior pose: `x,y,z,yaw,pitch,roll` (metres, degrees), or a pose file whose first
    /// pose is used. Without --window it only supplies roll/pitch (and z for xy-yaw).
    #[arg(long, value_name = "POSE|FILE", allow_hyphen_values = true)]
    pub guess: Option<String>,
    /// Search a window around the guess: `xy,z,yaw` half-widths (metres, metres, degrees)
    /// instead of the whole target with every heading.
    #[arg(long, value_name = "XY,Z,YAW")]
    pub window: Option<String>,
    /// Search the whole target and every heading (the default; conflicts with --window).
    #[arg(long, conflicts_with = "window")]
    pub global: bool,
    /// Skip the ICP refinement.
    #[arg(long)]
    pub no_refine: bool,
    /// Ignore source points farther than this from the sensor, metres.
    #[arg(long, default_value_t = 30.0)]
    pub max_range: f64,
    /// 3DTK .3d input: keep only returns between 20 cm and 3270 cm.
    #[arg(long = "3dtk-valid")]
    pub threedtk_valid: bool,
    #[command(flatten)]
    pub threads: ThreadsArgs,
    /// Print per-level particle counts and timings.
    #[arg(long)]
    pub verbose: bool,
    /// How the global search explores the poses: `multires` (the thesis' multi-resolution
    /// search, heuristic) or `exact` (branch and bound: the best pose of the finest lattice,
    /// guaranteed).
    #[arg(long, value_enum, default_value = "multires")]
    pub search: SearchArg,
    /// The exact search's work limit, in voxel bounds (one node bounded over one scan
    /// voxel): past it the search stops with an error instead of running for hours where
    /// every pose scores alike (a floor against a floor). Default: the library's.
    #[arg(long, value_name = "N")]
    pub exact_max_work: Option<f64>,
    /// Further scans to place in the same map after SOURCE (a map target only): the map is
    /// prepared once (its search pyramid, its voxel centres indexed for ICP, its surface
    /// for the agreement checks) and each scan pays only for its own search, refinement
    /// and checks; each `seconds` then counts that scan alone. Every option applies to
    /// every scan (one --guess and --window for all). Give it after the positional
    /// arguments (it takes every value that follows). Text prints each result under its
    /// scan's name; --json prints one object, `{"prepare_seconds": .., "map_resolution":
    /// .., "resolution": .., "results": [..]}` (the map's voxel edge, the one it was read
    /// at), a report per scan in order.
    #[arg(long, value_name = "SCAN", num_args = 1..)]
    pub also: Vec<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

fn read_cloud(path: &Path, valid: bool) -> anyhow::Result<PointCloud> {
    let opts = ReadOptions {
        uos_valid_only: valid,
        ..Default::default()
    };
    Ok(io::read_cloud_with(path, &opts)?.cloud)
}

fn guess(s: &str) -> anyhow::Result<Pose> {
    if Path::new(s).exists() {
        let list = io::read_poses(s)?;
        return list
            .poses
            .first()
            .map(|p| p.pose)
            .with_context(|| format!("{s}: no pose in the file"));
    }
    if !s.contains(',') {
        bail!(
            "--guess: '{s}' is neither a pose x,y,z,yaw,pitch,roll (metres, degrees) nor a pose \
             file: there is no file of that name"
        );
    }
    parse_pose(s, "--guess")
}

fn params(a: &AlignArgs) -> anyhow::Result<RegisterParams> {
    let prior = a
        .guess
        .as_deref()
        .map(guess)
        .transpose()?
        .unwrap_or_else(Pose::identity);
    let region = match &a.window {
        Some(w) => {
            let v = parse_numbers::<3>(w, "--window")?;
            if a.guess.is_none() {
                bail!("--window needs --guess (the window's centre)");
            }
            Region::Window {
                xy: v[0],
                z: v[1],
                yaw: v[2].to_radians(),
            }
        }
        None => Region::Global,
    };
    let dof = a.dof.dof();
    Ok(RegisterParams {
        search: SearchParams {
            resolution: a.resolution,
            levels: a.levels,
            dof,
            region,
            prior,
            max_range: a.max_range,
            search: match a.search {
                SearchArg::Multires => SearchMode::MultiResolution,
                SearchArg::Exact => SearchMode::Exact,
            },
            exact_max_work: match a.exact_max_work {
                // A float on the command line (`1e11`); the library checks it is >= 1.
                Some(w) if w.is_finite() && w >= 0.0 => w.min(u64::MAX as f64) as u64,
                Some(w) => bail!("--exact-max-work must be a number >= 1, got {w}"),
                None => align::EXACT_MAX_WORK,
            },
            ..Default::default()
        },
        refine: (!a.no_refine).then(IcpParams::default),
        trust: Default::default(),
    })
}

fn print(r: &Registration, a: &AlignArgs) -> anyhow::Result<()> {
    if a.json {
        let v = align::AlignmentReport::new(
            r,
            &a.source.display().to_string(),
            &a.target.display().to_string(),
        );
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    print_text(r, a)
}

fn print_text(r: &Registration, a: &AlignArgs) -> anyhow::Result<()> {
    let t = r.pose.translation();
    let (y, p, ro) = r.pose.yaw_pitch_roll();
    let s = &r.search;
    println!("T_target_source:");
    for row in align::matrix_rows(&r.pose) {
        println!(
            "  {:>12.6} {:>12.6} {:>12.6} {:>12.6}",
            row[0], row[1], row[2], row[3]
        );
    }
    println!("translation   ({:.4}, {:.4}, {:.4}) m", t.x, t.y, t.z);
    println!(
        "yaw/pitch/roll {:.3} / {:.3} / {:.3} deg",
        y.to_degrees(),
        p.to_degrees(),
        ro.to_degrees()
    );
    println!(
        "search        overlap {} of {} voxels ({:.1} %), significance {:.1}, ambiguity {}, {} poses in {:.3} s{}",
        s.overlap,
        s.scan_voxels,
        100.0 * s.overlap_fraction,
        s.significance,
        s.ambiguity,
        s.evaluated,
        s.seconds,
        if s.guard_acted { " (survivor cap acted)" } else { "" }
    );
    if let Some(f) = &r.refinement {
        println!(
            "refinement    {} in {} iterations, inlier RMS {:.4} m, inliers {:.1} %, {:.3} s",
            if f.converged {
                "converged"
            } else {
                "NOT converged"
            },
            f.iterations,
            f.inlier_rms,
            100.0 * f.inlier_fraction,
            f.seconds
        );
        if !f.degeneracy.weak.is_empty() {
            println!(
                "              weakly constrained: {}",
                f.degeneracy.weak.join("; ")
            );
        }
    }
    if let Some(v) = &r.verification {
        let w = v.winner();
        let from = match w.origin {
            Origin::Search => "the search",
            Origin::UprightLook => "the upright look (floors and ceilings thinned)",
            Origin::Slide => "a slide along the weakly held direction",
            Origin::Screened => "a near-best pose of the search screened among look-alikes",
        };
        let n = v.hypotheses.len();
        println!(
            "verified      {n} {}; the winner came from {from} (fit {:.0}, agreement {:.3})",
            if n == 1 { "hypothesis" } else { "hypotheses" },
            w.fit,
            w.consistency.agreement()
        );
    }
    if r.trusted {
        println!("trusted       yes ({:.3} s)", r.seconds);
    } else {
        println!(
            "trusted       NO: {} ({:.3} s)",
            r.doubts.join("; "),
            r.seconds
        );
    }
    if a.verbose {
        for l in &s.levels {
            println!(
                "  level {} ({:.3} m, {:.3} deg): {} scan voxels, {} poses, {} passed, {} kept, best {}, {:.3} s",
                l.level,
                l.resolution,
                l.angular_step.to_degrees(),
                l.scan_voxels,
                l.evaluated,
                l.passed,
                l.survivors,
                l.best_overlap,
                l.seconds
            );
        }
    }
    Ok(())
}

/// Runs `olmap align` (and `localize`, which is the same with a map target).
pub fn run(a: &AlignArgs) -> anyhow::Result<ExitCode> {
    set_threads(a.threads.threads)?;
    let p = params(a)?;
    let is_map = MapFormat::from_path(&a.target).is_some();
    if !a.also.is_empty() {
        if !is_map {
            bail!(
                "--also places further scans in a map: {} is not a map (.olm, .bt)",
                a.target.display()
            );
        }
        return localize_many(a, &p);
    }
    let source = read_cloud(&a.source, a.threedtk_valid)?;
    let r = if is_map {
        let loaded = occupancy::read_map(&a.target)?;
        align::localize_in(&source, &loaded.map, loaded.free.as_ref(), &p)?
    } else {
        let target = read_cloud(&a.target, a.threedtk_valid)?;
        align::register(&source, &target, &p)?
    };
    print(&r, a)?;
    Ok(ExitCode::SUCCESS)
}

/// `olmap localize SOURCE MAP --also SCAN...`: every scan read first (a bad file fails
/// before any work), the map prepared once, the scans placed in order.
fn localize_many(a: &AlignArgs, p: &RegisterParams) -> anyhow::Result<ExitCode> {
    let paths: Vec<&PathBuf> = std::iter::once(&a.source).chain(&a.also).collect();
    let scans = paths
        .iter()
        .map(|path| read_cloud(path, a.threedtk_valid))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let loaded = occupancy::read_map(&a.target)?;
    let started = Instant::now();
    let localizer = match loaded.free {
        Some(free) => Localizer::with_free_space(loaded.map, free, p)?,
        None => Localizer::new(loaded.map, p)?,
    };
    let prepare_seconds = started.elapsed().as_secs_f64();
    let target = a.target.display().to_string();
    let mut reports = Vec::new();
    if !a.json {
        println!(
            "prepared {} ({} voxels at {} m, read at {} m{}) in {prepare_seconds:.3} s",
            target,
            localizer.len(),
            localizer.map_resolution(),
            localizer.resolution(),
            if localizer.has_free_space() {
                ", with its free space"
            } else {
                ", no free space known"
            }
        );
    }
    for (path, scan) in paths.iter().zip(&scans) {
        let r = localizer.localize(scan, p)?;
        if a.json {
            reports.push(align::AlignmentReport::new(
                &r,
                &path.display().to_string(),
                &target,
            ));
        } else {
            println!("\n{}", path.display());
            print_text(&r, a)?;
        }
    }
    if a.json {
        let v = serde_json::json!({
            "prepare_seconds": prepare_seconds,
            "map_resolution": localizer.map_resolution(),
            "resolution": localizer.resolution(),
            "free_space": localizer.has_free_space(),
            "results": reports,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    }
    Ok(ExitCode::SUCCESS)
}
