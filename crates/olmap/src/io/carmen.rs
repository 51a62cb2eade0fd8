//! CARMEN laser logs (`.log`, `.log.gz`, `.log.bz2`): the classic 2D SLAM benchmark format.
//!
//! One message per line. Only front-laser scans are read:
//!
//! `FLASER n r_1 … r_n x y theta odom_x odom_y odom_theta timestamp hostname logger_timestamp`
//!
//! `n` ranges in metres, beams evenly spaced over 180° from −90° (right) counter-clockwise,
//! `angle_k = −π/2 + k·π/n`; then the laser's pose (x, y in metres, theta in radians) and the
//! odometry pose. In the "corrected" logs of the Freiburg SLAM evaluation both poses are the
//! SLAM-corrected one. `ODOM`, `NEFF`, `PARAM`, `#` and other message lines are counted and
//! skipped. A range at or beyond the log's no-return value (the largest range in the log,
//! 50 or 81.9 m in the shared logs) is a no-return; [`CarmenScan::points`] drops it.
//!
//! Scans are named `scan000000`, `scan000001`, … in the order of the `FLASER` lines, the
//! same names `olmap poses LOG --out` and `olmap map LOG --poses-out` write, so their pose
//! lists compare with `olmap eval`.
//!
//! ```
//! use olmap::io::carmen::parse_carmen;
//! let log = "PARAM robot_frontlaser_offset 0.0\n\
//!            FLASER 4 1.0 2.0 50.0 1.5 0.5 0.0 0.1 0.5 0.0 0.1 12.5 host 12.5\n";
//! let log = parse_carmen(log.as_bytes()).unwrap();
//! assert_eq!(log.scans.len(), 1);
//! assert_eq!(log.skipped_lines, 1);
//! let scan = &log.scans[0];
//! assert_eq!(scan.ranges.len(), 4);
//! // Beam 0 points right (−90°): 1 m to the right of the laser.
//! let pts = scan.points(50.0, 0.0);
//! assert!((pts[0].x).abs() < 1e-9 && (pts[0].y + 1.0).abs() < 1e-9);
//! assert_eq!(pts.len(), 3); // the 50 m beam is a no-return
//! ```

use std::f64::consts::PI;
use std::io::BufRead;
use std::path::Path;

use nalgebra::Vector2;

use crate::error::{Error, ParseError, Result};
use crate::file::text::{fields, for_each_line, parse_f64};
use crate::geometry::{Pose, PoseList};

/// The most beams one `FLASER` line may announce (the shared logs have 180 and 360; a
/// line is at most 1 MiB anyway).
pub const MAX_BEAMS: usize = 100_000;

/// One `FLASER` message.
#[derive(Debug, Clone, PartialEq)]
pub struct CarmenScan {
    /// 1-based line of the message in the (decompressed) log.
    pub line: usize,
    /// The message's timestamp, seconds.
    pub time: f64,
    /// Ranges in metres, beam 0 at −90°, counter-clockwise.
    pub ranges: Vec<f32>,
    /// The laser's pose in the log's world frame: `(x, y, theta)`, metres and radians.
    pub pose: [f64; 3],
    /// The odometry pose `(x, y, theta)` (equal to `pose` in the corrected logs).
    pub odometry: [f64; 3],
}

impl CarmenScan {
    /// The bearing of beam `k` of `n`, radians: `−π/2 + k·π/n`.
    pub fn beam_angle(k: usize, n: usize) -> f64 {
        -PI / 2.0 + k as f64 * PI / n as f64
    }

    /// The returns as points in the laser's frame (x forward, y left), metres: beams with a
    /// range below `no_return` and above `min_range`.
    pub fn points(&self, no_return: f64, min_range: f64) -> Vec<Vector2<f64>> {
        let n = self.ranges.len();
        self.ranges
            .iter()
            .enumerate()
            .filter(|(_, &r)| (r as f64) < no_return && (r as f64) > min_range)
            .map(|(k, &r)| {
                let (s, c) = Self::beam_angle(k, n).sin_cos();
                Vector2::new(r as f64 * c, r as f64 * s)
            })
            .collect()
    }

    /// The laser's pose as a spatial pose in the plane z = 0.
    pub fn pose3(&self) -> Pose {
        Pose::from_xyz_ypr(self.pose[0], self.pose[1], 0.0, self.pose[2], 0.0, 0.0)
    }
}

/// A CARMEN log's laser scans.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CarmenLog {
    /// The `FLASER` messages in file order.
    pub scans: Vec<CarmenScan>,
    /// The largest range in the log, metres: the sensor's no-return value.
    pub max_range: f64,
    /// Lines of other messages (`ODOM`, `NEFF`, `PARAM`, comments) skipped.
    pub skipped_lines: usize,
}

impl CarmenLog {
    /// The name of scan `index`: `scan000000`, `scan000001`, …
    pub fn scan_name(index: usize) -> String {
        format!("scan{index:06}")
    }

    /// The scans' laser poses as a pose list named [`CarmenLog::scan_name`].
    pub fn poses(&self) -> PoseList {
        let mut list = PoseList::default();
        for (i, s) in self.scans.iter().enumerate() {
            list.push(Self::scan_name(i), s.pose3());
        }
        list
    }
}

/// Whether a file name looks like a CARMEN log (`.log`, `.log.gz`, `.log.bz2`,
/// case-insensitive).
pub fn is_carmen_path(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    name.ends_with(".log") || name.ends_with(".log.gz") || name.ends_with(".log.bz2")
}

/// Reads a CARMEN log (plain, gzip or bzip2; decompression capped as for clouds, see
/// [`super::max_decompressed_bytes`]).
pub fn read_carmen(path: impl AsRef<Path>) -> Result<CarmenLog> {
    let path = path.as_ref();
    let (reader, _compression, size) = super::open_text(path)?;
    let log = parse_carmen(reader)
        .map_err(|e| Error::read(path, "CARMEN log", super::decompression_limit(e, size)))?;
    if log.scans.is_empty() {
        return Err(Error::read(
            path,
            "CARMEN log",
            ParseError::Malformed("no FLASER line: the log holds no front-laser scan".into()),
        ));
    }
    Ok(log)
}

/// Parses a CARMEN log from a stream. Errors name the line.
pub fn parse_carmen<R: BufRead>(reader: R) -> std::result::Result<CarmenLog, ParseError> {
    let mut log = CarmenLog::default();
    for_each_line(reader, |line_no, line| {
        let mut it = fields(line);
        match it.next() {
            Some("FLASER") => {
                let scan = parse_flaser(line_no, it)?;
                for &r in &scan.ranges {
                    log.max_range = log.max_range.max(r as f64);
                }
                log.scans.push(scan);
            }
            _ => log.skipped_lines += 1,
        }
        Ok(())
    })?;
    Ok(log)
}

fn parse_flaser<'a>(
    line_no: usize,
    mut it: impl Iterator<Item = &'a str>,
) -> std::result::Result<CarmenScan, ParseError> {
    let bad = |what: String| ParseError::line(line_no, what);
    let n_text = it
        .next()
        .ok_or_else(|| bad("FLASER without a beam count".into()))?;
    let n: usize = n_text.parse().map_err(|_| {
        bad(format!(
            "FLASER beam count {n_text:?} is not a whole number"
        ))
    })?;
    if n == 0 || n > MAX_BEAMS {
        return Err(bad(format!(
            "FLASER announces {n} beams; expected 1 to {MAX_BEAMS}"
        )));
    }
    let mut number = |what: &str| -> std::result::Result<f64, ParseError> {
        let f = it
            .next()
            .ok_or_else(|| bad(format!("FLASER line ends before its {what}")))?;
        let v = parse_f64(f.as_bytes())
            .ok_or_else(|| bad(format!("FLASER {what} {f:?} is not a number")))?;
        if !v.is_finite() {
            return Err(bad(format!("FLASER {what} is {v}, not a finite number")));
        }
        Ok(v)
    };
    let mut ranges = Vec::with_capacity(n);
    for k in 0..n {
        let r = number(&format!("range {}", k + 1))?;
        if r < 0.0 {
            return Err(bad(format!("FLASER range {} is negative ({r} m)", k + 1)));
        }
        ranges.push(r as f32);
    }
    let pose = [number("x")?, number("y")?, number("theta")?];
    let odometry = [
        number("odometry x")?,
        number("odometry y")?,
        number("odometry theta")?,
    ];
    let time = number("timestamp")?;
    Ok(CarmenScan {
        line: line_no,
        time,
        ranges,
        pose,
        odometry,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_line_and_the_field() {
        let cases: [(&str, &str); 5] = [
            ("FLASER\n", "beam count"),
            ("# c\nFLASER 3 1 2\n", "ends before its range 3"),
            ("FLASER 2 1 -2 0 0 0 0 0 0 1\n", "negative"),
            ("FLASER 1 1 0 0 nan 0 0 0 1\n", "finite"),
            ("FLASER 1000000 1\n", "beams"),
        ];
        for (text, needle) in cases {
            let e = parse_carmen(text.as_bytes()).unwrap_err().to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
            assert!(e.contains("line"), "{text:?}: {e}");
        }
    }

    #[test]
    fn beams_sweep_counter_clockwise_from_the_right() {
        assert!((CarmenScan::beam_angle(0, 180) + PI / 2.0).abs() < 1e-12);
        assert!((CarmenScan::beam_angle(90, 180)).abs() < 1e-12);
        assert!((CarmenScan::beam_angle(180, 360)).abs() < 1e-12);
    }
}
