//! PCD, the Point Cloud Data format of the Point Cloud Library (PCL), version 0.7.
//!
//! Source: the PCD v0.7 specification (PCL documentation, "The PCD (Point Cloud Data) file
//! format") and the behaviour of PCL's `pcd_io.cpp`, which is what real files follow.
//!
//! A PCD file is a text header, one `KEY values...` per line, ending with the `DATA` line;
//! the point data follows straight after that line's `\n`:
//!
//! ```text
//! # .PCD v0.7 - Point Cloud Data file format
//! VERSION 0.7
//! FIELDS x y z intensity
//! SIZE 4 4 4 4
//! TYPE F F F F
//! COUNT 1 1 1 1
//! WIDTH 2
//! HEIGHT 1
//! VIEWPOINT 0 0 0 1 0 0 0
//! POINTS 2
//! DATA ascii
//! 1.5 2 3 17
//! 4 5 6 12
//! ```
//!
//! * `FIELDS` names the per-point fields; `SIZE` gives their size in bytes (1, 2, 4 or 8),
//!   `TYPE` their kind (`I` signed integer, `U` unsigned integer, `F` floating point, only
//!   with size 4 or 8) and `COUNT` how many values each field has (`fpfh` has 33).
//! * `WIDTH` × `HEIGHT` is the number of points; `HEIGHT` > 1 marks an *organised* cloud (an
//!   image-like grid, in which PCL stores missing returns as NaN points). `POINTS` repeats the
//!   product.
//! * `VIEWPOINT tx ty tz qw qx qy qz` is the sensor pose.
//! * `DATA ascii`: one point per line, values separated by whitespace. `DATA binary`: packed
//!   little-endian records, the fields in order (record size Σ size·count). `DATA
//!   binary_compressed`: a little-endian `u32` compressed size, a `u32` uncompressed size and
//!   one LZF block (see [`crate::file::lzf`]) of the data rearranged field by field
//!   (structure of arrays: all the values of the first field, then of the second, ...).
//!
//! ## What the reader takes from a file
//! * `x y z` (any numeric type) are the positions; points with a NaN or infinite coordinate
//!   are dropped and counted in [`ReadReport::dropped_non_finite`](crate::io::ReadReport::dropped_non_finite);
//! * `intensity` (that exact name, any numeric type) becomes the cloud's intensity;
//! * `normal_x normal_y normal_z` (all three) become the normals;
//! * `rgb` or `rgba` (4 bytes of any type) become the colours: the 4 bytes read as a
//!   little-endian `u32` hold `0x00RRGGBB` (the alpha byte of `rgba` is ignored);
//! * the `VIEWPOINT` translation becomes the cloud's origin (its rotation is not kept).
//!
//! Every other field (`curvature`, `label`, `fpfh`, PCL's `_` padding, ...) is skipped; all
//! the names appear in [`ReadReport::fields`](crate::io::ReadReport::fields).
//!
//! ## Quirks handled
//! * `VERSION` may be `0.7`, `.7`, or the older `.6`/`.5` (or absent); `COLUMNS` is read as
//!   `FIELDS`; `COUNT` defaults to 1, `HEIGHT` to 1, `POINTS` to `WIDTH` × `HEIGHT`, `WIDTH` to
//!   `POINTS` (when `HEIGHT` is 1), `VIEWPOINT` to the identity; ascii files may omit `SIZE`
//!   and `TYPE` (then every field is `F 4`). Keys are case-insensitive, `#` lines are comments.
//! * Organised clouds full of NaN points are normal; the report keeps `(WIDTH, HEIGHT)` in
//!   [`ReadReport::organized`](crate::io::ReadReport::organized) although the points returned are only the finite ones.
//! * In ascii files an `rgb` value of type `F` may be written either as the integer
//!   `0x00RRGGBB` (what PCL writes) or as the float whose bits hold it; an integer token is
//!   taken as the packed integer. `nan`, `NaN`, `inf` are accepted everywhere; blank lines
//!   are skipped; lines after the announced points are ignored.
//! * `binary_compressed` files often carry bytes after the LZF block; they are ignored, as
//!   are bytes after the last record of `binary` files.
//!
//! Nothing in a header is trusted: the sizes are checked for overflow, and no buffer is
//! sized from the header's counts before the bytes are there, so a header that claims
//! 10¹² points above a few bytes of data gives [`ParseError::Truncated`](crate::error::ParseError::Truncated), not an
//! out-of-memory abort. No input makes the reader panic.
//!
//! ## What the writer writes
//! `x y z` (`F 4`), then `intensity` (`F 4`), `normal_x normal_y normal_z` (`F 4`) and `rgb`
//! (`U 4`, `0x00RRGGBB`) when the cloud has them; `WIDTH` = the number of points, `HEIGHT` 1,
//! `VIEWPOINT` = the origin with the identity rotation. Ascii values are written in their
//! shortest round-trip form, so every encoding reads back bit for bit.
//!
//! ## Where the code lives
//! `header.rs` parses the header; `read.rs` holds [`read()`] and the ascii data, `binary.rs`
//! the `binary` and `binary_compressed` data, `write.rs` [`write()`]; the scalar types and
//! the colour packing they share are here.

mod binary;
mod header;
mod read;
mod write;

pub use read::read;
pub use write::write;

/// Bytes of binary data read and decoded at a time.
const CHUNK_BYTES: usize = 1 << 20;

/// The numeric type of a field's values (`TYPE` letter and `SIZE` together).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    /// The scalar of a `TYPE` letter (upper case) and `SIZE`, if the pair is valid.
    fn new(kind: u8, size: usize) -> Option<Scalar> {
        Some(match (kind, size) {
            (b'I', 1) => Scalar::I8,
            (b'U', 1) => Scalar::U8,
            (b'I', 2) => Scalar::I16,
            (b'U', 2) => Scalar::U16,
            (b'I', 4) => Scalar::I32,
            (b'U', 4) => Scalar::U32,
            (b'I', 8) => Scalar::I64,
            (b'U', 8) => Scalar::U64,
            (b'F', 4) => Scalar::F32,
            (b'F', 8) => Scalar::F64,
            _ => return None,
        })
    }

    /// Bytes per value.
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    /// The little-endian value at `pos` of `buf`, as a double (0 where `buf` is too short,
    /// which the callers rule out).
    #[inline]
    fn read(self, buf: &[u8], pos: usize) -> f64 {
        match self {
            Scalar::I8 => f64::from(i8::from_le_bytes(bytes_at(buf, pos))),
            Scalar::U8 => f64::from(u8::from_le_bytes(bytes_at(buf, pos))),
            Scalar::I16 => f64::from(i16::from_le_bytes(bytes_at(buf, pos))),
            Scalar::U16 => f64::from(u16::from_le_bytes(bytes_at(buf, pos))),
            Scalar::I32 => f64::from(i32::from_le_bytes(bytes_at(buf, pos))),
            Scalar::U32 => f64::from(u32::from_le_bytes(bytes_at(buf, pos))),
            Scalar::I64 => i64::from_le_bytes(bytes_at(buf, pos)) as f64,
            Scalar::U64 => u64::from_le_bytes(bytes_at(buf, pos)) as f64,
            Scalar::F32 => f64::from(f32::from_le_bytes(bytes_at(buf, pos))),
            Scalar::F64 => f64::from_le_bytes(bytes_at(buf, pos)),
        }
    }

    /// Parses an ascii value of this type. `F 4` values are parsed as `f32` directly (going
    /// through `f64` could round twice and miss the written value).
    #[inline]
    fn parse(self, token: &[u8]) -> Option<f64> {
        let s = std::str::from_utf8(token).ok()?;
        match self {
            Scalar::F32 => s.parse::<f32>().ok().map(f64::from),
            _ => s.parse::<f64>().ok(),
        }
    }
}

/// `N` bytes of `buf` from `pos`, zeros where `buf` is too short.
#[inline]
fn bytes_at<const N: usize>(buf: &[u8], pos: usize) -> [u8; N] {
    let mut out = [0u8; N];
    if let Some(src) = buf.get(pos..pos.saturating_add(N)) {
        out.copy_from_slice(src);
    }
    out
}

/// A token for an error message, cut short when long.
fn shown(token: &str) -> String {
    const MAX: usize = 40;
    if token.chars().count() <= MAX {
        token.to_string()
    } else {
        let mut s: String = token.chars().take(MAX).collect();
        s.push('…');
        s
    }
}

/// `0x00RRGGBB` to `[r, g, b]`.
#[inline]
fn unpack_rgb(v: u32) -> [u8; 3] {
    [(v >> 16) as u8, (v >> 8) as u8, v as u8]
}

/// `[r, g, b]` to `0x00RRGGBB`.
#[inline]
fn pack_rgb(c: [u8; 3]) -> u32 {
    u32::from(c[0]) << 16 | u32::from(c[1]) << 8 | u32::from(c[2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::PointCloud;
    use crate::error::{Location, ParseError};
    use crate::io::{CloudFormat, PcdEncoding};
    use nalgebra::{Point3, Vector3};
    use proptest::prelude::*;

    pub(super) const ALL: [PcdEncoding; 3] = [
        PcdEncoding::Ascii,
        PcdEncoding::Binary,
        PcdEncoding::BinaryCompressed,
    ];

    /// A cloud with awkward values (long decimal forms, tiny, huge, negative zero).
    pub(super) fn sample(n: usize, intensity: bool, normals: bool, colors: bool) -> PointCloud {
        let f = |i: usize, k: usize| -> f32 {
            let t = (i * 3 + k) as f32;
            match (i + k) % 5 {
                0 => t / 3.0,
                1 => -t * 0.1 - 1e-7,
                2 => 1e20 / (t + 1.0),
                3 => (t * 0.37).sin() * 1e-30,
                _ => -0.0,
            }
        };
        let points = (0..n)
            .map(|i| Point3::new(f(i, 0), f(i, 1), f(i, 2)))
            .collect();
        let mut cloud = PointCloud::from_points(points).with_origin(Point3::new(0.1, -2.5, 1e-3));
        if intensity {
            let v = (0..n).map(|i| f(i, 7) * 3.0).collect();
            cloud.set_intensity(Some(v)).unwrap();
        }
        if normals {
            let v = (0..n)
                .map(|i| Vector3::new(f(i, 3), f(i, 4), f(i, 5)))
                .collect();
            cloud.set_normals(Some(v)).unwrap();
        }
        if colors {
            let v = (0..n)
                .map(|i| [i as u8, (i * 7) as u8, 255 - (i % 256) as u8])
                .collect();
            cloud.set_colors(Some(v)).unwrap();
        }
        cloud
    }

    pub(super) fn encode(cloud: &PointCloud, encoding: PcdEncoding) -> Vec<u8> {
        let mut bytes = Vec::new();
        write(&mut bytes, cloud, encoding).unwrap();
        bytes
    }

    /// Bit patterns, so that -0.0 and 0.0 differ.
    pub(super) fn bits(cloud: &PointCloud) -> Vec<u32> {
        let mut v: Vec<u32> = cloud
            .points()
            .iter()
            .flat_map(|p| p.coords.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
            .collect();
        if let Some(i) = cloud.intensity() {
            v.extend(i.iter().map(|x| x.to_bits()));
        }
        if let Some(n) = cloud.normals() {
            v.extend(
                n.iter()
                    .flat_map(|n| n.iter().map(|x| x.to_bits()).collect::<Vec<_>>()),
            );
        }
        v
    }

    #[test]
    fn round_trips_every_encoding_and_attribute_set() {
        for encoding in ALL {
            for mask in 0..8 {
                for n in [0, 1, 257] {
                    let cloud = sample(n, mask & 1 != 0, mask & 2 != 0, mask & 4 != 0);
                    let bytes = encode(&cloud, encoding);
                    let loaded = read(&bytes[..])
                        .unwrap_or_else(|e| panic!("{encoding:?} mask {mask} n {n}: {e}"));
                    assert_eq!(loaded.cloud, cloud, "{encoding:?} mask {mask} n {n}");
                    assert_eq!(bits(&loaded.cloud), bits(&cloud));
                    let r = &loaded.report;
                    assert_eq!(r.records, n as u64);
                    assert_eq!(r.dropped_non_finite, 0);
                    assert_eq!(r.organized, None);
                    assert_eq!(r.format, CloudFormat::Pcd);
                    assert_eq!(r.fields[..3], ["x", "y", "z"]);
                }
            }
        }
    }

    pub(super) const GOOD_HEAD: &str =
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\n";

    pub(super) fn header_error(text: &str) -> (usize, String) {
        match read(text.as_bytes()) {
            Err(ParseError::Invalid {
                at: Location::Line(n),
                reason,
            }) => (n, reason),
            other => panic!("expected a line error for {text:?}, got {other:?}"),
        }
    }

    /// A byte-level change to a file.
    #[derive(Debug, Clone)]
    enum Mutation {
        Flip(usize, u8),
        Insert(usize, u8),
        Delete(usize),
        Truncate(usize),
    }

    fn mutation() -> impl Strategy<Value = Mutation> {
        prop_oneof![
            (any::<usize>(), 0u8..8).prop_map(|(i, b)| Mutation::Flip(i, b)),
            (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Insert(i, b)),
            any::<usize>().prop_map(Mutation::Delete),
            any::<usize>().prop_map(Mutation::Truncate),
        ]
    }

    fn mutate(mut bytes: Vec<u8>, mutations: &[Mutation]) -> Vec<u8> {
        for m in mutations {
            let len = bytes.len().max(1);
            match *m {
                Mutation::Flip(i, b) if !bytes.is_empty() => bytes[i % len] ^= 1 << b,
                Mutation::Insert(i, b) => bytes.insert(i % (bytes.len() + 1), b),
                Mutation::Delete(i) if !bytes.is_empty() => {
                    bytes.remove(i % len);
                }
                Mutation::Truncate(i) => bytes.truncate(i % (bytes.len() + 1)),
                _ => {}
            }
        }
        bytes
    }

    proptest! {
        #[test]
        fn prop_mutated_files_never_panic(
            encoding in prop_oneof![
                Just(PcdEncoding::Ascii),
                Just(PcdEncoding::Binary),
                Just(PcdEncoding::BinaryCompressed),
            ],
            mask in 0u8..8,
            mutations in prop::collection::vec(mutation(), 1..6),
        ) {
            let cloud = sample(20, mask & 1 != 0, mask & 2 != 0, mask & 4 != 0);
            let bytes = mutate(encode(&cloud, encoding), &mutations);
            let _ = read(&bytes[..]);
        }

        #[test]
        fn prop_random_data_after_a_valid_header_never_panics(
            data in prop_oneof![Just("ascii"), Just("binary"), Just("binary_compressed")],
            points in prop_oneof![0u64..50, any::<u32>().prop_map(u64::from)],
            tail in prop::collection::vec(any::<u8>(), 0..2000),
        ) {
            let mut bytes = format!(
                "FIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nWIDTH {points}\nPOINTS {points}\n\
                 DATA {data}\n"
            )
            .into_bytes();
            bytes.extend_from_slice(&tail);
            if let Ok(loaded) = read(&bytes[..]) {
                prop_assert_eq!(loaded.report.records, points);
            }
        }

        #[test]
        fn prop_random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..500)) {
            let _ = read(&bytes[..]);
        }

        #[test]
        fn prop_round_trip_arbitrary_floats(
            values in prop::collection::vec(
                (any::<f32>(), any::<f32>(), any::<f32>(), any::<f32>()), 0..40),
        ) {
            let finite: Vec<_> = values
                .into_iter()
                .filter(|v| v.0.is_finite() && v.1.is_finite() && v.2.is_finite() && !v.3.is_nan())
                .collect();
            let mut cloud = PointCloud::from_points(
                finite.iter().map(|v| Point3::new(v.0, v.1, v.2)).collect());
            cloud.set_intensity(Some(finite.iter().map(|v| v.3).collect())).unwrap();
            for encoding in ALL {
                let loaded = read(&encode(&cloud, encoding)[..]).unwrap();
                prop_assert_eq!(bits(&loaded.cloud), bits(&cloud));
            }
        }
    }
}
