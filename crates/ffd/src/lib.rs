//! volmorph-ffd: free-form deformation of polygon meshes (Feng et al. 2002 and the baselines it
//! is compared with). Every function **pushes forward**: model points go to `map(x)`.
//!
//! * [`baseline`] — vertex FFD (Sederberg–Parry with a Bézier lattice or any B-spline
//!   lattice), uniform midpoint subdivision, adaptive subdivision by the mid-edge error test.
//! * [`accurate`] — the accurate FFD: [`accurate::AccuratePlan`] (repair, knot-plane
//!   subdivision, coplanar grouping with ε_n = 2.2e-8 / ε_d = 1.1e-6, Table 1 frames and
//!   degrees, trimming loops, shared edges) and [`accurate::TrimmedModel`] (Bézier patches by
//!   two-stage interpolation in each patch's own knot cell, exact edge curves, surface area).
//! * [`polygon`] — checking and repairing input faces (NaN, degenerate, non-convex, non-planar).
//! * [`subdivide`] — robust subdivision by knot planes (singular cases of Fig. 5).
//! * [`frame`] — Table 1: local frame `(s, t, n)` and surface degrees per plane.
//! * [`interp`] — precomputed inverse Bernstein collocation matrices up to degree 12.
//! * [`step`] — STEP AP214 export (advanced faces, shared edge curves with pcurves, shells).
//! * [`tessellate`] — watertight tessellation to a chordal tolerance.
//! * [`shapes`] — generated models for tests and benchmarks.
//!
//! The initial lattices of §3.1 are [`volmorph_lattice::BSplineLattice::feng_uniform_around`]
//! and [`volmorph_lattice::BSplineLattice::feng_end_interpolating_around`].
//!
//! ```
//! use std::sync::Arc;
//! use volmorph_lattice::BSplineLattice;
//! use volmorph_ffd::accurate::AccuratePlan;
//! use volmorph_mesh::{DVec3, Mesh};
//! // One square, a degree-2 lattice of 4×4×4 control points around it.
//! let square = Mesh::from_polygons(
//!     vec![DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y],
//!     [[0u32, 1, 2, 3]],
//! )?;
//! let mut lat = BSplineLattice::feng_end_interpolating_around(
//!     DVec3::new(0.0, 0.0, -0.5), DVec3::new(1.0, 1.0, 0.5), [2, 2, 2], [4, 4, 4])?;
//! lat.move_control_point([1, 1, 2], DVec3::new(0.0, 0.0, 0.3))?;
//! let plan = Arc::new(AccuratePlan::new(&square, &lat)?);
//! assert_eq!(plan.stats().sub_polygons, 4); // cut by the knot planes x = 0.5 and y = 0.5
//! let model = plan.deform(&lat)?;
//! assert_eq!(model.surfaces.len(), 4);
//! assert!(model.surface_area() > 1.0); // the bulge adds area
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod error;

pub mod accurate;
pub mod baseline;
pub mod frame;
pub mod interp;
pub mod polygon;
pub mod shapes;
pub mod step;
pub mod subdivide;
pub mod tessellate;

pub use error::FfdError;
