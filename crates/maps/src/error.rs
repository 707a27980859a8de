//! Errors of map files and map construction.

use volmorph_deform::DeformError;

/// Everything that can go wrong reading, writing or building a map.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// A map refused its description (handles, control points, options), or a lattice file
    /// (`.tfm`, `.bxf`) is malformed.
    #[error(transparent)]
    Deform(#[from] DeformError),
    /// JSON that does not parse or has fields of the wrong shape.
    #[error("map JSON: {0}")]
    Json(String),
    /// A well-formed description of something that is not a valid map (unknown kind, other
    /// version, missing field, bad option).
    #[error("invalid map: {0}")]
    Invalid(String),
    /// The map cannot be written in the requested format (e.g. a handle map as ITK `.tfm`).
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// Reading or writing the file failed.
    #[error(transparent)]
    Io(#[from] volmorph_io::IoError),
    /// The error of the file at `path`.
    #[error("{path}: {source}")]
    File {
        /// The file read or written.
        path: String,
        /// What went wrong.
        #[source]
        source: Box<MapError>,
    },
}

impl MapError {
    /// A JSON (de)serialisation error.
    pub(crate) fn json(e: serde_json::Error) -> Self {
        MapError::Json(e.to_string())
    }

    /// This error, as the error of the file `path`.
    #[must_use]
    pub fn at(self, path: &std::path::Path) -> Self {
        match self {
            e @ (MapError::File { .. } | MapError::Io(volmorph_io::IoError::Extension { .. })) => e,
            e => MapError::File {
                path: path.display().to_string(),
                source: Box::new(e),
            },
        }
    }
}
