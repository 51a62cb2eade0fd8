//! Mutual localisation (thesis §3.3.1-3.3.2, §3.5).

use nalgebra::Complex;
use olmap::sim::SimRng;
use olmap::team::{
    expected_position_error, mutual_pose, MutualObservation, MutualParams, MutualReject,
};

/// The exact observation of robot B at `(x, y, heading)` by A at the origin (heading 0),
/// both with beacons `d` ahead of their scanners.
fn observe(x: f64, y: f64, heading: f64, d: f64) -> MutualObservation {
    let b_beacon = (x + d * heading.cos(), y + d * heading.sin());
    let a = (b_beacon.0.powi(2) + b_beacon.1.powi(2)).sqrt();
    let alpha = b_beacon.1.atan2(b_beacon.0);
    // A's beacon (d, 0) seen from B.
    let (dx, dy) = (d - x, -y);
    let b = (dx * dx + dy * dy).sqrt();
    let beta = dy.atan2(dx) - heading;
    MutualObservation {
        a,
        alpha,
        b,
        beta,
        d,
    }
}

fn angle_diff(a: f64, b: f64) -> f64 {
    let t = std::f64::consts::TAU;
    ((a - b + std::f64::consts::PI).rem_euclid(t) - std::f64::consts::PI).abs()
}

/// Brute force: B's heading φ solves `d - b e^{i(φ+β)} + d e^{iφ} = a e^{iα}` (B's
/// scanner reached from A's beacon, B's beacon from B's scanner); scan φ finely, then
/// golden-section search on the squared residual.
fn numeric(o: &MutualObservation) -> (f64, f64, f64) {
    let f = |phi: f64| {
        let c = Complex::new(o.d, 0.0) - Complex::from_polar(o.b, phi + o.beta);
        let beacon = c + Complex::from_polar(o.d, phi);
        (beacon - Complex::from_polar(o.a, o.alpha)).norm_sqr()
    };
    let n = 36_000;
    let step = std::f64::consts::TAU / n as f64;
    let best = (0..n)
        .map(|k| -std::f64::consts::PI + k as f64 * step)
        .min_by(|x, y| f(*x).total_cmp(&f(*y)))
        .unwrap();
    let (mut lo, mut hi) = (best - step, best + step);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..200 {
        let (m1, m2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if f(m1) < f(m2) {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    let phi = 0.5 * (lo + hi);
    let c = Complex::new(o.d, 0.0) - Complex::from_polar(o.b, phi + o.beta);
    (c.re, c.im, phi)
}

#[test]
fn closed_form_agrees_with_brute_force_and_the_truth() {
    let mut rng = SimRng::new(42);
    for _ in 0..500 {
        let (r, bearing) = (rng.range(1.0, 8.0), rng.range(-3.1, 3.1));
        let (x, y) = (r * bearing.cos(), r * bearing.sin());
        let heading = rng.range(-3.1, 3.1);
        let d = [0.0, 0.07, 0.2][rng.index(3)];
        let o = observe(x, y, heading, d);
        let fix = mutual_pose(&o, &MutualParams::default()).unwrap();
        assert!((fix.s1 - fix.s2).abs() < 1e-9);
        assert!(
            (fix.x - x).abs() < 1e-9 && (fix.y - y).abs() < 1e-9,
            "{fix:?} vs {x} {y}"
        );
        assert!(angle_diff(fix.heading, heading) < 1e-9);
        let (nx, ny, nphi) = numeric(&o);
        assert!(
            (fix.x - nx).abs() < 1e-9 && (fix.y - ny).abs() < 1e-9,
            "closed form ({}, {}) vs numeric ({nx}, {ny})",
            fix.x,
            fix.y
        );
        assert!(angle_diff(fix.heading, nphi) < 1e-9);
    }
}

#[test]
fn distractors_are_rejected() {
    // One robot takes a retroreflective distractor somewhere in a 10 x 10 m room for the
    // other's beacon: the separations then disagree.
    let mut rng = SimRng::new(7);
    let trials = 2000;
    let mut rejected = 0;
    for _ in 0..trials {
        let (r, bearing) = (rng.range(1.0, 8.0), rng.range(-1.5, 1.5));
        let heading = rng.range(-3.1, 3.1);
        let mut o = observe(r * bearing.cos(), r * bearing.sin(), heading, 0.07);
        let (dx, dy) = (rng.range(-5.0, 5.0), rng.range(-5.0, 5.0));
        o.a = (dx * dx + dy * dy).sqrt().max(0.3);
        o.alpha = dy.atan2(dx);
        if matches!(
            mutual_pose(&o, &MutualParams::default()),
            Err(MutualReject::Distractor { .. })
        ) {
            rejected += 1;
        }
    }
    let share = rejected as f64 / trials as f64;
    eprintln!("distractors rejected: {:.1} %", 100.0 * share);
    assert!(share >= 0.95, "{share}");
}

#[test]
fn the_error_model_does_not_grow_with_separation() {
    // (3.37): Δa + w + (a / b) Δd, with a ≈ b.
    let near = observe(1.5, 0.2, 3.0, 0.07);
    let far = observe(7.5, 1.0, 3.0, 0.07);
    let en = expected_position_error(&near, 0.02, 0.01, 0.0).unwrap();
    let ef = expected_position_error(&far, 0.02, 0.01, 0.0).unwrap();
    assert!((en - 0.03).abs() < 1e-12 && (ef - 0.03).abs() < 1e-12);
    assert!(
        expected_position_error(&MutualObservation { a: 0.0, ..near }, 0.02, 0.01, 0.0).is_err()
    );
    // Degenerate input is an error, not a panic.
    let bad = MutualObservation { b: -1.0, ..near };
    assert!(matches!(
        mutual_pose(&bad, &MutualParams::default()),
        Err(MutualReject::Degenerate(_))
    ));
}

/// Beacons 0.1 m in diameter show only two returns at 8 m to a 0.25° scanner (3.5 cm
/// apart, 50° of retroreflection each side): the detector needs three.
const BEACON_RADIUS: f64 = 0.075;
const BEACON_OFFSET: f64 = 0.15;

/// Two robots with front beacons (0.15 m ahead, radius 0.075 m) in a large empty room, B
/// `r` metres from A, each within the other's 100° field of view; both scan with the
/// 0.25° scanner (range noise `sigma`). Returns the scans and B's true pose in A's frame.
fn scan_pair(
    rng: &mut SimRng,
    sigma: f64,
    r: f64,
    seed: u64,
    k: u64,
) -> (
    olmap::cloud::LaserScan,
    olmap::cloud::LaserScan,
    (f64, f64, f64),
) {
    use olmap::geometry::Pose;
    use olmap::sim::{box_room, PlanarScanner, RobotModel};
    let world = box_room(nalgebra::Vector3::new(24.0, 24.0, 3.0));
    let model = RobotModel {
        beacon_radius: BEACON_RADIUS,
        ..RobotModel::front_beacon(BEACON_OFFSET)
    };
    let ha = rng.range(-3.1, 3.1);
    let bearing = ha + rng.range(-0.7, 0.7);
    let (xb, yb) = (12.0 + r * bearing.cos(), 12.0 + r * bearing.sin());
    let hb = (12.0 - yb).atan2(12.0 - xb) + rng.range(-0.7, 0.7);
    let pa = Pose::from_xyz_ypr(12.0, 12.0, 0.0, ha, 0.0, 0.0);
    let pb = Pose::from_xyz_ypr(xb, yb, 0.0, hb, 0.0, 0.0);
    let mut scanner = PlanarScanner::sick_100_quarter_degree();
    scanner.noise.sigma = sigma;
    let sa = scanner.scan(
        &world,
        &model.objects(1, &pb),
        &(pa * model.scanner2d_pose()),
        seed,
        2 * k,
    );
    let sb = scanner.scan(
        &world,
        &model.objects(0, &pa),
        &(pb * model.scanner2d_pose()),
        seed,
        2 * k + 1,
    );
    let rel = pa.inverse() * pb;
    (
        sa,
        sb,
        (
            rel.translation().x,
            rel.translation().y,
            rel.yaw_pitch_roll().0,
        ),
    )
}

#[test]
fn mutual_localisation_from_simulated_scans_is_accurate_at_any_separation() {
    use olmap::beacon::ReflectiveParams;
    use olmap::team::mutual_from_scans;
    for sigma in [0.01, 0.02] {
        let mut rng = SimRng::new(99);
        let detect = ReflectiveParams {
            max_rms: 2.0 * sigma,
            ..Default::default()
        };
        // (sum of position errors, sum of heading errors, fixes, trials) near and far.
        let mut bins = [(0.0, 0.0, 0usize, 0usize); 2];
        for k in 0..300u64 {
            let r = rng.range(1.0, 8.0);
            let (sa, sb, (x, y, h)) = scan_pair(&mut rng, sigma, r, 5, k);
            let bin = &mut bins[usize::from(r > 4.5)];
            bin.3 += 1;
            let params = MutualParams {
                // Two noisy separations: allow for 2.5 sigma of their difference.
                max_separation_mismatch: (2.5 * std::f64::consts::SQRT_2 * sigma).max(0.02),
            };
            let got = mutual_from_scans(&sa, &sb, BEACON_RADIUS, BEACON_OFFSET, &detect, &params);
            if let Err(e) = &got {
                eprintln!("r {r:.2}: {e}");
            }
            if let Ok(fix) = got {
                bin.0 += ((fix.x - x).powi(2) + (fix.y - y).powi(2)).sqrt();
                bin.1 += angle_diff(fix.heading, h).to_degrees();
                bin.2 += 1;
            }
        }
        let mean = |b: &(f64, f64, usize, usize)| (b.0 / b.2 as f64, b.1 / b.2 as f64);
        let (near, far) = (mean(&bins[0]), mean(&bins[1]));
        eprintln!(
            "sigma {sigma}: 1-4.5 m: {}/{} fixes, {:.4} m, {:.2} deg; 4.5-8 m: {}/{} fixes, {:.4} m, {:.2} deg",
            bins[0].2, bins[0].3, near.0, near.1, bins[1].2, bins[1].3, far.0, far.1
        );
        for b in &bins {
            assert!(b.2 as f64 >= 0.8 * b.3 as f64, "too few fixes: {b:?}");
        }
        // Thesis §3.5: about 0.01-0.02 m and 1-1.5 degrees, independent of separation.
        for (pos, head) in [near, far] {
            assert!(pos < 0.03 && head < 2.0, "{pos} m, {head} deg");
        }
        assert!(
            far.0 < 2.0 * near.0 + 0.005,
            "position error grows with separation"
        );
    }
}

#[test]
fn the_3d_variant_projects_sightings_of_beacons_above_the_scanners() {
    use olmap::geometry::Pose;
    use olmap::sim::{box_room, sightings_at, RobotModel, SightingModel};
    // Thesis §6.3.3: beacons straight above the 3D scanners; project to the floor, d = 0.
    let world = box_room(nalgebra::Vector3::new(12.0, 10.0, 3.0));
    let model = RobotModel::default();
    let exact = SightingModel {
        range_sigma: 0.0,
        angle_sigma: 0.0,
        ..Default::default()
    };
    let mut rng = SimRng::new(3);
    let mut checked = 0;
    for _ in 0..50 {
        let a = Pose::from_xyz_ypr(6.0, 5.0, 0.0, rng.range(-3.1, 3.1), 0.0, 0.0);
        let (r, t) = (rng.range(1.0, 4.5), rng.range(-3.1, 3.1));
        let b = Pose::from_xyz_ypr(
            6.0 + r * t.cos(),
            5.0 + r * t.sin(),
            0.0,
            rng.range(-3.1, 3.1),
            0.0,
            0.0,
        );
        let objects: Vec<_> = [a, b]
            .iter()
            .enumerate()
            .flat_map(|(k, p)| model.objects(k, p))
            .collect();
        let s = sightings_at(&world, &model, &exact, &[a, b], &objects, 0, 0.0, 1);
        let (Some(ab), Some(ba)) = (
            s.iter().find(|x| x.observer == 0),
            s.iter().find(|x| x.observer == 1),
        ) else {
            continue; // one is behind the other's mast (outside the 270° view)
        };
        let o = MutualObservation::from_3d(
            ab.range,
            ab.bearing,
            ab.elevation,
            ba.range,
            ba.bearing,
            ba.elevation,
        );
        let fix = mutual_pose(&o, &MutualParams::default()).unwrap();
        let truth = a.inverse() * b;
        assert!((fix.x - truth.translation().x).abs() < 1e-9);
        assert!((fix.y - truth.translation().y).abs() < 1e-9);
        assert!(angle_diff(fix.heading, truth.yaw_pitch_roll().0) < 1e-9);
        checked += 1;
    }
    // Each sees the other in its 270° view about 56 % of the time.
    assert!(checked >= 15, "only {checked} two-way sightings");
}
