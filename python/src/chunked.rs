//! Chunked pull-back and push-forward and OME-Zarr stores, the Rust half of `volmorph.dask`.
//!
//! Boxes cross this boundary in numpy order: `start` and `stop` are `(z, y, x)` voxel indices
//! (half-open), as dask slices them. Each call is one library call
//! ([`volmorph_warp::chunked`], [`volmorph_volume_io::omezarr`]) with the GIL released.

use std::path::PathBuf;

use pyo3::prelude::*;
use volmorph_volume::{IndexBox, VoxelType};
use volmorph_volume_io::omezarr::{
    self, OmeZarrReader, OmeZarrWriter, ZarrVersion, ZarrWriteOptions,
};
use volmorph_warp::apply::WarpMethod;
use volmorph_warp::chunked::push::{self, PushMethod, PushSource};
use volmorph_warp::chunked::{
    ChunkGrid, ChunkedMethod, chunk_geometry, chunk_indices, chunk_preimage as preimage,
    preimage_box, pull_chunk, sample_chunk,
};
use volmorph_warp::pullback::ResampleOptions;

use crate::error::{FileError, WarpError, input, to_py};
use crate::maps::PyMap;
use crate::volume::{PyGeometry, PyVolume};

type Zyx = (usize, usize, usize);

/// The chunked form of `method` with `background`: the library's one policy
/// ([`ChunkedMethod::new`]).
fn chunked_method(method: &str, background: f64) -> PyResult<ChunkedMethod> {
    let m: WarpMethod = method
        .parse()
        .map_err(|e: volmorph_warp::WarpError| to_py(crate::error::InputError::new_err, &e))?;
    ChunkedMethod::new(m, background).map_err(|e| to_py(crate::error::InputError::new_err, &e))
}

/// How `method` with `background` runs chunk by chunk: `"pullback"` (`chunk_preimage`, then
/// `warp_chunk` or `warp_zarr_chunk` per chunk) or `"push"` (`push_plan`, then `push_chunk` or
/// `push_zarr_chunk` per chunk). The library's one policy of what chunks
/// ([`ChunkedMethod::new`]); raises `InputError` naming the methods that do.
#[pyfunction]
#[pyo3(signature = (method, background=0.0))]
pub fn chunked_kind(method: &str, background: f64) -> PyResult<&'static str> {
    Ok(match chunked_method(method, background)? {
        ChunkedMethod::Pullback(_) => "pullback",
        ChunkedMethod::Push(_) => "push",
    })
}

/// The pull-back options of `method` (`pullback-linear` or `pullback-nearest`).
fn options(method: &str, background: f64) -> PyResult<ResampleOptions> {
    match chunked_method(method, background)? {
        ChunkedMethod::Pullback(o) => Ok(o),
        ChunkedMethod::Push(_) => Err(input(format!(
            "{method} is a push-forward: plan it with push_plan and run push_chunk or \
             push_zarr_chunk"
        ))),
    }
}

/// The push-forward of `method` (`pushforward-antialiased` or `pushforward-nearest`).
fn push_method(method: &str, background: f64) -> PyResult<PushMethod> {
    match chunked_method(method, background)? {
        ChunkedMethod::Push(m) => Ok(m),
        ChunkedMethod::Pullback(_) => Err(input(format!(
            "{method} is a pull-back: use chunk_preimage and warp_chunk or warp_zarr_chunk"
        ))),
    }
}

/// The numpy dtype name of a voxel type.
fn numpy_dtype(t: VoxelType) -> &'static str {
    match t {
        VoxelType::U8 => "uint8",
        VoxelType::I8 => "int8",
        VoxelType::U16 => "uint16",
        VoxelType::I16 => "int16",
        VoxelType::U32 => "uint32",
        VoxelType::I32 => "int32",
        VoxelType::F32 => "float32",
        VoxelType::F64 => "float64",
    }
}

/// `(z, y, x)` start and stop → an index box (x, y, z).
fn index_box(start: Zyx, stop: Zyx) -> IndexBox {
    IndexBox {
        start: [start.2, start.1, start.0],
        end: [stop.2, stop.1, stop.0],
    }
}

fn zyx(b: IndexBox) -> (Zyx, Zyx) {
    (
        (b.start[2], b.start[1], b.start[0]),
        (b.end[2], b.end[1], b.end[0]),
    )
}

/// The box of `input` voxels (`(start, stop)`, each `(z, y, x)`) that the output chunk
/// `start..stop` of `output` reads when pulled back through `map` with `method`, or `None`
/// if it reads none (every voxel maps outside the input). Exact: computed from the indices
/// the chunk samples, widened by the kernel support and a one-voxel margin.
#[pyfunction]
#[pyo3(signature = (map, input_geometry, output_geometry, start, stop, method="pullback-linear"))]
pub fn chunk_preimage(
    py: Python<'_>,
    map: &PyMap,
    input_geometry: PyGeometry,
    output_geometry: PyGeometry,
    start: Zyx,
    stop: Zyx,
    method: &str,
) -> PyResult<Option<(Zyx, Zyx)>> {
    let o = options(method, 0.0)?;
    let b = py
        .detach(|| {
            preimage(
                &map.inner,
                &input_geometry.inner,
                &output_geometry.inner,
                index_box(start, stop),
                &o,
            )
        })
        .map_err(|e| to_py(WarpError::new_err, &e))?;
    Ok((!b.is_empty()).then(|| zyx(b)))
}

/// Pull back the output chunk `start..stop` of `output` from `region`, the voxels of the box
/// of the input starting at `region_start` (`(z, y, x)`); the box must hold the chunk's
/// preimage (see `chunk_preimage`). The result equals the same voxels of
/// `warp(volume, map, method, output)` bit for bit.
#[pyfunction]
#[pyo3(signature = (region, region_start, map, input_geometry, output_geometry, start, stop, method="pullback-linear", background=0.0))]
#[allow(clippy::too_many_arguments)]
pub fn warp_chunk(
    py: Python<'_>,
    region: &PyVolume,
    region_start: Zyx,
    map: &PyMap,
    input_geometry: PyGeometry,
    output_geometry: PyGeometry,
    start: Zyx,
    stop: Zyx,
    method: &str,
    background: f64,
) -> PyResult<PyVolume> {
    let o = options(method, background)?;
    let data = region.to_rust(py)?;
    let chunk = index_box(start, stop);
    let rs = [region_start.2, region_start.1, region_start.0];
    let out = py.detach(|| -> Result<_, String> {
        let (ig, og) = (&input_geometry.inner, &output_geometry.inner);
        let mut idx = chunk_indices(&map.inner, ig, og, chunk).map_err(|e| e.to_string())?;
        let need = preimage_box(&idx, ig.dims, &o);
        let have = data.geometry().dims;
        let inside = need.is_empty()
            || (0..3).all(|a| need.start[a] >= rs[a] && need.end[a] <= rs[a] + have[a]);
        if !inside {
            return Err(format!(
                "the region (start {region_start:?}, shape {:?}) does not hold the chunk's \
                 preimage {:?}",
                (have[2], have[1], have[0]),
                zyx(need)
            ));
        }
        sample_chunk(&mut idx, &data, rs, &chunk_geometry(og, chunk), &o).map_err(|e| e.to_string())
    });
    let out = out.map_err(WarpError::new_err)?;
    PyVolume::from_rust(py, out)
}

/// Pull back the output chunk `start..stop` of `output` from resolution `level` of the
/// OME-Zarr image at `path`, reading only the chunk's preimage box of the store.
#[pyfunction]
#[pyo3(signature = (path, map, output_geometry, start, stop, method="pullback-linear", background=0.0, level=0))]
#[allow(clippy::too_many_arguments)]
pub fn warp_zarr_chunk(
    py: Python<'_>,
    path: PathBuf,
    map: &PyMap,
    output_geometry: PyGeometry,
    start: Zyx,
    stop: Zyx,
    method: &str,
    background: f64,
    level: usize,
) -> PyResult<PyVolume> {
    let o = options(method, background)?;
    let out = py.detach(|| -> Result<_, String> {
        let reader = OmeZarrReader::open_level(&path, level).map_err(|e| e.to_string())?;
        pull_chunk(
            &map.inner,
            reader.geometry(),
            &output_geometry.inner,
            index_box(start, stop),
            &o,
            |b| reader.read_box(b).map_err(volmorph_warp::WarpError::from),
        )
        .map_err(|e| e.to_string())
    });
    let out = out.map_err(WarpError::new_err)?;
    PyVolume::from_rust(py, out)
}

/// A box `(start, stop)` in numpy order.
type ZyxBox = (Zyx, Zyx);

/// One source of a push-forward chunk: `(slab, input box, output box)`, boxes `(z, y, x)`.
type PySource = (usize, ZyxBox, ZyxBox);

fn to_sources(sources: &[PySource]) -> Vec<PushSource> {
    sources
        .iter()
        .map(|&(slab, (a, b), (c, d))| PushSource {
            slab,
            input: index_box(a, b),
            output: index_box(c, d),
        })
        .collect()
}

/// Plan the chunked push-forward of an input on `input_geometry` through `map` onto
/// `output_geometry` cut into `chunks` (dask's normalised chunks: the chunk lengths along z,
/// y and x). Returns, for every output chunk, `(block index (z, y, x), input box or None,
/// sources)`: the box of the input the chunk reads (`(start, stop)`, `(z, y, x)`; `None` when
/// nothing reaches it) and its sources `(slab, input box, output box)` in slab order, to hand
/// to `push_chunk` or `push_zarr_chunk`. One evaluation of the map over the input, in
/// parallel threads, with the GIL released.
#[pyfunction]
#[pyo3(signature = (map, input_geometry, output_geometry, chunks, method="pushforward-antialiased", background=0.0))]
#[allow(clippy::type_complexity)]
pub fn push_plan(
    py: Python<'_>,
    map: &PyMap,
    input_geometry: PyGeometry,
    output_geometry: PyGeometry,
    chunks: (Vec<usize>, Vec<usize>, Vec<usize>),
    method: &str,
    background: f64,
) -> PyResult<Vec<(Zyx, Option<ZyxBox>, Vec<PySource>)>> {
    let m = push_method(method, background)?;
    let grid = ChunkGrid::from_sizes([chunks.2, chunks.1, chunks.0])
        .map_err(|e| to_py(crate::error::InputError::new_err, &e))?;
    let plan = py
        .detach(|| {
            push::plan_push(
                &map.inner,
                &input_geometry.inner,
                &output_geometry.inner,
                &m,
                &grid,
            )
        })
        .map_err(|e| to_py(WarpError::new_err, &e))?;
    Ok((0..grid.len())
        .map(|c| {
            let p = grid.position(c);
            let b = plan.input_box(c);
            let sources = plan
                .sources(c)
                .iter()
                .map(|s| (s.slab, zyx(s.input), zyx(s.output)))
                .collect();
            ((p[2], p[1], p[0]), (!b.is_empty()).then(|| zyx(b)), sources)
        })
        .collect())
}

/// Push forward the output chunk `start..stop` of `output_geometry` from `region`, the
/// voxels of the input box starting at `region_start` (`(z, y, x)`), which must be the
/// chunk's input box from `push_plan` (or the one voxel at the origin when it has none), with
/// the chunk's `sources` from `push_plan`. The result equals the same voxels of
/// `warp(volume, map, method, output_geometry)` bit for bit.
#[pyfunction]
#[pyo3(signature = (region, region_start, sources, map, input_geometry, output_geometry, start, stop, method="pushforward-antialiased", background=0.0))]
#[allow(clippy::too_many_arguments)]
pub fn push_chunk(
    py: Python<'_>,
    region: &PyVolume,
    region_start: Zyx,
    sources: Vec<PySource>,
    map: &PyMap,
    input_geometry: PyGeometry,
    output_geometry: PyGeometry,
    start: Zyx,
    stop: Zyx,
    method: &str,
    background: f64,
) -> PyResult<PyVolume> {
    let m = push_method(method, background)?;
    let data = region.to_rust(py)?;
    let sources = to_sources(&sources);
    let rs = [region_start.2, region_start.1, region_start.0];
    let out = py.detach(|| -> Result<_, String> {
        push::push_chunk(
            &map.inner,
            &input_geometry.inner,
            &output_geometry.inner,
            &m,
            index_box(start, stop),
            &sources,
            |want| {
                let have = data.geometry().dims;
                let given = IndexBox {
                    start: rs,
                    end: [0, 1, 2].map(|a| rs[a] + have[a]),
                };
                if given != want {
                    return Err(volmorph_warp::WarpError::InvalidOption(format!(
                        "the region (start {region_start:?}, shape {:?}) is not the chunk's \
                         input box {:?}",
                        (have[2], have[1], have[0]),
                        zyx(want)
                    )));
                }
                Ok(data)
            },
        )
        .map_err(|e| crate::error::chain(&e))
    });
    let out = out.map_err(WarpError::new_err)?;
    PyVolume::from_rust(py, out)
}

/// Push forward the output chunk `start..stop` of `output_geometry` from resolution `level`
/// of the OME-Zarr image at `path`, reading only the chunk's input box, with the chunk's
/// `sources` from `push_plan`.
#[pyfunction]
#[pyo3(signature = (path, sources, map, output_geometry, start, stop, method="pushforward-antialiased", background=0.0, level=0))]
#[allow(clippy::too_many_arguments)]
pub fn push_zarr_chunk(
    py: Python<'_>,
    path: PathBuf,
    sources: Vec<PySource>,
    map: &PyMap,
    output_geometry: PyGeometry,
    start: Zyx,
    stop: Zyx,
    method: &str,
    background: f64,
    level: usize,
) -> PyResult<PyVolume> {
    let m = push_method(method, background)?;
    let sources = to_sources(&sources);
    let out = py.detach(|| -> Result<_, String> {
        let reader = OmeZarrReader::open_level(&path, level).map_err(|e| e.to_string())?;
        push::push_chunk(
            &map.inner,
            reader.geometry(),
            &output_geometry.inner,
            &m,
            index_box(start, stop),
            &sources,
            |b| reader.read_box(b).map_err(volmorph_warp::WarpError::from),
        )
        .map_err(|e| crate::error::chain(&e))
    });
    let out = out.map_err(WarpError::new_err)?;
    PyVolume::from_rust(py, out)
}

/// The geometry, numpy dtype name and chunk shape `(z, y, x)` of resolution `level` of the
/// OME-Zarr image at `path` (metadata only).
#[pyfunction]
#[pyo3(signature = (path, level=0))]
pub fn zarr_info(
    py: Python<'_>,
    path: PathBuf,
    level: usize,
) -> PyResult<(PyGeometry, String, Zyx)> {
    let r = py
        .detach(|| OmeZarrReader::open_level(&path, level))
        .map_err(|e| to_py(FileError::new_err, &e))?;
    let c = r.chunk();
    Ok((
        PyGeometry {
            inner: *r.geometry(),
        },
        numpy_dtype(r.voxel_type()).to_string(),
        (c[2], c[1], c[0]),
    ))
}

/// Read the box `start..stop` (`(z, y, x)`) of resolution `level` of the OME-Zarr image at
/// `path` (only the chunks it overlaps).
#[pyfunction]
#[pyo3(signature = (path, start, stop, level=0))]
pub fn zarr_read_box(
    py: Python<'_>,
    path: PathBuf,
    start: Zyx,
    stop: Zyx,
    level: usize,
) -> PyResult<PyVolume> {
    let v = py
        .detach(|| {
            OmeZarrReader::open_level(&path, level).and_then(|r| r.read_box(index_box(start, stop)))
        })
        .map_err(|e| to_py(FileError::new_err, &e))?;
    PyVolume::from_rust(py, v)
}

/// Write the chunk `start..` (`(z, y, x)`) of level 0 into the OME-Zarr store being written
/// at `staging` (an `OmeZarrWriter`'s `staging` folder; any process may call this).
#[pyfunction]
pub fn zarr_store_chunk(
    py: Python<'_>,
    staging: PathBuf,
    start: Zyx,
    data: &PyVolume,
) -> PyResult<()> {
    let v = data.to_rust(py)?;
    let d = v.geometry().dims;
    let b = IndexBox {
        start: [start.2, start.1, start.0],
        end: [start.2 + d[0], start.1 + d[1], start.0 + d[2]],
    };
    py.detach(|| omezarr::store_chunk(&staging, b, &v))
        .map_err(|e| to_py(FileError::new_err, &e))
}

/// An OME-Zarr store being written: chunks go into `staging` (from any process, with
/// `zarr_store_chunk`); `finish()` builds the pyramid and renames the store into place.
/// A writer dropped without `finish()` leaves nothing behind.
#[pyclass(name = "OmeZarrWriter", module = "volmorph._volmorph", unsendable)]
pub struct PyOmeZarrWriter {
    inner: Option<OmeZarrWriter>,
}

#[pymethods]
impl PyOmeZarrWriter {
    #[new]
    #[pyo3(signature = (path, geometry, dtype, chunks, zarr_version=2, levels=None))]
    fn new(
        path: PathBuf,
        geometry: PyGeometry,
        dtype: &str,
        chunks: Zyx,
        zarr_version: u8,
        levels: Option<usize>,
    ) -> PyResult<Self> {
        let vt =
            VoxelType::parse(dtype).ok_or_else(|| input(format!("unsupported dtype {dtype}")))?;
        let version = match zarr_version {
            2 => ZarrVersion::V2,
            3 => ZarrVersion::V3,
            v => return Err(input(format!("zarr_version must be 2 or 3, got {v}"))),
        };
        let options = ZarrWriteOptions {
            version,
            chunk: [chunks.2, chunks.1, chunks.0],
            levels,
            compress: true,
        };
        let w = OmeZarrWriter::create(&path, &geometry.inner, vt, &options)
            .map_err(|e| to_py(FileError::new_err, &e))?;
        Ok(Self { inner: Some(w) })
    }

    /// The temporary folder chunks are written into until `finish()`.
    #[getter]
    fn staging(&self) -> PyResult<PathBuf> {
        let w = self
            .inner
            .as_ref()
            .ok_or_else(|| input("the store is already finished"))?;
        Ok(w.staging_path().to_path_buf())
    }

    /// Chunk shape `(z, y, x)` of level 0 (clipped to the volume).
    #[getter]
    fn chunks(&self) -> PyResult<Zyx> {
        let w = self
            .inner
            .as_ref()
            .ok_or_else(|| input("the store is already finished"))?;
        let c = w.chunk();
        Ok((c[2], c[1], c[0]))
    }

    /// Build the pyramid levels and move the store into place.
    fn finish(&mut self, py: Python<'_>) -> PyResult<()> {
        let w = self
            .inner
            .take()
            .ok_or_else(|| input("the store is already finished"))?;
        py.detach(|| w.finish())
            .map_err(|e| to_py(FileError::new_err, &e))
    }
}
