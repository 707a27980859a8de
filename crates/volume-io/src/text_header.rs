//! Machinery shared by the text-header formats (MetaImage, NRRD, VTK legacy) and raw voxels:
//! bounded header reading, strict number parsing, voxel decoding (raw, zlib/gzip, ASCII) into
//! an exactly-sized buffer, and voxel encoding in a chosen byte order.
//!
//! Guarantees: header text is never scanned beyond [`MAX_HEADER_BYTES`]; no voxel buffer is
//! allocated before the declared size has been checked against the bytes actually available
//! (raw data), against the deflate expansion limit (compressed data) or against the
//! minimum text length (ASCII data).

use std::borrow::Cow;
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use volmorph_io::IoError;

use volmorph_volume::{AnyVolume, Geometry, Volume, VolumeError, Voxel, VoxelType, with_volume};

/// Largest header text any reader scans: 1 MiB. Real headers are a few hundred bytes; the
/// bound keeps a hostile file (e.g. a gigabyte without a newline) from being scanned or
/// buffered in full.
pub(crate) const MAX_HEADER_BYTES: usize = 1 << 20;

/// Largest expansion factor of a deflate stream (zlib's documented worst case is 1032:1);
/// a compressed payload that claims to decompress to more than this is refused before
/// allocation.
const MAX_DEFLATE_RATIO: u64 = 1032;

/// Elements converted per chunk when swapping byte order on write.
const WRITE_CHUNK: usize = 1 << 16;

/// Decompressed bytes after the voxels read while looking for the end of a compressed
/// stream (to verify its checksum) before giving up on reaching it.
const MAX_TRAILING: u64 = 1 << 20;

/// Largest ASCII token accepted for one voxel value.
const MAX_TOKEN: usize = 128;

/// Map an OS error to an [`IoError::Os`] carrying `path`.
pub(crate) fn os_err(path: &Path) -> impl Fn(io::Error) -> VolumeError + Copy + '_ {
    move |source| VolumeError::Io(IoError::os(path, source))
}

/// The first bytes of a file (at most [`MAX_HEADER_BYTES`]) and the file's total length.
///
/// # Errors
/// I/O errors carrying the path.
pub(crate) fn read_prefix(path: &Path) -> Result<(Vec<u8>, u64), VolumeError> {
    let err = os_err(path);
    let file = volmorph_io::open_regular(path)?;
    let len = file.metadata().map_err(&err)?.len();
    let mut prefix = Vec::with_capacity(
        usize::try_from(len).map_or(MAX_HEADER_BYTES, |l| l.min(MAX_HEADER_BYTES)),
    );
    file.take(MAX_HEADER_BYTES as u64)
        .read_to_end(&mut prefix)
        .map_err(&err)?;
    Ok((prefix, len))
}

/// A line-by-line cursor over header text, bounded by [`MAX_HEADER_BYTES`].
///
/// Lines end at `\n`; a trailing `\r` is removed. [`Lines::pos`] is the byte offset just
/// after the last line returned, i.e. where binary data starts when that line ends the
/// header.
pub(crate) struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Lines<'a> {
    /// A cursor at the start of `bytes` (only the first [`MAX_HEADER_BYTES`] are visible).
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        let end = bytes.len().min(MAX_HEADER_BYTES);
        Self {
            bytes: &bytes[..end],
            pos: 0,
        }
    }

    /// Byte offset just after the last line returned.
    pub(crate) fn pos(&self) -> usize {
        self.pos
    }

    /// The next line, or `None` at the end of the visible text. A final line without a
    /// newline is returned only if `allow_unterminated`; otherwise `None` (the header is
    /// incomplete within the visible bytes).
    pub(crate) fn next_line(&mut self, allow_unterminated: bool) -> Option<Cow<'a, str>> {
        let rest = &self.bytes[self.pos..];
        if rest.is_empty() {
            return None;
        }
        let (line, advance) = match rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&rest[..i], i + 1),
            None if allow_unterminated => (rest, rest.len()),
            None => return None,
        };
        self.pos += advance;
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        Some(String::from_utf8_lossy(line))
    }
}

/// Parse one finite `f64` (C/`strtod` syntax as Rust accepts it; NaN and infinities are
/// refused).
///
/// # Errors
/// [`VolumeError::Format`] naming `what`.
pub(crate) fn parse_f64(fmt: &'static str, what: &str, s: &str) -> Result<f64, VolumeError> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(VolumeError::format(
            fmt,
            format!("{what}: value `{s}` is not finite"),
        )),
        Err(_) => Err(VolumeError::format(
            fmt,
            format!("{what}: `{s}` is not a number"),
        )),
    }
}

/// Parse exactly `n` whitespace-separated finite numbers.
///
/// # Errors
/// [`VolumeError::Format`] naming `what` for a wrong count or a bad number.
pub(crate) fn parse_f64_list(
    fmt: &'static str,
    what: &str,
    s: &str,
    n: usize,
) -> Result<Vec<f64>, VolumeError> {
    let toks: Vec<&str> = s.split_ascii_whitespace().collect();
    if toks.len() != n {
        return Err(VolumeError::format(
            fmt,
            format!(
                "{what}: expected {n} numbers, found {} in `{s}`",
                toks.len()
            ),
        ));
    }
    toks.iter().map(|t| parse_f64(fmt, what, t)).collect()
}

/// Parse a size: a positive integer that fits in `usize`.
///
/// # Errors
/// [`VolumeError::Format`] naming `what` for zero, negative, non-integer or overflowing
/// values.
pub(crate) fn parse_size(fmt: &'static str, what: &str, s: &str) -> Result<usize, VolumeError> {
    let t = s.trim();
    if t.starts_with('-') {
        return Err(VolumeError::format(
            fmt,
            format!("{what}: size `{t}` is negative"),
        ));
    }
    match t.parse::<u64>() {
        Ok(0) => Err(VolumeError::format(fmt, format!("{what}: size is zero"))),
        Ok(v) => usize::try_from(v)
            .map_err(|_| VolumeError::format(fmt, format!("{what}: size `{t}` overflows"))),
        Err(e) if matches!(e.kind(), std::num::IntErrorKind::PosOverflow) => Err(
            VolumeError::format(fmt, format!("{what}: size `{t}` overflows")),
        ),
        Err(_) => Err(VolumeError::format(
            fmt,
            format!("{what}: `{t}` is not a positive integer"),
        )),
    }
}

/// Parse exactly `n` whitespace-separated sizes (see [`parse_size`]).
///
/// # Errors
/// As [`parse_size`], or a wrong count.
pub(crate) fn parse_sizes(
    fmt: &'static str,
    what: &str,
    s: &str,
    n: usize,
) -> Result<Vec<usize>, VolumeError> {
    let toks: Vec<&str> = s.split_ascii_whitespace().collect();
    if toks.len() != n {
        return Err(VolumeError::format(
            fmt,
            format!("{what}: expected {n} sizes, found {} in `{s}`", toks.len()),
        ));
    }
    toks.iter().map(|t| parse_size(fmt, what, t)).collect()
}

/// Parse a signed integer.
///
/// # Errors
/// [`VolumeError::Format`] naming `what`.
pub(crate) fn parse_i64(fmt: &'static str, what: &str, s: &str) -> Result<i64, VolumeError> {
    s.trim()
        .parse::<i64>()
        .map_err(|_| VolumeError::format(fmt, format!("{what}: `{}` is not an integer", s.trim())))
}

pub(crate) use volmorph_io::fmt_f64;

/// Complete a direction matrix from its first `k` columns (`k` = 1 or 2, the image's
/// spatial axes). Columns lying in the xy plane are padded with the identity (`+z`), as ITK
/// embeds a 2-D direction matrix in 3-D; otherwise the missing columns are made orthonormal
/// to the given ones (`a × b` for the third).
pub(crate) fn complete_direction(cols: &[glam::DVec3]) -> glam::DMat3 {
    use glam::{DMat3, DVec3};
    match cols {
        [a] => {
            let (b, c) = a.normalize_or_zero().any_orthonormal_pair();
            DMat3::from_cols(*a, b, c)
        }
        [a, b] if a.z == 0.0 && b.z == 0.0 => DMat3::from_cols(*a, *b, DVec3::Z),
        [a, b] => {
            let c = a.cross(*b).normalize_or_zero();
            let c = if c == DVec3::ZERO { DVec3::Z } else { c };
            DMat3::from_cols(*a, *b, c)
        }
        [a, b, c, ..] => DMat3::from_cols(*a, *b, *c),
        [] => DMat3::IDENTITY,
    }
}

/// Where voxel bytes come from: an in-memory buffer or a file.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Input<'a> {
    /// The whole file (or byte string) is in memory.
    Bytes(&'a [u8]),
    /// A file on disk, read from an offset.
    File(&'a Path),
}

/// How the voxel bytes are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Encoding {
    /// Plain binary.
    Raw,
    /// A zlib stream (a gzip stream is also accepted, detected by its magic number, as
    /// MetaIO's inflate does).
    Zlib,
    /// A gzip stream (multi-member streams are concatenated).
    Gzip,
    /// Whitespace-separated decimal text.
    Ascii,
}

impl Encoding {
    fn name(self) -> &'static str {
        match self {
            Self::Raw => "raw",
            Self::Zlib => "zlib",
            Self::Gzip => "gzip",
            Self::Ascii => "ASCII",
        }
    }
}

/// Where the data starts in the input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Start {
    /// At this byte offset from the beginning.
    Offset(u64),
    /// The data are the last bytes of the input (NRRD `byte skip: -1`, MetaIO
    /// `HeaderSize = -1`); raw encoding only.
    FromEnd,
}

/// Everything needed to decode the voxels of one image.
#[derive(Debug, Clone)]
pub(crate) struct DataSpec {
    /// Format name for error messages.
    pub fmt: &'static str,
    /// Voxel type on disk (and in memory).
    pub voxel_type: VoxelType,
    /// Byte order on disk.
    pub big_endian: bool,
    /// Encoding of the data.
    pub encoding: Encoding,
    /// Where the (encoded) data start.
    pub start: Start,
    /// Text lines to skip at `start` before the data (NRRD `line skip`).
    pub line_skip: u64,
    /// Bytes to skip after the skipped lines and, for compressed encodings, after
    /// decompression, just before the voxels (NRRD `byte skip`, MetaIO `HeaderSize`).
    pub decoded_skip: u64,
    /// Size of the encoded payload, if the header declares it (MetaImage
    /// `CompressedDataSize`); bounds the compressed stream.
    pub encoded_len: Option<u64>,
    /// Require that nothing follows the voxels (raw data: headerless raw files, and MetaImage
    /// and NRRD data that do not lie at the end of a longer file).
    pub exact: bool,
    /// How size errors name the data and the header fields that declare their size;
    /// `None` for the generic wording.
    pub words: Option<SizeWords>,
}

/// How a format's size errors name what they compare, e.g. for a MetaImage data file:
/// `source` "ElementDataFile `ct.raw`", `fields` "DimSize, ElementType and HeaderSize",
/// `at_end` `Some("HeaderSize = -1")`.
#[derive(Debug, Clone)]
pub(crate) struct SizeWords {
    /// The data, as the header names them.
    pub source: String,
    /// The header fields that declare the data's size.
    pub fields: &'static str,
    /// What the header says for data at the end of a longer file, if the format can say it.
    pub at_end: Option<&'static str>,
}

/// Open `input` at `start` and return a buffered reader plus the number of bytes from
/// there to the end.
fn open<'a>(
    fmt: &'static str,
    input: Input<'a>,
    start: Start,
    tail_len: u64,
) -> Result<(Box<dyn BufRead + 'a>, u64), VolumeError> {
    let total = match input {
        Input::Bytes(b) => b.len() as u64,
        Input::File(p) => std::fs::metadata(p).map_err(os_err(p))?.len(),
    };
    let offset = match start {
        Start::Offset(o) => o,
        Start::FromEnd => total.checked_sub(tail_len).ok_or_else(|| {
            VolumeError::format(
                fmt,
                format!(
                    "voxel data truncated: the data are declared to be the last {tail_len} \
                     bytes of a {total}-byte file"
                ),
            )
        })?,
    };
    if offset > total {
        return Err(VolumeError::format(
            fmt,
            format!("voxel data truncated: data start at byte {offset} of a {total}-byte file"),
        ));
    }
    let avail = total - offset;
    let reader: Box<dyn BufRead + 'a> = match input {
        Input::Bytes(b) => {
            let o = usize::try_from(offset).unwrap_or(b.len()).min(b.len());
            Box::new(&b[o..])
        }
        Input::File(p) => {
            let mut f = File::open(p).map_err(os_err(p))?;
            f.seek(SeekFrom::Start(offset)).map_err(os_err(p))?;
            Box::new(BufReader::with_capacity(1 << 20, f))
        }
    };
    Ok((reader, avail))
}

/// Skip `n` newline-terminated lines without buffering them. Returns the bytes consumed.
fn skip_lines(fmt: &'static str, r: &mut dyn BufRead, n: u64) -> Result<u64, VolumeError> {
    let mut consumed = 0u64;
    for line in 0..n {
        loop {
            let buf = r
                .fill_buf()
                .map_err(|e| VolumeError::format(fmt, format!("reading skipped lines: {e}")))?;
            if buf.is_empty() {
                return Err(VolumeError::format(
                    fmt,
                    format!("data file ended while skipping line {} of {n}", line + 1),
                ));
            }
            if let Some(i) = buf.iter().position(|&b| b == b'\n') {
                r.consume(i + 1);
                consumed += i as u64 + 1;
                break;
            }
            let len = buf.len();
            r.consume(len);
            consumed += len as u64;
        }
    }
    Ok(consumed)
}

/// Read into `buf` until it is full or the reader ends (retrying interrupted reads); returns
/// the bytes read. The one short-read loop of the volume readers.
pub(crate) fn fill(r: &mut dyn Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(k) => got += k,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// Decode the voxels described by `spec` from `input` onto `geometry`.
///
/// # Errors
/// [`VolumeError::Format`] for truncated, oversized, corrupt or unparsable data; I/O errors
/// for unreadable files; [`VolumeError::Geometry`] for an invalid geometry (checked before
/// any allocation).
pub(crate) fn decode(
    input: Input<'_>,
    spec: &DataSpec,
    geometry: Geometry,
) -> Result<AnyVolume, VolumeError> {
    geometry.validate()?;
    let vt = spec.voxel_type;
    let n = volmorph_io::checked_len(&geometry.dims, vt.size())?;
    Ok(
        volmorph_volume::with_voxel_type!(vt, T => AnyVolume::from(Volume::new(
        geometry,
        decode_typed::<T>(input, spec, n)?
    )?)),
    )
}

/// Decode `n` values described by `spec` from `input`, as f64 (multi-channel images:
/// `n` counts every channel of every voxel).
///
/// # Errors
/// As [`decode`].
pub(crate) fn decode_values_f64(
    input: Input<'_>,
    spec: &DataSpec,
    n: usize,
) -> Result<Vec<f64>, VolumeError> {
    let vt = spec.voxel_type;
    volmorph_io::checked_len(&[n], vt.size().max(8))?;
    Ok(
        volmorph_volume::with_voxel_type!(vt, T => decode_typed::<T>(input, spec, n)?
        .into_iter()
        .map(|v| v.to_f64())
        .collect()),
    )
}

fn decode_typed<T: AsciiVoxel>(
    input: Input<'_>,
    spec: &DataSpec,
    n: usize,
) -> Result<Vec<T>, VolumeError> {
    let fmt = spec.fmt;
    let nbytes = (n as u64) * (std::mem::size_of::<T>() as u64);
    if spec.start == Start::FromEnd && spec.encoding != Encoding::Raw {
        return Err(VolumeError::format(
            fmt,
            "data at the end of the file (skip -1) is only allowed with raw encoding",
        ));
    }
    let (mut r, mut avail) = open(fmt, input, spec.start, nbytes)?;
    if spec.line_skip > 0 {
        let used = skip_lines(fmt, &mut *r, spec.line_skip)?;
        avail = avail.saturating_sub(used);
    }
    match spec.encoding {
        Encoding::Raw => {
            let need = nbytes.saturating_add(spec.decoded_skip);
            if avail < need || (spec.exact && avail != need) {
                let short = avail < need;
                let what = if short {
                    "voxel data truncated"
                } else {
                    "voxel data size mismatch"
                };
                let msg = match &spec.words {
                    None => {
                        let skipped = if spec.decoded_skip > 0 {
                            format!(" (including {} skipped)", spec.decoded_skip)
                        } else {
                            String::new()
                        };
                        format!(
                            "{what}: {n} voxels of {} need {need} bytes{skipped}, but {avail} \
                             bytes are present",
                            T::TYPE
                        )
                    }
                    Some(w) => {
                        let lines = if spec.line_skip > 0 {
                            format!(" after {} skipped lines", spec.line_skip)
                        } else {
                            String::new()
                        };
                        let skipped = if spec.decoded_skip > 0 {
                            format!(" and {} skipped bytes", spec.decoded_skip)
                        } else {
                            String::new()
                        };
                        let longer = match (short, w.at_end) {
                            (true, _) => String::new(),
                            (false, Some(e)) => format!(
                                "; the data must fill it exactly unless the header says \
                                 {e} (data at the end of a longer file)"
                            ),
                            (false, None) => "; the data must fill it exactly".into(),
                        };
                        format!(
                            "{what}: {} holds {avail} bytes{lines}, but {} declare {need} \
                             bytes ({n} voxels of {}{skipped}){longer}",
                            w.source,
                            w.fields,
                            T::TYPE
                        )
                    }
                };
                return Err(VolumeError::format(fmt, msg));
            }
            if spec.decoded_skip > 0 {
                skip_bytes(fmt, &mut *r, spec.decoded_skip, "raw")?;
            }
            read_binary(fmt, &mut *r, n, spec.big_endian, "raw")
        }
        Encoding::Zlib | Encoding::Gzip => {
            let enc_len = spec.encoded_len.map_or(avail, |l| l.min(avail));
            if let Some(l) = spec.encoded_len
                && l > avail
            {
                return Err(VolumeError::format(
                    fmt,
                    format!("compressed data truncated: {l} bytes declared, {avail} bytes present"),
                ));
            }
            let max_out = enc_len.saturating_mul(MAX_DEFLATE_RATIO).saturating_add(64);
            let need = nbytes.saturating_add(spec.decoded_skip);
            if need > max_out {
                return Err(VolumeError::format(
                    fmt,
                    format!(
                        "compressed data too short: {enc_len} compressed bytes cannot hold the \
                         {need} bytes the header declares"
                    ),
                ));
            }
            let limited = (&mut *r).take(enc_len);
            let mut dec: Box<dyn Read + '_> = match spec.encoding {
                Encoding::Gzip => Box::new(flate2::read::MultiGzDecoder::new(limited)),
                _ => {
                    let mut limited = BufReader::new(limited);
                    let is_gz = volmorph_io::is_gzip(limited.fill_buf().map_err(|e| {
                        VolumeError::format(fmt, format!("reading compressed data: {e}"))
                    })?);
                    if is_gz {
                        Box::new(flate2::read::MultiGzDecoder::new(limited))
                    } else {
                        Box::new(flate2::read::ZlibDecoder::new(limited))
                    }
                }
            };
            let what = spec.encoding.name();
            if spec.decoded_skip > 0 {
                skip_bytes(fmt, &mut *dec, spec.decoded_skip, what)?;
            }
            let v = read_binary(fmt, &mut *dec, n, spec.big_endian, what)?;
            // Read on to the end of the stream so its checksum is verified; a corrupt stream
            // can otherwise decode to plausible voxels.
            let mut sink = [0u8; 4096];
            let mut extra = 0u64;
            loop {
                match dec.read(&mut sink) {
                    Ok(0) => break,
                    Ok(k) => {
                        extra += k as u64;
                        if spec.exact {
                            return Err(VolumeError::format(
                                fmt,
                                format!("{what} data hold more than the {nbytes} bytes expected"),
                            ));
                        }
                        if extra > MAX_TRAILING {
                            break;
                        }
                    }
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(e) => return Err(corrupt(fmt, what, &e)),
                }
            }
            Ok(v)
        }
        Encoding::Ascii => {
            if spec.decoded_skip > 0 {
                let used = skip_bytes(fmt, &mut *r, spec.decoded_skip, "ASCII")?;
                avail = avail.saturating_sub(used);
            }
            // Every value takes at least one character and one separator.
            if (n as u64).saturating_mul(2) > avail.saturating_add(1) {
                return Err(VolumeError::format(
                    fmt,
                    format!(
                        "ASCII data truncated: {avail} bytes cannot hold {n} whitespace-separated \
                         values"
                    ),
                ));
            }
            read_ascii(fmt, &mut *r, n)
        }
    }
}

fn corrupt(fmt: &'static str, what: &str, e: &io::Error) -> VolumeError {
    VolumeError::format(fmt, format!("corrupt {what} data: {e}"))
}

fn skip_bytes(fmt: &'static str, r: &mut dyn Read, n: u64, what: &str) -> Result<u64, VolumeError> {
    let got = io::copy(&mut r.take(n), &mut io::sink()).map_err(|e| corrupt(fmt, what, &e))?;
    if got < n {
        return Err(VolumeError::format(
            fmt,
            format!("{what} data ended after {got} of the {n} bytes to skip"),
        ));
    }
    Ok(got)
}

/// Read `n` binary voxels into an exactly-sized buffer and fix their byte order in place.
fn read_binary<T: Voxel>(
    fmt: &'static str,
    r: &mut dyn Read,
    n: usize,
    big_endian: bool,
    what: &str,
) -> Result<Vec<T>, VolumeError> {
    let mut v = vec![T::default(); n];
    let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut v);
    let got = fill(r, bytes).map_err(|e| corrupt(fmt, what, &e))?;
    if got < bytes.len() {
        return Err(VolumeError::format(
            fmt,
            format!(
                "voxel data truncated: {what} data hold {got} bytes, {} needed",
                bytes.len()
            ),
        ));
    }
    to_native(&mut v, big_endian);
    Ok(v)
}

/// Convert values stored in the given byte order to native order, in place.
pub(crate) fn to_native<T: Voxel>(v: &mut [T], big_endian: bool) {
    if std::mem::size_of::<T>() > 1 && big_endian != cfg!(target_endian = "big") {
        v.par_chunks_mut(WRITE_CHUNK).for_each(|c| {
            for x in c {
                *x = x.swap_bytes();
            }
        });
    }
}

/// A voxel type that can be parsed from one decimal token.
pub(crate) trait AsciiVoxel: Voxel {
    /// Parse one token exactly (integers must be in range; integral decimals such as `3.0`
    /// are accepted for integer types).
    fn parse_token(s: &str) -> Option<Self>;
}

macro_rules! ascii_int {
    ($($t:ty),*) => {$(
        impl AsciiVoxel for $t {
            fn parse_token(s: &str) -> Option<Self> {
                s.parse::<$t>().ok().or_else(|| {
                    let f = s.parse::<f64>().ok()?;
                    let (lo, hi) = <$t as Voxel>::TYPE.range();
                    (f == f.trunc() && f >= lo && f <= hi).then(|| f as $t)
                })
            }
        }
    )*};
}
ascii_int!(u8, i8, u16, i16, u32, i32);

impl AsciiVoxel for f32 {
    fn parse_token(s: &str) -> Option<Self> {
        s.parse::<f32>().ok()
    }
}

impl AsciiVoxel for f64 {
    fn parse_token(s: &str) -> Option<Self> {
        s.parse::<f64>().ok()
    }
}

/// Parse `n` whitespace-separated values; trailing text after them is ignored.
fn read_ascii<T: AsciiVoxel>(
    fmt: &'static str,
    r: &mut dyn BufRead,
    n: usize,
) -> Result<Vec<T>, VolumeError> {
    let mut out = Vec::with_capacity(n);
    let mut tok: Vec<u8> = Vec::with_capacity(MAX_TOKEN);
    let io = |e: io::Error| VolumeError::format(fmt, format!("reading ASCII data: {e}"));
    let push = |tok: &mut Vec<u8>, out: &mut Vec<T>| -> Result<(), VolumeError> {
        let s = std::str::from_utf8(tok).unwrap_or("");
        let v = T::parse_token(s).ok_or_else(|| {
            VolumeError::format(
                fmt,
                format!(
                    "ASCII value {} `{}` is not a valid {}",
                    out.len(),
                    String::from_utf8_lossy(tok),
                    T::TYPE
                ),
            )
        })?;
        out.push(v);
        tok.clear();
        Ok(())
    };
    'outer: loop {
        let buf = r.fill_buf().map_err(io)?;
        if buf.is_empty() {
            break;
        }
        let len = buf.len();
        for &b in buf {
            if b.is_ascii_whitespace() {
                if !tok.is_empty() {
                    push(&mut tok, &mut out)?;
                    if out.len() == n {
                        break 'outer;
                    }
                }
            } else {
                if tok.len() >= MAX_TOKEN {
                    return Err(VolumeError::format(
                        fmt,
                        format!("ASCII value {} is longer than {MAX_TOKEN} bytes", out.len()),
                    ));
                }
                tok.push(b);
            }
        }
        r.consume(len);
    }
    if !tok.is_empty() && out.len() < n {
        push(&mut tok, &mut out)?;
    }
    if out.len() < n {
        return Err(VolumeError::format(
            fmt,
            format!("ASCII data truncated: found {} of {n} values", out.len()),
        ));
    }
    Ok(out)
}

/// Write the voxels of `volume` in the given byte order (no header).
///
/// # Errors
/// The writer's I/O error.
pub(crate) fn write_voxels(
    w: &mut dyn Write,
    volume: &AnyVolume,
    big_endian: bool,
) -> io::Result<()> {
    with_volume!(volume, v => write_slice(w, v.data(), big_endian))
}

/// Write `values` in the given byte order (no header).
///
/// # Errors
/// The writer's I/O error.
pub(crate) fn write_values<T: Voxel>(
    w: &mut dyn Write,
    values: &[T],
    big_endian: bool,
) -> io::Result<()> {
    write_slice(w, values, big_endian)
}

fn write_slice<T: Voxel>(w: &mut dyn Write, data: &[T], big_endian: bool) -> io::Result<()> {
    if std::mem::size_of::<T>() == 1 || big_endian == cfg!(target_endian = "big") {
        return w.write_all(bytemuck::cast_slice(data));
    }
    let mut buf: Vec<T> = Vec::with_capacity(WRITE_CHUNK.min(data.len()));
    for chunk in data.chunks(WRITE_CHUNK) {
        buf.clear();
        buf.extend(chunk.iter().map(|x| x.swap_bytes()));
        w.write_all(bytemuck::cast_slice(&buf))?;
    }
    Ok(())
}

/// A writer that counts the bytes passing through.
pub(crate) struct CountingWriter<W> {
    /// The wrapped writer.
    pub inner: W,
    /// Bytes written so far.
    pub count: u64,
}

impl<W: Write> Write for CountingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let k = self.inner.write(buf)?;
        self.count += k as u64;
        Ok(k)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// Resolve a data file named in a header: relative names are relative to the header's
/// directory.
pub(crate) fn resolve_data_file(header_path: Option<&Path>, name: &str) -> PathBuf {
    let p = Path::new(name);
    if p.is_absolute() {
        return p.to_path_buf();
    }
    match header_path.and_then(Path::parent) {
        Some(dir) => dir.join(p),
        None => p.to_path_buf(),
    }
}

/// Refuse, when reading from memory, a header that names a detached data file.
///
/// # Errors
/// [`VolumeError::Unsupported`] naming the file when `data_file` is `Some`: reading it
/// needs the header's path.
pub(crate) fn require_attached(fmt: &str, data_file: Option<&str>) -> Result<(), VolumeError> {
    match data_file {
        Some(f) => Err(VolumeError::Unsupported(format!(
            "{fmt} header names the data file `{f}`: reading it needs the header's path"
        ))),
        None => Ok(()),
    }
}

/// The path of the data file `name` that the header at `header_path` names in its field
/// `key` (see [`resolve_data_file`]), checked to be a regular file inside the header's folder
/// (after resolving symbolic links) unless `options` allow external data.
///
/// # Errors
/// [`VolumeError::Format`] naming the field, the name and the path looked for when no such
/// file exists or it is not a regular file (a folder, a FIFO, a device);
/// [`VolumeError::ExternalData`] when it lies outside the header's folder.
pub(crate) fn existing_data_file(
    fmt: &'static str,
    key: &str,
    header_path: &Path,
    name: &str,
    options: &crate::ReadOptions,
) -> Result<PathBuf, VolumeError> {
    let data = resolve_data_file(Some(header_path), name);
    let meta = match std::fs::metadata(&data) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            return Err(VolumeError::format(
                fmt,
                format!("{key} `{name}` not found (looked for {})", data.display()),
            ));
        }
        Err(e) => {
            return Err(VolumeError::format(
                fmt,
                format!("{key} `{name}`: cannot read {}: {e}", data.display()),
            ));
        }
    };
    if !meta.is_file() {
        return Err(VolumeError::format(
            fmt,
            format!(
                "{key} `{name}` is {}, not a regular file ({})",
                volmorph_io::file_kind(&meta),
                data.display()
            ),
        ));
    }
    if !options.allow_external_data {
        let dir = match header_path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let inside = match (dir.canonicalize(), data.canonicalize()) {
            (Ok(d), Ok(f)) => f.starts_with(&d),
            _ => false,
        };
        if !inside {
            return Err(VolumeError::ExternalData {
                field: format!("{fmt} {key}"),
                name: name.to_string(),
                resolved: data
                    .canonicalize()
                    .unwrap_or_else(|_| data.clone())
                    .display()
                    .to_string(),
            });
        }
    }
    Ok(data)
}

/// Compression level for flate2 from a user level (clamped to 0–9).
pub(crate) fn level(l: u32) -> flate2::Compression {
    flate2::Compression::new(l.min(9))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fmt_f64_round_trips() {
        for v in [
            0.0,
            -0.0,
            1.0,
            -3.0,
            0.1,
            1.0 / 3.0,
            1e-7,
            -2.5e-300,
            1e300,
            123456789.123,
            f64::MIN_POSITIVE,
        ] {
            let s = fmt_f64(v);
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), v.to_bits(), "{s}");
        }
        assert_eq!(fmt_f64(2.0), "2");
        assert_eq!(fmt_f64(0.5), "0.5");
    }

    #[test]
    fn strict_numbers() {
        assert!(parse_f64("t", "x", "nan").is_err());
        assert!(parse_f64("t", "x", "inf").is_err());
        assert!(parse_f64("t", "x", "1.5x").is_err());
        assert_eq!(parse_f64("t", "x", " -2.5e1 ").unwrap(), -25.0);
        assert!(parse_size("t", "x", "0").is_err());
        assert!(parse_size("t", "x", "-3").is_err());
        assert!(parse_size("t", "x", "99999999999999999999999").is_err());
        assert!(parse_size("t", "x", "2.5").is_err());
        assert_eq!(parse_sizes("t", "x", "2 3  4", 3).unwrap(), vec![2, 3, 4]);
        assert!(parse_sizes("t", "x", "2 3", 3).is_err());
    }

    #[test]
    fn lines_are_bounded() {
        let big = vec![b'a'; MAX_HEADER_BYTES + 10];
        let mut l = Lines::new(&big);
        assert!(l.next_line(false).is_none());
        let mut l = Lines::new(b"ab\r\ncd\nef");
        assert_eq!(l.next_line(false).unwrap(), "ab");
        assert_eq!(l.pos(), 4);
        assert_eq!(l.next_line(false).unwrap(), "cd");
        assert!(l.next_line(false).is_none());
        assert_eq!(l.next_line(true).unwrap(), "ef");
    }

    #[test]
    fn ascii_tokens_parse_strictly() {
        assert_eq!(u8::parse_token("255"), Some(255));
        assert_eq!(u8::parse_token("256"), None);
        assert_eq!(i16::parse_token("-3.0"), Some(-3));
        assert_eq!(i16::parse_token("-3.5"), None);
        assert_eq!(f32::parse_token("0.1"), Some(0.1f32));
    }
}
