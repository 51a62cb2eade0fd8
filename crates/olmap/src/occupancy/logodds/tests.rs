//! Tests of the log-odds map against OctoMap's semantics, written out independently.

use std::collections::{HashMap, HashSet};

use nalgebra::Point3;

use super::*;
use crate::cloud::PointCloud;
use crate::fixtures;
use crate::geometry::Pose;
use crate::io::octomap_bt;
use crate::occupancy::VoxelRay;

fn cloud(points: &[[f32; 3]]) -> PointCloud {
    PointCloud::from_points(
        points
            .iter()
            .map(|p| Point3::new(p[0], p[1], p[2]))
            .collect(),
    )
}

/// OctoMap's `computeUpdate` + `updateNode`, in f64 with hash sets, one scan at a time.
struct Reference {
    res: f64,
    model: LogOddsModel,
    values: HashMap<VoxelKey, f64>,
}

impl Reference {
    fn insert(&mut self, scan: &PointCloud, pose: &Pose) {
        let origin = pose.transform_point(&scan.origin());
        let (mut free, mut occupied) = (HashSet::new(), HashSet::new());
        for p in scan.points() {
            let end = pose.transform_point(&p.cast::<f64>());
            let r = (end - origin).norm();
            let (end, hit) = if r > self.model.max_range {
                (origin + (end - origin) * (self.model.max_range / r), false)
            } else {
                (end, true)
            };
            let keys: Vec<VoxelKey> = VoxelRay::new(&origin, &end, self.res).collect();
            free.extend(keys[..keys.len() - 1].iter().copied());
            if hit {
                occupied.insert(*keys.last().unwrap());
            }
        }
        let (lo, hi) = (logit(self.model.clamp_min), logit(self.model.clamp_max));
        for (keys, delta) in [
            (
                free.difference(&occupied).copied().collect::<Vec<_>>(),
                logit(self.model.prob_miss),
            ),
            (occupied.into_iter().collect(), logit(self.model.prob_hit)),
        ] {
            for k in keys {
                let v = self.values.entry(k).or_insert(0.0);
                *v = (*v + delta).clamp(lo, hi);
            }
        }
    }

    fn state(&self, k: &VoxelKey) -> VoxelState {
        match self.values.get(k) {
            None => VoxelState::Unknown,
            Some(&v) if v >= logit(self.model.occupancy_threshold) => VoxelState::Occupied,
            Some(_) => VoxelState::Free,
        }
    }
}

fn sorted(map: &LogOddsMap) -> Vec<(VoxelKey, VoxelState)> {
    let mut v: Vec<_> = map.voxels().collect();
    v.sort_unstable_by_key(|(k, _)| (k.x, k.y, k.z));
    v
}

#[test]
fn one_ray_frees_its_path_and_hits_its_end_once_per_scan() {
    let mut map = LogOddsMap::new(0.1, LogOddsModel::default()).unwrap();
    // Ten returns in one voxel are one observation.
    let s = map
        .insert_scan(&cloud(&[[1.05, 0.05, 0.05]; 10]), &Pose::identity())
        .unwrap();
    assert_eq!((s.rays, s.occupied_updates, s.free_updates), (10, 1, 10));
    assert_eq!(map.len(), 11);
    let p = map.probability(&VoxelKey::new(10, 0, 0)).unwrap();
    assert!((p - 0.7).abs() < 1e-3, "{p}");
    let p = map.probability(&VoxelKey::new(0, 0, 0)).unwrap();
    assert!((p - 0.4).abs() < 1e-3, "{p}");
    // A voxel crossed by one ray and hit by another in the same scan is only hit.
    let mut map = LogOddsMap::new(0.1, LogOddsModel::default()).unwrap();
    map.insert_scan(
        &cloud(&[[0.55, 0.05, 0.05], [1.05, 0.05, 0.05]]),
        &Pose::identity(),
    )
    .unwrap();
    assert_eq!(map.state(&VoxelKey::new(5, 0, 0)), VoxelState::Occupied);
    assert_eq!(map.state(&VoxelKey::new(7, 0, 0)), VoxelState::Free);
}

#[test]
fn rays_beyond_max_range_free_space_only_up_to_the_cut() {
    let model = LogOddsModel {
        max_range: 0.5,
        ..LogOddsModel::default()
    };
    let mut map = LogOddsMap::new(0.1, model).unwrap();
    let s = map
        .insert_scan(&cloud(&[[3.05, 0.05, 0.05]]), &Pose::identity())
        .unwrap();
    assert_eq!((s.truncated, s.occupied_updates), (1, 0));
    // The cut is 0.5 m from the origin, at x = 0.49996: voxels 0..=3 free, voxel 4 (the
    // cut's) not updated.
    for x in 0..4 {
        assert_eq!(map.state(&VoxelKey::new(x, 0, 0)), VoxelState::Free, "{x}");
    }
    assert_eq!(map.state(&VoxelKey::new(4, 0, 0)), VoxelState::Unknown);
    assert_eq!(map.stats().occupied, 0);
}

#[test]
fn clamping_bounds_how_long_a_wall_takes_to_disappear() {
    // OctoMap's numbers: hit 0.847, miss -0.405, upper clamp 3.511. A wall hit many times
    // sits at the clamp; 8 see-through scans leave 0.267 (occupied), the 9th -0.138.
    let mut map = LogOddsMap::new(0.1, LogOddsModel::default()).unwrap();
    let wall = VoxelKey::new(10, 0, 0);
    for _ in 0..20 {
        map.insert_scan(&cloud(&[[1.05, 0.05, 0.05]]), &Pose::identity())
            .unwrap();
    }
    let l = map.log_odds(&wall).unwrap();
    assert!((l - logit(0.971)).abs() < 1e-3, "{l}");
    for i in 1..=9 {
        map.insert_scan(&cloud(&[[2.05, 0.05, 0.05]]), &Pose::identity())
            .unwrap();
        let want = if i < 9 {
            VoxelState::Occupied
        } else {
            VoxelState::Free
        };
        assert_eq!(map.state(&wall), want, "after {i} misses");
    }
    // The lower clamp: a voxel freed 100 times sits at logit(0.1192) = -2.0.
    for _ in 0..100 {
        map.insert_scan(&cloud(&[[2.05, 0.05, 0.05]]), &Pose::identity())
            .unwrap();
    }
    let l = map.log_odds(&VoxelKey::new(3, 0, 0)).unwrap();
    assert!((l - logit(0.1192)).abs() < 1e-3, "{l}");
}

#[test]
fn agrees_with_a_plain_reference_of_octomaps_update_over_many_scans() {
    let scene = fixtures::furnished_room(0.05);
    let model = LogOddsModel {
        max_range: 6.0,
        ..LogOddsModel::default()
    };
    let res = 0.1;
    let mut map = LogOddsMap::new(res, model).unwrap();
    let mut reference = Reference {
        res,
        model,
        values: HashMap::new(),
    };
    let mut total = LogOddsInsertStats::default();
    for (x, y, yaw) in [
        (3.0, 3.0, 0.0),
        (6.0, 4.5, 40.0),
        (9.5, 6.5, 200.0),
        (4.0, 6.0, 300.0),
    ] {
        let pose = Pose::from_xyz_ypr(x, y, 1.2, yaw, 0.0, 0.0);
        // Points in range and beyond it (the scene spans 12 m, the range is 6 m).
        let scan = fixtures::scan_of(&scene, &pose, 9.0);
        total.add(&map.insert_scan(&scan, &pose).unwrap());
        reference.insert(&scan, &pose);
    }
    assert!(
        total.truncated > 1000 && total.occupied_updates > 1000,
        "{total:?}"
    );
    assert_eq!(map.len(), reference.values.len());
    let mut counts = HashMap::new();
    for (k, s) in map.voxels() {
        assert_eq!(s, reference.state(&k), "{k:?}");
        *counts.entry(s).or_insert(0usize) += 1;
        // Fixed point within 0.0005 per update of the float value (at most 4 updates).
        let l = map.log_odds(&k).unwrap();
        assert!((l - reference.values[&k]).abs() < 2e-3, "{k:?}: {l}");
    }
    let stats = map.stats();
    assert_eq!(
        (stats.occupied, stats.free),
        (counts[&VoxelState::Occupied], counts[&VoxelState::Free])
    );
    assert!(stats.bytes_per_voxel() > 0.0);
}

#[test]
fn the_map_does_not_depend_on_the_thread_count() {
    let scene = fixtures::hall(0.1);
    let poses = fixtures::hall_trajectory(3, 6.0);
    let build = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut map = LogOddsMap::new(0.1, LogOddsModel::default()).unwrap();
            for p in &poses {
                map.insert_scan(&fixtures::scan_of(&scene, p, 12.0), p)
                    .unwrap();
            }
            sorted(&map)
        })
    };
    let one = build(1);
    assert!(one.len() > 100_000, "{}", one.len());
    assert_eq!(one, build(2));
    assert_eq!(one, build(3));
}

#[test]
fn bt_export_keeps_free_and_occupied_voxels() {
    let scene = fixtures::furnished_room(0.05);
    let pose = Pose::from_xyz_ypr(4.0, 4.0, 1.0, 30.0, 0.0, 0.0);
    let mut map = LogOddsMap::new(0.05, LogOddsModel::default()).unwrap();
    map.insert_scan(&fixtures::scan_of(&scene, &pose, 20.0), &pose)
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("free.bt");
    let written = map.write_bt(&path).unwrap();
    let tree =
        octomap_bt::read_leaves(std::io::BufReader::new(std::fs::File::open(&path).unwrap()))
            .unwrap();
    assert_eq!(tree.stats, written);
    let stats = map.stats();
    assert!(stats.free > 10 * stats.occupied, "{stats:?}");
    assert_eq!(tree.expanded_voxels(), stats.occupied as u64);
    assert_eq!(tree.free_voxels(), stats.free as u64);
    // Free space is pruned: far fewer free leaves than free voxels.
    assert!(
        tree.stats.free_leaves * 4 < stats.free as u64,
        "{:?}",
        tree.stats
    );
    let same = tree.compare(&tree).unwrap();
    assert_eq!(
        (same.both_known, same.agree),
        (map.len() as u64, map.len() as u64)
    );
    // The occupied-only export of the same voxels: the free ones become unknown.
    let occupied: Vec<VoxelKey> = map
        .voxels()
        .filter(|(_, s)| *s == VoxelState::Occupied)
        .map(|(k, _)| k)
        .collect();
    let mut buf = Vec::new();
    octomap_bt::write(&mut buf, 0.05, &occupied).unwrap();
    let only = octomap_bt::read_leaves(&buf[..]).unwrap();
    let c = tree.compare(&only).unwrap();
    assert_eq!(
        (c.both_known, c.occupied_both, c.known_here),
        (
            stats.occupied as u64,
            stats.occupied as u64,
            map.len() as u64
        )
    );
}

#[test]
fn bad_input_is_refused() {
    assert!(LogOddsMap::new(0.0, LogOddsModel::default()).is_err());
    assert!(LogOddsMap::new(f64::NAN, LogOddsModel::default()).is_err());
    let mut map = LogOddsMap::new(0.1, LogOddsModel::default()).unwrap();
    let far = Pose::from_xyz_ypr(1e6, 0.0, 0.0, 0.0, 0.0, 0.0);
    assert!(map.insert_scan(&cloud(&[[1.0, 0.0, 0.0]]), &far).is_err());
    assert!(map.is_empty());
    // Non-finite and out-of-range points are skipped, the rest inserted.
    let s = map
        .insert_scan(
            &cloud(&[[f32::NAN, 0.0, 0.0], [1e9, 0.0, 0.0], [0.55, 0.05, 0.05]]),
            &Pose::identity(),
        )
        .unwrap();
    assert_eq!((s.skipped, s.occupied_updates), (2, 1));
}

#[test]
fn a_scan_beyond_the_brick_limit_is_refused_and_changes_nothing() {
    let mut map = LogOddsMap::new(0.05, LogOddsModel::default()).unwrap();
    map.brick_limit = 2_000;
    map.insert_scan(&cloud(&[[1.0, 0.0, 0.0]]), &Pose::identity())
        .unwrap();
    let before = sorted(&map);
    // 200 rays of 500 m fanning out: far more than 2,000 fresh bricks.
    let far: Vec<[f32; 3]> = (0..200)
        .map(|i| {
            let a = i as f32 * 0.03;
            [500.0 * a.cos(), 500.0 * a.sin(), 3.0]
        })
        .collect();
    let err = map
        .insert_scan(&cloud(&far), &Pose::identity())
        .unwrap_err();
    assert!(matches!(err, Error::TooLarge { .. }), "{err}");
    assert!(err.to_string().contains("resolution"), "{err}");
    assert_eq!(sorted(&map), before);
    // With a maximum range the same scan fits.
    let mut map = LogOddsMap::new(
        0.05,
        LogOddsModel {
            max_range: 2.0,
            ..LogOddsModel::default()
        },
    )
    .unwrap();
    map.brick_limit = 2_000;
    let s = map.insert_scan(&cloud(&far), &Pose::identity()).unwrap();
    assert_eq!(s.truncated, 200);
}
