use std::fmt;

use volmorph_io::IoError;

use crate::MeshFormat;

/// Where in a file a parse error was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line number of a text file (or of a text header).
    Line(usize),
    /// 0-based byte offset into binary data.
    Byte(usize),
    /// The file's header as a whole (e.g. a required declaration is missing).
    Header,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Line(l) => write!(f, "line {l}"),
            Self::Byte(b) => write!(f, "byte {b}"),
            Self::Header => f.write_str("header"),
        }
    }
}

/// Errors of mesh construction and mesh file I/O.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// Reading bytes failed (missing file, corrupt gzip stream, …).
    #[error(transparent)]
    Io(#[from] IoError),
    /// Writing output failed.
    #[error("write failed: {0}")]
    Write(#[from] std::io::Error),
    /// A file is malformed for its format.
    #[error("{format} {location}: {message}")]
    Parse {
        /// The format being read.
        format: MeshFormat,
        /// Where the problem was found.
        location: Location,
        /// What is wrong, in terms of the file's own fields.
        message: String,
    },
    /// A face refers to a vertex that does not exist.
    #[error("face {face} refers to vertex {index}, but the mesh has {vertex_count} vertices")]
    IndexOutOfRange {
        /// 0-based face number.
        face: usize,
        /// The offending (0-based) vertex index.
        index: u64,
        /// Number of vertices in the mesh.
        vertex_count: usize,
    },
    /// A face has fewer than three vertices.
    #[error("face {face} has {len} vertices; a polygon needs at least 3")]
    FaceTooSmall {
        /// 0-based face number.
        face: usize,
        /// Its vertex count.
        len: usize,
    },
    /// Face offsets (CSR) are malformed: they must start at 0, never decrease and end at the
    /// number of indices.
    #[error("malformed face offsets: {0}")]
    Offsets(String),
    /// The mesh exceeds the 32-bit index space (more than `u32::MAX` vertices or face corners).
    #[error("mesh too large: {0}")]
    TooLarge(String),
    /// An extra per-element property to write is malformed (wrong number of values, empty,
    /// non-ASCII or whitespace-containing name, or a name used twice or by a standard property).
    #[error("invalid PLY property: {0}")]
    InvalidProperty(String),
    /// A shape parameter is out of range (a primitive's size, radius or resolution).
    #[error("invalid shape: {0}")]
    InvalidShape(String),
    /// A valid request volmorph does not handle (unknown extension, binary OFF, …).
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// An error attributed to a file path.
    ///
    /// Displays as `path: error`; the inner error is part of the message, not a separate
    /// `source()`, so error chains do not repeat it.
    #[error("{path}: {error}")]
    File {
        /// The file concerned.
        path: String,
        /// What went wrong.
        error: Box<MeshError>,
    },
}

impl MeshError {
    /// Shorthand for a [`MeshError::Parse`] error.
    pub fn parse(format: MeshFormat, location: Location, message: impl Into<String>) -> Self {
        Self::Parse {
            format,
            location,
            message: message.into(),
        }
    }

    /// Attach a file path to this error (no-op if it already carries one, including an
    /// operating-system error of [`MeshError::Io`], which names its path itself).
    #[must_use]
    pub fn at(self, path: &std::path::Path) -> Self {
        match self {
            e @ Self::File { .. } => e,
            Self::Io(e) if e.path().is_some() => Self::Io(e),
            e => Self::File {
                path: path.display().to_string(),
                error: Box::new(e),
            },
        }
    }
}
