//! What can go wrong reading a bag.

use std::path::PathBuf;

use crate::error::{Error, ParseError};

/// A failure reading or decoding a ROS 2 bag. Message-level failures name the topic, the
/// message's index on that topic (0-based, in bag order) and its type.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// A file could not be opened or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The path is neither an `.mcap` file nor a rosbag2 folder olmap can read.
    #[error("{path}: not a ROS 2 bag olmap reads: {reason}")]
    NotABag {
        /// The path given.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// The MCAP container is damaged (truncated, bad CRC, bad record); reading stopped
    /// there, and the messages before it were delivered.
    #[error("{file}: {reason} (after {messages} readable messages)")]
    Container {
        /// The MCAP file.
        file: PathBuf,
        /// What is wrong.
        reason: String,
        /// Messages delivered before the failure.
        messages: u64,
    },
    /// One message could not be decoded.
    #[error("{file}: topic '{topic}', message {index} ({type_name}): {reason}")]
    Message {
        /// The MCAP file that holds it.
        file: PathBuf,
        /// Its topic.
        topic: String,
        /// Its index on the topic (0-based).
        index: u64,
        /// Its declared type.
        type_name: String,
        /// What is wrong.
        reason: String,
    },
    /// A topic asked for is not in the bag.
    #[error("{path}: no topic '{topic}' in the bag (topics: {known})")]
    NoTopic {
        /// The bag.
        path: PathBuf,
        /// The topic asked for.
        topic: String,
        /// The bag's topics with their types.
        known: String,
    },
    /// A request the bag cannot satisfy (no scan at an index, no odometry, ...).
    #[error("{path}: {reason}")]
    Request {
        /// The bag.
        path: PathBuf,
        /// What is missing.
        reason: String,
    },
}

impl From<BagError> for Error {
    fn from(e: BagError) -> Self {
        match e {
            BagError::Io { path, source } => Error::Io { path, source },
            BagError::NotABag { path, reason } => Error::UnknownFormat { path, reason },
            BagError::Container {
                file,
                reason,
                messages,
            } => Error::Read {
                path: file,
                format: "ROS 2 bag",
                source: ParseError::Malformed(format!(
                    "{reason} (after {messages} readable messages)"
                )),
            },
            BagError::Message {
                file,
                topic,
                index,
                type_name,
                reason,
            } => Error::Read {
                path: file,
                format: "ROS 2 bag",
                source: ParseError::Malformed(format!(
                    "topic '{topic}', message {index} ({type_name}): {reason}"
                )),
            },
            other => Error::NotFound {
                what: other.to_string(),
            },
        }
    }
}
