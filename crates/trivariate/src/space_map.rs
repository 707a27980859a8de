//! The geometry of a trivariate NURBS volume as a space map, so that volumes, meshes and F-rep
//! shapes can be deformed by it (the free-form deformation of Sederberg and Parry with a NURBS
//! solid, and Martin & Cohen's volume as a deformed parameter box).
//!
//! **Direction.** [`GeometryMap`] sends points of a *placement box* in physical space — the
//! undeformed model — to where the geometry spline puts them (push-forward): a point `x` of the
//! box has parameters `u = (x − box_min) ⊘ (box_max − box_min)` in the shared domain `[0, 1]³`
//! and goes to `S(u)`. Points outside the closed box are not moved. The map is continuous across
//! the box surface only where the volume's boundary faces coincide with the box faces (as for
//! an identity placement); the Jacobian is `DS(u) · diag(1 / extent)` inside and `I` outside.

use glam::{DMat3, DVec3};
use volmorph_deform::SpaceMap;
use volmorph_spline::TensorBSpline;

use crate::error::TrivariateError;
use crate::eval::{EvalMethod, VolumeEvaluator};

/// A trivariate geometry spline acting on its placement box; see the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct GeometryMap {
    geometry: TensorBSpline<3>,
    box_min: DVec3,
    extent: DVec3,
}

impl GeometryMap {
    /// The map of `geometry` (a 3-component spline on `[0, 1]³`) with its parameter domain
    /// placed on the physical box `box_min ..= box_max`.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] if the geometry does not have 3 components or its
    /// domain is not `[0, 1]³`, or if the box is empty, inverted or not finite.
    pub fn new(
        geometry: TensorBSpline<3>,
        box_min: DVec3,
        box_max: DVec3,
    ) -> Result<Self, TrivariateError> {
        if geometry.dim() != 3 {
            return Err(TrivariateError::InvalidArgument(format!(
                "a geometry map needs a 3-component spline, got {} components",
                geometry.dim()
            )));
        }
        if geometry.domain() != [[0.0, 1.0]; 3] {
            return Err(TrivariateError::InvalidArgument(format!(
                "a geometry map needs the domain [0, 1]³, got {:?}",
                geometry.domain()
            )));
        }
        let extent = box_max - box_min;
        if !(box_min.is_finite() && box_max.is_finite() && extent.min_element() > 0.0) {
            return Err(TrivariateError::InvalidArgument(format!(
                "placement box {box_min} ..= {box_max} is empty, inverted or not finite"
            )));
        }
        Ok(Self {
            geometry,
            box_min,
            extent,
        })
    }

    /// The map placed on the unit cube (parameters equal physical coordinates).
    ///
    /// # Errors
    /// As [`GeometryMap::new`].
    pub fn on_unit_cube(geometry: TensorBSpline<3>) -> Result<Self, TrivariateError> {
        Self::new(geometry, DVec3::ZERO, DVec3::ONE)
    }

    /// The geometry spline.
    #[must_use]
    pub fn geometry(&self) -> &TensorBSpline<3> {
        &self.geometry
    }

    /// The placement box `(min, max)`.
    #[must_use]
    pub fn placement(&self) -> (DVec3, DVec3) {
        (self.box_min, self.box_min + self.extent)
    }

    /// Parameters of `x`, `None` outside the closed box (or NaN).
    fn parameter(&self, x: DVec3) -> Option<[f64; 3]> {
        let u = (x - self.box_min) / self.extent;
        (u.cmpge(DVec3::ZERO).all() && u.cmple(DVec3::ONE).all()).then(|| u.to_array())
    }

    fn eval(&self, x: DVec3) -> Option<(DVec3, DMat3)> {
        let u = self.parameter(x)?;
        let mut value = [0.0; 3];
        let mut gradient = [0.0; 9];
        VolumeEvaluator::new(&self.geometry)
            .eval_into(EvalMethod::default(), u, &mut value, &mut gradient)
            .ok()?;
        // gradient[a·3 + c] = ∂S_c/∂u_a: column a of DS.
        let ds = DMat3::from_cols_array(&gradient);
        let scale = DMat3::from_diagonal(self.extent.recip());
        Some((DVec3::from_array(value), ds * scale))
    }
}

impl SpaceMap for GeometryMap {
    fn apply(&self, p: DVec3) -> DVec3 {
        self.eval(p).map_or(p, |(x, _)| x)
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.eval(p).map_or(DMat3::IDENTITY, |(_, j)| j)
    }

    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        self.eval(p).unwrap_or((p, DMat3::IDENTITY))
    }
}
