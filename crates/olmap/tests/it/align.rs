//! Registration on real data: global search from the identity with no prior, then ICP,
//! against the reference poses of the data README (tolerances from its §1.7 and §3).

use olmap::align::icp::IcpParams;
use olmap::align::{self, Dof, RegisterParams, Registration, SearchMode, SearchParams};
use olmap::cloud::PointCloud;
use olmap::geometry::{Pose, PoseError};
use olmap::io;

use crate::data;

fn tdk(i: usize) -> PointCloud {
    olmap::test_data::threedtk_scan(i, true).expect("the data folder was found")
}

fn car(d: &std::path::Path, name: &str) -> PointCloud {
    io::read_cloud(d.join("libpointmatcher_car").join(name))
        .unwrap()
        .cloud
}

fn params(dof: Dof) -> RegisterParams {
    params_in(dof, SearchMode::default())
}

fn params_in(dof: Dof, search: SearchMode) -> RegisterParams {
    RegisterParams {
        search: SearchParams {
            dof,
            search,
            ..Default::default()
        },
        refine: Some(IcpParams::default()),
        trust: Default::default(),
    }
}

fn report(name: &str, r: &Registration, e: &PoseError) {
    let f = r.refinement.as_ref();
    eprintln!(
        "{name}: search {:.3} s ({} poses, overlap {:.2}, z {:.0}, ambiguity {}), refine {:.3} s (inliers {:.2}, rms {:.3}), trusted {} {:?} | dx {:.3} dy {:.3} dz {:.3} m, yaw {:.2} pitch {:.2} roll {:.2} deg",
        r.search.seconds, r.search.evaluated, r.search.overlap_fraction, r.search.significance, r.search.ambiguity,
        f.map_or(0.0, |f| f.seconds), f.map_or(0.0, |f| f.inlier_fraction), f.map_or(0.0, |f| f.inlier_rms),
        r.trusted, r.doubts, e.dx_m, e.dy_m, e.dz_m, e.yaw_deg, e.pitch_deg, e.roll_deg
    );
}

#[test]
fn threedtk_pairs_register_globally() {
    threedtk_pairs_register_globally_in(SearchMode::MultiResolution);
}

fn threedtk_pairs_register_globally_in(mode: SearchMode) {
    if data().is_none() {
        return;
    }
    let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
    let scans: Vec<PointCloud> = (0..3).map(tdk).collect();
    for (src, dst) in [(1usize, 0usize), (2, 0), (2, 1)] {
        let reference = refs.poses[dst].pose.inverse() * refs.poses[src].pose;
        let r = align::register(&scans[src], &scans[dst], &params_in(Dof::XyzYaw, mode)).unwrap();
        let e = PoseError::between(&r.pose, &reference);
        report(&format!("3DTK {src}->{dst} ({mode:?})"), &r, &e);
        assert_eq!(r.search.exact, mode == SearchMode::Exact);
        // Data README §1.7: 5 cm / 1 deg in x, y, yaw; 15 cm / 3 deg in z, pitch, roll.
        assert!(
            e.dx_m.abs() < 0.05 && e.dy_m.abs() < 0.05 && e.yaw_deg.abs() < 1.0,
            "{src}->{dst}: {e:?}"
        );
        assert!(
            e.dz_m.abs() < 0.15 && e.pitch_deg.abs() < 3.0 && e.roll_deg.abs() < 3.0,
            "{src}->{dst}: {e:?}"
        );
        assert!(
            r.trusted,
            "{src}->{dst}: a right answer should be trusted: {:?}",
            r.doubts
        );
    }
}

/// The same pairs and tolerances with the exact search over the whole scan and every
/// heading. Ignored by default: it takes about six minutes on two cores (each pair needs
/// two branch-and-bound passes, the optimum and the proof that no second cluster reaches
/// `keep_ratio` of it; see README "Search modes"). Run it with
/// `cargo test --release -p olmap --test it exact_search_registers_the_3dtk_pairs_globally -- --ignored`.
#[test]
#[ignore = "about six minutes on two cores; run explicitly"]
fn exact_search_registers_the_3dtk_pairs_globally() {
    threedtk_pairs_register_globally_in(SearchMode::Exact);
}

/// On every real pair, the exact search's score is at least the multi-resolution
/// search's (it is the optimum of the same lattice), and its pose passes the same accuracy
/// tests. The exact search over the whole scan with every heading takes minutes (the
/// ignored test above), so both searches look in the same window: ±0.5 m in x and y, ±0.3 m in
/// z, ±5° in heading, centred 0.23 m and 2° off the reference pose.
#[test]
fn exact_search_scores_at_least_the_multi_resolution_search() {
    if data().is_none() {
        return;
    }
    let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
    let scans: Vec<PointCloud> = (0..3).map(tdk).collect();
    for (src, dst) in [(1usize, 0usize), (2, 0), (2, 1)] {
        let reference = refs.poses[dst].pose.inverse() * refs.poses[src].pose;
        let mut p = params_in(Dof::XyzYaw, SearchMode::MultiResolution);
        p.search.prior =
            reference * Pose::from_xyz_ypr(0.2, -0.1, 0.05, 2f64.to_radians(), 0.0, 0.0);
        p.search.region = align::Region::Window {
            xy: 0.5,
            z: 0.3,
            yaw: 5f64.to_radians(),
        };
        let fast = align::register(&scans[src], &scans[dst], &p).unwrap();
        p.search.search = SearchMode::Exact;
        let exact = align::register(&scans[src], &scans[dst], &p).unwrap();
        eprintln!(
            "3DTK {src}->{dst} window: exact score {} ({} nodes, {:.2} s), multi-resolution {} ({} poses, {:.2} s)",
            exact.search.score, exact.search.evaluated, exact.search.seconds,
            fast.search.score, fast.search.evaluated, fast.search.seconds
        );
        assert!(exact.search.exact && !fast.search.exact);
        assert!(
            exact.search.score >= fast.search.score,
            "{src}->{dst}: {} < {}",
            exact.search.score,
            fast.search.score
        );
        let e = PoseError::between(&exact.pose, &reference);
        report(&format!("3DTK {src}->{dst} (exact, window)"), &exact, &e);
        // Data README §1.7: 5 cm / 1 deg in x, y, yaw; 15 cm / 3 deg in z, pitch, roll.
        assert!(
            e.dx_m.abs() < 0.05 && e.dy_m.abs() < 0.05 && e.yaw_deg.abs() < 1.0,
            "{src}->{dst}: {e:?}"
        );
        assert!(
            e.dz_m.abs() < 0.15 && e.pitch_deg.abs() < 3.0 && e.roll_deg.abs() < 3.0,
            "{src}->{dst}: {e:?}"
        );
        assert!(exact.trusted, "{src}->{dst}: {:?}", exact.doubts);
    }
}

#[test]
fn car_pair_registers_globally_in_six_dof() {
    let Some(d) = data() else { return };
    let gt = *io::csv::read_pose_table_path(d.join("libpointmatcher_car/carCloudList.csv"))
        .unwrap()
        .get("car_cloud401.csv")
        .unwrap();
    let r = align::register(
        &car(&d, "car_cloud401.csv"),
        &car(&d, "car_cloud400.csv"),
        &params(Dof::six_dof()),
    )
    .unwrap();
    let e = PoseError::between(&r.pose, &gt);
    report("car 401->400", &r, &e);
    // Data README §3: >= 5 cm / 0.5 deg.
    assert!(e.translation_m < 0.05 && e.rotation_deg < 0.5, "{e:?}");
    assert!(r.trusted, "{:?}", r.doubts);
}

/// The car pair's accuracy test (data README §3) with the exact search in six degrees of
/// freedom, next to the multi-resolution search in the same window: ±0.25 m in x and y,
/// ±0.3 m in z, ±1.5° in heading, roll and pitch, centred 0.18 m and 1.6° off the
/// reference pose. Over every heading and ±15° of tilt the exact search would take hours
/// (README "Search modes"); this window takes seconds.
#[test]
fn exact_search_registers_the_car_pair_in_six_dof_in_a_window() {
    let Some(d) = data() else { return };
    let gt = *io::csv::read_pose_table_path(d.join("libpointmatcher_car/carCloudList.csv"))
        .unwrap()
        .get("car_cloud401.csv")
        .unwrap();
    let (src, dst) = (car(&d, "car_cloud401.csv"), car(&d, "car_cloud400.csv"));
    let mut p = params_in(
        Dof::SixDof {
            max_tilt: 1.5f64.to_radians(),
        },
        SearchMode::MultiResolution,
    );
    p.search.prior = gt
        * Pose::from_xyz_ypr(
            0.15,
            -0.1,
            0.05,
            1f64.to_radians(),
            0.8f64.to_radians(),
            -0.9f64.to_radians(),
        );
    p.search.region = align::Region::Window {
        xy: 0.25,
        z: 0.3,
        yaw: 1.5f64.to_radians(),
    };
    let fast = align::register(&src, &dst, &p).unwrap();
    p.search.search = SearchMode::Exact;
    let exact = align::register(&src, &dst, &p).unwrap();
    eprintln!(
        "car 401->400 window: exact score {} ({} nodes, {:.2} s), multi-resolution {} ({} poses, {:.2} s)",
        exact.search.score, exact.search.evaluated, exact.search.seconds,
        fast.search.score, fast.search.evaluated, fast.search.seconds
    );
    assert!(exact.search.exact && !fast.search.exact);
    assert!(exact.search.score >= fast.search.score);
    for (name, r) in [("exact", &exact), ("multi-resolution", &fast)] {
        let e = PoseError::between(&r.pose, &gt);
        report(&format!("car 401->400 ({name}, window)"), r, &e);
        // Data README §3: >= 5 cm / 0.5 deg.
        assert!(
            e.translation_m < 0.05 && e.rotation_deg < 0.5,
            "{name}: {e:?}"
        );
        assert!(r.trusted, "{name}: {:?}", r.doubts);
    }
}

#[test]
fn unrelated_scenes_are_not_trusted() {
    let Some(d) = data() else { return };
    let outdoor = car(&d, "car_cloud400.csv");
    let indoor = tdk(0);
    let office = io::read_cloud(d.join("octomap_share_data/scan.dat"))
        .unwrap()
        .cloud;
    for (name, src, dst) in [
        ("car->3DTK", &outdoor, &indoor),
        ("scan.dat->3DTK", &office, &indoor),
        ("3DTK->scan.dat", &indoor, &office),
    ] {
        let r = align::register(src, dst, &params(Dof::XyzYaw)).unwrap();
        report(name, &r, &PoseError::between(&r.pose, &Pose::identity()));
        assert!(!r.trusted, "{name}: an unrelated scene must not be trusted");
    }
}

/// Issue 22, a real pair trusted 3.4 m off: 3DTK scan002 localised in a map of scan000
/// came back trusted at the identity (the two sensors' near floors on each other; a map
/// keeps no free space to contradict the scan's side), searched at 0.05 m (in a 0.05 m
/// map), and in six degrees of freedom at the default 0.1 m too. The truth, 3.4 m ahead,
/// was not among the hypotheses: at 0.05 m the upright look counted the phase of the
/// samples on distant walls, and six-degree-of-freedom searches had no upright look. The
/// look now searches at 0.1 m at the finest ([`align::verify::UPRIGHT_LOOK_FINEST`]) and
/// for six degrees of freedom at the prior's tilt: the truth is refined as a hypothesis
/// and the identity is not trusted over it. The same pair registered cloud to cloud may
/// be refused, never trusted wrong. Tolerances: data README §1.7.
#[test]
fn a_3dtk_scan_in_a_map_is_not_trusted_on_the_sensors_floors() {
    if data().is_none() {
        return;
    }
    let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
    let truth = refs.poses[0].pose.inverse() * refs.poses[2].pose;
    let (source, target) = (tdk(2), tdk(0));
    let right = |pose: &Pose| {
        let e = PoseError::between(pose, &truth);
        e.dx_m.abs() < 0.05 && e.dy_m.abs() < 0.05 && e.yaw_deg.abs() < 1.0
    };
    for (dof, resolution) in [
        (Dof::XyzYaw, 0.05),
        (Dof::six_dof(), 0.1),
        (Dof::six_dof(), 0.05),
    ] {
        let map = olmap::occupancy::OccupancyList::from_cloud(&target, resolution).unwrap();
        let mut p = params(dof);
        p.search.resolution = resolution;
        let what = format!("{dof:?} at {resolution} m");
        let localized = align::localize(&source, &map, &p).unwrap();
        report(
            &format!("3DTK 2 in a map of 0, {what} (localize)"),
            &localized,
            &PoseError::between(&localized.pose, &truth),
        );
        let hypotheses = &localized
            .verification
            .as_ref()
            .expect("a refined localisation is verified")
            .hypotheses;
        assert!(
            hypotheses.iter().any(|h| right(&h.pose())),
            "{what}: the truth was not among the {} hypotheses",
            hypotheses.len()
        );
        let registered = align::register(&source, &target, &p).unwrap();
        report(
            &format!("3DTK 2->0, {what} (register)"),
            &registered,
            &PoseError::between(&registered.pose, &truth),
        );
        for (how, r) in [("localize", &localized), ("register", &registered)] {
            assert!(
                !r.trusted || right(&r.pose),
                "{what}, {how}: trusted {:?} off",
                PoseError::between(&r.pose, &truth)
            );
        }
    }
}

/// A window that leaves out the true pose is not trusted at a look-alike inside it when the
/// map keeps its free space: a 3DTK scan localised in an OctoMap tree of another (written
/// with free nodes, as `olmap voxelize --free-space` writes it, and read back) is
/// contradicted where its surfaces would lie in the map's free space. Without free space
/// the same localisations were trusted 1.6-3.4 m off (2026-12-07 sweep; the map's side of
/// the agreement alone does not separate them). A window holding the truth is still
/// trusted and right. Tolerances: data README §1.7.
#[test]
fn a_3dtk_scan_in_a_map_with_free_space_is_not_trusted_in_a_window_without_the_truth() {
    if data().is_none() {
        return;
    }
    let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
    let dir = tempfile::tempdir().unwrap();
    let window = |xy: f64| align::Region::Window {
        xy,
        z: 0.2,
        yaw: 5f64.to_radians(),
    };
    let ahead = |dx: f64| Pose::from_xyz_ypr(dx, 0.0, 0.0, 0.0, 0.0, 0.0);
    // (scan, map, resolution, prior from the truth, window half-width, holds the truth)
    let cases = [
        (2, 0, 0.1, None, 0.5, false),
        (2, 1, 0.1, Some(-3.4), 2.0, false),
        (1, 0, 0.1, Some(-3.4), 2.0, false),
        (2, 0, 0.05, Some(-3.4), 0.5, false),
        (2, 0, 0.1, Some(0.2), 0.5, true),
        (2, 1, 0.1, Some(0.2), 0.5, true),
        (1, 0, 0.1, Some(0.2), 0.5, true),
    ];
    for (s, t, resolution, from_truth, half, holds) in cases {
        let truth = refs.poses[t].pose.inverse() * refs.poses[s].pose;
        let path = dir.path().join(format!("map{t}_{resolution}.bt"));
        if !path.exists() {
            let mut map =
                olmap::occupancy::LogOddsMap::new(resolution, Default::default()).unwrap();
            map.insert_scan(&tdk(t), &Pose::identity()).unwrap();
            map.write_bt(&path).unwrap();
        }
        let loaded = olmap::occupancy::read_map(&path).unwrap();
        let free = loaded
            .free
            .as_ref()
            .expect("the tree's free leaves are read");
        let mut p = params(Dof::XyzYaw);
        p.search.resolution = resolution;
        p.search.prior = from_truth.map_or(Pose::identity(), |dx| ahead(dx) * truth);
        p.search.region = window(half);
        let r = align::localize_in(&tdk(s), &loaded.map, Some(free), &p).unwrap();
        let e = PoseError::between(&r.pose, &truth);
        let what = format!("{s} in a map of {t} at {resolution} m, window ±{half} m");
        report(&what, &r, &e);
        let right = e.dx_m.abs() < 0.05 && e.dy_m.abs() < 0.05 && e.yaw_deg.abs() < 1.0;
        assert!(!r.trusted || right, "{what}: trusted {e:?} off");
        if holds {
            assert!(r.trusted && right, "{what}: {e:?} {:?}", r.doubts);
        }
    }
}

/// A scan of a place a map with free space does not hold is not trusted on a look-alike
/// of it. The demo lab (4 robots x 10 stops; seeds 1 and 4): one robot's last scans,
/// whose places the other robots barely saw (the truth overlaps their map 5-22 %),
/// localised globally in a map of the other three robots' scans ray traced at their true
/// poses. A sweep of every robot against the others (the map at the team's poses) found
/// these scans trusted 15-17 m and 90° off, on desk rows that repeat the scan's place,
/// while the same map without its free space doubted them: the free space had refuted
/// the look-alikes the map's surfaces fit as well and left the one it contradicted least.
/// Right within 0.3 m and 3° (the trust suite's tolerance: the simulator's truth is exact).
#[test]
fn a_scan_of_a_place_a_map_with_free_space_does_not_hold_is_not_trusted_on_a_look_alike() {
    use olmap::sim::{simulate, SimConfig};
    for (seed, robot, scans) in [(1u64, 2usize, [8usize, 9])] {
        let data = simulate(&SimConfig::demo_lab(seed, 4, 10), |_, _| {}).unwrap();
        let others = data
            .robots
            .iter()
            .enumerate()
            .filter(|(r, _)| *r != robot)
            .flat_map(|(_, rb)| rb.scans.iter().zip(&rb.truth));
        let max_range = olmap::mapping::MapParams::default().sensor.max_range;
        let map = olmap::occupancy::LogOddsMap::of_placed_scans(0.1, max_range, others).unwrap();
        let (occupied, free) = map.occupancy_and_free().unwrap();
        for k in scans {
            let truth = data.robots[robot].truth[k];
            let scan = &data.robots[robot].scans[k];
            let r = align::localize_in(scan, &occupied, Some(&free), &params(Dof::XyzYaw)).unwrap();
            let off = (r.pose.translation() - truth.translation()).norm();
            let turned = r.pose.rotation().angle_to(&truth.rotation()).to_degrees();
            eprintln!(
                "seed {seed} robot{robot} scan{k:03}: trusted {} {off:.2} m {turned:.1}° {:?}",
                r.trusted, r.doubts
            );
            assert!(
                !r.trusted || (off <= 0.3 && turned <= 3.0),
                "seed {seed} robot{robot} scan{k:03} trusted {off:.2} m and {turned:.1}° off"
            );
        }
    }
}

#[test]
fn same_input_same_output_on_any_thread_count() {
    if data().is_none() {
        return;
    }
    let (a, b) = (tdk(1), tdk(0));
    let p = params(Dof::XyzYaw);
    let many = align::register(&a, &b, &p).unwrap();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let single = one.install(|| align::register(&a, &b, &p).unwrap());
    assert_eq!(many.pose.to_row_major_3x4(), single.pose.to_row_major_3x4());
    assert_eq!(
        many.search.pose.to_row_major_3x4(),
        single.search.pose.to_row_major_3x4()
    );
    assert_eq!(many.search.evaluated, single.search.evaluated);
}

/// A window search whose best pose lies outside the inner half of the window, farther than
/// a refinement may move it (3 cells), is not refined when the caller widens instead
/// ([`align::OnWindowEdge::Widen`]): untrusted, with the reason, and no refinement; the same
/// search refined as usual is refined. Inside the inner half, widening changes nothing.
/// 3DTK 1->0, window ±1.5 m / ±5° around priors 1.2 m and 0.1 m off the reference in x.
#[test]
fn a_window_match_in_the_outer_half_is_not_refined_when_the_caller_widens() {
    if data().is_none() {
        return;
    }
    let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
    let (src, dst) = (tdk(1), tdk(0));
    let reference = refs.poses[0].pose.inverse() * refs.poses[1].pose;
    let target = align::SearchTarget::from_cloud(&dst, 0.1, 4).unwrap();
    let run = |off: f64, on_edge: align::OnWindowEdge| {
        let mut p = params(Dof::XyzYaw);
        p.search.prior = reference * Pose::from_xyz_ypr(off, 0.0, 0.0, 0.0, 0.0, 0.0);
        p.search.region = align::Region::Window {
            xy: 1.5,
            z: 0.3,
            yaw: 5f64.to_radians(),
        };
        align::register_to_prepared_or_widen(&src, &src, &target, &dst, None, &p, on_edge).unwrap()
    };
    let widen = align::OnWindowEdge::Widen { inner: 0.5 };
    let outer = run(1.2, widen);
    assert!(
        !outer.trusted && outer.refinement.is_none(),
        "{:?}",
        outer.doubts
    );
    assert!(
        outer.doubts.iter().any(|d| d.contains("inner 50 %")),
        "{:?}",
        outer.doubts
    );
    let refined = run(1.2, align::OnWindowEdge::Refine);
    assert!(refined.refinement.is_some());
    let inner = run(0.1, widen);
    assert!(
        inner.refinement.is_some() && inner.trusted,
        "{:?}",
        inner.doubts
    );
    let e = PoseError::between(&inner.pose, &reference);
    // Data README §1.7: 5 cm / 1 deg in x, y, yaw.
    assert!(
        e.dx_m.abs() < 0.05 && e.dy_m.abs() < 0.05 && e.yaw_deg.abs() < 1.0,
        "{e:?}"
    );
}
