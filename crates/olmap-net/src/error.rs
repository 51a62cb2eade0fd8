//! The crate's errors: [`NetError`] for what a node cannot do, [`BadMessage`] for a payload
//! it refuses (counted and dropped, never fatal).

use crate::protocol::Kind;

/// Why a received payload was refused. A refused payload is counted
/// ([`crate::status::Counters`]), logged once per reason and dropped: never stored, never
/// a crash.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BadMessage {
    /// Larger than the node's cap.
    #[error("payload of {bytes} bytes is over the {max}-byte cap")]
    Oversized {
        /// Its size.
        bytes: usize,
        /// The cap.
        max: usize,
    },
    /// Shorter than what it announces, or than the envelope.
    #[error("truncated: {0}")]
    Truncated(String),
    /// Not an olmap-net payload.
    #[error("bad magic bytes (not an olmap-net payload)")]
    Magic,
    /// A wire-format version this node does not know.
    #[error("unknown wire-format version {0} (this node speaks {v})", v = crate::protocol::VERSION)]
    Version(u8),
    /// Not the kind its key carries.
    #[error("payload kind {got} on a key for {expected:?}")]
    Kind {
        /// What it says it is.
        got: String,
        /// What the key carries.
        expected: Kind,
    },
    /// The CRC-32 does not match: damaged on the way.
    #[error("checksum mismatch (stored {stored:08x}, computed {computed:08x})")]
    Checksum {
        /// The checksum it carries.
        stored: u32,
        /// The checksum of what arrived.
        computed: u32,
    },
    /// The key does not name a record (or names another robot or scan than the payload).
    #[error("key mismatch: {0}")]
    Key(String),
    /// The body does not decode.
    #[error("malformed body: {0}")]
    Body(String),
    /// A record that differs from the one already held under its key.
    #[error("conflict: {0}")]
    Conflict(String),
    /// Over the robot's allowed record rate.
    #[error("robot {0} is over its record rate")]
    Rate(u32),
}

impl BadMessage {
    /// A short stable name of the reason, for counters and reports.
    pub fn reason(&self) -> &'static str {
        match self {
            BadMessage::Oversized { .. } => "oversized",
            BadMessage::Truncated(_) => "truncated",
            BadMessage::Magic => "bad_magic",
            BadMessage::Version(_) => "wrong_version",
            BadMessage::Kind { .. } => "wrong_kind",
            BadMessage::Checksum { .. } => "bad_checksum",
            BadMessage::Key(_) => "wrong_key",
            BadMessage::Body(_) => "malformed",
            BadMessage::Conflict(_) => "conflict",
            BadMessage::Rate(_) => "rate_limited",
        }
    }
}

/// What a node cannot do.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    /// Zenoh refused (configuration, session, declaration).
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// The persistent store failed.
    #[error("store {path}: {reason}")]
    Store {
        /// The store file.
        path: std::path::PathBuf,
        /// What failed.
        reason: String,
    },
    /// An argument or option is not usable.
    #[error("{0}")]
    InvalidArgument(String),
    /// olmap itself failed (reading a dataset, mapping, writing outputs).
    #[error(transparent)]
    Olmap(#[from] olmap::Error),
    /// A wait ran out.
    #[error("timed out: {0}")]
    Timeout(String),
}

impl NetError {
    pub(crate) fn zenoh(e: impl std::fmt::Display) -> NetError {
        NetError::Zenoh(e.to_string())
    }
}

/// The crate's result type.
pub type Result<T, E = NetError> = std::result::Result<T, E>;
