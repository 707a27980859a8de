//! Point inversion: physical point → parameters of a trivariate geometry volume.
//!
//! Newton's iteration `u_{k+1} = u_k + J(u_k)⁻¹ (x − P(u_k))` (the iteration the paper uses to
//! walk through volumes, §5.2 eq. 9), with steps clamped to the domain `[0, 1]³` and the 3×3
//! system solved by Gaussian elimination with partial pivoting. If Newton from the starting
//! guess does not converge, a **subdivision fallback** splits the volume (exact knot
//! insertion, `TensorBSpline::split`) breadth-first, discards pieces whose control-point
//! bounding box does not contain the point (the convex hull property of NURBS with positive
//! weights), and restarts Newton from the parametric centre of each surviving piece.

use std::collections::VecDeque;

use volmorph_spline::TensorBSpline;

use crate::TrivariateError;
use crate::bounds::point_box;
use crate::error::ctx;
use crate::eval::{EvalMethod, VolumeEvaluator};

/// Controls of [`invert`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InversionOptions {
    /// Accept parameters whose image is within this physical distance of the target
    /// (caller's length unit).
    pub tolerance: f64,
    /// Newton iterations per start.
    pub max_iterations: usize,
    /// Deepest subdivision level (each level halves one parametric axis).
    pub max_depth: usize,
    /// Most pieces examined by the subdivision fallback (bounds the work for points outside
    /// the volume).
    pub max_pieces: usize,
}

impl Default for InversionOptions {
    /// `tolerance = 1e-10`, 30 iterations, depth 15 (5 halvings per axis), 2048 pieces.
    fn default() -> Self {
        Self {
            tolerance: 1e-10,
            max_iterations: 30,
            max_depth: 15,
            max_pieces: 2048,
        }
    }
}

/// Solve the 3×3 system `j · x = b` (j column-major: `j[a]` = ∂P/∂u_a); `None` if singular.
fn solve3(j: &[f64; 9], b: [f64; 3]) -> Option<[f64; 3]> {
    solve3_rows(
        std::array::from_fn(|r| std::array::from_fn(|c| j[3 * c + r])),
        b,
    )
}

/// Solve the 3×3 system `m · x = b` (row-major `m`) by Gaussian elimination with partial
/// pivoting; `None` when singular relative to the matrix scale.
pub(crate) fn solve3_rows(m: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let mut a = [[0.0; 4]; 3];
    let mut scale: f64 = 0.0;
    for r in 0..3 {
        for c in 0..3 {
            a[r][c] = m[r][c];
            scale = scale.max(m[r][c].abs());
        }
        a[r][3] = b[r];
    }
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    for c in 0..3 {
        let mut piv = c;
        for r in c + 1..3 {
            if a[r][c].abs() > a[piv][c].abs() {
                piv = r;
            }
        }
        if a[piv][c].abs() <= 1e-14 * scale {
            return None;
        }
        a.swap(c, piv);
        for r in c + 1..3 {
            let f = a[r][c] / a[c][c];
            let pivot_row = a[c];
            for (dst, &src) in a[r][c..].iter_mut().zip(&pivot_row[c..]) {
                *dst -= f * src;
            }
        }
    }
    let mut x = [0.0; 3];
    for r in (0..3).rev() {
        let mut s = a[r][3];
        for c in r + 1..3 {
            s -= a[r][c] * x[c];
        }
        x[r] = s / a[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Newton from `u0`; returns the best parameters and their distance.
fn newton(
    e: &VolumeEvaluator<'_>,
    x: [f64; 3],
    u0: [f64; 3],
    opts: &InversionOptions,
) -> Result<([f64; 3], f64), TrivariateError> {
    let mut u = u0;
    let mut p = [0.0; 3];
    let mut g = [0.0; 9];
    let mut best = (u, f64::INFINITY);
    for _ in 0..=opts.max_iterations {
        e.eval_into(EvalMethod::default(), u, &mut p, &mut g)?;
        let d = dist(p, x);
        if d < best.1 {
            best = (u, d);
        }
        if d <= opts.tolerance {
            break;
        }
        let Some(step) = solve3(&g, [x[0] - p[0], x[1] - p[1], x[2] - p[2]]) else {
            break;
        };
        let next = std::array::from_fn(|a| (u[a] + step[a]).clamp(0.0, 1.0));
        if next == u {
            break;
        }
        u = next;
    }
    Ok(best)
}

/// Parameters `u ∈ [0, 1]³` with `|geometry(u) − x| ≤ options.tolerance`, by Newton from
/// `guess` (the parametric centre when `None`) with a subdivision fallback (see the
/// [module docs](self)). `geometry` must have 3 coordinates.
///
/// # Errors
/// [`TrivariateError::GeometryDimension`] unless the geometry is 3-D;
/// [`TrivariateError::InvalidArgument`] for non-finite input or a non-positive tolerance;
/// [`TrivariateError::InversionFailed`] when no parameters are found (e.g. the point lies
/// outside the volume), with the smallest distance reached.
pub fn invert(
    geometry: &TensorBSpline<3>,
    x: [f64; 3],
    guess: Option<[f64; 3]>,
    options: &InversionOptions,
) -> Result<[f64; 3], TrivariateError> {
    if geometry.dim() != 3 {
        return Err(TrivariateError::GeometryDimension {
            expected: 3,
            got: geometry.dim(),
        });
    }
    if !x.iter().all(|v| v.is_finite()) || options.tolerance.is_nan() || options.tolerance <= 0.0 {
        return Err(TrivariateError::InvalidArgument(format!(
            "point {x:?} must be finite and tolerance {} positive",
            options.tolerance
        )));
    }
    let e = VolumeEvaluator::new(geometry);
    let start = guess.unwrap_or([0.5; 3]);
    let (u, mut best) = newton(&e, x, start.map(|v| v.clamp(0.0, 1.0)), options)?;
    if best <= options.tolerance {
        return Ok(u);
    }
    let mut queue = VecDeque::new();
    queue.push_back((geometry.clone(), 0usize));
    let mut seen = 0usize;
    while let Some((piece, depth)) = queue.pop_front() {
        seen += 1;
        if seen > options.max_pieces {
            break;
        }
        let (lo, hi) = point_box(&piece.control_points());
        if (0..3).any(|k| x[k] < lo[k] - options.tolerance || x[k] > hi[k] + options.tolerance) {
            continue;
        }
        let dom = piece.domain();
        let centre = dom.map(|[a, b]| 0.5 * (a + b));
        let (u, d) = newton(&e, x, centre, options)?;
        if d <= options.tolerance {
            return Ok(u);
        }
        best = best.min(d);
        if depth < options.max_depth {
            let axis = depth % 3;
            let [a, b] = dom[axis];
            let (l, r) = piece
                .split(axis, 0.5 * (a + b))
                .map_err(ctx("inversion subdivision"))?;
            queue.push_back((l, depth + 1));
            queue.push_back((r, depth + 1));
        }
    }
    Err(TrivariateError::InversionFailed {
        x: x[0],
        y: x[1],
        z: x[2],
        residual: best,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{AggregateCurve, AggregateSurface, AggregateVolume, extrude, revolve};
    use volmorph_spline::KnotVector;
    use volmorph_testkit::Rng;

    fn deformed_cube() -> TensorBSpline<3> {
        let kv = KnotVector::clamped_uniform(3, 5, [0.0, 1.0]).unwrap();
        let mut pts = Vec::new();
        let mut ws = Vec::new();
        for k in 0..5 {
            for j in 0..5 {
                for i in 0..5 {
                    let (x, y, z) = (f64::from(i), f64::from(j), f64::from(k));
                    pts.extend([
                        x + 0.2 * (y * z).sin(),
                        y + 0.15 * (x * 1.3).cos(),
                        z + 0.1 * x * y / 4.0,
                    ]);
                    ws.push(1.0 + 0.1 * ((i + 2 * j + k) % 3) as f64);
                }
            }
        }
        TensorBSpline::new_rational([kv.clone(), kv.clone(), kv], 3, pts, ws).unwrap()
    }

    #[test]
    fn newton_inverts_a_smooth_volume() {
        let s = deformed_cube();
        let opts = InversionOptions::default();
        // The parameter-space corner, then random parameters.
        let mut rng = Rng::new(3);
        for i in 0..50 {
            let u = if i == 0 {
                [0.0; 3]
            } else {
                [rng.unit(), rng.unit(), rng.unit()]
            };
            let x = s.eval(u).unwrap();
            let got = invert(&s, [x[0], x[1], x[2]], None, &opts).unwrap();
            let back = s.eval(got).unwrap();
            assert!(dist([back[0], back[1], back[2]], [x[0], x[1], x[2]]) <= 1e-10);
            for a in 0..3 {
                assert!((got[a] - u[a]).abs() < 1e-8, "{got:?} vs {u:?}");
            }
        }
        assert!(matches!(
            invert(&s, [100.0, 0.0, 0.0], None, &opts),
            Err(TrivariateError::InversionFailed { .. })
        ));
        assert!(invert(&s, [f64::NAN, 0.0, 0.0], None, &opts).is_err());
    }

    #[test]
    fn subdivision_rescues_newton_on_a_thick_shell() {
        // A 350° revolved annulus: Newton from the centre parameter lands on the wrong side.
        let kv = KnotVector::clamped_uniform(1, 2, [0.0, 1.0]).unwrap();
        let c = AggregateCurve::new(
            TensorBSpline::new([kv], 3, vec![1.0, 0.0, 0.0, 2.0, 0.0, 0.0]).unwrap(),
        )
        .unwrap();
        let ring: AggregateSurface =
            revolve(&c, [0.0; 3], [0.0, 0.0, 1.0], 350f64.to_radians()).unwrap();
        let v: AggregateVolume = extrude(&ring, [0.0, 0.0, 1.0]).unwrap();
        let g = v.geometry();
        let opts = InversionOptions::default();
        for u in [
            [0.3, 0.02, 0.5],
            [0.9, 0.97, 0.1],
            [0.5, 0.5, 0.5],
            [0.1, 0.75, 0.9],
        ] {
            let x = g.eval(u).unwrap();
            let got = invert(g, [x[0], x[1], x[2]], Some([0.5, 0.0, 0.5]), &opts).unwrap();
            for a in 0..3 {
                assert!((got[a] - u[a]).abs() < 1e-8, "{got:?} vs {u:?}");
            }
        }
        // The hole of the ring is not part of the volume.
        assert!(invert(g, [0.0, 0.0, 0.5], None, &opts).is_err());
    }
}
