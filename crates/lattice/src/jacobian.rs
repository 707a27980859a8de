//! Jacobians of lattice maps: one-pass value-and-Jacobian at a point, and the separable dense
//! path on voxel grids.
//!
//! For a lattice `S(u, v, w) = Σ N_i(u) N_j(v) N_k(w) P_ijk` with `(u, v, w) = F⁻¹(x)` (see
//! [`crate::lattice`]), the physical Jacobian is
//!
//! ```text
//! Dφ(x) = [∂S/∂u  ∂S/∂v  ∂S/∂w] · diag(1/spacing) · axesᵀ
//! ```
//!
//! inside the box and `I` outside, exactly as [`SpaceMap::jacobian`] states.
//!
//! * **At a point** ([`SpaceMap::apply_with_jacobian`] on a [`BSplineLattice`]): the basis
//!   values and first derivatives of each axis are computed once into stack buffers and the
//!   `(p_u+1)(p_v+1)(p_w+1)` control points are read once, giving the image and the three
//!   partial derivatives together. This is the kernel Newton inversion calls at every step.
//! * **On a grid** ([`BSplineLattice::jacobian_grid_separable`], used by
//!   [`SpaceMap::jacobian_grid`] when the grid is aligned with the lattice): as
//!   [`crate::grid`] does for values, each axis's parameters are tabulated once with their
//!   basis values **and derivatives**. For each row `(j, k)` three rows of partial sums along
//!   u are blended once from the control layers,
//!
//!   ```text
//!   A_i = Σ_jk N_j N_k P_ijk,   B_i = Σ_jk N'_j N_k P_ijk,   C_i = Σ_jk N_j N'_k P_ijk,
//!   ```
//!
//!   and each voxel of the row needs only `3(p_u + 1)` terms:
//!   `∂S/∂u = Σ_i N'_i A_i`, `∂S/∂v = Σ_i N_i B_i`, `∂S/∂w = Σ_i N_i C_i`. Parallel over
//!   z-slabs, no allocation per voxel.
//!
//! Both agree with the pointwise [`SpaceMap::jacobian`] to rounding (≈1e-13 relative). At a
//! voxel centre lying exactly on a knot of a lattice that is only C⁰ there (degree 1, or a
//! repeated knot) the two may pick the derivative of different sides.
//!
//! [`SpaceMap::jacobian`]: crate::SpaceMap::jacobian
//! [`SpaceMap::apply_with_jacobian`]: crate::SpaceMap::apply_with_jacobian
//! [`SpaceMap::jacobian_grid`]: crate::SpaceMap::jacobian_grid

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_spline::{
    BasisTable, KnotVector, basis_funs_and_derivs_into, uniform_cubic, uniform_cubic_derivative,
};
use volmorph_volume::Geometry;

use crate::BSplineLattice;
use crate::grid::aligned_steps;
use volmorph_deform::DeformError;
use volmorph_deform::map::check_len;

/// Largest degree per axis the one-pass point kernel handles with its fixed stack buffers;
/// lattices of higher degree use the spline crate's general evaluation. Cubic lattices (True
/// 1992) and the Bézier lattices of Sederberg–Parry FFD in practice are far below it.
pub const POINT_KERNEL_MAX_DEGREE: usize = 7;

/// Basis buffer length of the point kernel.
const KERNEL_BUF: usize = POINT_KERNEL_MAX_DEGREE + 1;

/// Image and Jacobian of `lat` at physical point `p` in one pass over the control points
/// (`(p, I)` outside the box). `None` when a degree exceeds [`POINT_KERNEL_MAX_DEGREE`] or the
/// basis cannot be evaluated (the caller then falls back to the general path).
pub(crate) fn lattice_value_and_jacobian(lat: &BSplineLattice, p: DVec3) -> Option<(DVec3, DMat3)> {
    let frame = lat.frame();
    let u = frame.to_parameter(p);
    if !lat.contains_parameter(u) {
        return Some((p, DMat3::IDENTITY));
    }
    let knots = lat.knots();
    let mut vals = [[0.0; KERNEL_BUF]; 3];
    let mut ders = [[0.0; KERNEL_BUF]; 3];
    let mut first = [0usize; 3];
    let mut orders = [0usize; 3];
    for a in 0..3 {
        let kv = &knots[a];
        let deg = kv.degree();
        if deg > POINT_KERNEL_MAX_DEGREE {
            return None;
        }
        first[a] = axis_basis(kv, u[a], &mut vals[a], &mut ders[a])?;
        orders[a] = deg + 1;
    }
    let coefs = lat.spline().homogeneous_coefficients();
    let [cx, cy, _] = lat.counts();
    let [wx, wy, wz] = orders;
    let (mut value, mut du, mut dv, mut dw) = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
    for c in 0..wz {
        let (nz, dz) = (vals[2][c], ders[2][c]);
        for b in 0..wy {
            let (ny, dy) = (vals[1][b], ders[1][b]);
            let base = ((first[2] + c) * cy + first[1] + b) * cx + first[0];
            let row = coefs.get(3 * base..3 * (base + wx))?;
            let (mut s0, mut s1) = (DVec3::ZERO, DVec3::ZERO);
            for ((q, &n), &d) in row.chunks_exact(3).zip(&vals[0][..wx]).zip(&ders[0][..wx]) {
                let q = DVec3::new(q[0], q[1], q[2]);
                s0 += n * q;
                s1 += d * q;
            }
            let w = ny * nz;
            value += w * s0;
            du += w * s1;
            dv += (dy * nz) * s0;
            dw += (ny * dz) * s0;
        }
    }
    Some((
        value,
        DMat3::from_cols(du, dv, dw) * frame.to_parameter_matrix(),
    ))
}

/// Knots count as equally spaced for the uniform cubic shortcut of [`axis_basis`] when their
/// differences agree to this relative tolerance (integer knots are exact; knots read from text
/// differ by a few ulps). The shortcut's values then differ from Cox–de Boor's by rounding.
const UNIFORM_KNOT_TOL: f64 = 1e-12;

/// Basis values and first derivatives of `kv` at in-domain `u` into `vals`/`ders`; returns the
/// first control index. Cubic spans whose eight surrounding knots are equally spaced (True's
/// lattices) use the closed-form uniform cubic basis instead of the triangular recursion.
#[inline]
fn axis_basis(
    kv: &KnotVector,
    u: f64,
    vals: &mut [f64; KERNEL_BUF],
    ders: &mut [f64; KERNEL_BUF],
) -> Option<usize> {
    let deg = kv.degree();
    let span = kv.find_span(u).ok()?;
    if deg == 3
        && let Some(w) = kv.knots().get(span - 3..span + 5)
    {
        let h = w[4] - w[3];
        if h > 0.0
            && w.windows(2)
                .all(|p| ((p[1] - p[0]) - h).abs() <= UNIFORM_KNOT_TOL * h)
        {
            let inv_h = 1.0 / h;
            let t = (u - w[3]) * inv_h;
            vals[..4].copy_from_slice(&uniform_cubic(t));
            for (d, b) in ders.iter_mut().zip(uniform_cubic_derivative(t)) {
                *d = b * inv_h;
            }
            return Some(span - 3);
        }
    }
    basis_funs_and_derivs_into(kv, span, u, vals, ders).ok()?;
    Some(span - deg)
}

/// One grid axis against one lattice axis: the contiguous range `lo..hi` of grid indices
/// inside the knot domain and their basis values and derivatives.
struct DerivAxis {
    lo: usize,
    hi: usize,
    table: Option<BasisTable>,
}

impl DerivAxis {
    fn new(kv: &KnotVector, n: usize, start: f64, step: f64) -> Result<Self, DeformError> {
        let param = |i: usize| start + step * i as f64;
        // Parameters are monotone in the index, so the in-domain indices are contiguous.
        let lo = (0..n).find(|&i| kv.contains(param(i)));
        let Some(lo) = lo else {
            return Ok(Self {
                lo: 0,
                hi: 0,
                table: None,
            });
        };
        let hi = (lo..n).find(|&i| !kv.contains(param(i))).unwrap_or(n);
        let params: Vec<f64> = (lo..hi).map(param).collect();
        Ok(Self {
            lo,
            hi,
            table: Some(BasisTable::new(kv, &params, true)?),
        })
    }

    /// First control index, basis values and derivatives of grid index `i`, if in the domain.
    #[inline]
    fn at(&self, i: usize) -> Option<(usize, &[f64], &[f64])> {
        if i < self.lo || i >= self.hi {
            return None;
        }
        let t = self.table.as_ref()?;
        let r = i - self.lo;
        Some((t.first(r)?, t.values(r)?, t.derivatives(r)?))
    }
}

impl BSplineLattice {
    /// The Jacobian at every voxel centre of `grid` (x fastest, columns `∂/∂x, ∂/∂y, ∂/∂z`)
    /// by separable per-axis tables of basis values and derivatives (see the
    /// [module docs](self)); `I` at voxels outside the lattice box. Agrees with pointwise
    /// [`SpaceMap::jacobian`] to rounding. Parallel over z-slabs; allocates only per-axis tables
    /// and one row buffer per task.
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid geometry, [`DeformError::BufferLength`] for a
    /// wrong `out` length, [`DeformError::GridNotAligned`] if the grid axes are not parallel to
    /// the lattice axes (use [`SpaceMap::jacobian_grid`], which falls back to pointwise
    /// evaluation), [`DeformError::Spline`] for an absurd table size.
    ///
    /// [`SpaceMap::jacobian`]: crate::SpaceMap::jacobian
    /// [`SpaceMap::jacobian_grid`]: crate::SpaceMap::jacobian_grid
    pub fn jacobian_grid_separable(
        &self,
        grid: &Geometry,
        out: &mut [DMat3],
    ) -> Result<(), DeformError> {
        grid.validate()?;
        check_len(grid.len(), out.len())?;
        let (start, step) = aligned_steps(self, grid)?.ok_or_else(|| {
            DeformError::GridNotAligned(
                "grid index axes are not parallel to the lattice's parameter axes".into(),
            )
        })?;
        if out.is_empty() {
            return Ok(());
        }
        let k = self.knots();
        let axes = [
            DerivAxis::new(&k[0], grid.dims[0], start[0], step[0])?,
            DerivAxis::new(&k[1], grid.dims[1], start[1], step[1])?,
            DerivAxis::new(&k[2], grid.dims[2], start[2], step[2])?,
        ];
        let deg = self.degree();
        let [wx, wy, wz] = [deg[0] + 1, deg[1] + 1, deg[2] + 1];
        let [nx, ny, _] = grid.dims;
        let [cx, cy, _] = self.counts();
        let to_param = self.frame().to_parameter_matrix();
        let coefs = self.spline().homogeneous_coefficients();
        // Control columns along u touched by any in-domain voxel (first indices decrease along
        // i when the grid axis runs against the lattice axis).
        let ax = &axes[0];
        let (c_lo, c_hi) = match (ax.at(ax.lo), ax.hi.checked_sub(1).and_then(|l| ax.at(l))) {
            (Some((f0, ..)), Some((f1, ..))) => (f0.min(f1), (f0.max(f1) + wx).min(cx)),
            _ => (0, 0),
        };
        let width = c_hi - c_lo;
        out.par_chunks_mut(nx * ny).enumerate().for_each_init(
            || vec![DVec3::ZERO; 3 * width],
            |sums, (kz, slab)| {
                let zk = axes[2].at(kz);
                for (j, row) in slab.chunks_exact_mut(nx).enumerate() {
                    let (Some((fz, nz, dz)), Some((fy, ny_, dy))) = (zk, axes[1].at(j)) else {
                        row.fill(DMat3::IDENTITY);
                        continue;
                    };
                    sums.fill(DVec3::ZERO);
                    let (a_row, rest) = sums.split_at_mut(width);
                    let (b_row, c_row) = rest.split_at_mut(width);
                    for c in 0..wz {
                        for b in 0..wy {
                            let (wa, wb, wc) = (ny_[b] * nz[c], dy[b] * nz[c], ny_[b] * dz[c]);
                            let base = ((fz + c) * cy + fy + b) * cx;
                            let layer = &coefs[3 * (base + c_lo)..3 * (base + c_hi)];
                            for (((q, sa), sb), sc) in layer
                                .chunks_exact(3)
                                .zip(a_row.iter_mut())
                                .zip(b_row.iter_mut())
                                .zip(c_row.iter_mut())
                            {
                                let q = DVec3::new(q[0], q[1], q[2]);
                                *sa += wa * q;
                                *sb += wb * q;
                                *sc += wc * q;
                            }
                        }
                    }
                    for (i, o) in row.iter_mut().enumerate() {
                        *o = match ax.at(i) {
                            Some((fx, nx_, dx)) => {
                                let r = fx - c_lo..fx - c_lo + wx;
                                let (mut su, mut sv, mut sw) =
                                    (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
                                for ((((&n, &d), &a), &b), &c) in nx_
                                    .iter()
                                    .zip(dx)
                                    .zip(&a_row[r.clone()])
                                    .zip(&b_row[r.clone()])
                                    .zip(&c_row[r])
                                {
                                    su += d * a;
                                    sv += n * b;
                                    sw += n * c;
                                }
                                DMat3::from_cols(su, sv, sw) * to_param
                            }
                            None => DMat3::IDENTITY,
                        };
                    }
                }
            },
        );
        Ok(())
    }
}
