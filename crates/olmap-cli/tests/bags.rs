//! `olmap bag info`, `olmap bag extract`, `olmap map BAG` and `olmap export … .mcap`, end to
//! end on the shared ROS 2 bags (data README §6).

use std::path::PathBuf;
use std::process::{Command, Output};

fn olmap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_olmap"))
        .args(args)
        .output()
        .expect("the olmap binary runs")
}

fn bags() -> Option<PathBuf> {
    olmap::test_data::dir().map(|d| d.join("ros2_bags"))
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn bag_info_json_lists_topics_with_the_documented_keys() {
    let Some(b) = bags() else { return };
    let out = olmap(&[
        "bag",
        "info",
        "--json",
        b.join("3dtk_points").to_str().unwrap(),
    ]);
    let v: serde_json::Value = serde_json::from_str(&ok(&out)).unwrap();
    let topics = v["topics"].as_array().unwrap();
    let points = topics.iter().find(|t| t["name"] == "/points").unwrap();
    assert_eq!(points["type"], "sensor_msgs/msg/PointCloud2");
    assert_eq!(points["count"], 3);
    // make_real_bags.py: the scans at t0 + 1 s and t0 + 21 s, t0 = 1.6e9 s.
    assert_eq!(points["first_stamp"], 1_600_000_001.0);
    assert_eq!(points["last_stamp"], 1_600_000_021.0);
    assert_eq!(
        v["frames"],
        serde_json::json!(["base_link", "laser", "odom"])
    );
}

#[test]
fn extract_then_map_equals_map_from_the_bag_and_export_writes_mcap() {
    let Some(b) = bags() else { return };
    let bag = b.join("3dtk_points");
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("ex");
    let report: serde_json::Value = serde_json::from_str(&ok(&olmap(&[
        "bag",
        "extract",
        bag.to_str().unwrap(),
        "-o",
        dir.to_str().unwrap(),
        "--json",
    ])))
    .unwrap();
    assert_eq!(report["scans"], 3);
    assert_eq!(report["odometry"], "/odom");
    for f in [
        "scans/000000.pcd",
        "scans/000002.pcd",
        "odometry.txt",
        "stamps.csv",
    ] {
        assert!(dir.join(f).is_file(), "{f}");
    }
    let stamps = std::fs::read_to_string(dir.join("stamps.csv")).unwrap();
    assert!(stamps.contains("000001,1,1600000011000000000,"), "{stamps}");
    let a = tmp.path().join("a.olm");
    let c = tmp.path().join("c.olm");
    ok(&olmap(&[
        "map",
        dir.join("scans").to_str().unwrap(),
        "--odometry",
        dir.join("odometry.txt").to_str().unwrap(),
        "-o",
        a.to_str().unwrap(),
    ]));
    ok(&olmap(&[
        "map",
        bag.to_str().unwrap(),
        "-o",
        c.to_str().unwrap(),
    ]));
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&c).unwrap());
    let m = tmp.path().join("map.mcap");
    ok(&olmap(&[
        "export",
        c.to_str().unwrap(),
        "-o",
        m.to_str().unwrap(),
    ]));
    let info = ok(&olmap(&["bag", "info", m.to_str().unwrap()]));
    assert!(
        info.contains("/olmap/map") && info.contains("sensor_msgs/msg/PointCloud2"),
        "{info}"
    );
    // A topic that is not there: a clear error listing what is.
    let out = olmap(&[
        "bag",
        "extract",
        bag.to_str().unwrap(),
        "-o",
        dir.to_str().unwrap(),
        "--topic",
        "/velodyne",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no topic '/velodyne'")
            && err.contains("/points [sensor_msgs/msg/PointCloud2]"),
        "{err}"
    );
}
