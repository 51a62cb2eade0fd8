//! [`read_poses`]: pose files of any kind olmap knows, told apart by extension.

use std::path::Path;

use super::{csv, slam6d};
use crate::error::{Error, ParseError, Result};
use crate::geometry::PoseList;

/// The name a file gives the scan or pose it holds: its file stem (`scan000.3d` ->
/// `scan000`).
pub fn file_stem_name(path: &Path) -> String {
    path.file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}

/// Reads the poses of any supported pose file, by extension: 3DTK `.pose` (one pose named
/// by the file stem), 3DTK `.frames` (the final frame, named by the file stem), CSV pose
/// tables (`.csv`, libpointmatcher's `carCloudList.csv`), CARMEN logs (`.log`, `.log.gz`:
/// the `FLASER` poses, named `scan000000`, …; see [`super::carmen`]), and otherwise an olmap pose list
/// (name + row-major 3x4 of `T_map_scan` per line; KITTI `poses.txt` too). Everything in
/// right-handed metres.
///
/// ```
/// use olmap::geometry::{Pose, PoseList};
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("poses.txt");
/// let mut list = PoseList::default();
/// list.push("scan000", Pose::from_xyz_ypr(1.0, 0.0, 0.0, 0.0, 0.0, 0.0));
/// list.write_path(&path).unwrap();
/// let back = olmap::io::read_poses(&path).unwrap();
/// assert_eq!(back.len(), 1);
/// assert!(back.get("scan000").is_some());
/// ```
pub fn read_poses(path: impl AsRef<Path>) -> Result<PoseList> {
    read_poses_with(path, false)
}

/// [`read_poses`], with every frame of a `.frames` file when `all_frames` (named
/// `STEM#i`) instead of only the final one.
pub fn read_poses_with(path: impl AsRef<Path>, all_frames: bool) -> Result<PoseList> {
    let path = path.as_ref();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let mut list = PoseList::default();
    let stem = || {
        path.file_stem()
            .map_or_else(|| "pose".into(), |s| s.to_string_lossy().into_owned())
    };
    if super::carmen::is_carmen_path(path) {
        return Ok(super::carmen::read_carmen(path)?.poses());
    }
    match ext.as_str() {
        "pose" => list.push(stem(), slam6d::read_pose_path(path)?),
        "frames" => {
            let frames = slam6d::read_frames_path(path)?;
            if all_frames {
                for (i, f) in frames.iter().enumerate() {
                    list.push(format!("{}#{i}", stem()), f.pose);
                }
            } else {
                let last = frames.last().ok_or_else(|| Error::Read {
                    path: path.to_path_buf(),
                    format: "3DTK .frames",
                    source: ParseError::Empty,
                })?;
                list.push(stem(), last.pose);
            }
        }
        "csv" => list.poses.extend(csv::read_pose_table_path(path)?.poses),
        _ => list.poses.extend(PoseList::read_path(path)?.poses),
    }
    Ok(list)
}
