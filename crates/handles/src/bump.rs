//! Bryson's bump transform (True 1992 §2.2, after Bryson 1992): a transformation `T` applied
//! in full near a centre and faded out to the identity by a smooth bump of the distance.
//!
//! With `s(x, a) = 0` for `x ≤ 0`, `exp(−((a − x)/x)²)` for `0 < x < a`, `1` for `x ≥ a`, the
//! step `step(x, r0, r1) = s(x − r0, r1 − r0)` and the bump of the distance `d = |x − c|`,
//! `bump(d) = s(r0 − d, r0 − r1)` — 1 within `r1` of the centre, 0 beyond `r0`,
//!
//! ```text
//! T'(x) = bump(|x − c|)·T(x) + (1 − bump(|x − c|))·x
//! ```
//!
//! (`ID` in the seed is the identity transformation.) The map is `C¹` everywhere and `C^∞`
//! except on the sphere `d = r1`. It acts as a push-forward on points (True and Bryson move
//! surface vertices with it).

use glam::{DMat3, DVec3};

use volmorph_deform::{Affine, DeformError, SpaceMap};

/// Bryson's bump-weighted transformation; see the [module docs](self).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BumpMap {
    center: DVec3,
    inner: f64,
    outer: f64,
    transform: Affine,
}

impl BumpMap {
    /// `T` applied fully within `inner` (= `r1`) of `center`, faded to the identity at
    /// `outer` (= `r0`). Distances in physical units, `0 ≤ inner < outer`.
    ///
    /// # Errors
    /// [`DeformError::NonFinite`] for NaN/infinite input, [`DeformError::InvalidHandles`]
    /// unless `0 ≤ inner < outer`.
    pub fn new(
        center: DVec3,
        inner: f64,
        outer: f64,
        transform: Affine,
    ) -> Result<Self, DeformError> {
        let vals = [
            ("bump centre", center.x),
            ("bump centre", center.y),
            ("bump centre", center.z),
            ("bump inner radius", inner),
            ("bump outer radius", outer),
        ];
        for (what, v) in vals
            .into_iter()
            .chain(transform.matrix.to_cols_array().map(|v| ("bump matrix", v)))
            .chain(transform.offset.to_array().map(|v| ("bump offset", v)))
        {
            if !v.is_finite() {
                return Err(DeformError::NonFinite {
                    what: what.into(),
                    value: v,
                });
            }
        }
        if !(inner >= 0.0 && inner < outer) {
            return Err(DeformError::InvalidHandles(format!(
                "bump radii need 0 ≤ inner < outer, got inner {inner}, outer {outer}"
            )));
        }
        Ok(Self {
            center,
            inner,
            outer,
            transform,
        })
    }

    /// The bump that drags `handle` to `target`: a translation by `target − handle` about
    /// `handle`.
    ///
    /// # Errors
    /// As [`new`](Self::new).
    pub fn drag(handle: DVec3, target: DVec3, inner: f64, outer: f64) -> Result<Self, DeformError> {
        Self::new(handle, inner, outer, Affine::translation(target - handle))
    }

    /// The centre of the bump (physical units).
    #[must_use]
    pub fn center(&self) -> DVec3 {
        self.center
    }

    /// Radius within which the transform applies fully (`r1`).
    #[must_use]
    pub fn inner(&self) -> f64 {
        self.inner
    }

    /// Radius at which the map has faded to the identity (`r0`).
    #[must_use]
    pub fn outer(&self) -> f64 {
        self.outer
    }

    /// The affine transform applied at the centre.
    #[must_use]
    pub fn transform(&self) -> Affine {
        self.transform
    }

    /// The bump weight at distance `d` from the centre and its derivative `d bump / d d`.
    #[must_use]
    pub fn weight(&self, d: f64) -> (f64, f64) {
        if d <= self.inner {
            (1.0, 0.0)
        } else if d >= self.outer {
            (0.0, 0.0)
        } else {
            let x = self.outer - d; // in (0, r0 − r1)
            let s = (d - self.inner) / x;
            let b = (-s * s).exp();
            let ds = (self.outer - self.inner) / (x * x);
            (b, -2.0 * s * ds * b)
        }
    }
}

impl SpaceMap for BumpMap {
    fn apply(&self, p: DVec3) -> DVec3 {
        let (b, _) = self.weight((p - self.center).length());
        if b == 0.0 {
            return p;
        }
        b * self.transform.apply(p) + (1.0 - b) * p
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.apply_with_jacobian(p).1
    }

    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        let r = p - self.center;
        let d = r.length();
        let (b, db) = self.weight(d);
        if b == 0.0 {
            return (p, DMat3::IDENTITY);
        }
        let t = self.transform.apply(p);
        let grad = if d > 0.0 { (db / d) * r } else { DVec3::ZERO };
        let disp = t - p;
        let j = b * self.transform.matrix
            + (1.0 - b) * DMat3::IDENTITY
            + DMat3::from_cols(disp * grad.x, disp * grad.y, disp * grad.z);
        (b * t + (1.0 - b) * p, j)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_deform::map::central_jacobian;

    #[test]
    fn full_inside_identity_outside_smooth_between() {
        let rot = Affine {
            matrix: DMat3::from_rotation_z(0.5),
            offset: DVec3::new(1.0, 0.0, 0.0),
        };
        let m = BumpMap::new(DVec3::new(1.0, 2.0, 3.0), 2.0, 5.0, rot).unwrap();
        let inside = DVec3::new(1.5, 2.0, 3.0);
        assert_eq!(m.apply(inside), rot.apply(inside));
        let outside = DVec3::new(7.0, 2.0, 3.0);
        assert_eq!(m.apply(outside), outside);
        // Hand value: d = 3.5 → s = 1.5/1.5 = 1, bump = e⁻¹.
        let (b, _) = m.weight(3.5);
        assert!((b - (-1.0f64).exp()).abs() < 1e-15);
        for p in [
            DVec3::new(3.0, 3.5, 3.2),
            DVec3::new(1.0, 5.9, 2.0),
            DVec3::new(-1.5, 2.2, 4.0),
        ] {
            let (y, j) = m.apply_with_jacobian(p);
            assert_eq!(y, m.apply(p));
            assert!(
                (j - central_jacobian(&m, p)).abs_diff_eq(DMat3::ZERO, 1e-7),
                "{p}"
            );
        }
        // Drag: the handle lands on the target.
        let d = BumpMap::drag(DVec3::ZERO, DVec3::new(0.5, 0.0, 0.0), 1.0, 3.0).unwrap();
        assert_eq!(d.apply(DVec3::ZERO), DVec3::new(0.5, 0.0, 0.0));
        assert!(BumpMap::drag(DVec3::ZERO, DVec3::ONE, 3.0, 3.0).is_err());
        assert!(BumpMap::drag(DVec3::ZERO, DVec3::ONE, -1.0, 3.0).is_err());
        assert!(BumpMap::drag(DVec3::NAN, DVec3::ONE, 1.0, 3.0).is_err());
    }
}
