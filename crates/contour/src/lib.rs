//! Isosurfaces of sampled volumes for volmorph.
//!
//! [`marching_cubes`] (and [`marching_cubes_any`] for run-time voxel types) extracts the
//! surface `value = level` of a [`Volume`](volmorph_volume::Volume) as an indexed triangle
//! [`Mesh`](volmorph_mesh::Mesh) in **physical coordinates**, with outward per-vertex normals
//! from the field's gradient — the marching-cubes step True 1992 (§5.6) uses to display
//! warped voxmaps.
//!
//! [`dual_contouring`] (and [`dual_contouring_any`]) extracts the same surface by dual
//! contouring on the field's Hermite data (edge crossings and gradient normals), as McPhail
//! contours volumetric edits (§3.5.1): one vertex per crossed cell, at the mass point of its
//! crossings where the surface is smooth and at the minimiser of the quadratic error function
//! ([`Qef`]) where the cell holds a sharp edge or corner ([`DcOptions::feature_angle`]), so
//! that sharp features survive instead of being rounded off.
//!
//! Conventions (both extractors):
//! * **Inside** is `value ≥ level` by default (densities, CT);
//!   [`McOptions::inside_below`] makes it `value ≤ level` (signed distances, negative
//!   inside). Samples exactly at the level are inside; NaN samples are outside.
//! * **Orientation:** triangles are counter-clockwise seen from outside, so their
//!   right-hand-rule normals point from the inside to the outside, also for mirrored
//!   geometries (negative direction determinant).
//! * **Topology:** one shared vertex per crossed grid edge, a case table whose choice on
//!   ambiguous faces depends on the face alone (crack-free), no degenerate triangles. A
//!   level set that stays off the volume boundary gives a closed, outward-oriented
//!   2-manifold.
//!
//! ```
//! use volmorph_contour::{McOptions, marching_cubes};
//! use volmorph_volume::phantom::{self, Phantom};
//!
//! // The sphere phantom's signed distance on a 24³ grid; the solid is where it is ≤ 0.
//! let sdf = phantom::signed_distance(Phantom::Sphere, [24, 24, 24])?;
//! let options = McOptions { inside_below: true };
//! let surface = marching_cubes(&sdf, 0.0, &options)?;
//! let report = surface.mesh.validate();
//! assert!(report.is_closed_manifold());
//! assert_eq!(report.euler_characteristic, 2);
//! assert_eq!(surface.normals.len(), surface.mesh.positions().len());
//! // Outward orientation: the enclosed volume is positive, close to that of the ball.
//! let r = phantom::SPHERE_RADIUS;
//! let ball = 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
//! assert!((surface.mesh.signed_volume() / ball - 1.0).abs() < 0.03);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Dual contouring keeps the corners of a cube:
//!
//! ```
//! use glam::DVec3;
//! use volmorph_contour::{DcOptions, dual_contouring};
//! use volmorph_volume::{Geometry, Volume};
//!
//! // Exact signed distance to the cube [2.5, 8.5]³ (index units) on a 12³ grid.
//! let cube = Volume::from_fn(Geometry::new([12, 12, 12]), |i, j, k| {
//!     let d = (DVec3::new(i as f64, j as f64, k as f64) - DVec3::splat(5.5)).abs() - 3.0;
//!     d.max(DVec3::ZERO).length() + d.max_element().min(0.0)
//! })?;
//! let options = DcOptions { inside_below: true, ..DcOptions::default() };
//! let surface = dual_contouring(&cube, 0.0, &options)?;
//! assert!(surface.mesh.validate().is_closed_manifold());
//! // A vertex sits on the corner (2.5, 2.5, 2.5), where marching cubes would cut it off.
//! let corner = DVec3::splat(2.5);
//! let nearest = surface.mesh.positions().iter().map(|p| p.distance(corner)).fold(f64::MAX, f64::min);
//! assert!(nearest < 1e-6);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod dual;
mod error;
mod marching;
mod qef;
mod scan;
mod table;

pub use dual::{
    DEFAULT_FEATURE_ANGLE, DcOptions, QuadDiagonal, VertexRule, clamp_to_cell, dual_contouring,
    dual_contouring_any, dual_contouring_any_with, dual_contouring_with, flatness, quad_diagonal,
};
pub use qef::{DEFAULT_SINGULAR_THRESHOLD, Qef, QefSolution, symmetric_eigen};

pub use error::ContourError;
pub use marching::{
    EDGE_MARGIN, IsoSurface, McOptions, marching_cubes, marching_cubes_any,
    marching_cubes_any_with, marching_cubes_with,
};
pub use table::{mc_case_triangles, mc_corner_offset, mc_edge_corners};
