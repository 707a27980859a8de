//! The batch kernel four points at a time, one point per lane (x86-64 AVX2, `f64×4`).
//!
//! For each group of four points the frame (parameters `to_parameter_matrix · (p − origin)`,
//! in `glam`'s order), the domain test, the knot span of every axis (the number of knots
//! `≤ u`, clamped as in the per-point kernel) and the Cox–de Boor basis row of every axis run
//! in vector registers, each lane holding one point. The `(p+1)³`-point contraction then runs
//! per point over the `[x, y, z, 0]` control points (one vector multiply and add per control
//! point, the basis value broadcast from memory): with the points in lanes it would need a
//! 4×4 transposition of every control point read, more instructions than the broadcasts.
//!
//! Every lane performs exactly the IEEE operations of [`point`](super::point) (and so of the
//! pointwise `BSplineLattice` evaluation) in the same order; no multiply is fused with an add
//! (Rust never contracts them and no FMA intrinsic is used), so every point gets the
//! per-point kernel's bits. Points outside the lattice (and NaN ones) are returned unchanged,
//! from the bits read; a group of fewer than four points at the end goes through
//! [`point`](super::point).
//!
//! For a batch of at least as many points as the table has entries, the control points of
//! every cell (knot-span triple) are first copied side by side into [`Cells`], so that a
//! point's `(p+1)³` control points are one bounds-checked slice read at constant offsets
//! rather than `(p+1)²` rows found through the lattice's strides.
//!
//! The loop is compiled with AVX2 enabled and chosen at run time
//! (`is_x86_feature_detected!`); calling it is the one `unsafe` operation here (the
//! intrinsics are safe inside it, and every memory access goes through bounds-checked
//! slices).

use std::arch::x86_64::{
    __m256d, _CMP_GE_OQ, _CMP_LE_OQ, _mm256_add_pd, _mm256_and_pd, _mm256_cmp_pd,
    _mm256_cvttpd_epi32, _mm256_div_pd, _mm256_max_pd, _mm256_min_pd, _mm256_movemask_pd,
    _mm256_mul_pd, _mm256_set_pd, _mm256_set1_pd, _mm256_setzero_pd, _mm256_sub_pd,
};

use glam::DVec3;

use super::{Net, point};

/// Whether the CPU runs [`run`] (AVX2).
pub(super) fn available() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// Largest cell table [`Cells::new`] builds, in bytes (the L2 cache of the reference
/// machine is 2 MiB; a 9×9×9 cubic lattice needs 442 KiB, Feng's 6×8×6 quadratic one 81 KiB).
const MAX_CELL_TABLE_BYTES: usize = 1 << 20;

/// The control points of every cell of a lattice side by side: cell `(c₀, c₁, c₂)` (knot
/// spans `cₐ + p`) holds its `(p+1)³` control points as `[x, y, z, 0]`, `u` fastest, then
/// `v`, then `w` (the contraction's order).
pub(super) struct Cells {
    quads: Vec<[f64; 4]>,
    counts: [usize; 3],
}

impl Cells {
    /// The table of `net`'s lattice of degree `p` on every axis, if it has at most as many
    /// entries as there are `points` to evaluate and at most [`MAX_CELL_TABLE_BYTES`].
    pub(super) fn new(net: &Net<'_>, p: usize, points: usize) -> Option<Self> {
        let counts = net.last_span.map(|s| s + 1 - p);
        let n = p + 1;
        let len = counts.iter().product::<usize>() * n * n * n;
        if len > points || len * std::mem::size_of::<[f64; 4]>() > MAX_CELL_TABLE_BYTES {
            return None;
        }
        let [nu, nv, _] = net.counts;
        let mut quads = Vec::with_capacity(len);
        for c2 in 0..counts[2] {
            for c1 in 0..counts[1] {
                for c0 in 0..counts[0] {
                    for k in 0..n {
                        for j in 0..n {
                            let base = c0 + nu * (c1 + j + nv * (c2 + k));
                            quads.extend_from_slice(net.ctrl.get(base..base + n)?);
                        }
                    }
                }
            }
        }
        Some(Self { quads, counts })
    }
}

/// Evaluate a lattice of degree `P` on every axis at `points` into `out` (same length),
/// four points at a time (see the [module docs](self)), reading control points from
/// `cells` where given. Requires [`available`].
pub(super) fn run<const P: usize>(
    net: &Net<'_>,
    cells: Option<&Cells>,
    points: &[DVec3],
    out: &mut [DVec3],
) {
    debug_assert!(available());
    // SAFETY: `groups` is compiled with AVX2 enabled, and callers check `available()`
    // first. (It is otherwise safe: every memory access is bounds-checked.)
    #[allow(unsafe_code)]
    unsafe {
        groups::<P>(net, cells, points, out);
    }
}

/// The loop over groups of four points. Requires AVX2.
#[target_feature(enable = "avx2")]
fn groups<const P: usize>(
    net: &Net<'_>,
    cells: Option<&Cells>,
    points: &[DVec3],
    out: &mut [DVec3],
) {
    let frame = net.lattice.frame();
    let m = frame.to_parameter_matrix();
    let origin = frame.origin().to_array().map(|o| _mm256_set1_pd(o));
    // Column `c`, row `r` of the parameter matrix, broadcast.
    let cols = [m.x_axis, m.y_axis, m.z_axis].map(|c| c.to_array().map(|v| _mm256_set1_pd(v)));
    let lo = net.domain.map(|d| _mm256_set1_pd(d[0]));
    let hi = net.domain.map(|d| _mm256_set1_pd(d[1]));
    let one = _mm256_set1_pd(1.0);
    let degree = _mm256_set1_pd(P as f64);
    let last = net.last_span.map(|s| _mm256_set1_pd(s as f64));
    let flat: &[f64] = bytemuck::cast_slice(points);
    let mut pairs = flat.chunks_exact(12).zip(out.chunks_exact_mut(4));
    'groups: for (p, o) in &mut pairs {
        let x = [0, 1, 2].map(|c| _mm256_set_pd(p[9 + c], p[6 + c], p[3 + c], p[c]));
        // `to_parameter`: `M · (p − origin)` as glam computes it, column by column.
        let d = [0, 1, 2].map(|c| _mm256_sub_pd(x[c], origin[c]));
        let u = [0, 1, 2].map(|r| {
            let s = _mm256_add_pd(
                _mm256_mul_pd(cols[0][r], d[0]),
                _mm256_mul_pd(cols[1][r], d[1]),
            );
            _mm256_add_pd(s, _mm256_mul_pd(cols[2][r], d[2]))
        });
        // `contains_parameter`: the closed domain on every axis (NaN lanes are outside).
        let within = |a: usize| {
            _mm256_and_pd(
                _mm256_cmp_pd::<_CMP_GE_OQ>(u[a], lo[a]),
                _mm256_cmp_pd::<_CMP_LE_OQ>(u[a], hi[a]),
            )
        };
        let inside = _mm256_movemask_pd(_mm256_and_pd(
            _mm256_and_pd(within(0), within(1)),
            within(2),
        ));
        let unmoved = |l: usize| DVec3::new(p[3 * l], p[3 * l + 1], p[3 * l + 2]);
        if inside == 0 {
            for (l, v) in o.iter_mut().enumerate() {
                *v = unmoved(l);
            }
            continue;
        }
        // Knot spans as in `point`: the number of knots ≤ u, minus one, clamped to
        // `[P, last_span]` (counts are small integers, exact in f64; a NaN or outside lane
        // gets some span in range and is not used).
        let mut spans = [[0usize; 4]; 3];
        for a in 0..3 {
            let mut count = _mm256_setzero_pd();
            for &t in &net.padded[a] {
                let le = _mm256_cmp_pd::<_CMP_LE_OQ>(_mm256_set1_pd(t), u[a]);
                count = _mm256_add_pd(count, _mm256_and_pd(le, one));
            }
            let s = _mm256_max_pd(_mm256_min_pd(_mm256_sub_pd(count, one), last[a]), degree);
            let s: [i32; 4] = bytemuck::cast(_mm256_cvttpd_epi32(s));
            spans[a] = s.map(|v| v as usize);
        }
        // The knots Cox–de Boor reads, lane by lane: window entry `i` is knot
        // `span + 1 − P + i`.
        let mut kt = [[_mm256_setzero_pd(); 6]; 3];
        for a in 0..3 {
            let window = |l: usize| net.knots[a].get(spans[a][l] + 1 - P..spans[a][l] + P + 1);
            let (Some(w0), Some(w1), Some(w2), Some(w3)) =
                (window(0), window(1), window(2), window(3))
            else {
                // Not reached (spans are clamped into range); the per-point kernel decides.
                for (l, v) in o.iter_mut().enumerate() {
                    *v = point_vec::<P>(net, unmoved(l));
                }
                continue 'groups;
            };
            for i in 0..2 * P {
                kt[a][i] = _mm256_set_pd(w3[i], w2[i], w1[i], w0[i]);
            }
        }
        // Basis rows, `basis[a][q][lane]`.
        let basis: [[[f64; 4]; 4]; 3] =
            std::array::from_fn(|a| basis_lanes::<P>(&kt[a], u[a]).map(bytemuck::cast));
        for (l, v) in o.iter_mut().enumerate() {
            *v = if inside & (1 << l) == 0 {
                unmoved(l)
            } else {
                let span = [spans[0][l], spans[1][l], spans[2][l]];
                match cells {
                    Some(cells) => contract_cell::<P>(cells, span, &basis, l),
                    None => contract::<P>(net, span, &basis, l),
                }
                .unwrap_or_else(|| unmoved(l))
            };
        }
    }
    let done = points.len() - points.len() % 4;
    for (v, &q) in out[done..].iter_mut().zip(&points[done..]) {
        *v = point_vec::<P>(net, q);
    }
}

/// [`point`] as a `DVec3`.
#[inline(always)]
fn point_vec<const P: usize>(net: &Net<'_>, p: DVec3) -> DVec3 {
    let r = point::<P>(net, p);
    DVec3::new(r[0], r[1], r[2])
}

/// `volmorph_spline::basis_in_span` for four points at once along one axis: `out[q]` is
/// basis function `q` of each lane's span (`kt[i]`: window entry `i` of each lane), the same
/// operations lane by lane.
#[inline]
#[target_feature(enable = "avx2")]
fn basis_lanes<const P: usize>(kt: &[__m256d; 6], u: __m256d) -> [__m256d; 4] {
    let zero = _mm256_setzero_pd();
    let mut left = [zero; 4];
    let mut right = [zero; 4];
    let mut out = [zero; 4];
    out[0] = _mm256_set1_pd(1.0);
    for j in 1..=P {
        left[j] = _mm256_sub_pd(u, kt[P - j]);
        right[j] = _mm256_sub_pd(kt[P - 1 + j], u);
        let mut saved = zero;
        for r in 0..j {
            let temp = _mm256_div_pd(out[r], _mm256_add_pd(right[r + 1], left[j - r]));
            out[r] = _mm256_add_pd(saved, _mm256_mul_pd(right[r + 1], temp));
            saved = _mm256_mul_pd(left[j - r], temp);
        }
        out[j] = saved;
    }
    out
}

/// `Σ b_u[i] b_v[j] b_w[k] P` for lane `lane` over the control points of the cell `span`,
/// in the order of the pointwise contraction (rows along u, then v, then w); `None` where
/// the cell's control points are missing (as in [`point`]).
#[inline]
#[target_feature(enable = "avx2")]
fn contract<const P: usize>(
    net: &Net<'_>,
    span: [usize; 3],
    basis: &[[[f64; 4]; 4]; 3],
    lane: usize,
) -> Option<DVec3> {
    let [nu, nv, _] = net.counts;
    let first = [span[0] - P, span[1] - P, span[2] - P];
    let weight = |a: usize, q: usize| _mm256_set1_pd(basis[a][q][lane]);
    let mut acc = _mm256_setzero_pd();
    for k in 0..=P {
        let mut pv = _mm256_setzero_pd();
        for j in 0..=P {
            let base = first[0] + nu * (first[1] + j + nv * (first[2] + k));
            let row = net.ctrl.get(base..=base + P)?;
            let mut pu = _mm256_setzero_pd();
            for (i, c) in row.iter().enumerate() {
                let c: __m256d = bytemuck::cast(*c);
                pu = _mm256_add_pd(pu, _mm256_mul_pd(weight(0, i), c));
            }
            pv = _mm256_add_pd(pv, _mm256_mul_pd(weight(1, j), pu));
        }
        acc = _mm256_add_pd(acc, _mm256_mul_pd(weight(2, k), pv));
    }
    let acc: [f64; 4] = bytemuck::cast(acc);
    Some(DVec3::new(acc[0], acc[1], acc[2]))
}

/// [`contract`] reading the cell's control points from `cells`: the same sums in the same
/// order.
#[inline]
#[target_feature(enable = "avx2")]
fn contract_cell<const P: usize>(
    cells: &Cells,
    span: [usize; 3],
    basis: &[[[f64; 4]; 4]; 3],
    lane: usize,
) -> Option<DVec3> {
    let n = P + 1;
    let [c0, c1, c2] = [span[0] - P, span[1] - P, span[2] - P];
    let first = ((c2 * cells.counts[1] + c1) * cells.counts[0] + c0) * n * n * n;
    let cell = cells.quads.get(first..first + n * n * n)?;
    let weight = |a: usize, q: usize| _mm256_set1_pd(basis[a][q][lane]);
    let mut acc = _mm256_setzero_pd();
    for k in 0..n {
        let mut pv = _mm256_setzero_pd();
        for j in 0..n {
            let mut pu = _mm256_setzero_pd();
            for i in 0..n {
                let c: __m256d = bytemuck::cast(cell[(k * n + j) * n + i]);
                pu = _mm256_add_pd(pu, _mm256_mul_pd(weight(0, i), c));
            }
            pv = _mm256_add_pd(pv, _mm256_mul_pd(weight(1, j), pu));
        }
        acc = _mm256_add_pd(acc, _mm256_mul_pd(weight(2, k), pv));
    }
    let acc: [f64; 4] = bytemuck::cast(acc);
    Some(DVec3::new(acc[0], acc[1], acc[2]))
}
