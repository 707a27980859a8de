//! The box-filter tally shared by the full and the incremental push-forward (True 1992 §5.4).
//!
//! An input voxel of value `d` whose proxy box is `[lo, hi]` (output continuous-index space)
//! adds, to every output voxel `q` it overlaps, the weight
//! `w = w_z(q_z)·w_y(q_y)·w_x(q_x)` — the overlap of `[lo, hi]` with `[q − ½, q + ½]` per axis,
//! multiplied in that order — to `W_q` and `w·d` to `V_q`. Tallies live in a buffer covering
//! a [`Region`] of the output grid; the caller sizes the region so that it holds every box
//! (boxes are clamped to it only to guard that invariant).
//!
//! The per-axis overlaps are computed once per box (not once per cell), and the whole
//! product is scaled by a sign, so erasing a box (`sign = −1`) subtracts exactly the
//! values that adding it (`sign = +1`) added.

use glam::DVec3;
use volmorph_volume::Voxel;

use crate::pushforward::PushForwardStats;

mod lanes;
#[cfg(target_arch = "x86_64")]
mod lanes_x4;

pub(crate) use lanes::{MAPPED, NON_FINITE, OUTSIDE, RowBoxes, Target};

/// Boxes spanning at most this many output cells along every axis take the fast path with
/// per-axis weights in stack arrays; larger ones compute the overlaps cell by cell.
const SMALL: usize = 4;

/// One output voxel's tallies `[V, W]` (weighted value, weight).
pub(crate) trait Cell: Copy + Send + Sync {
    /// Add `wd` to `V` and `w` to `W`.
    fn add(&mut self, wd: f64, w: f64);

    /// A buffer of these cells as the vector kernels take it.
    fn lanes(buf: &mut [Self]) -> Lanes<'_>;
}

/// A tally buffer of one of the two cell types (what the vector kernels dispatch on).
pub(crate) enum Lanes<'a> {
    /// `f32` tallies (the full push-forward).
    F32(&'a mut [[f32; 2]]),
    /// `f64` tallies (the incremental engine).
    F64(&'a mut [[f64; 2]]),
}

impl Cell for [f32; 2] {
    #[inline(always)]
    fn add(&mut self, wd: f64, w: f64) {
        self[0] += wd as f32;
        self[1] += w as f32;
    }

    fn lanes(buf: &mut [Self]) -> Lanes<'_> {
        Lanes::F32(buf)
    }
}

impl Cell for [f64; 2] {
    #[inline(always)]
    fn add(&mut self, wd: f64, w: f64) {
        self[0] += wd;
        self[1] += w;
    }

    fn lanes(buf: &mut [Self]) -> Lanes<'_> {
        Lanes::F64(buf)
    }
}

/// A box of grid indices `lo .. lo + dims` (half-open per axis), x fastest in any buffer laid
/// over it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct Region {
    /// First index per axis.
    pub lo: [usize; 3],
    /// Extent per axis.
    pub dims: [usize; 3],
}

impl Region {
    /// Number of indices in the box.
    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// `true` if the box holds no index.
    pub fn is_empty(&self) -> bool {
        self.dims.contains(&0)
    }

    /// The region of output cells overlapped with positive length by the axis-aligned box
    /// `[lo, hi]` (output index space) in a grid of `dims`; empty if none (or if the bounds
    /// are empty or NaN).
    pub fn of_bounds(lo: DVec3, hi: DVec3, dims: [usize; 3]) -> Self {
        let mut r = Self::default();
        for a in 0..3 {
            if lo[a].partial_cmp(&hi[a]).is_none_or(|o| o.is_gt()) {
                return Self::default();
            }
            match cell_range(lo[a], hi[a], dims[a]) {
                Some((s, e)) => {
                    r.lo[a] = s;
                    r.dims[a] = e - s + 1;
                }
                None => return Self::default(),
            }
        }
        r
    }
}

/// Minimum of two non-NaN numbers (one `minsd`; `f64::min` also handles NaN, at a cost).
#[inline(always)]
fn fmin(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

/// Maximum of two non-NaN numbers (one `maxsd`).
#[inline(always)]
fn fmax(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// Component-wise [`fmin`].
#[inline(always)]
pub(crate) fn vmin(a: DVec3, b: DVec3) -> DVec3 {
    DVec3::new(fmin(a.x, b.x), fmin(a.y, b.y), fmin(a.z, b.z))
}

/// Component-wise [`fmax`].
#[inline(always)]
pub(crate) fn vmax(a: DVec3, b: DVec3) -> DVec3 {
    DVec3::new(fmax(a.x, b.x), fmax(a.y, b.y), fmax(a.z, b.z))
}

/// Positive overlap of `[lo, hi]` with the output voxel `[q − ½, q + ½]` (index units).
#[inline(always)]
pub(crate) fn overlap(lo: f64, hi: f64, q: usize) -> f64 {
    let c = q as f64;
    fmax(fmin(hi, c + 0.5) - fmax(lo, c - 0.5), 0.0)
}

/// Range `a..=b` of output indices in `0..n` whose cells `[q − ½, q + ½]` overlap `[lo, hi]`
/// with positive length (`a = ⌊lo + ½⌋`, `b = ⌈hi − ½⌉`, clamped), or `None` if there are
/// none. Written without `floor`/`ceil` calls: this sits in the per-voxel loop.
#[inline(always)]
pub(crate) fn cell_range(lo: f64, hi: f64, n: usize) -> Option<(usize, usize)> {
    let nf = n as f64;
    // Callers pass non-NaN bounds (finite images, or the empty fold ±∞).
    if hi <= lo || hi <= -0.5 || lo >= nf - 0.5 {
        return None;
    }
    // Truncation is the floor for positive values; here lo + ½ < n.
    let s = lo + 0.5;
    let a = if s > 0.0 { s as usize } else { 0 };
    let t = hi - 0.5;
    let b = if t <= 0.0 {
        0
    } else if t >= nf - 1.0 {
        n - 1
    } else {
        let c = t as usize;
        if (c as f64) < t { c + 1 } else { c }
    };
    Some((a, b))
}

/// Cell range of `[lo, hi]` along one axis of an output grid of `n` cells, clamped to the
/// region `[r0, r0 + rn)`; `None` if empty.
#[inline(always)]
fn axis_range(lo: f64, hi: f64, n: usize, r0: usize, rn: usize) -> Option<(usize, usize)> {
    let (a, b) = cell_range(lo, hi, n)?;
    let (a, b) = (a.max(r0), b.min((r0 + rn).checked_sub(1)?));
    (a <= b).then_some((a, b))
}

/// For a box `[lo, hi]` at most two cells long: the first cell `a = ⌊lo + ½⌋`, the
/// overlaps with cells `a`, `a + 1`, `a + 2` (zero-padded) and the number of cells with
/// positive overlap (1 to 3: a box of length at most 1 reaches 1 or 2 cells, a longer one
/// 2 or 3). Equal to [`overlap`], since `a − ½ ≤ lo < a + ½` and `hi ≤ lo + 2`.
#[inline(always)]
fn short(lo: f64, hi: f64) -> Option<(usize, [f64; 3], usize)> {
    let s = lo + 0.5;
    let len = hi - lo;
    if s >= 0.0 && len > 0.0 && len <= 2.0 && s < 1e15 {
        // Truncation is the floor for 0 ≤ s < 2⁵³. Signed conversions: one instruction
        // each, where unsigned ones take several.
        let ai = s as i64;
        let a = ai as usize;
        let e = ai as f64 + 0.5;
        // The last cell's weight is zero unless `hi` passes its lower edge; such a cell is
        // left out (see `splat` on why skipping a zero term changes no bit).
        if len <= 1.0 {
            let n = if hi > e { 2 } else { 1 };
            return Some((a, [fmin(hi, e) - lo, fmax(hi - e, 0.0), 0.0], n));
        }
        let e1 = e + 1.0;
        let n = if hi > e1 { 3 } else { 2 };
        return Some((a, [e - lo, fmin(hi, e1) - e, fmax(hi - e1, 0.0)], n));
    }
    None
}

/// The cells `a .. a + n` of a [`short`] box clipped to the region's `[r0, r0 + rn)`, and
/// whether they carry positive weight.
#[inline(always)]
fn clip((a, w, n): (usize, [f64; 3], usize), r0: usize, rn: usize) -> (usize, usize, bool) {
    let (s, e) = (a.max(r0), (a + n).min(r0 + rn));
    let positive = (s..e).any(|q| w[q - a] > 0.0);
    (s, e, positive)
}

/// One box of the fast path: buffer index of its first cell, row and plane strides of the
/// buffer, per-axis weights (x, y, z), value and sign.
struct Kernel {
    base: usize,
    sy: usize,
    sz: usize,
    w: [[f64; 3]; 3],
    d: f64,
    sign: f64,
}

impl Kernel {
    /// Add the `NX × NY × NZ` cells (`w = ((sign·w_z)·w_y)·w_x`, as the general path).
    #[inline(always)]
    fn run<C: Cell, const NX: usize, const NY: usize, const NZ: usize>(&self, buf: &mut [C]) {
        let [wx, wy, wz] = &self.w;
        for (z, &wz) in wz.iter().enumerate().take(NZ) {
            let wz = self.sign * wz;
            for (y, &wy) in wy.iter().enumerate().take(NY) {
                let wyz = wz * wy;
                let i = self.base + z * self.sz + y * self.sy;
                if let Some(cells) = buf.get_mut(i..i + NX) {
                    for (cell, &wx) in cells.iter_mut().zip(wx) {
                        let w = wyz * wx;
                        cell.add(w * self.d, w);
                    }
                }
            }
        }
    }
}

/// Per-axis overlaps of `[lo, hi]` with cells `a..=b` (at most [`SMALL`]) and their sum.
#[inline(always)]
fn small_weights(lo: f64, hi: f64, a: usize, b: usize) -> ([f64; SMALL], f64) {
    let mut w = [0.0; SMALL];
    let mut s = 0.0;
    for (q, slot) in (a..=b).zip(w.iter_mut()) {
        *slot = overlap(lo, hi, q);
        s += *slot;
    }
    (w, s)
}

/// Spread value `d` of the box `[lo, hi]` (output index space; finite) over the cells of
/// `buf`, which covers `region` of an output grid of `out` dims: `V += sign·w·d`,
/// `W += sign·w` per overlapped cell. Returns `true` if the box overlaps some output voxel
/// with positive volume.
#[inline(always)]
pub(crate) fn splat<C: Cell>(
    lo: DVec3,
    hi: DVec3,
    d: f64,
    sign: f64,
    out: [usize; 3],
    region: &Region,
    buf: &mut [C],
) -> bool {
    // Fast path: a box at most two cells long along every axis ([`splat_short`]).
    if d.is_finite()
        && let (Some(x), Some(y), Some(z)) =
            (short(lo.x, hi.x), short(lo.y, hi.y), short(lo.z, hi.z))
    {
        return splat_short([x, y, z], d, sign, region, buf);
    }
    splat_general(lo, hi, d, sign, out, region, buf)
}

/// The [`short`] per-axis cells and overlaps of one box.
type Short = (usize, [f64; 3], usize);

/// [`splat`] of a box at most two cells long along every axis (finite `d`), given its
/// per-axis [`short`] results: inside the region it covers one to three cells per axis from
/// `a = ⌊lo + ½⌋`, fully unrolled per shape. Same weights and products as the general path.
/// Cells of zero overlap are skipped: their terms are ±0, and adding ±0 to a tally changes
/// no bit, because a tally starts at +0 and a sum of rounded additions is −0 only when both
/// addends are −0, so no tally is ever −0 (the one value to which adding +0 is not the
/// identity).
#[inline(always)]
fn splat_short<C: Cell>(
    [x, y, z]: [Short; 3],
    d: f64,
    sign: f64,
    region: &Region,
    buf: &mut [C],
) -> bool {
    let [rx, ry, rz] = region.lo;
    let [dx, dy, dz] = region.dims;
    {
        let inside =
            |(a, _, n): (usize, [f64; 3], usize), r0: usize, rn: usize| a >= r0 && a + n <= r0 + rn;
        let ((xa, wx, nx), (ya, wy, ny), (za, wz, nz)) = (x, y, z);
        if inside(x, rx, dx) && inside(y, ry, dy) && inside(z, rz, dz) {
            let base = ((za - rz) * dy + (ya - ry)) * dx + (xa - rx);
            let k = Kernel {
                base,
                sy: dx,
                sz: dx * dy,
                w: [wx, wy, wz],
                d,
                sign,
            };
            macro_rules! shapes {
                ($($x:literal $y:literal $z:literal),*) => {
                    match (nx, ny, nz) {
                        $(($x, $y, $z) => k.run::<C, $x, $y, $z>(buf),)*
                        _ => k.run::<C, 3, 3, 3>(buf),
                    }
                };
            }
            shapes!(
                1 1 1, 2 1 1, 3 1 1, 1 2 1, 2 2 1, 3 2 1, 1 3 1, 2 3 1, 3 3 1,
                1 1 2, 2 1 2, 3 1 2, 1 2 2, 2 2 2, 3 2 2, 1 3 2, 2 3 2, 3 3 2,
                1 1 3, 2 1 3, 3 1 3, 1 2 3, 2 2 3, 3 2 3, 1 3 3, 2 3 3
            );
            return true;
        }
        // Partly outside the region: the same weights and products on the cells inside.
        let (xs, xe, px) = clip(x, rx, dx);
        let (ys, ye, py) = clip(y, ry, dy);
        let (zs, ze, pz) = clip(z, rz, dz);
        if xs >= xe || ys >= ye || zs >= ze {
            return false;
        }
        for qz in zs..ze {
            let wz = sign * wz[qz - za];
            for qy in ys..ye {
                let wyz = wz * wy[qy - ya];
                let row = ((qz - rz) * dy + (qy - ry)) * dx;
                let Some(cells) = buf.get_mut(row + xs - rx..row + xe - rx) else {
                    continue;
                };
                for (qx, cell) in (xs..xe).zip(cells) {
                    let w = wyz * wx[qx - xa];
                    cell.add(w * d, w);
                }
            }
        }
        px && py && pz
    }
}

/// [`splat`] of any box (finite bounds): per-axis cell ranges, overlaps cell by cell.
#[inline(always)]
fn splat_general<C: Cell>(
    lo: DVec3,
    hi: DVec3,
    d: f64,
    sign: f64,
    out: [usize; 3],
    region: &Region,
    buf: &mut [C],
) -> bool {
    let [rx, ry, rz] = region.lo;
    let [dx, dy, dz] = region.dims;
    let (Some((xa, xb)), Some((ya, yb)), Some((za, zb))) = (
        axis_range(lo.x, hi.x, out[0], rx, dx),
        axis_range(lo.y, hi.y, out[1], ry, dy),
        axis_range(lo.z, hi.z, out[2], rz, dz),
    ) else {
        return false;
    };
    if xb - xa < SMALL && yb - ya < SMALL && zb - za < SMALL {
        let (wx, sx) = small_weights(lo.x, hi.x, xa, xb);
        let (wy, sy) = small_weights(lo.y, hi.y, ya, yb);
        let (wz, sz) = small_weights(lo.z, hi.z, za, zb);
        let nx = xb - xa + 1;
        for (qz, &wz) in (za..=zb).zip(&wz) {
            let wz = sign * wz;
            for (qy, &wy) in (ya..=yb).zip(&wy) {
                let wyz = wz * wy;
                let row = ((qz - rz) * dy + (qy - ry)) * dx + (xa - rx);
                if let Some(cells) = buf.get_mut(row..row + nx) {
                    for (cell, &wx) in cells.iter_mut().zip(&wx) {
                        let w = wyz * wx;
                        cell.add(w * d, w);
                    }
                }
            }
        }
        return sx * sy * sz > 0.0;
    }
    let mut total = 0.0;
    for qz in za..=zb {
        let wz = overlap(lo.z, hi.z, qz);
        if wz <= 0.0 {
            continue;
        }
        let wz = sign * wz;
        for qy in ya..=yb {
            let wyz = wz * overlap(lo.y, hi.y, qy);
            if wyz == 0.0 {
                continue;
            }
            let row = ((qz - rz) * dy + (qy - ry)) * dx;
            let Some(cells) = buf.get_mut(row + (xa - rx)..=row + (xb - rx)) else {
                continue;
            };
            for (qx, cell) in (xa..=xb).zip(cells) {
                let w = wyz * overlap(lo.x, hi.x, qx);
                cell.add(w * d, w);
                total += w.abs();
            }
        }
    }
    total > 0.0
}

/// Bounds `(lo, hi)` of the six face-centre images of a voxel with centre image `p` and
/// neighbouring centre images `nb` (−x, +x, −y, +y, −z, +z), each face image being the mean
/// of `p` and one neighbour (True §5.4). `None` if any face image is NaN or infinite.
///
/// `min_k ½(p + c_k) = ½(p + min_k c_k)` holds exactly in floating point (rounding is
/// monotone and halving exact), so the box is bit-identical to the bounds of the six means.
#[inline(always)]
pub(crate) fn averaged_bounds(p: DVec3, nb: [DVec3; 6]) -> Option<(DVec3, DVec3)> {
    match raw_bounds(p, nb) {
        (lo, hi, true) => Some((lo, hi)),
        // A point is NaN or infinite (no box), or finite points overflowed a sum: then the
        // cheap min/max selected exactly and only the bounds themselves need checking.
        (lo, hi, false) => {
            let finite = p.is_finite() && nb.iter().all(|q| q.is_finite());
            (finite && lo.is_finite() && hi.is_finite()).then_some((lo, hi))
        }
    }
}

/// [`averaged_bounds`] for points known to be finite and small enough that no sum
/// overflows (magnitudes below about 1e307): the same bounds, without the checks. For
/// other points the result is unspecified (but no panic).
#[inline(always)]
pub(crate) fn unchecked_bounds(p: DVec3, nb: [DVec3; 6]) -> (DVec3, DVec3) {
    let mn = vmin(
        vmin(vmin(nb[0], nb[1]), vmin(nb[2], nb[3])),
        vmin(nb[4], nb[5]),
    );
    let mx = vmax(
        vmax(vmax(nb[0], nb[1]), vmax(nb[2], nb[3])),
        vmax(nb[4], nb[5]),
    );
    (0.5 * (p + mn), 0.5 * (p + mx))
}

/// [`averaged_bounds`] without branches: the bounds and `true`, or `false` when a point is
/// NaN or infinite or a sum overflows (then [`averaged_bounds`] decides).
#[inline(always)]
fn raw_bounds(p: DVec3, nb: [DVec3; 6]) -> (DVec3, DVec3, bool) {
    let s = p + nb[0] + nb[1] + nb[2] + nb[3] + nb[4] + nb[5];
    let (lo, hi) = unchecked_bounds(p, nb);
    // A finite sum means every point is finite (NaN and infinities propagate), and then the
    // cheap min/max select exactly.
    let ok = (s.x + s.y + s.z + lo.x + lo.y + lo.z + hi.x + hi.y + hi.z).is_finite();
    (lo, hi, ok)
}

/// Where a box of input voxels finds its values and centre images.
pub(crate) struct Voxels<'a, T> {
    /// Input values, x fastest, rows of `vdims[0]`, planes of `vdims[0]·vdims[1]`.
    pub values: &'a [T],
    /// Dims of the value array.
    pub vdims: [usize; 3],
    /// Centre images (output index space), x fastest, rows of `cdims[0]`, planes of
    /// `cdims[0]·cdims[1]`; every voxel's six neighbours must be present.
    pub centres: &'a [DVec3],
    /// Row and plane extents of the centre array (x and y dims).
    pub cdims: [usize; 2],
}

/// `true` if the box `[lo, hi]` (output index space, finite) overlaps some voxel of an output
/// grid of `out` dims with positive volume — exactly when [`splat`] over the whole grid
/// returns `true`.
#[inline(always)]
pub(crate) fn reaches_grid(lo: DVec3, hi: DVec3, out: [usize; 3]) -> bool {
    (0..3).all(|a| cell_range(lo[a], hi[a], out[a]).is_some())
}

/// The slices one row of input voxels reads: values, centre images with one extra on each
/// side in x (`centres[n + 1]` is voxel `n`'s), and the −y, +y, −z, +z neighbours' rows.
pub(crate) struct Row<'a, T> {
    /// Value-array index of the row's first voxel.
    pub first: usize,
    /// The row's values.
    pub values: &'a [T],
    /// Centre images of the row widened by one in x.
    pub centres: &'a [DVec3],
    /// Centre images of the rows at −y, +y, −z, +z.
    pub ym: &'a [DVec3],
    /// See [`Row::ym`].
    pub yp: &'a [DVec3],
    /// See [`Row::ym`].
    pub zm: &'a [DVec3],
    /// See [`Row::ym`].
    pub zp: &'a [DVec3],
}

impl<T> Row<'_, T> {
    /// Per voxel of the row: its value, centre image and the six neighbours' (−x, +x, −y,
    /// +y, −z, +z).
    #[inline(always)]
    fn stencils(&self) -> impl Iterator<Item = (&T, DVec3, [DVec3; 6])> {
        self.centres
            .windows(3)
            .zip(self.values)
            .zip(self.ym.iter().zip(self.yp))
            .zip(self.zm.iter().zip(self.zp))
            .map(
                #[inline(always)]
                |(((w, v), (ym, yp)), (zm, zp))| (v, w[1], [w[0], w[2], *ym, *yp, *zm, *zp]),
            )
    }

    /// Voxel `n`'s centre image and its six neighbours' (−x, +x, −y, +y, −z, +z), if the
    /// row holds them.
    #[inline(always)]
    pub fn stencil(&self, n: usize) -> Option<(DVec3, [DVec3; 6])> {
        let c = self.centres.get(n..n + 3)?;
        let nb = [
            c[0],
            c[2],
            *self.ym.get(n)?,
            *self.yp.get(n)?,
            *self.zm.get(n)?,
            *self.zp.get(n)?,
        ];
        Some((c[1], nb))
    }

    /// Per voxel of the row: its value and proxy box ([`averaged_bounds`]).
    #[inline(always)]
    pub fn boxes(&self) -> impl Iterator<Item = (&T, Option<(DVec3, DVec3)>)> {
        self.stencils().map(
            #[inline(always)]
            |(v, p, nb)| (v, averaged_bounds(p, nb)),
        )
    }
}

/// Row `(dj, dk)` of the input voxels of `vbox` (value-array indices), whose centre images
/// sit at centre-array index `c0 + (voxel − vbox.lo)`; `None` (unreachable for the
/// callers' layouts) if a slice falls outside the arrays.
#[inline(always)]
pub(crate) fn row<'a, T>(
    src: &Voxels<'a, T>,
    vbox: &Region,
    c0: [usize; 3],
    dj: usize,
    dk: usize,
) -> Option<Row<'a, T>> {
    let [vx, vy, _] = src.vdims;
    let [sy, _] = src.cdims;
    let sz = src.cdims[0] * src.cdims[1];
    let nx = vbox.dims[0];
    let c = src.centres;
    let v0 = vbox.lo[0] + vx * (vbox.lo[1] + dj + vy * (vbox.lo[2] + dk));
    // Centre index of the row's first voxel; its −x neighbour is one before.
    let n0 = c0[0] + sy * (c0[1] + dj) + sz * (c0[2] + dk);
    let (ym, zm) = (n0.checked_sub(sy)?, n0.checked_sub(sz)?);
    Some(Row {
        first: v0,
        values: src.values.get(v0..v0 + nx)?,
        centres: c.get(n0.checked_sub(1)?..n0 + nx + 1)?,
        ym: c.get(ym..ym + nx)?,
        yp: c.get(n0 + sy..n0 + sy + nx)?,
        zm: c.get(zm..zm + nx)?,
        zp: c.get(n0 + sz..n0 + sz + nx)?,
    })
}

/// Tally (with `sign`) the boxes of the input voxels in `vbox` (value-array indices), whose
/// centre images sit at centre-array index `c0 + (voxel − vbox.lo)`, with True's averaged
/// face centres, into `buf` over `region` of an output grid of `out` dims.
///
/// Row by row through [`RowBoxes`] (AVX2 kernels where the CPU has them, chosen at run
/// time); the same bits as [`averaged_bounds`] and [`splat`] voxel by voxel in index order.
pub(crate) fn tally_averaged<'a, T: Voxel, C: Cell>(
    src: &Voxels<'a, T>,
    vbox: &Region,
    c0: [usize; 3],
    out: [usize; 3],
    region: &Region,
    buf: &mut [C],
    sign: f64,
) -> PushForwardStats {
    let mut stats = PushForwardStats::default();
    let mut boxes = RowBoxes::default();
    for dk in 0..vbox.dims[2] {
        for dj in 0..vbox.dims[1] {
            let Some(row) = row(src, vbox, c0, dj, dk) else {
                // Count the row as non-finite rather than panic.
                stats.non_finite += vbox.dims[0];
                continue;
            };
            boxes.tally(&row, Target { sign, out, region }, buf);
            let mut counts = [0usize; 3];
            for &o in boxes.outcomes() {
                counts[usize::from(o.min(NON_FINITE))] += 1;
            }
            stats.mapped += counts[usize::from(MAPPED)];
            stats.outside += counts[usize::from(OUTSIDE)];
            stats.non_finite += counts[usize::from(NON_FINITE)];
        }
    }
    stats
}

/// The face-centre images (output index space) of a box of input voxels of `dims`: `x` on
/// `(dims₀ + 1) × dims₁ × dims₂` points (voxel `i` has x-faces `i` and `i + 1`), `y` on
/// `dims₀ × (dims₁ + 1) × dims₂`, `z` on `dims₀ × dims₁ × (dims₂ + 1)`, x fastest.
pub(crate) struct FaceImages<'a> {
    /// Images of the faces normal to x.
    pub x: &'a [DVec3],
    /// Images of the faces normal to y.
    pub y: &'a [DVec3],
    /// Images of the faces normal to z.
    pub z: &'a [DVec3],
    /// Voxels of the box per axis.
    pub dims: [usize; 3],
}

impl FaceImages<'_> {
    /// The proxy box of voxel `(i, j, k)` of the box: the bounds of its six face images, or
    /// `None` if one is NaN or infinite (or lies outside the arrays).
    #[inline(always)]
    pub fn bounds(&self, i: usize, j: usize, k: usize) -> Option<(DVec3, DVec3)> {
        let [nx, ny, _] = self.dims;
        let bx = (nx + 1) * (j + ny * k) + i;
        let by = nx * (j + (ny + 1) * k) + i;
        let bz = nx * (j + ny * k) + i;
        let pts = [
            *self.x.get(bx)?,
            *self.x.get(bx + 1)?,
            *self.y.get(by)?,
            *self.y.get(by + nx)?,
            *self.z.get(bz)?,
            *self.z.get(bz + nx * ny)?,
        ];
        if !pts.iter().all(|p| p.is_finite()) {
            return None;
        }
        Some(
            pts[1..]
                .iter()
                .fold((pts[0], pts[0]), |(lo, hi), p| (lo.min(*p), hi.max(*p))),
        )
    }
}

/// Tally the boxes of the input voxels in `vbox` (value-array indices into `values` of
/// `vdims`) whose face images are `faces` (over `vbox`'s voxels), in index order, into `buf`
/// over `region` of an output grid of `out` dims (the mapped face centres of
/// [`FaceCentres::Mapped`](crate::pushforward::FaceCentres::Mapped)).
pub(crate) fn tally_mapped<T: Voxel, C: Cell>(
    values: &[T],
    vdims: [usize; 3],
    vbox: &Region,
    faces: &FaceImages<'_>,
    out: [usize; 3],
    region: &Region,
    buf: &mut [C],
) -> PushForwardStats {
    let mut stats = PushForwardStats::default();
    let [vx, vy, _] = vdims;
    for k in 0..vbox.dims[2] {
        for j in 0..vbox.dims[1] {
            let first = vbox.lo[0] + vx * (vbox.lo[1] + j + vy * (vbox.lo[2] + k));
            for i in 0..vbox.dims[0] {
                let (Some(v), Some((lo, hi))) = (values.get(first + i), faces.bounds(i, j, k))
                else {
                    stats.non_finite += 1;
                    continue;
                };
                if splat(lo, hi, v.to_f64(), 1.0, out, region, buf) {
                    stats.mapped += 1;
                } else {
                    stats.outside += 1;
                }
            }
        }
    }
    stats
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression: a short box beside the region along x (but across it along y and z)
    /// made the clipped path compute an index below zero.
    #[test]
    fn short_box_beside_the_region_touches_nothing() {
        let region = Region {
            lo: [4, 0, 0],
            dims: [4, 4, 4],
        };
        let mut buf = vec![[0.0f64; 2]; region.len()];
        let (lo, hi) = (DVec3::new(0.7, -0.3, -0.3), DVec3::new(1.6, 0.6, 0.6));
        assert!(!splat(lo, hi, 5.0, 1.0, [8, 4, 4], &region, &mut buf));
        assert!(buf.iter().all(|c| *c == [0.0, 0.0]));
        // Shifted to straddle the region's edge: only the overlap with cell 4 ([3.5, 4.5]),
        // 4.1 − 3.5 = 0.6, lands (cell 3 lies outside); y and z are inside.
        let (lo, hi) = (lo + DVec3::X * 2.5, hi + DVec3::X * 2.5);
        assert!(splat(lo, hi, 5.0, 1.0, [8, 4, 4], &region, &mut buf));
        let total: f64 = buf.iter().map(|c| c[1]).sum();
        assert!((total - 0.6 * 0.9 * 0.9).abs() < 1e-12, "{total}");
        assert!(buf.iter().all(|c| (c[0] - 5.0 * c[1]).abs() < 1e-12));
    }
}
