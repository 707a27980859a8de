//! Volume rendering of an attribute along rays through a trivariate volume (Martin & Cohen
//! §5.2).
//!
//! # Algorithm
//!
//! 1. The ray's boundary hits come from [`RayTracer::intersect`]. The ray **enters** at the
//!    first hit `t_h` for which the point a little further on, `t_h + ε` with
//!    `ε = ENTRY_PROBE × diagonal`, lies in the solid ([`RayTracer::locate`]); a ray whose
//!    origin is inside starts at `t = 0`.
//! 2. Samples are taken at `t_k = t_entry + k·Δt`; the parameters of each sample are tracked
//!    from the previous ones by the Newton iteration of eq. 9 ([`RayTracer::track`]). Leaving
//!    the parametric domain is not leaving the volume: across the seam face of a revolved
//!    solid (`θ = 0 ≡ 2π`) or near its degenerate axis the tracked point is inverted afresh and
//!    the walk continues. A sample is outside only when inversion fails too.
//! 3. When the sample at `t_{k+1}` is outside, the exit `t_exit` is the last boundary hit in
//!    `(t_k, t_{k+1}]` (or, failing that, the result of bisection with inside tests). Sample
//!    `k` then stands for the segment `[t_k, t_exit]`; every other sample stands for `Δt`.
//!    After the exit the search resumes at step 1 beyond `t_exit` (non-convex volumes).
//! 4. The attribute value `a` at a sample goes through the [`TransferFunction`] to a colour
//!    `C` and an opacity per unit length `α₁`; the opacity of a segment of length `L` is
//!    `α = 1 − (1 − α₁)^L` (Beer–Lambert, so results do not depend on Δt for constant
//!    attributes). Compositing is the paper's front-to-back accumulation
//!    `C_acc += T·α·C`, `T ← T·(1 − α)` with `T` (the paper's `α_acc`) starting at 1; the walk
//!    stops early when `T` falls below [`RenderOptions::min_transmittance`].
//!
//! 5. With [`RenderOptions::shading`] set, the colour `C` of each sample is lit by the
//!    project's one shading model ([`Shading`]: Blinn–Phong, light fixed to the camera) with
//!    the normal `−∇ₓa`, the attribute's physical gradient (eq. 10: `JPᵀ ∇ₓa = ∇ᵤa`), so
//!    surfaces of rising attribute face the regions of lower value. [`VolumeRenderer::render_ray`]
//!    has no camera and is never shaded.
//!
//! [`SceneRenderer`] renders several volumes in one picture (§5.4): each ray is walked
//! through every volume as above and the samples of all of them are composited front to back
//! by depth.
//!
//! Colours are linear RGB throughout: transfer-function colours are linear, compositing is in
//! linear light, and [`VolumeRenderer::render_image`] encodes pixels to sRGB.
//! [`RayColor::opacity`] is `1 − T`; [`RayColor::color`] is `C_acc` (premultiplied by opacity).

use glam::DVec3;
use rayon::prelude::*;
use volmorph_render::shading::{Lighting, premultiplied_to_pixel, srgb8_to_linear};
use volmorph_render::{Camera, Colormap, RgbaImage, Shading};

use crate::eval::{EvalMethod, VolumeEvaluator};
use crate::optics::physical_gradient;
use crate::raytrace::{BoundaryHit, RayTracer, check_ray};
use crate::{AggregateVolume, TrivariateError};
use volmorph_spline::TensorBSpline;

/// Entry probe distance relative to the model diagonal (see the [module docs](self)).
pub const ENTRY_PROBE: f64 = 1e-6;

/// One control point of a [`TransferFunction`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransferPoint {
    /// Attribute value.
    pub value: f64,
    /// Linear RGB colour, each channel in `[0, 1]`.
    pub color: [f64; 3],
    /// Opacity of a slab of unit length (model units) in `[0, 1]`.
    pub opacity: f64,
}

/// A piecewise-linear transfer function: attribute value → (colour, opacity per unit length).
/// Between control points colour and opacity are interpolated linearly; below the first and
/// above the last point they are constant (clamped).
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    points: Vec<TransferPoint>,
}

impl TransferFunction {
    /// A transfer function through `points` (sorted here by value).
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for no points, non-finite values, repeated values,
    /// or colour channels or opacities outside `[0, 1]`.
    pub fn new(mut points: Vec<TransferPoint>) -> Result<Self, TrivariateError> {
        if points.is_empty() {
            return Err(TrivariateError::InvalidArgument(
                "transfer function needs at least one point".into(),
            ));
        }
        for p in &points {
            let unit = |x: f64| (0.0..=1.0).contains(&x);
            if !p.value.is_finite() || !p.color.iter().all(|&c| unit(c)) || !unit(p.opacity) {
                return Err(TrivariateError::InvalidArgument(format!(
                    "transfer point {p:?} needs a finite value and colour/opacity in [0, 1]"
                )));
            }
        }
        points.sort_by(|a, b| a.value.total_cmp(&b.value));
        if points.windows(2).any(|w| w[0].value == w[1].value) {
            return Err(TrivariateError::InvalidArgument(
                "transfer function values must be distinct".into(),
            ));
        }
        Ok(Self { points })
    }

    /// Parse `value:r,g,b,opacity;value:r,g,b,opacity;…` (channels in `[0, 1]`).
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] naming the malformed entry; as
    /// [`TransferFunction::new`].
    pub fn parse(text: &str) -> Result<Self, TrivariateError> {
        let mut pts = Vec::new();
        for entry in text.split(';').map(str::trim).filter(|s| !s.is_empty()) {
            let bad = || {
                TrivariateError::InvalidArgument(format!(
                    "transfer entry {entry:?} is not value:r,g,b,opacity"
                ))
            };
            let (v, rest) = entry.split_once(':').ok_or_else(bad)?;
            let nums: Vec<f64> = rest
                .split(',')
                .map(|s| s.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| bad())?;
            let [r, g, b, a] = nums[..] else {
                return Err(bad());
            };
            pts.push(TransferPoint {
                value: v.trim().parse().map_err(|_| bad())?,
                color: [r, g, b],
                opacity: a,
            });
        }
        Self::new(pts)
    }

    /// A ramp over `[lo, hi]`: colours from `colormap` at 9 points (decoded from sRGB to
    /// linear), opacity per unit length rising linearly from 0 at `lo` to `max_opacity` at
    /// `hi`.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] unless `lo < hi` are finite and
    /// `max_opacity ∈ [0, 1]`.
    pub fn ramp(
        lo: f64,
        hi: f64,
        colormap: Colormap,
        max_opacity: f64,
    ) -> Result<Self, TrivariateError> {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(TrivariateError::InvalidArgument(format!(
                "transfer ramp needs finite lo < hi, got [{lo}, {hi}]"
            )));
        }
        let pts = (0..9)
            .map(|i| {
                let f = f64::from(i) / 8.0;
                #[allow(clippy::cast_possible_truncation)]
                let c = colormap.map(f as f32);
                TransferPoint {
                    value: lo + f * (hi - lo),
                    color: c.map(srgb8_to_linear),
                    opacity: f * max_opacity,
                }
            })
            .collect();
        Self::new(pts)
    }

    /// Opacity per unit length that [`TransferFunction::for_attribute`] rises to.
    pub const DEFAULT_MAX_OPACITY: f64 = 0.9;

    /// The default transfer function of attribute `attribute` of `model`: a viridis
    /// [`ramp`](Self::ramp) over the attribute's range ([`AggregateVolume::attribute_range`])
    /// with opacity rising to [`DEFAULT_MAX_OPACITY`](Self::DEFAULT_MAX_OPACITY); a constant
    /// attribute gets a ramp one unit wide starting at its value.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for a missing attribute or a non-finite range.
    pub fn for_attribute(
        model: &AggregateVolume,
        attribute: &str,
    ) -> Result<Self, TrivariateError> {
        let (lo, mut hi) = model.attribute_range(attribute)?;
        if hi <= lo {
            hi = lo + 1.0;
        }
        Self::ramp(lo, hi, Colormap::Viridis, Self::DEFAULT_MAX_OPACITY)
    }

    /// The control points, sorted by value.
    #[must_use]
    pub fn points(&self) -> &[TransferPoint] {
        &self.points
    }

    /// Colour and opacity per unit length at attribute value `a` (NaN maps to the first
    /// point).
    #[must_use]
    pub fn lookup(&self, a: f64) -> ([f64; 3], f64) {
        let pts = &self.points;
        let (Some(first), Some(last)) = (pts.first(), pts.last()) else {
            return ([0.0; 3], 0.0);
        };
        if a.is_nan() || a <= first.value {
            return (first.color, first.opacity);
        }
        if a >= last.value {
            return (last.color, last.opacity);
        }
        let i = pts.partition_point(|p| p.value <= a).max(1);
        let (p, q) = (&pts[i - 1], &pts[i]);
        let f = (a - p.value) / (q.value - p.value);
        (
            std::array::from_fn(|c| p.color[c] + f * (q.color[c] - p.color[c])),
            p.opacity + f * (q.opacity - p.opacity),
        )
    }
}

/// Options of [`VolumeRenderer`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Step `Δt` along the ray, model units (> 0).
    pub step: f64,
    /// Component of the attribute that drives the transfer function.
    pub component: usize,
    /// Stop when the transmittance `T` falls below this (early termination).
    pub min_transmittance: f64,
    /// Most samples per ray (bounds the work of a degenerate input).
    pub max_samples: usize,
    /// Gradient shading of [`VolumeRenderer::render_image`] (see the [module docs](self));
    /// `None`: colours as the transfer function gives them.
    pub shading: Option<Shading>,
}

impl RenderOptions {
    /// Defaults for a model of diagonal `diagonal`: `Δt = diagonal/256`, component 0,
    /// `min_transmittance = 1/512`, 1 000 000 samples, no shading.
    #[must_use]
    pub fn for_diagonal(diagonal: f64) -> Self {
        Self {
            step: diagonal / 256.0,
            component: 0,
            min_transmittance: 1.0 / 512.0,
            max_samples: 1_000_000,
            shading: None,
        }
    }
}

/// Accumulated colour of one ray (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayColor {
    /// `C_acc`, premultiplied linear RGB.
    pub color: [f64; 3],
    /// `1 − T`.
    pub opacity: f64,
    /// Number of samples composited.
    pub samples: usize,
}

/// One sample of a walk: its depth along the ray (the start of the segment it stands for),
/// its (lit) linear colour and the opacity of its segment.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    t: f64,
    color: [f64; 3],
    alpha: f64,
}

/// The paper's front-to-back step: `C_acc += T·α·C`, `T ← T·(1 − α)`.
fn composite(out: &mut RayColor, trans: &mut f64, s: &Sample) {
    for (acc, ck) in out.color.iter_mut().zip(s.color) {
        *acc += *trans * s.alpha * ck;
    }
    *trans *= 1.0 - s.alpha;
    out.samples += 1;
}

/// Renders one attribute of an aggregate volume by the algorithm of the [module docs](self).
#[derive(Debug, Clone)]
pub struct VolumeRenderer<'a> {
    tracer: &'a RayTracer,
    attribute: &'a TensorBSpline<3>,
    transfer: TransferFunction,
    options: RenderOptions,
}

/// Where a walk enters the solid.
pub(crate) struct Entry {
    pub t: f64,
    pub params: [f64; 3],
    pub hit: Option<BoundaryHit>,
}

/// The first entry of the ray into the solid at or after `after` (see the module docs).
pub(crate) fn find_entry(
    tracer: &RayTracer,
    origin: [f64; 3],
    d: [f64; 3],
    hits: &[BoundaryHit],
    after: f64,
) -> Result<Option<Entry>, TrivariateError> {
    let at = |t: f64| std::array::from_fn(|c| origin[c] + t * d[c]);
    let eps = ENTRY_PROBE * tracer.diagonal();
    if after <= 0.0
        && let Some(u) = tracer.locate(origin, None)?
    {
        // The origin is inside unless it sits on the boundary with the ray leaving.
        if tracer.locate(at(eps), Some(u))?.is_some() {
            return Ok(Some(Entry {
                t: 0.0,
                params: u,
                hit: None,
            }));
        }
    }
    for h in hits.iter().filter(|h| h.t > after) {
        if tracer.locate(at(h.t + eps), Some(h.params))?.is_some() {
            return Ok(Some(Entry {
                t: h.t,
                params: h.params,
                hit: Some(*h),
            }));
        }
    }
    Ok(None)
}

/// The exit between an inside sample at `t_in` (parameters `u_in`) and an outside one at
/// `t_out`: the last hit in `(t_in, t_out]`, else bisection with inside tests.
pub(crate) fn find_exit(
    tracer: &RayTracer,
    origin: [f64; 3],
    d: [f64; 3],
    hits: &[BoundaryHit],
    t_in: f64,
    u_in: [f64; 3],
    t_out: f64,
) -> Result<(f64, Option<BoundaryHit>), TrivariateError> {
    if let Some(h) = hits.iter().rev().find(|h| h.t > t_in && h.t <= t_out) {
        return Ok((h.t, Some(*h)));
    }
    let (mut lo, mut hi, mut u) = (t_in, t_out, u_in);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        let p = std::array::from_fn(|c| origin[c] + mid * d[c]);
        match tracer.locate(p, Some(u))? {
            Some(v) => {
                lo = mid;
                u = v;
            }
            None => hi = mid,
        }
    }
    Ok((0.5 * (lo + hi), None))
}

impl<'a> VolumeRenderer<'a> {
    /// A renderer of attribute `attribute` of `volume`, whose geometry `tracer` was built
    /// from.
    ///
    /// # Errors
    /// [`TrivariateError::UnknownAttribute`]; [`TrivariateError::InvalidArgument`] for a
    /// component beyond the attribute's dimension, a non-positive or non-finite step, a
    /// transmittance threshold outside `[0, 1)` or zero `max_samples`.
    pub fn new(
        volume: &'a AggregateVolume,
        tracer: &'a RayTracer,
        attribute: &str,
        transfer: TransferFunction,
        options: RenderOptions,
    ) -> Result<Self, TrivariateError> {
        let spline = volume
            .attribute(attribute)
            .ok_or_else(|| TrivariateError::UnknownAttribute(attribute.to_owned()))?;
        if options.component >= spline.dim() {
            return Err(TrivariateError::InvalidArgument(format!(
                "component {} of attribute {attribute:?} (dimension {})",
                options.component,
                spline.dim()
            )));
        }
        if !(options.step.is_finite() && options.step > 0.0) {
            return Err(TrivariateError::InvalidArgument(format!(
                "render step {} must be finite and > 0",
                volmorph_io::Num(options.step)
            )));
        }
        // A ray takes at most `max_samples` steps: a shorter step could not cross the model
        // and would spend the whole sample budget on every ray.
        let min_step = tracer.diagonal() / options.max_samples.max(1) as f64;
        if options.step < min_step {
            return Err(TrivariateError::InvalidArgument(format!(
                "render step {} is below {} (the model's diagonal / {} samples per ray): a ray \
                 could not cross the model",
                volmorph_io::Num(options.step),
                volmorph_io::Num(min_step),
                options.max_samples
            )));
        }
        if !(0.0..1.0).contains(&options.min_transmittance) || options.max_samples == 0 {
            return Err(TrivariateError::InvalidArgument(format!(
                "min_transmittance {} must be in [0, 1) and max_samples > 0",
                options.min_transmittance
            )));
        }
        Ok(Self {
            tracer,
            attribute: spline,
            transfer,
            options,
        })
    }

    /// Composite the ray `origin + t·dir` (see the [module docs](self)), unshaded.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for a non-finite origin or a zero or non-finite
    /// direction; evaluation errors otherwise.
    pub fn render_ray(&self, origin: [f64; 3], dir: [f64; 3]) -> Result<RayColor, TrivariateError> {
        self.walk(origin, dir, None)
    }

    /// Composite the ray `origin + t·dir`, lit by `lighting` when given.
    fn walk(
        &self,
        origin: [f64; 3],
        dir: [f64; 3],
        lighting: Option<&Lighting>,
    ) -> Result<RayColor, TrivariateError> {
        let mut out = RayColor {
            color: [0.0; 3],
            opacity: 0.0,
            samples: 0,
        };
        let mut trans = 1.0;
        let min = self.options.min_transmittance;
        self.samples(origin, dir, lighting, &mut |s| {
            composite(&mut out, &mut trans, s);
            trans >= min
        })?;
        out.opacity = 1.0 - trans;
        Ok(out)
    }

    /// Walk the ray `origin + t·dir` and hand every sample, front to back, to `sink` (colour
    /// lit by `lighting` when given) until `sink` returns `false`, the volume's own
    /// transmittance falls below [`RenderOptions::min_transmittance`] (after that sample) or
    /// [`RenderOptions::max_samples`] are taken.
    fn samples(
        &self,
        origin: [f64; 3],
        dir: [f64; 3],
        lighting: Option<&Lighting>,
        sink: &mut dyn FnMut(&Sample) -> bool,
    ) -> Result<(), TrivariateError> {
        let d = check_ray(origin, dir)?;
        let geometry = VolumeEvaluator::new(self.tracer.geometry());
        let mut point = [0.0; 3];
        let mut jac = [0.0; 9];
        let hits = self.tracer.intersect(origin, d)?;
        let at = |t: f64| -> [f64; 3] { std::array::from_fn(|c| origin[c] + t * d[c]) };
        let ev = VolumeEvaluator::new(self.attribute);
        let dim = self.attribute.dim();
        let mut val = [0.0; 16];
        let mut grad = [0.0; 48];
        let mut big_val = vec![0.0; if dim > 16 { dim } else { 0 }];
        let mut big_grad = vec![0.0; if dim > 16 { 3 * dim } else { 0 }];
        let mut count = 0usize;
        let mut trans = 1.0;
        let mut after = 0.0;
        let step = self.options.step;
        'walk: while let Some(entry) = find_entry(self.tracer, origin, d, &hits, after)? {
            let mut t = entry.t;
            let mut u = entry.params;
            loop {
                if count >= self.options.max_samples {
                    break 'walk;
                }
                let next_t = t + step;
                let next = self.tracer.track(at(next_t), u)?;
                let (len, exit) = match &next {
                    Some(_) => (step, None),
                    None => {
                        let (te, _) = find_exit(self.tracer, origin, d, &hits, t, u, next_t)?;
                        (te - t, Some(te))
                    }
                };
                let a = if dim > 16 {
                    ev.eval_into(EvalMethod::default(), u, &mut big_val, &mut big_grad)?;
                    big_val[self.options.component]
                } else {
                    ev.eval_into(EvalMethod::default(), u, &mut val, &mut grad)?;
                    val[self.options.component]
                };
                let (mut c, a1) = self.transfer.lookup(a);
                let alpha = if a1 >= 1.0 {
                    if len > 0.0 { 1.0 } else { 0.0 }
                } else {
                    1.0 - (1.0 - a1).powf(len.max(0.0))
                };
                if let Some(light) = lighting
                    && alpha > 0.0
                {
                    let gu = std::array::from_fn(|ax| {
                        if dim > 16 {
                            big_grad[ax * dim + self.options.component]
                        } else {
                            grad[ax * dim + self.options.component]
                        }
                    });
                    geometry.eval_into(EvalMethod::default(), u, &mut point, &mut jac)?;
                    let n = -DVec3::from_array(physical_gradient(&jac, gu));
                    c = light.shade(c, n, -DVec3::from_array(d));
                }
                count += 1;
                trans *= 1.0 - alpha;
                if !sink(&Sample { t, color: c, alpha }) || trans < self.options.min_transmittance {
                    break 'walk;
                }
                match (next, exit) {
                    (Some(n), _) => {
                        t = next_t;
                        u = n.params;
                    }
                    (None, Some(te)) => {
                        after = te + self.options.step.min(ENTRY_PROBE * self.tracer.diagonal());
                        break;
                    }
                    (None, None) => break 'walk,
                }
            }
        }
        Ok(())
    }

    /// The lighting of `camera`'s view, when the options ask for shading.
    fn lighting(&self, camera: &Camera) -> Result<Option<Lighting>, TrivariateError> {
        match &self.options.shading {
            Some(s) => {
                Ok(Some(s.for_camera(camera).map_err(|e| {
                    TrivariateError::InvalidArgument(e.to_string())
                })?))
            }
            None => Ok(None),
        }
    }

    /// Render `camera`'s view: one ray per pixel centre, rows in parallel (rayon), shaded when
    /// [`RenderOptions::shading`] is set. Pixels are `C_acc` encoded to 8-bit sRGB with alpha
    /// `1 − T` (straight alpha: colour divided by opacity).
    ///
    /// # Errors
    /// The first ray's error; image allocation errors and invalid shading parameters as
    /// [`TrivariateError::InvalidArgument`].
    pub fn render_image(&self, camera: &Camera) -> Result<RgbaImage, TrivariateError> {
        self.render_image_with(camera, &volmorph_io::NoProgress)
    }

    /// [`VolumeRenderer::render_image`] reporting one step per image row to `progress` and
    /// stopping when it is cancelled.
    ///
    /// # Errors
    /// As [`VolumeRenderer::render_image`]; [`TrivariateError::Cancelled`] when `progress`
    /// asks to stop.
    pub fn render_image_with(
        &self,
        camera: &Camera,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<RgbaImage, TrivariateError> {
        let lighting = self.lighting(camera)?;
        let (w, h) = (camera.width(), camera.height());
        progress.start("volume rendering", u64::from(h));
        let mut img = RgbaImage::new(w, h, [0, 0, 0, 0])
            .map_err(|e| TrivariateError::InvalidArgument(e.to_string()))?;
        let width = w as usize;
        img.pixels_mut()
            .par_chunks_mut(width.max(1))
            .enumerate()
            .try_for_each(|(y, row)| -> Result<(), TrivariateError> {
                let y = u32::try_from(y).unwrap_or(u32::MAX);
                for (x, px) in row.iter_mut().enumerate() {
                    let x = u32::try_from(x).unwrap_or(u32::MAX);
                    let ray = camera.ray(x, y);
                    let c =
                        self.walk(ray.origin.to_array(), ray.dir.to_array(), lighting.as_ref())?;
                    *px = premultiplied_to_pixel(c.color, c.opacity);
                }
                progress.advance(1);
                Ok(progress.check()?)
            })?;
        Ok(img)
    }
}

/// Several volumes in one picture (§5.4's `TraceRay` over an environment of volumes), each
/// with its own model, attribute, transfer function and options.
///
/// Each ray is walked through every volume as [`VolumeRenderer`] walks it (entry, tracked
/// samples, exit, re-entry), and the samples of all volumes are composited front to back in
/// the order of their depth along the ray (a stable merge: equal depths keep the order of the
/// volumes). Where the volumes' intervals along the ray do not overlap this is exactly §5.4's
/// loop — the nearest volume's interval is composited, then the next volume hit beyond its
/// exit, and so on. Where intervals overlap (interpenetrating volumes) the samples interleave
/// by depth, which is what the line-of-sight integral over the union of the volumes asks for;
/// the paper's loop, restarting from the exit of the first volume, would skip the part of the
/// other volume that lies in front of that exit. Compositing stops when the transmittance
/// falls below the smallest [`RenderOptions::min_transmittance`] of the volumes; a ray that
/// meets only one volume gets exactly that volume's [`VolumeRenderer`] colour.
#[derive(Debug, Clone)]
pub struct SceneRenderer<'a> {
    parts: Vec<VolumeRenderer<'a>>,
    min_transmittance: f64,
}

impl<'a> SceneRenderer<'a> {
    /// A scene of `parts` (one renderer per volume).
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for an empty list.
    pub fn new(parts: Vec<VolumeRenderer<'a>>) -> Result<Self, TrivariateError> {
        let min_transmittance = parts
            .iter()
            .map(|p| p.options.min_transmittance)
            .reduce(f64::min)
            .ok_or_else(|| {
                TrivariateError::InvalidArgument("a scene needs at least one volume".into())
            })?;
        Ok(Self {
            parts,
            min_transmittance,
        })
    }

    /// The volumes' renderers.
    #[must_use]
    pub fn parts(&self) -> &[VolumeRenderer<'a>] {
        &self.parts
    }

    /// Smallest and largest corner of the union of the volumes' bounding boxes.
    #[must_use]
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.parts {
            let (a, b) = p.tracer.bounds();
            for c in 0..3 {
                lo[c] = lo[c].min(a[c]);
                hi[c] = hi[c].max(b[c]);
            }
        }
        (lo, hi)
    }

    /// Composite the ray `origin + t·dir` through every volume (unshaded).
    ///
    /// # Errors
    /// As [`VolumeRenderer::render_ray`].
    pub fn render_ray(&self, origin: [f64; 3], dir: [f64; 3]) -> Result<RayColor, TrivariateError> {
        let lights = vec![None; self.parts.len()];
        self.walk(origin, dir, &lights, &mut Vec::new())
    }

    fn walk(
        &self,
        origin: [f64; 3],
        dir: [f64; 3],
        lights: &[Option<Lighting>],
        buf: &mut Vec<(f64, usize, Sample)>,
    ) -> Result<RayColor, TrivariateError> {
        buf.clear();
        for (i, (p, light)) in self.parts.iter().zip(lights).enumerate() {
            p.samples(origin, dir, light.as_ref(), &mut |s| {
                buf.push((s.t, i, *s));
                true
            })?;
        }
        // Stable: equal depths keep the volumes' order (and each volume's own order).
        buf.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut out = RayColor {
            color: [0.0; 3],
            opacity: 0.0,
            samples: 0,
        };
        let mut trans = 1.0;
        for (_, _, s) in buf.iter() {
            composite(&mut out, &mut trans, s);
            if trans < self.min_transmittance {
                break;
            }
        }
        out.opacity = 1.0 - trans;
        Ok(out)
    }

    /// Render `camera`'s view (as [`VolumeRenderer::render_image`], each volume shaded by its
    /// own options).
    ///
    /// # Errors
    /// As [`VolumeRenderer::render_image`].
    pub fn render_image(&self, camera: &Camera) -> Result<RgbaImage, TrivariateError> {
        self.render_image_with(camera, &volmorph_io::NoProgress)
    }

    /// [`SceneRenderer::render_image`] reporting one step per image row to `progress` and
    /// stopping when it is cancelled.
    ///
    /// # Errors
    /// As [`VolumeRenderer::render_image_with`].
    pub fn render_image_with(
        &self,
        camera: &Camera,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<RgbaImage, TrivariateError> {
        let lights = self
            .parts
            .iter()
            .map(|p| p.lighting(camera))
            .collect::<Result<Vec<_>, _>>()?;
        let (w, h) = (camera.width(), camera.height());
        progress.start("volume rendering", u64::from(h));
        let mut img = RgbaImage::new(w, h, [0, 0, 0, 0])
            .map_err(|e| TrivariateError::InvalidArgument(e.to_string()))?;
        let width = w as usize;
        img.pixels_mut()
            .par_chunks_mut(width.max(1))
            .enumerate()
            .try_for_each(|(y, row)| -> Result<(), TrivariateError> {
                let y = u32::try_from(y).unwrap_or(u32::MAX);
                let mut buf = Vec::new();
                for (x, px) in row.iter_mut().enumerate() {
                    let x = u32::try_from(x).unwrap_or(u32::MAX);
                    let ray = camera.ray(x, y);
                    let c =
                        self.walk(ray.origin.to_array(), ray.dir.to_array(), &lights, &mut buf)?;
                    *px = premultiplied_to_pixel(c.color, c.opacity);
                }
                progress.advance(1);
                Ok(progress.check()?)
            })?;
        Ok(img)
    }
}
