//! Modeling operators that lift aggregates one level up the hierarchy (Martin & Cohen §3):
//! curve → surface → volume by extrusion, revolution or ruling.
//!
//! # Conventions
//!
//! * The new parametric axis is always **appended last** (a surface made from a curve `u` has
//!   parameters `(u, t)`; a volume made from a surface `(u, v)` has `(u, v, t)`), with `t`
//!   running over `[0, 1]`.
//! * Geometry: extrusion moves `t = 0 → 1` along a vector; revolution turns by a signed angle
//!   about an oriented axis (right-hand rule), built from exact rational quadratic arcs
//!   (NURBS Book A8.1: at most 90° per arc, double interior knots); ruling interpolates linearly
//!   (in homogeneous coordinates) between two objects.
//! * Attributes: with a single operand (extrude, revolve) every attribute is **ruled with
//!   itself** — it does not vary along `t` (degree 1, two equal layers). With two operands
//!   (rule) attributes with the same name are ruled across; an attribute present in only one
//!   operand is ruled with itself.

use volmorph_spline::{KnotVector, TensorBSpline};

use crate::TrivariateError;
use crate::aggregate::{Aggregate, GEOMETRY_DIM, check_unit_domain};
use crate::error::ctx;

/// Stack `layers` (homogeneous nets with identical knots, `dim` and rationality) along a new
/// last axis with knot vector `kv`.
fn stack<const N: usize, const M: usize>(
    knots: &[KnotVector; N],
    kv: KnotVector,
    dim: usize,
    rational: bool,
    layers: &[&[f64]],
) -> Result<TensorBSpline<M>, TrivariateError> {
    if M != N + 1 {
        return Err(TrivariateError::InvalidArgument(format!(
            "lifting {N} parameters gives {} parameters, not {M}",
            N + 1
        )));
    }
    let new_knots: [KnotVector; M] =
        std::array::from_fn(|a| if a < N { knots[a].clone() } else { kv.clone() });
    let total: usize = layers.iter().map(|l| l.len()).sum();
    let mut coefs = Vec::with_capacity(total);
    for l in layers {
        coefs.extend_from_slice(l);
    }
    TensorBSpline::from_homogeneous(new_knots, dim, rational, coefs).map_err(ctx("lifted object"))
}

fn linear_kv() -> Result<KnotVector, TrivariateError> {
    KnotVector::bezier(1, [0.0, 1.0]).map_err(ctx("ruling knot vector"))
}

/// Rule a spline with itself along a new last axis: constant in `t`.
fn self_ruled<const N: usize, const M: usize>(
    s: &TensorBSpline<N>,
) -> Result<TensorBSpline<M>, TrivariateError> {
    let h = s.homogeneous_coefficients();
    stack(s.knots(), linear_kv()?, s.dim(), s.is_rational(), &[h, h])
}

fn self_ruled_attributes<const N: usize, const M: usize>(
    a: &Aggregate<N>,
) -> Result<Vec<(String, TensorBSpline<M>)>, TrivariateError> {
    a.attributes()
        .iter()
        .map(|at| Ok((at.name().to_owned(), self_ruled(at.spline())?)))
        .collect()
}

fn check_vec(what: &str, v: [f64; 3]) -> Result<f64, TrivariateError> {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if !(n.is_finite() && n > 0.0) {
        return Err(TrivariateError::InvalidArgument(format!(
            "{what} {v:?} must be finite and non-zero"
        )));
    }
    Ok(n)
}

/// Extrude an aggregate along `direction` (physical units): the result's geometry at `t` is the
/// original geometry translated by `t · direction`. `M` must be `N + 1`.
///
/// # Errors
/// [`TrivariateError::InvalidArgument`] for a zero or non-finite direction (or `M ≠ N + 1`).
pub fn extrude<const N: usize, const M: usize>(
    a: &Aggregate<N>,
    direction: [f64; 3],
) -> Result<Aggregate<M>, TrivariateError> {
    check_vec("extrusion direction", direction)?;
    let g = a.geometry();
    let h0 = g.homogeneous_coefficients();
    let hdim = g.homogeneous_dim();
    let mut h1 = h0.to_vec();
    for c in h1.chunks_exact_mut(hdim) {
        let w = if g.is_rational() {
            c[GEOMETRY_DIM]
        } else {
            1.0
        };
        for k in 0..GEOMETRY_DIM {
            c[k] += w * direction[k];
        }
    }
    let geometry = stack(
        g.knots(),
        linear_kv()?,
        GEOMETRY_DIM,
        g.is_rational(),
        &[h0, &h1],
    )?;
    Ok(Aggregate::from_parts_unchecked(
        geometry,
        self_ruled_attributes(a)?,
    ))
}

/// Revolve an aggregate by `angle` radians (sign by the right-hand rule about `axis_direction`)
/// about the axis through `axis_point`. Each control point sweeps an exact rational circular
/// arc, so every point of the result lies at constant distance from the axis along `t`.
/// `M` must be `N + 1`.
///
/// # Errors
/// [`TrivariateError::InvalidArgument`] for a zero axis direction, non-finite input or
/// `|angle|` outside `(0, 2π]`.
pub fn revolve<const N: usize, const M: usize>(
    a: &Aggregate<N>,
    axis_point: [f64; 3],
    axis_direction: [f64; 3],
    angle: f64,
) -> Result<Aggregate<M>, TrivariateError> {
    let len = check_vec("axis direction", axis_direction)?;
    if !axis_point.iter().all(|x| x.is_finite()) {
        return Err(TrivariateError::InvalidArgument(format!(
            "axis point {axis_point:?} must be finite"
        )));
    }
    let two_pi = std::f64::consts::TAU;
    if !(angle.is_finite() && angle != 0.0 && angle.abs() <= two_pi) {
        return Err(TrivariateError::InvalidArgument(format!(
            "revolution angle {angle} must be non-zero with |angle| <= 2π"
        )));
    }
    let ax = axis_direction.map(|x| x / len);
    // Number of arcs: at most a quarter turn each.
    let quarter = std::f64::consts::FRAC_PI_2;
    let arcs = ((angle.abs() / quarter) - 1e-12).ceil().clamp(1.0, 4.0) as usize;
    let dtheta = angle / arcs as f64;
    let wm = (dtheta / 2.0).cos();
    let mut interior = Vec::with_capacity(2 * (arcs - 1));
    for i in 1..arcs {
        let k = i as f64 / arcs as f64;
        interior.extend([k, k]);
    }
    let kv = KnotVector::clamped(2, &interior, [0.0, 1.0]).map_err(ctx("revolution knots"))?;
    let g = a.geometry();
    let pts = g.control_points();
    let ws = g.weights();
    let ncp = g.num_control_points();
    let nlayers = 2 * arcs + 1;
    // Layer j: (angle factor c, s, radial scale, weight).
    let mut layer_coefs: Vec<Vec<f64>> = Vec::with_capacity(nlayers);
    for j in 0..nlayers {
        let theta = dtheta * j as f64 / 2.0;
        let (scale, wj) = if j % 2 == 0 {
            (1.0, 1.0)
        } else {
            (1.0 / wm, wm)
        };
        let (s, c) = theta.sin_cos();
        let mut layer = Vec::with_capacity(ncp * 4);
        for i in 0..ncp {
            let p = &pts[3 * i..3 * i + 3];
            let d = [
                p[0] - axis_point[0],
                p[1] - axis_point[1],
                p[2] - axis_point[2],
            ];
            let along = d[0] * ax[0] + d[1] * ax[1] + d[2] * ax[2];
            let oc = [
                axis_point[0] + along * ax[0],
                axis_point[1] + along * ax[1],
                axis_point[2] + along * ax[2],
            ];
            let x = [p[0] - oc[0], p[1] - oc[1], p[2] - oc[2]];
            let y = [
                ax[1] * x[2] - ax[2] * x[1],
                ax[2] * x[0] - ax[0] * x[2],
                ax[0] * x[1] - ax[1] * x[0],
            ];
            let w = ws.as_ref().map_or(1.0, |v| v[i]) * wj;
            for k in 0..3 {
                layer.push(w * (oc[k] + scale * (c * x[k] + s * y[k])));
            }
            layer.push(w);
        }
        layer_coefs.push(layer);
    }
    let refs: Vec<&[f64]> = layer_coefs.iter().map(Vec::as_slice).collect();
    let geometry = stack(g.knots(), kv, GEOMETRY_DIM, true, &refs)?;
    Ok(Aggregate::from_parts_unchecked(
        geometry,
        self_ruled_attributes(a)?,
    ))
}

/// Knot values (with multiplicity) of `from` missing in `into`, restricted to the open domain.
fn missing_knots(into: &KnotVector, from: &KnotVector) -> Vec<f64> {
    let [s, e] = into.domain();
    let mut out = Vec::new();
    for (v, m) in from.distinct() {
        if v > s && v < e {
            let have = into.multiplicity(v);
            for _ in have..m {
                out.push(v);
            }
        }
    }
    out
}

/// Make two splines share degrees, knot vectors and rationality by knot refinement (exact).
fn make_compatible<const N: usize>(
    what: &str,
    a: &TensorBSpline<N>,
    b: &TensorBSpline<N>,
) -> Result<(TensorBSpline<N>, TensorBSpline<N>), TrivariateError> {
    if a.degrees() != b.degrees() {
        return Err(TrivariateError::Incompatible(format!(
            "{what}: degrees {:?} and {:?} differ",
            a.degrees(),
            b.degrees()
        )));
    }
    if a.dim() != b.dim() {
        return Err(TrivariateError::Incompatible(format!(
            "{what}: value dimensions {} and {} differ",
            a.dim(),
            b.dim()
        )));
    }
    let (mut a, mut b) = if a.is_rational() || b.is_rational() {
        (a.to_rational(), b.to_rational())
    } else {
        (a.clone(), b.clone())
    };
    for axis in 0..N {
        let add_a = missing_knots(&a.knots()[axis], &b.knots()[axis]);
        let add_b = missing_knots(&b.knots()[axis], &a.knots()[axis]);
        if !add_a.is_empty() {
            a = a.refine(axis, &add_a).map_err(ctx(what))?;
        }
        if !add_b.is_empty() {
            b = b.refine(axis, &add_b).map_err(ctx(what))?;
        }
        if a.knots()[axis] != b.knots()[axis] {
            return Err(TrivariateError::Incompatible(format!(
                "{what}: end knots of axis {axis} differ and cannot be merged"
            )));
        }
    }
    Ok((a, b))
}

fn rule_pair<const N: usize, const M: usize>(
    what: &str,
    a: &TensorBSpline<N>,
    b: &TensorBSpline<N>,
) -> Result<TensorBSpline<M>, TrivariateError> {
    let (a, b) = make_compatible(what, a, b)?;
    stack(
        a.knots(),
        linear_kv()?,
        a.dim(),
        a.is_rational(),
        &[a.homogeneous_coefficients(), b.homogeneous_coefficients()],
    )
}

/// Rule between two aggregates: the result is `first` at `t = 0` and `second` at `t = 1`,
/// linear in `t` (in homogeneous coordinates). Components are made compatible by exact knot
/// refinement (union of the knot vectors); they must have equal degrees. Attributes named in
/// both operands are ruled across (equal degrees and dimensions required); an attribute of only
/// one operand is ruled with itself. Attribute order: `first`'s, then `second`'s new ones.
/// `M` must be `N + 1`.
///
/// # Errors
/// [`TrivariateError::Incompatible`] for differing degrees, attribute dimensions or end knots.
pub fn rule<const N: usize, const M: usize>(
    first: &Aggregate<N>,
    second: &Aggregate<N>,
) -> Result<Aggregate<M>, TrivariateError> {
    let geometry = rule_pair("geometry", first.geometry(), second.geometry())?;
    let mut attrs = Vec::new();
    for at in first.attributes() {
        let name = at.name();
        let s = match second.attribute(name) {
            Some(other) => rule_pair(&format!("attribute {name:?}"), at.spline(), other)?,
            None => self_ruled(at.spline())?,
        };
        attrs.push((name.to_owned(), s));
    }
    for at in second.attributes() {
        if first.attribute(at.name()).is_none() {
            attrs.push((at.name().to_owned(), self_ruled(at.spline())?));
        }
    }
    let out = Aggregate::from_parts_unchecked(geometry, attrs);
    check_unit_domain("ruled geometry", out.geometry())?;
    Ok(out)
}
