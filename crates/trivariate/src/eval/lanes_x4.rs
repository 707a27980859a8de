//! Tricubic refinement evaluation four parameter points at a time, one point per lane
//! (x86-64 AVX2, `f64×4`).
//!
//! For each group of four points the domain test, the knot span of every axis (the number
//! of knots `≤ u`, clamped to the last non-empty span: `KnotVector::find_span`'s span inside
//! the domain) and the point and derivative α rows of every axis (`alpha_rows` with `P = 3`)
//! run in vector registers, each lane holding one point. The rows are then transposed into
//! each point's `[f64; 4]` rows and the sub-net contraction runs per point, as in the
//! per-point kernel: its homogeneous tuples are the vector there, written out with
//! intrinsics for homogeneous dimension 4 (rational 3D volumes: the accumulators stay in
//! registers and every control point is one load, two multiplies and two adds).
//!
//! Every lane performs exactly the IEEE operations of the per-point kernel in the same
//! order; no multiply is fused with an add (Rust never contracts them and no FMA intrinsic is
//! used), so every point gets the per-point kernel's bits. A group with a point outside the
//! domain (or NaN) goes through the per-point kernel point by point, which reports the error
//! of the first such point, as does a group of fewer than four points at the end.
//!
//! The loop is compiled with AVX2 enabled and chosen at run time
//! (`is_x86_feature_detected!`); calling it is the one `unsafe` operation here (the
//! intrinsics are safe inside it, and every memory access goes through bounds-checked
//! slices).

use std::arch::x86_64::{
    __m256d, _CMP_GE_OQ, _CMP_LE_OQ, _mm256_add_pd, _mm256_and_pd, _mm256_cmp_pd,
    _mm256_cvttpd_epi32, _mm256_div_pd, _mm256_min_pd, _mm256_movemask_pd, _mm256_mul_pd,
    _mm256_permute2f128_pd, _mm256_set_pd, _mm256_set1_pd, _mm256_setzero_pd, _mm256_sub_pd,
    _mm256_unpackhi_pd, _mm256_unpacklo_pd,
};

use volmorph_spline::TensorBSpline;

use super::{contract, project, refinement_run};
use crate::TrivariateError;

/// The degree this kernel evaluates on every axis.
const P: usize = 3;

/// Each point's per-axis rows of a group: `rows[a][lane]`.
type PointRows = [[[f64; 4]; 4]; 3];

/// Whether the CPU runs [`run`] (AVX2).
pub(super) fn available() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// Points and first derivatives of the tricubic volume `s` of homogeneous dimension `H` at
/// `params` into `values` (`dim` per point) and `gradients` (`3·dim` per point), four points
/// at a time (see the [module docs](self)). Requires [`available`], degree 3 on every axis,
/// `H = s.homogeneous_dim()` and output slices of exactly those lengths.
///
/// # Errors
/// The per-point kernel's error for the first point outside the domain (or NaN).
pub(super) fn run<const H: usize>(
    s: &TensorBSpline<3>,
    params: &[[f64; 3]],
    values: &mut [f64],
    gradients: &mut [f64],
) -> Result<(), TrivariateError> {
    debug_assert!(available() && s.degrees() == [P; 3] && s.homogeneous_dim() == H);
    // SAFETY: `groups` is compiled with AVX2 enabled, and callers check `available()`
    // first. (It is otherwise safe: every memory access is bounds-checked.)
    #[allow(unsafe_code)]
    unsafe {
        groups::<H>(s, params, values, gradients)
    }
}

/// The loop over groups of four points. Requires AVX2.
#[target_feature(enable = "avx2")]
fn groups<const H: usize>(
    s: &TensorBSpline<3>,
    params: &[[f64; 3]],
    values: &mut [f64],
    gradients: &mut [f64],
) -> Result<(), TrivariateError> {
    let dim = s.dim();
    let kv = s.knots();
    let knots: [&[f64]; 3] = std::array::from_fn(|a| kv[a].knots());
    let lo = kv.each_ref().map(|k| _mm256_set1_pd(k.domain()[0]));
    let hi = kv.each_ref().map(|k| _mm256_set1_pd(k.domain()[1]));
    let last = kv.each_ref().map(|k| _mm256_set1_pd(k.last_span() as f64));
    let one = _mm256_set1_pd(1.0);
    let mut groups = params
        .chunks_exact(4)
        .zip(values.chunks_exact_mut(4 * dim))
        .zip(gradients.chunks_exact_mut(12 * dim));
    'groups: for ((u, v), g) in &mut groups {
        let t = [0, 1, 2].map(|a| _mm256_set_pd(u[3][a], u[2][a], u[1][a], u[0][a]));
        // `KnotVector::contains` on every axis (NaN lanes are outside).
        let within = |a: usize| {
            _mm256_and_pd(
                _mm256_cmp_pd::<_CMP_GE_OQ>(t[a], lo[a]),
                _mm256_cmp_pd::<_CMP_LE_OQ>(t[a], hi[a]),
            )
        };
        let inside = _mm256_and_pd(_mm256_and_pd(within(0), within(1)), within(2));
        if _mm256_movemask_pd(inside) != 0b1111 {
            refinement_run(s, u, v, g)?;
            continue;
        }
        let mut pt = [[_mm256_setzero_pd(); 4]; 3];
        let mut de = [[_mm256_setzero_pd(); 4]; 3];
        let mut first = [[0usize; 3]; 4];
        for a in 0..3 {
            // Inside the domain, the number of knots ≤ u minus one (at least `P`: the first
            // `P + 1` knots are ≤ the domain start), clamped to the last non-empty span, is
            // `find_span`'s span. Counts are small integers, exact in f64.
            let mut count = _mm256_setzero_pd();
            for &k in knots[a] {
                let le = _mm256_cmp_pd::<_CMP_LE_OQ>(_mm256_set1_pd(k), t[a]);
                count = _mm256_add_pd(count, _mm256_and_pd(le, one));
            }
            let span = _mm256_min_pd(_mm256_sub_pd(count, one), last[a]);
            let span: [i32; 4] = bytemuck::cast(_mm256_cvttpd_epi32(span));
            // The knots the α rows read: window entry `i` is knot `span − 2 + i`.
            let window = |l: usize| {
                let s = span[l] as usize;
                knots[a].get(s - (P - 1)..s + P + 1)
            };
            let (Some(w0), Some(w1), Some(w2), Some(w3)) =
                (window(0), window(1), window(2), window(3))
            else {
                // Not reached (spans lie in `P ..= last_span`); the per-point kernel decides.
                refinement_run(s, u, v, g)?;
                continue 'groups;
            };
            let w: [__m256d; 2 * P] =
                std::array::from_fn(|i| _mm256_set_pd(w3[i], w2[i], w1[i], w0[i]));
            (pt[a], de[a]) = alpha_lanes(&w, t[a]);
            for (f, &sp) in first.iter_mut().zip(&span) {
                f[a] = sp as usize - P;
            }
        }
        // Each point's rows: `rows[a][lane]` is `pt[a]` (or `de[a]`) of that lane.
        let rows_of = |r: &[[__m256d; 4]; 3]| r.map(|q| transpose(q).map(bytemuck::cast));
        let (pts, des): (PointRows, PointRows) = (rows_of(&pt), rows_of(&de));
        for (l, (v, g)) in v
            .chunks_exact_mut(dim)
            .zip(g.chunks_exact_mut(3 * dim))
            .enumerate()
        {
            let p = [pts[0][l], pts[1][l], pts[2][l]];
            let d = [des[0][l], des[1][l], des[2][l]];
            if H == 4 {
                contract_h4(s, first[l], &p, &d, v, g);
            } else {
                contract::<H, 4, 4>(s, first[l], [P + 1; 3], &p, &d, v, g);
            }
        }
    }
    let done = params.len() - params.len() % 4;
    refinement_run(
        s,
        &params[done..],
        &mut values[done * dim..],
        &mut gradients[done * 3 * dim..],
    )
}

/// `alpha_rows::<4, 3>` for four points at once: the point and derivative rows of each
/// lane's span (`w[i]`: knot `span − 2 + i` of each lane), the same operations lane by lane.
#[inline]
#[target_feature(enable = "avx2")]
fn alpha_lanes(w: &[__m256d; 2 * P], t: __m256d) -> ([__m256d; 4], [__m256d; 4]) {
    let zero = _mm256_setzero_pd();
    let one = _mm256_set1_pd(1.0);
    let mut l = [zero; 4];
    let mut r = [zero; 4];
    l[P - 1] = one;
    r[P] = one;
    for lev in (1..P).rev() {
        l[lev - 1] = zero;
        r[lev - 1] = zero;
        for q in lev..=P {
            // Knot `j = span + q − P` is window entry `q − 1`, knot `j + P + 1 − lev` entry
            // `q + P − lev`.
            let lo = w[q - 1];
            let a = _mm256_div_pd(_mm256_sub_pd(t, lo), _mm256_sub_pd(w[q + P - lev], lo));
            let (tl, tr) = (l[q], r[q]);
            l[q - 1] = _mm256_add_pd(l[q - 1], _mm256_mul_pd(_mm256_sub_pd(one, a), tl));
            r[q - 1] = _mm256_add_pd(r[q - 1], _mm256_mul_pd(_mm256_sub_pd(one, a), tr));
            l[q] = _mm256_mul_pd(a, tl);
            r[q] = _mm256_mul_pd(a, tr);
        }
    }
    let (us, ue) = (w[P - 1], w[P]);
    let d = _mm256_sub_pd(ue, us);
    let g = _mm256_div_pd(_mm256_sub_pd(t, us), d);
    let c = _mm256_div_pd(_mm256_set1_pd(P as f64), d);
    let point = std::array::from_fn(|q| {
        _mm256_add_pd(
            _mm256_mul_pd(_mm256_sub_pd(one, g), l[q]),
            _mm256_mul_pd(g, r[q]),
        )
    });
    let deriv = std::array::from_fn(|q| _mm256_mul_pd(c, _mm256_sub_pd(r[q], l[q])));
    (point, deriv)
}

/// `contract::<4, 4, 4>` with the homogeneous 4-tuples in vector registers: the same sums in
/// the same order (each starting from `0.0`), then the same projection.
#[inline]
#[target_feature(enable = "avx2")]
fn contract_h4(
    s: &TensorBSpline<3>,
    first: [usize; 3],
    pt: &[[f64; 4]; 3],
    de: &[[f64; 4]; 3],
    value: &mut [f64],
    gradient: &mut [f64],
) {
    let coefs = s.homogeneous_coefficients();
    let [n0, n1, _] = s.counts();
    let (s1, s2) = (4 * n0, 4 * n0 * n1);
    let a = pt[0].map(|x| _mm256_set1_pd(x));
    let b = de[0].map(|x| _mm256_set1_pd(x));
    let zero = _mm256_setzero_pd();
    let (mut h, mut hu, mut hv, mut hw) = (zero, zero, zero, zero);
    for k in 0..=P {
        let (mut sp, mut su, mut sv) = (zero, zero, zero);
        for j in 0..=P {
            let base = first[0] * 4 + (first[1] + j) * s1 + (first[2] + k) * s2;
            let Some(row) = coefs.get(base..base + 4 * (P + 1)) else {
                // Not reached (the spans are valid); the scalar contraction decides.
                contract::<4, 4, 4>(s, first, [P + 1; 3], pt, de, value, gradient);
                return;
            };
            let (mut rp, mut ru) = (zero, zero);
            for (i, c) in bytemuck::cast_slice::<f64, [f64; 4]>(row)
                .iter()
                .enumerate()
            {
                let c: __m256d = bytemuck::cast(*c);
                rp = _mm256_add_pd(rp, _mm256_mul_pd(a[i], c));
                ru = _mm256_add_pd(ru, _mm256_mul_pd(b[i], c));
            }
            let (bp, bd) = (_mm256_set1_pd(pt[1][j]), _mm256_set1_pd(de[1][j]));
            sp = _mm256_add_pd(sp, _mm256_mul_pd(bp, rp));
            su = _mm256_add_pd(su, _mm256_mul_pd(bp, ru));
            sv = _mm256_add_pd(sv, _mm256_mul_pd(bd, rp));
        }
        let (cp, cd) = (_mm256_set1_pd(pt[2][k]), _mm256_set1_pd(de[2][k]));
        h = _mm256_add_pd(h, _mm256_mul_pd(cp, sp));
        hu = _mm256_add_pd(hu, _mm256_mul_pd(cp, su));
        hv = _mm256_add_pd(hv, _mm256_mul_pd(cp, sv));
        hw = _mm256_add_pd(hw, _mm256_mul_pd(cd, sp));
    }
    let [h, hu, hv, hw]: [[f64; 4]; 4] = [h, hu, hv, hw].map(bytemuck::cast);
    project(s, &h, [&hu, &hv, &hw], value, gradient);
}

/// The 4×4 transpose: lane `l` of `rows[q]` becomes lane `q` of the result's entry `l`.
#[inline]
#[target_feature(enable = "avx2")]
fn transpose(rows: [__m256d; 4]) -> [__m256d; 4] {
    let [r0, r1, r2, r3] = rows;
    let (t0, t1) = (_mm256_unpacklo_pd(r0, r1), _mm256_unpackhi_pd(r0, r1));
    let (t2, t3) = (_mm256_unpacklo_pd(r2, r3), _mm256_unpackhi_pd(r2, r3));
    [
        _mm256_permute2f128_pd::<0x20>(t0, t2),
        _mm256_permute2f128_pd::<0x20>(t1, t3),
        _mm256_permute2f128_pd::<0x31>(t0, t2),
        _mm256_permute2f128_pd::<0x31>(t1, t3),
    ]
}
