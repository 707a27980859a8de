//! Direct manipulation: dragged points land on their targets, the solution has least norm
//! (checked against normal equations built from an independent basis evaluation), the tool
//! radius and frozen boundary restrict the moves, the map is unchanged away from the drag,
//! undo/redo restore lattices bit for bit, and bad input gives the documented errors.

use glam::{DMat3, DVec3};
use volmorph_deform::SpaceMap;
use volmorph_lattice::manipulate::{
    ControlPointMove, Drag, DragError, DragOptions, ManipulationSession, solve_drags,
};
use volmorph_lattice::{BSplineLattice, LatticeFrame};
use volmorph_spline::KnotVector;

use volmorph_testkit::Rng;

/// Relative tolerance for "the dragged point lands on its target".
const LAND_TOL: f64 = 1e-9;

/// True's 9³ uniform cubic lattice on `[0, 60]³` (regions of 10 units), identity.
fn cubic9() -> BSplineLattice {
    BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(60.0), [9; 3]).unwrap()
}

/// `cubic9` with its interior control points jiggled, so the map is not the identity.
fn cubic9_deformed(seed: u64) -> BSplineLattice {
    let mut lat = cubic9();
    let mut r = Rng::new(seed);
    for k in 3..6 {
        for j in 3..6 {
            for i in 3..6 {
                lat.move_control_point([i, j, k], r.point(1.0) * 2.0)
                    .unwrap();
            }
        }
    }
    lat
}

/// Quadratic lattice with non-uniform clamped knots and different counts per axis.
fn quadratic_nonuniform() -> BSplineLattice {
    let knots = [
        KnotVector::clamped(2, &[0.15, 0.4, 0.45, 0.8], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(2, &[0.3, 0.7], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(2, &[0.2, 0.25, 0.6, 0.9, 0.95], [0.0, 1.0]).unwrap(),
    ];
    let mut lat = BSplineLattice::identity_around(
        DVec3::new(-5.0, 2.0, 1.0),
        DVec3::new(15.0, 10.0, 21.0),
        knots,
    )
    .unwrap();
    let mut r = Rng::new(77);
    let c = lat.counts();
    for k in 1..c[2] - 1 {
        for j in 1..c[1] - 1 {
            for i in 1..c[0] - 1 {
                lat.move_control_point([i, j, k], r.point(1.0) * 0.5)
                    .unwrap();
            }
        }
    }
    lat
}

/// A cubic 7 × 8 × 9 lattice in an oblique frame (rotated, anisotropic spacing).
fn oblique() -> BSplineLattice {
    let axes = DMat3::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.9);
    let corner = DVec3::new(10.0, -4.0, 3.0);
    let extent = DVec3::new(8.0, 12.0, 6.0);
    BSplineLattice::uniform_cubic_in_box(corner, axes, extent, [7, 8, 9]).unwrap()
}

/// Physical point at box fraction `t ∈ [0, 1]³` of a lattice.
fn at(lat: &BSplineLattice, t: DVec3) -> DVec3 {
    let d = lat.domain();
    let u = DVec3::new(
        d[0][0] + t.x * (d[0][1] - d[0][0]),
        d[1][0] + t.y * (d[1][1] - d[1][0]),
        d[2][0] + t.z * (d[2][1] - d[2][0]),
    );
    lat.frame().to_physical(u)
}

fn assert_lands(lat: &BSplineLattice, drags: &[Drag]) {
    for d in drags {
        let got = lat.apply(d.material);
        let scale = d.target.length().max(1.0);
        assert!(
            (got - d.target).length() <= LAND_TOL * scale,
            "{} ↦ {got}, target {} (miss {:e})",
            d.material,
            d.target,
            (got - d.target).length()
        );
    }
}

fn bits(lat: &BSplineLattice) -> Vec<[u64; 3]> {
    lat.control_points()
        .iter()
        .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        .collect()
}

/// Solve, check the solution's bookkeeping, apply, check the landing.
fn drag_and_check(lat: &mut BSplineLattice, drags: &[Drag], options: &DragOptions) {
    let before = lat.clone();
    let sol = solve_drags(lat, drags, options).unwrap();
    assert_eq!(sol.drag_count(), drags.len());
    assert!(sol.is_full_rank(), "rank {} of {}", sol.rank(), drags.len());
    assert!(sol.max_residual() <= 1e-12 * 60.0, "{:?}", sol.residuals());
    let moves = sol.apply(lat).unwrap();
    assert_lands(lat, drags);
    // Moves are absolute new positions of exactly the changed control points.
    for &(idx, p) in &moves {
        assert_eq!(lat.control_point(idx).unwrap(), p);
        assert_ne!(before.control_point(idx).unwrap(), p);
    }
    let c = lat.counts();
    let moved: std::collections::HashSet<[usize; 3]> = moves.iter().map(|m| m.0).collect();
    for k in 0..c[2] {
        for j in 0..c[1] {
            for i in 0..c[0] {
                if !moved.contains(&[i, j, k]) {
                    assert_eq!(
                        lat.control_point([i, j, k]).unwrap(),
                        before.control_point([i, j, k]).unwrap()
                    );
                }
            }
        }
    }
}

#[test]
fn single_drag_lands_exactly_on_cubic_9() {
    let mut lat = cubic9();
    let p = DVec3::new(31.0, 28.5, 30.2);
    let d = [Drag::new(p, DVec3::new(36.0, 27.0, 33.0))];
    let sol = solve_drags(&lat, &d, &DragOptions::default()).unwrap();
    assert_eq!(sol.rank(), 1);
    assert_eq!(sol.displacements().len(), 64);
    drag_and_check(&mut lat, &d, &DragOptions::default());
    // A second drag of the already moved point, on the now deformed lattice.
    let d2 = [Drag::new(p, DVec3::new(30.0, 35.0, 29.0))];
    drag_and_check(&mut lat, &d2, &DragOptions::default());
}

#[test]
fn single_drag_has_closed_form_least_norm_solution() {
    // One drag: B is the row of weights w, so ΔP_c = w_c Δq / |w|².
    let lat = cubic9_deformed(3);
    let p = DVec3::new(22.0, 41.0, 33.3);
    let t = DVec3::new(20.0, 44.0, 30.0);
    let dq = t - lat.apply(p);
    let sol = solve_drags(&lat, &[Drag::new(p, t)], &DragOptions::default()).unwrap();
    let w: Vec<f64> = sol
        .displacements()
        .iter()
        .map(|&(idx, _)| basis_weight(&lat, idx, p))
        .collect();
    let w2: f64 = w.iter().map(|x| x * x).sum();
    for (&(idx, d), wc) in sol.displacements().iter().zip(&w) {
        let want = dq * (wc / w2);
        assert!(
            (d - want).length() <= 1e-12 * dq.length(),
            "{idx:?}: {d} vs {want}"
        );
    }
    assert!((sol.singular_values()[0] - w2.sqrt()).abs() < 1e-12);
}

#[test]
fn multiple_drags_land_exactly_on_a_deformed_cubic_9() {
    let mut lat = cubic9_deformed(11);
    // Overlapping supports: the three points share control points.
    let drags = [
        Drag::new(DVec3::new(25.0, 30.0, 30.0), DVec3::new(22.0, 31.0, 29.0)),
        Drag::new(DVec3::new(33.0, 30.0, 31.0), DVec3::new(37.0, 29.0, 33.0)),
        Drag::new(DVec3::new(29.0, 36.0, 27.0), DVec3::new(29.5, 40.0, 25.0)),
        Drag::new(DVec3::new(45.0, 12.0, 50.0), DVec3::new(44.0, 13.0, 51.0)),
    ];
    drag_and_check(&mut lat, &drags, &DragOptions::default());
}

#[test]
fn drags_land_on_a_quadratic_nonuniform_lattice() {
    let mut lat = quadratic_nonuniform();
    let drags = [
        Drag::new(
            at(&lat, DVec3::new(0.42, 0.5, 0.23)),
            at(&lat, DVec3::new(0.5, 0.45, 0.3)),
        ),
        Drag::new(
            at(&lat, DVec3::new(0.7, 0.2, 0.61)),
            at(&lat, DVec3::new(0.66, 0.25, 0.58)),
        ),
    ];
    let sol = solve_drags(&lat, &drags, &DragOptions::default()).unwrap();
    assert!(sol.displacements().len() <= 2 * 27);
    drag_and_check(&mut lat, &drags, &DragOptions::default());
}

#[test]
fn drags_land_in_an_oblique_frame() {
    let mut lat = oblique();
    let drags = [
        Drag::new(
            at(&lat, DVec3::new(0.5, 0.5, 0.5)),
            at(&lat, DVec3::new(0.55, 0.4, 0.5)),
        ),
        Drag::new(
            at(&lat, DVec3::new(0.3, 0.62, 0.44)),
            at(&lat, DVec3::new(0.28, 0.7, 0.5)),
        ),
    ];
    drag_and_check(&mut lat, &drags, &DragOptions::default());
    assert_least_norm(&oblique(), &drags);
}

/// `N_c(p)` measured through the map itself: move control point `c` by one unit along x and
/// read the change of the image of `p` (independent of the solver's basis evaluation).
fn basis_weight(lat: &BSplineLattice, idx: [usize; 3], p: DVec3) -> f64 {
    let mut moved = lat.clone();
    moved.move_control_point(idx, DVec3::X).unwrap();
    (moved.apply(p) - lat.apply(p)).x
}

/// Solve `A z = y` (dense, small, partial pivoting) for several right-hand sides.
#[allow(clippy::needless_range_loop)] // dense elimination reads best with indices
fn gauss_solve(mut a: Vec<Vec<f64>>, mut y: Vec<DVec3>) -> Vec<DVec3> {
    let n = a.len();
    for col in 0..n {
        let piv = (col..n)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap();
        a.swap(col, piv);
        y.swap(col, piv);
        for row in col + 1..n {
            let f = a[row][col] / a[col][col];
            for c in col..n {
                a[row][c] -= f * a[col][c];
            }
            let yc = y[col];
            y[row] -= f * yc;
        }
    }
    let mut z = vec![DVec3::ZERO; n];
    for row in (0..n).rev() {
        let mut s = y[row];
        for c in row + 1..n {
            s -= a[row][c] * z[c];
        }
        z[row] = s / a[row][row];
    }
    z
}

/// Compare the solver with `ΔP = Bᵀ (B Bᵀ)⁻¹ ΔQ` over the same columns (B measured through
/// the map), and check that the solution is orthogonal to the null space of B.
fn assert_least_norm(lat: &BSplineLattice, drags: &[Drag]) {
    let sol = solve_drags(lat, drags, &DragOptions::default()).unwrap();
    let cols: Vec<[usize; 3]> = sol.displacements().iter().map(|d| d.0).collect();
    let b: Vec<Vec<f64>> = drags
        .iter()
        .map(|d| {
            cols.iter()
                .map(|&c| basis_weight(lat, c, d.material))
                .collect()
        })
        .collect();
    let m = drags.len();
    let bbt: Vec<Vec<f64>> = (0..m)
        .map(|r| {
            (0..m)
                .map(|s| b[r].iter().zip(&b[s]).map(|(x, y)| x * y).sum())
                .collect()
        })
        .collect();
    let dq: Vec<DVec3> = drags
        .iter()
        .map(|d| d.target - lat.apply(d.material))
        .collect();
    let scale = dq.iter().fold(0.0_f64, |s, q| s.max(q.length()));
    let z = gauss_solve(bbt, dq);
    for (c, &(idx, d)) in sol.displacements().iter().enumerate() {
        let want: DVec3 = (0..m).map(|r| b[r][c] * z[r]).sum();
        assert!(
            (d - want).length() <= 1e-9 * scale,
            "{idx:?}: {d} vs {want}"
        );
    }
    // Null-space vectors v − Bᵀ(BBᵀ)⁻¹Bv of random v are orthogonal to the solution.
    let mut r = Rng::new(5);
    let n = cols.len();
    for _ in 0..5 {
        let v: Vec<DVec3> = (0..n).map(|_| r.point(1.0)).collect();
        let bv: Vec<DVec3> = (0..m)
            .map(|row| (0..n).map(|c| b[row][c] * v[c]).sum())
            .collect();
        let bbt: Vec<Vec<f64>> = (0..m)
            .map(|i| {
                (0..m)
                    .map(|j| b[i].iter().zip(&b[j]).map(|(x, y)| x * y).sum())
                    .collect()
            })
            .collect();
        let zz = gauss_solve(bbt, bv);
        let null: Vec<DVec3> = (0..n)
            .map(|c| v[c] - (0..m).map(|row| b[row][c] * zz[row]).sum::<DVec3>())
            .collect();
        for axis in 0..3 {
            let dot: f64 = (0..n)
                .map(|c| sol.displacements()[c].1[axis] * null[c][axis])
                .sum();
            let nn: f64 = null.iter().map(|x| x[axis] * x[axis]).sum::<f64>().sqrt();
            assert!(dot.abs() <= 1e-9 * scale * nn, "axis {axis}: {dot:e}");
        }
    }
}

#[test]
fn solution_is_the_least_norm_one() {
    let lat = cubic9_deformed(21);
    assert_least_norm(
        &lat,
        &[
            Drag::new(DVec3::new(25.0, 30.0, 30.0), DVec3::new(22.0, 31.0, 29.0)),
            Drag::new(DVec3::new(31.0, 33.0, 31.0), DVec3::new(37.0, 29.0, 33.0)),
            Drag::new(DVec3::new(28.0, 36.0, 27.0), DVec3::new(29.5, 40.0, 25.0)),
        ],
    );
    let q = quadratic_nonuniform();
    assert_least_norm(
        &q,
        &[
            Drag::new(
                at(&q, DVec3::new(0.42, 0.5, 0.23)),
                at(&q, DVec3::new(0.5, 0.45, 0.3)),
            ),
            Drag::new(
                at(&q, DVec3::new(0.5, 0.4, 0.3)),
                at(&q, DVec3::new(0.45, 0.4, 0.31)),
            ),
        ],
    );
}

#[test]
fn same_point_to_two_targets_is_least_squares_and_reported() {
    let mut lat = cubic9_deformed(8);
    let p = DVec3::new(27.0, 31.0, 33.0);
    let (t1, t2) = (DVec3::new(30.0, 31.0, 33.0), DVec3::new(26.0, 35.0, 31.0));
    let sol = solve_drags(
        &lat,
        &[Drag::new(p, t1), Drag::new(p, t2)],
        &Default::default(),
    )
    .unwrap();
    assert_eq!(sol.rank(), 1);
    assert!(!sol.is_full_rank());
    let half = (t1 - t2) * 0.5;
    assert!((sol.residuals()[0] - half).length() < 1e-12 * 30.0);
    assert!((sol.residuals()[1] + half).length() < 1e-12 * 30.0);
    // Least squares and least norm: the same as one drag to the midpoint.
    let mid = solve_drags(&lat, &[Drag::new(p, (t1 + t2) * 0.5)], &Default::default()).unwrap();
    for (a, b) in sol.displacements().iter().zip(mid.displacements()) {
        assert_eq!(a.0, b.0);
        assert!((a.1 - b.1).length() < 1e-12 * 30.0);
    }
    sol.apply(&mut lat).unwrap();
    assert!((lat.apply(p) - (t1 + t2) * 0.5).length() < 1e-9 * 30.0);
}

#[test]
fn radius_limits_the_moves_and_the_point_still_lands() {
    let lat = cubic9_deformed(2);
    let p = DVec3::new(31.0, 29.0, 32.0);
    let image = lat.apply(p);
    let d = [Drag::new(p, DVec3::new(34.0, 27.0, 30.0))];
    for r in [12.0, 16.0, 1e9] {
        let opts = DragOptions::with_radius(r);
        let sol = solve_drags(&lat, &d, &opts).unwrap();
        for &(idx, _) in sol.displacements() {
            assert!(lat.control_point(idx).unwrap().distance(image) <= r);
        }
        let mut l = lat.clone();
        drag_and_check(&mut l, &d, &opts);
        // Every control point farther than r kept its place, bit for bit.
        let c = l.counts();
        for k in 0..c[2] {
            for j in 0..c[1] {
                for i in 0..c[0] {
                    let old = lat.control_point([i, j, k]).unwrap();
                    if old.distance(image) > r {
                        assert_eq!(l.control_point([i, j, k]).unwrap(), old);
                    }
                }
            }
        }
    }
    // A smaller radius selects fewer control points, and their moves are larger.
    let small = solve_drags(&lat, &d, &DragOptions::with_radius(12.0)).unwrap();
    let full = solve_drags(&lat, &d, &DragOptions::default()).unwrap();
    assert!(small.displacements().len() < full.displacements().len());
    let norm = |s: &volmorph_lattice::DragSolution| {
        s.displacements()
            .iter()
            .map(|x| x.1.length_squared())
            .sum::<f64>()
    };
    assert!(norm(&small) > norm(&full));
    // A radius reaching no control point of the support is an error.
    assert!(matches!(
        solve_drags(&lat, &d, &DragOptions::with_radius(0.5)),
        Err(DragError::NoInfluence { drag: 0, .. })
    ));
}

#[test]
fn map_is_unchanged_outside_the_support() {
    let mut lat = cubic9_deformed(4);
    let before = lat.clone();
    let p = DVec3::new(31.0, 29.0, 42.0); // parameters (3.1, 2.9, 4.2)
    let sol = solve_drags(
        &lat,
        &[Drag::new(p, DVec3::new(35.0, 25.0, 40.0))],
        &Default::default(),
    )
    .unwrap();
    // Moved control indices: spans (3, 2, 4) → i in 3..=6, j in 2..=5, k in 4..=7; their
    // basis functions live on u ∈ (i − 3, i + 1), so the changed region is
    // (0, 7) × (−1, 6) × (1, 8) in parameters.
    let lo = DVec3::new(0.0, -1.0, 1.0);
    let hi = DVec3::new(7.0, 6.0, 8.0);
    for &(idx, _) in sol.displacements() {
        for a in 0..3 {
            assert!(idx[a] as f64 - 3.0 >= lo[a] && idx[a] as f64 + 1.0 <= hi[a]);
        }
    }
    sol.apply(&mut lat).unwrap();
    let mut r = Rng::new(9);
    let mut outside = 0;
    for _ in 0..4000 {
        let x = r.point_in(DVec3::ZERO, DVec3::ONE) * 60.0;
        let u = x / 10.0;
        if (0..3).any(|a| u[a] <= lo[a] || u[a] >= hi[a]) {
            outside += 1;
            let (a, b) = (lat.apply(x), before.apply(x));
            assert_eq!(
                a.to_array().map(f64::to_bits),
                b.to_array().map(f64::to_bits)
            );
        }
    }
    assert!(outside > 300, "{outside}");
    // Inside the region, near the point, the map did change.
    assert_ne!(
        lat.apply(p + DVec3::splat(1.0)),
        before.apply(p + DVec3::splat(1.0))
    );
}

#[test]
fn frozen_boundary_keeps_the_box_surface_fixed() {
    let lat = cubic9();
    let opts = DragOptions {
        freeze_boundary: true,
        ..DragOptions::default()
    };
    // Near the face x = 0: the support reaches the three outermost layers, which stay.
    let p = DVec3::new(4.0, 30.0, 30.0);
    let d = [Drag::new(p, DVec3::new(6.0, 31.0, 30.0))];
    let sol = solve_drags(&lat, &d, &opts).unwrap();
    assert!(!sol.displacements().is_empty());
    for &(idx, _) in sol.displacements() {
        assert!(idx.iter().all(|&i| (3..6).contains(&i)), "{idx:?}");
    }
    let full = solve_drags(&lat, &d, &Default::default()).unwrap();
    assert!(full.displacements().iter().any(|m| m.0[0] < 3));
    let mut l = lat.clone();
    drag_and_check(&mut l, &d, &opts);
    // The box surface stays where it was, so the map is continuous across it.
    let mut r = Rng::new(1);
    for _ in 0..200 {
        let mut x = r.point_in(DVec3::ZERO, DVec3::ONE) * 60.0;
        let face = (r.unit() * 6.0) as usize;
        x[face % 3] = if face < 3 { 0.0 } else { 60.0 };
        assert!((l.apply(x) - x).length() < 1e-12 * 60.0);
    }
    // On the face itself only frozen control points have weight.
    let on_face = [Drag::new(
        DVec3::new(0.0, 30.0, 30.0),
        DVec3::new(0.0, 33.0, 30.0),
    )];
    assert!(matches!(
        solve_drags(&lat, &on_face, &opts),
        Err(DragError::NoInfluence {
            freeze_boundary: true,
            ..
        })
    ));
    // Bézier lattices freeze only their outermost layer.
    let bez = BSplineLattice::bezier_around(DVec3::ZERO, DVec3::splat(1.0), [3, 3, 3]).unwrap();
    let sol = solve_drags(
        &bez,
        &[Drag::new(DVec3::splat(0.5), DVec3::splat(0.6))],
        &opts,
    )
    .unwrap();
    let idx: Vec<[usize; 3]> = sol.displacements().iter().map(|m| m.0).collect();
    assert_eq!(idx.len(), 8);
    assert!(idx.iter().all(|i| i.iter().all(|&c| c == 1 || c == 2)));
}

#[test]
fn bad_input_is_a_clear_error() {
    let lat = cubic9();
    let ok = DVec3::splat(30.0);
    let opts = DragOptions::default();
    assert!(matches!(
        solve_drags(&lat, &[], &opts),
        Err(DragError::NoDrags)
    ));
    let e = solve_drags(
        &lat,
        &[
            Drag::new(ok, ok),
            Drag::new(DVec3::new(f64::NAN, 1.0, 1.0), ok),
        ],
        &opts,
    )
    .unwrap_err();
    assert!(matches!(
        e,
        DragError::NonFinite {
            drag: 1,
            what: "material point",
            ..
        }
    ));
    assert!(matches!(
        solve_drags(
            &lat,
            &[Drag::new(ok, DVec3::new(1.0, f64::INFINITY, 1.0))],
            &opts
        ),
        Err(DragError::NonFinite { what: "target", .. })
    ));
    let e = solve_drags(&lat, &[Drag::new(DVec3::new(-0.5, 3.0, 3.0), ok)], &opts).unwrap_err();
    assert!(matches!(e, DragError::MaterialOutsideBox { drag: 0, .. }));
    assert!(e.to_string().contains("outside the lattice box"), "{e}");
    let e = solve_drags(&lat, &[Drag::new(ok, DVec3::new(30.0, 60.5, 3.0))], &opts).unwrap_err();
    assert!(matches!(e, DragError::TargetOutsideBox { drag: 0, .. }));
    assert!(e.to_string().contains("target"), "{e}");
    // Points on the closed box surface are inside.
    solve_drags(
        &lat,
        &[Drag::new(
            DVec3::new(0.0, 60.0, 30.0),
            DVec3::new(60.0, 60.0, 0.0),
        )],
        &opts,
    )
    .unwrap();
    for r in [0.0, -1.0, f64::NAN] {
        assert!(matches!(
            solve_drags(&lat, &[Drag::new(ok, ok)], &DragOptions::with_radius(r)),
            Err(DragError::InvalidRadius { .. })
        ));
        assert!(ManipulationSession::new(lat.clone(), DragOptions::with_radius(r)).is_err());
    }
    // A solution applied to a lattice with a different control net.
    let sol = solve_drags(&lat, &[Drag::new(ok, ok + 1.0)], &opts).unwrap();
    let mut small =
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(60.0), [5; 3]).unwrap();
    let untouched = small.clone();
    assert!(matches!(
        sol.apply(&mut small),
        Err(DragError::LatticeMismatch {
            expected: [9, 9, 9],
            got: [5, 5, 5]
        })
    ));
    assert_eq!(small, untouched);
}

#[test]
fn a_drag_to_where_the_point_already_is_moves_nothing() {
    let mut lat = cubic9_deformed(6);
    let p = DVec3::new(20.0, 20.0, 20.0);
    let sol = solve_drags(&lat, &[Drag::new(p, lat.apply(p))], &Default::default()).unwrap();
    assert!(sol.apply(&mut lat).unwrap().is_empty());
    assert_eq!(lat, cubic9_deformed(6));
}

#[test]
fn undo_and_redo_restore_lattices_bit_for_bit() {
    let start = cubic9_deformed(13);
    let mut s = ManipulationSession::new(start.clone(), DragOptions::default()).unwrap();
    assert!(s.undo().is_none() && s.redo().is_none());
    let mut r = Rng::new(31);
    let mut states = vec![bits(&start)];
    let mut outs: Vec<Vec<ControlPointMove>> = Vec::new();
    for _ in 0..4 {
        let p = DVec3::splat(15.0) + r.point_in(DVec3::ZERO, DVec3::ONE) * 30.0;
        let t = p + r.point(1.0) * 4.0;
        let out = s.drag(&[Drag::new(p, t)]).unwrap();
        assert_lands(s.lattice(), &[Drag::new(p, t)]);
        states.push(bits(s.lattice()));
        outs.push(out.moves);
    }
    assert_eq!(s.undo_depth(), 4);
    for n in (0..4).rev() {
        let moves = s.undo().unwrap();
        assert_eq!(bits(s.lattice()), states[n]);
        // The returned moves are the restored positions of the control points the drag moved.
        assert_eq!(moves.len(), outs[n].len());
        for (&(i, p), &(j, _)) in moves.iter().zip(&outs[n]) {
            assert_eq!(i, j);
            assert_eq!(s.lattice().control_point(i).unwrap(), p);
        }
    }
    assert!(s.undo().is_none());
    assert_eq!(s.redo_depth(), 4);
    for n in 1..=2 {
        assert_eq!(s.redo().unwrap(), outs[n - 1]);
        assert_eq!(bits(s.lattice()), states[n]);
    }
    // A new drag after undo drops the redo history.
    s.undo().unwrap();
    assert_eq!(bits(s.lattice()), states[1]);
    s.drag(&[Drag::new(DVec3::splat(30.0), DVec3::splat(31.0))])
        .unwrap();
    assert_eq!(s.redo_depth(), 0);
    assert!(s.redo().is_none());
    assert_eq!(s.undo_depth(), 2);
    s.undo().unwrap();
    s.undo().unwrap();
    assert_eq!(bits(s.lattice()), states[0]);
    assert_eq!(s.lattice(), &start);
    // A failed drag changes neither the lattice nor the history.
    assert!(
        s.drag(&[Drag::new(DVec3::splat(-1.0), DVec3::ZERO)])
            .is_err()
    );
    assert_eq!(s.redo_depth(), 2);
    assert_eq!(bits(s.lattice()), states[0]);
}

#[test]
fn history_limit_drops_the_oldest_edits() {
    let mut s = ManipulationSession::new(cubic9(), DragOptions::default()).unwrap();
    s.set_history_limit(2);
    for n in 0..3 {
        let p = DVec3::splat(20.0 + 5.0 * f64::from(n));
        s.drag(&[Drag::new(p, p + 1.0)]).unwrap();
    }
    assert_eq!(s.undo_depth(), 2);
    assert_eq!(s.history().count(), 2);
    s.set_history_limit(1);
    assert_eq!(s.undo_depth(), 1);
    s.clear_history();
    assert!(s.undo().is_none());
    // Limit 0 disables undo but drags still apply.
    s.set_history_limit(0);
    let p = DVec3::splat(33.0);
    s.drag(&[Drag::new(p, p + 2.0)]).unwrap();
    assert_eq!(s.undo_depth(), 0);
    assert_lands(s.lattice(), &[Drag::new(p, p + 2.0)]);
}

#[test]
fn many_drags_more_than_control_points_are_least_squares() {
    // 30 drags of distinct points on a tiny 4³ lattice (64 control points, but a point
    // near a corner only sees some of them): the system is consistent, so every point
    // still lands when the targets come from an actual lattice map.
    let lat = BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(1.0), [4; 3]).unwrap();
    let mut goal = lat.clone();
    let mut r = Rng::new(17);
    for k in 0..4 {
        for j in 0..4 {
            for i in 0..4 {
                goal.move_control_point([i, j, k], r.point(1.0) * 0.02)
                    .unwrap();
            }
        }
    }
    let drags: Vec<Drag> = (0..80)
        .map(|_| {
            let p = DVec3::splat(0.1) + r.point_in(DVec3::ZERO, DVec3::ONE) * 0.8;
            Drag::new(p, goal.apply(p))
        })
        .collect();
    let sol = solve_drags(&lat, &drags, &Default::default()).unwrap();
    assert_eq!(sol.rank(), 64);
    assert!(sol.max_residual() < 1e-12);
    let mut l = lat.clone();
    sol.apply(&mut l).unwrap();
    assert_lands(&l, &drags);
    // 80 equations in 64 unknowns with full column rank: the goal lattice is recovered, to
    // the accuracy the conditioning of B allows.
    // Points in [0.1, 0.9]³ see the corner control points only through basis values of
    // about 1e-3, so B is ill-conditioned by nature (1e7–1e8 for random draws of 80 points);
    // the bound only rejects a near-singular draw, and the recovery check below scales with
    // the condition number actually found.
    let sv = sol.singular_values();
    let cond = sv[0] / sv[63];
    assert!(cond < 1e9, "condition number {cond:e}");
    for (a, b) in l.control_points().iter().zip(goal.control_points()) {
        let err = (*a - b).length();
        assert!(
            err < 1e-13 * cond,
            "error {err:e}, condition number {cond:e}"
        );
    }
}

#[test]
fn frame_axes_do_not_matter_for_landing() {
    // The oblique lattice with a left-handed frame.
    let axes = DMat3::from_cols(DVec3::Y, DVec3::X, DVec3::Z);
    let frame =
        LatticeFrame::new(DVec3::new(1.0, 2.0, 3.0), axes, DVec3::new(2.0, 3.0, 4.0)).unwrap();
    let knots = [
        KnotVector::uniform(3, 7, [0.0, 4.0]).unwrap(),
        KnotVector::uniform(3, 6, [0.0, 3.0]).unwrap(),
        KnotVector::uniform(3, 8, [0.0, 5.0]).unwrap(),
    ];
    let mut lat = BSplineLattice::identity(frame, knots).unwrap();
    let drags = [Drag::new(
        at(&lat, DVec3::new(0.4, 0.5, 0.6)),
        at(&lat, DVec3::new(0.45, 0.4, 0.66)),
    )];
    drag_and_check(&mut lat, &drags, &DragOptions::with_radius(6.0));
}

/// Issue 14: messages printed user-supplied numbers with `{}`/`{:.6}`, so a point at 1e300
/// gave a 300-digit message. Drag errors and frame errors now print `1e300` (the project's
/// `Num` notation), whatever precision they ask for.
#[test]
fn numbers_past_1e9_print_hundreds_of_digits() {
    // 1e300 written out is 301 characters: a shorter message cannot hold it.
    let short = |msg: String| {
        assert!(
            msg.len() < 300 && msg.contains("e300"),
            "{} chars: {msg}",
            msg.len()
        );
    };
    let lat = cubic9();
    let opts = DragOptions::default();
    let ok = DVec3::splat(30.0);
    let e = solve_drags(&lat, &[Drag::new(DVec3::new(1e300, 3.0, 3.0), ok)], &opts).unwrap_err();
    assert!(matches!(e, DragError::MaterialOutsideBox { .. }), "{e}");
    short(e.to_string());
    let e = solve_drags(&lat, &[Drag::new(ok, DVec3::new(-1e300, 3.0, 3.0))], &opts).unwrap_err();
    assert!(matches!(e, DragError::TargetOutsideBox { .. }), "{e}");
    short(e.to_string());
    let e = solve_drags(
        &lat,
        &[Drag::new(DVec3::new(1e300, f64::NAN, 0.0), ok)],
        &opts,
    )
    .unwrap_err();
    assert!(matches!(e, DragError::NonFinite { .. }), "{e}");
    short(e.to_string());
    // An axis whose length overflows, a negative spacing, a corner that is not finite.
    let axes = DMat3::from_cols(DVec3::new(1e300, 1e300, 0.0), DVec3::Y, DVec3::Z);
    short(
        LatticeFrame::skewed(DVec3::ZERO, axes, DVec3::ONE)
            .unwrap_err()
            .to_string(),
    );
    short(
        LatticeFrame::axis_aligned(DVec3::ZERO, DVec3::new(1.0, -1e300, 1.0))
            .unwrap_err()
            .to_string(),
    );
    short(
        LatticeFrame::axis_aligned(DVec3::new(1e300, f64::INFINITY, 0.0), DVec3::ONE)
            .unwrap_err()
            .to_string(),
    );
}
