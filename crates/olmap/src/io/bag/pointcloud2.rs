//! `sensor_msgs/PointCloud2` to olmap clouds: any field layout (offsets, padding,
//! `point_step`/`row_step`, either byte order, organised clouds), NaN returns dropped and
//! counted, `intensity` kept, per-point times (`time`, `t`, `timestamp`) returned.

use nalgebra::Point3;

use super::messages::{PointCloud2, PointField};
use crate::cloud::PointCloud;

/// A decoded `PointCloud2`.
#[derive(Debug, Clone)]
pub struct DecodedCloud {
    /// The valid points, in the message's frame; the sensor origin is the frame's origin.
    pub cloud: PointCloud,
    /// Per-point time offsets as the message stores them (same order as the points), when
    /// it has a `time`, `t` or `timestamp` field.
    pub times: Option<Vec<f64>>,
    /// Points in the message (`width × height`).
    pub records: u64,
    /// Points dropped because a coordinate was NaN or infinite.
    pub dropped_non_finite: u64,
    /// The message's field names.
    pub fields: Vec<String>,
}

fn type_size(datatype: u8) -> Option<usize> {
    Some(match datatype {
        1 | 2 => 1,
        3 | 4 => 2,
        5..=7 => 4,
        8 => 8,
        _ => return None,
    })
}

/// How to read one scalar field out of a point record.
#[derive(Debug, Clone, Copy)]
struct Reader {
    offset: usize,
    datatype: u8,
    big: bool,
}

impl Reader {
    #[inline]
    fn read(&self, p: &[u8]) -> f64 {
        let o = self.offset;
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let mut b = [0u8; $n];
                b.copy_from_slice(&p[o..o + $n]);
                (if self.big {
                    <$t>::from_be_bytes(b)
                } else {
                    <$t>::from_le_bytes(b)
                }) as f64
            }};
        }
        match self.datatype {
            1 => p[o] as i8 as f64,
            2 => p[o] as f64,
            3 => get!(i16, 2),
            4 => get!(u16, 2),
            5 => get!(i32, 4),
            6 => get!(u32, 4),
            7 => get!(f32, 4),
            _ => get!(f64, 8),
        }
    }
}

/// Checks the message's layout and decodes its points. Errors say which field or step is
/// wrong; nothing is allocated before the layout is known to fit the data.
pub fn decode_points(msg: &PointCloud2<'_>) -> Result<DecodedCloud, String> {
    let step = msg.point_step as usize;
    if step == 0 {
        return Err("point_step is 0".into());
    }
    for f in &msg.fields {
        let size = type_size(f.datatype)
            .ok_or_else(|| format!("field '{}' has unknown datatype {}", f.name, f.datatype))?;
        let end = (f.offset as u64) + (size as u64) * u64::from(f.count.max(1));
        if end > step as u64 {
            return Err(format!(
                "field '{}' (offset {}, {} × {} bytes) runs past point_step {}",
                f.name, f.offset, f.count, size, step
            ));
        }
    }
    let points = u64::from(msg.width) * u64::from(msg.height);
    let row_bytes = u64::from(msg.width) * step as u64;
    if u64::from(msg.row_step) < row_bytes {
        return Err(format!(
            "row_step {} is shorter than width {} × point_step {}",
            msg.row_step, msg.width, step
        ));
    }
    let needed = if msg.height == 0 {
        0
    } else {
        u64::from(msg.row_step) * u64::from(msg.height - 1) + row_bytes
    };
    if needed > msg.data.len() as u64 {
        return Err(format!(
            "the header claims {points} points ({} × {}, row_step {}) in {needed} bytes, but the \
             data holds {} bytes",
            msg.width,
            msg.height,
            msg.row_step,
            msg.data.len()
        ));
    }
    let find = |names: &[&str]| -> Option<&PointField> {
        names
            .iter()
            .find_map(|n| msg.fields.iter().find(|f| f.name == *n))
    };
    let reader = |f: &PointField| Reader {
        offset: f.offset as usize,
        datatype: f.datatype,
        big: msg.is_bigendian,
    };
    let axis = |n: &str| {
        find(&[n])
            .map(reader)
            .ok_or_else(|| format!("no '{n}' field (fields: {})", field_names(msg).join(", ")))
    };
    let (x, y, z) = (axis("x")?, axis("y")?, axis("z")?);
    let intensity = find(&["intensity", "intensities", "reflectivity"]).map(reader);
    let time = find(&["time", "t", "timestamp", "offset_time"]).map(reader);

    let n = points as usize;
    let mut pts: Vec<Point3<f32>> = Vec::with_capacity(n);
    let mut inten: Vec<f32> = Vec::with_capacity(if intensity.is_some() { n } else { 0 });
    let mut times: Vec<f64> = Vec::with_capacity(if time.is_some() { n } else { 0 });
    let fast = !msg.is_bigendian
        && cfg!(target_endian = "little")
        && [x, y, z].iter().all(|r| r.datatype == 7)
        && intensity.is_none()
        && time.is_none();
    for row in 0..msg.height as usize {
        let start = row * msg.row_step as usize;
        let bytes = &msg.data[start..start + row_bytes as usize];
        if fast {
            push_xyz_f32(bytes, step, [x.offset, y.offset, z.offset], &mut pts);
            continue;
        }
        for p in bytes.chunks_exact(step) {
            let q = Point3::new(x.read(p) as f32, y.read(p) as f32, z.read(p) as f32);
            if !(q.x.is_finite() && q.y.is_finite() && q.z.is_finite()) {
                continue;
            }
            pts.push(q);
            if let Some(r) = intensity {
                inten.push(r.read(p) as f32);
            }
            if let Some(r) = time {
                times.push(r.read(p));
            }
        }
    }
    let kept = pts.len() as u64;
    let mut cloud = PointCloud::from_points(pts);
    if intensity.is_some() {
        cloud
            .set_intensity(Some(inten))
            .map_err(|e| e.to_string())?;
    }
    Ok(DecodedCloud {
        cloud,
        times: time.map(|_| times),
        records: points,
        dropped_non_finite: points - kept,
        fields: field_names(msg),
    })
}

/// The plain `x y z float32` little-endian layout: the hot loop, ~1 ns a point.
#[inline(never)]
fn push_xyz_f32(bytes: &[u8], step: usize, offsets: [usize; 3], out: &mut Vec<Point3<f32>>) {
    let [ox, oy, oz] = offsets;
    let f = |p: &[u8], o: usize| f32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]]);
    for p in bytes.chunks_exact(step) {
        let q = Point3::new(f(p, ox), f(p, oy), f(p, oz));
        if q.x.is_finite() && q.y.is_finite() && q.z.is_finite() {
            out.push(q);
        }
    }
}

fn field_names(msg: &PointCloud2<'_>) -> Vec<String> {
    msg.fields.iter().map(|f| f.name.clone()).collect()
}

/// A `PointCloud2` layout of `x y z` float32 (and `intensity` when the cloud has it),
/// packed, little-endian: the bytes and the fields.
pub fn encode_points(cloud: &PointCloud) -> (Vec<PointField>, u32, Vec<u8>) {
    let with_i = cloud.intensity().is_some();
    let names: &[&str] = if with_i {
        &["x", "y", "z", "intensity"]
    } else {
        &["x", "y", "z"]
    };
    let fields = names
        .iter()
        .enumerate()
        .map(|(k, n)| PointField {
            name: (*n).into(),
            offset: 4 * k as u32,
            datatype: 7,
            count: 1,
        })
        .collect();
    let step = 4 * names.len();
    let mut data = Vec::with_capacity(step * cloud.len());
    for (k, p) in cloud.points().iter().enumerate() {
        for v in [p.x, p.y, p.z] {
            data.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(i) = cloud.intensity() {
            data.extend_from_slice(&i[k].to_le_bytes());
        }
    }
    (fields, step as u32, data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::bag::messages::Header;

    fn msg<'a>(
        fields: Vec<PointField>,
        step: u32,
        data: &'a [u8],
        w: u32,
        h: u32,
        row: u32,
        big: bool,
    ) -> PointCloud2<'a> {
        PointCloud2 {
            header: Header::default(),
            height: h,
            width: w,
            fields,
            is_bigendian: big,
            point_step: step,
            row_step: row,
            data,
            is_dense: false,
        }
    }

    fn field(name: &str, offset: u32, datatype: u8) -> PointField {
        PointField {
            name: name.into(),
            offset,
            datatype,
            count: 1,
        }
    }

    #[test]
    fn padded_organised_big_endian_layouts_decode() {
        // 2 x 2 organised cloud, big-endian: z f64 at 0, x f32 at 8, y i16 at 12, pad to 16;
        // rows padded to 40 bytes; one NaN point.
        let mut data = Vec::new();
        let pts = [
            (1.0f32, 2i16, 3.0f64),
            (f32::NAN, 0, 0.0),
            (4.0, -5, 6.0),
            (7.0, 8, 9.0),
        ];
        for (k, (x, y, z)) in pts.iter().enumerate() {
            data.extend_from_slice(&z.to_be_bytes());
            data.extend_from_slice(&x.to_be_bytes());
            data.extend_from_slice(&y.to_be_bytes());
            data.extend_from_slice(&[0, 0]);
            if k % 2 == 1 {
                data.extend_from_slice(&[0xAA; 8]);
            }
        }
        let fields = vec![field("z", 0, 8), field("x", 8, 7), field("y", 12, 3)];
        let d = decode_points(&msg(fields, 16, &data, 2, 2, 40, true)).unwrap();
        assert_eq!(d.records, 4);
        assert_eq!(d.dropped_non_finite, 1);
        let got: Vec<_> = d.cloud.points().iter().map(|p| (p.x, p.y, p.z)).collect();
        assert_eq!(got, [(1.0, 2.0, 3.0), (4.0, -5.0, 6.0), (7.0, 8.0, 9.0)]);
    }

    #[test]
    fn bad_layouts_are_refused_with_the_reason() {
        let data = [0u8; 32];
        let xyz = || vec![field("x", 0, 7), field("y", 4, 7), field("z", 8, 7)];
        let e = decode_points(&msg(xyz(), 8, &data, 2, 1, 16, false)).unwrap_err();
        assert!(e.contains("runs past point_step"), "{e}");
        let e = decode_points(&msg(xyz(), 16, &data, 2, 1, 8, false)).unwrap_err();
        assert!(e.contains("row_step"), "{e}");
        let e = decode_points(&msg(
            xyz(),
            16,
            &data,
            1_000_000,
            1_000_000,
            16_000_000,
            false,
        ))
        .unwrap_err();
        assert!(e.contains("1000000000000 points"), "{e}");
        let e =
            decode_points(&msg(vec![field("x", 0, 7)], 16, &data, 2, 1, 32, false)).unwrap_err();
        assert!(e.contains("no 'y' field"), "{e}");
        let e =
            decode_points(&msg(vec![field("x", 0, 9)], 16, &data, 2, 1, 32, false)).unwrap_err();
        assert!(e.contains("unknown datatype"), "{e}");
    }

    #[test]
    fn encoded_clouds_decode_to_the_same_points() {
        let mut cloud = PointCloud::from_points(vec![
            Point3::new(1.0, -2.0, 3.5),
            Point3::new(0.25, 0.0, -1.0),
        ]);
        cloud.set_intensity(Some(vec![10.0, 20.0])).unwrap();
        let (fields, step, data) = encode_points(&cloud);
        let d = decode_points(&msg(fields, step, &data, 2, 1, 2 * step, false)).unwrap();
        assert_eq!(d.cloud.points(), cloud.points());
        assert_eq!(d.cloud.intensity(), cloud.intensity());
    }
}
