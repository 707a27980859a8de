//! Newton inversion of lattice maps and the dense Jacobian paths: round trips on random
//! injective lattices, exact affine inverses, honest failure on folds and out-of-image
//! targets, and agreement of the one-pass and separable Jacobians with pointwise evaluation.

use glam::{DMat3, DVec3};
use volmorph_deform::inverse::first_order_guess;
use volmorph_deform::{
    Affine, Compose, DeformError, InverseOptions, InverseStatus, SpaceMap, invert_point,
};
use volmorph_lattice::BSplineLattice;
use volmorph_spline::KnotVector;
use volmorph_volume::Geometry;

use volmorph_testkit::Rng;

/// Every control point moved by a random vector of `[−scale/2, scale/2)³`.
fn displaced(mut lat: BSplineLattice, scale: f64, seed: u64) -> BSplineLattice {
    let mut r = Rng::new(seed);
    let [nx, ny, nz] = lat.counts();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                lat.move_control_point([i, j, k], r.point(0.5) * scale)
                    .unwrap();
            }
        }
    }
    lat
}

/// Only control points at least three layers from every side moved (the map stays C² and
/// the identity outside the box), by a random vector of `[−scale/2, scale/2)³`.
fn displaced_inside(mut lat: BSplineLattice, scale: f64, seed: u64) -> BSplineLattice {
    let mut r = Rng::new(seed);
    let [nx, ny, nz] = lat.counts();
    for k in 3..nz.saturating_sub(3) {
        for j in 3..ny.saturating_sub(3) {
            for i in 3..nx.saturating_sub(3) {
                lat.move_control_point([i, j, k], r.point(0.5) * scale)
                    .unwrap();
            }
        }
    }
    lat
}

fn oblique_axes() -> DMat3 {
    DMat3::from_axis_angle(DVec3::new(0.3, -0.5, 1.0).normalize(), 0.7)
}

/// Small random moves (a fifth of a cell at most) on cubic, oblique, non-uniform and Bézier
/// lattices: all injective.
fn injective_lattices() -> Vec<BSplineLattice> {
    let axes = oblique_axes();
    let corner = DVec3::new(-3.0, 2.0, 0.5);
    let extent = DVec3::new(10.0, 8.0, 12.0);
    let knots = [
        KnotVector::clamped(3, &[0.2, 0.45, 0.7], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(2, &[0.3, 0.6], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(4, &[0.5], [0.0, 1.0]).unwrap(),
    ];
    vec![
        displaced_inside(
            BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(12.0), [10, 10, 10])
                .unwrap(),
            0.6,
            1,
        ),
        displaced(
            BSplineLattice::uniform_cubic_in_box(corner, axes, extent, [7, 6, 8]).unwrap(),
            0.5,
            2,
        ),
        displaced(
            BSplineLattice::identity_in_box(corner, axes, extent, knots).unwrap(),
            0.4,
            3,
        ),
        displaced(
            BSplineLattice::bezier_in_box(corner, DMat3::IDENTITY, extent, [3, 2, 4]).unwrap(),
            0.8,
            4,
        ),
    ]
}

/// Random points of the lattice's box shrunk by the fraction `margin` of its size on every
/// side (grown for a negative margin).
fn points_in_box(lat: &BSplineLattice, n: usize, margin: f64, seed: u64) -> Vec<DVec3> {
    let mut r = Rng::new(seed);
    let d = lat.domain();
    (0..n)
        .map(|_| {
            let t =
                DVec3::splat(margin) + r.point_in(DVec3::ZERO, DVec3::ONE) * (1.0 - 2.0 * margin);
            let u = DVec3::new(
                d[0][0] + t.x * (d[0][1] - d[0][0]),
                d[1][0] + t.y * (d[1][1] - d[1][0]),
                d[2][0] + t.z * (d[2][1] - d[2][0]),
            );
            lat.frame().to_physical(u)
        })
        .collect()
}

#[test]
fn lattice_round_trips_both_ways() {
    let opts = InverseOptions::default();
    for (l, lat) in injective_lattices().iter().enumerate() {
        // Away from the box surface, where lattices with moved outer layers jump to the
        // identity outside (and the preimage would not be unique).
        for (n, &x) in points_in_box(lat, 300, 0.1, 10 + l as u64)
            .iter()
            .enumerate()
        {
            // Forward then back: the preimage of φ(x) is x (φ injective there).
            let y = lat.apply(x);
            let r = invert_point(lat, y, None, &opts);
            assert!(r.converged(), "lattice {l}, point {n}: {r:?}");
            assert!((lat.apply(r.point) - y).length() <= 1e-9, "{r:?}");
            assert!((r.point - x).length() <= 1e-9, "lattice {l}: {x} vs {r:?}");
            assert!(r.det_jacobian > 0.0);
            assert!((r.det_jacobian - lat.jacobian(r.point).determinant()).abs() < 1e-12);
            // Back then forward, for a target that is not an image of a sampled point.
            let y = x + DVec3::new(0.1, -0.05, 0.07);
            let r = invert_point(lat, y, None, &opts);
            assert!(r.converged(), "lattice {l}, target {y}: {r:?}");
            assert!((lat.apply(r.point) - y).length() <= 1e-9);
            assert!(r.iterations <= 8, "{r:?}");
        }
        // Outside the box the map is the identity, and so is its inverse.
        let far = lat.frame().to_physical(DVec3::splat(-5.0));
        let r = invert_point(lat, far, None, &opts);
        assert_eq!(
            (r.status, r.point, r.iterations),
            (InverseStatus::Converged, far, 0)
        );
    }
}

#[test]
fn a_caller_guess_is_used_and_a_bad_one_recovered_from() {
    let lat = &injective_lattices()[0];
    let x = DVec3::new(5.0, 6.5, 7.0);
    let y = lat.apply(x);
    let opts = InverseOptions::default().with_tolerance(1e-11);
    let exact = invert_point(lat, y, Some(x), &opts);
    assert_eq!((exact.iterations, exact.point), (0, x));
    let far = invert_point(lat, y, Some(x + DVec3::new(2.0, -2.0, 1.5)), &opts);
    assert!(far.converged(), "{far:?}");
    assert!((far.point - x).length() < 1e-9);
    let g = first_order_guess(lat, y);
    assert!(
        (g - x).length() < (y - x).length(),
        "first-order guess improves on y"
    );
}

#[test]
fn affine_and_composed_maps_invert_exactly() {
    let a = Affine {
        matrix: oblique_axes() * DMat3::from_diagonal(DVec3::new(1.5, 0.8, 2.0)),
        offset: DVec3::new(-4.0, 1.0, 7.5),
    };
    let inv = a.matrix.inverse();
    let mut r = Rng::new(99);
    for _ in 0..100 {
        let y = r.point(1.0) * 50.0;
        let p = invert_point(&a, y, None, &InverseOptions::default());
        assert!(p.converged() && p.iterations <= 1, "{p:?}");
        let want = inv * (y - a.offset);
        assert!((p.point - want).length() <= 1e-12 * want.length().max(1.0));
    }
    // A lattice after an affine map: the inverse is the lattice's inverse of the affine image.
    let lat = &injective_lattices()[1];
    let c = Compose(lat, Affine::translation(DVec3::new(0.3, 0.0, -0.2)));
    for x in points_in_box(lat, 50, 0.1, 7) {
        let y = c.apply(x);
        let p = invert_point(&c, y, None, &InverseOptions::default());
        assert!(p.converged(), "{p:?}");
        assert!((p.point - x).length() < 1e-9);
    }
}

#[test]
fn out_of_image_targets_are_not_reported_as_solutions() {
    // Every control point moved by +1.5 along x: inside the box the map is x ↦ x + 1.5, outside
    // it is the identity, so targets in the first 1.5 units of the box have no preimage.
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(9.0), [7, 7, 7]).unwrap();
    lat.map_control_points(|p| p + DVec3::new(1.5, 0.0, 0.0))
        .unwrap();
    let opts = InverseOptions::default();
    for y in [
        DVec3::new(0.2, 4.0, 4.0),
        DVec3::new(1.0, 1.0, 8.0),
        DVec3::new(1.4, 4.5, 2.0),
    ] {
        let r = invert_point(&lat, y, None, &opts);
        assert!(!r.converged(), "{y}: {r:?}");
        assert!(r.residual > 1e-3, "{r:?}");
        // The reported residual is the true one at the reported point.
        assert!((r.residual - (lat.apply(r.point) - y).length()).abs() < 1e-12);
    }
    // Targets well inside the shifted box still invert.
    let r = invert_point(&lat, DVec3::new(5.0, 4.0, 4.0), None, &opts);
    assert!(r.converged());
    assert!((r.point - DVec3::new(3.5, 4.0, 4.0)).length() < 1e-9);
}

/// A lattice folded by pushing the central control plane past its neighbours along x.
fn folded_lattice() -> BSplineLattice {
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(8.0), [9, 9, 9]).unwrap();
    for k in 3..6 {
        for j in 3..6 {
            lat.move_control_point([4, j, k], DVec3::new(3.0, 0.0, 0.0))
                .unwrap();
        }
    }
    lat
}

#[test]
fn folds_are_flagged_by_the_determinant_at_the_solution() {
    let lat = folded_lattice();
    // A point where the map folds, and its image.
    let x = (0..400)
        .map(|n| DVec3::new(2.0 + 4.0 * f64::from(n) / 400.0, 4.0, 4.0))
        .find(|&p| lat.jacobian(p).determinant() < -0.05)
        .expect("the lattice folds along its central line");
    let y = lat.apply(x);
    let opts = InverseOptions::default();
    // Started on the folded sheet, Newton returns a preimage there and says so.
    let on_fold = invert_point(&lat, y, Some(x + DVec3::new(0.01, 0.0, 0.0)), &opts);
    assert!(on_fold.converged(), "{on_fold:?}");
    assert!((lat.apply(on_fold.point) - y).length() <= 1e-9);
    assert!(on_fold.det_jacobian < 0.0, "{on_fold:?}");
    // Started elsewhere, it may find another preimage (not unique under a fold) — but
    // whatever it returns as converged really maps to y, and its determinant is reported.
    let mut signs = [0usize; 2];
    for n in 0..40 {
        let guess = DVec3::new(f64::from(n) * 0.2, 4.0, 4.0);
        let r = invert_point(&lat, y, Some(guess), &opts);
        if r.converged() {
            assert!((lat.apply(r.point) - y).length() <= 1e-9);
            let det = lat.jacobian(r.point).determinant();
            assert!((r.det_jacobian - det).abs() < 1e-9);
            signs[usize::from(det > 0.0)] += 1;
        } else {
            assert!(r.residual > opts.tolerance_for(y), "{r:?}");
        }
    }
    assert!(
        signs[0] > 0 && signs[1] > 0,
        "both sheets reached: {signs:?}"
    );
}

#[test]
fn nan_targets_and_guesses_never_panic() {
    let lat = &injective_lattices()[1];
    let opts = InverseOptions::default();
    for y in [
        DVec3::new(f64::NAN, 1.0, 1.0),
        DVec3::splat(f64::INFINITY),
        DVec3::new(0.0, f64::NEG_INFINITY, 0.0),
    ] {
        assert_eq!(
            invert_point(lat, y, None, &opts).status,
            InverseStatus::NonFinite
        );
    }
    let r = invert_point(lat, DVec3::ONE, Some(DVec3::new(0.0, f64::NAN, 0.0)), &opts);
    assert_eq!(r.status, InverseStatus::NonFinite);
    let r = invert_point(lat, DVec3::ONE, None, &opts.with_max_iterations(0));
    assert!(matches!(
        r.status,
        InverseStatus::Converged | InverseStatus::NotConverged
    ));
}

// ---------------------------------------------------------------------------------------
// Jacobians on grids

fn rel_close(a: DMat3, b: DMat3, tol: f64) -> bool {
    let scale = b
        .to_cols_array()
        .iter()
        .fold(1.0_f64, |m, v| m.max(v.abs()));
    (a - b).abs_diff_eq(DMat3::ZERO, tol * scale)
}

fn assert_jacobian_grid_matches(lat: &BSplineLattice, grid: &Geometry, out: &[DMat3]) {
    let [nx, ny, nz] = grid.dims;
    let mut inside = 0;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let x = grid.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                let want = lat.jacobian(x);
                let got = out[grid.offset(i, j, k)];
                assert!(
                    rel_close(got, want, 1e-10),
                    "voxel ({i},{j},{k}): {got:?} vs {want:?}"
                );
                if lat.contains(x) {
                    inside += 1;
                } else {
                    assert_eq!(got, DMat3::IDENTITY, "outside the box J = I");
                }
            }
        }
    }
    assert!(inside > 0 && inside < grid.len(), "grid straddles the box");
}

#[test]
fn one_pass_value_and_jacobian_agree_with_apply_and_jacobian() {
    for lat in injective_lattices() {
        for x in points_in_box(&lat, 200, -0.1, 5) {
            let (v, j) = lat.apply_with_jacobian(x);
            let want = lat.apply(x);
            assert!((v - want).length() <= 1e-13 * want.length().max(1.0));
            assert!(rel_close(j, lat.jacobian(x), 1e-13));
        }
    }
    // Degrees above the point kernel's buffers take the general path.
    let high = displaced(
        BSplineLattice::bezier_around(DVec3::ZERO, DVec3::ONE, [9, 2, 2]).unwrap(),
        0.05,
        6,
    );
    let x = DVec3::new(0.3, 0.6, 0.2);
    assert_eq!(
        high.apply_with_jacobian(x),
        (high.apply(x), high.jacobian(x))
    );
}

#[test]
fn separable_jacobian_grid_agrees_with_pointwise() {
    // Uniform cubic, every control point moved, grid reaching beyond the box.
    let lat = displaced(
        BSplineLattice::uniform_cubic_around(DVec3::splat(-0.5), DVec3::splat(11.5), [9, 9, 9])
            .unwrap(),
        1.5,
        21,
    );
    let grid = Geometry::new([17, 15, 14])
        .with_origin(DVec3::new(-2.0, -1.3, -2.1))
        .with_spacing(DVec3::new(0.9, 1.0, 1.1));
    let mut out = vec![DMat3::ZERO; grid.len()];
    lat.jacobian_grid_separable(&grid, &mut out).unwrap();
    assert_jacobian_grid_matches(&lat, &grid, &out);
    out.fill(DMat3::ZERO);
    lat.jacobian_grid(&grid, &mut out).unwrap();
    assert_jacobian_grid_matches(&lat, &grid, &out);

    // Grid axes against the lattice axes.
    let flipped = grid
        .with_origin(DVec3::new(13.0, -1.3, 12.0))
        .with_direction(DMat3::from_diagonal(DVec3::new(-1.0, 1.0, -1.0)));
    lat.jacobian_grid_separable(&flipped, &mut out).unwrap();
    assert_jacobian_grid_matches(&lat, &flipped, &out);

    // Oblique frame, non-uniform knots of degrees 3, 2, 4, grid sharing the lattice's axes.
    let axes = oblique_axes();
    let corner = DVec3::new(3.0, -2.0, 1.0);
    let extent = DVec3::new(3.0, 2.0, 2.5);
    let knots = [
        KnotVector::clamped(3, &[0.1, 0.45, 0.45], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(2, &[0.3], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(4, &[0.55], [0.0, 1.0]).unwrap(),
    ];
    let nonuni = displaced(
        BSplineLattice::identity_in_box(corner, axes, extent, knots).unwrap(),
        0.3,
        13,
    );
    let aligned = Geometry::new([9, 8, 8])
        .with_spacing(DVec3::new(0.43, 0.31, 0.37))
        .with_direction(axes)
        .with_origin(corner + axes * DVec3::new(-0.6, -0.4, -0.5));
    let mut out = vec![DMat3::ZERO; aligned.len()];
    nonuni.jacobian_grid_separable(&aligned, &mut out).unwrap();
    assert_jacobian_grid_matches(&nonuni, &aligned, &out);
    // Bézier lattice on the same grid.
    let bez = displaced(
        BSplineLattice::bezier_in_box(corner, axes, extent, [2, 3, 4]).unwrap(),
        0.3,
        12,
    );
    bez.jacobian_grid(&aligned, &mut out).unwrap();
    assert_jacobian_grid_matches(&bez, &aligned, &out);

    // A grid not parallel to the lattice: the separable path refuses, the trait falls back.
    let skew = aligned.with_direction(DMat3::IDENTITY);
    assert!(matches!(
        nonuni.jacobian_grid_separable(&skew, &mut out),
        Err(DeformError::GridNotAligned(_))
    ));
    nonuni.jacobian_grid(&skew, &mut out).unwrap();
    assert_jacobian_grid_matches(&nonuni, &skew, &out);

    // Bad buffers and grids are errors.
    assert!(matches!(
        lat.jacobian_grid(&grid, &mut out[1..]),
        Err(DeformError::BufferLength { .. })
    ));
    let bad = grid.with_spacing(DVec3::new(1.0, -1.0, 1.0));
    assert!(matches!(
        lat.jacobian_grid(&bad, &mut out),
        Err(DeformError::Grid(_))
    ));
}

#[test]
fn constant_jacobian_maps_fill_the_grid() {
    let grid = Geometry::new([4, 3, 2]);
    let a = Affine::linear(oblique_axes() * 2.0);
    let mut out = vec![DMat3::ZERO; grid.len()];
    a.jacobian_grid(&grid, &mut out).unwrap();
    assert!(out.iter().all(|&m| m == a.matrix));
    volmorph_deform::Identity
        .jacobian_grid(&grid, &mut out)
        .unwrap();
    assert!(out.iter().all(|&m| m == DMat3::IDENTITY));
    // Composition: chain rule through the default pointwise loop.
    let lat = &injective_lattices()[0];
    let c = Compose(a, lat);
    let g = Geometry::new([5, 5, 5]).with_spacing(DVec3::splat(2.5));
    let mut out = vec![DMat3::ZERO; g.len()];
    c.jacobian_grid(&g, &mut out).unwrap();
    for (n, m) in out.iter().enumerate() {
        let x = g.index_to_physical(DVec3::new(
            (n % 5) as f64,
            (n / 5 % 5) as f64,
            (n / 25) as f64,
        ));
        assert!(rel_close(*m, a.matrix * lat.jacobian(x), 1e-12));
    }
}
