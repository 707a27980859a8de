//! Stanford PLY: `ascii`, `binary_little_endian` and `binary_big_endian`, version 1.0.
//!
//! **Read.** The header's `element`/`property` declarations drive the parse. The `vertex`
//! element must have scalar properties `x`, `y`, `z`, of any scalar type (`char`/`int8`,
//! `uchar`/`uint8`, `short`/`int16`, `ushort`/`uint16`, `int`/`int32`, `uint`/`uint32`,
//! `float`/`float32`, `double`/`float64`); they are converted exactly to `f64` (an ASCII
//! value declared `float` is parsed to the nearest `f32`, as a binary one would be stored).
//! The `face` element's list property `vertex_indices` (or `vertex_index`) gives the polygons;
//! its count and index types may be any integer type (a float index must be integral). Every
//! other element and property — normals, colours, texture coordinates, `edge`, `material`,
//! lists — is skipped, by its declared size in binary files, except that
//! [`read_ply_bytes_with_colors`] also returns the `red green blue` colour channels of the
//! vertex or face element. `comment` and `obj_info` lines
//! are ignored. A file without a `face` element is a point cloud (a mesh without faces).
//! Data after the last declared element is ignored.
//!
//! Counts in the header are never trusted for allocation. When the file's size is known (an
//! uncompressed file, bytes in memory), memory is reserved only as far as the remaining data
//! can hold, and a binary element of fixed size (or a list) whose declared length does not
//! fit in the file is refused before reading it. A stream ([`read_ply_stream`], a gzip file)
//! is parsed as it arrives, never held whole: memory is reserved in bounded steps and the
//! mesh grows within the memory budget; a binary element or list longer than the data is
//! refused where the data ends, with the same message, and nothing in such an element is
//! reported on before it is known to be whole, so errors are those of the whole file.
//!
//! **Write.** `vertex` with `double` (or `float`, on request) `x y z`, and `face` with
//! `property list uchar int vertex_indices` (wider count/index types only when a face has
//! more than 255 vertices or there are more than 2³¹ vertices).
//!
//! **Extra properties.** [`write_ply_with_properties`] appends caller-supplied scalar
//! properties ([`PlyProperties`]) to the `vertex` element (after `x y z`, in the order given)
//! and to the `face` element (after `vertex_indices`): `uchar` ([`PlyValues::U8`], e.g. the
//! conventional `red green blue` colour channels), `float` ([`PlyValues::F32`]) or `double`
//! ([`PlyValues::F64`]), one value per vertex or face. The reader skips such properties.

use std::io::{BufRead, Write};

use glam::DVec3;

use super::Builder;
use super::input::{Ignore, Input, Source, at_byte, reserve_within};
use super::text::{
    parse_f32, parse_f64, parse_i64, show, write_f32, write_f64, write_face_indices,
};
use crate::error::Location;
use crate::{Mesh, MeshColors, MeshError, MeshFormat};

/// Encoding of a PLY file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyEncoding {
    /// `format ascii 1.0`.
    Ascii,
    /// `format binary_little_endian 1.0`.
    BinaryLittleEndian,
    /// `format binary_big_endian 1.0`.
    BinaryBigEndian,
}

impl PlyEncoding {
    fn keyword(self) -> &'static str {
        match self {
            Self::Ascii => "ascii",
            Self::BinaryLittleEndian => "binary_little_endian",
            Self::BinaryBigEndian => "binary_big_endian",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &[u8]) -> Option<Self> {
        Some(match name {
            b"char" | b"int8" => Self::I8,
            b"uchar" | b"uint8" => Self::U8,
            b"short" | b"int16" => Self::I16,
            b"ushort" | b"uint16" => Self::U16,
            b"int" | b"int32" => Self::I32,
            b"uint" | b"uint32" => Self::U32,
            b"float" | b"float32" => Self::F32,
            b"double" | b"float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    /// Decode a binary value; `b` holds at least `size()` bytes.
    #[inline(always)]
    fn read_f64(self, b: &[u8], big: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:literal) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        match self {
            Self::I8 => f64::from(b[0] as i8),
            Self::U8 => f64::from(b[0]),
            Self::I16 => f64::from(get!(i16, 2)),
            Self::U16 => f64::from(get!(u16, 2)),
            Self::I32 => f64::from(get!(i32, 4)),
            Self::U32 => f64::from(get!(u32, 4)),
            Self::F32 => f64::from(get!(f32, 4)),
            Self::F64 => get!(f64, 8),
        }
    }

    /// Decode a binary integer (floats must be integral and within ±2⁵³).
    #[inline(always)]
    fn read_int(self, b: &[u8], big: bool) -> Option<i64> {
        let v = self.read_f64(b, big);
        if matches!(self, Self::F32 | Self::F64) {
            (v.fract() == 0.0 && v.abs() <= 9_007_199_254_740_992.0).then_some(v as i64)
        } else {
            Some(v as i64)
        }
    }

    /// Parse an ASCII value as this type would hold it.
    #[inline]
    fn parse_value(self, tok: &[u8]) -> Option<f64> {
        match self {
            Self::F32 => parse_f32(tok).map(f64::from),
            Self::F64 => parse_f64(tok),
            _ => parse_i64(tok).map(|v| v as f64),
        }
    }

    /// Parse an ASCII integer (floats must be integral).
    #[inline]
    fn parse_int(self, tok: &[u8]) -> Option<i64> {
        match self {
            Self::F32 | Self::F64 => {
                let v = parse_f64(tok)?;
                (v.fract() == 0.0 && v.abs() <= 9_007_199_254_740_992.0).then_some(v as i64)
            }
            _ => parse_i64(tok),
        }
    }
}

#[derive(Debug, Clone)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

impl Element {
    /// Byte size of one item if every property is a scalar.
    fn fixed_size(&self) -> Option<usize> {
        self.props.iter().try_fold(0usize, |acc, p| match p.kind {
            Kind::Scalar(s) => Some(acc + s.size()),
            Kind::List { .. } => None,
        })
    }
}

struct Header {
    encoding: PlyEncoding,
    elements: Vec<Element>,
}

/// Header keywords whose lines are ignored (and not held while reading a stream).
const COMMENT_WORDS: &[&[u8]] = &[b"comment", b"obj_info"];

fn herr(line: usize, m: impl Into<String>) -> MeshError {
    MeshError::parse(MeshFormat::Ply, Location::Line(line), m)
}

/// Read the header, leaving `input` at the first byte of the data.
fn parse_header<S: Source>(input: &mut Input<S>) -> Result<Header, MeshError> {
    let mut line_no = 0usize;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        line_no += 1;
        let found = input.read_line(Ignore::AfterWord(COMMENT_WORDS))?;
        let Some(found) = found.filter(|l| l.newline) else {
            return Err(herr(
                line_no,
                if line_no == 1 {
                    "not a PLY file (no header line)".to_string()
                } else {
                    "header ended without 'end_header'".to_string()
                },
            ));
        };
        let line = input.line_bytes(&found);
        let mut words = super::text::Words::new(line);
        let first = words.next();
        if line_no == 1 {
            if first != Some(b"ply") || words.next().is_some() {
                return Err(herr(1, "not a PLY file (first line must be 'ply')"));
            }
            continue;
        }
        let Some(kw) = first else {
            continue; // tolerate blank header lines
        };
        match kw {
            b"comment" | b"obj_info" => {}
            b"format" => {
                let enc = match words.next() {
                    Some(b"ascii") => PlyEncoding::Ascii,
                    Some(b"binary_little_endian") => PlyEncoding::BinaryLittleEndian,
                    Some(b"binary_big_endian") => PlyEncoding::BinaryBigEndian,
                    other => {
                        return Err(herr(
                            line_no,
                            format!("unknown format '{}'", show(other.unwrap_or(b""))),
                        ));
                    }
                };
                match words.next() {
                    Some(b"1.0" | b"1") => {}
                    other => {
                        return Err(herr(
                            line_no,
                            format!(
                                "unsupported PLY version '{}' (only 1.0)",
                                show(other.unwrap_or(b""))
                            ),
                        ));
                    }
                }
                if encoding.replace(enc).is_some() {
                    return Err(herr(line_no, "second 'format' line"));
                }
            }
            b"element" => {
                let (Some(name), Some(count)) = (words.next(), words.next()) else {
                    return Err(herr(line_no, "'element' needs a name and a count"));
                };
                let count = parse_i64(count)
                    .and_then(|c| usize::try_from(c).ok())
                    .ok_or_else(|| herr(line_no, format!("bad element count '{}'", show(count))))?;
                let name = String::from_utf8_lossy(name).into_owned();
                if elements.iter().any(|e| e.name == name) {
                    return Err(herr(line_no, format!("element '{name}' declared twice")));
                }
                elements.push(Element {
                    name,
                    count,
                    props: Vec::new(),
                });
            }
            b"property" => {
                let Some(el) = elements.last_mut() else {
                    return Err(herr(line_no, "'property' before any 'element'"));
                };
                let ty = words
                    .next()
                    .ok_or_else(|| herr(line_no, "'property' needs a type"))?;
                let scalar = |w: Option<&[u8]>| {
                    let w = w.unwrap_or(b"");
                    Scalar::parse(w).ok_or_else(|| {
                        herr(line_no, format!("unknown property type '{}'", show(w)))
                    })
                };
                let kind = if ty == b"list" {
                    let count = scalar(words.next())?;
                    if matches!(count, Scalar::F32 | Scalar::F64) {
                        return Err(herr(line_no, "a list count type must be an integer type"));
                    }
                    let item = scalar(words.next())?;
                    Kind::List { count, item }
                } else {
                    Kind::Scalar(scalar(Some(ty))?)
                };
                let name = words
                    .next()
                    .ok_or_else(|| herr(line_no, "'property' needs a name"))?;
                el.props.push(Property {
                    name: String::from_utf8_lossy(name).into_owned(),
                    kind,
                });
            }
            b"end_header" => break,
            other => {
                return Err(herr(
                    line_no,
                    format!("unknown header keyword '{}'", show(other)),
                ));
            }
        }
    }
    let encoding = encoding.ok_or_else(|| herr(line_no, "header has no 'format' line"))?;
    Ok(Header { encoding, elements })
}

/// What the reader does with each element's properties.
struct Roles {
    vertex: Option<usize>,
    /// Property indices of x, y, z in the vertex element.
    xyz: [usize; 3],
    face: Option<usize>,
    /// Property index of the face index list.
    face_list: usize,
    /// Property indices of the colour channels in the vertex element, if it has all three.
    vertex_rgb: Option<[usize; 3]>,
    /// Property indices of the colour channels in the face element, if it has all three.
    face_rgb: Option<[usize; 3]>,
}

/// Names of the red, green and blue channel properties, in order of preference.
const CHANNEL_NAMES: [[&str; 3]; 3] = [
    ["red", "r", "diffuse_red"],
    ["green", "g", "diffuse_green"],
    ["blue", "b", "diffuse_blue"],
];

/// Property indices of the scalar `red green blue` channels of `el` (or `r g b`,
/// `diffuse_red …`), if all three are there.
fn find_rgb(el: &Element) -> Option<[usize; 3]> {
    let mut out = [0usize; 3];
    for (k, names) in CHANNEL_NAMES.iter().enumerate() {
        out[k] = names.iter().find_map(|n| {
            el.props
                .iter()
                .position(|p| p.name == *n && matches!(p.kind, Kind::Scalar(_)))
        })?;
    }
    Some(out)
}

/// An 8-bit channel from a colour property value of type `s`: integers are taken as 0‥=255
/// (clamped; 16-bit ones scaled by 255/65535), floats as 0‥=1 (scaled by 255 and rounded).
/// `None` for a value that is not finite.
fn channel(s: Scalar, v: f64) -> Option<u8> {
    if !v.is_finite() {
        return None;
    }
    let c = match s {
        Scalar::F32 | Scalar::F64 => v * 255.0,
        Scalar::U16 | Scalar::I16 => v * 255.0 / 65535.0,
        _ => v,
    };
    Some(c.round().clamp(0.0, 255.0) as u8)
}

/// Colour channels gathered while reading one element.
struct ColorSink {
    /// Property indices of red, green, blue.
    props: [usize; 3],
    colors: Vec<[u8; 3]>,
    current: [u8; 3],
}

impl ColorSink {
    fn new(props: Option<[usize; 3]>) -> Option<Self> {
        props.map(|props| Self {
            props,
            colors: Vec::new(),
            current: [0; 3],
        })
    }

    /// Record property `pi` of type `s` with value `v`; false for a non-finite channel.
    #[inline]
    fn take(&mut self, pi: usize, s: Scalar, v: f64) -> bool {
        match self.props.iter().position(|&p| p == pi) {
            Some(k) => match channel(s, v) {
                Some(c) => {
                    self.current[k] = c;
                    true
                }
                None => false,
            },
            None => true,
        }
    }

    #[inline]
    fn wants(&self, pi: usize) -> bool {
        self.props.contains(&pi)
    }

    fn end_item(&mut self) {
        self.colors.push(self.current);
    }
}

fn find_roles(h: &Header) -> Result<Roles, MeshError> {
    let ferr = |m: String| MeshError::parse(MeshFormat::Ply, Location::Header, m);
    let mut roles = Roles {
        vertex: None,
        xyz: [0; 3],
        face: None,
        face_list: 0,
        vertex_rgb: None,
        face_rgb: None,
    };
    for (ei, el) in h.elements.iter().enumerate() {
        if el.name == "vertex" {
            roles.vertex = Some(ei);
            for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
                let pi = el
                    .props
                    .iter()
                    .position(|p| p.name == axis)
                    .ok_or_else(|| ferr(format!("vertex element has no '{axis}' property")))?;
                if !matches!(el.props[pi].kind, Kind::Scalar(_)) {
                    return Err(ferr(format!("vertex property '{axis}' is a list")));
                }
                roles.xyz[k] = pi;
            }
            roles.vertex_rgb = find_rgb(el);
        } else if el.name == "face" {
            roles.face = Some(ei);
            roles.face_rgb = find_rgb(el);
            let pi = el
                .props
                .iter()
                .position(|p| p.name == "vertex_indices")
                .or_else(|| el.props.iter().position(|p| p.name == "vertex_index"))
                .ok_or_else(|| {
                    ferr("face element has no 'vertex_indices' or 'vertex_index' list".into())
                })?;
            if !matches!(el.props[pi].kind, Kind::List { .. }) {
                return Err(ferr(format!(
                    "face property '{}' is not a list",
                    el.props[pi].name
                )));
            }
            roles.face_list = pi;
        }
    }
    if roles.face.is_some() && roles.vertex.is_none() {
        return Err(ferr("file has faces but no vertex element".into()));
    }
    Ok(roles)
}

/// Parse a PLY file from its (uncompressed) bytes.
///
/// # Errors
/// [`MeshError::Parse`] for a malformed header (with its line), a missing `x`/`y`/`z` or face
/// index list, truncated or malformed data (byte offset for binary, line for ASCII), a face
/// with fewer than three vertices or an index outside the vertices;
/// [`MeshError::TooLarge`] beyond the 32-bit limits; [`volmorph_io::IoError::Budget`] (as
/// [`MeshError::Io`]) when the mesh outgrows the memory budget.
pub fn read_ply_bytes(bytes: &[u8]) -> Result<Mesh, MeshError> {
    read_ply_input(&mut Input::slice(bytes, MeshFormat::Ply), false).map(|(m, _)| m)
}

/// Parse a PLY file as [`read_ply_bytes`] does, and also its colours: the vertex element's
/// `red green blue` properties (also named `r g b` or `diffuse_red …`) when it has all three,
/// else the face element's; `None` when neither has them. Integer channels are taken as
/// 0‥=255 (clamped; 16-bit ones scaled), float channels as 0‥=1.
///
/// # Errors
/// As [`read_ply_bytes`], and [`MeshError::Parse`] for a colour value that is not finite.
pub fn read_ply_bytes_with_colors(bytes: &[u8]) -> Result<(Mesh, Option<MeshColors>), MeshError> {
    read_ply_input(&mut Input::slice(bytes, MeshFormat::Ply), true)
}

/// Parse a PLY file from a stream, as it is read (for instance while a gzip file is
/// inflated): memory holds the mesh and one window of input (a header line, a token, a
/// binary item), never the whole file; header comments are skipped as they are read. The
/// stream's size is not known, so a binary element longer than the data is found where the
/// data ends, and the mesh is checked against the memory budget as it grows.
///
/// # Errors
/// As [`read_ply_bytes`]; [`MeshError::Io`] when reading fails, and [`MeshError::Parse`] for
/// a header line or ASCII word longer than [`MAX_STREAM_LINE`](super::obj::MAX_STREAM_LINE).
pub fn read_ply_stream(r: &mut dyn BufRead) -> Result<Mesh, MeshError> {
    read_ply_stream_with_colors(r).map(|(m, _)| m)
}

/// [`read_ply_stream`] with the colours of [`read_ply_bytes_with_colors`].
///
/// # Errors
/// As [`read_ply_stream`], and [`MeshError::Parse`] for a colour value that is not finite.
pub fn read_ply_stream_with_colors(
    r: &mut dyn BufRead,
) -> Result<(Mesh, Option<MeshColors>), MeshError> {
    let mut input = Input::reader(r, None, MeshFormat::Ply, "PLY stream".into());
    read_ply_input(&mut input, true)
}

/// The PLY reader over any input; colour properties are read only when `colors` is set
/// (otherwise they are skipped like any other property).
pub(crate) fn read_ply_input<S: Source>(
    input: &mut Input<S>,
    colors: bool,
) -> Result<(Mesh, Option<MeshColors>), MeshError> {
    let h = parse_header(input)?;
    let mut roles = find_roles(&h)?;
    if !colors {
        roles.vertex_rgb = None;
        roles.face_rgb = None;
    }
    let nv = roles.vertex.map_or(0, |v| h.elements[v].count);
    crate::mesh::check_vertex_count(nv)?;
    match h.encoding {
        PlyEncoding::Ascii => read_ascii(&h, &roles, input),
        PlyEncoding::BinaryLittleEndian => read_binary(&h, &roles, input, false),
        PlyEncoding::BinaryBigEndian => read_binary(&h, &roles, input, true),
    }
}

fn face_len_error(loc: Location, face: usize, k: i64) -> MeshError {
    MeshError::parse(
        MeshFormat::Ply,
        loc,
        format!("face {face} has {k} vertices; a polygon needs at least 3"),
    )
}

fn index_error(loc: Location, face: usize, i: Option<i64>, nv: usize) -> MeshError {
    MeshError::parse(
        MeshFormat::Ply,
        loc,
        match i {
            Some(i) => format!("face {face} refers to vertex {i}, but there are {nv} vertices"),
            None => format!("face {face} has a non-integer vertex index"),
        },
    )
}

/// Byte offset of property `pi` within an item of `el` (all of whose properties before it
/// are scalars).
fn scalar_offset(el: &Element, pi: usize) -> usize {
    el.props[..pi]
        .iter()
        .map(|p| match p.kind {
            Kind::Scalar(s) => s.size(),
            Kind::List { .. } => 0,
        })
        .sum()
}

fn read_binary<S: Source>(
    h: &Header,
    roles: &Roles,
    input: &mut Input<S>,
    big: bool,
) -> Result<(Mesh, Option<MeshColors>), MeshError> {
    let mut b = Builder::new();
    let mut vcol = ColorSink::new(roles.vertex_rgb);
    let mut fcol = ColorSink::new(roles.face_rgb);
    let nv = roles.vertex.map_or(0, |v| h.elements[v].count);
    for (ei, el) in h.elements.iter().enumerate() {
        let is_vertex = roles.vertex == Some(ei);
        let is_face = roles.face == Some(ei);
        if el.props.is_empty() {
            continue; // occupies no bytes
        }
        if let Some(stride) = el.fixed_size() {
            // The element must be whole before any of its items is reported on: checked here
            // when the input's size is known, else where the data ends.
            let start = input.offset();
            let need = (el.count as u128) * (stride as u128);
            let short = |avail: u64| {
                MeshError::parse(
                    MeshFormat::Ply,
                    at_byte(start),
                    format!(
                        "element '{}' declares {} items of {stride} bytes ({need} bytes) but \
                         only {avail} bytes remain (truncated file or wrong count)",
                        el.name, el.count
                    ),
                )
            };
            if let Some(avail) = input.remaining()
                && need > u128::from(avail)
            {
                return Err(short(avail));
            }
            if !is_vertex {
                let want = u64::try_from(need).unwrap_or(u64::MAX);
                let got = input.skip(want)?;
                if got < want {
                    return Err(short(got));
                }
                continue;
            }
            let mut offs = [0usize; 3];
            let mut tys = [Scalar::F32; 3];
            for k in 0..3 {
                let pi = roles.xyz[k];
                offs[k] = scalar_offset(el, pi);
                if let Kind::Scalar(s) = el.props[pi].kind {
                    tys[k] = s;
                }
            }
            // Offset and type of each colour channel.
            let col = vcol.as_ref().map(|sink| {
                sink.props.map(|pi| match el.props[pi].kind {
                    Kind::Scalar(s) => (scalar_offset(el, pi), s),
                    Kind::List { .. } => (scalar_offset(el, pi), Scalar::U8),
                })
            });
            reserve_within(&mut b.positions, input.capacity_hint(el.count, stride));
            let mut bad = None;
            let mut done = 0usize;
            while done < el.count {
                let window = input.window();
                let k = (el.count - done).min(window.len() / stride);
                if k == 0 {
                    if !input.ensure(stride)? {
                        return Err(short(input.end() - start));
                    }
                    continue;
                }
                let items = &window[..k * stride];
                if bad.is_none() && col.is_none() && tys == [Scalar::F64; 3] && offs == [0, 8, 16] {
                    // The usual layouts, decoded directly.
                    b.reserve_vertices(k)?;
                    for item in items.chunks_exact(stride) {
                        let c = |o: usize| {
                            let a: [u8; 8] = item[o..o + 8].try_into().unwrap_or_default();
                            if big {
                                f64::from_be_bytes(a)
                            } else {
                                f64::from_le_bytes(a)
                            }
                        };
                        b.positions.push(DVec3::new(c(0), c(8), c(16)));
                    }
                } else if bad.is_none()
                    && col.is_none()
                    && tys == [Scalar::F32; 3]
                    && offs == [0, 4, 8]
                {
                    b.reserve_vertices(k)?;
                    for item in items.chunks_exact(stride) {
                        let c = |o: usize| {
                            let a: [u8; 4] = item[o..o + 4].try_into().unwrap_or_default();
                            f64::from(if big {
                                f32::from_be_bytes(a)
                            } else {
                                f32::from_le_bytes(a)
                            })
                        };
                        b.positions.push(DVec3::new(c(0), c(4), c(8)));
                    }
                } else if bad.is_none() {
                    let at = input.offset();
                    b.reserve_vertices(k)?;
                    for (j, item) in items.chunks_exact(stride).enumerate() {
                        let c = |k: usize| tys[k].read_f64(&item[offs[k]..], big);
                        b.positions.push(DVec3::new(c(0), c(1), c(2)));
                        if let (Some(sink), Some(col)) = (vcol.as_mut(), col) {
                            let mut rgb = [0u8; 3];
                            for (ch, &(off, t)) in col.iter().enumerate() {
                                match channel(t, t.read_f64(&item[off..], big)) {
                                    Some(v) => rgb[ch] = v,
                                    None => {
                                        bad = Some(bad_color(
                                            at + (j * stride) as u64,
                                            "vertex",
                                            done + j,
                                        ));
                                        break;
                                    }
                                }
                            }
                            if bad.is_some() {
                                break;
                            }
                            sink.colors.push(rgb);
                        }
                    }
                }
                input.advance(k * stride);
                done += k;
            }
            if let Some(e) = bad {
                return Err(e);
            }
            continue;
        }
        // Elements with lists: item by item, straight from the window when it holds the item.
        let min_item: usize = el
            .props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => s.size(),
                Kind::List { count, .. } => count.size(),
            })
            .sum();
        let cap = input.capacity_hint(el.count, min_item);
        if is_vertex {
            reserve_within(&mut b.positions, cap);
        }
        if is_face {
            reserve_within(&mut b.offsets, cap);
            reserve_within(
                &mut b.indices,
                input.capacity_hint(cap.saturating_mul(3), 1),
            );
        }
        let r = ItemReader {
            el,
            roles,
            is_vertex,
            is_face,
            big,
            nv,
        };
        let mut item = 0usize;
        while item < el.count {
            // The items the window holds whole, read in place.
            let window = input.window();
            let at = input.offset();
            let mut pos = 0usize;
            while item < el.count {
                let (start, corners) = (pos, b.indices.len());
                let mut xyz = [0.0f64; 3];
                let sink = if is_vertex {
                    vcol.as_mut()
                } else if is_face {
                    fcol.as_mut()
                } else {
                    None
                };
                if !r.item_in(window, &mut pos, at, item, &mut xyz, &mut b, sink)? {
                    // It goes on past the window: undone, and read with more care below.
                    pos = start;
                    b.indices.truncate(corners);
                    break;
                }
                r.end_item(xyz, &mut b, &mut vcol, &mut fcol)?;
                item += 1;
            }
            input.advance(pos);
            if item < el.count {
                let mut xyz = [0.0f64; 3];
                let sink = if is_vertex {
                    vcol.as_mut()
                } else if is_face {
                    fcol.as_mut()
                } else {
                    None
                };
                r.partial_item(input, item, &mut xyz, &mut b, sink)?;
                r.end_item(xyz, &mut b, &mut vcol, &mut fcol)?;
                item += 1;
            }
        }
    }
    Ok((b.finish(), pick_colors(vcol, fcol)))
}

fn bad_color(at: u64, what: &str, item: usize) -> MeshError {
    MeshError::parse(
        MeshFormat::Ply,
        at_byte(at),
        format!("{what} {item} has a colour channel that is not a finite number"),
    )
}

fn truncated(at: u64, what: String) -> MeshError {
    MeshError::parse(
        MeshFormat::Ply,
        at_byte(at),
        format!("data ends inside {what} (truncated file)"),
    )
}

/// Reads the items of a binary element that has lists.
struct ItemReader<'a> {
    el: &'a Element,
    roles: &'a Roles,
    is_vertex: bool,
    is_face: bool,
    big: bool,
    /// Vertices in the file.
    nv: usize,
}

impl ItemReader<'_> {
    /// Scalar property `pi` of type `s` of item `item`, its bytes starting at `bytes`, at
    /// offset `at`: a vertex coordinate or a colour channel is kept.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn scalar(
        &self,
        pi: usize,
        s: Scalar,
        bytes: &[u8],
        at: u64,
        item: usize,
        xyz: &mut [f64; 3],
        sink: Option<&mut ColorSink>,
    ) -> Result<(), MeshError> {
        if self.is_vertex
            && let Some(k) = self.roles.xyz.iter().position(|&x| x == pi)
        {
            xyz[k] = s.read_f64(bytes, self.big);
        }
        if let Some(sink) = sink
            && sink.wants(pi)
            && !sink.take(pi, s, s.read_f64(bytes, self.big))
        {
            return Err(bad_color(at, &self.el.name, item));
        }
        Ok(())
    }

    /// The whole index list (`n` items of type `it`, at offset `at`) of face `item`.
    #[inline(always)]
    fn face_list(
        &self,
        b: &mut Builder,
        list: &[u8],
        it: Scalar,
        n: i64,
        at: u64,
        item: usize,
    ) -> Result<(), MeshError> {
        if n < 3 {
            return Err(face_len_error(at_byte(at), item, n));
        }
        // The list is in memory: its length is justified by the data.
        b.reserve_corners(n as usize)?;
        for v in list.chunks_exact(it.size()) {
            match it.read_int(v, self.big) {
                Some(i) if i >= 0 && (i as u64) < self.nv as u64 => b.indices.push(i as u32),
                i => return Err(index_error(at_byte(at), item, i, self.nv)),
            }
        }
        Ok(())
    }

    /// Item `item` from `w` at `*pos` (`w` starts at offset `at`), moving `*pos` past it:
    /// `false` as soon as a property goes on past `w` (the item's corners pushed so far are
    /// then the caller's to undo). Each property is used only once `w` holds it whole, so
    /// errors are reported in the order of the file, as by [`ItemReader::partial_item`].
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn item_in(
        &self,
        w: &[u8],
        pos: &mut usize,
        at: u64,
        item: usize,
        xyz: &mut [f64; 3],
        b: &mut Builder,
        mut sink: Option<&mut ColorSink>,
    ) -> Result<bool, MeshError> {
        let mut p = *pos;
        for (pi, prop) in self.el.props.iter().enumerate() {
            match prop.kind {
                Kind::Scalar(s) => {
                    let Some(bytes) = w.get(p..p + s.size()) else {
                        return Ok(false);
                    };
                    self.scalar(pi, s, bytes, at + p as u64, item, xyz, sink.as_deref_mut())?;
                    p += s.size();
                }
                Kind::List { count, item: it } => {
                    let Some(cb) = w.get(p..p + count.size()) else {
                        return Ok(false);
                    };
                    let n = count.read_int(cb, self.big).unwrap_or(-1);
                    if n < 0 {
                        return Err(MeshError::parse(
                            MeshFormat::Ply,
                            at_byte(at + p as u64),
                            format!("negative list length {n} in {} {item}", self.el.name),
                        ));
                    }
                    p += count.size();
                    let Some(list) = (n as usize)
                        .checked_mul(it.size())
                        .and_then(|len| w.get(p..p.checked_add(len)?))
                    else {
                        return Ok(false);
                    };
                    if self.is_face && pi == self.roles.face_list {
                        self.face_list(b, list, it, n, at + p as u64, item)?;
                    }
                    p += list.len();
                }
            }
        }
        *pos = p;
        Ok(true)
    }

    /// Finish item `item`: a vertex at `xyz`, or the face whose corners were pushed, and the
    /// item's colour.
    #[inline(always)]
    fn end_item(
        &self,
        xyz: [f64; 3],
        b: &mut Builder,
        vcol: &mut Option<ColorSink>,
        fcol: &mut Option<ColorSink>,
    ) -> Result<(), MeshError> {
        if self.is_vertex {
            b.push_vertex(DVec3::from_array(xyz))?;
            if let Some(sink) = vcol.as_mut() {
                sink.end_item();
            }
        }
        if self.is_face {
            b.end_face()?;
            if let Some(sink) = fcol.as_mut() {
                sink.end_item();
            }
        }
        Ok(())
    }

    /// Item `item` that the window does not hold whole (the end of a window or of the data):
    /// property by property, reporting where the data ends.
    #[cold]
    fn partial_item<S: Source>(
        &self,
        input: &mut Input<S>,
        item: usize,
        xyz: &mut [f64; 3],
        b: &mut Builder,
        mut sink: Option<&mut ColorSink>,
    ) -> Result<(), MeshError> {
        let el = self.el;
        for (pi, p) in el.props.iter().enumerate() {
            match p.kind {
                Kind::Scalar(s) => {
                    let at = input.offset();
                    let bytes = input
                        .take(s.size())?
                        .ok_or_else(|| truncated(at, format!("{} {item}", el.name)))?;
                    self.scalar(pi, s, bytes, at, item, xyz, sink.as_deref_mut())?;
                }
                Kind::List { count, item: it } => {
                    let at = input.offset();
                    let cb = input
                        .take(count.size())?
                        .ok_or_else(|| truncated(at, format!("{} {item}", el.name)))?;
                    let n = count.read_int(cb, self.big).unwrap_or(-1);
                    if n < 0 {
                        return Err(MeshError::parse(
                            MeshFormat::Ply,
                            at_byte(at),
                            format!("negative list length {n} in {} {item}", el.name),
                        ));
                    }
                    let list_at = input.offset();
                    let too_short =
                        || truncated(list_at, format!("the {n}-item list of {} {item}", el.name));
                    let remaining = input.remaining();
                    let Some(len) = (n as usize)
                        .checked_mul(it.size())
                        .filter(|&l| remaining.is_none_or(|r| l as u64 <= r))
                    else {
                        return Err(too_short());
                    };
                    if !(self.is_face && pi == self.roles.face_list) {
                        if input.skip(len as u64)? < len as u64 {
                            return Err(too_short());
                        }
                        continue;
                    }
                    // The list must be whole before its length or indices are reported on.
                    let window = input.window();
                    if window.len() >= len {
                        self.face_list(b, &window[..len], it, n, list_at, item)?;
                        input.advance(len);
                    } else {
                        read_list_across(input, b, it, n as usize, self.big, self.nv).map_err(
                            |e| match e {
                                ListError::Short => too_short(),
                                ListError::Small => face_len_error(at_byte(list_at), item, n),
                                ListError::Index(i) => {
                                    index_error(at_byte(list_at), item, i, self.nv)
                                }
                                ListError::Other(e) => e,
                            },
                        )?;
                    }
                }
            }
        }
        Ok(())
    }
}

/// Why a face's index list was refused.
enum ListError {
    /// The data ends inside it.
    Short,
    /// It has fewer than three items.
    Small,
    /// It has this bad index (`None`: not an integer).
    Index(Option<i64>),
    /// Reading or the budget failed.
    Other(MeshError),
}

/// Read a face's list of `n` indices of type `it` that the window does not hold whole (a
/// stream): the first bad index is reported only once the list is known to be whole, as
/// when the list is checked against the input's size first.
#[cold]
fn read_list_across<S: Source>(
    input: &mut Input<S>,
    b: &mut Builder,
    it: Scalar,
    n: usize,
    big: bool,
    nv: usize,
) -> Result<(), ListError> {
    let size = it.size();
    let mut bad = None;
    let mut left = n;
    while left > 0 {
        let window = input.window();
        let k = left.min(window.len() / size);
        if k == 0 {
            if !input.ensure(size).map_err(ListError::Other)? {
                return Err(ListError::Short);
            }
            continue;
        }
        if bad.is_none() && n >= 3 {
            for v in window[..k * size].chunks_exact(size) {
                match it.read_int(v, big) {
                    Some(i) if i >= 0 && (i as u64) < nv as u64 => {
                        b.push_index(i as u32).map_err(ListError::Other)?;
                    }
                    i => {
                        bad = Some(i);
                        break;
                    }
                }
            }
        }
        input.advance(k * size);
        left -= k;
    }
    if n < 3 {
        return Err(ListError::Small);
    }
    match bad {
        Some(i) => Err(ListError::Index(i)),
        None => Ok(()),
    }
}

/// The next token of element `el`'s item `item`, with its line.
#[inline(always)]
fn need<'a, S: Source>(
    input: &'a mut Input<S>,
    el: &Element,
    item: usize,
) -> Result<(usize, &'a [u8]), MeshError> {
    input.require_token(|line| {
        MeshError::parse(
            MeshFormat::Ply,
            Location::Line(line),
            format!(
                "data ends in {} {item} of {} (truncated file or wrong count)",
                el.name, el.count
            ),
        )
    })
}

fn read_ascii<S: Source>(
    h: &Header,
    roles: &Roles,
    input: &mut Input<S>,
) -> Result<(Mesh, Option<MeshColors>), MeshError> {
    let mut b = Builder::new();
    let mut vcol = ColorSink::new(roles.vertex_rgb);
    let mut fcol = ColorSink::new(roles.face_rgb);
    let nv = roles.vertex.map_or(0, |v| h.elements[v].count);
    let err = |line: usize, m: String| MeshError::parse(MeshFormat::Ply, Location::Line(line), m);
    for (ei, el) in h.elements.iter().enumerate() {
        let is_vertex = roles.vertex == Some(ei);
        let is_face = roles.face == Some(ei);
        if el.props.is_empty() {
            continue;
        }
        // Each item takes at least one token of at least two bytes (value and separator).
        let cap = input.capacity_hint(el.count, 2);
        if is_vertex {
            reserve_within(&mut b.positions, cap);
        }
        if is_face {
            reserve_within(&mut b.offsets, cap);
            reserve_within(
                &mut b.indices,
                input.capacity_hint(cap.saturating_mul(3), 2),
            );
        }
        for item in 0..el.count {
            let mut xyz = [0.0f64; 3];
            for (pi, p) in el.props.iter().enumerate() {
                match p.kind {
                    Kind::Scalar(s) => {
                        let (line, tok) = need(input, el, item)?;
                        if is_vertex && let Some(k) = roles.xyz.iter().position(|&x| x == pi) {
                            xyz[k] = s.parse_value(tok).ok_or_else(|| {
                                err(
                                    line,
                                    format!(
                                        "bad {} value '{}' for vertex {item}",
                                        p.name,
                                        show(tok)
                                    ),
                                )
                            })?;
                        }
                        let sink = if is_vertex {
                            vcol.as_mut()
                        } else if is_face {
                            fcol.as_mut()
                        } else {
                            None
                        };
                        if let Some(sink) = sink
                            && sink.wants(pi)
                            && !s.parse_value(tok).is_some_and(|v| sink.take(pi, s, v))
                        {
                            return Err(err(
                                line,
                                format!("bad colour value '{}' for {} {item}", show(tok), el.name),
                            ));
                        }
                    }
                    Kind::List { count, item: it } => {
                        let (line, tok) = need(input, el, item)?;
                        let n = count.parse_int(tok).filter(|&n| n >= 0).ok_or_else(|| {
                            err(
                                line,
                                format!("bad list length '{}' in {} {item}", show(tok), el.name),
                            )
                        })?;
                        let wanted = is_face && pi == roles.face_list;
                        if wanted && n < 3 {
                            return Err(face_len_error(Location::Line(line), item, n));
                        }
                        for _ in 0..n {
                            let (line, tok) = need(input, el, item)?;
                            if wanted {
                                let i = it.parse_int(tok);
                                match i {
                                    Some(i) if i >= 0 && (i as u64) < nv as u64 => {
                                        b.push_index(i as u32)?;
                                    }
                                    Some(_) => {
                                        return Err(index_error(Location::Line(line), item, i, nv));
                                    }
                                    None => {
                                        return Err(err(
                                            line,
                                            format!(
                                                "bad vertex index '{}' in face {item}",
                                                show(tok)
                                            ),
                                        ));
                                    }
                                }
                            }
                        }
                    }
                }
            }
            if is_vertex {
                b.push_vertex(DVec3::from_array(xyz))?;
                if let Some(sink) = vcol.as_mut() {
                    sink.end_item();
                }
            }
            if is_face {
                b.end_face()?;
                if let Some(sink) = fcol.as_mut() {
                    sink.end_item();
                }
            }
        }
    }
    Ok((b.finish(), pick_colors(vcol, fcol)))
}

/// The colours read: per vertex when the vertex element had them, else per face.
fn pick_colors(vertex: Option<ColorSink>, face: Option<ColorSink>) -> Option<MeshColors> {
    match (vertex, face) {
        (Some(v), _) => Some(MeshColors::PerVertex(v.colors)),
        (None, Some(f)) => Some(MeshColors::PerFace(f.colors)),
        (None, None) => None,
    }
}

/// Values of one extra PLY property, one per element (vertex or face).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlyValues<'a> {
    /// Written as `uchar` (colour channels `red`, `green`, `blue`, `alpha` by convention).
    U8(&'a [u8]),
    /// Written as `float`.
    F32(&'a [f32]),
    /// Written as `double`.
    F64(&'a [f64]),
}

impl PlyValues<'_> {
    fn len(&self) -> usize {
        match self {
            Self::U8(v) => v.len(),
            Self::F32(v) => v.len(),
            Self::F64(v) => v.len(),
        }
    }

    fn type_name(&self) -> &'static str {
        match self {
            Self::U8(_) => "uchar",
            Self::F32(_) => "float",
            Self::F64(_) => "double",
        }
    }
}

/// One named extra scalar property of the `vertex` or `face` element.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlyProperty<'a> {
    /// Property name: non-empty printable ASCII without whitespace, not `x`, `y`, `z` or
    /// `vertex_indices`, unique within its element.
    pub name: &'a str,
    /// One value per vertex (vertex properties) or per face (face properties).
    pub values: PlyValues<'a>,
}

/// Extra per-vertex and per-face properties for [`write_ply_with_properties`] (see the module
/// documentation). The default has none.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PlyProperties<'a> {
    /// Written after `x y z` of every vertex, in this order.
    pub vertex: Vec<PlyProperty<'a>>,
    /// Written after `vertex_indices` of every face, in this order.
    pub face: Vec<PlyProperty<'a>>,
}

fn check_properties(
    props: &[PlyProperty<'_>],
    count: usize,
    element: &str,
    reserved: &[&str],
) -> Result<(), MeshError> {
    for (i, p) in props.iter().enumerate() {
        let ok = !p.name.is_empty() && p.name.bytes().all(|b| b.is_ascii_graphic());
        if !ok {
            return Err(MeshError::InvalidProperty(format!(
                "{element} property name {:?} must be non-empty printable ASCII without spaces",
                p.name
            )));
        }
        if reserved.contains(&p.name) || props[..i].iter().any(|q| q.name == p.name) {
            return Err(MeshError::InvalidProperty(format!(
                "{element} property {:?} is used twice",
                p.name
            )));
        }
        if p.values.len() != count {
            return Err(MeshError::InvalidProperty(format!(
                "{element} property {:?} has {} values for {count} {element}s",
                p.name,
                p.values.len()
            )));
        }
    }
    Ok(())
}

/// Write the `i`-th value of each property (ASCII: preceded by a space).
fn write_props<W: Write>(
    w: &mut W,
    props: &[PlyProperty<'_>],
    i: usize,
    encoding: PlyEncoding,
) -> Result<(), MeshError> {
    let big = encoding == PlyEncoding::BinaryBigEndian;
    for p in props {
        match encoding {
            PlyEncoding::Ascii => {
                w.write_all(b" ")?;
                match p.values {
                    PlyValues::U8(v) => write!(w, "{}", v[i])?,
                    PlyValues::F32(v) => write_f32(w, v[i])?,
                    PlyValues::F64(v) => write_f64(w, v[i])?,
                }
            }
            _ => match p.values {
                PlyValues::U8(v) => w.write_all(&[v[i]])?,
                PlyValues::F32(v) => w.write_all(&if big {
                    v[i].to_be_bytes()
                } else {
                    v[i].to_le_bytes()
                })?,
                PlyValues::F64(v) => w.write_all(&if big {
                    v[i].to_be_bytes()
                } else {
                    v[i].to_le_bytes()
                })?,
            },
        }
    }
    Ok(())
}

/// Write `mesh` as PLY in `encoding`, with `float` instead of `double` coordinates when
/// `single_precision` (see the module documentation).
///
/// # Errors
/// [`MeshError::IndexOutOfRange`] / [`MeshError::FaceTooSmall`] for a mesh built with
/// [`Mesh::from_csr_unvalidated`] that has such faces (nothing is written then);
/// [`MeshError::Write`] when the writer fails.
pub fn write_ply<W: Write>(
    w: &mut W,
    mesh: &Mesh,
    encoding: PlyEncoding,
    single_precision: bool,
) -> Result<(), MeshError> {
    write_ply_with_properties(
        w,
        mesh,
        encoding,
        single_precision,
        &PlyProperties::default(),
    )
}

/// [`write_ply`] with extra per-vertex and per-face scalar properties (see the module
/// documentation).
///
/// # Errors
/// As [`write_ply`], plus [`MeshError::InvalidProperty`] (nothing is written then) when a
/// property has the wrong number of values or a bad, reserved or repeated name.
pub fn write_ply_with_properties<W: Write>(
    w: &mut W,
    mesh: &Mesh,
    encoding: PlyEncoding,
    single_precision: bool,
    extra: &PlyProperties<'_>,
) -> Result<(), MeshError> {
    mesh.check_faces()?;
    check_properties(
        &extra.vertex,
        mesh.vertex_count(),
        "vertex",
        &["x", "y", "z"],
    )?;
    check_properties(&extra.face, mesh.face_count(), "face", &["vertex_indices"])?;
    let max_len = mesh.max_face_len();
    let count_ty = if max_len <= 255 {
        Scalar::U8
    } else if max_len <= 65535 {
        Scalar::U16
    } else {
        Scalar::U32
    };
    let index_ty = if mesh.vertex_count() <= i32::MAX as usize {
        Scalar::I32
    } else {
        Scalar::U32
    };
    let name = |s: Scalar| match s {
        Scalar::U8 => "uchar",
        Scalar::U16 => "ushort",
        Scalar::U32 => "uint",
        _ => "int",
    };
    let coord = if single_precision { "float" } else { "double" };
    write!(
        w,
        "ply\nformat {} 1.0\ncomment volmorph mesh\nelement vertex {}\n\
         property {coord} x\nproperty {coord} y\nproperty {coord} z\n",
        encoding.keyword(),
        mesh.vertex_count(),
    )?;
    for p in &extra.vertex {
        writeln!(w, "property {} {}", p.values.type_name(), p.name)?;
    }
    write!(
        w,
        "element face {}\nproperty list {} {} vertex_indices\n",
        mesh.face_count(),
        name(count_ty),
        name(index_ty)
    )?;
    for p in &extra.face {
        writeln!(w, "property {} {}", p.values.type_name(), p.name)?;
    }
    w.write_all(b"end_header\n")?;
    match encoding {
        PlyEncoding::Ascii => {
            for (i, p) in mesh.positions().iter().enumerate() {
                for (k, x) in p.to_array().into_iter().enumerate() {
                    if k > 0 {
                        w.write_all(b" ")?;
                    }
                    if single_precision {
                        write_f32(w, x as f32)?;
                    } else {
                        write_f64(w, x)?;
                    }
                }
                write_props(w, &extra.vertex, i, encoding)?;
                w.write_all(b"\n")?;
            }
            for (f, face) in mesh.faces().enumerate() {
                write!(w, "{}", face.len())?;
                if extra.face.is_empty() {
                    write_face_indices(w, face, 0)?;
                } else {
                    for &i in face {
                        write!(w, " {i}")?;
                    }
                    write_props(w, &extra.face, f, encoding)?;
                    w.write_all(b"\n")?;
                }
            }
        }
        PlyEncoding::BinaryLittleEndian | PlyEncoding::BinaryBigEndian => {
            let big = encoding == PlyEncoding::BinaryBigEndian;
            macro_rules! put {
                ($v:expr) => {
                    if big {
                        w.write_all(&$v.to_be_bytes())?
                    } else {
                        w.write_all(&$v.to_le_bytes())?
                    }
                };
            }
            for (i, p) in mesh.positions().iter().enumerate() {
                for x in p.to_array() {
                    if single_precision {
                        put!(x as f32);
                    } else {
                        put!(x);
                    }
                }
                write_props(w, &extra.vertex, i, encoding)?;
            }
            for (f, face) in mesh.faces().enumerate() {
                let n = face.len();
                match count_ty {
                    Scalar::U8 => put!(n as u8),
                    Scalar::U16 => put!(n as u16),
                    _ => put!(n as u32),
                }
                for &i in face {
                    // Both index types hold `i` with the same bit pattern.
                    put!(i);
                }
                write_props(w, &extra.face, f, encoding)?;
            }
        }
    }
    Ok(())
}
