//! Typed errors of the library.
//!
//! Every error that concerns a file names the file and, where it can, the line or byte
//! offset and what was expected there. Parsers work on streams without a path and return a
//! [`ParseError`]; the path-level functions in [`crate::io`] wrap it into [`Error::Read`]
//! together with the path and the format.
//!
//! Which variant says what, so that a caller can act on it:
//!
//! | variant | meaning | returned by, for example |
//! |---|---|---|
//! | [`Error::Io`], [`Error::IsDirectory`] | the file system refused | every reader and writer |
//! | [`Error::UnknownFormat`], [`Error::Read`] | a file is not what it claims (path, format, line) | [`crate::io::read_cloud`], [`crate::occupancy::read_map`], [`crate::io::read_poses`] |
//! | [`Error::Write`] | a write failed; the target is untouched | [`crate::file::write_atomic`] and every writer |
//! | [`Error::EmptyInput`] | nothing to work on: wait for data or pick another input | registration with an empty target or no source point in range, [`crate::mapping::build_map`] without scans, [`crate::team::map_team`] on an empty store, [`crate::io::scan_files`] finding no scan |
//! | [`Error::TooLarge`] | over a limit olmap enforces: ask for less | a memory estimate over [`crate::limits::MAX_ESTIMATE_BYTES`] (a search's uniform start, a simulation, an overlap surface), the exact search's bound grids and work, 2D and navigation grids beyond their cell limits, a `.bz2` file that decompresses beyond its limit, a `.bt` octree that expands beyond its voxel limit, a point whose voxel key is outside the representable range |
//! | [`Error::Unsupported`] | a valid request olmap does not do | reserved for format variants and mode combinations |
//! | [`Error::NotFound`] | a name is not where it was looked up | [`crate::mapping::odometry_for`] (a scan without an odometry pose), [`crate::mapping::run_map_job`] (no scan of the first scan's name) |
//! | [`Error::InvalidArgument`] | a bad parameter value or a contradiction between parameters | parameter checks everywhere |

use std::fmt;
use std::path::PathBuf;

/// Where in a stream a parse problem was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// A 1-based line number in a text file (or in the text header of a binary file).
    Line(usize),
    /// A 0-based byte offset in a binary file.
    Byte(u64),
    /// A 0-based point (record) index.
    Point(u64),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(n) => write!(f, "line {n}"),
            Location::Byte(n) => write!(f, "byte {n}"),
            Location::Point(n) => write!(f, "point {n}"),
        }
    }
}

/// A problem found while parsing a stream (no path attached yet).
#[derive(Debug, thiserror::Error)]
pub enum ParseError {
    /// The underlying reader failed.
    #[error("read failed: {0}")]
    Io(#[from] std::io::Error),
    /// The stream holds no data at all.
    #[error("the file is empty")]
    Empty,
    /// The stream ended before the data its header announced.
    #[error("the file ends early: {0}")]
    Truncated(String),
    /// Content that does not follow the format, at a known place.
    #[error("{at}: {reason}")]
    Invalid {
        /// Where the problem is.
        at: Location,
        /// What was wrong and what was expected.
        reason: String,
    },
    /// Content that does not follow the format, with no single place to name.
    #[error("{0}")]
    Malformed(String),
    /// A valid file using a feature this reader does not support.
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// The stream asks for more than a limit the reader enforces (decompressed bytes, an
    /// octree's expanded voxels, a whole-file text format's size): reading stopped before
    /// the memory was spent. The path-level readers turn it into [`Error::TooLarge`].
    #[error("too large: {what} (limit {limit})")]
    TooLarge {
        /// What was too large, with its size or the estimate of it.
        what: String,
        /// The limit, with its unit.
        limit: String,
    },
}

impl ParseError {
    /// Shorthand for [`ParseError::Invalid`].
    pub fn at(at: Location, reason: impl Into<String>) -> Self {
        ParseError::Invalid {
            at,
            reason: reason.into(),
        }
    }

    /// Shorthand for [`ParseError::Invalid`] at a 1-based line.
    pub fn line(line: usize, reason: impl Into<String>) -> Self {
        Self::at(Location::Line(line), reason)
    }
}

/// The library's error type.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be opened, created or renamed.
    #[error("{path}: {source}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A path that should be a regular file is a directory.
    #[error("{path}: is a directory, expected a file")]
    IsDirectory {
        /// The path given.
        path: PathBuf,
    },
    /// The format of a file could not be told from its name or content.
    #[error("{path}: unknown file format: {reason}")]
    UnknownFormat {
        /// The file concerned.
        path: PathBuf,
        /// Why no format matched, and which ones are known.
        reason: String,
    },
    /// A file could not be parsed.
    #[error("{path}: not a valid {format} file: {source}")]
    Read {
        /// The file concerned.
        path: PathBuf,
        /// The format it was read as.
        format: &'static str,
        /// What was wrong.
        source: ParseError,
    },
    /// A file could not be written.
    #[error("{path}: cannot write {format}: {reason}")]
    Write {
        /// The file concerned.
        path: PathBuf,
        /// The format being written.
        format: &'static str,
        /// What was wrong.
        reason: String,
    },
    /// An input that must hold something held nothing (an empty cloud, map or scan
    /// list): the caller may wait for more data or ask for another input.
    #[error("empty input: {what}")]
    EmptyInput {
        /// What was empty.
        what: String,
    },
    /// A request beyond a limit olmap enforces (memory, threads, sizes): the caller may
    /// retry with a smaller request.
    #[error("too large: {what} (limit {limit})")]
    TooLarge {
        /// What was too large, with its size.
        what: String,
        /// The limit, with its unit.
        limit: String,
    },
    /// A valid request olmap does not support (a format variant, a mode combination).
    #[error("unsupported: {what}")]
    Unsupported {
        /// What is not supported.
        what: String,
    },
    /// A name looked up in a file or a set was not there (a scan without a pose).
    #[error("{what}: not found")]
    NotFound {
        /// What was looked up, and where.
        what: String,
    },
    /// A parameter or request that cannot be honoured (a bad value, a contradiction
    /// between parameters).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
}

impl Error {
    /// Wraps a stream parser's error with the path and format of the file it read: an
    /// [`Error::Read`], except for [`ParseError::TooLarge`], which becomes an
    /// [`Error::TooLarge`] naming the path (the file may be valid; it asks for too much).
    pub fn read(path: impl Into<PathBuf>, format: &'static str, source: ParseError) -> Self {
        let path = path.into();
        match source {
            ParseError::TooLarge { what, limit } => Error::TooLarge {
                what: format!("{}: {format}: {what}", path.display()),
                limit,
            },
            source => Error::Read {
                path,
                format,
                source,
            },
        }
    }

    /// Wraps an IO error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

/// `Result` with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// The one-line message of an error and its causes (`error.source()`, then its source, ...),
/// joined with `": "`, each said once.
///
/// olmap's errors already name their cause in their own message (`scan.pcd: not a valid
/// PCD file: line 4: ...`) and also return it as their [`std::error::Error::source`], as
/// does `std::io::Error` inside them; a front end that prints the whole chain (anyhow's
/// `{:#}`) would say every cause twice. This skips a cause whose text the message already
/// holds, and keeps the rest (a front end's own context, say).
///
/// ```
/// use olmap::error::{chain_message, Error, ParseError};
/// let e = Error::read("scan.xyz", "XYZ text", ParseError::line(2, "expected x y z"));
/// let chain = [&e as &(dyn std::error::Error + 'static), std::error::Error::source(&e).unwrap()];
/// assert_eq!(chain_message(chain), "scan.xyz: not a valid XYZ text file: line 2: expected x y z");
/// ```
pub fn chain_message<'a>(
    chain: impl IntoIterator<Item = &'a (dyn std::error::Error + 'static)>,
) -> String {
    let mut message = String::new();
    for e in chain {
        let text = e.to_string();
        if message.is_empty() {
            message = text;
        } else if !message.contains(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
    }
    message
}
