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
//!   over the partial sums `p` with the voxel's basis values `b` and first column `f`.
//!
//! So every coordinate has the portable loop's bits. The kernel is compiled with AVX2 enabled
//! and chosen at run time (`is_x86_feature_detected!`); calling it is the one `unsafe`
//! operation here (the intrinsics are safe inside it and every memory access goes through
//! slices).

use std::arch::x86_64::{__m256d, _mm256_add_pd, _mm256_mul_pd, _mm256_set1_pd, _mm256_setzero_pd};

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

/// The voxels of the row from its partial sums (see the [module docs](self)).
#[inline]
#[target_feature(enable = "avx2")]
fn voxels(sums: &[[f64; 4]], firsts: &[usize], c_lo: usize, values: &[f64], out: &mut [DVec3]) {
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
