//! The integration tests of `register`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod conformance;
mod phantom_pipeline;
mod progress;
mod steps;
