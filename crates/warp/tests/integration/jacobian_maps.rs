//! Jacobian determinant maps against closed forms, folding detection and error handling.

use glam::{DMat3, DVec3};
use volmorph_deform::{Affine, Identity, SpaceMap};
use volmorph_lattice::BSplineLattice;
use volmorph_volume::Geometry;
use volmorph_warp::WarpError;
use volmorph_warp::jacobian::{FoldingReport, jacobian_determinant, jacobian_determinant_into};

fn grid() -> Geometry {
    Geometry::new([21, 17, 19])
        .with_spacing(DVec3::new(1.0, 1.2, 1.05))
        .with_origin(DVec3::new(0.1, 0.2, -0.3))
}

fn lattice_around(g: &Geometry, counts: [usize; 3]) -> BSplineLattice {
    let (lo, hi) = g.physical_bounds();
    BSplineLattice::uniform_cubic_around(lo - DVec3::ONE, hi + DVec3::ONE, counts).unwrap()
}

fn assert_all_near(values: &[f32], want: f64, tol: f64) {
    for &v in values {
        assert!((f64::from(v) - want).abs() <= tol, "{v} vs {want}");
    }
}

#[test]
fn identity_maps_have_unit_determinant() {
    let g = grid();
    let j = jacobian_determinant(&Identity, &g).unwrap();
    assert_eq!(j.geometry(), &g);
    assert!(j.data().iter().all(|&v| v == 1.0));
    let lat = lattice_around(&g, [7, 6, 8]);
    let j = jacobian_determinant(&lat, &g).unwrap();
    assert_all_near(j.data(), 1.0, 1e-6);
    let r = FoldingReport::of(j.data());
    assert_eq!(r.count, g.len());
    assert_eq!(r.count_nonpositive, 0);
    assert!(!r.folds());
    assert!((r.mean - 1.0).abs() < 1e-6);
}

#[test]
fn uniform_scaling_has_determinant_s_cubed() {
    let g = grid();
    let s = 1.5;
    let j =
        jacobian_determinant(&Affine::linear(DMat3::from_diagonal(DVec3::splat(s))), &g).unwrap();
    assert_all_near(j.data(), s * s * s, 0.0);
    // The same scaling as a lattice: control points scaled about the box centre. B-splines
    // reproduce linear maps, so inside the box the lattice is p ↦ c + s(p − c).
    let mut lat = lattice_around(&g, [6, 6, 6]);
    let (lo, hi) = g.physical_bounds();
    let c = 0.5 * (lo + hi);
    let counts = lat.counts();
    for k in 0..counts[2] {
        for jj in 0..counts[1] {
            for i in 0..counts[0] {
                let p = lat.control_point([i, jj, k]).unwrap();
                lat.set_control_point([i, jj, k], c + s * (p - c)).unwrap();
            }
        }
    }
    let j = jacobian_determinant(&lat, &g).unwrap();
    assert_all_near(j.data(), s * s * s, 1e-5);
}

#[test]
fn affine_determinant_is_det_a() {
    let a = Affine {
        matrix: DMat3::from_cols(
            DVec3::new(1.2, 0.3, -0.1),
            DVec3::new(-0.2, 0.9, 0.4),
            DVec3::new(0.05, -0.3, 1.4),
        ),
        offset: DVec3::new(3.0, -2.0, 1.0),
    };
    let det = a.matrix.determinant();
    let j = jacobian_determinant(&a, &grid()).unwrap();
    assert_all_near(j.data(), det, 1e-6 * det.abs());
    // A reflection has a negative determinant everywhere: every voxel counts as folded.
    let mirror = Affine::linear(DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)));
    let r = FoldingReport::of_map(&mirror, &grid()).unwrap();
    assert_eq!(r.count_nonpositive, r.count);
    assert_eq!(r.fraction_nonpositive, 1.0);
}

#[test]
fn folding_lattice_is_reported() {
    let g = Geometry::new([21, 21, 21]);
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(20.0), [7, 7, 7]).unwrap();
    // Control points are 5 apart. The displacement 30·N₃(u)N₃(v)N₃(w) has ∂/∂x as low as
    // −30 · (½ / 5) · (⅔)² ≈ −1.33 (cubic B-spline: max |N′| = ½ per knot span, peak N = ⅔),
    // so pushing the middle point 30 units along +x, past its three +x neighbours, folds.
    lat.move_control_point([3, 3, 3], DVec3::new(30.0, 0.0, 0.0))
        .unwrap();
    let j = jacobian_determinant(&lat, &g).unwrap();
    let r = FoldingReport::of(j.data());
    assert!(r.count_nonpositive > 0, "{r}");
    assert!(r.folds());
    assert!(r.min <= 0.0 && r.max > 1.0, "{r}");
    let expected = j.data().iter().filter(|&&v| v <= 0.0).count();
    assert_eq!(r.count_nonpositive, expected);
    assert!((r.fraction_nonpositive - expected as f64 / g.len() as f64).abs() < 1e-15);
    // The folded voxels lie where the control point moved, not far away.
    assert_eq!(j[[0, 0, 0]], 1.0);
    // Each determinant agrees with the map's own Jacobian.
    let x = DVec3::new(10.0, 10.0, 10.0);
    assert_eq!(j[[10, 10, 10]], lat.jacobian(x).determinant() as f32);
    let text = r.to_string();
    assert!(
        text.contains(&format!(
            "{} of {} voxels fold",
            r.count_nonpositive, r.count
        )),
        "{text}"
    );
}

#[test]
fn report_statistics_by_hand() {
    let r = FoldingReport::of(&[1.0, 2.0, -1.0, 0.0, f32::NAN, f32::INFINITY]);
    assert_eq!(r.count, 6);
    assert_eq!(r.count_nonpositive, 2);
    assert_eq!(r.count_nonfinite, 2);
    assert_eq!((r.min, r.max, r.mean), (-1.0, 2.0, 0.5));
    assert!((r.fraction_nonpositive - 2.0 / 6.0).abs() < 1e-15);
    assert!(r.to_string().ends_with("; 2 non-finite"), "{r}");
    let empty = FoldingReport::of(&[]);
    assert_eq!((empty.count, empty.fraction_nonpositive), (0, 0.0));
    assert!(empty.min.is_nan() && empty.mean.is_nan());
    // Many values: the parallel reduction agrees with a sequential sum.
    let v: Vec<f32> = (0..300_000)
        .map(|i| ((i % 1000) as f32 - 10.0) * 0.01)
        .collect();
    let r = FoldingReport::of(&v);
    let mean = v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
    assert!((r.mean - mean).abs() < 1e-9);
    assert_eq!(r.count_nonpositive, 300 * 11);
}

#[test]
fn bad_grids_are_errors() {
    for bad in [
        Geometry::new([4, 0, 4]),
        Geometry::new([4, 4, 4]).with_spacing(DVec3::new(0.0, 1.0, 1.0)),
        Geometry::new([4, 4, 4]).with_direction(DMat3::from_cols(DVec3::X, DVec3::X, DVec3::Z)),
        Geometry::new([1 << 20, 1 << 20, 1 << 20]),
    ] {
        let e = jacobian_determinant(&Identity, &bad).unwrap_err();
        assert!(
            matches!(
                e,
                WarpError::Geometry {
                    what: "Jacobian grid",
                    ..
                }
            ),
            "{e:?}"
        );
    }
    let g = grid();
    let mut long = vec![0.0; g.len() + 3];
    let e = jacobian_determinant_into(&Identity, &g, &mut long).unwrap_err();
    assert!(
        matches!(e, WarpError::BufferLength { got, .. } if got == g.len() + 3),
        "{e:?}"
    );
}
