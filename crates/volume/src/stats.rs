//! Summary statistics and quantiles of a volume.
//!
//! * [`Statistics::of`] / [`Statistics::of_any`] — voxel counts by class (finite, NaN, ±∞),
//!   and min, max, sum, mean and population standard deviation **over the finite values**.
//!   Computed in parallel over contiguous blocks of voxels: each block is summed with
//!   Neumaier's compensated summation, its variance is taken by the corrected two-pass
//!   formula around the block mean, and the blocks are merged in memory order with Chan's
//!   pairwise update — so the result is deterministic (independent of thread scheduling) and a
//!   256³ volume of values near 10⁷ keeps its standard deviation to ~10⁻¹⁰ relative. A block
//!   holding a value above 2⁴⁴⁸ (whose square could overflow) takes its mean and variance of
//!   the values scaled by 2⁻⁶⁰⁰, exactly, so every finite input gives a finite mean and
//!   standard deviation; other blocks are computed unscaled, bit for bit as without it.
//! * [`quantiles`] / [`quantiles_any`] — quantiles of the finite values by linear
//!   interpolation between order statistics (the "type 7" definition, NumPy's and R's
//!   default), computed **exactly** for every voxel type: order statistics are found by radix
//!   selection (parallel histograms of 8- or 16-bit digits of an order-preserving key), which
//!   never copies or sorts the volume.

use std::fmt;

use rayon::prelude::*;

use crate::{AnyVolume, Volume, VolumeError, Voxel, VoxelType};

/// Voxels per parallel block.
const BLOCK: usize = 1 << 16;

/// Largest finite magnitude of a block whose variance is taken unscaled: 2⁴⁴⁸. The sum of
/// `n` squared deviations, each at most `(2·max)²`, stays below `f64::MAX` (2¹⁰²⁴) for every
/// count `n < 2⁶⁴` only if `max < 2⁴⁷⁹`; 2⁴⁴⁸ leaves room for rounding. Ordinary data stay
/// below it and get the unscaled arithmetic, bit for bit.
const SCALE_ABOVE: f64 = pow2(448);

/// The exponent by which a block above [`SCALE_ABOVE`] is scaled down: its values are
/// multiplied by 2⁻⁶⁰⁰ (exactly: a power of two), which takes every finite value below
/// 2⁴²⁴ (< 2⁴⁷⁹, as above) and the block's largest one above 2⁻¹⁵², far from underflow.
const SCALE_EXP: i32 = 600;

/// `2^e` for `-1022 ≤ e ≤ 1023` (a normal number), built from its bits so that it is exact.
const fn pow2(e: i32) -> f64 {
    f64::from_bits(((e + 1023) as u64) << 52)
}

/// Summary statistics of a volume's values.
///
/// `min`, `max`, `sum`, `mean` and `std` are computed over the finite values only; when there
/// is none, `min`, `max`, `mean` and `std` are NaN and `sum` is 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Statistics {
    /// Number of voxels.
    pub count: usize,
    /// Number of finite values (every voxel of an integer volume).
    pub finite: usize,
    /// Number of NaN values.
    pub nan: usize,
    /// Number of `+∞` values.
    pub pos_inf: usize,
    /// Number of `−∞` values.
    pub neg_inf: usize,
    /// Smallest finite value.
    pub min: f64,
    /// Largest finite value.
    pub max: f64,
    /// Sum of the finite values (compensated).
    pub sum: f64,
    /// Mean of the finite values.
    pub mean: f64,
    /// Population standard deviation of the finite values, `√(Σ(x − mean)² / finite)`.
    pub std: f64,
}

/// Partial statistics of a run of voxels, mergeable in order.
#[derive(Debug, Clone, Copy)]
struct Partial {
    n: usize,
    nan: usize,
    pos_inf: usize,
    neg_inf: usize,
    min: f64,
    max: f64,
    /// Neumaier sum: `sum + comp` is the compensated total.
    sum: f64,
    comp: f64,
    /// The mean, in units of `2^exp`.
    mean: f64,
    /// Σ(x − mean)², in units of `2^(2·exp)`.
    m2: f64,
    /// 0, or [`SCALE_EXP`] for values too large to square ([`SCALE_ABOVE`]).
    exp: i32,
}

impl Partial {
    const EMPTY: Self = Self {
        n: 0,
        nan: 0,
        pos_inf: 0,
        neg_inf: 0,
        min: f64::INFINITY,
        max: f64::NEG_INFINITY,
        sum: 0.0,
        comp: 0.0,
        mean: 0.0,
        m2: 0.0,
        exp: 0,
    };

    /// Statistics of one block: compensated sum, then the corrected two-pass variance (of the
    /// values scaled by `2^-SCALE_EXP` if any exceeds [`SCALE_ABOVE`]).
    fn of_block<T: Voxel>(block: &[T]) -> Self {
        let mut p = Self::EMPTY;
        for &v in block {
            let x = v.to_f64();
            if x.is_finite() {
                p.n += 1;
                p.min = p.min.min(x);
                p.max = p.max.max(x);
                neumaier_add(&mut p.sum, &mut p.comp, x);
            } else if x.is_nan() {
                p.nan += 1;
            } else if x > 0.0 {
                p.pos_inf += 1;
            } else {
                p.neg_inf += 1;
            }
        }
        if p.n == 0 {
            return p;
        }
        let n = p.n as f64;
        let big = p.min.abs().max(p.max.abs()) > SCALE_ABOVE;
        p.exp = if big { SCALE_EXP } else { 0 };
        // Multiplying by 1 changes nothing: ordinary blocks get the unscaled arithmetic.
        let k = pow2(-p.exp);
        let m0 = if big {
            let (mut sum, mut comp) = (0.0, 0.0);
            for &v in block {
                let x = v.to_f64();
                if x.is_finite() {
                    neumaier_add(&mut sum, &mut comp, x * k);
                }
            }
            (sum + comp) / n
        } else {
            (p.sum + p.comp) / n
        };
        let (mut d1, mut d2) = (0.0, 0.0);
        for &v in block {
            let x = v.to_f64();
            if x.is_finite() {
                let d = x * k - m0;
                d1 += d;
                d2 += d * d;
            }
        }
        p.mean = m0 + d1 / n;
        p.m2 = (d2 - d1 * d1 / n).max(0.0);
        p
    }

    /// Express `mean` and `m2` in units of `2^exp` (`exp ≥ self.exp`): exact unless they
    /// fall below the normal range, where they are negligible beside values of that scale.
    fn rescale(&mut self, exp: i32) {
        if exp != self.exp {
            let f = pow2(self.exp - exp);
            self.mean *= f;
            self.m2 = self.m2 * f * f;
            self.exp = exp;
        }
    }

    /// Append `b` (the values after `self`'s in memory order).
    fn merge(mut self, b: &Self) -> Self {
        self.nan += b.nan;
        self.pos_inf += b.pos_inf;
        self.neg_inf += b.neg_inf;
        if b.n == 0 {
            return self;
        }
        if self.n == 0 {
            return Self {
                nan: self.nan,
                pos_inf: self.pos_inf,
                neg_inf: self.neg_inf,
                ..*b
            };
        }
        let mut b = *b;
        let exp = self.exp.max(b.exp);
        self.rescale(exp);
        b.rescale(exp);
        let (na, nb) = (self.n as f64, b.n as f64);
        let n = na + nb;
        let delta = b.mean - self.mean;
        self.mean += delta * (nb / n);
        self.m2 += b.m2 + delta * delta * (na * nb / n);
        self.n += b.n;
        self.min = self.min.min(b.min);
        self.max = self.max.max(b.max);
        neumaier_add(&mut self.sum, &mut self.comp, b.sum);
        self.comp += b.comp;
        self
    }
}

/// Neumaier's improved Kahan–Babuška step: add `x` to the running `sum` with compensation.
#[inline]
fn neumaier_add(sum: &mut f64, comp: &mut f64, x: f64) {
    let t = *sum + x;
    if sum.abs() >= x.abs() {
        *comp += (*sum - t) + x;
    } else {
        *comp += (x - t) + *sum;
    }
    *sum = t;
}

impl Statistics {
    /// Statistics of `volume` (see the type and module documentation for the method).
    #[must_use]
    pub fn of<T: Voxel>(volume: &Volume<T>) -> Self {
        let blocks: Vec<Partial> = volume
            .data()
            .par_chunks(BLOCK)
            .map(Partial::of_block)
            .collect();
        let p = blocks.iter().fold(Partial::EMPTY, |acc, b| acc.merge(b));
        let (min, max, mean, std) = if p.n == 0 {
            (f64::NAN, f64::NAN, f64::NAN, f64::NAN)
        } else {
            let unit = pow2(p.exp);
            (
                p.min,
                p.max,
                p.mean * unit,
                (p.m2 / p.n as f64).sqrt() * unit,
            )
        };
        Self {
            count: volume.len(),
            finite: p.n,
            nan: p.nan,
            pos_inf: p.pos_inf,
            neg_inf: p.neg_inf,
            min,
            max,
            sum: p.sum + p.comp,
            mean,
            std,
        }
    }

    /// Statistics of a volume whose voxel type is known at run time.
    #[must_use]
    pub fn of_any(volume: &AnyVolume) -> Self {
        crate::with_volume!(volume, v => Self::of(v))
    }
}

/// Format `x` with about six significant digits, in fixed or exponent notation.
fn fmt_short(x: f64, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    if !x.is_finite() || x == 0.0 {
        return write!(f, "{x}");
    }
    let mag = x.abs().log10().floor();
    if (-4.0..6.0).contains(&mag) {
        let decimals = (5.0 - mag).max(0.0) as usize;
        let s = format!("{x:.decimals$}");
        let s = if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.')
        } else {
            &s
        };
        f.write_str(s)
    } else {
        write!(f, "{x:.5e}")
    }
}

impl fmt::Display for Statistics {
    /// One line: `N voxels (F finite, …): min … max … mean … std … sum …`; the NaN and ±∞
    /// counts are shown only when non-zero.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} voxels ({} finite", self.count, self.finite)?;
        for (n, what) in [
            (self.nan, "NaN"),
            (self.pos_inf, "+inf"),
            (self.neg_inf, "-inf"),
        ] {
            if n > 0 {
                write!(f, ", {n} {what}")?;
            }
        }
        f.write_str("): min ")?;
        fmt_short(self.min, f)?;
        f.write_str(" max ")?;
        fmt_short(self.max, f)?;
        f.write_str(" mean ")?;
        fmt_short(self.mean, f)?;
        f.write_str(" std ")?;
        fmt_short(self.std, f)?;
        f.write_str(" sum ")?;
        fmt_short(self.sum, f)
    }
}

/// Width in bits of the order-preserving key of `T`.
fn key_bits<T: Voxel>() -> u32 {
    8 * T::TYPE.size() as u32
}

/// Order-preserving unsigned key of a finite value (`None` for NaN and ±∞): integers are
/// offset by the type's minimum; floats have their sign bit flipped (positive) or all bits
/// flipped (negative).
#[inline]
fn key<T: Voxel>(v: T) -> Option<u64> {
    let x = v.to_f64();
    match T::TYPE {
        VoxelType::F32 => x.is_finite().then(|| {
            let b = (x as f32).to_bits();
            u64::from(if b >> 31 == 1 { !b } else { b | 1 << 31 })
        }),
        VoxelType::F64 => x.is_finite().then(|| {
            let b = x.to_bits();
            if b >> 63 == 1 { !b } else { b | 1 << 63 }
        }),
        t => Some((x - t.range().0) as u64),
    }
}

/// The value whose key is `k` (inverse of [`key`]).
fn unkey<T: Voxel>(k: u64) -> f64 {
    match T::TYPE {
        VoxelType::F32 => {
            let b = k as u32;
            let b = if b >> 31 == 1 { b & !(1 << 31) } else { !b };
            f64::from(f32::from_bits(b))
        }
        VoxelType::F64 => {
            let b = if k >> 63 == 1 { k & !(1 << 63) } else { !k };
            f64::from_bits(b)
        }
        t => k as f64 + t.range().0,
    }
}

/// Histogram of digit `(key >> shift) & (bins − 1)` over the finite values whose key has
/// `prefix` in its bits above `prefix_shift` (all keys when `prefix_shift` ≥ 64), in parallel.
fn digit_histogram<T: Voxel>(
    data: &[T],
    prefix: u64,
    prefix_shift: u32,
    shift: u32,
    bins: usize,
) -> Vec<u64> {
    let mask = bins as u64 - 1;
    data.par_chunks(BLOCK)
        .fold(
            || vec![0u64; bins],
            |mut h, block| {
                for &v in block {
                    if let Some(k) = key(v)
                        && k.checked_shr(prefix_shift).unwrap_or(0) == prefix
                    {
                        h[((k >> shift) & mask) as usize] += 1;
                    }
                }
                h
            },
        )
        .reduce(
            || vec![0u64; bins],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(&b) {
                    *x += y;
                }
                a
            },
        )
}

/// The finite values of ranks `ranks` (0-based, ascending order; each < the finite count), by
/// radix selection on the keys, most significant digit first.
fn select_ranks<T: Voxel>(data: &[T], ranks: &[u64]) -> Vec<f64> {
    let bits = key_bits::<T>();
    // (prefix so far, rank within the values sharing that prefix)
    let mut state: Vec<(u64, u64)> = ranks.iter().map(|&r| (0, r)).collect();
    let mut known = 0u32;
    while known < bits {
        let d = (bits - known).min(16);
        let shift = bits - known - d;
        let bins = 1usize << d;
        let mut prefixes: Vec<u64> = state.iter().map(|s| s.0).collect();
        prefixes.sort_unstable();
        prefixes.dedup();
        for prefix in prefixes {
            let hist = digit_histogram(data, prefix, bits - known, shift, bins);
            for s in state.iter_mut().filter(|s| s.0 == prefix) {
                let mut below = 0u64;
                let mut digit = bins as u64 - 1;
                for (b, &h) in hist.iter().enumerate() {
                    if s.1 < below + h {
                        digit = b as u64;
                        break;
                    }
                    below += h;
                }
                *s = ((prefix << d) | digit, s.1.saturating_sub(below));
            }
        }
        known += d;
    }
    state.iter().map(|s| unkey::<T>(s.0)).collect()
}

/// Quantiles of the finite values of `volume` at probabilities `probs` (each in `[0, 1]`),
/// in the order given.
///
/// Definition ("type 7", NumPy's `quantile` default): with the `n` finite values sorted
/// ascending as `x₀ ≤ … ≤ x_{n−1}` and `h = (n − 1)·p`, the quantile is
/// `x_⌊h⌋ + (h − ⌊h⌋)·(x_⌊h⌋+1 − x_⌊h⌋)` (so `p = 0` is the minimum, `p = 1` the maximum).
/// The order statistics are exact for every voxel type (radix selection, see the module
/// documentation); only the final interpolation is rounded, in `f64`. NaN and ±∞ values are
/// ignored; with no finite value every quantile is NaN.
///
/// Cost: one parallel histogram pass over the volume per key digit and distinct candidate
/// prefix — one pass for 8- and 16-bit types, about `1 + 2·probs.len()` for 32-bit types and
/// `1 + 6·probs.len()` for `f64`; no copy of the data.
///
/// # Errors
/// [`VolumeError::InvalidArgument`] if a probability is NaN or outside `[0, 1]`.
pub fn quantiles<T: Voxel>(volume: &Volume<T>, probs: &[f64]) -> Result<Vec<f64>, VolumeError> {
    if let Some(p) = probs.iter().find(|p| !(0.0..=1.0).contains(*p)) {
        return Err(VolumeError::InvalidArgument(format!(
            "quantile probability {p} is not in [0, 1]"
        )));
    }
    if probs.is_empty() {
        return Ok(Vec::new());
    }
    let data = volume.data();
    let finite = data
        .par_chunks(BLOCK)
        .map(|b| b.iter().filter(|v| v.to_f64().is_finite()).count())
        .sum::<usize>() as u64;
    if finite == 0 {
        return Ok(vec![f64::NAN; probs.len()]);
    }
    let last = finite - 1;
    let positions: Vec<(u64, u64, f64)> = probs
        .iter()
        .map(|&p| {
            let h = last as f64 * p;
            let lo = (h.floor() as u64).min(last);
            (lo, (lo + 1).min(last), h - lo as f64)
        })
        .collect();
    let mut ranks: Vec<u64> = positions.iter().flat_map(|&(l, h, _)| [l, h]).collect();
    ranks.sort_unstable();
    ranks.dedup();
    let values = select_ranks(data, &ranks);
    let value_of = |r: u64| {
        ranks
            .binary_search(&r)
            .ok()
            .and_then(|i| values.get(i).copied())
            .unwrap_or(f64::NAN)
    };
    Ok(positions
        .iter()
        .map(|&(lo, hi, t)| {
            let a = value_of(lo);
            if t == 0.0 {
                a
            } else {
                a + t * (value_of(hi) - a)
            }
        })
        .collect())
}

/// [`quantiles`] of a volume whose voxel type is known at run time.
///
/// # Errors
/// As [`quantiles`].
pub fn quantiles_any(volume: &AnyVolume, probs: &[f64]) -> Result<Vec<f64>, VolumeError> {
    crate::with_volume!(volume, v => quantiles(v, probs))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_preserve_order_and_invert() {
        let f = [-3.5e30f32, -1.0, -0.0, 0.0, 1e-40, 2.5, f32::MAX];
        for w in f.windows(2) {
            assert!(key(w[0]).unwrap() <= key(w[1]).unwrap());
        }
        for &x in &f {
            assert_eq!(unkey::<f32>(key(x).unwrap()), f64::from(x));
        }
        let d = [f64::MIN, -1e-300, 0.0, 7.25, f64::MAX];
        for w in d.windows(2) {
            assert!(key(w[0]).unwrap() < key(w[1]).unwrap());
        }
        for &x in &d {
            assert_eq!(unkey::<f64>(key(x).unwrap()), x);
        }
        assert_eq!(key(f32::NAN), None);
        assert_eq!(key(f64::NEG_INFINITY), None);
        assert_eq!(key(i16::MIN), Some(0));
        assert_eq!(key(i16::MAX), Some(65_535));
        assert_eq!(unkey::<i32>(key(-17i32).unwrap()), -17.0);
        assert_eq!(key_bits::<u8>(), 8);
    }

    #[test]
    fn neumaier_recovers_cancelled_terms() {
        let (mut s, mut c) = (0.0, 0.0);
        for x in [1.0, 1e100, 1.0, -1e100] {
            neumaier_add(&mut s, &mut c, x);
        }
        assert_eq!(s + c, 2.0);
    }

    #[test]
    fn short_format() {
        struct S(f64);
        impl fmt::Display for S {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                fmt_short(self.0, f)
            }
        }
        assert_eq!(S(2.5).to_string(), "2.5");
        assert_eq!(S(0.1 + 0.2).to_string(), "0.3");
        assert_eq!(S(-1234.5678).to_string(), "-1234.57");
        assert_eq!(S(1.5e7).to_string(), "1.50000e7");
        assert_eq!(S(0.0).to_string(), "0");
        assert_eq!(S(f64::NAN).to_string(), "NaN");
    }
}
