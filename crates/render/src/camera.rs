//! Pinhole and orthographic cameras.
//!
//! Conventions (world coordinates are f64, right-handed):
//!
//! * The camera looks along `forward = normalize(target − eye)`; `right = forward × up`
//!   (normalised) points to increasing image x and `up` (re-orthogonalised as
//!   `right × forward`) to decreasing image y.
//! * Image coordinates are continuous: x from 0 at the left edge to `width` at the right
//!   edge, y from 0 at the **top** edge to `height` at the bottom edge. Pixel `(i, j)` covers
//!   `[i, i+1) × [j, j+1)`, so pixel (0, 0) is the top-left pixel and its centre is
//!   (0.5, 0.5) — the same layout as [`RgbaImage`](crate::RgbaImage).
//! * Depth is the distance along `forward` from the eye (for orthographic cameras, from the
//!   plane through the eye perpendicular to `forward`).

use glam::DVec3;

use crate::error::RenderError;
use crate::geometry::{Aabb, Ray};
use crate::image::pixel_count;

/// How a [`Camera`] maps the world onto its image plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Pinhole camera with vertical field of view `fov_y` (full angle, radians, in (0, π)).
    /// The horizontal field follows from the image's aspect ratio (square pixels).
    Perspective {
        /// Full vertical field-of-view angle, radians.
        fov_y: f64,
    },
    /// Parallel projection showing a slab `view_height` world units tall (width from the
    /// aspect ratio); all rays share the direction `forward`.
    Orthographic {
        /// Height of the visible region, world units.
        view_height: f64,
    },
}

impl Projection {
    fn validate(self) -> Result<Self, RenderError> {
        match self {
            Projection::Perspective { fov_y } => {
                if !(fov_y > 0.0 && fov_y < std::f64::consts::PI) {
                    return Err(RenderError::invalid(format!(
                        "perspective fov_y must be in (0, π) radians, got {fov_y}"
                    )));
                }
            }
            Projection::Orthographic { view_height } => {
                if !(view_height > 0.0 && view_height.is_finite()) {
                    return Err(RenderError::invalid(format!(
                        "orthographic view_height must be finite and > 0, got {view_height}"
                    )));
                }
            }
        }
        Ok(self)
    }
}

/// Relative margin [`Framing::Sphere`] leaves around the bounding sphere (5 %).
pub const FIT_MARGIN: f64 = 1.05;

/// Fraction of the narrower half-extent of the picture that the corners of a box framed by
/// [`Framing::Box`] reach: 85 %, the margin volmorph's mesh pictures have always had (room for
/// antialiased silhouettes and a little air around the model).
pub const BOX_FILL: f64 = 0.85;

/// How [`Camera::frame`] fits a box into the picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Framing {
    /// Fit the box's bounding sphere (margin [`FIT_MARGIN`]): the same scale from every
    /// direction, so turntable frames line up.
    #[default]
    Sphere,
    /// Fit the box's corners as seen from this direction ([`BOX_FILL`]): the tightest
    /// picture of the box.
    Box,
}

/// A camera with an orthonormal frame, a projection and an image size in pixels.
///
/// Conventions: the camera looks along `forward`; `right` points to increasing image x and
/// `up` to decreasing image y. Image coordinates are continuous, x from 0 at the left edge to
/// `width`, y from 0 at the **top** edge to `height`; pixel `(i, j)` covers
/// `[i, i+1) × [j, j+1)`, so pixel (0, 0) is the top-left pixel with its centre at
/// (0.5, 0.5), matching [`RgbaImage`](crate::RgbaImage). Depth is the distance along
/// `forward` from the eye (orthographic: from the plane through the eye).
///
/// ```
/// use glam::DVec3;
/// use volmorph_render::{Camera, Projection};
/// let cam = Camera::look_at(DVec3::new(0.0, 0.0, 10.0), DVec3::ZERO, DVec3::Y,
///                           Projection::Perspective { fov_y: 0.8 }, 64, 48).unwrap();
/// let ray = cam.ray(10, 20);
/// let (x, y, depth) = cam.project(ray.at(7.0)).unwrap();
/// assert!((x - 10.5).abs() < 1e-9 && (y - 20.5).abs() < 1e-9 && depth > 0.0);
/// // The target is in the middle of the picture.
/// let (cx, cy, d) = cam.project(DVec3::ZERO).unwrap();
/// assert!((cx - 32.0).abs() < 1e-9 && (cy - 24.0).abs() < 1e-9 && (d - 10.0).abs() < 1e-9);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    eye: DVec3,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
    projection: Projection,
    width: u32,
    height: u32,
    /// Half extents of the image plane (see [`Camera::half_extents`]), cached.
    half_w: f64,
    half_h: f64,
}

impl Camera {
    /// A camera at `eye` looking at `target`, with `up` giving the upward direction of the
    /// picture (it need not be perpendicular to the view direction, only not parallel to it),
    /// rendering `width × height` pixels.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for non-finite vectors, `eye == target`, `up` zero or
    /// parallel to the view direction, or an invalid projection parameter;
    /// [`RenderError::Size`] for a zero or oversized image.
    pub fn look_at(
        eye: DVec3,
        target: DVec3,
        up: DVec3,
        projection: Projection,
        width: u32,
        height: u32,
    ) -> Result<Self, RenderError> {
        pixel_count(width.into(), height.into(), 1)?;
        let projection = projection.validate()?;
        if !(eye.is_finite() && target.is_finite() && up.is_finite()) {
            return Err(RenderError::invalid(format!(
                "camera vectors must be finite: eye {eye}, target {target}, up {up}"
            )));
        }
        let forward = (target - eye).try_normalize().ok_or_else(|| {
            RenderError::invalid(format!("camera eye and target coincide at {eye}"))
        })?;
        let right = forward.cross(up).try_normalize().ok_or_else(|| {
            RenderError::invalid(format!(
                "camera up {up} is zero or parallel to the view direction {forward}"
            ))
        })?;
        let up = right.cross(forward);
        let mut cam = Self {
            eye,
            forward,
            right,
            up,
            projection,
            width,
            height,
            half_w: 0.0,
            half_h: 0.0,
        };
        cam.set_projection(projection);
        Ok(cam)
    }

    /// Install a validated projection and refresh the cached half extents: at unit distance
    /// for perspective (tangents of the half angles), in world units for orthographic.
    fn set_projection(&mut self, projection: Projection) {
        self.projection = projection;
        self.half_h = match projection {
            Projection::Perspective { fov_y } => (0.5 * fov_y).tan(),
            Projection::Orthographic { view_height } => 0.5 * view_height,
        };
        self.half_w = self.half_h * self.aspect();
    }

    /// Eye position (perspective centre; for orthographic cameras, the centre of the image
    /// plane).
    #[must_use]
    pub fn eye(&self) -> DVec3 {
        self.eye
    }

    /// Unit viewing direction.
    #[must_use]
    pub fn forward(&self) -> DVec3 {
        self.forward
    }

    /// Unit vector towards increasing image x.
    #[must_use]
    pub fn right(&self) -> DVec3 {
        self.right
    }

    /// Unit vector towards decreasing image y (the picture's up), perpendicular to
    /// `forward` and `right`.
    #[must_use]
    pub fn up(&self) -> DVec3 {
        self.up
    }

    /// The projection.
    #[must_use]
    pub fn projection(&self) -> Projection {
        self.projection
    }

    /// Image width in pixels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height in pixels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Width / height.
    #[must_use]
    pub fn aspect(&self) -> f64 {
        f64::from(self.width) / f64::from(self.height)
    }

    /// The same view rendered at `width × height` pixels (used for supersampling: the
    /// picture plane is unchanged, only its pixel grid). Callers keep the aspect ratio.
    pub(crate) fn resize(&mut self, width: u32, height: u32) {
        self.width = width;
        self.height = height;
        self.set_projection(self.projection);
    }

    /// Half extents of the image plane: at unit distance for perspective (tangents of the
    /// half angles), in world units for orthographic.
    fn half_extents(&self) -> (f64, f64) {
        (self.half_w, self.half_h)
    }

    /// Continuous image coordinates → normalised device coordinates in [−1, 1] (y up).
    fn ndc(&self, x: f64, y: f64) -> (f64, f64) {
        (
            2.0 * x / f64::from(self.width) - 1.0,
            1.0 - 2.0 * y / f64::from(self.height),
        )
    }

    /// The ray through the centre of pixel `(px, py)`, i.e. [`Camera::ray_at`]`(px + 0.5,
    /// py + 0.5)`. Pixels outside the image give rays outside the view, by extrapolation.
    #[must_use]
    pub fn ray(&self, px: u32, py: u32) -> Ray {
        self.ray_at(f64::from(px) + 0.5, f64::from(py) + 0.5)
    }

    /// The ray through continuous image point `(x, y)` (x right from the left edge, y down
    /// from the top edge, in pixels; use fractional offsets for supersampling).
    ///
    /// Perspective rays start at the eye; orthographic rays start on the plane through the
    /// eye perpendicular to `forward` and all have direction `forward`. `dir` is unit length.
    #[must_use]
    pub fn ray_at(&self, x: f64, y: f64) -> Ray {
        let (sx, sy) = self.ndc(x, y);
        let (hw, hh) = self.half_extents();
        match self.projection {
            Projection::Perspective { .. } => {
                let d = self.forward + (sx * hw) * self.right + (sy * hh) * self.up;
                Ray {
                    origin: self.eye,
                    dir: d.normalize_or(self.forward),
                }
            }
            Projection::Orthographic { .. } => Ray {
                origin: self.eye + (sx * hw) * self.right + (sy * hh) * self.up,
                dir: self.forward,
            },
        }
    }

    /// Where world point `p` lands: `(x, y, depth)` in continuous image coordinates (pixel
    /// centres at half-integers) and depth along `forward`. Inverse of
    /// [`Camera::ray_at`]: every point of `ray_at(x, y)` in front of the camera projects to
    /// `(x, y)`. Points outside the view project outside `[0, width] × [0, height]`.
    ///
    /// Returns `None` for points behind the camera (depth ≤ 0 for perspective, < 0 for
    /// orthographic) and for non-finite points.
    #[must_use]
    pub fn project(&self, p: DVec3) -> Option<(f64, f64, f64)> {
        let d = p - self.eye;
        let depth = d.dot(self.forward);
        let (hw, hh) = self.half_extents();
        let (sx, sy) = match self.projection {
            Projection::Perspective { .. } => {
                if depth.is_nan() || depth <= 0.0 {
                    return None;
                }
                (
                    d.dot(self.right) / (depth * hw),
                    d.dot(self.up) / (depth * hh),
                )
            }
            Projection::Orthographic { .. } => {
                if depth.is_nan() || depth < 0.0 {
                    return None;
                }
                (d.dot(self.right) / hw, d.dot(self.up) / hh)
            }
        };
        let x = 0.5 * (sx + 1.0) * f64::from(self.width);
        let y = 0.5 * (1.0 - sy) * f64::from(self.height);
        (x.is_finite() && y.is_finite()).then_some((x, y, depth))
    }

    /// A copy of this camera moved (and, for orthographic cameras, zoomed) so that the whole
    /// box `[min, max]` is in view, keeping the viewing direction, up vector, field of view and
    /// image size. The picture is centred on the box centre; `framing` says how tight:
    ///
    /// * [`Framing::Sphere`]: the box's bounding sphere fills the narrower view angle up to
    ///   the [`FIT_MARGIN`] margin. The scale does not depend on the viewing direction, so the
    ///   frames of a turntable line up.
    /// * [`Framing::Box`]: the projected corners of the box reach [`BOX_FILL`] of the narrower
    ///   half-extent of the picture. Perspective: the distance is solved in closed form from
    ///   every corner's offset and depth (the tightest distance that keeps all of them in,
    ///   and always outside the box). Orthographic: the view height follows the box's
    ///   extent across the view.
    ///
    /// In both, every corner of the box then projects inside the image at positive depth,
    /// and the eye is outside the box.
    ///
    /// ```
    /// use glam::DVec3;
    /// use volmorph_render::{Aabb, Camera, Framing, Projection};
    /// let cam = Camera::look_at(DVec3::new(1.0, 2.0, 3.0), DVec3::ZERO, DVec3::Z,
    ///                           Projection::Perspective { fov_y: 0.6 }, 320, 200).unwrap();
    /// let (min, max) = (DVec3::new(-10.0, 0.0, 5.0), DVec3::new(30.0, 8.0, 9.0));
    /// for framing in [Framing::Sphere, Framing::Box] {
    ///     let framed = cam.frame(min, max, framing).unwrap();
    ///     for corner in Aabb::new(min, max).unwrap().corners() {
    ///         let (x, y, depth) = framed.project(corner).unwrap();
    ///         assert!((0.0..=320.0).contains(&x) && (0.0..=200.0).contains(&y) && depth > 0.0);
    ///     }
    ///     assert_eq!(framed.forward(), cam.forward());
    /// }
    /// ```
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when the corners are not finite, `min > max` on an
    /// axis, or the box is a single point (nothing to frame).
    pub fn frame(&self, min: DVec3, max: DVec3, framing: Framing) -> Result<Camera, RenderError> {
        let bbox = Aabb::new(min, max)?;
        let center = bbox.center();
        let radius = 0.5 * bbox.size().length();
        if !(radius > 0.0 && radius.is_finite()) {
            return Err(RenderError::invalid(format!(
                "cannot frame a box of zero or non-finite size: min {min}, max {max}"
            )));
        }
        let mut cam = *self;
        // Offsets of the corners from the centre in the camera frame: (right, up, forward).
        let offsets = bbox.corners().map(|c| {
            let d = c - center;
            (d.dot(self.right), d.dot(self.up), d.dot(self.forward))
        });
        match (self.projection, framing) {
            (Projection::Perspective { .. }, Framing::Sphere) => {
                let (hw, hh) = self.half_extents();
                let half_angle = hw.atan().min(hh.atan());
                let dist = FIT_MARGIN * radius / half_angle.sin();
                cam.eye = center - dist * self.forward;
            }
            (Projection::Perspective { .. }, Framing::Box) => {
                // Corner (a, b, z) at eye distance D projects to a / (D + z) · (1/hw) in NDC;
                // it stays within BOX_FILL when D ≥ |a| / (BOX_FILL·hw) − z (same for b).
                let (hw, hh) = self.half_extents();
                let (kw, kh) = (BOX_FILL * hw, BOX_FILL * hh);
                let mut dist = 0.0_f64;
                let mut nearest = f64::NEG_INFINITY;
                for (a, b, z) in offsets {
                    dist = dist.max(a.abs() / kw - z).max(b.abs() / kh - z);
                    nearest = nearest.max(-z);
                }
                // Keep the eye outside the box even when it is seen end-on.
                let dist = dist.max(nearest + 1e-3 * radius);
                cam.eye = center - dist * self.forward;
            }
            (Projection::Orthographic { .. }, _) => {
                let (ex, ey) = offsets
                    .iter()
                    .fold((0.0_f64, 0.0_f64), |(ex, ey), &(a, b, _)| {
                        (ex.max(a.abs()), ey.max(b.abs()))
                    });
                let half_h = match framing {
                    Framing::Sphere => radius * FIT_MARGIN * (1.0 / self.aspect()).max(1.0),
                    Framing::Box => {
                        let half_h = ey.max(ex / self.aspect());
                        // A box seen end-on (all corners on the axis) still gets a visible slab.
                        (if half_h > 0.0 { half_h } else { radius }) / BOX_FILL
                    }
                };
                cam.set_projection(Projection::Orthographic {
                    view_height: 2.0 * half_h,
                });
                cam.eye = center - 2.0 * radius * self.forward;
            }
        }
        Ok(cam)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const PERSP: Projection = Projection::Perspective { fov_y: 0.9 };
    const ORTHO: Projection = Projection::Orthographic { view_height: 3.0 };

    fn cameras(width: u32, height: u32) -> Vec<Camera> {
        let eye = DVec3::new(2.0, -3.0, 5.0);
        let target = DVec3::new(0.5, 0.25, -0.5);
        [PERSP, ORTHO]
            .into_iter()
            .map(|p| Camera::look_at(eye, target, DVec3::Z, p, width, height).unwrap())
            .collect()
    }

    #[test]
    fn pixel_centre_rays_project_back_to_their_pixel() {
        for cam in cameras(7, 5) {
            for py in 0..5 {
                for px in 0..7 {
                    let r = cam.ray(px, py);
                    assert!((r.dir.length() - 1.0).abs() < 1e-12);
                    for t in [0.5, 1.0, 4.0, 20.0] {
                        let (x, y, depth) = cam.project(r.at(t)).unwrap();
                        assert!((x - (f64::from(px) + 0.5)).abs() < 1e-9, "{x} vs {px}");
                        assert!((y - (f64::from(py) + 0.5)).abs() < 1e-9, "{y} vs {py}");
                        assert!((depth - t * r.dir.dot(cam.forward())).abs() < 1e-9);
                        assert!(depth > 0.0);
                    }
                }
            }
        }
    }

    #[test]
    fn centre_ray_points_at_the_target() {
        let target = DVec3::new(0.5, 0.25, -0.5);
        // Odd size: the middle pixel's centre is the image centre.
        for cam in cameras(9, 7) {
            let r = cam.ray(4, 3);
            assert!((r.dir - cam.forward()).length() < 1e-12);
            let to_target = target - r.origin;
            assert!(to_target.cross(r.dir).length() < 1e-12, "ray misses target");
            assert!(to_target.dot(r.dir) > 0.0);
            let (x, y, _) = cam.project(target).unwrap();
            assert!((x - 4.5).abs() < 1e-9 && (y - 3.5).abs() < 1e-9);
        }
        // Even size: the image centre lies between pixels.
        for cam in cameras(8, 6) {
            let r = cam.ray_at(4.0, 3.0);
            assert!((target - r.origin).cross(r.dir).length() < 1e-12);
        }
    }

    #[test]
    fn image_axes_have_the_documented_orientation() {
        for cam in cameras(8, 6) {
            let target = DVec3::new(0.5, 0.25, -0.5);
            let (x0, y0, _) = cam.project(target).unwrap();
            let (xr, yr, _) = cam.project(target + 0.1 * cam.right()).unwrap();
            let (xu, yu, _) = cam.project(target + 0.1 * cam.up()).unwrap();
            assert!(xr > x0 && (yr - y0).abs() < 1e-9, "right is +x");
            assert!(yu < y0 && (xu - x0).abs() < 1e-9, "up is −y (row 0 on top)");
            // World up (+Z) appears upwards in the picture.
            assert!(cam.up().dot(DVec3::Z) > 0.0);
            assert!(cam.right().dot(cam.forward()).abs() < 1e-15);
            assert!(cam.up().dot(cam.forward()).abs() < 1e-15);
        }
    }

    #[test]
    fn field_of_view_and_view_height_reach_the_image_edges() {
        let fov = 0.9_f64;
        let cam = Camera::look_at(DVec3::ZERO, -DVec3::Z, DVec3::Y, PERSP, 10, 4).unwrap();
        // A point at half the vertical field above the axis lands on the top edge.
        let p = DVec3::new(0.0, (0.5 * fov).tan(), -1.0);
        let (x, y, d) = cam.project(p).unwrap();
        assert!((x - 5.0).abs() < 1e-9 && y.abs() < 1e-9 && (d - 1.0).abs() < 1e-12);
        // Horizontal field follows the aspect ratio (square pixels).
        let p = DVec3::new(2.5 * (0.5 * fov).tan(), 0.0, -1.0);
        let (x, _, _) = cam.project(p).unwrap();
        assert!((x - 10.0).abs() < 1e-9);

        let cam = Camera::look_at(DVec3::ZERO, -DVec3::Z, DVec3::Y, ORTHO, 10, 4).unwrap();
        let (x, y, _) = cam.project(DVec3::new(-3.75, -1.5, -7.0)).unwrap();
        assert!(x.abs() < 1e-9 && (y - 4.0).abs() < 1e-9);
    }

    #[test]
    fn orthographic_rays_are_parallel() {
        let cam = cameras(6, 4)[1];
        let d0 = cam.ray(0, 0).dir;
        for py in 0..4 {
            for px in 0..6 {
                let r = cam.ray(px, py);
                assert_eq!(r.dir, d0);
                assert_eq!(r.dir, cam.forward());
                // Origins lie on the plane through the eye perpendicular to the view.
                assert!((r.origin - cam.eye()).dot(cam.forward()).abs() < 1e-12);
            }
        }
        // Adjacent pixel origins are one pixel (view_height / height) apart.
        let step = (cam.ray(1, 0).origin - cam.ray(0, 0).origin).length();
        assert!((step - 3.0 / 4.0).abs() < 1e-12);
    }

    #[test]
    fn points_behind_the_camera_do_not_project() {
        let [persp, ortho] = cameras(4, 4)[..] else {
            unreachable!("two cameras")
        };
        for cam in [persp, ortho] {
            assert!(cam.project(cam.eye() - cam.forward()).is_none());
            assert!(cam.project(DVec3::splat(f64::NAN)).is_none());
        }
        assert!(persp.project(persp.eye()).is_none());
        // Orthographic: on the eye plane is still in view (depth 0).
        assert_eq!(ortho.project(ortho.eye()).map(|p| p.2), Some(0.0));
    }

    #[test]
    fn look_at_refuses_degenerate_input() {
        let ok = |e, t, u, p, w, h| Camera::look_at(e, t, u, p, w, h);
        assert!(ok(DVec3::ONE, DVec3::ONE, DVec3::Z, PERSP, 4, 4).is_err());
        assert!(ok(DVec3::ZERO, DVec3::Z, DVec3::Z, PERSP, 4, 4).is_err());
        assert!(ok(DVec3::ZERO, DVec3::X, DVec3::ZERO, PERSP, 4, 4).is_err());
        assert!(ok(DVec3::ZERO, DVec3::X, DVec3::Z, PERSP, 0, 4).is_err());
        assert!(ok(DVec3::ZERO, DVec3::X, DVec3::Z, PERSP, 1 << 20, 1 << 20).is_err());
        let bad_fov = Projection::Perspective {
            fov_y: std::f64::consts::PI,
        };
        assert!(ok(DVec3::ZERO, DVec3::X, DVec3::Z, bad_fov, 4, 4).is_err());
        let bad_fov = Projection::Perspective { fov_y: f64::NAN };
        assert!(ok(DVec3::ZERO, DVec3::X, DVec3::Z, bad_fov, 4, 4).is_err());
        let bad_h = Projection::Orthographic { view_height: 0.0 };
        assert!(ok(DVec3::ZERO, DVec3::X, DVec3::Z, bad_h, 4, 4).is_err());
        let nan = DVec3::new(f64::NAN, 0.0, 0.0);
        assert!(ok(nan, DVec3::X, DVec3::Z, PERSP, 4, 4).is_err());
        // Non-perpendicular up is fine.
        assert!(
            ok(
                DVec3::ZERO,
                DVec3::X,
                DVec3::new(1.0, 0.0, 1.0),
                PERSP,
                4,
                4
            )
            .is_ok()
        );
    }

    #[test]
    fn frame_refuses_bad_boxes() {
        let cam = cameras(4, 4)[0];
        for f in [Framing::Sphere, Framing::Box] {
            assert!(cam.frame(DVec3::ONE, DVec3::ZERO, f).is_err());
            assert!(cam.frame(DVec3::ONE, DVec3::ONE, f).is_err());
            assert!(cam.frame(DVec3::ZERO, DVec3::splat(f64::NAN), f).is_err());
        }
    }

    #[test]
    fn sphere_framing_has_the_same_scale_from_every_direction() {
        let (lo, hi) = (DVec3::new(-1.0, -2.0, 0.0), DVec3::new(3.0, 1.0, 0.5));
        let mut dists = Vec::new();
        for dir in [
            DVec3::X,
            DVec3::new(1.0, 1.0, 0.3),
            DVec3::new(-0.2, 1.0, -0.7),
        ] {
            let cam = Camera::look_at(DVec3::ZERO, dir, DVec3::Z, PERSP, 64, 48).unwrap();
            let f = cam.frame(lo, hi, Framing::Sphere).unwrap();
            dists.push((f.eye() - 0.5 * (lo + hi)).length());
        }
        assert!(
            dists.iter().all(|d| (d - dists[0]).abs() < 1e-12),
            "{dists:?}"
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]
        #[test]
        fn project_inverts_ray_at_for_random_cameras(
            eye in proptest::array::uniform3(-20.0f64..20.0),
            target in proptest::array::uniform3(-20.0f64..20.0),
            up in proptest::array::uniform3(-1.0f64..1.0),
            fov in 0.05f64..3.0,
            view_height in 0.01f64..100.0,
            width in 1u32..2000,
            height in 1u32..2000,
            fx in 0.0f64..1.0,
            fy in 0.0f64..1.0,
            t in 0.01f64..100.0,
            ortho in any::<bool>(),
        ) {
            let projection = if ortho {
                Projection::Orthographic { view_height }
            } else {
                Projection::Perspective { fov_y: fov }
            };
            let Ok(cam) = Camera::look_at(
                DVec3::from_array(eye), DVec3::from_array(target), DVec3::from_array(up),
                projection, width, height,
            ) else {
                return Ok(());
            };
            let (x, y) = (fx * f64::from(width), fy * f64::from(height));
            let r = cam.ray_at(x, y);
            prop_assert!((r.dir.length() - 1.0).abs() < 1e-12);
            let (px, py, depth) = cam.project(r.at(t)).expect("in front");
            let tol = 1e-7 * f64::from(width.max(height));
            prop_assert!((px - x).abs() < tol && (py - y).abs() < tol, "({px}, {py}) vs ({x}, {y})");
            prop_assert!((depth - t * r.dir.dot(cam.forward())).abs() < 1e-9 * (1.0 + t));
        }

        #[test]
        fn frame_fits_every_corner(
            dir in proptest::array::uniform3(-1.0f64..1.0),
            lo in proptest::array::uniform3(-50.0f64..50.0),
            ext in proptest::array::uniform3(0.0f64..30.0),
            width in 1u32..300,
            height in 1u32..300,
            fov in 0.05f64..3.0,
            ortho in any::<bool>(),
            tight in any::<bool>(),
        ) {
            let dir = DVec3::from_array(dir);
            let framing = if tight { Framing::Box } else { Framing::Sphere };
            prop_assume!(dir.length() > 0.1 && dir.normalize().cross(DVec3::Z).length() > 0.05);
            let projection = if ortho {
                Projection::Orthographic { view_height: 1.0 }
            } else {
                Projection::Perspective { fov_y: fov }
            };
            let cam = Camera::look_at(DVec3::ZERO, dir, DVec3::Z, projection, width, height)
                .unwrap();
            let lo = DVec3::from_array(lo);
            let hi = lo + DVec3::from_array(ext);
            prop_assume!(ext.iter().any(|&e| e > 1e-3));
            let fitted = cam.frame(lo, hi, framing).unwrap();
            let bbox = Aabb::new(lo, hi).unwrap();
            prop_assert!(!bbox.contains(fitted.eye()) || ortho, "eye inside the box");
            prop_assert!((fitted.forward() - cam.forward()).length() < 1e-15);
            let (w, h) = (f64::from(width), f64::from(height));
            let mut max_reach = 0.0_f64;
            for c in Aabb::new(lo, hi).unwrap().corners() {
                let (x, y, d) = fitted.project(c).expect("corner in front of the camera");
                prop_assert!(d > 0.0);
                prop_assert!((0.0..=w).contains(&x) && (0.0..=h).contains(&y),
                    "corner {c} at ({x}, {y}) outside {w}×{h}");
                max_reach = max_reach.max((2.0 * x / w - 1.0).abs()).max((2.0 * y / h - 1.0).abs());
            }
            if tight {
                // Box framing is tight: some corner reaches the fill fraction (perspective:
                // unless the eye had to back off to stay outside a box seen end-on).
                prop_assert!(max_reach < BOX_FILL + 1e-9, "reach {max_reach}");
                if ortho {
                    prop_assert!(max_reach > BOX_FILL - 1e-9, "reach {max_reach}");
                }
            }
        }
    }
}
