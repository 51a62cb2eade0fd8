//! Packing a voxel key and its count into one `u64`.
//!
//! Layout (most significant first): 18 bits x, 18 bits y, 18 bits z (each stored as
//! `k + 2^17`, so keys from -131,072 to 131,071), then 10 bits of count (1..=1023). A stored
//! voxel always has a count of at least 1, so a packed entry is never 0: 0 marks an empty
//! slot of the hash table. Eight bytes per entry is what keeps the map under 16 bytes per
//! stored voxel.
//!
//! The key range is ±131,072 voxels per axis about the map origin: ±2.6 km at 0.02 m,
//! ±6.5 km at 0.05 m, ±13 km at 0.1 m.

use crate::geometry::VoxelKey;

/// Bits per axis of a packed key.
pub const AXIS_BITS: u32 = 18;
const OFFSET: i64 = 1 << (AXIS_BITS - 1);
const AXIS_MASK: u64 = (1 << AXIS_BITS) - 1;
/// Bits of the count.
pub const COUNT_BITS: u32 = 10;
/// The largest count a voxel can hold (counts saturate here).
pub const MAX_COUNT: u16 = (1 << COUNT_BITS) - 1;
const COUNT_MASK: u64 = MAX_COUNT as u64;
/// Smallest representable key index on each axis.
pub const KEY_MIN: i32 = -(OFFSET as i32);
/// Largest representable key index on each axis.
pub const KEY_MAX: i32 = (OFFSET - 1) as i32;

/// A key packed into the low 54 bits of a `u64`.
pub type PackedKey = u64;

/// Packs a key, or `None` when an index is outside `KEY_MIN..=KEY_MAX`.
#[inline]
pub fn pack_key(k: VoxelKey) -> Option<PackedKey> {
    let f = |v: i32| {
        let s = v as i64 + OFFSET;
        (0..=AXIS_MASK as i64).contains(&s).then_some(s as u64)
    };
    Some((f(k.x)? << (2 * AXIS_BITS)) | (f(k.y)? << AXIS_BITS) | f(k.z)?)
}

/// Unpacks a key.
#[inline]
pub fn unpack_key(p: PackedKey) -> VoxelKey {
    let f = |s: u64| ((s & AXIS_MASK) as i64 - OFFSET) as i32;
    VoxelKey::new(f(p >> (2 * AXIS_BITS)), f(p >> AXIS_BITS), f(p))
}

/// A table entry from a packed key and a count in `1..=MAX_COUNT`.
#[inline]
pub fn entry(key: PackedKey, count: u16) -> u64 {
    debug_assert!((1..=MAX_COUNT).contains(&count));
    (key << COUNT_BITS) | count as u64
}

/// The packed key of an entry.
#[inline]
pub fn entry_key(e: u64) -> PackedKey {
    e >> COUNT_BITS
}

/// The count of an entry.
#[inline]
pub fn entry_count(e: u64) -> u16 {
    (e & COUNT_MASK) as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_round_trip_and_range() {
        for k in [
            VoxelKey::new(0, 0, 0),
            VoxelKey::new(-1, 2, -3),
            VoxelKey::new(KEY_MIN, KEY_MAX, KEY_MIN),
            VoxelKey::new(KEY_MAX, KEY_MIN, KEY_MAX),
        ] {
            let p = pack_key(k).unwrap();
            assert_eq!(unpack_key(p), k);
            let e = entry(p, 7);
            assert_ne!(e, 0);
            assert_eq!((entry_key(e), entry_count(e)), (p, 7));
        }
        assert!(pack_key(VoxelKey::new(KEY_MAX + 1, 0, 0)).is_none());
        assert!(pack_key(VoxelKey::new(0, KEY_MIN - 1, 0)).is_none());
        assert!(pack_key(VoxelKey::new(0, 0, i32::MIN)).is_none());
    }

    #[test]
    fn packed_order_is_x_then_y_then_z() {
        let a = pack_key(VoxelKey::new(-1, 5, 5)).unwrap();
        let b = pack_key(VoxelKey::new(0, -5, -5)).unwrap();
        let c = pack_key(VoxelKey::new(0, -5, -4)).unwrap();
        assert!(a < b && b < c);
    }
}
