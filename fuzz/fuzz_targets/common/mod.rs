//! What the fuzz targets whose readers take paths share: one private temporary folder per
//! fuzzing process, where each input is written before it is read.

use std::path::Path;
use std::sync::OnceLock;

/// The process's private folder (created on first use, removed at exit).
pub fn folder() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("a temporary folder"))
        .path()
}
