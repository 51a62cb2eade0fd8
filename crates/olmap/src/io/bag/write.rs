//! Writing MCAP files Foxglove and the rosbag2 tools open: a map as `PointCloud2`, scan
//! poses as `nav_msgs/Path` and `/tf`.

use std::io::{Seek, Write};
use std::path::Path;

use super::messages::{
    encode_path, encode_tf, schemas, Header, PointCloud2, PoseStamped, Stamp, TransformStamped,
};
use super::pointcloud2::encode_points;
use crate::cloud::PointCloud;
use crate::error::Result;
use crate::geometry::PoseList;

/// What to write into a map bag.
#[derive(Debug, Clone)]
pub struct MapBag<'a> {
    /// The map's points (voxel centres; intensity = count) in frame `map`.
    pub cloud: &'a PointCloud,
    /// Scan poses `T_map_scan`, written as one `nav_msgs/Path` per robot (the name's part
    /// before `/`, or one path) on `/olmap/path`, and as `/tf` transforms `map -> NAME`.
    pub poses: Option<&'a PoseList>,
    /// The stamp of every message (default: 0 = the epoch).
    pub stamp: Stamp,
}

/// Writes `map` as an MCAP file (zstd chunks): `/olmap/map` (`sensor_msgs/msg/PointCloud2`,
/// frame `map`), and with poses `/olmap/path` (`nav_msgs/msg/Path`, one message per robot)
/// and `/tf` (`tf2_msgs/msg/TFMessage`, one transform `map -> scan name` per pose, `/`
/// replaced by `_` in frame names). The file appears complete or not at all.
pub fn write_map_mcap(path: &Path, map: &MapBag<'_>) -> Result<()> {
    crate::file::write_atomic(path, "MCAP", |file| write_map(file, map))
}

/// The bytes [`write_map_mcap`] writes (the fuzzer's sample of olmap's own bags).
#[cfg(any(test, feature = "test-support"))]
pub(crate) fn map_mcap_bytes(map: &MapBag<'_>) -> std::io::Result<Vec<u8>> {
    let mut out = std::io::Cursor::new(Vec::new());
    write_map(&mut out, map)?;
    Ok(out.into_inner())
}

/// Writes `map` as MCAP to `out`.
fn write_map<W: Write + Seek>(out: W, map: &MapBag<'_>) -> std::io::Result<()> {
    {
        let e = |err: mcap::McapError| std::io::Error::other(err.to_string());
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("ros2")
            .library(concat!("olmap ", env!("CARGO_PKG_VERSION")))
            .create(out)
            .map_err(e)?;
        let t = map.stamp.nanos().max(0) as u64;
        let header = Header {
            stamp: map.stamp,
            frame_id: "map".into(),
        };
        let put = |w: &mut mcap::Writer<_>, topic: &str, ty: &str, schema: &str, data: &[u8]| {
            let sid = w.add_schema(ty, "ros2msg", schema.as_bytes())?;
            let cid = w.add_channel(sid, topic, "cdr", &Default::default())?;
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: cid,
                    sequence: 0,
                    log_time: t,
                    publish_time: t,
                },
                data,
            )
        };
        let (fields, step, data) = encode_points(map.cloud);
        let n = map.cloud.len() as u32;
        let pc = PointCloud2 {
            header: header.clone(),
            height: 1,
            width: n,
            fields,
            is_bigendian: false,
            point_step: step,
            row_step: step * n,
            data: &data,
            is_dense: true,
        };
        put(
            &mut w,
            "/olmap/map",
            "sensor_msgs/msg/PointCloud2",
            &schemas::point_cloud2(),
            &pc.encode(),
        )
        .map_err(e)?;
        if let Some(poses) = map.poses {
            let mut robots: Vec<(String, Vec<PoseStamped>)> = Vec::new();
            let mut tfs = Vec::new();
            for p in &poses.poses {
                let robot = p.name.split_once('/').map_or("", |(r, _)| r).to_string();
                let stamped = PoseStamped {
                    header: header.clone(),
                    pose: p.pose,
                };
                match robots.iter_mut().find(|(r, _)| *r == robot) {
                    Some((_, v)) => v.push(stamped),
                    None => robots.push((robot, vec![stamped])),
                }
                tfs.push(TransformStamped {
                    header: header.clone(),
                    child_frame_id: p.name.replace('/', "_"),
                    transform: p.pose,
                });
            }
            let path_schema = schemas::path();
            for (_, poses) in &robots {
                put(
                    &mut w,
                    "/olmap/path",
                    "nav_msgs/msg/Path",
                    &path_schema,
                    &encode_path(&header, poses),
                )
                .map_err(e)?;
            }
            put(
                &mut w,
                "/tf",
                "tf2_msgs/msg/TFMessage",
                &schemas::tf_message(),
                &encode_tf(&tfs),
            )
            .map_err(e)?;
        }
        w.finish().map_err(e)?;
        Ok(())
    }
}
