//! Live editing: maps that are linear in their parameters, and the one mechanism that updates
//! what depends on them when a parameter moves.
//!
//! * [`LinearMap`] — a map `f(v) = b(v) + Σ_k c_k(v) t_k` whose base `b` and coefficients `c_k`
//!   do not depend on the parameter vectors `t_k`. B-spline lattices are linear in their
//!   control points (True 1992 §4), affine and frame moving least squares in their target
//!   handles (McPhail §5.4.2–5.4.3), thin-plate / volume splines in their targets. Each map says
//!   where moving a parameter can change it ([`Influence`]): a lattice's control point acts on
//!   the image of its support box only, a handle map everywhere.
//! * [`LiveGrid`] — such a map sampled on a coarse grid with the coefficients of the parameters
//!   being edited kept per node, so moving a parameter costs one multiply-add per grid node; the
//!   drag protocol of McPhail §5.5.4 ([`LiveGrid::select`] stores `f(v) − c_k(v) t_k` for the
//!   picked parameter, after which each drag step writes `f(v) = stored + c_k(v) t_k` exactly).
//!
//! The full-resolution counterpart is the incremental push-forward of `volmorph-warp`, which
//! redoes only the voxels a parameter's [`Influence`] reaches. Both take any [`LinearMap`], so
//! "move one parameter, update the region" is one mechanism for every such map.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_volume::Geometry;

use crate::map::check_finite;
use crate::{DeformError, SampledMap, SpaceMap};

/// Where moving some parameters of a [`LinearMap`] can change the map: outside this region the
/// map is the same before and after, whatever the new values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Influence {
    /// Nowhere: the parameters have no effect (e.g. control points whose support is empty).
    Nowhere,
    /// Anywhere in space (handle maps: every coefficient is non-zero almost everywhere).
    Everywhere,
    /// Inside the closed parallelepiped with these corners (physical coordinates; corner `c`
    /// has bit 0 of `c` for the high end of the first edge, bit 1 for the second, bit 2 for
    /// the third): the image of a box of parameter space under an affine frame, as a lattice's
    /// support box is.
    Within([DVec3; 8]),
}

impl Influence {
    /// The axis-aligned box `(lo, hi)` around the region, `None` for [`Influence::Nowhere`] and
    /// [`Influence::Everywhere`].
    #[must_use]
    pub fn bounds(&self) -> Option<(DVec3, DVec3)> {
        match self {
            Influence::Within(c) => Some(
                c.iter()
                    .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
                        (lo.min(*p), hi.max(*p))
                    }),
            ),
            _ => None,
        }
    }
}

/// A map affine in its parameter vectors: `f(v) = b(v) + Σ_k c_k(v) t_k`; see the
/// [module docs](self).
///
/// Parameters are 3-vectors in physical units: control points of a lattice, target positions of
/// point handles, target origins and axes of frames. Their order is fixed by the map and
/// documented by each implementation.
pub trait LinearMap: SpaceMap {
    /// The number `K` of parameter vectors.
    fn parameter_count(&self) -> usize;

    /// The current parameter vectors `t_k`, in the map's order.
    fn parameters(&self) -> Vec<DVec3>;

    /// Replace every parameter vector (same order and length as
    /// [`parameters`](Self::parameters)).
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for a wrong length, [`DeformError::NonFinite`] for a
    /// NaN/infinite vector; the map is unchanged on error.
    fn set_parameters(&mut self, values: &[DVec3]) -> Result<(), DeformError>;

    /// Set some parameters: `(k, value)` pairs, applied in order (a `k` may repeat). The
    /// default goes through [`set_parameters`](Self::set_parameters); maps where one parameter
    /// is cheap to change override it.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for `k` out of range, else as
    /// [`set_parameters`](Self::set_parameters); the map is unchanged on error.
    fn set_some_parameters(&mut self, changes: &[(usize, DVec3)]) -> Result<(), DeformError> {
        let mut all = self.parameters();
        for &(k, value) in changes {
            let n = all.len();
            *all.get_mut(k).ok_or_else(|| {
                DeformError::InvalidHandles(format!("parameter {k} out of range ({n} parameters)"))
            })? = value;
        }
        self.set_parameters(&all)
    }

    /// Write every coefficient `c_k(v)` into `out[..K]` (only `min(out.len(), K)` are written)
    /// and return the base `b(v)`, so that `f(v) = b(v) + Σ_k c_k(v) t_k`.
    fn coefficients_into(&self, v: DVec3, out: &mut [f64]) -> DVec3;

    /// `out[i] = c_k(points[i])`: one parameter's coefficient at many points. The default
    /// computes every coefficient at each point through
    /// [`coefficients_into`](Self::coefficients_into); maps with local support or a cheaper
    /// per-parameter form (lattices, thin-plate splines) override it.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for `k` out of range, [`DeformError::BufferLength`] if
    /// `out` is not one value per point.
    fn coefficient_column(
        &self,
        k: usize,
        points: &[DVec3],
        out: &mut [f64],
    ) -> Result<(), DeformError> {
        check_parameter(k, self.parameter_count())?;
        crate::map::check_len(points.len(), out.len())?;
        let n = self.parameter_count();
        out.par_chunks_mut(256)
            .zip(points.par_chunks(256))
            .for_each(|(o, p)| {
                let mut all = vec![0.0; n];
                for (o, &p) in o.iter_mut().zip(p) {
                    self.coefficients_into(p, &mut all);
                    *o = all[k];
                }
            });
        Ok(())
    }

    /// `true` when [`coefficients_into`](Self::coefficients_into) costs about as much as one
    /// evaluation of the map (moving least squares), so computing every coefficient at every
    /// node of a [`LiveGrid`] up front is the fast way; `false` (the default) when single
    /// columns are much cheaper (local support, or a factorised system).
    fn dense_coefficients_are_cheap(&self) -> bool {
        false
    }

    /// Where moving the parameters `ks` can change the map. The default,
    /// [`Influence::Everywhere`], is always correct.
    fn influence(&self, ks: &[usize]) -> Influence {
        let _ = ks;
        Influence::Everywhere
    }

    /// `true` if `other` has the same base and coefficients (only the parameter values may
    /// differ): same knots and frame for a lattice, same sources and weighting for a handle
    /// map. An engine built for `self` can then be moved to `other` by parameter edits.
    fn same_structure(&self, other: &Self) -> bool
    where
        Self: Sized;
}

/// `Ok` if `k < count`.
///
/// # Errors
/// [`DeformError::InvalidHandles`] otherwise.
pub fn check_parameter(k: usize, count: usize) -> Result<(), DeformError> {
    if k < count {
        Ok(())
    } else {
        Err(DeformError::InvalidHandles(format!(
            "parameter {k} out of range ({count} parameters)"
        )))
    }
}

/// The parameters whose values differ between `a` and `b` (same length assumed; extra entries
/// of the longer one are ignored).
#[must_use]
pub fn changed_parameters(a: &[DVec3], b: &[DVec3]) -> Vec<usize> {
    a.iter()
        .zip(b)
        .enumerate()
        .filter(|(_, (x, y))| x != y)
        .map(|(k, _)| k)
        .collect()
}

/// A selected parameter during a drag: `f(v) − c_k(v) t_k` at every node.
#[derive(Debug, Clone)]
struct Selection {
    index: usize,
    base: Vec<DVec3>,
}

/// A [`LinearMap`] sampled on a grid, with the coefficients of edited parameters stored per
/// node, for real-time parameter edits (McPhail §5.5.4); see the [module docs](self).
///
/// Columns of coefficients are computed when a parameter is first moved or selected and kept;
/// for maps whose dense coefficients are cheap
/// ([`LinearMap::dense_coefficients_are_cheap`]) every column is computed up front in one
/// pass over the nodes. Memory: one `f64` per node per stored column (32³ nodes × 200
/// handles = 52 MB).
#[derive(Debug, Clone)]
pub struct LiveGrid<M: LinearMap> {
    map: M,
    sampled: SampledMap,
    /// Node positions (physical), x fastest, for lazily computed columns.
    nodes: Vec<DVec3>,
    /// Column `k`: `c_k` at every node, once computed.
    columns: Vec<Option<Vec<f64>>>,
    parameters: Vec<DVec3>,
    selection: Option<Selection>,
}

impl<M: LinearMap> LiveGrid<M> {
    /// Sample `map` on `grid`; compute every coefficient column up front when the map says
    /// dense coefficients are cheap (parallel over nodes).
    ///
    /// # Errors
    /// As [`SampledMap::from_map`]; [`DeformError::Io`] if the node count or nodes ×
    /// parameters coefficients exceed the allocation limit.
    pub fn new(map: M, grid: Geometry) -> Result<Self, DeformError> {
        grid.validate()?;
        let n = volmorph_io::checked_len(&grid.dims, std::mem::size_of::<DVec3>())?;
        let parameters = map.parameters();
        let k = parameters.len();
        let [nx, ny, _] = grid.dims;
        let nodes: Vec<DVec3> = (0..n)
            .into_par_iter()
            .map(|i| {
                grid.index_to_physical(DVec3::new(
                    (i % nx) as f64,
                    (i / nx % ny) as f64,
                    (i / (nx * ny)) as f64,
                ))
            })
            .collect();
        let (positions, columns) = if map.dense_coefficients_are_cheap() {
            let (p, c) = dense_columns(&map, &nodes, &parameters)?;
            (p, c.into_iter().map(Some).collect())
        } else {
            let mut p = vec![DVec3::ZERO; n];
            map.apply_grid(&grid, &mut p)?;
            (p, vec![None; k])
        };
        let sampled = SampledMap::from_positions(grid, positions)?;
        Ok(Self {
            map,
            sampled,
            nodes,
            columns,
            parameters,
            selection: None,
        })
    }

    /// The exact map with the current parameters (the per-voxel mode).
    #[must_use]
    pub fn map(&self) -> &M {
        &self.map
    }

    /// The sampled map (trilinear between nodes).
    #[must_use]
    pub fn sampled(&self) -> &SampledMap {
        &self.sampled
    }

    /// Current parameter vectors.
    #[must_use]
    pub fn parameters(&self) -> &[DVec3] {
        &self.parameters
    }

    /// The stored coefficients `c_k` of parameter `k` at every node (x fastest), if computed.
    #[must_use]
    pub fn coefficients(&self, k: usize) -> Option<&[f64]> {
        self.columns.get(k)?.as_deref()
    }

    /// Compute and keep column `k` if it is not stored yet.
    fn ensure_column(&mut self, k: usize) -> Result<(), DeformError> {
        check_parameter(k, self.parameters.len())?;
        if self.columns[k].is_none() {
            let mut c = Vec::new();
            c.try_reserve_exact(self.nodes.len()).map_err(|_| {
                volmorph_io::IoError::Size(format!(
                    "no memory for a coefficient column of {} nodes",
                    self.nodes.len()
                ))
            })?;
            c.resize(self.nodes.len(), 0.0);
            self.map.coefficient_column(k, &self.nodes, &mut c)?;
            self.columns[k] = Some(c);
        }
        Ok(())
    }

    fn column(&self, k: usize) -> &[f64] {
        self.columns[k].as_deref().unwrap_or(&[])
    }

    fn commit(&mut self, k: usize, t: DVec3) -> Result<(), DeformError> {
        self.map.set_some_parameters(&[(k, t)])?;
        self.parameters[k] = t;
        Ok(())
    }

    /// Move parameter `k` to `t`: every node gains `c_k(v)·(t − t_old)` (one multiply-add per
    /// node). Clears a selection of another parameter.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for `k` out of range, [`DeformError::NonFinite`] for a
    /// NaN/infinite `t`; the grid is unchanged on error.
    pub fn move_parameter(&mut self, k: usize, t: DVec3) -> Result<(), DeformError> {
        if self.selection.as_ref().is_some_and(|s| s.index == k) {
            return self.drag_selected(t);
        }
        check_parameter(k, self.parameters.len())?;
        check_finite("parameter", &[t])?;
        self.ensure_column(k)?;
        let delta = t - self.parameters[k];
        self.commit(k, t)?;
        self.selection = None;
        let c = self.columns[k].as_deref().unwrap_or(&[]);
        for (p, &ck) in self.sampled.positions.iter_mut().zip(c) {
            *p += ck * delta;
        }
        Ok(())
    }

    /// Select parameter `k` for a drag: store `f(v) − c_k(v) t_k` at every node (§5.5.4).
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for `k` out of range.
    pub fn select(&mut self, k: usize) -> Result<(), DeformError> {
        self.ensure_column(k)?;
        let t = self.parameters[k];
        let mut base = self.selection.take().map(|s| s.base).unwrap_or_default();
        base.clear();
        base.extend(
            self.sampled
                .positions
                .iter()
                .zip(self.column(k))
                .map(|(p, &ck)| *p - ck * t),
        );
        self.selection = Some(Selection { index: k, base });
        Ok(())
    }

    /// The selected parameter, if any.
    #[must_use]
    pub fn selected(&self) -> Option<usize> {
        self.selection.as_ref().map(|s| s.index)
    }

    /// Move the selected parameter to `t`: every node becomes `stored + c_k(v)·t`.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] if nothing is selected, [`DeformError::NonFinite`] for
    /// a NaN/infinite `t`.
    pub fn drag_selected(&mut self, t: DVec3) -> Result<(), DeformError> {
        let Some(k) = self.selected() else {
            return Err(DeformError::InvalidHandles(
                "no parameter selected for dragging".into(),
            ));
        };
        check_finite("parameter", &[t])?;
        self.commit(k, t)?;
        let c = self.columns[k].as_deref().unwrap_or(&[]);
        if let Some(sel) = &self.selection {
            for ((p, b), &ck) in self.sampled.positions.iter_mut().zip(&sel.base).zip(c) {
                *p = *b + ck * t;
            }
        }
        Ok(())
    }

    /// Replace every parameter and update every node from the stored columns (`O(nodes ×
    /// changed parameters)`, no source-dependent work); columns of changed parameters are
    /// computed first where missing.
    ///
    /// # Errors
    /// As [`LinearMap::set_parameters`]; the grid is unchanged on error.
    pub fn set_parameters(&mut self, values: &[DVec3]) -> Result<(), DeformError> {
        if values.len() != self.parameters.len() {
            return Err(DeformError::InvalidHandles(format!(
                "{} parameters for a map of {}",
                values.len(),
                self.parameters.len()
            )));
        }
        check_finite("parameter", values)?;
        let changed = changed_parameters(&self.parameters, values);
        for &k in &changed {
            self.ensure_column(k)?;
        }
        self.map.set_parameters(values)?;
        let old = std::mem::replace(&mut self.parameters, values.to_vec());
        let columns = &self.columns;
        let deltas: Vec<(usize, DVec3)> =
            changed.iter().map(|&k| (k, values[k] - old[k])).collect();
        self.sampled
            .positions
            .par_chunks_mut(4096)
            .enumerate()
            .for_each(|(chunk, p)| {
                let start = chunk * 4096;
                for &(k, d) in &deltas {
                    let c = &columns[k].as_deref().unwrap_or(&[])[start..start + p.len()];
                    for (p, &ck) in p.iter_mut().zip(c) {
                        *p += ck * d;
                    }
                }
            });
        self.selection = None;
        Ok(())
    }
}

/// Every node's image and every coefficient column in one parallel pass over the nodes.
fn dense_columns<M: LinearMap>(
    map: &M,
    nodes: &[DVec3],
    parameters: &[DVec3],
) -> Result<(Vec<DVec3>, Vec<Vec<f64>>), DeformError> {
    let n = nodes.len();
    let k = parameters.len();
    volmorph_io::checked_len(&[n, k], std::mem::size_of::<f64>())?;
    let mut columns: Vec<Vec<f64>> = (0..k).map(|_| vec![0.0; n]).collect();
    let mut positions = vec![DVec3::ZERO; n];
    // Each chunk of nodes owns its piece of every column.
    const CHUNK: usize = 512;
    let chunks = n.div_ceil(CHUNK);
    let mut pieces: Vec<Vec<&mut [f64]>> = (0..chunks).map(|_| Vec::with_capacity(k)).collect();
    for col in &mut columns {
        for (c, piece) in col.chunks_mut(CHUNK).enumerate() {
            pieces[c].push(piece);
        }
    }
    pieces
        .into_par_iter()
        .zip(positions.par_chunks_mut(CHUNK))
        .zip(nodes.par_chunks(CHUNK))
        .for_each(|((mut rows, pos), pts)| {
            let mut scratch = vec![0.0; k];
            for (local, (p, &v)) in pos.iter_mut().zip(pts).enumerate() {
                let mut f = map.coefficients_into(v, &mut scratch);
                for ((row, &ck), t) in rows.iter_mut().zip(&scratch).zip(parameters) {
                    row[local] = ck;
                    f += ck * *t;
                }
                *p = f;
            }
        });
    Ok((positions, columns))
}

impl<M: LinearMap> SpaceMap for LiveGrid<M> {
    fn apply(&self, p: DVec3) -> DVec3 {
        self.sampled.apply(p)
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.sampled.jacobian(p)
    }

    fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        self.sampled.apply_grid(grid, out)
    }
}
