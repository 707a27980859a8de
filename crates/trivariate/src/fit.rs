//! Fitting trivariate (and lower-dimensional) splines to gridded data (Martin & Cohen §3).
//!
//! * [`interpolate`] — the paper's interpolation at the Greville abscissae ("nodal values")
//!   by separable solves along each axis (its equations (2)–(3)). It delegates to
//!   `volmorph_spline`'s [`Interpolator`], which factors each axis's collocation matrix once
//!   with a banded LU (no pivoting: the matrix is totally positive) and applies it along every
//!   grid line.
//! * [`least_squares`] — for noisy data with more samples than control points: on a tensor
//!   grid of samples the least-squares problem `min ‖(A_2 ⊗ A_1 ⊗ A_0) P − c‖` separates, since
//!   `(A_2 ⊗ A_1 ⊗ A_0)⁺ = A_2⁺ ⊗ A_1⁺ ⊗ A_0⁺` for full-column-rank factors. Each axis's
//!   `m_a × n_a` collocation matrix is factored once by a Householder QR (faer) and solved in
//!   the least-squares sense for all grid lines at once — never an explicit inverse or the
//!   normal equations.
//! * [`least_squares_knots`] — the knots [`fit_sampled_volume`] fits uniformly spaced samples
//!   with: averaging (Piegl & Tiller, *The NURBS Book*, eq. 9.8) of uniform control-point
//!   parameters, so the basis functions are spread like the samples and the collocation
//!   matrix stays well conditioned for every count up to the number of samples.
//!
//! Data layout: `dim` values per grid point, grid index axis 0 fastest (as control nets).
//! Results are polynomial splines on the given knot vectors (use the unit domain to attach
//! them to an [`crate::Aggregate`]).

use faer::Mat;
use faer::linalg::solvers::SolveLstsq;
use volmorph_spline::{Interpolator, KnotVector, TensorBSpline, basis_funs_into};

use crate::TrivariateError;
use crate::error::ctx;

/// Smallest ratio `min |R_ii| / max |R_ii|` of the QR factor of a least-squares collocation
/// matrix accepted as full rank: `√ε` of `f64` (1.49e-8). Since `σ_min ≤ |R_ii| ≤ σ_max`, a
/// ratio at or below it proves the condition number `κ ≥ 1/√ε`, where `κ²·ε ≥ 1`: the
/// least-squares solution of data with a residual then has no correct digit (its relative
/// sensitivity is about `ε·(κ + κ²·tan θ)`, Golub & Van Loan, *Matrix Computations*, 4th ed.,
/// §5.3.8). Well-placed sites are far from it: [`least_squares_knots`] with 8 to 300 uniform
/// sites keeps the ratio above 0.14 for every count and order up to 6 (measured), where the
/// clamped uniform knots used before fell to 1e-14 at 300 sites and 299 cubic control points.
pub const RANK_TOLERANCE: f64 = 1.490_116_119_384_765_6e-8;

/// The Greville abscissae of each axis: the sample sites [`interpolate`] expects.
#[must_use]
pub fn greville_sites<const N: usize>(knots: &[KnotVector; N]) -> [Vec<f64>; N] {
    std::array::from_fn(|a| knots[a].greville())
}

/// Interpolate data sampled on the grid of Greville abscissae of `knots` (paper §3): the
/// result `S` satisfies `S(g) = c_g` at every grid site `g`.
///
/// # Errors
/// [`TrivariateError::Spline`] for a wrong data length, non-finite data, a zero `dim`, or
/// Greville sites outside the domain (unclamped knot vectors).
pub fn interpolate<const N: usize>(
    knots: [KnotVector; N],
    dim: usize,
    data: &[f64],
) -> Result<TensorBSpline<N>, TrivariateError> {
    Interpolator::greville(knots)
        .and_then(|i| i.fit(dim, data))
        .map_err(ctx("Greville interpolation"))
}

/// Clamped knots on `[0, 1]` of `degree` for `count` control points, for least squares over
/// uniformly spaced sites: the interior knots average `degree` consecutive uniform
/// control-point parameters `k / (count − 1)` (Piegl & Tiller, *The NURBS Book*, eq. 9.8,
/// applied to the control points' parameters),
/// `t_{p+j} = (j + (p − 1)/2) / (count − 1)` for `j = 1 … count − p − 1`.
///
/// Every Greville abscissa whose knots are all interior is then exactly `k / (count − 1)` (the
/// `p` at each end lie within a knot span of it), so the basis functions are spread like
/// uniform samples: `count ≤ m` uniform sites `i / (m − 1)` put a site near the
/// peak of every basis function and the collocation matrix stays well conditioned for every
/// count from `degree + 1` to `m` (with `count = m` it is interpolation at uniform sites on
/// averaged knots, Piegl & Tiller's eq. 9.8 proper). Clamped *uniform* knots instead crowd
/// the Greville abscissae near the ends (cubic: `0, h/3, h` in the first knot span), where
/// near `count = m` uniform sites put only two per span: the matrix then loses rank exponentially in `m`
/// (at 300 sites and 299 cubic control points its smallest singular value is 1e-14).
/// Piegl & Tiller's least-squares placement (eq. 9.68–9.69) does not help there: with
/// `m ≈ count` its first span nearly vanishes (`min |R_ii|` ≈ 3e-11 at 300 and 299).
///
/// # Errors
/// [`TrivariateError::Spline`] for a degree above the supported maximum or
/// `count ≤ degree`.
pub fn least_squares_knots(degree: usize, count: usize) -> Result<KnotVector, TrivariateError> {
    if count <= degree {
        // Let the knot vector name the problem (too few control points for the degree).
        return KnotVector::clamped_uniform(degree, count, [0.0, 1.0]).map_err(ctx("knots"));
    }
    let last = (count - 1) as f64;
    let shift = (degree as f64 - 1.0) / 2.0;
    let interior: Vec<f64> = (1..count - degree)
        .map(|j| (j as f64 + shift) / last)
        .collect();
    KnotVector::clamped(degree, &interior, [0.0, 1.0]).map_err(ctx("knots"))
}

/// Least-squares fit of data sampled on the tensor grid `sites[0] × sites[1] × …` (each axis
/// non-decreasing, inside its knot vector's domain, at least as many sites as basis
/// functions). Minimises the sum of squared differences over all samples and components.
///
/// # Errors
/// [`TrivariateError::TooFewSamples`], [`TrivariateError::DataLength`],
/// [`TrivariateError::InvalidArgument`] (unsorted, non-finite or out-of-domain sites,
/// non-finite data, zero `dim`), [`TrivariateError::RankDeficient`] when some basis function
/// has too little support among the sites (the ratio test of [`RANK_TOLERANCE`]).
pub fn least_squares<const N: usize>(
    knots: [KnotVector; N],
    sites: [&[f64]; N],
    dim: usize,
    data: &[f64],
) -> Result<TensorBSpline<N>, TrivariateError> {
    least_squares_with(knots, sites, dim, data, &volmorph_io::NoProgress)
}

/// [`least_squares`] advancing `progress` by one step per axis solved (`N` steps; the
/// caller announces the stage) and stopping between axes when cancelled. The result equals
/// [`least_squares`]'s bit for bit.
///
/// # Errors
/// As [`least_squares`]; [`TrivariateError::Cancelled`] when `progress` asks to stop.
pub fn least_squares_with<const N: usize>(
    knots: [KnotVector; N],
    sites: [&[f64]; N],
    dim: usize,
    data: &[f64],
    progress: &dyn volmorph_io::Progress,
) -> Result<TensorBSpline<N>, TrivariateError> {
    if dim == 0 {
        return Err(TrivariateError::InvalidArgument(
            "dim must be positive".into(),
        ));
    }
    let mut sizes: [usize; N] = std::array::from_fn(|a| sites[a].len());
    let mut expected = dim;
    for (a, &m) in sizes.iter().enumerate() {
        let n = knots[a].num_basis();
        if m < n {
            return Err(TrivariateError::TooFewSamples {
                axis: a,
                samples: m,
                controls: n,
            });
        }
        expected = expected.checked_mul(m).ok_or(TrivariateError::DataLength {
            what: "least-squares data",
            expected: usize::MAX,
            got: data.len(),
        })?;
    }
    if data.len() != expected {
        return Err(TrivariateError::DataLength {
            what: "least-squares data",
            expected,
            got: data.len(),
        });
    }
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(TrivariateError::InvalidArgument(format!(
            "data value {i} is not finite"
        )));
    }
    let mut cur = data.to_vec();
    for a in 0..N {
        progress.check()?;
        let kv = &knots[a];
        let n = kv.num_basis();
        let m = sizes[a];
        let colloc = collocation(a, kv, sites[a])?;
        let qr = colloc.qr();
        let r = qr.thin_R();
        let rmax = (0..n).map(|i| r[(i, i)].abs()).fold(0.0, f64::max);
        if rmax == 0.0 || (0..n).any(|i| r[(i, i)].abs() <= RANK_TOLERANCE * rmax) {
            return Err(TrivariateError::RankDeficient { axis: a });
        }
        let inner: usize = dim * sizes[..a].iter().product::<usize>();
        let outer: usize = sizes[a + 1..].iter().product();
        let cols = inner * outer;
        let mut rhs = Mat::<f64>::from_fn(m, cols, |i, c| {
            cur[c % inner + inner * (i + m * (c / inner))]
        });
        qr.solve_lstsq_in_place(rhs.as_mut());
        let mut next = vec![0.0; inner * n * outer];
        for c in 0..cols {
            for i in 0..n {
                next[c % inner + inner * (i + n * (c / inner))] = rhs[(i, c)];
            }
        }
        cur = next;
        sizes[a] = n;
        progress.advance(1);
    }
    TensorBSpline::new(knots, dim, cur).map_err(ctx("least-squares fit"))
}

/// Dense `m × n` collocation matrix `A[j][i] = N_i(sites[j])` of one axis.
fn collocation(axis: usize, kv: &KnotVector, sites: &[f64]) -> Result<Mat<f64>, TrivariateError> {
    let p = kv.degree();
    let mut a = Mat::<f64>::zeros(sites.len(), kv.num_basis());
    let mut vals = vec![0.0; p + 1];
    let mut prev = f64::NEG_INFINITY;
    for (j, &t) in sites.iter().enumerate() {
        if t.is_nan() || t < prev {
            return Err(TrivariateError::InvalidArgument(format!(
                "axis {axis}: site {j} ({t}) is NaN or smaller than its predecessor"
            )));
        }
        prev = t;
        let span = kv.find_span(t).map_err(|_| {
            TrivariateError::InvalidArgument(format!(
                "axis {axis}: site {j} ({t}) lies outside the domain {:?}",
                kv.domain()
            ))
        })?;
        basis_funs_into(kv, span, t, &mut vals).map_err(ctx("collocation"))?;
        for (q, &v) in vals.iter().enumerate() {
            a[(j, span - p + q)] = v;
        }
    }
    Ok(a)
}

/// How [`fit_sampled_volume`] fitted the samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampledFitKind {
    /// As many control points as samples on every axis: interpolation at the Greville
    /// abscissae of clamped uniform knots, with the geometry placed so that every voxel
    /// centre is the image of its own Greville point (every sample is reproduced at its own
    /// position).
    Interpolation,
    /// Fewer control points than samples on some axis: least squares over the voxel centres,
    /// with a trilinear box geometry (voxel centre `i` at parameter `i / (n − 1)`) and the
    /// attribute on [`least_squares_knots`].
    LeastSquares,
}

/// A sampled volume fitted by [`fit_sampled_volume`].
#[derive(Debug, Clone)]
pub struct SampledFit {
    /// The model: the geometry over the volume's voxel-centre box and the attribute.
    pub model: crate::AggregateVolume,
    /// How the attribute was fitted.
    pub kind: SampledFitKind,
}

/// Fit the samples of `volume` (one value per voxel, x fastest) as an attribute named `name`
/// of order `order` (degree `p = order − 1`) with `counts` control points per axis, over
/// `[0, 1]³` (Martin & Cohen §3). The geometry's corners `u, v, w ∈ {0, 1}` are the corner
/// voxel centres in both cases.
///
/// * `counts` equal to the volume's dims: the attribute, on clamped uniform knots,
///   interpolates the samples at the Greville abscissae `ξ_i = (t_{i+1} + … + t_{i+p}) / p`
///   (cubic: `0, h/3, h, 2h, …, 1 − h/3, 1` with `h = 1/(n − 3)`) — the well-conditioned
///   sites the paper prescribes (the per-axis Lebesgue constant stays below 2, where uniform
///   sites give 6·10⁴ at 64 samples). The geometry is the tensor product of per-axis splines
///   on the same knots interpolating the voxel index `i` at `ξ_i`, taken through the volume's
///   index-to-physical map: voxel `(i, j, k)`'s centre is the image of `(ξ_i, ξ_j, ξ_k)`, and
///   the attribute there is its sample to rounding.
/// * Fewer control points on some axis: the geometry is the trilinear map of the voxel-centre
///   box, so voxel `(i, j, k)` sits at parameters `(i, j, k) / (dims − 1)`, and the attribute,
///   on [`least_squares_knots`], is the least-squares fit over those sites (every count from
///   the order to the number of samples is well conditioned).
///
/// # Errors
/// [`TrivariateError::InvalidArgument`] for fewer than 2 samples along an axis, an order
/// below 2, counts below the order or above the samples, or non-finite samples; the fitting
/// errors of [`interpolate`] and [`least_squares`].
pub fn fit_sampled_volume(
    volume: &volmorph_volume::Volume<f64>,
    order: usize,
    counts: [usize; 3],
    name: &str,
) -> Result<SampledFit, TrivariateError> {
    fit_sampled_volume_with(volume, order, counts, name, &volmorph_io::NoProgress)
}

/// [`fit_sampled_volume`] reporting to `progress`: one stage of 3 steps (interpolation: the
/// geometry, the collocation factorisations, the attribute's solve; least squares: one per
/// axis solved), stopping between steps when cancelled. The result equals
/// [`fit_sampled_volume`]'s bit for bit.
///
/// # Errors
/// As [`fit_sampled_volume`]; [`TrivariateError::Cancelled`] when `progress` asks to stop.
pub fn fit_sampled_volume_with(
    volume: &volmorph_volume::Volume<f64>,
    order: usize,
    counts: [usize; 3],
    name: &str,
    progress: &dyn volmorph_io::Progress,
) -> Result<SampledFit, TrivariateError> {
    let g = volume.geometry();
    let dims = g.dims;
    if dims.iter().any(|&d| d < 2) {
        return Err(TrivariateError::InvalidArgument(format!(
            "the volume needs at least 2 samples per axis to fit, has {dims:?}"
        )));
    }
    if order < 2 {
        return Err(TrivariateError::InvalidArgument(format!(
            "the order must be at least 2 (linear), got {order}"
        )));
    }
    for a in 0..3 {
        if counts[a] > dims[a] {
            return Err(TrivariateError::InvalidArgument(format!(
                "axis {a}: {} control points exceed the {} samples (a fit needs at most one \
                 control point per sample)",
                counts[a], dims[a]
            )));
        }
        if counts[a] < order {
            return Err(TrivariateError::InvalidArgument(format!(
                "axis {a}: too few control points ({}) for the order {order}",
                counts[a]
            )));
        }
    }
    let degree = order - 1;
    let data = volume.data();
    progress.start(
        &format!(
            "fitting {}×{}×{} control points",
            counts[0], counts[1], counts[2]
        ),
        3,
    );
    if counts == dims {
        let knots: [KnotVector; 3] = [
            KnotVector::clamped_uniform(degree, counts[0], [0.0, 1.0]).map_err(ctx("knots"))?,
            KnotVector::clamped_uniform(degree, counts[1], [0.0, 1.0]).map_err(ctx("knots"))?,
            KnotVector::clamped_uniform(degree, counts[2], [0.0, 1.0]).map_err(ctx("knots"))?,
        ];
        // Per axis, the spline on the attribute's knots with value m at Greville point m.
        let mut coefficient: [Vec<f64>; 3] = Default::default();
        for a in 0..3 {
            let idx: Vec<f64> = (0..dims[a]).map(|m| m as f64).collect();
            let s = interpolate([knots[a].clone()], 1, &idx)?;
            coefficient[a] = s.control_points();
        }
        let mut pts = Vec::with_capacity(3 * dims.iter().product::<usize>());
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let c =
                        glam::DVec3::new(coefficient[0][i], coefficient[1][j], coefficient[2][k]);
                    pts.extend(g.index_to_physical(c).to_array());
                }
            }
        }
        let geometry = TensorBSpline::new(knots.clone(), 3, pts).map_err(ctx("geometry"))?;
        progress.advance(1);
        progress.check()?;
        let interpolator = Interpolator::greville(knots).map_err(ctx("Greville interpolation"))?;
        progress.advance(1);
        progress.check()?;
        let attribute = interpolator
            .fit(1, data)
            .map_err(ctx("Greville interpolation"))?;
        progress.advance(1);
        return Ok(SampledFit {
            model: crate::Aggregate::new(geometry)?.with_attribute(name, attribute)?,
            kind: SampledFitKind::Interpolation,
        });
    }
    // Least squares: trilinear box geometry, sample (i, j, k) at parameters (i, j, k)/(dims − 1),
    // the attribute on knots whose Greville abscissae are spread like those sites.
    let knots: [KnotVector; 3] = [
        least_squares_knots(degree, counts[0])?,
        least_squares_knots(degree, counts[1])?,
        least_squares_knots(degree, counts[2])?,
    ];
    let lin = KnotVector::clamped_uniform(1, 2, [0.0, 1.0]).map_err(ctx("knots"))?;
    let mut pts = Vec::with_capacity(24);
    for k in 0..2 {
        for j in 0..2 {
            for i in 0..2 {
                let idx = glam::DVec3::new(
                    (i * (dims[0] - 1)) as f64,
                    (j * (dims[1] - 1)) as f64,
                    (k * (dims[2] - 1)) as f64,
                );
                pts.extend(g.index_to_physical(idx).to_array());
            }
        }
    }
    let geometry =
        TensorBSpline::new([lin.clone(), lin.clone(), lin], 3, pts).map_err(ctx("geometry"))?;
    let sites: [Vec<f64>; 3] = std::array::from_fn(|a| {
        (0..dims[a])
            .map(|i| i as f64 / (dims[a] - 1) as f64)
            .collect()
    });
    let attribute =
        least_squares_with(knots, [&sites[0], &sites[1], &sites[2]], 1, data, progress)?;
    Ok(SampledFit {
        model: crate::Aggregate::new(geometry)?.with_attribute(name, attribute)?,
        kind: SampledFitKind::LeastSquares,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kv(p: usize, interior: &[f64]) -> KnotVector {
        KnotVector::clamped(p, interior, [0.0, 1.0]).unwrap()
    }

    fn grid(sites: &[Vec<f64>; 3], f: impl Fn([f64; 3]) -> [f64; 2]) -> Vec<f64> {
        let mut d = Vec::new();
        for &w in &sites[2] {
            for &v in &sites[1] {
                for &u in &sites[0] {
                    d.extend(f([u, v, w]));
                }
            }
        }
        d
    }

    #[test]
    fn rank_tolerance_is_the_square_root_of_epsilon() {
        assert_eq!(RANK_TOLERANCE, f64::EPSILON.sqrt());
    }

    #[test]
    fn interpolation_reproduces_data_at_greville_sites() {
        let knots = [kv(3, &[0.3, 0.5]), kv(2, &[0.25, 0.7, 0.8]), kv(3, &[])];
        let sites = greville_sites(&knots);
        let f = |x: [f64; 3]| [(3.0 * x[0]).sin() * x[1].exp() + x[2], x[0] * x[1] * x[2]];
        let data = grid(&sites, f);
        let s = interpolate(knots, 2, &data).unwrap();
        let mut out = [0.0; 2];
        for &w in &sites[2] {
            for &v in &sites[1] {
                for &u in &sites[0] {
                    s.eval_into([u, v, w], &mut out).unwrap();
                    let want = f([u, v, w]);
                    assert!((out[0] - want[0]).abs() < 1e-12 && (out[1] - want[1]).abs() < 1e-12);
                }
            }
        }
        assert!(interpolate([kv(1, &[])], 1, &[1.0]).is_err());
    }

    #[test]
    fn least_squares_reproduces_data_in_the_spline_space() {
        let knots = [kv(3, &[0.4]), kv(2, &[0.5]), kv(1, &[0.3, 0.6])];
        let counts = knots.clone().map(|k| k.num_basis());
        let n: usize = counts.iter().product();
        let coefs: Vec<f64> = (0..2 * n)
            .map(|i| ((i * 37 % 11) as f64 - 5.0) * 0.3)
            .collect();
        let truth = TensorBSpline::new(knots.clone(), 2, coefs.clone()).unwrap();
        let sites: [Vec<f64>; 3] = std::array::from_fn(|a| {
            let m = 2 * counts[a] + 3;
            (0..m)
                .map(|i| (i as f64 / (m - 1) as f64).powf(1.3))
                .collect()
        });
        let data = grid(&sites, |x| {
            let v = truth.eval(x).unwrap();
            [v[0], v[1]]
        });
        let s = least_squares(knots.clone(), [&sites[0], &sites[1], &sites[2]], 2, &data).unwrap();
        let got = s.control_points();
        for (a, b) in got.iter().zip(&coefs) {
            assert!((a - b).abs() < 1e-10, "{a} vs {b}");
        }
        // Noise: the fit's residual is no larger than the truth's.
        let noisy: Vec<f64> = data
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.01 * (((i * 7919) % 13) as f64 - 6.0))
            .collect();
        let fit =
            least_squares(knots.clone(), [&sites[0], &sites[1], &sites[2]], 2, &noisy).unwrap();
        let resid = |s: &TensorBSpline<3>| {
            let model = grid(&sites, |x| {
                let v = s.eval(x).unwrap();
                [v[0], v[1]]
            });
            model
                .iter()
                .zip(&noisy)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
        };
        assert!(resid(&fit) <= resid(&truth) + 1e-12);
        // Errors.
        let few = [vec![0.0, 0.5, 1.0], sites[1].clone(), sites[2].clone()];
        assert!(matches!(
            least_squares(knots.clone(), [&few[0], &few[1], &few[2]], 2, &data),
            Err(TrivariateError::TooFewSamples { axis: 0, .. })
        ));
        assert!(matches!(
            least_squares(
                knots.clone(),
                [&sites[0], &sites[1], &sites[2]],
                2,
                &data[1..]
            ),
            Err(TrivariateError::DataLength { .. })
        ));
        let mut bad = sites[0].clone();
        bad.swap(1, 2);
        assert!(matches!(
            least_squares(knots.clone(), [&bad, &sites[1], &sites[2]], 2, &data),
            Err(TrivariateError::InvalidArgument(_))
        ));
        // All samples of axis 2 clustered in the first span: later basis functions unsupported.
        let clustered: Vec<f64> = (0..sites[2].len()).map(|i| 0.01 * i as f64).collect();
        assert!(matches!(
            least_squares(knots, [&sites[0], &sites[1], &clustered], 2, &data),
            Err(TrivariateError::RankDeficient { axis: 2 })
        ));
    }
}
