//! Pixel buffers: [`RgbaImage`] (8-bit straight-alpha colour) and [`ScalarImage`] (f32 values
//! that renderers accumulate into before mapping them to colour).
//!
//! Both are stored row-major with **row 0 at the top** of the picture and x increasing to the
//! right: pixel `(x, y)` lives at index `y * width + x`. This is the order PNG stores rows in
//! and the order [`Camera`](crate::Camera) numbers pixels in.

use rayon::prelude::*;

use crate::colormap::ScalarStyle;
use crate::error::RenderError;
use crate::window::Window;

/// Largest image, in pixels, that any constructor or PNG reader accepts: 2³⁰ (one gigapixel,
/// 4 GiB as RGBA8).
///
/// The limit is checked before anything is allocated, so a corrupt PNG header claiming a
/// 2³¹ × 2³¹ image is refused instead of exhausting memory. It is far above any picture
/// volmorph renders or warps.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 30;

/// Number of pixels of a `width × height` image, after checking that both are non-zero and
/// that the image stays within [`MAX_IMAGE_PIXELS`] and `volmorph_io`'s allocation cap for
/// `bytes_per_pixel`-byte elements.
pub(crate) fn pixel_count(
    width: u64,
    height: u64,
    bytes_per_pixel: usize,
) -> Result<usize, RenderError> {
    let size_err = |reason| RenderError::Size {
        width,
        height,
        reason,
    };
    if width == 0 || height == 0 {
        return Err(size_err("width and height must be at least 1"));
    }
    match width.checked_mul(height) {
        Some(n) if n <= MAX_IMAGE_PIXELS => {}
        _ => return Err(size_err("more pixels than MAX_IMAGE_PIXELS (2^30)")),
    }
    let w = usize::try_from(width).map_err(|_| size_err("width does not fit in memory"))?;
    let h = usize::try_from(height).map_err(|_| size_err("height does not fit in memory"))?;
    Ok(volmorph_io::checked_len(&[w, h], bytes_per_pixel)?)
}

/// Composite `src` over `dst` (Porter–Duff *source-over*) with **straight** (non-premultiplied)
/// alpha, both 8-bit sRGB-coded as stored; the result is straight alpha too.
///
/// With αs, αd in [0, 1]: α = αs + αd(1 − αs) and each colour channel
/// c = (cs·αs + cd·αd(1 − αs)) / α, rounded to the nearest integer; a fully transparent result
/// is `[0, 0, 0, 0]`. An opaque `src` returns `src`, a transparent `src` returns `dst`, and an
/// opaque `dst` gives an opaque result. Blending is done on the coded values (no
/// linearisation), as PNG viewers and browsers do.
///
/// ```
/// use volmorph_render::blend_over;
/// assert_eq!(blend_over([255, 0, 0, 255], [0, 0, 255, 255]), [255, 0, 0, 255]);
/// assert_eq!(blend_over([255, 0, 0, 0], [0, 0, 255, 255]), [0, 0, 255, 255]);
/// // Half-transparent red over opaque blue: an even purple, still opaque.
/// assert_eq!(blend_over([255, 0, 0, 128], [0, 0, 255, 255]), [128, 0, 127, 255]);
/// ```
#[must_use]
pub fn blend_over(src: [u8; 4], dst: [u8; 4]) -> [u8; 4] {
    let sa = u32::from(src[3]);
    if sa == 255 {
        return src;
    }
    if sa == 0 {
        return dst;
    }
    let da = u32::from(dst[3]);
    // Everything below is in units of 1/255² so the arithmetic stays exact in integers.
    let ws = sa * 255;
    let wd = da * (255 - sa);
    let wa = ws + wd; // output alpha × 255², > 0 because sa > 0
    let mix = |cs: u8, cd: u8| {
        let num = u32::from(cs) * ws + u32::from(cd) * wd;
        // round(num / wa); the quotient is ≤ 255 because it is a convex combination.
        ((2 * num + wa) / (2 * wa)) as u8
    };
    [
        mix(src[0], dst[0]),
        mix(src[1], dst[1]),
        mix(src[2], dst[2]),
        ((wa + 127) / 255) as u8,
    ]
}

/// Rec. ITU-R BT.709 luma of 8-bit sRGB-coded values, in 0‥=255 (weights 0.2126, 0.7152,
/// 0.0722 applied to the coded, not linearised, values — Y′ in the standard's notation).
#[must_use]
pub fn luma709(rgb: [u8; 3]) -> f32 {
    0.2126 * f32::from(rgb[0]) + 0.7152 * f32::from(rgb[1]) + 0.0722 * f32::from(rgb[2])
}

/// An 8-bit RGBA picture with straight (non-premultiplied) alpha, sRGB-coded colour.
///
/// Row-major, **row 0 at the top**, x to the right: pixel `(x, y)` is `pixels()[y * width + x]`.
/// Width and height are at least 1 and `width × height ≤ MAX_IMAGE_PIXELS`; every
/// constructor checks this, so `pixels().len() == width × height` always holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbaImage {
    width: u32,
    height: u32,
    pixels: Vec<[u8; 4]>,
}

impl RgbaImage {
    /// A `width × height` image with every pixel set to `fill`.
    ///
    /// # Errors
    /// [`RenderError::Size`] when a dimension is zero or the image exceeds
    /// [`MAX_IMAGE_PIXELS`].
    pub fn new(width: u32, height: u32, fill: [u8; 4]) -> Result<Self, RenderError> {
        let n = pixel_count(width.into(), height.into(), 4)?;
        Ok(Self {
            width,
            height,
            pixels: vec![fill; n],
        })
    }

    /// Wrap an existing row-major pixel buffer (row 0 at the top).
    ///
    /// # Errors
    /// [`RenderError::Size`] for zero or oversized dimensions, [`RenderError::LengthMismatch`]
    /// when `pixels.len() != width × height`.
    pub fn from_pixels(width: u32, height: u32, pixels: Vec<[u8; 4]>) -> Result<Self, RenderError> {
        check_buffer("pixels", width, height, pixels.len())?;
        Ok(Self {
            width,
            height,
            pixels,
        })
    }

    /// An image whose pixel `(x, y)` is `f(x, y)`, evaluated in parallel over rows (so `f`
    /// must be `Sync`; it is called exactly once per pixel, in no particular order).
    ///
    /// ```
    /// use volmorph_render::RgbaImage;
    /// let img = RgbaImage::from_fn(3, 2, |x, y| [x as u8, y as u8, 0, 255]).unwrap();
    /// assert_eq!(img.get(2, 1), Some([2, 1, 0, 255]));
    /// assert_eq!(img.pixels()[1 * 3 + 2], [2, 1, 0, 255]); // row-major, row 0 on top
    /// ```
    ///
    /// # Errors
    /// [`RenderError::Size`] for zero or oversized dimensions.
    pub fn from_fn<F>(width: u32, height: u32, f: F) -> Result<Self, RenderError>
    where
        F: Fn(u32, u32) -> [u8; 4] + Sync,
    {
        let mut img = Self::new(width, height, [0; 4])?;
        fill_rows(&mut img.pixels, width, f);
        Ok(img)
    }

    /// An opaque grey image from 8-bit grey levels (row-major, row 0 at the top).
    ///
    /// # Errors
    /// [`RenderError::Size`] for zero or oversized dimensions, [`RenderError::LengthMismatch`]
    /// when `grey.len() != width × height`.
    pub fn from_grey8(width: u32, height: u32, grey: &[u8]) -> Result<Self, RenderError> {
        check_buffer("grey", width, height, grey.len())?;
        Ok(Self {
            width,
            height,
            pixels: grey.iter().map(|&g| [g, g, g, 255]).collect(),
        })
    }

    /// Width in pixels (≥ 1).
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels (≥ 1).
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// All pixels, row-major, row 0 at the top.
    #[must_use]
    pub fn pixels(&self) -> &[[u8; 4]] {
        &self.pixels
    }

    /// All pixels, mutable (the length cannot change).
    pub fn pixels_mut(&mut self) -> &mut [[u8; 4]] {
        &mut self.pixels
    }

    /// The pixel buffer, consuming the image.
    #[must_use]
    pub fn into_pixels(self) -> Vec<[u8; 4]> {
        self.pixels
    }

    /// The pixels as interleaved bytes `r, g, b, a, r, g, b, a, …` (the layout of an RGBA8 PNG).
    #[must_use]
    pub fn as_bytes(&self) -> &[u8] {
        self.pixels.as_flattened()
    }

    /// Row `y` (0 = top), or `None` when `y ≥ height`.
    #[must_use]
    pub fn row(&self, y: u32) -> Option<&[[u8; 4]]> {
        self.pixels
            .chunks_exact(self.width as usize)
            .nth(y as usize)
    }

    fn index(&self, x: u32, y: u32) -> Option<usize> {
        (x < self.width && y < self.height).then(|| y as usize * self.width as usize + x as usize)
    }

    /// Pixel `(x, y)` (x to the right, y down from the top row), or `None` outside the image.
    #[must_use]
    pub fn get(&self, x: u32, y: u32) -> Option<[u8; 4]> {
        self.index(x, y).and_then(|i| self.pixels.get(i).copied())
    }

    /// Overwrite pixel `(x, y)` with `p`. Returns `false` (and changes nothing) when the pixel
    /// is outside the image, so drawing code can clip by ignoring the result.
    pub fn put(&mut self, x: u32, y: u32, p: [u8; 4]) -> bool {
        match self.index(x, y).and_then(|i| self.pixels.get_mut(i)) {
            Some(q) => {
                *q = p;
                true
            }
            None => false,
        }
    }

    /// Composite `p` over pixel `(x, y)` with [`blend_over`]. Returns `false` (and changes
    /// nothing) outside the image.
    pub fn blend(&mut self, x: u32, y: u32, p: [u8; 4]) -> bool {
        match self.index(x, y).and_then(|i| self.pixels.get_mut(i)) {
            Some(q) => {
                *q = blend_over(p, *q);
                true
            }
            None => false,
        }
    }

    /// Set every pixel to `p`.
    pub fn fill(&mut self, p: [u8; 4]) {
        self.pixels.fill(p);
    }

    /// Mirror the image top-to-bottom in place (for sources whose rows run bottom-up, such as
    /// slices indexed with y increasing upwards).
    pub fn flip_vertical(&mut self) {
        let w = self.width as usize;
        let h = self.height as usize;
        for y in 0..h / 2 {
            let (top, bottom) = self.pixels.split_at_mut((h - 1 - y) * w);
            top[y * w..(y + 1) * w].swap_with_slice(&mut bottom[..w]);
        }
    }

    /// This image composited over a uniform `background` with [`blend_over`]: the picture as
    /// seen on that background. An opaque background gives an opaque result.
    ///
    /// ```
    /// use volmorph_render::RgbaImage;
    /// let img = RgbaImage::new(2, 2, [255, 255, 255, 0]).unwrap();
    /// let on_black = img.composite_over([0, 0, 0, 255]);
    /// assert!(on_black.pixels().iter().all(|&p| p == [0, 0, 0, 255]));
    /// ```
    #[must_use]
    pub fn composite_over(&self, background: [u8; 4]) -> Self {
        let mut out = self.clone();
        out.pixels
            .par_chunks_mut(self.width as usize)
            .for_each(|row| row.iter_mut().for_each(|p| *p = blend_over(*p, background)));
        out
    }

    /// Composite `top` (same size) over this image, pixel by pixel, with [`blend_over`] —
    /// layering an overlay (handles, a second modality) onto a picture.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when the sizes differ.
    pub fn draw_over(&mut self, top: &RgbaImage) -> Result<(), RenderError> {
        if (top.width, top.height) != (self.width, self.height) {
            return Err(RenderError::invalid(format!(
                "overlay is {}×{} but the image is {}×{}",
                top.width, top.height, self.width, self.height
            )));
        }
        let w = self.width as usize;
        self.pixels
            .par_chunks_mut(w)
            .zip(top.pixels.par_chunks(w))
            .for_each(|(dst, src)| {
                for (d, &s) in dst.iter_mut().zip(src) {
                    *d = blend_over(s, *d);
                }
            });
        Ok(())
    }

    /// This image magnified by factors `fx`, `fy` ≥ 1 along x and y with nearest-neighbour
    /// sampling (crisp voxels, as slice viewers show them): the output is
    /// `round(width·fx) × round(height·fy)` pixels, and output pixel `(x, y)` takes the input
    /// pixel under its centre.
    ///
    /// ```
    /// use volmorph_render::RgbaImage;
    /// let img = RgbaImage::from_fn(2, 1, |x, _| [x as u8, 0, 0, 255]).unwrap();
    /// let big = img.resize_nearest(3.0, 2.0).unwrap();
    /// assert_eq!((big.width(), big.height()), (6, 2));
    /// assert_eq!(big.get(2, 1), Some([0, 0, 0, 255]));
    /// assert_eq!(big.get(3, 0), Some([1, 0, 0, 255]));
    /// ```
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for a factor below 1 or not finite;
    /// [`RenderError::Size`] when the result exceeds [`MAX_IMAGE_PIXELS`] or 65535 pixels on
    /// a side (more than any screen shows).
    pub fn resize_nearest(&self, fx: f64, fy: f64) -> Result<Self, RenderError> {
        if !(fx >= 1.0 && fy >= 1.0 && fx.is_finite() && fy.is_finite()) {
            return Err(RenderError::invalid(format!(
                "magnification {fx} × {fy} must be finite and at least 1"
            )));
        }
        if fx == 1.0 && fy == 1.0 {
            return Ok(self.clone());
        }
        let (iw, ih) = (self.width, self.height);
        let w = (f64::from(iw) * fx).round();
        let h = (f64::from(ih) * fy).round();
        if !(w <= f64::from(u16::MAX) && h <= f64::from(u16::MAX)) {
            return Err(RenderError::Size {
                width: w as u64,
                height: h as u64,
                reason: "a magnified picture is limited to 65535 pixels on a side",
            });
        }
        let (w, h) = ((w as u32).max(1), (h as u32).max(1));
        Self::from_fn(w, h, |x, y| {
            let sx = ((f64::from(x) + 0.5) / fx) as u32;
            let sy = ((f64::from(y) + 0.5) / fy) as u32;
            self.pixels[(sy.min(ih - 1) * iw + sx.min(iw - 1)) as usize]
        })
    }

    /// Opaque RGB pixels: the image composited over the opaque `background` colour, alpha
    /// dropped (for RGB PNG output).
    #[must_use]
    pub fn to_rgb(&self, background: [u8; 3]) -> Vec<[u8; 3]> {
        let bg = [background[0], background[1], background[2], 255];
        self.pixels
            .iter()
            .map(|&p| {
                let q = blend_over(p, bg);
                [q[0], q[1], q[2]]
            })
            .collect()
    }
}

/// Peak signal-to-noise ratio of `b` against `a`, in dB, over the R, G, B and A channels of
/// the 8-bit pixels: `10·log10(255² / MSE)`; infinite for identical pictures.
///
/// ```
/// use volmorph_render::{RgbaImage, psnr};
/// let a = RgbaImage::new(4, 4, [100, 100, 100, 255]).unwrap();
/// let mut b = a.clone();
/// assert!(psnr(&a, &b).unwrap().is_infinite());
/// b.put(0, 0, [110, 100, 100, 255]);
/// // One channel of 64 off by 10: MSE = 100 / 64.
/// let want = 10.0 * (255.0f64 * 255.0 * 64.0 / 100.0).log10();
/// assert!((psnr(&a, &b).unwrap() - want).abs() < 1e-9);
/// ```
///
/// # Errors
/// [`RenderError::InvalidArgument`] when the sizes differ.
pub fn psnr(a: &RgbaImage, b: &RgbaImage) -> Result<f64, RenderError> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(RenderError::invalid(format!(
            "cannot compare a {}×{} picture with a {}×{} one",
            a.width, a.height, b.width, b.height
        )));
    }
    let sum: f64 = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .flat_map(|(p, q)| (0..4).map(move |c| f64::from(p[c]) - f64::from(q[c])))
        .map(|d| d * d)
        .sum();
    let mse = sum / (4 * a.pixels.len()) as f64;
    Ok(if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0 * 255.0 / mse).log10()
    })
}

/// A single-channel f32 picture that renderers accumulate into (ray-cast intensities,
/// Jacobian determinants, slice samples) before mapping it to colour.
///
/// Same layout as [`RgbaImage`]: row-major, **row 0 at the top**, value `(x, y)` at
/// `values()[y * width + x]`, width and height ≥ 1. Values may be any f32, including NaN
/// (meaning "no value", e.g. outside the volume); mappings document what NaN becomes.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarImage {
    width: u32,
    height: u32,
    values: Vec<f32>,
}

impl ScalarImage {
    /// A `width × height` image with every value set to `value`.
    ///
    /// # Errors
    /// [`RenderError::Size`] for zero or oversized dimensions.
    pub fn new(width: u32, height: u32, value: f32) -> Result<Self, RenderError> {
        let n = pixel_count(width.into(), height.into(), 4)?;
        Ok(Self {
            width,
            height,
            values: vec![value; n],
        })
    }

    /// Wrap an existing row-major value buffer (row 0 at the top).
    ///
    /// # Errors
    /// [`RenderError::Size`] for zero or oversized dimensions, [`RenderError::LengthMismatch`]
    /// when `values.len() != width × height`.
    pub fn from_values(width: u32, height: u32, values: Vec<f32>) -> Result<Self, RenderError> {
        check_buffer("values", width, height, values.len())?;
        Ok(Self {
            width,
            height,
            values,
        })
    }

    /// An image whose value `(x, y)` is `f(x, y)`, evaluated in parallel over rows.
    ///
    /// # Errors
    /// [`RenderError::Size`] for zero or oversized dimensions.
    pub fn from_fn<F>(width: u32, height: u32, f: F) -> Result<Self, RenderError>
    where
        F: Fn(u32, u32) -> f32 + Sync,
    {
        let mut img = Self::new(width, height, 0.0)?;
        fill_rows(&mut img.values, width, f);
        Ok(img)
    }

    /// The BT.709 luma ([`luma709`], 0‥=255) of each pixel of `img`, ignoring alpha — the grey
    /// levels of a picture read from PNG, ready for resampling.
    #[must_use]
    pub fn luma_of(img: &RgbaImage) -> Self {
        Self {
            width: img.width,
            height: img.height,
            values: img
                .pixels
                .iter()
                .map(|p| luma709([p[0], p[1], p[2]]))
                .collect(),
        }
    }

    /// Width in pixels (≥ 1).
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels (≥ 1).
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// All values, row-major, row 0 at the top.
    #[must_use]
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// All values, mutable (the length cannot change).
    pub fn values_mut(&mut self) -> &mut [f32] {
        &mut self.values
    }

    /// The value buffer, consuming the image.
    #[must_use]
    pub fn into_values(self) -> Vec<f32> {
        self.values
    }

    fn index(&self, x: u32, y: u32) -> Option<usize> {
        (x < self.width && y < self.height).then(|| y as usize * self.width as usize + x as usize)
    }

    /// Value `(x, y)` (x to the right, y down from the top row), or `None` outside the image.
    #[must_use]
    pub fn get(&self, x: u32, y: u32) -> Option<f32> {
        self.index(x, y).and_then(|i| self.values.get(i).copied())
    }

    /// Overwrite value `(x, y)`. Returns `false` (and changes nothing) outside the image.
    pub fn put(&mut self, x: u32, y: u32, v: f32) -> bool {
        match self.index(x, y).and_then(|i| self.values.get_mut(i)) {
            Some(q) => {
                *q = v;
                true
            }
            None => false,
        }
    }

    /// Add `v` to value `(x, y)` (splatting, accumulation). Returns `false` outside the image.
    pub fn add(&mut self, x: u32, y: u32, v: f32) -> bool {
        match self.index(x, y).and_then(|i| self.values.get_mut(i)) {
            Some(q) => {
                *q += v;
                true
            }
            None => false,
        }
    }

    /// Set every value to `v`.
    pub fn fill(&mut self, v: f32) {
        self.values.fill(v);
    }

    /// Smallest and largest finite value, or `None` when no value is finite.
    #[must_use]
    pub fn finite_range(&self) -> Option<(f32, f32)> {
        finite_range(&self.values)
    }

    /// Map the values to colour with `style` (window, colour map, NaN colour, diverging
    /// centre); see [`render_scalar_with`](crate::render_scalar_with).
    #[must_use]
    pub fn to_rgba(&self, style: &ScalarStyle) -> RgbaImage {
        let mut pixels = vec![[0u8; 4]; self.values.len()];
        style.map_into(&self.values, &mut pixels, self.width as usize);
        RgbaImage {
            width: self.width,
            height: self.height,
            pixels,
        }
    }

    /// 8-bit grey levels `round(255 · window(v))`; NaN becomes 0.
    #[must_use]
    pub fn to_grey8(&self, window: &Window) -> Vec<u8> {
        let norm = window.normalizer();
        self.values
            .par_iter()
            .map(|&v| norm.apply(v).map_or(0, |t| (t * 255.0 + 0.5) as u8))
            .collect()
    }

    /// 16-bit grey levels `round(65535 · window(v))`; NaN becomes 0.
    #[must_use]
    pub fn to_grey16(&self, window: &Window) -> Vec<u16> {
        let norm = window.normalizer();
        self.values
            .par_iter()
            .map(|&v| {
                norm.apply(v)
                    .map_or(0, |t| (f64::from(t) * 65535.0 + 0.5) as u16)
            })
            .collect()
    }
}

/// Smallest and largest finite value of `values`, or `None` when none is finite.
#[must_use]
pub fn finite_range(values: &[f32]) -> Option<(f32, f32)> {
    values
        .iter()
        .filter(|v| v.is_finite())
        .fold(None, |acc, &v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })
}

/// Set `buf[y·width + x] = f(x, y)` for every element of the row-major `buf`, in parallel
/// over rows (`f` is called exactly once per element, in no particular order).
fn fill_rows<P: Send>(buf: &mut [P], width: u32, f: impl Fn(u32, u32) -> P + Sync) {
    buf.par_chunks_mut(width as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, p) in row.iter_mut().enumerate() {
                *p = f(x as u32, y as u32);
            }
        });
}

/// Check the dimensions (as [`pixel_count`]) and that a buffer of `len` elements named
/// `what` holds exactly `width × height` of them.
///
/// # Errors
/// [`RenderError::Size`] or [`RenderError::LengthMismatch`].
fn check_buffer(
    what: &'static str,
    width: u32,
    height: u32,
    len: usize,
) -> Result<(), RenderError> {
    let n = pixel_count(width.into(), height.into(), 4)?;
    check_len(what, width, height, n, len)
}

pub(crate) fn check_len(
    what: &'static str,
    width: u32,
    height: u32,
    expected: usize,
    got: usize,
) -> Result<(), RenderError> {
    if expected == got {
        Ok(())
    } else {
        Err(RenderError::LengthMismatch {
            what,
            width,
            height,
            expected,
            got,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn blend_over_hand_values_and_identities() {
        let red = [255, 0, 0, 255];
        let blue = [0, 0, 255, 255];
        assert_eq!(blend_over(red, blue), red);
        assert_eq!(blend_over([1, 2, 3, 0], blue), blue);
        // 25 % white over opaque black: 63.75 → 64.
        assert_eq!(
            blend_over([255, 255, 255, 64], [0, 0, 0, 255]),
            [64, 64, 64, 255]
        );
        // Two half-transparent layers: α = 0.5 + 0.5·0.5 = 0.75; red weight 2/3.
        let c = blend_over([255, 0, 0, 255 / 2 + 1], [0, 0, 255, 255 / 2 + 1]);
        assert_eq!(c[3], 192);
        assert!((i32::from(c[0]) - 170).abs() <= 1 && (i32::from(c[2]) - 85).abs() <= 1);
        // Nothing over nothing stays nothing.
        assert_eq!(blend_over([0; 4], [0; 4]), [0; 4]);
    }

    proptest! {
        #[test]
        fn blend_over_properties(src in any::<[u8; 4]>(), dst in any::<[u8; 4]>()) {
            let out = blend_over(src, dst);
            // Output alpha is the Porter–Duff α, never below either input's.
            let a = f64::from(src[3]) / 255.0;
            let b = f64::from(dst[3]) / 255.0;
            let expect = 255.0 * (a + b * (1.0 - a));
            prop_assert!((f64::from(out[3]) - expect).abs() <= 0.5 + 1e-9);
            prop_assert!(out[3] >= src[3].max(dst[3]));
            // Over a transparent background the source is unchanged.
            prop_assert_eq!(blend_over(src, [dst[0], dst[1], dst[2], 0]),
                            if src[3] == 0 { [dst[0], dst[1], dst[2], 0] } else { src });
            // Colour is a convex combination of the inputs.
            for c in 0..3 {
                prop_assert!(out[c] >= src[c].min(dst[c]) && out[c] <= src[c].max(dst[c]));
            }
            if dst[3] == 255 {
                prop_assert_eq!(out[3], 255);
            }
        }
    }

    #[test]
    fn layout_is_row_major_top_row_first() {
        let img = RgbaImage::from_fn(4, 3, |x, y| [x as u8, y as u8, 0, 255]).unwrap();
        assert_eq!(img.pixels().len(), 12);
        for y in 0..3 {
            for x in 0..4 {
                assert_eq!(
                    img.pixels()[(y * 4 + x) as usize],
                    [x as u8, y as u8, 0, 255]
                );
                assert_eq!(img.get(x, y), Some([x as u8, y as u8, 0, 255]));
            }
        }
        assert_eq!(img.row(2).unwrap()[3], [3, 2, 0, 255]);
        assert_eq!(img.row(3), None);
        assert_eq!(img.get(4, 0), None);
        assert_eq!(img.get(0, 3), None);
        assert_eq!(&img.as_bytes()[4..8], &[1, 0, 0, 255]);
    }

    #[test]
    fn put_blend_fill_and_flip() {
        let mut img = RgbaImage::new(3, 3, [0, 0, 0, 255]).unwrap();
        assert!(img.put(2, 1, [9, 9, 9, 255]));
        assert!(!img.put(3, 1, [9, 9, 9, 255]));
        assert!(!img.blend(0, 7, [9, 9, 9, 255]));
        assert!(img.blend(0, 0, [255, 255, 255, 128]));
        assert_eq!(img.get(0, 0), Some([128, 128, 128, 255]));
        assert_eq!(img.get(2, 1), Some([9, 9, 9, 255]));

        let mut f = RgbaImage::from_fn(2, 5, |x, y| [x as u8, y as u8, 1, 2]).unwrap();
        let orig = f.clone();
        f.flip_vertical();
        for y in 0..5 {
            assert_eq!(f.row(y), orig.row(4 - y));
        }
        f.flip_vertical();
        assert_eq!(f, orig);

        img.fill([1, 2, 3, 4]);
        assert!(img.pixels().iter().all(|&p| p == [1, 2, 3, 4]));
    }

    #[test]
    fn sizes_are_checked_before_allocation() {
        assert!(matches!(
            RgbaImage::new(0, 5, [0; 4]),
            Err(RenderError::Size { .. })
        ));
        assert!(matches!(
            RgbaImage::new(1 << 20, 1 << 20, [0; 4]),
            Err(RenderError::Size { .. })
        ));
        assert!(matches!(
            ScalarImage::new(u32::MAX, u32::MAX, 0.0),
            Err(RenderError::Size { .. })
        ));
        assert!(matches!(
            RgbaImage::from_pixels(2, 2, vec![[0; 4]; 3]),
            Err(RenderError::LengthMismatch {
                expected: 4,
                got: 3,
                ..
            })
        ));
        assert!(ScalarImage::from_values(3, 2, vec![0.0; 5]).is_err());
        assert!(RgbaImage::from_grey8(3, 2, &[0; 7]).is_err());
    }

    #[test]
    fn compositing_images() {
        let top =
            RgbaImage::from_fn(2, 1, |x, _| [255, 0, 0, if x == 0 { 255 } else { 0 }]).unwrap();
        let flat = top.composite_over([0, 0, 255, 255]);
        assert_eq!(flat.pixels(), &[[255, 0, 0, 255], [0, 0, 255, 255]]);
        assert_eq!(top.to_rgb([0, 255, 0]), vec![[255, 0, 0], [0, 255, 0]]);

        let mut base = RgbaImage::new(2, 1, [0, 0, 255, 255]).unwrap();
        base.draw_over(&top).unwrap();
        assert_eq!(base, flat);
        let wrong = RgbaImage::new(1, 2, [0; 4]).unwrap();
        assert!(matches!(
            base.draw_over(&wrong),
            Err(RenderError::InvalidArgument(_))
        ));

        let grey = RgbaImage::from_grey8(2, 1, &[7, 200]).unwrap();
        assert_eq!(grey.pixels(), &[[7, 7, 7, 255], [200, 200, 200, 255]]);
    }

    #[test]
    fn scalar_image_accumulates_and_converts() {
        let mut s = ScalarImage::new(3, 2, 0.0).unwrap();
        assert!(s.add(1, 1, 2.0));
        assert!(s.add(1, 1, 0.5));
        assert!(!s.add(3, 0, 1.0));
        assert!(s.put(0, 0, f32::NAN));
        assert!(s.put(2, 0, -4.0));
        assert_eq!(s.get(1, 1), Some(2.5));
        assert_eq!(s.values()[4], 2.5);
        assert_eq!(s.finite_range(), Some((-4.0, 2.5)));
        assert_eq!(finite_range(&[f32::NAN, f32::INFINITY]), None);

        let w = Window::from_range(0.0, 2.0).unwrap();
        let s = ScalarImage::from_values(5, 1, vec![f32::NAN, -1.0, 0.5, 1.0, 9.0]).unwrap();
        assert_eq!(s.to_grey8(&w), vec![0, 0, 64, 128, 255]);
        assert_eq!(s.to_grey16(&w), vec![0, 0, 16384, 32768, 65535]);

        let f = ScalarImage::from_fn(4, 3, |x, y| (x * 10 + y) as f32).unwrap();
        assert_eq!(f.get(3, 2), Some(32.0));
        assert_eq!(f.values()[2 * 4 + 3], 32.0);

        let rgba =
            RgbaImage::from_pixels(2, 1, vec![[255, 255, 255, 0], [255, 0, 0, 255]]).unwrap();
        let l = ScalarImage::luma_of(&rgba);
        assert!((l.values()[0] - 255.0).abs() < 1e-3);
        assert!((l.values()[1] - 0.2126 * 255.0).abs() < 1e-3);
    }
}
