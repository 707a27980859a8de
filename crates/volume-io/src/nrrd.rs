//! NRRD (teem "nearly raw raster data"): `.nrrd` with the voxels after the header, or
//! `.nhdr` with the voxels in a separate data file.
//!
//! The header starts with a magic line `NRRD0001` … `NRRD0005`, followed by `field: value`
//! lines, `key:=value` pairs (kept in the [`Header`] under their key, in file order, like
//! the fields) and `#` comments; it ends at the first empty line (attached data follow it)
//! or at the end of a detached header.
//!
//! In the [`Header`], the magic line comes first as `("magic", "NRRD0004")`; field names
//! are lower-cased (`"space directions"`), `key:=value` keys are kept as written.
//!
//! # Fields used
//! * `type` — every C spelling NRRD allows for 8/16/32-bit integers, `float` and `double`
//!   (`signed char`, `uchar`, `unsigned short int`, `int16_t`, …). 64-bit integers and
//!   `block` are refused as unsupported.
//! * `dimension`, `sizes` — axes, fastest first. Up to three *spatial* axes are read as
//!   i, j, k (fewer give `nz = 1`, `ny = 1`). A non-spatial axis (a space direction `none`,
//!   or a kind other than `domain`/`space`/`???`) is accepted only with size 1 and dropped,
//!   so a 4-D scalar volume with a trailing `size 1` axis reads as 3-D; larger non-spatial
//!   axes (vectors, time series) are refused as unsupported. With fewer than three spatial
//!   axes the missing direction columns are completed orthonormally (identity padding when
//!   the given ones lie in the xy plane, as ITK embeds 2-D images).
//! * `encoding` — `raw`, `gzip`/`gz`, `ascii`/`text`/`txt`; `bzip2`, `hex` and `zrl` are
//!   refused as unsupported. `endian` is required for multi-byte binary data.
//! * `space` / `space dimension`, `space directions`, `space origin` — the geometry: the
//!   direction vector of axis `a` is column `a` of `direction · diag(spacing)`, so spacing is
//!   its length and the direction column its normalised value; `space origin` is the
//!   position of voxel (0, 0, 0). Coordinates are converted to volmorph's LPS space exactly
//!   as ITK's `NrrdImageIO` does: `right-anterior-superior` (RAS) negates x and y,
//!   `left-anterior-superior` (LAS) negates y, `left-posterior-superior` (LPS) is unchanged,
//!   and spaces without an anatomical meaning (`scanner-xyz`, `3D-right-handed`,
//!   `3D-left-handed`, or a bare `space dimension`) are taken as they are. Time-varying
//!   spaces (`…-time`) are refused as unsupported.
//! * Without space information: `spacings` (NaN → 1; a negative spacing flips the axis) and
//!   `axis mins` (plus half a spacing for `centers: cell`) give an axis-aligned geometry.
//! * `byte skip` (−1 with raw encoding: the data are the last bytes of the file), `line
//!   skip` (lines skipped before the byte skip; with gzip the line skip applies to the
//!   compressed file and the byte skip to the decompressed data, as teem does), and
//!   `data file` — a single file name, relative to the header's directory; the `LIST` and
//!   `format min max step` multi-file forms are refused as unsupported.
//! * Raw data must fill their file exactly: the skipped lines and bytes, then the voxels
//!   (after the header's blank line for attached data), or any length of at least the
//!   voxels' with `byte skip: -1`. A shorter or longer file is refused, naming the data,
//!   the fields and both sizes.
//!
//! # Writing
//! `NRRD0004`, `space: left-posterior-superior`, `space directions` = columns of
//! `direction · diag(spacing)`, `space origin`, `kinds: domain domain domain`,
//! `endian: little`, `encoding: raw` or `gzip` ([`WriteOptions::compress`], at
//! [`WriteOptions::level`]). `.nhdr` gets its data in a file named after the header and
//! the write, `<name>.nhdr.<8 hex digits>.raw` (`.raw.gz` when compressed), written before
//! the header and committed by the header's rename (see [`volmorph_io::atomic`]): a failed
//! or killed write leaves the old header with its own old data, and `X.nhdr` never shares a
//! data file with `X.mhd`. A `data file` outside the header's folder is refused on reading
//! unless [`ReadOptions::allow_external_data`] is set. Numbers are printed in shortest round-trip form;
//! since NRRD stores only the product `direction · diag(spacing)`, an oblique direction
//! and its spacing read back to within a few ulps (axis-aligned geometry is exact).

use std::io::Write;
use std::path::Path;

use glam::{DMat3, DVec3};

use crate::text_header::{self, DataSpec, Encoding, Input, Lines, Start, fmt_f64, os_err};
use crate::{Header, ReadOptions, WriteOptions};
use volmorph_volume::{AnyVolume, Geometry, VolumeError, VoxelType};

const FMT: &str = "NRRD";

fn err(msg: impl Into<String>) -> VolumeError {
    VolumeError::format(FMT, msg)
}

fn unsupported(msg: impl std::fmt::Display) -> VolumeError {
    VolumeError::Unsupported(format!("NRRD {msg}"))
}

/// A parsed NRRD header.
#[derive(Debug)]
struct Nrrd {
    geometry: Geometry,
    voxel_type: VoxelType,
    big_endian: bool,
    encoding: Encoding,
    byte_skip: i64,
    line_skip: u64,
    data_file: Option<String>,
    /// Byte offset just after the blank line that ends an attached header.
    data_offset: Option<usize>,
    header: Header,
}

fn parse_type(v: &str) -> Result<VoxelType, VolumeError> {
    let norm = v.split_ascii_whitespace().collect::<Vec<_>>().join(" ");
    Ok(match norm.to_ascii_lowercase().as_str() {
        "signed char" | "int8" | "int8_t" => VoxelType::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => VoxelType::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            VoxelType::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => {
            VoxelType::U16
        }
        "int" | "signed int" | "int32" | "int32_t" => VoxelType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => VoxelType::U32,
        "float" => VoxelType::F32,
        "double" => VoxelType::F64,
        t @ ("longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t"
        | "ulonglong"
        | "unsigned long long"
        | "unsigned long long int"
        | "uint64"
        | "uint64_t"
        | "block") => {
            return Err(unsupported(format!(
                "type `{t}` (supported: 8/16/32-bit integers, float, double)"
            )));
        }
        _ => return Err(err(format!("unknown type `{v}`"))),
    })
}

fn type_name(t: VoxelType) -> &'static str {
    match t {
        VoxelType::U8 => "unsigned char",
        VoxelType::I8 => "signed char",
        VoxelType::U16 => "unsigned short",
        VoxelType::I16 => "short",
        VoxelType::U32 => "unsigned int",
        VoxelType::I32 => "int",
        VoxelType::F32 => "float",
        VoxelType::F64 => "double",
    }
}

fn parse_encoding(v: &str) -> Result<Encoding, VolumeError> {
    Ok(match v.trim().to_ascii_lowercase().as_str() {
        "raw" => Encoding::Raw,
        "gzip" | "gz" => Encoding::Gzip,
        "ascii" | "text" | "txt" => Encoding::Ascii,
        e @ ("bzip2" | "bz2" | "hex" | "zrl") => {
            return Err(unsupported(format!(
                "encoding `{e}` (supported: raw, gzip, ascii)"
            )));
        }
        e => return Err(err(format!("unknown encoding `{e}`"))),
    })
}

/// Per-space sign factors that take the space's coordinates to LPS, or `None` for spaces
/// taken as they are. Also returns the space dimension.
fn parse_space(v: &str) -> Result<(usize, DVec3), VolumeError> {
    let lps = DVec3::ONE;
    Ok(match v.trim().to_ascii_lowercase().as_str() {
        "right-anterior-superior" | "ras" => (3, DVec3::new(-1.0, -1.0, 1.0)),
        "left-anterior-superior" | "las" => (3, DVec3::new(1.0, -1.0, 1.0)),
        "left-posterior-superior" | "lps" => (3, lps),
        "scanner-xyz" | "3d-right-handed" | "3d-left-handed" => (3, lps),
        s @ ("right-anterior-superior-time"
        | "rast"
        | "left-anterior-superior-time"
        | "last"
        | "left-posterior-superior-time"
        | "lpst"
        | "scanner-xyz-time"
        | "3d-right-handed-time"
        | "3d-left-handed-time") => {
            return Err(unsupported(format!(
                "space `{s}` (time-varying spaces are not supported)"
            )));
        }
        _ => return Err(err(format!("unknown space `{v}`"))),
    })
}

/// Parse one vector `(x,y,z)` (whitespace allowed inside) with `n` finite components.
fn parse_vector(what: &str, s: &str, n: usize) -> Result<Vec<f64>, VolumeError> {
    let t = s.trim();
    let inner = t
        .strip_prefix('(')
        .and_then(|r| r.strip_suffix(')'))
        .ok_or_else(|| err(format!("{what}: `{t}` is not a vector `(x,y,z)`")))?;
    let parts: Vec<&str> = inner.split(',').collect();
    if parts.len() != n {
        return Err(err(format!(
            "{what}: vector `{t}` has {} components, space dimension is {n}",
            parts.len()
        )));
    }
    parts
        .iter()
        .map(|p| text_header::parse_f64(FMT, what, p))
        .collect()
}

/// Split `space directions` into per-axis tokens: `(…)` groups or `none`.
fn split_vectors(what: &str, s: &str) -> Result<Vec<String>, VolumeError> {
    let mut out = Vec::new();
    let mut rest = s.trim_start();
    while !rest.is_empty() {
        if rest.starts_with('(') {
            let end = rest
                .find(')')
                .ok_or_else(|| err(format!("{what}: unclosed `(` in `{s}`")))?;
            out.push(rest[..=end].to_string());
            rest = rest[end + 1..].trim_start();
        } else {
            let end = rest
                .find(|c: char| c.is_ascii_whitespace())
                .unwrap_or(rest.len());
            out.push(rest[..end].to_string());
            rest = rest[end..].trim_start();
        }
    }
    Ok(out)
}

/// Parse per-axis numbers where `nan` marks "unknown".
fn parse_axis_numbers(what: &str, s: &str, n: usize) -> Result<Vec<Option<f64>>, VolumeError> {
    let toks: Vec<&str> = s.split_ascii_whitespace().collect();
    if toks.len() != n {
        return Err(err(format!(
            "{what}: expected {n} values (one per axis), found {}",
            toks.len()
        )));
    }
    toks.iter()
        .map(|t| {
            if t.eq_ignore_ascii_case("nan") {
                Ok(None)
            } else {
                text_header::parse_f64(FMT, what, t).map(Some)
            }
        })
        .collect()
}

/// Kinds that describe a position in space (or an unknown kind).
fn is_spatial_kind(k: &str) -> bool {
    matches!(
        k.to_ascii_lowercase().as_str(),
        "domain" | "space" | "???" | "none"
    )
}

fn parse_header(bytes: &[u8], complete: bool) -> Result<Nrrd, VolumeError> {
    let mut lines = Lines::new(bytes);
    let magic = lines
        .next_line(complete)
        .ok_or_else(|| err("empty file: missing the NRRD000x magic line"))?;
    let magic = magic.trim_end().to_string();
    match magic
        .strip_prefix("NRRD000")
        .and_then(|d| d.parse::<u8>().ok())
    {
        Some(1..=5) if magic.len() == 8 => {}
        Some(_) if magic.len() == 8 => {
            return Err(unsupported(format!(
                "format version `{magic}` (NRRD0001 to NRRD0005)"
            )));
        }
        _ => {
            return Err(err(format!(
                "not a NRRD file: first line is `{}`",
                magic.chars().take(40).collect::<String>()
            )));
        }
    }
    let mut fields: Vec<(String, String)> = vec![("magic".into(), magic)];
    // Indices into `fields` of real NRRD fields (not `key:=value` pairs).
    let mut field_idx: Vec<usize> = Vec::new();
    let mut data_offset = None;
    let mut line_no = 1usize;
    loop {
        let Some(line) = lines.next_line(complete) else {
            if !complete || bytes.len() >= text_header::MAX_HEADER_BYTES {
                return Err(err(format!(
                    "header does not end within the first {} bytes",
                    text_header::MAX_HEADER_BYTES.min(bytes.len())
                )));
            }
            break;
        };
        line_no += 1;
        if line.is_empty() {
            data_offset = Some(lines.pos());
            break;
        }
        if line.starts_with('#') {
            continue;
        }
        let kv = line.find(":=");
        let field = line.find(": ");
        match (kv, field) {
            (Some(i), f) if f.is_none_or(|f| i < f) => {
                fields.push((line[..i].to_string(), line[i + 2..].to_string()));
            }
            (_, Some(i)) => {
                field_idx.push(fields.len());
                fields.push((
                    line[..i].trim().to_ascii_lowercase(),
                    line[i + 2..].trim().to_string(),
                ));
            }
            _ => {
                return Err(err(format!(
                    "header line {line_no} `{}` is neither `field: value` nor `key:=value`",
                    line.chars().take(80).collect::<String>()
                )));
            }
        }
    }
    let get = |names: &[&str]| {
        field_idx
            .iter()
            .map(|&i| &fields[i])
            .find(|(k, _)| names.contains(&k.as_str()))
            .map(|(_, v)| v.as_str())
    };

    let voxel_type = parse_type(get(&["type"]).ok_or_else(|| err("missing the type field"))?)?;
    let dim_s = get(&["dimension"]).ok_or_else(|| err("missing the dimension field"))?;
    let dim = text_header::parse_size(FMT, "dimension", dim_s)?;
    if dim > 16 {
        return Err(err(format!("dimension {dim} exceeds NRRD's maximum of 16")));
    }
    let sizes_s = get(&["sizes"]).ok_or_else(|| err("missing the sizes field"))?;
    let sizes = text_header::parse_sizes(FMT, "sizes", sizes_s, dim)?;
    let encoding =
        parse_encoding(get(&["encoding"]).ok_or_else(|| err("missing the encoding field"))?)?;
    let big_endian = match get(&["endian"]) {
        Some(e) => match e.trim().to_ascii_lowercase().as_str() {
            "little" => false,
            "big" => true,
            _ => return Err(err(format!("endian `{e}` is neither little nor big"))),
        },
        None if voxel_type.size() > 1 && encoding != Encoding::Ascii => {
            return Err(err(
                "missing the endian field (required for multi-byte binary data)",
            ));
        }
        None => false,
    };

    // Space.
    let (space_dim, factors) = match (get(&["space"]), get(&["space dimension"])) {
        (Some(_), Some(_)) => {
            return Err(err("both space and space dimension are given"));
        }
        (Some(s), None) => {
            let (d, f) = parse_space(s)?;
            (Some(d), f)
        }
        (None, Some(d)) => {
            let d = text_header::parse_size(FMT, "space dimension", d)?;
            if d > 3 {
                return Err(unsupported(format!("space dimension {d} (at most 3)")));
            }
            (Some(d), DVec3::ONE)
        }
        (None, None) => (None, DVec3::ONE),
    };
    let directions: Option<Vec<Option<Vec<f64>>>> = match get(&["space directions"]) {
        None => None,
        Some(s) => {
            let sd = space_dim.ok_or_else(|| {
                err("space directions given without a space or space dimension field")
            })?;
            let toks = split_vectors("space directions", s)?;
            if toks.len() != dim {
                return Err(err(format!(
                    "space directions: expected {dim} vectors (one per axis), found {}",
                    toks.len()
                )));
            }
            Some(
                toks.iter()
                    .map(|t| {
                        if t.eq_ignore_ascii_case("none") {
                            Ok(None)
                        } else {
                            parse_vector("space directions", t, sd).map(Some)
                        }
                    })
                    .collect::<Result<_, _>>()?,
            )
        }
    };
    let origin: Option<Vec<f64>> = match get(&["space origin"]) {
        None => None,
        Some(s) => {
            let sd = space_dim.ok_or_else(|| {
                err("space origin given without a space or space dimension field")
            })?;
            Some(parse_vector("space origin", s, sd)?)
        }
    };
    let kinds: Option<Vec<String>> = match get(&["kinds"]) {
        None => None,
        Some(s) => {
            let k: Vec<String> = s.split_ascii_whitespace().map(str::to_string).collect();
            if k.len() != dim {
                return Err(err(format!(
                    "kinds: expected {dim} kinds (one per axis), found {}",
                    k.len()
                )));
            }
            Some(k)
        }
    };
    let spacings = get(&["spacings"])
        .map(|s| parse_axis_numbers("spacings", s, dim))
        .transpose()?;
    let mins = get(&["axis mins", "axismins"])
        .map(|s| parse_axis_numbers("axis mins", s, dim))
        .transpose()?;
    let cell_centered: Vec<bool> = match get(&["centers", "centerings"]) {
        None => vec![false; dim],
        Some(s) => s
            .split_ascii_whitespace()
            .map(|c| c.eq_ignore_ascii_case("cell"))
            .collect(),
    };

    // Which axes are spatial.
    let mut spatial: Vec<usize> = Vec::new();
    for a in 0..dim {
        let is_spatial = match &directions {
            Some(d) => d[a].is_some(),
            None => kinds.as_ref().is_none_or(|k| is_spatial_kind(&k[a])),
        };
        if is_spatial {
            spatial.push(a);
        } else if sizes[a] != 1 {
            let kind = kinds.as_ref().map_or("none", |k| k[a].as_str());
            return Err(unsupported(format!(
                "axis {a} (kind {kind}, size {}) is not spatial: multi-component and \
                 time-series images are not supported",
                sizes[a]
            )));
        }
    }
    // A 4-D file without kinds or directions: drop trailing axes of size 1.
    while spatial.len() > 3 && spatial.last().is_some_and(|&a| sizes[a] == 1) {
        spatial.pop();
    }
    if spatial.len() > 3 {
        return Err(unsupported(format!(
            "{}-D image with sizes {sizes:?} (at most 3 spatial axes)",
            spatial.len()
        )));
    }
    if spatial.is_empty() {
        return Err(err("no spatial axis"));
    }

    let mut g = Geometry::new([1, 1, 1]);
    let mut cols: Vec<DVec3> = Vec::with_capacity(3);
    for (i, &a) in spatial.iter().enumerate() {
        g.dims[i] = sizes[a];
        let dir = directions.as_ref().and_then(|d| d[a].as_ref());
        if let Some(v) = dir {
            let mut p = DVec3::ZERO;
            for (c, &x) in v.iter().enumerate().take(3) {
                p[c] = x;
            }
            let p = p * factors;
            let len = p.length();
            if !(len > 0.0 && len.is_finite()) {
                return Err(err(format!(
                    "space directions: the vector of axis {a} has zero or non-finite length"
                )));
            }
            g.spacing[i] = len;
            cols.push(p / len);
        } else {
            let mut e = DVec3::ZERO;
            e[i] = 1.0;
            let s = spacings.as_ref().and_then(|s| s[a]).unwrap_or(1.0);
            if s == 0.0 {
                return Err(err(format!("spacings: axis {a} has spacing 0")));
            }
            g.spacing[i] = s.abs();
            cols.push(if s < 0.0 { -e } else { e });
            if origin.is_none()
                && directions.is_none()
                && let Some(Some(m)) = mins.as_ref().map(|m| m[a])
            {
                let half = if cell_centered.get(a).copied().unwrap_or(false) {
                    0.5 * s
                } else {
                    0.0
                };
                g.origin[i] = m + half;
            }
        }
    }
    if let Some(o) = &origin {
        let mut p = DVec3::ZERO;
        for (c, &x) in o.iter().enumerate().take(3) {
            p[c] = x;
        }
        g.origin = p * factors;
    }
    g.direction = text_header::complete_direction(&cols);
    g.validate().map_err(|e| err(e.to_string()))?;

    let byte_skip = match get(&["byte skip", "byteskip"]) {
        Some(s) => {
            let b = text_header::parse_i64(FMT, "byte skip", s)?;
            if b < -1 {
                return Err(err(format!("byte skip {b} is negative")));
            }
            if b == -1 && encoding != Encoding::Raw {
                return Err(err("byte skip -1 is only allowed with raw encoding"));
            }
            b
        }
        None => 0,
    };
    let line_skip = match get(&["line skip", "lineskip"]) {
        Some(s) => {
            let l = text_header::parse_i64(FMT, "line skip", s)?;
            u64::try_from(l).map_err(|_| err(format!("line skip {l} is negative")))?
        }
        None => 0,
    };
    let data_file = match get(&["data file", "datafile"]) {
        None => None,
        Some(f) => {
            let toks: Vec<&str> = f.split_ascii_whitespace().collect();
            if toks.first().is_some_and(|t| *t == "LIST") {
                return Err(unsupported(
                    "data file LIST (multiple data files); only a single data file is supported",
                ));
            }
            if toks.len() >= 4 && toks[0].contains('%') {
                return Err(unsupported(format!(
                    "data file pattern `{f}` (multiple data files); only a single data file \
                     is supported"
                )));
            }
            if f.is_empty() {
                return Err(err("data file is empty"));
            }
            Some(f.to_string())
        }
    };
    if data_file.is_none() && data_offset.is_none() {
        return Err(err(
            "the header has no data file and no blank line before attached data",
        ));
    }
    Ok(Nrrd {
        geometry: g,
        voxel_type,
        big_endian,
        encoding,
        byte_skip,
        line_skip,
        data_file,
        data_offset,
        header: Header { fields },
    })
}

/// Decode the voxels of `n` from `input`, starting at `base` (0 for a data file). Raw data
/// fill their file exactly (the skipped lines and bytes, then the voxels) unless
/// `byte skip: -1` puts them at the end of a longer file.
fn decode(n: &Nrrd, input: Input<'_>, base: u64) -> Result<AnyVolume, VolumeError> {
    let (start, line_skip, skip) = if n.byte_skip == -1 {
        (Start::FromEnd, 0, 0)
    } else {
        (Start::Offset(base), n.line_skip, n.byte_skip as u64)
    };
    let source = match &n.data_file {
        Some(name) => format!("data file `{name}`"),
        None => "the data after the header".into(),
    };
    let spec = DataSpec {
        fmt: FMT,
        voxel_type: n.voxel_type,
        big_endian: n.big_endian,
        encoding: n.encoding,
        start,
        line_skip,
        decoded_skip: skip,
        encoded_len: None,
        exact: n.encoding == Encoding::Raw,
        words: Some(text_header::SizeWords {
            source,
            fields: "sizes, type, line skip and byte skip",
            at_end: Some("byte skip: -1"),
        }),
    };
    text_header::decode(input, &spec, n.geometry)
}

/// Read a single-file NRRD (`.nrrd` with attached data) from memory.
///
/// # Errors
/// [`VolumeError::Format`] for a malformed header or truncated/corrupt voxel data;
/// [`VolumeError::Unsupported`] for valid features volmorph does not handle (see the module
/// docs) and for a header that names a detached data file (use [`crate::read`] with
/// the header's path).
pub fn read_bytes(bytes: &[u8]) -> Result<(AnyVolume, Header), VolumeError> {
    let nrrd = parse_header(bytes, bytes.len() <= text_header::MAX_HEADER_BYTES)?;
    text_header::require_attached(FMT, nrrd.data_file.as_deref())?;
    let off = nrrd.data_offset.unwrap_or(bytes.len()) as u64;
    let v = decode(&nrrd, Input::Bytes(bytes), off)?;
    Ok((v, nrrd.header))
}

pub(crate) fn read(path: &Path, options: &ReadOptions) -> Result<(AnyVolume, Header), VolumeError> {
    let (prefix, len) = text_header::read_prefix(path)?;
    let nrrd = parse_header(&prefix, prefix.len() as u64 == len)?;
    let v = match &nrrd.data_file {
        None => {
            let off = nrrd.data_offset.unwrap_or(prefix.len()) as u64;
            decode(&nrrd, Input::File(path), off)?
        }
        Some(name) => {
            let data = text_header::existing_data_file(FMT, "data file", path, name, options)?;
            decode(&nrrd, Input::File(&data), 0).map_err(|e| e.at(&data))?
        }
    };
    Ok((v, nrrd.header))
}

fn vector(v: DVec3) -> String {
    format!("({},{},{})", fmt_f64(v.x), fmt_f64(v.y), fmt_f64(v.z))
}

fn header_text(volume: &AnyVolume, compress: bool, data_file: Option<&str>) -> String {
    let g = volume.geometry();
    let m: DMat3 = g.index_to_physical_matrix();
    let mut s = String::with_capacity(512);
    s.push_str("NRRD0004\n");
    s.push_str("# Complete NRRD file format specification at:\n");
    s.push_str("# http://teem.sourceforge.net/nrrd/format.html\n");
    s.push_str(&format!("type: {}\n", type_name(volume.voxel_type())));
    s.push_str("dimension: 3\n");
    s.push_str("space: left-posterior-superior\n");
    s.push_str(&format!(
        "sizes: {} {} {}\n",
        g.dims[0], g.dims[1], g.dims[2]
    ));
    s.push_str(&format!(
        "space directions: {} {} {}\n",
        vector(m.x_axis),
        vector(m.y_axis),
        vector(m.z_axis)
    ));
    s.push_str("kinds: domain domain domain\n");
    s.push_str("endian: little\n");
    s.push_str(if compress {
        "encoding: gzip\n"
    } else {
        "encoding: raw\n"
    });
    s.push_str(&format!("space origin: {}\n", vector(g.origin)));
    match data_file {
        Some(f) => s.push_str(&format!("data file: {f}\n")),
        None => s.push('\n'),
    }
    s
}

fn write_data(
    w: &mut dyn Write,
    volume: &AnyVolume,
    options: &WriteOptions,
) -> std::io::Result<()> {
    if options.compress {
        let mut enc = flate2::write::GzEncoder::new(w, text_header::level(options.level));
        text_header::write_voxels(&mut enc, volume, false)?;
        enc.finish()?.flush()
    } else {
        text_header::write_voxels(w, volume, false)
    }
}

pub(crate) fn write(
    path: &Path,
    volume: &AnyVolume,
    options: &WriteOptions,
) -> Result<(), VolumeError> {
    volume.geometry().validate()?;
    let os = os_err(path);
    let data_ext = if options.compress { "raw.gz" } else { "raw" };
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("nhdr"))
    {
        volmorph_io::write_detached::<VolumeError, _, _, _>(
            path,
            data_ext,
            &["raw", "raw.gz"],
            |w| write_data(w, volume, options).map_err(&os),
            |w, data_name, ()| {
                w.write_all(header_text(volume, options.compress, Some(data_name)).as_bytes())
                    .map_err(&os)
            },
        )
        .map(drop)
    } else {
        let text = header_text(volume, options.compress, None);
        volmorph_io::write_atomic::<VolumeError, _>(path, |w| {
            w.write_all(text.as_bytes()).map_err(&os)?;
            write_data(w, volume, options).map_err(&os)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_spellings() {
        for (s, t) in [
            ("signed char", VoxelType::I8),
            ("uint8_t", VoxelType::U8),
            ("unsigned  short   int", VoxelType::U16),
            ("short int", VoxelType::I16),
            ("signed int", VoxelType::I32),
            ("uint", VoxelType::U32),
            ("float", VoxelType::F32),
            ("double", VoxelType::F64),
        ] {
            assert_eq!(parse_type(s).unwrap(), t, "{s}");
        }
        for t in VoxelType::ALL {
            assert_eq!(parse_type(type_name(t)).unwrap(), t);
        }
        assert!(matches!(
            parse_type("int64"),
            Err(VolumeError::Unsupported(_))
        ));
        assert!(matches!(
            parse_type("quad"),
            Err(VolumeError::Format { .. })
        ));
    }

    #[test]
    fn vectors() {
        assert_eq!(
            split_vectors("x", "(1, 0,0) none  (0,1,0)").unwrap(),
            vec!["(1, 0,0)", "none", "(0,1,0)"]
        );
        assert_eq!(
            parse_vector("x", "(1, -2.5,3e1)", 3).unwrap(),
            vec![1.0, -2.5, 30.0]
        );
        assert!(parse_vector("x", "(1,2)", 3).is_err());
        assert!(parse_vector("x", "(1,nan,2)", 3).is_err());
        assert!(split_vectors("x", "(1,2,3").is_err());
    }
}
