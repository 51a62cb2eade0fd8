//! 3DTK (slam6D) pose files: `scanNNN.pose` (initial estimate) and `scanNNN.frames`
//! (registration history). Both are converted to olmap's right-handed metres.
//!
//! * `.pose`: six numbers, `x y z` in cm then `θx θy θz` in **degrees**, in 3DTK's
//!   left-handed frame; the rotation is `R = Rx(θx) Ry(θy) Rz(θz)` (`EulerToMatrix4`) and
//!   `p_global = R p + t`. It is the pose "as given by e.g. odometry", not a registration.
//! * `.frames`: one frame per line, 16 numbers = a 4x4 matrix in **column-major** (OpenGL)
//!   order (translation in elements 12-14, cm), then the algorithm code of the step that
//!   produced it (0 invalid, 1 ICP, 2 ICP inactive, 3 LUM, 4 ELCH). The **last** frame is the
//!   final registered pose. The 2009 legacy layout (each matrix line followed by an RGBA
//!   colour line) is read too; colours map to codes as 3DTK's `convert.py` did.
//!
//! Conversion to right-handed metres: see [`crate::geometry::pose_rh_m_from_3dtk_cm`].

use std::io::{BufRead, Write};
use std::path::Path;

use nalgebra::{Matrix4, Rotation3, Vector3};

use crate::error::{ParseError, Result};
use crate::file::text::{for_each_line, is_blank_or_comment, parse_f64};
use crate::geometry::{pose_3dtk_cm_from_rh_m, pose_rh_m_from_3dtk_cm, Pose};

/// Rotation tolerance for matrices written with six significant digits.
const TOLERANCE: f64 = 1e-3;

/// The processing step that produced a frame (3DTK's `Scan::AlgoType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AlgoType {
    /// 0: invalid.
    Invalid,
    /// 1: ICP.
    Icp,
    /// 2: ICP, scan inactive.
    IcpInactive,
    /// 3: LUM (global relaxation).
    Lum,
    /// 4: ELCH (loop closing).
    Elch,
    /// Any other code.
    Other(i64),
}

impl AlgoType {
    /// The type of a numeric code.
    pub fn from_code(code: i64) -> Self {
        match code {
            0 => AlgoType::Invalid,
            1 => AlgoType::Icp,
            2 => AlgoType::IcpInactive,
            3 => AlgoType::Lum,
            4 => AlgoType::Elch,
            c => AlgoType::Other(c),
        }
    }

    /// The numeric code.
    pub fn code(self) -> i64 {
        match self {
            AlgoType::Invalid => 0,
            AlgoType::Icp => 1,
            AlgoType::IcpInactive => 2,
            AlgoType::Lum => 3,
            AlgoType::Elch => 4,
            AlgoType::Other(c) => c,
        }
    }
}

/// One line of a `.frames` file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// The scan's pose in the global (first scan's) frame, right-handed metres.
    pub pose: Pose,
    /// The step that produced it; `None` for a legacy colour that maps to no code.
    pub algo: Option<AlgoType>,
}

fn parse_numbers(line: &str, line_no: usize) -> Result<Vec<f64>, ParseError> {
    line.split_whitespace()
        .map(|t| {
            parse_f64(t.as_bytes())
                .ok_or_else(|| ParseError::line(line_no, format!("'{t}' is not a number")))
        })
        .collect()
}

/// The left-handed rotation `Rx(ax) Ry(ay) Rz(az)` of a `.pose` file (radians).
fn rotation_3dtk(ax: f64, ay: f64, az: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::x_axis(), ax)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), ay)
        * Rotation3::from_axis_angle(&Vector3::z_axis(), az)
}

/// Reads a `.pose` stream as `T_global_scan` in right-handed metres.
pub fn read_pose<R: BufRead>(reader: R) -> Result<Pose, ParseError> {
    let mut values = Vec::new();
    let mut any = false;
    for_each_line(reader, |line_no, line| {
        any = true;
        if is_blank_or_comment(line) {
            return Ok(());
        }
        values.extend(parse_numbers(line, line_no)?);
        Ok(())
    })?;
    if !any {
        return Err(ParseError::Empty);
    }
    if values.len() != 6 {
        return Err(ParseError::Malformed(format!(
            "expected 6 numbers (x y z in cm, then rotations about x y z in degrees), found {}",
            values.len()
        )));
    }
    let r = rotation_3dtk(
        values[3].to_radians(),
        values[4].to_radians(),
        values[5].to_radians(),
    );
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(r.matrix());
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&Vector3::new(values[0], values[1], values[2]));
    pose_rh_m_from_3dtk_cm(&m, TOLERANCE).map_err(|e| ParseError::Malformed(e.to_string()))
}

/// Writes a `.pose` stream for a right-handed metre pose.
pub fn write_pose<W: Write>(mut w: W, pose: &Pose) -> std::io::Result<()> {
    let m = pose_3dtk_cm_from_rh_m(pose);
    // Decompose R = Rx(a) Ry(b) Rz(c): R02 = sin b, R12 = -sin a cos b, R22 = cos a cos b,
    // R01 = -cos b sin c, R00 = cos b cos c.
    let b = m[(0, 2)].clamp(-1.0, 1.0).asin();
    let a = (-m[(1, 2)]).atan2(m[(2, 2)]);
    let c = (-m[(0, 1)]).atan2(m[(0, 0)]);
    writeln!(w, "{} {} {}", m[(0, 3)], m[(1, 3)], m[(2, 3)])?;
    writeln!(
        w,
        "{} {} {}",
        a.to_degrees(),
        b.to_degrees(),
        c.to_degrees()
    )
}

fn legacy_color_code(rgba: &[f64]) -> Option<AlgoType> {
    let key: Vec<i64> = rgba.iter().map(|v| v.round() as i64).collect();
    match key.as_slice() {
        [-1, 0, 0, 1] => Some(AlgoType::Invalid),
        [0, 0, 1, 1] => Some(AlgoType::Icp),
        [1, 1, 0, 1] => Some(AlgoType::IcpInactive),
        [1, 0, 0, 1] => Some(AlgoType::Lum),
        _ => None,
    }
}

/// Reads a `.frames` stream (current or legacy layout); at least one frame is required.
pub fn read_frames<R: BufRead>(reader: R) -> Result<Vec<Frame>, ParseError> {
    let mut frames: Vec<Frame> = Vec::new();
    // A legacy matrix line waiting for its colour line.
    let mut pending: Option<(usize, Pose)> = None;
    let mut any = false;
    for_each_line(reader, |line_no, line| {
        any = true;
        if is_blank_or_comment(line) {
            return Ok(());
        }
        let v = parse_numbers(line, line_no)?;
        if let Some((_, pose)) = pending.take() {
            if v.len() != 4 {
                return Err(ParseError::line(
                    line_no,
                    format!(
                        "legacy .frames: expected an RGBA colour line (4 numbers), found {}",
                        v.len()
                    ),
                ));
            }
            frames.push(Frame {
                pose,
                algo: legacy_color_code(&v),
            });
            return Ok(());
        }
        if v.len() != 16 && v.len() != 17 {
            return Err(ParseError::line(
                line_no,
                format!(
                    "expected 16 matrix elements (column-major) and a type code, found {} numbers",
                    v.len()
                ),
            ));
        }
        let m = Matrix4::from_column_slice(&v[..16]);
        let pose = pose_rh_m_from_3dtk_cm(&m, TOLERANCE).map_err(|e| {
            ParseError::line(line_no, e.to_string().replace("invalid argument: ", ""))
        })?;
        if v.len() == 17 {
            frames.push(Frame {
                pose,
                algo: Some(AlgoType::from_code(v[16] as i64)),
            });
        } else {
            pending = Some((line_no, pose));
        }
        Ok(())
    })?;
    if !any {
        return Err(ParseError::Empty);
    }
    if let Some((line_no, _)) = pending {
        return Err(ParseError::line(
            line_no,
            "legacy .frames: the last matrix has no colour line",
        ));
    }
    if frames.is_empty() {
        return Err(ParseError::Malformed("no frame found".into()));
    }
    Ok(frames)
}

/// Writes a `.frames` stream in the current layout.
pub fn write_frames<W: Write>(mut w: W, frames: &[Frame]) -> std::io::Result<()> {
    for f in frames {
        let m = pose_3dtk_cm_from_rh_m(&f.pose);
        for v in m.as_slice() {
            // nalgebra stores column-major, as the format wants.
            write!(w, "{v} ")?;
        }
        writeln!(w, "{}", f.algo.map_or(0, AlgoType::code))?;
    }
    Ok(())
}

/// Reads a `.pose` file.
pub fn read_pose_path(path: impl AsRef<Path>) -> Result<Pose> {
    crate::file::parse_file(path.as_ref(), "3DTK .pose", read_pose)
}

/// Reads a `.frames` file.
pub fn read_frames_path(path: impl AsRef<Path>) -> Result<Vec<Frame>> {
    crate::file::parse_file(path.as_ref(), "3DTK .frames", read_frames)
}

/// The final registered pose of a `.frames` file (its last frame).
pub fn read_final_frame_path(path: impl AsRef<Path>) -> Result<Pose> {
    Ok(read_frames_path(path)?
        .last()
        .expect("read_frames returns at least one frame")
        .pose)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_round_trip() {
        let p = Pose::from_xyz_ypr(1.57, 0.031, -0.075, 0.0149, 0.0237, 0.0102);
        let mut buf = Vec::new();
        write_pose(&mut buf, &p).unwrap();
        let back = read_pose(&buf[..]).unwrap();
        assert!((back.to_matrix4() - p.to_matrix4()).abs().max() < 1e-12);
    }

    #[test]
    fn frames_round_trip_and_legacy() {
        let frames = vec![
            Frame {
                pose: Pose::identity(),
                algo: Some(AlgoType::IcpInactive),
            },
            Frame {
                pose: Pose::from_xyz_ypr(1.5, 0.03, -0.09, 0.01, 0.01, 0.004),
                algo: Some(AlgoType::Icp),
            },
        ];
        let mut buf = Vec::new();
        write_frames(&mut buf, &frames).unwrap();
        let back = read_frames(&buf[..]).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[1].algo, Some(AlgoType::Icp));
        assert!(
            (back[1].pose.to_matrix4() - frames[1].pose.to_matrix4())
                .abs()
                .max()
                < 1e-12
        );
        let legacy = "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 \n0 0 1 1\n1 0 0 0 0 1 0 0 0 0 1 0 100 0 0 1 \n1 0 0 1\n";
        let back = read_frames(legacy.as_bytes()).unwrap();
        assert_eq!(back[0].algo, Some(AlgoType::Icp));
        assert_eq!(back[1].algo, Some(AlgoType::Lum));
        // x_lh = 100 cm to the right is y = -1 m.
        assert!((back[1].pose.translation() - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
        assert!(read_frames(&b"1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n"[..]).is_err());
        assert!(read_frames(&b"1 2 3\n"[..]).is_err());
        assert!(read_pose(&b"1 2 3\n4 5\n"[..]).is_err());
    }
}
