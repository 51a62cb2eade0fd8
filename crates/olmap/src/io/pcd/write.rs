//! Writing a cloud as PCD v0.7 in any of the three encodings.

use std::io::{self, Write};

use nalgebra::{Point3, Vector3};

use super::{pack_rgb, CHUNK_BYTES};
use crate::cloud::PointCloud;
use crate::file::lzf;
use crate::io::PcdEncoding;

/// Writes a cloud as PCD v0.7 in the given encoding.
///
/// Fields: `x y z`, then `intensity`, `normal_x normal_y normal_z` and `rgb` where the cloud
/// has them. Every encoding reads back bit for bit with [`read`](fn@super::read).
///
/// ```
/// use olmap::cloud::PointCloud;
/// use olmap::io::{pcd, PcdEncoding};
/// use nalgebra::Point3;
/// let cloud = PointCloud::from_points(vec![Point3::new(0.1, 0.2, 0.3)]);
/// let mut bytes = Vec::new();
/// pcd::write(&mut bytes, &cloud, PcdEncoding::Ascii).unwrap();
/// assert!(bytes.ends_with(b"DATA ascii\n0.1 0.2 0.3\n"));
/// assert_eq!(pcd::read(&bytes[..]).unwrap().cloud, cloud);
/// ```
pub fn write<W: Write>(mut w: W, cloud: &PointCloud, encoding: PcdEncoding) -> io::Result<()> {
    let columns = columns(cloud);
    write_header(&mut w, cloud, &columns, encoding)?;
    match encoding {
        PcdEncoding::Ascii => write_ascii(&mut w, cloud.len(), &columns)?,
        PcdEncoding::Binary => write_binary(&mut w, cloud.len(), &columns)?,
        PcdEncoding::BinaryCompressed => write_compressed(&mut w, cloud.len(), &columns)?,
    }
    w.flush()
}

/// One written field: every value is 4 bytes.
#[derive(Debug, Clone, Copy)]
enum Column<'a> {
    Coord(&'a [Point3<f32>], usize),
    Intensity(&'a [f32]),
    Normal(&'a [Vector3<f32>], usize),
    Rgb(&'a [[u8; 3]]),
}

impl Column<'_> {
    fn name(self) -> &'static str {
        match self {
            Column::Coord(_, k) => ["x", "y", "z"][k],
            Column::Intensity(_) => "intensity",
            Column::Normal(_, k) => ["normal_x", "normal_y", "normal_z"][k],
            Column::Rgb(_) => "rgb",
        }
    }

    fn is_float(self) -> bool {
        !matches!(self, Column::Rgb(_))
    }

    /// The 4 bytes of point `i` as a `u32` (float bits, or the packed colour).
    #[inline]
    fn word(self, i: usize) -> u32 {
        match self {
            Column::Coord(p, k) => p[i][k].to_bits(),
            Column::Intensity(v) => v[i].to_bits(),
            Column::Normal(n, k) => n[i][k].to_bits(),
            Column::Rgb(c) => pack_rgb(c[i]),
        }
    }
}

/// The columns written for a cloud, in file order.
fn columns(cloud: &PointCloud) -> Vec<Column<'_>> {
    let mut cols: Vec<Column> = (0..3).map(|k| Column::Coord(cloud.points(), k)).collect();
    if let Some(v) = cloud.intensity() {
        cols.push(Column::Intensity(v));
    }
    if let Some(n) = cloud.normals() {
        cols.extend((0..3).map(|k| Column::Normal(n, k)));
    }
    if let Some(c) = cloud.colors() {
        cols.push(Column::Rgb(c));
    }
    cols
}

fn write_header<W: Write>(
    w: &mut W,
    cloud: &PointCloud,
    columns: &[Column],
    encoding: PcdEncoding,
) -> io::Result<()> {
    let n = u32::try_from(cloud.len()).map_err(|_| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            "PCD holds at most 4294967295 points",
        )
    })?;
    let list = |f: &dyn Fn(Column) -> &'static str| {
        columns.iter().map(|&c| f(c)).collect::<Vec<_>>().join(" ")
    };
    let o = cloud.origin();
    let data = match encoding {
        PcdEncoding::Ascii => "ascii",
        PcdEncoding::Binary => "binary",
        PcdEncoding::BinaryCompressed => "binary_compressed",
    };
    write!(
        w,
        "# .PCD v0.7 - Point Cloud Data file format\n\
         VERSION 0.7\n\
         FIELDS {}\n\
         SIZE {}\n\
         TYPE {}\n\
         COUNT {}\n\
         WIDTH {n}\n\
         HEIGHT 1\n\
         VIEWPOINT {} {} {} 1 0 0 0\n\
         POINTS {n}\n\
         DATA {data}\n",
        list(&|c| c.name()),
        list(&|_| "4"),
        list(&|c| if c.is_float() { "F" } else { "U" }),
        list(&|_| "1"),
        o.x,
        o.y,
        o.z,
    )
}

fn write_ascii<W: Write>(w: &mut W, n: usize, columns: &[Column]) -> io::Result<()> {
    use std::fmt::Write as _;
    let mut text = String::with_capacity(CHUNK_BYTES + 1024);
    for i in 0..n {
        for (k, col) in columns.iter().enumerate() {
            if k > 0 {
                text.push(' ');
            }
            let word = col.word(i);
            if col.is_float() {
                let _ = write!(text, "{}", f32::from_bits(word));
            } else {
                let _ = write!(text, "{word}");
            }
        }
        text.push('\n');
        if text.len() >= CHUNK_BYTES {
            w.write_all(text.as_bytes())?;
            text.clear();
        }
    }
    w.write_all(text.as_bytes())
}

fn write_binary<W: Write>(w: &mut W, n: usize, columns: &[Column]) -> io::Result<()> {
    let record = 4 * columns.len();
    let per_chunk = (CHUNK_BYTES / record).max(1);
    let mut buf = Vec::with_capacity(per_chunk * record);
    for start in (0..n).step_by(per_chunk) {
        buf.clear();
        for i in start..(start + per_chunk).min(n) {
            for col in columns {
                buf.extend_from_slice(&col.word(i).to_le_bytes());
            }
        }
        w.write_all(&buf)?;
    }
    Ok(())
}

fn write_compressed<W: Write>(w: &mut W, n: usize, columns: &[Column]) -> io::Result<()> {
    let mut soa = Vec::with_capacity(n * 4 * columns.len());
    for col in columns {
        for i in 0..n {
            soa.extend_from_slice(&col.word(i).to_le_bytes());
        }
    }
    let packed = lzf::compress(&soa);
    let too_big = |_| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            "binary_compressed PCD data is limited to 4 GiB; use binary",
        )
    };
    let uncompressed = u32::try_from(soa.len()).map_err(too_big)?;
    let compressed = u32::try_from(packed.len()).map_err(too_big)?;
    w.write_all(&compressed.to_le_bytes())?;
    w.write_all(&uncompressed.to_le_bytes())?;
    w.write_all(&packed)
}

#[cfg(test)]
mod tests {
    use crate::io::pcd::read;
    use crate::io::pcd::tests::{encode, sample};
    use crate::io::PcdEncoding;
    use nalgebra::Point3;

    #[test]
    fn writes_the_documented_header() {
        let cloud = sample(2, true, true, true);
        let bytes = encode(&cloud, PcdEncoding::Binary);
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.starts_with(
            "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n\
             FIELDS x y z intensity normal_x normal_y normal_z rgb\n\
             SIZE 4 4 4 4 4 4 4 4\nTYPE F F F F F F F U\nCOUNT 1 1 1 1 1 1 1 1\n\
             WIDTH 2\nHEIGHT 1\nVIEWPOINT 0.1 -2.5 0.001 1 0 0 0\nPOINTS 2\nDATA binary\n"
        ));
        let loaded = read(&bytes[..]).unwrap();
        assert_eq!(loaded.report.encoding, "binary");
        assert_eq!(
            loaded.report.fields,
            [
                "x",
                "y",
                "z",
                "intensity",
                "normal_x",
                "normal_y",
                "normal_z",
                "rgb"
            ]
        );
        assert_eq!(loaded.cloud.origin(), Point3::new(0.1, -2.5, 1e-3));
    }
}
