//! Push-forward chunk by chunk (out-of-core stores, Dask), bit for bit the in-memory
//! [`push_forward_antialiased`](crate::pushforward::push_forward_antialiased) and
//! [`push_forward_nearest`](crate::pushforward::push_forward_nearest).
//!
//! # Direction
//!
//! As [`pushforward`](crate::pushforward): every *input* voxel goes to where the map sends
//! it. An input voxel therefore writes into whichever output chunks its image reaches, and
//! an output chunk is known only once every input voxel reaching it has been tallied.
//!
//! # Why the result is the in-memory one, bit for bit
//!
//! The in-memory antialiased push-forward cuts the input into z-slabs whose size depends
//! only on the input's dims, tallies each slab into `f32` sums `[V, W]` starting from zero
//! (its voxels in index order), adds the slabs' tallies into the output sums in slab order,
//! and normalises. Floating-point addition is not associative, so a chunk must repeat those
//! very additions. For an output chunk `o`, [`push_chunk`] does, for every slab `s` whose
//! voxels reach `o`, in slab order:
//!
//! 1. evaluate the images of the voxels of `B(s, o)` — the box of the slab's voxels whose
//!    proxy boxes (or, nearest, images) reach `o` — on the same fixed tiles the in-memory
//!    path evaluates them on (the map's grid evaluation may depend on the grid, so the bits
//!    of an image are those of its tile; see `crate::centres`), so every proxy box has the
//!    in-memory bits;
//! 2. tally those voxels, in index order (a subsequence of the slab's order, and voxels
//!    left out add nothing to `o`), into a zeroed buffer over `o`'s part of the slab's
//!    footprint: the box tally gives the same weight to a cell whatever part of the output
//!    it is restricted to (`tally::splat`), so each of `o`'s cells receives the slab tally's
//!    very additions;
//! 3. add that buffer to the chunk's sums, exactly as the in-memory path adds a slab's tally.
//!
//! Skipped slabs and cells add `+0` to sums that are never `−0`, which changes no bit. The
//! nearest push-forward keeps the largest value per output voxel, visiting voxels in input
//! order; the chunk visits its sources in slab order and each box in index order, so ties
//! and NaN values resolve as in memory too.
//!
//! # Planning
//!
//! [`plan_push`] evaluates the map over the whole input once (slab by slab, in bands of rows,
//! in parallel) and records, for every output chunk, its sources `S(o)`: the slabs that
//! reach it, each with `B(s, o)` and the output box it touches in `o` (both widened by
//! [`FOOTPRINT_MARGIN`]), plus the voxel counts of [`PushForwardStats`]. The command line
//! and `volmorph.dask` both plan with it; a task needs only its chunk's sources.
//!
//! # Costs
//!
//! * Work: the plan is one evaluation of the map and one proxy box per input voxel (about a
//!   tenth of the push-forward); each chunk evaluates the tiles of its sources (whole tiles
//!   of 64 × 64 points, so a border of up to 64 points more per side than it needs) and
//!   tallies each voxel that reaches it (a voxel whose box straddles a chunk border is
//!   tallied once per chunk it reaches, restricted to that chunk).
//! * Memory per task ([`PushPlan::task_bytes`], checked against the budget before the input
//!   is read): the input box `∪ B(s, o)` in the input's voxel type, 8 bytes of sums per
//!   voxel of `o` and as many for one slab's part, 24 bytes per mapped point of the largest
//!   source (three times for mapped face centres), and the output chunk. For a smooth map
//!   this is about `o`'s size times the local area stretch, whatever the volume's size.

use std::collections::HashMap;

use rayon::prelude::*;
use volmorph_deform::SpaceMap;
use volmorph_volume::{AnyVolume, Geometry, IndexBox, Volume, Voxel};

use super::{ChunkGrid, check_chunk, chunk_geometry, nonempty};
use crate::WarpError;
use crate::centres::PointGrid;
use crate::pushforward::{
    AntialiasOptions, FaceCentres, PushForwardStats, ToIndex, images, normalise_into,
    output_geometry, round_index, slabs, try_filled,
};
use crate::tally::{
    FaceImages, Region, Voxels, averaged_bounds, cell_range, reaches_grid, tally_averaged,
    tally_mapped,
};

/// Output cells added on every side of an input voxel's cell range when deciding which
/// chunks (and which part of them) it reaches. The box tally writes only cells its box
/// overlaps, and finds them by the same `⌊lo + ½⌋` as the plan, but decides its last cell by
/// a comparison that may round the other way than the plan's `⌈hi − ½⌉`; one cell of margin
/// keeps the plan a superset (a voxel planned for a chunk it does not reach adds nothing).
pub const FOOTPRINT_MARGIN: usize = 1;

/// Mapped points per band of the plan (rows of a slab evaluated together): 2²¹ points are
/// 48 MiB of images per thread, and a slab's plan holds one band at a time.
const PLAN_BAND_POINTS: usize = 1 << 21;

/// Which push-forward runs chunk by chunk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PushMethod {
    /// True §5.3 "map and round" ([`push_forward_nearest`](crate::pushforward::push_forward_nearest)).
    Nearest,
    /// True §5.4 box-filter antialiasing
    /// ([`push_forward_antialiased`](crate::pushforward::push_forward_antialiased)).
    Antialiased(AntialiasOptions),
}

impl PushMethod {
    fn validate(&self) -> Result<(), WarpError> {
        match self {
            Self::Antialiased(o) if !o.background.is_finite() => {
                Err(WarpError::Background(o.background))
            }
            _ => Ok(()),
        }
    }
}

/// One input slab's part in one output chunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PushSource {
    /// The slab (number in the in-memory push-forward's partition of the input, [`slab_ranges`]).
    pub slab: usize,
    /// Input voxels of the slab whose images may reach the chunk (input indices; inside the
    /// slab).
    pub input: IndexBox,
    /// Output voxels of the chunk those voxels may write (output indices; inside the chunk).
    pub output: IndexBox,
}

/// The slabs of the in-memory push-forward of an input of `dims`: half-open ranges of z
/// slices, fixed by the dims alone (so the order of floating-point sums never depends on
/// threads or chunks).
#[must_use]
pub fn slab_ranges(dims: [usize; 3]) -> Vec<(usize, usize)> {
    slabs(dims)
}

/// The plan of a chunked push-forward: for every output chunk its sources, and what happens
/// to the input voxels.
#[derive(Debug, Clone, PartialEq)]
pub struct PushPlan {
    input: Geometry,
    output: Geometry,
    method: PushMethod,
    chunks: ChunkGrid,
    sources: Vec<Vec<PushSource>>,
    stats: PushForwardStats,
}

impl PushPlan {
    /// The input grid.
    #[must_use]
    pub fn input(&self) -> &Geometry {
        &self.input
    }

    /// The output grid.
    #[must_use]
    pub fn output(&self) -> &Geometry {
        &self.output
    }

    /// The push-forward planned.
    #[must_use]
    pub fn method(&self) -> &PushMethod {
        &self.method
    }

    /// The output chunks.
    #[must_use]
    pub fn chunks(&self) -> &ChunkGrid {
        &self.chunks
    }

    /// The sources of chunk number `chunk` in slab order (empty for a chunk nothing reaches,
    /// or past the last chunk).
    #[must_use]
    pub fn sources(&self, chunk: usize) -> &[PushSource] {
        self.sources.get(chunk).map_or(&[], Vec::as_slice)
    }

    /// The input box chunk number `chunk` reads: the union of its sources' input boxes
    /// (empty when nothing reaches it).
    #[must_use]
    pub fn input_box(&self, chunk: usize) -> IndexBox {
        input_box(self.sources(chunk))
    }

    /// Counts of what happens to the input voxels, equal to the in-memory push-forward's
    /// [`PushForward::stats`](crate::pushforward::PushForward::stats).
    #[must_use]
    pub fn stats(&self) -> PushForwardStats {
        self.stats
    }

    /// Working memory of chunk number `chunk`'s task, in bytes, for an input of
    /// `voxel_bytes` bytes per voxel (see the [module docs](self)).
    #[must_use]
    pub fn task_bytes(&self, chunk: usize, voxel_bytes: usize) -> u64 {
        task_bytes(
            &self.method,
            self.chunks.chunk(chunk),
            self.sources(chunk),
            voxel_bytes,
        )
    }

    /// [`push_chunk`] of chunk number `chunk` with this plan's grids, method and sources.
    ///
    /// # Errors
    /// As [`push_chunk`]; [`WarpError::InvalidOption`] for a chunk number past the last.
    pub fn push_chunk<M, R>(&self, map: &M, chunk: usize, read: R) -> Result<AnyVolume, WarpError>
    where
        M: SpaceMap + ?Sized,
        R: FnOnce(IndexBox) -> Result<AnyVolume, WarpError>,
    {
        if chunk >= self.chunks.len() {
            return Err(WarpError::InvalidOption(format!(
                "chunk {chunk} of a plan of {} chunks",
                self.chunks.len()
            )));
        }
        push_chunk(
            map,
            &self.input,
            &self.output,
            &self.method,
            self.chunks.chunk(chunk),
            self.sources(chunk),
            read,
        )
    }
}

/// The union of the sources' input boxes.
fn input_box(sources: &[PushSource]) -> IndexBox {
    sources
        .iter()
        .fold(IndexBox::default(), |b, s| b.union(&s.input))
}

fn box_dims(b: &IndexBox) -> [usize; 3] {
    [0, 1, 2].map(|a| b.end[a].saturating_sub(b.start[a]))
}

fn task_bytes(
    method: &PushMethod,
    chunk: IndexBox,
    sources: &[PushSource],
    voxel_bytes: usize,
) -> u64 {
    let vb = voxel_bytes as u64;
    let o = chunk.len() as u64;
    let read = nonempty(input_box(sources)).len() as u64 * vb;
    let largest = |f: &dyn Fn(&PushSource) -> u64| sources.iter().map(f).max().unwrap_or(0);
    let points = largest(&|s| {
        let d = box_dims(&s.input).map(|d| d as u64);
        match method {
            PushMethod::Nearest => d[0] * d[1] * d[2],
            PushMethod::Antialiased(a) if a.face_centres == FaceCentres::Mapped => {
                3 * (d[0] + 1) * (d[1] + 1) * (d[2] + 1)
            }
            PushMethod::Antialiased(_) => (d[0] + 2) * (d[1] + 2) * (d[2] + 2),
        }
    });
    let work = match method {
        PushMethod::Nearest => o * (vb + 1),
        PushMethod::Antialiased(_) => o * (8 + vb) + largest(&|s| s.output.len() as u64) * 8,
    };
    read.saturating_add(points.saturating_mul(24))
        .saturating_add(work)
}

/// Plan a chunked push-forward of an input on `input` onto `output`, cut into `chunks` (see
/// the [module docs](self)).
///
/// # Errors
/// [`WarpError::Geometry`] for an invalid grid; [`WarpError::InvalidOption`] if `chunks`
/// does not cover `output`; [`WarpError::Background`] for a non-finite background;
/// [`WarpError::MapOnGrid`] if the map's evaluation fails; [`WarpError::Allocation`] if a
/// band of mapped points exceeds the memory budget.
pub fn plan_push<M: SpaceMap + ?Sized>(
    map: &M,
    input: &Geometry,
    output: &Geometry,
    method: &PushMethod,
    chunks: &ChunkGrid,
) -> Result<PushPlan, WarpError> {
    plan_push_with(map, input, output, method, chunks, &volmorph_io::NoProgress)
}

/// [`plan_push`] reporting to `progress`: one stage whose steps are the input's z-slices,
/// advanced slab by slab, stopping between slabs when cancelled.
///
/// # Errors
/// As [`plan_push`]; [`WarpError::Cancelled`] when `progress` asks to stop.
pub fn plan_push_with<M: SpaceMap + ?Sized>(
    map: &M,
    input: &Geometry,
    output: &Geometry,
    method: &PushMethod,
    chunks: &ChunkGrid,
    progress: &dyn volmorph_io::Progress,
) -> Result<PushPlan, WarpError> {
    input
        .validate_unbounded()
        .map_err(|source| WarpError::Geometry {
            what: "input grid",
            source,
        })?;
    output.validate_unbounded().map_err(output_geometry)?;
    method.validate()?;
    if chunks.dims() != output.dims {
        return Err(WarpError::InvalidOption(format!(
            "the chunks cover {:?} voxels, the output grid has {:?}",
            chunks.dims(),
            output.dims
        )));
    }
    let owners = chunks.owners();
    let to_index = ToIndex::new(output);
    let slab_list = slabs(input.dims);
    progress.start("planning the push-forward", input.dims[2] as u64);
    let ctx = PlanContext {
        map,
        input,
        output_dims: output.dims,
        to_index,
        method,
        chunks,
        owners: &owners,
    };
    let parts: Vec<SlabPlan> = slab_list
        .par_iter()
        .map(|&slab| {
            progress.check()?;
            let p = ctx.slab(slab);
            progress.advance((slab.1 - slab.0) as u64);
            p
        })
        .collect::<Result<_, WarpError>>()?;
    progress.check()?;
    let mut sources: Vec<Vec<PushSource>> = vec![Vec::new(); chunks.len()];
    let mut stats = PushForwardStats::default();
    for (slab, part) in parts.into_iter().enumerate() {
        stats.add(&part.stats);
        for (c, (input, output)) in part.parts {
            if let Some(list) = sources.get_mut(c) {
                list.push(PushSource {
                    slab,
                    input,
                    output,
                });
            }
        }
    }
    Ok(PushPlan {
        input: *input,
        output: *output,
        method: *method,
        chunks: chunks.clone(),
        sources,
        stats,
    })
}

/// What one slab contributes to the plan: per chunk number, the input and output boxes.
struct SlabPlan {
    parts: HashMap<usize, (IndexBox, IndexBox)>,
    stats: PushForwardStats,
}

struct PlanContext<'a, M: ?Sized> {
    map: &'a M,
    input: &'a Geometry,
    output_dims: [usize; 3],
    to_index: ToIndex,
    method: &'a PushMethod,
    chunks: &'a ChunkGrid,
    owners: &'a [Vec<u32>; 3],
}

/// A run of voxels along x that reach the same chunks.
struct Run {
    /// First and last chunk position per axis (x, y, z).
    key: [u32; 6],
    i0: usize,
    i1: usize,
    /// Output cells reached (inclusive bounds).
    lo: [usize; 3],
    hi: [usize; 3],
}

/// Collects the voxels of one slab into runs and the runs into per-chunk boxes.
struct Collector<'a> {
    chunks: &'a ChunkGrid,
    owners: &'a [Vec<u32>; 3],
    parts: HashMap<usize, (IndexBox, IndexBox)>,
    run: Option<Run>,
}

impl Collector<'_> {
    /// Voxel `i` of the current row reaches the output cells `lo ..= hi`.
    fn voxel(&mut self, i: usize, j: usize, k: usize, lo: [usize; 3], hi: [usize; 3]) {
        let o = self.owners;
        let key = [
            o[0][lo[0]],
            o[0][hi[0]],
            o[1][lo[1]],
            o[1][hi[1]],
            o[2][lo[2]],
            o[2][hi[2]],
        ];
        if let Some(r) = self.run.as_mut().filter(|r| r.key == key) {
            r.i1 = i;
            for a in 0..3 {
                r.lo[a] = r.lo[a].min(lo[a]);
                r.hi[a] = r.hi[a].max(hi[a]);
            }
            return;
        }
        self.flush(j, k);
        self.run = Some(Run {
            key,
            i0: i,
            i1: i,
            lo,
            hi,
        });
    }

    /// Record the current run (of row `j`, slice `k`) in every chunk it reaches.
    fn flush(&mut self, j: usize, k: usize) {
        let Some(r) = self.run.take() else {
            return;
        };
        let ib = IndexBox {
            start: [r.i0, j, k],
            end: [r.i1 + 1, j + 1, k + 1],
        };
        let [x0, x1, y0, y1, z0, z1] = r.key.map(|c| c as usize);
        for cz in z0..=z1 {
            for cy in y0..=y1 {
                for cx in x0..=x1 {
                    let c = self.chunks.index_of([cx, cy, cz]);
                    let cb = self.chunks.chunk(c);
                    let ob = IndexBox {
                        start: [0, 1, 2].map(|a| r.lo[a].max(cb.start[a])),
                        end: [0, 1, 2].map(|a| (r.hi[a] + 1).min(cb.end[a])),
                    };
                    let e = self
                        .parts
                        .entry(c)
                        .or_insert((IndexBox::default(), IndexBox::default()));
                    e.0 = e.0.union(&ib);
                    e.1 = e.1.union(&ob);
                }
            }
        }
    }
}

impl<M: SpaceMap + ?Sized> PlanContext<'_, M> {
    /// The output cells an antialiased proxy box may write, widened by
    /// [`FOOTPRINT_MARGIN`]; `None` if it reaches no output voxel.
    fn box_cells(&self, lo: glam::DVec3, hi: glam::DVec3) -> Option<([usize; 3], [usize; 3])> {
        let n = self.output_dims;
        if !reaches_grid(lo, hi, n) {
            return None;
        }
        let mut a = [0usize; 3];
        let mut b = [0usize; 3];
        for ax in 0..3 {
            let (s, e) = cell_range(lo[ax], hi[ax], n[ax])?;
            a[ax] = s.saturating_sub(FOOTPRINT_MARGIN);
            b[ax] = (e + FOOTPRINT_MARGIN).min(n[ax] - 1);
        }
        Some((a, b))
    }

    fn slab(&self, (k0, k1): (usize, usize)) -> Result<SlabPlan, WarpError> {
        let [nx, ny, _] = self.input.dims;
        let nk = k1 - k0;
        let per_row = (nx + 2) * (nk + 2);
        let rows = (PLAN_BAND_POINTS / per_row.max(1)).saturating_sub(2).max(1);
        let mut col = Collector {
            chunks: self.chunks,
            owners: self.owners,
            parts: HashMap::new(),
            run: None,
        };
        let mut stats = PushForwardStats::default();
        for j0 in (0..ny).step_by(rows) {
            let j1 = (j0 + rows).min(ny);
            let nj = j1 - j0;
            match self.method {
                PushMethod::Nearest => {
                    let bx = Region {
                        lo: [1, j0 + 1, k0 + 1],
                        dims: [nx, nj, nk],
                    };
                    let mut pts = points(bx.len())?;
                    PointGrid::centres(self.input.dims)
                        .eval_box(self.map, self.input, &bx, &mut pts)?;
                    let n = self.output_dims;
                    for kk in 0..nk {
                        for j in j0..j1 {
                            let row = &pts[nx * ((j - j0) + nj * kk)..][..nx];
                            for (i, p) in row.iter().enumerate() {
                                if !p.is_finite() {
                                    stats.non_finite += 1;
                                    continue;
                                }
                                let q = self.to_index.apply(*p);
                                match (
                                    round_index(q.x, n[0]),
                                    round_index(q.y, n[1]),
                                    round_index(q.z, n[2]),
                                ) {
                                    (Some(x), Some(y), Some(z)) => {
                                        stats.mapped += 1;
                                        col.voxel(i, j, k0 + kk, [x, y, z], [x, y, z]);
                                    }
                                    _ => stats.outside += 1,
                                }
                            }
                            col.flush(j, k0 + kk);
                        }
                    }
                }
                PushMethod::Antialiased(o) if o.face_centres == FaceCentres::Mapped => {
                    let face = |a: usize| {
                        let mut dims = [nx, nj, nk];
                        dims[a] += 1;
                        let bx = Region {
                            lo: [0, j0, k0],
                            dims,
                        };
                        let grid = PointGrid::faces(a, self.input.dims);
                        images(self.map, self.input, &grid, &bx, &self.to_index)
                    };
                    let (fx, fy, fz) = (face(0)?.0, face(1)?.0, face(2)?.0);
                    let faces = FaceImages {
                        x: &fx,
                        y: &fy,
                        z: &fz,
                        dims: [nx, nj, nk],
                    };
                    for kk in 0..nk {
                        for j in j0..j1 {
                            for i in 0..nx {
                                self.classify(
                                    faces.bounds(i, j - j0, kk),
                                    &mut stats,
                                    &mut col,
                                    [i, j, k0 + kk],
                                );
                            }
                            col.flush(j, k0 + kk);
                        }
                    }
                }
                PushMethod::Antialiased(_) => {
                    let bx = Region {
                        lo: [0, j0, k0],
                        dims: [nx + 2, nj + 2, nk + 2],
                    };
                    let grid = PointGrid::centres(self.input.dims);
                    let (c, _) = images(self.map, self.input, &grid, &bx, &self.to_index)?;
                    let (sy, sz) = (nx + 2, (nx + 2) * (nj + 2));
                    for kk in 0..nk {
                        for j in j0..j1 {
                            for i in 0..nx {
                                let n = (i + 1) + sy * (j - j0 + 1) + sz * (kk + 1);
                                let nb = [
                                    c[n - 1],
                                    c[n + 1],
                                    c[n - sy],
                                    c[n + sy],
                                    c[n - sz],
                                    c[n + sz],
                                ];
                                self.classify(
                                    averaged_bounds(c[n], nb),
                                    &mut stats,
                                    &mut col,
                                    [i, j, k0 + kk],
                                );
                            }
                            col.flush(j, k0 + kk);
                        }
                    }
                }
            }
        }
        Ok(SlabPlan {
            parts: col.parts,
            stats,
        })
    }

    /// Count an antialiased voxel's proxy box and record the cells it may write.
    #[inline]
    fn classify(
        &self,
        proxy: Option<(glam::DVec3, glam::DVec3)>,
        stats: &mut PushForwardStats,
        col: &mut Collector<'_>,
        [i, j, k]: [usize; 3],
    ) {
        let Some((lo, hi)) = proxy else {
            stats.non_finite += 1;
            return;
        };
        match self.box_cells(lo, hi) {
            Some((a, b)) => {
                stats.mapped += 1;
                col.voxel(i, j, k, a, b);
            }
            None => stats.outside += 1,
        }
    }
}

/// A zeroed buffer of `n` mapped points, checked against the budget.
fn points(n: usize) -> Result<Vec<glam::DVec3>, WarpError> {
    volmorph_io::try_vec("mapped points", n, glam::DVec3::ZERO).map_err(|_| WarpError::Allocation {
        what: "mapped points",
        bytes: n.saturating_mul(24),
    })
}

/// Check that `sources` can be the sources of `chunk`: in increasing slab order, each
/// input box non-empty and inside its slab, each output box non-empty and inside the chunk.
fn check_sources(
    input: &Geometry,
    chunk: IndexBox,
    sources: &[PushSource],
) -> Result<(), WarpError> {
    let slab_list = slabs(input.dims);
    let mut last: Option<usize> = None;
    for s in sources {
        let bad = |why: &str| {
            Err(WarpError::InvalidOption(format!(
                "source {s:?} of the chunk {:?}..{:?}: {why}",
                chunk.start, chunk.end
            )))
        };
        if last.is_some_and(|l| s.slab <= l) {
            return bad("sources must be in increasing slab order");
        }
        last = Some(s.slab);
        let Some(&(k0, k1)) = slab_list.get(s.slab) else {
            return bad(&format!("the input has {} slabs", slab_list.len()));
        };
        let slab = IndexBox {
            start: [0, 0, k0],
            end: [input.dims[0], input.dims[1], k1],
        };
        if s.input.is_empty() || s.input.union(&slab) != slab {
            return bad(&format!(
                "the input box is empty or leaves the slab {slab:?}"
            ));
        }
        if s.output.is_empty() || s.output.union(&chunk) != chunk {
            return bad("the output box is empty or leaves the chunk");
        }
    }
    Ok(())
}

/// Push forward the input voxels of `sources` (as planned by [`plan_push`] for `chunk`)
/// into the output chunk `chunk` of `output`: `read` is asked once for the union of the
/// sources' input boxes (one voxel when there is none, for the voxel type) and returns its
/// voxels, x fastest, in the input's voxel type. Returns the chunk's voxels on
/// [`chunk_geometry`], equal bit for bit to the same voxels of the in-memory push-forward
/// of the whole input (see the [module docs](self)).
///
/// # Errors
/// [`WarpError::Geometry`] for an invalid grid; [`WarpError::InvalidOption`] for a chunk
/// outside `output` or sources that are not a plan's (order, boxes); the errors of `read`;
/// [`WarpError::BufferLength`] if `read` returns another size than the box; an
/// [`volmorph_io::IoError::Budget`] (as [`WarpError::Volume`]) when the task's working memory
/// exceeds the budget; [`WarpError::MapOnGrid`] if the map's evaluation fails.
pub fn push_chunk<M, R>(
    map: &M,
    input: &Geometry,
    output: &Geometry,
    method: &PushMethod,
    chunk: IndexBox,
    sources: &[PushSource],
    read: R,
) -> Result<AnyVolume, WarpError>
where
    M: SpaceMap + ?Sized,
    R: FnOnce(IndexBox) -> Result<AnyVolume, WarpError>,
{
    check_chunk(output, chunk)?;
    input
        .validate_unbounded()
        .map_err(|source| WarpError::Geometry {
            what: "input grid",
            source,
        })?;
    method.validate()?;
    check_sources(input, chunk, sources)?;
    volmorph_io::check_bytes(
        &format!(
            "the push-forward of the chunk {:?}..{:?} ({} sources)",
            chunk.start,
            chunk.end,
            sources.len()
        ),
        task_bytes(method, chunk, sources, 8),
    )
    .map_err(|e| WarpError::Volume(e.into()))?;
    let want = nonempty(input_box(sources));
    let region = read(want)?;
    let dims = box_dims(&want);
    if region.geometry().dims != dims {
        return Err(WarpError::BufferLength {
            dims,
            expected: want.len(),
            got: region.geometry().len(),
        });
    }
    let task = Task {
        map,
        input,
        output,
        chunk,
        sources,
        region_start: want.start,
        to_index: ToIndex::new(output),
    };
    volmorph_volume::with_volume!(&region, v => task.run(v, method).map(AnyVolume::from))
}

/// One chunk's push-forward.
struct Task<'a, M: ?Sized> {
    map: &'a M,
    input: &'a Geometry,
    output: &'a Geometry,
    chunk: IndexBox,
    sources: &'a [PushSource],
    region_start: [usize; 3],
    to_index: ToIndex,
}

impl<M: SpaceMap + ?Sized> Task<'_, M> {
    fn run<T: Voxel>(
        &self,
        region: &Volume<T>,
        method: &PushMethod,
    ) -> Result<Volume<T>, WarpError> {
        let data = match method {
            PushMethod::Nearest => self.nearest(region)?,
            PushMethod::Antialiased(o) => self.antialiased(region, o)?,
        };
        Volume::new(chunk_geometry(self.output, self.chunk), data).map_err(output_geometry)
    }

    /// The source's voxel box in the region's own indices.
    fn local(&self, s: &PushSource) -> Region {
        Region {
            lo: [0, 1, 2].map(|a| s.input.start[a] - self.region_start[a]),
            dims: box_dims(&s.input),
        }
    }

    fn antialiased<T: Voxel>(
        &self,
        region: &Volume<T>,
        o: &AntialiasOptions,
    ) -> Result<Vec<T>, WarpError> {
        let cd = box_dims(&self.chunk);
        let c0 = self.chunk.start;
        let mut acc = try_filled(self.chunk.len(), [0.0f32; 2], "chunk accumulator")?;
        let largest = self
            .sources
            .iter()
            .map(|s| s.output.len())
            .max()
            .unwrap_or(0);
        let mut tally = try_filled(largest, [0.0f32; 2], "slab accumulator")?;
        let values = region.data();
        let vdims = region.geometry().dims;
        for s in self.sources {
            let vb = box_dims(&s.input);
            let vbox = self.local(s);
            let r = Region {
                lo: s.output.start,
                dims: box_dims(&s.output),
            };
            let t = &mut tally[..r.len()];
            t.fill([0.0; 2]);
            match o.face_centres {
                FaceCentres::AveragedCentres => {
                    // Centre `i` of the widened grid is input voxel `i − 1`: the box of the
                    // source's voxels plus one on every side starts at its first voxel.
                    let bx = Region {
                        lo: s.input.start,
                        dims: vb.map(|d| d + 2),
                    };
                    let grid = PointGrid::centres(self.input.dims);
                    let (c, _) = images(self.map, self.input, &grid, &bx, &self.to_index)?;
                    let src = Voxels {
                        values,
                        vdims,
                        centres: &c,
                        cdims: [bx.dims[0], bx.dims[1]],
                    };
                    tally_averaged(&src, &vbox, [1, 1, 1], self.output.dims, &r, t, 1.0);
                }
                FaceCentres::Mapped => {
                    let face = |a: usize| {
                        let mut dims = vb;
                        dims[a] += 1;
                        let bx = Region {
                            lo: s.input.start,
                            dims,
                        };
                        let grid = PointGrid::faces(a, self.input.dims);
                        images(self.map, self.input, &grid, &bx, &self.to_index)
                    };
                    let (fx, fy, fz) = (face(0)?.0, face(1)?.0, face(2)?.0);
                    let faces = FaceImages {
                        x: &fx,
                        y: &fy,
                        z: &fz,
                        dims: vb,
                    };
                    tally_mapped(values, vdims, &vbox, &faces, self.output.dims, &r, t);
                }
            }
            // Add the slab's part exactly as the in-memory path adds a slab's tally.
            for z in 0..r.dims[2] {
                for y in 0..r.dims[1] {
                    let a = (r.lo[0] - c0[0])
                        + cd[0] * ((r.lo[1] + y - c0[1]) + cd[1] * (r.lo[2] + z - c0[2]));
                    let b = r.dims[0] * (y + r.dims[1] * z);
                    for (d, s) in acc[a..a + r.dims[0]].iter_mut().zip(&t[b..b + r.dims[0]]) {
                        d[0] += s[0];
                        d[1] += s[1];
                    }
                }
            }
        }
        let mut out = try_filled(acc.len(), T::from_f64(0.0), "chunk output")?;
        normalise_into(&acc, &mut out, o.background);
        Ok(out)
    }

    fn nearest<T: Voxel>(&self, region: &Volume<T>) -> Result<Vec<T>, WarpError> {
        let cd = box_dims(&self.chunk);
        let c0 = self.chunk.start;
        let mut out = try_filled(self.chunk.len(), T::default(), "chunk output")?;
        let mut written = try_filled(self.chunk.len(), false, "coverage")?;
        let values = region.data();
        let [vx, vy, _] = region.geometry().dims;
        let n = self.output.dims;
        for s in self.sources {
            let vb = box_dims(&s.input);
            let vbox = self.local(s);
            let bx = Region {
                lo: s.input.start.map(|i| i + 1),
                dims: vb,
            };
            let mut pts = points(bx.len())?;
            PointGrid::centres(self.input.dims).eval_box(self.map, self.input, &bx, &mut pts)?;
            let mut m = 0usize;
            for k in 0..vb[2] {
                for j in 0..vb[1] {
                    let first = vbox.lo[0] + vx * (vbox.lo[1] + j + vy * (vbox.lo[2] + k));
                    for i in 0..vb[0] {
                        let p = pts[m];
                        m += 1;
                        if !p.is_finite() {
                            continue;
                        }
                        let q = self.to_index.apply(p);
                        let (Some(x), Some(y), Some(z)) = (
                            round_index(q.x, n[0]),
                            round_index(q.y, n[1]),
                            round_index(q.z, n[2]),
                        ) else {
                            continue;
                        };
                        if !self.chunk.contains([x, y, z]) {
                            continue;
                        }
                        let t = (x - c0[0]) + cd[0] * ((y - c0[1]) + cd[1] * (z - c0[2]));
                        let v = values[first + i];
                        if let (Some(slot), Some(w)) = (out.get_mut(t), written.get_mut(t))
                            && (!*w || v > *slot)
                        {
                            *slot = v;
                            *w = true;
                        }
                    }
                }
            }
        }
        Ok(out)
    }
}

/// Push forward every chunk of `plan` (in parallel), reading input boxes through `read` and
/// handing each chunk to `write` with its box (see [`push_chunk`]). The union of the
/// written chunks equals the in-memory push-forward bit for bit. Returns the plan's
/// statistics.
///
/// # Errors
/// The first error of [`push_chunk`], `read` or `write` (other chunks may have been written).
pub fn push_chunked<M, R, W>(
    map: &M,
    plan: &PushPlan,
    read: R,
    write: W,
) -> Result<PushForwardStats, WarpError>
where
    M: SpaceMap + ?Sized,
    R: Fn(IndexBox) -> Result<AnyVolume, WarpError> + Sync,
    W: Fn(IndexBox, AnyVolume) -> Result<(), WarpError> + Sync,
{
    push_chunked_with(map, plan, read, write, &volmorph_io::NoProgress)
}

/// [`push_chunked`] reporting to `progress`: one stage whose steps are the chunks, each
/// advanced once written; when cancelled no further chunk is started (chunks already handed
/// to `write` stay written, so the caller discards its partial output).
///
/// # Errors
/// As [`push_chunked`]; [`WarpError::Cancelled`] when `progress` asks to stop.
pub fn push_chunked_with<M, R, W>(
    map: &M,
    plan: &PushPlan,
    read: R,
    write: W,
    progress: &dyn volmorph_io::Progress,
) -> Result<PushForwardStats, WarpError>
where
    M: SpaceMap + ?Sized,
    R: Fn(IndexBox) -> Result<AnyVolume, WarpError> + Sync,
    W: Fn(IndexBox, AnyVolume) -> Result<(), WarpError> + Sync,
{
    let n = plan.chunks().len();
    progress.start(&format!("pushing {n} chunks forward out of core"), n as u64);
    (0..n)
        .into_par_iter()
        .try_for_each(|c| -> Result<(), WarpError> {
            progress.check()?;
            let v = plan.push_chunk(map, c, &read)?;
            write(plan.chunks().chunk(c), v)?;
            progress.advance(1);
            Ok(())
        })?;
    progress.check()?;
    Ok(plan.stats())
}
