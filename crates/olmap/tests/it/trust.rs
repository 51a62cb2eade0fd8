//! Trusted means right (issue 22): the verdict on the simulated trust suite and on the
//! audit's failure cases. Wrong = outside 0.3 m / 3° of the truth
//! ([`olmap::sim::RIGHT_TRANSLATION`], [`olmap::sim::RIGHT_ROTATION`]) in simulation, and
//! any trusted answer where no rigid transform exists.

use olmap::align::{self, Dof, RegisterParams, SearchParams};
use olmap::bench::{run_trust, Outcome, TrustOptions};
use olmap::cloud::PointCloud;

use crate::data;

/// A short pass of the trust suite (2 pairs of each of the 14 kinds, a seed the thresholds
/// were not chosen on): no trusted answer is wrong. (That the verdict is not simply "never"
/// is checked on real data: `a_scan_against_itself_is_trusted_at_the_identity` and the
/// real pairs of `align.rs`.) Until the cleaner-rival test (`Verification::cleaner_rival`)
/// desk-rows-01 was trusted 6.05 m off here. The whole suite at this seed (17 pairs of
/// each kind) still trusts 3 of 238 pairs wrongly (a scan of one place laid over another,
/// one of two rooms laid over its twin, a low-overlap pair turned half round): this pass
/// guards what is fixed, it does not say the verdict is done (issue 22).
#[test]
fn trust_suite_short_pass_has_no_trusted_wrong_answer() {
    let report = run_trust(
        &TrustOptions {
            seed: 11,
            per_scene: 2,
            register: RegisterParams::default(),
        },
        |_, _| {},
    )
    .unwrap();
    assert_eq!(report.rows.len(), 28);
    for r in &report.rows {
        eprintln!(
            "{} {:?} err {:?} m overlap {:.2} z {:.0} rival {:.2} agreement {:?} {:?}",
            r.name,
            r.outcome,
            r.error_m,
            r.overlap_fraction,
            r.significance,
            r.runner_up_ratio,
            r.agreement,
            r.doubts
        );
    }
    let wrong: Vec<&str> = report
        .rows
        .iter()
        .filter(|r| r.outcome == Outcome::TrustedWrong)
        .map(|r| r.name.as_str())
        .collect();
    assert!(wrong.is_empty(), "trusted and wrong: {wrong:?}");
    // The search and the verification find the truth of some pairs with one right answer
    // (whether the verdict dares to trust them is what the full suite reports).
    assert!(
        report
            .rows
            .iter()
            .any(|r| r.answer == "unique" && r.right == Some(true)),
        "no pair with a unique answer was found right"
    );
}

/// The full suite (17 pairs of each kind, 238 pairs; minutes in release): the numbers of
/// the closing note. `cargo test --release -- --ignored trust_suite_full`.
#[test]
#[ignore = "minutes: the whole trust suite"]
fn trust_suite_full_has_no_trusted_wrong_answer() {
    let report = run_trust(
        &TrustOptions {
            seed: 4,
            per_scene: 17,
            register: RegisterParams::default(),
        },
        |_, _| {},
    )
    .unwrap();
    for s in &report.scenes {
        eprintln!(
            "{:15} {:9} pairs {:2} trusted-right {:2} alias {:2} wrong {:2} untrusted {:2} right {:2}",
            s.scene, s.answer, s.pairs, s.trusted_right, s.trusted_alias, s.trusted_wrong,
            s.untrusted, s.right
        );
    }
    assert_eq!(report.trusted_wrong, 0);
}

/// Along a corridor every shift overlaps about as well, so the global search's few best
/// poses can all lie metres from the truth; the verification then slides the scan along
/// the weakly held direction (`olmap::align::verify::weak_axis`) and doubts a winner that a
/// cleaner rival refutes (`Verification::cleaner_rival`). On the trust suite's corridor
/// ring (seed 4, pairs 0-8: two scans 1-6 m apart along one long side) the search alone
/// found 1 of the 9 truths and 2 answers were trusted 3.9 and 5.5 m off. Now no trusted
/// answer is wrong (a trusted pose where the rescanned world looks the same is a
/// look-alike, not an error), and more than half are trusted and right: a corridor ring
/// has junctions and furniture within a scan's reach, so a verdict that finds the truth
/// must be able to say so.
#[test]
fn corridor_ring_pairs_are_found_along_the_corridor_or_doubted() {
    let mut right = 0;
    for k in 0..9 {
        let case = olmap::sim::trust_case(4, olmap::sim::TrustScene::RingCorridor, k).unwrap();
        let r = align::register(&case.source, &case.target, &RegisterParams::default()).unwrap();
        let is_right = case.is_right(&r.pose).unwrap();
        eprintln!(
            "{}: trusted {} right {is_right} {:?}",
            case.name, r.trusted, r.doubts
        );
        if r.trusted && !is_right {
            assert!(
                case.is_alias(&r.pose).unwrap(),
                "{} trusted {:.2} m off: {:?}",
                case.name,
                olmap::sim::pose_error(&r.pose, &case.truth.unwrap()).0,
                r.verification.map(|v| v.hypotheses.len())
            );
        }
        right += usize::from(r.trusted && is_right);
    }
    assert!(right >= 5, "only {right} of 9 trusted and right");
}

/// Two scans 1-3 m apart in a furnished room overlap most where one's dense near floor
/// lies on the other's ("the robot did not move", turned to line a wall up): the search
/// alone lost the truth at a coarse level in these pairs of the trust suite (seed 4:
/// same-place 0 and 6, partial views 0 and 7; found 2.1-2.7 m off and doubted), though
/// the truth fits better than anything it refined. The upright look (the search again
/// with the floors thinned, its best poses verified beside the search's:
/// `olmap::align::verify::Origin::UprightLook`) finds each, trusted. The same look finds
/// look-alikes where two scans barely overlap (low-overlap 2: 8.2 m off, agreement 0.90;
/// a symmetric hall, pair 5: 9.6 m off, 0.95); the stricter agreement it must meet
/// (`TrustThresholds::min_upright_agreement`) doubts them.
#[test]
fn pairs_the_floor_hides_are_found_by_the_upright_look_and_look_alikes_doubted() {
    use olmap::align::verify::Origin;
    use olmap::sim::{trust_case, TrustScene};
    for (scene, k) in [
        (TrustScene::SamePlace, 0),
        (TrustScene::SamePlace, 6),
        (TrustScene::Partial, 0),
        (TrustScene::Partial, 7),
    ] {
        let case = trust_case(4, scene, k).unwrap();
        let r = align::register(&case.source, &case.target, &RegisterParams::default()).unwrap();
        let v = r.verification.as_ref().expect("verified");
        assert!(
            r.trusted && case.is_right(&r.pose).unwrap(),
            "{}: trusted {} error {:.2} m {:?}",
            case.name,
            r.trusted,
            olmap::sim::pose_error(&r.pose, &case.truth.unwrap()).0,
            r.doubts
        );
        assert_eq!(v.winner().origin, Origin::UprightLook, "{}", case.name);
    }
    for (scene, k) in [(TrustScene::LowOverlap, 2), (TrustScene::SymmetricHall, 5)] {
        let case = trust_case(4, scene, k).unwrap();
        let r = align::register(&case.source, &case.target, &RegisterParams::default()).unwrap();
        let right = case.is_right(&r.pose).unwrap();
        assert!(
            !r.trusted || right,
            "{} trusted {:.2} m off",
            case.name,
            olmap::sim::pose_error(&r.pose, &case.truth.unwrap()).0
        );
    }
}

/// A scan of a room's corner (two walls, floor and ceiling) from one simulated world laid
/// over a corner of a room in another (trust suite, seed 1, unrelated pair 6): every test
/// but one passed (overlap 0.49, z 93, distinct rivals refuted, agreement 0.925 against the
/// 0.85 floor, which right real pairs need: 3DTK 002->000 agrees at 0.89), and it was
/// trusted. Each scan leaves structure where the other saw through (a strip from floor to
/// ceiling, a wall 3 m long): 6.1 % of the scan's observed surface and 4.8 % of the
/// target's in patches larger than a thing that moves. Right pairs leave such structure on
/// one side only (a door, glass), so the verdict's two-sided test
/// (`TrustThresholds::max_two_sided_disagreement`) doubts it; the real pairs, which leave
/// 3-11 % on one side and at most 1.4 % on the other, stay trusted (`align.rs`).
#[test]
fn a_room_corner_laid_over_another_world_s_corner_is_not_trusted() {
    use olmap::sim::{trust_case, TrustScene};
    let case = trust_case(1, TrustScene::Unrelated, 6).unwrap();
    assert!(case.truth.is_none(), "an unrelated pair");
    let r = align::register(&case.source, &case.target, &RegisterParams::default()).unwrap();
    let c = r.consistency.expect("refined");
    eprintln!("{:?} {c:?}", r.doubts);
    assert!(!r.trusted, "two unrelated places trusted: {c:?}");
    assert!(
        r.doubts
            .iter()
            .any(|d| d.starts_with("both scans leave structure")),
        "{:?}",
        r.doubts
    );
}

/// `k` people (fronts 0.5 m wide and 1.75 m tall, 1.5-4 m from the sensor, each where the
/// scan saw at least 0.5 m past them) added to a scan as its scanner would see them: what
/// lies behind each person within its width and height is replaced by the person's front.
fn with_people(scan: &PointCloud, k: usize, rng: &mut olmap::sim::SimRng) -> PointCloud {
    use std::f64::consts::PI;
    let o = scan.origin();
    let mut points: Vec<nalgebra::Point3<f32>> = scan.points().to_vec();
    // Range in the plane and the angle off `heading` of each point, and whether it lies
    // in the height band a person hides.
    let polar = |p: &nalgebra::Point3<f32>, heading: f64| {
        let (dx, dy) = (f64::from(p.x) - o.x, f64::from(p.y) - o.y);
        let off = (dy.atan2(dx) - heading + PI).rem_euclid(2.0 * PI) - PI;
        (dx.hypot(dy), off, p.z > 0.02 && p.z < 1.75)
    };
    for _ in 0..k {
        let (mut r, mut heading) = (0.0, 0.0);
        for _ in 0..50 {
            r = rng.range(1.5, 4.0);
            heading = rng.range(-PI, PI);
            let half = (0.25 / r).atan();
            let behind: Vec<f64> = points
                .iter()
                .map(|p| polar(p, heading))
                .filter(|&(_, off, band)| band && off.abs() < half)
                .map(|(d, _, _)| d)
                .collect();
            let open = behind.iter().filter(|&&d| d > r + 0.5).count();
            if behind.len() > 20 && open * 10 > behind.len() * 9 {
                break;
            }
        }
        let half = (0.25 / r).atan();
        for p in &mut points {
            let (d, off, band) = polar(p, heading);
            if band && off.abs() < half && d > r {
                p.x = (o.x + (f64::from(p.x) - o.x) * r / d) as f32;
                p.y = (o.y + (f64::from(p.y) - o.y) * r / d) as f32;
            }
        }
    }
    PointCloud::from_points(points).with_origin(o)
}

/// The two-sided agreement test leaves people alone: two scans of one place, each with 6
/// people standing where the other saw through (drawn anew), are found right and not
/// doubted by it, though both scans leave more than 3 % of their observed surface where
/// the other saw through. Counting every contradicted voxel, such pairs were refused (4 of
/// 6 same-place pairs of the suite with 4 people a scan, checked through the CLI); only
/// patches larger than a thing that moves (`olmap::align::MOVABLE_WIDTH` across,
/// `MOVABLE_HEIGHT` tall) count now. (Rule 3's cleaner-rival test still counts every
/// contradicted voxel: with 6 people it doubts same-place-11 over a rival 4.7 m away.)
#[test]
fn people_who_walked_about_in_both_scans_do_not_make_a_right_pair_untrusted() {
    use olmap::sim::{trust_case, SimRng, TrustScene};
    let mut rng = SimRng::new(7);
    for k in [2, 11] {
        let case = trust_case(1, TrustScene::SamePlace, k).unwrap();
        let source = with_people(&case.source, 6, &mut rng);
        let target = with_people(&case.target, 6, &mut rng);
        let r = align::register(&source, &target, &RegisterParams::default()).unwrap();
        let c = r.consistency.expect("refined");
        eprintln!("{}: {:?} {c:?}", case.name, r.doubts);
        assert!(case.is_right(&r.pose).unwrap(), "{}", case.name);
        let (s, t) = (c.source, c.target.expect("both sides"));
        assert!(
            s.agreement() < 0.97 && t.agreement() < 0.97,
            "{}: the people left too little where the other saw through to test: {c:?}",
            case.name
        );
        assert!(
            !r.doubts.iter().any(|d| d.starts_with("both scans leave")),
            "{}: {:?}",
            case.name,
            r.doubts
        );
    }
}

/// Audit 1: a real 3DTK scan mirrored (y -> -y) against the original has no rigid
/// transform onto it; it was trusted at z 187-233 because many voxels coincide. The
/// agreement test sees the mirrored surfaces hanging in the original's free space.
#[test]
fn audit_mirrored_scan_not_trusted() {
    if data().is_none() {
        return;
    }
    let original = olmap::test_data::threedtk_scan(0, true).expect("the data folder was found");
    let mut mirrored = original.clone();
    for p in mirrored.points_mut() {
        p.y = -p.y;
    }
    let o = original.origin();
    mirrored.set_origin(nalgebra::Point3::new(o.x, -o.y, o.z));
    let params = RegisterParams {
        search: SearchParams {
            dof: Dof::XyzYaw,
            ..Default::default()
        },
        ..Default::default()
    };
    let r = align::register(&mirrored, &original, &params).unwrap();
    eprintln!(
        "mirrored: overlap {:.2} z {:.0} agreement {:?} {:?}",
        r.search.overlap_fraction,
        r.search.significance,
        r.consistency.map(|c| c.agreement()),
        r.doubts
    );
    assert!(!r.trusted, "a mirror image has no rigid transform");
}

/// The same scan against itself is trusted at the identity: the agreement and uniqueness
/// tests do not refuse a perfect match (the test above could pass by refusing everything).
#[test]
fn a_scan_against_itself_is_trusted_at_the_identity() {
    if data().is_none() {
        return;
    }
    let scan: PointCloud = olmap::test_data::threedtk_scan(0, true).expect("the data folder");
    let params = RegisterParams {
        search: SearchParams {
            dof: Dof::XyzYaw,
            ..Default::default()
        },
        ..Default::default()
    };
    let r = align::register(&scan, &scan, &params).unwrap();
    assert!(r.trusted, "{:?}", r.doubts);
    assert!(r.pose.translation().norm() < 0.05, "{:?}", r.pose);
    let c = r.consistency.expect("refined");
    assert!(c.agreement() > 0.95, "{c:?}");
}

/// Global localisation among look-alikes (issue 22): the warehouse (200 x 200 m, identical
/// rack rows) mapped from 144 lidar scans at their true poses along its front cross-aisle
/// and first aisle, and a held-out scan of the cross-aisle localised with no initial
/// guess. Along the cross-aisle every aisle mouth looks like the next: the search finds
/// 40-60 distinct poses scoring within 80 % of its best. Before the screening of the
/// search's other near-best poses and the doubt about more of them than it lists
/// (`olmap::align::verify::unverified_look_alikes`), it was trusted 54 m off, and of the
/// next six held-out scans three more 17-63 m off (checked with the same scans and map
/// through the CLI). Trusting it now must mean being right. (Minutes without optimisation:
/// one query only.)
#[test]
fn scans_among_the_warehouse_s_look_alike_aisles_are_not_trusted_wrong() {
    use olmap::occupancy::OccupancyList;
    use olmap::sim::{
        pose_error, simulate, OdometryNoise, Scanner3d, SimConfig, SpinningLidar, WorldKind,
        RIGHT_ROTATION, RIGHT_TRANSLATION,
    };
    let mut lidar = SpinningLidar::default();
    lidar.noise.sigma = 0.02;
    let mut config = SimConfig {
        world: WorldKind::Warehouse,
        seed: 1,
        robots: 1,
        stops: 160,
        scanner: Scanner3d::Lidar(lidar),
        odometry: OdometryNoise::typical(),
        ..Default::default()
    };
    config.motion.step = (1.5, 2.5);
    let data = simulate(&config, |_, _| {}).unwrap();
    let robot = &data.robots[0];
    let mut map = OccupancyList::new(0.05).unwrap();
    for (i, (scan, pose)) in robot.scans.iter().zip(&robot.truth).enumerate() {
        if i % 10 != 5 {
            map.add_points(scan, pose, 1);
        }
    }
    let q = 5;
    // At the map's own 0.05 m (where it was trusted 54 m off) and at the default search
    // resolution, 0.1 m, which reads the map at its next level.
    for resolution in [0.05, 0.1] {
        let params = RegisterParams {
            search: SearchParams {
                resolution,
                ..Default::default()
            },
            ..Default::default()
        };
        let r = align::localize(&robot.scans[q], &map, &params).unwrap();
        let (dt, dr) = pose_error(&r.pose, &robot.truth[q]);
        eprintln!(
            "scan {q} at {resolution} m: {dt:.2} m / {:.2} deg off, trusted {}, ambiguity {}, {:?}",
            dr.to_degrees(),
            r.trusted,
            r.search.ambiguity,
            r.doubts
        );
        assert!(
            !r.trusted || (dt <= RIGHT_TRANSLATION && dr <= RIGHT_ROTATION),
            "scan {q} at {resolution} m trusted {dt:.2} m / {:.1} deg off",
            dr.to_degrees()
        );
    }
}
