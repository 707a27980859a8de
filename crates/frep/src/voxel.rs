//! Sampled volumes as defining functions: the data behind the model language's
//! `vmVolume(path, x, level [, kernel [, outside]])` primitive (see [`crate::compile()`]).
//!
//! A [`VoxelField`] holds a volume read through `volmorph-volume-io` (any format volmorph
//! reads) and interpolates it at **continuous voxel indices** `u = (i, j, k)`: the compiler
//! writes the physical-to-index map `u = (direction · diag(spacing))⁻¹ (x − origin)` of the
//! volume's full geometry (direction matrix included) as expression nodes before the sample
//! node, so gradients follow the chain rule through it and interval bounds of a physical box
//! become index boxes by interval arithmetic on that affine map.
//!
//! # The sampled function
//!
//! The conventions are those of [`volmorph_volume::sample::Sampler`] with
//! [`Boundary::Constant`](volmorph_volume::sample::Boundary::Constant)`(outside)`, so a
//! `vmVolume` value agrees with the project's sampler at every point (to rounding):
//!
//! * [`VoxelKernel::Linear`] — trilinear interpolation of the voxel values;
//!   [`VoxelKernel::CubicBSpline`] — the interpolating cubic B-spline (Unser's prefilter with
//!   whole-sample mirror extension, coefficients stored as the sampler stores them: `f32`
//!   for every voxel type but `f64`).
//! * The volume covers the index box `[−½, n − ½]` along each axis. Within it, a coordinate
//!   in the half-voxel border outside `[0, n − 1]` is clamped to the edge voxel plane
//!   (constant extrapolation over half a voxel). Beyond it the sample is the constant
//!   [`VoxelField::outside`] — by default the smallest voxel value, so nothing outside the
//!   data is more solid than the emptiest voxel (air for a CT).
//! * Unlike the sampler, a NaN coordinate gives NaN (the F-rep convention: NaN propagates).
//!
//! # Derivatives
//!
//! A sample node carries a derivative order per axis (in index units). The value of order
//! `(a, b, c)` is `Σ v_ijk w⁽ᵃ⁾(x − i) w⁽ᵇ⁾(y − j) w⁽ᶜ⁾(z − k)` with the kernel's derivative
//! weights: for the linear kernel `(1 − t, t)`, then `(−1, 1)`, then zero; for the cubic
//! B-spline its first three derivatives, then zero. Derivatives are one-sided at the kinks of
//! the linear kernel (the right cell's, as the sampler's cell choice), zero along an axis in
//! the clamped half-voxel border, and zero outside the volume.
//!
//! # Interval bounds
//!
//! [`VoxelField::bound`] encloses the sample over an index box from a min–max pyramid of the
//! interpolated values (voxels or coefficients): level `L` holds the minimum and maximum of
//! each `2^L`-aligned brick, and a query takes the coarsest level at which the box's
//! support meets at most four bricks per axis. Both kernels are convex combinations of the
//! values in their support (nonnegative weights summing to one), so the value lies within
//! their minimum and maximum, joined with `outside` when the box leaves the volume. A
//! derivative of total order `k ≥ 1` is a convex combination of `k`-th differences of those
//! values, bounded by `±2^{k−1}·(max − min)`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, Weak};

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_volume::{AnyVolume, Geometry, Volume, Voxel, VoxelType};

use crate::error::FrepError;
use crate::ops::Interval;

/// Interpolation of a [`VoxelField`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum VoxelKernel {
    /// Trilinear interpolation (`C⁰`, eight voxels per sample).
    #[default]
    Linear,
    /// Interpolating cubic B-spline (`C²`, 64 coefficients per sample, one prefilter pass
    /// when the volume is loaded).
    CubicBSpline,
}

impl VoxelKernel {
    /// Parse `linear` or `cubic` (also `cubic-bspline`).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] naming the accepted names.
    pub fn parse(s: &str) -> Result<Self, FrepError> {
        match s.to_ascii_lowercase().as_str() {
            "linear" | "trilinear" => Ok(Self::Linear),
            "cubic" | "cubic-bspline" | "bspline" => Ok(Self::CubicBSpline),
            _ => Err(FrepError::InvalidArgument(format!(
                "unknown interpolation \"{s}\" (expected \"linear\" or \"cubic\")"
            ))),
        }
    }

    /// Polynomial degree per axis: derivatives of higher order vanish.
    #[must_use]
    pub fn degree(self) -> u8 {
        match self {
            Self::Linear => 1,
            Self::CubicBSpline => 3,
        }
    }

    /// Largest number of values along one axis a sample reads.
    fn width(self) -> usize {
        match self {
            Self::Linear => 2,
            Self::CubicBSpline => 4,
        }
    }
}

/// The interpolated values: voxels (linear) or B-spline coefficients (cubic).
#[derive(Debug)]
enum Values {
    F32(Vec<f32>),
    F64(Vec<f64>),
}

/// Min–max pyramid: `levels[l]` holds `(min, max)` of the bricks of side `2^(l+1)`.
#[derive(Debug)]
struct Pyramid {
    levels: Vec<Level>,
}

#[derive(Debug)]
struct Level {
    dims: [usize; 3],
    range: Vec<(f64, f64)>,
}

/// A sampled volume as a function of continuous voxel indices; see the
/// [module documentation](self). Shared between shapes by [`Arc`]; two fields are equal only
/// if they are the same object.
pub struct VoxelField {
    name: String,
    geometry: Geometry,
    kernel: VoxelKernel,
    outside: f64,
    values: Values,
    data_min: f64,
    data_max: f64,
    index_from_physical: DMat3,
    pyramid: Pyramid,
}

impl std::fmt::Debug for VoxelField {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VoxelField")
            .field("name", &self.name)
            .field("dims", &self.geometry.dims)
            .field("kernel", &self.kernel)
            .field("outside", &self.outside)
            .finish_non_exhaustive()
    }
}

impl PartialEq for VoxelField {
    fn eq(&self, other: &Self) -> bool {
        std::ptr::eq(self, other)
    }
}

/// Bytes a [`VoxelField`] of `n` voxels allocates per voxel beyond the value array: the
/// pyramid's `(min, max)` pairs, at most `n/7` of 16 bytes (rounded up).
const PYRAMID_BYTES_PER_VOXEL: u64 = 3;

impl VoxelField {
    /// Build from a volume. `name` is used in messages (the file path); `outside` is the
    /// value beyond the volume (`None`: the smallest voxel value).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] for an empty volume, a non-finite voxel or `outside`;
    /// [`FrepError::Volume`] when the values, coefficients or pyramid exceed the memory
    /// budget (checked before allocating) or the geometry is invalid.
    pub fn new(
        name: &str,
        volume: &AnyVolume,
        kernel: VoxelKernel,
        outside: Option<f64>,
    ) -> Result<Self, FrepError> {
        volmorph_volume::with_volume!(volume, v => Self::from_volume(name, v, kernel, outside))
    }

    fn from_volume<T: Voxel>(
        name: &str,
        volume: &Volume<T>,
        kernel: VoxelKernel,
        outside: Option<f64>,
    ) -> Result<Self, FrepError> {
        let geometry = *volume.geometry();
        geometry.validate()?;
        let dims = geometry.dims;
        let n = volmorph_io::checked_len(&dims, 1).map_err(volmorph_volume::VolumeError::from)?;
        if n == 0 {
            return Err(FrepError::InvalidArgument(format!(
                "{name}: the volume is empty"
            )));
        }
        // f32 holds 8- and 16-bit integers and f32 voxels exactly; wider types keep f64.
        let wide = matches!(T::TYPE, VoxelType::U32 | VoxelType::I32 | VoxelType::F64);
        let elem = if wide { 8 } else { 4 };
        volmorph_io::check_elems(
            &format!(
                "the interpolation values of {name} ({}×{}×{})",
                dims[0], dims[1], dims[2]
            ),
            n as u64,
            elem + PYRAMID_BYTES_PER_VOXEL,
        )
        .map_err(volmorph_volume::VolumeError::from)?;
        let (data_min, data_max) = volume
            .data()
            .par_iter()
            .map(|v| {
                let x = v.to_f64();
                (x, x)
            })
            .reduce(
                || (f64::INFINITY, f64::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        if !(data_min.is_finite() && data_max.is_finite()) {
            return Err(FrepError::InvalidArgument(format!(
                "{name}: the volume holds non-finite values (NaN or infinity)"
            )));
        }
        let outside = outside.unwrap_or(data_min);
        if !outside.is_finite() {
            return Err(FrepError::InvalidArgument(format!(
                "{name}: the value outside the volume must be finite, got {outside}"
            )));
        }
        let values = match (kernel, wide) {
            (VoxelKernel::Linear, false) => Values::F32(
                volume
                    .data()
                    .par_iter()
                    .map(|v| v.to_f64() as f32)
                    .collect(),
            ),
            (VoxelKernel::Linear, true) => {
                Values::F64(volume.data().par_iter().map(|v| v.to_f64()).collect())
            }
            // The sampler's coefficient precision: f64 only for f64 volumes.
            (VoxelKernel::CubicBSpline, _) if T::TYPE == VoxelType::F64 => Values::F64(
                volmorph_volume::sample::bspline_coefficients::<T, f64, _>(volume)?,
            ),
            (VoxelKernel::CubicBSpline, _) => Values::F32(
                volmorph_volume::sample::bspline_coefficients::<T, f32, _>(volume)?,
            ),
        };
        let pyramid = match &values {
            Values::F32(d) => Pyramid::build(d, dims),
            Values::F64(d) => Pyramid::build(d, dims),
        };
        Ok(Self {
            name: name.to_string(),
            geometry,
            kernel,
            outside,
            values,
            data_min,
            data_max,
            index_from_physical: geometry.index_to_physical_matrix().inverse(),
            pyramid,
        })
    }

    /// The name given at construction (the file path for [`load`]).
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The volume's geometry.
    #[must_use]
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// The interpolation kernel.
    #[must_use]
    pub fn kernel(&self) -> VoxelKernel {
        self.kernel
    }

    /// The value beyond the volume.
    #[must_use]
    pub fn outside(&self) -> f64 {
        self.outside
    }

    /// Smallest and largest voxel value.
    #[must_use]
    pub fn data_range(&self) -> (f64, f64) {
        (self.data_min, self.data_max)
    }

    /// `M` and `o` of the physical-to-index map `u = M (x − o)`.
    #[must_use]
    pub fn index_map(&self) -> (DMat3, DVec3) {
        (self.index_from_physical, self.geometry.origin)
    }

    /// The sample (derivative `order` per axis, in index units) at continuous index `u`.
    #[must_use]
    pub fn eval(&self, order: [u8; 3], u: [f64; 3]) -> f64 {
        match &self.values {
            Values::F32(d) => self.eval_in(d, order, u),
            Values::F64(d) => self.eval_in(d, order, u),
        }
    }

    /// The sample of `order` and its gradient with respect to `u` (the samples of `order`
    /// raised by one along each axis).
    #[must_use]
    pub fn eval_with_gradient(&self, order: [u8; 3], u: [f64; 3]) -> (f64, [f64; 3]) {
        let up = |a: usize| {
            let mut o = order;
            o[a] = o[a].saturating_add(1);
            self.eval(o, u)
        };
        (self.eval(order, u), [up(0), up(1), up(2)])
    }

    /// The sample at physical point `p` (order 0): what `vmVolume` adds to `−level`.
    #[must_use]
    pub fn sample_physical(&self, p: DVec3) -> f64 {
        let u = self.index_from_physical * (p - self.geometry.origin);
        self.eval([0; 3], u.to_array())
    }

    fn eval_in<T: Copy + Into<f64>>(&self, d: &[T], order: [u8; 3], u: [f64; 3]) -> f64 {
        if u.iter().any(|v| v.is_nan()) {
            return f64::NAN;
        }
        let dims = self.geometry.dims;
        let mut axes = [Axis::default(); 3];
        for a in 0..3 {
            match self.axis(u[a], dims[a], order[a]) {
                Some(ax) => axes[a] = ax,
                None => return if order == [0; 3] { self.outside } else { 0.0 },
            }
        }
        let (sy, sz) = (dims[0], dims[0] * dims[1]);
        let mut acc = 0.0;
        for (&k, &wk) in axes[2].idx[..axes[2].n].iter().zip(&axes[2].w) {
            if wk == 0.0 {
                continue;
            }
            let mut plane = 0.0;
            for (&j, &wj) in axes[1].idx[..axes[1].n].iter().zip(&axes[1].w) {
                if wj == 0.0 {
                    continue;
                }
                let o = sy * j + sz * k;
                let mut row = 0.0;
                for (&i, &wi) in axes[0].idx[..axes[0].n].iter().zip(&axes[0].w) {
                    row += wi * d[o + i].into();
                }
                plane += wj * row;
            }
            acc += wk * plane;
        }
        acc
    }

    /// Indices and weights along one axis of `n` voxels for coordinate `x` (not NaN) and
    /// derivative `order`; `None` beyond the sampled domain `[−½, n − ½]`.
    fn axis(&self, x: f64, n: usize, order: u8) -> Option<Axis> {
        let last = (n - 1) as f64;
        if !(x >= -0.5 && x <= last + 0.5) {
            return None;
        }
        let clamped = !(0.0..=last).contains(&x);
        let x = x.clamp(0.0, last);
        let mut ax = Axis::default();
        if order > self.kernel.degree() || (clamped && order > 0) {
            // Zero weights: the sample is 0.
            ax.n = 1;
            return Some(ax);
        }
        match self.kernel {
            VoxelKernel::Linear => {
                if n == 1 {
                    ax.n = 1;
                    ax.w[0] = if order == 0 { 1.0 } else { 0.0 };
                    return Some(ax);
                }
                // x ≥ 0, so truncation is floor.
                let i0 = (x as usize).min(n - 2);
                let t = x - i0 as f64;
                ax.n = 2;
                ax.idx[..2].copy_from_slice(&[i0, i0 + 1]);
                ax.w[..2].copy_from_slice(&if order == 0 {
                    [1.0 - t, t]
                } else {
                    [-1.0, 1.0]
                });
            }
            VoxelKernel::CubicBSpline => {
                let i = x as isize;
                let t = x - i as f64;
                ax.n = 4;
                for (k, slot) in ax.idx.iter_mut().enumerate() {
                    *slot = mirror_index(i - 1 + k as isize, n);
                }
                ax.w = match order {
                    0 => volmorph_spline::uniform_cubic(t),
                    1 => volmorph_spline::uniform_cubic_derivative(t),
                    2 => volmorph_spline::uniform_cubic_second_derivative(t),
                    _ => [-1.0, 3.0, -3.0, 1.0],
                };
            }
        }
        Some(ax)
    }

    /// An enclosure of the sample of `order` over the index box `u` (see the
    /// [module documentation](self)); the NaN flag is set when a coordinate may be NaN.
    #[must_use]
    pub fn bound(&self, order: [u8; 3], u: [Interval; 3]) -> Interval {
        let nan = u.iter().any(|i| i.nan);
        let dims = self.geometry.dims;
        let total: u32 = order.iter().map(|&o| u32::from(o)).sum();
        if order.iter().any(|&o| o > self.kernel.degree()) {
            return with_nan(Interval::point(0.0), nan);
        }
        let mut partly_outside = false;
        let mut lo = [0usize; 3];
        let mut hi = [0usize; 3];
        for a in 0..3 {
            let last = (dims[a] - 1) as f64;
            let (l, h) = (u[a].lo, u[a].hi);
            if h < -0.5 || l > last + 0.5 {
                // Wholly outside along this axis.
                let v = if total == 0 { self.outside } else { 0.0 };
                return with_nan(Interval::point(v), nan);
            }
            partly_outside |= l < -0.5 || h > last + 0.5;
            let (lc, hc) = (l.clamp(0.0, last), h.clamp(0.0, last));
            let reach = self.kernel.width() / 2;
            lo[a] = (lc as usize).saturating_sub(reach - 1).saturating_sub(1);
            hi[a] = ((hc as usize) + reach).min(dims[a] - 1);
        }
        let (mn, mx) = match &self.values {
            Values::F32(d) => self.pyramid.range(d, dims, lo, hi),
            Values::F64(d) => self.pyramid.range(d, dims, lo, hi),
        };
        // Rounding of the weighted sums: at most 64 terms of weights summing to one.
        let slack = 64.0 * f64::EPSILON * mn.abs().max(mx.abs());
        let mut iv = if total == 0 {
            Interval::new(mn - slack, mx + slack)
        } else {
            let r = (mx - mn) * f64::from(1u32 << (total - 1).min(30)) + 8.0 * slack;
            Interval::new(-r, r)
        };
        if partly_outside {
            iv = iv.hull(Interval::point(if total == 0 { self.outside } else { 0.0 }));
        }
        with_nan(iv, nan)
    }
}

fn with_nan(mut i: Interval, nan: bool) -> Interval {
    i.nan |= nan;
    i
}

/// Indices and weights along one axis (`n` of them used).
#[derive(Debug, Clone, Copy, Default)]
struct Axis {
    n: usize,
    idx: [usize; 4],
    w: [f64; 4],
}

/// Reflect integer index `m` into `0..n` (whole-sample symmetry, period `2(n − 1)`): the
/// extension of the B-spline prefilter.
fn mirror_index(m: isize, n: usize) -> usize {
    if n <= 1 {
        return 0;
    }
    let last = n - 1;
    let period = 2 * last as isize;
    let r = m.rem_euclid(period).unsigned_abs();
    if r > last { 2 * last - r } else { r }
}

/// Bricks of side `2^(level+1)` per axis for `dims`.
fn level_dims(dims: [usize; 3], shift: u32) -> [usize; 3] {
    dims.map(|d| ((d - 1) >> shift) + 1)
}

impl Pyramid {
    fn build<T: Copy + Into<f64> + Sync>(d: &[T], dims: [usize; 3]) -> Pyramid {
        let mut levels: Vec<Level> = Vec::new();
        let max_side = dims.iter().copied().max().unwrap_or(1);
        let mut shift = 1u32;
        while (max_side - 1) >> (shift - 1) > 0 {
            let ld = level_dims(dims, shift);
            let [lx, ly, lz] = ld;
            let mut range = vec![(f64::INFINITY, f64::NEG_INFINITY); lx * ly * lz];
            match levels.last() {
                None => {
                    range
                        .par_chunks_mut(lx * ly)
                        .enumerate()
                        .for_each(|(bz, slab)| {
                            for k in (bz << 1)..((bz << 1) + 2).min(dims[2]) {
                                for j in 0..dims[1] {
                                    let row = &d[dims[0] * (j + dims[1] * k)..][..dims[0]];
                                    let out = &mut slab[lx * (j >> 1)..][..lx];
                                    for (i, v) in row.iter().enumerate() {
                                        let v: f64 = (*v).into();
                                        let r = &mut out[i >> 1];
                                        r.0 = r.0.min(v);
                                        r.1 = r.1.max(v);
                                    }
                                }
                            }
                        });
                }
                Some(prev) => {
                    let [px, py, pz] = prev.dims;
                    range
                        .par_chunks_mut(lx * ly)
                        .enumerate()
                        .for_each(|(bz, slab)| {
                            for k in (bz << 1)..((bz << 1) + 2).min(pz) {
                                for j in 0..py {
                                    let row = &prev.range[px * (j + py * k)..][..px];
                                    let out = &mut slab[lx * (j >> 1)..][..lx];
                                    for (i, v) in row.iter().enumerate() {
                                        let r = &mut out[i >> 1];
                                        r.0 = r.0.min(v.0);
                                        r.1 = r.1.max(v.1);
                                    }
                                }
                            }
                        });
                }
            }
            levels.push(Level { dims: ld, range });
            shift += 1;
        }
        Pyramid { levels }
    }

    /// `(min, max)` of the values over the index box `lo..=hi` (a superset: whole bricks).
    fn range<T: Copy + Into<f64>>(
        &self,
        d: &[T],
        dims: [usize; 3],
        lo: [usize; 3],
        hi: [usize; 3],
    ) -> (f64, f64) {
        // The finest level at which the box meets at most 4 bricks per axis.
        let mut shift = 0u32;
        while (0..3).any(|a| (hi[a] >> shift) - (lo[a] >> shift) >= 4) {
            shift += 1;
        }
        let mut mn = f64::INFINITY;
        let mut mx = f64::NEG_INFINITY;
        if shift == 0 {
            for k in lo[2]..=hi[2] {
                for j in lo[1]..=hi[1] {
                    let o = dims[0] * (j + dims[1] * k);
                    for v in &d[o + lo[0]..=o + hi[0]] {
                        let v: f64 = (*v).into();
                        mn = mn.min(v);
                        mx = mx.max(v);
                    }
                }
            }
            return (mn, mx);
        }
        let Some(level) = self.levels.get(shift as usize - 1) else {
            // Not reached: the coarsest level has one brick per axis.
            return (f64::NEG_INFINITY, f64::INFINITY);
        };
        let [lx, ly, _] = level.dims;
        for k in (lo[2] >> shift)..=(hi[2] >> shift) {
            for j in (lo[1] >> shift)..=(hi[1] >> shift) {
                let o = lx * (j + ly * k);
                for r in &level.range[o + (lo[0] >> shift)..=o + (hi[0] >> shift)] {
                    mn = mn.min(r.0);
                    mx = mx.max(r.1);
                }
            }
        }
        (mn, mx)
    }
}

/// Key of the process-wide cache of loaded volumes.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct CacheKey {
    path: PathBuf,
    modified: Option<std::time::SystemTime>,
    len: u64,
    kernel: VoxelKernel,
    outside: Option<u64>,
}

static CACHE: Mutex<Option<HashMap<CacheKey, Weak<VoxelField>>>> = Mutex::new(None);

/// Read the volume file `path` (any format `volmorph-volume-io` reads, with its default
/// [`ReadOptions`](volmorph_volume_io::ReadOptions): the process's memory budget, external
/// data rule and frame) into a [`VoxelField`]. A file already loaded with the same kernel and
/// `outside` (and not changed since) is shared rather than read again, as long as a shape
/// still holds it.
///
/// # Errors
/// [`FrepError::Volume`] when the file cannot be read; as [`VoxelField::new`].
pub fn load(
    path: &Path,
    kernel: VoxelKernel,
    outside: Option<f64>,
) -> Result<Arc<VoxelField>, FrepError> {
    let canonical = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
    let meta = std::fs::metadata(&canonical).ok();
    let key = CacheKey {
        path: canonical,
        modified: meta.as_ref().and_then(|m| m.modified().ok()),
        len: meta.as_ref().map_or(0, std::fs::Metadata::len),
        kernel,
        outside: outside.map(f64::to_bits),
    };
    if let Ok(cache) = CACHE.lock()
        && let Some(hit) = cache
            .as_ref()
            .and_then(|c| c.get(&key))
            .and_then(Weak::upgrade)
    {
        return Ok(hit);
    }
    let volume = volmorph_volume_io::read(path)?;
    let field = Arc::new(VoxelField::new(
        &path.display().to_string(),
        &volume,
        kernel,
        outside,
    )?);
    if let Ok(mut cache) = CACHE.lock() {
        let map = cache.get_or_insert_with(HashMap::new);
        map.retain(|_, w| w.strong_count() > 0);
        map.insert(key, Arc::downgrade(&field));
    }
    Ok(field)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pyramid_ranges_enclose_the_values() {
        let dims = [7, 5, 9];
        let d: Vec<f32> = (0..7 * 5 * 9)
            .map(|i| ((i * 7919 % 97) as f32) - 40.0)
            .collect();
        let p = Pyramid::build(&d, dims);
        for (lo, hi) in [
            ([0, 0, 0], [6, 4, 8]),
            ([1, 2, 3], [2, 2, 3]),
            ([0, 1, 0], [6, 1, 8]),
            ([5, 0, 7], [6, 4, 8]),
        ] {
            let (mn, mx) = p.range(&d, dims, lo, hi);
            for k in lo[2]..=hi[2] {
                for j in lo[1]..=hi[1] {
                    for i in lo[0]..=hi[0] {
                        let v = f64::from(d[i + 7 * (j + 5 * k)]);
                        assert!(mn <= v && v <= mx, "{lo:?}..{hi:?}: {v} not in {mn}..{mx}");
                    }
                }
            }
        }
        // The whole box: exactly the data's range.
        let (mn, mx) = p.range(&d, dims, [0, 0, 0], [6, 4, 8]);
        assert_eq!(mn, -40.0);
        assert_eq!(mx, 56.0);
    }
}
