//! Writing a cloud as PLY, `binary_little_endian` or `ascii`.

use std::io::{self, Write};

use nalgebra::Vector3;

use crate::cloud::PointCloud;
use crate::io::PlyEncoding;

/// Bytes of output buffered by the writer before a `write_all`.
const WRITE_CHUNK: usize = 1 << 16;

/// Writes a cloud as PLY: `binary_little_endian` or `ascii`, `float` x y z, then
/// `float intensity`, `float nx ny nz` and `uchar red green blue` where present, and the
/// sensor origin in a `comment olmap origin x y z` line. Reading the result back gives
/// the same cloud, bit for bit, in both encodings.
///
/// ```
/// use olmap::cloud::PointCloud;
/// use olmap::io::{ply, PlyEncoding};
/// let cloud = PointCloud::from_points(vec![nalgebra::Point3::new(0.1, 0.2, 0.3)]);
/// let mut bytes = Vec::new();
/// ply::write(&mut bytes, &cloud, PlyEncoding::Ascii).unwrap();
/// assert_eq!(ply::read(&bytes[..]).unwrap().cloud, cloud);
/// ```
pub fn write<W: Write>(mut w: W, cloud: &PointCloud, encoding: PlyEncoding) -> io::Result<()> {
    w.write_all(header_text(cloud, encoding).as_bytes())?;
    match encoding {
        PlyEncoding::BinaryLittleEndian => write_binary(&mut w, cloud)?,
        PlyEncoding::Ascii => write_ascii(&mut w, cloud)?,
    }
    w.flush()
}

/// The header the writer puts before the data.
fn header_text(cloud: &PointCloud, encoding: PlyEncoding) -> String {
    let o = cloud.origin();
    let format = match encoding {
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
        PlyEncoding::Ascii => "ascii",
    };
    let mut h = format!(
        "ply\nformat {format} 1.0\ncomment written by olmap\n\
         comment olmap origin {:?} {:?} {:?}\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n",
        o.x,
        o.y,
        o.z,
        cloud.len()
    );
    if cloud.intensity().is_some() {
        h.push_str("property float intensity\n");
    }
    if cloud.normals().is_some() {
        h.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if cloud.colors().is_some() {
        h.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    h.push_str("end_header\n");
    h
}

/// The attributes of point `i` (neutral values where an attribute list is short, which
/// the [`PointCloud`] invariant rules out).
type Attrs = (Option<f32>, Option<Vector3<f32>>, Option<[u8; 3]>);

fn attrs(cloud: &PointCloud, i: usize) -> Attrs {
    (
        cloud.intensity().map(|v| v.get(i).copied().unwrap_or(0.0)),
        cloud
            .normals()
            .map(|v| v.get(i).copied().unwrap_or_else(Vector3::zeros)),
        cloud.colors().map(|v| v.get(i).copied().unwrap_or([0; 3])),
    )
}

fn write_binary<W: Write>(w: &mut W, cloud: &PointCloud) -> io::Result<()> {
    let mut buf = Vec::with_capacity(WRITE_CHUNK + 64);
    for (i, p) in cloud.points().iter().enumerate() {
        for v in [p.x, p.y, p.z] {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        let (intensity, normal, color) = attrs(cloud, i);
        if let Some(v) = intensity {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(n) = normal {
            for v in [n.x, n.y, n.z] {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
        if let Some(c) = color {
            buf.extend_from_slice(&c);
        }
        if buf.len() >= WRITE_CHUNK {
            w.write_all(&buf)?;
            buf.clear();
        }
    }
    w.write_all(&buf)
}

fn write_ascii<W: Write>(w: &mut W, cloud: &PointCloud) -> io::Result<()> {
    use std::fmt::Write as _;
    let mut buf = String::with_capacity(WRITE_CHUNK + 256);
    for (i, p) in cloud.points().iter().enumerate() {
        let _ = write!(buf, "{} {} {}", p.x, p.y, p.z);
        let (intensity, normal, color) = attrs(cloud, i);
        if let Some(v) = intensity {
            let _ = write!(buf, " {v}");
        }
        if let Some(n) = normal {
            let _ = write!(buf, " {} {} {}", n.x, n.y, n.z);
        }
        if let Some(c) = color {
            let _ = write!(buf, " {} {} {}", c[0], c[1], c[2]);
        }
        buf.push('\n');
        if buf.len() >= WRITE_CHUNK {
            w.write_all(buf.as_bytes())?;
            buf.clear();
        }
    }
    w.write_all(buf.as_bytes())
}

#[cfg(test)]
mod tests {
    use crate::io::ply::tests::{sample, to_bytes};
    use crate::io::PlyEncoding;

    #[test]
    fn writer_header_is_as_documented() {
        let bytes = to_bytes(&sample(true, true, true), PlyEncoding::BinaryLittleEndian);
        let text = String::from_utf8_lossy(&bytes);
        let header: Vec<&str> = text.lines().take_while(|l| *l != "end_header").collect();
        assert_eq!(
            header,
            [
                "ply",
                "format binary_little_endian 1.0",
                "comment written by olmap",
                "comment olmap origin 0.30000000000000004 -1e-300 12345.678901234567",
                "element vertex 8",
                "property float x",
                "property float y",
                "property float z",
                "property float intensity",
                "property float nx",
                "property float ny",
                "property float nz",
                "property uchar red",
                "property uchar green",
                "property uchar blue",
            ]
        );
    }
}
