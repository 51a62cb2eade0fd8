//! `olmap`: the command-line program of the olmap toolkit.
//!
//! Every command has `--help`; commands that compute something have `--json` for scripts.
//! Errors are printed as one line naming the file and the reason, with a non-zero exit
//! status (1 for a failure, 2 for a bad command line).
//!
//! A closed standard output (`olmap info --json FILE | head -1`) ends the program quietly,
//! as it ends any Unix tool: the default action of SIGPIPE is restored at start (Rust
//! ignores the signal and turns every write to a closed pipe into an error, which
//! `println!` turns into a panic). The process then ends by the signal (the shell shows
//! status 141) with nothing on stderr. This covers every print of every command, clap's
//! help included, without routing each through a special writer.

mod args;
mod commands;
#[cfg(feature = "net")]
mod signals;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// olmap: 3D mapping and localisation for one or many mobile robots.
///
/// Reads the scan formats robots produce (PCD, PLY, XYZ text, 3DTK .3d/.pose/.frames, CSV,
/// KITTI .bin, OctoMap ScanGraph; any of them .bz2-compressed), converts and filters them.
/// Units are metres and degrees on the command line; frames are right-handed, x forward,
/// y left, z up.
#[derive(Parser)]
#[command(name = "olmap", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Describe point-cloud and map files: format, points or voxels, bounding box, ranges.
    Info(commands::info::InfoArgs),
    /// Convert a point cloud between formats, optionally filtering and transforming it.
    Convert(commands::convert::ConvertArgs),
    /// Build an occupancy-list map from point clouds (endpoints or ray tracing).
    Voxelize(commands::voxelize::VoxelizeArgs),
    /// Write a map as another map format or as a cloud of voxel centres.
    Export(commands::export::ExportArgs),
    /// ROS 2 bags (rosbag2 folders, .mcap files): list topics and frames, extract scans with
    /// their odometry into a folder `olmap map` reads.
    Bag(commands::bag::BagArgs),
    /// Compare two OctoMap .bt trees voxel by voxel: voxels both know, and how many they
    /// classify alike (free / occupied).
    CompareBt(commands::compare_bt::CompareBtArgs),
    /// Merge maps of the same resolution (counts add).
    Merge(commands::merge::MergeArgs),
    /// Register a scan onto another scan with no initial guess (multi-resolution search,
    /// then ICP); prints T_target_source and whether to trust it.
    Align(commands::align::AlignArgs),
    /// Localise a scan in a prior map (.olm, .bt) with no initial guess.
    Localize(commands::align::AlignArgs),
    /// Build a map from many scans (batch best-overlap-first or sequential), with optional
    /// odometry; writes the map, the scan poses and a report. A CARMEN 2D laser log
    /// (.log, .log.gz) is mapped in x-y-yaw with loop closure.
    Map(commands::map::MapArgs),
    /// Compare estimated poses with reference poses (per scan and summaries).
    Eval(commands::eval::EvalArgs),
    /// Print pose files (3DTK .pose/.frames, CSV pose tables, pose lists) in metres and
    /// degrees, or convert them to an olmap pose list.
    Poses(commands::poses::PosesArgs),
    /// The relative pose of two robots that see each other's beacon (mutual localisation,
    /// thesis §3.3.1), with the distractor test and the expected error.
    Mutual(commands::mutual::MutualArgs),
    /// Generate a multi-robot dataset in a simulated world: scans, odometry, ground truth,
    /// sightings between robots (and optionally 2D scans and raw mirror-scanner logs).
    Simulate(commands::simulate::SimulateArgs),
    /// Build a 2D occupancy grid from planar laser scans (CSV) and their poses; writes a ROS
    /// map (PGM + YAML).
    Grid2d(commands::grid2d::Grid2dArgs),
    /// Find circular beacons of known radius in a 2D laser scan (CSV or JSON): least
    /// squares, range-weighted Hough transform or retroreflective runs.
    Beacons(commands::beacons::BeaconsArgs),
    /// Map a multi-robot dataset as a team: sightings confine the scan searches (thesis
    /// (6.2)-(6.4)), seen robots are cleared; optionally compare with every robot alone.
    Team(commands::team::TeamArgs),
    /// Scan-store files: what one holds (`info`), several merged into one (`merge`), the
    /// readable records of a damaged one recovered (`salvage`).
    Store(commands::store::StoreArgs),
    /// Run the built-in demonstration on generated data (no download needed).
    Demo(commands::demo::DemoArgs),
    /// Rotating-mirror 3D scanner tools: convert a raw log to a cloud, check repeatability.
    Scanner(commands::scanner::ScannerArgs),
    /// Run the standard benchmark set (shared data and simulator): insertion, overlap
    /// evaluations, alignment and localisation in both search modes, map building, thread
    /// scaling, peak memory.
    Bench(commands::bench::BenchArgs),
    /// Draw a map as a PNG: a top view coloured by height (optional height band, grid,
    /// path), a depth image from a viewpoint (pinhole or panoramic), or the overlap
    /// surface of a scan around a pose (heat map).
    Render(commands::render::RenderArgs),
    /// The navigation grid of a map (thesis §7.3): free / occupied / unknown cells in a
    /// robot-height band, ray traced from the scan poses; writes a ROS map (PGM + YAML).
    Navgrid(commands::navgrid::NavgridArgs),
    /// Pose graphs (g2o files): optimise one (sparse Levenberg-Marquardt on the manifold,
    /// chordal initialisation, robust kernels) or describe it.
    Graph(commands::graph::GraphArgs),
    /// Ask a map: occupied at a point, first hit along a ray, voxels near a point, free
    /// segment.
    Query(commands::query::QueryArgs),
    /// Live team (Zenoh): replay one robot of a dataset in real time, publishing each stop's
    /// occupancy list and serving every record it holds (`--map`: map as well).
    #[cfg(feature = "net")]
    Robot(commands::net::RobotArgs),
    /// Live team (Zenoh): merge every robot's records into a persistent store, map them as
    /// they arrive, serve the map; writes the outputs on SIGINT/SIGTERM.
    #[cfg(feature = "net")]
    Mapper(commands::net::MapperArgs),
    /// Live team (Zenoh): a status line per node (alive, records, placed scans, latency)
    /// until a mapper has placed N scans or time is up.
    #[cfg(feature = "net")]
    Watch(commands::net::WatchArgs),
}

/// Restores the default action of SIGPIPE (end the process), which the Rust runtime sets to
/// "ignore" before `main`.
#[cfg(unix)]
fn quiet_on_closed_pipe() {
    // SAFETY: `signal` with SIG_DFL installs no handler (no Rust code runs in signal
    // context); it is called first thing in `main`, before any thread is started.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Elsewhere a write to a closed pipe stays an error (reported by [`main`] quietly).
#[cfg(not(unix))]
fn quiet_on_closed_pipe() {}

/// Whether an error is (caused by) a write to a closed pipe.
fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

fn main() -> ExitCode {
    quiet_on_closed_pipe();
    // A decoder panicking on a damaged file is reported as olmap's error, not as a panic.
    olmap::guard::quiet_guarded_panics();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info(a) => commands::info::run(&a),
        Command::Convert(a) => commands::convert::run(&a),
        Command::Poses(a) => commands::poses::run(&a),
        Command::Map(a) => commands::map::run(&a),
        Command::Eval(a) => commands::eval::run(&a),
        Command::Align(a) | Command::Localize(a) => commands::align::run(&a),
        Command::Voxelize(a) => commands::voxelize::run(&a),
        Command::CompareBt(a) => commands::compare_bt::run(&a),
        Command::Export(a) => commands::export::run(&a),
        Command::Merge(a) => commands::merge::run(&a),
        Command::Bag(a) => commands::bag::run(&a),
        Command::Mutual(a) => commands::mutual::run(&a),
        Command::Simulate(a) => commands::simulate::run(&a),
        Command::Team(a) => commands::team::run(&a),
        #[cfg(feature = "net")]
        Command::Robot(a) => commands::net::run_robot_cmd(&a),
        #[cfg(feature = "net")]
        Command::Mapper(a) => commands::net::run_mapper_cmd(&a),
        #[cfg(feature = "net")]
        Command::Watch(a) => commands::net::run_watch_cmd(&a),
        Command::Demo(a) => commands::demo::run(&a),
        Command::Store(a) => commands::store::run(&a),
        Command::Grid2d(a) => commands::grid2d::run(&a),
        Command::Beacons(a) => commands::beacons::run(&a),
        Command::Scanner(a) => commands::scanner::run(&a),
        Command::Bench(a) => commands::bench::run(&a),
        Command::Render(a) => commands::render::run(&a),
        Command::Navgrid(a) => commands::navgrid::run(&a),
        Command::Query(a) => commands::query::run(&a),
        Command::Graph(a) => commands::graph::run(&a),
    };
    match result {
        Ok(code) => code,
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            // Each cause once: olmap's errors name their cause in their own message.
            eprintln!("error: {}", olmap::error::chain_message(e.chain()));
            ExitCode::FAILURE
        }
    }
}
