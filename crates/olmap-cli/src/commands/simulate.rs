//! `olmap simulate`: generate a multi-robot dataset with ground truth.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, ValueEnum};
use olmap::sim::{
    simulate, MirrorScanner, OdometryNoise, PlanarScanner, RobotModel, Scanner3d, SimConfig,
    SpinningLidar, WorldKind,
};
use olmap::sim::{write_dataset, SimulateReport};

use crate::args::{parse_numbers, progress};

/// The longest `--step`, metres: past it consecutive scans of the simulated scanners
/// hardly overlap.
const MAX_STEP_M: f64 = 20.0;

/// The world generators.
#[derive(Clone, Copy, ValueEnum)]
pub enum WorldArg {
    /// An office floor: corridor, rooms with doors, a stairwell shaft.
    Office,
    /// One ~20 x 20 m lab room with pillars and furniture (like thesis §6.5).
    Lab,
    /// A long featureless corridor (hard for alignment).
    Corridor,
    /// An empty 8 x 6 x 3 m room.
    BoxRoom,
    /// Three identical furnished rooms in a row, joined by open doorways (repetition).
    TwinRooms,
    /// A 24 x 10 m hall with rows of identical desks (repetition along the rows).
    DeskHall,
    /// A 16 x 10 m hall symmetric under a half turn (every view has a twin).
    SymmetricHall,
    /// A corridor loop round a solid core (26 x 16 m outside, 3 m wide, a 72 m centre
    /// line); robots drive round it instead of wandering, so long runs close a loop.
    CorridorRing,
    /// A 200 x 200 x 10 m warehouse: 31 double rack rows (6 m high, 3.6 m aisles) with
    /// random loads on every shelf; robots drive a serpentine through the aisles (large-scale
    /// mapping and localisation; repetition everywhere but the loads).
    Warehouse,
}

/// The 3D scanners.
#[derive(Clone, Copy, ValueEnum)]
pub enum ScannerArg {
    /// The enhanced rotating-mirror scanner (2D scanner facing up, §4.3.3).
    Mirror,
    /// The standard rotating-mirror scanner (mirror in front, §4.3.1).
    MirrorStandard,
    /// A 32-beam spinning lidar (-30..+10° elevation).
    Lidar,
}

/// Odometry error presets.
#[derive(Clone, Copy, ValueEnum)]
pub enum OdometryArg {
    /// Perfect odometry.
    None,
    /// 2 % scale, 0.5°/m drift, 2 cm and 1° per stop.
    Typical,
    /// The thesis' degraded odometry: about 0.5 m and 10° per motion (§6.5.1).
    Degraded,
    /// Strong drift, fair locally: 5 % scale, 2°/m heading drift, 7.5 cm and 3° per stop
    /// (a 72 m loop ends metres off).
    Drifting,
}

/// Where beacons are mounted.
#[derive(Clone, Copy, ValueEnum)]
pub enum BeaconArg {
    /// Above the 3D scanner (seen by 3D scanners, §6.3.3).
    Above,
    /// 0.1 m in front of the 2D scanner, on a body lower than the 2D scanner (seen by 2D
    /// scanners, §3.3.1).
    Front,
}

/// Arguments of `olmap simulate`.
#[derive(Args)]
pub struct SimulateArgs {
    /// The world.
    #[arg(long, value_enum, default_value = "lab")]
    pub world: WorldArg,
    /// Number of robots.
    #[arg(long, default_value_t = 4)]
    pub robots: usize,
    /// Stop-and-scan positions per robot (--step apart).
    #[arg(long, default_value_t = 20)]
    pub scans_per_robot: usize,
    /// Shortest and longest drive between two stops, metres (`MIN,MAX`, each drive drawn
    /// uniformly between them; at most 20 m).
    #[arg(long, default_value = "1,2", value_name = "MIN,MAX")]
    pub step: String,
    /// Seed: the same seed gives a byte-identical dataset.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The 3D scanner.
    #[arg(long, value_enum, default_value = "mirror")]
    pub scanner: ScannerArg,
    /// Odometry error.
    #[arg(long, value_enum, default_value = "typical")]
    pub odometry: OdometryArg,
    /// Beacon mount.
    #[arg(long, value_enum, default_value = "above")]
    pub beacon: BeaconArg,
    /// Also simulate a 2D scanner (180° at 0.5°) and write its scans as CSV.
    #[arg(long)]
    pub scans2d: bool,
    /// Also write the mirror scanner's raw logs (sweeps and encoder events).
    #[arg(long)]
    pub raw_logs: bool,
    /// Range noise of the scanners, standard deviation in metres.
    #[arg(long, default_value_t = 0.02)]
    pub range_noise: f64,
    /// Output folder (must not exist or be empty).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap simulate`.
pub fn run(a: &SimulateArgs) -> anyhow::Result<ExitCode> {
    if !(a.range_noise >= 0.0 && a.range_noise.is_finite()) {
        anyhow::bail!(
            "--range-noise must be a finite number >= 0, got {}",
            a.range_noise
        );
    }
    let world = match a.world {
        WorldArg::Office => WorldKind::Office,
        WorldArg::Lab => WorldKind::Lab,
        WorldArg::Corridor => WorldKind::Corridor,
        WorldArg::BoxRoom => WorldKind::BoxRoom,
        WorldArg::TwinRooms => WorldKind::TwinRooms,
        WorldArg::DeskHall => WorldKind::DeskHall,
        WorldArg::SymmetricHall => WorldKind::SymmetricHall,
        WorldArg::CorridorRing => WorldKind::CorridorRing,
        WorldArg::Warehouse => WorldKind::Warehouse,
    };
    let mut scanner = match a.scanner {
        ScannerArg::Mirror => Scanner3d::Mirror(MirrorScanner::enhanced()),
        ScannerArg::MirrorStandard => Scanner3d::Mirror(MirrorScanner::standard()),
        ScannerArg::Lidar => Scanner3d::Lidar(SpinningLidar::default()),
    };
    match &mut scanner {
        Scanner3d::Mirror(m) => m.noise.sigma = a.range_noise,
        Scanner3d::Lidar(l) => l.noise.sigma = a.range_noise,
    }
    if a.raw_logs && !matches!(scanner, Scanner3d::Mirror(_)) {
        anyhow::bail!("--raw-logs needs a mirror scanner (--scanner mirror or mirror-standard)");
    }
    let mut config = SimConfig {
        world,
        seed: a.seed,
        robots: a.robots,
        stops: a.scans_per_robot,
        scanner,
        raw_logs: a.raw_logs,
        odometry: match a.odometry {
            OdometryArg::None => OdometryNoise::none(),
            OdometryArg::Typical => OdometryNoise::typical(),
            OdometryArg::Degraded => OdometryNoise::degraded(),
            OdometryArg::Drifting => OdometryNoise::drifting(),
        },
        ..Default::default()
    };
    if let BeaconArg::Front = a.beacon {
        config.robot = RobotModel::front_beacon(0.1);
        config.sighting.fov = 180f64.to_radians();
    }
    if a.scans2d {
        let mut p = PlanarScanner::sick_180_half_degree();
        p.noise.sigma = a.range_noise.min(0.01);
        config.scanner2d = Some(p);
    }
    let [lo, hi] = parse_numbers::<2>(&a.step, "--step")?;
    if !(lo > 0.0 && lo <= hi && hi <= MAX_STEP_M) {
        anyhow::bail!(
            "--step: expected 0 < MIN <= MAX <= {MAX_STEP_M} metres, got '{}'",
            a.step
        );
    }
    config.motion.step = (lo, hi);
    olmap::sim::check_dataset_output(&a.output)?;
    let start = Instant::now();
    let total = a.robots.saturating_mul(a.scans_per_robot) as u64;
    let bar = progress(total, "simulate", a.json);
    let data = simulate(&config, |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    let sim_seconds = start.elapsed().as_secs_f64();
    write_dataset(&a.output, &data)?;
    let seconds = start.elapsed().as_secs_f64();
    let r = SimulateReport::new(&a.output.display().to_string(), &data, sim_seconds, seconds);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{} robots x {} scans in the {} world (seed {}): {} points, {} sightings ({} mutual) in {:.2} s -> {}",
            a.robots,
            a.scans_per_robot,
            r.world,
            a.seed,
            r.points,
            r.sightings,
            r.mutual_sightings,
            seconds,
            a.output.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}
