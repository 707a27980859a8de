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

/// The extension of the PNG pictures written here (`.png`, any case): every writer of this
/// module refuses another before writing anything ([`check_png`]).
pub const PNG_EXTENSIONS: &[&str] = volmorph_io::extension::OutputFormat::Png.extensions();

/// Check that `path` ends in `.png` (any case) before anything is rendered or written.
///
/// # Errors
/// [`RenderError::Io`] with [`IoError::Extension`] naming the path, the extension found and
/// `.png`.
pub fn check_png(path: &Path) -> Result<(), RenderError> {
    Ok(volmorph_io::extension::check(path, PNG_EXTENSIONS)?)
}

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
    // fdeflate-based: several times faster than the default level for a few percent in size,
    // the right trade for renderers writing many frames.
    enc.set_compression(png::Compression::Fast);
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
    check_png(path)?;
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
/// [`RenderError::Io`] with [`IoError::Extension`] for a path not ending in `.png`
/// ([`check_png`], nothing written); [`RenderError::PngEncode`] or [`RenderError::Io`] when
/// encoding or writing fails; errors name `path`. On error no file is left at `path` (an existing file is untouched).
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
/// [`RenderError::Io`] with [`IoError::Extension`] for a path not ending in `.png`
/// ([`check_png`]); [`RenderError::Size`] / [`RenderError::LengthMismatch`] when
/// `rgb.len() != width × height` or the size is zero or oversized; [`RenderError::PngEncode`] or [`RenderError::Io`] when
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

/// Largest frame count of [`write_apng`].
pub const MAX_APNG_FRAMES: usize = 10_000;

/// Write `frames` (all the same size) as an animated PNG (APNG, 8-bit RGBA) that loops
/// forever, showing each frame for `delay_ms` milliseconds. Browsers and most image viewers
/// play it; others show the first frame.
///
/// # Errors
/// [`RenderError::Io`] with [`IoError::Extension`] for a path not ending in `.png` or `.apng`;
/// [`RenderError::InvalidArgument`] for no frames, more than [`MAX_APNG_FRAMES`], frames of
/// different sizes or a delay outside 1‥=65535 ms; [`RenderError::PngEncode`] or
/// [`RenderError::Io`] when encoding or writing fails. Errors name `path`; on error no file
/// is left there.
pub fn write_apng(path: &Path, frames: &[RgbaImage], delay_ms: u32) -> Result<(), RenderError> {
    volmorph_io::extension::check(path, &["png", "apng"])?;
    let check = || -> Result<(), RenderError> {
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
        if let Some(f) = frames
            .iter()
            .find(|f| (f.width(), f.height()) != (first.width(), first.height()))
        {
            return Err(RenderError::invalid(format!(
                "animation frames differ in size: {}×{} and {}×{}",
                first.width(),
                first.height(),
                f.width(),
                f.height()
            )));
        }
        if !(1..=u32::from(u16::MAX)).contains(&delay_ms) {
            return Err(RenderError::invalid(format!(
                "frame delay {delay_ms} ms must be 1 to 65535"
            )));
        }
        Ok(())
    };
    check().map_err(|e| e.at(path))?;
    let (width, height) = (frames[0].width(), frames[0].height());
    write_atomic(path, |w| -> Result<(), RenderError> {
        let mut enc = png::Encoder::new(&mut *w, width, height);
        enc.set_color(ColorType::Rgba);
        enc.set_depth(BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        enc.set_animated(frames.len() as u32, 0)?;
        enc.set_frame_delay(delay_ms as u16, 1000)?;
        let mut writer = enc.write_header()?;
        for f in frames {
            writer.write_image_data(f.as_bytes())?;
        }
        writer.finish()?;
        Ok(())
    })
    .map_err(|e: RenderError| e.at(path))
}

/// Read a PNG file into 8-bit RGBA: any colour type (grey, grey+alpha, RGB, RGBA, palette),
/// any bit depth (1–16), interlaced or not; gamma, colour-profile and sBIT chunks are
/// ignored (samples are taken as stored). Grey becomes `[g, g, g, 255]`, palette entries are looked up, `tRNS`
/// transparency becomes alpha, sub-8-bit samples are scaled to 0‥=255 and 16-bit samples
/// are rounded to the nearest 8-bit value (`round(v · 255 / 65535)`). Only the first frame
/// of an animated PNG is read.
///
/// # Errors
/// [`RenderError::Io`] when the file cannot be opened; [`RenderError::Size`] when the header
/// declares an image over [`MAX_IMAGE_PIXELS`](crate::MAX_IMAGE_PIXELS) (checked before
/// allocating); [`RenderError::PngDecode`] for corrupt or truncated data. Errors name `path`.
pub fn read_png(path: &Path) -> Result<RgbaImage, RenderError> {
    let file = File::open(path).map_err(|source| RenderError::Io(IoError::os(path, source)))?;
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
    // The decoded rows and the RGBA pixels are held together: check their sum.
    volmorph_io::budget::check_bytes(
        &format!("decoding a {width}×{height} PNG"),
        (size as u64).saturating_add((n as u64).saturating_mul(4)),
    )?;
    let mut buf = volmorph_io::try_vec("the decoded PNG rows", size, 0u8)?;
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
    let mut pixels = volmorph_io::try_with_capacity("the PNG's RGBA pixels", n)?;
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

#[cfg(test)]
mod apng_tests {
    use super::*;

    #[test]
    fn animations_round_trip_their_first_frame_and_refuse_bad_input() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("spin.png");
        let frames: Vec<RgbaImage> = (0..3u8)
            .map(|i| RgbaImage::new(4, 3, [i * 80, 0, 255 - i * 80, 255]).unwrap())
            .collect();
        write_apng(&path, &frames, 100).unwrap();
        // A plain PNG reader sees the first frame.
        assert_eq!(read_png(&path).unwrap(), frames[0]);
        let bytes = std::fs::read(&path).unwrap();
        let has = |tag: &[u8]| bytes.windows(4).any(|w| w == tag);
        assert!(has(b"acTL") && has(b"fcTL") && has(b"fdAT"), "not an APNG");
        let odd = [frames[0].clone(), RgbaImage::new(3, 3, [0; 4]).unwrap()];
        for (f, d) in [(&odd[..], 100), (&frames[..0], 100), (&frames[..], 0)] {
            let e = write_apng(&path, f, d).unwrap_err().to_string();
            assert!(e.contains("spin.png"), "{e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decode with the png crate directly, no transformations: (colour, depth, w, h, bytes).
    fn raw(path: &Path) -> (ColorType, BitDepth, u32, u32, Vec<u8>) {
        let file = BufReader::new(File::open(path).unwrap());
        let mut reader = png::Decoder::new(file).read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        buf.truncate(info.buffer_size());
        (
            info.color_type,
            info.bit_depth,
            info.width,
            info.height,
            buf,
        )
    }

    /// Encode a test PNG with the png crate directly.
    fn build(
        (w, h): (u32, u32),
        color: ColorType,
        depth: BitDepth,
        palette: Option<&[u8]>,
        trns: Option<&[u8]>,
        data: &[u8],
    ) -> Vec<u8> {
        let mut out = Vec::new();
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(color);
        enc.set_depth(depth);
        if let Some(p) = palette {
            enc.set_palette(p.to_vec());
        }
        if let Some(t) = trns {
            enc.set_trns(t.to_vec());
        }
        let mut wr = enc.write_header().unwrap();
        wr.write_image_data(data).unwrap();
        wr.finish().unwrap();
        out
    }

    /// Issue 15: `slice -o x.jpg` wrote PNG bytes. Every PNG writer refuses another
    /// extension before writing, naming the file, what it found and `.png`.
    #[test]
    fn pictures_with_another_extension_are_refused_unwritten() {
        let dir = tempfile::tempdir().unwrap();
        let img = RgbaImage::new(2, 2, [9; 4]).unwrap();
        for name in ["x.jpg", "x.tif", "x", "x.png.bak"] {
            let p = dir.path().join(name);
            let e = write_png_rgba(&p, &img).unwrap_err();
            assert!(
                matches!(e, RenderError::Io(IoError::Extension { .. })),
                "{name}: {e}"
            );
            let msg = e.to_string();
            assert!(msg.contains(name) && msg.ends_with("use .png"), "{msg}");
            assert!(write_png_grey8(&p, 1, 1, &[0]).is_err());
            assert!(write_apng(&p, std::slice::from_ref(&img), 10).is_err());
            assert!(!p.exists(), "{name} was created");
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        write_png_rgba(&dir.path().join("upper.PNG"), &img).unwrap();
    }

    #[test]
    fn rgba_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        let img = RgbaImage::from_fn(13, 7, |x, y| {
            [
                (x * 19) as u8,
                (y * 37) as u8,
                (x * y) as u8,
                (255 - x * 11) as u8,
            ]
        })
        .unwrap();
        write_png_rgba(&p, &img).unwrap();
        let (c, d, w, h, bytes) = raw(&p);
        assert_eq!((c, d, w, h), (ColorType::Rgba, BitDepth::Eight, 13, 7));
        assert_eq!(bytes, img.as_bytes());
        assert_eq!(read_png(&p).unwrap(), img);
        assert_eq!(decode_png(&encode_png_rgba(&img).unwrap()).unwrap(), img);
    }

    #[test]
    fn rgb_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rgb.png");
        let rgb: Vec<[u8; 3]> = (0..6 * 4)
            .map(|i| [i as u8, (i * 7) as u8, 255 - i as u8])
            .collect();
        write_png_rgb(&p, 6, 4, &rgb).unwrap();
        let (c, d, w, h, bytes) = raw(&p);
        assert_eq!((c, d, w, h), (ColorType::Rgb, BitDepth::Eight, 6, 4));
        assert_eq!(bytes, rgb.as_flattened());
        let back = read_png(&p).unwrap();
        for (q, c) in back.pixels().iter().zip(&rgb) {
            assert_eq!(*q, [c[0], c[1], c[2], 255]);
        }
    }

    #[test]
    fn grey8_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("g8.png");
        let grey: Vec<u8> = (0..=255).collect();
        write_png_grey8(&p, 32, 8, &grey).unwrap();
        let (c, d, w, h, bytes) = raw(&p);
        assert_eq!((c, d, w, h), (ColorType::Grayscale, BitDepth::Eight, 32, 8));
        assert_eq!(bytes, grey);
        let back = read_png(&p).unwrap();
        assert_eq!(back.get(5, 2), Some([69, 69, 69, 255]));
        assert!(
            back.pixels()
                .iter()
                .zip(&grey)
                .all(|(q, &g)| *q == [g, g, g, 255])
        );
    }

    #[test]
    fn grey16_round_trip_is_exact_and_reads_rounded() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("g16.png");
        let grey: Vec<u16> = vec![0, 128, 129, 257 * 77, 32767, 32768, 65534, 65535];
        write_png_grey16(&p, 4, 2, &grey).unwrap();
        let (c, d, w, h, bytes) = raw(&p);
        assert_eq!(
            (c, d, w, h),
            (ColorType::Grayscale, BitDepth::Sixteen, 4, 2)
        );
        let decoded: Vec<u16> = bytes
            .chunks_exact(2)
            .map(|b| u16::from_be_bytes([b[0], b[1]]))
            .collect();
        assert_eq!(decoded, grey);
        // round(v · 255 / 65535)
        let expect = [0u8, 0, 1, 77, 127, 128, 255, 255];
        let back = read_png(&p).unwrap();
        for (q, &e) in back.pixels().iter().zip(&expect) {
            assert_eq!(*q, [e, e, e, 255]);
        }
    }

    #[test]
    fn reads_low_bit_depth_grey_palette_and_alpha_variants() {
        // 1-bit grey: 1 → 255, packed MSB first; 5 pixels use one byte per row.
        let png1 = build(
            (5, 2),
            ColorType::Grayscale,
            BitDepth::One,
            None,
            None,
            &[0b1010_1000, 0b0101_0000],
        );
        let img = decode_png(&png1).unwrap();
        let row0: Vec<u8> = img.row(0).unwrap().iter().map(|p| p[0]).collect();
        let row1: Vec<u8> = img.row(1).unwrap().iter().map(|p| p[0]).collect();
        assert_eq!(row0, [255, 0, 255, 0, 255]);
        assert_eq!(row1, [0, 255, 0, 255, 0]);
        assert!(
            img.pixels()
                .iter()
                .all(|p| p[3] == 255 && p[0] == p[1] && p[1] == p[2])
        );

        let palette = [10, 20, 30, 40, 50, 60, 70, 80, 90];
        let be16 = |v: &[u16]| -> Vec<u8> { v.iter().flat_map(|x| x.to_be_bytes()).collect() };
        let rgb16 = be16(&[0, 257 * 3, 65535, 129, 128, 32768]);
        let rgba16 = be16(&[65535, 0, 257 * 200, 257 * 50]);
        type Case<'a> = (
            &'a str,
            (u32, u32),
            ColorType,
            BitDepth,
            Option<&'a [u8]>,
            Option<&'a [u8]>,
            &'a [u8],
            &'a [[u8; 4]],
        );
        #[rustfmt::skip]
        let cases: [Case<'_>; 7] = [
            // v → 17 v.
            ("4-bit grey", (3, 1), ColorType::Grayscale, BitDepth::Four, None, None,
             &[0x5F, 0x00], &[[85, 85, 85, 255], [255, 255, 255, 255], [0, 0, 0, 255]]),
            // tRNS on the first two entries; indices 0, 1, 2, 0.
            ("2-bit palette with tRNS", (4, 1), ColorType::Indexed, BitDepth::Two,
             Some(&palette), Some(&[0, 128]), &[0b0001_1000],
             &[[10, 20, 30, 0], [40, 50, 60, 128], [70, 80, 90, 255], [10, 20, 30, 0]]),
            ("8-bit palette without transparency", (2, 1), ColorType::Indexed, BitDepth::Eight,
             Some(&palette), None, &[2, 1], &[[70, 80, 90, 255], [40, 50, 60, 255]]),
            // Grey 7 is transparent.
            ("grey with a tRNS key colour", (2, 1), ColorType::Grayscale, BitDepth::Eight,
             None, Some(&[0, 7]), &[7, 8], &[[7, 7, 7, 0], [8, 8, 8, 255]]),
            ("grey + alpha, 8 bits", (2, 1), ColorType::GrayscaleAlpha, BitDepth::Eight,
             None, None, &[9, 100, 200, 255], &[[9, 9, 9, 100], [200, 200, 200, 255]]),
            // Rounded to 8 bits.
            ("RGB, 16 bits", (2, 1), ColorType::Rgb, BitDepth::Sixteen, None, None,
             &rgb16, &[[0, 3, 255, 255], [1, 0, 128, 255]]),
            ("RGBA, 16 bits", (1, 1), ColorType::Rgba, BitDepth::Sixteen, None, None,
             &rgba16, &[[255, 0, 200, 50]]),
        ];
        for (what, size, color, depth, pal, trns, data, expect) in cases {
            let png = build(size, color, depth, pal, trns, data);
            assert_eq!(decode_png(&png).unwrap().pixels(), expect, "{what}");
        }
    }

    /// CRC-32 (ISO-HDLC, as PNG chunks use), bitwise.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    #[test]
    fn absurd_dimensions_are_refused_before_allocating() {
        let mut ihdr = b"IHDR".to_vec();
        ihdr.extend_from_slice(&100_000u32.to_be_bytes());
        ihdr.extend_from_slice(&100_000u32.to_be_bytes());
        ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
        let mut file = b"\x89PNG\r\n\x1a\n".to_vec();
        file.extend_from_slice(&13u32.to_be_bytes());
        file.extend_from_slice(&ihdr);
        file.extend_from_slice(&crc32(&ihdr).to_be_bytes());
        let err = decode_png(&file).unwrap_err();
        assert!(
            matches!(
                err,
                RenderError::Size {
                    width: 100_000,
                    height: 100_000,
                    ..
                }
            ),
            "{err}"
        );

        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("huge.png");
        std::fs::write(&p, &file).unwrap();
        let msg = read_png(&p).unwrap_err().to_string();
        assert!(msg.contains("huge.png") && msg.contains("100000"), "{msg}");
    }

    #[test]
    fn errors_name_the_file_and_leave_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("short.png");
        let err = write_png_grey8(&p, 4, 4, &[0; 15]).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("short.png") && msg.contains("15"), "{msg}");
        assert!(!p.exists());

        // An existing file survives a failed write.
        std::fs::write(&p, b"old").unwrap();
        assert!(write_png_grey16(&p, 2, 2, &[0; 3]).is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

        let missing_dir = dir.path().join("no/such/dir/x.png");
        let img = RgbaImage::new(1, 1, [0; 4]).unwrap();
        let msg = write_png_rgba(&missing_dir, &img).unwrap_err().to_string();
        assert!(msg.contains("x.png"), "{msg}");

        let msg = read_png(&dir.path().join("absent.png"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("absent.png"), "{msg}");

        // Truncated and corrupt data.
        let good = encode_png_rgba(&RgbaImage::new(8, 8, [1, 2, 3, 4]).unwrap()).unwrap();
        let t = dir.path().join("trunc.png");
        std::fs::write(&t, &good[..good.len() - 20]).unwrap();
        let err = read_png(&t).unwrap_err();
        assert!(err.to_string().contains("trunc.png"), "{err}");
        assert!(decode_png(b"not a png at all").is_err());
        assert!(decode_png(&[]).is_err());
    }
}
