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

/// The pose `T_target_source` of `olmap align --json`'s output.
fn registered_pose(v: &serde_json::Value) -> Pose {
    let m: Vec<f64> = v["T_target_source"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
        .collect();
    Pose::from_row_major_3x4(
        &[
            m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8], m[9], m[10], m[11],
        ],
        1e-6,
    )
    .unwrap()
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
    let found = registered_pose(&v);
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

/// Issue 22 audit 1: a robot's scans of the simulated office mapped without odometry (every
/// scan searched globally, batch order) place no scan wrong. The audit's own run (seed 11,
/// robot 0) and three that placed a scan 5-7 m and 180° off: a global match trusted
/// against a smaller map, where the scan's own place was not mapped yet and its room's
/// half-turn twin was, then confirmed only in a window round that pose after its place
/// had been mapped (seeds 1 and 8, robot 2; seed 6, robot 0); and seed 4's robot 3, whose
/// corridor scans were trusted turned end for end or 5.2 m along the corridor where the
/// scans could not tell. (Robot 3 of seed 11 placed scan003 turned end for end, 4.7 m off,
/// until the slides ranked positions from `weak_axis::SLIDE_MIN_SUPPORT`; it now leaves
/// that scan out: `a_corridor_truth_overlapping_less_than_the_winner_is_still_proposed`.)
#[test]
fn audit_office_map_without_odometry_places_no_scan_wrong() {
    for (seed, robot) in [(11, 0), (1, 2), (6, 0), (8, 2), (4, 3)] {
        office_robot_mapped_without_odometry_places_no_scan_wrong(seed, robot);
    }
}

/// `olmap simulate --world office --robots 4 --scans-per-robot 6 --seed SEED -o OUT`.
fn simulate_office_team(seed: u64, out: &Path) {
    let seed = seed.to_string();
    ok(&olmap(&[
        "simulate",
        "--world",
        "office",
        "--robots",
        "4",
        "--scans-per-robot",
        "6",
        "--seed",
        &seed,
        "-o",
        out.to_str().unwrap(),
    ]));
}

fn office_robot_mapped_without_odometry_places_no_scan_wrong(seed: u64, robot: usize) {
    let dir = tempfile::tempdir().unwrap();
    let o4 = dir.path().join("o4");
    simulate_office_team(seed, &o4);
    let robot_dir = o4.join(format!("robot{robot}"));
    let poses = dir.path().join("p.txt");
    let report = dir.path().join("r.json");
    ok(&olmap(&[
        "map",
        robot_dir.join("scans").to_str().unwrap(),
        "-o",
        dir.path().join("m.olm").to_str().unwrap(),
        "--poses-out",
        poses.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]));
    let placed = read_poses(&poses).unwrap();
    let truth = read_poses(robot_dir.join("truth.txt")).unwrap();
    let first = truth.get("scan000").unwrap();
    assert!(!placed.poses.is_empty());
    for p in &placed.poses {
        let t = first.inverse() * *truth.get(&p.name).unwrap();
        let (et, er) = error(&p.pose, &t);
        eprintln!("seed {seed} robot{robot} {}: {et:.2} m {er:.1}°", p.name);
        assert!(
            et <= 0.3 && er <= 3.0,
            "seed {seed} robot{robot}: {} placed {et:.2} m and {er:.1}° off",
            p.name
        );
    }
}

/// In a corridor of the simulated office (seed 4, robot 3) scan003 onto scan000: the scan
/// turned end for end and laid over the other near its sensor contradicts nothing and
/// overlaps most, while the truth lies 4-5 m along the corridor as placed. The corridor
/// slides now keep the cleanest position of each copy (as placed, turned), so the truth is
/// verified as a hypothesis, and the turned match, which it does not contradict, is not
/// trusted (it was, 2.0 m and 180° off, and the robot's map placed the scan there).
#[test]
fn a_corridor_scan_turned_end_for_end_is_not_trusted_over_the_truth_along_the_corridor() {
    corridor_truth_is_verified_and_no_wrong_match_trusted(4);
}

/// The same pair in the office of seed 11: the truth lies 4.69 m along the corridor from
/// the winner and turned end for end, and overlaps less (0.46 of the winner's support in
/// the slides' quick count, 0.60 in the verdict's). While the slides asked the verdict's
/// 0.5 of a position before ranking its cleanness, the truth was never proposed and the
/// winner was trusted 4.69 m and 180° off (the robot's map placed the scan there); the
/// slides now rank positions supported 0.4 as well (`weak_axis::SLIDE_MIN_SUPPORT`).
#[test]
fn a_corridor_truth_overlapping_less_than_the_winner_is_still_proposed() {
    corridor_truth_is_verified_and_no_wrong_match_trusted(11);
}

/// Robot 3's scan003 aligned onto its scan000 in the simulated office of `seed`: some
/// hypothesis lies within 0.3 m and 3° of the truth, and a trusted answer is right.
fn corridor_truth_is_verified_and_no_wrong_match_trusted(seed: u64) {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("o");
    simulate_office_team(seed, &o);
    let scans = o.join("robot3").join("scans");
    let out = ok(&olmap(&[
        "align",
        scans.join("scan003.pcd").to_str().unwrap(),
        scans.join("scan000.pcd").to_str().unwrap(),
        "--json",
    ]));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let truth = truth_between(&o, "robot3", "scan000", "scan003");
    let near_truth = v["uniqueness"]["hypotheses"]
        .as_array()
        .unwrap()
        .iter()
        .any(|h| {
            let xyz: Vec<f64> = h["pose"]["xyz_m"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let ypr: Vec<f64> = h["pose"]["yaw_pitch_roll_deg"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap().to_radians())
                .collect();
            let p = Pose::from_xyz_ypr(xyz[0], xyz[1], xyz[2], ypr[0], ypr[1], ypr[2]);
            let (et, er) = error(&p, &truth);
            et <= 0.3 && er <= 3.0
        });
    assert!(
        near_truth,
        "seed {seed}: no hypothesis near the truth: {}",
        v["uniqueness"]
    );
    let (et, er) = error(&registered_pose(&v), &truth);
    if v["trusted"].as_bool().unwrap() {
        assert!(
            et <= 0.3 && er <= 3.0,
            "seed {seed}: trusted but {et:.2} m and {er:.1}° off"
        );
    }
}
