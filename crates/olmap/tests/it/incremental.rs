//! The incremental mapper (issue 23 item 1, 3D): scans placed one at a time as they
//! arrive, waiting scans placed once a link or the map reaches them, the pose graph run on
//! the live map; and the live team map built record by record. The batch mapper's test on
//! the corridor ring sits here too, beside the incremental ones on the same world.

use olmap::geometry::PoseError;
use olmap::mapping::posegraph::GraphRefineParams;
use olmap::mapping::{
    build_map, evaluate, IncrementalMapper, MapMode, MapParams, Placement, ScanInput, ScanLink,
    ScanOutcome,
};
use olmap::sim::{OdometryNoise, SimDataset, SimRobot};
use olmap::team::{map_team, LiveTeam, TeamParams};

fn lab(seed: u64, robots: usize, stops: usize, odometry: OdometryNoise) -> SimDataset {
    crate::sim_lab(seed, robots, stops, odometry)
}

/// One robot driving `stops` stops round the corridor ring of `seed`.
fn ring(seed: u64, stops: usize, odometry: OdometryNoise) -> SimDataset {
    olmap::sim::simulate(
        &olmap::sim::SimConfig {
            world: olmap::sim::WorldKind::CorridorRing,
            seed,
            robots: 1,
            stops,
            odometry,
            ..Default::default()
        },
        |_, _| {},
    )
    .unwrap()
}

/// Every scan `build` placed is within `metres` of `robot`'s truth (in its first scan's
/// frame).
fn assert_placed_within(build: &olmap::mapping::MapBuild, robot: &SimRobot, metres: f64) {
    for p in &build.placed {
        let truth = robot.truth[0].inverse() * robot.truth[p.index];
        let e = PoseError::between(&p.pose, &truth);
        assert!(
            e.translation_m <= metres,
            "{} is {:.3} m off",
            p.name,
            e.translation_m
        );
    }
}

/// An incremental mapper with the team mapper's parameters, robots joining only through
/// sightings.
fn team_mapper() -> IncrementalMapper {
    let mut settings = olmap::mapping::TeamLinks::none(0);
    settings.hold_unlinked = true;
    IncrementalMapper::with_team(TeamParams::default().map, settings).unwrap()
}

/// Robot `r`'s scan `k` of `data`, named as the team mapper names it, with its odometry.
fn scan_input(data: &SimDataset, r: usize, k: usize) -> ScanInput {
    ScanInput {
        name: format!("robot{r}/scan{k:03}"),
        cloud: data.robots[r].scans[k].clone(),
        odometry: Some(data.robots[r].odometry[k]),
    }
}

/// One robot in the lab with the thesis' degraded odometry (0.5 m / 10° per move), its
/// scans given one at a time: each is placed when it arrives, within a map voxel (0.1 m)
/// and 1° of the truth, as the batch mapper places the same scans. The pose graph then
/// keeps them there, and a scan given after it is placed against the rebuilt map.
#[test]
fn one_robot_scan_by_scan_is_placed_on_arrival_and_stays_right_after_the_graph() {
    let data = lab(3, 1, 6, OdometryNoise::degraded());
    let robot = &data.robots[0];
    let scans = robot.scan_inputs();
    let truth = |i: usize| robot.truth[0].inverse() * robot.truth[i];
    let mut mapper = IncrementalMapper::new(MapParams::default()).unwrap();
    for scan in scans.iter().take(5).cloned() {
        let name = scan.name.clone();
        match mapper.add_scan(scan).unwrap() {
            ScanOutcome::Placed(p) => {
                let e = PoseError::between(&p.pose, &truth(p.index));
                assert!(
                    e.translation_m <= 0.1 && e.rotation_deg <= 1.0,
                    "{name} placed {:.3} m / {:.2} deg off",
                    e.translation_m,
                    e.rotation_deg
                );
            }
            ScanOutcome::Waiting(w) => panic!("{name} not placed on arrival: {:?}", w.reasons),
        }
    }
    assert_eq!(mapper.placements().len(), 5);
    assert!(mapper.waiting().is_empty());
    // The batch mapper on the same five scans places them too (same registrations).
    let batch = build_map(&scans[..5], &MapParams::default(), |_, _| {}).unwrap();
    assert_eq!(batch.placed.len(), 5);
    // `build_map` in incremental mode is this mapper, run offline: the same poses.
    let incremental = MapParams {
        mode: MapMode::Incremental,
        ..Default::default()
    };
    let offline = build_map(&scans[..5], &incremental, |_, _| {}).unwrap();
    let poses = |placed: &[olmap::mapping::PlacedScan]| {
        placed.iter().map(|p| (p.index, p.pose)).collect::<Vec<_>>()
    };
    assert_eq!(poses(&offline.placed), poses(mapper.placements()));
    assert_eq!(offline.scan_maps.len(), 5);
    // Its frame is the first scan given: naming another is refused, not reordered.
    let other_first = MapParams {
        first: 2,
        ..incremental
    };
    let e = build_map(&scans[..5], &other_first, |_, _| {}).unwrap_err();
    assert!(e.to_string().contains("first in the input"), "{e}");

    let refined = mapper.optimise(&GraphRefineParams::default()).unwrap();
    assert_eq!(refined.poses.len(), 5);
    for p in mapper.placements() {
        let e = PoseError::between(&p.pose, &truth(p.index));
        assert!(
            e.translation_m <= 0.1 && e.rotation_deg <= 1.0,
            "{} after the graph: {:.3} m / {:.2} deg off",
            p.name,
            e.translation_m,
            e.rotation_deg
        );
    }
    let last = scans[5].clone();
    let ScanOutcome::Placed(p) = mapper.add_scan(last).unwrap() else {
        panic!("the scan given after the graph was not placed");
    };
    let e = PoseError::between(&p.pose, &truth(5));
    assert!(e.translation_m <= 0.1 && e.rotation_deg <= 1.0, "{e:?}");
    let map = mapper.map().unwrap();
    assert!(!map.is_empty());
    let build = mapper.into_build().unwrap();
    assert_eq!(build.placed.len(), 6);
    assert_eq!(build.scan_maps.len(), 6);
}

/// The thesis' degraded odometry (0.35 m per axis and 10° per move) puts a robot's next
/// scan outside the inner half of the first ±0.5 m window most of the time, where a match
/// is not trusted until a wider window finds it again. Once a few scans are placed, the
/// incremental mapper starts each search at the window its robot's recent odometry errors
/// call for: the same scans are placed at the same accuracy with fewer registrations than
/// the sequential mapper (the same order, every window from the first).
#[test]
fn the_incremental_mapper_starts_at_the_window_its_robots_odometry_errors_call_for() {
    let data = lab(1, 1, 10, OdometryNoise::degraded());
    let robot = &data.robots[0];
    let scans = robot.scan_inputs();
    let run = |mode: MapMode| {
        let params = MapParams {
            mode,
            ..Default::default()
        };
        build_map(&scans, &params, |_, _| {}).unwrap()
    };
    let incremental = run(MapMode::Incremental);
    let sequential = run(MapMode::Sequential);
    for build in [&incremental, &sequential] {
        assert_eq!(build.placed.len(), scans.len(), "{:?}", build.rejected);
        assert_placed_within(build, robot, 0.1);
    }
    assert!(
        incremental.registrations < sequential.registrations,
        "incremental {} registrations, sequential {}",
        incremental.registrations,
        sequential.registrations
    );
}

/// Records given out of capture order (a robot's second scan before its first, the other
/// robot's scans in between) are all placed, by arrival or by the retries of waiting
/// scans, within a map voxel of the truth; a record given twice is refused.
#[test]
fn records_given_out_of_order_are_all_placed() {
    let data = lab(2, 2, 2, OdometryNoise::degraded());
    let store = data.to_store().unwrap();
    let truth = data.truth_list(&store);
    let mut team = LiveTeam::new(TeamParams::default()).unwrap();
    for (robot, seq) in [(0u32, 0u32), (1, 1), (0, 1), (1, 0)] {
        let scan = store.get(robot, seq).unwrap();
        team.add(scan, &store.robot_name(robot)).unwrap();
    }
    let mut rounds = 0;
    while team.has_due() && rounds < 10 {
        team.retry_waiting(1).unwrap();
        rounds += 1;
    }
    assert_eq!(
        team.placements().len(),
        4,
        "placed {:?}, waiting {:?}",
        team.poses(),
        team.mapper().waiting()
    );
    let e = evaluate(&team.poses(), &truth).unwrap();
    assert!(e.summary.translation_m[2] <= 0.1, "{:?}", e.summary);
    let again = store.get(1, 0).unwrap();
    assert!(team.add(again, "robot1").is_err());
}

/// Scans of a second robot given before anything ties that robot to the map wait with the
/// reason, and are not searched (a global match of a lone robot can be a mirror image);
/// the robot joins once a link from a placed scan reaches one of its scans.
#[test]
fn an_unlinked_robot_waits_for_a_link() {
    let data = lab(2, 2, 2, OdometryNoise::degraded());
    let mut mapper = team_mapper();
    let input = |r: usize, k: usize| scan_input(&data, r, k);
    assert!(matches!(
        mapper
            .add_linked_scan(input(0, 0), 0, 0, Vec::new())
            .unwrap(),
        ScanOutcome::Placed(_)
    ));
    let ScanOutcome::Waiting(w) = mapper
        .add_linked_scan(input(1, 0), 1, 0, Vec::new())
        .unwrap()
    else {
        panic!("an unlinked robot's scan was placed");
    };
    assert!(
        w.reasons.iter().any(|r| r.contains("no sighting ties")),
        "{:?}",
        w.reasons
    );
    assert_eq!(mapper.registrations(), 0, "an unlinked scan was searched");
    assert!(!mapper.has_due());
    // A link to a scan that was never given is an input error.
    let bad = ScanLink::Mutual {
        other: 7,
        relative: olmap::geometry::Pose::identity(),
    };
    assert!(mapper
        .add_linked_scan(input(0, 1), 0, 1, vec![bad])
        .is_err());
    // Robot 0's second scan arrives with a two-way sighting of robot 1's first scan (its
    // true relative pose `T_other_this`): robot 1's scan is then due and placed.
    let truth = |r: usize, k: usize| data.robots[0].truth[0].inverse() * data.robots[r].truth[k];
    let link = ScanLink::Mutual {
        other: 1,
        relative: truth(1, 0).inverse() * truth(0, 1),
    };
    assert!(matches!(
        mapper
            .add_linked_scan(input(0, 1), 0, 1, vec![link])
            .unwrap(),
        ScanOutcome::Placed(_)
    ));
    assert!(mapper.has_due());
    let placed = mapper.retry_waiting(4).unwrap();
    assert_eq!(placed.len(), 1, "{:?}", mapper.waiting());
    let e = PoseError::between(&placed[0].pose, &truth(1, 0));
    assert!(e.translation_m <= 0.1 && e.rotation_deg <= 1.0, "{e:?}");
}

/// Thesis (6.4): a two-way sighting gives a scan's whole pose relative to the other
/// robot's. When the map cannot confirm it (here robot 1's second scan overlaps robot 0's
/// first by 9 %, under the 10 % the verdict needs) the scan is placed at the sighting's
/// pose, as `Placement::MutualSighting`, unless the map contradicts it there: the same
/// sighting turned by 90° or 180° puts the scan's surfaces into space the map saw free,
/// and the scan waits.
#[test]
fn a_two_way_sighting_places_a_scan_the_map_cannot_confirm_unless_the_map_contradicts_it() {
    let data = lab(2, 2, 2, OdometryNoise::degraded());
    let truth = |r: usize, k: usize| data.robots[0].truth[0].inverse() * data.robots[r].truth[k];
    let turn =
        |deg: f64| olmap::geometry::Pose::from_xyz_ypr(0.0, 0.0, 0.0, deg.to_radians(), 0.0, 0.0);
    for (turned, right) in [(0.0, true), (90.0, false), (180.0, false)] {
        let mut mapper = team_mapper();
        mapper
            .add_linked_scan(scan_input(&data, 0, 0), 0, 0, Vec::new())
            .unwrap();
        // `T_other_this`, robot 0's first scan being the map frame.
        let link = ScanLink::Mutual {
            other: 0,
            relative: truth(1, 1) * turn(turned),
        };
        let outcome = mapper
            .add_linked_scan(scan_input(&data, 1, 1), 1, 1, vec![link])
            .unwrap();
        match (outcome, right) {
            (ScanOutcome::Placed(p), true) => {
                assert_eq!(p.via, Placement::MutualSighting { other: 0 }, "{p:?}");
                let e = PoseError::between(&p.pose, &truth(1, 1));
                assert!(e.translation_m <= 1e-6 && e.rotation_deg <= 1e-6, "{e:?}");
            }
            (ScanOutcome::Waiting(w), false) => assert!(!w.reasons.is_empty()),
            (outcome, _) => panic!("sighting turned by {turned}°: {outcome:?}"),
        }
    }
}

/// The live team map of a four-robot lab (4 robots x 3 stops, degraded odometry),
/// records given stop by stop as a network delivers them: every scan placed, as accurate
/// as the batch team map of the same records (mean within a map voxel of it, no scan off
/// by more than 0.3 m: the team criterion).
#[test]
fn a_live_team_map_given_stop_by_stop_is_as_accurate_as_the_batch_map() {
    let data = lab(1, 4, 3, OdometryNoise::degraded());
    let store = data.to_store().unwrap();
    let truth = data.truth_list(&store);
    let mut records: Vec<_> = store.iter().collect();
    records.sort_by_key(|s| (s.seq, s.robot));
    let mut team = LiveTeam::new(TeamParams::default()).unwrap();
    for scan in records {
        team.add(scan, &store.robot_name(scan.robot)).unwrap();
        let mut rounds = 0;
        while team.has_due() && rounds < 100 {
            team.retry_waiting(1).unwrap();
            rounds += 1;
        }
        assert!(!team.has_due(), "waiting scans still due after 100 retries");
    }
    let batch = map_team(&store, &TeamParams::default(), |_, _| {}).unwrap();
    let live = evaluate(&team.poses(), &truth).unwrap().summary;
    let offline = evaluate(&batch.poses(), &truth).unwrap().summary;
    assert_eq!(team.placements().len(), batch.build.placed.len());
    assert_eq!(team.placements().len(), 12, "{:?}", team.mapper().waiting());
    assert!(live.translation_m[2] <= 0.3, "live {live:?}");
    assert!(
        live.translation_m[0] <= offline.translation_m[0] + 0.1,
        "live {live:?} vs batch {offline:?}"
    );
}

/// A scan whose only link leads to another waiting scan waits too; once that scan is
/// placed (here by a link that arrives later), the first is due again and placed, without
/// waiting for the map to grow.
#[test]
fn a_scan_linked_to_a_waiting_scan_is_retried_when_that_scan_is_placed() {
    let data = lab(2, 3, 2, OdometryNoise::degraded());
    let mut mapper = team_mapper();
    let input = |r: usize, k: usize| scan_input(&data, r, k);
    let truth = |r: usize, k: usize| data.robots[0].truth[0].inverse() * data.robots[r].truth[k];
    // `T_other_this` of a two-way sighting between scan (r, k) (other) and this one.
    let mutual =
        |other: usize, (r, k): (usize, usize), (tr, tk): (usize, usize)| ScanLink::Mutual {
            other,
            relative: truth(r, k).inverse() * truth(tr, tk),
        };
    // 0: robot0/scan000 frames the map. 1: robot2/scan000, nothing ties it: waits.
    mapper
        .add_linked_scan(input(0, 0), 0, 0, Vec::new())
        .unwrap();
    let first = mapper
        .add_linked_scan(input(2, 0), 2, 0, Vec::new())
        .unwrap();
    assert!(matches!(first, ScanOutcome::Waiting(_)));
    // 2: robot1/scan000, tied only to robot2/scan000 (waiting): waits.
    let linked = vec![mutual(1, (2, 0), (1, 0))];
    let second = mapper.add_linked_scan(input(1, 0), 1, 0, linked).unwrap();
    assert!(matches!(second, ScanOutcome::Waiting(_)), "{second:?}");
    // 3: robot0/scan001 saw robot2/scan000: robot2's scan is due and placed by a retry;
    // then robot1's is due (its link now leads to a placed scan) and placed too.
    let link = vec![mutual(1, (2, 0), (0, 1))];
    mapper.add_linked_scan(input(0, 1), 0, 1, link).unwrap();
    let mut placed = Vec::new();
    for _ in 0..10 {
        if !mapper.has_due() {
            break;
        }
        placed.extend(mapper.retry_waiting(1).unwrap());
    }
    let names: Vec<&str> = placed.iter().map(|p| p.name.as_str()).collect();
    assert!(
        names.contains(&"robot2/scan000") && names.contains(&"robot1/scan000"),
        "placed {names:?}, waiting {:?}",
        mapper.waiting()
    );
    for p in &placed {
        let r: usize = p.name[5..6].parse().unwrap();
        let e = PoseError::between(&p.pose, &truth(r, 0));
        assert!(
            e.translation_m <= 0.1 && e.rotation_deg <= 1.0,
            "{}: {e:?}",
            p.name
        );
    }
}

/// A first scan that cannot frame a map (a point past the map's key range) is refused and
/// not kept: the next scan frames the map as scan 0.
#[test]
fn a_refused_first_scan_leaves_nothing_behind() {
    let data = lab(2, 1, 1, OdometryNoise::none());
    let mut mapper = IncrementalMapper::new(MapParams::default()).unwrap();
    let mut far = data.robots[0].scans[0].clone();
    far.push_with(nalgebra::Point3::new(1.0e12f32, 0.0, 1.0), None, None, None);
    let bad = ScanInput {
        name: "far".into(),
        cloud: far,
        odometry: None,
    };
    let refused = mapper.add_scan(bad);
    assert!(refused.is_err(), "{refused:?}");
    assert!(mapper.scans().is_empty());
    let good = ScanInput {
        name: "good".into(),
        cloud: data.robots[0].scans[0].clone(),
        odometry: None,
    };
    let ScanOutcome::Placed(p) = mapper.add_scan(good).unwrap() else {
        panic!("the first good scan did not frame the map");
    };
    assert_eq!((p.index, mapper.scans().len()), (0, 1));
}

/// Issue 23's simulated loop: one robot drives 52 stops (1-2 m apart) round the 72 m
/// corridor ring with drifting odometry (5 % scale, 2°/m heading drift: odometry alone
/// ends metres off), its scans given in order to the incremental mapper with the pose
/// graph. Every scan is placed and none is more than 0.10 m off the truth (the issue's
/// bound), although 5 % wrong loop closures (2-5 m off, as confident as a typical real
/// one) are injected into the graph: the kernel down-weights each, and the report names it.
#[test]
fn a_72_m_corridor_loop_with_drifting_odometry_closes_within_a_decimetre() {
    let stops = 52;
    let data = ring(1, stops, OdometryNoise::drifting());
    let robot = &data.robots[0];
    let truth = |i: usize| robot.truth[0].inverse() * robot.truth[i];
    // The loop is real: the last stops see the first again, and odometry alone is lost.
    let back = (robot.truth[stops - 1].translation() - robot.truth[0].translation()).norm();
    assert!(back <= 10.0, "the robot ends {back:.1} m from its start");
    let odometry_error = (0..stops)
        .map(|i| PoseError::between(&robot.odometry[i], &truth(i)).translation_m)
        .fold(0.0, f64::max);
    assert!(
        odometry_error > 2.0,
        "odometry alone is {odometry_error:.2} m off at most"
    );
    let params = MapParams {
        mode: MapMode::Incremental,
        graph: Some(GraphRefineParams {
            inject_wrong_closures: 0.05,
            inject_seed: 1,
            ..Default::default()
        }),
        ..Default::default()
    };
    let build = build_map(&robot.scan_inputs(), &params, |_, _| {}).unwrap();
    assert_eq!(build.placed.len(), stops, "waiting: {:?}", build.rejected);
    assert_placed_within(&build, robot, 0.10);
    let report = &build.graph.as_ref().expect("the graph ran").report;
    assert!(
        report.edges.get("loop_closure").copied().unwrap_or(0) > report.injected.len(),
        "real loop closures besides the injected: {:?}",
        report.edges
    );
    assert!(!report.injected.is_empty());
    for c in &report.injected {
        assert!(c.down_weighted, "injected {} -> {} kept", c.from, c.to);
        assert!(
            report
                .down_weighted
                .iter()
                .any(|d| d.from == c.from && d.to == c.to),
            "{} -> {} not named among the down-weighted edges",
            c.from,
            c.to
        );
    }
}

/// Issue 23's loop with the thesis' degraded odometry (0.35 m and 10° per move, 5 % scale,
/// 2°/m drift), seed 3: at scan 23, half way round, ICP reached the truth from the odometry
/// window's search pose 0.38 m along the north corridor (the things along its walls repeat,
/// and the lattice's overlap preferred a look-alike by a few per cent), agreeing at 0.999.
/// The verdict refused that refinement for moving more than 3 cells, and the chain stopped
/// there (23 of 52 placed: the later scans' odometry reached back too far). A refined pose the
/// search did not propose is now trusted at the upright look's closer agreement (0.97),
/// and the whole loop is placed within the decimetre.
#[test]
fn the_72_m_loop_with_the_thesis_degraded_odometry_is_placed_whole_on_seed_3() {
    let stops = 52;
    let data = ring(3, stops, OdometryNoise::degraded());
    let robot = &data.robots[0];
    let params = MapParams {
        mode: MapMode::Incremental,
        graph: Some(GraphRefineParams::default()),
        ..Default::default()
    };
    let build = build_map(&robot.scan_inputs(), &params, |_, _| {}).unwrap();
    assert_eq!(build.placed.len(), stops, "waiting: {:?}", build.rejected);
    assert_placed_within(&build, robot, 0.10);
}

/// Never confidently wrong in a corridor: with the thesis' degraded odometry (0.35 m and
/// 10° per move) round the corridor ring, seed 2, the mapper loses the chain at scan 23 (a
/// stretch where a slide of 0.4 m along the corridor fits nearly as well). Without a global
/// search to compare with, a later scan predicted from scan 22 across a 20-scan gap once
/// searched a window ±8 m wide and was trusted 8.7 m off at a look-alike stretch, and every
/// later scan followed it. Now such a scan waits, saying why, and no placed scan is more
/// than 0.3 m off (the bound for a placed scan).
#[test]
fn a_scan_whose_odometry_reaches_back_too_far_waits_instead_of_matching_a_look_alike() {
    let stops = 46;
    let data = ring(2, stops, OdometryNoise::degraded());
    let robot = &data.robots[0];
    let params = MapParams {
        mode: MapMode::Incremental,
        ..Default::default()
    };
    let build = build_map(&robot.scan_inputs(), &params, |_, _| {}).unwrap();
    assert!(build.placed.len() >= 10, "{} placed", build.placed.len());
    assert_placed_within(&build, robot, 0.3);
    assert!(
        build
            .rejected
            .iter()
            .any(|r| r.reasons.iter().any(|why| why.contains("reaches back"))),
        "{:?}",
        build.rejected
    );
}

/// The batch mapper on the corridor ring with the thesis' degraded odometry (seed 2, the
/// first 26 of 46 stops): before [`olmap::mapping::MapMode::Batch`] let the map grow along
/// the robot's path first, its second round searched the middle of the north corridor in a
/// window ±25 % of a 35 m odometry path wide and trusted a look-alike stretch of the south
/// corridor, and 9 scans followed it, all 13.5 m off. Now a scan predicted over a path of
/// more than 8 m waits while a scan predicted over a shorter one is left; the chain from
/// both ends stops where the corridor is ambiguous, and nothing is placed wrong.
#[test]
fn the_batch_mapper_grows_along_the_path_before_searching_a_wide_corridor_window() {
    let data = ring(2, 46, OdometryNoise::degraded());
    let robot = &data.robots[0];
    let params = MapParams {
        mode: MapMode::Batch,
        ..Default::default()
    };
    let scans = &robot.scan_inputs()[..26];
    let build = build_map(scans, &params, |_, _| {}).unwrap();
    // The bound for a trusted pose (0.3 m); scans 0-22 chain from the start.
    assert_placed_within(&build, robot, 0.3);
    assert!(build.placed.len() >= 20, "{} placed", build.placed.len());
}

/// A team mapper holding robot 0's first `scans` scans, every one placed.
fn robot0_mapped(data: &SimDataset, scans: usize) -> IncrementalMapper {
    let mut mapper = team_mapper();
    for k in 0..scans {
        mapper
            .add_linked_scan(scan_input(data, 0, k), 0, k as u64, Vec::new())
            .unwrap();
    }
    assert_eq!(
        mapper.placements().len(),
        scans,
        "robot 0's scans map alone"
    );
    mapper
}

/// A scan given with a sighting moved `shift` metres from the truth: with the true sighting
/// (`shift` 0) placed within 5 cm of `truth`; with a moved one either placed as well (the
/// map corrected it) or waiting because the wider look found a better pose.
fn assert_right_or_vetoed(outcome: ScanOutcome, truth: &olmap::geometry::Pose, shift: f64) {
    match outcome {
        ScanOutcome::Placed(p) => {
            let e = PoseError::between(&p.pose, truth);
            assert!(
                e.translation_m <= 0.05,
                "sighting moved {shift} m: placed {:.3} m off via {:?}",
                e.translation_m,
                p.via
            );
        }
        ScanOutcome::Waiting(w) => {
            assert!(
                shift > 0.0,
                "the true sighting left the scan waiting: {w:?}"
            );
            assert!(
                w.reasons.iter().any(|r| r.contains("4 times as wide")),
                "{:?}",
                w.reasons
            );
        }
    }
}

/// Issue 23's finding, a confident wrong placement (issue 22): a two-way sighting wrong by
/// 1.0 m (lab seed 1) placed robot 1's scan 1.0 m off as a *trusted* match: the sighting's
/// ±0.3 m window held a look-alike near the wrong pose (overlap 13 %, agreement 0.89) and
/// not the truth. A search four times as wide finds a pose that fits the map clearly better,
/// and the scan waits. The same sighting unshifted still places the scan (within 5 cm).
#[test]
fn a_two_way_sighting_a_metre_off_is_not_trusted_on_a_look_alike_in_its_window() {
    let data = lab(1, 2, 2, OdometryNoise::degraded());
    let truth = |r: usize, k: usize| data.robots[0].truth[0].inverse() * data.robots[r].truth[k];
    for shift in [0.0, 1.0] {
        let mut mapper = team_mapper();
        mapper
            .add_linked_scan(scan_input(&data, 0, 0), 0, 0, Vec::new())
            .unwrap();
        let moved = olmap::geometry::Pose::from_xyz_ypr(0.0, shift, 0.0, 0.0, 0.0, 0.0);
        let link = ScanLink::Mutual {
            other: 0,
            relative: moved * truth(1, 1),
        };
        let outcome = mapper
            .add_linked_scan(scan_input(&data, 1, 1), 1, 1, vec![link])
            .unwrap();
        assert_right_or_vetoed(outcome, &truth(1, 1), shift);
    }
}

/// The same for a one-way sighting (issue 22): robot 1 saw robot 0's beacon (6.3), and the
/// beacon it reports is 0.5 m off (lab seed 2, robot 0's four scans mapped first). The
/// locus through the wrong beacon held a look-alike 0.62 m from the truth, trusted. A
/// search 4 times as wide as a two-way window around that match finds the truth fitting
/// the map better, and the scan waits; the true sighting still places it (within 5 cm).
#[test]
fn a_one_way_sighting_half_a_metre_off_is_not_trusted_on_a_look_alike_on_its_locus() {
    let data = lab(2, 2, 4, OdometryNoise::degraded());
    let truth = |r: usize, k: usize| data.robots[0].truth[0].inverse() * data.robots[r].truth[k];
    let mount = olmap::mapping::TeamLinks::none(0).beacon_mount;
    for shift in [0.0, 0.5] {
        let mut mapper = robot0_mapped(&data, 4);
        // Robot 0's beacon (scan 2) as robot 1 saw it from its scan 2, moved `shift` in y.
        let robot0_in_robot1 = truth(1, 2).inverse() * truth(0, 2);
        let link = ScanLink::Saw {
            other: 2,
            observed: robot0_in_robot1.transform_point(&mount)
                + nalgebra::Vector3::new(0.0, shift, 0.0),
        };
        let outcome = mapper
            .add_linked_scan(scan_input(&data, 1, 2), 1, 2, vec![link])
            .unwrap();
        assert_right_or_vetoed(outcome, &truth(1, 2), shift);
    }
}

/// A two-way sighting 1 m off for a later scan of a robot already in the map (lab seed 6:
/// robot 1 joined through a true sighting at its scan 2; its scan 3 comes with a wrong one).
/// The window search there was not trusted, the map did not contradict the sighting's pose,
/// and the sighting alone placed the scan 1.002 m off, trusted (`MutualSighting`), although
/// its odometry window places it right. The sighting alone now places only a robot's
/// joining scan: the later scan goes on to its odometry windows and is placed within 5 cm.
#[test]
fn a_placed_robots_later_scan_is_not_placed_by_a_wrong_two_way_sighting_alone() {
    let data = lab(6, 2, 5, OdometryNoise::degraded());
    let truth = |r: usize, k: usize| data.robots[0].truth[0].inverse() * data.robots[r].truth[k];
    let mut mapper = robot0_mapped(&data, 5);
    let join = ScanLink::Mutual {
        other: 2,
        relative: truth(0, 2).inverse() * truth(1, 2),
    };
    let joined = mapper
        .add_linked_scan(scan_input(&data, 1, 2), 1, 2, vec![join])
        .unwrap();
    assert!(matches!(joined, ScanOutcome::Placed(_)), "{joined:?}");
    let moved = olmap::geometry::Pose::from_xyz_ypr(0.0, 1.0, 0.0, 0.0, 0.0, 0.0);
    let wrong = ScanLink::Mutual {
        other: 3,
        relative: moved * (truth(0, 3).inverse() * truth(1, 3)),
    };
    match mapper
        .add_linked_scan(scan_input(&data, 1, 3), 1, 3, vec![wrong])
        .unwrap()
    {
        ScanOutcome::Placed(p) => {
            let e = PoseError::between(&p.pose, &truth(1, 3));
            assert!(
                e.translation_m <= 0.05,
                "placed {:.3} m off via {:?}",
                e.translation_m,
                p.via
            );
        }
        ScanOutcome::Waiting(w) => panic!("its odometry window should place it: {w:?}"),
    }
}
