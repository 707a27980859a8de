//! Bernstein polynomials `B_{i,n}(t) = C(n, i) tⁱ (1 − t)ⁿ⁻ⁱ` on `t ∈ [0, 1]` and their
//! derivatives, any degree up to [`crate::MAX_DEGREE`].
//!
//! All values of one degree are computed together by the de Casteljau-style recurrence
//! `B_{i,n} = (1 − t) B_{i,n−1} + t B_{i−1,n−1}` (The NURBS Book A1.3), which is stable and
//! exact at `t = 0` and `t = 1`. Derivatives use
//! `d/dt B_{i,n} = n (B_{i−1,n−1} − B_{i,n−1})`, applied `k` times for order `k`.

use crate::SplineError;

/// All `n + 1` Bernstein polynomials of degree `degree` at `t`, written to `out[..=degree]`.
/// No allocation. `t` outside `[0, 1]` extrapolates the polynomials.
///
/// # Errors
/// [`SplineError::BufferLength`] if `out.len() < degree + 1`.
///
/// ```
/// use volmorph_spline::bernstein_into;
/// let mut b = [0.0; 4];
/// bernstein_into(3, 0.25, &mut b).unwrap();
/// assert!((b.iter().sum::<f64>() - 1.0).abs() < 1e-15); // partition of unity
/// assert!((b[1] - 3.0 * 0.25 * 0.75 * 0.75).abs() < 1e-15);
/// ```
pub fn bernstein_into(degree: usize, t: f64, out: &mut [f64]) -> Result<(), SplineError> {
    if out.len() <= degree {
        return Err(SplineError::BufferLength {
            expected: degree.saturating_add(1),
            got: out.len(),
        });
    }
    bernstein_unchecked(degree, t, out);
    Ok(())
}

/// A1.3 without the length check (`out.len() ≥ degree + 1`).
#[inline]
pub(crate) fn bernstein_unchecked(degree: usize, t: f64, out: &mut [f64]) {
    let s = 1.0 - t;
    out[0] = 1.0;
    for j in 1..=degree {
        let mut saved = 0.0;
        for o in &mut out[..j] {
            let temp = *o;
            *o = saved + s * temp;
            saved = t * temp;
        }
        out[j] = saved;
    }
}

/// The `order`-th derivatives of all Bernstein polynomials of degree `degree` at `t`, written to
/// `out[..=degree]` (all zero when `order > degree`). No allocation.
///
/// # Errors
/// [`SplineError::BufferLength`] if `out.len() < degree + 1`.
///
/// ```
/// use volmorph_spline::bernstein_derivative_into;
/// // d/dt of B_{0,2} = (1-t)^2 is -2(1-t).
/// let mut d = [0.0; 3];
/// bernstein_derivative_into(2, 1, 0.3, &mut d).unwrap();
/// assert!((d[0] + 2.0 * 0.7).abs() < 1e-15);
/// assert!(d.iter().sum::<f64>().abs() < 1e-15);
/// ```
pub fn bernstein_derivative_into(
    degree: usize,
    order: usize,
    t: f64,
    out: &mut [f64],
) -> Result<(), SplineError> {
    if out.len() <= degree {
        return Err(SplineError::BufferLength {
            expected: degree.saturating_add(1),
            got: out.len(),
        });
    }
    bernstein_derivative_unchecked(degree, order, t, out);
    Ok(())
}

#[inline]
pub(crate) fn bernstein_derivative_unchecked(degree: usize, order: usize, t: f64, out: &mut [f64]) {
    if order > degree {
        out[..=degree].fill(0.0);
        return;
    }
    let base = degree - order;
    bernstein_unchecked(base, t, out);
    out[base + 1..=degree].fill(0.0);
    // Raise: values of degree m -> derivative factors of degree m + 1.
    for m in base..degree {
        let scale = (m + 1) as f64;
        // new[i] = (m+1) (old[i-1] - old[i]); old[m+1] = 0.
        out[m + 1] = scale * out[m];
        for i in (1..=m).rev() {
            out[i] = scale * (out[i - 1] - out[i]);
        }
        out[0] *= -scale;
    }
}

/// One Bernstein polynomial `B_{i,n}(t)`; 0 when `i > n`.
#[must_use]
pub fn bernstein(i: usize, n: usize, t: f64) -> f64 {
    if i > n {
        return 0.0;
    }
    // C(n, i) t^i (1-t)^(n-i), binomial built incrementally in floating point.
    let mut c = 1.0;
    for k in 0..i.min(n - i) {
        c = c * (n - k) as f64 / (k + 1) as f64;
    }
    c * pow(t, i) * pow(1.0 - t, n - i)
}

/// `x^e` by repeated squaring for exponents that fit in `i32`, `powf` beyond.
fn pow(x: f64, e: usize) -> f64 {
    i32::try_from(e).map_or_else(|_| x.powf(e as f64), |e| x.powi(e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn partition_of_unity_and_closed_form(n in 0usize..=20, t in 0.0f64..=1.0) {
            let mut b = [0.0; 21];
            bernstein_into(n, t, &mut b).unwrap();
            let s: f64 = b[..=n].iter().sum();
            prop_assert!((s - 1.0).abs() < 1e-13);
            for (i, &bi) in b[..=n].iter().enumerate() {
                prop_assert!(bi >= 0.0);
                prop_assert!((bi - bernstein(i, n, t)).abs() < 1e-12);
            }
        }

        #[test]
        fn derivatives_match_finite_differences(n in 1usize..=12, t in 0.05f64..0.95) {
            let mut d1 = [0.0; 13];
            let mut d2 = [0.0; 13];
            bernstein_derivative_into(n, 1, t, &mut d1).unwrap();
            bernstein_derivative_into(n, 2, t, &mut d2).unwrap();
            let h = 1e-5;
            let mut bp = [0.0; 13];
            let mut bm = [0.0; 13];
            let mut b0 = [0.0; 13];
            bernstein_into(n, t + h, &mut bp).unwrap();
            bernstein_into(n, t - h, &mut bm).unwrap();
            bernstein_into(n, t, &mut b0).unwrap();
            for i in 0..=n {
                let fd = (bp[i] - bm[i]) / (2.0 * h);
                prop_assert!((d1[i] - fd).abs() < 1e-6 * (1.0 + fd.abs()));
                let fd2 = (bp[i] - 2.0 * b0[i] + bm[i]) / (h * h);
                prop_assert!((d2[i] - fd2).abs() < 2e-2 * (1.0 + fd2.abs()));
            }
        }
    }

    #[test]
    fn end_values_and_high_orders() {
        let mut b = [0.0; 6];
        bernstein_into(5, 0.0, &mut b).unwrap();
        assert_eq!(b, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        bernstein_into(5, 1.0, &mut b).unwrap();
        assert_eq!(b, [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        // The 5th derivative of a quintic Bernstein polynomial is the constant 5! (-1)^(5-i) C(5,i).
        bernstein_derivative_into(5, 5, 0.3, &mut b).unwrap();
        let expect = [-120.0, 600.0, -1200.0, 1200.0, -600.0, 120.0];
        for i in 0..6 {
            assert!((b[i] - expect[i]).abs() < 1e-9);
        }
        bernstein_derivative_into(5, 6, 0.3, &mut b).unwrap();
        assert!(b.iter().all(|&x| x == 0.0));
        assert!(bernstein_into(3, 0.5, &mut b[..3]).is_err());
        assert_eq!(bernstein(4, 3, 0.5), 0.0);
    }
}
