//! Tensor-product interpolation at the Greville abscissae (Martin & Cohen §3), or at any sites
//! satisfying the Schoenberg–Whitney condition.
//!
//! Given data `c_{j_0 j_1 j_2}` sampled on the grid of sites (one site per basis function on
//! each axis), the control net `P` with `Σ P_i Π_a N_{i_a}(τ^a_{j_a}) = c_j` is found by
//! separable solves: the collocation matrix `A_a[j][i] = N_{i}(τ^a_j)` of each axis is factored
//! once and applied along every line of that axis (Martin & Cohen's equations (2)–(3) in any
//! order; the operator `A^{-1} ⊗^a` commutes across axes).
//!
//! # Why a banded LU without pivoting
//!
//! At sites `τ_0 ≤ … ≤ τ_{n−1}` the collocation matrix has at most `p + 1` non-zeros per row
//! inside a band (row `j` touches columns `span(τ_j) − p … span(τ_j)`), so a band factorisation
//! costs O(n·p²) once and O(n·p) per line, against O(n³) and O(n²) for a dense LU such as
//! `faer`'s — and a volume fit solves one line per grid row. The matrix is **totally positive**
//! (Karlin; de Boor 1976), and it is non-singular exactly when `N_j(τ_j) ≠ 0` for all `j`
//! (Schoenberg–Whitney), which Greville sites satisfy whenever multiplicities are ≤ p. For a
//! non-singular totally positive matrix, Gaussian elimination **without pivoting** is stable and
//! its pivots are positive (de Boor & Pinkus 1977), so pivoting would only cost band width.
//! This is the classical choice of de Boor's `SPLINT`. Sites violating Schoenberg–Whitney, or a
//! pivot that vanishes numerically, are reported as [`SplineError::SingularCollocation`].
//!
//! Interpolation needs every site inside the domain of its knot vector; the Greville abscissae
//! of an unclamped knot vector fall outside it at the ends, so use clamped knot vectors (as
//! Martin & Cohen do) or supply sites explicitly.

use rayon::prelude::*;

use crate::basis::{BASIS_BUF, basis_unchecked};
use crate::spline::checked_count;
use crate::{KnotVector, SplineError, TensorBSpline};

/// A pivot below this magnitude is treated as zero. Collocation entries lie in `[0, 1]` and each
/// row sums to 1, so legitimate pivots of a well-posed problem are far above it; a smaller one
/// means the sites (nearly) violate the Schoenberg–Whitney condition.
const PIVOT_TOLERANCE: f64 = 1e-13;

/// The LU factorisation (no pivoting) of one axis's collocation matrix, stored as a band.
///
/// ```
/// use volmorph_spline::{Collocation, KnotVector};
/// let kv = KnotVector::clamped_uniform(3, 8, [0.0, 1.0]).unwrap();
/// let lu = Collocation::greville(&kv).unwrap();
/// // Solving against the values of a spline at the sites returns its coefficients.
/// let coefs = [0.0, 1.0, -1.0, 2.0, 0.5, 0.0, 3.0, 1.0];
/// let c = volmorph_spline::BSplineCurve::new([kv], 1, coefs.to_vec()).unwrap();
/// let mut rhs: Vec<f64> = lu.sites().iter().map(|&t| c.eval([t]).unwrap()[0]).collect();
/// lu.solve_in_place(&mut rhs, 1).unwrap();
/// for (x, y) in rhs.iter().zip(coefs) {
///     assert!((x - y).abs() < 1e-12);
/// }
/// ```
#[derive(Debug, Clone)]
pub struct Collocation {
    n: usize,
    kl: usize,
    ku: usize,
    /// Row-major band: entry `(i, j)` at `i·(kl + ku + 1) + (j + kl − i)`; L below the diagonal
    /// (unit diagonal implied), U on and above.
    band: Vec<f64>,
    sites: Vec<f64>,
}

impl Collocation {
    /// Factor the collocation matrix at the Greville abscissae of `kv`.
    ///
    /// # Errors
    /// As [`Collocation::new`] (in particular [`SplineError::InvalidSite`] when a Greville
    /// abscissa lies outside the domain of an unclamped knot vector).
    pub fn greville(kv: &KnotVector) -> Result<Self, SplineError> {
        Self::new(kv, &kv.greville())
    }

    /// Factor the collocation matrix `A[j][i] = N_i(sites[j])`.
    ///
    /// # Errors
    /// [`SplineError::SiteCount`] unless there is one site per basis function;
    /// [`SplineError::InvalidSite`] if sites decrease, are NaN or leave the domain;
    /// [`SplineError::SingularCollocation`] if the Schoenberg–Whitney condition fails.
    pub fn new(kv: &KnotVector, sites: &[f64]) -> Result<Self, SplineError> {
        let n = kv.num_basis();
        let p = kv.degree();
        if sites.len() != n {
            return Err(SplineError::SiteCount {
                axis: 0,
                expected: n,
                got: sites.len(),
            });
        }
        let mut spans = Vec::with_capacity(n);
        for (index, &value) in sites.iter().enumerate() {
            let bad = !kv.contains(value) || (index > 0 && value < sites[index - 1]);
            if bad {
                return Err(SplineError::InvalidSite { index, value });
            }
            let s = kv.find_span_clamped(value);
            // Schoenberg–Whitney: row j must reach column j.
            if !(s >= index && s - p <= index) {
                return Err(SplineError::SingularCollocation { row: index });
            }
            spans.push(s);
        }
        let kl = spans
            .iter()
            .enumerate()
            .map(|(j, &s)| j - (s - p))
            .max()
            .unwrap_or(0);
        let ku = spans
            .iter()
            .enumerate()
            .map(|(j, &s)| s - j)
            .max()
            .unwrap_or(0);
        let w = kl + ku + 1;
        let mut band = vec![0.0; checked_count(&[n, w])?];
        let mut vals = [0.0; BASIS_BUF];
        for (j, (&t, &s)) in sites.iter().zip(&spans).enumerate() {
            basis_unchecked(kv.knots(), p, s, t, &mut vals);
            for (r, &v) in vals[..=p].iter().enumerate() {
                let col = s - p + r;
                band[j * w + col + kl - j] = v;
            }
        }
        // Doolittle elimination without pivoting inside the band.
        for k in 0..n {
            let pivot = band[k * w + kl];
            if pivot.is_nan() || pivot.abs() <= PIVOT_TOLERANCE {
                return Err(SplineError::SingularCollocation { row: k });
            }
            let jmax = (k + ku).min(n - 1);
            for i in k + 1..=(k + kl).min(n - 1) {
                let l = band[i * w + k + kl - i] / pivot;
                band[i * w + k + kl - i] = l;
                if l != 0.0 {
                    for j in k + 1..=jmax {
                        band[i * w + j + kl - i] -= l * band[k * w + j + kl - k];
                    }
                }
            }
        }
        Ok(Self {
            n,
            kl,
            ku,
            band,
            sites: sites.to_vec(),
        })
    }

    /// Number of unknowns (basis functions).
    #[must_use]
    pub fn len(&self) -> usize {
        self.n
    }

    /// Always `false` (a knot vector has at least one basis function).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The interpolation sites.
    #[must_use]
    pub fn sites(&self) -> &[f64] {
        &self.sites
    }

    /// Solve `A X = B` in place for `inner` right-hand sides stored row by row: row `j` of `B`
    /// (the data at site `j`) is `rhs[j·inner .. (j+1)·inner]`. O(n·(kl+ku)·inner), no
    /// allocation.
    ///
    /// # Errors
    /// [`SplineError::BufferLength`] if `rhs.len() != n·inner`.
    pub fn solve_in_place(&self, rhs: &mut [f64], inner: usize) -> Result<(), SplineError> {
        if rhs.len() != self.n * inner {
            return Err(SplineError::BufferLength {
                expected: self.n * inner,
                got: rhs.len(),
            });
        }
        let (n, kl, ku) = (self.n, self.kl, self.ku);
        let w = kl + ku + 1;
        // Forward: L y = b (unit lower).
        for i in 1..n {
            let (head, tail) = rhs.split_at_mut(i * inner);
            let xi = &mut tail[..inner];
            for j in i.saturating_sub(kl)..i {
                let l = self.band[i * w + j + kl - i];
                if l != 0.0 {
                    for (x, &y) in xi.iter_mut().zip(&head[j * inner..(j + 1) * inner]) {
                        *x -= l * y;
                    }
                }
            }
        }
        // Backward: U x = y.
        for i in (0..n).rev() {
            let (head, tail) = rhs.split_at_mut((i + 1) * inner);
            let xi = &mut head[i * inner..];
            for j in i + 1..=(i + ku).min(n - 1) {
                let u = self.band[i * w + j + kl - i];
                if u != 0.0 {
                    let off = (j - i - 1) * inner;
                    for (x, &y) in xi.iter_mut().zip(&tail[off..off + inner]) {
                        *x -= u * y;
                    }
                }
            }
            let inv = 1.0 / self.band[i * w + kl];
            for x in xi.iter_mut() {
                *x *= inv;
            }
        }
        Ok(())
    }
}

/// Cached per-axis factorisations for repeated tensor-product fits on the same knots and sites
/// (e.g. several attribute fields of one volume, Martin & Cohen §2.2).
#[derive(Debug, Clone)]
pub struct Interpolator<const N: usize> {
    knots: [KnotVector; N],
    axes: [Collocation; N],
}

impl<const N: usize> Interpolator<N> {
    /// Factor every axis at its Greville abscissae.
    ///
    /// # Errors
    /// As [`Collocation::greville`], with the axis named in [`SplineError::SiteCount`].
    pub fn greville(knots: [KnotVector; N]) -> Result<Self, SplineError> {
        let sites: [Vec<f64>; N] = std::array::from_fn(|a| knots[a].greville());
        Self::with_sites(knots, sites)
    }

    /// Factor every axis at the given sites (`sites[a]` has one site per basis function of
    /// axis `a`).
    ///
    /// # Errors
    /// As [`Collocation::new`].
    pub fn with_sites(knots: [KnotVector; N], sites: [Vec<f64>; N]) -> Result<Self, SplineError> {
        let mut axes = Vec::with_capacity(N);
        for a in 0..N {
            let c = Collocation::new(&knots[a], &sites[a]).map_err(|e| match e {
                SplineError::SiteCount { expected, got, .. } => SplineError::SiteCount {
                    axis: a,
                    expected,
                    got,
                },
                other => other,
            })?;
            axes.push(c);
        }
        let axes: [Collocation; N] = axes
            .try_into()
            .map_err(|_| SplineError::InvalidAxis { axis: N, dims: N })?;
        Ok(Self { knots, axes })
    }

    /// The sites of `axis` (`None` if the axis does not exist).
    #[must_use]
    pub fn sites(&self, axis: usize) -> Option<&[f64]> {
        self.axes.get(axis).map(Collocation::sites)
    }

    /// Number of data values expected per component: the product of the control counts.
    #[must_use]
    pub fn grid_len(&self) -> usize {
        self.knots.iter().map(KnotVector::num_basis).product()
    }

    /// Turn data sampled on the site grid (`dim` values per site, axis 0 fastest) into control
    /// coefficients in place, by one banded solve per line of each axis.
    ///
    /// # Errors
    /// [`SplineError::ZeroDimension`] or [`SplineError::CoefficientCount`].
    pub fn solve_in_place(&self, dim: usize, data: &mut [f64]) -> Result<(), SplineError> {
        if dim == 0 {
            return Err(SplineError::ZeroDimension);
        }
        let counts: [usize; N] = std::array::from_fn(|a| self.knots[a].num_basis());
        let mut sizes = counts.to_vec();
        sizes.push(dim);
        let expected = checked_count(&sizes)?;
        if data.len() != expected {
            return Err(SplineError::CoefficientCount {
                expected,
                got: data.len(),
            });
        }
        for a in 0..N {
            let inner = counts[..a].iter().product::<usize>() * dim;
            let line = counts[a] * inner;
            // Independent lines (blocks) are solved in parallel; each solve is sequential and
            // sweeps whole contiguous rows of `inner` values.
            data.par_chunks_exact_mut(line)
                .try_for_each(|block| self.axes[a].solve_in_place(block, inner))?;
        }
        Ok(())
    }

    /// Fit a polynomial spline to `data` sampled on the site grid (`dim` values per site,
    /// axis 0 fastest). The result interpolates the data at every grid site.
    ///
    /// # Errors
    /// As [`Interpolator::solve_in_place`], plus [`SplineError::NonFiniteCoefficient`] for
    /// non-finite data.
    pub fn fit(&self, dim: usize, data: &[f64]) -> Result<TensorBSpline<N>, SplineError> {
        let mut coefs = data.to_vec();
        self.solve_in_place(dim, &mut coefs)?;
        TensorBSpline::new(self.knots.clone(), dim, coefs)
    }
}

/// Interpolate data sampled at the Greville abscissae of `knots` (Martin & Cohen §3):
/// `data` has `dim` values per grid point `(j_0, …, j_{N−1})`, axis 0 fastest, the grid being
/// `knots[0].greville() × knots[1].greville() × …`.
///
/// # Errors
/// As [`Interpolator::greville`] and [`Interpolator::fit`].
///
/// ```
/// use volmorph_spline::{KnotVector, interpolate_greville};
/// // f(u, v) = u² v is reproduced exactly by a biquadratic interpolant.
/// let ku = KnotVector::clamped_uniform(2, 5, [0.0, 1.0]).unwrap();
/// let kv = KnotVector::clamped_uniform(2, 4, [-1.0, 1.0]).unwrap();
/// let (gu, gv) = (ku.greville(), kv.greville());
/// let data: Vec<f64> = gv.iter().flat_map(|&v| gu.iter().map(move |&u| u * u * v)).collect();
/// let s = interpolate_greville([ku, kv], 1, &data).unwrap();
/// assert!((s.eval([0.3, 0.7]).unwrap()[0] - 0.09 * 0.7).abs() < 1e-13);
/// ```
pub fn interpolate_greville<const N: usize>(
    knots: [KnotVector; N],
    dim: usize,
    data: &[f64],
) -> Result<TensorBSpline<N>, SplineError> {
    Interpolator::greville(knots)?.fit(dim, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unclamped_greville_and_bad_sites_are_rejected() {
        let kv = KnotVector::uniform(3, 6, [0.0, 1.0]).unwrap();
        assert!(matches!(
            Collocation::greville(&kv),
            Err(SplineError::InvalidSite { index: 0, .. })
        ));
        let kc = KnotVector::clamped_uniform(2, 4, [0.0, 1.0]).unwrap();
        assert!(matches!(
            Collocation::new(&kc, &[0.0, 0.5, 1.0]),
            Err(SplineError::SiteCount { expected: 4, .. })
        ));
        assert!(matches!(
            Collocation::new(&kc, &[0.0, 0.6, 0.5, 1.0]),
            Err(SplineError::InvalidSite { index: 2, .. })
        ));
        // All sites in the first span: Schoenberg-Whitney fails for the last functions.
        assert!(matches!(
            Collocation::new(&kc, &[0.0, 0.1, 0.2, 0.3]),
            Err(SplineError::SingularCollocation { .. })
        ));
        let lu = Collocation::greville(&kc).unwrap();
        assert!(lu.solve_in_place(&mut [0.0; 3], 1).is_err());
        assert_eq!(lu.len(), 4);
        let ip = Interpolator::greville([kc.clone(), kc]).unwrap();
        assert_eq!(ip.grid_len(), 16);
        assert!(ip.fit(1, &[0.0; 15]).is_err());
        assert!(ip.fit(0, &[]).is_err());
        assert_eq!(ip.sites(1).map(<[f64]>::len), Some(4));
        assert!(ip.sites(2).is_none());
    }

    #[test]
    fn explicit_sites_interpolate() {
        let kv = KnotVector::clamped(3, &[0.3, 0.3, 0.7], [0.0, 1.0]).unwrap();
        let sites = [0.0, 0.1, 0.3, 0.5, 0.8, 0.9, 1.0];
        let ip = Interpolator::with_sites([kv], [sites.to_vec()]).unwrap();
        let data: Vec<f64> = sites.iter().map(|t| (5.0 * t).cos()).collect();
        let s = ip.fit(1, &data).unwrap();
        for (t, d) in sites.iter().zip(&data) {
            assert!((s.eval([*t]).unwrap()[0] - d).abs() < 1e-12);
        }
    }
}
