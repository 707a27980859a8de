//! VTK XML image data (`.vti`): a regular grid with point scalars and, since VTK 9, a
//! direction matrix.
//!
//! # Reading
//!
//! The file is `<VTKFile type="ImageData" byte_order="LittleEndian|BigEndian"
//! header_type="UInt32|UInt64" [compressor="vtkZLibDataCompressor"]>` holding
//! `<ImageData WholeExtent="i0 i1 j0 j1 k0 k1" Origin="…" Spacing="…" [Direction="9 numbers"]>`
//! and one `<Piece Extent="…">` covering the whole extent, whose `<PointData>` holds the
//! scalars as a `<DataArray type=… [NumberOfComponents="1"] format="ascii|binary|appended">`:
//! the array named by `PointData Scalars="…"`, or else the only (or first) single-component
//! array. Every layout VTK writes is read: `ascii` text, `binary` (base64 of a byte-count
//! header and the data), `appended` data after `<AppendedData encoding="raw|base64">` and its
//! `_` marker at the array's `offset`, each optionally zlib-compressed in VTK's block framing
//! (`[blocks, block size, last block size, compressed sizes…]`, integers of `header_type`).
//! Types: `Int8`/`UInt8`/`Int16`/`UInt16`/`Int32`/`UInt32`/`Float32`/`Float64` (and the
//! legacy `char`…`double` names). Files with several pieces, multi-component arrays, LZ4 or
//! LZMA compression, or only cell data are refused as unsupported, by name.
//!
//! # Geometry
//!
//! VTK's image data maps index `(i, j, k)` of the extent to `Origin + Direction · (Spacing ⊙
//! (i, j, k))` with `Direction` given **row-major** — ITK's convention, so volmorph's geometry
//! is read as it stands: spacing and direction as written, origin moved to the first voxel of
//! the extent (`Origin + Direction · (Spacing ⊙ (i0, j0, k0))`). A missing `Direction` is the
//! identity. Negative spacings (allowed by VTK) become positive with the direction column
//! negated, as ITK does.
//!
//! # Writing
//!
//! `version="1.0"`, little-endian, `header_type="UInt64"`, `WholeExtent="0 nx−1 …"`,
//! `Origin`, `Spacing`, `Direction` in shortest round-trip form (so geometry reads back bit
//! for bit), one piece whose point scalars (`scalars`) are appended raw after the XML, or
//! zlib-compressed in 1 MiB blocks with [`WriteOptions::compress`].
//!
//! XML is parsed by `quick-xml` and base64 decoded by `base64`; only the block framing, which
//! is VTK's own, is written here.

use std::io::{Read, Write};
use std::path::Path;

use base64::Engine as _;
use glam::{DMat3, DVec3};
use quick_xml::events::{BytesStart, Event};

use crate::text_header::{self, DataSpec, Encoding, Input, Start, fmt_f64, os_err};
use crate::{Header, WriteOptions};
use volmorph_volume::{AnyVolume, Geometry, VolumeError, VoxelType};

const FMT: &str = "VTK XML image data";

/// Uncompressed size of the blocks the writer compresses (VTK's default is 32 KiB; larger
/// blocks compress a little better and any size reads back).
const WRITE_BLOCK: usize = 1 << 20;

/// Largest expansion of a zlib block accepted (zlib's documented worst case is 1032:1).
const MAX_DEFLATE_RATIO: u64 = 1032;

fn err(msg: impl Into<String>) -> VolumeError {
    VolumeError::format(FMT, msg)
}

fn vtk_type(name: &str) -> Result<VoxelType, VolumeError> {
    Ok(match name {
        "Int8" | "char" | "signed_char" => VoxelType::I8,
        "UInt8" | "unsigned_char" => VoxelType::U8,
        "Int16" | "short" => VoxelType::I16,
        "UInt16" | "unsigned_short" => VoxelType::U16,
        "Int32" | "int" => VoxelType::I32,
        "UInt32" | "unsigned_int" => VoxelType::U32,
        "Float32" | "float" => VoxelType::F32,
        "Float64" | "double" => VoxelType::F64,
        "Int64" | "UInt64" | "long" | "unsigned_long" | "String" | "Bit" => {
            return Err(VolumeError::Unsupported(format!(
                "VTK data array type {name} (supported: Int8 UInt8 Int16 UInt16 Int32 UInt32 \
                 Float32 Float64)"
            )));
        }
        other => return Err(err(format!("unknown DataArray type `{other}`"))),
    })
}

fn vtk_type_name(t: VoxelType) -> &'static str {
    match t {
        VoxelType::I8 => "Int8",
        VoxelType::U8 => "UInt8",
        VoxelType::I16 => "Int16",
        VoxelType::U16 => "UInt16",
        VoxelType::I32 => "Int32",
        VoxelType::U32 => "UInt32",
        VoxelType::F32 => "Float32",
        VoxelType::F64 => "Float64",
    }
}

/// Attributes of one element as `(name, value)` pairs.
fn attributes(e: &BytesStart<'_>) -> Result<Vec<(String, String)>, VolumeError> {
    let name = e.name().as_ref().to_owned();
    e.attributes()
        .map(|a| {
            let a = a.map_err(|x| err(format!("<{name}>: bad attribute: {x}")))?;
            let key = a.key.as_ref().to_owned();
            let value = a
                .normalized_value(quick_xml::XmlVersion::Implicit1_0)
                .map_err(|x| err(format!("<{name}> attribute {key}: {x}")))?
                .into_owned();
            Ok((key, value))
        })
        .collect()
}

fn attr<'a>(attrs: &'a [(String, String)], key: &str) -> Option<&'a str> {
    attrs
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

/// How one data array is stored.
#[derive(Debug, Clone)]
enum Storage {
    /// Text content of the element.
    Ascii(String),
    /// Base64 text content of the element.
    Binary(String),
    /// At this offset of the appended data.
    Appended(u64),
}

#[derive(Debug, Clone)]
struct Array {
    name: String,
    voxel_type: VoxelType,
    components: usize,
    storage: Storage,
}

/// Everything the XML part of the file says.
struct Parsed {
    big_endian: bool,
    header_u64: bool,
    zlib: bool,
    geometry: Geometry,
    array: Array,
    /// Byte offset of the first appended byte (just after `_`), if there is appended data.
    appended: Option<(usize, bool)>,
    header: Header,
}

fn numbers<const N: usize>(what: &str, s: &str) -> Result<[f64; N], VolumeError> {
    let v = text_header::parse_f64_list(FMT, what, s, N)?;
    let mut out = [0.0; N];
    out.copy_from_slice(&v);
    Ok(out)
}

fn extent(what: &str, s: &str) -> Result<[i64; 6], VolumeError> {
    let t: Vec<&str> = s.split_ascii_whitespace().collect();
    if t.len() != 6 {
        return Err(err(format!("{what}: expected 6 integers, found `{s}`")));
    }
    let mut e = [0i64; 6];
    for (o, x) in e.iter_mut().zip(t) {
        *o = text_header::parse_i64(FMT, what, x)?;
    }
    Ok(e)
}

/// Parse the XML up to `<AppendedData>` (or the end).
#[allow(clippy::too_many_lines)] // one pass over the element tree reads best in one piece
fn parse(bytes: &[u8]) -> Result<Parsed, VolumeError> {
    // The appended section is raw binary, not XML: parse only what precedes it.
    let xml_end = find(bytes, b"<AppendedData").unwrap_or(bytes.len());
    let mut reader = quick_xml::Reader::from_reader(&bytes[..xml_end]);
    reader.config_mut().trim_text(true);
    let mut fields: Vec<(String, String)> = Vec::new();
    let mut big_endian = false;
    let mut header_u64 = false;
    let mut zlib = false;
    let mut seen_file = false;
    let mut whole: Option<[i64; 6]> = None;
    let mut origin = DVec3::ZERO;
    let mut spacing = DVec3::ONE;
    let mut direction = DMat3::IDENTITY;
    let mut pieces = 0usize;
    let mut piece_extent: Option<[i64; 6]> = None;
    let mut in_point_data = false;
    let mut in_cell_data = false;
    let mut cell_arrays = 0usize;
    let mut active: Option<String> = None;
    let mut arrays: Vec<Array> = Vec::new();
    // The DataArray whose text content is being collected.
    let mut open_array: Option<(Array, String)> = None;
    let mut buf = Vec::new();
    loop {
        let ev = reader.read_event_into(&mut buf).map_err(|e| {
            err(format!(
                "malformed XML at byte {}: {e}",
                reader.buffer_position()
            ))
        })?;
        match ev {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let empty = matches!(ev, Event::Empty(_));
                let name = e.name().as_ref().to_owned();
                let a = attributes(e)?;
                match name.as_str() {
                    "VTKFile" => {
                        seen_file = true;
                        match attr(&a, "type") {
                            Some("ImageData") => {}
                            other => {
                                return Err(VolumeError::Unsupported(format!(
                                    "VTK XML dataset type {} (only ImageData, .vti)",
                                    other.unwrap_or("(none)")
                                )));
                            }
                        }
                        big_endian = match attr(&a, "byte_order") {
                            Some("BigEndian") => true,
                            Some("LittleEndian") | None => false,
                            Some(o) => return Err(err(format!("byte_order `{o}`"))),
                        };
                        header_u64 = match attr(&a, "header_type") {
                            Some("UInt64") => true,
                            Some("UInt32") | None => false,
                            Some(o) => return Err(err(format!("header_type `{o}`"))),
                        };
                        zlib = match attr(&a, "compressor") {
                            None | Some("") => false,
                            Some("vtkZLibDataCompressor") => true,
                            Some(o) => {
                                return Err(VolumeError::Unsupported(format!(
                                    "VTK compressor {o} (only vtkZLibDataCompressor)"
                                )));
                            }
                        };
                        for k in ["version", "byte_order", "header_type", "compressor"] {
                            if let Some(v) = attr(&a, k) {
                                fields.push((k.to_owned(), v.to_owned()));
                            }
                        }
                    }
                    "ImageData" => {
                        let w = attr(&a, "WholeExtent")
                            .ok_or_else(|| err("<ImageData> has no WholeExtent"))?;
                        whole = Some(extent("WholeExtent", w)?);
                        if let Some(o) = attr(&a, "Origin") {
                            origin = DVec3::from_array(numbers::<3>("Origin", o)?);
                        }
                        if let Some(s) = attr(&a, "Spacing") {
                            spacing = DVec3::from_array(numbers::<3>("Spacing", s)?);
                        }
                        if let Some(d) = attr(&a, "Direction") {
                            // Row-major.
                            direction =
                                DMat3::from_cols_array(&numbers::<9>("Direction", d)?).transpose();
                        }
                        for k in ["WholeExtent", "Origin", "Spacing", "Direction"] {
                            if let Some(v) = attr(&a, k) {
                                fields.push((k.to_owned(), v.to_owned()));
                            }
                        }
                    }
                    "Piece" => {
                        pieces += 1;
                        if let Some(x) = attr(&a, "Extent") {
                            piece_extent = Some(extent("Piece Extent", x)?);
                        }
                    }
                    "PointData" => {
                        in_point_data = !empty;
                        active = attr(&a, "Scalars").map(str::to_owned);
                        if let Some(s) = &active {
                            fields.push(("PointData Scalars".into(), s.clone()));
                        }
                    }
                    "CellData" => in_cell_data = !empty,
                    "DataArray" if in_cell_data => cell_arrays += 1,
                    "DataArray" if in_point_data => {
                        let ty = attr(&a, "type").ok_or_else(|| err("DataArray without type"))?;
                        let components = match attr(&a, "NumberOfComponents") {
                            Some(c) => text_header::parse_size(FMT, "NumberOfComponents", c)?,
                            None => 1,
                        };
                        let format = attr(&a, "format").unwrap_or("ascii");
                        let array_name = attr(&a, "Name").unwrap_or("").to_owned();
                        let storage = match format {
                            "ascii" => Storage::Ascii(String::new()),
                            "binary" => Storage::Binary(String::new()),
                            "appended" => {
                                let off = attr(&a, "offset").ok_or_else(|| {
                                    err(format!("appended DataArray `{array_name}` has no offset"))
                                })?;
                                let off = text_header::parse_i64(FMT, "offset", off)?;
                                Storage::Appended(u64::try_from(off).map_err(|_| {
                                    err(format!("DataArray offset {off} is negative"))
                                })?)
                            }
                            o => return Err(err(format!("DataArray format `{o}`"))),
                        };
                        fields.push((
                            format!("DataArray {array_name}"),
                            format!("{ty} ×{components} {format}"),
                        ));
                        let arr = Array {
                            name: array_name,
                            voxel_type: vtk_type(ty)?,
                            components,
                            storage,
                        };
                        if matches!(arr.storage, Storage::Appended(_)) || empty {
                            arrays.push(arr);
                        } else {
                            open_array = Some((arr, String::new()));
                        }
                    }
                    _ => {}
                }
            }
            Event::Text(t) => {
                if let Some((_, text)) = &mut open_array {
                    // Numbers or base64: no entities to resolve.
                    text.push_str(&t.into_inner());
                }
            }
            Event::End(e) => match e.name().as_ref() {
                "DataArray" => {
                    if let Some((mut arr, text)) = open_array.take() {
                        arr.storage = match arr.storage {
                            Storage::Ascii(_) => Storage::Ascii(text),
                            Storage::Binary(_) => Storage::Binary(text),
                            s @ Storage::Appended(_) => s,
                        };
                        arrays.push(arr);
                    }
                }
                "PointData" => in_point_data = false,
                "CellData" => in_cell_data = false,
                _ => {}
            },
            Event::Eof => break,
            _ => {}
        }
        buf.clear();
    }
    if !seen_file {
        return Err(err("no <VTKFile> element: not a VTK XML file"));
    }
    let whole = whole.ok_or_else(|| err("no <ImageData> element"))?;
    if pieces > 1 {
        return Err(VolumeError::Unsupported(format!(
            "VTK image data in {pieces} pieces (only single-piece files)"
        )));
    }
    if let Some(p) = piece_extent
        && p != whole
    {
        return Err(VolumeError::Unsupported(format!(
            "a piece with extent {p:?} inside the whole extent {whole:?} (only a piece \
             covering the whole extent)"
        )));
    }
    let array = pick_array(arrays, active.as_deref(), cell_arrays)?;
    let mut dims = [0usize; 3];
    let mut start = DVec3::ZERO;
    for a in 0..3 {
        let n = whole[2 * a + 1]
            .checked_sub(whole[2 * a])
            .and_then(|v| v.checked_add(1))
            .filter(|&v| v > 0)
            .ok_or_else(|| err(format!("WholeExtent {whole:?} is empty or overflows")))?;
        dims[a] = usize::try_from(n).map_err(|_| err("WholeExtent overflows"))?;
        start[a] = whole[2 * a] as f64;
    }
    // Negative spacing: positive spacing along the negated direction (ITK's reader rule).
    for a in 0..3 {
        if spacing[a] < 0.0 {
            spacing[a] = -spacing[a];
            *direction.col_mut(a) = DVec3::ZERO - direction.col(a);
            start[a] = -start[a];
        }
    }
    let geometry = Geometry {
        dims,
        spacing,
        origin: origin + direction * (spacing * start),
        direction,
    };
    geometry
        .validate()
        .map_err(|e| err(format!("the header describes an unusable geometry: {e}")))?;
    let appended = if xml_end < bytes.len() {
        // `<AppendedData encoding="…">` then optional whitespace and `_`.
        let tag_end = bytes[xml_end..]
            .iter()
            .position(|&b| b == b'>')
            .map(|p| xml_end + p + 1)
            .ok_or_else(|| err("<AppendedData> tag is not closed"))?;
        let tag = String::from_utf8_lossy(&bytes[xml_end..tag_end]);
        let base64 = if tag.contains("\"base64\"") {
            true
        } else if tag.contains("\"raw\"") {
            false
        } else {
            return Err(err(format!(
                "<AppendedData> encoding is not raw or base64: {tag}"
            )));
        };
        let us = bytes[tag_end..]
            .iter()
            .position(|&b| b == b'_')
            .ok_or_else(|| err("appended data have no `_` marker"))?;
        if !bytes[tag_end..tag_end + us]
            .iter()
            .all(u8::is_ascii_whitespace)
        {
            return Err(err(
                "unexpected text between <AppendedData> and its `_` marker",
            ));
        }
        Some((tag_end + us + 1, base64))
    } else {
        None
    };
    fields.push(("scalars".into(), array.name.clone()));
    Ok(Parsed {
        big_endian,
        header_u64,
        zlib,
        geometry,
        array,
        appended,
        header: Header { fields },
    })
}

fn pick_array(
    arrays: Vec<Array>,
    active: Option<&str>,
    cell_arrays: usize,
) -> Result<Array, VolumeError> {
    if arrays.is_empty() {
        return Err(if cell_arrays > 0 {
            VolumeError::Unsupported("VTK image with cell data only (point data needed)".into())
        } else {
            err("no point data array")
        });
    }
    let chosen = match active {
        Some(n) => arrays.iter().position(|a| a.name == n).ok_or_else(|| {
            err(format!(
                "PointData names Scalars=\"{n}\" but no DataArray has that name"
            ))
        })?,
        None => arrays.iter().position(|a| a.components == 1).unwrap_or(0),
    };
    let a = arrays.into_iter().nth(chosen).expect("index from position");
    if a.components != 1 {
        return Err(VolumeError::Unsupported(format!(
            "point data `{}` has {} components (only scalars)",
            a.name, a.components
        )));
    }
    Ok(a)
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// Base64 text to bytes, ignoring whitespace; concatenated padded segments (VTK encodes a
/// header and the data separately) are decoded one after the other.
fn base64_decode(text: &[u8]) -> Result<Vec<u8>, VolumeError> {
    let clean: Vec<u8> = text
        .iter()
        .copied()
        .filter(|b| !b.is_ascii_whitespace())
        .collect();
    let mut out = Vec::with_capacity(clean.len() / 4 * 3);
    let mut rest = &clean[..];
    while !rest.is_empty() {
        // A segment ends after the first 4-character group that holds padding.
        let mut end = rest.len();
        let mut g = 0;
        while g + 4 <= rest.len() {
            if rest[g + 2] == b'=' || rest[g + 3] == b'=' {
                end = g + 4;
                break;
            }
            g += 4;
        }
        base64::engine::general_purpose::STANDARD
            .decode_vec(&rest[..end], &mut out)
            .map_err(|e| err(format!("corrupt base64 data: {e}")))?;
        rest = &rest[end..];
    }
    Ok(out)
}

/// Reads VTK's framing integers.
struct Ints {
    u64: bool,
    big_endian: bool,
}

impl Ints {
    fn size(&self) -> usize {
        if self.u64 { 8 } else { 4 }
    }
    fn get(&self, b: &[u8], i: usize) -> Result<u64, VolumeError> {
        let s = self.size();
        let chunk = b
            .get(i * s..(i + 1) * s)
            .ok_or_else(|| err("data block header truncated"))?;
        Ok(match (self.u64, self.big_endian) {
            (true, false) => u64::from_le_bytes(chunk.try_into().expect("8 bytes")),
            (true, true) => u64::from_be_bytes(chunk.try_into().expect("8 bytes")),
            (false, false) => u64::from(u32::from_le_bytes(chunk.try_into().expect("4 bytes"))),
            (false, true) => u64::from(u32::from_be_bytes(chunk.try_into().expect("4 bytes"))),
        })
    }
}

/// The uncompressed bytes of the array from its encoded form `all`: VTK's framing header
/// (a byte count, or the block table of compressed data) followed by the data (and, for
/// appended raw data, whatever follows them).
fn unframe(p: &Parsed, need: u64, all: &[u8]) -> Result<Vec<u8>, VolumeError> {
    let ints = Ints {
        u64: p.header_u64,
        big_endian: p.big_endian,
    };
    let s = ints.size();
    if !p.zlib {
        let h = all;
        let n = ints.get(h, 0)?;
        if n != need {
            return Err(err(format!(
                "the data array holds {n} bytes, {need} expected for {} voxels",
                p.geometry.len()
            )));
        }
        let data = h.get(s..).unwrap_or(&[]);
        if (data.len() as u64) < need {
            return Err(err(format!(
                "voxel data truncated: {} of {need} bytes present",
                data.len()
            )));
        }
        return Ok(data[..need as usize].to_vec());
    }
    let blocks = ints.get(all, 0)?;
    let block = ints.get(all, 1)?;
    let last = ints.get(all, 2)?;
    let total = if blocks == 0 {
        0
    } else {
        let last_len = if last == 0 { block } else { last };
        (blocks - 1)
            .checked_mul(block)
            .and_then(|v| v.checked_add(last_len))
            .ok_or_else(|| err("compressed block sizes overflow"))?
    };
    if total != need {
        return Err(err(format!(
            "compressed data hold {total} bytes in {blocks} blocks, {need} expected"
        )));
    }
    let hlen = usize::try_from(blocks)
        .ok()
        .and_then(|b| b.checked_add(3))
        .and_then(|b| b.checked_mul(s))
        .filter(|&l| l as u64 <= need.saturating_add(1 << 20))
        .ok_or_else(|| err(format!("{blocks} compressed blocks is impossible")))?;
    let mut csizes = Vec::with_capacity(blocks as usize);
    let mut csum = 0u64;
    for b in 0..blocks as usize {
        let c = ints.get(all, 3 + b)?;
        csum = csum.saturating_add(c);
        csizes.push(c);
    }
    if csum.saturating_mul(MAX_DEFLATE_RATIO).saturating_add(64) < need {
        return Err(err("compressed data too short for the declared size"));
    }
    let data = all.get(hlen..).unwrap_or(&[]);
    if (data.len() as u64) < csum {
        return Err(err(format!(
            "compressed data truncated: {} of {csum} bytes present",
            data.len()
        )));
    }
    let mut out = Vec::new();
    out.try_reserve_exact(need as usize)
        .map_err(|_| err(format!("cannot allocate {need} bytes")))?;
    let mut pos = 0usize;
    for (b, &c) in csizes.iter().enumerate() {
        let expect = if b + 1 == csizes.len() && last != 0 {
            last
        } else {
            block
        };
        let before = out.len();
        let mut dec = flate2::read::ZlibDecoder::new(&data[pos..pos + c as usize]);
        (&mut dec)
            .take(expect + 1)
            .read_to_end(&mut out)
            .map_err(|e| err(format!("corrupt zlib block {b}: {e}")))?;
        if (out.len() - before) as u64 != expect {
            return Err(err(format!(
                "zlib block {b} holds {} bytes, {expect} expected",
                out.len() - before
            )));
        }
        pos += c as usize;
    }
    Ok(out)
}

fn decode_array(bytes: &[u8], p: &Parsed) -> Result<AnyVolume, VolumeError> {
    let vt = p.array.voxel_type;
    let n = volmorph_io::checked_len(&p.geometry.dims, vt.size())?;
    let need = (n * vt.size()) as u64;
    let raw_spec = |big_endian| DataSpec {
        fmt: FMT,
        voxel_type: vt,
        big_endian,
        encoding: Encoding::Raw,
        start: Start::Offset(0),
        line_skip: 0,
        decoded_skip: 0,
        encoded_len: None,
        exact: true,
        words: None,
    };
    let raw = match &p.array.storage {
        Storage::Ascii(text) => {
            let spec = DataSpec {
                encoding: Encoding::Ascii,
                exact: false,
                ..raw_spec(false)
            };
            return text_header::decode(Input::Bytes(text.as_bytes()), &spec, p.geometry);
        }
        Storage::Binary(text) => {
            // The header and the data are base64-encoded separately; decode the whole.
            unframe(p, need, &base64_decode(text.as_bytes())?)?
        }
        Storage::Appended(off) => {
            let (start, base64) = p
                .appended
                .ok_or_else(|| err("an appended DataArray but no <AppendedData> section"))?;
            let at = usize::try_from(*off)
                .ok()
                .and_then(|o| o.checked_add(start))
                .filter(|&a| a <= bytes.len())
                .ok_or_else(|| err(format!("appended offset {off} lies beyond the file")))?;
            let tail = &bytes[at..];
            if base64 {
                let end = tail.iter().position(|&b| b == b'<').unwrap_or(tail.len());
                unframe(p, need, &base64_decode(&tail[..end])?)?
            } else {
                unframe(p, need, tail)?
            }
        }
    };
    text_header::decode(Input::Bytes(&raw), &raw_spec(p.big_endian), p.geometry)
}

/// Read a `.vti` file held in memory.
///
/// # Errors
/// [`VolumeError::Format`] for malformed XML, geometry or data; [`VolumeError::Unsupported`]
/// for other datasets, several pieces, vectors, 64-bit integers and LZ4/LZMA compression.
pub fn read_bytes(bytes: &[u8]) -> Result<(AnyVolume, Header), VolumeError> {
    let p = parse(bytes)?;
    let v = decode_array(bytes, &p)?;
    Ok((v, p.header))
}

pub(crate) fn read(path: &Path) -> Result<(AnyVolume, Header), VolumeError> {
    let len = std::fs::metadata(path).map_err(os_err(path))?.len();
    volmorph_io::checked_len(&[usize::try_from(len).unwrap_or(usize::MAX)], 1)?;
    let bytes = std::fs::read(path).map_err(os_err(path))?;
    read_bytes(&bytes)
}

/// Write a `.vti` file (see the [module docs](self)).
pub(crate) fn write(
    path: &Path,
    volume: &AnyVolume,
    options: &WriteOptions,
) -> Result<(), VolumeError> {
    let g = volume.geometry();
    g.validate()?;
    let join = |v: &[f64]| v.iter().map(|&x| fmt_f64(x)).collect::<Vec<_>>().join(" ");
    let ext = format!(
        "0 {} 0 {} 0 {}",
        g.dims[0] - 1,
        g.dims[1] - 1,
        g.dims[2] - 1
    );
    let compressor = if options.compress {
        " compressor=\"vtkZLibDataCompressor\""
    } else {
        ""
    };
    let xml = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt64\"{compressor}>\n  <ImageData \
         WholeExtent=\"{ext}\" Origin=\"{}\" Spacing=\"{}\" Direction=\"{}\">\n    <Piece \
         Extent=\"{ext}\">\n      <PointData Scalars=\"scalars\">\n        <DataArray \
         type=\"{}\" Name=\"scalars\" format=\"appended\" offset=\"0\"/>\n      </PointData>\n      \
         <CellData/>\n    </Piece>\n  </ImageData>\n  <AppendedData encoding=\"raw\">\n   _",
        join(&g.origin.to_array()),
        join(&g.spacing.to_array()),
        join(&g.direction.transpose().to_cols_array()),
        vtk_type_name(volume.voxel_type()),
    );
    let os = os_err(path);
    volmorph_io::write_atomic::<VolumeError, _>(path, |w| {
        w.write_all(xml.as_bytes()).map_err(os)?;
        let mut data = Vec::new();
        let bytes: &[u8] = if cfg!(target_endian = "little") {
            volume.as_bytes()
        } else {
            text_header::write_voxels(&mut data, volume, false).map_err(os)?;
            &data
        };
        if options.compress {
            let blocks: Vec<Vec<u8>> = bytes
                .chunks(WRITE_BLOCK)
                .map(|c| {
                    let mut e = flate2::write::ZlibEncoder::new(
                        Vec::with_capacity(c.len() / 2),
                        text_header::level(options.level),
                    );
                    e.write_all(c)?;
                    e.finish()
                })
                .collect::<std::io::Result<_>>()
                .map_err(os)?;
            let last = bytes.len() % WRITE_BLOCK;
            let mut head: Vec<u64> = vec![blocks.len() as u64, WRITE_BLOCK as u64, last as u64];
            head.extend(blocks.iter().map(|b| b.len() as u64));
            for h in head {
                w.write_all(&h.to_le_bytes()).map_err(os)?;
            }
            for b in &blocks {
                w.write_all(b).map_err(os)?;
            }
        } else {
            w.write_all(&(bytes.len() as u64).to_le_bytes())
                .map_err(os)?;
            w.write_all(bytes).map_err(os)?;
        }
        w.write_all(b"\n  </AppendedData>\n</VTKFile>\n")
            .map_err(os)
    })
}
