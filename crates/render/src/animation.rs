//! Animations as single files: animated PNG (APNG) and animated GIF, chosen by extension.
//!
//! * [`AnimationFormat::from_path`] — `.png` / `.apng` → [`AnimationFormat::Apng`], `.gif` →
//!   [`AnimationFormat::Gif`], any other extension (or none) → `None`, which callers take to
//!   mean a folder of numbered frames.
//! * [`write_animation`] — write frames in the format the path names.
//! * [`write_gif`] — GIF89a looping forever. GIF holds at most 256 colours, so the frames share
//!   one **global palette**: the exact colours when all frames together use at most 256 (a
//!   lossless GIF), else a palette learned by **NeuQuant** (Dekker 1994, the `color_quant`
//!   crate the `gif` crate uses) from a sample of up to [`GIF_TRAINING_PIXELS`] pixels spread
//!   evenly over all frames, every pixel then taking its nearest palette entry. One palette for
//!   every frame keeps colours from flickering between frames. GIF has no partial
//!   transparency: pixels are composited over white first.
//!
//! [`write_apng`] keeps full 8-bit RGBA colour and alpha; GIF trades colour for the widest
//! support (every browser, chat client and slide program plays it).

use std::collections::HashMap;
use std::path::Path;

use volmorph_io::write_atomic;

use crate::error::RenderError;
use crate::image::RgbaImage;
use crate::png_file::{MAX_APNG_FRAMES, write_apng};

/// Largest number of pixels NeuQuant learns a GIF palette from (2²⁰); a longer animation is
/// sampled evenly. NeuQuant itself looks at one pixel in [`GIF_NEUQUANT_SAMPLE_FACTOR`].
pub const GIF_TRAINING_PIXELS: usize = 1 << 20;

/// NeuQuant's sampling factor for GIF palettes of long animations: 10, the speed/quality
/// compromise its author and the `gif` crate recommend (1 = best, 30 = fastest). Samples of at
/// most [`GIF_FULL_QUALITY_PIXELS`] pixels are learned at factor 1 (every pixel), where the
/// network would otherwise see too few pixels to settle.
pub const GIF_NEUQUANT_SAMPLE_FACTOR: i32 = 10;

/// Largest sample (pixels) learned at NeuQuant's best sampling factor 1 (2¹⁸).
pub const GIF_FULL_QUALITY_PIXELS: usize = 1 << 18;

/// Colour that transparent parts of frames are composited over in a GIF (white).
pub const GIF_BACKGROUND: [u8; 3] = [255, 255, 255];

/// A single-file animation format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnimationFormat {
    /// Animated PNG (`.png`, `.apng`): 8-bit RGBA, lossless.
    Apng,
    /// Animated GIF (`.gif`): 256 colours, 1/100 s timing.
    Gif,
}

/// The extensions of single-file animations ([`write_animation`]): `.png`, `.apng` (animated
/// PNG) and `.gif`.
pub const ANIMATION_EXTENSIONS: &[&str] =
    volmorph_io::extension::OutputFormat::Animation.extensions();

impl AnimationFormat {
    /// The format named by `path`'s extension (case-insensitive, one of
    /// [`ANIMATION_EXTENSIONS`]), or `None` when it names none of them (callers write a folder
    /// of frames then).
    #[must_use]
    pub fn from_path(path: &Path) -> Option<Self> {
        match volmorph_io::extension::matching(path, ANIMATION_EXTENSIONS)? {
            "gif" => Some(Self::Gif),
            _ => Some(Self::Apng),
        }
    }

    /// The format of an animation output file, checked before any frame is rendered.
    ///
    /// # Errors
    /// [`RenderError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
    /// extension found and [`ANIMATION_EXTENSIONS`].
    pub fn for_output(path: &Path) -> Result<Self, RenderError> {
        Self::from_path(path)
            .ok_or_else(|| volmorph_io::extension::refused(path, ANIMATION_EXTENSIONS).into())
    }

    /// What the format is called in messages: "animated PNG" or "animated GIF".
    #[must_use]
    pub fn description(self) -> &'static str {
        match self {
            Self::Apng => "animated PNG",
            Self::Gif => "animated GIF",
        }
    }
}

/// Picture and video extensions that look like an animation file but that volmorph cannot
/// write; an output folder of frames with one of them is refused rather than created
/// ([`check_frames_folder`]).
pub const UNWRITABLE_ANIMATION_EXTENSIONS: [&str; 11] = [
    "jpg", "jpeg", "tif", "tiff", "webp", "bmp", "mp4", "mov", "avi", "mkv", "webm",
];

/// Refuse `path` as a folder of numbered frames when its extension (case-insensitive) names
/// a picture or video format in [`UNWRITABLE_ANIMATION_EXTENSIONS`] (`.jpg`, `.mp4`, …): the
/// user meant a file, and would otherwise get a folder of that name. Paths whose extension
/// [`AnimationFormat::from_path`] knows are written as files and never reach this check.
///
/// # Errors
/// [`RenderError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
/// extension found and [`ANIMATION_EXTENSIONS`] (or a folder).
pub fn check_frames_folder(path: &Path) -> Result<(), RenderError> {
    if volmorph_io::extension::matching(path, &UNWRITABLE_ANIMATION_EXTENSIONS).is_some() {
        return Err(volmorph_io::extension::refused(path, ANIMATION_EXTENSIONS).into());
    }
    Ok(())
}

/// Check an animation output before any frame is rendered: a file whose extension is one of
/// [`ANIMATION_EXTENSIONS`], or a folder for numbered frames ([`check_frames_folder`]).
///
/// # Errors
/// As [`check_frames_folder`].
pub fn check_animation_output(path: &Path) -> Result<(), RenderError> {
    match AnimationFormat::from_path(path) {
        Some(_) => Ok(()),
        None => check_frames_folder(path),
    }
}

/// Write `frames` (all the same size) as one animation file at `path` in the format its
/// extension names ([`AnimationFormat::from_path`]), looping forever, each frame shown for
/// `delay_ms` milliseconds (a GIF rounds it to 1/100 s, at least 1/100 s).
///
/// # Errors
/// [`RenderError::Io`] with [`volmorph_io::IoError::Extension`] for an extension that is not
/// `.png`, `.apng` or `.gif` ([`AnimationFormat::for_output`]), and as [`write_apng`] or
/// [`write_gif`]. Errors name `path`; on error no file is left there.
pub fn write_animation(
    path: &Path,
    frames: &[RgbaImage],
    delay_ms: u32,
) -> Result<(), RenderError> {
    match AnimationFormat::for_output(path)? {
        AnimationFormat::Apng => write_apng(path, frames, delay_ms),
        AnimationFormat::Gif => write_gif(path, frames, delay_ms),
    }
}

/// Check what every animation writer requires: at least one frame, at most
/// [`MAX_APNG_FRAMES`], equal sizes, a delay in 1‥=65535 ms.
fn check_frames(frames: &[RgbaImage], delay_ms: u32) -> Result<(u32, u32), RenderError> {
    let Some(first) = frames.first() else {
        return Err(RenderError::invalid(
            "an animation needs at least one frame",
        ));
    };
    if frames.len() > MAX_APNG_FRAMES {
        return Err(RenderError::invalid(format!(
            "{} frames is more than an animation may hold ({MAX_APNG_FRAMES})",
            frames.len()
        )));
    }
    let size = (first.width(), first.height());
    if let Some(f) = frames.iter().find(|f| (f.width(), f.height()) != size) {
        return Err(RenderError::invalid(format!(
            "animation frames differ in size: {}×{} and {}×{}",
            size.0,
            size.1,
            f.width(),
            f.height()
        )));
    }
    if !(1..=u32::from(u16::MAX)).contains(&delay_ms) {
        return Err(RenderError::invalid(format!(
            "frame delay {delay_ms} ms must be 1 to 65535"
        )));
    }
    Ok(size)
}

/// A global palette (`r g b` triples, at most 256) for `frames` (opaque RGB) and the index
/// of every pixel of every frame in it.
fn quantise(frames: &[Vec<[u8; 3]>]) -> (Vec<u8>, Vec<Vec<u8>>) {
    // Exact palette when the colours fit.
    let mut exact: HashMap<[u8; 3], u8> = HashMap::new();
    let fits = frames.iter().flatten().all(|c| {
        if exact.contains_key(c) {
            return true;
        }
        if exact.len() == 256 {
            return false;
        }
        let n = exact.len() as u8;
        exact.insert(*c, n);
        true
    });
    if fits {
        let mut palette = vec![0u8; exact.len() * 3];
        for (c, &i) in &exact {
            palette[usize::from(i) * 3..][..3].copy_from_slice(c);
        }
        let indices = frames
            .iter()
            .map(|f| f.iter().map(|c| exact[c]).collect())
            .collect();
        return (palette, indices);
    }
    // NeuQuant on an even sample of all frames.
    let total: usize = frames.iter().map(Vec::len).sum();
    let stride = total.div_ceil(GIF_TRAINING_PIXELS).max(1);
    let mut sample = Vec::with_capacity(4 * total.div_ceil(stride));
    for c in frames.iter().flatten().step_by(stride) {
        sample.extend_from_slice(&[c[0], c[1], c[2], 255]);
    }
    let factor = if sample.len() / 4 <= GIF_FULL_QUALITY_PIXELS {
        1
    } else {
        GIF_NEUQUANT_SAMPLE_FACTOR
    };
    let nq = color_quant::NeuQuant::new(factor, 256, &sample);
    let palette = nq.color_map_rgb();
    let mut cache: HashMap<[u8; 3], u8> = HashMap::new();
    let indices = frames
        .iter()
        .map(|f| {
            f.iter()
                .map(|c| {
                    *cache
                        .entry(*c)
                        .or_insert_with(|| nq.index_of(&[c[0], c[1], c[2], 255]) as u8)
                })
                .collect()
        })
        .collect();
    (palette, indices)
}

/// Write `frames` (all the same size, at most 65535 pixels a side) as an animated GIF that
/// loops forever, each frame shown for `delay_ms` milliseconds rounded to the nearest 1/100 s
/// (at least 1/100 s), with one global palette (see the [module documentation](self)).
///
/// # Errors
/// [`RenderError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in
/// `.gif`; [`RenderError::InvalidArgument`] for no frames, more than [`MAX_APNG_FRAMES`],
/// frames of different sizes or larger than 65535 pixels a side, or a delay outside
/// 1‥=65535 ms;
/// [`RenderError::GifEncode`] or [`RenderError::Io`] when encoding or writing fails. Errors
/// name `path`; on error no file is left there.
pub fn write_gif(path: &Path, frames: &[RgbaImage], delay_ms: u32) -> Result<(), RenderError> {
    volmorph_io::extension::check(path, &["gif"])?;
    let check = || -> Result<(u16, u16), RenderError> {
        let (w, h) = check_frames(frames, delay_ms)?;
        match (u16::try_from(w), u16::try_from(h)) {
            (Ok(w), Ok(h)) => Ok((w, h)),
            _ => Err(RenderError::invalid(format!(
                "a GIF is at most 65535 pixels a side, not {w}×{h}"
            ))),
        }
    };
    let (w, h) = check().map_err(|e| e.at(path))?;
    let rgb: Vec<Vec<[u8; 3]>> = frames.iter().map(|f| f.to_rgb(GIF_BACKGROUND)).collect();
    let (palette, indices) = quantise(&rgb);
    let delay = ((delay_ms + 5) / 10).clamp(1, u32::from(u16::MAX)) as u16;
    write_atomic(path, |out| -> Result<(), RenderError> {
        let mut enc = gif::Encoder::new(&mut *out, w, h, &palette)?;
        enc.set_repeat(gif::Repeat::Infinite)?;
        for px in indices {
            let mut frame = gif::Frame::from_indexed_pixels(w, h, px, None);
            frame.delay = delay;
            enc.write_frame(&frame)?;
        }
        enc.into_inner()?; // writes the trailer
        Ok(())
    })
    .map_err(|e: RenderError| e.at(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(n: usize, colours: bool) -> Vec<RgbaImage> {
        (0..n)
            .map(|i| {
                RgbaImage::from_fn(40, 30, |x, y| {
                    if colours {
                        // Thousands of colours: NeuQuant.
                        [(x * 6) as u8, (y * 8) as u8, (i * 40) as u8, 255]
                    } else {
                        // A moving square on grey: few colours, exact palette.
                        let inside = (x as usize).abs_diff(5 + 5 * i) < 4 && y < 10;
                        if inside {
                            [200, 30, 30, 255]
                        } else {
                            [90, 90, 90, 255]
                        }
                    }
                })
                .unwrap()
            })
            .collect()
    }

    fn decode(path: &Path) -> (Vec<Vec<u8>>, Vec<u16>) {
        let mut opts = gif::DecodeOptions::new();
        opts.set_color_output(gif::ColorOutput::RGBA);
        let mut d = opts.read_info(std::fs::File::open(path).unwrap()).unwrap();
        let mut out = Vec::new();
        let mut delays = Vec::new();
        while let Some(f) = d.read_next_frame().unwrap() {
            out.push(f.buffer.to_vec());
            delays.push(f.delay);
        }
        (out, delays)
    }

    #[test]
    fn few_colours_give_an_exact_gif() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.gif");
        let f = frames(4, false);
        write_animation(&p, &f, 80).unwrap();
        let (decoded, delays) = decode(&p);
        assert_eq!(decoded.len(), 4);
        assert_eq!(delays, vec![8; 4]);
        for (d, f) in decoded.iter().zip(&f) {
            assert_eq!(d.as_slice(), f.as_bytes(), "lossless with ≤ 256 colours");
        }
        assert_ne!(decoded[0], decoded[1]);
    }

    #[test]
    fn many_colours_are_quantised_closely() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("b.GIF");
        let f = frames(3, true);
        write_gif(&p, &f, 40).unwrap();
        let (decoded, _) = decode(&p);
        assert_eq!(decoded.len(), 3);
        for (d, f) in decoded.iter().zip(&f) {
            let err: f64 = d
                .iter()
                .zip(f.as_bytes())
                .map(|(a, b)| f64::from(a.abs_diff(*b)))
                .sum::<f64>()
                / d.len() as f64;
            assert!(err < 12.0, "mean error {err} per channel");
        }
        assert_ne!(decoded[0], decoded[2]);
    }

    #[test]
    fn formats_by_extension_and_bad_input() {
        use std::path::PathBuf;
        let fmt = |s: &str| AnimationFormat::from_path(&PathBuf::from(s));
        assert_eq!(fmt("m.png"), Some(AnimationFormat::Apng));
        assert_eq!(fmt("m.APNG"), Some(AnimationFormat::Apng));
        assert_eq!(fmt("m.gif"), Some(AnimationFormat::Gif));
        assert_eq!(fmt("frames"), None);
        assert_eq!(fmt("m.mp4"), None);
        let dir = tempfile::tempdir().unwrap();
        let f = frames(2, false);
        let bad = dir.path().join("m.mp4");
        let e = write_animation(&bad, &f, 50).unwrap_err().to_string();
        assert!(e.contains("m.mp4") && e.contains(".gif"), "{e}");
        assert!(!bad.exists());
        // A GIF writer takes only .gif; a folder of frames no picture extension.
        assert!(write_gif(&dir.path().join("m.png"), &f, 50).is_err());
        assert!(check_frames_folder(&dir.path().join("frames.JPG")).is_err());
        assert!(check_animation_output(&dir.path().join("frames")).is_ok());
        assert!(check_animation_output(&dir.path().join("m.Gif")).is_ok());
        let p = dir.path().join("c.gif");
        assert!(write_gif(&p, &[], 50).is_err());
        assert!(write_gif(&p, &f, 0).is_err());
        let odd = vec![f[0].clone(), RgbaImage::new(3, 3, [0; 4]).unwrap()];
        assert!(write_gif(&p, &odd, 50).is_err());
        assert!(!p.exists(), "nothing is written on error");
        // APNG by extension: decodes as PNG (first frame).
        let a = dir.path().join("m.apng");
        write_animation(&a, &f, 50).unwrap();
        assert_eq!(crate::read_png(&a).unwrap(), f[0]);
    }
}
