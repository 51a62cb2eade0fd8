//! The library pipelines front ends call: pose files by extension, scan files of folders
//! and lists, odometry matching, `run_map_job` and `run_team_pipeline` with their typed
//! reports (what they write is what they report).

use std::path::{Path, PathBuf};

use olmap::cloud::PointCloud;
use olmap::geometry::{Pose, PoseError, PoseList};
use olmap::io::{self, slam6d, WriteOptions};
use olmap::mapping::{odometry_for, run_map_job, MapJob, MapParams, MapReport, OdometrySource};
use olmap::sim::{simulate, OdometryNoise, SimConfig, WorldKind};
use olmap::team::{run_team_pipeline, TeamJob, TeamParams, TeamReport};
use olmap::Error;

fn pose(x: f64, y: f64, yaw_deg: f64) -> Pose {
    Pose::from_xyz_ypr(x, y, 0.2, yaw_deg.to_radians(), 0.0, 0.0)
}

fn close(a: &Pose, b: &Pose) -> bool {
    let e = PoseError::between(a, b);
    // 3DTK files hold centimetres and degrees as text: micrometres and microdegrees.
    e.translation_m < 1e-6 && e.rotation_deg < 1e-4
}

fn write(path: &Path, f: impl FnOnce(&mut Vec<u8>) -> std::io::Result<()>) {
    let mut bytes = Vec::new();
    f(&mut bytes).unwrap();
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn read_poses_tells_pose_files_apart_by_extension() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (pose(1.0, 2.0, 30.0), pose(-3.0, 0.5, -100.0));
    let mut list = PoseList::default();
    list.push("scan000", a);
    list.push("scan001", b);
    let txt = dir.path().join("poses.txt");
    list.write_path(&txt).unwrap();
    let csv = dir.path().join("table.csv");
    write(&csv, |w| io::csv::write_pose_table(w, &list));
    let one = dir.path().join("scan007.pose");
    write(&one, |w| slam6d::write_pose(w, &a));
    let frames = dir.path().join("scan009.frames");
    let f = |pose| slam6d::Frame { pose, algo: None };
    write(&frames, |w| slam6d::write_frames(w, &[f(a), f(b)]));

    for path in [&txt, &csv] {
        let got = io::read_poses(path).unwrap();
        assert_eq!(got.len(), 2, "{}", path.display());
        assert!(close(got.get("scan000").unwrap(), &a), "{}", path.display());
        assert!(close(got.get("scan001").unwrap(), &b), "{}", path.display());
    }
    let got = io::read_poses(&one).unwrap();
    assert_eq!(got.poses[0].name, "scan007");
    assert!(close(&got.poses[0].pose, &a));
    // A .frames file gives its final frame, or every frame named STEM#i.
    let last = io::read_poses(&frames).unwrap();
    assert_eq!(last.len(), 1);
    assert!(close(last.get("scan009").unwrap(), &b));
    let all = io::read_poses_with(&frames, true).unwrap();
    let names: Vec<&str> = all.poses.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["scan009#0", "scan009#1"]);
    assert!(close(&all.poses[0].pose, &a));
}

fn touch(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, "1 2 3\n").unwrap();
    p
}

#[test]
fn scan_files_follow_the_folder_rules() {
    let root = tempfile::tempdir().unwrap();
    // A 3DTK folder: only the .3d scans, sorted, not the text files beside them.
    let tdk = root.path().join("tdk");
    std::fs::create_dir(&tdk).unwrap();
    for n in ["scan001.3d", "scan000.3d", "notes.txt", "scan000.pose"] {
        touch(&tdk, n);
    }
    // Any other folder: every cloud file, sorted; poses and unknown files left out.
    let mixed = root.path().join("mixed");
    std::fs::create_dir(&mixed).unwrap();
    for n in ["b.xyz", "a.pcd", "c.pose", "readme.md"] {
        touch(&mixed, n);
    }
    let got = io::scan_files(std::slice::from_ref(&tdk), None).unwrap();
    assert_eq!(got, [tdk.join("scan000.3d"), tdk.join("scan001.3d")]);
    let got = io::scan_files(std::slice::from_ref(&mixed), None).unwrap();
    assert_eq!(got, [mixed.join("a.pcd"), mixed.join("b.xyz")]);
    // A list file: paths relative to its folder, comments and blank lines skipped, after
    // the paths given directly.
    let list = root.path().join("list.txt");
    std::fs::write(&list, "# scans\nmixed/b.xyz\n\n  tdk/scan001.3d  \n").unwrap();
    let direct = mixed.join("a.pcd");
    let got = io::scan_files(std::slice::from_ref(&direct), Some(&list)).unwrap();
    assert_eq!(
        got,
        [
            direct,
            root.path().join("mixed/b.xyz"),
            root.path().join("tdk/scan001.3d")
        ]
    );
    // Nothing at all is an empty input, not a map of nothing.
    let empty = root.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    assert!(matches!(
        io::scan_files(&[empty], None),
        Err(Error::EmptyInput { .. })
    ));
}

#[test]
fn odometry_is_matched_by_name_or_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let paths: Vec<PathBuf> = ["s0.pcd", "s1.pcd"]
        .iter()
        .map(|n| dir.path().join(n))
        .collect();
    let (a, b) = (pose(1.0, 0.0, 0.0), pose(2.0, 0.0, 10.0));
    let file = |names: &[&str], name: &str| {
        let mut list = PoseList::default();
        for (n, p) in names.iter().zip([b, a, a]) {
            list.push(*n, p);
        }
        let path = dir.path().join(name);
        list.write_path(&path).unwrap();
        OdometrySource::File(path)
    };
    // By name, whatever the order in the file.
    let got = odometry_for(&file(&["s1", "s0"], "named.txt"), &paths).unwrap();
    assert_eq!(got, [Some(a), Some(b)]);
    // Names that match nothing, one pose per scan: in order.
    let got = odometry_for(&file(&["x", "y"], "ordered.txt"), &paths).unwrap();
    assert_eq!(got, [Some(b), Some(a)]);
    // Neither: the missing scan is named.
    let err = odometry_for(&file(&["x", "y", "z"], "other.txt"), &paths).unwrap_err();
    assert!(
        matches!(&err, Error::NotFound { what } if what.contains("s0")),
        "{err}"
    );
    assert_eq!(
        odometry_for(&OdometrySource::None, &paths).unwrap(),
        [None, None]
    );
}

#[test]
fn map_job_writes_what_its_report_says() {
    let dir = tempfile::tempdir().unwrap();
    let room = olmap::fixtures::furnished_room(0.05);
    let stops = [
        pose(3.0, 3.0, 0.0),
        pose(4.0, 3.4, 15.0),
        pose(5.0, 4.0, 30.0),
    ];
    let mut scans = Vec::new();
    for (i, p) in stops.iter().enumerate() {
        let cloud: PointCloud = olmap::fixtures::scan_of(&room, p, 12.0);
        let path = dir.path().join(format!("scan{i}.pcd"));
        io::write_cloud(&path, &cloud, &WriteOptions::default()).unwrap();
        scans.push(path);
    }
    let out = dir.path().join("map.olm");
    let job = MapJob {
        scans: scans.clone(),
        odometry: OdometrySource::None,
        read: Default::default(),
        first: Some("scan1".into()),
        params: MapParams::default(),
        output: out.clone(),
        poses_out: Some(dir.path().join("poses.txt")),
        free_space_out: None,
        scans_out: None,
        report: Some(dir.path().join("report.json")),
        graph_out: None,
    };
    let run = run_map_job(&job, &mut |_, _, _| {}).unwrap();
    assert_eq!(run.report.scans, 3);
    assert_eq!(run.report.placed.len(), run.build.placed.len());
    // The named first scan defines the frame.
    assert_eq!(run.report.placed[0].name, "scan1");
    assert_eq!(run.report.placed[0].order, 0);
    // What was written is what was reported.
    let text = std::fs::read_to_string(dir.path().join("report.json")).unwrap();
    let back: MapReport = serde_json::from_str(&text).unwrap();
    assert_eq!(back, run.report);
    let map = olmap::occupancy::read_map(&out).unwrap().map;
    assert_eq!(map.len(), run.report.voxels);
    let poses = PoseList::read_path(dir.path().join("poses.txt")).unwrap();
    let names: Vec<&str> = poses.poses.iter().map(|p| p.name.as_str()).collect();
    let reported: Vec<&str> = run.report.placed.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, reported);
    #[cfg(feature = "render")]
    assert!(dir.path().join("report.html").is_file());

    // A first scan that is not there, and an output that is not a map, are refused
    // (the output before anything is read).
    let mut bad = job.clone();
    bad.first = Some("scan9".into());
    assert!(matches!(
        run_map_job(&bad, &mut |_, _, _| {}),
        Err(Error::NotFound { .. })
    ));
    let mut bad = job;
    bad.scans = vec![dir.path().join("missing.pcd")];
    bad.output = dir.path().join("map.png");
    assert!(matches!(
        run_map_job(&bad, &mut |_, _, _| {}),
        Err(Error::InvalidArgument(m)) if m.contains("map.png")
    ));
}

#[test]
fn team_pipeline_writes_what_its_report_says() {
    let data = simulate(
        &SimConfig {
            world: WorldKind::Lab,
            seed: 2,
            robots: 2,
            stops: 3,
            odometry: OdometryNoise::degraded(),
            ..Default::default()
        },
        |_, _| {},
    )
    .unwrap();
    let store = data.to_store().unwrap();
    let truth = data.truth_list(&store);
    assert_eq!(truth.len(), store.len());
    let dir = tempfile::tempdir().unwrap();
    let run = run_team_pipeline(
        &TeamJob {
            store: &store,
            truth: Some(&truth),
            params: &TeamParams::default(),
            out: dir.path(),
            solo: true,
        },
        &mut |_, _, _| {},
    )
    .unwrap();
    let r = &run.report;
    assert_eq!(r.format, olmap::team::TEAM_REPORT_FORMAT);
    assert_eq!(r.scans, store.len());
    assert_eq!(r.robots, ["robot0", "robot1"]);
    assert_eq!(r.placements.len(), run.team.build.placed.len());
    let team = r.evaluation.team.as_ref().expect("a truth was given");
    assert_eq!(team.compared, r.placements.len());
    assert_eq!(
        team.histogram.iter().map(|b| b.count).sum::<usize>(),
        team.compared
    );
    assert_eq!(r.evaluation.solo_per_robot.len(), 2);
    assert!(r.evaluation.solo.is_some());
    // Every placement with a truth carries its error, and the report file is the report.
    assert!(r.placements.iter().all(|p| p.error.is_some()));
    let text = std::fs::read_to_string(dir.path().join("report.json")).unwrap();
    let back: TeamReport = serde_json::from_str(&text).unwrap();
    assert_eq!(&back, r);
    let poses = PoseList::read_path(dir.path().join("team_poses.txt")).unwrap();
    assert_eq!(poses.len(), r.placements.len());
    for robot in ["robot0", "robot1"] {
        assert!(dir.path().join(format!("solo/{robot}.olm")).is_file());
    }
    let map = olmap::occupancy::read_map(dir.path().join("team.olm"))
        .unwrap()
        .map;
    assert_eq!(map.len(), r.voxels);
}

/// The errors a caller acts on are told apart by variant, not by message.
#[test]
fn typed_errors_say_what_a_caller_can_do() {
    use olmap::align::{register, RegisterParams};
    use olmap::grid2d::OccupancyGrid2d;
    use olmap::team::{map_team, ScanStore};

    let room = olmap::fixtures::furnished_room(0.1);
    let scan = olmap::fixtures::scan_of(&room, &pose(3.0, 3.0, 0.0), 12.0);
    let nothing = PointCloud::from_points(Vec::new());
    // Nothing to align onto, or nothing of the scan in range: empty inputs.
    assert!(matches!(
        register(&scan, &nothing, &RegisterParams::default()),
        Err(Error::EmptyInput { .. })
    ));
    // Every point 100 m from the sensor (at the origin), beyond the 30 m range.
    let far = PointCloud::from_points(
        (0..50)
            .map(|i| nalgebra::Point3::new(100.0, i as f32 * 0.1, 1.0))
            .collect(),
    );
    assert!(matches!(
        register(&far, &scan, &RegisterParams::default()),
        Err(Error::EmptyInput { .. })
    ));
    assert!(matches!(
        map_team(&ScanStore::new(), &TeamParams::default(), |_, _| {}),
        Err(Error::EmptyInput { .. })
    ));
    // A grid beyond the cell limit: too large, and the message names the limit.
    let err = OccupancyGrid2d::fixed(0.05, (0.0, 0.0), 1 << 20, 1 << 20).unwrap_err();
    assert!(
        matches!(&err, Error::TooLarge { limit, .. } if limit.contains("cells")),
        "{err}"
    );
    // A bad parameter stays an invalid argument.
    assert!(matches!(
        OccupancyGrid2d::new(-1.0),
        Err(Error::InvalidArgument(_))
    ));
}
