//! The hash table behind occupancy lists: open addressing over packed `u64` entries.
//!
//! Linear probing, backward-shift deletion (no tombstones), any capacity (the home slot is
//! the high half of `hash * capacity`), load kept between 0.53 and 0.8 by growing 1.5x.
//! At 8 bytes per slot that is 10 to 15 bytes per stored voxel, and a missing key costs a
//! few probes within one or two cache lines: the common case of the overlap inner loop.
//!
//! The hash is seeded by the capacity. Without that, copying one table into a smaller one
//! entry by entry (slot order = hash order) piles every key into one probe run and turns
//! the copy quadratic: 185,000 voxels took 7 s instead of milliseconds.

use super::packed::{entry, entry_count, entry_key, PackedKey};

const MAX_LOAD_NUM: usize = 4;
const MAX_LOAD_DEN: usize = 5;
const MIN_CAPACITY: usize = 16;

/// A set of packed entries keyed by their packed voxel key.
#[derive(Clone, Default)]
pub(crate) struct VoxelTable {
    slots: Vec<u64>,
    len: usize,
    seed: u64,
}

/// MurmurHash3's 64-bit finaliser of the key mixed with the table's seed.
#[inline]
fn hash(key: PackedKey, seed: u64) -> u64 {
    let mut h = key ^ seed;
    h ^= h >> 33;
    h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
    h ^= h >> 33;
    h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    h ^ (h >> 33)
}

fn seed_for(capacity: usize) -> u64 {
    (capacity as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

impl VoxelTable {
    /// An empty table with room for `n` entries without growing.
    pub fn with_capacity(n: usize) -> Self {
        let cap = (n * MAX_LOAD_DEN).div_ceil(MAX_LOAD_NUM).max(MIN_CAPACITY);
        VoxelTable {
            slots: vec![0; cap],
            len: 0,
            seed: seed_for(cap),
        }
    }

    /// Number of entries.
    #[inline]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Bytes held by the slots.
    pub fn memory_bytes(&self) -> usize {
        self.slots.capacity() * std::mem::size_of::<u64>()
    }

    #[inline]
    fn home(&self, key: PackedKey) -> usize {
        ((hash(key, self.seed) as u128 * self.slots.len() as u128) >> 64) as usize
    }

    /// The slot holding `key`, if any.
    #[inline]
    pub fn find(&self, key: PackedKey) -> Option<usize> {
        let n = self.slots.len();
        if n == 0 {
            return None;
        }
        let mut i = self.home(key);
        loop {
            let e = self.slots[i];
            if e == 0 {
                return None;
            }
            if entry_key(e) == key {
                return Some(i);
            }
            i += 1;
            if i == n {
                i = 0;
            }
        }
    }

    /// The count stored for `key` (0 when absent).
    #[inline]
    pub fn get(&self, key: PackedKey) -> u16 {
        self.find(key).map_or(0, |i| entry_count(self.slots[i]))
    }

    /// Whether `key` is stored.
    #[inline]
    pub fn contains(&self, key: PackedKey) -> bool {
        self.find(key).is_some()
    }

    fn grow(&mut self) {
        self.rehash((self.slots.len() * 3 / 2).max(MIN_CAPACITY));
    }

    fn rehash(&mut self, capacity: usize) {
        let old = std::mem::replace(&mut self.slots, vec![0; capacity]);
        self.seed = seed_for(capacity);
        self.len = 0;
        for e in old.into_iter().filter(|&e| e != 0) {
            self.insert_new(e);
        }
    }

    /// Inserts an entry whose key is known to be absent.
    fn insert_new(&mut self, e: u64) {
        let n = self.slots.len();
        let mut i = self.home(entry_key(e));
        while self.slots[i] != 0 {
            i += 1;
            if i == n {
                i = 0;
            }
        }
        self.slots[i] = e;
        self.len += 1;
    }

    /// Sets the count of `key`: `f(current)` with 0 for absent; a result of 0 removes it.
    /// `f` must return at most `MAX_COUNT`.
    #[inline]
    pub fn update(&mut self, key: PackedKey, f: impl FnOnce(u16) -> u16) {
        match self.find(key) {
            Some(i) => {
                let c = f(entry_count(self.slots[i]));
                if c == 0 {
                    self.remove_at(i);
                } else {
                    self.slots[i] = entry(key, c);
                }
            }
            None => {
                let c = f(0);
                if c != 0 {
                    if (self.len + 1) * MAX_LOAD_DEN > self.slots.len() * MAX_LOAD_NUM {
                        self.grow();
                    }
                    self.insert_new(entry(key, c));
                }
            }
        }
    }

    /// Removes the entry in slot `i`, shifting later entries of the probe run back.
    fn remove_at(&mut self, mut i: usize) {
        let n = self.slots.len();
        let mut j = i;
        loop {
            j += 1;
            if j == n {
                j = 0;
            }
            let e = self.slots[j];
            if e == 0 {
                break;
            }
            let k = self.home(entry_key(e));
            // The entry at j may stay when its home lies cyclically in (i, j].
            let stays = if i <= j {
                i < k && k <= j
            } else {
                i < k || k <= j
            };
            if !stays {
                self.slots[i] = e;
                i = j;
            }
        }
        self.slots[i] = 0;
        self.len -= 1;
    }

    /// The longest distance of an entry from its home slot (a health check of the hash).
    #[cfg(test)]
    pub fn max_displacement(&self) -> usize {
        let n = self.slots.len();
        self.slots
            .iter()
            .enumerate()
            .filter(|(_, e)| **e != 0)
            .map(|(i, e)| (i + n - self.home(entry_key(*e))) % n)
            .max()
            .unwrap_or(0)
    }

    /// Every entry, in slot order.
    pub fn entries(&self) -> impl Iterator<Item = u64> + '_ {
        self.slots.iter().copied().filter(|&e| e != 0)
    }

    /// Shrinks the slots to the smallest capacity that keeps the load at most 0.8.
    pub fn shrink_to_fit(&mut self) {
        let want = (self.len * MAX_LOAD_DEN)
            .div_ceil(MAX_LOAD_NUM)
            .max(MIN_CAPACITY);
        if want < self.slots.len() {
            self.rehash(want);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rustc_hash::FxHashMap;

    #[test]
    fn copying_in_slot_order_into_a_growing_table_stays_linear() {
        // Regression: with an unseeded hash, slot order of a big table is hash order, and
        // re-inserting it into a small growing table built one giant probe run.
        let mut big = VoxelTable::default();
        for k in 1..=200_000u64 {
            big.update(k * 7919, |_| 1);
        }
        let mut copy = VoxelTable::default();
        for (i, e) in big.entries().enumerate() {
            copy.update(entry_key(e), |_| entry_count(e));
            if i % 5000 == 0 {
                // Probe runs stay short all along, not only after the last rehash.
                assert!(
                    copy.max_displacement() < 200,
                    "{} at {i}",
                    copy.max_displacement()
                );
            }
        }
        assert_eq!(copy.len(), big.len());
    }

    #[test]
    fn matches_a_hash_map_under_random_updates() {
        let mut t = VoxelTable::default();
        let mut reference: FxHashMap<u64, u16> = FxHashMap::default();
        let mut s = 12345u64;
        for step in 0..200_000u32 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let key = s % 3000 + 1; // few keys: many collisions, removals and re-insertions
            let delta = (s >> 40) % 5;
            let add = step % 3 != 0;
            let f = |c: u16| {
                if add {
                    (c + delta as u16).min(1023)
                } else {
                    c.saturating_sub(delta as u16)
                }
            };
            t.update(key, f);
            let r = reference.entry(key).or_insert(0);
            *r = f(*r);
            if *r == 0 {
                reference.remove(&key);
            }
            assert_eq!(t.len(), reference.len());
        }
        for (k, c) in &reference {
            assert_eq!(t.get(*k), *c);
        }
        assert_eq!(t.entries().count(), reference.len());
        for k in 3001..4000 {
            assert!(!t.contains(k));
        }
        t.shrink_to_fit();
        for (k, c) in &reference {
            assert_eq!(t.get(*k), *c);
        }
        assert!(t.memory_bytes() <= 16 * t.len().max(16));
    }
}
