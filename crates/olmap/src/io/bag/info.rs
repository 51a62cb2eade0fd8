//! What a bag holds: topics with their types, counts and stamps, and the frames named in
//! its messages (`olmap bag info`).

use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;

use super::container::{Bag, BagMessage};
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
    let mut summary = Summary::default();
    let result = bag.for_each_message(|m| {
        summary.add(m);
        Ok(true)
    });
    summary.finish(
        bag.path.display().to_string(),
        bag.files.iter().map(|f| f.display().to_string()).collect(),
        result,
    )
}

/// [`bag_info`] of one MCAP file's bytes, named `name` in messages (what the fuzzer drives:
/// the same container reading, schema parsing and message decoding).
#[cfg(any(test, feature = "test-support"))]
pub(crate) fn bag_info_of_bytes(bytes: &[u8], name: &std::path::Path) -> Result<BagInfo, BagError> {
    let mut summary = Summary::default();
    let (mut counts, mut delivered) = (std::collections::HashMap::new(), 0);
    let result = super::container::read_stream(
        bytes,
        bytes.len() as u64,
        name,
        &mut counts,
        &mut delivered,
        &mut |m| {
            summary.add(m);
            Ok(true)
        },
    );
    summary.finish(
        name.display().to_string(),
        vec![name.display().to_string()],
        result.map(|_| ()),
    )
}

/// What [`bag_info`] gathers message by message.
#[derive(Default)]
struct Summary {
    topics: BTreeMap<String, TopicInfo>,
    frames: BTreeSet<String>,
    problems: Vec<String>,
    messages: u64,
}

impl Summary {
    /// Counts one message and decodes it from its schema.
    fn add(&mut self, m: &BagMessage<'_>) {
        self.messages += 1;
        let t = m.log_time as f64 * 1e-9;
        let e = self
            .topics
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
                    collect_frames(&v, &mut self.frames);
                    None
                }
                Err(e) => Some(e.to_string()),
            },
        };
        if let Some(p) = problem {
            if self.problems.len() < MAX_PROBLEMS {
                self.problems.push(m.error(p).to_string());
            }
        }
    }

    /// The summary, once reading ended with `result` (a damaged container is
    /// [`BagInfo::stopped_early`]; any other error is returned).
    fn finish(
        self,
        path: String,
        files: Vec<String>,
        result: Result<(), BagError>,
    ) -> Result<BagInfo, BagError> {
        let stopped_early = match result {
            Ok(()) => None,
            Err(e @ BagError::Container { .. }) => Some(e.to_string()),
            Err(e) => return Err(e),
        };
        Ok(BagInfo {
            path,
            files,
            topics: self.topics.into_values().collect(),
            messages: self.messages,
            frames: self.frames.into_iter().collect(),
            problems: self.problems,
            stopped_early,
        })
    }
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
