//! The `binary` (packed records) and `binary_compressed` (LZF-compressed columns) data of
//! a PCD file, read a chunk at a time.

use std::io::{self, BufRead};

use nalgebra::Vector3;

use super::header::{Header, Roles};
use super::read::CloudBuilder;
use super::{bytes_at, Scalar, CHUNK_BYTES};
use crate::error::{Location, ParseError};
use crate::file::lzf;
use crate::io::{finite_point, ReadReport};

/// Where the first value of a field of point `i` lies in a buffer: `base + i * stride`.
#[derive(Debug, Clone, Copy)]
struct Accessor {
    base: usize,
    stride: usize,
    scalar: Scalar,
}

impl Accessor {
    #[inline]
    fn value(self, buf: &[u8], i: usize) -> f64 {
        self.scalar.read(buf, self.base + i * self.stride)
    }

    /// The 4 bytes of the value as a little-endian `u32` (for `rgb`).
    #[inline]
    fn bits(self, buf: &[u8], i: usize) -> u32 {
        u32::from_le_bytes(bytes_at(buf, self.base + i * self.stride))
    }
}

/// The accessors of the fields the cloud keeps.
#[derive(Debug, Clone, Copy)]
struct Plan {
    xyz: [Accessor; 3],
    intensity: Option<Accessor>,
    normals: Option<[Accessor; 3]>,
    rgb: Option<Accessor>,
}

impl Plan {
    fn new(roles: &Roles, accessor: impl Fn(usize) -> Accessor) -> Plan {
        Plan {
            xyz: roles.xyz.map(&accessor),
            intensity: roles.intensity.map(&accessor),
            normals: roles.normals.map(|n| n.map(&accessor)),
            rgb: roles.rgb.map(&accessor),
        }
    }

    /// Packed records (`DATA binary`): point `i` is the `i`-th record of the buffer.
    fn packed(header: &Header) -> Plan {
        Plan::new(&header.roles, |f| Accessor {
            base: header.fields[f].offset,
            stride: header.record_size,
            scalar: header.fields[f].scalar,
        })
    }

    /// Structure of arrays (`DATA binary_compressed`) of `points` points: field `f` starts at
    /// `points × offset(f)`.
    fn columns(header: &Header, points: usize) -> Plan {
        Plan::new(&header.roles, |f| Accessor {
            base: points * header.fields[f].offset,
            stride: header.fields[f].bytes(),
            scalar: header.fields[f].scalar,
        })
    }

    /// Decodes points `0..n` of `buf`, keeping the finite ones.
    fn decode(&self, buf: &[u8], n: usize, out: &mut CloudBuilder, report: &mut ReadReport) {
        let numeric = self
            .xyz
            .iter()
            .chain(&self.intensity)
            .chain(self.normals.iter().flatten());
        if numeric.into_iter().all(|a| a.scalar == Scalar::F32) {
            // The usual case, compiled without the per-value type dispatch.
            self.decode_as::<true>(buf, n, out, report);
        } else {
            self.decode_as::<false>(buf, n, out, report);
        }
    }

    /// [`Plan::decode`]; with `ALL_F32` every numeric field is known to be `F 4`.
    #[inline(always)]
    fn decode_as<const ALL_F32: bool>(
        &self,
        buf: &[u8],
        n: usize,
        out: &mut CloudBuilder,
        report: &mut ReadReport,
    ) {
        let value = |a: Accessor, i: usize| {
            if ALL_F32 {
                f64::from(f32::from_le_bytes(bytes_at(buf, a.base + i * a.stride)))
            } else {
                a.value(buf, i)
            }
        };
        for i in 0..n {
            let xyz = self.xyz.map(|a| value(a, i));
            let Some(p) = finite_point(xyz, report) else {
                continue;
            };
            let intensity = self.intensity.map_or(0.0, |a| value(a, i) as f32);
            let normal = self.normals.map_or_else(Vector3::zeros, |n| {
                Vector3::new(
                    value(n[0], i) as f32,
                    value(n[1], i) as f32,
                    value(n[2], i) as f32,
                )
            });
            let rgb = self.rgb.map_or(0, |a| a.bits(buf, i));
            out.push(p, intensity, normal, rgb);
        }
    }
}

/// Reads up to `want` bytes (fewer only at the end of the stream) into `buf`. The buffer
/// grows as bytes arrive, so a size claimed by a header allocates nothing that is not there.
fn fill_up_to<R: BufRead>(reader: &mut R, buf: &mut Vec<u8>, want: usize) -> io::Result<()> {
    buf.clear();
    while buf.len() < want {
        let available = match reader.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if available.is_empty() {
            break;
        }
        let n = available.len().min(want - buf.len());
        buf.extend_from_slice(&available[..n]);
        reader.consume(n);
    }
    Ok(())
}

/// `POINTS × record size` in bytes, or an error when it overflows.
fn data_bytes(header: &Header) -> Result<u64, ParseError> {
    header
        .points
        .checked_mul(header.record_size as u64)
        .ok_or_else(|| {
            ParseError::Malformed(format!(
                "POINTS × record size = {} × {} bytes overflows",
                header.points, header.record_size
            ))
        })
}

/// `DATA binary`: packed records, read and decoded a chunk at a time.
pub(super) fn read_binary<R: BufRead>(
    reader: &mut R,
    header: &Header,
    out: &mut CloudBuilder,
    report: &mut ReadReport,
) -> Result<(), ParseError> {
    let total = data_bytes(header)?;
    let record = header.record_size;
    let per_chunk = (CHUNK_BYTES / record).max(1);
    let plan = Plan::packed(header);
    let mut buf = Vec::new();
    let mut remaining = header.points;
    let mut done = 0u64;
    while remaining > 0 {
        // Both fit: n <= per_chunk, and n * record <= max(CHUNK_BYTES, record).
        let n = remaining.min(per_chunk as u64) as usize;
        let want = n * record;
        fill_up_to(reader, &mut buf, want)?;
        if buf.len() < want {
            return Err(ParseError::Truncated(format!(
                "binary data: expected {total} bytes ({} points × {record} bytes) after the \
                 header, found {}",
                header.points,
                done + buf.len() as u64
            )));
        }
        plan.decode(&buf, n, out, report);
        done += want as u64;
        remaining -= n as u64;
    }
    Ok(())
}

/// `DATA binary_compressed`: two sizes and an LZF block of the fields as columns.
pub(super) fn read_compressed<R: BufRead>(
    reader: &mut R,
    header: &Header,
    out: &mut CloudBuilder,
    report: &mut ReadReport,
) -> Result<(), ParseError> {
    let mut buf = Vec::new();
    fill_up_to(reader, &mut buf, 8)?;
    if buf.len() < 8 {
        return Err(ParseError::Truncated(format!(
            "binary_compressed: expected the 8-byte block sizes after the header, found {} bytes",
            buf.len()
        )));
    }
    let compressed = u32::from_le_bytes(bytes_at(&buf, 0));
    let uncompressed = u32::from_le_bytes(bytes_at(&buf, 4));
    let expected = data_bytes(header)?;
    if u64::from(uncompressed) != expected {
        return Err(ParseError::at(
            Location::Byte(header.data_offset + 4),
            format!(
                "binary_compressed: the block holds {uncompressed} bytes uncompressed, but \
                 POINTS × record size = {} × {} = {expected}",
                header.points, header.record_size
            ),
        ));
    }
    fill_up_to(reader, &mut buf, compressed as usize)?;
    if buf.len() < compressed as usize {
        return Err(ParseError::Truncated(format!(
            "binary_compressed: expected an LZF block of {compressed} bytes, found {}",
            buf.len()
        )));
    }
    let data = lzf::decompress(&buf, uncompressed as usize).map_err(|e| {
        // The instruction at fault, as a byte of the file (the block starts 8 bytes in).
        let block = header.data_offset + 8;
        ParseError::at(
            Location::Byte(block + e.position().unwrap_or(0) as u64),
            format!("binary_compressed: {}", e.what()),
        )
    })?;
    // `points <= uncompressed` (records are at least 3 bytes), so it fits a usize.
    let points = header.points as usize;
    Plan::columns(header, points).decode(&data, points, out, report);
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::error::{Location, ParseError};
    use crate::io::pcd::read;
    use crate::io::pcd::tests::{encode, sample, ALL};
    use crate::io::PcdEncoding;

    #[test]
    fn tolerates_bytes_after_the_compressed_block() {
        let cloud = sample(100, true, false, true);
        let mut bytes = encode(&cloud, PcdEncoding::BinaryCompressed);
        bytes.extend_from_slice(&[0xde, 0xad, 0xbe, 0xef, 0, 0, 0, 1, 2, 3]);
        bytes.extend(std::iter::repeat_n(0u8, 4096));
        let loaded = read(&bytes[..]).unwrap();
        assert_eq!(loaded.cloud, cloud);
        assert_eq!(loaded.report.encoding, "binary_compressed");
    }

    #[test]
    fn reads_an_empty_compressed_cloud() {
        let text = b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nPOINTS 0\n\
                     DATA binary_compressed\n\0\0\0\0\0\0\0\0";
        let loaded = read(&text[..]).unwrap();
        assert!(loaded.cloud.is_empty());
        assert_eq!(loaded.report.records, 0);
    }

    #[test]
    fn rejects_truncated_binary_with_the_byte_counts() {
        let cloud = sample(10, false, false, false);
        let bytes = encode(&cloud, PcdEncoding::Binary);
        match read(&bytes[..bytes.len() - 5]) {
            Err(ParseError::Truncated(msg)) => {
                assert!(msg.contains("expected 120 bytes"), "{msg}");
                assert!(msg.contains("found 115"), "{msg}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn header_claiming_huge_counts_is_truncated_not_oom() {
        for data in ["binary", "ascii", "binary_compressed"] {
            let text = format!(
                "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1000000\nHEIGHT 1000000\n\
                 POINTS 1000000000000\nDATA {data}\n0123456789abcdef"
            );
            let err = read(text.as_bytes()).unwrap_err();
            assert!(
                matches!(err, ParseError::Truncated(_) | ParseError::Invalid { .. }),
                "{data}: {err:?}"
            );
        }
        // A record size that overflows.
        let text = "FIELDS x y z\nSIZE 4 4 8\nTYPE F F U\nCOUNT 1 1 2305843009213693951\n\
                    WIDTH 4294967295\nHEIGHT 4294967295\nDATA binary\n";
        assert!(read(text.as_bytes()).is_err());
        let text = "FIELDS x y z\nSIZE 4 4 8\nTYPE F F U\nCOUNT 1 1 2305843009213693950\n\
                    WIDTH 4294967295\nHEIGHT 4294967295\nDATA binary\n";
        assert!(read(text.as_bytes()).is_err());
        // A huge single record with little data.
        let text = "FIELDS x y z\nSIZE 4 4 8\nTYPE F F U\nCOUNT 1 1 200000000000\n\
                    WIDTH 1\nDATA binary\n0123";
        assert!(matches!(
            read(text.as_bytes()),
            Err(ParseError::Truncated(_))
        ));
    }

    #[test]
    fn rejects_lying_points() {
        // POINTS and WIDTH agree but promise more than the data holds.
        let cloud = sample(3, false, false, false);
        for encoding in ALL {
            let bytes = encode(&cloud, encoding);
            let text = String::from_utf8_lossy(&bytes)
                .replace("WIDTH 3", "WIDTH 4")
                .replace("POINTS 3", "POINTS 4");
            let patched: Vec<u8> = if encoding == PcdEncoding::Ascii {
                text.into_bytes()
            } else {
                let split = bytes.windows(5).position(|w| w == b"DATA ").unwrap();
                let head = String::from_utf8_lossy(&bytes[..split])
                    .replace("WIDTH 3", "WIDTH 4")
                    .replace("POINTS 3", "POINTS 4");
                [head.as_bytes(), &bytes[split..]].concat()
            };
            let err = read(&patched[..]).unwrap_err();
            match encoding {
                PcdEncoding::BinaryCompressed => assert!(
                    matches!(
                        err,
                        ParseError::Invalid {
                            at: Location::Byte(_),
                            ..
                        }
                    ),
                    "{err:?}"
                ),
                _ => assert!(matches!(err, ParseError::Truncated(_)), "{err:?}"),
            }
        }
    }

    #[test]
    fn rejects_a_wrong_uncompressed_size() {
        let cloud = sample(4, false, false, false);
        let mut bytes = encode(&cloud, PcdEncoding::BinaryCompressed);
        let at = bytes
            .windows(18)
            .position(|w| w == b"binary_compressed\n")
            .unwrap()
            + 18;
        bytes[at + 4] ^= 1;
        assert!(read(&bytes[..]).is_err());
        let mut bytes = encode(&cloud, PcdEncoding::BinaryCompressed);
        bytes.truncate(at + 10);
        assert!(matches!(read(&bytes[..]), Err(ParseError::Truncated(_))));
    }
}
