//! [`LiveMap`]: the kinds of map that are linear in their parameters, as one value, so live
//! editing engines (`volmorph_deform::LiveGrid`, the incremental push-forward) take any of them.

use glam::{DMat3, DVec3};
use volmorph_deform::live::{Influence, LinearMap};
use volmorph_deform::{DeformError, SpaceMap};
use volmorph_handles::{AffineMls, FrameMls, ThinPlateMap, WendlandMap};
use volmorph_lattice::BSplineLattice;
use volmorph_volume::Geometry;

use crate::AnyMap;

/// A map linear in its parameters: control points of a lattice, targets of affine MLS, target
/// frames of frame MLS, targets of a thin-plate or Wendland spline (see [`LinearMap`] for the
/// parameter order of each).
// One value per map object, never stored in bulk: boxing the lattice would only add an
// indirection to every evaluation.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum LiveMap {
    /// A B-spline lattice.
    Lattice(BSplineLattice),
    /// Affine moving least squares.
    AffineMls(AffineMls),
    /// Frame-based moving least squares.
    FrameMls(FrameMls),
    /// A thin-plate spline.
    ThinPlate(ThinPlateMap),
    /// A compactly supported Wendland spline.
    Wendland(WendlandMap),
}

impl AnyMap {
    /// The map as a [`LiveMap`] if its kind is linear in its parameters, `None` otherwise
    /// (similarity and rigid MLS fit a rotation, compositions and inverses are not linear).
    #[must_use]
    pub fn to_live(&self) -> Option<LiveMap> {
        match self {
            AnyMap::Lattice(m) => Some(LiveMap::Lattice(m.clone())),
            AnyMap::AffineMls(m) => Some(LiveMap::AffineMls(m.clone())),
            AnyMap::FrameMls(m) => Some(LiveMap::FrameMls(m.clone())),
            AnyMap::ThinPlate(m) => Some(LiveMap::ThinPlate(m.clone())),
            AnyMap::Wendland(m) => Some(LiveMap::Wendland(m.clone())),
            _ => None,
        }
    }
}

impl From<LiveMap> for AnyMap {
    fn from(m: LiveMap) -> Self {
        match m {
            LiveMap::Lattice(m) => AnyMap::Lattice(m),
            LiveMap::AffineMls(m) => AnyMap::AffineMls(m),
            LiveMap::FrameMls(m) => AnyMap::FrameMls(m),
            LiveMap::ThinPlate(m) => AnyMap::ThinPlate(m),
            LiveMap::Wendland(m) => AnyMap::Wendland(m),
        }
    }
}

macro_rules! each {
    ($self:expr, $m:ident => $e:expr) => {
        match $self {
            LiveMap::Lattice($m) => $e,
            LiveMap::AffineMls($m) => $e,
            LiveMap::FrameMls($m) => $e,
            LiveMap::ThinPlate($m) => $e,
            LiveMap::Wendland($m) => $e,
        }
    };
}

impl SpaceMap for LiveMap {
    fn apply(&self, p: DVec3) -> DVec3 {
        each!(self, m => m.apply(p))
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        each!(self, m => m.jacobian(p))
    }

    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        each!(self, m => m.apply_with_jacobian(p))
    }

    fn apply_batch(&self, points: &[DVec3], out: &mut [DVec3]) -> Result<(), DeformError> {
        each!(self, m => m.apply_batch(points, out))
    }

    fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        each!(self, m => m.apply_grid(grid, out))
    }

    fn apply_grid_part(
        &self,
        grid: &Geometry,
        part: volmorph_volume::IndexBox,
        out: &mut [DVec3],
    ) -> Result<(), DeformError> {
        each!(self, m => m.apply_grid_part(grid, part, out))
    }

    fn jacobian_grid(&self, grid: &Geometry, out: &mut [DMat3]) -> Result<(), DeformError> {
        each!(self, m => m.jacobian_grid(grid, out))
    }
}

impl LinearMap for LiveMap {
    fn parameter_count(&self) -> usize {
        each!(self, m => m.parameter_count())
    }

    fn parameters(&self) -> Vec<DVec3> {
        each!(self, m => m.parameters())
    }

    fn set_parameters(&mut self, values: &[DVec3]) -> Result<(), DeformError> {
        each!(self, m => m.set_parameters(values))
    }

    fn set_some_parameters(&mut self, changes: &[(usize, DVec3)]) -> Result<(), DeformError> {
        each!(self, m => m.set_some_parameters(changes))
    }

    fn coefficients_into(&self, v: DVec3, out: &mut [f64]) -> DVec3 {
        each!(self, m => m.coefficients_into(v, out))
    }

    fn coefficient_column(
        &self,
        k: usize,
        points: &[DVec3],
        out: &mut [f64],
    ) -> Result<(), DeformError> {
        each!(self, m => m.coefficient_column(k, points, out))
    }

    fn dense_coefficients_are_cheap(&self) -> bool {
        each!(self, m => m.dense_coefficients_are_cheap())
    }

    fn influence(&self, ks: &[usize]) -> Influence {
        each!(self, m => m.influence(ks))
    }

    fn same_structure(&self, other: &Self) -> bool {
        match (self, other) {
            (LiveMap::Lattice(a), LiveMap::Lattice(b)) => a.same_structure(b),
            (LiveMap::AffineMls(a), LiveMap::AffineMls(b)) => a.same_structure(b),
            (LiveMap::FrameMls(a), LiveMap::FrameMls(b)) => a.same_structure(b),
            (LiveMap::ThinPlate(a), LiveMap::ThinPlate(b)) => a.same_structure(b),
            (LiveMap::Wendland(a), LiveMap::Wendland(b)) => a.same_structure(b),
            _ => false,
        }
    }
}
