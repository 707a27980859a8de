//! The integration tests of `scene`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod by_handles;
mod scene_commands;
mod scene_progress;
mod scene_sculpt;
