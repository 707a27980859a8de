//! Trivariate B-spline lattice maps (free-form deformation lattices).
//!
//! A [`BSplineLattice`] is the map
//!
//! ```text
//! x ↦ Σ_ijk N_i(u) N_j(v) N_k(w) P_ijk,    (u, v, w) = F⁻¹(x)
//! ```
//!
//! where `N` are the B-spline basis functions of one [`KnotVector`] per axis, `P_ijk` are
//! control points in **physical** coordinates (index `i` fastest, then `j`, then `k`), and `F`
//! is the lattice's [`LatticeFrame`], the affine map from parameter space to physical space
//!
//! ```text
//! F(u) = origin + axes · (spacing ⊙ u),    F⁻¹(x) = (axes · diag(spacing))⁻¹ · (x − origin)
//! ```
//!
//! with unit `axes` (columns: physical direction of the u, v and w axes). Parameter `u`
//! therefore counts lattice cells of physical size `spacing.x` along `axes.x_axis`.
//!
//! # Orthonormal and skewed frames
//!
//! Most lattices have **orthonormal** axes (a box, possibly rotated; then
//! `F⁻¹(x) = spacing⁻¹ ⊙ (axesᵀ · (x − origin))`). A **skewed** frame
//! ([`LatticeFrame::parallelepiped`], [`LatticeFrame::skewed`]) has unit axes at arbitrary,
//! non-degenerate angles: the lattice box is then Sederberg and Parry's parallelepiped
//! (True 1992 §2.1), `Q = Q₀ + sS + tT + uU` with `S, T, U` the frame's edge vectors
//! ([`LatticeFrame::edges`], the columns of `axes · diag(spacing)`) and the local coordinates
//! `(s, t, u)` found by the linear equations of §2.1 (here the inverse of the edge matrix).
//! Everything a lattice does — evaluation, analytic Jacobians (`∂S/∂u · F⁻¹'s matrix`), Newton
//! inversion, drags, the JSON form — holds for either kind; the fast grid paths apply when a
//! grid's index axes are parallel to the lattice axes (e.g. a sheared CT grid and the lattice
//! placed on its voxels), and fall back to pointwise evaluation otherwise.
//!
//! # Identity placement
//!
//! Placing `P_ijk = F(ξ_i, ξ_j, ξ_k)` at the Greville abscissae `ξ` of the knot vectors makes
//! the map **exactly the identity** on the lattice's box (B-splines reproduce linear functions
//! from their Greville abscissae, and the map is affine-invariant). For the uniform cubic
//! lattices of True 1992 §5.5 / Fig. 8 with `n` control points along an axis, the knots are
//! the integers `−3 … n` with domain `[0, n − 3]`, so the box is divided into `n − 3` equal
//! regions and control point `i` sits at parameter `ξ_i = i − 1`: an evenly spaced lattice
//! whose first and last control points lie **one region outside** the box on each side
//! (Fig. 8 for `n = 9`: a 6 × 6 grid of regions, control points at −1, 0, …, 7). Bézier
//! (Sederberg–Parry) lattices use single-span clamped knot vectors on `[0, 1]`, whose Greville
//! abscissae `i / l` place the control points evenly on the box, corners included.
//!
//! # Outside the box
//!
//! The map is defined on the box `F([a_u, b_u] × [a_v, b_v] × [a_w, b_w])` (the closed knot
//! domains). **Points outside the box are not moved** (`apply(x) = x`, Jacobian `I`), as in
//! Sederberg–Parry FFD. The resulting map is continuous across the box surface exactly when the
//! displacement `map(x) − x` vanishes on that surface. For the uniform cubic placement, the
//! displacement on the face `u = 0` is a blend of the control points with `i ∈ {0, 1, 2}` only
//! (`B_3(0) = 0`), so the map is continuous — indeed C² — across the whole box surface as long
//! as the **three outermost layers of control points on every side are left at their identity
//! places**; moving any of them creates a jump at the surface. For clamped (Bézier) knots the
//! face values depend only on the face's own control points, so continuity (C⁰ only) requires
//! the outermost layer to stay in place.

use glam::{DMat3, DVec3};
use volmorph_spline::{BSplineVolume, KnotVector, SplineError, TensorBSpline};
use volmorph_volume::Geometry;
use volmorph_volume::direction::{DIRECTION_ORTHONORMAL_TOL, orthonormalize};

use rayon::prelude::*;

use volmorph_deform::DeformError;
use volmorph_deform::map::{SpaceMap, apply_grid_pointwise};
use volmorph_io::Nums;

/// Points per parallel work item of [`BSplineLattice`]'s batch evaluation.
const BATCH_CHUNK: usize = 4096;

/// Largest order (degree + 1) of the small-degree batch kernel.
const SMALL_ORDER: usize = 4;

/// Smallest volume `|det(axes)|` of the parallelepiped spanned by the unit axes of a skewed
/// [`LatticeFrame`] (1 for orthonormal axes, 0 for coplanar ones). The condition number of the
/// axes matrix is at most about `2 / |det|`, so above this bound parameters keep at least 12
/// significant digits of their `f64` precision through `F⁻¹`; a lattice closer to flat (two
/// axes within 0.06° of each other) is refused as degenerate.
pub const MIN_FRAME_VOLUME: f64 = 1e-3;

/// An axis whose length is within this of 1 counts as a unit vector in
/// [`LatticeFrame::skewed`] and is kept bit for bit (a normalised vector has a length within a
/// few ulps of 1).
const UNIT_AXIS_TOL: f64 = 8.0 * f64::EPSILON;

/// The affine frame of a lattice: parameter `u ↦ origin + axes·(spacing ⊙ u)`, with orthonormal
/// or skewed unit axes. See the [module docs](self).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatticeFrame {
    origin: DVec3,
    axes: DMat3,
    spacing: DVec3,
    to_param: DMat3,
    skewed: bool,
}

impl LatticeFrame {
    /// A frame with physical position `origin` of parameter `(0, 0, 0)`, orthonormal `axes`
    /// (columns: physical directions of u, v, w; either handedness) and physical length
    /// `spacing` of one parameter unit along each axis.
    ///
    /// Axes orthonormal within
    /// [`DIRECTION_ORTHONORMAL_TOL`] (e.g. an oblique scan's direction,
    /// orthonormal only to single precision) are replaced by their polar factor, the nearest
    /// orthonormal matrix, by [`orthonormalize`] — the rule every direction entering volmorph
    /// follows; [`LatticeFrame::axes`] returns the snapped matrix. For skewed axes use
    /// [`LatticeFrame::skewed`].
    ///
    /// # Errors
    /// [`DeformError::InvalidFrame`] for non-finite values, a spacing that is not > 0, or axes
    /// whose Gram matrix deviates from `I` by more than
    /// [`DIRECTION_ORTHONORMAL_TOL`].
    pub fn new(origin: DVec3, axes: DMat3, spacing: DVec3) -> Result<Self, DeformError> {
        check_origin_spacing(origin, spacing)?;
        if !axes.is_finite() {
            return Err(DeformError::InvalidFrame("axes are not finite".into()));
        }
        let axes = orthonormalize(axes).map_err(|e| {
            DeformError::InvalidFrame(format!(
                "lattice axes {}: {e} (a skewed lattice is made by LatticeFrame::skewed)",
                columns_text(axes)
            ))
        })?;
        let to_param = DMat3::from_diagonal(spacing.recip()) * axes.transpose();
        Ok(Self {
            origin,
            axes,
            spacing,
            to_param,
            skewed: false,
        })
    }

    /// A frame whose axes may be **skewed** (Sederberg–Parry's parallelepiped, True 1992
    /// §2.1): `axes` columns are the physical directions of u, v, w, of any non-zero length
    /// (each is normalised, its length folded into `spacing`) and at any non-degenerate angles;
    /// `spacing` is the physical length of one parameter unit along each (normalised) axis.
    /// Axes that are orthonormal within
    /// [`DIRECTION_ORTHONORMAL_TOL`] after normalisation give the orthonormal frame of
    /// [`LatticeFrame::new`] (snapped by the one direction rule), so a frame is skewed exactly
    /// when [`LatticeFrame::is_skewed`] says so.
    ///
    /// # Errors
    /// [`DeformError::InvalidFrame`] for non-finite values, a spacing that is not > 0, a zero
    /// axis, or unit axes spanning a volume below [`MIN_FRAME_VOLUME`] (nearly coplanar).
    pub fn skewed(origin: DVec3, axes: DMat3, spacing: DVec3) -> Result<Self, DeformError> {
        check_origin_spacing(origin, spacing)?;
        if !axes.is_finite() {
            return Err(DeformError::InvalidFrame("axes are not finite".into()));
        }
        let mut unit = axes;
        let mut spacing = spacing;
        for a in 0..3 {
            let len = axes.col(a).length();
            if !(len.is_finite() && len > 0.0) {
                return Err(DeformError::InvalidFrame(format!(
                    "lattice axis {a} {} has no direction",
                    Nums(&axes.col(a).to_array())
                )));
            }
            // Unit to rounding (as written by `to_json`): keep the bits, so a written frame
            // reads back identical.
            if (len - 1.0).abs() > UNIT_AXIS_TOL {
                *unit.col_mut(a) = axes.col(a) / len;
                spacing[a] *= len;
            }
        }
        if volmorph_volume::direction::orthonormality_deviation(unit) <= DIRECTION_ORTHONORMAL_TOL {
            return Self::new(origin, unit, spacing);
        }
        let volume = unit.determinant();
        if volume.is_nan() || volume.abs() < MIN_FRAME_VOLUME {
            return Err(DeformError::InvalidFrame(format!(
                "lattice axes {} span a volume of {volume:.3e} (unit axes), below \
                 {MIN_FRAME_VOLUME:e}: the parallelepiped is degenerate",
                columns_text(unit)
            )));
        }
        let edges = unit * DMat3::from_diagonal(spacing);
        if !(edges.is_finite() && spacing.is_finite()) {
            return Err(DeformError::InvalidFrame(format!(
                "lattice edges {} overflow",
                columns_text(edges)
            )));
        }
        let to_param = edges.inverse();
        if !to_param.is_finite() {
            return Err(DeformError::InvalidFrame(format!(
                "lattice edges {} cannot be inverted",
                columns_text(edges)
            )));
        }
        Ok(Self {
            origin,
            axes: unit,
            spacing,
            to_param,
            skewed: true,
        })
    }

    /// The frame of Sederberg and Parry's parallelepiped (True 1992 §2.1): parameter
    /// `(0, 0, 0)` at `origin` and one parameter unit along u, v, w given by the physical edge
    /// vectors `edges` (columns `S, T, U`), so `F(s, t, u) = origin + sS + tT + uU`. Orthonormal
    /// or skewed as [`LatticeFrame::skewed`] decides.
    ///
    /// # Errors
    /// As [`LatticeFrame::skewed`].
    pub fn parallelepiped(origin: DVec3, edges: DMat3) -> Result<Self, DeformError> {
        Self::skewed(origin, edges, DVec3::ONE)
    }

    /// An axis-aligned frame (`axes = I`).
    ///
    /// # Errors
    /// As [`LatticeFrame::new`].
    pub fn axis_aligned(origin: DVec3, spacing: DVec3) -> Result<Self, DeformError> {
        Self::new(origin, DMat3::IDENTITY, spacing)
    }

    /// Physical position of parameter `(0, 0, 0)`.
    #[must_use]
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// Unit axes (columns: physical directions of u, v, w); orthonormal unless
    /// [`LatticeFrame::is_skewed`].
    #[must_use]
    pub fn axes(&self) -> DMat3 {
        self.axes
    }

    /// Physical length of one parameter unit along u, v, w.
    #[must_use]
    pub fn spacing(&self) -> DVec3 {
        self.spacing
    }

    /// `true` for a skewed frame (axes not orthonormal; see [`LatticeFrame::skewed`]).
    #[must_use]
    pub fn is_skewed(&self) -> bool {
        self.skewed
    }

    /// The edge vectors of one parameter unit, `axes · diag(spacing)` (columns `S, T, U` of
    /// True's §2.1): the linear part of `F`.
    #[must_use]
    pub fn edges(&self) -> DMat3 {
        self.axes * DMat3::from_diagonal(self.spacing)
    }

    /// The linear part of `F⁻¹` (physical → parameter steps): `diag(1/spacing) · axesᵀ` for an
    /// orthonormal frame, the inverse of [`LatticeFrame::edges`] in general.
    #[must_use]
    pub fn to_parameter_matrix(&self) -> DMat3 {
        self.to_param
    }

    /// The matrix `G = axes⁻ᵀ` turning per-axis derivatives into physical gradients: a
    /// function `w(x)` of the parameters with `d_a = (∂w/∂u_a) / spacing_a` (the derivative per
    /// unit of physical length along axis `a`, as [`BSplineLattice::point_basis`] gives it) has
    /// the physical gradient `∇w = G · d`. `G = axes` for an orthonormal frame.
    #[must_use]
    pub fn gradient_matrix(&self) -> DMat3 {
        if self.skewed {
            self.to_param.transpose() * DMat3::from_diagonal(self.spacing)
        } else {
            self.axes
        }
    }

    /// Parameters of physical point `x`: `F⁻¹(x) = to_parameter_matrix · (x − origin)`.
    #[inline]
    #[must_use]
    pub fn to_parameter(&self, x: DVec3) -> DVec3 {
        self.to_param * (x - self.origin)
    }

    /// Physical point of parameters `u`: `F(u) = origin + axes·(spacing ⊙ u)`.
    #[inline]
    #[must_use]
    pub fn to_physical(&self, u: DVec3) -> DVec3 {
        self.origin + self.axes * (self.spacing * u)
    }
}

/// Check a frame's origin and spacing.
fn check_origin_spacing(origin: DVec3, spacing: DVec3) -> Result<(), DeformError> {
    if !origin.is_finite() {
        return Err(DeformError::InvalidFrame(format!(
            "origin {} is not finite",
            Nums(&origin.to_array())
        )));
    }
    if !(spacing.is_finite() && spacing.min_element() > 0.0) {
        return Err(DeformError::InvalidFrame(format!(
            "spacing {} must be finite and > 0",
            Nums(&spacing.to_array())
        )));
    }
    Ok(())
}

/// A matrix for messages, column by column (`[[x0, y0, z0], [x1, …], …]`, as glam prints
/// it) in [`Num`](volmorph_io::Num)'s notation, so a huge entry prints as `1e300`.
fn columns_text(m: DMat3) -> String {
    format!(
        "[{}, {}, {}]",
        Nums(&m.x_axis.to_array()),
        Nums(&m.y_axis.to_array()),
        Nums(&m.z_axis.to_array())
    )
}

/// A trivariate B-spline (or Bézier) lattice map with physical control points. See the
/// [module docs](self) for the map, the identity placement and the behaviour outside the box.
///
/// ```
/// use glam::DVec3;
/// use volmorph_deform::SpaceMap;
/// use volmorph_lattice::BSplineLattice;
/// // True's 9 × 9 × 9 lattice around a box: the initial map is the identity.
/// let lat = BSplineLattice::uniform_cubic_around(
///     DVec3::new(-1.0, 0.0, 2.0),
///     DVec3::new(5.0, 3.0, 4.0),
///     [9, 9, 9],
/// )
/// .unwrap();
/// for p in [DVec3::new(0.3, 1.7, 2.2), DVec3::new(5.0, 3.0, 4.0), DVec3::new(-1.0, 0.0, 2.0)] {
///     assert!((lat.apply(p) - p).length() < 1e-12 * p.length());
///     assert!((lat.jacobian(p) - glam::DMat3::IDENTITY).abs_diff_eq(glam::DMat3::ZERO, 1e-12));
/// }
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct BSplineLattice {
    frame: LatticeFrame,
    spline: BSplineVolume,
}

/// Padding of a flat axis in [`BSplineLattice::feng_around_model`], relative to the model's
/// largest extent: enough for a non-degenerate lattice, small enough not to change the
/// deformation of the model's plane noticeably.
pub const FLAT_AXIS_PADDING: f64 = 1e-3;

/// The form of Feng et al.'s initial volume.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FengForm {
    /// Clamped knots, outermost control points on the box faces (§3.1.3).
    EndInterpolating,
    /// Uniform unclamped knots with the scaling step (§3.1.2).
    Uniform,
    /// The forward-mapping baseline of Fig. 2b (§3.1.1): the end-interpolating knots with
    /// evenly spaced control points, which warps the object before any control point moves
    /// ([`BSplineLattice::feng_forward_around`]).
    Forward,
}

impl FengForm {
    /// The form's name on the command line: `end-interpolating`, `uniform` or `forward`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::EndInterpolating => "end-interpolating",
            Self::Uniform => "uniform",
            Self::Forward => "forward",
        }
    }

    /// Whether the initial volume is the identity on its box (every form but
    /// [`FengForm::Forward`]).
    #[must_use]
    pub fn is_identity(self) -> bool {
        !matches!(self, Self::Forward)
    }
}

/// Validate a box given by corner and extent.
fn check_extent(corner: DVec3, extent: DVec3) -> Result<(), DeformError> {
    for a in 0..3 {
        let (lo, e) = (corner[a], extent[a]);
        if !(lo.is_finite() && e.is_finite() && e > 0.0 && (lo + e).is_finite()) {
            return Err(DeformError::DegenerateBox {
                axis: a,
                min: lo,
                max: lo + e,
            });
        }
    }
    Ok(())
}

impl BSplineLattice {
    /// The identity lattice for `knots` in `frame`: control point `(i, j, k)` at
    /// `frame.to_physical((ξ_i, ξ_j, ξ_k))` (Greville abscissae). The map is the identity on
    /// the box `F(domain)`.
    ///
    /// # Errors
    /// [`DeformError::Spline`] if a knot vector has degree 0,
    /// [`DeformError::TooManyControlPoints`] or [`DeformError::Io`] (memory budget) if the net
    /// is too large (checked before allocating), [`DeformError::NonFinite`] if a control
    /// point overflows.
    pub fn identity(frame: LatticeFrame, knots: [KnotVector; 3]) -> Result<Self, DeformError> {
        check_net_size([
            knots[0].num_basis(),
            knots[1].num_basis(),
            knots[2].num_basis(),
        ])?;
        let mut spline = TensorBSpline::identity(knots)?;
        let params = spline.control_points();
        for (lin, u) in params.chunks_exact(3).enumerate() {
            let x = frame.to_physical(DVec3::from_slice(u));
            let idx = unravel(lin, spline.counts());
            set_point(&mut spline, idx, x)?;
        }
        Ok(Self { frame, spline })
    }

    /// The identity lattice for `knots` fitted to the box with corner `corner`, orthonormal
    /// `axes` (columns: directions of the box edges) and edge lengths `extent`: the knot domain
    /// `[a, b]` of each axis is stretched onto the box edge, so `spacing = extent / (b − a)`
    /// and `F(a_u, a_v, a_w) = corner`.
    ///
    /// # Errors
    /// [`DeformError::DegenerateBox`] for a non-finite or non-positive extent,
    /// [`DeformError::InvalidFrame`] for bad axes, and the errors of
    /// [`BSplineLattice::identity`].
    pub fn identity_in_box(
        corner: DVec3,
        axes: DMat3,
        extent: DVec3,
        knots: [KnotVector; 3],
    ) -> Result<Self, DeformError> {
        check_extent(corner, extent)?;
        let start = DVec3::new(
            knots[0].domain()[0],
            knots[1].domain()[0],
            knots[2].domain()[0],
        );
        let len = DVec3::new(
            knots[0].domain()[1] - start.x,
            knots[1].domain()[1] - start.y,
            knots[2].domain()[1] - start.z,
        );
        let spacing = extent / len;
        let origin = corner - axes * (spacing * start);
        let frame = LatticeFrame::new(origin, axes, spacing)?;
        Self::identity(frame, knots)
    }

    /// The identity lattice for `knots` on the axis-aligned box `[min, max]`.
    ///
    /// # Errors
    /// As [`BSplineLattice::identity_in_box`].
    pub fn identity_around(
        min: DVec3,
        max: DVec3,
        knots: [KnotVector; 3],
    ) -> Result<Self, DeformError> {
        Self::identity_in_box(min, DMat3::IDENTITY, max - min, knots)
    }

    /// True's uniform cubic lattice (§5.5, Fig. 8) on the box with corner `corner`, orthonormal
    /// `axes` and edge lengths `extent`, with `counts[a] ≥ 4` control points per axis: the box
    /// is split into `counts[a] − 3` equal regions per axis and the control points form an
    /// evenly spaced grid reaching one region beyond the box on each side. The map is the
    /// identity on the box.
    ///
    /// # Errors
    /// [`DeformError::TooFewControlPoints`] if a count is below 4,
    /// [`DeformError::DegenerateBox`], [`DeformError::InvalidFrame`], [`DeformError::Spline`]
    /// for an absurd count.
    pub fn uniform_cubic_in_box(
        corner: DVec3,
        axes: DMat3,
        extent: DVec3,
        counts: [usize; 3],
    ) -> Result<Self, DeformError> {
        let knots = uniform_cubic_knots(counts)?;
        Self::identity_in_box(corner, axes, extent, knots)
    }

    /// The identity lattice for `knots` fitted to the **parallelepiped** with corner `corner`
    /// and edge vectors `edges` (columns: the three box edges leaving the corner, at any
    /// non-degenerate angles; Sederberg–Parry's `S, T, U` of True 1992 §2.1): the knot domain
    /// `[a, b]` of each axis is stretched onto its edge, so `F(a_u, a_v, a_w) = corner` and the
    /// lattice box is `corner + s·S + t·T + u·U`, `s, t, u ∈ [0, 1]`. Orthonormal edges give the
    /// lattice of [`BSplineLattice::identity_in_box`].
    ///
    /// # Errors
    /// [`DeformError::InvalidFrame`] for a non-finite corner, a zero edge or edges spanning a
    /// degenerate parallelepiped (see [`MIN_FRAME_VOLUME`]), and the errors of
    /// [`BSplineLattice::identity`].
    pub fn identity_in_parallelepiped(
        corner: DVec3,
        edges: DMat3,
        knots: [KnotVector; 3],
    ) -> Result<Self, DeformError> {
        let mut start = DVec3::ZERO;
        let mut unit_edges = edges;
        for a in 0..3 {
            let [lo, hi] = knots[a].domain();
            start[a] = lo;
            *unit_edges.col_mut(a) = edges.col(a) / (hi - lo);
        }
        if !corner.is_finite() {
            return Err(DeformError::InvalidFrame(format!(
                "corner {} is not finite",
                Nums(&corner.to_array())
            )));
        }
        let frame = LatticeFrame::parallelepiped(DVec3::ZERO, unit_edges)?;
        let origin = corner - frame.edges() * start;
        let frame = LatticeFrame::parallelepiped(origin, unit_edges)?;
        Self::identity(frame, knots)
    }

    /// True's uniform cubic lattice (§5.5) on the parallelepiped with corner `corner` and edge
    /// vectors `edges` (see [`BSplineLattice::identity_in_parallelepiped`]): `counts[a] − 3`
    /// equal regions along each edge, the control points an evenly spaced skewed grid reaching
    /// one region beyond the box on each side. The identity on the box.
    ///
    /// # Errors
    /// [`DeformError::TooFewControlPoints`] if a count is below 4, and the errors of
    /// [`BSplineLattice::identity_in_parallelepiped`].
    pub fn uniform_cubic_in_parallelepiped(
        corner: DVec3,
        edges: DMat3,
        counts: [usize; 3],
    ) -> Result<Self, DeformError> {
        let knots = uniform_cubic_knots(counts)?;
        Self::identity_in_parallelepiped(corner, edges, knots)
    }

    /// Sederberg and Parry's Bézier lattice of degrees `(l, m, n)` (each ≥ 1) on the
    /// parallelepiped `corner + s·S + t·T + u·U` (`edges` = columns `S, T, U`): control points
    /// at `corner + (i/l)·S + (j/m)·T + (k/n)·U` (True 1992 §2.1), the identity map.
    ///
    /// # Errors
    /// As [`BSplineLattice::bezier_in_box`] and
    /// [`BSplineLattice::identity_in_parallelepiped`].
    pub fn bezier_in_parallelepiped(
        corner: DVec3,
        edges: DMat3,
        degrees: [usize; 3],
    ) -> Result<Self, DeformError> {
        Self::identity_in_parallelepiped(corner, edges, bezier_knots(degrees)?)
    }

    /// True's uniform cubic lattice on the axis-aligned box `[min, max]`; see
    /// [`BSplineLattice::uniform_cubic_in_box`].
    ///
    /// # Errors
    /// As [`BSplineLattice::uniform_cubic_in_box`].
    pub fn uniform_cubic_around(
        min: DVec3,
        max: DVec3,
        counts: [usize; 3],
    ) -> Result<Self, DeformError> {
        Self::uniform_cubic_in_box(min, DMat3::IDENTITY, max - min, counts)
    }

    /// A Sederberg–Parry Bézier lattice of degrees `(l, m, n)` (each ≥ 1) on the box with
    /// corner `corner`, orthonormal `axes` and edge lengths `extent`: `(l+1)(m+1)(n+1)` control
    /// points at `corner + axes·(extent ⊙ (i/l, j/m, k/n))`, the identity map.
    ///
    /// # Errors
    /// [`DeformError::TooFewControlPoints`] for a degree of 0, [`DeformError::Spline`] for a
    /// degree above [`volmorph_spline::MAX_DEGREE`], and the errors of
    /// [`BSplineLattice::identity_in_box`].
    pub fn bezier_in_box(
        corner: DVec3,
        axes: DMat3,
        extent: DVec3,
        degrees: [usize; 3],
    ) -> Result<Self, DeformError> {
        Self::identity_in_box(corner, axes, extent, bezier_knots(degrees)?)
    }

    /// A Sederberg–Parry Bézier lattice on the axis-aligned box `[min, max]`; see
    /// [`BSplineLattice::bezier_in_box`].
    ///
    /// # Errors
    /// As [`BSplineLattice::bezier_in_box`].
    pub fn bezier_around(min: DVec3, max: DVec3, degrees: [usize; 3]) -> Result<Self, DeformError> {
        Self::bezier_in_box(min, DMat3::IDENTITY, max - min, degrees)
    }

    /// Feng et al.'s uniform initial volume (2002 §3.1.2) on the axis-aligned box `[min, max]`
    /// with `degrees[a] ≥ 1` and `counts[a] ≥ degrees[a] + 1` control points per axis.
    ///
    /// The parameters are the physical coordinates themselves (frame origin 0, spacing 1, axes
    /// `I`), so a point's local coordinates are its coordinates. Along each axis the knots are
    /// uniform and unclamped, `u_i = min + (i − k)(max − min)/(n − k)` for `i = 0 … n + k`, which
    /// makes the domain exactly `[min, max]`. The control points are first spread evenly,
    /// `x'_i = min + i (max − min)/(n − 1)`; the resulting volume is linear but covers a smaller
    /// box `[x'(min), x'(max)]`, so the **scaling step** maps the control coordinates by
    /// `x''_i = min + s (x'_i − x'(min))` with `s = (max − min)/(x'(max) − x'(min))`. The
    /// volume then reproduces every point of the box and its Jacobian is the identity.
    ///
    /// # Errors
    /// [`DeformError::DegenerateBox`] for a non-finite or empty box,
    /// [`DeformError::TooFewControlPoints`] for a degree of 0 or `counts[a] < degrees[a] + 1`,
    /// [`DeformError::Spline`] for a degree above [`volmorph_spline::MAX_DEGREE`].
    pub fn feng_uniform_around(
        min: DVec3,
        max: DVec3,
        degrees: [usize; 3],
        counts: [usize; 3],
    ) -> Result<Self, DeformError> {
        check_extent(min, max - min)?;
        check_net_size(counts)?;
        let mut knots = Vec::with_capacity(3);
        let mut coords: Vec<Vec<f64>> = Vec::with_capacity(3);
        for a in 0..3 {
            let (k, n) = (degrees[a], counts[a]);
            if k == 0 || n < k + 1 {
                return Err(DeformError::TooFewControlPoints {
                    axis: a,
                    count: n,
                    min: k.max(1) + 1,
                });
            }
            let kv = KnotVector::uniform(k, n, [min[a], max[a]])?;
            let len = max[a] - min[a];
            let even: Vec<f64> = (0..n)
                .map(|i| min[a] + i as f64 * len / (n - 1) as f64)
                .collect();
            // Corners of the volume spanned by the evenly spread points.
            let curve = volmorph_spline::BSplineCurve::new([kv.clone()], 1, even.clone())?;
            let lo = curve.eval([min[a]])?[0];
            let hi = curve.eval([max[a]])?[0];
            let scale = len / (hi - lo);
            coords.push(even.iter().map(|&x| min[a] + scale * (x - lo)).collect());
            knots.push(kv);
        }
        let [ku, kv, kw]: [KnotVector; 3] = knots
            .try_into()
            .map_err(|_| DeformError::InvalidFrame("three knot vectors expected".into()))?;
        let frame = LatticeFrame::axis_aligned(DVec3::ZERO, DVec3::ONE)?;
        let mut pts = Vec::with_capacity(check_net_size(counts)?);
        for z in &coords[2] {
            for y in &coords[1] {
                for x in &coords[0] {
                    pts.push(DVec3::new(*x, *y, *z));
                }
            }
        }
        Self::from_parts(frame, [ku, kv, kw], &pts)
    }

    /// Feng et al.'s end-interpolating initial volume (2002 §3.1.3): the uniform volume of
    /// [`BSplineLattice::feng_uniform_around`] converted by knot insertion at the domain ends
    /// ([`volmorph_spline::TensorBSpline::clamp_ends`]). The knots become clamped with the same
    /// interior knots, the map is still the identity with Jacobian `I` on `[min, max]`, and the
    /// control points follow Eq. (2): along each axis the gaps between successive control
    /// points grow `h/k, 2h/k, …, h` from each end (`h` the knot spacing), the outermost
    /// points lying on the box faces.
    ///
    /// # Errors
    /// As [`BSplineLattice::feng_uniform_around`].
    pub fn feng_end_interpolating_around(
        min: DVec3,
        max: DVec3,
        degrees: [usize; 3],
        counts: [usize; 3],
    ) -> Result<Self, DeformError> {
        let uniform = Self::feng_uniform_around(min, max, degrees, counts)?;
        let mut spline = uniform.spline;
        for a in 0..3 {
            spline = spline.clamp_ends(a)?;
        }
        Ok(Self {
            frame: uniform.frame,
            spline,
        })
    }

    /// Feng et al.'s **forward-mapping** initial volume (2002 §3.1.1, Fig. 2b), the baseline the
    /// identity forms replace: the object is embedded by the linear map `L` from its bounding
    /// box `[min, max]` onto the parametric domain — here the domain *is* the box (frame
    /// origin 0, spacing 1, axes `I`), so `L` is the identity and a point's local coordinates
    /// are its coordinates — and the volume is end-interpolating (clamped knots with the
    /// uniform interior knots of [`BSplineLattice::feng_end_interpolating_around`]) with its
    /// control points **evenly** spaced, `x_i = min + i (max − min)/(n − 1)`.
    ///
    /// B-splines reproduce `x` only from the Greville abscissae `ξ_i` (the control points of
    /// the identity form, Eq. 2), so this volume moves every point by
    ///
    /// ```text
    /// d(x) = Σ_i N_i(x) (x_i − ξ_i)        (per axis)
    /// ```
    ///
    /// before any control point is edited: the paper's "warp in the deformation". Eq. 2's
    /// gaps between Greville abscissae grow from `h/k` at each end to `h` inside, while the
    /// even gaps are constant, so every even point below the centre lies above its Greville
    /// abscissa and every one above it below (`x_i − ξ_i` has the sign of `centre − ξ_i`):
    /// points are pulled towards the centre plane of each axis. The box faces (where the
    /// volume interpolates its end control points) and, by symmetry, the centre planes stay;
    /// an axis with `n = k + 1` (a Bézier axis, whose Greville abscissae are even) is not
    /// warped at all.
    ///
    /// # Errors
    /// As [`BSplineLattice::feng_uniform_around`].
    pub fn feng_forward_around(
        min: DVec3,
        max: DVec3,
        degrees: [usize; 3],
        counts: [usize; 3],
    ) -> Result<Self, DeformError> {
        let identity = Self::feng_end_interpolating_around(min, max, degrees, counts)?;
        let even: Vec<Vec<f64>> = (0..3)
            .map(|a| {
                let n = counts[a];
                (0..n)
                    .map(|i| min[a] + i as f64 * (max[a] - min[a]) / (n - 1) as f64)
                    .collect()
            })
            .collect();
        let mut pts = Vec::with_capacity(check_net_size(counts)?);
        for z in &even[2] {
            for y in &even[1] {
                for x in &even[0] {
                    pts.push(DVec3::new(*x, *y, *z));
                }
            }
        }
        Self::from_parts(identity.frame, identity.spline.knots().clone(), &pts)
    }

    /// Assemble a lattice from its parts: `control_points` in physical coordinates, index `i`
    /// fastest, one per basis function of `knots`.
    ///
    /// # Errors
    /// [`DeformError::Spline`] for a wrong number of points (`CoefficientCount`) or a knot
    /// vector of degree 0 (`DegreeTooLow`: a piecewise-constant map cannot be continuous),
    /// [`DeformError::NonFinite`] for a NaN or infinite coordinate.
    pub fn from_parts(
        frame: LatticeFrame,
        knots: [KnotVector; 3],
        control_points: &[DVec3],
    ) -> Result<Self, DeformError> {
        for (a, k) in knots.iter().enumerate() {
            if k.degree() == 0 {
                return Err(DeformError::Spline(SplineError::DegreeTooLow {
                    axis: a,
                    degree: 0,
                    min: 1,
                }));
            }
        }
        let mut coefs = Vec::with_capacity(control_points.len().saturating_mul(3));
        for (i, p) in control_points.iter().enumerate() {
            for c in 0..3 {
                if !p[c].is_finite() {
                    return Err(DeformError::NonFinite {
                        what: format!("control point {i}, component {c}"),
                        value: p[c],
                    });
                }
            }
            coefs.extend_from_slice(&p.to_array());
        }
        let spline = TensorBSpline::new(knots, 3, coefs)?;
        Ok(Self { frame, spline })
    }

    /// Feng et al.'s initial volume (§3.1) of `form` around the box `lo ..= hi` of a model
    /// (e.g. a mesh's bounding box), with degrees `degrees` and `counts` control points per
    /// axis. An axis along which the box is flat (a planar mesh) is padded symmetrically by
    /// [`FLAT_AXIS_PADDING`] of the largest extent (1 model unit if every extent is 0), so the
    /// lattice has a volume.
    ///
    /// # Errors
    /// [`DeformError::NonFinite`] for a non-finite box, and the errors of
    /// [`BSplineLattice::feng_end_interpolating_around`] / [`BSplineLattice::feng_uniform_around`].
    pub fn feng_around_model(
        lo: DVec3,
        hi: DVec3,
        degrees: [usize; 3],
        counts: [usize; 3],
        form: FengForm,
    ) -> Result<Self, DeformError> {
        for (what, p) in [("model box minimum", lo), ("model box maximum", hi)] {
            for a in 0..3 {
                if !p[a].is_finite() {
                    return Err(DeformError::NonFinite {
                        what: format!("{what}, component {a}"),
                        value: p[a],
                    });
                }
            }
        }
        let (mut lo, mut hi) = (lo, hi);
        let ext = hi - lo;
        let pad = FLAT_AXIS_PADDING * ext.max_element();
        let pad = if pad > 0.0 { pad } else { 1.0 };
        for a in 0..3 {
            if ext[a] <= 0.0 {
                lo[a] -= 0.5 * pad;
                hi[a] += 0.5 * pad;
            }
        }
        match form {
            FengForm::EndInterpolating => {
                Self::feng_end_interpolating_around(lo, hi, degrees, counts)
            }
            FengForm::Uniform => Self::feng_uniform_around(lo, hi, degrees, counts),
            FengForm::Forward => Self::feng_forward_around(lo, hi, degrees, counts),
        }
    }

    /// The identity uniform cubic lattice with `counts` control points per axis on the box of
    /// voxel centres of `grid`, in the grid's own direction frame (True 1992 Fig. 8: the box
    /// from the first to the last voxel centre, so every voxel centre is inside). A sheared
    /// grid (e.g. a tilted-gantry CT) gets a skewed lattice with the same shear, so the grid's
    /// index axes stay parallel to the lattice axes and the fast grid paths apply.
    ///
    /// # Errors
    /// [`DeformError::DegenerateBox`] if the grid is a single voxel thick along an axis,
    /// [`DeformError::InvalidFrame`] if its direction is degenerate, and the errors of
    /// [`BSplineLattice::uniform_cubic_in_parallelepiped`] (fewer than 4 control points per
    /// axis).
    pub fn identity_on_voxels(grid: &Geometry, counts: [usize; 3]) -> Result<Self, DeformError> {
        let extent = grid.spacing
            * DVec3::new(
                grid.dims[0].saturating_sub(1) as f64,
                grid.dims[1].saturating_sub(1) as f64,
                grid.dims[2].saturating_sub(1) as f64,
            );
        for a in 0..3 {
            if extent[a].is_nan() || extent[a] <= 0.0 {
                return Err(DeformError::DegenerateBox {
                    axis: a,
                    min: 0.0,
                    max: extent[a],
                });
            }
        }
        if volmorph_volume::direction::orthonormality_deviation(grid.direction)
            <= DIRECTION_ORTHONORMAL_TOL
        {
            return Self::uniform_cubic_in_box(grid.origin, grid.direction, extent, counts);
        }
        let edges = grid.direction * DMat3::from_diagonal(extent);
        Self::uniform_cubic_in_parallelepiped(grid.origin, edges, counts)
    }

    /// The parameter frame.
    #[must_use]
    pub fn frame(&self) -> &LatticeFrame {
        &self.frame
    }

    /// The knot vectors of the u, v and w axes.
    #[must_use]
    pub fn knots(&self) -> &[KnotVector; 3] {
        self.spline.knots()
    }

    /// Control points per axis.
    #[must_use]
    pub fn counts(&self) -> [usize; 3] {
        self.spline.counts()
    }

    /// Polynomial degree per axis.
    #[must_use]
    pub fn degree(&self) -> [usize; 3] {
        self.spline.degrees()
    }

    /// Parameter domain `[a, b]` per axis (the box is its image under the frame).
    #[must_use]
    pub fn domain(&self) -> [[f64; 2]; 3] {
        self.spline.domain()
    }

    /// The underlying spline from parameters to physical points.
    #[must_use]
    pub fn spline(&self) -> &BSplineVolume {
        &self.spline
    }

    /// `true` if parameters `u` lie in the closed domain (the map moves only such points).
    #[inline]
    #[must_use]
    pub fn contains_parameter(&self, u: DVec3) -> bool {
        let k = self.spline.knots();
        k[0].contains(u.x) && k[1].contains(u.y) && k[2].contains(u.z)
    }

    /// `true` if physical point `x` lies in the lattice's closed box.
    #[must_use]
    pub fn contains(&self, x: DVec3) -> bool {
        self.contains_parameter(self.frame.to_parameter(x))
    }

    /// Control point `index` (physical coordinates).
    ///
    /// # Errors
    /// [`DeformError::IndexOutOfRange`].
    pub fn control_point(&self, index: [usize; 3]) -> Result<DVec3, DeformError> {
        let lin = self.linear(index)?;
        Ok(DVec3::from_slice(
            &self.spline.homogeneous_coefficients()[3 * lin..3 * lin + 3],
        ))
    }

    /// All control points, index `i` fastest (allocates).
    #[must_use]
    pub fn control_points(&self) -> Vec<DVec3> {
        self.spline
            .homogeneous_coefficients()
            .chunks_exact(3)
            .map(DVec3::from_slice)
            .collect()
    }

    /// Move control point `index` to the physical position `p`.
    ///
    /// # Errors
    /// [`DeformError::IndexOutOfRange`], [`DeformError::NonFinite`].
    pub fn set_control_point(&mut self, index: [usize; 3], p: DVec3) -> Result<(), DeformError> {
        self.linear(index)?;
        set_point(&mut self.spline, index, p)
    }

    /// Displace control point `index` by `delta`.
    ///
    /// # Errors
    /// As [`BSplineLattice::set_control_point`].
    pub fn move_control_point(
        &mut self,
        index: [usize; 3],
        delta: DVec3,
    ) -> Result<(), DeformError> {
        let p = self.control_point(index)?;
        self.set_control_point(index, p + delta)
    }

    /// Where control point `index` sits in the identity lattice with the same knots and frame:
    /// `frame.to_physical(ξ)` at the Greville abscissae.
    ///
    /// # Errors
    /// [`DeformError::IndexOutOfRange`].
    pub fn identity_position(&self, index: [usize; 3]) -> Result<DVec3, DeformError> {
        self.linear(index)?;
        let k = self.spline.knots();
        let mut u = DVec3::ZERO;
        for a in 0..3 {
            u[a] = k[a]
                .greville_at(index[a])
                .ok_or(DeformError::IndexOutOfRange {
                    index,
                    counts: self.counts(),
                })?;
        }
        Ok(self.frame.to_physical(u))
    }

    /// Displacement of control point `index` from its identity position.
    ///
    /// # Errors
    /// [`DeformError::IndexOutOfRange`].
    pub fn displacement(&self, index: [usize; 3]) -> Result<DVec3, DeformError> {
        Ok(self.control_point(index)? - self.identity_position(index)?)
    }

    /// Replace every control point `P` by `f(P)` (e.g. an affine transform: by affine
    /// invariance the new map is `f ∘ map` on the box).
    ///
    /// # Errors
    /// [`DeformError::NonFinite`] if `f` produces a NaN or infinite point; the lattice is then
    /// left unchanged.
    pub fn map_control_points(&mut self, f: impl Fn(DVec3) -> DVec3) -> Result<(), DeformError> {
        let new: Vec<DVec3> = self.control_points().into_iter().map(f).collect();
        *self = Self::from_parts(self.frame, self.spline.knots().clone(), &new)?;
        Ok(())
    }

    /// [`SpaceMap::apply`] of a polynomial lattice given its control points `ctrl` (index `i`
    /// fastest).
    #[inline]
    pub(crate) fn apply_with_net(&self, ctrl: &[DVec3], p: DVec3) -> DVec3 {
        let u = self.frame.to_parameter(p);
        if !self.contains_parameter(u) {
            return p;
        }
        let knots = self.spline.knots();
        let deg = [knots[0].degree(), knots[1].degree(), knots[2].degree()];
        let mut spans = [0usize; 3];
        for a in 0..3 {
            let Ok(span) = knots[a].find_span(u[a]) else {
                return p;
            };
            spans[a] = span;
        }
        if deg.iter().all(|&d| d < SMALL_ORDER) {
            // Stack buffers of the order only (degrees ≤ 3, the common case).
            let mut b = [[0.0; SMALL_ORDER]; 3];
            for a in 0..3 {
                volmorph_spline::basis_in_span::<SMALL_ORDER>(
                    knots[a].knots(),
                    deg[a],
                    spans[a],
                    u[a],
                    &mut b[a],
                );
            }
            return self.contract(ctrl, spans, deg, &b).unwrap_or(p);
        }
        let mut b = [[0.0; volmorph_spline::MAX_DEGREE + 1]; 3];
        for a in 0..3 {
            if volmorph_spline::basis_funs_into(&knots[a], spans[a], u[a], &mut b[a]).is_err() {
                return p;
            }
        }
        self.contract(ctrl, spans, deg, &b).unwrap_or(p)
    }

    /// `Σ b_u[i] b_v[j] b_w[k] P` over the control points of the cell `spans`.
    #[inline]
    fn contract<const L: usize>(
        &self,
        ctrl: &[DVec3],
        spans: [usize; 3],
        deg: [usize; 3],
        b: &[[f64; L]; 3],
    ) -> Option<DVec3> {
        let [nu, nv, _] = self.spline.counts();
        let first = [spans[0] - deg[0], spans[1] - deg[1], spans[2] - deg[2]];
        let mut acc = DVec3::ZERO;
        for k in 0..=deg[2] {
            let mut pv = DVec3::ZERO;
            for j in 0..=deg[1] {
                let base = first[0] + nu * (first[1] + j + nv * (first[2] + k));
                let row = ctrl.get(base..=base + deg[0])?;
                let mut pu = DVec3::ZERO;
                for (c, w) in row.iter().zip(&b[0]) {
                    pu += *w * *c;
                }
                pv += b[1][j] * pu;
            }
            acc += b[2][k] * pv;
        }
        Some(acc)
    }

    /// Image of in-domain parameters `u` (no domain check beyond the spline's own).
    fn eval_param(&self, u: DVec3) -> Option<DVec3> {
        let mut v = [0.0; 3];
        self.spline.eval_into(u.to_array(), &mut v).ok()?;
        Some(DVec3::from_array(v))
    }

    fn linear(&self, index: [usize; 3]) -> Result<usize, DeformError> {
        self.spline
            .linear_index(index)
            .ok_or(DeformError::IndexOutOfRange {
                index,
                counts: self.counts(),
            })
    }
}

impl SpaceMap for BSplineLattice {
    /// `Σ N_i(u) N_j(v) N_k(w) P_ijk` at the parameters of `p` inside the box, `p` outside.
    fn apply(&self, p: DVec3) -> DVec3 {
        let u = self.frame.to_parameter(p);
        if !self.contains_parameter(u) {
            return p;
        }
        self.eval_param(u).unwrap_or(p)
    }

    /// Parallel over chunks of points with the control net copied once into a contiguous
    /// array of points and a per-point kernel (span search, Cox–de Boor basis per axis, one
    /// contraction over the `(p+1)³` control points); agrees with [`SpaceMap::apply`] to
    /// rounding. Polynomial lattices of one degree up to [`crate::batch::MAX_BATCH_DEGREE`]
    /// on every axis take the vectorised kernel of [`crate::batch`] (the same bits).
    fn apply_batch(&self, points: &[DVec3], out: &mut [DVec3]) -> Result<(), DeformError> {
        volmorph_deform::map::check_len(points.len(), out.len())?;
        if self.spline.is_rational() {
            out.par_chunks_mut(BATCH_CHUNK)
                .zip(points.par_chunks(BATCH_CHUNK))
                .for_each(|(o, p)| {
                    for (o, &p) in o.iter_mut().zip(p) {
                        *o = self.apply(p);
                    }
                });
            return Ok(());
        }
        if crate::batch::apply_batch(self, points, out) {
            return Ok(());
        }
        let ctrl = self.control_points();
        out.par_chunks_mut(BATCH_CHUNK)
            .zip(points.par_chunks(BATCH_CHUNK))
            .for_each(|(o, p)| {
                for (o, &p) in o.iter_mut().zip(p) {
                    *o = self.apply_with_net(&ctrl, p);
                }
            });
        Ok(())
    }

    /// Analytic: `∂S/∂u · diag(1/spacing) · axesᵀ` inside the box (chain rule through the
    /// frame), `I` outside.
    fn jacobian(&self, p: DVec3) -> DMat3 {
        let u = self.frame.to_parameter(p);
        if !self.contains_parameter(u) {
            return DMat3::IDENTITY;
        }
        let mut v = [0.0; 3];
        let mut g = [0.0; 9];
        if self
            .spline
            .eval_with_gradient_into(u.to_array(), &mut v, &mut g)
            .is_err()
        {
            return DMat3::IDENTITY;
        }
        DMat3::from_cols_array(&g) * self.frame.to_param
    }

    /// Separable per-axis basis tables when the grid axes are parallel to the lattice axes
    /// (see [`BSplineLattice::apply_grid_separable`]), pointwise otherwise.
    fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        if crate::grid::aligned_steps(self, grid)?.is_some() {
            self.apply_grid_separable(grid, out)
        } else {
            apply_grid_pointwise(self, grid, out)
        }
    }

    /// The separable part plan ([`crate::grid::LatticeGridPlan::part`]) when the grid axes
    /// are parallel to the lattice axes, pointwise otherwise: the bits of
    /// [`SpaceMap::apply_grid`] on the whole grid, for the part's points only.
    fn apply_grid_part(
        &self,
        grid: &Geometry,
        part: volmorph_volume::IndexBox,
        out: &mut [DVec3],
    ) -> Result<(), DeformError> {
        volmorph_deform::map::check_part(grid, part, out)?;
        if crate::grid::aligned_steps(self, grid)?.is_some() {
            crate::grid::LatticeGridPlan::part(self, grid, part)?.apply(self, out)
        } else {
            volmorph_deform::map::apply_grid_part_pointwise(self, grid, part, out)
        }
    }

    /// One pass over the control points for both the image and the Jacobian (see
    /// [`crate::jacobian`]); the general path for degrees above
    /// [`crate::jacobian::POINT_KERNEL_MAX_DEGREE`].
    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        crate::jacobian::lattice_value_and_jacobian(self, p)
            .unwrap_or_else(|| (self.apply(p), self.jacobian(p)))
    }

    /// Separable per-axis tables of basis values and derivatives when the grid axes are
    /// parallel to the lattice axes (see [`BSplineLattice::jacobian_grid_separable`]),
    /// pointwise otherwise.
    fn jacobian_grid(&self, grid: &Geometry, out: &mut [DMat3]) -> Result<(), DeformError> {
        if crate::grid::aligned_steps(self, grid)?.is_some() {
            self.jacobian_grid_separable(grid, out)
        } else {
            volmorph_deform::map::jacobian_grid_pointwise(self, grid, out)
        }
    }
}

/// Knot vectors of True's uniform cubic lattice: integers `−3 … n` with domain `[0, n − 3]`.
/// Refuse a control net of `counts` points above [`crate::json::MAX_CONTROL_POINTS`] (the
/// cap lattice readers enforce) or beyond the memory budget, before anything is allocated.
/// Returns the number of control points.
///
/// # Errors
/// [`DeformError::TooManyControlPoints`], or [`DeformError::Io`] for the budget.
pub fn check_net_size(counts: [usize; 3]) -> Result<usize, DeformError> {
    let max = crate::json::MAX_CONTROL_POINTS;
    let total = counts
        .iter()
        .try_fold(1usize, |acc, &n| acc.checked_mul(n))
        .filter(|&t| t <= max)
        .ok_or(DeformError::TooManyControlPoints { counts, max })?;
    volmorph_io::check_elems(
        &format!(
            "a lattice of {}×{}×{} control points",
            counts[0], counts[1], counts[2]
        ),
        total as u64,
        std::mem::size_of::<DVec3>() as u64,
    )?;
    Ok(total)
}

pub(crate) fn uniform_cubic_knots(counts: [usize; 3]) -> Result<[KnotVector; 3], DeformError> {
    for (a, &n) in counts.iter().enumerate() {
        if n < 4 {
            return Err(DeformError::TooFewControlPoints {
                axis: a,
                count: n,
                min: 4,
            });
        }
    }
    check_net_size(counts)?;
    try_axes(|a| {
        let n = counts[a];
        Ok(KnotVector::uniform(3, n, [0.0, (n - 3) as f64])?)
    })
}

/// Single-span clamped knot vectors on `[0, 1]` of `degrees` (Sederberg–Parry Bézier lattices).
fn bezier_knots(degrees: [usize; 3]) -> Result<[KnotVector; 3], DeformError> {
    try_axes(|a| {
        if degrees[a] == 0 {
            return Err(DeformError::TooFewControlPoints {
                axis: a,
                count: 1,
                min: 2,
            });
        }
        Ok(KnotVector::bezier(degrees[a], [0.0, 1.0])?)
    })
}

fn try_axes<T>(mut f: impl FnMut(usize) -> Result<T, DeformError>) -> Result<[T; 3], DeformError> {
    Ok([f(0)?, f(1)?, f(2)?])
}

fn unravel(lin: usize, counts: [usize; 3]) -> [usize; 3] {
    [
        lin % counts[0],
        (lin / counts[0]) % counts[1],
        lin / (counts[0] * counts[1]),
    ]
}

fn set_point(spline: &mut BSplineVolume, index: [usize; 3], p: DVec3) -> Result<(), DeformError> {
    for c in 0..3 {
        if !p[c].is_finite() {
            return Err(DeformError::NonFinite {
                what: format!("control point {index:?}, component {c}"),
                value: p[c],
            });
        }
    }
    spline.set_control_point(index, &p.to_array())?;
    Ok(())
}
