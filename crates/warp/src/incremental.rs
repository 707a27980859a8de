//! Incremental antialiased push-forward through an editable B-spline lattice (True 1992 §5.3
//! "the main loop", §5.4).
//!
//! **Direction.** As in [`crate::pushforward`]: every *source* voxel is pushed forward to
//! where the lattice sends it, and its box-filtered value is spread over the *output* voxels
//! its proxy box overlaps.
//!
//! [`IncrementalPushForward`] keeps everything the push-forward of True §5.4 computes —
//! the images of the voxel centres (True's "deformation mapping array", with the one-voxel
//! margin that averaged face centres need) and the per-output-voxel tallies `[V, W]` — so
//! that moving control points only redoes what they influence, as in True's main loop:
//!
//! 1. **Influenced region.** Control point `i` of an axis of degree `p` blends the knot spans
//!    `i ..= i + p` (span index `s` = `[u_s, u_{s+1})`, blended by control points
//!    `s − p ..= s`; in True's region numbering, regions `i − 3 ..= i`). The bounding box of
//!    the non-empty spans of all moved points (read from the knot vector of each axis, so
//!    any degree and any knots) is the parameter box where the map can change; outside it,
//!    and outside the lattice box (where the map is the identity), it cannot. The box is
//!    turned into the box of voxel centres (margin included) whose parameters lie in it,
//!    widened by [`PARAMETER_MARGIN`] voxels against rounding.
//! 2. **Redone voxels.** A source voxel's proxy box depends on its own centre image and its
//!    six neighbours' (face centres are averages), so the voxels to redo are the influenced
//!    centres dilated by one voxel, clipped to the source.
//! 3. **Erase, remap, add.** For the redone voxels the old boxes are subtracted from the
//!    tallies (exactly the values once added, with the sign flipped), the influenced centre
//!    images are re-evaluated with the new lattice through [`SpaceMap::apply_grid`] on the
//!    sub-grid they form (the evaluation a full push-forward uses), and the new boxes are
//!    added: all slabs erase, then the centre images are replaced, then all slabs add. Work
//!    runs over z-slabs of the redone box (a partition fixed by the box), tallying straight
//!    into the tallies: slabs whose output z-ranges are disjoint run in parallel, groups of
//!    them one after the other, so every output voxel receives its contributions in an
//!    order fixed by the partition and results do not depend on the number of threads.
//!
//! The moved control points are handled together: the redone region is the bounding box
//! of their influence, which suits the clusters that dragging a point moves (the control
//! points blending one region). Callers moving far-apart points at once may update per
//! cluster instead (each update is exact).
//! 4. **Renormalise** the output voxels in the union of the slabs' output boxes with True's
//!    rule (see [`crate::pushforward`]).
//!
//! Tallies are kept in `f64`: erase-then-add cancels to rounding (about 1e-16 relative per
//! update), so no drift builds up over many edits. After any sequence of updates the volume
//! equals [`push_forward_antialiased_f32`](crate::pushforward::push_forward_antialiased_f32)
//! with the current lattice and the same options, up to the `f32` accumulation of the
//! latter (about 1e-6 relative).
//!
//! # Memory
//!
//! The engine holds, for a source of `n = nx·ny·nz` voxels and an output of `m` voxels:
//! the source values (`4n` bytes, `f32`), the centre images (`24·(nx+2)(ny+2)(nz+2)` bytes,
//! `f64` points in output index space), the tallies (`16m` bytes) and the current volume
//! (`4m` bytes) — about 105 MB for 128³ → 128³, 815 MB for 256³ → 256³. An update adds
//! only the re-evaluated centre images (`24` bytes each, kept between updates).
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
//! use volmorph_deform::BSplineLattice;
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
//! let report = engine.move_control_points(&[([2, 2, 2], DVec3::new(1.5, -0.5, 0.25))])?;
//! assert!(report.redone > 0 && report.redone < v.len());
//! let full = push_forward_antialiased_f32(&v, engine.lattice(), &g, &opts)?;
//! for (a, b) in engine.volume().data().iter().zip(full.volume.data()) {
//!     assert!((a - b).abs() <= 1e-5 * 10.0);
//! }
//! assert_eq!(engine.stats(), full.stats);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use glam::DVec3;
use rayon::prelude::*;
use volmorph_deform::{BSplineLattice, SpaceMap};
use volmorph_volume::{Geometry, Volume, Voxel};

use crate::WarpError;
use crate::pushforward::{
    AntialiasOptions, FaceCentres, PushForwardStats, ToIndex, normalise, offset_grid,
    output_geometry, try_filled,
};
use crate::tally::{Region, Voxels, tally_averaged, vmax, vmin};

/// Widening, in source voxels, of the box of voxel centres whose parameters lie in the
/// influenced parameter box. The map evaluation and this test compute a centre's parameter
/// along different roundings (≈1e-13 relative); a voxel redone needlessly costs a little
/// time, a voxel missed would be wrong, so the margin is generous.
pub const PARAMETER_MARGIN: f64 = 1e-6;

/// Target number of redone source voxels per slab of an update (slabs are whole z-slices of
/// the redone box, at least [`MIN_SLAB_SLICES`] thick, their count a multiple of
/// [`SLAB_GROUPING`]). Depends only on the box, so the slab partition — and with it the
/// order of floating-point sums — never depends on the thread count.
const SLAB_VOXELS: usize = 1 << 16;

/// The slab count is rounded up to a multiple of this: neighbouring slabs usually fall
/// into two alternating groups, and each group of a multiple of two slabs shares evenly
/// over two threads.
const SLAB_GROUPING: usize = 4;

/// Thinnest slab, in source z-slices: boxes spill about a plane into the output planes of
/// the neighbouring slabs, so thinner slabs would overlap several neighbours and need more
/// groups run one after the other.
const MIN_SLAB_SLICES: usize = 4;

/// A box of voxel indices `start[a] .. end[a]` per axis (half-open; empty if any
/// `start[a] >= end[a]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IndexBox {
    /// First index per axis (x, y, z).
    pub start: [usize; 3],
    /// One past the last index per axis.
    pub end: [usize; 3],
}

impl IndexBox {
    /// Number of voxels in the box.
    #[must_use]
    pub fn len(&self) -> usize {
        (0..3)
            .map(|a| self.end[a].saturating_sub(self.start[a]))
            .product()
    }

    /// `true` if the box holds no voxel.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// `true` if voxel `[i, j, k]` lies in the box.
    #[must_use]
    pub fn contains(&self, index: [usize; 3]) -> bool {
        (0..3).all(|a| index[a] >= self.start[a] && index[a] < self.end[a])
    }

    fn of(r: &Region) -> Self {
        if r.is_empty() {
            return Self::default();
        }
        Self {
            start: r.lo,
            end: [0, 1, 2].map(|a| r.lo[a] + r.dims[a]),
        }
    }
}

/// What an update of an [`IncrementalPushForward`] did. Counts only, no timings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct UpdateReport {
    /// Control points whose position changed.
    pub moved: usize,
    /// Voxel centres whose images were re-evaluated (including the one-voxel margin around
    /// the source that averaged face centres use).
    pub remapped: usize,
    /// Source voxels whose boxes were erased and tallied again (`source_box.len()`).
    pub redone: usize,
    /// The redone source voxels (source indices; empty if the edit reaches no voxel).
    pub source_box: IndexBox,
    /// The output voxels whose tallies may have changed and were renormalised (output
    /// indices; empty if none).
    pub output_box: IndexBox,
    /// The redone voxels under the old lattice.
    pub before: PushForwardStats,
    /// The redone voxels under the new lattice. The engine's [`stats`] change by
    /// `after − before`.
    ///
    /// [`stats`]: IncrementalPushForward::stats
    pub after: PushForwardStats,
}

/// New centre images of an update: the points (x fastest) over a margin-coordinate box and
/// the bounds of the finite points of each of its z-planes.
struct Fresh<'a> {
    points: &'a [DVec3],
    region: &'a Region,
    plane_bounds: &'a [(DVec3, DVec3)],
}

/// A slab of an update: its source voxels and the output region their old and new boxes
/// can reach.
#[derive(Debug, Clone, Copy)]
struct SlabPlan {
    voxels: Region,
    output: Region,
}

/// The antialiased push-forward of a source volume through a [`BSplineLattice`], kept up to
/// date under control-point moves by redoing only the influenced region (see the
/// [module docs](self) for the algorithm, its exactness and its memory use).
///
/// The result always equals
/// [`push_forward_antialiased_f32`](crate::pushforward::push_forward_antialiased_f32) of the
/// source with [`lattice`](Self::lattice) on the output geometry with the engine's options
/// (to the `f32` rounding of the latter), and [`stats`](Self::stats) equals its
/// [`PushForwardStats`].
#[derive(Debug)]
pub struct IncrementalPushForward {
    source: Geometry,
    values: Vec<f32>,
    lattice: BSplineLattice,
    output: Geometry,
    to_index: ToIndex,
    background: f64,
    /// Images of the voxel centres of the source grid widened by one voxel on every side
    /// (source index `v` is entry `v + 1`), in output continuous-index space.
    centres: Vec<DVec3>,
    tallies: Vec<[f64; 2]>,
    volume: Volume<f32>,
    stats: PushForwardStats,
    fresh: Vec<DVec3>,
}

impl IncrementalPushForward {
    /// Push `source` (values converted to `f32`) forward through `lattice` onto `output` with
    /// True's box-filter antialiasing, keeping the state for incremental updates.
    ///
    /// `options.face_centres` must be [`FaceCentres::AveragedCentres`] (True's method, the
    /// default): the incremental scheme rests on stored voxel-centre images, as True's
    /// footnote 4 explains; `options.background` is honoured as in the full push-forward.
    ///
    /// # Errors
    /// [`WarpError::Geometry`] for an invalid `output`, [`WarpError::Background`] for a
    /// non-finite background, [`WarpError::Unsupported`] for
    /// [`FaceCentres::Mapped`], [`WarpError::MapOnGrid`] if the lattice fails on the
    /// voxel-centre grid, [`WarpError::Allocation`] if a buffer cannot be allocated.
    pub fn new<T: Voxel>(
        source: &Volume<T>,
        lattice: BSplineLattice,
        output: &Geometry,
        options: &AntialiasOptions,
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
        let grid = offset_grid(&g, DVec3::splat(-1.0), cdims);
        lattice
            .apply_grid(&grid, &mut centres)
            .map_err(|source| WarpError::MapOnGrid {
                grid: "voxel-centre",
                source,
            })?;
        centres
            .par_iter_mut()
            .with_min_len(4096)
            .for_each(|p| *p = to_index.apply(*p));
        let tallies = try_filled(output.len(), [0.0f64; 2], "tallies")?;
        let data = try_filled(output.len(), 0.0f32, "output")?;
        let volume = Volume::new(*output, data).map_err(output_geometry)?;
        let mut engine = Self {
            source: g,
            values,
            lattice,
            output: *output,
            to_index,
            background: options.background,
            centres,
            tallies,
            volume,
            stats: PushForwardStats::default(),
            fresh: Vec::new(),
        };
        let all = Region {
            lo: [0; 3],
            dims: g.dims,
        };
        let (_, after, _) = engine.retally(&all, None);
        engine.stats = after;
        let everything = Region {
            lo: [0; 3],
            dims: output.dims,
        };
        engine.renormalise(&everything);
        Ok(engine)
    }

    /// The current push-forward on the output geometry. Kept up to date by every update
    /// (only the output voxels an update can reach are recomputed).
    #[must_use]
    pub fn volume(&self) -> &Volume<f32> {
        &self.volume
    }

    /// The lattice the current volume is the push-forward through.
    #[must_use]
    pub fn lattice(&self) -> &BSplineLattice {
        &self.lattice
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

    /// What happens to the source voxels under the current lattice (equal to the
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

    /// Displace control points: `(index, delta)` moves control point `index` (lattice
    /// indices `[i, j, k]`) by `delta` (physical units), in order (an index may repeat), then
    /// updates the push-forward incrementally (see the [module docs](self)).
    ///
    /// # Errors
    /// [`WarpError::ControlPoint`] if an index is out of range or a new position is NaN or
    /// infinite; [`WarpError::MapOnGrid`] if the new lattice fails on the voxel-centre grid;
    /// [`WarpError::Allocation`] if the re-evaluated centre images cannot be stored. On error
    /// the engine is unchanged.
    pub fn move_control_points(
        &mut self,
        moves: &[([usize; 3], DVec3)],
    ) -> Result<UpdateReport, WarpError> {
        let mut lattice = self.lattice.clone();
        for &(index, delta) in moves {
            lattice
                .move_control_point(index, delta)
                .map_err(WarpError::ControlPoint)?;
        }
        self.set_lattice(lattice)
    }

    /// Replace the lattice by `lattice`, which must have the same knots and frame: the
    /// control points that differ are found and the push-forward is updated incrementally.
    ///
    /// # Errors
    /// [`WarpError::LatticeMismatch`] if the knots or the frame differ;
    /// [`WarpError::MapOnGrid`] and [`WarpError::Allocation`] as
    /// [`move_control_points`](Self::move_control_points). On error the engine is unchanged.
    pub fn set_lattice(&mut self, lattice: BSplineLattice) -> Result<UpdateReport, WarpError> {
        if lattice.knots() != self.lattice.knots() || lattice.frame() != self.lattice.frame() {
            return Err(WarpError::LatticeMismatch);
        }
        let [cx, cy, _] = lattice.counts();
        let moved: Vec<[usize; 3]> = lattice
            .spline()
            .homogeneous_coefficients()
            .chunks_exact(3)
            .zip(
                self.lattice
                    .spline()
                    .homogeneous_coefficients()
                    .chunks_exact(3),
            )
            .enumerate()
            .filter(|(_, (a, b))| a != b)
            .map(|(n, _)| [n % cx, (n / cx) % cy, n / (cx * cy)])
            .collect();
        self.update(lattice, &moved)
    }

    /// Update from the current lattice to `lattice`, whose control points `moved` differ.
    fn update(
        &mut self,
        lattice: BSplineLattice,
        moved: &[[usize; 3]],
    ) -> Result<UpdateReport, WarpError> {
        let mut report = UpdateReport {
            moved: moved.len(),
            ..UpdateReport::default()
        };
        let influenced = self.influenced_centres(&lattice, moved);
        if influenced.is_empty() {
            self.lattice = lattice;
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
        // New centre images of the influenced box (margin coordinates m = source index + 1).
        let sub = offset_grid(
            &self.source,
            DVec3::new(
                influenced.lo[0] as f64 - 1.0,
                influenced.lo[1] as f64 - 1.0,
                influenced.lo[2] as f64 - 1.0,
            ),
            influenced.dims,
        );
        let len = influenced.len();
        reserve(&mut self.fresh, len, "voxel-centre images")?;
        self.fresh.resize(len, DVec3::ZERO);
        lattice
            .apply_grid(&sub, &mut self.fresh[..len])
            .map_err(|source| WarpError::MapOnGrid {
                grid: "voxel-centre",
                source,
            })?;
        // Convert to output indices, with the bounds of each plane's finite images.
        let to_index = self.to_index;
        let plane = influenced.dims[0] * influenced.dims[1];
        let plane_bounds: Vec<(DVec3, DVec3)> = self.fresh[..len]
            .par_chunks_mut(plane)
            .map(|pts| {
                let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
                for p in pts {
                    *p = to_index.apply(*p);
                    if p.is_finite() {
                        lo = vmin(lo, *p);
                        hi = vmax(hi, *p);
                    }
                }
                (lo, hi)
            })
            .collect();
        let points = std::mem::take(&mut self.fresh);
        let fresh = Fresh {
            points: &points[..len],
            region: &influenced,
            plane_bounds: &plane_bounds,
        };
        let (before, after, out) = self.retally(&redo, Some(&fresh));
        self.fresh = points;
        self.renormalise(&out);
        self.lattice = lattice;
        self.stats = PushForwardStats {
            mapped: self.stats.mapped.saturating_sub(before.mapped) + after.mapped,
            non_finite: self.stats.non_finite.saturating_sub(before.non_finite) + after.non_finite,
            outside: self.stats.outside.saturating_sub(before.outside) + after.outside,
        };
        report.remapped = len;
        report.redone = redo.len();
        report.source_box = IndexBox::of(&redo);
        report.output_box = IndexBox::of(&out);
        report.before = before;
        report.after = after;
        Ok(report)
    }

    /// The box, in margin coordinates (source index + 1, `0 ..= n + 1` per axis), of the
    /// voxel centres whose images can change when control points `moved` change.
    fn influenced_centres(&self, lattice: &BSplineLattice, moved: &[[usize; 3]]) -> Region {
        let knots = lattice.knots();
        let mut plo = [f64::INFINITY; 3];
        let mut phi = [f64::NEG_INFINITY; 3];
        for index in moved {
            for a in 0..3 {
                let p = knots[a].degree();
                for span in knots[a].spans() {
                    if span.index >= index[a] && span.index <= index[a] + p {
                        plo[a] = plo[a].min(span.start);
                        phi[a] = phi[a].max(span.end);
                    }
                }
            }
        }
        if (0..3).any(|a| plo[a].partial_cmp(&phi[a]).is_none_or(|o| o.is_gt())) {
            return Region::default();
        }
        // Source continuous indices of the parameter box's corners.
        let frame = lattice.frame();
        let mut lo = DVec3::INFINITY;
        let mut hi = DVec3::NEG_INFINITY;
        for c in 0..8 {
            let u = DVec3::new(
                if c & 1 == 0 { plo[0] } else { phi[0] },
                if c & 2 == 0 { plo[1] } else { phi[1] },
                if c & 4 == 0 { plo[2] } else { phi[2] },
            );
            let x = self.source.physical_to_index(frame.to_physical(u));
            lo = lo.min(x);
            hi = hi.max(x);
        }
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

    /// Subtract (if `fresh` is given) the old boxes of the source voxels in `redo`, store the
    /// new centre images `fresh`, and add the voxels' new boxes. Returns the stats of the
    /// redone voxels before and after and the output region the boxes can reach.
    ///
    /// Slabs tally straight into the tallies. They run in colour groups (see [`colours`]):
    /// within a group the slabs' output z-ranges are disjoint, so they run in parallel on
    /// disjoint planes; groups run one after the other. Every output voxel therefore receives
    /// its contributions in an order fixed by the slab partition alone, whatever the number
    /// of threads.
    fn retally(
        &mut self,
        redo: &Region,
        fresh: Option<&Fresh<'_>>,
    ) -> (PushForwardStats, PushForwardStats, Region) {
        let cdims = [self.source.dims[0] + 2, self.source.dims[1] + 2];
        if redo.is_empty() {
            if let Some(f) = fresh {
                store_centres(&mut self.centres, cdims, f.points, f.region);
            }
            return (
                PushForwardStats::default(),
                PushForwardStats::default(),
                Region::default(),
            );
        }
        let plans = self.plan_slabs(redo, fresh);
        let groups = colours(&plans);
        let touched = plans
            .iter()
            .fold(Region::default(), |acc, p| acc.union(&p.output));
        let before = match fresh {
            Some(f) => {
                let old = self.tally_groups(&plans, &groups, -1.0);
                store_centres(&mut self.centres, cdims, f.points, f.region);
                old
            }
            None => PushForwardStats::default(),
        };
        let after = self.tally_groups(&plans, &groups, 1.0);
        (before, after, touched)
    }

    /// Tally (with `sign`) the voxels of every slab plan from the stored centre images
    /// straight into the tallies, group by group.
    fn tally_groups(
        &mut self,
        plans: &[SlabPlan],
        groups: &[Vec<usize>],
        sign: f64,
    ) -> PushForwardStats {
        let src = Voxels {
            values: &self.values,
            vdims: self.source.dims,
            centres: &self.centres,
            cdims: [self.source.dims[0] + 2, self.source.dims[1] + 2],
        };
        let out = self.output.dims;
        let plane = out[0] * out[1];
        let mut stats = PushForwardStats::default();
        for group in groups {
            // Members are sorted by output z and their z-ranges are disjoint: hand each its
            // own planes of the tallies.
            let mut work: Vec<(&SlabPlan, Region, &mut [[f64; 2]])> =
                Vec::with_capacity(group.len());
            let mut rest: &mut [[f64; 2]] = &mut self.tallies;
            let mut taken = 0usize;
            for &g in group {
                let plan = &plans[g];
                let (z0, dz) = if plan.output.is_empty() {
                    (taken, 0)
                } else {
                    (plan.output.lo[2], plan.output.dims[2])
                };
                let (_, tail) = std::mem::take(&mut rest).split_at_mut((z0 - taken) * plane);
                let (mine, tail) = tail.split_at_mut(dz * plane);
                rest = tail;
                taken = z0 + dz;
                let region = Region {
                    lo: [0, 0, z0],
                    dims: [out[0], out[1], dz],
                };
                work.push((plan, region, mine));
            }
            let counts: Vec<PushForwardStats> = work
                .into_par_iter()
                .map(|(plan, region, planes)| {
                    let c0 = [0, 1, 2].map(|a| plan.voxels.lo[a] + 1);
                    tally_averaged(&src, &plan.voxels, c0, out, &region, planes, sign)
                })
                .collect();
            for c in &counts {
                stats.add(c);
            }
        }
        stats
    }

    /// Split `redo` into z-slabs and find, for each, the output region its old and new boxes
    /// can reach: the cells overlapped by the bounding box of the finite centre images its
    /// voxels read (face centres lie between centres).
    fn plan_slabs(&self, redo: &Region, fresh: Option<&Fresh<'_>>) -> Vec<SlabPlan> {
        // A multiple of SLAB_GROUPING slabs (each colour group then splits evenly over a few
        // threads), at least MIN_SLAB_SLICES thick, planes shared out evenly.
        let nz = redo.dims[2];
        let wanted = redo
            .len()
            .div_ceil(SLAB_VOXELS)
            .next_multiple_of(SLAB_GROUPING);
        let count = wanted.min(nz / MIN_SLAB_SLICES).max(1);
        let slabs: Vec<(usize, usize)> = (0..count)
            .map(|s| {
                let (a, b) = (s * nz / count, (s + 1) * nz / count);
                (redo.lo[2] + a, b - a)
            })
            .collect();
        let cdims = [self.source.dims[0] + 2, self.source.dims[1] + 2];
        slabs
            .par_iter()
            .map(|&(z0, nz)| {
                let voxels = Region {
                    lo: [redo.lo[0], redo.lo[1], z0],
                    dims: [redo.dims[0], redo.dims[1], nz],
                };
                // Margin coordinates of the voxels' centres and their neighbours.
                let neighbourhood = Region {
                    lo: voxels.lo,
                    dims: [0, 1, 2].map(|a| voxels.dims[a] + 2),
                };
                let (mut lo, mut hi) = bounds(&self.centres, cdims, &neighbourhood);
                if let Some(f) = fresh {
                    // The neighbourhood spans the fresh box in x and y (it is the redone box
                    // widened by one, the redone box the fresh box widened by one), so the
                    // fresh planes it meets bound its fresh points.
                    let z_lo = neighbourhood.lo[2].max(f.region.lo[2]);
                    let z_hi = (neighbourhood.lo[2] + neighbourhood.dims[2])
                        .min(f.region.lo[2] + f.region.dims[2]);
                    for &(l, h) in f
                        .plane_bounds
                        .get(
                            z_lo.saturating_sub(f.region.lo[2])
                                ..z_hi.saturating_sub(f.region.lo[2]),
                        )
                        .unwrap_or(&[])
                    {
                        lo = lo.min(l);
                        hi = hi.max(h);
                    }
                }
                SlabPlan {
                    voxels,
                    output: Region::of_bounds(lo, hi, self.output.dims),
                }
            })
            .collect()
    }

    /// Recompute the output voxels of `region` from their tallies (True's rule).
    fn renormalise(&mut self, region: &Region) {
        if region.is_empty() {
            return;
        }
        let [nx, ny, _] = self.output.dims;
        let bg = self.background;
        let [x0, y0, z0] = region.lo;
        let [dx, dy, dz] = region.dims;
        self.volume
            .data_mut()
            .par_chunks_mut(nx * ny)
            .zip(self.tallies.par_chunks(nx * ny))
            .skip(z0)
            .take(dz)
            .for_each(|(vp, tp)| {
                for j in y0..y0 + dy {
                    let s = j * nx + x0;
                    for (v, t) in vp[s..s + dx].iter_mut().zip(&tp[s..s + dx]) {
                        *v = f32::from_f64(normalise(t[0], t[1], bg));
                    }
                }
            });
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

/// Bounds of the finite points of `pts` (x fastest, rows of `dims[0]`, planes of
/// `dims[0]·dims[1]`) inside `r`; `(+∞, −∞)` if none.
fn bounds(pts: &[DVec3], dims: [usize; 2], r: &Region) -> (DVec3, DVec3) {
    let mut lo = DVec3::INFINITY;
    let mut hi = DVec3::NEG_INFINITY;
    for k in r.lo[2]..r.lo[2] + r.dims[2] {
        for j in r.lo[1]..r.lo[1] + r.dims[1] {
            let s = r.lo[0] + dims[0] * (j + dims[1] * k);
            for p in pts.get(s..s + r.dims[0]).unwrap_or(&[]) {
                if p.is_finite() {
                    lo = vmin(lo, *p);
                    hi = vmax(hi, *p);
                }
            }
        }
    }
    (lo, hi)
}

/// Write `fresh` (centre images over the margin-coordinate box `fresh_box`) into `centres`
/// (rows of `cdims[0]`, planes of `cdims[0]·cdims[1]`).
fn store_centres(centres: &mut [DVec3], cdims: [usize; 2], fresh: &[DVec3], fresh_box: &Region) {
    let [cx, cy] = cdims;
    let [fx, fy, _] = fresh_box.dims;
    if fresh_box.is_empty() {
        return;
    }
    centres
        .par_chunks_mut(cx * cy)
        .skip(fresh_box.lo[2])
        .zip(fresh.par_chunks(fx * fy))
        .for_each(|(plane, src)| {
            for (j, row) in src.chunks_exact(fx).enumerate() {
                let s = (fresh_box.lo[1] + j) * cx + fresh_box.lo[0];
                plane[s..s + fx].copy_from_slice(row);
            }
        });
}

/// Group slab plans (indices) so that within a group the output z-ranges are pairwise
/// disjoint, each group sorted by output z; greedy in slab order, so the grouping depends on
/// the plans alone. Plans reaching no output voxel join the first group.
fn colours(plans: &[SlabPlan]) -> Vec<Vec<usize>> {
    let z_range = |p: &SlabPlan| (p.output.lo[2], p.output.lo[2] + p.output.dims[2]);
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (n, plan) in plans.iter().enumerate() {
        let (a, b) = z_range(plan);
        let fits = |g: &Vec<usize>| {
            plan.output.is_empty()
                || g.iter().all(|&m| {
                    let o = &plans[m];
                    let (c, d) = z_range(o);
                    o.output.is_empty() || b <= c || d <= a
                })
        };
        match groups.iter_mut().find(|g| fits(g)) {
            Some(g) => g.push(n),
            None => groups.push(vec![n]),
        }
    }
    for g in &mut groups {
        g.sort_by_key(|&m| {
            let o = &plans[m];
            if o.output.is_empty() {
                0
            } else {
                o.output.lo[2]
            }
        });
    }
    groups
}
