//! Derivative control nets (Martin & Cohen §2.1).
//!
//! The partial derivative along axis `a` of a degree-`p` B-spline with knots `u` and control
//! points `P_i` is the degree-`p − 1` B-spline with the knot vector `u` minus its first and last
//! knot and control points
//!
//! `Q_i = p·(P_{i+1} − P_i)/(u_{i+p+1} − u_{i+1})`, `i = 0 … n − 2`
//!
//! (with order `k = p + 1` this is Martin & Cohen's `(k−1)/(u_{i+k} − u_{i+1})` formula). When a
//! knot has multiplicity `p + 1` inside the knot vector, the denominator vanishes for exactly one
//! `i`; that basis function of degree `p − 1` is identically zero, so the term and one copy of
//! the knot are dropped, which keeps the derivative's knot vector valid and the function exact.
//!
//! For rational splines the derivative of the homogeneous map `P^w` is again a (polynomial)
//! B-spline in `dim + 1` components: [`TensorBSpline::homogeneous_derivative`]. The derivative of
//! the projected rational map is not a spline of the same form, so
//! [`TensorBSpline::derivative`] rejects rational input.

use crate::{KnotVector, SplineError, TensorBSpline};

impl<const N: usize> TensorBSpline<N> {
    /// The partial derivative `∂S/∂u_axis` of a polynomial spline, as a spline of degree one
    /// lower along `axis` (same dimension, same domain).
    ///
    /// # Errors
    /// [`SplineError::InvalidAxis`], [`SplineError::RationalDerivative`] for rational splines,
    /// [`SplineError::DegreeZeroDerivative`] when the axis has degree 0.
    ///
    /// ```
    /// use volmorph_spline::{BSplineCurve, KnotVector};
    /// // S(u) = u^3 on [0, 2] as a clamped cubic; S' = 3u^2.
    /// let kv = KnotVector::clamped_uniform(3, 6, [0.0, 2.0]).unwrap();
    /// let g = kv.greville();
    /// let s = volmorph_spline::interpolate_greville([kv], 1, &g.iter().map(|u| u * u * u).collect::<Vec<_>>()).unwrap();
    /// let d = s.derivative(0).unwrap();
    /// assert_eq!(d.degrees(), [2]);
    /// assert!((d.eval([1.3]).unwrap()[0] - 3.0 * 1.3 * 1.3).abs() < 1e-12);
    /// ```
    pub fn derivative(&self, axis: usize) -> Result<Self, SplineError> {
        if self.is_rational() {
            return Err(SplineError::RationalDerivative);
        }
        self.homogeneous_derivative(axis)
    }

    /// The partial derivative along `axis` of the homogeneous form `P^w` (Martin & Cohen eq. 1):
    /// a polynomial spline with `dim + 1` components `(∂(w·S), ∂w)` for rational input, and
    /// simply `∂S` (`dim` components) for polynomial input.
    ///
    /// # Errors
    /// [`SplineError::InvalidAxis`] or [`SplineError::DegreeZeroDerivative`].
    pub fn homogeneous_derivative(&self, axis: usize) -> Result<Self, SplineError> {
        Self::check_axis(axis)?;
        let kv = &self.knots()[axis];
        let p = kv.degree();
        if p == 0 {
            return Err(SplineError::DegreeZeroDerivative { axis });
        }
        let u = kv.knots();
        let n = kv.num_basis();
        // Kept derivative coefficients i (denominator > 0) and the derivative knot vector
        // u_1 .. u_{m-1} with one knot removed per dropped i (its index i + 1 in u).
        let mut keep = Vec::with_capacity(n - 1);
        let mut knots = Vec::with_capacity(u.len() - 2);
        let mut dropped = vec![false; u.len()];
        for i in 0..n - 1 {
            if u[i + p + 1] > u[i + 1] {
                keep.push(i);
            } else {
                dropped[i + 1] = true;
            }
        }
        for (j, &k) in u.iter().enumerate().take(u.len() - 1).skip(1) {
            if !dropped[j] {
                knots.push(k);
            }
        }
        let dkv = KnotVector::new(p - 1, knots)?;
        let (outer, len, inner) = self.axis_blocks(axis);
        let new_len = keep.len();
        let src = self.homogeneous_coefficients();
        let mut out = vec![0.0; outer * new_len * inner];
        let pf = p as f64;
        for o in 0..outer {
            let sblk = &src[o * len * inner..(o + 1) * len * inner];
            let dblk = &mut out[o * new_len * inner..(o + 1) * new_len * inner];
            for (r, &i) in keep.iter().enumerate() {
                let s = pf / (u[i + p + 1] - u[i + 1]);
                let (a, b) = (
                    &sblk[i * inner..(i + 1) * inner],
                    &sblk[(i + 1) * inner..(i + 2) * inner],
                );
                for ((d, &x0), &x1) in dblk[r * inner..(r + 1) * inner].iter_mut().zip(a).zip(b) {
                    *d = s * (x1 - x0);
                }
            }
        }
        let mut all_knots = self.knots().clone();
        all_knots[axis] = dkv;
        let dim = self.homogeneous_dim();
        Ok(Self::from_parts_unchecked(all_knots, dim, false, out))
    }
}

#[cfg(test)]
mod tests {
    use crate::{BSplineCurve, KnotVector};

    #[test]
    fn full_multiplicity_interior_knot_is_handled() {
        // Degree 2 with a discontinuity (multiplicity 3) at 1.
        let kv = KnotVector::new(2, vec![0., 0., 0., 1., 1., 1., 2., 2., 2.]).unwrap();
        let c = BSplineCurve::new([kv], 1, vec![0.0, 1.0, 3.0, -2.0, 0.5, 4.0]).unwrap();
        let d = c.derivative(0).unwrap();
        assert_eq!(d.knots()[0].knots(), &[0., 0., 1., 1., 2., 2.]);
        assert_eq!(d.counts(), [4]);
        for &u in &[0.2, 0.7, 1.0, 1.4, 2.0] {
            let (_, g) = c.eval_with_gradient([u]).unwrap();
            assert!((d.eval([u]).unwrap()[0] - g[0]).abs() < 1e-12, "u={u}");
        }
    }

    #[test]
    fn degree_zero_and_rational_are_rejected() {
        let kv = KnotVector::clamped_uniform(0, 2, [0.0, 1.0]).unwrap();
        let c = BSplineCurve::new([kv.clone()], 1, vec![0.0, 1.0]).unwrap();
        assert!(c.derivative(0).is_err());
        assert!(c.derivative(1).is_err());
        let k1 = KnotVector::clamped_uniform(1, 2, [0.0, 1.0]).unwrap();
        let r = BSplineCurve::new_rational([k1], 1, vec![0.0, 1.0], vec![1.0, 2.0]).unwrap();
        assert!(r.derivative(0).is_err());
        let h = r.homogeneous_derivative(0).unwrap();
        // P^w = ((1-u)*0 + u*2, (1-u) + 2u): derivative (2, 1).
        assert_eq!(h.dim(), 2);
        assert_eq!(h.eval([0.4]).unwrap(), vec![2.0, 1.0]);
    }
}
