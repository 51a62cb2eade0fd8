//! The ROS 2 message types olmap reads and writes, decoded and encoded directly (no schema
//! interpretation on the hot path): `std_msgs/Header`, `sensor_msgs/PointCloud2` and
//! `LaserScan`, `nav_msgs/Odometry` and `Path`, `geometry_msgs/PoseStamped`,
//! `tf2_msgs/TFMessage`.

use nalgebra::{Quaternion, Translation3, UnitQuaternion, Vector3};

use super::cdr::{CdrError, CdrReader, CdrWriter};
use crate::geometry::Pose;

/// `builtin_interfaces/Time`: seconds and nanoseconds since the epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default, Hash)]
pub struct Stamp {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds (0..1e9).
    pub nanosec: u32,
}

impl Stamp {
    /// Nanoseconds since the epoch.
    pub fn nanos(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }

    /// Seconds since the epoch.
    pub fn seconds(self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }

    /// The stamp of `nanos` nanoseconds since the epoch.
    pub fn from_nanos(nanos: i64) -> Stamp {
        Stamp {
            sec: nanos.div_euclid(1_000_000_000) as i32,
            nanosec: nanos.rem_euclid(1_000_000_000) as u32,
        }
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Stamp, CdrError> {
        Ok(Stamp {
            sec: r.i32()?,
            nanosec: r.u32()?,
        })
    }

    fn write(self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// When the data was taken.
    pub stamp: Stamp,
    /// The frame the data is in.
    pub frame_id: String,
}

impl Header {
    fn read(r: &mut CdrReader<'_>) -> Result<Header, CdrError> {
        Ok(Header {
            stamp: Stamp::read(r)?,
            frame_id: r.string()?.to_string(),
        })
    }

    fn write(&self, w: &mut CdrWriter) {
        self.stamp.write(w);
        w.string(&self.frame_id);
    }
}

/// `sensor_msgs/PointField`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointField {
    /// Field name (`x`, `intensity`, `t`, ...).
    pub name: String,
    /// Byte offset within a point.
    pub offset: u32,
    /// Element type: 1 int8, 2 uint8, 3 int16, 4 uint16, 5 int32, 6 uint32, 7 float32,
    /// 8 float64.
    pub datatype: u8,
    /// Number of elements.
    pub count: u32,
}

/// `sensor_msgs/PointCloud2`, with its data borrowed from the message.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud2<'a> {
    /// Stamp and frame.
    pub header: Header,
    /// Rows (1 for an unorganised cloud).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// The per-point layout.
    pub fields: Vec<PointField>,
    /// Whether the data is big-endian.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// The points.
    pub data: &'a [u8],
    /// True when no point is invalid (NaN).
    pub is_dense: bool,
}

impl<'a> PointCloud2<'a> {
    /// Decodes a CDR message.
    pub fn decode(message: &'a [u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(message)?;
        let header = Header::read(&mut r)?;
        let height = r.u32()?;
        let width = r.u32()?;
        let n = r.count("PointField sequence", 13)?;
        let mut fields = Vec::with_capacity(n);
        for _ in 0..n {
            fields.push(PointField {
                name: r.string()?.to_string(),
                offset: r.u32()?,
                datatype: r.u8()?,
                count: r.u32()?,
            });
        }
        Ok(PointCloud2 {
            header,
            height,
            width,
            fields,
            is_bigendian: r.bool()?,
            point_step: r.u32()?,
            row_step: r.u32()?,
            data: r.byte_sequence()?,
            is_dense: r.bool()?,
        })
    }

    /// Encodes as a little-endian CDR message.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = CdrWriter::new();
        self.header.write(&mut w);
        w.u32(self.height);
        w.u32(self.width);
        w.u32(self.fields.len() as u32);
        for f in &self.fields {
            w.string(&f.name);
            w.u32(f.offset);
            w.u8(f.datatype);
            w.u32(f.count);
        }
        w.bool(self.is_bigendian);
        w.u32(self.point_step);
        w.u32(self.row_step);
        w.u32(self.data.len() as u32);
        w.bytes(self.data);
        w.bool(self.is_dense);
        w.finish()
    }
}

/// `sensor_msgs/LaserScan`.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Stamp and frame.
    pub header: Header,
    /// Angle of the first beam (rad, counter-clockwise from x).
    pub angle_min: f32,
    /// Angle of the last beam (rad).
    pub angle_max: f32,
    /// Angle between beams (rad).
    pub angle_increment: f32,
    /// Time between beams (s).
    pub time_increment: f32,
    /// Time between scans (s).
    pub scan_time: f32,
    /// Shortest valid range (m).
    pub range_min: f32,
    /// Longest valid range (m).
    pub range_max: f32,
    /// Ranges (m); outside `[range_min, range_max]` or non-finite = no return.
    pub ranges: Vec<f32>,
    /// Intensities (device units), empty or one per range.
    pub intensities: Vec<f32>,
}

impl LaserScan {
    /// Decodes a CDR message.
    pub fn decode(message: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(message)?;
        Ok(LaserScan {
            header: Header::read(&mut r)?,
            angle_min: r.f32()?,
            angle_max: r.f32()?,
            angle_increment: r.f32()?,
            time_increment: r.f32()?,
            scan_time: r.f32()?,
            range_min: r.f32()?,
            range_max: r.f32()?,
            ranges: r.f32_sequence()?,
            intensities: r.f32_sequence()?,
        })
    }
}

fn read_pose(r: &mut CdrReader<'_>) -> Result<Pose, CdrError> {
    let [x, y, z] = r.f64_array::<3>()?;
    let [qx, qy, qz, qw] = r.f64_array::<4>()?;
    Ok(pose_from(Vector3::new(x, y, z), [qx, qy, qz, qw]))
}

fn write_pose(w: &mut CdrWriter, pose: &Pose) {
    let t = pose.translation();
    let q = pose.rotation();
    for v in [t.x, t.y, t.z, q.i, q.j, q.k, q.w] {
        w.f64(v);
    }
}

/// A pose from a translation and an `(x, y, z, w)` quaternion, normalised (an all-zero
/// quaternion, which some drivers send for "no rotation", is taken as the identity).
pub fn pose_from(t: Vector3<f64>, q: [f64; 4]) -> Pose {
    let q = Quaternion::new(q[3], q[0], q[1], q[2]);
    let rot = if q.norm() > 1e-9 {
        UnitQuaternion::from_quaternion(q)
    } else {
        UnitQuaternion::identity()
    };
    Pose::from_isometry(nalgebra::Isometry3::from_parts(Translation3::from(t), rot))
}

/// `nav_msgs/Odometry` (the pose part: the twist is not used).
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Stamp and the odometry frame (`odom`).
    pub header: Header,
    /// The moving frame (`base_link`).
    pub child_frame_id: String,
    /// `T_header_child`.
    pub pose: Pose,
}

impl Odometry {
    /// Decodes a CDR message (the covariance and twist are read past).
    pub fn decode(message: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(message)?;
        let header = Header::read(&mut r)?;
        let child_frame_id = r.string()?.to_string();
        let pose = read_pose(&mut r)?;
        Ok(Odometry {
            header,
            child_frame_id,
            pose,
        })
    }
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose in the header's frame.
    pub pose: Pose,
}

impl PoseStamped {
    /// Decodes a CDR message.
    pub fn decode(message: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(message)?;
        Ok(PoseStamped {
            header: Header::read(&mut r)?,
            pose: read_pose(&mut r)?,
        })
    }

    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        write_pose(w, &self.pose);
    }
}

/// Encodes a `nav_msgs/Path`.
pub fn encode_path(header: &Header, poses: &[PoseStamped]) -> Vec<u8> {
    let mut w = CdrWriter::new();
    header.write(&mut w);
    w.u32(poses.len() as u32);
    for p in poses {
        p.write(&mut w);
    }
    w.finish()
}

/// `geometry_msgs/TransformStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// `T_parent_child`.
    pub transform: Pose,
}

/// Decodes a `tf2_msgs/TFMessage`.
pub fn decode_tf(message: &[u8]) -> Result<Vec<TransformStamped>, CdrError> {
    let mut r = CdrReader::new(message)?;
    let n = r.count("TransformStamped sequence", 8 + 4 + 4 + 56)?;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        out.push(TransformStamped {
            header: Header::read(&mut r)?,
            child_frame_id: r.string()?.to_string(),
            transform: read_pose(&mut r)?,
        });
    }
    Ok(out)
}

/// Encodes a `tf2_msgs/TFMessage`.
pub fn encode_tf(transforms: &[TransformStamped]) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.u32(transforms.len() as u32);
    for t in transforms {
        t.header.write(&mut w);
        w.string(&t.child_frame_id);
        write_pose(&mut w, &t.transform);
    }
    w.finish()
}

/// The `ros2msg` schema texts of the types olmap writes (definitions without comments).
pub mod schemas {
    const SEP: &str =
        "\n================================================================================\n";

    fn join(parts: &[&str]) -> String {
        let mut s = parts[0].to_string();
        for p in &parts[1..] {
            s.push_str(SEP);
            s.push_str(p);
        }
        s
    }

    const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
    const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
    const POSE: &str = "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n";
    const POINT: &str = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n";
    const QUAT: &str =
        "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";

    /// `sensor_msgs/msg/PointCloud2`.
    pub fn point_cloud2() -> String {
        join(&[
            "std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\n\
             bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
            HEADER,
            TIME,
            "MSG: sensor_msgs/PointField\nuint8 INT8 = 1\nuint8 UINT8 = 2\nuint8 INT16 = 3\n\
             uint8 UINT16 = 4\nuint8 INT32 = 5\nuint8 UINT32 = 6\nuint8 FLOAT32 = 7\n\
             uint8 FLOAT64 = 8\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n",
        ])
    }

    /// `nav_msgs/msg/Path`.
    pub fn path() -> String {
        join(&[
            "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n",
            HEADER,
            TIME,
            "MSG: geometry_msgs/PoseStamped\nstd_msgs/Header header\nPose pose\n",
            POSE,
            POINT,
            QUAT,
        ])
    }

    /// `tf2_msgs/msg/TFMessage`.
    pub fn tf_message() -> String {
        join(&[
            "geometry_msgs/TransformStamped[] transforms\n",
            "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\n\
             Transform transform\n",
            HEADER,
            TIME,
            "MSG: geometry_msgs/Transform\nVector3 translation\nQuaternion rotation\n",
            "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
            QUAT,
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::bag::dynamic;
    use crate::io::bag::schema::parse_schema;

    #[test]
    fn written_messages_decode_by_their_own_schemas() {
        let header = Header {
            stamp: Stamp { sec: 5, nanosec: 7 },
            frame_id: "map".into(),
        };
        let pose = Pose::from_xyz_ypr(1.0, 2.0, 3.0, 0.5, 0.1, -0.2);
        let tf = encode_tf(&[TransformStamped {
            header: header.clone(),
            child_frame_id: "base_link".into(),
            transform: pose,
        }]);
        let back = decode_tf(&tf).unwrap();
        assert_eq!(back[0].child_frame_id, "base_link");
        assert!((back[0].transform.translation() - pose.translation()).norm() < 1e-12);
        let defs = parse_schema("tf2_msgs/msg/TFMessage", &schemas::tf_message()).unwrap();
        let v = dynamic::decode(&defs, &tf).unwrap();
        let t0 = &v.to_json()["transforms"][0];
        assert_eq!(t0["header"]["frame_id"], "map");
        assert_eq!(t0["transform"]["translation"]["z"], 3.0);

        let path = encode_path(
            &header,
            &[PoseStamped {
                header: header.clone(),
                pose,
            }],
        );
        let defs = parse_schema("nav_msgs/msg/Path", &schemas::path()).unwrap();
        let v = dynamic::decode(&defs, &path).unwrap().to_json();
        assert_eq!(v["poses"][0]["pose"]["position"]["y"], 2.0);

        let data = [1u8, 2, 3, 4];
        let pc = PointCloud2 {
            header,
            height: 1,
            width: 1,
            fields: vec![PointField {
                name: "x".into(),
                offset: 0,
                datatype: 7,
                count: 1,
            }],
            is_bigendian: false,
            point_step: 4,
            row_step: 4,
            data: &data,
            is_dense: true,
        };
        let bytes = pc.encode();
        assert_eq!(PointCloud2::decode(&bytes).unwrap(), pc);
        let defs = parse_schema("sensor_msgs/msg/PointCloud2", &schemas::point_cloud2()).unwrap();
        let v = dynamic::decode(&defs, &bytes).unwrap().to_json();
        assert_eq!(v["fields"][0]["name"], "x");
        assert_eq!(v["is_dense"], true);
    }
}
