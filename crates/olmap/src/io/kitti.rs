//! KITTI velodyne scans (`.bin`): packed little-endian float32 records `x y z intensity`.
//!
//! The format of the KITTI odometry and raw benchmarks (and of many datasets that copied
//! it): no header, 16 bytes per point, metres in the sensor frame (x forward, y left,
//! z up), intensity (reflectance) in `[0, 1]`. A file whose size is not a multiple of
//! 16 bytes is truncated and rejected.

use std::io::{BufRead, Write};

use super::{finite_point, CloudFormat, LoadedCloud, ReadReport};
use crate::cloud::PointCloud;
use crate::error::ParseError;

const RECORD: usize = 16;

/// Reads a KITTI `.bin` stream.
pub fn read<R: BufRead>(mut reader: R) -> Result<LoadedCloud, ParseError> {
    let mut report = ReadReport::new(CloudFormat::KittiBin);
    report.fields = ["x", "y", "z", "intensity"].map(String::from).to_vec();
    let mut points = Vec::new();
    let mut intensity = Vec::new();
    let mut buf = vec![0u8; RECORD * 65536];
    let mut filled = 0usize;
    let mut total = 0u64;
    loop {
        let n = reader.read(&mut buf[filled..])?;
        if n == 0 {
            break;
        }
        filled += n;
        total += n as u64;
        let whole = filled / RECORD * RECORD;
        for rec in buf[..whole].chunks_exact(RECORD) {
            let f = |i: usize| f32::from_le_bytes([rec[i], rec[i + 1], rec[i + 2], rec[i + 3]]);
            report.records += 1;
            if let Some(p) = finite_point([f(0) as f64, f(4) as f64, f(8) as f64], &mut report) {
                points.push(p);
                intensity.push(f(12));
            }
        }
        buf.copy_within(whole..filled, 0);
        filled -= whole;
    }
    if total == 0 {
        return Err(ParseError::Empty);
    }
    if filled != 0 {
        return Err(ParseError::Truncated(format!(
            "{total} bytes is not a whole number of 16-byte records (x y z intensity as float32); the last record has {filled} bytes"
        )));
    }
    let mut cloud = PointCloud::from_points(points);
    cloud.set_intensity(Some(intensity)).expect("same length");
    Ok(LoadedCloud { cloud, report })
}

/// Writes a KITTI `.bin` stream (intensity 0 where the cloud has none).
pub fn write<W: Write>(mut w: W, cloud: &PointCloud) -> std::io::Result<()> {
    let mut out = Vec::with_capacity(RECORD * 4096);
    for (i, p) in cloud.points().iter().enumerate() {
        let inten = cloud.intensity().map_or(0.0, |v| v[i]);
        for v in [p.x, p.y, p.z, inten] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        if out.len() >= RECORD * 4096 {
            w.write_all(&out)?;
            out.clear();
        }
    }
    w.write_all(&out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn round_trip_and_truncation() {
        let mut c = PointCloud::from_points(vec![
            Point3::new(1.5, -2.0, 0.25),
            Point3::new(f32::MAX, 0.0, -1e-30),
        ]);
        c.set_intensity(Some(vec![0.5, 1.0])).unwrap();
        let mut buf = Vec::new();
        write(&mut buf, &c).unwrap();
        assert_eq!(buf.len(), 32);
        assert_eq!(read(&buf[..]).unwrap().cloud, c);
        assert!(matches!(read(&buf[..31]), Err(ParseError::Truncated(_))));
        assert!(matches!(read(&b""[..]), Err(ParseError::Empty)));
    }
}
