//! [`SampledMap`]: any [`SpaceMap`] evaluated once at the nodes of a coarse grid (e.g. 32³ over
//! a 512² × 300 CT volume) and interpolated trilinearly in between — the "RGB texture" of
//! McPhail's thesis §5.5.2. Resampling a volume through it costs one trilinear lookup per voxel
//! instead of one evaluation of the full map; the exact per-voxel mode is simply the original
//! map.
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

/// A map sampled at the nodes of a grid and interpolated trilinearly; see the
/// [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct SampledMap {
    pub(crate) grid: Geometry,
    pub(crate) positions: Vec<DVec3>,
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

    /// [`SampledMap::covering`] with `n` nodes per axis, but no more nodes on an axis than
    /// `geometry` has voxels (and at least one): the coarse grid of a map sampled at most `n`
    /// times per axis over `geometry`.
    ///
    /// # Errors
    /// As [`SampledMap::covering`].
    pub fn covering_at_most(geometry: &Geometry, n: usize) -> Result<Geometry, DeformError> {
        Self::covering(geometry, geometry.dims.map(|d| n.min(d).max(1)))
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
