//! Sampled volumes with physical geometry.
//!
//! * [`Geometry`] — dims, spacing, origin and 3×3 direction, ITK convention:
//!   `physical = origin + direction · (spacing ⊙ index)`, x fastest in memory.
//! * [`Volume<T>`] — a typed voxel array on a [`Geometry`]; [`AnyVolume`] when the type is only
//!   known at run time (files).
//! * [`Voxel`] / [`VoxelType`] — the supported voxel types and their conversions.
//! * [`sample`] — nearest, trilinear and prefiltered cubic B-spline interpolation at
//!   continuous indices or physical points, with a stated boundary policy.
//! * [`stats`] — value statistics and exact quantiles; [`slice`](mod@slice) — axis-aligned slices.
//! * [`format`](mod@format) — NIfTI-1, MetaImage, NRRD, VTK legacy and raw files, chosen by extension.
//! * [`phantom`] — the built-in models as u8 density and f32 signed distance.
//!
//! Everything here works in physical coordinates (millimetres for medical images) in `f64`.
//!
//! ```
//! use volmorph_volume::{AnyVolume, DVec3, format};
//! use volmorph_volume::phantom::{self, Phantom};
//! use volmorph_volume::sample::{Boundary, Interpolation, Sampler};
//!
//! let dir = std::env::temp_dir().join(format!("volmorph-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let path = dir.join("sphere.mha");
//!
//! // A built-in model: u8 density, the object is where the value is at least 127.
//! let sphere = AnyVolume::from(phantom::density(Phantom::Sphere, [33, 33, 33])?);
//! format::write(&path, &sphere)?; // the format follows the extension
//! let back = format::read(&path)?;
//! // Voxels and geometry survive the round trip exactly. (NIfTI stores geometry in f32,
//! // so a `.nii.gz` would keep the voxels exactly and the geometry to f32 precision.)
//! assert!(back.as_bytes() == sphere.as_bytes() && back.geometry() == sphere.geometry());
//!
//! // Sample at physical points (model units here): inside the ball and far outside it.
//! let s = Sampler::from_any(&back, Interpolation::CubicBSpline, Boundary::Constant(0.0))?;
//! assert!((s.sample_physical(DVec3::ZERO) - 255.0).abs() < 1e-3);
//! assert_eq!(s.sample_physical(DVec3::splat(5.0)), 0.0);
//! std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

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
