//! The error type of every fallible operation in this crate.

use volmorph_io::IoError;
use volmorph_spline::SplineError;

/// Errors of aggregate construction, modeling operators, fitting, evaluation, point inversion
/// and the JSON file format.
#[derive(Debug, thiserror::Error)]
pub enum TrivariateError {
    /// An error of the underlying spline layer (unsorted knots, wrong control-net size,
    /// non-positive weights, parameters outside the domain, …), with what was being built.
    #[error("{context}: {source}")]
    Spline {
        /// Which object or operation failed (e.g. `attribute "density"`).
        context: String,
        /// The spline-layer error.
        source: SplineError,
    },
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(#[from] IoError),
    /// Encoding a mesh failed (invalid extra property, writer failure).
    #[error(transparent)]
    Mesh(#[from] volmorph_mesh::MeshError),
    /// A JSON document is malformed or does not follow the format (message names the place).
    #[error("invalid trivariate JSON: {0}")]
    Json(String),
    /// A component's parametric domain is not the unit interval on some axis (Martin & Cohen
    /// §2.2 normalise every domain to the unit cube).
    #[error("{what}: domain of axis {axis} is [{start}, {end}], expected [0, 1]")]
    DomainNotUnit {
        /// The component (`geometry` or `attribute "name"`).
        what: String,
        /// Parametric axis (0 = u).
        axis: usize,
        /// Domain start.
        start: f64,
        /// Domain end.
        end: f64,
    },
    /// The geometry has the wrong number of coordinates.
    #[error("geometry must have {expected} coordinates per control point, got {got}")]
    GeometryDimension {
        /// Required dimension.
        expected: usize,
        /// Supplied dimension.
        got: usize,
    },
    /// Two attributes share a name, or an attribute name is empty.
    #[error("attribute name {0:?} is empty or used twice")]
    AttributeName(String),
    /// No attribute has this name.
    #[error("no attribute named {0:?}")]
    UnknownAttribute(String),
    /// The geometry's control points do not span as many dimensions as it has parameters (all
    /// control points of a volume coplanar, of a surface collinear, of a curve coincident).
    #[error("degenerate {what}: control points span only {rank} dimension(s), need {needed}")]
    Degenerate {
        /// `curve`, `surface` or `volume`.
        what: &'static str,
        /// Affine dimension of the control points.
        rank: usize,
        /// Number of parametric axes.
        needed: usize,
    },
    /// Two objects cannot be ruled or combined (differing degrees, dimensions, rationality).
    #[error("incompatible objects: {0}")]
    Incompatible(String),
    /// An argument is out of range (zero vector, zero angle, NaN, …); the message says which.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// A data array has the wrong length.
    #[error("{what}: expected {expected} values, got {got}")]
    DataLength {
        /// What the array holds.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Supplied length.
        got: usize,
    },
    /// Least squares needs at least as many samples as control points on every axis.
    #[error("axis {axis}: {samples} samples cannot determine {controls} control points")]
    TooFewSamples {
        /// Parametric axis.
        axis: usize,
        /// Samples on that axis.
        samples: usize,
        /// Control points on that axis.
        controls: usize,
    },
    /// A least-squares collocation matrix is numerically rank deficient (the sites leave a
    /// basis function without enough support; see `fit::RANK_TOLERANCE`).
    #[error(
        "axis {axis}: least-squares collocation matrix is rank deficient (the sample sites \
         leave a basis function with too little support)"
    )]
    RankDeficient {
        /// Parametric axis.
        axis: usize,
    },
    /// Point inversion found no parameters mapping to the point within tolerance.
    #[error(
        "no parameters map to ({}, {}, {}) within tolerance (best residual {})",
        volmorph_io::Num(*x),
        volmorph_io::Num(*y),
        volmorph_io::Num(*z),
        volmorph_io::Num(*residual)
    )]
    InversionFailed {
        /// Physical x.
        x: f64,
        /// Physical y.
        y: f64,
        /// Physical z.
        z: f64,
        /// Smallest distance reached.
        residual: f64,
    },
    /// A modeling recipe is malformed or one of its steps fails ([`crate::recipe`]).
    #[error("{source_name}: {json_path}: {message}")]
    Recipe {
        /// The recipe (its file name).
        source_name: String,
        /// JSON path of the field at fault, e.g. `steps[2].revolve.angle_degrees`.
        json_path: String,
        /// What is wrong.
        message: String,
    },
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; nothing was
    /// written.
    #[error("stopped on request")]
    Cancelled(#[from] volmorph_io::Cancelled),
}

/// Attach a context to a spline-layer error. The context is converted to a `String` only
/// when an error occurs, so `ctx("literal")` costs nothing on the success path of per-point
/// code (pass a closure's `format!` through `map_err(|e| ctx(format!(…))(e))` when the
/// context must be formatted).
pub(crate) fn ctx<C: Into<String>>(context: C) -> impl FnOnce(SplineError) -> TrivariateError {
    move |source| TrivariateError::Spline {
        context: context.into(),
        source,
    }
}
