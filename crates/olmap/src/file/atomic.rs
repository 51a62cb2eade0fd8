//! Atomic file writes: a temporary file beside the target, renamed into place on success.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Error, Result};

/// Writes a file atomically: `write` fills a temporary file beside `path`, which is renamed
/// onto `path` only when everything succeeded; on failure the temporary file is removed and
/// an existing `path` is left untouched.
pub fn write_atomic(
    path: &Path,
    format: &'static str,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    if path.is_dir() {
        return Err(Error::IsDirectory {
            path: path.to_path_buf(),
        });
    }
    let file_name = path.file_name().ok_or_else(|| Error::Write {
        path: path.to_path_buf(),
        format,
        reason: "the path has no file name".into(),
    })?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(file_name);
    tmp_name.push(format!(".olmap-tmp-{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    let file = File::create(&tmp).map_err(|e| Error::io(path, e))?;
    let mut w = BufWriter::with_capacity(1 << 18, file);
    let result = write(&mut w).and_then(|_| w.flush());
    drop(w);
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::Write {
            path: path.to_path_buf(),
            format,
            reason: e.to_string(),
        });
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })
}
