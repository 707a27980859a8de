//! Evaluation on tensor grids of parameters with precomputed basis tables.
//!
//! When a spline is evaluated at every point of a grid `u_0[i] × u_1[j] × u_2[k]` (every voxel
//! of a volume pushed through a lattice map, True 1992 §5.2), the basis values along each axis
//! depend only on that axis's parameter, so they are computed once per axis into a
//! [`BasisTable`] and reused for every grid point, and for every spline sharing the knots (True's
//! observation that the coefficient tables do not change when control points move). Grid
//! points are processed in parallel chunks with rayon; nothing is allocated per point.
//!
//! Output layout: grid point `(i_0, …, i_{N−1})` has linear index
//! `i_0 + g_0·(i_1 + g_1·(…))` (axis 0 fastest, like control nets and voxels) and occupies
//! `dim` values in the value buffer and `N·dim` values (axis-major) in the gradient buffer.

use rayon::prelude::*;

use crate::basis::{BASIS_BUF, basis_and_first_unchecked, basis_unchecked};
use crate::spline::checked_count;
use crate::{KnotVector, SplineError, TensorBSpline};

/// Grid points per parallel work item: large enough to amortise scheduling, small enough to
/// balance two to a few dozen cores on typical volumes.
const POINTS_PER_TASK: usize = 4096;

/// Basis values (and optionally first derivatives) of one knot vector at a list of parameters.
///
/// ```
/// use volmorph_spline::{BasisTable, KnotVector, uniform_cubic};
/// // True's lattice: granularity G = 4 samples per unit region.
/// let kv = KnotVector::uniform(3, 9, [0.0, 6.0]).unwrap();
/// let params: Vec<f64> = (0..24).map(|e| f64::from(e) / 4.0).collect();
/// let table = BasisTable::new(&kv, &params, false).unwrap();
/// // Entry e blends control points first(e) .. first(e)+3 with True's B0..B3 at (e mod G)/G.
/// assert_eq!(table.first(5), Some(1));
/// let b = uniform_cubic(0.25);
/// for (x, y) in table.values(5).unwrap().iter().zip(b) {
///     assert!((x - y).abs() < 1e-15);
/// }
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct BasisTable {
    knots: KnotVector,
    params: Vec<f64>,
    first: Vec<usize>,
    vals: Vec<f64>,
    ders: Option<Vec<f64>>,
}

impl BasisTable {
    /// Tabulate the `p + 1` non-zero basis functions of `kv` at each parameter (and their first
    /// derivatives when `with_derivatives`).
    ///
    /// # Errors
    /// [`SplineError::ParameterOutsideDomain`] for a parameter outside the domain or NaN,
    /// [`SplineError::TooLarge`] for an absurd table size.
    pub fn new(
        kv: &KnotVector,
        params: &[f64],
        with_derivatives: bool,
    ) -> Result<Self, SplineError> {
        let w = kv.degree() + 1;
        let len = checked_count(&[params.len(), w])?;
        let mut first = Vec::with_capacity(params.len());
        let mut vals = vec![0.0; len];
        let mut ders = with_derivatives.then(|| vec![0.0; len]);
        let mut v = [0.0; BASIS_BUF];
        let mut d = [0.0; BASIS_BUF];
        for (i, &u) in params.iter().enumerate() {
            let span = kv.find_span(u)?;
            first.push(span - kv.degree());
            if let Some(ders) = ders.as_mut() {
                basis_and_first_unchecked(kv.knots(), kv.degree(), span, u, &mut v, &mut d);
                ders[i * w..(i + 1) * w].copy_from_slice(&d[..w]);
            } else {
                basis_unchecked(kv.knots(), kv.degree(), span, u, &mut v);
            }
            vals[i * w..(i + 1) * w].copy_from_slice(&v[..w]);
        }
        Ok(Self {
            knots: kv.clone(),
            params: params.to_vec(),
            first,
            vals,
            ders,
        })
    }

    /// The knot vector the table was built for.
    #[must_use]
    pub fn knot_vector(&self) -> &KnotVector {
        &self.knots
    }

    /// The tabulated parameters.
    #[must_use]
    pub fn params(&self) -> &[f64] {
        &self.params
    }

    /// Number of tabulated parameters.
    #[must_use]
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// `true` if no parameter is tabulated.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// `true` if first derivatives were tabulated.
    #[must_use]
    pub fn has_derivatives(&self) -> bool {
        self.ders.is_some()
    }

    /// Index of the first control point influencing parameter `i` (`span − p`); `None` if
    /// `i >= self.len()`.
    #[must_use]
    pub fn first(&self, i: usize) -> Option<usize> {
        self.first.get(i).copied()
    }

    /// The `p + 1` basis values at parameter `i`; `None` if `i >= self.len()`.
    #[must_use]
    pub fn values(&self, i: usize) -> Option<&[f64]> {
        let w = self.knots.degree() + 1;
        self.vals.get(i * w..(i + 1) * w)
    }

    /// The `p + 1` first derivatives at parameter `i`; `None` if not tabulated or
    /// `i >= self.len()`.
    #[must_use]
    pub fn derivatives(&self, i: usize) -> Option<&[f64]> {
        let w = self.knots.degree() + 1;
        self.ders.as_ref().and_then(|d| d.get(i * w..(i + 1) * w))
    }
}

impl<const N: usize> TensorBSpline<N> {
    /// Evaluate on the grid `tables[0].params() × tables[1].params() × …` (see the
    /// [module docs](crate::grid) for the layout). `values` needs `dim` entries per grid point;
    /// `gradients`, when given, `N·dim` per point and tables built with derivatives. Runs in
    /// parallel over chunks of grid points; no allocation per point.
    ///
    /// # Errors
    /// [`SplineError::TableMismatch`] if a table was built for another knot vector than the
    /// spline's axis, [`SplineError::MissingDerivatives`] if gradients are requested from a
    /// table without derivatives, [`SplineError::BufferLength`] for wrong buffer sizes,
    /// [`SplineError::TooLarge`].
    ///
    /// ```
    /// use volmorph_spline::{BSplineSurface, BasisTable, KnotVector};
    /// let k = KnotVector::clamped_uniform(2, 4, [0.0, 1.0]).unwrap();
    /// let s = BSplineSurface::new([k.clone(), k.clone()], 1, (0..16).map(f64::from).collect())
    ///     .unwrap();
    /// let us = [0.0, 0.3, 1.0];
    /// let vs = [0.1, 0.9];
    /// let t = [BasisTable::new(&k, &us, false).unwrap(), BasisTable::new(&k, &vs, false).unwrap()];
    /// let mut out = [0.0; 6];
    /// s.eval_grid_into(&t, &mut out, None).unwrap();
    /// assert!((out[1 + 3] - s.eval([0.3, 0.9]).unwrap()[0]).abs() < 1e-14);
    /// ```
    pub fn eval_grid_into(
        &self,
        tables: &[BasisTable; N],
        values: &mut [f64],
        gradients: Option<&mut [f64]>,
    ) -> Result<(), SplineError> {
        for (axis, t) in tables.iter().enumerate() {
            if t.knot_vector() != &self.knots()[axis] {
                return Err(SplineError::TableMismatch { axis });
            }
        }
        let grid: [usize; N] = std::array::from_fn(|a| tables[a].len());
        let npts = checked_count(&grid)?;
        let dim = self.dim();
        let expected = checked_count(&[npts, dim])?;
        if values.len() != expected {
            return Err(SplineError::BufferLength {
                expected,
                got: values.len(),
            });
        }
        if let Some(g) = gradients.as_deref() {
            let expected = checked_count(&[npts, N, dim])?;
            if g.len() != expected {
                return Err(SplineError::BufferLength {
                    expected,
                    got: g.len(),
                });
            }
            if let Some(axis) = tables.iter().position(|t| !t.has_derivatives()) {
                return Err(SplineError::MissingDerivatives { axis });
            }
        }
        if npts == 0 {
            return Ok(());
        }
        let net = self.net();
        let orders: [usize; N] = std::array::from_fn(|a| tables[a].knots.degree() + 1);
        let run = |start: usize, vchunk: &mut [f64], mut gchunk: Option<&mut [f64]>| {
            let mut vals = [[0.0; BASIS_BUF]; N];
            let mut ders = [[0.0; BASIS_BUF]; N];
            let mut idx = unravel(start, &grid);
            for (k, v) in vchunk.chunks_exact_mut(dim).enumerate() {
                let mut first = [0usize; N];
                for a in 0..N {
                    let i = idx[a];
                    first[a] = tables[a].first[i];
                    let w = orders[a];
                    vals[a][..w].copy_from_slice(&tables[a].vals[i * w..(i + 1) * w]);
                    if let (Some(d), true) = (&tables[a].ders, gchunk.is_some()) {
                        ders[a][..w].copy_from_slice(&d[i * w..(i + 1) * w]);
                    }
                }
                match gchunk.as_deref_mut() {
                    Some(g) => net.contract(
                        first,
                        orders,
                        &vals,
                        Some(&ders),
                        v,
                        Some(&mut g[k * N * dim..(k + 1) * N * dim]),
                    ),
                    None => net.contract(first, orders, &vals, None, v, None),
                }
                for a in 0..N {
                    idx[a] += 1;
                    if idx[a] < grid[a] {
                        break;
                    }
                    idx[a] = 0;
                }
            }
        };
        let chunk = POINTS_PER_TASK;
        match gradients {
            Some(g) => values
                .par_chunks_mut(chunk * dim)
                .zip(g.par_chunks_mut(chunk * N * dim))
                .enumerate()
                .for_each(|(c, (v, g))| run(c * chunk, v, Some(g))),
            None => values
                .par_chunks_mut(chunk * dim)
                .enumerate()
                .for_each(|(c, v)| run(c * chunk, v, None)),
        }
        Ok(())
    }
}

/// Multi-index (axis 0 fastest) of linear grid index `lin`.
fn unravel<const N: usize>(mut lin: usize, grid: &[usize; N]) -> [usize; N] {
    let mut idx = [0; N];
    for a in 0..N {
        idx[a] = lin % grid[a];
        lin /= grid[a];
    }
    idx
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BSplineVolume;

    #[test]
    fn grid_matches_pointwise_evaluation_with_gradients() {
        let ku = KnotVector::uniform(3, 7, [0.0, 4.0]).unwrap();
        let kv = KnotVector::clamped(2, &[0.5, 0.5], [0.0, 1.0]).unwrap();
        let kw = KnotVector::clamped_uniform(1, 3, [-1.0, 1.0]).unwrap();
        let n = 7 * kv.num_basis() * 3;
        let pts: Vec<f64> = (0..2 * n)
            .map(|i| (f64::from(i as u32) * 0.37).sin())
            .collect();
        let w: Vec<f64> = (0..n)
            .map(|i| 1.0 + 0.5 * (f64::from(i as u32)).cos())
            .collect();
        let s =
            BSplineVolume::new_rational([ku.clone(), kv.clone(), kw.clone()], 2, pts, w).unwrap();
        let pu: Vec<f64> = (0..=40).map(|i| f64::from(i) * 0.1).collect();
        let pv = [0.0, 0.25, 0.5, 0.75, 1.0];
        let pw = [-1.0, 0.0, 0.3, 1.0];
        let t = [
            BasisTable::new(&ku, &pu, true).unwrap(),
            BasisTable::new(&kv, &pv, true).unwrap(),
            BasisTable::new(&kw, &pw, true).unwrap(),
        ];
        let np = pu.len() * pv.len() * pw.len();
        let mut vals = vec![0.0; np * 2];
        let mut grads = vec![0.0; np * 6];
        s.eval_grid_into(&t, &mut vals, Some(&mut grads)).unwrap();
        let mut k = 0;
        for &w in &pw {
            for &v in &pv {
                for &u in &pu {
                    let (ev, eg) = s.eval_with_gradient([u, v, w]).unwrap();
                    assert!((ev[0] - vals[2 * k]).abs() < 1e-14);
                    assert!((ev[1] - vals[2 * k + 1]).abs() < 1e-14);
                    for c in 0..6 {
                        assert!((eg[c] - grads[6 * k + c]).abs() < 1e-12);
                    }
                    k += 1;
                }
            }
        }
        // Wrong table, wrong sizes, missing derivatives.
        let t_bad = [t[1].clone(), t[1].clone(), t[2].clone()];
        assert!(s.eval_grid_into(&t_bad, &mut vals, None).is_err());
        assert!(s.eval_grid_into(&t, &mut vals[1..], None).is_err());
        let t_nod = [
            BasisTable::new(&ku, &pu, false).unwrap(),
            t[1].clone(),
            t[2].clone(),
        ];
        assert!(
            s.eval_grid_into(&t_nod, &mut vals, Some(&mut grads))
                .is_err()
        );
        assert!(BasisTable::new(&ku, &[5.0], false).is_err());
    }
}
