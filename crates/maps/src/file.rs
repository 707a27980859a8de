//! Map files, by extension: `.json` (the map JSON of [`crate::json`], which includes the
//! lattice JSON), `.tfm` / `.txt` (ITK text transforms, [`crate::itk`]; a `.txt` whose first
//! entry is an elastix `(Name value …)` line is an elastix transform parameter file,
//! [`crate::elastix`]), `.mat` (ITK/ANTs MATLAB transforms, [`crate::itk_mat`]), `.bxf`
//! (plastimatch B-spline lattices) and `.nii`, `.nii.gz`, `.mha`, `.mhd` (ITK displacement
//! fields, [`crate::field`]).

use std::path::Path;

use volmorph_lattice::formats::bxf;
use volmorph_volume::VolumeError;

use crate::field::DisplacementField;
use crate::{AnyMap, MapError, elastix, itk, itk_mat};

/// Largest map file read, in bytes (1 GiB of text: a 2²⁵-node sampled map). Checked against
/// the file's size before reading it.
pub const MAX_MAP_FILE_BYTES: u64 = 1 << 30;

/// The extensions [`write_map`] writes (without the dot): map JSON, ITK text transforms,
/// plastimatch, ITK/ANTs MATLAB and displacement fields ([`MapFormat::of`]).
pub const WRITE_EXTENSIONS: &[&str] = &[
    "json", "tfm", "txt", "bxf", "mat", "nii", "nii.gz", "mha", "mhd",
];

/// The extensions of displacement fields [`write_field`] writes (without the dot).
pub const FIELD_EXTENSIONS: &[&str] = &["nii", "nii.gz", "mha", "mhd"];

/// Check that `path` ends in an extension [`write_map`] writes ([`WRITE_EXTENSIONS`]),
/// before anything is read or written.
///
/// # Errors
/// [`MapError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the extension
/// found and the accepted ones.
pub fn check_output(path: &Path) -> Result<(), MapError> {
    Ok(volmorph_io::extension::check(path, WRITE_EXTENSIONS)?)
}

/// Check that `path` ends in an extension [`write_field`] writes ([`FIELD_EXTENSIONS`]),
/// before anything is read or sampled.
///
/// # Errors
/// [`MapError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the extension
/// found and [`FIELD_EXTENSIONS`].
pub fn check_field_output(path: &Path) -> Result<(), MapError> {
    Ok(volmorph_io::extension::check(path, FIELD_EXTENSIONS)?)
}

/// A map file format, chosen by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapFormat {
    /// volmorph map JSON (`.json`).
    Json,
    /// ITK text transform (`.tfm`, `.txt`).
    ItkTfm,
    /// plastimatch B-spline (`.bxf`).
    Bxf,
    /// ITK MATLAB transform, as ANTs writes affine transforms (`.mat`).
    ItkMat,
    /// elastix transform parameter file (`.txt` starting with a `(Name value …)` entry; read
    /// only).
    Elastix,
    /// ITK displacement field: a 3-component vector image (`.nii`, `.nii.gz`, `.mha`,
    /// `.mhd`).
    DisplacementField,
}

impl MapFormat {
    /// The format of `path`, by its extension (case-insensitive). A `.txt` file is an ITK
    /// transform here; [`read_map`] tells an elastix parameter file by its content.
    ///
    /// # Errors
    /// [`MapError::Unsupported`] for another extension, naming the ones known.
    pub fn of(path: &Path) -> Result<Self, MapError> {
        let name = path
            .file_name()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if [".nii", ".nii.gz", ".mha", ".mhd"]
            .iter()
            .any(|e| name.ends_with(e))
        {
            return Ok(Self::DisplacementField);
        }
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "json" => Ok(Self::Json),
            "tfm" | "txt" => Ok(Self::ItkTfm),
            "bxf" => Ok(Self::Bxf),
            "mat" => Ok(Self::ItkMat),
            "h5" | "hdf5" => Err(MapError::Unsupported(format!(
                "{}: HDF5 ITK transform files (.{ext}) are not read; save the transform as \
                 text (.tfm) or MATLAB (.mat)",
                path.display()
            ))),
            _ => Err(MapError::Unsupported(format!(
                "{}: unknown map file extension; use .json, .tfm, .txt (ITK or elastix), .mat, \
                 .bxf, or a displacement field .nii, .nii.gz, .mha, .mhd",
                path.display()
            ))),
        }
    }
}

/// Read the whole file at `path`, refusing files over `max` bytes before reading.
fn read_bytes(path: &Path, max: u64) -> Result<Vec<u8>, MapError> {
    let os = |e| volmorph_io::IoError::os(path, e);
    let meta = std::fs::metadata(path).map_err(os)?;
    if !meta.is_file() {
        return Err(MapError::Invalid(format!(
            "{} is not a regular file",
            path.display()
        )));
    }
    if meta.len() > max {
        return Err(MapError::Invalid(format!(
            "{} is {} bytes, more than the {max} bytes a map file of this kind may have",
            path.display(),
            meta.len()
        )));
    }
    Ok(std::fs::read(path).map_err(os)?)
}

/// Read the whole text file at `path`, refusing files over [`MAX_MAP_FILE_BYTES`] before
/// reading.
pub(crate) fn read_text(path: &Path) -> Result<String, MapError> {
    let bytes = read_bytes(path, MAX_MAP_FILE_BYTES)?;
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
            MapFormat::ItkTfm | MapFormat::Elastix => {
                let text = read_text(path)?;
                if elastix::looks_like_elastix(&text) {
                    elastix::read_elastix(path, &text)
                } else {
                    itk::parse_tfm(&text)
                }
            }
            MapFormat::Bxf => Ok(AnyMap::Lattice(bxf::parse_bxf(&read_text(path)?)?)),
            MapFormat::ItkMat => {
                let bytes = read_bytes(path, MAX_MAT_FILE_BYTES)?;
                itk_mat::parse_mat(&bytes)
            }
            MapFormat::DisplacementField => {
                let (image, _) =
                    volmorph_volume_io::vector::read_vector(path).map_err(volume_error)?;
                Ok(AnyMap::DisplacementField(DisplacementField::from_image(
                    image,
                )?))
            }
        }
    };
    read().map_err(|e| e.at(path))
}

/// Largest `.mat` transform file read, in bytes (a MATLAB file of a few parameter vectors).
pub const MAX_MAT_FILE_BYTES: u64 = 1 << 20;

/// Write the displacement field of `map` on `grid` (`d(x) = map(x) − x` at every node, see
/// [`DisplacementField::from_map`]) as an ITK vector image at `path` (`.nii`, `.nii.gz`,
/// `.mha`, `.mhd`) of `precision`; returns the field written.
///
/// # Errors
/// [`MapError::Io`] with [`volmorph_io::IoError::Extension`] for another extension
/// ([`check_field_output`], nothing sampled or written); the sampling errors of
/// [`DisplacementField::from_map`]; I/O errors; every error names `path`.
pub fn write_field(
    path: &Path,
    map: &AnyMap,
    grid: volmorph_volume::Geometry,
    precision: volmorph_volume_io::vector::VectorPrecision,
) -> Result<DisplacementField, MapError> {
    // The extension's error names `path` itself.
    check_field_output(path)?;
    let write = || -> Result<DisplacementField, MapError> {
        let field = DisplacementField::from_map(map, grid)?;
        write_field_image(path, &field, precision)?;
        Ok(field)
    };
    write().map_err(|e| e.at(path))
}

/// A volume error as a map error: [`VolumeError::Unsupported`] as
/// [`MapError::Unsupported`] (one "unsupported:" in the message, not two), the others as
/// [`MapError::Invalid`].
fn volume_error(e: VolumeError) -> MapError {
    match e {
        VolumeError::Unsupported(m) => MapError::Unsupported(m),
        e => MapError::Invalid(e.to_string()),
    }
}

fn write_field_image(
    path: &Path,
    field: &DisplacementField,
    precision: volmorph_volume_io::vector::VectorPrecision,
) -> Result<(), MapError> {
    volmorph_volume_io::vector::write_vector(
        path,
        &field.to_image(),
        precision,
        &volmorph_volume_io::WriteOptions::default(),
    )
    .map_err(volume_error)
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
        MapFormat::ItkMat | MapFormat::Elastix | MapFormat::DisplacementField => {
            Err(MapError::Unsupported(
                "this format is not text written by map_to_string (see write_map)".into(),
            ))
        }
    }
}

/// Write a map file atomically; the format follows the extension ([`MapFormat::of`]).
///
/// # Errors
/// As [`map_to_string`], and I/O errors, as [`MapError::File`] naming `path`.
pub fn write_map(path: &Path, map: &AnyMap) -> Result<(), MapError> {
    check_output(path)?;
    let write = || -> Result<(), MapError> {
        let format = MapFormat::of(path)?;
        match (format, map) {
            (MapFormat::DisplacementField, AnyMap::DisplacementField(f)) => {
                return write_field_image(
                    path,
                    f,
                    volmorph_volume_io::vector::VectorPrecision::F64,
                );
            }
            (MapFormat::DisplacementField, other) => {
                return Err(MapError::Unsupported(format!(
                    "a {} map has no grid of its own: sample it as a displacement field on a \
                     reference grid (volmorph map field MAP --reference VOLUME -o FIELD)",
                    other.kind()
                )));
            }
            (MapFormat::ItkMat, m) => {
                let bytes = itk_mat::to_mat_bytes(m)?;
                return volmorph_io::write_atomic(path, |w| {
                    use std::io::Write;
                    w.write_all(&bytes)
                        .map_err(|e| MapError::Io(volmorph_io::IoError::os(path, e)))
                });
            }
            _ => {}
        }
        let text = map_to_string(map, format)?;
        volmorph_io::write_atomic(path, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes())
                .map_err(|e| MapError::Io(volmorph_io::IoError::os(path, e)))
        })
    };
    write().map_err(|e| e.at(path))
}
