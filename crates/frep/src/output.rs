//! Output of shapes: polygon meshes through the project's isosurface extractors, and
//! ray-cast pictures and animations.
//!
//! **Meshes.** [`mesh`] samples the field on a grid ([`crate::grid::sample`]) and extracts
//! `f = 0` with `volmorph_contour`'s marching cubes or dual contouring, inside where
//! `f ≥ 0`; with [`MeshOptions::close`] the grid's outer layer is forced outside, so a shape
//! cut by the box still gives a closed surface (capped at the box).
//!
//! **Pictures.** [`render`] casts one ray per pixel through a
//! [`Camera`], restricted to a bounding box. For compiled shapes
//! the first root along each ray is found by **interval-bounded subdivision**: a segment
//! whose interval enclosure is negative holds no solid and is skipped whole; otherwise it is
//! halved (front half first) with the tape specialised to the segment, down to
//! `segment / 2^`[`RenderOptions::max_depth`]; in a leaf segment the solid is located by
//! samples and bisection. A thin feature cannot be stepped over: it makes the enclosure of
//! every segment containing it non-negative somewhere, so subdivision reaches it. Fields
//! without a tape fall back to uniform stepping ([`RenderOptions::fallback_steps`]) and can
//! miss features thinner than a step. Shading is the project's one model,
//! [`Shading`] (Blinn–Phong, light fixed to the camera, in linear light), with the outward
//! normal `−∇f/|∇f|`. A NaN value is a miss, but the values sampled along the rays follow
//! the rule of grid sampling: NaN where a data-dependent loop of the model had not ended
//! fails the picture with the loop's position, and so does NaN at every sample.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use glam::DVec3;
use rayon::prelude::*;
use volmorph_contour::{
    DcOptions, IsoSurface, McOptions, dual_contouring_with, marching_cubes_with,
};
use volmorph_render::shading::{Lighting, linear_to_srgb8, srgb8_to_linear};
use volmorph_render::{Aabb, Camera, Ray, RgbaImage, Shading, write_png_rgba};
use volmorph_volume::Geometry;

use crate::error::FrepError;
use crate::field::Field;
use crate::grid::{self, SampleTally};
use crate::ops::Dual;
use crate::tape::{BatchScratch, IntervalScratch, Tape};

/// Isosurface extractor of [`mesh`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MeshMethod {
    /// Marching cubes.
    #[default]
    MarchingCubes,
    /// Dual contouring (keeps sharp edges and corners of CSG models).
    DualContouring,
}

/// Options of [`mesh`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MeshOptions {
    /// Extractor.
    pub method: MeshMethod,
    /// Force the grid's outer layer outside the solid, capping shapes cut by the box so the
    /// mesh is closed.
    pub close: bool,
}

/// Value written on the outer layer by [`MeshOptions::close`]: just outside (negative).
const OUTSIDE: f32 = -1e-6;

/// Sample `field` on `geometry` and extract its surface `f = 0` (solid `f ≥ 0`), vertices in
/// physical coordinates, triangles counter-clockwise seen from outside.
///
/// # Errors
/// As [`grid::sample`], and [`FrepError::Contour`] when extraction fails (a grid dimension
/// below 2, too many vertices).
pub fn mesh(
    field: &dyn Field,
    geometry: &Geometry,
    options: &MeshOptions,
) -> Result<IsoSurface, FrepError> {
    mesh_with(field, geometry, options, &volmorph_io::NoProgress)
}

/// [`mesh`] reporting to `progress`: two stages, the sampling of [`grid::sample_with`] (one
/// step per z-layer) and the extraction (as [`volmorph_contour::marching_cubes_with`] or
/// [`volmorph_contour::dual_contouring_with`]), stopping when cancelled. The result equals
/// [`mesh`]'s bit for bit.
///
/// # Errors
/// As [`mesh`]; [`FrepError::Cancelled`] (or [`FrepError::Contour`] wrapping
/// [`volmorph_contour::ContourError::Cancelled`]) when `progress` asks to stop.
pub fn mesh_with(
    field: &dyn Field,
    geometry: &Geometry,
    options: &MeshOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<IsoSurface, FrepError> {
    let mut vol = grid::sample_with(field, geometry, progress)?;
    if options.close {
        let [nx, ny, nz] = vol.dims();
        for (n, v) in vol.data_mut().iter_mut().enumerate() {
            let (i, j, k) = (n % nx, n / nx % ny, n / (nx * ny));
            if i == 0 || j == 0 || k == 0 || i + 1 == nx || j + 1 == ny || k + 1 == nz {
                *v = v.min(OUTSIDE);
            }
        }
    }
    Ok(match options.method {
        MeshMethod::MarchingCubes => {
            marching_cubes_with(&vol, 0.0, &McOptions::default(), progress)?
        }
        MeshMethod::DualContouring => {
            dual_contouring_with(&vol, 0.0, &DcOptions::default(), progress)?
        }
    })
}

/// What a front-end says about an extracted surface ([`SurfaceSummary::of`]): its size and
/// whether it is a closed manifold, or why not.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SurfaceSummary {
    /// Vertices of the mesh.
    pub vertices: usize,
    /// Triangles (faces) of the mesh.
    pub triangles: usize,
    /// `Ok(χ)` (the Euler characteristic) for a closed manifold, else the reasons it is not.
    pub closed: Result<i64, Vec<NotClosed>>,
}

/// Why an extracted surface is not a closed manifold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NotClosed {
    /// Edges with one face: the grid's box cuts the shape (enlarge the box, or cap the
    /// shape with [`MeshOptions::close`]).
    Boundary(usize),
    /// Edges or vertices shared by more than one sheet: features thinner than a grid cell,
    /// where one dual-contouring vertex serves several sheets (refine the grid, or use
    /// marching cubes).
    NonManifold(usize),
    /// Neither of the above, e.g. faces that disagree on orientation.
    Other,
}

impl SurfaceSummary {
    /// Validate `mesh` and summarise it.
    #[must_use]
    pub fn of(mesh: &volmorph_mesh::Mesh) -> Self {
        let report = mesh.validate();
        let closed = if report.is_closed_manifold() {
            Ok(report.euler_characteristic)
        } else {
            let mut why = Vec::new();
            if report.boundary_edges.count > 0 {
                why.push(NotClosed::Boundary(report.boundary_edges.count));
            }
            let nm = report.non_manifold_edges.count + report.non_manifold_vertices.count;
            if nm > 0 {
                why.push(NotClosed::NonManifold(nm));
            }
            if why.is_empty() {
                why.push(NotClosed::Other);
            }
            Err(why)
        };
        Self {
            vertices: mesh.vertex_count(),
            triangles: mesh.face_count(),
            closed,
        }
    }
}

impl std::fmt::Display for NotClosed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotClosed::Boundary(n) => write!(
                f,
                "{n} boundary edges: the box cuts the shape, enlarge the bounds or close the box"
            ),
            NotClosed::NonManifold(n) => write!(
                f,
                "{n} non-manifold edges/vertices: features thinner than a grid cell, refine \
                 the grid or use marching cubes"
            ),
            NotClosed::Other => write!(f, "inconsistently oriented faces"),
        }
    }
}

/// `V vertices, T triangles, closed manifold, Euler characteristic χ`, or
/// `…, not a closed manifold (reasons)`.
impl std::fmt::Display for SurfaceSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} vertices, {} triangles, ",
            self.vertices, self.triangles
        )?;
        match &self.closed {
            Ok(chi) => write!(f, "closed manifold, Euler characteristic {chi}"),
            Err(why) => {
                let why: Vec<String> = why.iter().map(ToString::to_string).collect();
                write!(f, "not a closed manifold ({})", why.join("; "))
            }
        }
    }
}

/// Options of [`render`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Box the rays are clipped to (the shape is assumed inside it), min corner.
    pub bounds_min: DVec3,
    /// Max corner of the box.
    pub bounds_max: DVec3,
    /// sRGB colour of the solid.
    pub color: [u8; 3],
    /// Background colour (straight alpha).
    pub background: [u8; 4],
    /// Light and material ([`Shading`]: light in camera coordinates).
    pub shading: Shading,
    /// Subdivision depth of the interval root search: leaf segments are
    /// `2^-max_depth` of the clipped ray (1–30).
    pub max_depth: u32,
    /// Uniform steps along a ray for fields without a tape (at least 2).
    pub fallback_steps: usize,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            bounds_min: DVec3::splat(-1.6),
            bounds_max: DVec3::splat(1.6),
            color: [222, 184, 135],
            background: [255, 255, 255, 255],
            shading: Shading::default(),
            max_depth: 14,
            fallback_steps: 1024,
        }
    }
}

impl RenderOptions {
    fn validate(&self) -> Result<Aabb, FrepError> {
        if !(1..=30).contains(&self.max_depth) || self.fallback_steps < 2 {
            return Err(FrepError::InvalidArgument(format!(
                "render depth must be 1..=30 and fallback steps ≥ 2, got {} and {}",
                self.max_depth, self.fallback_steps
            )));
        }
        self.shading.validate()?;
        Ok(Aabb::new(self.bounds_min, self.bounds_max)?)
    }
}

/// Bisection steps refining a root inside a leaf segment.
const BISECTIONS: usize = 48;

/// Ray-cast picture of the solid `f ≥ 0` (see the [module docs](self)).
///
/// The values sampled along the rays follow the rule of grid sampling
/// ([`grid::sample`]): a NaN value where a data-dependent loop of the model had not ended
/// fails the picture (casting stops at the first), and so does a field NaN at every sample.
///
/// # Errors
/// [`FrepError::InvalidArgument`] for options out of range; [`FrepError::Render`] for an
/// invalid bounding box or image size; [`FrepError::LoopBudget`] naming the loop when a
/// data-dependent loop of the model had not ended at a sampled point (its value NaN);
/// [`FrepError::AllNan`] when every sampled value is NaN.
pub fn render(
    field: &dyn Field,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<RgbaImage, FrepError> {
    render_with(field, camera, options, &volmorph_io::NoProgress)
}

/// Side of the square pixel tiles of [`render`], cast together as packets.
pub const TILE: u32 = 8;

/// Subdivision depths above [`RenderOptions::max_depth`] at which a ray segment that interval
/// arithmetic cannot decide is sampled at every leaf point at once with the batch evaluator
/// (`2^(BATCH_LEVELS + 1) + 1` points per ray) instead of being halved further. Chosen by
/// measurement on the HyperFun benchmark scenes: below it interval evaluations dominate,
/// above it samples that intervals would have skipped do.
pub const BATCH_LEVELS: u32 = 4;

/// [`render`] reporting to `progress`: one stage whose steps are the picture's rows,
/// stopping between rows of tiles when cancelled. The result equals [`render`]'s bit for bit.
///
/// # Errors
/// As [`render`]; [`FrepError::Cancelled`] when `progress` asks to stop.
pub fn render_with(
    field: &dyn Field,
    camera: &Camera,
    options: &RenderOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<RgbaImage, FrepError> {
    let bbox = options.validate()?;
    let (w, h) = (camera.width(), camera.height());
    progress.start(&format!("ray casting {w}×{h}"), u64::from(h));
    let mut img = RgbaImage::new(w, h, options.background)?;
    let lighting = options.shading.for_camera(camera)?;
    let color = options.color.map(srgb8_to_linear);
    let masks = grid::loop_masks(field);
    // Set once a NaN value is found where a loop had not ended: the picture fails then,
    // so the remaining rows are skipped as when cancelled.
    let failed = AtomicBool::new(false);
    let stop = || progress.is_cancelled() || failed.load(Ordering::Relaxed);
    let Some(tape) = field.tape() else {
        let tally = img
            .pixels_mut()
            .par_chunks_mut(w as usize)
            .enumerate()
            .map(|(y, row)| {
                let mut tally = SampleTally::new(0);
                if stop() {
                    return tally;
                }
                for (x, px) in row.iter_mut().enumerate() {
                    let ray = camera.ray(x as u32, y as u32);
                    let Some((t0, t1)) = bbox.intersect(&ray) else {
                        continue;
                    };
                    let steps = options.fallback_steps;
                    if let Some(t) = march(field, &ray, t0.max(0.0), t1, steps, &mut tally) {
                        *px = shade(field, ray.at(t), ray.dir, &lighting, color);
                    }
                }
                progress.advance(1);
                tally
            })
            .reduce(SampleTally::default, SampleTally::merge);
        progress.check()?;
        tally.verdict(field)?;
        return Ok(img);
    };
    let rows_per_band = TILE as usize * w as usize;
    let tally = img
        .pixels_mut()
        .par_chunks_mut(rows_per_band)
        .enumerate()
        .map(|(band, pixels)| {
            let y0 = band as u32 * TILE;
            let rows = (pixels.len() / w as usize) as u32;
            let mut caster = Caster::new(tape, &bbox, options.max_depth, &masks);
            for x0 in (0..w).step_by(TILE as usize) {
                if stop() {
                    return caster.tally;
                }
                let x1 = (x0 + TILE).min(w);
                caster.tile(camera, x0, y0, x1, y0 + rows);
                if caster.tally.loop_failed() {
                    failed.store(true, Ordering::Relaxed);
                }
                for (k, hit) in caster.hits.iter().enumerate() {
                    let Some((_, g)) = *hit else {
                        continue;
                    };
                    let (x, y) = (x0 + k as u32 % (x1 - x0), k as u32 / (x1 - x0));
                    let dir = caster.rays[k].dir;
                    pixels[(y * w + x) as usize] = shade_gradient(g, dir, &lighting, color);
                }
            }
            progress.advance(u64::from(rows));
            caster.tally
        })
        .reduce(SampleTally::default, SampleTally::merge);
    progress.check()?;
    tally.verdict(field)?;
    Ok(img)
}

/// The reference picture of a compiled shape (the definition [`render`] computes faster):
/// every pixel's ray, clipped to the box, is cut into `2^max_depth` leaf segments by
/// recursive halving; each leaf's start, midpoint and end are sampled in order, and the first
/// leaf with a sample `f ≥ 0` gives the hit — its start if that is the sample, else the
/// boundary found by bisection between the sample and the one before it — shaded with the
/// gradient there. No interval arithmetic: `2^(max_depth+1) + 1` evaluations per ray, for
/// tests on small pictures. NaN values are not checked (they are misses, as in [`render`]).
///
/// # Errors
/// [`FrepError::InvalidArgument`] for options out of range; [`FrepError::Render`] for an
/// invalid bounding box or image size.
pub fn render_naive(
    tape: &Tape,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<RgbaImage, FrepError> {
    let bbox = options.validate()?;
    let w = camera.width();
    let mut img = RgbaImage::new(w, camera.height(), options.background)?;
    let lighting = options.shading.for_camera(camera)?;
    let color = options.color.map(srgb8_to_linear);
    img.pixels_mut()
        .par_chunks_mut(w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            let mut regs = Vec::new();
            for (x, px) in row.iter_mut().enumerate() {
                let ray = camera.ray(x as u32, y as u32);
                let Some((t0, t1)) = bbox.intersect(&ray) else {
                    continue;
                };
                let mut leaves = Vec::new();
                dyadic_leaves(t0.max(0.0), t1, options.max_depth, &mut leaves);
                let mut f = |t: f64| tape.eval_with(ray.at(t), &mut regs);
                if let Some(t) = first_hit(&leaves, &mut f) {
                    *px = shade(tape, ray.at(t), ray.dir, &lighting, color);
                }
            }
        });
    Ok(img)
}

/// The leaf segments of `[ta, tb]` halved `depth` times, in order (recursive midpoints, the
/// arithmetic of every caster).
fn dyadic_leaves(ta: f64, tb: f64, depth: u32, out: &mut Vec<(f64, f64)>) {
    if depth == 0 {
        out.push((ta, tb));
        return;
    }
    let tm = 0.5 * (ta + tb);
    dyadic_leaves(ta, tm, depth - 1, out);
    dyadic_leaves(tm, tb, depth - 1, out);
}

/// The hit on the first leaf with a sample `f ≥ 0` (see [`render_naive`]).
fn first_hit(leaves: &[(f64, f64)], f: &mut dyn FnMut(f64) -> f64) -> Option<f64> {
    for &(ta, tb) in leaves {
        if let Some(t) = leaf_hit(ta, tb, f) {
            return Some(t);
        }
    }
    None
}

/// The rule of one leaf segment: its start if `f(ta) ≥ 0`, else bisection into the first
/// half-segment whose end has `f ≥ 0`.
fn leaf_hit(ta: f64, tb: f64, f: &mut dyn FnMut(f64) -> f64) -> Option<f64> {
    let tm = 0.5 * (ta + tb);
    if f(ta) >= 0.0 {
        return Some(ta);
    }
    for (lo, hi) in [(ta, tm), (tm, tb)] {
        if f(hi) >= 0.0 {
            return Some(bisect(f, lo, hi));
        }
    }
    None
}

/// One ray of a tile and where its search stands.
struct RayState {
    /// Index into [`Caster::rays`].
    k: usize,
    /// The segment at the current node.
    ta: f64,
    tb: f64,
}

/// Per-thread state of the tiled caster: the rays of one tile at a time, packet by packet.
///
/// A packet is a set of rays of the tile sharing a node of the recursive halving of their
/// (own) clipped segments. Its box — the hull of its rays' segment end points — is bounded
/// with intervals by the node's tape: a negative enclosure skips the node for every ray at
/// once; otherwise the tape is specialised to the box, and the packet is split into its
/// four quarters of pixels when its box is much wider across the rays than along them, else
/// halved along the rays. From [`BATCH_LEVELS`] above the leaf depth on, each ray's leaf
/// samples are evaluated together by the batch evaluator and the leaf rule applied in
/// order. Every decision uses sound enclosures or exact values of tapes specialised to boxes
/// containing the points, so each pixel's hit is the one [`render_naive`] defines.
struct Caster<'a> {
    tape: &'a Tape,
    bbox: &'a Aabb,
    max_depth: u32,
    rays: Vec<Ray>,
    /// The root segment per ray (`None`: the ray misses the box).
    segs: Vec<Option<(f64, f64)>>,
    /// Hit per ray: `t` and the gradient there (by a tape specialised to a box containing
    /// the point: the full tape's gradient, bit for bit).
    hits: Vec<Option<(f64, DVec3)>>,
    iv: IntervalScratch,
    batch: BatchScratch,
    regs: Vec<f64>,
    duals: Vec<Dual>,
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
    vals: Vec<f64>,
    leaves: Vec<(f64, f64)>,
    /// The still-running masks of the model's loops ([`grid::loop_masks`]).
    masks: &'a [Tape],
    /// Scratch of [`Caster::count_samples`]: x, y, z of the NaN samples, mask values.
    nan_points: [Vec<f64>; 4],
    /// The batch samples so far and their NaN values.
    tally: SampleTally,
}

impl<'a> Caster<'a> {
    fn new(tape: &'a Tape, bbox: &'a Aabb, max_depth: u32, masks: &'a [Tape]) -> Self {
        Self {
            tape,
            bbox,
            max_depth,
            masks,
            nan_points: Default::default(),
            tally: SampleTally::new(masks.len()),
            rays: Vec::new(),
            segs: Vec::new(),
            hits: Vec::new(),
            iv: IntervalScratch::default(),
            batch: BatchScratch::default(),
            regs: Vec::new(),
            duals: Vec::new(),
            xs: Vec::new(),
            ys: Vec::new(),
            zs: Vec::new(),
            vals: Vec::new(),
            leaves: Vec::new(),
        }
    }

    /// Cast the pixels `[x0, x1) × [y0, y1)` into [`Caster::hits`] (row-major).
    fn tile(&mut self, camera: &Camera, x0: u32, y0: u32, x1: u32, y1: u32) {
        self.rays.clear();
        self.segs.clear();
        self.hits.clear();
        let mut live = Vec::new();
        for y in y0..y1 {
            for x in x0..x1 {
                let ray = camera.ray(x, y);
                let seg = self.bbox.intersect(&ray).map(|(t0, t1)| (t0.max(0.0), t1));
                if let Some((ta, tb)) = seg {
                    live.push(RayState {
                        k: self.rays.len(),
                        ta,
                        tb,
                    });
                }
                self.rays.push(ray);
                self.segs.push(seg);
                self.hits.push(None);
            }
        }
        let w = (x1 - x0) as usize;
        let tape = self.tape;
        self.node(tape, live, w, 0);
    }

    /// Record the hit of ray `k` at `t`, with the gradient by `tape`.
    fn hit(&mut self, tape: &Tape, k: usize, t: f64) {
        let (_, g) = tape.gradient_with(self.rays[k].at(t), &mut self.duals);
        self.hits[k] = Some((t, g));
    }

    /// Search the packet `live` (its rays' segments at `depth`) with `tape`; nothing once a
    /// loop of the model is known not to have ended (the picture fails).
    fn node(&mut self, tape: &Tape, live: Vec<RayState>, w: usize, depth: u32) {
        if self.tally.loop_failed() {
            return;
        }
        let live: Vec<RayState> = live
            .into_iter()
            .filter(|r| self.hits[r.k].is_none())
            .collect();
        if live.is_empty() {
            return;
        }
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let mut along = 0.0f64;
        for r in &live {
            let ray = &self.rays[r.k];
            let (pa, pb) = (ray.at(r.ta), ray.at(r.tb));
            lo = lo.min(pa.min(pb));
            hi = hi.max(pa.max(pb));
            along = along.max((pb - pa).length());
        }
        let iv = tape.interval_with(lo, hi, &mut self.iv);
        if !iv.nan && iv.hi < 0.0 {
            return;
        }
        if !iv.nan && iv.lo >= 0.0 {
            // The solid fills the box: a ray starting its search here hits at its start.
            for r in &live {
                if self.segs[r.k].is_some_and(|(t0, _)| t0 == r.ta) {
                    self.hit(tape, r.k, r.ta);
                }
            }
        }
        let live: Vec<RayState> = live
            .into_iter()
            .filter(|r| self.hits[r.k].is_none())
            .collect();
        if live.is_empty() {
            return;
        }
        if depth + BATCH_LEVELS >= self.max_depth {
            self.sample(tape, &live, depth);
            return;
        }
        let special = tape.simplify(&self.iv);
        let tape = special.as_ref().unwrap_or(tape);
        let across = (hi - lo).length();
        if live.len() > 1 && across > 2.0 * along {
            // Split the pixels into quarters (each ray stays in one).
            let mut quarters: [Vec<RayState>; 4] = Default::default();
            let (mut nx, mut ny) = (usize::MAX, usize::MAX);
            let (mut mx, mut my) = (0usize, 0usize);
            for r in &live {
                let (x, y) = (r.k % w, r.k / w);
                nx = nx.min(x);
                ny = ny.min(y);
                mx = mx.max(x);
                my = my.max(y);
            }
            let (sx, sy) = ((nx + mx).div_ceil(2), (ny + my).div_ceil(2));
            for r in live {
                let (x, y) = (r.k % w, r.k / w);
                quarters[usize::from(x >= sx) + 2 * usize::from(y >= sy)].push(r);
            }
            for q in quarters {
                self.node(tape, q, w, depth);
            }
            return;
        }
        let (mut front, mut back) = (
            Vec::with_capacity(live.len()),
            Vec::with_capacity(live.len()),
        );
        for r in &live {
            let tm = 0.5 * (r.ta + r.tb);
            front.push(RayState {
                k: r.k,
                ta: r.ta,
                tb: tm,
            });
            back.push(RayState {
                k: r.k,
                ta: tm,
                tb: r.tb,
            });
        }
        self.node(tape, front, w, depth + 1);
        self.node(tape, back, w, depth + 1);
    }

    /// Every leaf sample of the packet's segments at once, then the leaf rule per ray.
    fn sample(&mut self, tape: &Tape, live: &[RayState], depth: u32) {
        let levels = self.max_depth.saturating_sub(depth);
        let per_ray = (1usize << (levels + 1)) + 1;
        self.xs.clear();
        self.ys.clear();
        self.zs.clear();
        let mut leaves = std::mem::take(&mut self.leaves);
        for r in live {
            leaves.clear();
            dyadic_leaves(r.ta, r.tb, levels, &mut leaves);
            let ray = &self.rays[r.k];
            for &(ta, tb) in &leaves {
                for t in [ta, 0.5 * (ta + tb)] {
                    let p = ray.at(t);
                    self.xs.push(p.x);
                    self.ys.push(p.y);
                    self.zs.push(p.z);
                }
            }
            let p = ray.at(r.tb);
            self.xs.push(p.x);
            self.ys.push(p.y);
            self.zs.push(p.z);
        }
        self.vals.resize(self.xs.len(), 0.0);
        tape.eval_batch_with(
            &self.xs,
            &self.ys,
            &self.zs,
            &mut self.vals,
            &mut self.batch,
        );
        self.count_samples();
        for (n, r) in live.iter().enumerate() {
            let v = &self.vals[n * per_ray..(n + 1) * per_ray];
            // The first sample f ≥ 0 decides: a leaf start is taken as it is, a midpoint or
            // leaf end is bisected against the sample before it (the leaf rule in order).
            let Some(j) = v.iter().position(|&f| f >= 0.0) else {
                continue;
            };
            leaves.clear();
            dyadic_leaves(r.ta, r.tb, levels, &mut leaves);
            let (leaf, half) = (j / 2, j % 2);
            let t = if j == per_ray - 1 {
                let (ta, tb) = leaves[leaves.len() - 1];
                self.bisect(tape, r.k, 0.5 * (ta + tb), tb)
            } else if half == 0 {
                if leaf == 0 {
                    leaves[0].0
                } else {
                    // The end of the leaf before: bisected in its second half.
                    let (ta, tb) = leaves[leaf - 1];
                    self.bisect(tape, r.k, 0.5 * (ta + tb), tb)
                }
            } else {
                let (ta, tb) = leaves[leaf];
                self.bisect(tape, r.k, ta, 0.5 * (ta + tb))
            };
            self.hit(tape, r.k, t);
        }
        self.leaves = leaves;
    }

    /// Add the batch just evaluated ([`Caster::vals`] at the points of `xs`, `ys`, `zs`) to
    /// the tally, with the loops still running at its NaN values (the masks evaluated in one
    /// batch at those points).
    fn count_samples(&mut self) {
        self.tally.samples += self.vals.len();
        let nan = self.vals.iter().filter(|v| v.is_nan()).count();
        if nan == 0 {
            return;
        }
        self.tally.nan += nan;
        if self.masks.is_empty() {
            return;
        }
        let mut at = std::mem::take(&mut self.nan_points);
        for c in &mut at {
            c.clear();
        }
        for (n, v) in self.vals.iter().enumerate() {
            if v.is_nan() {
                at[0].push(self.xs[n]);
                at[1].push(self.ys[n]);
                at[2].push(self.zs[n]);
            }
        }
        let [xs, ys, zs, out] = &mut at;
        out.resize(xs.len(), 0.0);
        for (m, count) in self.masks.iter().zip(&mut self.tally.running) {
            m.eval_batch_with(xs, ys, zs, out, &mut self.batch);
            *count += out.iter().filter(|&&a| grid::loop_running(a)).count();
        }
        self.nan_points = at;
    }

    fn bisect(&mut self, tape: &Tape, k: usize, lo: f64, hi: f64) -> f64 {
        let ray = self.rays[k];
        let regs = &mut self.regs;
        bisect(&mut |t| tape.eval_with(ray.at(t), regs), lo, hi)
    }
}

/// Colour of the surface point `p` seen along `dir`, base colour `color` in linear light.
fn shade(field: &dyn Field, p: DVec3, dir: DVec3, lighting: &Lighting, color: [f64; 3]) -> [u8; 4] {
    shade_gradient(field.gradient(p).1, dir, lighting, color)
}

/// Colour of a surface point with gradient `g` seen along `dir`.
fn shade_gradient(g: DVec3, dir: DVec3, lighting: &Lighting, color: [f64; 3]) -> [u8; 4] {
    let n = (-g).try_normalize().unwrap_or(-dir);
    let c = lighting.shade(color, n, -dir);
    [
        linear_to_srgb8(c[0]),
        linear_to_srgb8(c[1]),
        linear_to_srgb8(c[2]),
        255,
    ]
}

/// Refine `f(lo) < 0 ≤ f(hi)` to the boundary; returns a point with `f ≥ 0`.
fn bisect(f: &mut dyn FnMut(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    for _ in 0..BISECTIONS {
        let m = 0.5 * (lo + hi);
        if f(m) >= 0.0 {
            hi = m;
        } else {
            lo = m;
        }
    }
    hi
}

/// Uniform stepping for fields without a tape, every value counted in `tally`.
fn march(
    field: &dyn Field,
    ray: &Ray,
    ta: f64,
    tb: f64,
    steps: usize,
    tally: &mut SampleTally,
) -> Option<f64> {
    let mut f = |t: f64| {
        let v = field.value(ray.at(t));
        tally.samples += 1;
        tally.nan += usize::from(v.is_nan());
        v
    };
    if f(ta) >= 0.0 {
        return Some(ta);
    }
    let dt = (tb - ta) / steps as f64;
    let mut prev = ta;
    for s in 1..=steps {
        let t = ta + dt * s as f64;
        if f(t) >= 0.0 {
            return Some(bisect(&mut f, prev, t));
        }
        prev = t;
    }
    None
}

/// The time `t = i/(frames − 1)` of frame `i` of an animation of `frames` (`t = 0` for a single
/// frame).
pub(crate) fn frame_time(i: usize, frames: usize) -> f64 {
    if frames == 1 {
        0.0
    } else {
        i as f64 / (frames - 1) as f64
    }
}

/// Render `frames` pictures of `field_at(t)` for `t = i/(frames − 1)` (`t = 0` for a single
/// frame) and write them as `dir/{prefix}{i:04}.png`; returns the paths in order.
///
/// # Errors
/// [`FrepError::InvalidArgument`] for zero frames, errors of `field_at`, [`render`] and the
/// PNG writer (atomic writes: a failed frame leaves no partial file).
pub fn render_animation(
    frames: usize,
    field_at: &dyn Fn(f64) -> Result<Box<dyn Field>, FrepError>,
    camera: &Camera,
    options: &RenderOptions,
    dir: &Path,
    prefix: &str,
) -> Result<Vec<PathBuf>, FrepError> {
    render_animation_with(
        frames,
        field_at,
        camera,
        options,
        dir,
        prefix,
        &volmorph_io::NoProgress,
    )
}

/// [`render_animation`] reporting to `progress`: one stage of `frames × height` steps (the
/// rows of every frame). When cancelled it stops between rows and removes the frames it had
/// already written, so a cancelled call leaves no output. The frames equal
/// [`render_animation`]'s bit for bit.
///
/// # Errors
/// As [`render_animation`]; [`FrepError::Cancelled`] when `progress` asks to stop.
pub fn render_animation_with(
    frames: usize,
    field_at: &dyn Fn(f64) -> Result<Box<dyn Field>, FrepError>,
    camera: &Camera,
    options: &RenderOptions,
    dir: &Path,
    prefix: &str,
    progress: &dyn volmorph_io::Progress,
) -> Result<Vec<PathBuf>, FrepError> {
    if frames == 0 {
        return Err(FrepError::InvalidArgument(
            "an animation needs at least one frame".into(),
        ));
    }
    progress.start(
        &format!("rendering {frames} frames"),
        (frames as u64).saturating_mul(u64::from(camera.height())),
    );
    let rows = volmorph_io::Within(progress);
    let mut out = Vec::with_capacity(frames);
    let mut go = || -> Result<(), FrepError> {
        for i in 0..frames {
            let field = field_at(frame_time(i, frames))?;
            let img = render_with(field.as_ref(), camera, options, &rows)?;
            let path = dir.join(format!("{prefix}{i:04}.png"));
            write_png_rgba(&path, &img)?;
            out.push(path);
        }
        Ok(())
    };
    match go() {
        Ok(()) => Ok(out),
        Err(e @ FrepError::Cancelled(_)) => {
            for p in &out {
                // Best effort: a frame that cannot be removed is left, the error still says
                // the animation was cancelled.
                let _ = std::fs::remove_file(p);
            }
            Err(e)
        }
        Err(e) => Err(e),
    }
}

/// The pictures of [`render_animation`] kept in memory instead of written, in order (for a
/// single animation file, e.g. `volmorph_render::write_animation`).
///
/// # Errors
/// [`FrepError::InvalidArgument`] for zero frames, errors of `field_at` and [`render`].
pub fn render_frames(
    frames: usize,
    field_at: &dyn Fn(f64) -> Result<Box<dyn Field>, FrepError>,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<Vec<RgbaImage>, FrepError> {
    if frames == 0 {
        return Err(FrepError::InvalidArgument(
            "an animation needs at least one frame".into(),
        ));
    }
    render_frames_with(frames, field_at, camera, options, &volmorph_io::NoProgress)
}

/// [`render_frames`] reporting one step per picture row to `progress` (the total announced
/// is `frames × camera height`), and stopping with [`FrepError::Cancelled`] when asked.
///
/// # Errors
/// As [`render_frames`], and [`FrepError::Cancelled`].
pub fn render_frames_with(
    frames: usize,
    field_at: &dyn Fn(f64) -> Result<Box<dyn Field>, FrepError>,
    camera: &Camera,
    options: &RenderOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<Vec<RgbaImage>, FrepError> {
    if frames == 0 {
        return Err(FrepError::InvalidArgument(
            "an animation needs at least one frame".into(),
        ));
    }
    progress.start(
        &format!("rendering {frames} frames"),
        (frames as u64).saturating_mul(u64::from(camera.height())),
    );
    let rows = volmorph_io::Within(progress);
    (0..frames)
        .map(|i| {
            let field = field_at(frame_time(i, frames))?;
            render_with(field.as_ref(), camera, options, &rows)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compile_source;
    use volmorph_render::Projection;

    fn tape(src: &str) -> Tape {
        Tape::new(&compile_source(src, &Default::default()).unwrap())
    }

    #[test]
    fn sphere_mesh_is_closed_and_has_the_right_volume() {
        let t = tape("m(x[3], a[1]) { array c[3]; c = [0, 0, 0]; m = hfSphere(x, c, 1); }");
        let g = grid::box_geometry(DVec3::splat(-1.3), DVec3::splat(1.3), [32; 3]).unwrap();
        for method in [MeshMethod::MarchingCubes, MeshMethod::DualContouring] {
            let s = mesh(
                &t,
                &g,
                &MeshOptions {
                    method,
                    close: false,
                },
            )
            .unwrap();
            let report = s.mesh.validate();
            assert!(report.is_closed_manifold(), "{method:?}");
            let v = s.mesh.signed_volume();
            assert!(
                (v / (4.0 / 3.0 * std::f64::consts::PI) - 1.0).abs() < 0.03,
                "{v}"
            );
        }
        // A block cut by the box: closed only when capped.
        let b =
            tape("m(x[3], a[1]) { array v[3]; v = [-2, -0.5, -0.5]; m = hfBlock(x, v, 4, 1, 1); }");
        let g = grid::box_geometry(DVec3::splat(-1.0), DVec3::splat(1.0), [24; 3]).unwrap();
        let open = mesh(&b, &g, &MeshOptions::default()).unwrap();
        assert!(!open.mesh.validate().is_closed_manifold());
        let closed = mesh(
            &b,
            &g,
            &MeshOptions {
                close: true,
                ..Default::default()
            },
        )
        .unwrap();
        assert!(closed.mesh.validate().is_closed_manifold());
    }

    /// The tiled, interval-pruned caster gives the picture of the brute-force per-pixel
    /// reference, pixel for pixel, on models with R-functions, `min`/`max` (pruned by
    /// specialisation), data-dependent selects and a thin feature, in perspective and
    /// orthographic views, with pictures whose size is not a multiple of the tile.
    #[test]
    fn render_equals_the_per_pixel_reference() {
        let models = [
            "m(x[3], a[1]) { array c[3]; array v[3]; c = [0, 0, 0]; v = [-0.9, -0.9, -0.9];
               m = hfBlock(x, v, 1.8, 1.8, 1.8) \\ hfSphere(x, c, 1.1); }",
            "m(x[3], a[1]) { a1 = sqrt((x[1]-0.4)^2 + x[2]^2 + x[3]^2) - 0.6;
               b1 = sqrt((x[1]+0.4)^2 + x[2]^2 + x[3]^2) - 0.6;
               h = max(0.3 - abs(a1 - b1), 0) / 0.3;
               g = min(a1, b1) - h*h*h*0.05; m = max(-g, 0.004 - abs(x[3] - 0.95)); }",
            "m(x[3], a[1]) { if x[1] > 0.1 then m = 1 - x[1]^2 - x[2]^2 - x[3]^2;
               else m = 0.6 - abs(x[2]) - abs(x[3]); endif; }",
            "m(x[3], a[1]) { g = sin(4*x[1])*cos(4*x[2]) + sin(4*x[2])*cos(4*x[3])
               + sin(4*x[3])*cos(4*x[1]); m = min(0.3 - abs(g), 1.2 - max(abs(x[1]), abs(x[2]), abs(x[3]))); }",
        ];
        let opts = RenderOptions {
            bounds_min: DVec3::splat(-1.25),
            bounds_max: DVec3::splat(1.25),
            max_depth: 9,
            ..Default::default()
        };
        for (i, src) in models.iter().enumerate() {
            let t = tape(src);
            for projection in [
                Projection::Perspective { fov_y: 0.7 },
                Projection::Orthographic { view_height: 2.6 },
            ] {
                let cam = Camera::look_at(
                    DVec3::new(3.2, -2.1, 1.7),
                    DVec3::ZERO,
                    DVec3::Z,
                    projection,
                    37,
                    29,
                )
                .unwrap();
                let fast = render(&t, &cam, &opts).unwrap();
                let naive = render_naive(&t, &cam, &opts).unwrap();
                let hits = naive
                    .pixels()
                    .iter()
                    .filter(|p| **p != opts.background)
                    .count();
                assert!(hits > 50, "model {i}: {hits} pixels");
                for (k, (a, b)) in fast.pixels().iter().zip(naive.pixels()).enumerate() {
                    assert_eq!(a, b, "model {i} {projection:?}: pixel {k}");
                }
            }
        }
    }

    #[test]
    fn render_finds_thin_features() {
        // A slab 0.002 thick facing the camera: stepping with 64 samples would miss it,
        // interval subdivision does not.
        let t = tape("m(x[3], a[1]) { m = 0.001 - abs(x[3] - 0.123); }");
        let cam = Camera::look_at(
            DVec3::new(0.0, 0.0, 5.0),
            DVec3::ZERO,
            DVec3::Y,
            Projection::Orthographic { view_height: 2.0 },
            16,
            16,
        )
        .unwrap();
        let o = RenderOptions {
            bounds_min: DVec3::splat(-1.0),
            bounds_max: DVec3::splat(1.0),
            ..Default::default()
        };
        let img = render(&t, &cam, &o).unwrap();
        assert!(
            img.pixels().iter().all(|p| *p != o.background),
            "slab missed"
        );
        // The same slab seen through a field without a tape and 64 steps is missed.
        struct Opaque(Tape);
        impl Field for Opaque {
            fn value(&self, p: DVec3) -> f64 {
                self.0.eval(p)
            }
        }
        let img = render(
            &Opaque(t),
            &cam,
            &RenderOptions {
                fallback_steps: 64,
                ..o
            },
        )
        .unwrap();
        assert!(img.pixels().iter().all(|p| *p == o.background));
    }
}
