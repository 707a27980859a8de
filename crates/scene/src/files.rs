//! Objects from files and to files: what kind of object a file holds (by extension, and for
//! `.json` by its content), reading it, and writing any object in any format volmorph writes.

use std::path::Path;

use volmorph_handles::HandleSet;
use volmorph_maps::{HandleMethod, HandleOptions, MapFormat, read_map, write_map};
use volmorph_mesh::MeshFormat;

use volmorph_maps::AnyMap;

use crate::command::NewObject;
use crate::object::{Object, ObjectId};
use crate::{Recipe, Scene, SceneError};

/// Largest `.hf` or `.json` file inspected or read whole (64 MiB).
pub const MAX_TEXT_FILE_BYTES: u64 = 64 << 20;

/// What a file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// A volume (NIfTI, MetaImage, NRRD, VTK, raw).
    Volume,
    /// A polygon mesh (OBJ, STL, PLY, OFF, optionally gzipped).
    Mesh,
    /// A map (map JSON, lattice JSON, ITK `.tfm`, plastimatch `.bxf`).
    Map,
    /// Handles (handle JSON pairs, six-column text).
    Handles,
    /// An F-rep model (HyperFun `.hf`).
    Frep,
    /// A trivariate NURBS model (volmorph trivariate JSON).
    Nurbs,
}

fn read_small_text(path: &Path) -> Result<String, SceneError> {
    // A FIFO or a device (`/dev/zero`) reports length 0: refuse what is not a regular file.
    let meta = volmorph_io::open_regular(path)?
        .metadata()
        .map_err(|e| volmorph_io::IoError::os(path, e))?;
    if meta.len() > MAX_TEXT_FILE_BYTES {
        return Err(SceneError::invalid(format!(
            "{}: {} bytes is more than a text model may have ({MAX_TEXT_FILE_BYTES})",
            path.display(),
            meta.len()
        )));
    }
    std::fs::read_to_string(path).map_err(|e| SceneError::Io(volmorph_io::IoError::os(path, e)))
}

/// The kind of object `path` holds: by extension, and for `.json` by the document's
/// `"format"` / `"kind"` fields.
///
/// # Errors
/// [`SceneError::Invalid`] for an extension volmorph does not read, naming the known ones;
/// I/O errors when a `.json` file must be inspected.
pub fn kind_of(path: &Path) -> Result<FileKind, SceneError> {
    if MeshFormat::from_path(path).is_ok() {
        return Ok(FileKind::Mesh);
    }
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "hf" => return Ok(FileKind::Frep),
        "tfm" | "bxf" => return Ok(FileKind::Map),
        "json" => {
            let text = read_small_text(path)?;
            let v: serde_json::Value = serde_json::from_str(&text)
                .map_err(|e| SceneError::invalid(format!("{}: not JSON: {e}", path.display())))?;
            return Ok(
                if v.get("format").and_then(|f| f.as_str())
                    == Some(volmorph_trivariate::format::FORMAT_NAME)
                {
                    FileKind::Nurbs
                } else if v.get("kind").is_some() {
                    FileKind::Map
                } else {
                    FileKind::Handles
                },
            );
        }
        "txt" | "xyz" | "pts" | "csv" | "fcsv" => return Ok(FileKind::Handles),
        _ => {}
    }
    if volmorph_volume_io::Format::from_path(path).is_ok() {
        return Ok(FileKind::Volume);
    }
    Err(SceneError::invalid(format!(
        "{}: cannot tell what the file holds from its extension (volumes: .nii .nii.gz .mha \
         .mhd .nrrd .nhdr .vtk; meshes: .obj .stl .ply .off [.gz]; maps: .json .tfm .bxf; \
         handles: .json .txt; F-rep: .hf; NURBS: .json)",
        path.display()
    )))
}

/// Read the object `path` holds ([`kind_of`]). A handle file gives a handle map with the rigid
/// MLS method and default options.
///
/// # Errors
/// The reader's error, naming the file.
pub fn read_object(path: &Path) -> Result<NewObject, SceneError> {
    read_object_with(path, &volmorph_io::NoProgress)
}

/// [`read_object`] reporting one stage, `reading NAME`, of one step (the file read), and
/// polling `progress` before and after reading. The readers do not poll it while they read,
/// so a cancellation takes effect once the file is read: the object is dropped and
/// [`SceneError::Cancelled`] returned.
///
/// # Errors
/// As [`read_object`]; [`SceneError::Cancelled`] when `progress` asks to stop.
pub fn read_object_with(
    path: &Path,
    progress: &dyn volmorph_io::Progress,
) -> Result<NewObject, SceneError> {
    progress.start(&format!("reading {}", file_name(path)), 1);
    progress.check()?;
    let object = read_any(path)?;
    progress.advance(1);
    progress.check()?;
    Ok(object)
}

/// The file name of `path` for messages and progress labels (the whole path if it has none).
pub(crate) fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// The file of frame `n` (1-based, three digits at least) of a sequence written into `dir`,
/// in the format of `like`: its full extension (`nii.gz`, `mha`, …), `nii.gz` when it has
/// none. E.g. frame 7 like `out.nii.gz` is `dir/frame_007.nii.gz`.
#[must_use]
pub fn frame_path(dir: &Path, n: usize, like: &Path) -> std::path::PathBuf {
    let ext = like
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.split_once('.'))
        .map_or("nii.gz", |(_, e)| e);
    dir.join(format!("frame_{n:03}.{ext}"))
}

/// `true` for a `.step` / `.stp` path (any case, [`volmorph_ffd::step::EXTENSIONS`]): the
/// accurate FFD's trimmed surfaces.
#[must_use]
pub fn is_step(path: &Path) -> bool {
    volmorph_io::extension::matching(path, volmorph_ffd::step::EXTENSIONS).is_some()
}

/// The extension of F-rep model files [`Scene::export`] writes (HyperFun text).
pub const FREP_EXTENSIONS: &[&str] = &["hf"];

/// Every extension [`Scene::export`] writes some object as (volumes, meshes, maps and handle
/// or NURBS JSON, STEP, HyperFun), without the dot; which one fits depends on the object.
#[must_use]
pub fn export_extensions() -> Vec<&'static str> {
    let mut all: Vec<&'static str> = Vec::new();
    for list in [
        volmorph_volume_io::WRITE_EXTENSIONS,
        &volmorph_mesh::format::WRITE_EXTENSIONS[..],
        volmorph_maps::file::WRITE_EXTENSIONS,
        volmorph_ffd::step::EXTENSIONS,
        FREP_EXTENSIONS,
    ] {
        for &e in list {
            if !all.contains(&e) {
                all.push(e);
            }
        }
    }
    all
}

/// Check an export path before a project is read: its extension must be one
/// [`Scene::export`] writes some object as ([`export_extensions`]); the object's own format is
/// checked when it is written.
///
/// # Errors
/// [`SceneError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
/// extension found and the accepted ones.
pub fn check_export_path(path: &Path) -> Result<(), SceneError> {
    Ok(volmorph_io::extension::check(path, &export_extensions())?)
}

fn read_any(path: &Path) -> Result<NewObject, SceneError> {
    Ok(match kind_of(path)? {
        FileKind::Volume => NewObject::Volume(volmorph_volume_io::read(path)?),
        FileKind::Mesh => NewObject::Mesh(volmorph_mesh::read(path)?),
        FileKind::Map => NewObject::Map(read_map(path)?),
        FileKind::Handles => NewObject::Handles {
            set: HandleSet::read(path)?,
            method: HandleMethod::Rigid,
            options: HandleOptions::default(),
        },
        FileKind::Frep => NewObject::Frep {
            source: read_small_text(path)?,
            params: Default::default(),
        },
        FileKind::Nurbs => NewObject::Nurbs(volmorph_trivariate::load_volume(path)?),
    })
}

impl Scene {
    /// Write object `id` to `path` in the format its extension names: volumes in any volume
    /// format, meshes in any mesh format, maps as map JSON / ITK `.tfm` / `.bxf`, handle maps
    /// as handle JSON (`.json`) or as their map (`.tfm`), F-rep models as `.hf`, NURBS models as
    /// trivariate JSON; derived objects as their result. Written atomically.
    ///
    ///
    /// A deformed mesh ([`Recipe::DeformedMesh`] through a B-spline lattice) written as
    /// `.step` / `.stp` is the **accurate** FFD of its mesh (Feng et al. 2002: trimmed Bézier
    /// surfaces, [`volmorph_ffd::accurate`]), not the vertex FFD the scene shows: a closed
    /// mesh gives a `MANIFOLD_SOLID_BREP`, an open one a shell-based surface model.
    ///
    /// # Errors
    /// [`SceneError::Io`] with [`volmorph_io::IoError::Extension`] for an extension no object
    /// is written as ([`check_export_path`], checked first) or that the object's writer does
    /// not write; [`SceneError::NoObject`]; [`SceneError::Invalid`] for a derived object not
    /// computed or a format that cannot hold the object (STEP for anything but a deformed mesh
    /// through a B-spline lattice); the writer's errors.
    pub fn export(&self, id: ObjectId, path: &Path) -> Result<(), SceneError> {
        self.export_with(id, path, &volmorph_io::NoProgress)
    }

    /// [`Scene::export`] reporting to `progress` and stopping when it is cancelled: a STEP
    /// file reports the stages of [`volmorph_ffd::accurate::accurate_ffd_with`], then
    /// `writing NAME` (one step); every other format the one stage `writing NAME`. Nothing
    /// is written when the export is cancelled.
    ///
    /// # Errors
    /// As [`Scene::export`]; [`SceneError::Cancelled`] when `progress` asks to stop.
    pub fn export_with(
        &self,
        id: ObjectId,
        path: &Path,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<(), SceneError> {
        check_export_path(path)?;
        progress.check()?;
        if is_step(path) {
            let model = self.accurate_ffd_with(id, progress)?;
            progress.start(&format!("writing {}", file_name(path)), 1);
            progress.check()?;
            volmorph_ffd::step::write_step(path, &model)?;
            progress.advance(1);
            return Ok(());
        }
        progress.start(&format!("writing {}", file_name(path)), 1);
        self.write_object(id, path)?;
        progress.advance(1);
        Ok(())
    }

    /// The accurate FFD (Feng et al. 2002) of deformed mesh `id`: its mesh through its
    /// B-spline lattice as trimmed Bézier surfaces, reporting the stages of
    /// [`volmorph_ffd::accurate::accurate_ffd_with`] to `progress`.
    ///
    /// # Errors
    /// [`SceneError::NoObject`]; [`SceneError::Invalid`] unless `id` is a deformed mesh whose
    /// map is a B-spline lattice; the FFD's errors; [`SceneError::Cancelled`].
    pub fn accurate_ffd_with(
        &self,
        id: ObjectId,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<volmorph_ffd::accurate::TrimmedModel, SceneError> {
        let entry = self.get(id)?;
        let Object::Derived(d) = &entry.object else {
            return Err(SceneError::invalid(format!(
                "object {id} ({:?}) is a {}: the accurate FFD (STEP) is made from a deformed \
                 mesh (a mesh through a B-spline lattice)",
                entry.name,
                entry.object.kind()
            )));
        };
        let Recipe::DeformedMesh { mesh, map } = d.recipe() else {
            return Err(SceneError::invalid(format!(
                "object {id} ({:?}) is a {} result: the accurate FFD (STEP) is made from a \
                 deformed mesh (a mesh through a B-spline lattice)",
                entry.name,
                d.recipe().name()
            )));
        };
        let lattice = match self.map(*map)? {
            AnyMap::Lattice(l) => l,
            other => {
                return Err(SceneError::invalid(format!(
                    "object {id} ({:?}) deforms its mesh by a {} map: the accurate FFD (STEP) \
                     needs a B-spline lattice",
                    entry.name,
                    other.kind()
                )));
            }
        };
        let mesh = self.mesh(*mesh)?;
        Ok(volmorph_ffd::accurate::accurate_ffd_with(
            mesh, lattice, progress,
        )?)
    }

    fn write_object(&self, id: ObjectId, path: &Path) -> Result<(), SceneError> {
        let entry = self.get(id)?;
        match &entry.object {
            Object::Volume(_) | Object::Derived(_) if entry.object.volume().is_some() => {
                let v = entry.object.volume().ok_or(SceneError::NoObject(id))?;
                volmorph_volume_io::write(path, v)?;
            }
            Object::Mesh(_) | Object::Sculpt(_) | Object::Derived(_)
                if entry.object.mesh().is_some() =>
            {
                let m = entry.object.mesh().ok_or(SceneError::NoObject(id))?;
                volmorph_mesh::write(path, m)?;
            }
            Object::Derived(d) => {
                return Err(SceneError::invalid(format!(
                    "object {id} ({:?}) has no result to write{}",
                    entry.name,
                    d.error().map(|e| format!(": {e}")).unwrap_or_default()
                )));
            }
            Object::Map(crate::MapObject::Handles(h))
                if MapFormat::of(path).ok() == Some(MapFormat::Json) =>
            {
                h.set().write_json(path)?;
            }
            Object::Map(m) => write_map(path, m.map())?,
            Object::Frep(f) => {
                volmorph_io::extension::check(path, FREP_EXTENSIONS)?;
                write_text(path, f.source())?;
            }
            Object::Nurbs(a) => volmorph_trivariate::save(path, a)?,
            _ => {
                return Err(SceneError::invalid(format!(
                    "object {id} cannot be written"
                )));
            }
        }
        Ok(())
    }
}

pub(crate) fn write_text(path: &Path, text: &str) -> Result<(), SceneError> {
    volmorph_io::write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| SceneError::Io(volmorph_io::IoError::os(path, e)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames keep the output's whole extension (two-part ones included), default to
    /// `nii.gz` without one, and number from three digits up.
    #[test]
    fn frame_paths_keep_the_whole_extension() {
        let d = Path::new("frames");
        let cases = [
            (7, "out.nii.gz", "frames/frame_007.nii.gz"),
            (12, "dir/warped.mha", "frames/frame_012.mha"),
            (1, "bare", "frames/frame_001.nii.gz"),
            (1234, "a.nrrd", "frames/frame_1234.nrrd"),
        ];
        for (n, like, want) in cases {
            assert_eq!(frame_path(d, n, Path::new(like)), Path::new(want), "{like}");
        }
    }
}
