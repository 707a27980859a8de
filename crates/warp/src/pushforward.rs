//! Push-forward of a volume through a space map (True 1992 §5.3–§5.4).
//!
//! **Direction.** Every *input* voxel is sent to where the map takes it: the voxel centre `p`
//! (physical point of index `(i, j, k)` in the input geometry) goes to the physical point
//! `map.apply(p)`, which is then located in the *output* geometry chosen by the caller. This
//! is free-form deformation of the model (True §4); for ITK-style resampling, where output
//! point `x` samples the input at `map(x)`, use [`crate::pullback`].
//!
//! Two operations:
//!
//! * [`push_forward_nearest`] — True §5.3 "map and round": each input voxel writes its value
//!   into the output voxel nearest to the image of its centre. Fast, aliased, leaves holes
//!   where the map stretches; meant as a preview.
//! * [`push_forward_antialiased`] / [`push_forward_antialiased_f32`] — True §5.4 box-filter
//!   antialiasing: each input voxel is a unit box of constant value; its image is
//!   approximated by the axis-aligned bounding box (in output index space) of the images of
//!   its six face centres, and the value is spread over the output voxels the box overlaps,
//!   weighted by overlap volume.
//!
//! # Conventions
//!
//! * Output voxel `q` is the unit cube `[q − ½, q + ½]³` in the output's **continuous index**
//!   space (`Geometry::physical_to_index`), so "fraction of the target voxel's volume"
//!   (True §5.4) is the overlap volume measured in output index units.
//! * The six face centres of input voxel `(i, j, k)` are the input points of continuous index
//!   `(i ± ½, j, k)`, `(i, j ± ½, k)` and `(i, j, k ± ½)`. Their images come either, as in
//!   True (§5.4, footnote 4), from averaging the images of the two voxel centres each face
//!   separates ([`FaceCentres::AveragedCentres`], the default, one map evaluation per voxel),
//!   or from mapping the three face-centre grids, each offset by half a voxel along one axis
//!   ([`FaceCentres::Mapped`], three evaluations per voxel). Either way the map is evaluated
//!   through its grid entry point [`SpaceMap::apply_grid`] (lattices use their table-driven
//!   fast path), never pointwise six times per voxel, on fixed tiles of 64 × 64 points one
//!   plane deep (`centres::TILE`), so that a chunk of the output can recompute any part of
//!   the evaluation with the same bits ([`crate::chunked::push`]).
//! * **Normalisation (True §5.4, verbatim rule).** Per output voxel the weights `W = Σ w` and
//!   weighted values `V = Σ w·d` are tallied; then `d = V / W` where `W ≥ 1` (overlapping
//!   bounding boxes), and `d = V` where `W < 1` — "the portion left uncovered \[counts\] as
//!   contributing zero". [`AntialiasOptions::background`] generalises the zero: where
//!   `W < 1` the result is `V + (1 − W)·background`, which is the paper's rule for the
//!   default background 0.
//! * **Non-finite images.** An input voxel whose centre (nearest) or any of whose six face
//!   centres (antialiased; with averaging, a face image is non-finite when either centre
//!   image is) maps to a NaN or infinite point is skipped and counted in
//!   [`PushForwardStats::non_finite`]; it contributes nothing.
//! * Work is split into input z-slabs whose size depends only on the input dimensions, and
//!   the slabs' contributions are combined in slab order, so results are bit-identical for
//!   any number of rayon threads, and [`crate::chunked::push`] reproduces them chunk by
//!   chunk.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_deform::Affine;
//! use volmorph_volume::{Geometry, Volume};
//! use volmorph_warp::pushforward::{AntialiasOptions, push_forward_antialiased_f32};
//!
//! // A single bright voxel pushed half a voxel along +x is shared by two output voxels.
//! let g = Geometry::new([4, 3, 3]);
//! let v = Volume::from_fn(g, |i, j, k| if (i, j, k) == (1, 1, 1) { 8.0f32 } else { 0.0 })?;
//! let shift = Affine::translation(DVec3::new(0.5, 0.0, 0.0));
//! let r = push_forward_antialiased_f32(&v, &shift, &g, &AntialiasOptions::default())?;
//! assert_eq!((r.volume[[1, 1, 1]], r.volume[[2, 1, 1]]), (4.0, 4.0));
//! assert_eq!(r.volume.data().iter().sum::<f32>(), 8.0); // mass is conserved
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use glam::{DMat3, DVec3};
use multiversion::multiversion;
use rayon::prelude::*;
use volmorph_deform::SpaceMap;
use volmorph_volume::{Geometry, Volume, VolumeError, Voxel};

use crate::WarpError;
use crate::centres::PointGrid;
use crate::tally::{FaceImages, Region, Voxels, cell_range, tally_averaged, tally_mapped};

/// Input voxels per slab (rounded to whole z-slices, at least one slice). Fixed, so the slab
/// partition — and with it the order of floating-point sums — never depends on the thread
/// count. 2¹⁹ voxels keep a slab's mapped points near 13 MB (one centre grid) or 38 MB
/// (three face-centre grids); one slab per rayon thread is in flight at a time.
const SLAB_VOXELS: usize = 1 << 19;

/// What happened to the input voxels. `mapped + non_finite + outside` is the input's voxel
/// count.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PushForwardStats {
    /// Input voxels that contributed to at least one output voxel.
    pub mapped: usize,
    /// Input voxels skipped because the map sent their centre (nearest) or one of their face
    /// centres (antialiased) to a NaN or infinite point.
    pub non_finite: usize,
    /// Input voxels whose image lies outside the output grid (nearest: the rounded index is
    /// out of range; antialiased: the bounding box overlaps no output voxel with positive
    /// volume, which includes boxes collapsed to zero thickness).
    pub outside: usize,
}

impl PushForwardStats {
    pub(crate) fn add(&mut self, o: &Self) {
        self.mapped += o.mapped;
        self.non_finite += o.non_finite;
        self.outside += o.outside;
    }
}

/// A pushed-forward volume on the caller's output geometry, with counts of what happened to
/// the input voxels.
#[derive(Debug, Clone, PartialEq)]
pub struct PushForward<T> {
    /// The result, on the requested output geometry.
    pub volume: Volume<T>,
    /// Per-input-voxel bookkeeping.
    pub stats: PushForwardStats,
}

/// Options of the antialiased push-forward.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AntialiasOptions {
    /// How the images of the six face centres of an input voxel are obtained.
    pub face_centres: FaceCentres,
    /// Value of the uncovered part of an output voxel (in the input's value units). Where the
    /// accumulated weight `W` is below 1 the result is `V + (1 − W)·background`; output voxels
    /// no input reaches are exactly `background`. Default 0, True's rule.
    pub background: f64,
}

impl Default for AntialiasOptions {
    fn default() -> Self {
        Self {
            face_centres: FaceCentres::default(),
            background: 0.0,
        }
    }
}

/// How [`push_forward_antialiased`] finds the images of an input voxel's six face centres
/// (the corners of its proxy box, True §5.4).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum FaceCentres {
    /// True's method (§5.4 and its footnote 4): the image of the face centre between two
    /// neighbouring voxel centres is the **mean of the images of those two centres**. The map
    /// is evaluated once per voxel centre, on the input grid widened by one voxel on every
    /// side (so the outer faces have a neighbour), about one evaluation per voxel. Exact for
    /// affine maps; for a smooth map the error is `O(h²)` in the voxel size `h`.
    #[default]
    AveragedCentres,
    /// The face centres themselves are mapped: three grids offset by half a voxel along x, y
    /// and z, each evaluated once through [`SpaceMap::apply_grid`] — about three evaluations
    /// per voxel, exact images of the face centres.
    Mapped,
}

/// Affine map from physical points to continuous output indices,
/// `index = m·(p − origin)` with `m = (direction·diag(spacing))⁻¹`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ToIndex {
    m: DMat3,
    origin: DVec3,
}

impl ToIndex {
    pub(crate) fn new(g: &Geometry) -> Self {
        Self {
            m: g.index_to_physical_matrix().inverse(),
            origin: g.origin,
        }
    }

    #[inline(always)]
    pub(crate) fn apply(&self, p: DVec3) -> DVec3 {
        self.m * (p - self.origin)
    }
}

/// The geometry of the grid of continuous input indices `offset + (i, j, k)`,
/// `(i, j, k) < dims`: same spacing and direction, origin moved to `offset`.
pub(crate) fn offset_grid(g: &Geometry, offset: DVec3, dims: [usize; 3]) -> Geometry {
    Geometry {
        dims,
        origin: g.index_to_physical(offset),
        ..*g
    }
}

/// The error for an unusable output geometry.
pub(crate) fn output_geometry(source: VolumeError) -> WarpError {
    WarpError::Geometry {
        what: "output grid",
        source,
    }
}

/// A vector of `len` copies of `value`, or an allocation error instead of an abort.
pub(crate) fn try_filled<V: Clone>(
    len: usize,
    value: V,
    what: &'static str,
) -> Result<Vec<V>, WarpError> {
    let mut v = Vec::new();
    v.try_reserve_exact(len)
        .map_err(|_| WarpError::Allocation {
            what,
            bytes: len.saturating_mul(std::mem::size_of::<V>()),
        })?;
    v.resize(len, value);
    Ok(v)
}

/// Slabs of whole input z-slices: `(k0, k1)` half-open ranges, size fixed by the dims.
pub(crate) fn slabs(dims: [usize; 3]) -> Vec<(usize, usize)> {
    let plane = dims[0].saturating_mul(dims[1]).max(1);
    let step = (SLAB_VOXELS / plane).max(1);
    (0..dims[2])
        .step_by(step)
        .map(|k0| (k0, (k0 + step).min(dims[2])))
        .collect()
}

/// Nearest output index along one axis of continuous index `x` (ties go up), or `None`
/// outside `0..n`.
#[inline]
pub(crate) fn round_index(x: f64, n: usize) -> Option<usize> {
    let r = (x + 0.5).floor();
    // `n as f64` is exact for any size a validated geometry allows.
    if r >= 0.0 && r < n as f64 {
        Some(r as usize)
    } else {
        None
    }
}

/// True §5.3 "map and round": push every input voxel centre `p` to `map.apply(p)` and write
/// the voxel's value into the output voxel (of `output`) nearest to that point.
///
/// * **Rounding:** the continuous output index of the image is rounded per axis to the
///   nearest integer, ties towards the higher index (`⌊x + ½⌋`); images rounding outside
///   the output grid are dropped (counted in [`PushForwardStats::outside`]).
/// * **Collisions:** when several input voxels land in the same output voxel, the **largest
///   value** (by `PartialOrd`) is kept, which preserves thin bright structures. Candidates
///   are visited in input memory order (x fastest) after the map is evaluated, so the
///   result is deterministic and independent of the thread count (a NaN float value is
///   replaced by nothing and replaces nothing that arrived before it).
/// * **Holes:** output voxels that no input voxel reaches keep the background value
///   `T::default()` (zero), as in True's target voxmap.
/// * Input voxels whose image is NaN or infinite are skipped and counted in
///   [`PushForwardStats::non_finite`].
///
/// # Errors
/// [`WarpError::Geometry`] for an invalid `output`,
/// [`WarpError::MapOnGrid`] if the map's grid evaluation fails,
/// [`WarpError::Allocation`] if a working buffer cannot be allocated.
pub fn push_forward_nearest<T: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
) -> Result<PushForward<T>, WarpError> {
    push_forward_nearest_with(input, map, output, &volmorph_io::NoProgress)
}

/// [`push_forward_nearest`] reporting to `progress`: one stage whose steps are the input's
/// z-slices, advanced slab by slab, stopping between slabs when cancelled. The result
/// equals [`push_forward_nearest`]'s bit for bit.
///
/// # Errors
/// As [`push_forward_nearest`]; [`WarpError::Cancelled`] when `progress` asks to stop.
pub fn push_forward_nearest_with<T: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    progress: &dyn volmorph_io::Progress,
) -> Result<PushForward<T>, WarpError> {
    output.validate().map_err(output_geometry)?;
    let to_index = ToIndex::new(output);
    let [nxo, nyo, nzo] = output.dims;
    let mut out = try_filled(output.len(), T::default(), "output")?;
    let mut written = try_filled(output.len(), false, "coverage")?;
    let g = input.geometry();
    let [nx, ny, _] = g.dims;
    let plane = nx * ny;
    let data = input.data();
    let mut stats = PushForwardStats::default();
    let slab_list = slabs(g.dims);
    let max_slab = slab_list.iter().map(|s| s.1 - s.0).max().unwrap_or(0);
    let mut images = try_filled(plane * max_slab, DVec3::ZERO, "mapped points")?;
    let centres = PointGrid::centres(g.dims);
    progress.start("nearest push-forward", g.dims[2] as u64);
    for (k0, k1) in slab_list {
        progress.check()?;
        let bx = Region {
            lo: [1, 1, k0 + 1],
            dims: [nx, ny, k1 - k0],
        };
        let images = &mut images[..bx.len()];
        centres.eval_box(map, g, &bx, images)?;
        let values = &data[k0 * plane..k1 * plane];
        for (&p, &v) in images.iter().zip(values) {
            if !p.is_finite() {
                stats.non_finite += 1;
                continue;
            }
            let q = to_index.apply(p);
            let target = match (
                round_index(q.x, nxo),
                round_index(q.y, nyo),
                round_index(q.z, nzo),
            ) {
                (Some(i), Some(j), Some(k)) => i + nxo * (j + nyo * k),
                _ => {
                    stats.outside += 1;
                    continue;
                }
            };
            stats.mapped += 1;
            if let (Some(slot), Some(w)) = (out.get_mut(target), written.get_mut(target))
                && (!*w || v > *slot)
            {
                *slot = v;
                *w = true;
            }
        }
        progress.advance((k1 - k0) as u64);
    }
    progress.check()?;
    let volume = Volume::new(*output, out).map_err(output_geometry)?;
    Ok(PushForward { volume, stats })
}

/// True §5.4 box-filter antialiased push-forward, result in the input's voxel type.
///
/// Each input voxel `(i, j, k)` is the box of constant value `d` around its centre. Its six
/// face centres are pushed forward as chosen by [`AntialiasOptions::face_centres`] (see the
/// [module docs](self)); the axis-aligned
/// bounding box `[lo, hi]` of their images, in output continuous-index space, stands in for
/// the image of the voxel. For every output voxel `q` the box overlaps, the weight
/// `w = Π_a max(0, min(hi_a, q_a + ½) − max(lo_a, q_a − ½))` (the overlap as a fraction of
/// `q`'s volume) is added to `W_q` and `w·d` to `V_q`. Finally
/// `d_q = V_q / W_q` if `W_q ≥ 1`, else `V_q + (1 − W_q)·background` (True's rule, see the
/// module docs). Sums are accumulated in `f32` (weights computed in `f64`); the result is
/// converted with [`Voxel::from_f64`] (rounded and saturated for integer types).
///
/// With the identity map and `output == input.geometry()` every box is its own voxel
/// (weight 1), so the input is reproduced. The cost grows with the number of output voxels
/// each box covers: a map that blows a voxel up over a large region costs accordingly.
///
/// # Errors
/// [`WarpError::Geometry`] for an invalid `output`,
/// [`WarpError::Background`] for a non-finite background,
/// [`WarpError::MapOnGrid`] if the map's grid evaluation fails,
/// [`WarpError::Allocation`] if a working buffer cannot be allocated.
pub fn push_forward_antialiased<T: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &AntialiasOptions,
) -> Result<PushForward<T>, WarpError> {
    push_forward_antialiased_with(input, map, output, options, &volmorph_io::NoProgress)
}

/// [`push_forward_antialiased`] reporting to `progress`: one stage whose steps are the
/// input's z-slices, advanced slab by slab, stopping between windows of slabs when
/// cancelled. The result equals [`push_forward_antialiased`]'s bit for bit.
///
/// # Errors
/// As [`push_forward_antialiased`]; [`WarpError::Cancelled`] when `progress` asks to stop.
pub fn push_forward_antialiased_with<T: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &AntialiasOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<PushForward<T>, WarpError> {
    let (acc, stats) = accumulate(input, map, output, options, progress)?;
    finish(acc, stats, output, options)
}

/// [`push_forward_antialiased`] with an `f32` result (no rounding to the input type), for
/// further processing such as isosurface extraction.
///
/// # Errors
/// As [`push_forward_antialiased`].
pub fn push_forward_antialiased_f32<T: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &AntialiasOptions,
) -> Result<PushForward<f32>, WarpError> {
    push_forward_antialiased_f32_with(input, map, output, options, &volmorph_io::NoProgress)
}

/// [`push_forward_antialiased_f32`] reporting to `progress` as
/// [`push_forward_antialiased_with`] does.
///
/// # Errors
/// As [`push_forward_antialiased_with`].
pub fn push_forward_antialiased_f32_with<T: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &AntialiasOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<PushForward<f32>, WarpError> {
    let (acc, stats) = accumulate(input, map, output, options, progress)?;
    finish(acc, stats, output, options)
}

/// True's normalisation of one output voxel's tallies (see the module docs): `V / W` where
/// `W ≥ 1`, else `V + (1 − W)·background`.
#[inline]
pub(crate) fn normalise(v: f64, w: f64, background: f64) -> f64 {
    if w >= 1.0 {
        v / w
    } else {
        v + (1.0 - w) * background
    }
}

/// Normalise the tallies `[V, W]` into the output volume (True's rule plus background).
fn finish<U: Voxel>(
    acc: Vec<[f32; 2]>,
    stats: PushForwardStats,
    output: &Geometry,
    options: &AntialiasOptions,
) -> Result<PushForward<U>, WarpError> {
    let background = options.background;
    let mut data = try_filled(acc.len(), U::from_f64(0.0), "output")?;
    data.par_chunks_mut(4096)
        .zip(acc.par_chunks(4096))
        .for_each(|(d, s)| normalise_into(s, d, background));
    let volume = Volume::new(*output, data).map_err(output_geometry)?;
    Ok(PushForward { volume, stats })
}

/// `dst[i] = U::from_f64(normalise(V, W, background))` for the tallies `src[i] = [V, W]`.
/// Compiled for the baseline target and for x86-64 with AVX2, chosen at run time: on the
/// baseline target the integer types' `f64::round` (in [`Voxel::from_f64`]) is a library
/// call per voxel, from SSE4.1 on a few inline instructions. Both give the same bits (the
/// same IEEE operations; Rust never contracts a multiply and an add).
#[multiversion(targets("x86_64+avx2+fma"))]
pub(crate) fn normalise_into<U: Voxel>(src: &[[f32; 2]], dst: &mut [U], background: f64) {
    for (d, &[v, w]) in dst.iter_mut().zip(src) {
        *d = U::from_f64(normalise(f64::from(v), f64::from(w), background));
    }
}

/// The tallies of one input slab over the output z-planes `z0 .. z0 + data.len()/plane`.
struct SlabTally {
    z0: usize,
    data: Vec<[f32; 2]>,
    stats: PushForwardStats,
}

/// Tally `[V, W]` per output voxel over all input slabs, combined in slab order.
fn accumulate<T: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    options: &AntialiasOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<(Vec<[f32; 2]>, PushForwardStats), WarpError> {
    output.validate().map_err(output_geometry)?;
    if !options.background.is_finite() {
        return Err(WarpError::Background(options.background));
    }
    let to_index = ToIndex::new(output);
    let plane_out = output.dims[0] * output.dims[1];
    // Filled plane by plane as the slab tallies arrive (see `add_tally`), not zeroed first.
    let mut acc = Vec::new();
    acc.try_reserve_exact(output.len())
        .map_err(|_| WarpError::Allocation {
            what: "accumulator",
            bytes: output.len().saturating_mul(std::mem::size_of::<[f32; 2]>()),
        })?;
    let mut stats = PushForwardStats::default();
    let slab_list = slabs(input.geometry().dims);
    // Slabs run in parallel in windows of one slab per thread; each window's tallies are
    // added in slab order, so the sums never depend on the thread count.
    let window = rayon::current_num_threads().max(1);
    progress.start("antialiased push-forward", input.geometry().dims[2] as u64);
    for batch in slab_list.chunks(window) {
        progress.check()?;
        let tallies: Vec<Result<SlabTally, WarpError>> = batch
            .par_iter()
            .map(|&slab| {
                progress.check()?;
                let t = tally_slab(input, map, output, &to_index, options.face_centres, slab);
                progress.advance((slab.1 - slab.0) as u64);
                t
            })
            .collect();
        for tally in tallies {
            let tally = tally?;
            stats.add(&tally.stats);
            if tally.data.is_empty() {
                continue;
            }
            add_tally(&mut acc, tally.z0 * plane_out, &tally.data, plane_out);
        }
    }
    progress.check()?;
    acc.resize(output.len(), [0.0; 2]);
    Ok((acc, stats))
}

/// Add a slab's tallies `data`, which start at accumulator index `start`, to `acc`, whose
/// length marks the planes tallied so far (every later index is an implicit +0): indices
/// already there get `+= s`, a gap before `start` gets zeros, and indices past the end are
/// appended as `0 + s`, the very sum a zeroed accumulator would hold (so the result has the
/// bits of zeroing the whole accumulator first and adding every tally, without that extra
/// pass over it). `acc` must have the capacity for every index.
fn add_tally(acc: &mut Vec<[f32; 2]>, start: usize, data: &[[f32; 2]], plane: usize) {
    if acc.len() < start {
        acc.resize(start, [0.0; 2]);
    }
    let (old, new) = data.split_at((acc.len() - start).min(data.len()));
    acc[start..start + old.len()]
        .par_chunks_mut(plane.max(1))
        .zip(old.par_chunks(plane.max(1)))
        .for_each(|(d, s)| {
            for (d, s) in d.iter_mut().zip(s) {
                d[0] += s[0];
                d[1] += s[1];
            }
        });
    acc.par_extend(new.par_iter().map(|s| [0.0 + s[0], 0.0 + s[1]]));
}

/// Evaluate `map` on the points of box `bx` of `grid` (tile by tile, see
/// [`crate::centres`]), convert the images to output indices and return them with the span
/// `(min z, max z)` of the finite ones (`(+∞, −∞)` if none).
pub(crate) fn images<M: SpaceMap + ?Sized>(
    map: &M,
    input: &Geometry,
    grid: &PointGrid,
    bx: &Region,
    to_index: &ToIndex,
) -> Result<(Vec<DVec3>, (f64, f64)), WarpError> {
    let mut pts = volmorph_io::try_vec("mapped points", bx.len(), DVec3::ZERO).map_err(|_| {
        WarpError::Allocation {
            what: "mapped points",
            bytes: bx.len().saturating_mul(std::mem::size_of::<DVec3>()),
        }
    })?;
    grid.eval_box(map, input, bx, &mut pts)?;
    // Convert to output indices and take the z span of the finite images in the same pass
    // (min/max are order-independent, so the span does not depend on the thread count).
    let span = pts
        .par_chunks_mut(4096)
        .map(|c| {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for p in c {
                *p = to_index.apply(*p);
                if p.is_finite() {
                    lo = lo.min(p.z);
                    hi = hi.max(p.z);
                }
            }
            (lo, hi)
        })
        .reduce(
            || (f64::INFINITY, f64::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        );
    Ok((pts, span))
}

/// The union of two z spans.
fn union(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0.min(b.0), a.1.max(b.1))
}

/// Tally the input slab `k0..k1` into a buffer over the output z-planes it reaches.
fn tally_slab<T: Voxel, M: SpaceMap + ?Sized>(
    input: &Volume<T, impl AsRef<[T]> + Sync>,
    map: &M,
    output: &Geometry,
    to_index: &ToIndex,
    faces: FaceCentres,
    (k0, k1): (usize, usize),
) -> Result<SlabTally, WarpError> {
    let g = input.geometry();
    let [nx, ny, _] = g.dims;
    let nk = k1 - k0;
    let values = &input.data()[k0 * nx * ny..k1 * nx * ny];
    match faces {
        FaceCentres::Mapped => {
            let face = |a: usize| {
                let mut dims = [nx, ny, nk];
                dims[a] += 1;
                let bx = Region {
                    lo: [0, 0, k0],
                    dims,
                };
                images(map, g, &PointGrid::faces(a, g.dims), &bx, to_index)
            };
            let (fx, sx) = face(0)?;
            let (fy, sy) = face(1)?;
            let (fz, sz) = face(2)?;
            let span = union(union(sx, sy), sz);
            let (region, mut data) = slab_buffer(output, span)?;
            let faces = FaceImages {
                x: &fx,
                y: &fy,
                z: &fz,
                dims: [nx, ny, nk],
            };
            let all = Region {
                lo: [0; 3],
                dims: [nx, ny, nk],
            };
            let stats = tally_mapped(
                values,
                [nx, ny, nk],
                &all,
                &faces,
                output.dims,
                &region,
                &mut data,
            );
            Ok(SlabTally {
                z0: region.lo[2],
                data,
                stats,
            })
        }
        FaceCentres::AveragedCentres => {
            // Voxel centres with a one-voxel margin: index (i, j, k) of the slab is entry
            // (i + 1, j + 1, k + 1) of this box.
            let bx = Region {
                lo: [0, 0, k0],
                dims: [nx + 2, ny + 2, nk + 2],
            };
            let (c, span) = images(map, g, &PointGrid::centres(g.dims), &bx, to_index)?;
            // The face averages lie within the span of the centres.
            let (region, mut data) = slab_buffer(output, span)?;
            let src = Voxels {
                values,
                vdims: [nx, ny, nk],
                centres: &c,
                cdims: [nx + 2, ny + 2],
            };
            let all = Region {
                lo: [0; 3],
                dims: [nx, ny, nk],
            };
            let stats = tally_averaged(&src, &all, [1, 1, 1], output.dims, &region, &mut data, 1.0);
            Ok(SlabTally {
                z0: region.lo[2],
                data,
                stats,
            })
        }
    }
}

/// The zeroed tally buffer of a slab whose finite images have z in `(zlo, zhi)`: whole output
/// planes over the z cells that span reaches (empty if none).
fn slab_buffer(
    output: &Geometry,
    (zlo, zhi): (f64, f64),
) -> Result<(Region, Vec<[f32; 2]>), WarpError> {
    let [nxo, nyo, nzo] = output.dims;
    let region = match cell_range(zlo, zhi, nzo) {
        Some((a, b)) => Region {
            lo: [0, 0, a],
            dims: [nxo, nyo, b - a + 1],
        },
        None => Region::default(),
    };
    let data = try_filled(region.len(), [0.0f32; 2], "slab accumulator")?;
    Ok((region, data))
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_testkit::Rng;

    /// Filling the accumulator as the tallies arrive gives the bits of zeroing it first and
    /// adding every tally, whatever planes the tallies cover: gaps no tally reaches, tallies
    /// overlapping the planes before them, tallies reaching back below the planes filled
    /// so far, and trailing planes nothing reaches.
    #[test]
    fn accumulator_filled_on_arrival_equals_zeroed_then_added() {
        let mut rng = Rng::new(3);
        let plane = 6;
        let planes = 12;
        for case in 0..200 {
            let mut want = vec![[0.0f32; 2]; plane * planes];
            let mut got = Vec::with_capacity(plane * planes);
            for _ in 0..1 + rng.index(5) {
                let z0 = rng.index(planes);
                let nz = 1 + rng.index(planes - z0);
                let data: Vec<[f32; 2]> = (0..nz * plane)
                    .map(|_| {
                        if rng.chance(0.2) {
                            [0.0, 0.0]
                        } else {
                            [rng.range(-5.0, 300.0) as f32, rng.range(0.0, 2.0) as f32]
                        }
                    })
                    .collect();
                for (d, s) in want[z0 * plane..].iter_mut().zip(&data) {
                    d[0] += s[0];
                    d[1] += s[1];
                }
                add_tally(&mut got, z0 * plane, &data, plane);
            }
            got.resize(plane * planes, [0.0; 2]);
            let bits = |v: &[[f32; 2]]| -> Vec<[u32; 2]> {
                v.iter().map(|c| c.map(f32::to_bits)).collect()
            };
            assert_eq!(bits(&got), bits(&want), "case {case}");
        }
    }
}
