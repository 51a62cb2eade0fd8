//! What a node reports: its counters ([`Counters`]) and the status it publishes
//! ([`NodeStatus`], JSON on `olmap/TEAM/status/NODE`).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// Traffic and refusal counters of one node.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Counters {
    /// Records stored that were new.
    pub records_new: u64,
    /// Records received that were already held (duplicates: no-ops).
    pub records_duplicate: u64,
    /// New records that arrived through a fetch (anti-entropy) rather than a publish.
    pub records_recovered: u64,
    /// Records this node published as their recorder.
    pub records_published: u64,
    /// Bytes of record payloads this node published as their recorder.
    pub record_bytes_published: u64,
    /// Fetch requests sent.
    pub fetches_sent: u64,
    /// Records sent in answer to fetches.
    pub fetch_replies: u64,
    /// Refused payloads by reason ([`crate::BadMessage::reason`]).
    pub refused: BTreeMap<String, u64>,
    /// Messages the fault plan dropped (sent or received).
    pub fault_dropped: u64,
    /// Messages the fault plan sent twice.
    pub fault_duplicated: u64,
}

impl Counters {
    /// Every refused payload.
    pub fn refused_total(&self) -> u64 {
        self.refused.values().sum()
    }
}

/// One robot as a node sees it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RobotStatus {
    /// Records of the robot the node holds.
    pub held: u64,
    /// Scans of the robot in the node's map (mappers only).
    pub placed: u64,
}

/// A node's status, published periodically as JSON (fields a sender leaves out read as
/// their defaults).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NodeStatus {
    /// The node's name.
    pub node: String,
    /// `robot`, `mapper` or `robot+mapper`.
    pub role: String,
    /// Seconds since the node started.
    pub uptime_s: f64,
    /// Records held in all.
    pub records: u64,
    /// Per robot name.
    pub robots: BTreeMap<String, RobotStatus>,
    /// Scans placed in the map (mappers).
    pub placed: u64,
    /// Occupied voxels of the map (mappers).
    pub map_voxels: u64,
    /// Live map updates: records given to it and waiting scans placed (mappers).
    pub map_runs: u64,
    /// Records given to the live map (mappers): once it equals `records`, the live map
    /// reflects every record held.
    pub mapped_records: u64,
    /// Publish→placement latency of the last placed scans, milliseconds: p50, p95, max
    /// (mappers; over every scan whose publish time is known).
    pub latency_ms: Option<[f64; 3]>,
    /// The same over the scans placed when their record arrived, not after waiting for the
    /// map to reach them (a robot no sighting ties to the map yet waits for seconds):
    /// what the mapper's own speed gives (mappers).
    pub arrival_latency_ms: Option<[f64; 3]>,
    /// The node's counters.
    pub counters: Counters,
}

/// The `q`-quantile (0-1) of `values` (sorted in place), nearest rank.
pub fn quantile(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(|a, b| a.total_cmp(b));
    let i = ((q * values.len() as f64).ceil() as usize).clamp(1, values.len()) - 1;
    Some(values[i])
}
