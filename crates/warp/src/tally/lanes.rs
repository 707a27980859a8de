//! The proxy boxes of a row of source voxels and their tally, computed over the row in
//! vector lanes (True 1992 §5.4; the box filter of [`super`]).
//!
//! A row is done in two passes over flat coordinates (three per voxel, x, y, z), each
//! coordinate `m` through the same IEEE operations in the same order as the per-voxel path
//! ([`super::unchecked_bounds`], then [`super::short`]), so the bits are theirs:
//!
//! 1. **Boxes** ([`fill`]): the min and max of the six neighbouring centre images, the box
//!    `[lo, hi]`, the first cell `a = ⌊lo + ½⌋` and the overlaps with cells `a` and `a + 1`,
//!    and, where the box is at most two cells long on that axis, holds only finite points
//!    and its two cells lie inside the tally region, the coordinate's share
//!    `(a − r₀)·stride` of the buffer index of the box's first cell (NaN otherwise).
//! 2. **Tally** ([`tally`]): per voxel, the three shares add up to the buffer index of its
//!    first cell (NaN if one axis did not fit); such a voxel adds its 2 × 2 × 2 cells with
//!    no branch on its shape (a cell beyond the box gets the weight +0, and adding ±0 to a
//!    tally changes no bit: see [`super::splat_short`]). A voxel whose box is short and
//!    finite on every axis and has no cell in the region on one of them (its share −∞, so
//!    the sum is −∞) is [`OUTSIDE`] at once: the per-voxel path would find the same box,
//!    take [`super::splat_short`], clip that axis to nothing and add nothing. Such voxels
//!    are common where a recomputed region cuts through a run of blocks (a quarter of the
//!    voxels a drag of the teapot's spout tallies went the per-voxel path, half of them
//!    only to find they were outside). Every other voxel takes the per-voxel path
//!    ([`super::averaged_bounds`], [`super::splat`]) unchanged.
//!
//! Each voxel still adds to each cell at most once, voxels in row order, so every cell sums
//! its contributions in the order the per-voxel path does.
//!
//! Both passes exist in two forms with the same bits: the portable loops here (compiled
//! for whatever target the caller is) and AVX2 kernels (`lanes_x4`, four coordinates per
//! register, chosen at run time).

use volmorph_volume::Voxel;

use super::{Cell, Kernel, Region, Row, averaged_bounds, fmax, fmin, splat};

/// What a source voxel's proxy box did: it overlapped some output voxel of the grid with
/// positive volume.
pub(crate) const MAPPED: u8 = 0;
/// See [`MAPPED`]: the box overlaps no output voxel.
pub(crate) const OUTSIDE: u8 = 1;
/// See [`MAPPED`]: a face-centre image is NaN or infinite (no box).
pub(crate) const NON_FINITE: u8 = 2;

/// Where the tally region lies along each axis, for the boxes pass: a box fits along axis
/// `a` when its two cells `first, first + 1` satisfy `r0[a] ≤ first ≤ last[a]`; its share
/// of the buffer index is then `(first − r0[a])·stride[a]`. All values are integers below
/// 2⁵³, so every product and sum of shares is exact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Fit {
    /// First region index per axis.
    pub r0: [f64; 3],
    /// Largest first cell per axis whose second cell is still in the region
    /// (`r0 + dims − 2`; below `r0` when the region is one cell thin).
    pub last: [f64; 3],
    /// Buffer strides per axis (1, row, plane).
    pub stride: [f64; 3],
}

impl Fit {
    /// The fit of boxes to `region`, laid out x fastest.
    pub fn of(region: &Region) -> Self {
        let [dx, dy, _] = region.dims;
        Self {
            r0: region.lo.map(|v| v as f64),
            last: [0, 1, 2].map(|a| region.lo[a] as f64 + region.dims[a] as f64 - 2.0),
            stride: [1.0, dx as f64, (dx * dy) as f64],
        }
    }
}

/// Where a row's boxes are tallied: with `sign`, into a buffer over `region` of an output
/// grid of `out` dims (as [`splat`] takes them).
#[derive(Clone, Copy)]
pub(crate) struct Target<'a> {
    /// +1 to add the boxes, −1 to erase them.
    pub sign: f64,
    /// Dims of the output grid.
    pub out: [usize; 3],
    /// The region of the output grid the buffer covers.
    pub region: &'a Region,
}

/// One row's work: the row, its flat coordinates, the fit of its boxes to the region and
/// where they are tallied.
pub(crate) struct Job<'a, 'r, T> {
    /// The row of voxels.
    pub row: &'a Row<'r, T>,
    /// Its flat coordinates.
    pub flat: Flat<'a>,
    /// [`Fit::of`] the target's region.
    pub fit: Fit,
    /// Where the boxes go.
    pub target: Target<'a>,
}

/// The flat coordinates one row of voxels reads (`n3` = three per voxel): centre images
/// widened by one voxel in x (`c[m + 3]` is coordinate `m`'s centre, `c[m]` and `c[m + 6]`
/// its −x and +x neighbours) and the −y, +y, −z, +z neighbours' rows.
#[derive(Clone, Copy)]
pub(crate) struct Flat<'a> {
    /// Centre images of the row widened by one in x (`n3 + 6` coordinates).
    pub c: &'a [f64],
    /// The −y neighbours (`n3`).
    pub ym: &'a [f64],
    /// The +y neighbours.
    pub yp: &'a [f64],
    /// The −z neighbours.
    pub zm: &'a [f64],
    /// The +z neighbours.
    pub zp: &'a [f64],
}

impl<'a> Flat<'a> {
    /// The flat coordinates of `row`, or `None` if a slice is shorter than the row needs
    /// (unreachable for rows built by [`super::row`]).
    pub fn of<T>(row: &Row<'a, T>) -> Option<Self> {
        let n3 = 3 * row.values.len();
        let flat = |p: &'a [glam::DVec3], len: usize| -> Option<&'a [f64]> {
            let f: &[f64] = bytemuck::cast_slice(p);
            f.get(..len)
        };
        Some(Self {
            c: flat(row.centres, n3 + 6)?,
            ym: flat(row.ym, n3)?,
            yp: flat(row.yp, n3)?,
            zm: flat(row.zm, n3)?,
            zp: flat(row.zp, n3)?,
        })
    }
}

/// What the boxes pass writes, per flat coordinate `m` (the slices are `n3` long, `w01`
/// `2·n3`).
pub(crate) struct Boxes<'a> {
    /// Box lower bounds.
    pub lo: &'a mut [f64],
    /// Overlaps with cells `a` and `a + 1`, interleaved (`w01[2m]`, `w01[2m + 1]`).
    pub w01: &'a mut [f64],
    /// The coordinate's share of the buffer index of the box's first cell; −∞ where the
    /// box is short and finite but has no cell in the region on this axis; NaN where it
    /// takes neither the two-cell path nor that exit on this axis.
    pub share: &'a mut [f64],
}

/// The boxes pass for coordinate `m` (see the [module docs](self)); `axis = m % 3`.
/// Requires `m < n3` for slices of the lengths [`Flat`] and [`Boxes`] state.
#[inline(always)]
pub(crate) fn fill_one(f: &Flat<'_>, fit: &Fit, m: usize, axis: usize, out: &mut Boxes<'_>) {
    let (cm, cp, p) = (f.c[m], f.c[m + 6], f.c[m + 3]);
    let (ym, yp, zm, zp) = (f.ym[m], f.yp[m], f.zm[m], f.zp[m]);
    // As `unchecked_bounds`: the neighbours (−x, +x, −y, +y, −z, +z) paired.
    let mn = fmin(fmin(fmin(cm, cp), fmin(ym, yp)), fmin(zm, zp));
    let mx = fmax(fmax(fmax(cm, cp), fmax(ym, yp)), fmax(zm, zp));
    let l = 0.5 * (p + mn);
    let h = 0.5 * (p + mx);
    // A finite sum of the seven points means every one is finite.
    let t = p + cm + cp + ym + yp + zm + zp;
    // As `short`, both of its cases computed and one selected.
    let s = l + 0.5;
    let len = h - l;
    let ok = s >= 0.0 && len > 0.0 && len <= 2.0 && s < 1e15;
    let a = s.trunc();
    let e = a + 0.5;
    let e1 = e + 1.0;
    let one = len <= 1.0;
    let v0 = if one { fmin(h, e) - l } else { e - l };
    let v1 = if one {
        fmax(h - e, 0.0)
    } else {
        fmin(h, e1) - e
    };
    // At most two cells: a box longer than one cell reaches a third cell past `e1`.
    let two = one || h <= e1;
    let fits = ok && two && a >= fit.r0[axis] && a <= fit.last[axis] && t.is_finite();
    // The box's last cell, as `short` counts its cells (`a + n − 1`).
    let last_cell = if one {
        a + if h > e { 1.0 } else { 0.0 }
    } else {
        a + if h > e1 { 2.0 } else { 1.0 }
    };
    let outside = ok && t.is_finite() && (last_cell < fit.r0[axis] || a > fit.last[axis] + 1.0);
    out.lo[m] = l;
    out.w01[2 * m] = v0;
    out.w01[2 * m + 1] = v1;
    out.share[m] = if fits {
        (a - fit.r0[axis]) * fit.stride[axis]
    } else if outside {
        f64::NEG_INFINITY
    } else {
        f64::NAN
    };
}

/// The boxes pass over the row (portable loop).
pub(crate) fn fill(f: &Flat<'_>, fit: &Fit, out: &mut Boxes<'_>) {
    for m in 0..out.lo.len() {
        fill_one(f, fit, m, m % 3, out);
    }
}

/// The per-voxel path for voxel `n` of `row` (one that did not fit the two-cell path): its
/// box from the stencil ([`averaged_bounds`]), tallied by [`splat`].
#[inline(always)]
fn one_voxel<T, C: Cell>(row: &Row<'_, T>, n: usize, d: f64, t: &Target<'_>, buf: &mut [C]) -> u8 {
    match row.stencil(n).and_then(|(p, nb)| averaged_bounds(p, nb)) {
        None => NON_FINITE,
        Some((lo, hi)) if splat(lo, hi, d, t.sign, t.out, t.region, buf) => MAPPED,
        Some(_) => OUTSIDE,
    }
}

/// How voxel `n` (value `d`) is tallied, read from its three shares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Path {
    /// The two-cell path, from this buffer index of its first cell.
    TwoCells(usize),
    /// [`OUTSIDE`] with nothing to add: every axis is short and finite and one lies wholly
    /// outside the region (a −∞ share; the sum is −∞ only when no share is NaN).
    Outside,
    /// The per-voxel path.
    Voxel,
}

/// The [`Path`] of voxel `n` with value `d`, from its three shares. A non-finite `d` takes
/// the per-voxel path (whose general branch handles it), as [`splat`] does.
#[inline(always)]
pub(crate) fn path_of(share: &[f64], n: usize, d: f64) -> Path {
    let Some(s) = share.get(3 * n..3 * n + 3) else {
        return Path::Voxel;
    };
    let base = s[0] + s[1] + s[2];
    if !d.is_finite() {
        Path::Voxel
    } else if base >= 0.0 {
        Path::TwoCells(base as usize)
    } else if base == f64::NEG_INFINITY {
        Path::Outside
    } else {
        Path::Voxel
    }
}

/// The tally pass over `row`'s voxels in order, each outcome ([`MAPPED`], [`OUTSIDE`],
/// [`NON_FINITE`]) written to `outcome`, by its [`path_of`]: a voxel with a buffer index goes
/// to `two_cells(buf, n, base, d)` (its 2 × 2 × 2 cells), one known to lie outside the
/// region is [`OUTSIDE`] at once, any other takes the per-voxel path.
#[inline(always)]
pub(crate) fn each_voxel<T: Voxel, C: Cell>(
    row: &Row<'_, T>,
    share: &[f64],
    t: &Target<'_>,
    buf: &mut [C],
    outcome: &mut [u8],
    mut two_cells: impl FnMut(&mut [C], usize, usize, f64),
) {
    for (n, (v, o)) in row.values.iter().zip(outcome.iter_mut()).enumerate() {
        let d = v.to_f64();
        *o = match path_of(share, n, d) {
            Path::TwoCells(base) => {
                two_cells(buf, n, base, d);
                MAPPED
            }
            Path::Outside => OUTSIDE,
            Path::Voxel => one_voxel(row, n, d, t, buf),
        };
    }
}

/// The tally pass (portable loop): the two-cell voxels through [`Kernel::run`] with the
/// third cell's weights zero.
fn tally<T: Voxel, C: Cell>(
    row: &Row<'_, T>,
    w01: &[f64],
    share: &[f64],
    t: &Target<'_>,
    buf: &mut [C],
    outcome: &mut [u8],
) {
    let [dx, dy, _] = t.region.dims;
    each_voxel(row, share, t, buf, outcome, |buf, n, base, d| {
        if let Some(w) = w01.get(6 * n..6 * n + 6) {
            let k = Kernel {
                base,
                sy: dx,
                sz: dx * dy,
                w: [[w[0], w[1], 0.0], [w[2], w[3], 0.0], [w[4], w[5], 0.0]],
                d,
                sign: t.sign,
            };
            k.run::<C, 2, 2, 2>(buf);
        }
    });
}

/// Whether the CPU runs the AVX2 kernels.
pub(crate) fn vector_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    return super::lanes_x4::available();
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// The working rows of the two passes, kept between rows (and the outcomes of the last
/// row tallied).
#[derive(Debug, Default)]
pub(crate) struct RowBoxes {
    /// Box lower bounds, three per voxel.
    lo: Vec<f64>,
    /// Overlaps with a box's first two cells per axis, six per voxel.
    w01: Vec<f64>,
    /// Shares of the first cell's buffer index, three per voxel.
    share: Vec<f64>,
    /// Per voxel: [`MAPPED`], [`OUTSIDE`] or [`NON_FINITE`].
    outcome: Vec<u8>,
}

impl RowBoxes {
    /// Tally the boxes of `row`'s voxels into `buf` as `target` says, in vector lanes where
    /// the CPU has AVX2 (see the [module docs](self)); afterwards [`RowBoxes::outcomes`]
    /// tells what each voxel did. The same bits as [`averaged_bounds`] and [`splat`] voxel
    /// by voxel.
    pub fn tally<T: Voxel, C: Cell>(
        &mut self,
        row: &Row<'_, T>,
        target: Target<'_>,
        buf: &mut [C],
    ) {
        self.tally_with(row, target, buf, vector_available());
    }

    /// [`RowBoxes::tally`] with the AVX2 kernels (`vector`, which requires
    /// [`vector_available`]) or the portable loops.
    pub(crate) fn tally_with<T: Voxel, C: Cell>(
        &mut self,
        row: &Row<'_, T>,
        target: Target<'_>,
        buf: &mut [C],
        vector: bool,
    ) {
        let n = row.values.len();
        let n3 = 3 * n;
        for (v, len) in [
            (&mut self.lo, n3),
            (&mut self.w01, 2 * n3),
            (&mut self.share, n3),
        ] {
            v.resize(len, 0.0);
        }
        self.outcome.resize(n, NON_FINITE);
        let mut boxes = Boxes {
            lo: &mut self.lo,
            w01: &mut self.w01,
            share: &mut self.share,
        };
        let Some(flat) = Flat::of(row) else {
            // Unreachable for rows built by `super::row`: every voxel takes the per-voxel
            // path, which finds no stencil.
            boxes.share.fill(f64::NAN);
            tally(row, boxes.w01, boxes.share, &target, buf, &mut self.outcome);
            return;
        };
        let job = Job {
            row,
            flat,
            fit: Fit::of(target.region),
            target,
        };
        #[cfg(target_arch = "x86_64")]
        if vector {
            super::lanes_x4::run(&job, &mut boxes, C::lanes(buf), &mut self.outcome);
            return;
        }
        let _ = vector;
        fill(&job.flat, &job.fit, &mut boxes);
        tally(row, boxes.w01, boxes.share, &target, buf, &mut self.outcome);
    }

    /// What each voxel of the last row tallied did ([`MAPPED`], [`OUTSIDE`],
    /// [`NON_FINITE`]).
    pub fn outcomes(&self) -> &[u8] {
        &self.outcome
    }

    /// The z lower bound of voxel `n`'s box in the last row tallied (meaningful where it
    /// was [`MAPPED`]).
    pub fn lo_z(&self, n: usize) -> f64 {
        self.lo.get(3 * n + 2).copied().unwrap_or(f64::NAN)
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use volmorph_testkit::Rng;

    use super::*;

    /// Same bits, or both NaN.
    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// A cell type whose buffers the test compares bit for bit.
    trait Bits: Cell + Default {
        fn bits(&self) -> [f64; 2];
        fn start(v: f64, w: f64) -> Self;
    }

    impl Bits for [f32; 2] {
        fn bits(&self) -> [f64; 2] {
            self.map(f64::from)
        }
        fn start(v: f64, w: f64) -> Self {
            [v as f32, w as f32]
        }
    }

    impl Bits for [f64; 2] {
        fn bits(&self) -> [f64; 2] {
            *self
        }
        fn start(v: f64, w: f64) -> Self {
            [v, w]
        }
    }

    /// Owned slices of one row (see [`Row`]).
    struct RowData {
        values: Vec<f32>,
        centres: Vec<DVec3>,
        ym: Vec<DVec3>,
        yp: Vec<DVec3>,
        zm: Vec<DVec3>,
        zp: Vec<DVec3>,
    }

    impl RowData {
        fn row(&self) -> Row<'_, f32> {
            Row {
                first: 0,
                values: &self.values,
                centres: &self.centres,
                ym: &self.ym,
                yp: &self.yp,
                zm: &self.zm,
                zp: &self.zp,
            }
        }
    }

    /// A row of `n` voxels whose centre images run along x from `start` with spacing
    /// `step` (plus jitter `jitter`), its neighbour rows one output cell away, and values;
    /// `edge` plants special coordinates (NaN, infinities, huge magnitudes, exact half and
    /// whole cells, −0).
    fn random_row(
        rng: &mut Rng,
        n: usize,
        start: DVec3,
        step: f64,
        jitter: f64,
        edge: bool,
    ) -> RowData {
        let pt = |c: DVec3, rng: &mut Rng| c + rng.point(jitter);
        let centre = |i: f64| start + DVec3::X * step * i;
        let centres: Vec<DVec3> = (0..n + 2)
            .map(|i| pt(centre(i as f64 - 1.0), rng))
            .collect();
        let side = |d: DVec3, rng: &mut Rng| -> Vec<DVec3> {
            (0..n).map(|i| pt(centre(i as f64) + d, rng)).collect()
        };
        let mut row = RowData {
            values: (0..n).map(|_| rng.range(-3.0, 250.0) as f32).collect(),
            ym: side(-DVec3::Y * step, rng),
            yp: side(DVec3::Y * step, rng),
            zm: side(-DVec3::Z * step, rng),
            zp: side(DVec3::Z * step, rng),
            centres,
        };
        if edge {
            let specials = [
                f64::NAN,
                f64::INFINITY,
                f64::NEG_INFINITY,
                1e308,
                -1e308,
                1e300,
                -0.0,
                0.5,
                1.5,
                2.0,
                -0.5,
                4.5,
                1e16,
            ];
            for _ in 0..(n / 3).max(1) {
                let v = specials[rng.index(specials.len())];
                let a = rng.index(3);
                let slot = match rng.index(6) {
                    0 => &mut row.centres[rng.index(n + 2)],
                    1 => &mut row.ym[rng.index(n)],
                    2 => &mut row.yp[rng.index(n)],
                    3 => &mut row.zm[rng.index(n)],
                    4 => &mut row.zp[rng.index(n)],
                    _ => {
                        // A whole voxel on exact cell edges, or a non-finite value.
                        let i = rng.index(n);
                        row.values[i] = [f32::NAN, f32::INFINITY, 0.0, -0.0][rng.index(4)];
                        continue;
                    }
                };
                slot[a] = v;
            }
        }
        row
    }

    /// The tally buffer of `region` with random non-negative starting tallies (a tally is
    /// never −0).
    fn start_buffer<C: Bits>(rng: &mut Rng, region: &Region) -> Vec<C> {
        (0..region.len())
            .map(|_| {
                if rng.chance(0.3) {
                    C::start(0.0, 0.0)
                } else {
                    C::start(rng.range(0.0, 100.0), rng.range(0.0, 3.0))
                }
            })
            .collect()
    }

    /// The per-voxel path the lanes must reproduce: each voxel's [`averaged_bounds`] and
    /// [`splat`] in row order.
    fn reference<C: Cell>(
        row: &Row<'_, f32>,
        sign: f64,
        out: [usize; 3],
        region: &Region,
        buf: &mut [C],
    ) -> Vec<(u8, f64)> {
        (0..row.values.len())
            .map(|n| {
                let d = row.values[n].to_f64();
                match row.stencil(n).and_then(|(p, nb)| averaged_bounds(p, nb)) {
                    None => (NON_FINITE, f64::NAN),
                    Some((lo, hi)) if splat(lo, hi, d, sign, out, region, buf) => (MAPPED, lo.z),
                    Some(_) => (OUTSIDE, f64::NAN),
                }
            })
            .collect()
    }

    fn check_rows<C: Bits>(seed: u64, vector: bool) {
        let mut rng = Rng::new(seed);
        let out = [20, 9, 8];
        let regions = [
            Region {
                lo: [0, 0, 0],
                dims: out,
            },
            Region {
                lo: [3, 2, 1],
                dims: [12, 4, 5],
            },
            Region {
                lo: [5, 4, 3],
                dims: [1, 1, 2],
            },
        ];
        let mut boxes = RowBoxes::default();
        let (mut two_cell, mut outside) = (0, 0);
        for case in 0..600 {
            let n = 1 + rng.index(30);
            let start = rng.point_in(DVec3::new(-2.0, -1.5, -1.5), DVec3::new(8.0, 9.5, 8.5));
            // Near-identity, squeezed and stretched rows (boxes of 1–3 cells per axis).
            let step = [1.0, 0.6, 1.3, 2.2][case % 4];
            let jitter = [0.0, 0.05, 0.3][rng.index(3)];
            let data = random_row(&mut rng, n, start, step, jitter, case % 5 == 4);
            let row = data.row();
            let region = regions[rng.index(regions.len())];
            let sign = if rng.chance(0.2) { -1.0 } else { 1.0 };
            let first: Vec<C> = start_buffer(&mut rng, &region);
            let mut want = first.clone();
            let expected = reference(&row, sign, out, &region, &mut want);
            let mut got = first;
            let target = Target {
                sign,
                out,
                region: &region,
            };
            boxes.tally_with(&row, target, &mut got, vector);
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                let (g, w) = (g.bits(), w.bits());
                assert!(
                    same(g[0], w[0]) && same(g[1], w[1]),
                    "case {case} cell {i}: {g:?} vs {w:?}"
                );
            }
            for (k, &(o, lo_z)) in expected.iter().enumerate() {
                assert_eq!(boxes.outcomes()[k], o, "case {case} voxel {k}");
                if o == MAPPED {
                    assert!(same(boxes.lo_z(k), lo_z), "case {case} voxel {k}");
                }
            }
            two_cell += (0..n)
                .filter(|&k| matches!(path_of(&boxes.share, k, 1.0), Path::TwoCells(_)))
                .count();
            outside += (0..n)
                .filter(|&k| path_of(&boxes.share, k, 1.0) == Path::Outside)
                .count();
        }
        // The two-cell path and the early exit outside the region are taken (and so
        // tested) often.
        assert!(two_cell > 500, "{two_cell} voxels on the two-cell path");
        assert!(outside > 500, "{outside} voxels known outside at once");
    }

    /// The portable loops and (where the CPU has AVX2) the AVX2 kernels reproduce the
    /// per-voxel box filter bit for bit (cells and outcomes), `f32` and `f64` tallies, on
    /// random rows and rows with non-finite, overflowing, huge and exactly cell-aligned
    /// coordinates, in and at the edges of the tally region.
    #[test]
    fn lanes_match_the_voxel_path() {
        for (seed, v) in [(11, false), (21, true)] {
            if v && !vector_available() {
                continue;
            }
            check_rows::<[f32; 2]>(seed, v);
            check_rows::<[f64; 2]>(seed + 1, v);
        }
    }

    /// The AVX2 boxes pass writes the portable pass's bits, coordinate by coordinate (also
    /// the tail of fewer than twelve coordinates and the NaN shares).
    #[test]
    fn vector_boxes_pass_matches_the_portable_pass() {
        #[cfg(target_arch = "x86_64")]
        if super::super::lanes_x4::available() {
            let mut rng = Rng::new(31);
            let region = Region {
                lo: [1, 0, 2],
                dims: [14, 8, 5],
            };
            let fit = Fit::of(&region);
            for case in 0..300 {
                let n = 1 + rng.index(40);
                let step = [1.0, 0.7, 1.6][case % 3];
                let start = rng.point(3.0) + 4.0;
                let data = random_row(&mut rng, n, start, step, 0.2, case % 3 == 0);
                let row = data.row();
                let flat = Flat::of(&row).unwrap();
                let run = |vector: bool| {
                    let (mut lo, mut w01, mut share) =
                        (vec![0.0; 3 * n], vec![0.0; 6 * n], vec![0.0; 3 * n]);
                    let mut b = Boxes {
                        lo: &mut lo,
                        w01: &mut w01,
                        share: &mut share,
                    };
                    if vector {
                        let mut buf = vec![[0.0f64; 2]; region.len()];
                        let mut outcome = vec![0; n];
                        let job = Job {
                            row: &row,
                            flat,
                            fit,
                            target: Target {
                                sign: 1.0,
                                out: [20, 9, 8],
                                region: &region,
                            },
                        };
                        let lanes = Cell::lanes(&mut buf[..]);
                        super::super::lanes_x4::run(&job, &mut b, lanes, &mut outcome);
                    } else {
                        fill(&flat, &fit, &mut b);
                    }
                    (lo, w01, share)
                };
                let (a, b) = (run(false), run(true));
                for (x, y) in [(&a.0, &b.0), (&a.1, &b.1), (&a.2, &b.2)] {
                    for (m, (x, y)) in x.iter().zip(y).enumerate() {
                        assert!(same(*x, *y), "case {case} coordinate {m}: {x} vs {y}");
                    }
                }
            }
        }
    }
}
