use std::path::Path;

use volmorph_io::IoError;

/// Errors of volume construction, sampling and file I/O.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// Reading or writing bytes failed (includes truncation and impossible sizes).
    #[error(transparent)]
    Io(#[from] IoError),
    /// The geometry is unusable: zero dims, non-positive or non-finite spacing, singular or
    /// non-finite direction, non-finite origin.
    #[error("invalid geometry: {0}")]
    Geometry(String),
    /// A data buffer does not have one value per voxel.
    #[error("data has {got} values but dims {dims:?} need {expected}")]
    LengthMismatch {
        /// Volume dims.
        dims: [usize; 3],
        /// Voxel count the dims imply.
        expected: usize,
        /// Values supplied.
        got: usize,
    },
    /// A file is malformed for its format.
    #[error("{format}: {message}")]
    Format {
        /// Format name ("NIfTI-1", "MetaImage", …).
        format: &'static str,
        /// What is wrong, in terms of the file's own fields.
        message: String,
    },
    /// An argument is outside what the operation accepts (a slice position outside the
    /// volume, a probability outside [0, 1], an output buffer of the wrong length, …).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// A valid file uses a feature volmorph does not handle (e.g. a 5-D NIfTI image).
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// A header names a data file outside its own folder (an absolute path, `../`, or a
    /// symbolic link leading out), which is refused unless the reader is allowed external
    /// data (`ReadOptions::allow_external_data` in `volmorph-volume-io`, the command-line
    /// option `--allow-external-data`).
    #[error(
        "{field} `{name}` resolves to {resolved}, outside the header's folder; data files \
         outside it are refused unless allowed (--allow-external-data)"
    )]
    ExternalData {
        /// Format and header field, e.g. "MetaImage ElementDataFile".
        field: String,
        /// The name as written in the header.
        name: String,
        /// Where it resolves to.
        resolved: String,
    },
    /// An error attributed to a file path.
    ///
    /// Displays as `path: error`; the inner error is part of the message, not a separate
    /// `source()`, so error chains do not repeat it.
    #[error("{path}: {error}")]
    File {
        /// The file concerned.
        path: String,
        /// What went wrong.
        error: Box<VolumeError>,
    },
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; nothing was
    /// written.
    #[error("stopped on request")]
    Cancelled(#[from] volmorph_io::Cancelled),
}

impl VolumeError {
    /// Shorthand for a [`VolumeError::Format`] error.
    pub fn format(format: &'static str, message: impl Into<String>) -> Self {
        Self::Format {
            format,
            message: message.into(),
        }
    }

    /// Attach a file path to this error (no-op if it already carries one).
    #[must_use]
    pub fn at(self, path: &Path) -> Self {
        match self {
            e @ Self::File { .. } => e,
            // An OS or extension error about this very file already names it.
            Self::Io(e) if e.path().is_some_and(|p| Path::new(p) == path) => Self::Io(e),
            e => Self::File {
                path: path.display().to_string(),
                error: Box::new(e),
            },
        }
    }
}
