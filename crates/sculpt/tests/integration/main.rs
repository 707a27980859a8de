//! The integration tests of `sculpt`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod common;

mod job_progress;
mod proptest_edits;
mod sculpt;
