//! Indexed polygon meshes for volmorph: construction, normals, validation and the OBJ, STL,
//! PLY and OFF file formats.
//!
//! * [`Mesh`] — `f64` positions and polygon faces in compact CSR form. Faces list their
//!   vertices **counter-clockwise seen from the front**; the front (outward) normal follows the
//!   right-hand rule, e.g. `(b − a) × (c − a)` for a triangle `(a, b, c)`.
//! * [`Mesh::validate`] → [`ValidationReport`] — non-finite coordinates, bad indices,
//!   degenerate faces, non-manifold and inconsistently oriented edges, boundaries, Euler
//!   characteristic; readable through `Display`.
//! * [`format`] — [`read`], [`write`] and [`write_with`] choose the format by extension
//!   ([`MeshFormat::from_path`]) and accept gzip-compressed input; each format module also
//!   works on byte slices.
//!
//! Coordinates are in the model's own unit (millimetres in volmorph's physical space).
//! Nothing here panics on bad data: readers and checked constructors return a [`MeshError`],
//! and [`Mesh::validate`] describes meshes assembled by code.

mod error;
pub mod format;
mod hash;
mod mesh;
mod validate;

pub use error::{Location, MeshError};
pub use format::{
    MeshFormat, MeshWriteOptions, read, read_bytes, to_bytes, write, write_to, write_with,
};
pub use format::{
    obj::read_obj_bytes, off::read_off_bytes, ply::read_ply_bytes, stl::read_stl_bytes,
};
pub use mesh::{Faces, MAX_ELEMENTS, Mesh};
pub use validate::{DEGENERATE_RELATIVE_AREA, Issue, MAX_EXAMPLES, ValidationReport};

/// Re-export of the vector type used in the public API.
pub use glam::DVec3;
