//! PNG output and input.
//!
//! Writers go through [`volmorph_io::write_atomic`], so a failure never leaves a half-written
//! file. The reader decodes any PNG the `png` crate understands (greyscale, grey+alpha, RGB,
//! RGBA, palette; 1, 2, 4, 8 and 16 bits; interlaced or not; `tRNS` transparency) into
//! 8-bit RGBA. Gamma, colour-profile and sBIT chunks are ignored: samples are taken as
//! stored.

use std::fs::File;
use std::io::{BufRead, BufReader, Cursor, Seek, Write};
use std::path::Path;

use png::{BitDepth, ColorType};
use volmorph_io::{IoError, write_atomic};

use crate::error::RenderError;
use crate::image::{RgbaImage, check_len, pixel_count};

/// Encode one image into `w`. `data` holds the rows top to bottom, tightly packed.
fn encode<W: Write>(
    w: W,
    width: u32,
    height: u32,
    color: ColorType,
    depth: BitDepth,
    data: &[u8],
) -> Result<(), RenderError> {
    let mut enc = png::Encoder::new(w, width, height);
    enc.set_color(color);
    enc.set_depth(depth);
    let mut writer = enc.write_header()?;
    writer.write_image_data(data)?;
    writer.finish()?;
    Ok(())
}

fn write_file(
    path: &Path,
    width: u32,
    height: u32,
    color: ColorType,
    depth: BitDepth,
    data: &[u8],
) -> Result<(), RenderError> {
    write_atomic(path, |w| encode(&mut *w, width, height, color, depth, data))
        .map_err(|e: RenderError| e.at(path))
}

/// Check dimensions and element count of a caller-supplied buffer; errors name `path`.
fn check_buffer(
    path: &Path,
    what: &'static str,
    width: u32,
    height: u32,
    got: usize,
) -> Result<(), RenderError> {
    pixel_count(width.into(), height.into(), 8)
        .and_then(|n| check_len(what, width, height, n, got))
        .map_err(|e| e.at(path))
}

/// Write `img` as an 8-bit RGBA PNG (straight alpha, rows top to bottom).
///
/// # Errors
/// [`RenderError::PngEncode`] or [`RenderError::Io`] when encoding or writing fails; errors
/// name `path`. On error no file is left at `path` (an existing file is untouched).
pub fn write_png_rgba(path: &Path, img: &RgbaImage) -> Result<(), RenderError> {
    write_file(
        path,
        img.width(),
        img.height(),
        ColorType::Rgba,
        BitDepth::Eight,
        img.as_bytes(),
    )
}

/// Write `rgb` (row-major, row 0 at the top) as an 8-bit RGB PNG. Use
/// [`RgbaImage::to_rgb`] to flatten an RGBA picture onto a background first.
///
/// # Errors
/// [`RenderError::Size`] / [`RenderError::LengthMismatch`] when `rgb.len() != width × height`
/// or the size is zero or oversized; [`RenderError::PngEncode`] or [`RenderError::Io`] when
/// encoding or writing fails. Errors name `path`; on error no file is left at `path`.
pub fn write_png_rgb(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[[u8; 3]],
) -> Result<(), RenderError> {
    check_buffer(path, "rgb", width, height, rgb.len())?;
    write_file(
        path,
        width,
        height,
        ColorType::Rgb,
        BitDepth::Eight,
        rgb.as_flattened(),
    )
}

/// Write `grey` (row-major, row 0 at the top) as an 8-bit greyscale PNG.
///
/// # Errors
/// As [`write_png_rgb`].
pub fn write_png_grey8(
    path: &Path,
    width: u32,
    height: u32,
    grey: &[u8],
) -> Result<(), RenderError> {
    check_buffer(path, "grey", width, height, grey.len())?;
    write_file(
        path,
        width,
        height,
        ColorType::Grayscale,
        BitDepth::Eight,
        grey,
    )
}

/// Write `grey` (row-major, row 0 at the top) as a 16-bit greyscale PNG (samples stored
/// big-endian, as PNG requires).
///
/// # Errors
/// As [`write_png_rgb`].
pub fn write_png_grey16(
    path: &Path,
    width: u32,
    height: u32,
    grey: &[u16],
) -> Result<(), RenderError> {
    check_buffer(path, "grey", width, height, grey.len())?;
    let bytes: Vec<u8> = grey.iter().flat_map(|v| v.to_be_bytes()).collect();
    write_file(
        path,
        width,
        height,
        ColorType::Grayscale,
        BitDepth::Sixteen,
        &bytes,
    )
}

/// Encode `img` as an 8-bit RGBA PNG in memory.
///
/// # Errors
/// [`RenderError::PngEncode`] when encoding fails.
pub fn encode_png_rgba(img: &RgbaImage) -> Result<Vec<u8>, RenderError> {
    let mut out = Vec::new();
    encode(
        &mut out,
        img.width(),
        img.height(),
        ColorType::Rgba,
        BitDepth::Eight,
        img.as_bytes(),
    )?;
    Ok(out)
}

/// Read a PNG file into 8-bit RGBA (see the [module documentation](self) for what is
/// decoded). Grey becomes `[g, g, g, 255]`, palette entries are looked up, `tRNS`
/// transparency becomes alpha, sub-8-bit samples are scaled to 0‥=255 and 16-bit samples
/// are rounded to the nearest 8-bit value (`round(v · 255 / 65535)`). Only the first frame
/// of an animated PNG is read.
///
/// # Errors
/// [`RenderError::Io`] when the file cannot be opened; [`RenderError::Size`] when the header
/// declares an image over [`MAX_IMAGE_PIXELS`](crate::MAX_IMAGE_PIXELS) (checked before
/// allocating); [`RenderError::PngDecode`] for corrupt or truncated data. Errors name `path`.
pub fn read_png(path: &Path) -> Result<RgbaImage, RenderError> {
    let file = File::open(path).map_err(|source| {
        RenderError::Io(IoError::Os {
            path: path.display().to_string(),
            source,
        })
    })?;
    decode(BufReader::new(file)).map_err(|e| e.at(path))
}

/// Decode an in-memory PNG into 8-bit RGBA, exactly as [`read_png`] does for a file.
///
/// ```
/// use volmorph_render::{decode_png, encode_png_rgba, RgbaImage};
/// let img = RgbaImage::from_fn(5, 3, |x, y| [x as u8 * 50, y as u8 * 100, 7, 200]).unwrap();
/// assert_eq!(decode_png(&encode_png_rgba(&img).unwrap()).unwrap(), img);
/// ```
///
/// # Errors
/// As [`read_png`], without the path.
pub fn decode_png(bytes: &[u8]) -> Result<RgbaImage, RenderError> {
    decode(Cursor::new(bytes))
}

fn decode<R: BufRead + Seek>(r: R) -> Result<RgbaImage, RenderError> {
    let mut decoder = png::Decoder::new(r);
    decoder.set_transformations(png::Transformations::EXPAND);
    // Check the declared size before the decoder or we allocate for it.
    let (width, height) = decoder.read_header_info()?.size();
    let n = pixel_count(width.into(), height.into(), 8)?;
    let mut reader = decoder.read_info()?;
    let size = reader.output_buffer_size().ok_or(RenderError::Size {
        width: width.into(),
        height: height.into(),
        reason: "decoded image does not fit in memory",
    })?;
    let mut buf = vec![0u8; size];
    let info = reader.next_frame(&mut buf)?;
    let (fw, fh) = (info.width, info.height);
    let channels = match info.color_type {
        ColorType::Grayscale => 1,
        ColorType::GrayscaleAlpha => 2,
        ColorType::Rgb => 3,
        ColorType::Rgba => 4,
        ColorType::Indexed => {
            return Err(RenderError::invalid(
                "PNG palette was not expanded by the decoder",
            ));
        }
    };
    let bytes_per_sample = match info.bit_depth {
        BitDepth::Eight => 1,
        BitDepth::Sixteen => 2,
        other => {
            return Err(RenderError::invalid(format!(
                "PNG samples of {other:?} bits were not expanded by the decoder"
            )));
        }
    };
    let bpp = channels * bytes_per_sample;
    let row_bytes = fw as usize * bpp;
    if (fw, fh) != (width, height) || info.line_size < row_bytes || row_bytes == 0 {
        return Err(RenderError::invalid(format!(
            "PNG first frame is {fw}×{fh} with {}-byte rows, expected {width}×{height} with \
             {row_bytes}-byte rows",
            info.line_size
        )));
    }
    let sample = |s: &[u8]| -> u8 {
        match *s {
            [hi, lo] => {
                let v = u32::from(u16::from_be_bytes([hi, lo]));
                ((v * 255 + 32767) / 65535) as u8
            }
            [v] => v,
            _ => 0,
        }
    };
    let mut pixels = Vec::with_capacity(n);
    for row in buf.chunks(info.line_size).take(height as usize) {
        for px in row.get(..row_bytes).unwrap_or(&[]).chunks_exact(bpp) {
            let mut s = px.chunks_exact(bytes_per_sample).map(sample);
            let mut next = || s.next().unwrap_or(0);
            pixels.push(match channels {
                1 => {
                    let g = next();
                    [g, g, g, 255]
                }
                2 => {
                    let g = next();
                    [g, g, g, next()]
                }
                3 => [next(), next(), next(), 255],
                _ => [next(), next(), next(), next()],
            });
        }
    }
    RgbaImage::from_pixels(width, height, pixels)
}
