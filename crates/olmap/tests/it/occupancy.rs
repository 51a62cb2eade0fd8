//! Occupancy lists: property tests against brute-force references, and real data.

use std::collections::HashSet;

use nalgebra::Point3;
use olmap::cloud::PointCloud;
use olmap::geometry::{Pose, VoxelKey};
use olmap::io;
use olmap::occupancy::{OccupancyList, Pyramid, SensorModel, VoxelRay};
use proptest::prelude::*;

use crate::data;

/// Length of the part of segment a-b inside voxel `k` (slab clipping).
fn length_inside(a: &Point3<f64>, b: &Point3<f64>, k: VoxelKey, res: f64) -> f64 {
    let lo = Point3::new(k.x as f64, k.y as f64, k.z as f64) * res;
    let d = b - a;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for i in 0..3 {
        let (l, h) = (lo[i], lo[i] + res);
        if d[i].abs() < 1e-15 {
            if a[i] < l || a[i] > h {
                return 0.0;
            }
        } else {
            let (u, v) = ((l - a[i]) / d[i], (h - a[i]) / d[i]);
            t0 = t0.max(u.min(v));
            t1 = t1.min(u.max(v));
        }
    }
    ((t1 - t0).max(0.0)) * d.norm()
}

fn coord() -> impl Strategy<Value = f64> {
    -3.0f64..3.0
}

fn voxel_set() -> impl Strategy<Value = Vec<(i32, i32, i32, u16)>> {
    proptest::collection::vec((-40i32..40, -40i32..40, -10i32..10, 1u16..20), 0..300)
}

fn list_of(res: f64, v: &[(i32, i32, i32, u16)]) -> OccupancyList {
    let mut l = OccupancyList::new(res).unwrap();
    for &(x, y, z, c) in v {
        l.set(VoxelKey::new(x, y, z), c as u32).unwrap();
    }
    l
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn keys_use_floor(c in -1e4f64..1e4, res in 0.01f64..1.0) {
        let k = VoxelKey::from_point(&Point3::new(c, -c, c * 0.5), res).unwrap();
        for (v, key) in [(c, k.x), (-c, k.y), (c * 0.5, k.z)] {
            let lo = key as f64 * res;
            prop_assert!(lo <= v + 1e-9 && v < lo + res + 1e-9, "{v} in cell {key} of {res}");
        }
    }

    #[test]
    fn dda_visits_what_fine_sampling_visits(
        ax in coord(), ay in coord(), az in coord(), bx in coord(), by in coord(), bz in coord(),
        res in 0.05f64..0.5,
    ) {
        let (a, b) = (Point3::new(ax, ay, az), Point3::new(bx, by, bz));
        let dda: Vec<VoxelKey> = VoxelRay::new(&a, &b, res).collect();
        prop_assert_eq!(dda[0], VoxelKey::from_point(&a, res).unwrap());
        prop_assert_eq!(*dda.last().unwrap(), VoxelKey::from_point(&b, res).unwrap());
        let dda_set: HashSet<VoxelKey> = dda.iter().copied().collect();
        prop_assert_eq!(dda_set.len(), dda.len(), "a voxel visited twice");
        let n = 20_000;
        let reference: HashSet<VoxelKey> = (0..=n)
            .map(|i| VoxelKey::from_point(&(a + (b - a) * (i as f64 / n as f64)), res).unwrap())
            .collect();
        let step = (b - a).norm() / n as f64;
        // Voxels only one side has are ties: the segment barely touches them.
        for k in dda_set.symmetric_difference(&reference) {
            let inside = length_inside(&a, &b, *k, res);
            prop_assert!(inside <= 2.0 * step + 1e-9, "voxel {k:?}: {inside} m of the ray inside it");
        }
    }

    #[test]
    fn downsampling_commutes(v in voxel_set()) {
        let l = list_of(0.05, &v);
        let twice = l.downsample(2).unwrap().downsample(2).unwrap();
        let once = l.downsample(4).unwrap();
        prop_assert_eq!(twice.sorted(), once.sorted());
        prop_assert!((twice.resolution() - once.resolution()).abs() < 1e-15);
    }

    #[test]
    fn self_overlap_is_the_size(v in voxel_set()) {
        let l = list_of(0.1, &v);
        prop_assert_eq!(l.overlap(&l, &Pose::identity()).unwrap(), l.len() as u64);
        let keys = l.transformed_keys(&Pose::identity());
        prop_assert_eq!(l.overlap_keys(&keys, [0, 0, 0]), l.len() as u64);
    }

    #[test]
    fn merge_is_commutative_and_associative(a in voxel_set(), b in voxel_set(), c in voxel_set()) {
        let (la, lb, lc) = (list_of(0.1, &a), list_of(0.1, &b), list_of(0.1, &c));
        let mut ab = la.clone();
        ab.merge(&lb).unwrap();
        let mut ba = lb.clone();
        ba.merge(&la).unwrap();
        prop_assert_eq!(ab.sorted(), ba.sorted());
        let mut ab_c = ab.clone();
        ab_c.merge(&lc).unwrap();
        let mut bc = lb.clone();
        bc.merge(&lc).unwrap();
        let mut a_bc = la.clone();
        a_bc.merge(&bc).unwrap();
        prop_assert_eq!(ab_c.sorted(), a_bc.sorted());
    }
}

/// The ray-trace sensor model written plainly: per-scan sets, then updates.
fn reference_insert(map: &mut OccupancyList, cloud: &PointCloud, pose: &Pose, model: &SensorModel) {
    let res = map.resolution();
    let o = pose.transform_point(&cloud.origin());
    let mut hits = HashSet::new();
    let mut frees = HashSet::new();
    for p in cloud.points() {
        let e = pose.transform_point(&p.cast());
        let r = (e - o).norm();
        let (end, hit) = if r > model.max_range {
            (o + (e - o) * (model.max_range / r), false)
        } else {
            (e, true)
        };
        let keys: Vec<VoxelKey> = VoxelRay::new(&o, &end, res).collect();
        let n = if hit { keys.len() - 1 } else { keys.len() };
        frees.extend(keys[..n].iter().copied());
        if hit {
            hits.insert(VoxelKey::from_point(&end, res).unwrap());
        }
    }
    for k in frees.difference(&hits) {
        let c = map.count(*k) as u32;
        map.set(*k, c.saturating_sub(model.miss as u32)).unwrap();
    }
    for k in &hits {
        let c = map.count(*k) as u32;
        map.set(*k, (c + model.hit as u32).min(model.max_count as u32))
            .unwrap();
    }
}

fn random_scan(seed: u64, n: usize) -> PointCloud {
    let mut s = seed | 1;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let pts = (0..n)
        .map(|_| {
            let (az, el, r) = (
                next() * std::f64::consts::TAU,
                next() * 1.2 - 0.6,
                0.3 + next() * 6.0,
            );
            Point3::new(
                (r * el.cos() * az.cos()) as f32,
                (r * el.cos() * az.sin()) as f32,
                (r * el.sin()) as f32,
            )
        })
        .collect();
    PointCloud::from_points(pts)
}

#[test]
fn ray_tracing_matches_the_plain_reference_on_any_thread_count() {
    let model = SensorModel {
        hit: 2,
        miss: 1,
        max_count: 9,
        max_range: 4.0,
    };
    let mut fast = OccupancyList::new(0.1).unwrap();
    let mut plain = OccupancyList::new(0.1).unwrap();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let mut single = OccupancyList::new(0.1).unwrap();
    for i in 0..6 {
        let scan = random_scan(i + 1, 5000);
        let pose = Pose::from_xyz_ypr(
            0.3 * i as f64,
            -0.1 * i as f64,
            0.05,
            0.4 * i as f64,
            0.0,
            0.02,
        );
        fast.insert_scan(&scan, &pose, &model).unwrap();
        reference_insert(&mut plain, &scan, &pose, &model);
        one.install(|| single.insert_scan(&scan, &pose, &model).unwrap());
    }
    assert!(fast.len() > 1000);
    assert_eq!(fast.sorted(), plain.sorted());
    assert_eq!(fast.sorted(), single.sorted());
}

#[test]
fn pyramid_updated_incrementally_equals_rebuilt() {
    let model = SensorModel::default();
    let mut pyramid = Pyramid::new(OccupancyList::new(0.05).unwrap(), 5).unwrap();
    for i in 0..4 {
        let scan = random_scan(100 + i, 3000);
        let pose = Pose::from_xyz_ypr(0.5 * i as f64, 0.2, 0.0, 0.3 * i as f64, 0.0, 0.0);
        pyramid.insert_scan(&scan, &pose, &model).unwrap();
    }
    let rebuilt = Pyramid::new(pyramid.base().clone(), 5).unwrap();
    for i in 0..5 {
        assert_eq!(
            pyramid.level(i).sorted(),
            rebuilt.level(i).sorted(),
            "level {i}"
        );
    }
}

#[test]
fn real_scans_voxelise_with_ray_tracing() {
    let Some(d) = data() else { return };
    let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
    let scans: Vec<PointCloud> = (0..3)
        .map(|i| olmap::test_data::threedtk_scan(i, true).expect("the data folder was found"))
        .collect();
    let dat = io::read_cloud(d.join("octomap_share_data/scan.dat"))
        .unwrap()
        .cloud;
    for res in [0.05, 0.1] {
        for (name, cloud) in [("scan000", &scans[0]), ("scan.dat", &dat)] {
            let mut traced = OccupancyList::new(res).unwrap();
            let s = traced
                .insert_scan(cloud, &Pose::identity(), &SensorModel::default())
                .unwrap();
            let endpoints = OccupancyList::from_cloud(cloud, res).unwrap();
            eprintln!(
                "{name} at {res} m: {} voxels ray-traced, {} endpoint voxels, {s:?}",
                traced.len(),
                endpoints.len()
            );
            // A single scan is tens of thousands of voxels (thesis §5.3.1: 20k for a room at
            // 0.1 m), never more than its endpoint voxels. Into an empty map a scan's own
            // rays free nothing (within one scan a hit wins over a miss); only the endpoints
            // of rays cut at the maximum range are missing.
            assert!(
                (5_000..200_000).contains(&traced.len()),
                "{name} at {res}: {}",
                traced.len()
            );
            assert!(traced.len() <= endpoints.len());
            assert!(traced.len() as f64 >= 0.9 * endpoints.len() as f64);
            assert_eq!(s.rays as usize, cloud.len());
        }
    }
    // Three 3DTK scans at their reference poses: the overlap of scan001 with the map of
    // scan000 is far higher at the reference pose than 1 m or 10 degrees away.
    let res = 0.1;
    let mut map = OccupancyList::new(res).unwrap();
    map.insert_scan(&scans[0], &refs.poses[0].pose, &SensorModel::default())
        .unwrap();
    let scan1 = OccupancyList::from_cloud(&scans[1], res).unwrap();
    let at = map.overlap(&scan1, &refs.poses[1].pose).unwrap();
    let shifted = Pose::from_xyz_ypr(1.0, 0.0, 0.0, 0.0, 0.0, 0.0) * refs.poses[1].pose;
    let turned =
        refs.poses[1].pose * Pose::from_xyz_ypr(0.0, 0.0, 0.0, 10f64.to_radians(), 0.0, 0.0);
    let off1 = map.overlap(&scan1, &shifted).unwrap();
    let off2 = map.overlap(&scan1, &turned).unwrap();
    eprintln!(
        "overlap at the reference pose {at}, 1 m off {off1}, 10 deg off {off2} of {}",
        scan1.len()
    );
    assert!(at > 2 * off1 && at > 2 * off2, "{at} vs {off1}, {off2}");
    for (i, scan) in scans.iter().enumerate().skip(1) {
        map.insert_scan(scan, &refs.poses[i].pose, &SensorModel::default())
            .unwrap();
    }
    let s = map.stats();
    assert!(
        s.bytes_per_voxel() <= 16.0,
        "{:.1} bytes per voxel",
        s.bytes_per_voxel()
    );
}
