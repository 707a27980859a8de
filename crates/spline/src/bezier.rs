//! Bézier pieces: Bernstein control nets on one knot span (curve segment), one span box
//! (surface patch) or one span cell (volume cell), and their extraction from B-splines.
//!
//! Extraction refines every axis until each breakpoint of the domain (ends included) has
//! multiplicity `p` (knots already at `p` or more are left alone). After that, the polynomial
//! piece on the non-empty span `[u_k, u_{k+1})` is the Bézier polynomial whose control points
//! are `P_{k−p} … P_k` of the refined net, on the parameter interval `[u_k, u_{k+1}]`
//! (Feng 2002 uses exactly this to turn a B-spline lattice into Bézier cells). Rational splines
//! give rational Bézier pieces (homogeneous coefficients, weights preserved).
//!
//! A [`BezierPiece`] is evaluated with the Bernstein basis in the local parameter
//! `t = (u − start)/(end − start)`; its domain is the closed box of its span.

use crate::bernstein::{bernstein_derivative_unchecked, bernstein_unchecked};
use crate::spline::{Net, checked_count, next_outer};
use crate::{KnotVector, MAX_DEGREE, SplineError, TensorBSpline, basis::BASIS_BUF};

/// A tensor-product Bézier (Bernstein) piece with `N` parametric axes on a parameter box.
///
/// Coefficients are homogeneous and stored like those of [`TensorBSpline`]: `hdim` values per
/// control point (`(w·P, w)` when rational), axis 0 fastest; axis `a` has `degree[a] + 1`
/// control points.
///
/// ```
/// use volmorph_spline::{BSplineCurve, KnotVector};
/// // A single-span clamped spline is already in Bernstein form: extraction returns its net.
/// let kv = KnotVector::bezier(3, [2.0, 4.0]).unwrap();
/// let c = BSplineCurve::new([kv], 1, vec![1.0, -2.0, 5.0, 0.5]).unwrap();
/// let pieces = c.bezier_pieces().unwrap();
/// assert_eq!(pieces.len(), 1);
/// assert_eq!(pieces[0].homogeneous_coefficients(), &[1.0, -2.0, 5.0, 0.5]);
/// assert_eq!(pieces[0].domain(), [[2.0, 4.0]]);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct BezierPiece<const N: usize> {
    degrees: [usize; N],
    domain: [[f64; 2]; N],
    span: [usize; N],
    dim: usize,
    rational: bool,
    counts: [usize; N],
    coefs: Vec<f64>,
}

/// A Bézier curve segment.
pub type BezierSegment = BezierPiece<1>;
/// A tensor-product Bézier surface patch.
pub type BezierPatch = BezierPiece<2>;
/// A trivariate Bézier volume cell.
pub type BezierCell = BezierPiece<3>;

impl<const N: usize> BezierPiece<N> {
    /// A Bézier piece from homogeneous coefficients (`dim + rational` values per control point,
    /// `(w·P, w)` when rational, axis 0 fastest) on the parameter box `domain`. `span` is a
    /// caller-chosen label (extraction stores the span's ordinal per axis).
    ///
    /// # Errors
    /// [`SplineError::DegreeTooHigh`], [`SplineError::EmptyDomain`],
    /// [`SplineError::ZeroDimension`], [`SplineError::CoefficientCount`],
    /// [`SplineError::NonFiniteCoefficient`], [`SplineError::NonPositiveWeight`].
    pub fn new(
        degrees: [usize; N],
        domain: [[f64; 2]; N],
        span: [usize; N],
        dim: usize,
        rational: bool,
        coefs: Vec<f64>,
    ) -> Result<Self, SplineError> {
        const { assert!(N >= 1, "a Bézier piece needs at least one parametric axis") };
        for (&degree, &[start, end]) in degrees.iter().zip(&domain) {
            if degree > MAX_DEGREE {
                return Err(SplineError::DegreeTooHigh {
                    degree,
                    max: MAX_DEGREE,
                });
            }
            if !(start.is_finite() && end.is_finite() && start < end) {
                return Err(SplineError::EmptyDomain { start, end });
            }
        }
        if dim == 0 {
            return Err(SplineError::ZeroDimension);
        }
        let counts = degrees.map(|p| p + 1);
        let hdim = dim + usize::from(rational);
        let mut sizes = counts.to_vec();
        sizes.push(hdim);
        let expected = checked_count(&sizes)?;
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
                if c[dim] <= 0.0 {
                    return Err(SplineError::NonPositiveWeight {
                        index,
                        value: c[dim],
                    });
                }
            }
        }
        Ok(Self {
            degrees,
            domain,
            span,
            dim,
            rational,
            counts,
            coefs,
        })
    }

    /// Degrees per axis.
    #[must_use]
    pub fn degrees(&self) -> [usize; N] {
        self.degrees
    }

    /// Parameter box `[[start, end]; N]` of the piece (the span box of the source spline).
    #[must_use]
    pub fn domain(&self) -> [[f64; 2]; N] {
        self.domain
    }

    /// Ordinal of the source span along each axis (0 = first non-empty span of the domain,
    /// in the order of [`KnotVector::spans`]).
    #[must_use]
    pub fn span(&self) -> [usize; N] {
        self.span
    }

    /// Dimension of the values.
    #[must_use]
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// `true` if the piece is rational.
    #[must_use]
    pub fn is_rational(&self) -> bool {
        self.rational
    }

    /// The homogeneous Bernstein coefficients (see the type docs for layout).
    #[must_use]
    pub fn homogeneous_coefficients(&self) -> &[f64] {
        &self.coefs
    }

    /// All Cartesian control points, `dim` values each, axis 0 fastest (allocates).
    #[must_use]
    pub fn control_points(&self) -> Vec<f64> {
        if !self.rational {
            return self.coefs.clone();
        }
        self.coefs
            .chunks_exact(self.dim + 1)
            .flat_map(|c| c[..self.dim].iter().map(move |v| v / c[self.dim]))
            .collect()
    }

    fn local(&self, params: [f64; N]) -> Result<[f64; N], SplineError> {
        let mut t = [0.0; N];
        for a in 0..N {
            let [start, end] = self.domain[a];
            let u = params[a];
            if !(u >= start && u <= end) {
                return Err(SplineError::ParameterOutsideDomain {
                    axis: a,
                    value: u,
                    start,
                    end,
                });
            }
            t[a] = (u - start) / (end - start);
        }
        Ok(t)
    }

    fn net(&self) -> Net<'_, N> {
        Net {
            coefs: &self.coefs,
            counts: &self.counts,
            dim: self.dim,
            rational: self.rational,
        }
    }

    /// Evaluate at `params` (global parameters inside [`BezierPiece::domain`]) into
    /// `out[..dim]`. No allocation.
    ///
    /// # Errors
    /// [`SplineError::ParameterOutsideDomain`] or [`SplineError::BufferLength`].
    pub fn eval_into(&self, params: [f64; N], out: &mut [f64]) -> Result<(), SplineError> {
        self.net()
            .evaluate(out, None, |vals, ders| self.fill_basis(params, vals, ders))
    }

    /// Value and first partial derivatives with respect to the **global** parameters
    /// (`gradient[a·dim + c] = ∂S_c/∂u_a`). No allocation.
    ///
    /// # Errors
    /// [`SplineError::ParameterOutsideDomain`] or [`SplineError::BufferLength`].
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

    /// Fill the Bernstein values at `params` (and their first derivatives with respect to
    /// the global parameters when `ders` is given) per axis; returns the first control index
    /// (0) and the number of functions per axis.
    fn fill_basis(
        &self,
        params: [f64; N],
        vals: &mut [[f64; BASIS_BUF]; N],
        mut ders: Option<&mut [[f64; BASIS_BUF]; N]>,
    ) -> Result<([usize; N], [usize; N]), SplineError> {
        let t = self.local(params)?;
        for a in 0..N {
            bernstein_unchecked(self.degrees[a], t[a], &mut vals[a]);
            if let Some(d) = ders.as_deref_mut() {
                bernstein_derivative_unchecked(self.degrees[a], 1, t[a], &mut d[a]);
                let scale = 1.0 / (self.domain[a][1] - self.domain[a][0]);
                for x in &mut d[a][..=self.degrees[a]] {
                    *x *= scale;
                }
            }
        }
        Ok(([0; N], self.counts))
    }

    /// Allocating form of [`BezierPiece::eval_into`].
    ///
    /// # Errors
    /// As [`BezierPiece::eval_into`].
    pub fn eval(&self, params: [f64; N]) -> Result<Vec<f64>, SplineError> {
        let mut out = vec![0.0; self.dim];
        self.eval_into(params, &mut out)?;
        Ok(out)
    }

    /// Subdivide the piece along `axis` at the interior parameter `u` (de Casteljau, via knot
    /// insertion): two Bézier pieces of the same degrees covering `[start, u]` and `[u, end]` of
    /// that axis, with the same span label.
    ///
    /// # Errors
    /// [`SplineError::InvalidAxis`], or [`SplineError::KnotOutsideDomain`] unless
    /// `start < u < end`.
    pub fn split(&self, axis: usize, u: f64) -> Result<(Self, Self), SplineError> {
        let (l, r) = self.to_bspline()?.split(axis, u)?;
        let piece = |s: TensorBSpline<N>| Self {
            degrees: self.degrees,
            domain: s.domain(),
            span: self.span,
            dim: self.dim,
            rational: self.rational,
            counts: self.counts,
            coefs: s.homogeneous_coefficients().to_vec(),
        };
        Ok((piece(l), piece(r)))
    }

    /// The same piece as a single-span clamped B-spline on its domain box.
    ///
    /// # Errors
    /// Only if the piece was built with inconsistent data (cannot happen for extracted pieces).
    pub fn to_bspline(&self) -> Result<TensorBSpline<N>, SplineError> {
        let mut knots = Vec::with_capacity(N);
        for a in 0..N {
            knots.push(KnotVector::bezier(self.degrees[a], self.domain[a])?);
        }
        let knots: [KnotVector; N] = knots
            .try_into()
            .map_err(|_| SplineError::InvalidAxis { axis: N, dims: N })?;
        TensorBSpline::from_homogeneous(knots, self.dim, self.rational, self.coefs.clone())
    }
}

impl<const N: usize> TensorBSpline<N> {
    /// The spline refined so that every breakpoint of every axis has multiplicity at least the
    /// degree (Bézier form, see the [module docs](self)); same function.
    ///
    /// # Errors
    /// [`SplineError::TooLarge`] if the refined net would be too large.
    pub fn to_bezier_form(&self) -> Result<Self, SplineError> {
        let mut s = self.clone();
        for axis in 0..N {
            let x = s.knots()[axis].bezier_insertions();
            s = s.refine(axis, &x)?;
        }
        Ok(s)
    }

    /// Split the spline into its Bézier pieces, one per non-empty span box, ordered with the
    /// axis-0 span index fastest. Each piece reproduces the spline exactly on its box.
    ///
    /// # Errors
    /// [`SplineError::TooLarge`] if the pieces would exceed the allocation bound.
    ///
    /// ```
    /// use volmorph_spline::{BSplineSurface, KnotVector};
    /// let ku = KnotVector::clamped_uniform(2, 5, [0.0, 1.0]).unwrap(); // 3 spans
    /// let kv = KnotVector::uniform(1, 3, [0.0, 2.0]).unwrap(); // 2 spans, unclamped
    /// let coefs: Vec<f64> = (0..15).map(|i| f64::from(i).sin()).collect();
    /// let s = BSplineSurface::new([ku, kv], 1, coefs).unwrap();
    /// let pieces = s.bezier_pieces().unwrap();
    /// assert_eq!(pieces.len(), 6);
    /// let p = &pieces[4]; // u span 1, v span 1
    /// assert_eq!(p.span(), [1, 1]);
    /// let [[u0, u1], [v0, v1]] = p.domain();
    /// let (u, v) = (0.5 * (u0 + u1), 0.3 * v0 + 0.7 * v1);
    /// assert!((p.eval([u, v]).unwrap()[0] - s.eval([u, v]).unwrap()[0]).abs() < 1e-12);
    /// ```
    pub fn bezier_pieces(&self) -> Result<Vec<BezierPiece<N>>, SplineError> {
        let refined = self.to_bezier_form()?;
        let degrees = refined.degrees();
        let spans: Vec<Vec<crate::KnotSpan>> = refined
            .knots()
            .iter()
            .map(|k| k.spans().collect())
            .collect();
        let span_counts: [usize; N] = std::array::from_fn(|a| spans[a].len());
        let orders = degrees.map(|p| p + 1);
        let hdim = refined.homogeneous_dim();
        let mut piece_sizes = orders.to_vec();
        piece_sizes.push(hdim);
        let piece_len = checked_count(&piece_sizes)?;
        let num_pieces = checked_count(&span_counts)?;
        checked_count(&[num_pieces, piece_len])?;
        let counts = refined.counts();
        let src = refined.homogeneous_coefficients();
        let mut pieces = Vec::with_capacity(num_pieces);
        let mut cell = [0usize; N];
        for _ in 0..num_pieces {
            let first: [usize; N] = std::array::from_fn(|a| spans[a][cell[a]].index - degrees[a]);
            let domain: [[f64; 2]; N] =
                std::array::from_fn(|a| [spans[a][cell[a]].start, spans[a][cell[a]].end]);
            let mut coefs = Vec::with_capacity(piece_len);
            // Copy the sub-net row by row (axis 0 rows are contiguous).
            let mut idx = [0usize; N];
            loop {
                let mut lin = 0;
                for a in (0..N).rev() {
                    let i = if a == 0 { first[0] } else { first[a] + idx[a] };
                    lin = lin * counts[a] + i;
                }
                coefs.extend_from_slice(&src[lin * hdim..(lin + orders[0]) * hdim]);
                if !next_outer(&mut idx, &orders) {
                    break;
                }
            }
            pieces.push(BezierPiece {
                degrees,
                domain,
                span: cell,
                dim: refined.dim(),
                rational: refined.is_rational(),
                counts: orders,
                coefs,
            });
            for a in 0..N {
                cell[a] += 1;
                if cell[a] < span_counts[a] {
                    break;
                }
                cell[a] = 0;
            }
        }
        Ok(pieces)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BSplineCurve;

    #[test]
    fn uniform_cubic_segment_has_known_bezier_points() {
        // A uniform cubic B-spline segment with control points 0, 0, 6, 0 (scalar) has Bézier
        // points (P0+4P1+P2)/6, (2P1+P2)/3, (P1+2P2)/3, (P1+4P2+P3)/6 = 1, 2, 4, 4.
        let kv = KnotVector::uniform(3, 4, [0.0, 1.0]).unwrap();
        let c = BSplineCurve::new([kv], 1, vec![0.0, 0.0, 6.0, 0.0]).unwrap();
        let p = c.bezier_pieces().unwrap();
        assert_eq!(p.len(), 1);
        let got = p[0].homogeneous_coefficients();
        for (g, e) in got.iter().zip([1.0, 2.0, 4.0, 4.0]) {
            assert!((g - e).abs() < 1e-14, "{got:?}");
        }
        let b = p[0].to_bspline().unwrap();
        assert!((b.eval([0.3]).unwrap()[0] - c.eval([0.3]).unwrap()[0]).abs() < 1e-14);
    }

    #[test]
    fn piece_split_is_de_casteljau() {
        // Quadratic 0, 1, 0 on [0, 1] split at 0.5: left net 0, 1/2, 1/2; right 1/2, 1/2, 0.
        let p = BezierSegment::new([2], [[0.0, 1.0]], [0], 1, false, vec![0.0, 1.0, 0.0]).unwrap();
        let (l, r) = p.split(0, 0.5).unwrap();
        assert_eq!(l.homogeneous_coefficients(), &[0.0, 0.5, 0.5]);
        assert_eq!(r.homogeneous_coefficients(), &[0.5, 0.5, 0.0]);
        assert_eq!((l.domain(), r.domain()), ([[0.0, 0.5]], [[0.5, 1.0]]));
        assert!(p.split(0, 1.0).is_err());
        assert!(p.split(1, 0.5).is_err());
    }

    #[test]
    fn piece_validation() {
        assert!(BezierSegment::new([2], [[0.0, 1.0]], [0], 1, false, vec![0.0; 2]).is_err());
        assert!(BezierSegment::new([2], [[1.0, 1.0]], [0], 1, false, vec![0.0; 3]).is_err());
        assert!(
            BezierSegment::new([1], [[0.0, 1.0]], [0], 1, true, vec![0.0, 1.0, 0.0, 0.0]).is_err()
        );
        let s = BezierSegment::new([1], [[0.0, 2.0]], [0], 1, false, vec![1.0, 3.0]).unwrap();
        assert_eq!(s.eval([1.0]).unwrap(), vec![2.0]);
        assert!(s.eval([2.5]).is_err());
        let (mut v, mut g) = ([0.0], [0.0]);
        s.eval_with_gradient_into([0.5], &mut v, &mut g).unwrap();
        assert!((g[0] - 1.0).abs() < 1e-15);
    }
}
