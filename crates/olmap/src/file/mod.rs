//! File plumbing every layer uses: atomic writes and output sets, buffered opening, text-line and byte
//! cursors, CRC-32 and LZF. This is the bottom layer of the crate: it imports nothing but
//! [`crate::error`], and the formats in [`crate::io`], the map files in
//! [`crate::occupancy`], the stores in [`crate::team`] and the pictures in
//! [`crate::render`] all build on it.

mod atomic;
pub mod crc32;
pub(crate) mod cursor;
pub(crate) mod header;
pub mod lzf;
mod outputs;
mod read;
pub(crate) mod text;

pub use atomic::{remove_stale_temporaries, write_atomic, STALE_AFTER};
pub use outputs::{check_output, html_path_beside, OutputSet};
pub(crate) use read::parse_file;
pub use read::{open_buffered, read_bytes, read_bytes_at_most};
pub use text::MAX_LINE_BYTES;
