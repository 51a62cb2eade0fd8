//! `olmap demo --live`: the four-robot demo as five processes on loopback — four robots and
//! a mapper, every node losing 20 % of what it sends, the mapper killed (SIGKILL) half way
//! and restarted on its store — then the batch demo's error table from the mapper's report
//! and the network figures.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use olmap::sim::write_dataset;
use serde::Serialize;

use crate::error::{NetError, Result};
use crate::node::NetOptions;
use crate::watch::{run_watch, WatchOptions};

/// What the live demo runs.
#[derive(Debug, Clone)]
pub struct LiveDemoConfig {
    /// The `olmap` executable to start the processes from.
    pub exe: PathBuf,
    /// Output folder: `dataset/`, the stores, the processes' logs, `map/` (the mapper's
    /// outputs).
    pub out: PathBuf,
    /// Robots (default 4).
    pub robots: usize,
    /// Stops per robot (default 10).
    pub scans_per_robot: usize,
    /// Simulator seed (default 1).
    pub seed: u64,
    /// Probability that a node loses a message it sends (default 0.2).
    pub drop: f64,
    /// Stops per second per robot (default 1).
    pub rate: f64,
    /// Give up after this long (default 1 h).
    pub timeout: Duration,
}

impl LiveDemoConfig {
    /// The demo's defaults with `exe` writing into `out`.
    pub fn new(exe: PathBuf, out: PathBuf) -> Self {
        LiveDemoConfig {
            exe,
            out,
            robots: 4,
            scans_per_robot: 10,
            seed: 1,
            drop: 0.2,
            rate: 1.0,
            timeout: Duration::from_secs(3600),
        }
    }
}

/// What the live demo measured.
#[derive(Debug, Clone, Serialize)]
pub struct LiveDemoReport {
    /// Records the robots recorded, in all.
    pub records: u64,
    /// Records the restarted mapper found in its store.
    pub mapper_resumed_with: Option<u64>,
    /// Records in the mapper's final store (all of them: nothing lost).
    pub mapper_records: u64,
    /// The team evaluation of the mapper's final map against the truth (`report.json`'s
    /// `evaluation.team`).
    pub team: serde_json::Value,
    /// Mean bytes of a record payload as sent (occupancy lists).
    pub bytes_per_scan: f64,
    /// Publish→placement latency at the restarted mapper, ms: p50, p95, max (scans placed
    /// after the restart whose publish time it heard).
    pub latency_ms: Option<[f64; 3]>,
    /// Records that arrived through anti-entropy fetches rather than publishes, all nodes.
    pub records_recovered: u64,
    /// Messages the injected faults dropped, all nodes.
    pub fault_dropped: u64,
    /// Seconds of the whole demo.
    pub total_seconds: f64,
    /// The mapper's output folder.
    pub live: PathBuf,
}

/// A child process killed when dropped.
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn spawn(exe: &Path, args: &[String], log: &Path, stdout: Option<&Path>) -> Result<Proc> {
    let file = |p: &Path| {
        std::fs::File::create(p)
            .map_err(|e| NetError::InvalidArgument(format!("{}: {e}", p.display())))
    };
    let mut c = Command::new(exe);
    c.args(args).stderr(file(log)?);
    match stdout {
        Some(p) => c.stdout(file(p)?),
        None => c.stdout(Stdio::null()),
    };
    c.spawn()
        .map(Proc)
        .map_err(|e| NetError::InvalidArgument(format!("starting {}: {e}", exe.display())))
}

/// Sends SIGTERM (the process writes what it must and exits).
fn terminate(p: &Proc) {
    #[cfg(unix)]
    // SAFETY: a signal to our own child's pid.
    unsafe {
        libc::kill(p.0.id() as libc::pid_t, libc::SIGTERM);
    }
}

fn wait_exit(p: &mut Proc, limit: Duration) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if let Ok(Some(_)) = p.0.try_wait() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    false
}

fn read_json(path: &Path) -> Result<serde_json::Value> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| NetError::InvalidArgument(format!("{}: {e}", path.display())))?;
    serde_json::from_str(&text)
        .map_err(|e| NetError::InvalidArgument(format!("{}: {e}", path.display())))
}

/// Runs the live demo; `progress` hears each stage.
pub fn run_live_demo(
    cfg: &LiveDemoConfig,
    mut progress: impl FnMut(&str),
) -> Result<LiveDemoReport> {
    let start = Instant::now();
    let out = &cfg.out;
    std::fs::create_dir_all(out)
        .map_err(|e| NetError::InvalidArgument(format!("{}: {e}", out.display())))?;
    let dataset = out.join("dataset");
    progress("simulating the team");
    let data = crate::lab::demo_lab(cfg.seed, cfg.robots, cfg.scans_per_robot)?;
    write_dataset(&dataset, &data)?;
    for stale in std::fs::read_dir(out).into_iter().flatten().flatten() {
        if stale.path().extension().is_some_and(|e| e == "redb") {
            let _ = std::fs::remove_file(stale.path());
        }
    }
    let records = (cfg.robots * cfg.scans_per_robot) as u64;
    let port = crate::lab::free_loopback_port()?;
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let team = format!("demo{}", std::process::id());
    let p = |x: &Path| x.to_string_lossy().into_owned();
    let net = |seed: u64| -> Vec<String> {
        [
            "--team",
            &team,
            "--no-scouting",
            "--fault-drop",
            &cfg.drop.to_string(),
            "--fault-seed",
            &seed.to_string(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let live = out.join("map");
    let mut mapper_args: Vec<String> = vec![
        "mapper".into(),
        "--store".into(),
        p(&out.join("mapper.redb")),
        "-o".into(),
        p(&live),
        "--truth".into(),
        p(&dataset),
        "--listen".into(),
        endpoint.clone(),
    ];
    mapper_args.extend(net(1000));
    progress("starting the mapper and the robots");
    let mut mapper = spawn(&cfg.exe, &mapper_args, &out.join("mapper.log"), None)?;
    std::thread::sleep(Duration::from_millis(500));
    let mut robots = Vec::new();
    for r in 0..cfg.robots {
        let name = format!("robot{r}");
        let mut a: Vec<String> = vec![
            "robot".into(),
            "--dataset".into(),
            p(&dataset),
            "--robot".into(),
            name.clone(),
            "--rate".into(),
            cfg.rate.to_string(),
            "--store".into(),
            p(&out.join(format!("{name}.redb"))),
            "--connect".into(),
            endpoint.clone(),
            "--json".into(),
        ];
        a.extend(net(r as u64 + 1));
        robots.push(spawn(
            &cfg.exe,
            &a,
            &out.join(format!("{name}.log")),
            Some(&out.join(format!("{name}.json"))),
        )?);
    }
    // Half way through the stops: kill the mapper, restart it on its store.
    std::thread::sleep(Duration::from_secs_f64(
        cfg.scans_per_robot as f64 / cfg.rate / 2.0,
    ));
    progress("killing the mapper (SIGKILL) and restarting it on its store");
    let _ = mapper.0.kill();
    wait_exit(&mut mapper, Duration::from_secs(10));
    drop(mapper);
    std::thread::sleep(Duration::from_secs(1));
    let mut mapper = spawn(
        &cfg.exe,
        &mapper_args,
        &out.join("mapper-restarted.log"),
        None,
    )?;
    progress("waiting until the mapper holds every record");
    let watch = run_watch(
        &WatchOptions {
            net: NetOptions::loopback(&team, None, &[port]),
            until_placed: None,
            until_held: Some(records),
            until_mapped: None,
            timeout: Some(cfg.timeout),
            max_payload: 1 << 20,
        },
        |_| {},
        || false,
    )?;
    if !watch.reached {
        return Err(NetError::Timeout(format!(
            "the mapper did not receive all {records} records within {:?}",
            cfg.timeout
        )));
    }
    // Latency figures need every record given to the live map (a scan it cannot place
    // waits: wait for the records, not for placements).
    progress("waiting for the live map to take every record");
    run_watch(
        &WatchOptions {
            net: NetOptions::loopback(&team, None, &[port]),
            until_placed: None,
            until_held: None,
            until_mapped: Some(records),
            timeout: Some(cfg.timeout.min(Duration::from_secs(1200))),
            max_payload: 1 << 20,
        },
        |_| {},
        || false,
    )?;
    progress("stopping: the mapper maps its store and writes its outputs");
    terminate(&mapper);
    if !wait_exit(&mut mapper, cfg.timeout) {
        return Err(NetError::Timeout(
            "the mapper did not finish writing".into(),
        ));
    }
    for r in &robots {
        terminate(r);
    }
    for r in &mut robots {
        wait_exit(r, Duration::from_secs(30));
    }
    let report = read_json(&live.join("report.json"))?;
    let net_status = read_json(&live.join("net.json"))?;
    let mut bytes = 0u64;
    let mut published = 0u64;
    let mut recovered = net_status["counters"]["records_recovered"]
        .as_u64()
        .unwrap_or(0);
    let mut dropped = net_status["counters"]["fault_dropped"]
        .as_u64()
        .unwrap_or(0);
    for r in 0..cfg.robots {
        let v = read_json(&out.join(format!("robot{r}.json")))?;
        let c = &v["status"]["counters"];
        bytes += c["record_bytes_published"].as_u64().unwrap_or(0);
        published += c["records_published"].as_u64().unwrap_or(0);
        recovered += c["records_recovered"].as_u64().unwrap_or(0);
        dropped += c["fault_dropped"].as_u64().unwrap_or(0);
    }
    let resumed = std::fs::read_to_string(out.join("mapper-restarted.log"))
        .ok()
        .and_then(|log| {
            log.split("resumed with ")
                .nth(1)?
                .split(' ')
                .next()?
                .parse()
                .ok()
        });
    let latency_ms = serde_json::from_value(net_status["latency_ms"].clone())
        .ok()
        .flatten();
    Ok(LiveDemoReport {
        records,
        mapper_resumed_with: resumed,
        mapper_records: net_status["records"].as_u64().unwrap_or(0),
        team: report["evaluation"]["team"].clone(),
        bytes_per_scan: bytes as f64 / published.max(1) as f64,
        latency_ms,
        records_recovered: recovered,
        fault_dropped: dropped,
        total_seconds: start.elapsed().as_secs_f64(),
        live,
    })
}
