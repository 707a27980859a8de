//! The integration tests of `maps`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod conformance;
mod elastix;
mod fields;
mod itk_tps;
