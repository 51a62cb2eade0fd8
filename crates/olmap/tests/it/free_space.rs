//! The free-space map (`occupancy::LogOddsMap`) on simulated scenes: OctoMap's update
//! written out independently, thread-count independence, `.bt` export with free nodes.

use std::collections::{HashMap, HashSet};

use olmap::cloud::PointCloud;
use olmap::fixtures;
use olmap::geometry::{Pose, VoxelKey};
use olmap::io::octomap_bt;
use olmap::occupancy::{logit, LogOddsInsertStats, LogOddsMap, LogOddsModel, VoxelRay, VoxelState};

fn sorted(map: &LogOddsMap) -> Vec<(VoxelKey, VoxelState)> {
    let mut v: Vec<_> = map.voxels().collect();
    v.sort_unstable_by_key(|(k, _)| (k.x, k.y, k.z));
    v
}

/// OctoMap's `computeUpdate` + `updateNode` with hash sets, one scan at a time, with its
/// `f32` log-odds.
struct Reference {
    res: f64,
    model: LogOddsModel,
    values: HashMap<VoxelKey, f32>,
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
        let f = |p: f64| logit(p) as f32;
        let (lo, hi) = (f(self.model.clamp_min), f(self.model.clamp_max));
        for (keys, delta) in [
            (
                free.difference(&occupied).copied().collect::<Vec<_>>(),
                f(self.model.prob_miss),
            ),
            (occupied.into_iter().collect(), f(self.model.prob_hit)),
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
            Some(&v) if v >= logit(self.model.occupancy_threshold) as f32 => VoxelState::Occupied,
            Some(_) => VoxelState::Free,
        }
    }
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
    // Six rounds from four places: voxels get long runs of hits and misses, clamped and
    // not, where fixed-point or reordered sums would drift from OctoMap's.
    let places = [
        (3.0, 3.0, 0.0),
        (6.0, 4.5, 40.0),
        (9.5, 6.5, 200.0),
        (4.0, 6.0, 300.0),
    ];
    for (i, &(x, y, yaw)) in places.iter().cycle().take(24).enumerate() {
        let j = i as f64;
        let (x, y, yaw) = (x + 0.013 * j, y - 0.007 * j, yaw + 1.5 * j);
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
        // OctoMap's arithmetic, bit for bit.
        assert_eq!(
            map.log_odds(&k),
            Some(f64::from(reference.values[&k])),
            "{k:?}"
        );
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
