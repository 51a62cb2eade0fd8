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
