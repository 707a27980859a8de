//! Reproducible pseudo-random numbers for the phantoms: a counter-based generator, so that the
//! value for voxel `n` of stream `seed` does not depend on the order or the thread in which
//! voxels are filled (parallel generation gives the same volume bit for bit).
//!
//! Each number is SplitMix64's output function applied to `seed·φ + counter` (φ the 64-bit
//! golden ratio); this is the finaliser of Steele, Lea and Flood's generator (OOPSLA 2014) used
//! as a hash of the counter. Written here because the project's seeded generator is a
//! sequential stream for tests only, and a library needs a stateless one.

/// 64 random bits for `(seed, counter)`.
#[inline]
#[must_use]
pub fn bits(seed: u64, counter: u64) -> u64 {
    let mut z = seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(counter.wrapping_mul(0xD1B5_4A32_D192_ED03))
        .wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Uniform in `[0, 1)` (53 bits).
#[inline]
#[must_use]
pub fn uniform(seed: u64, counter: u64) -> f64 {
    (bits(seed, counter) >> 11) as f64 / (1u64 << 53) as f64
}

/// Standard normal (Box–Muller on two uniforms of counters `2n`, `2n + 1`).
#[inline]
#[must_use]
pub fn normal(seed: u64, n: u64) -> f64 {
    let u1 = uniform(seed, 2 * n).max(f64::MIN_POSITIVE);
    let u2 = uniform(seed, 2 * n + 1);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A sequential stream on top of the counter-based numbers.
#[derive(Debug, Clone)]
pub struct Stream {
    seed: u64,
    counter: u64,
}

impl Stream {
    /// Stream `seed` from counter 0.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self { seed, counter: 0 }
    }

    /// Next uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        self.counter += 1;
        lo + (hi - lo) * uniform(self.seed, self.counter)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moments_of_uniform_and_normal() {
        let n = 200_000u64;
        let mean_u = (0..n).map(|i| uniform(5, i)).sum::<f64>() / n as f64;
        assert!((mean_u - 0.5).abs() < 0.005);
        let v: Vec<f64> = (0..n).map(|i| normal(9, i)).collect();
        let m = v.iter().sum::<f64>() / n as f64;
        let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n as f64;
        assert!(m.abs() < 0.01 && (var - 1.0).abs() < 0.02, "{m} {var}");
        assert_ne!(bits(1, 0), bits(2, 0));
    }
}
