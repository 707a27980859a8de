//! The user's frozen perspective view (McPhail §3.3.2): the depth-peel image the user edits
//! in, updated dab by dab over the pixels the tool covers, and the view-dependent grid of
//! Algorithm 3.1.

use glam::DVec3;
use rayon::prelude::*;

use crate::SculptError;
use crate::grid::Grid;
use crate::interval::{Op, combine};
use crate::peel::{Crossing, PerspectiveView, RayRect, TriangleSoup, peel_view};
use crate::tool::{Pose, Tool};

/// A pixel's index with its crossings before and after an edit.
pub(crate) type PixelChange = (u32, Vec<Crossing>, Vec<Crossing>);

/// A perspective view and the depth-peel image of the sculpted solid seen through it.
#[derive(Debug, Clone, PartialEq)]
pub struct FrozenView {
    view: PerspectiveView,
    /// Crossings per pixel, `u + width · v`.
    rays: Vec<Vec<Crossing>>,
}

/// `ray` as a clean interval list from −∞ when it starts inside (its first crossing leaves).
fn opened(ray: &[Crossing]) -> Vec<Crossing> {
    let mut v = Vec::with_capacity(ray.len() + 1);
    if ray.first().is_some_and(|c| !c.entering) {
        v.push(Crossing {
            depth: f64::NEG_INFINITY,
            normal: [0.0; 3],
            entering: true,
        });
    }
    v.extend_from_slice(ray);
    v
}

/// Drop the −∞ crossing added by [`opened`].
fn closed(mut ray: Vec<Crossing>) -> Vec<Crossing> {
    if ray.first().is_some_and(|c| c.depth == f64::NEG_INFINITY) {
        ray.remove(0);
    }
    ray
}

impl FrozenView {
    /// Peel `soup` through `view`.
    ///
    /// # Errors
    /// As [`crate::depth_peel_perspective`].
    pub fn new(view: PerspectiveView, soup: &TriangleSoup) -> Result<Self, SculptError> {
        let image = crate::peel::depth_peel_perspective(soup, &view)?;
        let rays = (0..view.height())
            .flat_map(|v| (0..view.width()).map(move |u| (u, v)))
            .map(|(u, v)| image.ray(u, v).to_vec())
            .collect();
        Ok(Self { view, rays })
    }

    /// The view.
    #[must_use]
    pub fn view(&self) -> &PerspectiveView {
        &self.view
    }

    /// Crossings of the solid along the ray of pixel `(u, v)` (distances from the eye,
    /// sorted; the first one is leaving when the eye is inside the solid). Empty outside the
    /// viewport.
    #[must_use]
    pub fn ray(&self, u: usize, v: usize) -> &[Crossing] {
        if u >= self.view.width() || v >= self.view.height() {
            return &[];
        }
        &self.rays[u + self.view.width() * v]
    }

    /// Nearest visible crossing of pixel `(u, v)`: the first surface the eye sees there.
    #[must_use]
    pub fn first_hit(&self, u: usize, v: usize) -> Option<Crossing> {
        self.ray(u, v).first().copied()
    }

    /// The pixels the tool at `poses` changes, with their old and new crossings.
    pub(crate) fn paint(
        &self,
        tool: &Tool,
        poses: &[Pose],
        op: Op,
    ) -> Result<Vec<PixelChange>, SculptError> {
        let soup = tool.posed_union(poses);
        let (w, h) = (self.view.width(), self.view.height());
        // Pixels the tool can cover: its vertices' screen box, or everything when a vertex
        // is behind the near plane.
        let mut lo = (f64::INFINITY, f64::INFINITY);
        let mut hi = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        let mut full = false;
        for &p in &soup.positions {
            match self.view.screen(p) {
                Some((x, y)) => {
                    lo = (lo.0.min(x), lo.1.min(y));
                    hi = (hi.0.max(x), hi.1.max(y));
                }
                None => full = true,
            }
        }
        let rect = if full {
            Some(RayRect {
                u0: 0,
                u1: w - 1,
                v0: 0,
                v1: h - 1,
            })
        } else {
            let u0 = lo.0.ceil().max(0.0);
            let v0 = lo.1.ceil().max(0.0);
            let u1 = hi.0.floor().min((w - 1) as f64);
            let v1 = hi.1.floor().min((h - 1) as f64);
            (u0 <= u1 && v0 <= v1).then_some(RayRect {
                u0: u0 as usize,
                u1: u1 as usize,
                v0: v0 as usize,
                v1: v1 as usize,
            })
        };
        let block = match rect {
            Some(r) => Some(peel_view(&soup, &self.view, r)?),
            None => None,
        };
        let pixels: Vec<usize> = match (op, &block) {
            (Op::Intersect, _) => (0..w * h).collect(),
            (_, Some(b)) => {
                let r = b.rect;
                (r.v0..=r.v1)
                    .flat_map(|v| (r.u0..=r.u1).map(move |u| u + w * v))
                    .collect()
            }
            (_, None) => Vec::new(),
        };
        Ok(pixels
            .par_iter()
            .filter_map(|&px| {
                let (u, v) = (px % w, px / w);
                let tool_ray = block.as_ref().map_or(&[][..], |b| b.ray(u, v));
                let old = self.ray(u, v);
                if tool_ray.is_empty() && (op != Op::Intersect || old.is_empty()) {
                    return None;
                }
                let mut new = Vec::with_capacity(old.len() + 2);
                combine(&opened(old), &opened(tool_ray), op, &mut new);
                let new = closed(new);
                (new != old).then(|| (px as u32, old.to_vec(), new))
            })
            .collect())
    }

    /// Set the pixels of `changes` to their new (or old) crossings.
    pub(crate) fn set(&mut self, changes: &[PixelChange], new: bool) {
        if changes.is_empty() {
            return;
        }
        for (px, old, nw) in changes {
            self.rays[*px as usize] = if new { nw.clone() } else { old.clone() };
        }
    }

    /// The view-dependent grid of Algorithm 3.1: the nearest and farthest first-hit depths
    /// `δmin`, `δmax` over the picture, the two spherical caps of rays of those lengths from
    /// the eye, the cube around their extrema (side: the largest extent), padded by `pad`
    /// (a fraction of the side on every side), with `n` points per axis.
    ///
    /// # Errors
    /// [`SculptError::InvalidOption`] when no pixel sees the solid or `pad` is negative; as
    /// [`Grid::new`].
    pub fn grid(&self, n: usize, pad: f64) -> Result<Grid, SculptError> {
        if !(pad.is_finite() && pad >= 0.0) {
            return Err(SculptError::option("pad", pad, "a finite fraction ≥ 0"));
        }
        let (w, h) = (self.view.width(), self.view.height());
        let mut dmin = f64::INFINITY;
        let mut dmax = f64::NEG_INFINITY;
        for v in 0..h {
            for u in 0..w {
                if let Some(c) = self.first_hit(u, v)
                    && c.depth.is_finite()
                {
                    dmin = dmin.min(c.depth);
                    dmax = dmax.max(c.depth);
                }
            }
        }
        if dmin > dmax {
            return Err(SculptError::option(
                "view",
                "no pixel sees the solid",
                "a view in which the solid is visible",
            ));
        }
        let mut lo = DVec3::INFINITY;
        let mut hi = DVec3::NEG_INFINITY;
        for v in 0..h {
            for u in 0..w {
                for d in [dmin, dmax] {
                    let p = self.view.point(u, v, d);
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
            }
        }
        let side = (hi - lo).max_element();
        let mid = (lo + hi) * 0.5;
        let full = side * (1.0 + 2.0 * pad);
        let spacing = full / (n.max(2) - 1) as f64;
        Grid::new(mid - DVec3::splat(full * 0.5), spacing, [n; 3])
    }
}
