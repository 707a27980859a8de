//! Zeros of scalar trivariate splines by Bézier subdivision (Martin & Cohen §5.1).
//!
//! Isosurfaces and planar slices are both the zero set of one scalar trivariate spline
//! `D(u) = Σ D_i B_i(u)` on the shared unit domain:
//!
//! * [`isosurface_function`] — the isosurface `A(u) = A*` of a scalar attribute with
//!   homogeneous control values `(w_i A_i, w_i)` gives `D_i = w_i (A_i − A*)` on the attribute's
//!   knots (`w_i = 1` for a polynomial attribute). Because every `w_i > 0`,
//!   `D(u) = W(u)·(A(u) − A*)` with `W = Σ w_i B_i > 0`: `D` has the sign of `A − A*`.
//! * [`plane_function`] — the slice of the geometry by the plane `(a, b, c, d)·(x, 1) = 0` gives
//!   `D_i = (w_i P_i, w_i)·(a, b, c, d)` on the geometry's knots, so that
//!   `D(u) = W(u)·((a, b, c)·P(u) + d)`: `D` has the sign of the plane function at `P(u)`.
//!
//! Both are polynomial (non-rational) scalar splines even for rational inputs, exactly as in the
//! paper. [`isolate_roots`] then runs the paper's search: `D` is broken into its Bézier pieces
//! (one per knot-span box, [`TensorBSpline::bezier_pieces`]), which form the search list. Each
//! piece taken from the list is
//!
//! 1. put in the **root list** if all its control values lie within `ε` of zero (the ε-box
//!    test; [`RootCell::within_epsilon`] is `true`);
//! 2. otherwise **subdivided** at the midpoint of every axis (eight children, de Casteljau via
//!    [`volmorph_spline::BezierPiece::split`]) if its control values straddle zero
//!    (`min ≤ 0 ≤ max`) — by the convex-hull property a piece whose control values all have one
//!    strict sign holds no zero of `D` and is
//! 3. **discarded**.
//!
//! The paper subdivides until the list is empty; to bound the work a straddling piece that has
//! already been subdivided [`RootOptions::max_depth`] times is put in the root list as well
//! ([`RootCell::within_epsilon`] is `false`). Every zero of `D` therefore lies in the union of
//! the returned cells (closed parameter boxes): nothing is missed, only the localisation is
//! limited by the depth.

use rayon::prelude::*;
use volmorph_spline::{BezierCell, TensorBSpline};

use crate::TrivariateError;
use crate::error::ctx;

/// Default ε of the ε-box test, relative to the largest `|D_i|` of the whole spline: control
/// values below `1e-12·max|D_i|` are rounding noise of f64 subdivision (each de Casteljau level
/// adds a few ulps), so such a piece is zero to working precision.
pub const DEFAULT_EPSILON: f64 = 1e-12;

/// Default subdivision depth of [`isolate_roots`]: two halvings per axis localise the zero set
/// to a quarter of a knot span, enough to decide which elements the polygonisation refines
/// (deeper searches cost up to eight times more per level and change no element's status on
/// the benchmark models), at a cost of at most `8²` children per straddling Bézier piece.
pub const DEFAULT_MAX_DEPTH: u32 = 2;

/// Largest accepted [`RootOptions::max_depth`] (each level multiplies the worst-case number of
/// cells by eight; ten levels already allow `2³⁰` cells per piece).
pub const MAX_DEPTH_LIMIT: u32 = 10;

/// Options of [`isolate_roots`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RootOptions {
    /// ε of the ε-box test, **relative** to the largest absolute control value of `D`
    /// (finite, `≥ 0`). Default [`DEFAULT_EPSILON`].
    pub epsilon: f64,
    /// Subdivision levels after which a straddling piece is kept as a root cell without
    /// further subdivision (`≤` [`MAX_DEPTH_LIMIT`]). Default [`DEFAULT_MAX_DEPTH`].
    pub max_depth: u32,
}

impl Default for RootOptions {
    fn default() -> Self {
        Self {
            epsilon: DEFAULT_EPSILON,
            max_depth: DEFAULT_MAX_DEPTH,
        }
    }
}

/// One cell of the root list: a Bézier piece of `D` (scalar, domain = the cell's parameter
/// box) that may contain zeros of `D`.
#[derive(Debug, Clone, PartialEq)]
pub struct RootCell {
    /// The Bézier piece of `D` on the cell; [`BezierCell::span`] is the knot-span box (Bézier
    /// element of `D`) it was subdivided from, [`BezierCell::domain`] the cell's box.
    pub piece: BezierCell,
    /// Number of subdivisions from the Bézier element to this cell.
    pub depth: u32,
    /// `true` when the cell passed the ε-box test (all control values within ε of zero), so
    /// `D ≈ 0` on the whole cell; `false` when it still straddles zero at the depth limit.
    pub within_epsilon: bool,
}

/// The scalar spline `D` whose zero set is the isosurface `A(u) = level` of the scalar
/// attribute `attribute` (see the [module docs](self)): `D_i = w_i (A_i − level)` on the
/// attribute's knots, polynomial.
///
/// # Errors
/// [`TrivariateError::InvalidArgument`] if `level` is not finite or the attribute is not scalar
/// (`dim ≠ 1`); [`TrivariateError::Spline`] cannot occur for valid splines.
pub fn isosurface_function(
    attribute: &TensorBSpline<3>,
    level: f64,
) -> Result<TensorBSpline<3>, TrivariateError> {
    if !level.is_finite() {
        return Err(TrivariateError::InvalidArgument(format!(
            "isosurface level must be finite, got {level}"
        )));
    }
    if attribute.dim() != 1 {
        return Err(TrivariateError::InvalidArgument(format!(
            "isosurfaces need a scalar attribute, this one has {} components",
            attribute.dim()
        )));
    }
    let h = attribute.homogeneous_coefficients();
    let coefs: Vec<f64> = if attribute.is_rational() {
        h.chunks_exact(2).map(|c| c[0] - level * c[1]).collect()
    } else {
        h.iter().map(|&a| a - level).collect()
    };
    TensorBSpline::new(attribute.knots().clone(), 1, coefs).map_err(ctx("isosurface function"))
}

/// Check a plane `(a, b, c, d)`: finite with a non-zero normal `(a, b, c)`.
pub(crate) fn check_plane(plane: [f64; 4]) -> Result<(), TrivariateError> {
    if plane.iter().any(|v| !v.is_finite()) {
        return Err(TrivariateError::InvalidArgument(format!(
            "plane coefficients must be finite, got {plane:?}"
        )));
    }
    if plane[0] == 0.0 && plane[1] == 0.0 && plane[2] == 0.0 {
        return Err(TrivariateError::InvalidArgument(
            "plane normal (a, b, c) must not be zero".into(),
        ));
    }
    Ok(())
}

/// The scalar spline `D` whose zero set is the slice of `geometry` (3 coordinates) by the plane
/// `{x : (a, b, c, d)·(x, 1) = 0}` (see the [module docs](self)): `D_i = (w_i P_i, w_i)·plane`
/// on the geometry's knots, polynomial. The plane is not normalised: `D` scales with `|(a,b,c)|`.
///
/// # Errors
/// [`TrivariateError::InvalidArgument`] for a non-finite plane or a zero normal `(a, b, c)`;
/// [`TrivariateError::GeometryDimension`] unless the geometry has 3 coordinates.
pub fn plane_function(
    geometry: &TensorBSpline<3>,
    plane: [f64; 4],
) -> Result<TensorBSpline<3>, TrivariateError> {
    check_plane(plane)?;
    if geometry.dim() != 3 {
        return Err(TrivariateError::GeometryDimension {
            expected: 3,
            got: geometry.dim(),
        });
    }
    let [a, b, c, d] = plane;
    let h = geometry.homogeneous_coefficients();
    let coefs: Vec<f64> = if geometry.is_rational() {
        h.chunks_exact(4)
            .map(|p| a * p[0] + b * p[1] + c * p[2] + d * p[3])
            .collect()
    } else {
        h.chunks_exact(3)
            .map(|p| a * p[0] + b * p[1] + c * p[2] + d)
            .collect()
    };
    TensorBSpline::new(geometry.knots().clone(), 1, coefs).map_err(ctx("plane function"))
}

/// Smallest and largest homogeneous value (first component) of a scalar piece.
fn value_range(piece: &BezierCell) -> (f64, f64) {
    let h = piece.homogeneous_coefficients();
    let stride = if piece.is_rational() { 2 } else { 1 };
    h.iter()
        .step_by(stride)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}

/// Split a piece at the midpoint of every axis into its eight children.
fn octants(piece: &BezierCell) -> Result<Vec<BezierCell>, TrivariateError> {
    let mut cells = vec![piece.clone()];
    for axis in 0..3 {
        let mut next = Vec::with_capacity(cells.len() * 2);
        for c in &cells {
            let [s, e] = c.domain()[axis];
            let (l, r) = c
                .split(axis, 0.5 * (s + e))
                .map_err(ctx("root isolation subdivision"))?;
            next.push(l);
            next.push(r);
        }
        cells = next;
    }
    Ok(cells)
}

/// Run the search list of one Bézier element (see the [module docs](self)).
fn search(element: BezierCell, eps: f64, max_depth: u32) -> Result<Vec<RootCell>, TrivariateError> {
    let mut roots = Vec::new();
    let mut list = vec![(element, 0u32)];
    while let Some((piece, depth)) = list.pop() {
        let (lo, hi) = value_range(&piece);
        if lo >= -eps && hi <= eps {
            roots.push(RootCell {
                piece,
                depth,
                within_epsilon: true,
            });
        } else if lo <= 0.0 && hi >= 0.0 {
            if depth >= max_depth {
                roots.push(RootCell {
                    piece,
                    depth,
                    within_epsilon: false,
                });
            } else {
                list.extend(octants(&piece)?.into_iter().map(|c| (c, depth + 1)));
            }
        }
    }
    Ok(roots)
}

/// Isolate the zeros of the scalar spline `d` (polynomial, or rational with its homogeneous
/// numerator tested) by the subdivision search of Martin & Cohen §5.1 (see the
/// [module docs](self)). Bézier elements are searched in parallel; the result lists the root
/// cells element by element (axis-0 span fastest), each element's cells in search order.
///
/// # Errors
/// [`TrivariateError::InvalidArgument`] if `d` is not scalar, `epsilon` is negative or not
/// finite, or `max_depth` exceeds [`MAX_DEPTH_LIMIT`]; [`TrivariateError::Spline`] if the
/// Bézier pieces would exceed the allocation bound.
pub fn isolate_roots(
    d: &TensorBSpline<3>,
    options: &RootOptions,
) -> Result<Vec<RootCell>, TrivariateError> {
    isolate_roots_with(d, options, &volmorph_io::NoProgress)
}

/// [`isolate_roots`] reporting to `progress`: one stage whose steps are the Bézier
/// elements searched, stopping between elements when cancelled. The result equals
/// [`isolate_roots`]'s.
///
/// # Errors
/// As [`isolate_roots`]; [`TrivariateError::Cancelled`] when `progress` asks to stop.
pub fn isolate_roots_with(
    d: &TensorBSpline<3>,
    options: &RootOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<Vec<RootCell>, TrivariateError> {
    if d.dim() != 1 {
        return Err(TrivariateError::InvalidArgument(format!(
            "root isolation needs a scalar spline, got {} components",
            d.dim()
        )));
    }
    if !(options.epsilon.is_finite() && options.epsilon >= 0.0) {
        return Err(TrivariateError::InvalidArgument(format!(
            "epsilon must be finite and non-negative, got {}",
            options.epsilon
        )));
    }
    if options.max_depth > MAX_DEPTH_LIMIT {
        return Err(TrivariateError::InvalidArgument(format!(
            "max_depth {} exceeds the limit {MAX_DEPTH_LIMIT}",
            options.max_depth
        )));
    }
    let stride = d.homogeneous_dim();
    let scale = d
        .homogeneous_coefficients()
        .iter()
        .step_by(stride)
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let eps = options.epsilon * scale;
    let pieces = d.bezier_pieces().map_err(ctx("Bézier extraction"))?;
    progress.start("isolating the roots", pieces.len() as u64);
    let found: Result<Vec<Vec<RootCell>>, TrivariateError> = pieces
        .into_par_iter()
        .map(|p| {
            progress.check()?;
            let r = search(p, eps, options.max_depth);
            progress.advance(1);
            r
        })
        .collect();
    let found = found?;
    progress.check()?;
    Ok(found.into_iter().flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use volmorph_spline::KnotVector;

    fn kv(p: usize, n: usize) -> KnotVector {
        KnotVector::clamped_uniform(p, n, [0.0, 1.0]).unwrap()
    }

    fn inside(cell: &RootCell, u: [f64; 3]) -> bool {
        cell.piece
            .domain()
            .iter()
            .zip(u)
            .all(|(&[s, e], x)| x >= s - 1e-12 && x <= e + 1e-12)
    }

    #[test]
    fn functions_follow_the_paper() {
        // Rational attribute: D = W·(A − A*) has the sign of A − A* and vanishes with it.
        let k = [kv(2, 3), kv(1, 2), kv(2, 4)];
        let n = 3 * 2 * 4;
        let vals: Vec<f64> = (0..n).map(|i| (f64::from(i) * 0.7).sin()).collect();
        let w: Vec<f64> = (0..n).map(|i| 0.5 + f64::from(i % 5) * 0.3).collect();
        let a = TensorBSpline::new_rational(k.clone(), 1, vals, w.clone()).unwrap();
        let d = isosurface_function(&a, 0.2).unwrap();
        assert!(!d.is_rational());
        let wsp = TensorBSpline::new(k, 1, w).unwrap();
        for u in [[0.1, 0.2, 0.3], [0.9, 0.5, 0.05], [0.5, 1.0, 0.7]] {
            let (av, dv, wv) = (
                a.eval(u).unwrap()[0],
                d.eval(u).unwrap()[0],
                wsp.eval(u).unwrap()[0],
            );
            assert!((dv - wv * (av - 0.2)).abs() < 1e-12);
        }
        assert!(isosurface_function(&a, f64::NAN).is_err());
        // Plane through a rational geometry: D = W·(n·P + d).
        let g = TensorBSpline::new_rational(
            [kv(1, 2), kv(1, 2), kv(1, 2)],
            3,
            (0..8)
                .flat_map(|c| [f64::from(c & 1), f64::from((c >> 1) & 1), f64::from(c >> 2)])
                .collect(),
            vec![1.0, 2.0, 1.5, 1.0, 0.7, 1.0, 1.2, 3.0],
        )
        .unwrap();
        let plane = [1.0, -2.0, 0.5, 0.3];
        let dp = plane_function(&g, plane).unwrap();
        let wg = TensorBSpline::new(
            [kv(1, 2), kv(1, 2), kv(1, 2)],
            1,
            vec![1.0, 2.0, 1.5, 1.0, 0.7, 1.0, 1.2, 3.0],
        )
        .unwrap();
        for u in [[0.1, 0.2, 0.3], [0.9, 0.5, 0.05]] {
            let p = g.eval(u).unwrap();
            let f = plane[0] * p[0] + plane[1] * p[1] + plane[2] * p[2] + plane[3];
            let expect = wg.eval(u).unwrap()[0] * f;
            assert!((dp.eval(u).unwrap()[0] - expect).abs() < 1e-12);
        }
        assert!(plane_function(&g, [0.0, 0.0, 0.0, 1.0]).is_err());
        assert!(plane_function(&g, [f64::NAN, 0.0, 1.0, 1.0]).is_err());
    }

    #[test]
    fn search_discards_epsilon_boxes_and_bounds() {
        // D = u − 0.3 on a linear spline with 4 spans: only the span containing 0.3 straddles.
        let k = [kv(1, 5), kv(1, 2), kv(1, 2)];
        let coefs: Vec<f64> = (0..20).map(|i| f64::from(i % 5) * 0.25 - 0.3).collect();
        let d = TensorBSpline::new(k, 1, coefs).unwrap();
        let roots = isolate_roots(
            &d,
            &RootOptions {
                epsilon: 0.0,
                max_depth: 2,
            },
        )
        .unwrap();
        // Depth 2: the span [0.25, 0.5] is cut in four along u; 0.3 lies in [0.25, 0.3125];
        // v and w are cut in four too, giving 16 cells.
        assert_eq!(roots.len(), 16);
        for r in &roots {
            assert_eq!(r.depth, 2);
            assert!(!r.within_epsilon);
            assert_eq!(r.piece.domain()[0], [0.25, 0.3125]);
        }
        // A zero spline is one ε-box per element, never subdivided.
        let z = TensorBSpline::new([kv(2, 4), kv(1, 2), kv(1, 2)], 1, vec![0.0; 16]).unwrap();
        let roots = isolate_roots(&z, &RootOptions::default()).unwrap();
        assert_eq!(roots.len(), 2);
        assert!(roots.iter().all(|r| r.within_epsilon && r.depth == 0));
        // Bad options.
        let bad = RootOptions {
            epsilon: -1.0,
            ..RootOptions::default()
        };
        assert!(isolate_roots(&d, &bad).is_err());
        let bad = RootOptions {
            max_depth: 11,
            ..RootOptions::default()
        };
        assert!(isolate_roots(&d, &bad).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        /// Every sign change between neighbouring samples of a dense grid lies in a root cell.
        #[test]
        fn root_isolation_never_misses_a_root(
            pu in 1usize..4, pv in 1usize..4, pw in 1usize..3,
            extra in 0usize..3,
            seed in proptest::collection::vec(-1.0f64..1.0, 150),
            shift in -0.5f64..0.5,
            depth in 0u32..3,
        ) {
            let (nu, nv, nw) = (pu + 1 + extra, pv + 1 + extra, pw + 1);
            let k = [kv(pu, nu), kv(pv, nv), kv(pw, nw)];
            let coefs: Vec<f64> = (0..nu * nv * nw).map(|i| seed[i % seed.len()] + shift).collect();
            let d = TensorBSpline::new(k, 1, coefs).unwrap();
            let roots = isolate_roots(&d, &RootOptions { epsilon: 0.0, max_depth: depth }).unwrap();
            let m = 13usize;
            let at = |i: usize| i as f64 / (m - 1) as f64;
            let mut vals = vec![0.0; m * m * m];
            for k in 0..m { for j in 0..m { for i in 0..m {
                vals[i + m * (j + m * k)] = d.eval([at(i), at(j), at(k)]).unwrap()[0];
            }}}
            for k in 0..m { for j in 0..m { for i in 0..m {
                let v = vals[i + m * (j + m * k)];
                if v == 0.0 {
                    let z = [at(i), at(j), at(k)];
                    prop_assert!(roots.iter().any(|r| inside(r, z)), "zero at {z:?} missed");
                }
                for (di, dj, dk) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                    let (i2, j2, k2) = (i + di, j + dj, k + dk);
                    if i2 >= m || j2 >= m || k2 >= m { continue; }
                    let w = vals[i2 + m * (j2 + m * k2)];
                    if (v > 0.0) == (w > 0.0) { continue; }
                    // A zero lies on the segment: locate it by bisection and check coverage.
                    let (mut a, mut b) = ([at(i), at(j), at(k)], [at(i2), at(j2), at(k2)]);
                    for _ in 0..60 {
                        let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2])];
                        let fm = d.eval(mid).unwrap()[0];
                        if (fm > 0.0) == (v > 0.0) { a = mid; } else { b = mid; }
                    }
                    prop_assert!(roots.iter().any(|r| inside(r, a)), "zero at {a:?} missed");
                }
            }}}
        }
    }
}
