//! ROS 2 bags (data README §6): every fixture reads and decodes to what independent readers
//! (Python `mcap` and `rosbags`, `tests/data/bags/make_expected.py`) decode; the real-scan
//! bags give the very scans and odometry of the original files; mapping from a bag equals
//! mapping from its extracted folder; damaged and lying bags are typed errors naming the
//! topic and message; a written map bag reads back.

use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};
use olmap::cloud::PointCloud;
use olmap::geometry::Pose;
use olmap::io::bag::messages::{Header, PointCloud2, PointField, Stamp};
use olmap::io::bag::{
    bag_info, dynamic, extract_scans, write_extraction, write_map_mcap, Bag, ExtractOptions,
    MapBag, ScanSpec,
};

fn bags() -> Option<PathBuf> {
    crate::data().map(|d| d.join("ros2_bags"))
}

fn expected() -> serde_json::Value {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bags/expected.json");
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

#[test]
fn every_fixture_has_the_topics_counts_and_stamps_the_mcap_reference_reads() {
    let Some(dir) = bags() else { return };
    let exp = expected();
    for (name, e) in exp.as_object().unwrap() {
        let bag = Bag::open(dir.join(name)).unwrap();
        let info = bag_info(&bag).unwrap();
        assert!(
            info.stopped_early.is_none(),
            "{name}: {:?}",
            info.stopped_early
        );
        assert!(info.problems.is_empty(), "{name}: {:?}", info.problems);
        let topics = e["topics"].as_array().unwrap();
        assert_eq!(info.topics.len(), topics.len(), "{name}");
        for (got, want) in info.topics.iter().zip(topics) {
            assert_eq!(got.name, want["name"], "{name}");
            assert_eq!(got.type_name, want["type"], "{name}");
            assert_eq!(
                got.count,
                want["count"].as_u64().unwrap(),
                "{name} {}",
                got.name
            );
            let first = want["first_log_time_ns"].as_u64().unwrap() as f64 * 1e-9;
            let last = want["last_log_time_ns"].as_u64().unwrap() as f64 * 1e-9;
            assert!(
                (got.first_stamp - first).abs() < 1e-6,
                "{name} {}",
                got.name
            );
            assert!((got.last_stamp - last).abs() < 1e-6, "{name} {}", got.name);
        }
    }
    // The split bag: five files, read in order.
    assert_eq!(Bag::open(dir.join("wbag")).unwrap().files.len(), 5);
}

#[test]
fn every_cdr_primitive_and_array_decodes_to_what_rosbags_decodes() {
    let Some(dir) = bags() else { return };
    let exp = expected();
    for name in ["cdr_test", "talker", "wbag"] {
        let bag = Bag::open(dir.join(name)).unwrap();
        let mut decoded: std::collections::BTreeMap<String, Vec<serde_json::Value>> =
            Default::default();
        bag.for_each_message(|m| {
            let wanted = name == "cdr_test" || m.type_name == "std_msgs/msg/String";
            if wanted {
                let defs = m.schema.unwrap().defs().unwrap();
                let v = dynamic::decode(defs, m.data).map_err(|e| m.error(e.to_string()))?;
                decoded.entry(m.topic.into()).or_default().push(v.to_json());
            }
            Ok(true)
        })
        .unwrap();
        if name == "cdr_test" {
            let want = exp[name]["messages"].as_object().unwrap();
            assert_eq!(decoded.len(), want.len());
            for (topic, msgs) in want {
                let got = &decoded[topic];
                assert_eq!(got.len(), msgs.as_array().unwrap().len(), "{topic}");
                for (k, (g, w)) in got.iter().zip(msgs.as_array().unwrap()).enumerate() {
                    same(g, w, &format!("{name} {topic} message {k}"));
                }
            }
        } else {
            let want = exp[name]["first_and_last"].as_object().unwrap();
            assert_eq!(decoded.len(), want.len(), "{name}");
            for (topic, fl) in want {
                let got = &decoded[topic];
                assert_eq!(&got[0], &fl[0], "{name} {topic}");
                assert_eq!(got.last().unwrap(), &fl[1], "{name} {topic}");
            }
        }
    }
}

/// `got` (olmap) equals `want` (rosbags) up to two documented differences of
/// representation: rosbags lists a message's constants (upper-case names) and the
/// placeholder byte of an empty message (`structure_needs_at_least_one_member`) as fields,
/// which are not on the wire as fields; and it reads `byte` (IDL `octet`, unsigned in
/// rosidl) as signed, so `byte` values compare modulo 256.
fn same(got: &serde_json::Value, want: &serde_json::Value, at: &str) {
    use serde_json::Value as J;
    match (got, want) {
        (J::Object(g), J::Object(w)) => {
            let fields: Vec<_> = w
                .iter()
                .filter(|(k, _)| {
                    *k != "structure_needs_at_least_one_member"
                        && !k
                            .chars()
                            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
                })
                .collect();
            assert_eq!(
                g.len(),
                fields.len(),
                "{at}: fields {:?} vs {:?}",
                g.keys(),
                w.keys()
            );
            for (k, wv) in fields {
                same(&g[k], wv, &format!("{at}.{k}"));
            }
        }
        (J::Array(g), J::Array(w)) => {
            assert_eq!(g.len(), w.len(), "{at}");
            for (i, (a, b)) in g.iter().zip(w).enumerate() {
                same(a, b, &format!("{at}[{i}]"));
            }
        }
        (J::Number(a), J::Number(b)) if at.contains("byte_value") => {
            assert_eq!(
                a.as_i64().unwrap(),
                b.as_i64().unwrap().rem_euclid(256),
                "{at}"
            );
        }
        _ => assert_eq!(got, want, "{at}"),
    }
}

#[test]
fn the_3dtk_bag_holds_the_3dtk_scans_and_their_odometry() {
    let Some(dir) = bags() else { return };
    let bag = Bag::open(dir.join("3dtk_points")).unwrap();
    let ex = extract_scans(&bag, &ExtractOptions::default()).unwrap();
    assert_eq!(ex.topic, "/points");
    assert_eq!(ex.odometry_source.as_deref(), Some("/odom"));
    assert_eq!(ex.scans.len(), 3);
    let tdir = olmap::test_data::threedtk_dir().unwrap();
    for (i, s) in ex.scans.iter().enumerate() {
        // The writer converted the valid returns to right-handed metres in f64 and stored
        // f32: olmap's own .3d reader must give the same points to f32 rounding (2 µm at
        // 30 m).
        let file = olmap::test_data::threedtk_scan(i, true).unwrap();
        assert_eq!(s.cloud.len(), file.len(), "scan {i}");
        let worst = s
            .cloud
            .points()
            .iter()
            .zip(file.points())
            .map(|(a, b)| (a - b).abs().max())
            .fold(0.0f32, f32::max);
        assert!(worst <= 2e-6, "scan {i}: {worst} m");
        assert_eq!(s.frame, "laser");
        // T_odom_laser = the scan's .pose odometry (data README §6).
        let pose =
            olmap::io::slam6d::read_pose_path(tdir.join(format!("scan{i:03}.pose"))).unwrap();
        let o = s.odometry.unwrap();
        assert!(
            (o.translation() - pose.translation()).norm() < 1e-9,
            "scan {i}"
        );
        assert!(o.rotation().angle_to(&pose.rotation()) < 1e-9, "scan {i}");
    }
    // In base_link: the mount (0.20, 0, 0.50) m moves every point and the sensor origin.
    let opts = ExtractOptions {
        frame: Some("base_link".into()),
        max: Some(1),
        ..Default::default()
    };
    let b = extract_scans(&bag, &opts).unwrap();
    let s = &b.scans[0];
    assert_eq!(s.frame, "base_link");
    assert_eq!(s.cloud.origin(), Point3::new(0.2, 0.0, 0.5));
    let d = s.cloud.points()[10] - ex.scans[0].cloud.points()[10];
    assert!((d - Vector3::new(0.2f32, 0.0, 0.5)).norm() < 1e-6);
    // The odometry is then that of base_link: T_odom_base = T_odom_laser · mount⁻¹.
    let mount = Pose::from_translation(Vector3::new(0.2, 0.0, 0.5));
    let want = ex.scans[0].odometry.unwrap() * mount.inverse();
    assert!((s.odometry.unwrap().translation() - want.translation()).norm() < 1e-9);
    // BAG#TOPIC@INDEX names one scan for every command that reads clouds.
    let spec = format!("{}#/points@2", dir.join("3dtk_points").display());
    let one = olmap::io::read_cloud(&spec).unwrap();
    assert_eq!(one.cloud.points(), ex.scans[2].cloud.points());
    let bad = ScanSpec::parse(&format!("{}#/points@3", dir.join("3dtk_points").display()));
    let e = bad.unwrap().read().unwrap_err().to_string();
    assert!(e.contains("no message 3 on topic '/points'"), "{e}");
}

#[test]
fn aligning_and_mapping_from_the_bag_equal_the_same_from_files() {
    let Some(dir) = bags() else { return };
    let bag = Bag::open(dir.join("3dtk_points")).unwrap();
    // The scans in the laser frame are the .3d scans bit for bit: any registration of them
    // gives the same pose as on the files.
    let ex = extract_scans(&bag, &ExtractOptions::default()).unwrap();
    for (i, s) in ex.scans.iter().enumerate() {
        assert_eq!(
            s.cloud.points(),
            olmap::test_data::threedtk_scan(i, true).unwrap().points()
        );
    }
    // Map from the bag and from its extracted folder: the same map file.
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("extracted");
    let report = write_extraction(&bag, &ExtractOptions::default(), &out).unwrap();
    assert_eq!(report.scans, 3);
    let mut files: Vec<PathBuf> = std::fs::read_dir(out.join("scans"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    let job = |output: PathBuf, scans: Vec<PathBuf>| olmap::mapping::MapJob {
        scans,
        odometry: olmap::mapping::OdometrySource::File(out.join("odometry.txt")),
        read: Default::default(),
        first: None,
        params: olmap::mapping::MapParams::default(),
        output,
        poses_out: None,
        free_space_out: None,
        scans_out: None,
        report: None,
        graph_out: None,
    };
    let from_files =
        olmap::mapping::run_map_job(&job(tmp.path().join("a.olm"), files), &mut |_, _, _| {})
            .unwrap();
    let from_bag = olmap::mapping::run_map_job_on(
        &job(tmp.path().join("b.olm"), Vec::new()),
        olmap::mapping::bag_scan_inputs(&ex),
        &mut |_, _, _| {},
    )
    .unwrap();
    assert_eq!(from_bag.build.placed.len(), 3);
    assert_eq!(
        std::fs::read(tmp.path().join("a.olm")).unwrap(),
        std::fs::read(tmp.path().join("b.olm")).unwrap()
    );
    for (a, b) in from_files.build.placed.iter().zip(&from_bag.build.placed) {
        assert_eq!(a.name, b.name);
        assert!((a.pose.translation() - b.pose.translation()).norm() < 1e-9);
    }
}

#[test]
fn the_intel_bag_holds_the_carmen_log_scans_and_poses() {
    let Some(dir) = bags() else { return };
    let log = olmap::io::carmen::read_carmen(
        crate::data()
            .unwrap()
            .join("carmen_2d/intel-corrected.log.gz"),
    )
    .unwrap();
    let bag = Bag::open(dir.join("intel_scans")).unwrap();
    let ex = extract_scans(&bag, &ExtractOptions::default()).unwrap();
    assert_eq!(ex.type_name, "sensor_msgs/msg/LaserScan");
    assert_eq!(ex.scans.len(), 300);
    for (s, l) in ex.scans.iter().zip(&log.scans) {
        let laser = s.laser.as_ref().unwrap();
        assert_eq!(laser.ranges, l.ranges, "{}", s.name);
        let o = s.odometry.unwrap();
        let t = o.translation();
        let (yaw, _, _) = o.yaw_pitch_roll();
        assert!(
            (t.x - l.pose[0]).abs() < 1e-9 && (t.y - l.pose[1]).abs() < 1e-9,
            "{}",
            s.name
        );
        let dyaw = (yaw - l.pose[2] + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        assert!(dyaw.abs() < 1e-9, "{}", s.name);
        // The stamp is the log's time stamp (ns rounding).
        assert!((s.stamp.seconds() - l.time).abs() < 1e-6, "{}", s.name);
    }
}

/// A one-file bag with a `PointCloud2` topic holding the given messages, written with the
/// `mcap` crate.
fn write_bag(path: &Path, clouds: &[Vec<u8>], extra_type: Option<(&str, &str)>) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    // One uncompressed chunk per message (each with its CRC), so damage stays in one
    // message's chunk.
    let mut w = mcap::WriteOptions::new()
        .chunk_size(Some(1))
        .compression(None)
        .create(file)
        .unwrap();
    let schema = olmap::io::bag::messages::schemas::point_cloud2();
    let sid = w
        .add_schema("sensor_msgs/msg/PointCloud2", "ros2msg", schema.as_bytes())
        .unwrap();
    let cid = w
        .add_channel(sid, "/points", "cdr", &Default::default())
        .unwrap();
    for (k, data) in clouds.iter().enumerate() {
        let header = mcap::records::MessageHeader {
            channel_id: cid,
            sequence: k as u32,
            log_time: k as u64 * 1000,
            publish_time: k as u64 * 1000,
        };
        w.write_to_known_channel(&header, data).unwrap();
    }
    if let Some((ty, text)) = extra_type {
        let sid = w.add_schema(ty, "ros2msg", text.as_bytes()).unwrap();
        let cid = w
            .add_channel(sid, "/other", "cdr", &Default::default())
            .unwrap();
        let header = mcap::records::MessageHeader {
            channel_id: cid,
            sequence: 0,
            log_time: 5,
            publish_time: 5,
        };
        w.write_to_known_channel(&header, &[0, 1, 0, 0, 7]).unwrap();
    }
    w.finish().unwrap();
}

fn cloud_msg(
    width: u32,
    height: u32,
    step: u32,
    row_step: u32,
    fields: &[(&str, u32)],
    data: &[u8],
) -> Vec<u8> {
    PointCloud2 {
        header: Header {
            stamp: Stamp { sec: 1, nanosec: 0 },
            frame_id: "lidar".into(),
        },
        height,
        width,
        fields: fields
            .iter()
            .map(|(n, o)| PointField {
                name: (*n).into(),
                offset: *o,
                datatype: 7,
                count: 1,
            })
            .collect(),
        is_bigendian: false,
        point_step: step,
        row_step,
        data,
        is_dense: false,
    }
    .encode()
}

#[test]
fn lying_point_clouds_are_skipped_with_their_topic_index_and_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let xyz = [("x", 0), ("y", 4), ("z", 8)];
    let mut good = Vec::new();
    for v in [1.0f32, 2.0, 3.0, 0.0, f32::NAN, 4.0, 5.0, 6.0, 0.0] {
        good.extend_from_slice(&v.to_le_bytes());
    }
    // Pad the good cloud to 2 points of 16 bytes; the second is a NaN return.
    let mut data = Vec::new();
    data.extend_from_slice(&good[..12]);
    data.extend_from_slice(&[0; 4]);
    data.extend_from_slice(&good[16..28]);
    data.extend_from_slice(&[0; 4]);
    let msgs = vec![
        cloud_msg(2, 1, 16, 32, &xyz, &data), // 0: fine
        cloud_msg(2, 1, 8, 16, &xyz, &data),  // 1: step < fields
        cloud_msg(2, 1, 16, 8, &xyz, &data),  // 2: row_step short
        cloud_msg(2, 1, 16, 32, &[("x", 0), ("y", 4), ("z", 14)], &data), // 3: offset past step
        cloud_msg(1_000_000, 1_000_000, 16, 16_000_000, &xyz, &data), // 4: 10^12 points
        vec![0, 1, 0, 0, 3],                  // 5: cut short
    ];
    let path = tmp.path().join("bad.mcap");
    write_bag(&path, &msgs, Some(("foo/msg/Bar", "baz/Qux q\n")));
    let bag = Bag::open(&path).unwrap();
    let ex = extract_scans(&bag, &ExtractOptions::default()).unwrap();
    assert_eq!(ex.scans.len(), 1);
    assert_eq!(ex.scans[0].cloud.len(), 1);
    assert_eq!(ex.scans[0].dropped, 1);
    let reasons = [
        "runs past point_step",
        "row_step 8 is shorter",
        "field 'z' (offset 14",
        "claims 1000000000000 points",
        "ends early",
    ];
    assert_eq!(ex.skipped.len(), reasons.len(), "{:?}", ex.skipped);
    for (k, (s, r)) in ex.skipped.iter().zip(reasons).enumerate() {
        let at = format!(
            "topic '/points', message {} (sensor_msgs/msg/PointCloud2)",
            k + 1
        );
        assert!(s.contains(&at) && s.contains(r), "{s}");
    }
    // The unknown type: listed by `bag info` as a problem naming it; refused as a scan topic.
    let info = bag_info(&bag).unwrap();
    assert!(
        info.problems.iter().any(|p| p.contains("topic '/other', message 0 (foo/msg/Bar)") && p.contains("baz/Qux")),
        "{:?}",
        info.problems
    );
    let e = extract_scans(
        &bag,
        &ExtractOptions {
            topic: Some("/other".into()),
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("topic '/other' holds foo/msg/Bar"), "{e}");
}

#[test]
fn damaged_files_stop_at_the_damage_and_keep_what_was_readable() {
    let Some(dir) = bags() else { return };
    let original = std::fs::read(dir.join("3dtk_points/3dtk_points.mcap")).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    // Truncated in the middle of the last scan.
    let cut = tmp.path().join("cut.mcap");
    std::fs::write(&cut, &original[..original.len() * 3 / 4]).unwrap();
    let bag = Bag::open(&cut).unwrap();
    let info = bag_info(&bag).unwrap();
    let stop = info
        .stopped_early
        .clone()
        .expect("a truncated file is reported");
    assert!(
        stop.contains("truncated") || stop.contains("ends"),
        "{stop}"
    );
    let ex = extract_scans(&bag, &ExtractOptions::default()).unwrap();
    assert!(ex.stopped_early.is_some());
    assert_eq!(ex.scans.len(), 2, "the first two scans precede the cut");
    // A flipped byte inside the second message's chunk: its CRC no longer matches.
    let marker = |v: f32| {
        let mut d = Vec::new();
        for _ in 0..3 {
            d.extend_from_slice(&v.to_le_bytes());
        }
        d
    };
    let xyz = [("x", 0), ("y", 4), ("z", 8)];
    let msgs: Vec<Vec<u8>> = [1111.0f32, 2222.0, 3333.0]
        .iter()
        .map(|&v| cloud_msg(1, 1, 12, 12, &xyz, &marker(v)))
        .collect();
    let good = tmp.path().join("good.mcap");
    write_bag(&good, &msgs, None);
    let mut bytes = std::fs::read(&good).unwrap();
    let needle = marker(2222.0);
    let at = bytes
        .windows(needle.len())
        .position(|w| w == needle.as_slice())
        .expect("the second cloud's points are stored uncompressed");
    bytes[at + 1] ^= 0x55;
    let bad = tmp.path().join("crc.mcap");
    std::fs::write(&bad, &bytes).unwrap();
    let bag = Bag::open(&bad).unwrap();
    let info = bag_info(&bag).unwrap();
    let stop = info.stopped_early.expect("a bad CRC is reported");
    assert!(stop.to_lowercase().contains("crc"), "{stop}");
    assert_eq!(
        info.messages, 1,
        "the message before the damaged chunk is kept"
    );
    let ex = extract_scans(&bag, &ExtractOptions::default()).unwrap();
    assert_eq!(ex.scans.len(), 1);
    assert_eq!(ex.scans[0].cloud.points()[0].x, 1111.0);
    // Not a bag at all.
    let junk = tmp.path().join("junk.mcap");
    std::fs::write(&junk, b"hello").unwrap();
    assert!(Bag::open(&junk)
        .unwrap_err()
        .to_string()
        .contains("MCAP magic"));
}

#[test]
fn a_written_map_bag_reads_back() {
    let mut cloud = PointCloud::from_points(vec![
        Point3::new(1.0, 2.0, 3.0),
        Point3::new(-1.5, 0.25, 0.0),
    ]);
    cloud.set_intensity(Some(vec![3.0, 1.0])).unwrap();
    let mut poses = olmap::geometry::PoseList::default();
    poses.push("robot0/scan000", Pose::identity());
    poses.push(
        "robot0/scan001",
        Pose::from_translation(Vector3::new(1.0, 0.0, 0.0)),
    );
    poses.push(
        "robot1/scan000",
        Pose::from_xyz_ypr(0.0, 2.0, 0.0, 0.3, 0.0, 0.0),
    );
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("map.mcap");
    write_map_mcap(
        &path,
        &MapBag {
            cloud: &cloud,
            poses: Some(&poses),
            stamp: Stamp::default(),
        },
    )
    .unwrap();
    let bag = Bag::open(&path).unwrap();
    let info = bag_info(&bag).unwrap();
    let names: Vec<_> = info
        .topics
        .iter()
        .map(|t| (t.name.as_str(), t.count))
        .collect();
    assert_eq!(names, [("/olmap/map", 1), ("/olmap/path", 2), ("/tf", 1)]);
    assert!(info.problems.is_empty(), "{:?}", info.problems);
    assert!(info.frames.contains(&"robot1_scan000".to_string()));
    let ex = extract_scans(&bag, &ExtractOptions::default()).unwrap();
    assert_eq!(ex.scans[0].cloud.points(), cloud.points());
    assert_eq!(ex.scans[0].cloud.intensity(), cloud.intensity());
    assert_eq!(ex.scans[0].frame, "map");
}

#[test]
fn a_broken_odometry_message_is_named_and_the_scans_still_come_out() {
    let tmp = tempfile::tempdir().unwrap();
    let mut data = Vec::new();
    for v in [1.0f32, 2.0, 3.0] {
        data.extend_from_slice(&v.to_le_bytes());
    }
    let msgs = vec![cloud_msg(
        1,
        1,
        12,
        12,
        &[("x", 0), ("y", 4), ("z", 8)],
        &data,
    )];
    let path = tmp.path().join("odom.mcap");
    // The extra topic `/other` is the bag's only Odometry topic; its one message is 5 bytes.
    write_bag(&path, &msgs, Some(("nav_msgs/msg/Odometry", "int32 x\n")));
    let ex = extract_scans(&Bag::open(&path).unwrap(), &ExtractOptions::default()).unwrap();
    assert_eq!(ex.scans.len(), 1);
    assert_eq!(ex.odometry_source.as_deref(), Some("/other"));
    assert!(ex.scans[0].odometry.is_none());
    assert_eq!(ex.skipped.len(), 1, "{:?}", ex.skipped);
    assert!(
        ex.skipped[0].contains("topic '/other', message 0 (nav_msgs/msg/Odometry)"),
        "{:?}",
        ex.skipped
    );
}

/// Issue 22, item 3 (readers cap allocations by the bytes present), found by fuzzing the
/// bag container: a 10 KB bag whose first record claimed 805 MB made `olmap bag info` hold
/// 793 MB (the reader sized its buffer to the claim before reading). A claim past the end
/// of the file now ends the reading as damage, and a chunk may not decompress to more
/// than 64 times its file (at least 32 MiB): both say so, and nothing that large is
/// allocated.
#[test]
fn a_length_past_the_end_of_the_file_is_damage_not_an_allocation() {
    let tmp = tempfile::tempdir().unwrap();
    let cloud = PointCloud::from_points(
        (0..200)
            .map(|i| Point3::new(i as f32 * 0.01, 1.0, 0.5))
            .collect(),
    );
    let good = tmp.path().join("map.mcap");
    write_map_mcap(
        &good,
        &MapBag {
            cloud: &cloud,
            poses: None,
            stamp: Stamp::from_nanos(0),
        },
    )
    .unwrap();
    let bytes = std::fs::read(&good).unwrap();
    assert_eq!(bag_info(&Bag::open(&good).unwrap()).unwrap().messages, 1);
    // The records after the 8-byte magic: opcode (1 byte), length (u64).
    let records = |b: &[u8]| {
        let mut at = 8;
        let mut out = Vec::new();
        while at + 9 <= b.len() {
            let len = u64::from_le_bytes(b[at + 1..at + 9].try_into().unwrap());
            out.push((b[at], at));
            at += 9 + len as usize;
        }
        out
    };
    let stop = |b: &[u8]| {
        let path = tmp.path().join("damaged.mcap");
        std::fs::write(&path, b).unwrap();
        bag_info(&Bag::open(&path).unwrap())
            .unwrap()
            .stopped_early
            .expect("the damage is reported")
    };
    // The header record (opcode 1) claims 20 MB (within the record limit of a small
    // file, past its end), then 805 MB (past the limit).
    let (op, at) = records(&bytes)[0];
    assert_eq!(op, 1);
    for (claim, said) in [
        (20_000_000u64, format!("has {} left", bytes.len() - 17)),
        (805_306_368, "805306368".to_string()),
    ] {
        let mut lying = bytes.clone();
        lying[at + 1..at + 9].copy_from_slice(&claim.to_le_bytes());
        let why = stop(&lying);
        assert!(why.contains(&said), "{claim}: {why}");
    }
    // The chunk (opcode 6) claims to decompress to 900 MB: over 64 x the file.
    let mut bomb = bytes.clone();
    let (_, chunk) = *records(&bytes)
        .iter()
        .find(|(op, _)| *op == 6)
        .expect("a chunk");
    // Chunk: start time, end time (u64 each), then the uncompressed size.
    let size = chunk + 9 + 16;
    bomb[size..size + 8].copy_from_slice(&900_000_000u64.to_le_bytes());
    let why = stop(&bomb);
    assert!(why.contains("900000000"), "{why}");
}
