//! What a bag holds: topics with their types, counts and stamps, and the frames named in
//! its messages (`olmap bag info`).

use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;

use super::container::Bag;
use super::dynamic::{self, Value};
use super::error::BagError;

/// One topic of a bag.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct TopicInfo {
    /// The topic name.
    pub name: String,
    /// Its message type (`sensor_msgs/msg/PointCloud2`).
    #[serde(rename = "type")]
    pub type_name: String,
    /// Messages recorded.
    pub count: u64,
    /// The first message's log time, seconds since the epoch.
    pub first_stamp: f64,
    /// The last message's log time, seconds since the epoch.
    pub last_stamp: f64,
    /// The message encoding (`cdr`).
    pub encoding: String,
}

/// A summary of a bag.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct BagInfo {
    /// The bag's path.
    pub path: String,
    /// Its MCAP files, in order.
    pub files: Vec<String>,
    /// Its topics, by name.
    pub topics: Vec<TopicInfo>,
    /// Messages read.
    pub messages: u64,
    /// Frames named in message headers (`frame_id`, `child_frame_id`), sorted.
    pub frames: Vec<String>,
    /// Messages whose content could not be decoded from their schema (topic, index, why);
    /// at most [`MAX_PROBLEMS`] are listed.
    pub problems: Vec<String>,
    /// Why reading stopped early (a damaged or truncated file), if it did: everything
    /// before it is in this summary.
    pub stopped_early: Option<String>,
}

/// How many undecodable messages [`BagInfo::problems`] lists.
pub const MAX_PROBLEMS: usize = 20;

/// Reads a whole bag and summarises it. Every message is decoded from its schema (to
/// find frames and to check it); a message that does not decode is listed in
/// [`BagInfo::problems`], and a damaged file ends the reading with
/// [`BagInfo::stopped_early`] set. Only a bag that cannot be opened is an error.
pub fn bag_info(bag: &Bag) -> Result<BagInfo, BagError> {
    let mut topics: BTreeMap<String, TopicInfo> = BTreeMap::new();
    let mut frames = BTreeSet::new();
    let mut problems = Vec::new();
    let mut messages = 0u64;
    let result = bag.for_each_message(|m| {
        messages += 1;
        let t = m.log_time as f64 * 1e-9;
        let e = topics
            .entry(m.topic.to_string())
            .or_insert_with(|| TopicInfo {
                name: m.topic.to_string(),
                type_name: m.type_name.to_string(),
                count: 0,
                first_stamp: t,
                last_stamp: t,
                encoding: m.encoding.to_string(),
            });
        e.count += 1;
        e.first_stamp = e.first_stamp.min(t);
        e.last_stamp = e.last_stamp.max(t);
        let problem = match m.schema.map(|s| s.defs()) {
            _ if m.encoding != "cdr" => None,
            None => Some("no schema".to_string()),
            Some(Err(e)) => Some(e.to_string()),
            Some(Ok(defs)) => match dynamic::decode(defs, m.data) {
                Ok(v) => {
                    collect_frames(&v, &mut frames);
                    None
                }
                Err(e) => Some(e.to_string()),
            },
        };
        if let Some(p) = problem {
            if problems.len() < MAX_PROBLEMS {
                problems.push(m.error(p).to_string());
            }
        }
        Ok(true)
    });
    let stopped_early = match result {
        Ok(()) => None,
        Err(e @ BagError::Container { .. }) => Some(e.to_string()),
        Err(e) => return Err(e),
    };
    Ok(BagInfo {
        path: bag.path.display().to_string(),
        files: bag.files.iter().map(|f| f.display().to_string()).collect(),
        topics: topics.into_values().collect(),
        messages,
        frames: frames.into_iter().collect(),
        problems,
        stopped_early,
    })
}

fn collect_frames(v: &Value, out: &mut BTreeSet<String>) {
    match v {
        Value::Struct(fields) => {
            for (name, value) in fields {
                match value {
                    Value::String(s)
                        if (name == "frame_id" || name == "child_frame_id") && !s.is_empty() =>
                    {
                        if out.len() < 10_000 {
                            out.insert(s.trim_start_matches('/').to_string());
                        }
                    }
                    other => collect_frames(other, out),
                }
            }
        }
        // Arrays of numbers hold no frames; skip the big ones quickly.
        Value::Array(items) if matches!(items.first(), Some(Value::Struct(_))) => {
            for i in items {
                collect_frames(i, out);
            }
        }
        _ => {}
    }
}
