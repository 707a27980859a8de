//! volmorph-spline: knot vectors, B-spline / NURBS / Bernstein bases, curves, surfaces and
//! trivariate volumes, knot insertion and refinement, Bézier extraction, derivative control
//! nets and Greville interpolation. No I/O.
//!
//! * [`KnotVector`] — validated degree-bound knot vectors (uniform, clamped, arbitrary with
//!   multiplicities), right-open span search, Greville abscissae ([`knots`] states the
//!   conventions).
//! * [`basis_funs_into`], [`basis_funs_and_derivs_into`], [`BasisWorkspace`] — B-spline basis
//!   functions and derivatives (NURBS Book A2.2/A2.3) into caller buffers;
//!   [`uniform_cubic`] — True's `B0 … B3`; [`bernstein_into`] and friends — Bernstein basis.
//! * [`TensorBSpline<N>`] with aliases [`BSplineCurve`], [`BSplineSurface`],
//!   [`BSplineVolume`] — polynomial or rational tensor products of any value dimension,
//!   homogeneous flat storage with axis 0 fastest ([`spline`] states the layout), allocation-free
//!   evaluation of values and first derivatives.
//! * [`TensorBSpline::refine`] / [`TensorBSpline::insert_knot`] — Boehm insertion and A5.4
//!   refinement per axis; [`TensorBSpline::bezier_pieces`] — [`BezierPiece`]s per span box.
//! * [`BasisTable`] and [`TensorBSpline::eval_grid_into`] — parallel evaluation on parameter
//!   grids with precomputed basis tables (True §5.2).
//! * [`TensorBSpline::derivative`] — derivative control nets (Martin & Cohen §2.1).
//! * [`interpolate_greville`], [`Interpolator`], [`Collocation`] — separable tensor-product
//!   interpolation (Martin & Cohen §3) with banded LU per axis.
//!
//! Parameters outside a domain are rejected with [`SplineError::ParameterOutsideDomain`], never
//! clamped silently.

pub mod basis;
pub mod bernstein;
pub mod bezier;
mod derivative;
mod error;
pub mod grid;
pub mod interpolate;
pub mod knots;
mod refine;
pub mod spline;

pub use basis::{
    BasisWorkspace, basis_derivs, basis_funs, basis_funs_and_derivs_into, basis_funs_into,
    basis_in_span, uniform_cubic, uniform_cubic_derivative, uniform_cubic_second_derivative,
};
pub use bernstein::{bernstein, bernstein_derivative_into, bernstein_into};
pub use bezier::{BezierCell, BezierPatch, BezierPiece, BezierSegment};
pub use error::SplineError;
pub use grid::BasisTable;
pub use interpolate::{Collocation, Interpolator, interpolate_greville};
pub use knots::{KnotSpan, KnotVector, MAX_DEGREE};
pub use spline::{BSplineCurve, BSplineSurface, BSplineVolume, TensorBSpline};
