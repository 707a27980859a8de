//! volmorph-deform: mappings of physical space, the one trait they share, and what works for
//! every mapping.
//!
//! * [`SpaceMap`] — the one trait every deformation implements: `apply`, `jacobian`,
//!   `apply_with_jacobian`, `apply_batch` and the grid entry points `apply_grid` and
//!   `jacobian_grid`. The trait has no direction; see [`map`] for push-forward versus
//!   pull-back.
//! * [`Identity`], [`Affine`], [`Compose`] — elementary maps and composition (`Compose(a, b)`
//!   applies `b` first).
//! * [`inverse`] — point inversion `φ(x) = y` by damped Newton iteration ([`invert_point`]),
//!   which turns a push-forward map into the pull-back a renderer needs.
//! * [`sampled`] — any map sampled on a coarse grid and interpolated trilinearly
//!   ([`SampledMap`], McPhail §5.5.2).
//! * [`live`] — maps linear in their parameters ([`LinearMap`]: lattices, affine and frame MLS,
//!   thin-plate splines), where a parameter's [`Influence`] bounds what moving it changes, and
//!   such a map kept on a coarse grid and updated by one multiply-add per node when a parameter
//!   moves ([`LiveGrid`], McPhail §5.5.4).
//!
//! The maps themselves live in the crates above this one: B-spline / NURBS / Bézier lattices
//! in `volmorph-lattice`, handle-driven maps (moving least squares, thin-plate and volume
//! splines) in `volmorph-handles`.
//!
//! Physical coordinates follow the ITK convention of [`volmorph_volume::Geometry`]:
//! `physical = origin + direction·(spacing ⊙ index)`, voxels x fastest.
//!
//! ```
//! use glam::{DMat3, DVec3};
//! use volmorph_deform::{Affine, Compose, SpaceMap};
//! // Scale by 2 along x, then shift by one unit along z: `Compose(a, b)` applies `b` first.
//! let scale = Affine { matrix: DMat3::from_diagonal(DVec3::new(2.0, 1.0, 1.0)), offset: DVec3::ZERO };
//! let shift = Affine { matrix: DMat3::IDENTITY, offset: DVec3::Z };
//! let m = Compose(shift, scale);
//! assert_eq!(m.apply(DVec3::new(1.0, 2.0, 3.0)), DVec3::new(2.0, 2.0, 4.0));
//! assert_eq!(m.jacobian(DVec3::ZERO), scale.matrix);
//! ```

mod error;
pub mod inverse;
pub mod live;
pub mod map;
pub mod sampled;

pub use error::DeformError;
pub use inverse::{InverseOptions, InverseStatus, PointInverse, invert_point};
pub use live::{Influence, LinearMap, LiveGrid};
pub use map::{Affine, Compose, Identity, SpaceMap};
pub use sampled::SampledMap;
