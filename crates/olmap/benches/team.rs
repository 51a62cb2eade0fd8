//! Cooperative mapping on simulated data: the search of one sighted robot's scan along
//! the sighting's locus (thesis (6.2)) against the global search of the same scan in the
//! same target, a small team map against the same scans mapped robot by robot, and the
//! demo's team placed record by record (the live map's incremental cost).
//!
//! `cargo bench -p olmap --bench team`. The poses each search evaluates and its error are
//! printed once.

use std::sync::OnceLock;

use divan::Bencher;
use olmap::align::{global_search, Locus, Region, SearchParams, SearchTarget};
use olmap::cloud::PointCloud;
use olmap::geometry::{Pose, PoseError};
use olmap::sim::{simulate, RobotModel, SimConfig, SimDataset};
use olmap::team::{map_solo, map_team, TeamParams};

fn main() {
    divan::main();
}

fn data() -> &'static SimDataset {
    static D: OnceLock<SimDataset> = OnceLock::new();
    D.get_or_init(|| simulate(&SimConfig::demo_lab(2, 3, 4), |_, _| {}).unwrap())
}

/// (target = the observer's scan, source = the seen robot's scan in its 0.1-2.8 m band,
/// the (6.2) locus, the true pose of the source in the target).
type Case = (SearchTarget, PointCloud, Locus, Pose);

fn case() -> &'static Case {
    static C: OnceLock<Case> = OnceLock::new();
    C.get_or_init(|| {
        let d = data();
        let g = d.sightings.first().expect("a sighting");
        let (a, b, k) = (g.observer, g.target, g.stop);
        let target = SearchTarget::from_cloud(&d.robots[a].scans[k], 0.1, 5).unwrap();
        let source = d.robots[b].scans[k].z_band(0.1, 2.8);
        let m = RobotModel::default().beacon_center();
        let locus = Locus::seen_at([g.beacon.x, g.beacon.y, g.beacon.z], [m.x, m.y, m.z]);
        let truth = d.robots[a].truth[k].inverse() * d.robots[b].truth[k];
        (target, source, locus, truth)
    })
}

fn search(region: Region) -> olmap::align::Alignment {
    let (target, source, _, _) = case();
    let params = SearchParams {
        region,
        ..Default::default()
    };
    global_search(source, target, &params).unwrap()
}

fn region(name: &str) -> Region {
    match name {
        "locus" => Region::Locus(case().2),
        _ => Region::Global,
    }
}

/// One scan searched along the locus of a sighting, or globally.
#[divan::bench(args = ["locus", "global"], sample_count = 10)]
fn search_sighted_scan(bencher: Bencher, name: &str) {
    let r = search(region(name));
    let e = PoseError::between(&r.pose, &case().3);
    eprintln!(
        "[{name}] {} poses evaluated, overlap {}, error {:.3} m / {:.2} deg",
        r.evaluated, r.overlap, e.translation_m, e.rotation_deg
    );
    bencher.bench(|| search(region(name)));
}

/// Mapping 3 robots x 4 scans: as a team (sightings, clearing) or every robot alone.
#[divan::bench(args = ["team", "solo"], sample_count = 2, sample_size = 1)]
fn map_three_robots(bencher: Bencher, how: &str) {
    let store = data().to_store().unwrap();
    let params = TeamParams::default();
    bencher.bench(|| match how {
        "team" => map_team(&store, &params, |_, _| {})
            .unwrap()
            .build
            .placed
            .len(),
        _ => map_solo(&store, &params, |_, _| {})
            .unwrap()
            .iter()
            .map(|(_, m)| m.build.placed.len())
            .sum(),
    });
}

/// The demo's team (lab seed 1, 4 robots x 10 stops, degraded odometry), as a store.
fn demo_team() -> &'static (olmap::team::ScanStore, olmap::geometry::PoseList) {
    static D: OnceLock<(olmap::team::ScanStore, olmap::geometry::PoseList)> = OnceLock::new();
    D.get_or_init(|| {
        let data = simulate(&SimConfig::demo_lab(1, 4, 10), |_, _| {}).unwrap();
        let store = data.to_store().unwrap();
        let truth = data.truth_list(&store);
        (store, truth)
    })
}

/// Incremental placement with the library's default parameters: the demo's 40 records (raw
/// clouds) given to a `LiveTeam` stop by stop, waiting scans retried after each; time per
/// record is the divan time divided by 40. The placed count and the error against the
/// truth are printed once. The network mapper's own cost (0.1 m occupancy records, its
/// live parameters) is `olmap-net`'s `live_map` bench.
#[divan::bench(sample_count = 3, sample_size = 1)]
fn live_team_record_by_record(bencher: Bencher) {
    let (store, truth) = demo_team();
    let mut records: Vec<_> = store.iter().collect();
    records.sort_by_key(|s| (s.seq, s.robot));
    let run = || {
        let mut team = olmap::team::LiveTeam::new(TeamParams::default()).unwrap();
        for scan in &records {
            team.add(scan, &store.robot_name(scan.robot)).unwrap();
            for _ in 0..100 {
                if !team.has_due() {
                    break;
                }
                team.retry_waiting(1).unwrap();
            }
        }
        team
    };
    static PRINTED: OnceLock<()> = OnceLock::new();
    PRINTED.get_or_init(|| {
        let team = run();
        let e = olmap::mapping::evaluate(&team.poses(), truth)
            .unwrap()
            .summary;
        eprintln!(
            "live team: {}/{} placed, {} registrations, mean {:.3} m, max {:.3} m",
            team.placements().len(),
            records.len(),
            team.mapper().registrations(),
            e.translation_m[0],
            e.translation_m[2]
        );
    });
    bencher
        .counter(divan::counter::ItemsCount::new(records.len()))
        .bench(run);
}
