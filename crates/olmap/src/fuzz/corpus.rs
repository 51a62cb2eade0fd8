//! The files the fuzzer mutates: the real samples of the shared data (cut to their first
//! lines where they are long text) and files written by olmap itself in every format and
//! encoding it writes.

use std::path::Path;

use nalgebra::{Point3, Vector3};

use super::targets::Target;
use crate::cloud::{LaserScan, PointCloud};
use crate::error::{Error, Result};
use crate::geometry::{Pose, PoseList, VoxelKey};
use crate::io::slam6d::{AlgoType, Frame};
use crate::io::{self, CloudFormat, PcdEncoding, PlyEncoding, WriteOptions};
use crate::occupancy::{MapFormat, OccupancyList};
use crate::scanner::{MirrorEvent, MirrorEventKind, MirrorGeometry, MirrorLog, Sweep};
use crate::team::{ScanStore, StoredScan, StoredSighting};

/// Lines kept of a long real text file: enough for headers and a few hundred records,
/// small enough that a case takes microseconds.
const HEAD_LINES: usize = 120;

/// A file to mutate and the reader that reads it.
#[derive(Debug, Clone)]
pub struct Sample {
    /// Where it comes from (`3dtk_dat/scan000.3d (first 120 lines)`, `olmap PCD binary`).
    pub name: String,
    /// The reader to feed it to.
    pub target: Target,
    /// The file's bytes.
    pub bytes: Vec<u8>,
    /// How often it is picked relative to the others (1 for most; less for the large
    /// whole real files, which take milliseconds a case).
    pub weight: f64,
}

impl Sample {
    fn new(name: impl Into<String>, target: Target, bytes: Vec<u8>) -> Self {
        Sample {
            name: name.into(),
            target,
            bytes,
            weight: 1.0,
        }
    }
}

/// The whole corpus: olmap's own files, and the real ones when `data` (the shared data
/// folder) is given. Every sample reads without error before mutation (checked by the
/// tests).
pub fn corpus(data: Option<&Path>) -> Result<Vec<Sample>> {
    let mut out = own_files()?;
    if let Some(dir) = data {
        out.extend(real_files(dir)?);
    }
    Ok(out)
}

/// Lines of a CARMEN log kept as a sample (a `FLASER` line holds 180 ranges).
#[cfg(feature = "gzip")]
const CARMEN_LINES: usize = 30;

/// The first `n` lines of a text.
fn head(bytes: &[u8], n: usize) -> Vec<u8> {
    let end = bytes
        .iter()
        .enumerate()
        .filter(|(_, &b)| b == b'\n')
        .nth(n.saturating_sub(1))
        .map_or(bytes.len(), |(i, _)| i + 1);
    bytes[..end].to_vec()
}

/// The real files of the shared data folder `dir`.
fn real_files(dir: &Path) -> Result<Vec<Sample>> {
    let read = |rel: &str| -> Result<Vec<u8>> {
        let path = dir.join(rel);
        std::fs::read(&path).map_err(|e| Error::io(path, e))
    };
    let cut = |rel: &str| format!("{rel} (first {HEAD_LINES} lines)");
    let mut out = Vec::new();
    for scan in ["scan000", "scan001"] {
        let rel = format!("3dtk_dat/{scan}.3d");
        out.push(Sample::new(
            cut(&rel),
            Target::Cloud(CloudFormat::Uos),
            head(&read(&rel)?, HEAD_LINES),
        ));
    }
    for rel in ["3dtk_dat/scan001.pose", "3dtk_dat/scan002.pose"] {
        out.push(Sample::new(rel, Target::Pose3dtk, read(rel)?));
    }
    for rel in [
        "3dtk_dat/scan001.frames",
        "3dtk_dat/frames_history/scan001.frames.cf17522d",
        "3dtk_dat/frames_history/scan001.frames.38966dfc",
    ] {
        out.push(Sample::new(rel, Target::Frames3dtk, read(rel)?));
    }
    #[cfg(feature = "gzip")]
    {
        use std::io::Read;
        let rel = "carmen_2d/intel-corrected.log.gz";
        let path = dir.join(rel);
        // The log readers' own decompression; the first 256 KiB hold the lines kept.
        let (stream, _, _) = io::open_text(&path)?;
        let mut text = Vec::new();
        stream
            .take(1 << 18)
            .read_to_end(&mut text)
            .map_err(|e| Error::io(path, e))?;
        out.push(Sample::new(
            format!("{rel} (first {CARMEN_LINES} lines)"),
            Target::CarmenLog,
            head(&text, CARMEN_LINES),
        ));
    }
    out.push(Sample::new(
        "3dtk_dat/reference_poses_rh_m.txt",
        Target::PoseList,
        read("3dtk_dat/reference_poses_rh_m.txt")?,
    ));
    out.push(Sample::new(
        "libpointmatcher_car/carCloudList.csv",
        Target::PoseTable,
        read("libpointmatcher_car/carCloudList.csv")?,
    ));
    for rel in [
        "libpointmatcher_car/car_cloud400.csv",
        "libpointmatcher_car/car_cloud401.csv",
    ] {
        out.push(Sample::new(
            cut(rel),
            Target::Cloud(CloudFormat::Csv),
            head(&read(rel)?, HEAD_LINES),
        ));
    }
    let scan_dat = head(&read("octomap_share_data/scan.dat")?, HEAD_LINES);
    out.push(Sample::new(
        cut("octomap_share_data/scan.dat"),
        Target::Cloud(CloudFormat::Xyz),
        scan_dat.clone(),
    ));
    #[cfg(feature = "bzip2")]
    out.push(Sample::new(
        format!("{} as .bz2", cut("octomap_share_data/scan.dat")),
        Target::Bzip2(CloudFormat::Xyz),
        bzip2(&scan_dat)?,
    ));
    let graph = read("octomap_share_data/spherical_scan.graph")?;
    // A cut copy: the first 200 points of the node (count patched), then its pose, id
    // and edges, so that mutations reach every part of the file in a short case.
    out.push(Sample::new(
        "octomap_share_data/spherical_scan.graph (first 200 points)",
        Target::Cloud(CloudFormat::ScanGraph),
        cut_graph(&graph, 200),
    ));
    let mut whole = Sample::new(
        "octomap_share_data/spherical_scan.graph",
        Target::Cloud(CloudFormat::ScanGraph),
        graph,
    );
    whole.weight = 0.05;
    out.push(whole);
    let mut bt = Sample::new(
        "octomap_share_data/geb079.bt",
        Target::Map(MapFormat::OctomapBt),
        read("octomap_share_data/geb079.bt")?,
    );
    bt.weight = 0.01;
    out.push(bt);
    // Recorded bags: uncompressed chunks (a CDR test bag, 2D scans of the Intel lab) and
    // zstd chunks (a talker, one file of a split bag).
    #[cfg(feature = "bag")]
    for (rel, weight) in [
        ("ros2_bags/cdr_test/cdr_test_0.mcap", 1.0),
        ("ros2_bags/talker/talker.mcap", 1.0),
        ("ros2_bags/wbag/wbag_0.mcap", 1.0),
        ("ros2_bags/intel_scans/intel_scans.mcap", 0.05),
    ] {
        let mut bag = Sample::new(rel, Target::McapBag, read(rel)?);
        bag.weight = weight;
        out.push(bag);
    }
    #[cfg(feature = "las")]
    for rel in ["las/autzen.las", "las/autzen.laz", "las/autzen.copc.laz"] {
        out.push(Sample::new(
            rel,
            Target::Cloud(CloudFormat::Las),
            read(rel)?,
        ));
    }
    Ok(out)
}

/// A one-node ScanGraph cut to its first `keep` points (the count patched): the layout
/// of `u32 nodes; u32 points; points x 28 bytes; pose 64 bytes; u32 id; u32 edges`.
fn cut_graph(graph: &[u8], keep: u32) -> Vec<u8> {
    let n = graph
        .get(4..8)
        .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    if n <= keep || graph.len() < 8 + 28 * n as usize {
        return graph.to_vec();
    }
    let mut out = graph[..4].to_vec();
    out.extend_from_slice(&keep.to_le_bytes());
    out.extend_from_slice(&graph[8..8 + 28 * keep as usize]);
    out.extend_from_slice(&graph[8 + 28 * n as usize..]);
    out
}

#[cfg(feature = "bzip2")]
fn bzip2(bytes: &[u8]) -> Result<Vec<u8>> {
    use std::io::Write;
    let mut enc = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::best());
    enc.write_all(bytes)
        .and_then(|_| enc.finish())
        .map_err(|e| Error::InvalidArgument(format!("bzip2 compression failed: {e}")))
}

/// A small cloud with every attribute and awkward values (a NaN point, huge and tiny
/// coordinates).
fn small_cloud() -> PointCloud {
    let n = 24;
    let mut points = Vec::with_capacity(n);
    let mut intensity = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(n);
    let mut colors = Vec::with_capacity(n);
    for i in 0..n {
        let t = i as f32;
        points.push(match i {
            0 => Point3::new(-0.0, 1e-40, 3.0e38),
            1 => Point3::new(1e-7, -123_456.79, 0.1),
            _ => Point3::new(t * 0.37 - 4.0, (t * 1.3).sin() * 6.0, t * 0.05),
        });
        intensity.push(t * 10.5);
        normals.push(Vector3::new(t.cos(), t.sin(), 0.0));
        colors.push([(i * 10) as u8, 255 - i as u8, 7]);
    }
    let mut cloud = PointCloud::from_points(points).with_origin(Point3::new(0.5, -0.25, 1.0));
    let attach = |r: Result<()>| r.expect("one attribute per point");
    attach(cloud.set_intensity(Some(intensity)));
    attach(cloud.set_normals(Some(normals)));
    attach(cloud.set_colors(Some(colors)));
    cloud
}

fn written(cloud: &PointCloud, format: CloudFormat, options: &WriteOptions) -> Result<Vec<u8>> {
    let mut buf = Vec::new();
    io::write_cloud_to(&mut buf, cloud, format, options)
        .map_err(|e| Error::InvalidArgument(format!("writing a {format} sample: {e}")))?;
    Ok(buf)
}

fn to_bytes(what: &str, f: impl FnOnce(&mut Vec<u8>) -> std::io::Result<()>) -> Result<Vec<u8>> {
    let mut buf = Vec::new();
    f(&mut buf).map_err(|e| Error::InvalidArgument(format!("writing a {what} sample: {e}")))?;
    Ok(buf)
}

/// Files written by olmap itself, in every format and encoding it writes.
fn own_files() -> Result<Vec<Sample>> {
    let cloud = small_cloud();
    let mut out = Vec::new();
    let plain = WriteOptions::default();
    for format in CloudFormat::ALL {
        if format == CloudFormat::Las {
            continue; // below: LAS cannot hold the cloud's 3e38 m point
        }
        out.push(Sample::new(
            format!("olmap {format}"),
            Target::Cloud(format),
            written(&cloud, format, &plain)?,
        ));
    }
    for (name, pcd_encoding) in [
        ("ascii", PcdEncoding::Ascii),
        ("binary_compressed", PcdEncoding::BinaryCompressed),
    ] {
        let options = WriteOptions {
            pcd_encoding,
            ..Default::default()
        };
        out.push(Sample::new(
            format!("olmap PCD {name}"),
            Target::Cloud(CloudFormat::Pcd),
            written(&cloud, CloudFormat::Pcd, &options)?,
        ));
    }
    #[cfg(feature = "las")]
    for laz in [false, true] {
        let in_range = cloud.select(|_, p| p.coords.iter().all(|v| v.abs() < 1e6));
        let options = WriteOptions {
            laz: Some(laz),
            ..Default::default()
        };
        out.push(Sample::new(
            if laz { "olmap LAZ" } else { "olmap LAS" },
            Target::Cloud(CloudFormat::Las),
            written(&in_range, CloudFormat::Las, &options)?,
        ));
    }
    let ascii_ply = WriteOptions {
        ply_encoding: PlyEncoding::Ascii,
        ..Default::default()
    };
    out.push(Sample::new(
        "olmap PLY ascii",
        Target::Cloud(CloudFormat::Ply),
        written(&cloud, CloudFormat::Ply, &ascii_ply)?,
    ));
    #[cfg(feature = "bzip2")]
    for format in [CloudFormat::Pcd, CloudFormat::Xyz, CloudFormat::KittiBin] {
        out.push(Sample::new(
            format!("olmap {format} as .bz2"),
            Target::Bzip2(format),
            bzip2(&written(&cloud, format, &plain)?)?,
        ));
    }
    let mut map = OccupancyList::new(0.1)?;
    for (i, p) in cloud.points().iter().enumerate().skip(2) {
        let key = VoxelKey::new(
            (p.x * 10.0) as i32,
            (p.y * 10.0) as i32,
            (p.z * 10.0) as i32,
        );
        map.set(key, 1 + (i % 7) as u32)?;
    }
    // Eight voxels filling one 2x2x2 block: the .bt writer prunes them into one leaf.
    for k in 0..8 {
        map.set(
            VoxelKey::new(40 + (k & 1), 40 + (k >> 1 & 1), 40 + (k >> 2)),
            3,
        )?;
    }
    out.push(Sample::new(
        "olmap .olm",
        Target::Map(MapFormat::Olm),
        to_bytes(".olm", |w| map.write_olm(w))?,
    ));
    let keys: Vec<VoxelKey> = map.sorted().into_iter().map(|(k, _)| k).collect();
    out.push(Sample::new(
        "olmap .bt",
        Target::Map(MapFormat::OctomapBt),
        to_bytes(".bt", |w| {
            crate::io::octomap_bt::write(w, map.resolution(), &keys).map(|_| ())
        })?,
    ));
    let mut poses = PoseList::default();
    for i in 0..4 {
        let f = i as f64;
        poses.push(
            format!("scan{i:03}"),
            Pose::from_xyz_ypr(f * 1.5, -f, 0.1 * f, 0.3 * f, 0.01, -0.02),
        );
    }
    out.push(Sample::new(
        "olmap pose list",
        Target::PoseList,
        to_bytes("pose list", |w| poses.write(w))?,
    ));
    out.push(Sample::new(
        "olmap CSV pose table",
        Target::PoseTable,
        to_bytes("pose table", |w| io::csv::write_pose_table(w, &poses))?,
    ));
    let pose = poses.poses[2].pose;
    out.push(Sample::new(
        "olmap 3DTK .pose",
        Target::Pose3dtk,
        to_bytes(".pose", |w| io::slam6d::write_pose(w, &pose))?,
    ));
    let frames: Vec<Frame> = poses
        .poses
        .iter()
        .zip([
            AlgoType::Icp,
            AlgoType::IcpInactive,
            AlgoType::Lum,
            AlgoType::Icp,
        ])
        .map(|(p, algo)| Frame {
            pose: p.pose,
            algo: Some(algo),
        })
        .collect();
    out.push(Sample::new(
        "olmap 3DTK .frames",
        Target::Frames3dtk,
        to_bytes(".frames", |w| io::slam6d::write_frames(w, &frames))?,
    ));
    let store_bytes = to_bytes("store", |w| store(&cloud, &poses)?.write_to(w))?;
    out.push(Sample::new(
        "olmap scan store",
        Target::Store,
        store_bytes.clone(),
    ));
    out.push(Sample::new(
        "olmap scan store",
        Target::StoreSalvage,
        store_bytes,
    ));
    out.push(Sample::new(
        "olmap mirror log",
        Target::MirrorLog,
        to_bytes("mirror log", |w| mirror_log().write(w))?,
    ));
    out.push(Sample::new(
        "CARMEN log",
        Target::CarmenLog,
        CARMEN_SAMPLE.as_bytes().to_vec(),
    ));
    #[cfg(feature = "bag")]
    out.extend(ros_messages(&cloud));
    #[cfg(feature = "bag")]
    {
        let bag = io::bag::MapBag {
            cloud: &cloud,
            poses: Some(&poses),
            stamp: io::bag::messages::Stamp::from_nanos(1_700_000_000_123_456_789),
        };
        let bytes = io::bag::map_mcap_bytes(&bag)
            .map_err(|e| Error::InvalidArgument(format!("the fuzzer's map bag: {e}")))?;
        out.push(Sample::new("olmap map bag", Target::McapBag, bytes));
    }
    let scan = laser_scan();
    out.push(Sample::new(
        "olmap laser scan CSV",
        Target::LaserScanCsv,
        to_bytes("laser scan CSV", |w| scan.write_csv(w))?,
    ));
    out.push(Sample::new(
        "olmap laser scan JSON",
        Target::LaserScanJson,
        to_bytes("laser scan JSON", |w| scan.write_json(w))?,
    ));
    Ok(out)
}

/// A store of two robots, with odometry, sightings and every point attribute.
fn store(cloud: &PointCloud, poses: &PoseList) -> std::io::Result<ScanStore> {
    let mut store = ScanStore::new();
    let invalid = |e: Error| std::io::Error::other(e.to_string());
    for (k, p) in poses.poses.iter().enumerate() {
        let robot = (k % 2) as u32;
        let sightings = if k == 1 {
            vec![StoredSighting {
                target: 0,
                range: 2.5,
                bearing: 0.3,
                elevation: -0.05,
                beacon: Point3::new(2.4, 0.7, 0.3),
                mutual: true,
            }]
        } else {
            Vec::new()
        };
        store
            .insert(StoredScan {
                robot,
                seq: k as u32,
                time: 1.5 * k as f64,
                odometry: (k != 2).then_some(p.pose),
                cloud: cloud.clone(),
                sightings,
            })
            .map_err(invalid)?;
    }
    store.set_robot_name(0, "alpha").map_err(invalid)?;
    Ok(store)
}

/// A raw log of a few sweeps and mirror events of the standard scanner.
fn mirror_log() -> MirrorLog {
    let header = MirrorGeometry {
        scan_beams: 5,
        ..MirrorGeometry::standard()
    };
    let mut sweeps = Vec::new();
    let mut events = Vec::new();
    for k in 0..4 {
        let t = 0.013 * k as f64;
        sweeps.push(Sweep {
            time: t,
            duration: 0.01,
            angle_min: header.scan_angle_min,
            angle_step: header.scan_angle_step,
            ranges: vec![2.5, f32::INFINITY, 3.25, 0.5, 7.9],
            intensities: (k % 2 == 0).then(|| vec![0.6, 0.0, 0.41, 1.0, 0.2]),
        });
        events.push(MirrorEvent {
            time: t + 0.002,
            kind: if k == 2 {
                MirrorEventKind::Trigger
            } else {
                MirrorEventKind::Tick
            },
        });
    }
    MirrorLog {
        header,
        sweeps,
        events,
    }
}

/// A CARMEN log as the shared logs write it: parameters, odometry, and front-laser scans
/// (`FLASER n r1..rn x y theta odom_x odom_y odom_theta time host logger_time`), one with
/// a beam at the no-return range.
const CARMEN_SAMPLE: &str = "\
# CARMEN Logfile
PARAM robot_front_laser_max 81.9 nohost 0
ODOM 0.0 0.0 0.0 0 0 0 1.0 nohost 1.0
FLASER 5 1.25 2.5 3.75 81.9 0.5 0.1 0.2 0.05 0.1 0.2 0.05 1.5 nohost 1.5
FLASER 5 1.2 2.4 3.7 4.9 0.55 0.4 0.2 0.06 0.4 0.2 0.06 2.5 nohost 2.5
";

/// A ROS 2 point cloud (the small cloud), laser scan and transform message, CDR-encoded
/// as a bag stores them.
#[cfg(feature = "bag")]
fn ros_messages(cloud: &PointCloud) -> Vec<Sample> {
    use io::bag::cdr::CdrWriter;
    use io::bag::messages::{encode_tf, Header, PointCloud2, Stamp, TransformStamped};
    let header = |frame: &str| Header {
        stamp: Stamp::from_nanos(1_700_000_000_123_456_789),
        frame_id: frame.into(),
    };
    let (fields, point_step, data) = io::bag::pointcloud2::encode_points(cloud);
    let n = cloud.len() as u32;
    let points = PointCloud2 {
        header: header("lidar"),
        height: 1,
        width: n,
        fields,
        is_bigendian: false,
        point_step,
        row_step: point_step * n,
        data: &data,
        is_dense: false,
    }
    .encode();
    let mut w = CdrWriter::new();
    w.i32(1_700_000_000);
    w.u32(5);
    w.string("laser");
    for v in [-1.5f32, 1.5, 0.75, 0.0, 0.1, 0.05, 30.0] {
        w.f32(v);
    }
    let ranges = [1.0f32, f32::INFINITY, 2.5, 40.0, f32::NAN];
    w.u32(ranges.len() as u32);
    ranges.iter().for_each(|&r| w.f32(r));
    w.u32(ranges.len() as u32);
    ranges.iter().for_each(|_| w.f32(100.0));
    let scan = w.finish();
    let tf = encode_tf(&[
        TransformStamped {
            header: header("map"),
            child_frame_id: "odom".into(),
            transform: Pose::from_xyz_ypr(1.0, -2.0, 0.1, 0.3, 0.0, 0.0),
        },
        TransformStamped {
            header: header("odom"),
            child_frame_id: "base_link".into(),
            transform: Pose::identity(),
        },
    ]);
    vec![
        Sample::new("ROS 2 PointCloud2", Target::PointCloud2Message, points),
        Sample::new("ROS 2 LaserScan", Target::LaserScanMessage, scan),
        Sample::new("ROS 2 TFMessage", Target::TfMessage, tf),
    ]
}

/// A 2D scan with intensities and a beam without return.
fn laser_scan() -> LaserScan {
    LaserScan {
        angle_min: -std::f64::consts::FRAC_PI_2,
        angle_increment: 20f64.to_radians(),
        range_min: 0.05,
        range_max: 8.0,
        ranges: vec![2.5, f32::INFINITY, 3.25, 0.5, 7.9, 1.0, 1.25, 4.0, 6.5, 0.3],
        intensities: Some(vec![0.6, 0.0, 0.41, 1.0, 0.2, 0.3, 0.9, 0.1, 0.5, 0.7]),
        time: 12.5,
    }
}
