//! `olmap robot`, `olmap mapper`, `olmap watch`: the team live over Zenoh (the `net`
//! feature, on by default), through the `olmap-net` crate. Net options are shared.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use clap::Args;
use olmap::team::TeamParams;
use olmap_net::mapper::{Mapper, MapperOptions};
use olmap_net::robot::{replay_on, robot_records, run_robot, RobotOptions};
use olmap_net::watch::{run_watch, WatchOptions, WatchSummary};
use olmap_net::{FaultPlan, NetOptions, NodeOptions, NodeStatus};

use crate::signals;

/// How a node reaches its team (shared by robot, mapper and watch).
#[derive(Args, Clone)]
pub struct NetArgs {
    /// The team's name: every key is under `olmap/TEAM/`. Nodes of different teams on one
    /// network ignore each other.
    #[arg(long, default_value = "olmap")]
    pub team: String,
    /// Listen on this Zenoh endpoint, e.g. `tcp/0.0.0.0:7447` (repeatable). Default: any
    /// free port on every interface (peer mode).
    #[arg(long)]
    pub listen: Vec<String>,
    /// Connect to this Zenoh endpoint, e.g. `tcp/192.168.1.10:7447` (repeatable).
    #[arg(long)]
    pub connect: Vec<String>,
    /// A Zenoh JSON5 configuration file for anything else: TLS, user/password
    /// authentication, access control, scouting (see the README). --listen, --connect and
    /// --no-scouting apply on top of it.
    #[arg(long)]
    pub zenoh_config: Option<PathBuf>,
    /// Turn off multicast scouting (finding peers on the LAN without endpoints); use with
    /// explicit --listen/--connect.
    #[arg(long)]
    pub no_scouting: bool,
}

impl NetArgs {
    fn options(&self) -> NetOptions {
        NetOptions {
            team: self.team.clone(),
            listen: self.listen.clone(),
            connect: self.connect.clone(),
            zenoh_config: self.zenoh_config.clone(),
            scouting: !self.no_scouting,
        }
    }
}

/// Limits and injected faults of a robot or mapper node.
#[derive(Args, Clone)]
pub struct NodeArgs {
    /// Largest payload accepted, bytes; larger ones are counted and dropped.
    #[arg(long, default_value_t = 16 << 20)]
    pub max_payload: usize,
    /// Most new records accepted per robot per second; more are dropped and fetched later.
    #[arg(long, default_value_t = 50)]
    pub max_rate: u32,
    /// Seconds between digests/statuses (and anti-entropy fetches).
    #[arg(long, default_value_t = 1.0)]
    pub period: f64,
    /// Fault injection: probability (0-1) that a message this node sends is lost.
    #[arg(long, default_value_t = 0.0)]
    pub fault_drop: f64,
    /// Fault injection: probability (0-1) that a message is sent twice.
    #[arg(long, default_value_t = 0.0)]
    pub fault_dup: f64,
    /// Fault injection: reorder messages within a window of this many.
    #[arg(long, default_value_t = 0)]
    pub fault_reorder: usize,
    /// Fault injection: seed of the random choices.
    #[arg(long, default_value_t = 1)]
    pub fault_seed: u64,
    /// Fault injection: a partition `START:END` in seconds after start, during which the
    /// node neither sends nor receives (repeatable).
    #[arg(long, value_parser = parse_partition)]
    pub fault_partition: Vec<(Duration, Duration)>,
}

fn parse_partition(s: &str) -> Result<(Duration, Duration), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("'{s}' is not START:END (seconds)"))?;
    let secs = |v: &str| -> Result<Duration, String> {
        let x: f64 = v
            .trim()
            .parse()
            .map_err(|_| format!("'{v}' is not a number of seconds"))?;
        Duration::try_from_secs_f64(x).map_err(|_| format!("{x} s is not a duration"))
    };
    Ok((secs(a)?, secs(b)?))
}

impl NodeArgs {
    fn apply(&self, o: &mut NodeOptions) -> anyhow::Result<()> {
        o.max_payload = self.max_payload;
        o.max_rate = self.max_rate;
        o.period = Duration::try_from_secs_f64(self.period)
            .map_err(|_| anyhow::anyhow!("--period {} is not a duration", self.period))?;
        o.faults = FaultPlan {
            drop: self.fault_drop,
            duplicate: self.fault_dup,
            reorder: self.fault_reorder,
            seed: self.fault_seed,
            partitions: self.fault_partition.clone(),
        };
        o.check()?;
        Ok(())
    }
}

/// Arguments of `olmap robot`.
#[derive(Args)]
pub struct RobotArgs {
    /// The dataset folder (`olmap simulate` output) to replay one robot of, or a ROS 2 bag
    /// (rosbag2 folder or .mcap) of this robot (scans and odometry: --topic, --odom-topic,
    /// --frame; put the scans in the robot frame with e.g. --frame base_link).
    #[arg(long)]
    pub dataset: PathBuf,
    /// With a bag: which scans and odometry.
    #[command(flatten)]
    pub bag: crate::commands::bag::BagSelectArgs,
    /// The robot to replay, by its name in the dataset (e.g. `robot0`); also the node's name.
    #[arg(long)]
    pub robot: String,
    /// Stops replayed per second.
    #[arg(long, default_value_t = 1.0)]
    pub rate: f64,
    /// The team's finest resolution, metres: each scan is sent as its occupancy list at
    /// this resolution (one point per occupied voxel) with the sensor origin, odometry and
    /// sightings — not the raw cloud.
    #[arg(long, default_value_t = 0.1)]
    pub resolution: f64,
    /// The robot's persistent store (a redb database; created if missing). A robot
    /// restarted on its store resumes after the last stop it recorded. Default
    /// `ROBOT.redb` in the current folder.
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// Also run the mapper role (as in the thesis, every robot can map): needs --out.
    #[arg(long)]
    pub map: bool,
    /// With --map: the output folder.
    #[arg(short, long)]
    pub out: Option<PathBuf>,
    /// After the last stop, keep serving the store this many seconds, then exit. Default:
    /// until interrupted (Ctrl-C, SIGTERM).
    #[arg(long)]
    pub linger: Option<f64>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub net: NetArgs,
    #[command(flatten)]
    pub node: NodeArgs,
}

/// Arguments of `olmap mapper`.
#[derive(Args)]
pub struct MapperArgs {
    /// The mapper's persistent store (a redb database; created if missing). Restarted on
    /// it, the mapper resumes with every record it had.
    #[arg(long)]
    pub store: PathBuf,
    /// Output folder, written on SIGINT/SIGTERM and when asked (`olmap/TEAM/write`):
    /// team.olm / .bt / .ply, team_poses.txt, team.store, report.json, net.json.
    #[arg(short, long)]
    pub out: PathBuf,
    /// The node's name.
    #[arg(long, default_value = "mapper")]
    pub name: String,
    /// The dataset the robots replay, for ground truth in the report (optional).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Print the final status as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub net: NetArgs,
    #[command(flatten)]
    pub node: NodeArgs,
}

/// Arguments of `olmap watch`.
#[derive(Args)]
pub struct WatchArgs {
    /// Exit (status 0) once a mapper reports at least this many placed scans.
    #[arg(long)]
    pub until_placed: Option<u64>,
    /// Exit (status 0) once a mapper reports holding at least this many records (with
    /// --until-placed: once both hold).
    #[arg(long)]
    pub until_held: Option<u64>,
    /// Exit after this many seconds (status 1 if a target was set and not reached).
    #[arg(long)]
    pub timeout: Option<f64>,
    /// Print the final summary as JSON (no live lines).
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub net: NetArgs,
}

/// One line per node.
fn status_line(s: &NodeStatus, alive: bool) -> String {
    let robots: Vec<String> = s
        .robots
        .iter()
        .map(|(n, r)| {
            if s.role.contains("mapper") {
                format!("{n} {}/{}", r.placed, r.held)
            } else {
                format!("{n} {}", r.held)
            }
        })
        .collect();
    let latency = s
        .latency_ms
        .map(|[p50, p95, _]| format!(", latency p50 {p50:.0} ms p95 {p95:.0} ms"))
        .unwrap_or_default();
    let map = if s.role.contains("mapper") {
        format!(", placed {}, map {} voxels", s.placed, s.map_voxels)
    } else {
        String::new()
    };
    format!(
        "{:<10} {:<6} {:<12} {} records [{}]{map}{latency}, {} recovered, {} refused",
        s.node,
        if alive { "alive" } else { "gone" },
        s.role,
        s.records,
        robots.join(", "),
        s.counters.records_recovered,
        s.counters.refused_total()
    )
}

/// The final status line and what was written.
fn print_written(status: &NodeStatus, written: Option<&olmap_net::mapper::MapperOutputs>) {
    eprintln!("{}", status_line(status, true));
    if let Some(w) = written {
        println!(
            "wrote {} ({} records, {} scans placed)",
            w.out.display(),
            w.records,
            w.placed
        );
    }
}

fn wait_until_stopped(stop: &AtomicBool, limit: Option<Duration>) {
    let start = Instant::now();
    while !stop.load(Ordering::Relaxed) && limit.is_none_or(|l| start.elapsed() < l) {
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Runs `olmap robot`.
pub fn run_robot_cmd(args: &RobotArgs) -> anyhow::Result<ExitCode> {
    let stop = signals::stop_flag();
    let store = args
        .store
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{}.redb", args.robot)));
    let mut node = NodeOptions::new(
        &args.robot,
        if args.map { "robot+mapper" } else { "robot" },
        store,
        args.net.options(),
    );
    args.node.apply(&mut node)?;
    node.list_resolution = args.resolution;
    if args.map && args.out.is_none() {
        anyhow::bail!("--map needs --out FOLDER for the map it builds");
    }
    let opts = RobotOptions {
        dataset: args.dataset.clone(),
        bag: args.bag.options()?,
        robot: args.robot.clone(),
        rate: args.rate,
        resolution: args.resolution,
        node,
    };
    let json = args.json;
    let mut on_stop = |seq: u32, s: &olmap_net::robot::RobotSummary| {
        if !json {
            eprintln!(
                "{}: stop {seq} published ({} points -> {} voxels, {} bytes so far)",
                opts.robot, s.raw_points, s.list_points, s.bytes
            );
        }
    };
    let linger = args
        .linger
        .map(|s| {
            Duration::try_from_secs_f64(s)
                .map_err(|_| anyhow::anyhow!("--linger {s} is not a number of seconds"))
        })
        .transpose()?;
    let serving = |summary: &olmap_net::robot::RobotSummary| {
        if !json {
            eprintln!(
                "{}: {} stops published, {} resumed from the store; serving the store{}",
                opts.robot,
                summary.published,
                summary.resumed,
                linger.map_or(" until interrupted".to_string(), |s| format!(
                    " for {} s",
                    s.as_secs_f64()
                ))
            );
        }
    };
    let (summary, status, written) = if args.map {
        let (robot, scans) = robot_records(&opts)?;
        let mapper = Mapper::start(MapperOptions {
            node: opts.node.clone(),
            out: args.out.clone().expect("checked"),
            params: TeamParams::default(),
            truth: None,
            settle: Duration::ZERO,
        })?;
        let summary = replay_on(mapper.node(), &opts, robot, &scans, stop, &mut on_stop)?;
        serving(&summary);
        wait_until_stopped(stop, linger);
        let written = mapper.finish()?;
        let status = written.status.clone();
        (summary, status, Some(written))
    } else {
        let (node, summary) = run_robot(&opts, stop, on_stop)?;
        serving(&summary);
        wait_until_stopped(stop, linger);
        let status = node.status();
        node.close();
        (summary, status, None)
    };
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "robot": summary, "status": status, "map": written,
            }))?
        );
    } else {
        print_written(&status, written.as_ref());
    }
    Ok(ExitCode::SUCCESS)
}

/// Runs `olmap mapper`.
pub fn run_mapper_cmd(args: &MapperArgs) -> anyhow::Result<ExitCode> {
    let stop = signals::stop_flag();
    let mut node = NodeOptions::new(&args.name, "mapper", &args.store, args.net.options());
    args.node.apply(&mut node)?;
    let truth = match &args.truth {
        Some(dir) => {
            let data = olmap::sim::read_dataset(dir)?;
            let (store, _) = data.to_store_skipping()?;
            data.has_truth().then(|| data.truth_list(&store))
        }
        None => None,
    };
    let mapper = Mapper::start(MapperOptions {
        node,
        out: args.out.clone(),
        params: TeamParams::default(),
        truth,
        settle: Duration::ZERO,
    })?;
    if !args.json {
        eprintln!(
            "{}: resumed with {} records; mapping as records arrive (Ctrl-C or SIGTERM writes {} and exits)",
            args.name,
            mapper.node().held(),
            args.out.display()
        );
    }
    let mut last_line = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
        if !args.json && last_line.elapsed() >= Duration::from_secs(2) {
            eprintln!("{}", status_line(&mapper.node().status(), true));
            last_line = Instant::now();
        }
    }
    let (written, status) = if mapper.node().held() > 0 {
        let w = mapper.finish()?;
        let status = w.status.clone();
        (Some(w), status)
    } else {
        eprintln!("{}: no record received: nothing written", args.name);
        let status = mapper.node().status();
        mapper.close();
        (None, status)
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&status)?);
    } else {
        print_written(&status, written.as_ref());
    }
    Ok(ExitCode::SUCCESS)
}

/// Runs `olmap watch`.
pub fn run_watch_cmd(args: &WatchArgs) -> anyhow::Result<ExitCode> {
    let stop = signals::stop_flag();
    let timeout = args
        .timeout
        .map(|t| {
            Duration::try_from_secs_f64(t)
                .map_err(|_| anyhow::anyhow!("--timeout {t} is not a number of seconds"))
        })
        .transpose()?;
    let json = args.json;
    let print = |s: &WatchSummary| {
        if json {
            return;
        }
        for (name, st) in &s.nodes {
            eprintln!("{}", status_line(st, s.alive.contains(name)));
        }
    };
    let summary = run_watch(
        &WatchOptions {
            net: args.net.options(),
            until_placed: args.until_placed,
            until_held: args.until_held,
            until_mapped: None,
            timeout,
            max_payload: 1 << 20,
        },
        print,
        || stop.load(Ordering::Relaxed),
    )?;
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "{} nodes heard, {} alive after {:.1} s{}",
            summary.nodes.len(),
            summary.alive.len(),
            summary.elapsed_s,
            if summary.reached {
                ""
            } else {
                ": target not reached"
            }
        );
    }
    Ok(if summary.reached {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
