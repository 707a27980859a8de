//! [`BenchError`]: why a benchmark could not be set up or run.

use thiserror::Error;

/// Why a benchmark could not be set up or run: a setting out of range, or the library call
/// being timed (or building its input) failed.
#[derive(Debug, Error)]
pub enum BenchError {
    /// A setting of a suite is out of its range. `setting` is the field's name (a front-end
    /// spells it its own way, e.g. `--edit-size` for `edit_size`), `value` what was given and
    /// `expected` what is allowed.
    #[error("{setting} {value} {expected}")]
    Setting {
        /// The setting's name, as the field of the suite's configuration.
        setting: &'static str,
        /// The value given.
        value: String,
        /// What is allowed, e.g. "must be between 4 and 1024".
        expected: String,
    },
    /// A case produced a result that shows it did not do the work it times (e.g. a drag that
    /// changed no voxel, a result that differs from the reference).
    #[error("{case}: {message}")]
    Check {
        /// The case's name.
        case: String,
        /// What is wrong.
        message: String,
    },
    /// Building a volume failed.
    #[error(transparent)]
    Volume(#[from] volmorph_volume::VolumeError),
    /// Building or editing a map failed.
    #[error(transparent)]
    Deform(#[from] volmorph_deform::DeformError),
    /// Solving a drag failed.
    #[error(transparent)]
    Drag(#[from] volmorph_lattice::DragError),
    /// A warp failed.
    #[error(transparent)]
    Warp(#[from] volmorph_warp::WarpError),
    /// An isosurface extraction failed.
    #[error(transparent)]
    Contour(#[from] volmorph_contour::ContourError),
    /// A mesh deformation failed.
    #[error(transparent)]
    Ffd(#[from] volmorph_ffd::FfdError),
    /// Compiling or sampling an F-rep model failed.
    #[error(transparent)]
    Frep(#[from] volmorph_frep::FrepError),
    /// A scene command failed.
    #[error(transparent)]
    Scene(#[from] volmorph_scene::SceneError),
}

impl BenchError {
    /// A [`BenchError::Setting`] for `setting = value`, which must lie in `range`.
    pub(crate) fn range<T: std::fmt::Display + PartialOrd>(
        setting: &'static str,
        value: T,
        range: std::ops::RangeInclusive<T>,
    ) -> Result<(), Self> {
        if range.contains(&value) {
            return Ok(());
        }
        Err(Self::Setting {
            setting,
            value: value.to_string(),
            expected: format!("must be between {} and {}", range.start(), range.end()),
        })
    }

    /// A [`BenchError::Check`].
    pub fn check(case: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Check {
            case: case.into(),
            message: message.into(),
        }
    }
}
