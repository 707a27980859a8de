//! Quality of a registration (McPhail's thesis §5.5.3–5.5.5) and the numbers users compare:
//! overlays, local sub-cube comparison, global metrics, Jacobian fold reports, target
//! registration error.
//!
//! # Algorithm 5.1
//!
//! The thesis' transfer function compares the fixed image `S` with the warped moving image
//! `f⁻¹(T)` at one point: with both intensities normalised to `[0, 1]` (a window), where both
//! are non-zero, `γ = min(i_S, i_T)` and the colour is `(i_S − γ, γ, i_T − γ)` — green where the
//! two agree, red where the fixed image is brighter, blue where the moving one is — and the
//! opacity grows linearly with the magnitude of the difference, so mismatches stand out in a
//! volume rendering (here `α = alpha_floor + alpha_gain·|i_S − i_T|`, clamped to 1). It is
//! symmetric in the two images up to swapping red and blue. Where either intensity is zero the
//! colour is transparent black. [`overlay_colour`] is the function, [`overlay_volume`] its
//! per-voxel colours and opacities, [`slice_overlay`] an axis-aligned section as a picture
//! (opaque colours on black), [`render_overlay`] the volume rendering the thesis shows.
//!
//! # Other checks
//!
//! * [`subcube_comparison`] — the sub-cubes around a handle pair (§5.5.3): the fixed cube around
//!   `p`, the moving cube resampled through the map, and the moving cube around `q` shifted only,
//!   with their NCC.
//! * [`crate::metrics::compare`] before and after — NCC, mean squared difference, MI.
//! * [`jacobian_report`] — the Jacobian determinant map and fold report of **any** map (closed
//!   form where the map has one, central differences otherwise).
//! * [`tre`] — target registration error at landmark pairs: `|φ(x_i) − y_i|`, with mean,
//!   standard deviation, 95th percentile and maximum in mm; landmarks from Slicer `.fcsv`,
//!   physical text or DIR-Lab voxel text ([`read_landmarks`]).

use std::path::Path;

use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;
use volmorph_deform::SpaceMap;
use volmorph_render::{Aabb, Camera, Framing, Projection, Ray, RgbaImage};
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::jacobian::{FoldingReport, jacobian_determinant};

use crate::RegisterError;
use crate::image::{LinearImage, same_grid};

/// Options of the overlays.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OverlayOptions {
    /// Intensities `window[0] → 0` and `window[1] → 1` (clamped).
    pub window: [f64; 2],
    /// Opacity of a perfect match.
    pub alpha_floor: f64,
    /// Opacity per unit of normalised difference.
    pub alpha_gain: f64,
}

impl OverlayOptions {
    /// Options with the given window, opacity 0.05 at a match and 1 at a difference of 0.5.
    #[must_use]
    pub fn with_window(lo: f64, hi: f64) -> Self {
        Self {
            window: [lo, hi],
            alpha_floor: 0.05,
            alpha_gain: 1.9,
        }
    }

    /// A window from the 1st to the 99th percentile of `v`'s finite values.
    #[must_use]
    pub fn for_image(v: &Volume<f32>) -> Self {
        let mut s: Vec<f32> = v.data().iter().copied().filter(|x| x.is_finite()).collect();
        if s.is_empty() {
            return Self::with_window(0.0, 1.0);
        }
        let n = s.len();
        let lo_i = n / 100;
        let hi_i = (n * 99 / 100).min(n - 1);
        s.select_nth_unstable_by(lo_i, f32::total_cmp);
        let lo = f64::from(s[lo_i]);
        s.select_nth_unstable_by(hi_i, f32::total_cmp);
        let hi = f64::from(s[hi_i]);
        Self::with_window(lo, if hi > lo { hi } else { lo + 1.0 })
    }

    fn normalise(&self, v: f64) -> f64 {
        ((v - self.window[0]) / (self.window[1] - self.window[0])).clamp(0.0, 1.0)
    }
}

/// Algorithm 5.1 for one pair of (raw) intensities: RGBA in `[0, 1]` (see the
/// [module docs](self)).
#[must_use]
pub fn overlay_colour(fixed: f64, moving: f64, o: &OverlayOptions) -> [f64; 4] {
    let (s, t) = (o.normalise(fixed), o.normalise(moving));
    if s == 0.0 || t == 0.0 || !s.is_finite() || !t.is_finite() {
        return [0.0; 4];
    }
    let g = s.min(t);
    let a = (o.alpha_floor + o.alpha_gain * (s - t).abs()).clamp(0.0, 1.0);
    [s - g, g, t - g, a]
}

fn to_u8(c: [f64; 4]) -> [u8; 4] {
    c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
}

/// Algorithm 5.1 at every voxel of two images on one grid, as 8-bit RGBA (x fastest).
///
/// # Errors
/// [`RegisterError::Mismatch`] for different grids.
pub fn overlay_volume(
    fixed: &Volume<f32>,
    warped: &Volume<f32>,
    o: &OverlayOptions,
) -> Result<Vec<[u8; 4]>, RegisterError> {
    same_grid(fixed.geometry(), warped.geometry(), "warped image")?;
    Ok(fixed
        .data()
        .par_iter()
        .zip(warped.data().par_iter())
        .map(|(&a, &b)| to_u8(overlay_colour(f64::from(a), f64::from(b), o)))
        .collect())
}

/// An axis-aligned section (`axis` 0 = x, 1 = y, 2 = z; `index` along it) of the overlay as a
/// picture: opaque Algorithm 5.1 colours on black, laid out as
/// [`volmorph_volume::slice`] lays out slices (first in-plane index to the right, second up).
///
/// # Errors
/// [`RegisterError::Mismatch`] for different grids or an index out of range,
/// [`RegisterError::Render`] for an impossible picture size.
pub fn slice_overlay(
    fixed: &Volume<f32>,
    warped: &Volume<f32>,
    axis: usize,
    index: usize,
    o: &OverlayOptions,
) -> Result<RgbaImage, RegisterError> {
    same_grid(fixed.geometry(), warped.geometry(), "warped image")?;
    let dims = fixed.dims();
    if axis > 2 || index >= dims[axis] {
        return Err(RegisterError::Mismatch(format!(
            "section {index} along axis {axis} outside dims {dims:?}"
        )));
    }
    let (a, b) = match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let (w, h) = (dims[a], dims[b]);
    let g = fixed.geometry();
    Ok(RgbaImage::from_fn(w as u32, h as u32, |x, y| {
        let mut idx = [0usize; 3];
        idx[axis] = index;
        idx[a] = x as usize;
        idx[b] = h - 1 - y as usize;
        let n = g.offset(idx[0], idx[1], idx[2]);
        let c = overlay_colour(f64::from(fixed.data()[n]), f64::from(warped.data()[n]), o);
        to_u8([c[0], c[1], c[2], 1.0])
    })?)
}

/// Samples per voxel length along a ray of [`render_overlay`].
pub const SAMPLES_PER_VOXEL: f64 = 2.0;
/// Accumulated opacity at which a ray of [`render_overlay`] stops: what lies behind changes the
/// pixel by less than one 8-bit level.
const OPAQUE: f64 = 1.0 - 1.0 / 512.0;

/// Algorithm 5.1 as a volume rendering: every ray of `camera` is marched through the voxel-
/// centre box of the images at [`SAMPLES_PER_VOXEL`] samples per voxel, both images are
/// sampled trilinearly, [`overlay_colour`] gives colour and opacity per voxel length
/// (corrected to the step, `1 − (1 − α)^Δ`), and the samples are composited front to back
/// (emission–absorption) over black. Mismatches (red, blue) are opaque, matches (green) faint,
/// so the picture shows where and how the registration fails.
///
/// # Errors
/// [`RegisterError::Mismatch`] for images on different grids, [`RegisterError::Render`] for an
/// impossible picture size.
pub fn render_overlay(
    fixed: &Volume<f32>,
    warped: &Volume<f32>,
    camera: &Camera,
    o: &OverlayOptions,
) -> Result<RgbaImage, RegisterError> {
    same_grid(fixed.geometry(), warped.geometry(), "warped image")?;
    let (fi, wi) = (LinearImage::new(fixed), LinearImage::new(warped));
    // The box of voxel centres in index space, where the rays are marched.
    let bounds = Aabb::new(
        DVec3::ZERO,
        DVec3::from_array(fixed.dims().map(|n| (n - 1) as f64)),
    )?;
    let (w, h) = (camera.width(), camera.height());
    let pixels: Vec<[u8; 4]> = (0..u64::from(w) * u64::from(h))
        .into_par_iter()
        .map(|n| {
            let ray = camera.ray((n % u64::from(w)) as u32, (n / u64::from(w)) as u32);
            let start = fi.index_of(ray.origin);
            let Ok(ray) = Ray::new(start, fi.index_of(ray.origin + ray.dir) - start) else {
                return [0, 0, 0, 255];
            };
            let Some((t0, t1)) = bounds.intersect(&ray) else {
                return [0, 0, 0, 255];
            };
            // t counts voxel lengths along the ray (unit direction in index space).
            let dt = 1.0 / SAMPLES_PER_VOXEL;
            let (mut rgb, mut acc) = (DVec3::ZERO, 0.0);
            let mut t = t0 + 0.5 * dt;
            while t <= t1 && acc < OPAQUE {
                let idx = ray.at(t);
                if let (Some(a), Some(b)) = (fi.value_at_index(idx), wi.value_at_index(idx)) {
                    let c = overlay_colour(f64::from(a), f64::from(b), o);
                    let alpha = 1.0 - (1.0 - c[3]).powf(1.0 / SAMPLES_PER_VOXEL);
                    rgb += (1.0 - acc) * alpha * DVec3::new(c[0], c[1], c[2]);
                    acc += (1.0 - acc) * alpha;
                }
                t += dt;
            }
            to_u8([rgb.x, rgb.y, rgb.z, 1.0])
        })
        .collect();
    Ok(RgbaImage::from_pixels(w, h, pixels)?)
}

/// An orthographic camera looking at the physical box of `g` from the front of a patient in
/// LPS coordinates (from −y towards +y, superior up), `width` pixels wide.
///
/// # Errors
/// [`RegisterError::Render`] for a degenerate box or picture size.
pub fn anterior_camera(g: &Geometry, width: u32) -> Result<Camera, RegisterError> {
    let (lo, hi) = g.physical_bounds();
    let size = hi - lo;
    let centre = 0.5 * (lo + hi);
    let height = ((f64::from(width) * size.z / size.x.max(1e-9)).round() as u32).clamp(16, 4096);
    let cam = Camera::look_at(
        centre - DVec3::Y * (size.length() + 1.0),
        centre,
        DVec3::Z,
        Projection::Orthographic {
            view_height: size.z.max(1e-9),
        },
        width,
        height,
    )?;
    Ok(cam.frame(lo, hi, Framing::Box)?)
}

/// The sub-cubes around one handle pair (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct SubcubeComparison {
    /// Fixed image around `p`.
    pub fixed: Volume<f32>,
    /// Moving image through the map (`T(φ(x))` for `x` in the cube).
    pub mapped: Volume<f32>,
    /// Moving image around `q`, shifted by `q − p` only.
    pub shifted: Volume<f32>,
    /// NCC of fixed and mapped cubes.
    pub ncc_mapped: f64,
    /// NCC of fixed and shifted cubes.
    pub ncc_shifted: f64,
    /// Algorithm 5.1 colours of fixed against mapped (x fastest).
    pub overlay: Vec<[u8; 4]>,
}

/// Compare the sub-cubes of half-size `half` voxels (on the fixed grid's axes) around the handle
/// pair `p → q` (see the [module docs](self)); samples outside an image are NaN and left out of
/// the NCC.
///
/// # Errors
/// [`RegisterError::TooLittle`] if the cubes share fewer than 8 valid samples.
pub fn subcube_comparison(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    map: &dyn SpaceMap,
    p: DVec3,
    q: DVec3,
    half: usize,
    o: &OverlayOptions,
) -> Result<SubcubeComparison, RegisterError> {
    let n = 2 * half + 1;
    let step = fixed.geometry().index_to_physical_matrix();
    let corner = p - step * DVec3::splat(half as f64);
    let geom = Geometry {
        dims: [n, n, n],
        spacing: fixed.geometry().spacing,
        origin: corner,
        direction: fixed.geometry().direction,
    };
    let (fi, mi) = (LinearImage::new(fixed), LinearImage::new(moving));
    let mut a = Vec::with_capacity(n * n * n);
    let mut b = Vec::with_capacity(n * n * n);
    let mut c = Vec::with_capacity(n * n * n);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let x = geom.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                a.push(fi.value(x).unwrap_or(f32::NAN));
                b.push(mi.value(map.apply(x)).unwrap_or(f32::NAN));
                c.push(mi.value(x + (q - p)).unwrap_or(f32::NAN));
            }
        }
    }
    let (fa, fb, fc) = (
        Volume::new(geom, a)?,
        Volume::new(geom, b)?,
        Volume::new(geom, c)?,
    );
    let ncc_mapped = crate::metrics::compare(&fa, &fb, None)?.ncc;
    let ncc_shifted = crate::metrics::compare(&fa, &fc, None)?.ncc;
    let overlay = overlay_volume(&fa, &fb, o)?;
    Ok(SubcubeComparison {
        fixed: fa,
        mapped: fb,
        shifted: fc,
        ncc_mapped,
        ncc_shifted,
        overlay,
    })
}

/// The Jacobian determinant map of `map` on `grid` and its fold report.
///
/// # Errors
/// [`RegisterError::Warp`] for an invalid grid or a failing map.
pub fn jacobian_report(
    map: &dyn SpaceMap,
    grid: &Geometry,
) -> Result<(Volume<f32>, FoldingReport), RegisterError> {
    let j = jacobian_determinant(map, grid)?;
    let r = FoldingReport::of(j.data());
    Ok((j, r))
}

/// Target registration error statistics, mm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TreStats {
    /// Landmark pairs.
    pub count: usize,
    /// Mean error.
    pub mean: f64,
    /// Standard deviation (population).
    pub sd: f64,
    /// 95th percentile (linear interpolation between order statistics).
    pub p95: f64,
    /// Largest error.
    pub max: f64,
    /// Error of every pair, in order.
    pub errors: Vec<f64>,
}

impl TreStats {
    /// Statistics of a list of errors.
    ///
    /// # Errors
    /// [`RegisterError::TooLittle`] for an empty list.
    pub fn of(errors: Vec<f64>) -> Result<Self, RegisterError> {
        if errors.is_empty() {
            return Err(RegisterError::TooLittle("no landmark pairs".into()));
        }
        let n = errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / n;
        let sd = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
        let mut s = errors.clone();
        s.sort_by(f64::total_cmp);
        let pos = 0.95 * (s.len() - 1) as f64;
        let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
        let p95 = s[lo] + (s[hi] - s[lo]) * (pos - lo as f64);
        Ok(Self {
            count: errors.len(),
            mean,
            sd,
            p95,
            max: s[s.len() - 1],
            errors,
        })
    }
}

impl std::fmt::Display for TreStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "TRE over {} landmarks: mean {:.2} mm, sd {:.2}, p95 {:.2}, max {:.2}",
            self.count, self.mean, self.sd, self.p95, self.max
        )
    }
}

/// TRE of `map` (fixed → moving) at landmark pairs `fixed[i] ↔ moving[i]`: `|φ(x_i) − y_i|`.
///
/// # Errors
/// [`RegisterError::Mismatch`] for lists of different lengths, [`RegisterError::TooLittle`] for
/// none.
pub fn tre(
    map: &dyn SpaceMap,
    fixed: &[DVec3],
    moving: &[DVec3],
) -> Result<TreStats, RegisterError> {
    if fixed.len() != moving.len() {
        return Err(RegisterError::Mismatch(format!(
            "{} fixed landmarks but {} moving ones",
            fixed.len(),
            moving.len()
        )));
    }
    TreStats::of(
        fixed
            .iter()
            .zip(moving)
            .map(|(&x, &y)| (map.apply(x) - y).length())
            .collect(),
    )
}

/// How a landmark file gives its points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LandmarkUnits {
    /// Physical LPS millimetres (`.fcsv` files are converted from RAS as Slicer declares).
    Physical,
    /// DIR-Lab: voxel indices counted from 1, converted through the image's geometry.
    DirLabVoxels,
}

/// Read a landmark list: Slicer `.fcsv`, or text with three numbers per line (physical or
/// DIR-Lab voxel coordinates, as `units` says; `geometry` converts voxels).
///
/// # Errors
/// [`RegisterError::Map`] (the handle-file parser's errors naming the line) or
/// [`RegisterError::Io`].
pub fn read_landmarks(
    path: &Path,
    units: LandmarkUnits,
    geometry: &Geometry,
) -> Result<Vec<DVec3>, RegisterError> {
    let pts = volmorph_handles::handles::read_point_list(path)?;
    Ok(match units {
        LandmarkUnits::Physical => pts,
        LandmarkUnits::DirLabVoxels => pts
            .into_iter()
            .map(|p| geometry.index_to_physical(p - DVec3::ONE))
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_deform::Affine;

    #[test]
    fn algorithm_5_1_colours() {
        let o = OverlayOptions::with_window(0.0, 100.0);
        let m = overlay_colour(50.0, 50.0, &o);
        assert_eq!([m[0], m[2]], [0.0, 0.0]);
        assert!((m[1] - 0.5).abs() < 1e-12 && (m[3] - 0.05).abs() < 1e-12);
        let r = overlay_colour(80.0, 30.0, &o);
        assert!((r[0] - 0.5).abs() < 1e-12 && (r[1] - 0.3).abs() < 1e-12 && r[2] == 0.0);
        let b = overlay_colour(30.0, 80.0, &o);
        assert_eq!([b[0], b[1], b[2], b[3]], [r[2], r[1], r[0], r[3]]);
        assert_eq!(overlay_colour(0.0, 80.0, &o), [0.0; 4]);
    }

    /// The volume-rendered overlay of two equal images is green only; a block brighter in the
    /// fixed image shows red where it projects and nowhere else; a uniform slab of agreement
    /// reaches the opacity of the closed-form emission–absorption integral.
    #[test]
    fn volume_rendered_overlay_shows_mismatch_where_it_projects() {
        let g = Geometry::new([24, 20, 16]);
        let mut a = Volume::new(g, vec![50.0f32; g.len()]).unwrap();
        let b = a.clone();
        let o = OverlayOptions::with_window(0.0, 100.0);
        let cam = anterior_camera(&g, 48).unwrap();
        let same = render_overlay(&a, &b, &cam, &o).unwrap();
        let centre = cam.project(DVec3::new(12.0, 10.0, 8.0)).unwrap();
        let px = |img: &RgbaImage, x: f64, y: f64| img.get(x as u32, y as u32).unwrap();
        let c = px(&same, centre.0, centre.1);
        assert_eq!((c[0], c[2]), (0, 0), "{c:?}");
        // Green: 0.5 emitted with per-voxel opacity 0.05 over 19 voxels of depth (y) along
        // the ray: 0.5 · (1 − 0.95^19) · 255.
        let expect = 0.5 * (1.0 - 0.95f64.powf(19.0)) * 255.0;
        assert!((f64::from(c[1]) - expect).abs() < 4.0, "{c:?} vs {expect}");
        for k in 6..10 {
            for j in 0..20 {
                for i in 4..8 {
                    a[[i, j, k]] = 90.0;
                }
            }
        }
        let diff = render_overlay(&a, &b, &cam, &o).unwrap();
        let inside = cam.project(DVec3::new(6.0, 10.0, 8.0)).unwrap();
        let d = px(&diff, inside.0, inside.1);
        assert!(d[0] > 100 && d[2] == 0, "{d:?}");
        let c = px(&diff, centre.0, centre.1);
        assert_eq!((c[0], c[2]), (0, 0), "{c:?}");
        assert!(
            render_overlay(
                &a,
                &Volume::new(Geometry::new([2, 2, 2]), vec![0.0; 8]).unwrap(),
                &cam,
                &o
            )
            .is_err()
        );
    }

    #[test]
    fn tre_statistics() {
        let t = Affine::translation(DVec3::new(3.0, 4.0, 0.0));
        let x = vec![DVec3::ZERO, DVec3::X, DVec3::Y];
        let y: Vec<DVec3> = x.iter().map(|&p| p + DVec3::new(3.0, 4.0, 0.0)).collect();
        let s = tre(&t, &x, &x).unwrap();
        assert!((s.mean - 5.0).abs() < 1e-12 && s.sd.abs() < 1e-12 && (s.max - 5.0).abs() < 1e-12);
        assert!(tre(&t, &x, &y).unwrap().max < 1e-12);
        let st = TreStats::of((1..=20).map(f64::from).collect()).unwrap();
        assert!((st.p95 - 19.05).abs() < 1e-12 && (st.mean - 10.5).abs() < 1e-12);
        assert!(tre(&t, &x, &y[..2]).is_err());
        assert!(TreStats::of(vec![]).is_err());
    }
}
