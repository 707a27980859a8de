//! volmorph-testkit: what the tests and benchmarks of every volmorph crate share.
//!
//! * [`Rng`] — the one seeded pseudo-random generator of the test suites and benches.
//!
//! This crate is a dev-dependency only; nothing in a library or front-end depends on it.

mod rng;

pub use rng::Rng;
