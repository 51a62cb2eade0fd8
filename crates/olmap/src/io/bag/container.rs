//! Opening a bag (a rosbag2 folder or one `.mcap` file) and streaming its messages.

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::error::BagError;
use super::schema::{parse_schema, MessageDefs, SchemaError};

/// The largest MCAP record (or decompressed chunk) olmap reads: 1 GiB. A larger one is
/// refused as damaged rather than allocated.
pub const MAX_RECORD_BYTES: usize = 1 << 30;

/// A ROS 2 bag on disk: its MCAP files in order.
#[derive(Debug, Clone)]
pub struct Bag {
    /// The path given (folder or file).
    pub path: PathBuf,
    /// The MCAP files, in recording order (split bags have several).
    pub files: Vec<PathBuf>,
}

/// A message type's schema, as the bag declares it.
#[derive(Debug)]
pub struct SchemaInfo {
    /// The type name (`sensor_msgs/msg/PointCloud2`).
    pub name: String,
    /// The schema encoding (`ros2msg` for ROS 2 bags).
    pub encoding: String,
    /// The schema text.
    pub text: String,
    defs: OnceLock<Result<MessageDefs, SchemaError>>,
}

impl SchemaInfo {
    /// The parsed definitions (parsed once, on first use).
    pub fn defs(&self) -> Result<&MessageDefs, &SchemaError> {
        self.defs
            .get_or_init(|| {
                if self.encoding != "ros2msg" {
                    return Err(SchemaError {
                        type_name: self.name.clone(),
                        line: 0,
                        reason: format!(
                            "schema encoding '{}' (only ros2msg is decoded)",
                            self.encoding
                        ),
                    });
                }
                parse_schema(&self.name, &self.text)
            })
            .as_ref()
    }
}

/// One message, as [`Bag::for_each_message`] hands it over.
#[derive(Debug)]
pub struct BagMessage<'a> {
    /// Its topic.
    pub topic: &'a str,
    /// Its type (`sensor_msgs/msg/PointCloud2`); empty when the channel has no schema.
    pub type_name: &'a str,
    /// The channel's message encoding (`cdr` for ROS 2).
    pub encoding: &'a str,
    /// The schema, when the channel has one.
    pub schema: Option<&'a Arc<SchemaInfo>>,
    /// The message's index on its topic (0-based, in bag order, across split files).
    pub index: u64,
    /// The time it was recorded (ns since the epoch).
    pub log_time: u64,
    /// The serialised message.
    pub data: &'a [u8],
    /// The MCAP file it came from.
    pub file: &'a Path,
}

impl BagMessage<'_> {
    /// A [`BagError::Message`] about this message.
    pub fn error(&self, reason: impl Into<String>) -> BagError {
        BagError::Message {
            file: self.file.to_path_buf(),
            topic: self.topic.to_string(),
            index: self.index,
            type_name: self.type_name.to_string(),
            reason: reason.into(),
        }
    }
}

struct Channel {
    topic: String,
    encoding: String,
    schema: Option<Arc<SchemaInfo>>,
}

impl Bag {
    /// Opens a bag: a `.mcap` file, or a rosbag2 folder (its `metadata.yaml` lists the files
    /// in order; without one, every `.mcap` in the folder in natural name order).
    ///
    /// ```no_run
    /// let bag = olmap::io::bag::Bag::open("recording/")?;
    /// println!("{} file(s)", bag.files.len());
    /// # Ok::<(), olmap::io::bag::BagError>(())
    /// ```
    pub fn open(path: impl AsRef<Path>) -> Result<Bag, BagError> {
        let path = path.as_ref().to_path_buf();
        let meta = std::fs::metadata(&path).map_err(|source| BagError::Io {
            path: path.clone(),
            source,
        })?;
        let not_a_bag = |reason: String| BagError::NotABag {
            path: path.clone(),
            reason,
        };
        if meta.is_file() {
            let mut magic = [0u8; 8];
            let mut f = std::fs::File::open(&path).map_err(|source| BagError::Io {
                path: path.clone(),
                source,
            })?;
            let n = f.read(&mut magic).unwrap_or(0);
            if n < 8 || &magic[..5] != b"\x89MCAP" {
                return Err(not_a_bag(if path.extension().is_some_and(|e| e == "db3") {
                    "a rosbag2 SQLite (.db3) file; olmap reads MCAP bags (convert with `ros2 bag \
                     convert`)"
                        .into()
                } else {
                    "no MCAP magic at the start".into()
                }));
            }
            return Ok(Bag {
                files: vec![path.clone()],
                path,
            });
        }
        let yaml = path.join("metadata.yaml");
        let mut files = Vec::new();
        if yaml.is_file() {
            let text = std::fs::read_to_string(&yaml).map_err(|source| BagError::Io {
                path: yaml.clone(),
                source,
            })?;
            if let Some(storage) = yaml_scalar(&text, "storage_identifier") {
                if storage != "mcap" {
                    return Err(not_a_bag(format!(
                        "storage '{storage}' (olmap reads MCAP bags; convert with `ros2 bag \
                         convert`)"
                    )));
                }
            }
            for name in yaml_list(&text, "relative_file_paths") {
                let file = path.join(&name);
                if name.contains("..") || !file.is_file() {
                    return Err(not_a_bag(format!(
                        "metadata.yaml lists '{name}', which is not a file in the folder"
                    )));
                }
                files.push(file);
            }
        }
        if files.is_empty() {
            let entries = std::fs::read_dir(&path).map_err(|source| BagError::Io {
                path: path.clone(),
                source,
            })?;
            files = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && p.extension().is_some_and(|e| e == "mcap"))
                .collect();
            files.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
        }
        if files.is_empty() {
            return Err(not_a_bag(
                "a folder with no .mcap files (and no metadata.yaml listing any)".into(),
            ));
        }
        Ok(Bag { path, files })
    }

    /// Streams every message of every file in order to `visit`, which may stop early by
    /// returning `false`. Reading stops at the first damaged record with
    /// [`BagError::Container`]; the messages before it have been visited. A message-level
    /// error returned by `visit` stops reading too and is returned as is.
    pub fn for_each_message(
        &self,
        mut visit: impl FnMut(&BagMessage<'_>) -> Result<bool, BagError>,
    ) -> Result<(), BagError> {
        let mut topic_counts: HashMap<String, u64> = HashMap::new();
        let mut delivered = 0u64;
        for file in &self.files {
            if !read_file(file, &mut topic_counts, &mut delivered, &mut visit)? {
                return Ok(());
            }
        }
        Ok(())
    }
}

/// The largest record or decompressed chunk read from a file of `len` bytes: what the
/// gzip and bzip2 readers allow a whole stream ([`crate::io::max_decompressed_bytes`]:
/// [`crate::io::DECOMPRESSION_RATIO`] times the file, at least
/// [`crate::io::DECOMPRESSED_FLOOR_BYTES`]), here per record and chunk, at most
/// [`MAX_RECORD_BYTES`]. A damaged chunk header cannot make the decompressor's buffer larger.
fn record_limit(len: u64) -> usize {
    crate::io::max_decompressed_bytes(len).min(MAX_RECORD_BYTES as u64) as usize
}

/// Reads one MCAP file; `Ok(false)` when `visit` asked to stop.
fn read_file(
    file: &Path,
    topic_counts: &mut HashMap<String, u64>,
    delivered: &mut u64,
    visit: &mut impl FnMut(&BagMessage<'_>) -> Result<bool, BagError>,
) -> Result<bool, BagError> {
    let io = |source| BagError::Io {
        path: file.to_path_buf(),
        source,
    };
    let f = std::fs::File::open(file).map_err(io)?;
    let len = f.metadata().map_err(io)?.len();
    read_stream(f, len, file, topic_counts, delivered, visit)
}

/// Reads the MCAP file `file` of `len` bytes from `src` (its start); `Ok(false)` when
/// `visit` asked to stop. The reader's buffer never grows past the bytes the file has
/// left: a record claiming more (a damaged length, or a file cut short) ends the reading
/// as damage, saying so; a record or decompressed chunk is at most [`record_limit`] bytes.
pub(crate) fn read_stream(
    mut f: impl Read,
    len: u64,
    file: &Path,
    topic_counts: &mut HashMap<String, u64>,
    delivered: &mut u64,
    visit: &mut impl FnMut(&BagMessage<'_>) -> Result<bool, BagError>,
) -> Result<bool, BagError> {
    let limit = record_limit(len);
    let options = LinearReaderOptions::default()
        .with_validate_chunk_crcs(true)
        .with_prevalidate_chunk_crcs(true)
        .with_record_length_limit(limit);
    let mut reader = LinearReader::new_with_options(options);
    let container = |reason: String, delivered: u64| BagError::Container {
        file: file.to_path_buf(),
        reason,
        messages: delivered,
    };
    // Bytes of the file not read yet, and the first request for more than that.
    let mut left = len;
    let mut overclaim: Option<(usize, u64)> = None;
    reader
        .add_decompressor(super::lz4::Lz4FrameDecoder::new())
        .map_err(|e| container(e.to_string(), *delivered))?;
    let mut schemas: HashMap<u16, Arc<SchemaInfo>> = HashMap::new();
    let mut channels: HashMap<u16, Channel> = HashMap::new();
    while let Some(event) = guarded(|| reader.next_event()).map_err(|e| container(e, *delivered))? {
        let event = event.map_err(|e| {
            let reason = match (&e, overclaim) {
                (mcap::McapError::UnexpectedEof, Some((n, had))) => format!(
                    "a record claims {n} more bytes where the file has {had} left: the file is \
                     truncated, or a length in it is damaged"
                ),
                _ => describe(&e, limit, len),
            };
            container(reason, *delivered)
        })?;
        let (opcode, data) = match event {
            LinearReadEvent::ReadRequest(n) => {
                // The reader asks for what the structure it is in claims. A claim past the
                // end of the file (a damaged length, or a file cut short) gets what is
                // left, and the end of the file then stops the reading: the buffer never
                // grows to a length the file does not hold. (A file that ends where it
                // should is never asked for more than it has.)
                let available = usize::try_from(left).unwrap_or(usize::MAX);
                if n > available && overclaim.is_none() {
                    overclaim = Some((n, left));
                }
                let buf = reader.insert(n.min(available.max(1)));
                let got = f.read(buf).map_err(|source| BagError::Io {
                    path: file.to_path_buf(),
                    source,
                })?;
                left = left.saturating_sub(got as u64);
                reader.notify_read(got);
                continue;
            }
            LinearReadEvent::Record { opcode, data } => (opcode, data),
        };
        let record = guarded(|| mcap::parse_record(opcode, data))
            .map_err(|e| container(e, *delivered))?
            .map_err(|e| container(describe(&e, limit, len), *delivered))?;
        match record {
            Record::Schema { header, data } => {
                let text = String::from_utf8_lossy(&data).into_owned();
                schemas.insert(
                    header.id,
                    Arc::new(SchemaInfo {
                        name: header.name,
                        encoding: header.encoding,
                        text,
                        defs: OnceLock::new(),
                    }),
                );
            }
            Record::Channel(c) => {
                let schema = schemas.get(&c.schema_id).cloned();
                channels.insert(
                    c.id,
                    Channel {
                        topic: c.topic,
                        encoding: c.message_encoding,
                        schema,
                    },
                );
            }
            Record::Message { header, data } => {
                let Some(ch) = channels.get(&header.channel_id) else {
                    return Err(container(
                        format!(
                            "a message on channel {} before that channel was declared",
                            header.channel_id
                        ),
                        *delivered,
                    ));
                };
                let counter = topic_counts.entry(ch.topic.clone()).or_insert(0);
                let index = *counter;
                *counter += 1;
                let msg = BagMessage {
                    topic: &ch.topic,
                    type_name: ch.schema.as_ref().map_or("", |s| s.name.as_str()),
                    encoding: &ch.encoding,
                    schema: ch.schema.as_ref(),
                    index,
                    log_time: header.log_time,
                    data: &data,
                    file,
                };
                *delivered += 1;
                if !visit(&msg)? {
                    return Ok(false);
                }
            }
            _ => {}
        }
    }
    Ok(true)
}

/// Runs a call into the `mcap` crate, turning a panic into the reason the file is refused
/// ([`crate::guard`]). Its reader has arithmetic that damaged lengths can overflow (mcap
/// 0.26: a record inside an uncompressed chunk whose CRC is 0, the "not computed" value,
/// claiming more than the chunk holds), which panics where overflow is checked (debug and
/// test builds) and wraps where it is not; the fuzzer found it.
fn guarded<T>(call: impl FnOnce() -> T) -> Result<T, String> {
    crate::guard::guarded(call)
        .map_err(|why| format!("the MCAP reader failed on damaged data ({why})"))
}

/// What an MCAP error says about the file, with the size limit when a record or chunk
/// was over it (`limit` bytes, for a file of `len`).
fn describe(e: &mcap::McapError, limit: usize, len: u64) -> String {
    match e {
        mcap::McapError::UnexpectedEof => {
            "the file ends in the middle of a record (truncated?)".into()
        }
        mcap::McapError::RecordTooLarge { .. } | mcap::McapError::ChunkTooLarge(_) => format!(
            "{e} (olmap reads a record or decompressed chunk of at most {limit} bytes from a \
             file of {len} bytes: {} times the file, at least {} MiB)",
            crate::io::DECOMPRESSION_RATIO,
            crate::io::DECOMPRESSED_FLOOR_BYTES >> 20
        ),
        other => other.to_string(),
    }
}

/// The value of a top-level-or-nested `key: value` line (first occurrence).
fn yaml_scalar(text: &str, key: &str) -> Option<String> {
    text.lines().find_map(|l| {
        let l = l.trim();
        l.strip_prefix(key)
            .and_then(|rest| rest.strip_prefix(':'))
            .map(|v| v.trim().trim_matches(['"', '\'']).to_string())
    })
}

/// The items of a block list `key:\n  - a\n  - b` (first occurrence).
fn yaml_list(text: &str, key: &str) -> Vec<String> {
    let mut lines = text.lines();
    let mut out = Vec::new();
    for l in lines.by_ref() {
        if l.trim() == format!("{key}:") {
            break;
        }
    }
    for l in lines {
        match l.trim().strip_prefix("- ") {
            Some(item) => out.push(item.trim().trim_matches(['"', '\'']).to_string()),
            None => break,
        }
    }
    out
}

/// Compares names with digit runs as numbers (`bag_2` before `bag_10`).
fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    let key = |s: &str| -> Vec<(String, u64)> {
        let mut out = Vec::new();
        let mut text = String::new();
        let mut num: Option<u64> = None;
        for c in s.chars() {
            if let Some(d) = c.to_digit(10) {
                num = Some(num.unwrap_or(0).saturating_mul(10).saturating_add(d.into()));
            } else {
                if let Some(n) = num.take() {
                    out.push((std::mem::take(&mut text), n));
                }
                text.push(c);
            }
        }
        out.push((text, num.unwrap_or(0)));
        out
    };
    key(a).cmp(&key(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_files_sort_naturally_and_yaml_lists_parse() {
        let mut v = vec!["b_10.mcap", "b_2.mcap", "b_0.mcap"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, ["b_0.mcap", "b_2.mcap", "b_10.mcap"]);
        let yaml = "x:\n  storage_identifier: mcap\n  relative_file_paths:\n  - a_0.mcap\n  - a_1.mcap\n  files:\n";
        assert_eq!(
            yaml_list(yaml, "relative_file_paths"),
            ["a_0.mcap", "a_1.mcap"]
        );
        assert_eq!(
            yaml_scalar(yaml, "storage_identifier").as_deref(),
            Some("mcap")
        );
    }
}
