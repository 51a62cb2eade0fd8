//! The binary data of a PLY file (either byte order): the elements before `vertex`
//! skipped, then the vertices read.

use std::io::{self, BufRead};

use nalgebra::{Point3, Vector3};

use super::header::{Element, Header, Kind, Scalar};
use super::vertex::{color_byte, scalar_of, Builder, Plan, COLOR, INTENSITY, NORMAL, SLOTS, X};
use crate::error::{Location, ParseError};

/// Bytes of binary vertex records read and decoded at a time.
const CHUNK_BYTES: usize = 1 << 20;

/// A binary stream that counts the bytes it has delivered.
struct BinInput<R> {
    r: R,
    /// Offset of the next byte in the stream.
    pos: u64,
}

impl<R: BufRead> BinInput<R> {
    /// Fills `buf` as far as the stream allows; returns the bytes read (short at the end).
    fn fill(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let mut got = 0;
        while got < buf.len() {
            match self.r.read(&mut buf[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        self.pos += got as u64;
        Ok(got)
    }

    /// Skips up to `n` bytes; returns how many were skipped (fewer at the end).
    fn skip(&mut self, n: u64) -> io::Result<u64> {
        let mut left = n;
        while left > 0 {
            let avail = match self.r.fill_buf() {
                Ok(b) => b.len(),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if avail == 0 {
                break;
            }
            let k = (avail as u64).min(left) as usize;
            self.r.consume(k);
            left -= k as u64;
        }
        let done = n - left;
        self.pos += done;
        Ok(done)
    }

    /// Reads one value of type `ty`; `None` at the end of the stream.
    #[inline]
    fn value<const BE: bool>(&mut self, ty: Scalar) -> io::Result<Option<f64>> {
        let mut b = [0u8; 8];
        let b = &mut b[..ty.size()];
        let got = self.fill(b)?;
        Ok((got == b.len()).then(|| ty.decode::<BE>(b)))
    }
}

/// Where a binary record is being read, for messages.
struct At<'a> {
    element: &'a Element,
    instance: u64,
}

impl At<'_> {
    fn truncated(&self, prop: &str) -> ParseError {
        ParseError::Truncated(format!(
            "element '{}' ({} instances announced): the data ends inside instance {}, \
             property '{prop}'",
            self.element.name, self.element.count, self.instance
        ))
    }
}

/// Reads a list count and checks it is a whole non-negative number.
fn list_count<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    ty: Scalar,
    at: &At<'_>,
    prop: &str,
) -> Result<u64, ParseError> {
    let start = input.pos;
    let c = input.value::<BE>(ty)?.ok_or_else(|| at.truncated(prop))?;
    if c < 0.0 {
        return Err(ParseError::at(
            Location::Byte(start),
            format!(
                "element '{}' instance {}: list '{prop}' has a negative count {c}",
                at.element.name, at.instance
            ),
        ));
    }
    Ok(c as u64)
}

/// Skips one list property's items.
fn skip_list<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    count_ty: Scalar,
    item: Scalar,
    at: &At<'_>,
    prop: &str,
) -> Result<(), ParseError> {
    let n = list_count::<BE, R>(input, count_ty, at, prop)?;
    let bytes = n
        .checked_mul(item.size() as u64)
        .ok_or_else(|| at.truncated(prop))?;
    if input.skip(bytes)? < bytes {
        return Err(at.truncated(prop));
    }
    Ok(())
}

/// Skips every instance of an element that is not read.
fn skip_binary_element<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    el: &Element,
) -> Result<(), ParseError> {
    if let Some(size) = el.fixed_size() {
        let total = el.count.checked_mul(size as u64);
        let skipped = match total {
            Some(t) => input.skip(t)?,
            None => input.skip(u64::MAX)?,
        };
        if total != Some(skipped) {
            return Err(ParseError::Truncated(format!(
                "element '{}' announces {} instances of {size} bytes, but the data ends after \
                 {} bytes",
                el.name, el.count, skipped
            )));
        }
        return Ok(());
    }
    // With a list property every instance holds at least one byte, so this loop ends
    // with the data whatever the count claims.
    for instance in 0..el.count {
        let at = At {
            element: el,
            instance,
        };
        for p in &el.props {
            match p.kind {
                Kind::Scalar(s) => {
                    if input.skip(s.size() as u64)? < s.size() as u64 {
                        return Err(at.truncated(&p.name));
                    }
                }
                Kind::List { count, item } => skip_list::<BE, R>(input, count, item, &at, &p.name)?,
            }
        }
    }
    Ok(())
}

/// Reads the binary data: skips the elements before `vertex`, then reads the vertices.
pub(super) fn read_binary<const BE: bool, R: BufRead>(
    reader: R,
    header: &Header,
    plan: &Plan,
    out: &mut Builder,
) -> Result<(), ParseError> {
    let mut input = BinInput {
        r: reader,
        pos: header.data_start,
    };
    for el in &header.elements[..plan.vertex] {
        skip_binary_element::<BE, R>(&mut input, el)?;
    }
    let vertex = &header.elements[plan.vertex];
    match vertex.fixed_size() {
        Some(size) => read_fixed_vertices::<BE, R>(&mut input, vertex, size, plan, out),
        None => read_list_vertices::<BE, R>(&mut input, vertex, plan, out),
    }
}

/// Fixed-size vertex records: read in large chunks and decoded in place.
fn read_fixed_vertices<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    vertex: &Element,
    size: usize,
    plan: &Plan,
    out: &mut Builder,
) -> Result<(), ParseError> {
    let layout = RecordLayout::new(vertex, plan);
    let per_chunk = (CHUNK_BYTES / size).max(1) as u64;
    let first = vertex.count.min(per_chunk) as usize;
    let mut buf = vec![0u8; first * size];
    let mut done = 0u64;
    while done < vertex.count {
        let n = (vertex.count - done).min(per_chunk) as usize;
        let chunk = &mut buf[..n * size];
        let got = input.fill(chunk)?;
        if got < chunk.len() {
            return Err(ParseError::Truncated(format!(
                "the header announces {} vertices of {size} bytes, but the data ends after \
                 {} complete vertices",
                vertex.count,
                done + (got / size) as u64
            )));
        }
        layout.decode::<BE>(chunk, size, out);
        done += n as u64;
    }
    Ok(())
}

/// A value's place in a fixed-size binary record.
#[derive(Debug, Clone, Copy)]
struct Field {
    off: usize,
    ty: Scalar,
}

impl Field {
    /// Stands for a value the record lacks (reads as NaN); never used for kept slots.
    const ABSENT: Field = Field {
        off: usize::MAX,
        ty: Scalar::U8,
    };

    #[inline(always)]
    fn read<const BE: bool>(self, rec: &[u8]) -> f64 {
        rec.get(self.off..)
            .map_or(f64::NAN, |b| self.ty.decode::<BE>(b))
    }

    /// Reads a colour channel (see [`color_byte`]); `uchar` is taken as is.
    #[inline(always)]
    fn color<const BE: bool>(self, rec: &[u8]) -> u8 {
        match self.ty {
            Scalar::U8 => rec.get(self.off).copied().unwrap_or(0),
            ty => color_byte(self.read::<BE>(rec), ty.is_float()),
        }
    }
}

/// Where the kept values lie in a fixed-size binary vertex record. Records are decoded
/// column by column (all x y z of a chunk, then all intensities, ...), which keeps every
/// loop free of branches other than the type dispatch.
struct RecordLayout {
    /// Per slot, the property feeding it.
    at: [Option<Field>; SLOTS],
}

impl RecordLayout {
    fn new(vertex: &Element, plan: &Plan) -> Self {
        let mut at = [None; SLOTS];
        let mut off = 0;
        for (i, p) in vertex.props.iter().enumerate() {
            let ty = scalar_of(p);
            if let Some(slot) = plan.slot(i).and_then(|s| at.get_mut(s)) {
                *slot = Some(Field { off, ty });
            }
            off += ty.size();
        }
        RecordLayout { at }
    }

    fn field(&self, slot: usize) -> Field {
        self.at
            .get(slot)
            .copied()
            .flatten()
            .unwrap_or(Field::ABSENT)
    }

    fn triple(&self, first: usize) -> [Field; 3] {
        [
            self.field(first),
            self.field(first + 1),
            self.field(first + 2),
        ]
    }

    /// Decodes a chunk of records into the builder, dropping non-finite points.
    fn decode<const BE: bool>(&self, chunk: &[u8], size: usize, out: &mut Builder) {
        let recs = || chunk.chunks_exact(size);
        let start = out.points.len();
        let [x, y, z] = self.triple(X);
        if [x, y, z].iter().all(|f| f.ty == Scalar::F32) {
            // The common case: no detour through f64.
            out.points.extend(recs().map(|r| {
                Point3::new(
                    f32_at::<BE>(r, x.off),
                    f32_at::<BE>(r, y.off),
                    f32_at::<BE>(r, z.off),
                )
            }));
        } else {
            out.points.extend(recs().map(|r| {
                Point3::new(
                    x.read::<BE>(r) as f32,
                    y.read::<BE>(r) as f32,
                    z.read::<BE>(r) as f32,
                )
            }));
        }
        if let Some(v) = &mut out.intensity {
            let f = self.field(INTENSITY);
            v.extend(recs().map(|r| f.read::<BE>(r) as f32));
        }
        if let Some(v) = &mut out.normals {
            let [a, b, c] = self.triple(NORMAL);
            v.extend(recs().map(|r| {
                Vector3::new(
                    a.read::<BE>(r) as f32,
                    b.read::<BE>(r) as f32,
                    c.read::<BE>(r) as f32,
                )
            }));
        }
        if let Some(v) = &mut out.colors {
            let [a, b, c] = self.triple(COLOR);
            v.extend(recs().map(|r| [a.color::<BE>(r), b.color::<BE>(r), c.color::<BE>(r)]));
        }
        out.drop_non_finite_from(start);
    }
}

/// The `float` at byte `off` of a record (NaN past its end, which callers rule out).
#[inline(always)]
fn f32_at<const BE: bool>(rec: &[u8], off: usize) -> f32 {
    match rec.get(off..).and_then(<[u8]>::first_chunk) {
        Some(a) if BE => f32::from_be_bytes(*a),
        Some(a) => f32::from_le_bytes(*a),
        None => f32::NAN,
    }
}

/// Vertex records with list properties: read property by property.
fn read_list_vertices<const BE: bool, R: BufRead>(
    input: &mut BinInput<R>,
    vertex: &Element,
    plan: &Plan,
    out: &mut Builder,
) -> Result<(), ParseError> {
    let mut slots = [0.0f64; SLOTS];
    for instance in 0..vertex.count {
        let at = At {
            element: vertex,
            instance,
        };
        for (i, p) in vertex.props.iter().enumerate() {
            match p.kind {
                Kind::Scalar(ty) => {
                    let v = input
                        .value::<BE>(ty)?
                        .ok_or_else(|| at.truncated(&p.name))?;
                    if let Some(s) = plan.slot(i).and_then(|s| slots.get_mut(s)) {
                        *s = v;
                    }
                }
                Kind::List { count, item } => skip_list::<BE, R>(input, count, item, &at, &p.name)?,
            }
        }
        out.push(&slots);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::error::{Location, ParseError};
    use crate::io::ply::read;
    use crate::io::ply::tests::{big_endian_with_faces, sample, to_bytes};
    use crate::io::PlyEncoding;
    use nalgebra::{Point3, Vector3};

    #[test]
    fn big_endian_doubles_after_a_face_element() {
        let loaded = read(&big_endian_with_faces()[..]).unwrap();
        let c = &loaded.cloud;
        assert_eq!(
            c.points(),
            [
                Point3::new(1.5, -2.0, 3.25),
                Point3::new(0.0, 1e3, -0.5),
                Point3::new(-7.75, 8.0, 9.5)
            ]
        );
        assert_eq!(c.colors().unwrap(), [[255, 0, 7], [1, 2, 3], [10, 20, 30]]);
        assert!(c.intensity().is_none() && c.normals().is_none());
        assert_eq!(c.origin(), Point3::origin());
        assert_eq!(loaded.report.encoding, "binary_big_endian");
        assert_eq!(
            loaded.report.fields,
            ["x", "y", "z", "red", "green", "blue"]
        );
    }

    #[test]
    fn list_property_in_the_middle_of_binary_vertices() {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n\
            property float x\nproperty list uchar float extra\nproperty float y\n\
            property float z\nproperty double reflectance\nproperty float nx\n\
            property float ny\nproperty float nz\nend_header\n"
            .to_vec();
        let rows: [(f32, &[f32], f32, f32, f64); 3] = [
            (1.0, &[9.0, 8.0], 2.0, 3.0, 0.5),
            (4.0, &[], 5.0, 6.0, 1.5),
            (7.0, &[1.0, 2.0, 3.0, 4.0, 5.0], 8.0, 9.0, 2.5),
        ];
        for (x, list, y, z, r) in rows {
            b.extend_from_slice(&x.to_le_bytes());
            b.push(list.len() as u8);
            for v in list {
                b.extend_from_slice(&v.to_le_bytes());
            }
            for v in [y, z] {
                b.extend_from_slice(&v.to_le_bytes());
            }
            b.extend_from_slice(&r.to_le_bytes());
            for v in [0.0f32, 0.0, 1.0] {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        let loaded = read(&b[..]).unwrap();
        let c = &loaded.cloud;
        assert_eq!(
            c.points(),
            [
                Point3::new(1.0, 2.0, 3.0),
                Point3::new(4.0, 5.0, 6.0),
                Point3::new(7.0, 8.0, 9.0)
            ]
        );
        assert_eq!(c.intensity().unwrap(), [0.5, 1.5, 2.5]);
        assert_eq!(c.normals().unwrap(), [Vector3::z(); 3]);
        // The same data with a byte missing is truncated.
        b.pop();
        assert!(matches!(read(&b[..]), Err(ParseError::Truncated(_))));
    }

    /// Replaces text in the header of a PLY file, leaving the data as it is.
    fn edit_header(file: &[u8], from: &str, to: &str) -> Vec<u8> {
        let end = b"end_header\n";
        let split = file.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&file[..split]).unwrap();
        let mut out = header.replacen(from, to, 1).into_bytes();
        out.extend_from_slice(&file[split..]);
        out
    }

    #[test]
    fn truncated_and_lying_binary_data() {
        let full = to_bytes(&sample(true, true, true), PlyEncoding::BinaryLittleEndian);
        for cut in [1, 5, 27] {
            let r = read(&full[..full.len() - cut]);
            assert!(
                matches!(r, Err(ParseError::Truncated(_))),
                "cut {cut}: {r:?}"
            );
        }
        // A header claiming 10^12 vertices over a few bytes of data.
        let r = read(&edit_header(&full, "vertex 8", "vertex 1000000000000")[..]);
        assert!(matches!(r, Err(ParseError::Truncated(_))), "{r:?}");
        // The same in front of the vertices, with and without list properties.
        let be = big_endian_with_faces();
        for (from, to) in [
            ("face 2", "face 1000000000000"),
            ("face 2", "face 18446744073709551615"),
            ("vertex 3", "vertex 99999999999999"),
        ] {
            let r = read(&edit_header(&be, from, to)[..]);
            assert!(
                matches!(r, Err(ParseError::Truncated(_))),
                "{from} -> {to}: {r:?}"
            );
        }
        let fixed = "ply\nformat binary_little_endian 1.0\nelement pad 1000000000000\n\
            property double a\nelement vertex 1\nproperty float x\nproperty float y\n\
            property float z\nend_header\n0123456789";
        assert!(matches!(
            read(fixed.as_bytes()),
            Err(ParseError::Truncated(_))
        ));
    }

    #[test]
    fn negative_binary_list_count_is_an_error() {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement face 1\n\
            property list char int idx\nelement vertex 0\nproperty float x\n\
            property float y\nproperty float z\nend_header\n"
            .to_vec();
        let start = b.len() as u64;
        b.push(0xFF);
        match read(&b[..]) {
            Err(ParseError::Invalid {
                at: Location::Byte(n),
                ..
            }) => assert_eq!(n, start),
            other => panic!("{other:?}"),
        }
    }
}
