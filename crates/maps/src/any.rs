//! [`AnyMap`]: one value for every kind of space map volmorph has.

use glam::{DMat3, DVec3};
use volmorph_deform::inverse::Inverse;
use volmorph_deform::{Affine, DeformError, Identity, SampledMap, SpaceMap};
use volmorph_handles::{
    AffineMls, BumpMap, FrameMls, RigidMls, SimilarityMls, ThinPlateMap, WendlandMap,
};
use volmorph_lattice::BSplineLattice;
use volmorph_trivariate::GeometryMap;
use volmorph_volume::{Geometry, IndexBox};

use crate::field::DisplacementField;
use crate::refined::Refined;

/// Every kind of space map, as one value that can be stored, written to a file (JSON, and ITK
/// `.tfm` where ITK has the same transform) and applied. Each variant keeps its own direction
/// convention (see the variant's type); [`AnyMap`] itself adds none.
///
/// [`AnyMap::Compose`] applies its maps **in list order**: `Compose([a, b])` sends `x` to
/// `b(a(x))` (a pipeline, the first map first).
// One value per map object, never stored in bulk: boxing the lattice would only add an
// indirection to every evaluation.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum AnyMap {
    /// The identity.
    Identity,
    /// An affine map `x ↦ A x + t`.
    Affine(Affine),
    /// A B-spline / Bézier lattice (True 1992; Feng 2002).
    Lattice(BSplineLattice),
    /// Affine moving least squares through point handles.
    AffineMls(AffineMls),
    /// Similarity moving least squares through point handles.
    SimilarityMls(SimilarityMls),
    /// Rigid moving least squares through point handles.
    RigidMls(RigidMls),
    /// Frame-based moving least squares.
    FrameMls(FrameMls),
    /// Thin-plate / volume spline through point handles.
    ThinPlate(ThinPlateMap),
    /// Affine trend plus compactly supported Wendland kernels through point handles (the
    /// handle map that scales to tens of thousands of handles).
    Wendland(WendlandMap),
    /// Bryson's bump transform.
    Bump(BumpMap),
    /// A trivariate NURBS geometry acting on its placement box.
    Geometry(GeometryMap),
    /// A map sampled on a grid and interpolated trilinearly, extended outside the grid by a
    /// constant displacement.
    Sampled(SampledMap),
    /// A dense displacement field `x ↦ x + d(x)` as ITK's `DisplacementFieldTransform`
    /// (trilinear, zero displacement beyond half a voxel outside its grid; see
    /// [`crate::field`]).
    DisplacementField(DisplacementField),
    /// The maps in list order, the first applied first.
    Compose(Vec<AnyMap>),
    /// The numerical inverse (Newton) of a map.
    Inverse(Box<Inverse<AnyMap>>),
    /// A map plus a lattice correction, `x ↦ base(x) + L(x) − x` (a dense registration's
    /// result).
    Refined(Box<Refined<AnyMap>>),
}

impl AnyMap {
    /// The kind's name, as in the map JSON's `"kind"` field.
    #[must_use]
    pub fn kind(&self) -> &'static str {
        match self {
            AnyMap::Identity => "identity",
            AnyMap::Affine(_) => "affine",
            AnyMap::Lattice(_) => volmorph_lattice::json::LATTICE_JSON_KIND,
            AnyMap::AffineMls(_) | AnyMap::SimilarityMls(_) | AnyMap::RigidMls(_) => "mls",
            AnyMap::FrameMls(_) => "frame-mls",
            AnyMap::ThinPlate(_) => "thin-plate",
            AnyMap::Wendland(_) => "wendland",
            AnyMap::Bump(_) => "bump",
            AnyMap::Geometry(_) => "nurbs-geometry",
            AnyMap::Sampled(_) => "sampled",
            AnyMap::DisplacementField(_) => "displacement-field",
            AnyMap::Compose(_) => "compose",
            AnyMap::Inverse(_) => "inverse",
            AnyMap::Refined(_) => "refined",
        }
    }

    /// A one-line description: the kind and its size (control points, handles, grid nodes,
    /// components).
    #[must_use]
    pub fn summary(&self) -> String {
        match self {
            AnyMap::Identity => "identity".into(),
            AnyMap::Affine(a) => format!(
                "affine, det {:.6}, translation {:.4}",
                volmorph_io::Num(a.matrix.determinant()),
                volmorph_io::Nums(&a.offset.to_array())
            ),
            AnyMap::Lattice(l) => {
                let [cx, cy, cz] = l.counts();
                let [dx, dy, dz] = l.degree();
                format!("B-spline lattice, degree {dx}×{dy}×{dz}, {cx}×{cy}×{cz} control points")
            }
            AnyMap::AffineMls(m) => format!("affine MLS, {} point handles", m.sources().len()),
            AnyMap::SimilarityMls(m) => {
                format!("similarity MLS, {} point handles", m.sources().len())
            }
            AnyMap::RigidMls(m) => format!("rigid MLS, {} point handles", m.sources().len()),
            AnyMap::FrameMls(m) => format!("frame MLS, {} frames", m.sources().len()),
            AnyMap::ThinPlate(m) => format!("thin-plate spline, {} handles", m.sources().len()),
            AnyMap::Wendland(m) => format!(
                "Wendland compact-support spline, {} handles, support radius {}",
                m.sources().len(),
                volmorph_io::fmt_f64(m.support())
            ),
            AnyMap::Bump(b) => format!("bump, radii {} .. {}", b.inner(), b.outer()),
            AnyMap::Geometry(g) => {
                let [cx, cy, cz] = g.geometry().counts();
                format!("NURBS geometry, {cx}×{cy}×{cz} control points")
            }
            AnyMap::Sampled(s) => {
                let [nx, ny, nz] = s.grid().dims;
                format!("sampled map, {nx}×{ny}×{nz} nodes")
            }
            AnyMap::DisplacementField(f) => {
                let [nx, ny, nz] = f.grid().dims;
                let max = f
                    .displacements()
                    .iter()
                    .map(|d| d.length())
                    .fold(0.0, f64::max);
                format!(
                    "displacement field, {nx}×{ny}×{nz} nodes, largest displacement {}",
                    volmorph_io::fmt_f64(max)
                )
            }
            AnyMap::Compose(ms) => format!(
                "composition of {} maps: {}",
                ms.len(),
                ms.iter().map(AnyMap::kind).collect::<Vec<_>>().join(" → ")
            ),
            AnyMap::Inverse(i) => format!("inverse of {}", i.map().summary()),
            AnyMap::Refined(r) => {
                let [cx, cy, cz] = r.correction.counts();
                format!(
                    "{} refined by a correction lattice of {cx}×{cy}×{cz} control points",
                    r.base.summary()
                )
            }
        }
    }

    /// The inverse map: the exact inverse for the identity and invertible affine maps, the
    /// inner map for an inverse, the reversed composition of inverses for a composition, and
    /// the numerical [`Inverse`] otherwise.
    ///
    /// # Errors
    /// [`DeformError::Singular`] for a singular affine map.
    pub fn inverse(self, options: volmorph_deform::InverseOptions) -> Result<Self, DeformError> {
        Ok(match self {
            AnyMap::Identity => AnyMap::Identity,
            AnyMap::Affine(a) => {
                let det = a.matrix.determinant();
                if !(det.is_finite() && det != 0.0) {
                    return Err(DeformError::Singular(format!(
                        "the affine map has determinant {det} and no inverse"
                    )));
                }
                let m = a.matrix.inverse();
                AnyMap::Affine(Affine {
                    matrix: m,
                    offset: -(m * a.offset),
                })
            }
            AnyMap::Inverse(i) => i.map().clone(),
            AnyMap::Compose(ms) => AnyMap::Compose(
                ms.into_iter()
                    .rev()
                    .map(|m| m.inverse(options))
                    .collect::<Result<_, _>>()?,
            ),
            other => AnyMap::Inverse(Box::new(Inverse::new(other, options))),
        })
    }

    /// The composition `then ∘ self` (self first), flattening nested compositions.
    #[must_use]
    pub fn then(self, then: AnyMap) -> AnyMap {
        let mut list = match self {
            AnyMap::Compose(ms) => ms,
            AnyMap::Identity => Vec::new(),
            m => vec![m],
        };
        match then {
            AnyMap::Compose(ms) => list.extend(ms),
            AnyMap::Identity => {}
            m => list.push(m),
        }
        match list.len() {
            0 => AnyMap::Identity,
            1 => list.pop().unwrap_or(AnyMap::Identity),
            _ => AnyMap::Compose(list),
        }
    }

    /// The map as a `&dyn SpaceMap` (the variant's own fast paths are kept).
    #[must_use]
    pub fn as_space_map(&self) -> &dyn SpaceMap {
        match self {
            AnyMap::Identity => &Identity,
            AnyMap::Affine(m) => m,
            AnyMap::Lattice(m) => m,
            AnyMap::AffineMls(m) => m,
            AnyMap::SimilarityMls(m) => m,
            AnyMap::RigidMls(m) => m,
            AnyMap::FrameMls(m) => m,
            AnyMap::ThinPlate(m) => m,
            AnyMap::Wendland(m) => m,
            AnyMap::Bump(m) => m,
            AnyMap::Geometry(m) => m,
            AnyMap::Sampled(m) => m,
            AnyMap::DisplacementField(m) => m,
            AnyMap::Compose(_) => self,
            AnyMap::Inverse(m) => m.as_ref(),
            AnyMap::Refined(m) => m.as_ref(),
        }
    }
}

impl SpaceMap for AnyMap {
    fn apply(&self, p: DVec3) -> DVec3 {
        match self {
            AnyMap::Compose(ms) => ms.iter().fold(p, |x, m| m.apply(x)),
            m => m.as_space_map().apply(p),
        }
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.apply_with_jacobian(p).1
    }

    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        match self {
            // Chain rule: J = J_n(x_{n−1}) ⋯ J_1(x_0).
            AnyMap::Compose(ms) => ms.iter().fold((p, DMat3::IDENTITY), |(x, j), m| {
                let (y, jm) = m.apply_with_jacobian(x);
                (y, jm * j)
            }),
            m => m.as_space_map().apply_with_jacobian(p),
        }
    }

    fn apply_batch(&self, points: &[DVec3], out: &mut [DVec3]) -> Result<(), DeformError> {
        match self {
            AnyMap::Compose(ms) => {
                volmorph_deform::map::check_len(points.len(), out.len())?;
                out.copy_from_slice(points);
                let mut tmp = vec![DVec3::ZERO; points.len()];
                for m in ms {
                    m.apply_batch(out, &mut tmp)?;
                    out.copy_from_slice(&tmp);
                }
                Ok(())
            }
            m => m.as_space_map().apply_batch(points, out),
        }
    }

    fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        match self {
            AnyMap::Compose(ms) => {
                let Some((first, rest)) = ms.split_first() else {
                    return Identity.apply_grid(grid, out);
                };
                first.apply_grid(grid, out)?;
                if rest.is_empty() {
                    return Ok(());
                }
                let mut tmp = vec![DVec3::ZERO; out.len()];
                for m in rest {
                    m.apply_batch(out, &mut tmp)?;
                    out.copy_from_slice(&tmp);
                }
                Ok(())
            }
            m => m.as_space_map().apply_grid(grid, out),
        }
    }

    fn apply_grid_part(
        &self,
        grid: &Geometry,
        part: IndexBox,
        out: &mut [DVec3],
    ) -> Result<(), DeformError> {
        match self {
            // As `apply_grid`: the first map on the grid (its part), the others pointwise.
            AnyMap::Compose(ms) => {
                let Some((first, rest)) = ms.split_first() else {
                    return Identity.apply_grid_part(grid, part, out);
                };
                first.apply_grid_part(grid, part, out)?;
                if rest.is_empty() {
                    return Ok(());
                }
                let mut tmp = vec![DVec3::ZERO; out.len()];
                for m in rest {
                    m.apply_batch(out, &mut tmp)?;
                    out.copy_from_slice(&tmp);
                }
                Ok(())
            }
            m => m.as_space_map().apply_grid_part(grid, part, out),
        }
    }

    fn jacobian_grid(&self, grid: &Geometry, out: &mut [DMat3]) -> Result<(), DeformError> {
        match self {
            AnyMap::Compose(_) => volmorph_deform::map::jacobian_grid_pointwise(self, grid, out),
            m => m.as_space_map().jacobian_grid(grid, out),
        }
    }
}

macro_rules! from_map {
    ($($t:ty => $v:ident),* $(,)?) => {
        $(impl From<$t> for AnyMap {
            fn from(m: $t) -> Self {
                AnyMap::$v(m)
            }
        })*
    };
}

from_map!(
    Affine => Affine,
    BSplineLattice => Lattice,
    AffineMls => AffineMls,
    SimilarityMls => SimilarityMls,
    RigidMls => RigidMls,
    FrameMls => FrameMls,
    ThinPlateMap => ThinPlate,
    WendlandMap => Wendland,
    BumpMap => Bump,
    GeometryMap => Geometry,
    SampledMap => Sampled,
    DisplacementField => DisplacementField,
);

impl From<Identity> for AnyMap {
    fn from(_: Identity) -> Self {
        AnyMap::Identity
    }
}

impl From<Refined<AnyMap>> for AnyMap {
    fn from(m: Refined<AnyMap>) -> Self {
        AnyMap::Refined(Box::new(m))
    }
}

impl From<Inverse<AnyMap>> for AnyMap {
    fn from(m: Inverse<AnyMap>) -> Self {
        AnyMap::Inverse(Box::new(m))
    }
}
