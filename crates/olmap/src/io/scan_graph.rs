//! OctoMap's binary ScanGraph (`.graph`): a pose graph whose nodes carry 3D scans.
//!
//! Layout (`ScanGraph::writeBinary`, little-endian as written on x86):
//! ```text
//! u32 n_nodes; n_nodes x { Pointcloud; Pose6D; u32 id }
//! u32 n_edges; n_edges x { u32 first; u32 second; Pose6D constraint; f64 weight }
//! Pointcloud = u32 n_points; n_points x Vector3
//! Vector3    = i32 (= 3); f64 x; f64 y; f64 z
//! Pose6D     = Vector3 translation; Quaternion
//! Quaternion = i32 (= 4); f64 w; f64 x; f64 y; f64 z
//! ```
//! A node's points are in its sensor frame and its pose is `T_world_node`. [`read`] returns
//! all scans in the world frame, concatenated (sensor origin: the first node's position);
//! [`read_nodes`] keeps them apart. Edges are checked for completeness and ignored.

use std::io::{BufRead, Write};

use nalgebra::{Point3, Quaternion, UnitQuaternion, Vector3};

use super::{finite_point, CloudFormat, LoadedCloud, ReadReport};
use crate::cloud::PointCloud;
use crate::error::{Location, ParseError};
use crate::file::cursor::StreamCursor;
use crate::geometry::Pose;

/// One node of a ScanGraph: a scan in its sensor frame and the sensor's pose.
#[derive(Debug, Clone)]
pub struct ScanNode {
    /// The node id stored in the file.
    pub id: u32,
    /// `T_world_node`.
    pub pose: Pose,
    /// The scan, in the node's sensor frame.
    pub cloud: PointCloud,
}

/// Reading the tagged vectors and poses of a ScanGraph.
trait GraphValues {
    fn tagged(&mut self, tag: u32, n: usize, what: &str) -> Result<[f64; 4], ParseError>;
    fn pose(&mut self) -> Result<Pose, ParseError>;
}

impl<R: BufRead> GraphValues for StreamCursor<R> {
    fn tagged(&mut self, tag: u32, n: usize, what: &str) -> Result<[f64; 4], ParseError> {
        let at = self.pos();
        let t = self.u32(what)?;
        if t != tag {
            return Err(ParseError::at(
                Location::Byte(at),
                format!("{what}: expected the size tag {tag}, found {t}"),
            ));
        }
        let mut v = [0.0; 4];
        for x in v.iter_mut().take(n) {
            *x = self.f64(what)?;
        }
        Ok(v)
    }
    fn pose(&mut self) -> Result<Pose, ParseError> {
        let at = self.pos();
        let t = self.tagged(3, 3, "pose translation")?;
        let q = self.tagged(4, 4, "pose quaternion")?;
        let quat = Quaternion::new(q[0], q[1], q[2], q[3]);
        let norm = quat.norm();
        if !(norm.is_finite() && (norm - 1.0).abs() < 1e-3) || t.iter().any(|v| !v.is_finite()) {
            return Err(ParseError::at(
                Location::Byte(at),
                format!("pose is not a rigid transform (quaternion norm {norm})"),
            ));
        }
        Ok(Pose::from_parts(
            Vector3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_quaternion(quat),
        ))
    }
}

/// Points reserved up front per node at most; beyond that the vector grows as points
/// arrive, so a count claimed by the file allocates nothing that is not there.
const INITIAL_POINTS: u32 = 1 << 16;

/// Reads every node of a ScanGraph, scans in their sensor frames. The stream is read as it
/// comes, never whole; memory grows only with the points actually read.
pub fn read_nodes<R: BufRead>(reader: R) -> Result<(Vec<ScanNode>, ReadReport), ParseError> {
    let mut c = StreamCursor::new(reader);
    if c.at_end()? {
        return Err(ParseError::Empty);
    }
    let mut report = ReadReport::new(CloudFormat::ScanGraph);
    report.fields = vec!["x".into(), "y".into(), "z".into()];
    let n_nodes = c.u32("node count")?;
    let mut nodes = Vec::new();
    for node in 0..n_nodes {
        let at = c.pos();
        let n_points = c.u32("point count")?;
        let mut points = Vec::with_capacity(n_points.min(INITIAL_POINTS) as usize);
        for i in 0..n_points {
            let v = c.tagged(3, 3, "point").map_err(|e| match e {
                ParseError::Truncated(m) => ParseError::Truncated(format!(
                    "node {node} announces {n_points} points (count at byte {at}), the file \
                     ends in point {i}: {m}"
                )),
                e => e,
            })?;
            report.records += 1;
            if let Some(p) = finite_point([v[0], v[1], v[2]], &mut report) {
                points.push(p);
            }
        }
        let pose = c.pose()?;
        let id = c.u32("node id")?;
        nodes.push(ScanNode {
            id,
            pose,
            cloud: PointCloud::from_points(points),
        });
    }
    let n_edges = c.u32("edge count")?;
    for _ in 0..n_edges {
        c.u32("edge first id")?;
        c.u32("edge second id")?;
        c.pose()?;
        c.f64("edge weight")?;
    }
    Ok((nodes, report))
}

/// Reads a ScanGraph as one cloud in the world frame.
pub fn read<R: BufRead>(reader: R) -> Result<LoadedCloud, ParseError> {
    let (nodes, report) = read_nodes(reader)?;
    let world: Vec<PointCloud> = nodes.iter().map(|n| n.cloud.transformed(&n.pose)).collect();
    let mut cloud = PointCloud::concatenate(&world);
    if let Some(first) = nodes.first() {
        cloud.set_origin(Point3::from(first.pose.translation()));
    }
    Ok(LoadedCloud { cloud, report })
}

/// Writes a cloud as a one-node ScanGraph: the node sits at the cloud's sensor origin with
/// identity rotation, and holds the points relative to it.
pub fn write<W: Write>(w: W, cloud: &PointCloud) -> std::io::Result<()> {
    write_nodes(w, [(Pose::identity(), cloud)])
}

/// Writes clouds with their poses `T_world_scan` as a ScanGraph without edges (what
/// OctoMap's `graph2tree` inserts): node `i` (id `i`) sits at the pose of the cloud's
/// sensor origin, `T_world_scan * translation(origin)`, and holds the points relative to
/// that origin.
pub fn write_nodes<'a, W: Write>(
    mut w: W,
    clouds: impl IntoIterator<Item = (Pose, &'a PointCloud)>,
) -> std::io::Result<()> {
    let clouds: Vec<(Pose, &PointCloud)> = clouds.into_iter().collect();
    let vec3 = |out: &mut Vec<u8>, v: [f64; 3]| {
        out.extend_from_slice(&3i32.to_le_bytes());
        for x in v {
            out.extend_from_slice(&x.to_le_bytes());
        }
    };
    let count = |n: usize, what: &str| {
        u32::try_from(n).map_err(|_| std::io::Error::other(format!("more than 2^32 {what}")))
    };
    w.write_all(&count(clouds.len(), "clouds")?.to_le_bytes())?;
    for (id, (pose, cloud)) in clouds.iter().enumerate() {
        let o = cloud.origin();
        let mut out = Vec::with_capacity(8 + cloud.len() * 28 + 80);
        out.extend_from_slice(&count(cloud.len(), "points")?.to_le_bytes());
        for p in cloud.points() {
            vec3(
                &mut out,
                [p.x as f64 - o.x, p.y as f64 - o.y, p.z as f64 - o.z],
            );
        }
        let node = pose * &Pose::from_parts(o.coords, UnitQuaternion::identity());
        let t = node.translation();
        vec3(&mut out, [t.x, t.y, t.z]);
        let q = node.rotation();
        out.extend_from_slice(&4i32.to_le_bytes());
        for x in [q.w, q.i, q.j, q.k] {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.extend_from_slice(&count(id, "clouds")?.to_le_bytes());
        w.write_all(&out)?;
    }
    w.write_all(&0u32.to_le_bytes()) // no edges
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation() {
        let c = PointCloud::from_points(vec![
            Point3::new(1.0, 2.0, 3.0),
            Point3::new(-4.5, 0.0, 0.25),
        ])
        .with_origin(Point3::new(1.0, 0.0, -0.5));
        let mut buf = Vec::new();
        write(&mut buf, &c).unwrap();
        let back = read(&buf[..]).unwrap().cloud;
        assert_eq!(back, c);
        for cut in [0, 3, 10, buf.len() - 1] {
            assert!(read(&buf[..cut]).is_err(), "cut at {cut}");
        }
    }

    #[test]
    fn nodes_keep_their_poses_and_sensor_origins() {
        let a = PointCloud::from_points(vec![Point3::new(1.0, 0.0, 0.0)]);
        let b =
            PointCloud::from_points(vec![Point3::new(0.0, 2.0, 0.0), Point3::new(0.5, 0.0, 0.0)])
                .with_origin(Point3::new(0.0, 0.0, 1.0));
        let pa = Pose::from_xyz_ypr(3.0, 0.0, 0.0, 90.0, 0.0, 0.0);
        let pb = Pose::from_xyz_ypr(0.0, -1.0, 0.5, -30.0, 10.0, 0.0);
        let mut buf = Vec::new();
        write_nodes(&mut buf, [(pa, &a), (pb, &b)]).unwrap();
        let (nodes, _) = read_nodes(&buf[..]).unwrap();
        assert_eq!(nodes.len(), 2);
        assert_eq!(nodes[1].id, 1);
        for (node, (pose, cloud)) in nodes.iter().zip([(pa, &a), (pb, &b)]) {
            // Same points in the world, and the node sits at the sensor origin.
            let o = pose.transform_point(&cloud.origin());
            assert!((Point3::from(node.pose.translation()) - o).norm() < 1e-9);
            for (p, q) in node.cloud.points().iter().zip(cloud.points()) {
                let w1 = node.pose.transform_point(&p.cast::<f64>());
                let w2 = pose.transform_point(&q.cast::<f64>());
                assert!((w1 - w2).norm() < 1e-6, "{w1} {w2}");
            }
        }
    }
}
