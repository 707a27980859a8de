//! Extended space mappings (Savchenko & Pasko, §3–§4): transformations of a defining
//! function `ξ = f(x)` by mappings of the extended space `(x, ξ)`.
//!
//! Mappings that can be written as expressions return a new [`Shape`] (so the result is
//! compiled, bounded by intervals and differentiated like any model, and mappings compose by
//! applying one to the result of another):
//!
//! | mapping | formula | function |
//! | --- | --- | --- |
//! | offset (Eq. 10, `d` constant) | `f(x) + d` | [`offset`] |
//! | control points (Eq. 10–11) | `f(x) − Σ f(pᵢ)(1 − rᵢ²)³/(1 + rᵢ²)`, `rᵢ² < 1` | [`control_points`] |
//! | convolution along a curve (Eq. 12) | `f(x) − ∫₀¹ f(c(t)) e^{−r/a} dt`, Simpson | [`convolution_deformation`] |
//! | metamorphosis (Eq. 13) | `h₁ f(x) + h₂ g(x)` | [`metamorphosis`] |
//! | offset along the gradient (Eq. 17) | `f(x + d ∇f(x))` | [`offset_along_gradient`] |
//! | thin shell (Eq. 17, Fig. 8) | `f(ψ, ψ, ψ)`, `ψ = a f(x) + b` | [`thin_shell`] |
//! | maze (Eq. 17, Fig. 9) | `f(ψ, ψ, ψ)`, `ψ = a sin(b f(x) + c)` | [`maze`] |
//!
//! Mappings through an arbitrary [`SpaceMap`] are [`Field`]s evaluated pointwise:
//!
//! | mapping | formula | type |
//! | --- | --- | --- |
//! | coordinate space mapping (Eq. 15) | `f(φ⁻¹(x'))` with `φ⁻¹` given as a map | [`Pullback`] |
//! | inverse displacement (Eq. 16) | `f(x' + s·d(x'))` with `d` a [`Displacement`] | [`Displaced`] |
//! | combined mapping (Eq. 18) | `(1 − h₁(t)) f(x' + h₂(t) d₂(x')) + h₁(t) d₁(x')` | [`Combined`] |
//!
//! Schedules `h(t)` for metamorphosis and combined mappings are [`Schedule`]s.
//!
//! A displacement `d(x)` is a vector per point, not a moved point, so it is a
//! [`Displacement`], not a [`SpaceMap`]; [`Displacing`] is the space map `x ↦ x + s·d(x)` it
//! defines (what [`Displaced`] pulls the defining function back through).
//!
//! Control-point coordinate mappings (§4.2 with the Appendix's volume spline) are a
//! [`Displaced`] field over a [`SplineDisplacement`], built by [`displace_by_handles`]. The
//! algebraic sum of a defining function and a volume spline through scattered function values
//! (§4.1.1, reconstruction from surface points) and the reconstruction of a solid from
//! cross-sections by metamorphosis along `z` (Fig. 4) are in [`crate::reconstruct`].

use glam::{DMat3, DVec3};
use volmorph_deform::SpaceMap;
use volmorph_handles::volume_spline::{VolumeSpline, VolumeSplineSystem};

use crate::error::FrepError;
use crate::field::Field;
use crate::ops::{BinaryOp, UnaryOp};
use crate::shape::{Builder, Id, Shape};
use crate::tape::Tape;

/// `f(x) + d`: iso-valued offset (Eq. 10 with a constant displacement): `d > 0` expands the
/// solid, `d < 0` contracts it.
#[must_use]
pub fn offset(f: &Shape, d: f64) -> Shape {
    f.map(|b, r, _| b.add_c(r, d))
}

/// A control point of a function mapping (Eq. 11) with its area of influence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlPoint {
    /// Position `pᵢ` (physical units), meant to lie on the deformed surface.
    pub position: DVec3,
    /// Linear map from the offset `x − pᵢ` to the normalised offset whose length is `rᵢ`:
    /// `I / r₀` for a sphere of radius `r₀`, the inverse of the matrix of semi-axis vectors
    /// for an arbitrarily oriented ellipsoid.
    pub influence: DMat3,
}

impl ControlPoint {
    /// A control point with a spherical area of influence of radius `radius`.
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] unless `radius` is finite and positive and the position
    /// finite.
    pub fn sphere(position: DVec3, radius: f64) -> Result<Self, FrepError> {
        if !(radius > 0.0 && radius.is_finite() && position.is_finite()) {
            return Err(FrepError::InvalidArgument(format!(
                "control point at {position} needs a finite positive radius of influence, got {radius}"
            )));
        }
        Ok(Self {
            position,
            influence: DMat3::from_diagonal(DVec3::splat(1.0 / radius)),
        })
    }

    /// A control point with an elliptic area of influence whose semi-axes are the three
    /// vectors `axes` (any orientation, lengths are the radii): `rᵢ = |A⁻¹(x − pᵢ)|` with `A`
    /// the matrix of the axes as columns.
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] when the axes are degenerate (not spanning space) or not
    /// finite.
    pub fn ellipsoid(position: DVec3, axes: [DVec3; 3]) -> Result<Self, FrepError> {
        let a = DMat3::from_cols(axes[0], axes[1], axes[2]);
        let det = a.determinant();
        if !(det.is_finite() && det.abs() > 1e-300 && position.is_finite()) {
            return Err(FrepError::InvalidArgument(format!(
                "elliptic area of influence at {position} has degenerate axes {axes:?}"
            )));
        }
        Ok(Self {
            position,
            influence: a.inverse(),
        })
    }

    /// The normalised squared distance `rᵢ²` of `x`.
    #[must_use]
    pub fn r2(&self, x: DVec3) -> f64 {
        (self.influence * (x - self.position)).length_squared()
    }
}

/// The Wyvill-type kernel of Eq. 11 at normalised squared distance `r2`:
/// `(1 − r²)³ / (1 + r²)` for `r² < 1`, else 0.
#[must_use]
pub fn wyvill_kernel(r2: f64) -> f64 {
    if r2 < 1.0 {
        let t = 1.0 - r2;
        t * t * t / (1.0 + r2)
    } else {
        0.0
    }
}

fn kernel_node(b: &mut Builder, r2: Id) -> Id {
    let one = b.constant(1.0);
    let t = b.sub(one, r2);
    let t3 = b.unary(UnaryOp::PowI(3), t);
    let den = b.add(one, r2);
    let k = b.div(t3, den);
    let inside = b.binary(BinaryOp::Lt, r2, one);
    let zero = b.constant(0.0);
    b.select(inside, k, zero)
}

/// Function mapping controlled by points (Eq. 10–11): `f̃(x) = f(x) + d(x)` with
/// `d(x) = −Σ f(pᵢ) (1 − rᵢ²)³/(1 + rᵢ²)` over the points whose area of influence contains
/// `x`. Each control point with no other area of influence reaching it lies exactly on the
/// surface of the result (`f̃(pᵢ) = 0`); points inside the solid pinch it, points outside
/// pull it out.
#[must_use]
pub fn control_points(f: &Shape, points: &[ControlPoint]) -> Shape {
    let tape = Tape::new(f);
    let fp: Vec<f64> = points.iter().map(|c| tape.eval(c.position)).collect();
    f.map(|b, root, x| {
        let mut d = root;
        for (c, &fpi) in points.iter().zip(&fp) {
            let m = c.influence;
            let mut r2 = b.constant(0.0);
            for row in 0..3 {
                let mut comp = b.constant(0.0);
                for (k, &xk) in x.iter().enumerate() {
                    let dk = b.add_c(xk, -c.position[k]);
                    let term = b.mul_c(dk, m.col(k)[row]);
                    comp = b.add(comp, term);
                }
                let c2 = b.square(comp);
                r2 = b.add(r2, c2);
            }
            let k = kernel_node(b, r2);
            let w = b.mul_c(k, fpi);
            d = b.sub(d, w);
        }
        d
    })
}

/// Convolution deformation along a parametric curve (Eq. 10 with Eq. 12):
/// `f̃(x) = f(x) − ∫₀¹ f(c(t)) e^{−|x − c(t)|/a} dt`, the integral by composite Simpson's
/// rule on `intervals` (even, ≥ 2) sub-intervals.
///
/// # Errors
/// [`FrepError::InvalidArgument`] when `intervals` is odd or below 2, `a` is not positive and
/// finite, or the curve gives a non-finite point.
pub fn convolution_deformation(
    f: &Shape,
    curve: &dyn Fn(f64) -> DVec3,
    a: f64,
    intervals: usize,
) -> Result<Shape, FrepError> {
    if intervals < 2 || !intervals.is_multiple_of(2) || intervals > 1 << 16 {
        return Err(FrepError::InvalidArgument(format!(
            "Simpson's rule needs an even number of intervals from 2 to 65536, got {intervals}"
        )));
    }
    if !(a > 0.0 && a.is_finite()) {
        return Err(FrepError::InvalidArgument(format!(
            "the decay length `a` must be finite and positive, got {a}"
        )));
    }
    let tape = Tape::new(f);
    let h = 1.0 / intervals as f64;
    let mut nodes = Vec::with_capacity(intervals + 1);
    for j in 0..=intervals {
        let p = curve(j as f64 * h);
        if !p.is_finite() {
            return Err(FrepError::InvalidArgument(format!(
                "the curve is not finite at t = {}",
                j as f64 * h
            )));
        }
        let w = if j == 0 || j == intervals {
            1.0
        } else if j % 2 == 1 {
            4.0
        } else {
            2.0
        };
        nodes.push((p, w * h / 3.0 * tape.eval(p)));
    }
    Ok(f.map(|b, root, x| {
        let mut d = root;
        for &(p, w) in &nodes {
            let mut r2 = b.constant(0.0);
            for (k, &xk) in x.iter().enumerate() {
                let dk = b.add_c(xk, -p[k]);
                let s = b.square(dk);
                r2 = b.add(r2, s);
            }
            let r = b.sqrt(r2);
            let e = b.mul_c(r, -1.0 / a);
            let e = b.unary(UnaryOp::Exp, e);
            let term = b.mul_c(e, w);
            d = b.sub(d, term);
        }
        d
    }))
}

/// Metamorphosis (Eq. 13): `h1·f(x) + h2·g(x)`. With `h1 = 1 − s`, `h2 = s` the result is
/// `f` at `s = 0` and `g` at `s = 1`.
#[must_use]
pub fn metamorphosis(f: &Shape, g: &Shape, h1: f64, h2: f64) -> Shape {
    f.combine(g, |b, a, c| {
        let a = b.mul_c(a, h1);
        let c = b.mul_c(c, h2);
        b.add(a, c)
    })
}

/// A schedule `h(t)` for `t ∈ [0, 1]` (values outside are clamped to `[0, 1]` first).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Schedule {
    /// `h(t) = t`.
    Linear,
    /// `h(t) = √t` (fast start; the coordinate mapping of the seed's Fig. 11).
    Sqrt,
    /// `h(t) = 0` for `t ≤ t0`, `(t − t0)² / (1 − t0)²` after (delayed start; Fig. 11 uses
    /// `t0 = 0.3`).
    Delayed {
        /// Time before which nothing changes, in `[0, 1)`.
        t0: f64,
    },
    /// `h(t) = 3t² − 2t³`.
    Smoothstep,
}

impl Schedule {
    /// `h(t)`.
    #[must_use]
    pub fn at(&self, t: f64) -> f64 {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        match *self {
            Schedule::Linear => t,
            Schedule::Sqrt => t.sqrt(),
            Schedule::Delayed { t0 } => {
                if t <= t0 {
                    0.0
                } else {
                    (t - t0) * (t - t0) / ((1.0 - t0) * (1.0 - t0))
                }
            }
            Schedule::Smoothstep => t * t * (3.0 - 2.0 * t),
        }
    }

    /// Parse `linear`, `sqrt`, `smoothstep` or `delayed:T0`.
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] naming the accepted forms.
    pub fn parse(s: &str) -> Result<Self, FrepError> {
        let bad = || {
            FrepError::InvalidArgument(format!(
                "unknown schedule `{s}` (expected linear, sqrt, smoothstep or delayed:T0 with T0 in [0, 1))"
            ))
        };
        match s {
            "linear" => Ok(Self::Linear),
            "sqrt" => Ok(Self::Sqrt),
            "smoothstep" => Ok(Self::Smoothstep),
            _ => {
                let t0: f64 = s
                    .strip_prefix("delayed:")
                    .ok_or_else(bad)?
                    .parse()
                    .map_err(|_| bad())?;
                if (0.0..1.0).contains(&t0) {
                    Ok(Self::Delayed { t0 })
                } else {
                    Err(bad())
                }
            }
        }
    }
}

/// The form [`Schedule::parse`] reads: `linear`, `sqrt`, `smoothstep` or `delayed:T0` (`T0`
/// in its shortest round-trip form, so parsing the text gives the schedule back exactly).
impl std::fmt::Display for Schedule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Schedule::Linear => f.write_str("linear"),
            Schedule::Sqrt => f.write_str("sqrt"),
            Schedule::Smoothstep => f.write_str("smoothstep"),
            Schedule::Delayed { t0 } => write!(f, "delayed:{t0:?}"),
        }
    }
}

/// Metamorphosis at time `t` with schedule `h`: `(1 − h(t)) f + h(t) g`, exactly `f` at
/// `t = 0` and `g` at `t = 1` for every schedule.
#[must_use]
pub fn morph(f: &Shape, g: &Shape, t: f64, schedule: Schedule) -> Shape {
    let s = schedule.at(t);
    if s == 0.0 {
        return f.clone();
    }
    if s == 1.0 {
        return g.clone();
    }
    metamorphosis(f, g, 1.0 - s, s)
}

/// Offset along the gradient (Eq. 17): `f(x + d ∇f(x))` — the coordinates are moved along
/// the function's gradient (the normal direction on the surface, pointing into the solid),
/// so `d > 0` expands the solid by about `d |∇f|²` there. The gradient is symbolic, so the
/// result stays an exact, interval-bounded expression.
#[must_use]
pub fn offset_along_gradient(f: &Shape, d: f64) -> Shape {
    f.map(|b, root, x| {
        let g = b.gradient(root);
        let moved = [0, 1, 2].map(|k| {
            let s = b.mul_c(g[k], d);
            b.add(x[k], s)
        });
        b.import(f, moved)
    })
}

/// Function-dependent mapping `f(ψ(x), ψ(x), ψ(x))` for a coordinate function `ψ` built
/// from `f(x)` (Eq. 17 with `x₁ = x₂ = x₃ = ψ`).
#[must_use]
pub fn function_dependent(f: &Shape, psi: impl FnOnce(&mut Builder, Id) -> Id) -> Shape {
    f.map(|b, root, _| {
        let p = psi(b, root);
        b.import(f, [p, p, p])
    })
}

/// Thin shell (Fig. 8): `ψ = a f(x) + b` in [`function_dependent`].
#[must_use]
pub fn thin_shell(f: &Shape, a: f64, b_: f64) -> Shape {
    function_dependent(f, |b, r| {
        let s = b.mul_c(r, a);
        b.add_c(s, b_)
    })
}

/// Maze (Fig. 9): `ψ = a sin(b f(x) + c)` in [`function_dependent`].
#[must_use]
pub fn maze(f: &Shape, a: f64, b_: f64, c: f64) -> Shape {
    function_dependent(f, |b, r| {
        let s = b.mul_c(r, b_);
        let s = b.add_c(s, c);
        let s = b.unary(UnaryOp::Sin, s);
        b.mul_c(s, a)
    })
}

/// Coordinate space mapping (Eq. 15): `f(φ⁻¹(x'))` where `inverse` is the map `φ⁻¹` (a
/// pull-back: output point `x'` samples `f` at `inverse.apply(x')`). The gradient follows
/// the chain rule `Jᵀ ∇f`.
#[derive(Debug, Clone)]
pub struct Pullback<F, M> {
    /// The defining function `f`.
    pub field: F,
    /// `φ⁻¹`.
    pub inverse: M,
}

impl<F: Field, M: SpaceMap> Field for Pullback<F, M> {
    fn value(&self, p: DVec3) -> f64 {
        self.field.value(self.inverse.apply(p))
    }

    fn gradient(&self, p: DVec3) -> (f64, DVec3) {
        let (q, j) = self.inverse.apply_with_jacobian(p);
        let (v, g) = self.field.gradient(q);
        (v, j.transpose() * g)
    }
}

/// A displacement field `d(x)`: the vector (physical units) by which the point `x` moves, not
/// the moved point. [`Displacing`] turns it into the space map `x ↦ x + s·d(x)`.
pub trait Displacement: Send + Sync {
    /// The displacement `d(p)`.
    fn displacement(&self, p: DVec3) -> DVec3;

    /// `d(p)` and its Jacobian `∂d/∂x` (columns: derivatives along x, y, z).
    fn displacement_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3);
}

/// A constant displacement: every point moves by the same vector (zero Jacobian).
impl Displacement for DVec3 {
    fn displacement(&self, _: DVec3) -> DVec3 {
        *self
    }

    fn displacement_with_jacobian(&self, _: DVec3) -> (DVec3, DMat3) {
        (*self, DMat3::ZERO)
    }
}

impl<D: Displacement + ?Sized> Displacement for &D {
    fn displacement(&self, p: DVec3) -> DVec3 {
        (**self).displacement(p)
    }

    fn displacement_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        (**self).displacement_with_jacobian(p)
    }
}

/// The space map of a displacement, `x ↦ x + scale · d(x)`, with Jacobian
/// `I + scale · ∂d/∂x`. Scale 0 is the identity; scale 1 moves every point by its
/// displacement; scale −1 is Eq. 16's inverse mapping for the seed's handle splines.
#[derive(Debug, Clone)]
pub struct Displacing<D> {
    /// `d(x)`.
    pub displacement: D,
    /// Factor on the displacement.
    pub scale: f64,
}

impl<D: Displacement> SpaceMap for Displacing<D> {
    fn apply(&self, p: DVec3) -> DVec3 {
        p + self.scale * self.displacement.displacement(p)
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.apply_with_jacobian(p).1
    }

    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        let (d, j) = self.displacement.displacement_with_jacobian(p);
        (p + self.scale * d, DMat3::IDENTITY + j * self.scale)
    }
}

/// Inverse mapping by displacement (Eq. 16): `f(x' + scale · d(x'))`, the defining function
/// pulled back through [`Displacing`].
#[derive(Debug, Clone)]
pub struct Displaced<F, D> {
    /// The defining function `f`.
    pub field: F,
    /// `d(x')`.
    pub displacement: D,
    /// Factor on the displacement (`h₂(t)` of a schedule; 1 for Eq. 16 itself).
    pub scale: f64,
}

impl<F, D> Displaced<F, D> {
    /// The space map `x' ↦ x' + scale · d(x')` the field is pulled back through.
    fn map(&self) -> Displacing<&D> {
        Displacing {
            displacement: &self.displacement,
            scale: self.scale,
        }
    }
}

impl<F: Field, D: Displacement> Field for Displaced<F, D> {
    fn value(&self, p: DVec3) -> f64 {
        self.field.value(self.map().apply(p))
    }

    fn gradient(&self, p: DVec3) -> (f64, DVec3) {
        let (q, jac) = self.map().apply_with_jacobian(p);
        let (v, g) = self.field.gradient(q);
        (v, jac.transpose() * g)
    }
}

/// A displacement field interpolated by the Appendix's volume spline (`D = 3`, Green's
/// function `G(r) = r` plus a linear polynomial, minimal bending energy): a [`Displacement`]
/// with `d(pᵢ) = δᵢ` at the centres `pᵢ` (or a smoothing fit for `smoothing > 0`). Plug it
/// into [`Displaced`], [`Combined`] or [`Displacing`]; [`displace_by_handles`] builds the
/// seed's §4.2 mapping with it.
///
/// The Jacobian is the spline's analytic gradient (`G` has a cusp at each centre, where the
/// one-sided gradient of the kernel term is taken as zero).
///
/// Its JSON form (serde) is its input, `{"centres": [[x, y, z], …], "displacements": […],
/// "smoothing": s}`; reading it solves the spline again (the same bits, since the solve is
/// deterministic) and validates as [`SplineDisplacement::new`].
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "SplineDisplacementInput", into = "SplineDisplacementInput")]
pub struct SplineDisplacement {
    input: SplineDisplacementInput,
    spline: VolumeSpline<3>,
}

/// What a [`SplineDisplacement`] is solved from (its file form).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct SplineDisplacementInput {
    centres: Vec<[f64; 3]>,
    displacements: Vec<[f64; 3]>,
    smoothing: f64,
}

impl TryFrom<SplineDisplacementInput> for SplineDisplacement {
    type Error = FrepError;

    fn try_from(i: SplineDisplacementInput) -> Result<Self, FrepError> {
        let v = |a: &[[f64; 3]]| a.iter().map(|p| DVec3::from_array(*p)).collect::<Vec<_>>();
        Self::new(&v(&i.centres), &v(&i.displacements), i.smoothing)
    }
}

impl From<SplineDisplacement> for SplineDisplacementInput {
    fn from(s: SplineDisplacement) -> Self {
        s.input
    }
}

impl SplineDisplacement {
    /// Interpolate the displacements `displacements[i]` at `centres[i]` (physical units), with
    /// smoothing `smoothing ≥ 0` (0 interpolates; see
    /// [`volmorph_handles::volume_spline`] for its normalisation).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] when the two lists differ in length or a displacement is
    /// not finite; [`FrepError::Deform`] from [`VolumeSplineSystem::new`] for fewer than 4
    /// centres, coincident or coplanar centres, non-finite coordinates or a singular system.
    pub fn new(
        centres: &[DVec3],
        displacements: &[DVec3],
        smoothing: f64,
    ) -> Result<Self, FrepError> {
        if centres.len() != displacements.len() {
            return Err(FrepError::InvalidArgument(format!(
                "{} displacements for {} centres",
                displacements.len(),
                centres.len()
            )));
        }
        if let Some((i, d)) = displacements
            .iter()
            .enumerate()
            .find(|(_, d)| !d.is_finite())
        {
            return Err(FrepError::InvalidArgument(format!(
                "displacement {i} is not finite: {d}"
            )));
        }
        let c: Vec<[f64; 3]> = centres.iter().map(|p| p.to_array()).collect();
        let system = VolumeSplineSystem::<3>::new(&c, smoothing)?;
        let values: Vec<f64> = displacements.iter().flat_map(|d| d.to_array()).collect();
        Ok(Self {
            spline: system.solve(&values, 3)?,
            input: SplineDisplacementInput {
                centres: c,
                displacements: displacements.iter().map(|d| d.to_array()).collect(),
                smoothing,
            },
        })
    }

    /// The underlying 3-component spline.
    #[must_use]
    pub fn spline(&self) -> &VolumeSpline<3> {
        &self.spline
    }
}

impl Displacement for SplineDisplacement {
    fn displacement(&self, p: DVec3) -> DVec3 {
        let mut d = [0.0; 3];
        self.spline.eval(p.to_array(), &mut d);
        DVec3::from_array(d)
    }

    fn displacement_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        self.spline.eval_with_jacobian(p)
    }
}

/// The seed's §4.2 coordinate space mapping driven by control points: the handles `Qᵢ`
/// (`sources`, on or near the surface of `field`) move to `Dᵢ` (`targets`). As in the seed, the
/// volume spline `d` interpolates `δᵢ = Dᵢ − Qᵢ` at `pᵢ = Dᵢ`, and the deformed defining
/// function is `f(x' − d(x'))` — the inverse mapping of Eq. 16 written with the sign that
/// sends each target back to its source (`x = x' − d(x')`, so `f̃(Dᵢ) = f(Qᵢ)`): a source on
/// the surface `f = 0` becomes a target on the surface of the result. The returned
/// [`Displaced`] has `scale = −1`; setting `scale = −s` gives the partial motion `s ∈ [0, 1]`
/// of an animation (exact at `s = 0` and `s = 1` only).
///
/// # Errors
/// As [`SplineDisplacement::new`] (at least 4 non-coplanar, distinct targets), plus
/// [`FrepError::InvalidArgument`] when the lists differ in length or a point is not finite.
pub fn displace_by_handles<F: Field>(
    field: F,
    sources: &[DVec3],
    targets: &[DVec3],
    smoothing: f64,
) -> Result<Displaced<F, SplineDisplacement>, FrepError> {
    Ok(Displaced {
        field,
        displacement: handle_spline(sources, targets, smoothing)?,
        scale: -1.0,
    })
}

/// The displacement spline of [`displace_by_handles`]: `d` interpolates `δᵢ = Dᵢ − Qᵢ` at
/// the targets `Dᵢ` (smoothing `smoothing ≥ 0`).
///
/// # Errors
/// [`FrepError::InvalidArgument`] when the lists differ in length or a point is not finite;
/// as [`SplineDisplacement::new`] otherwise.
pub fn handle_spline(
    sources: &[DVec3],
    targets: &[DVec3],
    smoothing: f64,
) -> Result<SplineDisplacement, FrepError> {
    if sources.len() != targets.len() {
        return Err(FrepError::InvalidArgument(format!(
            "{} targets for {} source handles",
            targets.len(),
            sources.len()
        )));
    }
    if let Some(p) = sources.iter().chain(targets).find(|p| !p.is_finite()) {
        return Err(FrepError::InvalidArgument(format!(
            "handle {p} is not finite"
        )));
    }
    let deltas: Vec<DVec3> = targets.iter().zip(sources).map(|(d, q)| *d - *q).collect();
    SplineDisplacement::new(targets, &deltas, smoothing)
}

/// Smallest squared distance (in the spline's normalised coordinates, centres in the unit
/// ball) under which [`spline_nodes`] takes the distance to a centre as `√SPLINE_R2_FLOOR`:
/// the kernel `G(r) = r` has a cusp at its centre, where the symbolic gradient of `√s` would
/// be `0·∞ = NaN`; with the floor it is zero there, the one-sided value
/// [`volmorph_handles::volume_spline::green_gradient_factor`] takes. The value changes by at
/// most `1e-150` of a weight.
pub const SPLINE_R2_FLOOR: f64 = 1e-300;

/// The 3D volume spline `U` (the Appendix's `G(r) = r` plus a linear polynomial) written as
/// expression nodes at the point `x`: one node per value component. Evaluates to
/// [`VolumeSpline::eval`]'s values up to rounding (the sums are taken in another order), and
/// is differentiated and bounded over boxes like any expression, so a shape built with it
/// keeps exact gradients, interval culling and compiled evaluation.
pub fn spline_nodes(b: &mut Builder, spline: &VolumeSpline<3>, x: [Id; 3]) -> Vec<Id> {
    let v = spline.value_dim();
    let (shift, scale) = spline.normalisation();
    let xn = [0, 1, 2].map(|a| {
        let d = b.add_c(x[a], -shift[a]);
        b.mul_c(d, scale)
    });
    let poly = spline.polynomial();
    let mut out: Vec<Id> = (0..v)
        .map(|c| {
            let mut s = b.constant(poly[c]);
            for (a, &xa) in xn.iter().enumerate() {
                let t = b.mul_c(xa, poly[(a + 1) * v + c]);
                s = b.add(s, t);
            }
            s
        })
        .collect();
    let floor = b.constant(SPLINE_R2_FLOOR);
    for (p, w) in spline
        .normalised_centres()
        .iter()
        .zip(spline.weights().chunks_exact(v))
    {
        let mut r2 = b.constant(0.0);
        for (a, &xa) in xn.iter().enumerate() {
            let d = b.add_c(xa, -p[a]);
            let d2 = b.square(d);
            r2 = b.add(r2, d2);
        }
        let r2 = b.binary(BinaryOp::Max, r2, floor);
        let r = b.sqrt(r2);
        for (o, &wc) in out.iter_mut().zip(w) {
            let t = b.mul_c(r, wc);
            *o = b.add(*o, t);
        }
    }
    out
}

/// The seed's §4.2 coordinate space mapping driven by control points (Eq. 15–16, Fig. 5) as
/// a [`Shape`]: `f(x' − s·d(x'))` with the spline `d` of [`handle_spline`] written by
/// [`spline_nodes`] — the closed form of [`displace_by_handles`] (which is `s = 1`), so the
/// result is compiled, interval-bounded and differentiated like any model and can be mapped
/// further. `s` scales the motion (`h₂(t)` of a schedule; exact at `s = 0` and `s = 1` only).
///
/// # Errors
/// As [`handle_spline`]; [`FrepError::InvalidArgument`] for a non-finite `s`.
pub fn displace_by_handles_shape(
    f: &Shape,
    sources: &[DVec3],
    targets: &[DVec3],
    smoothing: f64,
    s: f64,
) -> Result<Shape, FrepError> {
    if !s.is_finite() {
        return Err(FrepError::InvalidArgument(format!(
            "the motion factor must be finite, got {s}"
        )));
    }
    let d = handle_spline(sources, targets, smoothing)?;
    Ok(displaced_shape(f, d.spline(), s))
}

/// `f(x − s·d(x))` for a 3-component displacement spline `d` (see [`spline_nodes`]).
#[must_use]
pub fn displaced_shape(f: &Shape, d: &VolumeSpline<3>, s: f64) -> Shape {
    if s == 0.0 {
        return f.clone();
    }
    Shape::build(|b, x| {
        let dn = spline_nodes(b, d, x);
        let moved = [0, 1, 2].map(|k| {
            let t = b.mul_c(dn[k], -s);
            b.add(x[k], t)
        });
        b.import(f, moved)
    })
}

/// Function mapping by a volume spline through control points (§4.1.1, the smooth
/// alternative to Eq. 11 the seed describes after it): `f̃(x) = f(x) + U(x)` with `U` the
/// 3D volume spline through `U(pᵢ) = vᵢ − f(pᵢ)`, so `f̃(pᵢ) = vᵢ` (every `vᵢ = 0`: the
/// points lie on the surface of the result). The same function as
/// [`crate::reconstruct::SplineCorrected::through_values`], as a [`Shape`].
///
/// # Errors
/// As [`crate::reconstruct::SplineCorrected::through_values`].
pub fn spline_points(
    f: &Shape,
    points: &[DVec3],
    values: &[f64],
    smoothing: f64,
) -> Result<Shape, FrepError> {
    let corrected = crate::reconstruct::SplineCorrected::through_values(
        Tape::new(f),
        points,
        values,
        smoothing,
    )?;
    Ok(f.map(|b, root, x| {
        let u = spline_nodes(b, corrected.spline(), x);
        b.add(root, u[0])
    }))
}

/// Offset along the gradient with a distance that varies in space (Eq. 17, Fig. 7: "offsets
/// with the distance modulated by the depth data"): `f(x + d(x) ∇f(x))`, the gradient
/// symbolic as in [`offset_along_gradient`].
#[must_use]
pub fn offset_along_gradient_by(f: &Shape, d: &Shape) -> Shape {
    f.map(|b, root, x| {
        let g = b.gradient(root);
        let dist = b.import(d, x);
        let moved = [0, 1, 2].map(|k| {
            let s = b.mul(g[k], dist);
            b.add(x[k], s)
        });
        b.import(f, moved)
    })
}

/// Coordinate space mapping by an affine map (Eq. 15): the solid moved by the push-forward
/// `φ(x) = M x + o`, i.e. `f(φ⁻¹(x')) = f(M⁻¹(x' − o))`.
///
/// # Errors
/// [`FrepError::InvalidArgument`] when `M` is singular (|det| below `1e-12` of its largest
/// entry cubed) or anything is not finite.
pub fn affine(f: &Shape, matrix: DMat3, offset: DVec3) -> Result<Shape, FrepError> {
    let scale = matrix
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let det = matrix.determinant();
    if !(det.is_finite() && offset.is_finite() && det.abs() > 1e-12 * scale.powi(3)) {
        return Err(FrepError::InvalidArgument(format!(
            "the affine map needs a finite invertible matrix and a finite offset, got \
             det = {det}, offset {offset}"
        )));
    }
    let inv = matrix.inverse();
    Ok(f.map(|b, _, x| {
        let moved = [0, 1, 2].map(|r| {
            let mut acc = b.constant(0.0);
            for (c, &xc) in x.iter().enumerate() {
                let d = b.add_c(xc, -offset[c]);
                let t = b.mul_c(d, inv.col(c)[r]);
                acc = b.add(acc, t);
            }
            acc
        });
        b.import(f, moved)
    }))
}

/// The combined mapping of Eq. 18 in the seed's Fig. 10c form as a [`Shape`] at weights
/// `w₁ = h₁(t)`, `w₂ = h₂(t)`: `(1 − w₁) f(x' − w₂ d(x')) + w₁ g(x')`, `d` the displacement
/// spline of [`handle_spline`] (so `x' − d(x')` is the seed's `x' + d₂(x')`). Exactly
/// `f` at `w₁ = w₂ = 0` and exactly `g` at `w₁ = 1`. The closed form of [`Combined`].
#[must_use]
pub fn combined(f: &Shape, g: &Shape, d: &VolumeSpline<3>, w1: f64, w2: f64) -> Shape {
    if w1 == 1.0 {
        return g.clone();
    }
    let moved = displaced_shape(f, d, w2);
    if w1 == 0.0 {
        return moved;
    }
    metamorphosis(&moved, g, 1.0 - w1, w1)
}

/// Combined mapping (Eq. 18, the seed's Fig. 10c form):
/// `ξ' = (1 − h₁(t)) f(x' + h₂(t) d₂(x')) + h₁(t) d₁(x')` — a coordinate mapping toward the
/// target by the displacement map `d₂`, corrected by metamorphosis into the target
/// function `d₁`, each on its own schedule.
#[derive(Debug, Clone)]
pub struct Combined<F, G, D> {
    /// Initial defining function `f`.
    pub initial: F,
    /// Target defining function `d₁`.
    pub target: G,
    /// Displacement `d₂`.
    pub displacement: D,
    /// Metamorphosis schedule `h₁`.
    pub h1: Schedule,
    /// Coordinate-mapping schedule `h₂`.
    pub h2: Schedule,
    /// Time `t ∈ [0, 1]`.
    pub t: f64,
}

impl<F: Field, G: Field, D: Displacement> Field for Combined<F, G, D> {
    fn value(&self, p: DVec3) -> f64 {
        let (w1, w2) = (self.h1.at(self.t), self.h2.at(self.t));
        let moved = Displacing {
            displacement: &self.displacement,
            scale: w2,
        }
        .apply(p);
        let a = if w1 < 1.0 {
            (1.0 - w1) * self.initial.value(moved)
        } else {
            0.0
        };
        let b = if w1 > 0.0 {
            w1 * self.target.value(p)
        } else {
            0.0
        };
        a + b
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compile_source;

    fn ball(r: f64) -> Shape {
        Shape::build(|b, [x, y, z]| {
            let (x2, y2, z2) = (b.square(x), b.square(y), b.square(z));
            let s = b.add(x2, y2);
            let s = b.add(s, z2);
            let r2 = b.constant(r * r);
            b.sub(r2, s)
        })
    }

    #[test]
    fn control_points_lie_on_the_result() {
        let f = ball(1.0);
        let pts = [
            ControlPoint::sphere(DVec3::new(0.5, 0.0, 0.0), 0.3).unwrap(),
            ControlPoint::sphere(DVec3::new(0.0, 1.3, 0.0), 0.4).unwrap(),
            ControlPoint::ellipsoid(
                DVec3::new(0.0, 0.0, -0.7),
                [
                    DVec3::new(0.2, 0.2, 0.0),
                    DVec3::new(-0.1, 0.1, 0.0),
                    DVec3::Z * 0.3,
                ],
            )
            .unwrap(),
        ];
        let g = Tape::new(&control_points(&f, &pts));
        let ft = Tape::new(&f);
        for c in &pts {
            assert!(g.eval(c.position).abs() < 1e-12, "{}", g.eval(c.position));
        }
        // Eq. 11 at an arbitrary point.
        let x = DVec3::new(0.55, 0.1, -0.05);
        let want = ft.eval(x)
            - pts
                .iter()
                .map(|c| ft.eval(c.position) * wyvill_kernel(c.r2(x)))
                .sum::<f64>();
        assert!((g.eval(x) - want).abs() < 1e-12);
        // Outside every area of influence nothing changes.
        let far = DVec3::new(-2.0, -2.0, 2.0);
        assert_eq!(g.eval(far), ft.eval(far));
        assert!(ControlPoint::sphere(DVec3::ZERO, 0.0).is_err());
    }

    #[test]
    fn convolution_matches_simpson_sum() {
        let f = ball(1.0);
        let curve = |t: f64| DVec3::new(t.cos(), t.sin(), t - 0.5);
        let g = Tape::new(&convolution_deformation(&f, &curve, 0.25, 8).unwrap());
        let ft = Tape::new(&f);
        let x = DVec3::new(0.3, 0.4, -0.2);
        let h = 1.0 / 8.0;
        let mut integral = 0.0;
        for j in 0..=8 {
            let p = curve(f64::from(j) * h);
            let w = if j == 0 || j == 8 {
                1.0
            } else if j % 2 == 1 {
                4.0
            } else {
                2.0
            };
            integral += w * h / 3.0 * ft.eval(p) * (-(x - p).length() / 0.25).exp();
        }
        assert!((g.eval(x) - (ft.eval(x) - integral)).abs() < 1e-12);
        assert!(convolution_deformation(&f, &curve, 0.25, 7).is_err());
        assert!(convolution_deformation(&f, &curve, -1.0, 8).is_err());
    }

    #[test]
    fn metamorphosis_ends_are_the_two_shapes() {
        let f = ball(1.0);
        let g = compile_source(
            "m(x[3], a[1]) { array v[3]; v = [-1, -1, -1]; m = hfBlock(x, v, 2, 2, 2); }",
            &Default::default(),
        )
        .unwrap();
        for s in [
            Schedule::Linear,
            Schedule::Sqrt,
            Schedule::Delayed { t0: 0.3 },
            Schedule::Smoothstep,
        ] {
            assert_eq!(morph(&f, &g, 0.0, s), f);
            assert_eq!(morph(&f, &g, 1.0, s), g);
        }
        let m = Tape::new(&morph(&f, &g, 0.5, Schedule::Linear));
        let (ft, gt) = (Tape::new(&f), Tape::new(&g));
        let x = DVec3::new(0.3, -0.2, 0.9);
        assert!((m.eval(x) - 0.5 * (ft.eval(x) + gt.eval(x))).abs() < 1e-12);
        assert_eq!(Schedule::Delayed { t0: 0.3 }.at(0.2), 0.0);
        assert!((Schedule::Delayed { t0: 0.3 }.at(1.0) - 1.0).abs() < 1e-15);
        assert!((Schedule::Delayed { t0: 0.3 }.at(0.65) - 0.35 * 0.35 / 0.49).abs() < 1e-15);
        assert_eq!(
            Schedule::parse("delayed:0.3").unwrap(),
            Schedule::Delayed { t0: 0.3 }
        );
        assert!(Schedule::parse("delayed:1.5").is_err());
        for s in [
            Schedule::Linear,
            Schedule::Sqrt,
            Schedule::Smoothstep,
            Schedule::Delayed { t0: 0.3 },
            Schedule::Delayed { t0: 0.1 + 0.2 },
            Schedule::Delayed { t0: 0.0 },
        ] {
            assert_eq!(Schedule::parse(&s.to_string()).unwrap(), s, "{s}");
        }
    }

    #[test]
    fn function_dependent_mappings_follow_their_formulas() {
        let f = ball(1.0);
        let ft = Tape::new(&f);
        let x = DVec3::new(0.3, 0.2, -0.4);
        let (v, g) = ft.gradient(x);
        let off = Tape::new(&offset_along_gradient(&f, 0.1));
        assert!((off.eval(x) - ft.eval(x + 0.1 * g)).abs() < 1e-12);
        let shell = Tape::new(&thin_shell(&f, 0.5, 0.1));
        let psi = 0.5 * v + 0.1;
        assert!((shell.eval(x) - ft.eval(DVec3::splat(psi))).abs() < 1e-12);
        let mz = Tape::new(&maze(&f, 0.8, 7.0, 0.2));
        let psi = 0.8 * (7.0 * v + 0.2).sin();
        assert!((mz.eval(x) - ft.eval(DVec3::splat(psi))).abs() < 1e-12);
        let o = Tape::new(&offset(&f, 0.25));
        assert_eq!(o.eval(x), v + 0.25);
    }

    #[test]
    fn space_mapped_fields_follow_their_formulas() {
        use volmorph_deform::Affine;
        let ft = Tape::new(&ball(1.0));
        let shift = Affine::translation(DVec3::new(0.5, 0.0, 0.0));
        let pb = Pullback {
            field: &ft,
            inverse: shift,
        };
        let x = DVec3::new(0.1, 0.2, 0.3);
        assert_eq!(pb.value(x), ft.eval(x + DVec3::new(0.5, 0.0, 0.0)));
        let (_, g) = pb.gradient(x);
        assert!((g - ft.gradient(x + DVec3::X * 0.5).1).length() < 1e-12);
        // A constant displacement: x + s·d.
        let d = DVec3::new(0.0, 0.2, 0.0);
        let dis = Displaced {
            field: &ft,
            displacement: d,
            scale: 0.5,
        };
        assert_eq!(dis.value(x), ft.eval(x + DVec3::new(0.0, 0.1, 0.0)));
        let target = Tape::new(&ball(0.5));
        for t in [0.0, 0.4, 1.0] {
            let c = Combined {
                initial: &ft,
                target: &target,
                displacement: d,
                h1: Schedule::Delayed { t0: 0.3 },
                h2: Schedule::Sqrt,
                t,
            };
            let (w1, w2) = (Schedule::Delayed { t0: 0.3 }.at(t), t.sqrt());
            let want =
                (1.0 - w1) * ft.eval(x + w2 * DVec3::new(0.0, 0.2, 0.0)) + w1 * target.eval(x);
            assert!((c.value(x) - want).abs() < 1e-12);
        }
    }

    #[test]
    fn handle_displacement_moves_the_surface_to_the_targets() {
        let ft = Tape::new(&ball(1.0));
        let sources = [
            DVec3::X,
            DVec3::Y,
            DVec3::Z,
            -DVec3::X,
            -DVec3::Y,
            -DVec3::Z,
            DVec3::new(1.0, 1.0, 1.0).normalize(),
        ];
        let mut targets = sources;
        targets[0] = DVec3::new(1.4, 0.1, 0.0);
        targets[6] *= 0.8;
        let d = displace_by_handles(&ft, &sources, &targets, 0.0).unwrap();
        for t in &targets {
            assert!(d.value(*t).abs() < 1e-9, "{}", d.value(*t));
        }
        assert_eq!(d.scale, -1.0);
        assert!(d.value(DVec3::ZERO) > 0.0);
        assert!(d.value(DVec3::new(1.3, 0.1, 0.0)) > 0.0);
        assert!(d.value(DVec3::splat(2.0)) < 0.0);
        // The chain rule against central differences.
        let x = DVec3::new(0.4, -0.3, 0.2);
        let (v, g) = d.gradient(x);
        assert_eq!(v, d.value(x));
        let h = 1e-6;
        for e in [DVec3::X, DVec3::Y, DVec3::Z] {
            let fd = (d.value(x + h * e) - d.value(x - h * e)) / (2.0 * h);
            assert!((fd - g.dot(e)).abs() < 1e-6, "{fd} vs {}", g.dot(e));
        }
        // The displacement field interpolates δ = D − Q at D.
        for (q, t) in sources.iter().zip(&targets) {
            assert!((d.displacement.displacement(*t) - (*t - *q)).length() < 1e-9);
        }
        // Identical handles: the identity.
        let id = displace_by_handles(&ft, &sources, &sources, 0.0).unwrap();
        assert!((id.value(x) - ft.eval(x)).abs() < 1e-12);
        assert!(displace_by_handles(&ft, &sources, &targets[..5], 0.0).is_err());
        assert!(displace_by_handles(&ft, &sources[..3], &targets[..3], 0.0).is_err());
        let mut nan = targets;
        nan[1].x = f64::NAN;
        assert!(displace_by_handles(&ft, &sources, &nan, 0.0).is_err());
    }
}
