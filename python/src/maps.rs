//! `Map`: every map kind of `volmorph_maps::AnyMap` (lattices, MLS and thin-plate handle maps,
//! frames, Wendland, bump, NURBS geometries, sampled fields, compositions, inverses).
//!
//! Points are N×3 float64 arrays of physical `(x, y, z)`; they are read in place when
//! C-contiguous (otherwise copied once) and results are moved into numpy without a copy.

use glam::{DMat3, DVec3};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyAny;
use volmorph_deform::{Affine, InverseOptions, SpaceMap};
use volmorph_handles::{HandleSet, TpsKernel};
use volmorph_lattice::BSplineLattice;
use volmorph_maps::{AnyMap, HandleDirection, HandleMethod, HandleOptions};

use crate::error::{FileError, MapError, input, to_py, with_context};
use crate::volume::{PyGeometry, mat3, vec3};

/// Read an N×3 array of finite points.
pub fn points(a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<DVec3>> {
    let s = a.shape();
    if s[1] != 3 {
        return Err(input(format!(
            "expected an N×3 array of points, got shape {s:?}"
        )));
    }
    let v = a.as_array();
    let mut out = Vec::with_capacity(s[0]);
    for (n, r) in v.rows().into_iter().enumerate() {
        let p = DVec3::new(r[0], r[1], r[2]);
        if !p.is_finite() {
            return Err(input(format!(
                "point {n} is not finite: ({}, {}, {})",
                r[0], r[1], r[2]
            )));
        }
        out.push(p);
    }
    Ok(out)
}

/// An N×3 float64 array of `pts` (moved, not copied).
pub fn points_out(py: Python<'_>, pts: Vec<DVec3>) -> PyResult<Bound<'_, PyAny>> {
    let n = pts.len();
    let flat: Vec<f64> = pts.into_iter().flat_map(|p| p.to_array()).collect();
    Ok(PyArray1::from_vec(py, flat).reshape([n, 3])?.into_any())
}

/// Reject maps whose image of a probe point is not finite (NaN in a map's parameters).
fn check_finite(map: &AnyMap, probe: DVec3) -> PyResult<()> {
    let y = map.apply(probe);
    if y.is_finite() {
        Ok(())
    } else {
        Err(MapError::new_err(format!(
            "the {} map is not finite at ({}, {}, {}): its parameters hold NaN or infinity",
            map.kind(),
            probe.x,
            probe.y,
            probe.z
        )))
    }
}

/// A map of physical space to physical space. A map has no direction of its own: `warp`'s
/// method says whether it is read as a pull-back (output point → input point) or as a
/// deformation of the model (push-forward, inverse).
///
/// >>> import numpy as np
/// >>> m = Map.affine(np.eye(3) * 2.0, (1.0, 0.0, 0.0))
/// >>> m.map(np.array([[1.0, 1.0, 1.0]]))
/// array([[3., 2., 2.]])
#[pyclass(name = "Map", module = "volmorph._volmorph", frozen, from_py_object)]
#[derive(Clone)]
pub struct PyMap {
    /// The Rust map.
    pub inner: AnyMap,
}

impl PyMap {
    fn wrap(inner: AnyMap) -> Self {
        Self { inner }
    }
}

#[pymethods]
impl PyMap {
    /// The identity map.
    #[staticmethod]
    fn identity() -> Self {
        Self::wrap(AnyMap::Identity)
    }

    /// The affine map `x ↦ matrix @ x + offset`.
    #[staticmethod]
    fn affine(matrix: &Bound<'_, PyAny>, offset: &Bound<'_, PyAny>) -> PyResult<Self> {
        Ok(Self::wrap(AnyMap::Affine(Affine {
            matrix: mat3("matrix", matrix)?,
            offset: vec3("offset", offset)?,
        })))
    }

    /// The identity B-spline lattice of `counts` `(nx, ny, nz)` control points over the
    /// voxel grid `geometry` (cubic, as `volmorph drag` places it).
    #[staticmethod]
    #[pyo3(signature = (geometry, counts=(9, 9, 9)))]
    fn lattice(geometry: PyGeometry, counts: (usize, usize, usize)) -> PyResult<Self> {
        let l = BSplineLattice::identity_on_voxels(&geometry.inner, counts.into())
            .map_err(|e| to_py(MapError::new_err, &e))?;
        Ok(Self::wrap(AnyMap::Lattice(l)))
    }

    /// A map through point handles: `sources` go to `targets` (N×3 arrays) by `method`
    /// (`"affine"`, `"similarity"`, `"rigid"` MLS, `"tps"` thin-plate spline, `"wendland"`).
    /// With `backward=True` the map sends targets to sources: the pull-back that makes the
    /// content at each source appear at its target (as `volmorph handles warp`).
    ///
    /// `kernel` is the thin-plate spline's radial kernel: `"r"` (the 3-D biharmonic, the
    /// default) or `"r2logr"` (`r² ln r`, McPhail's and Bookstein's); `support` the Wendland
    /// support radius in physical units (default: about a fixed number of neighbours per
    /// handle). Each is refused for the methods that do not use it.
    #[staticmethod]
    #[pyo3(signature = (sources, targets, method="tps", smoothing=0.0, backward=false, kernel=None, support=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_handles(
        py: Python<'_>,
        sources: PyReadonlyArray2<'_, f64>,
        targets: PyReadonlyArray2<'_, f64>,
        method: &str,
        smoothing: f64,
        backward: bool,
        kernel: Option<&str>,
        support: Option<f64>,
    ) -> PyResult<Self> {
        let s = points(&sources)?;
        let t = points(&targets)?;
        if s.len() != t.len() {
            return Err(input(format!(
                "{} sources but {} targets: give one target per source",
                s.len(),
                t.len()
            )));
        }
        let method = HandleMethod::ALL
            .into_iter()
            .find(|m| m.name() == method)
            .ok_or_else(|| {
                input(format!(
                    "unknown handle method {method:?}; one of {}",
                    HandleMethod::ALL.map(HandleMethod::name).join(", ")
                ))
            })?;
        if !smoothing.is_finite() || smoothing < 0.0 {
            return Err(input(format!(
                "smoothing must be finite and ≥ 0, got {smoothing}"
            )));
        }
        let set = HandleSet {
            dim: 3,
            points: s.into_iter().zip(t).collect(),
            segments: Vec::new(),
            frames: Vec::new(),
        };
        let kernel = match kernel {
            None => TpsKernel::default(),
            Some(_) if method != HandleMethod::Tps => {
                return Err(input(format!(
                    "kernel: only the tps method has a kernel choice (method is {})",
                    method.name()
                )));
            }
            Some(k) => TpsKernel::parse(k).map_err(|e| input(e.to_string()))?,
        };
        if let Some(r) = support {
            if method != HandleMethod::Wendland {
                return Err(input(format!(
                    "support={r}: only the wendland method has a support radius (method is {})",
                    method.name()
                )));
            }
            if !(r.is_finite() && r > 0.0) {
                return Err(input(format!("support must be finite and > 0, got {r}")));
            }
        }
        let options = HandleOptions {
            smoothing,
            support,
            kernel,
            ..HandleOptions::default()
        };
        let direction = if backward {
            HandleDirection::TargetsToSources
        } else {
            HandleDirection::SourcesToTargets
        };
        let m = py
            .detach(|| volmorph_maps::handle_map(&set, method, &options, direction))
            .map_err(|e| to_py(MapError::new_err, &e))?;
        Ok(Self::wrap(m))
    }

    /// Read a map file: volmorph map JSON (any kind), ITK `.tfm` or plastimatch `.bxf`.
    #[staticmethod]
    fn load(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Self> {
        let m = py
            .detach(|| volmorph_maps::read_map(&path))
            .map_err(|e| with_context(FileError::new_err, "cannot read the map", &e))?;
        Ok(Self::wrap(m))
    }

    /// Write the map (the format follows the extension: `.json`, `.tfm`, `.bxf`).
    fn save(&self, py: Python<'_>, path: std::path::PathBuf) -> PyResult<()> {
        py.detach(|| volmorph_maps::write_map(&path, &self.inner))
            .map_err(|e| to_py(FileError::new_err, &e))
    }

    /// The map from volmorph map JSON text.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        let m = AnyMap::from_json(text).map_err(|e| to_py(MapError::new_err, &e))?;
        Ok(Self::wrap(m))
    }

    /// The map as volmorph map JSON text.
    fn to_json(&self) -> PyResult<String> {
        self.inner
            .to_json()
            .map_err(|e| to_py(MapError::new_err, &e))
    }

    /// The kind's name, as in the JSON's `"kind"` (`"lattice"`, `"thin-plate"`, …).
    #[getter]
    fn kind(&self) -> &'static str {
        self.inner.kind()
    }

    /// A one-line description of the map.
    #[getter]
    fn summary(&self) -> String {
        self.inner.summary()
    }

    /// The images of N×3 points, an N×3 array. Raises `MapError` if an image is not finite.
    fn map<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let p = self::points(&points)?;
        let out = py.detach(|| {
            let mut out = vec![DVec3::ZERO; p.len()];
            self.inner.apply_batch(&p, &mut out).map(|()| out)
        });
        let out = out.map_err(|e| to_py(MapError::new_err, &e))?;
        if let Some(n) = out.iter().position(|q| !q.is_finite()) {
            return Err(MapError::new_err(format!(
                "the {} map is not finite at point {n} ({}, {}, {})",
                self.inner.kind(),
                p[n].x,
                p[n].y,
                p[n].z
            )));
        }
        points_out(py, out)
    }

    /// The Jacobian matrices at N×3 points, an N×3×3 array: `J[n, r, c] = ∂map_r/∂x_c`.
    fn jacobian<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let p = self::points(&points)?;
        let n = p.len();
        let flat: Vec<f64> = py.detach(|| {
            p.iter()
                .flat_map(|&x| {
                    let j: DMat3 = self.inner.jacobian(x);
                    crate::volume::rows(j).into_iter().flatten()
                })
                .collect()
        });
        Ok(PyArray1::from_vec(py, flat).reshape([n, 3, 3])?.into_any())
    }

    /// The inverse map (exact for affine maps and compositions of them, Newton iteration
    /// otherwise).
    fn inverse(&self) -> PyResult<Self> {
        let m = self
            .inner
            .clone()
            .inverse(InverseOptions::default())
            .map_err(|e| to_py(MapError::new_err, &e))?;
        Ok(Self::wrap(m))
    }

    /// The composition applying `self` first, then `other`: `x ↦ other(self(x))`.
    fn then(&self, other: &PyMap) -> Self {
        Self::wrap(self.inner.clone().then(other.inner.clone()))
    }

    /// For a lattice: the control points, an array of shape `(nz, ny, nx, 3)` (physical).
    #[getter]
    fn control_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let AnyMap::Lattice(l) = &self.inner else {
            return Err(input(format!(
                "control points belong to lattices, this is a {} map",
                self.inner.kind()
            )));
        };
        let [cx, cy, cz] = l.counts();
        let flat: Vec<f64> = l
            .control_points()
            .into_iter()
            .flat_map(|p| p.to_array())
            .collect();
        Ok(PyArray1::from_vec(py, flat)
            .reshape([cz, cy, cx, 3])?
            .into_any())
    }

    /// For a lattice: a copy with the control points `points` (shape `(nz, ny, nx, 3)`).
    fn with_control_points(&self, points: &Bound<'_, PyAny>) -> PyResult<Self> {
        let AnyMap::Lattice(l) = &self.inner else {
            return Err(input(format!(
                "control points belong to lattices, this is a {} map",
                self.inner.kind()
            )));
        };
        let mut l = l.clone();
        let [cx, cy, cz] = l.counts();
        let a: numpy::PyReadonlyArrayDyn<'_, f64> = points
            .extract()
            .map_err(|_| input("control points: expected a float64 array"))?;
        if a.shape() != [cz, cy, cx, 3] {
            return Err(input(format!(
                "control points: expected shape {:?}, got {:?}",
                [cz, cy, cx, 3],
                a.shape()
            )));
        }
        let v = a.as_array();
        for k in 0..cz {
            for j in 0..cy {
                for i in 0..cx {
                    let p = DVec3::new(v[[k, j, i, 0]], v[[k, j, i, 1]], v[[k, j, i, 2]]);
                    l.set_control_point([i, j, k], p)
                        .map_err(|e| to_py(MapError::new_err, &e))?;
                }
            }
        }
        let m = AnyMap::Lattice(l);
        check_finite(&m, DVec3::ZERO)?;
        Ok(Self::wrap(m))
    }

    fn __repr__(&self) -> String {
        format!("Map({})", self.inner.summary())
    }
}
