//! The cubic row of the separable path in vector registers (x86-64 AVX2, `f64×4`): the
//! blending of the row's control layers into its partial sums, and the row's voxels.
//!
//! Control points and partial sums are held as padded `[x, y, z, 0]` columns, one register
//! each, so a lane holds one coordinate and performs the scalar loop's operations on it in
//! its order (no multiply is fused with an add):
//!
//! * **blending**: the partial sum of column `c` is `0 + w₀·P₀[c] + w₁·P₁[c] + …` over the
//!   row's [`Layer`]s in their order, as the portable loop's `row_sum[c] += w·P[c]` from a
//!   zeroed row. Four columns are summed at a time in registers (each layer's weight is
//!   broadcast once per four columns), so a row's sums are stored once instead of once per
//!   layer.
//! * **voxels**: each voxel of the row is `0 + b₀·p_f + b₁·p_{f+1} + b₂·p_{f+2} + b₃·p_{f+3}`
//!   over the partial sums `p` with the voxel's basis values `b` and first column `f`. Four
//!   consecutive voxels with the same `f` (all but the groups straddling a knot) run in
//!   structure-of-arrays lanes: one register per coordinate, lane `l` voxel `l`, the four
//!   voxels' basis values transposed into one register per term and each sum broadcast;
//!   the three registers are interleaved back into `[x, y, z]` points. Other voxels run one
//!   at a time with `[x, y, z, 0]` lanes.
//!
//! So every coordinate has the portable loop's bits. The kernel is compiled with AVX2 enabled
//! and chosen at run time (`is_x86_feature_detected!`); calling it is the one `unsafe`
//! operation here (the intrinsics are safe inside it and every memory access goes through
//! slices).

use std::arch::x86_64::{
    __m256d, _mm256_add_pd, _mm256_mul_pd, _mm256_permute2f128_pd, _mm256_set1_pd,
    _mm256_setzero_pd, _mm256_unpackhi_pd, _mm256_unpacklo_pd,
};

use glam::DVec3;

/// One control layer of a row: the weight `n_w·n_v` of its `(v, w)` control row and the
/// index of the row's first control column (`c_lo`) in the control points.
pub(super) type Layer = (f64, usize);

/// Whether the CPU runs [`cubic_row`] (AVX2), checked once per call of the grid evaluation.
pub(super) fn available() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// The control points as padded `[x, y, z, 0]` columns, the layout [`cubic_row`] reads.
pub(super) fn padded(points: &[DVec3]) -> Vec<[f64; 4]> {
    points.iter().map(|p| [p.x, p.y, p.z, 0.0]).collect()
}

/// One cubic row: blends the `columns` control columns of every layer of `layers` (weights
/// and first columns into `points`, a [`padded`] net) into `sums` (resized to `columns`),
/// then sets `out[r]` from the four sums starting at column `firsts[r] − c_lo` with the
/// basis values `values[4r .. 4r + 4]`. A layer whose columns are missing from `points`
/// adds nothing, and a voxel whose columns are missing from `sums` is left as it is (as in
/// the portable loop). Requires [`available`].
#[allow(clippy::too_many_arguments)]
pub(super) fn cubic_row(
    points: &[[f64; 4]],
    layers: &[Layer],
    columns: usize,
    sums: &mut Vec<[f64; 4]>,
    firsts: &[usize],
    c_lo: usize,
    values: &[f64],
    out: &mut [DVec3],
) {
    sums.resize(columns, [0.0; 4]);
    // SAFETY: `row` is compiled with AVX2 enabled, and callers check `available()` first.
    // (It is otherwise safe: every memory access goes through slices.)
    #[allow(unsafe_code)]
    unsafe {
        row(points, layers, sums, firsts, c_lo, values, out);
    }
}

#[target_feature(enable = "avx2")]
fn row(
    points: &[[f64; 4]],
    layers: &[Layer],
    sums: &mut [[f64; 4]],
    firsts: &[usize],
    c_lo: usize,
    values: &[f64],
    out: &mut [DVec3],
) {
    let mut quads = sums.chunks_exact_mut(4);
    let mut column = 0;
    for q in &mut quads {
        if let Ok(q) = <&mut [[f64; 4]; 4]>::try_from(q) {
            blend(points, layers, column, q);
        }
        column += 4;
    }
    for s in quads.into_remainder() {
        blend(points, layers, column, std::array::from_mut(s));
        column += 1;
    }
    voxels(sums, firsts, c_lo, values, out);
}

/// The partial sums of the `N` columns from `column` on (see the [module docs](self)).
#[inline]
#[target_feature(enable = "avx2")]
fn blend<const N: usize>(
    points: &[[f64; 4]],
    layers: &[Layer],
    column: usize,
    out: &mut [[f64; 4]; N],
) {
    let mut acc = [_mm256_setzero_pd(); N];
    for &(w, start) in layers {
        let first = start + column;
        let Some(p) = points.get(first..first + N) else {
            continue;
        };
        let w = _mm256_set1_pd(w);
        for (a, &p) in acc.iter_mut().zip(p) {
            *a = _mm256_add_pd(*a, _mm256_mul_pd(w, bytemuck::cast::<_, __m256d>(p)));
        }
    }
    for (o, a) in out.iter_mut().zip(acc) {
        *o = bytemuck::cast(a);
    }
}

/// The voxels of the row from its partial sums (see the [module docs](self)): four voxels
/// at a time in structure-of-arrays lanes where they share their columns (one register per
/// coordinate, lane `l` the group's voxel `l`), one at a time with `[x, y, z, 0]` lanes
/// elsewhere.
#[inline]
#[target_feature(enable = "avx2")]
fn voxels(sums: &[[f64; 4]], firsts: &[usize], c_lo: usize, values: &[f64], out: &mut [DVec3]) {
    let flat: &mut [f64] = bytemuck::cast_slice_mut(out);
    let groups = flat
        .chunks_exact_mut(12)
        .zip(firsts.chunks_exact(4))
        .zip(values.chunks_exact(16));
    let mut done = 0;
    for ((o, f), b) in groups {
        // Plain tests, no closures or `Option` combinators: callgrind showed those
        // compiled without AVX2 and called out of line, a call per group.
        let shared = f[1] == f[0] && f[2] == f[0] && f[3] == f[0];
        let columns = match f[0].checked_sub(c_lo) {
            Some(c) if shared => sums.get(c..c + 4),
            _ => None,
        };
        let quad = match columns {
            Some(p) => <&[[f64; 4]; 4]>::try_from(p).ok(),
            None => None,
        };
        match (quad, <&mut [f64; 12]>::try_from(&mut *o)) {
            (Some(p), Ok(o)) => four_voxels(p, b, o),
            _ => one_by_one(sums, f, c_lo, b, bytemuck::cast_slice_mut(o)),
        }
        done += 4;
    }
    let (firsts, values) = (firsts.get(done..).unwrap_or(&[]), values.get(4 * done..));
    if let (Some(o), Some(b)) = (out.get_mut(done..), values) {
        one_by_one(sums, firsts, c_lo, b, o);
    }
}

/// Four voxels sharing the columns `p`: lane `l` of each coordinate's register is
/// `0 + b₀·p₀ + b₁·p₁ + b₂·p₂ + b₃·p₃` with voxel `l`'s basis values (`b[4l .. 4l + 4]`);
/// written to `o` as four `[x, y, z]` points.
#[inline]
#[target_feature(enable = "avx2")]
fn four_voxels(p: &[[f64; 4]; 4], b: &[f64], o: &mut [f64; 12]) {
    // The basis values by column: register n holds b_n of the four voxels.
    let r = [load(b, 0), load(b, 4), load(b, 8), load(b, 12)];
    let (t0, t1) = (
        _mm256_unpacklo_pd(r[0], r[1]),
        _mm256_unpackhi_pd(r[0], r[1]),
    );
    let (t2, t3) = (
        _mm256_unpacklo_pd(r[2], r[3]),
        _mm256_unpackhi_pd(r[2], r[3]),
    );
    let basis = [
        _mm256_permute2f128_pd::<0x20>(t0, t2),
        _mm256_permute2f128_pd::<0x20>(t1, t3),
        _mm256_permute2f128_pd::<0x31>(t0, t2),
        _mm256_permute2f128_pd::<0x31>(t1, t3),
    ];
    let (x, y, z) = (
        combine(&basis, p, 0),
        combine(&basis, p, 1),
        combine(&basis, p, 2),
    );
    // Interleave to x₀ y₀ z₀ x₁ | y₁ z₁ x₂ y₂ | z₂ x₃ y₃ z₃.
    let xy_even = _mm256_unpacklo_pd(x, y); // x₀ y₀ x₂ y₂
    let xy_odd = _mm256_unpackhi_pd(x, y); // x₁ y₁ x₃ y₃
    let zx = _mm256_unpacklo_pd(z, xy_odd); // z₀ x₁ z₂ x₃
    let yz = _mm256_unpackhi_pd(xy_odd, z); // y₁ z₁ y₃ z₃
    let quads = [
        _mm256_permute2f128_pd::<0x20>(xy_even, zx),
        _mm256_permute2f128_pd::<0x30>(yz, xy_even),
        _mm256_permute2f128_pd::<0x31>(zx, yz),
    ];
    for (chunk, q) in o.chunks_exact_mut(4).zip(quads) {
        chunk.copy_from_slice(&bytemuck::cast::<_, [f64; 4]>(q));
    }
}

/// Coordinate `a` of four voxels: `0 + b₀·p₀[a] + b₁·p₁[a] + b₂·p₂[a] + b₃·p₃[a]` with the
/// voxels' basis values by term in `basis`.
#[inline]
#[target_feature(enable = "avx2")]
fn combine(basis: &[__m256d; 4], p: &[[f64; 4]; 4], a: usize) -> __m256d {
    let mut acc = _mm256_setzero_pd();
    for (bn, pn) in basis.iter().zip(p) {
        acc = _mm256_add_pd(acc, _mm256_mul_pd(*bn, _mm256_set1_pd(pn[a])));
    }
    acc
}

/// Four values of `b` from `at` as a register (zeros where `b` is shorter).
#[inline]
#[target_feature(enable = "avx2")]
fn load(b: &[f64], at: usize) -> __m256d {
    match b.get(at..at + 4) {
        Some(&[b0, b1, b2, b3]) => bytemuck::cast([b0, b1, b2, b3]),
        _ => _mm256_setzero_pd(),
    }
}

/// Voxels one at a time: `out[r]` from the four sums starting at column `firsts[r] − c_lo`
/// with the basis values `values[4r .. 4r + 4]` in `[x, y, z, 0]` lanes; a voxel whose
/// columns are missing from `sums` is left as it is.
#[inline]
#[target_feature(enable = "avx2")]
fn one_by_one(sums: &[[f64; 4]], firsts: &[usize], c_lo: usize, values: &[f64], out: &mut [DVec3]) {
    for ((o, &f), b) in out.iter_mut().zip(firsts).zip(values.chunks_exact(4)) {
        let f = f - c_lo;
        if let Some(p) = sums.get(f..f + 4) {
            let term =
                |n: usize| _mm256_mul_pd(_mm256_set1_pd(b[n]), bytemuck::cast::<_, __m256d>(p[n]));
            let mut acc = _mm256_add_pd(_mm256_setzero_pd(), term(0));
            acc = _mm256_add_pd(acc, term(1));
            acc = _mm256_add_pd(acc, term(2));
            acc = _mm256_add_pd(acc, term(3));
            let v: [f64; 4] = bytemuck::cast(acc);
            *o = DVec3::new(v[0], v[1], v[2]);
        }
    }
}
