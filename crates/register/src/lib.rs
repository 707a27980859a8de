//! volmorph-register: the registration workbench of McPhail's thesis ch. 5 — from two scans
//! to a checked deformation and the lung measurements built on it.
//!
//! Direction: every map here sends a point of the **fixed** image (the thesis' source `S`) to
//! the corresponding point of the **moving** image (target `T`), `φ: fixed → moving`, the
//! convention of ITK and elastix. Resampling the moving image through `φ` on the fixed grid
//! (pull-back) gives the warped moving image `T∘φ`, which is compared with the fixed one
//! (the thesis' `f⁻¹(T)` against `S`, §5.5.4).
//!
//! * [`select`] — automatic handle selection on the edge-enhanced fixed image (§5.3.1).
//! * [`matching`] — correspondences by NCC with the thesis' distance penalty, re-centred
//!   iterations, sub-voxel refinement, per-handle affine frames, confidence, outlier
//!   rejection and coarse-to-fine search (§5.3.2).
//! * [`solve`] — the deformation through the handles: thin-plate spline, affine MLS or frame
//!   MLS (§5.4).
//! * [`live`] — the coarse-grid preview updated by one multiply-add per node when one
//!   correspondence is corrected by hand (§5.5.4).
//! * [`dense`] — dense refinement of a cubic B-spline lattice on an intensity metric (MSE, NCC,
//!   Mattes mutual information) with analytic gradients, multi-resolution, bending-energy and
//!   folding penalties and the handle correspondences as soft constraints.
//! * [`metrics`] — NCC, mean squared difference and mutual information between two images.
//! * [`quality`] — Algorithm 5.1 overlays, local sub-cube comparison, global metrics before
//!   and after, fold reports for any map, target registration error.
//! * [`lungs`] — the lobe-based lung model (§5.6); [`ventilation`] — the Jacobian and the
//!   HU-based volume change per lobe (§5.7).
//! * [`phantom`] — a breathing lung phantom with known motion and landmarks, and known smooth
//!   deformations of any volume.
//! * [`pipeline`] — the whole registration and each step as one call, with their outputs.

pub mod dense;
mod error;
pub mod image;
pub mod live;
pub mod lungs;
pub mod matching;
pub mod metrics;
pub(crate) mod noise;
pub mod optimize;
pub mod phantom;
pub mod pipeline;
pub mod quality;
pub mod select;
pub mod solve;
pub mod steps;
pub mod ventilation;

pub use error::RegisterError;
