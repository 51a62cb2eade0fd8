//! Property tests: random and mutated bytes fed to every reader never panic; and the short
//! pass of the mutation fuzzer (`olmap::fuzz`) over every reader, real samples included.

use olmap::io::{self, CloudFormat, PcdEncoding, PlyEncoding, ReadOptions, WriteOptions};
use proptest::prelude::*;

use crate::round_trip::synthetic_cloud;

fn samples() -> Vec<(CloudFormat, Vec<u8>)> {
    let cloud = synthetic_cloud(20);
    let mut out = Vec::new();
    let mut push = |format, opts: WriteOptions| {
        let mut buf = Vec::new();
        io::write_cloud_to(&mut buf, &cloud, format, &opts).unwrap();
        out.push((format, buf));
    };
    for format in CloudFormat::ALL {
        if format != CloudFormat::Las {
            push(format, WriteOptions::default());
        }
    }
    for pcd_encoding in [PcdEncoding::Ascii, PcdEncoding::BinaryCompressed] {
        push(
            CloudFormat::Pcd,
            WriteOptions {
                pcd_encoding,
                ..Default::default()
            },
        );
    }
    push(
        CloudFormat::Ply,
        WriteOptions {
            ply_encoding: PlyEncoding::Ascii,
            ..Default::default()
        },
    );
    // LAS holds millimetres within ±2,147 km of its origin: not the 3.4e38 m point.
    #[cfg(feature = "las")]
    for laz in [false, true] {
        let in_range = cloud.select(|_, p| p.coords.iter().all(|v| v.abs() < 1e6));
        let mut buf = Vec::new();
        let opts = WriteOptions {
            laz: Some(laz),
            ..Default::default()
        };
        io::write_cloud_to(&mut buf, &in_range, CloudFormat::Las, &opts).unwrap();
        out.push((CloudFormat::Las, buf));
    }
    out
}

#[derive(Debug, Clone)]
enum Mutation {
    Flip(usize, u8),
    Insert(usize, u8),
    Delete(usize),
    Truncate(usize),
    Digit(usize, u8),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 1u8..=255).prop_map(|(i, b)| Mutation::Flip(i, b)),
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Insert(i, b)),
        any::<usize>().prop_map(Mutation::Delete),
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), b'0'..=b'9').prop_map(|(i, b)| Mutation::Digit(i, b)),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    if bytes.is_empty() {
        return;
    }
    let n = bytes.len();
    match *m {
        Mutation::Flip(i, b) => bytes[i % n] ^= b,
        Mutation::Insert(i, b) => bytes.insert(i % (n + 1), b),
        Mutation::Delete(i) => {
            bytes.remove(i % n);
        }
        Mutation::Truncate(i) => bytes.truncate(i % n),
        Mutation::Digit(i, b) => bytes[i % n] = b,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048), which in 0usize..CloudFormat::ALL.len()) {
        let format = CloudFormat::ALL[which];
        let _ = io::read_cloud_from(&bytes[..], format, &ReadOptions::default());
    }

    #[test]
    fn mutated_files_never_panic(which in 0usize..12, muts in proptest::collection::vec(mutation(), 1..6)) {
        let samples = samples();
        let (format, mut bytes) = samples[which % samples.len()].clone();
        for m in &muts {
            apply(&mut bytes, m);
        }
        let _ = io::read_cloud_from(&bytes[..], format, &ReadOptions { uos_valid_only: true, ..Default::default() });
    }
}

fn olm_sample() -> Vec<u8> {
    let cloud = synthetic_cloud(300);
    // The cloud's extreme points (3.4e38 m) have no voxel key: `from_cloud` refuses them,
    // `add_points` skips them.
    let mut map = olmap::occupancy::OccupancyList::new(0.5).unwrap();
    map.add_points(&cloud, &olmap::geometry::Pose::identity(), 1);
    let mut buf = Vec::new();
    map.write_olm(&mut buf).unwrap();
    buf
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn map_readers_never_panic(muts in proptest::collection::vec(mutation(), 1..6), noise in proptest::collection::vec(any::<u8>(), 0..512)) {
        let mut bytes = olm_sample();
        for m in &muts {
            apply(&mut bytes, m);
        }
        let _ = olmap::occupancy::OccupancyList::read_olm(&bytes[..]);
        let _ = olmap::occupancy::OccupancyList::read_olm(&noise[..]);
        let mut bt = b"# Octomap OcTree binary file\nid OcTree\nsize 9\nres 0.1\ndata\n".to_vec();
        bt.extend_from_slice(&noise);
        let _ = olmap::io::octomap_bt::read(&bt[..], 1 << 20);
    }
}

/// The CI pass of the fuzzer: 20,000 mutated inputs (about a second) over every reader (the real
/// samples when the shared data is there), no panic, no time bomb, no message that says a
/// clause twice, and every unmutated sample readable. Long runs: `examples/fuzz.rs`.
#[test]
fn fuzz_short_pass_over_every_reader() {
    let samples = olmap::fuzz::corpus(crate::data().as_deref()).unwrap();
    let config = olmap::fuzz::FuzzConfig {
        seed: 22,
        cases: Some(20_000),
        // Generous for a debug build on a busy machine: a case takes microseconds.
        slow_seconds: 5.0,
        ..Default::default()
    };
    let report = olmap::fuzz::run(&config, &samples, |_| {});
    for f in &report.findings {
        eprintln!(
            "{:?}: {} case {:?} from {}",
            f.kind,
            f.target.name(),
            f.case,
            f.sample
        );
    }
    assert!(
        report.findings.is_empty(),
        "{} findings",
        report.findings.len()
    );
    assert_eq!(report.cases, 20_000);
    // Every reader ran, and saw both inputs it accepts and inputs it refuses.
    for t in &report.targets {
        assert!(t.cases >= 40, "{}: {} cases", t.target, t.cases);
        assert!(t.refused > 0, "{}: nothing refused", t.target);
    }
    let names: Vec<&str> = report.targets.iter().map(|t| t.target.as_str()).collect();
    for needed in [
        "PCD",
        "PLY",
        "XYZ text",
        "3DTK .3d",
        "CSV point table",
        "KITTI .bin",
        "OctoMap ScanGraph",
        "olmap .olm",
        "OctoMap .bt",
        "pose list",
        "CSV pose table",
        "3DTK .pose",
        "3DTK .frames",
        "scan store",
        "scan store salvage",
        "mirror log",
        "laser scan CSV",
        "laser scan JSON",
        "bzip2 XYZ text",
        "CARMEN log",
    ] {
        assert!(names.contains(&needed), "{needed} not fuzzed: {names:?}");
    }
    #[cfg(feature = "las")]
    assert!(names.contains(&"LAS/LAZ"), "LAS/LAZ not fuzzed: {names:?}");
    #[cfg(feature = "bag")]
    for needed in [
        "ROS 2 PointCloud2",
        "ROS 2 LaserScan",
        "ROS 2 TFMessage",
        "ROS 2 bag (MCAP)",
    ] {
        assert!(names.contains(&needed), "{needed} not fuzzed: {names:?}");
    }
}

#[test]
fn fuzz_cases_replay_exactly() {
    let samples = olmap::fuzz::corpus(None).unwrap();
    for case in [0, 17, 999] {
        let (a, bytes_a, out_a) = olmap::fuzz::replay(&samples, 5, case);
        let (b, bytes_b, out_b) = olmap::fuzz::replay(&samples, 5, case);
        assert_eq!((a, &bytes_a), (b, &bytes_b));
        assert_eq!(out_a, out_b);
    }
    assert_ne!(
        olmap::fuzz::case_input(&samples, 5, 1).1,
        olmap::fuzz::case_input(&samples, 6, 1).1
    );
}
