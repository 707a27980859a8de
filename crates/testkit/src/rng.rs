//! [`Rng`]: SplitMix64, the seeded generator of every test and benchmark.
//!
//! Written here rather than taken from `rand`: test data must stay the same bit for bit across
//! dependency updates (a failing case is reproduced by its seed, and benchmark inputs must not
//! change under a `cargo update`), and `rand` does not promise a stable stream for `StdRng`
//! across versions. SplitMix64 (Steele, Lea and Flood, "Fast splittable pseudorandom number
//! generators", OOPSLA 2014) passes BigCrush, is a dozen lines, and is what Java's
//! `SplittableRandom` uses.

use glam::DVec3;

/// A deterministic pseudo-random generator (SplitMix64). The same seed gives the same stream
/// on every platform and forever.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rng(u64);

impl Rng {
    /// A generator seeded with `seed` (any value, including 0).
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`, with 53 random bits.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform integer in `0..n` (`n > 0`; returns 0 for `n == 0`). Multiply-shift, so the
    /// bias is below `n / 2⁶⁴`.
    pub fn index(&mut self, n: usize) -> usize {
        ((u128::from(self.next_u64()) * n as u128) >> 64) as usize
    }

    /// `true` with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }

    /// A point uniform in the box `[lo, hi)` (per component).
    pub fn point_in(&mut self, lo: DVec3, hi: DVec3) -> DVec3 {
        DVec3::new(
            self.range(lo.x, hi.x),
            self.range(lo.y, hi.y),
            self.range(lo.z, hi.z),
        )
    }

    /// A point uniform in the cube `[-half, half)³`.
    pub fn point(&mut self, half: f64) -> DVec3 {
        self.point_in(DVec3::splat(-half), DVec3::splat(half))
    }

    /// A unit vector uniform on the sphere (rejection sampling in the unit ball).
    pub fn direction(&mut self) -> DVec3 {
        loop {
            let v = self.point(1.0);
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }

    /// Approximately normal with mean 0 and standard deviation 1 (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.unit(); // (0, 1]
        let u2 = self.unit();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_stream_of_seed_zero() {
        // The published SplitMix64 outputs for seed 0 (e.g. the reference C implementation by
        // Vigna): a changed constant or shift shows here.
        let mut r = Rng::new(0);
        assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        assert_eq!(r.next_u64(), 0x06C4_5D18_8009_454F);
    }

    #[test]
    fn unit_and_index_stay_in_range_and_spread() {
        let mut r = Rng::new(7);
        let mut buckets = [0usize; 10];
        for _ in 0..10_000 {
            let u = r.unit();
            assert!((0.0..1.0).contains(&u));
            buckets[r.index(10)] += 1;
        }
        // Each bucket expects 1000; 5 sigma is about 150.
        assert!(
            buckets.iter().all(|&b| (850..1150).contains(&b)),
            "{buckets:?}"
        );
        assert_eq!(r.index(0), 0);
    }

    #[test]
    fn directions_are_unit_and_normals_have_unit_variance() {
        let mut r = Rng::new(3);
        for _ in 0..100 {
            assert!((r.direction().length() - 1.0).abs() < 1e-12);
        }
        let n = 20_000;
        let xs: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(
            mean.abs() < 0.03 && (var - 1.0).abs() < 0.05,
            "{mean} {var}"
        );
    }
}
