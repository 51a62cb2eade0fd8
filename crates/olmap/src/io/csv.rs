//! CSV point tables (libpointmatcher style) and CSV pose tables (`carCloudList.csv`).
//!
//! **Point tables.** One point per row; fields separated by commas (spaces around them
//! allowed) or by whitespace alone. The first row is a header when any of its fields is not
//! a number; columns are then found by name (case-insensitive): `x y z` (required),
//! `nx ny nz` or `normal_x normal_y normal_z` (normals), `intensity` / `reflectance` / `i`,
//! and `red green blue` or `r g b` (colours 0-255). Without a header the first three
//! columns are `x y z` and the rest is ignored. libpointmatcher's `car_cloud400.csv` has a
//! header and commas; `car_cloud401.csv`, despite its extension, has neither.
//!
//! **Pose tables.** A header `reading, gT00, gT01, ..., gT33`, then one row per cloud: its
//! file name and the 16 elements of a 4x4 rigid transform in row-major order
//! ([`read_pose_table`]).

use std::io::{BufRead, Write};
use std::path::Path;

use nalgebra::{Matrix4, Vector3};

use super::xyz::truncate;
use super::{finite_point, CloudFormat, LoadedCloud, ReadReport};
use crate::cloud::PointCloud;
use crate::error::{ParseError, Result};
use crate::file::text::{fields, for_each_line, is_blank_or_comment, parse_f64};
use crate::geometry::{Pose, PoseList};

#[derive(Default)]
struct Columns {
    xyz: [usize; 3],
    normal: Option<[usize; 3]>,
    intensity: Option<usize>,
    color: Option<[usize; 3]>,
    needed: usize,
}

impl Columns {
    fn positional() -> Self {
        Columns {
            xyz: [0, 1, 2],
            needed: 3,
            ..Default::default()
        }
    }

    fn from_header(names: &[String], line_no: usize) -> Result<Self, ParseError> {
        let find = |cands: &[&str]| names.iter().position(|n| cands.contains(&n.as_str()));
        let triple = |a: &[&str], b: &[&str], c: &[&str]| match (find(a), find(b), find(c)) {
            (Some(i), Some(j), Some(k)) => Some([i, j, k]),
            _ => None,
        };
        let xyz = triple(&["x"], &["y"], &["z"]).ok_or_else(|| {
            ParseError::line(
                line_no,
                format!(
                    "header has no x, y and z columns (found: {})",
                    names.join(", ")
                ),
            )
        })?;
        let normal = triple(
            &["nx", "normal_x"],
            &["ny", "normal_y"],
            &["nz", "normal_z"],
        );
        let intensity = find(&["intensity", "reflectance", "i"]);
        let color = triple(&["red", "r"], &["green", "g"], &["blue", "b"]);
        let needed = xyz
            .iter()
            .chain(normal.iter().flatten())
            .chain(intensity.iter())
            .chain(color.iter().flatten())
            .max()
            .map_or(3, |m| m + 1);
        Ok(Columns {
            xyz,
            normal,
            intensity,
            color,
            needed,
        })
    }
}

/// Reads a CSV point table.
pub fn read<R: BufRead>(reader: R) -> Result<LoadedCloud, ParseError> {
    let mut report = ReadReport::new(CloudFormat::Csv);
    let mut columns: Option<Columns> = None;
    let mut cloud = PointCloud::new();
    let mut values: Vec<f64> = Vec::with_capacity(16);
    let mut any_line = false;
    for_each_line(reader, |line_no, line| {
        any_line = true;
        if is_blank_or_comment(line) {
            return Ok(());
        }
        let cols = match &columns {
            Some(c) => c,
            None => {
                let tokens: Vec<&str> = fields(line).collect();
                let is_header = tokens.iter().any(|t| parse_f64(t.as_bytes()).is_none());
                let c = if is_header {
                    let names: Vec<String> = tokens
                        .iter()
                        .map(|t| t.trim().to_ascii_lowercase())
                        .collect();
                    let c = Columns::from_header(&names, line_no)?;
                    report.fields = names;
                    c
                } else {
                    report.fields = vec!["x".into(), "y".into(), "z".into()];
                    Columns::positional()
                };
                report.encoding = if line.contains(',') {
                    "comma-separated"
                } else {
                    "whitespace-separated"
                }
                .into();
                let header = is_header;
                // Set up attributes before the first point.
                if c.intensity.is_some() {
                    cloud.set_intensity(Some(Vec::new())).expect("empty cloud");
                }
                if c.normal.is_some() {
                    cloud.set_normals(Some(Vec::new())).expect("empty cloud");
                }
                if c.color.is_some() {
                    cloud.set_colors(Some(Vec::new())).expect("empty cloud");
                }
                columns = Some(c);
                if header {
                    return Ok(());
                }
                columns.as_ref().expect("just set")
            }
        };
        values.clear();
        for (i, t) in fields(line).enumerate() {
            if i >= cols.needed {
                break;
            }
            let v = parse_f64(t.as_bytes()).ok_or_else(|| {
                ParseError::line(
                    line_no,
                    format!("column {} is not a number: '{}'", i + 1, truncate(t, 30)),
                )
            })?;
            values.push(v);
        }
        if values.len() < cols.needed {
            return Err(ParseError::line(
                line_no,
                format!(
                    "expected at least {} columns, found {}",
                    cols.needed,
                    values.len()
                ),
            ));
        }
        report.records += 1;
        let [a, b, c] = cols.xyz;
        let Some(p) = finite_point([values[a], values[b], values[c]], &mut report) else {
            return Ok(());
        };
        let normal = cols
            .normal
            .map(|[i, j, k]| Vector3::new(values[i] as f32, values[j] as f32, values[k] as f32));
        let intensity = cols.intensity.map(|i| values[i] as f32);
        let color = cols
            .color
            .map(|idx| idx.map(|i| values[i].round().clamp(0.0, 255.0) as u8));
        cloud.push_with(p, intensity, normal, color);
        Ok(())
    })?;
    if !any_line {
        return Err(ParseError::Empty);
    }
    if columns.is_none() {
        return Err(ParseError::Malformed("no header and no data rows".into()));
    }
    Ok(LoadedCloud { cloud, report })
}

/// Writes a CSV point table with a header (`x,y,z[,nx,ny,nz][,intensity][,red,green,blue]`).
pub fn write<W: Write>(mut w: W, cloud: &PointCloud) -> std::io::Result<()> {
    let mut header = String::from("x,y,z");
    if cloud.normals().is_some() {
        header.push_str(",nx,ny,nz");
    }
    if cloud.intensity().is_some() {
        header.push_str(",intensity");
    }
    if cloud.colors().is_some() {
        header.push_str(",red,green,blue");
    }
    writeln!(w, "{header}")?;
    let mut line = String::with_capacity(128);
    for (i, p) in cloud.points().iter().enumerate() {
        use std::fmt::Write as _;
        line.clear();
        let _ = write!(line, "{},{},{}", p.x, p.y, p.z);
        if let Some(n) = cloud.normals() {
            let _ = write!(line, ",{},{},{}", n[i].x, n[i].y, n[i].z);
        }
        if let Some(v) = cloud.intensity() {
            let _ = write!(line, ",{}", v[i]);
        }
        if let Some(c) = cloud.colors() {
            let _ = write!(line, ",{},{},{}", c[i][0], c[i][1], c[i][2]);
        }
        line.push('\n');
        w.write_all(line.as_bytes())?;
    }
    Ok(())
}

/// Reads a pose table (`carCloudList.csv`): each row's name and its row-major 4x4 matrix.
///
/// For libpointmatcher's car data the matrix of a cloud is its pose in the frame of the
/// first cloud (`T_400_401` for `car_cloud401.csv`).
pub fn read_pose_table<R: BufRead>(reader: R) -> Result<PoseList, ParseError> {
    let mut list = PoseList::default();
    let mut seen_header = false;
    for_each_line(reader, |line_no, line| {
        if is_blank_or_comment(line) {
            return Ok(());
        }
        let tokens: Vec<&str> = line.split(',').map(str::trim).collect();
        if !seen_header
            && tokens
                .iter()
                .skip(1)
                .any(|t| parse_f64(t.as_bytes()).is_none())
        {
            seen_header = true;
            return Ok(());
        }
        seen_header = true;
        if tokens.len() < 17 {
            return Err(ParseError::line(
                line_no,
                format!(
                    "expected a name and 16 matrix elements, found {} fields",
                    tokens.len()
                ),
            ));
        }
        let mut m = Matrix4::zeros();
        for (i, t) in tokens[1..17].iter().enumerate() {
            m[(i / 4, i % 4)] = parse_f64(t.as_bytes()).ok_or_else(|| {
                ParseError::line(
                    line_no,
                    format!("matrix element {} is not a number: '{t}'", i + 1),
                )
            })?;
        }
        let pose = Pose::from_matrix4(&m, crate::geometry::pose_file::ROTATION_TOLERANCE).map_err(
            |e| ParseError::line(line_no, e.to_string().replace("invalid argument: ", "")),
        )?;
        list.push(tokens[0], pose);
        Ok(())
    })?;
    if list.is_empty() {
        return Err(ParseError::Empty);
    }
    Ok(list)
}

/// Reads a pose table file; see [`read_pose_table`].
pub fn read_pose_table_path(path: impl AsRef<Path>) -> Result<PoseList> {
    crate::file::parse_file(path.as_ref(), "CSV pose table", read_pose_table)
}

/// Writes a pose table in the `carCloudList.csv` layout.
pub fn write_pose_table<W: Write>(mut w: W, poses: &PoseList) -> std::io::Result<()> {
    write!(w, "reading")?;
    for r in 0..4 {
        for c in 0..4 {
            write!(w, ", gT{r}{c}")?;
        }
    }
    writeln!(w)?;
    for np in &poses.poses {
        write!(w, "{}", np.name)?;
        let m = np.pose.to_matrix4();
        for r in 0..4 {
            for c in 0..4 {
                write!(w, ", {}", m[(r, c)])?;
            }
        }
        writeln!(w)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_by_name_and_positional() {
        let text = "z,x,y,intensity\n 3 , 1 , 2 , 0.5\n6,4,5,1\n";
        let l = read(text.as_bytes()).unwrap();
        assert_eq!(l.cloud.points()[0], nalgebra::Point3::new(1.0, 2.0, 3.0));
        assert_eq!(l.cloud.intensity().unwrap(), &[0.5, 1.0]);
        let text = "   1.0e+00   2.0e+00  3.0\n4 5 6\n";
        let l = read(text.as_bytes()).unwrap();
        assert_eq!(l.cloud.len(), 2);
        assert_eq!(l.report.encoding, "whitespace-separated");
    }

    #[test]
    fn round_trip_with_attributes() {
        let mut c = PointCloud::from_points(vec![nalgebra::Point3::new(0.1, -2.5, 3.25)]);
        c.set_normals(Some(vec![Vector3::new(0.0, 0.6, 0.8)]))
            .unwrap();
        c.set_intensity(Some(vec![12.5])).unwrap();
        c.set_colors(Some(vec![[1, 2, 255]])).unwrap();
        let mut buf = Vec::new();
        write(&mut buf, &c).unwrap();
        let back = read(&buf[..]).unwrap().cloud;
        assert_eq!(back, c);
    }

    #[test]
    fn errors() {
        assert!(read(&b"a,b,c\n1,2,3\n"[..]).is_err());
        let e = read(&b"x,y,z\n1,2,3\n1,2\n"[..]).unwrap_err().to_string();
        assert!(e.contains("line 3"), "{e}");
        assert!(read(&b""[..]).is_err());
    }

    #[test]
    fn pose_table_round_trip() {
        let mut list = PoseList::default();
        list.push("a.csv", Pose::identity());
        list.push(
            "b.csv",
            Pose::from_xyz_ypr(0.06, 0.19, -0.03, -0.15, -0.11, -0.16),
        );
        let mut buf = Vec::new();
        write_pose_table(&mut buf, &list).unwrap();
        let back = read_pose_table(&buf[..]).unwrap();
        assert_eq!(back.len(), 2);
        let d = back.poses[1].pose.to_matrix4() - list.poses[1].pose.to_matrix4();
        assert!(d.abs().max() < 1e-12);
    }
}
