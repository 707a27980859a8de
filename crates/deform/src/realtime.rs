//! Deformations sampled on a coarse grid and updated in real time as target handles move
//! (McPhail's thesis §5.5.2, §5.5.4).
//!
//! * [`SampledMap`] — any [`SpaceMap`] evaluated once at the nodes of a coarse grid (e.g. 32³
//!   over a 512² × 300 CT volume) and interpolated trilinearly in between: the "RGB texture"
//!   of §5.5.2. Resampling a volume through it costs one trilinear lookup per voxel instead of
//!   one evaluation of the full map. The exact per-voxel mode is simply the original map.
//! * [`LinearHandleMap`] — maps that are affine in their target handles,
//!   `f(v) = b(v) + Σ_k c_k(v) t_k` with `b` and `c_k` independent of the targets `t_k`
//!   (affine MLS §5.4.2, frame MLS §5.4.3).
//! * [`HandleGrid`] — a [`SampledMap`] of such a map plus every node's coefficients `c_k(v)`,
//!   computed once per set of **source** handles. Moving a target then costs one multiply-add
//!   per grid node; [`HandleGrid::select`] stores `f(v) − c_i(v) t_i` for the picked handle so
//!   that each drag step writes `f(v) = stored + c_i(v) t_i` exactly, as §5.5.4 describes.
//!
//! # Outside the grid
//!
//! [`SampledMap`] extends the map beyond its grid by a constant displacement: a point is
//! clamped to the grid's index box, and the displacement found there is added to the point
//! itself. The extension is continuous; its Jacobian is the identity along clamped axes.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_volume::Geometry;

use crate::map::check_len;
use crate::{DeformError, SpaceMap};

/// A map that is affine in its target vectors: `f(v) = b(v) + Σ_k c_k(v) t_k`, where neither
/// the base `b` nor the coefficients `c_k` depend on the targets `t_k` (which may be handle
/// positions, frame axes, segment end points: anything the user moves). See the
/// [module docs](self).
pub trait LinearHandleMap: SpaceMap {
    /// The current target vectors `t_k`, in the order of the coefficients.
    fn target_vectors(&self) -> Vec<DVec3>;

    /// Replace the target vectors (same order and length as
    /// [`target_vectors`](Self::target_vectors)).
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for a wrong length, [`DeformError::NonFinite`] for a
    /// NaN/infinite vector.
    fn set_target_vectors(&mut self, targets: &[DVec3]) -> Result<(), DeformError>;

    /// Write the coefficients `c_k(v)` into `out[..K]` (`K` = number of target vectors; only
    /// `min(out.len(), K)` are written) and return the base `b(v)`, so that
    /// `f(v) = b(v) + Σ_k c_k(v) t_k`.
    fn coefficients_into(&self, v: DVec3, out: &mut [f64]) -> DVec3;
}

/// A map sampled at the nodes of a grid and interpolated trilinearly; see the
/// [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct SampledMap {
    grid: Geometry,
    positions: Vec<DVec3>,
    to_index: DMat3,
    from_index: DMat3,
}

impl SampledMap {
    /// Sample `map` at every node of `grid` (through [`SpaceMap::apply_grid`], so maps with
    /// grid fast paths use them).
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid grid (zero dims, bad spacing or direction),
    /// [`DeformError::Io`] if the node count is beyond the allocation limit.
    pub fn from_map<M: SpaceMap + ?Sized>(map: &M, grid: Geometry) -> Result<Self, DeformError> {
        grid.validate()?;
        let n = volmorph_io::checked_len(&grid.dims, std::mem::size_of::<DVec3>())?;
        let mut positions = vec![DVec3::ZERO; n];
        map.apply_grid(&grid, &mut positions)?;
        Self::from_positions(grid, positions)
    }

    /// Wrap mapped node positions (`positions[i + nx·(j + ny·k)]` is the image of node
    /// `(i, j, k)`).
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid grid, [`DeformError::BufferLength`] for a wrong
    /// count, [`DeformError::NonFinite`] for a NaN/infinite position.
    pub fn from_positions(grid: Geometry, positions: Vec<DVec3>) -> Result<Self, DeformError> {
        grid.validate()?;
        check_len(grid.len(), positions.len())?;
        if let Some((i, p)) = positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(DeformError::NonFinite {
                what: format!("sampled position {i}"),
                value: if p.x.is_finite() {
                    if p.y.is_finite() { p.z } else { p.y }
                } else {
                    p.x
                },
            });
        }
        let from_index = grid.index_to_physical_matrix();
        Ok(Self {
            grid,
            positions,
            to_index: from_index.inverse(),
            from_index,
        })
    }

    /// A grid of `nodes` nodes per axis spanning the voxel centres of `geometry` (same
    /// origin and direction; first and last node on the first and last voxel centre).
    ///
    /// # Errors
    /// [`DeformError::Grid`] if `geometry` or the result is invalid (e.g. a zero node count).
    pub fn covering(geometry: &Geometry, nodes: [usize; 3]) -> Result<Geometry, DeformError> {
        geometry.validate()?;
        let g = geometry.resampled(nodes);
        g.validate()?;
        Ok(g)
    }

    /// The sampling grid.
    #[must_use]
    pub fn grid(&self) -> &Geometry {
        &self.grid
    }

    /// Mapped node positions (x fastest).
    #[must_use]
    pub fn positions(&self) -> &[DVec3] {
        &self.positions
    }

    /// Clamped continuous index, cell corner and fractions, and which axes were inside.
    #[inline]
    fn locate(&self, x: DVec3) -> ([usize; 3], DVec3, DVec3, [bool; 3]) {
        let idx = self.to_index * (x - self.grid.origin);
        let mut base = [0usize; 3];
        let mut frac = DVec3::ZERO;
        let mut clamped = DVec3::ZERO;
        let mut inside = [true; 3];
        for a in 0..3 {
            let n = self.grid.dims[a];
            let hi = (n - 1) as f64;
            let c = if idx[a].is_nan() {
                0.0
            } else {
                idx[a].clamp(0.0, hi)
            };
            inside[a] = c == idx[a];
            clamped[a] = c;
            if n == 1 {
                base[a] = 0;
                frac[a] = 0.0;
            } else {
                // c ≤ n − 1, so the floor is a valid node; the last cell covers c = n − 1.
                let i0 = (c.floor() as usize).min(n - 2);
                base[a] = i0;
                frac[a] = c - i0 as f64;
            }
        }
        (base, frac, clamped, inside)
    }

    #[inline]
    fn node(&self, i: usize, j: usize, k: usize) -> DVec3 {
        let [nx, ny, _] = self.grid.dims;
        self.positions[i + nx * (j + ny * k)]
    }

    /// The eight corner positions of the cell at `base` (x fastest), repeating nodes along
    /// axes with a single node.
    #[inline]
    fn corners(&self, base: [usize; 3]) -> [DVec3; 8] {
        let step = |a: usize| usize::from(self.grid.dims[a] > 1);
        let (i0, j0, k0) = (base[0], base[1], base[2]);
        let (i1, j1, k1) = (i0 + step(0), j0 + step(1), k0 + step(2));
        [
            self.node(i0, j0, k0),
            self.node(i1, j0, k0),
            self.node(i0, j1, k0),
            self.node(i1, j1, k0),
            self.node(i0, j0, k1),
            self.node(i1, j0, k1),
            self.node(i0, j1, k1),
            self.node(i1, j1, k1),
        ]
    }
}

impl SampledMap {
    /// Trilinear interpolation at a continuous index strictly usable as is (every
    /// coordinate in `[0, n − 1]`), without the outside extension.
    #[inline]
    fn interior(&self, idx: DVec3) -> DVec3 {
        let [nx, ny, nz] = self.grid.dims;
        let cell = |c: f64, n: usize| -> (usize, f64, usize) {
            if n == 1 {
                (0, 0.0, 0)
            } else {
                let i0 = (c as usize).min(n - 2);
                (i0, c - i0 as f64, 1)
            }
        };
        let (i0, u, si) = cell(idx.x, nx);
        let (j0, v, sj) = cell(idx.y, ny);
        let (k0, w, sk) = cell(idx.z, nz);
        let sj = sj * nx;
        let sk = sk * nx * ny;
        let o = i0 + nx * (j0 + ny * k0);
        let p = &self.positions;
        let x00 = p[o].lerp(p[o + si], u);
        let x10 = p[o + sj].lerp(p[o + sj + si], u);
        let x01 = p[o + sk].lerp(p[o + sk + si], u);
        let x11 = p[o + sk + sj].lerp(p[o + sk + sj + si], u);
        x00.lerp(x10, v).lerp(x01.lerp(x11, v), w)
    }
}

impl SpaceMap for SampledMap {
    fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        let [nx, ny, _] = crate::map::check_grid(grid, out)?;
        if out.is_empty() {
            return Ok(());
        }
        // Voxel index → index of this map's grid, an affine map applied incrementally.
        let a = self.to_index * grid.index_to_physical_matrix();
        let b = self.to_index * (grid.origin - self.grid.origin);
        let hi = DVec3::new(
            (self.grid.dims[0] - 1) as f64,
            (self.grid.dims[1] - 1) as f64,
            (self.grid.dims[2] - 1) as f64,
        );
        out.par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(k, slab)| {
                for (j, row) in slab.chunks_exact_mut(nx).enumerate() {
                    let start = b + a * DVec3::new(0.0, j as f64, k as f64);
                    for (i, o) in row.iter_mut().enumerate() {
                        let idx = start + a.x_axis * i as f64;
                        *o = if idx.cmpge(DVec3::ZERO).all() && idx.cmple(hi).all() {
                            self.interior(idx)
                        } else {
                            self.apply(
                                grid.index_to_physical(DVec3::new(i as f64, j as f64, k as f64)),
                            )
                        };
                    }
                }
            });
        Ok(())
    }

    fn apply(&self, x: DVec3) -> DVec3 {
        let (base, t, clamped, inside) = self.locate(x);
        if inside.iter().all(|&b| b) {
            return self.interior(clamped);
        }
        let c = self.corners(base);
        let x00 = c[0].lerp(c[1], t.x);
        let x10 = c[2].lerp(c[3], t.x);
        let x01 = c[4].lerp(c[5], t.x);
        let x11 = c[6].lerp(c[7], t.x);
        let y0 = x00.lerp(x10, t.y);
        let y1 = x01.lerp(x11, t.y);
        let f = y0.lerp(y1, t.z);
        // Constant-displacement extension: zero inside the grid up to rounding.
        f + (x - (self.grid.origin + self.from_index * clamped))
    }

    fn jacobian(&self, x: DVec3) -> DMat3 {
        let (base, t, _, inside) = self.locate(x);
        let c = self.corners(base);
        let (u, v, w) = (t.x, t.y, t.z);
        let (u0, v0, w0) = (1.0 - u, 1.0 - v, 1.0 - w);
        let dx = ((c[1] - c[0]) * v0 + (c[3] - c[2]) * v) * w0
            + ((c[5] - c[4]) * v0 + (c[7] - c[6]) * v) * w;
        let dy = ((c[2] - c[0]) * u0 + (c[3] - c[1]) * u) * w0
            + ((c[6] - c[4]) * u0 + (c[7] - c[5]) * u) * w;
        let dz = ((c[4] - c[0]) * u0 + (c[5] - c[1]) * u) * v0
            + ((c[6] - c[2]) * u0 + (c[7] - c[3]) * u) * v;
        // Index axes with a single node have no derivative.
        let single = |a: usize| self.grid.dims[a] == 1;
        let mut g = DMat3::from_cols(dx, dy, dz) - self.from_index;
        let cols = [&mut g.x_axis, &mut g.y_axis, &mut g.z_axis];
        for (a, col) in cols.into_iter().enumerate() {
            if !inside[a] || single(a) {
                *col = DVec3::ZERO;
            }
        }
        g * self.to_index + DMat3::IDENTITY
    }
}

/// A selected handle during a drag: `f(v) − c_i(v) t_i` at every node.
#[derive(Debug, Clone)]
struct Selection {
    index: usize,
    base: Vec<DVec3>,
}

/// A [`LinearHandleMap`] sampled on a grid with every node's coefficients stored, for
/// real-time target edits (§5.5.4); see the [module docs](self).
///
/// Memory: one `f64` per node per target vector (32³ nodes × 200 handles = 52 MB).
#[derive(Debug, Clone)]
pub struct HandleGrid<M: LinearHandleMap> {
    map: M,
    sampled: SampledMap,
    /// Target-major: `coefficients[k·nodes + n]`.
    coefficients: Vec<f64>,
    targets: Vec<DVec3>,
    selection: Option<Selection>,
}

impl<M: LinearHandleMap> HandleGrid<M> {
    /// Sample `map` on `grid` and precompute every node's coefficients (parallel).
    ///
    /// # Errors
    /// As [`SampledMap::from_map`]; [`DeformError::Io`] if nodes × targets coefficients
    /// exceed the allocation limit.
    pub fn new(map: M, grid: Geometry) -> Result<Self, DeformError> {
        grid.validate()?;
        let nodes = volmorph_io::checked_len(&grid.dims, std::mem::size_of::<DVec3>())?;
        let targets = map.target_vectors();
        let k = targets.len();
        let len = volmorph_io::checked_len(&[nodes, k], std::mem::size_of::<f64>())?;
        let [nx, ny, _] = grid.dims;
        let mut coefficients = vec![0.0; len];
        let mut positions = vec![DVec3::ZERO; nodes];
        // One pass over the nodes, in parallel chunks; each chunk owns its piece of every
        // target's coefficient row (rows are target-major for the updates).
        const CHUNK: usize = 512;
        let chunks = nodes.div_ceil(CHUNK);
        let mut pieces: Vec<Vec<&mut [f64]>> = (0..chunks).map(|_| Vec::with_capacity(k)).collect();
        if nodes > 0 {
            for row in coefficients.chunks_mut(nodes) {
                for (c, piece) in row.chunks_mut(CHUNK).enumerate() {
                    pieces[c].push(piece);
                }
            }
        }
        pieces
            .into_par_iter()
            .zip(positions.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (mut rows, pos))| {
                let mut scratch = vec![0.0; k];
                for (local, p) in pos.iter_mut().enumerate() {
                    let n = c * CHUNK + local;
                    let v = grid.index_to_physical(DVec3::new(
                        (n % nx) as f64,
                        (n / nx % ny) as f64,
                        (n / (nx * ny)) as f64,
                    ));
                    let mut f = map.coefficients_into(v, &mut scratch);
                    for ((row, &ck), t) in rows.iter_mut().zip(&scratch).zip(&targets) {
                        row[local] = ck;
                        f += ck * *t;
                    }
                    *p = f;
                }
            });
        let sampled = SampledMap::from_positions(grid, positions)?;
        Ok(Self {
            map,
            sampled,
            coefficients,
            targets,
            selection: None,
        })
    }

    /// The exact map with the current targets (the per-voxel mode).
    #[must_use]
    pub fn map(&self) -> &M {
        &self.map
    }

    /// The sampled map (trilinear between nodes).
    #[must_use]
    pub fn sampled(&self) -> &SampledMap {
        &self.sampled
    }

    /// Current target vectors.
    #[must_use]
    pub fn targets(&self) -> &[DVec3] {
        &self.targets
    }

    /// The stored coefficients `c_k` of target `k` at every node (x fastest), if `k` is in
    /// range.
    #[must_use]
    pub fn coefficients(&self, k: usize) -> Option<&[f64]> {
        let n = self.sampled.grid.len();
        self.coefficients.get(k * n..(k + 1) * n)
    }

    fn check_target(&self, k: usize, t: DVec3) -> Result<(), DeformError> {
        if k >= self.targets.len() {
            return Err(DeformError::InvalidHandles(format!(
                "target {k} out of range ({} targets)",
                self.targets.len()
            )));
        }
        crate::map::check_finite("target", &[t])
    }

    fn commit_target(&mut self, k: usize, t: DVec3) -> Result<(), DeformError> {
        let mut all = self.targets.clone();
        all[k] = t;
        self.map.set_target_vectors(&all)?;
        self.targets = all;
        Ok(())
    }

    /// Move target `k` to `t`: every node gains `c_k(v)·(t − t_old)` (one multiply-add per
    /// node). Clears a selection of another handle.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for `k` out of range, [`DeformError::NonFinite`] for a
    /// NaN/infinite `t`.
    pub fn move_target(&mut self, k: usize, t: DVec3) -> Result<(), DeformError> {
        if self.selection.as_ref().is_some_and(|s| s.index == k) {
            return self.drag_selected(t);
        }
        self.check_target(k, t)?;
        let delta = t - self.targets[k];
        self.commit_target(k, t)?;
        self.selection = None;
        let n = self.sampled.grid.len();
        let c = &self.coefficients[k * n..(k + 1) * n];
        for (p, &ck) in self.sampled.positions.iter_mut().zip(c) {
            *p += ck * delta;
        }
        Ok(())
    }

    /// Select target `k` for a drag: store `f(v) − c_k(v) t_k` at every node (§5.5.4).
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for `k` out of range.
    pub fn select(&mut self, k: usize) -> Result<(), DeformError> {
        let t = *self.targets.get(k).ok_or_else(|| {
            DeformError::InvalidHandles(format!(
                "target {k} out of range ({} targets)",
                self.targets.len()
            ))
        })?;
        let n = self.sampled.grid.len();
        let c = &self.coefficients[k * n..(k + 1) * n];
        let mut base = match self.selection.take() {
            Some(s) => s.base,
            None => Vec::new(),
        };
        base.clear();
        base.extend(
            self.sampled
                .positions
                .iter()
                .zip(c)
                .map(|(p, &ck)| *p - ck * t),
        );
        self.selection = Some(Selection { index: k, base });
        Ok(())
    }

    /// The selected target, if any.
    #[must_use]
    pub fn selected(&self) -> Option<usize> {
        self.selection.as_ref().map(|s| s.index)
    }

    /// Move the selected target to `t`: every node becomes `stored + c_k(v)·t`.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] if nothing is selected, [`DeformError::NonFinite`] for
    /// a NaN/infinite `t`.
    pub fn drag_selected(&mut self, t: DVec3) -> Result<(), DeformError> {
        let Some(k) = self.selected() else {
            return Err(DeformError::InvalidHandles(
                "no target selected for dragging".into(),
            ));
        };
        self.check_target(k, t)?;
        self.commit_target(k, t)?;
        let n = self.sampled.grid.len();
        let c = &self.coefficients[k * n..(k + 1) * n];
        if let Some(sel) = &self.selection {
            for ((p, b), &ck) in self.sampled.positions.iter_mut().zip(&sel.base).zip(c) {
                *p = *b + ck * t;
            }
        }
        Ok(())
    }

    /// Replace all targets and resample every node from the coefficients (`O(nodes ×
    /// targets)`, no source-dependent work).
    ///
    /// # Errors
    /// As [`LinearHandleMap::set_target_vectors`].
    pub fn set_targets(&mut self, targets: &[DVec3]) -> Result<(), DeformError> {
        self.map.set_target_vectors(targets)?;
        let n = self.sampled.grid.len();
        let old = std::mem::replace(&mut self.targets, targets.to_vec());
        let coeffs = &self.coefficients;
        let new = &self.targets;
        self.sampled
            .positions
            .par_chunks_mut(4096)
            .enumerate()
            .for_each(|(chunk, p)| {
                let start = chunk * 4096;
                for (k, (t_old, t_new)) in old.iter().zip(new).enumerate() {
                    let d = *t_new - *t_old;
                    if d == DVec3::ZERO {
                        continue;
                    }
                    let c = &coeffs[k * n + start..k * n + start + p.len()];
                    for (p, &ck) in p.iter_mut().zip(c) {
                        *p += ck * d;
                    }
                }
            });
        self.selection = None;
        Ok(())
    }
}

impl<M: LinearHandleMap> SpaceMap for HandleGrid<M> {
    fn apply(&self, p: DVec3) -> DVec3 {
        self.sampled.apply(p)
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.sampled.jacobian(p)
    }
}
