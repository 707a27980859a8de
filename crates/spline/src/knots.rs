//! Knot vectors bound to a polynomial degree.
//!
//! # Conventions
//!
//! A [`KnotVector`] of degree `p` holds `m + 1` non-decreasing finite knots
//! `u_0 ≤ u_1 ≤ … ≤ u_m` and defines `n = m − p` B-spline basis functions `N_{0,p} … N_{n−1,p}`
//! (one per control point). The **domain** is `[u_p, u_n]`; on it the basis is a partition of
//! unity. Knots are compared exactly (multiplicity is a property of bit-equal values, which every
//! operation in this crate preserves by copying knot values rather than recomputing them).
//!
//! **Spans** use the right-open convention: span `i` is `[u_i, u_{i+1})` and is *non-empty* when
//! `u_i < u_{i+1}`. [`KnotVector::find_span`] returns, for `u` in `[u_p, u_n)`, the unique `i`
//! with `p ≤ i ≤ n − 1`, `u_i ≤ u < u_{i+1}`. The right end `u = u_n` of the domain belongs to the
//! **last non-empty span** (the largest `i ≤ n − 1` with `u_i < u_{i+1}`), so the domain is
//! closed and every spline is evaluated by its last polynomial piece there. Values of `u` outside
//! the domain (and NaN) are rejected with [`SplineError::ParameterOutsideDomain`].
//!
//! Validation (every constructor): degree ≤ [`MAX_DEGREE`], at least `2(p + 1)` knots (so
//! `n ≥ p + 1`), all knots finite and non-decreasing, no multiplicity above `p + 1`, and a
//! non-empty domain `u_p < u_n`.

use crate::SplineError;

/// Largest supported degree in any direction.
///
/// Evaluation keeps its basis values in stack buffers of `MAX_DEGREE + 1` entries so that it never
/// allocates. The accurate B-spline FFD needs degrees up to 12 (composition of a tricubic lattice
/// with bilinear/bicubic patches); 32 leaves ample margin while keeping buffers small.
pub const MAX_DEGREE: usize = 32;

/// A non-empty knot span `[start, end)` of a knot vector's domain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnotSpan {
    /// Index `i` of the span: it is `[u_i, u_{i+1})`, with `p ≤ i ≤ n − 1`.
    pub index: usize,
    /// `u_i`.
    pub start: f64,
    /// `u_{i+1}` (> `start`).
    pub end: f64,
}

/// A validated, degree-bound knot vector (see the [module docs](self) for conventions).
///
/// ```
/// use volmorph_spline::KnotVector;
/// // Clamped cubic with 6 control points on [0, 3]: end knots have multiplicity 4.
/// let kv = KnotVector::clamped_uniform(3, 6, [0.0, 3.0]).unwrap();
/// assert_eq!(kv.knots(), &[0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 3.0, 3.0, 3.0]);
/// assert_eq!(kv.num_basis(), 6);
/// assert_eq!(kv.domain(), [0.0, 3.0]);
/// // Right-open spans; the domain end belongs to the last non-empty span.
/// assert_eq!(kv.find_span(1.0).unwrap(), 4);
/// assert_eq!(kv.find_span(3.0).unwrap(), 5);
/// assert!(kv.find_span(3.0 + 1e-12).is_err());
/// // Greville abscissae of a clamped vector start and end at the domain ends.
/// let g = kv.greville();
/// assert_eq!((g[0], g[5]), (0.0, 3.0));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct KnotVector {
    degree: usize,
    knots: Vec<f64>,
}

impl KnotVector {
    /// Validate an arbitrary knot vector (multiplicities allowed up to `degree + 1`).
    ///
    /// # Errors
    /// [`SplineError::DegreeTooHigh`], [`SplineError::TooFewKnots`],
    /// [`SplineError::NonFiniteKnot`], [`SplineError::DecreasingKnots`],
    /// [`SplineError::MultiplicityTooHigh`] or [`SplineError::EmptyDomain`].
    pub fn new(degree: usize, knots: Vec<f64>) -> Result<Self, SplineError> {
        if degree > MAX_DEGREE {
            return Err(SplineError::DegreeTooHigh {
                degree,
                max: MAX_DEGREE,
            });
        }
        let needed = 2 * (degree + 1);
        if knots.len() < needed {
            return Err(SplineError::TooFewKnots {
                degree,
                len: knots.len(),
                needed,
            });
        }
        for (index, &value) in knots.iter().enumerate() {
            if !value.is_finite() {
                return Err(SplineError::NonFiniteKnot { index, value });
            }
        }
        for (index, w) in knots.windows(2).enumerate() {
            if w[1] < w[0] {
                return Err(SplineError::DecreasingKnots {
                    index: index + 1,
                    previous: w[0],
                    value: w[1],
                });
            }
        }
        for (value, multiplicity) in distinct_of(&knots) {
            if multiplicity > degree + 1 {
                return Err(SplineError::MultiplicityTooHigh {
                    value,
                    multiplicity,
                    max: degree + 1,
                });
            }
        }
        let n = knots.len() - degree - 1;
        let (start, end) = (knots[degree], knots[n]);
        if start >= end {
            return Err(SplineError::EmptyDomain { start, end });
        }
        Ok(Self { degree, knots })
    }

    /// Uniform, unclamped ("periodic-style") knot vector for `num_ctrl` control points whose
    /// domain `[u_p, u_n]` is exactly `domain`: knots `u_i = a + (i − p)·h` with
    /// `h = (b − a)/(num_ctrl − p)`, so `p` knots lie before `a` and `p` after `b`.
    ///
    /// With `p = 3`, `num_ctrl = CSIZE` and `domain = [0, CSIZE − 3]` this is True's lattice
    /// parametrisation (knots at integers, span `[a, a+1)` blended by control points
    /// `a … a+3` with [`crate::uniform_cubic`]).
    ///
    /// # Errors
    /// [`SplineError::TooFewControlPoints`] if `num_ctrl < degree + 1`,
    /// [`SplineError::EmptyDomain`] if `domain` is not finite with `a < b`,
    /// [`SplineError::TooLarge`] for an absurd `num_ctrl`, and the errors of
    /// [`KnotVector::new`].
    pub fn uniform(degree: usize, num_ctrl: usize, domain: [f64; 2]) -> Result<Self, SplineError> {
        check_count_and_domain(degree, num_ctrl, domain)?;
        let [a, b] = domain;
        let p = degree;
        let h = (b - a) / (num_ctrl - p) as f64;
        let m = num_ctrl + p + 1;
        let knots = (0..m)
            .map(|i| {
                if i == p {
                    a
                } else if i == num_ctrl {
                    b
                } else if i > num_ctrl {
                    b + (i - num_ctrl) as f64 * h
                } else {
                    a + (i as f64 - p as f64) * h
                }
            })
            .collect();
        Self::new(degree, knots)
    }

    /// Clamped (open, end-interpolating) knot vector with uniformly spaced interior knots:
    /// `a` and `b` repeated `p + 1` times and `num_ctrl − p − 1` interior knots at
    /// `a + i·(b − a)/(num_ctrl − p)`.
    ///
    /// # Errors
    /// As [`KnotVector::uniform`].
    pub fn clamped_uniform(
        degree: usize,
        num_ctrl: usize,
        domain: [f64; 2],
    ) -> Result<Self, SplineError> {
        check_count_and_domain(degree, num_ctrl, domain)?;
        let [a, b] = domain;
        let segs = num_ctrl - degree;
        let h = (b - a) / segs as f64;
        let interior: Vec<f64> = (1..segs).map(|i| a + i as f64 * h).collect();
        Self::clamped(degree, &interior, domain)
    }

    /// Clamped knot vector with the given interior knots (non-decreasing, strictly inside
    /// `(a, b)`, multiplicities allowed up to `degree + 1`): `a` repeated `p + 1` times, the
    /// interior knots, `b` repeated `p + 1` times. The spline interpolates its first and last
    /// control points.
    ///
    /// # Errors
    /// [`SplineError::DegreeTooHigh`], [`SplineError::EmptyDomain`] for a bad `domain`,
    /// [`SplineError::InteriorKnotOutsideDomain`], and the errors of [`KnotVector::new`].
    pub fn clamped(degree: usize, interior: &[f64], domain: [f64; 2]) -> Result<Self, SplineError> {
        check_degree(degree)?;
        let [a, b] = domain;
        if !(a.is_finite() && b.is_finite() && a < b) {
            return Err(SplineError::EmptyDomain { start: a, end: b });
        }
        if let Some(&value) = interior.iter().find(|&&v| !(v > a && v < b)) {
            return Err(SplineError::InteriorKnotOutsideDomain {
                value,
                start: a,
                end: b,
            });
        }
        let mut knots = Vec::with_capacity(interior.len() + 2 * (degree + 1));
        knots.extend(std::iter::repeat_n(a, degree + 1));
        knots.extend_from_slice(interior);
        knots.extend(std::iter::repeat_n(b, degree + 1));
        Self::new(degree, knots)
    }

    /// The Bézier knot vector of degree `p` on `domain`: `a` and `b` each repeated `p + 1`
    /// times; its basis is the Bernstein basis mapped to `domain`.
    ///
    /// # Errors
    /// As [`KnotVector::clamped`].
    pub fn bezier(degree: usize, domain: [f64; 2]) -> Result<Self, SplineError> {
        Self::clamped(degree, &[], domain)
    }

    /// Polynomial degree `p`.
    #[inline]
    #[must_use]
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Order `k = p + 1` (the convention of Martin & Cohen and de Boor).
    #[inline]
    #[must_use]
    pub fn order(&self) -> usize {
        self.degree + 1
    }

    /// All knots, repeated knots written out.
    #[inline]
    #[must_use]
    pub fn knots(&self) -> &[f64] {
        &self.knots
    }

    /// Number of knots `m + 1`.
    #[inline]
    #[must_use]
    pub fn len(&self) -> usize {
        self.knots.len()
    }

    /// Always `false`: a valid knot vector has at least `2(p + 1)` knots.
    #[inline]
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.knots.is_empty()
    }

    /// Number of basis functions `n = m − p` = number of control points along this axis.
    #[inline]
    #[must_use]
    pub fn num_basis(&self) -> usize {
        self.knots.len() - self.degree - 1
    }

    /// The domain `[u_p, u_n]` (closed; see the module docs for the span convention).
    #[inline]
    #[must_use]
    pub fn domain(&self) -> [f64; 2] {
        [self.knots[self.degree], self.knots[self.num_basis()]]
    }

    /// `true` if `u` lies in the closed domain.
    #[inline]
    #[must_use]
    pub fn contains(&self, u: f64) -> bool {
        let [a, b] = self.domain();
        u >= a && u <= b
    }

    /// `u` clamped into the domain (NaN maps to the domain start).
    #[inline]
    #[must_use]
    pub fn clamp(&self, u: f64) -> f64 {
        let [a, b] = self.domain();
        if u > b {
            b
        } else if u >= a {
            u
        } else {
            a
        }
    }

    /// `true` if the first and last knots have multiplicity `p + 1` (end-interpolating).
    #[must_use]
    pub fn is_clamped(&self) -> bool {
        let p = self.degree;
        let k = &self.knots;
        let last = k.len() - 1;
        k[0] == k[p] && k[last - p] == k[last]
    }

    /// Index of the first non-empty span of the domain.
    #[must_use]
    pub fn first_span(&self) -> usize {
        let mut i = self.degree;
        while self.knots[i] == self.knots[i + 1] {
            i += 1;
        }
        i
    }

    /// Index of the last non-empty span of the domain (the span owning the domain end).
    #[must_use]
    pub fn last_span(&self) -> usize {
        let mut i = self.num_basis() - 1;
        while self.knots[i] == self.knots[i + 1] {
            i -= 1;
        }
        i
    }

    /// The span index `i` with `u_i ≤ u < u_{i+1}` (right-open), `p ≤ i ≤ n − 1`; `u = u_n`
    /// maps to [`KnotVector::last_span`]. O(log m).
    ///
    /// # Errors
    /// [`SplineError::ParameterOutsideDomain`] (with `axis` 0) if `u` is outside the domain or
    /// NaN.
    #[inline]
    pub fn find_span(&self, u: f64) -> Result<usize, SplineError> {
        if self.contains(u) {
            Ok(self.find_span_clamped(u))
        } else {
            let [start, end] = self.domain();
            Err(SplineError::ParameterOutsideDomain {
                axis: 0,
                value: u,
                start,
                end,
            })
        }
    }

    /// Like [`KnotVector::find_span`], with `u` first clamped into the domain (NaN maps to the
    /// first span). Never fails.
    #[inline]
    #[must_use]
    pub fn find_span_clamped(&self, u: f64) -> usize {
        let [a, b] = self.domain();
        if u >= b {
            self.last_span()
        } else if u > a {
            // Largest i with u_i <= u; since u_p = a < u < b = u_n it lies in p..n-1.
            self.knots.partition_point(|&k| k <= u) - 1
        } else {
            self.first_span()
        }
    }

    /// `true` if `span` is a non-empty span of the domain (`p ≤ span ≤ n − 1`,
    /// `u_span < u_{span+1}`).
    #[inline]
    #[must_use]
    pub fn is_valid_span(&self, span: usize) -> bool {
        span >= self.degree && span < self.num_basis() && self.knots[span] < self.knots[span + 1]
    }

    /// Number of knots exactly equal to `u` (0 if `u` is not a knot).
    #[must_use]
    pub fn multiplicity(&self, u: f64) -> usize {
        let lo = self.knots.partition_point(|&k| k < u);
        let hi = self.knots.partition_point(|&k| k <= u);
        hi - lo
    }

    /// Distinct knot values in increasing order with their multiplicities.
    #[must_use]
    pub fn distinct(&self) -> Vec<(f64, usize)> {
        distinct_of(&self.knots).collect()
    }

    /// Distinct knot values inside the closed domain (the breakpoints of the piecewise
    /// polynomial), with their multiplicities in the whole knot vector.
    #[must_use]
    pub fn breakpoints(&self) -> Vec<(f64, usize)> {
        let [a, b] = self.domain();
        distinct_of(&self.knots)
            .filter(|&(v, _)| v >= a && v <= b)
            .collect()
    }

    /// The non-empty spans of the domain, left to right.
    pub fn spans(&self) -> impl Iterator<Item = KnotSpan> + '_ {
        (self.degree..self.num_basis()).filter_map(move |i| {
            let (start, end) = (self.knots[i], self.knots[i + 1]);
            (start < end).then_some(KnotSpan {
                index: i,
                start,
                end,
            })
        })
    }

    /// Number of non-empty spans of the domain (polynomial pieces).
    #[must_use]
    pub fn num_spans(&self) -> usize {
        self.spans().count()
    }

    /// Greville abscissa (nodal value) of basis function `i`:
    /// `ξ_i = (u_{i+1} + … + u_{i+p}) / p` (Martin & Cohen §3 with order `k = p + 1`); for
    /// degree 0 the midpoint `(u_i + u_{i+1})/2`. The result is clamped to
    /// `[u_{i+1}, u_{i+p}]` so that repeated knots give their exact value. Returns `None` if
    /// `i ≥ n`.
    #[must_use]
    pub fn greville_at(&self, i: usize) -> Option<f64> {
        if i >= self.num_basis() {
            return None;
        }
        let p = self.degree;
        if p == 0 {
            return Some(0.5 * (self.knots[i] + self.knots[i + 1]));
        }
        let ks = &self.knots[i + 1..=i + p];
        let mean = ks.iter().sum::<f64>() / p as f64;
        Some(mean.clamp(ks[0], ks[p - 1]))
    }

    /// All Greville abscissae `ξ_0 … ξ_{n−1}` (non-decreasing). For a clamped knot vector they
    /// lie in the domain with `ξ_0 = a`, `ξ_{n−1} = b`; for an unclamped one the first and last
    /// lie outside it.
    #[must_use]
    pub fn greville(&self) -> Vec<f64> {
        (0..self.num_basis())
            .filter_map(|i| self.greville_at(i))
            .collect()
    }

    /// The knot vector affinely mapped so that its domain becomes `domain` exactly
    /// (`u ↦ c + (u − a)·(d − c)/(b − a)`); equal knots stay bit-equal, so multiplicities are
    /// preserved. A spline with rescaled knots and unchanged control values is the same spline
    /// reparametrised.
    ///
    /// # Errors
    /// [`SplineError::EmptyDomain`] unless `domain` is finite with `c < d`; the errors of
    /// [`KnotVector::new`] if the mapped knots overflow.
    ///
    /// ```
    /// use volmorph_spline::KnotVector;
    /// let kv = KnotVector::uniform(3, 9, [0.0, 6.0]).unwrap();
    /// let unit = kv.rescaled([0.0, 1.0]).unwrap();
    /// assert_eq!(unit.domain(), [0.0, 1.0]);
    /// assert_eq!(unit.knots()[0], -0.5);
    /// ```
    pub fn rescaled(&self, domain: [f64; 2]) -> Result<Self, SplineError> {
        let [c, d] = domain;
        if !(c.is_finite() && d.is_finite() && c < d) {
            return Err(SplineError::EmptyDomain { start: c, end: d });
        }
        let [a, b] = self.domain();
        let scale = (d - c) / (b - a);
        let knots = self
            .knots
            .iter()
            .map(|&u| {
                if u == a {
                    c
                } else if u == b {
                    d
                } else {
                    c + (u - a) * scale
                }
            })
            .collect();
        Self::new(self.degree, knots)
    }

    /// The knot vector obtained by merging the sorted knots `new_knots` into this one
    /// (the knot vector of [`crate::TensorBSpline::refine`]).
    ///
    /// # Errors
    /// [`SplineError::KnotOutsideDomain`] if a knot is outside the domain or NaN;
    /// [`SplineError::MultiplicityTooHigh`] if a multiplicity would exceed `p + 1`.
    pub fn refined(&self, new_knots: &[f64]) -> Result<Self, SplineError> {
        let sorted = self.sorted_insertions(new_knots)?;
        let mut merged = Vec::with_capacity(self.knots.len() + sorted.len());
        let (mut i, mut j) = (0, 0);
        while i < self.knots.len() || j < sorted.len() {
            if j >= sorted.len() || (i < self.knots.len() && self.knots[i] <= sorted[j]) {
                merged.push(self.knots[i]);
                i += 1;
            } else {
                merged.push(sorted[j]);
                j += 1;
            }
        }
        Self::new(self.degree, merged)
    }

    /// Check that every knot to insert lies in the domain and return them sorted.
    pub(crate) fn sorted_insertions(&self, new_knots: &[f64]) -> Result<Vec<f64>, SplineError> {
        let [start, end] = self.domain();
        if let Some(&value) = new_knots.iter().find(|&&v| !self.contains(v)) {
            return Err(SplineError::KnotOutsideDomain { value, start, end });
        }
        let mut sorted = new_knots.to_vec();
        sorted.sort_by(f64::total_cmp);
        Ok(sorted)
    }

    /// The knots to insert so that every breakpoint of the domain (ends included) has
    /// multiplicity at least `p`: after this refinement each non-empty span carries exactly the
    /// Bézier control points of its polynomial piece.
    #[must_use]
    pub fn bezier_insertions(&self) -> Vec<f64> {
        let p = self.degree;
        let mut out = Vec::new();
        for (v, m) in self.breakpoints() {
            if m < p {
                out.extend(std::iter::repeat_n(v, p - m));
            }
        }
        out
    }
}

fn check_degree(degree: usize) -> Result<(), SplineError> {
    if degree > MAX_DEGREE {
        Err(SplineError::DegreeTooHigh {
            degree,
            max: MAX_DEGREE,
        })
    } else {
        Ok(())
    }
}

fn check_count_and_domain(
    degree: usize,
    num_ctrl: usize,
    domain: [f64; 2],
) -> Result<(), SplineError> {
    check_degree(degree)?;
    // The knot vector holds num_ctrl + degree + 1 values.
    num_ctrl
        .checked_add(degree + 1)
        .ok_or_else(|| SplineError::TooLarge(format!("{num_ctrl} control points")))
        .and_then(|m| crate::spline::checked_count(&[m]))?;
    if num_ctrl < degree + 1 {
        return Err(SplineError::TooFewControlPoints {
            degree,
            count: num_ctrl,
            needed: degree + 1,
        });
    }
    let [a, b] = domain;
    if !(a.is_finite() && b.is_finite() && a < b) {
        return Err(SplineError::EmptyDomain { start: a, end: b });
    }
    Ok(())
}

/// Distinct values of a sorted slice with their run lengths.
fn distinct_of(knots: &[f64]) -> impl Iterator<Item = (f64, usize)> + '_ {
    let mut i = 0;
    std::iter::from_fn(move || {
        let &v = knots.get(i)?;
        let start = i;
        while i < knots.len() && knots[i] == v {
            i += 1;
        }
        Some((v, i - start))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_problem() {
        assert!(matches!(
            KnotVector::new(2, vec![0.0, 0.0, 0.0, 1.0, 1.0]),
            Err(SplineError::TooFewKnots { needed: 6, .. })
        ));
        assert!(matches!(
            KnotVector::new(1, vec![0.0, 0.0, f64::NAN, 1.0]),
            Err(SplineError::NonFiniteKnot { index: 2, .. })
        ));
        assert!(matches!(
            KnotVector::new(1, vec![0.0, 1.0, 0.5, 2.0]),
            Err(SplineError::DecreasingKnots { index: 2, .. })
        ));
        assert!(matches!(
            KnotVector::new(1, vec![0.0, 0.0, 0.0, 1.0, 1.0]),
            Err(SplineError::MultiplicityTooHigh {
                multiplicity: 3,
                ..
            })
        ));
        assert!(matches!(
            KnotVector::new(1, vec![0.0, 1.0, 1.0, 2.0]),
            Err(SplineError::EmptyDomain { .. })
        ));
        assert!(matches!(
            KnotVector::new(MAX_DEGREE + 1, vec![0.0; 100]),
            Err(SplineError::DegreeTooHigh { .. })
        ));
        assert!(KnotVector::uniform(3, 3, [0.0, 1.0]).is_err());
        assert!(matches!(
            KnotVector::uniform(3, usize::MAX, [0.0, 1.0]),
            Err(SplineError::TooLarge(_))
        ));
        assert!(matches!(
            KnotVector::clamped_uniform(usize::MAX, 4, [0.0, 1.0]),
            Err(SplineError::DegreeTooHigh { .. })
        ));
        assert!(KnotVector::clamped(usize::MAX, &[], [0.0, 1.0]).is_err());
        assert!(KnotVector::clamped(2, &[1.5], [0.0, 1.0]).is_err());
        assert!(KnotVector::clamped(2, &[0.5], [1.0, 1.0]).is_err());
    }

    #[test]
    fn uniform_matches_true_lattice() {
        // CSIZE = 9, domain [0, CSIZE - 3] = [0, 6]: knots at the integers -3 .. 9.
        let kv = KnotVector::uniform(3, 9, [0.0, 6.0]).unwrap();
        let expect: Vec<f64> = (-3..=9).map(f64::from).collect();
        assert_eq!(kv.knots(), expect.as_slice());
        assert_eq!(kv.domain(), [0.0, 6.0]);
        assert!(!kv.is_clamped());
        // s in [a, a+1) is span a + 3.
        for a in 0..6 {
            assert_eq!(kv.find_span(f64::from(a) + 0.5).unwrap(), a as usize + 3);
            assert_eq!(kv.find_span(f64::from(a)).unwrap(), a as usize + 3);
        }
        assert_eq!(kv.find_span(6.0).unwrap(), 8);
        assert_eq!(kv.num_spans(), 6);
    }

    #[test]
    fn spans_with_multiplicities() {
        let kv = KnotVector::new(2, vec![0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 3.0, 3.0, 3.0]).unwrap();
        assert_eq!(kv.num_basis(), 6);
        assert_eq!(kv.multiplicity(1.0), 2);
        assert_eq!(kv.multiplicity(0.5), 0);
        assert_eq!(kv.distinct(), vec![(0.0, 3), (1.0, 2), (2.0, 1), (3.0, 3)]);
        let spans: Vec<usize> = kv.spans().map(|s| s.index).collect();
        assert_eq!(spans, vec![2, 4, 5]);
        assert_eq!(kv.find_span(0.0).unwrap(), 2);
        assert_eq!(kv.find_span(1.0).unwrap(), 4);
        assert_eq!(kv.find_span(0.999).unwrap(), 2);
        assert_eq!(kv.find_span(3.0).unwrap(), 5);
        assert_eq!(kv.find_span_clamped(-7.0), 2);
        assert_eq!(kv.find_span_clamped(f64::NAN), 2);
        assert_eq!(kv.find_span_clamped(9.0), 5);
        assert!(kv.find_span(f64::NAN).is_err());
        assert!(kv.find_span(-1e-300).is_err());
        // Greville: averages of pairs.
        assert_eq!(kv.greville(), vec![0.0, 0.5, 1.0, 1.5, 2.5, 3.0]);
        assert_eq!(kv.bezier_insertions(), vec![2.0]);
    }

    #[test]
    fn empty_domain_end_spans_are_skipped() {
        // Degree 1, knots with an empty last domain span: u_2 = u_3 = 2 (n = 3).
        let kv = KnotVector::new(1, vec![0.0, 0.0, 1.0, 2.0, 2.0]).unwrap();
        assert_eq!(kv.domain(), [0.0, 2.0]);
        assert_eq!(kv.last_span(), 2);
        assert_eq!(kv.find_span(2.0).unwrap(), 2);
    }

    #[test]
    fn refined_merges_and_checks() {
        let kv = KnotVector::clamped_uniform(2, 4, [0.0, 2.0]).unwrap();
        let r = kv.refined(&[1.5, 0.5, 1.0]).unwrap();
        assert_eq!(
            r.knots(),
            &[0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.5, 2.0, 2.0, 2.0]
        );
        assert!(kv.refined(&[2.5]).is_err());
        assert!(kv.refined(&[1.0, 1.0]).is_ok());
        assert!(kv.refined(&[1.0, 1.0, 1.0]).is_err());
        assert!(kv.refined(&[0.0]).is_err());
    }

    #[test]
    fn greville_is_exact_at_clamped_ends() {
        let kv = KnotVector::clamped_uniform(3, 7, [0.1, 0.7]).unwrap();
        let g = kv.greville();
        assert_eq!(g[0], 0.1);
        assert_eq!(g[6], 0.7);
        assert!(g.windows(2).all(|w| w[0] < w[1]));
    }
}
