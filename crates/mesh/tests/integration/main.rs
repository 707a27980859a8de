//! The integration tests of `mesh`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod common;

mod colors;
mod formats;
mod gzip_budget;
mod mesh;
mod roundtrip_prop;
mod validate;
