//! Handle deformation that scales to tens of thousands of handles: an affine trend plus
//! compactly supported radial basis functions (Wendland's C² kernel), solved by a sparse
//! Cholesky factorisation.
//!
//! # The map
//!
//! For handle pairs `p_i → q_i` (`i < N`), [`WendlandMap`] is the push-forward
//!
//! ```text
//! f(x) = A x + b + Σ_i w_i φ(‖x − p_i‖ / ρ),        φ(s) = (1 − s)⁴₊ (4s + 1)
//! ```
//!
//! where `(A, b)` is the least-squares affine map of the pairs (a translation only when the
//! sources are too flat to fix an affine map, see [`MIN_AFFINE_CONDITION`]), and the weights
//! `w_i ∈ ℝ³` make the map interpolate the handles: `(K + λI) W = R` with
//! `K_ij = φ(‖p_i − p_j‖/ρ)` and `R_i = q_i − A p_i − b`. `φ` is Wendland's `φ₃,₁`, positive
//! definite in ℝ³ and C² (Wendland 1995; used for elastic registration by Fornefett, Rohr &
//! Stiehl 2001), so `K` is symmetric positive definite for distinct sources and is factorised
//! by Cholesky. Because `φ` vanishes beyond the support radius `ρ`, `K` has only the pairs
//! of sources closer than `ρ`: with `k` neighbours per handle it holds `≈ kN` entries, and
//! faer's supernodal sparse Cholesky (with its fill-reducing ordering) factorises it in far
//! less than the `O(N³)` time and `O(N²)` memory of the thin-plate spline's dense system.
//! Evaluation touches only the sources within `ρ` of the point, found through a uniform
//! cell grid of cell size `ρ`.
//!
//! Away from every handle (farther than `ρ`) the map is the affine trend; near the handles it
//! bends to pass through them exactly (with smoothing `λ = 0`). The Jacobian is analytic:
//! `∂f/∂x = A + Σ_i w_i ∇φ_iᵀ` with `∇φ_i = −20 (1 − s)³ (x − p_i) / ρ²`.
//!
//! # Support radius
//! By default `ρ` is chosen so that a handle has about [`DEFAULT_NEIGHBOURS`] others within
//! reach on average, from the sources' bounding box: `ρ = (3 k V / (4π N))^{1/3}` (the box
//! volume `V` with each edge at least 1 % of the diagonal, so flat handle sets get a finite
//! radius). A larger radius gives smoother, more global corrections at more cost.
//!
//! # Memory
//! Every size is checked against the memory budget ([`volmorph_io::budget`]) before it is
//! allocated: the kernel matrix's entries are counted (through the same neighbour grid,
//! stopping once the count passes what the budget holds) before any is computed, and the
//! Cholesky factor's non-zeros, known from the symbolic factorisation (faer's fill-reducing
//! ordering and column counts), are checked with the factorisation's workspace before the
//! numeric factorisation. A support reaching most of the handles makes both dense (`N²/2`
//! entries); the refusal names the `support`, the sizes and the default support.
//!
//! # Live edits
//! The map is linear in its targets (the trend is a least-squares fit, the weights a linear
//! solve), so it implements [`LinearMap`] with the targets as parameters: moving a target
//! re-solves with the kept Cholesky factor (no refactorisation), and live grids and the
//! incremental push-forward work with it. With `N` the number of handles, `M` the inverse
//! covariance of the sources about their mean `p̄`, the trend's coefficient of target `k` at
//! `x` is `a_k(x) = 1/N + (p_k − p̄)ᵀ M (x − p̄)` (`1/N` alone for a flat set, whose trend is
//! the translation `x − p̄ + q̄`), and the map's is
//! `c_k(x) = a_k(x) + Σ_i φ_i(x) [(K + λI)⁻¹ (e_k − a_k(P))]_i`. Moving one target changes
//! the trend, so its influence is everywhere.
//!
//! The neighbour grid is written here because it is twenty lines, needed for both the
//! assembly and every evaluation, and a general k-d tree crate would add more than it saves.

use std::sync::Arc;

use std::sync::atomic::{AtomicU64, Ordering};

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky, factorize_symbolic_cholesky};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, Mat, Side};
use glam::{DMat3, DVec3};
use rayon::prelude::*;

use volmorph_deform::live::{LinearMap, check_parameter};
use volmorph_deform::{DeformError, SpaceMap};

/// Average number of other handles within the support radius chosen by default. Enough for
/// the corrections between neighbouring handles to overlap smoothly; the factorisation cost
/// grows with it.
pub const DEFAULT_NEIGHBOURS: f64 = 40.0;

/// Smallest ratio of the smallest to the largest eigenvalue of the sources' covariance for
/// which the least-squares affine trend is fitted; flatter (coplanar, collinear) handle sets
/// get a translation only, which any set determines.
pub const MIN_AFFINE_CONDITION: f64 = 1e-8;

/// Bytes per kernel entry of the assembled lower triangle of `K + λI`: a `usize` row index
/// and an `f64` value (faer's compressed-column `SparseColMatRef<usize, f64>`, built in place
/// from the counted columns). Checked against the memory budget before the entries are
/// computed.
const MATRIX_BYTES_PER_ENTRY: u64 = 16;

/// Bytes per non-zero of the Cholesky factor: an `f64` (faer's
/// `SymbolicCholesky::len_val` values). Checked, with the factorisation's workspace, before
/// the numeric factorisation.
const FACTOR_BYTES_PER_ENTRY: u64 = 8;

/// Wendland's `φ₃,₁(s) = (1 − s)⁴ (4s + 1)` for `s < 1`, 0 beyond.
#[must_use]
#[inline]
pub fn wendland_c2(s: f64) -> f64 {
    if s >= 1.0 {
        0.0
    } else {
        let t = 1.0 - s;
        let t2 = t * t;
        t2 * t2 * (4.0 * s + 1.0)
    }
}

/// Sources bucketed in cubic cells of edge `cell` (compressed rows: the indices of cell `c`
/// are `items[start[c]..start[c + 1]]`).
#[derive(Debug, Clone)]
struct CellGrid {
    origin: DVec3,
    inv_cell: f64,
    dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl CellGrid {
    fn new(points: &[DVec3], cell: f64) -> Result<Self, DeformError> {
        let (lo, hi) = bounds(points);
        let inv_cell = 1.0 / cell;
        let mut dims = [1usize; 3];
        let mut total: usize = 1;
        for (a, d) in dims.iter_mut().enumerate() {
            *d = ((hi[a] - lo[a]) * inv_cell).floor() as usize + 1;
            total = total.saturating_mul(*d);
        }
        let mut start = volmorph_io::try_vec("the handle neighbour grid", total + 1, 0u32)?;
        let mut grid = Self {
            origin: lo,
            inv_cell,
            dims,
            start: Vec::new(),
            items: vec![0; points.len()],
        };
        let keys: Vec<usize> = points.iter().map(|&p| grid.key(grid.cell_of(p))).collect();
        for &k in &keys {
            start[k + 1] += 1;
        }
        for c in 0..total {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        for (i, &k) in keys.iter().enumerate() {
            grid.items[fill[k] as usize] = i as u32;
            fill[k] += 1;
        }
        grid.start = start;
        Ok(grid)
    }

    fn cell_of(&self, p: DVec3) -> [i64; 3] {
        let q = (p - self.origin) * self.inv_cell;
        [q.x.floor() as i64, q.y.floor() as i64, q.z.floor() as i64]
    }

    fn key(&self, c: [i64; 3]) -> usize {
        (c[0] as usize) + self.dims[0] * ((c[1] as usize) + self.dims[1] * (c[2] as usize))
    }

    /// Call `f(i)` for every point in the 27 cells around `p` (a superset of the points
    /// within one cell edge of `p`).
    #[inline]
    fn for_each_near(&self, p: DVec3, mut f: impl FnMut(usize)) {
        let c = self.cell_of(p);
        for dz in -1..=1 {
            let z = c[2].saturating_add(dz);
            if z < 0 || z >= self.dims[2] as i64 {
                continue;
            }
            for dy in -1..=1 {
                let y = c[1].saturating_add(dy);
                if y < 0 || y >= self.dims[1] as i64 {
                    continue;
                }
                for dx in -1..=1 {
                    let x = c[0].saturating_add(dx);
                    if x < 0 || x >= self.dims[0] as i64 {
                        continue;
                    }
                    let k = self.key([x, y, z]);
                    for &i in &self.items[self.start[k] as usize..self.start[k + 1] as usize] {
                        f(i as usize);
                    }
                }
            }
        }
    }
}

fn bounds(points: &[DVec3]) -> (DVec3, DVec3) {
    points.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    )
}

/// Call `f(i, s)` for every source `i ≥ j` within the support of source `j`, with
/// `s = ‖p_i − p_j‖ / ρ < 1`: the entries of column `j` of the kernel matrix's lower triangle.
/// Counting and assembly both go through here, so they agree entry for entry.
#[inline]
fn for_each_in_column(
    grid: &CellGrid,
    sources: &[DVec3],
    j: usize,
    rho: f64,
    mut f: impl FnMut(usize, f64),
) {
    let inv_rho = 1.0 / rho;
    let pj = sources[j];
    grid.for_each_near(pj, |i| {
        if i >= j {
            let s = (sources[i] - pj).length() * inv_rho;
            if s < 1.0 {
                f(i, s);
            }
        }
    });
}

/// The default support radius for `sources` (see the module documentation).
#[must_use]
pub fn default_support(sources: &[DVec3]) -> f64 {
    let (lo, hi) = bounds(sources);
    let ext = hi - lo;
    let floor = (0.01 * ext.length()).max(f64::MIN_POSITIVE);
    let e = ext.max(DVec3::splat(floor));
    let v = e.x * e.y * e.z;
    let n = sources.len().max(1) as f64;
    (3.0 * DEFAULT_NEIGHBOURS * v / (4.0 * std::f64::consts::PI * n)).cbrt()
}

/// The trend's dependence on the targets, fixed by the sources: the least-squares affine
/// fit about the sources' mean, or a translation for flat sets.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Trend {
    /// `a_k(x) = 1/N + (p_k − mean)ᵀ inv_cov (x − mean)`.
    Affine { mean: DVec3, inv_cov: DMat3 },
    /// `a_k(x) = 1/N`, base `x − mean`.
    Translation { mean: DVec3 },
}

impl Trend {
    fn of(sources: &[DVec3]) -> Self {
        let n = sources.len() as f64;
        let mean = sources.iter().sum::<DVec3>() / n;
        let mut spp = DMat3::ZERO;
        for &p in sources {
            let dp = p - mean;
            spp += outer(dp, dp);
        }
        // det / trace³ is a scale-free flatness test of the (positive semi-definite)
        // covariance: it is 1/27 for an isotropic set and 0 for a coplanar one.
        let tr = spp.x_axis.x + spp.y_axis.y + spp.z_axis.z;
        let flat =
            tr.is_nan() || tr <= 0.0 || spp.determinant() <= MIN_AFFINE_CONDITION * tr * tr * tr;
        if flat {
            Trend::Translation { mean }
        } else {
            Trend::Affine {
                mean,
                inv_cov: spp.inverse(),
            }
        }
    }

    /// The part of the trend at `x` that does not depend on the targets.
    fn base(&self, x: DVec3) -> DVec3 {
        match *self {
            Trend::Affine { .. } => DVec3::ZERO,
            Trend::Translation { mean } => x - mean,
        }
    }

    /// `M (x − p̄)` for the affine trend (zero for a translation), so that
    /// `a_k(x) = 1/N + (p_k − p̄) · lever(x)`.
    fn lever(&self, x: DVec3) -> DVec3 {
        match *self {
            Trend::Affine { mean, inv_cov } => inv_cov * (x - mean),
            Trend::Translation { .. } => DVec3::ZERO,
        }
    }

    fn mean(&self) -> DVec3 {
        match *self {
            Trend::Affine { mean, .. } | Trend::Translation { mean } => mean,
        }
    }
}

/// Least-squares affine map `x ↦ A x + b` sending `sources` towards `targets`, of the form
/// `trend` fixes: a translation when the sources are too flat (see [`MIN_AFFINE_CONDITION`]
/// and [`Trend::of`]).
fn affine_fit(trend: &Trend, sources: &[DVec3], targets: &[DVec3]) -> (DMat3, DVec3) {
    let qs = targets.iter().sum::<DVec3>() / targets.len() as f64;
    match *trend {
        Trend::Translation { mean } => (DMat3::IDENTITY, qs - mean),
        Trend::Affine { mean, inv_cov } => {
            let mut sqp = DMat3::ZERO;
            for (&p, &q) in sources.iter().zip(targets) {
                sqp += outer(q - qs, p - mean);
            }
            let a = sqp * inv_cov;
            (a, qs - a * mean)
        }
    }
}

fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// What a Wendland map keeps of its sources, shared by the maps that differ only in their
/// targets (a live edit clones the map, not the factorisation).
#[derive(Debug)]
struct System {
    sources: Vec<DVec3>,
    support: f64,
    smoothing: f64,
    grid: CellGrid,
    /// Structure (fill-reducing ordering, supernodes) of the Cholesky factor of `K + λI`.
    symbolic: SymbolicCholesky<usize>,
    /// The factor's values, `symbolic.len_val()` of them.
    factor: Vec<f64>,
    trend: Trend,
}

impl System {
    /// `(K + λI)⁻¹ R` for the `c` columns of `rhs` (`n × c`, row-major by handle).
    fn solve(&self, rhs: &mut Mat<f64>) {
        let par = faer::get_global_parallelism();
        let scratch = self
            .symbolic
            .solve_in_place_scratch::<f64>(rhs.ncols(), par);
        LltRef::new(&self.symbolic, &self.factor).solve_in_place_with_conj(
            Conj::No,
            rhs.as_mut(),
            par,
            MemStack::new(&mut MemBuffer::new(scratch)),
        );
    }

    /// `Σ_i φ(‖x − p_i‖/ρ) w_i` for any per-handle values `w`.
    #[inline]
    fn kernel_sum<T>(&self, x: DVec3, w: &[T]) -> T
    where
        T: Copy + std::ops::Mul<f64, Output = T> + std::ops::AddAssign + Default,
    {
        let inv = 1.0 / self.support;
        let r2max = self.support * self.support;
        let mut d = T::default();
        self.grid.for_each_near(x, |i| {
            // Most candidates lie outside the support: reject them before the square root.
            let r2 = (x - self.sources[i]).length_squared();
            if r2 < r2max {
                d += w[i] * wendland_c2(r2.sqrt() * inv);
            }
        });
        d
    }
}

/// Affine trend plus compactly supported Wendland corrections through handle pairs (see the
/// module documentation): a push-forward `SpaceMap` sending each source to its target, linear
/// in the targets ([`LinearMap`]).
#[derive(Debug, Clone)]
pub struct WendlandMap {
    system: Arc<System>,
    targets: Vec<DVec3>,
    weights: Vec<DVec3>,
    affine: DMat3,
    translation: DVec3,
}

impl WendlandMap {
    /// The map sending `sources[i]` to `targets[i]`, with the default support radius
    /// ([`default_support`]) and smoothing `smoothing ≥ 0` (0 interpolates; larger values
    /// trade exactness at the handles for smoothness, in units of the kernel's peak).
    ///
    /// # Errors
    /// As [`WendlandMap::with_support`].
    pub fn new(sources: &[DVec3], targets: &[DVec3], smoothing: f64) -> Result<Self, DeformError> {
        Self::with_support(sources, targets, None, smoothing, &volmorph_io::NoProgress)
    }

    /// The map with support radius `support` (physical units; `None` for the default), and
    /// progress reported through `progress` (stages: counting the entries, assembly,
    /// factorisation).
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for no handles, mismatched counts, a non-positive
    /// support or negative smoothing; [`DeformError::NonFinite`] for a non-finite coordinate;
    /// [`DeformError::Io`] when the kernel matrix, its fill-reducing ordering or its Cholesky
    /// factor would exceed the memory budget (checked before each is allocated; the message
    /// names the `support`, the sizes and the default support);
    /// [`DeformError::Singular`] when the factorisation fails (coincident sources);
    /// [`DeformError::Cancelled`] when cancelled.
    pub fn with_support(
        sources: &[DVec3],
        targets: &[DVec3],
        support: Option<f64>,
        smoothing: f64,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Self, DeformError> {
        let n = sources.len();
        if n == 0 || n != targets.len() {
            return Err(DeformError::InvalidHandles(format!(
                "{n} sources and {} targets: give at least one pair, as many targets as \
                 sources",
                targets.len()
            )));
        }
        volmorph_deform::map::check_finite("source", sources)?;
        volmorph_deform::map::check_finite("target", targets)?;
        if !(smoothing.is_finite() && smoothing >= 0.0) {
            return Err(DeformError::InvalidHandles(format!(
                "smoothing must be finite and ≥ 0, got {}",
                volmorph_io::Num(smoothing)
            )));
        }
        let rho = support.unwrap_or_else(|| default_support(sources));
        if !(rho.is_finite() && rho > 0.0) {
            return Err(DeformError::InvalidHandles(format!(
                "support radius must be positive and finite, got {}",
                volmorph_io::Num(rho)
            )));
        }
        let grid = CellGrid::new(sources, rho)?;
        let default = default_support(sources);
        let what = |entries: &str| {
            format!(
                "the compact-support system of {n} handles with `support` {} ({entries}; the \
                 default support for these handles, {}, reaches about {DEFAULT_NEIGHBOURS} \
                 others per handle)",
                volmorph_io::Num(rho),
                volmorph_io::Num(default),
            )
        };

        // Count the lower triangle's entries, column by column, before computing any: a
        // support reaching most of the handles makes the system dense, and counting stops
        // as soon as the count passes what the budget can hold.
        progress.start("counting the compact-support system's entries", n as u64);
        let limit = volmorph_io::memory_limit();
        let cap = limit / MATRIX_BYTES_PER_ENTRY;
        let counted = AtomicU64::new(0);
        let counts: Vec<usize> = (0..n)
            .into_par_iter()
            .map(|j| {
                if counted.load(Ordering::Relaxed) > cap {
                    return 0;
                }
                let mut c = 0usize;
                for_each_in_column(&grid, sources, j, rho, |_, _| c += 1);
                counted.fetch_add(c as u64, Ordering::Relaxed);
                progress.advance(1);
                c
            })
            .collect();
        let nnz = counted.into_inner();
        if nnz > cap {
            // Counting stopped early: `nnz` is a lower bound.
            return Err(volmorph_io::IoError::Budget {
                what: what(&format!("at least {nnz} kernel entries")),
                bytes: nnz.saturating_mul(MATRIX_BYTES_PER_ENTRY),
                limit,
            }
            .into());
        }
        progress.check().map_err(cancelled)?;
        volmorph_io::check_elems(
            &what(&format!("{nnz} kernel entries")),
            nnz,
            MATRIX_BYTES_PER_ENTRY,
        )?;

        // Assembly: the lower triangle in compressed columns (rows sorted), each column
        // written in parallel into its own slice.
        progress.start("assembling the compact-support system", n as u64);
        let nnz = nnz as usize;
        let mut col_ptr = volmorph_io::try_vec("kernel column starts", n + 1, 0usize)?;
        for (j, &c) in counts.iter().enumerate() {
            col_ptr[j + 1] = col_ptr[j] + c;
        }
        let mut row_idx = volmorph_io::try_vec("kernel row indices", nnz, 0usize)?;
        let mut values = volmorph_io::try_vec("kernel entries", nnz, 0.0f64)?;
        let mut columns = Vec::with_capacity(n);
        let (mut rows_rest, mut values_rest) = (&mut row_idx[..], &mut values[..]);
        for &c in &counts {
            let (r, rr) = std::mem::take(&mut rows_rest).split_at_mut(c);
            let (v, vr) = std::mem::take(&mut values_rest).split_at_mut(c);
            columns.push((r, v));
            (rows_rest, values_rest) = (rr, vr);
        }
        columns
            .into_par_iter()
            .enumerate()
            .for_each(|(j, (rows, vals))| {
                let mut col = Vec::with_capacity(rows.len());
                for_each_in_column(&grid, sources, j, rho, |i, s| {
                    col.push((i, wendland_c2(s) + if i == j { smoothing } else { 0.0 }));
                });
                col.sort_unstable_by_key(|&(i, _)| i);
                for ((r, v), (i, x)) in rows.iter_mut().zip(vals.iter_mut()).zip(col) {
                    *r = i;
                    *v = x;
                }
                progress.advance(1);
            });
        progress.check().map_err(cancelled)?;
        let k = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx),
            &values,
        );

        // The factor's size from the symbolic factorisation (fill-reducing ordering, column
        // counts), checked with the numeric factorisation's workspace before allocating.
        progress.start("factorising (sparse Cholesky)", 1);
        let ordering = amd::order_maybe_unsorted_scratch::<usize>(n, nnz);
        volmorph_io::check_bytes(
            &what(&format!(
                "the fill-reducing ordering of {nnz} kernel entries"
            )),
            ordering.size_bytes() as u64,
        )?;
        let symbolic = factorize_symbolic_cholesky(
            k.symbolic(),
            Side::Lower,
            Default::default(),
            Default::default(),
        )
        .map_err(|e| DeformError::Singular(format!("ordering the sparse system: {e:?}")))?;
        let par = faer::get_global_parallelism();
        let workspace = symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default());
        let fill = symbolic.len_val();
        let factor_bytes = (fill as u64)
            .saturating_mul(FACTOR_BYTES_PER_ENTRY)
            .saturating_add(workspace.size_bytes() as u64);
        volmorph_io::check_bytes(
            &what(&format!(
                "a Cholesky factor of {fill} non-zeros for {nnz} kernel entries, with its \
                 workspace"
            )),
            factor_bytes,
        )?;
        let mut factor = volmorph_io::try_vec("the Cholesky factor", fill, 0.0f64)?;
        let mut buffer =
            MemBuffer::try_new(workspace).map_err(|_| volmorph_io::IoError::Alloc {
                what: "the Cholesky factorisation's workspace".into(),
                bytes: workspace.size_bytes() as u64,
            })?;
        symbolic
            .factorize_numeric_llt(
                &mut factor,
                k,
                Side::Lower,
                Default::default(),
                par,
                MemStack::new(&mut buffer),
                Default::default(),
            )
            .map_err(|e| {
                DeformError::Singular(format!(
                    "the compact-support system is not positive definite ({e}); two sources \
                     coincide or nearly so"
                ))
            })?;
        drop(buffer);
        drop((col_ptr, row_idx, values));
        progress.advance(1);
        let system = Arc::new(System {
            sources: sources.to_vec(),
            support: rho,
            smoothing,
            grid,
            symbolic,
            factor,
            trend: Trend::of(sources),
        });
        Self::solved(system, targets.to_vec())
    }

    /// The map of `system` through `targets`: trend fit and weights by the kept factor.
    fn solved(system: Arc<System>, targets: Vec<DVec3>) -> Result<Self, DeformError> {
        let n = targets.len();
        let (affine, translation) = affine_fit(&system.trend, &system.sources, &targets);
        let mut rhs = Mat::<f64>::zeros(n, 3);
        for i in 0..n {
            let r = targets[i] - (affine * system.sources[i] + translation);
            for c in 0..3 {
                rhs[(i, c)] = r[c];
            }
        }
        system.solve(&mut rhs);
        let weights: Vec<DVec3> = (0..n)
            .map(|i| DVec3::new(rhs[(i, 0)], rhs[(i, 1)], rhs[(i, 2)]))
            .collect();
        if weights.iter().any(|w| !w.is_finite()) {
            return Err(DeformError::Singular(
                "the compact-support solve gave non-finite weights".into(),
            ));
        }
        Ok(Self {
            system,
            targets,
            weights,
            affine,
            translation,
        })
    }

    /// Move the targets (same count), keeping the sources' factorisation: one sparse solve.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for a wrong count, [`DeformError::NonFinite`] for a
    /// non-finite target; the map is unchanged on error.
    pub fn set_targets(&mut self, targets: &[DVec3]) -> Result<(), DeformError> {
        if targets.len() != self.targets.len() {
            return Err(DeformError::InvalidHandles(format!(
                "{} targets given for {} handles",
                targets.len(),
                self.targets.len()
            )));
        }
        volmorph_deform::map::check_finite("target", targets)?;
        *self = Self::solved(Arc::clone(&self.system), targets.to_vec())?;
        Ok(())
    }

    /// The support radius `ρ` in physical units.
    #[must_use]
    pub fn support(&self) -> f64 {
        self.system.support
    }

    /// The smoothing parameter.
    #[must_use]
    pub fn smoothing(&self) -> f64 {
        self.system.smoothing
    }

    /// The handles' sources.
    #[must_use]
    pub fn sources(&self) -> &[DVec3] {
        &self.system.sources
    }

    /// The handles' targets.
    #[must_use]
    pub fn targets(&self) -> &[DVec3] {
        &self.targets
    }

    /// The affine trend `(A, b)`: the map far from every handle.
    #[must_use]
    pub fn affine(&self) -> (DMat3, DVec3) {
        (self.affine, self.translation)
    }

    /// `a_k(x)` for every `k` into `out`, from the trend's lever at `x`.
    fn trend_coefficients(&self, lever: DVec3, out: &mut [f64]) {
        let sys = &*self.system;
        let inv_n = 1.0 / sys.sources.len() as f64;
        let mean = sys.trend.mean();
        for (o, &p) in out.iter_mut().zip(&sys.sources) {
            *o = inv_n + (p - mean).dot(lever);
        }
    }
}

fn cancelled(c: volmorph_io::Cancelled) -> DeformError {
    DeformError::Cancelled(c)
}

impl SpaceMap for WendlandMap {
    fn apply(&self, p: DVec3) -> DVec3 {
        self.affine * p + self.translation + self.system.kernel_sum(p, &self.weights)
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.apply_with_jacobian(p).1
    }

    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        let sys = &*self.system;
        let inv = 1.0 / sys.support;
        let mut d = DVec3::ZERO;
        let mut j = self.affine;
        sys.grid.for_each_near(p, |i| {
            let r = p - sys.sources[i];
            let s = r.length() * inv;
            if s < 1.0 {
                let w = self.weights[i];
                d += w * wendland_c2(s);
                let t = 1.0 - s;
                // ∇φ(‖r‖/ρ) = −20 (1 − s)³ r / ρ².
                let g = r * (-20.0 * t * t * t * inv * inv);
                j += outer(w, g);
            }
        });
        (self.affine * p + self.translation + d, j)
    }

    fn apply_batch(&self, points: &[DVec3], out: &mut [DVec3]) -> Result<(), DeformError> {
        volmorph_deform::map::check_len(points.len(), out.len())?;
        out.par_chunks_mut(1024)
            .zip(points.par_chunks(1024))
            .for_each(|(o, p)| {
                for (o, &p) in o.iter_mut().zip(p) {
                    *o = self.apply(p);
                }
            });
        Ok(())
    }
}

/// Parameters: the targets, in handle order (see the [module docs](self#live-edits)).
impl LinearMap for WendlandMap {
    fn parameter_count(&self) -> usize {
        self.targets.len()
    }

    fn parameters(&self) -> Vec<DVec3> {
        self.targets.clone()
    }

    fn set_parameters(&mut self, values: &[DVec3]) -> Result<(), DeformError> {
        self.set_targets(values)
    }

    fn coefficients_into(&self, v: DVec3, out: &mut [f64]) -> DVec3 {
        // c(v)ᵀ = a(v)ᵀ + yᵀ (I − a(P)) with y = (K + λI)⁻¹ φ(v); b(v) = b₀(v) − Σ y_i b₀(p_i).
        let sys = &*self.system;
        let n = sys.sources.len();
        let inv = 1.0 / sys.support;
        let mut phi = Mat::<f64>::zeros(n, 1);
        sys.grid.for_each_near(v, |i| {
            let s = (v - sys.sources[i]).length() * inv;
            if s < 1.0 {
                phi[(i, 0)] = wendland_c2(s);
            }
        });
        sys.solve(&mut phi);
        let y: Vec<f64> = (0..n).map(|i| phi[(i, 0)]).collect();
        let sum_y: f64 = y.iter().sum();
        let mut lever_y = DVec3::ZERO;
        let mut base = sys.trend.base(v);
        for (&yi, &p) in y.iter().zip(&sys.sources) {
            lever_y += yi * sys.trend.lever(p);
            base -= yi * sys.trend.base(p);
        }
        let m = out.len().min(n);
        let mut a = vec![0.0; n];
        self.trend_coefficients(sys.trend.lever(v), &mut a);
        let mean = sys.trend.mean();
        let inv_n = 1.0 / n as f64;
        for k in 0..m {
            // Σ_i y_i a_k(p_i) = Σy / N + (p_k − p̄) · Σ_i y_i M (p_i − p̄).
            let ya = sum_y * inv_n + (sys.sources[k] - mean).dot(lever_y);
            out[k] = a[k] + y[k] - ya;
        }
        base
    }

    fn coefficient_column(
        &self,
        k: usize,
        points: &[DVec3],
        out: &mut [f64],
    ) -> Result<(), DeformError> {
        let sys = &*self.system;
        let n = sys.sources.len();
        check_parameter(k, n)?;
        volmorph_deform::map::check_len(points.len(), out.len())?;
        // z = (K + λI)⁻¹ (e_k − a_k(P)); c_k(x) = a_k(x) + Σ_i φ_i(x) z_i.
        let mean = sys.trend.mean();
        let inv_n = 1.0 / n as f64;
        let dk = sys.sources[k] - mean;
        let mut rhs = Mat::<f64>::zeros(n, 1);
        for (i, &p) in sys.sources.iter().enumerate() {
            rhs[(i, 0)] = f64::from(u8::from(i == k)) - (inv_n + dk.dot(sys.trend.lever(p)));
        }
        sys.solve(&mut rhs);
        let z: Vec<f64> = (0..n).map(|i| rhs[(i, 0)]).collect();
        out.par_chunks_mut(1024)
            .zip(points.par_chunks(1024))
            .for_each(|(o, p)| {
                for (o, &x) in o.iter_mut().zip(p) {
                    *o = inv_n + dk.dot(sys.trend.lever(x)) + sys.kernel_sum(x, &z);
                }
            });
        Ok(())
    }

    fn same_structure(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.system, &other.system)
            || (self.system.sources == other.system.sources
                && self.system.support == other.system.support
                && self.system.smoothing == other.system.smoothing)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_is_c2_with_compact_support() {
        assert_eq!(wendland_c2(0.0), 1.0);
        assert_eq!(wendland_c2(1.0), 0.0);
        assert_eq!(wendland_c2(1.5), 0.0);
        // φ'(s) = −20 s (1 − s)³, so φ'(0) = 0 and φ'(1) = 0: check by differences.
        let h = 1e-6;
        for s in [0.1, 0.37, 0.8] {
            let fd = (wendland_c2(s + h) - wendland_c2(s - h)) / (2.0 * h);
            let exact = -20.0 * s * (1.0 - s).powi(3);
            assert!((fd - exact).abs() < 1e-6, "{s}: {fd} vs {exact}");
        }
    }

    #[test]
    fn affine_fit_recovers_affine_and_falls_back_for_flat_sets() {
        let a = DMat3::from_cols(
            DVec3::new(1.1, 0.2, 0.0),
            DVec3::new(-0.1, 0.9, 0.3),
            DVec3::new(0.0, 0.1, 1.2),
        );
        let b = DVec3::new(3.0, -1.0, 2.0);
        let src: Vec<DVec3> = (0..20)
            .map(|i| {
                let t = i as f64;
                DVec3::new((t * 0.7).sin() * 5.0, (t * 1.3).cos() * 4.0, t * 0.3)
            })
            .collect();
        let dst: Vec<DVec3> = src.iter().map(|&p| a * p + b).collect();
        let (fa, fb) = affine_fit(&Trend::of(&src), &src, &dst);
        assert!((fa - a).abs_diff_eq(DMat3::ZERO, 1e-9) && fb.abs_diff_eq(b, 1e-9));
        let flat: Vec<DVec3> = src.iter().map(|p| DVec3::new(p.x, p.y, 0.0)).collect();
        let moved: Vec<DVec3> = flat.iter().map(|&p| p + b).collect();
        let (fa, fb) = affine_fit(&Trend::of(&flat), &flat, &moved);
        assert_eq!(fa, DMat3::IDENTITY);
        assert!(fb.abs_diff_eq(b, 1e-12));
    }
}
