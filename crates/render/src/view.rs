//! Camera presets: a viewing direction given as azimuth and elevation about an up axis, named
//! views, and the framed camera every picture of volmorph is taken with.
//!
//! # Conventions
//!
//! * [`UpAxis::Z`] (the default; medical volumes in LPS have the patient's head towards +z):
//!   azimuth 0 looks from +x, azimuth 90° from +y; elevation 90° looks straight down from +z.
//! * [`UpAxis::Y`] (meshes from most modelling tools): azimuth 0 looks from +z, azimuth 90°
//!   from +x; elevation 90° looks down from +y.
//! * In both, increasing azimuth turns the eye counter-clockwise about the up axis as seen
//!   from above (right-handed), and the up axis appears upwards in the picture. At elevation
//!   ±90° the picture's up is the limit of the tilted views, so the views are continuous in
//!   the angles: the top of the picture points away from the azimuth's direction.
//!
//! Named views ([`Orbit::named`]): `front`, `side`, `top`, `iso` (for models), and the
//! anatomical `anterior`, `posterior`, `left`, `right`, `superior`, `inferior`, which follow
//! the LPS convention of volmorph's volumes with z up (patient's left +x, posterior +y,
//! superior +z): the anterior view shows the face with the patient's right on the left of the
//! picture, as 3D Slicer does.

use std::fmt;

use glam::DVec3;

use crate::camera::{Camera, Framing, Projection};
use crate::error::RenderError;

/// Vertical field of view of volmorph's perspective pictures: 0.6 rad (34°), a normal lens.
pub const DEFAULT_FOV_Y: f64 = 0.6;

/// The world axis that appears upwards in a picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UpAxis {
    /// +y is up (meshes from most modelling tools, glTF).
    Y,
    /// +z is up (medical volumes in LPS, CAD, volmorph's built-in models).
    #[default]
    Z,
}

impl std::str::FromStr for UpAxis {
    type Err = RenderError;

    /// `y` or `z` (case-insensitive).
    fn from_str(s: &str) -> Result<Self, RenderError> {
        match s.trim().to_ascii_lowercase().as_str() {
            "y" => Ok(Self::Y),
            "z" => Ok(Self::Z),
            _ => Err(RenderError::invalid(format!("up axis {s:?} is not y or z"))),
        }
    }
}

/// A viewing direction: azimuth and elevation in degrees about an up axis (see the [module
/// docs](self) for the conventions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orbit {
    azimuth: f64,
    elevation: f64,
    up: UpAxis,
}

/// The named views of [`Orbit::named`] with their azimuth and elevation for z up.
const NAMED: [(&str, f64, f64); 10] = [
    ("front", 0.0, 0.0),
    ("side", -90.0, 0.0),
    ("top", -90.0, 90.0),
    // The three-quarter view volmorph's mesh pictures have always used: from the front-right,
    // above, eye direction (0.55, −1, 0.6).
    ("iso", -61.189_206_257_026_93, 27.732_231_110_780_79),
    ("anterior", -90.0, 0.0),
    ("posterior", 90.0, 0.0),
    ("left", 0.0, 0.0),
    ("right", 180.0, 0.0),
    ("superior", -90.0, 90.0),
    ("inferior", -90.0, -90.0),
];

impl Orbit {
    /// The view from azimuth `azimuth` and elevation `elevation` (degrees) about `up`.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when an angle is not finite or the elevation is
    /// outside `[−90, 90]`.
    pub fn new(azimuth: f64, elevation: f64, up: UpAxis) -> Result<Self, RenderError> {
        if !(azimuth.is_finite() && elevation.is_finite() && elevation.abs() <= 90.0) {
            return Err(RenderError::invalid(format!(
                "view azimuth {azimuth}, elevation {elevation}: angles must be finite and the \
                 elevation within [-90, 90] degrees"
            )));
        }
        Ok(Self {
            azimuth,
            elevation,
            up,
        })
    }

    /// A named view (see the [module docs](self)), or `None` for an unknown name. The angles
    /// are those of the name for z up; with y up the same angles are used about y.
    #[must_use]
    pub fn named(name: &str, up: UpAxis) -> Option<Self> {
        let name = name.trim().to_ascii_lowercase();
        NAMED
            .iter()
            .find(|(n, ..)| *n == name)
            .map(|&(_, az, el)| Self {
                azimuth: az,
                elevation: el,
                up,
            })
    }

    /// The names [`Orbit::named`] knows.
    pub fn names() -> impl Iterator<Item = &'static str> {
        NAMED.iter().map(|(n, ..)| *n)
    }

    /// Parse `AZ,EL` (degrees) or a view name.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] naming the text when it is neither.
    pub fn parse(text: &str, up: UpAxis) -> Result<Self, RenderError> {
        if let Some(o) = Self::named(text, up) {
            return Ok(o);
        }
        let bad = || {
            RenderError::invalid(format!(
                "view {text:?} is neither AZIMUTH,ELEVATION in degrees nor a view name ({})",
                Self::names().collect::<Vec<_>>().join(", ")
            ))
        };
        let (a, e) = text.split_once(',').ok_or_else(bad)?;
        let az: f64 = a.trim().parse().map_err(|_| bad())?;
        let el: f64 = e.trim().parse().map_err(|_| bad())?;
        Self::new(az, el, up)
    }

    /// Azimuth, degrees.
    #[must_use]
    pub fn azimuth(&self) -> f64 {
        self.azimuth
    }

    /// Elevation, degrees, in `[−90, 90]`.
    #[must_use]
    pub fn elevation(&self) -> f64 {
        self.elevation
    }

    /// The up axis.
    #[must_use]
    pub fn up_axis(&self) -> UpAxis {
        self.up
    }

    /// The same view turned by `degrees` more azimuth (turntables).
    #[must_use]
    pub fn turned(&self, degrees: f64) -> Self {
        Self {
            azimuth: self.azimuth + degrees,
            ..*self
        }
    }

    /// Unit direction from the looked-at point towards the eye, world coordinates.
    #[must_use]
    pub fn eye_direction(&self) -> DVec3 {
        let (sa, ca) = self.azimuth.to_radians().sin_cos();
        let (se, ce) = self.elevation.to_radians().sin_cos();
        self.in_world(DVec3::new(ce * ca, ce * sa, se))
    }

    /// Unit up direction of the picture, perpendicular to [`Orbit::eye_direction`]: the
    /// derivative of the eye direction with respect to elevation, which is the up axis made
    /// perpendicular to the view for tilted views and stays defined straight above or below.
    #[must_use]
    pub fn picture_up(&self) -> DVec3 {
        let (sa, ca) = self.azimuth.to_radians().sin_cos();
        let (se, ce) = self.elevation.to_radians().sin_cos();
        self.in_world(DVec3::new(-se * ca, -se * sa, ce))
    }

    /// Coordinates in the z-up frame → world coordinates for this orbit's up axis (a
    /// rotation: z-up x, y, z become y-up z, x, y).
    fn in_world(self, v: DVec3) -> DVec3 {
        match self.up {
            UpAxis::Z => v,
            UpAxis::Y => DVec3::new(v.y, v.z, v.x),
        }
    }

    /// A camera looking from this direction at the box `[min, max]`, framed by `framing`,
    /// rendering `width × height` pixels. `projection` gives the kind of camera and the field
    /// of view; an orthographic view height is replaced by the framing's.
    ///
    /// ```
    /// use volmorph_render::{Framing, Orbit, Projection, UpAxis, DEFAULT_FOV_Y};
    /// use glam::DVec3;
    /// let orbit = Orbit::parse("35,25", UpAxis::Z).unwrap();
    /// let cam = orbit.camera((DVec3::splat(-1.0), DVec3::ONE),
    ///     Projection::Perspective { fov_y: DEFAULT_FOV_Y }, Framing::Sphere, 640, 480).unwrap();
    /// // The camera looks at the box centre from the orbit's direction, z up the picture.
    /// assert!((cam.forward() + orbit.eye_direction()).length() < 1e-12);
    /// assert!(cam.up().z > 0.0);
    /// ```
    ///
    /// # Errors
    /// As [`Camera::look_at`] and [`Camera::frame`].
    pub fn camera(
        &self,
        (min, max): (DVec3, DVec3),
        projection: Projection,
        framing: Framing,
        width: u32,
        height: u32,
    ) -> Result<Camera, RenderError> {
        view_camera(
            self.eye_direction(),
            self.picture_up(),
            (min, max),
            projection,
            framing,
            (width, height),
        )
    }

    /// The camera of ray-cast model pictures (F-rep shapes, NURBS volumes): perspective with
    /// [`DEFAULT_FOV_Y`], looking from this orbit at the box `[min, max]` (world units) with
    /// its bounding sphere framed ([`Framing::Sphere`], so the model stays in frame from every
    /// direction and the frames of a morph or turntable do not jump), for a `width × height`
    /// picture in pixels.
    ///
    /// # Errors
    /// As [`Orbit::camera`]: an empty or non-finite box, or an invalid picture size.
    pub fn model_camera(
        &self,
        bounds: (DVec3, DVec3),
        size: (u32, u32),
    ) -> Result<Camera, RenderError> {
        self.perspective_camera(bounds, Framing::Sphere, size)
    }

    /// This orbit's perspective camera with [`DEFAULT_FOV_Y`] on `bounds`, framed by
    /// `framing`: the presets [`Orbit::model_camera`] and [`Orbit::mesh_camera`].
    pub(crate) fn perspective_camera(
        &self,
        bounds: (DVec3, DVec3),
        framing: Framing,
        (width, height): (u32, u32),
    ) -> Result<Camera, RenderError> {
        self.camera(
            bounds,
            Projection::Perspective {
                fov_y: DEFAULT_FOV_Y,
            },
            framing,
            width,
            height,
        )
    }
}

impl fmt::Display for Orbit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{}", self.azimuth, self.elevation)
    }
}

/// A camera looking at the box `[min, max]` from direction `eye_direction` (from the box
/// towards the eye, any length) with `up` appearing upwards in the picture (not parallel to
/// the direction), framed by `framing`; `projection` as in [`Orbit::camera`].
///
/// # Errors
/// As [`Camera::look_at`] and [`Camera::frame`].
pub fn view_camera(
    eye_direction: DVec3,
    up: DVec3,
    (min, max): (DVec3, DVec3),
    projection: Projection,
    framing: Framing,
    (width, height): (u32, u32),
) -> Result<Camera, RenderError> {
    let center = 0.5 * (min + max);
    let dir = eye_direction.try_normalize().ok_or_else(|| {
        RenderError::invalid(format!(
            "view direction {eye_direction} is zero or not finite"
        ))
    })?;
    Camera::look_at(center + dir, center, up, projection, width, height)?.frame(min, max, framing)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn z_up_directions() {
        let o = |az, el| Orbit::new(az, el, UpAxis::Z).unwrap();
        assert!((o(0.0, 0.0).eye_direction() - DVec3::X).length() < 1e-12);
        assert!((o(90.0, 0.0).eye_direction() - DVec3::Y).length() < 1e-12);
        assert!((o(0.0, 90.0).eye_direction() - DVec3::Z).length() < 1e-12);
        assert!((o(0.0, 0.0).picture_up() - DVec3::Z).length() < 1e-12);
        // Straight down from +z at azimuth −90 (the "top" view): the picture's up is +y.
        assert!((o(-90.0, 90.0).picture_up() - DVec3::Y).length() < 1e-12);
    }

    #[test]
    fn y_up_directions() {
        let o = |az, el| Orbit::new(az, el, UpAxis::Y).unwrap();
        assert!((o(0.0, 0.0).eye_direction() - DVec3::Z).length() < 1e-12);
        assert!((o(90.0, 0.0).eye_direction() - DVec3::X).length() < 1e-12);
        assert!((o(0.0, 90.0).eye_direction() - DVec3::Y).length() < 1e-12);
        assert!((o(30.0, 10.0).picture_up().dot(DVec3::Y)) > 0.9);
    }

    #[test]
    fn frames_are_orthonormal_and_right_handed() {
        for up in [UpAxis::Y, UpAxis::Z] {
            for az in [-170.0, -45.0, 0.0, 33.0, 120.0] {
                for el in [-90.0, -60.0, 0.0, 25.0, 89.0, 90.0] {
                    let o = Orbit::new(az, el, up).unwrap();
                    let (e, u) = (o.eye_direction(), o.picture_up());
                    assert!((e.length() - 1.0).abs() < 1e-12 && (u.length() - 1.0).abs() < 1e-12);
                    assert!(e.dot(u).abs() < 1e-12);
                    // Increasing azimuth moves the eye towards the picture's right
                    // (right = forward × up = −e × u): the scene turns counter-clockwise.
                    let right = (-e).cross(u);
                    let next = o.turned(1e-4).eye_direction();
                    if el.abs() < 90.0 {
                        assert!((next - e).dot(right) > 0.0, "{az} {el} {up:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn anterior_view_puts_the_patients_right_on_the_left() {
        let o = Orbit::named("anterior", UpAxis::Z).unwrap();
        let cam = o
            .camera(
                (DVec3::splat(-1.0), DVec3::ONE),
                Projection::Perspective {
                    fov_y: DEFAULT_FOV_Y,
                },
                Framing::Sphere,
                100,
                100,
            )
            .unwrap();
        // LPS: the patient's right is −x, anterior −y, superior +z.
        let (xr, ..) = cam.project(DVec3::new(-0.5, 0.0, 0.0)).unwrap();
        let (xl, ..) = cam.project(DVec3::new(0.5, 0.0, 0.0)).unwrap();
        assert!(xr < xl, "patient's right must be on the picture's left");
        let (_, ys, _) = cam.project(DVec3::new(0.0, 0.0, 0.5)).unwrap();
        let (_, yi, _) = cam.project(DVec3::new(0.0, 0.0, -0.5)).unwrap();
        assert!(ys < yi, "superior must be up (smaller row)");
        // The eye is in front of the face (−y).
        assert!(cam.eye().y < -1.0);
    }

    #[test]
    fn named_views_match_the_historical_mesh_directions() {
        let iso = Orbit::named("iso", UpAxis::Z).unwrap().eye_direction();
        assert!((iso - DVec3::new(0.55, -1.0, 0.6).normalize()).length() < 1e-12);
        let side = Orbit::named("side", UpAxis::Z).unwrap().eye_direction();
        assert!((side - DVec3::NEG_Y).length() < 1e-12);
        let top = Orbit::named("TOP", UpAxis::Z).unwrap();
        assert!((top.eye_direction() - DVec3::Z).length() < 1e-12);
        assert!((top.picture_up() - DVec3::Y).length() < 1e-12);
        assert!(Orbit::named("nope", UpAxis::Z).is_none());
    }

    #[test]
    fn parsing() {
        let o = Orbit::parse(" 30 , -20 ", UpAxis::Y).unwrap();
        assert_eq!(
            (o.azimuth(), o.elevation(), o.up_axis()),
            (30.0, -20.0, UpAxis::Y)
        );
        assert_eq!(Orbit::parse("side", UpAxis::Z).unwrap().azimuth(), -90.0);
        for bad in ["", "30", "a,b", "0,91", "nan,0", "0,-90.5", "1,2,3"] {
            assert!(Orbit::parse(bad, UpAxis::Z).is_err(), "{bad}");
        }
        assert_eq!("Y".parse::<UpAxis>().unwrap(), UpAxis::Y);
        assert!("x".parse::<UpAxis>().is_err());
        assert_eq!(o.to_string(), "30,-20");
    }
}
