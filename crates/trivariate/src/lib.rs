//! volmorph-trivariate: trivariate NURBS volumes carrying attribute volumes
//! (Martin & Cohen, "Representation and Extraction of Volumetric Attributes Using Trivariate
//! Splines", §2–§5).
//!
//! * [`Aggregate`] ([`AggregateCurve`], [`AggregateSurface`], [`AggregateVolume`]) — a geometry
//!   spline in R³ plus named attribute splines, each with its own order, knots and control
//!   net, on the shared domain `[0, 1]^N` ([`aggregate`] states the conventions).
//! * [`extrude`], [`revolve`], [`rule`] — modeling operators lifting curves to surfaces and
//!   surfaces to volumes, carrying attributes along ([`modeling`]).
//! * [`recipe`] — modeling recipes: curves, attributes and the §3 operators as a versioned JSON
//!   document built into a model ([`Recipe`], [`build_recipe_file`]).
//! * [`format`](mod@format) — the documented JSON file format with [`load`] / [`save`].
//! * [`fit`] — interpolation at the Greville abscissae and separable least squares (§3).
//! * [`VolumeEvaluator`] — points and first partial derivatives by knot refinement (the α
//!   scheme of §4) or de Boor, per point or in rayon batches ([`eval`]).
//! * [`invert`](mod@invert) — physical point → parameters by Newton with a subdivision fallback.
//! * [`extract`] — the zero finding of §5.1: the scalar spline `D` of an isosurface or planar
//!   slice, and root isolation by Bézier subdivision ([`isolate_roots`]).
//! * [`isosurface`](mod@isosurface) — crack-free polygonisation of isosurfaces ([`isosurface()`])
//!   and planar slices ([`slice()`]) with per-vertex parameters and attribute values, written as
//!   coloured PLY or OBJ.
//! * [`GeometryMap`] — the geometry as a [`volmorph_deform::SpaceMap`] on a placement box,
//!   so volumes, meshes and F-rep shapes can be deformed by a NURBS solid ([`space_map`]).
//! * [`RayTracer`] — ray–boundary intersection (faces and `det J = 0`, Theorem 1, with
//!   [`cone`] culling) and parameter tracking along rays (§5.2, [`raytrace`]).
//! * [`VolumeRenderer`] — front-to-back volume rendering of an attribute through
//!   [`TransferFunction`]s ([`volrender`]); [`SceneRenderer`] composites several volumes,
//!   each with its own attribute and transfer function, in one picture (§5.4).
//! * [`trace_optical_path`] — bent rays through a refractive-index attribute (§5.3,
//!   [`optics`]: the paper's Snell stepping, its ray-equation form, and the default adaptive
//!   Dormand–Prince integrator of the ray equation); [`exact_back_focal_distance`] is the GRIN
//!   lens's exact meridional trace; [`grin_lens`] builds the gradient-index lens example ([`examples`]);
//!   [`RayFan`]s of parallel rays, the measured back focal distance and the side view of the
//!   paths ([`ray_fan`]).
//!
//! The spline machinery (knot vectors, bases, refinement, Greville interpolation) is
//! `volmorph_spline`'s; this crate builds on it.

pub mod aggregate;
mod bounds;
pub mod cone;
mod error;
pub mod eval;
pub mod examples;
pub mod extract;
pub mod fit;
pub mod format;
pub mod invert;
pub mod isosurface;
pub mod modeling;
pub mod optics;
pub mod ray_fan;
pub mod raytrace;
pub mod recipe;
pub mod space_map;
pub mod volrender;

pub use aggregate::{
    Aggregate, AggregateCurve, AggregateSurface, AggregateVolume, Attribute, GEOMETRY_DIM,
};
pub use error::TrivariateError;
pub use eval::{EvalMethod, VolumeEvaluator};
pub use examples::{
    ExactFocus, GRIN_ATTRIBUTE, GrinLensSpec, ParaxialFocus, exact_back_focal_distance, grin_lens,
    grin_lens_recipe, paraxial_focus,
};
pub use extract::{
    RootCell, RootOptions, isolate_roots, isolate_roots_with, isosurface_function, plane_function,
};
pub use format::{AnyAggregate, load, load_volume, save};
pub use invert::{InversionOptions, invert};
pub use isosurface::{
    Coloring, PolygonizeOptions, ZeroSetMesh, isosurface, isosurface_with, slice, slice_with,
};
pub use modeling::{extrude, revolve, rule};
pub use optics::{
    OpticalPath, OpticsOptions, PathMethod, draw_paths, reference_options, refract,
    trace_optical_path, write_paths_obj,
};
pub use ray_fan::{
    FocusMeasurement, GrinLensCheck, RayFan, check_grin_lens, measured_back_focal_distance,
    side_view,
};
pub use raytrace::{BoundaryHit, HitKind, RayTracer, TraceOptions, Tracked};
pub use recipe::{Recipe, build_recipe_file, load_recipe};
pub use space_map::GeometryMap;
pub use volrender::{
    RayColor, RenderOptions, SceneRenderer, TransferFunction, TransferPoint, VolumeRenderer,
};
