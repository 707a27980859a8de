//! volmorph-bench: every benchmark of volmorph, set up once.
//!
//! `volmorph bench warp|isosurface|ffd|frep|handles|scene` and the criterion benches in this
//! crate's `benches/` run the same code: the inputs (teapot volumes, moved lattices, handle
//! sets, spheres, F-rep scenes, a scene with a warped volume), the named cases, the targets
//! ([`targets`], by the issue that set them), and the timing of one call per run
//! ([`timing::Case`]). The command line measures each case `--repeat` times and prints min,
//! median and max ([`timing::Report`], text or JSON); criterion drives the same case through
//! [`timing::Case::total`].
//!
//! One module per suite, each with a configuration (validated, with the defaults at which the
//! targets are stated), the inputs as public functions or structs, the cases, and `run`:
//!
//! * [`warp`] — pull-back, push-forward and Jacobian of a moved lattice on the teapot;
//!   incremental update and drag;
//! * [`isosurface`] — marching cubes and dual contouring of a sphere's distance field;
//! * [`ffd`] — accurate and vertex FFD of spheres through a moved degree-2 lattice;
//! * [`frep`] — culled grid sampling of F-rep models (the built-in [`frep::SCENES`] or files);
//! * [`handles`] — 2D and 3D MLS and thin-plate splines;
//! * [`scene`] — a drag through the scene and the same drag on the engines;
//! * [`roofline`] — the machine's memory bandwidth and floating-point rate, the roofs of every
//!   hot path.
//!
//! Random inputs come from [`volmorph_testkit::Rng`] with the seed [`SEED`], so every run and
//! every machine times the same inputs.
//!
//! # Layout: why the criterion benches live here
//!
//! The criterion benches of the suites above are this crate's benches, not those of the
//! crates they measure. Cargo does accept a dev-dependency cycle (say `volmorph-warp`'s
//! benches depending on this crate, which depends on `volmorph-warp`), but the crate under
//! test is then compiled twice — once as the dependency of this crate, once as the test or
//! bench target — and for unit tests the two copies are different crates whose types do not
//! match; the graph is cyclic for every tool that orders crates (publishing, vendoring). So
//! the benches that share these set-ups live in `crates/bench/benches/`, and the dependency
//! arrows stay one-way: this crate depends on the libraries, the command line depends on this
//! crate. Micro-benches with no command-line counterpart (lattice grid paths and drag solves
//! in `volmorph-lattice`, the inverse pull-back in `volmorph-warp`, the trivariate, render and
//! file-format benches) stay with their crates.

pub mod ffd;
pub mod frep;
pub mod handles;
pub mod isosurface;
pub mod roofline;
pub mod scene;
pub mod targets;
pub mod timing;
pub mod warp;

mod error;

pub use error::BenchError;
pub use timing::{Case, Item, Report, Sample, Unit};

/// Seed of every random input (lattice displacements, handle sets), so every run times the
/// same inputs.
pub const SEED: u64 = 0x5eed;

/// Largest voxels per axis accepted for a cubic input (a 1024³ `f32` volume is 4 GiB).
pub const MAX_SIZE: usize = 1024;

/// Largest number of timed runs per case.
pub const MAX_REPEAT: usize = 1000;

/// Check a repeat count.
fn check_repeat(repeat: usize) -> Result<(), BenchError> {
    BenchError::range("repeat", repeat, 1..=MAX_REPEAT)
}
