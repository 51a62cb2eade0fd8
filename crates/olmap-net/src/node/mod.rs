//! [`Node`]: one process's place in the team — its durable store, the records it receives,
//! publishes and serves, and the anti-entropy loop that fetches what it misses.

mod options;

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use olmap::team::{ScanStore, StoredScan};
use zenoh::qos::CongestionControl;
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::Wait;

pub use options::{NetOptions, NodeOptions};

use crate::durable::DurableStore;
use crate::error::{BadMessage, NetError, Result};
use crate::fault::{Faults, Outgoing};
use crate::protocol::{open, Digest, FetchRequest, Keys, Kind, RecordMessage, MAX_FETCH};
use crate::status::{Counters, NodeStatus, RobotStatus};

/// How long a fetch waits for replies.
const FETCH_TIMEOUT: Duration = Duration::from_secs(2);
/// Most fetches one anti-entropy round sends.
const FETCHES_PER_ROUND: usize = 8;

/// Locks a mutex, carrying on with the data if another thread panicked while holding it
/// (every structure here stays consistent between statements).
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Nanoseconds since the Unix epoch.
pub(crate) fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Figures a mapper adds to its node's status.
#[derive(Debug, Clone, Default)]
pub struct MapFigures {
    /// Scans placed per robot id.
    pub placed: BTreeMap<u32, u64>,
    /// Occupied voxels of the live map (updated when the mapper is idle).
    pub voxels: u64,
    /// Live map updates: records given to it and waiting scans placed.
    pub runs: u64,
    /// Records given to the live map so far.
    pub mapped_records: u64,
    /// Publish→placement latency of placed scans, ms: p50, p95, max.
    pub latency_ms: Option<[f64; 3]>,
    /// The same of the scans placed when their record arrived (not those that waited for
    /// the map to reach them), ms: p50, p95, max.
    pub arrival_latency_ms: Option<[f64; 3]>,
}

/// State shared between a node's threads and Zenoh's callbacks.
pub(crate) struct Shared {
    pub(crate) opts: NodeOptions,
    pub(crate) keys: Keys,
    start: Instant,
    pub(crate) store: Mutex<DurableStore>,
    pub(crate) counters: Mutex<Counters>,
    /// Publish time of records, for latency (ns since the epoch; absent when unknown).
    pub(crate) sent_ns: Mutex<HashMap<(u32, u32), u64>>,
    faults: Mutex<Option<Faults>>,
    /// Records seen in other nodes' digests and not held: robot → seqs.
    wants: Mutex<BTreeMap<u32, BTreeSet<u32>>>,
    /// Bumped at every new record; waited on by mappers.
    pub(crate) generation: Mutex<u64>,
    pub(crate) changed: Condvar,
    pub(crate) stop: AtomicBool,
    logged: Mutex<HashSet<&'static str>>,
    /// Per robot: the second a rate window started, records in it.
    rate: Mutex<HashMap<u32, (u64, u32)>>,
    pub(crate) figures: Mutex<Option<MapFigures>>,
    pub(crate) session: zenoh::Session,
}

impl Shared {
    fn refuse(&self, key: &str, bad: &BadMessage) {
        *lock(&self.counters)
            .refused
            .entry(bad.reason().to_string())
            .or_default() += 1;
        if lock(&self.logged).insert(bad.reason()) {
            eprintln!(
                "{}: dropped a payload on {key}: {bad} (further '{}' payloads are counted, not logged)",
                self.opts.name,
                bad.reason()
            );
        }
    }

    fn over_rate(&self, robot: u32) -> bool {
        let second = self.start.elapsed().as_secs();
        let mut rate = lock(&self.rate);
        let entry = rate.entry(robot).or_insert((second, 0));
        if entry.0 != second {
            *entry = (second, 0);
        }
        entry.1 += 1;
        entry.1 > self.opts.max_rate
    }

    /// Handles a record payload received on `key` (published, or a fetch reply).
    pub(crate) fn receive_record(&self, key: &str, payload: &[u8], via_fetch: bool) {
        if let Some(f) = lock(&self.faults).as_mut() {
            if f.drop_incoming() {
                lock(&self.counters).fault_dropped += 1;
                return;
            }
        }
        let checked = (|| {
            let k = self
                .keys
                .parse_record(key)
                .ok_or_else(|| BadMessage::Key(format!("'{key}' is not a record key")))?;
            let body = open(payload, Kind::Record, self.opts.max_payload)?;
            RecordMessage::decode(body, k)
        })();
        let msg = match checked {
            Ok(m) => m,
            Err(bad) => return self.refuse(key, &bad),
        };
        let key_pair = (msg.scan.robot, msg.scan.seq);
        let held = lock(&self.store)
            .store()
            .get(key_pair.0, key_pair.1)
            .is_some();
        if !held && self.over_rate(msg.scan.robot) {
            return self.refuse(key, &BadMessage::Rate(msg.scan.robot));
        }
        let inserted = lock(&self.store).insert(&msg.name, &msg.scan);
        match inserted {
            Ok(Ok(true)) => {
                {
                    let mut c = lock(&self.counters);
                    c.records_new += 1;
                    if via_fetch {
                        c.records_recovered += 1;
                    }
                }
                if msg.sent_ns != 0 {
                    lock(&self.sent_ns).entry(key_pair).or_insert(msg.sent_ns);
                }
                if let Some(w) = lock(&self.wants).get_mut(&key_pair.0) {
                    w.remove(&key_pair.1);
                }
                self.bump();
            }
            Ok(Ok(false)) => lock(&self.counters).records_duplicate += 1,
            Ok(Err(bad)) => self.refuse(key, &bad),
            Err(e) => eprintln!(
                "{}: could not store scan {} of robot {}: {e}",
                self.opts.name, key_pair.1, key_pair.0
            ),
        }
    }

    fn bump(&self) {
        *lock(&self.generation) += 1;
        self.changed.notify_all();
    }

    /// Sends through the fault plan.
    pub(crate) fn send(&self, msg: Outgoing) {
        let out = match lock(&self.faults).as_mut() {
            Some(f) => {
                let before = (f.dropped, f.duplicated);
                let out = f.outgoing(msg);
                let mut c = lock(&self.counters);
                c.fault_dropped += f.dropped - before.0;
                c.fault_duplicated += f.duplicated - before.1;
                out
            }
            None => vec![msg],
        };
        for m in out {
            self.put(m);
        }
    }

    fn put(&self, m: Outgoing) {
        let cc = if m.block {
            CongestionControl::Block
        } else {
            CongestionControl::Drop
        };
        if let Err(e) = self
            .session
            .put(&m.key, m.payload)
            .congestion_control(cc)
            .wait()
        {
            if !self.stop.load(Ordering::Relaxed) {
                eprintln!("{}: publishing on {} failed: {e}", self.opts.name, m.key);
            }
        }
    }

    /// Notes what another node's digest holds that this one lacks.
    fn receive_digest(&self, key: &str, payload: &[u8]) {
        if let Some(f) = lock(&self.faults).as_mut() {
            if f.drop_incoming() {
                lock(&self.counters).fault_dropped += 1;
                return;
            }
        }
        let digest =
            match open(payload, Kind::Digest, self.opts.max_payload).and_then(Digest::decode) {
                Ok(d) => d,
                Err(bad) => return self.refuse(key, &bad),
            };
        if self.keys.node_of(key) != Some(digest.node.as_str()) {
            return self.refuse(
                key,
                &BadMessage::Key(format!("a digest of node '{}' on {key}", digest.node)),
            );
        }
        if digest.node == self.opts.name {
            return;
        }
        let store = lock(&self.store);
        let mut wants = lock(&self.wants);
        for (robot, holdings) in &digest.robots {
            // Bounded: at most a few fetches' worth of wants per robot at a time.
            let w = wants.entry(*robot).or_default();
            for seq in holdings.seqs(usize::MAX) {
                if w.len() >= MAX_FETCH * FETCHES_PER_ROUND {
                    break;
                }
                if store.store().get(*robot, seq).is_none() {
                    w.insert(seq);
                }
            }
        }
    }

    /// Answers a fetch with every requested record held.
    fn answer_fetch(&self, query: &zenoh::query::Query) {
        let Some(payload) = query.payload().map(|p| p.to_bytes().into_owned()) else {
            return;
        };
        if let Some(f) = lock(&self.faults).as_ref() {
            if f.partitioned() {
                return;
            }
        }
        let key = query.key_expr().as_str().to_string();
        let req = match open(&payload, Kind::Fetch, self.opts.max_payload)
            .and_then(FetchRequest::decode)
        {
            Ok(r) => r,
            Err(bad) => return self.refuse(&key, &bad),
        };
        if key != self.keys.records_of(req.robot) {
            return self.refuse(
                &key,
                &BadMessage::Key(format!("a fetch of robot {} on {key}", req.robot)),
            );
        }
        let replies: Vec<(String, Vec<u8>)> = {
            let store = lock(&self.store);
            let sent = lock(&self.sent_ns);
            req.seqs
                .iter()
                .filter_map(|&seq| store.store().get(req.robot, seq).map(|s| (seq, s)))
                .map(|(seq, scan)| {
                    let msg = RecordMessage {
                        name: store.store().robot_name(req.robot),
                        sent_ns: sent.get(&(req.robot, seq)).copied().unwrap_or(0),
                        scan: scan.clone(),
                    };
                    (
                        self.keys.record(req.robot, seq),
                        msg.encode_at(Some(self.opts.list_resolution)),
                    )
                })
                .collect()
        };
        for (k, bytes) in replies {
            // Replies go through the plan's drop and duplication (not its reordering:
            // a reply must leave before the query closes).
            let copies = match lock(&self.faults).as_mut() {
                Some(f) => {
                    let before = (f.dropped, f.duplicated);
                    let n = f.copies();
                    let mut c = lock(&self.counters);
                    c.fault_dropped += f.dropped - before.0;
                    c.fault_duplicated += f.duplicated - before.1;
                    n
                }
                None => 1,
            };
            for _ in 0..copies {
                lock(&self.counters).fetch_replies += 1;
                if let Err(e) = query.reply(&k, bytes.clone()).wait() {
                    eprintln!("{}: replying on {k} failed: {e}", self.opts.name);
                }
            }
        }
    }

    /// One anti-entropy round: publish the digest and status, fetch what others hold.
    fn round(&self) {
        let digest = lock(&self.store).digest(&self.opts.name);
        self.send(Outgoing {
            key: self.keys.digest(&self.opts.name),
            payload: digest.encode(),
            block: false,
        });
        let status = self.status();
        self.send(Outgoing {
            key: self.keys.status(&self.opts.name),
            payload: crate::protocol::seal(
                Kind::Status,
                &serde_json::to_vec(&status).expect("status serialises"),
            ),
            block: false,
        });
        let wanted: Vec<FetchRequest> = {
            let wants = lock(&self.wants);
            wants
                .iter()
                .filter(|(_, s)| !s.is_empty())
                .flat_map(|(robot, seqs)| {
                    let seqs: Vec<u32> = seqs.iter().copied().collect();
                    seqs.chunks(MAX_FETCH)
                        .map(|c| FetchRequest {
                            robot: *robot,
                            seqs: c.to_vec(),
                        })
                        .collect::<Vec<_>>()
                })
                .take(FETCHES_PER_ROUND)
                .collect()
        };
        for req in wanted {
            self.fetch(&req);
        }
        if let Some(f) = lock(&self.faults).as_mut() {
            let due = f.release_due();
            for m in due {
                self.put(m);
            }
        }
    }

    fn fetch(&self, req: &FetchRequest) {
        if let Some(f) = lock(&self.faults).as_ref() {
            if f.partitioned() {
                return;
            }
        }
        lock(&self.counters).fetches_sent += 1;
        let replies = match self
            .session
            .get(self.keys.records_of(req.robot))
            .payload(req.encode())
            .target(QueryTarget::All)
            .consolidation(ConsolidationMode::None)
            .timeout(FETCH_TIMEOUT)
            .wait()
        {
            Ok(r) => r,
            Err(e) => {
                eprintln!("{}: fetch failed: {e}", self.opts.name);
                return;
            }
        };
        while let Ok(reply) = replies.recv() {
            if let Ok(sample) = reply.result() {
                let bytes = sample.payload().to_bytes();
                self.receive_record(sample.key_expr().as_str(), &bytes, true);
            }
        }
        // What was asked and did not come stays wanted only if a later digest lists it.
        if let Some(w) = lock(&self.wants).get_mut(&req.robot) {
            for s in &req.seqs {
                w.remove(s);
            }
        }
    }

    pub(crate) fn status(&self) -> NodeStatus {
        let store = lock(&self.store);
        let figures = lock(&self.figures).clone();
        let mut robots = BTreeMap::new();
        for r in store.store().robots() {
            robots.insert(
                store.store().robot_name(r),
                RobotStatus {
                    held: store.store().scans_of(r).count() as u64,
                    placed: figures
                        .as_ref()
                        .and_then(|f| f.placed.get(&r).copied())
                        .unwrap_or(0),
                },
            );
        }
        NodeStatus {
            node: self.opts.name.clone(),
            role: self.opts.role.clone(),
            uptime_s: self.start.elapsed().as_secs_f64(),
            records: store.store().len() as u64,
            robots,
            placed: figures.as_ref().map_or(0, |f| f.placed.values().sum()),
            map_voxels: figures.as_ref().map_or(0, |f| f.voxels),
            map_runs: figures.as_ref().map_or(0, |f| f.runs),
            mapped_records: figures.as_ref().map_or(0, |f| f.mapped_records),
            latency_ms: figures.as_ref().and_then(|f| f.latency_ms),
            arrival_latency_ms: figures.as_ref().and_then(|f| f.arrival_latency_ms),
            counters: lock(&self.counters).clone(),
        }
    }
}

/// A thread handing every item a Zenoh channel delivers to `handle`, until the node stops
/// or the channel closes.
fn serve<T: Send + 'static, H>(
    shared: &Arc<Shared>,
    channel: H,
    tick: Duration,
    handle: impl Fn(&Shared, T) + Send + 'static,
) -> JoinHandle<()>
where
    H: std::ops::Deref<Target = zenoh::handlers::FifoChannelHandler<T>> + Send + 'static,
{
    let s = shared.clone();
    std::thread::spawn(move || {
        while !s.stop.load(Ordering::Relaxed) {
            match channel.recv_timeout(tick) {
                Ok(Some(item)) => handle(&s, item),
                Ok(None) => {}
                Err(_) => break,
            }
        }
    })
}

/// One process's place in the team: its durable store, a subscriber merging every record
/// published on the team's keys, a queryable serving every record it holds (store and
/// forward), a liveliness token, and a thread that every period publishes its digest and
/// status and fetches what other nodes' digests show it lacks (anti-entropy).
///
/// Dropping the node (or [`Node::close`]) stops its threads and closes its session.
pub struct Node {
    pub(crate) shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    _token: zenoh::liveliness::LivelinessToken,
}

impl Node {
    /// Opens the store, the Zenoh session, and starts the node.
    pub fn start(opts: NodeOptions) -> Result<Node> {
        opts.check()?;
        let keys = Keys::new(&opts.net.team)?;
        let store = DurableStore::open(&opts.store)?;
        let config = opts.net.zenoh_config()?;
        let session = zenoh::open(config).wait().map_err(NetError::zenoh)?;
        let faults = opts
            .faults
            .is_active()
            .then(|| Faults::new(opts.faults.clone()));
        // A node resuming from a non-empty store starts one generation in, so that a
        // mapper maps what it already holds.
        let generation = u64::from(!store.store().is_empty());
        let shared = Arc::new(Shared {
            keys: keys.clone(),
            start: Instant::now(),
            store: Mutex::new(store),
            counters: Mutex::new(Counters::default()),
            sent_ns: Mutex::new(HashMap::new()),
            faults: Mutex::new(faults),
            wants: Mutex::new(BTreeMap::new()),
            generation: Mutex::new(generation),
            changed: Condvar::new(),
            stop: AtomicBool::new(false),
            logged: Mutex::new(HashSet::new()),
            rate: Mutex::new(HashMap::new()),
            figures: Mutex::new(None),
            session: session.clone(),
            opts,
        });
        let token = session
            .liveliness()
            .declare_token(keys.alive(&shared.opts.name))
            .wait()
            .map_err(NetError::zenoh)?;
        let records = session
            .declare_subscriber(keys.records())
            .wait()
            .map_err(NetError::zenoh)?;
        let digests = session
            .declare_subscriber(keys.digests())
            .wait()
            .map_err(NetError::zenoh)?;
        let queries = session
            .declare_queryable(keys.records())
            .wait()
            .map_err(NetError::zenoh)?;
        let tick = Duration::from_millis(100);
        let mut threads = vec![
            serve(
                &shared,
                records,
                tick,
                |s, sample: zenoh::sample::Sample| {
                    let bytes = sample.payload().to_bytes();
                    s.receive_record(sample.key_expr().as_str(), &bytes, false);
                },
            ),
            serve(
                &shared,
                digests,
                tick,
                |s, sample: zenoh::sample::Sample| {
                    let bytes = sample.payload().to_bytes();
                    s.receive_digest(sample.key_expr().as_str(), &bytes);
                },
            ),
            serve(&shared, queries, tick, |s, query: zenoh::query::Query| {
                s.answer_fetch(&query)
            }),
        ];
        let s = shared.clone();
        threads.push(std::thread::spawn(move || {
            let mut next = Instant::now();
            while !s.stop.load(Ordering::Relaxed) {
                if Instant::now() >= next {
                    s.round();
                    next = Instant::now() + s.opts.period;
                } else if let Some(f) = lock(&s.faults).as_mut() {
                    let due = f.release_due();
                    for m in due {
                        s.put(m);
                    }
                }
                std::thread::sleep(tick.min(s.opts.period));
            }
        }));
        Ok(Node {
            shared,
            threads,
            _token: token,
        })
    }

    /// The node's name.
    pub fn name(&self) -> &str {
        &self.shared.opts.name
    }

    /// The team's keys.
    pub fn keys(&self) -> &Keys {
        &self.shared.keys
    }

    /// The Zenoh session (for extra declarations, e.g. a mapper's queryables).
    pub fn session(&self) -> &zenoh::Session {
        &self.shared.session
    }

    /// Records a scan this node's robot made (`name` is the robot's name): stored durably
    /// first, then published with blocking congestion control. Returns whether it was new
    /// (a restarted robot re-recording a scan it holds sends nothing).
    pub fn record(&self, name: &str, scan: StoredScan) -> Result<bool> {
        if scan.seq == u32::MAX {
            return Err(NetError::InvalidArgument(format!(
                "scan number {} of robot {} is reserved (the last u32)",
                scan.seq, scan.robot
            )));
        }
        let new = match lock(&self.shared.store).insert(name, &scan)? {
            Ok(new) => new,
            Err(bad) => return Err(NetError::InvalidArgument(bad.to_string())),
        };
        if new {
            self.shared.bump();
        }
        let key = (scan.robot, scan.seq);
        let sent_ns = *lock(&self.shared.sent_ns).entry(key).or_insert_with(now_ns);
        let payload = RecordMessage {
            name: name.to_string(),
            sent_ns,
            scan,
        }
        .encode_at(Some(self.shared.opts.list_resolution));
        {
            let mut c = lock(&self.shared.counters);
            c.records_published += 1;
            c.record_bytes_published += payload.len() as u64;
        }
        self.shared.send(Outgoing {
            key: self.shared.keys.record(key.0, key.1),
            payload,
            block: true,
        });
        Ok(new)
    }

    /// A copy of the records held.
    pub fn store_snapshot(&self) -> ScanStore {
        lock(&self.shared.store).store().clone()
    }

    /// Whether the node holds record `(robot, seq)`.
    pub fn holds(&self, robot: u32, seq: u32) -> bool {
        lock(&self.shared.store).store().get(robot, seq).is_some()
    }

    /// Number of records held.
    pub fn held(&self) -> usize {
        lock(&self.shared.store).store().len()
    }

    /// The node's counters.
    pub fn counters(&self) -> Counters {
        lock(&self.shared.counters).clone()
    }

    /// The node's status as it publishes it.
    pub fn status(&self) -> NodeStatus {
        self.shared.status()
    }

    /// Writes the records held as a `.store` file.
    pub fn export(&self, path: impl AsRef<std::path::Path>) -> Result<()> {
        lock(&self.shared.store).export(path)
    }

    /// Waits until the node holds at least `count` records, or `timeout` passes; returns
    /// whether it got there.
    pub fn wait_for(&self, count: usize, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        let mut generation = lock(&self.shared.generation);
        loop {
            if self.held() >= count {
                return true;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            generation = self
                .shared
                .changed
                .wait_timeout(generation, left.min(Duration::from_millis(100)))
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }

    /// Stops the threads and closes the session.
    pub fn close(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.shared.changed.notify_all();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        let _ = self.shared.session.close().wait();
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        self.shutdown();
    }
}
