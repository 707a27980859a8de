//! Issue 16: `volmorph nurbs fit` on long axes, with the default options and with one control
//! point fewer than the samples, and the value range of the model it writes.

use crate::common::ok;
use volmorph_trivariate::load_volume;

/// Overshoot allowed per unit difference between neighbouring samples: cubic interpolation
/// of a unit step overshoots by 0.1078 (see `trivariate`'s `fit_range` tests); a little more
/// for rounding.
const STEP_OVERSHOOT: f64 = 0.11;

/// The sphere density phantom's largest difference between neighbouring voxels: 255 across
/// its ramp of 3 voxels of the coarsest axis (`phantom::RAMP_VOXELS` = 1.5 each side), i.e.
/// 85 per voxel along that axis, and less along finer ones.
const PHANTOM_STEP: f64 = 85.0;

#[test]
fn nurbs_fit_with_default_options_keeps_a_143_sample_axis_within_the_data_range() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("s.nii");
    let model = dir.path().join("s.json");
    ok(&[&"phantom", &"sphere", &"--dims", &"143,8,8", &"-o", &src]);
    let out = ok(&[&"nurbs", &"fit", &src, &"-o", &model]);
    assert!(
        out.contains("interpolation at the Greville abscissae") && out.contains("143x8x8"),
        "{out}"
    );
    let m = load_volume(&model).unwrap();
    let s = m.attribute("value").expect("the default attribute name");
    assert_eq!(s.counts(), [143, 8, 8]);
    // Every voxel centre (its Greville point) and every midpoint between neighbouring ones.
    let dense: Vec<Vec<f64>> = s
        .knots()
        .iter()
        .map(|k| {
            let g = k.greville();
            let mut d = vec![g[0]];
            for w in g.windows(2) {
                d.extend([0.5 * (w[0] + w[1]), w[1]]);
            }
            d
        })
        .collect();
    // Each axis adds at most one step overshoot.
    let margin = 3.0 * STEP_OVERSHOOT * PHANTOM_STEP;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &w in &dense[2] {
        for &v in &dense[1] {
            for &u in &dense[0] {
                let x = s.eval([u, v, w]).unwrap()[0];
                lo = lo.min(x);
                hi = hi.max(x);
            }
        }
    }
    assert!(
        lo >= -margin && hi <= 255.0 + margin,
        "fitted values [{lo}, {hi}] beyond [0, 255] ± {margin}"
    );
    // The data reach both ends of the range, so the fit does too.
    assert!(lo <= 0.5 && hi >= 254.5, "fitted values [{lo}, {hi}]");
}

#[test]
fn nurbs_fit_least_squares_with_one_fewer_control_point_is_not_rank_deficient() {
    // Failed with "least-squares collocation matrix is rank deficient".
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("s.nii");
    let model = dir.path().join("s.json");
    ok(&[&"phantom", &"sphere", &"--dims", &"300,8,8", &"-o", &src]);
    let out = ok(&[
        &"nurbs",
        &"fit",
        &src,
        &"--control-points",
        &"299,8,8",
        &"-o",
        &model,
    ]);
    assert!(
        out.contains("least squares") && out.contains("299x8x8"),
        "{out}"
    );
    let m = load_volume(&model).unwrap();
    let s = m.attribute("value").unwrap();
    let margin = 3.0 * STEP_OVERSHOOT * PHANTOM_STEP;
    for i in 0..=598 {
        for j in 0..=14 {
            let (u, v) = (f64::from(i) / 598.0, f64::from(j) / 14.0);
            let x = s.eval([u, v, 0.5]).unwrap()[0];
            assert!(
                (-margin..=255.0 + margin).contains(&x),
                "value {x} at ({u}, {v}, 0.5)"
            );
        }
    }
}
