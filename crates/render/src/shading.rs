//! The one shading model of volmorph: Blinn–Phong lighting from a single directional light
//! fixed to the camera, computed in linear light.
//!
//! Every renderer that lights a surface uses it: triangle meshes
//! ([`render_triangles`](crate::render_triangles)), F-rep ray casting, the trivariate volume
//! renderer and direct volume rendering with gradient normals.
//!
//! # Conventions
//!
//! * **Light in the camera frame.** [`Shading::light`] is the direction *towards* the light in
//!   camera coordinates: `x` to the right of the picture, `y` up the picture, `z` towards the
//!   viewer (out of the screen). The light therefore moves with the camera: a turntable keeps
//!   the same lighting on the side facing the viewer, as in 3D Slicer, ParaView and Blender's
//!   viewport. [`Shading::for_camera`] turns it into world coordinates once per picture.
//! * **Two-sided.** The shading normal is turned towards the viewer before lighting, so the
//!   visible side of a surface (or of a gradient in a volume) is the lit one.
//! * **Intensity.** With unit normal `n`, unit light direction `l`, unit direction to the
//!   viewer `v` and half vector `h = normalize(l + v)`:
//!
//!   `colour = base · (ambient + (1 − ambient) · max(n·l, 0)) + specular · max(n·h, 0)^shininess`
//!
//!   the highlight only where `n·l > 0`, each channel clamped to 1. With `v` taken per
//!   point (the ray through the pixel), highlights are right for perspective cameras too.
//! * **Colour space.** `base` and the result are **linear** RGB in `[0, 1]`. Colours that users
//!   give (mesh colours, transfer-function colours, colour maps) are sRGB-coded and decoded
//!   with [`srgb_to_linear`]; pictures are encoded with [`linear_to_srgb8`] after all
//!   lighting, compositing and supersample averaging.

use glam::{DVec3, Vec3};

use crate::Camera;
use crate::error::RenderError;

/// Default Blinn–Phong exponent: a broad highlight, as the renderers have always used.
pub const DEFAULT_SHININESS: f64 = 32.0;

/// Parameters of the shading model (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shading {
    /// Direction *towards* the light in camera coordinates (x right, y up, z towards the
    /// viewer); need not be normalised, must be finite and non-zero.
    pub light: DVec3,
    /// Fraction of the base colour lit regardless of the light, in `[0, 1]`.
    pub ambient: f64,
    /// Strength of the Blinn–Phong highlight, in `[0, 1]` (0: matte).
    pub specular: f64,
    /// Exponent of the highlight, at least 1 (larger: smaller, sharper highlight).
    pub shininess: f64,
}

impl Default for Shading {
    /// Light from the upper left, behind the viewer; 20 % ambient; a soft highlight.
    fn default() -> Self {
        Self {
            light: DVec3::new(-0.4, 0.6, 1.0),
            ambient: 0.2,
            specular: 0.25,
            shininess: DEFAULT_SHININESS,
        }
    }
}

impl Shading {
    /// Check the parameters.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] naming the parameter when the light is zero or not
    /// finite, `ambient` or `specular` is outside `[0, 1]`, or `shininess` is below 1 or not
    /// finite.
    pub fn validate(&self) -> Result<(), RenderError> {
        if !(self.light.is_finite() && self.light.length_squared() > 0.0) {
            return Err(RenderError::invalid(format!(
                "light direction {} must be finite and non-zero",
                self.light
            )));
        }
        if !(0.0..=1.0).contains(&self.ambient) {
            return Err(RenderError::invalid(format!(
                "ambient {} must lie in [0, 1]",
                self.ambient
            )));
        }
        if !(0.0..=1.0).contains(&self.specular) {
            return Err(RenderError::invalid(format!(
                "specular {} must lie in [0, 1]",
                self.specular
            )));
        }
        if !(self.shininess >= 1.0 && self.shininess.is_finite()) {
            return Err(RenderError::invalid(format!(
                "shininess {} must be finite and at least 1",
                self.shininess
            )));
        }
        Ok(())
    }

    /// The light of this model for pictures taken by `camera`, in world coordinates.
    ///
    /// # Errors
    /// As [`Shading::validate`].
    pub fn for_camera(&self, camera: &Camera) -> Result<Lighting, RenderError> {
        self.validate()?;
        let l = self.light.normalize();
        let light = (camera.right() * l.x + camera.up() * l.y - camera.forward() * l.z).normalize();
        // Integral exponents (the usual case) take repeated multiplication in the f32 path.
        let shininess_int = (self.shininess.fract() == 0.0 && self.shininess <= 1024.0)
            .then_some(self.shininess as i32);
        Ok(Lighting {
            light,
            light32: light.as_vec3(),
            ambient: self.ambient,
            specular: self.specular,
            shininess: self.shininess,
            ambient32: self.ambient as f32,
            specular32: self.specular as f32,
            shininess32: self.shininess as f32,
            shininess_int,
        })
    }
}

/// A [`Shading`] resolved for one camera: the light in world coordinates. Made by
/// [`Shading::for_camera`]; cheap to copy into per-pixel loops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lighting {
    light: DVec3,
    light32: Vec3,
    ambient: f64,
    specular: f64,
    shininess: f64,
    ambient32: f32,
    specular32: f32,
    shininess32: f32,
    shininess_int: Option<i32>,
}

impl Lighting {
    /// Unit direction towards the light, world coordinates.
    #[must_use]
    pub fn light(&self) -> DVec3 {
        self.light
    }

    /// Diffuse factor `ambient + (1 − ambient)·max(n·l, 0)` and highlight
    /// `specular·max(n·h, 0)^shininess` for normal `normal` (any length; zero means "no
    /// orientation": fully lit, no highlight) seen from `to_viewer` (unit, from the point
    /// towards the eye). The normal is turned towards the viewer first (two-sided lighting).
    #[must_use]
    #[inline]
    pub fn factors(&self, normal: DVec3, to_viewer: DVec3) -> (f64, f64) {
        let Some(n) = normal.try_normalize() else {
            return (1.0, 0.0);
        };
        let n = if n.dot(to_viewer) < 0.0 { -n } else { n };
        let diffuse = n.dot(self.light).max(0.0);
        let k = self.ambient + (1.0 - self.ambient) * diffuse;
        let spec = if diffuse > 0.0 && self.specular > 0.0 {
            let h = (self.light + to_viewer).normalize_or(to_viewer);
            self.specular * n.dot(h).max(0.0).powf(self.shininess)
        } else {
            0.0
        };
        (k, spec)
    }

    /// Linear colour of a surface point: `base` (linear RGB) lit as the [module
    /// docs](self) say, each channel clamped to 1.
    #[must_use]
    #[inline]
    pub fn shade(&self, base: [f64; 3], normal: DVec3, to_viewer: DVec3) -> [f64; 3] {
        let (k, spec) = self.factors(normal, to_viewer);
        base.map(|c| (c * k + spec).min(1.0))
    }

    /// The lighting of one viewing direction `to_viewer` (unit, towards the eye) in single
    /// precision, for per-sample loops along one ray (direct volume rendering): the half
    /// vector is computed once.
    #[must_use]
    #[inline(always)]
    pub fn for_view(&self, to_viewer: Vec3) -> ViewLighting {
        ViewLighting {
            light: self.light32,
            half: (self.light32 + to_viewer).normalize_or(to_viewer),
            to_viewer,
            ambient: self.ambient32,
            specular: self.specular32,
            shininess: self.shininess32,
            shininess_int: self.shininess_int,
        }
    }
}

/// [`Lighting`] for one viewing direction, single precision (see [`Lighting::for_view`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewLighting {
    light: Vec3,
    half: Vec3,
    to_viewer: Vec3,
    ambient: f32,
    specular: f32,
    shininess: f32,
    shininess_int: Option<i32>,
}

impl ViewLighting {
    /// [`Lighting::factors`] for normal `normal` (any length; zero or non-finite: fully lit,
    /// no highlight); agrees with the f64 version to f32 rounding.
    #[must_use]
    #[inline(always)]
    pub fn factors(&self, normal: Vec3) -> (f32, f32) {
        let len2 = normal.length_squared();
        if len2.is_nan() || len2 <= 0.0 || len2.is_infinite() {
            return (1.0, 0.0);
        }
        // Normalise and turn towards the viewer in one factor.
        let inv = len2.sqrt().recip();
        let inv = if normal.dot(self.to_viewer) < 0.0 {
            -inv
        } else {
            inv
        };
        let diffuse = (normal.dot(self.light) * inv).max(0.0);
        let k = self.ambient + (1.0 - self.ambient) * diffuse;
        let spec = if diffuse > 0.0 && self.specular > 0.0 {
            let c = (normal.dot(self.half) * inv).max(0.0);
            self.specular
                * match self.shininess_int {
                    Some(p) => pow_int(c, p),
                    None => c.powf(self.shininess),
                }
        } else {
            0.0
        };
        (k, spec)
    }
}

/// `x^p` for `p ≥ 0` by repeated squaring (inline, unlike the `powi` intrinsic's library
/// call).
#[inline(always)]
fn pow_int(mut x: f32, mut p: i32) -> f32 {
    let mut r = 1.0;
    while p > 0 {
        if p & 1 == 1 {
            r *= x;
        }
        x *= x;
        p >>= 1;
    }
    r
}

/// sRGB transfer function: coded value in `[0, 1]` → linear light (IEC 61966-2-1).
#[must_use]
pub fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Inverse sRGB transfer function: linear light → coded value in `[0, 1]` (clamped; NaN
/// gives 0).
#[must_use]
pub fn linear_to_srgb(c: f64) -> f64 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// An 8-bit sRGB-coded channel → linear light in `[0, 1]`.
#[must_use]
pub fn srgb8_to_linear(c: u8) -> f64 {
    srgb_to_linear(f64::from(c) / 255.0)
}

/// Linear light → 8-bit sRGB-coded channel (rounded; clamped to `[0, 1]` first).
#[must_use]
pub fn linear_to_srgb8(c: f64) -> u8 {
    (linear_to_srgb(c) * 255.0).round() as u8
}

/// [`linear_to_srgb8`] by table lookup on the value rounded to 16 bits, for per-pixel loops:
/// the same code except within 1/131 070 of a rounding boundary.
#[must_use]
#[inline]
pub fn linear_to_srgb8_fast(c: f32) -> u8 {
    static TABLE: std::sync::LazyLock<Vec<u8>> = std::sync::LazyLock::new(|| {
        (0..=65_535u32)
            .map(|i| linear_to_srgb8(f64::from(i) / 65_535.0))
            .collect()
    });
    let i = (c.clamp(0.0, 1.0) * 65_535.0 + 0.5) as usize;
    TABLE[i.min(65_535)]
}

/// Straight-alpha 8-bit sRGB pixel of a **premultiplied** linear colour `rgb` with opacity
/// `alpha ∈ [0, 1]` (what front-to-back compositing accumulates). Fully transparent gives
/// `[0, 0, 0, 0]`.
#[must_use]
pub fn premultiplied_to_pixel(rgb: [f64; 3], alpha: f64) -> [u8; 4] {
    if alpha.is_nan() || alpha <= 0.0 {
        return [0, 0, 0, 0];
    }
    let a = alpha.min(1.0);
    [
        linear_to_srgb8(rgb[0] / a),
        linear_to_srgb8(rgb[1] / a),
        linear_to_srgb8(rgb[2] / a),
        (a * 255.0).round() as u8,
    ]
}

/// An opaque 8-bit sRGB pixel of premultiplied linear colour `rgb` with opacity `alpha`
/// composited over the opaque sRGB `background` (in linear light).
#[must_use]
pub fn premultiplied_over(rgb: [f64; 3], alpha: f64, background: [u8; 3]) -> [u8; 4] {
    let t = 1.0 - alpha.clamp(0.0, 1.0);
    let c = |k: usize| linear_to_srgb8(rgb[k] + t * srgb8_to_linear(background[k]));
    [c(0), c(1), c(2), 255]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Projection;

    fn camera() -> Camera {
        Camera::look_at(
            DVec3::new(0.0, 0.0, 5.0),
            DVec3::ZERO,
            DVec3::Y,
            Projection::Perspective { fov_y: 0.6 },
            8,
            8,
        )
        .unwrap()
    }

    #[test]
    fn light_is_fixed_to_the_camera() {
        // Camera on +z looking at the origin, up +y: camera x = world x, y = world y and
        // "towards the viewer" = world +z.
        let s = Shading {
            light: DVec3::new(1.0, 2.0, 3.0),
            ..Shading::default()
        };
        let l = s.for_camera(&camera()).unwrap().light();
        assert!((l - DVec3::new(1.0, 2.0, 3.0).normalize()).length() < 1e-12);
        // A camera turned to look along +x: towards the viewer is −x.
        let cam = Camera::look_at(
            DVec3::ZERO,
            DVec3::X,
            DVec3::Z,
            Projection::Perspective { fov_y: 0.6 },
            8,
            8,
        )
        .unwrap();
        let head_on = Shading {
            light: DVec3::Z,
            ..Shading::default()
        };
        let l = head_on.for_camera(&cam).unwrap().light();
        assert!((l + DVec3::X).length() < 1e-12);
    }

    #[test]
    fn blinn_phong_terms() {
        let s = Shading {
            light: DVec3::Z,
            ambient: 0.25,
            specular: 0.5,
            shininess: 8.0,
        };
        let lit = s.for_camera(&camera()).unwrap();
        let v = DVec3::Z;
        // Facing the light and the viewer: full diffuse, full highlight.
        let (k, spec) = lit.factors(DVec3::Z, v);
        assert!((k - 1.0).abs() < 1e-12 && (spec - 0.5).abs() < 1e-12);
        // Tilted by 60°: n·l = ½, n·h = ½ (h = l = v).
        let n = DVec3::new(3f64.sqrt() / 2.0, 0.0, 0.5);
        let (k, spec) = lit.factors(n, v);
        assert!((k - (0.25 + 0.75 * 0.5)).abs() < 1e-12);
        assert!((spec - 0.5 * 0.5f64.powi(8)).abs() < 1e-12);
        // Two-sided: the back of the surface is lit as its front.
        assert_eq!(lit.factors(-n, v), lit.factors(n, v));
        // Edge-on to the light: ambient only, no highlight.
        let (k, spec) = lit.factors(DVec3::X, DVec3::X);
        assert!((k - 0.25).abs() < 1e-12 && spec == 0.0);
        // No normal: fully lit, no highlight.
        assert_eq!(lit.factors(DVec3::ZERO, v), (1.0, 0.0));
        // Colour: base scaled, highlight added, clamped.
        let c = lit.shade([0.5, 1.0, 0.0], DVec3::Z, v);
        assert_eq!(c, [1.0, 1.0, 0.5]);
        // The f32 path agrees, on both sides of the surface.
        let view = lit.for_view(v.as_vec3());
        for m in [n, -n, DVec3::new(0.3, -0.2, 0.9)] {
            let (k32, s32) = view.factors(m.as_vec3());
            let (k64, s64) = lit.factors(m, v);
            assert!((f64::from(k32) - k64).abs() < 1e-6 && (f64::from(s32) - s64).abs() < 1e-6);
        }
        assert_eq!(view.factors(Vec3::ZERO), (1.0, 0.0));
        assert_eq!(pow_int(0.5, 5), 0.03125);
        assert_eq!(pow_int(3.0, 0), 1.0);
    }

    #[test]
    fn invalid_parameters_are_refused() {
        let d = Shading::default();
        for bad in [
            Shading {
                light: DVec3::ZERO,
                ..d
            },
            Shading { ambient: 1.5, ..d },
            Shading {
                specular: f64::NAN,
                ..d
            },
            Shading {
                shininess: 0.5,
                ..d
            },
        ] {
            assert!(bad.validate().is_err());
            assert!(bad.for_camera(&camera()).is_err());
        }
    }

    #[test]
    fn srgb_round_trips_every_code() {
        for c in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb8_to_linear(c)), c);
        }
        assert_eq!(linear_to_srgb8(f64::NAN), 0);
        assert_eq!(linear_to_srgb8(2.0), 255);
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-6);
        for i in 0..=1000 {
            let c = f64::from(i) / 1000.0;
            assert!(linear_to_srgb8_fast(c as f32).abs_diff(linear_to_srgb8(c)) <= 1);
        }
        assert_eq!(linear_to_srgb8_fast(f32::NAN), 0);
        assert_eq!(linear_to_srgb8_fast(3.0), 255);
    }

    #[test]
    fn premultiplied_pixels() {
        assert_eq!(premultiplied_to_pixel([0.0; 3], 0.0), [0, 0, 0, 0]);
        let half = srgb8_to_linear(200) * 0.5;
        assert_eq!(
            premultiplied_to_pixel([half, 0.0, 0.0], 0.5),
            [200, 0, 0, 128]
        );
        // Over black, a premultiplied colour is itself; opaque ignores the background.
        assert_eq!(
            premultiplied_over([half, 0.0, 0.0], 0.5, [0, 0, 0]),
            [linear_to_srgb8(half), 0, 0, 255]
        );
        let c = srgb8_to_linear(90);
        assert_eq!(premultiplied_over([c; 3], 1.0, [255; 3]), [90, 90, 90, 255]);
    }
}
