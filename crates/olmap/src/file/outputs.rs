//! Output sets: the files (and folders) of one run, checked before any computing and
//! put in place together at the end, so that a failed or interrupted run leaves the old
//! outputs, never a mixture of old and new or a part of the new ones.
//!
//! A pipeline with several outputs
//! 1. declares them first ([`OutputSet::file`], [`OutputSet::dir`], [`OutputSet::folder`],
//!    [`OutputSet::remove`]): each path is checked now — its folder exists and is
//!    writable (proved by creating and removing a temporary file there), it is not a
//!    folder itself (or, for [`OutputSet::dir`], not a file), no two outputs are the same
//!    file — so that a typo in the last output fails before hours of computing;
//! 2. computes;
//! 3. writes every output where [`OutputSet::path`] says: a hidden staging folder
//!    (`.olmap-stage-RANDOM`) in each target's folder, under the output's own name (so
//!    that formats told by the extension and files naming each other, like a ROS map's
//!    YAML naming its image, come out the same);
//! 4. [`OutputSet::commit`]s: with the target folders locked (`flock`, so that two
//!    processes committing into one folder take turns and the folder ends with one
//!    run's complete set), every staged output is renamed onto its target. An existing
//!    file is first hard-linked into the staging folder (readers never see it missing)
//!    and an existing folder moved there; if any rename fails, everything done is undone
//!    and the old outputs are back. Outputs declared with [`OutputSet::remove`] (what an
//!    older run wrote and this one does not, like `solo/` without `--solo`) are moved
//!    away at the same time.
//!
//! Dropping a set that was not committed (an error, a panic in a caller) removes its
//! staging folders and the folders it created that are still empty; a killed process
//! leaves a hidden staging folder that the next olmap writer in that folder removes once
//! it is older than [`STALE_AFTER`](super::STALE_AFTER). The commit itself is a handful of
//! renames; a kill in the middle of it can leave a mixture (both complete sets are then on
//! disk: the new one in place or in the staging folder, the old one in its `.olmap-old/`).
//!
//! Device nodes, FIFOs and sockets among the outputs (`/dev/null`, `/dev/stdout`) are
//! written through at once in step 3: a stream cannot be staged and taken back. Symbolic
//! links are followed to what they name, which is replaced (the link stays).

use std::fs::File;
use std::path::{Path, PathBuf};

use super::atomic::{create_temp, parent_of, random_u64, resolve, sync_dir, Target, STAGE_PREFIX};
use crate::error::{Error, Result};

/// What one declared output is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// A file, replaced as a whole.
    File,
    /// A folder, replaced as a whole (its old content goes).
    Dir,
    /// A device node, FIFO or socket: written through.
    Special,
    /// Removed at the commit if present (a stale output of an older run).
    Remove,
}

#[derive(Debug)]
struct Output {
    /// The path as given (for messages).
    declared: PathBuf,
    /// Where the path leads after following symbolic links.
    target: PathBuf,
    kind: Kind,
    format: &'static str,
}

/// A hidden staging folder inside one target folder.
#[derive(Debug)]
struct Stage {
    /// The target folder.
    dir: PathBuf,
    /// The staging folder, once created.
    path: Option<PathBuf>,
}

/// The outputs of one run, put in place together or not at all (module documentation).
///
/// ```
/// use std::io::Write;
/// use olmap::file::{write_atomic, OutputSet};
/// let dir = std::env::temp_dir().join(format!("olmap-doc-set-{}", std::process::id()));
/// let mut set = OutputSet::new();
/// set.folder(&dir)?;
/// set.file(&dir.join("a.txt"), "text")?;
/// set.file(&dir.join("b.txt"), "text")?;
/// // ... compute ...
/// for name in ["a.txt", "b.txt"] {
///     let staged = set.path(&dir.join(name))?;
///     write_atomic(&staged, "text", |w| w.write_all(name.as_bytes()))?;
/// }
/// assert!(!dir.join("a.txt").exists()); // nothing in place before the commit
/// set.commit()?;
/// assert_eq!(std::fs::read_to_string(dir.join("b.txt")).unwrap(), "b.txt");
/// # std::fs::remove_dir_all(&dir).ok();
/// # Ok::<(), olmap::Error>(())
/// ```
#[derive(Debug, Default)]
pub struct OutputSet {
    outputs: Vec<Output>,
    stages: Vec<Stage>,
    /// Folders proved writable.
    writable: Vec<PathBuf>,
    /// Folders this set created, outermost first.
    created: Vec<PathBuf>,
    committed: bool,
}

fn write_error(path: &Path, format: &'static str, reason: impl Into<String>) -> Error {
    Error::Write {
        path: path.to_path_buf(),
        format,
        reason: reason.into(),
    }
}

/// The HTML report's path beside a JSON report: the same name with the extension `html`
/// (`NAME.report.html` when the JSON file itself ends in `.html`).
pub fn html_path_beside(json_path: &Path) -> PathBuf {
    let mut path = json_path.with_extension("html");
    if path == json_path {
        path = json_path.with_extension("report.html");
    }
    path
}

/// Checks now, before any computing, that `path` can be written as a `format` file: its
/// folder exists and is writable, and it is not a folder. The same check as
/// [`OutputSet::file`], for a run with a single output.
pub fn check_output(path: &Path, format: &'static str) -> Result<()> {
    OutputSet::new().file(path, format)
}

impl OutputSet {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Proves `dir` writable by creating and removing a temporary file in it.
    fn check_writable(&mut self, dir: &Path, path: &Path, format: &'static str) -> Result<()> {
        if self.writable.iter().any(|d| d == dir) {
            return Ok(());
        }
        match std::fs::metadata(dir) {
            Ok(m) if m.is_dir() => {}
            Ok(_) => {
                return Err(write_error(
                    path,
                    format,
                    format!("{} is not a folder", dir.display()),
                ))
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(write_error(
                    path,
                    format,
                    format!("the folder {} does not exist", dir.display()),
                ))
            }
            Err(e) => return Err(Error::io(dir, e)),
        }
        let (tmp, file) = create_temp(dir, std::ffi::OsStr::new("probe")).map_err(|e| {
            write_error(
                path,
                format,
                format!("the folder {} is not writable: {e}", dir.display()),
            )
        })?;
        drop(file);
        let _ = std::fs::remove_file(tmp);
        self.writable.push(dir.to_path_buf());
        Ok(())
    }

    fn declare(
        &mut self,
        path: &Path,
        target: PathBuf,
        kind: Kind,
        format: &'static str,
    ) -> Result<()> {
        if kind != Kind::Special
            && self
                .outputs
                .iter()
                .any(|o| o.target == target && o.kind != Kind::Special)
        {
            return Err(Error::InvalidArgument(format!(
                "{}: this run would write that file twice (two outputs lead to {})",
                path.display(),
                target.display()
            )));
        }
        if kind != Kind::Special {
            if target.file_name().is_none() {
                return Err(write_error(path, format, "the path has no file name"));
            }
            let dir = parent_of(&target);
            self.check_writable(&dir, path, format)?;
            if !self.stages.iter().any(|s| s.dir == dir) {
                self.stages.push(Stage { dir, path: None });
            }
        }
        self.outputs.push(Output {
            declared: path.to_path_buf(),
            target,
            kind,
            format,
        });
        Ok(())
    }

    /// Declares an output file. Checked now: not a folder, its folder exists and is
    /// writable, no other output of the set is the same file. A symbolic link is followed
    /// (the file it names is replaced); a device node, FIFO or socket is written through.
    pub fn file(&mut self, path: &Path, format: &'static str) -> Result<()> {
        match resolve(path)? {
            Target::Dir(_) => Err(Error::IsDirectory {
                path: path.to_path_buf(),
            }),
            Target::Special(p) => self.declare(path, p, Kind::Special, format),
            Target::Missing(p) | Target::File(p) => self.declare(path, p, Kind::File, format),
        }
    }

    /// Declares an output folder that this run writes whole and that replaces an existing
    /// one at the commit (its old content goes). Checked now: not a file, its parent
    /// folder exists and is writable.
    pub fn dir(&mut self, path: &Path, format: &'static str) -> Result<()> {
        match resolve(path)? {
            Target::Missing(p) | Target::Dir(p) => self.declare(path, p, Kind::Dir, format),
            Target::File(_) | Target::Special(_) => {
                Err(write_error(path, format, "exists and is not a folder"))
            }
        }
    }

    /// Declares a path that this run does not write but an older run may have (a stale
    /// output): if present at the commit it is removed with the rest of the old set.
    pub fn remove(&mut self, path: &Path) -> Result<()> {
        let target = resolve(path)?;
        if let Target::Special(_) = target {
            return Ok(());
        }
        self.declare(path, target.path().to_path_buf(), Kind::Remove, "file")
    }

    /// A folder that will hold outputs (an output folder given by the user): created now,
    /// with its parents, if missing, and checked writable. The folders it creates are
    /// removed again if the set is dropped without a commit and they are still empty.
    pub fn folder(&mut self, dir: &Path) -> Result<()> {
        let mut missing = Vec::new();
        let mut p = dir.to_path_buf();
        while !p.as_os_str().is_empty() && std::fs::symlink_metadata(&p).is_err() {
            missing.push(p.clone());
            match p.parent() {
                Some(q) => p = q.to_path_buf(),
                None => break,
            }
        }
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        self.created.extend(missing.into_iter().rev());
        match resolve(dir)? {
            Target::Dir(real) => self.check_writable(&real, dir, "folder"),
            _ => Err(write_error(dir, "folder", "exists and is not a folder")),
        }
    }

    /// Where to write the declared output `path` now: in the staging folder (created on
    /// first use) under the output's own name; for a folder output, an empty staged
    /// folder; for a device node, the device itself. An undeclared path is an
    /// [`Error::InvalidArgument`].
    pub fn path(&mut self, path: &Path) -> Result<PathBuf> {
        let i = self
            .outputs
            .iter()
            .position(|o| o.declared == path)
            .ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "{}: not an output declared for this run",
                    path.display()
                ))
            })?;
        let (kind, target) = (self.outputs[i].kind, self.outputs[i].target.clone());
        if kind == Kind::Special {
            return Ok(target);
        }
        if kind == Kind::Remove {
            return Err(Error::InvalidArgument(format!(
                "{}: declared as an output to remove, not to write",
                path.display()
            )));
        }
        let stage = self.stage_of(&target)?;
        let staged = stage.join(target.file_name().expect("checked at declaration"));
        if kind == Kind::Dir && !staged.exists() {
            std::fs::create_dir(&staged).map_err(|e| Error::io(&staged, e))?;
        }
        Ok(staged)
    }

    /// The staging folder for `target`'s folder, created on first use.
    fn stage_of(&mut self, target: &Path) -> Result<PathBuf> {
        let dir = parent_of(target);
        let stage = self
            .stages
            .iter_mut()
            .find(|s| s.dir == dir)
            .expect("every declared output has a stage");
        if let Some(p) = &stage.path {
            return Ok(p.clone());
        }
        let mut last = None;
        for _ in 0..16 {
            let p = dir.join(format!("{STAGE_PREFIX}{:016x}", random_u64()));
            match std::fs::create_dir(&p) {
                Ok(()) => {
                    stage.path = Some(p.clone());
                    return Ok(p);
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last = Some(e),
                Err(e) => return Err(Error::io(&dir, e)),
            }
        }
        Err(Error::io(
            &dir,
            last.unwrap_or_else(|| std::io::Error::other("no free staging name")),
        ))
    }

    /// Puts every staged output in place (module documentation): all of them, or on an
    /// error none (the old outputs are restored). A declared file or folder that was not
    /// written is an error.
    pub fn commit(mut self) -> Result<()> {
        for o in &self.outputs {
            if matches!(o.kind, Kind::File | Kind::Dir) {
                let staged = self.staged_path(o);
                if staged.is_none_or(|p| p.symlink_metadata().is_err()) {
                    return Err(write_error(
                        &o.declared,
                        o.format,
                        "the run did not write it (nothing was put in place)",
                    ));
                }
            }
        }
        let mut dirs: Vec<PathBuf> = self.stages.iter().map(|s| s.dir.clone()).collect();
        dirs.sort();
        dirs.dedup();
        // Advisory locks on the target folders (sorted: no two committers deadlock);
        // released when dropped. Where a folder cannot be locked, commit unlocked.
        let _locks: Vec<File> = dirs
            .iter()
            .filter_map(|d| File::open(d).ok())
            .filter(|f| f.lock().is_ok())
            .collect();
        let mut undo: Vec<Undo> = Vec::new();
        let result = self.swap_in(&mut undo);
        if result.is_err() {
            for u in undo.into_iter().rev() {
                u.run();
            }
        }
        for d in &dirs {
            sync_dir(d);
        }
        result?;
        self.committed = true;
        self.clean_stages();
        Ok(())
    }

    fn staged_path(&self, o: &Output) -> Option<PathBuf> {
        let dir = parent_of(&o.target);
        let stage = self.stages.iter().find(|s| s.dir == dir)?;
        Some(stage.path.as_ref()?.join(o.target.file_name()?))
    }

    /// The renames of a commit, each recorded in `undo` once done.
    fn swap_in(&mut self, undo: &mut Vec<Undo>) -> Result<()> {
        // Old outputs first: files hard-linked aside (still in place), folders and stale
        // outputs moved aside.
        let mut backups: Vec<Option<PathBuf>> = Vec::with_capacity(self.outputs.len());
        for i in 0..self.outputs.len() {
            let (kind, target) = (self.outputs[i].kind, self.outputs[i].target.clone());
            let exists = target.symlink_metadata().is_ok();
            if kind == Kind::Special || !exists {
                backups.push(None);
                continue;
            }
            let stage = self.stage_of(&target)?;
            let old = stage.join(".olmap-old");
            if !old.exists() {
                std::fs::create_dir(&old).map_err(|e| Error::io(&old, e))?;
            }
            let backup = old.join(i.to_string());
            let io = |e| Error::io(&self.outputs[i].declared, e);
            if kind == Kind::File && std::fs::hard_link(&target, &backup).is_ok() {
                undo.push(Undo::Relink {
                    backup: backup.clone(),
                    target: target.clone(),
                });
            } else {
                std::fs::rename(&target, &backup).map_err(io)?;
                undo.push(Undo::Rename {
                    from: backup.clone(),
                    to: target.clone(),
                });
            }
            backups.push(Some(backup));
        }
        for (i, backup) in backups.iter().enumerate() {
            let o = &self.outputs[i];
            if !matches!(o.kind, Kind::File | Kind::Dir) {
                continue;
            }
            let staged = self.staged_path(o).expect("checked before");
            if o.kind == Kind::Dir && backup.is_none() && o.target.exists() {
                return Err(write_error(
                    &o.declared,
                    o.format,
                    "appeared during the run",
                ));
            }
            std::fs::rename(&staged, &o.target).map_err(|e| Error::io(&o.declared, e))?;
            undo.push(match (o.kind, backup) {
                (Kind::File, Some(_)) => Undo::Nothing,
                _ => Undo::Rename {
                    from: o.target.clone(),
                    to: staged,
                },
            });
        }
        Ok(())
    }

    /// Removes the staging folders (with the old outputs moved there).
    fn clean_stages(&mut self) {
        for s in &mut self.stages {
            if let Some(p) = s.path.take() {
                let _ = std::fs::remove_dir_all(&p);
            }
        }
    }
}

/// One step of a commit, as undone on failure.
enum Undo {
    /// A file was hard-linked to `backup` and then (maybe) replaced: put the old one back.
    Relink { backup: PathBuf, target: PathBuf },
    /// `to` was renamed to `from`: rename it back.
    Rename { from: PathBuf, to: PathBuf },
    /// Undone by an earlier step.
    Nothing,
}

impl Undo {
    fn run(self) {
        match self {
            Undo::Relink { backup, target } => {
                let _ = std::fs::rename(backup, target);
            }
            Undo::Rename { from, to } => {
                let _ = std::fs::rename(from, to);
            }
            Undo::Nothing => {}
        }
    }
}

impl Drop for OutputSet {
    fn drop(&mut self) {
        if self.committed {
            return;
        }
        self.clean_stages();
        for d in self.created.iter().rev() {
            let _ = std::fs::remove_dir(d);
        }
    }
}
