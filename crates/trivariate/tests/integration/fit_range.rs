//! Issue 16: fitted sampled volumes stay near the range of their data, agree with it at the
//! voxel centres, and least squares works for every control-point count up to the samples.
//!
//! The data are True's density phantoms (0–255 with a 3-voxel antialiasing ramp), evaluated
//! densely: at every voxel centre's parameters and every midpoint between neighbouring ones.

use volmorph_spline::{KnotVector, TensorBSpline};
use volmorph_trivariate::TrivariateError;
use volmorph_trivariate::fit::{
    SampledFit, SampledFitKind, fit_sampled_volume, least_squares, least_squares_knots,
};
use volmorph_volume::Volume;
use volmorph_volume::phantom::{self, Phantom};

/// Overshoot of cubic spline interpolation per unit difference between neighbouring samples.
/// Cubic interpolation of a unit step sampled on a uniform grid (far from the ends, where
/// Greville interpolation is cardinal) overshoots by `0.1078` (coefficients `|k|/2 +
/// λ^|k|/(2(2 + λ))` of `max(0, x)`, `λ = √3 − 2`; checked by
/// `cubic_interpolation_of_a_step_overshoots_by_the_cardinal_constant`), a linear ramp over
/// `w ≥ 2` samples by at most `0.085` per unit step. A smooth field sampled finely overshoots
/// far less (the interpolation error is `≤ 5/384 h⁴ ‖f⁗‖`, Hall & Meyer 1976); the phantoms'
/// clamped ramp has slope jumps, so the step bound is the one that applies.
const STEP_OVERSHOOT: f64 = 0.11;

/// Relative error of Greville interpolation at its own sites: the banded LU of the totally
/// positive collocation matrix is backward stable without pivoting (de Boor & Pinkus 1977) and
/// the per-axis Lebesgue constant is below 2, so a few rounding errors of 1.1e-16 times the
/// data range remain; 1e-9 leaves a wide margin.
const INTERPOLATION_TOLERANCE: f64 = 1e-9;

fn sphere(dims: [usize; 3]) -> Volume<f64> {
    phantom::density(Phantom::Sphere, dims)
        .unwrap()
        .cast::<f64>()
}

fn range(v: &Volume<f64>) -> (f64, f64) {
    v.data()
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

/// The largest difference between samples `step` apart along `axis`.
fn largest_difference(v: &Volume<f64>, axis: usize, step: usize) -> f64 {
    let d = v.geometry().dims;
    let mut worst: f64 = 0.0;
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                let mut n = [i, j, k];
                n[axis] += step;
                if n[axis] < d[axis] {
                    worst = worst.max((v[[i, j, k]] - v[n]).abs());
                }
            }
        }
    }
    worst
}

/// The overshoot margin of a fit: `STEP_OVERSHOOT` times the sum over the axes of the largest
/// data difference across one control-point spacing (one sample for interpolation). Each
/// axis's solve is a 1-D fit of the previous axes' results, so the per-axis overshoots add.
/// Measured: interpolation of the 143×8×8 sphere reaches 17.4 above 255 against a margin of
/// 19.0 (its two coarse axes step by 85 per voxel, each adding about 0.108 · 85); least
/// squares at most 22 against margins of 19 to 81.
fn margin(v: &Volume<f64>, counts: [usize; 3]) -> f64 {
    let d = v.geometry().dims;
    (0..3)
        .map(|a| {
            let step = (d[a] - 1).div_ceil(counts[a] - 1).max(1);
            STEP_OVERSHOOT * largest_difference(v, a, step)
        })
        .sum()
}

/// The parameters of the voxel centres along each axis, as the fit places them.
fn centre_params(fit: &SampledFit, dims: [usize; 3]) -> [Vec<f64>; 3] {
    let knots = fit.model.attribute("v").unwrap().knots().clone();
    std::array::from_fn(|a| match fit.kind {
        SampledFitKind::Interpolation => knots[a].greville(),
        SampledFitKind::LeastSquares => (0..dims[a])
            .map(|i| i as f64 / (dims[a] - 1) as f64)
            .collect(),
    })
}

/// The centres' parameters and the midpoints between neighbouring ones.
fn dense(params: &[f64]) -> Vec<f64> {
    let mut out = vec![params[0]];
    for w in params.windows(2) {
        out.push(0.5 * (w[0] + w[1]));
        out.push(w[1]);
    }
    out
}

fn eval(s: &TensorBSpline<3>, u: [f64; 3]) -> f64 {
    let mut v = [0.0];
    s.eval_into(u, &mut v).unwrap();
    v[0]
}

/// The fitted values' range over the dense parameter grid.
fn fitted_range(fit: &SampledFit, dims: [usize; 3]) -> (f64, f64) {
    let s = fit.model.attribute("v").unwrap();
    let p = centre_params(fit, dims).map(|p| dense(&p));
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &w in &p[2] {
        for &v in &p[1] {
            for &u in &p[0] {
                let x = eval(s, [u, v, w]);
                lo = lo.min(x);
                hi = hi.max(x);
            }
        }
    }
    (lo, hi)
}

/// Root-mean-square difference between the fitted attribute at the voxel centres and the
/// samples, and the largest difference.
fn residual(fit: &SampledFit, vol: &Volume<f64>) -> (f64, f64) {
    residual_of(
        fit.model.attribute("v").unwrap(),
        &centre_params(fit, vol.geometry().dims),
        vol,
    )
}

fn residual_of(s: &TensorBSpline<3>, p: &[Vec<f64>; 3], vol: &Volume<f64>) -> (f64, f64) {
    let d = vol.geometry().dims;
    let (mut sq, mut worst) = (0.0, 0.0_f64);
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                let e = eval(s, [p[0][i], p[1][j], p[2][k]]) - vol[[i, j, k]];
                sq += e * e;
                worst = worst.max(e.abs());
            }
        }
    }
    ((sq / vol.data().len() as f64).sqrt(), worst)
}

/// Schoenberg's variation-diminishing spline on the fit's knots: control point `k` is the
/// data linearly interpolated at Greville abscissa `ξ_k` (parameter `i / (n − 1)` is voxel
/// `i`). It lies in the fit's spline space, so least squares can do no worse.
fn variation_diminishing(fit: &SampledFit, vol: &Volume<f64>) -> TensorBSpline<3> {
    let d = vol.geometry().dims;
    let knots: [KnotVector; 3] = fit.model.attribute("v").unwrap().knots().clone();
    // Per axis, each Greville abscissa as (lower voxel, weight of the upper one).
    let at: [Vec<(usize, f64)>; 3] = std::array::from_fn(|a| {
        knots[a]
            .greville()
            .iter()
            .map(|&g| {
                let x = g * (d[a] - 1) as f64;
                let i = (x.floor() as usize).min(d[a] - 2);
                (i, x - i as f64)
            })
            .collect()
    });
    let mut coefs = Vec::new();
    for &(k, wz) in &at[2] {
        for &(j, wy) in &at[1] {
            for &(i, wx) in &at[0] {
                let mut c = 0.0;
                for (dk, fz) in [(0, 1.0 - wz), (1, wz)] {
                    for (dj, fy) in [(0, 1.0 - wy), (1, wy)] {
                        for (di, fx) in [(0, 1.0 - wx), (1, wx)] {
                            c += fx * fy * fz * vol[[i + di, j + dj, k + dk]];
                        }
                    }
                }
                coefs.push(c);
            }
        }
    }
    TensorBSpline::new(knots, 1, coefs).unwrap()
}

#[test]
fn cubic_interpolation_of_a_step_overshoots_by_the_cardinal_constant() {
    // A unit step in the middle of 41 samples at the Greville abscissae.
    let kv = KnotVector::clamped_uniform(3, 41, [0.0, 1.0]).unwrap();
    let g = kv.greville();
    let data: Vec<f64> = (0..41).map(|i| if i < 20 { 0.0 } else { 1.0 }).collect();
    let s = volmorph_trivariate::fit::interpolate([kv], 1, &data).unwrap();
    let mut hi: f64 = 0.0;
    for w in g.windows(2) {
        for t in 0..=100 {
            let u = w[0] + (w[1] - w[0]) * f64::from(t) / 100.0;
            hi = hi.max(s.eval([u]).unwrap()[0]);
        }
    }
    assert!(
        (hi - 1.0 - 0.1078).abs() < 2e-3 && hi - 1.0 <= STEP_OVERSHOOT,
        "step overshoot {}",
        hi - 1.0
    );
}

/// Interpolation (the default options) of the sphere phantom: the samples back at the voxel
/// centres, and no value beyond the range by more than the step margin.
fn check_interpolation(dims: [usize; 3]) {
    let vol = sphere(dims);
    let fit = fit_sampled_volume(&vol, 4, dims, "v").unwrap();
    assert_eq!(fit.kind, SampledFitKind::Interpolation);
    let (lo, hi) = range(&vol);
    let (rms, worst) = residual(&fit, &vol);
    assert!(
        worst <= INTERPOLATION_TOLERANCE * (hi - lo),
        "{dims:?}: interpolation misses a sample by {worst} (rms {rms})"
    );
    let m = margin(&vol, dims);
    let (flo, fhi) = fitted_range(&fit, dims);
    eprintln!("{dims:?} interpolation: data [{lo}, {hi}], fit [{flo}, {fhi}], margin {m}");
    assert!(
        flo >= lo - m && fhi <= hi + m,
        "{dims:?}: fitted range [{flo}, {fhi}] beyond [{lo}, {hi}] ± {m}"
    );
}

/// Least squares with `counts`: no worse than the variation-diminishing spline at the voxel
/// centres, and no value beyond the range by more than the step margin.
fn check_least_squares(dims: [usize; 3], counts: [usize; 3]) {
    let vol = sphere(dims);
    let fit = fit_sampled_volume(&vol, 4, counts, "v").unwrap();
    assert_eq!(fit.kind, SampledFitKind::LeastSquares);
    let (lo, hi) = range(&vol);
    let (rms, worst) = residual(&fit, &vol);
    let vd = variation_diminishing(&fit, &vol);
    let (vd_rms, _) = residual_of(&vd, &centre_params(&fit, dims), &vol);
    let m = margin(&vol, counts);
    let (flo, fhi) = fitted_range(&fit, dims);
    eprintln!(
        "{dims:?} least squares {counts:?}: rms {rms} (variation-diminishing {vd_rms}), worst \
         {worst}, fit [{flo}, {fhi}], margin {m}"
    );
    assert!(
        rms <= vd_rms * (1.0 + 1e-12),
        "{dims:?} {counts:?}: least-squares rms {rms} above the variation-diminishing {vd_rms}"
    );
    assert!(
        flo >= lo - m && fhi <= hi + m,
        "{dims:?} {counts:?}: fitted range [{flo}, {fhi}] beyond [{lo}, {hi}] ± {m}"
    );
}

#[test]
fn interpolated_sphere_phantoms_stay_within_the_data_range() {
    check_interpolation([24, 24, 24]);
    check_interpolation([32, 32, 32]);
    check_interpolation([143, 8, 8]);
}

#[test]
fn least_squares_sphere_phantoms_stay_within_the_data_range() {
    check_least_squares([24, 24, 24], [12, 12, 12]);
    check_least_squares([32, 32, 32], [16, 20, 31]);
    check_least_squares([143, 8, 8], [71, 8, 6]);
    check_least_squares([143, 8, 8], [142, 7, 8]);
}

#[test]
fn least_squares_with_one_fewer_control_point_is_not_rank_deficient() {
    // `phantom sphere --dims 300,8,8` then `nurbs fit --control-points 299,8,8` failed with
    // "least-squares collocation matrix is rank deficient": clamped uniform knots put three
    // Greville abscissae in each end span, where 300 uniform sites put two.
    check_least_squares([300, 8, 8], [299, 8, 8]);
    check_least_squares([300, 8, 8], [299, 7, 7]);
    // The default options on the same volume interpolate.
    check_interpolation([300, 8, 8]);
}

/// A smooth test signal on `[0, 1]` with values in [−1, 1].
fn signal(t: f64) -> f64 {
    (7.0 * t).sin() * (1.0 - t) + 0.3 * (23.0 * t * t).cos() * t
}

/// One axis of `n` uniform samples fitted with `m` control points of `order` on
/// [`least_squares_knots`]: the fit exists, reproduces a polynomial of the spline's degree,
/// and keeps the coefficients of noise-like data bounded (no amplification by a nearly
/// singular matrix).
fn check_axis(n: usize, m: usize, order: usize) -> f64 {
    let p = order - 1;
    let kv = least_squares_knots(p, m).unwrap();
    assert_eq!(kv.num_basis(), m);
    let sites: Vec<f64> = (0..n).map(|i| i as f64 / (n - 1) as f64).collect();
    let fit = |data: &[f64]| -> Result<TensorBSpline<1>, TrivariateError> {
        least_squares([kv.clone()], [&sites], 1, data)
    };
    // A polynomial of degree p lies in the space: reproduced at every site.
    let poly = |t: f64| (0..=p).map(|e| (t - 0.4).powi(e as i32)).sum::<f64>();
    let data: Vec<f64> = sites.iter().map(|&t| poly(t)).collect();
    let s = fit(&data).unwrap_or_else(|e| panic!("n {n}, m {m}, order {order}: {e}"));
    for (&t, &want) in sites.iter().zip(&data) {
        let got = s.eval([t]).unwrap()[0];
        assert!(
            (got - want).abs() < 1e-9,
            "n {n}, m {m}, order {order}: polynomial {got} vs {want} at {t}"
        );
    }
    // Alternating, noise-like data in [−1, 1]: coefficients stay of order one.
    let data: Vec<f64> = (0..n)
        .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 } * ((i * 7919 % 13) as f64 / 12.0))
        .collect();
    let s = fit(&data).unwrap();
    let big = s
        .control_points()
        .iter()
        .fold(0.0_f64, |a, c| a.max(c.abs()));
    assert!(
        big < COEFFICIENT_GROWTH,
        "n {n}, m {m}, order {order}: coefficient {big} from data in [-1, 1]"
    );
    // A smooth signal: the fit is no worse than the variation-diminishing spline.
    let data: Vec<f64> = sites.iter().map(|&t| signal(t)).collect();
    let s = fit(&data).unwrap();
    let vd = TensorBSpline::new(
        [kv.clone()],
        1,
        kv.greville().iter().map(|&g| signal(g)).collect(),
    )
    .unwrap();
    let sq = |s: &TensorBSpline<1>| {
        sites
            .iter()
            .zip(&data)
            .map(|(&t, &d)| (s.eval([t]).unwrap()[0] - d).powi(2))
            .sum::<f64>()
    };
    assert!(sq(&s) <= sq(&vd) * (1.0 + 1e-12) + 1e-24);
    big
}

/// Bound on the largest coefficient of a least-squares fit of data in [−1, 1] on
/// [`least_squares_knots`] over uniform sites, any count and order ≤ 6. Measured: 16.3, from
/// order-6 fits of the alternating data (cardinal interpolation alone amplifies `(−1)^k` by
/// `120/16 = 7.5` at order 6, 3 at order 4). The nearly singular matrices of the clamped
/// uniform knots used before amplify by up to `1/σ_min ≈ 1e14` at 300 samples.
const COEFFICIENT_GROWTH: f64 = 40.0;

#[test]
fn every_count_from_the_order_to_the_samples_fits_an_axis() {
    let mut big: f64 = 0.0;
    for order in 2..=6 {
        for n in [8, 17, 143] {
            for m in order..=n {
                big = big.max(check_axis(n, m, order));
            }
        }
        let n = 300;
        for m in [order, n / 2, n - 1, n] {
            big = big.max(check_axis(n, m, order));
        }
    }
    eprintln!("largest coefficient of a fit of data in [-1, 1]: {big}");
}

#[test]
fn every_count_fits_a_long_volume_axis() {
    for n in [8, 17, 143, 300] {
        let vol = sphere([n, 4, 4]);
        for m in [4, n / 2, n - 1, n] {
            let m = m.max(4);
            let fit = fit_sampled_volume(&vol, 4, [m, 4, 4], "v")
                .unwrap_or_else(|e| panic!("n {n}, m {m}: {e}"));
            let want = if m == n {
                SampledFitKind::Interpolation
            } else {
                SampledFitKind::LeastSquares
            };
            assert_eq!(fit.kind, want, "n {n}, m {m}");
        }
    }
}

#[test]
fn least_squares_knots_put_greville_abscissae_at_uniform_parameters() {
    for p in 1..=5 {
        for m in p + 1..40 {
            let kv = least_squares_knots(p, m).unwrap();
            assert_eq!(kv.num_basis(), m);
            assert!(kv.is_clamped());
            assert_eq!(kv.domain(), [0.0, 1.0]);
            let g = kv.greville();
            for (k, &x) in g.iter().enumerate() {
                let want = k as f64 / (m - 1) as f64;
                if k >= p && k + p < m {
                    assert!((x - want).abs() < 1e-12, "p {p}, m {m}, k {k}: {x}");
                } else {
                    // The clamped ends: within one knot span.
                    assert!((x - want).abs() <= 1.0 / (m - 1) as f64 + 1e-12);
                }
            }
        }
        assert!(least_squares_knots(p, p).is_err());
    }
}
