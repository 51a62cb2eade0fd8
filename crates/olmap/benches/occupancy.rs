//! Occupancy-list throughput on the shared real data: ray-traced insertion (points/s) at
//! 0.05 m and 0.1 m with a 30 m maximum range, on one thread and on all threads; endpoint-only
//! insertion as the floor; memory per stored voxel is printed once.
//!
//! `cargo bench -p olmap --bench occupancy`

use std::sync::OnceLock;

use divan::counter::ItemsCount;
use divan::Bencher;
use olmap::cloud::PointCloud;
use olmap::geometry::Pose;
use olmap::io::{self, ReadOptions};
use olmap::occupancy::{OccupancyList, SensorModel};

fn main() {
    divan::main();
}

/// (name, scans with their map poses).
type Dataset = (&'static str, Vec<(PointCloud, Pose)>);

fn datasets() -> &'static [Dataset] {
    static DATA: OnceLock<Vec<Dataset>> = OnceLock::new();
    DATA.get_or_init(|| {
        let Some(dir) = olmap::test_data::dir() else {
            return Vec::new();
        };
        let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
        let valid = ReadOptions {
            uos_valid_only: true,
            ..Default::default()
        };
        let tdk: Vec<_> = (0..3)
            .map(|i| {
                let c = io::read_cloud_with(dir.join(format!("3dtk_dat/scan00{i}.3d")), &valid)
                    .unwrap();
                (c.cloud, refs.poses[i].pose)
            })
            .collect();
        let dat = io::read_cloud(dir.join("octomap_share_data/scan.dat"))
            .unwrap()
            .cloud;
        vec![
            ("3dtk_000-002", tdk),
            ("scan.dat", vec![(dat, Pose::identity())]),
        ]
    })
}

fn points(set: &Dataset) -> usize {
    set.1.iter().map(|(c, _)| c.len()).sum()
}

fn build(set: &Dataset, res: f64) -> OccupancyList {
    let mut map = OccupancyList::new(res).unwrap();
    for (cloud, pose) in &set.1 {
        map.insert_scan(cloud, pose, &SensorModel::default())
            .unwrap();
    }
    map
}

const CASES: [(&str, f64); 4] = [
    ("3dtk_000-002", 0.05),
    ("3dtk_000-002", 0.10),
    ("scan.dat", 0.05),
    ("scan.dat", 0.10),
];

fn case_names() -> [&'static str; 4] {
    ["3dtk@0.05", "3dtk@0.10", "scan.dat@0.05", "scan.dat@0.10"]
}

fn find(name: &str) -> Option<(&'static Dataset, f64)> {
    let i = case_names().iter().position(|n| *n == name)?;
    let (set, res) = CASES[i];
    datasets().iter().find(|d| d.0 == set).map(|d| (d, res))
}

fn report_memory(set: &Dataset, res: f64) {
    static ONCE: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());
    let key = format!("{}@{res}", set.0);
    let mut done = ONCE.lock().unwrap();
    if !done.contains(&key) {
        let map = build(set, res);
        let s = map.stats();
        eprintln!(
            "[{key}] {} voxels, {:.1} bytes/voxel in memory",
            s.voxels,
            s.bytes_per_voxel()
        );
        done.push(key);
    }
}

/// Ray-traced insertion on all threads of the rayon pool.
#[divan::bench(args = case_names(), sample_count = 5, sample_size = 1)]
fn raytrace_all_threads(bencher: Bencher, case: &str) {
    let Some((set, res)) = find(case) else { return };
    report_memory(set, res);
    bencher
        .counter(ItemsCount::new(points(set)))
        .bench(|| build(set, res));
}

/// Ray-traced insertion on one thread.
#[divan::bench(args = case_names(), sample_count = 5, sample_size = 1)]
fn raytrace_one_thread(bencher: Bencher, case: &str) {
    let Some((set, res)) = find(case) else { return };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    bencher
        .counter(ItemsCount::new(points(set)))
        .bench(|| pool.install(|| build(set, res)));
}

/// Endpoints only (no ray tracing): the floor.
#[divan::bench(args = case_names(), sample_count = 5, sample_size = 1)]
fn endpoints_only(bencher: Bencher, case: &str) {
    let Some((set, res)) = find(case) else { return };
    bencher.counter(ItemsCount::new(points(set))).bench(|| {
        let mut map = OccupancyList::new(res).unwrap();
        for (cloud, pose) in &set.1 {
            map.add_points(cloud, pose, 1);
        }
        map
    });
}

/// A ~200,000-voxel map and a 5,000-voxel scan at 0.02 m, both from real scans: the map is
/// the 3DTK scans 000-002 at their reference poses plus OctoMap's scan.dat (endpoints), the
/// scan every k-th voxel of 3DTK scan001.
fn overlap_problem() -> Option<&'static (OccupancyList, OccupancyList, Pose)> {
    static P: OnceLock<Option<(OccupancyList, OccupancyList, Pose)>> = OnceLock::new();
    P.get_or_init(|| {
        let sets = datasets();
        let tdk = &sets.iter().find(|d| d.0 == "3dtk_000-002")?.1;
        let dat = &sets.iter().find(|d| d.0 == "scan.dat")?.1;
        let res = 0.02;
        let mut map = OccupancyList::new(res).unwrap();
        for (cloud, pose) in tdk.iter().chain(dat) {
            map.add_points(cloud, pose, 1);
        }
        let full = OccupancyList::from_cloud(&tdk[1].0, res).unwrap();
        let sorted = full.sorted();
        let step = sorted.len() / 5000;
        let mut scan = OccupancyList::new(res).unwrap();
        for (k, c) in sorted.iter().step_by(step).take(5000) {
            scan.set(*k, *c as u32).unwrap();
        }
        eprintln!(
            "[overlap] map {} voxels, scan {} voxels",
            map.len(),
            scan.len()
        );
        Some((map, scan, tdk[1].1))
    })
    .as_ref()
}

/// Overlap evaluations (5,000-voxel scan against the ~200,000-voxel map), one thread.
#[divan::bench(sample_count = 10, sample_size = 20)]
fn overlap_5k_scan_200k_map(bencher: Bencher) {
    let Some((map, scan, pose)) = overlap_problem() else {
        return;
    };
    let mut i = 0u32;
    bencher.counter(ItemsCount::new(1usize)).bench_local(|| {
        i = i.wrapping_add(1);
        // A slightly different pose each call, as in a search.
        let d = Pose::from_xyz_ypr(
            0.01 * (i % 7) as f64,
            0.0,
            0.0,
            0.001 * (i % 5) as f64,
            0.0,
            0.0,
        );
        map.overlap(scan, &(d * *pose)).unwrap()
    });
}

/// The same evaluations with the scan pre-rotated: integer key offsets only (§5.3.3).
#[divan::bench(sample_count = 10, sample_size = 20)]
fn overlap_keys_5k_scan_200k_map(bencher: Bencher) {
    let Some((map, scan, pose)) = overlap_problem() else {
        return;
    };
    let keys = scan.transformed_keys(pose);
    let mut i = 0i32;
    bencher.counter(ItemsCount::new(1usize)).bench_local(|| {
        i = i.wrapping_add(1);
        map.overlap_keys(&keys, [i % 7 - 3, i % 5 - 2, 0])
    });
}
