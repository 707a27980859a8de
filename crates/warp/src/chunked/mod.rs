//! Chunk-by-chunk warps for volumes that do not fit in memory (OME-Zarr stores, Dask): the
//! pull-back here, the push-forward in [`push`].
//!
//! Which methods run chunk by chunk is decided in one place, [`ChunkedMethod::new`]; the
//! command line and `volmorph.dask` both ask it, and [`warp_chunks_with`] runs either kind
//! over a [`ChunkGrid`] of the output.
//!
//! # Direction
//!
//! As [`pullback`](crate::pullback): output voxel `x` takes the input's value at `map(x)`.
//!
//! # How a pull-back chunk is computed
//!
//! The output grid is cut into boxes of voxels (chunks, [`IndexBox`]). For one chunk:
//!
//! 1. [`chunk_indices`]: the map is evaluated at the chunk's voxel centres and each image is
//!    turned into a continuous index of the **whole** input grid, with exactly the arithmetic
//!    of [`pullback::resample`](crate::pullback::resample): the map is evaluated through
//!    [`SpaceMap::apply_grid`] on the same tiles of [`pullback::TILE`](crate::pullback::TILE)
//!    voxels, anchored at the same voxels of the output grid (a chunk that does not start on
//!    a tile boundary evaluates the whole tiles it overlaps and keeps its part), and the same
//!    physical-to-index map with the same snapping to voxel centres.
//! 2. [`preimage_box`]: the bounding box of those indices, widened by the interpolation
//!    kernel's support and [`PREIMAGE_MARGIN`], clipped to the input. Because it is computed
//!    from the very indices the chunk samples, it is exact: not an estimate that a strongly
//!    bending map could escape. Points that sample nothing (outside the input under a
//!    constant boundary, or NaN) do not widen it.
//! 3. Only that box of the input is read, and [`sample_chunk`] samples it at the indices
//!    shifted by the box's start. The shift subtracts an integer from each index, which is
//!    exact in `f64`, so the interpolation weights, the neighbours and the interior/border
//!    decision are those of the in-memory warp: **the chunked result is bit for bit the
//!    in-memory pull-back** whatever the chunk shape (tested with odd chunk shapes).
//!
//! [`warp_chunked`] runs every chunk of a list in parallel (rayon), holding per thread one
//! chunk's indices (24 bytes per output voxel), its input box and its output voxels: memory
//! is bounded by the chunk size and the map's local stretch, not by the volume.
//!
//! # What it does not do
//!
//! Cubic B-spline interpolation samples coefficients prefiltered over the *whole* input (an
//! infinite-support recursive filter), so a box of the input cannot reproduce it; it is
//! refused ([`WarpError::Unsupported`]), as is [`Boundary::Mirror`] (a point outside the
//! input reflects to a place the box need not contain). The push-forward (both methods) runs
//! chunk by chunk through [`push`] (design and costs in `docs/chunked-pushforward.md`); the
//! pull-back through the inverse (Newton per voxel, with a cubic prefilter for its cubic
//! kind) does not.

use glam::DVec3;
use rayon::prelude::*;
use volmorph_deform::SpaceMap;
use volmorph_volume::sample::{Boundary, Interpolation, Sampler};
use volmorph_volume::{AnyVolume, Geometry, IndexBox, Volume, Voxel};

use crate::WarpError;
use crate::apply::WarpMethod;
use crate::pullback::{IndexMap, ResampleOptions, TILE};
use crate::pushforward::{AntialiasOptions, PushForwardStats};

pub mod push;

use push::PushMethod;

/// Voxels added on every side of a chunk's preimage box beyond the kernel's own support
/// (one voxel for linear, the rounding neighbour for nearest). The box is computed from the
/// sampled indices themselves, so this is not a guard against an inexact bound; it keeps the
/// box a superset of the stencil under any tie-breaking of the kernels' floor at integer
/// indices (a linear stencil at an exact integer reads `i` and `i + 1`).
pub const PREIMAGE_MARGIN: usize = 1;

/// A warp method that runs chunk by chunk, with its options: the one policy of which
/// [`WarpMethod`]s the out-of-core command line and `volmorph.dask` accept.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChunkedMethod {
    /// Pull-back with linear or nearest interpolation (see the [module docs](self)).
    Pullback(ResampleOptions),
    /// Push-forward, antialiased or nearest ([`push`]).
    Push(PushMethod),
}

impl ChunkedMethod {
    /// The chunked form of `method` with `background` (the value of output voxels nothing
    /// reaches): `pullback-linear` and `pullback-nearest` (constant boundary),
    /// `pushforward-antialiased` (True's averaged face centres, the default of the in-memory
    /// warp) and `pushforward-nearest` (background 0 only, as in
    /// [`warp_volume`](crate::apply::warp_volume)). The result of every one equals the
    /// in-memory [`warp_volume`](crate::apply::warp_volume) with the same method bit for bit.
    ///
    /// # Errors
    /// [`WarpError::Background`] for a non-finite background; [`WarpError::InvalidOption`]
    /// for a non-zero background with `pushforward-nearest`; [`WarpError::Unsupported`] for
    /// the cubic pull-back and the inverse methods, naming the supported ones.
    pub fn new(method: WarpMethod, background: f64) -> Result<Self, WarpError> {
        if !background.is_finite() {
            return Err(WarpError::Background(background));
        }
        match method {
            WarpMethod::PullbackLinear => Ok(Self::Pullback(ResampleOptions::new(
                Interpolation::Linear,
                background,
            ))),
            WarpMethod::PullbackNearest => Ok(Self::Pullback(ResampleOptions::new(
                Interpolation::Nearest,
                background,
            ))),
            WarpMethod::PushforwardAntialiased => {
                Ok(Self::Push(PushMethod::Antialiased(AntialiasOptions {
                    background,
                    ..AntialiasOptions::default()
                })))
            }
            WarpMethod::PushforwardNearest if background != 0.0 => Err(WarpError::InvalidOption(
                "a background is not used by pushforward-nearest (holes stay 0)".into(),
            )),
            WarpMethod::PushforwardNearest => Ok(Self::Push(PushMethod::Nearest)),
            WarpMethod::PullbackCubic
            | WarpMethod::InverseNearest
            | WarpMethod::InverseLinear
            | WarpMethod::InverseCubic => Err(WarpError::Unsupported(
                "chunked (out-of-core, Dask) warps support pullback-linear, pullback-nearest, \
                 pushforward-antialiased and pushforward-nearest: cubic B-splines prefilter \
                 the whole input, and the inverse methods are not chunked",
            )),
        }
    }
}

/// The chunks of an output grid as a tensor grid (the chunking of OME-Zarr stores and dask
/// arrays): along each axis `a` the chunk boundaries `0 = b₀ < b₁ < … < b_m = dims[a]`, and
/// the chunks are the products of the per-axis intervals, numbered x fastest
/// (`cx + counts[0]·(cy + counts[1]·cz)`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChunkGrid {
    bounds: [Vec<usize>; 3],
}

impl ChunkGrid {
    /// A grid of `dims` voxels cut into `chunk`-sized chunks from index 0 (the last chunk
    /// along an axis is shorter when `chunk` does not divide `dims`).
    ///
    /// # Errors
    /// [`WarpError::InvalidOption`] for a zero chunk edge or dimension.
    pub fn regular(dims: [usize; 3], chunk: [usize; 3]) -> Result<Self, WarpError> {
        if chunk.contains(&0) || dims.contains(&0) {
            return Err(WarpError::InvalidOption(format!(
                "chunk shape {chunk:?} of a {dims:?} grid: every edge and dimension must be \
                 at least 1"
            )));
        }
        Self::from_sizes([0, 1, 2].map(|a| {
            (0..dims[a])
                .step_by(chunk[a])
                .map(|s| chunk[a].min(dims[a] - s))
                .collect()
        }))
    }

    /// A grid whose chunks along axis `a` have the lengths `sizes[a]` in order (dask's
    /// `chunks`, reversed to x, y, z).
    ///
    /// # Errors
    /// [`WarpError::InvalidOption`] for an axis without chunks or a chunk of length 0.
    pub fn from_sizes(sizes: [Vec<usize>; 3]) -> Result<Self, WarpError> {
        let mut bounds: [Vec<usize>; 3] = Default::default();
        for a in 0..3 {
            if sizes[a].is_empty() || sizes[a].contains(&0) {
                return Err(WarpError::InvalidOption(format!(
                    "chunk sizes {:?} along axis {a}: need at least one chunk, none of \
                     length 0",
                    sizes[a]
                )));
            }
            let mut b = Vec::with_capacity(sizes[a].len() + 1);
            b.push(0usize);
            for &n in &sizes[a] {
                let next = b[b.len() - 1].checked_add(n).ok_or_else(|| {
                    WarpError::InvalidOption(format!("chunk sizes along axis {a} overflow"))
                })?;
                b.push(next);
            }
            bounds[a] = b;
        }
        Ok(Self { bounds })
    }

    /// Voxels of the chunked grid per axis.
    #[must_use]
    pub fn dims(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| self.bounds[a].last().copied().unwrap_or(0))
    }

    /// Chunks per axis.
    #[must_use]
    pub fn counts(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| self.bounds[a].len().saturating_sub(1))
    }

    /// Number of chunks.
    #[must_use]
    pub fn len(&self) -> usize {
        self.counts().iter().product()
    }

    /// `true` if the grid has no chunk (never, for a grid built by the constructors).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The number of chunk `[cx, cy, cz]` (x fastest).
    #[must_use]
    pub fn index_of(&self, c: [usize; 3]) -> usize {
        let n = self.counts();
        c[0] + n[0] * (c[1] + n[1] * c[2])
    }

    /// The per-axis position `[cx, cy, cz]` of chunk number `index`.
    #[must_use]
    pub fn position(&self, index: usize) -> [usize; 3] {
        let n = self.counts();
        [index % n[0], (index / n[0]) % n[1], index / (n[0] * n[1])]
    }

    /// The voxels of chunk number `index` (an empty box past the last chunk).
    #[must_use]
    pub fn chunk(&self, index: usize) -> IndexBox {
        if index >= self.len() {
            return IndexBox::default();
        }
        let c = self.position(index);
        IndexBox {
            start: [0, 1, 2].map(|a| self.bounds[a][c[a]]),
            end: [0, 1, 2].map(|a| self.bounds[a][c[a] + 1]),
        }
    }

    /// Every chunk, in number order.
    #[must_use]
    pub fn boxes(&self) -> Vec<IndexBox> {
        (0..self.len()).map(|c| self.chunk(c)).collect()
    }

    /// Per axis, the chunk position of every voxel index.
    pub(crate) fn owners(&self) -> [Vec<u32>; 3] {
        [0, 1, 2].map(|a| {
            let b = &self.bounds[a];
            let mut o = Vec::with_capacity(b.last().copied().unwrap_or(0));
            for (c, w) in b.windows(2).enumerate() {
                o.extend(std::iter::repeat_n(c as u32, w[1] - w[0]));
            }
            o
        })
    }
}

/// Warp `input` (read box by box through `read`) onto `output`, chunk by chunk over
/// `chunks`, by `method`, handing each chunk to `write` with its box. The pull-back runs
/// [`warp_chunked_with`]; the push-forward plans with [`push::plan_push_with`] (one stage of
/// progress) and runs [`push::push_chunked_with`] (a second stage), and its statistics are
/// returned. The union of the written chunks equals the in-memory
/// [`warp_volume`](crate::apply::warp_volume) with the same method bit for bit.
///
/// # Errors
/// [`WarpError::InvalidOption`] if `chunks` does not cover `output`; the errors of the
/// functions named above; [`WarpError::Cancelled`] when `progress` asks to stop (chunks
/// already written stay written; the caller discards its partial output).
#[allow(clippy::too_many_arguments)]
pub fn warp_chunks_with<M, R, W>(
    map: &M,
    input: &Geometry,
    output: &Geometry,
    chunks: &ChunkGrid,
    method: &ChunkedMethod,
    read: R,
    write: W,
    progress: &dyn volmorph_io::Progress,
) -> Result<Option<PushForwardStats>, WarpError>
where
    M: SpaceMap + ?Sized,
    R: Fn(IndexBox) -> Result<AnyVolume, WarpError> + Sync,
    W: Fn(IndexBox, AnyVolume) -> Result<(), WarpError> + Sync,
{
    if chunks.dims() != output.dims {
        return Err(WarpError::InvalidOption(format!(
            "the chunks cover {:?} voxels, the output grid has {:?}",
            chunks.dims(),
            output.dims
        )));
    }
    match method {
        ChunkedMethod::Pullback(o) => {
            warp_chunked_with(
                map,
                input,
                output,
                &chunks.boxes(),
                o,
                read,
                write,
                progress,
            )?;
            Ok(None)
        }
        ChunkedMethod::Push(m) => {
            let plan = push::plan_push_with(map, input, output, m, chunks, progress)?;
            push::push_chunked_with(map, &plan, read, write, progress).map(Some)
        }
    }
}

/// Check that `options` can be computed chunk by chunk.
///
/// # Errors
/// [`WarpError::Unsupported`] for cubic B-spline interpolation or the mirror boundary (see
/// the [module docs](self)).
pub fn check_chunkable(options: &ResampleOptions) -> Result<(), WarpError> {
    if options.interpolation == Interpolation::CubicBSpline {
        return Err(WarpError::Unsupported(
            "cubic B-spline interpolation prefilters the whole input, so it cannot run chunk by \
             chunk; use linear or nearest interpolation for chunked (out-of-core, Dask) warps",
        ));
    }
    if matches!(options.boundary, Boundary::Mirror) {
        return Err(WarpError::Unsupported(
            "the mirror boundary reflects points to parts of the input a chunk does not read; \
             use a constant or clamped boundary for chunked warps",
        ));
    }
    Ok(())
}

pub(crate) fn check_chunk(output: &Geometry, chunk: IndexBox) -> Result<(), WarpError> {
    output
        .validate_unbounded()
        .map_err(|source| WarpError::Geometry {
            what: "output grid",
            source,
        })?;
    if chunk.is_empty() || (0..3).any(|a| chunk.end[a] > output.dims[a]) {
        return Err(WarpError::InvalidOption(format!(
            "chunk {:?}..{:?} is empty or outside the output grid's {:?} voxels",
            chunk.start, chunk.end, output.dims
        )));
    }
    Ok(())
}

/// The grid of `chunk` inside `output`: same spacing and direction, origin at the chunk's
/// first voxel.
#[must_use]
pub fn chunk_geometry(output: &Geometry, chunk: IndexBox) -> Geometry {
    Geometry {
        dims: [0, 1, 2].map(|a| chunk.end[a] - chunk.start[a]),
        origin: output.index_to_physical(DVec3::new(
            chunk.start[0] as f64,
            chunk.start[1] as f64,
            chunk.start[2] as f64,
        )),
        ..*output
    }
}

/// Continuous input indices (of the whole `input` grid, snapped to voxel centres within
/// [`INDEX_SNAP_TOL`](crate::pullback::INDEX_SNAP_TOL)) of `map`'s images of the voxel
/// centres of `chunk` of `output`, x fastest: the very values
/// [`pullback::resample`](crate::pullback::resample) samples for those voxels.
///
/// # Errors
/// [`WarpError::Geometry`] for an invalid grid, [`WarpError::InvalidOption`] for a chunk
/// that is empty or outside `output`, [`WarpError::Map`] if the map's evaluation fails,
/// [`WarpError::Allocation`] if the chunk's index buffer exceeds the memory budget.
pub fn chunk_indices<M: SpaceMap + ?Sized>(
    map: &M,
    input: &Geometry,
    output: &Geometry,
    chunk: IndexBox,
) -> Result<Vec<DVec3>, WarpError> {
    check_chunk(output, chunk)?;
    input
        .validate_unbounded()
        .map_err(|source| WarpError::Geometry {
            what: "input grid",
            source,
        })?;
    let to_index = IndexMap::new(input);
    let cd = [0, 1, 2].map(|a| chunk.end[a] - chunk.start[a]);
    let n = cd[0] * cd[1] * cd[2];
    let mut out =
        volmorph_io::try_vec("chunk index", n, DVec3::ZERO).map_err(|_| WarpError::Allocation {
            what: "chunk index",
            bytes: n.saturating_mul(std::mem::size_of::<DVec3>()),
        })?;
    // The tiles of `pullback::resample`: anchored at multiples of the tile edge, clipped to
    // the output grid.
    let [nx, ny, nz] = output.dims;
    let t = [TILE[0].min(nx), TILE[1].min(ny), TILE[2].min(nz)];
    let mut points: Vec<DVec3> = Vec::with_capacity(t[0] * t[1] * t[2]);
    let first = [0, 1, 2].map(|a| chunk.start[a] / t[a] * t[a]);
    for z0 in (first[2]..chunk.end[2]).step_by(t[2]) {
        for y0 in (first[1]..chunk.end[1]).step_by(t[1]) {
            for x0 in (first[0]..chunk.end[0]).step_by(t[0]) {
                let dims = [t[0].min(nx - x0), t[1].min(ny - y0), t[2].min(nz - z0)];
                let tile = Geometry {
                    dims,
                    origin: output.index_to_physical(DVec3::new(x0 as f64, y0 as f64, z0 as f64)),
                    ..*output
                };
                points.resize(dims[0] * dims[1] * dims[2], DVec3::ZERO);
                map.apply_grid(&tile, &mut points)?;
                let lo = [
                    x0.max(chunk.start[0]),
                    y0.max(chunk.start[1]),
                    z0.max(chunk.start[2]),
                ];
                let hi = [
                    (x0 + dims[0]).min(chunk.end[0]),
                    (y0 + dims[1]).min(chunk.end[1]),
                    (z0 + dims[2]).min(chunk.end[2]),
                ];
                for z in lo[2]..hi[2] {
                    for y in lo[1]..hi[1] {
                        let src = (y - y0 + dims[1] * (z - z0)) * dims[0];
                        let dst = (y - chunk.start[1] + cd[1] * (z - chunk.start[2])) * cd[0];
                        for x in lo[0]..hi[0] {
                            out[dst + x - chunk.start[0]] = to_index.apply(points[src + x - x0]);
                        }
                    }
                }
            }
        }
    }
    Ok(out)
}

/// The box of input voxels that sampling at `indices` (continuous indices of an input grid
/// of `input_dims` voxels) reads under `options`: the indices' bounding box, widened by the
/// kernel's support and [`PREIMAGE_MARGIN`], clipped to the input. Points that read no voxel
/// (NaN; outside the sampled box `[−½, n − ½]` under a constant boundary) are left out; under
/// the clamped boundary points are clamped first. The box is empty when no point reads any
/// voxel.
#[must_use]
pub fn preimage_box(
    indices: &[DVec3],
    input_dims: [usize; 3],
    options: &ResampleOptions,
) -> IndexBox {
    let n = input_dims.map(|d| d as f64);
    let clamp = matches!(options.boundary, Boundary::Clamp);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for q in indices {
        let mut q = q.to_array();
        if q.iter().any(|c| c.is_nan()) {
            continue;
        }
        if clamp {
            for a in 0..3 {
                q[a] = q[a].clamp(0.0, n[a] - 1.0);
            }
        } else if (0..3).any(|a| !(q[a] >= -0.5 && q[a] <= n[a] - 0.5)) {
            continue;
        }
        for a in 0..3 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    if lo[0] > hi[0] {
        return IndexBox::default();
    }
    let m = PREIMAGE_MARGIN as f64;
    let mut b = IndexBox::default();
    for a in 0..3 {
        // Nearest reads round(q) ≤ ⌊q⌋ + 1, linear reads ⌊q⌋ and ⌊q⌋ + 1.
        let s = (lo[a].floor() - m).max(0.0);
        let e = (hi[a].floor() + 2.0 + m).min(n[a]);
        b.start[a] = s as usize;
        b.end[a] = e as usize;
    }
    b
}

/// The box of the input that `chunk` of `output` reads: [`chunk_indices`] then
/// [`preimage_box`]. Planning code (a Dask graph) uses it to read only that region.
///
/// # Errors
/// As [`chunk_indices`] and [`check_chunkable`].
pub fn chunk_preimage<M: SpaceMap + ?Sized>(
    map: &M,
    input: &Geometry,
    output: &Geometry,
    chunk: IndexBox,
    options: &ResampleOptions,
) -> Result<IndexBox, WarpError> {
    check_chunkable(options)?;
    let idx = chunk_indices(map, input, output, chunk)?;
    Ok(preimage_box(&idx, input.dims, options))
}

/// The box read when a chunk's [`preimage_box`] is empty: one voxel, so the sampler has a
/// volume to answer its outside value from.
pub(crate) fn nonempty(b: IndexBox) -> IndexBox {
    if b.is_empty() {
        IndexBox {
            start: [0; 3],
            end: [1; 3],
        }
    } else {
        b
    }
}

/// Sample `region` (the input voxels of the box starting at `region_start`, a box that
/// contains [`preimage_box`] of `indices`) at `indices` (continuous indices of the whole
/// input, as from [`chunk_indices`]) into a volume on `chunk_grid` of the region's voxel
/// type. `indices` is shifted in place to the region's own index space.
///
/// # Errors
/// [`WarpError::BufferLength`] if `indices` is not one per voxel of `chunk_grid`;
/// [`WarpError::Unsupported`] as [`check_chunkable`]; [`WarpError::Volume`] if the sampler
/// cannot be built.
pub fn sample_chunk(
    indices: &mut [DVec3],
    region: &AnyVolume,
    region_start: [usize; 3],
    chunk_grid: &Geometry,
    options: &ResampleOptions,
) -> Result<AnyVolume, WarpError> {
    check_chunkable(options)?;
    if indices.len() != chunk_grid.len() {
        return Err(WarpError::BufferLength {
            dims: chunk_grid.dims,
            expected: chunk_grid.len(),
            got: indices.len(),
        });
    }
    let shift = DVec3::new(
        region_start[0] as f64,
        region_start[1] as f64,
        region_start[2] as f64,
    );
    for q in indices.iter_mut() {
        *q -= shift;
    }
    volmorph_volume::with_volume!(region, v => sample_typed(v, indices, chunk_grid, options).map(AnyVolume::from))
}

fn sample_typed<T: Voxel>(
    region: &Volume<T>,
    indices: &[DVec3],
    chunk_grid: &Geometry,
    options: &ResampleOptions,
) -> Result<Volume<T>, WarpError> {
    let sampler = Sampler::new(region, options.interpolation, options.boundary)?;
    let mut out =
        volmorph_io::try_vec("chunk output", indices.len(), T::default()).map_err(|_| {
            WarpError::Allocation {
                what: "chunk output",
                bytes: indices.len().saturating_mul(std::mem::size_of::<T>()),
            }
        })?;
    sampler.sample_index_serial(indices, &mut out)?;
    Volume::new(*chunk_grid, out).map_err(|source| WarpError::Geometry {
        what: "chunk grid",
        source,
    })
}

/// Pull-back of one chunk: [`chunk_indices`], [`preimage_box`], `read` of that box of the
/// input (it returns the box's voxels, x fastest, in the input's voxel type), then
/// [`sample_chunk`]. Returns the chunk's voxels on [`chunk_geometry`], equal bit for bit to
/// the same voxels of [`pullback::resample_any`](crate::pullback::resample_any) over the
/// whole input.
///
/// # Errors
/// As [`chunk_indices`] and [`sample_chunk`], the errors of `read`, and
/// [`WarpError::BufferLength`] if `read` returns a volume of another size than the box.
pub fn pull_chunk<M: SpaceMap + ?Sized>(
    map: &M,
    input: &Geometry,
    output: &Geometry,
    chunk: IndexBox,
    options: &ResampleOptions,
    read: impl FnOnce(IndexBox) -> Result<AnyVolume, WarpError>,
) -> Result<AnyVolume, WarpError> {
    check_chunkable(options)?;
    let mut idx = chunk_indices(map, input, output, chunk)?;
    let b = nonempty(preimage_box(&idx, input.dims, options));
    let region = read(b)?;
    let want = [0, 1, 2].map(|a| b.end[a] - b.start[a]);
    if region.geometry().dims != want {
        return Err(WarpError::BufferLength {
            dims: want,
            expected: b.len(),
            got: region.geometry().len(),
        });
    }
    sample_chunk(
        &mut idx,
        &region,
        b.start,
        &chunk_geometry(output, chunk),
        options,
    )
}

/// Pull-back of `input` (read box by box through `read`) onto `output`, chunk by chunk over
/// `chunks` (in parallel), each result handed to `write` with its chunk box. See
/// [`pull_chunk`] for one chunk; the union of the written chunks equals
/// [`pullback::resample_any`](crate::pullback::resample_any) bit for bit.
///
/// # Errors
/// The first error of [`pull_chunk`], `read` or `write` (other chunks may have been written).
pub fn warp_chunked<M, R, W>(
    map: &M,
    input: &Geometry,
    output: &Geometry,
    chunks: &[IndexBox],
    options: &ResampleOptions,
    read: R,
    write: W,
) -> Result<(), WarpError>
where
    M: SpaceMap + ?Sized,
    R: Fn(IndexBox) -> Result<AnyVolume, WarpError> + Sync,
    W: Fn(IndexBox, AnyVolume) -> Result<(), WarpError> + Sync,
{
    warp_chunked_with(
        map,
        input,
        output,
        chunks,
        options,
        read,
        write,
        &volmorph_io::NoProgress,
    )
}

/// [`warp_chunked`] reporting to `progress`: one stage whose steps are the chunks, each
/// advanced once written; when cancelled no further chunk is started (chunks already handed
/// to `write` stay written, so the caller discards its partial output, as the OME-Zarr
/// writer's staging folder is discarded when it is dropped unfinished).
///
/// # Errors
/// As [`warp_chunked`]; [`WarpError::Cancelled`] when `progress` asks to stop.
#[allow(clippy::too_many_arguments)]
pub fn warp_chunked_with<M, R, W>(
    map: &M,
    input: &Geometry,
    output: &Geometry,
    chunks: &[IndexBox],
    options: &ResampleOptions,
    read: R,
    write: W,
    progress: &dyn volmorph_io::Progress,
) -> Result<(), WarpError>
where
    M: SpaceMap + ?Sized,
    R: Fn(IndexBox) -> Result<AnyVolume, WarpError> + Sync,
    W: Fn(IndexBox, AnyVolume) -> Result<(), WarpError> + Sync,
{
    check_chunkable(options)?;
    progress.start(
        &format!("warping {} chunks out of core", chunks.len()),
        chunks.len() as u64,
    );
    chunks
        .par_iter()
        .try_for_each(|&c| -> Result<(), WarpError> {
            progress.check()?;
            let v = pull_chunk(map, input, output, c, options, &read)?;
            write(c, v)?;
            progress.advance(1);
            Ok(())
        })?;
    Ok(progress.check()?)
}
