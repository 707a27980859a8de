//! Errors of the mesh deformation crate.

use volmorph_deform::DeformError;
use volmorph_io::IoError;
use volmorph_mesh::MeshError;
use volmorph_spline::SplineError;

/// Everything that can go wrong deforming a mesh, building trimmed surfaces or writing them.
#[derive(Debug, thiserror::Error)]
pub enum FfdError {
    /// The mesh has no faces (or every face was degenerate and dropped).
    #[error("the mesh has no usable faces")]
    EmptyMesh,
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate ({value})")]
    NonFinite {
        /// 0-based vertex index.
        vertex: usize,
        /// The offending value.
        value: f64,
    },
    /// A face is unusable and cannot be repaired (out-of-range index, a polygon whose
    /// projection self-intersects, …).
    #[error("face {face}: {message}")]
    BadFace {
        /// 0-based face index in the input mesh.
        face: usize,
        /// What is wrong.
        message: String,
    },
    /// A Bézier surface would need a degree above the precomputed interpolation matrices.
    #[error(
        "surface degree {degree} exceeds the supported maximum {max} (lattice degrees {lattice:?})"
    )]
    DegreeTooHigh {
        /// Required degree.
        degree: usize,
        /// Largest supported degree ([`crate::interp::MAX_INTERPOLATION_DEGREE`]).
        max: usize,
        /// Degrees of the lattice.
        lattice: [usize; 3],
    },
    /// The lattice given to a prepared plan does not have the knots and frame the plan was
    /// built for.
    #[error("lattice does not match the prepared plan: {0}")]
    LatticeMismatch(String),
    /// An option value is out of range.
    #[error("invalid option: {0}")]
    InvalidOption(String),
    /// A size limit would be exceeded.
    #[error("too large: {0}")]
    TooLarge(String),
    /// An internal consistency check of the subdivision or of the trimming topology failed.
    #[error("inconsistent geometry: {0}")]
    Inconsistent(String),
    /// From the lattice.
    #[error(transparent)]
    Deform(#[from] DeformError),
    /// From the spline layer.
    #[error(transparent)]
    Spline(#[from] SplineError),
    /// From mesh construction or mesh I/O.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// From file I/O.
    #[error(transparent)]
    Io(#[from] IoError),
    /// Writing output failed.
    #[error("write failed: {0}")]
    Write(#[from] std::io::Error),
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; nothing was
    /// written.
    #[error("stopped on request")]
    Cancelled(#[from] volmorph_io::Cancelled),
}
