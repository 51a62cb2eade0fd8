//! g2o pose-graph files: `VERTEX_SE2`, `EDGE_SE2`, `VERTEX_SE3:QUAT`, `EDGE_SE3:QUAT`
//! and `FIX`, read strictly and written so that they read back to the same numbers.
//!
//! Lines (whitespace-separated; `#` comments and blank lines are skipped):
//! * `VERTEX_SE2 id x y theta`;
//! * `EDGE_SE2 i j dx dy dtheta` + the 6 upper-triangular entries of the 3x3 information
//!   matrix, row by row;
//! * `VERTEX_SE3:QUAT id x y z qx qy qz qw`;
//! * `EDGE_SE3:QUAT i j x y z qx qy qz qw` + the 21 upper-triangular entries of the 6x6
//!   information matrix, row by row, translation first, then rotation;
//! * `FIX id [id ...]`: nodes the solver must not move.
//!
//! An edge's measurement is `T_i_j`; a vertex's pose is `T_world_vertex`. A file holds
//! either SE(2) or SE(3) elements. Any other element, a wrong field count, a bad number, a
//! duplicate vertex, an edge to an unknown vertex or a quaternion far from unit length is
//! an error naming the line. Memory stays bounded whatever a file holds: lines longer than
//! [`MAX_LINE`] bytes are refused before they are buffered, vertex ids are map keys (a huge
//! id allocates nothing), and at most [`MAX_ELEMENTS`] vertices and edges are read.
//! Edge kinds and kernels are not part of the format: edges read back as
//! [`EdgeKind::Generic`] without kernel.

use std::io::{BufRead, Read, Write};
use std::path::Path;

use nalgebra::{Matrix3, Matrix6, Quaternion, UnitQuaternion, Vector3};

use super::model::{Edge, EdgeKind, Kernel, Measurement, NodePose, PoseGraph, Se2, Space};
use crate::error::{ParseError, Result};
use crate::file::{parse_file, write_atomic};
use crate::geometry::Pose;

/// Longest line accepted, bytes (an SE(3) edge with 21 full-precision numbers is ~600).
pub const MAX_LINE: usize = 16 * 1024;

/// Most vertices plus edges read from one file.
pub const MAX_ELEMENTS: usize = 50_000_000;

/// Largest deviation of a file's quaternion norm from 1 (files store 6 or so digits).
const QUATERNION_TOLERANCE: f64 = 1e-3;

/// Reads a g2o file (see the module doc); errors name the file and line.
pub fn read_g2o(path: &Path) -> Result<PoseGraph> {
    parse_file(path, "g2o", parse_g2o)
}

/// Parses g2o text from a stream.
pub fn parse_g2o<R: BufRead>(mut reader: R) -> Result<PoseGraph, ParseError> {
    let mut graph: Option<PoseGraph> = None;
    let mut fixes: Vec<(usize, u64)> = Vec::new();
    let mut buf = Vec::with_capacity(512);
    let mut line_no = 0usize;
    let mut elements = 0usize;
    loop {
        buf.clear();
        let n = (&mut reader)
            .take(MAX_LINE as u64 + 1)
            .read_until(b'\n', &mut buf)?;
        if n == 0 {
            break;
        }
        line_no += 1;
        if buf.len() > MAX_LINE && buf.last() != Some(&b'\n') {
            return Err(ParseError::line(
                line_no,
                format!("line longer than {MAX_LINE} bytes"),
            ));
        }
        let line = std::str::from_utf8(&buf)
            .map_err(|_| ParseError::line(line_no, "not text (invalid UTF-8 bytes)"))?;
        let mut words = line.split_ascii_whitespace();
        let Some(tag) = words.next() else {
            continue;
        };
        if tag.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = words.collect();
        let err = |reason: String| ParseError::line(line_no, reason);
        let space = match tag {
            "VERTEX_SE2" | "EDGE_SE2" => Space::Se2,
            "VERTEX_SE3:QUAT" | "EDGE_SE3:QUAT" => Space::Se3,
            "FIX" => {
                if fields.is_empty() {
                    return Err(err("FIX without a vertex id".into()));
                }
                for f in &fields {
                    fixes.push((line_no, parse_id(f).map_err(err)?));
                }
                continue;
            }
            other => {
                return Err(err(format!(
                    "unsupported element '{}' (olmap reads VERTEX_SE2, EDGE_SE2, VERTEX_SE3:QUAT, EDGE_SE3:QUAT and FIX)",
                    other.chars().take(40).collect::<String>()
                )))
            }
        };
        let g = graph.get_or_insert_with(|| PoseGraph::new(space));
        if g.space() != space {
            return Err(err(format!(
                "{tag} in a file of {} elements (a file is either SE(2) or SE(3))",
                match g.space() {
                    Space::Se2 => "SE(2)",
                    Space::Se3 => "SE(3)",
                }
            )));
        }
        elements += 1;
        if elements > MAX_ELEMENTS {
            return Err(err(format!(
                "more than {MAX_ELEMENTS} vertices and edges (olmap's limit)"
            )));
        }
        let expected = match tag {
            "VERTEX_SE2" => 4,
            "EDGE_SE2" => 2 + 3 + 6,
            "VERTEX_SE3:QUAT" => 8,
            _ => 2 + 7 + 21,
        };
        if fields.len() != expected {
            return Err(err(format!(
                "{tag} needs {expected} fields after the tag, found {}",
                fields.len()
            )));
        }
        let nums = |from: usize| -> Result<Vec<f64>, ParseError> {
            fields[from..]
                .iter()
                .enumerate()
                .map(|(k, f)| {
                    f.parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| {
                            err(format!(
                                "{tag} field {}: '{}' is not a finite number",
                                from + k + 1,
                                f.chars().take(40).collect::<String>()
                            ))
                        })
                })
                .collect()
        };
        let added = match tag {
            "VERTEX_SE2" => {
                let id = parse_id(fields[0]).map_err(err)?;
                let v = nums(1)?;
                g.add_node(id, NodePose::Se2(Se2::new(v[0], v[1], v[2])))
                    .map(|_| ())
            }
            "VERTEX_SE3:QUAT" => {
                let id = parse_id(fields[0]).map_err(err)?;
                let v = nums(1)?;
                let pose = pose_from(&v).map_err(err)?;
                g.add_node(id, NodePose::Se3(pose)).map(|_| ())
            }
            "EDGE_SE2" => {
                let (i, j) = (
                    parse_id(fields[0]).map_err(err)?,
                    parse_id(fields[1]).map_err(err)?,
                );
                let v = nums(2)?;
                let info = upper_triangular::<3>(&v[3..]);
                g.add_edge(Edge {
                    from: i,
                    to: j,
                    kind: EdgeKind::Generic,
                    measurement: Measurement::Se2 {
                        t_i_j: Se2::new(v[0], v[1], v[2]),
                        information: Matrix3::from_fn(|r, c| info[r * 3 + c]),
                    },
                    kernel: Kernel::None,
                })
                .map(|_| ())
            }
            _ => {
                let (i, j) = (
                    parse_id(fields[0]).map_err(err)?,
                    parse_id(fields[1]).map_err(err)?,
                );
                let v = nums(2)?;
                let pose = pose_from(&v[..7]).map_err(err)?;
                let info = upper_triangular::<6>(&v[7..]);
                g.add_edge(Edge {
                    from: i,
                    to: j,
                    kind: EdgeKind::Generic,
                    measurement: Measurement::Se3 {
                        t_i_j: pose,
                        information: Matrix6::from_fn(|r, c| info[r * 6 + c]),
                    },
                    kernel: Kernel::None,
                })
                .map(|_| ())
            }
        };
        added.map_err(|e| err(format!("{e}")))?;
    }
    let Some(mut graph) = graph else {
        return Err(ParseError::Empty);
    };
    for (line, id) in fixes {
        graph.set_fixed(id, true).map_err(|_| {
            ParseError::line(
                line,
                format!("FIX names vertex {id}, which the file does not define"),
            )
        })?;
    }
    Ok(graph)
}

fn parse_id(s: &str) -> Result<u64, String> {
    s.parse::<u64>().map_err(|_| {
        format!(
            "'{}' is not a vertex id (a non-negative integer)",
            s.chars().take(40).collect::<String>()
        )
    })
}

/// `x y z qx qy qz qw` as a pose; the quaternion must have unit norm within
/// [`QUATERNION_TOLERANCE`] (it is renormalised).
fn pose_from(v: &[f64]) -> Result<Pose, String> {
    let q = Quaternion::new(v[6], v[3], v[4], v[5]);
    let n = q.norm();
    if (n - 1.0).abs() > QUATERNION_TOLERANCE {
        return Err(format!(
            "the quaternion (qx qy qz qw) = ({} {} {} {}) has norm {n}, expected 1",
            v[3], v[4], v[5], v[6]
        ));
    }
    Ok(Pose::from_parts(
        Vector3::new(v[0], v[1], v[2]),
        UnitQuaternion::new_normalize(q),
    ))
}

/// A symmetric N x N matrix (row-major) from its upper triangle, row by row.
fn upper_triangular<const N: usize>(v: &[f64]) -> Vec<f64> {
    let mut m = vec![0.0; N * N];
    let mut k = 0;
    for r in 0..N {
        for c in r..N {
            m[r * N + c] = v[k];
            m[c * N + r] = v[k];
            k += 1;
        }
    }
    m
}

/// Writes a graph as a g2o file (atomically): vertices in the graph's order, then edges,
/// then one `FIX` line per fixed node. Numbers are written in Rust's shortest round-trip
/// form, so the file reads back to the same values.
pub fn write_g2o(path: &Path, graph: &PoseGraph) -> Result<()> {
    write_atomic(path, "g2o", |w| write_g2o_to(w, graph))
}

/// Writes g2o text to a stream (see [`write_g2o`]).
pub fn write_g2o_to<W: Write>(w: &mut W, graph: &PoseGraph) -> std::io::Result<()> {
    for n in graph.nodes() {
        match n.pose {
            NodePose::Se2(p) => writeln!(w, "VERTEX_SE2 {} {} {} {}", n.id, p.x, p.y, p.theta)?,
            NodePose::Se3(p) => {
                let t = p.translation();
                let q = p.rotation();
                writeln!(
                    w,
                    "VERTEX_SE3:QUAT {} {} {} {} {} {} {} {}",
                    n.id, t.x, t.y, t.z, q.i, q.j, q.k, q.w
                )?
            }
        }
    }
    for e in graph.edges() {
        match &e.measurement {
            Measurement::Se2 { t_i_j, information } => {
                write!(
                    w,
                    "EDGE_SE2 {} {} {} {} {}",
                    e.from, e.to, t_i_j.x, t_i_j.y, t_i_j.theta
                )?;
                for r in 0..3 {
                    for c in r..3 {
                        write!(w, " {}", information[(r, c)])?;
                    }
                }
                writeln!(w)?;
            }
            Measurement::Se3 { t_i_j, information } => {
                let t = t_i_j.translation();
                let q = t_i_j.rotation();
                write!(
                    w,
                    "EDGE_SE3:QUAT {} {} {} {} {} {} {} {} {}",
                    e.from, e.to, t.x, t.y, t.z, q.i, q.j, q.k, q.w
                )?;
                for r in 0..6 {
                    for c in r..6 {
                        write!(w, " {}", information[(r, c)])?;
                    }
                }
                writeln!(w)?;
            }
        }
    }
    for n in graph.nodes().iter().filter(|n| n.fixed) {
        writeln!(w, "FIX {}", n.id)?;
    }
    Ok(())
}
