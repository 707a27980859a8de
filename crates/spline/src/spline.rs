//! Tensor-product B-spline and NURBS objects of any parametric dimension `N` (curves `N = 1`,
//! surfaces `N = 2`, trivariate volumes `N = 3`) whose control values have any dimension `dim`.
//!
//! # Storage
//!
//! Control values are stored contiguously in one flat `Vec<f64>` in **homogeneous form**: each
//! control point occupies `hdim` consecutive values, where `hdim = dim` for a polynomial spline
//! and `hdim = dim + 1` for a rational one, whose tuple is `(w·P, w)` (weighted coordinates
//! followed by the weight, the `P^w` of Martin & Cohen §2.1). Knot insertion, refinement and
//! Bézier extraction are linear in these homogeneous values, so they treat both kinds alike.
//!
//! Control point `(i_0, …, i_{N−1})` starts at `hdim · (i_0 + n_0·(i_1 + n_1·(i_2 + …)))`:
//! **axis 0 (u) fastest**, then v, then w, matching the voxel order of volmorph volumes.
//!
//! # Evaluation
//!
//! `S(u) = Σ P_i Π_a N_{i_a,p_a}(u_a)` for polynomial splines and
//! `S(u) = Σ w_i P_i Π N / Σ w_i Π N` for rational ones; first partial derivatives of rational
//! splines use the quotient rule on the homogeneous sums, `∂S = (∂A − ∂W·S)/W`. Parameters
//! must lie in each axis's closed domain (see [`crate::knots`] for the span convention); outside
//! it evaluation returns [`SplineError::ParameterOutsideDomain`]. The `_into` methods never
//! allocate: basis values live in stack buffers of [`MAX_DEGREE`]` + 1` entries.

use crate::basis::{BASIS_BUF, basis_and_first_unchecked, basis_unchecked};
use crate::{KnotVector, MAX_DEGREE, SplineError};

/// Multiply sizes with overflow checking and require `product · 8` bytes to stay within the
/// memory budget ([`volmorph_io::memory_limit`]). Returns the product.
pub(crate) fn checked_count(dims: &[usize]) -> Result<usize, SplineError> {
    let mut n: usize = 1;
    for &d in dims {
        n = n
            .checked_mul(d)
            .ok_or_else(|| SplineError::TooLarge(format!("sizes {dims:?} overflow")))?;
    }
    volmorph_io::check_elems(&format!("a spline array of sizes {dims:?}"), n as u64, 8)
        .map_err(|e| SplineError::TooLarge(e.to_string()))?;
    Ok(n)
}

/// A tensor-product B-spline (polynomial or rational) with `N` parametric axes and
/// `dim`-dimensional control values. See the [module docs](self) for storage and evaluation
/// conventions.
///
/// ```
/// use volmorph_spline::{BSplineCurve, KnotVector};
/// // A rational quadratic quarter circle: every point has unit distance from the origin.
/// let kv = KnotVector::bezier(2, [0.0, 1.0]).unwrap();
/// let w = std::f64::consts::FRAC_1_SQRT_2;
/// let c = BSplineCurve::new_rational(
///     [kv],
///     2,
///     vec![1.0, 0.0, 1.0, 1.0, 0.0, 1.0],
///     vec![1.0, w, 1.0],
/// )
/// .unwrap();
/// let mut p = [0.0; 2];
/// for i in 0..=10 {
///     c.eval_into([f64::from(i) / 10.0], &mut p).unwrap();
///     assert!((p[0].hypot(p[1]) - 1.0).abs() < 1e-14);
/// }
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct TensorBSpline<const N: usize> {
    knots: [KnotVector; N],
    counts: [usize; N],
    dim: usize,
    rational: bool,
    coefs: Vec<f64>,
}

/// A B-spline / NURBS curve.
pub type BSplineCurve = TensorBSpline<1>;
/// A tensor-product B-spline / NURBS surface (control index `(i, j)`, `i` fastest).
pub type BSplineSurface = TensorBSpline<2>;
/// A trivariate B-spline / NURBS volume (control index `(i, j, k)`, `i` fastest).
pub type BSplineVolume = TensorBSpline<3>;

impl<const N: usize> TensorBSpline<N> {
    /// A polynomial (non-rational) spline. `coefs` holds one `dim`-tuple per control point in
    /// axis-0-fastest order; the control count along axis `a` is `knots[a].num_basis()`.
    ///
    /// # Errors
    /// [`SplineError::ZeroDimension`], [`SplineError::CoefficientCount`],
    /// [`SplineError::NonFiniteCoefficient`] or [`SplineError::TooLarge`].
    pub fn new(knots: [KnotVector; N], dim: usize, coefs: Vec<f64>) -> Result<Self, SplineError> {
        Self::from_parts(knots, dim, false, coefs)
    }

    /// A rational spline from Cartesian control points (`dim`-tuples, axis 0 fastest) and one
    /// weight per control point. Stored as homogeneous `(w·P, w)`.
    ///
    /// # Errors
    /// As [`TensorBSpline::new`], plus [`SplineError::NonPositiveWeight`] (weights must be
    /// finite and > 0) and [`SplineError::CoefficientCount`] for a wrong number of weights.
    pub fn new_rational(
        knots: [KnotVector; N],
        dim: usize,
        points: Vec<f64>,
        weights: Vec<f64>,
    ) -> Result<Self, SplineError> {
        if dim == 0 {
            return Err(SplineError::ZeroDimension);
        }
        let counts = counts_of(&knots);
        let n = checked_count(&counts)?;
        let expected = n
            .checked_mul(dim)
            .ok_or_else(|| SplineError::TooLarge("control net".into()))?;
        if points.len() != expected {
            return Err(SplineError::CoefficientCount {
                expected,
                got: points.len(),
            });
        }
        if weights.len() != n {
            return Err(SplineError::CoefficientCount {
                expected: n,
                got: weights.len(),
            });
        }
        let hdim = dim + 1;
        let mut coefs = vec![0.0; checked_count(&[n, hdim])?];
        for (i, (dst, (src, &w))) in coefs
            .chunks_exact_mut(hdim)
            .zip(points.chunks_exact(dim).zip(&weights))
            .enumerate()
        {
            if !(w.is_finite() && w > 0.0) {
                return Err(SplineError::NonPositiveWeight { index: i, value: w });
            }
            for (d, &s) in dst.iter_mut().zip(src) {
                *d = w * s;
            }
            dst[dim] = w;
        }
        Self::from_parts(knots, dim, true, coefs)
    }

    /// A spline from homogeneous coefficients: `hcoefs` holds `hdim = dim + rational` values
    /// per control point, `(w·P, w)` when `rational`.
    ///
    /// # Errors
    /// As [`TensorBSpline::new_rational`].
    pub fn from_homogeneous(
        knots: [KnotVector; N],
        dim: usize,
        rational: bool,
        hcoefs: Vec<f64>,
    ) -> Result<Self, SplineError> {
        Self::from_parts(knots, dim, rational, hcoefs)
    }

    fn from_parts(
        knots: [KnotVector; N],
        dim: usize,
        rational: bool,
        coefs: Vec<f64>,
    ) -> Result<Self, SplineError> {
        const {
            assert!(
                N >= 1,
                "a tensor-product spline needs at least one parametric axis"
            )
        };
        if dim == 0 {
            return Err(SplineError::ZeroDimension);
        }
        let counts = counts_of(&knots);
        let n = checked_count(&counts)?;
        let hdim = dim + usize::from(rational);
        let expected = checked_count(&[n, hdim])?;
        if coefs.len() != expected {
            return Err(SplineError::CoefficientCount {
                expected,
                got: coefs.len(),
            });
        }
        if let Some((index, &value)) = coefs.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(SplineError::NonFiniteCoefficient { index, value });
        }
        if rational {
            for (index, c) in coefs.chunks_exact(hdim).enumerate() {
                let w = c[dim];
                if w <= 0.0 {
                    return Err(SplineError::NonPositiveWeight { index, value: w });
                }
            }
        }
        Ok(Self {
            knots,
            counts,
            dim,
            rational,
            coefs,
        })
    }

    /// Build without validation (internal: sizes and weights are correct by construction).
    pub(crate) fn from_parts_unchecked(
        knots: [KnotVector; N],
        dim: usize,
        rational: bool,
        coefs: Vec<f64>,
    ) -> Self {
        const {
            assert!(
                N >= 1,
                "a tensor-product spline needs at least one parametric axis"
            )
        };
        let counts = counts_of(&knots);
        debug_assert_eq!(
            coefs.len(),
            counts.iter().product::<usize>() * (dim + usize::from(rational))
        );
        Self {
            knots,
            counts,
            dim,
            rational,
            coefs,
        }
    }

    /// The identity map of parameter space: `dim = N` and control point `(i_0, …, i_{N−1})` at
    /// the Greville abscissae `(ξ^0_{i_0}, …, ξ^{N−1}_{i_{N−1}})`. By the linear precision of
    /// B-splines (`Σ ξ_i N_{i,p}(u) = u` for `p ≥ 1`) it evaluates to its parameters with unit
    /// Jacobian everywhere in the domain: the undeformed lattice of True's warps and of Feng's
    /// identity-Jacobian FFD.
    ///
    /// # Errors
    /// [`SplineError::DegreeTooLow`] if an axis has degree 0, [`SplineError::TooLarge`].
    ///
    /// ```
    /// use volmorph_spline::{BSplineVolume, KnotVector};
    /// let k = KnotVector::uniform(3, 9, [0.0, 6.0]).unwrap();
    /// let id = BSplineVolume::identity([k.clone(), k.clone(), k]).unwrap();
    /// let (v, g) = id.eval_with_gradient([1.25, 4.5, 6.0]).unwrap();
    /// assert!((v[0] - 1.25).abs() < 1e-14 && (v[1] - 4.5).abs() < 1e-14 && (v[2] - 6.0).abs() < 1e-14);
    /// assert!((g[0] - 1.0).abs() < 1e-14 && g[1].abs() < 1e-14 && (g[8] - 1.0).abs() < 1e-14);
    /// ```
    pub fn identity(knots: [KnotVector; N]) -> Result<Self, SplineError> {
        for (axis, k) in knots.iter().enumerate() {
            if k.degree() == 0 {
                return Err(SplineError::DegreeTooLow {
                    axis,
                    degree: 0,
                    min: 1,
                });
            }
        }
        let counts = counts_of(&knots);
        let n = checked_count(&counts)?;
        let greville: Vec<Vec<f64>> = knots.iter().map(KnotVector::greville).collect();
        let mut coefs = Vec::with_capacity(checked_count(&[n, N])?);
        for lin in 0..n {
            let mut rest = lin;
            for (a, g) in greville.iter().enumerate() {
                coefs.push(g[rest % counts[a]]);
                rest /= counts[a];
            }
        }
        Self::new(knots, N, coefs)
    }

    /// The knot vectors, one per axis.
    #[must_use]
    pub fn knots(&self) -> &[KnotVector; N] {
        &self.knots
    }

    /// Degrees per axis.
    #[must_use]
    pub fn degrees(&self) -> [usize; N] {
        std::array::from_fn(|a| self.knots[a].degree())
    }

    /// Control-point counts per axis (`knots[a].num_basis()`).
    #[must_use]
    pub fn counts(&self) -> [usize; N] {
        self.counts
    }

    /// Total number of control points.
    #[must_use]
    pub fn num_control_points(&self) -> usize {
        self.counts.iter().product()
    }

    /// Dimension of the control values (and of evaluated values).
    #[must_use]
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// `true` for a rational (NURBS) spline.
    #[must_use]
    pub fn is_rational(&self) -> bool {
        self.rational
    }

    /// Values stored per control point: `dim + 1` if rational, else `dim`.
    #[must_use]
    pub fn homogeneous_dim(&self) -> usize {
        self.dim + usize::from(self.rational)
    }

    /// The parametric domain per axis, `[[u_start, u_end], …]`.
    #[must_use]
    pub fn domain(&self) -> [[f64; 2]; N] {
        std::array::from_fn(|a| self.knots[a].domain())
    }

    /// The flat homogeneous coefficients (see the module docs for layout).
    #[must_use]
    pub fn homogeneous_coefficients(&self) -> &[f64] {
        &self.coefs
    }

    /// Linear control-point index of `index` (axis 0 fastest), or `None` when out of range.
    #[must_use]
    pub fn linear_index(&self, index: [usize; N]) -> Option<usize> {
        let mut lin = 0;
        for a in (0..N).rev() {
            if index[a] >= self.counts[a] {
                return None;
            }
            lin = lin * self.counts[a] + index[a];
        }
        Some(lin)
    }

    fn checked_linear(&self, index: [usize; N]) -> Result<usize, SplineError> {
        self.linear_index(index)
            .ok_or_else(|| SplineError::IndexOutOfRange {
                index: index.to_vec(),
                counts: self.counts.to_vec(),
            })
    }

    /// Write the Cartesian control point `index` (homogeneous form divided by its weight) into
    /// `out[..dim]`.
    ///
    /// # Errors
    /// [`SplineError::IndexOutOfRange`] or [`SplineError::BufferLength`].
    pub fn control_point_into(
        &self,
        index: [usize; N],
        out: &mut [f64],
    ) -> Result<(), SplineError> {
        let lin = self.checked_linear(index)?;
        check_out(out.len(), self.dim)?;
        let h = self.homogeneous_dim();
        let c = &self.coefs[lin * h..(lin + 1) * h];
        let inv = if self.rational {
            1.0 / c[self.dim]
        } else {
            1.0
        };
        for (o, &v) in out.iter_mut().zip(&c[..self.dim]) {
            *o = v * inv;
        }
        Ok(())
    }

    /// The weight of control point `index` (1 for polynomial splines).
    ///
    /// # Errors
    /// [`SplineError::IndexOutOfRange`].
    pub fn weight(&self, index: [usize; N]) -> Result<f64, SplineError> {
        let lin = self.checked_linear(index)?;
        Ok(if self.rational {
            self.coefs[lin * (self.dim + 1) + self.dim]
        } else {
            1.0
        })
    }

    /// Move control point `index` to the Cartesian position `point` (its weight is kept).
    ///
    /// # Errors
    /// [`SplineError::IndexOutOfRange`], [`SplineError::BufferLength`] if
    /// `point.len() != dim`, [`SplineError::NonFiniteCoefficient`].
    pub fn set_control_point(
        &mut self,
        index: [usize; N],
        point: &[f64],
    ) -> Result<(), SplineError> {
        let lin = self.checked_linear(index)?;
        if point.len() != self.dim {
            return Err(SplineError::BufferLength {
                expected: self.dim,
                got: point.len(),
            });
        }
        if let Some((i, &value)) = point.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(SplineError::NonFiniteCoefficient { index: i, value });
        }
        let h = self.homogeneous_dim();
        let c = &mut self.coefs[lin * h..(lin + 1) * h];
        let w = if self.rational { c[self.dim] } else { 1.0 };
        for (d, &s) in c.iter_mut().zip(point) {
            *d = w * s;
        }
        Ok(())
    }

    /// All Cartesian control points, `dim` values each, axis 0 fastest (allocates).
    #[must_use]
    pub fn control_points(&self) -> Vec<f64> {
        if !self.rational {
            return self.coefs.clone();
        }
        let h = self.dim + 1;
        let mut out = Vec::with_capacity(self.num_control_points() * self.dim);
        for c in self.coefs.chunks_exact(h) {
            let inv = 1.0 / c[self.dim];
            out.extend(c[..self.dim].iter().map(|v| v * inv));
        }
        out
    }

    /// All weights (`None` for polynomial splines).
    #[must_use]
    pub fn weights(&self) -> Option<Vec<f64>> {
        self.rational.then(|| {
            self.coefs
                .chunks_exact(self.dim + 1)
                .map(|c| c[self.dim])
                .collect()
        })
    }

    /// The same geometry as a rational spline with unit weights (a copy if already rational).
    #[must_use]
    pub fn to_rational(&self) -> Self {
        if self.rational {
            return self.clone();
        }
        let h = self.dim + 1;
        let mut coefs = vec![0.0; self.num_control_points() * h];
        for (d, s) in coefs
            .chunks_exact_mut(h)
            .zip(self.coefs.chunks_exact(self.dim))
        {
            d[..self.dim].copy_from_slice(s);
            d[self.dim] = 1.0;
        }
        Self::from_parts_unchecked(self.knots.clone(), self.dim, true, coefs)
    }

    /// The homogeneous form `P^w` as a polynomial spline with `dim + 1` components
    /// `(w·S, w)` (for a polynomial spline: `(S, 1)`).
    #[must_use]
    pub fn homogeneous(&self) -> Self {
        let r = self.to_rational();
        Self::from_parts_unchecked(r.knots, r.dim + 1, false, r.coefs)
    }

    /// The same spline with each axis affinely reparametrised onto `domain[a]` (knot vectors
    /// mapped by [`KnotVector::rescaled`]; control values unchanged). Martin & Cohen normalise
    /// every geometry and attribute volume to the unit cube this way.
    ///
    /// # Errors
    /// As [`KnotVector::rescaled`].
    pub fn reparametrized(&self, domain: [[f64; 2]; N]) -> Result<Self, SplineError> {
        let mut knots = self.knots.clone();
        for (k, d) in knots.iter_mut().zip(domain) {
            *k = k.rescaled(d)?;
        }
        Ok(Self::from_parts_unchecked(
            knots,
            self.dim,
            self.rational,
            self.coefs.clone(),
        ))
    }

    /// Replace the knot vector of `axis` and the coefficients (internal, used by refinement).
    pub(crate) fn with_axis(&self, axis: usize, kv: KnotVector, coefs: Vec<f64>) -> Self {
        let mut knots = self.knots.clone();
        knots[axis] = kv;
        Self::from_parts_unchecked(knots, self.dim, self.rational, coefs)
    }

    /// `(outer, len, inner)` block decomposition of the coefficient array along `axis`:
    /// element `(o, i, k)` is at `(o·len + i)·inner + k`.
    pub(crate) fn axis_blocks(&self, axis: usize) -> (usize, usize, usize) {
        let inner = self.counts[..axis].iter().product::<usize>() * self.homogeneous_dim();
        let outer = self.counts[axis + 1..].iter().product::<usize>();
        (outer, self.counts[axis], inner)
    }

    pub(crate) fn check_axis(axis: usize) -> Result<(), SplineError> {
        if axis < N {
            Ok(())
        } else {
            Err(SplineError::InvalidAxis { axis, dims: N })
        }
    }

    fn spans(&self, params: [f64; N]) -> Result<[usize; N], SplineError> {
        let mut spans = [0; N];
        for a in 0..N {
            spans[a] = self.knots[a].find_span(params[a]).map_err(|e| match e {
                SplineError::ParameterOutsideDomain {
                    value, start, end, ..
                } => SplineError::ParameterOutsideDomain {
                    axis: a,
                    value,
                    start,
                    end,
                },
                other => other,
            })?;
        }
        Ok(spans)
    }

    /// Evaluate the spline at `params` (one parameter per axis) into `out[..dim]`.
    /// No allocation.
    ///
    /// # Errors
    /// [`SplineError::ParameterOutsideDomain`] or [`SplineError::BufferLength`]
    /// (`out.len() < dim`).
    pub fn eval_into(&self, params: [f64; N], out: &mut [f64]) -> Result<(), SplineError> {
        self.net()
            .evaluate(out, None, |vals, ders| self.fill_basis(params, vals, ders))
    }

    /// Evaluate the value and all first partial derivatives at `params`. `value[..dim]` receives
    /// `S`, `gradient[a·dim + c]` receives `∂S_c/∂u_a` (axis-major). No allocation.
    ///
    /// # Errors
    /// [`SplineError::ParameterOutsideDomain`] or [`SplineError::BufferLength`]
    /// (`value.len() < dim` or `gradient.len() < N·dim`).
    pub fn eval_with_gradient_into(
        &self,
        params: [f64; N],
        value: &mut [f64],
        gradient: &mut [f64],
    ) -> Result<(), SplineError> {
        self.net().evaluate(value, Some(gradient), |vals, ders| {
            self.fill_basis(params, vals, ders)
        })
    }

    /// The control net in the form the contraction kernels read.
    pub(crate) fn net(&self) -> Net<'_, N> {
        Net {
            coefs: &self.coefs,
            counts: &self.counts,
            dim: self.dim,
            rational: self.rational,
        }
    }

    /// Fill the non-zero basis values at `params` (and their first derivatives when `ders`
    /// is given) per axis; returns the first control index and the number of functions per
    /// axis.
    fn fill_basis(
        &self,
        params: [f64; N],
        vals: &mut [[f64; BASIS_BUF]; N],
        mut ders: Option<&mut [[f64; BASIS_BUF]; N]>,
    ) -> Result<([usize; N], [usize; N]), SplineError> {
        let spans = self.spans(params)?;
        let mut first = [0; N];
        let mut orders = [0; N];
        for a in 0..N {
            let p = self.knots[a].degree();
            let knots = self.knots[a].knots();
            match ders.as_deref_mut() {
                None => basis_unchecked(knots, p, spans[a], params[a], &mut vals[a]),
                Some(d) => {
                    basis_and_first_unchecked(
                        knots,
                        p,
                        spans[a],
                        params[a],
                        &mut vals[a],
                        &mut d[a],
                    );
                }
            }
            first[a] = spans[a] - p;
            orders[a] = p + 1;
        }
        Ok((first, orders))
    }

    /// Allocating form of [`TensorBSpline::eval_into`].
    ///
    /// # Errors
    /// As [`TensorBSpline::eval_into`].
    pub fn eval(&self, params: [f64; N]) -> Result<Vec<f64>, SplineError> {
        let mut out = vec![0.0; self.dim];
        self.eval_into(params, &mut out)?;
        Ok(out)
    }

    /// Allocating form of [`TensorBSpline::eval_with_gradient_into`]: `(value, gradient)`.
    ///
    /// # Errors
    /// As [`TensorBSpline::eval_with_gradient_into`].
    pub fn eval_with_gradient(
        &self,
        params: [f64; N],
    ) -> Result<(Vec<f64>, Vec<f64>), SplineError> {
        let mut v = vec![0.0; self.dim];
        let mut g = vec![0.0; N * self.dim];
        self.eval_with_gradient_into(params, &mut v, &mut g)?;
        Ok((v, g))
    }
}

fn counts_of<const N: usize>(knots: &[KnotVector; N]) -> [usize; N] {
    std::array::from_fn(|a| knots[a].num_basis())
}

pub(crate) fn check_out(got: usize, expected: usize) -> Result<(), SplineError> {
    if got < expected {
        Err(SplineError::BufferLength { expected, got })
    } else {
        Ok(())
    }
}

/// Largest homogeneous dimension evaluated with register accumulators (points with weights,
/// RGBA-like attribute tuples); larger ones take the general path.
const SMALL_HDIM: usize = 8;

/// A borrowed homogeneous control net, shared by B-spline and Bézier evaluation.
pub(crate) struct Net<'a, const N: usize> {
    pub coefs: &'a [f64],
    pub counts: &'a [usize; N],
    pub dim: usize,
    pub rational: bool,
}

impl<const N: usize> Net<'_, N> {
    /// Contract the sub-net starting at `first` with `orders[a]` points per axis against the
    /// per-axis basis values (`vals[a][..orders[a]]`) and optionally first derivatives.
    /// Writes the (projected, for rational nets) value and gradient (axis-major).
    pub fn contract(
        &self,
        first: [usize; N],
        orders: [usize; N],
        vals: &[[f64; BASIS_BUF]; N],
        ders: Option<&[[f64; BASIS_BUF]; N]>,
        value: &mut [f64],
        grad: Option<&mut [f64]>,
    ) {
        let hdim = self.dim + usize::from(self.rational);
        if hdim <= SMALL_HDIM {
            self.contract_small(first, orders, vals, ders, value, grad);
        } else {
            self.contract_general(first, orders, vals, ders, value, grad);
        }
    }

    /// Evaluate into `value[..dim]` and, when `gradient` is given, the first partial
    /// derivatives into `gradient[..N·dim]` (axis-major: `gradient[a·dim + c] = ∂S_c/∂u_a`).
    /// `basis(vals, ders)` fills the per-axis basis values (and first derivatives when `ders`
    /// is `Some`) and returns the first control index and the number of functions per axis.
    /// No allocation.
    ///
    /// # Errors
    /// [`SplineError::BufferLength`] for short buffers (checked first), else the error of
    /// `basis`.
    pub fn evaluate(
        &self,
        value: &mut [f64],
        gradient: Option<&mut [f64]>,
        basis: impl FnOnce(
            &mut [[f64; BASIS_BUF]; N],
            Option<&mut [[f64; BASIS_BUF]; N]>,
        ) -> Result<([usize; N], [usize; N]), SplineError>,
    ) -> Result<(), SplineError> {
        let dim = self.dim;
        check_out(value.len(), dim)?;
        if let Some(g) = &gradient {
            check_out(g.len(), N * dim)?;
        }
        let mut vals = [[0.0; BASIS_BUF]; N];
        match gradient {
            None => {
                let (first, orders) = basis(&mut vals, None)?;
                self.contract(first, orders, &vals, None, &mut value[..dim], None);
            }
            Some(g) => {
                let mut ders = [[0.0; BASIS_BUF]; N];
                let (first, orders) = basis(&mut vals, Some(&mut ders))?;
                self.contract(
                    first,
                    orders,
                    &vals,
                    Some(&ders),
                    &mut value[..dim],
                    Some(&mut g[..N * dim]),
                );
            }
        }
        Ok(())
    }

    fn strides(&self) -> [usize; N] {
        let hdim = self.dim + usize::from(self.rational);
        let mut strides = [0usize; N];
        let mut s = hdim;
        for (stride, &count) in strides.iter_mut().zip(self.counts) {
            *stride = s;
            s *= count;
        }
        strides
    }

    /// Sum-factorised contraction with register accumulators, for `hdim <= SMALL_HDIM`: each
    /// axis-0 row of the sub-net is first reduced with the axis-0 basis, then scaled by the
    /// product of the other axes' basis values.
    fn contract_small(
        &self,
        first: [usize; N],
        orders: [usize; N],
        vals: &[[f64; BASIS_BUF]; N],
        ders: Option<&[[f64; BASIS_BUF]; N]>,
        value: &mut [f64],
        grad: Option<&mut [f64]>,
    ) {
        let dim = self.dim;
        let hdim = dim + usize::from(self.rational);
        let strides = self.strides();
        let mut acc = [0.0; SMALL_HDIM];
        let mut gacc = [[0.0; SMALL_HDIM]; N];
        let mut idx = [0usize; N];
        let o0 = orders[0];
        loop {
            let mut w_outer = 1.0;
            let mut base = first[0] * strides[0];
            for a in 1..N {
                w_outer *= vals[a][idx[a]];
                base += (first[a] + idx[a]) * strides[a];
            }
            let row = &self.coefs[base..base + o0 * hdim];
            let mut rv = [0.0; SMALL_HDIM];
            let mut rd = [0.0; SMALL_HDIM];
            match ders {
                None => {
                    for (c, &b) in row.chunks_exact(hdim).zip(&vals[0][..o0]) {
                        for k in 0..hdim {
                            rv[k] += b * c[k];
                        }
                    }
                    for k in 0..hdim {
                        acc[k] += w_outer * rv[k];
                    }
                }
                Some(d) => {
                    for ((c, &b), &db) in
                        row.chunks_exact(hdim).zip(&vals[0][..o0]).zip(&d[0][..o0])
                    {
                        for k in 0..hdim {
                            rv[k] += b * c[k];
                            rd[k] += db * c[k];
                        }
                    }
                    for k in 0..hdim {
                        acc[k] += w_outer * rv[k];
                        gacc[0][k] += w_outer * rd[k];
                    }
                    for (a, ga) in gacc.iter_mut().enumerate().skip(1) {
                        let dw = outer_derivative_weight(vals, d, &idx, a);
                        for k in 0..hdim {
                            ga[k] += dw * rv[k];
                        }
                    }
                }
            }
            if !next_outer(&mut idx, &orders) {
                break;
            }
        }
        if self.rational {
            let inv = 1.0 / acc[dim];
            for (v, &x) in value.iter_mut().zip(&acc[..dim]) {
                *v = x * inv;
            }
            if let Some(g) = grad {
                for a in 0..N {
                    let wa = gacc[a][dim];
                    for ((gv, &x), &v) in g[a * dim..(a + 1) * dim]
                        .iter_mut()
                        .zip(&gacc[a][..dim])
                        .zip(value.iter())
                    {
                        *gv = (x - wa * v) * inv;
                    }
                }
            }
        } else {
            value.copy_from_slice(&acc[..dim]);
            if let Some(g) = grad {
                for a in 0..N {
                    g[a * dim..(a + 1) * dim].copy_from_slice(&gacc[a][..dim]);
                }
            }
        }
    }

    /// Contraction for any `hdim`, accumulating directly into the output buffers.
    fn contract_general(
        &self,
        first: [usize; N],
        orders: [usize; N],
        vals: &[[f64; BASIS_BUF]; N],
        ders: Option<&[[f64; BASIS_BUF]; N]>,
        value: &mut [f64],
        mut grad: Option<&mut [f64]>,
    ) {
        let dim = self.dim;
        let hdim = dim + usize::from(self.rational);
        let strides = self.strides();
        value.fill(0.0);
        if let Some(g) = grad.as_deref_mut() {
            g.fill(0.0);
        }
        let mut wsum = 0.0;
        let mut wgrad = [0.0; N];
        // Odometer over axes 1..N; axis 0 is the contiguous inner loop.
        let mut idx = [0usize; N];
        loop {
            let mut w_outer = 1.0;
            let mut base = first[0] * strides[0];
            for a in 1..N {
                w_outer *= vals[a][idx[a]];
                base += (first[a] + idx[a]) * strides[a];
            }
            let mut dw = [0.0; N];
            if let Some(d) = ders {
                for (a, w) in dw.iter_mut().enumerate().skip(1) {
                    *w = outer_derivative_weight(vals, d, &idx, a);
                }
            }
            for i0 in 0..orders[0] {
                let off = base + i0 * hdim;
                let c = &self.coefs[off..off + hdim];
                let b0 = vals[0][i0] * w_outer;
                for (v, &x) in value.iter_mut().zip(&c[..dim]) {
                    *v += b0 * x;
                }
                if self.rational {
                    wsum += b0 * c[dim];
                }
                if let (Some(g), Some(d)) = (grad.as_deref_mut(), ders) {
                    let g0 = d[0][i0] * w_outer;
                    for (gv, &x) in g[..dim].iter_mut().zip(&c[..dim]) {
                        *gv += g0 * x;
                    }
                    if self.rational {
                        wgrad[0] += g0 * c[dim];
                    }
                    for a in 1..N {
                        let ga = vals[0][i0] * dw[a];
                        for (gv, &x) in g[a * dim..(a + 1) * dim].iter_mut().zip(&c[..dim]) {
                            *gv += ga * x;
                        }
                        if self.rational {
                            wgrad[a] += ga * c[dim];
                        }
                    }
                }
            }
            if !next_outer(&mut idx, &orders) {
                break;
            }
        }
        if self.rational {
            let inv = 1.0 / wsum;
            for v in value.iter_mut() {
                *v *= inv;
            }
            if let Some(g) = grad {
                for a in 0..N {
                    for (gv, &v) in g[a * dim..(a + 1) * dim].iter_mut().zip(value.iter()) {
                        *gv = (*gv - wgrad[a] * v) * inv;
                    }
                }
            }
        }
    }
}

/// Advance an odometer over the axes `1..N` (axis 0 is the contiguous inner loop, left at 0):
/// `idx[a]` runs over `0..orders[a]`, axis 1 fastest. Returns `false` once every index has
/// wrapped back to 0, i.e. after the last position.
pub(crate) fn next_outer<const N: usize>(idx: &mut [usize; N], orders: &[usize; N]) -> bool {
    for a in 1..N {
        idx[a] += 1;
        if idx[a] < orders[a] {
            return true;
        }
        idx[a] = 0;
    }
    false
}

/// `∂/∂u_a` of the outer weight `∏_{b≥1} vals[b][idx[b]]` at the odometer position `idx`
/// (axis `a ≥ 1`): the derivative of axis `a` times the values of the other outer axes.
fn outer_derivative_weight<const N: usize>(
    vals: &[[f64; BASIS_BUF]; N],
    ders: &[[f64; BASIS_BUF]; N],
    idx: &[usize; N],
    a: usize,
) -> f64 {
    let mut w = ders[a][idx[a]];
    for b in 1..N {
        if b != a {
            w *= vals[b][idx[b]];
        }
    }
    w
}

// Keep the degree bound visible to readers of this module.
const _: () = assert!(BASIS_BUF == MAX_DEGREE + 1);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn construction_is_validated() {
        let kv = KnotVector::clamped_uniform(1, 3, [0.0, 1.0]).unwrap();
        assert!(matches!(
            BSplineCurve::new([kv.clone()], 2, vec![0.0; 5]),
            Err(SplineError::CoefficientCount {
                expected: 6,
                got: 5
            })
        ));
        assert!(matches!(
            BSplineCurve::new([kv.clone()], 0, vec![]),
            Err(SplineError::ZeroDimension)
        ));
        assert!(matches!(
            BSplineCurve::new([kv.clone()], 1, vec![0.0, f64::NAN, 1.0]),
            Err(SplineError::NonFiniteCoefficient { index: 1, .. })
        ));
        assert!(matches!(
            BSplineCurve::new_rational([kv.clone()], 1, vec![0.0; 3], vec![1.0, 0.0, 1.0]),
            Err(SplineError::NonPositiveWeight { index: 1, .. })
        ));
        assert!(matches!(
            BSplineCurve::new_rational([kv.clone()], 1, vec![0.0; 3], vec![1.0, 1.0]),
            Err(SplineError::CoefficientCount {
                expected: 3,
                got: 2
            })
        ));
        assert!(matches!(
            BSplineCurve::from_homogeneous([kv], 1, true, vec![0.0, 1.0, 0.0, -1.0, 0.0, 1.0]),
            Err(SplineError::NonPositiveWeight { index: 1, .. })
        ));
    }

    #[test]
    fn accessors_round_trip() {
        let ku = KnotVector::clamped_uniform(1, 2, [0.0, 1.0]).unwrap();
        let kv = KnotVector::clamped_uniform(1, 3, [0.0, 2.0]).unwrap();
        let pts: Vec<f64> = (0..6).map(f64::from).collect();
        let w = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let mut s = BSplineSurface::new_rational([ku, kv], 1, pts.clone(), w.clone()).unwrap();
        assert_eq!(s.linear_index([1, 2]), Some(5));
        assert_eq!(s.linear_index([2, 0]), None);
        assert_eq!(s.weight([1, 1]).unwrap(), 4.0);
        let mut p = [0.0];
        s.control_point_into([1, 2], &mut p).unwrap();
        assert_eq!(p, [5.0]);
        s.set_control_point([0, 1], &[7.0]).unwrap();
        s.control_point_into([0, 1], &mut p).unwrap();
        assert!((p[0] - 7.0).abs() < 1e-15);
        assert_eq!(s.weights().unwrap(), w);
        assert!(s.control_point_into([0, 3], &mut p).is_err());
        assert!(s.eval_into([0.5, 2.5], &mut p).is_err());
        assert!(matches!(
            s.eval_into([0.5, 2.5], &mut p),
            Err(SplineError::ParameterOutsideDomain { axis: 1, .. })
        ));
        assert!(s.eval_into([0.5, 0.5], &mut []).is_err());
    }

    #[test]
    fn wide_values_take_the_general_path_consistently() {
        // A rational volume with 9 components (hdim 10 > SMALL_HDIM) against the 9 scalar
        // volumes with the same weights (hdim 2, fast path).
        let ks = [
            KnotVector::clamped_uniform(2, 4, [0.0, 1.0]).unwrap(),
            KnotVector::uniform(1, 3, [0.0, 2.0]).unwrap(),
            KnotVector::clamped(3, &[0.5], [0.0, 1.0]).unwrap(),
        ];
        let n = 4 * 3 * 5;
        let pts: Vec<f64> = (0..9 * n)
            .map(|i| (f64::from(i as u32) * 0.71).sin())
            .collect();
        let w: Vec<f64> = (0..n).map(|i| 1.5 + (f64::from(i as u32)).cos()).collect();
        let wide = BSplineVolume::new_rational(ks.clone(), 9, pts.clone(), w.clone()).unwrap();
        let t = [0.3, 1.7, 0.61];
        let (wv, wg) = wide.eval_with_gradient(t).unwrap();
        for c in 0..9 {
            let comp: Vec<f64> = (0..n).map(|i| pts[9 * i + c]).collect();
            let s = BSplineVolume::new_rational(ks.clone(), 1, comp, w.clone()).unwrap();
            let (v, g) = s.eval_with_gradient(t).unwrap();
            assert!((v[0] - wv[c]).abs() < 1e-14);
            for a in 0..3 {
                assert!((g[a] - wg[a * 9 + c]).abs() < 1e-12);
            }
            assert!((s.eval(t).unwrap()[0] - wide.eval(t).unwrap()[c]).abs() < 1e-14);
        }
    }

    #[test]
    fn bilinear_surface_is_exact() {
        // Degree (1,1) on [0,1]^2 with corners f = x + 2y + 3xy.
        let k = KnotVector::bezier(1, [0.0, 1.0]).unwrap();
        let f = |x: f64, y: f64| x + 2.0 * y + 3.0 * x * y;
        let coefs = vec![f(0., 0.), f(1., 0.), f(0., 1.), f(1., 1.)];
        let s = BSplineSurface::new([k.clone(), k], 1, coefs).unwrap();
        let (v, g) = s.eval_with_gradient([0.3, 0.8]).unwrap();
        assert!((v[0] - f(0.3, 0.8)).abs() < 1e-15);
        assert!((g[0] - (1.0 + 3.0 * 0.8)).abs() < 1e-14);
        assert!((g[1] - (2.0 + 3.0 * 0.3)).abs() < 1e-14);
    }
}
