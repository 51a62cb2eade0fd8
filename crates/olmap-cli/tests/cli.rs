//! End-to-end tests of the `olmap` program.

use std::path::PathBuf;
use std::process::{Command, Output};

fn olmap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_olmap"))
        .args(args)
        .output()
        .expect("the olmap binary runs")
}

fn json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("valid JSON on stdout")
}

fn data() -> Option<PathBuf> {
    olmap::test_data::dir()
}

#[test]
fn info_json_on_real_data() {
    let Some(d) = data() else { return };
    let scan = d.join("3dtk_dat/scan000.3d");
    let v = json(&olmap(&[
        "info",
        "--json",
        "--3dtk-valid",
        scan.to_str().unwrap(),
    ]));
    // Data README §1.3: 77,987 valid points of 81,360.
    assert_eq!(v[0]["points"], 77_987);
    assert_eq!(v[0]["records"], 81_360);
    assert_eq!(v[0]["dropped_invalid"], 81_360 - 77_987);
    assert_eq!(v[0]["format"], "3DTK .3d");
}

#[test]
fn info_reports_every_file_and_fails_on_a_bad_one() {
    let Some(d) = data() else { return };
    let good = d.join("octomap_share_data/scan.dat");
    let bad = d.join("octomap_share_data/mapcoll.txt");
    let out = olmap(&[
        "info",
        "--json",
        good.to_str().unwrap(),
        bad.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v[0]["points"], 88_206);
    assert!(v[1]["error"].as_str().unwrap().contains("mapcoll.txt"));
}

#[test]
fn convert_filters_and_round_trips() {
    let Some(d) = data() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scan.pcd");
    let scan = d.join("octomap_share_data/scan.dat");
    let v = json(&olmap(&[
        "convert",
        "--json",
        "--max-range",
        "10",
        "--z-min",
        "-0.5",
        "--pcd-encoding",
        "binary-compressed",
        scan.to_str().unwrap(),
        out.to_str().unwrap(),
    ]));
    let written = v["points_written"].as_u64().unwrap();
    assert!(written > 0 && written < 88_206);
    let back = olmap::io::read_cloud(&out).unwrap();
    assert_eq!(back.cloud.len() as u64, written);
    assert_eq!(back.report.encoding, "binary_compressed");
    let s = back.cloud.stats();
    assert!(s.range.unwrap().max <= 10.0 + 1e-6);
    assert!(s.bbox.unwrap().min.z >= -0.5 - 1e-6);
}

#[test]
fn info_and_convert_read_laz() {
    let Some(d) = data() else { return };
    let laz = d.join("las/autzen.laz");
    let v = json(&olmap(&["info", "--json", laz.to_str().unwrap()]));
    // Data README §7: autzen holds 106 points (the same in the .las).
    assert_eq!(v[0]["format"], "LAS/LAZ");
    assert_eq!(v[0]["points"], 106);
    assert_eq!(v[0]["records"], 106);
    let origin: Vec<f64> = v[0]["local_origin"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    // The header's bounds: x 635,616-638,865, y 848,978-853,362 (state plane).
    assert!((635_616.0..638_865.0).contains(&origin[0]), "{origin:?}");
    assert!((848_977.0..853_363.0).contains(&origin[1]), "{origin:?}");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("autzen.pcd");
    let r = json(&olmap(&[
        "convert",
        "--json",
        laz.to_str().unwrap(),
        out.to_str().unwrap(),
    ]));
    assert_eq!(r["points_written"], 106);
    assert_eq!(r["local_origin"], v[0]["local_origin"]);
    let pcd = olmap::io::read_cloud(&out).unwrap();
    assert_eq!(pcd.cloud, olmap::io::read_cloud(&laz).unwrap().cloud);
    // Back to LAS: the input's local origin becomes the offset, the frame is kept.
    let las = dir.path().join("autzen.las");
    json(&olmap(&[
        "convert",
        "--json",
        laz.to_str().unwrap(),
        las.to_str().unwrap(),
    ]));
    let back = olmap::io::read_cloud(&las).unwrap();
    assert_eq!(back.cloud.points(), pcd.cloud.points());
    assert_eq!(json_origin(&back.report.local_origin), v[0]["local_origin"]);
}

fn json_origin(o: &Option<[f64; 3]>) -> serde_json::Value {
    serde_json::to_value(o).unwrap()
}

#[test]
fn convert_refuses_bad_arguments_without_writing() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.xyz");
    std::fs::write(&input, "1 2 3\n4 5 6\n").unwrap();
    let out = dir.path().join("out.pcd");
    let r = olmap(&[
        "convert",
        "--box",
        "1,2,3",
        input.to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("--box"));
    let r = olmap(&[
        "convert",
        input.to_str().unwrap(),
        dir.path().join("out.nope").to_str().unwrap(),
    ]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("out.nope"));
    let missing = dir.path().join("missing.pcd");
    let r = olmap(&["convert", missing.to_str().unwrap(), out.to_str().unwrap()]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("missing.pcd"));
    assert!(!out.exists());
}

#[test]
fn demo_maps_a_team_and_each_robot_alone() {
    let dir = tempfile::tempdir().unwrap();
    let run = || {
        json(&olmap(&[
            "demo",
            "--json",
            "--robots",
            "2",
            "--scans-per-robot",
            "3",
            "--seed",
            "2",
            "--out",
            dir.path().to_str().unwrap(),
        ]))
    };
    let v = run();
    // The joint map reloads with the reported voxels; the report on disk is the one printed
    // (less the demo's extra fields).
    let map = olmap::occupancy::read_map(dir.path().join("team.olm"))
        .unwrap()
        .map;
    assert_eq!(map.len() as u64, v["voxels"].as_u64().unwrap());
    let on_disk: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(on_disk["placements"], v["placements"]);
    // Seed 2: the robots see each other, so robot1 joins robot0's map by a sighting, and
    // every scan is within the 0.3 m of the truth.
    let frames = v["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 2);
    assert!(
        frames[1]["linked_by"]
            .as_str()
            .unwrap()
            .starts_with("sighting"),
        "{v}"
    );
    let team = &v["evaluation"]["team"];
    assert_eq!(team["placed"].as_u64(), Some(6), "{v}");
    assert!(team["max_m"].as_f64().unwrap() < 0.3, "{team}");
    let bars = team["histogram"].as_array().unwrap();
    let counted: u64 = bars.iter().map(|b| b["count"].as_u64().unwrap()).sum();
    assert_eq!(counted, team["compared"].as_u64().unwrap());
    assert!(v["evaluation"]["solo"]["compared"].as_u64().unwrap() >= 2);
    assert!(v["relative_frames"].as_array().unwrap().len() == 1);
    let back = olmap::sim::read_dataset(v["dataset"].as_str().unwrap()).unwrap();
    assert_eq!(back.manifest.robots.len(), 2);
    // The HTML report: self-contained, with the team's and both robots' top views, the
    // error histogram and the entropy curve as inlined PNGs.
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert_eq!(
        html.matches("src=\"data:image/png;base64,").count(),
        5,
        "{html}"
    );
    assert!(html.contains("Figure 6.11") && html.contains("Map entropy"));
    assert!(!html.contains("src=\"http") && !html.contains("src=\"file"));
    // Map entropy (thesis (7.4)) after every scan that joined, one value each: the listed
    // voxels' terms with p0 = 0.5 are each below zero, so the first is negative.
    let h = v["entropy_after_scan"].as_array().unwrap();
    assert_eq!(h.len(), v["placements"].as_array().unwrap().len());
    assert!(h[0].as_f64().unwrap() < 0.0, "{h:?}");
    // A second run replaces its own dataset and gives the same poses.
    let again = run();
    assert_eq!(again["placements"], v["placements"]);
}

#[test]
fn team_maps_a_simulated_dataset_and_refuses_a_missing_one() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let out = dir.path().join("out");
    let sim = olmap(&[
        "simulate",
        "--robots",
        "2",
        "--scans-per-robot",
        "3",
        "--seed",
        "2",
        "--output",
        data.to_str().unwrap(),
    ]);
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let v = json(&olmap(&[
        "team",
        data.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--json",
    ]));
    for f in [
        "team.olm",
        "team.ply",
        "team.bt",
        "team_poses.txt",
        "team.store",
        "report.json",
        "report.html",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    // The store file holds every scan; the pose file every placed one.
    let store = olmap::team::ScanStore::read(out.join("team.store")).unwrap();
    assert_eq!(store.len(), 6);
    let poses = olmap::geometry::PoseList::read_path(out.join("team_poses.txt")).unwrap();
    assert_eq!(poses.len(), v["placements"].as_array().unwrap().len());
    assert!(v["evaluation"]["solo"].is_null());
    // The PLY of the map carries one colour per voxel, by height, for 3D viewers.
    let ply = olmap::io::read_cloud(out.join("team.ply")).unwrap().cloud;
    assert_eq!(ply.colors().map(|c| c.len()), Some(ply.len()));
    let missing = dir.path().join("nowhere");
    let r = olmap(&[
        "team",
        missing.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("nowhere"), "{err}");
}

#[test]
fn poses_from_3dtk_frames_match_the_reference_list() {
    let Some(d) = data() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("poses.txt");
    let frames: Vec<String> = ["scan000", "scan001", "scan002"]
        .iter()
        .map(|s| d.join(format!("3dtk_dat/{s}.frames")).display().to_string())
        .collect();
    let mut args = vec!["poses", "--json", "--out", out.to_str().unwrap()];
    args.extend(frames.iter().map(String::as_str));
    let v = json(&olmap(&args));
    // Data README §1.6: scan001 at (1.5680, 0.0363, -0.0908) m, yaw 0.715 degrees.
    assert_eq!(v[1]["name"], "scan001");
    let xyz = v[1]["xyz_m"].as_array().unwrap();
    assert!((xyz[0].as_f64().unwrap() - 1.5680).abs() < 1e-4);
    assert!((v[1]["yaw_pitch_roll_deg"][0].as_f64().unwrap() - 0.715).abs() < 1e-3);
    let written = olmap::geometry::PoseList::read_path(&out).unwrap();
    let reference =
        olmap::geometry::PoseList::read_path(d.join("3dtk_dat/reference_poses_rh_m.txt")).unwrap();
    for (a, b) in written.poses.iter().zip(&reference.poses) {
        let e = olmap::geometry::PoseError::between(&a.pose, &b.pose);
        assert!(
            e.translation_m < 1e-5 && e.rotation_deg < 1e-3,
            "{}: {e:?}",
            a.name
        );
    }
}

#[test]
fn voxelize_info_export_merge() {
    let Some(d) = data() else { return };
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("m.olm");
    let scans: Vec<String> = (0..3)
        .map(|i| {
            d.join(format!("3dtk_dat/scan00{i}.3d"))
                .display()
                .to_string()
        })
        .collect();
    let poses = d.join("3dtk_dat/reference_poses_rh_m.txt");
    let mut args = vec![
        "voxelize",
        "--json",
        "--ray-trace",
        "--3dtk-valid",
        "--resolution",
        "0.1",
        "--poses",
        poses.to_str().unwrap(),
        "-o",
        map.to_str().unwrap(),
    ];
    args.extend(scans.iter().map(String::as_str));
    let v = json(&olmap(&args));
    // README §1.3: 77,987 + 78,320 + 78,118 valid points.
    assert_eq!(v["points"], 77_987 + 78_320 + 78_118);
    let voxels = v["voxels"].as_u64().unwrap();
    assert!((10_000..100_000).contains(&voxels), "{voxels}");
    let info = json(&olmap(&["info", "--json", map.to_str().unwrap()]));
    assert_eq!(info[0]["voxels"].as_u64().unwrap(), voxels);
    assert_eq!(info[0]["resolution"], 0.1);
    // Export voxel centres as PLY with counts as intensity.
    let ply = dir.path().join("m.ply");
    let out = olmap(&["export", map.to_str().unwrap(), "-o", ply.to_str().unwrap()]);
    assert!(out.status.success());
    let cloud = olmap::io::read_cloud(&ply).unwrap().cloud;
    assert_eq!(cloud.len() as u64, voxels);
    assert!(cloud.intensity().unwrap().iter().all(|&c| c >= 1.0));
    // Merging a map with itself doubles every count and keeps the voxels.
    let merged = dir.path().join("mm.olm");
    let out = olmap(&[
        "merge",
        map.to_str().unwrap(),
        map.to_str().unwrap(),
        "-o",
        merged.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let a = olmap::occupancy::read_map(&map).unwrap().map;
    let b = olmap::occupancy::read_map(&merged).unwrap().map;
    assert_eq!(a.len(), b.len());
    assert!(a
        .iter()
        .all(|(k, c)| b.count(k) == (2 * c).min(olmap::occupancy::MAX_COUNT)));
}

#[test]
fn octomap_bt_read_write_and_octomap_accepts_ours() {
    let Some(d) = data() else { return };
    let bt = d.join("octomap_share_data/geb079.bt");
    let v = json(&olmap(&["info", "--json", bt.to_str().unwrap()]));
    // Data README §2.4: 532,566 nodes, 143,729 occupied leaves (137,745 at 0.08 m, 5,983 at
    // 0.16 m, 1 at 0.32 m) -> 137,745 + 8 x 5,983 + 64 voxels at 0.08 m; 284,415 free leaves.
    assert_eq!(v[0]["octree"]["nodes"], 532_566);
    assert_eq!(v[0]["octree"]["occupied_leaves"], 143_729);
    assert_eq!(v[0]["octree"]["free_leaves"], 284_415);
    assert_eq!(v[0]["voxels"], 137_745 + 8 * 5_983 + 64);
    assert_eq!(v[0]["resolution"], 0.08);
    let dir = tempfile::tempdir().unwrap();
    let olm = dir.path().join("g.olm");
    let ours = dir.path().join("g.bt");
    assert!(
        olmap(&["export", bt.to_str().unwrap(), "-o", olm.to_str().unwrap()])
            .status
            .success()
    );
    assert!(olmap(&[
        "export",
        olm.to_str().unwrap(),
        "-o",
        ours.to_str().unwrap()
    ])
    .status
    .success());
    let a = olmap::occupancy::read_map(&bt).unwrap();
    let b = olmap::occupancy::read_map(&ours).unwrap();
    assert_eq!(a.map.sorted(), b.map.sorted());
    let written = b.bt.unwrap();
    assert_eq!(
        written.occupied_leaves, 143_729,
        "pruned as far as OctoMap's own tree"
    );
    assert_eq!(written.free_leaves, 0);
    // OctoMap's own tools (Debian octomap-tools, installed by .ci/run when possible) must
    // read our file and count the same nodes.
    octomap_reads(&ours, written.nodes, &dir.path().join("g.ot"));
}

/// OctoMap's own tools (Debian octomap-tools, installed by .ci/run when possible) read a
/// `.bt` file and count `nodes` nodes in it; skipped (with a note) when they are missing.
fn octomap_reads(bt: &std::path::Path, nodes: u64, ot: &std::path::Path) {
    match Command::new("convert_octree").arg(bt).arg(ot).output() {
        Ok(out) => {
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let cmp = Command::new("compare_octrees")
                .arg(ot)
                .arg(ot)
                .output()
                .unwrap();
            let text = String::from_utf8_lossy(&cmp.stdout).to_string()
                + &String::from_utf8_lossy(&cmp.stderr);
            assert!(text.contains(&format!("Done ({nodes} nodes)")), "{text}");
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            eprintln!("octomap-tools not installed: the OctoMap cross-check is skipped")
        }
        Err(e) => panic!("convert_octree could not be started: {e}"),
    }
}

#[test]
fn free_space_map_matches_octomap_on_a_real_scan() {
    let Some(d) = data() else { return };
    let scan = d.join("octomap_share_data/scan.dat");
    let dir = tempfile::tempdir().unwrap();
    let ours = dir.path().join("free.bt");
    let graph = dir.path().join("scan.graph");
    // A .olm cannot hold free space: refused, nothing written.
    let olm = dir.path().join("free.olm");
    let out = olmap(&[
        "voxelize",
        "--free-space",
        scan.to_str().unwrap(),
        "-o",
        olm.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains(".bt"));
    assert!(!olm.exists());
    let v = json(&olmap(&[
        "voxelize",
        "--free-space",
        "--json",
        "--resolution",
        "0.1",
        scan.to_str().unwrap(),
        "-o",
        ours.to_str().unwrap(),
        "--scan-graph",
        graph.to_str().unwrap(),
    ]));
    // Data README §2.3: 88,206 finite points, ranges 0.47-29.05 m. Every ray ends in an
    // occupied voxel (no maximum range by default) and crosses free ones.
    let n = |k: &str| v[k].as_u64().unwrap();
    assert_eq!(n("points"), 88_206);
    assert_eq!(v["insertion"]["truncated"], 0);
    assert!(n("occupied") > 0 && n("occupied") <= 88_206);
    assert!(n("free") > 10 * n("occupied"));
    assert_eq!(n("voxels"), n("free") + n("occupied"));
    assert!(v["max_range"].is_null());
    let own = json(&olmap(&[
        "compare-bt",
        "--json",
        ours.to_str().unwrap(),
        ours.to_str().unwrap(),
    ]));
    assert_eq!(own["both_known"].as_u64(), Some(n("voxels")));
    assert_eq!(own["agreement"], 1.0);
    // Queries tell free from unknown: ahead of the sensor along x (inside the scan's
    // field of view, README §2.3) the rays cross free space; behind it (all x >= -0.08 m)
    // nothing was seen.
    let at = |p: &str| {
        json(&olmap(&[
            "query",
            "--json",
            ours.to_str().unwrap(),
            "--at",
            p,
        ]))
    };
    assert_eq!(at("0.35,0.05,0.05")["state"], "free");
    assert_eq!(at("-5,0,0")["state"], "unknown");
    let seg = |s: &str| {
        json(&olmap(&[
            "query",
            "--json",
            ours.to_str().unwrap(),
            "--segment",
            s,
        ]))
    };
    assert_eq!(seg("0.05,0.05,0.05,0.45,0.05,0.05")["known_free"], true);
    let behind = seg("0.05,0.05,0.05,-3,0.05,0.05");
    assert_eq!(
        (behind["free"].clone(), behind["known_free"].clone()),
        (true.into(), false.into())
    );
    // OctoMap itself on the same scan (Debian octomap-tools, installed by .ci/run when
    // possible): the acceptance is >= 99 % agreement on voxels both know.
    let theirs = dir.path().join("octomap.bt");
    match Command::new("graph2tree")
        .args([
            "-i",
            graph.to_str().unwrap(),
            "-o",
            theirs.to_str().unwrap(),
            "-res",
            "0.1",
        ])
        .output()
    {
        Ok(out) => {
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let c = json(&olmap(&[
                "compare-bt",
                "--json",
                ours.to_str().unwrap(),
                theirs.to_str().unwrap(),
            ]));
            let both = c["both_known"].as_u64().unwrap();
            assert!(c["agreement"].as_f64().unwrap() >= 0.99, "{c}");
            assert!(both as f64 >= 0.99 * n("voxels") as f64, "{c}");
            assert!(
                both as f64 >= 0.99 * c["known_there"].as_u64().unwrap() as f64,
                "{c}"
            );
            // OctoMap reads our tree with its free nodes, node for node.
            octomap_reads(
                &ours,
                v["bt_nodes"].as_u64().unwrap(),
                &dir.path().join("free.ot"),
            );
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            eprintln!("octomap-tools not installed: the OctoMap cross-check is skipped")
        }
        Err(e) => panic!("graph2tree could not be started: {e}"),
    }
}

#[test]
fn align_json_and_localize_in_a_map() {
    let Some(d) = data() else { return };
    let s0 = d.join("3dtk_dat/scan000.3d");
    let s1 = d.join("3dtk_dat/scan001.3d");
    let v = json(&olmap(&[
        "align",
        "--json",
        "--3dtk-valid",
        s1.to_str().unwrap(),
        s0.to_str().unwrap(),
    ]));
    // DESIGN.md: T_target_source as a 4x4 row-major array, overlap, significance, seconds.
    let m = v["T_target_source"].as_array().unwrap();
    assert_eq!(m.len(), 4);
    let tx = m[0][3].as_f64().unwrap();
    // Data README §1.6: scan001 is 1.568 m ahead of scan000 (5 cm tolerance, §1.7).
    assert!((tx - 1.568).abs() < 0.05, "{tx}");
    assert!(v["overlap"].as_u64().unwrap() > 0);
    assert!(v["significance"].as_f64().unwrap() > 10.0);
    assert!(v["seconds"].as_f64().unwrap() > 0.0);
    assert_eq!(v["trusted"], true);
    // The real pairs are found by the search itself, not by the upright look (whose
    // winners must agree at 0.97, more than real right pairs always do).
    let u = &v["uniqueness"];
    let chosen = u["chosen"].as_u64().unwrap() as usize;
    assert_eq!(u["hypotheses"][chosen]["origin"], "search", "{u}");
    // Localisation in a voxel map of scan000.
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("s0.olm");
    let out = olmap(&[
        "voxelize",
        "--3dtk-valid",
        "--resolution",
        "0.1",
        s0.to_str().unwrap(),
        "-o",
        map.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let v = json(&olmap(&[
        "localize",
        "--json",
        "--3dtk-valid",
        s1.to_str().unwrap(),
        map.to_str().unwrap(),
    ]));
    let tx = v["T_target_source"][0][3].as_f64().unwrap();
    assert!((tx - 1.568).abs() < 0.05, "{tx}");
    // Several scans in the map prepared once (`--also`): each placed as alone, and scan002
    // (data README §1.6: 3.378 m ahead of scan000; 5 cm, §1.7) placed too.
    let s2 = d.join("3dtk_dat/scan002.3d");
    let many = json(&olmap(&[
        "localize",
        "--json",
        "--3dtk-valid",
        s1.to_str().unwrap(),
        map.to_str().unwrap(),
        "--also",
        s2.to_str().unwrap(),
    ]));
    assert!(many["prepare_seconds"].as_f64().unwrap() > 0.0);
    let results = many["results"].as_array().unwrap();
    assert_eq!(results.len(), 2);
    assert_eq!(results[0]["source"], s1.to_str().unwrap());
    assert_eq!(results[0]["trusted"], v["trusted"]);
    assert_eq!(results[0]["T_target_source"], v["T_target_source"]);
    let tx = results[1]["T_target_source"][0][3].as_f64().unwrap();
    assert!((tx - 3.378).abs() < 0.05, "{tx}");
    assert_eq!(results[1]["trusted"], true);
    assert_eq!(many["free_space"], false, "a .olm map keeps no free space");
    // The same map with its free space (an OctoMap tree with free nodes): a window around
    // the identity leaves out scan002's true pose 3.4 m ahead; the identity, where the two
    // sensors' floors and near walls lie on each other, is refused because scan002's walls
    // would stand in the map's free space. Both scans are placed in it as before.
    let free_map = dir.path().join("s0.bt");
    let out = olmap(&[
        "voxelize",
        "--3dtk-valid",
        "--resolution",
        "0.1",
        "--free-space",
        s0.to_str().unwrap(),
        "-o",
        free_map.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let window = json(&olmap(&[
        "localize",
        "--json",
        "--3dtk-valid",
        s2.to_str().unwrap(),
        free_map.to_str().unwrap(),
        "--guess",
        "0,0,0,0,0,0",
        "--window",
        "0.5,0.2,5",
    ]));
    assert_eq!(window["trusted"], false, "{}", window["doubts"]);
    let with_free = json(&olmap(&[
        "localize",
        "--json",
        "--3dtk-valid",
        s1.to_str().unwrap(),
        free_map.to_str().unwrap(),
        "--also",
        s2.to_str().unwrap(),
    ]));
    assert_eq!(with_free["free_space"], true);
    // Both placed; scan001 trusted. Globally, scan002 is trusted only where the map's
    // surfaces single its pose out, and on the surfaces alone the two sensors' floors at
    // the identity fit it better (only the map's free space refutes them), so it is
    // reported untrusted, as in the map without free space.
    for (r, ahead, trusted) in with_free["results"]
        .as_array()
        .unwrap()
        .iter()
        .zip([(1.568, true), (3.378, false)])
        .map(|(r, (a, t))| (r, a, t))
    {
        let tx = r["T_target_source"][0][3].as_f64().unwrap();
        assert!(
            (tx - ahead).abs() < 0.05 && r["trusted"] == trusted,
            "{tx} {r}"
        );
    }
    // --also places scans in a map, not in another scan.
    let out = olmap(&[
        "align",
        s1.to_str().unwrap(),
        s0.to_str().unwrap(),
        "--also",
        s2.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--also") && err.contains("not a map"), "{err}");
}

/// `olmap map --free-space-out` writes the placed scans ray traced into a tree that keeps
/// free space; scan002, held out, localised in it with a window around the identity (its
/// truth 3.4 m ahead: data README §1.6) is refused, globally placed within 5 cm (§1.7); a
/// free-space output that is not a .bt fails before any work.
#[test]
fn a_map_written_with_its_free_space_refuses_a_window_without_the_truth() {
    let Some(d) = data() else { return };
    let dir = tempfile::tempdir().unwrap();
    let folder = d.join("3dtk_dat");
    let (s0, s1, s2) = (
        folder.join("scan000.3d"),
        folder.join("scan001.3d"),
        folder.join("scan002.3d"),
    );
    let (map, free) = (dir.path().join("m.olm"), dir.path().join("m.bt"));
    let out = olmap(&[
        "map",
        "--3dtk-valid",
        s0.to_str().unwrap(),
        s1.to_str().unwrap(),
        "-o",
        map.to_str().unwrap(),
        "--free-space-out",
        free.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let localize = |extra: &[&str]| {
        let mut args = vec!["localize", "--json", "--3dtk-valid", s2.to_str().unwrap()];
        args.push(free.to_str().unwrap());
        args.extend_from_slice(extra);
        json(&olmap(&args))
    };
    let window = localize(&["--guess", "0,0,0,0,0,0", "--window", "0.5,0.2,5"]);
    assert_eq!(window["trusted"], false, "{}", window["translation"]);
    let global = localize(&[]);
    let tx = global["T_target_source"][0][3].as_f64().unwrap();
    assert!(
        global["trusted"] == true && (tx - 3.378).abs() < 0.05,
        "{tx}"
    );
    let wrong = dir.path().join("free.olm");
    let out = olmap(&[
        "map",
        s0.to_str().unwrap(),
        "-o",
        dir.path().join("other.olm").to_str().unwrap(),
        "--free-space-out",
        wrong.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("(.bt)"), "{err}");
    assert!(!wrong.exists() && !dir.path().join("other.olm").exists());
}

#[test]
fn map_a_3dtk_folder_then_eval_and_export() {
    let Some(d) = data() else { return };
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("map.olm");
    let poses = dir.path().join("poses.txt");
    let report = dir.path().join("report.json");
    let folder = d.join("3dtk_dat");
    let v = json(&olmap(&[
        "map",
        "--json",
        folder.to_str().unwrap(),
        "-o",
        map.to_str().unwrap(),
        "--poses-out",
        poses.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "--scans-out",
        dir.path().join("scans").to_str().unwrap(),
    ]));
    assert_eq!(v["placed"].as_array().unwrap().len(), 3);
    // The scan-pose pairs: one list per scan and the same poses.
    for i in 0..3 {
        let l = olmap::occupancy::OccupancyList::read_olm_path(
            dir.path().join(format!("scans/scan00{i}.olm")),
        )
        .unwrap();
        // The scan's own voxels, less the few its own rays cleared (mixed pixels).
        let cloud = olmap::io::read_cloud(folder.join(format!("scan00{i}.3d")))
            .unwrap()
            .cloud;
        let hit = olmap::occupancy::OccupancyList::from_cloud(&cloud, 0.1)
            .unwrap()
            .len();
        assert!(
            l.len() <= hit && l.len() as f64 > 0.8 * hit as f64,
            "{} of {hit}",
            l.len()
        );
    }
    assert_eq!(
        std::fs::read_to_string(dir.path().join("scans/poses.txt")).unwrap(),
        std::fs::read_to_string(&poses).unwrap()
    );
    assert!(v["rejected"].as_array().unwrap().is_empty());
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(saved["placed"], v["placed"]);
    // The HTML report beside it: the map's top view and the entropy curve, inlined.
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert_eq!(html.matches("src=\"data:image/png;base64,").count(), 2);
    assert!(html.contains("scan002"));
    // Against the reference (data README §1.7 tolerances, checked on the total here).
    let reference = folder.join("reference_poses_rh_m.txt");
    let e = json(&olmap(&[
        "eval",
        "--json",
        "--poses",
        poses.to_str().unwrap(),
        "--reference",
        reference.to_str().unwrap(),
    ]));
    assert_eq!(e["summary"]["scans"], 3);
    assert!(e["summary"]["translation_m"]["max"].as_f64().unwrap() < 0.15);
    assert!(e["summary"]["rotation_deg"]["max"].as_f64().unwrap() < 3.0);
    // The saved map reloads to the same content and exports to .bt and .ply.
    let loaded = olmap::occupancy::read_map(&map).unwrap().map;
    assert_eq!(loaded.len() as u64, v["voxels"].as_u64().unwrap());
    for out in ["map.bt", "map.ply"] {
        let p = dir.path().join(out);
        assert!(
            olmap(&["export", map.to_str().unwrap(), "-o", p.to_str().unwrap()])
                .status
                .success()
        );
    }
    let bt = olmap::occupancy::read_map(dir.path().join("map.bt"))
        .unwrap()
        .map;
    assert_eq!(
        bt.sorted().iter().map(|(k, _)| *k).collect::<Vec<_>>(),
        loaded.sorted().iter().map(|(k, _)| *k).collect::<Vec<_>>()
    );
    let ply = olmap::io::read_cloud(dir.path().join("map.ply")).unwrap();
    assert_eq!(ply.cloud.len(), loaded.len());
}

#[test]
fn simulate_writes_a_dataset_and_refuses_to_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    let args = [
        "simulate",
        "--json",
        "--world",
        "box-room",
        "--robots",
        "2",
        "--scans-per-robot",
        "2",
        "--scanner",
        "lidar",
        "--scans2d",
        "-o",
        out.to_str().unwrap(),
    ];
    let v = json(&olmap(&args));
    assert_eq!(v["scans"], 4);
    let back = olmap::sim::read_dataset(&out).unwrap();
    assert_eq!(back.manifest.world, "box-room");
    assert_eq!(back.manifest.robots[1].scans2d.len(), 2);
    // In an empty room two robots 1 m or more apart see each other both ways.
    assert_eq!(
        v["mutual_sightings"].as_u64().unwrap(),
        v["sightings"].as_u64().unwrap()
    );
    let points: u64 = (0..2)
        .flat_map(|r| back.scan_paths(r))
        .map(|p| olmap::io::read_cloud(&p).unwrap().cloud.len() as u64)
        .sum();
    assert_eq!(points, v["points"].as_u64().unwrap());
    // Again into the same folder: refused, the folder untouched.
    let before = std::fs::read(out.join("manifest.json")).unwrap();
    let again = olmap(&args);
    assert!(!again.status.success());
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(err.contains("not empty"), "{err}");
    assert_eq!(std::fs::read(out.join("manifest.json")).unwrap(), before);
}

/// `--step` sets the drive between stops (here in the warehouse, along an aisle of its
/// serpentine route); a step that is not 0 < MIN <= MAX <= 20 m is refused before anything
/// is written.
#[test]
fn simulate_drives_the_given_step_and_refuses_a_bad_one() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("wh");
    let v = json(&olmap(&[
        "simulate",
        "--json",
        "--world",
        "warehouse",
        "--robots",
        "1",
        "--scans-per-robot",
        "4",
        "--step",
        "3,3",
        "--scanner",
        "lidar",
        "-o",
        out.to_str().unwrap(),
    ]));
    assert_eq!(v["world"], "warehouse");
    let truth = olmap::io::read_poses(out.join("robot0").join("truth.txt")).unwrap();
    for k in 1..4 {
        let a = truth
            .get(&format!("scan{:03}", k - 1))
            .unwrap()
            .translation();
        let b = truth.get(&format!("scan{k:03}")).unwrap().translation();
        // 3 m along the route, moved up to 0.2 m sideways at each stop (the route's jitter).
        let d = (b - a).norm();
        assert!((d - 3.0).abs() <= 0.45, "stop {k}: {d:.3} m from the last");
    }
    for bad in ["0,1", "3,2", "1,25", "1"] {
        let target = dir.path().join(format!("bad{}", bad.replace(',', "_")));
        let o = olmap(&[
            "simulate",
            "--world",
            "warehouse",
            "--step",
            bad,
            "-o",
            target.to_str().unwrap(),
        ]);
        assert!(!o.status.success(), "--step {bad} accepted");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("--step"), "{err}");
        assert!(!target.exists(), "--step {bad} wrote {}", target.display());
    }
}

#[test]
fn mutual_localisation_from_numbers() {
    // B 4 m ahead of A and facing it; beacons 0.07 m ahead of each scanner.
    let v = json(&olmap(&[
        "mutual", "--a", "3.93", "--alpha", "0", "--b", "3.93", "--beta", "-0", "--json",
    ]));
    assert!((v["x_m"].as_f64().unwrap() - 4.0).abs() < 1e-9);
    assert!((v["heading_deg"].as_f64().unwrap().abs() - 180.0).abs() < 1e-9);
    // A distractor (separations 0.5 m apart) is refused with the reason.
    let out = olmap(&[
        "mutual", "--a", "3.43", "--alpha", "0", "--b", "3.93", "--beta", "0",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("distractor"));
}

#[test]
fn grid2d_builds_a_ros_map_from_2d_scans() {
    use olmap::geometry::{Pose, PoseList};
    use olmap::grid2d::Trinary;
    let dir = tempfile::tempdir().unwrap();
    let world = olmap::sim::box_room(nalgebra::Vector3::new(8.0, 6.0, 3.0));
    let mut scanner = olmap::sim::PlanarScanner::sick_180_half_degree();
    scanner.noise.sigma = 0.01;
    // Four stops; the last turns on the spot at the first one (skipped by the buckets).
    let stops = [
        (2.0, 3.0, 0.0),
        (6.0, 3.0, 3.1),
        (4.0, 1.5, 1.6),
        (2.1, 3.0, 2.0),
    ];
    let mut list = PoseList::default();
    let mut files = Vec::new();
    for (k, &(x, y, yaw)) in stops.iter().enumerate() {
        let pose = Pose::from_xyz_ypr(x, y, 0.3, yaw, 0.0, 0.0);
        let name = format!("scan{k:03}");
        let path = dir.path().join(format!("{name}.csv"));
        scanner
            .scan(&world, &[], &pose, 1, k as u64)
            .write_csv_path(&path)
            .unwrap();
        list.push(name, pose);
        files.push(path.to_str().unwrap().to_string());
    }
    let poses = dir.path().join("poses.txt");
    list.write_path(&poses).unwrap();
    let pgm = dir.path().join("room.pgm");
    let mut args = vec!["grid2d", "--json", "--bucket-radius", "0.5"];
    args.extend(files.iter().map(String::as_str));
    args.extend([
        "--poses",
        poses.to_str().unwrap(),
        "-o",
        pgm.to_str().unwrap(),
    ]);
    let v = json(&olmap(&args));
    assert_eq!(v["scans"], 4);
    assert_eq!(v["scans_integrated"], 3);
    assert_eq!(v["scans_skipped_by_buckets"], 1);
    let yaml = dir.path().join("room.yaml");
    assert_eq!(v["yaml"], yaml.to_str().unwrap());
    let map = olmap::grid2d::read_ros_map(&yaml).unwrap();
    assert_eq!(map.resolution, 0.05);
    assert_eq!(v["width"], map.width);
    assert!((v["origin"][0].as_f64().unwrap() - map.origin[0]).abs() < 1e-9);
    let c = map.counts();
    assert_eq!(v["cells"]["free"], c.free);
    assert_eq!(v["cells"]["occupied"], c.occupied);
    assert_eq!(v["cells"]["unknown"], c.unknown);
    // The room's middle is free, its walls occupied, beyond them unknown.
    assert_eq!(map.at_world(4.0, 3.0), Some(Trinary::Free));
    // (The wall face x = 8 lies on a cell boundary: its returns fall on either side.)
    assert!([7.97, 8.02]
        .iter()
        .any(|&x| map.at_world(x, 3.0) == Some(Trinary::Occupied)));
    assert_eq!(map.at_world(4.0, -0.5), Some(Trinary::Unknown));
    // A scan without a pose is an error naming it.
    let stray = dir.path().join("stray.csv");
    std::fs::copy(&files[0], &stray).unwrap();
    let out = olmap(&[
        "grid2d",
        stray.to_str().unwrap(),
        "--poses",
        poses.to_str().unwrap(),
        "-o",
        pgm.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("stray"));
}

#[test]
fn beacons_finds_a_simulated_cylinder() {
    use nalgebra::{Point3, Vector3};
    use olmap::sim::{box_room, Material, Object, PlanarScanner, Shape};
    let room = box_room(Vector3::new(8.0, 6.0, 3.0));
    let cylinder = Object {
        shape: Shape::Cylinder {
            base: Point3::new(4.0, 3.5, 0.0),
            radius: 0.125,
            height: 1.0,
        },
        material: Material::BEACON,
        id: 1,
    };
    let mut scanner = PlanarScanner::sick_180_half_degree();
    scanner.noise.sigma = 0.005;
    let sensor = olmap::geometry::Pose::from_xyz_ypr(1.0, 3.0, 0.4, 0.0, 0.0, 0.0);
    let scan = scanner.scan(&room, &[cylinder], &sensor, 1, 0);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("scan.csv");
    scan.write_csv_path(&csv).unwrap();
    // The cylinder is 3 m ahead and 0.5 m to the left of the sensor.
    for method in ["lsq", "reflective", "rwht"] {
        let v = json(&olmap(&[
            "beacons",
            csv.to_str().unwrap(),
            "--radius",
            "0.125",
            "--method",
            method,
            "--json",
        ]));
        assert_eq!(v["method"], method);
        let d = v["detections"].as_array().unwrap();
        let hit = d.iter().find(|d| {
            (d["x"].as_f64().unwrap() - 3.0).abs() < 0.03
                && (d["y"].as_f64().unwrap() - 0.5).abs() < 0.03
        });
        assert!(hit.is_some(), "{method}: {v}");
        if method != "rwht" {
            assert_eq!(d.len(), 1, "{method}: {v}");
        }
    }
    let text = olmap(&["beacons", csv.to_str().unwrap()]);
    assert!(text.status.success());
    assert!(String::from_utf8_lossy(&text.stdout).contains("1 circle(s)"));
    let bad = olmap(&["beacons", csv.to_str().unwrap(), "--radius", "-1"]);
    assert!(!bad.status.success());
}

#[test]
fn mutual_localisation_from_two_simulated_scans() {
    use olmap::geometry::Pose;
    use olmap::sim::{box_room, PlanarScanner, RobotModel};
    let dir = tempfile::tempdir().unwrap();
    let world = box_room(nalgebra::Vector3::new(12.0, 10.0, 3.0));
    let model = RobotModel {
        beacon_radius: 0.075,
        ..RobotModel::front_beacon(0.15)
    };
    let a = Pose::from_xyz_ypr(3.0, 4.0, 0.0, 0.3, 0.0, 0.0);
    let b = Pose::from_xyz_ypr(7.0, 6.0, 0.0, -2.5, 0.0, 0.0);
    let mut scanner = PlanarScanner::sick_180_half_degree();
    scanner.noise.sigma = 0.01;
    let s = model.scanner2d_pose();
    let sa = scanner.scan(&world, &model.objects(1, &b), &(a * s), 1, 0);
    let sb = scanner.scan(&world, &model.objects(0, &a), &(b * s), 1, 1);
    let (pa, pb) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
    sa.write_csv_path(&pa).unwrap();
    sb.write_csv_path(&pb).unwrap();
    let v = json(&olmap(&[
        "mutual",
        "--scans",
        pa.to_str().unwrap(),
        pb.to_str().unwrap(),
        "--radius",
        "0.075",
        "--offset",
        "0.15",
        "--json",
    ]));
    let truth = a.inverse() * b;
    let (x, y) = (v["x_m"].as_f64().unwrap(), v["y_m"].as_f64().unwrap());
    let err = ((x - truth.translation().x).powi(2) + (y - truth.translation().y).powi(2)).sqrt();
    // The thesis' bound (3.37) for 1 cm noise and a 0.15 m beacon: a few centimetres.
    assert!(err < 0.05, "{err}");
}

#[test]
fn scanner_convert_and_repeatability_of_a_simulated_raw_log() {
    use olmap::geometry::Pose;
    use olmap::sim::{box_room, MirrorScanner, RangeNoise};
    let dir = tempfile::tempdir().unwrap();
    let size = nalgebra::Vector3::new(6.0, 5.0, 3.0);
    let world = box_room(size);
    let t = Pose::from_xyz_ypr(2.5, 2.0, 1.2, 0.3, 0.0, 0.0);
    let mut s = MirrorScanner::enhanced();
    s.noise = RangeNoise::none();
    s.mirror_period /= 4.0;
    s.revolutions = 1.0;
    s.start_phase = 1.1;
    let (truth, log) = s.scan_raw(&world, &[], &t, 1, 0);
    let raw = dir.path().join("scan.mirror");
    log.write_path(&raw).unwrap();
    let pcd = dir.path().join("scan.pcd");
    let v = json(&olmap(&[
        "scanner",
        "convert",
        raw.to_str().unwrap(),
        "-o",
        pcd.to_str().unwrap(),
        "--filter-mixed",
        "--json",
    ]));
    assert_eq!(v["mounting"], "enhanced");
    let n = v["points"].as_u64().unwrap() as usize;
    // Exact returns in a bare room: nothing is a mixed pixel, every return comes back.
    assert_eq!(v["dropped"]["mixed_pixels"], 0, "{v}");
    assert_eq!(n, truth.len(), "{v}");
    let cloud = olmap::io::read_cloud(&pcd).unwrap().cloud;
    assert_eq!(cloud.len(), n);
    for p in cloud.points() {
        let w = t.transform_point(&nalgebra::Point3::new(p.x as f64, p.y as f64, p.z as f64));
        let d = (0..3)
            .map(|k| w[k].abs().min((w[k] - size[k]).abs()))
            .fold(f64::INFINITY, f64::min);
        assert!(d < 1e-4, "{w} is {d} m off the room");
    }
    let r = json(&olmap(&[
        "scanner",
        "repeatability",
        pcd.to_str().unwrap(),
        pcd.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(r["mean"].as_f64().unwrap(), 0.0);
    assert_eq!(r["points"].as_u64().unwrap() as usize, n);
    // A log without encoder events is an error, not a panic.
    let mut bad = log.clone();
    bad.events.clear();
    bad.write_path(&raw).unwrap();
    let out = olmap(&[
        "scanner",
        "convert",
        raw.to_str().unwrap(),
        "-o",
        pcd.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("trigger"));
}

#[test]
fn bench_quick_json_reports_every_measure() {
    let v = json(&olmap(&["bench", "--quick", "--json", "--threads", "2"]));
    assert_eq!(v["repeat"], 1, "--quick runs each measure once");
    let num = |x: &serde_json::Value, what: &str| {
        x.as_f64()
            .unwrap_or_else(|| panic!("{what} is a number: {x}"))
    };
    assert!(num(&v["insertion"]["points"], "points") > 0.0);
    assert!(num(&v["insertion"]["points_per_second"], "insertion rate") > 0.0);
    assert!(num(&v["overlap"]["poses_per_second"], "pose rate") > 0.0);
    assert!(num(&v["overlap"]["voxel_lookups_per_second"], "lookup rate") > 0.0);
    for section in ["alignment", "localisation", "modes"] {
        let rows = v[section].as_array().expect("a list of runs");
        assert!(!rows.is_empty(), "{section}");
        for r in rows {
            assert!(num(&r["seconds"], "seconds") > 0.0, "{section}: {r}");
            assert!(num(&r["total_seconds"], "total") > 0.0, "{section}: {r}");
            assert!(num(&r["translation_error_m"], "error").is_finite(), "{r}");
            assert!(num(&r["rotation_error_deg"], "error").is_finite(), "{r}");
        }
    }
    // The simulated pair: within the finest search lattice (0.1 m, below 1 degree).
    let pair = &v["alignment"][0];
    assert!(num(&pair["translation_error_m"], "error") < 0.15, "{pair}");
    assert!(num(&pair["rotation_error_deg"], "error") < 1.0, "{pair}");
    // Both modes on the small problem: the exact search finds the exhaustive optimum, which
    // the multi-resolution search cannot beat.
    let score = |mode: &str| {
        let r = v["modes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["mode"] == mode)
            .unwrap_or_else(|| panic!("a {mode} run"));
        r["score"].as_i64().unwrap()
    };
    assert_eq!(score("exact"), score("exhaustive"));
    assert!(score("multires") <= score("exact"));
    assert!(num(&v["exact_over_multires_time"], "ratio") > 0.0);
    assert!(num(&v["mapping"]["seconds_per_scan"], "per scan") > 0.0);
    let threads = v["threads"].as_array().unwrap();
    assert_eq!(threads.first().unwrap()["threads"], 1);
    assert_eq!(threads.last().unwrap()["threads"], 2);
    for t in threads {
        assert!(num(&t["seconds"], "seconds") > 0.0 && num(&t["speedup"], "speedup") > 0.0);
    }
    if cfg!(target_os = "linux") {
        assert!(num(&v["peak_memory_bytes"], "memory") > 0.0);
    }
}

#[test]
fn align_with_the_exact_search_in_a_window() {
    let Some(d) = data() else { return };
    let s0 = d.join("3dtk_dat/scan000.3d");
    let s1 = d.join("3dtk_dat/scan001.3d");
    let (s0, s1) = (s0.to_str().unwrap(), s1.to_str().unwrap());
    let multires = json(&olmap(&[
        "align",
        "--json",
        "--3dtk-valid",
        "--no-refine",
        s1,
        s0,
    ]));
    let t = &multires["translation"];
    let yaw = multires["yaw_pitch_roll_deg"][0].as_f64().unwrap();
    // A window of ±0.5 m, ±0.3 m, ±5° centred 0.2 m and 2° off the multi-resolution pose.
    let guess = format!(
        "{},{},{},{},0,0",
        t[0].as_f64().unwrap() + 0.2,
        t[1].as_f64().unwrap() - 0.1,
        t[2].as_f64().unwrap(),
        yaw + 2.0
    );
    let windowed = |mode: &str| {
        json(&olmap(&[
            "align",
            "--json",
            "--3dtk-valid",
            "--search",
            mode,
            "--guess",
            &guess,
            "--window",
            "0.5,0.3,5",
            s1,
            s0,
        ]))
    };
    let (exact, fast) = (windowed("exact"), windowed("multires"));
    assert_eq!(exact["search"]["exact"], true);
    assert_eq!(fast["search"]["exact"], false);
    // The optimum of the window's lattice scores at least as well as the heuristic's pose.
    let score = |v: &serde_json::Value| v["search"]["score"].as_i64().unwrap();
    assert!(score(&exact) >= score(&fast));
    // After ICP, data README §1.6: scan001 is 1.568 m ahead of scan000 (5 cm, §1.7).
    let tx = exact["T_target_source"][0][3].as_f64().unwrap();
    assert!((tx - 1.568).abs() < 0.05, "{tx}");
    assert_eq!(exact["trusted"], true);
}

fn room_scan_pose() -> olmap::geometry::Pose {
    olmap::geometry::Pose::from_xyz_ypr(4.03, 3.04, 1.0, 0.0, 0.0, 0.0)
}

/// A second scan of the room from the same pose (another noise seed; the lidar is exact),
/// in the sensor frame, with a coarser beam pattern.
fn scanned_room_cloud(world: &olmap::sim::World) -> olmap::cloud::PointCloud {
    let lidar = olmap::sim::SpinningLidar {
        beams: 61,
        elevation_min: (-60f64).to_radians(),
        elevation_max: 60f64.to_radians(),
        azimuth_step: 1f64.to_radians(),
        noise: olmap::sim::RangeNoise::none(),
    };
    lidar.scan(world, &[], &room_scan_pose(), 2, 0)
}

/// A 8 x 6 x 3 m room (inner corner at (0.03, 0.04, 0.02), so no face lies on a 0.1 m voxel
/// boundary) scanned from (4.03, 3.04, 1.0) by a noise-free lidar: the map's end points,
/// written with the scan pose into `dir`.
fn scanned_room(dir: &std::path::Path) -> (olmap::sim::World, olmap::occupancy::OccupancyList) {
    use nalgebra::{Point3, Vector3};
    use olmap::sim::{room_shell, Material, Object, RangeNoise, SpinningLidar, World};
    let objects = room_shell(
        Point3::new(0.03, 0.04, 0.02),
        Vector3::new(8.0, 6.0, 3.0),
        0.1,
        true,
    )
    .into_iter()
    .enumerate()
    .map(|(i, shape)| Object {
        shape,
        material: Material::WALL,
        id: i as u32,
    })
    .collect();
    let world = World::new("room", objects);
    let lidar = SpinningLidar {
        beams: 241,
        elevation_min: (-60f64).to_radians(),
        elevation_max: 60f64.to_radians(),
        azimuth_step: 0.5f64.to_radians(),
        noise: RangeNoise::none(),
    };
    let pose = room_scan_pose();
    let cloud = lidar.scan(&world, &[], &pose, 1, 0);
    let mut map = olmap::occupancy::OccupancyList::new(0.1).unwrap();
    map.add_points(&cloud, &pose, 1);
    olmap::occupancy::write_map(dir.join("room.olm"), &map).unwrap();
    let mut poses = olmap::geometry::PoseList::default();
    poses.push("scan000", pose);
    poses.write_path(dir.join("poses.txt")).unwrap();
    (world, map)
}

#[test]
fn render_navgrid_and_query_a_scanned_room() {
    let dir = tempfile::tempdir().unwrap();
    let (world, map) = scanned_room(dir.path());
    let m = dir.path().join("room.olm");
    let m = m.to_str().unwrap();
    let voxel_diagonal = 3f64.sqrt() * 0.1;
    // Top view in a band: the walls' cells drawn, the inside left white (or grid grey).
    let top = dir.path().join("top.png");
    let v = json(&olmap(&[
        "render",
        m,
        "-o",
        top.to_str().unwrap(),
        "--band",
        "0.3,2.5",
        "--json",
    ]));
    let img = image::open(&top).unwrap().to_rgb8();
    assert_eq!(img.width() as u64, v["width"].as_u64().unwrap());
    let (x0, y1, px) = (
        v["x_min_m"].as_f64().unwrap(),
        v["y_max_m"].as_f64().unwrap(),
        v["pixel_m"].as_f64().unwrap(),
    );
    let at = |x: f64, y: f64| {
        img.get_pixel(((x - x0) / px) as u32, ((y1 - y) / px) as u32)
            .0
    };
    let blank = |p: [u8; 3]| p == [255, 255, 255] || p == [215, 215, 215];
    for y in [1.05, 3.05, 5.05] {
        assert!(
            !blank(at(0.05, y)) && !blank(at(8.05, y)),
            "walls at y = {y}"
        );
    }
    for (x, y) in [(2.05, 2.05), (4.05, 3.05), (6.55, 4.55)] {
        assert!(blank(at(x, y)), "inside at ({x}, {y})");
    }
    // Depth image: the centre pixel looks along +x from the scan position at the far wall.
    let depth = dir.path().join("depth.png");
    let v = json(&olmap(&[
        "render",
        m,
        "-o",
        depth.to_str().unwrap(),
        "--view",
        "depth",
        "--from",
        "4.03,3.04,1.0,0",
        "--size",
        "41x31",
        "--fov",
        "60",
        "--json",
    ]));
    let o = nalgebra::Point3::new(4.03, 3.04, 1.0);
    let truth = world
        .cast(&o, &nalgebra::Vector3::x(), 30.0)
        .unwrap()
        .distance;
    let centre = v["centre_range_m"].as_f64().unwrap();
    assert!(
        (centre - truth).abs() <= voxel_diagonal,
        "{centre} vs {truth}"
    );
    assert_eq!(image::open(&depth).unwrap().width(), 41);
    let r = olmap(&[
        "render",
        m,
        "-o",
        depth.to_str().unwrap(),
        "--view",
        "depth",
    ]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("--from"));
    // Overlap surface (Figure 6.6): the room's own scan, searched around a pose 0.36 m off
    // the truth, peaks at the scan position (within one 0.1 m sample) and heading.
    let pcd = dir.path().join("scan.pcd");
    let cloud = scanned_room_cloud(&world);
    olmap::io::write_cloud(&pcd, &cloud, &Default::default()).unwrap();
    let heat = dir.path().join("overlap.png");
    let v = json(&olmap(&[
        "render",
        m,
        "-o",
        heat.to_str().unwrap(),
        "--view",
        "overlap",
        "--scan",
        pcd.to_str().unwrap(),
        "--from",
        "4.33,2.84,1.0,0",
        "--half-width",
        "0.6",
        "--headings",
        "12",
        "--json",
    ]));
    let peak = &v["peak"];
    assert!(
        (peak["x_m"].as_f64().unwrap() - 4.03).abs() <= 0.1 + 1e-9,
        "{v}"
    );
    assert!(
        (peak["y_m"].as_f64().unwrap() - 3.04).abs() <= 0.1 + 1e-9,
        "{v}"
    );
    // The scan position is the room's centre: a half turn fits as well as none.
    let yaw = peak["yaw_deg"].as_f64().unwrap().rem_euclid(180.0);
    assert!(yaw.min(180.0 - yaw) < 1e-6, "{v}");
    assert_eq!(image::open(&heat).unwrap().width(), 13 * 4);
    // Navigation grid: inside free, walls occupied, outside unknown.
    let pgm = dir.path().join("grid.pgm");
    let poses = dir.path().join("poses.txt");
    let v = json(&olmap(&[
        "navgrid",
        m,
        "--poses",
        poses.to_str().unwrap(),
        "--band",
        "0.1,1.2",
        "-o",
        pgm.to_str().unwrap(),
        "--json",
    ]));
    let grid = olmap::grid2d::read_ros_map(v["yaml"].as_str().unwrap()).unwrap();
    use olmap::grid2d::Trinary;
    let c = |i: i32| (i as f64 + 0.5) * 0.1;
    for i in 1..=79 {
        for j in 1..=59 {
            assert_eq!(grid.at_world(c(i), c(j)), Some(Trinary::Free), "({i}, {j})");
        }
    }
    for j in 0..=60 {
        assert_eq!(grid.at_world(c(0), c(j)), Some(Trinary::Occupied));
        assert_eq!(grid.at_world(c(80), c(j)), Some(Trinary::Occupied));
    }
    assert_eq!(grid.at_world(c(-1), c(30)), Some(Trinary::Unknown));
    assert_eq!(v["free"].as_u64().unwrap() as usize, grid.counts().free);
    // Queries: a ray to the north wall, a wall voxel, free and blocked segments, a radius.
    let v = json(&olmap(&[
        "query",
        m,
        "--ray",
        "4.03,3.04,1.0,0,1,0",
        "--json",
    ]));
    let truth = world
        .cast(&o, &nalgebra::Vector3::y(), 30.0)
        .unwrap()
        .distance;
    let d = v["distance_m"].as_f64().unwrap();
    assert!((d - truth).abs() <= voxel_diagonal, "{d} vs {truth}");
    let v = json(&olmap(&["query", m, "--at", "0.05,3.05,1.05", "--json"]));
    assert_eq!(v["occupied"], true);
    let v = json(&olmap(&["query", m, "--segment", "2,2,1,6,4,1", "--json"]));
    assert_eq!(v["free"], true);
    let v = json(&olmap(&["query", m, "--segment", "2,2,1,9,2,1", "--json"]));
    assert_eq!(v["free"], false);
    let v = json(&olmap(&[
        "query",
        m,
        "--radius",
        "0.05,3.05,1.05,0.3",
        "--json",
    ]));
    let want = map
        .occupied_within(&nalgebra::Point3::new(0.05, 3.05, 1.05), 0.3)
        .unwrap()
        .len();
    assert!(want > 0);
    assert_eq!(v["count"].as_u64().unwrap() as usize, want);
    // One question at a time, and a bad one is refused.
    assert!(!olmap(&["query", m]).status.success());
    assert!(!olmap(&["query", m, "--ray", "1,2,3"]).status.success());
    for cmd in ["render", "navgrid", "query"] {
        let h = olmap(&[cmd, "--help"]);
        assert!(h.status.success());
        assert!(String::from_utf8_lossy(&h.stdout).contains("--json"));
    }
}

/// A map as a Rerun recording: with the `rerun` feature an `.rrd` file (Rerun's RRF2
/// framing) is written; without it the export is refused with a message naming the
/// feature, and nothing is written.
#[test]
fn export_rrd_writes_a_rerun_recording_or_names_the_feature() {
    let dir = tempfile::tempdir().unwrap();
    let mut map = olmap::occupancy::OccupancyList::new(0.1).unwrap();
    for i in 0..20 {
        let p = nalgebra::Point3::new(0.05 + 0.1 * i as f64, 0.05, 0.05 * i as f64);
        map.set(map.key_of(&p).unwrap(), 3).unwrap();
    }
    let olm = dir.path().join("map.olm");
    map.write_olm_path(&olm).unwrap();
    let poses = dir.path().join("poses.txt");
    std::fs::write(
        &poses,
        "robot0/scan000 1 0 0 0 0 1 0 0 0 0 1 0\nrobot0/scan001 1 0 0 1 0 1 0 0 0 0 1 0\n",
    )
    .unwrap();
    let rrd = dir.path().join("map.rrd");
    let out = olmap(&[
        "export",
        olm.to_str().unwrap(),
        "-o",
        rrd.to_str().unwrap(),
        "--poses",
        poses.to_str().unwrap(),
    ]);
    if cfg!(feature = "rerun") {
        assert!(out.status.success(), "{out:?}");
        let bytes = std::fs::read(&rrd).unwrap();
        assert_eq!(&bytes[..4], b"RRF2");
        assert!(bytes.len() > 20 * 12, "{} bytes for 20 voxels", bytes.len());
    } else {
        assert!(!out.status.success());
        assert!(String::from_utf8_lossy(&out.stderr).contains("--features rerun"));
        assert!(!rrd.exists());
    }
    // --poses only means something in a recording.
    let ply = dir.path().join("map.ply");
    let out = olmap(&[
        "export",
        olm.to_str().unwrap(),
        "-o",
        ply.to_str().unwrap(),
        "--poses",
        poses.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(!ply.exists());
}

#[test]
fn audit_map_report_dir_checked_before_compute_cli() {
    // The audit: `olmap map … --report nodir/r.json` computed everything, wrote the map
    // and poses, then failed. Now it fails first and writes nothing.
    let Some(d) = data() else { return };
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("m.olm");
    let poses = dir.path().join("p.txt");
    let report = dir.path().join("nodir/r.json");
    let out = olmap(&[
        "map",
        d.join("3dtk_dat").to_str().unwrap(),
        "-o",
        map.to_str().unwrap(),
        "--poses-out",
        poses.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("nodir") && err.contains("does not exist"),
        "{err}"
    );
    assert!(!map.exists() && !poses.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Found mapping a 2D log with `-o m.olm`: the planar pipeline mapped the whole log and
/// wrote the poses before finding it could not write a cloud named `.olm`. Now the map's
/// format is checked first and nothing is written.
#[test]
fn a_2d_log_map_with_an_unknown_cloud_format_fails_before_writing_anything() {
    let Some(d) = data() else { return };
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("m.olm");
    let poses = dir.path().join("p.txt");
    let out = olmap(&[
        "map",
        d.join("carmen_2d/intel-corrected.log.gz").to_str().unwrap(),
        "--dof",
        "xy-yaw",
        "--max-scans",
        "20",
        "-o",
        map.to_str().unwrap(),
        "--poses-out",
        poses.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("m.olm") && err.contains("cannot tell the output format"),
        "{err}"
    );
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

fn small_store(robots: u32, seqs: u32) -> olmap::team::ScanStore {
    let mut s = olmap::team::ScanStore::new();
    for robot in 0..robots {
        s.set_robot_name(robot, &format!("bot{robot}")).unwrap();
        for seq in 0..seqs {
            let points = (0..20)
                .map(|i| nalgebra::Point3::new(i as f32 * 0.1, seq as f32, robot as f32))
                .collect();
            s.insert(olmap::team::StoredScan {
                robot,
                seq,
                time: seq as f64,
                odometry: None,
                cloud: olmap::cloud::PointCloud::from_points(points),
                sightings: Vec::new(),
            })
            .unwrap();
        }
    }
    s
}

#[test]
fn store_info_merge_and_salvage() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let whole = small_store(2, 5);
    whole.robot_store(0).write(p("a.store")).unwrap();
    whole.robot_store(1).write(p("b.store")).unwrap();
    let v = json(&olmap(&[
        "store",
        "merge",
        &p("a.store"),
        &p("b.store"),
        "-o",
        &p("m.store"),
        "--json",
    ]));
    assert_eq!(v["records"], 10);
    assert_eq!(olmap::team::ScanStore::read(p("m.store")).unwrap(), whole);
    let v = json(&olmap(&["store", "info", &p("m.store"), "--json"]));
    assert_eq!(v["intact"], true);
    assert_eq!(v["version"], olmap::team::STORE_VERSION);
    assert_eq!(v["robots"][1]["name"], "bot1");
    assert_eq!(v["robots"][1]["last_seq"], 4);
    // One bad byte in the middle of the file: info says where (exit 1), salvage keeps
    // nine records of ten.
    let mut bytes = std::fs::read(p("m.store")).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x55;
    std::fs::write(p("bad.store"), &bytes).unwrap();
    let out = olmap(&["store", "info", &p("bad.store"), "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["intact"], false);
    assert_eq!(v["records"], 9);
    let start = v["damage"][0]["start"].as_u64().unwrap();
    let end = v["damage"][0]["end"].as_u64().unwrap();
    assert!(start <= mid as u64 && (mid as u64) < end, "{v}");
    let v = json(&olmap(&[
        "store",
        "salvage",
        &p("bad.store"),
        "-o",
        &p("fixed.store"),
        "--json",
    ]));
    assert_eq!(v["records_recovered"], 9);
    assert_eq!(v["records_lost"], 1);
    assert_eq!(
        olmap::team::ScanStore::read(p("fixed.store"))
            .unwrap()
            .len(),
        9
    );
    // The strict readers refuse the damaged file with its offset; text output works too.
    let out = olmap(&["store", "merge", &p("bad.store"), "-o", &p("x.store")]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("byte {start}")), "{err}");
    let out = olmap(&["store", "info", &p("bad.store")]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("DAMAGED"));
}

/// The names in `dir` a user sees (not hidden), sorted.
fn visible_names(dir: &std::path::Path) -> Vec<String> {
    let mut v: Vec<String> = match std::fs::read_dir(dir) {
        Ok(entries) => entries
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| !n.starts_with('.'))
            .collect(),
        Err(_) => Vec::new(),
    };
    v.sort();
    v
}

#[test]
fn audit_killed_run_leaves_no_partial_output() {
    // A team run killed at any moment leaves its output folder with the complete set or
    // nothing, never a part of it (the outputs are put in place together at the end).
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let sim = olmap(&[
        "simulate",
        "--robots",
        "2",
        "--scans-per-robot",
        "3",
        "--seed",
        "4",
        "--output",
        data.to_str().unwrap(),
    ]);
    assert!(sim.status.success());
    let complete = [
        "report.html",
        "report.json",
        "solo",
        "team.bt",
        "team.olm",
        "team.ply",
        "team.store",
        "team_poses.txt",
    ];
    for (i, delay_ms) in [100u64, 700, 2000, 5000].into_iter().enumerate() {
        let out = dir.path().join(format!("out{i}"));
        let mut child = Command::new(env!("CARGO_BIN_EXE_olmap"))
            .args([
                "team",
                data.to_str().unwrap(),
                "--solo",
                "-o",
                out.to_str().unwrap(),
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        let _ = child.kill();
        let status = child.wait().unwrap();
        let names = visible_names(&out);
        assert!(
            names.is_empty() || names == complete,
            "killed after {delay_ms} ms ({status}): {names:?}"
        );
    }
    // Run to the end: the complete set.
    let out = dir.path().join("whole");
    let r = olmap(&[
        "team",
        data.to_str().unwrap(),
        "--solo",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(r.status.success());
    assert_eq!(visible_names(&out), complete);
}

/// `olmap graph optimise` on parking-garage from the file's values: the JSON keys of the
/// issue, the published costs in Ceres' convention (README §5: 8,362.72 -> 0.6348), and
/// the written file's cost re-evaluated by `olmap graph info`.
#[test]
fn graph_optimise_json_and_the_written_file_cost() {
    let Some(d) = data() else { return };
    let input = d.join("pose_graphs/parking-garage.g2o");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("opt.g2o");
    let v = json(&olmap(&[
        "graph",
        "optimise",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--init",
        "none",
        "--iterations",
        "50",
        "--json",
    ]));
    for key in [
        "initial_cost",
        "final_cost",
        "iterations",
        "seconds",
        "cost_convention",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_eq!(v["cost_convention"], "ceres");
    assert_eq!(v["space"], "se3");
    assert_eq!(v["nodes"], 1661);
    assert_eq!(v["edges"], 6275);
    let initial = v["initial_cost"].as_f64().unwrap();
    assert!((initial - 8362.72).abs() < 0.01, "{initial}");
    let fin = v["final_cost"].as_f64().unwrap();
    assert!(fin <= 0.63485 && fin > 0.6348 * 0.998, "{fin}");
    let info = json(&olmap(&["graph", "info", "--json", out.to_str().unwrap()]));
    let written = info["cost_ceres"].as_f64().unwrap();
    assert!((written - fin).abs() <= 1e-9 * fin, "{written} vs {fin}");
}

#[test]
fn graph_optimise_refuses_a_bad_file_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.g2o");
    std::fs::write(
        &bad,
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0\n",
    )
    .unwrap();
    let out_path = dir.path().join("out.g2o");
    let out = olmap(&[
        "graph",
        "optimise",
        bad.to_str().unwrap(),
        "-o",
        out_path.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.g2o") && err.contains("line 3"), "{err}");
    assert!(!out_path.exists());
}

/// Issue 23's interface on a real 2D log: `olmap poses LOG --out reference.txt`, `olmap map
/// LOG --dof xy-yaw --odometry-noise … --noise-seed … --poses-out P`, `olmap eval` — the
/// names match, the map's own report and `eval` agree on the error, and the error is within
/// the bound on the first 300 scans of the Intel log.
#[test]
fn carmen_log_maps_and_evaluates_end_to_end() {
    let Some(d) = data() else { return };
    let log = d.join("carmen_2d/intel-corrected.log.gz");
    let log = log.to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let reference = dir.path().join("reference.txt");
    let poses = dir.path().join("poses.txt");
    let graph = dir.path().join("graph.g2o");
    let out = olmap(&["poses", log, "--out", reference.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = json(&olmap(&[
        "map",
        log,
        "--dof",
        "xy-yaw",
        "--odometry-noise",
        "0.05,2",
        "--noise-seed",
        "4",
        "--max-scans",
        "300",
        "--poses-out",
        poses.to_str().unwrap(),
        "--graph-out",
        graph.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(report["scans"], 300);
    assert_eq!(report["placed"], 300);
    let anchored = report["errors"]["anchored_rmse_m"].as_f64().unwrap();
    assert!(
        report["errors"]["ate_rmse_m"].as_f64().unwrap() <= 0.10,
        "{report}"
    );
    // `olmap eval` (anchored at the first scan, as the map's anchored error) agrees.
    let eval = json(&olmap(&[
        "eval",
        "--poses",
        poses.to_str().unwrap(),
        "--reference",
        reference.to_str().unwrap(),
        "--json",
    ]));
    let scans = eval["scans"].as_array().unwrap();
    assert_eq!(scans.len(), 300);
    let rms = (scans
        .iter()
        .map(|s| s["translation_m"].as_f64().unwrap().powi(2))
        .sum::<f64>()
        / 300.0)
        .sqrt();
    assert!(
        (rms - anchored).abs() < 1e-3,
        "eval {rms} vs map {anchored}"
    );
    // The graph file holds one vertex per scan and the edges the report counts.
    let g2o = std::fs::read_to_string(&graph).unwrap();
    assert_eq!(
        g2o.lines().filter(|l| l.starts_with("VERTEX_SE2")).count(),
        300
    );
    let edges: u64 = report["edges"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_u64().unwrap())
        .sum();
    assert_eq!(
        g2o.lines().filter(|l| l.starts_with("EDGE_SE2")).count() as u64,
        edges
    );
    // A 6-DoF request and a bad noise argument are refused with a clear error.
    let bad = olmap(&["map", log, "--dof", "6dof"]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("x-y-yaw"));
    let bad = olmap(&["map", log, "--odometry-noise", "0.05"]);
    assert!(!bad.status.success());
}
