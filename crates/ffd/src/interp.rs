//! Polynomial interpolation of Bézier curves and tensor-product surfaces from equally spaced
//! samples (Feng et al. 2002 §3.4.2).
//!
//! A Bézier curve of degree `k` is fixed by its values at `t = i/k`, `i = 0 … k`: the
//! collocation matrix `B_k[i][j] = B_{j,k}(i/k)` (Eq. 3) is constant and invertible, so the
//! control points are `B_k⁻¹ · samples`. The inverses for `k ≤ `[`MAX_INTERPOLATION_DEGREE`]
//! are computed once per process. A surface of degrees `(n_s, n_t)` is interpolated in two
//! stages of curve interpolation (Eqs. 3 and 4), starting with the lower degree.

use std::sync::OnceLock;

use glam::DVec3;
use volmorph_spline::bernstein;

/// Largest degree whose inverse collocation matrix is precomputed (the paper's choice: a
/// `4 × 4 × 4` lattice gives surface degrees up to 12).
pub const MAX_INTERPOLATION_DEGREE: usize = 12;

/// The inverse collocation matrices `B_k⁻¹`, `k = 0 … MAX_INTERPOLATION_DEGREE`, row-major.
fn inverses() -> &'static [Vec<f64>] {
    static INV: OnceLock<Vec<Vec<f64>>> = OnceLock::new();
    INV.get_or_init(|| {
        (0..=MAX_INTERPOLATION_DEGREE)
            .map(|k| invert(&collocation(k), k + 1))
            .collect()
    })
}

/// `B_k[i][j] = B_{j,k}(i/k)` (row-major, `(k+1)²` entries); `B_0 = [1]`.
#[must_use]
pub fn collocation(k: usize) -> Vec<f64> {
    let n = k + 1;
    let mut m = vec![0.0; n * n];
    for i in 0..n {
        let t = if k == 0 { 0.0 } else { i as f64 / k as f64 };
        for j in 0..n {
            m[i * n + j] = bernstein(j, k, t);
        }
    }
    m
}

/// Gauss–Jordan inversion with partial pivoting followed by two steps of iterative refinement
/// (`X ← X + X(I − AX)`), which brings the residual of these small, moderately conditioned
/// matrices to a few ulps.
fn invert(a: &[f64], n: usize) -> Vec<f64> {
    let mut m = a.to_vec();
    let mut x = vec![0.0; n * n];
    for i in 0..n {
        x[i * n + i] = 1.0;
    }
    for col in 0..n {
        let piv = (col..n)
            .max_by(|&r, &s| m[r * n + col].abs().total_cmp(&m[s * n + col].abs()))
            .unwrap_or(col);
        if piv != col {
            for c in 0..n {
                m.swap(piv * n + c, col * n + c);
                x.swap(piv * n + c, col * n + c);
            }
        }
        let d = m[col * n + col];
        for c in 0..n {
            m[col * n + c] /= d;
            x[col * n + c] /= d;
        }
        for r in 0..n {
            if r != col {
                let f = m[r * n + col];
                if f != 0.0 {
                    for c in 0..n {
                        m[r * n + c] -= f * m[col * n + c];
                        x[r * n + c] -= f * x[col * n + c];
                    }
                }
            }
        }
    }
    for _ in 0..2 {
        // R = I − A X; X ← X + X R.
        let mut r = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let s: f64 = (0..n).map(|l| a[i * n + l] * x[l * n + j]).sum();
                r[i * n + j] = f64::from(u8::from(i == j)) - s;
            }
        }
        let mut nx = x.clone();
        for i in 0..n {
            for j in 0..n {
                nx[i * n + j] += (0..n).map(|l| x[i * n + l] * r[l * n + j]).sum::<f64>();
            }
        }
        x = nx;
    }
    x
}

/// The precomputed `B_k⁻¹` (row-major), or `None` for `k > MAX_INTERPOLATION_DEGREE`.
#[must_use]
pub fn inverse_collocation(k: usize) -> Option<&'static [f64]> {
    inverses().get(k).map(Vec::as_slice)
}

/// Control points of the Bézier curve of degree `samples.len() − 1` through `samples[i]` at
/// `t = i/k`, written to `out` (same length). Returns `false` (leaving `out` untouched) when
/// the degree exceeds [`MAX_INTERPOLATION_DEGREE`] or the lengths differ.
pub fn interpolate_curve(samples: &[DVec3], out: &mut [DVec3]) -> bool {
    let n = samples.len();
    if n == 0 || out.len() != n {
        return false;
    }
    let Some(inv) = inverse_collocation(n - 1) else {
        return false;
    };
    for (i, o) in out.iter_mut().enumerate() {
        let row = &inv[i * n..(i + 1) * n];
        *o = row.iter().zip(samples).map(|(&c, &s)| c * s).sum();
    }
    true
}

/// Two-stage interpolation of a tensor-product Bézier surface of degrees `(ns, nt)` from
/// samples `R(i/ns, j/nt)` stored at `samples[i + (ns + 1)·j]` (s index fastest); the control
/// points are written to `out` in the same layout. `scratch` must hold `(ns+1)(nt+1)` points.
/// Returns `false` when a degree exceeds [`MAX_INTERPOLATION_DEGREE`] or a length is wrong.
pub fn interpolate_surface(
    degrees: [usize; 2],
    samples: &[DVec3],
    scratch: &mut [DVec3],
    out: &mut [DVec3],
) -> bool {
    let [ns, nt] = degrees;
    let (a, b) = (ns + 1, nt + 1);
    let len = a * b;
    if samples.len() != len || scratch.len() != len || out.len() != len {
        return false;
    }
    let (Some(is), Some(it)) = (inverse_collocation(ns), inverse_collocation(nt)) else {
        return false;
    };
    let s_stage = |src: &[DVec3], dst: &mut [DVec3]| {
        for j in 0..b {
            for i in 0..a {
                dst[i + a * j] = (0..a).map(|l| is[i * a + l] * src[l + a * j]).sum();
            }
        }
    };
    let t_stage = |src: &[DVec3], dst: &mut [DVec3]| {
        for i in 0..a {
            for j in 0..b {
                dst[i + a * j] = (0..b).map(|l| it[j * b + l] * src[i + a * l]).sum();
            }
        }
    };
    // Eq. (3) along the lower degree first, then Eq. (4) along the other.
    if ns <= nt {
        s_stage(samples, scratch);
        t_stage(scratch, out);
    } else {
        t_stage(samples, scratch);
        s_stage(scratch, out);
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverses_are_inverses() {
        for k in 0..=MAX_INTERPOLATION_DEGREE {
            let n = k + 1;
            let a = collocation(k);
            let x = inverse_collocation(k).unwrap();
            for i in 0..n {
                for j in 0..n {
                    let s: f64 = (0..n).map(|l| a[i * n + l] * x[l * n + j]).sum();
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((s - want).abs() < 1e-11, "k={k} ({i},{j}) {s}");
                }
            }
        }
        assert!(inverse_collocation(MAX_INTERPOLATION_DEGREE + 1).is_none());
        // Hand-computed: B_1 = I; B_2 rows (1,0,0), (1/4,1/2,1/4), (0,0,1).
        assert_eq!(inverse_collocation(1).unwrap(), &[1.0, 0.0, 0.0, 1.0]);
        let b2 = inverse_collocation(2).unwrap();
        for (g, w) in b2
            .iter()
            .zip([1.0, 0.0, 0.0, -0.5, 2.0, -0.5, 0.0, 0.0, 1.0])
        {
            assert!((g - w).abs() < 1e-15);
        }
    }

    #[test]
    fn surface_interpolation_reproduces_a_polynomial_surface() {
        let f = |s: f64, t: f64| {
            DVec3::new(
                s * s * t - 2.0 * t.powi(3) + 1.0,
                s.powi(4) - t,
                (s - 0.3).powi(2) * (t + 0.5).powi(3),
            )
        };
        for (ns, nt) in [(4, 3), (5, 3), (6, 6), (12, 5)] {
            let (a, b) = (ns + 1, nt + 1);
            let mut samples = vec![DVec3::ZERO; a * b];
            for j in 0..b {
                for i in 0..a {
                    samples[i + a * j] = f(i as f64 / ns as f64, j as f64 / nt as f64);
                }
            }
            let mut scratch = vec![DVec3::ZERO; a * b];
            let mut cps = vec![DVec3::ZERO; a * b];
            assert!(interpolate_surface(
                [ns, nt],
                &samples,
                &mut scratch,
                &mut cps
            ));
            for (s, t) in [(0.13, 0.77), (0.5, 0.5), (0.91, 0.02)] {
                let mut p = DVec3::ZERO;
                for j in 0..b {
                    for i in 0..a {
                        p += bernstein(i, ns, s) * bernstein(j, nt, t) * cps[i + a * j];
                    }
                }
                assert!(
                    (p - f(s, t)).length() < 1e-10,
                    "({ns},{nt}) {p} {}",
                    f(s, t)
                );
            }
        }
        let mut out = [DVec3::ZERO; 2];
        assert!(!interpolate_curve(&[DVec3::ZERO; 3], &mut out));
    }
}
