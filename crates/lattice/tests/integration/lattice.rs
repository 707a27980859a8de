//! Properties of lattice maps: identity placements, locality, affine invariance, analytic
//! Jacobians, agreement of the dense grid paths with pointwise evaluation, JSON round trips.

use glam::{DMat3, DVec3};
use proptest::prelude::*;
use volmorph_deform::{Affine, Compose, DeformError, SpaceMap};
use volmorph_lattice::{BSplineLattice, LatticeFrame};
use volmorph_spline::KnotVector;
use volmorph_testkit::Rng;
use volmorph_volume::Geometry;

/// A rotation by `angle` about the normalised `axis` (orthonormal, right-handed).
fn rotation(axis: DVec3, angle: f64) -> DMat3 {
    DMat3::from_axis_angle(axis.normalize(), angle)
}

/// Random points of the box `corner + axes·(extent ⊙ t)`, `t ∈ [0, 1]³`, corners included.
fn box_points(corner: DVec3, axes: DMat3, extent: DVec3, n: usize, seed: u64) -> Vec<DVec3> {
    let mut r = Rng::new(seed);
    let mut pts: Vec<DVec3> = (0..n)
        .map(|_| corner + axes * (extent * r.point_in(DVec3::ZERO, DVec3::ONE)))
        .collect();
    for c in 0..8 {
        let t = DVec3::new(
            f64::from(c & 1),
            f64::from((c >> 1) & 1),
            f64::from((c >> 2) & 1),
        );
        pts.push(corner + axes * (extent * t));
    }
    pts
}

fn assert_identity(lat: &BSplineLattice, pts: &[DVec3]) {
    for &p in pts {
        let q = lat.apply(p);
        assert!(
            (q - p).length() <= 1e-12 * p.length().max(1.0),
            "{p} ↦ {q} ({:e})",
            (q - p).length()
        );
        let j = lat.jacobian(p);
        assert!(
            j.abs_diff_eq(DMat3::IDENTITY, 1e-12),
            "Jacobian at {p}: {j:?}"
        );
    }
}

/// Interior of True's lattice perturbed at random (outer three layers left in place), plus a
/// few border points moved.
fn displaced(mut lat: BSplineLattice, scale: f64, seed: u64) -> BSplineLattice {
    let mut r = Rng::new(seed);
    let [nx, ny, nz] = lat.counts();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let d = r.point(0.5) * scale;
                lat.move_control_point([i, j, k], d).unwrap();
            }
        }
    }
    lat
}

#[test]
fn uniform_cubic_identity_axis_aligned_and_odd_counts() {
    for counts in [[4, 4, 4], [9, 9, 9], [5, 7, 4], [12, 4, 6]] {
        let (lo, hi) = (DVec3::new(-3.0, 10.0, 0.5), DVec3::new(7.0, 14.0, 100.0));
        let lat = BSplineLattice::uniform_cubic_around(lo, hi, counts).unwrap();
        assert_eq!(lat.counts(), counts);
        assert_eq!(lat.degree(), [3, 3, 3]);
        assert_identity(&lat, &box_points(lo, DMat3::IDENTITY, hi - lo, 300, 7));
    }
}

#[test]
fn uniform_cubic_placement_matches_true_fig8() {
    // 9 control points, 6 regions of length 2 on [0, 12]: control points at −2, 0, …, 14.
    let lat =
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::new(12.0, 6.0, 3.0), [9, 7, 4])
            .unwrap();
    for i in 0..9 {
        let p = lat.control_point([i, 0, 0]).unwrap();
        assert_eq!(p, DVec3::new(2.0 * (i as f64 - 1.0), -1.5, -3.0));
    }
    assert_eq!(
        lat.control_point([8, 6, 3]).unwrap(),
        DVec3::new(14.0, 7.5, 6.0)
    );
    assert_eq!(
        lat.identity_position([8, 6, 3]).unwrap(),
        DVec3::new(14.0, 7.5, 6.0)
    );
    assert_eq!(lat.domain(), [[0.0, 6.0], [0.0, 4.0], [0.0, 1.0]]);
}

#[test]
fn rotated_translated_nonuniform_and_bezier_identities() {
    let axes = rotation(DVec3::new(1.0, 2.0, -0.5), 0.7);
    let corner = DVec3::new(100.0, -20.0, 3.0);
    let extent = DVec3::new(4.0, 9.0, 2.5);
    let pts = box_points(corner, axes, extent, 300, 11);
    let cubic = BSplineLattice::uniform_cubic_in_box(corner, axes, extent, [6, 5, 8]).unwrap();
    assert_identity(&cubic, &pts);
    let knots = [
        KnotVector::clamped(3, &[0.1, 0.15, 0.6, 0.6], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(2, &[0.3, 2.0], [-1.0, 5.0]).unwrap(),
        KnotVector::new(1, vec![0.0, 0.5, 0.7, 2.0, 2.1]).unwrap(),
    ];
    let nonuni = BSplineLattice::identity_in_box(corner, axes, extent, knots.clone()).unwrap();
    assert_identity(&nonuni, &pts);
    let bez = BSplineLattice::bezier_in_box(corner, axes, extent, [2, 3, 1]).unwrap();
    assert_eq!(bez.counts(), [3, 4, 2]);
    assert_identity(&bez, &pts);
    // Sederberg–Parry placement: corner + axes·(extent ⊙ (i/l, j/m, k/n)).
    let p = bez.control_point([1, 2, 1]).unwrap();
    let want = corner + axes * (extent * DVec3::new(0.5, 2.0 / 3.0, 1.0));
    assert!((p - want).length() < 1e-12 * want.length());
    let aligned = BSplineLattice::identity_around(DVec3::ZERO, DVec3::ONE, knots).unwrap();
    assert_identity(
        &aligned,
        &box_points(DVec3::ZERO, DMat3::IDENTITY, DVec3::ONE, 100, 3),
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]
    #[test]
    fn identity_for_any_counts_and_box(
        nx in 4usize..12, ny in 4usize..12, nz in 4usize..12,
        lo in prop::array::uniform3(-50.0f64..50.0),
        ext in prop::array::uniform3(0.01f64..80.0),
        seed in any::<u64>(),
    ) {
        let lo = DVec3::from_array(lo);
        let ext = DVec3::from_array(ext);
        let lat = BSplineLattice::uniform_cubic_around(lo, lo + ext, [nx, ny, nz]).unwrap();
        for p in box_points(lo, DMat3::IDENTITY, ext, 20, seed) {
            let q = lat.apply(p);
            prop_assert!((q - p).length() <= 1e-12 * p.length().max(ext.max_element()));
        }
    }
}

#[test]
fn outside_the_box_points_are_not_moved() {
    let lat = displaced(
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(6.0), [9, 9, 9]).unwrap(),
        0.5,
        5,
    );
    for p in [
        DVec3::new(-0.001, 3.0, 3.0),
        DVec3::new(3.0, 6.0001, 3.0),
        DVec3::new(1e9, -1e9, 0.0),
    ] {
        assert_eq!(lat.apply(p), p);
        assert_eq!(lat.jacobian(p), DMat3::IDENTITY);
        assert!(!lat.contains(p));
    }
    assert!(lat.contains(DVec3::splat(6.0)));
    let nan = DVec3::new(f64::NAN, 1.0, 1.0);
    assert!(lat.apply(nan).x.is_nan());
}

#[test]
fn moving_a_control_point_changes_only_its_support() {
    let base =
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::new(6.0, 6.0, 12.0), [9, 9, 9])
            .unwrap();
    let base = displaced(base, 0.3, 9);
    let mut moved = base.clone();
    let idx = [4, 2, 6];
    moved
        .move_control_point(idx, DVec3::new(0.7, -1.1, 2.0))
        .unwrap();
    let dd = moved.displacement(idx).unwrap() - base.displacement(idx).unwrap();
    assert!((dd - DVec3::new(0.7, -1.1, 2.0)).length() < 1e-14);
    // Basis function i of knots −3 … n is supported on parameters [i − 3, i + 1].
    let support = |a: usize, u: f64| u > idx[a] as f64 - 3.0 && u < idx[a] as f64 + 1.0;
    let mut r = Rng::new(21);
    let (mut inside, mut outside) = (0, 0);
    for _ in 0..4000 {
        let p = DVec3::new(6.0, 6.0, 12.0) * r.point_in(DVec3::ZERO, DVec3::ONE);
        let u = base.frame().to_parameter(p);
        if support(0, u.x) && support(1, u.y) && support(2, u.z) {
            inside += 1;
            assert_ne!(moved.apply(p), base.apply(p));
        } else {
            outside += 1;
            assert_eq!(moved.apply(p), base.apply(p), "{p} outside support changed");
        }
    }
    assert!(inside > 100 && outside > 100);
}

#[test]
fn affine_invariance() {
    let axes = rotation(DVec3::new(0.3, -1.0, 0.2), 1.1);
    let lat = displaced(
        BSplineLattice::uniform_cubic_in_box(
            DVec3::new(1.0, 2.0, 3.0),
            axes,
            DVec3::new(5.0, 3.0, 4.0),
            [7, 5, 6],
        )
        .unwrap(),
        0.8,
        33,
    );
    let a = Affine {
        matrix: DMat3::from_cols(
            DVec3::new(1.5, 0.2, -0.3),
            DVec3::new(0.1, 0.9, 0.4),
            DVec3::new(-0.2, 0.3, 2.0),
        ),
        offset: DVec3::new(-4.0, 7.0, 0.5),
    };
    let mut transformed = lat.clone();
    transformed.map_control_points(|p| a.apply(p)).unwrap();
    let composed = Compose(a, &lat);
    // Box corners may round to just outside the box, where neither map moves points.
    let pts = box_points(
        DVec3::new(1.0, 2.0, 3.0),
        axes,
        DVec3::new(5.0, 3.0, 4.0),
        400,
        4,
    );
    let inside: Vec<DVec3> = pts.into_iter().filter(|&p| lat.contains(p)).collect();
    assert!(inside.len() >= 400);
    for p in inside {
        let want = composed.apply(p);
        let got = transformed.apply(p);
        assert!(
            (got - want).length() <= 1e-12 * want.length(),
            "{got} vs {want}"
        );
        let jd = transformed.jacobian(p) - composed.jacobian(p);
        assert!(jd.abs_diff_eq(DMat3::ZERO, 1e-12));
    }
}

/// The trait's default central-difference Jacobian, for comparison.
struct Numeric<'a>(&'a BSplineLattice);
impl SpaceMap for Numeric<'_> {
    fn apply(&self, p: DVec3) -> DVec3 {
        self.0.apply(p)
    }
}

#[test]
fn analytic_jacobian_matches_central_differences() {
    let axes = rotation(DVec3::new(-1.0, 0.5, 0.25), 0.4);
    let corner = DVec3::new(-2.0, 0.0, 1.0);
    let extent = DVec3::new(8.0, 5.0, 6.0);
    let cubic = displaced(
        BSplineLattice::uniform_cubic_in_box(corner, axes, extent, [8, 6, 7]).unwrap(),
        1.0,
        2,
    );
    let knots = [
        KnotVector::clamped(2, &[0.2, 0.5, 0.5], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(4, &[0.7], [0.0, 1.0]).unwrap(),
        KnotVector::bezier(3, [0.0, 1.0]).unwrap(),
    ];
    let general = displaced(
        BSplineLattice::identity_in_box(corner, axes, extent, knots).unwrap(),
        1.0,
        3,
    );
    // Points well inside the box so the difference stencil stays inside.
    let inner = corner + axes * (extent * 0.05);
    for lat in [&cubic, &general] {
        for p in box_points(inner, axes, extent * 0.9, 200, 8) {
            let a = lat.jacobian(p);
            let n = Numeric(lat).jacobian(p);
            let scale = a
                .to_cols_array()
                .iter()
                .fold(1.0_f64, |m, v| m.max(v.abs()));
            assert!(
                (a - n).abs_diff_eq(DMat3::ZERO, 1e-7 * scale),
                "{a:?} vs {n:?}"
            );
        }
    }
}

/// Compare a grid evaluation with pointwise `apply`.
fn assert_grid_matches(lat: &BSplineLattice, grid: &Geometry, out: &[DVec3]) {
    let [nx, ny, nz] = grid.dims;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let x = grid.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                let want = lat.apply(x);
                let got = out[grid.offset(i, j, k)];
                assert!(
                    (got - want).length() <= 1e-12 * want.length().max(1.0),
                    "voxel ({i},{j},{k}): {got} vs {want}"
                );
            }
        }
    }
}

#[test]
fn dense_paths_agree_with_pointwise_apply() {
    // Box [−0.5, 11.5]³ in 6 regions of 2 voxels (G = 2), grid reaching 2 voxels beyond it.
    let lat = displaced(
        BSplineLattice::uniform_cubic_around(DVec3::splat(-0.5), DVec3::splat(11.5), [9, 9, 9])
            .unwrap(),
        0.6,
        17,
    );
    let grid = Geometry::new([16, 15, 14]).with_origin(DVec3::new(-2.0, -1.0, -2.0));
    let mut out = vec![DVec3::ZERO; grid.len()];
    lat.apply_grid_table(&grid, &mut out).unwrap();
    assert_grid_matches(&lat, &grid, &out);
    out.fill(DVec3::ZERO);
    lat.apply_grid_separable(&grid, &mut out).unwrap();
    assert_grid_matches(&lat, &grid, &out);
    out.fill(DVec3::ZERO);
    lat.apply_grid(&grid, &mut out).unwrap();
    assert_grid_matches(&lat, &grid, &out);

    // Different integer G per axis, non-cubic counts, anisotropic spacing.
    let lat2 = displaced(
        BSplineLattice::uniform_cubic_around(
            DVec3::new(0.25, -0.3, 0.1),
            DVec3::new(
                0.25 + 3.0 * 0.5 * 3.0,
                -0.3 + 4.0 * 0.2 * 4.0,
                0.1 + 1.0 * 5.0,
            ),
            [6, 7, 4],
        )
        .unwrap(),
        0.2,
        5,
    );
    let grid2 = Geometry::new([20, 18, 7])
        .with_spacing(DVec3::new(0.5, 0.2, 1.0))
        .with_origin(DVec3::new(-0.5, -0.5, -0.4));
    let mut out2 = vec![DVec3::ZERO; grid2.len()];
    lat2.apply_grid_table(&grid2, &mut out2).unwrap();
    assert_grid_matches(&lat2, &grid2, &out2);
    lat2.apply_grid_separable(&grid2, &mut out2).unwrap();
    assert_grid_matches(&lat2, &grid2, &out2);

    // Grid axes running against the lattice axes (x and z flipped), same voxel centres.
    let flipped = Geometry::new([16, 15, 14])
        .with_origin(DVec3::new(13.0, -1.0, 11.0))
        .with_direction(DMat3::from_diagonal(DVec3::new(-1.0, 1.0, -1.0)));
    let mut outf = vec![DVec3::ZERO; flipped.len()];
    lat.apply_grid_table(&flipped, &mut outf).unwrap();
    assert_grid_matches(&lat, &flipped, &outf);
    outf.fill(DVec3::ZERO);
    lat.apply_grid_separable(&flipped, &mut outf).unwrap();
    assert_grid_matches(&lat, &flipped, &outf);
    for k in 0..14 {
        for j in 0..15 {
            for i in 0..16 {
                let a = out[grid.offset(i, j, k)];
                let b = outf[flipped.offset(15 - i, j, 13 - k)];
                assert!((a - b).length() <= 1e-12 * a.length().max(1.0));
            }
        }
    }

    // Non-integer G: only the separable path applies.
    let grid3 = Geometry::new([17, 13, 11])
        .with_spacing(DVec3::new(0.77, 0.93, 1.1))
        .with_origin(DVec3::new(-1.3, -0.9, -1.01));
    let mut out3 = vec![DVec3::ZERO; grid3.len()];
    assert!(matches!(
        lat.apply_grid_table(&grid3, &mut out3),
        Err(DeformError::TableUnavailable(_))
    ));
    lat.apply_grid_separable(&grid3, &mut out3).unwrap();
    assert_grid_matches(&lat, &grid3, &out3);
    lat.apply_grid(&grid3, &mut out3).unwrap();
    assert_grid_matches(&lat, &grid3, &out3);
}

#[test]
fn dense_paths_on_rotated_nonuniform_and_bezier_lattices() {
    let axes = rotation(DVec3::new(0.2, 0.4, 1.0), 0.9);
    let corner = DVec3::new(3.0, -2.0, 1.0);
    // Bézier lattice of degrees (2, 3, 4) spanning 6, 4, 5 voxels of a grid sharing its axes.
    let bez = displaced(
        BSplineLattice::bezier_in_box(corner, axes, DVec3::new(3.0, 2.0, 2.5), [2, 3, 4]).unwrap(),
        0.3,
        12,
    );
    let grid = Geometry::new([9, 8, 8])
        .with_spacing(DVec3::splat(0.5))
        .with_direction(axes)
        .with_origin(corner + axes * DVec3::new(-0.75, -0.75, -0.75));
    let mut out = vec![DVec3::ZERO; grid.len()];
    bez.apply_grid_table(&grid, &mut out).unwrap();
    assert_grid_matches(&bez, &grid, &out);
    bez.apply_grid_separable(&grid, &mut out).unwrap();
    assert_grid_matches(&bez, &grid, &out);

    let knots = [
        KnotVector::clamped(3, &[0.1, 0.45, 0.45], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(2, &[0.3], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(1, &[0.5], [0.0, 1.0]).unwrap(),
    ];
    let nonuni = displaced(
        BSplineLattice::identity_in_box(corner, axes, DVec3::new(3.0, 2.0, 2.5), knots).unwrap(),
        0.3,
        13,
    );
    assert!(matches!(
        nonuni.apply_grid_table(&grid, &mut out),
        Err(DeformError::TableUnavailable(_))
    ));
    nonuni.apply_grid_separable(&grid, &mut out).unwrap();
    assert_grid_matches(&nonuni, &grid, &out);

    // A grid not parallel to the lattice: fast paths refuse, apply_grid falls back.
    let skew = grid.with_direction(DMat3::IDENTITY);
    assert!(matches!(
        nonuni.apply_grid_separable(&skew, &mut out),
        Err(DeformError::GridNotAligned(_))
    ));
    nonuni.apply_grid(&skew, &mut out).unwrap();
    assert_grid_matches(&nonuni, &skew, &out);
    assert!(matches!(
        nonuni.apply_grid(&skew, &mut out[1..]),
        Err(DeformError::BufferLength { .. })
    ));
}

#[test]
fn json_round_trip_is_exact() {
    let axes = rotation(DVec3::new(1.0, 1.0, 0.3), 0.123_456_789);
    let lat = displaced(
        BSplineLattice::uniform_cubic_in_box(
            DVec3::new(0.1, 0.2, 0.3),
            axes,
            DVec3::new(1.0 / 3.0, 2.0, 7.0),
            [5, 7, 4],
        )
        .unwrap(),
        0.1,
        99,
    );
    let text = lat.to_json().unwrap();
    let back = BSplineLattice::from_json(&text).unwrap();
    assert_eq!(back, lat);
    assert_eq!(back.to_json().unwrap(), text);
    let knots = [
        KnotVector::clamped(2, &[0.3], [0.0, 1.0]).unwrap(),
        KnotVector::bezier(1, [0.0, 2.0]).unwrap(),
        KnotVector::new(3, vec![0.0, 0.1, 0.25, 0.3, 0.7, 0.71, 0.9, 1.3, 2.0]).unwrap(),
    ];
    let general = BSplineLattice::identity_around(DVec3::ZERO, DVec3::ONE, knots).unwrap();
    assert_eq!(
        BSplineLattice::from_json(&general.to_json().unwrap()).unwrap(),
        general
    );
}

#[test]
fn malformed_json_is_rejected_with_clear_errors() {
    let lat = BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::ONE, [4, 5, 4]).unwrap();
    let text = lat.to_json().unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let edit = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut w = v.clone();
        f(&mut w);
        BSplineLattice::from_json(&w.to_string()).unwrap_err()
    };
    let msg = |e: DeformError| e.to_string();
    assert!(msg(edit(&|w| w["version"] = 2.into())).contains("version 2"));
    assert!(msg(edit(&|w| w["kind"] = "tps".into())).contains("tps"));
    assert!(msg(edit(&|w| w["counts"][1] = 0.into())).contains("counts[1] is zero"));
    assert!(msg(edit(&|w| w["counts"][1] = 6.into())).contains("counts[1] = 6"));
    assert!(
        msg(edit(&|w| {
            w["control_points"].as_array_mut().unwrap().pop();
        }))
        .contains("79 control points, expected 80")
    );
    assert!(matches!(
        edit(&|w| w["control_points"][3][1] = serde_json::Value::Null),
        DeformError::Json { .. }
    ));
    assert!(matches!(
        edit(&|w| w["control_points"][3] = serde_json::json!([1.0, 2.0])),
        DeformError::Json { .. }
    ));
    assert!(matches!(
        edit(&|w| w["frame"]["spacing"][2] = (-1.0).into()),
        DeformError::InvalidFrame(_)
    ));
    assert!(matches!(
        edit(&|w| w["frame"]["axes"][0] = serde_json::json!([1.0, 0.1, 0.0])),
        DeformError::InvalidFrame(_)
    ));
    assert!(matches!(
        edit(&|w| w["knots"][0][2] = 100.into()),
        DeformError::Spline(_)
    ));
    let degree0 = edit(&|w| {
        w["degrees"][2] = 0.into();
        w["knots"][2] = serde_json::json!([0.0, 0.25, 0.5, 0.75, 1.0]);
    });
    assert!(degree0.to_string().contains("degree"), "{degree0}");
    assert!(matches!(
        edit(&|w| w["extra"] = 1.into()),
        DeformError::Json { .. }
    ));
    assert!(matches!(
        edit(&|w| w["counts"] = serde_json::json!([1 << 20, 1 << 20, 4])),
        DeformError::InvalidDescription(_)
    ));
    assert!(BSplineLattice::from_json("{").is_err());
    assert!(BSplineLattice::from_json(&text.replace("-1.0", "NaN")).is_err());
    assert!(BSplineLattice::from_json(&text.replace("-1.0", "1e999")).is_err());
}

#[test]
fn construction_and_editing_errors() {
    assert!(matches!(
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::ONE, [9, 3, 9]),
        Err(DeformError::TooFewControlPoints {
            axis: 1,
            count: 3,
            min: 4
        })
    ));
    assert!(matches!(
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::new(1.0, 0.0, 1.0), [4, 4, 4]),
        Err(DeformError::DegenerateBox { axis: 1, .. })
    ));
    assert!(matches!(
        BSplineLattice::uniform_cubic_around(
            DVec3::ZERO,
            DVec3::new(1.0, 1.0, f64::NAN),
            [4, 4, 4]
        ),
        Err(DeformError::DegenerateBox { axis: 2, .. })
    ));
    assert!(matches!(
        BSplineLattice::bezier_around(DVec3::ZERO, DVec3::ONE, [1, 0, 2]),
        Err(DeformError::TooFewControlPoints { axis: 1, .. })
    ));
    assert!(matches!(
        BSplineLattice::uniform_cubic_in_box(
            DVec3::ZERO,
            DMat3::from_diagonal(DVec3::new(1.0, 2.0, 1.0)),
            DVec3::ONE,
            [4, 4, 4]
        ),
        Err(DeformError::InvalidFrame(_))
    ));
    assert!(LatticeFrame::axis_aligned(DVec3::ZERO, DVec3::new(1.0, 0.0, 1.0)).is_err());
    let mut lat = BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::ONE, [4, 4, 4]).unwrap();
    assert!(matches!(
        lat.control_point([4, 0, 0]),
        Err(DeformError::IndexOutOfRange { .. })
    ));
    assert!(matches!(
        lat.set_control_point([0, 0, 0], DVec3::new(f64::NAN, 0.0, 0.0)),
        Err(DeformError::NonFinite { .. })
    ));
    assert!(lat.move_control_point([0, 0, 4], DVec3::ONE).is_err());
    assert!(lat.displacement([3, 3, 3]).unwrap() == DVec3::ZERO);
    let before = lat.clone();
    assert!(lat.map_control_points(|p| p * f64::INFINITY).is_err());
    assert_eq!(lat, before);
}

#[test]
fn grid_plans_are_reusable_across_control_point_edits() {
    use volmorph_lattice::grid::{GridPath, LatticeGridPlan};
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::splat(-0.5), DVec3::splat(11.5), [9, 9, 9])
            .unwrap();
    let grid = Geometry::new([14, 13, 12]).with_origin(DVec3::splat(-1.0));
    let plans = [
        LatticeGridPlan::new(&lat, &grid, GridPath::Table).unwrap(),
        LatticeGridPlan::new(&lat, &grid, GridPath::Separable).unwrap(),
    ];
    assert_eq!(plans[0].path(), GridPath::Table);
    assert_eq!(plans[1].grid(), &grid);
    let mut out = vec![DVec3::ZERO; grid.len()];
    for seed in 0..3 {
        lat = displaced(lat, 0.4, seed);
        for plan in &plans {
            out.fill(DVec3::ZERO);
            plan.apply(&lat, &mut out).unwrap();
            assert_grid_matches(&lat, &grid, &out);
        }
    }
    let other =
        BSplineLattice::uniform_cubic_around(DVec3::splat(-0.5), DVec3::splat(11.5), [9, 9, 8])
            .unwrap();
    assert!(matches!(
        plans[0].apply(&other, &mut out),
        Err(DeformError::GridNotAligned(_))
    ));
    assert!(matches!(
        plans[1].apply(&lat, &mut out[..5]),
        Err(DeformError::BufferLength { .. })
    ));
    let empty = Geometry::new([0, 4, 4]);
    let mut none: Vec<DVec3> = Vec::new();
    // Geometries with a zero dimension are invalid volmorph grids.
    assert!(matches!(
        lat.apply_grid_separable(&empty, &mut none),
        Err(DeformError::Grid(_))
    ));
    assert!(matches!(
        lat.apply_grid_table(&empty, &mut none),
        Err(DeformError::Grid(_))
    ));
    assert!(matches!(
        lat.apply_grid(&empty, &mut none),
        Err(DeformError::Grid(_))
    ));
}

#[test]
fn continuous_across_the_box_surface_iff_outer_layers_stay() {
    let (lo, hi) = (DVec3::ZERO, DVec3::new(6.0, 4.0, 5.0));
    let mut lat = BSplineLattice::uniform_cubic_around(lo, hi, [9, 8, 9]).unwrap();
    let mut r = Rng::new(77);
    // Move only the control points off the three outermost layers on every side.
    let [nx, ny, nz] = lat.counts();
    for k in 3..nz - 3 {
        for j in 3..ny - 3 {
            for i in 3..nx - 3 {
                lat.move_control_point([i, j, k], r.point(0.5) * 2.0)
                    .unwrap();
            }
        }
    }
    let eps = 1e-9;
    let jump = |lat: &BSplineLattice, p: DVec3, n: DVec3| {
        (lat.apply(p - eps * n) - lat.apply(p + eps * n)).length()
    };
    let mut max_jump = 0.0_f64;
    for _ in 0..200 {
        let t = r.point_in(DVec3::ZERO, DVec3::ONE) * (hi - lo);
        for (p, n) in [
            (DVec3::new(0.0, t.y, t.z), DVec3::NEG_X),
            (DVec3::new(6.0, t.y, t.z), DVec3::X),
            (DVec3::new(t.x, 0.0, t.z), DVec3::NEG_Y),
            (DVec3::new(t.x, 4.0, t.z), DVec3::Y),
            (DVec3::new(t.x, t.y, 0.0), DVec3::NEG_Z),
            (DVec3::new(t.x, t.y, 5.0), DVec3::Z),
        ] {
            max_jump = max_jump.max(jump(&lat, p, n));
        }
    }
    // Only the 2ε step itself plus rounding (the map is C² there, Jacobian I on the surface).
    assert!(max_jump <= 2.0 * eps + 1e-13, "jump {max_jump:e}");
    // Moving a point of the second layer opens a gap on the face x = 0.
    lat.move_control_point([1, 4, 4], DVec3::new(0.0, 0.5, 0.0))
        .unwrap();
    assert!(jump(&lat, DVec3::new(0.0, 2.0, 2.5), DVec3::NEG_X) > 1e-3);
}

/// Feng 2002 §3.1.2–3.1.3: the uniform and end-interpolating initial volumes fix every point of
/// the box with Jacobian `I`, parameters equal coordinates, and the end-interpolating control
/// points follow Eq. (2).
#[test]
fn feng_initial_volumes_are_the_identity_with_eq2_spacing() {
    let (min, max) = (DVec3::new(-2.0, 1.0, 3.5), DVec3::new(4.0, 2.5, 9.0));
    let extent = max - min;
    let pts = box_points(min, DMat3::IDENTITY, extent, 200, 17);
    for degrees in [[2, 2, 2], [1, 2, 3], [3, 3, 1], [4, 2, 2]] {
        for counts in [[6, 8, 6], [5, 4, 7], [9, 9, 9]] {
            if (0..3).any(|a| counts[a] < degrees[a] + 1) {
                continue;
            }
            let uni = BSplineLattice::feng_uniform_around(min, max, degrees, counts).unwrap();
            let end =
                BSplineLattice::feng_end_interpolating_around(min, max, degrees, counts).unwrap();
            for lat in [&uni, &end] {
                assert_eq!(lat.counts(), counts);
                assert_eq!(lat.degree(), degrees);
                assert_eq!(
                    lat.frame().to_parameter(DVec3::new(1.5, -7.0, 2.0)),
                    DVec3::new(1.5, -7.0, 2.0)
                );
                for &p in &pts {
                    let q = lat.apply(p);
                    assert!((q - p).length() <= 1e-12 * p.length().max(1.0), "{p} ↦ {q}");
                    let j = lat.jacobian(p) - DMat3::IDENTITY;
                    assert!(
                        j.abs_diff_eq(DMat3::ZERO, 1e-12),
                        "{degrees:?} {counts:?} {j}"
                    );
                }
            }
            assert!(end.knots().iter().all(KnotVector::is_clamped));
            // Eq. (2) along x on the row j = k = 0: gaps u, 2u, …, ku from each end.
            let (k, n) = (degrees[0], counts[0]);
            let h = extent.x / (n - k) as f64;
            let xs: Vec<f64> = (0..n)
                .map(|i| end.control_point([i, 0, 0]).unwrap().x)
                .collect();
            assert!((xs[0] - min.x).abs() < 1e-12 && (xs[n - 1] - max.x).abs() < 1e-12);
            // Eq. (2) as stated holds when the two end ramps do not overlap (n ≥ 2k).
            for s in (0..n - 1).filter(|_| n >= 2 * k || n == k + 1) {
                let from_end = s.min(n - 2 - s);
                let want = if n == k + 1 {
                    extent.x / k as f64
                } else {
                    h * ((from_end + 1).min(k)) as f64 / k as f64
                };
                assert!(
                    (xs[s + 1] - xs[s] - want).abs() < 1e-12,
                    "{degrees:?} {counts:?} gap {s}"
                );
            }
        }
    }
    assert!(BSplineLattice::feng_uniform_around(min, max, [2, 0, 2], [4, 4, 4]).is_err());
    assert!(BSplineLattice::feng_uniform_around(min, max, [3, 3, 3], [3, 4, 4]).is_err());
    assert!(
        BSplineLattice::feng_uniform_around(min, DVec3::new(4.0, 1.0, 9.0), [2; 3], [4; 3])
            .is_err()
    );
}

/// Cox–de Boor recursion, written out here independently of `volmorph_spline` (the last
/// basis function is 1 at the right end of a clamped vector).
fn cox_de_boor(knots: &[f64], i: usize, p: usize, u: f64) -> f64 {
    let last = knots[knots.len() - 1];
    if p == 0 {
        let (a, b) = (knots[i], knots[i + 1]);
        return if (a <= u && u < b) || (u == last && b == last && a < b) {
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

/// Feng 2002 §3.1.1, Fig. 2b: the forward-mapped end-interpolating volume with evenly spaced
/// control points does not reproduce the object (the identity forms do): every point moves by
/// `d(x) = Σ N_i(x)(x_i − ξ_i)` per axis, towards the centre plane, zero on the faces and on a
/// Bézier axis.
#[test]
fn feng_forward_mapping_warps_by_the_predicted_displacement() {
    use volmorph_lattice::FengForm;
    let (min, max) = (DVec3::new(-2.0, 1.0, 3.5), DVec3::new(4.0, 2.5, 9.0));
    let extent = max - min;
    let centre = 0.5 * (min + max);
    let pts = box_points(min, DMat3::IDENTITY, extent, 300, 23);
    // Fig. 2's volume (degree 2×2×1, lattice 4×4×2) and two richer ones.
    for (degrees, counts) in [
        ([2, 2, 1], [4, 4, 2]),
        ([2, 3, 2], [6, 5, 3]),
        ([3, 1, 2], [7, 2, 5]),
    ] {
        let fwd = BSplineLattice::feng_around_model(min, max, degrees, counts, FengForm::Forward)
            .unwrap();
        let end = BSplineLattice::feng_around_model(
            min,
            max,
            degrees,
            counts,
            FengForm::EndInterpolating,
        )
        .unwrap();
        assert_eq!(fwd.knots(), end.knots());
        let mut largest: f64 = 0.0;
        for &p in &pts {
            assert!(
                (end.apply(p) - p).length() < 1e-12,
                "identity form moves {p}"
            );
            let q = fwd.apply(p);
            for a in 0..3 {
                let knots = fwd.knots()[a].knots();
                let (k, n) = (degrees[a], counts[a]);
                let predicted: f64 = (0..n)
                    .map(|i| {
                        let even = min[a] + i as f64 * extent[a] / (n - 1) as f64;
                        let greville = knots[i + 1..=i + k].iter().sum::<f64>() / k as f64;
                        cox_de_boor(knots, i, k, p[a]) * (even - greville)
                    })
                    .sum();
                let d = q[a] - p[a];
                assert!(
                    (d - predicted).abs() < 1e-12,
                    "{degrees:?} axis {a}: {d} vs {predicted}"
                );
                // Towards the centre plane, never past it.
                assert!(
                    d * (centre[a] - p[a]).signum() >= -1e-12,
                    "axis {a} at {p}: {d}"
                );
                assert!(d.abs() <= (centre[a] - p[a]).abs() + 1e-12);
                if n == k + 1 {
                    assert!(d.abs() < 1e-12, "a Bézier axis is not warped");
                }
                largest = largest.max(d.abs());
            }
        }
        // The warp is visible: a few percent of the extent.
        assert!(
            largest > 0.01 * extent.min_element(),
            "{degrees:?}: {largest}"
        );
        // The faces stay (end interpolation).
        for c in [min, max, DVec3::new(min.x, max.y, min.z)] {
            assert!((fwd.apply(c) - c).length() < 1e-12);
        }
    }
    assert_eq!(FengForm::Forward.name(), "forward");
    assert!(!FengForm::Forward.is_identity() && FengForm::Uniform.is_identity());
}

/// The batch kernel agrees with `apply` inside, on and outside the box, for several degrees
/// and frames.
#[test]
fn apply_batch_agrees_with_apply() {
    let (min, max) = (DVec3::new(-1.0, 0.5, 2.0), DVec3::new(3.0, 2.0, 5.0));
    let mut r = Rng::new(8);
    for (degrees, counts) in [
        ([2, 2, 2], [6, 8, 6]),
        ([1, 3, 2], [4, 5, 3]),
        ([3, 3, 3], [4, 4, 4]),
        ([4, 2, 1], [6, 4, 3]),
    ] {
        let mut lat =
            BSplineLattice::feng_end_interpolating_around(min, max, degrees, counts).unwrap();
        for k in 0..counts[2] {
            for j in 0..counts[1] {
                for i in 0..counts[0] {
                    lat.move_control_point([i, j, k], r.point(0.5) * 0.4)
                        .unwrap();
                }
            }
        }
        let mut pts: Vec<DVec3> = (0..5000)
            .map(|_| min - 0.5 + (max - min + 1.0) * r.point_in(DVec3::ZERO, DVec3::ONE))
            .collect();
        pts.extend([min, max, DVec3::new(max.x, min.y, max.z)]);
        let mut out = vec![DVec3::ZERO; pts.len()];
        lat.apply_batch(&pts, &mut out).unwrap();
        for (p, o) in pts.iter().zip(&out) {
            assert!((lat.apply(*p) - *o).length() < 1e-12, "{p}");
        }
        assert!(lat.apply_batch(&pts, &mut out[1..]).is_err());
    }
    let cubic = BSplineLattice::uniform_cubic_around(min, max, [7, 5, 6]).unwrap();
    let pts: Vec<DVec3> = (0..500)
        .map(|_| min + (max - min) * r.point_in(DVec3::ZERO, DVec3::ONE))
        .collect();
    let mut out = vec![DVec3::ZERO; pts.len()];
    cubic.apply_batch(&pts, &mut out).unwrap();
    for (p, o) in pts.iter().zip(&out) {
        assert!((*p - *o).length() < 1e-12);
    }
}

/// Every box of a grid evaluated with `apply_grid_part` has, bit for bit, the images the whole
/// grid's `apply_grid` gives its points: on aligned grids (the separable part plan, with axes
/// running either way and margins outside the lattice box) and on a rotated grid (pointwise).
#[test]
fn grid_parts_have_the_bits_of_the_whole_grid() {
    let lat = displaced(
        BSplineLattice::uniform_cubic_around(DVec3::splat(-0.5), DVec3::splat(11.5), [9, 9, 9])
            .unwrap(),
        0.6,
        17,
    );
    let grids = [
        Geometry::new([16, 15, 14]).with_origin(DVec3::new(-2.0, -1.0, -2.0)),
        Geometry::new([17, 13, 11])
            .with_spacing(DVec3::new(0.77, 0.93, 1.1))
            .with_origin(DVec3::new(-1.3, -0.9, -1.01)),
        Geometry::new([16, 15, 14])
            .with_origin(DVec3::new(13.0, -1.0, 11.0))
            .with_direction(DMat3::from_diagonal(DVec3::new(-1.0, 1.0, -1.0))),
        Geometry::new([9, 8, 7]).with_direction(rotation(DVec3::new(0.2, 0.4, 1.0), 0.3)),
    ];
    for grid in &grids {
        let mut whole = vec![DVec3::ZERO; grid.len()];
        lat.apply_grid(grid, &mut whole).unwrap();
        let [nx, ny, nz] = grid.dims;
        for (start, end) in [
            ([0, 0, 0], [nx, ny, nz]),
            ([1, 2, 3], [nx - 2, ny, nz - 1]),
            ([nx - 1, 0, 0], [nx, 1, nz]),
            ([3, 3, 3], [5, 4, 4]),
            ([0, ny - 3, 2], [2, ny, 3]),
        ] {
            let part = volmorph_volume::IndexBox { start, end };
            // Twice: the second evaluation reuses the axis plans the first one built.
            for pass in 0..2 {
                let mut got = vec![DVec3::splat(f64::NAN); part.len()];
                lat.apply_grid_part(grid, part, &mut got).unwrap();
                let mut n = 0;
                for k in start[2]..end[2] {
                    for j in start[1]..end[1] {
                        for i in start[0]..end[0] {
                            let want = whole[grid.offset(i, j, k)];
                            assert_eq!(
                                got[n].to_array().map(f64::to_bits),
                                want.to_array().map(f64::to_bits),
                                "point ({i}, {j}, {k}) of part {start:?}..{end:?}, pass {pass}"
                            );
                            n += 1;
                        }
                    }
                }
            }
            // A composition (lattice first) keeps the lattice's part evaluation.
            let mut by_default = vec![DVec3::ZERO; part.len()];
            Compose(Affine::translation(DVec3::X), lat.clone())
                .apply_grid_part(grid, part, &mut by_default)
                .unwrap();
            let mut composed = vec![DVec3::ZERO; grid.len()];
            Compose(Affine::translation(DVec3::X), lat.clone())
                .apply_grid(grid, &mut composed)
                .unwrap();
            let mut n = 0;
            for k in start[2]..end[2] {
                for j in start[1]..end[1] {
                    for i in start[0]..end[0] {
                        assert_eq!(
                            by_default[n].to_array().map(f64::to_bits),
                            composed[grid.offset(i, j, k)].to_array().map(f64::to_bits)
                        );
                        n += 1;
                    }
                }
            }
        }
        // A part leaving the grid, or a buffer of the wrong length, is refused.
        let outside = volmorph_volume::IndexBox {
            start: [0, 0, 0],
            end: [nx + 1, 1, 1],
        };
        assert!(matches!(
            lat.apply_grid_part(grid, outside, &mut vec![DVec3::ZERO; nx + 1]),
            Err(DeformError::BufferLength { .. })
        ));
        let one = volmorph_volume::IndexBox {
            start: [0, 0, 0],
            end: [1, 1, 1],
        };
        assert!(matches!(
            lat.apply_grid_part(grid, one, &mut [DVec3::ZERO; 2]),
            Err(DeformError::BufferLength { .. })
        ));
    }
}
