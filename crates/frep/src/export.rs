//! Writing a field to the file a front-end names, with the kind of output chosen by the
//! file's extension: a polygon mesh of `f = 0`, a ray-cast picture, or the sampled defining
//! function as a volume; and animations, as one file or a folder of frames.
//!
//! Every front-end that lets a user name an output (`volmorph frep map`, `frep points`,
//! `frep sections`, the Python package) goes through [`export_with`] and
//! [`write_frames_with`], so the same path gives the same kind of file everywhere, and the
//! summaries they print ([`Written`], [`Frames`]) read the same. Files are written
//! atomically by the underlying writers: a failed or cancelled call leaves no partial file.
//!
//! Conventions as everywhere in the crate: inside where `f ≥ 0`; bounds, grids and cameras
//! in the model's world coordinates.

use std::fmt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use glam::DVec3;
use volmorph_io::Progress;
use volmorph_mesh::{MeshFormat, MeshWriteOptions};
use volmorph_render::{AnimationFormat, Camera, RgbaImage, write_animation, write_png_rgba};
use volmorph_volume::{AnyVolume, Geometry, Volume};

use crate::error::FrepError;
use crate::field::Field;
use crate::grid::{isotropic_box_geometry, sample_with};
use crate::output::{
    MeshOptions, RenderOptions, SurfaceSummary, mesh_with, render_animation_with,
    render_frames_with, render_with,
};

/// Largest grid size per axis [`export_with`] samples on (a 2048³ `f32` volume is 32 GiB;
/// the memory budget is checked before allocating in any case).
pub const MAX_GRID: usize = 2048;

/// Largest number of frames [`write_frames_with`] renders.
pub const MAX_FRAMES: usize = 10_000;

/// What a single output file holds, by its extension ([`OutputKind::of`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputKind {
    /// A mesh of the surface `f = 0` (the extensions of [`MeshFormat`]: .obj, .ply, .stl,
    /// .off).
    Mesh,
    /// A ray-cast picture (.png).
    Picture,
    /// The sampled defining function (any volume format `volmorph_volume_io` writes; the
    /// writer refuses an extension it does not know).
    Volume,
}

impl OutputKind {
    /// The kind of file `path` names: a mesh format's extension, `.png` (any case) for a
    /// picture, anything else a volume.
    #[must_use]
    pub fn of(path: &Path) -> Self {
        if MeshFormat::from_path(path).is_ok() {
            Self::Mesh
        } else if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"))
        {
            Self::Picture
        } else {
            Self::Volume
        }
    }

    /// The extensions an F-rep output file may have ([`OutputKind::for_output`]): the mesh
    /// formats, `.png`, and the volume formats written.
    #[must_use]
    pub fn extensions() -> Vec<&'static str> {
        let mut all: Vec<&'static str> = volmorph_mesh::format::WRITE_EXTENSIONS.to_vec();
        all.extend_from_slice(volmorph_render::PNG_EXTENSIONS);
        all.extend_from_slice(volmorph_volume_io::WRITE_EXTENSIONS);
        all
    }

    /// The kind of output file `path` names, checked before anything is sampled or written:
    /// a mesh format's extension, `.png`, or a volume format volmorph writes.
    ///
    /// # Errors
    /// [`FrepError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
    /// extension found and [`OutputKind::extensions`].
    pub fn for_output(path: &Path) -> Result<Self, FrepError> {
        let kind = Self::of(path);
        let fits = match kind {
            Self::Mesh => volmorph_mesh::format::check_output(path).is_ok(),
            Self::Picture => true,
            Self::Volume => volmorph_volume_io::check_output(path).is_ok(),
        };
        if fits {
            Ok(kind)
        } else {
            Err(volmorph_io::extension::refused(path, &Self::extensions()).into())
        }
    }
}

/// How [`export_with`] samples, meshes and pictures a field.
#[derive(Debug, Clone)]
pub struct ExportOptions {
    /// The box `(lo, hi)` sampled, meshed or ray-cast (world units).
    pub bounds: (DVec3, DVec3),
    /// Voxel centres along the box's longest edge; the other axes keep the same step
    /// ([`isotropic_box_geometry`], at most [`MAX_GRID`]).
    pub grid: usize,
    /// Extractor and capping of a mesh.
    pub mesh: MeshOptions,
    /// Write a mesh as text (binary otherwise, where the format has both).
    pub ascii: bool,
    /// The camera of a picture.
    pub camera: Camera,
    /// Ray-casting options of a picture (its bounds are [`ExportOptions::bounds`]).
    pub render: RenderOptions,
}

/// What [`export_with`] wrote; its `Display` is the line a front-end reports.
#[derive(Debug, Clone, PartialEq)]
pub enum Written {
    /// A mesh extracted on a grid of `dims` samples.
    Mesh {
        /// Samples per axis.
        dims: [usize; 3],
        /// The mesh's size and closedness.
        surface: SurfaceSummary,
    },
    /// A picture.
    Picture(PictureSummary),
    /// A sampled volume.
    Volume(VolumeSummary),
}

impl fmt::Display for Written {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Mesh {
                dims: [nx, ny, nz],
                surface,
            } => write!(f, "{nx}×{ny}×{nz} grid: {surface}"),
            Self::Picture(p) => p.fmt(f),
            Self::Volume(v) => v.fmt(f),
        }
    }
}

impl Written {
    /// The warning a front-end prints when the output shows nothing of the model: a picture
    /// where no ray hit the solid, a mesh without a triangle (no surface `f = 0` in the box),
    /// a volume without a sample inside the solid. Names `bounds`, the box that was sampled
    /// or ray-cast, since the usual cause is a box that misses the model. `None` otherwise.
    ///
    /// Such an output is still written — an empty picture is the true picture of a box where
    /// the model is empty, and an animation may have empty frames — but never silently.
    #[must_use]
    pub fn empty_warning(&self, bounds: (DVec3, DVec3)) -> Option<String> {
        let what = match self {
            Self::Picture(p) if p.covered == 0.0 => {
                "no ray hit the solid: the picture shows only the background"
            }
            Self::Mesh { surface, .. } if surface.triangles == 0 => {
                "no surface f = 0 was found: the mesh is empty (the box lies wholly inside or \
                 wholly outside the solid)"
            }
            Self::Volume(v) if v.inside == 0 => "no sample is inside the solid (f ≥ 0)",
            _ => return None,
        };
        Some(format!(
            "{what}; the box {} misses the model or the model is empty there (frame it with \
             other bounds)",
            crate::extent::bounds_text(bounds)
        ))
    }
}

/// A ray-cast picture: its size, how much of it the model covers and how long casting took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PictureSummary {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Fraction (0 to 1) of the pixels that differ from the background.
    pub covered: f64,
    /// Casting time (writing excluded).
    pub elapsed: Duration,
}

impl PictureSummary {
    /// The summary of `img` cast with `options` in `elapsed`.
    #[must_use]
    pub fn of(img: &RgbaImage, options: &RenderOptions, elapsed: Duration) -> Self {
        let covered = img
            .pixels()
            .iter()
            .filter(|p| **p != options.background)
            .count();
        Self {
            width: img.width(),
            height: img.height(),
            covered: covered as f64 / img.pixels().len().max(1) as f64,
            elapsed,
        }
    }
}

impl fmt::Display for PictureSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}x{} picture in {:.2} s, the model covers {:.1} % of it",
            self.width,
            self.height,
            self.elapsed.as_secs_f64(),
            100.0 * self.covered
        )
    }
}

/// A sampled field: its grid, how many samples are inside (`f ≥ 0`) and how long sampling
/// took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeSummary {
    /// Samples per axis.
    pub dims: [usize; 3],
    /// Samples with `f ≥ 0`.
    pub inside: usize,
    /// Sampling time (writing excluded).
    pub elapsed: Duration,
}

impl VolumeSummary {
    /// The summary of `vol` sampled in `elapsed`.
    #[must_use]
    pub fn of(vol: &Volume<f32>, elapsed: Duration) -> Self {
        Self {
            dims: vol.geometry().dims,
            inside: vol.data().iter().filter(|v| **v >= 0.0).count(),
            elapsed,
        }
    }

    /// `N inside (P %)`.
    #[must_use]
    pub fn inside_text(&self) -> String {
        let total: usize = self.dims.iter().product();
        format!(
            "{} inside ({:.1} %)",
            self.inside,
            100.0 * self.inside as f64 / total.max(1) as f64
        )
    }
}

impl fmt::Display for VolumeSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [nx, ny, nz] = self.dims;
        write!(
            f,
            "{nx}×{ny}×{nz} samples in {:.1} ms, {}",
            self.elapsed.as_secs_f64() * 1e3,
            self.inside_text()
        )
    }
}

/// Sample `field` on `g` and write it as an `f32` volume to `path` (format by extension),
/// reporting the sampling to `progress`, then a stage "writing PATH" of unknown length.
/// Returns the volume's summary (the volume is moved into the writer, not copied).
///
/// # Errors
/// [`FrepError::Volume`] with [`volmorph_io::IoError::Extension`] for an extension no volume
/// writer takes, before anything is sampled; errors of [`sample_with`] (including
/// [`FrepError::Cancelled`]) and of the volume writer (the file system), naming `path`.
pub fn write_volume_with(
    field: &dyn Field,
    g: &Geometry,
    path: &Path,
    progress: &dyn Progress,
) -> Result<VolumeSummary, FrepError> {
    volmorph_volume_io::check_output(path)?;
    let t0 = Instant::now();
    let vol = sample_with(field, g, progress)?;
    let summary = VolumeSummary::of(&vol, t0.elapsed());
    progress.start(&format!("writing {}", path.display()), 0);
    progress.check()?;
    volmorph_volume_io::write(path, &AnyVolume::from(vol)).map_err(|e| in_file(path, e))?;
    Ok(summary)
}

/// Sample `field` on `g`, extract its surface ([`mesh_with`]) and write it to `path` (format
/// by extension; binary unless `ascii`), reporting to `progress`. Returns the mesh's
/// summary.
///
/// # Errors
/// [`FrepError::Mesh`] with [`volmorph_io::IoError::Extension`] for an extension no mesh
/// writer takes, before anything is sampled; errors of [`mesh_with`] (including
/// [`FrepError::Cancelled`]) and of the mesh writer, naming `path`.
pub fn write_mesh_with(
    field: &dyn Field,
    g: &Geometry,
    options: &MeshOptions,
    path: &Path,
    ascii: bool,
    progress: &dyn Progress,
) -> Result<SurfaceSummary, FrepError> {
    volmorph_mesh::format::check_output(path)?;
    let surface = mesh_with(field, g, options, progress)?;
    progress.start(&format!("writing {}", path.display()), 0);
    progress.check()?;
    let opts = MeshWriteOptions {
        binary: !ascii,
        ..MeshWriteOptions::default()
    };
    volmorph_mesh::write_with(path, &surface.mesh, &opts).map_err(|e| in_file(path, e))?;
    Ok(SurfaceSummary::of(&surface.mesh))
}

/// Ray-cast `field` ([`render_with`]) and write the picture to `path` as PNG, reporting to
/// `progress`. Returns the picture and its summary.
///
/// # Errors
/// [`FrepError::Render`] with [`volmorph_io::IoError::Extension`] for a path not ending in
/// `.png`, before anything is rendered; errors of [`render_with`] (including
/// [`FrepError::Cancelled`]) and of the PNG writer, naming `path`.
pub fn write_picture_with(
    field: &dyn Field,
    camera: &Camera,
    options: &RenderOptions,
    path: &Path,
    progress: &dyn Progress,
) -> Result<(RgbaImage, PictureSummary), FrepError> {
    volmorph_render::check_png(path)?;
    let t0 = Instant::now();
    let img = render_with(field, camera, options, progress)?;
    let summary = PictureSummary::of(&img, options, t0.elapsed());
    progress.start(&format!("writing {}", path.display()), 0);
    progress.check()?;
    write_png_rgba(path, &img).map_err(|e| in_file(path, e))?;
    Ok((img, summary))
}

/// Write `field` to `path` as its extension asks ([`OutputKind::of`]): a picture through
/// [`ExportOptions::camera`] restricted to the bounds, else a grid over the bounds
/// ([`isotropic_box_geometry`] with [`ExportOptions::grid`] samples along the longest edge)
/// meshed or written as a volume. Reports to `progress`.
///
/// # Errors
/// [`FrepError::Io`] with [`volmorph_io::IoError::Extension`] for an extension that names no
/// output kind ([`OutputKind::for_output`]), before anything is computed;
/// [`FrepError::InvalidArgument`] for a grid outside `2..=`[`MAX_GRID`] or an empty box;
/// errors of [`write_picture_with`], [`write_mesh_with`] and [`write_volume_with`].
pub fn export_with(
    field: &dyn Field,
    path: &Path,
    options: &ExportOptions,
    progress: &dyn Progress,
) -> Result<Written, FrepError> {
    let (lo, hi) = options.bounds;
    match OutputKind::for_output(path)? {
        OutputKind::Picture => {
            let render = RenderOptions {
                bounds_min: lo,
                bounds_max: hi,
                ..options.render
            };
            let (_, summary) = write_picture_with(field, &options.camera, &render, path, progress)?;
            Ok(Written::Picture(summary))
        }
        OutputKind::Mesh => {
            let g = isotropic_box_geometry(lo, hi, options.grid, MAX_GRID)?;
            let surface = write_mesh_with(field, &g, &options.mesh, path, options.ascii, progress)?;
            Ok(Written::Mesh {
                dims: g.dims,
                surface,
            })
        }
        OutputKind::Volume => {
            let g = isotropic_box_geometry(lo, hi, options.grid, MAX_GRID)?;
            let summary = write_volume_with(field, &g, path, progress)?;
            Ok(Written::Volume(summary))
        }
    }
}

/// What [`write_frames_with`] wrote; its `Display` is the line a front-end reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Frames {
    /// One animation file.
    File {
        /// Frames in it.
        count: usize,
        /// The file.
        path: PathBuf,
        /// Its format.
        format: AnimationFormat,
    },
    /// A folder of numbered PNG frames.
    Folder {
        /// The folder.
        dir: PathBuf,
        /// The frames in order.
        paths: Vec<PathBuf>,
    },
}

impl fmt::Display for Frames {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::File {
                count,
                path,
                format,
            } => write!(
                f,
                "{count} frames written to {} ({})",
                path.display(),
                format.description()
            ),
            Self::Folder { dir, paths } => {
                let name = |p: Option<&PathBuf>| p.map(|p| p.display().to_string());
                write!(
                    f,
                    "{} frames written to {} ({} … {})",
                    paths.len(),
                    dir.display(),
                    name(paths.first()).unwrap_or_default(),
                    name(paths.last()).unwrap_or_default()
                )
            }
        }
    }
}

/// Render `frames` pictures of `field_at(t)`, `t = 0 … 1` evenly, and write them as one
/// animation file when `path` names an [`AnimationFormat`] (`delay_ms` per frame), else as
/// `path/frame0000.png …` (the folder is created; a path whose extension names a picture or
/// video format that is not written is refused, see
/// [`volmorph_render::check_frames_folder`]). Reports to `progress`.
///
/// # Errors
/// [`FrepError::InvalidArgument`] for `frames` outside `1..=`[`MAX_FRAMES`]; a refused
/// folder name ([`volmorph_render::check_animation_output`], checked before any frame is
/// rendered) or a folder that cannot be created, naming `path`; errors of
/// [`render_frames_with`], [`render_animation_with`] and the animation writer (including
/// [`FrepError::Cancelled`]).
pub fn write_frames_with(
    frames: usize,
    field_at: &dyn Fn(f64) -> Result<Box<dyn Field>, FrepError>,
    camera: &Camera,
    options: &RenderOptions,
    path: &Path,
    delay_ms: u32,
    progress: &dyn Progress,
) -> Result<Frames, FrepError> {
    if !(1..=MAX_FRAMES).contains(&frames) {
        return Err(FrepError::InvalidArgument(format!(
            "{frames} frames: an animation has 1 to {MAX_FRAMES}"
        )));
    }
    volmorph_render::check_animation_output(path)?;
    if let Some(format) = AnimationFormat::from_path(path) {
        let images = render_frames_with(frames, field_at, camera, options, progress)?;
        progress.start(&format!("writing {}", path.display()), 0);
        progress.check()?;
        write_animation(path, &images, delay_ms).map_err(|e| in_file(path, e))?;
        return Ok(Frames::File {
            count: images.len(),
            path: path.to_path_buf(),
            format,
        });
    }
    volmorph_render::check_frames_folder(path)?;
    std::fs::create_dir_all(path).map_err(|e| volmorph_io::IoError::os(path, e))?;
    let paths = render_animation_with(frames, field_at, camera, options, path, "frame", progress)?;
    Ok(Frames::Folder {
        dir: path.to_path_buf(),
        paths,
    })
}

/// An error of a writer, naming the file (unless the writer's message already does).
fn in_file(path: &Path, e: impl Into<FrepError>) -> FrepError {
    let e = e.into();
    let name = path.display().to_string();
    if e.to_string().contains(&name) {
        e
    } else {
        FrepError::InFile {
            path: name,
            source: Box::new(e),
        }
    }
}
