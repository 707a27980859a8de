//! Optical path tracing through a volume with a spatially varying refractive index
//! (Martin & Cohen §5.3–§5.4).
//!
//! Three ways of following the ray inside ([`PathMethod`]): the paper's literal Snell stepping,
//! its ray-equation form (both first order, below), and the default, an adaptive
//! Dormand–Prince integrator of the ray equation ([below](#the-adaptive-integrator-the-default-pathmethodrk45)).
//!
//! # The paper's stepping (§5.3)
//!
//! The ray walks through the volume as in [`volrender`](crate::volrender): entry at the first
//! boundary hit beyond which the volume lies, parameters tracked by eq. 9
//! ([`RayTracer::track`]), exit at the last boundary hit before the first outside point. At
//! each step:
//!
//! * the index `η` and its parametric gradient `(∂η/∂u, ∂η/∂v, ∂η/∂w)` are evaluated, and the
//!   physical gradient is **eq. 10**, `∇η = (JPᵀ)⁻¹ (∂η/∂u, ∂η/∂v, ∂η/∂w)ᵀ`, with the Jacobian
//!   `JP` from the tracking step (where `JP` is singular — on the degenerate axis of a revolved
//!   volume — `∇η` is taken as 0 for that step);
//! * the direction is bent by **Snell's law** across the local isosurface of `η`
//!   ([`refract`]): `n = ∇η/|∇η|` flipped if needed so that `n · v < 0`,
//!   `t = n × (v × n)` (the tangential part of `v`, length `sin θ₀ = |v × n|`),
//!   `θ₁ = asin(η₀ sin θ₀ / η₁)` with `η₀` the index at the previous sample and `η₁` the index
//!   here, and `v₁ = sin θ₁ t̂ − cos θ₁ n`. The paper prints `+ cos θ₁ n`, but it measures `θ₁`
//!   from `−n` and `n` points against the ray, so the refracted ray continues along `−n`.
//!   When `η₀ sin θ₀ / η₁ > 1` the ray is totally internally reflected, `v₁ = v − 2(v·n)n`;
//!   when `∇η = 0` or `v ∥ n` (`sin θ₀ = 0`) the direction is unchanged;
//!
//!   Taken literally ([`PathMethod::Snell`], with `η₁ = η(u₂)` the index sampled at the new
//!   point) this update cannot bend a ray that runs **along** an isosurface: `η₀ = η₁` and
//!   `sin θ₀ = 1` give `θ₁ = θ₀`, although the ray equation `d(η v)/ds = ∇η` curves it towards
//!   higher index with curvature `|∇η|/η`. For a ray at a small angle `ψ` to the isosurface the
//!   update does give `dψ/ds = |∇η|/η`, but `ψ = 0` is a stationary point that only rounding
//!   leaves, late — paraxial rays entering a GRIN rod parallel to its axis start exactly
//!   there, and their focus comes out about 8 % long. [`PathMethod::RayEquation`] therefore
//!   uses the same Snell construction with the index
//!   `η₁ = |η₀ v + Δt ∇η|` that the ray equation implies over the step: the tangential part of
//!   `η v` is preserved exactly as in Snell's law, and the normal part grows by `Δt |∇η|`,
//!   i.e. `v₁ = (η₀ v + Δt ∇η)/|η₀ v + Δt ∇η|` (a ray turned back by a strong gradient
//!   reverses its normal component, the continuous form of total internal reflection).
//!   Both agree to first order wherever the ray crosses isosurfaces at a non-zero angle;
//! * **step size** (both stepwise methods): the ray's curvature is at most `|∇η|/η`, so the
//!   direction turns by about `Δt·|∇η|/η` per step; the step is
//!   `Δt = clamp(max_turn·η/|∇η|, min_step, max_step)` ([`OpticsOptions`]), i.e. the largest
//!   step that turns the ray by at most `max_turn` radians. Both are first-order accurate: the
//!   error of a focus they measure shrinks in proportion to the step.
//!
//! # The adaptive integrator (the default, [`PathMethod::Rk45`])
//!
//! The ray equation `d/ds (η dr/ds) = ∇η` (`s` the arc length) is integrated as the first-order
//! system of the position `r` and the optical momentum `p = η dr/ds` (`|p| = η`):
//!
//! ```text
//! dr/ds = p / η(r),        dp/ds = ∇η(r)
//! ```
//!
//! by the Dormand–Prince 5(4) pair (Dormand & Prince 1980; the tableau of Hairer, Nørsett &
//! Wanner, *Solving ODEs I*, §II.5, first-same-as-last). Every right-hand side tracks the
//! stage point's parameters by eq. 9 from those of the step's start and evaluates `η` and
//! `∇η` by eq. 10. **Error control**: the local error estimate `e` (5th minus embedded 4th
//! order solution) is measured as `max(|e_r|/(T·L), |e_p|/(T·η))` with `T` the tolerance
//! ([`OpticsOptions::tolerance`]) and `L` the model diagonal; a step with a measure `ε ≤ 1` is
//! accepted, and the next step is `h·clamp(0.9 ε^(−1/5), 0.2, 5)` (the standard controller,
//! Hairer et al. II.4), never above [`OpticsOptions::max_step`] (which also keeps the drawn
//! polyline smooth) nor below [`OpticsOptions::min_step`] (where a step is accepted whatever
//! its error). **Leaving the solid**: a step some stage of which lies outside is not taken;
//! instead the step length that ends exactly on the boundary is solved for — from an inside
//! state with unit direction `v`, the distance `φ` to the boundary along the tangent line
//! (the first [`RayTracer::intersect`] hit beyond which the solid ends) is the Newton
//! correction of the step length (`dφ/dh = −1` up to the path's curvature), steps that
//! overshoot are bisected back, and the exit is accepted once `φ ≤` [`EXIT_TOLERANCE`] × `L`.
//! The ray then refracts at the hit's surface normal.
//!
//! Its reference is [`reference_options`]: the same integrator at tolerance
//! [`REFERENCE_TOLERANCE`] with a step of at most `L/4000`. For the GRIN lens
//! ([`crate::examples`]) both are checked against an independent exact trace, the meridional
//! ray ODE in `z` ([`crate::examples::exact_back_focal_distance`]).
//!
//! At the entry and exit points the ray refracts against the outside medium
//! ([`OpticsOptions::outside_index`], 1 for air) with the boundary surface normal of the hit
//! (the same [`refract`], including total internal reflection, after which the ray stays
//! inside). After leaving the volume for good the path is continued straight for
//! [`OpticsOptions::exit_length`].

use std::path::Path;

use volmorph_render::{Camera, RgbaImage, draw::draw_line};

use crate::eval::{EvalMethod, VolumeEvaluator};
use crate::invert::solve3_rows;
use crate::raytrace::{BoundaryHit, RayTracer, check_ray};
use crate::volrender::{ENTRY_PROBE, find_entry, find_exit};
use crate::{AggregateVolume, TrivariateError};

/// Options of [`trace_optical_path`] (lengths in model units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpticsOptions {
    /// Largest step (> 0): the step of the stepwise methods where the index is nearly
    /// uniform, the cap on the adaptive integrator's steps.
    pub max_step: f64,
    /// Smallest step (> 0, ≤ `max_step`).
    pub min_step: f64,
    /// Largest direction change per step of the stepwise methods, radians (> 0).
    pub max_turn: f64,
    /// Local error tolerance of [`PathMethod::Rk45`] (relative to the model diagonal for
    /// positions and to the index for the optical momentum; > 0, finite). Unused by the
    /// stepwise methods.
    pub tolerance: f64,
    /// Refractive index of the medium outside the volume (> 0).
    pub outside_index: f64,
    /// Length of the straight segment appended after the ray finally leaves (≥ 0).
    pub exit_length: f64,
    /// Most steps per ray (bounds the work).
    pub max_steps: usize,
    /// How the ray is followed inside the volume.
    pub method: PathMethod,
}

/// How a ray is followed inside the volume (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PathMethod {
    /// Snell's law between the indices sampled at consecutive points (the paper's literal
    /// scheme; stalls for rays tangent to isosurfaces).
    Snell,
    /// Snell's law with the index implied by the ray equation over the step (first order).
    RayEquation,
    /// The ray equation integrated by Dormand–Prince 5(4) with error control (the default).
    #[default]
    Rk45,
}

impl PathMethod {
    /// The method's name on the command line: `snell`, `ray-equation` or `rk45`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Snell => "snell",
            Self::RayEquation => "ray-equation",
            Self::Rk45 => "rk45",
        }
    }

    /// The method named `name` ([`PathMethod::name`]).
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] naming the known methods.
    pub fn parse(name: &str) -> Result<Self, TrivariateError> {
        [Self::Snell, Self::RayEquation, Self::Rk45]
            .into_iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| {
                TrivariateError::InvalidArgument(format!(
                    "path method {name:?} is not snell, ray-equation or rk45"
                ))
            })
    }
}

/// Default local error tolerance of [`PathMethod::Rk45`]: the GRIN lens's back focal
/// distance then agrees with its exact trace to about 1e-7 (measured; the issue's bound is
/// 5e-4).
pub const DEFAULT_TOLERANCE: f64 = 1e-9;

/// Tolerance of the reference trace ([`reference_options`]): three orders below the
/// default, ten above the unit roundoff of `f64`, so the integration error of a trace
/// through a unit-sized model stays near 1e-12.
pub const REFERENCE_TOLERANCE: f64 = 1e-12;

/// How close to the boundary (× model diagonal) the adaptive integrator must end its last
/// step inside: ten times the tracking tolerance of [`RayTracer::track`] (1e-10), below
/// which "inside" itself is not resolved.
pub const EXIT_TOLERANCE: f64 = 1e-9;

/// Most Newton/bisection steps of the exit search (each halves the remaining distance at
/// least, so 60 reach `f64` resolution from any start).
const EXIT_ITERATIONS: usize = 60;

impl OpticsOptions {
    /// Defaults for a model of diagonal `diagonal`: steps between `diagonal·1e-5` and
    /// `diagonal/400`, `max_turn = 2e-3`, tolerance [`DEFAULT_TOLERANCE`], air outside, an
    /// exit segment of `2·diagonal`, 1 000 000 steps, [`PathMethod::Rk45`].
    #[must_use]
    pub fn for_diagonal(diagonal: f64) -> Self {
        Self {
            max_step: diagonal / 400.0,
            min_step: diagonal * 1e-5,
            max_turn: 2e-3,
            tolerance: DEFAULT_TOLERANCE,
            outside_index: 1.0,
            exit_length: 2.0 * diagonal,
            max_steps: 1_000_000,
            method: PathMethod::default(),
        }
    }

    fn validate(&self) -> Result<(), TrivariateError> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if !(pos(self.max_step)
            && pos(self.min_step)
            && self.min_step <= self.max_step
            && pos(self.max_turn)
            && pos(self.tolerance)
            && pos(self.outside_index)
            && self.exit_length.is_finite()
            && self.exit_length >= 0.0
            && self.max_steps > 0)
        {
            return Err(TrivariateError::InvalidArgument(format!(
                "optics options need finite positive steps (min ≤ max), turn, tolerance and \
                 outside index, a finite non-negative exit length and max_steps > 0: {self:?}"
            )));
        }
        Ok(())
    }
}

/// The reference trace's options for a model of diagonal `diagonal`: [`PathMethod::Rk45`]
/// at [`REFERENCE_TOLERANCE`] with steps of at most `diagonal/4000` (the rest as
/// [`OpticsOptions::for_diagonal`]).
#[must_use]
pub fn reference_options(diagonal: f64) -> OpticsOptions {
    OpticsOptions {
        max_step: diagonal / 4000.0,
        min_step: diagonal * 1e-7,
        tolerance: REFERENCE_TOLERANCE,
        method: PathMethod::Rk45,
        ..OpticsOptions::for_diagonal(diagonal)
    }
}

/// A traced ray: the polyline of its path and how it ended.
#[derive(Debug, Clone, PartialEq)]
pub struct OpticalPath {
    /// Path vertices from the ray origin (entry, interior samples, exit, end of the final
    /// straight segment).
    pub points: Vec<[f64; 3]>,
    /// Unit direction after the last vertex.
    pub direction: [f64; 3],
    /// Where the ray last left the volume, and its direction from there (`None` if it never
    /// entered or never left within `max_steps`).
    pub exit: Option<([f64; 3], [f64; 3])>,
    /// Number of times the ray entered the volume.
    pub entries: usize,
    /// Steps taken inside the volume (accepted steps of [`PathMethod::Rk45`]).
    pub steps: usize,
    /// Steps of [`PathMethod::Rk45`] rejected by its error control (0 for the others).
    pub rejected_steps: usize,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = dot(a, a).sqrt();
    (n > 0.0 && n.is_finite()).then(|| a.map(|x| x / n))
}

fn along(p: [f64; 3], t: f64, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|c| p[c] + t * v[c])
}

/// Snell's law at an interface with normal `normal` (any orientation, any non-zero length)
/// from index `eta0` into `eta1`, for the unit direction `v` (conventions in the
/// [module docs](self)). A zero or non-finite normal leaves `v` unchanged. Returns the new unit
/// direction and whether the ray was totally internally reflected.
#[must_use]
pub fn refract(v: [f64; 3], normal: [f64; 3], eta0: f64, eta1: f64) -> ([f64; 3], bool) {
    let Some(mut n) = normalize(normal) else {
        return (v, false);
    };
    if dot(n, v) > 0.0 {
        n = n.map(|x| -x);
    }
    let vn = dot(v, n);
    // t = n × (v × n) = v − n (n·v): the tangential part of v, |t| = sin θ0.
    let t = [v[0] - n[0] * vn, v[1] - n[1] * vn, v[2] - n[2] * vn];
    let sin0 = dot(t, t).sqrt();
    let Some(th) = normalize(t) else {
        return (v, false);
    };
    let sin1 = eta0 * sin0 / eta1;
    if !(sin1.is_finite()) {
        return (v, false);
    }
    if sin1 > 1.0 {
        let r = [
            v[0] - 2.0 * vn * n[0],
            v[1] - 2.0 * vn * n[1],
            v[2] - 2.0 * vn * n[2],
        ];
        return (normalize(r).unwrap_or(v), true);
    }
    let cos1 = (1.0 - sin1 * sin1).max(0.0).sqrt();
    let out = std::array::from_fn(|c| sin1 * th[c] - cos1 * n[c]);
    (normalize(out).unwrap_or(v), false)
}

/// Index and physical gradient (eq. 10) at parameters `u` with Jacobian `jac`
/// (column-major).
fn index_and_gradient(
    ev: &VolumeEvaluator<'_>,
    u: [f64; 3],
    jac: &[f64; 9],
) -> Result<(f64, [f64; 3]), TrivariateError> {
    let mut val = [0.0];
    let mut g = [0.0; 3];
    ev.eval_into(EvalMethod::default(), u, &mut val, &mut g)?;
    Ok((val[0], physical_gradient(jac, g)))
}

/// Physical gradient `∇ₓa` of an attribute from its parametric gradient `g = ∇ᵤa` and the
/// geometry's Jacobian `jac` (column-major, `jac[3a + c] = ∂P_c/∂u_a`), by the chain rule
/// `JPᵀ ∇ₓa = ∇ᵤa` (eq. 10); zero where the Jacobian is singular.
pub(crate) fn physical_gradient(jac: &[f64; 9], g: [f64; 3]) -> [f64; 3] {
    // JPᵀ has rows P_u, P_v, P_w.
    let m = [
        [jac[0], jac[1], jac[2]],
        [jac[3], jac[4], jac[5]],
        [jac[6], jac[7], jac[8]],
    ];
    solve3_rows(m, g).unwrap_or([0.0; 3])
}

/// The index at a point inside the solid.
#[derive(Debug, Clone, Copy)]
struct Sample {
    params: [f64; 3],
    eta: f64,
    grad: [f64; 3],
}

/// The refractive medium: the tracer of the geometry and the index attribute.
struct Medium<'a> {
    tracer: &'a RayTracer,
    ev: VolumeEvaluator<'a>,
    attribute: &'a str,
    options: &'a OpticsOptions,
}

/// How a walk through the solid ended.
enum Walk {
    /// Left the solid at `point`, going along `dir` (refracted into the outside medium).
    Exited { point: [f64; 3], dir: [f64; 3] },
    /// Stopped inside after `max_steps`.
    Stopped { point: [f64; 3], dir: [f64; 3] },
}

/// Steps counted over the whole ray.
#[derive(Default)]
struct Count {
    steps: usize,
    rejected: usize,
}

/// Dormand–Prince 5(4) nodes, coupling coefficients (row `s` used by stage `s`), and the
/// error weights `b₅ − b₄` (Hairer, Nørsett & Wanner, Table II.5.2). Row 6 equals `b₅`, so the
/// last stage is the step's result (first same as last).
const DP_A: [[f64; 6]; 7] = [
    [0.0; 6],
    [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
    [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
    [
        19372.0 / 6561.0,
        -25360.0 / 2187.0,
        64448.0 / 6561.0,
        -212.0 / 729.0,
        0.0,
        0.0,
    ],
    [
        9017.0 / 3168.0,
        -355.0 / 33.0,
        46732.0 / 5247.0,
        49.0 / 176.0,
        -5103.0 / 18656.0,
        0.0,
    ],
    [
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
    ],
];
const DP_E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];

/// The state `(r, p)` of the ray equation.
type State = [f64; 6];

/// One Dormand–Prince step: the new state, the sample and derivative there, and the error
/// measure (≤ 1 acceptable).
struct DpStep {
    y: State,
    sample: Sample,
    k: State,
    err: f64,
}

fn derivative(y: &State, s: &Sample) -> State {
    [
        y[3] / s.eta,
        y[4] / s.eta,
        y[5] / s.eta,
        s.grad[0],
        s.grad[1],
        s.grad[2],
    ]
}

fn position(y: &State) -> [f64; 3] {
    [y[0], y[1], y[2]]
}

fn momentum(y: &State) -> [f64; 3] {
    [y[3], y[4], y[5]]
}

impl Medium<'_> {
    fn check_eta(&self, eta: f64) -> Result<f64, TrivariateError> {
        if eta.is_finite() && eta > 0.0 {
            Ok(eta)
        } else {
            Err(TrivariateError::InvalidArgument(format!(
                "refractive index {:?} = {eta} must be finite and > 0",
                self.attribute
            )))
        }
    }

    /// The index at `x` tracked from parameters `guess`; `None` outside the solid.
    fn sample(&self, x: [f64; 3], guess: [f64; 3]) -> Result<Option<Sample>, TrivariateError> {
        let Some(tr) = self.tracer.track(x, guess)? else {
            return Ok(None);
        };
        let (eta, grad) = index_and_gradient(&self.ev, tr.params, &tr.jacobian)?;
        Ok(Some(Sample {
            params: tr.params,
            eta: self.check_eta(eta)?,
            grad,
        }))
    }

    /// Distance from the inside point `x` along the unit `v` to where the solid ends, and the
    /// boundary hit there; `None` when the line never leaves the solid ahead.
    fn exit_along(
        &self,
        x: [f64; 3],
        v: [f64; 3],
    ) -> Result<Option<(f64, BoundaryHit)>, TrivariateError> {
        let eps = ENTRY_PROBE * self.tracer.diagonal();
        for h in self.tracer.intersect(x, v)? {
            if self
                .tracer
                .locate(along(x, h.t + eps, v), Some(h.params))?
                .is_none()
            {
                return Ok(Some((h.t, h)));
            }
        }
        Ok(None)
    }

    /// The nearest boundary hit behind `x` (a point at most rounding past the boundary).
    fn hit_behind(&self, x: [f64; 3], v: [f64; 3]) -> Result<Option<BoundaryHit>, TrivariateError> {
        let back = v.map(|c| -c);
        Ok(self.tracer.intersect(x, back)?.first().copied())
    }

    /// One Dormand–Prince step of length `h` from `y` (sample `s`, derivative `k1`); `None`
    /// when a stage point lies outside the solid.
    fn dp_step(
        &self,
        y: &State,
        s: &Sample,
        k1: &State,
        h: f64,
    ) -> Result<Option<DpStep>, TrivariateError> {
        let mut ks = [[0.0; 6]; 7];
        ks[0] = *k1;
        let mut last = *s;
        let mut ys = *y;
        for st in 1..7 {
            ys = std::array::from_fn(|c| {
                y[c] + h * (0..st).map(|j| DP_A[st][j] * ks[j][c]).sum::<f64>()
            });
            let Some(sm) = self.sample(position(&ys), s.params)? else {
                return Ok(None);
            };
            ks[st] = derivative(&ys, &sm);
            last = sm;
        }
        let tol = self.options.tolerance;
        let scale_r = tol * self.tracer.diagonal();
        let scale_p = tol * last.eta.min(s.eta);
        let mut e = [0.0; 6];
        for (k, w) in ks.iter().zip(DP_E) {
            for (ec, kc) in e.iter_mut().zip(k) {
                *ec += w * kc;
            }
        }
        let err = e.iter().enumerate().fold(0.0f64, |m, (c, ec)| {
            let sc = if c < 3 { scale_r } else { scale_p };
            m.max((h * ec).abs() / sc)
        });
        Ok(Some(DpStep {
            y: ys,
            sample: last,
            k: ks[6],
            err: if err.is_nan() { f64::INFINITY } else { err },
        }))
    }

    /// Refract out of the solid at `point` (index `eta`, boundary `hit`): the exit, or the
    /// totally reflected direction when the ray stays inside.
    fn leave(&self, v: [f64; 3], hit: Option<&BoundaryHit>, eta: f64) -> ([f64; 3], bool) {
        let normal = hit.map_or([0.0; 3], |h| h.normal);
        refract(v, normal, eta, self.options.outside_index)
    }

    /// Follow the ray from `p` (direction `v`, index sample `first`) by the stepwise methods.
    fn walk_stepwise(
        &self,
        mut p: [f64; 3],
        mut v: [f64; 3],
        first: Sample,
        points: &mut Vec<[f64; 3]>,
        count: &mut Count,
    ) -> Result<Walk, TrivariateError> {
        let o = self.options;
        let (mut u, mut eta, mut grad) = (first.params, first.eta, first.grad);
        loop {
            if count.steps >= o.max_steps {
                return Ok(Walk::Stopped { point: p, dir: v });
            }
            count.steps += 1;
            let gnorm = dot(grad, grad).sqrt();
            let dt = if gnorm > 0.0 {
                (o.max_turn * eta / gnorm).clamp(o.min_step, o.max_step)
            } else {
                o.max_step
            };
            let target = along(p, dt, v);
            if let Some(s) = self.sample(target, u)? {
                v = match o.method {
                    PathMethod::Snell => refract(v, s.grad, eta, s.eta).0,
                    _ => {
                        let w = std::array::from_fn(|c| eta * v[c] + dt * s.grad[c]);
                        normalize(w).unwrap_or(v)
                    }
                };
                p = target;
                points.push(p);
                (u, eta, grad) = (s.params, s.eta, s.grad);
                continue;
            }
            let local = self.tracer.intersect(p, v)?;
            let (te, hit) = find_exit(self.tracer, p, v, &local, 0.0, u, dt)?;
            p = along(p, te, v);
            points.push(p);
            let (nv, reflected) = self.leave(v, hit.as_ref(), eta);
            v = nv;
            if reflected && let Some(tr) = self.tracer.track(p, u)? {
                // Still inside: continue the walk from the exit point.
                u = tr.params;
                continue;
            }
            return Ok(Walk::Exited { point: p, dir: v });
        }
    }

    /// Follow the ray from `p` (direction `v`, index sample `first`) by the adaptive
    /// Dormand–Prince integrator of the ray equation.
    fn walk_rk45(
        &self,
        p: [f64; 3],
        v: [f64; 3],
        first: Sample,
        points: &mut Vec<[f64; 3]>,
        count: &mut Count,
    ) -> Result<Walk, TrivariateError> {
        let o = self.options;
        let exit_tol = EXIT_TOLERANCE * self.tracer.diagonal();
        let grow = |err: f64| (0.9 * err.max(1e-300).powf(-0.2)).clamp(0.2, 5.0);
        let dir = |y: &State| normalize(momentum(y)).unwrap_or([0.0, 0.0, 1.0]);
        let mut y: State = [
            p[0],
            p[1],
            p[2],
            first.eta * v[0],
            first.eta * v[1],
            first.eta * v[2],
        ];
        let mut s = first;
        let mut k = derivative(&y, &s);
        let mut h = o.max_step;
        loop {
            if count.steps >= o.max_steps {
                return Ok(Walk::Stopped {
                    point: position(&y),
                    dir: dir(&y),
                });
            }
            h = h.clamp(o.min_step, o.max_step);
            if let Some(st) = self.dp_step(&y, &s, &k, h)? {
                if st.err <= 1.0 || h <= o.min_step {
                    (y, s, k) = (st.y, st.sample, st.k);
                    count.steps += 1;
                    points.push(position(&y));
                } else {
                    count.rejected += 1;
                }
                h *= grow(st.err);
                continue;
            }
            // The trial step leaves the solid: find the step that ends on the boundary.
            let r = position(&y);
            let v = dir(&y);
            let (phi, hit) = match self.exit_along(r, v)? {
                Some(e) if e.0 <= h => e,
                // The line leaves farther on (the path curves out) or not at all: shorten.
                _ => {
                    if h <= o.min_step {
                        // Cannot shorten further: leave along the tangent from here.
                        let hit = self.hit_behind(r, v)?;
                        let (nv, reflected) = self.leave(v, hit.as_ref(), s.eta);
                        if !reflected {
                            return Ok(Walk::Exited { point: r, dir: nv });
                        }
                        y = [
                            r[0],
                            r[1],
                            r[2],
                            s.eta * nv[0],
                            s.eta * nv[1],
                            s.eta * nv[2],
                        ];
                        k = derivative(&y, &s);
                        continue;
                    }
                    h *= 0.5;
                    continue;
                }
            };
            let mut end = (y, s, k, phi, hit, false);
            let (mut lo, mut hk) = (0.0, phi);
            let mut shrink_to = None;
            if phi > exit_tol {
                for _ in 0..EXIT_ITERATIONS {
                    match self.dp_step(&y, &s, &k, hk)? {
                        None => hk = lo + 0.5 * (hk - lo),
                        Some(st) if st.err > 1.0 && hk > o.min_step => {
                            shrink_to = Some(hk * grow(st.err));
                            break;
                        }
                        Some(st) => {
                            let vk = dir(&st.y);
                            let Some((phi_k, hit_k)) = self.exit_along(position(&st.y), vk)? else {
                                // Inside with no boundary ahead: take it as a regular step.
                                shrink_to = Some(hk);
                                break;
                            };
                            end = (st.y, st.sample, st.k, phi_k, hit_k, true);
                            if phi_k <= exit_tol {
                                break;
                            }
                            lo = hk;
                            hk += phi_k;
                        }
                    }
                }
            }
            if let Some(hs) = shrink_to {
                h = hs;
                continue;
            }
            let (ye, se, ke, phi_e, hit_e, stepped) = end;
            if stepped {
                count.steps += 1;
            }
            (y, s, k) = (ye, se, ke);
            if phi_e > exit_tol {
                // The search did not converge: keep the last inside step (or, without one,
                // aim at half the way to the boundary) and go on.
                if stepped {
                    points.push(position(&y));
                } else {
                    h = 0.5 * phi_e;
                }
                continue;
            }
            let ve = dir(&y);
            let point = along(position(&y), phi_e, ve);
            points.push(point);
            let (nv, reflected) = self.leave(ve, Some(&hit_e), s.eta);
            if !reflected {
                return Ok(Walk::Exited { point, dir: nv });
            }
            // Totally reflected: continue inside from the boundary point.
            match self.sample(point, s.params)? {
                Some(sp) => s = sp,
                None => return Ok(Walk::Exited { point, dir: nv }),
            }
            y = [
                point[0],
                point[1],
                point[2],
                s.eta * nv[0],
                s.eta * nv[1],
                s.eta * nv[2],
            ];
            k = derivative(&y, &s);
        }
    }
}

/// Trace one ray from `origin` along `dir` through the index attribute `attribute` of
/// `volume` (whose geometry `tracer` was built from), by the method of
/// [`OpticsOptions::method`] (see the [module docs](self)).
///
/// # Errors
/// [`TrivariateError::UnknownAttribute`]; [`TrivariateError::InvalidArgument`] for an
/// attribute that is not scalar or not positive where sampled, a bad ray (non-finite origin,
/// zero or non-finite direction) or bad options.
pub fn trace_optical_path(
    volume: &AggregateVolume,
    tracer: &RayTracer,
    attribute: &str,
    origin: [f64; 3],
    dir: [f64; 3],
    options: &OpticsOptions,
) -> Result<OpticalPath, TrivariateError> {
    options.validate()?;
    let spline = volume
        .attribute(attribute)
        .ok_or_else(|| TrivariateError::UnknownAttribute(attribute.to_owned()))?;
    if spline.dim() != 1 {
        return Err(TrivariateError::InvalidArgument(format!(
            "refractive index attribute {attribute:?} must be scalar, has dimension {}",
            spline.dim()
        )));
    }
    let mut v = check_ray(origin, dir)?;
    let medium = Medium {
        tracer,
        ev: VolumeEvaluator::new(spline),
        attribute,
        options,
    };
    let mut p = origin;
    let mut points = vec![origin];
    let mut exit = None;
    let mut entries = 0;
    let mut count = Count::default();
    loop {
        let hits = tracer.intersect(p, v)?;
        let skip = ENTRY_PROBE * tracer.diagonal();
        let after = if entries == 0 { 0.0 } else { skip };
        let Some(entry) = find_entry(tracer, p, v, &hits, after)? else {
            break;
        };
        entries += 1;
        p = along(p, entry.t, v);
        if entry.t > 0.0 {
            points.push(p);
        }
        let Some(first) = medium.sample(p, entry.params)? else {
            break;
        };
        if let Some(h) = entry.hit {
            v = refract(v, h.normal, options.outside_index, first.eta).0;
        }
        let walk = match options.method {
            PathMethod::Rk45 => medium.walk_rk45(p, v, first, &mut points, &mut count)?,
            PathMethod::Snell | PathMethod::RayEquation => {
                medium.walk_stepwise(p, v, first, &mut points, &mut count)?
            }
        };
        match walk {
            Walk::Exited { point, dir } => {
                (p, v) = (point, dir);
                exit = Some((p, v));
            }
            Walk::Stopped { point, dir } => {
                (p, v) = (point, dir);
                break;
            }
        }
    }
    if options.exit_length > 0.0 {
        points.push(along(p, options.exit_length, v));
    }
    Ok(OpticalPath {
        points,
        direction: v,
        exit,
        entries,
        steps: count.steps,
        rejected_steps: count.rejected,
    })
}

/// The extension of the polyline files [`write_paths_obj`] writes: `.obj`.
pub const PATHS_EXTENSIONS: &[&str] = &["obj"];

/// Write paths as a Wavefront OBJ file of polylines: all vertices (`v x y z`) followed by one
/// `l i j k …` element per path (1-based indices). Written atomically.
///
/// # Errors
/// [`TrivariateError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in
/// `.obj` ([`PATHS_EXTENSIONS`], nothing written); [`TrivariateError::Io`] when the file
/// cannot be written.
pub fn write_paths_obj(path: &Path, paths: &[OpticalPath]) -> Result<(), TrivariateError> {
    volmorph_io::extension::check(path, PATHS_EXTENSIONS)?;
    volmorph_io::write_atomic(path, |w| -> Result<(), TrivariateError> {
        use std::io::Write;
        let io = |e: std::io::Error| TrivariateError::Io(volmorph_io::IoError::os(path, e));
        writeln!(w, "# volmorph optical paths: {} polylines", paths.len()).map_err(io)?;
        for p in paths {
            for q in &p.points {
                writeln!(w, "v {} {} {}", q[0], q[1], q[2]).map_err(io)?;
            }
        }
        let mut base = 1usize;
        for p in paths {
            if p.points.len() >= 2 {
                write!(w, "l").map_err(io)?;
                for i in 0..p.points.len() {
                    write!(w, " {}", base + i).map_err(io)?;
                }
                writeln!(w).map_err(io)?;
            }
            base += p.points.len();
        }
        Ok(())
    })
}

/// Draw `paths` as lines of `color` over `image` through `camera` (segments with an end behind
/// the camera are skipped).
pub fn draw_paths(image: &mut RgbaImage, camera: &Camera, paths: &[OpticalPath], color: [u8; 4]) {
    for path in paths {
        for w in path.points.windows(2) {
            let a = camera.project(glam::DVec3::from_array(w[0]));
            let b = camera.project(glam::DVec3::from_array(w[1]));
            if let (Some(a), Some(b)) = (a, b) {
                draw_line(image, (a.0, a.1), (b.0, b.1), color);
            }
        }
    }
}
