//! Fans of parallel rays traced through a refractive-index attribute, the back focal distance
//! they measure, and the side-view picture of their paths (what `volmorph nurbs trace-optics`
//! shows, Martin & Cohen §5.3–§5.4).
//!
//! A [`RayFan`] is a set of parallel rays starting on a line before the model: across the
//! model's box for any model ([`RayFan::across`]), or in a meridional plane of the GRIN lens
//! example ([`RayFan::grin_meridian`]). [`RayFan::trace`] follows each by
//! [`trace_optical_path`]; [`measured_back_focal_distance`] traces one paraxial probe ray and
//! finds where it crosses the lens axis; [`side_view`] draws the paths orthographically,
//! looking across the plane of the fan.

use glam::DVec3;
use volmorph_render::draw::draw_box_edges;
use volmorph_render::{Framing, Projection, RgbaImage, view_camera};

use crate::examples::{
    ExactFocus, GrinLensSpec, ParaxialFocus, exact_back_focal_distance, paraxial_focus,
};
use crate::optics::{OpticalPath, OpticsOptions, PathMethod, draw_paths, trace_optical_path};
use crate::raytrace::RayTracer;
use crate::{AggregateVolume, TrivariateError};

/// Azimuth (radians) of the meridional plane the GRIN lens fan and probe lie in: off the
/// revolution seam at azimuth 0, where the lens's parametrisation has its boundary.
pub const GRIN_MERIDIAN_AZIMUTH: f64 = 0.3;

/// Fraction of the lens radius the GRIN fan spans on each side of the axis.
const GRIN_FAN_HEIGHT: f64 = 0.9;

/// Height of the paraxial probe ray, as a fraction of the lens radius: small enough for the
/// paraxial approximation (the focus error grows with the square of the height), large enough
/// that the ray's crossing with the axis is well conditioned.
pub const PROBE_HEIGHT: f64 = 0.02;

/// Fraction of the box diagonal the fan of [`RayFan::across`] spans.
const BOX_FAN_WIDTH: f64 = 0.9;

/// Parallel rays: one direction, several starting points on a line across it.
#[derive(Debug, Clone, PartialEq)]
pub struct RayFan {
    /// Unit direction of every ray.
    pub direction: DVec3,
    /// Start points, in order along the fan's line.
    pub starts: Vec<DVec3>,
    /// Unit vector along the fan's line (perpendicular to `direction`): with `direction` it
    /// spans the plane of the fan.
    pub spread: DVec3,
}

/// Fraction of the fan's line at which ray `i` of `n` starts.
fn fraction(i: usize, n: usize) -> f64 {
    if n == 1 {
        0.5
    } else {
        i as f64 / (n - 1) as f64
    }
}

impl RayFan {
    /// `n` rays along `direction`, starting one box diagonal before the centre of the box
    /// `(lo, hi)` and spread over 0.9 of the diagonal across it.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for `n = 0`, a zero or non-finite direction or
    /// box.
    pub fn across(
        (lo, hi): (DVec3, DVec3),
        direction: DVec3,
        n: usize,
    ) -> Result<Self, TrivariateError> {
        let d = direction.try_normalize().ok_or_else(|| {
            TrivariateError::InvalidArgument(format!(
                "ray direction {direction} must be finite and non-zero"
            ))
        })?;
        if n == 0 || !(lo.is_finite() && hi.is_finite()) {
            return Err(TrivariateError::InvalidArgument(
                "a ray fan needs at least one ray and a finite box".into(),
            ));
        }
        let diag = (hi - lo).length();
        let center = 0.5 * (lo + hi);
        let spread = d.any_orthonormal_vector();
        let starts = (0..n)
            .map(|i| center - diag * d + (fraction(i, n) - 0.5) * BOX_FAN_WIDTH * diag * spread)
            .collect();
        Ok(Self {
            direction: d,
            starts,
            spread,
        })
    }

    /// `n` rays along the axis (+z) of the GRIN lens `spec`, in the meridional plane at
    /// [`GRIN_MERIDIAN_AZIMUTH`], at heights spread over ±0.9 of the radius, starting on
    /// the plane half a thickness before the entry face.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for `n = 0`.
    pub fn grin_meridian(spec: &GrinLensSpec, n: usize) -> Result<Self, TrivariateError> {
        if n == 0 {
            return Err(TrivariateError::InvalidArgument(
                "a ray fan needs at least one ray".into(),
            ));
        }
        let radial = meridian();
        let starts = (0..n)
            .map(|i| {
                let r = (2.0 * fraction(i, n) - 1.0) * GRIN_FAN_HEIGHT * spec.radius;
                r * radial + DVec3::new(0.0, 0.0, -0.5 * spec.thickness)
            })
            .collect();
        Ok(Self {
            direction: DVec3::Z,
            starts,
            spread: radial,
        })
    }

    /// Trace every ray through the index attribute `attribute` of `model`.
    ///
    /// # Errors
    /// As [`trace_optical_path`].
    pub fn trace(
        &self,
        model: &AggregateVolume,
        tracer: &RayTracer,
        attribute: &str,
        options: &OpticsOptions,
    ) -> Result<Vec<OpticalPath>, TrivariateError> {
        self.starts
            .iter()
            .map(|s| {
                trace_optical_path(
                    model,
                    tracer,
                    attribute,
                    s.to_array(),
                    self.direction.to_array(),
                    options,
                )
            })
            .collect()
    }
}

/// Unit radial vector of the meridional plane at [`GRIN_MERIDIAN_AZIMUTH`].
fn meridian() -> DVec3 {
    DVec3::new(
        GRIN_MERIDIAN_AZIMUTH.cos(),
        GRIN_MERIDIAN_AZIMUTH.sin(),
        0.0,
    )
}

/// A back focal distance measured by tracing one probe ray ([`measured_back_focal_distance`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FocusMeasurement {
    /// Height of the probe ray above the axis.
    pub height: f64,
    /// Distance from the exit face to where the probe's exit line crosses the axis.
    pub back_focal_distance: f64,
    /// Steps the trace took inside the lens ([`OpticalPath::steps`]).
    pub steps: usize,
    /// Steps rejected by the error control ([`OpticalPath::rejected_steps`]).
    pub rejected_steps: usize,
}

/// The back focal distance of the GRIN lens `spec` (built by
/// [`grin_lens`](crate::grin_lens) as `model`) measured by tracing: a probe ray parallel to
/// the axis at [`PROBE_HEIGHT`] of the radius, followed through the lens by `options`, and
/// the distance from the exit face to where its exit line crosses the axis. `None` when the
/// probe does not leave the lens or leaves parallel to the axis. Compare with
/// [`exact_back_focal_distance`] at the same
/// height.
///
/// # Errors
/// As [`trace_optical_path`].
pub fn measured_back_focal_distance(
    model: &AggregateVolume,
    tracer: &RayTracer,
    attribute: &str,
    spec: &GrinLensSpec,
    options: &OpticsOptions,
) -> Result<Option<FocusMeasurement>, TrivariateError> {
    let radial = meridian();
    let r0 = PROBE_HEIGHT * spec.radius;
    let probe = r0 * radial + DVec3::new(0.0, 0.0, -0.5 * spec.thickness);
    let p = trace_optical_path(
        model,
        tracer,
        attribute,
        probe.to_array(),
        [0.0, 0.0, 1.0],
        options,
    )?;
    Ok(p.exit.and_then(|(e, v)| {
        let (e, v) = (DVec3::from_array(e), DVec3::from_array(v));
        let (re, vr) = (e.dot(radial), v.dot(radial));
        (vr.abs() > 1e-15).then(|| FocusMeasurement {
            height: r0,
            back_focal_distance: e.z + (-re / vr) * v.z - spec.thickness,
            steps: p.steps,
            rejected_steps: p.rejected_steps,
        })
    }))
}

/// The GRIN lens example checked by tracing ([`check_grin_lens`]): its paraxial focus, and
/// the probe ray's measured back focal distance with the exact trace at the probe's height.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GrinLensCheck {
    /// The lens.
    pub spec: GrinLensSpec,
    /// The paraxial focus.
    pub paraxial: ParaxialFocus,
    /// The probe ray's measurement and the exact trace at its height; `None` when the probe
    /// did not leave the lens towards the axis.
    pub measured: Option<(FocusMeasurement, ExactFocus)>,
    /// The method that traced the probe ([`OpticsOptions::method`]).
    pub method: PathMethod,
}

impl GrinLensCheck {
    /// The measured back focal distance's difference from `reference`, in percent of it.
    fn percent_from(m: &FocusMeasurement, reference: f64) -> f64 {
        100.0 * (m.back_focal_distance - reference) / reference
    }
}

impl std::fmt::Display for GrinLensCheck {
    /// Two lines: the lens and its paraxial focus; the measurement and its differences from
    /// the exact trace and from the paraxial focus (percentages fixed point when large,
    /// scientific when tiny), or that the probe did not leave the lens.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (s, p) = (&self.spec, &self.paraxial);
        writeln!(
            f,
            "GRIN lens R = {}, d = {}, n(r) = {}·(1 − {}·r²/2): paraxial back focal distance \
             {:.5}, effective focal length {:.5}",
            s.radius,
            s.thickness,
            s.n0,
            s.gradient,
            p.back_focal_distance,
            p.effective_focal_length
        )?;
        let Some((m, exact)) = &self.measured else {
            return write!(f, "the probe ray did not leave the lens towards the axis");
        };
        let rel = |reference: f64| {
            let pc = Self::percent_from(m, reference);
            if pc.abs() >= 1e-3 {
                format!("{pc:+.4}")
            } else {
                format!("{pc:+.2e}")
            }
        };
        write!(
            f,
            "measured back focal distance {:.8} (ray at height {:.4}, {} steps by {}): {} % \
             from the exact trace {:.8}, {} % from paraxial",
            m.back_focal_distance,
            m.height,
            m.steps,
            self.method.name(),
            rel(exact.back_focal_distance),
            exact.back_focal_distance,
            rel(p.back_focal_distance)
        )
    }
}

/// Check the GRIN lens `spec` (built by [`grin_lens`](crate::grin_lens) as `model`) by
/// tracing: its [`paraxial_focus`], the probe ray's
/// [`measured_back_focal_distance`] with `options`, and the
/// [`exact_back_focal_distance`] at the probe's height.
///
/// # Errors
/// As [`paraxial_focus`], [`measured_back_focal_distance`] and
/// [`exact_back_focal_distance`].
pub fn check_grin_lens(
    model: &AggregateVolume,
    tracer: &RayTracer,
    attribute: &str,
    spec: &GrinLensSpec,
    options: &OpticsOptions,
) -> Result<GrinLensCheck, TrivariateError> {
    let paraxial = paraxial_focus(spec)?;
    let measured = measured_back_focal_distance(model, tracer, attribute, spec, options)?
        .map(|m| exact_back_focal_distance(spec, m.height).map(|e| (m, e)))
        .transpose()?;
    Ok(GrinLensCheck {
        spec: *spec,
        paraxial,
        measured,
        method: options.method,
    })
}

/// A `width × height` picture of `paths` (red) and the model's box `bounds` (grey) on white,
/// seen orthographically from across the plane of `fan`, framed to the box and every path
/// point.
///
/// # Errors
/// [`TrivariateError::InvalidArgument`] with the render crate's message for a bad size or a
/// degenerate view.
pub fn side_view(
    paths: &[OpticalPath],
    bounds: (DVec3, DVec3),
    fan: &RayFan,
    (width, height): (u32, u32),
) -> Result<RgbaImage, TrivariateError> {
    let (mut lo, mut hi) = bounds;
    for q in paths.iter().flat_map(|p| &p.points) {
        lo = lo.min(DVec3::from_array(*q));
        hi = hi.max(DVec3::from_array(*q));
    }
    let look = fan.direction.cross(fan.spread).normalize_or(DVec3::Y);
    let ortho = Projection::Orthographic { view_height: 1.0 };
    let render = |e: volmorph_render::RenderError| TrivariateError::InvalidArgument(e.to_string());
    let cam = view_camera(
        look,
        fan.spread,
        (lo, hi),
        ortho,
        Framing::Box,
        (width, height),
    )
    .map_err(render)?;
    let mut img = RgbaImage::new(width, height, [255, 255, 255, 255]).map_err(render)?;
    draw_box_edges(&mut img, &cam, bounds.0, bounds.1, [150, 150, 150, 255]);
    draw_paths(&mut img, &cam, paths, [200, 30, 30, 255]);
    Ok(img)
}
