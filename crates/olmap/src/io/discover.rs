//! [`scan_files`]: the scan files named by paths, folders and list files.

use std::path::{Path, PathBuf};

use super::CloudFormat;
use crate::error::{Error, Result};
use crate::file::text::for_each_line;

/// Whether `p` is a file whose extension olmap reads as a point cloud (`.bz2` included).
pub fn is_cloud_file(p: &Path) -> bool {
    p.is_file()
        && p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
            CloudFormat::from_extension(e).is_some() || e.eq_ignore_ascii_case("bz2")
        })
}

/// The scan files of `paths` and `list`, in order:
/// * a file is taken as it is;
/// * a folder gives every cloud file in it ([`is_cloud_file`]), sorted by name; a folder
///   holding 3DTK `.3d` scans gives only those (it also holds `.pose`, `.frames` and text
///   files that are not scans);
/// * `list` is a text file of scan paths, one per line, relative to its own folder (`#`
///   comments and blank lines skipped).
///
/// Nothing at all is [`Error::EmptyInput`].
pub fn scan_files(paths: &[PathBuf], list: Option<&Path>) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut files: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| Error::io(p, e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| is_cloud_file(f))
                .collect();
            if files
                .iter()
                .any(|f| f.extension().is_some_and(|e| e == "3d"))
            {
                files.retain(|f| f.extension().is_some_and(|e| e == "3d"));
            }
            files.sort();
            out.extend(files);
        } else {
            out.push(p.clone());
        }
    }
    if let Some(list) = list {
        let base = list.parent().unwrap_or(Path::new("."));
        crate::file::parse_file(list, "scan list", |r| {
            for_each_line(r, |_, line| {
                let line = line.trim();
                if !line.is_empty() && !line.starts_with('#') {
                    out.push(base.join(line));
                }
                Ok(())
            })
        })?;
    }
    if out.is_empty() {
        return Err(Error::EmptyInput {
            what: "the scan list (no paths, folders or list file entries)".into(),
        });
    }
    Ok(out)
}
