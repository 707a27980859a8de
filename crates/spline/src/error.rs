//! The error type of every fallible operation in this crate.

/// Errors of knot-vector construction, spline construction, evaluation, refinement,
/// differentiation and interpolation.
///
/// Parameters outside a spline's domain are **rejected** (see
/// [`SplineError::ParameterOutsideDomain`]), never silently clamped; callers that want clamping
/// use [`crate::KnotVector::clamp`] or [`crate::KnotVector::find_span_clamped`] explicitly.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SplineError {
    /// A knot is NaN or infinite.
    #[error("knot {index} is not finite ({})", volmorph_io::Num(*value))]
    NonFiniteKnot {
        /// Position of the knot in the knot vector.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// Knots must be non-decreasing: `knots[index] < knots[index - 1]`.
    #[error("knots decrease at index {index}: {} then {}", volmorph_io::Num(*previous), volmorph_io::Num(*value))]
    DecreasingKnots {
        /// Position of the first knot smaller than its predecessor.
        index: usize,
        /// The predecessor's value.
        previous: f64,
        /// The offending value.
        value: f64,
    },
    /// A degree-`degree` basis needs at least `2·(degree + 1)` knots (so at least `degree + 1`
    /// control points).
    #[error("degree {degree} needs at least {needed} knots, got {len}")]
    TooFewKnots {
        /// Requested degree.
        degree: usize,
        /// Knots supplied.
        len: usize,
        /// Minimum number of knots.
        needed: usize,
    },
    /// Too few control points for the degree (needs `degree + 1`).
    #[error("degree {degree} needs at least {needed} control points, got {count}")]
    TooFewControlPoints {
        /// Requested degree.
        degree: usize,
        /// Control points requested.
        count: usize,
        /// Minimum count.
        needed: usize,
    },
    /// The degree exceeds [`crate::MAX_DEGREE`], the bound of the stack buffers used by
    /// allocation-free evaluation.
    #[error("degree {degree} exceeds the supported maximum {max}")]
    DegreeTooHigh {
        /// Requested degree.
        degree: usize,
        /// [`crate::MAX_DEGREE`].
        max: usize,
    },
    /// A knot value is repeated more than `degree + 1` times.
    #[error("knot {} has multiplicity {multiplicity}, more than degree + 1 = {max}", volmorph_io::Num(*value))]
    MultiplicityTooHigh {
        /// The repeated knot.
        value: f64,
        /// Its multiplicity.
        multiplicity: usize,
        /// Largest allowed multiplicity (`degree + 1`).
        max: usize,
    },
    /// The parametric domain `[u_p, u_n]` is empty or not finite.
    #[error("parametric domain [{}, {}] is empty or not finite", volmorph_io::Num(*start), volmorph_io::Num(*end))]
    EmptyDomain {
        /// Domain start.
        start: f64,
        /// Domain end.
        end: f64,
    },
    /// An interior knot given to a clamped constructor does not lie strictly inside the domain.
    #[error("interior knot {} is not strictly inside the domain [{}, {}]", volmorph_io::Num(*value), volmorph_io::Num(*start), volmorph_io::Num(*end))]
    InteriorKnotOutsideDomain {
        /// The knot.
        value: f64,
        /// Domain start.
        start: f64,
        /// Domain end.
        end: f64,
    },
    /// A parameter lies outside the domain `[start, end]` of `axis` (or is NaN).
    #[error("parameter {} on axis {axis} is outside the domain [{}, {}]", volmorph_io::Num(*value), volmorph_io::Num(*start), volmorph_io::Num(*end))]
    ParameterOutsideDomain {
        /// Parametric axis (0 = u, 1 = v, 2 = w).
        axis: usize,
        /// The parameter.
        value: f64,
        /// Domain start.
        start: f64,
        /// Domain end.
        end: f64,
    },
    /// A span index is not a non-empty span of the domain.
    #[error("{span} is not the index of a non-empty knot span inside the domain")]
    InvalidSpan {
        /// The span index.
        span: usize,
    },
    /// A knot to insert lies outside the domain.
    #[error("knot {} to insert is outside the domain [{}, {}]", volmorph_io::Num(*value), volmorph_io::Num(*start), volmorph_io::Num(*end))]
    KnotOutsideDomain {
        /// The knot.
        value: f64,
        /// Domain start.
        start: f64,
        /// Domain end.
        end: f64,
    },
    /// The number of values per control point must be at least 1.
    #[error("control values must have dimension >= 1")]
    ZeroDimension,
    /// A coefficient array does not have one `dim`-tuple per control point.
    #[error("expected {expected} coefficients, got {got}")]
    CoefficientCount {
        /// Required length.
        expected: usize,
        /// Supplied length.
        got: usize,
    },
    /// A control value is NaN or infinite.
    #[error("coefficient {index} is not finite ({})", volmorph_io::Num(*value))]
    NonFiniteCoefficient {
        /// Position in the flat coefficient array.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A rational weight is not finite and strictly positive.
    #[error("weight {index} is {}; weights must be finite and > 0", volmorph_io::Num(*value))]
    NonPositiveWeight {
        /// Linear control-point index.
        index: usize,
        /// The weight.
        value: f64,
    },
    /// An output or input buffer has the wrong length.
    #[error("buffer has length {got}, expected {expected}")]
    BufferLength {
        /// Required length.
        expected: usize,
        /// Supplied length.
        got: usize,
    },
    /// A control-point index is out of range.
    #[error("control index {index:?} is outside the control net {counts:?}")]
    IndexOutOfRange {
        /// The index.
        index: Vec<usize>,
        /// Control counts per axis.
        counts: Vec<usize>,
    },
    /// A parametric axis does not exist.
    #[error("axis {axis} does not exist for a {dims}-variate object")]
    InvalidAxis {
        /// Requested axis.
        axis: usize,
        /// Number of parametric axes.
        dims: usize,
    },
    /// Differentiation of a degree-0 direction (the derivative is not a spline).
    #[error("axis {axis} has degree 0; its derivative is not a B-spline")]
    DegreeZeroDerivative {
        /// The axis.
        axis: usize,
    },
    /// An operation needs a higher degree along `axis`.
    #[error("axis {axis} has degree {degree}; at least {min} is required")]
    DegreeTooLow {
        /// The axis.
        axis: usize,
        /// Its degree.
        degree: usize,
        /// Minimum degree.
        min: usize,
    },
    /// The derivative of a rational spline is not a rational spline of the same form.
    #[error(
        "the derivative of a rational spline is not a spline of the same kind; \
         use homogeneous_derivative"
    )]
    RationalDerivative,
    /// Interpolation sites do not match the control count of their axis.
    #[error("axis {axis} needs {expected} interpolation sites, got {got}")]
    SiteCount {
        /// The axis.
        axis: usize,
        /// Number of basis functions.
        expected: usize,
        /// Sites supplied.
        got: usize,
    },
    /// Interpolation sites must be non-decreasing and inside the domain.
    #[error("interpolation site {index} ({}) is decreasing or outside the domain", volmorph_io::Num(*value))]
    InvalidSite {
        /// Position of the site.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// The collocation matrix is singular: the sites violate the Schoenberg–Whitney condition
    /// (basis function `row` vanishes at site `row`) or elimination met a vanishing pivot.
    #[error("collocation matrix is singular at row {row} (Schoenberg-Whitney condition violated)")]
    SingularCollocation {
        /// Row of the failure.
        row: usize,
    },
    /// A [`crate::BasisTable`] was built for another knot vector than the spline's `axis`.
    #[error("basis table for axis {axis} was built for a different knot vector")]
    TableMismatch {
        /// The axis.
        axis: usize,
    },
    /// Gradients were requested from a [`crate::BasisTable`] built without derivatives.
    #[error("basis table for axis {axis} has no tabulated derivatives")]
    MissingDerivatives {
        /// The axis.
        axis: usize,
    },
    /// A size computation overflowed or exceeds the memory budget ([`volmorph_io::memory_limit`]).
    #[error("requested size is too large: {0}")]
    TooLarge(String),
}
