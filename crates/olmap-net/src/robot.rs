//! The robot role: replay one robot of a recorded dataset in real time, turning each scan
//! into what robots exchange, storing it durably and publishing it.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use olmap::team::{ScanStore, StoredScan};

use crate::error::{NetError, Result};
use crate::node::{Node, NodeOptions};

/// What a robot node replays and how.
#[derive(Debug, Clone)]
pub struct RobotOptions {
    /// The dataset folder (`olmap simulate` output), or a ROS 2 bag (rosbag2 folder or
    /// `.mcap` file) holding this one robot's scans and odometry.
    pub dataset: PathBuf,
    /// With a bag: which scans, odometry and frame (see [`olmap::io::bag::ExtractOptions`]).
    pub bag: olmap::io::bag::ExtractOptions,
    /// The robot's name in the dataset, e.g. `robot0` (also the node's name).
    pub robot: String,
    /// Stops replayed per second (default 1).
    pub rate: f64,
    /// The team's finest resolution, metres (default 0.1): each scan is sent as its
    /// occupancy list at this resolution — the occupied voxels' keys — with the sensor
    /// origin, odometry and sightings. Must equal the node's `list_resolution`.
    pub resolution: f64,
    /// The node (its name is the robot's name).
    pub node: NodeOptions,
}

/// What a replay did.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct RobotSummary {
    /// The robot's id in the dataset.
    pub robot: u32,
    /// Stops in the dataset.
    pub stops: usize,
    /// Stops recorded and published by this run.
    pub published: usize,
    /// Stops already in the store (a restarted robot does not record them again).
    pub resumed: usize,
    /// Points of the raw scans published, in all.
    pub raw_points: u64,
    /// Points of the occupancy lists published, in all.
    pub list_points: u64,
    /// Bytes of record payloads published, in all.
    pub bytes: u64,
}

/// A scan turned into what crosses the network: its cloud replaced by the occupancy list
/// at `resolution` (one point per occupied voxel: its centre, in key order; attributes
/// dropped), everything else as recorded.
pub fn occupancy_record(scan: &StoredScan, resolution: f64) -> Result<StoredScan> {
    let cloud = crate::protocol::occupancy_list(&scan.cloud, resolution).ok_or_else(|| {
        NetError::InvalidArgument(format!(
            "scan {} of robot {}: no occupancy list at {resolution} m (a resolution must be \
             positive, and every point within ±104,000 voxels of the origin)",
            scan.seq, scan.robot
        ))
    })?;
    Ok(StoredScan {
        cloud,
        ..scan.clone()
    })
}

/// Reads the robot's records: from a dataset folder, robot `opts.robot`'s id and scans in
/// seq order (a scan file that cannot be read is skipped with a warning on stderr); from a
/// ROS 2 bag, [`bag_records`].
pub fn robot_records(opts: &RobotOptions) -> Result<(u32, Vec<StoredScan>)> {
    let (dataset, name) = (opts.dataset.as_path(), opts.robot.as_str());
    if olmap::io::bag::is_bag_path(dataset) {
        return bag_records(dataset, name, &opts.bag);
    }
    let data = olmap::sim::read_dataset(dataset)?;
    let (store, skipped) = data.to_store_skipping()?;
    for s in data.skipped.iter().chain(&skipped) {
        eprintln!("warning: skipped {}: {}", s.path, s.reason);
    }
    let robot = store
        .robots()
        .into_iter()
        .find(|&r| store.robot_name(r) == name)
        .ok_or_else(|| {
            let names: Vec<String> = store
                .robots()
                .iter()
                .map(|&r| store.robot_name(r))
                .collect();
            NetError::InvalidArgument(format!(
                "no robot '{name}' in {} (it has {})",
                dataset.display(),
                names.join(", ")
            ))
        })?;
    Ok((robot, store.scans_of(robot).cloned().collect()))
}

/// One robot's records from a ROS 2 bag: each extracted scan (see
/// [`olmap::io::bag::extract_scans`]) becomes stop `seq` = its order in the bag, with its
/// header stamp, its odometry and no sightings. The robot's id is the number its name ends
/// in (`robot3` → 3), so that the team can tell robots apart; a bag has no ground truth.
pub fn bag_records(
    bag: &std::path::Path,
    name: &str,
    extract: &olmap::io::bag::ExtractOptions,
) -> Result<(u32, Vec<StoredScan>)> {
    let digits: String = name
        .chars()
        .rev()
        .take_while(char::is_ascii_digit)
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .collect();
    let robot: u32 = digits.parse().map_err(|_| {
        NetError::InvalidArgument(format!(
            "--robot '{name}': a robot replayed from a bag needs a name ending in its number \
             (robot0, robot1, ...), its id in the team"
        ))
    })?;
    let opened = olmap::io::bag::Bag::open(bag).map_err(olmap::Error::from)?;
    let ex = olmap::io::bag::extract_scans(&opened, extract)?;
    for s in &ex.skipped {
        eprintln!("warning: skipped {s}");
    }
    if let Some(s) = &ex.stopped_early {
        eprintln!("warning: reading stopped early: {s}");
    }
    let scans = ex
        .scans
        .into_iter()
        .enumerate()
        .map(|(seq, s)| StoredScan {
            robot,
            seq: seq as u32,
            time: s.stamp.seconds(),
            odometry: s.odometry,
            cloud: s.cloud,
            sightings: Vec::new(),
        })
        .collect();
    Ok((robot, scans))
}

/// Replays one robot: starts its node, then [`replay_on`] it. Returns with the node still
/// running (it keeps serving its store: the caller decides how long).
pub fn run_robot(
    opts: &RobotOptions,
    stop: &AtomicBool,
    mut on_stop: impl FnMut(u32, &RobotSummary),
) -> Result<(Node, RobotSummary)> {
    check_rate(opts.rate)?;
    let (robot, scans) = robot_records(opts)?;
    let mut node_opts = opts.node.clone();
    node_opts.list_resolution = opts.resolution;
    let node = Node::start(node_opts)?;
    let summary = replay_on(&node, opts, robot, &scans, stop, &mut on_stop)?;
    Ok((node, summary))
}

fn check_rate(rate: f64) -> Result<()> {
    if !(rate.is_finite() && rate > 0.0 && rate <= 1000.0) {
        return Err(NetError::InvalidArgument(format!(
            "--rate {rate} must be a number of stops per second in (0, 1000]"
        )));
    }
    Ok(())
}

/// Replays robot `robot`'s `scans` on a running node: at each stop (`1 / rate` seconds
/// apart) stores and publishes the stop's occupancy-list record, skipping stops the store
/// already holds (a robot restarted after a kill resumes where it was). Calls
/// `on_stop(seq, summary)` after each stop; returns early when `stop` is set.
pub fn replay_on(
    node: &Node,
    opts: &RobotOptions,
    robot: u32,
    scans: &[StoredScan],
    stop: &AtomicBool,
    on_stop: &mut dyn FnMut(u32, &RobotSummary),
) -> Result<RobotSummary> {
    check_rate(opts.rate)?;
    let mut summary = RobotSummary {
        robot,
        stops: scans.len(),
        ..RobotSummary::default()
    };
    let period = Duration::from_secs_f64(1.0 / opts.rate);
    let start = Instant::now();
    for (i, scan) in scans.iter().enumerate() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        if node.holds(robot, scan.seq) {
            summary.resumed += 1;
            continue;
        }
        let due = start + period.mul_f64((i - summary.resumed) as f64);
        while Instant::now() < due && !stop.load(Ordering::Relaxed) {
            std::thread::sleep((due - Instant::now()).min(Duration::from_millis(50)));
        }
        let record = occupancy_record(scan, opts.resolution)?;
        summary.raw_points += scan.cloud.len() as u64;
        summary.list_points += record.cloud.len() as u64;
        let before = node.counters().record_bytes_published;
        node.record(&opts.robot, record)?;
        summary.bytes += node.counters().record_bytes_published - before;
        summary.published += 1;
        on_stop(scan.seq, &summary);
    }
    Ok(summary)
}

/// Every robot's records of a store, as a robot replays them (tests and benches): the
/// occupancy-list records at `resolution`.
pub fn occupancy_store(store: &ScanStore, resolution: f64) -> Result<ScanStore> {
    let mut out = ScanStore::new();
    for scan in store.iter() {
        out.set_robot_name(scan.robot, &store.robot_name(scan.robot))?;
        out.insert(occupancy_record(scan, resolution)?)?;
    }
    Ok(out)
}
