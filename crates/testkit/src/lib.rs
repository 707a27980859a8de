//! volmorph-testkit: what the tests and benchmarks of every volmorph crate share.
//!
//! * [`Rng`] — the one seeded pseudo-random generator of the test suites and benches.
//! * [`alloc_peak`] — peak heap use of a piece of code, and running one test alone in a
//!   child process of its binary.
//! * [`conformance`] — the suite every space map runs ([`space_map_conformance!`]) and the
//!   extra checks of maps linear in their parameters ([`linear_map_conformance!`]).
//! * [`fingerprint`] — FNV-1a over output bits, for tests pinning rewritten kernels.
//! * [`progress`] — the contract of every `_with(…, progress)` function: steps reach the
//!   announced totals, cancellation returns an error carrying `Cancelled`.
//!
//! This crate is a dev-dependency of the libraries' tests and benches, and a dependency of
//! `volmorph-bench` only (the benchmark set-ups, whose random inputs it draws); no library
//! depends on it.

pub mod alloc_peak;
pub mod conformance;
pub mod fingerprint;
pub mod progress;
mod rng;

pub use conformance::Conformance;
pub use rng::Rng;
