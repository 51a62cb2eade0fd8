//! Stores converge over loopback Zenoh whatever the network does: seeded drop,
//! duplication, reordering, partitions that heal, a robot joining late, a mapper closed and
//! reopened from its store. Every node holds every record at the end, byte-identical to the
//! union of the robots' stores.

mod common;

use std::time::{Duration, Instant};

use common::{free_port, node_opts, record, store_bytes};
use olmap::team::ScanStore;
use olmap_net::{FaultPlan, Node};

const ROBOTS: u32 = 4;
const SCANS: u32 = 8;
const POINTS: usize = 400;

/// One fault schedule of the test.
struct Schedule {
    name: &'static str,
    plan: FaultPlan,
    /// A robot (by index) that starts only after the others have recorded everything.
    late: Option<u32>,
    /// Close the mapper after this many robots have recorded, and reopen it from its store.
    restart_mapper_after: Option<u32>,
    /// A robot (by index) that leaves half way through its stops and comes back on its
    /// store.
    comes_back: Option<u32>,
}

fn plan(drop: f64, duplicate: f64, reorder: usize, seed: u64) -> FaultPlan {
    FaultPlan {
        drop,
        duplicate,
        reorder,
        seed,
        partitions: Vec::new(),
    }
}

fn schedules() -> Vec<Schedule> {
    let s = |name, plan, late, restart_mapper_after| Schedule {
        name,
        plan,
        late,
        restart_mapper_after,
        comes_back: None,
    };
    let partition = |mut p: FaultPlan, a: u64, b: u64| {
        p.partitions = vec![(Duration::from_millis(a), Duration::from_millis(b))];
        p
    };
    vec![
        s("clean", FaultPlan::default(), None, None),
        s("drop 20 %", plan(0.2, 0.0, 0, 1), None, None),
        s("drop 40 %", plan(0.4, 0.0, 0, 2), None, None),
        s("duplicate 30 %", plan(0.0, 0.3, 0, 3), None, None),
        s("reorder 8", plan(0.0, 0.0, 8, 4), None, None),
        s(
            "drop 30 %, dup 10 %, reorder 8",
            plan(0.3, 0.1, 8, 5),
            None,
            None,
        ),
        s(
            "partition 0.1-1.5 s, healed",
            partition(plan(0.1, 0.0, 0, 6), 100, 1500),
            None,
            None,
        ),
        s(
            "drop 40 %, partition, late robot",
            partition(plan(0.4, 0.1, 4, 7), 0, 800),
            Some(3),
            None,
        ),
        s("late robot, drop 20 %", plan(0.2, 0.0, 0, 8), Some(1), None),
        s(
            "drop 40 %, dup 20 %, reorder 16",
            plan(0.4, 0.2, 16, 9),
            None,
            None,
        ),
        s(
            "mapper closed and reopened, drop 20 %",
            plan(0.2, 0.1, 4, 10),
            None,
            Some(2),
        ),
        Schedule {
            comes_back: Some(2),
            ..s(
                "robot leaves and comes back, drop 30 %",
                plan(0.3, 0.0, 0, 11),
                None,
                None,
            )
        },
    ]
}

fn run(schedule: &Schedule, index: usize) {
    let dir = tempfile::tempdir().unwrap();
    let team = format!("conv{index}");
    let port = free_port();
    let mut union = ScanStore::new();
    for r in 0..ROBOTS {
        union.set_robot_name(r, &format!("robot{r}")).unwrap();
        for s in 0..SCANS {
            union.insert(record(r, s, POINTS)).unwrap();
        }
    }
    let seeded = |k: u64| FaultPlan {
        seed: schedule.plan.seed * 100 + k,
        ..schedule.plan.clone()
    };
    let mapper_opts = node_opts(
        dir.path(),
        "mapper",
        "mapper",
        &team,
        Some(port),
        &[],
        seeded(99),
    );
    let mut mapper = Some(Node::start(mapper_opts.clone()).unwrap());
    let mut robots: Vec<Node> = Vec::new();
    let order: Vec<u32> = (0..ROBOTS)
        .filter(|r| Some(*r) != schedule.late)
        .chain(schedule.late)
        .collect();
    for (done, &r) in order.iter().enumerate() {
        let name = format!("robot{r}");
        let opts = node_opts(
            dir.path(),
            &name,
            "robot",
            &team,
            None,
            &[port],
            seeded(r as u64),
        );
        let mut node = Node::start(opts.clone()).unwrap();
        // Let the link come up, then record at 50 Hz.
        std::thread::sleep(Duration::from_millis(200));
        for s in 0..SCANS {
            if schedule.comes_back == Some(r) && s == SCANS / 2 {
                let held = node.held();
                node.close();
                std::thread::sleep(Duration::from_millis(300));
                node = Node::start(opts.clone()).unwrap();
                assert!(
                    node.held() >= held,
                    "{}: the robot's store lost records",
                    schedule.name
                );
            }
            assert!(node.record(&name, record(r, s, POINTS)).unwrap());
            std::thread::sleep(Duration::from_millis(20));
        }
        robots.push(node);
        if schedule.restart_mapper_after == Some(done as u32 + 1) {
            let held = mapper.as_ref().unwrap().held();
            mapper.take().unwrap().close();
            let reopened = Node::start(mapper_opts.clone()).unwrap();
            // At least what it held: records may still arrive between the count and close.
            assert!(
                reopened.held() >= held,
                "{}: the reopened store lost records",
                schedule.name
            );
            mapper = Some(reopened);
        }
    }
    let mapper = mapper.unwrap();
    let total = union.len();
    let deadline = Duration::from_secs(60);
    let started = Instant::now();
    assert!(
        mapper.wait_for(total, deadline),
        "{}: the mapper holds {}/{total} records after {deadline:?}; counters {:?}",
        schedule.name,
        mapper.held(),
        mapper.counters()
    );
    assert_eq!(
        store_bytes(&mapper.store_snapshot()),
        store_bytes(&union),
        "{}: the mapper's store is not the union",
        schedule.name
    );
    // Store and forward: every robot ends with every robot's records too.
    for node in &robots {
        let left = deadline.saturating_sub(started.elapsed());
        assert!(
            node.wait_for(total, left),
            "{}: {} holds {}/{total}",
            schedule.name,
            node.name(),
            node.held()
        );
        assert_eq!(store_bytes(&node.store_snapshot()), store_bytes(&union));
    }
    let c = mapper.counters();
    assert_eq!(
        c.refused_total(),
        0,
        "{}: refused {:?}",
        schedule.name,
        c.refused
    );
    if schedule.plan.drop >= 0.2 {
        // What the plan dropped came back through anti-entropy.
        let recovered: u64 = robots
            .iter()
            .map(|n| n.counters().records_recovered)
            .sum::<u64>()
            + c.records_recovered;
        assert!(
            recovered > 0,
            "{}: nothing was recovered by fetches",
            schedule.name
        );
    }
    for n in robots {
        n.close();
    }
    mapper.close();
}

#[test]
fn stores_converge_to_the_union_under_twelve_fault_schedules() {
    for (i, s) in schedules().iter().enumerate() {
        let t = Instant::now();
        run(s, i);
        eprintln!(
            "schedule {i} ({}): converged in {:.1} s",
            s.name,
            t.elapsed().as_secs_f64()
        );
    }
}
