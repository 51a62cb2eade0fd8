//! Circle (beacon) detection in simulated 2D scans with ground truth, and landmark
//! localisation (thesis §2.4-2.5).
//!
//! The detection experiment prints its numbers: run
//! `cargo test --release -p olmap --test it beacon -- --nocapture`.

use std::time::Instant;

use nalgebra::{Point2, Point3, Vector3};
use olmap::beacon::landmark::{
    localisation_error, match_landmarks, pose_change_from_landmarks, MotionLimits, Pose2,
};
use olmap::beacon::{
    detect_circles_lsq, detect_circles_reflective, detect_circles_rwht, Detection, LsqParams,
    ReflectiveParams, RwhtParams,
};
use olmap::cloud::LaserScan;
use olmap::error::{Location, ParseError};
use olmap::geometry::Pose;
use olmap::sim::{room_shell, Material, Object, PlanarScanner, Shape, SimRng, World};

const RADIUS: f64 = 0.125;
/// A detection within this distance of a true centre finds it.
const MATCH: f64 = 0.1;
const SENSOR_HEIGHT: f64 = 0.4;

/// A room with clutter and two cylinders, a sensor, and the cylinders' truth.
struct Scene {
    world: World,
    sensor: Pose,
    /// True centres in the sensor frame.
    truth: Vec<Point2<f64>>,
}

impl Scene {
    /// A room 9-14 m square with walls, six clutter boxes and two cylinders of radius
    /// 0.125 m at random places 1-8 m from the sensor (bearing within ±80°), made of
    /// `materials[k]`.
    fn random(seed: u64, materials: [Material; 2]) -> Scene {
        let mut rng = SimRng::new(seed);
        let (w, h) = (rng.range(9.0, 14.0), rng.range(9.0, 14.0));
        let mut objects: Vec<Object> =
            room_shell(Point3::origin(), Vector3::new(w, h, 2.5), 0.1, false)
                .into_iter()
                .map(|shape| Object {
                    shape,
                    material: Material::WALL,
                    id: 0,
                })
                .collect();
        let (sx, sy) = (rng.range(0.8, 2.0), rng.range(0.3 * h, 0.7 * h));
        let yaw = rng.range(-0.3, 0.3);
        let sensor = Pose::from_xyz_ypr(sx, sy, SENSOR_HEIGHT, yaw, 0.0, 0.0);
        let mut world_centres: Vec<Point2<f64>> = Vec::new();
        while world_centres.len() < 2 {
            let (r, b) = (rng.range(1.0, 8.0), rng.range(-80f64, 80.0).to_radians());
            let p = sensor.transform_point(&Point3::new(r * b.cos(), r * b.sin(), 0.0));
            let c = Point2::new(p.x, p.y);
            let inside = c.x > 0.4 && c.y > 0.4 && c.x < w - 0.4 && c.y < h - 0.4;
            if inside && world_centres.iter().all(|o| (o - c).norm() > 0.6) {
                world_centres.push(c);
            }
        }
        for (k, c) in world_centres.iter().enumerate() {
            objects.push(Object {
                shape: Shape::Cylinder {
                    base: Point3::new(c.x, c.y, 0.0),
                    radius: RADIUS,
                    height: 1.0,
                },
                material: materials[k],
                id: k as u32 + 1,
            });
        }
        let mut boxes = 0;
        for _ in 0..200 {
            if boxes == 6 {
                break;
            }
            let half = Vector3::new(
                rng.range(0.1, 0.4),
                rng.range(0.1, 0.4),
                rng.range(0.3, 0.5),
            );
            let c = Point2::new(rng.range(0.5, w - 0.5), rng.range(0.5, h - 0.5));
            let reach = half.xy().norm();
            let clear_sensor = (c - Point2::new(sx, sy)).norm() > reach + 0.8;
            let clear_cyl = world_centres
                .iter()
                .all(|o| (o - c).norm() > reach + RADIUS + 0.3);
            if clear_sensor && clear_cyl {
                objects.push(Object {
                    shape: Shape::Box {
                        center: Point3::new(c.x, c.y, half.z),
                        half,
                        yaw: rng.range(0.0, std::f64::consts::PI),
                    },
                    material: Material::FURNITURE,
                    id: 0,
                });
                boxes += 1;
            }
        }
        let inv = sensor.inverse();
        let truth = world_centres
            .iter()
            .map(|c| {
                let p = inv.transform_point(&Point3::new(c.x, c.y, SENSOR_HEIGHT));
                Point2::new(p.x, p.y)
            })
            .collect();
        Scene {
            world: World::new("beacon test room", objects),
            sensor,
            truth,
        }
    }

    fn scan(&self, scanner: &PlanarScanner, seed: u64) -> LaserScan {
        scanner.scan(&self.world, &[], &self.sensor, seed, 0)
    }

    /// Whether cylinder `k` is in full view: at least three beams of the scan geometry hit
    /// it and every beam passing more than 1 cm inside its tangents hits it (nothing
    /// occludes it, it is inside the field of view).
    fn fully_visible(&self, k: usize, scan: &LaserScan) -> bool {
        let c = self.truth[k];
        let (range, bearing) = (c.coords.norm(), c.y.atan2(c.x));
        let origin = Point3::from(self.sensor.translation());
        let rot = self.sensor.rotation();
        let half = (RADIUS / range).asin();
        let core = ((RADIUS - 0.01) / range).asin();
        if bearing - core < scan.angle(0) || bearing + core > scan.angle(scan.len() - 1) {
            return false;
        }
        let mut hits = 0;
        for i in 0..scan.len() {
            let off = (scan.angle(i) - bearing).abs();
            if off > half {
                continue;
            }
            let a = scan.angle(i);
            let dir = rot * Vector3::new(a.cos(), a.sin(), 0.0);
            let hit = self.world.cast(&origin, &dir, 8.0);
            let on = hit.is_some_and(|h| h.id == k as u32 + 1);
            if on {
                hits += 1;
            } else if off <= core {
                return false;
            }
        }
        hits >= 3
    }
}

/// Detection statistics over many scans.
#[derive(Default, Debug)]
struct Tally {
    scans: usize,
    visible: usize,
    visible_found: usize,
    all: usize,
    all_found: usize,
    false_positives: usize,
    error_sum: f64,
    errors: usize,
    seconds: f64,
}

impl Tally {
    fn add(&mut self, found: &[Detection], truth: &[Point2<f64>], visible: &[bool], seconds: f64) {
        self.scans += 1;
        self.seconds += seconds;
        let mut used = vec![false; found.len()];
        for (k, t) in truth.iter().enumerate() {
            let best = found
                .iter()
                .enumerate()
                .filter(|(j, _)| !used[*j])
                .map(|(j, d)| (j, (d.center - t).norm()))
                .filter(|(_, e)| *e <= MATCH)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            self.all += 1;
            if visible[k] {
                self.visible += 1;
            }
            if let Some((j, e)) = best {
                used[j] = true;
                self.all_found += 1;
                if visible[k] {
                    self.visible_found += 1;
                }
                self.error_sum += e;
                self.errors += 1;
            }
        }
        self.false_positives += used.iter().filter(|u| !**u).count();
    }

    fn rate(&self) -> f64 {
        self.visible_found as f64 / self.visible.max(1) as f64
    }

    fn fp_per_scan(&self) -> f64 {
        self.false_positives as f64 / self.scans.max(1) as f64
    }

    fn mean_error(&self) -> f64 {
        self.error_sum / self.errors.max(1) as f64
    }

    fn report(&self, name: &str) {
        eprintln!(
            "{name:>18}: detected {:5.1} % of {} fully visible cylinders ({:5.1} % of all {}), \
             {:.2} false positives per scan, mean centre error {:6.2} mm, {:8.1} µs per scan",
            100.0 * self.rate(),
            self.visible,
            100.0 * self.all_found as f64 / self.all.max(1) as f64,
            self.all,
            self.fp_per_scan(),
            1000.0 * self.mean_error(),
            1e6 * self.seconds / self.scans.max(1) as f64,
        );
    }
}

fn scanner(sigma: f64) -> PlanarScanner {
    let mut s = PlanarScanner::sick_180_half_degree();
    s.noise.sigma = sigma;
    s
}

fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = Instant::now();
    let v = f();
    (v, t.elapsed().as_secs_f64())
}

/// Thesis §2.4.2: least squares detects 98 % of circles against 50 % for the RWHT and is
/// 25 times more accurate. 200 random rooms, two plain cylinders each, 1 cm range noise.
#[test]
fn lsq_beats_rwht_on_simulated_rooms() {
    let scanner = scanner(0.01);
    let lsq = LsqParams::default();
    let lsq_polar = LsqParams {
        refine_iterations: 0,
        ..lsq
    };
    let lsq_loose = LsqParams {
        max_rms: 0.0125,
        ..lsq
    };
    let rwht = RwhtParams::default();
    let mut t_lsq = Tally::default();
    let mut t_polar = Tally::default();
    let mut t_loose = Tally::default();
    let mut t_rwht = Tally::default();
    for seed in 0..200u64 {
        let scene = Scene::random(1000 + seed, [Material::FURNITURE; 2]);
        let scan = scene.scan(&scanner, seed);
        let visible: Vec<bool> = (0..2).map(|k| scene.fully_visible(k, &scan)).collect();
        let (found, s) = timed(|| detect_circles_lsq(&scan, RADIUS, &lsq));
        t_lsq.add(&found, &scene.truth, &visible, s);
        let (found, s) = timed(|| detect_circles_lsq(&scan, RADIUS, &lsq_polar));
        t_polar.add(&found, &scene.truth, &visible, s);
        let (found, s) = timed(|| detect_circles_lsq(&scan, RADIUS, &lsq_loose));
        t_loose.add(&found, &scene.truth, &visible, s);
        let (found, s) = timed(|| detect_circles_rwht(&scan, RADIUS, &rwht));
        t_rwht.add(&found, &scene.truth, &visible, s);
    }
    t_lsq.report("LSQ");
    t_polar.report("LSQ polar fit only");
    t_loose.report("LSQ max_rms 1.25 cm");
    t_rwht.report("RWHT");
    assert!(t_lsq.visible >= 250, "too few visible cylinders: {t_lsq:?}");
    assert!(t_lsq.rate() > t_rwht.rate(), "{t_lsq:?} {t_rwht:?}");
    assert!(
        t_lsq.mean_error() < t_rwht.mean_error(),
        "{t_lsq:?} {t_rwht:?}"
    );
    assert!(t_lsq.rate() >= 0.85, "{t_lsq:?}");
    assert!(t_loose.rate() >= 0.95, "{t_loose:?}");
    assert!(t_lsq.mean_error() < 0.01, "{t_lsq:?}");
    assert!(t_lsq.fp_per_scan() < 0.2, "{t_lsq:?}");
}

/// Thesis §2.4.3: with retroreflective tape the bright runs give the beacon; plain
/// cylinders are ignored, whatever their shape.
#[test]
fn reflective_mode_finds_taped_cylinders_only() {
    let scanner = scanner(0.01);
    let params = ReflectiveParams {
        max_rms: 0.0125,
        ..ReflectiveParams::default()
    };
    let (mut visible, mut found, mut plain_found, mut wrong, mut err) = (0, 0, 0, 0, 0.0);
    for seed in 0..100u64 {
        let scene = Scene::random(5000 + seed, [Material::BEACON, Material::FURNITURE]);
        let scan = scene.scan(&scanner, seed);
        let dets = detect_circles_reflective(&scan, RADIUS, &params);
        let near = |k: usize| {
            dets.iter()
                .find(|d| (d.center - scene.truth[k]).norm() <= MATCH)
        };
        if scene.fully_visible(0, &scan) {
            visible += 1;
            if let Some(d) = near(0) {
                found += 1;
                err += (d.center - scene.truth[0]).norm();
            }
        }
        if near(1).is_some() {
            plain_found += 1;
        }
        wrong += dets
            .iter()
            .filter(|d| scene.truth.iter().all(|t| (d.center - t).norm() > MATCH))
            .count();
    }
    let rate = found as f64 / visible as f64;
    eprintln!(
        "reflective: found {found} of {visible} visible taped cylinders ({:.1} %), mean centre \
         error {:.2} mm, {plain_found} plain cylinders and {wrong} other things reported",
        100.0 * rate,
        1000.0 * err / found.max(1) as f64
    );
    assert!(visible >= 60, "{visible}");
    assert!(rate >= 0.9, "{rate}");
    assert_eq!(plain_found, 0);
    assert_eq!(wrong, 0);
    assert!(err / (found as f64) < 0.01);
}

/// A random planar motion and landmarks 1-6 m ahead of the robot.
fn landmarks(rng: &mut SimRng, n: usize) -> (Vec<Point2<f64>>, Pose2) {
    let before: Vec<Point2<f64>> = (0..n)
        .map(|_| {
            let (r, b) = (rng.range(1.0, 6.0), rng.range(-1.4, 1.4));
            Point2::new(r * b.cos(), r * b.sin())
        })
        .collect();
    let motion = Pose2::new(
        rng.range(-0.5, 0.5),
        rng.range(-0.5, 0.5),
        rng.range(-0.6, 0.6),
    );
    (before, motion)
}

#[test]
fn landmark_pose_change_is_exact_without_noise() {
    let mut rng = SimRng::new(42);
    for trial in 0..200 {
        let n = 2 + trial % 4;
        let (before, motion) = landmarks(&mut rng, n);
        let inv = motion.inverse();
        let after: Vec<Point2<f64>> = before.iter().map(|p| inv.transform_point(p)).collect();
        let got = pose_change_from_landmarks(&before, &after).unwrap();
        assert!((got.pose.x - motion.x).abs() < 1e-9, "{got:?} {motion:?}");
        assert!((got.pose.y - motion.y).abs() < 1e-9, "{got:?} {motion:?}");
        assert!(
            (got.pose.theta - motion.theta).abs() < 1e-9,
            "{got:?} {motion:?}"
        );
        assert!(got.rms < 1e-9);
        assert_eq!(got.landmarks, n);
        // Composition and the 3D pose agree.
        let back = got.pose * got.pose.inverse();
        assert!(back.distance() < 1e-12 && back.theta.abs() < 1e-12);
        let p3 = got.pose.to_pose();
        let q = p3.transform_point(&Point3::new(after[0].x, after[0].y, 0.0));
        assert!((q.xy().coords - before[0].coords).norm() < 1e-9);
    }
}

#[test]
fn landmark_pose_change_errors() {
    let p = |x, y| Point2::new(x, y);
    assert!(pose_change_from_landmarks(&[p(1.0, 0.0)], &[p(1.0, 0.0)]).is_err());
    assert!(pose_change_from_landmarks(&[], &[]).is_err());
    assert!(pose_change_from_landmarks(&[p(1.0, 0.0), p(2.0, 0.0)], &[p(1.0, 0.0)]).is_err());
    let coincident = [p(2.0, 1.0), p(2.0, 1.0)];
    let fine = [p(2.0, 1.0), p(3.0, 1.0)];
    assert!(pose_change_from_landmarks(&coincident, &fine).is_err());
    assert!(pose_change_from_landmarks(&fine, &coincident).is_err());
    assert!(pose_change_from_landmarks(&fine, &[p(f64::NAN, 0.0), p(1.0, 1.0)]).is_err());
}

/// Thesis (2.24)-(2.25): two landmarks 2 m apart about 4 m away, 1 cm range noise and
/// 2 mrad bearing noise in both observations. The pose change compares two noisy
/// observations, so its error is about sqrt(2) times one observation's.
#[test]
fn landmark_pose_change_error_matches_the_thesis_estimate() {
    let (sigma_r, sigma_b) = (0.01, 0.002);
    let a = Point2::new(4.0, 1.0);
    let b = Point2::new(4.0, -1.0);
    let predicted = std::f64::consts::SQRT_2 * localisation_error(4.0, 2.0, sigma_r, sigma_b);
    let mut rng = SimRng::new(7);
    let noisy = |p: &Point2<f64>, rng: &mut SimRng| {
        let r = p.coords.norm() + rng.gauss(sigma_r);
        let t = p.y.atan2(p.x) + rng.gauss(sigma_b);
        Point2::new(r * t.cos(), r * t.sin())
    };
    let trials = 2000;
    let mut sq = 0.0;
    for _ in 0..trials {
        let motion = Pose2::new(
            rng.range(-0.3, 0.3),
            rng.range(-0.3, 0.3),
            rng.range(-0.2, 0.2),
        );
        let inv = motion.inverse();
        let before = [noisy(&a, &mut rng), noisy(&b, &mut rng)];
        let after = [
            noisy(&inv.transform_point(&a), &mut rng),
            noisy(&inv.transform_point(&b), &mut rng),
        ];
        let got = pose_change_from_landmarks(&before, &after).unwrap();
        sq += (got.pose.x - motion.x).powi(2) + (got.pose.y - motion.y).powi(2);
    }
    let rms = (sq / trials as f64).sqrt();
    eprintln!(
        "landmark localisation: RMS position error {:.2} mm, thesis estimate (2.24)-(2.25) x sqrt 2 = {:.2} mm",
        1000.0 * rms,
        1000.0 * predicted
    );
    assert!(rms < 1.5 * predicted, "{rms} vs {predicted}");
    assert!(rms > 0.5 * predicted, "{rms} vs {predicted}");
}

#[test]
fn speed_limits_resolve_the_two_landmark_ambiguity() {
    let before = [Point2::new(4.0, 1.0), Point2::new(4.0, -1.0)];
    let motion = Pose2::new(0.1, 0.03, 0.1);
    let inv = motion.inverse();
    // Seen again in the other order.
    let after: Vec<Point2<f64>> = before
        .iter()
        .rev()
        .map(|p| inv.transform_point(p))
        .collect();
    // (2.18)-(2.19) at 4 m, 10 Hz, over half a second.
    let limits = MotionLimits::for_beacons(RADIUS, 4.0, 10.0, 0.01, 0.5);
    let m = match_landmarks(&before, &after, &limits, 0.02).unwrap();
    assert_eq!(m.pairs, vec![(1, 0), (0, 1)]);
    assert_eq!(m.alternatives, 0);
    assert!((m.pose.pose.theta - 0.1).abs() < 1e-9);
    assert!((m.pose.pose.x - 0.1).abs() < 1e-9 && (m.pose.pose.y - 0.03).abs() < 1e-9);
    // Without speed limits both assignments fit equally well: ambiguous (the swapped one
    // turns the robot about 180° about the midpoint).
    let loose = MotionLimits::new(100.0, 100.0, 1.0);
    let m = match_landmarks(&before, &after, &loose, 0.02).unwrap();
    assert_eq!(m.alternatives, 1);
    // Too fast a turn for the limits: no consistent assignment.
    let spun: Vec<Point2<f64>> = before
        .iter()
        .map(|p| Pose2::new(0.0, 0.0, 1.5).inverse().transform_point(p))
        .collect();
    assert!(match_landmarks(&before, &spun, &limits, 0.02).is_err());
}

#[test]
fn separations_identify_three_indistinguishable_landmarks() {
    let mut rng = SimRng::new(3);
    let loose = MotionLimits::new(100.0, 100.0, 1.0);
    for _ in 0..50 {
        let (before, motion) = landmarks(&mut rng, 3);
        let inv = motion.inverse();
        let mut after: Vec<(usize, Point2<f64>)> = before
            .iter()
            .enumerate()
            .map(|(k, p)| (k, inv.transform_point(p)))
            .collect();
        after.rotate_left(1 + rng.index(2));
        let pts: Vec<Point2<f64>> = after.iter().map(|a| a.1).collect();
        // Random landmarks are asymmetric enough unless two separations nearly agree.
        let d = |i: usize, j: usize| (before[i] - before[j]).norm();
        let seps = [d(0, 1), d(1, 2), d(0, 2)];
        let min_gap = (0..3)
            .flat_map(|i| (0..3).map(move |j| (i, j)))
            .filter(|(i, j)| i < j)
            .map(|(i, j)| (seps[i] - seps[j]).abs())
            .fold(f64::INFINITY, f64::min);
        if min_gap < 0.1 {
            continue;
        }
        let m = match_landmarks(&before, &pts, &loose, 0.01).unwrap();
        let expected: Vec<(usize, usize)> =
            after.iter().enumerate().map(|(j, a)| (a.0, j)).collect();
        assert_eq!(m.pairs, expected);
        assert_eq!(m.alternatives, 0);
        assert!((m.pose.pose.theta - motion.theta).abs() < 1e-9);
    }
}

#[test]
fn laser_scan_json_and_csv_round_trip() {
    let scene = Scene::random(77, [Material::BEACON, Material::FURNITURE]);
    let mut scan = scene.scan(&scanner(0.01), 1);
    scan.time = 12.25;
    assert!(
        scan.ranges.iter().any(|r| !r.is_finite()) || scan.ranges.iter().all(|r| r.is_finite())
    );
    scan.ranges[3] = f32::INFINITY;
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("scan.json");
    let csv = dir.path().join("scan.csv");
    scan.write_json_path(&json).unwrap();
    scan.write_csv_path(&csv).unwrap();
    assert_eq!(LaserScan::read_json_path(&json).unwrap(), scan);
    assert_eq!(LaserScan::read_path(&json).unwrap(), scan);
    assert_eq!(LaserScan::read_path(&csv).unwrap(), scan);
    // Detections are the same from either file.
    let a = detect_circles_lsq(
        &LaserScan::read_path(&json).unwrap(),
        RADIUS,
        &LsqParams::default(),
    );
    let b = detect_circles_lsq(&scan, RADIUS, &LsqParams::default());
    assert_eq!(a, b);
    // Without intensities, and a ROS-like object with extra fields.
    let bare = LaserScan {
        intensities: None,
        ..scan.clone()
    };
    let mut out = Vec::new();
    bare.write_json(&mut out).unwrap();
    assert_eq!(LaserScan::read_json(&out[..]).unwrap(), bare);
    let ros = r#"{"header": {"frame_id": "laser"}, "angle_min": -1.0, "angle_max": 1.0,
        "angle_increment": 1.0, "time_increment": 0.0, "scan_time": 0.1, "range_min": 0.1,
        "range_max": 8.0, "ranges": [1.5, null, 2.5], "intensities": []}"#;
    let got = LaserScan::read_json(ros.as_bytes()).unwrap();
    assert_eq!(got.ranges[1], f32::INFINITY);
    assert_eq!(got.intensities, None);
    assert_eq!(got.time, 0.0);
}

#[test]
fn bad_laser_scan_json_names_the_line() {
    let bad = "{\n  \"angle_min\": 0.0,\n  \"angle_increment\": oops,\n}";
    match LaserScan::read_json(bad.as_bytes()) {
        Err(ParseError::Invalid {
            at: Location::Line(3),
            ..
        }) => {}
        other => panic!("{other:?}"),
    }
    let missing = "{\n  \"angle_min\": 0.0,\n  \"angle_increment\": 0.1\n}";
    assert!(matches!(
        LaserScan::read_json(missing.as_bytes()),
        Err(ParseError::Invalid { .. })
    ));
    assert!(matches!(
        LaserScan::read_json(&b"  "[..]),
        Err(ParseError::Empty)
    ));
    let lengths = r#"{"angle_min": 0, "angle_increment": 0.1, "range_min": 0, "range_max": 8,
        "ranges": [1.0, 2.0], "intensities": [1.0]}"#;
    assert!(matches!(
        LaserScan::read_json(lengths.as_bytes()),
        Err(ParseError::Malformed(_))
    ));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.json");
    std::fs::write(&path, bad).unwrap();
    let e = LaserScan::read_path(&path).unwrap_err().to_string();
    assert!(e.contains("bad.json") && e.contains("line 3"), "{e}");
}
