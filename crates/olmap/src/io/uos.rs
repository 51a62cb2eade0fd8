//! 3DTK's "uos" scan format (`scanNNN.3d`), converted to olmap's frame on reading.
//!
//! Text, one point per line `x y z` in **centimetres** in 3DTK's **left-handed** scanner
//! frame (y up, z forward, x right). Parsing follows 3DTK's `readASCII`: `#` comments and
//! empty lines skipped, up to 10 unparseable lines tolerated at the top (the 2009 files
//! start with `360 x 225`). Points are converted to right-handed metres
//! (`x = z_lh/100, y = -x_lh/100, z = y_lh/100`, see
//! [`crate::geometry::point_rh_m_from_3dtk_cm`]).
//!
//! The example scans contain near-sensor echoes (range < 20 cm) and a max-range sentinel
//! (about 3276.7 cm); [`read`] with `valid_only` keeps `20 cm <= r < 3270 cm`
//! ([`VALID_RANGE_CM`]), the filter the data README recommends.

use std::io::{BufRead, Write};

use nalgebra::Point3;

use super::xyz::read_with;
use super::{CloudFormat, LoadedCloud};
use crate::cloud::PointCloud;
use crate::error::ParseError;
use crate::geometry::{point_3dtk_cm_from_rh_m, point_rh_m_from_3dtk_cm};

/// The valid range band of 3DTK scans, centimetres: `[min, max)`.
pub const VALID_RANGE_CM: (f64, f64) = (20.0, 3270.0);

/// Reads a `.3d` stream; with `valid_only`, returns outside [`VALID_RANGE_CM`] are dropped
/// and counted in `dropped_invalid`.
pub fn read<R: BufRead>(reader: R, valid_only: bool) -> Result<LoadedCloud, ParseError> {
    let (lo, hi) = VALID_RANGE_CM;
    let mut loaded = read_with(
        reader,
        CloudFormat::Uos,
        |p| {
            if !valid_only {
                return true;
            }
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            r >= lo && r < hi
        },
        |p| {
            let q = point_rh_m_from_3dtk_cm(p);
            [q.x, q.y, q.z]
        },
    )?;
    loaded.report.encoding = "left-handed cm (converted)".into();
    Ok(loaded)
}

/// Writes a cloud as a `.3d` file (converted back to left-handed centimetres).
pub fn write<W: Write>(mut w: W, cloud: &PointCloud) -> std::io::Result<()> {
    let mut line = String::with_capacity(64);
    for p in cloud.points() {
        let [x, y, z] = point_3dtk_cm_from_rh_m(&Point3::new(p.x as f64, p.y as f64, p.z as f64));
        line.clear();
        use std::fmt::Write as _;
        let _ = writeln!(line, "{x} {y} {z}");
        w.write_all(line.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converts_and_filters() {
        let text = "360 x 225\n100 50 300\n5 5 5\n0 0 3276.7\n";
        let all = read(text.as_bytes(), false).unwrap();
        assert_eq!(all.cloud.len(), 3);
        assert_eq!(all.report.header_lines_skipped, 1);
        assert_eq!(all.cloud.points()[0], Point3::new(3.0, -1.0, 0.5));
        let valid = read(text.as_bytes(), true).unwrap();
        assert_eq!(valid.cloud.len(), 1);
        assert_eq!(valid.report.dropped_invalid, 2);
    }

    #[test]
    fn round_trip() {
        let cloud = PointCloud::from_points(vec![
            Point3::new(1.25, -0.5, 2.0),
            Point3::new(-3.1, 0.01, 0.7),
        ]);
        let mut buf = Vec::new();
        write(&mut buf, &cloud).unwrap();
        let back = read(&buf[..], false).unwrap().cloud;
        for (a, b) in cloud.points().iter().zip(back.points()) {
            assert!((a - b).norm() < 1e-6);
        }
    }
}
