//! volmorph-handles: space maps driven by handles — points, frames and segments that the user
//! places and moves (McPhail's thesis ch. 4–5; Savchenko's volume splines; Bryson's bump).
//!
//! * [`mls`] — moving least squares through point handles in 3D (affine, similarity, rigid)
//!   and frame-based MLS.
//! * [`volume_spline`] — Savchenko's volume splines on Green's function in 2D and 3D, scalar or
//!   vector valued, and the [`ThinPlateMap`] built on them.
//! * [`wendland`] — affine trend plus compactly supported Wendland kernels solved by sparse
//!   Cholesky: the handle map that scales to tens of thousands of handles ([`WendlandMap`]).
//! * [`bump`] — Bryson's bump transform.
//! * [`mls2d`] — 2D MLS through points and line segments, for pictures.
//! * [`handles`] — handle files (volmorph JSON, Slicer `.fcsv`, text).
//!
//! Every map here is a [`volmorph_deform::SpaceMap`] sending each source handle to its target
//! (push-forward); errors are [`volmorph_deform::DeformError`]. The maps that are affine in
//! their targets (affine MLS, frame MLS, thin-plate splines) implement
//! [`volmorph_deform::LinearMap`], so a [`volmorph_deform::LiveGrid`] updates them in real time.

pub mod bump;
pub mod handles;
pub mod mls;
pub mod mls2d;
pub mod volume_spline;
pub mod wendland;

pub use bump::BumpMap;
pub use handles::HandleSet;
pub use mls::{AffineMls, Frame, FrameMls, RigidMls, SimilarityMls, Weighting};
pub use volume_spline::{ThinPlateMap, TpsKernel, VolumeSpline, VolumeSplineSystem};
pub use wendland::WendlandMap;
