//! volmorph-maps: every space map volmorph has, by name.
//!
//! * [`AnyMap`] — one value for every kind of map: identity, affine, B-spline lattices, MLS
//!   (affine, similarity, rigid, frames), thin-plate splines, Wendland compact-support splines,
//!   Bryson's bump, NURBS geometry,
//!   sampled maps, displacement fields, compositions, numerical inverses and refined maps
//!   (a map plus a lattice correction, [`Refined`]). It is a
//!   [`SpaceMap`](volmorph_deform::SpaceMap) that keeps each kind's fast paths.
//! * [`json`] — the tagged, versioned JSON form of every kind; [`itk`] — ITK text transforms
//!   for the kinds ITK has (affine, B-spline, composite); [`itk_mat`] — ITK/ANTs MATLAB `.mat`
//!   transforms; [`elastix`] — elastix transform parameter files and their chains;
//!   [`field`] — ITK displacement fields (vector images) as maps; [`file`](mod@file) — map
//!   files by extension ([`read_map`], [`write_map`], [`write_field`]).
//! * [`from_handles`] — the map a handle set builds ([`handle_map`]), in either direction.
//! * [`live`] — the kinds linear in their parameters as one [`LiveMap`] for the live-edit
//!   engines.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_deform::SpaceMap;
//! use volmorph_lattice::BSplineLattice;
//! use volmorph_maps::AnyMap;
//! let mut lat = BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(10.0), [5; 3])?;
//! lat.move_control_point([2, 2, 2], DVec3::new(0.5, 0.0, 0.0))?;
//! let map = AnyMap::from(lat).then(AnyMap::Affine(volmorph_deform::Affine {
//!     matrix: glam::DMat3::IDENTITY,
//!     offset: DVec3::Z,
//! }));
//! let back = AnyMap::from_json(&map.to_json()?)?;
//! let p = DVec3::new(4.0, 5.0, 6.0);
//! assert_eq!(back.apply(p), map.apply(p)); // exact: numbers round-trip bit for bit
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod any;
pub mod elastix;
mod error;
pub mod field;
pub mod file;
pub mod from_handles;
pub mod itk;
pub mod itk_mat;
pub mod json;
pub mod live;
pub mod refined;

pub use any::AnyMap;
pub use error::MapError;
pub use field::DisplacementField;
pub use file::{MapFormat, read_map, write_field, write_map};
pub use from_handles::{HandleDirection, HandleMethod, HandleOptions, handle_map};
pub use live::LiveMap;
pub use refined::Refined;
