//! The integration tests of `volume-io`, one module per topic, built as one test binary
//! (one link instead of one per file keeps the test build short).

mod common;

mod detached_data;
mod metaimage_io;
mod nifti_header;
mod nifti_itk_reference;
mod nifti_roundtrip;
mod nrrd_io;
mod omezarr;
mod peer_fixtures;
mod raw_io;
mod vtk_io;
