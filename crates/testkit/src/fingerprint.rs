//! Bit-for-bit fingerprints of kernel outputs, for the tests that pin a rewritten kernel to
//! the exact bits of the code it replaced.

/// FNV-1a (64-bit) over the little-endian bytes of a stream of 64-bit words: feed it the
/// `to_bits()` of every output value (widened to `u64`), indices, counts. Any change of a
/// value's bits or of their order changes the result (up to FNV's collisions).
#[must_use]
pub fn fnv1a(words: impl Iterator<Item = u64>) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for w in words {
        for b in w.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values_and_order_sensitivity() {
        // FNV-1a of the empty input is the offset basis; of the 8 bytes of 0u64, the
        // published 64-bit FNV-1a of eight zero bytes.
        assert_eq!(fnv1a(std::iter::empty()), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a([0u64].into_iter()), 0xa8c7_f832_281a_39c5);
        assert_ne!(fnv1a([1u64, 2].into_iter()), fnv1a([2u64, 1].into_iter()));
    }
}
