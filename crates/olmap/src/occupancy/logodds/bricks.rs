//! Brick storage of a log-odds map: 4 x 4 x 4 voxels of `f32` log-odds (256 bytes) per
//! brick, bricks found through a hash table keyed by the brick's packed coordinates.
//!
//! Free space is dense (every voxel a ray crosses), so whole bricks fill up and a voxel
//! costs a little over 4 bytes there; near surfaces bricks are partly unknown. A voxel is
//! never forgotten once observed, so bricks are only ever added.
//!
//! Keys are limited to OctoMap's 16-bit range (-32,768..=32,767 per axis), so that every
//! map can be written as a `.bt` tree.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use super::model::UNKNOWN;
use crate::geometry::VoxelKey;
use crate::occupancy::packed::{pack_key, unpack_key, AXIS_BITS};

/// Voxels per brick edge, as a power of two.
const EDGE_BITS: u32 = 2;
const EDGE_MASK: i32 = (1 << EDGE_BITS) - 1;
/// Voxels per brick.
pub(super) const BRICK_VOXELS: usize = 1 << (3 * EDGE_BITS);

/// One brick: the log-odds of its voxels ([`UNKNOWN`] for unobserved ones), indexed by
/// [`local_index`].
pub(super) type Brick = [f32; BRICK_VOXELS];

/// A brick's identity: the packed key of its lowest voxel (a multiple of 4 on each axis).
pub(super) type BrickId = u64;

/// The smallest key index per axis (OctoMap's).
pub(super) const MAP_KEY_MIN: i32 = -(1 << 15);
/// The largest key index per axis (OctoMap's).
pub(super) const MAP_KEY_MAX: i32 = (1 << 15) - 1;

/// The brick and the bit (index within the brick) of a voxel key, or `None` outside
/// OctoMap's key range ([`MAP_KEY_MIN`]..=[`MAP_KEY_MAX`] per axis).
#[inline]
pub(super) fn split(k: VoxelKey) -> Option<(BrickId, usize)> {
    let inside = |v: i32| (MAP_KEY_MIN..=MAP_KEY_MAX).contains(&v);
    if !(inside(k.x) && inside(k.y) && inside(k.z)) {
        return None;
    }
    let corner = VoxelKey::new(k.x & !EDGE_MASK, k.y & !EDGE_MASK, k.z & !EDGE_MASK);
    let id = pack_key(corner)?;
    Some((id, local_index(k)))
}

/// The index of a voxel within its brick: x in the lowest bits, then y, then z.
#[inline]
pub(super) fn local_index(k: VoxelKey) -> usize {
    ((k.x & EDGE_MASK) | (k.y & EDGE_MASK) << EDGE_BITS | (k.z & EDGE_MASK) << (2 * EDGE_BITS))
        as usize
}

/// The voxel key of index `i` of a brick.
#[inline]
pub(super) fn join(id: BrickId, i: usize) -> VoxelKey {
    let c = unpack_key(id);
    let i = i as i32;
    VoxelKey::new(
        c.x + (i & EDGE_MASK),
        c.y + (i >> EDGE_BITS & EDGE_MASK),
        c.z + (i >> (2 * EDGE_BITS) & EDGE_MASK),
    )
}

// The packed layout must leave the low bits of every axis for the brick index.
const _: () = assert!(AXIS_BITS > EDGE_BITS);

/// MurmurHash3's 64-bit finaliser: packed keys differ mostly in a few bits, which a plain
/// multiplicative hash would leave in the high half.
#[derive(Default, Clone, Copy)]
pub(super) struct MixHasher(u64);

impl Hasher for MixHasher {
    #[inline]
    fn finish(&self) -> u64 {
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = self.0.rotate_left(8) ^ u64::from(b);
        }
    }
    #[inline]
    fn write_u64(&mut self, v: u64) {
        self.0 = v;
    }
}

/// A hash map keyed by packed keys.
pub(super) type IdMap<V> = HashMap<BrickId, V, BuildHasherDefault<MixHasher>>;

/// The bricks of a map.
#[derive(Clone, Default)]
pub(super) struct Bricks {
    index: IdMap<u32>,
    data: Vec<Brick>,
}

impl Bricks {
    /// Number of bricks.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// The brick `id`, if any voxel of it was observed.
    #[inline]
    pub fn get(&self, id: BrickId) -> Option<&Brick> {
        self.index.get(&id).map(|&i| &self.data[i as usize])
    }

    /// The brick `id`, created all unknown if needed.
    #[inline]
    pub fn get_or_insert(&mut self, id: BrickId) -> &mut Brick {
        let next = self.data.len() as u32;
        let i = *self.index.entry(id).or_insert(next);
        if i == next {
            self.data.push([UNKNOWN; BRICK_VOXELS]);
        }
        &mut self.data[i as usize]
    }

    /// Every brick with its id, in no particular order.
    pub fn iter(&self) -> impl Iterator<Item = (BrickId, &Brick)> + '_ {
        self.index
            .iter()
            .map(|(&id, &i)| (id, &self.data[i as usize]))
    }

    /// Bytes held: the bricks and the index (its slots and control bytes).
    pub fn memory_bytes(&self) -> usize {
        self.data.capacity() * std::mem::size_of::<Brick>()
            + self.index.capacity() * (std::mem::size_of::<(BrickId, u32)>() + 1)
    }

    /// Gives back spare capacity.
    pub fn shrink_to_fit(&mut self) {
        self.data.shrink_to_fit();
        self.index.shrink_to_fit();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_and_join_are_inverse_across_signs() {
        for k in [
            VoxelKey::new(0, 0, 0),
            VoxelKey::new(-1, -4, -5),
            VoxelKey::new(7, -130, 32_767),
            VoxelKey::new(-32_768, 3, 2),
        ] {
            let (id, i) = split(k).unwrap();
            assert!(i < BRICK_VOXELS);
            assert_eq!(join(id, i), k);
        }
        // Neighbours across a brick face are in different bricks; within, in the same.
        assert_ne!(
            split(VoxelKey::new(-1, 0, 0)).unwrap().0,
            split(VoxelKey::new(0, 0, 0)).unwrap().0
        );
        assert_eq!(
            split(VoxelKey::new(1, 2, 3)).unwrap().0,
            split(VoxelKey::new(0, 0, 0)).unwrap().0
        );
        assert!(split(VoxelKey::new(32_768, 0, 0)).is_none());
        assert!(split(VoxelKey::new(0, -32_769, 0)).is_none());
    }
}
