//! Volume file formats, chosen by file extension.
//!
//! | extension | format | module |
//! | --- | --- | --- |
//! | `.nii`, `.nii.gz` | NIfTI-1 single file | [`nifti`] |
//! | `.mha`, `.mhd` (+ data file) | MetaImage | [`metaimage`] |
//! | `.nrrd`, `.nhdr` (+ data file) | NRRD | [`nrrd`] |
//! | `.vtk` | VTK legacy `STRUCTURED_POINTS` | [`vtk`] |
//! | `.raw` | headerless voxels, described by a [`raw::RawSpec`] | [`raw`] |
//!
//! Every reader returns the volume in volmorph's convention (see [`volmorph_volume::Geometry`]: ITK
//! physical space, x fastest) and refuses malformed input with a [`VolumeError`] — never a
//! panic, and never an allocation larger than the header's checked size. Every writer goes
//! through [`volmorph_io::write_atomic`], so a failed write leaves no partial file.
//!
//! ```
//! use volmorph_volume::{AnyVolume, DVec3};
//! use volmorph_volume_io as format;
//! use volmorph_volume::phantom::{self, Phantom};
//! use volmorph_volume::sample::{Boundary, Interpolation, Sampler};
//!
//! let dir = std::env::temp_dir().join(format!("volmorph-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let path = dir.join("sphere.mha");
//!
//! // A built-in model: u8 density, the object is where the value is at least 127.
//! let sphere = AnyVolume::from(phantom::density(Phantom::Sphere, [33, 33, 33])?);
//! format::write(&path, &sphere)?; // the format follows the extension
//! let back = format::read(&path)?;
//! // Voxels and geometry survive the round trip exactly. (NIfTI stores geometry in f32,
//! // so a `.nii.gz` would keep the voxels exactly and the geometry to f32 precision.)
//! assert!(back.as_bytes() == sphere.as_bytes() && back.geometry() == sphere.geometry());
//!
//! // Sample at physical points (model units here): inside the ball and far outside it.
//! let s = Sampler::from_any(&back, Interpolation::CubicBSpline, Boundary::Constant(0.0))?;
//! assert!((s.sample_physical(DVec3::ZERO) - 255.0).abs() < 1e-3);
//! assert_eq!(s.sample_physical(DVec3::splat(5.0)), 0.0);
//! std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod metaimage;
pub mod nifti;
pub mod nrrd;
pub mod raw;
mod text_header;
pub mod vtk;

use std::path::Path;

use volmorph_volume::{AnyVolume, VolumeError};

/// A volume file format, as chosen by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// NIfTI-1 (`.nii`, or gzip-compressed `.nii.gz`).
    Nifti,
    /// MetaImage with inline data (`.mha`) or a detached data file (`.mhd`).
    MetaImage,
    /// NRRD with inline data (`.nrrd`) or a detached data file (`.nhdr`).
    Nrrd,
    /// VTK legacy `STRUCTURED_POINTS` (`.vtk`).
    Vtk,
    /// Headerless raw voxels (`.raw`); reading needs a [`raw::RawSpec`].
    Raw,
}

impl Format {
    /// Choose the format from `path`'s extension (case-insensitive; `.nii.gz` counts as NIfTI).
    ///
    /// # Errors
    /// [`VolumeError::Unsupported`] for an unknown or missing extension.
    pub fn from_path(path: &Path) -> Result<Self, VolumeError> {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let fmt = if name.ends_with(".nii") || name.ends_with(".nii.gz") {
            Self::Nifti
        } else if name.ends_with(".mha") || name.ends_with(".mhd") {
            Self::MetaImage
        } else if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
            Self::Nrrd
        } else if name.ends_with(".vtk") {
            Self::Vtk
        } else if name.ends_with(".raw") {
            Self::Raw
        } else {
            return Err(VolumeError::Unsupported(format!(
                "cannot tell the volume format of {} from its extension \
                 (known: .nii .nii.gz .mha .mhd .nrrd .nhdr .vtk .raw)",
                path.display()
            )));
        };
        Ok(fmt)
    }

    /// Human-readable name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Nifti => "NIfTI-1",
            Self::MetaImage => "MetaImage",
            Self::Nrrd => "NRRD",
            Self::Vtk => "VTK legacy",
            Self::Raw => "raw",
        }
    }
}

/// Options for writers. Formats ignore options they have no use for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WriteOptions {
    /// Compress the voxel data where the format allows it (MetaImage `CompressedData`,
    /// NRRD `encoding: gzip`). NIfTI compression is chosen by the `.gz` extension instead.
    pub compress: bool,
    /// gzip/zlib level 0–9.
    pub level: u32,
}

impl Default for WriteOptions {
    fn default() -> Self {
        Self {
            compress: false,
            level: 6,
        }
    }
}

/// The header of a volume file as `(field, value)` pairs in file order, for display.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// Format-specific fields, e.g. `("sform_code", "1")` or `("ElementType", "MET_SHORT")`.
    pub fields: Vec<(String, String)>,
}

/// A volume together with the format and header it was read from.
#[derive(Debug, Clone, PartialEq)]
pub struct VolumeFile {
    /// The voxels and geometry.
    pub volume: AnyVolume,
    /// The format that was read.
    pub format: Format,
    /// The file's header fields.
    pub header: Header,
}

/// Read a volume; the format is chosen by extension.
///
/// # Errors
/// Any [`VolumeError`], carrying the file path. Reading a `.raw` file needs [`raw::read`]
/// with a [`raw::RawSpec`] and is refused here.
pub fn read(path: &Path) -> Result<AnyVolume, VolumeError> {
    read_with_header(path).map(|f| f.volume)
}

/// Read a volume and its header fields; the format is chosen by extension.
///
/// # Errors
/// As [`read`].
pub fn read_with_header(path: &Path) -> Result<VolumeFile, VolumeError> {
    let format = Format::from_path(path)?;
    let res = match format {
        Format::Nifti => nifti::read(path),
        Format::MetaImage => metaimage::read(path),
        Format::Nrrd => nrrd::read(path),
        Format::Vtk => vtk::read(path),
        Format::Raw => Err(VolumeError::Unsupported(
            "a .raw file has no header: give its dims and voxel type (raw::RawSpec)".into(),
        )),
    };
    let (volume, header) = res.map_err(|e| e.at(path))?;
    Ok(VolumeFile {
        volume,
        format,
        header,
    })
}

/// Write a volume with default [`WriteOptions`]; the format is chosen by extension.
///
/// # Errors
/// As [`write_with`].
pub fn write(path: &Path, volume: &AnyVolume) -> Result<(), VolumeError> {
    write_with(path, volume, &WriteOptions::default())
}

/// Write a volume; the format is chosen by extension. The file appears only when complete.
///
/// # Errors
/// [`VolumeError::Unsupported`] for an unknown extension or a voxel type the format cannot
/// store; I/O errors carrying the path.
pub fn write_with(
    path: &Path,
    volume: &AnyVolume,
    options: &WriteOptions,
) -> Result<(), VolumeError> {
    let res = match Format::from_path(path)? {
        Format::Nifti => nifti::write(path, volume, options),
        Format::MetaImage => metaimage::write(path, volume, options),
        Format::Nrrd => nrrd::write(path, volume, options),
        Format::Vtk => vtk::write(path, volume, options),
        Format::Raw => raw::write(path, volume, options),
    };
    res.map_err(|e| e.at(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_from_extension() {
        for (p, f) in [
            ("a/b.nii", Format::Nifti),
            ("B.NII.GZ", Format::Nifti),
            ("x.mha", Format::MetaImage),
            ("x.mhd", Format::MetaImage),
            ("x.nrrd", Format::Nrrd),
            ("x.nhdr", Format::Nrrd),
            ("x.vtk", Format::Vtk),
            ("x.raw", Format::Raw),
        ] {
            assert_eq!(Format::from_path(Path::new(p)).unwrap(), f, "{p}");
        }
        assert!(Format::from_path(Path::new("x.png")).is_err());
        assert!(Format::from_path(Path::new("noext")).is_err());
    }
}
