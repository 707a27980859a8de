//! Similarity of two images on one grid: normalised cross-correlation, mean squared
//! difference and (Mattes) mutual information.
//!
//! [`JointHistogram`] is the Parzen-window joint histogram of Mattes et al. (2003), as ITK's
//! `MattesMutualInformationImageToImageMetric` and elastix build it: the fixed intensity
//! falls into one bin (zero-order B-spline), the moving intensity is spread over four bins by
//! a cubic B-spline, so the mutual information is a smooth function of the moving values and
//! has the derivative used by the dense registration
//! ([`JointHistogram::derivative`]):
//!
//! ```text
//! ∂MI/∂m_x = −1/(N Δm) Σ_κ β₃'(κ − m̂_x) log(p(ι_x, κ) / p_M(κ))
//! ```
//!
//! (the fixed marginal does not depend on the moving values and the histogram sums to one).

use serde::Serialize;
use volmorph_volume::Volume;

use crate::RegisterError;
use crate::image::same_grid;

/// Histogram bins of the mutual information by default (elastix's and ITK's default is 32).
pub const DEFAULT_BINS: usize = 32;

/// Bins of padding on each side of the moving axis, for the support of the cubic kernel.
const PAD: usize = 2;

/// Cubic B-spline `β₃(t)`.
#[inline]
#[must_use]
pub fn cubic_bspline(t: f64) -> f64 {
    let a = t.abs();
    if a < 1.0 {
        2.0 / 3.0 - a * a + 0.5 * a * a * a
    } else if a < 2.0 {
        let b = 2.0 - a;
        b * b * b / 6.0
    } else {
        0.0
    }
}

/// Derivative `β₃'(t)`.
#[inline]
#[must_use]
pub fn cubic_bspline_derivative(t: f64) -> f64 {
    let a = t.abs();
    let s = t.signum();
    if a < 1.0 {
        s * (-2.0 * a + 1.5 * a * a)
    } else if a < 2.0 {
        let b = 2.0 - a;
        -s * 0.5 * b * b
    } else {
        0.0
    }
}

/// Parzen-window joint histogram of fixed and moving intensities (see the
/// [module docs](self)).
#[derive(Debug, Clone)]
pub struct JointHistogram {
    bins: usize,
    f_lo: f64,
    f_step: f64,
    m_lo: f64,
    m_step: f64,
    /// `counts[ι · width + κ]`, moving axis padded by [`PAD`] bins on each side.
    counts: Vec<f64>,
    total: f64,
}

impl JointHistogram {
    /// An empty histogram of `bins` bins over the fixed range `[f_lo, f_hi]` and the moving
    /// range `[m_lo, m_hi]` (values beyond are clamped to the range).
    ///
    /// # Errors
    /// [`RegisterError::Option`] for fewer than 4 bins or an empty or non-finite range.
    pub fn new(bins: usize, fixed: (f64, f64), moving: (f64, f64)) -> Result<Self, RegisterError> {
        if !(4..=1024).contains(&bins) {
            return Err(RegisterError::option("bins", "must be 4…1024"));
        }
        for (what, (lo, hi)) in [("fixed range", fixed), ("moving range", moving)] {
            if !(lo.is_finite() && hi.is_finite() && hi > lo) {
                return Err(RegisterError::option(
                    "histogram",
                    format!("{what} [{lo}, {hi}] is empty or not finite"),
                ));
            }
        }
        let width = bins + 2 * PAD;
        Ok(Self {
            bins,
            f_lo: fixed.0,
            f_step: (fixed.1 - fixed.0) / bins as f64,
            m_lo: moving.0,
            m_step: (moving.1 - moving.0) / (bins - 1) as f64,
            counts: vec![0.0; bins * width],
            total: 0.0,
        })
    }

    /// A histogram with the same bins and no counts.
    #[must_use]
    pub fn empty_like(&self) -> Self {
        let mut h = self.clone();
        h.counts.fill(0.0);
        h.total = 0.0;
        h
    }

    fn width(&self) -> usize {
        self.bins + 2 * PAD
    }

    #[inline]
    fn fixed_bin(&self, f: f64) -> usize {
        (((f - self.f_lo) / self.f_step).floor().max(0.0) as usize).min(self.bins - 1)
    }

    /// Continuous moving bin coordinate (padded axis).
    #[inline]
    fn moving_coord(&self, m: f64) -> f64 {
        ((m - self.m_lo) / self.m_step).clamp(0.0, (self.bins - 1) as f64) + PAD as f64
    }

    /// Add one sample pair.
    #[inline]
    pub fn add(&mut self, f: f64, m: f64) {
        let i = self.fixed_bin(f);
        let c = self.moving_coord(m);
        let k0 = c.floor() as usize - 1;
        let w = self.width();
        let row = &mut self.counts[i * w..(i + 1) * w];
        for (k, v) in row.iter_mut().enumerate().skip(k0).take(4) {
            *v += cubic_bspline(k as f64 - c);
        }
        self.total += 1.0;
    }

    /// Add the counts of another histogram with the same bins.
    pub fn merge(&mut self, other: &Self) {
        for (a, b) in self.counts.iter_mut().zip(&other.counts) {
            *a += *b;
        }
        self.total += other.total;
    }

    /// Number of samples.
    #[must_use]
    pub fn count(&self) -> f64 {
        self.total
    }

    /// Moving marginal `p_M(κ)` (padded axis).
    fn moving_marginal(&self) -> Vec<f64> {
        let w = self.width();
        let mut pm = vec![0.0; w];
        for row in self.counts.chunks_exact(w) {
            for (a, b) in pm.iter_mut().zip(row) {
                *a += *b;
            }
        }
        pm
    }

    /// Mutual information `Σ p log(p / (p_F p_M))` in nats (0 for an empty histogram).
    #[must_use]
    pub fn mutual_information(&self) -> f64 {
        if self.total <= 0.0 {
            return 0.0;
        }
        let w = self.width();
        let pm = self.moving_marginal();
        let mut mi = 0.0;
        for row in self.counts.chunks_exact(w) {
            let pf: f64 = row.iter().sum();
            if pf <= 0.0 {
                continue;
            }
            for (&c, &m) in row.iter().zip(&pm) {
                if c > 0.0 {
                    mi += c * (c * self.total / (pf * m)).ln();
                }
            }
        }
        mi / self.total
    }

    /// Table of `log(p(ι, κ) / p_M(κ))` for [`JointHistogram::derivative`].
    #[must_use]
    pub fn log_ratio_table(&self) -> Vec<f64> {
        let w = self.width();
        let pm = self.moving_marginal();
        let mut t = vec![0.0; self.counts.len()];
        for (row_t, row) in t.chunks_exact_mut(w).zip(self.counts.chunks_exact(w)) {
            for ((o, &c), &m) in row_t.iter_mut().zip(row).zip(&pm) {
                *o = if c > 0.0 && m > 0.0 {
                    (c / m).ln()
                } else {
                    0.0
                };
            }
        }
        t
    }

    /// `∂MI/∂m` for one sample pair `(f, m)` given [`JointHistogram::log_ratio_table`]
    /// (see the [module docs](self)).
    #[inline]
    #[must_use]
    pub fn derivative(&self, table: &[f64], f: f64, m: f64) -> f64 {
        let i = self.fixed_bin(f);
        let c = self.moving_coord(m);
        let k0 = c.floor() as usize - 1;
        let w = self.width();
        let row = &table[i * w..(i + 1) * w];
        let mut s = 0.0;
        for (k, v) in row.iter().enumerate().skip(k0).take(4) {
            s += cubic_bspline_derivative(k as f64 - c) * v;
        }
        -s / (self.total * self.m_step)
    }
}

/// Similarity of two images (see [`compare`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ImageMetrics {
    /// Voxels compared.
    pub count: usize,
    /// Normalised cross-correlation (−1…1).
    pub ncc: f64,
    /// Mean squared difference (image units²).
    pub msd: f64,
    /// Mattes mutual information with [`DEFAULT_BINS`] bins, in nats.
    pub mi: f64,
}

impl std::fmt::Display for ImageMetrics {
    /// `NCC …, MSD …, MI …`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "NCC {:.4}, MSD {:.2}, MI {:.4}",
            self.ncc, self.msd, self.mi
        )
    }
}

/// `(min, max)` of the finite values of `v` where `mask` allows.
#[must_use]
pub fn value_range(v: &[f32], mask: Option<&[u8]>) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for (n, &x) in v.iter().enumerate() {
        if mask.is_some_and(|m| m[n] == 0) || !x.is_finite() {
            continue;
        }
        lo = lo.min(f64::from(x));
        hi = hi.max(f64::from(x));
    }
    (lo, hi)
}

/// NCC, mean squared difference and mutual information of `a` and `b` on the same grid,
/// over the voxels where `mask` (same grid, non-zero) allows and both values are finite.
///
/// # Errors
/// [`RegisterError::Mismatch`] for different grids, [`RegisterError::TooLittle`] for fewer
/// than two voxels to compare.
pub fn compare(
    a: &Volume<f32>,
    b: &Volume<f32>,
    mask: Option<&Volume<u8>>,
) -> Result<ImageMetrics, RegisterError> {
    same_grid(a.geometry(), b.geometry(), "images compared")?;
    if let Some(m) = mask {
        same_grid(a.geometry(), m.geometry(), "mask")?;
    }
    let md = mask.map(Volume::data);
    let ok = |n: usize| md.is_none_or(|m| m[n] != 0);
    let (mut n, mut sa, mut sb, mut saa, mut sbb, mut sab, mut sd) =
        (0usize, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, (&x, &y)) in a.data().iter().zip(b.data()).enumerate() {
        if !ok(i) || !x.is_finite() || !y.is_finite() {
            continue;
        }
        let (x, y) = (f64::from(x), f64::from(y));
        n += 1;
        sa += x;
        sb += y;
        saa += x * x;
        sbb += y * y;
        sab += x * y;
        sd += (x - y) * (x - y);
    }
    if n < 2 {
        return Err(RegisterError::TooLittle(format!("{n} voxels to compare")));
    }
    let nf = n as f64;
    let va = saa - sa * sa / nf;
    let vb = sbb - sb * sb / nf;
    let ncc = if va > 0.0 && vb > 0.0 {
        (sab - sa * sb / nf) / (va * vb).sqrt()
    } else {
        0.0
    };
    let fr = value_range(a.data(), md);
    let mr = value_range(b.data(), md);
    let widen = |(lo, hi): (f64, f64)| {
        if hi > lo {
            (lo, hi)
        } else {
            (lo - 0.5, lo + 0.5)
        }
    };
    let mut h = JointHistogram::new(DEFAULT_BINS, widen(fr), widen(mr))?;
    for (i, (&x, &y)) in a.data().iter().zip(b.data()).enumerate() {
        if ok(i) && x.is_finite() && y.is_finite() {
            h.add(f64::from(x), f64::from(y));
        }
    }
    Ok(ImageMetrics {
        count: n,
        ncc,
        msd: sd / nf,
        mi: h.mutual_information(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bspline_kernel_is_a_partition_of_unity_with_matching_derivative() {
        for t in [0.0, 0.3, 0.77, 1.5] {
            let s: f64 = (-3..=3).map(|k| cubic_bspline(k as f64 - t)).sum();
            assert!((s - 1.0).abs() < 1e-12);
            let h = 1e-6;
            let fd = (cubic_bspline(t + h) - cubic_bspline(t - h)) / (2.0 * h);
            assert!((fd - cubic_bspline_derivative(t)).abs() < 1e-6);
        }
    }

    /// The analytic derivative of the MI equals a finite difference of the MI.
    #[test]
    fn mi_derivative_matches_finite_difference() {
        let f: Vec<f64> = (0..400).map(|i| ((i * 37) % 101) as f64).collect();
        let m: Vec<f64> = f
            .iter()
            .enumerate()
            .map(|(i, &x)| 0.5 * x + ((i * 13) % 7) as f64)
            .collect();
        let build = |m: &[f64]| {
            let mut h = JointHistogram::new(16, (0.0, 100.0), (-5.0, 60.0)).unwrap();
            for (&x, &y) in f.iter().zip(m) {
                h.add(x, y);
            }
            h
        };
        let h = build(&m);
        let t = h.log_ratio_table();
        for idx in [3usize, 50, 222] {
            let d = h.derivative(&t, f[idx], m[idx]);
            let eps = 1e-4;
            let mut mp = m.clone();
            mp[idx] += eps;
            let mut mm = m.clone();
            mm[idx] -= eps;
            let fd =
                (build(&mp).mutual_information() - build(&mm).mutual_information()) / (2.0 * eps);
            assert!((d - fd).abs() < 1e-6 * (1.0 + fd.abs()), "{d} vs {fd}");
        }
        // Identical images have the largest MI of the three couplings here.
        let same = build(&f.iter().map(|x| x * 0.6 - 1.0).collect::<Vec<_>>());
        assert!(same.mutual_information() > h.mutual_information());
    }
}
