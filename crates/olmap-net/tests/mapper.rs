//! A mapper on the network maps exactly what `olmap team` maps from the same records, and
//! about as accurately as `olmap team` on the raw scans.

mod common;

use std::time::{Duration, Instant};

use common::{free_port, node_opts, store_bytes};
use olmap::sim::{simulate, OdometryNoise, SimConfig, WorldKind};
use olmap::team::{run_team_pipeline, TeamJob, TeamParams};
use olmap_net::mapper::{Mapper, MapperOptions};
use olmap_net::robot::occupancy_store;
use olmap_net::{FaultPlan, Node};

/// The team's finest resolution: what robots send.
const RESOLUTION: f64 = 0.1;

#[test]
fn the_network_mapper_maps_what_olmap_team_maps_from_the_same_records() {
    let data = simulate(
        &SimConfig {
            world: WorldKind::Lab,
            seed: 2,
            robots: 2,
            stops: 3,
            odometry: OdometryNoise::degraded(),
            ..Default::default()
        },
        |_, _| {},
    )
    .unwrap();
    let raw = data.to_store().unwrap();
    let truth = data.truth_list(&raw);
    let records = occupancy_store(&raw, RESOLUTION).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let out = dir.path().join("out");
    let faults = |seed| FaultPlan {
        drop: 0.3,
        duplicate: 0.1,
        reorder: 4,
        seed,
        partitions: Vec::new(),
    };
    let mapper = Mapper::start(MapperOptions {
        node: node_opts(
            dir.path(),
            "mapper",
            "mapper",
            "maptest",
            Some(port),
            &[],
            faults(1),
        ),
        out: out.clone(),
        params: TeamParams::default(),
        truth: Some(truth.clone()),
        settle: Duration::from_millis(100),
    })
    .unwrap();
    let mut robots = Vec::new();
    for r in records.robots() {
        let name = records.robot_name(r);
        let node = Node::start(node_opts(
            dir.path(),
            &name,
            "robot",
            "maptest",
            None,
            &[port],
            faults(10 + r as u64),
        ))
        .unwrap();
        std::thread::sleep(Duration::from_millis(200));
        for scan in records.scans_of(r) {
            node.record(&name, scan.clone()).unwrap();
        }
        robots.push(node);
    }
    assert!(
        mapper
            .node()
            .wait_for(records.len(), Duration::from_secs(60)),
        "the mapper holds {}/{}",
        mapper.node().held(),
        records.len()
    );
    assert_eq!(
        store_bytes(&mapper.node().store_snapshot()),
        store_bytes(&records)
    );
    // The live map catches up: every record placed incrementally, with latency figures,
    // each live pose within a map voxel (0.1 m) of the truth.
    let deadline = Instant::now() + Duration::from_secs(600);
    while mapper.node().status().placed < records.len() as u64 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(200));
    }
    let status = mapper.node().status();
    assert_eq!(status.placed, records.len() as u64, "{status:?}");
    assert_eq!(status.mapped_records, records.len() as u64, "{status:?}");
    assert!(
        status.latency_ms.is_some(),
        "no latency figures: {status:?}"
    );
    let live = olmap::mapping::evaluate(&mapper.live_poses(), &truth).unwrap();
    assert_eq!(live.summary.scans, records.len());
    assert!(
        live.summary.translation_m[2] <= RESOLUTION,
        "{:?}",
        live.summary
    );

    let written = mapper.write_outputs().unwrap();
    assert_eq!(written.records, records.len());
    for name in [
        "team.olm",
        "team_poses.txt",
        "team.store",
        "report.json",
        "net.json",
    ] {
        assert!(out.join(name).is_file(), "{name} missing");
    }
    // `olmap team` on the same records, in one process: the same bytes.
    let single = dir.path().join("single");
    let stored = olmap::team::ScanStore::read(out.join("team.store")).unwrap();
    assert_eq!(store_bytes(&stored), store_bytes(&records));
    let one = run_team_pipeline(
        &TeamJob {
            store: &stored,
            truth: Some(&truth),
            params: &TeamParams::default(),
            out: &single,
            solo: false,
        },
        &mut |_, _, _| {},
    )
    .unwrap();
    for name in ["team.olm", "team_poses.txt"] {
        assert_eq!(
            std::fs::read(out.join(name)).unwrap(),
            std::fs::read(single.join(name)).unwrap(),
            "{name} differs from olmap team's"
        );
    }
    // As accurate as the team on the raw scans: the occupancy list moves each point by at
    // most half a voxel diagonal, so no placed scan may be worse by more than that.
    let raw_run = run_team_pipeline(
        &TeamJob {
            store: &raw,
            truth: Some(&truth),
            params: &TeamParams::default(),
            out: &dir.path().join("raw"),
            solo: false,
        },
        &mut |_, _, _| {},
    )
    .unwrap();
    let net_eval = one.report.evaluation.team.clone().unwrap();
    let raw_eval = raw_run.report.evaluation.team.clone().unwrap();
    eprintln!(
        "occupancy lists at {RESOLUTION} m: placed {}/{} mean {:.3} max {:.3} m; raw scans: placed {}/{} mean {:.3} max {:.3} m",
        net_eval.placed, net_eval.scans, net_eval.mean_m, net_eval.max_m,
        raw_eval.placed, raw_eval.scans, raw_eval.mean_m, raw_eval.max_m
    );
    let half_diagonal = RESOLUTION * 3f64.sqrt() / 2.0;
    assert_eq!(net_eval.placed, raw_eval.placed);
    assert!(net_eval.max_m <= raw_eval.max_m + half_diagonal);
    for n in robots {
        n.close();
    }
    mapper.close();
}
