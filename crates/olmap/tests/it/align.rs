//! Global alignment on real data, from the identity with no prior.

use olmap::align::{self, Dof, SearchParams};
use olmap::cloud::PointCloud;
use olmap::geometry::{Pose, PoseError, PoseList};
use olmap::io::{self, ReadOptions};

use crate::data;

fn tdk(d: &std::path::Path, i: usize) -> PointCloud {
    let valid = ReadOptions {
        uos_valid_only: true,
        ..Default::default()
    };
    io::read_cloud_with(d.join(format!("3dtk_dat/scan00{i}.3d")), &valid)
        .unwrap()
        .cloud
}

#[test]
fn threedtk_pairs_global() {
    let Some(d) = data() else { return };
    let refs = PoseList::read_path(d.join("3dtk_dat/reference_poses_rh_m.txt")).unwrap();
    let scans: Vec<PointCloud> = (0..3).map(|i| tdk(&d, i)).collect();
    for (src, dst) in [(1usize, 0usize), (2, 0), (2, 1)] {
        let reference = refs.poses[dst].pose.inverse() * refs.poses[src].pose;
        let params = SearchParams::default();
        let a = align::align_clouds(&scans[src], &scans[dst], &params).unwrap();
        let e = PoseError::between(&a.pose, &reference);
        eprintln!(
            "{src}->{dst}: {:.3}s overlap {} / {} ({:.2}) z {:.1} amb {} guard {} eval {} | dx {:.3} dy {:.3} dz {:.3} yaw {:.2} pitch {:.2} roll {:.2}",
            a.seconds, a.overlap, a.scan_voxels, a.overlap_fraction, a.significance, a.ambiguity, a.guard_acted, a.evaluated,
            e.dx_m, e.dy_m, e.dz_m, e.yaw_deg, e.pitch_deg, e.roll_deg
        );
        for l in &a.levels {
            eprintln!("   level {} res {:.2} dth {:.2}deg scan {} eval {} passed {} kept {} best {} {:.3}s", l.level, l.resolution, l.angular_step.to_degrees(), l.scan_voxels, l.evaluated, l.passed, l.survivors, l.best_overlap, l.seconds);
        }
        // Coarse search only: within a finest cell or two of the reference.
        assert!(
            e.dx_m.abs() < 0.25 && e.dy_m.abs() < 0.25 && e.yaw_deg.abs() < 2.0,
            "{src}->{dst}: {e:?}"
        );
    }
    let _ = Dof::XyzYaw;
    let _ = Pose::identity();
}

#[test]
#[ignore]
fn probe_landscape() {
    let Some(d) = data() else { return };
    let refs = PoseList::read_path(d.join("3dtk_dat/reference_poses_rh_m.txt")).unwrap();
    let s0 = tdk(&d, 0);
    let s2 = tdk(&d, 2);
    let mut zs: Vec<f32> = s0.points().iter().map(|p| p.z).collect();
    zs.sort_by(f32::total_cmp);
    let q = |f: f64| zs[(f * (zs.len() - 1) as f64) as usize];
    eprintln!(
        "z percentiles 1 5 10 25 50 75 90: {} {} {} {} {} {} {}",
        q(0.01),
        q(0.05),
        q(0.1),
        q(0.25),
        q(0.5),
        q(0.75),
        q(0.9)
    );
    let reference = refs.poses[2].pose;
    for res in [0.1, 0.2, 0.4, 0.8, 1.6] {
        let map = olmap::occupancy::OccupancyList::from_cloud(&s0, res).unwrap();
        let scan = olmap::occupancy::OccupancyList::from_cloud(&s2, res).unwrap();
        let at_ref = map.overlap(&scan, &reference).unwrap();
        let at_id = map.overlap(&scan, &Pose::identity()).unwrap();
        let mut best_x = (0, 0.0);
        for i in -10..50 {
            let x = i as f64 * 0.1;
            let p = Pose::from_xyz_ypr(
                x,
                reference.translation().y,
                reference.translation().z,
                0.0057,
                0.0,
                0.0,
            );
            let o = map.overlap(&scan, &p).unwrap();
            if o > best_x.0 {
                best_x = (o, x);
            }
        }
        eprintln!(
            "res {res}: scan {} map {} at ref {at_ref} at identity {at_id}; best along x {:?}",
            scan.len(),
            map.len(),
            best_x
        );
    }
}

fn drop_horizontal(l: &olmap::occupancy::OccupancyList) -> olmap::occupancy::OccupancyList {
    use olmap::geometry::VoxelKey;
    l.filtered(|k, _| {
        let mut same = 0;
        let mut other = 0;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if (dx, dy, dz) == (0, 0, 0) {
                        continue;
                    }
                    if l.count(VoxelKey::new(k.x + dx, k.y + dy, k.z + dz)) > 0 {
                        if dz == 0 {
                            same += 1
                        } else {
                            other += 1
                        }
                    }
                }
            }
        }
        !(same >= 3 && other <= 1)
    })
}

#[test]
#[ignore]
fn probe_landscape_no_floor() {
    let Some(d) = data() else { return };
    let refs = PoseList::read_path(d.join("3dtk_dat/reference_poses_rh_m.txt")).unwrap();
    let s0 = tdk(&d, 0);
    let s2 = tdk(&d, 2);
    let reference = refs.poses[2].pose;
    for res in [0.1, 0.2, 0.4] {
        let map = drop_horizontal(&olmap::occupancy::OccupancyList::from_cloud(&s0, res).unwrap());
        let scan = drop_horizontal(&olmap::occupancy::OccupancyList::from_cloud(&s2, res).unwrap());
        let at_ref = map.overlap(&scan, &reference).unwrap();
        let at_id = map.overlap(&scan, &Pose::identity()).unwrap();
        let mut best = (0, 0.0, 0.0);
        for i in -10..50 {
            for zi in -4..=4 {
                let x = i as f64 * 0.1;
                let z = zi as f64 * 0.05;
                let p = Pose::from_xyz_ypr(x, reference.translation().y, z, 0.0057, 0.0, 0.0);
                let o = map.overlap(&scan, &p).unwrap();
                if o > best.0 {
                    best = (o, x, z);
                }
            }
        }
        eprintln!(
            "res {res}: scan {} map {} at ref {at_ref} at identity {at_id}; best along x,z {:?}",
            scan.len(),
            map.len(),
            best
        );
    }
}

#[test]
#[ignore]
fn probe_free_space() {
    use olmap::geometry::VoxelKey;
    use olmap::occupancy::VoxelRay;
    use std::collections::HashSet;
    let Some(d) = data() else { return };
    let refs = PoseList::read_path(d.join("3dtk_dat/reference_poses_rh_m.txt")).unwrap();
    let s0 = tdk(&d, 0);
    let s2 = tdk(&d, 2);
    let reference = refs.poses[2].pose;
    for res in [0.1, 0.2, 0.4, 0.8] {
        let map = olmap::occupancy::OccupancyList::from_cloud(&s0, res).unwrap();
        let mut free: HashSet<VoxelKey> = HashSet::new();
        for p in s0.points() {
            let keys: Vec<VoxelKey> =
                VoxelRay::new(&nalgebra::Point3::origin(), &p.cast(), res).collect();
            for k in &keys[..keys.len().saturating_sub(2)] {
                free.insert(*k);
            }
        }
        let scan = olmap::occupancy::OccupancyList::from_cloud(&s2, res).unwrap();
        let score = |pose: &Pose| {
            let keys = scan.transformed_keys(pose);
            let hits = keys.iter().filter(|k| map.count(**k) > 0).count() as i64;
            let conf = keys
                .iter()
                .filter(|k| map.count(**k) == 0 && free.contains(k))
                .count() as i64;
            (hits, conf, hits - conf)
        };
        let mut best = (i64::MIN, 0.0, 0.0);
        for i in -10..50 {
            for yi in -3..=3 {
                let x = i as f64 * 0.1;
                let y = yi as f64 * 0.05;
                let p = Pose::from_xyz_ypr(x, y, reference.translation().z, 0.0057, 0.0, 0.0);
                let s = score(&p).2;
                if s > best.0 {
                    best = (s, x, y);
                }
            }
        }
        eprintln!(
            "res {res}: free {} ref {:?} identity {:?} best {:?}",
            free.len(),
            score(&reference),
            score(&Pose::identity()),
            best
        );
    }
}

#[test]
#[ignore]
fn probe_car() {
    let Some(d) = data() else { return };
    let c400 = io::read_cloud(d.join("libpointmatcher_car/car_cloud400.csv"))
        .unwrap()
        .cloud;
    let c401 = io::read_cloud(d.join("libpointmatcher_car/car_cloud401.csv"))
        .unwrap()
        .cloud;
    let gt = *olmap::io::csv::read_pose_table_path(d.join("libpointmatcher_car/carCloudList.csv"))
        .unwrap()
        .get("car_cloud401.csv")
        .unwrap();
    for (res, levels, surv) in [(0.2, 0, 50), (0.2, 0, 300), (0.1, 0, 50)] {
        let params = SearchParams {
            resolution: res,
            levels,
            dof: Dof::six_dof(),
            max_survivors: surv,
            ..Default::default()
        };
        let a = align::align_clouds(&c401, &c400, &params).unwrap();
        let e = PoseError::between(&a.pose, &gt);
        eprintln!("res {res} levels {levels}: {:.3}s overlap {} / {} z {:.1} amb {} | t {:.3} rot {:.2} | {:?}", a.seconds, a.overlap, a.scan_voxels, a.significance, a.ambiguity, e.translation_m, e.rotation_deg, e);
        for l in &a.levels {
            eprintln!("   level {} res {:.2} dth {:.2}deg scan {} eval {} passed {} kept {} best {} {:.3}s", l.level, l.resolution, l.angular_step.to_degrees(), l.scan_voxels, l.evaluated, l.passed, l.survivors, l.best_overlap, l.seconds);
        }
    }
}

#[test]
#[ignore]
fn probe_negative() {
    let Some(d) = data() else { return };
    let c400 = io::read_cloud(d.join("libpointmatcher_car/car_cloud400.csv"))
        .unwrap()
        .cloud;
    let s0 = tdk(&d, 0);
    let s1 = tdk(&d, 1);
    let dat = io::read_cloud(d.join("octomap_share_data/scan.dat"))
        .unwrap()
        .cloud;
    for (name, src, dst) in [
        ("3dtk1->car", &s1, &c400),
        ("car->3dtk0", &c400, &s0),
        ("scan.dat->3dtk0", &dat, &s0),
        ("3dtk0->scan.dat", &s0, &dat),
        ("3dtk1->3dtk0", &s1, &s0),
    ] {
        let params = SearchParams::default();
        let a = align::align_clouds(src, dst, &params).unwrap();
        eprintln!(
            "{name}: {:.3}s overlap {} / {} ({:.2}) z {:.1} amb {} cands {:?}",
            a.seconds,
            a.overlap,
            a.scan_voxels,
            a.overlap_fraction,
            a.significance,
            a.ambiguity,
            a.candidates.iter().map(|c| c.overlap).collect::<Vec<_>>()
        );
    }
}
