//! The per-robot scan store (thesis §6.3.2): merge laws, synchronisation, conflicts, the
//! file format and its bad-input handling, and the records built from a simulated run.

use nalgebra::{Point3, Vector3};
use olmap::cloud::PointCloud;
use olmap::geometry::Pose;
use olmap::sim::{read_dataset, write_dataset};
use olmap::sim::{simulate, Scanner3d, SimConfig, SimRng, SpinningLidar, WorldKind};
use olmap::team::{ScanStore, StoredScan, StoredSighting};
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

fn with_crc(mut data: Vec<u8>) -> Vec<u8> {
    let n = data.len() - 4;
    let crc = olmap::file::crc32::crc32(&data[..n]);
    data[n..].copy_from_slice(&crc.to_le_bytes());
    data
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
    // Header: magic 8, version 4, name count 4, record count 8 -> first record at 24.
    let mut absurd = good.clone();
    absurd[16..24].copy_from_slice(&u64::MAX.to_le_bytes());
    check("absurd.olstore", &with_crc(absurd), "announced");
    // First record: robot 4, seq 4, time 8, odometry flag 1 -> pose at byte 41.
    let mut nan = good.clone();
    nan[41..49].copy_from_slice(&f64::NAN.to_le_bytes());
    check("nan.olstore", &with_crc(nan), "byte 41");
    let mut flipped = good.clone();
    let last = flipped.len() - 10;
    flipped[last] ^= 1;
    check("flipped.olstore", &flipped, "checksum");
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
