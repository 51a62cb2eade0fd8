//! Reading a PCD file: the entry point, the cloud being built and the ascii data.

use std::io::BufRead;

use nalgebra::{Point3, Vector3};

use super::binary::{read_binary, read_compressed};
use super::header::{read_header, DataEncoding, Header, Roles};
use super::{shown, unpack_rgb, Scalar};
use crate::cloud::PointCloud;
use crate::error::ParseError;
use crate::file::text::{read_line_capped, MAX_LINE_BYTES};
use crate::io::{finite_point, CloudFormat, LoadedCloud, ReadReport};

/// Points reserved up front at most; beyond that the vectors grow as points arrive.
const INITIAL_CAPACITY: u64 = 1 << 16;

/// Reads a PCD file (any of the three encodings) from a stream.
///
/// The stream is read up to the end of the point data; trailing bytes are not looked at.
/// Errors name the header line (for header and ascii problems) and what was expected there.
///
/// ```
/// let pcd = b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 2\n\
///             DATA ascii\n1 2 3\nnan 0 0\n";
/// let loaded = olmap::io::pcd::read(&pcd[..]).unwrap();
/// assert_eq!(loaded.cloud.len(), 1);
/// assert_eq!(loaded.report.dropped_non_finite, 1);
/// ```
pub fn read<R: BufRead>(mut reader: R) -> Result<LoadedCloud, ParseError> {
    let header = read_header(&mut reader)?;
    let mut report = ReadReport::new(CloudFormat::Pcd);
    report.encoding = header.encoding.name().to_string();
    report.records = header.points;
    report.fields = header.fields.iter().map(|f| f.name.clone()).collect();
    if header.height > 1 {
        report.organized = Some((header.width, header.height));
    }
    let mut builder = CloudBuilder::new(&header.roles, header.points.min(INITIAL_CAPACITY));
    match header.encoding {
        DataEncoding::Ascii => read_ascii(&mut reader, &header, &mut builder, &mut report)?,
        DataEncoding::Binary => read_binary(&mut reader, &header, &mut builder, &mut report)?,
        DataEncoding::BinaryCompressed => {
            read_compressed(&mut reader, &header, &mut builder, &mut report)?
        }
    }
    let v = &header.viewpoint;
    let cloud = builder.finish(Point3::new(v[0], v[1], v[2]))?;
    Ok(LoadedCloud { cloud, report })
}

/// The vectors of the cloud being read.
pub(super) struct CloudBuilder {
    points: Vec<Point3<f32>>,
    intensity: Option<Vec<f32>>,
    normals: Option<Vec<Vector3<f32>>>,
    colors: Option<Vec<[u8; 3]>>,
}

impl CloudBuilder {
    fn new(roles: &Roles, capacity: u64) -> Self {
        let cap = usize::try_from(capacity).unwrap_or(0);
        CloudBuilder {
            points: Vec::with_capacity(cap),
            intensity: roles.intensity.map(|_| Vec::with_capacity(cap)),
            normals: roles.normals.map(|_| Vec::with_capacity(cap)),
            colors: roles.rgb.map(|_| Vec::with_capacity(cap)),
        }
    }

    /// Appends a point; the attributes the cloud does not carry are ignored.
    #[inline]
    pub(super) fn push(&mut self, p: Point3<f32>, intensity: f32, normal: Vector3<f32>, rgb: u32) {
        self.points.push(p);
        if let Some(v) = &mut self.intensity {
            v.push(intensity);
        }
        if let Some(v) = &mut self.normals {
            v.push(normal);
        }
        if let Some(v) = &mut self.colors {
            v.push(unpack_rgb(rgb));
        }
    }

    fn finish(self, origin: Point3<f64>) -> Result<PointCloud, ParseError> {
        let mut cloud = PointCloud::from_points(self.points).with_origin(origin);
        let attach = |e: crate::Error| ParseError::Malformed(e.to_string());
        cloud.set_intensity(self.intensity).map_err(attach)?;
        cloud.set_normals(self.normals).map_err(attach)?;
        cloud.set_colors(self.colors).map_err(attach)?;
        Ok(cloud)
    }
}

/// What an ascii token feeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Coord(usize),
    Intensity,
    Normal(usize),
    Rgb,
    Skip,
}

/// How to read one ascii token.
#[derive(Debug, Clone, Copy)]
struct TokenSpec {
    role: Role,
    scalar: Scalar,
    field: usize,
}

/// The values of one ascii line.
#[derive(Debug, Clone, Copy, Default)]
struct AsciiPoint {
    xyz: [f64; 3],
    intensity: f32,
    normal: [f32; 3],
    rgb: u32,
}

impl AsciiPoint {
    /// Parses a token into its slot; `None` if it is not a number of the field's type.
    #[inline]
    fn take(&mut self, spec: TokenSpec, token: &[u8]) -> Option<()> {
        match spec.role {
            Role::Rgb => self.rgb = parse_rgb(token, spec.scalar)?,
            role => {
                let v = spec.scalar.parse(token)?;
                match role {
                    Role::Coord(k) => self.xyz[k] = v,
                    Role::Intensity => self.intensity = v as f32,
                    Role::Normal(k) => self.normal[k] = v as f32,
                    Role::Rgb | Role::Skip => {}
                }
            }
        }
        Some(())
    }
}

/// An ascii colour: the packed integer (what PCL writes, also for `TYPE F`), or for `F`
/// fields the float whose bits hold it.
fn parse_rgb(token: &[u8], scalar: Scalar) -> Option<u32> {
    let s = std::str::from_utf8(token).ok()?;
    if let Ok(v) = s.parse::<i64>() {
        // I 4 colours are negative when the alpha byte is set: keep the low 32 bits.
        return Some(v as u32);
    }
    match scalar {
        Scalar::F32 => s.parse::<f32>().ok().map(f32::to_bits),
        _ => None,
    }
}

/// The token specs of an ascii line: one per value (fields with `COUNT` n give n tokens).
fn token_specs(header: &Header) -> Vec<TokenSpec> {
    let roles = &header.roles;
    let role_of = |f: usize| {
        if let Some(k) = roles.xyz.iter().position(|&i| i == f) {
            Role::Coord(k)
        } else if roles.intensity == Some(f) {
            Role::Intensity
        } else if let Some(k) = roles.normals.and_then(|n| n.iter().position(|&i| i == f)) {
            Role::Normal(k)
        } else if roles.rgb == Some(f) {
            Role::Rgb
        } else {
            Role::Skip
        }
    };
    let mut specs = Vec::new();
    for (f, field) in header.fields.iter().enumerate() {
        for k in 0..field.count {
            specs.push(TokenSpec {
                role: if k == 0 { role_of(f) } else { Role::Skip },
                scalar: field.scalar,
                field: f,
            });
        }
    }
    specs
}

/// `DATA ascii`: one point per line.
fn read_ascii<R: BufRead>(
    reader: &mut R,
    header: &Header,
    out: &mut CloudBuilder,
    report: &mut ReadReport,
) -> Result<(), ParseError> {
    // Every value takes a byte and a separator: more values than fit on a line of the
    // longest length read cannot be ascii data (and would not be worth a token list).
    let values = header
        .fields
        .iter()
        .try_fold(0u64, |sum, f| sum.checked_add(f.count as u64))
        .unwrap_or(u64::MAX);
    if values > MAX_LINE_BYTES / 2 {
        return Err(ParseError::line(
            header.data_line,
            format!(
                "DATA ascii: COUNT gives {values} values per point, more than a line of {} MiB \
                 can hold",
                MAX_LINE_BYTES >> 20
            ),
        ));
    }
    let specs = token_specs(header);
    let mut line = Vec::with_capacity(256);
    let mut line_no = header.data_line;
    let mut found = 0u64;
    while found < header.points {
        line.clear();
        if read_line_capped(reader, &mut line, line_no + 1)? == 0 {
            return Err(ParseError::Truncated(format!(
                "ascii data: the header announces {} points, found {found}",
                header.points
            )));
        }
        line_no += 1;
        let mut values = AsciiPoint::default();
        let mut tokens = 0usize;
        for token in line
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty())
        {
            if let Some(&spec) = specs.get(tokens) {
                values.take(spec, token).ok_or_else(|| {
                    ParseError::line(
                        line_no,
                        format!(
                            "field '{}': expected a number, found '{}'",
                            header.fields[spec.field].name,
                            shown(&String::from_utf8_lossy(token))
                        ),
                    )
                })?;
            }
            tokens += 1;
        }
        if tokens == 0 {
            continue;
        }
        if tokens != specs.len() {
            return Err(ParseError::line(
                line_no,
                format!(
                    "expected {} values (one per field value of FIELDS), found {tokens}",
                    specs.len()
                ),
            ));
        }
        found += 1;
        if let Some(p) = finite_point(values.xyz, report) {
            let [nx, ny, nz] = values.normal;
            out.push(p, values.intensity, Vector3::new(nx, ny, nz), values.rgb);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::file::lzf;
    use crate::io::pcd::pack_rgb;
    use crate::io::pcd::tests::{header_error, GOOD_HEAD};

    #[test]
    fn reads_an_organised_ascii_cloud_with_nans() {
        let text = "# .PCD v0.7 - Point Cloud Data file format\n\
            VERSION .7\n\
            FIELDS x y z rgb\n\
            SIZE 4 4 4 4\n\
            TYPE F F F F\n\
            COUNT 1 1 1 1\n\
            WIDTH 3\n\
            HEIGHT 2\n\
            VIEWPOINT 1 2 3 1 0 0 0\n\
            POINTS 6\n\
            DATA ascii\n\
            1 2 3 16711680\n\
            nan nan nan 0\n\
            \n\
            4.5 -5 6e2 4.808e+06\n\
            NaN 1 1 0\n\
            1 inf 1 0\r\n\
            7 8 9 255\n\
            this line is past the announced points and ignored\n";
        let loaded = read(text.as_bytes()).unwrap();
        let r = &loaded.report;
        assert_eq!(r.encoding, "ascii");
        assert_eq!(r.records, 6);
        assert_eq!(r.organized, Some((3, 2)));
        assert_eq!(r.dropped_non_finite, 3);
        assert_eq!(r.fields, ["x", "y", "z", "rgb"]);
        let c = &loaded.cloud;
        assert_eq!(
            c.points(),
            [
                Point3::new(1.0, 2.0, 3.0),
                Point3::new(4.5, -5.0, 600.0),
                Point3::new(7.0, 8.0, 9.0)
            ]
        );
        let float_rgb = unpack_rgb(4.808e+06f32.to_bits());
        assert_eq!(c.colors().unwrap(), [[255, 0, 0], float_rgb, [0, 0, 255]]);
        assert_eq!(c.origin(), Point3::new(1.0, 2.0, 3.0));
        assert!(c.intensity().is_none() && c.normals().is_none());
    }

    /// Little-endian bytes of one record of the mixed-type layout below.
    struct Mixed {
        x: f64,
        y: i16,
        z: u8,
        intensity: u16,
        rgb: f32,
        normal: [f32; 3],
        curvature: f32,
        fpfh: [f32; 33],
        label: i32,
    }

    fn mixed_header(n: usize, data: &str) -> String {
        format!(
            "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n\
             FIELDS x y z intensity rgb normal_x normal_y normal_z curvature fpfh label\n\
             SIZE 8 2 1 2 4 4 4 4 4 4 4\nTYPE F I U U F F F F F F I\n\
             COUNT 1 1 1 1 1 1 1 1 1 33 1\nWIDTH {n}\nHEIGHT 1\n\
             VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
        )
    }

    fn mixed_points(n: usize) -> Vec<Mixed> {
        (0..n)
            .map(|i| Mixed {
                x: if i == 2 { f64::NAN } else { i as f64 + 0.25 },
                y: -(i as i16) * 300,
                z: (i * 40) as u8,
                intensity: 1000 + i as u16,
                rgb: f32::from_bits(pack_rgb([i as u8, 2, 200])),
                normal: [0.0, i as f32, -1.0],
                curvature: 0.5,
                fpfh: [i as f32 + 100.0; 33],
                label: -7,
            })
            .collect()
    }

    /// Each field of a record as bytes, in header order.
    fn mixed_fields(m: &Mixed) -> Vec<Vec<u8>> {
        let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<_>>();
        vec![
            m.x.to_le_bytes().to_vec(),
            m.y.to_le_bytes().to_vec(),
            vec![m.z],
            m.intensity.to_le_bytes().to_vec(),
            m.rgb.to_le_bytes().to_vec(),
            f32s(&m.normal[..1]),
            f32s(&m.normal[1..2]),
            f32s(&m.normal[2..]),
            f32s(&[m.curvature]),
            f32s(&m.fpfh),
            m.label.to_le_bytes().to_vec(),
        ]
    }

    fn check_mixed(loaded: &LoadedCloud, n: usize) {
        let points = mixed_points(n);
        let kept: Vec<&Mixed> = points.iter().filter(|m| m.x.is_finite()).collect();
        let c = &loaded.cloud;
        assert_eq!(c.len(), kept.len());
        assert_eq!(loaded.report.dropped_non_finite, 1);
        assert_eq!(loaded.report.records, n as u64);
        assert_eq!(loaded.report.fields.len(), 11);
        for (k, m) in kept.iter().enumerate() {
            let p = c.points()[k];
            assert_eq!(p, Point3::new(m.x as f32, f32::from(m.y), f32::from(m.z)));
            assert_eq!(c.intensity().unwrap()[k], f32::from(m.intensity));
            assert_eq!(c.normals().unwrap()[k], Vector3::from(m.normal));
            assert_eq!(c.colors().unwrap()[k], unpack_rgb(m.rgb.to_bits()));
        }
    }

    #[test]
    fn reads_binary_with_mixed_types_and_extra_fields() {
        let n = 5;
        let mut bytes = mixed_header(n, "binary").into_bytes();
        for m in mixed_points(n) {
            bytes.extend(mixed_fields(&m).concat());
        }
        check_mixed(&read(&bytes[..]).unwrap(), n);
        // Trailing bytes after the records are not looked at.
        bytes.extend_from_slice(b"trailing");
        check_mixed(&read(&bytes[..]).unwrap(), n);
    }

    #[test]
    fn reads_compressed_with_mixed_types_and_extra_fields() {
        let n = 4;
        let records: Vec<Vec<Vec<u8>>> = mixed_points(n).iter().map(mixed_fields).collect();
        let mut soa = Vec::new();
        for f in 0..11 {
            for r in &records {
                soa.extend_from_slice(&r[f]);
            }
        }
        let packed = lzf::compress(&soa);
        let mut bytes = mixed_header(n, "binary_compressed").into_bytes();
        bytes.extend((packed.len() as u32).to_le_bytes());
        bytes.extend((soa.len() as u32).to_le_bytes());
        bytes.extend(&packed);
        check_mixed(&read(&bytes[..]).unwrap(), n);
    }

    #[test]
    fn reads_ascii_with_mixed_types_and_extra_fields() {
        let n = 3;
        let mut text = mixed_header(n, "ascii");
        for m in mixed_points(n) {
            let fpfh: Vec<String> = m.fpfh.iter().map(|v| v.to_string()).collect();
            text += &format!(
                "{} {} {} {} {} {} {} {} {} {} {}\n",
                m.x,
                m.y,
                m.z,
                m.intensity,
                m.rgb.to_bits(),
                m.normal[0],
                m.normal[1],
                m.normal[2],
                m.curvature,
                fpfh.join(" "),
                m.label
            );
        }
        check_mixed(&read(text.as_bytes()).unwrap(), n);
    }

    #[test]
    fn rejects_bad_ascii_values() {
        let bad = [
            ("1 2 x\n1 2 3\n", 10),
            ("1 2 3 4\n1 2 3\n", 10),
            ("1 2 3\n1 2\n", 11),
            ("1 2 3\n1 2 0x10\n", 11),
        ];
        for (data, line) in bad {
            let text = format!("{GOOD_HEAD}DATA ascii\n{data}");
            let (n, reason) = header_error(&text);
            assert_eq!(n, line, "{data:?}: {reason}");
        }
        let text = format!("{GOOD_HEAD}DATA ascii\n1 2 3\n");
        assert!(matches!(
            read(text.as_bytes()),
            Err(ParseError::Truncated(_))
        ));
        let (_, reason) = header_error(&format!("{GOOD_HEAD}DATA ascii\n1 2 abc\n1 2 3\n"));
        assert!(
            reason.contains("field 'z'") && reason.contains("abc"),
            "{reason}"
        );
    }
}
