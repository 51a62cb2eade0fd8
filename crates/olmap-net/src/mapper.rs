//! The mapper role: merge every record of the team into a durable store, re-map the team
//! as records arrive, publish figures, serve the map and poses, and write the outputs on
//! request and on exit.
//!
//! Placement is the batch team mapper of `olmap team` re-run on the merged store whenever
//! new records have arrived (and the previous run has finished): so the final map and
//! poses are exactly those `olmap team` computes from the same records. An incremental 3D
//! mapper would cut the publish→placement latency from one whole team mapping to one scan's
//! placement; until olmap has one, this is the honest choice.

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use olmap::geometry::PoseList;
use olmap::team::{
    map_team, run_team_pipeline, ScanStore, TeamJob, TeamMap, TeamParams, TeamReport,
};
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
    /// The team mapper's parameters.
    pub params: TeamParams,
    /// Ground truth to evaluate against, named as the team map names scans.
    pub truth: Option<PoseList>,
    /// Wait this long after a record arrives before mapping, so that a burst is mapped
    /// once (default 0.2 s).
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

/// The latest completed mapping run.
#[derive(Default)]
struct Latest {
    map: Option<Arc<TeamMap>>,
    /// Scans placed so far (by `(robot, seq)`), for latency: first placement only.
    placed_once: HashSet<(u32, u32)>,
    latencies_ms: Vec<f64>,
}

/// A running mapper: a [`Node`], a mapping thread and a serving thread.
pub struct Mapper {
    node: Node,
    opts: Arc<MapperOptions>,
    latest: Arc<Mutex<Latest>>,
    threads: Vec<JoinHandle<()>>,
    write_lock: Arc<Mutex<()>>,
    /// Set when the mapper is finishing: no new mapping run starts.
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
                        let bytes = lock(&latest).map.as_ref().map(|m| {
                            let mut v = Vec::new();
                            m.build.map.write_olm(&mut v).map(|_| v)
                        });
                        if let Some(Ok(bytes)) = bytes {
                            let _ = query.reply(query.key_expr().clone(), bytes).wait();
                        }
                    }
                    if let Ok(Some(query)) = poses_q.try_recv() {
                        idle = false;
                        let text = lock(&latest).map.as_ref().map(|m| {
                            let mut v = Vec::new();
                            m.poses().write(&mut v).map(|_| v)
                        });
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

    /// The latest joint map, if a mapping run has completed.
    pub fn latest(&self) -> Option<Arc<TeamMap>> {
        lock(&self.latest).map.clone()
    }

    /// Maps the store as it is now with the team pipeline and writes every output into the
    /// output folder (one consistent set: see [`run_team_pipeline`]).
    pub fn write_outputs(&self) -> Result<MapperOutputs> {
        write_outputs(&self.node.shared, &self.opts, &self.write_lock)
    }

    /// Writes the outputs one last time (no new live mapping run starts meanwhile; one in
    /// progress finishes), then closes: what a mapper does on SIGINT/SIGTERM.
    pub fn finish(self) -> Result<MapperOutputs> {
        self.finishing.store(true, Ordering::Relaxed);
        let out = self.write_outputs();
        self.close();
        out
    }

    /// Stops the threads (a mapping run in progress finishes first) and closes the node.
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

fn mapping_loop(
    shared: &Shared,
    opts: &MapperOptions,
    latest: &Mutex<Latest>,
    finishing: &AtomicBool,
) {
    let mut mapped_generation = 0u64;
    while !shared.stop.load(Ordering::Relaxed) && !finishing.load(Ordering::Relaxed) {
        let generation = {
            let g = lock(&shared.generation);
            let g = shared
                .changed
                .wait_timeout(g, Duration::from_millis(200))
                .unwrap_or_else(|p| p.into_inner())
                .0;
            *g
        };
        if generation == mapped_generation || shared.stop.load(Ordering::Relaxed) {
            continue;
        }
        std::thread::sleep(opts.settle);
        if finishing.load(Ordering::Relaxed) {
            break;
        }
        mapped_generation = *lock(&shared.generation);
        let store = lock(&shared.store).store().clone();
        let started = Instant::now();
        match map_team(&store, &opts.params, |_, _| {}) {
            Ok(team) => publish_run(shared, latest, team, store.len() as u64),
            Err(e) => eprintln!(
                "{}: mapping {} records failed after {:.1} s: {e}",
                shared.opts.name,
                store.len(),
                started.elapsed().as_secs_f64()
            ),
        }
    }
}

/// Records a completed run: latencies of scans placed for the first time, figures.
fn publish_run(shared: &Shared, latest: &Mutex<Latest>, team: TeamMap, mapped_records: u64) {
    let now = now_ns();
    let mut placed: BTreeMap<u32, u64> = BTreeMap::new();
    let mut latest = lock(latest);
    {
        let sent = lock(&shared.sent_ns);
        for p in &team.build.placed {
            let key = team.keys[p.index];
            *placed.entry(key.0).or_default() += 1;
            if latest.placed_once.insert(key) {
                if let Some(&t) = sent.get(&key) {
                    latest.latencies_ms.push(now.saturating_sub(t) as f64 / 1e6);
                }
            }
        }
    }
    let mut l = latest.latencies_ms.clone();
    let latency_ms = match (
        quantile(&mut l, 0.5),
        quantile(&mut l, 0.95),
        quantile(&mut l, 1.0),
    ) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    let mut figures = lock(&shared.figures);
    let f = figures.get_or_insert_with(MapFigures::default);
    f.placed = placed;
    f.voxels = team.build.map.len() as u64;
    f.runs += 1;
    f.mapped_records = mapped_records;
    f.latency_ms = latency_ms;
    latest.map = Some(Arc::new(team));
}
