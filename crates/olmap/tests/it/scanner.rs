//! Issue 10: rotating-mirror raw logs to clouds, the pixel-mixing filter, repeatability and
//! the triangulation scanner. Simulated raw logs of a box room (`sim::MirrorScanner`)
//! convert to clouds on the room's planes; tolerances come from the physics.

use nalgebra::{Point3, Vector3};
use olmap::cloud::PointCloud;
use olmap::geometry::Pose;
use olmap::scanner::{
    convert_log, intersect_ray_plane, optimal_baseline, repeatability, triangulate_2d,
    triangulate_pixel, triangulation_range_error, ConvertParams, ConvertedScan, LaserPlane,
    MirrorEvent, MirrorEventKind, MirrorLog, PinholeIntrinsics, Ray, RepeatabilityParams,
};
use olmap::sim::{room_shell, Material, MirrorScanner, Object, RangeNoise, Shape, World};

const ROOM: [f64; 3] = [7.0, 6.0, 3.0];
/// Obstacle boxes inside the room (for depth edges): min and max corners.
const BOXES: [([f64; 3], [f64; 3]); 3] = [
    ([4.2, 1.6, 0.0], [5.0, 2.6, 1.9]),
    ([1.0, 3.6, 0.0], [1.3, 3.9, 3.0]),
    ([3.4, 4.3, 0.7], [4.6, 4.8, 1.0]),
];

fn wall(shape: Shape) -> Object {
    Object {
        shape,
        material: Material::WALL,
        id: 0,
    }
}

fn room(with_box: bool) -> World {
    let mut objects: Vec<Object> = room_shell(
        Point3::origin(),
        Vector3::new(ROOM[0], ROOM[1], ROOM[2]),
        0.2,
        true,
    )
    .into_iter()
    .map(wall)
    .collect();
    if with_box {
        for (a, b) in BOXES {
            objects.push(wall(Shape::aabb_box(
                Point3::new(a[0], a[1], a[2]),
                Point3::new(b[0], b[1], b[2]),
            )));
        }
    }
    World::new("box room", objects)
}

/// A tilted sensor pose inside the room.
fn pose() -> Pose {
    Pose::from_xyz_ypr(2.6, 2.3, 1.3, 0.35, 0.04, -0.03)
}

/// Distance of a world point to the nearest room plane and its unit normal.
fn room_plane(p: &Point3<f64>) -> (f64, Vector3<f64>) {
    let mut best = (f64::INFINITY, Vector3::zeros());
    for axis in 0..3 {
        for plane in [0.0, ROOM[axis]] {
            let d = (p[axis] - plane).abs();
            if d < best.0 {
                let mut n = Vector3::zeros();
                n[axis] = 1.0;
                best = (d, n);
            }
        }
    }
    best
}

/// Distance of a world point to the nearest obstacle box's surface.
fn box_distance(p: &Point3<f64>) -> f64 {
    BOXES
        .iter()
        .map(|&(a, b)| one_box_distance(p, a, b))
        .fold(f64::INFINITY, f64::min)
}

fn one_box_distance(p: &Point3<f64>, a: [f64; 3], b: [f64; 3]) -> f64 {
    let mut outside = Vector3::zeros();
    let mut inside = f64::INFINITY;
    for k in 0..3 {
        let (c, h) = (0.5 * (a[k] + b[k]), 0.5 * (b[k] - a[k]));
        let q = (p[k] - c).abs() - h;
        outside[k] = q.max(0.0);
        inside = inside.min(-q);
    }
    if outside.norm() > 0.0 {
        outside.norm()
    } else {
        inside.max(0.0)
    }
}

fn world_points(c: &PointCloud, t: &Pose) -> Vec<Point3<f64>> {
    c.points()
        .iter()
        .map(|p| t.transform_point(&Point3::new(p.x as f64, p.y as f64, p.z as f64)))
        .collect()
}

fn residuals(c: &PointCloud, t: &Pose) -> Vec<f64> {
    world_points(c, t).iter().map(|p| room_plane(p).0).collect()
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn max(v: &[f64]) -> f64 {
    v.iter().cloned().fold(0.0, f64::max)
}

fn convert(log: &MirrorLog, correction: bool) -> ConvertedScan {
    let params = ConvertParams {
        within_sweep_correction: correction,
        ..ConvertParams::default()
    };
    convert_log(log, &params).unwrap()
}

/// Both mountings, trigger phases all round the revolution, several mirror speeds. A
/// whole revolution is logged so the trigger is always seen.
fn variants() -> Vec<(String, MirrorScanner)> {
    crate::sim_scanners::exact_mirror_variants(&[0.0, 0.3, 2.0, 4.4, -1.0], &[1.0, 3.7], Some(1.0))
}

#[test]
fn exact_logs_convert_onto_the_room_planes() {
    let world = room(false);
    let t = pose();
    for (name, scanner) in variants() {
        let (truth, mut log) = scanner.scan_raw(&world, &[], &t, 1, 0);
        // The simulator logs no return for beams the mirror does not reflect; give them a
        // range so the converter has to recognise them itself.
        let g = log.header.clone();
        let mut blind = 0;
        for sweep in &mut log.sweeps {
            for i in 0..sweep.ranges.len() {
                if !g.reflects(sweep.angle(i), scanner.mirror_angle(sweep.beam_time(i))) {
                    sweep.ranges[i] = 3.0;
                    blind += 1;
                }
            }
        }
        let start = std::time::Instant::now();
        let out = convert(&log, true);
        let secs = start.elapsed().as_secs_f64();
        let res = residuals(&out.cloud, &t);
        // Exact ranges, a constant-speed mirror: linear interpolation is exact, only f32
        // storage of the points remains (~1e-6 m).
        assert!(max(&res) < 1e-4, "{name}: max residual {}", max(&res));
        // Every simulated return comes back, and at the simulator's own position.
        assert_eq!(out.cloud.len(), truth.len(), "{name}: {:?}", out.stats);
        let worst = out
            .cloud
            .points()
            .iter()
            .zip(truth.points())
            .map(|(a, b)| (a - b).norm())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{name}: {worst}");
        let s = out.stats;
        assert_eq!(s.trigger_mismatches, 0, "{name}");
        assert!(
            s.edge_on > 0 && s.outside_mirror > 0 && s.blocked > 0,
            "{name}: {s:?}"
        );
        assert_eq!(
            s.edge_on + s.outside_mirror + s.blocked,
            blind,
            "{name}: {s:?}"
        );
        assert_eq!(
            s.points + s.no_return + s.outside_mirror + s.edge_on + s.blocked + s.beyond_max_range,
            s.beams,
            "{name}: {s:?}"
        );
        eprintln!(
            "{name}: {} points, max residual {:.2e} m, {:.2e} points/s",
            s.points,
            max(&res),
            s.points as f64 / secs
        );
    }
}

#[test]
fn noisy_logs_scatter_about_the_planes_by_sigma() {
    let world = room(false);
    let t = pose();
    for base in [MirrorScanner::standard(), MirrorScanner::enhanced()] {
        let mut s = base.clone();
        s.start_phase = 1.3;
        s.revolutions = 1.0;
        let sigma = s.noise.sigma;
        let (_, log) = s.scan_raw(&world, &[], &t, 7, 0);
        let out = convert(&log, true);
        let g = &log.header;
        // The range noise is along the beam: its component across the plane is
        // dr cos(incidence), so the expected rms residual is sigma sqrt(mean cos^2).
        let mut cos2 = 0.0;
        let mut res = Vec::new();
        for (p, src) in world_points(&out.cloud, &t).iter().zip(&out.sources) {
            let sweep = &log.sweeps[src[0] as usize];
            let i = src[1] as usize;
            let alpha = s.mirror_angle(sweep.beam_time(i));
            let beam = g.beam(sweep.angle(i), alpha).unwrap();
            let dir = t.transform_vector(&beam.direction);
            let (d, n) = room_plane(p);
            // Points near an edge of the room could be matched to the wrong plane.
            if d > 5.0 * sigma {
                continue;
            }
            cos2 += dir.dot(&n).powi(2);
            res.push(d);
        }
        let expected = sigma * (cos2 / res.len() as f64).sqrt();
        let got = rms(&res);
        let name = format!("{:?}", g.mounting);
        eprintln!(
            "{name}: {} points, rms residual {got:.5} m, expected {expected:.5} m",
            res.len()
        );
        // Tens of thousands of points: the rms is within a few per cent of its expectation.
        assert!(res.len() > 10_000, "{name}");
        assert!(
            (got / expected - 1.0).abs() < 0.05,
            "{name}: {got} vs {expected}"
        );
    }
}

#[test]
fn without_the_within_sweep_correction_planes_bend() {
    let world = room(false);
    let t = pose();
    for base in [MirrorScanner::standard(), MirrorScanner::enhanced()] {
        let mut s = base.clone();
        s.noise = RangeNoise::none();
        s.start_phase = 0.2;
        s.revolutions = 1.0;
        let (_, log) = s.scan_raw(&world, &[], &t, 3, 0);
        let with = residuals(&convert(&log, true).cloud, &t);
        let without = residuals(&convert(&log, false).cloud, &t);
        let name = format!("{:?}", log.header.mounting);
        // Without the correction a beam fired up to one sweep duration after the sweep's
        // timestamp is placed at the elevation of that timestamp: an angle error of up to
        // 2 omega duration (phi turns twice as fast as the mirror), a displacement of up to
        // r_max times that.
        let dphi = 2.0 * std::f64::consts::TAU / s.mirror_period * s.sweep_duration;
        let bound = log.header.max_range * dphi;
        eprintln!(
            "{name}: rms residual with correction {:.2e} m, without {:.2e} m (max {:.2e}, bound {bound:.2e})",
            rms(&with),
            rms(&without),
            max(&without)
        );
        assert!(max(&with) < 1e-4, "{name}");
        assert!(max(&without) <= bound + 1e-4, "{name}");
        // At a few metres the error is millimetres to centimetres: far above the exact
        // conversion.
        assert!(rms(&without) > 1e-3, "{name}: {}", rms(&without));
        assert!(rms(&without) > 20.0 * rms(&with), "{name}");
    }
}

#[test]
fn mixed_pixel_filter_removes_floating_returns_and_keeps_good_ones() {
    let world = room(true);
    let t = pose();
    for base in [MirrorScanner::enhanced(), MirrorScanner::standard()] {
        let mut s = base.clone();
        s.start_phase = 0.5;
        s.revolutions = 1.0;
        let mut mixed_s = s.clone();
        mixed_s.noise.mixed_pixels = 1.0;
        // The same seed draws the same noise: the two logs differ only in mixed pixels (a
        // tiny but non-zero probability keeps the random draws in step and never mixes).
        s.noise.mixed_pixels = f64::MIN_POSITIVE;
        let (_, clean) = s.scan_raw(&world, &[], &t, 11, 0);
        let (_, mixed) = mixed_s.scan_raw(&world, &[], &t, 11, 0);
        let all = convert_log(&mixed, &ConvertParams::default()).unwrap();
        let params = ConvertParams {
            filter_mixed: true,
            ..ConvertParams::default()
        };
        let filtered = convert_log(&mixed, &params).unwrap();
        let kept: std::collections::HashSet<[u32; 2]> = filtered.sources.iter().copied().collect();
        let (mut good, mut good_kept, mut floating, mut floating_removed) = (0, 0, 0, 0);
        let (mut n_mixed, mut mixed_removed) = (0, 0);
        for (p, src) in world_points(&all.cloud, &t).iter().zip(&all.sources) {
            let (k, i) = (src[0] as usize, src[1] as usize);
            let is_kept = kept.contains(src);
            if clean.sweeps[k].ranges[i] == mixed.sweeps[k].ranges[i] {
                good += 1;
                good_kept += is_kept as usize;
            } else {
                n_mixed += 1;
                mixed_removed += !is_kept as usize;
                // A mixed return within 0.15 m (7.5 sigma) of a surface cannot be told from
                // a noisy return on it and does no harm; those floating farther out are the
                // ones the filter must remove.
                if room_plane(p).0.min(box_distance(p)) > 0.15 {
                    floating += 1;
                    floating_removed += !is_kept as usize;
                }
            }
        }
        let removed = floating_removed as f64 / floating as f64;
        let kept_rate = good_kept as f64 / good as f64;
        let name = format!("{:?}", mixed.header.mounting);
        eprintln!(
            "{name}: {n_mixed} mixed pixels ({mixed_removed} removed), {floating} floating, \
             {:.1} % of those removed; {good_kept} of {good} good returns kept ({:.3} %)",
            100.0 * removed,
            100.0 * kept_rate
        );
        // Enough floating returns for the rate to mean something.
        assert!(floating >= 50, "{name}: {floating}");
        assert!(removed >= 0.90, "{name}: {removed}");
        assert!(kept_rate >= 0.99, "{name}: {kept_rate}");
        assert_eq!(
            filtered.stats.mixed_pixels,
            all.cloud.len() - filtered.cloud.len()
        );
    }
}

#[test]
fn repeatability_of_two_noisy_scans_matches_the_noise() {
    let world = room(false);
    let t = pose();
    let s = MirrorScanner::enhanced();
    let mut s = s.clone();
    s.start_phase = 0.4;
    s.revolutions = 1.0;
    let sigma = s.noise.sigma;
    let a = convert(&s.scan_raw(&world, &[], &t, 21, 0).1, true).cloud;
    let b = convert(&s.scan_raw(&world, &[], &t, 22, 0).1, true).cloud;
    let r = repeatability(&a, &b, &RepeatabilityParams::default()).unwrap();
    eprintln!("repeatability: {r:?}");
    // Two scans with independent noise: the closest point of B lies on B's noisy copy of
    // the surface, whose offset from A's point across the surface is the difference of two
    // draws (sd sqrt(2) sigma, reduced by cos(incidence)), and the nearest neighbour can
    // only be closer: the median is below sqrt(2) sigma 0.674 and of the order of sigma.
    assert!(r.median < 2f64.sqrt() * 0.6745 * sigma, "{r:?}");
    assert!(r.median > 0.1 * sigma, "{r:?}");
    assert!(r.mean < 2.0 * sigma && r.share_above < 0.3, "{r:?}");
    // Identical scans: all zero.
    let same = repeatability(&a, &a, &RepeatabilityParams::default()).unwrap();
    assert_eq!((same.mean, same.share_above), (0.0, 0.0));
    assert!(repeatability(&a, &PointCloud::new(), &RepeatabilityParams::default()).is_err());
}

#[test]
fn bad_logs_give_errors() {
    let world = room(false);
    let mut s = MirrorScanner::standard();
    s.noise = RangeNoise::none();
    s.revolutions = 0.05;
    s.start_phase = 0.25;
    let (_, log) = s.scan_raw(&world, &[], &pose(), 1, 0);
    assert!(convert_log(&log, &ConvertParams::default()).is_ok());
    let p = ConvertParams::default();
    // No trigger.
    let mut l = log.clone();
    l.events.retain(|e| e.kind != MirrorEventKind::Trigger);
    assert!(convert_log(&l, &p).is_err());
    // Fewer than two ticks.
    let mut l = log.clone();
    let first_tick = l
        .events
        .iter()
        .position(|e| e.kind == MirrorEventKind::Tick)
        .unwrap();
    l.events.retain(|e| e.kind == MirrorEventKind::Trigger);
    l.events.push(log.events[first_tick]);
    l.events.sort_by(|a, b| a.time.total_cmp(&b.time));
    assert!(convert_log(&l, &p).is_err());
    // A sweep far outside the encoder history.
    let mut l = log.clone();
    let mut late = l.sweeps[0].clone();
    late.time = 1e3;
    l.sweeps.push(late);
    assert!(convert_log(&l, &p).is_err());
    // Events out of order.
    let mut l = log.clone();
    l.events.reverse();
    assert!(convert_log(&l, &p).is_err());
    // Mismatched intensities.
    let mut l = log.clone();
    l.sweeps[0].intensities = Some(vec![1.0]);
    assert!(convert_log(&l, &p).is_err());
    // Bad geometry.
    let mut l = log.clone();
    l.header.ticks_per_revolution = 0;
    assert!(convert_log(&l, &p).is_err());
    // A missed tick after the trigger shows as a trigger mismatch on the next revolution.
    let mut s2 = s.clone();
    s2.revolutions = 1.2;
    let (_, mut l) = s2.scan_raw(&world, &[], &pose(), 1, 0);
    let trig = l
        .events
        .iter()
        .position(|e| e.kind == MirrorEventKind::Trigger)
        .unwrap();
    l.events.remove(trig + 5);
    let out = convert_log(&l, &p).unwrap();
    assert_eq!(out.stats.trigger_mismatches, 1);
    let _ = MirrorEvent {
        time: 0.0,
        kind: MirrorEventKind::Tick,
    };
}

#[test]
fn triangulation_reproduces_known_points() {
    let k = PinholeIntrinsics {
        fx: 610.0,
        fy: 605.0,
        cx: 322.5,
        cy: 241.0,
    };
    // Camera looking along world +x (z_cam = x, x_cam = -y, y_cam = -z), 0.3 m above
    // the laser, turned slightly.
    let look = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
        0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0,
    ));
    let t_wc = Pose::from_xyz_ypr(0.0, 0.0, 0.3, 0.1, 0.05, 0.0)
        * Pose::from_parts(
            Vector3::zeros(),
            nalgebra::UnitQuaternion::from_rotation_matrix(&look),
        );
    // The laser plane: through the aperture and two lit wall points.
    let plane = LaserPlane::from_points(
        &Point3::new(0.0, 0.0, 0.0),
        &Point3::new(4.0, -1.0, -0.6),
        &Point3::new(4.0, 1.5, 0.4),
    )
    .unwrap();
    for truth in [
        Point3::new(3.0, 0.2, 0.0),
        Point3::new(1.5, -0.7, -0.2),
        Point3::new(6.0, 2.0, 0.3),
    ] {
        // Move the point onto the plane, project it, triangulate it back.
        let p = truth - plane.normal.into_inner() * plane.distance(&truth);
        let (u, v) = k.project(&t_wc.inverse().transform_point(&p)).unwrap();
        let q = triangulate_pixel(&k, &t_wc, &plane, u, v).unwrap();
        assert!((q - p).norm() < 1e-9, "{p} -> {q}");
    }
    assert!(LaserPlane::from_points(
        &Point3::origin(),
        &Point3::new(1.0, 1.0, 1.0),
        &Point3::new(2.0, 2.0, 2.0)
    )
    .is_err());
    let ray = Ray {
        origin: Point3::origin(),
        direction: Vector3::x_axis(),
    };
    let wall = LaserPlane::from_points(
        &Point3::new(2.0, 0.0, 0.0),
        &Point3::new(2.0, 1.0, 0.0),
        &Point3::new(2.0, 0.0, 1.0),
    )
    .unwrap();
    assert!(
        (intersect_ray_plane(&ray, &wall).unwrap() - Point3::new(2.0, 0.0, 0.0)).norm() < 1e-15
    );
}

#[test]
fn triangulation_error_grows_as_4_6() {
    let s: f64 = 0.4;
    let da = 1e-7;
    let mut last = 0.0;
    for x in [0.5f64, 1.0, 2.0, 4.0, 8.0] {
        // (4.1) on the bisector y = s / 2: beta from the origin, alpha = -beta from (0, s).
        let beta = (s / 2.0 / x).atan();
        let (x0, y0) = triangulate_2d(s, -beta, beta).unwrap();
        assert!((x0 - x).abs() < 1e-12 && (y0 - s / 2.0).abs() < 1e-12);
        // Each angle off by da in the worst (opposite) senses.
        let (x1, _) = triangulate_2d(s, -beta - da, beta + da).unwrap();
        let numeric = (x1 - x0).abs();
        let law = triangulation_range_error(x, s, da);
        assert!(
            (numeric / law - 1.0).abs() < 1e-4,
            "x {x}: {numeric} vs {law}"
        );
        // Quadratic growth: doubling the range nearly quadruples the error.
        if last > 0.0 {
            assert!(law / last > 3.5, "{}", law / last);
        }
        last = law;
        // The optimal baseline s = 2x minimises the law.
        let best = triangulation_range_error(x, optimal_baseline(x), da);
        for f in [0.5, 0.9, 1.1, 2.0] {
            assert!(best <= triangulation_range_error(x, f * optimal_baseline(x), da));
        }
    }
}

#[test]
fn visible_volume_and_range_limits() {
    let world = room(true);
    let t = pose();
    let mut s = MirrorScanner::enhanced();
    s.noise = RangeNoise::none();
    s.mirror_period /= 4.0;
    s.revolutions = 1.0;
    let (_, log) = s.scan_raw(&world, &[], &t, 5, 0);
    let all = convert(&log, true);
    // Visible-volume limits in the manner of thesis (4.11): 0.5 < r < 3 (a short max range
    // here so that it bites), |theta| < 40 deg, and a window of reflected elevations
    // around straight ahead (phi = 270 deg for the enhanced mounting).
    let window = (200f64.to_radians(), 300f64.to_radians());
    let params = ConvertParams {
        max_range: Some(3.0),
        min_range: 0.5,
        theta_limit: Some(40f64.to_radians()),
        elevation_window: Some(window),
        ..ConvertParams::default()
    };
    let out = convert_log(&log, &params).unwrap();
    let st = out.stats;
    assert!(
        st.beyond_max_range > 0 && st.outside_elevation > 0,
        "{st:?}"
    );
    assert!(st.outside_mirror > all.stats.outside_mirror, "{st:?}");
    assert!(out.cloud.len() > 1000 && out.cloud.len() < all.cloud.len());
    for src in &out.sources {
        let sw = &log.sweeps[src[0] as usize];
        let i = src[1] as usize;
        let r = sw.ranges[i] as f64;
        assert!((0.5..=3.0).contains(&r), "{r}");
        assert!(sw.angle(i).abs() <= 40f64.to_radians() + 1e-12);
        let phi = (2.0 * s.mirror_angle(sw.beam_time(i))).rem_euclid(std::f64::consts::TAU);
        assert!(phi >= window.0 - 1e-9 && phi <= window.1 + 1e-9, "{phi}");
    }
    // The same points as the unrestricted conversion, just fewer.
    let full: std::collections::HashMap<[u32; 2], Point3<f32>> = all
        .sources
        .iter()
        .copied()
        .zip(all.cloud.points().iter().copied())
        .collect();
    for (src, p) in out.sources.iter().zip(out.cloud.points()) {
        assert_eq!(full[src], *p);
    }
}
