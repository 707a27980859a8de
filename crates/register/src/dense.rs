//! Dense refinement: the initial map (the handle solution) corrected by a cubic B-spline
//! displacement optimised on an intensity metric, as elastix and NiftyReg do:
//!
//! ```text
//! φ(x) = h(x) + (L(x) − x)
//! ```
//!
//! with `h` the initial map and `L` a lattice that starts as the identity ([`Refined`](volmorph_maps::Refined) is this
//! sum as a map). The handle solution is kept exactly; the lattice adds what the intensities
//! show beyond it.
//!
//! # Objective
//!
//! ```text
//! C(P) = D(F, M∘φ) + λ_b h² BE(L)/V + λ_f mean_s max(0, ε − det Dφ(s))²
//!        + λ_h Σ_i c_i |φ(p_i) − q_i|² / (s̄² Σ_i c_i)
//! ```
//!
//! * `D` is the metric over the fixed samples (a sample mapped outside the moving image takes
//!   the edge value there, with no gradient): the mean
//!   squared difference divided by the fixed variance ([`Metric::Mse`]), `−NCC`
//!   ([`Metric::Ncc`]) or `−MI` with Mattes' Parzen histogram ([`Metric::MutualInformation`],
//!   [`crate::metrics::JointHistogram`]);
//! * `BE` is the bending energy `∫ Σ_ab |∂²L/∂x_a∂x_b|²` of the correction over the lattice box
//!   of volume `V`,
//!   computed exactly as a quadratic form of the control points (Kronecker products of the
//!   1-D Gram matrices of the B-splines and their derivatives, by 4-point Gauss quadrature per
//!   span), made dimensionless by the control spacing `h`;
//! * the folding penalty keeps `det Dφ ≥ ε` at the centre of every lattice cell;
//! * the handle correspondences `p_i → q_i` stay as soft constraints weighted by their
//!   confidence `c_i` (`s̄` = mean voxel spacing, so `λ_h` is the cost of one voxel of error).
//!
//! # Gradient
//!
//! The metric's derivative per sample, `∂D/∂m_x · ∇M(φ(x))` (∇M: exact gradient of the trilinear
//! interpolant, [`crate::image::LinearImage`]), is taken to the control points by the adjoint of
//! the lattice's separable grid evaluation ([`LatticeGridPlan::apply_adjoint`]); the penalties
//! have closed-form gradients (the quadratic form; the cofactor matrix of `Dφ`; the basis at
//! each `p_i`). The control points are optimised by L-BFGS ([`crate::optimize`]).
//!
//! # Multi-resolution
//!
//! Image pyramids of both scans and a lattice whose cells halve from level to level: each
//! finer lattice is the exact B-spline subdivision of the previous one ([`subdivide`]: every
//! cell split in two along each axis, masks `(1, 6, 1)/8` and `(1, 1)/2`), so nothing is lost
//! between levels and coarse images only move coarse control points. At each level the metric
//! is evaluated on the level's voxel grid, strided to at most `max_samples` samples.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use volmorph_deform::SpaceMap;
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::grid::{GridPath, LatticeGridPlan};
use volmorph_spline::{uniform_cubic, uniform_cubic_derivative, uniform_cubic_second_derivative};
use volmorph_volume::{Geometry, Volume};

use crate::RegisterError;
use crate::error::{non_negative, positive};
use crate::image::{LinearImage, pyramid, same_grid};
use crate::matching::Correspondence;
use crate::metrics::{JointHistogram, value_range};
use crate::optimize::{LbfgsOptions, minimise, minimise_with};

/// Samples per parallel task.
const CHUNK: usize = 8192;

/// Intensity metric of the dense refinement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Metric {
    /// Mean squared difference (same modality, same intensity scale).
    Mse,
    /// Normalised cross-correlation (intensities related linearly; the default for CT pairs).
    #[default]
    Ncc,
    /// Mattes mutual information (any statistical relation: other modalities, changed
    /// contrast; elastix's default).
    MutualInformation,
}

impl std::str::FromStr for Metric {
    type Err = RegisterError;

    /// `mse`, `ncc` or `mi` (also `mutual-information`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "mse" => Ok(Metric::Mse),
            "ncc" => Ok(Metric::Ncc),
            "mi" | "mutual-information" => Ok(Metric::MutualInformation),
            _ => Err(RegisterError::option(
                "metric",
                format!("unknown metric {s:?}; use mse, ncc or mi"),
            )),
        }
    }
}

/// Options of [`refine`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DenseOptions {
    /// Metric.
    pub metric: Metric,
    /// Control-point spacing of the finest lattice, mm (at most; cells fit the image box).
    pub grid_spacing: f64,
    /// Resolution levels (image pyramid and lattice subdivision).
    pub levels: usize,
    /// L-BFGS iterations per level.
    pub iterations: usize,
    /// Bending-energy weight `λ_b`.
    pub bending: f64,
    /// Folding-penalty weight `λ_f`.
    pub folding: f64,
    /// Smallest Jacobian determinant `ε` not penalised.
    pub fold_threshold: f64,
    /// Weight `λ_h` of the handle correspondences (0 ignores them).
    pub landmarks: f64,
    /// Histogram bins of the mutual information.
    pub bins: usize,
    /// Largest number of metric samples per level (the level grid is strided to fit).
    pub max_samples: usize,
}

impl Default for DenseOptions {
    fn default() -> Self {
        Self {
            metric: Metric::Ncc,
            grid_spacing: 10.0,
            levels: 3,
            iterations: 60,
            bending: 0.05,
            folding: 1.0,
            fold_threshold: 0.1,
            landmarks: 1.0,
            bins: crate::metrics::DEFAULT_BINS,
            max_samples: 150_000,
        }
    }
}

/// What happened at one level.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DenseLevel {
    /// Level (0 = full resolution).
    pub level: usize,
    /// Control points per axis.
    pub control_points: [usize; 3],
    /// Metric samples.
    pub samples: usize,
    /// L-BFGS iterations.
    pub iterations: usize,
    /// Objective evaluations.
    pub evaluations: usize,
    /// Objective before and after.
    pub cost_start: f64,
    /// Objective after.
    pub cost_end: f64,
}

/// Result of [`refine`].
#[derive(Debug, Clone)]
pub struct DenseResult {
    /// The correction lattice `L` (the identity where nothing was corrected).
    pub correction: BSplineLattice,
    /// Per level, coarsest first.
    pub levels: Vec<DenseLevel>,
}

/// A uniform cubic lattice with `regions` cells per axis on the voxel-centre box of `g`, the
/// identity map there.
///
/// # Errors
/// [`RegisterError::Map`] for a degenerate box (an axis with one voxel) or a non-orthonormal
/// direction.
pub fn lattice_on(g: &Geometry, regions: [usize; 3]) -> Result<BSplineLattice, RegisterError> {
    let extent = DVec3::new(
        (g.dims[0] as f64 - 1.0) * g.spacing.x,
        (g.dims[1] as f64 - 1.0) * g.spacing.y,
        (g.dims[2] as f64 - 1.0) * g.spacing.z,
    );
    Ok(BSplineLattice::uniform_cubic_in_box(
        g.origin,
        g.direction,
        extent,
        regions.map(|r| r + 3),
    )?)
}

/// The exact subdivision of a uniform cubic lattice: every cell split in two along each axis
/// (see the [module docs](self)); the map is unchanged.
///
/// # Errors
/// [`RegisterError::Map`] if the result cannot be built.
pub fn subdivide(lat: &BSplineLattice) -> Result<BSplineLattice, RegisterError> {
    let counts = lat.counts();
    let f = lat.frame();
    let extent = f.spacing()
        * DVec3::new(
            (counts[0] - 3) as f64,
            (counts[1] - 3) as f64,
            (counts[2] - 3) as f64,
        );
    let corner = f.to_physical(DVec3::ZERO);
    let fine_counts = counts.map(|n| 2 * (n - 3) + 3);
    let fine = if f.is_skewed() {
        BSplineLattice::uniform_cubic_in_parallelepiped(
            corner,
            f.axes() * DMat3::from_diagonal(extent),
            fine_counts,
        )?
    } else {
        BSplineLattice::uniform_cubic_in_box(corner, f.axes(), extent, fine_counts)?
    };
    let mut pts = lat.control_points();
    let mut dims = counts;
    for axis in 0..3 {
        let n = dims[axis];
        let m = 2 * n - 3;
        let mut nd = dims;
        nd[axis] = m;
        let mut out = vec![DVec3::ZERO; nd[0] * nd[1] * nd[2]];
        let stride_in = [1, dims[0], dims[0] * dims[1]];
        let stride_out = [1, nd[0], nd[0] * nd[1]];
        for k in 0..nd[2] {
            for j in 0..nd[1] {
                for i in 0..nd[0] {
                    let idx = [i, j, k];
                    let mi = idx[axis];
                    let mut base = idx;
                    base[axis] = 0;
                    let b_in: usize = (0..3).map(|a| base[a] * stride_in[a]).sum();
                    let at = |c: usize| pts[b_in + c * stride_in[axis]];
                    let v = if mi % 2 == 0 {
                        let c = mi / 2;
                        (at(c) + at(c + 1)) * 0.5
                    } else {
                        let c = mi.div_ceil(2);
                        (at(c - 1) + at(c) * 6.0 + at(c + 1)) / 8.0
                    };
                    out[(0..3).map(|a| idx[a] * stride_out[a]).sum::<usize>()] = v;
                }
            }
        }
        pts = out;
        dims = nd;
    }
    Ok(BSplineLattice::from_parts(
        *fine.frame(),
        fine.knots().clone(),
        &pts,
    )?)
}

/// Separable bending-energy operator of a uniform cubic lattice (see the [module docs](self)).
struct Bending {
    dims: [usize; 3],
    /// Per axis: scaled Gram matrices of values, first and second derivatives (`n × n`).
    g: [[Vec<f64>; 3]; 3],
}

impl Bending {
    fn new(lat: &BSplineLattice) -> Self {
        let dims = lat.counts();
        let h = lat.frame().spacing();
        // 4-point Gauss–Legendre on [0, 1] (exact to degree 7).
        let a = 0.5 * (3.0f64 / 7.0 + 2.0 / 7.0 * (6.0f64 / 5.0).sqrt()).sqrt();
        let b = 0.5 * (3.0f64 / 7.0 - 2.0 / 7.0 * (6.0f64 / 5.0).sqrt()).sqrt();
        let wa = (18.0 - 30.0f64.sqrt()) / 72.0;
        let wb = (18.0 + 30.0f64.sqrt()) / 72.0;
        let nodes = [(0.5 - a, wa), (0.5 - b, wb), (0.5 + b, wb), (0.5 + a, wa)];
        let g = std::array::from_fn(|axis| {
            let n = dims[axis];
            let scale = [h[axis], 1.0 / h[axis], 1.0 / h[axis].powi(3)];
            std::array::from_fn(|d| {
                let mut m = vec![0.0; n * n];
                for s in 0..n - 3 {
                    for &(t, w) in &nodes {
                        let v = match d {
                            0 => uniform_cubic(t),
                            1 => uniform_cubic_derivative(t),
                            _ => uniform_cubic_second_derivative(t),
                        };
                        for p in 0..4 {
                            for q in 0..4 {
                                m[(s + p) * n + s + q] += w * v[p] * v[q] * scale[d];
                            }
                        }
                    }
                }
                m
            })
        });
        Self { dims, g }
    }

    /// `out = (A_x ⊗ A_y ⊗ A_z) d` with the Gram matrices of derivative orders `orders`.
    fn kron(&self, d: &[DVec3], orders: [usize; 3]) -> Vec<DVec3> {
        let mut cur = d.to_vec();
        for (axis, &ord) in orders.iter().enumerate() {
            let n = self.dims[axis];
            let m = &self.g[axis][ord];
            let stride = [1, self.dims[0], self.dims[0] * self.dims[1]][axis];
            let mut out = vec![DVec3::ZERO; cur.len()];
            for (idx, o) in out.iter_mut().enumerate() {
                let pos = idx / stride % n;
                let base = idx - pos * stride;
                let lo = pos.saturating_sub(3);
                let hi = (pos + 4).min(n);
                let mut acc = DVec3::ZERO;
                for q in lo..hi {
                    acc += m[pos * n + q] * cur[base + q * stride];
                }
                *o = acc;
            }
            cur = out;
        }
        cur
    }

    /// Bending energy of displacements `d` and its gradient `2 K d`.
    fn energy(&self, d: &[DVec3]) -> (f64, Vec<DVec3>) {
        let terms: [([usize; 3], f64); 6] = [
            ([2, 0, 0], 1.0),
            ([0, 2, 0], 1.0),
            ([0, 0, 2], 1.0),
            ([1, 1, 0], 2.0),
            ([1, 0, 1], 2.0),
            ([0, 1, 1], 2.0),
        ];
        let mut kd = vec![DVec3::ZERO; d.len()];
        for (orders, w) in terms {
            for (a, b) in kd.iter_mut().zip(self.kron(d, orders)) {
                *a += w * b;
            }
        }
        let e: f64 = d.iter().zip(&kd).map(|(a, b)| a.dot(*b)).sum();
        (e, kd.into_iter().map(|v| 2.0 * v).collect())
    }
}

/// Bending energy `∫ Σ |∂²φ/∂x_a∂x_b|²` (mm³·mm⁻²) of a uniform cubic lattice over its box.
#[must_use]
pub fn bending_energy(lat: &BSplineLattice) -> f64 {
    Bending::new(lat).energy(&lat.control_points()).0
}

/// Cofactor matrix of `m` (`∂ det m / ∂m`), valid for singular `m` too.
fn cofactor(m: DMat3) -> DMat3 {
    let (a, b, c) = (m.x_axis, m.y_axis, m.z_axis);
    // Columns of the cofactor matrix: b×c, c×a, a×b.
    DMat3::from_cols(b.cross(c), c.cross(a), a.cross(b))
}

/// Level data of the metric.
struct Samples {
    grid: Geometry,
    fixed: Vec<f32>,
    mask: Option<Vec<u8>>,
}

/// Strided sample grid of a pyramid level with at most `max` voxels.
fn samples_of(level: &Volume<f32>, mask: Option<&Volume<u8>>, max: usize) -> Samples {
    let g = *level.geometry();
    let mut stride = 1usize;
    while g
        .dims
        .iter()
        .map(|&n| n.div_ceil(stride))
        .product::<usize>()
        > max
        && stride < 64
    {
        stride += 1;
    }
    let dims = g.dims.map(|n| n.div_ceil(stride));
    let grid = Geometry {
        dims,
        spacing: g.spacing * stride as f64,
        origin: g.origin,
        direction: g.direction,
    };
    let [nx, ny, _] = g.dims;
    let mut fixed = Vec::with_capacity(grid.len());
    let mut mk = mask.map(|_| Vec::with_capacity(grid.len()));
    let mask_sampler = mask.map(|m| (m, m.geometry().index_to_physical_matrix().inverse()));
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let (a, b, c) = (i * stride, j * stride, k * stride);
                fixed.push(level.data()[a + nx * (b + ny * c)]);
                if let (Some(v), Some((m, inv))) = (mk.as_mut(), mask_sampler.as_ref()) {
                    let p = g.index_to_physical(DVec3::new(a as f64, b as f64, c as f64));
                    let idx = *inv * (p - m.geometry().origin);
                    let r = idx.round();
                    let md = m.dims();
                    let inside = (0..3).all(|a| r[a] >= 0.0 && (r[a] as usize) < md[a]);
                    v.push(if inside {
                        m.data()[r.x as usize + md[0] * (r.y as usize + md[1] * r.z as usize)]
                    } else {
                        0
                    });
                }
            }
        }
    }
    Samples {
        grid,
        fixed,
        mask: mk,
    }
}

/// Everything one level's objective needs.
struct LevelProblem<'a> {
    lat: BSplineLattice,
    plan: LatticeGridPlan,
    samples: Samples,
    moving: LinearImage<'a>,
    identity: Vec<DVec3>,
    /// `h(x) − x` at every sample.
    base: Vec<DVec3>,
    bending: Bending,
    /// Basis at the fold points and `D h − I` there.
    fold_points: Vec<(volmorph_lattice::grid::PointBasis, DMat3)>,
    /// Basis at `p_i`, the target `q_i − (h(p_i) − p_i)`, the confidence.
    landmark_points: Vec<(volmorph_lattice::grid::PointBasis, DVec3, f64)>,
    options: DenseOptions,
    fixed_var: f64,
    moving_range: (f64, f64),
    fixed_range: (f64, f64),
    volume: f64,
    mean_spacing: f64,
    voxel_spacing: f64,
}

impl LevelProblem<'_> {
    fn set_points(&mut self, x: &[f64]) -> Result<(), RegisterError> {
        let pts: Vec<DVec3> = x.chunks_exact(3).map(DVec3::from_slice).collect();
        self.lat = BSplineLattice::from_parts(*self.lat.frame(), self.lat.knots().clone(), &pts)?;
        Ok(())
    }

    /// Metric value and per-control-point gradient (metric only).
    fn metric(&self, grad: &mut [DVec3]) -> f64 {
        let n = self.samples.grid.len();
        let mut phi = vec![DVec3::ZERO; n];
        if self.plan.apply(&self.lat, &mut phi).is_err() {
            return f64::INFINITY;
        }
        phi.par_iter_mut()
            .zip(self.base.par_iter())
            .for_each(|(p, b)| *p += *b);
        let mask = self.samples.mask.as_deref();
        // (m, ∇m) per sample; NaN m for samples outside the mask. A sample mapped outside the
        // moving image keeps the edge value with a zero gradient rather than being dropped, so
        // the optimiser gains nothing by pushing awkward samples out of the image.
        let sampled: Vec<(f32, DVec3)> = phi
            .par_iter()
            .enumerate()
            .map(|(i, &p)| {
                if mask.is_some_and(|m| m[i] == 0) {
                    return (f32::NAN, DVec3::ZERO);
                }
                self.moving
                    .sample(p)
                    .unwrap_or_else(|| (self.moving.value_clamped(p), DVec3::ZERO))
            })
            .collect();
        let f = &self.samples.fixed;
        let valid = sampled.iter().filter(|s| !s.0.is_nan()).count();
        if valid < 16 {
            return f64::INFINITY;
        }
        let nv = valid as f64;
        let mut dcdm = vec![0.0f64; n];
        let value = match self.options.metric {
            Metric::Mse => {
                let scale = 1.0 / (nv * self.fixed_var);
                let sum: f64 = sampled
                    .par_iter()
                    .zip(f.par_iter())
                    .zip(dcdm.par_iter_mut())
                    .map(|(((m, _), &fv), d)| {
                        if m.is_nan() {
                            return 0.0;
                        }
                        let r = f64::from(*m) - f64::from(fv);
                        *d = 2.0 * r * scale;
                        r * r
                    })
                    .sum();
                sum * scale
            }
            Metric::Ncc => {
                let (mut sf, mut sm, mut sff, mut smm, mut sfm) = (0.0, 0.0, 0.0, 0.0, 0.0);
                for ((m, _), &fv) in sampled.iter().zip(f) {
                    if m.is_nan() {
                        continue;
                    }
                    let (a, b) = (f64::from(fv), f64::from(*m));
                    sf += a;
                    sm += b;
                    sff += a * a;
                    smm += b * b;
                    sfm += a * b;
                }
                let (mf, mm) = (sf / nv, sm / nv);
                let vf = sff - nv * mf * mf;
                let vm = smm - nv * mm * mm;
                if vf <= 0.0 || vm <= 0.0 {
                    return f64::INFINITY;
                }
                let cov = sfm - nv * mf * mm;
                let ncc = cov / (vf * vm).sqrt();
                let inv = 1.0 / (vf * vm).sqrt();
                for ((d, (m, _)), &fv) in dcdm.iter_mut().zip(&sampled).zip(f) {
                    if !m.is_nan() {
                        let dn = (f64::from(fv) - mf) * inv - ncc * (f64::from(*m) - mm) / vm;
                        *d = -dn;
                    }
                }
                -ncc
            }
            Metric::MutualInformation => {
                let Ok(empty) =
                    JointHistogram::new(self.options.bins, self.fixed_range, self.moving_range)
                else {
                    return f64::INFINITY;
                };
                let h = sampled
                    .par_chunks(CHUNK)
                    .zip(f.par_chunks(CHUNK))
                    .fold(
                        || empty.empty_like(),
                        |mut h, (s, fc)| {
                            for ((m, _), &fv) in s.iter().zip(fc) {
                                if !m.is_nan() {
                                    h.add(f64::from(fv), f64::from(*m));
                                }
                            }
                            h
                        },
                    )
                    .reduce(
                        || empty.empty_like(),
                        |mut a, b| {
                            a.merge(&b);
                            a
                        },
                    );
                let table = h.log_ratio_table();
                dcdm.par_iter_mut()
                    .zip(sampled.par_iter())
                    .zip(f.par_iter())
                    .for_each(|((d, (m, _)), &fv)| {
                        if !m.is_nan() {
                            *d = -h.derivative(&table, f64::from(fv), f64::from(*m));
                        }
                    });
                -h.mutual_information()
            }
        };
        let per_sample: Vec<DVec3> = sampled
            .par_iter()
            .zip(dcdm.par_iter())
            .map(|((m, g), &d)| if m.is_nan() { DVec3::ZERO } else { d * *g })
            .collect();
        if self
            .plan
            .apply_adjoint(self.lat.counts(), &per_sample, grad)
            .is_err()
        {
            return f64::INFINITY;
        }
        value
    }

    /// Full objective and gradient at control points `x` (flattened).
    fn evaluate(&mut self, x: &[f64], g: &mut [f64]) -> f64 {
        if self.set_points(x).is_err() {
            return f64::INFINITY;
        }
        let nc = x.len() / 3;
        let mut grad = vec![DVec3::ZERO; nc];
        let mut cost = self.metric(&mut grad);
        if !cost.is_finite() {
            return f64::INFINITY;
        }
        let pts: Vec<DVec3> = x.chunks_exact(3).map(DVec3::from_slice).collect();
        if self.options.bending > 0.0 {
            let d: Vec<DVec3> = pts
                .iter()
                .zip(&self.identity)
                .map(|(p, i)| *p - *i)
                .collect();
            let (e, ge) = self.bending.energy(&d);
            let w = self.options.bending * self.mean_spacing * self.mean_spacing / self.volume;
            cost += w * e;
            for (a, b) in grad.iter_mut().zip(ge) {
                *a += w * b;
            }
        }
        let counts = self.lat.counts();
        let axes = self.lat.frame().gradient_matrix();
        if self.options.folding > 0.0 && !self.fold_points.is_empty() {
            let w = self.options.folding / self.fold_points.len() as f64;
            let eps = self.options.fold_threshold;
            for (b, dh) in &self.fold_points {
                let mut j = *dh;
                let mut phys = [[DVec3::ZERO; 4]; 4 * 4];
                for c in 0..4 {
                    for bb in 0..4 {
                        for a in 0..4 {
                            let gl = DVec3::new(
                                b.derivatives[0][a] * b.values[1][bb] * b.values[2][c],
                                b.values[0][a] * b.derivatives[1][bb] * b.values[2][c],
                                b.values[0][a] * b.values[1][bb] * b.derivatives[2][c],
                            );
                            let gp = axes * gl;
                            phys[c * 4 + bb][a] = gp;
                            let p = pts[b.control_index(counts, a, bb, c)];
                            j += DMat3::from_cols(p * gp.x, p * gp.y, p * gp.z);
                        }
                    }
                }
                let det = j.determinant();
                if det < eps {
                    let r = eps - det;
                    cost += w * r * r;
                    let de = cofactor(j) * (-2.0 * w * r);
                    for c in 0..4 {
                        for bb in 0..4 {
                            for a in 0..4 {
                                let gp = phys[c * 4 + bb][a];
                                grad[b.control_index(counts, a, bb, c)] += de * gp;
                            }
                        }
                    }
                }
            }
        }
        if self.options.landmarks > 0.0 && !self.landmark_points.is_empty() {
            let total: f64 = self.landmark_points.iter().map(|l| l.2).sum();
            let w = self.options.landmarks / (total * self.voxel_spacing * self.voxel_spacing);
            for (b, q, c) in &self.landmark_points {
                let mut v = DVec3::ZERO;
                for cc in 0..4 {
                    for bb in 0..4 {
                        for a in 0..4 {
                            let wt = b.values[0][a] * b.values[1][bb] * b.values[2][cc];
                            v += wt * pts[b.control_index(counts, a, bb, cc)];
                        }
                    }
                }
                let r = v - *q;
                cost += w * c * r.length_squared();
                for cc in 0..4 {
                    for bb in 0..4 {
                        for a in 0..4 {
                            let wt = b.values[0][a] * b.values[1][bb] * b.values[2][cc];
                            grad[b.control_index(counts, a, bb, cc)] += (2.0 * w * c * wt) * r;
                        }
                    }
                }
            }
        }
        for (o, v) in g.chunks_exact_mut(3).zip(&grad) {
            o.copy_from_slice(&v.to_array());
        }
        cost
    }
}

fn flatten(p: &[DVec3]) -> Vec<f64> {
    p.iter().flat_map(|v| v.to_array()).collect()
}

/// Least-squares fit of `lat`'s control points to `target` sampled on `grid` (L-BFGS on
/// `Σ |φ(x) − target(x)|²`, started from `target` at the control points): the lattice closest
/// to any map, e.g. to hand a handle or refined map to ITK as a `BSplineTransform`.
///
/// # Errors
/// [`RegisterError::Map`] if `grid` is not aligned with the lattice or the map fails on it.
pub fn fit_to_map(
    lat: &BSplineLattice,
    grid: &Geometry,
    target: &dyn SpaceMap,
) -> Result<BSplineLattice, RegisterError> {
    let plan = LatticeGridPlan::new(lat, grid, GridPath::Separable)?;
    let mut want = vec![DVec3::ZERO; grid.len()];
    target.apply_grid(grid, &mut want)?;
    let start: Vec<DVec3> = lat
        .control_points()
        .iter()
        .map(|&p| target.apply(p))
        .collect();
    let mut x = flatten(&start);
    let (frame, knots, counts) = (*lat.frame(), lat.knots().clone(), lat.counts());
    let n = grid.len() as f64;
    let mut phi = vec![DVec3::ZERO; grid.len()];
    let opts = LbfgsOptions {
        iterations: 60,
        first_step: grid.spacing.min_element(),
        relative_tolerance: 1e-9,
        max_line_search: 20,
    };
    minimise(&mut x, &opts, |x, g| {
        let pts: Vec<DVec3> = x.chunks_exact(3).map(DVec3::from_slice).collect();
        let Ok(l) = BSplineLattice::from_parts(frame, knots.clone(), &pts) else {
            return f64::INFINITY;
        };
        if plan.apply(&l, &mut phi).is_err() {
            return f64::INFINITY;
        }
        let r: Vec<DVec3> = phi
            .iter()
            .zip(&want)
            .map(|(a, b)| (*a - *b) * (2.0 / n))
            .collect();
        let cost = phi
            .iter()
            .zip(&want)
            .map(|(a, b)| (*a - *b).length_squared())
            .sum::<f64>()
            / n;
        let mut gr = vec![DVec3::ZERO; pts.len()];
        if plan.apply_adjoint(counts, &r, &mut gr).is_err() {
            return f64::INFINITY;
        }
        for (o, v) in g.chunks_exact_mut(3).zip(&gr) {
            o.copy_from_slice(&v.to_array());
        }
        cost
    });
    let pts: Vec<DVec3> = x.chunks_exact(3).map(DVec3::from_slice).collect();
    Ok(BSplineLattice::from_parts(frame, knots, &pts)?)
}

/// Refine `initial` (a map `fixed → moving`, e.g. the handle solution) by a B-spline correction
/// on the metric (see the [module docs](self)); the refined map is
/// `Refined { base: initial, correction }`. `constraints` are kept as soft constraints
/// (their used ones, weighted by confidence); `mask` (on the fixed grid, non-zero = used)
/// limits the metric's samples.
///
/// # Errors
/// [`RegisterError::Option`] for options out of range, [`RegisterError::Mismatch`] for a mask
/// on another grid, [`RegisterError::TooLittle`] for images with fewer than 4 voxels along an
/// axis, [`RegisterError::Map`] for a fixed grid whose direction is not orthonormal.
pub fn refine(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    initial: &dyn SpaceMap,
    constraints: &[Correspondence],
    mask: Option<&Volume<u8>>,
    options: &DenseOptions,
) -> Result<DenseResult, RegisterError> {
    refine_with(
        fixed,
        moving,
        initial,
        constraints,
        mask,
        options,
        &volmorph_io::NoProgress,
    )
}

/// [`refine`] reporting to `progress`: one stage of `levels × iterations` steps, one per
/// L-BFGS iteration of every pyramid level (the iterations a level does not need are
/// counted when it converges), stopping between iterations when cancelled. The result
/// equals [`refine`]'s bit for bit.
///
/// # Errors
/// As [`refine`]; [`RegisterError::Cancelled`] when `progress` asks to stop.
pub fn refine_with(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    initial: &dyn SpaceMap,
    constraints: &[Correspondence],
    mask: Option<&Volume<u8>>,
    options: &DenseOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<DenseResult, RegisterError> {
    let spacing = positive("grid_spacing", options.grid_spacing)?;
    if options.levels == 0 || options.levels > 6 {
        return Err(RegisterError::option("levels", "must be 1…6"));
    }
    non_negative("bending", options.bending)?;
    non_negative("folding", options.folding)?;
    non_negative("landmarks", options.landmarks)?;
    non_negative("fold_threshold", options.fold_threshold)?;
    if options.max_samples < 1000 {
        return Err(RegisterError::option(
            "max_samples",
            "must be at least 1000",
        ));
    }
    if let Some(m) = mask {
        same_grid(fixed.geometry(), m.geometry(), "mask")?;
    }
    let g0 = *fixed.geometry();
    if g0.dims.iter().any(|&n| n < 4) || moving.dims().iter().any(|&n| n < 4) {
        return Err(RegisterError::TooLittle(
            "dense refinement needs at least 4 voxels along every axis".into(),
        ));
    }
    let extent = DVec3::new(
        (g0.dims[0] - 1) as f64 * g0.spacing.x,
        (g0.dims[1] - 1) as f64 * g0.spacing.y,
        (g0.dims[2] - 1) as f64 * g0.spacing.z,
    );
    let coarse = f64::from(1u32 << (options.levels - 1));
    let regions: [usize; 3] =
        std::array::from_fn(|a| ((extent[a] / (spacing * coarse)).ceil() as usize).max(1));
    let fp = pyramid(fixed, options.levels, crate::matching::PYRAMID_MIN_DIMS);
    let mp = pyramid(moving, options.levels, crate::matching::PYRAMID_MIN_DIMS);
    let moving_range = {
        let (lo, hi) = value_range(moving.data(), None);
        if hi > lo {
            (lo, hi)
        } else {
            (lo - 0.5, lo + 0.5)
        }
    };
    let mut lat = lattice_on(&g0, regions)?;
    let mut reports = Vec::new();
    let voxel_spacing = g0.spacing.element_sum() / 3.0;
    progress.start(
        &format!("dense refinement, {} levels", fp.len()),
        (fp.len() as u64).saturating_mul(options.iterations as u64),
    );
    for level in (0..fp.len()).rev() {
        progress.check()?;
        let samples = samples_of(&fp[level], mask, options.max_samples);
        if level != fp.len() - 1 {
            lat = subdivide(&lat)?;
        }
        let plan = LatticeGridPlan::new(&lat, &samples.grid, GridPath::Separable)?;
        let mut base = vec![DVec3::ZERO; samples.grid.len()];
        initial.apply_grid(&samples.grid, &mut base)?;
        base.par_iter_mut().enumerate().for_each(|(n, b)| {
            *b -= samples.grid.voxel_position(n);
        });
        let identity = lattice_on(&g0, lat.counts().map(|n| n - 3))?.control_points();
        let counts = lat.counts();
        let frame = *lat.frame();
        let mut centres = Vec::new();
        for k in 0..counts[2] - 3 {
            for j in 0..counts[1] - 3 {
                for i in 0..counts[0] - 3 {
                    centres.push(frame.to_physical(DVec3::new(i as f64, j as f64, k as f64) + 0.5));
                }
            }
        }
        let fold_points: Vec<_> = centres
            .par_iter()
            .filter_map(|&x| {
                lat.point_basis(x)
                    .map(|b| (b, initial.jacobian(x) - DMat3::IDENTITY))
            })
            .collect();
        let landmark_points = constraints
            .iter()
            .filter(|c| c.status.is_used() && c.confidence > 0.0)
            .filter_map(|c| {
                let offset = initial.apply(c.source) - c.source;
                lat.point_basis(c.source)
                    .map(|b| (b, c.target - offset, c.confidence))
            })
            .collect();
        let (fixed_range, fixed_var) = {
            let used: Vec<f64> = samples
                .fixed
                .iter()
                .enumerate()
                .filter(|(i, _)| samples.mask.as_ref().is_none_or(|m| m[*i] != 0))
                .map(|(_, &v)| f64::from(v))
                .collect();
            let n = used.len().max(1) as f64;
            let mean = used.iter().sum::<f64>() / n;
            let var = used.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
            let lo = used.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = used.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            ((lo, if hi > lo { hi } else { lo + 1.0 }), var.max(1e-12))
        };
        let mean_spacing = frame.spacing().element_sum() / 3.0;
        let volume = (frame.spacing()
            * DVec3::new(
                (counts[0] - 3) as f64,
                (counts[1] - 3) as f64,
                (counts[2] - 3) as f64,
            ))
        .element_product();
        let n_samples = samples.grid.len();
        let mut problem = LevelProblem {
            bending: Bending::new(&lat),
            lat: lat.clone(),
            plan,
            samples,
            moving: LinearImage::new(&mp[level.min(mp.len() - 1)]),
            identity,
            base,
            fold_points,
            landmark_points,
            options: *options,
            fixed_var,
            moving_range,
            fixed_range,
            volume,
            mean_spacing,
            voxel_spacing,
        };
        let mut x = flatten(&lat.control_points());
        let opts = LbfgsOptions {
            iterations: options.iterations,
            first_step: 0.5 * fp[level].geometry().spacing.min_element(),
            relative_tolerance: 1e-6,
            max_line_search: 12,
        };
        let r = minimise_with(&mut x, &opts, |x, g| problem.evaluate(x, g), progress)?;
        problem.set_points(&x)?;
        lat = problem.lat;
        reports.push(DenseLevel {
            level,
            control_points: counts,
            samples: n_samples,
            iterations: r.iterations,
            evaluations: r.evaluations,
            cost_start: r.start,
            cost_end: r.end,
        });
    }
    progress.check()?;
    Ok(DenseResult {
        correction: lat,
        levels: reports,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wavy() -> BSplineLattice {
        let g = Geometry::new([20, 16, 12]).with_spacing(DVec3::new(1.0, 1.5, 2.0));
        let mut lat = lattice_on(&g, [3, 2, 2]).unwrap();
        jiggle(&mut lat);
        lat
    }

    /// Move every control point of `lat` by a fixed pattern.
    fn jiggle(lat: &mut BSplineLattice) {
        let c = lat.counts();
        for k in 0..c[2] {
            for j in 0..c[1] {
                for i in 0..c[0] {
                    let d = DVec3::new(
                        ((i * 3 + j) % 5) as f64 * 0.3,
                        ((j * 2 + k) % 3) as f64 * -0.4,
                        ((i + k) % 4) as f64 * 0.2,
                    );
                    lat.move_control_point([i, j, k], d).unwrap();
                }
            }
        }
    }

    #[test]
    fn subdivision_keeps_the_map() {
        let lat = wavy();
        let fine = subdivide(&lat).unwrap();
        assert_eq!(fine.counts(), [9, 7, 7]);
        for i in 0..200 {
            let t = f64::from(i);
            let p = DVec3::new(
                (t * 0.37).fract() * 19.0,
                (t * 0.61).fract() * 22.5,
                (t * 0.13).fract() * 22.0,
            );
            assert!((fine.apply(p) - lat.apply(p)).length() < 1e-10, "{p}");
        }
    }

    /// A skewed (parallelepiped) lattice subdivides into a skewed lattice of the same map.
    #[test]
    fn subdivision_of_a_skewed_lattice_keeps_the_map() {
        let edges = DMat3::from_cols(
            DVec3::new(20.0, 0.0, 0.0),
            DVec3::new(6.0, 18.0, 0.0),
            DVec3::new(-3.0, 4.0, 16.0),
        );
        let mut lat =
            BSplineLattice::uniform_cubic_in_parallelepiped(DVec3::ZERO, edges, [6, 5, 5]).unwrap();
        jiggle(&mut lat);
        let fine = subdivide(&lat).unwrap();
        assert!(fine.frame().is_skewed());
        assert_eq!(fine.counts(), [9, 7, 7]);
        for i in 0..200 {
            let t = f64::from(i);
            let s = DVec3::new((t * 0.37).fract(), (t * 0.61).fract(), (t * 0.13).fract());
            let p = edges * s;
            assert!((fine.apply(p) - lat.apply(p)).length() < 1e-10, "{p}");
        }
    }

    /// The quadratic form equals the bending energy integrated by sampling second derivatives.
    #[test]
    fn bending_energy_matches_quadrature() {
        let lat = wavy();
        let be = bending_energy(&lat);
        // Midpoint-rule integral of Σ |∂²φ/∂a∂b|² by central differences of the Jacobian.
        let (lo, hi) = (DVec3::ZERO, DVec3::new(19.0, 22.5, 22.0));
        let n = 48;
        let h = (hi - lo) / n as f64;
        let e = 1e-4;
        let mut sum = 0.0;
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = lo + h * (DVec3::new(i as f64, j as f64, k as f64) + 0.5);
                    for a in 0..3 {
                        let mut d = DVec3::ZERO;
                        d[a] = e;
                        let dj = (lat.jacobian(p + d) - lat.jacobian(p - d)) * (0.5 / e);
                        sum += dj.x_axis.length_squared()
                            + dj.y_axis.length_squared()
                            + dj.z_axis.length_squared();
                    }
                }
            }
        }
        let integral = sum * h.element_product();
        assert!((be - integral).abs() < 0.02 * be, "{be} vs {integral}");
        // The identity does not bend.
        let g = Geometry::new([20, 16, 12]).with_spacing(DVec3::new(1.0, 1.5, 2.0));
        assert!(bending_energy(&lattice_on(&g, [3, 2, 2]).unwrap()).abs() < 1e-9);
    }

    #[test]
    fn cofactor_is_the_derivative_of_the_determinant() {
        let m = DMat3::from_cols(
            DVec3::new(1.0, 0.2, -0.3),
            DVec3::new(0.1, 0.9, 0.4),
            DVec3::new(0.0, -0.2, 1.1),
        );
        let c = cofactor(m);
        let e = 1e-6;
        for col in 0..3 {
            for row in 0..3 {
                let mut a = m;
                a.col_mut(col)[row] += e;
                let mut b = m;
                b.col_mut(col)[row] -= e;
                let fd = (a.determinant() - b.determinant()) / (2.0 * e);
                assert!((fd - c.col(col)[row]).abs() < 1e-8);
            }
        }
    }
}
