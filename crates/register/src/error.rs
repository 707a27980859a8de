//! Errors of the registration crate.

use volmorph_deform::DeformError;
use volmorph_volume::VolumeError;
use volmorph_warp::WarpError;

/// Everything that can go wrong selecting handles, matching them, solving, refining, checking
/// or measuring a registration.
#[derive(Debug, thiserror::Error)]
pub enum RegisterError {
    /// An option is out of its domain (`what` names it, `why` says what is allowed).
    #[error("invalid option {what}: {why}")]
    Option {
        /// The option, e.g. `"radius"`.
        what: &'static str,
        /// What is wrong and what is allowed.
        why: String,
    },
    /// Two inputs that must describe the same thing do not (sizes, grids, counts).
    #[error("mismatched inputs: {0}")]
    Mismatch(String),
    /// Not enough usable data for the step (too few handles, an empty mask, no landmarks).
    #[error("not enough data: {0}")]
    TooLittle(String),
    /// A text or JSON input that does not have its documented layout.
    #[error("{file}: {message}")]
    Parse {
        /// File (or description of the text) being read.
        file: String,
        /// What is wrong, with the line or field.
        message: String,
    },
    /// A volume could not be read, written or built.
    #[error(transparent)]
    Volume(#[from] VolumeError),
    /// A map could not be built or evaluated.
    #[error(transparent)]
    Map(#[from] DeformError),
    /// A map file could not be read or written, or a map could not be built by name.
    #[error(transparent)]
    Maps(#[from] volmorph_maps::MapError),
    /// Applying a map to a volume failed.
    #[error(transparent)]
    Warp(#[from] WarpError),
    /// A picture could not be made or written.
    #[error(transparent)]
    Render(#[from] volmorph_render::RenderError),
    /// A file operation failed.
    #[error(transparent)]
    Io(#[from] volmorph_io::IoError),
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; nothing was
    /// written.
    #[error("stopped on request")]
    Cancelled(#[from] volmorph_io::Cancelled),
}

impl RegisterError {
    /// An [`RegisterError::Option`] error.
    pub(crate) fn option(what: &'static str, why: impl Into<String>) -> Self {
        Self::Option {
            what,
            why: why.into(),
        }
    }
}

/// Check that an option is finite and positive.
pub(crate) fn positive(what: &'static str, v: f64) -> Result<f64, RegisterError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(RegisterError::option(
            what,
            format!("must be finite and > 0, got {}", volmorph_io::Num(v)),
        ))
    }
}

/// Check that an option is finite and non-negative.
pub(crate) fn non_negative(what: &'static str, v: f64) -> Result<f64, RegisterError> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(RegisterError::option(
            what,
            format!("must be finite and ≥ 0, got {}", volmorph_io::Num(v)),
        ))
    }
}
