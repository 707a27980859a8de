//! Shaded PNG pictures of meshes, shared by `volmorph mesh render`, `volmorph isosurface
//! --png` and the demo. Cameras, framing and shading are `volmorph_render`'s.

use std::path::Path;

use anyhow::Context;
use glam::DVec3;
use volmorph_mesh::{Mesh, MeshColors};
use volmorph_render::{
    Camera, DEFAULT_FOV_Y, Framing, Orbit, Projection, ShadeStyle, SurfaceColors, UpAxis,
    render_triangles_with_colors, write_png_rgba,
};

/// Named directions a picture looks from, for models with z up (`volmorph_render`'s named
/// views of the same names).
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
    /// The render crate's view of the same name, z up.
    fn orbit(self) -> Orbit {
        let name = match self {
            Self::Side => "side",
            Self::Front => "front",
            Self::Top => "top",
            Self::Iso => "iso",
        };
        Orbit::named(name, UpAxis::Z).unwrap_or_else(|| unreachable!("{name} is a named view"))
    }
}

/// A perspective camera looking from `view` that frames the box `[min, max]`.
///
/// # Errors
/// If the box is empty or not finite, or the picture size is invalid.
pub fn camera(view: View, bounds: (DVec3, DVec3), size: (u32, u32)) -> anyhow::Result<Camera> {
    orbit_camera(&view.orbit(), bounds, size)
}

/// The camera of mesh pictures: perspective with the default field of view, looking from
/// `orbit`, the box `[min, max]` framed tightly.
///
/// # Errors
/// If the box is empty or not finite, or the picture size is invalid.
pub fn orbit_camera(
    orbit: &Orbit,
    bounds: (DVec3, DVec3),
    (width, height): (u32, u32),
) -> anyhow::Result<Camera> {
    Ok(orbit.camera(
        bounds,
        Projection::Perspective {
            fov_y: DEFAULT_FOV_Y,
        },
        Framing::Box,
        width,
        height,
    )?)
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
    write_colored_mesh_png(path, mesh, normals, None, camera)
}

/// [`write_mesh_png`] with the mesh's own colours (per vertex, or per face: every fan
/// triangle of a face takes its colour) instead of the default clay and blue when `colors`
/// is given.
///
/// # Errors
/// If the colours do not match the mesh, or the picture cannot be drawn or written.
pub fn write_colored_mesh_png(
    path: &Path,
    mesh: &Mesh,
    normals: Option<&[DVec3]>,
    colors: Option<&MeshColors>,
    camera: &Camera,
) -> anyhow::Result<()> {
    let triangles: Vec<[u32; 3]> = mesh.fan_triangles().collect();
    if let Some(c) = colors {
        c.check(mesh)?;
    }
    let per_triangle: Vec<[u8; 3]>;
    let surface = match colors {
        None => SurfaceColors::Uniform,
        Some(MeshColors::PerVertex(c)) => SurfaceColors::PerVertex(c),
        Some(MeshColors::PerFace(c)) => {
            // Fan triangles come face by face, `len − 2` per face.
            per_triangle = mesh
                .faces()
                .zip(c)
                .flat_map(|(f, &c)| std::iter::repeat_n(c, f.len().saturating_sub(2)))
                .collect();
            SurfaceColors::PerTriangle(&per_triangle)
        }
    };
    let computed;
    let normals = match normals {
        Some(n) => n,
        None => {
            computed = mesh.vertex_normals();
            &computed
        }
    };
    let img = render_triangles_with_colors(
        camera,
        mesh.positions(),
        &triangles,
        Some(normals),
        surface,
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

/// Parse a picture size `WIDTHxHEIGHT` (e.g. `800x600`) or one number for a square.
///
/// # Errors
/// As [`crate::args::size`].
pub fn size(s: &str) -> anyhow::Result<(u32, u32)> {
    crate::args::size(s)
}
