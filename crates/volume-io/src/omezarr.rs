//! OME-Zarr (OME-NGFF multiscale images): v0.4 on Zarr v2 and v0.5 on Zarr v3, read and
//! written with the `zarrs` crate on a filesystem store.
//!
//! # Geometry
//!
//! NGFF lists the array axes slowest first; volmorph's three spatial axes are the last three
//! array axes, named `z`, `y`, `x` in that order. A C-order Zarr array of shape
//! `[nz, ny, nx]` has x fastest in memory, which is volmorph's layout, so voxels are copied
//! as they are. Axes before them (`t`, `c`) must have length 1 and are dropped on reading.
//!
//! Each dataset's `coordinateTransformations` (a `scale`, then optionally a `translation`,
//! followed by the multiscale's own optional ones) give the physical position of voxel
//! centre `i` as `scale ⊙ i + translation` per axis. So volmorph's `spacing = (sx, sy, sz)`
//! and `origin = (tx, ty, tz)`, the array lists reversed. NGFF has **no direction matrix**:
//! a volume read from OME-Zarr has the identity direction, and writing a volume whose
//! direction is not the identity is refused ([`VolumeError::Unsupported`]) rather than
//! silently dropping its orientation; resample it onto an axis-aligned grid first. Axis
//! units are reported in the header and not converted.
//!
//! # Pyramids
//!
//! Level 0 is the full resolution. Level `l + 1` has `⌈n_l / 2⌉` voxels per axis; its voxel
//! is the mean of the (up to) 2×2×2 voxels of level `l` it covers, rounded to the voxel type
//! ([`Voxel::from_f64`]), with twice the spacing and the translation of the block's centre
//! (`t + s/2`, the centre of a full block). Levels are built chunk by chunk from the level
//! above, so writing a pyramid never holds more than one chunk neighbourhood per thread.
//!
//! # Atomic output
//!
//! A store is written into a [`PartialDir`] next to the target and renamed into place when
//! complete: a failed or interrupted write never leaves a half-written store.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;
use serde_json::{Value, json};
use volmorph_io::PartialDir;
use volmorph_volume::{
    AnyVolume, DMat3, DVec3, Geometry, IndexBox, Volume, VolumeError, Voxel, VoxelType,
};
use zarrs::array::{Array, ArraySubset, ElementOwned};
use zarrs::filesystem::FilesystemStore;

use crate::Header;

/// Format name in error messages.
pub const FORMAT: &str = "OME-Zarr";

/// Default chunk edge (voxels per axis) of written stores: 64³ voxels are 512 KiB of `u16`,
/// large enough that per-chunk overhead (one file, one codec call) is small and small enough
/// that a chunk neighbourhood per thread fits a bounded-memory warp.
pub const DEFAULT_CHUNK: usize = 64;

/// Levels of a written pyramid stop once every axis of the coarsest level fits in one chunk,
/// and never exceed this count.
pub const MAX_LEVELS: usize = 16;

/// zstd level of written chunks: zstd's own default, a good speed/size trade-off.
pub const ZSTD_LEVEL: i32 = 3;

/// Largest metadata document read (`.zattrs`, `.zarray`, `zarr.json`): real ones are a few
/// KiB; anything far larger is not metadata.
pub const MAX_METADATA_BYTES: u64 = 16 << 20;

/// Which Zarr and NGFF version a store uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ZarrVersion {
    /// OME-NGFF v0.4 on Zarr v2 (`.zgroup`, `.zattrs`, `.zarray`): read by every OME-Zarr tool.
    #[default]
    V2,
    /// OME-NGFF v0.5 on Zarr v3 (`zarr.json`, attributes under `ome`).
    V3,
}

impl ZarrVersion {
    /// The NGFF version written for this Zarr version.
    #[must_use]
    pub fn ngff(self) -> &'static str {
        match self {
            Self::V2 => "0.4",
            Self::V3 => "0.5",
        }
    }
}

/// How a store is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ZarrWriteOptions {
    /// Zarr/NGFF version.
    pub version: ZarrVersion,
    /// Chunk shape in voxels along x, y, z (each ≥ 1; clipped to the dims).
    pub chunk: [usize; 3],
    /// Number of pyramid levels including the full resolution (≥ 1); `None` halves until
    /// the coarsest level fits one chunk (at most [`MAX_LEVELS`]).
    pub levels: Option<usize>,
    /// Compress chunks with zstd at [`ZSTD_LEVEL`]; uncompressed otherwise.
    pub compress: bool,
}

impl Default for ZarrWriteOptions {
    fn default() -> Self {
        Self {
            version: ZarrVersion::V2,
            chunk: [DEFAULT_CHUNK; 3],
            levels: None,
            compress: true,
        }
    }
}

/// One resolution level of a multiscale image: its array path and voxel-centre transform.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Array path relative to the image group (`"0"`, `"1"`, …).
    pub path: String,
    /// Voxel spacing along x, y, z (physical units per voxel, > 0).
    pub scale: [f64; 3],
    /// Physical position of voxel `(0, 0, 0)` along x, y, z.
    pub translation: [f64; 3],
}

/// The `multiscales[0]` entry of an OME-Zarr image group, in volmorph's axis order.
#[derive(Debug, Clone, PartialEq)]
pub struct Multiscale {
    /// NGFF version (`"0.4"`, `"0.5"`).
    pub version: String,
    /// Name of the image, if given.
    pub name: Option<String>,
    /// Number of array axes (3 to 5): the leading ones (time, channel) have length 1.
    pub ndim: usize,
    /// Units of x, y, z, if given (not converted).
    pub units: [Option<String>; 3],
    /// The levels, full resolution first.
    pub datasets: Vec<Dataset>,
}

fn fmt_err(message: impl Into<String>) -> VolumeError {
    VolumeError::format(FORMAT, message)
}

fn zerr(what: &str, e: impl std::fmt::Display) -> VolumeError {
    fmt_err(format!("{what}: {e}"))
}

/// A JSON array of exactly `n` finite numbers.
fn numbers(v: &Value, n: usize, field: &str) -> Result<Vec<f64>, VolumeError> {
    let a = v
        .as_array()
        .ok_or_else(|| fmt_err(format!("{field} is not a list")))?;
    if a.len() != n {
        return Err(fmt_err(format!(
            "{field} has {} values, the image has {n} axes",
            a.len()
        )));
    }
    a.iter()
        .map(|x| {
            x.as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| fmt_err(format!("{field} holds {x}, not a finite number")))
        })
        .collect()
}

/// Fold a list of `coordinateTransformations` into `(scale, translation)` per array axis:
/// `x ↦ scale ⊙ x + translation` after `(scale, translation)` already applied.
fn fold_transforms(
    list: &Value,
    n: usize,
    field: &str,
    scale: &mut [f64],
    translation: &mut [f64],
) -> Result<(), VolumeError> {
    let items = list
        .as_array()
        .ok_or_else(|| fmt_err(format!("{field} is not a list")))?;
    for (k, t) in items.iter().enumerate() {
        let kind = t.get("type").and_then(Value::as_str).unwrap_or("");
        let here = format!("{field}[{k}]");
        match kind {
            "scale" => {
                let s = numbers(
                    t.get("scale").ok_or_else(|| {
                        fmt_err(format!("{here}: a scale without values (or a path, which volmorph does not read)"))
                    })?,
                    n,
                    &format!("{here}.scale"),
                )?;
                for a in 0..n {
                    scale[a] *= s[a];
                    translation[a] *= s[a];
                }
            }
            "translation" => {
                let s = numbers(
                    t.get("translation").ok_or_else(|| {
                        fmt_err(format!("{here}: a translation without values (or a path, which volmorph does not read)"))
                    })?,
                    n,
                    &format!("{here}.translation"),
                )?;
                for a in 0..n {
                    translation[a] += s[a];
                }
            }
            "identity" => {}
            other => {
                return Err(VolumeError::Unsupported(format!(
                    "{FORMAT}: {here} has type `{other}`; volmorph reads scale and translation"
                )));
            }
        }
    }
    Ok(())
}

/// Parse the attributes of an OME-Zarr image group: the `.zattrs` document (Zarr v2, NGFF
/// v0.4 and earlier) or the group's `zarr.json` (Zarr v3, NGFF v0.5, attributes under
/// `ome`). The first multiscale image is returned with its axes in volmorph's order.
///
/// # Errors
/// [`VolumeError::Format`] naming the field for malformed JSON, a missing `multiscales`,
/// axes that are not (optional length-1 `time`/`channel` axes, then) the spatial `z`, `y`,
/// `x`, transforms with the wrong length, non-finite or non-positive scales;
/// [`VolumeError::Unsupported`] for transform types other than scale and translation.
pub fn parse_attributes(bytes: &[u8], version: ZarrVersion) -> Result<Multiscale, VolumeError> {
    let doc: Value = serde_json::from_slice(bytes).map_err(|e| zerr("metadata is not JSON", e))?;
    let attrs = match version {
        ZarrVersion::V2 => &doc,
        ZarrVersion::V3 => {
            let a = doc
                .get("attributes")
                .ok_or_else(|| fmt_err("zarr.json has no attributes"))?;
            a.get("ome").unwrap_or(a)
        }
    };
    let ms = attrs
        .get("multiscales")
        .and_then(Value::as_array)
        .and_then(|m| m.first())
        .ok_or_else(|| fmt_err("no multiscales image in the group attributes"))?;
    let ngff = ms
        .get("version")
        .or_else(|| attrs.get("version"))
        .and_then(Value::as_str)
        .unwrap_or(match version {
            ZarrVersion::V2 => "0.4",
            ZarrVersion::V3 => "0.5",
        })
        .to_string();
    let axes = ms
        .get("axes")
        .and_then(Value::as_array)
        .ok_or_else(|| fmt_err("multiscales[0].axes is missing (NGFF before v0.3)"))?;
    let n = axes.len();
    if !(3..=5).contains(&n) {
        return Err(fmt_err(format!(
            "multiscales[0].axes has {n} axes; volmorph reads 3-D images (z, y, x) with optional \
             time and channel axes of length 1"
        )));
    }
    let name_of = |a: &Value| -> String {
        a.as_str()
            .or_else(|| a.get("name").and_then(Value::as_str))
            .unwrap_or("")
            .to_ascii_lowercase()
    };
    let mut units: [Option<String>; 3] = [None, None, None];
    for (k, want) in ["z", "y", "x"].iter().enumerate() {
        let a = &axes[n - 3 + k];
        let got = name_of(a);
        if got != *want {
            return Err(fmt_err(format!(
                "multiscales[0].axes[{}] is `{got}`; volmorph needs the last three axes to be z, y, x",
                n - 3 + k
            )));
        }
        if let Some(t) = a.get("type").and_then(Value::as_str)
            && t != "space"
        {
            return Err(fmt_err(format!(
                "multiscales[0].axes[{}] (`{want}`) has type `{t}`, not space",
                n - 3 + k
            )));
        }
        units[2 - k] = a.get("unit").and_then(Value::as_str).map(str::to_string);
    }
    for (k, a) in axes[..n - 3].iter().enumerate() {
        let kind = a.get("type").and_then(Value::as_str).unwrap_or("");
        if kind == "space" {
            return Err(fmt_err(format!(
                "multiscales[0].axes[{k}] (`{}`) is a fourth spatial axis",
                name_of(a)
            )));
        }
    }
    let datasets = ms
        .get("datasets")
        .and_then(Value::as_array)
        .filter(|d| !d.is_empty())
        .ok_or_else(|| fmt_err("multiscales[0].datasets is missing or empty"))?;
    let mut out = Vec::with_capacity(datasets.len());
    for (l, d) in datasets.iter().enumerate() {
        let field = format!("multiscales[0].datasets[{l}]");
        let path = d
            .get("path")
            .and_then(Value::as_str)
            .ok_or_else(|| fmt_err(format!("{field}.path is missing")))?;
        if path.is_empty()
            || path.starts_with('/')
            || path
                .split('/')
                .any(|p| p == ".." || p == "." || p.is_empty())
        {
            return Err(fmt_err(format!(
                "{field}.path `{path}` is not a relative path inside the image"
            )));
        }
        let mut scale = vec![1.0; n];
        let mut translation = vec![0.0; n];
        let list = d
            .get("coordinateTransformations")
            .ok_or_else(|| fmt_err(format!("{field}.coordinateTransformations is missing")))?;
        fold_transforms(
            list,
            n,
            &format!("{field}.coordinateTransformations"),
            &mut scale,
            &mut translation,
        )?;
        if let Some(list) = ms.get("coordinateTransformations") {
            fold_transforms(
                list,
                n,
                "multiscales[0].coordinateTransformations",
                &mut scale,
                &mut translation,
            )?;
        }
        let xyz = |v: &[f64]| [v[n - 1], v[n - 2], v[n - 3]];
        let scale = xyz(&scale);
        if scale.iter().any(|&s| !(s.is_finite() && s > 0.0)) {
            return Err(fmt_err(format!(
                "{field}: spatial scale {scale:?} (x, y, z) is not positive"
            )));
        }
        let translation = xyz(&translation);
        if translation.iter().any(|t| !t.is_finite()) {
            return Err(fmt_err(format!(
                "{field}: spatial translation {translation:?} (x, y, z) is not finite"
            )));
        }
        out.push(Dataset {
            path: path.to_string(),
            scale,
            translation,
        });
    }
    Ok(Multiscale {
        version: ngff,
        name: ms.get("name").and_then(Value::as_str).map(str::to_string),
        ndim: n,
        units,
        datasets: out,
    })
}

/// The extensions of OME-Zarr stores written ([`OmeZarrWriter::create`]): `.ome.zarr` and
/// `.zarr`.
pub const ZARR_EXTENSIONS: &[&str] = &["ome.zarr", "zarr"];

/// `true` if `path` names an OME-Zarr store (`.ome.zarr` or `.zarr`, case-insensitive).
#[must_use]
pub fn is_ome_zarr_path(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let name = name.trim_end_matches('/');
    name.ends_with(".ome.zarr") || name.ends_with(".zarr")
}

/// Read a metadata file of at most [`MAX_METADATA_BYTES`], `None` if absent.
fn read_small(path: &Path) -> Result<Option<Vec<u8>>, VolumeError> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(volmorph_io::IoError::os(path, e).into()),
        Ok(m) if m.len() > MAX_METADATA_BYTES => {
            return Err(fmt_err(format!(
                "{} is {} bytes, too large for metadata",
                path.display(),
                m.len()
            )));
        }
        Ok(_) => {}
    }
    std::fs::read(path)
        .map(Some)
        .map_err(|e| volmorph_io::IoError::os(path, e).into())
}

/// The voxel type of a zarrs data type, if volmorph has it.
fn voxel_type_of(dt: &zarrs::array::DataType) -> Option<VoxelType> {
    use zarrs::array::data_type as d;
    [
        (d::uint8(), VoxelType::U8),
        (d::int8(), VoxelType::I8),
        (d::uint16(), VoxelType::U16),
        (d::int16(), VoxelType::I16),
        (d::uint32(), VoxelType::U32),
        (d::int32(), VoxelType::I32),
        (d::float32(), VoxelType::F32),
        (d::float64(), VoxelType::F64),
    ]
    .into_iter()
    .find(|(z, _)| z == dt)
    .map(|(_, v)| v)
}

/// Zarr v3 `data_type` and Zarr v2 `dtype` (little-endian) of a voxel type.
fn zarr_type_names(t: VoxelType) -> (&'static str, &'static str) {
    match t {
        VoxelType::U8 => ("uint8", "|u1"),
        VoxelType::I8 => ("int8", "|i1"),
        VoxelType::U16 => ("uint16", "<u2"),
        VoxelType::I16 => ("int16", "<i2"),
        VoxelType::U32 => ("uint32", "<u4"),
        VoxelType::I32 => ("int32", "<i4"),
        VoxelType::F32 => ("float32", "<f4"),
        VoxelType::F64 => ("float64", "<f8"),
    }
}

/// An open OME-Zarr image: one resolution level, read box by box.
pub struct OmeZarrReader {
    path: PathBuf,
    array: Array<FilesystemStore>,
    multiscale: Multiscale,
    version: ZarrVersion,
    level: usize,
    geometry: Geometry,
    voxel_type: VoxelType,
    chunk: [usize; 3],
}

impl std::fmt::Debug for OmeZarrReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OmeZarrReader")
            .field("path", &self.path)
            .field("level", &self.level)
            .field("geometry", &self.geometry)
            .field("voxel_type", &self.voxel_type)
            .finish_non_exhaustive()
    }
}

impl OmeZarrReader {
    /// Open level 0 (full resolution) of the image at `path`.
    ///
    /// # Errors
    /// As [`OmeZarrReader::open_level`].
    pub fn open(path: &Path) -> Result<Self, VolumeError> {
        Self::open_level(path, 0)
    }

    /// Open resolution `level` of the image at `path` (a Zarr v2 group with `.zattrs`, or a
    /// Zarr v3 group `zarr.json`). Only metadata is read.
    ///
    /// # Errors
    /// [`VolumeError::Format`] for a folder that is not an OME-Zarr image, malformed metadata
    /// (see [`parse_attributes`]), a level that does not exist, an array whose shape does not
    /// have length-1 leading axes, or a chunk grid that is not regular;
    /// [`VolumeError::Unsupported`] for a data type volmorph has no voxel type for.
    pub fn open_level(path: &Path, level: usize) -> Result<Self, VolumeError> {
        let open = || -> Result<Self, VolumeError> {
            if !path.is_dir() {
                return Err(fmt_err("not a folder (an OME-Zarr store is a folder)"));
            }
            let (bytes, version) = if let Some(b) = read_small(&path.join("zarr.json"))? {
                (b, ZarrVersion::V3)
            } else if let Some(b) = read_small(&path.join(".zattrs"))? {
                (b, ZarrVersion::V2)
            } else {
                return Err(fmt_err(
                    "neither zarr.json (Zarr v3) nor .zattrs (Zarr v2) found: not an OME-Zarr image",
                ));
            };
            let multiscale = parse_attributes(&bytes, version)?;
            let ds = multiscale.datasets.get(level).ok_or_else(|| {
                VolumeError::InvalidArgument(format!(
                    "level {level} does not exist: the image has {} level(s)",
                    multiscale.datasets.len()
                ))
            })?;
            let store =
                Arc::new(FilesystemStore::new(path).map_err(|e| zerr("cannot open the store", e))?);
            let array = Array::open(store, &format!("/{}", ds.path))
                .map_err(|e| zerr(&format!("array `{}`", ds.path), e))?;
            let shape = array.shape().to_vec();
            let n = multiscale.ndim;
            if shape.len() != n {
                return Err(fmt_err(format!(
                    "array `{}` has {} dimensions, the axes list {n}",
                    ds.path,
                    shape.len()
                )));
            }
            if let Some(a) = shape[..n - 3].iter().position(|&s| s != 1) {
                return Err(VolumeError::Unsupported(format!(
                    "{FORMAT}: array `{}` axis {a} has length {}; volmorph reads one 3-D volume \
                     (time and channel axes of length 1)",
                    ds.path, shape[a]
                )));
            }
            let to_usize = |v: u64, what: &str| {
                usize::try_from(v).map_err(|_| fmt_err(format!("{what} {v} is too large")))
            };
            let dims = [
                to_usize(shape[n - 1], "x size")?,
                to_usize(shape[n - 2], "y size")?,
                to_usize(shape[n - 3], "z size")?,
            ];
            let voxel_type = voxel_type_of(array.data_type()).ok_or_else(|| {
                VolumeError::Unsupported(format!(
                    "{FORMAT}: data type {} of array `{}` (volmorph reads u8, i8, u16, i16, u32, \
                     i32, f32, f64)",
                    array.data_type(),
                    ds.path
                ))
            })?;
            let zero = vec![0u64; n];
            let cs = array
                .chunk_shape(&zero)
                .map_err(|e| zerr(&format!("chunk grid of `{}`", ds.path), e))?;
            if cs.len() != n {
                return Err(fmt_err("chunk shape does not match the array"));
            }
            let chunk = [
                to_usize(cs[n - 1].get(), "chunk x size")?,
                to_usize(cs[n - 2].get(), "chunk y size")?,
                to_usize(cs[n - 3].get(), "chunk z size")?,
            ];
            let geometry = Geometry::new(dims)
                .with_spacing(DVec3::from_array(ds.scale))
                .with_origin(DVec3::from_array(ds.translation));
            geometry.validate_unbounded()?;
            Ok(Self {
                path: path.to_path_buf(),
                array,
                multiscale,
                version,
                level,
                geometry,
                voxel_type,
                chunk,
            })
        };
        open().map_err(|e| e.at(path))
    }

    /// The level's grid: dims x, y, z, spacing and origin from its transforms, identity
    /// direction.
    #[must_use]
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// The voxel type of the array.
    #[must_use]
    pub fn voxel_type(&self) -> VoxelType {
        self.voxel_type
    }

    /// Chunk shape of the level's array along x, y, z.
    #[must_use]
    pub fn chunk(&self) -> [usize; 3] {
        self.chunk
    }

    /// The image's multiscale metadata (every level).
    #[must_use]
    pub fn multiscale(&self) -> &Multiscale {
        &self.multiscale
    }

    /// Zarr version of the store.
    #[must_use]
    pub fn version(&self) -> ZarrVersion {
        self.version
    }

    /// Header fields for display (`volmorph info`).
    #[must_use]
    pub fn header(&self) -> Header {
        let m = &self.multiscale;
        let mut fields = vec![
            (
                "zarr_format".to_string(),
                match self.version {
                    ZarrVersion::V2 => "2",
                    ZarrVersion::V3 => "3",
                }
                .to_string(),
            ),
            ("ngff_version".into(), m.version.clone()),
            ("levels".into(), m.datasets.len().to_string()),
            ("level".into(), self.level.to_string()),
            ("array_dimensions".into(), m.ndim.to_string()),
            ("chunk_xyz".into(), format!("{:?}", self.chunk)),
            ("data_type".into(), self.array.data_type().to_string()),
        ];
        if let Some(n) = &m.name {
            fields.push(("name".into(), n.clone()));
        }
        for (a, u) in ["x", "y", "z"].iter().zip(&m.units) {
            if let Some(u) = u {
                fields.push((format!("unit_{a}"), u.clone()));
            }
        }
        for (l, d) in m.datasets.iter().enumerate() {
            fields.push((
                format!("level{l}"),
                format!(
                    "path {} scale_xyz {:?} translation_xyz {:?}",
                    d.path, d.scale, d.translation
                ),
            ));
        }
        Header { fields }
    }

    /// Read the voxels of `region` (half-open index box, x, y, z) into a volume whose
    /// geometry is the region's: same spacing, origin at the region's first voxel. Only the
    /// chunks overlapping the region are read and decoded.
    ///
    /// # Errors
    /// [`VolumeError::InvalidArgument`] for an empty region or one outside the level's dims;
    /// [`VolumeError::Io`] if the region exceeds the memory budget
    /// ([`volmorph_io::check_bytes`], checked before allocating); [`VolumeError::Format`]
    /// for chunks that fail to decode or have the wrong size.
    pub fn read_box(&self, region: IndexBox) -> Result<AnyVolume, VolumeError> {
        let dims = self.geometry.dims;
        if region.is_empty() || (0..3).any(|a| region.end[a] > dims[a]) {
            return Err(VolumeError::InvalidArgument(format!(
                "box {:?}..{:?} is empty or outside the image's {dims:?} voxels",
                region.start, region.end
            )));
        }
        let sub = [
            region.end[0] - region.start[0],
            region.end[1] - region.start[1],
            region.end[2] - region.start[2],
        ];
        volmorph_io::checked_len(&sub, self.voxel_type.size())?;
        let geometry = Geometry {
            dims: sub,
            origin: self.geometry.index_to_physical(DVec3::new(
                region.start[0] as f64,
                region.start[1] as f64,
                region.start[2] as f64,
            )),
            ..self.geometry
        };
        let n = self.multiscale.ndim;
        let mut ranges = vec![0u64..1; n];
        for a in 0..3 {
            ranges[n - 1 - a] = region.start[a] as u64..region.end[a] as u64;
        }
        let subset = ArraySubset::new_with_ranges(&ranges);
        volmorph_volume::with_voxel_type!(self.voxel_type, T => {
            let data: Vec<T> = read_subset::<T>(&self.array, &subset)
                .map_err(|e| e.at(&self.path))?;
            Volume::new(geometry, data).map(AnyVolume::from)
        })
    }

    /// Read the whole level (after checking its size against the memory budget).
    ///
    /// # Errors
    /// As [`OmeZarrReader::read_box`].
    pub fn read_all(&self) -> Result<AnyVolume, VolumeError> {
        self.read_box(IndexBox::all(self.geometry.dims))
    }
}

fn read_subset<T: ElementOwned>(
    array: &Array<FilesystemStore>,
    subset: &ArraySubset,
) -> Result<Vec<T>, VolumeError> {
    let v: Vec<T> = array
        .retrieve_array_subset(subset)
        .map_err(|e| zerr("reading chunks", e))?;
    if v.len() as u64 != subset.num_elements() {
        return Err(fmt_err("decoded region has the wrong size"));
    }
    Ok(v)
}

/// Read level 0 of an OME-Zarr image as a volume, with its header fields.
///
/// # Errors
/// As [`OmeZarrReader::open`] and [`OmeZarrReader::read_all`].
pub fn read(path: &Path) -> Result<(AnyVolume, Header), VolumeError> {
    let r = OmeZarrReader::open(path)?;
    let v = r.read_all().map_err(|e| e.at(path))?;
    Ok((v, r.header()))
}

/// Dims of each level of a pyramid over `dims` (level 0 first).
#[must_use]
pub fn pyramid_dims(dims: [usize; 3], chunk: [usize; 3], levels: Option<usize>) -> Vec<[usize; 3]> {
    let mut out = vec![dims];
    let want = levels.unwrap_or(MAX_LEVELS).clamp(1, MAX_LEVELS);
    while out.len() < want {
        let d = *out.last().expect("level 0 is there");
        let fits = (0..3).all(|a| d[a] <= chunk[a]);
        if (levels.is_none() && fits) || d.iter().all(|&n| n == 1) {
            break;
        }
        out.push(d.map(|n| n.div_ceil(2)));
    }
    out
}

/// A store being written: metadata in place, chunks written by [`OmeZarrWriter::write_chunk`],
/// pyramid built and the folder committed by [`OmeZarrWriter::finish`].
pub struct OmeZarrWriter {
    dir: PartialDir,
    arrays: Vec<Array<FilesystemStore>>,
    dims: Vec<[usize; 3]>,
    chunk: [usize; 3],
    voxel_type: VoxelType,
}

impl std::fmt::Debug for OmeZarrWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OmeZarrWriter")
            .field("target", &self.dir.target())
            .field("dims", &self.dims)
            .field("chunk", &self.chunk)
            .field("voxel_type", &self.voxel_type)
            .finish_non_exhaustive()
    }
}

impl OmeZarrWriter {
    /// Start a store at `path` for a volume on `geometry` with voxels of `voxel_type`: writes
    /// the group and array metadata of every pyramid level into a temporary folder.
    ///
    /// # Errors
    /// [`VolumeError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in
    /// `.ome.zarr` or `.zarr` ([`ZARR_EXTENSIONS`], nothing written);
    /// [`VolumeError::Unsupported`] if `geometry.direction` is not the identity (NGFF has no
    /// direction); [`VolumeError::InvalidArgument`] for a zero chunk edge or level count;
    /// [`VolumeError::Geometry`] for an invalid geometry; I/O errors naming the path.
    pub fn create(
        path: &Path,
        geometry: &Geometry,
        voxel_type: VoxelType,
        options: &ZarrWriteOptions,
    ) -> Result<Self, VolumeError> {
        volmorph_io::extension::check(path, ZARR_EXTENSIONS)?;
        let go = || -> Result<Self, VolumeError> {
            geometry.validate_unbounded()?;
            if geometry.direction != DMat3::IDENTITY {
                return Err(VolumeError::Unsupported(format!(
                    "{FORMAT} has no direction matrix (OME-NGFF stores scale and translation \
                     only), and this volume's direction is {:?}; resample it onto an \
                     axis-aligned grid first (volmorph warp --output-grid) or write another format",
                    geometry.direction.to_cols_array()
                )));
            }
            if options.chunk.contains(&0) || options.levels == Some(0) {
                return Err(VolumeError::InvalidArgument(format!(
                    "chunk {:?} and levels {:?} must be at least 1",
                    options.chunk, options.levels
                )));
            }
            let chunk = [0, 1, 2].map(|a| options.chunk[a].min(geometry.dims[a]));
            let dims = pyramid_dims(geometry.dims, chunk, options.levels);
            let dir = PartialDir::create(path)?;
            let root = dir.path().to_path_buf();
            let write = |p: PathBuf, v: &Value| -> Result<(), VolumeError> {
                let text = serde_json::to_vec_pretty(v).map_err(|e| zerr("metadata", e))?;
                std::fs::write(&p, text).map_err(|e| volmorph_io::IoError::os(&p, e).into())
            };
            let s0 = geometry.spacing.to_array();
            let t0 = geometry.origin.to_array();
            let datasets: Vec<Value> = (0..dims.len())
                .map(|l| {
                    let f = (1u64 << l) as f64;
                    // Level l's voxel 0 is the centre of the first 2^l block of level 0.
                    let s = s0.map(|s| s * f);
                    let t = [0, 1, 2].map(|a| t0[a] + 0.5 * (f - 1.0) * s0[a]);
                    json!({
                        "path": l.to_string(),
                        "coordinateTransformations": [
                            {"type": "scale", "scale": [s[2], s[1], s[0]]},
                            {"type": "translation", "translation": [t[2], t[1], t[0]]},
                        ],
                    })
                })
                .collect();
            let axes = json!([
                {"name": "z", "type": "space"},
                {"name": "y", "type": "space"},
                {"name": "x", "type": "space"},
            ]);
            let name = path
                .file_name()
                .map(|n| {
                    n.to_string_lossy()
                        .trim_end_matches(".ome.zarr")
                        .to_string()
                })
                .unwrap_or_default();
            let (v3type, v2type) = zarr_type_names(voxel_type);
            match options.version {
                ZarrVersion::V2 => {
                    write(root.join(".zgroup"), &json!({"zarr_format": 2}))?;
                    write(
                        root.join(".zattrs"),
                        &json!({"multiscales": [{
                            "version": "0.4",
                            "name": name,
                            "axes": axes,
                            "datasets": datasets,
                            "type": "mean",
                            "metadata": {"method": "volmorph 2x2x2 mean"},
                        }]}),
                    )?;
                }
                ZarrVersion::V3 => {
                    write(
                        root.join("zarr.json"),
                        &json!({
                            "zarr_format": 3,
                            "node_type": "group",
                            "attributes": {"ome": {
                                "version": "0.5",
                                "multiscales": [{
                                    "name": name,
                                    "axes": axes,
                                    "datasets": datasets,
                                    "type": "mean",
                                    "metadata": {"method": "volmorph 2x2x2 mean"},
                                }],
                            }},
                        }),
                    )?;
                }
            }
            let store = Arc::new(
                FilesystemStore::new(&root).map_err(|e| zerr("cannot create the store", e))?,
            );
            let mut arrays = Vec::with_capacity(dims.len());
            for (l, d) in dims.iter().enumerate() {
                let adir = root.join(l.to_string());
                std::fs::create_dir(&adir).map_err(|e| volmorph_io::IoError::os(&adir, e))?;
                let shape = [d[2], d[1], d[0]];
                let cshape = [chunk[2].min(d[2]), chunk[1].min(d[1]), chunk[0].min(d[0])];
                match options.version {
                    ZarrVersion::V2 => {
                        let compressor = if options.compress {
                            json!({"id": "zstd", "level": ZSTD_LEVEL})
                        } else {
                            Value::Null
                        };
                        write(
                            adir.join(".zarray"),
                            &json!({
                                "zarr_format": 2,
                                "shape": shape,
                                "chunks": cshape,
                                "dtype": v2type,
                                "compressor": compressor,
                                "fill_value": 0,
                                "order": "C",
                                "filters": null,
                                "dimension_separator": "/",
                            }),
                        )?;
                        write(
                            adir.join(".zattrs"),
                            &json!({"_ARRAY_DIMENSIONS": ["z", "y", "x"]}),
                        )?;
                    }
                    ZarrVersion::V3 => {
                        let mut codecs =
                            vec![json!({"name": "bytes", "configuration": {"endian": "little"}})];
                        if options.compress {
                            codecs.push(json!({"name": "zstd", "configuration": {"level": ZSTD_LEVEL, "checksum": false}}));
                        }
                        write(
                            adir.join("zarr.json"),
                            &json!({
                                "zarr_format": 3,
                                "node_type": "array",
                                "shape": shape,
                                "data_type": v3type,
                                "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": cshape}},
                                "chunk_key_encoding": {"name": "default", "configuration": {"separator": "/"}},
                                "fill_value": 0,
                                "codecs": codecs,
                                "dimension_names": ["z", "y", "x"],
                                "attributes": {},
                            }),
                        )?;
                    }
                }
                let array = Array::open(store.clone(), &format!("/{l}"))
                    .map_err(|e| zerr(&format!("array {l}"), e))?;
                arrays.push(array);
            }
            Ok(Self {
                dir,
                arrays,
                dims,
                chunk,
                voxel_type,
            })
        };
        go().map_err(|e| e.at(path))
    }

    /// Chunk shape (x, y, z) of level 0.
    #[must_use]
    pub fn chunk(&self) -> [usize; 3] {
        self.chunk
    }

    /// The temporary folder the store is written into until [`OmeZarrWriter::finish`]:
    /// other processes (Dask workers) write level-0 chunks there with [`store_chunk`].
    #[must_use]
    pub fn staging_path(&self) -> &Path {
        self.dir.path()
    }

    /// The boxes of level 0's chunks (x fastest), each clipped to the dims: the unit of
    /// [`OmeZarrWriter::write_chunk`].
    #[must_use]
    pub fn chunk_boxes(&self) -> Vec<IndexBox> {
        chunk_boxes(self.dims[0], self.chunk)
    }

    /// Write one chunk of level 0: `region` must be one of [`OmeZarrWriter::chunk_boxes`] and
    /// `data` its voxels (x fastest, `region.len()` values of the store's voxel type).
    /// Chunks may be written from several threads at once.
    ///
    /// # Errors
    /// [`VolumeError::InvalidArgument`] for a box that is not a chunk or data of the wrong
    /// type or length; [`VolumeError::Format`] if encoding or storing fails.
    pub fn write_chunk(&self, region: IndexBox, data: &AnyVolume) -> Result<(), VolumeError> {
        write_level_chunk(&self.arrays[0], self.chunk, self.dims[0], region, data)
    }

    /// Build the pyramid levels from level 0 (chunk by chunk, in parallel) and commit the
    /// store into place.
    ///
    /// # Errors
    /// Errors reading back or writing chunks; I/O errors of the commit. On error nothing is
    /// left at the target (an existing store there is untouched).
    pub fn finish(self) -> Result<(), VolumeError> {
        let target = self.dir.target().to_path_buf();
        let go = || -> Result<(), VolumeError> {
            for l in 1..self.arrays.len() {
                let (src, dst) = (&self.arrays[l - 1], &self.arrays[l]);
                let (sd, dd) = (self.dims[l - 1], self.dims[l]);
                let chunk = [0, 1, 2].map(|a| self.chunk[a].min(dd[a]));
                chunk_boxes(dd, chunk).into_par_iter().try_for_each(|b| {
                    let sb = IndexBox {
                        start: b.start.map(|s| 2 * s),
                        end: [0, 1, 2].map(|a| (2 * b.end[a]).min(sd[a])),
                    };
                    let src_box = read_array_box(src, self.voxel_type, sb)?;
                    let down = downsample(&src_box, b);
                    write_level_chunk(dst, chunk, dd, b, &down)
                })?;
            }
            Ok(())
        };
        go().map_err(|e| e.at(&target))?;
        self.dir
            .commit()
            .map_err(|e| VolumeError::from(e).at(&target))
    }
}

/// Write one level-0 chunk into a store that an [`OmeZarrWriter`] (possibly in another
/// process) is writing: `staging` is its [`OmeZarrWriter::staging_path`]. `region` must be
/// one of the writer's chunk boxes and `data` its voxels in the store's voxel type.
///
/// # Errors
/// [`VolumeError::Format`] if `staging` holds no level-0 array or storing fails;
/// [`VolumeError::InvalidArgument`] for a box that is not a chunk or data of another voxel
/// type or size.
pub fn store_chunk(staging: &Path, region: IndexBox, data: &AnyVolume) -> Result<(), VolumeError> {
    let go = || -> Result<(), VolumeError> {
        let store =
            Arc::new(FilesystemStore::new(staging).map_err(|e| zerr("cannot open the store", e))?);
        let array = Array::open(store, "/0").map_err(|e| zerr("array 0", e))?;
        let vt = voxel_type_of(array.data_type());
        if vt != Some(data.voxel_type()) {
            return Err(VolumeError::InvalidArgument(format!(
                "chunk voxels are {}, the store holds {}",
                data.voxel_type().name(),
                array.data_type()
            )));
        }
        let shape = array.shape();
        let cs = array
            .chunk_shape(&[0, 0, 0])
            .map_err(|e| zerr("chunk grid of array 0", e))?;
        if shape.len() != 3 || cs.len() != 3 {
            return Err(fmt_err("array 0 is not 3-D"));
        }
        let dims = [shape[2] as usize, shape[1] as usize, shape[0] as usize];
        let chunk = [
            cs[2].get() as usize,
            cs[1].get() as usize,
            cs[0].get() as usize,
        ];
        write_level_chunk(&array, chunk, dims, region, data)
    };
    go().map_err(|e| e.at(staging))
}

/// The chunk boxes of a grid of `dims` cut into `chunk`-sized pieces (x fastest).
#[must_use]
pub fn chunk_boxes(dims: [usize; 3], chunk: [usize; 3]) -> Vec<IndexBox> {
    let mut out = Vec::new();
    for z in (0..dims[2]).step_by(chunk[2].max(1)) {
        for y in (0..dims[1]).step_by(chunk[1].max(1)) {
            for x in (0..dims[0]).step_by(chunk[0].max(1)) {
                out.push(IndexBox {
                    start: [x, y, z],
                    end: [
                        (x + chunk[0]).min(dims[0]),
                        (y + chunk[1]).min(dims[1]),
                        (z + chunk[2]).min(dims[2]),
                    ],
                });
            }
        }
    }
    out
}

fn read_array_box(
    array: &Array<FilesystemStore>,
    voxel_type: VoxelType,
    b: IndexBox,
) -> Result<AnyVolume, VolumeError> {
    let dims = [0, 1, 2].map(|a| b.end[a] - b.start[a]);
    let subset = ArraySubset::new_with_ranges(&[
        b.start[2] as u64..b.end[2] as u64,
        b.start[1] as u64..b.end[1] as u64,
        b.start[0] as u64..b.end[0] as u64,
    ]);
    volmorph_volume::with_voxel_type!(voxel_type, T => {
        let data: Vec<T> = read_subset::<T>(array, &subset)?;
        Volume::new(Geometry::new(dims), data).map(AnyVolume::from)
    })
}

/// 2×2×2 mean of `src` (a level's region starting at twice `dst`'s start) onto `dst`.
fn downsample(src: &AnyVolume, dst: IndexBox) -> AnyVolume {
    volmorph_volume::with_volume!(src, v => AnyVolume::from(downsample_typed(v, dst)))
}

fn downsample_typed<T: Voxel>(v: &Volume<T>, dst: IndexBox) -> Volume<T> {
    let dd = [0, 1, 2].map(|a| dst.end[a] - dst.start[a]);
    let sd = v.dims();
    let d = v.data();
    let mut out: Vec<T> = Vec::with_capacity(dd[0] * dd[1] * dd[2]);
    for k in 0..dd[2] {
        for j in 0..dd[1] {
            for i in 0..dd[0] {
                let (mut sum, mut n) = (0.0f64, 0u32);
                for z in 2 * k..(2 * k + 2).min(sd[2]) {
                    for y in 2 * j..(2 * j + 2).min(sd[1]) {
                        for x in 2 * i..(2 * i + 2).min(sd[0]) {
                            sum += d[x + sd[0] * (y + sd[1] * z)].to_f64();
                            n += 1;
                        }
                    }
                }
                out.push(T::from_f64(sum / f64::from(n.max(1))));
            }
        }
    }
    Volume::new(Geometry::new(dd), out).expect("one value per voxel")
}

fn write_level_chunk(
    array: &Array<FilesystemStore>,
    chunk: [usize; 3],
    dims: [usize; 3],
    region: IndexBox,
    data: &AnyVolume,
) -> Result<(), VolumeError> {
    let ok = (0..3).all(|a| {
        region.start[a].is_multiple_of(chunk[a])
            && region.end[a] == (region.start[a] + chunk[a]).min(dims[a])
    });
    if !ok || data.geometry().dims != [0, 1, 2].map(|a| region.end[a] - region.start[a]) {
        return Err(VolumeError::InvalidArgument(format!(
            "box {:?}..{:?} with {:?} voxels is not a chunk of the store (chunk {chunk:?}, dims {dims:?})",
            region.start,
            region.end,
            data.geometry().dims
        )));
    }
    let idx = [
        (region.start[2] / chunk[2]) as u64,
        (region.start[1] / chunk[1]) as u64,
        (region.start[0] / chunk[0]) as u64,
    ];
    let res = volmorph_volume::with_volume!(data, v => {
        let d = v.dims();
        if d == chunk {
            array.store_chunk(&idx, v.data())
        } else {
            // Zarr chunks at the far edges keep the full chunk shape: pad with the fill value.
            array.store_chunk(&idx, padded(v.data(), d, chunk))
        }
    });
    res.map_err(|e| zerr("writing a chunk", e))
}

/// `data` (`dims` voxels, x fastest) in the corner of a zero-filled block of `chunk` voxels.
fn padded<T: Voxel>(data: &[T], dims: [usize; 3], chunk: [usize; 3]) -> Vec<T> {
    let mut out = vec![T::default(); chunk[0] * chunk[1] * chunk[2]];
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            let src = dims[0] * (y + dims[1] * z);
            let dst = chunk[0] * (y + chunk[1] * z);
            out[dst..dst + dims[0]].copy_from_slice(&data[src..src + dims[0]]);
        }
    }
    out
}

/// Write `volume` as an OME-Zarr store with a pyramid (see the [module docs](self)).
///
/// # Errors
/// As [`OmeZarrWriter::create`], [`OmeZarrWriter::write_chunk`] and
/// [`OmeZarrWriter::finish`].
pub fn write(
    path: &Path,
    volume: &AnyVolume,
    options: &ZarrWriteOptions,
) -> Result<(), VolumeError> {
    let w = OmeZarrWriter::create(path, volume.geometry(), volume.voxel_type(), options)?;
    w.chunk_boxes()
        .into_par_iter()
        .try_for_each(|b| {
            let piece = crop(volume, b);
            w.write_chunk(b, &piece)
        })
        .map_err(|e| e.at(path))?;
    w.finish()
}

/// The voxels of `b` (inside `volume`) as a volume on the box's own grid.
fn crop(volume: &AnyVolume, b: IndexBox) -> AnyVolume {
    let dd = [0, 1, 2].map(|a| b.end[a] - b.start[a]);
    let g = volume.geometry();
    let geometry = Geometry {
        dims: dd,
        origin: g.index_to_physical(DVec3::new(
            b.start[0] as f64,
            b.start[1] as f64,
            b.start[2] as f64,
        )),
        ..*g
    };
    volmorph_volume::with_volume!(volume, v => {
        let [nx, ny, _] = v.dims();
        let d = v.data();
        let mut out = Vec::with_capacity(dd[0] * dd[1] * dd[2]);
        for z in b.start[2]..b.end[2] {
            for y in b.start[1]..b.end[1] {
                let row = nx * (y + ny * z);
                out.extend_from_slice(&d[row + b.start[0]..row + b.end[0]]);
            }
        }
        AnyVolume::from(Volume::new(geometry, out).expect("length matches dims"))
    })
}
