//! The simulated scanners in a closed box room: exact returns lie on the room's planes,
//! noisy ones have the configured spread, beacons are bright, scans are deterministic, and
//! the 2D scan CSV and the mirror log read back exactly.

use std::f64::consts::TAU;

use nalgebra::{Point3, Vector3};
use olmap::cloud::{LaserScan, PointCloud};
use olmap::geometry::Pose;
use olmap::scanner::{MirrorEventKind, MirrorLog};
use olmap::sim::{
    room_shell, Material, MirrorScanner, Object, PlanarScanner, RangeNoise, Shape, SpinningLidar,
    World,
};

const ROOM: [f64; 3] = [8.0, 6.0, 3.0];

fn room(extra: Vec<Object>) -> World {
    let mut objects: Vec<Object> = room_shell(
        Point3::origin(),
        Vector3::new(ROOM[0], ROOM[1], ROOM[2]),
        0.2,
        true,
    )
    .into_iter()
    .map(|shape| Object {
        shape,
        material: Material::WALL,
        id: 0,
    })
    .collect();
    objects.extend(extra);
    World::new("box room", objects)
}

/// A tilted sensor pose inside the room.
fn pose() -> Pose {
    Pose::from_xyz_ypr(3.1, 2.4, 1.3, 0.4, 0.05, -0.03)
}

/// The nearest of the room's six planes (0..6: x=0, x=max, y=0, y=max, z=0, z=max) and
/// the distance to it.
fn nearest_plane(p: &Point3<f64>) -> (usize, f64) {
    (0..6)
        .map(|k| {
            let (axis, far) = (k / 2, k % 2 == 1);
            let plane = if far { ROOM[axis] } else { 0.0 };
            (k, (p[axis] - plane).abs())
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap()
}

/// Asserts every point of a sensor-frame cloud lies on a room plane within 1e-5 m; returns
/// how many points each plane got.
fn assert_on_planes(cloud: &PointCloud, t_world_sensor: &Pose, what: &str) -> [usize; 6] {
    assert!(!cloud.is_empty(), "{what}: no points");
    let mut per_plane = [0usize; 6];
    for (i, p) in cloud.points().iter().enumerate() {
        let w = t_world_sensor.transform_point(&p.cast::<f64>());
        let (k, d) = nearest_plane(&w);
        assert!(
            d < 1e-5,
            "{what}: point {i} {w} is {d} m off the nearest plane"
        );
        per_plane[k] += 1;
    }
    per_plane
}

fn exact_lidar() -> SpinningLidar {
    SpinningLidar {
        azimuth_step: 1f64.to_radians(),
        noise: RangeNoise::none(),
        ..SpinningLidar::default()
    }
}

#[test]
fn lidar_exact_returns_lie_on_the_room() {
    let world = room(vec![]);
    let lidar = exact_lidar();
    let cloud = lidar.scan(&world, &[], &pose(), 1, 0);
    assert_eq!(cloud.len(), lidar.beams * lidar.azimuths());
    assert_eq!(cloud.intensity().unwrap().len(), cloud.len());
    assert_eq!(cloud.origin(), Point3::origin());
    let per_plane = assert_on_planes(&cloud, &pose(), "lidar");
    // Floor and walls; the top laser (+10°, +13° with the tilt) stays below the ceiling.
    assert!(per_plane[..5].iter().all(|&n| n > 0), "{per_plane:?}");
    assert_eq!(per_plane[5], 0);
}

#[test]
fn planar_exact_returns_lie_on_the_room() {
    let world = room(vec![]);
    for mut scanner in [
        PlanarScanner::sick_180_half_degree(),
        PlanarScanner::sick_100_quarter_degree(),
    ] {
        scanner.noise = RangeNoise::none().with_max_range(8.0);
        let scan = scanner.scan(&world, &[], &pose(), 1, 0);
        assert_eq!(scan.len(), scanner.beams());
        assert!(scan.ranges.iter().all(|r| r.is_finite()));
        assert!((scan.angle(0) + scanner.fov / 2.0).abs() < 1e-12);
        assert!((scan.angle(scan.len() - 1) - scanner.fov / 2.0).abs() < 1e-9);
        let cloud = scan.to_cloud();
        assert_eq!(cloud.len(), scan.len());
        assert!(cloud.points().iter().all(|p| p.z == 0.0));
        assert_on_planes(&cloud, &pose(), "2D scanner");
    }
    assert_eq!(PlanarScanner::sick_180_half_degree().beams(), 361);
    assert_eq!(PlanarScanner::sick_100_quarter_degree().beams(), 401);
}

/// Both mirror scanners, exact, over the given start phases and mirror speed-ups (and
/// logging `revolutions` of the mirror when set), each with a name.
pub(crate) fn exact_mirror_variants(
    phases: &[f64],
    speed_ups: &[f64],
    revolutions: Option<f64>,
) -> Vec<(String, MirrorScanner)> {
    let mut v = Vec::new();
    for base in [MirrorScanner::standard(), MirrorScanner::enhanced()] {
        for &phase in phases {
            for &speed_up in speed_ups {
                let mut s = base.clone();
                s.start_phase = phase;
                s.mirror_period = base.mirror_period / speed_up;
                if let Some(r) = revolutions {
                    s.revolutions = r;
                }
                s.noise = RangeNoise::none();
                let name = format!(
                    "{:?} phase {phase} period {}",
                    s.geometry.mounting, s.mirror_period
                );
                v.push((name, s));
            }
        }
    }
    v
}

#[test]
fn mirror_exact_returns_lie_on_the_room_and_match_the_log() {
    let world = room(vec![]);
    let t = pose();
    for (name, scanner) in exact_mirror_variants(&[0.0, 1.0, 2.5], &[1.0, 4.0], None) {
        let (cloud, log) = scanner.scan_raw(&world, &[], &t, 3, 1);
        let per_plane = assert_on_planes(&cloud, &t, &name);
        // Half a revolution of a double-sided mirror turns the reflected plane all round.
        assert!(per_plane.iter().all(|&n| n > 0), "{name}: {per_plane:?}");
        assert_eq!(log.sweeps.len(), scanner.sweeps(), "{name}");
        // The log's ranges, put through (4.10) with the true mirror angle of each beam's
        // own time, give the cloud back.
        let g = &log.header;
        let mut k = 0;
        for s in &log.sweeps {
            assert_eq!(s.ranges.len(), g.scan_beams);
            for (i, &r) in s.ranges.iter().enumerate() {
                if !r.is_finite() {
                    continue;
                }
                let alpha = scanner.mirror_angle(s.beam_time(i));
                assert!(
                    g.reflects(s.angle(i), alpha),
                    "{name}: a blind beam has a range"
                );
                let p = g.point(r as f64, s.angle(i), alpha);
                let q = cloud.points()[k].cast::<f64>();
                assert!(
                    (p - q).norm() < 1e-5,
                    "{name}: log beam {i} {p} vs cloud {q}"
                );
                k += 1;
            }
        }
        assert_eq!(k, cloud.len(), "{name}: log returns vs cloud points");
        eprintln!(
            "{name}: {} sweeps, {} points, per plane {per_plane:?}",
            log.sweeps.len(),
            cloud.len()
        );
        // The mirror moves within a sweep: beams of one sweep see different elevations.
        let s = &log.sweeps[1];
        assert!(s.beam_time(g.scan_beams - 1) - s.beam_time(0) > 0.01);
    }
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn assert_sigma(diffs: &[f64], sigma: f64, what: &str) {
    let r = rms(diffs);
    assert!(diffs.len() > 2000, "{what}: only {} samples", diffs.len());
    assert!(
        (r / sigma - 1.0).abs() < 0.1,
        "{what}: range error RMS {r} vs sigma {sigma} ({} samples)",
        diffs.len()
    );
}

#[test]
fn range_noise_has_the_configured_sigma() {
    let world = room(vec![]);
    let t = pose();
    let noisy = RangeNoise {
        sigma: 0.02,
        ..RangeNoise::default()
    };
    // Lidar: measured range minus true range, beam by beam.
    let exact = exact_lidar();
    let lidar = SpinningLidar {
        noise: noisy,
        ..exact.clone()
    };
    let a = exact.scan(&world, &[], &t, 5, 0);
    let b = lidar.scan(&world, &[], &t, 5, 0);
    assert_eq!(a.len(), b.len());
    let d: Vec<f64> = a
        .points()
        .iter()
        .zip(b.points())
        .map(|(p, q)| q.cast::<f64>().coords.norm() - p.cast::<f64>().coords.norm())
        .collect();
    assert_sigma(&d, 0.02, "lidar");
    // 2D scanner: many sweeps of the same scene.
    let mut d = Vec::new();
    let mut scanner = PlanarScanner::sick_180_half_degree();
    for stream in 0..10 {
        scanner.noise = RangeNoise::none().with_max_range(20.0);
        let a = scanner.scan(&world, &[], &t, 5, stream);
        scanner.noise = noisy.with_max_range(20.0);
        let b = scanner.scan(&world, &[], &t, 5, stream);
        d.extend(
            a.ranges
                .iter()
                .zip(&b.ranges)
                .map(|(x, y)| *y as f64 - *x as f64),
        );
    }
    assert_sigma(&d, 0.02, "2D scanner");
    // Mirror scanners: the logged ranges (whole optical path).
    for base in [MirrorScanner::standard(), MirrorScanner::enhanced()] {
        let mut s = base.clone();
        s.geometry.max_range = 20.0;
        s.noise = RangeNoise::none().with_max_range(20.0);
        let (_, a) = s.scan_raw(&world, &[], &t, 5, 0);
        s.noise = noisy.with_max_range(20.0);
        let (cloud, b) = s.scan_raw(&world, &[], &t, 5, 0);
        let d: Vec<f64> = a
            .sweeps
            .iter()
            .zip(&b.sweeps)
            .flat_map(|(x, y)| x.ranges.iter().zip(&y.ranges))
            .filter(|(x, _)| x.is_finite())
            .map(|(x, y)| *y as f64 - *x as f64)
            .collect();
        assert_eq!(d.len(), cloud.len());
        assert_sigma(&d, 0.02, &format!("{:?} mirror", s.geometry.mounting));
        // The points moved along the reflected ray by the range error: the residual along
        // the ray has the same spread.
        let exact = s.clone();
        let mut exact = exact;
        exact.noise = RangeNoise::none().with_max_range(20.0);
        let c0 = exact.scan(&world, &[], &t, 5, 0);
        let along: Vec<f64> = c0
            .points()
            .iter()
            .zip(cloud.points())
            .map(|(p, q)| (q - p).cast::<f64>().norm())
            .collect();
        assert_sigma(&along, 0.02, "mirror points");
    }
}

#[test]
fn retroreflective_beacon_is_bright_in_the_2d_scan() {
    let beacon = Object {
        shape: Shape::Cylinder {
            base: Point3::new(5.0, 3.5, 0.0),
            radius: 0.1,
            height: 2.0,
        },
        material: Material::BEACON,
        id: 7,
    };
    let world = room(vec![beacon]);
    let t = Pose::from_xyz_ypr(2.0, 3.0, 1.0, 0.0, 0.0, 0.0);
    let scan = PlanarScanner::sick_180_half_degree().scan(&world, &[], &t, 9, 0);
    let ints = scan.intensities.as_ref().unwrap();
    let bearing = (0.5f64).atan2(3.0);
    let dist = (0.5f64.powi(2) + 9.0).sqrt() - 0.1;
    let mut bright = 0;
    for (i, &v) in ints.iter().enumerate() {
        let off = (scan.angle(i) - bearing).abs();
        if v > 1.5 {
            bright += 1;
            assert!(off < 2f64.to_radians(), "bright beam {i} points away");
            assert!((scan.ranges[i] as f64 - dist).abs() < 0.12);
        } else if off > 3f64.to_radians() {
            assert!(v <= 1.0, "beam {i}: {v}");
        }
    }
    assert!(bright >= 3, "{bright} bright beams");
    // The beacon's light survives into the cloud.
    let cloud = scan.to_cloud();
    assert_eq!(
        cloud
            .intensity()
            .unwrap()
            .iter()
            .filter(|&&v| v > 1.5)
            .count(),
        bright
    );
}

fn bits(c: &PointCloud) -> Vec<u32> {
    c.points()
        .iter()
        .flat_map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        .chain(c.intensity().unwrap().iter().map(|v| v.to_bits()))
        .collect()
}

fn with_threads<T: Send>(n: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .unwrap()
        .install(f)
}

#[test]
fn scans_are_deterministic_whatever_the_threads() {
    let obstacle = Object {
        shape: Shape::aabb_box(Point3::new(5.0, 3.0, 0.0), Point3::new(5.6, 3.8, 1.5)),
        material: Material::FURNITURE,
        id: 2,
    };
    let world = room(vec![]);
    let extra = [obstacle];
    let t = pose();
    let noise = RangeNoise {
        dropout: 0.1,
        mixed_pixels: 0.5,
        ..RangeNoise::default()
    };
    let lidar = SpinningLidar {
        noise,
        ..SpinningLidar::default()
    };
    let a = with_threads(1, || lidar.scan(&world, &extra, &t, 42, 3));
    let b = with_threads(4, || lidar.scan(&world, &extra, &t, 42, 3));
    assert_eq!(bits(&a), bits(&b));
    let c = lidar.scan(&world, &extra, &t, 43, 3);
    assert_ne!(bits(&a), bits(&c));
    let c = lidar.scan(&world, &extra, &t, 42, 4);
    assert_ne!(bits(&a), bits(&c));
    // The extra object is seen.
    let seen = a.points().iter().any(|p| {
        let w = t.transform_point(&p.cast::<f64>());
        (w.x - 5.0).abs() < 0.05 && w.y > 3.0 && w.y < 3.8 && w.z < 1.5
    });
    assert!(seen);

    let mut planar = PlanarScanner::sick_100_quarter_degree();
    planar.noise = noise;
    let a = with_threads(1, || planar.scan(&world, &extra, &t, 42, 3));
    let b = with_threads(3, || planar.scan(&world, &extra, &t, 42, 3));
    let to_bits = |s: &LaserScan| -> Vec<u32> { s.ranges.iter().map(|r| r.to_bits()).collect() };
    assert_eq!(to_bits(&a), to_bits(&b));
    assert_eq!(a.intensities, b.intensities);
    assert_ne!(to_bits(&a), to_bits(&planar.scan(&world, &extra, &t, 7, 3)));

    let mut mirror = MirrorScanner::enhanced();
    mirror.noise = noise;
    mirror.start_phase = 0.4;
    let (ca, la) = with_threads(1, || mirror.scan_raw(&world, &extra, &t, 42, 3));
    let (cb, lb) = with_threads(4, || mirror.scan_raw(&world, &extra, &t, 42, 3));
    assert_eq!(bits(&ca), bits(&cb));
    assert_eq!(la, lb);
    let (cc, _) = mirror.scan_raw(&world, &extra, &t, 41, 3);
    assert_ne!(bits(&ca), bits(&cc));
}

#[test]
fn laser_scan_csv_round_trip_is_exact() {
    let world = room(vec![]);
    let mut scan = PlanarScanner::sick_180_half_degree().scan(&world, &[], &pose(), 1, 2);
    scan.ranges[3] = f32::INFINITY;
    scan.ranges[4] = 1e-7;
    scan.time = 12.345_678_9;
    let mut text = Vec::new();
    scan.write_csv(&mut text).unwrap();
    let back = LaserScan::read_csv(&text[..]).unwrap();
    assert_eq!(back, scan);
    let rb: Vec<u32> = back.ranges.iter().map(|r| r.to_bits()).collect();
    let ra: Vec<u32> = scan.ranges.iter().map(|r| r.to_bits()).collect();
    assert_eq!(ra, rb);
    // Without intensities, and through files.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scan.csv");
    scan.intensities = None;
    scan.write_csv_path(&path).unwrap();
    assert_eq!(LaserScan::read_csv_path(&path).unwrap(), scan);

    // A malformed row names its line (line 9 = the fifth beam).
    let s = String::from_utf8(text).unwrap();
    let mut lines: Vec<&str> = s.lines().collect();
    assert_eq!(lines[0], "# olmap laser scan v1");
    lines[8] = "2.5,abc";
    let bad = lines.join("\n");
    let err = LaserScan::read_csv(bad.as_bytes()).unwrap_err().to_string();
    assert!(err.contains("line 9"), "{err}");
    std::fs::write(&path, &bad).unwrap();
    let err = LaserScan::read_csv_path(&path).unwrap_err().to_string();
    assert!(err.contains("line 9") && err.contains("scan.csv"), "{err}");
    // A bad parameter line too.
    lines[8] = "2.5,0.5";
    lines[2] = "0,1,2";
    let err = LaserScan::read_csv(lines.join("\n").as_bytes())
        .unwrap_err()
        .to_string();
    assert!(err.contains("line 3"), "{err}");
}

#[test]
fn mirror_log_round_trip_is_exact() {
    let world = room(vec![]);
    let mut scanner = MirrorScanner::standard();
    scanner.start_phase = 1.3;
    scanner.noise.dropout = 0.05;
    let (_, log) = scanner.scan_raw(&world, &[], &pose(), 8, 0);
    assert!(log
        .sweeps
        .iter()
        .any(|s| s.ranges.iter().any(|r| r.is_infinite())));
    let mut text = Vec::new();
    log.write(&mut text).unwrap();
    let back = MirrorLog::read(&text[..]).unwrap();
    assert_eq!(back, log);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scan.mirror");
    log.write_path(&path).unwrap();
    assert_eq!(MirrorLog::read_path(&path).unwrap(), log);

    // Without intensities too.
    let mut plain = log.clone();
    for s in &mut plain.sweeps {
        s.intensities = None;
    }
    let mut t2 = Vec::new();
    plain.write(&mut t2).unwrap();
    assert_eq!(MirrorLog::read(&t2[..]).unwrap(), plain);

    // Malformed records name their line.
    let s = String::from_utf8(text).unwrap();
    let lines: Vec<&str> = s.lines().collect();
    let first_sweep = lines.iter().position(|l| l.starts_with("S ")).unwrap();
    let first_event = lines.iter().position(|l| l.starts_with("E ")).unwrap();
    let corrupt = |k: usize, new: &str| {
        let mut l = lines.clone();
        l[k] = new;
        let err = MirrorLog::read(l.join("\n").as_bytes())
            .unwrap_err()
            .to_string();
        assert!(err.contains(&format!("line {}", k + 1)), "{new}: {err}");
    };
    let sweep_bad = lines[first_sweep].replacen(" inf", " x", 1);
    corrupt(first_sweep, &sweep_bad);
    let truncated = lines[first_sweep].rsplit_once(' ').unwrap().0.to_string();
    corrupt(first_sweep, &truncated);
    // A beam count whose double overflows (a crafted line once panicked here).
    corrupt(first_sweep, "S 0.5 0.1 0 0.01 18446744073709551615 1 2");
    corrupt(first_event, "E 0.5 tock");
    corrupt(first_event, "Q 0.5 tick");
    corrupt(first_sweep + 3, "E -1 tick"); // out of time order
    corrupt(2, "# mounting sideways");
    // A header missing a key is reported at the first record.
    let mut l = lines.clone();
    l.remove(4);
    let err = MirrorLog::read(l.join("\n").as_bytes())
        .unwrap_err()
        .to_string();
    assert!(err.contains("ticks_per_revolution"), "{err}");
    assert!(err.contains(&format!("line {first_sweep}")), "{err}");
}

#[test]
fn mirror_events_follow_the_mirror() {
    let world = room(vec![]);
    for (period, revolutions, phase) in [(10.0, 2.0, 0.7), (4.8, 1.0, 5.9), (40.0, 0.5, 0.0)] {
        let mut scanner = MirrorScanner::standard();
        scanner.mirror_period = period;
        scanner.revolutions = revolutions;
        scanner.start_phase = phase;
        scanner.sweep_rate = 5.0; // few sweeps: events are the subject here
        let (_, log) = scanner.scan_raw(&world, &[], &pose(), 1, 0);
        let n = log.header.ticks_per_revolution as f64;
        let ticks: Vec<f64> = log.event_times(MirrorEventKind::Tick);
        let triggers: Vec<f64> = log.event_times(MirrorEventKind::Trigger);
        // Ticks every 2 pi / n of mirror angle at the configured speed.
        for w in ticks.windows(2) {
            assert!((w[1] - w[0] - period / n).abs() < 1e-9, "{w:?}");
        }
        for &t in &ticks {
            let a = scanner.mirror_angle(t) / (TAU / n);
            assert!((a - a.round()).abs() < 1e-6, "tick at {t}: {a}");
        }
        let span = log.events.last().unwrap().time - log.events[0].time;
        assert!(ticks.len() as f64 >= n * span / period - 1.0);
        // One trigger per revolution, at the trigger angle.
        let expected = revolutions.floor().max(1.0) as usize;
        if revolutions >= 1.0 {
            assert_eq!(triggers.len(), expected, "{triggers:?}");
        }
        for w in triggers.windows(2) {
            assert!((w[1] - w[0] - period).abs() < 1e-9);
        }
        for &t in &triggers {
            let off =
                olmap::geometry::wrap_angle(scanner.mirror_angle(t) - log.header.trigger_angle);
            assert!(off.abs() < 1e-9 || (off.abs() - TAU).abs() < 1e-9, "{off}");
        }
        assert!(log.events.windows(2).all(|w| w[0].time <= w[1].time));
    }
}

#[test]
fn mixed_pixels_appear_at_depth_edges() {
    let block = Object {
        shape: Shape::aabb_box(Point3::new(3.0, 3.3, 0.0), Point3::new(3.5, 4.3, 2.0)),
        material: Material::FURNITURE,
        id: 1,
    };
    let world = room(vec![block]);
    let count_between = |p: f64| -> usize {
        let mut between = 0;
        for k in 0..10 {
            let t = Pose::from_xyz_ypr(1.0, 3.0 + 0.013 * k as f64, 1.2, 0.0, 0.0, 0.0);
            let mut scanner = PlanarScanner::sick_180_half_degree();
            scanner.noise = RangeNoise {
                mixed_pixels: p,
                ..RangeNoise::none()
            };
            let cloud = scanner.scan(&world, &[], &t, 1, k).to_cloud();
            between += cloud
                .points()
                .iter()
                .map(|q| t.transform_point(&q.cast::<f64>()))
                .filter(|w| w.x > 3.6 && w.x < 7.9 && w.y > 0.1 && w.y < 5.9)
                .count();
        }
        between
    };
    assert_eq!(count_between(0.0), 0);
    let mixed = count_between(1.0);
    assert!(mixed >= 3, "{mixed} mixed pixels");
}

#[test]
fn lidar_speed() {
    let world = room(vec![]);
    let lidar = SpinningLidar::default();
    let rays = lidar.beams * lidar.azimuths();
    let start = std::time::Instant::now();
    let cloud = lidar.scan(&world, &[], &pose(), 1, 0);
    let s = start.elapsed().as_secs_f64();
    assert_eq!(cloud.len(), rays);
    eprintln!(
        "lidar: {rays} rays in {:.1} ms: {:.2} Mrays/s on {} threads",
        s * 1e3,
        rays as f64 / s / 1e6,
        rayon::current_num_threads()
    );
}
