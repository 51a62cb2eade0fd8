//! The mapper role: merge every record of the team into a durable store, place each new
//! record in a live map as it arrives, publish figures, serve the live map and poses, and
//! write the outputs on request and on exit.
//!
//! Live placement is incremental ([`olmap::team::LiveTeam`]): each record is linked to the
//! records held (sightings at the same moment) and placed against the map as it is, in the
//! order records arrive; scans that cannot be placed yet wait and are retried when the
//! mapper has nothing new to place. The publish→placement latency is one scan's placement,
//! not a whole team mapping. The written outputs ([`Mapper::write_outputs`], on exit) are
//! the batch team mapper of `olmap team` run on the merged store, so the final map and
//! poses are exactly those `olmap team` computes from the same records, whatever order the
//! records arrived in.

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use olmap::align::icp::NormalNeighbourhood;
use olmap::geometry::PoseList;
use olmap::mapping::ScanOutcome;
use olmap::team::{run_team_pipeline, LiveTeam, ScanStore, TeamJob, TeamParams, TeamReport};
use serde::Serialize;
use zenoh::Wait;

use crate::error::{NetError, Result};
use crate::node::{lock, now_ns, MapFigures, Node, NodeOptions, Shared};
use crate::status::{quantile, NodeStatus};

/// What a mapper does.
#[derive(Debug, Clone)]
pub struct MapperOptions {
    /// The node (store, network, limits).
    pub node: NodeOptions,
    /// Output folder: `team.olm` (and `.bt`, `.ply`), `team_poses.txt`, `team.store`,
    /// `report.json` (the team report), `net.json` (the node's status and counters).
    pub out: PathBuf,
    /// The team mapper's parameters (the live map and the written outputs).
    pub params: TeamParams,
    /// Ground truth to evaluate against, named as the team map names scans.
    pub truth: Option<PoseList>,
    /// Wait this long after a record arrives before placing it in the live map (default
    /// 0: every record is placed as soon as the mapping thread is free).
    pub settle: Duration,
}

/// What a mapper wrote when it stopped or was asked to write.
#[derive(Debug, Clone, Serialize)]
pub struct MapperOutputs {
    /// The output folder.
    pub out: PathBuf,
    /// Records in the written store.
    pub records: usize,
    /// Scans placed in the written map.
    pub placed: usize,
    /// The node's status when written (also `net.json`).
    pub status: NodeStatus,
    /// The team report (also `report.json`).
    #[serde(skip)]
    pub report: Option<TeamReport>,
}

/// What the serving side sees of the live map: snapshots the mapping thread publishes
/// (the live map itself stays on the mapping thread, so a query never waits for a
/// placement).
#[derive(Default)]
struct Latest {
    /// The placed scans' poses after the last change.
    poses: PoseList,
    /// The live map as `.olm` bytes, made when the mapping thread was last idle.
    map_olm: Option<Arc<Vec<u8>>>,
    /// Scans placed so far (by `(robot, seq)`), for latency: first placement only.
    placed_once: HashSet<(u32, u32)>,
    latencies_ms: Vec<f64>,
    /// Those of scans placed when their record arrived.
    arrival_latencies_ms: Vec<f64>,
}
/// A running mapper: a [`Node`], a mapping thread and a serving thread.
pub struct Mapper {
    node: Node,
    opts: Arc<MapperOptions>,
    latest: Arc<Mutex<Latest>>,
    threads: Vec<JoinHandle<()>>,
    write_lock: Arc<Mutex<()>>,
    /// Set when the mapper is finishing: the live map takes no more records.
    finishing: Arc<AtomicBool>,
}

impl Mapper {
    /// Starts the node (resuming from its store), the mapping thread and the queryables
    /// `map`, `poses` and `write`.
    pub fn start(opts: MapperOptions) -> Result<Mapper> {
        let node = Node::start(opts.node.clone())?;
        let opts = Arc::new(opts);
        let latest = Arc::new(Mutex::new(Latest::default()));
        let write_lock = Arc::new(Mutex::new(()));
        let finishing = Arc::new(AtomicBool::new(false));
        *lock(&node.shared.figures) = Some(MapFigures::default());
        let mut threads = Vec::new();
        {
            let shared = node.shared.clone();
            let latest = latest.clone();
            let opts = opts.clone();
            let finishing = finishing.clone();
            threads.push(std::thread::spawn(move || {
                mapping_loop(&shared, &opts, &latest, &finishing)
            }));
        }
        {
            let keys = node.keys().clone();
            let session = node.session().clone();
            let q = |k: String| session.declare_queryable(k).wait().map_err(NetError::zenoh);
            let (map_q, poses_q, write_q) = (q(keys.map())?, q(keys.poses())?, q(keys.write())?);
            let shared = node.shared.clone();
            let latest = latest.clone();
            let opts = opts.clone();
            let write_lock = write_lock.clone();
            threads.push(std::thread::spawn(move || {
                let tick = Duration::from_millis(50);
                while !shared.stop.load(Ordering::Relaxed) {
                    let mut idle = true;
                    if let Ok(Some(query)) = map_q.try_recv() {
                        idle = false;
                        let bytes = lock(&latest).map_olm.clone();
                        if let Some(bytes) = bytes {
                            let _ = query
                                .reply(query.key_expr().clone(), bytes.as_slice())
                                .wait();
                        }
                    }
                    if let Ok(Some(query)) = poses_q.try_recv() {
                        idle = false;
                        let text = {
                            let l = lock(&latest);
                            let mut v = Vec::new();
                            (!l.poses.is_empty()).then(|| l.poses.write(&mut v).map(|_| v))
                        };
                        if let Some(Ok(text)) = text {
                            let _ = query.reply(query.key_expr().clone(), text).wait();
                        }
                    }
                    if let Ok(Some(query)) = write_q.try_recv() {
                        idle = false;
                        let answer = write_outputs(&shared, &opts, &write_lock)
                            .map(|o| o.out.display().to_string())
                            .unwrap_or_else(|e| format!("error: {e}"));
                        let _ = query.reply(query.key_expr().clone(), answer).wait();
                    }
                    if idle {
                        std::thread::sleep(tick);
                    }
                }
            }));
        }
        Ok(Mapper {
            node,
            opts,
            latest,
            threads,
            write_lock,
            finishing,
        })
    }

    /// The mapper's node.
    pub fn node(&self) -> &Node {
        &self.node
    }

    /// The live map's poses, named `ROBOT/scanNNN`, in joining order (empty before the
    /// first record).
    pub fn live_poses(&self) -> PoseList {
        lock(&self.latest).poses.clone()
    }

    /// Maps the store as it is now with the team pipeline and writes every output into the
    /// output folder (one consistent set: see [`run_team_pipeline`]).
    pub fn write_outputs(&self) -> Result<MapperOutputs> {
        write_outputs(&self.node.shared, &self.opts, &self.write_lock)
    }

    /// Writes the outputs one last time (the live map takes no more records meanwhile; a
    /// placement in progress finishes), then closes: what a mapper does on SIGINT/SIGTERM.
    pub fn finish(self) -> Result<MapperOutputs> {
        self.finishing.store(true, Ordering::Relaxed);
        let out = self.write_outputs();
        self.close();
        out
    }

    /// Stops the threads (a placement in progress finishes first) and closes the node.
    pub fn close(mut self) {
        self.node.shared.stop.store(true, Ordering::Relaxed);
        self.node.shared.changed.notify_all();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

fn write_outputs(
    shared: &Shared,
    opts: &MapperOptions,
    write_lock: &Mutex<()>,
) -> Result<MapperOutputs> {
    let _one_at_a_time = lock(write_lock);
    let store: ScanStore = lock(&shared.store).store().clone();
    if store.is_empty() {
        return Err(NetError::InvalidArgument(
            "the mapper holds no record yet: nothing to write".into(),
        ));
    }
    let run = run_team_pipeline(
        &TeamJob {
            store: &store,
            truth: opts.truth.as_ref(),
            params: &opts.params,
            out: &opts.out,
            solo: false,
        },
        &mut |_, _, _| {},
    )?;
    let status = shared.status();
    olmap::file::write_atomic(&opts.out.join("net.json"), "JSON", |w| {
        serde_json::to_writer_pretty(&mut *w, &status).map_err(std::io::Error::other)
    })?;
    Ok(MapperOutputs {
        out: opts.out.clone(),
        records: store.len(),
        placed: run.team.build.placed.len(),
        status,
        report: Some(run.report),
    })
}

/// Most waiting scans retried per idle round of the mapping thread.
const RETRIES_PER_ROUND: usize = 1;

/// The finest voxel, metres, at which the live map merges the placed records' points for
/// the refinement (ICP) of the next placements ([`live_params`]). Records cross the
/// network as occupancy lists of voxel centres at the team's resolution (0.1 m unless the
/// robots are told otherwise), so merging them at the batch mapper's 0.05 m quadruples
/// the map's points on every surface without sharper surfaces to fit: every placement
/// then rebuilds four times the points and their normals. Measured on the benchmark's
/// team (demo lab, 4 robots × 10 stops, thesis-degraded odometry, release, 2 cores):
/// placing the 40 records took 10.4 s at 0.05 m and 7.0 s at 0.1 m (seed 1), 11.4 s and
/// 7.9 s (seed 2), with every record placed and the placements as accurate against the
/// simulator's truth (mean / largest error 0.028 / 0.094 m and 0.030 / 0.097 m; seed 2
/// 0.055 / 0.143 m and 0.051 / 0.117 m).
pub const LIVE_REFINE_VOXEL: f64 = 0.1;

/// The live map's parameters: the mapper's, with the refinement points merged at no finer
/// than [`LIVE_REFINE_VOXEL`] and the ICP target's normals from each map voxel's 3 × 3 × 3
/// block ([`NormalNeighbourhood::VoxelBlock`]: the map's target is rebuilt after every
/// placement, and the normals a registration touches were about a fifth of its time with
/// a k-d tree query each). Measured with the benchmark's team (release, 2 cores, the 40
/// records given one by one): seed 1 4.4 → 3.7 s, placement errors mean / largest 0.030 /
/// 0.097 → 0.024 / 0.078 m; seed 2 5.1 → 5.0 s, 0.050 / 0.117 → 0.021 / 0.060 m; seed 3
/// 7.8 → 7.4 s, 24 of 40 placed either way, 0.014 / 0.045 m. The written outputs keep the
/// mapper's own parameters (they must equal `olmap team` on the same records). The cost of
/// a record with these parameters is the `live_map` benchmark (`cargo bench -p olmap-net
/// --bench live_map`).
pub fn live_params(params: &TeamParams) -> TeamParams {
    let mut live = params.clone();
    live.map.refine_map_voxel = live.map.refine_map_voxel.max(LIVE_REFINE_VOXEL);
    if let Some(icp) = &mut live.map.register.refine {
        icp.normal_neighbourhood = NormalNeighbourhood::VoxelBlock;
    }
    live
}

fn mapping_loop(
    shared: &Shared,
    opts: &MapperOptions,
    latest: &Mutex<Latest>,
    finishing: &AtomicBool,
) {
    let mut live = match LiveTeam::new(live_params(&opts.params)) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("{}: cannot start the live map: {e}", shared.opts.name);
            return;
        }
    };
    let mut seen_generation = 0u64;
    let mut reported_error = false;
    let mut map_snapshot_at = usize::MAX;
    let running = || !shared.stop.load(Ordering::Relaxed) && !finishing.load(Ordering::Relaxed);
    while running() {
        let generation = *lock(&shared.generation);
        let new = if generation != seen_generation {
            if !opts.settle.is_zero() {
                std::thread::sleep(opts.settle);
            }
            seen_generation = *lock(&shared.generation);
            unplaced_records(shared, &live)
        } else {
            Vec::new()
        };
        if new.is_empty() {
            // Nothing new: retry a waiting scan; else refresh the map snapshot; else wait.
            if live.has_due() {
                retry_round(shared, latest, &mut live, &mut reported_error);
            } else if map_snapshot_at != live.placements().len() {
                map_snapshot_at = live.placements().len();
                snapshot_map(shared, latest, &mut live);
            } else {
                let g = lock(&shared.generation);
                if *g == seen_generation {
                    let _ = shared
                        .changed
                        .wait_timeout(g, Duration::from_millis(200))
                        .unwrap_or_else(|p| p.into_inner());
                }
            }
            continue;
        }
        for (k, (name, scan)) in new.into_iter().enumerate() {
            if !running() {
                break;
            }
            // Records read together (they arrived while this thread was busy or settling)
            // are handled as if each had arrived alone: the waiting scans the previous one
            // made due are retried before the next is added. Otherwise a waiting scan is
            // retried against a map that grew meanwhile, and a registration that succeeds
            // against the smaller map can fail against the larger one: with the scan's
            // robot tied by it alone, three records of the staggered bench waited for good
            // when this thread was 0.3 s late.
            if k > 0 {
                while running() && live.has_due() {
                    if !retry_round(shared, latest, &mut live, &mut reported_error) {
                        break;
                    }
                }
            }
            match live.add(&scan, &name) {
                Ok(ScanOutcome::Placed(_)) => {
                    publish(shared, latest, &live, &[(scan.robot, scan.seq)], true)
                }
                Ok(ScanOutcome::Waiting(_)) => publish(shared, latest, &live, &[], true),
                Err(e) => report_once(shared, &mut reported_error, &e),
            }
        }
    }
}

/// One round of retries of the live map's waiting scans ([`RETRIES_PER_ROUND`]), the
/// placements published; `false` when the round failed (the error reported once).
fn retry_round(
    shared: &Shared,
    latest: &Mutex<Latest>,
    live: &mut LiveTeam,
    reported_error: &mut bool,
) -> bool {
    match live.retry_waiting(RETRIES_PER_ROUND) {
        Ok(placed) => {
            if !placed.is_empty() {
                publish(shared, latest, live, &placed, false);
            }
            true
        }
        Err(e) => {
            report_once(shared, reported_error, &e);
            false
        }
    }
}

/// Fuses the scans placed since the last snapshot into the live map and publishes it as
/// `.olm` bytes and its size (done when idle: ray tracing is not on the latency path).
fn snapshot_map(shared: &Shared, latest: &Mutex<Latest>, live: &mut LiveTeam) {
    let Ok(map) = live.map() else {
        return;
    };
    let voxels = map.len() as u64;
    let mut bytes = Vec::new();
    if map.write_olm(&mut bytes).is_err() {
        return;
    }
    lock(latest).map_olm = Some(Arc::new(bytes));
    let mut figures = lock(&shared.figures);
    figures.get_or_insert_with(MapFigures::default).voxels = voxels;
}

/// Logs the first live-mapping error (the written outputs, mapped in batch, are what
/// counts; the live map skips what it could not take).
fn report_once(shared: &Shared, reported: &mut bool, e: &olmap::Error) {
    if !*reported {
        eprintln!(
            "{}: live mapping: {e} (later errors not shown)",
            shared.opts.name
        );
        *reported = true;
    }
}

/// The records held and not yet in the live map, oldest first (by time stamp, then robot
/// and seq), with their robots' names.
fn unplaced_records(shared: &Shared, live: &LiveTeam) -> Vec<(String, olmap::team::StoredScan)> {
    let store = lock(&shared.store);
    let store = store.store();
    let mut new: Vec<(String, olmap::team::StoredScan)> = store
        .iter()
        .filter(|s| live.index_of(s.robot, s.seq).is_none())
        .map(|s| (store.robot_name(s.robot), s.clone()))
        .collect();
    new.sort_by(|a, b| {
        a.1.time
            .total_cmp(&b.1.time)
            .then((a.1.robot, a.1.seq).cmp(&(b.1.robot, b.1.seq)))
    });
    new
}

/// Publishes the live map's state after a change: the scans `placed` now (latency of those
/// placed for the first time; `on_arrival`: placed when their record arrived, not after
/// waiting), the poses, the figures.
fn publish(
    shared: &Shared,
    latest: &Mutex<Latest>,
    live: &LiveTeam,
    placed: &[(u32, u32)],
    on_arrival: bool,
) {
    let now = now_ns();
    let mut latest = lock(latest);
    {
        let sent = lock(&shared.sent_ns);
        for key in placed {
            if latest.placed_once.insert(*key) {
                if let Some(&t) = sent.get(key) {
                    let ms = now.saturating_sub(t) as f64 / 1e6;
                    latest.latencies_ms.push(ms);
                    if on_arrival {
                        latest.arrival_latencies_ms.push(ms);
                    }
                }
            }
        }
    }
    latest.poses = live.poses();
    let latency_ms = percentiles(&latest.latencies_ms);
    let arrival_latency_ms = percentiles(&latest.arrival_latencies_ms);
    let mut per_robot: BTreeMap<u32, u64> = BTreeMap::new();
    for p in live.placements() {
        *per_robot.entry(live.key(p.index).0).or_default() += 1;
    }
    let mut figures = lock(&shared.figures);
    let f = figures.get_or_insert_with(MapFigures::default);
    f.placed = per_robot;
    f.runs += 1;
    f.mapped_records = live.len() as u64;
    f.latency_ms = latency_ms;
    f.arrival_latency_ms = arrival_latency_ms;
}

/// p50, p95 and the largest of `values` (`None` when empty).
fn percentiles(values: &[f64]) -> Option<[f64; 3]> {
    let mut l = values.to_vec();
    match (
        quantile(&mut l, 0.5),
        quantile(&mut l, 0.95),
        quantile(&mut l, 1.0),
    ) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use olmap::align::icp::IcpParams;

    use super::*;

    /// The live map merges no finer than the records' resolution, its ICP normals from
    /// voxel blocks; a coarser merge asked for is kept, and nothing else of the parameters
    /// changes.
    #[test]
    fn the_live_map_merges_at_the_records_resolution_or_coarser() {
        let batch = TeamParams::default();
        assert!(batch.map.refine_map_voxel < LIVE_REFINE_VOXEL);
        let live = live_params(&batch);
        assert_eq!(live.map.refine_map_voxel, LIVE_REFINE_VOXEL);
        assert_eq!(live.map.sensor, batch.map.sensor);
        assert_eq!(live.map.odometry_window, batch.map.odometry_window);
        let (icp, batch_icp) = (
            live.map.register.refine.as_ref().unwrap(),
            batch.map.register.refine.as_ref().unwrap(),
        );
        assert_eq!(icp.normal_neighbourhood, NormalNeighbourhood::VoxelBlock);
        assert_eq!(
            IcpParams {
                normal_neighbourhood: batch_icp.normal_neighbourhood,
                ..icp.clone()
            },
            *batch_icp
        );
        let mut coarse = TeamParams::default();
        coarse.map.refine_map_voxel = 0.2;
        assert_eq!(live_params(&coarse).map.refine_map_voxel, 0.2);
    }
}
