//! The validation shared by [`ScanStore::insert`](super::ScanStore::insert) and the store
//! reader: names not empty; times, poses, sightings, origins and positions finite; odometry
//! rotations unit quaternions. Each check returns the reason in words.

use nalgebra::{Point3, Quaternion, Vector3};

use super::{StoredScan, StoredSighting};

/// Largest deviation of a stored quaternion's norm from 1.
const QUATERNION_TOLERANCE: f64 = 1e-6;

pub(super) fn check_name(name: &str) -> std::result::Result<(), String> {
    if name.is_empty() {
        return Err("a robot name must not be empty".into());
    }
    Ok(())
}

fn finite3(v: [f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

pub(super) fn check_time(t: f64) -> std::result::Result<(), String> {
    if t.is_finite() {
        Ok(())
    } else {
        Err(format!("time {t} is not finite"))
    }
}

pub(super) fn check_pose(t: &Vector3<f64>, q: &Quaternion<f64>) -> std::result::Result<(), String> {
    if !finite3([t.x, t.y, t.z]) || !q.coords.iter().all(|x| x.is_finite()) {
        return Err("the odometry pose is not finite".into());
    }
    let norm = q.norm();
    if (norm - 1.0).abs() > QUATERNION_TOLERANCE {
        return Err(format!(
            "the odometry rotation is not a unit quaternion (norm {norm})"
        ));
    }
    Ok(())
}

pub(super) fn check_sighting(s: &StoredSighting) -> std::result::Result<(), String> {
    if s.range.is_finite()
        && s.bearing.is_finite()
        && s.elevation.is_finite()
        && finite3([s.beacon.x, s.beacon.y, s.beacon.z])
    {
        Ok(())
    } else {
        Err(format!("the sighting of robot {} is not finite", s.target))
    }
}

pub(super) fn check_origin(o: &Point3<f64>) -> std::result::Result<(), String> {
    if finite3([o.x, o.y, o.z]) {
        Ok(())
    } else {
        Err("the sensor origin is not finite".into())
    }
}

pub(super) fn check_point(i: usize, p: &Point3<f32>) -> std::result::Result<(), String> {
    if p.x.is_finite() && p.y.is_finite() && p.z.is_finite() {
        Ok(())
    } else {
        Err(format!("point {i} is not finite"))
    }
}

pub(super) fn check_scan(s: &StoredScan) -> std::result::Result<(), String> {
    check_time(s.time)?;
    if let Some(p) = &s.odometry {
        check_pose(&p.translation(), p.rotation().quaternion())?;
    }
    for g in &s.sightings {
        check_sighting(g)?;
    }
    check_origin(&s.cloud.origin())?;
    for (i, p) in s.cloud.points().iter().enumerate() {
        check_point(i, p)?;
    }
    Ok(())
}
