//! Partial-volume smoothing of a region of the tri-dexel (McPhail §3.4.2).
//!
//! 1. **Partial volumes.** The solid fraction of each grid cell is estimated from the exact
//!    solid length along its twelve edges (each edge lies on a dexel ray); the partial volume
//!    of a grid point is the mean fraction of its eight cells, i.e. of the unit cube centred
//!    on it. Its ½ level follows the surface (exactly so for axis-aligned planes) and it
//!    changes continuously as the surface moves, which makes the smoothing independent of
//!    where the surface sits in the grid — the reason the thesis prefers it to convolving
//!    the rays' step functions.
//! 2. **Smoothing.** The partial volumes are averaged over a `(2k + 1)³` box kernel (k the
//!    user's kernel size in cells, applied separably).
//! 3. **Blending.** Inside the user's box the smoothed volume is used; over the next `3k`
//!    cells it is blended linearly with the unsmoothed one by the distance to the box, so
//!    the smoothed surface joins the untouched one gradually.
//! 4. **New Hermite data.** Along every dexel ray crossing the blended region the crossings
//!    are replaced by the ½-crossings of the blended volume (linear interpolation between
//!    grid points), with normals from the volume's Sobel gradient. The replaced stretch of
//!    each ray is widened until the volume agrees with the ray's own classification at both
//!    ends, so the ray is continuous where new and original crossings meet.
//!
//! Work is bounded to a box around the region (the thesis' O(n²)-sized band is what the box
//! costs for the region sizes of its Table 3.2).

use glam::DVec3;
use rayon::prelude::*;

use crate::SculptError;
use crate::dexel::TriDexel;
use crate::grid::{PointBox, transverse};
use crate::interval::inside_at;
use crate::peel::{Crossing, pack_normal};

/// Largest smoothing kernel, in cells.
pub const MAX_KERNEL: usize = 64;

/// A box to smooth and the kernel size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmoothRegion {
    /// Lower corner of the box to smooth fully (physical units).
    pub min: DVec3,
    /// Upper corner.
    pub max: DVec3,
    /// Kernel half-width in cells (1 to [`MAX_KERNEL`]): the smoothing averages over
    /// `(2k + 1)³` grid points, and blends back to the original over `3k` cells around the
    /// box.
    pub kernel: usize,
}

/// Dense `f64` values over an index box.
struct Field {
    b: PointBox,
    e: [usize; 3],
    v: Vec<f64>,
}

impl Field {
    fn new(b: PointBox, value: f64) -> Self {
        let e = b.extent();
        Self {
            b,
            e,
            v: vec![value; e[0] * e[1] * e[2]],
        }
    }

    #[inline]
    fn idx(&self, p: [usize; 3]) -> usize {
        (p[0] - self.b.lo[0])
            + self.e[0] * ((p[1] - self.b.lo[1]) + self.e[1] * (p[2] - self.b.lo[2]))
    }

    #[inline]
    fn get(&self, p: [usize; 3]) -> f64 {
        self.v[self.idx(p)]
    }
}

/// The new crossings of every ray the smoothing touches: `(axis, ray index, crossings)`.
pub(crate) fn smooth_rays(
    dexel: &TriDexel,
    region: &SmoothRegion,
) -> Result<Vec<(usize, usize, Vec<Crossing>)>, SculptError> {
    let g = *dexel.grid();
    let k = region.kernel;
    if !(1..=MAX_KERNEL).contains(&k) {
        return Err(SculptError::option("smoothing kernel", k, "1 to 64 cells"));
    }
    if !(region.min.is_finite() && region.max.is_finite() && region.min.cmple(region.max).all()) {
        return Err(SculptError::option(
            "smoothing region",
            format!("{} – {}", region.min, region.max),
            "a finite box with min ≤ max",
        ));
    }
    let d = g.dims();
    let interior = PointBox {
        lo: [1; 3],
        hi: [d[0] - 2, d[1] - 2, d[2] - 2],
    };
    let user = g.index_box_covering(region.min, region.max);
    if !user.intersects(&interior) {
        return Ok(Vec::new());
    }
    let clamp = |b: PointBox| PointBox {
        lo: std::array::from_fn(|a| b.lo[a].max(interior.lo[a])),
        hi: std::array::from_fn(|a| b.hi[a].min(interior.hi[a])),
    };
    let user = clamp(user);
    let blend = clamp(user.dilated(3 * k, &g));
    // Partial volumes are needed over the blend box plus the kernel and the widening of the
    // replaced stretches; cells over one more point.
    let work = clamp(blend.dilated(k + 2, &g));
    let cells = PointBox {
        lo: work.lo.map(|x| x - 1),
        hi: work.hi,
    };
    let points = cells.point_count();
    volmorph_io::checked_len(&[points, 4], size_of::<f64>())?;
    // Solid fraction of each cell (lowest corner in `cells`), from its 12 edges.
    let edge_fraction = |axis: usize, p: [usize; 3]| -> f64 {
        let (b, c) = transverse(axis);
        let ray = dexel.ray(axis, p[b], p[c]);
        let (t0, t1) = (g.coord(axis, p[axis]), g.coord(axis, p[axis] + 1));
        let mut solid = 0.0;
        for pair in ray.chunks(2) {
            let (a, z) = (
                pair[0].depth,
                pair.get(1).map_or(f64::INFINITY, |x| x.depth),
            );
            solid += (z.min(t1) - a.max(t0)).max(0.0);
        }
        solid / (t1 - t0)
    };
    let mut frac = Field::new(cells, 0.0);
    let e = frac.e;
    frac.v
        .par_chunks_mut(e[0])
        .enumerate()
        .for_each(|(row, out)| {
            let (y, z) = (cells.lo[1] + row % e[1], cells.lo[2] + row / e[1]);
            for (i, slot) in out.iter_mut().enumerate() {
                let c = [cells.lo[0] + i, y, z];
                let mut sum = 0.0;
                for axis in 0..3 {
                    let (u, v) = transverse(axis);
                    for du in 0..2 {
                        for dv in 0..2 {
                            let mut p = c;
                            p[u] += du;
                            p[v] += dv;
                            sum += edge_fraction(axis, p);
                        }
                    }
                }
                *slot = sum / 12.0;
            }
        });
    // Partial volume of each grid point of `work`: mean of its eight cells.
    let mut pv = Field::new(work, 0.0);
    let ew = pv.e;
    pv.v.par_chunks_mut(ew[0])
        .enumerate()
        .for_each(|(row, out)| {
            let (y, z) = (work.lo[1] + row % ew[1], work.lo[2] + row / ew[1]);
            for (i, slot) in out.iter_mut().enumerate() {
                let p = [work.lo[0] + i, y, z];
                let mut sum = 0.0;
                for dz in 0..2 {
                    for dy in 0..2 {
                        for dx in 0..2 {
                            sum += frac.get([p[0] - dx, p[1] - dy, p[2] - dz]);
                        }
                    }
                }
                *slot = sum / 8.0;
            }
        });
    drop(frac);
    // Box filter of half-width k, separably, over `work` (clamped at its border).
    let mut smooth = Field {
        b: pv.b,
        e: pv.e,
        v: pv.v.clone(),
    };
    for axis in 0..3 {
        box_filter(&mut smooth, axis, k);
    }
    // Blend by the distance to the user's box.
    let band = (3 * k) as f64;
    let mut blended = Field {
        b: pv.b,
        e: pv.e,
        v: pv.v.clone(),
    };
    blended
        .v
        .par_chunks_mut(ew[0])
        .enumerate()
        .for_each(|(row, out)| {
            let (y, z) = (work.lo[1] + row % ew[1], work.lo[2] + row / ew[1]);
            for (i, slot) in out.iter_mut().enumerate() {
                let p = [work.lo[0] + i, y, z];
                let dist = (0..3)
                    .map(|a| {
                        let x = p[a] as f64;
                        let gap = (user.lo[a] as f64 - x).max(x - user.hi[a] as f64).max(0.0);
                        gap * gap
                    })
                    .sum::<f64>()
                    .sqrt();
                let w = (1.0 - dist / band).clamp(0.0, 1.0);
                if w > 0.0 {
                    let o = smooth.get(p);
                    *slot = w * o + (1.0 - w) * *slot;
                }
            }
        });
    drop(smooth);
    // New rays.
    let mut out = Vec::new();
    for axis in 0..3 {
        let (b, c) = transverse(axis);
        let rays: Vec<(usize, usize)> = (blend.lo[c]..=blend.hi[c])
            .flat_map(|ic| (blend.lo[b]..=blend.hi[b]).map(move |ib| (ib, ic)))
            .collect();
        let found: Vec<(usize, usize, Vec<Crossing>)> = rays
            .par_iter()
            .filter_map(|&(ib, ic)| {
                let ray = dexel.ray(axis, ib, ic);
                let mut at = [0; 3];
                at[b] = ib;
                at[c] = ic;
                let point = |i: usize| {
                    let mut p = at;
                    p[axis] = i;
                    p
                };
                let solid = |i: usize| blended.get(point(i)) >= 0.5;
                let agrees = |i: usize| {
                    let v = blended.get(point(i));
                    let orig = inside_at(ray, g.coord(axis, i));
                    (v == 0.0 || v == 1.0) && (v == 1.0) == orig
                };
                // Widen the stretch until both ends agree with the ray.
                let (mut s0, mut s1) = (blend.lo[axis], blend.hi[axis]);
                while s0 > work.lo[axis] + 1 && !agrees(s0) {
                    s0 -= 1;
                }
                while s1 + 1 < work.hi[axis] && !agrees(s1) {
                    s1 += 1;
                }
                let (t0, t1) = (g.coord(axis, s0), g.coord(axis, s1));
                let mut new = Vec::with_capacity(ray.len() + 4);
                let mut state = false;
                let push = |new: &mut Vec<Crossing>, c: Crossing, state: &mut bool| {
                    if c.entering != *state {
                        if let Some(last) = new.last()
                            && last.depth >= c.depth
                        {
                            // Coincident with the previous crossing: they cancel.
                            new.pop();
                            *state = !*state;
                            return;
                        }
                        new.push(c);
                        *state = c.entering;
                    }
                };
                for x in ray.iter().filter(|x| x.depth <= t0) {
                    push(&mut new, *x, &mut state);
                }
                let axis_normal = |entering: bool| {
                    let mut n = DVec3::ZERO;
                    n[axis] = if entering { -1.0 } else { 1.0 };
                    n
                };
                if solid(s0) != state {
                    let entering = solid(s0);
                    push(
                        &mut new,
                        Crossing {
                            depth: t0,
                            normal: pack_normal(axis_normal(entering)),
                            entering,
                        },
                        &mut state,
                    );
                }
                for i in s0..s1 {
                    let (v0, v1) = (blended.get(point(i)), blended.get(point(i + 1)));
                    if (v0 >= 0.5) == (v1 >= 0.5) {
                        continue;
                    }
                    let s = ((v0 - 0.5) / (v0 - v1)).clamp(0.0, 1.0);
                    let depth = g.coord(axis, i) + s * (g.coord(axis, i + 1) - g.coord(axis, i));
                    let grad =
                        sobel(&blended, point(i)) * (1.0 - s) + sobel(&blended, point(i + 1)) * s;
                    let entering = v1 >= 0.5;
                    let n = (-grad)
                        .try_normalize()
                        .unwrap_or_else(|| axis_normal(entering));
                    push(
                        &mut new,
                        Crossing {
                            depth,
                            normal: pack_normal(n),
                            entering,
                        },
                        &mut state,
                    );
                }
                let orig_state = inside_at(ray, t1);
                if orig_state != state {
                    push(
                        &mut new,
                        Crossing {
                            depth: t1,
                            normal: pack_normal(axis_normal(orig_state)),
                            entering: orig_state,
                        },
                        &mut state,
                    );
                }
                for x in ray.iter().filter(|x| x.depth > t1) {
                    push(&mut new, *x, &mut state);
                }
                if new.len() % 2 == 1 {
                    new.pop();
                }
                (new.as_slice() != ray).then(|| (axis, g.ray_index(axis, ib, ic), new))
            })
            .collect();
        out.extend(found);
    }
    Ok(out)
}

/// Replace `f` by its running mean over `2k + 1` points along `axis` (the window clamped to
/// the field).
fn box_filter(f: &mut Field, axis: usize, k: usize) {
    let e = f.e;
    let stride = match axis {
        0 => 1,
        1 => e[0],
        _ => e[0] * e[1],
    };
    let n = e[axis];
    let lines: Vec<usize> = (0..e[0] * e[1] * e[2])
        .filter(|&i| {
            let coord = match axis {
                0 => i % e[0],
                1 => (i / e[0]) % e[1],
                _ => i / (e[0] * e[1]),
            };
            coord == 0
        })
        .collect();
    let src = f.v.clone();
    let results: Vec<(usize, Vec<f64>)> = lines
        .par_iter()
        .map(|&start| {
            let mut prefix = vec![0.0; n + 1];
            for i in 0..n {
                prefix[i + 1] = prefix[i] + src[start + i * stride];
            }
            let out: Vec<f64> = (0..n)
                .map(|i| {
                    let (a, z) = (i.saturating_sub(k), (i + k).min(n - 1));
                    (prefix[z + 1] - prefix[a]) / (z + 1 - a) as f64
                })
                .collect();
            (start, out)
        })
        .collect();
    for (start, out) in results {
        for (i, v) in out.into_iter().enumerate() {
            f.v[start + i * stride] = v;
        }
    }
}

/// Sobel gradient (per cell, up to a constant factor) of `f` at `p`, one-sided where a
/// neighbour is outside the field.
fn sobel(f: &Field, p: [usize; 3]) -> DVec3 {
    let mut g = DVec3::ZERO;
    let w = [1.0, 2.0, 1.0];
    for axis in 0..3 {
        let (u, v) = transverse(axis);
        let mut sum = 0.0;
        for du in 0..3 {
            for dv in 0..3 {
                let mut q = p;
                let (Some(qu), Some(qv)) = ((p[u] + du).checked_sub(1), (p[v] + dv).checked_sub(1))
                else {
                    continue;
                };
                q[u] = qu.clamp(f.b.lo[u], f.b.hi[u]);
                q[v] = qv.clamp(f.b.lo[v], f.b.hi[v]);
                let mut lo = q;
                let mut hi = q;
                lo[axis] = p[axis].saturating_sub(1).max(f.b.lo[axis]);
                hi[axis] = (p[axis] + 1).min(f.b.hi[axis]);
                let span = (hi[axis] - lo[axis]) as f64;
                if span > 0.0 {
                    sum += w[du] * w[dv] * (f.get(hi) - f.get(lo)) * 2.0 / span;
                }
            }
        }
        g[axis] = sum / 32.0;
    }
    g
}
