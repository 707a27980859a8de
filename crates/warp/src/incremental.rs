//! Incremental antialiased push-forward through a map edited live: a B-spline lattice (True
//! 1992 §5.3 "the main loop", §5.4) or any other [`LinearMap`] (handle maps).

//!
//! **Direction.** As in [`crate::pushforward`]: every *source* voxel is pushed forward to
//! where the map sends it, and its box-filtered value is spread over the *output* voxels
//! its proxy box overlaps.
//!
//! [`IncrementalPushForward`] keeps the images of the voxel centres (True's "deformation
//! mapping array", with the one-voxel margin that averaged face centres need) and the
//! current output, so that moving parameters (control points, handle targets) only redoes
//! what they influence, as in True's main loop:
//!
//! 1. **Influenced region.** The map says where the moved parameters can change it
//!    ([`LinearMap::influence`]). For a lattice, control point `i` of an axis of degree `p`
//!    blends the knot spans `i ..= i + p` (span index `s` = `[u_s, u_{s+1})`, blended by
//!    control points `s − p ..= s`; in True's region numbering, regions `i − 3 ..= i`); the
//!    bounding box of the non-empty spans of all moved points (read from the knot vector of
//!    each axis, so any degree and any knots) is the parameter box where the map can change,
//!    and its image under the lattice frame is the influence; outside it, and outside the
//!    lattice box (where the map is the identity), nothing changes. Handle maps influence
//!    everything. The region is turned into the box of voxel centres (margin included) it
//!    contains, widened by [`PARAMETER_MARGIN`] voxels against rounding.
//! 2. **Redone voxels.** A source voxel's proxy box depends on its own centre image and its
//!    six neighbours' (face centres are averages), so the voxels whose boxes change are the
//!    influenced centres dilated by one voxel, clipped to the source.
//! 3. **Remap.** The influenced centre images are re-evaluated with the new map through
//!    [`SpaceMap::apply_grid`](volmorph_deform::SpaceMap::apply_grid) on the fixed tiles
//!    every push-forward evaluates them on (whole tiles of 64 × 64 points one plane deep, so
//!    the images have the bits of a full evaluation) and stored, in one pass that also
//!    bounds the redone voxels' old and new boxes.
//!    Every output voxel those boxes overlap may change; no other can.
//! 4. **Recompute the changed output region.** True erases the old boxes of the redone
//!    voxels and adds their new ones. Here the tallies `[V, W]` of the output voxels in the
//!    bounding box of the old and new boxes are instead summed afresh from every source
//!    voxel whose box reaches them, and renormalised with True's rule (see
//!    [`crate::pushforward`]). The result is the same, but each redone voxel is tallied
//!    once instead of twice, and nothing cancels, so nothing drifts over many edits.
//!    The voxels whose boxes reach the region are found through the bounds of the boxes of
//!    short runs of voxels along x (blocks; see `BLOCK`), kept up to date in step 3.
//!
//! The moved control points are handled together: the redone region is the bounding box
//! of their influence, which suits the clusters that dragging a point moves (the control
//! points blending one region). Callers moving far-apart points at once may update per
//! cluster instead (each update is exact).
//!
//! Every output voxel sums its contributions in one fixed order (source voxels in index
//! order), whatever region is recomputed and however the work is split over threads, so
//! results are bit for bit the same for any number of threads, and after any sequence of
//! edits the volume is, bit for bit, the one a new engine built with the current map holds
//! (centre images are evaluated on the same fixed tiles whatever region is redone). It
//! equals
//! [`push_forward_antialiased_f32`](crate::pushforward::push_forward_antialiased_f32) with
//! the current map and the same options up to the `f32` accumulation of the latter
//! (about 1e-6 relative; the engine sums in `f64`).
//!
//! # Memory
//!
//! The engine holds, for a source of `n = nx·ny·nz` voxels and an output of `m` voxels:
//! the source values (`4n` bytes, `f32`), the centre images (`24·(nx+2)(ny+2)(nz+2)` bytes,
//! `f64` points in output index space), a status byte and `3` bytes of block bounds per
//! source voxel, scratch tallies (`16m` bytes, all zero between updates) and the current
//! volume (`4m` bytes) — about 110 MB for 128³ → 128³, 880 MB for 256³ → 256³. An update
//! adds only the re-evaluated centre images (`24` bytes each, kept between updates).
//!
//! # Why the nearest ("map and round") preview is not incremental
//!
//! True's cheap preview (§5.3 and footnote 4) writes each voxel into the output voxel
//! nearest to its image, and [`push_forward_nearest`](crate::pushforward::push_forward_nearest)
//! resolves collisions by keeping the **largest** value. A maximum cannot be un-added: when
//! a voxel leaves an output voxel, the new value is the maximum of the *remaining*
//! colliders, which are not recorded anywhere and would have to be found by scanning every
//! source voxel (True instead writes zeros, which is only approximate). An exact scheme
//! would need a per-output-voxel multiset of colliders — memory and bookkeeping that cost
//! more than the preview saves. The preview is cheap enough to recompute in full; only the
//! antialiased push-forward, whose tallies are sums, is maintained incrementally.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_deform::LinearMap;
//! use volmorph_lattice::BSplineLattice;
//! use volmorph_volume::{Geometry, Volume};
//! use volmorph_warp::incremental::IncrementalPushForward;
//! use volmorph_warp::pushforward::{AntialiasOptions, push_forward_antialiased_f32};
//!
//! let g = Geometry::new([16, 16, 16]);
//! let v = Volume::from_fn(g, |i, j, k| ((i * 7 + j * 3 + k) % 11) as f32)?;
//! let (lo, hi) = g.physical_bounds();
//! let lattice = BSplineLattice::uniform_cubic_around(lo, hi, [7, 7, 7])?;
//! let opts = AntialiasOptions::default();
//! let mut engine = IncrementalPushForward::new(&v, lattice, &g, &opts)?;
//! // Move control point [2, 2, 2] (parameter 2 + 7·(2 + 7·2)) by (1.5, −0.5, 0.25).
//! let k = engine.map().parameter_of([2, 2, 2])?;
//! let p = engine.map().control_point([2, 2, 2])? + DVec3::new(1.5, -0.5, 0.25);
//! let report = engine.set_parameters(&[(k, p)])?;
//! assert!(report.redone > 0 && report.redone < v.len());
//! let full = push_forward_antialiased_f32(&v, engine.map(), &g, &opts)?;
//! for (a, b) in engine.volume().data().iter().zip(full.volume.data()) {
//!     assert!((a - b).abs() <= 1e-5 * 10.0);
//! }
//! assert_eq!(engine.stats(), full.stats);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::sync::atomic::AtomicU8;
use std::sync::atomic::Ordering::Relaxed;

use glam::DVec3;
use multiversion::multiversion;
use rayon::prelude::*;
use volmorph_deform::live::{Influence, LinearMap, changed_parameters};
use volmorph_volume::{Geometry, IndexBox, Volume, Voxel};

use crate::WarpError;
use crate::centres::PointGrid;
use crate::pushforward::{
    AntialiasOptions, FaceCentres, PushForwardStats, ToIndex, normalise, output_geometry,
    try_filled,
};
use crate::tally::{
    MAPPED, NON_FINITE, OUTSIDE, Region, RowBoxes, Target, Voxels, reaches_grid, row, vmax, vmin,
};

/// Widening, in source voxels, of the box of voxel centres whose parameters lie in the
/// influenced parameter box. The map evaluation and this test compute a centre's parameter
/// along different roundings (≈1e-13 relative); a voxel redone needlessly costs a little
/// time, a voxel missed would be wrong, so the margin is generous.
pub const PARAMETER_MARGIN: f64 = 1e-6;

/// What an update of an [`IncrementalPushForward`] did. Counts only, no timings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct UpdateReport {
    /// Parameters (control points, handle targets) whose value changed.
    pub moved: usize,
    /// Voxel centres whose images were re-evaluated (including the one-voxel margin around
    /// the source that averaged face centres use).
    pub remapped: usize,
    /// Source voxels whose boxes may have changed (`source_box.len()`).
    pub redone: usize,
    /// The redone source voxels (source indices; empty if the edit reaches no voxel).
    pub source_box: IndexBox,
    /// The output voxels recomputed: every one whose value may have changed (output
    /// indices; empty if none).
    pub output_box: IndexBox,
    /// The redone voxels under the old map.
    pub before: PushForwardStats,
    /// The redone voxels under the new map. The engine's [`stats`] change by
    /// `after − before`.
    ///
    /// [`stats`]: IncrementalPushForward::stats
    pub after: PushForwardStats,
}

/// Edge lengths (x, y, z), in source voxels, of the blocks of the source grid whose
/// proxy-box bounds the engine keeps (see [`IncrementalPushForward`]): a recomputed output
/// region visits the voxels of every block whose bounds reach it, so smaller blocks visit
/// fewer needless voxels around the region and larger ones cost less bookkeeping. Longer
/// in x, the contiguous axis, to keep rows long.
const BLOCK: [usize; 3] = [16, 1, 1];

/// Fewest output planes in one slab of a recomputed output region: a block whose boxes
/// straddle a slab boundary is visited by both slabs, so slabs much thinner than a block's
/// reach would visit most blocks twice.
const MIN_SLAB_PLANES: usize = 8;

/// The antialiased push-forward of a source volume through a [`LinearMap`] (a lattice, affine
/// or frame MLS, a thin-plate spline), kept up to date under parameter moves by recomputing
/// only the output region they can change: the voxels the moved parameters'
/// [`Influence`] reaches (see the [module docs](self) for the algorithm, its exactness and its
/// memory use). A lattice's control point influences the image of its support box; a handle
/// map's target influences everything, so there an update is a full recompute.
///
/// The result always equals
/// [`push_forward_antialiased_f32`](crate::pushforward::push_forward_antialiased_f32) of the
/// source with [`map`](Self::map) on the output geometry with the engine's options
/// (to the `f32` rounding of the latter), and [`stats`](Self::stats) equals its
/// [`PushForwardStats`]. It is moreover, up to the rounding of re-evaluated centre images,
/// the volume a new engine built with the current map holds, whatever the edits that
/// led to it, and bit for bit the same for any number of threads.
#[derive(Debug)]
pub struct IncrementalPushForward<M> {
    source: Geometry,
    values: Vec<f32>,
    map: M,
    output: Geometry,
    to_index: ToIndex,
    background: f64,
    /// Images of the voxel centres of the source grid widened by one voxel on every side
    /// (source index `v` is entry `v + 1`), in output continuous-index space.
    centres: Vec<DVec3>,
    /// Per source voxel (x fastest): [`MAPPED`], [`OUTSIDE`] or [`NON_FINITE`].
    status: Vec<AtomicU8>,
    /// Number of centre images that are not [`sane`]; while there are none, every voxel
    /// has a proxy box and boxes are computed without checks.
    insane: usize,
    blocks: Blocks,
    volume: Volume<f32>,
    stats: PushForwardStats,
    /// Centre images re-evaluated by an update (kept to reuse the allocation).
    fresh: Vec<DVec3>,
    /// Tallies `[V, W]` of a recomputed output region (kept to reuse the allocation).
    scratch: Vec<[f64; 2]>,
    /// The [`Segments`] of the last update (kept to reuse the allocation).
    segment_store: Vec<(DVec3, DVec3)>,
}

/// The source grid cut into [`BLOCK`]-sized blocks (the last ones per axis shorter), with
/// the bounds, in output index space, of the proxy boxes of each block's voxels.
#[derive(Debug)]
struct Blocks {
    /// Blocks per axis.
    counts: [usize; 3],
    /// Per block (x fastest): the bounds of its voxels' finite proxy boxes, `(+∞, −∞)` if
    /// it has none.
    bounds: Vec<(DVec3, DVec3)>,
    /// Per z-layer of blocks: the union of its blocks' bounds.
    layers: Vec<(DVec3, DVec3)>,
}

impl Blocks {
    /// The blocks of a source grid of `dims`, with empty bounds.
    fn new(dims: [usize; 3]) -> Result<Self, WarpError> {
        let counts = [0, 1, 2].map(|a| dims[a].div_ceil(BLOCK[a]));
        let len = counts[0] * counts[1] * counts[2];
        let empty = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        Ok(Self {
            counts,
            bounds: try_filled(len, empty, "block bounds")?,
            layers: try_filled(counts[2], empty, "block bounds")?,
        })
    }

    /// The source voxels of block `[i, j, k]` in a source grid of `dims`.
    fn voxels(index: [usize; 3], dims: [usize; 3]) -> Region {
        let mut r = Region::default();
        for a in 0..3 {
            r.lo[a] = index[a] * BLOCK[a];
            r.dims[a] = BLOCK[a].min(dims[a] - r.lo[a]);
        }
        r
    }

    /// Range of block indices per axis (half-open) of the blocks meeting `voxels`.
    fn meeting(voxels: &Region) -> [(usize, usize); 3] {
        [0, 1, 2].map(|a| {
            let lo = voxels.lo[a];
            (lo / BLOCK[a], (lo + voxels.dims[a]).div_ceil(BLOCK[a]))
        })
    }
}

/// Bounds of the finite centre images along stretches of margin rows: for each margin row
/// (y, z) of `rows` and each block column `i` of `columns`, the row's images under the
/// column's voxels and their ±x neighbours (margin x from `16·i` for [`BLOCK`]`[0] = 16`,
/// `BLOCK[0] + 2` of them). A block's bounds are the union of the segments of the rows
/// its voxels and their neighbours sit on.
struct Segments {
    /// The margin rows covered (x extent unused).
    rows: Region,
    /// Block columns `i0 .. i1` (half-open).
    columns: (usize, usize),
    /// Planes of rows of columns, x fastest.
    bounds: Vec<(DVec3, DVec3)>,
}

impl Segments {
    /// Empty segments of `rows` × `columns`, stored in `store` (its allocation reused: a
    /// fresh one of several megabytes would be paged in anew by every update).
    fn new(rows: Region, columns: (usize, usize), mut store: Vec<(DVec3, DVec3)>) -> Self {
        let n = rows.dims[1] * rows.dims[2] * (columns.1 - columns.0);
        store.clear();
        store.resize(n, (DVec3::INFINITY, DVec3::NEG_INFINITY));
        Self {
            rows,
            columns,
            bounds: store,
        }
    }

    /// Empty segments of the margin rows and block columns the blocks meeting `redo` read,
    /// in a source grid of `dims`, stored in `store` (see [`Segments::new`]).
    fn covering(redo: &Region, dims: [usize; 3], store: Vec<(DVec3, DVec3)>) -> Self {
        let [(i0, i1), (j0, j1), (k0, k1)] = Blocks::meeting(redo);
        let [_, by, bz] = BLOCK;
        let rows = Region {
            lo: [0, j0 * by, k0 * bz],
            dims: [
                dims[0] + 2,
                (j1 * by).min(dims[1]) + 2 - j0 * by,
                (k1 * bz).min(dims[2]) + 2 - k0 * bz,
            ],
        };
        Self::new(rows, (i0, i1), store)
    }

    /// Number of block columns.
    fn columns(&self) -> usize {
        self.columns.1 - self.columns.0
    }

    /// The segment of margin row `(y, z)` under block column `i`, if covered.
    fn get(&self, y: usize, z: usize, i: usize) -> Option<(DVec3, DVec3)> {
        let dy = y
            .checked_sub(self.rows.lo[1])
            .filter(|&d| d < self.rows.dims[1])?;
        let dz = z
            .checked_sub(self.rows.lo[2])
            .filter(|&d| d < self.rows.dims[2])?;
        let di = i
            .checked_sub(self.columns.0)
            .filter(|&d| d < self.columns())?;
        self.bounds
            .get((dz * self.rows.dims[1] + dy) * self.columns() + di)
            .copied()
    }

    /// Fill `out` (one entry per column of `columns`) with the segments of the full margin
    /// row `row` of a source grid of `dims`.
    #[inline(always)]
    fn of_row(
        row: &[DVec3],
        columns: (usize, usize),
        dims: [usize; 3],
        out: &mut [(DVec3, DVec3)],
    ) {
        for (i, seg) in (columns.0..columns.1).zip(out) {
            let vbox = Blocks::voxels([i, 0, 0], dims);
            let (a, b) = (vbox.lo[0], vbox.lo[0] + vbox.dims[0] + 2);
            let mut hull = Hull::EMPTY;
            hull.add_all(row.get(a..b).unwrap_or(&[]));
            *seg = (hull.lo, hull.hi);
        }
    }
}

/// The [`IndexBox`] of a region (empty for an empty region).
fn index_box_of(r: &Region) -> IndexBox {
    if r.is_empty() {
        return IndexBox::default();
    }
    IndexBox {
        start: r.lo,
        end: [0, 1, 2].map(|a| r.lo[a] + r.dims[a]),
    }
}

impl<M: LinearMap + Clone> IncrementalPushForward<M> {
    /// Push `source` (values converted to `f32`) forward through `map` onto `output` with
    /// True's box-filter antialiasing, keeping the state for incremental updates.
    ///
    /// `options.face_centres` must be [`FaceCentres::AveragedCentres`] (True's method, the
    /// default): the incremental scheme rests on stored voxel-centre images, as True's
    /// footnote 4 explains; `options.background` is honoured as in the full push-forward.
    ///
    /// # Errors
    /// [`WarpError::Geometry`] for an invalid `output`, [`WarpError::Background`] for a
    /// non-finite background, [`WarpError::Unsupported`] for
    /// [`FaceCentres::Mapped`], [`WarpError::MapOnGrid`] if the map fails on the
    /// voxel-centre grid, [`WarpError::Allocation`] if a buffer cannot be allocated.
    pub fn new<T: Voxel>(
        source: &Volume<T>,
        map: M,
        output: &Geometry,
        options: &AntialiasOptions,
    ) -> Result<Self, WarpError> {
        Self::new_with(source, map, output, options, &volmorph_io::NoProgress)
    }

    /// [`IncrementalPushForward::new`] reporting to `progress` and stopping when it is
    /// cancelled: a stage "mapping voxel centres" of one step, then "antialiased
    /// push-forward" whose steps are the output's z-planes, advanced slab by slab. The engine
    /// equals [`IncrementalPushForward::new`]'s bit for bit.
    ///
    /// # Errors
    /// As [`IncrementalPushForward::new`]; [`WarpError::Cancelled`] when `progress` asks to
    /// stop.
    pub fn new_with<T: Voxel>(
        source: &Volume<T>,
        map: M,
        output: &Geometry,
        options: &AntialiasOptions,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Self, WarpError> {
        output.validate().map_err(output_geometry)?;
        if !options.background.is_finite() {
            return Err(WarpError::Background(options.background));
        }
        if options.face_centres != FaceCentres::AveragedCentres {
            return Err(WarpError::Unsupported(
                "the incremental push-forward needs averaged face centres (True's method); \
                 mapped face centres are only available in the full push-forward",
            ));
        }
        let g = *source.geometry();
        let [nx, ny, nz] = g.dims;
        let cdims = [nx + 2, ny + 2, nz + 2];
        let clen = cdims
            .iter()
            .try_fold(1usize, |acc, &d| acc.checked_mul(d))
            .ok_or(WarpError::Allocation {
                what: "voxel-centre images",
                bytes: usize::MAX,
            })?;
        let mut values = try_filled(source.len(), 0.0f32, "source values")?;
        values
            .par_iter_mut()
            .zip(source.data().par_iter())
            .for_each(|(d, s)| *d = s.to_f64() as f32);
        let to_index = ToIndex::new(output);
        let mut centres = try_filled(clen, DVec3::ZERO, "voxel-centre images")?;
        progress.start("mapping voxel centres", 1);
        progress.check()?;
        let all = Region {
            lo: [0; 3],
            dims: cdims,
        };
        PointGrid::centres(g.dims).eval_box(&map, &g, &all, &mut centres)?;
        centres
            .par_iter_mut()
            .with_min_len(4096)
            .for_each(|p| *p = to_index.apply(*p));
        progress.advance(1);
        progress.check()?;
        let mut status = Vec::new();
        status
            .try_reserve_exact(source.len())
            .map_err(|_| WarpError::Allocation {
                what: "voxel statuses",
                bytes: source.len(),
            })?;
        status.extend((0..source.len()).map(|_| AtomicU8::new(OUTSIDE)));
        let data = try_filled(output.len(), 0.0f32, "output")?;
        let volume = Volume::new(*output, data).map_err(output_geometry)?;
        let mut engine = Self {
            source: g,
            values,
            map,
            output: *output,
            to_index,
            background: options.background,
            centres,
            status,
            insane: 0,
            blocks: Blocks::new(g.dims)?,
            volume,
            stats: PushForwardStats::default(),
            fresh: Vec::new(),
            scratch: try_filled(output.len(), [0.0; 2], "tallies")?,
            segment_store: Vec::new(),
        };
        let all = Region {
            lo: [0; 3],
            dims: g.dims,
        };
        let everything = Region {
            lo: [0; 3],
            dims: output.dims,
        };
        engine.insane = engine.centres.par_iter().filter(|p| !sane(**p)).count();
        engine.refresh_blocks(&all, None);
        engine.reset_statuses(&all, engine.insane == 0);
        progress.start("antialiased push-forward", output.dims[2] as u64);
        engine.recompute(&everything, &all, progress);
        progress.check()?;
        engine.stats = engine.count(&all);
        Ok(engine)
    }

    /// The current push-forward on the output geometry. Kept up to date by every update
    /// (only the output voxels an update can reach are recomputed).
    #[must_use]
    pub fn volume(&self) -> &Volume<f32> {
        &self.volume
    }

    /// The map the current volume is the push-forward through.
    #[must_use]
    pub fn map(&self) -> &M {
        &self.map
    }

    /// The source geometry.
    #[must_use]
    pub fn source_geometry(&self) -> &Geometry {
        &self.source
    }

    /// The output geometry.
    #[must_use]
    pub fn output_geometry(&self) -> &Geometry {
        &self.output
    }

    /// The background value (see [`AntialiasOptions::background`]).
    #[must_use]
    pub fn background(&self) -> f64 {
        self.background
    }

    /// What happens to the source voxels under the current map (equal to the
    /// [`PushForwardStats`] of a full push-forward).
    #[must_use]
    pub fn stats(&self) -> PushForwardStats {
        self.stats
    }

    /// Consume the engine, returning the current volume.
    #[must_use]
    pub fn into_volume(self) -> Volume<f32> {
        self.volume
    }

    /// Set parameters: `(k, value)` gives parameter `k` (see [`LinearMap`]; for a lattice,
    /// control point `i + nu·(j + nv·k)`) the new value `value` (physical units), in order (a
    /// `k` may repeat), then updates the push-forward incrementally (see the
    /// [module docs](self)).
    ///
    /// # Errors
    /// [`WarpError::Parameters`] if an index is out of range or a new value is NaN or
    /// infinite; [`WarpError::MapOnGrid`] if the new map fails on the voxel-centre grid;
    /// [`WarpError::Allocation`] if the re-evaluated centre images cannot be stored. On error
    /// the engine is unchanged.
    pub fn set_parameters(
        &mut self,
        changes: &[(usize, DVec3)],
    ) -> Result<UpdateReport, WarpError> {
        let mut map = self.map.clone();
        map.set_some_parameters(changes)
            .map_err(WarpError::Parameters)?;
        let (old, new) = (self.map.parameters(), map.parameters());
        let mut moved: Vec<usize> = changes
            .iter()
            .map(|c| c.0)
            .filter(|&k| old.get(k) != new.get(k))
            .collect();
        moved.sort_unstable();
        moved.dedup();
        self.update(map, &moved)
    }

    /// Replace the map by `map`, which must have the same structure
    /// ([`LinearMap::same_structure`]: same knots and frame, same source handles): the
    /// parameters that differ are found and the push-forward is updated incrementally.
    ///
    /// # Errors
    /// [`WarpError::StructureMismatch`] if the structure differs;
    /// [`WarpError::MapOnGrid`] and [`WarpError::Allocation`] as
    /// [`set_parameters`](Self::set_parameters). On error the engine is unchanged.
    pub fn set_map(&mut self, map: M) -> Result<UpdateReport, WarpError> {
        if !map.same_structure(&self.map) {
            return Err(WarpError::StructureMismatch);
        }
        let moved = changed_parameters(&self.map.parameters(), &map.parameters());
        self.update(map, &moved)
    }

    /// Update from the current map to `map`, whose parameters `moved` differ.
    fn update(&mut self, map: M, moved: &[usize]) -> Result<UpdateReport, WarpError> {
        let mut report = UpdateReport {
            moved: moved.len(),
            ..UpdateReport::default()
        };
        let influenced = self.influenced_centres(&map, moved);
        if influenced.is_empty() {
            self.map = map;
            return Ok(report);
        }
        // Source voxels reading an influenced centre (their own or a neighbour's).
        let mut redo = Region::default();
        for a in 0..3 {
            let lo = influenced.lo[a].saturating_sub(2);
            let hi = (influenced.lo[a] + influenced.dims[a]).min(self.source.dims[a]);
            redo.lo[a] = lo;
            redo.dims[a] = hi.saturating_sub(lo);
        }
        // New centre images of the influenced box (margin coordinates m = source index + 1,
        // the indices of the centre grid), in physical space, on the tiles every push-forward
        // evaluates them on: the very bits a new engine or the full push-forward holds.
        let len = influenced.len();
        reserve(&mut self.fresh, len, "voxel-centre images")?;
        self.fresh.resize(len, DVec3::ZERO);
        PointGrid::centres(self.source.dims).eval_box(
            &map,
            &self.source,
            &influenced,
            &mut self.fresh[..len],
        )?;
        // Everything that can fail is done: commit.
        let before = self.count(&redo);
        // The redone voxels' boxes, old and new, lie between the centre images they read:
        // the old ones of their neighbourhood and the fresh ones (the neighbourhood's
        // unchanged images are among the old ones).
        let neighbourhood = Region {
            lo: redo.lo,
            dims: [0, 1, 2].map(|a| redo.dims[a] + 2),
        };
        let store = std::mem::take(&mut self.segment_store);
        let mut segments = Segments::covering(&redo, self.source.dims, store);
        let hulls = swap_in(
            &mut self.centres,
            self.source.dims,
            &neighbourhood,
            &self.fresh[..len],
            &influenced,
            &self.to_index,
            &mut segments,
            self.insane == 0,
        );
        let touched = Region::of_bounds(
            vmin(hulls.old.lo, hulls.new.lo),
            vmax(hulls.old.hi, hulls.new.hi),
            self.output.dims,
        );
        self.refresh_blocks(&redo, Some(&segments));
        self.segment_store = segments.bounds;
        self.insane = self.insane.saturating_sub(hulls.replaced_insane) + hulls.new_insane;
        self.reset_statuses(&redo, self.insane == 0);
        self.recompute(&touched, &redo, &volmorph_io::NoProgress);
        let after = self.count(&redo);
        self.map = map;
        self.stats = PushForwardStats {
            mapped: self.stats.mapped.saturating_sub(before.mapped) + after.mapped,
            non_finite: self.stats.non_finite.saturating_sub(before.non_finite) + after.non_finite,
            outside: self.stats.outside.saturating_sub(before.outside) + after.outside,
        };
        report.remapped = len;
        report.redone = redo.len();
        report.source_box = index_box_of(&redo);
        report.output_box = index_box_of(&touched);
        report.before = before;
        report.after = after;
        Ok(report)
    }

    /// The box, in margin coordinates (source index + 1, `0 ..= n + 1` per axis), of the
    /// voxel centres whose images can change when parameters `moved` of `map` change: those in
    /// the parameters' [`Influence`].
    fn influenced_centres(&self, map: &M, moved: &[usize]) -> Region {
        let (lo, hi) = match map.influence(moved) {
            Influence::Nowhere => return Region::default(),
            Influence::Everywhere => {
                return Region {
                    lo: [0; 3],
                    dims: self.source.dims.map(|n| n + 2),
                };
            }
            Influence::Within(corners) => {
                // Source continuous indices of the region's corners.
                let mut lo = DVec3::INFINITY;
                let mut hi = DVec3::NEG_INFINITY;
                for c in corners {
                    let x = self.source.physical_to_index(c);
                    lo = lo.min(x);
                    hi = hi.max(x);
                }
                (lo, hi)
            }
        };
        let mut r = Region::default();
        for a in 0..3 {
            let n = self.source.dims[a] as f64;
            // Margin centres sit at source indices −1 ..= n.
            let first = (lo[a] - PARAMETER_MARGIN).ceil().max(-1.0);
            let last = (hi[a] + PARAMETER_MARGIN).floor().min(n);
            if first.partial_cmp(&last).is_none_or(|o| o.is_gt()) {
                return Region::default();
            }
            // Both are integers in −1 ..= n here.
            r.lo[a] = (first + 1.0) as usize;
            r.dims[a] = (last - first) as usize + 1;
        }
        r
    }

    /// Recompute the bounds of every block meeting `redo` from the stored centre images: the
    /// bounds of the finite images of the block's voxel centres and their neighbours, which
    /// hold every proxy box of the block (a box's corners are means of such images).
    ///
    /// In two passes, so each image is read about once: the [`Segments`] of the margin rows
    /// the blocks read (given, or computed here, parallel over planes), then per block the
    /// union of its rows' segments (parallel over z-layers of blocks).
    fn refresh_blocks(&mut self, redo: &Region, given: Option<&Segments>) {
        if redo.is_empty() {
            return;
        }
        let dims = self.source.dims;
        let [cx, cy, _] = self.blocks.counts;
        let [(i0, i1), (j0, j1), (k0, k1)] = Blocks::meeting(redo);
        let mut computed = None;
        let segments = match given {
            Some(s) => s,
            None => {
                let mut s = Segments::covering(redo, dims, Vec::new());
                let rows = s.rows;
                let ncol = s.columns();
                let plane = rows.dims[1] * ncol;
                let cdims = [dims[0] + 2, dims[1] + 2];
                let centres = &self.centres;
                s.bounds
                    .par_chunks_mut(plane)
                    .enumerate()
                    .for_each(|(dz, out)| {
                        for (dy, out) in out.chunks_exact_mut(ncol).enumerate() {
                            let start = cdims[0] * (rows.lo[1] + dy + cdims[1] * (rows.lo[2] + dz));
                            if let Some(row) = centres.get(start..start + cdims[0]) {
                                Segments::of_row(row, (i0, i1), dims, out);
                            }
                        }
                    });
                computed.insert(s)
            }
        };
        let empty = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        let Blocks { bounds, layers, .. } = &mut self.blocks;
        bounds
            .par_chunks_mut(cx * cy)
            .zip(layers.par_iter_mut())
            .enumerate()
            .skip(k0)
            .take(k1 - k0)
            .for_each(|(k, (layer, union))| {
                for j in j0..j1 {
                    for i in i0..i1 {
                        let vbox = Blocks::voxels([i, j, k], dims);
                        let (mut lo, mut hi) = empty;
                        for z in vbox.lo[2]..vbox.lo[2] + vbox.dims[2] + 2 {
                            for y in vbox.lo[1]..vbox.lo[1] + vbox.dims[1] + 2 {
                                if let Some((l, h)) = segments.get(y, z, i) {
                                    lo = vmin(lo, l);
                                    hi = vmax(hi, h);
                                }
                            }
                        }
                        layer[j * cx + i] = (lo, hi);
                    }
                }
                *union = layer
                    .iter()
                    .fold(empty, |(lo, hi), &(l, h)| (vmin(lo, l), vmax(hi, h)));
            });
    }

    /// Set the status of every source voxel of `r` to [`OUTSIDE`] when `sane` (every centre
    /// image the voxels read is finite and moderate, so every proxy box exists;
    /// [`recompute`](Self::recompute) then marks the mapped ones), or else classify each
    /// voxel from its proxy box. Runs over z-planes in parallel.
    fn reset_statuses(&self, r: &Region, sane: bool) {
        let dims = self.source.dims;
        let [nx, ny, _] = dims;
        let src = Voxels {
            values: &self.values,
            vdims: dims,
            centres: &self.centres,
            cdims: [nx + 2, ny + 2],
        };
        let out = self.output.dims;
        let c0 = [0, 1, 2].map(|a| r.lo[a] + 1);
        (0..r.dims[2]).into_par_iter().for_each(|dk| {
            for dj in 0..r.dims[1] {
                let s = r.lo[0] + nx * (r.lo[1] + dj + ny * (r.lo[2] + dk));
                let Some(slots) = self.status.get(s..s + r.dims[0]) else {
                    continue;
                };
                if sane {
                    for slot in slots {
                        slot.store(OUTSIDE, Relaxed);
                    }
                    continue;
                }
                let Some(row) = row(&src, r, c0, dj, dk) else {
                    continue;
                };
                for (slot, (_, proxy)) in slots.iter().zip(row.boxes()) {
                    let status = match proxy {
                        Some((lo, hi)) if reaches_grid(lo, hi, out) => MAPPED,
                        Some(_) => OUTSIDE,
                        None => NON_FINITE,
                    };
                    slot.store(status, Relaxed);
                }
            }
        });
    }

    /// Counts of the statuses of the source voxels in `r`.
    fn count(&self, r: &Region) -> PushForwardStats {
        let [nx, ny, _] = self.source.dims;
        (r.lo[2]..r.lo[2] + r.dims[2])
            .into_par_iter()
            .map(|k| {
                // Two running sums instead of a table indexed by the status: the table's
                // increments form a store-to-load chain through one counter (about five
                // cycles a voxel); sums of comparisons carry no such chain.
                let (mut all, mut mapped, mut non_finite) = (0usize, 0usize, 0usize);
                for j in r.lo[1]..r.lo[1] + r.dims[1] {
                    let s = r.lo[0] + nx * (j + ny * k);
                    let row = self.status.get(s..s + r.dims[0]).unwrap_or(&[]);
                    all += row.len();
                    for st in row {
                        let st = st.load(Relaxed);
                        mapped += usize::from(st == MAPPED);
                        non_finite += usize::from(st >= NON_FINITE);
                    }
                }
                PushForwardStats {
                    mapped,
                    outside: all - mapped - non_finite,
                    non_finite,
                }
            })
            .reduce(PushForwardStats::default, |mut a, b| {
                a.add(&b);
                a
            })
    }

    /// Recompute the output voxels of `region` from scratch: their tallies are summed anew
    /// from the boxes of every source voxel (of every block whose bounds reach the region)
    /// and renormalised with True's rule. Source voxels of `redo` whose boxes reach the
    /// output grid are marked [`MAPPED`]; `region` must hold every output voxel their boxes
    /// overlap.
    ///
    /// The region is cut into slabs of whole output planes, recomputed in parallel. Within
    /// a slab, blocks are visited in index order and voxels in index order, so every output
    /// voxel sums its contributions in one fixed order — the same for any region holding
    /// it and any number of threads.
    ///
    /// The scratch tallies hold a cell per output voxel, so any region fits.
    ///
    /// Each slab advances `progress` by its planes; a slab that starts once `progress` is
    /// cancelled is skipped (its tallies stay zero), so a cancelled recomputation leaves the
    /// region incomplete: only [`IncrementalPushForward::new_with`] passes a cancellable
    /// progress, and it drops the engine.
    fn recompute(&mut self, region: &Region, redo: &Region, progress: &dyn volmorph_io::Progress) {
        let len = region.len();
        if region.is_empty() || self.scratch.len() < len {
            return;
        }
        let dims = self.source.dims;
        let out = self.output.dims;
        let [ox, oy, _] = out;
        let plane = ox * oy;
        let (rx, ry) = (region.dims[0], region.dims[1]);
        let rplane = rx * ry;
        let nz = region.dims[2];
        let count = (2 * rayon::current_num_threads())
            .min(nz / MIN_SLAB_PLANES)
            .max(1);
        // Each slab: its region, its tallies and its planes of the volume.
        let mut work = Vec::with_capacity(count);
        let data = self.volume.data_mut();
        let mut planes = data
            .get_mut(region.lo[2] * plane..(region.lo[2] + nz) * plane)
            .unwrap_or(&mut []);
        let mut tallies = &mut self.scratch[..len];
        for s in 0..count {
            let (a, b) = (s * nz / count, (s + 1) * nz / count);
            let (mine, rest) = std::mem::take(&mut planes).split_at_mut((b - a) * plane);
            planes = rest;
            let (buf, rest) = std::mem::take(&mut tallies).split_at_mut((b - a) * rplane);
            tallies = rest;
            let slab = Region {
                lo: [region.lo[0], region.lo[1], region.lo[2] + a],
                dims: [rx, ry, b - a],
            };
            work.push((slab, buf, mine));
        }
        let src = Voxels {
            values: &self.values,
            vdims: dims,
            centres: &self.centres,
            cdims: [dims[0] + 2, dims[1] + 2],
        };
        let [cx, cy, _] = self.blocks.counts;
        let blocks = &self.blocks;
        let status = &self.status;
        let bg = self.background;
        let z0 = region.lo[2];
        work.into_par_iter().for_each(|(slab, buf, vol)| {
            if progress.is_cancelled() {
                return;
            }
            // The scratch is all zeros between recomputations (cleared as it is read).
            let corner = |d: [usize; 3]| {
                DVec3::new(
                    (slab.lo[0] + d[0]) as f64,
                    (slab.lo[1] + d[1]) as f64,
                    (slab.lo[2] + d[2]) as f64,
                ) - 0.5
            };
            let (rlo, rhi) = (corner([0; 3]), corner(slab.dims));
            // Boxes overlapping the slab's cells with positive length (empty bounds fail
            // every test).
            let reaches = |&(lo, hi): &(DVec3, DVec3)| hi.cmpgt(rlo).all() && lo.cmplt(rhi).all();
            let layers = blocks.layers.iter().enumerate().filter(|(_, b)| reaches(b));
            let mut boxes = RowBoxes::default();
            // Runs of consecutive reaching blocks along x, visited as one box of voxels
            // (the same voxels in the same order, with longer rows).
            let runs = layers.flat_map(|(k, _)| {
                let first = k * cx * cy;
                let layer = blocks.bounds.get(first..first + cx * cy).unwrap_or(&[]);
                layer.chunks(cx).enumerate().flat_map(move |(j, row)| {
                    let mut i = 0;
                    std::iter::from_fn(move || {
                        while i < row.len() && !reaches(&row[i]) {
                            i += 1;
                        }
                        let start = i;
                        while i < row.len() && reaches(&row[i]) {
                            i += 1;
                        }
                        (start < i).then_some(([start, j, k], i - start))
                    })
                })
            });
            for (index, count) in runs {
                let mut vbox = Blocks::voxels(index, dims);
                vbox.dims[0] = (vbox.lo[0] + count * BLOCK[0]).min(dims[0]) - vbox.lo[0];
                tally_run(
                    &src,
                    &vbox,
                    out,
                    &slab,
                    buf,
                    status,
                    redo,
                    slab.lo[2] == z0,
                    &mut boxes,
                );
            }
            for (tp, vp) in buf
                .chunks_exact_mut(rplane)
                .zip(vol.chunks_exact_mut(plane))
            {
                for (j, trow) in tp.chunks_exact_mut(rx).enumerate() {
                    let s = (slab.lo[1] + j) * ox + slab.lo[0];
                    for (v, t) in vp[s..s + rx].iter_mut().zip(trow) {
                        *v = f32::from_f64(normalise(t[0], t[1], bg));
                        *t = [0.0; 2];
                    }
                }
            }
            progress.advance(slab.dims[2] as u64);
        });
    }
}

/// Tally the boxes of the source voxels of `vbox` into the slab `slab`'s tallies `buf`, and
/// mark [`MAPPED`] every voxel of `redo` whose box lands (in the slab holding the box's
/// first output plane; `first_slab` for the slab that also takes boxes reaching below the
/// grid). Voxels in index order, as [`IncrementalPushForward::recompute`] requires.
///
/// Row by row through [`RowBoxes`] (AVX2 kernels where the CPU has them, chosen at run
/// time; the same bits as the per-voxel box filter).
#[allow(clippy::too_many_arguments)]
fn tally_run<'a>(
    src: &Voxels<'a, f32>,
    vbox: &Region,
    out: [usize; 3],
    slab: &Region,
    buf: &mut [[f64; 2]],
    status: &[AtomicU8],
    redo: &Region,
    first_slab: bool,
    boxes: &mut RowBoxes,
) {
    let redo_end = [0, 1, 2].map(|a| redo.lo[a] + redo.dims[a]);
    let in_redo = |a: usize, i: usize| i >= redo.lo[a] && i < redo_end[a];
    let c0 = [0, 1, 2].map(|a| vbox.lo[a] + 1);
    for dk in 0..vbox.dims[2] {
        for dj in 0..vbox.dims[1] {
            let Some(row) = row(src, vbox, c0, dj, dk) else {
                continue;
            };
            // The boxes and cells of the whole row in vector lanes.
            let target = Target {
                sign: 1.0,
                out,
                region: slab,
            };
            boxes.tally(&row, target, buf);
            if !(in_redo(1, vbox.lo[1] + dj) && in_redo(2, vbox.lo[2] + dk)) {
                continue;
            }
            for (n, &o) in boxes.outcomes().iter().enumerate() {
                // The slab holding the box's first output plane (the first slab for boxes
                // reaching below the grid) marks a redone voxel.
                if o == MAPPED
                    && in_redo(0, vbox.lo[0] + n)
                    && (first_slab || boxes.lo_z(n) + 0.5 >= slab.lo[2] as f64)
                    && let Some(slot) = status.get(row.first + n)
                {
                    slot.store(MAPPED, Relaxed);
                }
            }
        }
    }
}

/// Reserve room for `len` elements in `v` (total capacity), or an allocation error.
fn reserve<V>(v: &mut Vec<V>, len: usize, what: &'static str) -> Result<(), WarpError> {
    let extra = len.saturating_sub(v.len());
    v.try_reserve(extra).map_err(|_| WarpError::Allocation {
        what,
        bytes: len.saturating_mul(std::mem::size_of::<V>()),
    })
}

/// Magnitude below which centre images are "sane": finite, and small enough that the sums
/// of seven of them forming a proxy box cannot overflow, so every box exists.
const SANE: f64 = 1e300;

/// `true` if every coordinate of `p` is finite with magnitude below [`SANE`].
#[inline(always)]
fn sane(p: DVec3) -> bool {
    p.abs().max_element() < SANE
}

/// Bounds of the finite points of a set (`(+∞, −∞)` if none).
#[derive(Debug, Clone, Copy)]
struct Hull {
    lo: DVec3,
    hi: DVec3,
}

impl Hull {
    const EMPTY: Self = Self {
        lo: DVec3::INFINITY,
        hi: DVec3::NEG_INFINITY,
    };

    #[inline(always)]
    fn add(&mut self, p: DVec3) {
        if p.is_finite() {
            self.lo = vmin(self.lo, p);
            self.hi = vmax(self.hi, p);
        }
    }

    fn union(self, o: Self) -> Self {
        Self {
            lo: vmin(self.lo, o.lo),
            hi: vmax(self.hi, o.hi),
        }
    }

    /// [`Hull::add`] of every point of `ps`; returns the largest coordinate magnitude of
    /// `ps` when every coordinate is finite (`None` otherwise).
    #[inline(always)]
    fn add_all(&mut self, ps: &[DVec3]) -> Option<f64> {
        match Span::of(ps) {
            Some(s) => {
                self.lo = vmin(self.lo, s.lo);
                self.hi = vmax(self.hi, s.hi);
                Some(s.max_abs)
            }
            None => {
                for p in ps {
                    self.add(*p);
                }
                None
            }
        }
    }
}

/// Bounds and largest magnitude of a run of points whose coordinates are all finite,
/// computed over the flat coordinates in vector lanes (twelve accumulators: four points of
/// three coordinates). Bounds are exact (a minimum or maximum rounds nothing); only the sign
/// of a zero bound may differ from a point-by-point fold, which no comparison the engine
/// makes can see.
struct Span {
    lo: DVec3,
    hi: DVec3,
    max_abs: f64,
}

impl Span {
    /// The span of `ps`, or `None` if a coordinate is NaN or infinite (or `ps` is empty).
    #[inline(always)]
    fn of(ps: &[DVec3]) -> Option<Self> {
        const L: usize = 12;
        let f: &[f64] = bytemuck::cast_slice(ps);
        let mut lo = [f64::INFINITY; L];
        let mut hi = [f64::NEG_INFINITY; L];
        let mut big = [0.0_f64; L];
        // `x · 0` is ±0 for a finite `x` and NaN otherwise; the sum is ±0 iff all are finite.
        let mut bad = [0.0_f64; L];
        let mut step = |k: usize, x: f64, lo: &mut [f64; L], hi: &mut [f64; L]| {
            lo[k] = if x < lo[k] { x } else { lo[k] };
            hi[k] = if x > hi[k] { x } else { hi[k] };
            let a = x.abs();
            big[k] = if a > big[k] { a } else { big[k] };
            bad[k] += x * 0.0;
        };
        let mut chunks = f.chunks_exact(L);
        for c in &mut chunks {
            for (k, &x) in c.iter().enumerate() {
                step(k, x, &mut lo, &mut hi);
            }
        }
        for (k, &x) in chunks.remainder().iter().enumerate() {
            step(k, x, &mut lo, &mut hi);
        }
        if ps.is_empty() || bad.iter().sum::<f64>() != 0.0 {
            return None;
        }
        let mut s = Self {
            lo: DVec3::INFINITY,
            hi: DVec3::NEG_INFINITY,
            max_abs: 0.0,
        };
        for k in 0..L {
            let a = k % 3;
            s.lo[a] = if lo[k] < s.lo[a] { lo[k] } else { s.lo[a] };
            s.hi[a] = if hi[k] > s.hi[a] { hi[k] } else { s.hi[a] };
            s.max_abs = if big[k] > s.max_abs {
                big[k]
            } else {
                s.max_abs
            };
        }
        Some(s)
    }
}

/// The hulls of the centre images of a neighbourhood before and after an update, and the
/// number of images that are not [`sane`] among the replaced and the new ones.
struct Hulls {
    old: Hull,
    new: Hull,
    replaced_insane: usize,
    new_insane: usize,
}

/// Over the margin-coordinate box `hood` of `centres` (rows of `cdims[0]`, planes of
/// `cdims[0]·cdims[1]`), which holds `fresh_box`: take the hull of the stored images, then
/// store `fresh` (physical images over `fresh_box`) converted to output indices by
/// `to_index`, taking their hull; and fill `segments` (whose rows hold the hood's) from the
/// new images — one pass, parallel over planes. `all_sane` tells that every stored image
/// is [`sane`] (then none of the replaced ones is counted).
#[allow(clippy::too_many_arguments)]
fn swap_in(
    centres: &mut [DVec3],
    dims: [usize; 3],
    hood: &Region,
    fresh: &[DVec3],
    fresh_box: &Region,
    to_index: &ToIndex,
    segments: &mut Segments,
    all_sane: bool,
) -> Hulls {
    let [cx, cy] = [dims[0] + 2, dims[1] + 2];
    let [fx, fy, _] = fresh_box.dims;
    let empty = || Hulls {
        old: Hull::EMPTY,
        new: Hull::EMPTY,
        replaced_insane: 0,
        new_insane: 0,
    };
    let rows = segments.rows;
    let columns = segments.columns;
    let per_plane = rows.dims[1] * segments.columns();
    centres
        .par_chunks_mut(cx * cy)
        .skip(rows.lo[2])
        .zip(segments.bounds.par_chunks_mut(per_plane))
        .enumerate()
        .map(|(dz, (plane, out))| {
            let k = rows.lo[2] + dz;
            let mut h = empty();
            let in_hood = k >= hood.lo[2] && k < hood.lo[2] + hood.dims[2];
            let new = k
                .checked_sub(fresh_box.lo[2])
                .filter(|&dz| dz < fresh_box.dims[2])
                .and_then(|dz| fresh.get(dz * fx * fy..(dz + 1) * fx * fy));
            for (dy, out) in out.chunks_exact_mut(columns.1 - columns.0).enumerate() {
                let j = rows.lo[1] + dy;
                let Some(full) = plane.get_mut(j * cx..(j + 1) * cx) else {
                    continue;
                };
                let in_row = in_hood && j >= hood.lo[1] && j < hood.lo[1] + hood.dims[1];
                let dy = j.wrapping_sub(fresh_box.lo[1]);
                let src = new
                    .filter(|_| dy < fy)
                    .and_then(|n| n.get(dy * fx..(dy + 1) * fx));
                let row = RowSwap {
                    hood: in_row.then_some((hood.lo[0], hood.lo[0] + hood.dims[0])),
                    src,
                    at: fresh_box.lo[0],
                    columns,
                    dims,
                };
                swap_row(full, &row, to_index, all_sane, &mut h, out);
            }
            h
        })
        .reduce(empty, |a, b| Hulls {
            old: a.old.union(b.old),
            new: a.new.union(b.new),
            replaced_insane: a.replaced_insane + b.replaced_insane,
            new_insane: a.new_insane + b.new_insane,
        })
}

/// One row of [`swap_in`]: the hood's part of the row, and the fresh images that go into it.
struct RowSwap<'a> {
    /// The hood's columns `[a, b)` of the row, if the row is in the hood.
    hood: Option<(usize, usize)>,
    /// The fresh physical images of the row, if it has any.
    src: Option<&'a [DVec3]>,
    /// The column of the first fresh image.
    at: usize,
    /// The block columns of the row's segments (see [`Segments::of_row`]).
    columns: (usize, usize),
    /// The source grid's dims.
    dims: [usize; 3],
}

/// [`swap_in`] on one row `full` of the centre images: add the stored images of the hood's
/// part to `h.old`, store the fresh ones converted by `to_index` and add them to `h.new`,
/// counting insane images as [`swap_in`] describes; then fill the row's block segments
/// `segments` (see [`Segments::of_row`]).
///
/// Compiled for the baseline target and for x86-64 with AVX2, chosen at run time: the
/// twelve accumulators of each of [`Span`]'s four running bounds fit AVX2's sixteen
/// four-lane registers, while baseline SSE2's two-lane registers spill them. Both give the
/// same bits (minima, maxima and the same IEEE products and sums; Rust never contracts a
/// multiply and an add).
#[multiversion(targets("x86_64+avx2+fma"))]
fn swap_row<'a>(
    full: &mut [DVec3],
    job: &RowSwap<'a>,
    to_index: &ToIndex,
    all_sane: bool,
    h: &mut Hulls,
    segments: &mut [(DVec3, DVec3)],
) {
    swap_hood(full, job, to_index, all_sane, h);
    Segments::of_row(full, job.columns, job.dims, segments);
}

/// The hood part of [`swap_row`] (inlined into each of its versions).
#[inline(always)]
fn swap_hood(
    full: &mut [DVec3],
    job: &RowSwap<'_>,
    to_index: &ToIndex,
    all_sane: bool,
    h: &mut Hulls,
) {
    let Some((a, b)) = job.hood else {
        return;
    };
    let Some(row) = full.get_mut(a..b) else {
        return;
    };
    h.old.add_all(row);
    let Some(src) = job.src else {
        return;
    };
    let dst = job
        .at
        .checked_sub(a)
        .and_then(|x| row.get_mut(x..x + src.len()));
    let Some(dst) = dst else {
        return;
    };
    // With no insane image stored, none is replaced.
    if !all_sane {
        h.replaced_insane += dst.iter().filter(|d| !sane(**d)).count();
    }
    for (d, p) in dst.iter_mut().zip(src) {
        *d = to_index.apply(*p);
    }
    if h.new.add_all(dst).is_none_or(|m| m >= SANE) {
        h.new_insane += dst.iter().filter(|d| !sane(**d)).count();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_testkit::Rng;

    /// The lane-wise span of a run of points is the point-by-point hull (every length, to
    /// cover the remainder after the 4-point chunks), its largest magnitude is the largest
    /// coordinate magnitude, and a NaN or infinite coordinate anywhere gives `None`, so
    /// [`Hull::add_all`] falls back to skipping the non-finite points one by one.
    #[test]
    fn span_is_the_pointwise_hull_and_refuses_non_finite_points() {
        let mut rng = Rng::new(7);
        for len in 0..40 {
            let ps: Vec<DVec3> = (0..len)
                .map(|_| {
                    DVec3::new(
                        rng.range(-9.0, 9.0),
                        rng.range(-1e3, 1e3),
                        rng.range(0.0, 1.0),
                    )
                })
                .collect();
            let mut want = Hull::EMPTY;
            for p in &ps {
                want.add(*p);
            }
            let max_abs = ps.iter().map(|p| p.abs().max_element()).fold(0.0, f64::max);
            match Span::of(&ps) {
                Some(s) => {
                    assert_eq!(
                        (s.lo, s.hi, s.max_abs),
                        (want.lo, want.hi, max_abs),
                        "{len} points"
                    );
                }
                None => assert_eq!(len, 0),
            }
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                if len == 0 {
                    continue;
                }
                let mut q = ps.clone();
                q[len / 2][len % 3] = bad;
                assert!(Span::of(&q).is_none(), "{bad} among {len} points");
                let mut h = Hull::EMPTY;
                assert_eq!(h.add_all(&q), None);
                let mut w = Hull::EMPTY;
                for p in &q {
                    w.add(*p);
                }
                assert_eq!((h.lo, h.hi), (w.lo, w.hi));
            }
        }
    }
}
