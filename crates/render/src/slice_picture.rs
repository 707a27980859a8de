//! Pictures of planar slices of a volume: window, colour map, physical aspect ratio, a
//! readable size and orientation labels, the way slice viewers show them.
//!
//! # Picture size
//!
//! [`slice_picture_size`] chooses the picture's pixels:
//!
//! * With [`PixelAspect::Physical`] (the default) the picture has the slice's **physical**
//!   aspect ratio, `width · spacing₁ : height · spacing₂`, so anisotropic voxels are not
//!   squashed; with [`PixelAspect::Voxel`] each voxel is a square.
//! * [`SliceSize::Auto`] (the default): one pixel per smallest spacing (per voxel with
//!   [`PixelAspect::Voxel`]), enlarged so that the **longer side is at least**
//!   [`DEFAULT_LONG_SIDE`] pixels; a slice already that large keeps its own size.
//! * [`SliceSize::LongSide`]`(n)`: the longer side is `n` pixels.
//! * [`SliceSize::Zoom`]`(f)`: `f` pixels per smallest spacing (per voxel).
//!
//! Sides are rounded to whole pixels, so the aspect ratio is exact to half a pixel per side.
//!
//! # Resampling
//!
//! The slice's **values** are resampled to the picture before the window and colour map are
//! applied (so interpolation never invents colours the map lacks): pixel centre `(X + ½)` maps
//! to the slice coordinate `(X + ½) · width / W − ½` (voxel centres at integers), clamped to the
//! slice, and [`Interpolation::Linear`] (the default) takes the bilinear mix of the four
//! nearest voxels, [`Interpolation::Nearest`] the nearest one. At the slice's own size both are
//! the identity.

use volmorph_volume::slice::Slice;

use crate::annotate::{OrientationLabels, draw_orientation_labels};
use crate::colormap::{Colormap, render_scalar};
use crate::error::RenderError;
use crate::image::RgbaImage;
use crate::window::Window;

/// Longer side, in pixels, of a slice picture of automatic size ([`SliceSize::Auto`]) when
/// the slice itself is smaller: 512, large enough to read a 64-voxel phantom or a 256 × 256
/// MR slice at a glance on any screen.
pub const DEFAULT_LONG_SIDE: u32 = 512;

/// Largest side, in pixels, of a slice picture (16384, four times a 4K screen's width).
pub const MAX_SLICE_SIDE: u32 = 16_384;

/// Shape of the picture's pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PixelAspect {
    /// The picture has the physical aspect ratio of the slice (voxel spacing honoured).
    #[default]
    Physical,
    /// Every voxel is a square of pixels, whatever its spacing.
    Voxel,
}

/// How large [`render_slice`] draws a slice (the rules are on [`slice_picture_size`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum SliceSize {
    /// One pixel per smallest spacing (or voxel), enlarged to a longer side of at least
    /// [`DEFAULT_LONG_SIDE`] pixels.
    #[default]
    Auto,
    /// The longer side has this many pixels (at least 1).
    LongSide(u32),
    /// This many pixels per smallest spacing (or per voxel); finite and positive.
    Zoom(f64),
}

/// How slice values are resampled to the picture's pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Interpolation {
    /// The nearest voxel (blocky; shows the voxels as they are).
    Nearest,
    /// Bilinear between the four nearest voxels (smooth).
    #[default]
    Linear,
}

/// How [`render_slice`] draws a slice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SliceStyle {
    /// Intensity window; `None` chooses [`Window::auto`] from the slice's own values.
    pub window: Option<Window>,
    /// Colour map applied to the windowed values.
    pub colormap: Colormap,
    /// Pixel shape: physical aspect ratio (default) or square voxels.
    pub aspect: PixelAspect,
    /// Picture size (default: at least [`DEFAULT_LONG_SIDE`] pixels on the longer side).
    pub size: SliceSize,
    /// Resampling of values to pixels (default bilinear).
    pub interpolation: Interpolation,
    /// Orientation labels drawn at the middle of the edges, or none (see
    /// [`OrientationLabels::for_slice`] and [`draw_orientation_labels`]).
    pub labels: Option<OrientationLabels>,
}

impl Default for SliceStyle {
    /// Automatic window, grey, physical aspect, automatic size, bilinear, no labels.
    fn default() -> Self {
        Self {
            window: None,
            colormap: Colormap::Grey,
            aspect: PixelAspect::Physical,
            size: SliceSize::Auto,
            interpolation: Interpolation::Linear,
            labels: None,
        }
    }
}

/// The picture size `(width, height)` in pixels of `slice` drawn with `aspect` and `size`.
///
/// With [`PixelAspect::Physical`] the picture has the slice's physical aspect ratio
/// (`width · spacing₁ : height · spacing₂`), with [`PixelAspect::Voxel`] square voxels.
/// [`SliceSize::Auto`]: one pixel per smallest spacing (per voxel), enlarged so the longer side
/// is at least [`DEFAULT_LONG_SIDE`]; [`SliceSize::LongSide`]`(n)`: the longer side is `n`;
/// [`SliceSize::Zoom`]`(f)`: `f` pixels per smallest spacing (per voxel). Sides are rounded to
/// whole pixels.
///
/// # Errors
/// [`RenderError::InvalidArgument`] for an empty slice, a pixel spacing that is not finite and
/// positive (with [`PixelAspect::Physical`]), a zoom that is not finite and positive or a long
/// side of 0; [`RenderError::Size`] when a side would exceed [`MAX_SLICE_SIDE`].
pub fn slice_picture_size(
    slice: &Slice,
    aspect: PixelAspect,
    size: SliceSize,
) -> Result<(u32, u32), RenderError> {
    if slice.width == 0 || slice.height == 0 {
        return Err(RenderError::invalid(format!(
            "the slice is empty ({} × {} voxels)",
            slice.width, slice.height
        )));
    }
    let [px, py] = match aspect {
        PixelAspect::Voxel => [1.0, 1.0],
        PixelAspect::Physical => {
            let [px, py] = slice.pixel_spacing;
            if !(px > 0.0 && py > 0.0 && px.is_finite() && py.is_finite()) {
                return Err(RenderError::invalid(format!(
                    "slice pixel spacing {px} × {py} must be finite and positive"
                )));
            }
            [px, py]
        }
    };
    let unit = px.min(py);
    // Extent in units of the smallest spacing: the picture size at one pixel per unit.
    let (ew, eh) = (
        slice.width as f64 * px / unit,
        slice.height as f64 * py / unit,
    );
    let long = ew.max(eh);
    let k = match size {
        SliceSize::Auto => long.max(f64::from(DEFAULT_LONG_SIDE)) / long,
        SliceSize::LongSide(0) => {
            return Err(RenderError::invalid(
                "the picture's longer side must be at least 1 pixel",
            ));
        }
        SliceSize::LongSide(n) => f64::from(n) / long,
        SliceSize::Zoom(f) => {
            if !(f > 0.0 && f.is_finite()) {
                return Err(RenderError::invalid(format!(
                    "slice zoom {f} must be finite and positive"
                )));
            }
            f
        }
    };
    let (w, h) = ((ew * k).round().max(1.0), (eh * k).round().max(1.0));
    let max = f64::from(MAX_SLICE_SIDE);
    if !(w <= max && h <= max) {
        return Err(RenderError::Size {
            width: w.min(u64::MAX as f64) as u64,
            height: h.min(u64::MAX as f64) as u64,
            reason: "a slice picture side is limited to MAX_SLICE_SIDE (16384) pixels",
        });
    }
    Ok((w as u32, h as u32))
}

/// The slice's values resampled to `w × h` pixels (row 0 at the top) as the [module
/// documentation](self) states.
fn resample(slice: &Slice, w: u32, h: u32, interpolation: Interpolation) -> Vec<f32> {
    let (sw, sh) = (slice.width, slice.height);
    if (w as usize, h as usize) == (sw, sh) {
        return slice.values.clone();
    }
    // Source coordinate of each output column / row: (lower index, weight of the next).
    let axis = |n_out: u32, n_in: usize| -> Vec<(usize, f64)> {
        let f = n_in as f64 / f64::from(n_out);
        (0..n_out)
            .map(|x| {
                let u = (f64::from(x) + 0.5) * f;
                match interpolation {
                    Interpolation::Nearest => ((u.floor() as usize).min(n_in - 1), 0.0),
                    Interpolation::Linear => {
                        let u = (u - 0.5).clamp(0.0, (n_in - 1) as f64);
                        let i = (u.floor() as usize).min(n_in.saturating_sub(2));
                        (i, u - i as f64)
                    }
                }
            })
            .collect()
    };
    let cols = axis(w, sw);
    let rows = axis(h, sh);
    let v = |c: usize, r: usize| f64::from(slice.values[r * sw + c]);
    let mut out = Vec::with_capacity(w as usize * h as usize);
    for &(r, tr) in &rows {
        let r1 = (r + 1).min(sh - 1);
        for &(c, tc) in &cols {
            let c1 = (c + 1).min(sw - 1);
            let value = if tr == 0.0 && tc == 0.0 {
                v(c, r)
            } else {
                let top = v(c, r) * (1.0 - tc) + v(c1, r) * tc;
                let bottom = v(c, r1) * (1.0 - tc) + v(c1, r1) * tc;
                top * (1.0 - tr) + bottom * tr
            };
            out.push(value as f32);
        }
    }
    out
}

/// The picture of `slice` (row 0 at the top, as [`Slice`] stores it) drawn as `style` says:
/// values resampled to [`slice_picture_size`], windowed, colour-mapped, and the orientation
/// labels drawn on top.
///
/// # Errors
/// [`RenderError::InvalidArgument`] when the window is automatic and the slice has no finite
/// value, or the size cannot be chosen (see [`slice_picture_size`]); [`RenderError::Size`]
/// when the picture would be too large.
pub fn render_slice(slice: &Slice, style: &SliceStyle) -> Result<RgbaImage, RenderError> {
    if slice.values.len() != slice.width.saturating_mul(slice.height) {
        return Err(RenderError::invalid(format!(
            "the slice has {} values for {} × {} pixels",
            slice.values.len(),
            slice.width,
            slice.height
        )));
    }
    let window = match style.window {
        Some(w) => w,
        None => Window::auto(&slice.values).map_err(|_| {
            RenderError::invalid("the slice has no finite values to choose a window from")
        })?,
    };
    let (w, h) = slice_picture_size(slice, style.aspect, style.size)?;
    let values = resample(slice, w, h, style.interpolation);
    let mut img = render_scalar(&values, w, h, &window, style.colormap)?;
    if let Some(labels) = &style.labels {
        draw_orientation_labels(&mut img, labels)?;
    }
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::annotate::{LABEL_COLOR, OrientationLabels};
    use glam::DMat3;
    use volmorph_volume::slice::Axis;

    fn slice() -> Slice {
        Slice {
            width: 3,
            height: 2,
            values: vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0],
            pixel_spacing: [1.0, 2.5],
            index: 0.0,
            axis: Axis::Z,
        }
    }

    fn native() -> SliceStyle {
        SliceStyle {
            aspect: PixelAspect::Voxel,
            size: SliceSize::Zoom(1.0),
            ..SliceStyle::default()
        }
    }

    #[test]
    fn window_aspect_and_zoom() {
        let s = slice();
        let img = render_slice(&s, &native()).unwrap();
        assert_eq!((img.width(), img.height()), (3, 2));
        // Automatic window over 0..5: first pixel black, last white.
        assert_eq!(img.get(0, 0), Some([0, 0, 0, 255]));
        assert_eq!(img.get(2, 1), Some([255, 255, 255, 255]));
        let style = SliceStyle {
            window: Some(Window::from_range(2.0, 3.0).unwrap()),
            size: SliceSize::Zoom(2.0),
            interpolation: Interpolation::Nearest,
            ..SliceStyle::default()
        };
        let img = render_slice(&s, &style).unwrap();
        // 3 × 2 voxels of 1 × 2.5 mm, doubled: 6 × 10 pixels.
        assert_eq!((img.width(), img.height()), (6, 10));
        assert_eq!(img.get(0, 0), Some([0, 0, 0, 255]));
        assert_eq!(img.get(5, 9), Some([255, 255, 255, 255]));
    }

    #[test]
    fn default_size_is_readable_and_keeps_the_physical_aspect() {
        // 40 × 25 voxels of 0.7 × 2.9 mm: 28 mm × 72.5 mm.
        let s = Slice {
            width: 40,
            height: 25,
            values: (0..1000).map(|v| v as f32).collect(),
            pixel_spacing: [0.7, 2.9],
            index: 0.0,
            axis: Axis::Y,
        };
        let (w, h) = slice_picture_size(&s, PixelAspect::Physical, SliceSize::Auto).unwrap();
        assert_eq!(h, DEFAULT_LONG_SIDE);
        let physical = (40.0 * 0.7) / (25.0 * 2.9);
        let aspect = f64::from(w) / f64::from(h);
        // Rounding to whole pixels moves the ratio by at most half a pixel on a side.
        assert!((aspect - physical).abs() <= 0.5 / f64::from(h) + 0.5 / f64::from(w));
        let img = render_slice(&s, &SliceStyle::default()).unwrap();
        assert_eq!((img.width(), img.height()), (w, h));
        // A large slice keeps one pixel per smallest spacing.
        let big = Slice {
            width: 700,
            height: 300,
            values: vec![0.0; 210_000],
            pixel_spacing: [1.0, 1.0],
            index: 0.0,
            axis: Axis::Z,
        };
        assert_eq!(
            slice_picture_size(&big, PixelAspect::Physical, SliceSize::Auto).unwrap(),
            (700, 300)
        );
        assert_eq!(
            slice_picture_size(&big, PixelAspect::Voxel, SliceSize::LongSide(70)).unwrap(),
            (70, 30)
        );
        assert_eq!(
            slice_picture_size(&s, PixelAspect::Voxel, SliceSize::Auto).unwrap(),
            (512, 320)
        );
    }

    #[test]
    fn linear_resampling_interpolates_values_and_is_exact_at_voxel_centres() {
        // A ramp along x: bilinear resampling of a linear function is linear in the interior.
        let s = Slice {
            width: 5,
            height: 1,
            values: vec![0.0, 10.0, 20.0, 30.0, 40.0],
            pixel_spacing: [1.0, 1.0],
            index: 0.0,
            axis: Axis::Z,
        };
        let v = resample(&s, 10, 2, Interpolation::Linear);
        // Output pixel centre x + ½ maps to source (x + ½)/2 − ½.
        for x in 1..9 {
            let u = (x as f64 + 0.5) / 2.0 - 0.5;
            assert!((f64::from(v[x]) - 10.0 * u).abs() < 1e-4, "{x}: {}", v[x]);
            assert_eq!(v[x], v[10 + x], "rows agree");
        }
        // Clamped at the borders.
        assert_eq!((v[0], v[9]), (0.0, 40.0));
        let n = resample(&s, 10, 1, Interpolation::Nearest);
        assert_eq!(
            n,
            [0.0, 0.0, 10.0, 10.0, 20.0, 20.0, 30.0, 30.0, 40.0, 40.0]
        );
        // A 1-voxel-wide slice resamples to a constant.
        let one = Slice {
            width: 1,
            height: 1,
            values: vec![3.0],
            ..s
        };
        assert_eq!(resample(&one, 4, 4, Interpolation::Linear), vec![3.0; 16]);
    }

    #[test]
    fn labels_are_drawn_at_the_expected_edges() {
        let s = Slice {
            width: 64,
            height: 64,
            values: vec![0.5; 64 * 64],
            pixel_spacing: [1.0, 1.0],
            index: 0.0,
            axis: Axis::Z,
        };
        let labelled = |direction: DMat3| {
            let style = SliceStyle {
                window: Some(Window::new(0.5, 1.0).unwrap()),
                labels: Some(OrientationLabels::for_slice(direction, Axis::Z).unwrap()),
                ..SliceStyle::default()
            };
            render_slice(&s, &style).unwrap()
        };
        let img = labelled(DMat3::IDENTITY);
        assert_eq!((img.width(), img.height()), (512, 512));
        // Label pixels lie only in the four edge bands' middles, none in the centre.
        let yellow = |x0: u32, x1: u32, y0: u32, y1: u32| {
            (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .filter(|&(x, y)| img.get(x, y) == Some(LABEL_COLOR))
                .count()
        };
        assert!(yellow(0, 40, 220, 292) > 0, "left label");
        assert!(yellow(472, 512, 220, 292) > 0, "right label");
        assert!(yellow(220, 292, 0, 40) > 0, "top label");
        assert!(yellow(220, 292, 472, 512) > 0, "bottom label");
        assert_eq!(yellow(40, 472, 40, 472), 0);
        let total = img.pixels().iter().filter(|p| **p == LABEL_COLOR).count();
        assert_eq!(
            total,
            yellow(0, 40, 220, 292)
                + yellow(472, 512, 220, 292)
                + yellow(220, 292, 0, 40)
                + yellow(220, 292, 472, 512)
        );
    }

    #[test]
    fn bad_input_is_an_error() {
        let mut s = slice();
        let zoom0 = SliceStyle {
            size: SliceSize::Zoom(0.0),
            ..SliceStyle::default()
        };
        assert!(render_slice(&s, &zoom0).is_err());
        let side0 = SliceStyle {
            size: SliceSize::LongSide(0),
            ..SliceStyle::default()
        };
        assert!(render_slice(&s, &side0).is_err());
        let huge = SliceStyle {
            size: SliceSize::Zoom(1e9),
            ..SliceStyle::default()
        };
        assert!(matches!(
            render_slice(&s, &huge),
            Err(RenderError::Size { .. })
        ));
        s.pixel_spacing = [0.0, 1.0];
        assert!(render_slice(&s, &SliceStyle::default()).is_err());
        assert!(
            render_slice(&s, &native()).is_ok(),
            "voxel aspect ignores spacing"
        );
        s.values = vec![f32::NAN; 6];
        assert!(render_slice(&s, &native()).is_err());
        s.values = vec![1.0; 5];
        assert!(render_slice(&s, &native()).is_err());
    }
}
