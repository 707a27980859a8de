//! The trilinear interior kernel four points at a time (x86-64 AVX2, `f64×4`).
//!
//! For each group of four continuous indices the interior test, the floor and fraction, the
//! voxel offset (32-bit integer lanes), the eight corner loads and the seven lerps run in
//! vector registers; each lane performs exactly the IEEE operations of
//! [`LinearKernel::eval`](super::LinearKernel) in the same order (no fused multiply-add:
//! Rust never contracts a multiply and an add, and the kernel uses neither `mul_add` nor an
//! FMA intrinsic), so every lane's value has the bits of the scalar kernel. A group with a
//! lane outside the interior box (border, outside, NaN) is sampled lane by lane through
//! [`Sampler::point`], as is the tail of fewer than four points.
//!
//! The kernel is compiled with AVX2 enabled and chosen at run time
//! (`is_x86_feature_detected!`); where the CPU lacks AVX2 [`run`] declines and the caller
//! runs the portable loop. Calling a function compiled for a target feature is the one
//! `unsafe` operation here (the intrinsics it uses are safe inside it, and every memory
//! access goes through bounds-checked slices).

use std::arch::x86_64::{
    __m128i, __m256d, _CMP_GE_OQ, _CMP_LT_OQ, _mm_add_epi32, _mm_mullo_epi32, _mm_set1_epi32,
    _mm256_add_pd, _mm256_and_pd, _mm256_cmp_pd, _mm256_cvtepi32_pd, _mm256_cvttpd_epi32,
    _mm256_movemask_pd, _mm256_mul_pd, _mm256_set_pd, _mm256_set1_pd, _mm256_sub_pd,
};

use glam::DVec3;

use super::{InteriorKernel, LinearKernel, Sampler};
use crate::Voxel;

/// Sample the continuous indices `indices` into `out` (values through [`Voxel::from_f64`])
/// with the trilinear kernel, four points at a time. Returns `false`, touching nothing,
/// when the vector kernel does not apply: the CPU lacks AVX2, or the volume has `2³¹` voxels
/// or more (offsets are computed in 32-bit lanes), or `d` is not one value per voxel.
pub(super) fn run<V: Voxel, O: Voxel>(
    s: &Sampler<'_>,
    d: &[V],
    indices: &[DVec3],
    out: &mut [O],
) -> bool {
    let [nx, ny, nz] = s.geometry.dims;
    let fits = nx
        .checked_mul(ny)
        .and_then(|p| p.checked_mul(nz))
        .is_some_and(|len| len == d.len() && len <= i32::MAX as usize);
    if !fits || indices.len() != out.len() || !std::arch::is_x86_feature_detected!("avx2") {
        return false;
    }
    // SAFETY: `groups` is compiled with AVX2 enabled, and the CPU has just been found to
    // support AVX2. (It is otherwise safe: every memory access is bounds-checked.)
    #[allow(unsafe_code)]
    unsafe {
        groups(s, d, indices, out);
    }
    true
}

/// The loop over groups of four points (see the [module docs](self)). Requires `d` to hold
/// one value per voxel and fewer than `2³¹` voxels (checked by [`run`]).
#[target_feature(enable = "avx2")]
fn groups<V: Voxel, O: Voxel>(s: &Sampler<'_>, d: &[V], indices: &[DVec3], out: &mut [O]) {
    let dims = s.geometry.dims;
    let (lo, hi) = LinearKernel::interior(dims);
    let (sy, sz) = (dims[0], dims[0] * dims[1]);
    // The cell of corner offset `o` is `d[o .. o + span]` (as in the scalar kernel).
    let span = sz + sy + 2;
    let lo4 = _mm256_set1_pd(lo);
    let hi4 = hi.map(|h| _mm256_set1_pd(h));
    let (sy4, sz4) = (_mm_set1_epi32(sy as i32), _mm_set1_epi32(sz as i32));
    let flat: &[f64] = bytemuck::cast_slice(indices);
    let mut pairs = flat.chunks_exact(12).zip(out.chunks_exact_mut(4));
    for (p, o) in &mut pairs {
        let x = _mm256_set_pd(p[9], p[6], p[3], p[0]);
        let y = _mm256_set_pd(p[10], p[7], p[4], p[1]);
        let z = _mm256_set_pd(p[11], p[8], p[5], p[2]);
        let inside = _mm256_and_pd(
            _mm256_and_pd(within(x, lo4, hi4[0]), within(y, lo4, hi4[1])),
            within(z, lo4, hi4[2]),
        );
        if _mm256_movemask_pd(inside) != 0b1111 {
            for (l, v) in o.iter_mut().enumerate() {
                let q = DVec3::new(p[3 * l], p[3 * l + 1], p[3 * l + 2]);
                *v = O::from_f64(s.point::<LinearKernel, V>(d, lo, hi, q));
            }
            continue;
        }
        // Inside the interior box 0 ≤ q < n − 1 < 2³¹: truncation is floor, as the scalar
        // kernel's `as i64`, and the integer converts back exactly.
        let (xi, yi, zi) = (
            _mm256_cvttpd_epi32(x),
            _mm256_cvttpd_epi32(y),
            _mm256_cvttpd_epi32(z),
        );
        let tx = _mm256_sub_pd(x, _mm256_cvtepi32_pd(xi));
        let ty = _mm256_sub_pd(y, _mm256_cvtepi32_pd(yi));
        let tz = _mm256_sub_pd(z, _mm256_cvtepi32_pd(zi));
        // x0 + sy·y0 + sz·z0 < nx·ny·nz < 2³¹: no lane overflows.
        let offsets: [i32; 4] = bytemuck::cast::<__m128i, _>(_mm_add_epi32(
            _mm_add_epi32(xi, _mm_mullo_epi32(yi, sy4)),
            _mm_mullo_epi32(zi, sz4),
        ));
        // One range check per lane for its whole cell, as in the scalar kernel.
        let cell = |n: usize| -> std::ops::Range<usize> {
            let c = offsets[n] as usize;
            c..c + span
        };
        let cells = [&d[cell(0)], &d[cell(1)], &d[cell(2)], &d[cell(3)]];
        let c0 = lerp(row(&cells, 0, tx), row(&cells, sy, tx), ty);
        let c1 = lerp(row(&cells, sz, tx), row(&cells, sz + sy, tx), ty);
        let values: [f64; 4] = bytemuck::cast(lerp(c0, c1, tz));
        for (v, value) in o.iter_mut().zip(values) {
            *v = O::from_f64(value);
        }
    }
    let done = indices.len() - indices.len() % 4;
    for (v, &q) in out[done..].iter_mut().zip(&indices[done..]) {
        *v = O::from_f64(s.point::<LinearKernel, V>(d, lo, hi, q));
    }
}

/// Lanes with `lo ≤ x < hi` (all bits set), ordered comparisons: NaN lanes are clear.
#[inline]
#[target_feature(enable = "avx2")]
fn within(x: __m256d, lo: __m256d, hi: __m256d) -> __m256d {
    _mm256_and_pd(
        _mm256_cmp_pd::<_CMP_GE_OQ>(x, lo),
        _mm256_cmp_pd::<_CMP_LT_OQ>(x, hi),
    )
}

/// Value `r` of each lane's cell, exactly converted to `f64`.
#[inline]
#[target_feature(enable = "avx2")]
fn corner<V: Voxel>(cells: &[&[V]; 4], r: usize) -> __m256d {
    _mm256_set_pd(
        cells[3][r].to_f64(),
        cells[2][r].to_f64(),
        cells[1][r].to_f64(),
        cells[0][r].to_f64(),
    )
}

/// Row `r` of each lane's cell interpolated along x: `lerp(cell[r], cell[r + 1], t)`. A
/// function rather than a closure: the compiler kept a closure doing this out of line
/// (callgrind), a call per row.
#[inline]
#[target_feature(enable = "avx2")]
fn row<V: Voxel>(cells: &[&[V]; 4], r: usize, t: __m256d) -> __m256d {
    lerp(corner(cells, r), corner(cells, r + 1), t)
}

/// `(1 − t)·a + t·b` lane by lane, the scalar `lerp`'s operations in its order.
#[inline]
#[target_feature(enable = "avx2")]
fn lerp(a: __m256d, b: __m256d, t: __m256d) -> __m256d {
    _mm256_add_pd(
        _mm256_mul_pd(_mm256_sub_pd(_mm256_set1_pd(1.0), t), a),
        _mm256_mul_pd(t, b),
    )
}

#[cfg(test)]
mod tests {
    use volmorph_testkit::Rng;

    use super::*;
    use crate::sample::{Boundary, Interpolation, KernelPath};
    use crate::{Geometry, Volume};

    const DIMS: [usize; 3] = [13, 9, 7];

    /// A volume of `T` whose values cover the type's range (both extremes included).
    fn volume<T: Voxel>(values: &[f64], seed: u64) -> Volume<T> {
        let mut rng = Rng::new(seed);
        let len = DIMS[0] * DIMS[1] * DIMS[2];
        let data = (0..len)
            .map(|n| T::from_f64(values[(n + rng.index(values.len())) % values.len()]))
            .collect();
        Volume::new(Geometry::new(DIMS), data).unwrap()
    }

    /// Continuous indices in groups of four: many groups wholly inside the interior box (the
    /// vector kernel), others with one lane on the border, outside, NaN, infinite, huge or
    /// exactly on a voxel plane, and a tail of three.
    fn indices(seed: u64) -> Vec<DVec3> {
        let mut rng = Rng::new(seed);
        let last = DIMS.map(|n| (n - 1) as f64);
        let inside = |rng: &mut Rng| {
            DVec3::new(
                rng.unit() * last[0],
                rng.unit() * last[1],
                rng.unit() * last[2],
            )
        };
        let odd = [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e300,
            -1e300,
            2_147_483_648.0,
            -0.0,
            -0.5,
            -0.25,
            -1e-300,
            12.0,
            12.5,
            8.0 - 1e-15,
            6.0,
            3.0,
        ];
        let mut out = Vec::new();
        for g in 0..600 {
            let mut group = [0; 4].map(|_| inside(&mut rng));
            if g % 3 == 1 {
                let (lane, axis) = (rng.index(4), rng.index(3));
                group[lane][axis] = odd[rng.index(odd.len())];
            }
            if g % 7 == 2 {
                // Exactly on a voxel plane: t = 0 along one axis.
                let axis = rng.index(3);
                group[rng.index(4)][axis] = rng.index(DIMS[axis] - 1) as f64;
            }
            out.extend(group);
        }
        out.extend([0; 3].map(|_| inside(&mut rng)));
        out
    }

    /// The same bits, or both NaN: Rust leaves the payload and sign of a NaN produced from
    /// NaN operands unspecified (which operand's payload survives depends on the operand
    /// order the compiler picks), so NaN results are deterministic only as NaN.
    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// Vector and portable loops against the single queries, bit for bit, for one voxel type
    /// and several output types.
    fn check<T: Voxel>(values: &[f64]) {
        let points = indices(7);
        for boundary in [Boundary::Constant(-7.0), Boundary::Clamp, Boundary::Mirror] {
            let v = volume::<T>(values, 3);
            let s = Sampler::new(&v, Interpolation::Linear, boundary).unwrap();
            let what = format!("{:?} {boundary:?}", T::TYPE);
            let want: Vec<f64> = points.iter().map(|&q| s.sample_index(q)).collect();
            for path in [KernelPath::Vector, KernelPath::Portable] {
                let mut got = vec![0f64; points.len()];
                s.sample_index_serial_by(&points, &mut got, path).unwrap();
                for (n, (g, w)) in got.iter().zip(&want).enumerate() {
                    assert!(same(*g, *w), "{what} {path:?} at {:?}: {g} {w}", points[n]);
                }
                let mut got32 = vec![0f32; points.len()];
                s.sample_index_serial_by(&points, &mut got32, path).unwrap();
                let mut got16 = vec![0i16; points.len()];
                s.sample_index_serial_by(&points, &mut got16, path).unwrap();
                for (n, w) in want.iter().enumerate() {
                    let q = points[n];
                    assert!(
                        same(got32[n].into(), f64::from(*w as f32)),
                        "{what} at {q:?}"
                    );
                    assert_eq!(got16[n], i16::from_f64(*w), "{what} at {q:?}");
                }
            }
        }
    }

    #[test]
    fn vector_kernel_matches_scalar_bits_for_every_voxel_type() {
        let ints = |lo: f64, hi: f64| [lo, hi, 0.0, 1.0, (lo + hi) / 2.0, hi - 1.0, lo + 3.0];
        check::<u8>(&ints(0.0, 255.0));
        check::<i8>(&ints(-128.0, 127.0));
        check::<u16>(&ints(0.0, 65_535.0));
        check::<i16>(&ints(-32_768.0, 32_767.0));
        check::<u32>(&ints(0.0, 4_294_967_295.0));
        check::<i32>(&ints(-2_147_483_648.0, 2_147_483_647.0));
        let floats = [
            0.0,
            -0.0,
            1.5,
            -3.25e7,
            f64::from(f32::MAX),
            f64::from(f32::MIN_POSITIVE) / 4.0,
            f64::NAN,
            f64::INFINITY,
            0.1,
        ];
        check::<f32>(&floats);
        check::<f64>(&[
            0.0,
            -0.0,
            1e300,
            -1e-310,
            f64::NAN,
            f64::NEG_INFINITY,
            0.1,
            7.0,
        ]);
    }

    /// Where the CPU has AVX2 the vector kernel really runs (and declines otherwise).
    #[test]
    fn vector_kernel_runs_where_avx2_is_present() {
        let v = volume::<f32>(&[1.0, 2.0, 3.0], 1);
        let s = Sampler::new(&v, Interpolation::Linear, Boundary::Clamp).unwrap();
        let points = vec![DVec3::new(1.5, 2.25, 3.75); 8];
        let mut out = vec![0f32; 8];
        let ran = run(&s, v.data(), &points, &mut out);
        assert_eq!(ran, std::arch::is_x86_feature_detected!("avx2"));
        if ran {
            let want = s.sample_index(points[0]) as f32;
            assert!(out.iter().all(|&o| o.to_bits() == want.to_bits()));
        }
        // A data slice that is not one value per voxel is declined, never read.
        assert!(!run(&s, &v.data()[1..], &points, &mut out));
    }
}
