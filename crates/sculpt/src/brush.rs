//! Brushes: tools of unit reach about their local origin, so that the scale of a [`Pose`]
//! is the brush's size.
//!
//! A brush's *size* is its reach: the radius of the smallest sphere about the pose's point
//! that holds the brush (a sphere brush of size `s` is the ball of radius `s`; a box brush of
//! size `s` is the cube whose corners lie at distance `s`, half-edge `s/√3`; a mesh brush is
//! centred at the centre of its bounding box). Interactive front-ends place a brush with
//! [`Pose`]`{ translation: point, scale: size, .. }` and draw the tool-radius sphere of the
//! same size around the cursor.
//!
//! [`Pose`]: crate::Pose

use std::sync::{Arc, OnceLock};

use glam::DVec3;
use volmorph_mesh::Mesh;
use volmorph_mesh::shapes::{cuboid, icosphere};

use crate::SculptError;
use crate::tool::Tool;

/// Subdivision level of the sphere brush's icosphere (1280 triangles: within 0.3 % of the
/// sphere's radius, and a convex tool, so dabs take the two-layer fast path).
pub const SPHERE_BRUSH_LEVEL: u32 = 3;

/// The built-in brush shapes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BrushShape {
    /// A ball (an icosphere of [`SPHERE_BRUSH_LEVEL`]).
    Sphere,
    /// An axis-aligned cube (12 triangles).
    Box,
}

/// The brush of `shape` with unit reach. Built once per process and shared: brushes of one
/// shape are the same `Arc` (front-ends may compare them with [`Arc::ptr_eq`]).
#[must_use]
pub fn brush(shape: BrushShape) -> Arc<Tool> {
    static SPHERE: OnceLock<Arc<Tool>> = OnceLock::new();
    static CUBE: OnceLock<Arc<Tool>> = OnceLock::new();
    let (cell, make): (_, fn() -> Result<Mesh, volmorph_mesh::MeshError>) = match shape {
        BrushShape::Sphere => (&SPHERE, || icosphere(SPHERE_BRUSH_LEVEL, 1.0, DVec3::ZERO)),
        BrushShape::Box => (&CUBE, || {
            let h = 1.0 / 3f64.sqrt();
            cuboid(DVec3::splat(-h), DVec3::splat(h))
        }),
    };
    cell.get_or_init(|| {
        // Fixed, valid shapes: neither step can fail.
        let mesh = make().expect("the built-in brush shapes are valid");
        Arc::new(Tool::new(&mesh).expect("the built-in brush shapes are closed"))
    })
    .clone()
}

/// A brush from any closed mesh: moved so that the centre of its bounding box is the local
/// origin and scaled to unit reach (its farthest vertex at distance 1).
///
/// # Errors
/// [`SculptError::InvalidMesh`] (role `"brush"`) for a mesh without vertices or with all
/// vertices at one point, or non-finite coordinates; as [`Tool::new`] for a mesh that is not
/// closed.
pub fn unit_brush(mesh: &Mesh) -> Result<Tool, SculptError> {
    let bad = |reason: &str| SculptError::InvalidMesh {
        role: "brush",
        reason: reason.into(),
    };
    let (lo, hi) = mesh
        .bounding_box()
        .ok_or_else(|| bad("it has no vertices"))?;
    if !(lo.is_finite() && hi.is_finite()) {
        return Err(bad("a vertex is not finite"));
    }
    let centre = 0.5 * (lo + hi);
    let reach = mesh
        .positions()
        .iter()
        .map(|p| (*p - centre).length())
        .fold(0.0, f64::max);
    if !(reach > 0.0 && reach.is_finite()) {
        return Err(bad("all its vertices are at one point"));
    }
    let mut unit = mesh.clone();
    for p in unit.positions_mut() {
        *p = (*p - centre) / reach;
    }
    Tool::new(&unit)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brushes_have_unit_reach_and_are_shared() {
        for shape in [BrushShape::Sphere, BrushShape::Box] {
            let b = brush(shape);
            assert!(
                (b.radius() - 1.0).abs() < 1e-12,
                "{shape:?}: {}",
                b.radius()
            );
            assert!(b.is_convex(), "{shape:?}");
            assert!(Arc::ptr_eq(&b, &brush(shape)));
        }
        assert!(!Arc::ptr_eq(
            &brush(BrushShape::Sphere),
            &brush(BrushShape::Box)
        ));
    }

    #[test]
    fn a_mesh_brush_is_centred_and_scaled_to_unit_reach() {
        // A box off the origin, twice as long in x: its centre goes to the origin and its
        // corners to distance 1.
        let m = cuboid(DVec3::new(3.0, 1.0, 1.0), DVec3::new(7.0, 3.0, 3.0)).unwrap();
        let t = unit_brush(&m).unwrap();
        assert!((t.radius() - 1.0).abs() < 1e-12);
        let s = t.soup();
        let (lo, hi) = s
            .positions
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            });
        assert!((lo + hi).length() < 1e-12, "{lo} {hi}");
        let corner = DVec3::new(2.0, 1.0, 1.0) / 6f64.sqrt();
        assert!((hi - corner).length() < 1e-12, "{hi}");
    }

    #[test]
    fn degenerate_brush_meshes_are_refused_by_name() {
        let e = unit_brush(&Mesh::new()).unwrap_err();
        assert!(e.to_string().contains("brush"), "{e}");
    }
}
