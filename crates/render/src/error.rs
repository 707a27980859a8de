use volmorph_io::IoError;

/// Errors of image construction, intensity mapping, cameras, PNG I/O and GIF output.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// Creating, renaming or reading a file failed, or a size is impossible (the message names
    /// the path or the dimensions).
    #[error(transparent)]
    Io(#[from] IoError),
    /// Image dimensions are zero, overflow, or exceed [`MAX_IMAGE_PIXELS`](crate::MAX_IMAGE_PIXELS).
    #[error("invalid image size {width}×{height}: {reason}")]
    Size {
        /// Requested width in pixels.
        width: u64,
        /// Requested height in pixels.
        height: u64,
        /// Why the size is refused.
        reason: &'static str,
    },
    /// A data buffer does not hold one element per pixel.
    #[error("{what} has {got} elements but a {width}×{height} image needs {expected}")]
    LengthMismatch {
        /// Which buffer ("values", "pixels", …).
        what: &'static str,
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
        /// Element count the dimensions imply.
        expected: usize,
        /// Elements supplied.
        got: usize,
    },
    /// A parameter is unusable (non-finite, out of range, degenerate geometry); the message
    /// names the parameter and its value.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// The PNG encoder failed.
    #[error("PNG encoding failed: {0}")]
    PngEncode(#[from] png::EncodingError),
    /// The PNG decoder failed (corrupt, truncated or unsupported file).
    #[error("PNG decoding failed: {0}")]
    PngDecode(#[from] png::DecodingError),
    /// The GIF encoder failed.
    #[error("GIF encoding failed: {0}")]
    GifEncode(#[from] gif::EncodingError),
    /// An error attributed to a file path.
    ///
    /// Displays as `path: error`; the inner error is part of the message, not a separate
    /// `source()`, so error chains do not repeat it.
    #[error("{path}: {error}")]
    File {
        /// The file concerned.
        path: String,
        /// What went wrong.
        error: Box<RenderError>,
    },
}

impl RenderError {
    /// Shorthand for a [`RenderError::InvalidArgument`] error.
    pub(crate) fn invalid(message: impl Into<String>) -> Self {
        Self::InvalidArgument(message.into())
    }

    /// Attach a file path to this error. A no-op for errors that already name a path
    /// ([`RenderError::File`] and operating-system failures reported by `volmorph_io`).
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
