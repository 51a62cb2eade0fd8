//! The watch role: a live view of the team — which nodes are alive (liveliness tokens) and
//! what each reports (statuses) — until a mapper has placed enough scans or time is up.

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::sample::SampleKind;
use zenoh::Wait;

use crate::error::{NetError, Result};
use crate::node::NetOptions;
use crate::protocol::{open, Keys, Kind};
use crate::status::NodeStatus;

/// When a watch stops.
#[derive(Debug, Clone, Default)]
pub struct WatchOptions {
    /// The network.
    pub net: NetOptions,
    /// Stop once a mapper reports at least this many placed scans.
    pub until_placed: Option<u64>,
    /// Stop once a mapper reports holding at least this many records (with `until_placed`:
    /// both).
    pub until_held: Option<u64>,
    /// Stop once a mapper's live map has been given at least this many records (with the
    /// other targets: once all hold).
    pub until_mapped: Option<u64>,
    /// Stop after this long (then [`WatchSummary::reached`] is false when `until_placed`
    /// was set).
    pub timeout: Option<Duration>,
    /// Largest status payload accepted, bytes.
    pub max_payload: usize,
}

/// What the team looked like when the watch stopped.
#[derive(Debug, Clone, Default, Serialize)]
pub struct WatchSummary {
    /// Whether the targets (`until_placed`, `until_held`) were reached (true when none was
    /// set and time ran out).
    pub reached: bool,
    /// Seconds watched.
    pub elapsed_s: f64,
    /// Nodes alive at the end.
    pub alive: BTreeSet<String>,
    /// The last status of every node heard from.
    pub nodes: BTreeMap<String, NodeStatus>,
    /// Status payloads refused (malformed).
    pub refused: u64,
}

/// Watches the team; calls `on_update` whenever a status arrives or a node comes or goes,
/// and returns when a mapper has placed `until_placed` scans, when `timeout` passes, or
/// when `stop` returns true.
pub fn run_watch(
    opts: &WatchOptions,
    mut on_update: impl FnMut(&WatchSummary),
    stop: impl Fn() -> bool,
) -> Result<WatchSummary> {
    let keys = Keys::new(&opts.net.team)?;
    let session = zenoh::open(opts.net.zenoh_config()?)
        .wait()
        .map_err(NetError::zenoh)?;
    let statuses = session
        .declare_subscriber(keys.statuses())
        .wait()
        .map_err(NetError::zenoh)?;
    let alive = session
        .liveliness()
        .declare_subscriber(keys.alives())
        .history(true)
        .wait()
        .map_err(NetError::zenoh)?;
    let start = Instant::now();
    let max = if opts.max_payload == 0 {
        1 << 20
    } else {
        opts.max_payload
    };
    let mut summary = WatchSummary::default();
    loop {
        let mut changed = false;
        while let Ok(Some(sample)) = alive.try_recv() {
            if let Some(node) = keys.node_of(sample.key_expr().as_str()) {
                changed = true;
                match sample.kind() {
                    SampleKind::Put => summary.alive.insert(node.to_string()),
                    SampleKind::Delete => summary.alive.remove(node),
                };
            }
        }
        while let Ok(Some(sample)) = statuses.try_recv() {
            let bytes = sample.payload().to_bytes();
            let status = open(&bytes, Kind::Status, max)
                .ok()
                .and_then(|b| serde_json::from_slice::<NodeStatus>(b).ok());
            match status {
                Some(s) if keys.node_of(sample.key_expr().as_str()) == Some(s.node.as_str()) => {
                    changed = true;
                    summary.nodes.insert(s.node.clone(), s);
                }
                _ => summary.refused += 1,
            }
        }
        summary.elapsed_s = start.elapsed().as_secs_f64();
        if changed {
            on_update(&summary);
        }
        let placed = opts
            .until_placed
            .is_none_or(|n| summary.nodes.values().any(|s| s.placed >= n));
        let held = opts.until_held.is_none_or(|n| {
            summary
                .nodes
                .values()
                .any(|s| s.role.contains("mapper") && s.records >= n)
        });
        let mapped = opts.until_mapped.is_none_or(|n| {
            summary
                .nodes
                .values()
                .any(|s| s.role.contains("mapper") && s.mapped_records >= n)
        });
        let targets =
            opts.until_placed.is_some() || opts.until_held.is_some() || opts.until_mapped.is_some();
        if targets && placed && held && mapped {
            summary.reached = true;
            break;
        }
        if opts.timeout.is_some_and(|t| start.elapsed() >= t) || stop() {
            summary.reached = !targets;
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = session.close().wait();
    Ok(summary)
}
