//! Pull-back through the inverse of a push-forward map: render a volume deformed by a
//! free-form deformation by sampling it at `φ⁻¹(y)` for every output voxel `y`.
//!
//! # Direction
//!
//! The map `φ` is a **push-forward** (a free-form deformation, True 1992 §4): it sends model
//! points to where they go. For every voxel centre `y` of the **output** grid, the output
//! value is the input's interpolated value at the model point that `φ` sends to `y`:
//!
//! ```text
//! output(y) = input(φ⁻¹(y))
//! ```
//!
//! This is the same picture [`crate::pushforward`] produces — the model deformed by `φ` — but
//! computed as a pull-back, one sample per output voxel, so it has neither the holes of
//! nearest-voxel splatting nor the blur of box-filter antialiasing. A translation
//! `φ(p) = p + t` moves the content by `+t`: `output(y) = input(y − t)` (the opposite of
//! [`crate::pullback::resample`] through the same map).
//!
//! # Inversion
//!
//! `φ⁻¹(y)` is found by damped Newton iteration ([`volmorph_deform::inverse`]) to a residual
//! `|φ(x) − y|` of at most [`InverseResampleOptions::tolerance`] (default
//! [`DEFAULT_TOLERANCE_VOXELS`] of the output's smallest voxel spacing). The grid is walked
//! coherently: along each row, Newton starts from the previous voxel's solution `x` advanced by
//! the first-order prediction `Dφ(x)⁻¹·Δy` of one output step `Δy` (the first voxel of a row
//! from the previous row's first solution, advanced one row step). When that start fails the
//! voxel is retried from the first-order inverse of the displacement `y − (φ(y) − y)`, and
//! then from `y` itself.
//!
//! Voxels where no start converges (a target outside the image of `φ`, a singular Jacobian,
//! non-finite values) take [`InverseResampleOptions::fill`] and are counted in
//! [`InverseReport::nonconverged`]. Where `φ` folds space a target may have several
//! preimages (the push-forward would overlap several layers of the model there); the walk
//! shows one of them — the one on the sheet the row is following, as long as the predicted
//! start converges — and the voxels whose preimage has `det Dφ ≤ 0` (an inverted sheet) are
//! counted in [`InverseReport::folded`], their value still sampled at the preimage found. An
//! optional `u8` mask marks both kinds of voxels ([`MASK_NOT_CONVERGED`], [`MASK_FOLDED`]).
//!
//! # How it runs
//!
//! Parallel (rayon) over blocks of whole rows; each task walks its rows as above and samples each
//! preimage immediately with [`Sampler::sample_index`] after the same index conversion and
//! voxel-centre snapping as [`crate::pullback`] (so a map that reproduces voxel centres copies
//! voxel values exactly). Nothing is allocated per voxel.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_deform::Affine;
//! use volmorph_volume::{Geometry, Volume};
//! use volmorph_volume::sample::Interpolation;
//! use volmorph_warp::inverse::{InverseResampleOptions, pullback_through_inverse};
//!
//! let g = Geometry::new([4, 4, 4]);
//! let input = Volume::from_fn(g, |i, j, k| (i + 10 * j + 100 * k) as f32).unwrap();
//! // The model pushed forward by p ↦ p + (1, 0, 0): output(y) = input(y − 1 along x).
//! let map = Affine::translation(DVec3::X);
//! let opts = InverseResampleOptions::new(Interpolation::Linear, 0.0);
//! let r = pullback_through_inverse::<f32, f32, _>(&input, &map, &g, &opts).unwrap();
//! assert_eq!(r.volume[[1, 2, 3]], input[[0, 2, 3]]);
//! assert_eq!(r.volume[[0, 2, 3]], 0.0); // its source x = −1 lies outside the input
//! assert_eq!(r.report.nonconverged, 0);
//! ```

use std::fmt;

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_deform::SpaceMap;
use volmorph_deform::inverse::{Lu3, PointInverse, first_order_guess, newton};
use volmorph_volume::sample::{Boundary, Interpolation, Sampler};
use volmorph_volume::{AnyVolume, AnyVolumeRef, Geometry, Volume, VolumeError, Voxel};

use crate::WarpError;
use crate::pullback::{IndexMap, ResampleOptions, checked_output_len};

/// Default Newton tolerance on the residual `|φ(x) − y|`, as a fraction of the output grid's
/// smallest voxel spacing: far below anything an interpolation kernel resolves, and a few
/// Newton steps from a coherent start.
pub const DEFAULT_TOLERANCE_VOXELS: f64 = 1e-6;

/// Default iteration limit per Newton start (see
/// [`volmorph_deform::inverse::DEFAULT_MAX_ITERATIONS`]).
pub const DEFAULT_MAX_ITERATIONS: u32 = volmorph_deform::inverse::DEFAULT_MAX_ITERATIONS;

/// Output voxels per parallel task (whole rows, at least one). Each task starts its first
/// row from the first-order guess, so tasks should hold many rows; 4 Ki voxels keep a few
/// hundred tasks on a 128³ grid for load balance.
const TASK_VOXELS: usize = 1 << 12;

/// Mask value of a voxel whose preimage was found where the map does not fold.
pub const MASK_CONVERGED: u8 = 0;
/// Mask value of a voxel for which Newton did not converge (the voxel holds the fill value).
pub const MASK_NOT_CONVERGED: u8 = 1;
/// Mask value of a voxel whose preimage was found where the map folds (`det Dφ ≤ 0`).
pub const MASK_FOLDED: u8 = 2;

/// How [`pullback_through_inverse`] samples the input and inverts the map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverseResampleOptions {
    /// Interpolation kernel and boundary policy of the input, applied at the preimages
    /// (default trilinear, `Constant(0)` outside the input).
    pub resample: ResampleOptions,
    /// Value of output voxels whose preimage was not found (default 0).
    pub fill: f64,
    /// Largest accepted residual `|φ(x) − y|` in physical units; `None` (the default) uses
    /// [`DEFAULT_TOLERANCE_VOXELS`] times the output's smallest spacing.
    pub tolerance: Option<f64>,
    /// Iteration limit per Newton start (default [`DEFAULT_MAX_ITERATIONS`]).
    pub max_iterations: u32,
    /// Whether to return a `u8` mask of the voxels that did not converge or landed on a fold
    /// ([`MASK_NOT_CONVERGED`], [`MASK_FOLDED`]; default `false`).
    pub mask: bool,
}

impl Default for InverseResampleOptions {
    fn default() -> Self {
        Self {
            resample: ResampleOptions::default(),
            fill: 0.0,
            tolerance: None,
            max_iterations: DEFAULT_MAX_ITERATIONS,
            mask: false,
        }
    }
}

impl InverseResampleOptions {
    /// Options with the given kernel; `default_value` is both the value beyond the input's
    /// edge ([`Boundary::Constant`]) and the fill of voxels without a preimage.
    #[must_use]
    pub fn new(interpolation: Interpolation, default_value: f64) -> Self {
        Self {
            resample: ResampleOptions::new(interpolation, default_value),
            fill: default_value,
            ..Self::default()
        }
    }

    /// Same options with another boundary policy of the input.
    #[must_use]
    pub fn with_boundary(mut self, boundary: Boundary) -> Self {
        self.resample.boundary = boundary;
        self
    }

    /// Same options with an absolute Newton tolerance (physical units).
    #[must_use]
    pub fn with_tolerance(mut self, tolerance: f64) -> Self {
        self.tolerance = Some(tolerance);
        self
    }

    /// Same options with another iteration limit.
    #[must_use]
    pub fn with_max_iterations(mut self, max_iterations: u32) -> Self {
        self.max_iterations = max_iterations;
        self
    }

    /// Same options, asking for the mask of non-converged and folded voxels.
    #[must_use]
    pub fn with_mask(mut self, mask: bool) -> Self {
        self.mask = mask;
        self
    }

    /// The absolute tolerance on `output`.
    fn tolerance_on(&self, output: &Geometry) -> Result<f64, WarpError> {
        let t = self
            .tolerance
            .unwrap_or(DEFAULT_TOLERANCE_VOXELS * output.spacing.min_element());
        if t.is_finite() && t > 0.0 {
            Ok(t)
        } else {
            Err(WarpError::InvalidOption(format!(
                "Newton tolerance {t} must be a finite number > 0"
            )))
        }
    }
}

/// What happened to the voxels of one [`pullback_through_inverse`] run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InverseReport {
    /// Output voxels.
    pub voxels: usize,
    /// Voxels for which Newton did not converge from any start (they hold the fill value).
    pub nonconverged: usize,
    /// Converged voxels whose preimage lies where the map folds (`det Dφ ≤ 0`).
    pub folded: usize,
}

impl InverseReport {
    /// `true` if every voxel converged to an unfolded preimage.
    #[must_use]
    pub fn is_clean(&self) -> bool {
        self.nonconverged == 0 && self.folded == 0
    }

    fn merge(self, other: Self) -> Self {
        Self {
            voxels: self.voxels + other.voxels,
            nonconverged: self.nonconverged + other.nonconverged,
            folded: self.folded + other.folded,
        }
    }
}

impl fmt::Display for InverseReport {
    /// One line, e.g. `inverse: 12 of 4096 voxels did not converge, 3 on a fold (det J ≤ 0)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "inverse: {} of {} voxels did not converge, {} on a fold (det J ≤ 0)",
            self.nonconverged, self.voxels, self.folded
        )
    }
}

/// The result of [`pullback_through_inverse`]: the output volume (a typed [`Volume`] or an
/// [`AnyVolume`]), the per-voxel report and, if asked for, the mask.
#[derive(Debug, Clone)]
pub struct InverseResample<V> {
    /// The output on the requested grid.
    pub volume: V,
    /// Counts of non-converged and folded voxels.
    pub report: InverseReport,
    /// Per-voxel [`MASK_CONVERGED`] / [`MASK_NOT_CONVERGED`] / [`MASK_FOLDED`] on the output
    /// grid, when [`InverseResampleOptions::mask`] is set.
    pub mask: Option<Volume<u8>>,
}

/// Pull-back through the inverse of the push-forward map `map`: a new volume on the grid
/// `output` whose voxel at physical position `y` holds `input`'s interpolated value at
/// `map⁻¹(y)` — the input model deformed by `map` used as a free-form deformation. See the
/// [module docs](self) for the direction, the inversion and the handling of folds and
/// non-convergence. The output voxel type `U` may differ from the input's `T`; values convert
/// with [`Voxel::from_f64`].
///
/// # Errors
/// [`WarpError::Geometry`] if `output` is invalid or too large for a `U` (or mask) array
/// within the memory budget ([`volmorph_io::memory_limit`]); [`WarpError::InvalidOption`] for a tolerance
/// that is not a finite number > 0; [`WarpError::Volume`] if the sampler cannot be built.
pub fn pullback_through_inverse<T: Voxel, U: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &InverseResampleOptions,
) -> Result<InverseResample<Volume<U>>, WarpError> {
    pullback_through_inverse_with(input, map, output, options, &volmorph_io::NoProgress)
}

/// [`pullback_through_inverse`] reporting to `progress`: one stage whose steps are the
/// output's rows (`ny · nz`), advanced per task of whole rows, stopping between tasks when
/// cancelled. The result equals [`pullback_through_inverse`]'s bit for bit.
///
/// # Errors
/// As [`pullback_through_inverse`]; [`WarpError::Cancelled`] when `progress` asks to stop.
pub fn pullback_through_inverse_with<T: Voxel, U: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &InverseResampleOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<InverseResample<Volume<U>>, WarpError> {
    let len = checked_output_len::<U>(output)?;
    let mut data = vec![U::default(); len];
    let mut mask = options.mask.then(|| vec![MASK_CONVERGED; len]);
    let report = pullback_through_inverse_into_with(
        input,
        map,
        output,
        options,
        &mut data,
        mask.as_deref_mut(),
        progress,
    )?;
    let geometry_error = |source: VolumeError| WarpError::Geometry {
        what: "output grid",
        source,
    };
    Ok(InverseResample {
        volume: Volume::new(*output, data).map_err(geometry_error)?,
        report,
        mask: mask
            .map(|m| Volume::new(*output, m))
            .transpose()
            .map_err(geometry_error)?,
    })
}

/// [`pullback_through_inverse`] into caller-provided buffers (x fastest, one value per voxel
/// of `output`); `mask`, when given, receives [`MASK_CONVERGED`] / [`MASK_NOT_CONVERGED`] /
/// [`MASK_FOLDED`] per voxel ([`InverseResampleOptions::mask`] is ignored).
///
/// # Errors
/// [`WarpError::Geometry`] if `output` is invalid, [`WarpError::BufferLength`] if `out` or
/// `mask` does not have one entry per voxel of `output`, and the errors of
/// [`pullback_through_inverse`].
pub fn pullback_through_inverse_into<T: Voxel, U: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &InverseResampleOptions,
    out: &mut [U],
    mask: Option<&mut [u8]>,
) -> Result<InverseReport, WarpError> {
    pullback_through_inverse_into_with(
        input,
        map,
        output,
        options,
        out,
        mask,
        &volmorph_io::NoProgress,
    )
}

/// [`pullback_through_inverse_into`] reporting to `progress` as
/// [`pullback_through_inverse_with`] does; when cancelled, `out` and `mask` hold an
/// unspecified mix of old and new values.
///
/// # Errors
/// As [`pullback_through_inverse_into`]; [`WarpError::Cancelled`] when `progress` asks to
/// stop.
pub fn pullback_through_inverse_into_with<T: Voxel, U: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &InverseResampleOptions,
    out: &mut [U],
    mask: Option<&mut [u8]>,
    progress: &dyn volmorph_io::Progress,
) -> Result<InverseReport, WarpError> {
    output.validate().map_err(|source| WarpError::Geometry {
        what: "output grid",
        source,
    })?;
    let len_error = |got: usize| WarpError::BufferLength {
        dims: output.dims,
        expected: output.len(),
        got,
    };
    if out.len() != output.len() {
        return Err(len_error(out.len()));
    }
    if let Some(m) = mask.as_deref()
        && m.len() != output.len()
    {
        return Err(len_error(m.len()));
    }
    let tolerance = options.tolerance_on(output)?;
    let sampler = Sampler::new(
        input,
        options.resample.interpolation,
        options.resample.boundary,
    )?;
    let walker = Walker {
        map,
        output,
        sampler: &sampler,
        to_index: IndexMap::new(input.geometry()),
        steps: output.index_to_physical_matrix(),
        tolerance,
        max_iterations: options.max_iterations,
        fill: U::from_f64(options.fill),
    };
    let [nx, ny, nz] = output.dims;
    progress.start(
        &format!("pull-back through the inverse onto {nx}×{ny}×{nz}"),
        (ny * nz) as u64,
    );
    if output.is_empty() {
        return Ok(InverseReport::default());
    }
    // Whole rows per task, about TASK_VOXELS voxels; tasks may span z-slices.
    let rows_per_task = (TASK_VOXELS / nx).clamp(1, ny * nz);
    let chunk = rows_per_task * nx;
    // One mask chunk per task, or empty stand-ins when no mask is wanted.
    let mask_chunks: Vec<&mut [u8]> = match mask {
        Some(m) => m.chunks_mut(chunk).collect(),
        None => (0..out.len().div_ceil(chunk))
            .map(|_| <&mut [u8]>::default())
            .collect(),
    };
    let report = out
        .par_chunks_mut(chunk)
        .zip(mask_chunks.into_par_iter())
        .enumerate()
        .map(|(t, (rows, mask))| {
            if progress.is_cancelled() {
                return InverseReport::default();
            }
            let n = (rows.len() / nx) as u64;
            let r = walker.rows(t * rows_per_task, rows, mask);
            progress.advance(n);
            r
        })
        .reduce(InverseReport::default, InverseReport::merge);
    progress.check()?;
    Ok(report)
}

/// Pull-back through the inverse of `map` for a volume whose voxel type is known at run time;
/// the output keeps the input's voxel type. See [`pullback_through_inverse`].
///
/// # Errors
/// As [`pullback_through_inverse`].
pub fn pullback_through_inverse_any(
    input: &AnyVolume,
    map: &dyn SpaceMap,
    output: &Geometry,
    options: &InverseResampleOptions,
) -> Result<InverseResample<AnyVolume>, WarpError> {
    pullback_through_inverse_any_with(input, map, output, options, &volmorph_io::NoProgress)
}

/// [`pullback_through_inverse_any`] reporting to `progress` as
/// [`pullback_through_inverse_with`] does.
///
/// # Errors
/// As [`pullback_through_inverse_with`].
pub fn pullback_through_inverse_any_with<'a>(
    input: impl Into<AnyVolumeRef<'a>>,
    map: &dyn SpaceMap,
    output: &Geometry,
    options: &InverseResampleOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<InverseResample<AnyVolume>, WarpError> {
    inverse_dyn(input.into(), map, output, options, progress)
}

/// The body of [`pullback_through_inverse_any_with`], not generic so that its voxel types are
/// compiled once, in this crate, rather than in every crate that calls it.
fn inverse_dyn(
    input: AnyVolumeRef<'_>,
    map: &dyn SpaceMap,
    output: &Geometry,
    options: &InverseResampleOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<InverseResample<AnyVolume>, WarpError> {
    fn same_type<T: Voxel>(
        v: &Volume<T, &[T]>,
        map: &dyn SpaceMap,
        output: &Geometry,
        options: &InverseResampleOptions,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<InverseResample<AnyVolume>, WarpError>
    where
        AnyVolume: From<Volume<T>>,
    {
        let r =
            pullback_through_inverse_with::<T, T, dyn SpaceMap>(v, map, output, options, progress)?;
        Ok(InverseResample {
            volume: AnyVolume::from(r.volume),
            report: r.report,
            mask: r.mask,
        })
    }
    volmorph_volume::with_volume_ref!(input, v => same_type(&v, map, output, options, progress))
}

/// Everything one z-slice task needs.
struct Walker<'a, M: ?Sized, U> {
    map: &'a M,
    output: &'a Geometry,
    sampler: &'a Sampler<'a>,
    to_index: IndexMap,
    /// Columns: physical step of one output index along i, j, k.
    steps: DMat3,
    tolerance: f64,
    max_iterations: u32,
    fill: U,
}

impl<M: SpaceMap + ?Sized, U: Voxel> Walker<'_, M, U> {
    /// Walk the rows `first_row, first_row + 1, …` (global row index `j + ny·k`) that make up
    /// `chunk`; `mask` is empty or one entry per voxel of the chunk.
    fn rows(&self, first_row: usize, chunk: &mut [U], mask: &mut [u8]) -> InverseReport {
        let [nx, ny, _] = self.output.dims;
        let mut report = InverseReport {
            voxels: chunk.len(),
            ..InverseReport::default()
        };
        // Solution at the first voxel of the previous row of the same slice, to start the
        // next row from.
        let mut row_start: Option<PointInverse> = None;
        for (n, row) in chunk.chunks_exact_mut(nx).enumerate() {
            let (j, k) = ((first_row + n) % ny, (first_row + n) / ny);
            if j == 0 {
                row_start = None;
            }
            let mut prev = row_start.map(|r| (r, self.steps.y_axis));
            for (i, o) in row.iter_mut().enumerate() {
                let y = self
                    .output
                    .index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                let guess = prev.map(|(r, step)| predict(&r, step));
                let r = self.invert(y, guess);
                let code = if r.converged() {
                    let index = self.to_index.apply(r.point);
                    *o = U::from_f64(self.sampler.sample_index(index));
                    prev = Some((r, self.steps.x_axis));
                    if i == 0 {
                        row_start = Some(r);
                    }
                    if r.det_jacobian > 0.0 {
                        MASK_CONVERGED
                    } else {
                        report.folded += 1;
                        MASK_FOLDED
                    }
                } else {
                    *o = self.fill;
                    prev = None;
                    if i == 0 {
                        row_start = None;
                    }
                    report.nonconverged += 1;
                    MASK_NOT_CONVERGED
                };
                if let Some(m) = mask.get_mut(n * nx + i) {
                    *m = code;
                }
            }
        }
        report
    }

    /// Newton from `guess`, then from the first-order guess, then from `y` (each start tried
    /// once); the first converged result, or the last failure.
    fn invert(&self, y: DVec3, guess: Option<DVec3>) -> PointInverse {
        let run = |x0: DVec3| newton(self.map, y, x0, self.tolerance, self.max_iterations);
        let mut last = None;
        if let Some(g) = guess {
            let r = run(g);
            if r.converged() {
                return r;
            }
            last = Some(r);
        }
        let first = first_order_guess(self.map, y);
        for (n, x0) in [first, y].into_iter().enumerate() {
            if guess == Some(x0) || (n == 1 && first == y) {
                continue;
            }
            let r = run(x0);
            if r.converged() {
                return r;
            }
            last = Some(r);
        }
        last.unwrap_or_else(|| run(y))
    }
}

/// First-order prediction of the preimage of `solution`'s target moved by `step`:
/// `x + Dφ(x)⁻¹·step`, or `x + step` when the Jacobian cannot be solved with.
#[inline]
fn predict(solution: &PointInverse, step: DVec3) -> DVec3 {
    let x = solution.point;
    match Lu3::factor(solution.jacobian) {
        Some(lu) => {
            let d = lu.solve(step);
            if d.is_finite() { x + d } else { x + step }
        }
        None => x + step,
    }
}
