//! Drawing into an [`RgbaImage`]: line segments, point markers and rectangles, for handle and
//! correspondence overlays.
//!
//! Coordinates are continuous image coordinates, as for [`Camera`]: x to the
//! right from the left edge, y down from the top edge, pixel `(i, j)` covering
//! `[i, i+1) × [j, j+1)` with its centre at `(i + 0.5, j + 0.5)`. Colours are composited with
//! [`blend_over`](crate::blend_over), so a translucent colour tints what is underneath; each
//! pixel of one primitive is blended at most once. Everything is clipped to the image, and
//! non-finite coordinates draw nothing, so screen positions of projected points can be
//! passed straight in.

use glam::DVec3;

use crate::Camera;
use crate::image::RgbaImage;

/// Shapes for [`draw_marker`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Marker {
    /// `+`: a horizontal and a vertical stroke through the centre.
    Plus,
    /// `×`: two diagonal strokes through the centre.
    Cross,
    /// Outline of the axis-aligned square of half-side `radius`.
    Square,
    /// Filled disc: pixels whose centres are within `radius` of the centre.
    Disc,
}

/// Clip the segment `a → b` to the rectangle `[x0, x1] × [y0, y1]` (Liang–Barsky); `None`
/// when nothing is left.
fn clip_segment(
    a: (f64, f64),
    b: (f64, f64),
    (x0, y0, x1, y1): (f64, f64, f64, f64),
) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    for (p, q) in [
        (-dx, a.0 - x0),
        (dx, x1 - a.0),
        (-dy, a.1 - y0),
        (dy, y1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
            if t0 > t1 {
                return None;
            }
        }
    }
    Some((
        (a.0 + t0 * dx, a.1 + t0 * dy),
        (a.0 + t1 * dx, a.1 + t1 * dy),
    ))
}

/// Draw the segment from `a` to `b` one pixel wide: every pixel the segment passes through
/// along its major axis (a DDA walk, the pixels containing `a` and `b` included) is blended
/// with `color`.
///
/// ```
/// use volmorph_render::{RgbaImage, draw::draw_line};
/// let mut img = RgbaImage::new(5, 5, [0, 0, 0, 255]).unwrap();
/// draw_line(&mut img, (0.5, 2.5), (4.5, 2.5), [255, 0, 0, 255]);
/// assert!((0..5).all(|x| img.get(x, 2) == Some([255, 0, 0, 255])));
/// assert_eq!(img.pixels().iter().filter(|p| p[0] == 255).count(), 5);
/// ```
pub fn draw_line(img: &mut RgbaImage, a: (f64, f64), b: (f64, f64), color: [u8; 4]) {
    let (w, h) = (img.width(), img.height());
    walk_line(w, h, a, b, |x, y| {
        img.blend(x, y, color);
    });
}

/// Draw the twelve edges of the box `[lo, hi]` as seen by `camera` (segments with an end
/// behind the camera are left out).
///
/// ```
/// use glam::DVec3;
/// use volmorph_render::{Camera, Projection, RgbaImage, draw::draw_box_edges};
/// let cam = Camera::look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, DVec3::Y,
///                           Projection::Orthographic { view_height: 4.0 }, 40, 40).unwrap();
/// let mut img = RgbaImage::new(40, 40, [0, 0, 0, 255]).unwrap();
/// draw_box_edges(&mut img, &cam, DVec3::splat(-1.0), DVec3::ONE, [255, 255, 255, 255]);
/// assert_eq!(img.get(10, 20), Some([255, 255, 255, 255])); // left edge x = −1
/// assert_eq!(img.get(20, 20), Some([0, 0, 0, 255])); // inside
/// ```
pub fn draw_box_edges(img: &mut RgbaImage, camera: &Camera, lo: DVec3, hi: DVec3, color: [u8; 4]) {
    let corner = |i: usize| {
        DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    for i in 0..8usize {
        for bit in [1usize, 2, 4] {
            if i & bit == 0
                && let (Some(a), Some(b)) =
                    (camera.project(corner(i)), camera.project(corner(i | bit)))
            {
                draw_line(img, (a.0, a.1), (b.0, b.1), color);
            }
        }
    }
}

/// Visit, once each and in order from `a` to `b`, the in-image pixels of the DDA walk of the
/// segment `a → b` in a `w × h` image.
fn walk_line(w: u32, h: u32, a: (f64, f64), b: (f64, f64), mut visit: impl FnMut(u32, u32)) {
    if !(a.0.is_finite() && a.1.is_finite() && b.0.is_finite() && b.1.is_finite()) {
        return;
    }
    let (wf, hf) = (f64::from(w), f64::from(h));
    // Clip a little outside the image so clipping never moves a visible pixel.
    let Some((a, b)) = clip_segment(a, b, (-1.0, -1.0, wf + 1.0, hf + 1.0)) else {
        return;
    };
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    // ≤ w + h + 4 after clipping, so the walk is bounded by the image size.
    let steps = dx.abs().max(dy.abs()).ceil().max(1.0) as usize;
    let mut last = None;
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let (x, y) = ((a.0 + t * dx).floor(), (a.1 + t * dy).floor());
        if last == Some((x, y)) {
            continue;
        }
        last = Some((x, y));
        if x >= 0.0 && y >= 0.0 && x < wf && y < hf {
            visit(x as u32, y as u32);
        }
    }
}

/// Blend `color` into every pixel whose centre lies in the closed rectangle spanned by
/// corners `a` and `b`.
pub fn fill_rect(img: &mut RgbaImage, a: (f64, f64), b: (f64, f64), color: [u8; 4]) {
    if !(a.0.is_finite() && a.1.is_finite() && b.0.is_finite() && b.1.is_finite()) {
        return;
    }
    let (w, h) = (f64::from(img.width()), f64::from(img.height()));
    // Pixel i's centre i + 0.5 is in [lo, hi] iff ceil(lo − 0.5) ≤ i ≤ floor(hi − 0.5).
    let range = |lo: f64, hi: f64, n: f64| {
        let first = (lo.min(hi) - 0.5).ceil().max(0.0);
        let last = (lo.max(hi) - 0.5).floor().min(n - 1.0);
        (first as u32, last as u32, first <= last)
    };
    let (x0, x1, okx) = range(a.0, b.0, w);
    let (y0, y1, oky) = range(a.1, b.1, h);
    if !(okx && oky) {
        return;
    }
    for y in y0..=y1 {
        for x in x0..=x1 {
            img.blend(x, y, color);
        }
    }
}

/// Draw a point marker of half-size `radius` pixels centred at `center`. A `radius` that is
/// negative or not finite draws nothing; a marker too small to reach a pixel centre marks
/// the pixel containing `center`.
///
/// ```
/// use volmorph_render::{RgbaImage, draw::{draw_marker, Marker}};
/// let mut img = RgbaImage::new(9, 9, [0, 0, 0, 0]).unwrap();
/// draw_marker(&mut img, (4.5, 4.5), 2.0, Marker::Plus, [0, 255, 0, 255]);
/// assert_eq!(img.get(4, 4), Some([0, 255, 0, 255])); // blended once: still opaque green
/// assert_eq!(img.get(2, 4), Some([0, 255, 0, 255]));
/// assert_eq!(img.get(3, 3), Some([0, 0, 0, 0]));
/// assert_eq!(img.pixels().iter().filter(|p| p[3] != 0).count(), 9);
/// ```
pub fn draw_marker(
    img: &mut RgbaImage,
    center: (f64, f64),
    radius: f64,
    marker: Marker,
    color: [u8; 4],
) {
    let (cx, cy) = center;
    if !(cx.is_finite() && cy.is_finite() && radius.is_finite() && radius >= 0.0) {
        return;
    }
    let r = radius;
    match marker {
        Marker::Plus => {
            let mut canvas = Overlay::new(img, color);
            canvas.line((cx - r, cy), (cx + r, cy));
            canvas.line((cx, cy - r), (cx, cy + r));
            canvas.commit();
        }
        Marker::Cross => {
            let mut canvas = Overlay::new(img, color);
            canvas.line((cx - r, cy - r), (cx + r, cy + r));
            canvas.line((cx - r, cy + r), (cx + r, cy - r));
            canvas.commit();
        }
        Marker::Square => {
            let mut canvas = Overlay::new(img, color);
            let (x0, y0, x1, y1) = (cx - r, cy - r, cx + r, cy + r);
            canvas.line((x0, y0), (x1, y0));
            canvas.line((x1, y0), (x1, y1));
            canvas.line((x1, y1), (x0, y1));
            canvas.line((x0, y1), (x0, y0));
            canvas.commit();
        }
        Marker::Disc => {
            let (w, h) = (f64::from(img.width()), f64::from(img.height()));
            let x_first = (cx - r - 0.5).ceil().max(0.0);
            let x_last = (cx + r - 0.5).floor().min(w - 1.0);
            let y_first = (cy - r - 0.5).ceil().max(0.0);
            let y_last = (cy + r - 0.5).floor().min(h - 1.0);
            let r2 = r * r;
            let mut any = false;
            if x_first <= x_last && y_first <= y_last {
                for y in y_first as u32..=y_last as u32 {
                    for x in x_first as u32..=x_last as u32 {
                        let (px, py) = (f64::from(x) + 0.5 - cx, f64::from(y) + 0.5 - cy);
                        if px * px + py * py <= r2 {
                            any |= img.blend(x, y, color);
                        }
                    }
                }
            }
            // A disc too small to hold a pixel centre still marks its centre's pixel.
            if !any && r < 1.0 && cx >= 0.0 && cy >= 0.0 && cx < w && cy < h {
                img.blend(cx as u32, cy as u32, color);
            }
        }
    }
}

/// Collects the pixels of several strokes so shared pixels (corners, crossings) are blended
/// only once.
struct Overlay<'a> {
    img: &'a mut RgbaImage,
    color: [u8; 4],
    pixels: Vec<(u32, u32)>,
}

impl<'a> Overlay<'a> {
    fn new(img: &'a mut RgbaImage, color: [u8; 4]) -> Self {
        Self {
            img,
            color,
            pixels: Vec::new(),
        }
    }

    /// Record the pixels [`draw_line`] would blend for `a → b`.
    fn line(&mut self, a: (f64, f64), b: (f64, f64)) {
        let pixels = &mut self.pixels;
        walk_line(self.img.width(), self.img.height(), a, b, |x, y| {
            pixels.push((x, y));
        });
    }

    fn commit(mut self) {
        self.pixels.sort_unstable();
        self.pixels.dedup();
        for &(x, y) in &self.pixels {
            self.img.blend(x, y, self.color);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BG: [u8; 4] = [0, 0, 0, 255];
    const INK: [u8; 4] = [255, 255, 255, 255];
    /// Translucent ink: a pixel blended twice would differ from one blended once.
    const TINT: [u8; 4] = [255, 0, 0, 100];

    fn marked(img: &RgbaImage) -> Vec<(u32, u32)> {
        let mut v = Vec::new();
        for y in 0..img.height() {
            for x in 0..img.width() {
                if img.get(x, y) != Some(BG) {
                    v.push((x, y));
                }
            }
        }
        v
    }

    fn all_blended_once(img: &RgbaImage) -> bool {
        let once = crate::blend_over(TINT, BG);
        marked(img)
            .iter()
            .all(|&(x, y)| img.get(x, y) == Some(once))
    }

    #[test]
    fn lines_visit_the_expected_pixels() {
        let mut img = RgbaImage::new(8, 8, BG).unwrap();
        draw_line(&mut img, (1.5, 6.5), (1.5, 2.5), INK);
        assert_eq!(marked(&img), (2..=6).map(|y| (1, y)).collect::<Vec<_>>());

        let mut img = RgbaImage::new(8, 8, BG).unwrap();
        draw_line(&mut img, (0.5, 0.5), (7.5, 7.5), TINT);
        assert_eq!(marked(&img), (0..8).map(|i| (i, i)).collect::<Vec<_>>());
        assert!(all_blended_once(&img));

        // A shallow line has one pixel per column.
        let mut img = RgbaImage::new(10, 4, BG).unwrap();
        draw_line(&mut img, (0.5, 0.5), (9.5, 3.5), TINT);
        let m = marked(&img);
        assert_eq!(m.len(), 10);
        assert!((0..10).all(|x| m.iter().filter(|p| p.0 == x).count() == 1));
        assert!(all_blended_once(&img));
    }

    #[test]
    fn lines_are_clipped_and_bounded() {
        let mut img = RgbaImage::new(6, 4, BG).unwrap();
        draw_line(&mut img, (-1e12, 2.5), (1e12, 2.5), INK);
        assert_eq!(marked(&img), (0..6).map(|x| (x, 2)).collect::<Vec<_>>());

        let mut img = RgbaImage::new(6, 4, BG).unwrap();
        draw_line(&mut img, (-5.0, -5.0), (-1.0, 100.0), INK);
        draw_line(&mut img, (f64::NAN, 1.0), (3.0, 1.0), INK);
        draw_line(&mut img, (0.0, 1.0), (f64::INFINITY, 1.0), INK);
        assert!(marked(&img).is_empty());
    }

    #[test]
    fn markers_have_the_documented_shapes() {
        let c = (4.5, 4.5);
        let count = |m: Marker, r: f64| {
            let mut img = RgbaImage::new(9, 9, BG).unwrap();
            draw_marker(&mut img, c, r, m, TINT);
            assert!(all_blended_once(&img), "{m:?}");
            marked(&img)
        };
        assert_eq!(count(Marker::Plus, 2.0).len(), 9);
        let cross = count(Marker::Cross, 2.0);
        assert_eq!(cross.len(), 9);
        assert!(cross.contains(&(2, 2)) && cross.contains(&(6, 2)) && cross.contains(&(4, 4)));
        let square = count(Marker::Square, 2.0);
        assert_eq!(square.len(), 16);
        assert!(!square.contains(&(4, 4)) && square.contains(&(2, 2)) && square.contains(&(6, 6)));
        // Lattice points within distance 2 of a lattice point: 13.
        assert_eq!(count(Marker::Disc, 2.0).len(), 13);
        // Tiny markers still mark the centre pixel.
        for m in [Marker::Plus, Marker::Cross, Marker::Square, Marker::Disc] {
            assert_eq!(count(m, 0.0), vec![(4, 4)], "{m:?}");
        }
        let mut img = RgbaImage::new(9, 9, BG).unwrap();
        draw_marker(&mut img, (4.1, 4.1), 0.3, Marker::Disc, INK);
        assert_eq!(marked(&img), vec![(4, 4)]);
        // Invalid radius or centre draws nothing; markers near the border are clipped.
        let mut img = RgbaImage::new(9, 9, BG).unwrap();
        draw_marker(&mut img, c, -1.0, Marker::Disc, INK);
        draw_marker(&mut img, (f64::NAN, 1.0), 1.0, Marker::Plus, INK);
        assert!(marked(&img).is_empty());
        draw_marker(&mut img, (0.5, 0.5), 3.0, Marker::Disc, INK);
        assert!(marked(&img).iter().all(|&(x, y)| x <= 3 && y <= 3));
        assert_eq!(img.get(0, 0), Some(INK));
    }

    #[test]
    fn rectangles_cover_pixel_centres_inside() {
        let mut img = RgbaImage::new(8, 8, BG).unwrap();
        fill_rect(&mut img, (5.6, 1.5), (2.4, 3.49), TINT);
        let m = marked(&img);
        // Centres 2.5‥5.5 across, 1.5 and 2.5 down (1.5 is on the closed boundary).
        assert_eq!(m.len(), 4 * 2);
        assert!(
            m.iter()
                .all(|&(x, y)| (2..=5).contains(&x) && (1..=2).contains(&y))
        );
        assert!(all_blended_once(&img));
        fill_rect(&mut img, (-100.0, -100.0), (100.0, 0.4), INK);
        assert_eq!(marked(&img).len(), 8);
        fill_rect(&mut img, (-100.0, -100.0), (100.0, 0.5), INK);
        assert_eq!(marked(&img).len(), 8 + 8);
    }
}
