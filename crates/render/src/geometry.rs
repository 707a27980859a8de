//! Rays and axis-aligned boxes: the two primitives every ray caster starts from.

use glam::DVec3;

use crate::error::RenderError;

/// A half-line `origin + t · dir`, `t ≥ 0`, in world coordinates (f64).
///
/// Rays made by [`Ray::new`] and by [`Camera`](crate::Camera) have a unit `dir`, so `t` is a
/// distance in world units. The fields are public; code that builds a `Ray` literally with a
/// non-unit `dir` gets `t` in multiples of `dir`'s length from [`Aabb::intersect`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: DVec3,
    /// Direction (unit length when made by this crate).
    pub dir: DVec3,
}

impl Ray {
    /// A ray from `origin` along `dir`, normalised to unit length.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when `origin` is not finite or `dir` is zero or not
    /// finite.
    pub fn new(origin: DVec3, dir: DVec3) -> Result<Self, RenderError> {
        if !origin.is_finite() {
            return Err(RenderError::invalid(format!(
                "ray origin must be finite, got {origin}"
            )));
        }
        match dir.try_normalize() {
            Some(dir) => Ok(Self { origin, dir }),
            None => Err(RenderError::invalid(format!(
                "ray direction must be finite and non-zero, got {dir}"
            ))),
        }
    }

    /// The point `origin + t · dir`.
    #[must_use]
    #[inline]
    pub fn at(&self, t: f64) -> DVec3 {
        self.origin + t * self.dir
    }
}

/// A closed axis-aligned box `[min, max]` with finite corners and `min ≤ max` on every axis
/// (flat boxes, even single points, are allowed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    min: DVec3,
    max: DVec3,
}

impl Aabb {
    /// The box with corners `min` and `max`.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when a corner is not finite or `min > max` on an axis.
    pub fn new(min: DVec3, max: DVec3) -> Result<Self, RenderError> {
        if !(min.is_finite() && max.is_finite()) || min.cmpgt(max).any() {
            return Err(RenderError::invalid(format!(
                "box corners must be finite with min ≤ max, got min {min}, max {max}"
            )));
        }
        Ok(Self { min, max })
    }

    /// The smallest box containing every point, or `None` when there are no points or one is
    /// not finite.
    #[must_use]
    pub fn from_points(points: impl IntoIterator<Item = DVec3>) -> Option<Self> {
        let mut it = points.into_iter();
        let first = it.next()?;
        let (min, max) = it.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p)));
        Self::new(min, max).ok()
    }

    /// Minimum corner.
    #[must_use]
    pub fn min(&self) -> DVec3 {
        self.min
    }

    /// Maximum corner.
    #[must_use]
    pub fn max(&self) -> DVec3 {
        self.max
    }

    /// Centre `(min + max) / 2`.
    #[must_use]
    pub fn center(&self) -> DVec3 {
        0.5 * (self.min + self.max)
    }

    /// Edge lengths `max − min` (≥ 0).
    #[must_use]
    pub fn size(&self) -> DVec3 {
        self.max - self.min
    }

    /// The eight corners; bit 0 of the index selects max x, bit 1 max y, bit 2 max z.
    #[must_use]
    pub fn corners(&self) -> [DVec3; 8] {
        std::array::from_fn(|i| {
            DVec3::new(
                if i & 1 == 0 { self.min.x } else { self.max.x },
                if i & 2 == 0 { self.min.y } else { self.max.y },
                if i & 4 == 0 { self.min.z } else { self.max.z },
            )
        })
    }

    /// `true` when `p` lies in the closed box.
    #[must_use]
    pub fn contains(&self, p: DVec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// The parameter interval `[t0, t1]` (with `0 ≤ t0 ≤ t1`) over which `ray` lies in the
    /// closed box, by the slab method; `None` when the ray misses the box, the box is behind
    /// the ray's origin, or the ray has a NaN component.
    ///
    /// A ray starting inside the box gets `t0 = 0`. Because the box is closed, a ray that
    /// only grazes it — touching an edge or corner, or running along a face — hits, with
    /// `t0 == t1` for a single touching point. A ray with a zero direction component hits
    /// only if its origin lies within that axis' slab.
    ///
    /// ```
    /// use glam::DVec3;
    /// use volmorph_render::{Aabb, Ray};
    /// let unit = Aabb::new(DVec3::ZERO, DVec3::ONE).unwrap();
    /// let ray = Ray::new(DVec3::new(-1.0, 0.5, 0.5), DVec3::X).unwrap();
    /// assert_eq!(unit.intersect(&ray), Some((1.0, 2.0)));
    /// let away = Ray::new(DVec3::new(-1.0, 0.5, 0.5), -DVec3::X).unwrap();
    /// assert_eq!(unit.intersect(&away), None);
    /// ```
    #[must_use]
    pub fn intersect(&self, ray: &Ray) -> Option<(f64, f64)> {
        let mut t0 = 0.0_f64;
        let mut t1 = f64::INFINITY;
        for axis in 0..3 {
            let o = ray.origin[axis];
            let d = ray.dir[axis];
            let (lo, hi) = (self.min[axis], self.max[axis]);
            if d == 0.0 {
                if !(lo <= o && o <= hi) {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / d;
            // A zero offset times an infinite inverse (denormal d) is NaN; it means "on the
            // plane now", t = 0.
            let slab = |bound: f64| {
                let off = bound - o;
                if off == 0.0 { 0.0 } else { off * inv }
            };
            let (mut ta, mut tb) = (slab(lo), slab(hi));
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            if ta.is_nan() || tb.is_nan() {
                return None;
            }
            t0 = t0.max(ta);
            t1 = t1.min(tb);
            if t0 > t1 {
                return None;
            }
        }
        Some((t0, t1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn unit() -> Aabb {
        Aabb::new(DVec3::ZERO, DVec3::ONE).unwrap()
    }

    fn ray(o: [f64; 3], d: [f64; 3]) -> Ray {
        Ray::new(DVec3::from_array(o), DVec3::from_array(d)).unwrap()
    }

    #[test]
    fn hand_cases() {
        let b = unit();
        // Straight through along x.
        assert_eq!(
            b.intersect(&ray([-1.0, 0.5, 0.5], [1.0, 0.0, 0.0])),
            Some((1.0, 2.0))
        );
        // Miss: parallel to x, above the box.
        assert_eq!(b.intersect(&ray([-1.0, 1.5, 0.5], [1.0, 0.0, 0.0])), None);
        // Miss: oblique, passing beside the box.
        assert_eq!(b.intersect(&ray([-1.0, 0.5, 0.5], [1.0, 2.0, 0.0])), None);
        // Box behind the origin.
        assert_eq!(b.intersect(&ray([2.0, 0.5, 0.5], [1.0, 0.0, 0.0])), None);
        // Starting inside: t0 = 0, exit at the far face.
        assert_eq!(
            b.intersect(&ray([0.25, 0.5, 0.5], [1.0, 0.0, 0.0])),
            Some((0.0, 0.75))
        );
        assert_eq!(
            b.intersect(&ray([0.5, 0.5, 0.5], [0.0, 0.0, -1.0])),
            Some((0.0, 0.5))
        );
        // Grazing: running along the top face (y = max) is a hit on the closed box.
        assert_eq!(
            b.intersect(&ray([-1.0, 1.0, 0.5], [1.0, 0.0, 0.0])),
            Some((1.0, 2.0))
        );
        // Grazing: along an edge.
        assert_eq!(
            b.intersect(&ray([-1.0, 1.0, 1.0], [1.0, 0.0, 0.0])),
            Some((1.0, 2.0))
        );
        // Grazing: touching the edge x = 0, y = 1 at a single point.
        let (t0, t1) = b
            .intersect(&ray([-1.0, 0.0, 0.5], [1.0, 1.0, 0.0]))
            .unwrap();
        assert!((t0 - 2f64.sqrt()).abs() < 1e-12 && (t1 - t0).abs() < 1e-12);
        // Just outside the face: miss.
        assert_eq!(
            b.intersect(&ray([-1.0, 1.0 + 1e-12, 0.5], [1.0, 0.0, 0.0])),
            None
        );
        // Flat box hit across its thickness.
        let flat = Aabb::new(DVec3::new(0.0, 0.0, 2.0), DVec3::new(1.0, 1.0, 2.0)).unwrap();
        assert_eq!(
            flat.intersect(&ray([0.5, 0.5, 0.0], [0.0, 0.0, 1.0])),
            Some((2.0, 2.0))
        );
        // A NaN direction hits nothing.
        let nan = Ray {
            origin: DVec3::splat(0.5),
            dir: DVec3::new(f64::NAN, 0.0, 1.0),
        };
        assert_eq!(b.intersect(&nan), None);
        // A denormal direction component on the face plane: treated as on the plane now.
        let tiny = Ray {
            origin: DVec3::new(0.0, 0.5, 0.5),
            dir: DVec3::new(f64::MIN_POSITIVE / 4.0, 0.0, 1.0),
        };
        assert_eq!(b.intersect(&tiny), Some((0.0, 0.5)));
    }

    #[test]
    fn constructors_validate() {
        assert!(Ray::new(DVec3::ZERO, DVec3::ZERO).is_err());
        assert!(Ray::new(DVec3::ZERO, DVec3::new(f64::NAN, 0.0, 0.0)).is_err());
        assert!(Ray::new(DVec3::splat(f64::INFINITY), DVec3::X).is_err());
        let r = Ray::new(DVec3::ZERO, DVec3::new(3.0, 4.0, 0.0)).unwrap();
        assert!((r.dir.length() - 1.0).abs() < 1e-15);
        assert!((r.at(5.0) - DVec3::new(3.0, 4.0, 0.0)).length() < 1e-14);

        assert!(Aabb::new(DVec3::ONE, DVec3::ZERO).is_err());
        assert!(Aabb::new(DVec3::ZERO, DVec3::splat(f64::INFINITY)).is_err());
        let b =
            Aabb::from_points([DVec3::new(1.0, -2.0, 3.0), DVec3::new(-1.0, 2.0, 0.0)]).unwrap();
        assert_eq!(b.min(), DVec3::new(-1.0, -2.0, 0.0));
        assert_eq!(b.max(), DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(b.center(), DVec3::new(0.0, 0.0, 1.5));
        assert_eq!(b.size(), DVec3::new(2.0, 4.0, 3.0));
        assert!(Aabb::from_points(std::iter::empty()).is_none());
        let c = b.corners();
        assert_eq!(c[0], b.min());
        assert_eq!(c[7], b.max());
        assert_eq!(c[5], DVec3::new(1.0, -2.0, 3.0));
        assert!(c.iter().all(|&p| b.contains(p)));
        assert!(!b.contains(DVec3::new(0.0, 0.0, 3.0001)));
    }

    proptest! {
        #[test]
        fn intersection_interval_agrees_with_point_membership(
            o in proptest::array::uniform3(-3.0f64..3.0),
            d in proptest::array::uniform3(-1.0f64..1.0),
            lo in proptest::array::uniform3(-1.0f64..0.0),
            ext in proptest::array::uniform3(0.0f64..2.0),
        ) {
            let Ok(r) = Ray::new(DVec3::from_array(o), DVec3::from_array(d)) else {
                return Ok(());
            };
            let lo = DVec3::from_array(lo);
            let b = Aabb::new(lo, lo + DVec3::from_array(ext)).unwrap();
            let grown = Aabb::new(b.min() - 1e-9, b.max() + 1e-9).unwrap();
            let shrunk_contains = |p: DVec3| {
                p.cmpgt(b.min() + 1e-9).all() && p.cmplt(b.max() - 1e-9).all()
            };
            match b.intersect(&r) {
                Some((t0, t1)) => {
                    prop_assert!(0.0 <= t0 && t0 <= t1);
                    for k in 0..=8 {
                        let t = t0 + (t1 - t0) * f64::from(k) / 8.0;
                        prop_assert!(grown.contains(r.at(t)), "t {t} in [{t0}, {t1}]");
                    }
                    // Outside the interval the ray is outside the (shrunk) box.
                    for k in 1..=20 {
                        let dt = f64::from(k) * 0.05 + 1e-6;
                        prop_assert!(!shrunk_contains(r.at(t1 + dt)));
                        if t0 - dt >= 0.0 {
                            prop_assert!(!shrunk_contains(r.at(t0 - dt)));
                        }
                    }
                }
                None => {
                    for k in 0..=400 {
                        let t = f64::from(k) * 0.025;
                        prop_assert!(!shrunk_contains(r.at(t)), "missed point at t {t}");
                    }
                }
            }
        }
    }
}
