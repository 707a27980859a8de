//! Depth-peel sculpting of closed meshes (McPhail, *Real-time volumetric data*, chapter 3):
//! Booleans with any closed mesh as a tool, painting strokes, partial-volume smoothing, and
//! local re-contouring stitched into the untouched mesh.
//!
//! # The representation (§3.3)
//!
//! * [`depth_peel_axis`] / [`depth_peel_perspective`] — a CPU depth peeler: per ray (pixel)
//!   of a view, every crossing of a closed mesh, sorted, with its unit outward normal and
//!   whether the ray enters or leaves the solid ([`Crossing`], [`DepthPeelImage`]). Coverage
//!   is exact and watertight ([`FRACTION_BITS`]), so rays through shared edges and vertices
//!   never gain or lose a crossing.
//! * [`TriDexel`] — three orthographic depth peels along x, y and z whose rays meet at the
//!   points of one uniform [`Grid`]; [`TriDexel::vote`] classifies a grid point by the
//!   majority of the three views (§3.3.2). Its size grows with the surface, not the volume.
//! * [`FrozenView`] — the user's [`PerspectiveView`] frozen for editing: its depth peel is
//!   updated dab by dab, and [`FrozenView::grid`] is the view-dependent grid of
//!   Algorithm 3.1.
//!
//! # Edits (§3.4)
//!
//! [`SculptDocument::apply`] performs an [`Edit`]:
//!
//! * [`Edit::Tool`] — [`Op::Add`], [`Op::Subtract`] or [`Op::Intersect`] with a closed
//!   [`Tool`] mesh placed by [`Pose`]s: one pose is a dab, several a painting stroke (the
//!   union of the tool along the poses, resampled). The tool is peeled along the grid's axes
//!   — convex tools in two layers without sorting — and each ray of the document is painted
//!   with the tool's ray ([`combine`], Algorithm 3.2).
//! * [`Edit::Smooth`] — partial-volume smoothing of a box ([`SmoothRegion`]), blended into
//!   the surroundings over three kernel widths.
//!
//! Each edit returns an [`EditRecord`] that [`SculptDocument::undo`] takes back and
//! [`SculptDocument::redo`] performs again, bit for bit, with the [`ChangedRegion`] (dexel
//! index box, re-contoured box, physical box) a view needs to redraw.
//!
//! # Local contouring and stitching (§3.5)
//!
//! Only the cells around what changed are contoured, from the tri-dexel's Hermite data, by
//! the project's dual contouring rules ([`volmorph_contour::VertexRule`],
//! [`volmorph_contour::quad_diagonal`]) with one vertex per sheet of surface in a cell, so
//! the patch is a 2-manifold even where plain dual contouring is not. The old triangles
//! meeting the box are cut at its faces, and the patch is joined to them along the cut
//! (fans from the boundary cells' vertices, then edge collapses that keep a closed
//! manifold). Every other triangle keeps its index and its vertices' coordinates exactly.
//!
//! [`run_job`] runs one sculpting job (tool edit and/or smoothing on a fitted grid) for
//! front-ends.
//!
//! # Conventions
//!
//! Physical coordinates in the meshes' own unit; depths along an orthographic ray are
//! physical coordinates along its axis. Meshes are closed, consistently oriented
//! 2-manifolds, counter-clockwise seen from outside (inside-out meshes are turned around).
//! The solid is where the mesh winds around a point a positive number of times. A grid point
//! exactly on a surface counts as inside when the surface is entered there (intervals are
//! closed at the entering end). The outermost grid points are always outside: tools are cut
//! half a cell inside the grid's border.
//!
//! ```
//! use std::sync::Arc;
//! use volmorph_mesh::DVec3;
//! use volmorph_mesh::shapes::icosphere;
//! use volmorph_sculpt::{Edit, Op, Pose, SculptDocument, SculptOptions, Tool};
//!
//! // A sphere on a 48³ grid, carved by a smaller sphere.
//! let base = icosphere(4, 1.0, DVec3::ZERO)?;
//! let mut doc = SculptDocument::around(&base, 48, 2.0, SculptOptions::default())?;
//! let brush = Arc::new(Tool::new(&icosphere(2, 0.3, DVec3::ZERO)?)?);
//! let record = doc.apply(&Edit::Tool {
//!     tool: brush,
//!     op: Op::Subtract,
//!     poses: vec![Pose::at(DVec3::new(0.9, 0.0, 0.2))],
//!     step: None,
//! })?;
//! let carved = doc.mesh()?;
//! assert!(carved.validate().is_closed_manifold());
//! assert!(carved.signed_volume() < base.signed_volume());
//! // Only the triangles near the dab were replaced.
//! let stats = record.stats();
//! assert!(stats.triangles_removed < stats.triangles_kept / 10);
//! // Undo restores the document exactly.
//! doc.undo(&record)?;
//! assert_eq!(doc.mesh()?.face_count(), base.face_count());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod brush;
mod cells;
mod collapse;
mod cut;
mod dexel;
mod document;
mod error;
mod exact;
mod grid;
mod interval;
mod job;
mod peel;
mod smooth;
mod stitch;
mod store;
mod stroke;
mod tool;
mod view;

pub use brush::{BrushShape, SPHERE_BRUSH_LEVEL, brush, unit_brush};
pub use dexel::{BitVolume, TriDexel};
pub use document::{
    ChangedRegion, DEFAULT_MARGIN, DEFAULT_MAX_DABS, Edit, EditRecord, EditStats, EditTimings,
    SculptDocument, SculptOptions,
};
pub use error::SculptError;
pub use exact::FRACTION_BITS;
pub use grid::{GRID_OFFSET, Grid, MAX_GRID_POINTS, MIN_GRID_POINTS, PointBox, transverse};
pub use interval::{Op, combine, inside_at, is_clean};
pub use job::{DEFAULT_GRID_POINTS, JOB_MARGIN, Job, JobReport, ToolEdit, run_job, run_job_with};
pub use peel::{
    Crossing, DepthPeelImage, MAX_VIEW_PIXELS, PerspectiveView, TriangleSoup, depth_peel_axis,
    depth_peel_perspective,
};
pub use smooth::{MAX_KERNEL, SmoothRegion};
pub use stroke::{MAX_STROKE_BYTES, Stroke};
pub use tool::{CONVEXITY_TOLERANCE, Pose, Tool, closed_soup, resample_stroke};
pub use view::FrozenView;
