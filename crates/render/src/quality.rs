//! McPhail's quality view (thesis §5.5.5, Algorithm 5.1): a source volume `S` and a target
//! volume `T` pulled back onto it by a deformation, overlaid in one volume rendering so that
//! where they match shows green and where one is brighter shows red (source) or blue
//! (target).
//!
//! # The transfer function of Algorithm 5.1
//!
//! At every sample both volumes are windowed to intensities `i_S, i_T ∈ [0, 1]`: `S` at the
//! sample point `x`, `T` at `map(x)` (the map is a pull-back from the source's space into the
//! target's, sampled on a coarse grid as in [`DeformedView`]; this is `f⁻¹(T)` compared with
//! `S` in the thesis' notation). Where either is empty (at or below
//! [`QualityOptions::threshold`]) the sample is transparent. Otherwise, with `γ = min(i_S,
//! i_T)`:
//!
//! * colour `(i_S − γ, γ, i_T − γ)`: green where the two agree, red where the source is
//!   brighter, blue where the target is;
//! * opacity growing linearly with the difference: the absorption per unit distance is
//!   [`QualityOptions::difference_opacity`]` · |i_S − i_T|`, so mismatches stand out and hide
//!   what is behind them;
//! * matched material glows without hiding anything: an emission of
//!   [`QualityOptions::emission`] per unit distance, which the thesis' additive blending of
//!   the green channel amounts to.
//!
//! The function is symmetric: swapping the volumes swaps red and blue. Samples are composited
//! front to back as in [`DvrRenderer`](crate::DvrRenderer) (`C += T·(α + ε)·c`, `T ← T(1 − α)`
//! with both opacities corrected for the step), unlit, with early termination, and with grid
//! cells culled where either volume is empty.

use std::sync::atomic::{AtomicU8, Ordering};

use glam::Vec3;

use crate::camera::Camera;
use crate::deformed::DeformedView;
use crate::dvr::{DvrVolume, MIN_TRANSMITTANCE, RayResult};
use crate::error::RenderError;
use crate::image::RgbaImage;
use crate::shading::{linear_to_srgb8_fast, srgb8_to_linear};
use crate::transfer::corrected_opacity;
use crate::window::{AUTO_WINDOW_PERCENTILES, Window};

/// Unit distances across the source's box diagonal when [`QualityOptions::unit_distance`] is
/// `None`: a 256-unit diagonal, about 1.4 mm for a head CT (a 350 mm diagonal), the scale the
/// default opacities were chosen at.
pub const QUALITY_UNITS_ACROSS: f64 = 256.0;

/// Options of [`render_quality`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QualityOptions {
    /// Step between samples, world units; `None`: half the source's smallest voxel spacing.
    pub step: Option<f64>,
    /// Window of the source's values; `None`: its 0.5–99.5 percentiles
    /// ([`AUTO_WINDOW_PERCENTILES`]).
    pub source_window: Option<Window>,
    /// Window of the target's values; `None`: its 0.5–99.5 percentiles.
    pub target_window: Option<Window>,
    /// Windowed intensity regarded as empty (the thesis' `i ≠ 0`), in `[0, 1)`.
    pub threshold: f64,
    /// Absorption per unit distance per unit of intensity difference.
    pub difference_opacity: f64,
    /// Emission per unit distance of matched material.
    pub emission: f64,
    /// Distance the two opacities above refer to, world units; `None`: the diagonal of the
    /// source's box over [`QUALITY_UNITS_ACROSS`], so the picture does not depend on the
    /// volume's physical size (about 1.4 mm for a head CT).
    pub unit_distance: Option<f64>,
    /// Colour behind the volumes (straight alpha, 8-bit sRGB).
    pub background: [u8; 4],
    /// Stop rays once opaque.
    pub early_termination: bool,
    /// Skip grid cells where either volume is empty.
    pub skip_empty_space: bool,
}

impl Default for QualityOptions {
    /// Automatic windows, threshold 0.05, absorption 0.5 per unit distance per unit
    /// difference, emission 0.01 per unit distance, the unit distance from the volume's size,
    /// on black.
    fn default() -> Self {
        Self {
            step: None,
            source_window: None,
            target_window: None,
            threshold: 0.05,
            difference_opacity: 0.5,
            emission: 0.01,
            unit_distance: None,
            background: [0, 0, 0, 255],
            early_termination: true,
            skip_empty_space: true,
        }
    }
}

/// `code ↦ clamp(a·code + b, 0, 1)`: a window applied to a volume's codes.
#[derive(Debug, Clone, Copy)]
struct CodeWindow {
    a: f32,
    b: f32,
    /// Largest code at or below the threshold (codes above can be non-empty).
    empty_up_to: f32,
}

impl CodeWindow {
    fn new(
        volume: &DvrVolume,
        window: Option<Window>,
        threshold: f64,
    ) -> Result<Self, RenderError> {
        let w = match window {
            Some(w) => w,
            None => {
                let (lo, hi) = AUTO_WINDOW_PERCENTILES;
                let (a, b) = volume.percentiles(lo, hi)?;
                Window::from_range(a, b.max(a))?
            }
        };
        let width = w.width().max(f64::MIN_POSITIVE);
        // value = lo + code·step; i = (value − lower) / width.
        let a = volume.value_of_code(1.0) - volume.value_of_code(0.0);
        let b = volume.value_of_code(0.0) - w.lower();
        let empty_up_to = (w.lower() + threshold * width - volume.value_of_code(0.0)) / a;
        Ok(Self {
            a: (a / width) as f32,
            b: (b / width) as f32,
            empty_up_to: empty_up_to as f32,
        })
    }

    #[inline(always)]
    fn apply(&self, code: f32) -> f32 {
        (code * self.a + self.b).clamp(0.0, 1.0)
    }
}

/// The quality view of `source` and `target` through `view`, a pull-back from the source's
/// space into `target` whose grid spans the region to show (usually
/// [`DeformedView::from_map_over`] with the source's geometry), as `camera` sees it (see the
/// [module docs](self)).
///
/// # Errors
/// [`RenderError::InvalidArgument`] when `view` was made for another target, an option is out
/// of range, or a volume has no finite value for its automatic window;
/// [`RenderError::Size`] for an oversized picture.
pub fn render_quality(
    source: &DvrVolume,
    target: &DvrVolume,
    view: &DeformedView,
    camera: &Camera,
    options: &QualityOptions,
) -> Result<RgbaImage, RenderError> {
    view.check_volume(target)?;
    let o = options;
    let positive = |x: f64| x > 0.0 && x.is_finite();
    if !((0.0..1.0).contains(&o.threshold)
        && o.difference_opacity >= 0.0
        && o.difference_opacity.is_finite()
        && (0.0..=1.0).contains(&o.emission)
        && o.unit_distance.is_none_or(positive))
    {
        return Err(RenderError::invalid(format!(
            "quality view: threshold {} must be in [0, 1), difference opacity {} finite and ≥ 0, \
             emission {} in [0, 1], unit distance {:?} positive",
            o.threshold, o.difference_opacity, o.emission, o.unit_distance
        )));
    }
    let unit_distance = o.unit_distance.unwrap_or_else(|| {
        let (lo, hi) = source.geometry().physical_bounds();
        (hi - lo).length().max(f64::MIN_POSITIVE) / QUALITY_UNITS_ACROSS
    });
    let spacing = source.geometry().spacing;
    let step = o
        .step
        .unwrap_or(0.5 * spacing.x.min(spacing.y).min(spacing.z));
    if !positive(step) {
        return Err(RenderError::invalid(format!(
            "sampling step {step} must be finite and positive"
        )));
    }
    let ws = CodeWindow::new(source, o.source_window, o.threshold)?;
    let wt = CodeWindow::new(target, o.target_window, o.threshold)?;
    let emission = corrected_opacity(o.emission, step, unit_distance) as f32;
    let (w, h) = (camera.width(), camera.height());
    let mut img = RgbaImage::new(w, h, [0; 4])?;
    let bg = o.background;
    let bg_alpha = f32::from(bg[3]) / 255.0;
    let bg_lin = [0, 1, 2].map(|c| srgb8_to_linear(bg[c]) as f32 * bg_alpha);
    let memo: Vec<AtomicU8> = view.visibility_memo();
    let cell_kept = |n: usize| -> bool {
        if !o.skip_empty_space {
            return true;
        }
        match memo[n].load(Ordering::Relaxed) {
            1 => return true,
            2 => return false,
            _ => {}
        }
        let (tlo, thi) = view.cell_box(n);
        let target_full = target
            .octree()
            .range_over(tlo.to_array(), thi.to_array())
            .is_some_and(|(_, mx)| f32::from(mx) > wt.empty_up_to);
        let corners = view
            .cell_world_corners(n)
            .map(|p| source.index_of(p).as_vec3());
        let slo = corners.iter().fold(Vec3::INFINITY, |a, &b| a.min(b));
        let shi = corners.iter().fold(Vec3::NEG_INFINITY, |a, &b| a.max(b));
        let source_full = source
            .octree()
            .range_over(slo.to_array(), shi.to_array())
            .is_some_and(|(_, mx)| f32::from(mx) > ws.empty_up_to);
        let keep = target_full && source_full;
        memo[n].store(if keep { 1 } else { 2 }, Ordering::Relaxed);
        keep
    };
    let (s_hi, t_hi) = (source.index_box(), target.index_box());
    let inside = |u: Vec3, hi: Vec3| u.cmpge(Vec3::ZERO).all() && u.cmple(hi).all();
    let step = step as f32;
    let cast = |x: u32, y: u32| -> RayResult {
        let ray = camera.ray(x, y);
        let (go, gd, ghi) = view.ray_in_grid(&ray);
        let Some((t0, t1)) = crate::dvr::slab(go, gd, Vec3::ZERO, ghi) else {
            return RayResult::EMPTY;
        };
        let t0 = t0.max(0.0);
        if t0 >= t1 {
            return RayResult::EMPTY;
        }
        let so = source.index_of(ray.origin).as_vec3();
        let sd = (source.index_of(ray.origin + ray.dir) - source.index_of(ray.origin)).as_vec3();
        let mut color = Vec3::ZERO;
        let mut trans = 1.0f32;
        view.walk((go, gd), (t0, t1), step, cell_kept, |_, ut, t, _| {
            let us = so + sd * t;
            if !inside(ut, t_hi) || !inside(us, s_hi) {
                return false;
            }
            let is = ws.apply(source.sample(us));
            let it = wt.apply(target.sample(ut));
            let th = o.threshold as f32;
            if is <= th || it <= th {
                return false;
            }
            let g = is.min(it);
            let c = Vec3::new(is - g, g, it - g);
            let absorb = ((o.difference_opacity as f32) * (is - it).abs()).min(1.0);
            let a = corrected_opacity(f64::from(absorb), f64::from(step), unit_distance) as f32;
            color += c * (trans * (a + emission).min(1.0));
            trans *= 1.0 - a;
            o.early_termination && trans < MIN_TRANSMITTANCE
        });
        RayResult {
            color: color.min(Vec3::ONE).to_array(),
            alpha: 1.0 - trans,
        }
    };
    use rayon::prelude::*;
    img.pixels_mut()
        .par_chunks_mut(w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, px) in row.iter_mut().enumerate() {
                let r = cast(x as u32, y as u32);
                let t = 1.0 - r.alpha;
                // Emitted light needs some coverage to show on a transparent background.
                let glow = r.color.iter().fold(0.0f32, |m, &c| m.max(c));
                let a = (r.alpha + t * bg_alpha).max(glow);
                *px = if a <= 0.0 {
                    [0; 4]
                } else {
                    let ch = |k: usize| linear_to_srgb8_fast((r.color[k] + t * bg_lin[k]) / a);
                    [ch(0), ch(1), ch(2), (a.min(1.0) * 255.0).round() as u8]
                };
            }
        });
    Ok(img)
}
