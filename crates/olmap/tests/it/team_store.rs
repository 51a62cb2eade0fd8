//! The per-robot scan store (thesis §6.3.2): merge laws, synchronisation, conflicts, the
//! file format and its bad-input handling, and the records built from a simulated run.

use nalgebra::{Point3, Vector3};
use olmap::cloud::PointCloud;
use olmap::geometry::Pose;
use olmap::sim::{read_dataset, write_dataset};
use olmap::sim::{simulate, Scanner3d, SimConfig, SimRng, SpinningLidar, WorldKind};
use olmap::team::{
    merge_store_files, salvage_store_file, store_info, ScanStore, StoredScan, StoredSighting,
};
use proptest::prelude::*;

/// A pseudo-random record for key `(robot, seq)`: the same salt gives the same record.
/// Attributes (odometry, intensity, normals, colours, sightings) come and go with the salt.
fn record(robot: u32, seq: u32, salt: u64) -> StoredScan {
    let mut rng = SimRng::for_item(salt, robot as u64, seq as u64);
    let n = rng.index(6);
    let points: Vec<Point3<f32>> = (0..n)
        .map(|_| {
            Point3::new(
                rng.range(-5.0, 5.0) as f32,
                rng.range(-5.0, 5.0) as f32,
                rng.range(0.0, 3.0) as f32,
            )
        })
        .collect();
    let mut cloud = PointCloud::from_points(points).with_origin(Point3::new(0.0, 0.0, 0.4));
    if rng.chance(0.5) {
        cloud
            .set_intensity(Some((0..n).map(|_| rng.range(0.0, 2.0) as f32).collect()))
            .unwrap();
    }
    if rng.chance(0.3) {
        cloud
            .set_normals(Some((0..n).map(|_| Vector3::new(0.0, 0.0, 1.0)).collect()))
            .unwrap();
    }
    if rng.chance(0.3) {
        cloud
            .set_colors(Some((0..n).map(|i| [i as u8, 7, 200]).collect()))
            .unwrap();
    }
    let odometry = rng.chance(0.8).then(|| {
        Pose::from_xyz_ypr(
            rng.range(-3.0, 3.0),
            rng.range(-3.0, 3.0),
            0.0,
            rng.range(-3.0, 3.0),
            0.0,
            0.0,
        )
    });
    let sightings = (0..rng.index(3) as u32)
        .map(|target| StoredSighting {
            target,
            range: rng.range(0.5, 8.0),
            bearing: rng.range(-3.0, 3.0),
            elevation: rng.range(-0.5, 0.5),
            beacon: Point3::new(rng.range(-8.0, 8.0), rng.range(-8.0, 8.0), 0.8),
            mutual: rng.chance(0.5),
        })
        .collect();
    StoredScan {
        robot,
        seq,
        time: seq as f64 * 10.0 + rng.uniform(),
        odometry,
        cloud,
        sightings,
    }
}

fn bytes(store: &ScanStore) -> Vec<u8> {
    let mut out = Vec::new();
    store.write_to(&mut out).unwrap();
    out
}

fn name(robot: u32) -> String {
    format!("pioneer-{robot}")
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Four robots' stores, records shared between some of them, merged in a random order
    /// and a random grouping, always give the same store, and merging is idempotent.
    #[test]
    fn merging_in_any_order_and_grouping_gives_the_identical_store(
        universe in prop::collection::btree_map((0u32..4, 0u32..5), (any::<u64>(), 1u8..16), 1..16),
        order in Just(vec![0usize, 1, 2, 3]).prop_shuffle(),
        picks in prop::collection::vec(any::<u8>(), 3),
        flips in prop::collection::vec(any::<bool>(), 3),
    ) {
        let mut stores = vec![ScanStore::new(); 4];
        for (i, s) in stores.iter_mut().enumerate() {
            let i = i as u32;
            s.set_robot_name(i, &name(i)).unwrap();
            s.set_robot_name((i + 1) % 4, &name((i + 1) % 4)).unwrap();
        }
        for (&(robot, seq), &(salt, mask)) in &universe {
            for (i, s) in stores.iter_mut().enumerate() {
                if mask & (1 << i) != 0 {
                    prop_assert!(s.insert(record(robot, seq, salt)).unwrap());
                }
            }
        }
        // Reference: left fold in robot order.
        let mut reference = ScanStore::new();
        for s in &stores {
            reference.merge(s).unwrap();
        }
        prop_assert_eq!(reference.len(), universe.len());
        // A random permutation, then random pairs merged (either way round) until one is left.
        let mut pool: Vec<ScanStore> = order.iter().map(|&i| stores[i].clone()).collect();
        for (pick, flip) in picks.iter().zip(&flips) {
            let j = *pick as usize % (pool.len() - 1);
            let right = pool.remove(j + 1);
            let left = &mut pool[j];
            if *flip {
                let mut right = right;
                right.merge(left).unwrap();
                *left = right;
            } else {
                left.merge(&right).unwrap();
            }
        }
        prop_assert_eq!(pool.len(), 1);
        let merged = pool.pop().unwrap();
        prop_assert_eq!(&merged, &reference);
        prop_assert_eq!(bytes(&merged), bytes(&reference));
        // Idempotent: merging anything already merged adds nothing and changes nothing.
        let mut again = merged.clone();
        prop_assert_eq!(again.merge(&merged).unwrap(), 0);
        for s in &stores {
            prop_assert_eq!(again.merge(s).unwrap(), 0);
        }
        prop_assert_eq!(&again, &merged);
        // And the bytes read back to the same store.
        prop_assert_eq!(&ScanStore::read_from(&bytes(&merged)[..]).unwrap(), &merged);
    }
}

#[test]
fn sync_gives_each_robot_what_it_lacks() {
    let mut a = ScanStore::new();
    let mut b = ScanStore::new();
    a.set_robot_name(0, "alice").unwrap();
    b.set_robot_name(1, "bob").unwrap();
    for seq in 0..3 {
        a.insert(record(0, seq, 1)).unwrap();
    }
    for seq in 0..2 {
        b.insert(record(1, seq, 2)).unwrap();
    }
    // Both already hold one scan of a third robot, relayed earlier.
    a.insert(record(2, 0, 3)).unwrap();
    b.insert(record(2, 0, 3)).unwrap();
    assert_eq!(a.missing_from(&b), vec![(1, 0), (1, 1)]);
    assert_eq!(b.missing_from(&a), vec![(0, 0), (0, 1), (0, 2)]);
    assert_eq!(ScanStore::sync(&mut a, &mut b).unwrap(), (2, 3));
    assert_eq!(a, b);
    assert_eq!(a.len(), 6);
    assert_eq!(a.robots(), vec![0, 1, 2]);
    assert_eq!(b.robot_name(0), "alice");
    assert_eq!(a.robot_name(1), "bob");
    assert_eq!(a.robot_name(2), "robot2");
    assert_eq!(a.scans_of(0).map(|s| s.seq).collect::<Vec<_>>(), [0, 1, 2]);
    assert_eq!(a.get(1, 1), Some(&record(1, 1, 2)));
    assert_eq!(ScanStore::sync(&mut a, &mut b).unwrap(), (0, 0));
    // Splitting by robot and merging back gives the whole store.
    let mut whole = ScanStore::new();
    for r in a.robots() {
        let own = a.robot_store(r);
        assert!(own.iter().all(|s| s.robot == r));
        whole.merge(&own).unwrap();
    }
    assert_eq!(whole.len(), a.len());
    assert_eq!(bytes(&whole), bytes(&a));
}

#[test]
fn conflicting_records_and_names_are_errors_that_change_nothing() {
    let mut a = ScanStore::new();
    let mut b = ScanStore::new();
    a.insert(record(0, 0, 1)).unwrap();
    a.insert(record(0, 1, 1)).unwrap();
    b.insert(record(1, 0, 2)).unwrap();
    let mut changed = record(0, 1, 1);
    changed.time += 1.0;
    b.insert(changed.clone()).unwrap();
    // Inserting the same record again is fine; a different one under the key is not.
    assert!(!a.insert(record(0, 1, 1)).unwrap());
    let err = a.insert(changed).unwrap_err().to_string();
    assert!(err.contains("conflicting") && err.contains("time"), "{err}");
    // Even a sign of zero counts: records are compared bit for bit.
    let mut zero = record(3, 0, 5);
    zero.time = 0.0;
    a.insert(zero.clone()).unwrap();
    zero.time = -0.0;
    assert!(a.insert(zero).is_err());
    let (a0, b0) = (a.clone(), b.clone());
    let err = a.merge(&b).unwrap_err().to_string();
    assert!(err.contains("scan 1 of robot 0"), "{err}");
    assert_eq!(a, a0);
    assert!(ScanStore::sync(&mut a, &mut b).is_err());
    assert_eq!((&a, &b), (&a0, &b0));
    // Two names for one robot.
    let mut c = ScanStore::new();
    c.set_robot_name(0, "alice").unwrap();
    c.set_robot_name(0, "alice").unwrap();
    assert!(c.set_robot_name(0, "eve").is_err());
    assert!(c.set_robot_name(1, "").is_err());
    let mut d = ScanStore::new();
    d.set_robot_name(0, "eve").unwrap();
    d.insert(record(5, 0, 9)).unwrap();
    let d0 = d.clone();
    assert!(d.merge(&c).is_err());
    assert!(ScanStore::sync(&mut c, &mut d).is_err());
    assert_eq!(d, d0);
    // Non-finite values never enter a store.
    let mut bad = record(0, 9, 1);
    bad.time = f64::NAN;
    assert!(a.insert(bad).is_err());
    let mut bad = record(0, 9, 1);
    bad.cloud = PointCloud::from_points(vec![Point3::new(f32::INFINITY, 0.0, 0.0)]);
    assert!(a.insert(bad).is_err());
    assert_eq!(a, a0);
}

fn small_sim() -> olmap::sim::SimDataset {
    let lidar = SpinningLidar {
        beams: 8,
        azimuth_step: 4f64.to_radians(),
        ..Default::default()
    };
    let config = SimConfig {
        world: WorldKind::BoxRoom,
        seed: 3,
        robots: 2,
        stops: 3,
        scanner: Scanner3d::Lidar(lidar),
        ..Default::default()
    };
    simulate(&config, |_, _| {}).unwrap()
}

#[test]
fn a_simulated_run_becomes_records_with_their_sightings_and_round_trips() {
    let data = small_sim();
    assert!(
        !data.sightings.is_empty(),
        "the robots should see each other"
    );
    let store = data.to_store().unwrap();
    assert_eq!(store.len(), 6);
    assert_eq!(store.robots(), vec![0, 1]);
    assert_eq!(store.robot_name(1), data.robots[1].name);
    let mut attached = 0;
    for (r, robot) in data.robots.iter().enumerate() {
        for k in 0..3 {
            let rec = store.get(r as u32, k as u32).unwrap();
            assert_eq!(rec.cloud, robot.scans[k]);
            assert!(rec.cloud.intensity().is_some(), "the lidar gives intensity");
            assert_eq!(rec.odometry, Some(robot.odometry[k]));
            assert_eq!(rec.time, k as f64 * data.config.stop_interval);
            let mut expected: Vec<_> = data
                .sightings
                .iter()
                .filter(|s| s.observer == r && s.stop == k)
                .collect();
            expected.sort_by_key(|s| s.target);
            assert_eq!(rec.sightings.len(), expected.len());
            for (got, want) in rec.sightings.iter().zip(&expected) {
                assert_eq!(got.target as usize, want.target);
                assert_eq!(
                    (
                        got.range,
                        got.bearing,
                        got.elevation,
                        got.beacon,
                        got.mutual
                    ),
                    (
                        want.range,
                        want.bearing,
                        want.elevation,
                        want.beacon,
                        want.mutual
                    )
                );
                assert_eq!(rec.time, want.time);
            }
            attached += rec.sightings.len();
        }
    }
    assert_eq!(attached, data.sightings.len());

    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("team.olstore");
    store.write(&path).unwrap();
    let back = ScanStore::read(&path).unwrap();
    assert_eq!(back, store);
    assert_eq!(std::fs::read(&path).unwrap(), bytes(&store));
    // Nothing else is left in the folder (the temporary file was renamed).
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 1);
    // Each robot's own store, synchronised, gives back the whole.
    let (mut s0, mut s1) = (store.robot_store(0), store.robot_store(1));
    assert_eq!((s0.len(), s1.len()), (3, 3));
    assert_eq!(ScanStore::sync(&mut s0, &mut s1).unwrap(), (3, 3));
    assert_eq!(s0, store);

    // The same dataset on disk gives the same records (clouds and odometry pass through
    // PCD and pose text files, so compare what they keep exactly).
    let dir = tmp.path().join("dataset");
    write_dataset(&dir, &data).unwrap();
    let disk = read_dataset(&dir).unwrap().to_store().unwrap();
    assert_eq!(disk.len(), store.len());
    for (a, b) in disk.iter().zip(store.iter()) {
        assert_eq!((a.robot, a.seq, a.time), (b.robot, b.seq, b.time));
        assert_eq!(a.sightings, b.sightings);
        assert_eq!(a.cloud.points(), b.cloud.points());
        assert_eq!(a.cloud.origin(), b.cloud.origin());
        let (pa, pb) = (a.odometry.unwrap(), b.odometry.unwrap());
        assert!((pa.translation() - pb.translation()).norm() < 1e-12);
        assert!(pa.rotation().angle_to(&pb.rotation()) < 1e-9);
    }
}

/// A small store whose bytes are easy to patch: no names, one record with odometry first.
fn patchable() -> ScanStore {
    let mut s = ScanStore::new();
    let mut first = record(0, 0, 4);
    first.odometry = Some(Pose::from_xyz_ypr(1.0, 2.0, 0.0, 0.5, 0.0, 0.0));
    s.insert(first).unwrap();
    s.insert(record(0, 1, 4)).unwrap();
    s.insert(record(1, 0, 4)).unwrap();
    s
}

/// Bytes of the header of a version-2 store without names: magic 8, version 4, name
/// count 4, record count 8, header checksum 4.
const HEADER: usize = 28;

/// Recomputes the header checksum and every record frame's checksum of version-2 bytes
/// (after a deliberate patch, so that the content checks are what refuses it).
fn with_crc(mut data: Vec<u8>) -> Vec<u8> {
    let crc = olmap::file::crc32::crc32(&data[..HEADER - 4]);
    data[HEADER - 4..HEADER].copy_from_slice(&crc.to_le_bytes());
    let mut pos = HEADER;
    while pos + 16 <= data.len() {
        let len = u64::from_le_bytes(data[pos + 8..pos + 16].try_into().unwrap()) as usize;
        let end = pos + 16 + len;
        if end + 4 > data.len() {
            break;
        }
        let crc = olmap::file::crc32::crc32(&data[pos + 8..end]);
        data[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        pos = end + 4;
    }
    data
}

/// The record frames of version-2 bytes: (start, end) of each.
fn frames(data: &[u8], header: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut pos = header;
    while pos < data.len() {
        assert_eq!(&data[pos..pos + 8], olmap::team::RECORD_MARKER);
        let len = u64::from_le_bytes(data[pos + 8..pos + 16].try_into().unwrap()) as usize;
        out.push((pos, pos + 16 + len + 4));
        pos += 16 + len + 4;
    }
    out
}

/// The version-1 bytes of the same store: the header without its checksum, the record
/// bodies back to back, one checksum of everything.
fn v1_bytes(store: &ScanStore) -> Vec<u8> {
    let v2 = bytes(store);
    let names_end = {
        // magic 8, version 4, name count 4, then names, then the record count.
        let mut pos = 12;
        let n = u32::from_le_bytes(v2[pos..pos + 4].try_into().unwrap());
        pos += 4;
        for _ in 0..n {
            let len = u32::from_le_bytes(v2[pos + 4..pos + 8].try_into().unwrap()) as usize;
            pos += 8 + len;
        }
        pos
    };
    let mut out = v2[..names_end + 8].to_vec();
    out[8..12].copy_from_slice(&1u32.to_le_bytes());
    for (start, end) in frames(&v2, names_end + 12) {
        out.extend_from_slice(&v2[start + 16..end - 4]);
    }
    let crc = olmap::file::crc32::crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

#[test]
fn damaged_store_files_are_refused_with_their_name() {
    let store = patchable();
    let good = bytes(&store);
    // Every truncation and every single flipped byte is an error, never a panic.
    for n in 0..good.len() {
        assert!(
            ScanStore::read_from(&good[..n]).is_err(),
            "truncated to {n}"
        );
    }
    for i in 0..good.len() {
        let mut bad = good.clone();
        bad[i] ^= 0x10;
        assert!(ScanStore::read_from(&bad[..]).is_err(), "byte {i} flipped");
    }
    let mut trailing = good.clone();
    trailing.push(0);
    assert!(ScanStore::read_from(&trailing[..]).is_err());

    let tmp = tempfile::tempdir().unwrap();
    let check = |file: &str, data: &[u8], expect: &str| {
        let path = tmp.path().join(file);
        std::fs::write(&path, data).unwrap();
        let err = ScanStore::read(&path).unwrap_err();
        let msg = err.to_string();
        assert!(
            matches!(err, olmap::Error::Read { .. }),
            "{file}: not a read error: {msg}"
        );
        assert!(
            msg.contains(file),
            "{file}: the message names no file: {msg}"
        );
        assert!(
            msg.contains(expect),
            "{file}: expected '{expect}' in: {msg}"
        );
    };
    check("half.olstore", &good[..good.len() / 2], "ends early");
    check("empty.olstore", &[], "empty");
    let mut magic = good.clone();
    magic[0] = b'X';
    check("magic.olstore", &magic, "magic");
    let mut version = good.clone();
    version[8..12].copy_from_slice(&7u32.to_le_bytes());
    check("version.olstore", &version, "version 7");
    // Header: magic 8, version 4, name count 4, record count 8, checksum 4 -> first
    // record frame at 28.
    let mut absurd = good.clone();
    absurd[16..24].copy_from_slice(&u64::MAX.to_le_bytes());
    check("absurd.olstore", &with_crc(absurd), "announced");
    // First frame: marker 8, length 8, then robot 4, seq 4, time 8, odometry flag 1 ->
    // pose at byte 61.
    let mut nan = good.clone();
    nan[61..69].copy_from_slice(&f64::NAN.to_le_bytes());
    check("nan.olstore", &with_crc(nan), "byte 61");
    // A flipped byte in the last record: refused naming the record and where it starts.
    let last_frame = *frames(&good, HEADER).last().unwrap();
    let mut flipped = good.clone();
    flipped[last_frame.1 - 10] ^= 1;
    check(
        "flipped.olstore",
        &flipped,
        &format!(
            "byte {}: record 2 (bytes {}..{}) is damaged: checksum",
            last_frame.0, last_frame.0, last_frame.1
        ),
    );
    let mut header = good.clone();
    header[13] ^= 1;
    check("header.olstore", &header, "byte 0: the header");
    // A failed write leaves no file behind and an existing one untouched.
    let target = tmp.path().join("keep.olstore");
    store.write(&target).unwrap();
    assert!(store.write(tmp.path()).is_err());
    assert_eq!(ScanStore::read(&target).unwrap(), store);
}

#[test]
fn to_store_refuses_sightings_without_a_scan() {
    let mut data = small_sim();
    let mut s = data.sightings.first().cloned().unwrap();
    s.stop = 99;
    data.sightings.push(s);
    let err = data.to_store().unwrap_err().to_string();
    assert!(err.contains("stop 99"), "{err}");
}

/// A store of three robots, 12 records, with names.
fn twelve() -> ScanStore {
    let mut s = ScanStore::new();
    for robot in 0..3 {
        s.set_robot_name(robot, &name(robot)).unwrap();
        for seq in 0..4 {
            s.insert(record(robot, seq, 11)).unwrap();
        }
    }
    s
}

/// The header of [`twelve`]'s file: 28 bytes plus 8 and the name per robot.
fn twelve_header() -> usize {
    28 + (0..3).map(|r| 8 + name(r).len()).sum::<usize>()
}

#[test]
fn audit_store_one_bad_byte_loses_one_record() {
    // The audit: one CRC over the whole file, so one bad byte lost every record.
    let store = twelve();
    let good = bytes(&store);
    let frames = frames(&good, twelve_header());
    assert_eq!(frames.len(), 12);
    let (start, end) = frames[5];
    let mut bad = good.clone();
    bad[(start + end) / 2] ^= 0x08;
    // The strict reader refuses it, naming the record and the byte where it starts.
    let err = ScanStore::read_from(&bad[..]).unwrap_err().to_string();
    assert!(
        err.contains(&format!("byte {start}: record 5 (bytes {start}..{end})")),
        "{err}"
    );
    // The salvage reader recovers the other eleven, bit for bit, and reports the one lost.
    let (salvaged, report) = ScanStore::salvage_from(&bad).unwrap();
    assert_eq!(salvaged.len(), 11);
    assert_eq!(report.records_recovered, 11);
    assert_eq!(report.records_expected, Some(12));
    assert_eq!(report.records_lost, 1);
    assert!(report.header_intact && report.verified && !report.intact());
    assert_eq!(report.damage.len(), 1);
    let d = &report.damage[0];
    assert_eq!((d.start, d.end), (start as u64, end as u64));
    assert_eq!((d.record, d.records_seen), (Some(5), 1));
    let lost = store.iter().nth(5).unwrap();
    assert!(salvaged.get(lost.robot, lost.seq).is_none());
    for s in salvaged.iter() {
        assert_eq!(Some(s), store.get(s.robot, s.seq));
    }
    assert_eq!(salvaged.robot_name(2), name(2));
    // An intact file salvages whole.
    let (all, report) = ScanStore::salvage_from(&good).unwrap();
    assert_eq!(all, store);
    assert!(report.intact());
}

#[test]
fn audit_store_every_bad_byte_costs_at_most_one_record() {
    let store = twelve();
    let good = bytes(&store);
    let header = twelve_header();
    for i in 0..good.len() {
        let mut bad = good.clone();
        bad[i] ^= 0x21;
        assert!(ScanStore::read_from(&bad[..]).is_err(), "byte {i}");
        let (salvaged, report) = ScanStore::salvage_from(&bad).unwrap();
        assert!(salvaged.len() >= 11, "byte {i}: {report:?}");
        for s in salvaged.iter() {
            assert_eq!(Some(s), store.get(s.robot, s.seq), "byte {i}");
        }
        // A bad byte in the header costs the names, never a record.
        if i < header {
            assert_eq!(salvaged.len(), 12, "byte {i}");
            assert!(!report.header_intact, "byte {i}");
        } else {
            assert_eq!(report.records_lost, 1, "byte {i}");
        }
        assert_eq!(report.damage.len(), 1, "byte {i}: {report:?}");
    }
    // Cut anywhere: every record before the cut is recovered.
    let frames = frames(&good, header);
    for cut in (header..good.len()).step_by(7) {
        let (salvaged, report) = ScanStore::salvage_from(&good[..cut]).unwrap();
        let whole = frames.iter().filter(|f| f.1 <= cut).count();
        assert_eq!(salvaged.len(), whole, "cut at {cut}");
        assert_eq!(report.records_lost, 12 - whole as u64, "cut at {cut}");
    }
}

#[test]
fn version_1_stores_still_read_and_salvage_unverified() {
    let store = twelve();
    let v1 = v1_bytes(&store);
    assert_eq!(ScanStore::read_from(&v1[..]).unwrap(), store);
    let (all, report) = ScanStore::salvage_from(&v1).unwrap();
    assert_eq!(all, store);
    assert!(report.intact());
    assert_eq!(report.version, 1);
    // One flipped bit in the first record's time (version 1 has no header checksum, so
    // the first record starts 4 bytes earlier; its time 8 bytes in): the whole file is
    // refused, and salvage returns the records that decode but cannot vouch for them.
    let mut bad = v1.clone();
    let i = twelve_header() - 4 + 8;
    bad[i] ^= 1;
    let err = ScanStore::read_from(&bad[..]).unwrap_err().to_string();
    assert!(err.contains("checksum"), "{err}");
    let (recovered, report) = ScanStore::salvage_from(&bad).unwrap();
    assert_eq!(recovered.len(), 12);
    assert!(!report.verified && !report.intact());
}

#[test]
fn store_files_info_merge_and_salvage() {
    let tmp = tempfile::tempdir().unwrap();
    let store = twelve();
    let (a, b) = (tmp.path().join("a.olstore"), tmp.path().join("b.olstore"));
    let mut first = store.robot_store(0);
    first.merge(&store.robot_store(1)).unwrap();
    first.write(&a).unwrap();
    let mut second = store.robot_store(1);
    second.merge(&store.robot_store(2)).unwrap();
    second.write(&b).unwrap();
    // Merge: robot 1's records are in both, identical.
    let out = tmp.path().join("merged.olstore");
    let r = merge_store_files(&[a.clone(), b.clone()], &out).unwrap();
    assert_eq!((r.inputs[0].added, r.inputs[1].added), (8, 4));
    assert_eq!(r.records, 12);
    assert_eq!(ScanStore::read(&out).unwrap(), store);
    assert_eq!(r.bytes, std::fs::metadata(&out).unwrap().len());
    // Info of an intact file, with a gap.
    let mut gappy = store.clone();
    gappy.insert(record(2, 9, 11)).unwrap();
    let g = tmp.path().join("gappy.olstore");
    gappy.write(&g).unwrap();
    let info = store_info(&g).unwrap();
    assert!(info.intact && info.damage.is_empty());
    assert_eq!((info.version, info.records, info.names), (2, 13, 3));
    let r2 = &info.robots[2];
    assert_eq!((r2.records, r2.first_seq, r2.last_seq), (5, 0, 9));
    assert_eq!(r2.gaps, [[4, 8]]);
    // A damaged file: info reports the damage, salvage writes the rest.
    let mut data = std::fs::read(&out).unwrap();
    let frames = frames(&data, twelve_header());
    data[frames[0].0 + 30] ^= 0xff;
    let bad = tmp.path().join("bad.olstore");
    std::fs::write(&bad, &data).unwrap();
    let err = ScanStore::read(&bad).unwrap_err().to_string();
    assert!(
        err.contains("bad.olstore") && err.contains("record 0"),
        "{err}"
    );
    let info = store_info(&bad).unwrap();
    assert!(!info.intact);
    assert_eq!((info.records, info.records_lost), (11, 1));
    assert_eq!(info.damage[0].start, frames[0].0 as u64);
    let fixed = tmp.path().join("fixed.olstore");
    let r = salvage_store_file(&bad, &fixed).unwrap();
    assert_eq!(r.salvage.records_recovered, 11);
    assert_eq!(ScanStore::read(&fixed).unwrap().len(), 11);
    // The output is checked before the input is read; a damaged input is not merged.
    assert!(salvage_store_file(&bad, &tmp.path().join("no/dir.olstore")).is_err());
    assert!(merge_store_files(&[a, bad], &tmp.path().join("m2.olstore")).is_err());
    assert!(!tmp.path().join("m2.olstore").exists());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Random damage (bytes overwritten, a stretch cut out, bytes inserted): the salvage
    /// reader never panics and every verified record it returns is one of the original,
    /// bit for bit.
    #[test]
    fn salvage_returns_only_original_records(
        writes in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..8),
        cut in proptest::option::of((any::<prop::sample::Index>(), 0usize..300)),
        insert in proptest::option::of((any::<prop::sample::Index>(), proptest::collection::vec(any::<u8>(), 1..40))),
    ) {
        let store = twelve();
        let mut data = bytes(&store);
        for (i, b) in writes {
            let i = i.index(data.len());
            data[i] = b;
        }
        if let Some((at, n)) = cut {
            let at = at.index(data.len());
            let end = (at + n).min(data.len());
            data.drain(at..end);
        }
        if let Some((at, bytes)) = insert {
            let at = at.index(data.len() + 1);
            data.splice(at..at, bytes);
        }
        if let Ok((salvaged, report)) = ScanStore::salvage_from(&data) {
            prop_assert_eq!(report.records_recovered, salvaged.len());
            // (Damage that turns the version into 1 gives unverified records, said so.)
            for s in salvaged.iter().filter(|_| report.verified) {
                prop_assert_eq!(Some(s), store.get(s.robot, s.seq));
            }
        }
    }
}
