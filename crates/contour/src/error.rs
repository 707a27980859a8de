use volmorph_mesh::MeshError;
use volmorph_volume::VolumeError;

/// Errors of isosurface extraction.
#[derive(Debug, thiserror::Error)]
pub enum ContourError {
    /// The iso level is NaN or infinite.
    #[error("iso level must be a finite number, got {0}")]
    NonFiniteLevel(f64),
    /// A dimension of the volume has fewer than two samples, so the grid has no cells.
    #[error(
        "volume dims {dims:?}: isosurface extraction needs at least 2 samples along every axis"
    )]
    TooSmall {
        /// The volume's dims `[nx, ny, nz]`.
        dims: [usize; 3],
    },
    /// The surface would have more vertices than 32-bit indices (or the allocation limit)
    /// allow.
    #[error("the isosurface would have {count} vertices, more than the limit of {limit}")]
    TooManyVertices {
        /// Number of vertices the surface needs.
        count: usize,
        /// Largest number allowed.
        limit: usize,
    },
    /// An option is out of its documented range.
    #[error("option {name} = {value} is invalid: expected {expected}")]
    InvalidOption {
        /// Name of the option field.
        name: &'static str,
        /// The value given.
        value: f64,
        /// The accepted range.
        expected: &'static str,
    },
    /// The volume's geometry is invalid (singular direction, bad spacing, …).
    #[error(transparent)]
    Volume(#[from] VolumeError),
    /// Building the mesh failed (too many triangles for 32-bit face corners).
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; nothing was
    /// written.
    #[error("stopped on request")]
    Cancelled(#[from] volmorph_io::Cancelled),
}
