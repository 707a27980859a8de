//! Project files: a scene saved as a versioned JSON manifest with its data files beside it, and
//! loaded back to the same state.
//!
//! ```text
//! scene.vmproj            the manifest (JSON, written last, atomically)
//! scene.vmproj.data/      one file per object that has bulk data: <id>.<tag>.mha (volumes,
//!                         exact geometry), <id>.<tag>.ply (meshes, binary double),
//!                         <id>.<tag>.json (NURBS); <tag> is 8 hex digits, new on every save
//! ```
//!
//! Saving is one commit: the data files get names no earlier save used, the manifest's atomic
//! rename commits them, and only then are the data files of earlier saves removed. A save that
//! fails or is killed at any point leaves the previous manifest with its own, untouched data
//! files (plus at worst unreferenced new ones, removed by the next save), never a manifest
//! beside data that is not its own.
//!
//! ```json
//! {
//!   "format": "volmorph-scene", "version": 1, "next_id": 4,
//!   "objects": [
//!     {"id": 1, "name": "teapot", "kind": "volume", "file": "scene.vmproj.data/1.3f09a2c1.mha"},
//!     {"id": 2, "name": "lattice", "kind": "map", "map": { …map JSON… }},
//!     {"id": 3, "name": "handles", "kind": "handles", "handles": { …handle JSON… },
//!      "method": "rigid", "options": {"weighting": {"type": "inverse-distance", "alpha": 1},
//!      "beta": 1, "smoothing": 0}},
//!     {"id": 4, "name": "warped", "kind": "derived", "recipe": { … },
//!      "file": "scene.vmproj.data/4.3f09a2c1.mha"}
//!   ]
//! }
//! ```
//!
//! Maps, handles, F-rep sources and recipes are stored in the manifest itself, numbers in their
//! shortest exact form. Derived results are stored too (as a cache), so a loaded scene shows
//! exactly what was saved; a derived object saved without a result is computed on loading.
//! Data file paths are relative to the manifest's folder and must stay inside it: absolute
//! paths, `..` and symbolic links that leave the folder are refused.
//!
//! A sculpt object is saved as its current mesh, its grid and its options; loading builds
//! the tri-dexel again from that mesh (so the mesh is restored exactly, the dexels as the
//! mesh's depth peel, and sculpting continues from there).

use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use serde_json::Value;
use volmorph_handles::{HandleSet, TpsKernel, Weighting};
use volmorph_maps::{AnyMap, HandleMethod, HandleOptions};
use volmorph_sculpt::{Grid as SculptGrid, SculptDocument, SculptOptions};

use crate::derived::{Derived, DerivedOutput, Recipe};
use crate::object::{Entry, FrepModel, HandleMap, MapObject, Object, ObjectId, SculptObject};
use crate::{Scene, SceneError};

/// The extension of project files (`scene.vmproj`), without the dot.
pub const PROJECT_EXTENSION: &str = "vmproj";

/// Check that `path` ends in `.vmproj` ([`PROJECT_EXTENSION`], any case) before a project is
/// built or saved there.
///
/// # Errors
/// [`SceneError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
/// extension found and `.vmproj`.
pub fn check_project_path(path: &Path) -> Result<(), SceneError> {
    Ok(volmorph_io::extension::check(path, &[PROJECT_EXTENSION])?)
}

/// Value of the manifest's `format` field.
pub const PROJECT_FORMAT: &str = "volmorph-scene";

/// Version of the manifest written, and the only one read.
pub const PROJECT_VERSION: u32 = 1;

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    format: String,
    version: u32,
    next_id: u64,
    objects: Vec<ObjectJson>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectJson {
    id: ObjectId,
    name: String,
    kind: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    file: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    map: Option<Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    handles: Option<Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    method: Option<HandleMethod>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    options: Option<OptionsJson>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    source: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    params: Option<BTreeMap<usize, f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    recipe: Option<Recipe>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sculpt: Option<SculptJson>,
}

/// The grid and options of a sculpt object.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SculptJson {
    origin: [f64; 3],
    spacing: f64,
    dims: [usize; 3],
    margin: usize,
    max_dabs: usize,
    feature_angle: f64,
    singular_threshold: f64,
}

impl From<&SculptDocument> for SculptJson {
    fn from(d: &SculptDocument) -> Self {
        let g = d.grid();
        let o = d.options();
        Self {
            origin: g.origin().to_array(),
            spacing: g.spacing(),
            dims: g.dims(),
            margin: o.margin,
            max_dabs: o.max_dabs,
            feature_angle: o.dc.feature_angle,
            singular_threshold: o.dc.singular_threshold,
        }
    }
}

impl SculptJson {
    fn grid_and_options(&self) -> Result<(SculptGrid, SculptOptions), SceneError> {
        let grid = SculptGrid::new(
            glam::DVec3::from_array(self.origin),
            self.spacing,
            self.dims,
        )?;
        let options = SculptOptions {
            dc: volmorph_contour::DcOptions {
                feature_angle: self.feature_angle,
                singular_threshold: self.singular_threshold,
                ..volmorph_contour::DcOptions::default()
            },
            margin: self.margin,
            max_dabs: self.max_dabs,
        };
        Ok((grid, options))
    }
}

#[derive(Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
enum WeightingJson {
    InverseDistance { alpha: f64 },
    Gaussian { sigma: f64 },
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct OptionsJson {
    weighting: WeightingJson,
    beta: f64,
    smoothing: f64,
    /// The Wendland support radius; absent for the default (and in projects written before
    /// the option existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    support: Option<f64>,
    /// The thin-plate kernel (`r2logr`); absent for the default `r` (and in projects
    /// written before the option existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    kernel: Option<String>,
}

impl From<&HandleOptions> for OptionsJson {
    fn from(o: &HandleOptions) -> Self {
        Self {
            weighting: match o.weighting {
                Weighting::InverseDistance { alpha } => WeightingJson::InverseDistance { alpha },
                Weighting::Gaussian { sigma } => WeightingJson::Gaussian { sigma },
            },
            beta: o.beta,
            smoothing: o.smoothing,
            support: o.support,
            kernel: (o.kernel != TpsKernel::R).then(|| o.kernel.name().to_owned()),
        }
    }
}

impl TryFrom<OptionsJson> for HandleOptions {
    type Error = String;
    fn try_from(o: OptionsJson) -> Result<Self, String> {
        let kernel = match o.kernel.as_deref() {
            None => TpsKernel::R,
            Some(k) => TpsKernel::parse(k).map_err(|e| e.to_string())?,
        };
        Ok(Self {
            weighting: match o.weighting {
                WeightingJson::InverseDistance { alpha } => Weighting::InverseDistance { alpha },
                WeightingJson::Gaussian { sigma } => Weighting::Gaussian { sigma },
            },
            beta: o.beta,
            smoothing: o.smoothing,
            support: o.support,
            kernel,
        })
    }
}

/// `true` for a data file name that [`Scene::save`] writes: `<id>.<8 hex digits>.<ext>`, or
/// `<id>.<ext>` as earlier versions wrote, for the extensions of saved data.
fn is_saved_data_file(name: &str) -> bool {
    let mut parts = name.split('.');
    let (Some(id), Some(second)) = (parts.next(), parts.next()) else {
        return false;
    };
    let third = parts.next();
    if parts.next().is_some() || id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
        return false;
    }
    let ext = match third {
        None => second,
        Some(ext) if second.len() == 8 && second.bytes().all(|b| b.is_ascii_hexdigit()) => ext,
        Some(_) => return false,
    };
    matches!(ext, "mha" | "ply" | "json")
}

/// The data folder of the project file `path`: `<file name>.data` beside it.
#[must_use]
pub fn data_folder(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".data");
    path.with_file_name(name)
}

fn project_err(path: &Path, message: impl Into<String>) -> SceneError {
    SceneError::Project {
        path: path.display().to_string(),
        message: message.into(),
    }
}

impl Scene {
    /// Save the scene as the project `path` (see the [module docs](self)): data files first,
    /// under names new to this save, then the manifest, atomically, then the data files of
    /// earlier saves are removed. A failure leaves any previous manifest and its data files in
    /// place.
    ///
    /// # Errors
    /// [`SceneError::Io`] with [`volmorph_io::IoError::Extension`] when `path` does not end in
    /// `.vmproj` ([`PROJECT_EXTENSION`], any case; checked before anything is written, see
    /// [`check_project_path`]); I/O errors naming the file; [`SceneError::Map`] if a map
    /// cannot be serialised.
    pub fn save(&self, path: &Path) -> Result<(), SceneError> {
        self.save_with(path, &volmorph_io::NoProgress)
    }

    /// [`Scene::save`] reporting one stage, `saving NAME`, of one step per object, and
    /// stopping between objects when `progress` is cancelled: the manifest is then not
    /// written and the data files of this save are removed, so any previous project is
    /// untouched.
    ///
    /// # Errors
    /// As [`Scene::save`]; [`SceneError::Cancelled`] when `progress` asks to stop.
    pub fn save_with(
        &self,
        path: &Path,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<(), SceneError> {
        check_project_path(path)?;
        progress.check()?;
        let folder = data_folder(path);
        std::fs::create_dir_all(&folder).map_err(|e| volmorph_io::IoError::os(&folder, e))?;
        let tag = format!("{:08x}", volmorph_io::atomic::token());
        let mut written: Vec<String> = Vec::new();
        let result = self.write_project(path, &folder, &tag, &mut written, progress);
        if result.is_err() {
            // Uncommitted: the previous manifest still names its own files.
            for name in &written {
                let _ = std::fs::remove_file(folder.join(name));
            }
            return result;
        }
        // Committed: the data files of earlier saves (and of saves that never committed).
        if let Ok(entries) = std::fs::read_dir(&folder) {
            for entry in entries.flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                if is_saved_data_file(&name) && !written.contains(&name) {
                    let _ = std::fs::remove_file(entry.path());
                }
            }
        }
        Ok(())
    }

    fn write_project(
        &self,
        path: &Path,
        folder: &Path,
        tag: &str,
        written: &mut Vec<String>,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<(), SceneError> {
        let base = path.parent().unwrap_or(Path::new(""));
        let rel = |file: &str| -> String {
            let f = folder.join(file);
            f.strip_prefix(base)
                .unwrap_or(&f)
                .to_string_lossy()
                .replace('\\', "/")
        };
        let mut objects = Vec::new();
        progress.start(
            &format!("saving {}", crate::files::file_name(path)),
            self.objects().count() as u64,
        );
        for (id, entry) in self.objects() {
            progress.check()?;
            let mut o = ObjectJson {
                id,
                name: entry.name.clone(),
                kind: entry.object.kind().to_owned(),
                file: None,
                map: None,
                handles: None,
                method: None,
                options: None,
                source: None,
                params: None,
                recipe: None,
                sculpt: None,
            };
            match &entry.object {
                Object::Volume(v) => {
                    let name = format!("{}.{tag}.mha", id.0);
                    written.push(name.clone());
                    volmorph_volume_io::write(&folder.join(&name), v)?;
                    o.file = Some(rel(&name));
                }
                Object::Mesh(m) => {
                    let name = format!("{}.{tag}.ply", id.0);
                    written.push(name.clone());
                    volmorph_mesh::write(&folder.join(&name), m)?;
                    o.file = Some(rel(&name));
                }
                Object::Nurbs(a) => {
                    let name = format!("{}.{tag}.json", id.0);
                    written.push(name.clone());
                    volmorph_trivariate::save(&folder.join(&name), a)?;
                    o.file = Some(rel(&name));
                }
                Object::Frep(f) => {
                    o.source = Some(f.source().to_owned());
                    o.params = Some(f.params().clone());
                }
                Object::Map(MapObject::Fixed(m)) => o.map = Some(m.to_json_value()?),
                Object::Map(MapObject::Handles(h)) => {
                    o.kind = "handles".into();
                    o.handles = Some(
                        serde_json::from_str(&h.set().to_json())
                            .map_err(|e| project_err(path, format!("handles of {id}: {e}")))?,
                    );
                    o.method = Some(h.method());
                    o.options = Some(h.options().into());
                }
                Object::Sculpt(sc) => {
                    let m = sc.mesh().ok_or_else(|| {
                        project_err(path, format!("sculpt object {id}: its mesh is too large"))
                    })?;
                    let name = format!("{}.{tag}.ply", id.0);
                    written.push(name.clone());
                    volmorph_mesh::write(&folder.join(&name), m)?;
                    o.file = Some(rel(&name));
                    o.sculpt = Some(SculptJson::from(sc.document()));
                }
                Object::Derived(d) => {
                    o.recipe = Some(d.recipe().clone());
                    match d.output() {
                        Some(DerivedOutput::Volume(v)) => {
                            let name = format!("{}.{tag}.mha", id.0);
                            written.push(name.clone());
                            volmorph_volume_io::write(&folder.join(&name), v)?;
                            o.file = Some(rel(&name));
                        }
                        Some(DerivedOutput::Mesh(m)) => {
                            let name = format!("{}.{tag}.ply", id.0);
                            written.push(name.clone());
                            volmorph_mesh::write(&folder.join(&name), m)?;
                            o.file = Some(rel(&name));
                        }
                        None => {}
                    }
                }
            }
            objects.push(o);
            progress.advance(1);
        }
        progress.check()?;
        let manifest = Manifest {
            format: PROJECT_FORMAT.into(),
            version: PROJECT_VERSION,
            next_id: self.next_id_value(),
            objects,
        };
        let text = serde_json::to_string_pretty(&manifest)
            .map_err(|e| project_err(path, e.to_string()))?;
        crate::files::write_text(path, &text)
    }

    /// Load the project `path` (see the [module docs](self)) into a new scene with an empty
    /// history.
    ///
    /// # Errors
    /// [`SceneError::Project`] for a malformed manifest, another format or version, a
    /// duplicate id, a data path outside the project's folder, or a recipe reading an object
    /// that does not precede it; the errors of the data files' readers.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        Self::load_with(path, &volmorph_io::NoProgress)
    }

    /// [`Scene::load`] reporting one stage, `loading NAME`, of one step per object, then the
    /// computations of derived objects saved without a result (as [`Scene::apply_with`]
    /// reports them), and stopping when `progress` is cancelled (between objects, and inside
    /// those computations).
    ///
    /// # Errors
    /// As [`Scene::load`]; [`SceneError::Cancelled`] when `progress` asks to stop.
    pub fn load_with(
        path: &Path,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Scene, SceneError> {
        progress.check()?;
        // Bounded by the memory budget; FIFOs and devices are refused by name.
        let bytes = volmorph_io::read_maybe_gz(path)?;
        let text = String::from_utf8(bytes)
            .map_err(|e| project_err(path, format!("not UTF-8 text: {e}")))?;
        let m: Manifest =
            serde_json::from_str(&text).map_err(|e| project_err(path, e.to_string()))?;
        if m.format != PROJECT_FORMAT {
            return Err(project_err(
                path,
                format!("format {:?} is not {PROJECT_FORMAT:?}", m.format),
            ));
        }
        if m.version != PROJECT_VERSION {
            return Err(project_err(
                path,
                format!(
                    "version {} is not supported (expected {PROJECT_VERSION})",
                    m.version
                ),
            ));
        }
        let base = path.parent().unwrap_or(Path::new(""));
        let mut scene = Scene::new();
        progress.start(
            &format!("loading {}", crate::files::file_name(path)),
            m.objects.len() as u64,
        );
        for o in m.objects {
            progress.check()?;
            let id = o.id;
            if scene.get(id).is_ok() {
                return Err(project_err(path, format!("object {id} appears twice")));
            }
            let file = || -> Result<PathBuf, SceneError> {
                let f = o
                    .file
                    .as_deref()
                    .ok_or_else(|| project_err(path, format!("object {id}: no \"file\"")))?;
                contained(base, f).map_err(|m| project_err(path, format!("object {id}: {m}")))
            };
            let object = match o.kind.as_str() {
                "volume" => Object::Volume(Arc::new(volmorph_volume_io::read(&file()?)?)),
                "mesh" => Object::Mesh(Arc::new(volmorph_mesh::read(&file()?)?)),
                "sculpt" => {
                    let (grid, options) = o
                        .sculpt
                        .as_ref()
                        .ok_or_else(|| project_err(path, format!("object {id}: no \"sculpt\"")))?
                        .grid_and_options()?;
                    let mesh = volmorph_mesh::read(&file()?)?;
                    Object::Sculpt(SculptObject::new(SculptDocument::new(
                        &mesh, grid, options,
                    )?))
                }
                "nurbs" => Object::Nurbs(Arc::new(volmorph_trivariate::load_volume(&file()?)?)),
                "frep" => Object::Frep(FrepModel::new(
                    o.source.as_deref().unwrap_or(""),
                    o.params.clone().unwrap_or_default(),
                )?),
                "map" => {
                    let v = o
                        .map
                        .as_ref()
                        .ok_or_else(|| project_err(path, format!("object {id}: no \"map\"")))?;
                    Object::Map(MapObject::Fixed(AnyMap::from_json_value(v, 0)?))
                }
                "handles" => {
                    let v = o
                        .handles
                        .as_ref()
                        .ok_or_else(|| project_err(path, format!("object {id}: no \"handles\"")))?;
                    let set = HandleSet::from_json(&v.to_string())?;
                    let method = o.method.unwrap_or(HandleMethod::Rigid);
                    let options = match o.options {
                        Some(j) => HandleOptions::try_from(j)
                            .map_err(|e| project_err(path, format!("object {id}: options: {e}")))?,
                        None => HandleOptions::default(),
                    };
                    Object::Map(MapObject::Handles(HandleMap::new(set, method, options)?))
                }
                "derived" => {
                    let recipe = o
                        .recipe
                        .clone()
                        .ok_or_else(|| project_err(path, format!("object {id}: no \"recipe\"")))?;
                    if recipe.inputs().iter().any(|i| *i >= id) {
                        return Err(project_err(
                            path,
                            format!(
                                "object {id}: its recipe reads an object that does not precede it"
                            ),
                        ));
                    }
                    match o.file {
                        None => Object::Derived(Derived::new(recipe)),
                        Some(_) => {
                            let f = file()?;
                            let out = if recipe.output_kind() == "volume" {
                                DerivedOutput::Volume(Arc::new(volmorph_volume_io::read(&f)?))
                            } else {
                                DerivedOutput::Mesh(Arc::new(volmorph_mesh::read(&f)?))
                            };
                            Object::Derived(Derived::with_output(recipe, out))
                        }
                    }
                }
                other => {
                    return Err(project_err(
                        path,
                        format!("object {id}: unknown kind {other:?}"),
                    ));
                }
            };
            scene.insert_raw(
                id,
                Entry {
                    name: o.name,
                    object,
                },
            );
            progress.advance(1);
        }
        scene.set_next_id(m.next_id);
        for (id, e) in scene.objects() {
            if let Object::Derived(d) = &e.object {
                scene
                    .check_recipe_of(id, d.recipe())
                    .map_err(|e| project_err(path, e.to_string()))?;
            }
        }
        scene.compute_missing(progress)?;
        scene.clear_history();
        Ok(scene)
    }
}

/// `relative` resolved against `base`, refused unless it stays inside `base`: no absolute
/// path, no `..`, and after resolving symbolic links still under `base`.
fn contained(base: &Path, relative: &str) -> Result<PathBuf, String> {
    let rel = Path::new(relative);
    if rel.is_absolute()
        || rel
            .components()
            .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
    {
        return Err(format!(
            "data path {relative:?} must be relative and stay inside the project's folder"
        ));
    }
    let full = base.join(rel);
    let canon_base = std::fs::canonicalize(if base.as_os_str().is_empty() {
        Path::new(".")
    } else {
        base
    })
    .map_err(|e| format!("project folder: {e}"))?;
    let canon = std::fs::canonicalize(&full).map_err(|e| format!("{}: {e}", full.display()))?;
    if !canon.starts_with(&canon_base) {
        return Err(format!(
            "data path {relative:?} leaves the project's folder (through a symbolic link)"
        ));
    }
    Ok(full)
}
