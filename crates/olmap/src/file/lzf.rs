//! LZF compression in pure Rust, in the stream format of Marc Lehmann's liblzf.
//!
//! PCL stores `DATA binary_compressed` PCD files as one LZF block (its `lzf.cpp` is a copy of
//! liblzf), so this module exists for [`crate::io::pcd`]. An LZF stream is a sequence of
//! instructions, each starting with a control byte `c`:
//!
//! * `c < 32`: a literal run; the next `c + 1` bytes are copied to the output.
//! * otherwise a back-reference: `len = c >> 5` (when it is 7 the next byte is added to it),
//!   then `offset = ((c & 0x1f) << 8) + next byte + 1`; `len + 2` bytes are copied from
//!   `offset` bytes before the end of the output, one by one, so a reference may overlap the
//!   bytes it produces (`offset` 1 repeats the last byte).
//!
//! Hence literal runs are 1..=32 bytes, offsets 1..=8192 and references 3..=264 bytes long
//! (the format allows 2, which never pays off and which liblzf does not produce).
//!
//! The stream carries no length: the caller knows the size of the decompressed data (PCD
//! stores it beside the block) and [`decompress`] insists on getting exactly that many bytes.
//! [`decompress`] never panics and never allocates more than the input can expand to, so it
//! is safe on untrusted data.

/// Longest literal run one control byte can announce.
const MAX_LITERAL: usize = 32;
/// Largest back-reference distance.
const MAX_OFFSET: usize = 1 << 13;
/// Longest back-reference.
const MAX_MATCH: usize = (1 << 8) + (1 << 3);
/// Shortest back-reference the compressor emits.
const MIN_MATCH: usize = 3;
/// Bits of the compressor's hash table index.
const HASH_BITS: u32 = 16;
/// The most output bytes one input byte can produce: a 3-byte reference gives 264 bytes.
const MAX_EXPANSION: usize = 88;

/// Why an LZF stream could not be decompressed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LzfError {
    /// The stream ends inside an instruction.
    #[error("LZF stream ends inside the instruction at byte {at}")]
    Truncated {
        /// Offset of the control byte of the incomplete instruction.
        at: usize,
    },
    /// A back-reference points before the start of the output.
    #[error(
        "LZF back-reference at byte {at} reaches {offset} bytes back but only {available} \
         bytes have been produced"
    )]
    BadReference {
        /// Offset of the control byte of the reference.
        at: usize,
        /// How far back the reference reaches.
        offset: usize,
        /// Bytes produced so far.
        available: usize,
    },
    /// The stream produces more bytes than expected.
    #[error("LZF stream produces more than the expected {expected} bytes (at byte {at})")]
    TooLong {
        /// Offset of the control byte of the instruction that overflows.
        at: usize,
        /// The expected decompressed size.
        expected: usize,
    },
    /// The stream ends having produced fewer bytes than expected.
    #[error("LZF stream produces {found} bytes, expected {expected}")]
    TooShort {
        /// The expected decompressed size.
        expected: usize,
        /// The bytes the stream produced.
        found: usize,
    },
}

impl LzfError {
    /// The offset in the stream of the instruction at fault (`None` when the stream as a
    /// whole is too short).
    pub fn position(&self) -> Option<usize> {
        match *self {
            LzfError::Truncated { at }
            | LzfError::BadReference { at, .. }
            | LzfError::TooLong { at, .. } => Some(at),
            LzfError::TooShort { .. } => None,
        }
    }

    /// What is wrong, without the position (for a caller that names the place itself,
    /// as a byte offset in its file).
    pub fn what(&self) -> String {
        match *self {
            LzfError::Truncated { .. } => "the LZF stream ends inside an instruction".into(),
            LzfError::BadReference {
                offset, available, ..
            } => format!(
                "an LZF back-reference reaches {offset} bytes back but only {available} bytes \
                 have been produced"
            ),
            LzfError::TooLong { expected, .. } => {
                format!("the LZF stream produces more than the expected {expected} bytes")
            }
            LzfError::TooShort { expected, found } => {
                format!("the LZF stream produces {found} bytes, expected {expected}")
            }
        }
    }
}

/// Decompresses an LZF stream that must produce exactly `expected_len` bytes.
///
/// Every malformed stream (cut short, referring before the start of the output, producing
/// more or fewer than `expected_len` bytes) is an error; no input makes it panic, and it
/// never reserves more memory than the input can really expand to.
///
/// ```
/// use olmap::file::lzf;
/// // A literal run "ab", then 4 bytes copied from 2 bytes back (overlapping).
/// let stream = [1, b'a', b'b', 2 << 5, 1];
/// assert_eq!(lzf::decompress(&stream, 6).unwrap(), b"ababab");
/// assert!(lzf::decompress(&stream, 5).is_err());
/// ```
pub fn decompress(input: &[u8], expected_len: usize) -> Result<Vec<u8>, LzfError> {
    let cap = expected_len.min(input.len().saturating_mul(MAX_EXPANSION));
    let mut out = Vec::with_capacity(cap);
    let mut ip = 0;
    while ip < input.len() {
        let at = ip;
        let ctrl = usize::from(input[ip]);
        ip += 1;
        if ctrl < MAX_LITERAL {
            let run = ctrl + 1;
            let literal = input.get(ip..ip + run).ok_or(LzfError::Truncated { at })?;
            if out.len() + run > expected_len {
                return Err(LzfError::TooLong {
                    at,
                    expected: expected_len,
                });
            }
            out.extend_from_slice(literal);
            ip += run;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += usize::from(*input.get(ip).ok_or(LzfError::Truncated { at })?);
                ip += 1;
            }
            len += 2;
            let low = usize::from(*input.get(ip).ok_or(LzfError::Truncated { at })?);
            ip += 1;
            let offset = ((ctrl & 0x1f) << 8) + low + 1;
            if offset > out.len() {
                return Err(LzfError::BadReference {
                    at,
                    offset,
                    available: out.len(),
                });
            }
            if out.len() + len > expected_len {
                return Err(LzfError::TooLong {
                    at,
                    expected: expected_len,
                });
            }
            copy_back(&mut out, offset, len);
        }
    }
    if out.len() != expected_len {
        return Err(LzfError::TooShort {
            expected: expected_len,
            found: out.len(),
        });
    }
    Ok(out)
}

/// Appends `len` bytes copied from `offset` bytes before the end of `out`, with the meaning
/// of a byte-by-byte copy when the ranges overlap (the pattern of the last `offset` bytes
/// repeats). The caller has checked `1 <= offset <= out.len()`.
#[inline]
fn copy_back(out: &mut Vec<u8>, offset: usize, len: usize) {
    let start = out.len() - offset;
    let mut copied = 0;
    while copied < len {
        // Everything from `start + copied` to the current end exists already: `offset` bytes.
        let n = (len - copied).min(offset);
        let from = start + copied;
        out.extend_from_within(from..from + n);
        copied += n;
    }
}

/// Compresses bytes into an LZF stream that liblzf (and PCL) can decompress.
///
/// A greedy compressor: a hash of the next three bytes finds the last position that started
/// with the same hash; a verified match of at least 3 bytes within 8192 bytes becomes a
/// back-reference, anything else a literal. Incompressible input grows by 1 byte in 32.
///
/// ```
/// use olmap::file::lzf;
/// let data = b"abcabcabcabcabcabcabcabc".repeat(10);
/// let packed = lzf::compress(&data);
/// assert!(packed.len() < data.len());
/// assert_eq!(lzf::decompress(&packed, data.len()).unwrap(), data);
/// ```
pub fn compress(input: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(input.len() + input.len() / MAX_LITERAL + 1);
    // Last position + 1 of each hash (0: none yet).
    let mut table = vec![0usize; 1 << HASH_BITS];
    let mut literal_start = 0;
    let mut ip = 0;
    while ip + MIN_MATCH <= input.len() {
        let h = hash3(input, ip);
        let candidate = table[h];
        table[h] = ip + 1;
        let len = match candidate.checked_sub(1) {
            Some(r) if ip - r <= MAX_OFFSET => match_length(input, r, ip),
            _ => 0,
        };
        if len < MIN_MATCH {
            ip += 1;
            continue;
        }
        let r = candidate - 1;
        emit_literals(&mut out, &input[literal_start..ip]);
        emit_reference(&mut out, ip - r, len);
        // Remember the positions inside the match too: better matches later on.
        for p in ip + 1..(ip + len).min(input.len().saturating_sub(MIN_MATCH - 1)) {
            table[hash3(input, p)] = p + 1;
        }
        ip += len;
        literal_start = ip;
    }
    emit_literals(&mut out, &input[literal_start..]);
    out
}

/// Hash-table index of the three bytes at `p` (the caller has checked they exist).
#[inline]
fn hash3(input: &[u8], p: usize) -> usize {
    let v = u32::from(input[p]) << 16 | u32::from(input[p + 1]) << 8 | u32::from(input[p + 2]);
    (v.wrapping_mul(0x9E37_79B1) >> (32 - HASH_BITS)) as usize
}

/// Length of the common run of `input[r..]` and `input[ip..]` (with `r < ip`), capped at
/// the longest reference.
#[inline]
fn match_length(input: &[u8], r: usize, ip: usize) -> usize {
    let max = MAX_MATCH.min(input.len() - ip);
    input[r..r + max]
        .iter()
        .zip(&input[ip..ip + max])
        .take_while(|(a, b)| a == b)
        .count()
}

/// Appends literal runs (of at most 32 bytes each) holding `bytes`.
fn emit_literals(out: &mut Vec<u8>, bytes: &[u8]) {
    for chunk in bytes.chunks(MAX_LITERAL) {
        out.push((chunk.len() - 1) as u8);
        out.extend_from_slice(chunk);
    }
}

/// Appends a back-reference of `len` (3..=264) bytes from `distance` (1..=8192) back.
fn emit_reference(out: &mut Vec<u8>, distance: usize, len: usize) {
    debug_assert!((1..=MAX_OFFSET).contains(&distance) && (MIN_MATCH..=MAX_MATCH).contains(&len));
    let off = distance - 1;
    let l = len - 2;
    let high = (off >> 8) as u8;
    if l < 7 {
        out.push(((l as u8) << 5) | high);
    } else {
        out.push((7 << 5) | high);
        out.push((l - 7) as u8);
    }
    out.push((off & 0xff) as u8);
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn round_trip(data: &[u8]) {
        let packed = compress(data);
        assert_eq!(decompress(&packed, data.len()).unwrap(), data);
    }

    /// A deterministic pseudo-random byte sequence (xorshift).
    fn noise(n: usize, mut seed: u64) -> Vec<u8> {
        (0..n)
            .map(|_| {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 24) as u8
            })
            .collect()
    }

    #[test]
    fn round_trips_small_inputs() {
        round_trip(b"");
        round_trip(b"a");
        round_trip(b"ab");
        round_trip(b"abc");
        round_trip(b"aaaa");
        assert_eq!(compress(b""), Vec::<u8>::new());
        assert_eq!(compress(b"a"), vec![0, b'a']);
    }

    #[test]
    fn round_trips_random_data() {
        for n in [31, 32, 33, 64, 1000, 70_000] {
            round_trip(&noise(n, n as u64 + 1));
        }
    }

    #[test]
    fn compresses_repetitive_data() {
        let data = vec![7u8; 100_000];
        let packed = compress(&data);
        assert!(packed.len() < 2_000, "{} bytes", packed.len());
        round_trip(&data);
        let pattern: Vec<u8> = b"0123456789abcdef"
            .iter()
            .cycle()
            .take(200_000)
            .copied()
            .collect();
        let packed = compress(&pattern);
        assert!(packed.len() < 4_000, "{} bytes", packed.len());
        round_trip(&pattern);
    }

    #[test]
    fn round_trips_large_mixed_data() {
        // Over 64 KiB, with repeats farther apart than the 8 KiB window and nearer.
        let mut data = noise(20_000, 99);
        let block = data.clone();
        data.extend_from_slice(&block[..5000]);
        data.extend_from_slice(&noise(10_000, 5));
        data.extend_from_slice(&block);
        data.extend(std::iter::repeat_n(0u8, 30_000));
        data.extend_from_slice(&block[100..9000]);
        assert!(data.len() > 65_536);
        round_trip(&data);
    }

    #[test]
    fn decodes_a_hand_made_stream() {
        let stream = [
            2,
            b'a',
            b'b',
            b'c', // literal "abc"
            (1 << 5),
            2, // 3 bytes from 3 back: "abc"
            (7 << 5),
            3,
            0, // 7 + 3 + 2 = 12 bytes from 1 back: "c" x 12
            0,
            b'!', // literal "!"
        ];
        let out = decompress(&stream, 19).unwrap();
        assert_eq!(out, b"abcabccccccccccccc!");
        // A long reference with a 13-bit offset.
        let mut data = noise(8192, 3);
        let head = data[..264].to_vec();
        data.extend_from_slice(&head);
        let mut stream = Vec::new();
        emit_literals(&mut stream, &data[..8192]);
        stream.extend_from_slice(&[(7 << 5) | 0x1f, 255, 0xff]);
        assert_eq!(decompress(&stream, 8192 + 264).unwrap(), data);
    }

    #[test]
    fn rejects_malformed_streams() {
        assert_eq!(
            decompress(&[5, b'a'], 6),
            Err(LzfError::Truncated { at: 0 })
        );
        assert_eq!(
            decompress(&[0, b'a', 1 << 5], 4),
            Err(LzfError::Truncated { at: 2 })
        );
        assert_eq!(
            decompress(&[0, b'a', 7 << 5, 1], 20),
            Err(LzfError::Truncated { at: 2 })
        );
        assert_eq!(
            decompress(&[0, b'a', 1 << 5, 1], 4),
            Err(LzfError::BadReference {
                at: 2,
                offset: 2,
                available: 1
            })
        );
        assert_eq!(
            decompress(&[1, b'a', b'b'], 1),
            Err(LzfError::TooLong { at: 0, expected: 1 })
        );
        assert_eq!(
            decompress(&[0, b'a', 1 << 5, 0], 3),
            Err(LzfError::TooLong { at: 2, expected: 3 })
        );
        assert_eq!(
            decompress(&[0, b'a'], 2),
            Err(LzfError::TooShort {
                expected: 2,
                found: 1
            })
        );
        assert_eq!(
            decompress(&[], 1),
            Err(LzfError::TooShort {
                expected: 1,
                found: 0
            })
        );
        assert!(decompress(&[0, b'a'], usize::MAX).is_err());
    }

    proptest! {
        #[test]
        fn prop_round_trip(data in prop::collection::vec(any::<u8>(), 0..3000)) {
            let packed = compress(&data);
            prop_assert_eq!(decompress(&packed, data.len()).unwrap(), data);
        }

        #[test]
        fn prop_round_trip_low_entropy(
            data in prop::collection::vec(0u8..3, 0..5000),
        ) {
            let packed = compress(&data);
            prop_assert_eq!(decompress(&packed, data.len()).unwrap(), data);
        }

        #[test]
        fn prop_decompress_never_panics(
            stream in prop::collection::vec(any::<u8>(), 0..500),
            len in prop_oneof![0usize..5000, any::<usize>()],
        ) {
            if let Ok(out) = decompress(&stream, len) {
                prop_assert_eq!(out.len(), len);
            }
        }
    }
}
