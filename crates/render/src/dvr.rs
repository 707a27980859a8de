//! Direct volume rendering on the CPU: ray casting with trilinear sampling, transfer
//! functions with step-corrected opacity, gradient shading, early ray termination and
//! empty-space skipping with a min–max octree.
//!
//! # Algorithm
//!
//! 1. **Preparation** ([`DvrVolume::new`]): voxel values are coded as `u16` (exactly for
//!    integer volumes spanning at most 65 536 values, such as CT in Hounsfield units;
//!    otherwise to 1/65 535 of the value range), and a [`MinMaxOctree`] over 8³-cell bricks is
//!    built. [`DvrRenderer::new`] tabulates the transfer function for the sampling step
//!    ([`TransferLut`]) and classifies the bricks: a brick is visible when some value in its
//!    range has a positive opacity (composite), or reaches the level (isosurface).
//! 2. **Rays** go through pixel centres ([`Camera::ray`]) and are clipped to the volume's box
//!    of voxel centres (physical, through spacing and direction, so the aspect and orientation
//!    are those of the scan) and to the optional cut-away plane.
//! 3. **Samples** lie at `t = k·Δ` along each ray (`Δ` the step in world units, `t` from the
//!    eye, or from the eye plane for orthographic cameras, where the samples therefore lie on
//!    view-aligned planes). A 3D DDA walks the bricks the ray crosses; invisible bricks are
//!    skipped whole. Skipping changes no sample: samples of a skipped brick are transparent.
//! 4. **Composite**: the value (trilinear) picks a table entry: linear colour `c` and the
//!    step's opacity `α = 1 − (1 − α_TF)^(Δ/unit)`. With shading, `c` is lit by the project's
//!    [`Shading`] with the gradient (central differences of the interpolated field, one voxel
//!    apart, mapped to world units) as normal. Front to back: `C += T·α·c`, `T ← T(1 − α)`.
//!    **Early termination** stops a ray when `T <` [`MIN_TRANSMITTANCE`]: what is left could
//!    change no 8-bit channel, even after sRGB encoding.
//! 5. **Maximum-intensity projection** keeps the largest value along the ray (bricks whose
//!    maximum cannot raise it are skipped) and shows its transfer-function colour with the
//!    function's opacity. **First-hit isosurface** stops at the first sample at or above the
//!    level, places the hit by linear interpolation from the previous sample, and shows the
//!    transfer function's colour at the level, shaded and opaque.
//! 6. Pixels are the composited linear colour over the background (in linear light), encoded
//!    to sRGB; a transparent background gives straight alpha.
//!
//! Rays run in parallel over picture rows (rayon); nothing is allocated per sample.

use std::sync::OnceLock;

use glam::{DMat3, DVec3, I16Vec4, Mat3, Vec3, Vec3A, Vec4, Vec4Swizzles};
use multiversion::multiversion;
use rayon::prelude::*;
use volmorph_volume::{AnyVolume, Geometry, Volume, Voxel, VoxelType, with_volume};

use crate::camera::Camera;
use crate::error::RenderError;
use crate::geometry::Ray;
use crate::image::RgbaImage;
use crate::octree::{DEFAULT_BRICK, MinMaxOctree, Visibility};
use crate::shading::{Lighting, Shading, ViewLighting, linear_to_srgb8_fast, srgb8_to_linear};
use crate::transfer::{DEFAULT_LUT_SIZE, TransferFunction, TransferLut};

/// Transmittance below which a ray stops (early termination): 1/4096. The light still to
/// come is at most `T` in linear units; sRGB encoding amplifies small values at most 12.92×,
/// so the encoded channel moves by less than 12.92/4096 ≈ 0.8/255 — never a full 8-bit step.
pub const MIN_TRANSMITTANCE: f32 = 1.0 / 4096.0;

/// Largest code of the `u16` voxel coding.
const CODE_MAX: f64 = 65_535.0;

/// A volume prepared for direct volume rendering: `u16`-coded values, geometry and a
/// min–max octree (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct DvrVolume {
    geometry: Geometry,
    dims: [usize; 3],
    data: Vec<u16>,
    /// Value of code 0.
    value_lo: f64,
    /// Value per code.
    value_step: f64,
    /// Largest code in use (the value range's top).
    code_max: u16,
    /// World → continuous index, linear part (`(direction · diag(spacing))⁻¹`).
    to_index: DMat3,
    octree: MinMaxOctree,
    /// Whether the source voxel type is an integer type.
    integer: bool,
    /// Largest cell index per axis (`n − 2`), as `f32`.
    max_cell: Vec3,
    /// Per voxel, for shaded pictures: the code less [`CODE_BIAS`] and the half central
    /// differences of the codes (one-sided at the faces), so that a sample reads its value and
    /// gradient in one 8-byte load per corner. Made on the first shaded picture.
    shaded: OnceLock<Vec<I16Vec4>>,
}

/// Offset of the codes in the shaded table ([`DvrVolume`]): `code − 32768` fits an `i16`, and
/// adding it back after the conversion to `f32` is exact.
const CODE_BIAS: f32 = 32_768.0;

/// Largest voxel count along an axis: cell indices are found in `f32` (`DvrVolume::cell_of`),
/// whose integers are exact and whose bits give the index below 2²³.
pub const MAX_DIMENSION: usize = 1 << 23;

/// `2²³`: adding it to an integral `f32` in `[0, 2²³)` puts the integer in the low mantissa
/// bits.
const MANTISSA_SHIFT: f32 = 8_388_608.0;

/// `v.floor()` lane by lane: one rounding instruction each where SSE4.1 is on (the AVX2
/// row kernel), where `Vec3A::floor` emulates it in about ten SSE2 instructions.
#[inline(always)]
fn floor(v: Vec3A) -> Vec3A {
    Vec3A::new(v.x.floor(), v.y.floor(), v.z.floor())
}

/// The integer in `[0, 2²³)` that the integral `x` stands for, without the saturating
/// float-to-integer conversion (its range checks cost a dozen instructions per axis).
#[inline(always)]
fn index_bits(x: f32) -> usize {
    ((x + MANTISSA_SHIFT).to_bits() & 0x7f_ffff) as usize
}

impl DvrVolume {
    /// Prepare `volume` of any voxel type.
    ///
    /// # Errors
    /// As [`DvrVolume::from_volume`].
    pub fn new(volume: &AnyVolume) -> Result<Self, RenderError> {
        with_volume!(volume, v => Self::from_volume(v))
    }

    /// Prepare a typed volume. NaN voxels are coded as the smallest value.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when the geometry is invalid, a dimension is below 2
    /// (nothing to interpolate) or above [`MAX_DIMENSION`], or no voxel value is finite.
    pub fn from_volume<T: Voxel>(volume: &Volume<T>) -> Result<Self, RenderError> {
        let geometry = *volume.geometry();
        geometry
            .validate()
            .map_err(|e| RenderError::invalid(format!("volume geometry: {e}")))?;
        let dims = geometry.dims;
        if dims.iter().any(|&d| d < 2) {
            return Err(RenderError::invalid(format!(
                "a volume of {dims:?} voxels has nothing to render (at least 2 per axis)"
            )));
        }
        if dims.iter().any(|&d| d > MAX_DIMENSION) {
            return Err(RenderError::invalid(format!(
                "a volume of {dims:?} voxels is too long to render (at most {MAX_DIMENSION} per \
                 axis)"
            )));
        }
        let (lo, hi) = volume
            .data()
            .par_iter()
            .map(|v| v.to_f64())
            .filter(|v| v.is_finite())
            .fold(
                || (f64::INFINITY, f64::NEG_INFINITY),
                |(a, b), v| (a.min(v), b.max(v)),
            )
            .reduce(
                || (f64::INFINITY, f64::NEG_INFINITY),
                |(a, b), (c, d)| (a.min(c), b.max(d)),
            );
        // The folds skip non-finite values, so lo > hi means none was finite.
        if lo > hi {
            return Err(RenderError::invalid("no voxel value is finite"));
        }
        let float = matches!(T::TYPE, VoxelType::F32 | VoxelType::F64);
        let value_step = if !float && hi - lo <= CODE_MAX {
            1.0
        } else if hi > lo {
            (hi - lo) / CODE_MAX
        } else {
            1.0
        };
        let inv = 1.0 / value_step;
        let code_max = ((hi - lo) * inv).round().clamp(0.0, CODE_MAX) as u16;
        let data: Vec<u16> = volume
            .data()
            .par_iter()
            .map(|v| {
                let x = (v.to_f64() - lo) * inv;
                if x.is_nan() {
                    0
                } else {
                    x.round().clamp(0.0, CODE_MAX) as u16
                }
            })
            .collect();
        let octree = MinMaxOctree::new(&data, dims, DEFAULT_BRICK)?;
        Ok(Self {
            to_index: geometry.index_to_physical_matrix().inverse(),
            geometry,
            dims,
            data,
            value_lo: lo,
            value_step,
            code_max,
            octree,
            integer: !float,
            max_cell: Vec3::new(
                (dims[0] - 2) as f32,
                (dims[1] - 2) as f32,
                (dims[2] - 2) as f32,
            ),
            shaded: OnceLock::new(),
        })
    }

    /// The volume's geometry.
    #[must_use]
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// Whether the source voxels were integers (their values are then coded exactly when they
    /// span at most 65 536 values).
    #[must_use]
    pub fn is_integer(&self) -> bool {
        self.integer
    }

    /// Smallest and largest finite voxel value.
    #[must_use]
    pub fn value_range(&self) -> (f64, f64) {
        (self.value_lo, self.value_of_code(f64::from(self.code_max)))
    }

    /// The value a (continuous) code stands for.
    #[must_use]
    pub fn value_of_code(&self, code: f64) -> f64 {
        self.value_lo + code * self.value_step
    }

    /// The (continuous) code of a value.
    #[must_use]
    pub fn code_of_value(&self, value: f64) -> f64 {
        (value - self.value_lo) / self.value_step
    }

    /// The `lo`-th and `hi`-th percentiles (0‥=100) of the voxel values, from the histogram
    /// of codes (exact for integer volumes, to one code otherwise).
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] unless `0 ≤ lo ≤ hi ≤ 100`.
    pub fn percentiles(&self, lo: f64, hi: f64) -> Result<(f64, f64), RenderError> {
        if !((0.0..=100.0).contains(&lo) && (0.0..=100.0).contains(&hi) && lo <= hi) {
            return Err(RenderError::invalid(format!(
                "percentiles must satisfy 0 ≤ lo ≤ hi ≤ 100, got {lo} and {hi}"
            )));
        }
        let hist = self
            .data
            .par_chunks(1 << 16)
            .fold(
                || vec![0u64; usize::from(self.code_max) + 1],
                |mut h, c| {
                    for &q in c {
                        h[usize::from(q)] += 1;
                    }
                    h
                },
            )
            .reduce_with(|mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            })
            .unwrap_or_default();
        let n = self.data.len() as f64;
        let at = |p: f64| -> f64 {
            let rank = (p / 100.0 * (n - 1.0)).round() as u64;
            let mut seen = 0u64;
            for (q, &c) in hist.iter().enumerate() {
                seen += c;
                if seen > rank {
                    return self.value_of_code(q as f64);
                }
            }
            self.value_of_code(f64::from(self.code_max))
        };
        Ok((at(lo), at(hi)))
    }

    /// The min–max octree of the codes.
    #[must_use]
    pub fn octree(&self) -> &MinMaxOctree {
        &self.octree
    }

    /// Physical point → continuous index.
    #[must_use]
    pub fn index_of(&self, p: DVec3) -> DVec3 {
        self.to_index * (p - self.geometry.origin)
    }

    /// Continuous index → physical point.
    #[must_use]
    pub fn point_of(&self, index: DVec3) -> DVec3 {
        self.geometry.index_to_physical(index)
    }

    /// Trilinear code at continuous index `u`, clamped to the grid box.
    #[inline(always)]
    pub(crate) fn sample(&self, u: Vec3) -> f32 {
        let (o, f) = self.cell_of(u);
        self.sample_cell(o, f)
    }

    /// The cell containing continuous index `u`: the offset of its low corner voxel and the
    /// fractions within it. Below 0 the cell is 0 with a negative fraction, beyond n − 1 the
    /// last cell with a fraction above 1: both only by rounding, as callers clip rays to the
    /// box.
    #[inline(always)]
    pub(crate) fn cell_of(&self, u: Vec3) -> (usize, Vec3) {
        let [nx, ny, _] = self.dims;
        // floor, then clamp to the cells: the same cell as truncating and clamping (they
        // differ only below 0, where both clamp to 0), found in the vector unit.
        let c = floor(u.into()).clamp(Vec3A::ZERO, self.max_cell.into());
        let f = Vec3::from(Vec3A::from(u) - c);
        let (i, j, k) = (index_bits(c.x), index_bits(c.y), index_bits(c.z));
        (i + nx * (j + ny * k), f)
    }

    /// Trilinear code in the cell at offset `o` with fractions `f` (see [`Self::cell_of`]).
    #[inline(always)]
    pub(crate) fn sample_cell(&self, o: usize, f: Vec3) -> f32 {
        let [nx, ny, _] = self.dims;
        let (sy, sz) = (nx, nx * ny);
        let d = &self.data[o..o + sz + sy + 2];
        let v = |n: usize| f32::from(d[n]);
        let c00 = v(0) + f.x * (v(1) - v(0));
        let c10 = v(sy) + f.x * (v(sy + 1) - v(sy));
        let c01 = v(sz) + f.x * (v(sz + 1) - v(sz));
        let c11 = v(sz + sy) + f.x * (v(sz + sy + 1) - v(sz + sy));
        let c0 = c00 + f.y * (c10 - c00);
        let c1 = c01 + f.y * (c11 - c01);
        c0 + f.z * (c1 - c0)
    }

    /// Per cell (indexed by its low corner voxel; the last layer along each axis is unused):
    /// whether `visible(min, max)` holds for the codes of its eight corners.
    fn cell_visibility(&self, visible: impl Fn(u16, u16) -> bool + Sync) -> CellBits {
        let [nx, ny, nz] = self.dims;
        let plane = nx * ny;
        let d = &self.data;
        let mut out = vec![false; d.len()];
        out.par_chunks_mut(plane)
            .enumerate()
            .take(nz - 1)
            .for_each(|(k, slab)| {
                let (lo, hi) = (&d[k * plane..][..plane], &d[(k + 1) * plane..][..plane]);
                for j in 0..ny - 1 {
                    let rows = [
                        &lo[j * nx..][..nx],
                        &lo[(j + 1) * nx..][..nx],
                        &hi[j * nx..][..nx],
                        &hi[(j + 1) * nx..][..nx],
                    ];
                    let out = &mut slab[j * nx..][..nx];
                    for i in 0..nx - 1 {
                        let (mut mn, mut mx) = (u16::MAX, 0u16);
                        for r in rows {
                            mn = mn.min(r[i]).min(r[i + 1]);
                            mx = mx.max(r[i]).max(r[i + 1]);
                        }
                        out[i] = visible(mn, mx);
                    }
                }
            });
        CellBits::from_bools(&out)
    }

    /// Gradient of the interpolated codes at `u` (clamped to the grid box), per unit of
    /// index: the trilinear interpolation of the voxels' central differences, which equals the
    /// central difference of the interpolated field one voxel apart wherever both ends are
    /// inside the grid.
    #[inline(always)]
    pub(crate) fn gradient(&self, u: Vec3) -> Vec3 {
        let [nx, ny, nz] = self.dims;
        let u = u.clamp(
            Vec3::ZERO,
            Vec3::new((nx - 1) as f32, (ny - 1) as f32, (nz - 1) as f32),
        );
        let (o, f) = self.cell_of(u);
        self.gradient_cell(o, f)
    }

    /// [`Self::gradient`] in the cell at offset `o` with fractions `f` (see
    /// [`Self::cell_of`]): for a sample whose cell is known, equal to `gradient(u)` for `u`
    /// in the grid box.
    #[inline(always)]
    pub(crate) fn gradient_cell(&self, o: usize, f: Vec3) -> Vec3 {
        self.sample_shaded(o, f).yzw()
    }

    /// The code ([`Self::sample_cell`], the same bits) and the gradient ([`Self::gradient_cell`])
    /// in the cell at offset `o` with fractions `f`, as `(code, ∂x, ∂y, ∂z)`: both from one
    /// trilinear interpolation of the shaded table's four lanes (each lane as
    /// `a + f·(b − a)`).
    #[inline(always)]
    pub(crate) fn sample_shaded(&self, o: usize, f: Vec3) -> Vec4 {
        let [nx, ny, _] = self.dims;
        let (sy, sz) = (nx, nx * ny);
        // One bounds check for the eight corners.
        let g = &self.shaded_table()[o..o + sz + sy + 2];
        let bias = Vec4::new(CODE_BIAS, 0.0, 0.0, 0.0);
        let v = |n: usize| g[n].as_vec4() + bias;
        let lerp = |a: Vec4, b: Vec4, t: f32| a + Vec4::splat(t) * (b - a);
        let c00 = lerp(v(0), v(1), f.x);
        let c10 = lerp(v(sy), v(sy + 1), f.x);
        let c01 = lerp(v(sz), v(sz + 1), f.x);
        let c11 = lerp(v(sz + sy), v(sz + sy + 1), f.x);
        let c0 = lerp(c00, c10, f.y);
        let c1 = lerp(c01, c11, f.y);
        lerp(c0, c1, f.z)
    }

    /// The shaded table (codes and gradients per voxel), computed on first use (in parallel
    /// over z-slices).
    fn shaded_table(&self) -> &[I16Vec4] {
        self.shaded.get_or_init(|| {
            let [nx, ny, nz] = self.dims;
            let d = &self.data;
            let plane = nx * ny;
            // Half differences rounded towards −∞ (an arithmetic shift): at most 32767 in
            // magnitude for 16-bit codes, so they fit an i16.
            let half = |a: u16, b: u16| ((i32::from(a) - i32::from(b)) >> 1) as i16;
            let bias = |q: u16| (i32::from(q) - CODE_BIAS as i32) as i16;
            let mut g = vec![I16Vec4::ZERO; d.len()];
            g.par_chunks_mut(plane).enumerate().for_each(|(k, slab)| {
                let here = &d[k * plane..][..plane];
                let below = &d[k.saturating_sub(1) * plane..][..plane];
                let above = &d[(k + 1).min(nz - 1) * plane..][..plane];
                for j in 0..ny {
                    let row = &here[j * nx..][..nx];
                    let prev = &here[j.saturating_sub(1) * nx..][..nx];
                    let next = &here[(j + 1).min(ny - 1) * nx..][..nx];
                    let (lo, hi) = (&below[j * nx..][..nx], &above[j * nx..][..nx]);
                    let out = &mut slab[j * nx..][..nx];
                    for i in 0..nx {
                        let (i0, i1) = (i.saturating_sub(1), (i + 1).min(nx - 1));
                        out[i] = I16Vec4::new(
                            bias(row[i]),
                            half(row[i1], row[i0]),
                            half(next[i], prev[i]),
                            half(hi[i], lo[i]),
                        );
                    }
                }
            });
            g
        })
    }

    /// The box of voxel centres in index space.
    pub(crate) fn index_box(&self) -> Vec3 {
        Vec3::new(
            (self.dims[0] - 1) as f32,
            (self.dims[1] - 1) as f32,
            (self.dims[2] - 1) as f32,
        )
    }
}

/// What a ray accumulates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RenderMode {
    /// Emission–absorption compositing through the transfer function.
    Composite,
    /// Maximum-intensity projection.
    MaximumIntensity,
    /// First hit of the isosurface at `level` (data units), shaded and opaque.
    Isosurface {
        /// Iso level.
        level: f64,
    },
}

/// A cut-away: the half-space the normal points into is removed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipPlane {
    /// A point of the plane (world coordinates).
    pub point: DVec3,
    /// Normal pointing into the removed half (any length, not zero).
    pub normal: DVec3,
}

/// Options of a [`DvrRenderer`].
#[derive(Debug, Clone, PartialEq)]
pub struct DvrOptions {
    /// What rays accumulate.
    pub mode: RenderMode,
    /// Value → colour and opacity.
    pub transfer: TransferFunction,
    /// Gradient shading; `None`: the transfer function's colours unlit.
    pub shading: Option<Shading>,
    /// Step between samples along a ray, world units; `None`: half the smallest voxel spacing.
    pub step: Option<f64>,
    /// Colour behind the volume (straight alpha; 8-bit sRGB).
    pub background: [u8; 4],
    /// Optional cut-away plane.
    pub clip: Option<ClipPlane>,
    /// Stop rays once they are opaque ([`MIN_TRANSMITTANCE`]).
    pub early_termination: bool,
    /// Skip bricks the transfer function makes invisible.
    pub skip_empty_space: bool,
    /// Entries of the transfer-function table.
    pub lut_size: usize,
}

impl DvrOptions {
    /// Composite rendering through `transfer`, shaded, with early termination and
    /// empty-space skipping, on black.
    #[must_use]
    pub fn new(transfer: TransferFunction) -> Self {
        Self {
            mode: RenderMode::Composite,
            transfer,
            shading: Some(Shading::default()),
            step: None,
            background: [0, 0, 0, 255],
            clip: None,
            early_termination: true,
            skip_empty_space: true,
            lut_size: DEFAULT_LUT_SIZE,
        }
    }
}

/// A renderer of one [`DvrVolume`] with fixed options: the transfer table and brick
/// classification are made once, and every [`DvrRenderer::render`] reuses them (turntables,
/// interactive views).
#[derive(Debug, Clone)]
pub struct DvrRenderer<'a> {
    pub(crate) volume: &'a DvrVolume,
    pub(crate) options: DvrOptions,
    pub(crate) step: f32,
    pub(crate) lut: TransferLut,
    /// Step opacity per table entry, apart from the colours so that transparent samples (most
    /// of them) touch only this 16 kB table.
    pub(crate) alpha: Vec<f32>,
    /// Linear colour per table entry.
    pub(crate) rgb: Vec<Vec3>,
    /// LUT entries per code.
    pub(crate) per_code: f32,
    pub(crate) visibility: Visibility,
    /// Chessboard distance, in bricks, from each brick to the nearest visible one (0:
    /// visible), capped at 255: a ray in a brick at distance `d` crosses only invisible bricks
    /// while it moves less than `(d − 1)` bricks along every axis.
    pub(crate) leap: Vec<u8>,
    /// Per cell (low corner voxel offset): whether a sample in it can be visible, the same
    /// test as the bricks' on the cell's eight corners (empty for maximum-intensity
    /// projection).
    pub(crate) cells: CellBits,
    /// Iso level as a code.
    pub(crate) level_code: f32,
}

impl<'a> DvrRenderer<'a> {
    /// Prepare rendering `volume` with `options`.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for a step that is not finite and positive, an
    /// invalid shading, clip plane or iso level, or a table size outside 2‥=2²⁴.
    pub fn new(volume: &'a DvrVolume, options: DvrOptions) -> Result<Self, RenderError> {
        let spacing = volume.geometry.spacing;
        let step = options
            .step
            .unwrap_or(0.5 * spacing.x.min(spacing.y).min(spacing.z));
        if !(step > 0.0 && step.is_finite()) {
            return Err(RenderError::invalid(format!(
                "sampling step {step} must be finite and positive"
            )));
        }
        if let Some(s) = &options.shading {
            s.validate()?;
            // Normals come from the shaded table: make it now, not inside the first picture.
            volume.shaded_table();
        }
        if let Some(c) = &options.clip
            && !(c.point.is_finite() && c.normal.is_finite() && c.normal.length_squared() > 0.0)
        {
            return Err(RenderError::invalid(format!(
                "clip plane through {} with normal {} must be finite with a non-zero normal",
                c.point, c.normal
            )));
        }
        let level_code = match options.mode {
            RenderMode::Isosurface { level } if !level.is_finite() => {
                return Err(RenderError::invalid(format!(
                    "iso level {level} must be finite"
                )));
            }
            RenderMode::Isosurface { level } => volume.code_of_value(level) as f32,
            _ => 0.0,
        };
        let lut = TransferLut::new(
            &options.transfer,
            volume.value_range(),
            options.lut_size,
            step,
        )?;
        let per_code = if volume.code_max > 0 {
            (lut.len() - 1) as f32 / f32::from(volume.code_max)
        } else {
            0.0
        };
        let index = |q: u16| {
            ((f32::from(q) * per_code + 0.5) as i32).clamp(0, lut.len() as i32 - 1) as usize
        };
        let composite = |mn: u16, mx: u16| lut.any_visible(index(mn), index(mx));
        let iso = |_: u16, mx: u16| f32::from(mx) >= level_code;
        let (visibility, cells) = match options.mode {
            RenderMode::Composite => (
                volume.octree.classify(composite),
                volume.cell_visibility(composite),
            ),
            RenderMode::Isosurface { .. } => {
                (volume.octree.classify(iso), volume.cell_visibility(iso))
            }
            RenderMode::MaximumIntensity => (
                volume.octree.classify(|_, _| true),
                CellBits::from_bools(&[]),
            ),
        };
        let leap = chessboard_distance(&visibility, volume.octree.level_dims(0));
        let alpha = lut.entries().iter().map(|e| e[3]).collect();
        let rgb = lut
            .entries()
            .iter()
            .map(|e| Vec3::new(e[0], e[1], e[2]))
            .collect();
        Ok(Self {
            volume,
            options,
            step: step as f32,
            alpha,
            rgb,
            lut,
            per_code,
            visibility,
            leap,
            cells,
            level_code,
        })
    }

    /// The transfer function.
    #[must_use]
    pub fn transfer(&self) -> &TransferFunction {
        &self.options.transfer
    }

    /// The sampling step in world units.
    #[must_use]
    pub fn step(&self) -> f64 {
        f64::from(self.step)
    }

    /// Number of bricks that can show something under the transfer function (composite) or
    /// reach the level (isosurface), and the number of bricks.
    #[must_use]
    pub fn visible_bricks(&self) -> (usize, usize) {
        let d = self.volume.octree.level_dims(0);
        (self.visibility.count(0), d[0] * d[1] * d[2])
    }

    /// The picture `camera` takes of the volume.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for invalid shading parameters;
    /// [`RenderError::Size`] for an oversized picture.
    pub fn render(&self, camera: &Camera) -> Result<RgbaImage, RenderError> {
        let lighting = self.lighting(camera)?;
        self.render_rows(
            camera,
            &Undeformed {
                renderer: self,
                lighting,
            },
        )
    }

    /// The lighting of a picture by `camera`, if shading is on.
    pub(crate) fn lighting(&self, camera: &Camera) -> Result<Option<Lighting>, RenderError> {
        self.options
            .shading
            .as_ref()
            .map(|s| s.for_camera(camera))
            .transpose()
    }

    /// Run `caster` for every pixel's ray (rows in parallel) and encode the result.
    pub(crate) fn render_rows<C: Caster>(
        &self,
        camera: &Camera,
        caster: &C,
    ) -> Result<RgbaImage, RenderError> {
        let (w, h) = (camera.width(), camera.height());
        let mut img = RgbaImage::new(w, h, [0; 4])?;
        let bg = self.options.background;
        let bg_alpha = f32::from(bg[3]) / 255.0;
        let bg_lin = [0, 1, 2].map(|c| srgb8_to_linear(bg[c]) as f32 * bg_alpha);
        img.pixels_mut()
            .par_chunks_mut(w as usize)
            .enumerate()
            .for_each(|(y, row)| row_kernel(camera, y as u32, row, caster, bg_lin, bg_alpha, bg));
        Ok(img)
    }

    /// Whether a region whose codes span `[mn, mx]` can show anything in this mode.
    pub(crate) fn range_visible(&self, mn: u16, mx: u16) -> bool {
        match self.options.mode {
            RenderMode::Composite => {
                let i = |q: u16| self.entry_index(f32::from(q));
                self.lut.any_visible(i(mn), i(mx))
            }
            RenderMode::Isosurface { .. } => f32::from(mx) >= self.level_code,
            RenderMode::MaximumIntensity => true,
        }
    }

    /// Whether a sample in the volume cell at offset `cell` can be visible.
    #[inline(always)]
    pub(crate) fn cells_visible(&self, cell: usize) -> bool {
        self.cells.get(cell)
    }

    /// Table entry of a code.
    #[inline(always)]
    pub(crate) fn entry_index(&self, q: f32) -> usize {
        ((q * self.per_code + 0.5) as i32).clamp(0, self.alpha.len() as i32 - 1) as usize
    }

    /// Cast one ray through the undeformed volume.
    #[inline(always)]
    fn cast(&self, ray: &Ray, lighting: Option<&Lighting>) -> RayResult {
        let vol = self.volume;
        let o = (vol.to_index * (ray.origin - vol.geometry.origin)).as_vec3();
        let d = (vol.to_index * ray.dir).as_vec3();
        let Some((t0, t1)) = self.clip_interval(ray, o, d, vol.index_box()) else {
            return RayResult::EMPTY;
        };
        let grad_to_world: Mat3 = vol.to_index.transpose().as_mat3();
        let mut acc = Accumulator::new(self, lighting, -ray.dir.as_vec3());
        let skip = self.options.skip_empty_space;
        let octree = &vol.octree;
        let brick = octree.brick() as f32;
        let inv_brick = 1.0 / brick;
        let [bx, by, bz] = octree.level_dims(0);
        let max_leaf = Vec3A::new((bx - 1) as f32, (by - 1) as f32, (bz - 1) as f32);
        // Parameter length of one brick along the ray's fastest axis.
        let brick_t = brick / d.abs().max_element();
        // Per axis: the brick face a ray leaves through (0 or 1 brick ahead) and 1/d.
        let exit_side = Vec3A::from(Vec3::select(d.cmpgt(Vec3::ZERO), Vec3::ONE, Vec3::ZERO));
        let inv_d = Vec3A::from(d.recip());
        let (oa, da) = (Vec3A::from(o), Vec3A::from(d));
        // Composite pictures with shading read code and gradient together.
        let shaded = acc.lighting.is_some() && matches!(self.options.mode, RenderMode::Composite);
        let mip = matches!(self.options.mode, RenderMode::MaximumIntensity);
        let inv_step = 1.0 / self.step;
        // Sample k lies at t = k·Δ; the first is the first at or after t0.
        let mut k = (t0 * inv_step).ceil() as u32;
        'ray: loop {
            let t = k as f32 * self.step;
            if t >= t1 {
                break;
            }
            // Samples up to `run_end` need no brick test: the whole brick is visible.
            let mut run_end = t1;
            if skip {
                // The brick of the sample (floor and clamp: the brick that truncating and
                // clamping gives) and the parameter where the ray leaves it.
                let b = floor((oa + da * t) * inv_brick).clamp(Vec3A::ZERO, max_leaf);
                let leaf = [index_bits(b.x), index_bits(b.y), index_bits(b.z)];
                // (As Vec3: its minimum ignores the NaN of a face in the plane of an axis the
                // ray does not move along.)
                let exit = Vec3::from(((b + exit_side) * brick - oa) * inv_d).min_element();
                if mip {
                    if f32::from(octree.range(0, leaf).1) <= acc.max_code {
                        k = k.max((exit * inv_step) as u32) + 1;
                        continue;
                    }
                } else {
                    let dist = self.leap[leaf[0] + bx * (leaf[1] + by * leaf[2])];
                    if dist > 0 {
                        // Leap over the bricks known to be empty: to where the ray leaves
                        // this brick, or further while it stays within dist − 1 bricks (every
                        // point up to there is in an invisible brick), and on to the next
                        // sample beyond.
                        let ahead = exit.max(t + f32::from(dist - 1) * brick_t);
                        k = k.max((ahead * inv_step) as u32) + 1;
                        continue;
                    }
                }
                run_end = exit.min(t1);
            }
            // The first sample always runs (progress even if rounding puts the exit before it).
            let mut first = true;
            loop {
                let t = k as f32 * self.step;
                if t >= t1 || (!first && t >= run_end) {
                    break;
                }
                first = false;
                let u = o + d * t;
                let (cell, f) = vol.cell_of(u);
                if skip && !mip && !self.cells.get(cell) {
                    k += 1;
                    continue;
                }
                let stop = if shaded {
                    let s = vol.sample_shaded(cell, f);
                    acc.composite(s.x, || grad_to_world * s.yzw())
                } else {
                    acc.add(
                        vol.sample_cell(cell, f),
                        || (t - self.step >= t0).then(|| vol.sample(o + d * (t - self.step))),
                        |s| {
                            grad_to_world
                                * if s == 0.0 {
                                    vol.gradient_cell(cell, f)
                                } else {
                                    vol.gradient(u - d * (self.step * s))
                                }
                        },
                    )
                };
                k += 1;
                if stop {
                    break 'ray;
                }
            }
        }
        acc.finish(self)
    }

    /// The parameter interval of `ray` inside the index box `[0, hi]` (ray in index space:
    /// `o + t·d`) and outside the cut-away, or `None`.
    pub(crate) fn clip_interval(
        &self,
        ray: &Ray,
        o: Vec3,
        d: Vec3,
        hi: Vec3,
    ) -> Option<(f32, f32)> {
        let (mut t0, mut t1) = slab(o, d, Vec3::ZERO, hi)?;
        t0 = t0.max(0.0);
        if let Some(c) = &self.options.clip {
            let s0 = c.normal.dot(ray.origin - c.point);
            let sd = c.normal.dot(ray.dir);
            // Keep s0 + t·sd ≤ 0.
            if sd == 0.0 {
                if s0 > 0.0 {
                    return None;
                }
            } else {
                let t = (-s0 / sd) as f32;
                if sd > 0.0 {
                    t1 = t1.min(t);
                } else {
                    t0 = t0.max(t);
                }
            }
        }
        (t0 < t1).then_some((t0, t1))
    }
}

/// One bit per cell, packed (an eighth of the memory of `bool`s, so that the per-sample test
/// stays in cache).
#[derive(Debug, Clone)]
pub(crate) struct CellBits(Vec<u64>);

impl CellBits {
    fn from_bools(b: &[bool]) -> Self {
        Self(
            b.chunks(64)
                .map(|c| {
                    c.iter()
                        .enumerate()
                        .fold(0u64, |w, (i, &v)| w | (u64::from(v) << i))
                })
                .collect(),
        )
    }

    #[inline(always)]
    fn get(&self, i: usize) -> bool {
        self.0[i >> 6] >> (i & 63) & 1 == 1
    }
}

/// Chessboard (L∞) distance, in nodes, from every node of a grid of `dims` to the nearest
/// visible node of `visibility`'s level 0 (0 for visible nodes), capped at 255, by a forward
/// and a backward raster pass over the 13 causal neighbours each (exact for this metric).
fn chessboard_distance(visibility: &Visibility, dims: [usize; 3]) -> Vec<u8> {
    let [nx, ny, nz] = dims;
    let mut dist: Vec<u8> = (0..nx * ny * nz)
        .map(|n| {
            let (i, j, k) = (n % nx, n / nx % ny, n / (nx * ny));
            if visibility.visible(0, [i, j, k]) {
                0
            } else {
                u8::MAX
            }
        })
        .collect();
    let idx = |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    // Neighbour offsets before (i, j, k) in raster order; the backward pass mirrors them.
    let mut causal = Vec::new();
    for dk in -1i64..=0 {
        for dj in -1i64..=1 {
            for di in -1i64..=1 {
                if dk < 0 || dj < 0 || (dj == 0 && di < 0) {
                    causal.push((di, dj, dk));
                }
            }
        }
    }
    let relax = |dist: &mut Vec<u8>, i: usize, j: usize, k: usize, sign: i64| {
        let here = idx(i, j, k);
        let mut best = dist[here];
        for &(di, dj, dk) in &causal {
            let (a, b, c) = (
                i as i64 + sign * di,
                j as i64 + sign * dj,
                k as i64 + sign * dk,
            );
            if a < 0 || b < 0 || c < 0 || a >= nx as i64 || b >= ny as i64 || c >= nz as i64 {
                continue;
            }
            best = best.min(dist[idx(a as usize, b as usize, c as usize)].saturating_add(1));
        }
        dist[here] = best;
    };
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                relax(&mut dist, i, j, k, 1);
            }
        }
    }
    for k in (0..nz).rev() {
        for j in (0..ny).rev() {
            for i in (0..nx).rev() {
                relax(&mut dist, i, j, k, -1);
            }
        }
    }
    dist
}

/// The slab intersection of the ray `o + t·d` with the box `[lo, hi]`, if any.
#[inline]
pub(crate) fn slab(o: Vec3, d: Vec3, lo: Vec3, hi: Vec3) -> Option<(f32, f32)> {
    let mut t0 = f32::NEG_INFINITY;
    let mut t1 = f32::INFINITY;
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
        } else {
            let inv = 1.0 / d[a];
            let (ta, tb) = ((lo[a] - o[a]) * inv, (hi[a] - o[a]) * inv);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    (t0 <= t1 && t1.is_finite() && t0.is_finite()).then_some((t0, t1))
}

/// What one ray produced: premultiplied linear colour and opacity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RayResult {
    pub color: [f32; 3],
    pub alpha: f32,
}

impl RayResult {
    pub const EMPTY: Self = Self {
        color: [0.0; 3],
        alpha: 0.0,
    };
}

/// What casts the rays of a picture for [`row_kernel`]. Implementations mark
/// [`Caster::cast`] `#[inline(always)]`: the ray loop must inline into the kernel to be
/// compiled in its AVX2 and FMA version (a closure was compiled apart, for the baseline
/// target only).
pub(crate) trait Caster: Sync {
    /// The result of one pixel's ray.
    fn cast(&self, ray: &Ray) -> RayResult;
}

/// The rays of an undeformed picture.
struct Undeformed<'r, 'a> {
    renderer: &'r DvrRenderer<'a>,
    lighting: Option<Lighting>,
}

impl Caster for Undeformed<'_, '_> {
    #[inline(always)]
    fn cast(&self, ray: &Ray) -> RayResult {
        self.renderer.cast(ray, self.lighting.as_ref())
    }
}

/// One picture row: cast and encode every pixel. Compiled also for AVX2 and FMA, chosen at
/// run time (the ray loops inline into it through [`Caster::cast`], so rounding and
/// multiply-adds become single instructions there).
#[multiversion(targets("x86_64+avx2+fma"))]
fn row_kernel<C: Caster>(
    camera: &Camera,
    y: u32,
    row: &mut [[u8; 4]],
    caster: &C,
    bg_lin: [f32; 3],
    bg_alpha: f32,
    bg: [u8; 4],
) {
    for (x, px) in row.iter_mut().enumerate() {
        let r = caster.cast(&camera.ray(x as u32, y));
        *px = encode(r, bg_lin, bg_alpha, bg);
    }
}

/// A ray's result over the background (premultiplied linear `bg_lin`, alpha `bg_alpha`),
/// encoded to straight-alpha sRGB.
#[inline]
fn encode(r: RayResult, bg_lin: [f32; 3], bg_alpha: f32, bg: [u8; 4]) -> [u8; 4] {
    if r.alpha == 0.0 {
        return if bg[3] == 0 { [0; 4] } else { bg };
    }
    let t = 1.0 - r.alpha;
    let a = r.alpha + t * bg_alpha;
    if a <= 0.0 {
        return [0; 4];
    }
    let c = |k: usize| linear_to_srgb8_fast((r.color[k] + t * bg_lin[k]) / a);
    [
        c(0),
        c(1),
        c(2),
        (f64::from(a.min(1.0)) * 255.0).round() as u8,
    ]
}

/// Front-to-back state of one ray for every mode.
pub(crate) struct Accumulator<'r> {
    renderer: &'r DvrRenderer<'r>,
    pub lighting: Option<ViewLighting>,
    color: Vec3,
    trans: f32,
    /// Largest code seen (maximum-intensity projection), −1 before any sample.
    pub max_code: f32,
    /// Isosurface hit colour, once found.
    hit: Option<Vec3>,
}

impl<'r> Accumulator<'r> {
    pub(crate) fn new(
        renderer: &'r DvrRenderer<'r>,
        lighting: Option<&Lighting>,
        to_viewer: Vec3,
    ) -> Self {
        Self {
            renderer,
            lighting: lighting.map(|l| l.for_view(to_viewer)),
            color: Vec3::ZERO,
            trans: 1.0,
            max_code: -1.0,
            hit: None,
        }
    }

    /// Lighting factors for a world-space gradient.
    #[inline(always)]
    fn light(&self, grad: impl FnOnce() -> Vec3) -> (f32, f32) {
        match &self.lighting {
            Some(l) => l.factors(grad()),
            None => (1.0, 0.0),
        }
    }

    /// Add the composite sample of code `q` whose world gradient `grad` gives (called only
    /// for a visible sample with shading on). Returns whether the ray is finished.
    #[inline(always)]
    pub(crate) fn composite(&mut self, q: f32, grad: impl FnOnce() -> Vec3) -> bool {
        let r = self.renderer;
        let i = r.entry_index(q);
        let a = r.alpha[i];
        if a > 0.0 {
            let (k, s) = self.light(grad);
            let c = (r.rgb[i] * k + Vec3::splat(s)).min(Vec3::ONE);
            self.color += c * (self.trans * a);
            self.trans *= 1.0 - a;
            return r.options.early_termination && self.trans < MIN_TRANSMITTANCE;
        }
        false
    }

    /// Add the sample of code `q`. `previous` gives, for the isosurface only, the code of the
    /// previous sample on the ray (if the ray had one); `grad_back(s)` is the world gradient
    /// at the point `s` steps back along the ray from this sample (`0 ≤ s < 1`; composite
    /// shading uses `s = 0`, the isosurface the interpolated crossing). Returns whether the
    /// ray is finished.
    #[inline(always)]
    pub(crate) fn add(
        &mut self,
        q: f32,
        previous: impl FnOnce() -> Option<f32>,
        grad_back: impl Fn(f32) -> Vec3,
    ) -> bool {
        let r = self.renderer;
        match r.options.mode {
            RenderMode::Composite => self.composite(q, || grad_back(0.0)),
            RenderMode::MaximumIntensity => {
                self.max_code = self.max_code.max(q);
                false
            }
            RenderMode::Isosurface { .. } => {
                if q < r.level_code {
                    return false;
                }
                let back = match previous() {
                    Some(p) if p < r.level_code => 1.0 - (r.level_code - p) / (q - p),
                    _ => 0.0,
                };
                let c = r.rgb[r.entry_index(r.level_code.max(0.0))];
                let (k, s) = self.light(|| grad_back(back));
                self.hit = Some((c * k + Vec3::splat(s)).min(Vec3::ONE));
                true
            }
        }
    }

    /// The ray's result.
    pub(crate) fn finish(&self, r: &DvrRenderer<'_>) -> RayResult {
        match r.options.mode {
            RenderMode::Composite => RayResult {
                color: self.color.to_array(),
                alpha: 1.0 - self.trans,
            },
            RenderMode::MaximumIntensity => {
                if self.max_code < 0.0 {
                    return RayResult::EMPTY;
                }
                let i = r.entry_index(self.max_code);
                let a = r.lut.raw_opacity(i).clamp(0.0, 1.0);
                RayResult {
                    color: (r.rgb[i] * a).to_array(),
                    alpha: a,
                }
            }
            RenderMode::Isosurface { .. } => match self.hit {
                Some(c) => RayResult {
                    color: c.to_array(),
                    alpha: 1.0,
                },
                None => RayResult::EMPTY,
            },
        }
    }
}

/// Amanatides–Woo traversal of the cells (of size `size`, grid `dims`) that the ray
/// `o + t·d` crosses for `t ∈ [t0, t1)`, yielding `(cell, t_enter, t_exit)`.
pub(crate) struct Dda {
    cell: [i64; 3],
    dims: [i64; 3],
    step: [i64; 3],
    t_max: [f32; 3],
    t_delta: [f32; 3],
    t: f32,
    t_end: f32,
}

impl Dda {
    pub(crate) fn new(o: Vec3, d: Vec3, t0: f32, t1: f32, size: f32, dims: [usize; 3]) -> Self {
        let p = o + d * t0;
        let mut cell = [0i64; 3];
        let mut step = [0i64; 3];
        let mut t_max = [f32::INFINITY; 3];
        let mut t_delta = [f32::INFINITY; 3];
        for a in 0..3 {
            let c = ((p[a] / size).floor() as i64).clamp(0, dims[a] as i64 - 1);
            cell[a] = c;
            if d[a] > 0.0 {
                step[a] = 1;
                t_max[a] = ((c + 1) as f32 * size - o[a]) / d[a];
                t_delta[a] = size / d[a];
            } else if d[a] < 0.0 {
                step[a] = -1;
                t_max[a] = (c as f32 * size - o[a]) / d[a];
                t_delta[a] = -size / d[a];
            }
        }
        Self {
            cell,
            dims: dims.map(|x| x as i64),
            step,
            t_max,
            t_delta,
            t: t0,
            t_end: t1,
        }
    }
}

impl Iterator for Dda {
    type Item = ([usize; 3], f32, f32);

    #[inline]
    fn next(&mut self) -> Option<Self::Item> {
        if self.t >= self.t_end || (0..3).any(|a| self.cell[a] < 0 || self.cell[a] >= self.dims[a])
        {
            return None;
        }
        let a = if self.t_max[0] < self.t_max[1] {
            if self.t_max[0] < self.t_max[2] { 0 } else { 2 }
        } else if self.t_max[1] < self.t_max[2] {
            1
        } else {
            2
        };
        let exit = self.t_max[a].min(self.t_end);
        let out = (self.cell.map(|c| c as usize), self.t, exit);
        self.t = exit;
        self.cell[a] += self.step[a];
        self.t_max[a] += self.t_delta[a];
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_volume::Geometry;

    /// Largest difference, in codes, between the shaded table's `f32` gradient and the exact
    /// trilinear interpolation of the half differences: seven `f32` interpolation steps on
    /// values below 2¹⁵, each rounding by at most half an ulp (2⁻⁹ at 2¹⁴‥2¹⁵), so about
    /// 7 × 2⁻⁹ ≈ 0.014, and 0.02 with a margin.
    const GRADIENT_TOLERANCE: f64 = 0.02;

    /// A 9 × 7 × 5 volume of scattered `u16` values (codes equal values).
    fn scattered() -> DvrVolume {
        let g = Geometry::new([9, 7, 5]);
        let v = Volume::from_fn(g, |i, j, k| {
            ((i * 7919 + j * 104_729 + k * 1_299_709) % 65_521) as u16
        })
        .unwrap();
        DvrVolume::from_volume(&v).unwrap()
    }

    /// The cell of the truncating, clamping form that `cell_of` replaced.
    fn cell_by_truncation(v: &DvrVolume, u: Vec3) -> (usize, Vec3) {
        let [nx, ny, nz] = v.dims;
        let cell = |x: f32, n: usize| -> (usize, f32) {
            let i = (x as i32).clamp(0, n as i32 - 2) as usize;
            (i, x - i as f32)
        };
        let (i, fx) = cell(u.x, nx);
        let (j, fy) = cell(u.y, ny);
        let (k, fz) = cell(u.z, nz);
        (i + nx * (j + ny * k), Vec3::new(fx, fy, fz))
    }

    #[test]
    fn cells_are_those_of_truncation_and_clamping() {
        let v = scattered();
        let xs = [
            -1.5, -1.0, -0.25, -0.0, 0.0, 0.3, 1.0, 2.5, 3.999_999, 4.0, 6.0, 6.5, 7.0, 7.75, 8.0,
            8.5, 1e9,
        ];
        for &x in &xs {
            for &y in &xs {
                for &z in &xs {
                    let u = Vec3::new(x, y, z);
                    let (a, fa) = v.cell_of(u);
                    let (b, fb) = cell_by_truncation(&v, u);
                    assert_eq!(a, b, "{u}");
                    assert_eq!(
                        fa.to_array().map(f32::to_bits),
                        fb.to_array().map(f32::to_bits)
                    );
                }
            }
        }
    }

    #[test]
    fn shaded_samples_keep_the_code_bits_and_interpolate_the_half_differences() {
        let v = scattered();
        let [nx, ny, nz] = v.dims;
        let code = |i: usize, j: usize, k: usize| f64::from(v.data[i + nx * (j + ny * k)]);
        // The half central differences (one-sided at the faces), rounded towards −∞.
        let half = |i: usize, j: usize, k: usize| -> [f64; 3] {
            let d = |a: f64, b: f64| ((a - b) / 2.0).floor();
            [
                d(
                    code((i + 1).min(nx - 1), j, k),
                    code(i.saturating_sub(1), j, k),
                ),
                d(
                    code(i, (j + 1).min(ny - 1), k),
                    code(i, j.saturating_sub(1), k),
                ),
                d(
                    code(i, j, (k + 1).min(nz - 1)),
                    code(i, j, k.saturating_sub(1)),
                ),
            ]
        };
        let mut rng = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 40) as f32 / (1u64 << 24) as f32
        };
        for _ in 0..2000 {
            let u = Vec3::new(next() * 8.0, next() * 6.0, next() * 4.0);
            let (cell, f) = v.cell_of(u);
            let s = v.sample_shaded(cell, f);
            assert_eq!(s.x.to_bits(), v.sample_cell(cell, f).to_bits(), "{u}");
            let (i, j, k) = (cell % nx, cell / nx % ny, cell / (nx * ny));
            let mut g = [0.0f64; 3];
            for c in 0..8 {
                let (di, dj, dk) = (c & 1, c >> 1 & 1, c >> 2);
                let w = [(di, f.x), (dj, f.y), (dk, f.z)]
                    .iter()
                    .map(|&(b, t)| {
                        if b == 1 {
                            f64::from(t)
                        } else {
                            1.0 - f64::from(t)
                        }
                    })
                    .product::<f64>();
                let h = half(i + di, j + dj, k + dk);
                for a in 0..3 {
                    g[a] += w * h[a];
                }
            }
            for a in 0..3 {
                assert!(
                    (f64::from(s[a + 1]) - g[a]).abs() <= GRADIENT_TOLERANCE,
                    "{u}: {s} against {g:?}"
                );
            }
        }
    }
}
