//! Evaluation of trivariate splines: points and first partial derivatives (Martin & Cohen §4).
//!
//! Two methods give the same numbers (up to rounding; the tests check agreement):
//!
//! * [`EvalMethod::Refinement`] — the paper's scheme. Stacking `k − 1 = p` copies of `t` in the
//!   span `[u_s, u_{s+1})` makes the refined control point `D_{μ−k+1}` the point on the curve,
//!   and `D_{μ−k+2}` together with it gives the derivative (eq. 4). Only the rows of the
//!   refinement matrix producing these points are generated, by the triangular α scheme run
//!   from its leaves: the two leaf rows `l` (`= A_{μ−k}`, the blossom `P(t,…,t,u_s)`) and `r`
//!   (`= A_{μ−k+2}`, the blossom `P(t,…,t,u_{s+1})`) are propagated together through the
//!   `p − 1` levels that do not involve the first-level factor `γ = (t − u_s)/(u_{s+1} − u_s)`,
//!   and the point row is their blend `(1 − γ)·l + γ·r` (paper, Figure 2). The derivative row is
//!   `p/(u_{s+1} − t)·(A_{μ−k+2} − A_{μ−k+1}) = p/(u_{s+1} − u_s)·(r − l)`; the second form is
//!   used because it stays finite at the right end of the domain, where `t = u_{s+1}`. The
//!   per-axis rows are applied as `A_w ⊗² (A_v ⊗¹ (A_u ⊗⁰ P^w))` restricted to the four
//!   refined points needed (point and one neighbour per axis), sum-factorised over the
//!   `(p_u+1)(p_v+1)(p_w+1)` sub-net. For rational volumes the derivative of the projected
//!   point is eq. (6), `P_u = p·w_{100}/((u_{s+1} − u_*)·w_{000})·(D_{100} − D_{000})`, which
//!   is the quotient rule `(H_u − w_u·P)/w` on the homogeneous sums; the latter is computed.
//! * [`EvalMethod::DeBoor`] — Cox–de Boor basis functions and their derivatives contracted with
//!   the control net, as [`TensorBSpline::eval_with_gradient_into`] does.
//!
//! Output layout (both methods): `value[..dim]` is the point, `gradient[a·dim + c]` is
//! `∂S_c/∂u_a` (axis-major, `a` = 0 for u). Neither method allocates per point.
//! [`EvalMethod::default`] is the faster one on the benchmark `benches/evaluate.rs`.
//!
//! Batches ([`VolumeEvaluator::eval_batch`]) of tricubic volumes run the refinement method
//! four parameter points per vector where the CPU has AVX2 (`lanes_x4`: spans and α rows one
//! point per lane), with the per-point kernel's bits and errors.

use multiversion::multiversion;
use rayon::prelude::*;
use volmorph_spline::{MAX_DEGREE, TensorBSpline};

use crate::TrivariateError;
use crate::error::ctx;

#[cfg(target_arch = "x86_64")]
mod lanes_x4;

/// Per-axis row buffer length.
const ROW: usize = MAX_DEGREE + 1;

/// Largest homogeneous dimension (value dimension + 1 if rational) evaluated by the refinement
/// kernel; larger attribute tuples use [`EvalMethod::DeBoor`].
pub const MAX_REFINEMENT_HDIM: usize = 8;

/// Points per rayon task in batch evaluation: large enough to amortise scheduling, small enough
/// to balance two to a few dozen cores.
const BATCH: usize = 4096;

/// Which evaluation algorithm to use (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EvalMethod {
    /// Knot refinement with the triangular α scheme (Martin & Cohen §4). The default: it was
    /// faster than de Boor on `benches/evaluate.rs` (12.0 M points with derivatives per
    /// second against 4.7 M, two cores).
    #[default]
    Refinement,
    /// Cox–de Boor basis contraction.
    DeBoor,
}

/// The rows of the evaluation refinement matrix for one axis: `point[q]` multiplies control
/// point `s − p + q` to give the refined point `D_{μ−k+1}` (the curve point), `deriv[q]` gives
/// the derivative. `knots` is the full knot vector, `s` a non-empty span containing `t`.
/// `P > 0` asserts the degree is `P` (constant-length loops); `P = 0` uses `p`.
#[inline(always)]
fn alpha_rows<const R: usize, const P: usize>(
    knots: &[f64],
    p: usize,
    s: usize,
    t: f64,
    point: &mut [f64],
    deriv: &mut [f64],
) {
    let p = if P > 0 { P } else { p };
    if p == 0 {
        point[0] = 1.0;
        deriv[0] = 0.0;
        return;
    }
    let mut l = [0.0; R];
    let mut r = [0.0; R];
    l[p - 1] = 1.0;
    r[p] = 1.0;
    // Levels p−1 … 1 of the triangle, from the leaves towards the control points.
    for lev in (1..p).rev() {
        l[lev - 1] = 0.0;
        r[lev - 1] = 0.0;
        for q in lev..=p {
            let j = s + q - p;
            let lo = knots[j];
            let a = (t - lo) / (knots[j + p + 1 - lev] - lo);
            let (tl, tr) = (l[q], r[q]);
            l[q - 1] += (1.0 - a) * tl;
            r[q - 1] += (1.0 - a) * tr;
            l[q] = a * tl;
            r[q] = a * tr;
        }
    }
    let (us, ue) = (knots[s], knots[s + 1]);
    let d = ue - us;
    let g = (t - us) / d;
    let c = p as f64 / d;
    for q in 0..=p {
        point[q] = (1.0 - g) * l[q] + g * r[q];
        deriv[q] = c * (r[q] - l[q]);
    }
}

/// A prepared evaluator for one trivariate spline (geometry or attribute).
#[derive(Debug, Clone, Copy)]
pub struct VolumeEvaluator<'a> {
    spline: &'a TensorBSpline<3>,
}

impl<'a> VolumeEvaluator<'a> {
    /// An evaluator borrowing `spline`.
    #[must_use]
    pub fn new(spline: &'a TensorBSpline<3>) -> Self {
        Self { spline }
    }

    /// The evaluated spline.
    #[must_use]
    pub fn spline(&self) -> &'a TensorBSpline<3> {
        self.spline
    }

    /// Point and first partial derivatives at `u` by `method` (layout in the
    /// [module docs](self)). No allocation.
    ///
    /// # Errors
    /// [`TrivariateError::Spline`] for parameters outside the domain (or NaN) and for
    /// `value.len() < dim` or `gradient.len() < 3·dim`.
    pub fn eval_into(
        &self,
        method: EvalMethod,
        u: [f64; 3],
        value: &mut [f64],
        gradient: &mut [f64],
    ) -> Result<(), TrivariateError> {
        match method {
            EvalMethod::Refinement if self.spline.homogeneous_dim() <= MAX_REFINEMENT_HDIM => {
                self.refinement_into(u, value, gradient)
            }
            _ => self
                .spline
                .eval_with_gradient_into(u, value, gradient)
                .map_err(ctx("de Boor evaluation")),
        }
    }

    /// [`EvalMethod::Refinement`] evaluation (see [`VolumeEvaluator::eval_into`]); for
    /// homogeneous dimensions above [`MAX_REFINEMENT_HDIM`] it returns
    /// [`TrivariateError::InvalidArgument`].
    ///
    /// # Errors
    /// As [`VolumeEvaluator::eval_into`].
    pub fn refinement_into(
        &self,
        u: [f64; 3],
        value: &mut [f64],
        gradient: &mut [f64],
    ) -> Result<(), TrivariateError> {
        refinement_point(self.spline, u, value, gradient)
    }

    /// Evaluate many parameter triples in parallel (rayon over batches of points):
    /// `values[i·dim..]` and `gradients[i·3·dim..]` receive point `i` in the layout of
    /// [`VolumeEvaluator::eval_into`].
    ///
    /// # Errors
    /// [`TrivariateError::DataLength`] for output slices of the wrong length; the error of
    /// the first failing point otherwise.
    pub fn eval_batch(
        &self,
        method: EvalMethod,
        params: &[[f64; 3]],
        values: &mut [f64],
        gradients: &mut [f64],
    ) -> Result<(), TrivariateError> {
        self.eval_batch_by(method, params, values, gradients, Path::Lanes)
    }

    /// [`VolumeEvaluator::eval_batch`] with refinement chunks through the loop `path`.
    fn eval_batch_by(
        &self,
        method: EvalMethod,
        params: &[[f64; 3]],
        values: &mut [f64],
        gradients: &mut [f64],
        path: Path,
    ) -> Result<(), TrivariateError> {
        let dim = self.spline.dim();
        if values.len() != params.len() * dim {
            return Err(TrivariateError::DataLength {
                what: "batch values",
                expected: params.len() * dim,
                got: values.len(),
            });
        }
        if gradients.len() != params.len() * 3 * dim {
            return Err(TrivariateError::DataLength {
                what: "batch gradients",
                expected: params.len() * 3 * dim,
                got: gradients.len(),
            });
        }
        params
            .par_chunks(BATCH)
            .zip(values.par_chunks_mut(BATCH * dim))
            .zip(gradients.par_chunks_mut(BATCH * 3 * dim))
            .try_for_each(|((ps, vs), gs)| match method {
                EvalMethod::Refinement if self.spline.homogeneous_dim() <= MAX_REFINEMENT_HDIM => {
                    refinement_chunk(self.spline, ps, vs, gs, path)
                }
                _ => {
                    for ((u, v), g) in ps
                        .iter()
                        .zip(vs.chunks_exact_mut(dim))
                        .zip(gs.chunks_exact_mut(3 * dim))
                    {
                        self.eval_into(method, *u, v, g)?;
                    }
                    Ok(())
                }
            })
    }
}

/// [`VolumeEvaluator::refinement_into`]: dispatches on the largest degree to row buffers
/// sized to it (zeroing `MAX_DEGREE`-sized buffers per point would cost more than the
/// arithmetic of a tricubic evaluation). Compiled twice — for the baseline target and for
/// x86-64 with AVX2 and FMA, where the homogeneous tuples of the contraction become vector
/// operations — and the variant is chosen at run time from the CPU's features. Rust never
/// contracts a multiply and an add into an FMA, so both variants give the same bits.
#[multiversion(targets("x86_64+avx2+fma"))]
fn refinement_point(
    s: &TensorBSpline<3>,
    u: [f64; 3],
    value: &mut [f64],
    gradient: &mut [f64],
) -> Result<(), TrivariateError> {
    refinement_dispatch(s, u, value, gradient)
}

/// Which loop a batch's refinement chunks run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Path {
    /// Tricubic volumes four points per vector (`lanes_x4`) where the CPU has AVX2; other
    /// volumes and CPUs as [`Path::PerPoint`].
    Lanes,
    /// One point at a time ([`refinement_run`]), the portable loop (chosen by the tests).
    #[cfg_attr(not(test), allow(dead_code))]
    PerPoint,
}

/// One chunk of a batch's refinement evaluation through the loop `path` (the homogeneous
/// dimension is at most [`MAX_REFINEMENT_HDIM`]; `values`/`gradients` hold `dim` and
/// `3·dim` numbers per point).
fn refinement_chunk(
    s: &TensorBSpline<3>,
    params: &[[f64; 3]],
    values: &mut [f64],
    gradients: &mut [f64],
    path: Path,
) -> Result<(), TrivariateError> {
    #[cfg(target_arch = "x86_64")]
    if path == Path::Lanes && s.degrees() == [3; 3] && lanes_x4::available() {
        return match s.homogeneous_dim() {
            1 => lanes_x4::run::<1>(s, params, values, gradients),
            2 => lanes_x4::run::<2>(s, params, values, gradients),
            3 => lanes_x4::run::<3>(s, params, values, gradients),
            4 => lanes_x4::run::<4>(s, params, values, gradients),
            5 => lanes_x4::run::<5>(s, params, values, gradients),
            6 => lanes_x4::run::<6>(s, params, values, gradients),
            7 => lanes_x4::run::<7>(s, params, values, gradients),
            _ => lanes_x4::run::<8>(s, params, values, gradients),
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = path;
    refinement_run(s, params, values, gradients)
}

/// [`refinement_point`] over a run of points (`values`/`gradients` hold `dim` and `3·dim`
/// numbers per point), choosing the compiled variant once per run.
#[multiversion(targets("x86_64+avx2+fma"))]
fn refinement_run(
    s: &TensorBSpline<3>,
    params: &[[f64; 3]],
    values: &mut [f64],
    gradients: &mut [f64],
) -> Result<(), TrivariateError> {
    let dim = s.dim();
    for ((u, v), g) in params
        .iter()
        .zip(values.chunks_exact_mut(dim))
        .zip(gradients.chunks_exact_mut(3 * dim))
    {
        refinement_dispatch(s, *u, v, g)?;
    }
    Ok(())
}

/// Row-length dispatch shared by the compiled variants (inlined into each).
#[inline(always)]
fn refinement_dispatch(
    s: &TensorBSpline<3>,
    u: [f64; 3],
    value: &mut [f64],
    gradient: &mut [f64],
) -> Result<(), TrivariateError> {
    let maxdeg = s.degrees().into_iter().max().unwrap_or(0);
    if maxdeg < 4 {
        refinement_kernel::<4>(s, u, value, gradient)
    } else if maxdeg < 8 {
        refinement_kernel::<8>(s, u, value, gradient)
    } else {
        refinement_kernel::<ROW>(s, u, value, gradient)
    }
}

/// [`VolumeEvaluator::refinement_into`] with per-axis rows of `R > max degree` entries.
#[inline(always)]
fn refinement_kernel<const R: usize>(
    s: &TensorBSpline<3>,
    u: [f64; 3],
    value: &mut [f64],
    gradient: &mut [f64],
) -> Result<(), TrivariateError> {
    let dim = s.dim();
    if value.len() < dim || gradient.len() < 3 * dim {
        return Err(TrivariateError::DataLength {
            what: "evaluation output",
            expected: 4 * dim,
            got: value.len().min(dim) + gradient.len(),
        });
    }
    let knots = s.knots();
    let mut pt = [[0.0; R]; 3];
    let mut de = [[0.0; R]; 3];
    let mut first = [0usize; 3];
    let mut ord = [0usize; 3];
    // Tricubic volumes (the common case) get loops of constant length, fully unrolled.
    let tricubic = s.degrees() == [3; 3];
    for a in 0..3 {
        let kv = &knots[a];
        let span = kv.find_span(u[a]).map_err(ctx("refinement evaluation"))?;
        let p = kv.degree();
        if tricubic {
            alpha_rows::<R, 3>(kv.knots(), p, span, u[a], &mut pt[a], &mut de[a]);
        } else {
            alpha_rows::<R, 0>(kv.knots(), p, span, u[a], &mut pt[a], &mut de[a]);
        }
        first[a] = span - p;
        ord[a] = p + 1;
    }
    let hdim = s.homogeneous_dim();
    macro_rules! go {
        ($h:literal) => {
            if tricubic {
                contract::<$h, R, 4>(s, first, ord, &pt, &de, value, gradient)
            } else {
                contract::<$h, R, 0>(s, first, ord, &pt, &de, value, gradient)
            }
        };
    }
    match hdim {
        1 => go!(1),
        2 => go!(2),
        3 => go!(3),
        4 => go!(4),
        5 => go!(5),
        6 => go!(6),
        7 => go!(7),
        8 => go!(8),
        _ => {
            return Err(TrivariateError::InvalidArgument(format!(
                "refinement evaluation supports at most {MAX_REFINEMENT_HDIM} homogeneous \
                 coordinates, got {hdim}"
            )));
        }
    }
    Ok(())
}

/// Sum-factorised application of the per-axis rows to the sub-net at `first` (homogeneous
/// dimension `H`), then projection of rational results. `O > 0` asserts that every axis
/// has order `O` (`ord` is then ignored and the loops have constant length); `O = 0` reads
/// the orders from `ord`.
#[inline(always)]
fn contract<const H: usize, const R: usize, const O: usize>(
    s: &TensorBSpline<3>,
    first: [usize; 3],
    ord: [usize; 3],
    pt: &[[f64; R]; 3],
    de: &[[f64; R]; 3],
    value: &mut [f64],
    gradient: &mut [f64],
) {
    let coefs = s.homogeneous_coefficients();
    let [n0, n1, _] = s.counts();
    let s1 = H * n0;
    let s2 = s1 * n1;
    let (o0, o1, o2) = if O > 0 {
        (O, O, O)
    } else {
        (ord[0], ord[1], ord[2])
    };
    let mut h = [0.0; H];
    let mut hu = [0.0; H];
    let mut hv = [0.0; H];
    let mut hw = [0.0; H];
    for k in 0..o2 {
        let mut sp = [0.0; H];
        let mut su = [0.0; H];
        let mut sv = [0.0; H];
        for j in 0..o1 {
            let base = first[0] * H + (first[1] + j) * s1 + (first[2] + k) * s2;
            let row = &coefs[base..base + o0 * H];
            let mut rp = [0.0; H];
            let mut ru = [0.0; H];
            for (c, (&a, &b)) in row
                .chunks_exact(H)
                .zip(pt[0][..o0].iter().zip(&de[0][..o0]))
            {
                for x in 0..H {
                    rp[x] += a * c[x];
                    ru[x] += b * c[x];
                }
            }
            let (bp, bd) = (pt[1][j], de[1][j]);
            for x in 0..H {
                sp[x] += bp * rp[x];
                su[x] += bp * ru[x];
                sv[x] += bd * rp[x];
            }
        }
        let (cp, cd) = (pt[2][k], de[2][k]);
        for x in 0..H {
            h[x] += cp * sp[x];
            hu[x] += cp * su[x];
            hv[x] += cp * sv[x];
            hw[x] += cd * sp[x];
        }
    }
    project(s, &h, [&hu, &hv, &hw], value, gradient);
}

/// The point and gradient from the homogeneous sums of [`contract`] (`h` the point; `hu`,
/// `hv`, `hw` its derivatives along u, v, w): for rational volumes the projection `h/w` and the quotient
/// rule `(h_a − w_a·P)/w`, otherwise the sums themselves.
#[inline(always)]
fn project<const H: usize>(
    s: &TensorBSpline<3>,
    h: &[f64; H],
    [hu, hv, hw]: [&[f64; H]; 3],
    value: &mut [f64],
    gradient: &mut [f64],
) {
    let dim = s.dim();
    if s.is_rational() {
        let w = h[dim];
        let inv = 1.0 / w;
        for c in 0..dim {
            let p = h[c] * inv;
            value[c] = p;
            gradient[c] = (hu[c] - hu[dim] * p) * inv;
            gradient[dim + c] = (hv[c] - hv[dim] * p) * inv;
            gradient[2 * dim + c] = (hw[c] - hw[dim] * p) * inv;
        }
    } else {
        value[..dim].copy_from_slice(&h[..dim]);
        gradient[..dim].copy_from_slice(&hu[..dim]);
        gradient[dim..2 * dim].copy_from_slice(&hv[..dim]);
        gradient[2 * dim..3 * dim].copy_from_slice(&hw[..dim]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use volmorph_spline::KnotVector;
    use volmorph_testkit::Rng;

    /// A random rational volume from a seed, with non-uniform clamped knots.
    pub(crate) fn random_volume(
        seed: u64,
        deg: [usize; 3],
        n: [usize; 3],
        dim: usize,
    ) -> TensorBSpline<3> {
        let mut rng = Rng::new(seed);
        let mut next = move || rng.unit();
        let knots: [KnotVector; 3] = std::array::from_fn(|a| {
            let m = n[a] - deg[a] - 1;
            let mut interior: Vec<f64> = (0..m).map(|_| 0.05 + 0.9 * next()).collect();
            interior.sort_by(f64::total_cmp);
            KnotVector::clamped(deg[a], &interior, [0.0, 1.0]).unwrap()
        });
        let count = n[0] * n[1] * n[2];
        let pts: Vec<f64> = (0..count * dim).map(|_| 4.0 * next() - 2.0).collect();
        let ws: Vec<f64> = (0..count).map(|_| 0.3 + 2.0 * next()).collect();
        TensorBSpline::new_rational(knots, dim, pts, ws).unwrap()
    }

    #[test]
    fn alpha_rows_are_basis_and_derivative() {
        let kv =
            KnotVector::new(3, vec![0., 0., 0., 0., 0.2, 0.5, 0.5, 0.9, 1., 1., 1., 1.]).unwrap();
        let mut p = [0.0; ROW];
        let mut d = [0.0; ROW];
        for i in 0..=50 {
            let t = f64::from(i) / 50.0;
            let s = kv.find_span(t).unwrap();
            alpha_rows::<ROW, 0>(kv.knots(), 3, s, t, &mut p, &mut d);
            let m = volmorph_spline::basis::basis_derivs(&kv, s, t, 1).unwrap();
            let (v, g) = m.split_at(4);
            for q in 0..4 {
                assert!((p[q] - v[q]).abs() < 1e-14, "t={t} q={q}");
                assert!((d[q] - g[q]).abs() < 1e-11, "t={t} q={q}");
            }
        }
    }

    #[test]
    fn linear_precision_of_identity_volume() {
        let kv = |n| KnotVector::clamped_uniform(3, n, [0.0, 1.0]).unwrap();
        let s = TensorBSpline::identity([kv(5), kv(6), kv(7)]).unwrap();
        let e = VolumeEvaluator::new(&s);
        let mut v = [0.0; 3];
        let mut g = [0.0; 9];
        e.refinement_into([0.3, 0.71, 1.0], &mut v, &mut g).unwrap();
        for (x, y) in v.iter().zip([0.3, 0.71, 1.0]) {
            assert!((x - y).abs() < 1e-14);
        }
        for a in 0..3 {
            for c in 0..3 {
                let want = if a == c { 1.0 } else { 0.0 };
                assert!((g[3 * a + c] - want).abs() < 1e-12);
            }
        }
        assert!(e.refinement_into([1.2, 0.0, 0.0], &mut v, &mut g).is_err());
        assert!(
            e.refinement_into([f64::NAN, 0.0, 0.0], &mut v, &mut g)
                .is_err()
        );
        assert!(e.refinement_into([0.0; 3], &mut v[..2], &mut g).is_err());
    }

    #[test]
    fn batch_matches_pointwise() {
        let s = random_volume(7, [3, 2, 3], [8, 5, 6], 3);
        let e = VolumeEvaluator::new(&s);
        // The parameter-space corner, then random parameters.
        let mut rng = Rng::new(8);
        let params: Vec<[f64; 3]> = std::iter::once([0.0; 3])
            .chain((1..10_000).map(|_| [rng.unit(), rng.unit(), rng.unit()]))
            .collect();
        let mut vs = vec![0.0; params.len() * 3];
        let mut gs = vec![0.0; params.len() * 9];
        e.eval_batch(EvalMethod::default(), &params, &mut vs, &mut gs)
            .unwrap();
        let mut v = [0.0; 3];
        let mut g = [0.0; 9];
        for (i, u) in params.iter().enumerate().step_by(997) {
            e.eval_into(EvalMethod::default(), *u, &mut v, &mut g)
                .unwrap();
            assert_eq!(&vs[3 * i..3 * i + 3], &v, "point {i}");
            assert_eq!(&gs[9 * i..9 * i + 9], &g, "point {i}");
        }
        assert!(
            e.eval_batch(EvalMethod::DeBoor, &params, &mut vs[1..], &mut gs)
                .is_err()
        );
    }

    /// The tricubic path (constant-length loops) against de Boor, rational and polynomial,
    /// uniform and non-uniform knots, including the domain faces.
    #[test]
    fn tricubic_fast_path_equals_de_boor() {
        for (seed, dim) in [(1, 3), (2, 1), (3, 4)] {
            let rational = random_volume(seed, [3; 3], [8, 6, 7], dim);
            let polynomial =
                TensorBSpline::new(rational.knots().clone(), dim, rational.control_points())
                    .unwrap();
            for s in [&rational, &polynomial] {
                let e = VolumeEvaluator::new(s);
                let mut v1 = vec![0.0; dim];
                let mut g1 = vec![0.0; 3 * dim];
                let (mut v2, mut g2) = (v1.clone(), g1.clone());
                let mut rng = Rng::new(seed + 10);
                for i in 0..500u32 {
                    let mut u = [rng.unit(), rng.unit(), rng.unit()];
                    if i % 50 == 0 {
                        u[(i / 50 % 3) as usize] = 1.0;
                    }
                    e.eval_into(EvalMethod::Refinement, u, &mut v1, &mut g1)
                        .unwrap();
                    e.eval_into(EvalMethod::DeBoor, u, &mut v2, &mut g2)
                        .unwrap();
                    for (a, b) in v1.iter().zip(&v2).chain(g1.iter().zip(&g2)) {
                        assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "{u:?}: {a} vs {b}");
                    }
                }
            }
        }
    }

    /// A tricubic volume of `n` control points per axis and value dimension `dim`, rational
    /// or not, with clamped random knots on `[0, 1]` or the unclamped integers `0 … n + 3`
    /// (domain `[3, n]`).
    fn tricubic(
        seed: u64,
        n: usize,
        dim: usize,
        rational: bool,
        clamped: bool,
    ) -> TensorBSpline<3> {
        let s = random_volume(seed, [3; 3], [n; 3], dim);
        let knots = if clamped {
            s.knots().clone()
        } else {
            let kv = KnotVector::new(3, (0..=n + 3).map(|i| i as f64).collect()).unwrap();
            [kv.clone(), kv.clone(), kv]
        };
        if rational {
            let w = s.weights().unwrap();
            TensorBSpline::new_rational(knots, dim, s.control_points(), w).unwrap()
        } else {
            TensorBSpline::new(knots, dim, s.control_points()).unwrap()
        }
    }

    /// Parameters in the domain of `s`: random, on knot planes, on the domain's faces and
    /// corners, `count` of them.
    fn domain_params(s: &TensorBSpline<3>, seed: u64, count: usize) -> Vec<[f64; 3]> {
        let mut rng = Rng::new(seed);
        (0..count)
            .map(|i| {
                std::array::from_fn(|a| {
                    let kv = &s.knots()[a];
                    let [lo, hi] = kv.domain();
                    match (i + a) % 5 {
                        0 | 1 => lo + rng.unit() * (hi - lo),
                        2 => kv.knots()[kv.degree() + rng.index(kv.num_basis() - kv.degree() + 1)],
                        3 => [lo, hi][rng.index(2)],
                        _ => lo + (hi - lo) * rng.index(4) as f64 / 3.0,
                    }
                })
            })
            .collect()
    }

    /// The batch through both loops against the per-point kernel, bit for bit.
    fn check_lanes(s: &TensorBSpline<3>, params: &[[f64; 3]]) {
        let dim = s.dim();
        let e = VolumeEvaluator::new(s);
        let mut want_v = vec![0.0; params.len() * dim];
        let mut want_g = vec![0.0; params.len() * 3 * dim];
        for ((u, v), g) in params
            .iter()
            .zip(want_v.chunks_exact_mut(dim))
            .zip(want_g.chunks_exact_mut(3 * dim))
        {
            e.refinement_into(*u, v, g).unwrap();
        }
        for path in [Path::Lanes, Path::PerPoint] {
            let mut vs = vec![f64::NAN; want_v.len()];
            let mut gs = vec![f64::NAN; want_g.len()];
            e.eval_batch_by(EvalMethod::Refinement, params, &mut vs, &mut gs, path)
                .unwrap();
            let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            for (i, u) in params.iter().enumerate() {
                let (v, g) = (i * dim..(i + 1) * dim, 3 * i * dim..3 * (i + 1) * dim);
                assert_eq!(bits(&vs[v.clone()]), bits(&want_v[v]), "{path:?} at {u:?}");
                assert_eq!(bits(&gs[g.clone()]), bits(&want_g[g]), "{path:?} at {u:?}");
            }
        }
    }

    #[test]
    fn lanes_equal_per_point_bits_for_every_homogeneous_dimension() {
        for (seed, dim, rational, clamped) in [
            (1, 3, true, true),
            (2, 3, false, true),
            (3, 1, true, false),
            (4, 7, true, true),
            (5, 8, false, false),
            (6, 2, false, true),
            (7, 5, true, false),
            (8, 4, false, true),
        ] {
            let s = tricubic(seed, 5 + seed as usize % 4, dim, rational, clamped);
            // 1 001 points: groups of four and a tail of one.
            check_lanes(&s, &domain_params(&s, seed, 1001));
            check_lanes(&s, &domain_params(&s, seed, 3));
        }
    }

    /// A batch with a point outside the domain, NaN or infinite reports the per-point
    /// kernel's error for the first such point, through both loops; the points before it are
    /// evaluated.
    #[test]
    fn lanes_report_the_first_point_outside_the_domain() {
        let s = tricubic(9, 8, 3, true, true);
        let e = VolumeEvaluator::new(&s);
        let good = domain_params(&s, 9, 64);
        for (n, bad) in [
            (13, [0.5, 1.5, 0.5]),
            (40, [0.5, 0.5, f64::NAN]),
            (2, [f64::INFINITY, 0.5, 0.5]),
            (63, [0.5, f64::NEG_INFINITY, 0.5]),
            (21, [-1e-300, 0.5, 0.5]),
        ] {
            let mut params = good.clone();
            params[n] = bad;
            params[n + 1..]
                .iter_mut()
                .step_by(5)
                .for_each(|u| u[1] = 2.0);
            let (mut v1, mut g1) = (vec![0.0; 3], vec![0.0; 9]);
            let want = e
                .refinement_into(bad, &mut v1, &mut g1)
                .unwrap_err()
                .to_string();
            for path in [Path::Lanes, Path::PerPoint] {
                let mut vs = vec![0.0; params.len() * 3];
                let mut gs = vec![0.0; params.len() * 9];
                let got = e
                    .eval_batch_by(EvalMethod::Refinement, &params, &mut vs, &mut gs, path)
                    .unwrap_err();
                assert_eq!(got.to_string(), want, "{path:?}");
                for (i, u) in params[..n].iter().enumerate() {
                    e.refinement_into(*u, &mut v1, &mut g1).unwrap();
                    assert_eq!(&vs[3 * i..3 * i + 3], &v1, "{path:?} point {i}");
                    assert_eq!(&gs[9 * i..9 * i + 9], &g1, "{path:?} point {i}");
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]
        #[test]
        fn lanes_equal_per_point(
            seed in any::<u64>(), n in 4usize..10, dim in 1usize..8,
            rational in any::<bool>(), clamped in any::<bool>(), count in 0usize..300,
        ) {
            let s = tricubic(seed, n, dim, rational, clamped);
            check_lanes(&s, &domain_params(&s, seed ^ 7, count));
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn refinement_equals_de_boor(
            seed in any::<u64>(),
            d0 in 0usize..4, d1 in 1usize..5, d2 in 1usize..4,
            extra in 0usize..4, dim in 1usize..5,
            u in 0.0f64..=1.0, v in 0.0f64..=1.0, w in 0.0f64..=1.0,
        ) {
            let deg = [d0, d1, d2];
            let n = [d0 + 1 + extra, d1 + 2, d2 + 1 + extra / 2];
            let s = random_volume(seed, deg, n, dim);
            let e = VolumeEvaluator::new(&s);
            let mut v1 = vec![0.0; dim];
            let mut g1 = vec![0.0; 3 * dim];
            let mut v2 = v1.clone();
            let mut g2 = g1.clone();
            e.eval_into(EvalMethod::Refinement, [u, v, w], &mut v1, &mut g1).unwrap();
            e.eval_into(EvalMethod::DeBoor, [u, v, w], &mut v2, &mut g2).unwrap();
            for (a, b) in v1.iter().zip(&v2) {
                prop_assert!((a - b).abs() <= 1e-11 * (1.0 + b.abs()), "{a} vs {b}");
            }
            for (a, b) in g1.iter().zip(&g2) {
                prop_assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "{a} vs {b}");
            }
        }
    }
}
