//! Shaded pictures of polygon meshes: any [`Mesh`] (fan-triangulated) with its own colours or
//! the default clay and blue, through a camera of the presets ([`Orbit::mesh_camera`]), in the
//! one shading model ([`ShadeStyle::default`]). `volmorph mesh render`, `volmorph isosurface
//! --png` and the demo's pictures are these.

use std::path::Path;

use glam::DVec3;
use volmorph_mesh::{Mesh, MeshColors};

use crate::{
    Camera, Framing, Orbit, RenderError, RgbaImage, ShadeStyle, SurfaceColors,
    render_triangles_with_colors, write_png_rgba,
};

impl Orbit {
    /// The camera of mesh pictures: perspective with [`DEFAULT_FOV_Y`](crate::DEFAULT_FOV_Y), looking from this
    /// orbit at the box `[min, max]` (physical units), framed tightly ([`Framing::Box`]), for a
    /// `width × height` picture in pixels.
    ///
    /// # Errors
    /// As [`Orbit::camera`]: an empty or non-finite box, or an invalid picture size.
    pub fn mesh_camera(
        &self,
        bounds: (DVec3, DVec3),
        size: (u32, u32),
    ) -> Result<Camera, RenderError> {
        self.perspective_camera(bounds, Framing::Box, size)
    }
}

/// The shaded picture of `mesh` (any polygons; fan-triangulated) through `camera`, with
/// `normals` per vertex (computed from the faces, [`Mesh::vertex_normals`], when `None`) and
/// the mesh's own `colors` (per vertex, or per face: every fan triangle of a face takes its
/// colour) instead of the default clay front and blue back faces when given.
///
/// # Errors
/// [`RenderError::InvalidArgument`] when the colours do not match the mesh; the errors of
/// [`render_triangles_with_colors`] (normals of the wrong length, an invalid style).
pub fn render_mesh(
    camera: &Camera,
    mesh: &Mesh,
    normals: Option<&[DVec3]>,
    colors: Option<&MeshColors>,
    style: &ShadeStyle,
) -> Result<RgbaImage, RenderError> {
    if let Some(c) = colors {
        c.check(mesh)
            .map_err(|e| RenderError::invalid(format!("mesh colours: {e}")))?;
    }
    let triangles: Vec<[u32; 3]> = mesh.fan_triangles().collect();
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
    render_triangles_with_colors(
        camera,
        mesh.positions(),
        &triangles,
        Some(normals),
        surface,
        style,
    )
}

/// [`render_mesh`] with the default [`ShadeStyle`], written atomically as a PNG at `path`.
///
/// # Errors
/// [`RenderError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in
/// `.png` ([`crate::check_png`]), before anything is drawn; as [`render_mesh`], and
/// [`write_png_rgba`]'s; errors name `path`.
pub fn write_mesh_png(
    path: &Path,
    mesh: &Mesh,
    normals: Option<&[DVec3]>,
    colors: Option<&MeshColors>,
    camera: &Camera,
) -> Result<(), RenderError> {
    crate::check_png(path)?;
    let img = render_mesh(camera, mesh, normals, colors, &ShadeStyle::default())
        .map_err(|e| e.at(path))?;
    write_png_rgba(path, &img).map_err(|e| e.at(path))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::UpAxis;

    fn tetrahedron() -> Mesh {
        let p = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(0.0, 0.0, 1.0),
        ];
        Mesh::from_triangles(p, &[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]).unwrap()
    }

    #[test]
    fn per_face_colours_paint_the_faces_and_wrong_counts_are_refused() {
        let m = tetrahedron();
        let orbit = Orbit::named("iso", UpAxis::Z).unwrap();
        let cam = orbit
            .mesh_camera(m.bounding_box().unwrap(), (64, 48))
            .unwrap();
        let red = MeshColors::PerFace(vec![[255, 0, 0]; 4]);
        let img = render_mesh(&cam, &m, None, Some(&red), &ShadeStyle::default()).unwrap();
        let background = ShadeStyle::default().background;
        let covered: Vec<_> = img.pixels().iter().filter(|&&p| p != background).collect();
        assert!(!covered.is_empty());
        // Shading only scales the colour: red stays the strongest channel everywhere.
        assert!(covered.iter().all(|p| p[0] >= p[1] && p[0] >= p[2]));
        let uniform = render_mesh(&cam, &m, None, None, &ShadeStyle::default()).unwrap();
        assert_ne!(uniform.pixels(), img.pixels());
        let short = MeshColors::PerFace(vec![[255, 0, 0]; 3]);
        assert!(render_mesh(&cam, &m, None, Some(&short), &ShadeStyle::default()).is_err());
    }
}
