//! A lattice as a [`LinearMap`]: the map `φ(x) = Σ_c N_c(u(x)) P_c` is linear in its control
//! points `P_c` (True 1992 §4), with local support, so moving a control point changes the map
//! only on the image of the knot spans its basis function covers.
//!
//! Parameters are the control points in the lattice's linear order (index `i` fastest, then
//! `j`, then `k`: parameter `i + nu·(j + nv·k)` is control point `[i, j, k]`), in physical
//! units. Outside the box the map is the identity: the base is `x` and every coefficient is 0;
//! inside, the base is 0 and the coefficients are the basis products `N_i(u) N_j(v) N_k(w)`.

use glam::DVec3;
use rayon::prelude::*;
use volmorph_deform::DeformError;
use volmorph_deform::live::{Influence, LinearMap, check_parameter};
use volmorph_deform::map::check_len;
use volmorph_spline::{KnotVector, MAX_DEGREE, basis_funs_into};

use crate::BSplineLattice;

impl BSplineLattice {
    /// Control index `[i, j, k]` of parameter `k` of the [`LinearMap`] form, if in range.
    #[must_use]
    pub fn control_index(&self, parameter: usize) -> Option<[usize; 3]> {
        let [nu, nv, nw] = self.counts();
        (parameter < nu * nv * nw)
            .then(|| [parameter % nu, parameter / nu % nv, parameter / (nu * nv)])
    }

    /// Parameter number of control point `index` in the [`LinearMap`] form.
    ///
    /// # Errors
    /// [`DeformError::IndexOutOfRange`].
    pub fn parameter_of(&self, index: [usize; 3]) -> Result<usize, DeformError> {
        let [nu, nv, nw] = self.counts();
        if index[0] < nu && index[1] < nv && index[2] < nw {
            Ok(index[0] + nu * (index[1] + nv * index[2]))
        } else {
            Err(DeformError::IndexOutOfRange {
                index,
                counts: self.counts(),
            })
        }
    }

    /// Control-point displacements `(index, delta)`, applied in order (an index may repeat),
    /// as [`LinearMap`] parameter changes `(parameter, new position)`, for the live-edit
    /// engines.
    ///
    /// # Errors
    /// [`DeformError::IndexOutOfRange`].
    pub fn changes_for_displacements(
        &self,
        moves: &[([usize; 3], DVec3)],
    ) -> Result<Vec<(usize, DVec3)>, DeformError> {
        let mut changes: Vec<(usize, DVec3)> = Vec::with_capacity(moves.len());
        for &(index, delta) in moves {
            let k = self.parameter_of(index)?;
            // A repeated index moves on from where the earlier entry put it.
            let from = match changes.iter().rev().find(|c| c.0 == k) {
                Some(c) => c.1,
                None => self.control_point(index)?,
            };
            changes.push((k, from + delta));
        }
        Ok(changes)
    }

    /// Control-point positions `(index, new position)` (the moves a
    /// [`ManipulationSession`](crate::ManipulationSession) returns) as [`LinearMap`] parameter
    /// changes.
    ///
    /// # Errors
    /// [`DeformError::IndexOutOfRange`].
    pub fn changes_for_positions(
        &self,
        moves: &[([usize; 3], DVec3)],
    ) -> Result<Vec<(usize, DVec3)>, DeformError> {
        moves
            .iter()
            .map(|&(index, p)| Ok((self.parameter_of(index)?, p)))
            .collect()
    }

    /// The closed parameter box where the basis function of control point `index` can be
    /// non-zero: per axis, the union of the non-empty knot spans `index ..= index + degree`.
    /// `None` if every one of those spans is empty (the control point acts nowhere).
    fn support(&self, index: [usize; 3]) -> Option<([f64; 3], [f64; 3])> {
        let knots = self.knots();
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for a in 0..3 {
            let p = knots[a].degree();
            for span in knots[a].spans() {
                if span.index >= index[a] && span.index <= index[a] + p {
                    lo[a] = lo[a].min(span.start);
                    hi[a] = hi[a].max(span.end);
                }
            }
            if lo[a].partial_cmp(&hi[a]).is_none_or(|o| o.is_gt()) {
                return None;
            }
        }
        Some((lo, hi))
    }
}

/// Basis values of axis `knots` at parameter `u`: the span and `degree + 1` values, `None` if
/// `u` is outside the domain.
fn axis_basis(knots: &KnotVector, u: f64) -> Option<(usize, [f64; MAX_DEGREE + 1])> {
    let span = knots.find_span(u).ok()?;
    let mut b = [0.0; MAX_DEGREE + 1];
    basis_funs_into(knots, span, u, &mut b).ok()?;
    Some((span, b))
}

impl LinearMap for BSplineLattice {
    fn parameter_count(&self) -> usize {
        let [nu, nv, nw] = self.counts();
        nu * nv * nw
    }

    fn parameters(&self) -> Vec<DVec3> {
        self.control_points()
    }

    fn set_parameters(&mut self, values: &[DVec3]) -> Result<(), DeformError> {
        *self = Self::from_parts(*self.frame(), self.knots().clone(), values)?;
        Ok(())
    }

    fn set_some_parameters(&mut self, changes: &[(usize, DVec3)]) -> Result<(), DeformError> {
        let n = self.parameter_count();
        for &(k, p) in changes {
            check_parameter(k, n)?;
            volmorph_deform::map::check_finite("control point", &[p])?;
        }
        for &(k, p) in changes {
            let index = self.control_index(k).unwrap_or_default();
            self.set_control_point(index, p)?;
        }
        Ok(())
    }

    fn coefficients_into(&self, v: DVec3, out: &mut [f64]) -> DVec3 {
        let m = out.len().min(self.parameter_count());
        let out = &mut out[..m];
        out.fill(0.0);
        let u = self.frame().to_parameter(v);
        if !self.contains_parameter(u) {
            return v;
        }
        let knots = self.knots();
        let mut basis = [(0usize, [0.0; MAX_DEGREE + 1]); 3];
        for a in 0..3 {
            match axis_basis(&knots[a], u[a]) {
                Some(b) => basis[a] = b,
                None => return v,
            }
        }
        let [nu, nv, _] = self.counts();
        let deg = self.degree();
        for k in 0..=deg[2] {
            let ck = basis[2].0 - deg[2] + k;
            for j in 0..=deg[1] {
                let cj = basis[1].0 - deg[1] + j;
                let wjk = basis[1].1[j] * basis[2].1[k];
                for i in 0..=deg[0] {
                    let ci = basis[0].0 - deg[0] + i;
                    if let Some(o) = out.get_mut(ci + nu * (cj + nv * ck)) {
                        *o = basis[0].1[i] * wjk;
                    }
                }
            }
        }
        DVec3::ZERO
    }

    fn coefficient_column(
        &self,
        k: usize,
        points: &[DVec3],
        out: &mut [f64],
    ) -> Result<(), DeformError> {
        check_parameter(k, self.parameter_count())?;
        check_len(points.len(), out.len())?;
        let index = self.control_index(k).unwrap_or_default();
        let Some((lo, hi)) = self.support(index) else {
            out.fill(0.0);
            return Ok(());
        };
        let knots = self.knots();
        let deg = self.degree();
        out.par_chunks_mut(1024)
            .zip(points.par_chunks(1024))
            .for_each(|(o, p)| {
                for (o, &x) in o.iter_mut().zip(p) {
                    *o = 0.0;
                    let u = self.frame().to_parameter(x);
                    if !self.contains_parameter(u) || (0..3).any(|a| u[a] < lo[a] || u[a] > hi[a]) {
                        continue;
                    }
                    let mut c = 1.0;
                    for a in 0..3 {
                        let Some((span, b)) = axis_basis(&knots[a], u[a]) else {
                            c = 0.0;
                            break;
                        };
                        // Basis functions span − p ..= span are non-zero on this span.
                        if index[a] + deg[a] < span || index[a] > span {
                            c = 0.0;
                            break;
                        }
                        c *= b[index[a] + deg[a] - span];
                    }
                    *o = c;
                }
            });
        Ok(())
    }

    /// The image under the frame of the union of the control points' support boxes.
    fn influence(&self, ks: &[usize]) -> Influence {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut any = false;
        for &k in ks {
            let Some(index) = self.control_index(k) else {
                continue;
            };
            if let Some((l, h)) = self.support(index) {
                any = true;
                for a in 0..3 {
                    lo[a] = lo[a].min(l[a]);
                    hi[a] = hi[a].max(h[a]);
                }
            }
        }
        if !any {
            return Influence::Nowhere;
        }
        let corners = std::array::from_fn(|c| {
            self.frame().to_physical(DVec3::new(
                if c & 1 == 0 { lo[0] } else { hi[0] },
                if c & 2 == 0 { lo[1] } else { hi[1] },
                if c & 4 == 0 { lo[2] } else { hi[2] },
            ))
        });
        Influence::Within(corners)
    }

    fn same_structure(&self, other: &Self) -> bool {
        self.frame() == other.frame() && self.knots() == other.knots()
    }
}
