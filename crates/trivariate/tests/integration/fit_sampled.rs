//! Fitting sampled volumes: interpolation at the Greville abscissae reproduces every sample at
//! its own voxel centre, stays within the data range on smooth data at sizes where uniform
//! sites diverge, and handles long axes; least squares works with fewer control points.

use glam::{DMat3, DVec3};
use volmorph_trivariate::fit::{SampledFitKind, fit_sampled_volume};
use volmorph_volume::{Geometry, Volume};

/// A smooth field on an oblique, anisotropic grid: a Gaussian blob plus a gentle ramp.
fn smooth(dims: [usize; 3]) -> Volume<f64> {
    let g = Geometry::new(dims)
        .with_spacing(DVec3::new(0.9, 1.1, 1.5))
        .with_origin(DVec3::new(-10.0, 4.0, 2.5))
        .with_direction(DMat3::from_rotation_z(0.3));
    let c = g.index_to_physical(DVec3::new(
        dims[0] as f64 * 0.45,
        dims[1] as f64 * 0.55,
        dims[2] as f64 * 0.5,
    ));
    let r = 0.25 * dims.iter().copied().min().unwrap() as f64;
    Volume::from_fn(g, |i, j, k| {
        let p = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
        200.0 * (-(p - c).length_squared() / (2.0 * r * r)).exp() + 0.3 * i as f64
    })
    .unwrap()
}

#[test]
fn interpolation_reproduces_every_sample_at_its_voxel_centre() {
    let vol = smooth([9, 7, 6]);
    let g = *vol.geometry();
    let fit = fit_sampled_volume(&vol, 4, g.dims, "v").unwrap();
    assert_eq!(fit.kind, SampledFitKind::Interpolation);
    let knots = fit.model.attribute("v").unwrap().knots().clone();
    let greville: Vec<Vec<f64>> = knots.iter().map(|k| k.greville()).collect();
    for k in 0..g.dims[2] {
        for j in 0..g.dims[1] {
            for i in 0..g.dims[0] {
                let u = [greville[0][i], greville[1][j], greville[2][k]];
                let p = DVec3::from_array(fit.model.point(u).unwrap());
                let want = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                assert!(
                    (p - want).length() < 1e-9,
                    "geometry at {i},{j},{k}: {p} vs {want}"
                );
                let mut v = [0.0];
                fit.model.attribute_into("v", u, &mut v).unwrap();
                let s = vol.data()[i + g.dims[0] * (j + g.dims[1] * k)];
                assert!(
                    (v[0] - s).abs() < 1e-9 * s.abs().max(1.0),
                    "value at {i},{j},{k}"
                );
            }
        }
    }
}

#[test]
fn regression_uniform_site_interpolation_diverged_beyond_16_samples() {
    // At 40 samples per axis uniform sites have a Lebesgue constant near 10³: the fitted
    // field overshot the data range by orders of magnitude. At the Greville abscissae it stays
    // within the data range plus a small cubic overshoot.
    let vol = smooth([40, 36, 34]);
    let (lo, hi) = vol
        .data()
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let fit = fit_sampled_volume(&vol, 4, vol.geometry().dims, "v").unwrap();
    let spline = fit.model.attribute("v").unwrap();
    let margin = 0.02 * (hi - lo);
    let mut r = volmorph_testkit::Rng::new(9);
    for _ in 0..5000 {
        let u = [r.unit(), r.unit(), r.unit()];
        let mut v = [0.0];
        spline.eval_into(u, &mut v).unwrap();
        assert!(
            v[0] >= lo - margin && v[0] <= hi + margin,
            "value {} at {u:?} outside [{lo}, {hi}] ± {margin}",
            v[0]
        );
    }
}

#[test]
fn regression_long_axes_were_rank_deficient() {
    // 150 samples along x failed with "least-squares collocation matrix is rank deficient".
    let vol = smooth([150, 6, 5]);
    let fit = fit_sampled_volume(&vol, 4, vol.geometry().dims, "v").unwrap();
    assert_eq!(fit.kind, SampledFitKind::Interpolation);
}

#[test]
fn least_squares_with_fewer_control_points_approximates() {
    let vol = smooth([30, 28, 26]);
    let fit = fit_sampled_volume(&vol, 4, [12, 12, 10], "v").unwrap();
    assert_eq!(fit.kind, SampledFitKind::LeastSquares);
    let g = *vol.geometry();
    let spline = fit.model.attribute("v").unwrap();
    let mut worst: f64 = 0.0;
    for (n, s) in vol.data().iter().enumerate() {
        let idx = [
            n % g.dims[0],
            n / g.dims[0] % g.dims[1],
            n / (g.dims[0] * g.dims[1]),
        ];
        let u = std::array::from_fn(|a| idx[a] as f64 / (g.dims[a] - 1) as f64);
        let mut v = [0.0];
        spline.eval_into(u, &mut v).unwrap();
        worst = worst.max((v[0] - s).abs());
    }
    assert!(
        worst < 2.0,
        "worst least-squares error {worst} (data up to ~210)"
    );
    // Bad options are errors.
    assert!(fit_sampled_volume(&vol, 1, [12, 12, 10], "v").is_err());
    assert!(fit_sampled_volume(&vol, 4, [3, 12, 10], "v").is_err());
    assert!(fit_sampled_volume(&vol, 4, [31, 12, 10], "v").is_err());
}
