//! Derived objects: results computed from other objects and kept up to date — warped volumes,
//! deformed meshes, isosurfaces, Jacobian maps, sampled F-rep models and their
//! metamorphoses — through the engines' incremental paths where one applies, and by full
//! recomputation otherwise. Both give the same result (to the rounding the engines document).
//!
//! Every update keeps what it replaced ([`Restore`]) until its command is done, so a command
//! cancelled halfway through bringing its derived objects up to date puts each one back
//! exactly as it was.

use std::sync::Arc;

use glam::DVec3;
use multiversion::multiversion;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use volmorph_contour::{DcOptions, McOptions, dual_contouring_any_with, marching_cubes_any_with};
use volmorph_deform::SpaceMap;
use volmorph_deform::live::{Influence, LinearMap};
use volmorph_frep::Tape;
use volmorph_frep::grid::sample_with as frep_sample_with;
use volmorph_frep::mapping::{Pullback, Schedule, morph};
use volmorph_maps::json::GridJson;
use volmorph_maps::{AnyMap, LiveMap};
use volmorph_mesh::Mesh;
use volmorph_volume::{AnyVolume, Geometry, IndexBox, Volume, Voxel, with_volume};
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume_with};
use volmorph_warp::incremental::IncrementalPushForward;
use volmorph_warp::jacobian::jacobian_determinant_with;
use volmorph_warp::pushforward::AntialiasOptions;

use crate::{MapObject, ObjectId, SceneError};

/// How an isosurface is extracted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SurfaceMethod {
    /// Marching cubes: crack-free, closed where the level set is.
    MarchingCubes,
    /// Dual contouring: sharp features kept.
    DualContouring,
}

/// What a derived object is computed from, and how.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "recipe", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Recipe {
    /// The volume `source` warped through map `map` by `method` onto the source's own grid.
    ///
    /// For a handle map with `swap_handles`, the map used is the one built from the swapped
    /// handles (targets to sources) and the method must be a pull-back: the content at each
    /// source appears at its target, the model moving the way the handles say (McPhail's
    /// backward mapping, as `volmorph handles warp` does). Otherwise the map is used as given,
    /// in the direction the method names.
    Warp {
        /// The volume warped.
        source: ObjectId,
        /// The map object.
        map: ObjectId,
        /// How the map is applied.
        #[serde(with = "method_name")]
        method: WarpMethod,
        /// Value of voxels nothing reaches.
        background: f64,
        /// Evaluate the map on an `n³` grid and interpolate (see
        /// [`WarpOptions::sampled_nodes`]).
        sampled_nodes: Option<usize>,
        /// For handle maps: pull back through the swapped handles.
        swap_handles: bool,
    },
    /// As [`Recipe::Warp`], onto the explicit output grid `grid` instead of the source's own
    /// (True 1992 §5.1: a target grid larger than the source, e.g. the source's grid padded
    /// by [`volmorph_warp::output::OutputGrid::resolve`], so the deformed model is not
    /// clipped). The incremental push-forward applies as for [`Recipe::Warp`].
    WarpOnto {
        /// The volume warped.
        source: ObjectId,
        /// The map object.
        map: ObjectId,
        /// How the map is applied.
        #[serde(with = "method_name")]
        method: WarpMethod,
        /// Value of voxels nothing reaches.
        background: f64,
        /// Evaluate the map on an `n³` grid and interpolate (see
        /// [`WarpOptions::sampled_nodes`]).
        sampled_nodes: Option<usize>,
        /// For handle maps: pull back through the swapped handles.
        swap_handles: bool,
        /// The output grid.
        grid: GridJson,
    },
    /// The vertices of mesh `mesh` pushed forward through map `map` (faces kept).
    DeformedMesh {
        /// The mesh deformed.
        mesh: ObjectId,
        /// The map object.
        map: ObjectId,
    },
    /// The level set `level` of volume `volume` (a volume or a derived volume).
    Isosurface {
        /// The volume.
        volume: ObjectId,
        /// The level.
        level: f64,
        /// The solid is where the value is at most the level (distances) instead of at least.
        inside_below: bool,
        /// Extraction method.
        method: SurfaceMethod,
    },
    /// The F-rep model `model` sampled at the voxel centres of volume `grid` (f32, solid where
    /// ≥ 0), optionally through map `map` read as a pull-back: the value at `x` is
    /// `f(map(x))` (Savchenko–Pasko Eq. 15 with `map` = φ⁻¹), so the model appears deformed by
    /// the inverse of `map` — give a map's inverse (`AnyMap::inverse`) to deform the model by
    /// the map itself.
    FrepSampled {
        /// The F-rep model.
        model: ObjectId,
        /// The map read as a pull-back, if any.
        map: Option<ObjectId>,
        /// The volume whose grid is sampled.
        grid: ObjectId,
    },
    /// The metamorphosis of F-rep model `from` into F-rep model `to` at time `t ∈ [0, 1]`
    /// (Savchenko–Pasko Eq. 13), sampled at the voxel centres of volume `grid` (f32, solid
    /// where ≥ 0): `ξ = h₁(t)·f(x) + h₂(t)·g(x)` with `h₂ = h(t)` the schedule and
    /// `h₁ = 1 − h(t)` (so `h₁(0) = 1, h₁(1) = 0, h₂(0) = 0, h₂(1) = 1`): exactly `from` at
    /// `t = 0` and `to` at `t = 1` ([`volmorph_frep::mapping::morph`]).
    FrepMorph {
        /// The model at `t = 0` (`f`).
        from: ObjectId,
        /// The model at `t = 1` (`g`).
        to: ObjectId,
        /// The time, in `[0, 1]`.
        t: f64,
        /// The schedule `h(t)`, as [`Schedule::parse`] reads it (`linear`, `sqrt`,
        /// `smoothstep`, `delayed:T0`).
        #[serde(with = "schedule_name")]
        schedule: Schedule,
        /// The volume whose grid is sampled.
        grid: ObjectId,
    },
    /// The Jacobian determinant of map `map` at the voxel centres of volume `grid` (f32; ≤ 0
    /// marks folding).
    Jacobian {
        /// The map object.
        map: ObjectId,
        /// The volume whose grid is sampled.
        grid: ObjectId,
    },
    /// The lobe labels of McPhail's lung model (§5.6.3,
    /// [`volmorph_register::lungs::trace_lobes`]; u8, labels as
    /// [`volmorph_register::phantom::lobe`], 0 outside the lungs): the fissures of `script`
    /// traced section by section through the enhanced lobe-boundary image `boundaries`
    /// within the lung mask `lungs` (1 right, 2 left, as
    /// [`volmorph_register::lungs::segment_lungs`] makes it; any voxel type, read as u8), both
    /// on one grid. A front-end edits the script click by click and sets the new recipe; an
    /// empty script labels each lung by height only.
    Lobes {
        /// The lung mask.
        lungs: ObjectId,
        /// The enhanced lobe-boundary image.
        boundaries: ObjectId,
        /// The key points of the fissures (pixel coordinates on axial sections).
        script: volmorph_register::lungs::LobeScript,
    },
}

mod method_name {
    use serde::{Deserialize, Deserializer, Serializer};
    use volmorph_warp::apply::WarpMethod;

    pub fn serialize<S: Serializer>(m: &WarpMethod, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(m.name())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<WarpMethod, D::Error> {
        let name = String::deserialize(d)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

mod schedule_name {
    use serde::{Deserialize, Deserializer, Serializer};
    use volmorph_frep::mapping::Schedule;

    pub fn serialize<S: Serializer>(h: &Schedule, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(h)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Schedule, D::Error> {
        let name = String::deserialize(d)?;
        Schedule::parse(&name).map_err(serde::de::Error::custom)
    }
}

impl Recipe {
    /// This recipe onto the output grid `grid`: a [`Recipe::Warp`] becomes the
    /// [`Recipe::WarpOnto`] of the same warp, a [`Recipe::WarpOnto`] changes its grid; other
    /// recipes are returned unchanged.
    #[must_use]
    pub fn onto(self, grid: &Geometry) -> Self {
        match self {
            Recipe::Warp {
                source,
                map,
                method,
                background,
                sampled_nodes,
                swap_handles,
            }
            | Recipe::WarpOnto {
                source,
                map,
                method,
                background,
                sampled_nodes,
                swap_handles,
                ..
            } => Recipe::WarpOnto {
                source,
                map,
                method,
                background,
                sampled_nodes,
                swap_handles,
                grid: GridJson::from(grid),
            },
            other => other,
        }
    }

    /// The objects this recipe reads.
    #[must_use]
    pub fn inputs(&self) -> Vec<ObjectId> {
        match self {
            Recipe::Warp { source, map, .. } | Recipe::WarpOnto { source, map, .. } => {
                vec![*source, *map]
            }
            Recipe::DeformedMesh { mesh, map } => vec![*mesh, *map],
            Recipe::Isosurface { volume, .. } => vec![*volume],
            Recipe::Jacobian { map, grid } => vec![*map, *grid],
            Recipe::FrepSampled { model, map, grid } => {
                let mut v = vec![*model, *grid];
                v.extend(*map);
                v
            }
            Recipe::FrepMorph { from, to, grid, .. } => vec![*from, *to, *grid],
            Recipe::Lobes {
                lungs, boundaries, ..
            } => vec![*lungs, *boundaries],
        }
    }

    /// The map object this recipe reads, if any.
    #[must_use]
    pub fn map(&self) -> Option<ObjectId> {
        match self {
            Recipe::Warp { map, .. }
            | Recipe::WarpOnto { map, .. }
            | Recipe::DeformedMesh { map, .. }
            | Recipe::Jacobian { map, .. } => Some(*map),
            Recipe::FrepSampled { map, .. } => *map,
            Recipe::Isosurface { .. } | Recipe::FrepMorph { .. } | Recipe::Lobes { .. } => None,
        }
    }

    /// The recipe's name in project files (the `"recipe"` tag): `warp`, `warp-onto`,
    /// `deformed-mesh`, `isosurface`, `frep-sampled`, `frep-morph`, `jacobian` or `lobes`.
    #[must_use]
    pub fn name(&self) -> &'static str {
        match self {
            Recipe::Warp { .. } => "warp",
            Recipe::WarpOnto { .. } => "warp-onto",
            Recipe::DeformedMesh { .. } => "deformed-mesh",
            Recipe::Isosurface { .. } => "isosurface",
            Recipe::FrepSampled { .. } => "frep-sampled",
            Recipe::FrepMorph { .. } => "frep-morph",
            Recipe::Jacobian { .. } => "jacobian",
            Recipe::Lobes { .. } => "lobes",
        }
    }

    /// The kind of result (`volume` or `mesh`).
    #[must_use]
    pub fn output_kind(&self) -> &'static str {
        match self {
            Recipe::Warp { .. }
            | Recipe::WarpOnto { .. }
            | Recipe::Jacobian { .. }
            | Recipe::FrepSampled { .. }
            | Recipe::FrepMorph { .. }
            | Recipe::Lobes { .. } => "volume",
            Recipe::DeformedMesh { .. } | Recipe::Isosurface { .. } => "mesh",
        }
    }
}

/// The computed result of a derived object.
#[derive(Debug, Clone)]
pub enum DerivedOutput {
    /// A volume.
    Volume(Arc<AnyVolume>),
    /// A mesh.
    Mesh(Arc<Mesh>),
}

/// A derived object: its recipe, its current result, and the engine that updates it
/// incrementally where one applies.
#[derive(Debug)]
pub struct Derived {
    recipe: Recipe,
    output: Option<DerivedOutput>,
    engine: Option<Box<IncrementalPushForward<LiveMap>>>,
    error: Option<String>,
}

/// A copy shares the result (copy on write) and leaves out the incremental engine, which the
/// copy rebuilds on its first update.
impl Clone for Derived {
    fn clone(&self) -> Self {
        Self {
            recipe: self.recipe.clone(),
            output: self.output.clone(),
            engine: None,
            error: self.error.clone(),
        }
    }
}

impl Derived {
    /// A derived object not computed yet.
    #[must_use]
    pub fn new(recipe: Recipe) -> Self {
        Self {
            recipe,
            output: None,
            engine: None,
            error: None,
        }
    }

    /// A derived object with a known result (read from a project's cache).
    #[must_use]
    pub fn with_output(recipe: Recipe, output: DerivedOutput) -> Self {
        Self {
            recipe,
            output: Some(output),
            engine: None,
            error: None,
        }
    }

    /// The recipe.
    #[must_use]
    pub fn recipe(&self) -> &Recipe {
        &self.recipe
    }

    /// The current result, if computed.
    #[must_use]
    pub fn output(&self) -> Option<&DerivedOutput> {
        self.output.as_ref()
    }

    /// The result as a volume.
    #[must_use]
    pub fn volume(&self) -> Option<&Arc<AnyVolume>> {
        match &self.output {
            Some(DerivedOutput::Volume(v)) => Some(v),
            _ => None,
        }
    }

    /// The result as a mesh.
    #[must_use]
    pub fn mesh(&self) -> Option<&Arc<Mesh>> {
        match &self.output {
            Some(DerivedOutput::Mesh(m)) => Some(m),
            _ => None,
        }
    }

    /// The error of the last computation, if it failed (the previous result is kept).
    #[must_use]
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }
}

/// What changed in the inputs of a derived object since its last computation.
#[derive(Debug, Clone)]
pub(crate) enum Hint {
    /// Anything may have changed: recompute.
    Full,
    /// Only parameters of the recipe's map changed: `(parameter, new value)`.
    Parameters(Vec<(usize, DVec3)>),
    /// Only the voxels in this box of the recipe's input volume changed.
    Region(IndexBox),
}

/// The inputs of a recipe, resolved.
pub(crate) struct Inputs<'a> {
    pub volume: Option<&'a Arc<AnyVolume>>,
    pub mesh: Option<&'a Arc<Mesh>>,
    pub map: Option<&'a MapObject>,
    pub frep: Option<&'a crate::FrepModel>,
    /// The second model of a metamorphosis.
    pub frep_to: Option<&'a crate::FrepModel>,
    /// A second volume (the lobe-boundary image of lobe tracing).
    pub second: Option<&'a Arc<AnyVolume>>,
}

/// What an update changed in a derived object: voxels (for volumes) and a physical box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dirty {
    /// The derived object.
    pub object: ObjectId,
    /// For volumes: the box of voxels that may have changed.
    pub voxels: Option<IndexBox>,
    /// The physical box `(lo, hi)` that may have changed (`None` when nothing changed).
    pub bounds: Option<(DVec3, DVec3)>,
}

/// The physical bounding box of the voxel centres of `b` in `g`, widened by half a voxel.
pub(crate) fn physical_box(g: &Geometry, b: &IndexBox) -> Option<(DVec3, DVec3)> {
    if b.is_empty() {
        return None;
    }
    let lo = DVec3::new(b.start[0] as f64, b.start[1] as f64, b.start[2] as f64) - 0.5;
    let hi = DVec3::new(b.end[0] as f64, b.end[1] as f64, b.end[2] as f64) - 0.5;
    let mut out = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for c in 0..8 {
        let idx = DVec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        );
        let p = g.index_to_physical(idx);
        out = (out.0.min(p), out.1.max(p));
    }
    Some(out)
}

/// The voxels of `v` as u8: borrowed when they are u8, else converted
/// ([`AnyVolume::to_typed`]).
pub(crate) fn u8_voxels(v: &AnyVolume) -> std::borrow::Cow<'_, Volume<u8>> {
    match v {
        AnyVolume::U8(t) => std::borrow::Cow::Borrowed(t),
        other => std::borrow::Cow::Owned(other.to_typed()),
    }
}

/// The voxels of `v` as f32: borrowed when they are f32, else converted.
fn f32_voxels(v: &AnyVolume) -> std::borrow::Cow<'_, Volume<f32>> {
    match v {
        AnyVolume::F32(t) => std::borrow::Cow::Borrowed(t),
        other => std::borrow::Cow::Owned(other.to_typed()),
    }
}

/// A zero volume of `source`'s voxel type on `grid`.
fn blank_like<T: Voxel>(_source: &Volume<T>, grid: Geometry) -> Result<Volume<T>, SceneError> {
    Ok(Volume::filled(grid, T::from_f64(0.0))?)
}

/// Copy the engine's `f32` result in box `b` into `out` (the source's voxel type, same
/// dims), converting with [`Voxel::from_f64`] as the full push-forward does; z-planes in
/// parallel. Voxels outside `b` are left alone; a box reaching outside the grid copies only
/// the part inside.
fn copy_box<T: Voxel>(engine: &Volume<f32>, out: &mut Volume<T>, b: &IndexBox) {
    let [nx, ny, nz] = out.geometry().dims;
    let plane = nx * ny;
    let (x0, x1) = (b.start[0].min(nx), b.end[0].min(nx));
    let (y0, y1) = (b.start[1].min(ny), b.end[1].min(ny));
    let (z0, z1) = (b.start[2].min(nz), b.end[2].min(nz));
    if x0 >= x1 || y0 >= y1 || z0 >= z1 || engine.data().len() != out.data().len() {
        return;
    }
    out.data_mut()
        .par_chunks_mut(plane)
        .zip(engine.data().par_chunks(plane))
        .skip(z0)
        .take(z1 - z0)
        .for_each(|(dst, src)| {
            for j in y0..y1 {
                let (a, e) = (nx * j + x0, nx * j + x1);
                convert_row(&src[a..e], &mut dst[a..e]);
            }
        });
}

/// `dst[i] = T::from_f64(src[i])` for one row. Compiled for the baseline target and for
/// x86-64 with AVX2, chosen at run time: on the baseline target `f64::round` (in
/// [`Voxel::from_f64`] of the integer types) is a library call per voxel, with SSE4.1 and
/// up it is a few inline instructions; both give the same bits (IEEE rounding, no
/// contraction).
#[multiversion(targets("x86_64+avx2+fma"))]
fn convert_row<T: Voxel>(src: &[f32], dst: &mut [T]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = T::from_f64(f64::from(*s));
    }
}

/// What an update of a derived object replaced, kept until its command is done so a
/// cancelled command can put every derived object back as it was ([`Derived::restore`]).
#[derive(Debug)]
pub(crate) enum Restore {
    /// A full recomputation (or a failure) replaced the result and the engine: the previous
    /// ones, moved out (no copy).
    State {
        output: Option<DerivedOutput>,
        engine: Option<Box<IncrementalPushForward<LiveMap>>>,
        error: Option<String>,
    },
    /// The incremental push-forward rewrote the voxels of `voxels` in place: their previous
    /// values, in the volume's voxel type ([`take_box`]). The engine has moved on; it is
    /// dropped on restore (it is a cache: the next update rebuilds it).
    Voxels {
        voxels: IndexBox,
        values: Option<Box<AnyVolume>>,
        error: Option<String>,
    },
    /// Nothing changed but the error (cleared).
    Unchanged { error: Option<String> },
    /// The incremental vertex FFD moved these vertices in place: their previous positions.
    Vertices {
        moved: Vec<(usize, DVec3)>,
        error: Option<String>,
    },
}

/// What a computation produced: a new result to put in place, or a result already updated
/// in place (the incremental paths) with what it replaced.
enum Update {
    Replace {
        output: DerivedOutput,
        engine: Option<Box<IncrementalPushForward<LiveMap>>>,
        dirty: Dirty,
    },
    InPlace {
        dirty: Dirty,
        restore: Restore,
    },
}

impl Derived {
    /// Bring the result up to date after the change `hint` of its inputs, reporting long
    /// computations to `progress`; returns what changed and what to put back if the command
    /// is cancelled later. On an error other than cancellation the previous result is kept,
    /// the error recorded and the incremental engine dropped (the next update recomputes).
    ///
    /// # Errors
    /// Only cancellation ([`SceneError::is_cancelled`]): the object is then unchanged.
    pub(crate) fn update_with(
        &mut self,
        id: ObjectId,
        inputs: &Inputs<'_>,
        hint: &Hint,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<(Dirty, Restore), SceneError> {
        let error = self.error.clone();
        match self.compute(id, inputs, hint, progress) {
            Ok(Update::Replace {
                output,
                engine,
                dirty,
            }) => {
                let restore = Restore::State {
                    output: self.output.replace(output),
                    engine: std::mem::replace(&mut self.engine, engine),
                    error,
                };
                self.error = None;
                Ok((dirty, restore))
            }
            Ok(Update::InPlace { dirty, restore }) => {
                self.error = None;
                Ok((dirty, restore))
            }
            Err(e) if e.is_cancelled() => Err(e),
            Err(e) => {
                self.error = Some(e.to_string());
                let restore = Restore::State {
                    output: self.output.clone(),
                    engine: self.engine.take(),
                    error,
                };
                Ok((
                    Dirty {
                        object: id,
                        voxels: None,
                        bounds: None,
                    },
                    restore,
                ))
            }
        }
    }

    /// Put back what an update replaced (`restore` from [`Derived::update_with`] on this
    /// object, the latest first when several updates ran).
    pub(crate) fn restore(&mut self, restore: Restore) {
        match restore {
            Restore::State {
                output,
                engine,
                error,
            } => {
                self.output = output;
                self.engine = engine;
                self.error = error;
            }
            Restore::Voxels {
                voxels,
                values,
                error,
            } => {
                if let Some(DerivedOutput::Volume(out)) = &mut self.output {
                    let out = Arc::make_mut(out);
                    with_volume!(out, v => put_box(v, &voxels, values.as_deref()));
                }
                self.engine = None;
                self.error = error;
            }
            Restore::Unchanged { error } => self.error = error,
            Restore::Vertices { moved, error } => {
                if let Some(DerivedOutput::Mesh(out)) = &mut self.output {
                    let out = Arc::make_mut(out);
                    for (i, p) in moved {
                        out.positions_mut()[i] = p;
                    }
                }
                self.error = error;
            }
        }
    }

    fn compute(
        &mut self,
        id: ObjectId,
        inputs: &Inputs<'_>,
        hint: &Hint,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Update, SceneError> {
        progress.check()?;
        let volume = |grid: &Geometry, v: AnyVolume| {
            let all = IndexBox::all(grid.dims);
            Update::Replace {
                output: DerivedOutput::Volume(Arc::new(v)),
                engine: None,
                dirty: Dirty {
                    object: id,
                    voxels: Some(all),
                    bounds: physical_box(grid, &all),
                },
            }
        };
        match self.recipe.clone() {
            Recipe::Warp {
                method,
                background,
                sampled_nodes,
                swap_handles,
                ..
            } => self.warp(
                id,
                inputs,
                hint,
                WarpSpec {
                    method,
                    background,
                    sampled_nodes,
                    swap_handles,
                    onto: None,
                },
                progress,
            ),
            Recipe::WarpOnto {
                method,
                background,
                sampled_nodes,
                swap_handles,
                grid,
                ..
            } => self.warp(
                id,
                inputs,
                hint,
                WarpSpec {
                    method,
                    background,
                    sampled_nodes,
                    swap_handles,
                    onto: Some(grid.geometry()),
                },
                progress,
            ),
            Recipe::DeformedMesh { .. } => self.deform_mesh(id, inputs, hint),
            Recipe::Isosurface {
                level,
                inside_below,
                method,
                ..
            } => {
                if let Hint::Region(b) = hint
                    && b.is_empty()
                    && self.output.is_some()
                {
                    return Ok(Update::InPlace {
                        dirty: Dirty {
                            object: id,
                            voxels: None,
                            bounds: None,
                        },
                        restore: Restore::Unchanged {
                            error: self.error.clone(),
                        },
                    });
                }
                let vol = inputs
                    .volume
                    .ok_or_else(|| SceneError::invalid("isosurface without a volume"))?;
                let surface = match method {
                    SurfaceMethod::MarchingCubes => {
                        marching_cubes_any_with(vol, level, &McOptions { inside_below }, progress)?
                    }
                    SurfaceMethod::DualContouring => dual_contouring_any_with(
                        vol,
                        level,
                        &DcOptions {
                            inside_below,
                            ..DcOptions::default()
                        },
                        progress,
                    )?,
                };
                let bounds = surface.mesh.bounding_box();
                let old = self.mesh().and_then(|m| m.bounding_box());
                Ok(Update::Replace {
                    output: DerivedOutput::Mesh(Arc::new(surface.mesh)),
                    engine: None,
                    dirty: Dirty {
                        object: id,
                        voxels: None,
                        bounds: union(bounds, old),
                    },
                })
            }
            Recipe::FrepSampled { .. } => {
                let model = inputs
                    .frep
                    .ok_or_else(|| SceneError::invalid("F-rep sampling without a model"))?;
                let grid = *inputs
                    .volume
                    .ok_or_else(|| SceneError::invalid("F-rep sampling without a grid"))?
                    .geometry();
                let tape = Tape::new(model.shape());
                let sampled = match inputs.map {
                    Some(m) => frep_sample_with(
                        &Pullback {
                            field: &tape,
                            inverse: m.map(),
                        },
                        &grid,
                        progress,
                    )?,
                    None => frep_sample_with(&tape, &grid, progress)?,
                };
                Ok(volume(&grid, AnyVolume::from(sampled)))
            }
            Recipe::FrepMorph { t, schedule, .. } => {
                let (Some(from), Some(to)) = (inputs.frep, inputs.frep_to) else {
                    return Err(SceneError::invalid("metamorphosis without its two models"));
                };
                let grid = *inputs
                    .volume
                    .ok_or_else(|| SceneError::invalid("metamorphosis without a grid"))?
                    .geometry();
                let tape = Tape::new(&morph(from.shape(), to.shape(), t, schedule));
                let sampled = frep_sample_with(&tape, &grid, progress)?;
                Ok(volume(&grid, AnyVolume::from(sampled)))
            }
            Recipe::Jacobian { .. } => {
                let map = inputs
                    .map
                    .ok_or_else(|| SceneError::invalid("Jacobian without a map"))?;
                let grid = *inputs
                    .volume
                    .ok_or_else(|| SceneError::invalid("Jacobian without a grid"))?
                    .geometry();
                let det = jacobian_determinant_with(map.map(), &grid, progress)?;
                Ok(volume(&grid, AnyVolume::from(det)))
            }
            Recipe::Lobes { script, .. } => {
                let (Some(lungs), Some(boundaries)) = (inputs.volume, inputs.second) else {
                    return Err(SceneError::invalid(
                        "lobe tracing without its lung mask and lobe-boundary image",
                    ));
                };
                let lungs = u8_voxels(lungs);
                let boundaries = f32_voxels(boundaries);
                let model = volmorph_register::lungs::trace_lobes_with(
                    &lungs,
                    &boundaries,
                    &script,
                    progress,
                )?;
                Ok(volume(lungs.geometry(), AnyVolume::from(model.lobes)))
            }
        }
    }

    fn warp(
        &mut self,
        id: ObjectId,
        inputs: &Inputs<'_>,
        hint: &Hint,
        spec: WarpSpec,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Update, SceneError> {
        let WarpSpec {
            method,
            background,
            sampled_nodes,
            swap_handles,
            onto,
        } = spec;
        let source = inputs
            .volume
            .ok_or_else(|| SceneError::invalid("warp without a volume"))?;
        let map_object = inputs
            .map
            .ok_or_else(|| SceneError::invalid("warp without a map"))?;
        let grid = onto.unwrap_or(*source.geometry());
        grid.validate()
            .map_err(|e| SceneError::invalid(format!("warp output grid: {e}")))?;
        // The incremental path: an antialiased push-forward through a map linear in its
        // parameters, evaluated exactly.
        let live = match (map_object, swap_handles) {
            (_, true) => None,
            (m, false) => m.map().to_live(),
        };
        let all = IndexBox::all(grid.dims);
        let everything = Dirty {
            object: id,
            voxels: Some(all),
            bounds: physical_box(&grid, &all),
        };
        if let (Some(live), WarpMethod::PushforwardAntialiased, None) =
            (&live, method, sampled_nodes)
        {
            if let (Hint::Parameters(changes), Some(engine), Some(DerivedOutput::Volume(out))) =
                (hint, &mut self.engine, &mut self.output)
            {
                // Not cancellable: an update touches only the region the moved parameters
                // reach, the work of an interactive drag.
                let report = engine.set_parameters(changes)?;
                let b = report.output_box;
                let out = Arc::make_mut(out);
                let values = with_volume!(&*out, v => take_box(v, &b))?.map(Box::new);
                with_volume!(out, v => copy_box(engine.volume(), v, &b));
                return Ok(Update::InPlace {
                    dirty: Dirty {
                        object: id,
                        voxels: Some(b),
                        bounds: physical_box(&grid, &b),
                    },
                    restore: Restore::Voxels {
                        voxels: b,
                        values,
                        error: self.error.clone(),
                    },
                });
            }
            let options = AntialiasOptions {
                background,
                ..AntialiasOptions::default()
            };
            let engine = with_volume!(&**source, v => {
                IncrementalPushForward::new_with(v, live.clone(), &grid, &options, progress)?
            });
            let mut out = with_volume!(&**source, v => AnyVolume::from(blank_like(v, grid)?));
            with_volume!(&mut out, v => copy_box(engine.volume(), v, &all));
            return Ok(Update::Replace {
                output: DerivedOutput::Volume(Arc::new(out)),
                engine: Some(Box::new(engine)),
                dirty: everything,
            });
        }
        let backward;
        let map: &AnyMap = match (map_object, swap_handles) {
            (MapObject::Handles(h), true) => {
                if !method.is_pullback() {
                    return Err(SceneError::invalid(format!(
                        "swapped handles give a pull-back map; {method} is not a pull-back"
                    )));
                }
                backward = h.backward()?;
                &backward
            }
            (MapObject::Fixed(_), true) => {
                return Err(SceneError::invalid(
                    "only a handle map can be applied with swapped handles",
                ));
            }
            (m, false) => m.map(),
        };
        let options = WarpOptions {
            background,
            mask: false,
            sampled_nodes,
        };
        let out = warp_volume_with(source.view(), map, &grid, method, &options, progress)?;
        Ok(Update::Replace {
            output: DerivedOutput::Volume(Arc::new(out.volume)),
            engine: None,
            dirty: everything,
        })
    }

    fn deform_mesh(
        &mut self,
        id: ObjectId,
        inputs: &Inputs<'_>,
        hint: &Hint,
    ) -> Result<Update, SceneError> {
        let mesh = inputs
            .mesh
            .ok_or_else(|| SceneError::invalid("deformed mesh without a mesh"))?;
        let map = inputs
            .map
            .ok_or_else(|| SceneError::invalid("deformed mesh without a map"))?
            .map();
        // Parameter moves of a map with local influence: only the vertices in the influence.
        if let (Hint::Parameters(changes), Some(DerivedOutput::Mesh(out)), Some(live)) =
            (hint, &mut self.output, map.to_live())
            && out.vertex_count() == mesh.vertex_count()
        {
            let ks: Vec<usize> = changes.iter().map(|c| c.0).collect();
            if let Influence::Within(_) = live.influence(&ks) {
                let (lo, hi) = live.influence(&ks).bounds().unwrap_or_default();
                // Gather the vertices inside the influence, map them with the same batch
                // evaluation a full update uses (so both agree bit for bit), scatter back.
                let src = mesh.positions();
                let (index, points): (Vec<usize>, Vec<DVec3>) = src
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| p.cmpge(lo).all() && p.cmple(hi).all())
                    .map(|(i, p)| (i, *p))
                    .unzip();
                let mut mapped = vec![DVec3::ZERO; points.len()];
                map.apply_batch(&points, &mut mapped)?;
                let out = Arc::make_mut(out);
                let mut dirty: Option<(DVec3, DVec3)> = None;
                let mut moved = Vec::with_capacity(index.len());
                for (&i, &new) in index.iter().zip(&mapped) {
                    let old = out.positions()[i];
                    moved.push((i, old));
                    out.positions_mut()[i] = new;
                    dirty = union(dirty, Some((old.min(new), old.max(new))));
                }
                return Ok(Update::InPlace {
                    dirty: Dirty {
                        object: id,
                        voxels: None,
                        bounds: dirty,
                    },
                    restore: Restore::Vertices {
                        moved,
                        error: self.error.clone(),
                    },
                });
            }
        }
        let mut out = (**mesh).clone();
        map.apply_batch(mesh.positions(), out.positions_mut())?;
        let bounds = union(
            out.bounding_box(),
            self.mesh().and_then(|m| m.bounding_box()),
        );
        Ok(Update::Replace {
            output: DerivedOutput::Mesh(Arc::new(out)),
            engine: None,
            dirty: Dirty {
                object: id,
                voxels: None,
                bounds,
            },
        })
    }
}

/// How a warp recipe applies its map.
struct WarpSpec {
    method: WarpMethod,
    background: f64,
    sampled_nodes: Option<usize>,
    swap_handles: bool,
    onto: Option<Geometry>,
}

/// The voxels of box `b` of `v` (clipped to the grid), in `v`'s own voxel type, as a volume
/// of the clipped box's dims (x fastest; its geometry is the unit grid, only the values
/// count). Rows are copied as they are: this copy is the undo record of every incremental
/// warp update, on the drag's critical path, and keeping the voxel type keeps it small (a
/// `u8` box takes a byte per voxel). `None` for a box outside the grid.
///
/// # Errors
/// [`SceneError::Volume`] if the box cannot be held (unreachable for a box of `v`).
fn take_box<T: Voxel>(v: &Volume<T>, b: &IndexBox) -> Result<Option<AnyVolume>, SceneError>
where
    AnyVolume: From<Volume<T>>,
{
    let [nx, ny, nz] = v.geometry().dims;
    let (x0, x1) = (b.start[0].min(nx), b.end[0].min(nx));
    let (y0, y1) = (b.start[1].min(ny), b.end[1].min(ny));
    let (z0, z1) = (b.start[2].min(nz), b.end[2].min(nz));
    let dims = [
        x1.saturating_sub(x0),
        y1.saturating_sub(y0),
        z1.saturating_sub(z0),
    ];
    if dims.contains(&0) {
        return Ok(None);
    }
    let mut out = Vec::with_capacity(dims.iter().product());
    let data = v.data();
    for k in z0..z1 {
        for j in y0..y1 {
            let row = (k * ny + j) * nx;
            out.extend_from_slice(&data[row + x0..row + x1]);
        }
    }
    Ok(Some(AnyVolume::from(Volume::new(
        Geometry::new(dims),
        out,
    )?)))
}

/// Write back what [`take_box`] took from box `b` (no record, or one of another voxel type,
/// writes nothing).
fn put_box<T: Voxel>(v: &mut Volume<T>, b: &IndexBox, record: Option<&AnyVolume>) {
    let [nx, ny, nz] = v.geometry().dims;
    let (x0, x1) = (b.start[0].min(nx), b.end[0].min(nx));
    let (y0, y1) = (b.start[1].min(ny), b.end[1].min(ny));
    let (z0, z1) = (b.start[2].min(nz), b.end[2].min(nz));
    let Some(record) = record.filter(|r| r.voxel_type() == T::TYPE) else {
        return;
    };
    if x0 >= x1 || y0 >= y1 || z0 >= z1 {
        return;
    }
    // The same voxel type: the conversion is an exact copy.
    let values = record.to_typed::<T>();
    let mut rows = values.data().chunks_exact(x1 - x0);
    let data = v.data_mut();
    for k in z0..z1 {
        for j in y0..y1 {
            let row = (k * ny + j) * nx;
            if let Some(src) = rows.next() {
                data[row + x0..row + x1].copy_from_slice(src);
            }
        }
    }
}

fn union(a: Option<(DVec3, DVec3)>, b: Option<(DVec3, DVec3)>) -> Option<(DVec3, DVec3)> {
    match (a, b) {
        (Some(a), Some(b)) => Some((a.0.min(b.0), a.1.max(b.1))),
        (a, None) => a,
        (None, b) => b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values that stress rounding and saturation: ties, values just off ties, negatives,
    /// out-of-range magnitudes, infinities and NaN.
    fn awkward() -> Vec<f32> {
        let mut v = vec![
            0.0,
            -0.0,
            0.5,
            1.5,
            2.5,
            -0.5,
            -1.5,
            0.499_999_97,
            0.500_000_06,
            254.5,
            255.49998,
            255.5,
            256.0,
            1e9,
            -1e9,
            32767.5,
            -32768.5,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
            1e-30,
        ];
        // A spread of ordinary values.
        v.extend((0..2000).map(|n| (n as f32) * 0.173 - 40.0));
        v
    }

    fn check<T: Voxel>() {
        let values = awkward();
        let g = Geometry::new([values.len(), 1, 1]);
        let engine = Volume::new(g, values.clone()).unwrap();
        let mut out = Volume::filled(g, T::from_f64(7.0)).unwrap();
        copy_box(&engine, &mut out, &IndexBox::all(g.dims));
        for (n, (v, o)) in values.iter().zip(out.data()).enumerate() {
            let want = T::from_f64(f64::from(*v));
            assert!(
                o.to_f64().to_bits() == want.to_f64().to_bits(),
                "{} voxel {n}: {v} gave {o:?}, not {want:?}",
                std::any::type_name::<T>()
            );
        }
    }

    /// The undo record of a box (taken in parallel over planes) holds the box's voxels in
    /// x-fastest order, clipped to the grid, and writing it back restores the volume.
    #[test]
    fn take_box_reads_the_clipped_box_in_order_and_put_box_restores_it() {
        let g = volmorph_volume::Geometry::new([7, 5, 6]);
        let v = Volume::<u16>::from_fn(g, |i, j, k| (i + 10 * j + 100 * k) as u16).unwrap();
        let b = IndexBox {
            start: [2, 1, 3],
            end: [9, 4, 6],
        };
        let taken = take_box(&v, &b).unwrap().unwrap();
        let mut expected = vec![];
        for k in 3..6 {
            for j in 1..4 {
                for i in 2..7 {
                    expected.push((i + 10 * j + 100 * k) as f64);
                }
            }
        }
        assert_eq!(
            taken.geometry().dims,
            [5, 3, 3],
            "the box clipped to the grid"
        );
        let values: Vec<f64> = taken
            .to_typed::<u16>()
            .data()
            .iter()
            .map(|x| f64::from(*x))
            .collect();
        assert_eq!(values, expected);
        assert_eq!(taken.voxel_type(), u16::TYPE, "kept in the volume's type");
        let mut w = Volume::<u16>::from_fn(g, |_, _, _| 0).unwrap();
        put_box(&mut w, &b, Some(&taken));
        for k in 0..6 {
            for j in 0..5 {
                for i in 0..7 {
                    let inside = (2..7).contains(&i) && (1..4).contains(&j) && (3..6).contains(&k);
                    let want = if inside { v.get(i, j, k).unwrap() } else { 0 };
                    assert_eq!(w.get(i, j, k).unwrap(), want, "({i}, {j}, {k})");
                }
            }
        }
        let outside = IndexBox {
            start: [0, 5, 0],
            end: [7, 9, 6],
        };
        assert!(take_box(&v, &outside).unwrap().is_none());
    }

    /// The run-time-dispatched row conversion gives exactly `Voxel::from_f64` for every
    /// voxel type, ties and saturation included.
    #[test]
    fn copy_box_converts_exactly_as_from_f64() {
        check::<u8>();
        check::<i8>();
        check::<u16>();
        check::<i16>();
        check::<u32>();
        check::<i32>();
        check::<f32>();
        check::<f64>();
    }

    /// Only the box is written, and a box reaching past the grid copies the part inside.
    #[test]
    fn copy_box_writes_only_the_box() {
        let g = Geometry::new([5, 4, 3]);
        let engine = Volume::from_fn(g, |i, j, k| (i + 10 * j + 100 * k) as f32).unwrap();
        let mut out = Volume::filled(g, 9999u16).unwrap();
        let b = IndexBox {
            start: [1, 2, 1],
            end: [9, 3, 7],
        };
        copy_box(&engine, &mut out, &b);
        for k in 0..3 {
            for j in 0..4 {
                for i in 0..5 {
                    let inside = i >= 1 && j == 2 && k >= 1;
                    let want = if inside {
                        (i + 10 * j + 100 * k) as u16
                    } else {
                        9999
                    };
                    assert_eq!(out[[i, j, k]], want, "voxel {i} {j} {k}");
                }
            }
        }
    }
}
