//! volmorph-deform: mappings of physical space and the lattices that define them.
//!
//! * [`SpaceMap`] — the one trait every deformation implements: `apply`, `jacobian`,
//!   `apply_with_jacobian`, `apply_batch` and the grid entry points `apply_grid` and
//!   `jacobian_grid`. The trait has no direction; see
//!   [`map`] for push-forward versus pull-back.
//! * [`Identity`], [`Affine`], [`Compose`] — elementary maps and composition (`Compose(a, b)`
//!   applies `b` first).
//! * [`BSplineLattice`] with its [`LatticeFrame`] — trivariate B-spline and Bézier lattice
//!   maps with physical control points (True 1992 §4, §5.5; Sederberg–Parry FFD), identity
//!   placements, analytic Jacobians, behaviour outside the box ([`lattice`] states the
//!   conventions), fast dense evaluation on voxel grids ([`grid`], True §5.2: separable
//!   per-axis tables and True's coefficient table, reusable across control-point edits as
//!   [`grid::LatticeGridPlan`]s) and a JSON form ([`json`]).
//! * [`jacobian`] — one-pass image-and-Jacobian of a lattice at a point and the separable
//!   Jacobian path on voxel grids ([`SpaceMap::jacobian_grid`]).
//! * [`inverse`] — point inversion `φ(x) = y` by damped Newton iteration ([`invert_point`]),
//!   which turns a push-forward map into the pull-back a renderer needs.
//! * [`formats`] — cubic lattices as ITK `BSplineTransform` files (`.tfm`) and plastimatch
//!   `.bxf` files, with the displacement-coefficient conventions of each.
//! * [`manipulate`] — direct manipulation (True 1992 §6, after Hsu): drag points of the model
//!   and move the control points by the least-norm amounts that land them exactly, with a tool
//!   radius, a frozen-boundary option and an undo/redo [`manipulate::ManipulationSession`].
//!
//! * Handle-driven maps: [`mls`] (affine, similarity and rigid moving least squares through
//!   point handles in 3D, frame-based MLS; McPhail's thesis ch. 4–5), [`volume_spline`]
//!   (Savchenko's volume splines on Green's function in 2D and 3D, with scalar or vector values,
//!   and the [`ThinPlateMap`] built on them), [`bump`] (Bryson's bump transform), [`mls2d`]
//!   (2D MLS through points and line segments, for images), [`handles`] (handle files) and
//!   [`realtime`] (coarse sampled maps with per-node coefficients, updated by one multiply-add
//!   per node when a target handle moves).
//!
//! Physical coordinates follow the ITK convention of [`volmorph_volume::Geometry`]:
//! `physical = origin + direction·(spacing ⊙ index)`, voxels x fastest.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_deform::{BSplineLattice, SpaceMap};
//! use volmorph_volume::Geometry;
//! // An identity lattice leaves every voxel centre where it is.
//! let lat = BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(8.0), [5, 7, 4])
//!     .unwrap();
//! let grid = Geometry::new([9, 9, 9]);
//! let mut out = vec![DVec3::ZERO; grid.len()];
//! lat.apply_grid(&grid, &mut out).unwrap();
//! for (n, p) in out.iter().enumerate() {
//!     let x = DVec3::new((n % 9) as f64, (n / 9 % 9) as f64, (n / 81) as f64);
//!     assert!((*p - x).length() <= 1e-12 * x.length().max(1.0));
//! }
//! ```

pub mod bump;
mod error;
pub mod formats;
pub mod grid;
pub mod handles;
pub mod inverse;
pub mod jacobian;
pub mod json;
pub mod lattice;
pub mod manipulate;
pub mod map;
pub mod mls;
pub mod mls2d;
pub mod realtime;
pub mod volume_spline;

pub use bump::BumpMap;
pub use error::DeformError;
pub use handles::HandleSet;
pub use inverse::{InverseOptions, InverseStatus, PointInverse, invert_point};
pub use lattice::{BSplineLattice, LatticeFrame};
pub use manipulate::{
    Drag, DragError, DragOptions, DragSolution, ManipulationSession, solve_drags,
};
pub use map::{Affine, Compose, Identity, SpaceMap};
pub use mls::{AffineMls, Frame, FrameMls, RigidMls, SimilarityMls, Weighting};
pub use realtime::{HandleGrid, LinearHandleMap, SampledMap};
pub use volume_spline::{ThinPlateMap, VolumeSpline, VolumeSplineSystem};
