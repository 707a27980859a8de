//! Interpolation of a volume at continuous indices and at physical points.
//!
//! A [`Sampler`] is built once from a [`Volume`] (any voxel type) and then answers point
//! queries without allocating: [`Sampler::sample_index`] at a continuous index `(i, j, k)`,
//! [`Sampler::sample_physical`] at a physical point (through the volume's [`Geometry`]), and
//! the parallel batch forms [`Sampler::sample_index_batch`] / [`Sampler::sample_physical_batch`]
//! that fill an output slice of any voxel type, and [`Sampler::sample_index_serial`] for
//! callers that parallelise themselves.
//!
//! The single queries are the reference: they run the general boundary code below for every
//! point. The batch forms dispatch on the voxel type once per call and run one monomorphised
//! loop per kernel in which a point whose whole stencil lies inside the volume (one bounds
//! test) is interpolated directly from the typed voxels; only points near or beyond the edge
//! take the general code. Both give the same bits.
//!
//! # Kernels ([`Interpolation`])
//!
//! * `Nearest` — the value of the voxel whose centre is nearest; half-way cases round **up**
//!   (towards +∞ along each axis), i.e. voxel `⌊x + ½⌋`, as ITK's nearest-neighbour function.
//! * `Linear` — trilinear interpolation between the eight surrounding voxel centres.
//! * `CubicBSpline` — cubic B-spline *interpolation*: the data are first turned into B-spline
//!   coefficients by Unser's recursive prefilter (pole `z = √3 − 2`), so the spline passes
//!   through every voxel value and is C² everywhere. The prefilter runs once, when the sampler
//!   is built, separably along i, j then k and in parallel (rayon); it extends each line by
//!   whole-sample mirror symmetry (`… s₂ s₁ | s₀ s₁ … s_{n−1} | s_{n−2} …`), as in Unser's
//!   paper and ITK, with the exact initial value for lines of up to 28 samples and a sum
//!   truncated at `|z|²⁸ < 2.2·10⁻¹⁶` for longer ones.
//!
//! **Coefficient precision.** Coefficients are stored as `f64` for `f64` volumes and as `f32`
//! for every other voxel type (half the memory and bandwidth; a 512³ volume needs 512 MiB).
//! All filter arithmetic is done in `f64` and the recursive state is carried in `f64`, so each
//! stored coefficient is rounded once per filter pass: the spline reproduces an `f32`-stored
//! volume's voxel values to about 10⁻⁶ of the data's magnitude. Evaluation accumulates in `f64`.
//!
//! # Sampled domain and boundary ([`Boundary`])
//!
//! Each voxel is the unit cell centred on its index, so the volume covers the continuous
//! index box `[−½, n − ½]` along each axis (closed at both ends), and the voxel centres span
//! `[0, n − 1]`. What a query returns depends on the boundary policy:
//!
//! * [`Boundary::Constant(c)`](Boundary::Constant) — a point outside the box `[−½, n − ½]³`
//!   (or with a NaN coordinate) returns `c` (ITK's "default pixel value"). Inside the box, a
//!   coordinate in the half-voxel border `[−½, 0)` or `(n − 1, n − ½]` is clamped to the
//!   nearest voxel centre plane first, so the border repeats the edge values (constant
//!   extrapolation over half a voxel, as ITK's linear function does).
//! * [`Boundary::Clamp`] — every point is inside: each coordinate is clamped to `[0, n − 1]`,
//!   so a point outside takes the value at the nearest point of the box of voxel centres
//!   (`±∞` clamp to the edge; NaN gives NaN).
//! * [`Boundary::Mirror`] — the volume is extended by whole-sample mirror symmetry about the
//!   first and last voxel centres (period `2(n − 1)`): each coordinate is reflected into
//!   `[0, n − 1]` first (the kernels, including the nearest-neighbour tie rule, then apply to
//!   the reflected coordinate). This is the extension the B-spline prefilter assumes, so for
//!   the cubic kernel the mirrored spline is one smooth function. Non-finite coordinates give
//!   NaN.
//!
//! Under every policy, a cubic query near the edge of `[0, n − 1]` reads its out-of-range
//! neighbour coefficients from the same mirror extension the prefilter used, so the spline
//! still interpolates the edge voxels exactly.
//!
//! Along an axis with a single voxel every coordinate inside the domain maps to index 0.
//!
//! # Costs (per sample, after construction)
//!
//! | kernel | reads | construction |
//! | --- | --- | --- |
//! | `Nearest` | 1 | none (borrows the voxels) |
//! | `Linear` | 8 | none (borrows the voxels) |
//! | `CubicBSpline` | 64 | one O(N) prefilter (6 sweeps), 4 (or 8) bytes per voxel |
//!
//! A physical query adds one 3×3 matrix–vector product.

use std::fmt;

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::{AnyVolume, Geometry, Volume, VolumeError, Voxel, VoxelType};

/// Pole of the cubic B-spline interpolation prefilter, `z = √3 − 2` (Unser 1993).
pub const CUBIC_BSPLINE_POLE: f64 = -0.267_949_192_431_122_7;

/// Gain of the cubic B-spline prefilter, `(1 − z)(1 − 1/z) = 6`.
const GAIN: f64 = 6.0;

/// Number of terms of the truncated causal initial sum: `|z|²⁸ ≈ 9.7·10⁻¹⁷ < f64::EPSILON`.
/// Lines of at most this many samples use Unser's exact mirror-boundary initial value.
const HORIZON: usize = 28;

/// Points per parallel task in the batch entry points.
const BATCH_CHUNK: usize = 4096;

#[cfg(target_arch = "x86_64")]
mod linear_x4;

/// Which loop samples a batch of continuous indices: the trilinear kernel four points at a
/// time where the CPU allows it (`Vector`), or the portable loop (`Portable`, what every
/// other kernel and CPU runs). Both give the same bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum KernelPath {
    /// The vector kernel when it applies, the portable loop otherwise.
    Vector,
    /// The portable loop only.
    #[cfg_attr(
        not(test),
        allow(dead_code, reason = "the tests force the portable loop")
    )]
    Portable,
}

/// The interpolation kernel of a [`Sampler`].
///
/// Costs are per sample; see the [module documentation](self) for the exact conventions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Interpolation {
    /// Value of the nearest voxel (ties round towards +∞: voxel `⌊x + ½⌋`). One read; no
    /// preprocessing. Piecewise constant.
    Nearest,
    /// Trilinear interpolation of the eight surrounding voxels. Eight reads; no preprocessing.
    /// Continuous, reproduces affine functions exactly between voxel centres.
    #[default]
    Linear,
    /// Interpolating cubic B-spline (prefiltered once at construction). 64 reads per sample;
    /// construction costs six O(N) sweeps and a coefficient array of 4 bytes per voxel
    /// (8 for `f64` volumes). C², reproduces the data at voxel centres and cubic polynomials
    /// away from the boundary.
    CubicBSpline,
}

/// What a [`Sampler`] returns near and beyond the edge of the volume.
///
/// The sampled domain is the continuous index box `[−½, n − ½]` along each axis; see the
/// [module documentation](self) for the precise rules.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Boundary {
    /// Points outside `[−½, n − ½]³` (or with a NaN coordinate) take this value; the half-voxel
    /// border inside it repeats the edge voxels.
    Constant(f64),
    /// Coordinates are clamped to `[0, n − 1]`: the nearest edge value continues forever.
    Clamp,
    /// Coordinates are reflected about the first and last voxel centres (period `2(n − 1)`),
    /// the extension assumed by the B-spline prefilter.
    Mirror,
}

impl Default for Boundary {
    /// `Constant(0.0)`, ITK's default.
    fn default() -> Self {
        Self::Constant(0.0)
    }
}

/// The values a sampler reads: the volume's own voxels (nearest, linear) or the B-spline
/// coefficients it computed (cubic).
enum Values<'a> {
    U8(&'a [u8]),
    I8(&'a [i8]),
    U16(&'a [u16]),
    I16(&'a [i16]),
    U32(&'a [u32]),
    I32(&'a [i32]),
    F32(&'a [f32]),
    F64(&'a [f64]),
    Coef32(Vec<f32>),
    Coef64(Vec<f64>),
}

/// Run `$body` with `$d` bound to the typed value slice of a [`Values`].
macro_rules! dispatch {
    ($values:expr, $d:ident => $body:expr) => {
        match $values {
            Values::U8($d) => $body,
            Values::I8($d) => $body,
            Values::U16($d) => $body,
            Values::I16($d) => $body,
            Values::U32($d) => $body,
            Values::I32($d) => $body,
            Values::F32($d) => $body,
            Values::F64($d) => $body,
            Values::Coef32($d) => $body,
            Values::Coef64($d) => $body,
        }
    };
}

impl Values<'_> {
    fn voxel_type(&self) -> VoxelType {
        match self {
            Values::U8(_) => VoxelType::U8,
            Values::I8(_) => VoxelType::I8,
            Values::U16(_) => VoxelType::U16,
            Values::I16(_) => VoxelType::I16,
            Values::U32(_) => VoxelType::U32,
            Values::I32(_) => VoxelType::I32,
            Values::F32(_) | Values::Coef32(_) => VoxelType::F32,
            Values::F64(_) | Values::Coef64(_) => VoxelType::F64,
        }
    }
}

/// Reinterpret `data` as a slice of the concrete type its [`Voxel::TYPE`] names.
fn borrow_values<T: Voxel>(data: &[T]) -> Result<Values<'_>, VolumeError> {
    fn cast<T: Voxel, U: bytemuck::Pod>(data: &[T]) -> Result<&[U], VolumeError> {
        bytemuck::try_cast_slice(data).map_err(|e| {
            VolumeError::Unsupported(format!(
                "voxel type {} does not have the layout of {}: {e}",
                std::any::type_name::<T>(),
                T::TYPE
            ))
        })
    }
    Ok(match T::TYPE {
        VoxelType::U8 => Values::U8(cast(data)?),
        VoxelType::I8 => Values::I8(cast(data)?),
        VoxelType::U16 => Values::U16(cast(data)?),
        VoxelType::I16 => Values::I16(cast(data)?),
        VoxelType::U32 => Values::U32(cast(data)?),
        VoxelType::I32 => Values::I32(cast(data)?),
        VoxelType::F32 => Values::F32(cast(data)?),
        VoxelType::F64 => Values::F64(cast(data)?),
    })
}

/// Interpolates one volume at continuous indices or physical points.
///
/// Built once ([`Sampler::new`]) and then queried any number of times, from any number of
/// threads (`Sampler: Sync`); queries never allocate. Nearest and linear samplers borrow the
/// volume's voxels; a cubic B-spline sampler owns its coefficient array and does not read the
/// volume after construction (the borrow is kept for a uniform type).
///
/// Values are returned as `f64`. See the [module documentation](self) for the kernels, the
/// sampled domain and the boundary policies.
pub struct Sampler<'a> {
    values: Values<'a>,
    geometry: Geometry,
    interpolation: Interpolation,
    boundary: Boundary,
    /// `(direction · diag(spacing))⁻¹`: physical offsets from the origin to index offsets.
    index_from_physical: DMat3,
}

impl fmt::Debug for Sampler<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Sampler")
            .field("dims", &self.geometry.dims)
            .field("values", &self.values.voxel_type())
            .field("interpolation", &self.interpolation)
            .field("boundary", &self.boundary)
            .finish_non_exhaustive()
    }
}

impl<'a> Sampler<'a> {
    /// Build a sampler for `volume`. For [`Interpolation::CubicBSpline`] this computes the
    /// B-spline coefficients (in parallel); the other kernels only borrow the voxels.
    ///
    /// # Errors
    /// [`VolumeError::Io`] if the coefficient array would exceed
    /// the memory budget ([`volmorph_io::memory_limit`]); [`VolumeError::Unsupported`] if a foreign [`Voxel`]
    /// implementation does not have the memory layout of the type its `TYPE` names.
    pub fn new<T: Voxel, D: AsRef<[T]>>(
        volume: &'a Volume<T, D>,
        interpolation: Interpolation,
        boundary: Boundary,
    ) -> Result<Self, VolumeError> {
        let geometry = *volume.geometry();
        let values = match interpolation {
            Interpolation::Nearest | Interpolation::Linear => borrow_values(volume.data())?,
            Interpolation::CubicBSpline => {
                if T::TYPE == VoxelType::F64 {
                    Values::Coef64(bspline_coefficients(volume)?)
                } else {
                    Values::Coef32(bspline_coefficients(volume)?)
                }
            }
        };
        let index_from_physical = geometry.index_to_physical_matrix().inverse();
        Ok(Self {
            values,
            geometry,
            interpolation,
            boundary,
            index_from_physical,
        })
    }

    /// Build a sampler for a volume whose voxel type is known at run time.
    ///
    /// # Errors
    /// As [`Sampler::new`].
    pub fn from_any(
        volume: &'a AnyVolume,
        interpolation: Interpolation,
        boundary: Boundary,
    ) -> Result<Self, VolumeError> {
        crate::with_volume!(volume, v => Sampler::new(v, interpolation, boundary))
    }

    /// Geometry of the sampled volume.
    #[must_use]
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// The interpolation kernel.
    #[must_use]
    pub fn interpolation(&self) -> Interpolation {
        self.interpolation
    }

    /// The boundary policy.
    #[must_use]
    pub fn boundary(&self) -> Boundary {
        self.boundary
    }

    /// Continuous index of physical point `p`, with the inverse index-to-physical matrix
    /// computed at construction (agrees with [`Geometry::physical_to_index`] up to rounding).
    #[inline]
    #[must_use]
    pub fn physical_to_index(&self, p: DVec3) -> DVec3 {
        self.index_from_physical * (p - self.geometry.origin)
    }

    /// Interpolated value at continuous index `index = (i, j, k)` (voxel centres at integers).
    #[inline]
    #[must_use]
    pub fn sample_index(&self, index: DVec3) -> f64 {
        dispatch!(&self.values, d => self.eval(d, index))
    }

    /// Interpolated value at physical point `p` (the value at index
    /// [`Sampler::physical_to_index`]`(p)`).
    #[inline]
    #[must_use]
    pub fn sample_physical(&self, p: DVec3) -> f64 {
        self.sample_index(self.physical_to_index(p))
    }

    /// Sample at every continuous index of `indices`, writing `out[n]` for `indices[n]`, in
    /// parallel. Values are converted with [`Voxel::from_f64`] (integer outputs round,
    /// saturate and map NaN to 0).
    ///
    /// # Errors
    /// [`VolumeError::InvalidArgument`] if `out` does not
    /// have one slot per index.
    pub fn sample_index_batch<O: Voxel>(
        &self,
        indices: &[DVec3],
        out: &mut [O],
    ) -> Result<(), VolumeError> {
        check_batch(indices.len(), out.len())?;
        dispatch!(&self.values, d => {
            out.par_chunks_mut(BATCH_CHUNK)
                .zip(indices.par_chunks(BATCH_CHUNK))
                .for_each(|(o, p)| self.run_index(d, p, o, KernelPath::Vector));
        });
        Ok(())
    }

    /// Sample at every continuous index of `indices`, writing `out[n]` for `indices[n]`, on
    /// the calling thread: the form for callers that already run in parallel (one call per
    /// row or slab of their own work). Values agree bit for bit with
    /// [`Sampler::sample_index`] and are converted with [`Voxel::from_f64`].
    ///
    /// The voxel type is dispatched once per call and each kernel runs a monomorphised loop
    /// with an interior fast path: a point whose whole stencil lies inside the volume (one
    /// bounds test per point) is interpolated directly from the typed voxels; only points
    /// near or beyond the edge take the general boundary code. On x86-64 CPUs with AVX2 the
    /// trilinear kernel runs four points at a time (`f64×4`, the same operations in the same
    /// order, so the same bits).
    ///
    /// # Errors
    /// [`VolumeError::InvalidArgument`] if `out` does not have one slot per index.
    pub fn sample_index_serial<O: Voxel>(
        &self,
        indices: &[DVec3],
        out: &mut [O],
    ) -> Result<(), VolumeError> {
        self.sample_index_serial_by(indices, out, KernelPath::Vector)
    }

    /// [`Sampler::sample_index_serial`] by the given path (the tests force the portable one).
    pub(crate) fn sample_index_serial_by<O: Voxel>(
        &self,
        indices: &[DVec3],
        out: &mut [O],
        path: KernelPath,
    ) -> Result<(), VolumeError> {
        check_batch(indices.len(), out.len())?;
        dispatch!(&self.values, d => self.run_index(d, indices, out, path));
        Ok(())
    }

    /// Sample at every physical point of `points`, writing `out[n]` for `points[n]`, in
    /// parallel. Values are converted with [`Voxel::from_f64`].
    ///
    /// # Errors
    /// [`VolumeError::InvalidArgument`] if `out` does not
    /// have one slot per point.
    pub fn sample_physical_batch<O: Voxel>(
        &self,
        points: &[DVec3],
        out: &mut [O],
    ) -> Result<(), VolumeError> {
        check_batch(points.len(), out.len())?;
        dispatch!(&self.values, d => self.batch(d, points, out, |p| self.physical_to_index(p)));
        Ok(())
    }

    fn batch<V: Voxel, O: Voxel>(
        &self,
        d: &[V],
        points: &[DVec3],
        out: &mut [O],
        to_index: impl Fn(DVec3) -> DVec3 + Sync,
    ) {
        out.par_chunks_mut(BATCH_CHUNK)
            .zip(points.par_chunks(BATCH_CHUNK))
            .for_each(|(o, p)| self.run(d, p, o, &to_index));
    }

    /// Sample continuous indices into `out` on the calling thread: the trilinear kernel four
    /// points at a time when `path` allows it and the CPU has AVX2 ([`linear_x4`]), otherwise
    /// [`Sampler::run`]. Both give the same bits.
    fn run_index<V: Voxel, O: Voxel>(
        &self,
        d: &[V],
        indices: &[DVec3],
        out: &mut [O],
        path: KernelPath,
    ) {
        #[cfg(target_arch = "x86_64")]
        if path == KernelPath::Vector
            && self.interpolation == Interpolation::Linear
            && linear_x4::run(self, d, indices, out)
        {
            return;
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = path;
        self.run(d, indices, out, |x| x);
    }

    /// Sample `points` (turned into continuous indices by `to_index`) into `out` on the
    /// calling thread, with the kernel chosen once for the whole slice.
    fn run<V: Voxel, O: Voxel>(
        &self,
        d: &[V],
        points: &[DVec3],
        out: &mut [O],
        to_index: impl Fn(DVec3) -> DVec3,
    ) {
        match self.interpolation {
            Interpolation::Nearest => {
                self.run_kernel::<NearestKernel, _, _>(d, points, out, to_index)
            }
            Interpolation::Linear => {
                self.run_kernel::<LinearKernel, _, _>(d, points, out, to_index)
            }
            Interpolation::CubicBSpline => {
                self.run_kernel::<CubicKernel, _, _>(d, points, out, to_index);
            }
        }
    }

    /// The loop of one kernel: points whose stencil lies inside the volume (the kernel's
    /// interior box, one test per point; NaN fails it) are evaluated by the kernel's direct
    /// formula, all others by the general boundary code of [`Sampler::eval`]. Both give the
    /// same bits for interior points (same index arithmetic, same floating-point operations
    /// in the same order).
    #[inline]
    fn run_kernel<K: InteriorKernel, V: Voxel, O: Voxel>(
        &self,
        d: &[V],
        points: &[DVec3],
        out: &mut [O],
        to_index: impl Fn(DVec3) -> DVec3,
    ) {
        let (lo, hi) = K::interior(self.geometry.dims);
        for (o, &p) in out.iter_mut().zip(points) {
            *o = O::from_f64(self.point::<K, V>(d, lo, hi, to_index(p)));
        }
    }

    /// One point of [`Sampler::run_kernel`]: kernel `K`'s direct formula inside its interior
    /// box `lo ≤ q < hi` (NaN fails the test), the general boundary code elsewhere.
    #[inline(always)]
    fn point<K: InteriorKernel, V: Voxel>(&self, d: &[V], lo: f64, hi: [f64; 3], q: DVec3) -> f64 {
        if q.x >= lo && q.x < hi[0] && q.y >= lo && q.y < hi[1] && q.z >= lo && q.z < hi[2] {
            K::eval(d, self.geometry.dims, q)
        } else {
            self.eval_border(d, q)
        }
    }

    /// Value returned for points outside the sampled domain.
    #[inline]
    fn outside(&self) -> f64 {
        match self.boundary {
            Boundary::Constant(c) => c,
            Boundary::Clamp | Boundary::Mirror => f64::NAN,
        }
    }

    /// [`Sampler::eval`] kept out of line: the rare border and outside points of the batch
    /// loops, which then stay small enough to inline their kernel and index map.
    #[inline(never)]
    #[cold]
    fn eval_border<V: Voxel>(&self, d: &[V], index: DVec3) -> f64 {
        self.eval(d, index)
    }

    #[inline]
    fn eval<V: Voxel>(&self, d: &[V], index: DVec3) -> f64 {
        let dims = self.geometry.dims;
        let (Some(x), Some(y), Some(z)) = (
            fold(index.x, dims[0], self.boundary),
            fold(index.y, dims[1], self.boundary),
            fold(index.z, dims[2], self.boundary),
        ) else {
            return self.outside();
        };
        let sy = dims[0];
        let sz = dims[0] * dims[1];
        match self.interpolation {
            Interpolation::Nearest => {
                let i = round_half_up(x, dims[0]);
                let j = round_half_up(y, dims[1]);
                let k = round_half_up(z, dims[2]);
                d[i + sy * j + sz * k].to_f64()
            }
            Interpolation::Linear => {
                let (x0, x1, tx) = linear_axis(x, dims[0]);
                let (y0, y1, ty) = linear_axis(y, dims[1]);
                let (z0, z1, tz) = linear_axis(z, dims[2]);
                let row = |j: usize, k: usize| {
                    let o = sy * j + sz * k;
                    lerp(d[o + x0].to_f64(), d[o + x1].to_f64(), tx)
                };
                let c0 = lerp(row(y0, z0), row(y1, z0), ty);
                let c1 = lerp(row(y0, z1), row(y1, z1), ty);
                lerp(c0, c1, tz)
            }
            Interpolation::CubicBSpline => {
                let (ix, wx) = cubic_axis(x, dims[0]);
                let (iy, wy) = cubic_axis(y, dims[1]);
                let (iz, wz) = cubic_axis(z, dims[2]);
                // Away from the i edges the four x neighbours are contiguous: one bounds check
                // per row instead of four.
                let contiguous = ix[3] == ix[0] + 3;
                let mut acc = 0.0;
                for (&k, &wk) in iz.iter().zip(&wz) {
                    let mut plane = 0.0;
                    for (&j, &wj) in iy.iter().zip(&wy) {
                        let o = sy * j + sz * k;
                        let r = if contiguous {
                            let row = &d[o + ix[0]..o + ix[0] + 4];
                            wx[0] * row[0].to_f64()
                                + wx[1] * row[1].to_f64()
                                + wx[2] * row[2].to_f64()
                                + wx[3] * row[3].to_f64()
                        } else {
                            wx[0] * d[o + ix[0]].to_f64()
                                + wx[1] * d[o + ix[1]].to_f64()
                                + wx[2] * d[o + ix[2]].to_f64()
                                + wx[3] * d[o + ix[3]].to_f64()
                        };
                        plane += wj * r;
                    }
                    acc += wk * plane;
                }
                acc
            }
        }
    }
}

/// A kernel's direct formula for points whose whole stencil lies inside the volume.
///
/// Implementations must return exactly what [`Sampler::eval`] returns for such points under
/// every boundary policy (inside the interior box every policy leaves the coordinates
/// unchanged, so this means the same index arithmetic and the same floating-point operations
/// in the same order).
trait InteriorKernel {
    /// The interior box `lo ≤ x < hi[a]` along each axis `a` of a volume of `dims` voxels
    /// (empty along an axis too short for the stencil).
    fn interior(dims: [usize; 3]) -> (f64, [f64; 3]);

    /// The value at continuous index `q` inside the interior box.
    fn eval<V: Voxel>(d: &[V], dims: [usize; 3], q: DVec3) -> f64;
}

/// Interior box `[lo, n − 1 − margin)` per axis as `f64` bounds.
#[inline]
fn interior_box(dims: [usize; 3], lo: f64, margin: f64) -> (f64, [f64; 3]) {
    let hi = |n: usize| n as f64 - 1.0 - margin;
    (lo, [hi(dims[0]), hi(dims[1]), hi(dims[2])])
}

/// `(⌊x⌋, x − ⌊x⌋)` for `0 ≤ x < 2⁶³` (the interior of a volume): truncation through `i64`
/// is floor there and both conversions are single instructions on baseline x86-64 (those
/// through `usize` are not). Same values as the general path's `x as usize`.
#[inline]
fn floor_fract(x: f64) -> (usize, f64) {
    let i = x as i64;
    (i as usize, x - i as f64)
}

/// [`Interpolation::Nearest`] on `[0, n − 1)`: `⌊x + ½⌋` never exceeds `n − 1` there.
struct NearestKernel;

impl InteriorKernel for NearestKernel {
    #[inline]
    fn interior(dims: [usize; 3]) -> (f64, [f64; 3]) {
        interior_box(dims, 0.0, 0.0)
    }

    #[inline(always)]
    fn eval<V: Voxel>(d: &[V], dims: [usize; 3], q: DVec3) -> f64 {
        let [nx, ny, _] = dims;
        // The result is below n since q < n − 1.
        let (i, _) = floor_fract(q.x + 0.5);
        let (j, _) = floor_fract(q.y + 0.5);
        let (k, _) = floor_fract(q.z + 0.5);
        d[i + nx * j + nx * ny * k].to_f64()
    }
}

/// [`Interpolation::Linear`] on `[0, n − 1)`: the upper neighbour `⌊x⌋ + 1` is in range.
struct LinearKernel;

impl InteriorKernel for LinearKernel {
    #[inline]
    fn interior(dims: [usize; 3]) -> (f64, [f64; 3]) {
        interior_box(dims, 0.0, 0.0)
    }

    #[inline(always)]
    fn eval<V: Voxel>(d: &[V], dims: [usize; 3], q: DVec3) -> f64 {
        let sy = dims[0];
        let sz = dims[0] * dims[1];
        let (x0, tx) = floor_fract(q.x);
        let (y0, ty) = floor_fract(q.y);
        let (z0, tz) = floor_fract(q.z);
        let o = x0 + sy * y0 + sz * z0;
        // The eight corners, one range check for the whole cell.
        let cell = &d[o..o + sz + sy + 2];
        let row = |r: usize| lerp(cell[r].to_f64(), cell[r + 1].to_f64(), tx);
        let c0 = lerp(row(0), row(sy), ty);
        let c1 = lerp(row(sz), row(sz + sy), ty);
        lerp(c0, c1, tz)
    }
}

/// [`Interpolation::CubicBSpline`] on `[1, n − 2)`: the four neighbours `⌊x⌋ − 1 … ⌊x⌋ + 2`
/// are in range, so no coefficient index needs mirroring.
struct CubicKernel;

impl InteriorKernel for CubicKernel {
    #[inline]
    fn interior(dims: [usize; 3]) -> (f64, [f64; 3]) {
        interior_box(dims, 1.0, 1.0)
    }

    #[inline(always)]
    fn eval<V: Voxel>(d: &[V], dims: [usize; 3], q: DVec3) -> f64 {
        let sy = dims[0];
        let sz = dims[0] * dims[1];
        let (i, tx) = floor_fract(q.x);
        let (j, ty) = floor_fract(q.y);
        let (k, tz) = floor_fract(q.z);
        let (wx, wy, wz) = (cubic_weights(tx), cubic_weights(ty), cubic_weights(tz));
        let o = (i - 1) + sy * (j - 1) + sz * (k - 1);
        // The 4×4×4 stencil, one range check for the whole block.
        let block = &d[o..o + 3 * sz + 3 * sy + 4];
        let mut acc = 0.0;
        for (c, &wk) in wz.iter().enumerate() {
            let mut plane = 0.0;
            for (b, &wj) in wy.iter().enumerate() {
                let r = c * sz + b * sy;
                let row = &block[r..r + 4];
                let v = wx[0] * row[0].to_f64()
                    + wx[1] * row[1].to_f64()
                    + wx[2] * row[2].to_f64()
                    + wx[3] * row[3].to_f64();
                plane += wj * v;
            }
            acc += wk * plane;
        }
        acc
    }
}

fn check_batch(points: usize, out: usize) -> Result<(), VolumeError> {
    if points == out {
        Ok(())
    } else {
        Err(VolumeError::InvalidArgument(format!(
            "{points} points need an output slice of {points} values, got {out}"
        )))
    }
}

/// Map coordinate `x` along an axis of `n ≥ 1` voxels into `[0, n − 1]` under `boundary`, or
/// `None` if the point is outside the sampled domain (or the coordinate unusable).
#[inline]
fn fold(x: f64, n: usize, boundary: Boundary) -> Option<f64> {
    let last = (n - 1) as f64;
    match boundary {
        Boundary::Constant(_) => (x >= -0.5 && x <= last + 0.5).then(|| x.clamp(0.0, last)),
        Boundary::Clamp => (!x.is_nan()).then(|| x.clamp(0.0, last)),
        Boundary::Mirror => x.is_finite().then(|| mirror_coordinate(x, last)),
    }
}

/// Reflect finite `x` into `[0, last]` (whole-sample symmetry, period `2·last`).
#[inline]
fn mirror_coordinate(x: f64, last: f64) -> f64 {
    if (0.0..=last).contains(&x) {
        return x;
    }
    if last == 0.0 {
        return 0.0;
    }
    let period = 2.0 * last;
    let y = x.rem_euclid(period);
    let y = if y > last { period - y } else { y };
    y.clamp(0.0, last)
}

/// Reflect integer index `m` into `0..n` (whole-sample symmetry, period `2(n − 1)`).
#[inline]
fn mirror_index(m: isize, n: usize) -> usize {
    if n <= 1 {
        return 0;
    }
    let last = n - 1;
    let period = 2 * last as isize;
    let r = m.rem_euclid(period).unsigned_abs();
    if r > last { 2 * last - r } else { r }
}

/// Nearest voxel of `x ∈ [0, n − 1]`, ties towards +∞.
#[inline]
fn round_half_up(x: f64, n: usize) -> usize {
    // x + 0.5 ≥ 0, so truncation is floor; a cast avoids the libm call `floor` compiles to
    // on baseline x86-64.
    ((x + 0.5) as usize).min(n - 1)
}

#[inline]
fn lerp(a: f64, b: f64, t: f64) -> f64 {
    // Exact at t = 0 and t = 1.
    (1.0 - t) * a + t * b
}

/// Lower and upper neighbour and weight of the upper one for `x ∈ [0, n − 1]`.
#[inline]
fn linear_axis(x: f64, n: usize) -> (usize, usize, f64) {
    // x ≥ 0, so truncation is floor (and cheaper than `f64::floor` on baseline x86-64).
    let i0 = (x as usize).min(n.saturating_sub(2));
    let t = x - i0 as f64;
    (i0, (i0 + 1).min(n - 1), t)
}

/// The four coefficient indices (mirrored into range) and cubic B-spline weights for
/// `x ∈ [0, n − 1]`.
#[inline]
fn cubic_axis(x: f64, n: usize) -> ([usize; 4], [f64; 4]) {
    // x ≥ 0, so truncation is floor (and cheaper than `f64::floor` on baseline x86-64).
    let i = x as isize;
    let t = x - i as f64;
    let idx = if i >= 1 && i + 2 < n as isize {
        // Interior: no reflection needed (the common case).
        let i = i.unsigned_abs();
        [i - 1, i, i + 1, i + 2]
    } else {
        [
            mirror_index(i - 1, n),
            mirror_index(i, n),
            mirror_index(i + 1, n),
            mirror_index(i + 2, n),
        ]
    };
    (idx, cubic_weights(t))
}

/// Cubic B-spline weights of the four neighbours `⌊x⌋ − 1 … ⌊x⌋ + 2` for fractional part
/// `t = x − ⌊x⌋ ∈ [0, 1]`.
#[inline]
fn cubic_weights(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    let s = 1.0 - t;
    [
        s * s * s / 6.0,
        (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
        (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
        t3 / 6.0,
    ]
}

/// Number of terms of the causal initial sum for a line of `n` samples.
#[inline]
fn init_len(n: usize) -> usize {
    n.min(HORIZON)
}

/// Weight of sample `k` in the causal initial value `c⁺[0]` of a line of `n ≥ 2` samples:
/// Unser's exact mirror-boundary sum `Σ_{k<2n−2} z^k s[mirror(k)] / (1 − z^{2n−2})` folded onto
/// the line when `n ≤ HORIZON`, the truncated sum `Σ_{k<HORIZON} z^k s[k]` otherwise.
#[inline]
fn init_weight(k: usize, n: usize) -> f64 {
    let z = CUBIC_BSPLINE_POLE;
    if n > HORIZON {
        return z.powi(k as i32);
    }
    let last = (n - 1) as i32;
    let norm = 1.0 - z.powi(2 * last);
    let k = k as i32;
    let w = if k == 0 || k == last {
        z.powi(k)
    } else {
        z.powi(k) + z.powi(2 * last - k)
    };
    w / norm
}

/// Anticausal initial value factor `z / (z² − 1)`.
const ANTICAUSAL: f64 = CUBIC_BSPLINE_POLE / (CUBIC_BSPLINE_POLE * CUBIC_BSPLINE_POLE - 1.0);

/// Turn one line of samples into cubic B-spline interpolation coefficients, in place.
///
/// Afterwards `(c[k−1] + 4·c[k] + c[k+1]) / 6 = s[k]` for every `k`, with `c` extended by
/// whole-sample mirror symmetry (`c[−1] = c[1]`, `c[n] = c[n−2]`). Unser's recursive filter:
/// gain 6, a causal then an anticausal first-order pass with pole [`CUBIC_BSPLINE_POLE`].
/// Lines of fewer than two samples are left unchanged (a constant is its own coefficient).
pub fn cubic_bspline_prefilter(line: &mut [f64]) {
    let n = line.len();
    if n < 2 {
        return;
    }
    let z = CUBIC_BSPLINE_POLE;
    let c0 = (0..init_len(n))
        .map(|k| init_weight(k, n) * line[k])
        .sum::<f64>();
    line[0] = GAIN * c0;
    for k in 1..n {
        line[k] = GAIN * line[k] + z * line[k - 1];
    }
    line[n - 1] = ANTICAUSAL * (line[n - 1] + z * line[n - 2]);
    for k in (0..n - 1).rev() {
        line[k] = z * (line[k + 1] - line[k]);
    }
}

/// The prefilter of [`cubic_bspline_prefilter`] applied along a sequence of equally long
/// blocks (vectorised across each block): `blocks[k][x]` is sample `k` of line `x`. The
/// recursive state is carried in `prev` (`f64`, resized to the block width), so stored values
/// are rounded once per pass.
fn prefilter_blocks<C: Voxel>(blocks: &mut [&mut [C]], prev: &mut Vec<f64>) {
    let n = blocks.len();
    if n < 2 {
        return;
    }
    let z = CUBIC_BSPLINE_POLE;
    // Causal initial value c⁺[0] = GAIN · Σ w_k s[k] (blocks 1.. are still the input).
    let w0 = GAIN * init_weight(0, n);
    prev.clear();
    prev.extend(blocks[0].iter().map(|v| w0 * v.to_f64()));
    for (k, block) in blocks.iter().enumerate().take(init_len(n)).skip(1) {
        let wk = GAIN * init_weight(k, n);
        for (p, v) in prev.iter_mut().zip(block.iter()) {
            *p += wk * v.to_f64();
        }
    }
    for (v, p) in blocks[0].iter_mut().zip(prev.iter()) {
        *v = C::from_f64(*p);
    }
    // Causal pass: c⁺[k] = GAIN · s[k] + z · c⁺[k−1].
    for block in blocks.iter_mut().skip(1) {
        for (p, v) in prev.iter_mut().zip(block.iter_mut()) {
            let c = GAIN * v.to_f64() + z * *p;
            *p = c;
            *v = C::from_f64(c);
        }
    }
    // Anticausal initial value from c⁺[n−1] (in prev) and c⁺[n−2].
    for (p, v) in prev.iter_mut().zip(blocks[n - 2].iter()) {
        *p = ANTICAUSAL * (*p + z * v.to_f64());
    }
    for (v, p) in blocks[n - 1].iter_mut().zip(prev.iter()) {
        *v = C::from_f64(*p);
    }
    // Anticausal pass: c[k] = z · (c[k+1] − c⁺[k]).
    for block in blocks.iter_mut().rev().skip(1) {
        for (p, v) in prev.iter_mut().zip(block.iter_mut()) {
            let c = z * (*p - v.to_f64());
            *p = c;
            *v = C::from_f64(c);
        }
    }
}

/// Cubic B-spline interpolation coefficients of `volume` (what an
/// [`Interpolation::CubicBSpline`] sampler interpolates: the spline
/// `Σ c_ijk β₃(x − i) β₃(y − j) β₃(z − k)` with `c` extended by whole-sample mirror symmetry
/// passes through every voxel value), stored as `C` in the volume's order (x fastest),
/// computed separably along i (rows, from the source voxels through a reusable `f64` line
/// buffer), j (rows of each z-slab as blocks) and k (column tiles of the xy-planes as blocks),
/// each pass in parallel. A sampler stores `f32` coefficients for every voxel type but `f64`.
///
/// # Errors
/// [`VolumeError::Io`] if the coefficient array would exceed the memory budget.
pub fn bspline_coefficients<T: Voxel, C: Voxel, D: AsRef<[T]>>(
    volume: &Volume<T, D>,
) -> Result<Vec<C>, VolumeError> {
    let [nx, ny, nz] = volume.dims();
    let len = volmorph_io::checked_len(&[nx, ny, nz], std::mem::size_of::<C>())?;
    let mut coef = vec![C::default(); len];
    let plane = nx * ny;

    // Along i: rows are contiguous.
    coef.par_chunks_mut(plane)
        .zip(volume.data().par_chunks(plane))
        .for_each_init(
            || Vec::with_capacity(nx),
            |line: &mut Vec<f64>, (dst, src)| {
                for (drow, srow) in dst.chunks_exact_mut(nx).zip(src.chunks_exact(nx)) {
                    line.clear();
                    line.extend(srow.iter().map(|v| v.to_f64()));
                    cubic_bspline_prefilter(line);
                    for (d, v) in drow.iter_mut().zip(line.iter()) {
                        *d = C::from_f64(*v);
                    }
                }
            },
        );

    // Along j: in each z-slab, the ny rows are the blocks.
    if ny > 1 {
        coef.par_chunks_mut(plane).for_each_init(
            || Vec::with_capacity(nx),
            |prev: &mut Vec<f64>, slab| {
                let mut rows: Vec<&mut [C]> = slab.chunks_exact_mut(nx).collect();
                prefilter_blocks(&mut rows, prev);
            },
        );
    }

    // Along k: split every xy-plane into the same column tiles; each tile's nz pieces are
    // the blocks of one independent filtering task.
    if nz > 1 {
        let tasks = 4 * rayon::current_num_threads();
        let tile = plane.div_ceil(tasks).max(512).min(plane);
        let ntiles = plane.div_ceil(tile);
        let mut tiles: Vec<Vec<&mut [C]>> = (0..ntiles).map(|_| Vec::with_capacity(nz)).collect();
        for p in coef.chunks_exact_mut(plane) {
            for (t, piece) in tiles.iter_mut().zip(p.chunks_mut(tile)) {
                t.push(piece);
            }
        }
        tiles.into_par_iter().for_each_init(
            || Vec::with_capacity(tile),
            |prev: &mut Vec<f64>, mut blocks| prefilter_blocks(&mut blocks, prev),
        );
    }
    Ok(coef)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirror_index_reflects_about_end_samples() {
        let n = 4; // period 6: 0 1 2 3 2 1 | 0 1 2 3 …
        let expect = [
            (-3, 3),
            (-2, 2),
            (-1, 1),
            (0, 0),
            (3, 3),
            (4, 2),
            (5, 1),
            (6, 0),
        ];
        for (m, e) in expect {
            assert_eq!(mirror_index(m, n), e, "m = {m}");
        }
        assert_eq!(mirror_index(-7, 1), 0);
        assert_eq!(mirror_index(3, 2), 1);
        assert_eq!(mirror_index(-1, 2), 1);
    }

    #[test]
    fn mirror_coordinate_folds() {
        assert_eq!(mirror_coordinate(-0.25, 3.0), 0.25);
        assert_eq!(mirror_coordinate(3.5, 3.0), 2.5);
        assert_eq!(mirror_coordinate(6.5, 3.0), 0.5);
        assert_eq!(mirror_coordinate(-1e-20, 3.0), 0.0);
        assert_eq!(mirror_coordinate(17.0, 0.0), 0.0);
    }

    #[test]
    fn init_weights_sum_to_the_mirror_dc_gain() {
        // For a constant line every coefficient equals the constant: c⁺ is s / (1 − z), so the
        // initial weights must sum to 1 / (1 − z) for every length.
        let z = CUBIC_BSPLINE_POLE;
        for n in 2..40 {
            let s: f64 = (0..init_len(n)).map(|k| init_weight(k, n)).sum();
            assert!((s - 1.0 / (1.0 - z)).abs() < 1e-14, "n = {n}: {s}");
        }
    }

    #[test]
    fn block_filter_matches_line_filter() {
        let n = 9;
        let w = 3;
        let src: Vec<f64> = (0..n * w).map(|i| ((i * 37 % 11) as f64) - 4.0).collect();
        let mut data = src.clone();
        let mut blocks: Vec<&mut [f64]> = data.chunks_mut(w).collect();
        prefilter_blocks(&mut blocks, &mut Vec::new());
        for x in 0..w {
            let mut line: Vec<f64> = (0..n).map(|k| src[k * w + x]).collect();
            cubic_bspline_prefilter(&mut line);
            for k in 0..n {
                assert!((line[k] - data[k * w + x]).abs() < 1e-12);
            }
        }
    }
}
