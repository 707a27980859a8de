//! The integration tests of `lattice`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod common;

mod bxf_plastimatch;
mod inverse_jacobian;
mod lattice;
mod manipulate;
mod size_limits;
mod skewed;
mod tfm_itk;
mod tool;
