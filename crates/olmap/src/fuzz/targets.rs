//! The readers the fuzzer drives: every file format olmap reads, each from a byte slice
//! through the same stream function its path-level reader uses.

use crate::cloud::LaserScan;
use crate::error::ParseError;
use crate::geometry::PoseList;
use crate::io::{self, CloudFormat, ReadOptions};
use crate::occupancy::{self, MapFormat};
use crate::scanner::MirrorLog;
use crate::team::ScanStore;

/// One reader of one file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// A point-cloud format through [`io::read_cloud_from`], then the cloud's statistics
    /// (what `olmap info` computes).
    Cloud(CloudFormat),
    /// A bzip2-compressed point cloud through [`io::read_bzip2_cloud_from`].
    Bzip2(CloudFormat),
    /// A map file through [`occupancy::read_map_from`] (`.olm`, OctoMap `.bt`).
    Map(MapFormat),
    /// olmap's pose list ([`PoseList::read`]).
    PoseList,
    /// libpointmatcher's pose table `carCloudList.csv` ([`io::csv::read_pose_table`]).
    PoseTable,
    /// A 3DTK `.pose` file ([`io::slam6d::read_pose`]).
    Pose3dtk,
    /// A 3DTK `.frames` file ([`io::slam6d::read_frames`]).
    Frames3dtk,
    /// A scan store ([`ScanStore::read_from`]).
    Store,
    /// A scan store read by the salvage reader ([`ScanStore::salvage_from`]), which must
    /// take any damage without panicking.
    StoreSalvage,
    /// A rotating-mirror scanner's raw log ([`MirrorLog::read`]).
    MirrorLog,
    /// A 2D laser scan as CSV ([`LaserScan::read_csv`]), then its points.
    LaserScanCsv,
    /// A 2D laser scan as JSON ([`LaserScan::read_json`]), then its points.
    LaserScanJson,
}

impl Target {
    /// A short name for reports (`PCD`, `bzip2 XYZ text`, `OctoMap .bt`, ...).
    pub fn name(self) -> String {
        match self {
            Target::Cloud(f) => f.name().to_string(),
            Target::Bzip2(f) => format!("bzip2 {}", f.name()),
            Target::Map(m) => m.name().to_string(),
            Target::PoseList => "pose list".into(),
            Target::PoseTable => "CSV pose table".into(),
            Target::Pose3dtk => "3DTK .pose".into(),
            Target::Frames3dtk => "3DTK .frames".into(),
            Target::Store => "scan store".into(),
            Target::StoreSalvage => "scan store salvage".into(),
            Target::MirrorLog => "mirror log".into(),
            Target::LaserScanCsv => "laser scan CSV".into(),
            Target::LaserScanJson => "laser scan JSON".into(),
        }
    }

    /// Reads `bytes` as this target's format; `Ok` holds how many items (points, voxels,
    /// poses, scans, records) the reader returned.
    pub fn read(self, bytes: &[u8]) -> Result<usize, ParseError> {
        match self {
            Target::Cloud(format) => {
                let options = ReadOptions {
                    // Also run the 3DTK validity filter (it computes ranges of every point).
                    uos_valid_only: format == CloudFormat::Uos,
                    ..Default::default()
                };
                let loaded = io::read_cloud_from(bytes, format, &options)?;
                let _ = loaded.cloud.stats();
                Ok(loaded.cloud.len())
            }
            Target::Bzip2(format) => bzip2(bytes, format),
            Target::Map(format) => Ok(occupancy::read_map_from(bytes, format)?.map.len()),
            Target::PoseList => Ok(PoseList::read(bytes)?.len()),
            Target::PoseTable => Ok(io::csv::read_pose_table(bytes)?.len()),
            Target::Pose3dtk => io::slam6d::read_pose(bytes).map(|_| 1),
            Target::Frames3dtk => Ok(io::slam6d::read_frames(bytes)?.len()),
            Target::Store => Ok(ScanStore::read_from(bytes)?.len()),
            Target::StoreSalvage => Ok(ScanStore::salvage_from(bytes)?.0.len()),
            Target::MirrorLog => {
                let log = MirrorLog::read(bytes)?;
                Ok(log.sweeps.len() + log.events.len())
            }
            Target::LaserScanCsv => Ok(LaserScan::read_csv(bytes)?.to_cloud().len()),
            Target::LaserScanJson => Ok(LaserScan::read_json(bytes)?.to_cloud().len()),
        }
    }
}

#[cfg(feature = "bzip2")]
fn bzip2(bytes: &[u8], format: CloudFormat) -> Result<usize, ParseError> {
    let loaded =
        io::read_bzip2_cloud_from(bytes, bytes.len() as u64, format, &ReadOptions::default())?;
    let _ = loaded.cloud.stats();
    Ok(loaded.cloud.len())
}

#[cfg(not(feature = "bzip2"))]
fn bzip2(_bytes: &[u8], _format: CloudFormat) -> Result<usize, ParseError> {
    Err(ParseError::Unsupported(
        "olmap was built without the `bzip2` feature".into(),
    ))
}
