//! Optical path tracing through a volume with a spatially varying refractive index
//! (Martin & Cohen §5.3–§5.4).
//!
//! # Algorithm
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
//!   there, and their focus comes out about 8 % long. The default,
//!   [`PathMethod::RayEquation`], therefore uses the same Snell construction with the index
//!   `η₁ = |η₀ v + Δt ∇η|` that the ray equation implies over the step: the tangential part of
//!   `η v` is preserved exactly as in Snell's law, and the normal part grows by `Δt |∇η|`,
//!   i.e. `v₁ = (η₀ v + Δt ∇η)/|η₀ v + Δt ∇η|` (a ray turned back by a strong gradient
//!   reverses its normal component, the continuous form of total internal reflection).
//!   Both agree to first order wherever the ray crosses isosurfaces at a non-zero angle;
//! * **step size**: the ray's curvature is at most `|∇η|/η`, so the direction turns by about
//!   `Δt·|∇η|/η` per step; the step is `Δt = clamp(max_turn·η/|∇η|, min_step, max_step)`
//!   ([`OpticsOptions`]), i.e. the largest step that turns the ray by at most `max_turn`
//!   radians.
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
use crate::raytrace::{RayTracer, check_ray};
use crate::volrender::{ENTRY_PROBE, find_entry, find_exit};
use crate::{AggregateVolume, TrivariateError};

/// Options of [`trace_optical_path`] (lengths in model units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpticsOptions {
    /// Largest step (> 0).
    pub max_step: f64,
    /// Smallest step (> 0, ≤ `max_step`).
    pub min_step: f64,
    /// Largest direction change per step, radians (> 0).
    pub max_turn: f64,
    /// Refractive index of the medium outside the volume (> 0).
    pub outside_index: f64,
    /// Length of the straight segment appended after the ray finally leaves (≥ 0).
    pub exit_length: f64,
    /// Most steps per ray (bounds the work).
    pub max_steps: usize,
    /// How the direction is updated inside the volume.
    pub method: PathMethod,
}

/// Direction update inside the volume (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PathMethod {
    /// Snell's law between the indices sampled at consecutive points (the paper's literal
    /// scheme; stalls for rays tangent to isosurfaces).
    Snell,
    /// Snell's law with the index implied by the ray equation over the step (the default).
    #[default]
    RayEquation,
}

impl OpticsOptions {
    /// Defaults for a model of diagonal `diagonal`: steps between `diagonal·1e-5` and
    /// `diagonal/400`, `max_turn = 2e-3`, air outside, an exit segment of `2·diagonal`,
    /// 1 000 000 steps, [`PathMethod::RayEquation`].
    #[must_use]
    pub fn for_diagonal(diagonal: f64) -> Self {
        Self {
            max_step: diagonal / 400.0,
            min_step: diagonal * 1e-5,
            max_turn: 2e-3,
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
            && pos(self.outside_index)
            && self.exit_length.is_finite()
            && self.exit_length >= 0.0
            && self.max_steps > 0)
        {
            return Err(TrivariateError::InvalidArgument(format!(
                "optics options need finite positive steps (min ≤ max), turn and outside index, \
                 a finite non-negative exit length and max_steps > 0: {self:?}"
            )));
        }
        Ok(())
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
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = dot(a, a).sqrt();
    (n > 0.0 && n.is_finite()).then(|| a.map(|x| x / n))
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

/// Trace one ray from `origin` along `dir` through the index attribute `attribute` of
/// `volume` (whose geometry `tracer` was built from), by the algorithm of the
/// [module docs](self).
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
    let ev = VolumeEvaluator::new(spline);
    let check_eta = |eta: f64| {
        if eta.is_finite() && eta > 0.0 {
            Ok(eta)
        } else {
            Err(TrivariateError::InvalidArgument(format!(
                "refractive index {attribute:?} = {eta} must be finite and > 0"
            )))
        }
    };
    let outside = options.outside_index;
    let mut p = origin;
    let mut points = vec![origin];
    let mut exit = None;
    let mut entries = 0;
    let mut steps = 0usize;
    'outer: loop {
        let hits = tracer.intersect(p, v)?;
        let skip = ENTRY_PROBE * tracer.diagonal();
        let after = if entries == 0 { 0.0 } else { skip };
        let Some(entry) = find_entry(tracer, p, v, &hits, after)? else {
            break;
        };
        entries += 1;
        p = std::array::from_fn(|c| p[c] + entry.t * v[c]);
        if entry.t > 0.0 {
            points.push(p);
        }
        let mut u = entry.params;
        let Some(first) = tracer.track(p, u)? else {
            break;
        };
        u = first.params;
        let (mut eta, mut grad) = index_and_gradient(&ev, u, &first.jacobian)?;
        eta = check_eta(eta)?;
        if let Some(h) = entry.hit {
            let (nv, _) = refract(v, h.normal, outside, eta);
            v = nv;
        }
        loop {
            steps += 1;
            if steps > options.max_steps {
                break 'outer;
            }
            let gnorm = dot(grad, grad).sqrt();
            let dt = if gnorm > 0.0 {
                (options.max_turn * eta / gnorm).clamp(options.min_step, options.max_step)
            } else {
                options.max_step
            };
            let target = std::array::from_fn(|c| p[c] + dt * v[c]);
            match tracer.track(target, u)? {
                Some(tr) => {
                    let (e1, g1) = index_and_gradient(&ev, tr.params, &tr.jacobian)?;
                    let e1 = check_eta(e1)?;
                    v = match options.method {
                        PathMethod::Snell => refract(v, g1, eta, e1).0,
                        PathMethod::RayEquation => {
                            let w = std::array::from_fn(|c| eta * v[c] + dt * g1[c]);
                            normalize(w).unwrap_or(v)
                        }
                    };
                    p = target;
                    points.push(p);
                    u = tr.params;
                    eta = e1;
                    grad = g1;
                }
                None => {
                    let local = tracer.intersect(p, v)?;
                    let (te, hit) = find_exit(tracer, p, v, &local, 0.0, u, dt)?;
                    p = std::array::from_fn(|c| p[c] + te * v[c]);
                    points.push(p);
                    let normal = hit.map_or([0.0; 3], |h| h.normal);
                    let (nv, reflected) = refract(v, normal, eta, outside);
                    v = nv;
                    if reflected {
                        // Still inside: continue the walk from the exit point.
                        if let Some(tr) = tracer.track(p, u)? {
                            u = tr.params;
                            continue;
                        }
                    }
                    exit = Some((p, v));
                    continue 'outer;
                }
            }
        }
    }
    if options.exit_length > 0.0 {
        points.push(std::array::from_fn(|c| p[c] + options.exit_length * v[c]));
    }
    Ok(OpticalPath {
        points,
        direction: v,
        exit,
        entries,
    })
}

/// Write paths as a Wavefront OBJ file of polylines: all vertices (`v x y z`) followed by one
/// `l i j k …` element per path (1-based indices). Written atomically.
///
/// # Errors
/// [`TrivariateError::Io`] when the file cannot be written.
pub fn write_paths_obj(path: &Path, paths: &[OpticalPath]) -> Result<(), TrivariateError> {
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
