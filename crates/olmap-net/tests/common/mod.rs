//! Helpers shared by the network tests: free loopback ports, synthetic records, store bytes.

#![allow(dead_code)]

use std::path::Path;
use std::time::Duration;

use nalgebra::{Point3, UnitQuaternion, Vector3};
use olmap::cloud::PointCloud;
use olmap::geometry::Pose;
use olmap::team::{ScanStore, StoredScan, StoredSighting};
use olmap_net::{FaultPlan, NetOptions, NodeOptions};

/// A loopback TCP port nobody listens on now (bound, read and released).
pub fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind a loopback port");
    l.local_addr().unwrap().port()
}

/// A deterministic record: `n` points in a 10 m box, odometry, one sighting on odd seqs.
pub fn record(robot: u32, seq: u32, n: usize) -> StoredScan {
    let mut s = (robot as u64) << 32 | seq as u64 | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let points: Vec<Point3<f32>> = (0..n)
        .map(|_| {
            Point3::new(
                (next() * 10.0) as f32,
                (next() * 10.0) as f32,
                (next() * 3.0) as f32,
            )
        })
        .collect();
    let sightings = if seq % 2 == 1 {
        vec![StoredSighting {
            target: (robot + 1) % 4,
            range: 3.0,
            bearing: 0.2,
            elevation: 0.0,
            beacon: Point3::new(2.9, 0.6, 0.5),
            mutual: false,
        }]
    } else {
        Vec::new()
    };
    StoredScan {
        robot,
        seq,
        time: seq as f64 * 10.0,
        odometry: Some(Pose::from_parts(
            Vector3::new(seq as f64, robot as f64, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.1 * seq as f64),
        )),
        cloud: PointCloud::from_points(points).with_origin(Point3::new(0.0, 0.0, 0.5)),
        sightings,
    }
}

/// The bytes of a store in its file format (identical stores, identical bytes).
pub fn store_bytes(store: &ScanStore) -> Vec<u8> {
    let mut v = Vec::new();
    store.write_to(&mut v).unwrap();
    v
}

/// Options of a test node: loopback only, no scouting, a short period.
pub fn node_opts(
    dir: &Path,
    name: &str,
    role: &str,
    team: &str,
    listen: Option<u16>,
    connect: &[u16],
    faults: FaultPlan,
) -> NodeOptions {
    let mut o = NodeOptions::new(
        name,
        role,
        dir.join(format!("{name}.redb")),
        NetOptions::loopback(team, listen, connect),
    );
    o.period = Duration::from_millis(100);
    o.faults = faults;
    o
}
