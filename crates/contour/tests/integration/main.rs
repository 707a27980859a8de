//! The integration tests of `contour`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod dual_contouring;
mod marching_cubes;
mod progress;
