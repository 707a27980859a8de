//! Indexed polygon meshes for volmorph: construction, normals, validation and the OBJ, STL,
//! PLY and OFF file formats.
//!
//! * [`Mesh`] — `f64` positions and polygon faces in compact CSR form. Faces list their
//!   vertices **counter-clockwise seen from the front**; the front (outward) normal follows the
//!   right-hand rule, e.g. `(b − a) × (c − a)` for a triangle `(a, b, c)`.
//! * [`Mesh::validate`] → [`ValidationReport`] — non-finite coordinates, bad indices,
//!   degenerate faces, non-manifold and inconsistently oriented edges, boundaries, Euler
//!   characteristic; readable through `Display`.
//! * [`shapes`] — closed primitives (geodesic sphere, box, torus) for tools and tests.
//! * [`format`](mod@format) — [`read`], [`write()`] and [`write_with`] choose the format by extension
//!   ([`MeshFormat::from_path`]) and accept gzip-compressed input; each format module also
//!   works on byte slices.
//!
//! Coordinates are in the model's own unit (millimetres in volmorph's physical space).
//! Nothing here panics on bad data: readers and checked constructors return a [`MeshError`],
//! and [`Mesh::validate`] describes meshes assembled by code.
//!
//! ```
//! use volmorph_mesh::{DVec3, Mesh, MeshFormat, MeshWriteOptions, read_bytes, to_bytes};
//!
//! // A unit square pyramid: one quad base and four triangles, counter-clockwise from outside.
//! let positions = vec![
//!     DVec3::new(0.0, 0.0, 0.0),
//!     DVec3::new(1.0, 0.0, 0.0),
//!     DVec3::new(1.0, 1.0, 0.0),
//!     DVec3::new(0.0, 1.0, 0.0),
//!     DVec3::new(0.5, 0.5, 1.0),
//! ];
//! let faces: [&[u32]; 5] = [&[0, 3, 2, 1], &[0, 1, 4], &[1, 2, 4], &[2, 3, 4], &[3, 0, 4]];
//! let pyramid = Mesh::from_polygons(positions, faces)?;
//! assert_eq!(pyramid.face_normal(0), Some(-DVec3::Z)); // the base faces down, outward
//! let report = pyramid.validate();
//! assert!(report.is_closed_manifold());
//! assert_eq!(report.euler_characteristic, 2);
//! assert!((pyramid.signed_volume() - 1.0 / 3.0).abs() < 1e-15);
//!
//! let bytes = to_bytes(&pyramid, MeshFormat::Ply, &MeshWriteOptions::default())?;
//! assert_eq!(read_bytes(&bytes, MeshFormat::Ply)?, pyramid);
//! # Ok::<(), volmorph_mesh::MeshError>(())
//! ```

mod error;
pub mod format;
mod hash;
mod mesh;
pub mod shapes;
mod validate;

pub use error::{Location, MeshError};
pub use format::{
    MeshColors, MeshFormat, MeshWriteOptions, read, read_bytes, read_with_colors, to_bytes, write,
    write_to, write_with,
};
pub use format::{
    obj::read_obj_bytes, off::read_off_bytes, ply::read_ply_bytes, ply::read_ply_bytes_with_colors,
    stl::read_stl_bytes,
};
pub use hash::{FastMap, MixHasher};
pub use mesh::{Faces, MAX_ELEMENTS, Mesh};
pub use validate::{DEGENERATE_RELATIVE_AREA, Issue, MAX_EXAMPLES, ValidationReport};

/// Re-export of the vector type used in the public API.
pub use glam::DVec3;
