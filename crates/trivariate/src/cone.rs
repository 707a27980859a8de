//! Bounding cones of direction sets and their dot and cross products (Martin & Cohen §5.2,
//! after Sederberg & Meyers): the test that culls sub-volumes whose Jacobian determinant
//! cannot vanish.
//!
//! # Conventions
//!
//! * A [`Cone`] is a unit axis `Ĉ` and a spread (half-)angle `θ ∈ [0, π]`, radians. It bounds
//!   a vector `v ≠ 0` when the angle between `v` and `Ĉ` is at most `θ`. A spread of `π` is the
//!   whole space ([`Cone::full`]): it bounds every vector, including the zero vector.
//! * [`Cone::fit`] is the paper's incremental algorithm. Its intermediate vector is the generator
//!   of the current cone lying in the plane of `Ĉ_{i−1}` and `v̂_i`, on the far side from `v̂_i`:
//!   `v_t = cos θ_{i−1} Ĉ_{i−1} − sin θ_{i−1} ê`, `ê = (v̂_i − cos α Ĉ_{i−1})/sin α`
//!   (the paper prints `cot θ sin α Ĉ − v̂`, which drops the `cos α Ĉ` term of `v̂`; the
//!   form used here is the generator the construction needs). The new cone is the smallest
//!   cone containing `v_t` and `v̂_i`: `Ĉ_i = (v̂_i + v_t)/‖v̂_i + v_t‖`, `cos θ_i = Ĉ_i · v_t`.
//!   Zero or non-finite vectors, and sets needing a spread of `π/2` or more about the running
//!   axis by the time `α + θ ≥ π`, give the full cone (conservative).
//! * [`Cone::cross`] crosses the axes and takes the spread of the paper,
//!   `θ₃ = asin(√(sin²θ₁ + 2 sin θ₁ sin θ₂ cos β + sin²θ₂) / sin β)` with `β` the **smaller**
//!   angle between the axis lines (`β ≤ π/2`); when the cones may contain parallel or
//!   antiparallel vectors (`θ₁ + θ₂ ≥ β`), a spread reaches `π/2`, or the `asin` argument
//!   reaches 1, the result is the full cone. A property test checks that random crosses are
//!   bounded.
//! * [`Cone::dot`] is the range of `cos ∠(a, b)` over unit vectors `a`, `b` of the two cones:
//!   the sign of `a · b` for vectors of any positive length is fixed when this range excludes 0.

use std::f64::consts::{FRAC_PI_2, PI};

/// A cone of directions: unit `axis` and spread half-angle `spread ∈ [0, π]` in radians
/// (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cone {
    axis: [f64; 3],
    spread: f64,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// `a / |a|`, or `None` for zero or non-finite vectors.
fn unit(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = norm(a);
    (n > 0.0 && n.is_finite()).then(|| a.map(|x| x / n))
}

/// Angle between unit vectors, robust near 0 and π (atan2 of sine and cosine).
fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    norm(cross(a, b)).atan2(dot(a, b))
}

/// Rounding slack added to fitted spreads so that the fitted vectors stay inside despite
/// floating-point error in the normalisations (a few ulps of an angle of order 1).
const SPREAD_SLACK: f64 = 1e-12;

impl Cone {
    /// The cone bounding every direction (spread `π`), also the zero vector.
    #[must_use]
    pub fn full() -> Self {
        Self {
            axis: [0.0, 0.0, 1.0],
            spread: PI,
        }
    }

    /// A cone with the given axis (normalised here) and spread; `None` when the axis is zero
    /// or not finite or the spread is outside `[0, π]`.
    #[must_use]
    pub fn new(axis: [f64; 3], spread: f64) -> Option<Self> {
        let axis = unit(axis)?;
        (0.0..=PI)
            .contains(&spread)
            .then_some(Self { axis, spread })
    }

    /// The unit axis `Ĉ`.
    #[must_use]
    pub fn axis(&self) -> [f64; 3] {
        self.axis
    }

    /// The spread half-angle `θ`, radians.
    #[must_use]
    pub fn spread(&self) -> f64 {
        self.spread
    }

    /// `true` for the cone bounding everything.
    #[must_use]
    pub fn is_full(&self) -> bool {
        self.spread >= PI
    }

    /// `true` when `v` is bounded: the angle between `v` and the axis is at most the spread
    /// (plus `slack` radians). The zero vector is bounded only by the full cone.
    #[must_use]
    pub fn contains(&self, v: [f64; 3], slack: f64) -> bool {
        if self.is_full() {
            return true;
        }
        unit(v).is_some_and(|u| angle(u, self.axis) <= self.spread + slack)
    }

    /// The bounding cone of `vectors` by the incremental algorithm of the
    /// [module docs](self). An empty set gives the full cone (nothing is known).
    #[must_use]
    pub fn fit(vectors: impl IntoIterator<Item = [f64; 3]>) -> Self {
        let mut it = vectors.into_iter();
        let Some(first) = it.next().and_then(unit) else {
            return Self::full();
        };
        let mut c = first;
        let mut theta = 0.0_f64;
        for v in it {
            let Some(v) = unit(v) else {
                return Self::full();
            };
            let alpha = angle(v, c);
            if alpha <= theta {
                continue;
            }
            if alpha + theta >= PI - SPREAD_SLACK {
                return Self::full();
            }
            let vt = if theta == 0.0 {
                c
            } else {
                let ca = alpha.cos();
                let Some(e) = unit([v[0] - ca * c[0], v[1] - ca * c[1], v[2] - ca * c[2]]) else {
                    return Self::full();
                };
                let (st, ct) = theta.sin_cos();
                [
                    ct * c[0] - st * e[0],
                    ct * c[1] - st * e[1],
                    ct * c[2] - st * e[2],
                ]
            };
            let Some(nc) = unit([v[0] + vt[0], v[1] + vt[1], v[2] + vt[2]]) else {
                return Self::full();
            };
            c = nc;
            // θ_i from cos θ_i = Ĉ_i · v_t, computed as an angle for accuracy.
            theta = angle(c, vt).max(angle(c, v));
        }
        Self {
            axis: c,
            spread: (theta + SPREAD_SLACK).min(PI),
        }
    }

    /// The range `[lo, hi]` of `cos ∠(a, b)` for directions `a` in `self` and `b` in `other`
    /// (the paper's `C₁ · C₂` for unit vectors): with `β` the angle between the axes,
    /// the angles range over `[max(0, β − θ₁ − θ₂), min(π, β + θ₁ + θ₂)]`.
    #[must_use]
    pub fn dot(&self, other: &Cone) -> [f64; 2] {
        let beta = angle(self.axis, other.axis);
        let s = self.spread + other.spread;
        let lo_angle = (beta - s).max(0.0);
        let hi_angle = (beta + s).min(PI);
        [hi_angle.cos(), lo_angle.cos()]
    }

    /// `true` when every `a · b` with `a` in `self`, `b` in `other` (non-zero) has the same
    /// strict sign, i.e. `0 ∉ self · other`.
    #[must_use]
    pub fn dot_excludes_zero(&self, other: &Cone) -> bool {
        if self.is_full() || other.is_full() {
            return false;
        }
        let beta = angle(self.axis, other.axis);
        let s = self.spread + other.spread;
        beta + s < FRAC_PI_2 || beta - s > FRAC_PI_2
    }

    /// A cone bounding `a × b` for every `a` in `self` and `b` in `other` (the paper's
    /// `C₁ × C₂`, see the [module docs](self) for the spread and when it is full).
    #[must_use]
    pub fn cross(&self, other: &Cone) -> Cone {
        let (t1, t2) = (self.spread, other.spread);
        if t1 >= FRAC_PI_2 || t2 >= FRAC_PI_2 {
            return Self::full();
        }
        let Some(axis) = unit(cross(self.axis, other.axis)) else {
            return Self::full();
        };
        let b = angle(self.axis, other.axis);
        let beta = b.min(PI - b);
        if t1 + t2 >= beta {
            return Self::full();
        }
        let (s1, s2) = (t1.sin(), t2.sin());
        let num = (s1 * s1 + 2.0 * s1 * s2 * beta.cos() + s2 * s2)
            .max(0.0)
            .sqrt();
        let arg = num / beta.sin();
        if arg.is_nan() || arg >= 1.0 {
            return Self::full();
        }
        Self {
            axis,
            spread: (arg.asin() + SPREAD_SLACK).min(PI),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn rot(v: [f64; 3], axis: [f64; 3], ang: f64) -> [f64; 3] {
        // Rodrigues rotation about a unit axis.
        let (s, c) = ang.sin_cos();
        let k = axis;
        let kxv = cross(k, v);
        let kv = dot(k, v);
        std::array::from_fn(|i| v[i] * c + kxv[i] * s + k[i] * kv * (1.0 - c))
    }

    /// A unit vector at angle `off` from `axis`, at azimuth `phi` around it.
    fn in_cone(axis: [f64; 3], off: f64, phi: f64) -> [f64; 3] {
        let a = unit(axis).unwrap();
        let helper = if a[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let t = unit(cross(a, helper)).unwrap();
        let tilted = rot(a, t, off);
        rot(tilted, a, phi)
    }

    #[test]
    fn fit_of_one_vector_is_that_direction() {
        let c = Cone::fit([[0.0, 3.0, 0.0]]);
        assert!((c.axis()[1] - 1.0).abs() < 1e-15);
        assert!(c.spread() < 1e-9);
        assert!(Cone::fit([[0.0; 3]]).is_full());
        assert!(Cone::fit(std::iter::empty()).is_full());
        assert!(Cone::fit([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]).is_full());
        assert!(Cone::fit([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]).is_full());
    }

    #[test]
    fn fit_of_two_vectors_is_their_bisector() {
        let c = Cone::fit([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((c.axis()[0] - h).abs() < 1e-12 && (c.axis()[1] - h).abs() < 1e-12);
        assert!((c.spread() - std::f64::consts::FRAC_PI_4).abs() < 1e-9);
    }

    #[test]
    fn dot_range_matches_axes() {
        let a = Cone::new([1.0, 0.0, 0.0], 0.1).unwrap();
        let b = Cone::new([0.0, 1.0, 0.0], 0.2).unwrap();
        let [lo, hi] = a.dot(&b);
        assert!((lo - (FRAC_PI_2 + 0.3).cos()).abs() < 1e-12);
        assert!((hi - (FRAC_PI_2 - 0.3).cos()).abs() < 1e-12);
        assert!(!a.dot_excludes_zero(&b));
        let c = Cone::new([1.0, 0.2, 0.0], 0.1).unwrap();
        assert!(a.dot_excludes_zero(&c));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn fit_bounds_all_its_vectors(
            vs in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, 0.05f64..1.0), 1..40),
            scale in 0.1f64..10.0,
        ) {
            let vs: Vec<[f64; 3]> = vs.iter().map(|&(x, y, z)| [x * scale, y * scale, z * scale]).collect();
            let c = Cone::fit(vs.iter().copied());
            for v in &vs {
                prop_assert!(c.contains(*v, 1e-9), "{v:?} not in {c:?}");
            }
        }

        #[test]
        fn cross_bounds_random_crosses(
            a in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            b in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            t1 in 0.0f64..0.6, t2 in 0.0f64..0.6,
            samples in proptest::collection::vec((0.0f64..1.0, 0.0f64..6.3, 0.0f64..1.0, 0.0f64..6.3), 16),
        ) {
            let (a, b) = ([a.0, a.1, a.2], [b.0, b.1, b.2]);
            prop_assume!(norm(a) > 0.1 && norm(b) > 0.1);
            let c1 = Cone::new(a, t1).unwrap();
            let c2 = Cone::new(b, t2).unwrap();
            let c3 = c1.cross(&c2);
            for &(f1, p1, f2, p2) in &samples {
                // Boundary vectors are the extreme cases; mix boundary and interior.
                let x = in_cone(a, t1 * f1.sqrt().max(f64::from(u8::from(f1 > 0.5))), p1);
                let y = in_cone(b, t2 * f2.sqrt().max(f64::from(u8::from(f2 > 0.5))), p2);
                prop_assert!(c1.contains(x, 1e-9) && c2.contains(y, 1e-9));
                let z = cross(x, y);
                prop_assert!(c3.contains(z, 1e-9), "{z:?} not in {c3:?}");
            }
        }
    }
}
