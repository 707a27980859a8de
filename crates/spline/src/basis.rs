//! B-spline basis functions and their derivatives (The NURBS Book, algorithms A2.2 and A2.3),
//! and the uniform cubic basis of True's lattice warps.
//!
//! At a span `i` (from [`KnotVector::find_span`]) exactly `p + 1` basis functions can be
//! non-zero: `N_{i−p,p} … N_{i,p}`. All functions here return them in that order, entry `j`
//! being `N_{i−p+j,p}`. The `_into` variants write into caller buffers and never allocate;
//! [`BasisWorkspace`] holds the scratch tables of the higher-derivative algorithm so a caller
//! evaluating many points allocates once.

use crate::{KnotVector, MAX_DEGREE, SplineError};

/// Buffer length for per-axis basis values: `MAX_DEGREE + 1`.
pub(crate) const BASIS_BUF: usize = MAX_DEGREE + 1;

fn check_span(kv: &KnotVector, span: usize) -> Result<(), SplineError> {
    if kv.is_valid_span(span) {
        Ok(())
    } else {
        Err(SplineError::InvalidSpan { span })
    }
}

fn check_len(got: usize, expected: usize) -> Result<(), SplineError> {
    if got < expected {
        Err(SplineError::BufferLength { expected, got })
    } else {
        Ok(())
    }
}

/// The `p + 1` non-zero basis functions at `u` in span `span`, written to `out[..p+1]`
/// (`out[j] = N_{span−p+j,p}(u)`). A2.2 (triangular Cox–de Boor), O(p²), no allocation.
///
/// `u` should lie in the span's closed interval `[u_span, u_{span+1}]`; outside it the values
/// are those of the span's polynomial pieces extended (no check is made, so callers can
/// extrapolate deliberately).
///
/// # Errors
/// [`SplineError::InvalidSpan`] if `span` is not a non-empty domain span,
/// [`SplineError::BufferLength`] if `out` is shorter than `p + 1`.
///
/// ```
/// use volmorph_spline::{KnotVector, basis_funs_into};
/// let kv = KnotVector::new(2, vec![0., 0., 0., 1., 2., 3., 3., 3.]).unwrap();
/// let mut n = [0.0; 3];
/// let span = kv.find_span(1.5).unwrap();
/// basis_funs_into(&kv, span, 1.5, &mut n).unwrap();
/// assert!((n.iter().sum::<f64>() - 1.0).abs() < 1e-15); // partition of unity
/// for (got, want) in n.iter().zip([0.125, 0.75, 0.125]) {
///     assert!((got - want).abs() < 1e-15);
/// }
/// ```
pub fn basis_funs_into(
    kv: &KnotVector,
    span: usize,
    u: f64,
    out: &mut [f64],
) -> Result<(), SplineError> {
    check_span(kv, span)?;
    check_len(out.len(), kv.degree() + 1)?;
    basis_unchecked(kv.knots(), kv.degree(), span, u, out);
    Ok(())
}

/// Allocating convenience form of [`basis_funs_into`].
///
/// # Errors
/// As [`basis_funs_into`].
pub fn basis_funs(kv: &KnotVector, span: usize, u: f64) -> Result<Vec<f64>, SplineError> {
    let mut out = vec![0.0; kv.degree() + 1];
    basis_funs_into(kv, span, u, &mut out)?;
    Ok(out)
}

/// The non-zero basis functions and their first derivatives at `u` in `span`:
/// `vals[j] = N_{span−p+j,p}(u)`, `ders[j] = N'_{span−p+j,p}(u)`. Uses
/// `N'_{j,p} = p·(N_{j,p−1}/(u_{j+p} − u_j) − N_{j+1,p−1}/(u_{j+p+1} − u_{j+1}))`; no allocation.
///
/// # Errors
/// As [`basis_funs_into`] (both buffers need `p + 1` entries).
pub fn basis_funs_and_derivs_into(
    kv: &KnotVector,
    span: usize,
    u: f64,
    vals: &mut [f64],
    ders: &mut [f64],
) -> Result<(), SplineError> {
    check_span(kv, span)?;
    check_len(vals.len(), kv.degree() + 1)?;
    check_len(ders.len(), kv.degree() + 1)?;
    basis_and_first_unchecked(kv.knots(), kv.degree(), span, u, vals, ders);
    Ok(())
}

/// A2.2 without checks: `span` must be a non-empty span with `p ≤ span`, `span + p < len`, and
/// `out.len() ≥ p + 1`.
#[inline]
pub(crate) fn basis_unchecked(knots: &[f64], p: usize, span: usize, u: f64, out: &mut [f64]) {
    basis_in_span::<BASIS_BUF>(knots, p, span, u, out);
}

/// The `p + 1` B-spline basis functions of degree `p` that are non-zero on knot span `span`
/// (`[knots[span], knots[span + 1])`), at `u`, into `out[..=p]` (Cox–de Boor, The NURBS
/// Book A2.2), with scratch arrays of `L` entries on the stack — a small `L` for low degrees
/// keeps hot per-point kernels lean.
///
/// Unchecked variant of [`basis_funs_into`] for callers that found `span` themselves on a
/// validated knot vector: `span` must satisfy `p ≤ span` and `span + p < knots.len()`.
///
/// # Panics
/// If `p ≥ L`, `out.len() ≤ p`, or `span` violates the bounds above.
#[inline]
pub fn basis_in_span<const L: usize>(
    knots: &[f64],
    p: usize,
    span: usize,
    u: f64,
    out: &mut [f64],
) {
    let mut left = [0.0; L];
    let mut right = [0.0; L];
    out[0] = 1.0;
    for j in 1..=p {
        left[j] = u - knots[span + 1 - j];
        right[j] = knots[span + j] - u;
        let mut saved = 0.0;
        for r in 0..j {
            let temp = out[r] / (right[r + 1] + left[j - r]);
            out[r] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        out[j] = saved;
    }
}

/// Values and first derivatives without checks (same preconditions as [`basis_unchecked`]).
#[inline]
pub(crate) fn basis_and_first_unchecked(
    knots: &[f64],
    p: usize,
    span: usize,
    u: f64,
    vals: &mut [f64],
    ders: &mut [f64],
) {
    if p == 0 {
        vals[0] = 1.0;
        ders[0] = 0.0;
        return;
    }
    // Degree p-1 functions N_{span-p+1+r, p-1}, r = 0..p-1, then one more A2.2 step.
    let mut lower = [0.0; BASIS_BUF];
    basis_unchecked(knots, p - 1, span, u, &mut lower);
    vals[..p].copy_from_slice(&lower[..p]);
    {
        let j = p;
        let mut saved = 0.0;
        for r in 0..j {
            let right = knots[span + r + 1] - u;
            let left = u - knots[span + 1 + r - j];
            let temp = vals[r] / (right + left);
            vals[r] = saved + right * temp;
            saved = left * temp;
        }
        vals[j] = saved;
    }
    let pf = p as f64;
    for k in 0..=p {
        let j = span - p + k; // global index of the function
        let mut d = 0.0;
        if k >= 1 {
            d += lower[k - 1] / (knots[j + p] - knots[j]);
        }
        if k < p {
            d -= lower[k] / (knots[j + p + 1] - knots[j + 1]);
        }
        ders[k] = pf * d;
    }
}

/// Scratch tables for [`BasisWorkspace::derivs_into`] (A2.3), sized for one degree.
///
/// ```
/// use volmorph_spline::{BasisWorkspace, KnotVector};
/// let kv = KnotVector::clamped_uniform(3, 5, [0.0, 1.0]).unwrap();
/// let mut ws = BasisWorkspace::new(3);
/// let mut d = vec![0.0; 4 * 4]; // orders 0..=3, 4 functions each
/// let span = kv.find_span(0.3).unwrap();
/// ws.derivs_into(&kv, span, 0.3, 3, &mut d).unwrap();
/// // Derivatives of a partition of unity sum to zero.
/// for k in 1..=3 {
///     assert!(d[k * 4..(k + 1) * 4].iter().sum::<f64>().abs() < 1e-12);
/// }
/// ```
#[derive(Debug, Clone)]
pub struct BasisWorkspace {
    degree: usize,
    ndu: Vec<f64>,
    a: Vec<f64>,
}

impl BasisWorkspace {
    /// Workspace for knot vectors of degree `degree` (allocates `(p+1)² + 2(p+1)` values;
    /// `degree` is capped at [`MAX_DEGREE`], the largest degree a [`KnotVector`] can have).
    #[must_use]
    pub fn new(degree: usize) -> Self {
        let degree = degree.min(MAX_DEGREE);
        let w = degree + 1;
        Self {
            degree,
            ndu: vec![0.0; w * w],
            a: vec![0.0; 2 * w],
        }
    }

    /// Degree this workspace was sized for (it is resized on demand for other degrees).
    #[must_use]
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Basis functions and derivatives up to order `order` at `u` in `span` (A2.3).
    ///
    /// `out[k·(p+1) + j]` = k-th derivative of `N_{span−p+j,p}` at `u`, for `k = 0..=order`;
    /// orders above `p` are zero. `out` needs `(order + 1)·(p + 1)` entries. No allocation when
    /// the workspace already has this degree.
    ///
    /// # Errors
    /// [`SplineError::InvalidSpan`], [`SplineError::BufferLength`], or
    /// [`SplineError::TooLarge`] if `(order + 1)·(p + 1)` overflows.
    pub fn derivs_into(
        &mut self,
        kv: &KnotVector,
        span: usize,
        u: f64,
        order: usize,
        out: &mut [f64],
    ) -> Result<(), SplineError> {
        check_span(kv, span)?;
        let p = kv.degree();
        let w = p + 1;
        let needed = order
            .checked_add(1)
            .and_then(|o| o.checked_mul(w))
            .ok_or_else(|| SplineError::TooLarge(format!("derivative order {order}")))?;
        check_len(out.len(), needed)?;
        if p != self.degree {
            *self = Self::new(p);
        }
        let knots = kv.knots();
        let ndu = &mut self.ndu;
        let idx = |r: usize, c: usize| r * w + c;
        let mut left = [0.0; BASIS_BUF];
        let mut right = [0.0; BASIS_BUF];
        ndu[0] = 1.0;
        for j in 1..=p {
            left[j] = u - knots[span + 1 - j];
            right[j] = knots[span + j] - u;
            let mut saved = 0.0;
            for r in 0..j {
                // Lower triangle: knot differences; upper: basis values.
                ndu[idx(j, r)] = right[r + 1] + left[j - r];
                let temp = ndu[idx(r, j - 1)] / ndu[idx(j, r)];
                ndu[idx(r, j)] = saved + right[r + 1] * temp;
                saved = left[j - r] * temp;
            }
            ndu[idx(j, j)] = saved;
        }
        out[..(order + 1) * w].fill(0.0);
        for j in 0..=p {
            out[j] = ndu[idx(j, p)];
        }
        let n = order.min(p);
        let a = &mut self.a;
        for r in 0..=p {
            let (mut s1, mut s2) = (0usize, 1usize);
            a[0] = 1.0;
            for k in 1..=n {
                let mut d = 0.0;
                let rk = r as isize - k as isize;
                let pk = p - k;
                if r >= k {
                    let rk = rk as usize;
                    a[s2 * w] = a[s1 * w] / ndu[idx(pk + 1, rk)];
                    d = a[s2 * w] * ndu[idx(rk, pk)];
                }
                let j1: usize = if rk >= -1 { 1 } else { (-rk) as usize };
                let j2: usize = if r as isize - 1 <= pk as isize {
                    k - 1
                } else {
                    p - r
                };
                for j in j1..=j2 {
                    let c = (rk + j as isize) as usize;
                    a[s2 * w + j] = (a[s1 * w + j] - a[s1 * w + j - 1]) / ndu[idx(pk + 1, c)];
                    d += a[s2 * w + j] * ndu[idx(c, pk)];
                }
                if r <= pk {
                    a[s2 * w + k] = -a[s1 * w + k - 1] / ndu[idx(pk + 1, r)];
                    d += a[s2 * w + k] * ndu[idx(r, pk)];
                }
                out[k * w + r] = d;
                std::mem::swap(&mut s1, &mut s2);
            }
        }
        let mut fac = p as f64;
        for k in 1..=n {
            for v in &mut out[k * w..(k + 1) * w] {
                *v *= fac;
            }
            fac *= (p - k) as f64;
        }
        Ok(())
    }
}

/// Allocating convenience form of [`BasisWorkspace::derivs_into`]: flat
/// `(order + 1) × (p + 1)` table, row `k` = k-th derivatives.
///
/// # Errors
/// As [`BasisWorkspace::derivs_into`], plus [`SplineError::TooLarge`] for an absurd `order`.
pub fn basis_derivs(
    kv: &KnotVector,
    span: usize,
    u: f64,
    order: usize,
) -> Result<Vec<f64>, SplineError> {
    let len = order
        .checked_add(1)
        .ok_or_else(|| SplineError::TooLarge(format!("derivative order {order}")))
        .and_then(|o| crate::spline::checked_count(&[o, kv.degree() + 1]))?;
    let mut out = vec![0.0; len];
    BasisWorkspace::new(kv.degree()).derivs_into(kv, span, u, order, &mut out)?;
    Ok(out)
}

/// True's uniform cubic B-spline basis (True 1992, §5.2) at local parameter `t ∈ [0, 1]`:
///
/// `B0 = (1−t)³/6`, `B1 = (3t³ − 6t² + 4)/6`, `B2 = (−3t³ + 3t² + 3t + 1)/6`, `B3 = t³/6`.
///
/// On the integer knot vector of [`KnotVector::uniform`] (degree 3), a parameter `s` in region
/// `[a, a+1)` is blended by control points `a … a+3` with weights `uniform_cubic(s − a)`.
///
/// ```
/// use volmorph_spline::uniform_cubic;
/// let b = uniform_cubic(0.0);
/// assert_eq!(b, [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0, 0.0]);
/// let s: f64 = uniform_cubic(0.37).iter().sum();
/// assert!((s - 1.0).abs() < 1e-15);
/// ```
#[inline]
#[must_use]
pub fn uniform_cubic(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    let s = 1.0 - t;
    const SIXTH: f64 = 1.0 / 6.0;
    [
        s * s * s * SIXTH,
        (3.0 * t3 - 6.0 * t2 + 4.0) * SIXTH,
        (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) * SIXTH,
        t3 * SIXTH,
    ]
}

/// First derivatives `dB_i/dt` of [`uniform_cubic`]:
/// `−(1−t)²/2`, `(3t² − 4t)/2`, `(−3t² + 2t + 1)/2`, `t²/2`.
#[inline]
#[must_use]
pub fn uniform_cubic_derivative(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    let t2 = t * t;
    [
        -0.5 * s * s,
        0.5 * (3.0 * t2 - 4.0 * t),
        0.5 * (-3.0 * t2 + 2.0 * t + 1.0),
        0.5 * t2,
    ]
}

/// Second derivatives `d²B_i/dt²` of [`uniform_cubic`]: `1−t`, `3t − 2`, `1 − 3t`, `t`.
#[inline]
#[must_use]
pub fn uniform_cubic_second_derivative(t: f64) -> [f64; 4] {
    [1.0 - t, 3.0 * t - 2.0, 1.0 - 3.0 * t, t]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Cox–de Boor recursion for one basis function (reference, right-open with the domain-end
    /// rule handled by the caller choosing interior points).
    fn cox_de_boor(knots: &[f64], i: usize, p: usize, u: f64) -> f64 {
        if p == 0 {
            return if knots[i] <= u && u < knots[i + 1] {
                1.0
            } else {
                0.0
            };
        }
        let mut v = 0.0;
        let d1 = knots[i + p] - knots[i];
        if d1 > 0.0 {
            v += (u - knots[i]) / d1 * cox_de_boor(knots, i, p - 1, u);
        }
        let d2 = knots[i + p + 1] - knots[i + 1];
        if d2 > 0.0 {
            v += (knots[i + p + 1] - u) / d2 * cox_de_boor(knots, i + 1, p - 1, u);
        }
        v
    }

    #[test]
    fn a22_matches_cox_de_boor() {
        let kv = KnotVector::new(
            3,
            vec![0.0, 0.0, 0.0, 0.0, 0.7, 1.0, 1.0, 2.5, 3.0, 3.0, 3.0, 3.0],
        )
        .unwrap();
        let mut n = [0.0; 4];
        for &u in &[0.0, 0.3, 0.7, 0.99, 1.0, 1.7, 2.9] {
            let span = kv.find_span(u).unwrap();
            basis_funs_into(&kv, span, u, &mut n).unwrap();
            for j in 0..kv.num_basis() {
                let expect = cox_de_boor(kv.knots(), j, 3, u);
                let got = if j + 3 >= span && j <= span {
                    n[j + 3 - span]
                } else {
                    0.0
                };
                assert!((expect - got).abs() < 1e-14, "u={u} j={j}");
            }
        }
    }

    #[test]
    fn first_derivatives_agree_with_a23() {
        let kv = KnotVector::new(
            4,
            vec![0., 0., 0., 0., 0., 0.5, 0.5, 1.2, 2., 3., 3., 3., 3., 3.],
        )
        .unwrap();
        let mut ws = BasisWorkspace::new(4);
        let mut table = vec![0.0; 5 * 6];
        let (mut v, mut d) = ([0.0; 5], [0.0; 5]);
        for &u in &[0.0, 0.1, 0.5, 0.8, 1.9, 3.0] {
            let span = kv.find_span(u).unwrap();
            ws.derivs_into(&kv, span, u, 5, &mut table).unwrap();
            basis_funs_and_derivs_into(&kv, span, u, &mut v, &mut d).unwrap();
            for j in 0..5 {
                assert!((table[j] - v[j]).abs() < 1e-13);
                assert!((table[5 + j] - d[j]).abs() < 1e-11, "u={u} j={j}");
            }
            // Order 5 > p is zero.
            assert!(table[25..30].iter().all(|&x| x == 0.0));
        }
    }

    #[test]
    fn a23_matches_finite_differences() {
        let kv = KnotVector::new(3, vec![0., 0., 0., 0., 0.4, 1.0, 1.6, 2., 2., 2., 2.]).unwrap();
        let u = 1.3;
        let span = kv.find_span(u).unwrap();
        let d = basis_derivs(&kv, span, u, 2).unwrap();
        let h = 1e-5;
        let f = |x: f64| basis_funs(&kv, span, x).unwrap();
        let (fp, fm, f0) = (f(u + h), f(u - h), f(u));
        for j in 0..4 {
            let d1 = (fp[j] - fm[j]) / (2.0 * h);
            let d2 = (fp[j] - 2.0 * f0[j] + fm[j]) / (h * h);
            assert!((d[4 + j] - d1).abs() < 1e-8);
            assert!((d[8 + j] - d2).abs() < 1e-4);
        }
    }

    #[test]
    fn uniform_cubic_matches_true_formulas_and_general_basis() {
        let kv = KnotVector::uniform(3, 9, [0.0, 6.0]).unwrap();
        let mut n = [0.0; 4];
        let (mut v, mut d) = ([0.0; 4], [0.0; 4]);
        let mut ws = BasisWorkspace::new(3);
        let mut table = [0.0; 12];
        for step in 0..=60 {
            let s = f64::from(step) * 0.1;
            let a = (s.floor() as usize).min(5);
            let t = s - a as f64;
            let b = uniform_cubic(t);
            // True's formulas, literally.
            let true_b = [
                (1.0 - t).powi(3) / 6.0,
                (3.0 * t.powi(3) - 6.0 * t * t + 4.0) / 6.0,
                (-3.0 * t.powi(3) + 3.0 * t * t + 3.0 * t + 1.0) / 6.0,
                t.powi(3) / 6.0,
            ];
            let span = kv.find_span(s).unwrap();
            assert_eq!(span, a + 3);
            basis_funs_into(&kv, span, s, &mut n).unwrap();
            basis_funs_and_derivs_into(&kv, span, s, &mut v, &mut d).unwrap();
            ws.derivs_into(&kv, span, s, 2, &mut table).unwrap();
            let db = uniform_cubic_derivative(t);
            let ddb = uniform_cubic_second_derivative(t);
            for i in 0..4 {
                assert!((b[i] - true_b[i]).abs() < 1e-15);
                assert!((b[i] - n[i]).abs() < 1e-14);
                assert!((db[i] - d[i]).abs() < 1e-13);
                assert!((ddb[i] - table[8 + i]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn bad_span_and_short_buffers_are_errors() {
        let kv = KnotVector::clamped_uniform(2, 4, [0.0, 1.0]).unwrap();
        let mut n = [0.0; 3];
        assert!(basis_funs_into(&kv, 0, 0.5, &mut n).is_err());
        assert!(basis_funs_into(&kv, 4, 0.5, &mut n).is_err());
        assert!(basis_funs_into(&kv, 2, 0.5, &mut n[..2]).is_err());
        let mut ws = BasisWorkspace::new(1);
        let mut t = [0.0; 6];
        assert!(ws.derivs_into(&kv, 2, 0.2, 2, &mut t).is_err());
        ws.derivs_into(&kv, 2, 0.2, 1, &mut t).unwrap();
        assert_eq!(ws.degree(), 2);
    }
}
