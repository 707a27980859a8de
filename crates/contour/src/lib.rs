//! Isosurfaces of sampled volumes for volmorph.
//!
//! [`marching_cubes`] (and [`marching_cubes_any`] for run-time voxel types) extracts the
//! surface `value = level` of a [`Volume`](volmorph_volume::Volume) as an indexed triangle
//! [`Mesh`](volmorph_mesh::Mesh) in **physical coordinates**, with outward per-vertex normals
//! from the field's gradient — the marching-cubes step True 1992 (§5.6) uses to display
//! warped voxmaps.
//!
//! Conventions:
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

mod error;
mod marching;
mod table;

pub use error::ContourError;
pub use marching::{EDGE_MARGIN, IsoSurface, McOptions, marching_cubes, marching_cubes_any};
