//! MetaImage (ITK MetaIO): `.mha` with the voxels inline after the header, or `.mhd` with
//! the voxels in a separate data file.
//!
//! The header is text, one `Key = Value` per line; `ElementDataFile` must be the last key
//! and, when it is `LOCAL`, the voxels start on the byte after its line.
//!
//! The [`Header`] lists every `Key = Value` pair in file order, keys as written.
//!
//! # Geometry
//! * `DimSize` — voxel counts, x fastest. `NDims` 2 reads as a single slice (`nz = 1`);
//!   `NDims` 4 is accepted only with a fourth size of 1.
//! * `ElementSpacing` — spacing (falls back to `ElementSize`, then 1).
//! * `Offset` (synonyms `Position`, `Origin`) — physical position of voxel (0, 0, 0).
//! * `TransformMatrix` (synonyms `Rotation`, `Orientation`) — the direction matrix. Its
//!   `NDims²` values are read exactly as ITK's `MetaImageIO` does: the values at
//!   `ii·NDims .. ii·NDims + NDims` form the direction of index axis `ii`, i.e. **column**
//!   `ii` of volmorph's direction matrix. The file therefore lists the direction matrix in
//!   column-major order: `TransformMatrix = d00 d10 d20 d01 d11 d21 d02 d12 d22` where
//!   `dRC` is row `R`, column `C`. A rotation by θ about z (x axis towards (cos θ, sin θ, 0))
//!   is written `cos θ  sin θ  0  -sin θ  cos θ  0  0 0 1`.
//! * Physical space is ITK's LPS space, as in volmorph; `AnatomicalOrientation` and
//!   `CenterOfRotation` are informational (kept in the [`Header`], not used), as in ITK.
//!
//! # Voxels
//! `ElementType` `MET_UCHAR MET_CHAR MET_USHORT MET_SHORT MET_UINT MET_INT MET_FLOAT
//! MET_DOUBLE`; `ElementNumberOfChannels` must be 1. Byte order from
//! `BinaryDataByteOrderMSB` / `ElementByteOrderMSB` (little-endian by default).
//! `CompressedData = True` means a zlib stream (gzip also accepted), optionally bounded by
//! `CompressedDataSize`. `BinaryData = False` means whitespace-separated decimal text.
//! `HeaderSize` bytes (−1: "the data are the last bytes") are skipped at the start of a
//! detached data file. Uncompressed binary data must fill their file exactly: a detached
//! data file holds `HeaderSize` bytes and the voxels (any length of at least the voxels'
//! with `HeaderSize = -1`), a `.mha` the header and the voxels; a shorter or longer file is
//! refused, naming the data file, the fields and both sizes. `ElementDataFile = LIST` and file-name patterns are refused as
//! unsupported.
//!
//! # Writing
//! Always `NDims = 3`, little-endian, with every number printed in shortest round-trip form
//! so spacing, origin and direction read back bit-exactly. `.mha` holds the voxels inline;
//! `.mhd` gets a data file beside it named after the header and the write,
//! `<name>.mhd.<8 hex digits>.raw` (`.zraw` when compressed), written before the header and
//! committed by the header's rename (see [`volmorph_io::atomic`]): a failed or killed write
//! leaves the old header with its own old data, and `X.mhd` never shares a data file with
//! `X.nhdr`.
//!
//! # Data file location
//! A detached data file must lie in the header's folder (after resolving symbolic links);
//! an absolute path, `../` or a link leading out is refused with
//! [`VolumeError::ExternalData`] unless [`ReadOptions::allow_external_data`] is set. A data
//! file that is not a regular file (a FIFO, a device) is refused. [`WriteOptions::compress`] selects
//! `CompressedData = True` at [`WriteOptions::level`].

use std::io::Write;
use std::path::Path;

use glam::{DMat3, DVec3};

use crate::text_header::{
    self, CountingWriter, DataSpec, Encoding, Input, Lines, Start, fmt_f64, os_err,
};
use crate::{Header, ReadOptions, WriteOptions};
use volmorph_volume::{AnyVolume, Geometry, VolumeError, VoxelType};

const FMT: &str = "MetaImage";

/// Extensions of the data files written beside a `.mhd` header.
const DATA_EXTS: [&str; 2] = ["raw", "zraw"];

/// `true` for a `.mhd` name (ASCII case ignored): the voxels go to a detached data file.
fn is_detached_name(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mhd"))
}

fn err(msg: impl Into<String>) -> VolumeError {
    VolumeError::format(FMT, msg)
}

/// A parsed MetaImage header.
#[derive(Debug)]
struct Meta {
    geometry: Geometry,
    voxel_type: VoxelType,
    /// `ElementNumberOfChannels` (values per voxel, interleaved).
    channels: usize,
    big_endian: bool,
    encoding: Encoding,
    compressed_size: Option<u64>,
    header_size: i64,
    /// `None` for `LOCAL`, else the data file name as written.
    data_file: Option<String>,
    /// Byte offset just after the `ElementDataFile` line.
    data_offset: usize,
    header: Header,
}

fn parse_bool(key: &str, v: &str) -> Result<bool, VolumeError> {
    match v.trim().to_ascii_lowercase().as_str() {
        "true" | "1" | "t" | "yes" => Ok(true),
        "false" | "0" | "f" | "no" => Ok(false),
        _ => Err(err(format!("{key} = `{v}` is not True or False"))),
    }
}

fn parse_element_type(v: &str) -> Result<VoxelType, VolumeError> {
    Ok(match v.trim().to_ascii_uppercase().as_str() {
        "MET_UCHAR" => VoxelType::U8,
        "MET_CHAR" => VoxelType::I8,
        "MET_USHORT" => VoxelType::U16,
        "MET_SHORT" => VoxelType::I16,
        "MET_UINT" => VoxelType::U32,
        "MET_INT" => VoxelType::I32,
        "MET_FLOAT" => VoxelType::F32,
        "MET_DOUBLE" => VoxelType::F64,
        t if matches!(
            t,
            "MET_LONG"
                | "MET_ULONG"
                | "MET_LONG_LONG"
                | "MET_ULONG_LONG"
                | "MET_STRING"
                | "MET_NONE"
                | "MET_OTHER"
                | "MET_FLOAT_MATRIX"
        ) || (t.starts_with("MET_") && t.ends_with("_ARRAY")) =>
        {
            return Err(VolumeError::Unsupported(format!(
                "MetaImage ElementType {t} (supported: MET_UCHAR MET_CHAR MET_USHORT MET_SHORT \
                 MET_UINT MET_INT MET_FLOAT MET_DOUBLE)"
            )));
        }
        t => return Err(err(format!("unknown ElementType `{t}`"))),
    })
}

fn element_type_name(t: VoxelType) -> &'static str {
    match t {
        VoxelType::U8 => "MET_UCHAR",
        VoxelType::I8 => "MET_CHAR",
        VoxelType::U16 => "MET_USHORT",
        VoxelType::I16 => "MET_SHORT",
        VoxelType::U32 => "MET_UINT",
        VoxelType::I32 => "MET_INT",
        VoxelType::F32 => "MET_FLOAT",
        VoxelType::F64 => "MET_DOUBLE",
    }
}

/// Parse the header in `bytes`; `complete` says that `bytes` is the whole file (so a last
/// line without a newline is a full line, not a cut-off one).
fn parse_header(bytes: &[u8], complete: bool) -> Result<Meta, VolumeError> {
    let mut lines = Lines::new(bytes);
    let mut fields: Vec<(String, String)> = Vec::new();
    let mut line_no = 0usize;
    let mut found_data_file = false;
    while let Some(line) = lines.next_line(complete) {
        line_no += 1;
        let t = line.trim();
        if t.is_empty() {
            continue;
        }
        let Some((k, v)) = t.split_once('=') else {
            return Err(err(format!(
                "header line {line_no} `{}` is not `Key = Value`",
                t.chars().take(80).collect::<String>()
            )));
        };
        let (k, v) = (k.trim().to_string(), v.trim().to_string());
        let last = k.eq_ignore_ascii_case("ElementDataFile");
        fields.push((k, v));
        if last {
            found_data_file = true;
            break;
        }
    }
    if !found_data_file {
        return Err(err(if bytes.len() >= text_header::MAX_HEADER_BYTES {
            format!(
                "no ElementDataFile key within the first {} bytes of the header",
                text_header::MAX_HEADER_BYTES
            )
        } else {
            "missing the ElementDataFile key (it must be the last key of the header)".into()
        }));
    }
    let data_offset = lines.pos();
    let get = |key: &str| {
        fields
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(key))
            .map(|(_, v)| v.as_str())
    };
    let get_any = |keys: &[&'static str]| keys.iter().find_map(|&k| get(k).map(|v| (k, v)));

    if let Some(ot) = get("ObjectType")
        && !ot.eq_ignore_ascii_case("Image")
    {
        return Err(VolumeError::Unsupported(format!(
            "MetaImage ObjectType `{ot}` (only Image)"
        )));
    }
    let ndims_s = get("NDims").ok_or_else(|| err("missing the NDims key"))?;
    let ndims = text_header::parse_size(FMT, "NDims", ndims_s)?;
    if ndims > 4 {
        return Err(VolumeError::Unsupported(format!(
            "MetaImage with NDims = {ndims} (1 to 3, or 4 with a fourth size of 1)"
        )));
    }
    let dims_s = get("DimSize").ok_or_else(|| err("missing the DimSize key"))?;
    let dims = text_header::parse_sizes(FMT, "DimSize", dims_s, ndims)?;
    if ndims == 4 && dims[3] != 1 {
        return Err(VolumeError::Unsupported(format!(
            "4-D MetaImage with DimSize {dims:?} (only a fourth size of 1 is supported)"
        )));
    }
    let k = ndims.min(3);
    let list = |key: &str, v: &str| text_header::parse_f64_list(FMT, key, v, ndims);
    let spacing = match get_any(&["ElementSpacing", "ElementSize"]) {
        Some((key, v)) => list(key, v)?,
        None => vec![1.0; ndims],
    };
    let offset = match get_any(&["Offset", "Position", "Origin"]) {
        Some((key, v)) => list(key, v)?,
        None => vec![0.0; ndims],
    };
    let mut geometry = Geometry::new([1, 1, 1]);
    let mut cols = [DVec3::X, DVec3::Y, DVec3::Z];
    if let Some((key, v)) = get_any(&["TransformMatrix", "Rotation", "Orientation"]) {
        let m = text_header::parse_f64_list(FMT, key, v, ndims * ndims)?;
        for (ii, col) in cols.iter_mut().enumerate().take(k) {
            let mut c = DVec3::ZERO;
            for jj in 0..k {
                c[jj] = m[ii * ndims + jj];
            }
            *col = c;
        }
    }
    for a in 0..k {
        geometry.dims[a] = dims[a];
        geometry.spacing[a] = spacing[a];
        geometry.origin[a] = offset[a];
    }
    geometry.direction = if k == 3 {
        DMat3::from_cols(cols[0], cols[1], cols[2])
    } else {
        let mut m = DMat3::from_cols(cols[0], cols[1], cols[2]);
        // Axes beyond NDims keep their unit direction, as ITK's lower-dimensional images.
        for (a, e) in [DVec3::X, DVec3::Y, DVec3::Z]
            .into_iter()
            .enumerate()
            .skip(k)
        {
            *m.col_mut(a) = e;
        }
        m
    };
    if !(geometry.spacing.is_finite() && geometry.spacing.min_element() > 0.0) {
        return Err(err(format!(
            "ElementSpacing {:?} must be positive",
            &spacing[..]
        )));
    }
    geometry.validate().map_err(|e| err(e.to_string()))?;

    let channels = match get("ElementNumberOfChannels") {
        Some(v) => text_header::parse_size(FMT, "ElementNumberOfChannels", v)?,
        None => 1,
    };
    if channels == 0 {
        return Err(err("ElementNumberOfChannels = 0"));
    }
    let et = get("ElementType").ok_or_else(|| err("missing the ElementType key"))?;
    let voxel_type = parse_element_type(et)?;
    let big_endian = match get_any(&["BinaryDataByteOrderMSB", "ElementByteOrderMSB"]) {
        Some((key, v)) => parse_bool(key, v)?,
        None => false,
    };
    let binary = match get("BinaryData") {
        Some(v) => parse_bool("BinaryData", v)?,
        None => true,
    };
    let compressed = match get("CompressedData") {
        Some(v) => parse_bool("CompressedData", v)?,
        None => false,
    };
    let compressed_size = match get("CompressedDataSize") {
        Some(v) if compressed => {
            Some(text_header::parse_size(FMT, "CompressedDataSize", v)? as u64)
        }
        _ => None,
    };
    let header_size = match get("HeaderSize") {
        Some(v) => {
            let h = text_header::parse_i64(FMT, "HeaderSize", v)?;
            if h < -1 {
                return Err(err(format!("HeaderSize = {h} is negative")));
            }
            h
        }
        None => 0,
    };
    let encoding = match (binary, compressed) {
        (_, true) => Encoding::Zlib,
        (true, false) => Encoding::Raw,
        (false, false) => Encoding::Ascii,
    };
    let edf = get("ElementDataFile").unwrap_or_default().to_string();
    let data_file = if edf.eq_ignore_ascii_case("LOCAL") {
        None
    } else if edf.is_empty() {
        return Err(err("ElementDataFile is empty"));
    } else if edf.to_ascii_uppercase().starts_with("LIST") {
        return Err(VolumeError::Unsupported(format!(
            "MetaImage ElementDataFile = {edf}: lists of slice files (only LOCAL or a single \
             data file)"
        )));
    } else if edf.contains('%') && edf.split_ascii_whitespace().count() >= 4 {
        return Err(VolumeError::Unsupported(format!(
            "MetaImage ElementDataFile = {edf}: numbered slice-file patterns (only LOCAL or a \
             single data file)"
        )));
    } else {
        Some(edf)
    };
    Ok(Meta {
        geometry,
        voxel_type,
        channels,
        big_endian,
        encoding,
        compressed_size,
        header_size,
        data_file,
        data_offset,
        header: Header { fields },
    })
}

/// Refuse a multi-channel image where a scalar volume is read.
fn require_scalar(meta: &Meta) -> Result<(), VolumeError> {
    if meta.channels != 1 {
        return Err(VolumeError::Unsupported(format!(
            "MetaImage with ElementNumberOfChannels = {}: a vector image (e.g. a displacement \
             field) is read as a map, not as a volume",
            meta.channels
        )));
    }
    Ok(())
}

fn decode(meta: &Meta, input: Input<'_>, detached: bool) -> Result<AnyVolume, VolumeError> {
    require_scalar(meta)?;
    text_header::decode(input, &data_spec(meta, detached), meta.geometry)
}

/// Where and how the data of `meta` are stored. Uncompressed binary data fill their file
/// exactly: a detached data file holds `HeaderSize` bytes and the voxels (unless
/// `HeaderSize = -1`: the voxels are the last bytes of a longer file), an inline one the
/// header and the voxels.
fn data_spec(meta: &Meta, detached: bool) -> DataSpec {
    let start = if !detached {
        Start::Offset(meta.data_offset as u64)
    } else if meta.header_size == -1 {
        Start::FromEnd
    } else {
        Start::Offset(0)
    };
    let words = if detached {
        text_header::SizeWords {
            source: format!(
                "ElementDataFile `{}`",
                meta.data_file.as_deref().unwrap_or_default()
            ),
            fields: "DimSize, ElementType and HeaderSize",
            at_end: Some("HeaderSize = -1"),
        }
    } else {
        text_header::SizeWords {
            source: "the data after the header (ElementDataFile = LOCAL)".into(),
            fields: "DimSize and ElementType",
            at_end: None,
        }
    };
    let spec = DataSpec {
        fmt: FMT,
        voxel_type: meta.voxel_type,
        big_endian: meta.big_endian,
        encoding: meta.encoding,
        start,
        line_skip: 0,
        decoded_skip: 0,
        encoded_len: meta.compressed_size,
        exact: meta.encoding == Encoding::Raw,
        words: Some(words),
    };
    if detached && meta.header_size > 0 {
        let skip = meta.header_size as u64;
        match meta.encoding {
            // HeaderSize counts bytes of the data file itself, before any decompression.
            Encoding::Raw | Encoding::Ascii => DataSpec {
                decoded_skip: skip,
                ..spec
            },
            _ => DataSpec {
                start: Start::Offset(skip),
                ..spec
            },
        }
    } else {
        spec
    }
}

/// The vectors of a 3-channel image (`ElementNumberOfChannels = 3`, interleaved), in f64.
fn decode_vectors(
    meta: &Meta,
    input: Input<'_>,
    detached: bool,
) -> Result<Vec<DVec3>, VolumeError> {
    if meta.channels != 3 {
        return Err(VolumeError::Unsupported(format!(
            "a displacement field has 3 components per voxel \
             (ElementNumberOfChannels = 3), this image has {}",
            meta.channels
        )));
    }
    meta.geometry.validate()?;
    let n = volmorph_io::checked_len(&meta.geometry.dims, 3 * 8)?;
    let values = text_header::decode_values_f64(input, &data_spec(meta, detached), 3 * n)?;
    let vectors: Vec<DVec3> = values
        .chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect();
    if let Some((i, _)) = vectors.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(err(format!(
            "vector {i} of the displacement field is not finite"
        )));
    }
    Ok(vectors)
}

/// Read a single-file 3-channel MetaImage (`.mha`) from memory: its geometry and vectors
/// (x fastest; components as stored, ITK's physical LPS frame).
///
/// # Errors
/// As [`read_bytes`]; [`VolumeError::Unsupported`] for an image without exactly 3 channels;
/// [`VolumeError::Format`] for a non-finite vector.
pub fn read_vector_bytes(bytes: &[u8]) -> Result<(Geometry, Vec<DVec3>, Header), VolumeError> {
    let meta = parse_header(bytes, bytes.len() <= text_header::MAX_HEADER_BYTES)?;
    text_header::require_attached(FMT, meta.data_file.as_deref())?;
    let v = decode_vectors(&meta, Input::Bytes(bytes), false)?;
    Ok((meta.geometry, v, meta.header))
}

/// Read a 3-channel `.mha` / `.mhd` (see [`read_vector_bytes`]).
pub(crate) fn read_vector(
    path: &Path,
    options: &ReadOptions,
) -> Result<(Geometry, Vec<DVec3>, Header), VolumeError> {
    let (prefix, len) = text_header::read_prefix(path)?;
    let meta = parse_header(&prefix, prefix.len() as u64 == len)?;
    let v = match &meta.data_file {
        None => decode_vectors(&meta, Input::File(path), false)?,
        Some(name) => {
            let data =
                text_header::existing_data_file(FMT, "ElementDataFile", path, name, options)?;
            decode_vectors(&meta, Input::File(&data), true).map_err(|e| e.at(&data))?
        }
    };
    Ok((meta.geometry, v, meta.header))
}

/// Read a single-file MetaImage (`.mha`, `ElementDataFile = LOCAL`) from memory.
///
/// # Errors
/// [`VolumeError::Format`] for a malformed header or truncated/corrupt voxel data;
/// [`VolumeError::Unsupported`] for a valid feature volmorph does not handle (multi-channel,
/// unsupported element type, …) and for a header that names a detached data file (use
/// [`crate::read`] with the header's path).
pub fn read_bytes(bytes: &[u8]) -> Result<(AnyVolume, Header), VolumeError> {
    let meta = parse_header(bytes, bytes.len() <= text_header::MAX_HEADER_BYTES)?;
    text_header::require_attached(FMT, meta.data_file.as_deref())?;
    let v = decode(&meta, Input::Bytes(bytes), false)?;
    Ok((v, meta.header))
}

pub(crate) fn read(path: &Path, options: &ReadOptions) -> Result<(AnyVolume, Header), VolumeError> {
    let (prefix, len) = text_header::read_prefix(path)?;
    let meta = parse_header(&prefix, prefix.len() as u64 == len)?;
    let v = match &meta.data_file {
        None => decode(&meta, Input::File(path), false)?,
        Some(name) => {
            let data =
                text_header::existing_data_file(FMT, "ElementDataFile", path, name, options)?;
            decode(&meta, Input::File(&data), true).map_err(|e| e.at(&data))?
        }
    };
    Ok((v, meta.header))
}

/// ITK's three-letter orientation code for a direction matrix: for each index axis, the
/// anatomical side it comes *from* (`R`/`L`, `A`/`P`, `I`/`S`), chosen by the dominant
/// component of its direction in LPS space (identity → `RAI`).
fn orientation_code(d: &DMat3) -> String {
    (0..3)
        .map(|c| {
            let col = d.col(c);
            let a = col.abs();
            let axis = if a.x >= a.y && a.x >= a.z {
                0
            } else if a.y >= a.z {
                1
            } else {
                2
            };
            let pos = col[axis] >= 0.0;
            match (axis, pos) {
                (0, true) => 'R',
                (0, false) => 'L',
                (1, true) => 'A',
                (1, false) => 'P',
                (2, true) => 'I',
                _ => 'S',
            }
        })
        .collect()
}

fn join(v: &[f64]) -> String {
    v.iter().map(|&x| fmt_f64(x)).collect::<Vec<_>>().join(" ")
}

fn header_text(volume: &AnyVolume, compressed_size: Option<u64>, data_file: &str) -> String {
    header_text_for(
        volume.geometry(),
        volume.voxel_type(),
        1,
        compressed_size,
        data_file,
    )
}

/// The header of an image on `g` with `channels` values of type `t` per voxel.
fn header_text_for(
    g: &Geometry,
    t: VoxelType,
    channels: usize,
    compressed_size: Option<u64>,
    data_file: &str,
) -> String {
    let mut s = String::with_capacity(512);
    s.push_str("ObjectType = Image\nNDims = 3\nBinaryData = True\n");
    s.push_str("BinaryDataByteOrderMSB = False\n");
    match compressed_size {
        Some(n) => s.push_str(&format!(
            "CompressedData = True\nCompressedDataSize = {n}\n"
        )),
        None => s.push_str("CompressedData = False\n"),
    }
    s.push_str(&format!(
        "TransformMatrix = {}\n",
        join(&g.direction.to_cols_array())
    ));
    s.push_str(&format!("Offset = {}\n", join(&g.origin.to_array())));
    s.push_str("CenterOfRotation = 0 0 0\n");
    s.push_str(&format!(
        "AnatomicalOrientation = {}\n",
        orientation_code(&g.direction)
    ));
    s.push_str(&format!(
        "ElementSpacing = {}\n",
        join(&g.spacing.to_array())
    ));
    s.push_str(&format!(
        "DimSize = {} {} {}\n",
        g.dims[0], g.dims[1], g.dims[2]
    ));
    if channels > 1 {
        s.push_str(&format!("ElementNumberOfChannels = {channels}\n"));
    }
    s.push_str(&format!("ElementType = {}\n", element_type_name(t)));
    s.push_str(&format!("ElementDataFile = {data_file}\n"));
    s
}

fn zlib(
    data: &dyn Fn(&mut dyn Write) -> std::io::Result<()>,
    options: &WriteOptions,
    w: impl Write,
) -> std::io::Result<u64> {
    let mut enc = flate2::write::ZlibEncoder::new(
        CountingWriter { inner: w, count: 0 },
        text_header::level(options.level),
    );
    data(&mut enc)?;
    let mut c = enc.finish()?;
    c.flush()?;
    Ok(c.count)
}

pub(crate) fn write(
    path: &Path,
    volume: &AnyVolume,
    options: &WriteOptions,
) -> Result<(), VolumeError> {
    volume.geometry().validate()?;
    write_payload(
        path,
        options,
        &|size, name| header_text(volume, size, name),
        &|w| text_header::write_voxels(w, volume, false),
    )
}

/// Write a 3-channel image (`ElementNumberOfChannels = 3`, the components interleaved) of
/// `f32` or `f64` (`voxel_type`), inline (`.mha`) or detached (`.mhd`) as [`write`] does.
pub(crate) fn write_vector(
    path: &Path,
    geometry: &Geometry,
    vectors: &[DVec3],
    voxel_type: VoxelType,
    options: &WriteOptions,
) -> Result<(), VolumeError> {
    geometry.validate()?;
    let data = |w: &mut dyn Write| -> std::io::Result<()> {
        if voxel_type == VoxelType::F32 {
            let v: Vec<f32> = vectors
                .iter()
                .flat_map(|v| v.to_array())
                .map(|x| x as f32)
                .collect();
            text_header::write_values(w, &v, false)
        } else {
            let v: Vec<f64> = vectors.iter().flat_map(|v| v.to_array()).collect();
            text_header::write_values(w, &v, false)
        }
    };
    write_payload(
        path,
        options,
        &|size, name| header_text_for(geometry, voxel_type, 3, size, name),
        &data,
    )
}

/// Write a header (`header(compressed size, data file name)`) and its data (`data`), inline
/// or detached by the name of `path`, compressed per `options`.
fn write_payload(
    path: &Path,
    options: &WriteOptions,
    header: &dyn Fn(Option<u64>, &str) -> String,
    data: &dyn Fn(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), VolumeError> {
    let os = os_err(path);
    let data_ext = if options.compress { "zraw" } else { "raw" };
    if is_detached_name(path) {
        volmorph_io::write_detached::<VolumeError, _, _, _>(
            path,
            data_ext,
            &DATA_EXTS,
            |w| {
                if options.compress {
                    Ok(Some(zlib(data, options, w).map_err(&os)?))
                } else {
                    data(w).map_err(&os)?;
                    Ok(None)
                }
            },
            |w, data_name, size| w.write_all(header(size, data_name).as_bytes()).map_err(&os),
        )
        .map(drop)
    } else if options.compress {
        let mut buf = Vec::new();
        let size = zlib(data, options, &mut buf).map_err(&os)?;
        let text = header(Some(size), "LOCAL");
        volmorph_io::write_atomic::<VolumeError, _>(path, |w| {
            w.write_all(text.as_bytes()).map_err(&os)?;
            w.write_all(&buf).map_err(&os)
        })
    } else {
        let text = header(None, "LOCAL");
        volmorph_io::write_atomic::<VolumeError, _>(path, |w| {
            w.write_all(text.as_bytes()).map_err(&os)?;
            data(w).map_err(&os)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orientation_codes_follow_itk() {
        assert_eq!(orientation_code(&DMat3::IDENTITY), "RAI");
        let flip = DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0));
        assert_eq!(orientation_code(&flip), "LPI");
        let perm = DMat3::from_cols(DVec3::Y, DVec3::NEG_Z, DVec3::X);
        assert_eq!(orientation_code(&perm), "ASR");
    }

    #[test]
    fn element_types() {
        for t in VoxelType::ALL {
            assert_eq!(parse_element_type(element_type_name(t)).unwrap(), t);
        }
        assert!(matches!(
            parse_element_type("MET_LONG_LONG"),
            Err(VolumeError::Unsupported(_))
        ));
        assert!(matches!(
            parse_element_type("MET_FLOAT_ARRAY"),
            Err(VolumeError::Unsupported(_))
        ));
        assert!(matches!(
            parse_element_type("MET_BANANA"),
            Err(VolumeError::Format { .. })
        ));
    }
}
