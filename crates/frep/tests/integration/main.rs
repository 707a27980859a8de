//! The integration tests of `frep`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod conformance;
mod displacement_map;
mod export;
mod models;
mod progress;
mod size_budget;
mod spec;
mod voxel;
