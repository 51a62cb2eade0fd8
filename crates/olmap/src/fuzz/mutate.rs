//! Mutations of a file's bytes: what damage, lies and editing slips do to real files.

use crate::sim::SimRng;

/// Numbers a text header might be edited to: zero, negatives, the edges of the integer
/// types, 10^12, floats that overflow, underflow or are not numbers.
const TEXT_NUMBERS: &[&str] = &[
    "0",
    "-1",
    "1",
    "255",
    "65536",
    "2147483647",
    "2147483648",
    "4294967295",
    "4294967296",
    "9223372036854775807",
    "18446744073709551615",
    "18446744073709551616",
    "1000000000000",
    "99999999999999999999999999",
    "1e308",
    "-1e308",
    "1e-320",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "0.0",
    "-0",
    "1e",
    ".",
];

/// Little-endian words a binary field might hold: the edges of the integer types, 10^12,
/// and the bits of NaN, infinity and the largest `f32`/`f64`.
const BINARY_WORDS: &[u64] = &[
    0,
    1,
    0x7F,
    0xFF,
    0xFFFF,
    0x7FFF_FFFF,
    0x8000_0000,
    0xFFFF_FFFF,
    1_000_000_000_000,
    0x7FFF_FFFF_FFFF_FFFF,
    u64::MAX,
    0x7FC0_0000,           // f32 NaN
    0x7F80_0000,           // f32 inf
    0x7F7F_FFFF,           // f32 max
    0x7FF8_0000_0000_0000, // f64 NaN
    0x7FF0_0000_0000_0000, // f64 inf
    0xFFF0_0000_0000_0000, // f64 -inf
    0x7FEF_FFFF_FFFF_FFFF, // f64 max
    0x3FF0_0000_0000_0000, // f64 1.0
];

/// Single bytes worth inserting: line ends, separators, signs, digits, the high bit.
const BYTES: &[u8] = b"\n\r \t,;#-+.e0159\x00\xff\x80";

/// How the `k`-th mutation of a case changed the bytes (for reports).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mutation {
    /// One bit flipped.
    BitFlip,
    /// One byte replaced by a random or an interesting one.
    SetByte,
    /// 1-4 bytes inserted.
    Insert,
    /// A run of 1-16 bytes deleted.
    Delete,
    /// The file cut short.
    Truncate,
    /// A decimal digit changed to another.
    Digit,
    /// A decimal number replaced by an edge value (huge, negative, NaN, ...).
    TextNumber,
    /// 2, 4 or 8 bytes overwritten with an edge value (little-endian).
    BinaryWord,
    /// A chunk copied to another place (inserted).
    Duplicate,
    /// The start of this file followed by the end of another file.
    Splice,
    /// A whole line deleted or doubled.
    Line,
}

/// Applies 1 to 8 random mutations (fewer more often) to `bytes`; `others` are the files
/// that splices may take a tail from. Deterministic for a given generator state.
pub fn mutate(bytes: &[u8], others: &[&[u8]], rng: &mut SimRng) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let mut n = 1;
    while n < 8 && rng.chance(0.45) {
        n += 1;
    }
    for _ in 0..n {
        let m = match rng.index(11) {
            0 => Mutation::BitFlip,
            1 => Mutation::SetByte,
            2 => Mutation::Insert,
            3 => Mutation::Delete,
            4 => Mutation::Truncate,
            5 => Mutation::Digit,
            6 => Mutation::TextNumber,
            7 => Mutation::BinaryWord,
            8 => Mutation::Duplicate,
            9 => Mutation::Splice,
            _ => Mutation::Line,
        };
        apply(&mut b, m, others, rng);
    }
    b
}

/// Applies one mutation.
pub fn apply(b: &mut Vec<u8>, m: Mutation, others: &[&[u8]], rng: &mut SimRng) {
    // Mutations near the start (the header) are the ones that lie about sizes: half of
    // the positions are drawn from the first 256 bytes.
    let pos = |rng: &mut SimRng, len: usize| -> usize {
        if len == 0 {
            0
        } else if rng.chance(0.5) {
            rng.index(len.min(256))
        } else {
            rng.index(len)
        }
    };
    let len = b.len();
    match m {
        Mutation::BitFlip if len > 0 => {
            let i = pos(rng, len);
            b[i] ^= 1 << rng.index(8);
        }
        Mutation::SetByte if len > 0 => {
            let i = pos(rng, len);
            b[i] = if rng.chance(0.5) {
                BYTES[rng.index(BYTES.len())]
            } else {
                rng.next_u64() as u8
            };
        }
        Mutation::Insert => {
            let i = pos(rng, len + 1).min(len);
            for _ in 0..1 + rng.index(4) {
                b.insert(i, BYTES[rng.index(BYTES.len())]);
            }
        }
        Mutation::Delete if len > 0 => {
            let i = pos(rng, len);
            let n = (1 + rng.index(16)).min(len - i);
            b.drain(i..i + n);
        }
        Mutation::Truncate if len > 0 => {
            let i = rng.index(len);
            b.truncate(i);
        }
        Mutation::Digit => {
            if let Some(i) = find_from(b, pos(rng, len), u8::is_ascii_digit) {
                b[i] = b'0' + rng.index(10) as u8;
            }
        }
        Mutation::TextNumber => {
            if let Some(start) = find_from(b, pos(rng, len), u8::is_ascii_digit) {
                let number = |c: &u8| c.is_ascii_digit() || matches!(c, b'.' | b'e' | b'E');
                let mut s = start;
                while s > 0 && (number(&b[s - 1]) || b[s - 1] == b'-') {
                    s -= 1;
                }
                let mut e = start;
                while e < b.len() && number(&b[e]) {
                    e += 1;
                }
                let token = TEXT_NUMBERS[rng.index(TEXT_NUMBERS.len())];
                b.splice(s..e, token.bytes());
            }
        }
        Mutation::BinaryWord if len > 0 => {
            let width = [2, 4, 8][rng.index(3)];
            let mut i = pos(rng, len);
            if rng.chance(0.5) {
                i -= i % width; // aligned, as real fields are
            }
            let word = BINARY_WORDS[rng.index(BINARY_WORDS.len())].to_le_bytes();
            for (k, &w) in word.iter().take(width).enumerate() {
                if let Some(x) = b.get_mut(i + k) {
                    *x = w;
                }
            }
        }
        Mutation::Duplicate if len > 0 => {
            let i = rng.index(len);
            let n = (1 + rng.index(256.min(len))).min(len - i);
            let chunk = b[i..i + n].to_vec();
            let at = rng.index(len + 1);
            b.splice(at..at, chunk);
        }
        Mutation::Splice if !others.is_empty() => {
            let other = others[rng.index(others.len())];
            let cut = rng.index(len + 1);
            let from = rng.index(other.len() + 1);
            b.truncate(cut);
            b.extend_from_slice(&other[from..]);
        }
        Mutation::Line => {
            let lines: Vec<usize> = std::iter::once(0)
                .chain(
                    b.iter()
                        .enumerate()
                        .filter(|(_, &c)| c == b'\n')
                        .map(|(i, _)| i + 1),
                )
                .filter(|&i| i < b.len())
                .collect();
            if !lines.is_empty() {
                let k = rng.index(lines.len().min(64));
                let s = lines[k];
                let e = lines.get(k + 1).copied().unwrap_or(b.len());
                if rng.chance(0.5) {
                    b.drain(s..e);
                } else {
                    let line = b[s..e].to_vec();
                    b.splice(s..s, line);
                }
            }
        }
        _ => {}
    }
}

/// The first position at or after `from` (wrapping to the start) whose byte matches.
fn find_from(b: &[u8], from: usize, pred: impl Fn(&u8) -> bool) -> Option<usize> {
    let from = from.min(b.len());
    b[from..]
        .iter()
        .position(&pred)
        .map(|i| i + from)
        .or_else(|| b[..from].iter().position(&pred))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_mutation_keeps_within_bounds_and_changes_something() {
        let base = b"FIELDS x y z\nWIDTH 12\nDATA ascii\n1 2 3\n4.5 -6e2 7\n".to_vec();
        let other = b"ply\nformat ascii 1.0\n".to_vec();
        let mut rng = SimRng::new(7);
        let kinds = [
            Mutation::BitFlip,
            Mutation::SetByte,
            Mutation::Insert,
            Mutation::Delete,
            Mutation::Truncate,
            Mutation::Digit,
            Mutation::TextNumber,
            Mutation::BinaryWord,
            Mutation::Duplicate,
            Mutation::Splice,
            Mutation::Line,
        ];
        for m in kinds {
            let mut changed = false;
            for _ in 0..50 {
                let mut b = base.clone();
                apply(&mut b, m, &[&other], &mut rng);
                changed |= b != base;
                // And on an empty file nothing panics.
                apply(&mut Vec::new(), m, &[&other], &mut rng);
            }
            assert!(changed, "{m:?} never changed the file");
        }
        // A text number is replaced whole.
        let mut hits = 0;
        for _ in 0..200 {
            let mut b = b"WIDTH 12\n".to_vec();
            apply(&mut b, Mutation::TextNumber, &[], &mut rng);
            let text = String::from_utf8_lossy(&b).into_owned();
            let value = text.trim_start_matches("WIDTH ").trim_end();
            hits += usize::from(TEXT_NUMBERS.contains(&value));
        }
        assert_eq!(hits, 200);
        // Same seed, same mutations.
        let a = mutate(&base, &[&other], &mut SimRng::new(3));
        let b = mutate(&base, &[&other], &mut SimRng::new(3));
        assert_eq!(a, b);
    }
}
