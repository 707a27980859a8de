//! Sampling defining functions on voxel grids.
//!
//! [`sample`] evaluates a [`Field`] at every voxel centre of a
//! [`Geometry`] (physical point `origin + direction · (spacing ⊙ index)`, x fastest) into an
//! `f32` [`Volume`].
//!
//! For compiled shapes the grid is cut into z-slabs processed in parallel (rayon); each slab
//! is split recursively in halves along its longest side. At every region the tape is
//! evaluated over the region's physical bounding box with intervals and **specialised**
//! ([`Tape::simplify`]): `min`/`max`/`select` sides that cannot decide the value in the
//! region are dropped, so far from the surface of a CSG model only a few instructions
//! remain. Regions of at most [`LEAF_POINTS`] voxels are evaluated with the batch
//! evaluator; on grids whose x axis is the physical x axis (no y or z component, and the y
//! and z steps without x component) the batch is row-structured, so every operation of x
//! alone is computed once per row position and every one of y and z alone once per row (the
//! gyroid's `sin(3x)`, a twist's `cos(1.2z)`), and full-lane operations read those compact
//! values broadcast. Because specialisation is exact, the result is **bit-for-bit the value
//! of point-by-point evaluation** of the full tape at each voxel centre ([`sample_naive`],
//! which the tests compare against).
//!
//! Fields without a tape are evaluated point by point in parallel (no culling).

use std::collections::HashMap;
use std::rc::Rc;

use glam::DVec3;
use rayon::prelude::*;
use volmorph_volume::{Geometry, Volume};

use crate::error::FrepError;
use crate::field::Field;
use crate::tape::{BatchScratch, IntervalScratch, Tape};

/// Largest region evaluated with the batch evaluator without further subdivision.
pub const LEAF_POINTS: usize = 4096;

/// How much longer than the other sides a region's x side must be before it is cut in
/// halves along x, on grids evaluated row-structured.
const ROW_SPLIT_BIAS: usize = 4;

/// z-layers per parallel task.
const SLAB: usize = 4;

/// Check a geometry and allocate its value buffer.
fn buffer(geometry: &Geometry) -> Result<Vec<f32>, FrepError> {
    geometry.validate()?;
    let n = volmorph_io::checked_len(&geometry.dims, size_of::<f32>())
        .map_err(|e| FrepError::InvalidArgument(format!("grid {:?}: {e}", geometry.dims)))?;
    Ok(vec![0.0f32; n])
}

/// Sample `field` at every voxel centre of `geometry`.
///
/// # Errors
/// [`FrepError::Volume`] for an invalid geometry; [`FrepError::InvalidArgument`] when the
/// grid exceeds the memory budget (checked before allocating);
/// [`FrepError::LoopBudget`] naming the loop when a data-dependent loop of the model had not
/// ended at some voxel (its value would be NaN); [`FrepError::AllNan`] when every value is
/// NaN.
pub fn sample(field: &dyn Field, geometry: &Geometry) -> Result<Volume<f32>, FrepError> {
    sample_with(field, geometry, &volmorph_io::NoProgress)
}

/// [`sample`] reporting one step per z-layer to `progress`; when it is cancelled the
/// remaining layers are skipped and [`FrepError::Cancelled`] is returned.
///
/// # Errors
/// As [`sample`].
pub fn sample_with(
    field: &dyn Field,
    geometry: &Geometry,
    progress: &dyn volmorph_io::Progress,
) -> Result<Volume<f32>, FrepError> {
    let mut data = buffer(geometry)?;
    let [nx, ny, nz] = geometry.dims;
    let layer = nx * ny;
    progress.start(&format!("sampling a {nx}×{ny}×{nz} grid"), nz as u64);
    match field.tape() {
        Some(tape) => {
            data.par_chunks_mut(layer * SLAB).enumerate().for_each_init(
                TapeCache::default,
                |cache, (s, slab)| {
                    if progress.is_cancelled() {
                        return;
                    }
                    let k0 = s * SLAB;
                    let nz = slab.len() / layer;
                    let frame = Frame::new(geometry);
                    let mut w = Worker {
                        geometry,
                        frame,
                        rows_separable: frame.rows_separable(),
                        out: slab,
                        k0,
                        batch: BatchScratch::default(),
                        iv: IntervalScratch::default(),
                        coords: vec![[0.0; LEAF_POINTS]; 4],
                        cache,
                    };
                    w.region(tape, Some(FULL_TAPE), [0, 0, k0], [nx, ny, k0 + nz]);
                    progress.advance(nz as u64);
                },
            );
        }
        None => {
            let frame = Frame::new(geometry);
            data.par_chunks_mut(layer).enumerate().for_each(|(k, sl)| {
                if progress.is_cancelled() {
                    return;
                }
                for (j, row) in sl.chunks_mut(nx).enumerate() {
                    let r = frame.row(j, k);
                    for (i, o) in row.iter_mut().enumerate() {
                        *o = field.value(frame.point(r, i)) as f32;
                    }
                }
                progress.advance(1);
            });
        }
    }
    progress.check()?;
    check_nan(field, geometry, &data)?;
    Ok(Volume::new(*geometry, data)?)
}

/// Refuse a sampled field that is NaN everywhere, or NaN where a data-dependent loop of the
/// model had not ended (see [`crate::Shape::unfinished_loops`]): [`SampleTally::verdict`]
/// of the grid's values.
fn check_nan(field: &dyn Field, geometry: &Geometry, data: &[f32]) -> Result<(), FrepError> {
    let nan = data.par_iter().filter(|v| v.is_nan()).count();
    let mut tally = SampleTally {
        samples: data.len(),
        nan,
        running: Vec::new(),
    };
    if nan > 0 {
        let [nx, ny, _] = geometry.dims;
        let frame = Frame::new(geometry);
        tally.running = loop_masks(field)
            .iter()
            .map(|active| {
                data.par_iter()
                    .enumerate()
                    .filter(|&(idx, v)| {
                        v.is_nan() && {
                            let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
                            loop_running(active.eval(frame.point(frame.row(j, k), i)))
                        }
                    })
                    .count()
            })
            .collect();
    }
    tally.verdict(field)
}

/// The still-running masks of the model's data-dependent loops
/// ([`crate::Shape::unfinished_loops`]), one tape each in the model's order; empty for a
/// field without a tape.
pub(crate) fn loop_masks(field: &dyn Field) -> Vec<Tape> {
    field.tape().map_or_else(Vec::new, |tape| {
        tape.shape()
            .unfinished_loops()
            .iter()
            .map(|guard| Tape::new(&guard.active))
            .collect()
    })
}

/// Whether a loop's mask value (of [`loop_masks`]) says the loop was still running at the
/// point.
#[inline]
pub(crate) fn loop_running(mask: f64) -> bool {
    mask != 0.0 && !mask.is_nan()
}

/// What an output saw of a field's values, for the one rule every output that samples a
/// field applies ([`SampleTally::verdict`]): grid sampling and ray casting.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct SampleTally {
    /// Values computed.
    pub samples: usize,
    /// Values that were NaN.
    pub nan: usize,
    /// Per loop of [`loop_masks`], the NaN values at points where it was still running.
    pub running: Vec<usize>,
}

impl SampleTally {
    /// An empty tally for a field with `loops` masks.
    pub(crate) fn new(loops: usize) -> Self {
        Self {
            samples: 0,
            nan: 0,
            running: vec![0; loops],
        }
    }

    /// The counts of `self` and `other` together.
    pub(crate) fn merge(mut self, other: Self) -> Self {
        self.samples += other.samples;
        self.nan += other.nan;
        if self.running.len() < other.running.len() {
            self.running.resize(other.running.len(), 0);
        }
        for (a, b) in self.running.iter_mut().zip(other.running) {
            *a += b;
        }
        self
    }

    /// Whether some NaN value was at a point where a loop was still running (the verdict
    /// will be [`FrepError::LoopBudget`] whatever else is sampled).
    pub(crate) fn loop_failed(&self) -> bool {
        self.running.iter().any(|&n| n > 0)
    }

    /// The rule for NaN values: [`FrepError::LoopBudget`] naming the first loop of `field`
    /// (in the model's order) that was still running where a value was NaN, else
    /// [`FrepError::AllNan`] when every value was NaN; NaN values elsewhere are accepted
    /// (outside, for pictures and meshes).
    ///
    /// # Errors
    /// As above.
    pub(crate) fn verdict(&self, field: &dyn Field) -> Result<(), FrepError> {
        if self.nan == 0 {
            return Ok(());
        }
        if let Some(tape) = field.tape() {
            for (guard, &points) in tape.shape().unfinished_loops().iter().zip(&self.running) {
                if points > 0 {
                    return Err(FrepError::LoopBudget {
                        pos: guard.pos,
                        passes: guard.passes,
                        points,
                    });
                }
            }
        }
        if self.nan == self.samples {
            return Err(FrepError::AllNan { points: self.nan });
        }
        Ok(())
    }
}

/// Reference sampler: the full tape at every voxel centre, one point at a time (parallel
/// over z-layers). [`sample`] must agree with it exactly.
///
/// # Errors
/// As [`sample`].
pub fn sample_naive(tape: &Tape, geometry: &Geometry) -> Result<Volume<f32>, FrepError> {
    let mut data = buffer(geometry)?;
    let [nx, ny, _] = geometry.dims;
    data.par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, sl)| {
            let mut regs = Vec::new();
            let frame = Frame::new(geometry);
            for (j, row) in sl.chunks_mut(nx).enumerate() {
                let r = frame.row(j, k);
                for (i, o) in row.iter_mut().enumerate() {
                    *o = tape.eval_with(frame.point(r, i), &mut regs) as f32;
                }
            }
        });
    Ok(Volume::new(*geometry, data)?)
}

/// The grid's physical frame: voxel `(i, j, k)` is at `row(j, k) + i · step_x` with
/// `row(j, k) = origin + j · step_y + k · step_z`, the columns of `direction · diag(spacing)`.
/// One formula for every sampler, so they agree bit for bit.
#[derive(Clone, Copy)]
struct Frame {
    origin: DVec3,
    step: [DVec3; 3],
}

impl Frame {
    fn new(g: &Geometry) -> Self {
        let m = g.index_to_physical_matrix();
        Self {
            origin: g.origin,
            step: [m.x_axis, m.y_axis, m.z_axis],
        }
    }

    #[inline]
    fn row(&self, j: usize, k: usize) -> DVec3 {
        self.origin + self.step[1] * j as f64 + self.step[2] * k as f64
    }

    #[inline]
    fn point(&self, row: DVec3, i: usize) -> DVec3 {
        row + self.step[0] * i as f64
    }

    /// Whether x depends on `i` only and y, z on `(j, k)` only, bit for bit: the x step
    /// has no y or z component and the y and z steps no x component. (The terms added are
    /// then signed zeros whose sign does not depend on the index, so the sums do not
    /// either.)
    fn rows_separable(&self) -> bool {
        let [sx, sy, sz] = self.step;
        sx.y == 0.0 && sx.z == 0.0 && sy.x == 0.0 && sz.x == 0.0
    }
}

/// A regular grid of `dims` voxel centres spanning the box `[lo, hi]` (corners on the first
/// and last voxel centres, identity direction).
///
/// # Errors
/// [`FrepError::InvalidArgument`] when a dimension is below 2 or the box is empty, inverted
/// or not finite.
pub fn box_geometry(lo: DVec3, hi: DVec3, dims: [usize; 3]) -> Result<Geometry, FrepError> {
    if dims.iter().any(|&d| d < 2) {
        return Err(FrepError::InvalidArgument(format!(
            "grid dimensions must be at least 2, got {dims:?}"
        )));
    }
    if !(lo.is_finite() && hi.is_finite()) || (hi - lo).min_element() <= 0.0 {
        return Err(FrepError::InvalidArgument(format!(
            "bounds must be finite with min < max on every axis, got {lo} .. {hi}"
        )));
    }
    let steps = DVec3::new(
        (dims[0] - 1) as f64,
        (dims[1] - 1) as f64,
        (dims[2] - 1) as f64,
    );
    Ok(Geometry::new(dims)
        .with_origin(lo)
        .with_spacing((hi - lo) / steps))
}

/// A grid over the box `[lo, hi]` with equal steps on every axis: `longest` voxel centres
/// along the longest edge, and on the other axes the count that keeps the same step (rounded,
/// at least 2, at most `max_dims`). Corners on the first and last voxel centres as in
/// [`box_geometry`].
///
/// # Errors
/// [`FrepError::InvalidArgument`] when `longest` is outside `2..=max_dims` or the box is
/// empty, inverted or not finite.
pub fn isotropic_box_geometry(
    lo: DVec3,
    hi: DVec3,
    longest: usize,
    max_dims: usize,
) -> Result<Geometry, FrepError> {
    if !(2..=max_dims).contains(&longest) {
        return Err(FrepError::InvalidArgument(format!(
            "grid size {longest} must be between 2 and {max_dims}"
        )));
    }
    let ext = hi - lo;
    let step = ext.max_element() / (longest - 1) as f64;
    let dims = ext
        .to_array()
        .map(|e| ((e / step).round() as usize + 1).clamp(2, max_dims));
    box_geometry(lo, hi, dims)
}

struct Worker<'a> {
    geometry: &'a Geometry,
    frame: Frame,
    /// [`Frame::rows_separable`]: leaves may use row-structured batch evaluation.
    rows_separable: bool,
    out: &'a mut [f32],
    k0: usize,
    batch: BatchScratch,
    iv: IntervalScratch,
    /// Leaf buffers: x, y, z and values.
    coords: Vec<[f64; LEAF_POINTS]>,
    cache: &'a mut TapeCache,
}

/// Largest number of specialised tapes a [`TapeCache`] keeps.
const TAPE_CACHE_LIMIT: usize = 1024;

/// The [`TapeCache`] id of the tape sampled.
const FULL_TAPE: usize = usize::MAX;

/// Specialised tapes one worker has built, by the tape they were specialised from and the
/// choices over the region: regions deciding the same `min`/`max`/`select` sides share one
/// tape (building it costs more than evaluating the intervals). [`Tape::simplify`] is a
/// function of the tape and the choices alone, so a cached tape is the one it would build.
#[derive(Default)]
struct TapeCache {
    tapes: Vec<Rc<Tape>>,
    index: HashMap<Vec<u8>, usize>,
    key: Vec<u8>,
}

impl TapeCache {
    /// `tape` specialised to the choices `iv` recorded over a region (`None`: nothing to
    /// prune, use `tape`), and its id. `id` names `tape` ([`FULL_TAPE`], or an index into
    /// the cache); `None` for a tape not cached (the cache was full), whose
    /// specialisations are not cached either.
    fn specialise(
        &mut self,
        tape: &Tape,
        id: Option<usize>,
        iv: &IntervalScratch,
    ) -> (Option<Rc<Tape>>, Option<usize>) {
        let Some(id) = id else {
            return (tape.simplify(iv).map(Rc::new), None);
        };
        self.key.clear();
        self.key.extend_from_slice(&id.to_le_bytes());
        iv.choice_key(&mut self.key);
        if let Some(&k) = self.index.get(&self.key[..]) {
            return (Some(Rc::clone(&self.tapes[k])), Some(k));
        }
        let Some(t) = tape.simplify(iv).map(Rc::new) else {
            return (None, Some(id));
        };
        if self.tapes.len() >= TAPE_CACHE_LIMIT {
            return (Some(t), None);
        }
        self.tapes.push(Rc::clone(&t));
        self.index.insert(self.key.clone(), self.tapes.len() - 1);
        (Some(t), Some(self.tapes.len() - 1))
    }
}

impl Worker<'_> {
    /// Fill the index box `[lo, hi)` (hi exclusive).
    /// `id` names `tape` in the worker's [`TapeCache`].
    fn region(&mut self, tape: &Tape, id: Option<usize>, lo: [usize; 3], hi: [usize; 3]) {
        let size = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let count = size[0] * size[1] * size[2];
        if count == 0 {
            return;
        }
        // Specialise the tape to the region's physical bounding box (when it has anything
        // to prune).
        let (specialised, id) = if tape.choice_count() > 0 {
            let (plo, phi) = self.bounds(lo, hi);
            let _ = tape.interval_with(plo, phi, &mut self.iv);
            if self.iv.pruned() == 0 {
                (None, id)
            } else {
                self.cache.specialise(tape, id, &self.iv)
            }
        } else {
            (None, id)
        };
        let tape = specialised.as_deref().unwrap_or(tape);
        if count <= LEAF_POINTS {
            self.leaf(tape, lo, hi);
            return;
        }
        // On rows-separable grids x is cut last (long rows make row-structured evaluation
        // cheap: compact values are read broadcast row by row).
        let bias = if self.rows_separable {
            ROW_SPLIT_BIAS
        } else {
            1
        };
        let weight = |a: usize| if a == 0 { size[a] } else { size[a] * bias };
        let axis = (0..3).max_by_key(|&a| weight(a)).unwrap_or(0);
        let mid = lo[axis] + size[axis] / 2;
        let mut hi_a = hi;
        hi_a[axis] = mid;
        let mut lo_b = lo;
        lo_b[axis] = mid;
        self.region(tape, id, lo, hi_a);
        self.region(tape, id, lo_b, hi);
    }

    /// Physical bounding box of the voxel centres in `[lo, hi)`.
    fn bounds(&self, lo: [usize; 3], hi: [usize; 3]) -> (DVec3, DVec3) {
        let mut mn = DVec3::splat(f64::INFINITY);
        let mut mx = DVec3::splat(f64::NEG_INFINITY);
        for c in 0..8 {
            let pick = |a: usize| if c >> a & 1 == 0 { lo[a] } else { hi[a] - 1 };
            let p = self.frame.point(self.frame.row(pick(1), pick(2)), pick(0));
            mn = mn.min(p);
            mx = mx.max(p);
        }
        (mn, mx)
    }

    fn leaf(&mut self, tape: &Tape, lo: [usize; 3], hi: [usize; 3]) {
        if self.rows_separable {
            self.leaf_rows(tape, lo, hi);
            return;
        }
        // The buffers are taken out of `self` while `store` writes the slab.
        let mut coords = std::mem::take(&mut self.coords);
        let [xs, ys, zs, vals] = &mut coords[..] else {
            return;
        };
        let row_len = hi[0] - lo[0];
        // Whole rows per batch (a leaf region holds at most LEAF_POINTS voxels, but a
        // constant tape may cover a larger region: then several batches).
        let rows_per = (LEAF_POINTS / row_len.max(1)).max(1);
        let nrows = (hi[1] - lo[1]) * (hi[2] - lo[2]);
        let mut r0 = 0;
        while r0 < nrows {
            let r1 = (r0 + rows_per).min(nrows);
            let mut n = 0;
            for r in r0..r1 {
                let (j, k) = (lo[1] + r % (hi[1] - lo[1]), lo[2] + r / (hi[1] - lo[1]));
                let base = self.frame.row(j, k);
                for i in lo[0]..hi[0].min(lo[0] + LEAF_POINTS) {
                    let p = self.frame.point(base, i);
                    xs[n] = p.x;
                    ys[n] = p.y;
                    zs[n] = p.z;
                    n += 1;
                }
            }
            tape.eval_batch_with(
                &xs[..n],
                &ys[..n],
                &zs[..n],
                &mut vals[..n],
                &mut self.batch,
            );
            self.store(lo, hi, r0, r1, &vals[..n]);
            r0 = r1;
        }
        self.coords = coords;
    }

    /// [`Worker::leaf`] on a rows-separable grid: the x coordinates of one row and the y
    /// and z coordinates of every row, evaluated row-structured. The coordinates are those
    /// of [`Frame::point`] (x does not depend on the row, y and z not on the column, bit
    /// for bit, by [`Frame::rows_separable`]).
    fn leaf_rows(&mut self, tape: &Tape, lo: [usize; 3], hi: [usize; 3]) {
        let row_len = (hi[0] - lo[0]).min(LEAF_POINTS);
        if row_len == 0 {
            return;
        }
        let mut coords = std::mem::take(&mut self.coords);
        let [xs, ys, zs, vals] = &mut coords[..] else {
            return;
        };
        let first = self.frame.row(lo[1], lo[2]);
        for (x, i) in xs.iter_mut().zip(lo[0]..lo[0] + row_len) {
            *x = self.frame.point(first, i).x;
        }
        let rows_per = (LEAF_POINTS / row_len).max(1);
        let nrows = (hi[1] - lo[1]) * (hi[2] - lo[2]);
        let mut r0 = 0;
        while r0 < nrows {
            let r1 = (r0 + rows_per).min(nrows);
            for (n, r) in (r0..r1).enumerate() {
                let (j, k) = (lo[1] + r % (hi[1] - lo[1]), lo[2] + r / (hi[1] - lo[1]));
                let p = self.frame.point(self.frame.row(j, k), lo[0]);
                ys[n] = p.y;
                zs[n] = p.z;
            }
            let n = (r1 - r0) * row_len;
            tape.eval_rows_with(
                &xs[..row_len],
                &ys[..r1 - r0],
                &zs[..r1 - r0],
                &mut vals[..n],
                &mut self.batch,
            );
            self.store(lo, hi, r0, r1, &vals[..n]);
            r0 = r1;
        }
        self.coords = coords;
    }

    /// Write the values of rows `r0..r1` of the region `[lo, hi)` (rows of at most
    /// [`LEAF_POINTS`] values, y fastest) into the slab.
    fn store(&mut self, lo: [usize; 3], hi: [usize; 3], r0: usize, r1: usize, vals: &[f64]) {
        let [nx, ny, _] = self.geometry.dims;
        let m = (hi[0] - lo[0]).min(LEAF_POINTS);
        for (r, v) in (r0..r1).zip(vals.chunks_exact(m)) {
            let (j, k) = (lo[1] + r % (hi[1] - lo[1]), lo[2] + r / (hi[1] - lo[1]));
            let base = nx * (j + ny * (k - self.k0)) + lo[0];
            for (o, v) in self.out[base..base + m].iter_mut().zip(v) {
                *o = *v as f32;
            }
        }
    }
}
