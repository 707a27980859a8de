//! The exception hierarchy: every error of the library crates becomes a subclass of
//! `volmorph.VolmorphError` carrying the message the CLI prints (the error and its causes,
//! joined by `": "`, as `anyhow`'s `{:#}` does).

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    _volmorph,
    VolmorphError,
    PyException,
    "Base class of every error volmorph raises."
);
create_exception!(
    _volmorph,
    InputError,
    VolmorphError,
    "A bad argument: wrong dtype, shape or layout of an array, non-finite values, unknown names."
);
create_exception!(
    _volmorph,
    FileError,
    VolmorphError,
    "A file that cannot be read or written (volumes, meshes, maps, models, projects)."
);
create_exception!(
    _volmorph,
    MapError,
    VolmorphError,
    "A map that cannot be built, evaluated or inverted."
);
create_exception!(
    _volmorph,
    WarpError,
    VolmorphError,
    "A warp, Jacobian map or isosurface that cannot be computed."
);
create_exception!(
    _volmorph,
    ModelError,
    VolmorphError,
    "An F-rep, NURBS or FFD model that cannot be compiled, fitted or deformed."
);
create_exception!(
    _volmorph,
    SceneError,
    VolmorphError,
    "A scene command that was refused (the scene is unchanged)."
);

/// The message of `e` and its causes, `"outer: inner: …"`.
pub fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let m = c.to_string();
        if !s.contains(&m) {
            s.push_str(": ");
            s.push_str(&m);
        }
        cause = c.source();
    }
    s
}

/// An exception constructor (`FileError::new_err`, …).
pub type Raise = fn(String) -> PyErr;

/// Convert a library error into the exception `raise` builds.
pub fn to_py(raise: Raise, e: &dyn std::error::Error) -> PyErr {
    raise(chain(e))
}

/// [`to_py`] with a leading context, as the CLI's `.context(...)` adds.
pub fn with_context(raise: Raise, context: &str, e: &dyn std::error::Error) -> PyErr {
    raise(format!("{context}: {}", chain(e)))
}

/// An [`InputError`] with `msg`.
pub fn input(msg: impl Into<String>) -> PyErr {
    InputError::new_err(msg.into())
}
