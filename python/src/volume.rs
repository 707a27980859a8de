//! `Geometry` and `Volume`: numpy arrays with volmorph's physical space (ITK convention).
//!
//! Layout: a volume of `nx × ny × nz` voxels is a C-contiguous numpy array of shape
//! `(nz, ny, nx)` (x fastest, as SimpleITK's `GetArrayFromImage`), which is exactly the
//! memory order of `volmorph_volume::Volume`. Spacing and origin are `(x, y, z)`; the
//! direction is a 3×3 matrix whose column `c` is the unit physical direction of index axis
//! `c` (ITK's `GetDirection` read row by row).
//!
//! Copies: a `Volume` keeps the numpy array it was made from (no copy). A warp reads the
//! numpy buffer in place ([`PyVolume::with_view`]: a readonly borrow held across the call
//! with the GIL released); the other computations copy the voxels once into the Rust buffer
//! they read ([`PyVolume::to_rust`]); results move from Rust into numpy without a copy
//! (`PyArray::from_vec`).

use glam::{DMat3, DVec3};
use numpy::{
    Element, PyArray1, PyArray3, PyArrayMethods, PyReadonlyArray2, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyAny;
use volmorph_volume::{AnyVolume, AnyVolumeRef, Geometry, VolumeRef, with_volume};

use crate::error::{FileError, input, to_py};

/// Read a 3-vector from a Python sequence, requiring finite values.
pub fn vec3(what: &str, v: &Bound<'_, PyAny>) -> PyResult<DVec3> {
    let a: Vec<f64> = v
        .extract()
        .map_err(|_| input(format!("{what}: expected three numbers (x, y, z)")))?;
    let [x, y, z] = a[..] else {
        return Err(input(format!(
            "{what}: expected three numbers (x, y, z), got {}",
            a.len()
        )));
    };
    let p = DVec3::new(x, y, z);
    if !p.is_finite() {
        return Err(input(format!("{what}: values must be finite, got {a:?}")));
    }
    Ok(p)
}

/// Read a 3×3 matrix (rows) into a `DMat3`.
pub fn mat3(what: &str, m: &Bound<'_, PyAny>) -> PyResult<DMat3> {
    let rows: Vec<Vec<f64>> = m
        .extract()
        .map_err(|_| input(format!("{what}: expected a 3×3 matrix")))?;
    if rows.len() != 3 || rows.iter().any(|r| r.len() != 3) {
        return Err(input(format!("{what}: expected a 3×3 matrix")));
    }
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err(input(format!("{what}: values must be finite")));
    }
    let col = |c: usize| DVec3::new(rows[0][c], rows[1][c], rows[2][c]);
    Ok(DMat3::from_cols(col(0), col(1), col(2)))
}

/// The rows of `m`.
pub fn rows(m: DMat3) -> [[f64; 3]; 3] {
    let r = |i: usize| [m.col(0)[i], m.col(1)[i], m.col(2)[i]];
    [r(0), r(1), r(2)]
}

/// The physical space of a voxel grid: `shape` `(nz, ny, nx)`, `spacing` and `origin`
/// `(x, y, z)`, `direction` (columns = axis directions). Voxel `(i, j, k)` (array element
/// `[k, j, i]`) has its centre at `origin + direction @ (spacing * (i, j, k))`.
///
/// >>> g = Geometry((4, 5, 6), spacing=(0.5, 0.5, 2.0))
/// >>> g.shape, g.spacing
/// ((4, 5, 6), (0.5, 0.5, 2.0))
#[pyclass(
    name = "Geometry",
    module = "volmorph._volmorph",
    frozen,
    eq,
    from_py_object
)]
#[derive(Clone, Copy, PartialEq)]
pub struct PyGeometry {
    /// The Rust geometry.
    pub inner: Geometry,
}

#[pymethods]
impl PyGeometry {
    #[new]
    #[pyo3(signature = (shape, spacing=None, origin=None, direction=None))]
    fn new(
        shape: (usize, usize, usize),
        spacing: Option<&Bound<'_, PyAny>>,
        origin: Option<&Bound<'_, PyAny>>,
        direction: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let (nz, ny, nx) = shape;
        let mut g = Geometry::new([nx, ny, nz]);
        if let Some(s) = spacing {
            g.spacing = vec3("spacing", s)?;
        }
        if let Some(o) = origin {
            g.origin = vec3("origin", o)?;
        }
        if let Some(d) = direction {
            g.direction = mat3("direction", d)?;
        }
        g.validate_unbounded()
            .map_err(|e| input(format!("geometry: {e}")))?;
        Ok(Self { inner: g })
    }

    /// Array shape `(nz, ny, nx)`.
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        let [nx, ny, nz] = self.inner.dims;
        (nz, ny, nx)
    }

    /// Voxel spacing `(x, y, z)`, physical units.
    #[getter]
    fn spacing(&self) -> (f64, f64, f64) {
        self.inner.spacing.into()
    }

    /// Centre of voxel `(0, 0, 0)`, physical `(x, y, z)`.
    #[getter]
    fn origin(&self) -> (f64, f64, f64) {
        self.inner.origin.into()
    }

    /// Direction matrix as rows; column `c` is the direction of index axis `c`.
    #[getter]
    fn direction(&self) -> [[f64; 3]; 3] {
        rows(self.inner.direction)
    }

    /// Physical points of continuous indices `(i, j, k)` (an N×3 array, x index first).
    fn index_to_physical<'py>(
        &self,
        py: Python<'py>,
        index: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let pts = crate::maps::points(&index)?;
        let out: Vec<DVec3> = pts
            .iter()
            .map(|&p| self.inner.index_to_physical(p))
            .collect();
        crate::maps::points_out(py, out)
    }

    /// Continuous indices `(i, j, k)` of physical points (an N×3 array).
    fn physical_to_index<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let pts = crate::maps::points(&points)?;
        let out: Vec<DVec3> = pts
            .iter()
            .map(|&p| self.inner.physical_to_index(p))
            .collect();
        crate::maps::points_out(py, out)
    }

    fn __repr__(&self) -> String {
        format!(
            "Geometry(shape={:?}, spacing={:?}, origin={:?}, direction={:?})",
            self.shape(),
            self.spacing(),
            self.origin(),
            self.direction()
        )
    }
}

/// A sampled volume: a numpy array of shape `(nz, ny, nx)` and its physical geometry.
///
/// The array must be C-contiguous and of dtype uint8, int8, uint16, int16, uint32, int32,
/// float32 or float64; the Volume keeps it without copying (`v.array is a`).
///
/// >>> import numpy as np
/// >>> a = np.zeros((4, 5, 6), dtype=np.float32)
/// >>> v = Volume(a, spacing=(1.0, 1.0, 2.0), origin=(0.0, 0.0, -3.0))
/// >>> v.array is a, v.dtype, v.spacing
/// (True, 'float32', (1.0, 1.0, 2.0))
#[pyclass(name = "Volume", module = "volmorph._volmorph", frozen)]
pub struct PyVolume {
    array: Py<PyAny>,
    geometry: Geometry,
}

/// Names of the accepted dtypes, for messages.
const DTYPES: &str = "uint8, int8, uint16, int16, uint32, int32, float32, float64";

/// Run `f` on the voxels of `array` read in place, with the GIL released, if its dtype is
/// `T`. The readonly borrow (which makes other Rust borrowers of the array fail rather than
/// write) is held until `f` returns.
fn typed_view<T, R, F>(array: &Bound<'_, PyAny>, g: Geometry, f: F) -> PyResult<Result<R, F>>
where
    T: Element + volmorph_volume::Voxel,
    for<'a> AnyVolumeRef<'a>: From<VolumeRef<'a, T>>,
    R: Send,
    F: for<'a> FnOnce(AnyVolumeRef<'a>) -> R + Send,
{
    let Ok(a) = array.cast::<PyArray3<T>>() else {
        return Ok(Err(f));
    };
    let r = a.readonly();
    let s = r
        .as_slice()
        .map_err(|_| input("the array must be C-contiguous"))?;
    let v = VolumeRef::from_slice(g, s).map_err(|e| input(e.to_string()))?;
    Ok(Ok(array.py().detach(move || f(AnyVolumeRef::from(v)))))
}

impl PyVolume {
    /// Run `f` with the GIL released on the voxels read in place from the numpy array (no
    /// copy; see the module docs). The array stays borrowed readonly while `f` runs; Python
    /// code of other threads must not write it meanwhile (numpy has no lock for that).
    ///
    /// # Errors
    /// An `InputError` if the array changed layout since it was checked.
    pub fn with_view<R, F>(&self, py: Python<'_>, f: F) -> PyResult<R>
    where
        R: Send,
        F: for<'a> FnOnce(AnyVolumeRef<'a>) -> R + Send,
    {
        let a = self.array.bind(py);
        let g = self.geometry;
        // Each dtype in turn: `f` comes back unused when the array is not of that type.
        macro_rules! try_types {
            ($f:ident; $($t:ty),*) => {$(
                let $f = match typed_view::<$t, R, F>(a, g, $f)? {
                    Ok(r) => return Ok(r),
                    Err(f) => f,
                };
            )*};
        }
        try_types!(f; u8, i8, u16, i16, u32, i32, f32, f64);
        drop(f);
        Err(input(format!("unsupported dtype; one of {DTYPES}")))
    }

    /// Check `array` (a numpy array, 3-D, C-contiguous, a supported dtype) against `g`.
    fn checked(array: &Bound<'_, PyAny>, g: Geometry) -> PyResult<Self> {
        let a = array.cast::<PyUntypedArray>().map_err(|_| {
            input(format!(
                "expected a numpy array, got {}",
                array
                    .get_type()
                    .name()
                    .map_or_else(|_| "?".into(), |n| n.to_string())
            ))
        })?;
        if a.ndim() != 3 {
            return Err(input(format!(
                "expected a 3-D array of shape (nz, ny, nx), got {} dimensions {:?}",
                a.ndim(),
                a.shape()
            )));
        }
        let dt = a.dtype().to_string();
        if !DTYPES.split(", ").any(|d| d == dt) {
            return Err(input(format!("unsupported dtype {dt}; one of {DTYPES}")));
        }
        if !a.is_c_contiguous() {
            return Err(input(
                "the array is not C-contiguous (a transposed or strided view); pass \
                 numpy.ascontiguousarray(a)",
            ));
        }
        let s = a.shape();
        if [s[2], s[1], s[0]] != g.dims {
            return Err(input(format!(
                "array shape {s:?} does not match the geometry's shape {:?}",
                [g.dims[2], g.dims[1], g.dims[0]]
            )));
        }
        g.validate().map_err(|e| input(format!("geometry: {e}")))?;
        Ok(Self {
            array: array.clone().unbind(),
            geometry: g,
        })
    }

    /// The voxels copied into a Rust volume (one copy, read through [`PyVolume::with_view`];
    /// see the module docs).
    ///
    /// # Errors
    /// A `FileError` if the copy exceeds the memory budget; an `InputError` if the array
    /// changed layout since it was checked.
    pub fn to_rust(&self, py: Python<'_>) -> PyResult<AnyVolume> {
        self.with_view(py, |v| {
            volmorph_io::check_elems(
                "the volume's Rust copy",
                v.geometry().len() as u64,
                v.voxel_type().size() as u64,
            )
            .map(|_| v.to_owned_volume())
        })?
        .map_err(|e| to_py(FileError::new_err, &e))
    }

    /// Move a Rust volume into a new Volume (no copy of the voxels).
    pub fn from_rust(py: Python<'_>, v: AnyVolume) -> PyResult<Self> {
        let geometry = *v.geometry();
        let [nx, ny, nz] = geometry.dims;
        let array = with_volume!(v, v => PyArray1::from_vec(py, v.into_data())
            .reshape([nz, ny, nx])?
            .into_any()
            .unbind());
        Ok(Self { array, geometry })
    }

    /// The geometry.
    pub fn geometry(&self) -> Geometry {
        self.geometry
    }
}

#[pymethods]
impl PyVolume {
    #[new]
    #[pyo3(signature = (array, spacing=None, origin=None, direction=None, geometry=None))]
    fn new(
        array: &Bound<'_, PyAny>,
        spacing: Option<&Bound<'_, PyAny>>,
        origin: Option<&Bound<'_, PyAny>>,
        direction: Option<&Bound<'_, PyAny>>,
        geometry: Option<PyGeometry>,
    ) -> PyResult<Self> {
        let shape: Vec<usize> = array
            .getattr("shape")
            .and_then(|s| s.extract())
            .map_err(|_| input("expected a numpy array"))?;
        let mut g = match geometry {
            Some(g) => {
                if spacing.is_some() || origin.is_some() || direction.is_some() {
                    return Err(input(
                        "give either geometry= or spacing/origin/direction, not both",
                    ));
                }
                g.inner
            }
            None => match shape[..] {
                [nz, ny, nx] => Geometry::new([nx, ny, nz]),
                _ => Geometry::new([0, 0, 0]),
            },
        };
        if let Some(s) = spacing {
            g.spacing = vec3("spacing", s)?;
        }
        if let Some(o) = origin {
            g.origin = vec3("origin", o)?;
        }
        if let Some(d) = direction {
            g.direction = mat3("direction", d)?;
        }
        Self::checked(array, g)
    }

    /// Read a volume file of any format volmorph knows (by extension: .nii/.nii.gz, .mha/.mhd,
    /// .nrrd/.nhdr, .vtk, .vti, .mgh/.mgz, DICOM files and folders, raw with a header).
    ///
    /// Raises `FileError` naming the file and field on bad input.
    #[staticmethod]
    fn read(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Self> {
        let v = py
            .detach(|| volmorph_volume_io::read(&path))
            .map_err(|e| to_py(FileError::new_err, &e))?;
        Self::from_rust(py, v)
    }

    /// Write the volume; the format follows the extension (as `Volume.read`). The file is
    /// written atomically (a failed write leaves no partial file).
    fn write(&self, py: Python<'_>, path: std::path::PathBuf) -> PyResult<()> {
        let v = self.to_rust(py)?;
        py.detach(|| volmorph_volume_io::write(&path, &v))
            .map_err(|e| to_py(FileError::new_err, &e))
    }

    /// The numpy array (shape `(nz, ny, nx)`), shared, not copied.
    #[getter]
    fn array(&self, py: Python<'_>) -> Py<PyAny> {
        self.array.clone_ref(py)
    }

    /// The array (as `array`), so `numpy.asarray(volume)` works without a copy.
    #[pyo3(signature = (dtype=None, copy=None))]
    fn __array__<'py>(
        &self,
        py: Python<'py>,
        dtype: Option<&Bound<'py, PyAny>>,
        copy: Option<bool>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let np = py.import("numpy")?;
        let a = self.array.bind(py);
        let f = if copy == Some(true) {
            "array"
        } else {
            "asarray"
        };
        np.call_method1(f, (a, dtype))
    }

    /// The numpy dtype name (`"uint16"`, …).
    #[getter]
    fn dtype(&self, py: Python<'_>) -> PyResult<String> {
        Ok(self.array.bind(py).getattr("dtype")?.str()?.to_string())
    }

    /// The array shape `(nz, ny, nx)`.
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        PyGeometry {
            inner: self.geometry,
        }
        .shape()
    }

    /// The geometry.
    #[getter(geometry)]
    fn py_geometry(&self) -> PyGeometry {
        PyGeometry {
            inner: self.geometry,
        }
    }

    /// Voxel spacing `(x, y, z)` (as `Geometry.spacing`).
    #[getter]
    fn spacing(&self) -> (f64, f64, f64) {
        self.py_geometry().spacing()
    }

    /// Centre of voxel `(0, 0, 0)` (as `Geometry.origin`).
    #[getter]
    fn origin(&self) -> (f64, f64, f64) {
        self.py_geometry().origin()
    }

    /// Direction matrix as rows (as `Geometry.direction`).
    #[getter]
    fn direction(&self) -> [[f64; 3]; 3] {
        self.py_geometry().direction()
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "Volume(shape={:?}, dtype={}, spacing={:?}, origin={:?})",
            self.shape(),
            self.dtype(py)?,
            self.spacing(),
            self.origin()
        ))
    }
}
