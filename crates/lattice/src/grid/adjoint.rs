//! Adjoints of lattice evaluation: gradients of a scalar objective with respect to the control
//! points, for optimisers that fit a lattice to data (dense image registration).
//!
//! A lattice map is linear in its control points, `φ(x) = Σ_c B_c(x) P_c` with the tensor
//! basis `B_c(x) = N_i(u) N_j(v) N_k(w)`. For an objective `E = Σ_x e(φ(x))` the chain rule
//! gives `∂E/∂P_c = Σ_x B_c(x) ∂e/∂φ(x)`: the transpose of the grid evaluation applied to the
//! per-voxel gradients. [`LatticeGridPlan::apply_adjoint`] computes it with the plan's own
//! per-axis basis tables, in the reverse order of [`LatticeGridPlan::apply`]: for each row
//! `(j, k)` the voxel gradients are first gathered along u into one partial sum per control
//! column (`p_u + 1` terms per voxel), and the row is then scattered once into its
//! `(p_v + 1)(p_w + 1)` control layers. Parallel over z-slabs, each task with its own
//! accumulator of the control net's size, summed at the end; nothing is allocated per voxel.
//!
//! [`BSplineLattice::point_basis`] gives the non-zero basis values and first derivatives at
//! one point, for objectives on scattered points (landmark constraints, Jacobian penalties).

use glam::DVec3;
use rayon::prelude::*;
use volmorph_spline::{MAX_DEGREE, basis_funs_and_derivs_into};

use super::LatticeGridPlan;
use crate::BSplineLattice;
use volmorph_deform::DeformError;
use volmorph_deform::map::check_len;

/// Basis functions of a lattice that are non-zero at one point (see
/// [`BSplineLattice::point_basis`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointBasis {
    /// First control index `(i, j, k)` of the `(p_u+1)(p_v+1)(p_w+1)` non-zero functions.
    pub first: [usize; 3],
    /// Number of non-zero functions per axis (degree + 1).
    pub order: [usize; 3],
    /// Values `N(u)` per axis (first `order[a]` entries used).
    pub values: [[f64; MAX_DEGREE + 1]; 3],
    /// Derivatives with respect to **physical** distance along the lattice axis
    /// (`dN/du / spacing`; first `order[a]` entries used).
    pub derivatives: [[f64; MAX_DEGREE + 1]; 3],
}

impl PointBasis {
    /// Linear index (i fastest) of the control point at offset `(a, b, c)` from
    /// [`PointBasis::first`] in a net of `counts` control points.
    #[inline]
    #[must_use]
    pub fn control_index(&self, counts: [usize; 3], a: usize, b: usize, c: usize) -> usize {
        (self.first[0] + a) + counts[0] * ((self.first[1] + b) + counts[1] * (self.first[2] + c))
    }
}

impl BSplineLattice {
    /// The non-zero basis functions at physical point `x`: `φ(x) = Σ N_a N_b N_c P` over the
    /// `order` cube starting at `first`. Derivatives are per unit of physical length along
    /// each lattice axis (`dN/du / spacing`), so the physical gradient of a basis product is
    /// `G · (N'_a N_b N_c, N_a N'_b N_c, N_a N_b N'_c)` with
    /// [`LatticeFrame::gradient_matrix`](crate::LatticeFrame::gradient_matrix) `G` (the axes for
    /// an orthonormal frame; for an axis-aligned one the three derivative products are the
    /// columns of the Jacobian).
    /// `None` outside the lattice box (where the map is the identity and does not depend on
    /// the control points) and for rational lattices.
    #[must_use]
    pub fn point_basis(&self, x: DVec3) -> Option<PointBasis> {
        if self.spline().is_rational() {
            return None;
        }
        let u = self.frame().to_parameter(x);
        if !self.contains_parameter(u) {
            return None;
        }
        let spacing = self.frame().spacing();
        let mut out = PointBasis {
            first: [0; 3],
            order: [0; 3],
            values: [[0.0; MAX_DEGREE + 1]; 3],
            derivatives: [[0.0; MAX_DEGREE + 1]; 3],
        };
        for (a, kv) in self.knots().iter().enumerate() {
            let deg = kv.degree();
            let span = kv.find_span(u[a]).ok()?;
            basis_funs_and_derivs_into(
                kv,
                span,
                u[a],
                &mut out.values[a][..=deg],
                &mut out.derivatives[a][..=deg],
            )
            .ok()?;
            for d in &mut out.derivatives[a][..=deg] {
                *d /= spacing[a];
            }
            out.first[a] = span - deg;
            out.order[a] = deg + 1;
        }
        Some(out)
    }
}

impl LatticeGridPlan {
    /// The adjoint (transpose) of [`LatticeGridPlan::apply`]: `out[c] += Σ_x B_c(x)·grads[x]`
    /// over the voxels `x` of the plan's grid inside the lattice box (x fastest), for a
    /// lattice with `counts` control points (index i fastest). With `grads[x] = ∂E/∂φ(x)` this
    /// is `∂E/∂P_c`, the gradient of the objective with respect to every control point. Voxels
    /// outside the box contribute nothing (the map does not depend on the control points
    /// there). Values are **added** to `out`.
    ///
    /// # Errors
    /// [`DeformError::BufferLength`] if `grads` is not one value per voxel or `out` not one per
    /// control point; [`DeformError::GridNotAligned`] if `counts` is not the control net of the
    /// knots the plan was built for.
    pub fn apply_adjoint(
        &self,
        counts: [usize; 3],
        grads: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), DeformError> {
        let expected = [
            self.knots[0].num_basis(),
            self.knots[1].num_basis(),
            self.knots[2].num_basis(),
        ];
        if counts != expected {
            return Err(DeformError::GridNotAligned(format!(
                "control net {counts:?} is not the plan's {expected:?}"
            )));
        }
        check_len(self.grid.len(), grads.len())?;
        check_len(counts[0] * counts[1] * counts[2], out.len())?;
        let [nx, ny, _] = self.grid.dims;
        let [cx, cy, _] = counts;
        let [wx, wy, wz] = self.orders;
        let n_ctrl = out.len();
        let total = grads
            .par_chunks(nx * ny)
            .enumerate()
            .fold(
                || (vec![DVec3::ZERO; n_ctrl], vec![DVec3::ZERO; cx]),
                |(mut acc, mut row_sum), (k, slab)| {
                    let Some((fz, bz)) = self.axes[2].at(k) else {
                        return (acc, row_sum);
                    };
                    for (j, row) in slab.chunks_exact(nx).enumerate() {
                        let Some((fy, by)) = self.axes[1].at(j) else {
                            continue;
                        };
                        row_sum.fill(DVec3::ZERO);
                        let mut any = false;
                        for (i, g) in row.iter().enumerate() {
                            if let Some((fx, bx)) = self.axes[0].at(i) {
                                any = true;
                                for (s, &n) in row_sum[fx..fx + wx].iter_mut().zip(bx) {
                                    *s += n * *g;
                                }
                            }
                        }
                        if !any {
                            continue;
                        }
                        for (c, &nz) in bz.iter().enumerate().take(wz) {
                            for (b, &ny_) in by.iter().enumerate().take(wy) {
                                let w = nz * ny_;
                                let base = ((fz + c) * cy + fy + b) * cx;
                                for (o, s) in acc[base..base + cx].iter_mut().zip(&row_sum) {
                                    *o += w * *s;
                                }
                            }
                        }
                    }
                    (acc, row_sum)
                },
            )
            .map(|(acc, _)| acc)
            .reduce(
                || vec![DVec3::ZERO; n_ctrl],
                |mut a, b| {
                    for (x, y) in a.iter_mut().zip(&b) {
                        *x += *y;
                    }
                    a
                },
            );
        for (o, t) in out.iter_mut().zip(&total) {
            *o += *t;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::GridPath;
    use glam::DMat3;
    use volmorph_deform::SpaceMap;
    use volmorph_testkit::Rng;
    use volmorph_volume::Geometry;

    fn moved_lattice(rng: &mut Rng) -> BSplineLattice {
        let mut lat = BSplineLattice::uniform_cubic_around(
            DVec3::ZERO,
            DVec3::new(11.0, 9.0, 7.0),
            [7, 6, 5],
        )
        .unwrap();
        for k in 0..5 {
            for j in 0..6 {
                for i in 0..7 {
                    lat.move_control_point([i, j, k], rng.point(0.8)).unwrap();
                }
            }
        }
        lat
    }

    /// ⟨A P, g⟩ = ⟨P, Aᵀ g⟩ for the grid evaluation A: the adjoint is the exact transpose.
    #[test]
    fn adjoint_is_the_transpose_of_grid_evaluation() {
        let mut rng = Rng::new(7);
        let lat = moved_lattice(&mut rng);
        // A grid reaching beyond the box on two sides (outside voxels contribute nothing).
        let grid = Geometry::new([14, 11, 9])
            .with_spacing(DVec3::new(0.9, 0.95, 0.85))
            .with_origin(DVec3::new(-0.5, 0.2, -0.3));
        let plan = LatticeGridPlan::new(&lat, &grid, GridPath::Separable).unwrap();
        let ctrl = lat.control_points();
        let mut phi = vec![DVec3::ZERO; grid.len()];
        plan.apply(&lat, &mut phi).unwrap();
        let g: Vec<DVec3> = (0..grid.len()).map(|_| rng.point(1.0)).collect();
        let mut adj = vec![DVec3::ZERO; ctrl.len()];
        plan.apply_adjoint(lat.counts(), &g, &mut adj).unwrap();
        // ⟨φ − x_outside, g⟩ where φ is linear in P only inside the box.
        let mut lhs = 0.0;
        for (n, (p, gv)) in phi.iter().zip(&g).enumerate() {
            let x = grid.index_to_physical(DVec3::new(
                (n % 14) as f64,
                (n / 14 % 11) as f64,
                (n / 154) as f64,
            ));
            if lat.contains(x) {
                lhs += p.dot(*gv);
            }
        }
        let rhs: f64 = ctrl.iter().zip(&adj).map(|(p, a)| p.dot(*a)).sum();
        assert!(
            (lhs - rhs).abs() < 1e-9 * lhs.abs().max(1.0),
            "{lhs} vs {rhs}"
        );
        // Wrong sizes are errors.
        assert!(plan.apply_adjoint([7, 6, 4], &g, &mut adj).is_err());
        assert!(plan.apply_adjoint(lat.counts(), &g[1..], &mut adj).is_err());
    }

    /// The point basis reproduces `apply` and `jacobian`.
    #[test]
    fn point_basis_reproduces_value_and_jacobian() {
        let mut rng = Rng::new(3);
        let lat = moved_lattice(&mut rng);
        let ctrl = lat.control_points();
        for _ in 0..50 {
            let x = rng.point_in(DVec3::ZERO, DVec3::new(11.0, 9.0, 7.0));
            let b = lat.point_basis(x).unwrap();
            let (mut v, mut du, mut dv, mut dw) =
                (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
            for c in 0..b.order[2] {
                for bb in 0..b.order[1] {
                    for a in 0..b.order[0] {
                        let p = ctrl[b.control_index(lat.counts(), a, bb, c)];
                        let (na, nb, nc) = (b.values[0][a], b.values[1][bb], b.values[2][c]);
                        v += na * nb * nc * p;
                        du += b.derivatives[0][a] * nb * nc * p;
                        dv += na * b.derivatives[1][bb] * nc * p;
                        dw += na * nb * b.derivatives[2][c] * p;
                    }
                }
            }
            assert!((v - lat.apply(x)).length() < 1e-10);
            let j = DMat3::from_cols(du, dv, dw);
            assert!(j.abs_diff_eq(lat.jacobian(x), 1e-9));
        }
        assert!(lat.point_basis(DVec3::splat(-1.0)).is_none());
    }
}
