//! Pictures of planar slices of a volume: window, colour map, physical aspect ratio and
//! magnification, the way slice viewers show them.

use volmorph_volume::slice::Slice;

use crate::colormap::{Colormap, render_scalar};
use crate::error::RenderError;
use crate::image::RgbaImage;
use crate::window::Window;

/// How [`render_slice`] draws a slice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SliceStyle {
    /// Intensity window; `None` chooses [`Window::auto`] from the slice's own values.
    pub window: Option<Window>,
    /// Colour map applied to the windowed values.
    pub colormap: Colormap,
    /// Draw pixels with the physical aspect ratio of the voxels (the shorter pixel side stays
    /// one picture pixel; the longer is stretched by nearest neighbour).
    pub physical_aspect: bool,
    /// Integer magnification (nearest neighbour), at least 1.
    pub scale: u32,
}

impl Default for SliceStyle {
    /// Automatic window, grey, voxel aspect (one pixel per voxel), no magnification.
    fn default() -> Self {
        Self {
            window: None,
            colormap: Colormap::Grey,
            physical_aspect: false,
            scale: 1,
        }
    }
}

/// The picture of `slice` (row 0 at the top, as [`Slice`] stores it) drawn as `style` says.
///
/// # Errors
/// [`RenderError::InvalidArgument`] when the window is automatic and the slice has no finite
/// value, or `scale` is 0; [`RenderError::Size`] when the picture would be too large.
pub fn render_slice(slice: &Slice, style: &SliceStyle) -> Result<RgbaImage, RenderError> {
    if style.scale == 0 {
        return Err(RenderError::invalid(
            "slice magnification must be at least 1",
        ));
    }
    let window = match style.window {
        Some(w) => w,
        None => Window::auto(&slice.values).map_err(|_| {
            RenderError::invalid("the slice has no finite values to choose a window from")
        })?,
    };
    let too_big = |_| RenderError::Size {
        width: slice.width as u64,
        height: slice.height as u64,
        reason: "a slice picture side must fit in 32 bits",
    };
    let (w, h) = (
        u32::try_from(slice.width).map_err(too_big)?,
        u32::try_from(slice.height).map_err(too_big)?,
    );
    let img = render_scalar(&slice.values, w, h, &window, style.colormap)?;
    let (sx, sy) = if style.physical_aspect {
        let [px, py] = slice.pixel_spacing;
        let m = px.min(py);
        if !(m > 0.0 && px.is_finite() && py.is_finite()) {
            return Err(RenderError::invalid(format!(
                "slice pixel spacing {px} × {py} must be finite and positive"
            )));
        }
        (px / m, py / m)
    } else {
        (1.0, 1.0)
    };
    let f = f64::from(style.scale);
    img.resize_nearest(sx * f, sy * f)
}

#[cfg(test)]
mod tests {
    use super::*;
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

    #[test]
    fn window_aspect_and_scale() {
        let s = slice();
        let img = render_slice(&s, &SliceStyle::default()).unwrap();
        assert_eq!((img.width(), img.height()), (3, 2));
        // Automatic window over 0..5: first pixel black, last white.
        assert_eq!(img.get(0, 0), Some([0, 0, 0, 255]));
        assert_eq!(img.get(2, 1), Some([255, 255, 255, 255]));
        let style = SliceStyle {
            window: Some(Window::from_range(2.0, 3.0).unwrap()),
            physical_aspect: true,
            scale: 2,
            ..SliceStyle::default()
        };
        let img = render_slice(&s, &style).unwrap();
        // 3 × 2 voxels of 1 × 2.5 mm, doubled: 6 × 10 pixels.
        assert_eq!((img.width(), img.height()), (6, 10));
        assert_eq!(img.get(0, 0), Some([0, 0, 0, 255]));
        assert_eq!(img.get(5, 9), Some([255, 255, 255, 255]));
    }

    #[test]
    fn bad_input_is_an_error() {
        let mut s = slice();
        let zero = SliceStyle {
            scale: 0,
            ..SliceStyle::default()
        };
        assert!(render_slice(&s, &zero).is_err());
        s.values = vec![f32::NAN; 6];
        assert!(render_slice(&s, &SliceStyle::default()).is_err());
    }
}
