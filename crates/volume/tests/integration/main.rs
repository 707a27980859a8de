//! The integration tests of `volume`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod phantom_progress;
mod phantom_sdf;
mod phantom_tree;
mod phantom_volume;
mod sample_interpolation;
mod size_budget;
mod slice_extract;
mod stats_summary;
