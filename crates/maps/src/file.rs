//! Map files, by extension: `.json` (the map JSON of [`crate::json`], which includes the
//! lattice JSON), `.tfm` / `.txt` (ITK text transforms, [`crate::itk`]) and `.bxf`
//! (plastimatch B-spline lattices).

use std::path::Path;

use volmorph_lattice::formats::bxf;

use crate::{AnyMap, MapError, itk};

/// Largest map file read, in bytes (1 GiB of text: a 2²⁵-node sampled map). Checked against
/// the file's size before reading it.
pub const MAX_MAP_FILE_BYTES: u64 = 1 << 30;

/// A map file format, chosen by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapFormat {
    /// volmorph map JSON (`.json`).
    Json,
    /// ITK text transform (`.tfm`, `.txt`).
    ItkTfm,
    /// plastimatch B-spline (`.bxf`).
    Bxf,
}

impl MapFormat {
    /// The format of `path`, by its extension (case-insensitive).
    ///
    /// # Errors
    /// [`MapError::Unsupported`] for another extension, naming the ones known.
    pub fn of(path: &Path) -> Result<Self, MapError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "json" => Ok(Self::Json),
            "tfm" | "txt" => Ok(Self::ItkTfm),
            "bxf" => Ok(Self::Bxf),
            "h5" | "hdf5" | "mat" => Err(MapError::Unsupported(format!(
                "{}: binary ITK transform files (.{ext}) are not read; save the transform as \
                 text (.tfm)",
                path.display()
            ))),
            _ => Err(MapError::Unsupported(format!(
                "{}: unknown map file extension; use .json, .tfm, .txt or .bxf",
                path.display()
            ))),
        }
    }
}

/// Read the whole text file at `path`, refusing files over [`MAX_MAP_FILE_BYTES`] before
/// reading.
fn read_text(path: &Path) -> Result<String, MapError> {
    let os = |e| volmorph_io::IoError::os(path, e);
    let meta = std::fs::metadata(path).map_err(os)?;
    if !meta.is_file() {
        return Err(MapError::Invalid(format!(
            "{} is not a regular file",
            path.display()
        )));
    }
    if meta.len() > MAX_MAP_FILE_BYTES {
        return Err(MapError::Invalid(format!(
            "{} is {} bytes, more than the {MAX_MAP_FILE_BYTES} bytes a map file may have",
            path.display(),
            meta.len()
        )));
    }
    let bytes = std::fs::read(path).map_err(os)?;
    String::from_utf8(bytes).map_err(|e| {
        MapError::Invalid(format!(
            "{} is not UTF-8 text (invalid byte at offset {})",
            path.display(),
            e.utf8_error().valid_up_to()
        ))
    })
}

/// Read a map file; the format follows the extension ([`MapFormat::of`]).
///
/// # Errors
/// The error of the format's reader, as [`MapError::File`] naming `path`.
pub fn read_map(path: &Path) -> Result<AnyMap, MapError> {
    let read = || -> Result<AnyMap, MapError> {
        match MapFormat::of(path)? {
            MapFormat::Json => AnyMap::from_json(&read_text(path)?),
            MapFormat::ItkTfm => itk::parse_tfm(&read_text(path)?),
            MapFormat::Bxf => Ok(AnyMap::Lattice(bxf::parse_bxf(&read_text(path)?)?)),
        }
    };
    read().map_err(|e| e.at(path))
}

/// The text of `map` in `format`.
///
/// # Errors
/// [`MapError::Unsupported`] if the format cannot hold the map (ITK and plastimatch hold only
/// some kinds).
pub fn map_to_string(map: &AnyMap, format: MapFormat) -> Result<String, MapError> {
    match format {
        MapFormat::Json => map.to_json(),
        MapFormat::ItkTfm => itk::to_tfm_string(map),
        MapFormat::Bxf => match map {
            AnyMap::Lattice(l) => Ok(bxf::bxf_to_string(l)?),
            other => Err(MapError::Unsupported(format!(
                "plastimatch .bxf holds B-spline lattices only, not a {} map",
                other.kind()
            ))),
        },
    }
}

/// Write a map file atomically; the format follows the extension ([`MapFormat::of`]).
///
/// # Errors
/// As [`map_to_string`], and I/O errors, as [`MapError::File`] naming `path`.
pub fn write_map(path: &Path, map: &AnyMap) -> Result<(), MapError> {
    let write = || -> Result<(), MapError> {
        let text = map_to_string(map, MapFormat::of(path)?)?;
        volmorph_io::write_atomic(path, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes())
                .map_err(|e| MapError::Io(volmorph_io::IoError::os(path, e)))
        })
    };
    write().map_err(|e| e.at(path))
}
