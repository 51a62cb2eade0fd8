//! Bit-exact identity of records: two records are identical when every number in them has
//! the same bit pattern (so `-0.0` and `0.0` differ, and a NaN equals itself). Merging uses
//! it; anything else under one key is a conflict.

use super::{StoredScan, StoredSighting};
use crate::cloud::PointCloud;
use crate::geometry::Pose;

fn same_f64(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits()
}

fn same_f32s(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

pub(super) fn same_option_pose(a: &Option<Pose>, b: &Option<Pose>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => {
            let (ta, tb) = (a.translation(), b.translation());
            let (qa, qb) = (a.rotation(), b.rotation());
            ta.iter().zip(tb.iter()).all(|(x, y)| same_f64(*x, *y))
                && qa
                    .coords
                    .iter()
                    .zip(qb.coords.iter())
                    .all(|(x, y)| same_f64(*x, *y))
        }
        _ => false,
    }
}

pub(super) fn same_sightings(a: &[StoredSighting], b: &[StoredSighting]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            x.target == y.target
                && x.mutual == y.mutual
                && same_f64(x.range, y.range)
                && same_f64(x.bearing, y.bearing)
                && same_f64(x.elevation, y.elevation)
                && x.beacon
                    .iter()
                    .zip(y.beacon.iter())
                    .all(|(p, q)| same_f64(*p, *q))
        })
}

fn same_cloud(a: &PointCloud, b: &PointCloud) -> bool {
    let (oa, ob) = (a.origin(), b.origin());
    oa.iter().zip(ob.iter()).all(|(x, y)| same_f64(*x, *y))
        && a.len() == b.len()
        && a.points()
            .iter()
            .zip(b.points())
            .all(|(p, q)| same_f32s(p.coords.as_slice(), q.coords.as_slice()))
        && match (a.intensity(), b.intensity()) {
            (None, None) => true,
            (Some(x), Some(y)) => same_f32s(x, y),
            _ => false,
        }
        && match (a.normals(), b.normals()) {
            (None, None) => true,
            (Some(x), Some(y)) => {
                x.len() == y.len()
                    && x.iter()
                        .zip(y)
                        .all(|(u, v)| same_f32s(u.as_slice(), v.as_slice()))
            }
            _ => false,
        }
        && a.colors() == b.colors()
}

pub(super) fn same_scan(a: &StoredScan, b: &StoredScan) -> bool {
    a.robot == b.robot
        && a.seq == b.seq
        && same_f64(a.time, b.time)
        && same_option_pose(&a.odometry, &b.odometry)
        && same_sightings(&a.sightings, &b.sightings)
        && same_cloud(&a.cloud, &b.cloud)
}
