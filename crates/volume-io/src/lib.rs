//! Volume file formats, chosen by file extension.
//!
//! | extension | format | module |
//! | --- | --- | --- |
//! | `.nii`, `.nii.gz` | NIfTI-1 single file | [`nifti`] |
//! | `.mha`, `.mhd` (+ data file) | MetaImage | [`metaimage`] |
//! | `.nrrd`, `.nhdr` (+ data file) | NRRD | [`nrrd`] |
//! | `.vtk` | VTK legacy `STRUCTURED_POINTS` (axis-aligned only) | [`vtk`] |
//! | `.vti` | VTK XML image data (with direction, VTK ≥ 9) | [`vti`] |
//! | `.mgh`, `.mgz` | FreeSurfer MGH (4-D: one frame at a time) | [`mgh`] |
//! | a folder, `.dcm`, `.dicom`, `.ima` (or the `DICM` preamble) | DICOM series and multi-frame files (read only) | [`dicom`] |
//! | a `.ome.zarr` (or `.zarr`) folder | OME-Zarr: NGFF v0.4 on Zarr v2, v0.5 on Zarr v3, pyramids, box reads | [`omezarr`] |
//! | `.raw` | headerless voxels, described by a [`raw::RawSpec`] | [`raw`] |
//!
//! Vector images with three components per voxel (displacement fields: NIfTI with
//! `intent_code` 1007 and `dim[5] = 3`, MetaImage with `ElementNumberOfChannels = 3`) are read
//! and written by [`vector`]; the volume readers refuse them by name.
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

pub mod dicom;
pub mod metaimage;
pub mod mgh;
pub mod nifti;
pub mod nrrd;
pub mod omezarr;
pub mod raw;
mod text_header;
pub mod vector;
pub mod vti;
pub mod vtk;

use std::path::Path;

use volmorph_volume::direction::snap_direction;
use volmorph_volume::{AnyVolume, Geometry, VolumeError, VoxelType};

/// Every volume extension volmorph knows (without the dot) and its format; compared with
/// the end of a file name case-insensitively, the longest match first
/// ([`volmorph_io::extension::matching`]).
pub const EXTENSIONS: [(&str, Format); 16] = [
    ("nii", Format::Nifti),
    ("nii.gz", Format::Nifti),
    ("mha", Format::MetaImage),
    ("mhd", Format::MetaImage),
    ("nrrd", Format::Nrrd),
    ("nhdr", Format::Nrrd),
    ("vtk", Format::Vtk),
    ("vti", Format::Vti),
    ("mgh", Format::Mgh),
    ("mgz", Format::Mgh),
    ("dcm", Format::Dicom),
    ("dicom", Format::Dicom),
    ("ima", Format::Dicom),
    ("raw", Format::Raw),
    ("ome.zarr", Format::OmeZarr),
    ("zarr", Format::OmeZarr),
];

/// The extensions of the volume formats volmorph writes ([`Format::for_output`]): every
/// format of [`EXTENSIONS`] but DICOM.
pub const WRITE_EXTENSIONS: &[&str] = &[
    "nii", "nii.gz", "mha", "mhd", "nrrd", "nhdr", "vtk", "vti", "mgh", "mgz", "raw", "ome.zarr",
    "zarr",
];

/// Check that `path` names a volume format volmorph writes, before reading or writing
/// anything ([`Format::for_output`]).
///
/// # Errors
/// As [`Format::for_output`].
pub fn check_output(path: &Path) -> Result<(), VolumeError> {
    Format::for_output(path).map(|_| ())
}

/// The error for a DICOM output: the extension error `refused` with the reason volmorph
/// writes no DICOM.
fn dicom_output_refused(refused: &volmorph_io::IoError) -> VolumeError {
    VolumeError::Unsupported(format!(
        "{refused} (volmorph reads DICOM but does not write it: a DICOM file needs patient \
         and study identity that a volume does not carry)"
    ))
}

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
    /// VTK XML image data (`.vti`), with a direction matrix.
    Vti,
    /// FreeSurfer MGH (`.mgh`, or gzip-compressed `.mgz`).
    Mgh,
    /// DICOM: a folder holding a series, one file of a series (`.dcm`, `.dicom`, `.ima`, or
    /// any name with the `DICM` preamble), or a multi-frame file. Read only.
    Dicom,
    /// Headerless raw voxels (`.raw`); reading needs a [`raw::RawSpec`].
    Raw,
    /// OME-Zarr (a `.ome.zarr` or `.zarr` folder): see [`omezarr`].
    OmeZarr,
}

impl Format {
    /// Choose the format from `path`'s extension (case-insensitive; `.nii.gz` counts as NIfTI);
    /// an existing folder is a DICOM series.
    ///
    /// # Errors
    /// [`VolumeError::Unsupported`] for an unknown or missing extension.
    pub fn from_path(path: &Path) -> Result<Self, VolumeError> {
        if omezarr::is_ome_zarr_path(path) {
            return Ok(Self::OmeZarr);
        }
        if path.is_dir() {
            return Ok(Self::Dicom);
        }
        Self::by_name(path, &EXTENSIONS.map(|(e, _)| e)).ok_or_else(|| {
            VolumeError::Unsupported(format!(
                "cannot tell the volume format of {} from its extension \
                 (known: .nii .nii.gz .mha .mhd .nrrd .nhdr .vtk .vti .mgh .mgz .raw .ome.zarr, DICOM .dcm files or \
                 a folder of them)",
                path.display()
            ))
        })
    }

    /// The format of the entry of [`EXTENSIONS`] that `path`'s file name ends in, looking only
    /// at the extensions `among` (the longest match; by name only).
    fn by_name(path: &Path, among: &[&str]) -> Option<Self> {
        let ext = volmorph_io::extension::matching(path, among)?;
        EXTENSIONS.iter().find(|(e, _)| *e == ext).map(|(_, f)| *f)
    }

    /// The format an output path names, checked before anything is read or written (the
    /// front-ends call it up front, [`write_with`] first thing): one of [`WRITE_EXTENSIONS`],
    /// by name only (an existing folder at `path` is not taken for a DICOM series).
    ///
    /// # Errors
    /// [`VolumeError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
    /// extension found and [`WRITE_EXTENSIONS`]; [`VolumeError::Unsupported`] with the same
    /// words and the reason for a DICOM extension (DICOM is read, not written).
    pub fn for_output(path: &Path) -> Result<Self, VolumeError> {
        if let Some(format) = Self::by_name(path, WRITE_EXTENSIONS) {
            return Ok(format);
        }
        let refused = volmorph_io::extension::refused(path, WRITE_EXTENSIONS);
        Err(match Self::by_name(path, &EXTENSIONS.map(|(e, _)| e)) {
            Some(Self::Dicom) => dicom_output_refused(&refused),
            _ => refused.into(),
        })
    }

    /// Human-readable name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Nifti => "NIfTI-1",
            Self::MetaImage => "MetaImage",
            Self::Nrrd => "NRRD",
            Self::Vtk => "VTK legacy",
            Self::Vti => "VTK XML image data",
            Self::Mgh => "FreeSurfer MGH",
            Self::Dicom => "DICOM",
            Self::Raw => "raw",
            Self::OmeZarr => omezarr::FORMAT,
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

/// Options for readers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadOptions {
    /// Accept a detached data file (MetaImage `ElementDataFile`, NRRD `data file`) that
    /// resolves, after symbolic links, outside the header's folder. Off by default: a header
    /// from an untrusted source could otherwise make volmorph read any file the user can
    /// read (and, through `convert`, copy it). The default of [`ReadOptions::default`] can
    /// be changed for the whole process with [`set_allow_external_data_default`].
    pub allow_external_data: bool,
    /// The 3-D frame to read from a 4-D file (0-based). `None` reads files with a single frame
    /// and refuses a file with more, naming how many it holds, so a time series is never
    /// silently cut to its first volume. Files with one frame accept `Some(0)`.
    pub frame: Option<usize>,
    /// The frame to read from a file holding several when [`ReadOptions::frame`] is `None`:
    /// the command line's global `--frame N`, applied to every volume a command reads. A file
    /// with a single frame is read as it is (so a 3-D reference grid beside a 4-D series
    /// needs nothing); a file with several but not this one is refused. `None` (the default,
    /// unless changed for the process with [`set_frame_default`]) refuses files with several
    /// frames, as [`ReadOptions::frame`] does.
    pub default_frame: Option<usize>,
}

static ALLOW_EXTERNAL_DEFAULT: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// Set the value of [`ReadOptions::allow_external_data`] in [`ReadOptions::default`] (and so
/// in [`read`]) for the rest of the process: the command line's `--allow-external-data`.
pub fn set_allow_external_data_default(allow: bool) {
    ALLOW_EXTERNAL_DEFAULT.store(allow, std::sync::atomic::Ordering::Relaxed);
}

/// No process-wide frame (see [`set_frame_default`]).
const NO_FRAME: usize = usize::MAX;

static FRAME_DEFAULT: std::sync::atomic::AtomicUsize =
    std::sync::atomic::AtomicUsize::new(NO_FRAME);

/// Set [`ReadOptions::default_frame`] in [`ReadOptions::default`] (and so in [`read`], the
/// read of every command, the scene's imports and the registration pipeline) for the rest of
/// the process: the command line's global `--frame N`.
pub fn set_frame_default(frame: Option<usize>) {
    FRAME_DEFAULT.store(
        frame.unwrap_or(NO_FRAME),
        std::sync::atomic::Ordering::Relaxed,
    );
}

/// The frame set by [`set_frame_default`], if any.
#[must_use]
pub fn frame_default() -> Option<usize> {
    let f = FRAME_DEFAULT.load(std::sync::atomic::Ordering::Relaxed);
    (f != NO_FRAME).then_some(f)
}

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            allow_external_data: ALLOW_EXTERNAL_DEFAULT.load(std::sync::atomic::Ordering::Relaxed),
            frame: None,
            default_frame: frame_default(),
        }
    }
}

/// Which 3-D frame of a file a reader returns (from [`ReadOptions::frame`] and
/// [`ReadOptions::default_frame`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FrameChoice {
    /// The file must hold a single frame; a file with several is refused, naming how many.
    #[default]
    Single,
    /// This frame; a file that does not hold it is refused.
    Exactly(usize),
    /// This frame of a file holding several; a file with a single frame is read as it is.
    OfSeries(usize),
}

impl FrameChoice {
    /// The choice [`read_with`] makes for `options`.
    #[must_use]
    pub fn of(options: &ReadOptions) -> Self {
        match (options.frame, options.default_frame) {
            (Some(f), _) => Self::Exactly(f),
            (None, Some(f)) => Self::OfSeries(f),
            (None, None) => Self::Single,
        }
    }
}

impl From<Option<usize>> for FrameChoice {
    /// `Some(f)` is [`FrameChoice::Exactly`], `None` is [`FrameChoice::Single`].
    fn from(frame: Option<usize>) -> Self {
        frame.map_or(Self::Single, Self::Exactly)
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
    /// The voxels and geometry (of the frame that was read).
    pub volume: AnyVolume,
    /// The format that was read.
    pub format: Format,
    /// The file's header fields.
    pub header: Header,
    /// Number of 3-D frames the file holds (a 4-D NIfTI's `dim[4]`; 1 for 3-D files).
    pub frames: usize,
    /// The frame that was read (`0 ≤ frame < frames`).
    pub frame: usize,
}

/// What a volume file holds, without its voxels: format, voxel type, grid, header fields and
/// frames. Returned by [`describe_with`] and [`VolumeFile::description`].
#[derive(Debug, Clone, PartialEq)]
pub struct VolumeDescription {
    /// The format that was read.
    pub format: Format,
    /// The voxel type of the data.
    pub voxel_type: VoxelType,
    /// The grid (of the frame described), direction snapped as [`read_with`] snaps it.
    pub geometry: Geometry,
    /// The file's header fields.
    pub header: Header,
    /// Number of 3-D frames the file holds (1 for 3-D files).
    pub frames: usize,
    /// The frame described (`0 ≤ frame < frames`).
    pub frame: usize,
}

impl VolumeFile {
    /// The file's description (a copy of everything but the voxels).
    #[must_use]
    pub fn description(&self) -> VolumeDescription {
        VolumeDescription {
            format: self.format,
            voxel_type: self.volume.voxel_type(),
            geometry: *self.volume.geometry(),
            header: self.header.clone(),
            frames: self.frames,
            frame: self.frame,
        }
    }
}

/// Describe the volume file at `path` (format, voxel type, grid, header, frames) as
/// [`read_with`] would read it with `options`, reading as little as the format allows: an
/// OME-Zarr store's metadata only (no chunk is opened, whatever the image's size); the other
/// formats are read whole (their readers parse header and data together) and the voxels
/// dropped.
///
/// # Errors
/// As [`read_with`] for the other formats; for OME-Zarr as
/// [`omezarr::OmeZarrReader::open`] (malformed metadata, a missing level), with the path,
/// and [`VolumeError::InvalidArgument`] for a frame other than 0.
pub fn describe_with(path: &Path, options: &ReadOptions) -> Result<VolumeDescription, VolumeError> {
    if Format::from_path(path).ok() == Some(Format::OmeZarr) {
        let r = omezarr::OmeZarrReader::open(path)?;
        let frame = choose_frame(FrameChoice::of(options), 1).map_err(|e| e.at(path))?;
        let mut geometry = *r.geometry();
        geometry.direction = snap_direction(geometry.direction);
        return Ok(VolumeDescription {
            format: Format::OmeZarr,
            voxel_type: r.voxel_type(),
            geometry,
            header: r.header(),
            frames: 1,
            frame,
        });
    }
    read_with(path, options).map(|f| f.description())
}

/// The frame to read from a file holding `frames` 3-D frames (see [`FrameChoice`]).
///
/// # Errors
/// [`VolumeError::InvalidArgument`] for a frame past the end, or no frame for a file with
/// several.
pub(crate) fn choose_frame(
    choice: impl Into<FrameChoice>,
    frames: usize,
) -> Result<usize, VolumeError> {
    match choice.into() {
        FrameChoice::OfSeries(_) if frames <= 1 => Ok(0),
        FrameChoice::Exactly(f) | FrameChoice::OfSeries(f) if f < frames => Ok(f),
        FrameChoice::Exactly(f) | FrameChoice::OfSeries(f) => {
            Err(VolumeError::InvalidArgument(format!(
                "frame {f} does not exist: the file holds {frames} frame{} (0 to {})",
                if frames == 1 { "" } else { "s" },
                frames.saturating_sub(1)
            )))
        }
        FrameChoice::Single if frames > 1 => Err(VolumeError::InvalidArgument(format!(
            "this 4-D image holds {frames} frames; choose one with --frame N \
             (ReadOptions::frame), 0 to {}",
            frames - 1
        ))),
        FrameChoice::Single => Ok(0),
    }
}

/// Read a volume with default [`ReadOptions`]; the format is chosen by extension.
///
/// # Errors
/// Any [`VolumeError`], carrying the file path: a path that is not a regular file (a
/// folder, a FIFO, a device) is refused before reading, and so is a detached data file
/// outside the header's folder ([`VolumeError::ExternalData`]). Reading a `.raw` file
/// needs [`raw::read`] with a [`raw::RawSpec`] and is refused here; a 4-D file with more than one
/// frame needs [`read_with`] and [`ReadOptions::frame`].
pub fn read(path: &Path) -> Result<AnyVolume, VolumeError> {
    read_with(path, &ReadOptions::default()).map(|f| f.volume)
}

/// Read a volume and its header fields with default [`ReadOptions`].
///
/// # Errors
/// As [`read`].
pub fn read_with_header(path: &Path) -> Result<VolumeFile, VolumeError> {
    read_with(path, &ReadOptions::default())
}

/// Read a volume, its header fields and its frame count, with `options`; the format is chosen
/// by extension. This is the one read path of every command.
///
/// The direction matrix goes through [`volmorph_volume::direction::snap_direction`]: a
/// direction orthonormal within
/// [`DIRECTION_ORTHONORMAL_TOL`](volmorph_volume::direction::DIRECTION_ORTHONORMAL_TOL) (an
/// oblique scan stored in single precision) becomes exactly orthonormal (its polar factor,
/// at most about 1e-7 from what the file holds), a skewed one is kept as it is.
///
/// # Errors
/// As [`read`] (a detached data file outside the header's folder is accepted with
/// [`ReadOptions::allow_external_data`]); [`VolumeError::InvalidArgument`] for a frame the
/// file does not hold, or no frame for a file with several.
pub fn read_with(path: &Path, options: &ReadOptions) -> Result<VolumeFile, VolumeError> {
    let format = match Format::from_path(path) {
        // DICOM files often have no extension: recognise them by their preamble.
        Err(_) if dicom::has_dicom_magic(path) => Format::Dicom,
        f => f?,
    };
    let choice = FrameChoice::of(options);
    let single = |r: Result<(AnyVolume, Header), VolumeError>| {
        let (v, h) = r?;
        choose_frame(choice, 1)?;
        Ok((v, h, 1))
    };
    let res = match format {
        Format::Nifti => nifti::read(path, choice),
        Format::MetaImage => single(metaimage::read(path, options)),
        Format::Nrrd => single(nrrd::read(path, options)),
        Format::Vtk => single(vtk::read(path)),
        Format::Vti => single(vti::read(path)),
        Format::Mgh => mgh::read(path, choice),
        Format::Dicom => single(dicom::read(path)),
        Format::OmeZarr => single(omezarr::read(path)),
        Format::Raw => Err(VolumeError::Unsupported(
            "a .raw file has no header: give its dims and voxel type (raw::RawSpec)".into(),
        )),
    };
    let (mut volume, header, frames) = res.map_err(|e| e.at(path))?;
    let frame = choose_frame(choice, frames).map_err(|e| e.at(path))?;
    let mut g = *volume.geometry();
    g.direction = snap_direction(g.direction);
    volume.set_geometry(g).map_err(|e| e.at(path))?;
    Ok(VolumeFile {
        volume,
        format,
        header,
        frames,
        frame,
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
    let res = match Format::for_output(path)? {
        Format::Nifti => nifti::write(path, volume, options),
        Format::MetaImage => metaimage::write(path, volume, options),
        Format::Nrrd => nrrd::write(path, volume, options),
        Format::Vtk => vtk::write(path, volume, options),
        Format::Vti => vti::write(path, volume, options),
        Format::Mgh => mgh::write(path, volume, options),
        Format::Dicom => Err(dicom_output_refused(&volmorph_io::extension::refused(
            path,
            WRITE_EXTENSIONS,
        ))),
        Format::Raw => raw::write(path, volume, options),
        Format::OmeZarr => omezarr::write(
            path,
            volume,
            &omezarr::ZarrWriteOptions {
                compress: true,
                ..Default::default()
            },
        ),
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
            ("x.VTI", Format::Vti),
            ("brain.mgz", Format::Mgh),
            ("x.mgh", Format::Mgh),
            ("IM0001.DCM", Format::Dicom),
            ("x.raw", Format::Raw),
            ("cells.ome.zarr", Format::OmeZarr),
            ("cells.ZARR", Format::OmeZarr),
        ] {
            assert_eq!(Format::from_path(Path::new(p)).unwrap(), f, "{p}");
        }
        assert!(Format::from_path(Path::new("x.png")).is_err());
        assert!(Format::from_path(Path::new("noext")).is_err());
        // Outputs: by name only, DICOM refused, the error naming what is written.
        assert_eq!(
            Format::for_output(Path::new("o.NII.GZ")).unwrap(),
            Format::Nifti
        );
        assert_eq!(
            Format::for_output(Path::new("o.ome.zarr")).unwrap(),
            Format::OmeZarr
        );
        for bad in ["o.png", "o", "o.nii.bak"] {
            let e = check_output(Path::new(bad)).unwrap_err();
            assert!(
                matches!(e, VolumeError::Io(volmorph_io::IoError::Extension { .. })),
                "{bad}: {e}"
            );
            assert!(e.to_string().starts_with(bad), "{e}");
            assert!(e.to_string().contains(".nii.gz"), "{e}");
        }
        // The written extensions are the table's, DICOM's left out.
        let table: Vec<&str> = EXTENSIONS
            .iter()
            .filter(|(_, f)| *f != Format::Dicom)
            .map(|(e, _)| *e)
            .collect();
        assert_eq!(table, WRITE_EXTENSIONS);
        // DICOM: the same words, and why.
        for bad in ["o.dcm", "o.IMA", "o.dicom"] {
            let e = check_output(Path::new(bad)).unwrap_err().to_string();
            assert!(e.contains(&format!("{bad}: the extension")), "{e}");
            assert!(e.contains(".nii.gz") && e.contains("reads DICOM but does not write it"));
        }
    }
}
