//! volmorph-testkit: what the tests and benchmarks of every volmorph crate share.
//!
//! * [`Rng`] — the one seeded pseudo-random generator of the test suites and benches.
//! * [`conformance`] — the suite every space map runs ([`space_map_conformance!`]) and the
//!   extra checks of maps linear in their parameters ([`linear_map_conformance!`]).
//!
//! This crate is a dev-dependency only; nothing in a library or front-end depends on it.

pub mod conformance;
mod rng;

pub use conformance::Conformance;
pub use rng::Rng;
