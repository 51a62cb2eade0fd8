//! The audit's confident wrong poses (issue 22, audit 1), reproduced with the exact
//! commands of the audit: a trusted answer must be right (0.3 m / 3° of the simulator's
//! truth), whatever else it is.

use std::path::Path;
use std::process::{Command, Output};

use olmap::geometry::Pose;
use olmap::io::read_poses;

fn olmap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_olmap"))
        .args(args)
        .output()
        .expect("the olmap binary runs")
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `T_a_b` from the simulator's truth (`T_world_scan`) of one robot.
fn truth_between(dataset: &Path, robot: &str, a: &str, b: &str) -> Pose {
    let truth = read_poses(dataset.join(robot).join("truth.txt")).unwrap();
    truth.get(a).unwrap().inverse() * *truth.get(b).unwrap()
}

fn error(a: &Pose, b: &Pose) -> (f64, f64) {
    let d = a.inverse() * *b;
    (d.translation().norm(), d.rotation().angle().to_degrees())
}

#[test]
fn audit_office_repetitive_pose_not_trusted_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let so = dir.path().join("so");
    let so_s = so.to_str().unwrap();
    ok(&olmap(&[
        "simulate",
        "--world",
        "office",
        "--robots",
        "1",
        "--scans-per-robot",
        "25",
        "--seed",
        "5",
        "-o",
        so_s,
    ]));
    let scans = so.join("robot0").join("scans");
    let source = scans.join("scan020.pcd");
    let target = scans.join("scan000.pcd");
    let out = ok(&olmap(&[
        "align",
        source.to_str().unwrap(),
        target.to_str().unwrap(),
        "--json",
    ]));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rows = v["T_target_source"].as_array().unwrap();
    let m: Vec<f64> = rows
        .iter()
        .flat_map(|r| r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
        .collect();
    let found = Pose::from_row_major_3x4(
        &[
            m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8], m[9], m[10], m[11],
        ],
        1e-6,
    )
    .unwrap();
    let truth = truth_between(&so, "robot0", "scan000", "scan020");
    let (et, er) = error(&found, &truth);
    eprintln!(
        "scan020 -> scan000: trusted {} error {et:.2} m {er:.1}°, doubts {}",
        v["trusted"], v["doubts"]
    );
    // The evidence the verdict weighed is in the report.
    assert!(v["uniqueness"]["search_runner_up_ratio"].is_number());
    assert!(v["uniqueness"]["spread_m"].is_array());
    if v["trusted"].as_bool().unwrap() {
        assert!(
            et <= 0.3 && er <= 3.0,
            "trusted but {et:.2} m and {er:.1}° off"
        );
    }
}

#[test]
#[ignore = "issue 22 audit 1 not fixed yet: scan004 is still placed 4.90 m and 180° off \
            (main placed 3 of 4 scans wrong; stop note of 2026-12-02)"]
fn audit_office_map_without_odometry_places_no_scan_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let o4 = dir.path().join("o4");
    ok(&olmap(&[
        "simulate",
        "--world",
        "office",
        "--robots",
        "4",
        "--scans-per-robot",
        "6",
        "--seed",
        "11",
        "-o",
        o4.to_str().unwrap(),
    ]));
    let poses = dir.path().join("p.txt");
    let report = dir.path().join("r.json");
    ok(&olmap(&[
        "map",
        o4.join("robot0").join("scans").to_str().unwrap(),
        "-o",
        dir.path().join("m.olm").to_str().unwrap(),
        "--poses-out",
        poses.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]));
    let placed = read_poses(&poses).unwrap();
    let truth = read_poses(o4.join("robot0").join("truth.txt")).unwrap();
    let first = truth.get("scan000").unwrap();
    assert!(!placed.poses.is_empty());
    for p in &placed.poses {
        let t = first.inverse() * *truth.get(&p.name).unwrap();
        let (et, er) = error(&p.pose, &t);
        eprintln!("{}: {et:.2} m {er:.1}°", p.name);
        assert!(
            et <= 0.3 && er <= 3.0,
            "{} placed {et:.2} m and {er:.1}° off",
            p.name
        );
    }
}
