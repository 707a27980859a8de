//! `Scene`: the document of `volmorph_scene` (objects by id, commands with undo/redo and change
//! reports, derived objects kept up to date, project files). Every edit goes through
//! `Scene::apply` as one `Command`, like the CLI and the studio.
//!
//! A change report is a dict: `added`, `removed`, `modified` (object ids), `dirty` (per derived
//! object: `object`, `voxels` `((i0, j0, k0), (i1, j1, k1))` half-open or `None`, `bounds`
//! `((x0, y0, z0), (x1, y1, z1))` or `None`), `errors` (`(id, message)` of derived objects whose
//! update failed) and `drag` (`moved`, `rank`, `drags`, `max_residual`) or `None`.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Mutex;

use numpy::PyReadonlyArray2;
use pyo3::prelude::*;
use pyo3::types::{PyAny, PyDict, PyList};
use volmorph_lattice::DragOptions;
use volmorph_scene::{Change, Command, NewObject, ObjectId, Recipe, Scene};

use crate::error::{FileError, SceneError, input, to_py};
use crate::maps::{PyMap, points};
use crate::ops::{mesh_in, mesh_out};
use crate::volume::{PyVolume, vec3};

/// A recipe from a Python dict (through JSON, as project files write recipes).
fn recipe_of<'py>(py: Python<'py>, recipe: &Bound<'py, PyAny>) -> PyResult<Recipe> {
    let text: String = py
        .import("json")?
        .call_method1("dumps", (recipe,))?
        .extract()?;
    serde_json::from_str(&text).map_err(|e| input(format!("recipe: {e}")))
}

fn change<'py>(py: Python<'py>, c: &Change) -> PyResult<Bound<'py, PyDict>> {
    let ids = |v: &[ObjectId]| v.iter().map(|i| i.0).collect::<Vec<_>>();
    let d = PyDict::new(py);
    d.set_item("added", ids(&c.added))?;
    d.set_item("removed", ids(&c.removed))?;
    d.set_item("modified", ids(&c.modified))?;
    let dirty = PyList::empty(py);
    for x in &c.dirty {
        let e = PyDict::new(py);
        e.set_item("object", x.object.0)?;
        e.set_item("voxels", x.voxels.map(|b| (b.start, b.end)))?;
        e.set_item(
            "bounds",
            x.bounds.map(|(lo, hi)| (lo.to_array(), hi.to_array())),
        )?;
        dirty.append(e)?;
    }
    d.set_item("dirty", dirty)?;
    d.set_item(
        "errors",
        c.errors
            .iter()
            .map(|(i, m)| (i.0, m.clone()))
            .collect::<Vec<_>>(),
    )?;
    match c.drag {
        Some(s) => {
            let e = PyDict::new(py);
            e.set_item("moved", s.moved)?;
            e.set_item("rank", s.rank)?;
            e.set_item("drags", s.drags)?;
            e.set_item("max_residual", s.max_residual)?;
            d.set_item("drag", e)?;
        }
        None => d.set_item("drag", py.None())?,
    }
    Ok(d)
}

/// A scene: volumes, meshes, F-rep models, maps and derived results, edited by commands with
/// undo and redo.
///
/// >>> import numpy as np
/// >>> s = Scene()
/// >>> v = s.add_volume("ct", Volume(np.zeros((8, 8, 8), dtype=np.float32)))
/// >>> m = s.add_map("identity", Map.identity())
/// >>> w = s.add_derived("warped", {"recipe": "warp", "source": v, "map": m,
/// ...     "method": "pullback-linear", "background": 0.0, "sampled_nodes": None,
/// ...     "swap_handles": False})["added"][0]
/// >>> s.volume(w).shape
/// (8, 8, 8)
#[pyclass(name = "Scene", module = "volmorph._volmorph")]
pub struct PyScene {
    scene: Mutex<Scene>,
}

impl PyScene {
    fn run(&self, py: Python<'_>, command: Command) -> PyResult<Change> {
        let mut guard = self
            .scene
            .lock()
            .map_err(|_| SceneError::new_err("the scene was poisoned by an earlier panic"))?;
        let scene: &mut Scene = &mut guard;
        py.detach(|| scene.apply(command))
            .map_err(|e| to_py(SceneError::new_err, &e))
    }

    /// Undo or redo (`step` is `Scene::undo` or `Scene::redo`) with the GIL released.
    fn history<'py>(
        &self,
        py: Python<'py>,
        step: fn(&mut Scene) -> Result<Option<Change>, volmorph_scene::SceneError>,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        let mut guard = self
            .scene
            .lock()
            .map_err(|_| SceneError::new_err("the scene was poisoned by an earlier panic"))?;
        let s: &mut Scene = &mut guard;
        let c = py
            .detach(|| step(s))
            .map_err(|e| to_py(SceneError::new_err, &e))?;
        c.map(|c| change(py, &c)).transpose()
    }

    fn with<R>(&self, f: impl FnOnce(&Scene) -> PyResult<R>) -> PyResult<R> {
        let scene = self
            .scene
            .lock()
            .map_err(|_| SceneError::new_err("the scene was poisoned by an earlier panic"))?;
        f(&scene)
    }

    fn add<'py>(&self, py: Python<'py>, name: &str, object: NewObject) -> PyResult<u64> {
        let c = self.run(
            py,
            Command::Add {
                name: name.into(),
                object,
            },
        )?;
        Ok(c.added[0].0)
    }
}

#[pymethods]
impl PyScene {
    /// An empty scene.
    #[new]
    fn new() -> Self {
        Self {
            scene: Mutex::new(Scene::new()),
        }
    }

    /// Open a project file (`.vmproj` and its data folder).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let s = py
            .detach(|| Scene::load(&path))
            .map_err(|e| to_py(FileError::new_err, &e))?;
        Ok(Self {
            scene: Mutex::new(s),
        })
    }

    /// Save the project file (a `.vmproj` name, any case; another extension is refused
    /// before anything is written) and its data folder.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        self.with(|s| {
            py.detach(|| s.save(&path))
                .map_err(|e| to_py(FileError::new_err, &e))
        })
    }

    /// Write object `id` to a file of its kind (volume, mesh, map).
    fn export(&self, py: Python<'_>, id: u64, path: PathBuf) -> PyResult<()> {
        self.with(|s| {
            py.detach(|| s.export(ObjectId(id), &path))
                .map_err(|e| to_py(FileError::new_err, &e))
        })
    }

    /// Add a volume; returns its id.
    fn add_volume(&self, py: Python<'_>, name: &str, volume: &PyVolume) -> PyResult<u64> {
        let v = volume.to_rust(py)?;
        self.add(py, name, NewObject::Volume(v))
    }

    /// Add a triangle mesh `(vertices, faces)`; returns its id.
    fn add_mesh(
        &self,
        py: Python<'_>,
        name: &str,
        vertices: PyReadonlyArray2<'_, f64>,
        faces: &Bound<'_, PyAny>,
    ) -> PyResult<u64> {
        let m = mesh_in(&vertices, faces)?;
        self.add(py, name, NewObject::Mesh(m))
    }

    /// Add an F-rep model from HyperFun source and parameters `{k: a_k}`; returns its id.
    #[pyo3(signature = (name, source, params=None))]
    fn add_frep(
        &self,
        py: Python<'_>,
        name: &str,
        source: String,
        params: Option<BTreeMap<usize, f64>>,
    ) -> PyResult<u64> {
        self.add(
            py,
            name,
            NewObject::Frep {
                source,
                params: params.unwrap_or_default(),
            },
        )
    }

    /// Add a map; returns its id.
    fn add_map(&self, py: Python<'_>, name: &str, map: &PyMap) -> PyResult<u64> {
        self.add(py, name, NewObject::Map(map.inner.clone()))
    }

    /// Add a derived object from a recipe dict, as in project files: `{"recipe": "warp",
    /// "source": id, "map": id, "method": "pullback-linear", "background": 0.0,
    /// "sampled_nodes": None, "swap_handles": False}`, `{"recipe": "isosurface", "volume": id,
    /// "level": 0.5, "inside_below": False, "method": "marching-cubes"}`, `"deformed-mesh"`,
    /// `"frep-sampled"`, `"jacobian"`, `{"recipe": "frep-morph", "from": id, "to": id, "t": 0.5,
    /// "schedule": "smoothstep", "grid": id}` (the metamorphosis of Savchenko–Pasko Eq. 13;
    /// schedules `linear`, `sqrt`, `smoothstep`, `delayed:T0`). Returns the change report.
    fn add_derived<'py>(
        &self,
        py: Python<'py>,
        name: &str,
        recipe: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let recipe = recipe_of(py, recipe)?;
        let c = self.run(
            py,
            Command::Add {
                name: name.into(),
                object: NewObject::Derived(recipe),
            },
        )?;
        change(py, &c)
    }

    /// Give derived object `id` a new recipe dict (as [`add_derived`](Self::add_derived)
    /// takes), e.g. a metamorphosis at another `t`: recomputed, one undo step.
    fn set_recipe<'py>(
        &self,
        py: Python<'py>,
        id: u64,
        recipe: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let recipe = recipe_of(py, recipe)?;
        let c = self.run(
            py,
            Command::SetRecipe {
                id: ObjectId(id),
                recipe,
            },
        )?;
        change(py, &c)
    }

    /// Remove object `id` (refused while a derived object uses it).
    fn remove<'py>(&self, py: Python<'py>, id: u64) -> PyResult<Bound<'py, PyDict>> {
        let c = self.run(py, Command::Remove { id: ObjectId(id) })?;
        change(py, &c)
    }

    /// Rename object `id`.
    fn rename<'py>(&self, py: Python<'py>, id: u64, name: String) -> PyResult<Bound<'py, PyDict>> {
        let c = self.run(
            py,
            Command::Rename {
                id: ObjectId(id),
                name,
            },
        )?;
        change(py, &c)
    }

    /// Put a new volume in place of volume `id` (derived objects follow).
    fn replace_volume<'py>(
        &self,
        py: Python<'py>,
        id: u64,
        volume: &PyVolume,
    ) -> PyResult<Bound<'py, PyDict>> {
        let v = volume.to_rust(py)?;
        let c = self.run(
            py,
            Command::Replace {
                id: ObjectId(id),
                object: NewObject::Volume(v),
            },
        )?;
        change(py, &c)
    }

    /// Direct manipulation (True 1992 §6): the points `grabbed` (N×3, on the model as
    /// deformed by lattice map `map`) go exactly to `targets`, moving only control points
    /// within `radius`; derived objects follow incrementally.
    #[pyo3(signature = (map, grabbed, targets, radius=None, freeze_boundary=false))]
    fn drag_points<'py>(
        &self,
        py: Python<'py>,
        map: u64,
        grabbed: PyReadonlyArray2<'py, f64>,
        targets: PyReadonlyArray2<'py, f64>,
        radius: Option<f64>,
        freeze_boundary: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let g = points(&grabbed)?;
        let t = points(&targets)?;
        if g.len() != t.len() {
            return Err(input(format!(
                "{} grabbed points but {} targets: give one target per grabbed point",
                g.len(),
                t.len()
            )));
        }
        let c = self.run(
            py,
            Command::DragPoints {
                map: ObjectId(map),
                grabbed: g,
                targets: t,
                options: DragOptions {
                    tool: radius.map(|radius| volmorph_lattice::ToolShape::Sphere { radius }),
                    freeze_boundary,
                    realm: None,
                },
            },
        )?;
        change(py, &c)
    }

    /// Set parameters of a map linear in them: `changes` is a list of `(index, (x, y, z))`
    /// (lattice control points by linear index, i fastest; handle targets).
    fn set_parameters<'py>(
        &self,
        py: Python<'py>,
        map: u64,
        changes: Vec<(usize, Bound<'py, PyAny>)>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let changes = changes
            .iter()
            .map(|(i, p)| Ok((*i, vec3("parameter", p)?)))
            .collect::<PyResult<Vec<_>>>()?;
        let c = self.run(
            py,
            Command::SetParameters {
                map: ObjectId(map),
                changes,
            },
        )?;
        change(py, &c)
    }

    /// Undo the last command; the change report, or `None` with nothing to undo.
    fn undo<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.history(py, Scene::undo)
    }

    /// Redo the last undone command; the change report, or `None`.
    fn redo<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.history(py, Scene::redo)
    }

    /// Commands that can be undone.
    #[getter]
    fn undo_depth(&self) -> PyResult<usize> {
        self.with(|s| Ok(s.undo_depth()))
    }

    /// Commands that can be redone.
    #[getter]
    fn redo_depth(&self) -> PyResult<usize> {
        self.with(|s| Ok(s.redo_depth()))
    }

    /// `(id, name, kind)` of every object.
    fn objects(&self) -> PyResult<Vec<(u64, String, &'static str)>> {
        self.with(|s| {
            Ok(s.objects()
                .map(|(id, e)| (id.0, e.name.clone(), e.object.kind()))
                .collect())
        })
    }

    /// The id of the first object named `name`, or `None`.
    fn find(&self, name: &str) -> PyResult<Option<u64>> {
        self.with(|s| Ok(s.find(name).map(|i| i.0)))
    }

    /// The volume of object `id` (a volume or a derived volume), copied out.
    fn volume(&self, py: Python<'_>, id: u64) -> PyResult<PyVolume> {
        let v = self.with(|s| {
            s.volume(ObjectId(id))
                .map(|v| (**v).clone())
                .map_err(|e| to_py(SceneError::new_err, &e))
        })?;
        PyVolume::from_rust(py, v)
    }

    /// The mesh of object `id` as `(vertices, faces)`.
    fn mesh<'py>(
        &self,
        py: Python<'py>,
        id: u64,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let m = self.with(|s| {
            s.mesh(ObjectId(id))
                .cloned()
                .map_err(|e| to_py(SceneError::new_err, &e))
        })?;
        mesh_out(py, &m)
    }

    /// The map of object `id`.
    fn map(&self, id: u64) -> PyResult<PyMap> {
        self.with(|s| {
            s.map(ObjectId(id))
                .map(|m| PyMap { inner: m.clone() })
                .map_err(|e| to_py(SceneError::new_err, &e))
        })
    }
}
