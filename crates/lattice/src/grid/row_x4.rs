//! The cubic row loop of the separable path with the three coordinates of a point in one
//! vector register (x86-64 AVX2, `f64×4`, the fourth lane unused).
//!
//! Each voxel of a row is `0 + b₀·p_f + b₁·p_{f+1} + b₂·p_{f+2} + b₃·p_{f+3}` over the row's
//! control-column partial sums `p` (the scalar loop's sums in its order, per coordinate: a
//! lane holds one coordinate, and no multiply is fused with an add), so every coordinate has
//! the scalar loop's bits. The partial sums are copied once per row into padded
//! `[x, y, z, 0]` columns so that each is one aligned-size load.
//!
//! The loop is compiled with AVX2 enabled and chosen at run time (`is_x86_feature_detected!`);
//! calling it is the one `unsafe` operation here (the intrinsics are safe inside it and every
//! memory access goes through slices).

use std::arch::x86_64::{__m256d, _mm256_add_pd, _mm256_mul_pd, _mm256_set1_pd, _mm256_setzero_pd};

use glam::DVec3;

/// Whether the CPU runs [`cubic_row`] (AVX2), checked once per call of the grid evaluation.
pub(super) fn available() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// The cubic voxels of one row: `out[r]` from the four padded partial sums starting at
/// column `firsts[r] − c_lo` with the basis values `values[4r .. 4r + 4]`; a voxel whose
/// columns are missing from `sums` is left as it is (as in the scalar loop). `sums` is
/// overwritten with the padded copy of `row_sum`. Requires [`available`].
pub(super) fn cubic_row(
    row_sum: &[DVec3],
    sums: &mut Vec<[f64; 4]>,
    firsts: &[usize],
    c_lo: usize,
    values: &[f64],
    out: &mut [DVec3],
) {
    sums.clear();
    sums.extend(row_sum.iter().map(|p| [p.x, p.y, p.z, 0.0]));
    // SAFETY: `voxels` is compiled with AVX2 enabled, and callers check `available()`
    // first. (It is otherwise safe: every memory access goes through slices.)
    #[allow(unsafe_code)]
    unsafe {
        voxels(sums, firsts, c_lo, values, out);
    }
}

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
