//! `olmap map`: a map built from many scans through the library's
//! [`olmap::mapping::run_map_job`].

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use clap::{Args, ValueEnum};
use olmap::align::icp::IcpParams;
use olmap::align::{RegisterParams, SearchParams};
use olmap::io::{self, ReadOptions};
use olmap::mapping::planar::{run_planar_log, OdometryNoise, PlanarLogJob, PlanarMapParams};
use olmap::mapping::posegraph::GraphRefineParams;
use olmap::mapping::{run_map_job, MapJob, MapMode, MapParams, OdometrySource};
use olmap::occupancy::{MapFormat, SensorModel};

use crate::args::{set_threads, DofArgs, StageBars, ThreadsArgs};

/// Mapping modes on the command line.
#[derive(Clone, Copy, ValueEnum)]
pub enum ModeArg {
    /// Best overlap first (thesis §6.4.1): robust to scans in any order.
    Batch,
    /// In the given order (online), each scan aligned once to the map so far.
    Sequential,
    /// In the given order, one at a time, as a live mapper receives them: a scan that
    /// cannot be placed yet waits and is retried as the map grows (the first scan is the
    /// map frame; --first is refused).
    Incremental,
}

/// Arguments of `olmap map`.
#[derive(Args)]
pub struct MapArgs {
    /// Scans (any point-cloud format) or folders of scans (every cloud file in them, by
    /// name; a 3DTK folder holds scanNNN.3d files); or one CARMEN 2D laser log (`.log`,
    /// `.log.gz`, `.log.bz2`), mapped in x-y-yaw with loop closure (see --odometry-noise);
    /// or one ROS 2 bag (rosbag2 folder or .mcap file; see --topic, --odom-topic, --frame).
    pub scans: Vec<PathBuf>,
    /// A text file listing scan paths, one per line (relative to the file's folder).
    #[arg(long, value_name = "FILE")]
    pub list: Option<PathBuf>,
    /// Odometry `T_world_scan`: a pose file (pose list or CSV pose table, matched by scan
    /// name or in order), or `3dtk` to read each scan's sibling .pose file.
    #[arg(long, value_name = "FILE|3dtk")]
    pub odometry: Option<String>,
    /// Output map (.olm or .bt). Required for scan files; for a 2D log, optional: the map's
    /// points as a cloud (.ply, .pcd, .xyz; z = 0).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Write the scan poses `T_map_scan` as a pose list.
    #[arg(long, value_name = "FILE")]
    pub poses_out: Option<PathBuf>,
    /// Also write the placed scans ray traced at their poses as an OctoMap .bt that keeps
    /// free space (OctoMap's sensor model: hit 0.7, miss 0.4, clamped 0.1192-0.971; rays cut
    /// at --max-range), at --resolution: the map to localise in with `olmap localize` when
    /// a --window may leave out the true pose (scans are checked against its free space).
    #[arg(long, value_name = "FILE.bt")]
    pub free_space_out: Option<PathBuf>,
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
    /// Batch (default), sequential or incremental.
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
    /// 2D logs (CARMEN `.log`/`.log.gz`): the odometry is the log's corrected poses
    /// degraded with seeded noise on every step between scans: σ of x and y = FRAC × the
    /// distance travelled, σ of the heading = DEG degrees per metre travelled and per radian
    /// turned. `0,0` maps from the corrected poses themselves.
    #[arg(long, value_name = "FRAC,DEG", default_value = "0.05,2")]
    pub odometry_noise: String,
    /// 2D logs: the seed of the odometry noise (and, for 2D logs and 3D scans, of
    /// --inject-wrong-closures).
    #[arg(long, default_value_t = 1)]
    pub noise_seed: u64,
    /// 2D logs: no loop closure (odometry and sequential registration only; shows what the
    /// pose graph's closures buy).
    #[arg(long)]
    pub no_loop_closure: bool,
    /// Robustness test: before the final solve, add this fraction of the accepted loop
    /// closures (2D logs) or pairwise registrations (3D scans, with --graph) again as wrong
    /// closures (2-5 m off, between random scans, drawn from --noise-seed); the report
    /// says which the robust kernel rejected. 0 (default) = none.
    #[arg(long, default_value_t = 0.0, value_name = "FRACTION")]
    pub inject_wrong_closures: f64,
    /// 2D logs: write a top view of the map (PNG, 5 cm pixels, 5 m grid) with the mapped
    /// path (blue) and the log's own path (red).
    #[arg(long, value_name = "FILE")]
    pub picture: Option<PathBuf>,
    /// 2D logs: map only the first N scans.
    #[arg(long, value_name = "N")]
    pub max_scans: Option<usize>,
    /// Write the pose graph (nodes = scans, odometry, registration and loop-closure edges
    /// with their information) as a g2o file. For 3D scans it turns on --graph.
    #[arg(long, value_name = "FILE")]
    pub graph_out: Option<PathBuf>,
    /// 3D scans: after every scan is placed, register each against its 4 nearest placed
    /// neighbours (within 6 m) again and solve a pose graph of these registrations (robust
    /// kernel) and the odometry (σ 0.1 m + 35 % of the distance, 2° + 10°/m), then fuse the
    /// map at the refined poses. The report's `graph` says what it did.
    #[arg(long)]
    pub graph: bool,
    #[command(flatten)]
    pub threads: ThreadsArgs,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
    /// ROS 2 bags (`olmap map BAG -o map.olm`): which scans and odometry to take.
    #[command(flatten)]
    pub bag: crate::commands::bag::BagSelectArgs,
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
            ModeArg::Incremental => MapMode::Incremental,
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
        graph: (a.graph || a.graph_out.is_some()).then(|| GraphRefineParams {
            inject_wrong_closures: a.inject_wrong_closures,
            inject_seed: a.noise_seed,
            ..Default::default()
        }),
        ..Default::default()
    })
}

/// Runs `olmap map`.
pub fn run(a: &MapArgs) -> anyhow::Result<ExitCode> {
    set_threads(a.threads.threads)?;
    if let [log] = a.scans.as_slice() {
        if io::carmen::is_carmen_path(log) {
            return run_log(a, log);
        }
    }
    if a.picture.is_some() || a.no_loop_closure || a.max_scans.is_some() {
        bail!(
            "--picture, --no-loop-closure and --max-scans are for 2D logs (one CARMEN \
             .log/.log.gz), so far"
        );
    }
    if a.inject_wrong_closures != 0.0 && !(a.graph || a.graph_out.is_some()) {
        bail!(
            "--inject-wrong-closures tests the pose graph: for 3D scans it needs --graph (or \
             --graph-out)"
        );
    }
    let Some(output) = &a.output else {
        bail!("--output (-o) is required: the map file (.olm or .bt) to write");
    };
    MapFormat::of_output(output)?;
    if let [one] = a.scans.as_slice() {
        if io::bag::is_bag_path(one) {
            return run_bag(a, one, output);
        }
    }
    let b = &a.bag;
    if b.topic.is_some()
        || b.odom_topic.is_some()
        || b.frame.is_some()
        || b.every.is_some()
        || b.max.is_some()
    {
        bail!(
            "--topic, --odom-topic, --frame, --every and --max are for a ROS 2 bag (one rosbag2 \
             folder or .mcap file as the input)"
        );
    }
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
        output: output.clone(),
        poses_out: a.poses_out.clone(),
        free_space_out: a.free_space_out.clone(),
        scans_out: a.scans_out.clone(),
        report: a.report.clone(),
        graph_out: a.graph_out.clone(),
    };
    let mut bars = StageBars::new(a.json);
    let run = run_map_job(&job, &mut |stage, done, total| {
        bars.update(stage, done, total)
    })?;
    bars.finish();
    print_run(a, output, &run)
}

/// `olmap map BAG`: the bag's scans and odometry (see `olmap bag extract`) mapped as scan
/// files would be.
fn run_bag(
    a: &MapArgs,
    bag: &std::path::Path,
    output: &std::path::Path,
) -> anyhow::Result<ExitCode> {
    if a.list.is_some() || a.odometry.is_some() || a.threedtk_valid || a.first.is_some() {
        bail!(
            "{}: --list, --odometry, --3dtk-valid and --first are for scan files; a bag brings \
             its scans and odometry (choose them with --topic, --odom-topic, --frame)",
            bag.display()
        );
    }
    let opened = io::bag::Bag::open(bag)?;
    let ex = io::bag::extract_scans(&opened, &a.bag.options()?)?;
    for s in &ex.skipped {
        eprintln!("warning: skipped {s}");
    }
    if let Some(s) = &ex.stopped_early {
        eprintln!("warning: reading stopped early: {s}");
    }
    if !a.json {
        println!(
            "{}: {} scans from {} [{}], odometry {}",
            bag.display(),
            ex.scans.len(),
            ex.topic,
            ex.type_name,
            ex.odometry_source.as_deref().unwrap_or("none")
        );
    }
    let job = MapJob {
        scans: Vec::new(),
        odometry: OdometrySource::None,
        read: ReadOptions::default(),
        first: None,
        params: map_params(a)?,
        output: output.to_path_buf(),
        poses_out: a.poses_out.clone(),
        free_space_out: a.free_space_out.clone(),
        scans_out: a.scans_out.clone(),
        report: a.report.clone(),
        graph_out: a.graph_out.clone(),
    };
    let mut bars = StageBars::new(a.json);
    let run = olmap::mapping::run_map_job_on(
        &job,
        olmap::mapping::bag_scan_inputs(&ex),
        &mut |stage, done, total| bars.update(stage, done, total),
    )?;
    bars.finish();
    print_run(a, output, &run)
}

fn print_run(
    a: &MapArgs,
    output: &std::path::Path,
    run: &olmap::mapping::MapRun,
) -> anyhow::Result<ExitCode> {
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
            output.display()
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
        if let Some(g) = &report.graph {
            println!(
                "  pose graph: edges {:?}, cost {:.4} -> {:.4}, largest move {:.3} m, {} \
                 edge(s) down-weighted",
                g.edges,
                g.initial_cost,
                g.final_cost,
                g.largest_move_m,
                g.down_weighted.len()
            );
            print_injected(&g.injected);
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The text lines of `--inject-wrong-closures`: how many the kernel caught, and each it
/// did not.
fn print_injected(injected: &[olmap::mapping::planar::InjectedClosure]) {
    if injected.is_empty() {
        return;
    }
    let caught = injected.iter().filter(|c| c.down_weighted).count();
    println!(
        "  injected wrong closures: {caught} of {} down-weighted by the kernel",
        injected.len()
    );
    for c in injected.iter().filter(|c| !c.down_weighted) {
        println!(
            "    NOT caught: {} -> {} ({:.2} m off)",
            c.from, c.to, c.offset_m
        );
    }
}

/// `olmap map LOG.log.gz`: a 2D log mapped in x-y-yaw with
/// [`olmap::mapping::planar::run_planar_log`].
fn run_log(a: &MapArgs, log: &std::path::Path) -> anyhow::Result<ExitCode> {
    if matches!(a.dof.dof, crate::args::DofArg::SixDof) {
        bail!(
            "{}: a 2D laser log is mapped in x-y-yaw, not 6dof",
            log.display()
        );
    }
    if a.list.is_some()
        || a.odometry.is_some()
        || a.scans_out.is_some()
        || a.free_space_out.is_some()
        || a.report.is_some()
        || a.graph
    {
        // (those are the 3D pipeline's inputs and outputs)
        bail!(
            "{}: --list, --odometry, --scans-out, --free-space-out, --report and --graph are \
             for scan files (a 2D log always has its pose graph); a 2D log carries its own \
             poses (degraded with --odometry-noise)",
            log.display()
        );
    }
    let [frac, deg] = crate::args::parse_numbers::<2>(&a.odometry_noise, "--odometry-noise")?;
    let mut params = PlanarMapParams::default();
    if a.no_loop_closure {
        params.closure = None;
    }
    let job = PlanarLogJob {
        log: log.to_path_buf(),
        max_scans: a.max_scans,
        max_range: a.max_range,
        noise: OdometryNoise {
            distance_fraction: frac,
            degrees_per_unit: deg,
        },
        noise_seed: a.noise_seed,
        params,
        poses_out: a.poses_out.clone(),
        graph_out: a.graph_out.clone(),
        map_out: a.output.clone(),
        picture_out: a.picture.clone(),
        inject_wrong_closures: a.inject_wrong_closures,
    };
    let mut bars = StageBars::new(a.json);
    let report = run_planar_log(&job, &mut |done, total| {
        bars.update(olmap::progress::Stage::Map, done, total)
    })?;
    bars.finish();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(ExitCode::SUCCESS);
    }
    let e = &report.errors;
    let o = &report.odometry_errors;
    println!(
        "{} of {} scans placed in {:.2} s ({:.1} ms per scan, slowest {:.0} ms); loop closure {}",
        report.placed,
        report.scans,
        report.seconds,
        report.ms_per_scan,
        report.max_ms_per_scan,
        if report.loop_closure { "on" } else { "off" }
    );
    println!("  placed by: {:?}", report.sources);
    println!("  graph edges: {:?}", report.edges);
    if report.loop_closure {
        println!(
            "  loop closures: {} tried, {} accepted ({} along corridors: heading and position across only), {} down-weighted by the robust kernel",
            report.closures_tried,
            report.closures_accepted,
            report.closures_partial,
            report.closures_down_weighted.len()
        );
    }
    print_injected(&report.injected_closures);
    println!(
        "  final solve: cost {:.4} -> {:.4}",
        report.initial_cost + 0.0,
        report.final_cost + 0.0
    );
    println!(
        "  against the log's corrected poses (odometry noise {} / {} deg, seed {}):",
        frac, deg, report.noise_seed
    );
    println!(
        "  {:<10} {:>10} {:>10} {:>10} {:>10} {:>11} {:>11}",
        "", "ATE rms m", "ATE max m", "yaw rms", "yaw max", "rel 1m rms", "rel 10m rms"
    );
    for (what, x) in [("mapped", e), ("odometry", o)] {
        println!(
            "  {:<10} {:>10.3} {:>10.3} {:>10.2} {:>10.2} {:>11.3} {:>11.3}",
            what,
            x.ate_rmse_m,
            x.ate_max_m,
            x.yaw_rmse_deg,
            x.yaw_max_deg,
            x.relative_1m_rmse_m,
            x.relative_10m_rmse_m
        );
    }
    Ok(ExitCode::SUCCESS)
}
