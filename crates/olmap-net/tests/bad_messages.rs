//! Bad payloads on the team's keys: the mapper keeps running, stores none of them, and
//! counts each by reason; a good record published afterwards is stored.

mod common;

use std::time::{Duration, Instant};

use common::{free_port, node_opts, record};
use olmap_net::protocol::{seal, Kind};
use olmap_net::{FaultPlan, Keys, NetOptions, Node, RecordMessage};
use zenoh::qos::CongestionControl;
use zenoh::Wait;

fn good(robot: u32, seq: u32, points: usize) -> Vec<u8> {
    RecordMessage {
        name: format!("robot{robot}"),
        sent_ns: 1,
        scan: record(robot, seq, points),
    }
    .encode()
}

#[test]
fn bad_payloads_are_counted_and_dropped_and_the_mapper_keeps_running() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let mut opts = node_opts(
        dir.path(),
        "mapper",
        "mapper",
        "bad",
        Some(port),
        &[],
        FaultPlan::default(),
    );
    opts.max_payload = 64 << 10;
    let mapper = Node::start(opts).unwrap();
    let keys = Keys::new("bad").unwrap();
    let attacker = zenoh::open(
        NetOptions::loopback("bad", None, &[port])
            .zenoh_config()
            .unwrap(),
    )
    .wait()
    .unwrap();
    // The link is up and the mapper subscribed once a good record gets through.
    let deadline = Instant::now() + Duration::from_secs(20);
    while !mapper.holds(3, 0) && Instant::now() < deadline {
        attacker
            .put(keys.record(3, 0), good(3, 0, 50))
            .wait()
            .unwrap();
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(mapper.holds(3, 0), "no link to the mapper");
    let before = mapper.counters().refused_total();

    let mut wrong_version = good(0, 2, 50);
    wrong_version[4] = 99;
    let mut wrong_checksum = good(0, 3, 50);
    let n = wrong_checksum.len();
    wrong_checksum[n - 1] ^= 0xff;
    let mut random = Vec::new();
    let mut s = 0x1234_5678u64;
    for _ in 0..3000 {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        random.push((s >> 33) as u8);
    }
    let bad: Vec<(String, Vec<u8>, &str)> = vec![
        (
            keys.record(0, 0),
            good(0, 0, 50)[..40].to_vec(),
            "truncated",
        ),
        (keys.record(0, 1), good(0, 1, 10_000), "oversized"),
        (keys.record(0, 2), wrong_version, "wrong_version"),
        (keys.record(0, 3), wrong_checksum, "bad_checksum"),
        // Robot 1's record published under robot 0's key.
        (keys.record(0, 4), good(1, 4, 50), "wrong_key"),
        (keys.record(0, 5), random.clone(), "bad_magic"),
        // A digest sealed as a record.
        (keys.record(0, 6), seal(Kind::Digest, b"xx"), "wrong_kind"),
        // A well-sealed record body that does not decode.
        (
            keys.record(0, 7),
            seal(Kind::Record, &[1, 0, b'a', 0, 0]),
            "malformed",
        ),
        (keys.digest("evil"), random.clone(), "bad_magic"),
        (
            format!("{}/rec/x/y", keys.prefix()),
            good(0, 8, 50),
            "wrong_key",
        ),
    ];
    for (key, payload, _) in &bad {
        // Blocking, as the nodes send records: a burst with the default (drop when the
        // link's queue is full) can lose some on a loaded machine (seen once in CI: 2 of
        // 11 arrived), and the test is about what the mapper does with those that arrive.
        attacker
            .put(key, payload.clone())
            .congestion_control(CongestionControl::Block)
            .wait()
            .unwrap();
    }
    // A fetch with a garbage request: answered with nothing, counted.
    let replies = attacker
        .get(keys.records_of(0))
        .payload(random.clone())
        .timeout(Duration::from_secs(1))
        .wait()
        .unwrap();
    assert!(replies.recv().is_err(), "a garbage fetch got a reply");

    let expected_total = before + bad.len() as u64 + 1;
    let deadline = Instant::now() + Duration::from_secs(20);
    while mapper.counters().refused_total() < expected_total && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let c = mapper.counters();
    assert_eq!(mapper.held(), 1, "a bad payload was stored");
    assert_eq!(c.refused_total(), expected_total, "{:?}", c.refused);
    for (_, _, reason) in &bad {
        assert!(
            c.refused.get(*reason).copied().unwrap_or(0) >= 1,
            "{reason}: {:?}",
            c.refused
        );
    }

    // Still alive: a good record is stored.
    attacker
        .put(keys.record(2, 0), good(2, 0, 50))
        .wait()
        .unwrap();
    assert!(mapper.wait_for(2, Duration::from_secs(10)));
    assert!(mapper.holds(2, 0));
    // A different record under a held key is a conflict, never stored.
    let mut other = record(2, 0, 50);
    other.time += 1.0;
    let conflicting = RecordMessage {
        name: "robot2".into(),
        sent_ns: 1,
        scan: other,
    }
    .encode();
    attacker.put(keys.record(2, 0), conflicting).wait().unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while !mapper.counters().refused.contains_key("conflict") && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(mapper.counters().refused.get("conflict"), Some(&1));
    assert_eq!(
        mapper.store_snapshot().get(2, 0).unwrap().time,
        record(2, 0, 50).time
    );
    let _ = attacker.close().wait();
    mapper.close();
}
