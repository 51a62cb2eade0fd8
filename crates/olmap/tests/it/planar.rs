//! Planar mapping with loop closure (issue 23): the real CARMEN logs of the shared data
//! (`carmen_2d/`, README §4) mapped from degraded odometry and compared with the logs'
//! corrected poses, and simulated corridors built to break loop closure (a ring, and a
//! straight corridor of identical doors driven there and back).
//!
//! Tolerances: the acceptance (ATE RMSE ≤ 0.10 m and max ≤ 0.30 m against the
//! corrected poses, which README §4.3 says are good to a few cm; ATE after the best rigid
//! fit, the standard definition); for the simulated ring, whose truth is exact,
//! max ≤ 0.10 m.

use nalgebra::Vector2;
use olmap::graph::{EdgeKind, Measurement, Se2};
use olmap::io::carmen::{read_carmen, CarmenLog};
use olmap::mapping::planar::{
    planar_errors, run_planar_log, OdometryNoise, PlanarLogJob, PlanarMapParams, PlanarMapper,
};

const NOISE: OdometryNoise = OdometryNoise {
    distance_fraction: 0.05,
    degrees_per_unit: 2.0,
};

fn log_path(name: &str) -> Option<std::path::PathBuf> {
    Some(crate::data()?.join("carmen_2d").join(name))
}

fn job(log: std::path::PathBuf, seed: u64, closure: bool) -> PlanarLogJob {
    let mut params = PlanarMapParams::default();
    if !closure {
        params.closure = None;
    }
    PlanarLogJob {
        log,
        max_scans: None,
        max_range: 30.0,
        noise: NOISE,
        noise_seed: seed,
        params,
        poses_out: None,
        graph_out: None,
        map_out: None,
        picture_out: None,
        inject_wrong_closures: 0.0,
    }
}

#[test]
fn carmen_reader_reads_the_intel_log_as_the_readme_describes() {
    let Some(path) = log_path("intel-corrected.log.gz") else {
        return;
    };
    let log = read_carmen(&path).unwrap();
    // README §4.1: 910 scans of 180 beams; §4.2: both poses are the corrected one.
    assert_eq!(log.scans.len(), 910);
    assert!(log.scans.iter().all(|s| s.ranges.len() == 180));
    assert!(log.scans.iter().all(|s| s.pose == s.odometry));
    assert!(log.max_range > 49.0, "no-return value {}", log.max_range);
    assert!(
        log.skipped_lines > 10_000,
        "ODOM/NEFF lines: {}",
        log.skipped_lines
    );
    let poses = olmap::io::read_poses(&path).unwrap();
    assert_eq!(poses.len(), 910);
    assert!(poses.get(&CarmenLog::scan_name(909)).is_some());
}

/// The whole Intel log with 5 % of its closures duplicated as wrong ones (2-5 m off):
/// within the bounds, every wrong closure down-weighted; without loop closure the
/// error is far larger (what the graph buys).
#[test]
fn intel_log_maps_within_bounds_with_loop_closure_and_wrong_closures_injected() {
    let Some(path) = log_path("intel-corrected.log.gz") else {
        return;
    };
    let mut with = job(path.clone(), 1, true);
    with.inject_wrong_closures = 0.05;
    let r = run_planar_log(&with, &mut |_, _| {}).unwrap();
    eprintln!("intel with closure: {:?}", r.errors);
    assert_eq!(r.placed, 910);
    assert!(r.closures_accepted > 50, "{} closures", r.closures_accepted);
    assert!(r.errors.ate_rmse_m <= 0.10, "{:?}", r.errors);
    assert!(r.errors.ate_max_m <= 0.30, "{:?}", r.errors);
    assert!(!r.injected_closures.is_empty());
    for c in &r.injected_closures {
        assert!(c.down_weighted, "wrong closure kept: {c:?}");
    }
    let without = run_planar_log(&job(path, 1, false), &mut |_, _| {}).unwrap();
    eprintln!("intel without closure: {:?}", without.errors);
    assert!(without.errors.ate_rmse_m > 3.0 * r.errors.ate_rmse_m);
    // Sequential registration alone still beats the odometry by far.
    assert!(without.errors.ate_rmse_m < 0.5 * without.odometry_errors.ate_rmse_m);
}

/// The ACES log (a large loop of long corridors, revisited from the other direction) with
/// loop closure on three noise seeds: within the bounds on every seed. Before the
/// target normals admitted a real local map's 2-3 cm of scatter (`PlanarIcpParams::
/// max_line_ratio` 0.1), its revisits matched 20-40 % of their points and were refused:
/// 0.104 / 0.160 / 0.125 m rms, up to 0.417 m.
#[test]
fn aces_log_maps_within_bounds_on_three_noise_seeds() {
    let Some(path) = log_path("aces-corrected.log.gz") else {
        return;
    };
    for seed in 1..=3 {
        let r = run_planar_log(&job(path.clone(), seed, true), &mut |_, _| {}).unwrap();
        eprintln!("aces seed {seed}: {:?}", r.errors);
        assert_eq!(r.placed, 440);
        assert!(r.errors.ate_rmse_m <= 0.10, "seed {seed}: {:?}", r.errors);
        assert!(r.errors.ate_max_m <= 0.30, "seed {seed}: {:?}", r.errors);
    }
}

/// Same inputs, same poses, whatever the thread count (the graph solve runs in parallel).
#[test]
fn planar_mapping_is_deterministic_across_thread_counts() {
    let Some(path) = log_path("intel-corrected.log.gz") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = |threads: usize, out: &str| {
        let mut j = job(path.clone(), 2, true);
        j.max_scans = Some(250);
        j.poses_out = Some(dir.path().join(out));
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| run_planar_log(&j, &mut |_, _| {}).unwrap());
        std::fs::read(dir.path().join(out)).unwrap()
    };
    assert_eq!(run(1, "a.txt"), run(2, "b.txt"));
}

// ---------------------------------------------------------------------------------------
// Simulated corridors: a 2D ray caster over wall segments.

struct World {
    walls: Vec<(Vector2<f64>, Vector2<f64>)>,
}

impl World {
    fn rect(&mut self, x0: f64, y0: f64, x1: f64, y1: f64) {
        let c = [
            Vector2::new(x0, y0),
            Vector2::new(x1, y0),
            Vector2::new(x1, y1),
            Vector2::new(x0, y1),
        ];
        for k in 0..4 {
            self.walls.push((c[k], c[(k + 1) % 4]));
        }
    }

    /// 180 beams over 180° (as the CARMEN logs), 1 cm range noise, returns within 30 m.
    fn scan(&self, pose: &Se2, seed: u64) -> Vec<Vector2<f64>> {
        let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut noise = || {
            // Sum of 4 uniforms: near-normal, σ ≈ 1 cm.
            let mut s = 0.0;
            for _ in 0..4 {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                s += (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            }
            s * 0.01 * (12.0f64 / 4.0).sqrt()
        };
        let o = Vector2::new(pose.x, pose.y);
        let mut out = Vec::new();
        for k in 0..180 {
            let a = -std::f64::consts::FRAC_PI_2 + k as f64 * std::f64::consts::PI / 180.0;
            let d = Vector2::new((pose.theta + a).cos(), (pose.theta + a).sin());
            let mut best = f64::INFINITY;
            for (p, q) in &self.walls {
                let e = q - p;
                let den = d.x * e.y - d.y * e.x;
                if den.abs() < 1e-12 {
                    continue;
                }
                let w = p - o;
                let t = (w.x * e.y - w.y * e.x) / den;
                let u = (w.x * d.y - w.y * d.x) / den;
                if t > 0.05 && (0.0..=1.0).contains(&u) && t < best {
                    best = t;
                }
            }
            if best < 30.0 {
                let r = best + noise();
                out.push(Vector2::new(r * a.cos(), r * a.sin()));
            }
        }
        out
    }
}

/// Poses every `step` metres along a closed polyline (turning in place at corners in 15°
/// steps), `laps` times round.
fn path(corners: &[Vector2<f64>], step: f64, laps: f64) -> Vec<Se2> {
    let mut out = Vec::new();
    let n = corners.len();
    let total_legs = (laps * n as f64).round() as usize;
    for leg in 0..total_legs {
        let a = corners[leg % n];
        let b = corners[(leg + 1) % n];
        let heading = (b.y - a.y).atan2(b.x - a.x);
        if let Some(last) = out.last().copied() {
            let last: Se2 = last;
            let turn = olmap::geometry::wrap_angle(heading - last.theta);
            let steps = (turn.abs() / 15f64.to_radians()).ceil() as usize;
            for s in 1..steps {
                out.push(Se2::new(
                    last.x,
                    last.y,
                    last.theta + turn * s as f64 / steps as f64,
                ));
            }
        }
        let len = (b - a).norm();
        let k = (len / step).round() as usize;
        for s in 0..k {
            let p = a + (b - a) * (s as f64 / k as f64);
            out.push(Se2::new(p.x, p.y, heading));
        }
    }
    out
}

fn map_world(world: &World, truth: &[Se2], seed: u64) -> PlanarMapper {
    map_world_with(world, truth, seed, PlanarMapParams::default())
}

fn map_world_with(
    world: &World,
    truth: &[Se2],
    seed: u64,
    params: PlanarMapParams,
) -> PlanarMapper {
    let odometry = NOISE.degrade(truth, seed);
    let mut mapper = PlanarMapper::new(params);
    for (i, t) in truth.iter().enumerate() {
        mapper
            .add_scan(
                format!("s{i:04}"),
                world.scan(t, seed * 100_000 + i as u64),
                Some(odometry[i]),
            )
            .unwrap();
    }
    mapper.optimise().unwrap();
    mapper
}

/// Every accepted closure's measurement against the true relative pose: the worst
/// translation (m) and rotation (deg) error.
fn worst_closure(mapper: &PlanarMapper, truth: &[Se2]) -> (usize, f64, f64) {
    let (mut n, mut t, mut r) = (0, 0.0f64, 0.0f64);
    for e in mapper.graph().edges() {
        let (
            EdgeKind::LoopClosure,
            Measurement::Se2 {
                t_i_j, information, ..
            },
        ) = (e.kind, e.measurement)
        else {
            continue;
        };
        let (i, j) = (e.from as usize, e.to as usize);
        let real = truth[i].inverse().compose(&truth[j]);
        n += 1;
        // A corridor closure holds nothing along its corridor (a null direction of its
        // information's translation block): its error there is not a claim.
        let mut d = Vector2::new(t_i_j.x - real.x, t_i_j.y - real.y);
        let block = information.fixed_view::<2, 2>(0, 0).into_owned();
        let eig = block.symmetric_eigen();
        let k = eig.eigenvalues.imin();
        if eig.eigenvalues[k] <= 1e-9 * eig.eigenvalues.max().max(1e-300) {
            let u: Vector2<f64> = eig.eigenvectors.column(k).into_owned();
            d -= u * u.dot(&d);
        }
        t = t.max(d.norm());
        r = r.max(
            olmap::geometry::wrap_angle(t_i_j.theta - real.theta)
                .abs()
                .to_degrees(),
        );
    }
    (n, t, r)
}

/// A 64 m corridor ring (22 m × 14 m outside, 2 m wide) with a few pillars at irregular
/// places, driven 1.25 times round from degraded odometry: every closure right, and the
/// map within 0.10 m of the truth everywhere.
#[test]
fn simulated_corridor_ring_closes_its_loop() {
    let mut world = World { walls: Vec::new() };
    world.rect(0.0, 0.0, 22.0, 14.0);
    world.rect(2.0, 2.0, 20.0, 12.0);
    for (x, y) in [
        (4.3, 0.1),
        (9.1, 1.75),
        (15.6, 0.1),
        (21.7, 5.2),
        (17.0, 13.75),
        (6.2, 13.75),
        (0.1, 8.4),
        (1.75, 3.3),
    ] {
        world.rect(x, y, x + 0.15, y + 0.15);
    }
    let corners = [
        Vector2::new(1.0, 1.0),
        Vector2::new(21.0, 1.0),
        Vector2::new(21.0, 13.0),
        Vector2::new(1.0, 13.0),
    ];
    let truth = path(&corners, 0.5, 1.25);
    for seed in [1, 2] {
        let mapper = map_world(&world, &truth, seed);
        let (n, t, r) = worst_closure(&mapper, &truth);
        assert!(n > 0, "seed {seed}: no loop closed");
        assert!(
            t < 0.2 && r < 1.5,
            "seed {seed}: a wrong closure ({t} m, {r} deg)"
        );
        let poses: Vec<Option<Se2>> = (0..truth.len()).map(|i| mapper.pose_of(i)).collect();
        let e = planar_errors(&poses, &truth);
        eprintln!("ring seed {seed}: {n} closures, {e:?}");
        assert!(e.ate_max_m <= 0.10, "seed {seed}: {e:?}");
    }
}

/// The ACES log (440 scans about 1 m apart, long bare corridors, one large loop): the big
/// loop's correction is metres, far beyond what the robust kernel keeps at the estimate
/// before it, so it must be held, confirmed by a second closure and applied. Every
/// accepted closure must be right against the corrected poses (good to a few cm, data
/// README §4.3; 0.3 m / 2° allows for scan matching on 1° beams), at least one must span
/// the big loop (≥ 100 m of travel), and the map must keep less than a tenth of the
/// odometry's error.
#[test]
fn aces_big_loop_closes_through_a_confirmed_held_closure() {
    let Some(path) = log_path("aces-corrected.log.gz") else {
        return;
    };
    let log = read_carmen(&path).unwrap();
    let reference: Vec<Se2> = log
        .scans
        .iter()
        .map(|s| Se2::new(s.pose[0], s.pose[1], s.pose[2]))
        .collect();
    let mut travel = vec![0.0; reference.len()];
    for i in 1..reference.len() {
        let d = reference[i - 1].inverse().compose(&reference[i]);
        travel[i] = travel[i - 1] + d.x.hypot(d.y);
    }
    let odometry = NOISE.degrade(&reference, 1);
    let params = PlanarMapParams {
        odometry_noise: NOISE,
        ..PlanarMapParams::default()
    };
    let mut mapper = PlanarMapper::new(params);
    let no_return = log.max_range.min(30.0) - 1e-6;
    let mut confirmed = 0;
    for (i, scan) in log.scans.iter().enumerate() {
        let p = mapper
            .add_scan(
                CarmenLog::scan_name(i),
                scan.points(no_return, 0.05),
                Some(odometry[i]),
            )
            .unwrap();
        confirmed += p
            .closures
            .iter()
            .filter(|c| c.corroborates.is_some())
            .count();
    }
    mapper.optimise().unwrap();
    let (n, t, r) = worst_closure(&mapper, &reference);
    let longest = mapper
        .graph()
        .edges()
        .iter()
        .filter(|e| e.kind == EdgeKind::LoopClosure)
        .map(|e| (travel[e.to as usize] - travel[e.from as usize]).abs())
        .fold(0.0, f64::max);
    let poses: Vec<Option<Se2>> = (0..reference.len()).map(|i| mapper.pose_of(i)).collect();
    let with = planar_errors(&poses, &reference);
    let odo: Vec<Option<Se2>> = odometry.iter().copied().map(Some).collect();
    let alone = planar_errors(&odo, &reference);
    eprintln!(
        "aces seed 1: {n} closures ({confirmed} confirmed held ones), longest {longest:.0} m, worst {t:.3} m / {r:.2} deg; {with:?}; odometry {alone:?}"
    );
    assert!(confirmed > 0, "no held closure was confirmed");
    assert!(t < 0.3 && r < 2.0, "a wrong closure ({t} m, {r} deg)");
    assert!(
        longest >= 100.0,
        "the big loop was not closed ({longest} m)"
    );
    assert!(
        with.ate_rmse_m <= 0.1 * alone.ate_rmse_m,
        "{with:?} vs odometry {alone:?}"
    );
}

/// A straight 60 m corridor with identical doors every 4 m, driven to the end and back:
/// every place on the way back looks like its neighbours 4 m away. Closures there must be
/// refused or right; none may be 4 m off.
#[test]
fn simulated_corridor_of_identical_doors_never_closes_a_wrong_loop() {
    let mut world = World { walls: Vec::new() };
    // Walls at y = ±1 with 1 m door recesses (0.3 m deep) every 4 m on the left side.
    world
        .walls
        .push((Vector2::new(0.0, -1.0), Vector2::new(60.0, -1.0)));
    world
        .walls
        .push((Vector2::new(0.0, -1.0), Vector2::new(0.0, 1.0)));
    world
        .walls
        .push((Vector2::new(60.0, -1.0), Vector2::new(60.0, 1.0)));
    let mut x = 0.0;
    while x < 60.0 {
        let door = x + 1.5;
        world
            .walls
            .push((Vector2::new(x, 1.0), Vector2::new(door, 1.0)));
        world
            .walls
            .push((Vector2::new(door, 1.0), Vector2::new(door, 1.3)));
        world
            .walls
            .push((Vector2::new(door, 1.3), Vector2::new(door + 1.0, 1.3)));
        world
            .walls
            .push((Vector2::new(door + 1.0, 1.3), Vector2::new(door + 1.0, 1.0)));
        world.walls.push((
            Vector2::new(door + 1.0, 1.0),
            Vector2::new((x + 4.0).min(60.0), 1.0),
        ));
        x += 4.0;
    }
    let corners = [Vector2::new(1.0, 0.0), Vector2::new(59.0, 0.0)];
    // Two legs of a two-corner loop: to the far end, turn round, back.
    let there_and_back = path(&corners, 0.5, 1.0);
    for seed in [1, 2, 3] {
        let mapper = map_world(&world, &there_and_back, seed);
        let (n, t, r) = worst_closure(&mapper, &there_and_back);
        eprintln!("door corridor seed {seed}: {n} closures, worst {t:.3} m {r:.2} deg");
        assert!(
            t < 1.0 && r < 3.0,
            "seed {seed}: a wrong closure ({t} m, {r} deg)"
        );
    }
}

/// A bare corridor 40 m long and 2.4 m wide (no doors, no pillars), driven to the end and
/// back: on the way back every closure is ambiguous along the corridor, so none is
/// accepted as a full closure. Corridor closures (heading and position across only) close
/// it anyway where the estimate has drifted little (seed 1), each right across the corridor
/// and in heading; where it has drifted more (seed 2) a corridor closure would be a large
/// correction, which only a full closure could confirm (a bare corridor has none), so none
/// is kept. (Where along the corridor the robot is stays the odometry's: nothing in the
/// world says.)
#[test]
fn a_bare_corridor_closes_through_closures_that_hold_only_across_it() {
    let mut world = World { walls: Vec::new() };
    world.rect(0.0, -1.2, 40.0, 1.2);
    let corners = [Vector2::new(1.0, 0.0), Vector2::new(39.0, 0.0)];
    let there_and_back = path(&corners, 0.5, 1.0);
    for seed in [1, 2] {
        let with = map_world(&world, &there_and_back, seed);
        let corridor_closures = with
            .graph()
            .edges()
            .iter()
            .filter(|e| match (e.kind, e.measurement) {
                (EdgeKind::LoopClosure, Measurement::Se2 { information, .. }) => {
                    information.fixed_view::<2, 2>(0, 0).determinant().abs()
                        <= 1e-9 * information.fixed_view::<2, 2>(0, 0).norm_squared()
                }
                _ => false,
            })
            .count();
        let (n, t, r) = worst_closure(&with, &there_and_back);
        let mut params = PlanarMapParams::default();
        params.closure.as_mut().unwrap().partial = false;
        let without = map_world_with(&world, &there_and_back, seed, params);
        let (n0, _, _) = worst_closure(&without, &there_and_back);
        eprintln!(
            "bare corridor seed {seed}: {n} closures ({corridor_closures} along the corridor), worst {t:.3} m {r:.2} deg; without corridor closures: {n0}"
        );
        assert_eq!(n0, 0, "seed {seed}: a full closure in a bare corridor");
        assert_eq!(n, corridor_closures, "seed {seed}: a full closure");
        if seed == 1 {
            assert!(corridor_closures > 0, "seed {seed}: no corridor closure");
        }
        // Across the corridor and in heading: the scanner's 1 cm noise on 1° beams.
        assert!(
            t < 0.1 && r < 1.0,
            "seed {seed}: a wrong closure ({t} m, {r} deg)"
        );
    }
}

/// Two bare corridors side by side (2.4 m wide, 40 m long, one 0.2 m wall between them,
/// joined at the far end), driven along the first, round the end and back along the
/// second: from inside, the second looks exactly like the first, 2.6 m away. A corridor
/// closure from the second onto the first would pull the map 2.6 m across; none may be
/// kept.
#[test]
fn side_by_side_bare_corridors_are_never_closed_onto_each_other() {
    let mut world = World { walls: Vec::new() };
    world.rect(0.0, -1.2, 42.4, 3.8);
    world.rect(0.0, 1.2, 40.0, 1.4);
    let corners = [
        Vector2::new(1.0, 0.0),
        Vector2::new(41.2, 0.0),
        Vector2::new(41.2, 2.6),
        Vector2::new(1.0, 2.6),
    ];
    let route = path(&corners, 0.5, 0.75);
    for seed in [1, 2, 3] {
        let mapper = map_world(&world, &route, seed);
        let (n, t, r) = worst_closure(&mapper, &route);
        let poses: Vec<Option<Se2>> = (0..route.len()).map(|i| mapper.pose_of(i)).collect();
        let e = planar_errors(&poses, &route);
        eprintln!("side-by-side seed {seed}: {n} closures, worst {t:.3} m {r:.2} deg; {e:?}");
        assert!(
            t < 1.0 && r < 3.0,
            "seed {seed}: a wrong closure ({t} m, {r} deg)"
        );
    }
}
