//! The live map's incremental cost as the network mapper pays it (issue 23): the demo's
//! team (lab, 4 robots × 10 stops, the thesis' degraded odometry, seed 1) sent as the
//! robots send it — each scan its occupancy list at the team's 0.1 m — and placed by a
//! [`LiveTeam`] with the mapper's own parameters ([`live_params`]: refinement points
//! merged at 0.1 m, block normals), record by record in stop order, the waiting records
//! retried after each, as the mapper's loop does. Time per record is the divan time
//! divided by 40; the placed count and the error against the simulator's truth are
//! printed once. (`olmap`'s own `team` bench places the raw clouds with the library's
//! default parameters: a batch map's, not the live mapper's.)
//!
//! `cargo bench -p olmap-net --bench live_map`

use std::sync::OnceLock;

use divan::Bencher;
use olmap::geometry::PoseList;
use olmap::team::{LiveTeam, ScanStore, TeamParams};
use olmap_net::demo_lab;
use olmap_net::mapper::live_params;
use olmap_net::robot::occupancy_store;

fn main() {
    divan::main();
}

/// The team's resolution: what the robots send (`RobotOptions::resolution`'s default).
const RESOLUTION: f64 = 0.1;

/// The demo's team as occupancy-list records, and the truth.
fn records() -> &'static (ScanStore, PoseList) {
    static D: OnceLock<(ScanStore, PoseList)> = OnceLock::new();
    D.get_or_init(|| {
        let data = demo_lab(1, 4, 10).expect("the demo's team simulates");
        let raw = data.to_store().expect("a store");
        let truth = data.truth_list(&raw);
        let store = occupancy_store(&raw, RESOLUTION).expect("occupancy records");
        (store, truth)
    })
}

/// Seconds of one record: its own `add`, and each retry of a waiting scan it made due
/// (each retry places at most one scan: one placement attempt).
struct RecordTimes {
    /// The whole record: its `add` and the retries after it.
    whole: f64,
    /// Each placement attempt alone: the `add`, then every retry.
    attempts: Vec<f64>,
}

/// Every record placed (or left waiting) in stop order; with each record's seconds (its
/// own placement and the retries it made due).
fn place_all(store: &ScanStore) -> (LiveTeam, Vec<RecordTimes>) {
    let mut records: Vec<_> = store.iter().collect();
    records.sort_by_key(|s| (s.seq, s.robot));
    let mut team = LiveTeam::new(live_params(&TeamParams::default())).expect("parameters");
    let mut times = Vec::with_capacity(records.len());
    for scan in &records {
        let start = std::time::Instant::now();
        team.add(scan, &store.robot_name(scan.robot))
            .expect("a record");
        let mut attempts = vec![start.elapsed().as_secs_f64()];
        for _ in 0..100 {
            if !team.has_due() {
                break;
            }
            let retry = std::time::Instant::now();
            team.retry_waiting(1).expect("a retry");
            attempts.push(retry.elapsed().as_secs_f64());
        }
        times.push(RecordTimes {
            whole: start.elapsed().as_secs_f64(),
            attempts,
        });
    }
    (team, times)
}

/// The median, 95th percentile and largest of `seconds`.
fn spread(mut seconds: Vec<f64>) -> [f64; 3] {
    seconds.sort_by(f64::total_cmp);
    let at = |q: f64| seconds[((seconds.len() - 1) as f64 * q).round() as usize];
    [at(0.5), at(0.95), at(1.0)]
}

/// The 40 records placed one by one by the live mapper's `LiveTeam`.
#[divan::bench(sample_count = 3, sample_size = 1)]
fn live_map_record_by_record(bencher: Bencher) {
    let (store, truth) = records();
    static PRINTED: OnceLock<()> = OnceLock::new();
    PRINTED.get_or_init(|| {
        let (team, times) = place_all(store);
        let e = olmap::mapping::evaluate(&team.poses(), truth)
            .expect("names match")
            .summary;
        let attempts: Vec<f64> = times.iter().flat_map(|t| t.attempts.clone()).collect();
        let n_attempts = attempts.len();
        let whole = spread(times.iter().map(|t| t.whole).collect());
        let one = spread(attempts);
        eprintln!(
            "live map (0.1 m records, live parameters): {}/{} placed, {} registrations, \
             mean {:.3} m, max {:.3} m; a record with the retries it made due: median {:.3} \
             s, 95th percentile {:.3} s, slowest {:.3} s; one placement attempt ({} adds \
             and retries): median {:.3} s, 95th percentile {:.3} s, slowest {:.3} s",
            team.placements().len(),
            store.len(),
            team.mapper().registrations(),
            e.translation_m[0],
            e.translation_m[2],
            whole[0],
            whole[1],
            whole[2],
            n_attempts,
            one[0],
            one[1],
            one[2]
        );
    });
    bencher
        .counter(divan::counter::ItemsCount::new(store.len()))
        .bench(|| place_all(store).0);
}
