//! Tests of the log-odds map against OctoMap's semantics, written out independently.

use nalgebra::Point3;

use super::*;
use crate::cloud::PointCloud;
use crate::geometry::Pose;

fn cloud(points: &[[f32; 3]]) -> PointCloud {
    PointCloud::from_points(
        points
            .iter()
            .map(|p| Point3::new(p[0], p[1], p[2]))
            .collect(),
    )
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

#[test]
fn the_brick_limit_holds_across_threads() {
    // 6,000 rays of 300 m fanning out (several chunks on several threads) against a
    // limit of 3,000 bricks: refused, whatever the thread count, the map unchanged.
    let far: Vec<[f32; 3]> = (0..6000)
        .map(|i| {
            let a = i as f32 * 0.001;
            [300.0 * a.cos(), 300.0 * a.sin(), (i % 7) as f32]
        })
        .collect();
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut map = LogOddsMap::new(0.1, LogOddsModel::default()).unwrap();
            map.brick_limit = 3_000;
            let err = map
                .insert_scan(&cloud(&far), &Pose::identity())
                .unwrap_err();
            assert!(matches!(err, Error::TooLarge { .. }), "{threads}: {err}");
            assert!(map.is_empty() && map.stats().bricks == 0);
        });
    }
}
