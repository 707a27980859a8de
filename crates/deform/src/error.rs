//! Errors of the deformation crate.

use volmorph_spline::SplineError;
use volmorph_volume::VolumeError;

/// Everything that can go wrong building, editing, evaluating or (de)serialising a space map.
#[derive(Debug, thiserror::Error)]
pub enum DeformError {
    /// An output buffer does not have one entry per input point / grid voxel.
    #[error("output buffer has {got} points, expected {expected}")]
    BufferLength {
        /// Required number of points.
        expected: usize,
        /// Number of points supplied.
        got: usize,
    },
    /// A lattice axis has fewer control points than its degree requires.
    #[error("lattice axis {axis} has {count} control points, needs at least {min}")]
    TooFewControlPoints {
        /// Axis 0 (u), 1 (v) or 2 (w).
        axis: usize,
        /// Control points supplied.
        count: usize,
        /// Minimum for that axis (degree + 1).
        min: usize,
    },
    /// A lattice would have more control points than any lattice may have (the same cap
    /// for lattices read from files and lattices created from options).
    #[error(
        "a lattice of {}×{}×{} control points exceeds the limit of {max} control points",
        counts[0], counts[1], counts[2]
    )]
    TooManyControlPoints {
        /// Control points per axis asked for.
        counts: [usize; 3],
        /// The cap.
        max: usize,
    },
    /// The box a lattice is built around is empty, inverted or not finite along an axis.
    #[error("lattice box is degenerate along axis {axis}: min {}, max {}", volmorph_io::Num(*min), volmorph_io::Num(*max))]
    DegenerateBox {
        /// Axis 0 (x), 1 (y) or 2 (z) of the box.
        axis: usize,
        /// Lower bound given.
        min: f64,
        /// Upper bound given.
        max: f64,
    },
    /// The parameter frame of a lattice is unusable (non-finite values, non-positive spacing,
    /// axes that are not orthonormal and right- or left-handed unit vectors).
    #[error("invalid lattice frame: {0}")]
    InvalidFrame(String),
    /// A control point or other coordinate is NaN or infinite.
    #[error("{what} is not finite: {}", volmorph_io::Num(*value))]
    NonFinite {
        /// Which value (e.g. "control point 12, component 1").
        what: String,
        /// The offending value.
        value: f64,
    },
    /// A control-point index lies outside the lattice.
    #[error("control point index {index:?} outside lattice of {counts:?} points")]
    IndexOutOfRange {
        /// Index asked for.
        index: [usize; 3],
        /// Control points per axis.
        counts: [usize; 3],
    },
    /// A lattice description (JSON) is inconsistent with itself.
    #[error("invalid lattice description: {0}")]
    InvalidDescription(String),
    /// A grid fast path needs the grid's index axes parallel to the lattice's parameter axes.
    #[error("grid not aligned with lattice: {0}")]
    GridNotAligned(String),
    /// True's coefficient-table path does not apply to this grid and lattice.
    #[error("coefficient table unavailable: {0}")]
    TableUnavailable(String),
    /// A transform file (ITK `.tfm`, plastimatch `.bxf`) that does not have its documented
    /// layout.
    #[error("{format} file{}: {message}", line_part(*line))]
    Parse {
        /// Format name, e.g. "ITK transform".
        format: &'static str,
        /// 1-based line number of the offending text (0 when the problem is the whole file).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A well-formed file or a lattice that the other format cannot represent (another
    /// transform type, a composite transform, a non-cubic or non-uniform lattice, …).
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// Handles (control points, frames, segments, spline centres) unusable for the requested
    /// map: too few, coincident, degenerate (all on a plane), mismatched source/target counts,
    /// an index out of range, or parameters out of their domain.
    #[error("invalid handles: {0}")]
    InvalidHandles(String),
    /// A linear system that should be regular is numerically singular.
    #[error("singular system: {0}")]
    Singular(String),
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(#[from] volmorph_io::IoError),
    /// JSON text that does not parse or does not have the documented shape.
    #[error("{what}: {error}")]
    Json {
        /// What the text was parsed as, e.g. "lattice JSON" or "handle JSON".
        what: &'static str,
        /// The parser's error (it names the line and column).
        error: serde_json::Error,
    },
    /// An invalid voxel grid was passed to a grid evaluation.
    #[error(transparent)]
    Grid(#[from] VolumeError),
    /// An error from the spline layer (knot vectors, evaluation).
    #[error(transparent)]
    Spline(#[from] SplineError),
    /// An error attributed to a file path.
    ///
    /// Displays as `path: error`; the inner error is part of the message, not a separate
    /// `source()`, so error chains do not repeat it.
    #[error("{path}: {error}")]
    File {
        /// The file concerned.
        path: String,
        /// What went wrong.
        error: Box<DeformError>,
    },
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; nothing was
    /// written.
    #[error("stopped on request")]
    Cancelled(#[from] volmorph_io::Cancelled),
}

/// `", line N"` for a 1-based line, nothing for 0 (a problem of the whole file).
fn line_part(line: usize) -> String {
    if line == 0 {
        String::new()
    } else {
        format!(", line {line}")
    }
}

impl DeformError {
    /// A [`DeformError::Json`] for text parsed as `what` (e.g. "handle JSON").
    pub fn json(what: &'static str) -> impl FnOnce(serde_json::Error) -> Self {
        move |error| Self::Json { what, error }
    }

    /// Attach a file path to this error (no-op if it already carries one, or if it is an OS
    /// error about this very file, which names it already).
    #[must_use]
    pub fn at(self, path: &std::path::Path) -> Self {
        match self {
            e @ Self::File { .. } => e,
            Self::Io(e) if e.path().is_some_and(|p| std::path::Path::new(p) == path) => Self::Io(e),
            e => Self::File {
                path: path.display().to_string(),
                error: Box::new(e),
            },
        }
    }

    /// The error without the file paths attached by [`DeformError::at`].
    #[must_use]
    pub fn innermost(&self) -> &Self {
        match self {
            Self::File { error, .. } => error.innermost(),
            e => e,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A handle file error about the whole file said "line 0".
    #[test]
    fn handle_error_reports_line_0() {
        let e = DeformError::Parse {
            format: "handle JSON",
            line: 0,
            message: "version 7 not supported".into(),
        };
        assert_eq!(e.to_string(), "handle JSON file: version 7 not supported");
        let e = DeformError::Parse {
            format: "ITK transform",
            line: 3,
            message: "x".into(),
        };
        assert_eq!(e.to_string(), "ITK transform file, line 3: x");
    }

    /// Handle JSON errors were labelled "lattice JSON".
    #[test]
    fn handle_json_parse_error_labelled_lattice_json() {
        let bad = serde_json::from_str::<serde_json::Value>("{").unwrap_err();
        let e = DeformError::json("handle JSON")(bad);
        let msg = e.to_string();
        assert!(
            msg.starts_with("handle JSON: ") && !msg.contains("lattice"),
            "{msg}"
        );
        let at = e.at(std::path::Path::new("dir/h.json"));
        assert!(
            at.to_string().starts_with("dir/h.json: handle JSON: "),
            "{at}"
        );
        assert!(matches!(at.innermost(), DeformError::Json { .. }));
    }
}
