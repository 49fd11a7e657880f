//! A fast hash for the generator's own keys (node ids, symbols, pairs of
//! them): a multiply-rotate mix per word, the idea of rustc's `FxHasher`.
//! The keys come from the generator's graph, not from input text, so the
//! flooding resistance of std's `SipHash` buys nothing here, while the
//! generator hashes millions of small keys on long chains
//! (`schedule/share.rs`: the pairs of every product and sum).

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

/// `HashMap` with [`FastHasher`].
pub(crate) type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<FastHasher>>;

/// `HashSet` with [`FastHasher`].
pub(crate) type FastSet<K> = HashSet<K, BuildHasherDefault<FastHasher>>;

/// Odd constant with well-spread bits (2^64 / golden ratio).
const K: u64 = 0x9e37_79b9_7f4a_7c15;

/// Word-at-a-time multiplicative hasher.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct FastHasher {
    hash: u64,
}

impl FastHasher {
    #[inline]
    fn add(&mut self, word: u64) {
        self.hash = (self.hash.rotate_left(5) ^ word).wrapping_mul(K);
    }
}

impl Hasher for FastHasher {
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            self.add(u64::from_le_bytes(c.try_into().expect("eight bytes")));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut last = [0u8; 8];
            last[..rest.len()].copy_from_slice(rest);
            self.add(u64::from_le_bytes(last));
        }
    }

    #[inline]
    fn write_u8(&mut self, i: u8) {
        self.add(u64::from(i));
    }

    #[inline]
    fn write_u16(&mut self, i: u16) {
        self.add(u64::from(i));
    }

    #[inline]
    fn write_u32(&mut self, i: u32) {
        self.add(u64::from(i));
    }

    #[inline]
    fn write_u64(&mut self, i: u64) {
        self.add(i);
    }

    #[inline]
    fn write_usize(&mut self, i: usize) {
        self.add(i as u64);
    }

    /// The high bits choose hashbrown's groups: fold them into the low ones
    /// too, so that keys differing in few low bits spread over both.
    #[inline]
    fn finish(&self) -> u64 {
        self.hash ^ (self.hash >> 32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hash::{BuildHasher, Hash};

    fn hash<T: Hash>(x: T) -> u64 {
        BuildHasherDefault::<FastHasher>::default().hash_one(x)
    }

    /// Small integer keys, as node ids are, land in distinct buckets of a
    /// table of 2^16 and in distinct top-7-bit tags often enough.
    #[test]
    fn consecutive_keys_spread() {
        let n = 1u64 << 16;
        let buckets: FastSet<u64> = (0..n).map(|i| hash(i) & (n - 1)).collect();
        assert!(
            buckets.len() as f64 > 0.6 * n as f64,
            "{} buckets",
            buckets.len()
        );
        let tags: FastSet<u64> = (0..4096u64).map(|i| hash(i) >> 57).collect();
        assert_eq!(tags.len(), 128);
        assert_ne!(hash((1u32, 2u32)), hash((2u32, 1u32)));
    }
}
