//! Built-in phantoms: deterministic solid models that can be sampled at any resolution.
//!
//! A [`Phantom`] is a solid given by a signed distance function (SDF) in its **model frame**.
//! The phantoms are the default data of volume warping and contouring: a sphere, a torus, a
//! rounded box, a block of sculpting clay with a hole, a groove and a bump, a teapot (the
//! model of True's volume warping examples, §7, Figs. 9–10) and a tree (Figs. 13–14).
//!
//! # Sign convention
//!
//! **[`Phantom::sdf`] is negative inside the solid, zero on its surface and positive outside.**
//! Every SDF here is 1-Lipschitz (`|f(a) − f(b)| ≤ |a − b|`), hence `|f(p)|` never exceeds the
//! Euclidean distance from `p` to the surface. For [`Phantom::Sphere`], [`Phantom::Torus`] and
//! [`Phantom::RoundedBox`] it *is* that distance ([`Phantom::is_exact`]); for the composites
//! ([`Phantom::ClayBlock`], [`Phantom::Teapot`]) it is a conservative bound, good for sphere
//! tracing and narrow bands but not for measuring thicknesses.
//!
//! # Model frame
//!
//! Right-handed, unitless, z up. Every phantom's solid lies inside the cube
//! `[-MODEL_EXTENT, MODEL_EXTENT]³ = [-0.9, 0.9]³` ([`Phantom::bounding_box`] gives a tighter
//! box). The volumes made here ([`geometry`]) have their voxel centres spanning
//! `[-GRID_EXTENT, GRID_EXTENT]³ = [-1.1, 1.1]³`, so there are at least 0.2 model units of
//! empty space between the solid and the grid boundary, and physical units *are* model units.
//!
//! # Density
//!
//! True (1992, §5.1) stores a model as unsigned bytes whose value / 255 is a density in
//! `[0, 1]`; the object is the isosurface at value 127 (density ½). [`density`] samples the SDF
//! at voxel centres and maps it through the antialiased ramp of [`density_value`]:
//!
//! ```text
//! value = round(clamp(127.5 − 127.5 · sdf / w, 0, 255)),   w = RAMP_VOXELS · max(spacing)
//! ```
//!
//! (halves rounded up), so voxels deeper than `w` inside are 255, voxels farther than `w`
//! outside are 0, and the 127.5 level of the un-quantised ramp is exactly the SDF's zero set.
//! The ramp is `2 · RAMP_VOXELS = 3` voxels wide along the coarsest axis (wider in true
//! distance where a composite's SDF bound has a gradient below 1), enough for linear
//! interpolation of the density to place the surface within half a voxel of the zero set
//! wherever the model has no detail finer than about two voxels; the phantoms are designed so
//! that this holds already at True's 30³.
//!
//! ```
//! use volmorph_volume::phantom::{self, Phantom};
//! use volmorph_volume::DVec3;
//!
//! let teapot: Phantom = "teapot".parse()?;
//! assert!(teapot.sdf(DVec3::ZERO) < 0.0); // the centre of the body is inside
//! assert!(teapot.sdf(DVec3::splat(0.95)) > 0.0);
//!
//! // True's model size: 30³ unsigned bytes, object at value 127.
//! let vol = phantom::density(teapot, [30, 30, 30])?;
//! assert_eq!(vol.get(0, 0, 0), Some(0));
//! assert_eq!(vol.get(15, 15, 15), Some(255));
//! assert_eq!(vol.geometry().origin, DVec3::splat(-1.1));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::fmt;
use std::str::FromStr;

use glam::{DVec2, DVec3};

use crate::{Geometry, Volume, VolumeError, Voxel};

/// Half edge of the cube `[-MODEL_EXTENT, MODEL_EXTENT]³` that contains every phantom's solid
/// (model units).
pub const MODEL_EXTENT: f64 = 0.9;

/// Half edge of the cube spanned by the voxel centres of [`geometry`] (model units).
pub const GRID_EXTENT: f64 = 1.1;

/// Half width of the density ramp of [`density`], in voxels of the coarsest axis.
pub const RAMP_VOXELS: f64 = 1.5;

/// The density value at which the object's surface lies (True 1992, §5.1).
pub const ISO_VALUE: u8 = 127;

/// Radius of [`Phantom::Sphere`], centred at the origin.
pub const SPHERE_RADIUS: f64 = 0.8;

/// Major radius (centre of the tube to the z axis) of [`Phantom::Torus`], whose axis is z and
/// whose centre is the origin.
pub const TORUS_MAJOR_RADIUS: f64 = 0.6;

/// Minor radius (radius of the tube) of [`Phantom::Torus`].
pub const TORUS_MINOR_RADIUS: f64 = 0.25;

/// Half extents along x, y, z of [`Phantom::RoundedBox`] (outer size, rounding included),
/// centred at the origin. All three differ so that swapped axes show.
pub const ROUNDED_BOX_HALF_EXTENTS: DVec3 = DVec3::new(0.8, 0.6, 0.4);

/// Radius of the rounded edges and corners of [`Phantom::RoundedBox`].
pub const ROUNDED_BOX_RADIUS: f64 = 0.15;

/// The centre of the spout's tip of [`Phantom::Teapot`] (model units): the point a drag
/// grabs to lower the spout, as in True 1992, Fig. 10.
pub const TEAPOT_SPOUT_TIP: DVec3 = teapot::SPOUT_TIP;

/// One of volmorph's built-in solid models. See the [module docs](self) for the frame, the
/// sign convention and the density mapping.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Phantom {
    /// Ball of radius [`SPHERE_RADIUS`] centred at the origin. Exact SDF.
    Sphere,
    /// Torus around the z axis, radii [`TORUS_MAJOR_RADIUS`] and [`TORUS_MINOR_RADIUS`],
    /// centred at the origin. Exact SDF.
    Torus,
    /// Box with half extents [`ROUNDED_BOX_HALF_EXTENTS`] whose edges and corners are rounded
    /// with radius [`ROUNDED_BOX_RADIUS`] (a Minkowski sum of a box and a ball), centred at the
    /// origin. Exact SDF.
    RoundedBox,
    /// A block of sculpting clay: a slab of 1.5 × 1.0 × 0.9 (x × y × z, centred at the
    /// origin) with rounded edges (radius 0.12), pierced along y by a round hole (radius 0.18,
    /// axis at x = −0.35, z = 0), with a round-bottomed groove along y in the top face (radius
    /// 0.14, axis at x = 0.4, z = 0.45) and a ball-shaped bump of radius 0.2 on the front face
    /// (−y), centred at (0.2, −0.5, −0.1). The edges of the hole and groove and the foot of
    /// the bump are smoothly blended, as if worked by hand. The block has no mirror symmetry,
    /// so flipped or swapped axes show after a deformation. 1-Lipschitz bound.
    ClayBlock,
    /// A teapot, z up, in the spirit of True's sculpted teapot (§7, Figs. 9–10):
    ///
    /// * body: ellipsoid centred at (0, 0, −0.1) with semi-axes (0.5, 0.5, 0.4), cut flat at
    ///   the base z = −0.45 and at the shoulder z = 0.22 (both edges rounded);
    /// * lid: a dome (semi-axes 0.25, 0.25, 0.16 about (0, 0, 0.2)) narrower than the
    ///   shoulder, so a ledge shows around it; knob: a ball of radius 0.1 at (0, 0, 0.45);
    /// * spout towards +x: two tapering-then-flaring segments (radius 0.12 → 0.09 → 0.1) from
    ///   inside the body at (0.36, 0, −0.18) through (0.6, 0, 0.04) to (0.76, 0, 0.25);
    /// * handle towards −x: a ring (torus about the y axis at (−0.635, 0, −0.05), radii 0.17
    ///   and 0.075) whose inner half is buried in the body; the hole around (−0.64, 0, −0.05)
    ///   is open.
    ///
    /// The parts are joined by smooth unions. No part is thinner than 0.15, two voxels at
    /// True's 30³, so the density isosurface follows the model there. Mirror-symmetric about
    /// the plane y = 0 only. 1-Lipschitz bound.
    Teapot,
    /// A tree, z up, for True's sculpted tree (§7, Figs. 13–14): a tapering trunk (radius
    /// 0.13 → 0.11) from (0, 0, −0.75) to the fork at (0, 0, −0.1), [`TREE_LIMBS`] limbs
    /// (radius 0.1 → 0.09) from the fork at azimuths 0°, 120° and 240° rising to radius 0.4
    /// and height 0.25, and at the end of each limb [`TREE_TWIGS_PER_LIMB`] twigs (radius
    /// 0.085 → 0.075) splaying ±0.6 rad in azimuth to radius 0.7 and height 0.7. Joints are
    /// smooth unions. One connected solid of genus 0; a horizontal cut between heights 0.0
    /// and 0.15 crosses the three limbs, one between 0.4 and 0.6 the six twigs. No part is
    /// thinner than 0.15 (two voxels at 30³). 1-Lipschitz bound.
    Tree,
}

/// Number of limbs of [`Phantom::Tree`] leaving the top of the trunk.
pub const TREE_LIMBS: usize = 3;

/// Number of twigs at the end of each limb of [`Phantom::Tree`].
pub const TREE_TWIGS_PER_LIMB: usize = 2;

impl Phantom {
    /// Every phantom, in the order of the enum.
    pub const ALL: [Phantom; 6] = [
        Self::Sphere,
        Self::Torus,
        Self::RoundedBox,
        Self::ClayBlock,
        Self::Teapot,
        Self::Tree,
    ];

    /// Kebab-case name, as accepted by [`FromStr`]: `sphere`, `torus`, `rounded-box`,
    /// `clay-block`, `teapot`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Sphere => "sphere",
            Self::Torus => "torus",
            Self::RoundedBox => "rounded-box",
            Self::ClayBlock => "clay-block",
            Self::Teapot => "teapot",
            Self::Tree => "tree",
        }
    }

    /// One-line human description of the model.
    #[must_use]
    pub const fn description(self) -> &'static str {
        match self {
            Self::Sphere => "ball of radius 0.8 at the origin (exact distance)",
            Self::Torus => "torus around z, major radius 0.6, tube radius 0.25 (exact distance)",
            Self::RoundedBox => {
                "box 1.6 x 1.2 x 0.8 with edges rounded to radius 0.15 (exact distance)"
            }
            Self::ClayBlock => {
                "block of clay with a through hole along y, a groove on top and a bump on the front"
            }
            Self::Teapot => {
                "teapot, z up: body, lid with knob, spout towards +x, handle towards -x"
            }
            Self::Tree => "tree, z up: a trunk forking into three limbs of two twigs each",
        }
    }

    /// `true` if [`Phantom::sdf`] is the exact Euclidean signed distance to the surface;
    /// `false` if it is a 1-Lipschitz bound (`|sdf| ≤` distance, same sign and zero set).
    #[must_use]
    pub const fn is_exact(self) -> bool {
        matches!(self, Self::Sphere | Self::Torus | Self::RoundedBox)
    }

    /// An axis-aligned box `(min, max)` in the model frame that contains the solid
    /// (`sdf ≤ 0`), tight to within 0.02 on every side and inside
    /// `[-MODEL_EXTENT, MODEL_EXTENT]³`.
    #[must_use]
    pub fn bounding_box(self) -> (DVec3, DVec3) {
        const PAD: f64 = 0.01;
        let (lo, hi) = match self {
            Self::Sphere => (DVec3::splat(-SPHERE_RADIUS), DVec3::splat(SPHERE_RADIUS)),
            Self::Torus => {
                let r = TORUS_MAJOR_RADIUS + TORUS_MINOR_RADIUS;
                let h = DVec3::new(r, r, TORUS_MINOR_RADIUS);
                (-h, h)
            }
            Self::RoundedBox => (-ROUNDED_BOX_HALF_EXTENTS, ROUNDED_BOX_HALF_EXTENTS),
            Self::ClayBlock => (
                DVec3::new(
                    -clay::HALF.x,
                    clay::BUMP_CENTER.y - clay::BUMP_RADIUS,
                    -clay::HALF.z,
                ),
                clay::HALF,
            ),
            Self::Teapot => (
                DVec3::new(
                    teapot::HANDLE_CENTER.x - teapot::HANDLE_MAJOR - teapot::HANDLE_MINOR,
                    -teapot::BODY_RADII.y,
                    teapot::BASE_Z,
                ),
                DVec3::new(
                    teapot::SPOUT_TIP.x + teapot::SPOUT_TIP_RADIUS,
                    teapot::BODY_RADII.y,
                    teapot::KNOB_CENTER.z + teapot::KNOB_RADIUS,
                ),
            ),
            Self::Tree => tree::bounds(),
        };
        (lo - DVec3::splat(PAD), hi + DVec3::splat(PAD))
    }

    /// Signed distance from `p` (model frame) to the phantom's surface: **negative inside**,
    /// zero on the surface, positive outside. Exact for [`Phantom::is_exact`] phantoms,
    /// otherwise a 1-Lipschitz bound with `|sdf(p)| ≤` the true distance. Deterministic: a pure
    /// function of `p` in `f64` arithmetic. Non-finite `p` gives a non-finite or meaningless
    /// result.
    #[must_use]
    pub fn sdf(&self, p: DVec3) -> f64 {
        match self {
            Self::Sphere => sphere_sdf(p),
            Self::Torus => torus_sdf(p),
            Self::RoundedBox => rounded_box_sdf(p),
            Self::ClayBlock => clay::sdf(p),
            Self::Teapot => teapot::sdf(p),
            Self::Tree => tree::sdf(p),
        }
    }
}

impl fmt::Display for Phantom {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The error of parsing a [`Phantom`] from a name that is not one of [`Phantom::name`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown phantom `{given}`; valid names: sphere, torus, rounded-box, clay-block, teapot, tree"
)]
pub struct ParsePhantomError {
    /// The name that was given.
    pub given: String,
}

impl FromStr for Phantom {
    type Err = ParsePhantomError;

    /// Parse a kebab-case [`Phantom::name`]; ASCII case and surrounding whitespace are ignored
    /// and `_` is accepted for `-`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let norm = s.trim().to_ascii_lowercase().replace('_', "-");
        Self::ALL
            .into_iter()
            .find(|ph| ph.name() == norm)
            .ok_or_else(|| ParsePhantomError {
                given: s.to_owned(),
            })
    }
}

/// The grid on which phantoms are sampled: `dims` voxels whose centres span
/// `[-GRID_EXTENT, GRID_EXTENT] = [-1.1, 1.1]` on each axis (origin −1.1, spacing
/// `2.2 / (n − 1)` along an axis of `n` voxels, identity direction). Physical units are model
/// units. Any dims ≥ 2 are allowed, also non-cubic ones (the spacing then differs per axis).
///
/// # Errors
/// [`VolumeError::Geometry`] if a dimension is below 2, or if the voxel count overflows or
/// exceeds the allocation limit.
pub fn geometry(dims: [usize; 3]) -> Result<Geometry, VolumeError> {
    if dims.iter().any(|&n| n < 2) {
        return Err(VolumeError::Geometry(format!(
            "phantom dims {dims:?} must be at least 2 along every axis"
        )));
    }
    let span = 2.0 * GRID_EXTENT;
    let spacing = DVec3::new(
        span / (dims[0] - 1) as f64,
        span / (dims[1] - 1) as f64,
        span / (dims[2] - 1) as f64,
    );
    let g = Geometry::new(dims)
        .with_spacing(spacing)
        .with_origin(DVec3::splat(-GRID_EXTENT));
    g.validate()?;
    Ok(g)
}

/// Half width `w` of the density ramp on `geometry`, in model units:
/// `RAMP_VOXELS · max(spacing)`.
#[must_use]
pub fn ramp_width(geometry: &Geometry) -> f64 {
    RAMP_VOXELS * geometry.spacing.max_element()
}

/// The density byte for signed distance `sdf` with ramp half width `w` (> 0):
/// `round(clamp(127.5 − 127.5 · sdf / w, 0, 255))`, rounding halves up. So `sdf ≤ −w` gives
/// 255, `sdf ≥ w` gives 0, and the un-quantised ramp passes 127.5 exactly at `sdf = 0` (stored
/// as 128); True's iso value 127 lies `w / 255` outside the zero set. NaN gives 0.
#[inline]
#[must_use]
pub fn density_value(sdf: f64, w: f64) -> u8 {
    ramp(sdf, 127.5 / w)
}

/// `round(clamp(127.5 − sdf · scale, 0, 255))`, halves up; the per-voxel kernel of
/// [`density_value`] with `scale = 127.5 / w` hoisted out of the loop.
#[inline]
fn ramp(sdf: f64, scale: f64) -> u8 {
    let v = (127.5 - sdf * scale).clamp(0.0, 255.0);
    // `v` is in [0, 255] or NaN: adding ½ and truncating rounds half up, and NaN casts to 0.
    (v + 0.5) as u8
}

/// The phantom's signed distance ([`Phantom::sdf`], negative inside) sampled at the voxel
/// centres of [`geometry`]`(dims)`, rounded to `f32`. Computed in parallel over z-slices;
/// bit-identical for any thread count.
///
/// # Errors
/// As [`geometry`]; also if the `f32` volume would exceed the allocation limit.
pub fn signed_distance(ph: Phantom, dims: [usize; 3]) -> Result<Volume<f32>, VolumeError> {
    signed_distance_with(ph, dims, &volmorph_io::NoProgress)
}

/// [`signed_distance`] reporting to `progress`: one stage whose steps are the z-slices,
/// stopping between slices when cancelled. The result equals [`signed_distance`]'s bit for
/// bit.
///
/// # Errors
/// As [`signed_distance`]; [`VolumeError::Cancelled`] when `progress` asks to stop.
pub fn signed_distance_with(
    ph: Phantom,
    dims: [usize; 3],
    progress: &dyn volmorph_io::Progress,
) -> Result<Volume<f32>, VolumeError> {
    let g = geometry(dims)?;
    volmorph_io::checked_len(&dims, size_of::<f32>())?;
    progress.start(&format!("{} signed distance", ph.name()), dims[2] as u64);
    sample(ph, g, |d| d as f32, progress)
}

/// The phantom as True's unsigned-byte density model (§5.1) on [`geometry`]`(dims)`: 255
/// inside, 0 outside, the object at iso value 127 ([`ISO_VALUE`]), antialiased by the ramp of
/// [`density_value`] with half width [`ramp_width`] (1.5 voxels of the coarsest axis).
/// Computed in parallel over z-slices; bit-identical for any thread count.
///
/// # Errors
/// As [`geometry`].
pub fn density(ph: Phantom, dims: [usize; 3]) -> Result<Volume<u8>, VolumeError> {
    density_with(ph, dims, &volmorph_io::NoProgress)
}

/// [`density`] reporting to `progress`: one stage whose steps are the z-slices, stopping
/// between slices when cancelled. The result equals [`density`]'s bit for bit.
///
/// # Errors
/// As [`density`]; [`VolumeError::Cancelled`] when `progress` asks to stop.
pub fn density_with(
    ph: Phantom,
    dims: [usize; 3],
    progress: &dyn volmorph_io::Progress,
) -> Result<Volume<u8>, VolumeError> {
    let g = geometry(dims)?;
    let scale = 127.5 / ramp_width(&g);
    progress.start(&format!("{} density", ph.name()), dims[2] as u64);
    sample(ph, g, |d| ramp(d, scale), progress)
}

/// Evaluate `map(sdf)` at every voxel centre of the axis-aligned grid `g`. The phantom is
/// dispatched once, outside the loop, so each SDF is inlined into its own voxel loop.
fn sample<T: Voxel>(
    ph: Phantom,
    g: Geometry,
    map: impl Fn(f64) -> T + Sync,
    progress: &dyn volmorph_io::Progress,
) -> Result<Volume<T>, VolumeError> {
    match ph {
        Phantom::Sphere => sample_sdf(g, sphere_sdf, map, progress),
        Phantom::Torus => sample_sdf(g, torus_sdf, map, progress),
        Phantom::RoundedBox => sample_sdf(g, rounded_box_sdf, map, progress),
        Phantom::ClayBlock => sample_sdf(g, clay::sdf, map, progress),
        Phantom::Teapot => sample_sdf(g, teapot::sdf, map, progress),
        Phantom::Tree => sample_sdf(g, tree::sdf, map, progress),
    }
}

fn sample_sdf<T: Voxel>(
    g: Geometry,
    sdf: impl Fn(DVec3) -> f64 + Sync,
    map: impl Fn(f64) -> T + Sync,
    progress: &dyn volmorph_io::Progress,
) -> Result<Volume<T>, VolumeError> {
    // Per-axis voxel-centre coordinates, bit-identical to `Geometry::index_to_physical` for an
    // identity direction (the off-diagonal products are +0).
    let axis = |a: usize| -> Vec<f64> {
        (0..g.dims[a])
            .map(|i| g.origin[a] + g.spacing[a] * i as f64)
            .collect()
    };
    let (xs, ys, zs) = (axis(0), axis(1), axis(2));
    let v = Volume::from_fn_with(
        g,
        |i, j, k| map(sdf(DVec3::new(xs[i], ys[j], zs[k]))),
        progress,
    )?;
    progress.check()?;
    Ok(v)
}

/// [`Phantom::Sphere`].
#[inline]
fn sphere_sdf(p: DVec3) -> f64 {
    p.length() - SPHERE_RADIUS
}

/// [`Phantom::Torus`].
#[inline]
fn torus_sdf(p: DVec3) -> f64 {
    torus_z(p, TORUS_MAJOR_RADIUS, TORUS_MINOR_RADIUS)
}

/// [`Phantom::RoundedBox`].
#[inline]
fn rounded_box_sdf(p: DVec3) -> f64 {
    rounded_box(p, ROUNDED_BOX_HALF_EXTENTS, ROUNDED_BOX_RADIUS)
}

// ---------------------------------------------------------------------------------------------
// Primitives. Each returns a 1-Lipschitz signed distance (negative inside); "exact" ones return
// the Euclidean signed distance.

/// Exact: torus around the z axis through the origin.
#[inline]
fn torus_z(p: DVec3, major: f64, minor: f64) -> f64 {
    DVec2::new(p.truncate().length() - major, p.z).length() - minor
}

/// Exact: box of half extents `half` with edges rounded by `radius` (Minkowski sum of the box
/// `half − radius` and a ball), centred at the origin. For a convex set `K` the signed distance
/// to `K ⊕ B(r)` is `sd_K − r`, inside as well as outside.
#[inline]
fn rounded_box(p: DVec3, half: DVec3, radius: f64) -> f64 {
    let q = p.abs() - (half - DVec3::splat(radius));
    q.max(DVec3::ZERO).length() + q.max_element().min(0.0) - radius
}

/// Exact: infinite cylinder along y through `(x0, ·, z0)`.
#[inline]
fn cylinder_y(p: DVec3, x0: f64, z0: f64, radius: f64) -> f64 {
    DVec2::new(p.x - x0, p.z - z0).length() - radius
}

/// Bound: ellipsoid of semi-axes `radii` centred at `c`, as
/// `(|(p − c) / radii| − 1) · min(radii)`. Its gradient has norm ≤ `min(radii) · max(1 / radii)
/// = 1`, and at the surface ≥ `min(radii) / max(radii)`.
#[inline]
fn ellipsoid(p: DVec3, c: DVec3, radii: DVec3) -> f64 {
    // With constant `radii` (all call sites) the reciprocal folds at compile time.
    (((p - c) * radii.recip()).length() - 1.0) * radii.min_element()
}

/// Convex hull of the balls `(a, ra)` and `(b, rb)`: a cone frustum capped by the two spheres.
/// Requires `|ra − rb| < |b − a|` (neither ball contains the other).
///
/// In the half plane `(h, ρ)` (h along the axis from `a`, ρ ≥ 0 the distance to the axis) the
/// boundary is the arc of circle `a`, the tangent segment and the arc of circle `b`; with
/// `sin θ = (ra − rb) / L` the segment has outward normal `n = (sin θ, cos θ)` and direction
/// `d = (cos θ, −sin θ)`, and runs over `0 ≤ (h, ρ)·d ≤ L cos θ`. The three pieces, each a
/// distance of gradient norm 1, meet continuously on the normals through the tangent points,
/// so the result is 1-Lipschitz; outside the hull it is the exact distance.
#[inline]
fn round_cone(p: DVec3, a: DVec3, ra: f64, b: DVec3, rb: f64) -> f64 {
    let axis = b - a;
    let len = axis.length();
    debug_assert!(
        (ra - rb).abs() < len,
        "one ball of the round cone contains the other"
    );
    let e = axis / len;
    let pa = p - a;
    let h = pa.dot(e);
    let rho = (pa - e * h).length();
    let s = (ra - rb) / len;
    let c = (1.0 - s * s).sqrt();
    let u = h * c - rho * s;
    if u < 0.0 {
        DVec2::new(h, rho).length() - ra
    } else if u > len * c {
        DVec2::new(h - len, rho).length() - rb
    } else {
        h * s + rho * c - ra
    }
}

/// Polynomial smooth minimum (smooth union) with blend width `k > 0`:
/// `min(a, b) − max(k − |a − b|, 0)² / (4k)`. Its partial derivatives are in `[0, 1]` and
/// sum to 1, so it maps 1-Lipschitz functions to a 1-Lipschitz function; it equals `min`
/// where `|a − b| ≥ k` and never exceeds it (the blend only adds material).
#[inline]
fn smin(a: f64, b: f64, k: f64) -> f64 {
    let h = (k - (a - b).abs()).max(0.0);
    // With a constant `k` (all call sites) `0.25 / k` folds at compile time.
    a.min(b) - h * h * (0.25 / k)
}

/// Smooth maximum (smooth intersection / difference), `−smin(−a, −b, k)`; only removes
/// material compared with `max`.
#[inline]
fn smax(a: f64, b: f64, k: f64) -> f64 {
    -smin(-a, -b, k)
}

/// The clay block ([`Phantom::ClayBlock`]).
mod clay {
    use glam::DVec3;

    use super::{cylinder_y, rounded_box, smax, smin};

    /// Outer half extents of the slab.
    pub(super) const HALF: DVec3 = DVec3::new(0.75, 0.5, 0.45);
    /// Edge rounding of the slab.
    const EDGE_RADIUS: f64 = 0.12;
    /// Through hole along y: axis at (x, z) = (HOLE_X, 0).
    const HOLE_X: f64 = -0.35;
    const HOLE_RADIUS: f64 = 0.18;
    /// Groove along y in the top face: axis at (x, z) = (GROOVE_X, HALF.z).
    const GROOVE_X: f64 = 0.4;
    const GROOVE_RADIUS: f64 = 0.14;
    /// Bump on the front (−y) face.
    pub(super) const BUMP_CENTER: DVec3 = DVec3::new(0.2, -0.5, -0.1);
    pub(super) const BUMP_RADIUS: f64 = 0.2;
    /// Blend widths ([`smax`]/[`smin`] `k`) of the hole and groove edges and of the bump.
    const CUT_BLEND: f64 = 0.12;
    const BUMP_BLEND: f64 = 0.12;

    pub(super) fn sdf(p: DVec3) -> f64 {
        let slab = rounded_box(p, HALF, EDGE_RADIUS);
        let hole = cylinder_y(p, HOLE_X, 0.0, HOLE_RADIUS);
        let groove = cylinder_y(p, GROOVE_X, HALF.z, GROOVE_RADIUS);
        let bump = (p - BUMP_CENTER).length() - BUMP_RADIUS;
        let d = smax(slab, -hole, CUT_BLEND);
        let d = smax(d, -groove, CUT_BLEND);
        smin(d, bump, BUMP_BLEND)
    }
}

/// The teapot ([`Phantom::Teapot`]), z up, spout towards +x, handle towards −x.
mod teapot {
    use glam::{DVec2, DVec3};

    use super::{ellipsoid, round_cone, smax, smin};

    /// Body: ellipsoid cut flat at the base and open at the top where the lid sits.
    const BODY_CENTER: DVec3 = DVec3::new(0.0, 0.0, -0.1);
    pub(super) const BODY_RADII: DVec3 = DVec3::new(0.5, 0.5, 0.4);
    pub(super) const BASE_Z: f64 = -0.45;
    const SHOULDER_Z: f64 = 0.22;
    /// Lid: a dome, narrower than the opening so that a ledge shows around it.
    const LID_CENTER: DVec3 = DVec3::new(0.0, 0.0, 0.2);
    const LID_RADII: DVec3 = DVec3::new(0.25, 0.25, 0.16);
    /// Knob: a ball resting on the top of the lid, joined to it by a fillet that reads as a
    /// short neck.
    pub(super) const KNOB_CENTER: DVec3 = DVec3::new(0.0, 0.0, 0.45);
    pub(super) const KNOB_RADIUS: f64 = 0.1;
    /// Spout: two tapering segments rooted inside the body, bending upwards.
    const SPOUT_ROOT: DVec3 = DVec3::new(0.36, 0.0, -0.18);
    const SPOUT_ROOT_RADIUS: f64 = 0.12;
    const SPOUT_BEND: DVec3 = DVec3::new(0.6, 0.0, 0.04);
    const SPOUT_BEND_RADIUS: f64 = 0.09;
    pub(super) const SPOUT_TIP: DVec3 = DVec3::new(0.76, 0.0, 0.25);
    pub(super) const SPOUT_TIP_RADIUS: f64 = 0.1;
    /// Handle: a torus in the xz plane (axis along y) whose inner half is inside the body.
    pub(super) const HANDLE_CENTER: DVec3 = DVec3::new(-0.635, 0.0, -0.05);
    pub(super) const HANDLE_MAJOR: f64 = 0.17;
    pub(super) const HANDLE_MINOR: f64 = 0.075;
    /// Blend widths ([`smin`]/[`smax`] `k`) of the base and shoulder edges and of the joints.
    const EDGE_BLEND: f64 = 0.1;
    const LID_BLEND: f64 = 0.06;
    const KNOB_BLEND: f64 = 0.08;
    const SPOUT_BLEND: f64 = 0.08;
    const BEND_BLEND: f64 = 0.06;
    const HANDLE_BLEND: f64 = 0.06;

    pub(super) fn sdf(p: DVec3) -> f64 {
        let body = smax(
            smax(
                ellipsoid(p, BODY_CENTER, BODY_RADII),
                BASE_Z - p.z,
                EDGE_BLEND,
            ),
            p.z - SHOULDER_Z,
            EDGE_BLEND,
        );

        let lid = ellipsoid(p, LID_CENTER, LID_RADII);
        let knob = (p - KNOB_CENTER).length() - KNOB_RADIUS;
        let top = smin(lid, knob, KNOB_BLEND);

        let spout = smin(
            round_cone(
                p,
                SPOUT_ROOT,
                SPOUT_ROOT_RADIUS,
                SPOUT_BEND,
                SPOUT_BEND_RADIUS,
            ),
            round_cone(
                p,
                SPOUT_BEND,
                SPOUT_BEND_RADIUS,
                SPOUT_TIP,
                SPOUT_TIP_RADIUS,
            ),
            BEND_BLEND,
        );

        // Torus around the y axis: the roles of y and z swap.
        let q = p - HANDLE_CENTER;
        let handle =
            DVec2::new(DVec2::new(q.x, q.z).length() - HANDLE_MAJOR, q.y).length() - HANDLE_MINOR;

        let d = smin(body, top, LID_BLEND);
        let d = smin(d, spout, SPOUT_BLEND);
        smin(d, handle, HANDLE_BLEND)
    }
}

/// The tree ([`Phantom::Tree`]).
mod tree {
    use glam::DVec3;

    use super::{TREE_LIMBS, TREE_TWIGS_PER_LIMB, round_cone, smin};

    /// Foot and top of the trunk, and their radii.
    const TRUNK: (DVec3, f64, DVec3, f64) = (
        DVec3::new(0.0, 0.0, -0.75),
        0.13,
        DVec3::new(0.0, 0.0, -0.1),
        0.11,
    );
    /// Limb radii at the fork and at the limb's end.
    const LIMB_RADII: (f64, f64) = (0.1, 0.09);
    /// Horizontal distance and height of a limb's end.
    const LIMB_END: (f64, f64) = (0.4, 0.25);
    /// Twig radii at the limb's end and at the tip.
    const TWIG_RADII: (f64, f64) = (0.085, 0.075);
    /// Horizontal distance and height of a twig's tip, and its azimuth offset (rad).
    const TWIG_TIP: (f64, f64, f64) = (0.7, 0.7, 0.6);
    /// Blend width of the joints.
    const BLEND: f64 = 0.04;

    /// Every segment `(a, ra, b, rb)`: trunk, limbs, twigs.
    fn segments() -> impl Iterator<Item = (DVec3, f64, DVec3, f64)> {
        let fork = TRUNK.2;
        let limbs = (0..TREE_LIMBS).flat_map(move |l| {
            let az = std::f64::consts::TAU * l as f64 / TREE_LIMBS as f64;
            let end = DVec3::new(LIMB_END.0 * az.cos(), LIMB_END.0 * az.sin(), LIMB_END.1);
            let limb = (fork, LIMB_RADII.0, end, LIMB_RADII.1);
            let twigs = (0..TREE_TWIGS_PER_LIMB).map(move |t| {
                let off = if TREE_TWIGS_PER_LIMB == 1 {
                    0.0
                } else {
                    TWIG_TIP.2 * (2.0 * t as f64 / (TREE_TWIGS_PER_LIMB - 1) as f64 - 1.0)
                };
                let a = az + off;
                let tip = DVec3::new(TWIG_TIP.0 * a.cos(), TWIG_TIP.0 * a.sin(), TWIG_TIP.1);
                (end, TWIG_RADII.0, tip, TWIG_RADII.1)
            });
            std::iter::once(limb).chain(twigs)
        });
        std::iter::once(TRUNK).chain(limbs)
    }

    pub(super) fn sdf(p: DVec3) -> f64 {
        segments()
            .map(|(a, ra, b, rb)| round_cone(p, a, ra, b, rb))
            .reduce(|d, e| smin(d, e, BLEND))
            .unwrap_or(f64::INFINITY)
    }

    /// The union of the segments' boxes (each round cone lies in the box of its two balls).
    pub(super) fn bounds() -> (DVec3, DVec3) {
        segments().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), (a, ra, b, rb)| {
                (
                    lo.min(a - DVec3::splat(ra)).min(b - DVec3::splat(rb)),
                    hi.max(a + DVec3::splat(ra)).max(b + DVec3::splat(rb)),
                )
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact: segment `a`–`b` thickened by `radius`.
    #[inline]
    fn capsule(p: DVec3, a: DVec3, b: DVec3, radius: f64) -> f64 {
        let ab = b - a;
        let t = ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
        (p - a - ab * t).length() - radius
    }

    #[test]
    fn names_round_trip_and_errors_list_names() {
        for ph in Phantom::ALL {
            assert_eq!(ph.name().parse::<Phantom>(), Ok(ph));
            assert_eq!(ph.to_string(), ph.name());
            assert!(!ph.description().is_empty());
        }
        assert_eq!(" Clay_Block ".parse::<Phantom>(), Ok(Phantom::ClayBlock));
        let err = "cube".parse::<Phantom>().unwrap_err().to_string();
        assert!(err.contains("cube"), "{err}");
        for ph in Phantom::ALL {
            assert!(err.contains(ph.name()), "{err}");
        }
    }

    #[test]
    fn round_cone_matches_capsule_for_equal_radii_and_ball_hull() {
        let a = DVec3::new(0.1, -0.2, 0.3);
        let b = DVec3::new(-0.4, 0.5, 0.2);
        for i in 0..200 {
            let t = f64::from(i);
            let p = DVec3::new((t * 0.37).sin(), (t * 0.73).cos(), (t * 1.31).sin()) * 1.2;
            let rc = round_cone(p, a, 0.2, b, 0.2);
            assert!((rc - capsule(p, a, b, 0.2)).abs() < 1e-12);
            // The hull of two balls lies between the union of the balls and their capsule
            // of the larger radius.
            let rc = round_cone(p, a, 0.3, b, 0.1);
            let balls = ((p - a).length() - 0.3).min((p - b).length() - 0.1);
            assert!(rc <= balls + 1e-12);
            assert!(rc >= capsule(p, a, b, 0.3) - 1e-12);
        }
    }

    #[test]
    fn smooth_ops_bracket_min_max() {
        for (a, b) in [(0.3, 0.31), (-0.2, 0.5), (0.0, 0.0), (1.0, -1.0)] {
            assert!(smin(a, b, 0.1) <= a.min(b));
            assert!(smax(a, b, 0.1) >= a.max(b));
            if (a - b).abs() >= 0.1 {
                assert_eq!(smin(a, b, 0.1), a.min(b));
            }
        }
    }
}
