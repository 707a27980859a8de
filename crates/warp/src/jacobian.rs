//! Jacobian determinant maps of a space map on a voxel grid, and folding statistics.
//!
//! For a map `φ` the determinant `J(x) = det Dφ(x)` measures the local change of volume: a
//! small cell of volume `dV` around `x` is sent to a cell of volume `J(x)·dV`. `J > 1` is
//! expansion, `0 < J < 1` compression, and `J ≤ 0` means the map **folds** space there (it
//! turns a neighbourhood inside out or collapses it), so it is not locally invertible. The
//! determinant does not depend on the direction the map is used in: the same values apply
//! whether the map pushes a model forward or pulls an image back.
//!
//! ```
//! use glam::{DMat3, DVec3};
//! use volmorph_deform::Affine;
//! use volmorph_volume::Geometry;
//! use volmorph_warp::jacobian::{FoldingReport, jacobian_determinant};
//!
//! let scale = Affine::linear(DMat3::from_diagonal(DVec3::new(2.0, 1.0, 0.5)));
//! let j = jacobian_determinant(&scale, &Geometry::new([4, 4, 4])).unwrap();
//! assert!(j.data().iter().all(|&d| d == 1.0));
//! let report = FoldingReport::of(j.data());
//! assert_eq!(report.count_nonpositive, 0);
//! ```

use std::fmt;

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_deform::SpaceMap;
use volmorph_volume::{Geometry, Volume, VolumeError};

use crate::WarpError;

/// Values per parallel task when summarising determinants.
const REPORT_CHUNK: usize = 1 << 16;

/// Target number of voxels per parallel slab (whole z-slices, at least one): 16 Ki Jacobians
/// are 1.1 MiB of `DMat3`, about a core's L2 cache.
const SLAB_POINTS: usize = 1 << 14;

/// The Jacobian determinant `det(map.jacobian(x))` at every voxel centre `x` of `grid`
/// (physical positions `grid.index_to_physical((i, j, k))`, x fastest), as `f32` on the same
/// geometry. Parallel over slabs of z-slices, each evaluated through the map's
/// [`SpaceMap::jacobian_grid`] on the slab's sub-grid (the separable table path for lattices
/// aligned with the grid, the map's own [`SpaceMap::jacobian`] pointwise otherwise: analytic
/// for lattices and affine maps, central differences for maps without a closed form). A
/// determinant outside the `f32` range becomes `±∞`; `J ≤ 0` marks folding (see the
/// [module docs](self)).
///
/// # Errors
/// [`WarpError::Geometry`] if `grid` is invalid or too large for an `f32` array within
/// the memory budget ([`volmorph_io::memory_limit`]); [`WarpError::Map`] if the map's grid evaluation fails.
pub fn jacobian_determinant<M: SpaceMap + ?Sized>(
    map: &M,
    grid: &Geometry,
) -> Result<Volume<f32>, WarpError> {
    jacobian_determinant_with(map, grid, &volmorph_io::NoProgress)
}

/// [`jacobian_determinant`] reporting to `progress`: one stage whose steps are the grid's
/// z-slices, advanced slab by slab, stopping between slabs when cancelled. The result
/// equals [`jacobian_determinant`]'s bit for bit.
///
/// # Errors
/// As [`jacobian_determinant`]; [`WarpError::Cancelled`] when `progress` asks to stop.
pub fn jacobian_determinant_with<M: SpaceMap + ?Sized>(
    map: &M,
    grid: &Geometry,
    progress: &dyn volmorph_io::Progress,
) -> Result<Volume<f32>, WarpError> {
    let geometry_error = |source: VolumeError| WarpError::Geometry {
        what: "Jacobian grid",
        source,
    };
    grid.validate().map_err(geometry_error)?;
    let len = volmorph_io::checked_len(&grid.dims, std::mem::size_of::<f32>())
        .map_err(|e| geometry_error(VolumeError::Io(e)))?;
    let mut data = vec![0.0f32; len];
    jacobian_determinant_into_with(map, grid, &mut data, progress)?;
    Volume::new(*grid, data).map_err(geometry_error)
}

/// [`jacobian_determinant`] into a caller-provided buffer (x fastest, one value per voxel of
/// `grid`).
///
/// # Errors
/// [`WarpError::Geometry`] if `grid` is invalid, [`WarpError::BufferLength`] if `out.len()` is
/// not `grid`'s voxel count, [`WarpError::Map`] if the map's grid evaluation fails.
pub fn jacobian_determinant_into<M: SpaceMap + ?Sized>(
    map: &M,
    grid: &Geometry,
    out: &mut [f32],
) -> Result<(), WarpError> {
    jacobian_determinant_into_with(map, grid, out, &volmorph_io::NoProgress)
}

/// [`jacobian_determinant_into`] reporting to `progress` as [`jacobian_determinant_with`]
/// does.
///
/// # Errors
/// As [`jacobian_determinant_into`]; [`WarpError::Cancelled`] when `progress` asks to stop.
pub fn jacobian_determinant_into_with<M: SpaceMap + ?Sized>(
    map: &M,
    grid: &Geometry,
    out: &mut [f32],
    progress: &dyn volmorph_io::Progress,
) -> Result<(), WarpError> {
    grid.validate().map_err(|source| WarpError::Geometry {
        what: "Jacobian grid",
        source,
    })?;
    if out.len() != grid.len() {
        return Err(WarpError::BufferLength {
            dims: grid.dims,
            expected: grid.len(),
            got: out.len(),
        });
    }
    if out.is_empty() {
        return Ok(());
    }
    let [nx, ny, nz] = grid.dims;
    let plane = nx * ny;
    let slab_nz = (SLAB_POINTS / plane).clamp(1, nz);
    progress.start(
        &format!("Jacobian determinants on {nx}×{ny}×{nz}"),
        nz as u64,
    );
    out.par_chunks_mut(plane * slab_nz)
        .enumerate()
        .try_for_each_init(
            Vec::new,
            |buf: &mut Vec<DMat3>, (s, chunk)| -> Result<(), WarpError> {
                progress.check()?;
                let slab = Geometry {
                    dims: [nx, ny, chunk.len() / plane],
                    origin: grid.index_to_physical(DVec3::new(0.0, 0.0, (s * slab_nz) as f64)),
                    ..*grid
                };
                // Grows once per task to the slab size; later slabs reuse it.
                buf.resize(chunk.len(), DMat3::ZERO);
                map.jacobian_grid(&slab, buf)?;
                for (o, m) in chunk.iter_mut().zip(buf.iter()) {
                    *o = m.determinant() as f32;
                }
                progress.advance((chunk.len() / plane) as u64);
                Ok(())
            },
        )?;
    Ok(progress.check()?)
}

/// Summary of a Jacobian determinant map: how much of it folds (`J ≤ 0`) and the range and mean
/// of the determinants.
///
/// Non-finite determinants (NaN, `±∞`) are counted in `count_nonfinite` and left out of every
/// other field; `fraction_nonpositive` is relative to all voxels. With no finite value, `min`,
/// `max` and `mean` are NaN.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FoldingReport {
    /// Number of determinants summarised (finite or not).
    pub count: usize,
    /// Number of finite determinants `J ≤ 0` (folded or collapsed voxels).
    pub count_nonpositive: usize,
    /// `count_nonpositive / count` (0 for an empty input).
    pub fraction_nonpositive: f64,
    /// Number of NaN or infinite determinants.
    pub count_nonfinite: usize,
    /// Smallest finite determinant.
    pub min: f64,
    /// Largest finite determinant.
    pub max: f64,
    /// Mean of the finite determinants.
    pub mean: f64,
}

/// Running totals of a [`FoldingReport`].
#[derive(Debug, Clone, Copy)]
struct Totals {
    count: usize,
    nonpositive: usize,
    nonfinite: usize,
    min: f64,
    max: f64,
    sum: f64,
}

impl Totals {
    const EMPTY: Self = Self {
        count: 0,
        nonpositive: 0,
        nonfinite: 0,
        min: f64::INFINITY,
        max: f64::NEG_INFINITY,
        sum: 0.0,
    };

    fn of(values: &[f32]) -> Self {
        let mut t = Self::EMPTY;
        t.count = values.len();
        for &v in values {
            let v = f64::from(v);
            if !v.is_finite() {
                t.nonfinite += 1;
                continue;
            }
            if v <= 0.0 {
                t.nonpositive += 1;
            }
            t.min = t.min.min(v);
            t.max = t.max.max(v);
            t.sum += v;
        }
        t
    }

    fn merge(a: Self, b: Self) -> Self {
        Self {
            count: a.count + b.count,
            nonpositive: a.nonpositive + b.nonpositive,
            nonfinite: a.nonfinite + b.nonfinite,
            min: a.min.min(b.min),
            max: a.max.max(b.max),
            sum: a.sum + b.sum,
        }
    }
}

impl FoldingReport {
    /// Summarise determinants (typically [`jacobian_determinant`]'s data), in parallel.
    #[must_use]
    pub fn of(determinants: &[f32]) -> Self {
        let t = determinants
            .par_chunks(REPORT_CHUNK)
            .map(Totals::of)
            .reduce(|| Totals::EMPTY, Totals::merge);
        let finite = t.count - t.nonfinite;
        let (min, max, mean) = if finite == 0 {
            (f64::NAN, f64::NAN, f64::NAN)
        } else {
            (t.min, t.max, t.sum / finite as f64)
        };
        Self {
            count: t.count,
            count_nonpositive: t.nonpositive,
            fraction_nonpositive: if t.count == 0 {
                0.0
            } else {
                t.nonpositive as f64 / t.count as f64
            },
            count_nonfinite: t.nonfinite,
            min,
            max,
            mean,
        }
    }

    /// Determinant map of `map` on `grid` and its summary in one call.
    ///
    /// # Errors
    /// As [`jacobian_determinant`].
    pub fn of_map<M: SpaceMap + ?Sized>(map: &M, grid: &Geometry) -> Result<Self, WarpError> {
        Ok(Self::of(jacobian_determinant(map, grid)?.data()))
    }

    /// Summary of `map` on an `n³` grid spanning the box `lo ..= hi` (axis-aligned; an axis
    /// along which the box is flat gets a tiny extent, so the grid stays valid), e.g. the
    /// bounding box of a mesh a map deforms.
    ///
    /// # Errors
    /// [`WarpError::InvalidOption`] for `n < 2` or a non-finite box; as [`jacobian_determinant`].
    pub fn over_box<M: SpaceMap + ?Sized>(
        map: &M,
        lo: glam::DVec3,
        hi: glam::DVec3,
        n: usize,
    ) -> Result<Self, WarpError> {
        if n < 2 || !(lo.is_finite() && hi.is_finite()) {
            return Err(WarpError::InvalidOption(format!(
                "a fold report needs at least 2 nodes per axis over a finite box (got {n} over \
                 {lo} ..= {hi})"
            )));
        }
        let ext = (hi - lo).max(glam::DVec3::splat(1e-9 * (hi - lo).max_element().max(1.0)));
        let g = Geometry::new([n; 3])
            .with_origin(lo)
            .with_spacing(ext / (n - 1) as f64);
        Self::of_map(map, &g)
    }

    /// `true` if any voxel folds (`J ≤ 0`) or has a non-finite determinant.
    #[must_use]
    pub fn folds(&self) -> bool {
        self.count_nonpositive > 0 || self.count_nonfinite > 0
    }
}

impl fmt::Display for FoldingReport {
    /// One line, e.g. `J: min 0.812, max 1.204, mean 1.000; 0 of 4096 voxels fold (J ≤ 0, 0.000%)`,
    /// followed by the count of non-finite determinants if there are any.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "J: min {:.3}, max {:.3}, mean {:.3}; {} of {} voxels fold (J ≤ 0, {:.3}%)",
            self.min,
            self.max,
            self.mean,
            self.count_nonpositive,
            self.count,
            100.0 * self.fraction_nonpositive
        )?;
        if self.count_nonfinite > 0 {
            write!(f, "; {} non-finite", self.count_nonfinite)?;
        }
        Ok(())
    }
}
