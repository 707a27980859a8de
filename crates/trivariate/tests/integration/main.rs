//! The integration tests of `trivariate`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod fit_range;
mod fit_sampled;
mod modeling;
mod optics_accuracy;
mod progress;
mod raytrace;
mod recipe;
