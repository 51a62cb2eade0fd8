//! Scan inputs from files: reading the clouds and matching odometry to them.

use std::path::PathBuf;

use super::ScanInput;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::io::{self, file_stem_name, slam6d, ReadOptions};
use crate::progress::{Progress, Stage};

/// Where the odometry of scan files comes from.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum OdometrySource {
    /// No odometry.
    #[default]
    None,
    /// Each scan's sibling 3DTK `.pose` file (`scan000.3d` -> `scan000.pose`).
    Sidecar3dtk,
    /// A pose file of any kind [`io::read_poses`] reads, matched to the scans by name
    /// (file stem) or, when it holds exactly one pose per scan, in order.
    File(PathBuf),
}

/// The odometry `T_world_scan` of each scan file (`None` everywhere without a source).
/// A scan without a pose in the file is [`Error::NotFound`].
pub fn odometry_for(source: &OdometrySource, paths: &[PathBuf]) -> Result<Vec<Option<Pose>>> {
    match source {
        OdometrySource::None => Ok(vec![None; paths.len()]),
        OdometrySource::Sidecar3dtk => paths
            .iter()
            .map(|p| Ok(Some(slam6d::read_pose_path(p.with_extension("pose"))?)))
            .collect(),
        OdometrySource::File(file) => {
            let list = io::read_poses(file)?;
            let by_order = list.len() == paths.len();
            paths
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let name = file_stem_name(p);
                    let found = list
                        .get(&name)
                        .or_else(|| by_order.then(|| &list.poses[i].pose));
                    found.copied().map(Some).ok_or_else(|| Error::NotFound {
                        what: format!("{}: an odometry pose for {name}", file.display()),
                    })
                })
                .collect()
        }
    }
}

/// Reads every scan file with its odometry into a [`ScanInput`] named by its file stem,
/// reporting [`Stage::Read`] progress.
pub fn read_scan_inputs(
    paths: &[PathBuf],
    odometry: Vec<Option<Pose>>,
    read: &ReadOptions,
    progress: Progress<'_>,
) -> Result<Vec<ScanInput>> {
    let mut scans = Vec::with_capacity(paths.len());
    for (i, (p, o)) in paths.iter().zip(odometry).enumerate() {
        scans.push(ScanInput {
            name: file_stem_name(p),
            cloud: io::read_cloud_with(p, read)?.cloud,
            odometry: o,
        });
        progress(Stage::Read, i + 1, paths.len());
    }
    Ok(scans)
}

/// The scans of a ROS 2 bag extraction as mapping inputs, named as
/// [`crate::io::bag::write_extraction`] names their files (the message's index on its topic),
/// with their odometry.
#[cfg(feature = "bag")]
pub fn bag_scan_inputs(ex: &crate::io::bag::Extraction) -> Vec<ScanInput> {
    ex.scans
        .iter()
        .map(|s| ScanInput {
            name: s.name.clone(),
            cloud: s.cloud.clone(),
            odometry: s.odometry,
        })
        .collect()
}

/// The index of the scan named `name` (a file stem).
pub fn scan_index(scans: &[ScanInput], name: &str) -> Result<usize> {
    scans
        .iter()
        .position(|s| s.name == name)
        .ok_or_else(|| Error::NotFound {
            what: format!("a scan named {name}"),
        })
}
