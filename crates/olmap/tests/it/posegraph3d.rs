//! The 3D pose-graph refinement of placed scans (`olmap::mapping::posegraph`): pairwise
//! registrations as edges, a scan placed off pulled back, the graph exported as g2o.

use olmap::geometry::Pose;
use olmap::graph::{parse_g2o, write_g2o_to, EdgeKind};
use olmap::mapping::posegraph::{refine_placed, GraphRefineParams};
use olmap::mapping::{build_map, MapParams, PlacedScan, Placement, TeamLinks};
use olmap::sim::{simulate, SimConfig, WorldKind};

/// One robot, `stops` stops in the simulated lab (mirror scanner, range σ 0.02 m,
/// typical odometry).
fn lab(stops: usize) -> olmap::sim::SimRobot {
    let config = SimConfig {
        world: WorldKind::Lab,
        seed: 11,
        robots: 1,
        stops,
        ..Default::default()
    };
    simulate(&config, |_, _| {}).unwrap().robots.remove(0)
}

/// A scan placed 0.25 m and 2° off (as a mapper's slide along repeated furniture would
/// leave it) among scans placed right: its neighbours' registrations pull it back. The
/// tolerance is half a 0.1 m map voxel and half a degree; the scans placed right must stay
/// within it too. The same poses with one thread or two.
#[test]
fn a_scan_placed_off_is_pulled_back_by_its_neighbours() {
    let robot = lab(6);
    let scans = robot.scan_inputs();
    let truth: Vec<Pose> = (0..scans.len())
        .map(|i| robot.truth[0].inverse() * robot.truth[i])
        .collect();
    let off = 3;
    let placed: Vec<PlacedScan> = (0..scans.len())
        .map(|i| {
            let mut pose = truth[i];
            if i == off {
                pose = pose * Pose::from_xyz_ypr(0.2, -0.15, 0.0, 2f64.to_radians(), 0.0, 0.0);
            }
            PlacedScan {
                index: i,
                name: scans[i].name.clone(),
                pose,
                order: i,
                overlap_fraction: 1.0,
                significance: f64::INFINITY,
                inlier_fraction: None,
                global: false,
                via: Placement::Odometry,
            }
        })
        .collect();
    let team = TeamLinks::none(scans.len());
    let params = GraphRefineParams::default();
    let refined = refine_placed(&scans, &team, &placed, &params).unwrap();
    let report = &refined.report;
    assert!(
        report.edges.get("registration").copied().unwrap_or(0) >= 3,
        "{report:?}"
    );
    assert!(
        report.edges.get("odometry").copied() == Some(scans.len() - 1),
        "{report:?}"
    );
    assert!(report.final_cost < report.initial_cost, "{report:?}");
    for (i, pose) in refined.poses.iter().enumerate() {
        let e = (pose.translation() - truth[i].translation()).norm();
        let r = pose.rotation().angle_to(&truth[i].rotation()).to_degrees();
        assert!(
            e < 0.05 && r < 0.5,
            "{}: {e:.3} m, {r:.2} deg off; {report:?}",
            scans[i].name
        );
    }
    assert!(report.largest_move_m > 0.2, "{report:?}");
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| refine_placed(&scans, &team, &placed, &params).unwrap());
    assert_eq!(one.poses, refined.poses);
}

/// `build_map` with the refinement on: every scan placed, the poses as accurate as the
/// mapper's (a voxel and a degree), the graph in the build with one node per placed scan,
/// and written as g2o it reads back with the same nodes and edge kinds.
#[test]
fn build_map_with_the_graph_refinement_exports_its_graph() {
    let robot = lab(4);
    let scans = robot.scan_inputs();
    let params = MapParams {
        register_band: Some((0.1, 2.8)),
        graph: Some(GraphRefineParams::default()),
        ..Default::default()
    };
    let m = build_map(&scans, &params, |_, _| {}).unwrap();
    assert_eq!(m.placed.len(), 4, "{:?}", m.rejected);
    for p in &m.placed {
        let truth = robot.truth[0].inverse() * robot.truth[p.index];
        let e = (p.pose.translation() - truth.translation()).norm();
        let r = p.pose.rotation().angle_to(&truth.rotation()).to_degrees();
        assert!(e < 0.1 && r < 1.0, "{}: {e:.3} m, {r:.2} deg", p.name);
    }
    let g = m.graph.as_ref().expect("asked for");
    assert_eq!(g.graph.nodes().len(), 4);
    let counts = g.graph.edge_counts();
    assert_eq!(counts.get(&EdgeKind::Odometry), Some(&3));
    assert!(
        counts.get(&EdgeKind::Registration).is_some_and(|&n| n >= 3),
        "{counts:?}"
    );
    let mut bytes = Vec::new();
    write_g2o_to(&mut bytes, &g.graph).unwrap();
    let back = parse_g2o(&bytes[..]).unwrap();
    assert_eq!(back.nodes().len(), 4);
    assert_eq!(back.edges().len(), g.graph.edges().len());
}
