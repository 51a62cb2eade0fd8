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
    /// A CARMEN 2D laser log's text ([`io::carmen::parse_carmen`]), then every scan's
    /// points.
    CarmenLog,
    /// A ROS 2 `sensor_msgs/PointCloud2` message as a bag stores it (CDR), decoded
    /// ([`io::bag::messages::PointCloud2::decode`]) and its points read
    /// ([`io::bag::pointcloud2::decode_points`]).
    #[cfg(feature = "bag")]
    PointCloud2Message,
    /// A ROS 2 `sensor_msgs/LaserScan` message (CDR,
    /// [`io::bag::messages::LaserScan::decode`]).
    #[cfg(feature = "bag")]
    LaserScanMessage,
    /// A ROS 2 `tf2_msgs/TFMessage` (CDR, [`io::bag::messages::decode_tf`]).
    #[cfg(feature = "bag")]
    TfMessage,
    /// A whole MCAP bag file, summarised as `olmap bag info` does ([`io::bag::bag_info`]:
    /// the container with its chunks, CRCs and decompression, every schema parsed, every
    /// message decoded from its schema). A file whose reading stopped at damage counts as
    /// refused.
    #[cfg(feature = "bag")]
    McapBag,
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
            Target::CarmenLog => "CARMEN log".into(),
            #[cfg(feature = "bag")]
            Target::PointCloud2Message => "ROS 2 PointCloud2".into(),
            #[cfg(feature = "bag")]
            Target::LaserScanMessage => "ROS 2 LaserScan".into(),
            #[cfg(feature = "bag")]
            Target::TfMessage => "ROS 2 TFMessage".into(),
            #[cfg(feature = "bag")]
            Target::McapBag => "ROS 2 bag (MCAP)".into(),
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
            Target::CarmenLog => {
                let log = io::carmen::parse_carmen(bytes)?;
                Ok(log
                    .scans
                    .iter()
                    .map(|s| s.points(log.max_range, 0.0).len())
                    .sum())
            }
            #[cfg(feature = "bag")]
            Target::PointCloud2Message => {
                use io::bag::{messages::PointCloud2, pointcloud2::decode_points};
                let message = PointCloud2::decode(bytes).map_err(cdr)?;
                let decoded = decode_points(&message).map_err(ParseError::Malformed)?;
                Ok(decoded.cloud.len())
            }
            #[cfg(feature = "bag")]
            Target::LaserScanMessage => Ok(io::bag::messages::LaserScan::decode(bytes)
                .map_err(cdr)?
                .ranges
                .len()),
            #[cfg(feature = "bag")]
            Target::TfMessage => Ok(io::bag::messages::decode_tf(bytes).map_err(cdr)?.len()),
            #[cfg(feature = "bag")]
            Target::McapBag => {
                let info = io::bag::bag_info_of_bytes(bytes, std::path::Path::new("fuzz.mcap"))
                    .map_err(|e| ParseError::Malformed(e.to_string()))?;
                match info.stopped_early {
                    Some(why) => Err(ParseError::Malformed(why)),
                    None => Ok(info.messages as usize),
                }
            }
        }
    }
}

/// A CDR decoding error as a parse error.
#[cfg(feature = "bag")]
fn cdr(e: io::bag::cdr::CdrError) -> ParseError {
    ParseError::Malformed(e.to_string())
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
