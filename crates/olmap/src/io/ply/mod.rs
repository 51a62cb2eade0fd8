//! The Polygon File Format (PLY, "Stanford triangle format").
//!
//! PLY was described by Greg Turk (Stanford, 1994) to store polygonal models as a list of
//! *elements*, each with a count and a list of typed *properties*. A file is a text header
//! followed by the data of every element in the order the header declares them:
//!
//! ```text
//! ply
//! format binary_little_endian 1.0      (or ascii / binary_big_endian)
//! comment written by olmap
//! element vertex 2
//! property float x                     (property <type> <name>)
//! property float y
//! property float z
//! property list uchar float extra      (property list <count type> <item type> <name>)
//! end_header
//! <data>
//! ```
//!
//! Scalar types are `char`/`int8`, `uchar`/`uint8`, `short`/`int16`, `ushort`/`uint16`,
//! `int`/`int32`, `uint`/`uint32`, `float`/`float32` and `double`/`float64`. In `ascii`
//! files each element instance is one line of whitespace-separated numbers (a list is its
//! count followed by its items); in binary files instances are packed records in the
//! declared byte order, a list being its count followed by its items.
//!
//! # What this reader takes from a file
//! Only the `vertex` element is read; it must have `x`, `y` and `z` (any numeric type).
//! Property names are matched case-insensitively:
//! * intensity: the first of `intensity`, `scalar_intensity` (CloudCompare writes
//!   `scalar_Intensity`) or `reflectance`;
//! * normals: `nx ny nz`, or PCL's `normal_x normal_y normal_z` (all three needed);
//! * colours: `red green blue`, or `diffuse_red diffuse_green diffuse_blue` (all three
//!   needed). `uchar` is taken as is; other integer types are clamped to 0..=255; floating
//!   point colours are taken to be in 0..=1 and scaled to 0..=255 (rounded, clamped).
//!
//! Every other vertex property, list properties included, is skipped.
//! [`ReadReport::fields`](crate::io::ReadReport::fields) lists all the vertex properties the header declares.
//!
//! # Quirks handled
//! * Elements declared before `vertex` (a `face` element first, say) are skipped in all
//!   three encodings, also when they have list properties; elements after `vertex` are not
//!   read at all (reading stops after the last vertex).
//! * CRLF line ends (Windows tools) in the header and in ascii data; blank lines are
//!   ignored; `comment` and `obj_info` lines may appear anywhere in the header.
//! * Points with a NaN or infinite coordinate (also after conversion to `f32`) are dropped
//!   and counted in [`ReadReport::dropped_non_finite`](crate::io::ReadReport::dropped_non_finite).
//! * The sensor origin: olmap writes `comment olmap origin <x> <y> <z>` and reads it back;
//!   other comments are ignored and the origin is (0, 0, 0) without one.
//! * Hostile input: counts in the header are never trusted for allocation (memory grows
//!   only with data actually read), arithmetic on them is checked, and a file shorter than
//!   its header announces gives [`ParseError::Truncated`](crate::error::ParseError::Truncated). The reader never panics.
//!
//! # Writer
//! [`write()`] writes `binary_little_endian` (the default) or `ascii` with `float` x, y, z,
//! then `float intensity`, `float nx ny nz` and `uchar red green blue` where the cloud has
//! them. Ascii floats use Rust's shortest round-trip form (`{}`; the origin comment uses
//! `{:?}`, which keeps huge and tiny `f64` short), so both encodings read back bit for bit.
//!
//! # Speed
//! Binary vertex records without list properties are read in 1 MiB chunks and decoded
//! column by column; `float` x y z take no detour through `f64`. Ascii lines are read into
//! one reused buffer and split without allocating; the time goes into `str::parse`.
//!
//! # Where the code lives
//! `header.rs` parses the header into its elements and properties; `vertex.rs` maps the
//! vertex properties onto the cloud's attributes; `read.rs` holds [`read()`] and the ascii
//! data, `binary.rs` the binary data, `write.rs` [`write()`].

mod binary;
mod header;
mod read;
mod vertex;
mod write;

pub use read::read;
pub use write::write;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::PointCloud;
    use crate::error::{Location, ParseError};
    use crate::io::{LoadedCloud, PlyEncoding};
    use nalgebra::{Point3, Vector3};
    use proptest::prelude::*;

    /// A cloud with awkward values (extremes, subnormals, non-representable decimals).
    pub(super) fn sample(intensity: bool, normals: bool, colors: bool) -> PointCloud {
        let xs: [f32; 8] = [
            0.1,
            -2.5e-3,
            f32::MAX,
            f32::MIN_POSITIVE,
            1e-45,
            -123456.79,
            1.0 / 3.0,
            0.0,
        ];
        let n = xs.len();
        let points = (0..n)
            .map(|i| Point3::new(xs[i], xs[(i + 3) % n], -xs[(i + 5) % n]))
            .collect();
        let mut c = PointCloud::from_points(points).with_origin(Point3::new(
            0.1 + 0.2,
            -1e-300,
            12345.678901234567,
        ));
        if intensity {
            c.set_intensity(Some(xs.iter().map(|v| v * 0.7).collect()))
                .unwrap();
        }
        if normals {
            let v = (0..n)
                .map(|i| Vector3::new(xs[i].sin(), (i as f32).cos(), -0.25))
                .collect();
            c.set_normals(Some(v)).unwrap();
        }
        if colors {
            let v = (0..n)
                .map(|i| {
                    [
                        i as u8 * 30,
                        255 - i as u8,
                        if i % 2 == 0 { 0 } else { 255 },
                    ]
                })
                .collect();
            c.set_colors(Some(v)).unwrap();
        }
        c
    }

    pub(super) fn to_bytes(cloud: &PointCloud, enc: PlyEncoding) -> Vec<u8> {
        let mut out = Vec::new();
        write(&mut out, cloud, enc).unwrap();
        out
    }

    #[test]
    fn round_trips_are_bit_exact() {
        for enc in [PlyEncoding::BinaryLittleEndian, PlyEncoding::Ascii] {
            for mask in 0..8 {
                let cloud = sample(mask & 1 != 0, mask & 2 != 0, mask & 4 != 0);
                let loaded = read(&to_bytes(&cloud, enc)[..]).unwrap();
                assert_eq!(loaded.cloud, cloud, "{enc:?} mask {mask}");
                for (a, b) in loaded.cloud.points().iter().zip(cloud.points()) {
                    assert_eq!(a.x.to_bits(), b.x.to_bits());
                }
                assert_eq!(loaded.report.records, cloud.len() as u64);
                assert_eq!(loaded.report.dropped_non_finite, 0);
                assert_eq!(&loaded.report.fields[..3], ["x", "y", "z"]);
                let want = match enc {
                    PlyEncoding::Ascii => "ascii",
                    PlyEncoding::BinaryLittleEndian => "binary_little_endian",
                };
                assert_eq!(loaded.report.encoding, want);
            }
        }
    }

    #[test]
    fn empty_cloud_round_trips() {
        let cloud = PointCloud::new().with_origin(Point3::new(1.0, 2.0, 3.0));
        for enc in [PlyEncoding::BinaryLittleEndian, PlyEncoding::Ascii] {
            assert_eq!(read(&to_bytes(&cloud, enc)[..]).unwrap().cloud, cloud);
        }
    }

    /// Big-endian doubles, with a `face` element (list properties) before `vertex` and an
    /// element after it whose data is missing (it must not be read).
    pub(super) fn big_endian_with_faces() -> Vec<u8> {
        let mut b = b"ply\nformat binary_big_endian 1.0\ncomment made by hand\n\
            element face 2\nproperty list uchar int vertex_indices\nproperty uchar flags\n\
            element vertex 3\nproperty double x\nproperty double y\nproperty double z\n\
            property uchar red\nproperty uchar green\nproperty uchar blue\n\
            element edge 7\nproperty int vertex1\nproperty int vertex2\nend_header\n"
            .to_vec();
        for face in [&[0i32, 1, 2][..], &[2, 1, 0, 1]] {
            b.push(face.len() as u8);
            for &i in face {
                b.extend_from_slice(&i.to_be_bytes());
            }
            b.push(0xAB);
        }
        for (p, c) in [
            ([1.5f64, -2.0, 3.25], [255u8, 0, 7]),
            ([0.0, 1e3, -0.5], [1, 2, 3]),
            ([-7.75, 8.0, 9.5], [10, 20, 30]),
        ] {
            for v in p {
                b.extend_from_slice(&v.to_be_bytes());
            }
            b.extend_from_slice(&c);
        }
        b
    }

    pub(super) fn invalid_at_line(r: Result<LoadedCloud, ParseError>) -> usize {
        match r {
            Err(ParseError::Invalid {
                at: Location::Line(n),
                ..
            }) => n,
            other => panic!("expected a line error, got {other:?}"),
        }
    }

    /// Applies byte mutations: (kind, position, value).
    fn mutate(bytes: &mut Vec<u8>, ops: &[(u8, usize, u8)]) {
        for &(kind, pos, val) in ops {
            let at = if bytes.is_empty() {
                0
            } else {
                pos % bytes.len()
            };
            match kind {
                0 if !bytes.is_empty() => bytes[at] ^= val.max(1),
                1 => bytes.insert(at, val),
                2 if !bytes.is_empty() => {
                    bytes.remove(at);
                }
                3 => bytes.truncate(at),
                _ => {}
            }
        }
    }

    fn seeds() -> [Vec<u8>; 3] {
        let cloud = sample(true, true, true);
        [
            to_bytes(&cloud, PlyEncoding::BinaryLittleEndian),
            to_bytes(&cloud, PlyEncoding::Ascii),
            big_endian_with_faces(),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(600))]

        #[test]
        fn mutated_files_never_panic(
            seed in 0usize..3,
            ops in prop::collection::vec((0u8..4, any::<usize>(), any::<u8>()), 1..6),
        ) {
            let mut bytes = seeds()[seed].clone();
            mutate(&mut bytes, &ops);
            let _ = read(&bytes[..]);
        }

        #[test]
        fn random_bytes_after_the_magic_never_panic(
            tail in prop::collection::vec(any::<u8>(), 0..300),
        ) {
            let mut bytes = b"ply\n".to_vec();
            bytes.extend_from_slice(&tail);
            let _ = read(&bytes[..]);
        }
    }
}
