//! The computations: warps, Jacobian maps, isosurfaces, mesh FFD, F-rep models and NURBS
//! volumes. Each is one library call with the GIL released (`Python::detach`).
//!
//! Meshes cross the boundary as `(vertices, faces)`: an N×3 float64 array of physical points
//! and an M×3 uint32 array of triangles (counter-clockwise seen from outside); polygon meshes
//! are triangulated.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use glam::DVec3;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyAny, PyDict};
use volmorph_contour::{DcOptions, McOptions, dual_contouring_any, marching_cubes_any};
use volmorph_frep::output::{MeshMethod, MeshOptions};
use volmorph_frep::{CompileOptions, Shape, Tape, compile_source};
use volmorph_maps::AnyMap;
use volmorph_mesh::Mesh;
use volmorph_trivariate::{AggregateVolume, PolygonizeOptions, ZeroSetMesh};
use volmorph_volume::AnyVolume;
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume};

use crate::error::{FileError, InputError, ModelError, WarpError, input, to_py};
use crate::maps::{PyMap, points, points_out};
use crate::volume::{PyGeometry, PyVolume};

/// A physical point `(x, y, z)` as Python sees it.
type Xyz = (f64, f64, f64);

/// `(vertices, faces)` of a mesh, triangulated.
pub fn mesh_out<'py>(
    py: Python<'py>,
    m: &Mesh,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let t;
    let m = if m.is_triangle_mesh() {
        m
    } else {
        t = m
            .triangulated()
            .map_err(|e| to_py(WarpError::new_err, &e))?;
        &t
    };
    let v = points_out(py, m.positions().to_vec())?;
    let n = m.face_count();
    let f = PyArray1::from_vec(py, m.indices().to_vec())
        .reshape([n, 3])?
        .into_any();
    Ok((v, f))
}

/// A triangle mesh from `(vertices, faces)` arrays.
pub fn mesh_in(vertices: &PyReadonlyArray2<'_, f64>, faces: &Bound<'_, PyAny>) -> PyResult<Mesh> {
    let v = points(vertices)?;
    let f: PyReadonlyArray2<'_, i64> = faces
        .call_method1("astype", ("int64",))
        .and_then(|a| a.extract())
        .map_err(|_| input("faces: expected an M×3 integer array"))?;
    if f.shape()[1] != 3 {
        return Err(input(format!(
            "faces: expected an M×3 array of triangles, got shape {:?}",
            f.shape()
        )));
    }
    let mut tris = Vec::with_capacity(f.shape()[0]);
    for r in f.as_array().rows() {
        let mut t = [0u32; 3];
        for (a, &i) in t.iter_mut().zip(r.iter()) {
            *a = u32::try_from(i)
                .map_err(|_| input(format!("faces: index {i} is not a vertex index")))?;
        }
        tris.push(t);
    }
    Mesh::from_triangles(v, &tris).map_err(|e| to_py(InputError::new_err, &e))
}

fn warp_method(name: &str) -> PyResult<WarpMethod> {
    name.parse::<WarpMethod>()
        .map_err(|e| to_py(InputError::new_err, &e))
}

/// Warp `volume` through `map` onto `geometry` (default: the volume's own grid), as
/// `volmorph warp` does, bit for bit.
///
/// `method` names the direction: `pullback-nearest|linear|cubic` (output voxel x takes the
/// input at map(x), ITK's convention), `pushforward-nearest|antialiased` (each input voxel
/// goes to map(x), True 1992 §5.3–5.4), `inverse-nearest|linear|cubic` (output voxel y takes
/// the input at map⁻¹(y), by Newton iteration). `background` fills voxels nothing reaches;
/// `sampled=N` evaluates the map on an N³ grid and interpolates. With `mask=True` (inverse
/// methods) returns `(volume, mask)`, the mask 1 where Newton did not converge and 2 on folds.
///
/// >>> import numpy as np
/// >>> v = Volume(np.arange(64, dtype=np.float32).reshape(4, 4, 4))
/// >>> w = warp(v, Map.identity(), "pullback-linear")
/// >>> bool((w.array == v.array).all())
/// True
#[pyfunction]
#[pyo3(signature = (volume, map, method="pullback-linear", geometry=None, background=0.0, sampled=None, mask=false))]
#[allow(clippy::too_many_arguments)]
pub fn warp<'py>(
    py: Python<'py>,
    volume: &PyVolume,
    map: &PyMap,
    method: &str,
    geometry: Option<PyGeometry>,
    background: f64,
    sampled: Option<usize>,
    mask: bool,
) -> PyResult<Bound<'py, PyAny>> {
    warp_timed(py, volume, map, method, geometry, background, sampled, mask).map(|(v, _)| v)
}

/// As [`warp`], also returning the seconds spent inside `warp_volume` (the Rust call alone),
/// for the Python-overhead benchmark (`scripts/python_overhead_bench.py`).
#[pyfunction]
#[pyo3(name = "_warp_timed", signature = (volume, map, method="pullback-linear", geometry=None, background=0.0, sampled=None, mask=false))]
#[allow(clippy::too_many_arguments)]
pub fn warp_timed<'py>(
    py: Python<'py>,
    volume: &PyVolume,
    map: &PyMap,
    method: &str,
    geometry: Option<PyGeometry>,
    background: f64,
    sampled: Option<usize>,
    mask: bool,
) -> PyResult<(Bound<'py, PyAny>, f64)> {
    let method = warp_method(method)?;
    if mask && !method.is_inverse() {
        return Err(input("mask=True needs an inverse-* method"));
    }
    if !background.is_finite() {
        return Err(input(format!(
            "background must be finite, got {background}"
        )));
    }
    let out_geometry = geometry.map_or(volume.geometry(), |g| g.inner);
    let options = WarpOptions {
        background,
        mask,
        sampled_nodes: sampled,
    };
    let (out, seconds) = volume.with_view(py, |input_volume| {
        let t = std::time::Instant::now();
        let out = warp_volume(input_volume, &map.inner, &out_geometry, method, &options);
        (out, t.elapsed().as_secs_f64())
    })?;
    let out = out.map_err(|e| to_py(WarpError::new_err, &e))?;
    let v = Bound::new(py, PyVolume::from_rust(py, out.volume)?)?.into_any();
    match out.mask {
        Some(m) if mask => {
            let m = Bound::new(py, PyVolume::from_rust(py, AnyVolume::from(m))?)?;
            Ok(((v, m).into_pyobject(py)?.into_any(), seconds))
        }
        _ => Ok((v, seconds)),
    }
}

/// The Jacobian determinant of `map` at the voxel centres of `geometry` (a float32 Volume;
/// ≤ 0 marks folding), as `volmorph jacobian`.
#[pyfunction]
pub fn jacobian_map(py: Python<'_>, map: &PyMap, geometry: PyGeometry) -> PyResult<PyVolume> {
    let det = py
        .detach(|| volmorph_warp::jacobian::jacobian_determinant(&map.inner, &geometry.inner))
        .map_err(|e| to_py(WarpError::new_err, &e))?;
    PyVolume::from_rust(py, AnyVolume::from(det))
}

/// The surface `value = level` of `volume` as `(vertices, faces)`, by `"marching-cubes"` or
/// `"dual-contouring"`; inside is `value ≥ level` (`inside_below=True`: `≤`, for distances).
#[pyfunction]
#[pyo3(signature = (volume, level, method="marching-cubes", inside_below=false))]
pub fn isosurface<'py>(
    py: Python<'py>,
    volume: &PyVolume,
    level: f64,
    method: &str,
    inside_below: bool,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    if !level.is_finite() {
        return Err(input(format!("level must be finite, got {level}")));
    }
    let v = volume.to_rust(py)?;
    let s = match method {
        "marching-cubes" => {
            py.detach(|| marching_cubes_any(&v, level, &McOptions { inside_below }))
        }
        "dual-contouring" => py.detach(|| {
            dual_contouring_any(
                &v,
                level,
                &DcOptions {
                    inside_below,
                    ..DcOptions::default()
                },
            )
        }),
        m => {
            return Err(input(format!(
                "unknown method {m:?}; one of marching-cubes, dual-contouring"
            )));
        }
    }
    .map_err(|e| to_py(WarpError::new_err, &e))?;
    mesh_out(py, &s.mesh)
}

/// Read a mesh file (OBJ, STL, PLY, OFF) as `(vertices, faces)`.
#[pyfunction]
pub fn read_mesh(py: Python<'_>, path: PathBuf) -> PyResult<(Bound<'_, PyAny>, Bound<'_, PyAny>)> {
    let m = py
        .detach(|| volmorph_mesh::read(&path))
        .map_err(|e| to_py(FileError::new_err, &e))?;
    mesh_out(py, &m)
}

/// Write `(vertices, faces)` to a mesh file (format by extension).
#[pyfunction]
pub fn write_mesh(
    py: Python<'_>,
    path: PathBuf,
    vertices: PyReadonlyArray2<'_, f64>,
    faces: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let m = mesh_in(&vertices, faces)?;
    py.detach(|| volmorph_mesh::write(&path, &m))
        .map_err(|e| to_py(FileError::new_err, &e))
}

fn lattice_of(map: &PyMap) -> PyResult<&volmorph_lattice::BSplineLattice> {
    match &map.inner {
        AnyMap::Lattice(l) => Ok(l),
        other => Err(input(format!(
            "FFD needs a B-spline lattice, got a {} map",
            other.kind()
        ))),
    }
}

/// Free-form deformation of a mesh by a lattice (push-forward), as `volmorph ffd`.
///
/// `mode="vertex"` moves the vertices. `mode="accurate"` builds the exact image (Feng 2002:
/// trimmed Bézier patches); it returns a tessellation within `chordal` (default 1e-3 of the
/// mesh's diagonal) and, with `step="out.step"`, also writes the trimmed surfaces to STEP.
#[pyfunction]
#[pyo3(signature = (vertices, faces, lattice, mode="vertex", chordal=None, step=None))]
pub fn ffd<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    faces: &Bound<'py, PyAny>,
    lattice: &PyMap,
    mode: &str,
    chordal: Option<f64>,
    step: Option<PathBuf>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let m = mesh_in(&vertices, faces)?;
    let l = lattice_of(lattice)?;
    let out = match mode {
        "vertex" => {
            if step.is_some() {
                return Err(input(
                    "STEP output holds trimmed surfaces and needs mode=\"accurate\"",
                ));
            }
            py.detach(|| volmorph_ffd::baseline::vertex_ffd(&m, l))
        }
        "accurate" => py.detach(|| -> Result<Mesh, volmorph_ffd::FfdError> {
            let plan = Arc::new(volmorph_ffd::accurate::AccuratePlan::new(&m, l)?);
            let model = plan.deform(l)?;
            if let Some(path) = &step {
                volmorph_ffd::step::write_step(path, &model)?;
            }
            let tol = match chordal {
                Some(t) => t,
                None => {
                    let (lo, hi) = m.bounding_box().unwrap_or((DVec3::ZERO, DVec3::ONE));
                    1e-3 * (hi - lo).length().max(f64::MIN_POSITIVE)
                }
            };
            volmorph_ffd::tessellate::tessellate(&model, tol)
        }),
        other => {
            return Err(input(format!(
                "unknown FFD mode {other:?}; one of vertex, accurate"
            )));
        }
    }
    .map_err(|e| to_py(ModelError::new_err, &e))?;
    mesh_out(py, &out)
}

/// An F-rep model compiled from HyperFun source: `f(x, y, z) ≥ 0` inside.
///
/// >>> import numpy as np
/// >>> s = Frep("my_model(x[3], a[1]) { array x[3]; my_model = 1 - (x[1]^2 + x[2]^2 + x[3]^2); }")
/// >>> s.evaluate(np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]))
/// array([ 1., -3.])
#[pyclass(name = "Frep", module = "volmorph._volmorph", frozen)]
pub struct PyFrep {
    shape: Shape,
}

impl PyFrep {
    /// Compile `source`; `data_dir` is the folder data files it names are relative to.
    fn compile(
        source: &str,
        params: Option<HashMap<usize, f64>>,
        object: Option<String>,
        data_dir: Option<std::path::PathBuf>,
    ) -> PyResult<Self> {
        let params = params.unwrap_or_default();
        if let Some((k, v)) = params.iter().find(|(_, v)| !v.is_finite()) {
            return Err(input(format!("parameter a{k} must be finite, got {v}")));
        }
        let options = CompileOptions {
            params,
            object,
            data_dir,
            ..CompileOptions::default()
        };
        let shape = compile_source(source, &options).map_err(|e| to_py(ModelError::new_err, &e))?;
        Ok(Self { shape })
    }

    /// The box that frames the model's solid ([`volmorph_frep::extent::Framing`]), its
    /// warning, if any, issued as a Python `UserWarning`.
    fn framed(&self, py: Python<'_>) -> PyResult<(DVec3, DVec3)> {
        let tape = Tape::new(&self.shape);
        let framing =
            py.detach(|| volmorph_frep::extent::Framing::of(&[&tape as &dyn volmorph_frep::Field]));
        if let Some(w) = framing.warning {
            let message = std::ffi::CString::new(w).unwrap_or_default();
            let category = py.get_type::<pyo3::exceptions::PyUserWarning>();
            PyErr::warn(py, category.as_any(), &message, 1)?;
        }
        Ok(framing.bounds)
    }
}

#[pymethods]
impl PyFrep {
    /// Compile `source` (HyperFun text) with parameter values `params` (`{1: a1, …}`,
    /// missing entries 0) and the object `object` (default: the last one).
    #[new]
    #[pyo3(signature = (source, params=None, object=None))]
    fn new(
        source: &str,
        params: Option<HashMap<usize, f64>>,
        object: Option<String>,
    ) -> PyResult<Self> {
        Self::compile(source, params, object, None)
    }

    /// Compile a model file.
    #[staticmethod]
    #[pyo3(signature = (path, params=None, object=None))]
    fn load(
        path: PathBuf,
        params: Option<HashMap<usize, f64>>,
        object: Option<String>,
    ) -> PyResult<Self> {
        let src = std::fs::read_to_string(&path).map_err(|e| {
            FileError::new_err(format!("cannot read model {}: {e}", path.display()))
        })?;
        // Data files the model names (`vmVolume`) are relative to its folder.
        let dir = path.parent().map(std::path::Path::to_path_buf);
        Self::compile(&src, params, object, dir).map_err(|e| {
            Python::attach(|py| ModelError::new_err(format!("{}: {}", path.display(), e.value(py))))
        })
    }

    /// The field at N×3 points (float64, ≥ 0 inside).
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let p = self::points(&points)?;
        let out = py.detach(|| {
            let tape = Tape::new(&self.shape);
            let x: Vec<f64> = p.iter().map(|q| q.x).collect();
            let y: Vec<f64> = p.iter().map(|q| q.y).collect();
            let z: Vec<f64> = p.iter().map(|q| q.z).collect();
            let mut out = vec![0.0; p.len()];
            tape.eval_batch(&x, &y, &z, &mut out);
            out
        });
        Ok(PyArray1::from_vec(py, out).into_any())
    }

    /// The box `((x0, y0, z0), (x1, y1, z1))` that frames the model's solid, the one the
    /// command line samples, meshes and renders when given no bounds
    /// (`volmorph_frep::extent::Framing`): the solid's box by interval arithmetic, enlarged on
    /// every side by 5 % of its largest side. A model with no solid, or one that reaches the
    /// edge of the search window, gets the fallback box `[-1.6, 1.6]³` and a `UserWarning`
    /// saying why.
    fn bounds(&self, py: Python<'_>) -> PyResult<(Xyz, Xyz)> {
        let (lo, hi) = self.framed(py)?;
        Ok((lo.into(), hi.into()))
    }

    /// A grid of `shape` `(nz, ny, nx)` voxel centres whose first and last centres are the
    /// corners of [`bounds`](Self::bounds) (identity direction), ready for `sample` and `mesh`.
    fn grid(&self, py: Python<'_>, shape: (usize, usize, usize)) -> PyResult<PyGeometry> {
        let (lo, hi) = self.framed(py)?;
        let (nz, ny, nx) = shape;
        let inner = volmorph_frep::grid::box_geometry(lo, hi, [nx, ny, nz])
            .map_err(|e| input(format!("grid {shape:?}: {e}")))?;
        Ok(PyGeometry { inner })
    }

    /// The field sampled at the voxel centres of `geometry` (a float32 Volume).
    fn sample(&self, py: Python<'_>, geometry: PyGeometry) -> PyResult<PyVolume> {
        let v = py
            .detach(|| volmorph_frep::grid::sample(&Tape::new(&self.shape), &geometry.inner))
            .map_err(|e| to_py(ModelError::new_err, &e))?;
        PyVolume::from_rust(py, AnyVolume::from(v))
    }

    /// The surface `f = 0` sampled on `geometry`, as `(vertices, faces)`; `method`
    /// `"marching-cubes"` or `"dual-contouring"`; `close=True` caps shapes cut by the box.
    #[pyo3(signature = (geometry, method="marching-cubes", close=false))]
    fn mesh<'py>(
        &self,
        py: Python<'py>,
        geometry: PyGeometry,
        method: &str,
        close: bool,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let method = match method {
            "marching-cubes" => MeshMethod::MarchingCubes,
            "dual-contouring" => MeshMethod::DualContouring,
            m => {
                return Err(input(format!(
                    "unknown method {m:?}; one of marching-cubes, dual-contouring"
                )));
            }
        };
        let s = py
            .detach(|| {
                volmorph_frep::output::mesh(
                    &Tape::new(&self.shape),
                    &geometry.inner,
                    &MeshOptions { method, close },
                )
            })
            .map_err(|e| to_py(ModelError::new_err, &e))?;
        mesh_out(py, &s.mesh)
    }
}

/// A trivariate NURBS volume with attributes (Martin & Cohen).
#[pyclass(name = "Nurbs", module = "volmorph._volmorph", frozen)]
pub struct PyNurbs {
    model: AggregateVolume,
}

fn zero_set<'py>(py: Python<'py>, z: &ZeroSetMesh) -> PyResult<Bound<'py, PyDict>> {
    let (v, f) = mesh_out(py, &z.mesh)?;
    let d = PyDict::new(py);
    d.set_item("vertices", v)?;
    d.set_item("faces", f)?;
    d.set_item("values", PyArray1::from_vec(py, z.values.clone()))?;
    d.set_item("attribute", z.attribute.clone())?;
    Ok(d)
}

#[pymethods]
impl PyNurbs {
    /// Fit a NURBS volume of `order` with `counts` `(nx, ny, nz)` control points (default:
    /// one per voxel, interpolation) to the voxel values of `volume`, stored as attribute
    /// `name`, as `volmorph nurbs fit`.
    #[staticmethod]
    #[pyo3(signature = (volume, order=4, counts=None, name="density"))]
    fn fit(
        py: Python<'_>,
        volume: &PyVolume,
        order: usize,
        counts: Option<(usize, usize, usize)>,
        name: &str,
    ) -> PyResult<Self> {
        let v = volume.to_rust(py)?.to_typed::<f64>();
        let n = counts.map_or(v.geometry().dims, Into::into);
        let fit = py
            .detach(|| volmorph_trivariate::fit::fit_sampled_volume(&v, order, n, name))
            .map_err(|e| to_py(ModelError::new_err, &e))?;
        Ok(Self { model: fit.model })
    }

    /// Read a NURBS volume (volmorph JSON).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let model = volmorph_trivariate::load_volume(&path).map_err(|e| {
            FileError::new_err(format!(
                "cannot load model {}: {}",
                path.display(),
                crate::error::chain(&e)
            ))
        })?;
        Ok(Self { model })
    }

    /// Write the NURBS volume (volmorph JSON).
    fn save(&self, path: PathBuf) -> PyResult<()> {
        volmorph_trivariate::save(&path, &self.model).map_err(|e| to_py(FileError::new_err, &e))
    }

    /// Attribute names.
    #[getter]
    fn attributes(&self) -> Vec<String> {
        self.model
            .attributes()
            .iter()
            .map(|a| a.name().to_owned())
            .collect()
    }

    /// Evaluate at N×3 parameters `(u, v, w)`: `{"points": N×3, "<attribute>": N, …}`.
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        params: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let u = points(&params)?;
        let mut pts = Vec::with_capacity(u.len());
        let mut attrs: Vec<Vec<f64>> =
            vec![Vec::with_capacity(u.len()); self.model.attributes().len()];
        for q in &u {
            let a = q.to_array();
            let p = self
                .model
                .geometry()
                .eval(a)
                .map_err(|e| to_py(ModelError::new_err, &e))?;
            pts.push(DVec3::new(p[0], p[1], p[2]));
            for (out, at) in attrs.iter_mut().zip(self.model.attributes()) {
                let v = at
                    .spline()
                    .eval(a)
                    .map_err(|e| to_py(ModelError::new_err, &e))?;
                out.push(v[0]);
            }
        }
        let d = PyDict::new(py);
        d.set_item("points", points_out(py, pts)?)?;
        for (vals, at) in attrs.into_iter().zip(self.model.attributes()) {
            d.set_item(at.name(), PyArray1::from_vec(py, vals))?;
        }
        Ok(d)
    }

    /// The planar slice `a·x + b·y + c·z + d = 0` (`plane = (a, b, c, d)`), coloured by
    /// `attribute`: `{"vertices", "faces", "values", "attribute"}`.
    #[pyo3(signature = (plane, attribute=None))]
    fn slice<'py>(
        &self,
        py: Python<'py>,
        plane: [f64; 4],
        attribute: Option<String>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let z = py
            .detach(|| {
                volmorph_trivariate::slice(
                    &self.model,
                    plane,
                    attribute.as_deref(),
                    &PolygonizeOptions::default(),
                )
            })
            .map_err(|e| to_py(ModelError::new_err, &e))?;
        zero_set(py, &z)
    }

    /// The isosurface `attribute = level`: `{"vertices", "faces", "values", "attribute"}`.
    #[pyo3(signature = (attribute, level, inside_below=false))]
    fn isosurface<'py>(
        &self,
        py: Python<'py>,
        attribute: &str,
        level: f64,
        inside_below: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let opts = PolygonizeOptions {
            inside_below,
            ..PolygonizeOptions::default()
        };
        let z = py
            .detach(|| volmorph_trivariate::isosurface(&self.model, attribute, level, &opts))
            .map_err(|e| to_py(ModelError::new_err, &e))?;
        zero_set(py, &z)
    }
}
