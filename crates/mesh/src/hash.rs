//! A small, fast hasher for integer and exact-position keys (merging vertices, mesh edges,
//! grid cells).
//!
//! Keys are bit patterns of coordinates or indices, which are not attacker-chosen hash-flooding vectors
//! in a way that matters here (a hostile file can at worst make one read slower), so the
//! default SipHash is replaced by a multiply–xorshift mix that is several times faster.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hash, Hasher};

use glam::DVec3;

/// `HashMap` with [`MixHasher`], for keys that are indices or coordinate bit patterns.
pub type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<MixHasher>>;

/// Hasher folding 64-bit words with a strong finaliser (MurmurHash3's `fmix64`), so keys
/// that differ only in high bits (typical of floating-point patterns) still spread over the
/// low bits hash tables index with.
#[derive(Debug, Default, Clone, Copy)]
pub struct MixHasher(u64);

#[inline]
fn fmix64(mut k: u64) -> u64 {
    k ^= k >> 33;
    k = k.wrapping_mul(0xff51_afd7_ed55_8ccd);
    k ^= k >> 33;
    k = k.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    k ^= k >> 33;
    k
}

impl Hasher for MixHasher {
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut w = [0u8; 8];
            w[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(w));
        }
    }
    #[inline]
    fn write_u64(&mut self, x: u64) {
        self.0 = fmix64(self.0.rotate_left(23) ^ x);
    }
    #[inline]
    fn write_u32(&mut self, x: u32) {
        self.write_u64(u64::from(x));
    }
    #[inline]
    fn write_i64(&mut self, x: i64) {
        self.write_u64(x as u64);
    }
    #[inline]
    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }
}

/// Exact identity of a position: the bit patterns of its coordinates, with `-0.0` folded
/// onto `0.0` so that numerically equal zeros merge.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) struct BitKey([u64; 3]);

impl BitKey {
    #[inline]
    pub(crate) fn new(p: DVec3) -> Self {
        #[inline]
        fn bits(x: f64) -> u64 {
            if x == 0.0 { 0 } else { x.to_bits() }
        }
        Self([bits(p.x), bits(p.y), bits(p.z)])
    }
}

impl Hash for BitKey {
    #[inline]
    fn hash<H: Hasher>(&self, state: &mut H) {
        state.write_u64(self.0[0]);
        state.write_u64(self.0[1]);
        state.write_u64(self.0[2]);
    }
}
