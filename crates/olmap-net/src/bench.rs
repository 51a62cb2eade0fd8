//! The network figures (`olmap bench --net`): bytes on the wire per scan (occupancy list
//! against the raw cloud), publish→placement latency with robots publishing in real time to
//! a mapper over loopback, and the process's memory per placed scan.

use std::time::{Duration, Instant};

use olmap::team::TeamParams;
use serde::Serialize;

use crate::error::{NetError, Result};
use crate::mapper::{Mapper, MapperOptions};
use crate::node::{NetOptions, Node, NodeOptions};
use crate::protocol::RecordMessage;
use crate::robot::occupancy_record;

/// The benchmark stops waiting when no scan was placed for this long after the last
/// publish (the rest wait for a sighting that never comes; the report says how many).
const STALL: Duration = Duration::from_secs(60);

/// What the benchmark runs.
#[derive(Debug, Clone)]
pub struct NetBenchOptions {
    /// Robots (default 4, the demo's).
    pub robots: usize,
    /// Stops per robot (default 10, the demo's).
    pub stops: usize,
    /// Stops per second per robot (default 1).
    pub rate: f64,
    /// The team's finest resolution, metres (default 0.1).
    pub resolution: f64,
    /// Simulator seed (default 1).
    pub seed: u64,
    /// Give up waiting for every scan to be placed after this long from the first publish
    /// (default 30 min), or once no scan was placed for a minute after the last publish.
    pub timeout: Duration,
    /// Loopback port of the mapper (0: pick a free one).
    pub port: u16,
    /// Robots publish out of step (robot `i` of `n` a fraction `i / n` of a period after
    /// robot 0, as robots that do not share a clock do) instead of all in the same
    /// instant (default false: the worst case, every stop's records queue together).
    pub staggered: bool,
    /// How long the mapper waits after records arrive before reading them
    /// ([`MapperOptions::settle`]; default 0). A settle longer than the time between
    /// publications makes the mapper read several records at once, as a busy mapper does.
    pub settle: Duration,
}

impl Default for NetBenchOptions {
    fn default() -> Self {
        NetBenchOptions {
            robots: 4,
            stops: 10,
            rate: 1.0,
            resolution: 0.1,
            seed: 1,
            timeout: Duration::from_secs(1800),
            port: 0,
            staggered: false,
            settle: Duration::ZERO,
        }
    }
}

/// The figures.
#[derive(Debug, Clone, Serialize)]
pub struct NetBenchReport {
    /// Robots, stops per robot, rate (stops/s per robot), resolution (m).
    pub robots: usize,
    /// Stops per robot.
    pub stops: usize,
    /// Stops per second per robot.
    pub rate: f64,
    /// Resolution of the occupancy lists, metres.
    pub resolution: f64,
    /// Whether the robots published out of step ([`NetBenchOptions::staggered`]).
    pub staggered: bool,
    /// The simulator's seed.
    pub seed: u64,
    /// Mean bytes of a record payload carrying the raw cloud.
    pub raw_bytes_per_scan: f64,
    /// Mean bytes of a record payload carrying the occupancy list (what is sent).
    pub list_bytes_per_scan: f64,
    /// Largest occupancy-list payload, bytes.
    pub list_bytes_max: usize,
    /// Mean points per raw scan and per occupancy list.
    pub points_raw: f64,
    /// Mean points per occupancy list.
    pub points_list: f64,
    /// Record bytes published by the robots in all (each record once, plus fault-free
    /// duplicates: none here).
    pub bytes_published: u64,
    /// Scans placed when the run ended, of all published.
    pub placed: u64,
    /// Scans published.
    pub published: u64,
    /// Publish→placement latency, ms: p50, p95, max.
    pub latency_ms: Option<[f64; 3]>,
    /// The same over the scans placed when their record arrived (not those that waited
    /// for a sighting or for the map to reach them), ms: p50, p95, max.
    pub arrival_latency_ms: Option<[f64; 3]>,
    /// Live map updates (records given, waiting scans placed).
    pub map_runs: u64,
    /// Seconds from the first publish until every scan was placed (or the timeout).
    pub wall_s: f64,
    /// Peak resident memory of the process (robots and mapper together), MiB.
    pub peak_rss_mib: Option<f64>,
    /// Resident memory before the nodes started, MiB.
    pub base_rss_mib: Option<f64>,
    /// (peak − base) / placed scans, KiB.
    pub memory_per_placed_kib: Option<f64>,
}

/// A `/proc/self/status` field in MiB (Linux only).
fn proc_mib(field: &str) -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with(field))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// Runs the benchmark: simulates the demo's lab team, measures the payload sizes, then
/// runs a mapper and one node per robot in this process over loopback (no faults), each
/// robot publishing its stops at `rate`, until the mapper has placed every scan.
pub fn run_net_bench(
    opts: &NetBenchOptions,
    mut progress: impl FnMut(&str),
) -> Result<NetBenchReport> {
    if !(opts.rate > 0.0 && opts.rate <= 100.0) || opts.robots == 0 || opts.stops == 0 {
        return Err(NetError::InvalidArgument(
            "the bench needs robots >= 1, stops >= 1 and a rate in (0, 100]".into(),
        ));
    }
    progress("simulating the team");
    let data = crate::lab::demo_lab(opts.seed, opts.robots, opts.stops)?;
    let raw = data.to_store()?;
    let mut raw_bytes = 0usize;
    let mut list_bytes = 0usize;
    let mut list_max = 0usize;
    let mut points = (0usize, 0usize);
    let mut lists = Vec::new();
    for scan in raw.iter() {
        let name = raw.robot_name(scan.robot);
        let list = occupancy_record(scan, opts.resolution)?;
        let enc = |s: &olmap::team::StoredScan, r: Option<f64>| {
            RecordMessage {
                name: name.clone(),
                sent_ns: 0,
                scan: s.clone(),
            }
            .encode_at(r)
            .len()
        };
        raw_bytes += enc(scan, None);
        let l = enc(&list, Some(opts.resolution));
        list_bytes += l;
        list_max = list_max.max(l);
        points.0 += scan.cloud.len();
        points.1 += list.cloud.len();
        lists.push((name, list));
    }
    let n = raw.len() as f64;
    let base_rss = proc_mib("VmRSS:");
    // One folder and team per run: two runs in one process (tests) must not share them.
    static RUNS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let run = format!(
        "{}-{}",
        std::process::id(),
        RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    );
    let dir = std::env::temp_dir().join(format!("olmap-net-bench-{run}"));
    std::fs::create_dir_all(&dir)
        .map_err(|e| NetError::InvalidArgument(format!("{}: {e}", dir.display())))?;
    let port = if opts.port != 0 {
        opts.port
    } else {
        crate::lab::free_loopback_port()?
    };
    let team = format!("bench{}", run.replace('-', "x"));
    let node_opts = |name: &str, role: &str, listen: Option<u16>, connect: &[u16]| {
        NodeOptions::new(
            name,
            role,
            dir.join(format!("{name}.redb")),
            NetOptions::loopback(&team, listen, connect),
        )
    };
    let result = (|| {
        let mapper = Mapper::start(MapperOptions {
            node: node_opts("mapper", "mapper", Some(port), &[]),
            out: dir.join("out"),
            params: TeamParams::default(),
            truth: None,
            settle: opts.settle,
        })?;
        let mut robots = Vec::new();
        for r in raw.robots() {
            let name = raw.robot_name(r);
            robots.push((
                r,
                name.clone(),
                Node::start(node_opts(&name, "robot", None, &[port]))?,
            ));
        }
        std::thread::sleep(Duration::from_millis(500));
        progress("robots publishing");
        let start = Instant::now();
        let period = Duration::from_secs_f64(1.0 / opts.rate);
        // Every publication, in time order: (due, robot slot, stop).
        let slots = robots.len();
        let mut due: Vec<(Duration, usize, usize)> = (0..opts.stops)
            .flat_map(|stop| (0..slots).map(move |i| (stop, i)))
            .map(|(stop, i)| {
                let phase = if opts.staggered {
                    i as f64 / slots as f64
                } else {
                    0.0
                };
                (period.mul_f64(stop as f64 + phase), i, stop)
            })
            .collect();
        due.sort();
        for (at, i, stop) in due {
            std::thread::sleep((start + at).saturating_duration_since(Instant::now()));
            let (r, name, node) = &robots[i];
            if let Some((_, list)) = lists
                .iter()
                .find(|(_, l)| l.robot == *r && l.seq as usize == stop)
            {
                node.record(name, list.clone())?;
            }
        }
        progress("waiting for every scan to be placed");
        let total = raw.len() as u64;
        // A scan no sighting ties to the map waits for good: stop when nothing more was
        // placed for a while after the last publish.
        let (mut placed, mut changed) = (0, Instant::now());
        while placed < total && start.elapsed() < opts.timeout && changed.elapsed() < STALL {
            std::thread::sleep(Duration::from_millis(100));
            let now = mapper.node().status().placed;
            if now != placed {
                (placed, changed) = (now, Instant::now());
            }
        }
        let status = mapper.node().status();
        let published: u64 = robots
            .iter()
            .map(|(_, _, n)| n.counters().records_published)
            .sum();
        let bytes: u64 = robots
            .iter()
            .map(|(_, _, n)| n.counters().record_bytes_published)
            .sum();
        let wall = start.elapsed().as_secs_f64();
        for (_, _, n) in robots {
            n.close();
        }
        mapper.close();
        Ok::<_, NetError>((status, published, bytes, wall))
    })();
    let _ = std::fs::remove_dir_all(&dir);
    let (status, published, bytes, wall) = result?;
    let peak = proc_mib("VmHWM:");
    let per_placed = match (peak, base_rss) {
        (Some(p), Some(b)) if status.placed > 0 => Some((p - b) * 1024.0 / status.placed as f64),
        _ => None,
    };
    Ok(NetBenchReport {
        robots: opts.robots,
        stops: opts.stops,
        rate: opts.rate,
        resolution: opts.resolution,
        staggered: opts.staggered,
        seed: opts.seed,
        raw_bytes_per_scan: raw_bytes as f64 / n,
        list_bytes_per_scan: list_bytes as f64 / n,
        list_bytes_max: list_max,
        points_raw: points.0 as f64 / n,
        points_list: points.1 as f64 / n,
        bytes_published: bytes,
        placed: status.placed,
        published,
        latency_ms: status.latency_ms,
        arrival_latency_ms: status.arrival_latency_ms,
        map_runs: status.map_runs,
        wall_s: wall,
        peak_rss_mib: peak,
        base_rss_mib: base_rss,
        memory_per_placed_kib: per_placed,
    })
}
