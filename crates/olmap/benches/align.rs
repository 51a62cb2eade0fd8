//! Global registration on the shared real data: the multi-resolution search and the ICP
//! refinement of each pair, on one thread and on all threads.
//!
//! `cargo bench -p olmap --bench align`. The accuracy of each pair is printed once.

use std::sync::OnceLock;

use divan::Bencher;
use olmap::align::icp::{refine, IcpParams};
use olmap::align::{self, Dof, RegisterParams, SearchMode, SearchParams};
use olmap::cloud::PointCloud;
use olmap::geometry::{Pose, PoseError};
use olmap::io::{self, ReadOptions};

fn main() {
    divan::main();
}

/// (name, source, target, reference T_target_source, dof, finest resolution)
type Pair = (&'static str, PointCloud, PointCloud, Pose, Dof, f64);

fn pairs() -> &'static [Pair] {
    static P: OnceLock<Vec<Pair>> = OnceLock::new();
    P.get_or_init(|| {
        let Some(d) = olmap::test_data::dir() else {
            return Vec::new();
        };
        let valid = ReadOptions {
            uos_valid_only: true,
            ..Default::default()
        };
        let tdk: Vec<PointCloud> = (0..3)
            .map(|i| {
                io::read_cloud_with(d.join(format!("3dtk_dat/scan00{i}.3d")), &valid)
                    .unwrap()
                    .cloud
            })
            .collect();
        let refs = olmap::test_data::threedtk_reference().expect("the data folder was found");
        let rel = |s: usize, t: usize| refs.poses[t].pose.inverse() * refs.poses[s].pose;
        let car = |n: &str| {
            io::read_cloud(d.join("libpointmatcher_car").join(n))
                .unwrap()
                .cloud
        };
        let gt = *io::csv::read_pose_table_path(d.join("libpointmatcher_car/carCloudList.csv"))
            .unwrap()
            .get("car_cloud401.csv")
            .unwrap();
        vec![
            (
                "3dtk_001-000",
                tdk[1].clone(),
                tdk[0].clone(),
                rel(1, 0),
                Dof::XyzYaw,
                0.1,
            ),
            (
                "3dtk_002-000",
                tdk[2].clone(),
                tdk[0].clone(),
                rel(2, 0),
                Dof::XyzYaw,
                0.1,
            ),
            (
                "3dtk_002-001",
                tdk[2].clone(),
                tdk[1].clone(),
                rel(2, 1),
                Dof::XyzYaw,
                0.1,
            ),
            (
                "car_401-400",
                car("car_cloud401.csv"),
                car("car_cloud400.csv"),
                gt,
                Dof::six_dof(),
                // Outdoor, ranges to 74 m: a 0.2 m finest cell.
                0.2,
            ),
        ]
    })
}

const NAMES: [&str; 4] = [
    "3dtk_001-000",
    "3dtk_002-000",
    "3dtk_002-001",
    "car_401-400",
];

fn pair(name: &str) -> Option<&'static Pair> {
    pairs().iter().find(|p| p.0 == name)
}

fn params(p: &Pair) -> RegisterParams {
    RegisterParams {
        search: SearchParams {
            dof: p.4,
            resolution: p.5,
            ..Default::default()
        },
        refine: Some(IcpParams::default()),
        trust: Default::default(),
    }
}

fn print_accuracy_once(p: &Pair) {
    static DONE: std::sync::Mutex<Vec<&'static str>> = std::sync::Mutex::new(Vec::new());
    let mut done = DONE.lock().unwrap();
    if done.contains(&p.0) {
        return;
    }
    done.push(p.0);
    let r = align::register(&p.1, &p.2, &params(p)).unwrap();
    let e = PoseError::between(&r.pose, &p.3);
    eprintln!(
        "[{}] {} poses searched; error {:.3} m / {:.3} deg (dx {:.3} dy {:.3} dz {:.3}, yaw {:.2} pitch {:.2} roll {:.2}); trusted {}",
        p.0, r.search.evaluated, e.translation_m, e.rotation_deg, e.dx_m, e.dy_m, e.dz_m, e.yaw_deg, e.pitch_deg, e.roll_deg, r.trusted
    );
}

fn one_thread() -> &'static rayon::ThreadPool {
    static POOL: OnceLock<rayon::ThreadPool> = OnceLock::new();
    POOL.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
    })
}

/// Search + refinement, all threads.
#[divan::bench(args = NAMES, sample_count = 5, sample_size = 1)]
fn register_all_threads(bencher: Bencher, name: &str) {
    let Some(p) = pair(name) else { return };
    print_accuracy_once(p);
    bencher.bench(|| align::register(&p.1, &p.2, &params(p)).unwrap());
}

/// Search + refinement, one thread.
#[divan::bench(args = NAMES, sample_count = 5, sample_size = 1)]
fn register_one_thread(bencher: Bencher, name: &str) {
    let Some(p) = pair(name) else { return };
    bencher.bench(|| one_thread().install(|| align::register(&p.1, &p.2, &params(p)).unwrap()));
}

/// The global search alone (no refinement), all threads.
#[divan::bench(args = NAMES, sample_count = 5, sample_size = 1)]
fn search_all_threads(bencher: Bencher, name: &str) {
    let Some(p) = pair(name) else { return };
    let mut prm = params(p);
    prm.refine = None;
    bencher.bench(|| align::register(&p.1, &p.2, &prm).unwrap());
}

/// The refinement alone, from the search's pose, all threads.
#[divan::bench(args = NAMES, sample_count = 5, sample_size = 1)]
fn refine_all_threads(bencher: Bencher, name: &str) {
    let Some(p) = pair(name) else { return };
    let mut prm = params(p);
    prm.refine = None;
    let start = align::register(&p.1, &p.2, &prm).unwrap().pose;
    bencher.bench(|| refine(&p.1, &p.2, &start, &IcpParams::default()).unwrap());
}

fn thesis() -> &'static olmap::sim::LocalisationBenchmark {
    static B: OnceLock<olmap::sim::LocalisationBenchmark> = OnceLock::new();
    B.get_or_init(|| olmap::sim::thesis_localisation(7, 16).unwrap())
}

/// The thesis benchmark (§5.4; `sim::thesis_localisation`, 16 map scans: 187,730 voxels at
/// 0.02 m over 210 m^2, whole map, every heading): the multi-resolution search, all threads.
/// The exact search does not finish in minutes here (README).
#[divan::bench(sample_count = 5, sample_size = 1)]
fn thesis_localisation(bencher: Bencher) {
    let b = thesis();
    let p = RegisterParams {
        search: b.params.clone(),
        refine: None,
        trust: Default::default(),
    };
    bencher.bench(|| align::localize(&b.scan, &b.map, &p).unwrap());
}

/// Both search modes and the exhaustive search on a small global problem (room scans at
/// 0.3 m, every heading): the ratio of the modes where the exact search is practical.
#[divan::bench(args = ["multires", "exact", "exhaustive"], sample_count = 10)]
fn small_global(bencher: Bencher, mode: &str) {
    let pts = olmap::fixtures::furnished_room(0.05);
    let t_target = Pose::from_xyz_ypr(6.0, 4.5, 1.2, 0.4, 0.0, 0.0);
    let motion = Pose::from_xyz_ypr(0.9, -0.4, 0.0, 2.0, 0.0, 0.0);
    let target = olmap::fixtures::scan_of(&pts, &t_target, 4.0);
    let source = olmap::fixtures::scan_of(&pts, &(t_target * motion), 4.0);
    let params = SearchParams {
        resolution: 0.3,
        levels: 3,
        dof: Dof::XyYaw,
        max_scan_voxels: 300,
        max_range: 4.0,
        search: if mode == "exact" {
            SearchMode::Exact
        } else {
            SearchMode::MultiResolution
        },
        ..Default::default()
    };
    let target = align::SearchTarget::from_cloud(&target, 0.3, 3).unwrap();
    bencher.bench(|| {
        if mode == "exhaustive" {
            align::exhaustive_search(&source, &target, &params).unwrap()
        } else {
            align::global_search(&source, &target, &params).unwrap()
        }
    });
}
