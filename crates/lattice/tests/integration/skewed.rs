//! Skewed lattices: Sederberg–Parry parallelepipeds (True 1992 §2.1) with axes at arbitrary,
//! non-degenerate angles — identity placement, local coordinates, Jacobians, inversion, drags,
//! grid evaluation and the file forms.

use glam::{DMat3, DVec3};
use volmorph_deform::{DeformError, InverseOptions, SpaceMap, invert_point};
use volmorph_lattice::formats::{bxf, itk_tfm};
use volmorph_lattice::lattice::MIN_FRAME_VOLUME;
use volmorph_lattice::manipulate::{Drag, DragOptions, solve_drags};
use volmorph_lattice::{BSplineLattice, LatticeFrame};
use volmorph_testkit::Rng;
use volmorph_volume::Geometry;

/// Edges S, T, U of a visibly sheared box: 60°, 75° and 80° between the axes.
fn edges() -> DMat3 {
    DMat3::from_cols(
        DVec3::new(40.0, 0.0, 0.0),
        DVec3::new(15.0, 28.0, 0.0),
        DVec3::new(6.0, -4.0, 22.0),
    )
}

const CORNER: DVec3 = DVec3::new(-3.0, 5.0, 1.5);

fn skewed_cubic(counts: [usize; 3]) -> BSplineLattice {
    BSplineLattice::uniform_cubic_in_parallelepiped(CORNER, edges(), counts).unwrap()
}

/// Points `corner + edges·t`, `t ∈ [0, 1]³` (corners included).
fn box_points(n: usize, seed: u64) -> Vec<DVec3> {
    let mut r = Rng::new(seed);
    let mut pts: Vec<DVec3> = (0..n)
        .map(|_| CORNER + edges() * r.point_in(DVec3::ZERO, DVec3::ONE))
        .collect();
    for c in 0..8u32 {
        let t = DVec3::new(
            f64::from(c & 1),
            f64::from((c >> 1) & 1),
            f64::from((c >> 2) & 1),
        );
        pts.push(CORNER + edges() * t);
    }
    pts
}

fn moved(mut lat: BSplineLattice, amount: f64, seed: u64) -> BSplineLattice {
    let mut r = Rng::new(seed);
    let [nx, ny, nz] = lat.counts();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                lat.move_control_point([i, j, k], amount * r.point(1.0))
                    .unwrap();
            }
        }
    }
    lat
}

#[test]
fn skewed_identity_lattice_is_the_identity_on_its_parallelepiped() {
    for lat in [
        skewed_cubic([7, 5, 6]),
        BSplineLattice::bezier_in_parallelepiped(CORNER, edges(), [2, 3, 1]).unwrap(),
    ] {
        assert!(lat.frame().is_skewed());
        for (n, p) in box_points(300, 1).into_iter().enumerate() {
            // Corners computed in floating point may round to just outside the box, where the
            // map is the identity too; interior points must be inside.
            assert!(n >= 300 || lat.contains(p), "{p}");
            let q = lat.apply(p);
            assert!((q - p).length() <= 1e-12 * p.length().max(1.0), "{p} ↦ {q}");
            let j = lat.jacobian(p);
            assert!(
                (j - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-12),
                "{p}: {j}"
            );
        }
        // Outside the parallelepiped (but inside its axis-aligned bounding box) nothing moves.
        let outside = CORNER + edges() * DVec3::new(1.05, 0.5, 0.5);
        assert!(!lat.contains(outside));
        assert_eq!(lat.apply(outside), outside);
    }
}

#[test]
fn local_coordinates_are_true_s_cross_product_formulas() {
    // §2.1: s = (T×U)·(Q−Q₀) / ((T×U)·S), and cyclically.
    let lat = BSplineLattice::bezier_in_parallelepiped(CORNER, edges(), [1, 1, 1]).unwrap();
    let (s_, t_, u_) = (edges().x_axis, edges().y_axis, edges().z_axis);
    for q in box_points(50, 2) {
        let d = q - CORNER;
        let expect = DVec3::new(
            t_.cross(u_).dot(d) / t_.cross(u_).dot(s_),
            s_.cross(u_).dot(d) / s_.cross(u_).dot(t_),
            s_.cross(t_).dot(d) / s_.cross(t_).dot(u_),
        );
        let got = lat.frame().to_parameter(q);
        assert!((got - expect).length() < 1e-13, "{got} vs {expect}");
    }
}

#[test]
fn sederberg_parry_control_points_sit_on_the_parallelepiped_grid() {
    let lat = BSplineLattice::bezier_in_parallelepiped(CORNER, edges(), [2, 3, 1]).unwrap();
    for k in 0..2 {
        for j in 0..4 {
            for i in 0..3 {
                let t = DVec3::new(i as f64 / 2.0, j as f64 / 3.0, k as f64);
                let expect = CORNER + edges() * t;
                let got = lat.control_point([i, j, k]).unwrap();
                assert!((got - expect).length() < 1e-12, "{i},{j},{k}: {got}");
            }
        }
    }
}

#[test]
fn skewed_jacobian_matches_central_differences() {
    let lat = moved(skewed_cubic([7, 6, 5]), 2.5, 3);
    let h = 1e-5;
    for p in box_points(120, 4) {
        // Stay a difference step away from the box surface.
        let t = lat.frame().to_parameter(p);
        let dom = lat.domain();
        if (0..3).any(|a| t[a] - dom[a][0] < 1e-3 || dom[a][1] - t[a] < 1e-3) {
            continue;
        }
        let j = lat.jacobian(p);
        let (v, jj) = lat.apply_with_jacobian(p);
        assert!((v - lat.apply(p)).length() < 1e-12 * v.length().max(1.0));
        for c in 0..3 {
            let mut e = DVec3::ZERO;
            e[c] = h;
            let fd = (lat.apply(p + e) - lat.apply(p - e)) / (2.0 * h);
            let scale = j.col(c).length().max(1.0);
            assert!(
                (fd - j.col(c)).length() < 1e-6 * scale,
                "{p} column {c}: {fd} vs {}",
                j.col(c)
            );
            assert!((jj.col(c) - j.col(c)).length() < 1e-12 * scale);
        }
    }
}

#[test]
fn skewed_lattice_inverts_by_newton() {
    let lat = moved(skewed_cubic([7, 6, 5]), 1.5, 5);
    for p in box_points(60, 6) {
        let t = lat.frame().to_parameter(p);
        if (0..3).any(|a| t[a] < 0.05 || t[a] > lat.domain()[a][1] - 0.05) {
            continue;
        }
        let y = lat.apply(p);
        let inv = invert_point(&lat, y, None, &InverseOptions::default());
        assert!(inv.converged(), "{p}: {:?}", inv.status);
        assert!((inv.point - p).length() < 1e-8, "{p} vs {}", inv.point);
    }
}

#[test]
fn drags_on_a_skewed_lattice_land_exactly() {
    let mut lat = skewed_cubic([9, 9, 9]);
    let drags = [
        Drag::new(
            CORNER + edges() * DVec3::new(0.4, 0.5, 0.5),
            CORNER + edges() * DVec3::new(0.45, 0.55, 0.5),
        ),
        Drag::new(
            CORNER + edges() * DVec3::new(0.7, 0.3, 0.6),
            CORNER + edges() * DVec3::new(0.66, 0.3, 0.65),
        ),
    ];
    let sol = solve_drags(&lat, &drags, &DragOptions::default()).unwrap();
    assert!(sol.is_full_rank());
    sol.apply(&mut lat).unwrap();
    for d in &drags {
        assert!((lat.apply(d.material) - d.target).length() < 1e-9);
    }
}

#[test]
fn grid_fast_paths_on_a_sheared_grid_equal_pointwise() {
    // A sheared grid (a tilted-gantry CT) and the identity lattice on its voxels: the lattice
    // takes the grid's shear, so the separable path applies and agrees with `apply`.
    let dir = DMat3::from_cols(
        DVec3::X,
        DVec3::new(0.0, 1.0, 0.0),
        DVec3::new(0.0, 0.34, 0.94).normalize(),
    );
    let grid = Geometry::new([17, 13, 11])
        .with_spacing(DVec3::new(0.8, 0.9, 2.5))
        .with_origin(DVec3::new(-4.0, 2.0, 7.0))
        .with_direction(dir);
    let mut lat = BSplineLattice::identity_on_voxels(&grid, [8, 8, 9]).unwrap();
    assert!(lat.frame().is_skewed());
    // Move only control points that leave the box surface in place, so voxels on the surface
    // (whose parameters may round to either side of it) agree between the paths.
    let mut r = Rng::new(7);
    for k in 3..6 {
        for j in 3..5 {
            for i in 3..5 {
                lat.move_control_point([i, j, k], r.point(1.2)).unwrap();
            }
        }
    }
    let mut fast = vec![DVec3::ZERO; grid.len()];
    lat.apply_grid_separable(&grid, &mut fast).unwrap();
    let mut slow = vec![DVec3::ZERO; grid.len()];
    volmorph_deform::map::apply_grid_pointwise(&lat, &grid, &mut slow).unwrap();
    for (a, b) in fast.iter().zip(&slow) {
        assert!(
            (*a - *b).length() < 1e-11 * b.length().max(1.0),
            "{a} vs {b}"
        );
    }
    let mut jf = vec![DMat3::ZERO; grid.len()];
    lat.jacobian_grid(&grid, &mut jf).unwrap();
    for (n, j) in jf.iter().enumerate() {
        let idx = DVec3::new(
            (n % 17) as f64,
            (n / 17 % 13) as f64,
            (n / (17 * 13)) as f64,
        );
        let p = grid.index_to_physical(idx);
        assert!((*j - lat.jacobian(p)).abs_diff_eq(DMat3::ZERO, 1e-11));
    }
}

#[test]
fn skewed_json_and_tfm_round_trip_exactly_and_bxf_refuses() {
    let lat = moved(skewed_cubic([7, 5, 6]), 1.0, 8);
    let text = lat.to_json().unwrap();
    assert!(text.contains("\"skewed\": true"));
    let back = BSplineLattice::from_json(&text).unwrap();
    assert_eq!(back, lat);
    // Without the flag, a non-orthonormal frame is refused.
    let unflagged = text.replace("\"skewed\": true", "\"skewed\": false");
    let e = BSplineLattice::from_json(&unflagged)
        .unwrap_err()
        .to_string();
    assert!(e.contains("orthonormal"), "{e}");
    // Orthonormal lattices keep their files: no flag written.
    let plain = BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::ONE, [4; 3]).unwrap();
    assert!(!plain.to_json().unwrap().contains("skewed"));

    let tfm = itk_tfm::parse_itk_tfm(&itk_tfm::itk_tfm_to_string(&lat).unwrap()).unwrap();
    assert!(tfm.frame().is_skewed());
    let mut r = Rng::new(9);
    for _ in 0..100 {
        let p = CORNER + edges() * r.point_in(DVec3::splat(-0.1), DVec3::splat(1.1));
        assert!((tfm.apply(p) - lat.apply(p)).length() < 1e-11 * p.length().max(1.0));
    }
    let e = bxf::bxf_to_string(&lat).unwrap_err();
    assert!(matches!(e, DeformError::Unsupported(_)), "{e}");
    assert!(e.to_string().contains("skewed"), "{e}");
}

#[test]
fn degenerate_and_nearly_orthonormal_frames() {
    // Coplanar axes are refused.
    let flat = DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 1e-5));
    let e = LatticeFrame::parallelepiped(DVec3::ZERO, flat).unwrap_err();
    assert!(e.to_string().contains("degenerate"), "{e}");
    assert!(
        LatticeFrame::parallelepiped(
            DVec3::ZERO,
            DMat3::from_cols(DVec3::X, DVec3::ZERO, DVec3::Z)
        )
        .is_err()
    );
    // Just above the bound is accepted.
    let sin = 2.0 * MIN_FRAME_VOLUME;
    let ok = DMat3::from_cols(
        DVec3::X,
        DVec3::new((1.0 - sin * sin).sqrt(), sin, 0.0),
        DVec3::Z,
    );
    assert!(
        LatticeFrame::parallelepiped(DVec3::ZERO, ok)
            .unwrap()
            .is_skewed()
    );
    // Axes orthonormal within the direction tolerance snap to an orthonormal frame.
    let nearly = DMat3::from_cols(
        DVec3::new(2.0, 0.0, 0.0),
        DVec3::new(1e-5, 3.0, 0.0),
        DVec3::new(0.0, 0.0, 0.5),
    );
    let f = LatticeFrame::parallelepiped(DVec3::ONE, nearly).unwrap();
    assert!(!f.is_skewed());
    assert!((f.spacing() - DVec3::new(2.0, 3.0, 0.5)).length() < 1e-9);
    // The gradient matrix is the inverse transpose of the unit axes.
    let s = LatticeFrame::parallelepiped(DVec3::ZERO, edges()).unwrap();
    let g = s.gradient_matrix();
    assert!((g.transpose() * s.axes() - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-13));
}
