//! The integration tests of `ffd`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod common;

mod accurate;
mod step_compact;
mod subdivision;
