//! Sampled volumes with physical geometry.
//!
//! * [`Geometry`] — dims, spacing, origin and 3×3 direction, ITK convention:
//!   `physical = origin + direction · (spacing ⊙ index)`, x fastest in memory.
//! * [`direction`] — the one tolerance and orthonormalisation (polar factor) applied to every
//!   direction matrix that enters volmorph.
//! * [`Volume<T>`] — a typed voxel array on a [`Geometry`] (owned; [`VolumeRef`] borrows the
//!   voxels from a caller's buffer); [`AnyVolume`] / [`AnyVolumeRef`] when the type is only
//!   known at run time (files).
//! * [`Voxel`] / [`VoxelType`] — the supported voxel types and their conversions.
//! * [`sample`] — nearest, trilinear and prefiltered cubic B-spline interpolation at
//!   continuous indices or physical points, with a stated boundary policy.
//! * [`stats`] — value statistics and exact quantiles; [`slice`](mod@slice) — axis-aligned slices.
//! * File formats live in `volmorph-volume-io`, so the data model and its samplers carry no
//!   parsers.
//! * [`phantom`] — the built-in models as u8 density and f32 signed distance.
//!
//! Everything here works in physical coordinates (millimetres for medical images) in `f64`.
//!
//! ```
//! use volmorph_volume::{AnyVolume, DVec3};
//! use volmorph_volume::phantom::{self, Phantom};
//! use volmorph_volume::sample::{Boundary, Interpolation, Sampler};
//!
//! // A built-in model: u8 density, the object is where the value is at least 127.
//! let sphere = AnyVolume::from(phantom::density(Phantom::Sphere, [33, 33, 33])?);
//! // Sample at physical points (model units here): inside the ball and far outside it.
//! let s = Sampler::from_any(&sphere, Interpolation::CubicBSpline, Boundary::Constant(0.0))?;
//! assert!((s.sample_physical(DVec3::ZERO) - 255.0).abs() < 1e-3);
//! assert_eq!(s.sample_physical(DVec3::splat(5.0)), 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod direction;
mod error;
mod geometry;
mod index_box;
pub mod phantom;
pub mod sample;
pub mod slice;
pub mod stats;
mod volume;
mod voxel;

pub use error::VolumeError;
pub use geometry::Geometry;
pub use index_box::IndexBox;
pub use volume::{AnyVolume, AnyVolumeRef, Volume, VolumeRef};
pub use voxel::{Voxel, VoxelType};

/// Re-export of the vector types used in the public API.
pub use glam::{DMat3, DVec3};
