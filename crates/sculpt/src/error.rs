use volmorph_contour::ContourError;
use volmorph_io::IoError;
use volmorph_mesh::MeshError;

/// Errors of sculpting.
#[derive(Debug, thiserror::Error)]
pub enum SculptError {
    /// A grid parameter is unusable (non-finite origin, spacing not positive, too few points).
    #[error("invalid grid: {0}")]
    InvalidGrid(String),
    /// The grid (or an image) needs more memory than the budget allows.
    #[error("{what} needs {count} elements, more than the limit of {limit}")]
    TooLarge {
        /// What was being allocated.
        what: &'static str,
        /// Number of elements requested.
        count: usize,
        /// Largest number allowed.
        limit: usize,
    },
    /// A mesh given as the sculpted shape or as a tool is unusable.
    #[error("{role} mesh: {reason}")]
    InvalidMesh {
        /// Which mesh: `"base"`, `"tool"`, …
        role: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// An option or edit parameter is out of its documented range.
    #[error("{name} = {value}: {expected}")]
    InvalidOption {
        /// Name of the parameter.
        name: &'static str,
        /// The value given, as text.
        value: String,
        /// What is accepted.
        expected: &'static str,
    },
    /// An undo or redo record does not belong to the document's current state.
    #[error("edit record {record} does not apply: {reason}")]
    RecordMismatch {
        /// Revision the record was made from.
        record: u64,
        /// Why it does not apply.
        reason: String,
    },
    /// The local re-contour could not be joined to the untouched mesh (the document is
    /// unchanged).
    #[error("cannot stitch the re-contoured region into the mesh: {0}")]
    Stitch(String),
    /// A stroke file or text is malformed (the message names the file, pose and field).
    #[error("stroke {0}")]
    Stroke(String),
    /// Contouring options are out of range.
    #[error(transparent)]
    Contour(#[from] ContourError),
    /// Building or reading a mesh failed.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// A size check failed.
    #[error(transparent)]
    Io(#[from] IoError),
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; nothing was
    /// written.
    #[error("stopped on request")]
    Cancelled(#[from] volmorph_io::Cancelled),
}

impl SculptError {
    pub(crate) fn option(name: &'static str, value: impl ToString, expected: &'static str) -> Self {
        Self::InvalidOption {
            name,
            value: value.to_string(),
            expected,
        }
    }
}
