//! Opening and reading whole files with errors that name them.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use crate::error::{Error, ParseError, Result};

/// Opens a file for buffered reading, with errors that name it (and a clear one for
/// directories).
pub fn open_buffered(path: &Path) -> Result<BufReader<File>> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_dir() {
        return Err(Error::IsDirectory {
            path: path.to_path_buf(),
        });
    }
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    Ok(BufReader::with_capacity(1 << 18, file))
}

/// Opens `path` and runs a stream parser on it, wrapping its error with the path and the
/// format name.
pub(crate) fn parse_file<T>(
    path: &Path,
    format: &'static str,
    parse: impl FnOnce(BufReader<File>) -> Result<T, ParseError>,
) -> Result<T> {
    parse(open_buffered(path)?).map_err(|source| Error::read(path, format, source))
}

/// Reads a whole file into memory, with errors that name it.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let mut r = open_buffered(path)?;
    let mut v = Vec::new();
    r.read_to_end(&mut v).map_err(|e| Error::io(path, e))?;
    Ok(v)
}

/// Reads a whole file of a `format` into memory, refusing one of more than `max` bytes
/// with [`Error::TooLarge`]: a file that never ends (a device, a pipe) stops there.
pub fn read_bytes_at_most(path: &Path, max: u64, format: &'static str) -> Result<Vec<u8>> {
    let mut v = Vec::new();
    open_buffered(path)?
        .take(max.saturating_add(1))
        .read_to_end(&mut v)
        .map_err(|e| Error::io(path, e))?;
    if v.len() as u64 > max {
        return Err(Error::TooLarge {
            what: format!("{}: a {format} of more than {max} bytes", path.display()),
            limit: format!("{max} bytes"),
        });
    }
    Ok(v)
}
