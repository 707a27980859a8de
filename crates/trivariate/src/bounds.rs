//! Axis-aligned boxes of control nets (the convex-hull bounds every culling test here uses).

/// The smallest box `(lo, hi)` holding the Cartesian points `x y z x y z …` (`lo = +∞`,
/// `hi = −∞` componentwise when there are none).
pub(crate) fn point_box(points: &[f64]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for c in points.chunks_exact(3) {
        for k in 0..3 {
            lo[k] = lo[k].min(c[k]);
            hi[k] = hi[k].max(c[k]);
        }
    }
    (lo, hi)
}
