//! The integration tests of `render`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod cubecut;
mod dvr;
mod slice_labels;
