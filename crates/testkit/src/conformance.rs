//! The conformance suite every [`SpaceMap`] runs, and the extra checks of every [`LinearMap`].
//!
//! A map type joins the suite with one [`space_map_conformance!`](crate::space_map_conformance)
//! line (and [`linear_map_conformance!`](crate::linear_map_conformance) if it is linear in its
//! parameters), giving a [`Conformance`] description: how to build a deformed instance and an
//! instance with identity parameters, the box of space to sample, and how the map survives its
//! file form. The macros expand to one `#[test]` per property, so a failure names the map and
//! the property.
//!
//! Properties of every map:
//! * `apply`, `apply_batch` and `apply_grid` agree (to [`EVAL_TOLERANCE`] relative: grid fast
//!   paths evaluate separably, in another order);
//! * the Jacobian (`jacobian`, `apply_with_jacobian`, `jacobian_grid`) matches central
//!   differences of `apply` (to the description's tolerance) and the three agree;
//! * identity parameters give the identity;
//! * the file form round-trips: the map read back applies bit for bit like the original.
//!
//! Properties of every linear map:
//! * `f(v) = b(v) + Σ_k c_k(v) t_k` with the map's own coefficients;
//! * a coefficient column equals the coefficients at each point;
//! * moving a parameter changes the map nowhere outside the parameter's influence;
//! * a [`LiveGrid`] updated by parameter moves equals a grid built on the moved map (the live
//!   edit equals a full re-evaluation).

use glam::{DMat3, DVec3};
use volmorph_deform::live::{Influence, LinearMap};
use volmorph_deform::{LiveGrid, SpaceMap};
use volmorph_volume::Geometry;

use crate::Rng;

/// Relative agreement required between `apply`, `apply_batch` and `apply_grid`: separable grid
/// paths sum the same products in another order, about 1e-15 relative per term.
pub const EVAL_TOLERANCE: f64 = 1e-11;

/// Relative agreement required of the live-edit updates with a full re-evaluation: each move
/// adds `c_k·Δt` to every node, so rounding grows by about one ulp of the node per move.
pub const LIVE_TOLERANCE: f64 = 1e-10;

/// How a map type takes part in the suite.
pub struct Conformance<M> {
    /// A deformed instance (parameters away from the identity).
    pub make: fn() -> M,
    /// An instance with identity parameters (control points at their identity places, targets
    /// equal to sources).
    pub identity: fn() -> M,
    /// The box of physical space sampled (where the map is defined and smooth enough for
    /// differences), `(lo, hi)`.
    pub domain: (DVec3, DVec3),
    /// Largest relative difference between the Jacobian and central differences of `apply`
    /// (about 1e-6 for smooth maps; larger for maps with kinks between samples).
    pub jacobian_tolerance: f64,
    /// The map written to its file form and read back.
    pub round_trip: fn(&M) -> M,
}

/// Points sampled in `domain` (the same for a given seed).
#[must_use]
pub fn sample_points(domain: (DVec3, DVec3), n: usize, seed: u64) -> Vec<DVec3> {
    let mut r = Rng::new(seed);
    (0..n).map(|_| r.point_in(domain.0, domain.1)).collect()
}

/// An oblique, anisotropic grid inside `domain`: 9 × 8 × 7 voxels, rotated and sheared off
/// the axes so grid fast paths meet a general geometry.
#[must_use]
pub fn oblique_grid(domain: (DVec3, DVec3)) -> Geometry {
    let (lo, hi) = domain;
    let ext = hi - lo;
    let dir = DMat3::from_rotation_z(0.2) * DMat3::from_rotation_x(-0.15);
    let dims = [9usize, 8, 7];
    // A grid that fits in the middle 60 % of the box whatever the rotation.
    let spacing = 0.6 * ext.min_element() / (dims[0] as f64) * DVec3::new(1.0, 1.1, 1.2);
    let centre = 0.5 * (lo + hi);
    let half = dir
        * (spacing
            * DVec3::new(
                (dims[0] - 1) as f64,
                (dims[1] - 1) as f64,
                (dims[2] - 1) as f64,
            )
            * 0.5);
    Geometry::new(dims)
        .with_spacing(spacing)
        .with_origin(centre - half)
        .with_direction(dir)
}

fn rel(a: DVec3, b: DVec3, scale: f64) -> f64 {
    (a - b).abs().max_element() / scale.max(1.0)
}

fn scale_of(domain: (DVec3, DVec3)) -> f64 {
    domain.0.abs().max(domain.1.abs()).max_element()
}

/// `apply`, `apply_batch` and `apply_grid` agree.
///
/// # Panics
/// When they differ by more than [`EVAL_TOLERANCE`] relative, naming the point.
pub fn check_batch_and_grid<M: SpaceMap>(c: &Conformance<M>) {
    let m = (c.make)();
    let s = scale_of(c.domain);
    let pts = sample_points(c.domain, 500, 1);
    let mut out = vec![DVec3::ZERO; pts.len()];
    m.apply_batch(&pts, &mut out).expect("apply_batch");
    for (p, o) in pts.iter().zip(&out) {
        let e = m.apply(*p);
        assert!(
            rel(e, *o, s) <= EVAL_TOLERANCE,
            "apply_batch at {p}: {o} vs apply {e}"
        );
    }
    let g = oblique_grid(c.domain);
    let mut grid = vec![DVec3::ZERO; g.len()];
    m.apply_grid(&g, &mut grid).expect("apply_grid");
    let [nx, ny, _] = g.dims;
    for (n, o) in grid.iter().enumerate() {
        let x = g.index_to_physical(DVec3::new(
            (n % nx) as f64,
            (n / nx % ny) as f64,
            (n / (nx * ny)) as f64,
        ));
        let e = m.apply(x);
        assert!(
            rel(e, *o, s) <= EVAL_TOLERANCE,
            "apply_grid at voxel {n} ({x}): {o} vs apply {e}"
        );
    }
    // Wrong buffer lengths are errors, not panics.
    assert!(m.apply_batch(&pts, &mut out[1..]).is_err());
    assert!(m.apply_grid(&g, &mut grid[1..]).is_err());
}

/// The Jacobian matches central differences, and `jacobian`, `apply_with_jacobian` and
/// `jacobian_grid` agree.
///
/// # Panics
/// When they differ by more than the description's tolerance, naming the point.
pub fn check_jacobian<M: SpaceMap>(c: &Conformance<M>) {
    let m = (c.make)();
    let s = scale_of(c.domain);
    for p in sample_points(c.domain, 200, 2) {
        let j = m.jacobian(p);
        let fd = volmorph_deform::map::central_jacobian(&m, p);
        let norm = fd.abs().to_cols_array().into_iter().fold(1.0f64, f64::max);
        let diff = (j - fd)
            .abs()
            .to_cols_array()
            .into_iter()
            .fold(0.0f64, f64::max);
        assert!(
            diff <= c.jacobian_tolerance * norm,
            "Jacobian at {p}: {j} vs central differences {fd} (difference {diff:e})"
        );
        let (y, jj) = m.apply_with_jacobian(p);
        assert!(
            rel(y, m.apply(p), s) <= EVAL_TOLERANCE,
            "apply_with_jacobian value at {p}"
        );
        let d = (jj - j)
            .abs()
            .to_cols_array()
            .into_iter()
            .fold(0.0f64, f64::max);
        assert!(
            d <= EVAL_TOLERANCE * norm,
            "apply_with_jacobian Jacobian at {p}: {jj} vs {j}"
        );
    }
    let g = oblique_grid(c.domain);
    let mut out = vec![DMat3::ZERO; g.len()];
    m.jacobian_grid(&g, &mut out).expect("jacobian_grid");
    let [nx, ny, _] = g.dims;
    for (n, o) in out.iter().enumerate() {
        let x = g.index_to_physical(DVec3::new(
            (n % nx) as f64,
            (n / nx % ny) as f64,
            (n / (nx * ny)) as f64,
        ));
        let j = m.jacobian(x);
        let norm = j.abs().to_cols_array().into_iter().fold(1.0f64, f64::max);
        let d = (*o - j)
            .abs()
            .to_cols_array()
            .into_iter()
            .fold(0.0f64, f64::max);
        assert!(
            d <= 1e-9 * norm,
            "jacobian_grid at voxel {n}: {o} vs jacobian {j}"
        );
    }
}

/// Identity parameters give the identity.
///
/// # Panics
/// When a point moves by more than 1e-9 relative.
pub fn check_identity<M: SpaceMap>(c: &Conformance<M>) {
    let m = (c.identity)();
    let s = scale_of(c.domain);
    for p in sample_points(c.domain, 300, 3) {
        let y = m.apply(p);
        assert!(rel(y, p, s) <= 1e-9, "identity parameters move {p} to {y}");
    }
    // And the deformed instance is not the identity (the other checks test something).
    let d = (c.make)();
    let moved = sample_points(c.domain, 300, 3)
        .into_iter()
        .any(|p| rel(d.apply(p), p, s) > 1e-6);
    assert!(moved, "the deformed instance does not deform the domain");
}

/// The file form round-trips: the map read back applies bit for bit like the original.
///
/// # Panics
/// At the first point where the two differ in any bit.
pub fn check_round_trip<M: SpaceMap>(c: &Conformance<M>) {
    let m = (c.make)();
    let back = (c.round_trip)(&m);
    for p in sample_points(c.domain, 300, 4) {
        let (a, b) = (m.apply(p), back.apply(p));
        assert!(
            a.to_array().map(f64::to_bits) == b.to_array().map(f64::to_bits),
            "round trip changes the map at {p}: {a} vs {b}"
        );
    }
}

/// The linear form `f(v) = b(v) + Σ c_k(v) t_k` holds, and coefficient columns equal the
/// coefficients at each point.
///
/// # Panics
/// When either differs by more than [`LIVE_TOLERANCE`] relative.
pub fn check_linear_form<M: LinearMap>(c: &Conformance<M>) {
    let m = (c.make)();
    let s = scale_of(c.domain);
    let t = m.parameters();
    let k = m.parameter_count();
    assert_eq!(t.len(), k);
    let pts = sample_points(c.domain, 60, 5);
    let mut coeffs = vec![0.0; k];
    let mut rows = Vec::with_capacity(pts.len());
    for p in &pts {
        let b = m.coefficients_into(*p, &mut coeffs);
        let f = coeffs
            .iter()
            .zip(&t)
            .fold(b, |acc, (ck, tk)| acc + *ck * *tk);
        let e = m.apply(*p);
        assert!(
            rel(f, e, s) <= LIVE_TOLERANCE,
            "linear form at {p}: {f} vs apply {e}"
        );
        rows.push(coeffs.clone());
    }
    for col in [0, k / 2, k - 1] {
        let mut out = vec![0.0; pts.len()];
        m.coefficient_column(col, &pts, &mut out).expect("column");
        for (i, o) in out.iter().enumerate() {
            assert!(
                (o - rows[i][col]).abs() <= 1e-10 * rows[i][col].abs().max(1.0),
                "column {col} at {}: {o} vs {}",
                pts[i],
                rows[i][col]
            );
        }
    }
    assert!(
        m.coefficient_column(k, &pts, &mut vec![0.0; pts.len()])
            .is_err()
    );
}

/// Moving a parameter changes the map nowhere outside its influence, and a [`LiveGrid`]
/// updated by moves (and by a selected drag) equals one built on the moved map.
///
/// # Panics
/// When a point outside the influence moves, or the grids differ by more than
/// [`LIVE_TOLERANCE`] relative.
pub fn check_live_edit<M: LinearMap + Clone>(c: &Conformance<M>) {
    let m = (c.make)();
    let s = scale_of(c.domain);
    let k = m.parameter_count();
    let mut r = Rng::new(6);
    let step = 0.05 * (c.domain.1 - c.domain.0).min_element();
    let moves: Vec<(usize, DVec3)> = (0..3)
        .map(|i| {
            let j = [k / 2, k / 3, 2 * k / 3][i];
            (j, m.parameters()[j] + step * r.direction())
        })
        .collect();
    // Influence.
    let mut moved = m.clone();
    moved.set_some_parameters(&moves[..1]).expect("move");
    let influence = m.influence(&[moves[0].0]);
    for p in sample_points(c.domain, 400, 7) {
        let outside = match influence {
            Influence::Nowhere => true,
            Influence::Everywhere => false,
            Influence::Within(_) => {
                let (lo, hi) = influence.bounds().unwrap_or((DVec3::ZERO, DVec3::ZERO));
                !(p.cmpge(lo).all() && p.cmple(hi).all())
            }
        };
        if outside {
            assert_eq!(
                m.apply(p),
                moved.apply(p),
                "moving parameter {} changed the map at {p}, outside its influence",
                moves[0].0
            );
        }
    }
    // Live grid: moves, then a selected drag, against a fresh grid of the final map.
    let g = oblique_grid(c.domain);
    let mut live = LiveGrid::new(m.clone(), g).expect("live grid");
    for &(j, t) in &moves {
        live.move_parameter(j, t).expect("move");
    }
    let (j, t0) = moves[0];
    live.select(j).expect("select");
    let t1 = t0 + step * DVec3::new(0.3, -0.2, 0.1);
    live.drag_selected(t1).expect("drag");
    let mut full_map = m.clone();
    full_map.set_some_parameters(&moves).expect("moves");
    full_map.set_some_parameters(&[(j, t1)]).expect("drag");
    let fresh = LiveGrid::new(full_map.clone(), g).expect("fresh grid");
    for (n, (a, b)) in live
        .sampled()
        .positions()
        .iter()
        .zip(fresh.sampled().positions())
        .enumerate()
    {
        assert!(
            rel(*a, *b, s) <= LIVE_TOLERANCE,
            "live grid node {n}: {a} vs fresh {b}"
        );
    }
    assert_eq!(live.parameters(), full_map.parameters().as_slice());
    // The edited exact map is the map with the new parameters.
    for p in sample_points(c.domain, 50, 8) {
        assert!(rel(live.map().apply(p), full_map.apply(p), s) <= EVAL_TOLERANCE);
    }
}

/// Generate the [conformance](self) tests of a [`SpaceMap`] type: a module `$name` with one
/// `#[test]` per property, from an expression giving its [`Conformance`].
#[macro_export]
macro_rules! space_map_conformance {
    ($name:ident, $conformance:expr) => {
        mod $name {
            #[allow(unused_imports)]
            use super::*;

            #[test]
            fn apply_batch_and_grid_agree() {
                $crate::conformance::check_batch_and_grid(&$conformance);
            }

            #[test]
            fn jacobian_matches_central_differences() {
                $crate::conformance::check_jacobian(&$conformance);
            }

            #[test]
            fn identity_parameters_give_the_identity() {
                $crate::conformance::check_identity(&$conformance);
            }

            #[test]
            fn file_form_round_trips_bit_for_bit() {
                $crate::conformance::check_round_trip(&$conformance);
            }
        }
    };
}

/// Generate the extra [conformance](self) tests of a [`LinearMap`] type (use together with
/// [`space_map_conformance!`](crate::space_map_conformance)).
#[macro_export]
macro_rules! linear_map_conformance {
    ($name:ident, $conformance:expr) => {
        mod $name {
            #[allow(unused_imports)]
            use super::*;

            #[test]
            fn linear_form_and_columns_hold() {
                $crate::conformance::check_linear_form(&$conformance);
            }

            #[test]
            fn live_edit_equals_full_re_evaluation() {
                $crate::conformance::check_live_edit(&$conformance);
            }
        }
    };
}
