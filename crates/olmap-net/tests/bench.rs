//! The network benchmark end to end on loopback, small: three robots publishing out of step
//! to a mapper in one process (127.0.0.1 only, a free port, bounded).

use std::time::Duration;

use olmap_net::bench::{run_net_bench, NetBenchOptions};

/// Seed 1's lab team, 3 robots x 3 stops, publishing out of step at 2 stops/s, bounded at
/// two minutes.
fn three_robots_out_of_step() -> NetBenchOptions {
    NetBenchOptions {
        robots: 3,
        stops: 3,
        rate: 2.0,
        timeout: Duration::from_secs(120),
        staggered: true,
        ..Default::default()
    }
}

/// Every record published is placed, the lists are far smaller than the raw clouds, the
/// latencies are ordered and span no longer than the run, and the report says the robots
/// were out of step.
#[test]
fn robots_out_of_step_are_all_placed_with_latencies() {
    let opts = three_robots_out_of_step();
    let mut stages = Vec::new();
    let r = run_net_bench(&opts, |s| stages.push(s.to_string())).unwrap();
    assert!(r.staggered);
    assert_eq!((r.robots, r.stops), (3, 3));
    assert_eq!(r.published, 9, "{r:?}");
    // (Seed 1: every robot's first records are tied by sightings within three stops.)
    assert_eq!(r.placed, 9, "{r:?}");
    // A 0.1 m occupancy list of a lab scan is several times smaller than the raw cloud.
    assert!(r.list_bytes_per_scan * 3.0 < r.raw_bytes_per_scan, "{r:?}");
    let [p50, p95, max] = r.latency_ms.expect("latencies");
    assert!(0.0 < p50 && p50 <= p95 && p95 <= max, "{r:?}");
    // No record waits longer than the run itself took.
    assert!(max <= 1000.0 * r.wall_s + 1.0, "{r:?}");
    assert!(
        stages.iter().any(|s| s.contains("publishing")),
        "{stages:?}"
    );
}

/// A mapper that reads records in batches (it waits 1.2 s after each arrival, as a busy
/// mapping thread would, while the robots publish every 0.5 s) builds the live map a
/// mapper reading them one by one does: all 9 placed. On seed 1 robot 1 is tied to the
/// map only by its first scan's sighting of robot 2; before the mapping thread retried the
/// scans each record made due before adding the next, that registration was tried against
/// the map grown by the whole batch, failed (the refinement slid along the lab's desks), and
/// robot 1's three records waited for good (6 of 9 placed).
#[test]
fn a_mapper_reading_records_in_batches_places_them_as_one_reading_them_singly() {
    let opts = NetBenchOptions {
        settle: Duration::from_millis(1200),
        ..three_robots_out_of_step()
    };
    let r = run_net_bench(&opts, |_| {}).unwrap();
    assert_eq!(r.published, 9, "{r:?}");
    assert_eq!(r.placed, 9, "{r:?}");
}
