//! The integration tests of `warp`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod chunked_pullback;
mod chunked_pushforward;
mod incremental_props;
mod inverse_pullback;
mod jacobian_maps;
mod kernel_fingerprints;
mod padded_output;
mod progress;
mod pullback_resample;
mod pushforward_props;
