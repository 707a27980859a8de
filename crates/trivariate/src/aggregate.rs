//! Aggregate objects (Martin & Cohen §2.2–§3): a geometry spline plus any number of named
//! attribute splines sharing the unit parametric domain.
//!
//! # Conventions
//!
//! * An [`Aggregate<N>`] has `N` parametric axes (curve `N = 1`, surface `N = 2`, volume
//!   `N = 3`). Every component — the geometry and each attribute — is an independent
//!   [`TensorBSpline<N>`] with its own degrees, knot vectors, control-net resolution and
//!   rationality; the **only** shared property is the parametric domain, which must be exactly
//!   the unit cube `[0, 1]^N` (paper §2.2: "we normalize all the domains to the unit cube").
//!   Use [`TensorBSpline::reparametrized`] to normalise a spline defined elsewhere.
//! * The geometry maps parameters to **physical space**: it has exactly
//!   [`GEOMETRY_DIM`]` = 3` coordinates (x, y, z) per control point, in the caller's length unit.
//!   Its control points must span at least `N` affine dimensions (a volume whose control points
//!   are all coplanar is rejected as degenerate).
//! * An attribute has any value dimension `≥ 1` (a density is 1, a colour 3 or 4, …) and is
//!   evaluated at the same parameters as the geometry: the attribute value "at" a physical
//!   point `x = P(u)` is `A(u)`.
//! * Attributes are kept in insertion order; names are unique and non-empty.

use volmorph_spline::TensorBSpline;

use crate::TrivariateError;
use crate::error::ctx;

/// Number of coordinates of every geometry control point (physical x, y, z).
pub const GEOMETRY_DIM: usize = 3;

/// Relative tolerance of the degeneracy test: a direction is independent when its component
/// orthogonal to the previous ones exceeds this fraction of the control net's extent. Control
/// points are stored in f64, so anything below ~1e-12 relative is rounding noise.
const DEGENERACY_TOLERANCE: f64 = 1e-12;

/// A named attribute spline carried by an aggregate.
#[derive(Debug, Clone, PartialEq)]
pub struct Attribute<const N: usize> {
    name: String,
    spline: TensorBSpline<N>,
}

impl<const N: usize> Attribute<N> {
    /// The attribute's name (unique within its aggregate).
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The attribute's spline (domain `[0, 1]^N`).
    #[must_use]
    pub fn spline(&self) -> &TensorBSpline<N> {
        &self.spline
    }
}

/// A geometry spline with named attribute splines on the shared domain `[0, 1]^N`
/// (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct Aggregate<const N: usize> {
    geometry: TensorBSpline<N>,
    attributes: Vec<Attribute<N>>,
}

/// An aggregate curve: geometry curve in R³ plus attribute curves.
pub type AggregateCurve = Aggregate<1>;
/// An aggregate surface: geometry surface in R³ plus attribute surfaces.
pub type AggregateSurface = Aggregate<2>;
/// An aggregate volume: trivariate NURBS geometry in R³ plus attribute volumes.
pub type AggregateVolume = Aggregate<3>;

/// Human name of an `N`-parameter object.
pub(crate) fn kind_name(n: usize) -> &'static str {
    match n {
        1 => "curve",
        2 => "surface",
        3 => "volume",
        _ => "object",
    }
}

/// Require the domain of `s` to be exactly `[0, 1]` on every axis.
pub(crate) fn check_unit_domain<const N: usize>(
    what: &str,
    s: &TensorBSpline<N>,
) -> Result<(), TrivariateError> {
    for (axis, [start, end]) in s.domain().into_iter().enumerate() {
        if start != 0.0 || end != 1.0 {
            return Err(TrivariateError::DomainNotUnit {
                what: what.to_owned(),
                axis,
                start,
                end,
            });
        }
    }
    Ok(())
}

/// Affine dimension (0..=3) spanned by the control points of a 3-D net.
fn affine_rank(points: &[f64]) -> usize {
    let mut it = points.chunks_exact(GEOMETRY_DIM);
    let Some(first) = it.next() else { return 0 };
    let o = [first[0], first[1], first[2]];
    let mut extent: f64 = 0.0;
    for p in points.chunks_exact(GEOMETRY_DIM) {
        for c in 0..3 {
            extent = extent.max((p[c] - o[c]).abs());
        }
    }
    if extent == 0.0 {
        return 0;
    }
    let tol = DEGENERACY_TOLERANCE * extent;
    let mut basis: Vec<[f64; 3]> = Vec::with_capacity(3);
    for p in points.chunks_exact(GEOMETRY_DIM) {
        let mut d = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        for b in &basis {
            let dot = d[0] * b[0] + d[1] * b[1] + d[2] * b[2];
            for c in 0..3 {
                d[c] -= dot * b[c];
            }
        }
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if n > tol {
            basis.push([d[0] / n, d[1] / n, d[2] / n]);
            if basis.len() == 3 {
                break;
            }
        }
    }
    basis.len()
}

impl<const N: usize> Aggregate<N> {
    /// An aggregate with `geometry` and no attributes.
    ///
    /// # Errors
    /// [`TrivariateError::GeometryDimension`] unless the geometry has 3 coordinates,
    /// [`TrivariateError::DomainNotUnit`] unless its domain is `[0, 1]^N`,
    /// [`TrivariateError::Degenerate`] if its control points span fewer than `N` dimensions.
    pub fn new(geometry: TensorBSpline<N>) -> Result<Self, TrivariateError> {
        Self::check_geometry(&geometry)?;
        Ok(Self {
            geometry,
            attributes: Vec::new(),
        })
    }

    fn check_geometry(g: &TensorBSpline<N>) -> Result<(), TrivariateError> {
        if g.dim() != GEOMETRY_DIM {
            return Err(TrivariateError::GeometryDimension {
                expected: GEOMETRY_DIM,
                got: g.dim(),
            });
        }
        check_unit_domain("geometry", g)?;
        let rank = affine_rank(&g.control_points());
        if rank < N {
            return Err(TrivariateError::Degenerate {
                what: kind_name(N),
                rank,
                needed: N,
            });
        }
        Ok(())
    }

    /// Add an attribute (it becomes carried data, §3).
    ///
    /// # Errors
    /// [`TrivariateError::AttributeName`] for an empty or already used name,
    /// [`TrivariateError::DomainNotUnit`] unless the attribute's domain is `[0, 1]^N`.
    pub fn add_attribute(
        &mut self,
        name: impl Into<String>,
        spline: TensorBSpline<N>,
    ) -> Result<(), TrivariateError> {
        let name = name.into();
        if name.is_empty() || self.attribute(&name).is_some() {
            return Err(TrivariateError::AttributeName(name));
        }
        check_unit_domain(&format!("attribute {name:?}"), &spline)?;
        self.attributes.push(Attribute { name, spline });
        Ok(())
    }

    /// Builder form of [`Aggregate::add_attribute`].
    ///
    /// # Errors
    /// As [`Aggregate::add_attribute`].
    pub fn with_attribute(
        mut self,
        name: impl Into<String>,
        spline: TensorBSpline<N>,
    ) -> Result<Self, TrivariateError> {
        self.add_attribute(name, spline)?;
        Ok(self)
    }

    /// Replace the spline of an existing attribute (explicit attribute editing, §3).
    ///
    /// # Errors
    /// [`TrivariateError::UnknownAttribute`], or [`TrivariateError::DomainNotUnit`].
    pub fn set_attribute(
        &mut self,
        name: &str,
        spline: TensorBSpline<N>,
    ) -> Result<(), TrivariateError> {
        check_unit_domain(&format!("attribute {name:?}"), &spline)?;
        let a = self
            .attributes
            .iter_mut()
            .find(|a| a.name == name)
            .ok_or_else(|| TrivariateError::UnknownAttribute(name.to_owned()))?;
        a.spline = spline;
        Ok(())
    }

    /// Remove an attribute and return its spline.
    ///
    /// # Errors
    /// [`TrivariateError::UnknownAttribute`].
    pub fn remove_attribute(&mut self, name: &str) -> Result<TensorBSpline<N>, TrivariateError> {
        let i = self
            .attributes
            .iter()
            .position(|a| a.name == name)
            .ok_or_else(|| TrivariateError::UnknownAttribute(name.to_owned()))?;
        Ok(self.attributes.remove(i).spline)
    }

    /// Replace the geometry (the default target of modification, §3).
    ///
    /// # Errors
    /// As [`Aggregate::new`].
    pub fn set_geometry(&mut self, geometry: TensorBSpline<N>) -> Result<(), TrivariateError> {
        Self::check_geometry(&geometry)?;
        self.geometry = geometry;
        Ok(())
    }

    /// The geometry spline (3 coordinates, domain `[0, 1]^N`).
    #[must_use]
    pub fn geometry(&self) -> &TensorBSpline<N> {
        &self.geometry
    }

    /// The attributes in insertion order.
    #[must_use]
    pub fn attributes(&self) -> &[Attribute<N>] {
        &self.attributes
    }

    /// The attribute spline named `name`, if any.
    #[must_use]
    pub fn attribute(&self, name: &str) -> Option<&TensorBSpline<N>> {
        self.attributes
            .iter()
            .find(|a| a.name == name)
            .map(|a| &a.spline)
    }

    /// Smallest and largest value of the first component of attribute `name` over its
    /// control points (Cartesian, for rational attributes): every value the attribute takes
    /// lies in it, by the convex hull property.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] when there is no attribute `name`.
    pub fn attribute_range(&self, name: &str) -> Result<(f64, f64), TrivariateError> {
        let s = self.attribute(name).ok_or_else(|| {
            TrivariateError::InvalidArgument(format!("model has no attribute {name:?}"))
        })?;
        Ok(crate::isosurface::control_range(s))
    }

    /// Physical point at parameters `u ∈ [0, 1]^N`.
    ///
    /// # Errors
    /// [`TrivariateError::Spline`] with `ParameterOutsideDomain` for parameters outside the
    /// unit cube or NaN.
    pub fn point(&self, u: [f64; N]) -> Result<[f64; 3], TrivariateError> {
        let mut p = [0.0; 3];
        self.geometry
            .eval_into(u, &mut p)
            .map_err(ctx("geometry"))?;
        Ok(p)
    }

    /// Value of attribute `name` at parameters `u`, written to `out[..dim]`. No allocation.
    ///
    /// # Errors
    /// [`TrivariateError::UnknownAttribute`]; [`TrivariateError::Spline`] for parameters
    /// outside the domain or a short `out`.
    pub fn attribute_into(
        &self,
        name: &str,
        u: [f64; N],
        out: &mut [f64],
    ) -> Result<(), TrivariateError> {
        let s = self
            .attribute(name)
            .ok_or_else(|| TrivariateError::UnknownAttribute(name.to_owned()))?;
        s.eval_into(u, out)
            .map_err(|e| ctx(format!("attribute {name:?}"))(e))
    }

    /// Assemble without re-validating (components produced by this crate's operators).
    pub(crate) fn from_parts_unchecked(
        geometry: TensorBSpline<N>,
        attributes: Vec<(String, TensorBSpline<N>)>,
    ) -> Self {
        Self {
            geometry,
            attributes: attributes
                .into_iter()
                .map(|(name, spline)| Attribute { name, spline })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_spline::KnotVector;

    fn unit_cube(deg: usize) -> TensorBSpline<3> {
        let kv = KnotVector::clamped_uniform(deg, deg + 1, [0.0, 1.0]).unwrap();
        let n = deg + 1;
        let mut pts = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let s = deg as f64;
                    pts.extend([i as f64 / s, j as f64 / s, k as f64 / s]);
                }
            }
        }
        TensorBSpline::new([kv.clone(), kv.clone(), kv], 3, pts).unwrap()
    }

    #[test]
    fn attributes_are_named_and_validated() {
        let mut a = Aggregate::new(unit_cube(1)).unwrap();
        let kv = KnotVector::clamped_uniform(2, 4, [0.0, 1.0]).unwrap();
        let dens =
            TensorBSpline::new([kv.clone(), kv.clone(), kv.clone()], 1, vec![2.0; 64]).unwrap();
        a.add_attribute("density", dens.clone()).unwrap();
        assert!(matches!(
            a.add_attribute("density", dens.clone()),
            Err(TrivariateError::AttributeName(_))
        ));
        assert!(matches!(
            a.add_attribute("", dens.clone()),
            Err(TrivariateError::AttributeName(_))
        ));
        let other = dens
            .reparametrized([[0.0, 2.0], [0.0, 1.0], [0.0, 1.0]])
            .unwrap();
        assert!(matches!(
            a.add_attribute("x", other),
            Err(TrivariateError::DomainNotUnit { axis: 0, .. })
        ));
        let mut v = [0.0];
        a.attribute_into("density", [0.3, 0.2, 0.9], &mut v)
            .unwrap();
        assert!((v[0] - 2.0).abs() < 1e-14);
        assert!(a.attribute_into("nope", [0.0; 3], &mut v).is_err());
        let p = a.point([0.25, 0.5, 0.75]).unwrap();
        assert!((p[0] - 0.25).abs() < 1e-15 && (p[2] - 0.75).abs() < 1e-15);
        assert!(a.point([1.5, 0.0, 0.0]).is_err());
        assert_eq!(a.remove_attribute("density").unwrap(), dens);
        assert!(a.attributes().is_empty());
    }

    #[test]
    fn degenerate_geometry_is_rejected() {
        let kv = KnotVector::clamped_uniform(1, 2, [0.0, 1.0]).unwrap();
        // All eight corners in the plane z = 0.
        let mut pts = Vec::new();
        for _k in 0..2 {
            for j in 0..2 {
                for i in 0..2 {
                    pts.extend([f64::from(i), f64::from(j), 0.0]);
                }
            }
        }
        let g = TensorBSpline::new([kv.clone(), kv.clone(), kv], 3, pts).unwrap();
        assert!(matches!(
            Aggregate::new(g),
            Err(TrivariateError::Degenerate {
                rank: 2,
                needed: 3,
                ..
            })
        ));
    }
}
