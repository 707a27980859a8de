//! [`IndexMap::apply`] four points at a time (x86-64 AVX2, `f64×4`).
//!
//! Each lane performs exactly the scalar operations in their order: the difference to the
//! origin, the matrix product as glam computes it (`x_axis·v.x + y_axis·v.y`, then
//! `+ z_axis·v.z`, no fused multiply-add), and [`snap`](super::snap) as a select: the
//! rounded value where `|x| < 2⁵¹` and `|x − r| ≤ INDEX_SNAP_TOL` (ordered comparisons, so
//! NaN keeps `x`), `x` elsewhere. The tail of fewer than four points runs the scalar map.
//!
//! The kernel is compiled with AVX2 enabled and chosen at run time
//! (`is_x86_feature_detected!`); calling it is the one `unsafe` operation here (the
//! intrinsics are safe inside it and every memory access goes through slices).

use std::arch::x86_64::{
    __m256d, _CMP_LE_OQ, _CMP_LT_OQ, _mm256_add_pd, _mm256_and_pd, _mm256_andnot_pd,
    _mm256_blendv_pd, _mm256_cmp_pd, _mm256_mul_pd, _mm256_set_pd, _mm256_set1_pd, _mm256_sub_pd,
};

use glam::DVec3;

use super::{INDEX_SNAP_TOL, IndexMap, ROUND_MAGIC, ROUND_MAGIC_LIMIT};

/// Map every point of `points` in place with `map`; `false`, touching nothing, where the CPU
/// lacks AVX2.
pub(super) fn apply_all(map: &IndexMap, points: &mut [DVec3]) -> bool {
    if !std::arch::is_x86_feature_detected!("avx2") {
        return false;
    }
    // SAFETY: `groups` is compiled with AVX2 enabled, and the CPU has just been found to
    // support AVX2. (It is otherwise safe: every memory access goes through slices.)
    #[allow(unsafe_code)]
    unsafe {
        groups(map, points);
    }
    true
}

/// The loop over groups of four points (see the [module docs](self)).
#[target_feature(enable = "avx2")]
fn groups(map: &IndexMap, points: &mut [DVec3]) {
    let m = map.matrix.to_cols_array().map(|v| _mm256_set1_pd(v));
    let o = map.origin.to_array().map(|v| _mm256_set1_pd(v));
    let mut quads = points.chunks_exact_mut(4);
    for q in &mut quads {
        let vx = _mm256_sub_pd(_mm256_set_pd(q[3].x, q[2].x, q[1].x, q[0].x), o[0]);
        let vy = _mm256_sub_pd(_mm256_set_pd(q[3].y, q[2].y, q[1].y, q[0].y), o[1]);
        let vz = _mm256_sub_pd(_mm256_set_pd(q[3].z, q[2].z, q[1].z, q[0].z), o[2]);
        // Row a of the product: column b's entry a is m[3·b + a].
        let row = |a: usize| {
            let c = _mm256_add_pd(_mm256_mul_pd(m[a], vx), _mm256_mul_pd(m[3 + a], vy));
            snap(_mm256_add_pd(c, _mm256_mul_pd(m[6 + a], vz)))
        };
        let [x, y, z]: [[f64; 4]; 3] = [row(0), row(1), row(2)].map(bytemuck::cast);
        for (l, p) in q.iter_mut().enumerate() {
            *p = DVec3::new(x[l], y[l], z[l]);
        }
    }
    for p in quads.into_remainder() {
        *p = map.apply(*p);
    }
}

/// [`snap`](super::snap) of each lane.
#[inline]
#[target_feature(enable = "avx2")]
fn snap(x: __m256d) -> __m256d {
    let abs = |v: __m256d| _mm256_andnot_pd(_mm256_set1_pd(-0.0), v);
    let magic = _mm256_set1_pd(ROUND_MAGIC);
    let r = _mm256_sub_pd(_mm256_add_pd(x, magic), magic);
    let small = _mm256_cmp_pd::<_CMP_LT_OQ>(abs(x), _mm256_set1_pd(ROUND_MAGIC_LIMIT));
    let near =
        _mm256_cmp_pd::<_CMP_LE_OQ>(abs(_mm256_sub_pd(x, r)), _mm256_set1_pd(INDEX_SNAP_TOL));
    _mm256_blendv_pd(x, r, _mm256_and_pd(small, near))
}

#[cfg(test)]
mod tests {
    use glam::DMat3;
    use volmorph_testkit::Rng;
    use volmorph_volume::Geometry;

    use super::*;

    /// Same bits, or both NaN (Rust leaves the payload of a NaN from NaN operands unspecified).
    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    #[test]
    fn vector_index_map_matches_the_scalar_map() {
        let g = Geometry::new([50, 60, 70])
            .with_spacing(DVec3::new(0.7, 1.3, 2.1))
            .with_origin(DVec3::new(-4.0, 2.5, 10.0))
            .with_direction(DMat3::from_rotation_y(0.4) * DMat3::from_rotation_z(-1.1));
        let axis = Geometry::new([50, 60, 70]).with_spacing(DVec3::new(0.5, 0.25, 3.0));
        let mut rng = Rng::new(5);
        for geometry in [g, axis] {
            let map = IndexMap::new(&geometry);
            let mut points = Vec::new();
            for n in 0..4003 {
                let idx = match n % 5 {
                    // Voxel centres (snapped exactly) and points a hair off them.
                    0 => DVec3::new(
                        rng.index(50) as f64,
                        rng.index(60) as f64,
                        rng.index(70) as f64,
                    ),
                    1 => DVec3::new(rng.index(50) as f64 + 3e-10, 7.0 - 2e-9, -1.0 + 1e-12),
                    2 => rng.point_in(DVec3::splat(-3.0), DVec3::new(53.0, 63.0, 73.0)),
                    3 => rng.point(1e6),
                    _ => DVec3::new(2.0 + rng.unit() * 1e-9, rng.range(-0.5, 0.5), 0.5),
                };
                points.push(geometry.index_to_physical(idx));
            }
            // Coordinates snap must pass through: NaN, infinities, magnitudes of 2⁵¹ and more.
            points.extend([
                DVec3::new(f64::NAN, 1.0, 2.0),
                DVec3::new(f64::INFINITY, f64::NEG_INFINITY, 0.0),
                DVec3::new(1e300, -1e300, 2_251_799_813_685_248.0),
                DVec3::new(-0.0, 4_503_599_627_370_497.0, 1e-300),
            ]);
            let want: Vec<DVec3> = points.iter().map(|&p| map.apply(p)).collect();
            let mut got = points.clone();
            let ran = apply_all(&map, &mut got);
            assert_eq!(ran, std::arch::is_x86_feature_detected!("avx2"));
            if !ran {
                continue;
            }
            for ((g, w), p) in got.iter().zip(&want).zip(&points) {
                for a in 0..3 {
                    assert!(same(g[a], w[a]), "{p:?}: {g:?} vs {w:?}");
                }
            }
        }
    }
}
