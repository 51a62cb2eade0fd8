//! Simulated robots, sightings and datasets on disk (issue: built-in simulator).

use nalgebra::{Point3, Vector3};
use olmap::geometry::Pose;
use olmap::sim::{
    odometry_for, plan_trajectories, room_shell, sightings_at, simulate, Material, MotionModel,
    Object, OdometryNoise, RobotModel, Scanner3d, SightingModel, SimConfig, SimRng, SpinningLidar,
    World, WorldKind,
};
use olmap::sim::{read_dataset, write_dataset};

/// An 8 x 6 x 3 m room, optionally with a full-height wall across it at x = 4.
fn room(divided: bool) -> World {
    let mut shapes = room_shell(Point3::origin(), Vector3::new(8.0, 6.0, 3.0), 0.2, true);
    if divided {
        shapes.push(olmap::sim::Shape::aabb_box(
            Point3::new(3.9, 0.0, 0.0),
            Point3::new(4.1, 6.0, 3.0),
        ));
    }
    World::new(
        "room",
        shapes
            .into_iter()
            .map(|shape| Object {
                shape,
                material: Material::WALL,
                id: 0,
            })
            .collect(),
    )
}

fn exact() -> SightingModel {
    SightingModel {
        range_sigma: 0.0,
        angle_sigma: 0.0,
        ..Default::default()
    }
}

fn sight(world: &World, poses: &[Pose], sm: &SightingModel) -> Vec<olmap::sim::Sighting> {
    let model = RobotModel::default();
    let objects: Vec<Object> = poses
        .iter()
        .enumerate()
        .flat_map(|(r, p)| model.objects(r, p))
        .collect();
    sightings_at(world, &model, sm, poses, &objects, 0, 0.0, 1)
}

#[test]
fn sightings_are_exact_without_noise_and_mutual_when_two_way() {
    let world = room(false);
    // A at (2, 3) facing +x; B at (6, 3.5) facing -x: each in the other's view.
    let a = Pose::from_xyz_ypr(2.0, 3.0, 0.0, 0.0, 0.0, 0.0);
    let b = Pose::from_xyz_ypr(6.0, 3.5, 0.0, std::f64::consts::PI, 0.0, 0.0);
    let s = sight(&world, &[a, b], &exact());
    assert_eq!(s.len(), 2, "{s:?}");
    assert!(s.iter().all(|x| x.mutual));
    let ab = s.iter().find(|x| x.observer == 0).unwrap();
    // Beacon centre of B in A's robot frame: (4, 0.5) at the same height.
    let model = RobotModel::default();
    let expect = Point3::new(4.0, 0.5, model.beacon_center().z);
    assert!((ab.beacon - expect).norm() < 1e-9, "{:?}", ab.beacon);
    let dz = model.beacon_center().z - model.sensor_height;
    assert!((ab.range - (16.25f64 + dz * dz).sqrt()).abs() < 1e-9);
    assert!((ab.bearing - 0.5f64.atan2(4.0)).abs() < 1e-12);
}

#[test]
fn sightings_respect_walls_field_of_view_and_range() {
    let a = Pose::from_xyz_ypr(2.0, 3.0, 0.0, 0.0, 0.0, 0.0);
    let b = Pose::from_xyz_ypr(6.0, 3.0, 0.0, std::f64::consts::PI, 0.0, 0.0);
    // A wall between them: nobody sees anybody.
    assert!(sight(&room(true), &[a, b], &exact()).is_empty());
    // B turned away (A straight behind it, outside its 270° view): one-way, not mutual.
    let b_away = Pose::from_xyz_ypr(6.0, 3.0, 0.0, 0.0, 0.0, 0.0);
    let s = sight(&room(false), &[a, b_away], &exact());
    assert_eq!(s.len(), 1, "{s:?}");
    assert_eq!((s[0].observer, s[0].target, s[0].mutual), (0, 1, false));
    // Beyond the detection range: nothing.
    let short = SightingModel {
        max_range: 3.0,
        ..exact()
    };
    assert!(sight(&room(false), &[a, b], &short).is_empty());
    // A third robot standing in the line of sight hides B from A (but A and B still
    // see the one in the middle).
    let c = Pose::from_xyz_ypr(4.0, 3.0, 0.0, 0.0, 0.0, 0.0);
    let s = sight(&room(false), &[a, b, c], &exact());
    assert!(!s.iter().any(|x| (x.observer, x.target) == (0, 1)), "{s:?}");
    assert!(s.iter().any(|x| (x.observer, x.target) == (0, 2)));
}

#[test]
fn trajectories_keep_clear_and_odometry_errors_have_the_configured_spread() {
    let world = WorldKind::Lab.build(3);
    let model = RobotModel::default();
    let motion = MotionModel::default();
    let mut rng = SimRng::new(5);
    let paths = plan_trajectories(
        &world,
        &model,
        &motion,
        4,
        25,
        &mut rng,
        olmap::sim::free_spot,
    )
    .expect("room for four robots");
    for path in &paths {
        for w in path.windows(2) {
            let d = (w[1].translation() - w[0].translation()).norm();
            assert!(
                d == 0.0 || (motion.step.0 - 1e-9..=motion.step.1 + 1e-9).contains(&d),
                "{d}"
            );
        }
        for p in path {
            let t = p.translation();
            assert!(world.is_clear(t.x, t.y, model.body_radius, 0.05, 1.0));
        }
    }
    #[allow(clippy::needless_range_loop)]
    for k in 0..25 {
        for i in 0..4 {
            for j in i + 1..4 {
                let d = (paths[i][k].translation() - paths[j][k].translation()).norm();
                assert!(
                    d >= motion.robot_spacing - 1e-9,
                    "robots {i}, {j} at stop {k}: {d}"
                );
            }
        }
    }
    // Perfect odometry reproduces the motion from the identity.
    let odo = odometry_for(&paths[0], &OdometryNoise::none(), &mut rng);
    for (o, t) in odo.iter().zip(&paths[0]) {
        let expect = paths[0][0].inverse() * *t;
        assert!((o.translation() - expect.translation()).norm() < 1e-9);
    }
    // Random error per motion: the spread of the relative-motion errors matches sigma.
    let noise = OdometryNoise {
        scale_error: 0.0,
        yaw_drift_per_m: 0.0,
        ..OdometryNoise::degraded()
    };
    let motion_true = Pose::from_xyz_ypr(1.5, 0.0, 0.0, 0.2, 0.0, 0.0);
    let n = 20_000;
    let (mut sx, mut syaw) = (0.0, 0.0);
    for _ in 0..n {
        let m = noise.corrupt(&motion_true, &mut rng);
        sx += (m.translation().x - 1.5).powi(2);
        syaw += (m.yaw_pitch_roll().0 - 0.2).powi(2);
    }
    let (sx, syaw) = ((sx / n as f64).sqrt(), (syaw / n as f64).sqrt());
    assert!((sx / noise.sigma_xy - 1.0).abs() < 0.05, "{sx}");
    assert!((syaw / noise.sigma_yaw - 1.0).abs() < 0.05, "{syaw}");
}

/// A world with a route is driven round it: in the corridor ring (a 23 x 13 m centre
/// line, 72 m) each stop keeps the robot's clearance, lies within the jitter (2 σ = 0.2 m)
/// of the centre line, is one step (1-2 m along the route; the straight line is shorter
/// only round a corner) from the last, and 52 stops go round once and past the start;
/// a second robot starts half way round.
#[test]
fn robots_drive_round_a_route_and_close_the_loop() {
    let world = WorldKind::CorridorRing.build(2);
    let route = world.route().to_vec();
    let perimeter: f64 = (0..route.len())
        .map(|i| {
            let (a, b) = (route[i], route[(i + 1) % route.len()]);
            ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt()
        })
        .sum();
    assert!((perimeter - 72.0).abs() < 1e-9, "{perimeter}");
    let (model, motion) = (RobotModel::default(), MotionModel::default());
    let paths = plan_trajectories(
        &world,
        &model,
        &motion,
        2,
        52,
        &mut SimRng::new(9),
        olmap::sim::free_spot,
    )
    .expect("the route is clear");
    // Distance from the centre line: the ring's centre line is the rectangle
    // [1.5, 24.5] x [1.5, 14.5].
    let off_centre = |x: f64, y: f64| {
        let outside_x = (1.5 - x).max(x - 24.5).max(0.0);
        let outside_y = (1.5 - y).max(y - 14.5).max(0.0);
        if outside_x > 0.0 || outside_y > 0.0 {
            outside_x.hypot(outside_y)
        } else {
            let dx = (x - 1.5).abs().min((x - 24.5).abs());
            let dy = (y - 1.5).abs().min((y - 14.5).abs());
            dx.min(dy)
        }
    };
    for path in &paths {
        assert_eq!(path.len(), 52);
        for p in path {
            let t = p.translation();
            assert!(world.is_clear(t.x, t.y, model.body_radius + motion.margin, 0.05, 1.0));
            assert!(off_centre(t.x, t.y) <= 0.2 + 1e-9, "{t:?}");
        }
        for w in path.windows(2) {
            let d = (w[1].translation() - w[0].translation()).norm();
            assert!((0.25..=motion.step.1 + 0.41).contains(&d), "step {d}");
        }
    }
    let start = paths[0][0].translation();
    let back = paths[0][40..]
        .iter()
        .map(|p| (p.translation() - start).norm())
        .fold(f64::INFINITY, f64::min);
    assert!(
        back <= 2.0,
        "the loop does not come back to the start: {back} m"
    );
    let second = (paths[1][0].translation() - start).norm();
    assert!(second >= 10.0, "robot 1 starts {second} m from robot 0");
}

fn small_config(seed: u64) -> SimConfig {
    let lidar = SpinningLidar {
        beams: 16,
        azimuth_step: 2f64.to_radians(),
        ..Default::default()
    };
    SimConfig {
        world: WorldKind::Lab,
        seed,
        robots: 3,
        stops: 3,
        scanner: Scanner3d::Lidar(lidar),
        ..Default::default()
    }
}

fn folder_bytes(dir: &std::path::Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().display().to_string();
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn datasets_are_byte_identical_for_a_seed_and_read_back() {
    let tmp = tempfile::tempdir().unwrap();
    let write = |seed: u64, name: &str| {
        let data = simulate(&small_config(seed), |_, _| {}).unwrap();
        let dir = tmp.path().join(name);
        write_dataset(&dir, &data).unwrap();
        (data, dir)
    };
    let (data, a) = write(7, "a");
    let (_, b) = write(7, "b");
    let (_, c) = write(8, "c");
    let (fa, fb, fc) = (folder_bytes(&a), folder_bytes(&b), folder_bytes(&c));
    assert!(fa.len() >= 3 * 3 + 3 * 2 + 2, "{} files", fa.len());
    assert_eq!(fa, fb, "same seed, same bytes");
    assert_ne!(fa, fc, "another seed, another dataset");
    // Read back: poses and sightings as simulated.
    let back = read_dataset(&a).unwrap();
    assert_eq!(back.manifest.robots.len(), 3);
    assert_eq!(back.sightings, data.sightings);
    for (r, robot) in data.robots.iter().enumerate() {
        // Pose files hold the matrix to the bit; the quaternion rebuilt from it may differ
        // in the last bit.
        let same = |a: &Pose, b: &Pose| {
            (a.translation() - b.translation()).norm() < 1e-12
                && a.rotation().angle_to(&b.rotation()) < 1e-9
        };
        for k in 0..3 {
            assert!(same(&back.truth[r].poses[k].pose, &robot.truth[k]));
            assert!(same(&back.odometry[r].poses[k].pose, &robot.odometry[k]));
        }
        let scan = olmap::io::read_cloud(&back.scan_paths(r)[1]).unwrap().cloud;
        assert_eq!(scan.len(), robot.scans[1].len());
        assert_eq!(scan.origin(), robot.scans[1].origin());
    }
    // A non-empty folder is refused and left as it was.
    let err = write_dataset(&a, &data).unwrap_err().to_string();
    assert!(err.contains("not empty"), "{err}");
    assert_eq!(folder_bytes(&a), fa);
    // A manifest of another version is refused with the file named.
    let m = a.join("manifest.json");
    let text = std::fs::read_to_string(&m)
        .unwrap()
        .replace("\"version\": 1", "\"version\": 9");
    std::fs::write(&m, text).unwrap();
    let err = read_dataset(&a).unwrap_err().to_string();
    assert!(
        err.contains("manifest.json") && err.contains("version 9"),
        "{err}"
    );
}

#[test]
fn a_simulated_robot_maps_its_lab_with_a_register_band() {
    use olmap::mapping::{build_map, MapParams};
    // One robot, six stops, the enhanced mirror scanner (sigma 0.02 m), typical odometry.
    let config = SimConfig {
        world: WorldKind::Lab,
        seed: 11,
        robots: 1,
        stops: 6,
        ..Default::default()
    };
    let data = simulate(&config, |_, _| {}).unwrap();
    let robot = &data.robots[0];
    let scans = robot.scan_inputs();
    let params = MapParams {
        register_band: Some((0.1, 2.8)),
        ..Default::default()
    };
    let m = build_map(&scans, &params, |_, _| {}).unwrap();
    assert_eq!(m.placed.len(), 6, "{:?}", m.rejected);
    // Against the truth, in the first scan's frame: the alignment issue's tolerances for
    // 0.1 m voxels (a voxel and a degree).
    for p in &m.placed {
        let truth = robot.truth[0].inverse() * robot.truth[p.index];
        let e = (p.pose.translation() - truth.translation()).norm();
        let r = p.pose.rotation().angle_to(&truth.rotation()).to_degrees();
        assert!(e < 0.1 && r < 1.0, "{}: {e:.3} m, {r:.2} deg", p.name);
    }
}

#[test]
fn robot_clearing_removes_the_sighted_robot_and_nothing_else() {
    use olmap::team::{clear_robots, ClearingParams};
    // Robot 0 scans robot 1 standing 3 m ahead in an empty room; robot 0's sighting gives
    // robot 1's beacon (above its scanner, so over its centre) in robot 0's frame.
    let world = room(false);
    let model = RobotModel::default();
    let a = Pose::from_xyz_ypr(2.0, 3.0, 0.0, 0.0, 0.0, 0.0);
    let b = Pose::from_xyz_ypr(5.0, 3.2, 0.0, 1.0, 0.0, 0.0);
    let s = sight(&world, &[a, b], &exact());
    let seen = s.iter().find(|x| x.observer == 0).expect("a sees b");
    let lidar = SpinningLidar {
        noise: olmap::sim::RangeNoise::none(),
        ..Default::default()
    };
    let scan = lidar
        .scan(
            &world,
            &model.objects(1, &b),
            &(a * model.sensor_pose()),
            1,
            0,
        )
        .transformed(&model.sensor_pose());
    // Robot 1's body and beacon, in robot 0's frame: within its radius of (3, 0.2).
    let on_robot = |p: &nalgebra::Point3<f32>| {
        ((p.x as f64 - 3.0).powi(2) + (p.y as f64 - 0.2).powi(2)).sqrt() < model.body_radius + 1e-3
    };
    let before = scan.points().iter().filter(|p| on_robot(p)).count();
    assert!(before > 50, "the lidar sees robot 1 ({before} points)");
    let params = ClearingParams {
        radius: model.body_radius + 0.1,
        height: 2.0,
    };
    let (kept, removed) = clear_robots(&scan, &[(seen.beacon.x, seen.beacon.y)], &params).unwrap();
    assert_eq!(kept.points().iter().filter(|p| on_robot(p)).count(), 0);
    assert_eq!(kept.len() + removed, scan.len());
    // Only what stood within the cylinder went (here: the robot and the floor under it).
    let near = |p: &nalgebra::Point3<f32>| {
        ((p.x as f64 - seen.beacon.x).powi(2) + (p.y as f64 - seen.beacon.y).powi(2)).sqrt()
            <= params.radius
    };
    assert_eq!(
        removed,
        scan.points()
            .iter()
            .filter(|p| near(p) && p.z < 2.0)
            .count()
    );
    assert!(removed >= before);
    assert!(clear_robots(
        &scan,
        &[],
        &ClearingParams {
            radius: f64::NAN,
            height: 2.0
        }
    )
    .is_err());
}
