//! Volumes rendered as deformed by a space map, without resampling them (McPhail §5.5.2,
//! §5.5.4).
//!
//! The map is sampled once on a coarse grid (a [`SampledMap`], for example 33³ nodes; the
//! "RGB texture" of §5.5.2) and interpolated trilinearly along every ray, so each sample costs
//! one trilinear interpolation of the grid and one of the volume instead of an evaluation of
//! the map. Editing a handle then changes only the grid (one multiply-add per node with
//! `volmorph_deform::HandleGrid`), and the next picture shows the new deformation.
//!
//! # Direction
//!
//! The map is a **pull-back**: the picture shows, at each point `x` of the displayed region,
//! the volume's content at `map(x)`. To see a model deformed by a push-forward `f`, give the
//! inverse of `f` (for handle deformations: the map built from the handles with sources and
//! targets swapped, as `volmorph handles warp` does for volumes).
//!
//! # Displayed region and culling
//!
//! Rays are clipped to the box of the grid's nodes (for [`DeformedView::from_map`], the box
//! of the volume's voxel centres, so the picture frames like the undeformed one). Where the
//! map leads outside the volume the sample is transparent. A grid cell is skipped when the
//! volume's octree shows nothing visible in the box of the volume positions of its eight
//! nodes: trilinear interpolation keeps every point of the cell inside that box, so culling
//! changes no sample.
//!
//! Shading uses the gradient of the deformed field, `J_mapᵀ ∇V`, with the Jacobian of the
//! trilinear interpolant.

use std::sync::atomic::{AtomicU8, Ordering};

use glam::{DMat3, Mat3, Vec3, Vec3A, Vec4Swizzles};
use rayon::prelude::*;
use volmorph_deform::{SampledMap, SpaceMap};
use volmorph_volume::Geometry;

use crate::camera::Camera;
use crate::dvr::{Accumulator, Caster, Dda, DvrRenderer, DvrVolume, RayResult, RenderMode};
use crate::error::RenderError;
use crate::geometry::Ray;
use crate::image::RgbaImage;
use crate::shading::Lighting;

/// A pull-back map sampled on a coarse grid, with every node's position in the index space
/// of one [`DvrVolume`] (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct DeformedView {
    grid: Geometry,
    /// World → grid index, linear part.
    to_grid: DMat3,
    /// Per node: the volume index of `map(node)`.
    nodes: Vec<Vec3>,
    /// Per cell (indexed by its low corner node): the box of its eight nodes' volume indices.
    cell_box: Vec<(Vec3, Vec3)>,
    /// The geometry of the volume the node positions refer to.
    volume_geometry: Geometry,
}

impl DeformedView {
    /// The view of `volume` through the sampled pull-back `map`.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when the map's grid has fewer than 2 nodes along an
    /// axis or an invalid geometry.
    pub fn new(volume: &DvrVolume, map: &SampledMap) -> Result<Self, RenderError> {
        let grid = *map.grid();
        grid.validate()
            .map_err(|e| RenderError::invalid(format!("deformation grid: {e}")))?;
        if grid.dims.iter().any(|&d| d < 2) {
            return Err(RenderError::invalid(format!(
                "a deformation grid needs at least 2 nodes per axis, got {:?}",
                grid.dims
            )));
        }
        let coarse: Vec<Vec3> = map
            .positions()
            .par_iter()
            .map(|&p| volume.index_of(p).as_vec3())
            .collect();
        let nodes = coarse;
        let [nx, ny, nz] = grid.dims;
        let mut cell_box = vec![(Vec3::ZERO, Vec3::ZERO); nodes.len()];
        cell_box
            .par_chunks_mut(nx * ny)
            .enumerate()
            .take(nz - 1)
            .for_each(|(k, slab)| {
                for j in 0..ny - 1 {
                    for i in 0..nx - 1 {
                        let o = i + nx * (j + ny * k);
                        let c = corners(&nodes, o, nx, nx * ny);
                        let lo = c.iter().fold(Vec3::INFINITY, |a, &b| a.min(b));
                        let hi = c.iter().fold(Vec3::NEG_INFINITY, |a, &b| a.max(b));
                        slab[i + nx * j] = (lo, hi);
                    }
                }
            });
        Ok(Self {
            to_grid: grid.index_to_physical_matrix().inverse(),
            grid,
            nodes,
            cell_box,
            volume_geometry: *volume.geometry(),
        })
    }

    /// Sample the pull-back `map` on `nodes` nodes per axis spanning the voxel centres of
    /// `volume` (through [`SpaceMap::apply_grid`], so maps with grid fast paths use them),
    /// and make the view.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for fewer than 2 nodes per axis or a map that gives
    /// non-finite positions; as [`DeformedView::new`].
    pub fn from_map<M: SpaceMap + ?Sized>(
        volume: &DvrVolume,
        map: &M,
        nodes: [usize; 3],
    ) -> Result<Self, RenderError> {
        Self::from_map_over(volume, map, volume.geometry(), nodes)
    }

    /// Like [`DeformedView::from_map`], with the grid spanning the voxel centres of `region`
    /// instead of the volume's (the displayed region, for example another volume's box: the
    /// quality view shows a target volume pulled back over its source).
    ///
    /// # Errors
    /// As [`DeformedView::from_map`].
    pub fn from_map_over<M: SpaceMap + ?Sized>(
        volume: &DvrVolume,
        map: &M,
        region: &Geometry,
        nodes: [usize; 3],
    ) -> Result<Self, RenderError> {
        if nodes.iter().any(|&n| n < 2) {
            return Err(RenderError::invalid(format!(
                "a deformation grid needs at least 2 nodes per axis, got {nodes:?}"
            )));
        }
        let deform = |e: volmorph_deform::DeformError| {
            RenderError::invalid(format!("cannot sample the deformation: {e}"))
        };
        let grid = SampledMap::covering(region, nodes).map_err(deform)?;
        let sampled = SampledMap::from_map(map, grid).map_err(deform)?;
        Self::new(volume, &sampled)
    }

    /// The map's grid.
    #[must_use]
    pub fn grid(&self) -> &Geometry {
        &self.grid
    }

    /// The grid cell containing grid position `c` (continuous grid index, clamped to the
    /// grid box): its low corner node and the fractions within it.
    #[inline(always)]
    fn locate(&self, c: Vec3) -> (usize, Vec3) {
        locate_in(self.grid.dims, c)
    }

    /// The pull-back's volume index at grid position `c`.
    #[inline(always)]
    fn map_at(&self, c: Vec3) -> Vec3 {
        let (o, f) = self.locate(c);
        let [nx, ny, _] = self.grid.dims;
        trilinear(&corners(&self.nodes, o, nx, nx * ny), f)
    }

    /// Jacobian of the pull-back's volume index with respect to world position at grid
    /// position `c`.
    #[inline(always)]
    fn jacobian_at(&self, c: Vec3, to_grid: Mat3) -> Mat3 {
        let (o, f) = self.locate(c);
        let [nx, ny, _] = self.grid.dims;
        cell_jacobian(&corners(&self.nodes, o, nx, nx * ny), f) * to_grid
    }

    /// Whether the volume shows anything under `visible` in grid cell `n` (by the box of its
    /// nodes' positions, through the volume's octree), remembered in `memo` (0: not yet
    /// known, 1: visible, 2: not) so that each cell a picture's rays reach is classified once.
    #[inline(always)]
    pub(crate) fn cell_visible(
        &self,
        n: usize,
        volume: &DvrVolume,
        memo: &[AtomicU8],
        visible: &impl Fn(u16, u16) -> bool,
    ) -> bool {
        match memo[n].load(Ordering::Relaxed) {
            1 => true,
            2 => false,
            _ => {
                let (lo, hi) = self.cell_box[n];
                let v = volume
                    .octree()
                    .range_over(lo.to_array(), hi.to_array())
                    .is_some_and(|(mn, mx)| visible(mn, mx));
                memo[n].store(if v { 1 } else { 2 }, Ordering::Relaxed);
                v
            }
        }
    }

    /// A fresh memo for [`DeformedView::cell_visible`].
    pub(crate) fn visibility_memo(&self) -> Vec<AtomicU8> {
        (0..self.cell_box.len()).map(|_| AtomicU8::new(0)).collect()
    }

    /// Check that the view was made for `volume`.
    pub(crate) fn check_volume(&self, volume: &DvrVolume) -> Result<(), RenderError> {
        if &self.volume_geometry != volume.geometry() {
            return Err(RenderError::invalid(
                "the deformed view was made for a volume with another geometry",
            ));
        }
        Ok(())
    }

    /// The ray in grid index space: origin, direction, clipped interval.
    pub(crate) fn ray_in_grid(&self, ray: &Ray) -> (Vec3, Vec3, Vec3) {
        let o = (self.to_grid * (ray.origin - self.grid.origin)).as_vec3();
        let d = (self.to_grid * ray.dir).as_vec3();
        let hi = Vec3::new(
            (self.grid.dims[0] - 1) as f32,
            (self.grid.dims[1] - 1) as f32,
            (self.grid.dims[2] - 1) as f32,
        );
        (o, d, hi)
    }

    pub(crate) fn to_grid(&self) -> DMat3 {
        self.to_grid
    }

    /// The world positions of the eight nodes of grid cell `n` (low corner node `n`).
    pub(crate) fn cell_world_corners(&self, n: usize) -> [glam::DVec3; 8] {
        let [nx, ny, _] = self.grid.dims;
        let (i, j, k) = (n % nx, n / nx % ny, n / (nx * ny));
        std::array::from_fn(|c| {
            let idx = glam::DVec3::new(
                (i + (c & 1)) as f64,
                (j + (c >> 1 & 1)) as f64,
                (k + (c >> 2)) as f64,
            );
            self.grid.index_to_physical(idx)
        })
    }

    /// The box of the map's volume indices over grid cell `n`.
    pub(crate) fn cell_box(&self, n: usize) -> (Vec3, Vec3) {
        self.cell_box[n]
    }

    /// Walk the samples `t = kΔ` of the ray (grid index space `o + t·d`) through the grid cells
    /// for which `keep(cell)` holds, calling `visit(c, u, t, jacobian)` with the grid position
    /// `c`, the map's volume index `u` and the Jacobian of the map (per grid unit) within the
    /// current cell; stops when `visit` returns `true`.
    #[inline(always)]
    pub(crate) fn walk(
        &self,
        (o, d): (Vec3, Vec3),
        (t0, t1): (f32, f32),
        step: f32,
        keep: impl Fn(usize) -> bool,
        mut visit: impl FnMut(Vec3, Vec3, f32, &dyn Fn(Vec3) -> Mat3) -> bool,
    ) {
        let [nx, ny, _] = self.grid.dims;
        let inv_step = 1.0 / step;
        for (cell, ta, tb) in Dda::new(o, d, t0, t1, 1.0, self.grid.dims.map(|n| n - 1)) {
            let n = cell[0] + nx * (cell[1] + ny * cell[2]);
            if !keep(n) {
                continue;
            }
            let k = corners(&self.nodes, n, nx, nx * ny);
            let base = Vec3::new(cell[0] as f32, cell[1] as f32, cell[2] as f32);
            // Along the ray the trilinear interpolant is a cubic in τ = t − ta.
            let cubic = Cubic::along(&k, o + d * ta - base, d);
            let mut s = (ta * inv_step).ceil() as u32;
            loop {
                let t = s as f32 * step;
                if t >= tb {
                    break;
                }
                let c = o + d * t;
                let jac = |c: Vec3| cell_jacobian(&k, (c - base).clamp(Vec3::ZERO, Vec3::ONE));
                if visit(c, cubic.at(t - ta), t, &jac) {
                    return;
                }
                s += 1;
            }
        }
    }
}

/// A trilinear interpolant restricted to the line `p + τ·v` (cell-local coordinates): a
/// cubic polynomial in `τ` per component, evaluated by Horner's rule. Kept in `Vec3A` (one
/// vector operation per step; the same operations per lane as in `Vec3`, so the same bits).
struct Cubic([Vec3A; 4]);

impl Cubic {
    /// The cubic of the cell with corners `k` (x fastest) along `p + τ·v`.
    #[inline(always)]
    fn along(k: &[Vec3; 8], p: Vec3, v: Vec3) -> Self {
        let k = k.map(Vec3A::from);
        // Multilinear form f = g + gx·x + gy·y + gz·z + gxy·xy + gxz·xz + gyz·yz + gxyz·xyz.
        let g = k[0];
        let gx = k[1] - k[0];
        let gy = k[2] - k[0];
        let gz = k[4] - k[0];
        let gxy = k[3] - k[2] - k[1] + k[0];
        let gxz = k[5] - k[4] - k[1] + k[0];
        let gyz = k[6] - k[4] - k[2] + k[0];
        let gxyz = k[7] - k[6] - k[5] + k[4] - k[3] + k[2] + k[1] - k[0];
        let (x0, y0, z0) = (p.x, p.y, p.z);
        let (x1, y1, z1) = (v.x, v.y, v.z);
        let c0 = g
            + gx * x0
            + gy * y0
            + gz * z0
            + gxy * (x0 * y0)
            + gxz * (x0 * z0)
            + gyz * (y0 * z0)
            + gxyz * (x0 * y0 * z0);
        let c1 = gx * x1
            + gy * y1
            + gz * z1
            + gxy * (x0 * y1 + x1 * y0)
            + gxz * (x0 * z1 + x1 * z0)
            + gyz * (y0 * z1 + y1 * z0)
            + gxyz * (x1 * y0 * z0 + x0 * y1 * z0 + x0 * y0 * z1);
        let c2 = gxy * (x1 * y1)
            + gxz * (x1 * z1)
            + gyz * (y1 * z1)
            + gxyz * (x1 * y1 * z0 + x1 * y0 * z1 + x0 * y1 * z1);
        let c3 = gxyz * (x1 * y1 * z1);
        Self([c0, c1, c2, c3])
    }

    #[inline(always)]
    fn at(&self, tau: f32) -> Vec3 {
        let [c0, c1, c2, c3] = self.0;
        Vec3::from(((c3 * tau + c2) * tau + c1) * tau + c0)
    }
}

/// The cell of a grid of `dims` nodes containing grid position `c` (clamped to the grid
/// box): the offset of its low corner node and the fractions within it.
#[inline(always)]
fn locate_in([nx, ny, nz]: [usize; 3], c: Vec3) -> (usize, Vec3) {
    let cell = |x: f32, n: usize| -> (usize, f32) {
        let x = x.clamp(0.0, (n - 1) as f32);
        let i = (x as i32).clamp(0, n as i32 - 2) as usize;
        (i, x - i as f32)
    };
    let (i, fx) = cell(c.x, nx);
    let (j, fy) = cell(c.y, ny);
    let (k, fz) = cell(c.z, nz);
    (i + nx * (j + ny * k), Vec3::new(fx, fy, fz))
}

/// The eight nodes of the cell whose low corner is node `o` (x fastest).
#[inline(always)]
fn corners(nodes: &[Vec3], o: usize, sy: usize, sz: usize) -> [Vec3; 8] {
    [
        nodes[o],
        nodes[o + 1],
        nodes[o + sy],
        nodes[o + sy + 1],
        nodes[o + sz],
        nodes[o + sz + 1],
        nodes[o + sz + sy],
        nodes[o + sz + sy + 1],
    ]
}

/// Derivative of the trilinear interpolant of corners `k` (x fastest) with respect to the
/// fractions, at fractions `f` (columns ∂/∂x, ∂/∂y, ∂/∂z).
#[inline(always)]
fn cell_jacobian(k: &[Vec3; 8], f: Vec3) -> Mat3 {
    let (u, v, w) = (f.x, f.y, f.z);
    let (u0, v0, w0) = (1.0 - u, 1.0 - v, 1.0 - w);
    let dx = ((k[1] - k[0]) * v0 + (k[3] - k[2]) * v) * w0
        + ((k[5] - k[4]) * v0 + (k[7] - k[6]) * v) * w;
    let dy = ((k[2] - k[0]) * u0 + (k[3] - k[1]) * u) * w0
        + ((k[6] - k[4]) * u0 + (k[7] - k[5]) * u) * w;
    let dz = ((k[4] - k[0]) * u0 + (k[5] - k[1]) * u) * v0
        + ((k[6] - k[2]) * u0 + (k[7] - k[3]) * u) * v;
    Mat3::from_cols(dx, dy, dz)
}

/// Trilinear interpolation of eight corner vectors (x fastest) at fractions `f`.
#[inline(always)]
fn trilinear(k: &[Vec3; 8], f: Vec3) -> Vec3 {
    let x00 = k[0].lerp(k[1], f.x);
    let x10 = k[2].lerp(k[3], f.x);
    let x01 = k[4].lerp(k[5], f.x);
    let x11 = k[6].lerp(k[7], f.x);
    x00.lerp(x10, f.y).lerp(x01.lerp(x11, f.y), f.z)
}

/// The rays of a deformed picture.
struct Deformed<'r, 'a> {
    renderer: &'r DvrRenderer<'a>,
    view: &'r DeformedView,
    memo: &'r [AtomicU8],
    lighting: Option<Lighting>,
}

impl Caster for Deformed<'_, '_> {
    #[inline(always)]
    fn cast(&self, ray: &Ray) -> RayResult {
        self.renderer
            .cast_deformed(self.view, self.memo, ray, self.lighting.as_ref())
    }
}

impl DvrRenderer<'_> {
    /// The picture `camera` takes of the volume as deformed by `view` (see the [module
    /// docs](crate::deformed)).
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when `view` was made for a volume of another geometry
    /// or the shading is invalid; [`RenderError::Size`] for an oversized picture.
    pub fn render_deformed(
        &self,
        view: &DeformedView,
        camera: &Camera,
    ) -> Result<RgbaImage, RenderError> {
        view.check_volume(self.volume)?;
        let lighting = self.lighting(camera)?;
        let memo = view.visibility_memo();
        self.render_rows(
            camera,
            &Deformed {
                renderer: self,
                view,
                memo: &memo,
                lighting,
            },
        )
    }

    /// Cast one ray through the deformed volume.
    #[inline(always)]
    fn cast_deformed(
        &self,
        view: &DeformedView,
        memo: &[AtomicU8],
        ray: &Ray,
        lighting: Option<&Lighting>,
    ) -> RayResult {
        let vol = self.volume;
        let (o, d, hi) = view.ray_in_grid(ray);
        let Some((t0, t1)) = self.clip_interval(ray, o, d, hi) else {
            return RayResult::EMPTY;
        };
        let to_grid = view.to_grid().as_mat3();
        let to_grid_t = to_grid.transpose();
        let mut acc = Accumulator::new(self, lighting, -ray.dir.as_vec3());
        let skip = self.options.skip_empty_space;
        let mip = matches!(self.options.mode, RenderMode::MaximumIntensity);
        let vol_hi = vol.index_box();
        let inside = |u: Vec3| u.cmpge(Vec3::ZERO).all() && u.cmple(vol_hi).all();
        // Composite pictures with shading read code and gradient together.
        let shaded = acc.lighting.is_some() && matches!(self.options.mode, RenderMode::Composite);
        // The walk of `DeformedView::walk`, written out so that the whole ray loop inlines
        // into the row kernel (a closure per sample was compiled apart).
        let step = self.step;
        let inv_step = 1.0 / step;
        let [nx, ny, _] = view.grid.dims;
        'ray: for (gcell, ta, tb) in Dda::new(o, d, t0, t1, 1.0, view.grid.dims.map(|n| n - 1)) {
            let n = gcell[0] + nx * (gcell[1] + ny * gcell[2]);
            if skip
                && !mip
                && !view.cell_visible(n, vol, memo, &|mn, mx| self.range_visible(mn, mx))
            {
                continue;
            }
            let k = corners(&view.nodes, n, nx, nx * ny);
            let base = Vec3::new(gcell[0] as f32, gcell[1] as f32, gcell[2] as f32);
            // Along the ray the trilinear interpolant is a cubic in τ = t − ta.
            let cubic = Cubic::along(&k, o + d * ta - base, d);
            let jac = |c: Vec3| cell_jacobian(&k, (c - base).clamp(Vec3::ZERO, Vec3::ONE));
            let mut s = (ta * inv_step).ceil() as u32;
            loop {
                let t = s as f32 * step;
                if t >= tb {
                    break;
                }
                s += 1;
                let u = cubic.at(t - ta);
                if !inside(u) {
                    continue;
                }
                let (cell, f) = vol.cell_of(u);
                if skip && !mip && !self.cells_visible(cell) {
                    continue;
                }
                // The grid position, for the Jacobian (only shaded samples need it).
                let c = o + d * t;
                let stop = if shaded {
                    let smp = vol.sample_shaded(cell, f);
                    // (J·G)ᵀ∇ as Gᵀ(Jᵀ∇): two products with a vector instead of one of two
                    // matrices.
                    acc.composite(smp.x, || to_grid_t * (jac(c).transpose() * smp.yzw()))
                } else {
                    acc.add(
                        vol.sample_cell(cell, f),
                        || {
                            let p = view.map_at(c - d * step);
                            (t - step >= t0 && inside(p)).then(|| vol.sample(p))
                        },
                        |sb| {
                            if sb == 0.0 {
                                (jac(c) * to_grid).transpose() * vol.gradient_cell(cell, f)
                            } else {
                                let c = c - d * (step * sb);
                                view.jacobian_at(c, to_grid).transpose()
                                    * vol.gradient(view.map_at(c))
                            }
                        },
                    )
                };
                if stop {
                    break 'ray;
                }
            }
        }
        acc.finish(self)
    }
}
