//! Applying space maps to volumes.
//!
//! Every operation names its direction (see DESIGN.md, "Direction of a map"):
//!
//! * [`apply`] — one entry point, [`apply::warp_volume`], for every method below, named by
//!   direction ([`apply::WarpMethod`]).
//! * [`pullback`] — *pull-back resampling*: output voxel `x` takes the input's value at
//!   `map(x)` (ITK's resampling convention).
//! * [`pushforward`] — *push-forward*: every input voxel is sent to `map(x)` in the output
//!   (free-form deformation of the model, True 1992 §5.3–§5.4).
//! * [`incremental`] — the antialiased push-forward kept up to date under parameter moves of
//!   any map linear in its parameters (lattices, affine and frame MLS, thin-plate splines) by
//!   redoing only the influenced region (True 1992 §5.3, the main loop).
//! * [`inverse`] — *pull-back through the inverse of a push-forward map*: output voxel `y`
//!   takes the input's value at `map⁻¹(y)` (Newton inversion per voxel), rendering the model
//!   deformed by a free-form deformation without push-forward's holes and aliasing.
//! * [`output`] — the output grid of a warp: the input's, padded (True 1992 §5.1, TSIZE >
//!   ISIZE) or explicit.
//! * [`chunked`] — pull-back chunk by chunk (out-of-core stores, Dask): each output chunk
//!   reads only its exact preimage box of the input; bit for bit the in-memory pull-back.
//! * [`jacobian`] — determinant maps of a map on a grid, and folding statistics.

pub mod apply;
mod centres;
pub mod chunked;
mod error;
pub mod incremental;
pub mod inverse;
pub mod jacobian;
pub mod output;
pub mod pullback;
pub mod pushforward;
mod tally;

pub use error::WarpError;
