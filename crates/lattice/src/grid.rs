//! Dense evaluation of lattice maps on voxel grids (True 1992 §5.2).
//!
//! Both fast paths need the grid's index axes to be parallel to the lattice's parameter axes
//! (same order, either sign), so that parameter `u` depends on index `i` only, `v` on `j` and
//! `w` on `k`. The parameter of every grid index is then tabulated once per axis:
//!
//! * **separable path** ([`BSplineLattice::apply_grid_separable`], any grid spacing): one
//!   [`BasisTable`] per axis. For each row `(j, k)` the `(p_v+1)(p_w+1)` control-point layers
//!   are blended once into a row of partial sums along u, and each voxel of the row then needs
//!   only `p_u + 1` terms.
//! * **coefficient-table path** ([`BSplineLattice::apply_grid_table`], True's scheme): when
//!   the lattice cell is an integer number `G` of voxels along each axis, the basis values
//!   repeat with period `G`, so the `(p_u+1)(p_v+1)(p_w+1)` weight products (64 for cubic
//!   lattices, True's Eq. 4) are precomputed for every combination of fractional positions —
//!   a table of `G_u·G_v·G_w` blocks of 64 contiguous weights — and each voxel is the 64-term
//!   sum of Eq. 5.
//!
//! Both run in parallel over z-slabs and allocate nothing per voxel; voxels outside the
//! lattice box are mapped to themselves, exactly as [`SpaceMap::apply`](volmorph_deform::SpaceMap::apply) does. Results agree
//! with pointwise `apply` to rounding (≈1e-13 relative).

use glam::DVec3;
use rayon::prelude::*;
use volmorph_spline::{BasisTable, KnotVector};
use volmorph_volume::{Geometry, IndexBox};

use crate::{BSplineLattice, LatticeFrame};
use volmorph_deform::DeformError;
use volmorph_deform::map::check_grid;

mod adjoint;
pub use adjoint::PointBasis;
#[cfg(target_arch = "x86_64")]
mod row_x4;

/// Largest off-diagonal drift allowed for a grid to count as aligned with a lattice: over the
/// whole grid, ignoring the cross terms may move a parameter by at most this many lattice
/// cells (far below the 1e-12 relative agreement the fast paths promise).
pub const ALIGNMENT_TOL: f64 = 1e-13;

/// Basis values at positions `i` and `i + G` count as the same table entry when they differ by
/// at most this much (they are equal in exact arithmetic for uniform knots; rounding in the
/// parameters leaves a few ulps).
pub const TABLE_WEIGHT_TOL: f64 = 1e-13;

/// Relative tolerance for the voxels-per-cell ratio `G` to count as an integer.
pub const GRANULARITY_TOL: f64 = 1e-9;

/// Largest coefficient table [`BSplineLattice::apply_grid_table`] builds, in bytes (256 MiB).
pub const MAX_TABLE_BYTES: usize = 256 << 20;

/// Per-axis parameter of grid index 0 and parameter step per grid index.
type AxisSteps = ([f64; 3], [f64; 3]);

/// Parameters of the grid indices along each axis, `u_a(i) = start_a + step_a·i`, if the grid
/// is aligned with the lattice; `None` otherwise. Validates the grid.
pub(crate) fn aligned_steps(
    lat: &BSplineLattice,
    grid: &Geometry,
) -> Result<Option<AxisSteps>, DeformError> {
    grid.validate()?;
    let m = lat.frame().to_parameter_matrix() * grid.index_to_physical_matrix();
    let start = lat.frame().to_parameter(grid.origin);
    let mut steps = [0.0; 3];
    for (a, step) in steps.iter_mut().enumerate() {
        // Row a of m: how u_a changes per index step along each grid axis.
        for b in 0..3 {
            let v = m.col(b)[a];
            if a == b {
                *step = v;
            } else if v.abs() * (grid.dims[b].saturating_sub(1) as f64) > ALIGNMENT_TOL {
                return Ok(None);
            }
        }
        if *step == 0.0 || !step.is_finite() {
            return Ok(None);
        }
    }
    Ok(Some((start.to_array(), steps)))
}

/// One grid axis against one lattice axis: the contiguous range of indices inside the knot
/// domain and their basis values (from a [`BasisTable`]).
#[derive(Debug, Clone)]
struct AxisPlan {
    lo: usize,
    hi: usize,
    /// Basis functions per index (the degree plus one).
    order: usize,
    /// First control index of each in-domain grid index `lo + r` (entry `r`).
    firsts: Vec<usize>,
    /// The basis values of grid index `lo + r` at entries `r·order .. (r+1)·order`.
    values: Vec<f64>,
}

/// Axis plans kept per thread by [`AxisPlan::cached`].
const AXIS_PLAN_CACHE: usize = 8;

/// An [`AxisPlan`] and everything it was computed from.
struct AxisPlanEntry {
    knots: KnotVector,
    range: std::ops::Range<usize>,
    start: u64,
    step: u64,
    plan: AxisPlan,
}

thread_local! {
    /// The axis plans this thread built last, most recent first (see [`AxisPlan::cached`]).
    static AXIS_PLANS: std::cell::RefCell<Vec<AxisPlanEntry>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

impl AxisPlan {
    /// The plan of the grid indices `range` only (indices stay those of the whole grid, and
    /// each index's parameter and basis values are the whole grid's bits).
    fn over(
        kv: &KnotVector,
        range: std::ops::Range<usize>,
        start: f64,
        step: f64,
    ) -> Result<Self, DeformError> {
        let param = |i: usize| start + step * i as f64;
        let order = kv.degree() + 1;
        let inside: Vec<usize> = range.filter(|&i| kv.contains(param(i))).collect();
        let (Some(&lo), Some(&last)) = (inside.first(), inside.last()) else {
            return Ok(Self {
                lo: 0,
                hi: 0,
                order,
                firsts: Vec::new(),
                values: Vec::new(),
            });
        };
        let params: Vec<f64> = (lo..=last).map(param).collect();
        let table = BasisTable::new(kv, &params, false)?;
        let firsts = (0..params.len()).filter_map(|r| table.first(r)).collect();
        let values = (0..params.len())
            .filter_map(|r| table.values(r))
            .flatten()
            .copied()
            .collect();
        Ok(Self {
            lo,
            hi: last + 1,
            order,
            firsts,
            values,
        })
    }

    /// [`AxisPlan::over`], remembered per thread: the plan depends only on the knots, the
    /// index range and the bits of `start` and `step`, so a plan built before from equal
    /// inputs is the same plan. The push-forward's fixed tiles
    /// (`volmorph_warp::centres`, through [`LatticeGridPlan::part`]) and the pull-back's
    /// tiles (`volmorph_warp::pullback`, through [`LatticeGridPlan::new`]) ask for the same
    /// few axes tile after tile and band after band; the last [`AXIS_PLAN_CACHE`] plans are
    /// kept.
    fn cached(
        kv: &KnotVector,
        range: std::ops::Range<usize>,
        start: f64,
        step: f64,
    ) -> Result<Self, DeformError> {
        let (sb, tb) = (start.to_bits(), step.to_bits());
        let hit = AXIS_PLANS.with_borrow_mut(|plans| {
            let n = plans.iter().position(|e| {
                e.start == sb && e.step == tb && e.range == range && same_bits(&e.knots, kv)
            })?;
            let e = plans.remove(n);
            let plan = e.plan.clone();
            plans.insert(0, e);
            Some(plan)
        });
        if let Some(plan) = hit {
            return Ok(plan);
        }
        let plan = Self::over(kv, range.clone(), start, step)?;
        AXIS_PLANS.with_borrow_mut(|plans| {
            plans.truncate(AXIS_PLAN_CACHE - 1);
            plans.insert(
                0,
                AxisPlanEntry {
                    knots: kv.clone(),
                    range,
                    start: sb,
                    step: tb,
                    plan: plan.clone(),
                },
            );
        });
        Ok(plan)
    }

    /// First control index and basis values of grid index `i`, if inside the domain.
    #[inline]
    fn at(&self, i: usize) -> Option<(usize, &[f64])> {
        if i < self.lo || i >= self.hi {
            return None;
        }
        let r = i - self.lo;
        Some((
            *self.firsts.get(r)?,
            self.values.get(r * self.order..(r + 1) * self.order)?,
        ))
    }
}

/// `true` if two knot vectors have the same degree and bit-identical knots (`==` on floats
/// would equate −0 and +0).
fn same_bits(a: &KnotVector, b: &KnotVector) -> bool {
    a.degree() == b.degree()
        && a.knots().len() == b.knots().len()
        && a.knots()
            .iter()
            .zip(b.knots())
            .all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Which loop evaluates the voxels of a row on the separable path: the cubic row loop in
/// vector registers where the CPU allows it (`Vector`, see `row_x4`), or the portable loop
/// (`Portable`, what other degrees and CPUs run). Both give the same bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RowLoop {
    /// The vector loop when it applies, the portable loop otherwise.
    Vector,
    /// The portable loop only.
    #[cfg_attr(
        not(test),
        allow(dead_code, reason = "the tests force the portable loop")
    )]
    Portable,
}

/// Which dense evaluation scheme a [`LatticeGridPlan`] uses (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GridPath {
    /// Per-axis basis tables and row partial sums; any spacing ratio.
    Separable,
    /// True's precomputed coefficient table of weight products (§5.2, Eq. 4); integer
    /// voxels-per-cell ratios only.
    Table,
}

/// True's coefficient table: one block of `(p_u+1)(p_v+1)(p_w+1)` weight products per
/// combination of per-axis classes, the u index fastest inside a block.
#[derive(Debug, Clone)]
struct CoefTable {
    classes: [Vec<u32>; 3],
    sizes: [usize; 3],
    weights: Vec<f64>,
}

/// Precomputed evaluation of lattices with given knots and frame on one voxel grid.
///
/// Everything that depends only on the parameters of the voxel centres — per-axis basis
/// tables and, for [`GridPath::Table`], True's coefficient table — is computed once; as True
/// observes (§5.2), these do not change when control points move, so one plan serves every
/// edit of a lattice: build it once, then call [`LatticeGridPlan::apply`] after each change.
///
/// ```
/// use glam::DVec3;
/// use volmorph_deform::SpaceMap;
/// use volmorph_lattice::{BSplineLattice, grid::{GridPath, LatticeGridPlan}};
/// use volmorph_volume::Geometry;
/// // True's setting: 9 control points, 6 regions of G = 10 voxels per axis.
/// let mut lat = BSplineLattice::uniform_cubic_around(
///     DVec3::splat(-0.5), DVec3::splat(59.5), [9, 9, 9]).unwrap();
/// let grid = Geometry::new([60, 60, 60]);
/// let plan = LatticeGridPlan::new(&lat, &grid, GridPath::Table).unwrap();
/// let mut out = vec![DVec3::ZERO; grid.len()];
/// plan.apply(&lat, &mut out).unwrap(); // identity lattice: voxel centres stay put
/// assert!((out[grid.offset(7, 30, 59)] - DVec3::new(7.0, 30.0, 59.0)).length() < 1e-12);
/// lat.move_control_point([4, 4, 4], DVec3::new(3.0, 0.0, 0.0)).unwrap();
/// plan.apply(&lat, &mut out).unwrap(); // same plan after the edit
/// let p = DVec3::new(29.0, 29.0, 29.0);
/// assert!((out[grid.offset(29, 29, 29)] - lat.apply(p)).length() < 1e-12);
/// ```
#[derive(Debug, Clone)]
pub struct LatticeGridPlan {
    grid: Geometry,
    /// The part of `grid` evaluated (the whole grid unless built by
    /// [`LatticeGridPlan::part`]).
    part: IndexBox,
    frame: LatticeFrame,
    knots: [KnotVector; 3],
    path: GridPath,
    axes: [AxisPlan; 3],
    orders: [usize; 3],
    table: Option<CoefTable>,
}

impl LatticeGridPlan {
    /// Precompute the evaluation of lattices with `lattice`'s knots and frame on `grid` by
    /// `path`.
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid geometry, [`DeformError::GridNotAligned`] if the
    /// grid's index axes are not parallel to the lattice's parameter axes (either sign),
    /// and for [`GridPath::Table`] [`DeformError::TableUnavailable`] if a lattice cell is not
    /// an integer number of voxels, knot spans differ in length, or the table would exceed
    /// [`MAX_TABLE_BYTES`].
    pub fn new(
        lattice: &BSplineLattice,
        grid: &Geometry,
        path: GridPath,
    ) -> Result<Self, DeformError> {
        grid.validate()?;
        let (start, step) = aligned_steps(lattice, grid)?.ok_or_else(|| {
            DeformError::GridNotAligned(
                "grid index axes are not parallel to the lattice's parameter axes".into(),
            )
        })?;
        let k = lattice.knots();
        let axes = [
            AxisPlan::cached(&k[0], 0..grid.dims[0], start[0], step[0])?,
            AxisPlan::cached(&k[1], 0..grid.dims[1], start[1], step[1])?,
            AxisPlan::cached(&k[2], 0..grid.dims[2], start[2], step[2])?,
        ];
        let deg = lattice.degree();
        let orders = [deg[0] + 1, deg[1] + 1, deg[2] + 1];
        let table = match path {
            GridPath::Separable => None,
            GridPath::Table => Some(coefficient_table(k, &axes, step, orders)?),
        };
        Ok(Self {
            grid: *grid,
            part: IndexBox {
                start: [0; 3],
                end: grid.dims,
            },
            frame: *lattice.frame(),
            knots: k.clone(),
            path,
            axes,
            orders,
            table,
        })
    }

    /// A separable plan for the box `part` of `grid` only: [`LatticeGridPlan::apply`] then
    /// fills `part.len()` points (x fastest) with the bits the whole grid's plan gives them
    /// (every index keeps its parameter `start + step·i` of the whole grid, and the row sums
    /// are per control column, whatever columns a row needs).
    ///
    /// # Errors
    /// As [`LatticeGridPlan::new`] with [`GridPath::Separable`]; [`DeformError::BufferLength`]
    /// if `part` leaves the grid.
    pub fn part(
        lattice: &BSplineLattice,
        grid: &Geometry,
        part: IndexBox,
    ) -> Result<Self, DeformError> {
        grid.validate()?;
        if (0..3).any(|a| part.end[a] > grid.dims[a]) {
            return Err(DeformError::BufferLength {
                expected: grid.len(),
                got: part.len(),
            });
        }
        let (start, step) = aligned_steps(lattice, grid)?.ok_or_else(|| {
            DeformError::GridNotAligned(
                "grid index axes are not parallel to the lattice's parameter axes".into(),
            )
        })?;
        let k = lattice.knots();
        let range = |a: usize| part.start[a].min(part.end[a])..part.end[a];
        let axes = [
            AxisPlan::cached(&k[0], range(0), start[0], step[0])?,
            AxisPlan::cached(&k[1], range(1), start[1], step[1])?,
            AxisPlan::cached(&k[2], range(2), start[2], step[2])?,
        ];
        let deg = lattice.degree();
        Ok(Self {
            grid: *grid,
            part,
            frame: *lattice.frame(),
            knots: k.clone(),
            path: GridPath::Separable,
            axes,
            orders: [deg[0] + 1, deg[1] + 1, deg[2] + 1],
            table: None,
        })
    }

    /// The grid the plan evaluates on.
    #[must_use]
    pub fn grid(&self) -> &Geometry {
        &self.grid
    }

    /// The evaluation scheme.
    #[must_use]
    pub fn path(&self) -> GridPath {
        self.path
    }

    /// Evaluate `lattice` at every voxel centre of the plan's grid (or of its part, for a
    /// plan built by [`LatticeGridPlan::part`]) into `out` (x fastest); voxels outside the
    /// lattice box are mapped to themselves. Parallel over z-slabs, no
    /// allocation per voxel; agrees with pointwise [`SpaceMap::apply`](volmorph_deform::SpaceMap::apply)
    /// to rounding.
    ///
    /// # Errors
    /// [`DeformError::GridNotAligned`] if `lattice` has other knots or another frame than the
    /// lattice the plan was built for (its control points may differ freely),
    /// [`DeformError::BufferLength`] if `out.len()` is not the grid's (or the part's) voxel
    /// count.
    pub fn apply(&self, lattice: &BSplineLattice, out: &mut [DVec3]) -> Result<(), DeformError> {
        if lattice.knots() != &self.knots || lattice.frame() != &self.frame {
            return Err(DeformError::GridNotAligned(
                "the lattice's knots or frame differ from those the plan was built for".into(),
            ));
        }
        self.grid.validate()?;
        volmorph_deform::map::check_len(self.part.len(), out.len())?;
        if out.is_empty() {
            return Ok(());
        }
        let points = lattice.control_points();
        match &self.table {
            None => self.apply_separable(&points, lattice.counts(), out, RowLoop::Vector),
            Some(t) => self.apply_table(t, &points, lattice.counts(), out),
        }
        Ok(())
    }

    fn apply_separable(
        &self,
        pts: &[DVec3],
        counts: [usize; 3],
        out: &mut [DVec3],
        row_loop: RowLoop,
    ) {
        let grid = &self.grid;
        let IndexBox {
            start: [x0, y0, z0],
            end: [x1, y1, _],
        } = self.part;
        let (nx, ny) = (x1 - x0, y1 - y0);
        let [cx, cy, _] = counts;
        let [wx, wy, wz] = self.orders;
        // Control columns along u that any in-domain voxel touches. (First indices decrease
        // along i when the grid axis runs against the lattice axis.)
        let ax = &self.axes[0];
        let (c_lo, c_hi) = match (ax.at(ax.lo), ax.hi.checked_sub(1).and_then(|l| ax.at(l))) {
            (Some((f0, _)), Some((f1, _))) => (f0.min(f1), (f0.max(f1) + wx).min(cx)),
            _ => (0, 0),
        };
        // The cubic row in vector registers where the CPU allows it (same bits).
        #[cfg(target_arch = "x86_64")]
        let vector = wx == 4 && row_loop == RowLoop::Vector && row_x4::available();
        #[cfg(target_arch = "x86_64")]
        let padded = if vector {
            row_x4::padded(pts)
        } else {
            Vec::new()
        };
        #[cfg(not(target_arch = "x86_64"))]
        let _ = row_loop;
        let columns = c_hi - c_lo;
        out.par_chunks_mut(nx * ny).enumerate().for_each_init(
            || {
                (
                    vec![DVec3::ZERO; columns],
                    Vec::<[f64; 4]>::new(),
                    Vec::<(f64, usize)>::with_capacity(wy * wz),
                )
            },
            |(row_sum, _sums, layers), (dk, slab)| {
                let k = z0 + dk;
                let zk = self.axes[2].at(k);
                for (dj, row) in slab.chunks_exact_mut(nx).enumerate() {
                    let j = y0 + dj;
                    let (Some((fz, bz)), Some((fy, by))) = (zk, self.axes[1].at(j)) else {
                        for (di, o) in row.iter_mut().enumerate() {
                            *o = centre(grid, x0 + di, j, k);
                        }
                        continue;
                    };
                    // Outside the knot domain along u: the identity. (The axis plan holds
                    // indices of the part only, so its range lies in `x0 .. x1`.)
                    let (lo, hi) = (ax.lo.clamp(x0, x1) - x0, ax.hi.clamp(x0, x1) - x0);
                    let hi = hi.max(lo);
                    let (before, rest) = row.split_at_mut(lo);
                    let (inside, after) = rest.split_at_mut(hi - lo);
                    for (di, o) in before.iter_mut().enumerate() {
                        *o = centre(grid, x0 + di, j, k);
                    }
                    for (di, o) in after.iter_mut().enumerate() {
                        *o = centre(grid, x0 + hi + di, j, k);
                    }
                    // The (wy × wz) control layers of this row: weight and first column.
                    layers.clear();
                    for (c, &nz) in bz.iter().enumerate().take(wz) {
                        for (b, &ny_) in by.iter().enumerate().take(wy) {
                            layers.push((nz * ny_, ((fz + c) * cy + fy + b) * cx + c_lo));
                        }
                    }
                    #[cfg(target_arch = "x86_64")]
                    if vector {
                        let (firsts, values) = (&ax.firsts, &ax.values);
                        row_x4::cubic_row(
                            &padded, layers, columns, _sums, firsts, c_lo, values, inside,
                        );
                        continue;
                    }
                    // Blend the layers once into a row of partial sums along u.
                    row_sum.fill(DVec3::ZERO);
                    for &(wgt, start) in layers.iter() {
                        for (s, &p) in row_sum.iter_mut().zip(&pts[start..start + columns]) {
                            *s += wgt * p;
                        }
                    }
                    let firsts = ax.firsts.iter().map(|&f| f - c_lo);
                    if wx == 4 {
                        // Cubic: the general loop below unrolled (same sums, same order).
                        for ((o, f), b) in
                            inside.iter_mut().zip(firsts).zip(ax.values.chunks_exact(4))
                        {
                            if let Some(p) = row_sum.get(f..f + 4) {
                                *o = DVec3::ZERO
                                    + b[0] * p[0]
                                    + b[1] * p[1]
                                    + b[2] * p[2]
                                    + b[3] * p[3];
                            }
                        }
                    } else {
                        for ((o, f), b) in inside
                            .iter_mut()
                            .zip(firsts)
                            .zip(ax.values.chunks_exact(wx))
                        {
                            let mut acc = DVec3::ZERO;
                            for (&n, &p) in b.iter().zip(row_sum.get(f..f + wx).unwrap_or(&[])) {
                                acc += n * p;
                            }
                            *o = acc;
                        }
                    }
                }
            },
        );
    }

    fn apply_table(&self, t: &CoefTable, pts: &[DVec3], counts: [usize; 3], out: &mut [DVec3]) {
        let grid = &self.grid;
        let [nx, ny, _] = grid.dims;
        let [cx, cy, _] = counts;
        let [wx, wy, wz] = self.orders;
        let block = wx * wy * wz;
        let [gx, gy, _] = t.sizes;
        out.par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(k, slab)| {
                let zk = self.axes[2].at(k).map(|v| v.0);
                for (j, row) in slab.chunks_exact_mut(nx).enumerate() {
                    let (Some(fz), Some((fy, _))) = (zk, self.axes[1].at(j)) else {
                        for (i, o) in row.iter_mut().enumerate() {
                            *o = centre(grid, i, j, k);
                        }
                        continue;
                    };
                    let ez = t.classes[2][k - self.axes[2].lo] as usize;
                    let ey = t.classes[1][j - self.axes[1].lo] as usize;
                    let row_block = (ez * gy + ey) * gx;
                    for (i, o) in row.iter_mut().enumerate() {
                        let Some((fx, _)) = self.axes[0].at(i) else {
                            *o = centre(grid, i, j, k);
                            continue;
                        };
                        let ex = t.classes[0][i - self.axes[0].lo] as usize;
                        let start = (row_block + ex) * block;
                        let w = &t.weights[start..start + block];
                        // True's Eq. 5: a sum of `block` (64) terms.
                        let mut acc = DVec3::ZERO;
                        for c in 0..wz {
                            for b in 0..wy {
                                let base = ((fz + c) * cy + fy + b) * cx + fx;
                                let ws = &w[(c * wy + b) * wx..(c * wy + b + 1) * wx];
                                for (&wt, &p) in ws.iter().zip(&pts[base..base + wx]) {
                                    acc += wt * p;
                                }
                            }
                        }
                        *o = acc;
                    }
                }
            });
    }
}

/// Build True's coefficient table (Eq. 4) for the per-axis plans.
fn coefficient_table(
    knots: &[KnotVector; 3],
    axes: &[AxisPlan; 3],
    step: [f64; 3],
    orders: [usize; 3],
) -> Result<CoefTable, DeformError> {
    let mut classes: [Vec<u32>; 3] = Default::default();
    let mut reps: [Vec<usize>; 3] = Default::default();
    for a in 0..3 {
        let g = granularity(&knots[a], step[a]).ok_or_else(|| {
            DeformError::TableUnavailable(format!(
                "axis {a}: a lattice cell is not an integer number of voxels, or knot spans \
                 differ in length"
            ))
        })?;
        (classes[a], reps[a]) = residue_classes(&axes[a], g, step[a] < 0.0);
    }
    let [wx, wy, wz] = orders;
    let block = wx * wy * wz;
    let sizes = [reps[0].len(), reps[1].len(), reps[2].len()];
    let [gx, gy, gz] = sizes;
    let len = [gx, gy, gz, block, 8]
        .iter()
        .try_fold(1usize, |acc, &v| acc.checked_mul(v))
        .filter(|&b| b <= MAX_TABLE_BYTES)
        .ok_or_else(|| {
            DeformError::TableUnavailable(format!(
                "a {gx}×{gy}×{gz}×{block} coefficient table exceeds {MAX_TABLE_BYTES} bytes"
            ))
        })?
        / 8;
    // c[ḡ][f̄][ē][k][j][i]: True's Eq. 4 with the u index fastest.
    let mut weights = vec![0.0; len];
    if block > 0 {
        weights
            .par_chunks_mut(block)
            .enumerate()
            .for_each(|(e, blk)| {
                let (ex, ey, ez) = (e % gx, (e / gx) % gy, e / (gx * gy));
                let bx = axes[0].at(reps[0][ex]).map(|t| t.1);
                let by = axes[1].at(reps[1][ey]).map(|t| t.1);
                let bz = axes[2].at(reps[2][ez]).map(|t| t.1);
                if let (Some(bx), Some(by), Some(bz)) = (bx, by, bz) {
                    for (c, &nz) in bz.iter().enumerate() {
                        for (b, &ny_) in by.iter().enumerate() {
                            for (a, &nx_) in bx.iter().enumerate() {
                                blk[(c * wy + b) * wx + a] = nx_ * ny_ * nz;
                            }
                        }
                    }
                }
            });
    }
    Ok(CoefTable {
        classes,
        sizes,
        weights,
    })
}

/// Voxel centre `(i, j, k)`, computed exactly as the pointwise path does.
#[inline]
fn centre(grid: &Geometry, i: usize, j: usize, k: usize) -> DVec3 {
    grid.index_to_physical(DVec3::new(i as f64, j as f64, k as f64))
}

impl BSplineLattice {
    /// Evaluate the map at every voxel centre of `grid` (x fastest) with separable per-axis
    /// basis tables (see the [module docs](self)); works for any spacing ratio. Agrees with
    /// pointwise [`SpaceMap::apply`](volmorph_deform::SpaceMap::apply) to rounding. Builds a
    /// [`LatticeGridPlan`] each call; keep one to evaluate repeatedly.
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid geometry, [`DeformError::BufferLength`] for a
    /// wrong `out` length, [`DeformError::GridNotAligned`] if the grid axes are not parallel to
    /// the lattice axes (use [`SpaceMap::apply_grid`](volmorph_deform::SpaceMap::apply_grid), which
    /// falls back to pointwise evaluation).
    pub fn apply_grid_separable(
        &self,
        grid: &Geometry,
        out: &mut [DVec3],
    ) -> Result<(), DeformError> {
        check_grid(grid, out)?;
        LatticeGridPlan::new(self, grid, GridPath::Separable)?.apply(self, out)
    }

    /// Evaluate the map at every voxel centre of `grid` (x fastest) with True's precomputed
    /// coefficient table (§5.2, Eqs. 4–5): requires the lattice cell to span an integer number
    /// `G_a` of voxels along each axis (knot spans of equal length), so that the basis values
    /// repeat with period `G_a`; each voxel is then a sum of `(p_u+1)(p_v+1)(p_w+1)` (64 for
    /// cubic lattices) contiguous table weights times control points. Agrees with pointwise
    /// [`SpaceMap::apply`](volmorph_deform::SpaceMap::apply) to rounding. Builds a [`LatticeGridPlan`]
    /// each call; keep one to evaluate repeatedly.
    ///
    /// # Errors
    /// As [`BSplineLattice::apply_grid_separable`], plus [`DeformError::TableUnavailable`] if a
    /// ratio is not an integer, the knot spans differ in length, or the table would exceed
    /// [`MAX_TABLE_BYTES`].
    pub fn apply_grid_table(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        check_grid(grid, out)?;
        LatticeGridPlan::new(self, grid, GridPath::Table)?.apply(self, out)
    }
}

/// The integer number `G` of grid steps per knot span, if every span in the domain has the
/// same length and that length is an integer multiple of `|step|`.
fn granularity(kv: &KnotVector, step: f64) -> Option<usize> {
    let spans: Vec<f64> = kv.spans().map(|s| s.end - s.start).collect();
    let h = *spans.first()?;
    if spans.iter().any(|&l| (l - h).abs() > GRANULARITY_TOL * h) {
        return None;
    }
    let g = h / step.abs();
    let r = g.round();
    ((g - r).abs() <= GRANULARITY_TOL * g && r >= 1.0 && r <= u32::MAX as f64).then_some(r as usize)
}

/// Group the in-domain indices of an axis into classes with identical basis values: index `i`
/// joins the class of `i − G` when it is one span further (one span back when the grid axis
/// runs against the lattice axis, `descending`) with the same values (to
/// [`TABLE_WEIGHT_TOL`]). Returns the class of every in-domain index (relative to `lo`) and
/// one representative grid index per class.
fn residue_classes(axis: &AxisPlan, g: usize, descending: bool) -> (Vec<u32>, Vec<usize>) {
    let mut class = Vec::with_capacity(axis.hi - axis.lo);
    let mut reps: Vec<usize> = Vec::new();
    for i in axis.lo..axis.hi {
        let r = i - axis.lo;
        let same = (r >= g)
            .then(|| (axis.at(i), axis.at(i - g)))
            .and_then(|(now, before)| {
                let ((f1, v1), (f0, v0)) = (now?, before?);
                let next = if descending {
                    f1 + 1 == f0
                } else {
                    f1 == f0 + 1
                };
                (next
                    && v1
                        .iter()
                        .zip(v0)
                        .all(|(x, y)| (x - y).abs() <= TABLE_WEIGHT_TOL))
                .then_some(class[r - g])
            });
        match same {
            Some(c) => class.push(c),
            None => {
                class.push(reps.len() as u32);
                reps.push(i);
            }
        }
    }
    (class, reps)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cubic lattice around `lo .. hi` with `counts` control points, each set to
    /// `point([i, j, k])`.
    fn lattice_with(
        lo: DVec3,
        hi: DVec3,
        counts: [usize; 3],
        mut point: impl FnMut([usize; 3]) -> DVec3,
    ) -> BSplineLattice {
        let mut lat = BSplineLattice::uniform_cubic_around(lo, hi, counts).unwrap();
        for k in 0..counts[2] {
            for j in 0..counts[1] {
                for i in 0..counts[0] {
                    lat.set_control_point([i, j, k], point([i, j, k])).unwrap();
                }
            }
        }
        lat
    }

    /// `plan` on `lat` by the vector and by the portable row loop, and the result of
    /// [`LatticeGridPlan::apply`].
    fn both_loops(plan: &LatticeGridPlan, lat: &BSplineLattice) -> [Vec<DVec3>; 3] {
        let (pts, counts) = (lat.control_points(), lat.counts());
        let mut out = [0; 3].map(|_| vec![DVec3::NAN; plan.part.len()]);
        let [vector, portable, applied] = &mut out;
        plan.apply_separable(&pts, counts, vector, RowLoop::Vector);
        plan.apply_separable(&pts, counts, portable, RowLoop::Portable);
        plan.apply(lat, applied).unwrap();
        out
    }

    /// The vector row loop gives the portable loop's bits: cubic lattices (moved at random,
    /// some control points far away) on grids running with and against the lattice axes,
    /// reaching beyond the lattice box, for whole grids and parts.
    #[test]
    fn vector_row_loop_matches_the_portable_loop() {
        let mut rng = volmorph_testkit::Rng::new(0x70_11);
        for (n, grid) in [
            Geometry::new([37, 11, 9])
                .with_spacing(DVec3::new(0.3, 0.9, 1.7))
                .with_origin(DVec3::new(-2.0, 1.0, 0.5)),
            Geometry::new([70, 6, 5])
                .with_direction(glam::DMat3::from_diagonal(DVec3::new(-1.0, 1.0, -1.0))),
        ]
        .into_iter()
        .enumerate()
        {
            let (lo, hi) = (DVec3::new(-3.0, -2.0, -4.0), DVec3::new(9.0, 8.0, 7.0));
            let id = BSplineLattice::uniform_cubic_around(lo, hi, [7, 6, 5]).unwrap();
            let lat = lattice_with(lo, hi, [7, 6, 5], |[i, j, k]| {
                let far = if (i + j + k + n) % 11 == 0 { 1e6 } else { 1.0 };
                id.control_point([i, j, k]).unwrap() + rng.point(far)
            });
            let [nx, ny, nz] = grid.dims;
            let parts = [
                IndexBox {
                    start: [0; 3],
                    end: grid.dims,
                },
                IndexBox {
                    start: [3, 1, 2],
                    end: [nx - 5, ny, nz - 1],
                },
            ];
            for part in parts {
                let plan = LatticeGridPlan::part(&lat, &grid, part).unwrap();
                let [vector, portable, applied] = both_loops(&plan, &lat);
                for (v, p) in vector.iter().zip(&portable) {
                    assert_eq!(
                        v.to_array().map(f64::to_bits),
                        p.to_array().map(f64::to_bits)
                    );
                }
                // `apply` takes the vector loop where the CPU allows it.
                assert_eq!(applied, vector);
            }
        }
    }

    /// The vector row (blending and voxels) gives the portable loop's bits on edge values:
    /// control coordinates of ±0, subnormals, ±1e308 (whose sums overflow to ±∞ and, mixed,
    /// to NaN) and ordinary ones, on parts of every width from 1 to 13 voxels, so the rows'
    /// column counts take every remainder modulo four.
    #[test]
    fn vector_row_blending_matches_the_portable_loop_on_edge_values() {
        /// Same bits, or both NaN (Rust leaves the payload of a NaN from NaN operands
        /// unspecified).
        fn same(a: f64, b: f64) -> bool {
            a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
        }
        let edge: [f64; 9] = [
            -0.0, 0.0, 1e308, -1e308, 5e-324, -2.5e-310, 1.0, -3.5, 1e-300,
        ];
        let mut rng = volmorph_testkit::Rng::new(0xb1ed);
        let grid = Geometry::new([40, 7, 6])
            .with_spacing(DVec3::new(0.37, 1.1, 1.3))
            .with_origin(DVec3::new(-2.5, -1.0, -3.0));
        for tame in [false, true] {
            let (lo, hi) = (DVec3::new(-3.0, -2.0, -4.0), DVec3::new(12.0, 8.0, 7.0));
            let lat = lattice_with(lo, hi, [11, 6, 5], |_| {
                let mut pick = || {
                    let v = edge[rng.index(edge.len())];
                    if tame && v.abs() > 1e300 { -0.0 } else { v }
                };
                DVec3::new(pick(), pick(), pick())
            });
            for width in 1..=13 {
                let x0 = rng.index(grid.dims[0] - width + 1);
                let part = IndexBox {
                    start: [x0, 1, 0],
                    end: [x0 + width, 6, 6],
                };
                let plan = LatticeGridPlan::part(&lat, &grid, part).unwrap();
                let [vector, portable, _] = both_loops(&plan, &lat);
                for (v, p) in vector.iter().zip(&portable) {
                    for a in 0..3 {
                        assert!(same(v[a], p[a]), "width {width}: {v:?} vs {p:?}");
                    }
                }
            }
        }
    }

    /// True's setting: with `G` voxels per cell the fractional positions repeat with period
    /// `G`, in either grid direction, so each axis has `G` table classes, plus one when a
    /// voxel sits exactly on the domain end (evaluated in the last span at `t = 1`).
    #[test]
    fn residue_classes_repeat_with_period_g() {
        let kv = KnotVector::uniform(3, 9, [0.0, 6.0]).unwrap();
        for (g, start, step, end_hit) in [
            (4usize, 0.0, 0.25, true),
            (5, 6.0, -0.2, true),
            (3, 0.5, 1.0 / 3.0, false),
            (2, 5.75, -0.5, false),
        ] {
            let axis = AxisPlan::over(&kv, 0..40, start, step).unwrap();
            let (class, reps) = residue_classes(&axis, g, step < 0.0);
            assert_eq!(reps.len(), g + usize::from(end_hit), "G = {g}");
            if !end_hit {
                for (r, &c) in class.iter().enumerate() {
                    assert_eq!(c as usize, r % g);
                }
            }
            // Every member of a class has its representative's basis values.
            for (r, &c) in class.iter().enumerate() {
                let (_, v) = axis.at(axis.lo + r).unwrap();
                let (_, w) = axis.at(reps[c as usize]).unwrap();
                assert!(
                    v.iter()
                        .zip(w)
                        .all(|(a, b)| (a - b).abs() <= TABLE_WEIGHT_TOL)
                );
            }
            assert_eq!(granularity(&kv, step), Some(g));
        }
        assert_eq!(granularity(&kv, 0.3), None);
        let clamped = KnotVector::clamped(3, &[0.2], [0.0, 1.0]).unwrap();
        assert_eq!(granularity(&clamped, 0.1), None);
    }
}
