//! The integration tests of `handles`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod handle_files;
mod handle_limits;
mod picture_progress;
mod realtime_grid;
mod wendland;
mod wendland_budget;
