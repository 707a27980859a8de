//! The two passes of [`super::lanes`] with four flat coordinates per register (x86-64
//! AVX2, `f64×4`).
//!
//! Boxes: twelve coordinates (four voxels) per step, so the axis pattern of the lanes
//! repeats (`[x y z x] [y z x y] [z x y z]`); each lane performs exactly the scalar
//! operations of [`lanes::fill_one`] in their order: `vminpd a, b` is `if a < b { a } else
//! { b }` (the second operand on NaN or equal zeros), `vmaxpd` likewise, ordered compares,
//! truncation by `vroundpd`, selects by `vblendvpd`, no fused multiply-add. The remaining
//! coordinates run [`lanes::fill_one`] itself.
//!
//! Tally: a voxel on the two-cell path builds its four rows of two cells as
//! `[w₀·d, w₀, w₁·d, w₁]` with `w = ((sign·w_z)·w_y)·w_x` (multiplication commutes exactly)
//! and adds each to its two `[V, W]` cells with one add (`f32` cells after one conversion
//! `vcvtpd2ps`, the rounding of `as f32`). Every other voxel takes the per-voxel path
//! ([`lanes::each_voxel`]).
//!
//! The kernels are compiled with AVX2 enabled and chosen at run time
//! (`is_x86_feature_detected!`); calling them is the one `unsafe` operation here (the
//! intrinsics are safe inside them and every memory access goes through slices).

use std::arch::x86_64::{
    __m128, __m256d, _CMP_EQ_OQ, _CMP_GE_OQ, _CMP_GT_OQ, _CMP_LE_OQ, _CMP_LT_OQ, _MM_FROUND_NO_EXC,
    _MM_FROUND_TO_ZERO, _mm_add_ps, _mm256_add_pd, _mm256_and_pd, _mm256_blend_pd,
    _mm256_blendv_pd, _mm256_cmp_pd, _mm256_cvtpd_ps, _mm256_max_pd, _mm256_min_pd, _mm256_mul_pd,
    _mm256_or_pd, _mm256_permute2f128_pd, _mm256_permute4x64_pd, _mm256_round_pd, _mm256_set_pd,
    _mm256_set1_pd, _mm256_setzero_pd, _mm256_sub_pd, _mm256_unpackhi_pd, _mm256_unpacklo_pd,
};

use volmorph_volume::Voxel;

use super::Lanes;
use super::lanes::{self, Boxes, Fit, Flat, Job};

/// Whether the CPU runs these kernels (AVX2).
pub(super) fn available() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// Both passes over `job`'s row (see [`lanes`]); requires [`available`].
pub(super) fn run<T: Voxel>(
    job: &Job<'_, '_, T>,
    boxes: &mut Boxes<'_>,
    buf: Lanes<'_>,
    outcome: &mut [u8],
) {
    // SAFETY: `both` is compiled with AVX2 enabled, and callers check `available()` first.
    // (It is otherwise safe: every memory access goes through slices.)
    #[allow(unsafe_code)]
    unsafe {
        both(job, boxes, buf, outcome);
    }
}

#[target_feature(enable = "avx2")]
fn both<T: Voxel>(job: &Job<'_, '_, T>, boxes: &mut Boxes<'_>, buf: Lanes<'_>, outcome: &mut [u8]) {
    fill(&job.flat, &job.fit, boxes);
    let Boxes { w01, share, .. } = boxes;
    match buf {
        Lanes::F32(b) => tally_f32(job, w01, share, b, outcome),
        Lanes::F64(b) => tally_f64(job, w01, share, b, outcome),
    }
}

/// Four coordinates from `s[i..]` (zeros past the end, which no caller reads).
#[inline]
#[target_feature(enable = "avx2")]
fn load(s: &[f64], i: usize) -> __m256d {
    match s.get(i..i + 4).and_then(|v| <[f64; 4]>::try_from(v).ok()) {
        Some(v) => bytemuck::cast(v),
        None => _mm256_setzero_pd(),
    }
}

/// Store four coordinates at `s[i..]` (nothing past the end).
#[inline]
#[target_feature(enable = "avx2")]
fn store(s: &mut [f64], i: usize, v: __m256d) {
    if let Some(d) = s.get_mut(i..i + 4) {
        d.copy_from_slice(&bytemuck::cast::<__m256d, [f64; 4]>(v));
    }
}

/// The boxes pass (see the [module docs](self)).
#[inline]
#[target_feature(enable = "avx2")]
fn fill(f: &Flat<'_>, fit: &Fit, out: &mut Boxes<'_>) {
    let n3 = out.lo.len();
    // Lane l of vector j of a step holds axis (4j + l) mod 3.
    let pattern = |v: [f64; 3], j: usize| {
        let a = |l: usize| v[(4 * j + l) % 3];
        _mm256_set_pd(a(3), a(2), a(1), a(0))
    };
    let r0 = [0, 1, 2].map(|j| pattern(fit.r0, j));
    let last = [0, 1, 2].map(|j| pattern(fit.last, j));
    let stride = [0, 1, 2].map(|j| pattern(fit.stride, j));
    let half = _mm256_set1_pd(0.5);
    let (zero, one, two) = (
        _mm256_setzero_pd(),
        _mm256_set1_pd(1.0),
        _mm256_set1_pd(2.0),
    );
    let limit = _mm256_set1_pd(1e15);
    let nan = _mm256_set1_pd(f64::NAN);
    let minus_inf = _mm256_set1_pd(f64::NEG_INFINITY);
    let end = [0, 1, 2].map(|j| _mm256_add_pd(last[j], one));
    let steps = n3 / 12;
    for step in 0..steps {
        for j in 0..3 {
            let m = 12 * step + 4 * j;
            let (cm, cp, p) = (load(f.c, m), load(f.c, m + 6), load(f.c, m + 3));
            let (ym, yp) = (load(f.ym, m), load(f.yp, m));
            let (zm, zp) = (load(f.zm, m), load(f.zp, m));
            let mn = _mm256_min_pd(
                _mm256_min_pd(_mm256_min_pd(cm, cp), _mm256_min_pd(ym, yp)),
                _mm256_min_pd(zm, zp),
            );
            let mx = _mm256_max_pd(
                _mm256_max_pd(_mm256_max_pd(cm, cp), _mm256_max_pd(ym, yp)),
                _mm256_max_pd(zm, zp),
            );
            let l = _mm256_mul_pd(half, _mm256_add_pd(p, mn));
            let h = _mm256_mul_pd(half, _mm256_add_pd(p, mx));
            let mut t = _mm256_add_pd(p, cm);
            for q in [cp, ym, yp, zm, zp] {
                t = _mm256_add_pd(t, q);
            }
            let s = _mm256_add_pd(l, half);
            let len = _mm256_sub_pd(h, l);
            let ok = _mm256_and_pd(
                _mm256_and_pd(
                    _mm256_cmp_pd::<_CMP_GE_OQ>(s, zero),
                    _mm256_cmp_pd::<_CMP_GT_OQ>(len, zero),
                ),
                _mm256_and_pd(
                    _mm256_cmp_pd::<_CMP_LE_OQ>(len, two),
                    _mm256_cmp_pd::<_CMP_LT_OQ>(s, limit),
                ),
            );
            let a = _mm256_round_pd::<{ _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC }>(s);
            let e = _mm256_add_pd(a, half);
            let e1 = _mm256_add_pd(e, one);
            let short = _mm256_cmp_pd::<_CMP_LE_OQ>(len, one);
            let v0 = _mm256_blendv_pd(
                _mm256_sub_pd(e, l),
                _mm256_sub_pd(_mm256_min_pd(h, e), l),
                short,
            );
            let v1 = _mm256_blendv_pd(
                _mm256_sub_pd(_mm256_min_pd(h, e1), e),
                _mm256_max_pd(_mm256_sub_pd(h, e), zero),
                short,
            );
            let two_cells = _mm256_or_pd(short, _mm256_cmp_pd::<_CMP_LE_OQ>(h, e1));
            let inside = _mm256_and_pd(
                _mm256_cmp_pd::<_CMP_GE_OQ>(a, r0[j]),
                _mm256_cmp_pd::<_CMP_LE_OQ>(a, last[j]),
            );
            // `t − t` is 0 for a finite `t`, NaN otherwise.
            let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(t, t), zero);
            let fits = _mm256_and_pd(_mm256_and_pd(ok, two_cells), _mm256_and_pd(inside, finite));
            // The box's last cell (`a + n − 1` of `short`) and whether it has no cell in
            // the region along this axis.
            let past_short = _mm256_and_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(h, e), one);
            let past_long =
                _mm256_add_pd(one, _mm256_and_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(h, e1), one));
            let last_cell = _mm256_add_pd(a, _mm256_blendv_pd(past_long, past_short, short));
            let outside = _mm256_and_pd(
                _mm256_and_pd(ok, finite),
                _mm256_or_pd(
                    _mm256_cmp_pd::<_CMP_LT_OQ>(last_cell, r0[j]),
                    _mm256_cmp_pd::<_CMP_GT_OQ>(a, end[j]),
                ),
            );
            let share = _mm256_blendv_pd(
                _mm256_blendv_pd(nan, minus_inf, outside),
                _mm256_mul_pd(_mm256_sub_pd(a, r0[j]), stride[j]),
                fits,
            );
            store(out.lo, m, l);
            store(out.share, m, share);
            // [v0₀ v1₀ v0₁ v1₁] and [v0₂ v1₂ v0₃ v1₃].
            let (lo2, hi2) = (_mm256_unpacklo_pd(v0, v1), _mm256_unpackhi_pd(v0, v1));
            store(out.w01, 2 * m, _mm256_permute2f128_pd::<0x20>(lo2, hi2));
            store(out.w01, 2 * m + 4, _mm256_permute2f128_pd::<0x31>(lo2, hi2));
        }
    }
    for m in 12 * steps..n3 {
        lanes::fill_one(f, fit, m, m % 3, out);
    }
}

/// The four rows `(z, y)` = (0, 0), (0, 1), (1, 0), (1, 1) of a two-cell voxel's cells,
/// each `[w₀·d, w₀, w₁·d, w₁]`, from its overlaps `w = [x₀, x₁, y₀, y₁, z₀, z₁]`.
#[inline]
#[target_feature(enable = "avx2")]
fn rows(w: &[f64], d: f64, sign: f64) -> [__m256d; 4] {
    let xy = load(w, 0);
    let (z0, z1) = (w.get(4).copied(), w.get(5).copied());
    let (z0, z1) = (z0.unwrap_or(0.0), z1.unwrap_or(0.0));
    let wz = _mm256_mul_pd(_mm256_set1_pd(sign), _mm256_set_pd(z1, z1, z0, z0));
    let wy = _mm256_permute2f128_pd::<0x11>(xy, xy);
    let wyz = _mm256_mul_pd(wz, wy);
    let wx = _mm256_permute4x64_pd::<0b01_01_00_00>(xy);
    let dv = _mm256_set1_pd(d);
    let row = |b: __m256d| {
        let w = _mm256_mul_pd(b, wx);
        _mm256_blend_pd::<0b0101>(w, _mm256_mul_pd(w, dv))
    };
    [
        row(_mm256_permute4x64_pd::<0x00>(wyz)),
        row(_mm256_permute4x64_pd::<0x55>(wyz)),
        row(_mm256_permute4x64_pd::<0xAA>(wyz)),
        row(_mm256_permute4x64_pd::<0xFF>(wyz)),
    ]
}

/// The tally pass for one cell type: `$add(buf, i, row)` adds a row of [`rows`] to cells
/// `i`, `i + 1`.
macro_rules! tally_cells {
    ($name:ident, $cell:ty, $add:ident) => {
        /// The tally pass (see the [module docs](self)) into cells of this type.
        #[inline]
        #[target_feature(enable = "avx2")]
        fn $name<T: Voxel>(
            job: &Job<'_, '_, T>,
            w01: &[f64],
            share: &[f64],
            buf: &mut [$cell],
            outcome: &mut [u8],
        ) {
            let t = &job.target;
            let sy = t.region.dims[0];
            let sz = sy * t.region.dims[1];
            lanes::each_voxel(
                job.row,
                share,
                t,
                buf,
                outcome,
                #[inline(always)]
                |buf, n, base, d| {
                    if let Some(w) = w01.get(6 * n..6 * n + 6) {
                        let [r00, r01, r10, r11] = rows(w, d, t.sign);
                        $add(buf, base, r00);
                        $add(buf, base + sy, r01);
                        $add(buf, base + sz, r10);
                        $add(buf, base + sz + sy, r11);
                    }
                },
            );
        }
    };
}

tally_cells!(tally_f32, [f32; 2], add_f32);
tally_cells!(tally_f64, [f64; 2], add_f64);

/// `[V, W]` of cells `i`, `i + 1` (`f32`) plus a row `[w₀·d, w₀, w₁·d, w₁]` rounded to `f32`.
#[inline]
#[target_feature(enable = "avx2")]
fn add_f32(buf: &mut [[f32; 2]], i: usize, r: __m256d) {
    if let Some(Ok(c)) = buf.get_mut(i..i + 2).map(<&mut [[f32; 2]; 2]>::try_from) {
        let c: &mut [f32; 4] = bytemuck::cast_mut(c);
        let sum = _mm_add_ps(bytemuck::cast::<[f32; 4], __m128>(*c), _mm256_cvtpd_ps(r));
        *c = bytemuck::cast(sum);
    }
}

/// `[V, W]` of cells `i`, `i + 1` (`f64`) plus a row `[w₀·d, w₀, w₁·d, w₁]`.
#[inline]
#[target_feature(enable = "avx2")]
fn add_f64(buf: &mut [[f64; 2]], i: usize, r: __m256d) {
    if let Some(Ok(c)) = buf.get_mut(i..i + 2).map(<&mut [[f64; 2]; 2]>::try_from) {
        let c: &mut [f64; 4] = bytemuck::cast_mut(c);
        *c = bytemuck::cast(_mm256_add_pd(bytemuck::cast::<[f64; 4], __m256d>(*c), r));
    }
}
