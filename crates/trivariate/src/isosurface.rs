//! Isosurfaces and planar slices of aggregate volumes as polygon meshes (Martin & Cohen §5.1).
//!
//! [`isosurface`] meshes `{P(u) : A(u) = A*}` for a scalar attribute `A`; [`slice()`] meshes the
//! region of the plane `(a, b, c, d)·(x, 1) = 0` inside the volume, `{P(u) : (a,b,c)·P(u) + d
//! = 0}`, and reports an attribute on it. Both follow the paper: the scalar spline `D` of
//! [`crate::extract`] is built, its zeros are isolated by Bézier subdivision
//! ([`isolate_roots`](crate::isolate_roots)), the geometry is refined over the root cells, refined further where a
//! flatness criterion asks for it, and polygonised.
//!
//! # Polygonisation (crack-free by construction)
//!
//! 1. **Elements.** The breakpoints of `D` and of the geometry are merged per axis; the geometry
//!    and `D` are refined at the merged breakpoints (knot refinement) and split into Bézier
//!    pieces, one per *element* (box of consecutive merged breakpoints). An element is *active*
//!    when it overlaps a root cell in its interior; only active elements can hold the zero set.
//! 2. **Flatness.** For an active element and axis `a`, the piecewise multilinear interpolant of
//!    a Bézier piece of degree `p` sampled at `n` steps deviates from it by at most
//!    `p(p−1)/8 · max‖Δ²_a‖ / n²` per axis (second differences of the control net along `a`,
//!    the Bézier chord bound). The criterion adds the geometry's bound `G_a` and the positional
//!    error of the zero set, `S · E_a / g`, where `E_a` is the same bound for `D`, `g` the
//!    magnitude of `D`'s gradient at the element centre (in element-local parameters) and `S` the
//!    largest speed `p_a·max‖ΔP‖` of the geometry net, and takes the smallest `n_a` with
//!    `Σ_a (G_a + S·E_a/g)/n_a² ≤ tolerance` (split evenly over the axes), capped at
//!    [`MAX_STEPS_PER_ELEMENT`]. For rational geometry the Cartesian control points are used
//!    (exact for constant weights, an estimate otherwise).
//! 3. **Lattice.** Axis `a` is sampled by one **global rectilinear lattice**: merged interval `j`
//!    is cut into `n_a(j)` equal steps, the largest `n_a` any active element in that slab needs
//!    (one step where none is active). Resolution therefore varies per element along each axis
//!    but neighbouring cells always share whole faces: there are no T-junctions.
//! 4. **Cells.** `D` is evaluated at every lattice node (precomputed basis tables, rayon over
//!    slabs); a node is *inside* when `D < 0` (`A < A*`, or the negative side of the plane).
//!    Each lattice cell is polygonised with volmorph's marching-cubes case table
//!    ([`volmorph_contour::mc_case_triangles`]). A crossing vertex belongs to a lattice
//!    **edge**, identified globally by (node, axis), and is computed once for all cells sharing
//!    the edge — so the mesh is crack-free and, away from the domain boundary, watertight.
//! 5. **Vertices.** Each crossing is moved onto the zero set by a safeguarded Newton iteration
//!    along its edge on the Cartesian function (`A(u) − A*`, or `(a,b,c)·P(u) + d`): Newton
//!    steps inside the sign bracket, bisection otherwise, until the residual is below
//!    [`VERTEX_RESIDUAL`] relative to the attribute's control-value range (isosurface) or to
//!    `|(a,b,c)|` times the geometry's bounding-box diagonal (slice).
//!
//! Triangles are wound counter-clockwise seen from the *outside* of the solid, in physical
//! space: for isosurfaces the solid is where the attribute is at or above the level (smaller
//! values outside; [`PolygonizeOptions::inside_below`] reverses this for distance-like
//! attributes), for slices the outside is the side the plane normal `(a, b, c)` points to. The
//! winding is also flipped when the geometry's Jacobian determinant is negative at the domain
//! centre (a mirrored parametrisation).
//!
//! The lattice resolves the zero set to the flatness tolerance; features thinner than one
//! lattice step (which root isolation does find) may be missed by the sign sampling.

use rayon::prelude::*;
use volmorph_contour::{mc_case_triangles, mc_corner_offset, mc_edge_corners};
use volmorph_mesh::DVec3;
use volmorph_mesh::Mesh;
use volmorph_spline::{BasisTable, BezierCell, KnotVector, TensorBSpline};

use crate::error::ctx;
use crate::extract::{
    RootOptions, check_plane, isolate_roots_with, isosurface_function, plane_function,
};
use crate::{AggregateVolume, TrivariateError};

/// Default flatness tolerance relative to the geometry's bounding-box diagonal (the diagonal
/// of the box of its control points, which contains the volume).
pub const DEFAULT_RELATIVE_TOLERANCE: f64 = 1e-3;

/// Largest number of lattice steps along one axis of one element. With the chord bound
/// `∝ 1/n²`, 64 steps reduce an element's deviation 4096-fold; finer demands mean a tolerance
/// far below the model's own accuracy.
pub const MAX_STEPS_PER_ELEMENT: usize = 64;

/// Largest number of lattice nodes (`2²⁶`; about 17 bytes per node are held while
/// polygonising, so at most about 1.1 GB): enough for the default tolerance on a CT fitted with
/// a fine control net (a 256×256×108 CT with 24³ control points needs 42 M nodes and 0.7 GB);
/// beyond it a larger tolerance is asked for.
pub const MAX_LATTICE_NODES: usize = 1 << 26;

/// Relative residual at which a vertex counts as on the zero set: `1e-13` of the attribute's
/// control-value range (isosurfaces) or of `|(a,b,c)|·diagonal` (slices), three orders below the
/// `1e-9` accuracy promised to callers, a few hundred ulps above f64 rounding of the sums.
pub const VERTEX_RESIDUAL: f64 = 1e-13;

/// Largest number of Newton/bisection steps per vertex: bisection alone halves the bracket
/// each step, so 200 steps reach the f64 resolution of any edge.
const MAX_VERTEX_STEPS: usize = 200;

/// Crossing edges solved per progress step (and per parallel task) when placing vertices:
/// enough Newton solves that one progress update per chunk costs nothing measurable.
const VERTEX_CHUNK: usize = 256;

/// Options of [`isosurface`] and [`slice()`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolygonizeOptions {
    /// Flatness tolerance in physical length units (finite, `> 0`); `None` uses
    /// `relative_tolerance` times the geometry's bounding-box diagonal.
    pub tolerance: Option<f64>,
    /// Flatness tolerance relative to the bounding-box diagonal when `tolerance` is `None`
    /// (finite, `> 0`). Default [`DEFAULT_RELATIVE_TOLERANCE`].
    pub relative_tolerance: f64,
    /// Options of the root isolation.
    pub roots: RootOptions,
    /// Isosurfaces only: the solid is where the attribute is at or *below* the level
    /// (distances, negative inside), so triangles face larger values. By default (`false`) the
    /// solid is where it is at or above the level (densities, CT numbers), as for
    /// `volmorph isosurface`, and triangles face smaller values.
    pub inside_below: bool,
}

impl Default for PolygonizeOptions {
    fn default() -> Self {
        Self {
            tolerance: None,
            relative_tolerance: DEFAULT_RELATIVE_TOLERANCE,
            roots: RootOptions::default(),
            inside_below: false,
        }
    }
}

/// A polygonised zero set (isosurface or slice region) with per-vertex parameters and attribute
/// values.
#[derive(Debug, Clone, PartialEq)]
pub struct ZeroSetMesh {
    /// Triangle mesh in physical coordinates (`mesh.positions()[i] = P(params[i])`).
    pub mesh: Mesh,
    /// Parameters `u ∈ [0, 1]³` of each vertex.
    pub params: Vec<[f64; 3]>,
    /// The reported attribute's value at each vertex (`A(params[i])`); empty when no attribute
    /// was requested.
    pub values: Vec<f64>,
    /// Per-triangle average of `values` over the triangle's three vertices (the per-polygon
    /// colouring of §5.1); empty when `values` is.
    pub face_values: Vec<f64>,
    /// Name of the reported attribute, if any.
    pub attribute: Option<String>,
    /// Number of root cells the subdivision search returned.
    pub root_cells: usize,
    /// Lattice nodes per axis.
    pub lattice: [usize; 3],
    /// The flatness tolerance used, in physical units.
    pub tolerance: f64,
}

/// Colouring of a written [`ZeroSetMesh`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coloring {
    /// No colours: geometry (and, in PLY, parameters and attribute values) only.
    None,
    /// One colour per vertex, from the vertex's attribute value.
    PerVertex,
    /// One colour per triangle, from the triangle's average attribute value (§5.1's colouring
    /// of slices by the average value). PLY only.
    PerPolygon,
}

/// Property names used by [`ZeroSetMesh::write`] besides the attribute's own.
const RESERVED: [&str; 9] = ["x", "y", "z", "u", "v", "w", "red", "green", "blue"];

impl ZeroSetMesh {
    /// The extensions [`ZeroSetMesh::write`] writes: `.ply` and `.obj`, any case.
    pub const EXTENSIONS: &'static [&'static str] = &["ply", "obj"];

    /// Check that `path` ends in one of [`ZeroSetMesh::EXTENSIONS`] before the mesh is
    /// computed.
    ///
    /// # Errors
    /// [`TrivariateError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
    /// extension found and the accepted ones.
    pub fn check_output(path: &std::path::Path) -> Result<(), TrivariateError> {
        Ok(volmorph_io::extension::check(path, Self::EXTENSIONS)?)
    }

    /// PLY property name of the attribute: its name with every byte that is not printable
    /// ASCII replaced by `_`, or `attribute` when that would clash with a standard property.
    fn property_name(&self) -> String {
        let raw = self.attribute.as_deref().unwrap_or("attribute");
        let s: String = raw
            .chars()
            .map(|c| if c.is_ascii_graphic() { c } else { '_' })
            .collect();
        if s.is_empty() || RESERVED.contains(&s.as_str()) || s == "vertex_indices" {
            "attribute".into()
        } else {
            s
        }
    }

    /// Write the mesh to `path`, atomically, in the format its extension names:
    ///
    /// * `.ply` (binary little-endian): vertices `double x y z`, `double u v w` (parameters),
    ///   the attribute as `float <name>` (when values exist) and `uchar red green blue` with
    ///   [`Coloring::PerVertex`]; faces `vertex_indices`, plus `float <name>` (the triangle's
    ///   average) and `uchar red green blue` with [`Coloring::PerPolygon`]. `<name>` is the
    ///   attribute's name (non-printable characters replaced by `_`; `attribute` if it would
    ///   clash with a standard property).
    /// * `.obj`: `v x y z` lines, or `v x y z r g b` (channels in `[0, 1]`) with
    ///   [`Coloring::PerVertex`], and `f` lines.
    ///
    /// `color` maps an attribute value to an 8-bit sRGB colour (a colour map over a value
    /// range); it is used only when colouring.
    ///
    /// # Errors
    /// [`TrivariateError::Io`] with [`volmorph_io::IoError::Extension`] for an extension other
    /// than `.ply`/`.obj` (nothing written); [`TrivariateError::InvalidArgument`] for
    /// colouring without attribute values, or [`Coloring::PerPolygon`] with OBJ;
    /// [`TrivariateError::Io`] / [`TrivariateError::Mesh`] when writing fails.
    pub fn write(
        &self,
        path: &std::path::Path,
        coloring: Coloring,
        color: &dyn Fn(f64) -> [u8; 3],
    ) -> Result<(), TrivariateError> {
        let ext = volmorph_io::extension::matching(path, Self::EXTENSIONS)
            .ok_or_else(|| volmorph_io::extension::refused(path, Self::EXTENSIONS))?;
        if coloring != Coloring::None && self.values.is_empty() {
            return Err(TrivariateError::InvalidArgument(
                "colouring needs attribute values; name an attribute".into(),
            ));
        }
        match ext {
            "ply" => volmorph_io::write_atomic(path, |w| self.write_ply(w, coloring, color)),
            "obj" => {
                let colors: Vec<[u8; 3]> = match coloring {
                    Coloring::None => Vec::new(),
                    Coloring::PerVertex => self.values.iter().map(|&v| color(v)).collect(),
                    Coloring::PerPolygon => {
                        return Err(TrivariateError::InvalidArgument(
                            "OBJ has no per-polygon colours; write PLY or colour per vertex".into(),
                        ));
                    }
                };
                volmorph_io::write_atomic(path, |w| {
                    if colors.is_empty() {
                        volmorph_mesh::format::obj::write_obj(w, &self.mesh)?;
                    } else {
                        volmorph_mesh::format::obj::write_obj_with_colors(w, &self.mesh, &colors)?;
                    }
                    Ok::<(), TrivariateError>(())
                })
            }
            _ => unreachable!("matching returns one of EXTENSIONS"),
        }
    }

    /// Encode as binary little-endian PLY into any writer (layout of [`ZeroSetMesh::write`]).
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for colouring without values;
    /// [`TrivariateError::Mesh`] when writing fails.
    pub fn write_ply<W: std::io::Write>(
        &self,
        w: &mut W,
        coloring: Coloring,
        color: &dyn Fn(f64) -> [u8; 3],
    ) -> Result<(), TrivariateError> {
        use volmorph_mesh::format::ply::{
            PlyEncoding, PlyProperties, PlyProperty, PlyValues, write_ply_with_properties,
        };
        if coloring != Coloring::None && self.values.is_empty() {
            return Err(TrivariateError::InvalidArgument(
                "colouring needs attribute values; name an attribute".into(),
            ));
        }
        let params: [Vec<f64>; 3] =
            std::array::from_fn(|a| self.params.iter().map(|u| u[a]).collect());
        let values: Vec<f32> = self.values.iter().map(|&v| v as f32).collect();
        let face_values: Vec<f32> = self.face_values.iter().map(|&v| v as f32).collect();
        let channels = |src: &[f64]| -> [Vec<u8>; 3] {
            let rgb: Vec<[u8; 3]> = src.iter().map(|&v| color(v)).collect();
            std::array::from_fn(|c| rgb.iter().map(|x| x[c]).collect())
        };
        let vrgb = if coloring == Coloring::PerVertex {
            channels(&self.values)
        } else {
            Default::default()
        };
        let frgb = if coloring == Coloring::PerPolygon {
            channels(&self.face_values)
        } else {
            Default::default()
        };
        let name = self.property_name();
        let mut extra = PlyProperties::default();
        for (n, p) in ["u", "v", "w"].into_iter().zip(&params) {
            extra.vertex.push(PlyProperty {
                name: n,
                values: PlyValues::F64(p),
            });
        }
        if !values.is_empty() {
            extra.vertex.push(PlyProperty {
                name: &name,
                values: PlyValues::F32(&values),
            });
        }
        let rgb_names = ["red", "green", "blue"];
        if coloring == Coloring::PerVertex {
            for (n, c) in rgb_names.into_iter().zip(&vrgb) {
                extra.vertex.push(PlyProperty {
                    name: n,
                    values: PlyValues::U8(c),
                });
            }
        }
        if coloring == Coloring::PerPolygon {
            extra.face.push(PlyProperty {
                name: &name,
                values: PlyValues::F32(&face_values),
            });
            for (n, c) in rgb_names.into_iter().zip(&frgb) {
                extra.face.push(PlyProperty {
                    name: n,
                    values: PlyValues::U8(c),
                });
            }
        }
        write_ply_with_properties(
            w,
            &self.mesh,
            PlyEncoding::BinaryLittleEndian,
            false,
            &extra,
        )?;
        Ok(())
    }

    /// Report another scalar attribute of `volume` (the volume the mesh was extracted from):
    /// `values`, `face_values` and `attribute` are recomputed for `name` at the vertex
    /// parameters (e.g. to colour an isosurface of one attribute by another).
    ///
    /// # Errors
    /// [`TrivariateError::UnknownAttribute`]; [`TrivariateError::InvalidArgument`] for a
    /// non-scalar attribute; [`TrivariateError::Spline`] for parameters outside the domain.
    pub fn report_attribute(
        &mut self,
        volume: &AggregateVolume,
        name: &str,
    ) -> Result<(), TrivariateError> {
        let s = volume
            .attribute(name)
            .ok_or_else(|| TrivariateError::UnknownAttribute(name.to_owned()))?;
        check_scalar(name, s)?;
        let values: Result<Vec<f64>, TrivariateError> = self
            .params
            .par_iter()
            .map(|&u| {
                let mut v = [0.0];
                s.eval_into(u, &mut v).map_err(ctx("attribute"))?;
                Ok(v[0])
            })
            .collect();
        self.values = values?;
        self.face_values = face_averages(&self.mesh, &self.values);
        self.attribute = Some(name.to_owned());
        Ok(())
    }

    /// `[min, max]` of the vertex attribute values, or `None` without values.
    #[must_use]
    pub fn value_range(&self) -> Option<[f64; 2]> {
        let mut it = self.values.iter().copied();
        let first = it.next()?;
        Some(it.fold([first, first], |[lo, hi], v| [lo.min(v), hi.max(v)]))
    }
}

/// The function whose zeros are meshed, in Cartesian form (for the vertex iteration).
#[derive(Clone, Copy)]
enum Target<'a> {
    /// `A(u) − level`.
    Iso {
        attribute: &'a TensorBSpline<3>,
        level: f64,
    },
    /// `n·P(u) + d`.
    Plane {
        geometry: &'a TensorBSpline<3>,
        plane: [f64; 4],
    },
}

impl Target<'_> {
    /// Value and derivative along `axis` at `u`.
    fn eval(&self, u: [f64; 3], axis: usize) -> Result<(f64, f64), TrivariateError> {
        match *self {
            Self::Iso { attribute, level } => {
                let (mut v, mut g) = ([0.0], [0.0; 3]);
                attribute
                    .eval_with_gradient_into(u, &mut v, &mut g)
                    .map_err(ctx("attribute"))?;
                Ok((v[0] - level, g[axis]))
            }
            Self::Plane { geometry, plane } => {
                let (mut p, mut g) = ([0.0; 3], [0.0; 9]);
                geometry
                    .eval_with_gradient_into(u, &mut p, &mut g)
                    .map_err(ctx("geometry"))?;
                let [a, b, c, d] = plane;
                let da = &g[3 * axis..3 * axis + 3];
                Ok((
                    a * p[0] + b * p[1] + c * p[2] + d,
                    a * da[0] + b * da[1] + c * da[2],
                ))
            }
        }
    }
}

/// Bounding box diagonal of a geometry's Cartesian control points.
fn diagonal(geometry: &TensorBSpline<3>) -> f64 {
    let hd = geometry.homogeneous_dim();
    let rational = geometry.is_rational();
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for c in geometry.homogeneous_coefficients().chunks_exact(hd) {
        let w = if rational { c[3] } else { 1.0 };
        for k in 0..3 {
            lo[k] = lo[k].min(c[k] / w);
            hi[k] = hi[k].max(c[k] / w);
        }
    }
    (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
}

/// Mesh the isosurface `A(u) = level` of the scalar attribute `attribute` of `volume` (see the
/// [module docs](self)). Vertices carry their parameters and `A` there (`≈ level`).
///
/// # Errors
/// [`TrivariateError::UnknownAttribute`]; [`TrivariateError::InvalidArgument`] for a
/// non-finite `level`, a non-scalar attribute, a tolerance that is not finite and positive,
/// bad root options, or a tolerance so small that the lattice would exceed
/// [`MAX_LATTICE_NODES`]; [`TrivariateError::Spline`] for allocation bounds.
pub fn isosurface(
    volume: &AggregateVolume,
    attribute: &str,
    level: f64,
    options: &PolygonizeOptions,
) -> Result<ZeroSetMesh, TrivariateError> {
    isosurface_with(volume, attribute, level, options, &volmorph_io::NoProgress)
}

/// [`isosurface`] reporting to `progress` in three stages (root isolation per Bézier
/// element, the lattice's cell layers, the vertices placed in chunks), stopping between
/// steps when cancelled. The result equals [`isosurface`]'s bit for bit.
///
/// # Errors
/// As [`isosurface`]; [`TrivariateError::Cancelled`] when `progress` asks to stop.
pub fn isosurface_with(
    volume: &AggregateVolume,
    attribute: &str,
    level: f64,
    options: &PolygonizeOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<ZeroSetMesh, TrivariateError> {
    let a = volume
        .attribute(attribute)
        .ok_or_else(|| TrivariateError::UnknownAttribute(attribute.to_owned()))?;
    let d = isosurface_function(a, level)?;
    let target = Target::Iso {
        attribute: a,
        level,
    };
    // Residual scale: the attribute's control-value range (1 for a constant attribute).
    let range = {
        let (lo, hi) = control_range(a);
        if hi > lo { hi - lo } else { 1.0 }
    };
    polygonize(
        volume,
        &d,
        target,
        range,
        Some(attribute),
        options,
        progress,
    )
}

/// Mesh the region of the plane `{x : (a, b, c, d)·(x, 1) = 0}` inside `volume` (see the
/// [module docs](self)), reporting the scalar attribute `attribute` at the vertices (and its
/// per-triangle average) when given.
///
/// # Errors
/// [`TrivariateError::InvalidArgument`] for a non-finite plane or zero normal `(a, b, c)`, a
/// non-scalar attribute, or a bad tolerance (as [`isosurface`]);
/// [`TrivariateError::UnknownAttribute`].
pub fn slice(
    volume: &AggregateVolume,
    plane: [f64; 4],
    attribute: Option<&str>,
    options: &PolygonizeOptions,
) -> Result<ZeroSetMesh, TrivariateError> {
    slice_with(volume, plane, attribute, options, &volmorph_io::NoProgress)
}

/// [`slice()`] reporting to `progress` as [`isosurface_with`] does.
///
/// # Errors
/// As [`slice()`]; [`TrivariateError::Cancelled`] when `progress` asks to stop.
pub fn slice_with(
    volume: &AggregateVolume,
    plane: [f64; 4],
    attribute: Option<&str>,
    options: &PolygonizeOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<ZeroSetMesh, TrivariateError> {
    check_plane(plane)?;
    if let Some(name) = attribute {
        let s = volume
            .attribute(name)
            .ok_or_else(|| TrivariateError::UnknownAttribute(name.to_owned()))?;
        check_scalar(name, s)?;
    }
    let g = volume.geometry();
    let d = plane_function(g, plane)?;
    let scale = plane[..3].iter().map(|v| v * v).sum::<f64>().sqrt() * diagonal(g);
    let target = Target::Plane { geometry: g, plane };
    polygonize(volume, &d, target, scale, attribute, options, progress)
}

fn check_scalar(name: &str, s: &TensorBSpline<3>) -> Result<(), TrivariateError> {
    if s.dim() == 1 {
        Ok(())
    } else {
        Err(TrivariateError::InvalidArgument(format!(
            "attribute {name:?} has {} components; a scalar attribute is needed",
            s.dim()
        )))
    }
}

/// Smallest and largest Cartesian control value (first component).
pub(crate) fn control_range<const N: usize>(s: &TensorBSpline<N>) -> (f64, f64) {
    let hd = s.homogeneous_dim();
    let rational = s.is_rational();
    s.homogeneous_coefficients()
        .chunks_exact(hd)
        .map(|c| if rational { c[0] / c[hd - 1] } else { c[0] })
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        })
}

/// Merged breakpoints of the two knot vectors (both have domain `[0, 1]`).
fn merged_breakpoints(a: &KnotVector, b: &KnotVector) -> Vec<f64> {
    let mut v: Vec<f64> = a
        .breakpoints()
        .into_iter()
        .chain(b.breakpoints())
        .map(|(x, _)| x)
        .collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// `s` refined so that its breakpoints include `bps` (each missing one inserted once).
fn refine_to(
    s: &TensorBSpline<3>,
    bps: &[Vec<f64>; 3],
) -> Result<TensorBSpline<3>, TrivariateError> {
    let missing: [Vec<f64>; 3] = std::array::from_fn(|a| {
        let have = s.knots()[a].breakpoints();
        bps[a]
            .iter()
            .copied()
            .filter(|x| !have.iter().any(|&(h, _)| h == *x))
            .collect()
    });
    s.refine_all([&missing[0], &missing[1], &missing[2]])
        .map_err(ctx("refinement at the merged breakpoints"))
}

/// Second-difference and first-difference bounds of a Bézier piece along each axis, on its
/// Cartesian control values (`dim` components): `(p(p−1)/8·max‖Δ²‖, p·max‖Δ‖)`.
fn chord_bounds(piece: &BezierCell) -> ([f64; 3], [f64; 3]) {
    let deg = piece.degrees();
    let n = deg.map(|p| p + 1);
    let dim = piece.dim();
    let hd = dim + usize::from(piece.is_rational());
    let h = piece.homogeneous_coefficients();
    let point = |i: usize, j: usize, k: usize, c: usize| {
        let base = hd * (i + n[0] * (j + n[1] * k));
        if piece.is_rational() {
            h[base + c] / h[base + dim]
        } else {
            h[base + c]
        }
    };
    let mut second = [0.0f64; 3];
    let mut first = [0.0f64; 3];
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let idx = [i, j, k];
                for a in 0..3 {
                    let step = |t: usize| {
                        let mut q = idx;
                        q[a] = t;
                        q
                    };
                    if idx[a] + 1 < n[a] {
                        let q = step(idx[a] + 1);
                        let mut s = 0.0;
                        for c in 0..dim {
                            let d = point(q[0], q[1], q[2], c) - point(i, j, k, c);
                            s += d * d;
                        }
                        first[a] = first[a].max(s.sqrt());
                    }
                    if idx[a] + 2 < n[a] {
                        let q1 = step(idx[a] + 1);
                        let q2 = step(idx[a] + 2);
                        let mut s = 0.0;
                        for c in 0..dim {
                            let d = point(i, j, k, c) - 2.0 * point(q1[0], q1[1], q1[2], c)
                                + point(q2[0], q2[1], q2[2], c);
                            s += d * d;
                        }
                        second[a] = second[a].max(s.sqrt());
                    }
                }
            }
        }
    }
    let mut g2 = [0.0; 3];
    let mut g1 = [0.0; 3];
    for a in 0..3 {
        let p = deg[a] as f64;
        g2[a] = p * (p - 1.0) / 8.0 * second[a];
        g1[a] = p * first[a];
    }
    (g2, g1)
}

/// Lattice steps per axis an active element needs (see the [module docs](self), step 2).
fn element_steps(
    geometry: &BezierCell,
    d: &BezierCell,
    tolerance: f64,
) -> Result<[usize; 3], TrivariateError> {
    let (geo2, geo1) = chord_bounds(geometry);
    let (d2, _) = chord_bounds(d);
    let speed = geo1.iter().copied().fold(0.0, f64::max);
    let dom = d.domain();
    let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (dom[a][0] + dom[a][1]));
    let (mut v, mut g) = ([0.0], [0.0; 3]);
    d.eval_with_gradient_into(centre, &mut v, &mut g)
        .map_err(ctx("flatness"))?;
    let local: f64 = (0..3)
        .map(|a| (g[a] * (dom[a][1] - dom[a][0])).powi(2))
        .sum::<f64>()
        .sqrt();
    let dscale = d
        .homogeneous_coefficients()
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()));
    // Near a critical point of D the positional error estimate blows up; the floor keeps it
    // finite and the per-element cap bounds the resolution there.
    let grad = local.max(1e-6 * dscale).max(f64::MIN_POSITIVE);
    Ok(std::array::from_fn(|a| {
        let need = geo2[a] + speed * d2[a] / grad;
        let n = (3.0 * need / tolerance).sqrt().ceil();
        if n.is_finite() && n >= 1.0 {
            (n as usize).min(MAX_STEPS_PER_ELEMENT)
        } else if n.is_finite() {
            1
        } else {
            MAX_STEPS_PER_ELEMENT
        }
    }))
}

/// Index of the merged interval containing a cell, by interior overlap: the intervals
/// `j` with `bps[j] < end && bps[j+1] > start`.
fn overlapping(bps: &[f64], [start, end]: [f64; 2]) -> std::ops::Range<usize> {
    let intervals = bps.len() - 1;
    let first = bps[1..].partition_point(|&b| b <= start).min(intervals);
    let last = bps[..intervals].partition_point(|&b| b < end);
    first..last.max(first)
}

/// Solve one crossing on the lattice edge from `u0` along `axis` to parameter `t1`.
fn solve_vertex(
    target: Target<'_>,
    u0: [f64; 3],
    axis: usize,
    t1: f64,
    ftol: f64,
) -> Result<[f64; 3], TrivariateError> {
    let at = |t: f64| {
        let mut u = u0;
        u[axis] = t;
        u
    };
    let (mut lo, mut hi) = (u0[axis], t1);
    let (f_lo, _) = target.eval(at(lo), axis)?;
    let (f_hi, _) = target.eval(at(hi), axis)?;
    if f_lo.abs() <= ftol {
        return Ok(at(lo));
    }
    if f_hi.abs() <= ftol {
        return Ok(at(hi));
    }
    if (f_lo < 0.0) == (f_hi < 0.0) {
        // The lattice signs came from D = W·f, which agrees in sign with f except within
        // rounding of zero: take the endpoint closer to the zero set.
        return Ok(at(if f_lo.abs() <= f_hi.abs() { lo } else { hi }));
    }
    let lo_negative = f_lo < 0.0;
    let mut t = lo + (hi - lo) * f_lo / (f_lo - f_hi);
    let mut width = hi - lo;
    for _ in 0..MAX_VERTEX_STEPS {
        let (f, df) = target.eval(at(t), axis)?;
        if f.abs() <= ftol {
            return Ok(at(t));
        }
        if (f < 0.0) == lo_negative {
            lo = t;
        } else {
            hi = t;
        }
        if (hi - lo).abs() <= 4.0 * f64::EPSILON * hi.abs().max(lo.abs()).max(1e-300) {
            break;
        }
        let newton = t - f / df;
        let (a, b) = if lo < hi { (lo, hi) } else { (hi, lo) };
        let shrunk = (hi - lo).abs() <= 0.5 * width;
        width = (hi - lo).abs();
        t = if newton.is_finite() && newton > a && newton < b && shrunk {
            newton
        } else {
            0.5 * (lo + hi)
        };
    }
    Ok(at(0.5 * (lo + hi)))
}

/// The shared polygonisation of [`isosurface`] and [`slice()`].
fn polygonize(
    volume: &AggregateVolume,
    d: &TensorBSpline<3>,
    target: Target<'_>,
    residual_scale: f64,
    attribute: Option<&str>,
    options: &PolygonizeOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<ZeroSetMesh, TrivariateError> {
    let geometry = volume.geometry();
    let diag = diagonal(geometry);
    let tolerance = match options.tolerance {
        Some(t) => t,
        None => options.relative_tolerance * diag,
    };
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Err(TrivariateError::InvalidArgument(format!(
            "tolerance must be finite and positive, got {tolerance}"
        )));
    }
    let value_spline = match attribute {
        Some(name) => {
            let s = volume
                .attribute(name)
                .ok_or_else(|| TrivariateError::UnknownAttribute(name.to_owned()))?;
            check_scalar(name, s)?;
            Some(s)
        }
        None => None,
    };
    let roots = isolate_roots_with(d, &options.roots, progress)?;

    // 1. Elements of the merged breakpoints, and the Bézier pieces of D and P on them.
    let mut bps: [Vec<f64>; 3] =
        std::array::from_fn(|a| merged_breakpoints(&d.knots()[a], &geometry.knots()[a]));
    // A slice reports an attribute that varies across the plane: its elements are merged in
    // too, and each active one gets at least `degree` steps per axis, so the colours follow
    // the attribute (an isosurface's reported attribute is constant, the level).
    let colour_degrees = match (&target, value_spline) {
        (Target::Plane { .. }, Some(v)) => {
            for (a, b) in bps.iter_mut().enumerate() {
                b.extend(v.knots()[a].breakpoints().into_iter().map(|(x, _)| x));
                b.sort_by(f64::total_cmp);
                b.dedup();
            }
            v.degrees()
        }
        _ => [1; 3],
    };
    let counts: [usize; 3] = std::array::from_fn(|a| bps[a].len() - 1);
    let nelem = counts[0] * counts[1] * counts[2];
    let mut active = vec![false; nelem];
    for r in &roots {
        let dom = r.piece.domain();
        let ranges: [std::ops::Range<usize>; 3] =
            std::array::from_fn(|a| overlapping(&bps[a], dom[a]));
        for k in ranges[2].clone() {
            for j in ranges[1].clone() {
                for i in ranges[0].clone() {
                    active[i + counts[0] * (j + counts[1] * k)] = true;
                }
            }
        }
    }
    let mut steps: [Vec<usize>; 3] = std::array::from_fn(|a| vec![1; counts[a]]);
    if active.iter().any(|&x| x) {
        let gp = refine_to(geometry, &bps)?
            .bezier_pieces()
            .map_err(ctx("geometry Bézier extraction"))?;
        let dp = refine_to(d, &bps)?
            .bezier_pieces()
            .map_err(ctx("Bézier extraction"))?;
        if gp.len() != nelem || dp.len() != nelem {
            return Err(TrivariateError::Incompatible(
                "Bézier elements do not match the merged breakpoints".into(),
            ));
        }
        let need: Result<Vec<(usize, [usize; 3])>, TrivariateError> = (0..nelem)
            .into_par_iter()
            .filter(|&e| active[e])
            .map(|e| {
                progress.check()?;
                Ok((e, element_steps(&gp[e], &dp[e], tolerance)?))
            })
            .collect();
        progress.check()?;
        for (e, n) in need? {
            let idx = [
                e % counts[0],
                (e / counts[0]) % counts[1],
                e / (counts[0] * counts[1]),
            ];
            for a in 0..3 {
                steps[a][idx[a]] = steps[a][idx[a]].max(n[a]).max(colour_degrees[a]);
            }
        }
    }

    // 3. The rectilinear lattice.
    let params: [Vec<f64>; 3] = std::array::from_fn(|a| {
        let mut p = Vec::with_capacity(steps[a].iter().sum::<usize>() + 1);
        for (j, &n) in steps[a].iter().enumerate() {
            let (s, e) = (bps[a][j], bps[a][j + 1]);
            for q in 0..n {
                p.push(s + (e - s) * q as f64 / n as f64);
            }
        }
        p.push(bps[a][counts[a]]);
        p
    });
    let dims: [usize; 3] = std::array::from_fn(|a| params[a].len());
    let nodes = dims[0]
        .checked_mul(dims[1])
        .and_then(|x| x.checked_mul(dims[2]))
        .filter(|&n| n <= MAX_LATTICE_NODES)
        .ok_or_else(|| {
            TrivariateError::InvalidArgument(format!(
                "tolerance {tolerance} needs a lattice of {}×{}×{} nodes, more than {MAX_LATTICE_NODES}; use a larger tolerance",
                dims[0], dims[1], dims[2]
            ))
        })?;

    // 4. D at the nodes.
    let tables: Result<Vec<BasisTable>, _> = (0..3)
        .map(|a| BasisTable::new(&d.knots()[a], &params[a], false))
        .collect();
    let tables = tables.map_err(ctx("lattice basis tables"))?;
    let tables: [BasisTable; 3] = tables
        .try_into()
        .map_err(|_| TrivariateError::InvalidArgument("lattice basis tables".into()))?;
    progress.check()?;
    let mut values = vec![0.0; nodes];
    d.eval_grid_into(&tables, &mut values, None)
        .map_err(ctx("lattice evaluation"))?;

    // Marching cubes over the cells, one z layer per task; edges keyed by (node, axis).
    let (nx, ny) = (dims[0], dims[1]);
    let node = |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    let layers = dims[2].saturating_sub(1);
    progress.start(
        &format!("polygonising a {}×{}×{} lattice", dims[0], dims[1], dims[2]),
        layers as u64,
    );
    let triangles: Vec<[u64; 3]> = (0..layers)
        .into_par_iter()
        .flat_map_iter(|k| {
            let mut out = Vec::new();
            if progress.is_cancelled() {
                return out;
            }
            for j in 0..ny - 1 {
                for i in 0..nx - 1 {
                    let mut case = 0u8;
                    for c in 0..8 {
                        let [dx, dy, dz] = mc_corner_offset(c);
                        if values[node(i + dx, j + dy, k + dz)] < 0.0 {
                            case |= 1 << c;
                        }
                    }
                    if case == 0 || case == 255 {
                        continue;
                    }
                    for tri in mc_case_triangles(case) {
                        out.push(tri.map(|e| {
                            let e = usize::from(e);
                            let [from, _] = mc_edge_corners(e);
                            let [dx, dy, dz] = mc_corner_offset(from);
                            (node(i + dx, j + dy, k + dz) * 3 + e / 4) as u64
                        }));
                    }
                }
            }
            progress.advance(1);
            out
        })
        .collect();
    progress.check()?;

    // 5. One vertex per crossed edge.
    let mut edges: Vec<u64> = triangles.iter().flatten().copied().collect();
    edges.par_sort_unstable();
    edges.dedup();
    let ftol = VERTEX_RESIDUAL * residual_scale;
    progress.start(
        &format!("placing {} vertices", edges.len()),
        edges.len().div_ceil(VERTEX_CHUNK) as u64,
    );
    let vparams: Result<Vec<Vec<[f64; 3]>>, TrivariateError> = edges
        .par_chunks(VERTEX_CHUNK)
        .map(|chunk| {
            progress.check()?;
            let solved = chunk
                .iter()
                .map(|&key| {
                    let key = key as usize;
                    let (n, axis) = (key / 3, key % 3);
                    let idx = [n % nx, (n / nx) % ny, n / (nx * ny)];
                    let u0 = [params[0][idx[0]], params[1][idx[1]], params[2][idx[2]]];
                    let t1 = params[axis][idx[axis] + 1];
                    solve_vertex(target, u0, axis, t1, ftol)
                })
                .collect();
            progress.advance(1);
            solved
        })
        .collect();
    let vparams: Vec<[f64; 3]> = vparams?.concat();
    progress.check()?;
    let positions: Result<Vec<DVec3>, TrivariateError> = vparams
        .par_iter()
        .map(|&u| volume.point(u).map(DVec3::from_array))
        .collect();
    let positions = positions?;
    let vvalues: Vec<f64> = match value_spline {
        Some(s) => {
            let r: Result<Vec<f64>, TrivariateError> = vparams
                .par_iter()
                .map(|&u| {
                    let mut v = [0.0];
                    s.eval_into(u, &mut v).map_err(ctx("attribute"))?;
                    Ok(v[0])
                })
                .collect();
            r?
        }
        None => Vec::new(),
    };
    // The cases above wind counter-clockwise seen from `D ≥ 0` (larger attribute values, or
    // the side the plane normal points to).
    let toward_smaller = matches!(target, Target::Iso { .. }) && !options.inside_below;
    let flip = jacobian_negative(geometry)? != toward_smaller;
    let mut indices = Vec::with_capacity(triangles.len() * 3);
    for t in &triangles {
        let mut tri = [0u32; 3];
        for (slot, key) in tri.iter_mut().zip(t) {
            let v = edges.binary_search(key).map_err(|_| {
                TrivariateError::InvalidArgument("internal: crossing edge without vertex".into())
            })?;
            *slot = u32::try_from(v).map_err(|_| {
                TrivariateError::InvalidArgument("mesh has more than 2³² vertices".into())
            })?;
        }
        if flip {
            tri.swap(1, 2);
        }
        indices.extend(tri);
    }
    let tris: Vec<[u32; 3]> = indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    let mesh = Mesh::from_triangles(positions, &tris)
        .map_err(|e| TrivariateError::InvalidArgument(format!("internal: invalid mesh: {e}")))?;
    let face_values = face_averages(&mesh, &vvalues);
    Ok(ZeroSetMesh {
        mesh,
        params: vparams,
        values: vvalues,
        face_values,
        attribute: attribute.map(str::to_owned),
        root_cells: roots.len(),
        lattice: dims,
        tolerance,
    })
}

/// Per-face mean of per-vertex values (empty without values).
fn face_averages(mesh: &Mesh, values: &[f64]) -> Vec<f64> {
    if values.is_empty() {
        return Vec::new();
    }
    mesh.faces()
        .map(|f| {
            f.iter()
                .map(|&v| values.get(v as usize).copied().unwrap_or(f64::NAN))
                .sum::<f64>()
                / f.len().max(1) as f64
        })
        .collect()
}

/// Whether the geometry's Jacobian determinant is negative at the domain centre.
fn jacobian_negative(geometry: &TensorBSpline<3>) -> Result<bool, TrivariateError> {
    let (mut p, mut g) = ([0.0; 3], [0.0; 9]);
    geometry
        .eval_with_gradient_into([0.5; 3], &mut p, &mut g)
        .map_err(ctx("geometry"))?;
    let c = |a: usize| DVec3::new(g[3 * a], g[3 * a + 1], g[3 * a + 2]);
    Ok(c(0).dot(c(1).cross(c(2))) < 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Aggregate;
    use crate::fit;
    use volmorph_spline::KnotVector;

    fn kv(p: usize, n: usize) -> KnotVector {
        KnotVector::clamped_uniform(p, n, [0.0, 1.0]).unwrap()
    }

    /// Identity-like geometry of the box `[0, size]` (degree `p`, `n` control points per axis).
    fn box_geometry(p: usize, n: usize, size: [f64; 3]) -> TensorBSpline<3> {
        let id = TensorBSpline::identity([kv(p, n), kv(p, n), kv(p, n)]).unwrap();
        let pts: Vec<f64> = id
            .control_points()
            .chunks_exact(3)
            .flat_map(|c| [c[0] * size[0], c[1] * size[1], c[2] * size[2]])
            .collect();
        TensorBSpline::new(id.knots().clone(), 3, pts).unwrap()
    }

    /// Scalar attribute interpolating `f(u)` at the Greville sites of a tricubic `n³` net.
    fn fitted(n: usize, f: impl Fn([f64; 3]) -> f64) -> TensorBSpline<3> {
        let k = [kv(3, n), kv(3, n), kv(3, n)];
        let s = fit::greville_sites(&k);
        let mut data = Vec::with_capacity(n * n * n);
        for &w in &s[2] {
            for &v in &s[1] {
                for &u in &s[0] {
                    data.push(f([u, v, w]));
                }
            }
        }
        fit::interpolate(k, 1, &data).unwrap()
    }

    fn area(m: &Mesh) -> f64 {
        (0..m.face_count()).filter_map(|f| m.face_area(f)).sum()
    }

    fn check_vertices(z: &ZeroSetMesh, vol: &AggregateVolume) {
        for (p, u) in z.mesh.positions().iter().zip(&z.params) {
            let q = vol.point(*u).unwrap();
            assert!((p.x - q[0]).abs() + (p.y - q[1]).abs() + (p.z - q[2]).abs() < 1e-12);
        }
    }

    #[test]
    fn distance_attribute_gives_a_closed_sphere_of_the_right_area() {
        let size = 2.0;
        let geo = box_geometry(1, 2, [size; 3]);
        let attr = fitted(12, |u| {
            ((u[0] - 0.5).powi(2) + (u[1] - 0.5).powi(2) + (u[2] - 0.5).powi(2)).sqrt() * size
        });
        let vol = Aggregate::new(geo)
            .unwrap()
            .with_attribute("r", attr)
            .unwrap();
        let r = 0.6;
        let below = PolygonizeOptions {
            inside_below: true,
            ..PolygonizeOptions::default()
        };
        let z = isosurface(&vol, "r", r, &below).unwrap();
        let report = z.mesh.validate();
        assert!(report.is_closed_manifold(), "{report:?}");
        assert_eq!(report.euler_characteristic, 2);
        let a = area(&z.mesh);
        let expect = 4.0 * std::f64::consts::PI * r * r;
        assert!((a - expect).abs() < 5e-3 * expect, "area {a} vs {expect}");
        // Vertices on the isosurface, at P(u), and reported values equal to the level.
        let range = 3f64.sqrt() * size / 2.0;
        for (u, v) in z.params.iter().zip(&z.values) {
            let mut x = [0.0];
            vol.attribute_into("r", *u, &mut x).unwrap();
            assert!((x[0] - r).abs() < 1e-9 * range);
            assert!((v - r).abs() < 1e-9 * range);
        }
        check_vertices(&z, &vol);
        // Outward orientation: the signed volume is positive (the solid is r ≤ level); with
        // the default convention (solid r ≥ level) the same surface faces inward.
        let signed_volume = |m: &Mesh| {
            m.fan_triangles()
                .map(|[a, b, c]| {
                    let p = m.positions();
                    p[a as usize].dot(p[b as usize].cross(p[c as usize]))
                })
                .sum::<f64>()
                / 6.0
        };
        let v = signed_volume(&z.mesh);
        let default = isosurface(&vol, "r", r, &PolygonizeOptions::default()).unwrap();
        assert!((signed_volume(&default.mesh) + v).abs() < 1e-9 * v.abs());
        let expect_v = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        assert!(
            (v - expect_v).abs() < 1e-2 * expect_v,
            "volume {v} vs {expect_v}"
        );
        // A tighter tolerance refines the lattice.
        let fine = isosurface(
            &vol,
            "r",
            r,
            &PolygonizeOptions {
                tolerance: Some(1e-4),
                ..below
            },
        )
        .unwrap();
        assert!(fine.lattice[0] > z.lattice[0]);
        assert!(fine.mesh.validate().is_closed_manifold());
    }

    /// A curved rational geometry and a rational attribute: vertices still satisfy
    /// `A(u) = A*`, sit at `P(u)`, and the surface is closed although element resolutions differ.
    #[test]
    fn rational_curved_volume_closed_isosurface() {
        let n = 6;
        let id = box_geometry(3, n, [1.0; 3]);
        let pts: Vec<f64> = id
            .control_points()
            .chunks_exact(3)
            .flat_map(|c| {
                let bend = 0.25 * (c[0] * 3.0).sin() * c[2];
                [
                    c[0] + 0.1 * c[1] * c[1],
                    c[1] + bend,
                    c[2] + 0.2 * c[0] * c[1],
                ]
            })
            .collect();
        let weights: Vec<f64> = (0..n * n * n)
            .map(|i| 1.0 + 0.3 * ((i as f64) * 0.37).sin().abs())
            .collect();
        let geo = TensorBSpline::new_rational(id.knots().clone(), 3, pts, weights.clone()).unwrap();
        let a = fitted(7, |u| {
            (u[0] - 0.45).powi(2) + 2.0 * (u[1] - 0.5).powi(2) + (u[2] - 0.55).powi(2)
        });
        let ra = TensorBSpline::new_rational(
            a.knots().clone(),
            1,
            a.control_points(),
            (0..343).map(|i| 1.0 + 0.5 * f64::from(i % 3)).collect(),
        )
        .unwrap();
        let vol = Aggregate::new(geo)
            .unwrap()
            .with_attribute("q", ra)
            .unwrap();
        let level = 0.04;
        let z = isosurface(&vol, "q", level, &PolygonizeOptions::default()).unwrap();
        assert!(z.mesh.face_count() > 100);
        assert!(z.mesh.validate().is_closed_manifold());
        let (lo, hi) = control_range(vol.attribute("q").unwrap());
        for u in &z.params {
            let mut x = [0.0];
            vol.attribute_into("q", *u, &mut x).unwrap();
            assert!((x[0] - level).abs() < 1e-9 * (hi - lo));
        }
        check_vertices(&z, &vol);
        // Element resolutions differ along some axis (the curved part needs more steps).
        assert!(z.lattice.iter().any(|&d| d > 4));
    }

    /// Regression: a slice through a flat geometry used to be two triangles whatever the
    /// attribute did across it, so its colours were four corner values. The slice now follows
    /// the attribute's elements: the linear interpolation of the vertex values over each
    /// triangle stays close to the attribute.
    #[test]
    fn slice_colours_follow_a_varying_attribute() {
        let geo = box_geometry(1, 2, [1.0, 1.0, 1.0]);
        let attr = fitted(12, |u| (6.0 * u[1]).sin() * (4.0 * u[2]).cos());
        let vol = Aggregate::new(geo)
            .unwrap()
            .with_attribute("q", attr.clone())
            .unwrap();
        let z = slice(
            &vol,
            [1.0, 0.0, 0.0, -0.4],
            Some("q"),
            &PolygonizeOptions::default(),
        )
        .unwrap();
        assert!(z.mesh.face_count() > 100, "{} faces", z.mesh.face_count());
        let mut worst = 0.0f64;
        for t in z.mesh.fan_triangles() {
            let [a, b, c] = t.map(|i| i as usize);
            let u: [f64; 3] =
                std::array::from_fn(|k| (z.params[a][k] + z.params[b][k] + z.params[c][k]) / 3.0);
            let mut v = [0.0];
            attr.eval_into(u, &mut v).unwrap();
            let mean = (z.values[a] + z.values[b] + z.values[c]) / 3.0;
            worst = worst.max((v[0] - mean).abs());
        }
        assert!(worst < 0.05, "centroid error {worst}");
    }

    #[test]
    fn slicing_a_box_by_x_gives_its_cross_section() {
        let size = [2.0, 1.0, 3.0];
        let geo = box_geometry(2, 4, size);
        let attr = fitted(5, |u| u[1] + 2.0 * u[2]);
        let vol = Aggregate::new(geo)
            .unwrap()
            .with_attribute("s", attr)
            .unwrap();
        for c in [0.7, 1.0, 1.9] {
            let plane = [2.0, 0.0, 0.0, -2.0 * c];
            let z = slice(&vol, plane, Some("s"), &PolygonizeOptions::default()).unwrap();
            let a = area(&z.mesh);
            assert!((a - 3.0).abs() < 1e-9, "x = {c}: area {a}");
            let diag = (4.0f64 + 1.0 + 9.0).sqrt();
            for (p, (u, v)) in z
                .mesh
                .positions()
                .iter()
                .zip(z.params.iter().zip(&z.values))
            {
                assert!((p.x - c).abs() < 1e-9 * diag);
                let expect = u[1] + 2.0 * u[2];
                assert!((v - expect).abs() < 1e-9);
            }
            assert_eq!(z.face_values.len(), z.mesh.face_count());
            // Normals follow the plane normal +x.
            for f in 0..z.mesh.face_count() {
                if let Some(n) = z.mesh.face_normal(f) {
                    assert!(n.x > 0.999, "{n:?}");
                }
            }
            check_vertices(&z, &vol);
            let report = z.mesh.validate();
            assert!(report.non_manifold_edges.is_empty() && report.misoriented_edges.is_empty());
        }
        // An oblique plane through a rational volume: vertices lie on it.
        let g = vol.geometry().to_rational();
        let vol2 = Aggregate::new(g).unwrap();
        let plane = [0.3, -1.0, 0.5, 0.2];
        let z = slice(&vol2, plane, None, &PolygonizeOptions::default()).unwrap();
        assert!(z.values.is_empty() && z.face_values.is_empty() && z.mesh.face_count() > 0);
        for p in z.mesh.positions() {
            let r = plane[0] * p.x + plane[1] * p.y + plane[2] * p.z + plane[3];
            assert!(r.abs() < 1e-9 * 14f64.sqrt());
        }
        // A plane missing the volume gives an empty mesh.
        let z = slice(
            &vol2,
            [1.0, 0.0, 0.0, 5.0],
            None,
            &PolygonizeOptions::default(),
        )
        .unwrap();
        assert_eq!(z.mesh.face_count(), 0);
    }

    #[test]
    fn bad_input_is_an_error() {
        let geo = box_geometry(1, 2, [1.0; 3]);
        let attr = fitted(4, |u| u[0]);
        let vol = Aggregate::new(geo)
            .unwrap()
            .with_attribute("a", attr)
            .unwrap();
        let o = PolygonizeOptions::default();
        assert!(matches!(
            isosurface(&vol, "a", f64::NAN, &o),
            Err(TrivariateError::InvalidArgument(_))
        ));
        assert!(matches!(
            isosurface(&vol, "b", 0.5, &o),
            Err(TrivariateError::UnknownAttribute(_))
        ));
        assert!(matches!(
            slice(&vol, [0.0, 0.0, 0.0, 1.0], None, &o),
            Err(TrivariateError::InvalidArgument(_))
        ));
        assert!(matches!(
            slice(&vol, [1.0, 0.0, 0.0, -0.5], Some("zz"), &o),
            Err(TrivariateError::UnknownAttribute(_))
        ));
        for t in [0.0, -1.0, f64::NAN] {
            let bad = PolygonizeOptions {
                tolerance: Some(t),
                ..o
            };
            assert!(matches!(
                isosurface(&vol, "a", 0.5, &bad),
                Err(TrivariateError::InvalidArgument(_))
            ));
        }
        let tiny = PolygonizeOptions {
            tolerance: Some(1e-300),
            ..o
        };
        // The per-element cap keeps even absurd tolerances bounded.
        assert!(isosurface(&vol, "a", 0.5, &tiny).is_ok());
        let colour = fitted(4, |u| u[0]);
        let two: Vec<f64> = colour
            .control_points()
            .iter()
            .flat_map(|&v| [v, v])
            .collect();
        let rg = TensorBSpline::new(colour.knots().clone(), 2, two).unwrap();
        let vol = vol.with_attribute("rg", rg).unwrap();
        assert!(matches!(
            isosurface(&vol, "rg", 0.5, &o),
            Err(TrivariateError::InvalidArgument(_))
        ));
        assert!(matches!(
            slice(&vol, [1.0, 0.0, 0.0, -0.5], Some("rg"), &o),
            Err(TrivariateError::InvalidArgument(_))
        ));
    }
}
