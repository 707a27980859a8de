//! Pull-back through the inverse of a push-forward map: agreement with pull-back through an
//! explicitly inverted affine map, round trips through lattices, agreement with the
//! push-forward on smooth fields, honest reporting of non-convergence and folds; and the
//! slab-wise Jacobian determinant map against pointwise determinants.

use glam::{DMat3, DVec3};
use volmorph_deform::{Affine, SpaceMap, invert_point};
use volmorph_lattice::BSplineLattice;
use volmorph_testkit::Rng;
use volmorph_volume::sample::{Boundary, Interpolation, Sampler};
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::WarpError;
use volmorph_warp::inverse::{
    InverseResampleOptions, MASK_CONVERGED, MASK_FOLDED, MASK_NOT_CONVERGED,
    pullback_through_inverse, pullback_through_inverse_into,
};
use volmorph_warp::jacobian::jacobian_determinant;
use volmorph_warp::pullback::{ResampleOptions, resample};
use volmorph_warp::pushforward::{AntialiasOptions, push_forward_antialiased_f32};

/// A smooth field (wavelengths of 10 to 20 voxels) on `g`.
fn smooth(g: Geometry) -> Volume<f32> {
    Volume::from_fn(g, |i, j, k| {
        let (x, y, z) = (i as f32, j as f32, k as f32);
        10.0 + 3.0 * (0.31 * x).sin() + 2.0 * (0.23 * y + 0.5).cos() + (0.4 * z).sin() * 1.5
    })
    .unwrap()
}

/// An irregular pattern (exposes any misplaced sample).
fn pattern(g: Geometry) -> Volume<f32> {
    Volume::from_fn(g, |i, j, k| {
        ((i * 37 + j * 91 + k * 53 + i * j * k) % 251) as f32 * 0.5
    })
    .unwrap()
}

fn opts(interpolation: Interpolation) -> InverseResampleOptions {
    InverseResampleOptions::new(interpolation, -1.0)
}

/// The affine map `p ↦ c + m·(p − c)`.
fn about(c: DVec3, m: DMat3) -> Affine {
    Affine {
        matrix: m,
        offset: c - m * c,
    }
}

fn inverse_affine(a: &Affine) -> Affine {
    let inv = a.matrix.inverse();
    Affine {
        matrix: inv,
        offset: -(inv * a.offset),
    }
}

fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn affine_equals_pullback_through_the_inverse_affine() {
    let g = Geometry::new([19, 17, 15])
        .with_spacing(DVec3::new(1.0, 1.2, 0.9))
        .with_origin(DVec3::new(-3.0, 2.0, 1.0));
    let input = pattern(g);
    let centre = g.index_to_physical(DVec3::new(9.0, 8.0, 7.0));
    let a = about(
        centre,
        DMat3::from_axis_angle(DVec3::new(0.2, 1.0, -0.4).normalize(), 0.35)
            * DMat3::from_diagonal(DVec3::new(1.1, 0.9, 1.05)),
    );
    let inv = inverse_affine(&a);
    for interpolation in [
        Interpolation::Nearest,
        Interpolation::Linear,
        Interpolation::CubicBSpline,
    ] {
        let got =
            pullback_through_inverse::<f32, f32, _>(&input, &a, &g, &opts(interpolation)).unwrap();
        assert_eq!(got.report.nonconverged, 0);
        assert_eq!(got.report.folded, 0);
        assert_eq!(got.report.voxels, g.len());
        assert!(got.report.is_clean());
        let want: Volume<f32> =
            resample(&input, &inv, &g, &ResampleOptions::new(interpolation, -1.0)).unwrap();
        let mut differ = 0;
        for (x, y) in got.volume.data().iter().zip(want.data()) {
            if (x - y).abs() > 1e-3 {
                differ += 1;
            }
        }
        // Nearest may round the other way for a preimage within rounding of a voxel face.
        let allowed = if interpolation == Interpolation::Nearest {
            3
        } else {
            0
        };
        assert!(
            differ <= allowed,
            "{interpolation:?}: {differ} voxels differ"
        );
    }
    // A whole-voxel translation moves the content forward, voxel values copied exactly.
    let t = Affine::translation(DVec3::new(2.0, -1.2, 0.0));
    let r = pullback_through_inverse::<f32, f32, _>(&input, &t, &g, &opts(Interpolation::Linear))
        .unwrap();
    assert_eq!(r.volume[[5, 3, 4]], input[[3, 4, 4]]);
    assert_eq!(r.volume[[1, 3, 4]], -1.0, "source outside the input");
}

#[test]
fn lattice_with_affine_control_points_equals_the_inverted_affine() {
    // Affine invariance: control points moved by an affine map make the lattice that map on
    // its box. The box is much larger than the grid, so every preimage lies inside it.
    let g = Geometry::new([20, 18, 16]).with_spacing(DVec3::new(1.0, 1.1, 1.2));
    let centre = g.index_to_physical(DVec3::new(9.5, 8.5, 7.5));
    let a = about(
        centre,
        DMat3::from_axis_angle(DVec3::new(-0.3, 0.4, 1.0).normalize(), 0.3)
            * DMat3::from_diagonal(DVec3::new(1.15, 0.95, 1.0)),
    );
    let mut lat = BSplineLattice::uniform_cubic_around(
        DVec3::splat(-20.0),
        DVec3::new(40.0, 40.0, 40.0),
        [8, 7, 9],
    )
    .unwrap();
    lat.map_control_points(|p| a.apply(p)).unwrap();
    let input = smooth(g);
    let got =
        pullback_through_inverse::<f32, f32, _>(&input, &lat, &g, &opts(Interpolation::Linear))
            .unwrap();
    assert!(got.report.is_clean(), "{}", got.report);
    let want: Volume<f32> = resample(
        &input,
        &inverse_affine(&a),
        &g,
        &ResampleOptions::new(Interpolation::Linear, -1.0),
    )
    .unwrap();
    assert!(max_diff(got.volume.data(), want.data()) < 1e-4);
}

/// A cubic lattice over `g` with the interior control points moved by up to `scale / 2`.
fn moved_lattice(g: &Geometry, scale: f64) -> BSplineLattice {
    let (lo, hi) = g.physical_bounds();
    let mut lat =
        BSplineLattice::uniform_cubic_around(lo - DVec3::ONE, hi + DVec3::ONE, [10, 10, 10])
            .unwrap();
    let mut rng = Rng::new(7);
    for k in 3..7 {
        for j in 3..7 {
            for i in 3..7 {
                lat.move_control_point([i, j, k], rng.point(0.5) * scale)
                    .unwrap();
            }
        }
    }
    lat
}

#[test]
fn every_voxel_samples_the_input_at_the_preimage() {
    let g = Geometry::new([22, 20, 18]).with_spacing(DVec3::new(1.0, 0.9, 1.1));
    let lat = moved_lattice(&g, 4.0);
    let input = pattern(g);
    let r = pullback_through_inverse::<f32, f64, _>(
        &input,
        &lat,
        &g,
        &opts(Interpolation::Linear).with_mask(true),
    )
    .unwrap();
    assert!(r.report.is_clean(), "{}", r.report);
    let mask = r.mask.expect("mask asked for");
    assert!(mask.data().iter().all(|&m| m == MASK_CONVERGED));
    let sampler = Sampler::new(&input, Interpolation::Linear, Boundary::Constant(-1.0)).unwrap();
    let tol = 1e-6 * 0.9;
    for (n, &v) in r.volume.data().iter().enumerate() {
        let (i, j, k) = (n % 22, n / 22 % 20, n / 440);
        let y = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
        let x = r_point(&lat, y);
        assert!((lat.apply(x) - y).length() <= tol);
        let want = sampler.sample_physical(x);
        // Pattern values up to 125 with slopes up to ~100 per voxel: a preimage error of
        // 1e-6 voxel moves a linear sample by at most ~1e-4.
        assert!((v - want).abs() < 1e-3, "voxel {n}: {v} vs {want}");
    }
}

fn r_point(lat: &BSplineLattice, y: DVec3) -> DVec3 {
    let r = invert_point(lat, y, None, &volmorph_deform::InverseOptions::default());
    assert!(r.converged(), "{r:?}");
    r.point
}

#[test]
fn pulling_back_through_the_map_undoes_the_inverse_pullback() {
    // out(y) = in(φ⁻¹(y)), then back(x) = out(φ(x)) = in(x): two linear interpolations of a
    // smooth field, so a small error away from the borders.
    let g = Geometry::new([32, 30, 28]);
    let lat = moved_lattice(&g, 3.0);
    let input = smooth(g);
    let forward = pullback_through_inverse::<f32, f32, _>(
        &input,
        &lat,
        &g,
        &opts(Interpolation::CubicBSpline),
    )
    .unwrap();
    assert!(forward.report.is_clean());
    let back: Volume<f32> = resample(
        &forward.volume,
        &lat,
        &g,
        &ResampleOptions::new(Interpolation::CubicBSpline, -1.0),
    )
    .unwrap();
    let mut worst = 0.0f32;
    for k in 4..24 {
        for j in 4..26 {
            for i in 4..28 {
                worst = worst.max((back[[i, j, k]] - input[[i, j, k]]).abs());
            }
        }
    }
    assert!(worst < 0.05, "round trip error {worst}");
    // The map really moved things: the forward image differs from the input.
    assert!(max_diff(forward.volume.data(), input.data()) > 0.5);
}

#[test]
fn agrees_with_antialiased_push_forward_on_a_smooth_field() {
    let g = Geometry::new([32, 30, 28]);
    let lat = moved_lattice(&g, 3.0);
    let input = smooth(g);
    let inv =
        pullback_through_inverse::<f32, f32, _>(&input, &lat, &g, &opts(Interpolation::Linear))
            .unwrap();
    let push = push_forward_antialiased_f32(&input, &lat, &g, &AntialiasOptions::default())
        .unwrap()
        .volume;
    let mut sum = 0.0f64;
    let mut worst = 0.0f32;
    let mut n = 0;
    for k in 4..24 {
        for j in 4..26 {
            for i in 4..28 {
                let d = (inv.volume[[i, j, k]] - push[[i, j, k]]).abs();
                worst = worst.max(d);
                sum += f64::from(d);
                n += 1;
            }
        }
    }
    // The field spans ~13 units; the box filter blurs over about a voxel.
    assert!(
        sum / f64::from(n) < 0.1,
        "mean difference {}",
        sum / f64::from(n)
    );
    assert!(worst < 0.6, "worst difference {worst}");
    // The plain pull-back through the same map is a different picture (the other direction).
    let pulled: Volume<f32> = resample(&input, &lat, &g, &ResampleOptions::default()).unwrap();
    let mut other = 0.0f64;
    for k in 4..24 {
        for j in 4..26 {
            for i in 4..28 {
                other += f64::from((pulled[[i, j, k]] - push[[i, j, k]]).abs());
            }
        }
    }
    assert!(other / f64::from(n) > 2.0 * sum / f64::from(n));
}

#[test]
fn identity_lattice_copies_voxels_exactly() {
    let g = Geometry::new([12, 11, 10])
        .with_spacing(DVec3::new(0.7, 1.3, 1.1))
        .with_origin(DVec3::new(3.0, -2.0, 0.4));
    let (lo, hi) = g.physical_bounds();
    let lat =
        BSplineLattice::uniform_cubic_around(lo - DVec3::ONE, hi + DVec3::ONE, [6, 7, 5]).unwrap();
    let input = pattern(g);
    for interpolation in [Interpolation::Nearest, Interpolation::Linear] {
        let r = pullback_through_inverse::<f32, f32, _>(&input, &lat, &g, &opts(interpolation))
            .unwrap();
        assert_eq!(r.volume.data(), input.data(), "{interpolation:?}");
    }
}

#[test]
fn out_of_image_voxels_are_filled_counted_and_masked() {
    // Every control point moved +3 along x: inside the box φ(p) = p + 3x̂, outside the
    // identity, so the first 3 units of the box have no preimage.
    let g = Geometry::new([16, 8, 8]);
    let mut lat = BSplineLattice::uniform_cubic_around(
        DVec3::new(2.5, -2.0, -2.0),
        DVec3::splat(12.5),
        [6, 6, 6],
    )
    .unwrap();
    lat.map_control_points(|p| p + DVec3::new(3.0, 0.0, 0.0))
        .unwrap();
    let input = pattern(g);
    let r = pullback_through_inverse::<f32, f32, _>(
        &input,
        &lat,
        &g,
        &opts(Interpolation::Linear).with_mask(true),
    )
    .unwrap();
    let mask = r.mask.unwrap();
    // Voxels i = 3, 4, 5 (x in [2.5, 5.5)) have no preimage.
    assert_eq!(r.report.nonconverged, 3 * 8 * 8, "{}", r.report);
    assert_eq!(r.report.folded, 0);
    for k in 0..8 {
        for j in 0..8 {
            for i in 0..16 {
                let (v, m) = (r.volume[[i, j, k]], mask[[i, j, k]]);
                if (3..6).contains(&i) {
                    assert_eq!((v, m), (-1.0, MASK_NOT_CONVERGED), "({i},{j},{k})");
                } else if i < 3 {
                    assert_eq!((v, m), (input[[i, j, k]], MASK_CONVERGED));
                } else if i <= 12 {
                    assert_eq!((v, m), (input[[i - 3, j, k]], MASK_CONVERGED));
                }
            }
        }
    }
    assert_eq!(
        mask.data()
            .iter()
            .filter(|&&m| m == MASK_NOT_CONVERGED)
            .count(),
        r.report.nonconverged
    );
}

#[test]
fn folds_follow_one_sheet_and_are_flagged_where_found() {
    let g = Geometry::new([20, 12, 12]);
    let mut lat = BSplineLattice::uniform_cubic_around(
        DVec3::splat(-0.5),
        DVec3::new(19.5, 11.5, 11.5),
        [9, 7, 7],
    )
    .unwrap();
    // Push the central control columns past their neighbours: the map folds.
    for k in 2..5 {
        for j in 2..5 {
            lat.move_control_point([4, j, k], DVec3::new(7.0, 0.0, 0.0))
                .unwrap();
        }
    }
    let det = jacobian_determinant(&lat, &g).unwrap();
    assert!(det.data().iter().any(|&d| d <= 0.0), "the lattice folds");
    let input = smooth(g);
    let mut out = vec![0.0f32; g.len()];
    let mut mask = vec![9u8; g.len()];
    let report = pullback_through_inverse_into(
        &input,
        &lat,
        &g,
        &opts(Interpolation::Linear),
        &mut out,
        Some(&mut mask),
    )
    .unwrap();
    // Continuous and the identity on the box surface, the map covers every target, and the
    // row-coherent walk follows an unfolded sheet through the overlap: no failure, and the
    // values are samples at genuine preimages.
    assert_eq!(report.nonconverged, 0, "{report}");
    assert!(mask.iter().all(|&m| m != 9));
    // Walking the rows the other way follows the other unfolded sheet: where the map folds,
    // the preimage is not unique and the picture depends on the start.
    let flipped = Geometry {
        origin: g.index_to_physical(DVec3::new(19.0, 0.0, 0.0)),
        direction: DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)),
        ..g
    };
    let back = pullback_through_inverse::<f32, f32, _>(
        &input,
        &lat,
        &flipped,
        &opts(Interpolation::Linear),
    )
    .unwrap();
    let mut differ = 0;
    for k in 0..12 {
        for j in 0..12 {
            for i in 0..20 {
                if (back.volume[[19 - i, j, k]] - out[g.offset(i, j, k)]).abs() > 1e-3 {
                    differ += 1;
                }
            }
        }
    }
    assert!(differ > 0, "the overlap shows different sheets");
    // Control points mirrored along x: inside the box the map reverses orientation
    // (det J = −1), so every voxel whose preimage is found there is flagged as folded.
    let mut mirror = BSplineLattice::uniform_cubic_around(
        DVec3::new(4.5, -1.0, -1.0),
        DVec3::new(14.5, 13.0, 13.0),
        [7, 5, 5],
    )
    .unwrap();
    mirror
        .map_control_points(|p| DVec3::new(19.0 - p.x, p.y, p.z))
        .unwrap();
    let r = pullback_through_inverse::<f32, f32, _>(
        &input,
        &mirror,
        &g,
        &opts(Interpolation::Linear).with_mask(true),
    )
    .unwrap();
    // Voxels i = 5..=14 lie in the box and have their mirror image i' = 19 − i as preimage.
    assert_eq!(r.report.nonconverged, 0, "{}", r.report);
    assert_eq!(r.report.folded, 10 * 12 * 12, "{}", r.report);
    assert!(!r.report.is_clean());
    let m = r.mask.unwrap();
    for (i, j, k) in [(5, 0, 0), (9, 4, 7), (14, 11, 11)] {
        assert_eq!(m[[i, j, k]], MASK_FOLDED);
        assert!((r.volume[[i, j, k]] - input[[19 - i, j, k]]).abs() < 1e-5);
    }
    assert_eq!(m[[4, 3, 3]], MASK_CONVERGED);
    assert_eq!(
        mask.iter().filter(|&&m| m == MASK_FOLDED).count(),
        report.folded
    );
    assert_eq!(
        mask.iter().filter(|&&m| m == MASK_NOT_CONVERGED).count(),
        report.nonconverged
    );
    assert!(mask.iter().all(|&m| m <= MASK_FOLDED));
    let text = report.to_string();
    assert!(
        text.contains(&format!("{} of {}", report.nonconverged, g.len())),
        "{text}"
    );
}

#[test]
fn bad_options_and_buffers_are_errors() {
    let g = Geometry::new([4, 4, 4]);
    let input = pattern(g);
    let map = Affine::translation(DVec3::X);
    for t in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let o = opts(Interpolation::Linear).with_tolerance(t);
        assert!(matches!(
            pullback_through_inverse::<f32, f32, _>(&input, &map, &g, &o),
            Err(WarpError::InvalidOption(_))
        ));
    }
    let o = opts(Interpolation::Linear);
    let mut out = vec![0.0f32; 63];
    assert!(matches!(
        pullback_through_inverse_into(&input, &map, &g, &o, &mut out, None),
        Err(WarpError::BufferLength { .. })
    ));
    let mut out = vec![0.0f32; 64];
    let mut mask = vec![0u8; 65];
    assert!(matches!(
        pullback_through_inverse_into(&input, &map, &g, &o, &mut out, Some(&mut mask)),
        Err(WarpError::BufferLength { .. })
    ));
    let bad = g.with_spacing(DVec3::new(1.0, 0.0, 1.0));
    assert!(matches!(
        pullback_through_inverse::<f32, f32, _>(&input, &map, &bad, &o),
        Err(WarpError::Geometry { .. })
    ));
    // A clamped boundary and an integer output type.
    let o = opts(Interpolation::Linear).with_boundary(Boundary::Clamp);
    let r = pullback_through_inverse::<f32, u8, _>(&input, &map, &g, &o).unwrap();
    assert_eq!(r.volume[[0, 1, 1]], input[[0, 1, 1]].round() as u8);
}

#[test]
fn slab_wise_determinants_match_pointwise() {
    // 40 × 40 × 24 voxels: several slabs of whole z-slices, lattice partly off the grid.
    let g = Geometry::new([40, 40, 24])
        .with_spacing(DVec3::new(0.5, 0.6, 0.8))
        .with_origin(DVec3::new(-3.0, -2.0, -1.0));
    let lat = moved_lattice(&central_half(&g), 2.0);
    let det = jacobian_determinant(&lat, &g).unwrap();
    for k in 0..24 {
        for j in 0..40 {
            for i in 0..40 {
                let x = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                let want = lat.jacobian(x).determinant();
                let got = f64::from(det[[i, j, k]]);
                assert!(
                    (got - want).abs() <= 1e-6 * want.abs().max(1.0),
                    "({i},{j},{k}): {got} vs {want}"
                );
            }
        }
    }
}

/// The central half of a grid (so that the grid reaches outside a lattice built over it).
fn central_half(g: &Geometry) -> Geometry {
    let d = g.dims;
    Geometry {
        dims: [d[0] / 2, d[1] / 2, d[2] / 2],
        origin: g.index_to_physical(DVec3::new(
            (d[0] / 4) as f64,
            (d[1] / 4) as f64,
            (d[2] / 4) as f64,
        )),
        ..*g
    }
}
