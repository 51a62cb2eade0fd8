//! Pose-graph solves: the standard benchmarks of the shared data (`pose_graphs/`, README §5)
//! from the file's values (parking-garage, M3500) and with the chordal initialisation
//! (sphere2500, M3500), and the incremental case: the solve after adding one loop closure
//! to a solved 1,000-node SE(3) graph, warm-started from the previous solution.
//!
//! `cargo bench -p olmap --bench graph` (needs the shared data for the file benchmarks).

use divan::Bencher;
use nalgebra::Matrix6;
use olmap::geometry::Pose;
use olmap::graph::{read_g2o, EdgeKind, Init, Kernel, PoseGraph, SolveParams, Space};

fn main() {
    divan::main();
}

fn solve_file(bencher: Bencher, name: &str, init: Init) {
    let Some(dir) = olmap::test_data::dir() else {
        return;
    };
    let graph = read_g2o(&dir.join("pose_graphs").join(name)).expect("benchmark file");
    let params = SolveParams {
        init,
        ..SolveParams::default()
    };
    bencher
        .with_inputs(|| graph.clone())
        .bench_local_values(|mut g| g.optimise(&params).expect("solve").final_cost);
}

#[divan::bench(sample_count = 5)]
fn parking_garage_from_file(bencher: Bencher) {
    solve_file(bencher, "parking-garage.g2o", Init::None);
}

#[divan::bench(sample_count = 5)]
fn sphere2500_chordal(bencher: Bencher) {
    solve_file(bencher, "sphere2500.g2o", Init::Chordal);
}

#[divan::bench(sample_count = 5)]
fn m3500_from_file(bencher: Bencher) {
    solve_file(bencher, "M3500.g2o", Init::None);
}

#[divan::bench(sample_count = 5)]
fn m3500_chordal(bencher: Bencher) {
    solve_file(bencher, "M3500.g2o", Init::Chordal);
}

/// A robot driving a 1,000-pose spiral through a building (3 laps of a 40 m loop, slowly
/// climbing), odometry with a little bias, loop closures every 10th pose to the lap
/// below; solved once.
fn solved_spiral() -> PoseGraph {
    let n = 1000u64;
    let lap = 333u64;
    let truth = |k: u64| {
        let a = std::f64::consts::TAU * k as f64 / lap as f64;
        let r = 40.0 / std::f64::consts::TAU;
        Pose::from_xyz_ypr(
            r * a.cos(),
            r * a.sin(),
            0.001 * k as f64,
            a + std::f64::consts::FRAC_PI_2,
            0.0,
            0.0,
        )
    };
    let mut g = PoseGraph::new(Space::Se3);
    let info = Matrix6::from_diagonal(&nalgebra::Vector6::new(1e4, 1e4, 1e4, 4e4, 4e4, 4e4));
    let bias = Pose::from_xyz_ypr(0.001, 0.0005, 0.0, 0.002, 0.0005, -0.0005);
    let mut guess = truth(0);
    g.add_node_se3(0, guess).unwrap();
    for k in 1..n {
        let odo = truth(k - 1).inverse() * truth(k) * bias;
        guess = guess * odo;
        g.add_node_se3(k, guess).unwrap();
        g.add_edge_se3(k - 1, k, EdgeKind::Odometry, odo, info, Kernel::None)
            .unwrap();
    }
    for k in (lap..n - 1).step_by(10) {
        let t = truth(k).inverse() * truth(k - lap);
        g.add_edge_se3(
            k,
            k - lap,
            EdgeKind::LoopClosure,
            t,
            info,
            Kernel::Dcs(10.0),
        )
        .unwrap();
    }
    g.optimise(&SolveParams::default()).unwrap();
    g
}

/// The solve after one new loop closure (the last pose onto the lap below), warm-started.
#[divan::bench(sample_count = 10)]
fn loop_closure_on_1000_nodes_warm(bencher: Bencher) {
    let base = solved_spiral();
    let n = base.nodes().len() as u64;
    let (a, b) = (n - 1, n - 1 - 333);
    let t = base.pose(a).unwrap().inverse() * base.pose(b).unwrap();
    // The new closure disagrees with the current estimate by 5 cm and 0.5 degrees.
    let t = t * Pose::from_xyz_ypr(0.05, 0.0, 0.0, 0.0087, 0.0, 0.0);
    let info = Matrix6::from_diagonal(&nalgebra::Vector6::new(1e4, 1e4, 1e4, 4e4, 4e4, 4e4));
    bencher
        .with_inputs(|| {
            let mut g = base.clone();
            g.add_edge_se3(a, b, EdgeKind::LoopClosure, t, info, Kernel::Dcs(10.0))
                .unwrap();
            g
        })
        .bench_local_values(|mut g| {
            let r = g.optimise(&SolveParams::default()).expect("solve");
            (r.iterations, r.final_cost)
        });
}
