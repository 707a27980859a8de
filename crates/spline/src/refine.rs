//! Knot insertion (Boehm) and knot refinement (The NURBS Book A5.4), per parametric axis.
//!
//! Refinement inserts a whole sorted set of knots `X` along one axis in a single backward sweep
//! (A5.4): control points not affected are copied, the affected ones are produced by the
//! convex blends of Boehm's single-knot insertion applied right to left. Every step is linear in
//! the homogeneous coefficients, so rational splines are refined exactly in `P^w` space. Along
//! axis `a` of a tensor product the control net is viewed as `outer × len × inner` blocks
//! (axis 0 fastest, see [`crate::spline`]); each step combines two whole `inner`-length
//! contiguous rows, so the sweep runs once per outer block (blocks in parallel with rayon) and
//! its inner loops vectorize.
//!
//! Inserted knots must lie in the closed domain and no multiplicity may exceed `p + 1`.
//! Insertion never changes the spline (the geometry and every attribute are identical as
//! functions of the parameters), which the tests check to 1e-12.

use rayon::prelude::*;

use crate::{KnotVector, SplineError, TensorBSpline};

impl<const N: usize> TensorBSpline<N> {
    /// Insert all knots of `new_knots` (any order, repeats allowed) along `axis`, returning the
    /// refined spline; the result represents exactly the same function.
    ///
    /// # Errors
    /// [`SplineError::InvalidAxis`], [`SplineError::KnotOutsideDomain`],
    /// [`SplineError::MultiplicityTooHigh`] (a multiplicity above `p + 1`) or
    /// [`SplineError::TooLarge`].
    ///
    /// ```
    /// use volmorph_spline::{BSplineCurve, KnotVector};
    /// let kv = KnotVector::clamped_uniform(3, 5, [0.0, 1.0]).unwrap();
    /// let c = BSplineCurve::new([kv], 1, vec![0.0, 2.0, -1.0, 3.0, 1.0]).unwrap();
    /// let r = c.refine(0, &[0.1, 0.5, 0.5, 0.9]).unwrap();
    /// assert_eq!(r.counts(), [9]);
    /// for i in 0..=20 {
    ///     let u = f64::from(i) / 20.0;
    ///     assert!((c.eval([u]).unwrap()[0] - r.eval([u]).unwrap()[0]).abs() < 1e-12);
    /// }
    /// ```
    pub fn refine(&self, axis: usize, new_knots: &[f64]) -> Result<Self, SplineError> {
        Self::check_axis(axis)?;
        if new_knots.is_empty() {
            return Ok(self.clone());
        }
        let kv = &self.knots()[axis];
        let x = kv.sorted_insertions(new_knots)?;
        let refined = kv.refined(&x)?;
        let (outer, len, inner) = self.axis_blocks(axis);
        let new_len = len + x.len();
        let total = crate::spline::checked_count(&[outer, new_len, inner])?;
        let mut out = vec![0.0; total];
        let src = self.homogeneous_coefficients();
        debug_assert_eq!(src.len(), outer * len * inner);
        out.par_chunks_mut(new_len * inner)
            .zip(src.par_chunks(len * inner))
            .for_each(|(dst, blk)| refine_block(kv, refined.knots(), &x, blk, dst, inner));
        Ok(self.with_axis(axis, refined, out))
    }

    /// Insert the knot `u` `times` times along `axis` (Boehm insertion; `times = 0` returns a
    /// copy).
    ///
    /// # Errors
    /// As [`TensorBSpline::refine`].
    pub fn insert_knot(&self, axis: usize, u: f64, times: usize) -> Result<Self, SplineError> {
        Self::check_axis(axis)?;
        let p = self.knots()[axis].degree();
        if times > p + 1 {
            return Err(SplineError::MultiplicityTooHigh {
                value: u,
                multiplicity: times,
                max: p + 1,
            });
        }
        self.refine(axis, &vec![u; times])
    }

    /// Refine every axis: `new_knots[a]` is inserted along axis `a`.
    ///
    /// # Errors
    /// As [`TensorBSpline::refine`].
    pub fn refine_all(&self, new_knots: [&[f64]; N]) -> Result<Self, SplineError> {
        let mut s = self.clone();
        for (axis, x) in new_knots.iter().enumerate() {
            s = s.refine(axis, x)?;
        }
        Ok(s)
    }
}

impl<const N: usize> TensorBSpline<N> {
    /// Subdivide along `axis` at the interior parameter `u`: `u` is inserted until it has
    /// multiplicity `p + 1`, and the net is cut there. The first result covers `[a, u]`, the
    /// second `[u, b]` of that axis; together they represent the spline exactly (Martin & Cohen
    /// §5.1 isolate isosurfaces and slices by such subdivision). Other axes are unchanged.
    ///
    /// # Errors
    /// [`SplineError::InvalidAxis`], or [`SplineError::KnotOutsideDomain`] unless
    /// `a < u < b` strictly.
    ///
    /// ```
    /// use volmorph_spline::{BSplineCurve, KnotVector};
    /// let kv = KnotVector::clamped_uniform(3, 6, [0.0, 3.0]).unwrap();
    /// let c = BSplineCurve::new([kv], 1, vec![0.0, 1.0, -1.0, 2.0, 0.0, 1.0]).unwrap();
    /// let (l, r) = c.split(0, 1.2).unwrap();
    /// assert_eq!(l.domain(), [[0.0, 1.2]]);
    /// assert_eq!(r.domain(), [[1.2, 3.0]]);
    /// assert!((l.eval([0.7]).unwrap()[0] - c.eval([0.7]).unwrap()[0]).abs() < 1e-12);
    /// assert!((r.eval([2.5]).unwrap()[0] - c.eval([2.5]).unwrap()[0]).abs() < 1e-12);
    /// ```
    pub fn split(&self, axis: usize, u: f64) -> Result<(Self, Self), SplineError> {
        Self::check_axis(axis)?;
        let kv = &self.knots()[axis];
        let [start, end] = kv.domain();
        if !(u > start && u < end) {
            return Err(SplineError::KnotOutsideDomain {
                value: u,
                start,
                end,
            });
        }
        let p = kv.degree();
        let times = p + 1 - kv.multiplicity(u);
        let r = self.insert_knot(axis, u, times)?;
        let rk = r.knots()[axis].knots();
        // First copy of u; the run is s ..= s + p.
        let s = rk.partition_point(|&k| k < u);
        let left_kv = KnotVector::new(p, rk[..=s + p].to_vec())?;
        let right_kv = KnotVector::new(p, rk[s..].to_vec())?;
        let (outer, len, inner) = r.axis_blocks(axis);
        let src = r.homogeneous_coefficients();
        let right_len = len - s;
        let mut left = Vec::with_capacity(outer * s * inner);
        let mut right = Vec::with_capacity(outer * right_len * inner);
        for o in 0..outer {
            let blk = &src[o * len * inner..(o + 1) * len * inner];
            left.extend_from_slice(&blk[..s * inner]);
            right.extend_from_slice(&blk[s * inner..]);
        }
        Ok((
            r.with_axis(axis, left_kv, left),
            r.with_axis(axis, right_kv, right),
        ))
    }
}

impl<const N: usize> TensorBSpline<N> {
    /// The end-interpolating (clamped) form along `axis`: the domain ends `a` and `b` are
    /// inserted until each has multiplicity `p + 1`, and the control points whose basis
    /// functions then vanish on the domain are dropped (Feng et al. 2002 §3.1.3). The result
    /// has knots `a^(p+1) … b^(p+1)`, the same interior knots, and represents exactly the same
    /// function on the domain; its first and last control rows along `axis` are the values on
    /// the faces `u = a` and `u = b`. A spline that is already clamped is returned unchanged.
    ///
    /// # Errors
    /// [`SplineError::InvalidAxis`] or [`SplineError::TooLarge`].
    ///
    /// ```
    /// use volmorph_spline::{BSplineCurve, KnotVector};
    /// let kv = KnotVector::uniform(2, 5, [0.0, 3.0]).unwrap();
    /// let c = BSplineCurve::new([kv], 1, vec![1.0, -1.0, 2.0, 0.5, 3.0]).unwrap();
    /// let e = c.clamp_ends(0).unwrap();
    /// assert!(e.knots()[0].is_clamped());
    /// assert_eq!(e.counts(), [5]);
    /// assert!((e.eval([1.3]).unwrap()[0] - c.eval([1.3]).unwrap()[0]).abs() < 1e-12);
    /// assert!((e.homogeneous_coefficients()[0] - c.eval([0.0]).unwrap()[0]).abs() < 1e-12);
    /// ```
    pub fn clamp_ends(&self, axis: usize) -> Result<Self, SplineError> {
        Self::check_axis(axis)?;
        let kv = &self.knots()[axis];
        let p = kv.degree();
        let [a, b] = kv.domain();
        let mut inserts = Vec::with_capacity(2 * (p + 1));
        inserts.extend(std::iter::repeat_n(
            a,
            p + 1 - kv.multiplicity(a).min(p + 1),
        ));
        inserts.extend(std::iter::repeat_n(
            b,
            p + 1 - kv.multiplicity(b).min(p + 1),
        ));
        let r = self.refine(axis, &inserts)?;
        let rk = r.knots()[axis].knots();
        let first = rk.partition_point(|&k| k < a);
        let last = rk.partition_point(|&k| k <= b); // one past the last copy of b
        if first == 0 && last == rk.len() {
            return Ok(r);
        }
        let new_kv = KnotVector::new(p, rk[first..last].to_vec())?;
        let (outer, len, inner) = r.axis_blocks(axis);
        let keep = new_kv.num_basis();
        let src = r.homogeneous_coefficients();
        let mut coefs = Vec::with_capacity(outer * keep * inner);
        for o in 0..outer {
            let blk = &src[o * len * inner..(o + 1) * len * inner];
            coefs.extend_from_slice(&blk[first * inner..(first + keep) * inner]);
        }
        Ok(r.with_axis(axis, new_kv, coefs))
    }
}

/// A5.4 on one block: `src` holds `n` rows of `inner` values, `dst` receives `n + r` rows.
/// `x` is sorted and inside the domain; `ubar` is the merged knot vector.
fn refine_block(
    kv: &KnotVector,
    ubar: &[f64],
    x: &[f64],
    src: &[f64],
    dst: &mut [f64],
    inner: usize,
) {
    let u = kv.knots();
    let p = kv.degree();
    let n = kv.num_basis() - 1; // last control index (NURBS Book notation)
    let r = x.len() - 1; // last index of X
    let a = kv.find_span_clamped(x[0]);
    let b = kv.find_span_clamped(x[r]) + 1;
    let row = |i: usize| i * inner..(i + 1) * inner;
    // Unaffected rows at both ends.
    dst[..(a - p + 1) * inner].copy_from_slice(&src[..(a - p + 1) * inner]);
    dst[(b - 1 + r + 1) * inner..(n + r + 2) * inner]
        .copy_from_slice(&src[(b - 1) * inner..(n + 1) * inner]);
    let mut i = b + p - 1;
    let mut k = b + p + r;
    for j in (0..=r).rev() {
        while x[j] <= u[i] && i > a {
            dst[row(k - p - 1)].copy_from_slice(&src[row(i - p - 1)]);
            k -= 1;
            i -= 1;
        }
        dst.copy_within(row(k - p), (k - p - 1) * inner);
        for l in 1..=p {
            let ind = k - p + l;
            let alfa = ubar[k + l] - x[j];
            if alfa == 0.0 {
                dst.copy_within(row(ind), (ind - 1) * inner);
            } else {
                let alfa = alfa / (ubar[k + l] - u[i - p + l]);
                let (lo, hi) = dst.split_at_mut(ind * inner);
                let target = &mut lo[(ind - 1) * inner..];
                let next = &hi[..inner];
                for (t, &q) in target.iter_mut().zip(next) {
                    *t = alfa * *t + (1.0 - alfa) * q;
                }
            }
        }
        k -= 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BSplineCurve;

    fn max_diff(a: &BSplineCurve, b: &BSplineCurve) -> f64 {
        let [lo, hi] = a.knots()[0].domain();
        (0..=200)
            .map(|i| {
                let u = lo + (hi - lo) * f64::from(i) / 200.0;
                let (va, vb) = (a.eval([u]).unwrap(), b.eval([u]).unwrap());
                va.iter()
                    .zip(&vb)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn insertion_at_domain_ends_of_unclamped_curve() {
        let kv = KnotVector::uniform(3, 7, [0.0, 4.0]).unwrap();
        let c =
            BSplineCurve::new([kv], 2, (0..14).map(|i| f64::from(i * i % 7)).collect()).unwrap();
        for (u, t) in [(0.0, 3), (4.0, 3), (0.0, 1), (4.0, 2), (2.0, 3), (1.5, 4)] {
            let r = c.insert_knot(0, u, t).unwrap();
            assert_eq!(r.counts()[0], 7 + t);
            assert!(max_diff(&c, &r) < 1e-12, "u={u} t={t}");
        }
        assert!(c.insert_knot(0, 4.5, 1).is_err());
        assert!(c.insert_knot(0, 1.0, 5).is_err());
        assert!(c.insert_knot(1, 1.0, 1).is_err());
    }

    #[test]
    fn clamp_ends_keeps_the_function_and_interpolates_the_ends() {
        for (p, n) in [(1, 3), (2, 4), (2, 7), (3, 6), (4, 9)] {
            let kv = KnotVector::uniform(p, n, [-1.0, 2.5]).unwrap();
            let coefs: Vec<f64> = (0..2 * n)
                .map(|i| ((i * 7 + 3) % 11) as f64 - 4.0)
                .collect();
            let c = BSplineCurve::new([kv], 2, coefs).unwrap();
            let e = c.clamp_ends(0).unwrap();
            assert!(e.knots()[0].is_clamped(), "p={p} n={n}");
            assert_eq!(e.counts(), [n]);
            assert_eq!(e.domain(), c.domain());
            assert!(max_diff(&c, &e) < 1e-12, "p={p} n={n}");
            let h = e.homogeneous_coefficients();
            let (lo, hi) = (c.eval([-1.0]).unwrap(), c.eval([2.5]).unwrap());
            assert!((h[0] - lo[0]).abs() < 1e-12 && (h[1] - lo[1]).abs() < 1e-12);
            assert!((h[2 * n - 2] - hi[0]).abs() < 1e-12 && (h[2 * n - 1] - hi[1]).abs() < 1e-12);
            // Already clamped: unchanged.
            assert_eq!(e.clamp_ends(0).unwrap(), e);
        }
        let c = BSplineCurve::new(
            [KnotVector::uniform(2, 4, [0.0, 1.0]).unwrap()],
            1,
            vec![0.0; 4],
        )
        .unwrap();
        assert!(c.clamp_ends(1).is_err());
    }

    #[test]
    fn boehm_single_insertion_hand_computed() {
        // Linear clamped curve, control 0, 1, 2 at Greville 0, 0.5, 1 (the identity):
        // inserting 0.25 gives control values at the new Greville points 0, 0.25, 0.5, 1.
        let kv = KnotVector::clamped_uniform(1, 3, [0.0, 1.0]).unwrap();
        let c = BSplineCurve::new([kv], 1, vec![0.0, 0.5, 1.0]).unwrap();
        let r = c.insert_knot(0, 0.25, 1).unwrap();
        assert_eq!(r.homogeneous_coefficients(), &[0.0, 0.25, 0.5, 1.0]);
        assert_eq!(r.knots()[0].knots(), &[0.0, 0.0, 0.25, 0.5, 1.0, 1.0]);
    }
}
