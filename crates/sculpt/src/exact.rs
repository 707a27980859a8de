//! Exact, watertight ray coverage of projected triangles.
//!
//! A depth peel must find, along every ray, each crossing of a closed mesh exactly once:
//! a ray through a shared edge or vertex must be counted by exactly one of the triangles
//! there, or the inside/outside parity of the whole ray flips. Floating-point edge functions
//! cannot promise that, so projected vertex coordinates are **quantised** to
//! 2^−[`FRACTION_BITS`] of a ray spacing (a displacement far below any tolerance of the
//! method) and the edge functions are evaluated exactly in 128-bit integers. Rays passing
//! exactly through an edge or a vertex are resolved by **simulation of simplicity**: the ray
//! point is taken as `p + (ε, ε²)` for an infinitesimal ε, so it never lies on an edge, and
//! the two triangles sharing an edge always disagree about it. With these two rules every
//! ray meets a closed mesh an even number of times, alternately entering and leaving once the
//! crossings are sorted, however the mesh is aligned with the rays.

/// Fraction bits of the quantised ray-plane coordinates: positions move by at most 2^−25 of a
/// ray spacing.
pub const FRACTION_BITS: u32 = 24;

/// Largest magnitude, in ray spacings, of a projected coordinate accepted for quantisation
/// (2^38, so quantised values stay below 2^62 and products of differences fit in 128 bits).
pub(crate) const MAX_RAY_COORD: f64 = (1u64 << 38) as f64;

const SCALE: f64 = (1u64 << FRACTION_BITS) as f64;

/// `x` (in ray spacings) in fixed point, or `None` if not finite or beyond
/// [`MAX_RAY_COORD`].
#[inline]
pub(crate) fn quantize(x: f64) -> Option<i64> {
    if x.is_finite() && x.abs() < MAX_RAY_COORD {
        Some((x * SCALE).round() as i64)
    } else {
        None
    }
}

/// The fixed-point coordinate of the ray with integer index `i`.
#[inline]
pub(crate) fn ray_fixed(i: i64) -> i64 {
    i << FRACTION_BITS
}

/// A triangle projected onto a ray plane, with its edges' exact coefficients.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Projected {
    v: [[i64; 2]; 3],
    /// Twice the signed area in fixed-point units squared (never zero).
    area2: i128,
}

impl Projected {
    /// The triangle `(a, b, c)` with quantised coordinates, or `None` when its projection has
    /// zero area (it covers no ray under simulation of simplicity).
    pub(crate) fn new(a: [i64; 2], b: [i64; 2], c: [i64; 2]) -> Option<Self> {
        let area2 = cross(a, b, c);
        (area2 != 0).then_some(Self {
            v: [a, b, c],
            area2,
        })
    }

    /// `true` when the projection is counter-clockwise (positive area) in the `(u, v)` ray
    /// plane: the triangle's right-hand normal points along `+u × v`, the ray direction.
    #[inline]
    pub(crate) fn counter_clockwise(&self) -> bool {
        self.area2 > 0
    }

    /// Range of integer ray indices `(u0..=u1, v0..=v1)` that may be covered (possibly empty:
    /// `u0 > u1`).
    pub(crate) fn ray_range(&self) -> ([i64; 2], [i64; 2]) {
        let mut lo = [i64::MAX; 2];
        let mut hi = [i64::MIN; 2];
        for p in &self.v {
            for d in 0..2 {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
        // Ceiling of lo / 2^F and floor of hi / 2^F (arithmetic shifts floor).
        let start = |x: i64| -((-x) >> FRACTION_BITS);
        (
            [start(lo[0]), hi[0] >> FRACTION_BITS],
            [start(lo[1]), hi[1] >> FRACTION_BITS],
        )
    }

    /// Barycentric weights of the triangle's vertices at the fixed-point ray point `p`, when
    /// the ray (perturbed by simulation of simplicity) passes through the triangle's interior.
    #[inline]
    pub(crate) fn cover(&self, p: [i64; 2]) -> Option<[f64; 3]> {
        let [a, b, c] = self.v;
        let wa = edge(b, c, p);
        let wb = edge(c, a, p);
        let wc = edge(a, b, p);
        let positive = self.area2 > 0;
        let side = |w: i128, from: [i64; 2], to: [i64; 2]| {
            if w != 0 {
                (w > 0) == positive
            } else {
                sos_positive(from, to) == positive
            }
        };
        if side(wa, b, c) && side(wb, c, a) && side(wc, a, b) {
            let s = self.area2 as f64;
            Some([wa as f64 / s, wb as f64 / s, wc as f64 / s])
        } else {
            None
        }
    }
}

/// `(b − a) × (c − a)`, exactly.
#[inline]
fn cross(a: [i64; 2], b: [i64; 2], c: [i64; 2]) -> i128 {
    let (bu, bv) = (
        i128::from(b[0]) - i128::from(a[0]),
        i128::from(b[1]) - i128::from(a[1]),
    );
    let (cu, cv) = (
        i128::from(c[0]) - i128::from(a[0]),
        i128::from(c[1]) - i128::from(a[1]),
    );
    bu * cv - bv * cu
}

/// Edge function of the directed edge `from → to` at `p`: positive when `p` is on its left.
#[inline]
fn edge(from: [i64; 2], to: [i64; 2], p: [i64; 2]) -> i128 {
    cross(from, to, p)
}

/// Sign of the edge function of `from → to` at `p + (ε, ε²)` when it is exactly zero at `p`:
/// its expansion is `(to.u − from.u) ε² − (to.v − from.v) ε`.
#[inline]
fn sos_positive(from: [i64; 2], to: [i64; 2]) -> bool {
    let dv = to[1] - from[1];
    if dv != 0 { dv < 0 } else { to[0] > from[0] }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(x: f64, y: f64) -> [i64; 2] {
        [quantize(x).unwrap(), quantize(y).unwrap()]
    }

    /// A fan of triangles around a vertex sitting exactly on a ray: the ray is covered by
    /// exactly one triangle of the fan, whatever the fan's shape.
    #[test]
    fn a_ray_through_a_shared_vertex_is_covered_once() {
        let centre = q(2.0, 3.0);
        let ring = [
            q(4.0, 3.0),
            q(3.0, 5.0),
            q(2.0, 4.5),
            q(0.5, 3.0),
            q(1.0, 1.0),
            q(2.0, 1.0),
            q(3.5, 2.0),
        ];
        let p = [ray_fixed(2), ray_fixed(3)];
        let mut hits = 0;
        for i in 0..ring.len() {
            let t = Projected::new(centre, ring[i], ring[(i + 1) % ring.len()]).unwrap();
            if t.cover(p).is_some() {
                hits += 1;
            }
        }
        assert_eq!(hits, 1);
    }

    /// Two triangles sharing an edge through ray points: each point on the edge belongs to
    /// exactly one of them, with either orientation of the pair.
    #[test]
    fn a_ray_on_a_shared_edge_is_covered_once() {
        let (a, b) = (q(0.0, 0.0), q(4.0, 4.0));
        for (l, r) in [(q(0.0, 4.0), q(4.0, 0.0)), (q(4.0, 0.0), q(0.0, 4.0))] {
            let t1 = Projected::new(a, b, l).unwrap();
            let t2 = Projected::new(b, a, r).unwrap();
            for i in 1..4 {
                let p = [ray_fixed(i), ray_fixed(i)];
                let n = usize::from(t1.cover(p).is_some()) + usize::from(t2.cover(p).is_some());
                assert_eq!(n, 1, "interior point {i} of the shared edge");
            }
        }
    }

    #[test]
    fn weights_interpolate_the_vertices() {
        let t = Projected::new(q(0.0, 0.0), q(4.0, 0.0), q(0.0, 4.0)).unwrap();
        let w = t.cover([ray_fixed(1), ray_fixed(1)]).unwrap();
        assert!((w[0] - 0.5).abs() < 1e-12 && (w[1] - 0.25).abs() < 1e-12);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let (u, v) = t.ray_range();
        assert_eq!((u, v), ([0, 4], [0, 4]));
        assert!(Projected::new(q(0.0, 0.0), q(1.0, 1.0), q(2.0, 2.0)).is_none());
    }
}
