//! The integration tests of `cli`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod common;

mod cli;
mod frep_framing;
mod jacobian;
mod nurbs_fit;
mod out_of_core_progress;
mod output_extensions;
mod pictures;
mod project;
mod realdata;
mod register;
mod scene_equals_cli;
mod true1992;
