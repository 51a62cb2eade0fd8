//! Map building: the 3DTK set and synthetic hall trajectories (10, 20, 40 scans in
//! trajectory order), batch mode, with and without odometry. Time per scan and the number
//! of registrations show how the cost grows with the scan count.
//!
//! `cargo bench -p olmap --bench mapping`

use std::sync::OnceLock;

use divan::counter::ItemsCount;
use divan::Bencher;
use olmap::fixtures::{hall, hall_trajectory, scan_of};
use olmap::geometry::Pose;
use olmap::mapping::{build_map, MapParams, ScanInput};

fn main() {
    divan::main();
}

fn threedtk(odometry: bool) -> Vec<ScanInput> {
    olmap::test_data::dir()
        .map(|d| olmap::fixtures::threedtk_scans(&d, odometry).unwrap())
        .unwrap_or_default()
}

fn synthetic(n: usize, odometry: bool) -> Vec<ScanInput> {
    static WORLD: OnceLock<Vec<nalgebra::Point3<f64>>> = OnceLock::new();
    let world = WORLD.get_or_init(|| hall(0.15));
    // 40 stops fill the 40 m hall at 0.9 m spacing; fewer stops cover its start.
    hall_trajectory(n, 0.9)
        .iter()
        .enumerate()
        .map(|(i, t)| ScanInput {
            name: format!("stop{i:02}"),
            cloud: scan_of(world, t, 8.0),
            odometry: odometry.then(|| {
                Pose::from_xyz_ypr(
                    0.03 * t.translation().x,
                    0.0,
                    0.0,
                    (0.5 * i as f64).to_radians(),
                    0.0,
                    0.0,
                ) * *t
            }),
        })
        .collect()
}

fn params(resolution: f64) -> MapParams {
    let mut p = MapParams::default();
    p.register.search.resolution = resolution;
    p
}

fn run(bencher: Bencher, scans: Vec<ScanInput>, resolution: f64, label: &str, truth: &[Pose]) {
    if scans.is_empty() {
        return;
    }
    let m = build_map(&scans, &params(resolution), |_, _| {}).unwrap();
    // Largest position error of a placed scan against the truth (in the first scan's frame).
    let worst = m
        .placed
        .iter()
        .filter(|_| !truth.is_empty())
        .map(|p| {
            let t = truth[0].inverse() * truth[p.index];
            (t.translation() - p.pose.translation()).norm()
        })
        .fold(0.0, f64::max);
    eprintln!(
        "[{label}] {} of {} placed, {} registrations, {:.2} s ({:.3} s per scan), worst error {}",
        m.placed.len(),
        scans.len(),
        m.registrations,
        m.seconds,
        m.seconds / scans.len() as f64,
        if truth.is_empty() {
            "n/a".to_string()
        } else {
            format!("{worst:.3} m")
        }
    );
    bencher
        .counter(ItemsCount::new(scans.len()))
        .bench(|| build_map(&scans, &params(resolution), |_, _| {}).unwrap());
}

/// The three 3DTK scans at 0.1 m.
#[divan::bench(args = [false, true], sample_count = 3, sample_size = 1)]
fn threedtk_batch(bencher: Bencher, odometry: bool) {
    run(
        bencher,
        threedtk(odometry),
        0.1,
        &format!("3dtk odometry={odometry}"),
        &[],
    );
}

/// Synthetic hall stops in trajectory order at 0.2 m, without odometry.
#[divan::bench(args = [10, 20, 40], sample_count = 2, sample_size = 1)]
fn hall_batch_no_odometry(bencher: Bencher, n: usize) {
    run(
        bencher,
        synthetic(n, false),
        0.2,
        &format!("hall {n} no odometry"),
        &hall_trajectory(n, 0.9),
    );
}

/// Synthetic hall stops in trajectory order at 0.2 m, with drifting odometry.
#[divan::bench(args = [10, 20, 40], sample_count = 2, sample_size = 1)]
fn hall_batch_odometry(bencher: Bencher, n: usize) {
    run(
        bencher,
        synthetic(n, true),
        0.2,
        &format!("hall {n} odometry"),
        &hall_trajectory(n, 0.9),
    );
}
