//! Sampled volumes with physical geometry.
//!
//! * [`Geometry`] — dims, spacing, origin and 3×3 direction, ITK convention:
//!   `physical = origin + direction · (spacing ⊙ index)`, x fastest in memory.
//! * [`Volume<T>`] — a typed voxel array on a [`Geometry`]; [`AnyVolume`] when the type is only
//!   known at run time (files).
//! * [`Voxel`] / [`VoxelType`] — the supported voxel types and their conversions.
//! * [`sample`] — nearest, trilinear and prefiltered cubic B-spline interpolation at
//!   continuous indices or physical points, with a stated boundary policy.
//! * [`stats`] — value statistics and exact quantiles; [`slice`] — axis-aligned slices.
//! * [`format`] — NIfTI-1, MetaImage, NRRD, VTK legacy and raw files, chosen by extension.
//! * [`phantom`] — the built-in models as u8 density and f32 signed distance.
//!
//! Everything here works in physical coordinates (millimetres for medical images) in `f64`.

mod error;
pub mod format;
mod geometry;
pub mod phantom;
pub mod sample;
pub mod slice;
pub mod stats;
mod volume;
mod voxel;

pub use error::VolumeError;
pub use geometry::Geometry;
pub use volume::{AnyVolume, Volume};
pub use voxel::{Voxel, VoxelType};

/// Re-export of the vector types used in the public API.
pub use glam::{DMat3, DVec3};
