//! Errors of scene commands, files and projects.

use crate::ObjectId;

/// Everything a scene command, an import, an export or a project file can fail with. A failed
/// command leaves the scene exactly as it was.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// No object has this id.
    #[error("no object {0}")]
    NoObject(ObjectId),
    /// The object exists but is of another kind than the command needs.
    #[error("object {id} ({name:?}) is a {found}, the command needs a {expected}")]
    WrongKind {
        /// The object.
        id: ObjectId,
        /// Its name.
        name: String,
        /// What the command needs.
        expected: &'static str,
        /// What the object is.
        found: &'static str,
    },
    /// An object still used by a derived object cannot be removed or retyped.
    #[error("object {id} is used by {users:?}; remove those first")]
    InUse {
        /// The object.
        id: ObjectId,
        /// The derived objects computed from it.
        users: Vec<ObjectId>,
    },
    /// A command's arguments are not usable (index out of range, non-finite value, …).
    #[error("{0}")]
    Invalid(String),
    /// A map refused the edit or its description.
    #[error(transparent)]
    Deform(#[from] volmorph_deform::DeformError),
    /// A drag could not be solved.
    #[error(transparent)]
    Drag(#[from] volmorph_lattice::DragError),
    /// A map file or map description failed.
    #[error(transparent)]
    Map(#[from] volmorph_maps::MapError),
    /// A warp failed.
    #[error(transparent)]
    Warp(#[from] volmorph_warp::WarpError),
    /// A volume failed (file, geometry).
    #[error(transparent)]
    Volume(#[from] volmorph_volume::VolumeError),
    /// A mesh failed (file, topology).
    #[error(transparent)]
    Mesh(#[from] volmorph_mesh::MeshError),
    /// Isosurface extraction failed.
    #[error(transparent)]
    Contour(#[from] volmorph_contour::ContourError),
    /// An F-rep model failed to parse, compile or evaluate (the message carries the line and
    /// column).
    #[error(transparent)]
    Frep(#[from] volmorph_frep::FrepError),
    /// A trivariate model failed.
    #[error(transparent)]
    Trivariate(#[from] volmorph_trivariate::TrivariateError),
    /// A sculpting edit failed (the sculpt object is unchanged).
    #[error(transparent)]
    Sculpt(#[from] volmorph_sculpt::SculptError),
    /// A picture could not be drawn or written (the message names the file).
    #[error(transparent)]
    Render(#[from] volmorph_render::RenderError),
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(#[from] volmorph_io::IoError),
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; the scene,
    /// its history and the files are as they were before the call.
    #[error("cancelled")]
    Cancelled(#[from] volmorph_io::Cancelled),
    /// An accurate FFD or its STEP file failed.
    #[error(transparent)]
    Ffd(#[from] volmorph_ffd::FfdError),
    /// A step of the lung model (segmentation, lobe tracing) failed or its script does not
    /// fit the volume.
    #[error(transparent)]
    Register(#[from] volmorph_register::RegisterError),
    /// A project file is malformed.
    #[error("project {path}: {message}")]
    Project {
        /// The project file.
        path: String,
        /// What is wrong.
        message: String,
    },
}

impl SceneError {
    pub(crate) fn invalid(message: impl Into<String>) -> Self {
        SceneError::Invalid(message.into())
    }

    /// `true` when the error is a cancellation asked through a [`volmorph_io::Progress`]
    /// (this variant, or a library's cancellation error anywhere in the source chain), not a
    /// failure: front-ends report it as "cancelled", not as an error.
    #[must_use]
    pub fn is_cancelled(&self) -> bool {
        matches!(self, SceneError::Cancelled(_)) || volmorph_io::is_cancelled_error(self)
    }
}
