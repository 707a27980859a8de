//! `volmorph._volmorph`: the Python extension module of volmorph (pyo3 + rust-numpy, abi3).
//!
//! A thin layer: every function converts its arguments, releases the GIL, calls one library
//! function or scene command, and converts the result. No domain logic lives here; what the
//! bindings need is added to the library crates with their own tests. The Python package
//! (`python/volmorph`) re-exports these names, adds the SimpleITK / nibabel conversions and
//! the Dask graph, and carries the type stubs.

mod chunked;
mod error;
mod maps;
mod ops;
mod scene;
mod volume;

use pyo3::prelude::*;

/// mimalloc rather than the system allocator: it reuses the memory of freed large buffers
/// instead of returning it to the system and faulting it in again page by page, which cost
/// marching cubes on a 256³ field about a third of its time (see `docs/performance.md`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// The module.
#[pymodule]
fn _volmorph(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("VolmorphError", py.get_type::<error::VolmorphError>())?;
    m.add("InputError", py.get_type::<error::InputError>())?;
    m.add("FileError", py.get_type::<error::FileError>())?;
    m.add("MapError", py.get_type::<error::MapError>())?;
    m.add("WarpError", py.get_type::<error::WarpError>())?;
    m.add("ModelError", py.get_type::<error::ModelError>())?;
    m.add("SceneError", py.get_type::<error::SceneError>())?;
    m.add_class::<volume::PyGeometry>()?;
    m.add_class::<volume::PyVolume>()?;
    m.add_class::<maps::PyMap>()?;
    m.add_class::<ops::PyFrep>()?;
    m.add_class::<ops::PyNurbs>()?;
    m.add_class::<scene::PyScene>()?;
    m.add_function(wrap_pyfunction!(ops::warp, m)?)?;
    m.add_function(wrap_pyfunction!(ops::warp_timed, m)?)?;
    m.add_function(wrap_pyfunction!(ops::jacobian_map, m)?)?;
    m.add_function(wrap_pyfunction!(ops::isosurface, m)?)?;
    m.add_function(wrap_pyfunction!(ops::ffd, m)?)?;
    m.add_function(wrap_pyfunction!(ops::read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(ops::write_mesh, m)?)?;
    m.add_class::<chunked::PyOmeZarrWriter>()?;
    m.add_function(wrap_pyfunction!(chunked::chunk_preimage, m)?)?;
    m.add_function(wrap_pyfunction!(chunked::warp_chunk, m)?)?;
    m.add_function(wrap_pyfunction!(chunked::warp_zarr_chunk, m)?)?;
    m.add_function(wrap_pyfunction!(chunked::chunked_kind, m)?)?;
    m.add_function(wrap_pyfunction!(chunked::push_plan, m)?)?;
    m.add_function(wrap_pyfunction!(chunked::push_chunk, m)?)?;
    m.add_function(wrap_pyfunction!(chunked::push_zarr_chunk, m)?)?;
    m.add_function(wrap_pyfunction!(chunked::zarr_info, m)?)?;
    m.add_function(wrap_pyfunction!(chunked::zarr_read_box, m)?)?;
    m.add_function(wrap_pyfunction!(chunked::zarr_store_chunk, m)?)?;
    Ok(())
}
