//! Map building on real data (3DTK, with and without odometry; a foreign scan mixed in).

use olmap::geometry::{PoseError, PoseList};
use olmap::io::{self, slam6d};
use olmap::mapping::{build_map, evaluate, MapMode, MapParams, ScanInput};

use crate::data;

fn threedtk(d: &std::path::Path, odometry: bool) -> Vec<ScanInput> {
    olmap::fixtures::threedtk_scans(d, odometry).unwrap()
}

fn check_against_reference(placed: &[olmap::mapping::PlacedScan], label: &str) {
    let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
    for p in placed {
        let reference = refs.poses[p.index].pose;
        let e = PoseError::between(&p.pose, &reference);
        eprintln!(
            "{label} {}: order {} dx {:.3} dy {:.3} dz {:.3} yaw {:.2} pitch {:.2} roll {:.2}",
            p.name, p.order, e.dx_m, e.dy_m, e.dz_m, e.yaw_deg, e.pitch_deg, e.roll_deg
        );
        // Data README §1.7 tolerances.
        assert!(
            e.dx_m.abs() < 0.05 && e.dy_m.abs() < 0.05 && e.yaw_deg.abs() < 1.0,
            "{label} {}: {e:?}",
            p.name
        );
        assert!(
            e.dz_m.abs() < 0.15 && e.pitch_deg.abs() < 3.0 && e.roll_deg.abs() < 3.0,
            "{label} {}: {e:?}",
            p.name
        );
    }
}

#[test]
fn threedtk_batch_map_with_and_without_odometry() {
    let Some(d) = data() else { return };
    for odometry in [false, true] {
        let scans = threedtk(&d, odometry);
        let m = build_map(&scans, &MapParams::default(), |_, _| {}).unwrap();
        eprintln!(
            "odometry {odometry}: {} placed, {} registrations, {:.2} s, {} voxels",
            m.placed.len(),
            m.registrations,
            m.seconds,
            m.map.len()
        );
        assert_eq!(m.placed.len(), 3, "{:?}", m.rejected);
        check_against_reference(&m.placed, if odometry { "odometry" } else { "no odometry" });
        assert!(m.map.len() > 10_000);
        // The scan-pose pairs rebuild the map: every rebuilt voxel lies within one cell
        // (re-binning) of a voxel of the ray-traced map, but for the few the other scans
        // saw through (cross-scan clearing, which the per-scan lists cannot apply).
        assert_eq!(m.scan_maps.len(), 3);
        let rebuilt = olmap::mapping::fuse_scan_maps(&m.scan_maps).unwrap();
        let near = rebuilt
            .iter()
            .filter(|(k, _)| {
                (-1..=1).any(|dx| {
                    (-1..=1).any(|dy| {
                        (-1..=1).any(|dz| {
                            m.map.count(olmap::geometry::VoxelKey::new(
                                k.x + dx,
                                k.y + dy,
                                k.z + dz,
                            )) > 0
                        })
                    })
                })
            })
            .count();
        let share = near as f64 / rebuilt.len() as f64;
        eprintln!(
            "rebuilt {} voxels, {:.3} near the ray-traced map",
            rebuilt.len(),
            share
        );
        assert!(share > 0.9, "{share}");
        if odometry {
            assert!(
                m.placed.iter().all(|p| !p.global),
                "odometry windows suffice here"
            );
        }
    }
}

#[test]
fn a_foreign_scan_is_rejected_with_a_reason() {
    let Some(d) = data() else { return };
    let mut scans = threedtk(&d, false);
    scans.insert(
        1,
        ScanInput {
            name: "car_cloud400".into(),
            cloud: io::read_cloud(d.join("libpointmatcher_car/car_cloud400.csv"))
                .unwrap()
                .cloud,
            odometry: None,
        },
    );
    for mode in [MapMode::Batch, MapMode::Sequential] {
        let params = MapParams {
            mode,
            ..Default::default()
        };
        let m = build_map(&scans, &params, |_, _| {}).unwrap();
        assert_eq!(m.rejected.len(), 1, "{mode:?}");
        assert_eq!(m.rejected[0].name, "car_cloud400");
        assert!(!m.rejected[0].reasons.is_empty());
        eprintln!(
            "{mode:?}: rejected {}: {:?}",
            m.rejected[0].name, m.rejected[0].reasons
        );
        let mut fixed: Vec<_> = m.placed.clone();
        for p in &mut fixed {
            // Index in the 3DTK set (the car was inserted at 1).
            if p.index > 1 {
                p.index -= 1;
            }
        }
        check_against_reference(&fixed, &format!("{mode:?} with a foreign scan"));
    }
}

#[test]
fn evaluation_of_the_reference_against_itself_and_the_odometry() {
    let Some(d) = data() else { return };
    let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
    let same = evaluate(&refs, &refs).unwrap();
    assert!(same.summary.translation_m[2] < 1e-9);
    let mut odo = PoseList::default();
    for i in 0..3 {
        odo.push(
            format!("00{i}"),
            slam6d::read_pose_path(d.join(format!("3dtk_dat/scan00{i}.pose"))).unwrap(),
        );
    }
    let e = evaluate(&odo, &refs).unwrap();
    // README §1.7: odometry (.pose) and final frames differ by about 2-4 cm and < 1 degree.
    assert_eq!(e.summary.scans, 3);
    assert!(
        e.summary.translation_m[2] < 0.05 && e.summary.rotation_deg[2] < 1.5,
        "{:?}",
        e.summary
    );
}

#[test]
fn batch_chains_scans_that_sequential_order_cannot() {
    use olmap::geometry::Pose;
    let world = olmap::fixtures::hall(0.15);
    // 20 stops along the hall, given in an interleaved order (0, 10, 1, 11, ...): scans
    // consecutive in the input are 19 m apart and never overlap (8 m sensor range).
    let truth: Vec<Pose> = olmap::fixtures::hall_trajectory(20, 1.9);
    let order: Vec<usize> = (0..10).flat_map(|i| [i, i + 10]).collect();
    let scans: Vec<ScanInput> = order
        .iter()
        .map(|&i| {
            let cloud = olmap::fixtures::scan_of(&world, &truth[i], 8.0);
            // Odometry drifting 3 % in distance and 0.5 degree per stop.
            let drift = Pose::from_xyz_ypr(
                0.03 * truth[i].translation().x,
                0.0,
                0.0,
                (0.5 * i as f64).to_radians(),
                0.0,
                0.0,
            );
            ScanInput {
                name: format!("stop{i:02}"),
                cloud,
                odometry: Some(drift * truth[i]),
            }
        })
        .collect();
    let run = |mode| {
        let mut params = MapParams {
            mode,
            ..Default::default()
        };
        params.register.search.resolution = 0.2;
        // The hall's surfaces are sampled every 0.15 m: refining on a 0.2 m grid keeps
        // one point per surface cell (this test is about the placement order, and a
        // 0.05 m grid made each of its ~400 registrations 4x dearer for no information).
        if let Some(icp) = params.register.refine.as_mut() {
            icp.source_voxel = 0.2;
            icp.target_voxel = 0.2;
        }
        build_map(&scans, &params, |_, _| {}).unwrap()
    };
    let batch = run(MapMode::Batch);
    let sequential = run(MapMode::Sequential);
    eprintln!(
        "batch: {} placed, {} registrations, {:.2} s; sequential: {} placed, {} registrations, {:.2} s",
        batch.placed.len(), batch.registrations, batch.seconds, sequential.placed.len(), sequential.registrations, sequential.seconds
    );
    for r in &batch.rejected {
        eprintln!("rejected {}: {:?}", r.name, r.reasons);
    }
    for p in &batch.placed {
        eprintln!(
            "placed {} #{} ov {:.2} z {:.1} global {} at {}",
            p.name, p.order, p.overlap_fraction, p.significance, p.global, p.pose
        );
    }
    assert_eq!(batch.placed.len(), 20, "{:?}", batch.rejected);
    assert!(
        sequential.placed.len() < 20,
        "strict input order cannot chain these scans"
    );
    // Batch poses against the truth, in the frame of the first scan.
    let mut est = PoseList::default();
    let mut reference = PoseList::default();
    for p in &batch.placed {
        est.push(p.name.clone(), p.pose);
        reference.push(p.name.clone(), truth[order[p.index]]);
    }
    let e = evaluate(&est, &reference).unwrap();
    eprintln!("batch error: {:?}", e.summary);
    assert!(
        e.summary.translation_m[2] < 0.1 && e.summary.rotation_deg[2] < 1.0,
        "{:?}",
        e.summary
    );
}
