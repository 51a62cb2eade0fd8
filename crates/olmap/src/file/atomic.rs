//! Atomic file writes: a temporary file beside the target, synced and renamed into place
//! on success.
//!
//! How a write goes, and why:
//! * **The output path is resolved first.** A symbolic link is followed to the file it
//!   names (written through: the link stays a link and its target gets the new content,
//!   as `cp` and shell redirection do); a device node, FIFO or socket (`/dev/null`,
//!   `/dev/stdout`) is written through directly, since it cannot be replaced by a regular
//!   file and holds no old content to protect; a folder is refused.
//! * **The temporary file gets an unpredictable name and is created exclusively**
//!   (`O_CREAT | O_EXCL`, [`std::fs::OpenOptions::create_new`]): a name planted in advance
//!   (a symbolic link to a file of the victim's) makes the creation fail instead of being
//!   followed. Its name is `.NAME.olmap-tmp-XXXXXXXXXXXXXXXX` in the target's folder (the
//!   same file system, so the rename is atomic), with 64 random bits from the standard
//!   library's randomly keyed hasher ([`std::collections::hash_map::RandomState`]: not
//!   cryptographic, but unknown to another process); a taken name is retried with new
//!   bits.
//! * **The content is flushed and `fsync`ed before the rename, and the folder after it**
//!   (on Unix), so that a power cut leaves the old file or the new one, never an empty or
//!   partial one. An existing target's permissions are kept.
//! * **Two writers of one output** each write their own temporary file; each rename
//!   replaces the whole file, so the result is one writer's complete file, never a
//!   mixture.
//! * **Leftovers of killed writers are removed**: a temporary file (`.*.olmap-tmp-*`) or
//!   staging folder of an [`OutputSet`](super::OutputSet) (`.olmap-stage-*`) older than
//!   [`STALE_AFTER`] is deleted by the next olmap writer in the same folder (each folder is
//!   swept at most once an hour per process). No olmap write takes hours, so an older one
//!   belongs to a process that died.

use std::collections::HashMap;
use std::ffi::OsStr;
use std::fs::{File, OpenOptions};
use std::hash::{BuildHasher, Hasher};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant, SystemTime};

use crate::error::{Error, Result};

/// Age after which a temporary file or staging folder left in a folder is taken for the
/// leftover of a killed writer and removed by the next writer there: six hours.
pub const STALE_AFTER: Duration = Duration::from_secs(6 * 3600);

/// What marks a temporary file's name (after `.NAME`).
pub(crate) const TMP_MARK: &str = ".olmap-tmp-";
/// How a staging folder's name starts.
pub(crate) const STAGE_PREFIX: &str = ".olmap-stage-";

/// Symbolic links followed at most when resolving an output path (as Linux's `ELOOP`).
const MAX_LINKS: usize = 40;
/// Names tried before giving up on creating a temporary file.
const MAX_TRIES: usize = 16;

/// What an output path is, after following symbolic links.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Target {
    /// Nothing there yet: a new regular file at this path.
    Missing(PathBuf),
    /// A regular file, replaced atomically.
    File(PathBuf),
    /// A folder.
    Dir(PathBuf),
    /// A device node, FIFO or socket: written through, never replaced.
    Special(PathBuf),
}

impl Target {
    /// The resolved path.
    pub(crate) fn path(&self) -> &Path {
        match self {
            Target::Missing(p) | Target::File(p) | Target::Dir(p) | Target::Special(p) => p,
        }
    }
}

/// Follows symbolic links from `path` to what it finally names.
pub(crate) fn resolve(path: &Path) -> Result<Target> {
    let mut p = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        let meta = match std::fs::symlink_metadata(&p) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Target::Missing(p)),
            Err(e) => return Err(Error::io(path, e)),
        };
        let kind = meta.file_type();
        if kind.is_symlink() {
            let link = std::fs::read_link(&p).map_err(|e| Error::io(path, e))?;
            p = if link.is_absolute() {
                link
            } else {
                parent_of(&p).join(link)
            };
        } else if kind.is_dir() {
            return Ok(Target::Dir(p));
        } else if kind.is_file() {
            return Ok(Target::File(p));
        } else {
            return Ok(Target::Special(p));
        }
    }
    Err(Error::Write {
        path: path.to_path_buf(),
        format: "file",
        reason: format!("more than {MAX_LINKS} symbolic links to follow"),
    })
}

/// The folder holding `path` (`.` for a bare file name).
pub(crate) fn parent_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// 64 bits no other process can predict: a freshly keyed standard hasher over the process
/// id, the time and a counter.
pub(crate) fn random_u64() -> u64 {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u32(std::process::id());
    h.write_u64(COUNTER.fetch_add(1, Ordering::Relaxed));
    if let Ok(t) = SystemTime::now().duration_since(SystemTime::UNIX_EPOCH) {
        h.write_u128(t.as_nanos());
    }
    h.finish()
}

/// Creates a new file exclusively in `dir`, named `.NAME.olmap-tmp-RANDOM`; never follows
/// or reuses an existing name.
pub(crate) fn create_temp(dir: &Path, name: &OsStr) -> std::io::Result<(PathBuf, File)> {
    let mut last = None;
    for _ in 0..MAX_TRIES {
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(name);
        tmp_name.push(format!("{TMP_MARK}{:016x}", random_u64()));
        let tmp = dir.join(tmp_name);
        match OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(f) => return Ok((tmp, f)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last.unwrap_or_else(|| std::io::Error::other("no free temporary name")))
}

/// `fsync`s a folder so that a rename in it survives a power cut (Unix; elsewhere, and
/// where the file system refuses, nothing).
pub(crate) fn sync_dir(dir: &Path) {
    #[cfg(unix)]
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
    #[cfg(not(unix))]
    let _ = dir;
}

/// Whether a folder entry's name is one olmap gives its temporary files and staging
/// folders.
pub(crate) fn is_olmap_temporary(name: &OsStr) -> bool {
    let name = name.to_string_lossy();
    name.starts_with(STAGE_PREFIX) || (name.starts_with('.') && name.contains(TMP_MARK))
}

/// Removes the temporary files and staging folders in `dir` older than `older_than`
/// (leftovers of killed writers); returns how many were removed. Errors (a folder that
/// cannot be read, an entry of another user's) are skipped: this is housekeeping.
pub fn remove_stale_temporaries(dir: &Path, older_than: Duration) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let now = SystemTime::now();
    let mut removed = 0;
    for entry in entries.flatten() {
        if !is_olmap_temporary(&entry.file_name()) {
            continue;
        }
        let Ok(meta) = entry.path().symlink_metadata() else {
            continue;
        };
        let old = meta
            .modified()
            .ok()
            .and_then(|m| now.duration_since(m).ok())
            .is_some_and(|age| age > older_than);
        if !old {
            continue;
        }
        // `remove_dir_all` does not follow symbolic links; a link is removed as a file.
        let gone = if meta.is_dir() {
            std::fs::remove_dir_all(entry.path())
        } else {
            std::fs::remove_file(entry.path())
        };
        if gone.is_ok() {
            removed += 1;
        }
    }
    removed
}

/// Sweeps `dir` for stale leftovers unless this process did within the last hour.
pub(crate) fn sweep_once(dir: &Path) {
    static SWEPT: Mutex<Option<HashMap<PathBuf, Instant>>> = Mutex::new(None);
    const AGAIN_AFTER: Duration = Duration::from_secs(3600);
    {
        let Ok(mut swept) = SWEPT.lock() else {
            return;
        };
        let swept = swept.get_or_insert_with(HashMap::new);
        if swept.len() > 4096 {
            swept.clear();
        }
        if swept.get(dir).is_some_and(|t| t.elapsed() < AGAIN_AFTER) {
            return;
        }
        swept.insert(dir.to_path_buf(), Instant::now());
    }
    remove_stale_temporaries(dir, STALE_AFTER);
}

fn write_error(path: &Path, format: &'static str, e: std::io::Error) -> Error {
    Error::Write {
        path: path.to_path_buf(),
        format,
        reason: e.to_string(),
    }
}

/// Writes a file atomically: `write` fills a new temporary file beside `path`, which is
/// `fsync`ed and renamed onto `path` only when everything succeeded (then the folder is
/// `fsync`ed); on failure the temporary file is removed and an existing `path` is left
/// untouched. A symbolic link is written through to the file it names; a device node,
/// FIFO or socket (`/dev/null`) is written directly; a folder is an
/// [`Error::IsDirectory`]. The module documentation says why each step is there.
pub fn write_atomic(
    path: &Path,
    format: &'static str,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let target = match resolve(path)? {
        Target::Dir(_) => {
            return Err(Error::IsDirectory {
                path: path.to_path_buf(),
            })
        }
        Target::Special(device) => return write_through(path, &device, format, write),
        t => t,
    };
    let real = target.path();
    let file_name = real.file_name().ok_or_else(|| Error::Write {
        path: path.to_path_buf(),
        format,
        reason: "the path has no file name".into(),
    })?;
    let dir = parent_of(real);
    sweep_once(&dir);
    let (tmp, file) = create_temp(&dir, file_name).map_err(|e| Error::io(path, e))?;
    if let Target::File(old) = &target {
        if let Ok(meta) = std::fs::metadata(old) {
            let _ = file.set_permissions(meta.permissions());
        }
    }
    let mut w = BufWriter::with_capacity(1 << 18, file);
    let result = write(&mut w)
        .and_then(|_| w.flush())
        .and_then(|_| w.get_ref().sync_all());
    drop(w);
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(write_error(path, format, e));
    }
    std::fs::rename(&tmp, real).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })?;
    sync_dir(&dir);
    Ok(())
}

/// Writes straight into a device node, FIFO or socket (nothing to replace atomically).
fn write_through(
    path: &Path,
    device: &Path,
    format: &'static str,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let file = OpenOptions::new()
        .write(true)
        .open(device)
        .map_err(|e| Error::io(path, e))?;
    let mut w = BufWriter::with_capacity(1 << 18, file);
    write(&mut w)
        .and_then(|_| w.flush())
        .map_err(|e| write_error(path, format, e))
}
