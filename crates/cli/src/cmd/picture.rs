//! Shaded PNG pictures of meshes, shared by `volmorph mesh render`, `volmorph isosurface
//! --png` and the demo.

use std::path::Path;

use anyhow::Context;
use glam::DVec3;
use volmorph_mesh::Mesh;
use volmorph_render::{Camera, Projection, ShadeStyle, render_triangles, write_png_rgba};

/// Direction a picture looks from, for models with z up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum View {
    /// From −y towards +y: x to the right, z up (the teapot's spout points right).
    Side,
    /// From +x towards −x: y to the right, z up.
    Front,
    /// From +z down: x to the right, y up.
    Top,
    /// From the front-right, above: a three-quarter view.
    Iso,
}

impl View {
    /// Unit direction from the model towards the eye, and the picture's up vector.
    fn eye_and_up(self) -> (DVec3, DVec3) {
        match self {
            Self::Side => (DVec3::NEG_Y, DVec3::Z),
            Self::Front => (DVec3::X, DVec3::Z),
            Self::Top => (DVec3::Z, DVec3::Y),
            Self::Iso => (DVec3::new(0.55, -1.0, 0.6).normalize(), DVec3::Z),
        }
    }
}

/// A perspective camera looking from `view` that frames the box `[min, max]`.
///
/// # Errors
/// If the box is empty or not finite, or the picture size is invalid.
pub fn camera(
    view: View,
    (min, max): (DVec3, DVec3),
    (width, height): (u32, u32),
) -> anyhow::Result<Camera> {
    let (dir, up) = view.eye_and_up();
    let centre = 0.5 * (min + max);
    let cam = Camera::look_at(
        centre + dir,
        centre,
        up,
        Projection::Perspective { fov_y: 0.5 },
        width,
        height,
    )?;
    let mut cam = cam.fit_bounds(min, max)?;
    // `fit_bounds` frames the bounding sphere; pull in until the box corners themselves fill
    // ~85% of the narrower picture half-extent (a few fixed-point steps on the distance).
    let corners = volmorph_render::Aabb::new(min, max)?.corners();
    for _ in 0..4 {
        let mut extent: f64 = 0.0;
        for c in corners {
            let (x, y, _) = cam
                .project(c)
                .context("model corner behind the camera while framing")?;
            extent = extent
                .max((2.0 * x / f64::from(width) - 1.0).abs())
                .max((1.0 - 2.0 * y / f64::from(height)).abs());
        }
        let dist = (cam.eye() - centre).length();
        let next = centre - cam.forward() * (dist * extent / 0.85);
        cam = Camera::look_at(next, centre, up, cam.projection(), width, height)?;
    }
    Ok(cam)
}

/// Render `mesh` (any polygons; fan-triangulated) with `normals` per vertex (computed from
/// the faces when `None`) through `camera`, and write it as a PNG at `path`.
///
/// # Errors
/// If the picture cannot be drawn or written.
pub fn write_mesh_png(
    path: &Path,
    mesh: &Mesh,
    normals: Option<&[DVec3]>,
    camera: &Camera,
) -> anyhow::Result<()> {
    let triangles: Vec<[u32; 3]> = mesh.fan_triangles().collect();
    let computed;
    let normals = match normals {
        Some(n) => n,
        None => {
            computed = mesh.vertex_normals();
            &computed
        }
    };
    let img = render_triangles(
        camera,
        mesh.positions(),
        &triangles,
        Some(normals),
        &ShadeStyle::default(),
    )?;
    write_png_rgba(path, &img).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// The bounding box of `mesh`, or an error naming `what` when it has no vertices.
///
/// # Errors
/// If the mesh is empty.
pub fn bounds(mesh: &Mesh, what: &str) -> anyhow::Result<(DVec3, DVec3)> {
    mesh.bounding_box()
        .with_context(|| format!("{what} has no vertices to draw"))
}

/// Parse a picture size `WIDTHxHEIGHT` (e.g. `800x600`).
///
/// # Errors
/// If the text is not two positive integers separated by `x`.
pub fn size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("picture size `{s}` is not WIDTHxHEIGHT"))?;
    let parse = |t: &str| -> anyhow::Result<u32> {
        let v: u32 = t
            .trim()
            .parse()
            .with_context(|| format!("picture size `{s}`: `{t}` is not a whole number"))?;
        anyhow::ensure!(v > 0, "picture size `{s}` must be at least 1x1");
        Ok(v)
    };
    Ok((parse(w)?, parse(h)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(size("800x600").unwrap(), (800, 600));
        assert_eq!(size("12X3").unwrap(), (12, 3));
        for bad in ["800", "0x5", "ax3", "-1x2", "3x"] {
            assert!(size(bad).is_err(), "{bad}");
        }
    }
}
