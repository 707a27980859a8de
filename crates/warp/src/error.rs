//! Errors of the warping crate.

use volmorph_deform::DeformError;
use volmorph_volume::VolumeError;

/// Everything that can go wrong applying a space map to a volume.
#[derive(Debug, thiserror::Error)]
pub enum WarpError {
    /// A grid passed by the caller is unusable (zero dims, bad spacing, singular direction,
    /// too many voxels for the output voxel type). `what` names the grid.
    #[error("{what}: {source}")]
    Geometry {
        /// Which grid is invalid (e.g. "output grid").
        what: &'static str,
        /// The geometry or size problem.
        #[source]
        source: VolumeError,
    },
    /// An output buffer does not have one value per voxel of the output grid.
    #[error("output buffer has {got} values, the output grid {dims:?} needs {expected}")]
    BufferLength {
        /// Output grid dims.
        dims: [usize; 3],
        /// Voxel count of the output grid.
        expected: usize,
        /// Values supplied.
        got: usize,
    },
    /// An option value is unusable (e.g. a Newton tolerance that is not a positive number).
    #[error("invalid option: {0}")]
    InvalidOption(String),
    /// Evaluating the space map failed.
    #[error("evaluating the space map: {0}")]
    Map(#[from] DeformError),
    /// Evaluating the space map on one of a push-forward's evaluation grids failed.
    #[error("evaluating the map on the {grid} grid: {source}")]
    MapOnGrid {
        /// Which grid: `"voxel-centre"`, `"x-face"`, `"y-face"` or `"z-face"`.
        grid: &'static str,
        /// The map's error.
        #[source]
        source: DeformError,
    },
    /// A background (fill) value is NaN or infinite.
    #[error("background value {0} is not finite")]
    Background(f64),
    /// Setting parameters of a live-edited map failed (index out of range, NaN or infinite
    /// value).
    #[error("cannot set the map's parameters: {0}")]
    Parameters(#[source] DeformError),
    /// A map handed to an incremental engine has another structure than the engine's map
    /// (other knots or frame of a lattice, other sources of a handle map): only parameter
    /// values may change between updates.
    #[error(
        "the new map has another structure than the current one (knots, frame or source \
         handles); only parameter values may change"
    )]
    StructureMismatch,
    /// An option combination the operation does not support.
    #[error("unsupported: {0}")]
    Unsupported(&'static str),
    /// A working buffer could not be allocated.
    #[error("cannot allocate {bytes} bytes for the {what} buffer")]
    Allocation {
        /// Which buffer.
        what: &'static str,
        /// Bytes requested (saturating).
        bytes: usize,
    },
    /// Preparing the input volume for sampling failed (e.g. the cubic B-spline coefficient
    /// array would exceed the allocation limit).
    #[error(transparent)]
    Volume(#[from] VolumeError),
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; nothing was
    /// written.
    #[error("stopped on request")]
    Cancelled(#[from] volmorph_io::Cancelled),
}
