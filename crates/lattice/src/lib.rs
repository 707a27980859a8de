//! volmorph-lattice: B-spline, NURBS and Bézier lattice maps (True 1992; Sederberg–Parry FFD;
//! Feng et al. 2002's initial volumes).
//!
//! * [`BSplineLattice`] with its [`LatticeFrame`] — trivariate lattice maps with physical
//!   control points (True 1992 §4, §5.5), identity placements, analytic Jacobians, behaviour
//!   outside the box ([`lattice`] states the conventions), fast dense evaluation on voxel grids
//!   ([`grid`], True §5.2: separable per-axis tables and True's coefficient table, reusable
//!   across control-point edits as [`grid::LatticeGridPlan`]s) and a JSON form ([`json`]).
//! * [`batch`] — the vectorised batch kernel of polynomial lattices (vertex FFD), bit for bit
//!   the pointwise evaluation.
//! * [`jacobian`] — one-pass image-and-Jacobian of a lattice at a point and the separable
//!   Jacobian path on voxel grids.
//! * [`formats`] — cubic lattices as ITK `BSplineTransform` files (`.tfm`) and plastimatch
//!   `.bxf` files, with the displacement-coefficient conventions of each.
//! * [`live`] — a lattice as a [`volmorph_deform::LinearMap`]: linear in its control points,
//!   with the local [`volmorph_deform::Influence`] of each.
//! * [`manipulate`] — direct manipulation (True 1992 §6, after Hsu): drag points of the model
//!   and move the control points by the least-norm amounts that land them exactly, with a tool
//!   radius, a frozen-boundary option and an undo/redo [`manipulate::ManipulationSession`].
//!
//! Every lattice is a [`volmorph_deform::SpaceMap`]; errors are [`volmorph_deform::DeformError`],
//! the error of every map.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_deform::SpaceMap;
//! use volmorph_lattice::BSplineLattice;
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

pub mod batch;
pub mod formats;
pub mod grid;
pub mod jacobian;
pub mod json;
pub mod lattice;
pub mod live;
pub mod manipulate;
pub mod tool;

pub use lattice::{BSplineLattice, FengForm, LatticeFrame};
pub use manipulate::{
    Drag, DragError, DragOptions, DragSolution, ManipulationSession, drags_from_deformed,
    solve_drags,
};
pub use tool::{CurveStep, Realm, ToolShape, curve_drag_steps};
