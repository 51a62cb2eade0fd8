//! Mapping the vertex properties onto the cloud's attributes, and the cloud being built.

use nalgebra::{Point3, Vector3};

use super::header::{Header, Kind, Property, Scalar};
use crate::cloud::PointCloud;
use crate::error::ParseError;
use crate::io::{finite_point, LoadedCloud, ReadReport};

/// Points reserved up front at most, whatever the header claims.
const INITIAL_CAPACITY: u64 = 1 << 16;

/// Names accepted for the intensity property (compared case-insensitively).
const INTENSITY_NAMES: [&str; 3] = ["intensity", "scalar_intensity", "reflectance"];
/// Name triples accepted for normals.
const NORMAL_NAMES: [[&str; 3]; 2] = [["nx", "ny", "nz"], ["normal_x", "normal_y", "normal_z"]];
/// Name triples accepted for colours.
const COLOR_NAMES: [[&str; 3]; 2] = [
    ["red", "green", "blue"],
    ["diffuse_red", "diffuse_green", "diffuse_blue"],
];

/// Slots of the per-vertex values the cloud keeps.
pub(super) const X: usize = 0;
pub(super) const INTENSITY: usize = 3;
pub(super) const NORMAL: usize = 4;
pub(super) const COLOR: usize = 7;
pub(super) const SLOTS: usize = 10;

/// Which vertex property feeds which slot.
#[derive(Debug)]
pub(super) struct Plan {
    /// Index of the vertex element.
    pub(super) vertex: usize,
    /// For every vertex property, the slot it fills.
    slot_of: Vec<Option<usize>>,
    intensity: bool,
    normals: bool,
    colors: bool,
    /// Per colour channel: whether its type is floating point (0..1 scale).
    color_float: [bool; 3],
}

/// Index of the first scalar property whose name is one of `names` (case-insensitive).
fn find_scalar(props: &[Property], names: &[&str]) -> Option<usize> {
    props.iter().position(|p| {
        matches!(p.kind, Kind::Scalar(_)) && names.iter().any(|n| p.name.eq_ignore_ascii_case(n))
    })
}

/// Indices of a triple of scalar properties, the first triple of `candidates` complete.
fn find_triple(props: &[Property], candidates: &[[&str; 3]]) -> Option<[usize; 3]> {
    candidates.iter().find_map(|names| {
        Some([
            find_scalar(props, &names[..1])?,
            find_scalar(props, &names[1..2])?,
            find_scalar(props, &names[2..])?,
        ])
    })
}

/// The scalar type of a property (callers pass scalar properties only).
pub(super) fn scalar_of(p: &Property) -> Scalar {
    match p.kind {
        Kind::Scalar(s) => s,
        Kind::List { item, .. } => item,
    }
}

impl Plan {
    pub(super) fn new(header: &Header) -> Result<Plan, ParseError> {
        let vertex = header
            .elements
            .iter()
            .position(|e| e.name == "vertex")
            .ok_or_else(|| {
                ParseError::line(
                    header.end_line,
                    "expected an 'element vertex' line before end_header",
                )
            })?;
        let el = &header.elements[vertex];
        let mut slot_of = vec![None; el.props.len()];
        for (axis, name) in ["x", "y", "z"].into_iter().enumerate() {
            let Some(i) = el
                .props
                .iter()
                .position(|p| p.name.eq_ignore_ascii_case(name))
            else {
                return Err(ParseError::line(
                    el.line,
                    format!("element 'vertex' has no property '{name}': expected x, y and z"),
                ));
            };
            if matches!(el.props[i].kind, Kind::List { .. }) {
                return Err(ParseError::line(
                    el.line,
                    format!("vertex property '{name}' is a list: expected a number"),
                ));
            }
            slot_of[i] = Some(X + axis);
        }
        let mut plan = Plan {
            vertex,
            slot_of,
            intensity: false,
            normals: false,
            colors: false,
            color_float: [false; 3],
        };
        if let Some(i) = find_scalar(&el.props, &INTENSITY_NAMES) {
            plan.claim(i, INTENSITY);
            plan.intensity = true;
        }
        if let Some(idx) = find_triple(&el.props, &NORMAL_NAMES) {
            for (k, i) in idx.into_iter().enumerate() {
                plan.claim(i, NORMAL + k);
            }
            plan.normals = true;
        }
        if let Some(idx) = find_triple(&el.props, &COLOR_NAMES) {
            for (k, i) in idx.into_iter().enumerate() {
                plan.claim(i, COLOR + k);
                plan.color_float[k] = scalar_of(&el.props[i]).is_float();
            }
            plan.colors = true;
        }
        Ok(plan)
    }

    /// Routes property `i` to `slot` unless it already feeds x, y or z.
    fn claim(&mut self, i: usize, slot: usize) {
        if let Some(s @ None) = self.slot_of.get_mut(i) {
            *s = Some(slot);
        }
    }

    /// The slot property `i` fills, if any.
    #[inline]
    pub(super) fn slot(&self, i: usize) -> Option<usize> {
        self.slot_of.get(i).copied().flatten()
    }
}

/// Collects the points and attributes while reading.
pub(super) struct Builder {
    pub(super) points: Vec<Point3<f32>>,
    pub(super) intensity: Option<Vec<f32>>,
    pub(super) normals: Option<Vec<Vector3<f32>>>,
    pub(super) colors: Option<Vec<[u8; 3]>>,
    color_float: [bool; 3],
    report: ReadReport,
}

impl Builder {
    pub(super) fn new(plan: &Plan, count: u64, report: ReadReport) -> Self {
        let cap = count.min(INITIAL_CAPACITY) as usize;
        Builder {
            points: Vec::with_capacity(cap),
            intensity: plan.intensity.then(|| Vec::with_capacity(cap)),
            normals: plan.normals.then(|| Vec::with_capacity(cap)),
            colors: plan.colors.then(|| Vec::with_capacity(cap)),
            color_float: plan.color_float,
            report,
        }
    }

    /// Adds one vertex from its slot values, unless a coordinate is not finite.
    #[inline]
    pub(super) fn push(&mut self, s: &[f64; SLOTS]) {
        let Some(p) = finite_point([s[X], s[X + 1], s[X + 2]], &mut self.report) else {
            return;
        };
        self.points.push(p);
        if let Some(v) = &mut self.intensity {
            v.push(s[INTENSITY] as f32);
        }
        if let Some(v) = &mut self.normals {
            v.push(Vector3::new(
                s[NORMAL] as f32,
                s[NORMAL + 1] as f32,
                s[NORMAL + 2] as f32,
            ));
        }
        if let Some(v) = &mut self.colors {
            let f = self.color_float;
            v.push([
                color_byte(s[COLOR], f[0]),
                color_byte(s[COLOR + 1], f[1]),
                color_byte(s[COLOR + 2], f[2]),
            ]);
        }
    }

    /// Removes the points from index `start` on that have a non-finite coordinate (with
    /// their attributes), counting them.
    pub(super) fn drop_non_finite_from(&mut self, start: usize) {
        let finite = |p: &Point3<f32>| p.x.is_finite() && p.y.is_finite() && p.z.is_finite();
        let Some(tail) = self.points.get(start..) else {
            return;
        };
        if tail.iter().all(finite) {
            return;
        }
        let keep: Vec<bool> = tail.iter().map(finite).collect();
        self.report.dropped_non_finite += keep.iter().filter(|k| !**k).count() as u64;
        compact_from(&mut self.points, start, &keep);
        if let Some(v) = &mut self.intensity {
            compact_from(v, start, &keep);
        }
        if let Some(v) = &mut self.normals {
            compact_from(v, start, &keep);
        }
        if let Some(v) = &mut self.colors {
            compact_from(v, start, &keep);
        }
    }

    pub(super) fn finish(self, origin: Point3<f64>) -> Result<LoadedCloud, ParseError> {
        let mut cloud = PointCloud::from_points(self.points).with_origin(origin);
        let attach = |r: crate::error::Result<()>| {
            r.map_err(|e| ParseError::Malformed(format!("internal: {e}")))
        };
        attach(cloud.set_intensity(self.intensity))?;
        attach(cloud.set_normals(self.normals))?;
        attach(cloud.set_colors(self.colors))?;
        Ok(LoadedCloud {
            cloud,
            report: self.report,
        })
    }
}

/// Keeps the elements of `v[start..]` whose flag in `keep` is set, in order.
fn compact_from<T: Copy>(v: &mut Vec<T>, start: usize, keep: &[bool]) {
    let mut w = start;
    for (r, &k) in (start..v.len()).zip(keep) {
        if k {
            if let Some(&x) = v.get(r) {
                if let Some(slot) = v.get_mut(w) {
                    *slot = x;
                }
            }
            w += 1;
        }
    }
    v.truncate(w);
}

/// Converts a colour channel value to a byte: floats are on a 0..1 scale, integers are
/// clamped (`as u8` saturates and maps NaN to 0).
#[inline]
pub(super) fn color_byte(v: f64, is_float: bool) -> u8 {
    if is_float {
        (v * 255.0).round() as u8
    } else {
        v as u8
    }
}

#[cfg(test)]
mod tests {
    use crate::cloud::PointCloud;
    use crate::io::ply::read;
    use crate::io::ply::tests::to_bytes;
    use crate::io::PlyEncoding;
    use nalgebra::Point3;

    #[test]
    fn non_finite_points_are_dropped_with_their_attributes() {
        let nan = f32::NAN;
        let pts = vec![
            Point3::new(1.0, 2.0, 3.0),
            Point3::new(nan, 0.0, 0.0),
            Point3::new(4.0, f32::INFINITY, 6.0),
            Point3::new(7.0, 8.0, 9.0),
        ];
        let mut cloud = PointCloud::from_points(pts);
        cloud.set_intensity(Some(vec![1.0, 2.0, 3.0, 4.0])).unwrap();
        cloud
            .set_colors(Some(vec![[1, 1, 1], [2, 2, 2], [3, 3, 3], [4, 4, 4]]))
            .unwrap();
        let keep = cloud.gather(&[0, 3]);
        for enc in [PlyEncoding::BinaryLittleEndian, PlyEncoding::Ascii] {
            let loaded = read(&to_bytes(&cloud, enc)[..]).unwrap();
            assert_eq!(loaded.cloud, keep, "{enc:?}");
            assert_eq!(loaded.report.records, 4);
            assert_eq!(loaded.report.dropped_non_finite, 2);
        }
        // Doubles beyond the f32 range are dropped too.
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\n\
            property double x\nproperty double y\nproperty double z\n\
            property float intensity\nend_header\n"
            .to_vec();
        for (p, i) in [([1e300f64, 0.0, 0.0], 5.0f32), ([0.5, 0.25, -1.0], 6.0)] {
            for v in p {
                b.extend_from_slice(&v.to_le_bytes());
            }
            b.extend_from_slice(&i.to_le_bytes());
        }
        let loaded = read(&b[..]).unwrap();
        assert_eq!(loaded.cloud.points(), [Point3::new(0.5, 0.25, -1.0)]);
        assert_eq!(loaded.cloud.intensity().unwrap(), [6.0]);
        assert_eq!(loaded.report.dropped_non_finite, 1);
    }

    #[test]
    fn integer_colours_are_clamped() {
        let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n\
            property float y\nproperty float z\nproperty int red\nproperty ushort green\n\
            property char blue\nend_header\n0 0 0 -5 300 100\n";
        let c = read(text.as_bytes()).unwrap().cloud;
        assert_eq!(c.colors().unwrap(), [[0, 255, 100]]);
    }
}
