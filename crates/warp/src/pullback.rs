//! Pull-back resampling of a volume through a space map (ITK's resampling convention).
//!
//! # Direction
//!
//! For every voxel centre `x` of the **output** grid (physical position
//! `output.index_to_physical((i, j, k))`, chosen by the caller and free to differ from the
//! input's grid in dims, spacing, origin and direction), the output value is the input's
//! interpolated value at the physical point `map.apply(x)`:
//!
//! ```text
//! output(x) = input(map(x))
//! ```
//!
//! So a translation `p ↦ p + t` moves the *content* by `−t`: `output(x) = input(x + t)`. To
//! move a model forward by a map `f`, pass its inverse (or use push-forward).
//!
//! # Kernels and boundary
//!
//! Interpolation and the policy beyond the input's edge are those of
//! [`volmorph_volume::sample`]: [`Interpolation::Nearest`], [`Interpolation::Linear`] (the
//! default) or [`Interpolation::CubicBSpline`]; [`Boundary::Constant(c)`](Boundary::Constant)
//! (the default, `c = 0`, ITK's "default pixel value") gives `c` to output voxels whose mapped
//! point falls outside the input's sampled box `[−½, n − ½]³` in index space, or is not finite.
//! Values are converted to the output voxel type with [`Voxel::from_f64`] (integer types round
//! to nearest, saturate, and take 0 for NaN, e.g. under [`Boundary::Clamp`] with a non-finite
//! mapped point).
//!
//! # Voxel centres are copied exactly
//!
//! A map that reproduces voxel centres only up to rounding (an identity lattice, a
//! whole-voxel translation with a non-integer spacing) would otherwise leave a continuous
//! index like `3.000_000_000_000_4`, and trilinear interpolation would blend a trace of the
//! neighbour into the value. Continuous indices within [`INDEX_SNAP_TOL`] of an integer are
//! therefore snapped to it before sampling, so such maps copy voxel values bit for bit. The
//! change this makes to any sample is at most `INDEX_SNAP_TOL` times the largest difference
//! between neighbouring values.
//!
//! # How it runs
//!
//! The output is cut into tiles of at most [`TILE`] voxels (x, y, z); bands of tiles (one
//! tile high and deep, the whole width) are processed in parallel (rayon). For each tile the
//! map is evaluated on the tile's voxel centres through [`SpaceMap::apply_grid`] on a
//! sub-geometry of the output grid (same spacing and direction, origin at the tile's first
//! voxel), so lattices use their separable fast path. The mapped points go to a per-task
//! buffer reused from tile to tile; each is turned in place into an input index with one
//! precomputed affine map (no matrix inverse per voxel; four points at a time where the CPU
//! has AVX2, same bits), and each row of the tile is sampled on the same thread with
//! [`Sampler::sample_index_serial`] (interior points straight from the typed voxels) into
//! its place in the output. A compact tile reads a compact region of the input, so the
//! sampling stays in cache. Nothing is allocated per voxel.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_deform::Affine;
//! use volmorph_volume::{Geometry, Volume};
//! use volmorph_warp::pullback::{ResampleOptions, resample};
//!
//! // f(i, j, k) = i + 10 j + 100 k on a 4×4×4 grid.
//! let g = Geometry::new([4, 4, 4]);
//! let input = Volume::from_fn(g, |i, j, k| (i + 10 * j + 100 * k) as f32).unwrap();
//! // Pull-back through p ↦ p + (1, 0, 0): output(x) = input(x + 1 along x).
//! let map = Affine::translation(DVec3::X);
//! let out: Volume<f32> = resample(&input, &map, &g, &ResampleOptions::default()).unwrap();
//! assert_eq!(out[[0, 2, 3]], input[[1, 2, 3]]);
//! assert_eq!(out[[3, 2, 3]], 0.0); // x + 1 = 4 lies outside the input: default value
//! ```

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_deform::SpaceMap;
use volmorph_volume::sample::{Boundary, Interpolation, Sampler};
use volmorph_volume::{AnyVolume, AnyVolumeRef, Geometry, Volume, VolumeError, Voxel, VoxelType};

use crate::WarpError;

#[cfg(target_arch = "x86_64")]
mod index_x4;

/// Continuous indices within this distance (in voxels) of an integer are snapped to it before
/// sampling. Maps that reproduce voxel centres analytically do so up to a few ulps of the
/// physical coordinates (≈1e-13 voxels for grids of thousands of voxels); 1e-9 voxels is far
/// above that and far below any offset an interpolation kernel could meaningfully resolve in
/// `f32` data (relative precision 6e-8).
pub const INDEX_SNAP_TOL: f64 = 1e-9;

/// Output tile (voxels along x, y, z) on which the map is evaluated and then sampled. A compact
/// tile reads a compact region of the input, so the sampling stays in cache; 8 Ki mapped
/// points are 192 KiB of `DVec3`, which stays in a core's L2 cache between the two passes,
/// and are enough that a lattice's per-call setup (its basis tables) is a small cost.
pub const TILE: [usize; 3] = [64, 16, 8];

/// How [`resample`] interpolates the input and what it returns beyond the input's edge.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ResampleOptions {
    /// Interpolation kernel of the input (default [`Interpolation::Linear`]).
    pub interpolation: Interpolation,
    /// Boundary policy of the input (default [`Boundary::Constant(0.0)`](Boundary::Constant):
    /// output voxels whose mapped point lies outside the input get `0`).
    pub boundary: Boundary,
}

impl ResampleOptions {
    /// Options with the given kernel and [`Boundary::Constant(default_value)`](Boundary::Constant).
    #[must_use]
    pub fn new(interpolation: Interpolation, default_value: f64) -> Self {
        Self {
            interpolation,
            boundary: Boundary::Constant(default_value),
        }
    }

    /// Same options with another interpolation kernel.
    #[must_use]
    pub fn with_interpolation(mut self, interpolation: Interpolation) -> Self {
        self.interpolation = interpolation;
        self
    }

    /// Same options with another boundary policy.
    #[must_use]
    pub fn with_boundary(mut self, boundary: Boundary) -> Self {
        self.boundary = boundary;
        self
    }
}

/// Pull-back resampling: a new volume on the grid `output` whose voxel at physical position
/// `x` holds `input`'s interpolated value at `map.apply(x)` (see the
/// [module docs](self) for the direction, snapping and boundary conventions). The output
/// voxel type `U` may differ from the input's `T`; values convert with [`Voxel::from_f64`].
///
/// # Errors
/// [`WarpError::Geometry`] if `output` is invalid or its voxel count times the size of `U`
/// exceeds the memory budget ([`volmorph_io::memory_limit`]); [`WarpError::Map`] if the map's grid evaluation
/// fails; [`WarpError::Volume`] if the sampler cannot be built (cubic coefficient array over
/// the allocation limit).
pub fn resample<T: Voxel, U: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &ResampleOptions,
) -> Result<Volume<U>, WarpError> {
    resample_with(input, map, output, options, &volmorph_io::NoProgress)
}

/// [`resample`] reporting to `progress`: one stage whose steps are the output's rows
/// (`ny · nz`), advanced band by band, and stopping between bands when cancelled. The
/// result equals [`resample`]'s bit for bit.
///
/// # Errors
/// As [`resample`]; [`WarpError::Cancelled`] when `progress` asks to stop (no volume is
/// returned).
pub fn resample_with<T: Voxel, U: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &ResampleOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<Volume<U>, WarpError> {
    let len = checked_output_len::<U>(output)?;
    let mut data = vec![U::default(); len];
    resample_into_with(input, map, output, options, &mut data, progress)?;
    Volume::new(*output, data).map_err(|source| WarpError::Geometry {
        what: "output grid",
        source,
    })
}

/// [`resample`] into a caller-provided buffer (x fastest, one value per voxel of `output`),
/// for loops that resample repeatedly into the same storage.
///
/// # Errors
/// [`WarpError::Geometry`] if `output` is invalid, [`WarpError::BufferLength`] if
/// `out.len()` is not `output`'s voxel count, and the errors of [`resample`].
pub fn resample_into<T: Voxel, U: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &ResampleOptions,
    out: &mut [U],
) -> Result<(), WarpError> {
    resample_into_with(input, map, output, options, out, &volmorph_io::NoProgress)
}

/// [`resample_into`] reporting to `progress` as [`resample_with`] does. When cancelled,
/// `out` holds an unspecified mix of old and new values.
///
/// # Errors
/// As [`resample_into`]; [`WarpError::Cancelled`] when `progress` asks to stop.
pub fn resample_into_with<T: Voxel, U: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &ResampleOptions,
    out: &mut [U],
    progress: &dyn volmorph_io::Progress,
) -> Result<(), WarpError> {
    output.validate().map_err(|source| WarpError::Geometry {
        what: "output grid",
        source,
    })?;
    if out.len() != output.len() {
        return Err(WarpError::BufferLength {
            dims: output.dims,
            expected: output.len(),
            got: out.len(),
        });
    }
    let sampler = Sampler::new(input, options.interpolation, options.boundary)?;
    let to_index = IndexMap::new(input.geometry());

    // One parallel task per band of `TILE[1]` rows × `TILE[2]` slices: the band's piece of
    // each slice is contiguous in `out`, and the band is processed tile by tile along x.
    let [nx, ny, nz] = output.dims;
    progress.start(
        &format!("pull-back resampling onto {nx}×{ny}×{nz}"),
        (ny * nz) as u64,
    );
    let [tx, ty, tz] = [TILE[0].min(nx), TILE[1].min(ny), TILE[2].min(nz)];
    let mut bands: Vec<Band<'_, U>> = Vec::with_capacity(ny.div_ceil(ty) * nz.div_ceil(tz));
    for (s, slab) in out.chunks_mut(nx * ny * tz).enumerate() {
        let first = bands.len();
        for (b, _) in (0..ny).step_by(ty).enumerate() {
            bands.push(Band {
                start: [b * ty, s * tz],
                rows: ty.min(ny - b * ty),
                slices: Vec::with_capacity(tz),
            });
        }
        for slice in slab.chunks_mut(nx * ny) {
            for (band, piece) in bands[first..].iter_mut().zip(slice.chunks_mut(ty * nx)) {
                band.slices.push(piece);
            }
        }
    }
    bands.into_par_iter().try_for_each_init(
        || Vec::with_capacity(tx * ty * tz),
        |points, band| -> Result<(), WarpError> {
            progress.check()?;
            let rows = (band.rows * band.slices.len()) as u64;
            pull_band(&sampler, &to_index, map, output, tx, band, points)?;
            progress.advance(rows);
            Ok(())
        },
    )?;
    Ok(progress.check()?)
}

/// Rows `start[0] .. start[0] + rows` of slices `start[1] ..` of the output: one piece of
/// `rows · nx` voxels per slice (x fastest).
struct Band<'a, U> {
    start: [usize; 2],
    rows: usize,
    slices: Vec<&'a mut [U]>,
}

/// Resample one band of the output, tile by tile along x (tiles `tx` voxels wide): the map
/// is evaluated on the tile's sub-grid into `points` (reused from tile to tile and band to
/// band), turned into input indices in place, and each row of the tile is sampled straight
/// into its place in the band.
fn pull_band<M: SpaceMap + ?Sized, U: Voxel>(
    sampler: &Sampler<'_>,
    to_index: &IndexMap,
    map: &M,
    output: &Geometry,
    tx: usize,
    mut band: Band<'_, U>,
    points: &mut Vec<DVec3>,
) -> Result<(), WarpError> {
    let nx = output.dims[0];
    let (rows, depth) = (band.rows, band.slices.len());
    for x0 in (0..nx).step_by(tx) {
        let w = tx.min(nx - x0);
        let tile = Geometry {
            dims: [w, rows, depth],
            origin: output.index_to_physical(DVec3::new(
                x0 as f64,
                band.start[0] as f64,
                band.start[1] as f64,
            )),
            ..*output
        };
        points.resize(w * rows * depth, DVec3::ZERO);
        map.apply_grid(&tile, points)?;
        to_index.apply_all(points);
        for (piece, tile_rows) in band.slices.iter_mut().zip(points.chunks_exact(w * rows)) {
            for (row, src) in piece.chunks_exact_mut(nx).zip(tile_rows.chunks_exact(w)) {
                sampler.sample_index_serial(src, &mut row[x0..x0 + w])?;
            }
        }
    }
    Ok(())
}

/// Pull-back resampling of a volume whose voxel type is known at run time; the output keeps
/// the input's voxel type. See [`resample`].
///
/// # Errors
/// As [`resample`].
pub fn resample_any(
    input: &AnyVolume,
    map: &dyn SpaceMap,
    output: &Geometry,
    options: &ResampleOptions,
) -> Result<AnyVolume, WarpError> {
    resample_any_to(input, map, output, options, input.voxel_type())
}

/// [`resample_any`] reporting to `progress` as [`resample_with`] does.
///
/// # Errors
/// As [`resample_with`].
pub fn resample_any_with<'a>(
    input: impl Into<AnyVolumeRef<'a>>,
    map: &dyn SpaceMap,
    output: &Geometry,
    options: &ResampleOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<AnyVolume, WarpError> {
    let input = input.into();
    resample_dyn(input, map, output, options, input.voxel_type(), progress)
}

/// Pull-back resampling of a run-time-typed volume into voxel type `to` (values convert with
/// [`Voxel::from_f64`]: integer types round, saturate and take 0 for NaN). See [`resample`].
///
/// # Errors
/// As [`resample`].
pub fn resample_any_to(
    input: &AnyVolume,
    map: &dyn SpaceMap,
    output: &Geometry,
    options: &ResampleOptions,
    to: VoxelType,
) -> Result<AnyVolume, WarpError> {
    resample_any_to_with(input, map, output, options, to, &volmorph_io::NoProgress)
}

/// [`resample_any_to`] reporting to `progress` as [`resample_with`] does.
///
/// # Errors
/// As [`resample_with`].
pub fn resample_any_to_with<'a>(
    input: impl Into<AnyVolumeRef<'a>>,
    map: &dyn SpaceMap,
    output: &Geometry,
    options: &ResampleOptions,
    to: VoxelType,
    progress: &dyn volmorph_io::Progress,
) -> Result<AnyVolume, WarpError> {
    resample_dyn(input.into(), map, output, options, to, progress)
}

/// The body of the run-time-typed pull-backs, not generic so that its voxel-type pairs are
/// compiled once, in this crate, rather than in every crate that calls them.
fn resample_dyn(
    input: AnyVolumeRef<'_>,
    map: &dyn SpaceMap,
    output: &Geometry,
    options: &ResampleOptions,
    to: VoxelType,
    progress: &dyn volmorph_io::Progress,
) -> Result<AnyVolume, WarpError> {
    volmorph_volume::with_voxel_type!(to, U => volmorph_volume::with_volume_ref!(input, v => {
        resample_with::<_, U, dyn SpaceMap>(&v, map, output, options, progress).map(AnyVolume::from)
    }))
}

/// Voxel count of `output` after checking the geometry and the byte size of a `U` array.
pub(crate) fn checked_output_len<U: Voxel>(output: &Geometry) -> Result<usize, WarpError> {
    let geometry_error = |source: VolumeError| WarpError::Geometry {
        what: "output grid",
        source,
    };
    output.validate().map_err(geometry_error)?;
    volmorph_io::checked_len(&output.dims, std::mem::size_of::<U>())
        .map_err(|e| geometry_error(VolumeError::Io(e)))
}

/// Physical point → continuous index of the input, `(direction·diag(spacing))⁻¹·(p − origin)`
/// with the inverse computed once, followed by snapping to voxel centres.
#[derive(Debug, Clone, Copy)]
pub(crate) struct IndexMap {
    matrix: DMat3,
    origin: DVec3,
}

impl IndexMap {
    pub(crate) fn new(geometry: &Geometry) -> Self {
        Self {
            matrix: geometry.index_to_physical_matrix().inverse(),
            origin: geometry.origin,
        }
    }

    #[inline(always)]
    pub(crate) fn apply(&self, p: DVec3) -> DVec3 {
        let c = self.matrix * (p - self.origin);
        DVec3::new(snap(c.x), snap(c.y), snap(c.z))
    }

    /// [`IndexMap::apply`] to every point in place: four points at a time where the CPU
    /// has AVX2 (`index_x4`, the same bits), one by one otherwise.
    pub(crate) fn apply_all(&self, points: &mut [DVec3]) {
        #[cfg(target_arch = "x86_64")]
        if index_x4::apply_all(self, points) {
            return;
        }
        for p in points.iter_mut() {
            *p = self.apply(*p);
        }
    }
}

/// `1.5·2⁵²`: adding and subtracting it rounds an `f64` of magnitude below `2⁵¹` to the
/// nearest integer in two additions (round-to-nearest mode), where `f64::round` is a library
/// call on baseline x86-64.
const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;

/// Magnitude below which [`ROUND_MAGIC`] rounding is exact (`2⁵¹`); larger values are already
/// integers or far outside any volume.
const ROUND_MAGIC_LIMIT: f64 = 2_251_799_813_685_248.0;

/// `x` rounded to the nearest integer if within [`INDEX_SNAP_TOL`] of it (NaN, ±∞ and
/// magnitudes of `2⁵¹` and more pass through unchanged).
#[inline(always)]
fn snap(x: f64) -> f64 {
    if x.abs() >= ROUND_MAGIC_LIMIT || x.is_nan() {
        return x;
    }
    let r = (x + ROUND_MAGIC) - ROUND_MAGIC;
    if (x - r).abs() <= INDEX_SNAP_TOL {
        r
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snap_rounds_only_near_integers() {
        assert_eq!(snap(3.000_000_000_000_4), 3.0);
        assert_eq!(snap(-2.000_000_000_1), -2.0);
        assert_eq!(snap(3.25), 3.25);
        assert_eq!(snap(3.000_001), 3.000_001);
        assert!(snap(f64::NAN).is_nan());
        assert_eq!(snap(f64::INFINITY), f64::INFINITY);
        assert_eq!(snap(-0.499_999), -0.499_999);
        assert_eq!(snap(1e300), 1e300);
        assert_eq!(snap(-1e-12), 0.0);
        for n in [-1_000_000.0, -3.0, 0.0, 7.0, 123_456_789.0] {
            assert_eq!(snap(n + 1e-10), n);
            assert_eq!(snap(n - 1e-10), n);
            assert_eq!(snap(n + 0.5), n + 0.5);
        }
    }

    #[test]
    fn index_map_inverts_geometry() {
        let g = Geometry::new([5, 6, 7])
            .with_spacing(DVec3::new(0.7, 1.3, 2.1))
            .with_origin(DVec3::new(-4.0, 2.5, 10.0))
            .with_direction(DMat3::from_rotation_y(0.4));
        let m = IndexMap::new(&g);
        for idx in [DVec3::new(1.0, 2.0, 3.0), DVec3::new(0.25, 4.5, 6.75)] {
            let back = m.apply(g.index_to_physical(idx));
            assert!((back - idx).length() < 1e-12, "{back:?} vs {idx:?}");
        }
        // Integer indices come back exactly.
        assert_eq!(
            m.apply(g.index_to_physical(DVec3::new(4.0, 5.0, 6.0))),
            DVec3::new(4.0, 5.0, 6.0)
        );
    }
}
