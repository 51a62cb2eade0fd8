//! The pose list text format: one named pose `T_map_scan` per line.
//!
//! ```text
//! # comments start with '#'; empty lines are skipped
//! name r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz [extra columns ignored]
//! ```
//! The twelve numbers are the row-major 3x4 matrix of `T_map_scan` (`p_map = R p_scan + t`,
//! metres). This is the layout of `data/3dtk_dat/reference_poses_rh_m.txt`. A line of exactly
//! twelve numbers and no name (the KITTI odometry `poses.txt` layout) is accepted too and
//! named by its 0-based index among the poses. The writer appends yaw, pitch and roll in
//! degrees as three extra columns for people to read; readers ignore them.

use std::io::{BufRead, Write};
use std::path::Path;

use super::pose::Pose;
use crate::error::{ParseError, Result};
use crate::file::text::{for_each_line, parse_f64};

/// A pose with the name of the scan (or robot, or frame) it belongs to.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedPose {
    /// The scan's name (first column of the file).
    pub name: String,
    /// `T_map_scan`.
    pub pose: Pose,
}

/// An ordered list of named poses, as stored in a pose file.
///
/// ```
/// use olmap::geometry::{Pose, PoseList};
/// let mut list = PoseList::default();
/// list.push("scan000", Pose::identity());
/// list.push("scan001", Pose::from_xyz_ypr(1.5, 0.0, 0.0, 0.01, 0.0, 0.0));
/// let mut text = Vec::new();
/// list.write(&mut text).unwrap();
/// let back = PoseList::read(&text[..]).unwrap();
/// assert_eq!(back.get("scan001").unwrap(), list.get("scan001").unwrap());
/// ```
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PoseList {
    /// The poses in file order.
    pub poses: Vec<NamedPose>,
}

/// Largest deviation from orthonormality accepted for a rotation read from text.
pub const ROTATION_TOLERANCE: f64 = 1e-3;

impl PoseList {
    /// Appends a pose.
    pub fn push(&mut self, name: impl Into<String>, pose: Pose) {
        self.poses.push(NamedPose {
            name: name.into(),
            pose,
        });
    }

    /// The pose of the first entry with this name.
    pub fn get(&self, name: &str) -> Option<&Pose> {
        self.poses.iter().find(|p| p.name == name).map(|p| &p.pose)
    }

    /// Number of poses.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// Whether the list holds no pose.
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// Parses a pose list from a stream.
    pub fn read<R: BufRead>(reader: R) -> Result<Self, ParseError> {
        let mut list = PoseList::default();
        for_each_line(reader, |line_no, line| {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                return Ok(());
            }
            let tokens: Vec<&str> = line.split_whitespace().collect();
            let all_numeric = tokens.len() == 12 && tokens.iter().all(|t| t.parse::<f64>().is_ok());
            let (name, numbers) = if all_numeric {
                (list.poses.len().to_string(), &tokens[..])
            } else if tokens.len() >= 13 {
                (tokens[0].to_string(), &tokens[1..13])
            } else {
                return Err(ParseError::line(
                    line_no,
                    format!(
                        "expected a name and 12 numbers (row-major 3x4 matrix), found {} fields",
                        tokens.len()
                    ),
                ));
            };
            let mut m = [0.0; 12];
            for (i, t) in numbers.iter().enumerate() {
                m[i] = parse_f64(t.as_bytes()).ok_or_else(|| {
                    ParseError::line(
                        line_no,
                        format!("matrix element {} is not a number: '{t}'", i + 1),
                    )
                })?;
            }
            let pose = Pose::from_row_major_3x4(&m, ROTATION_TOLERANCE).map_err(|e| {
                ParseError::line(line_no, e.to_string().replace("invalid argument: ", ""))
            })?;
            list.push(name, pose);
            Ok(())
        })?;
        if list.is_empty() {
            return Err(ParseError::Empty);
        }
        Ok(list)
    }

    /// Writes the list in the pose file format (full precision: reading it back is exact
    /// to the last bit of every matrix element).
    pub fn write<W: Write>(&self, mut w: W) -> std::io::Result<()> {
        writeln!(
            w,
            "# olmap pose list: name, then T_map_scan as a row-major 3x4 matrix (r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz, metres),"
        )?;
        writeln!(
            w,
            "# then yaw pitch roll in degrees (ZYX; ignored when read)"
        )?;
        for np in &self.poses {
            if np.name.is_empty()
                || np.name.contains(char::is_whitespace)
                || np.name.starts_with('#')
            {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!(
                        "pose name '{}' must be non-empty, without spaces, not starting with '#'",
                        np.name
                    ),
                ));
            }
            write!(w, "{}", np.name)?;
            for v in np.pose.to_row_major_3x4() {
                write!(w, " {v}")?;
            }
            let (y, p, r) = np.pose.yaw_pitch_roll();
            writeln!(
                w,
                "  {:.4} {:.4} {:.4}",
                y.to_degrees(),
                p.to_degrees(),
                r.to_degrees()
            )?;
        }
        Ok(())
    }

    /// Reads a pose file.
    pub fn read_path(path: impl AsRef<Path>) -> Result<Self> {
        crate::file::parse_file(path.as_ref(), "pose list", Self::read)
    }

    /// Writes a pose file atomically (temporary file, then rename).
    pub fn write_path(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::file::write_atomic(path.as_ref(), "pose list", |w| self.write(w))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_named_unnamed_and_extra_columns() {
        let text =
            "# header\n\n000 1 0 0 0 0 1 0 0 0 0 1 0  0.0 -0.0 0.0\n1 0 0 2 0 1 0 3 0 0 1 4\n";
        let list = PoseList::read(text.as_bytes()).unwrap();
        assert_eq!(list.len(), 2);
        assert_eq!(list.poses[0].name, "000");
        assert_eq!(list.poses[1].name, "1");
        assert_eq!(
            list.poses[1].pose.translation(),
            nalgebra::Vector3::new(2.0, 3.0, 4.0)
        );
    }

    #[test]
    fn errors_name_the_line() {
        let text = "# header\nscan 1 0 0 0 0 1 0 0 0 0 x 0\n";
        let err = PoseList::read(text.as_bytes()).unwrap_err().to_string();
        assert!(err.contains("line 2"), "{err}");
        let text = "scan 1 0 0 0 0 1 0 0 0 0 0 0\n";
        let err = PoseList::read(text.as_bytes()).unwrap_err().to_string();
        assert!(err.contains("rotation"), "{err}");
        assert!(matches!(
            PoseList::read(&b"# nothing\n"[..]),
            Err(ParseError::Empty)
        ));
    }

    #[test]
    fn round_trip_is_exact() {
        let mut list = PoseList::default();
        list.push("a", Pose::from_xyz_ypr(0.1, -0.2, 0.3, 1.0, 0.2, -0.3));
        let mut buf = Vec::new();
        list.write(&mut buf).unwrap();
        let back = PoseList::read(&buf[..]).unwrap();
        let (a, b) = (
            list.poses[0].pose.to_row_major_3x4(),
            back.poses[0].pose.to_row_major_3x4(),
        );
        for i in 0..12 {
            assert!((a[i] - b[i]).abs() < 1e-14, "{i}: {} vs {}", a[i], b[i]);
        }
    }
}
