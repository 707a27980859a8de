//! Shaded pictures of triangle meshes by z-buffer rasterisation.
//!
//! [`render_triangles`] draws the triangles `positions[t[0]], positions[t[1]], positions[t[2]]`
//! as seen by a [`Camera`], with a depth buffer, the project's one shading model
//! ([`Shading`]: Blinn–Phong from a light fixed to the camera) and optional supersampling.
//! It is the picture of an isosurface or a deformed mesh that the command-line tool writes
//! next to the mesh files.
//!
//! # Conventions
//!
//! * A triangle is **front-facing** when its vertices appear counter-clockwise on the picture,
//!   i.e. its right-handed normal `(b − a) × (c − a)` points towards the camera. Front faces are
//!   drawn in [`ShadeStyle::front`], back faces in [`ShadeStyle::back`], so an inverted or
//!   inconsistently oriented mesh shows at a glance (as Blender's face-orientation overlay).
//! * With per-vertex `normals` the shading normal is interpolated across the triangle
//!   (perspective-correct) and turned towards the viewer; without, the face normal is used
//!   (flat shading).
//! * Coverage: a pixel sample belongs to a triangle when it lies inside or **on** all three
//!   edges, so triangles sharing an edge leave no crack between them (the depth test decides
//!   between the two).
//! * Triangles with a vertex behind the camera (or with a non-finite vertex) are skipped:
//!   there is no near-plane clipping, so frame the model in front of the camera
//!   ([`Camera::frame`]).
//! * Shading is computed in linear light, with the direction to the viewer taken per sample
//!   (exact highlights for perspective cameras), and encoded to sRGB after the supersamples
//!   are averaged.
//!
//! Rasterisation runs in parallel over horizontal bands of the picture; each band walks only
//! the triangles binned to it.

use glam::DVec3;
use rayon::prelude::*;

use crate::shading::{Lighting, Shading, linear_to_srgb8, srgb8_to_linear};
use crate::{Camera, Projection, RenderError, RgbaImage};

/// Picture rows (after supersampling) per parallel band.
const BAND_ROWS: usize = 16;

/// Largest supersampling factor accepted by [`ShadeStyle::supersample`].
pub const MAX_SUPERSAMPLE: u32 = 4;

/// How [`render_triangles`] colours a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadeStyle {
    /// sRGB colour of front faces (counter-clockwise on the picture).
    pub front: [u8; 3],
    /// sRGB colour of back faces.
    pub back: [u8; 3],
    /// Colour of pixels no triangle covers (straight alpha).
    pub background: [u8; 4],
    /// Light and material of the shading model (light in camera coordinates).
    pub shading: Shading,
    /// Samples per pixel along each axis, `1..=`[`MAX_SUPERSAMPLE`]; `2` gives 4× antialiasing.
    pub supersample: u32,
}

impl Default for ShadeStyle {
    /// Warm clay front faces, blue back faces, white background, light from the upper left
    /// behind the viewer, 2 × 2 supersampling.
    fn default() -> Self {
        Self {
            front: [222, 184, 135],
            back: [70, 110, 200],
            background: [255, 255, 255, 255],
            shading: Shading::default(),
            supersample: 2,
        }
    }
}

impl ShadeStyle {
    fn validate(&self) -> Result<(), RenderError> {
        self.shading.validate()?;
        if !(1..=MAX_SUPERSAMPLE).contains(&self.supersample) {
            return Err(RenderError::invalid(format!(
                "supersample {} must lie in 1..={MAX_SUPERSAMPLE}",
                self.supersample
            )));
        }
        Ok(())
    }
}

/// A triangle projected to the (supersampled) picture.
#[derive(Debug, Clone, Copy)]
struct Projected {
    /// Picture coordinates `(x, y)` and `1/w` per vertex (`w` = depth for perspective, 1 for
    /// orthographic), for perspective-correct interpolation.
    v: [(f64, f64, f64); 3],
    /// View depth per vertex (z-buffer key, smaller is nearer).
    depth: [f64; 3],
    /// Signed doubled area in picture coordinates (y down): negative = counter-clockwise on
    /// screen = front-facing.
    area: f64,
    /// Triangle index.
    index: u32,
}

/// Draw `triangles` (vertex indices into `positions`) as seen by `camera`, shaded as `style`
/// says.
///
/// * A triangle is **front-facing** when its vertices appear counter-clockwise on the
///   picture (its right-handed normal points towards the camera); front faces take
///   [`ShadeStyle::front`], back faces [`ShadeStyle::back`].
/// * A pixel sample inside or on all three edges is covered, so triangles sharing an edge
///   leave no crack; a depth buffer keeps the nearest surface.
/// * Shading is the project's [`Shading`] model (light fixed to the camera, linear light),
///   with the shading normal (interpolated from `normals`, else the face normal) turned
///   towards the viewer.
/// * Triangles with a vertex behind the camera or not finite are skipped (no near-plane
///   clipping: frame the model with [`Camera::frame`]).
///
/// `normals`, if given, holds one shading normal per vertex (same length as `positions`; need
/// not be unit length).
///
/// ```
/// use glam::DVec3;
/// use volmorph_render::{Camera, Projection, ShadeStyle, render_triangles};
/// // A square of two triangles facing a camera on +z fills the middle of the picture.
/// let cam = Camera::look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, DVec3::Y,
///                           Projection::Orthographic { view_height: 4.0 }, 40, 40).unwrap();
/// let p = [DVec3::new(-1.0, -1.0, 0.0), DVec3::new(1.0, -1.0, 0.0),
///          DVec3::new(1.0, 1.0, 0.0), DVec3::new(-1.0, 1.0, 0.0)];
/// let img = render_triangles(&cam, &p, &[[0, 1, 2], [0, 2, 3]], None,
///                            &ShadeStyle::default()).unwrap();
/// let background = ShadeStyle::default().background;
/// assert_ne!(img.get(20, 20), Some(background)); // centre: covered
/// assert_eq!(img.get(2, 2), Some(background)); // corner: empty
/// ```
///
/// # Errors
/// [`RenderError::InvalidArgument`] for a vertex index out of range, a `normals` slice of the
/// wrong length, or an invalid style; [`RenderError::Size`] if the supersampled picture is
/// too large.
pub fn render_triangles(
    camera: &Camera,
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    normals: Option<&[DVec3]>,
    style: &ShadeStyle,
) -> Result<RgbaImage, RenderError> {
    render_triangles_with_colors(
        camera,
        positions,
        triangles,
        normals,
        SurfaceColors::Uniform,
        style,
    )
}

/// Colours of the surface drawn by [`render_triangles_with_colors`] (8-bit sRGB).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SurfaceColors<'a> {
    /// [`ShadeStyle::front`] on front faces and [`ShadeStyle::back`] on back faces.
    Uniform,
    /// One colour per vertex (same length as the positions), interpolated across each
    /// triangle in linear light (perspective-correct); both sides of a face take it.
    PerVertex(&'a [[u8; 3]]),
    /// One colour per triangle (same length as the triangles); both sides take it.
    PerTriangle(&'a [[u8; 3]]),
}

/// [`render_triangles`] with the surface coloured by `colors`: attribute colours of a mesh
/// (for instance a colour-mapped cut written as PLY) shaded by the same model. With vertex or
/// triangle colours both sides of a face show the colour (a cut plane seen from behind still
/// shows its attribute); the shading is unchanged.
///
/// # Errors
/// As [`render_triangles`], and [`RenderError::InvalidArgument`] when `colors` does not hold
/// one colour per vertex or triangle.
pub fn render_triangles_with_colors(
    camera: &Camera,
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    normals: Option<&[DVec3]>,
    colors: SurfaceColors<'_>,
    style: &ShadeStyle,
) -> Result<RgbaImage, RenderError> {
    style.validate()?;
    let lin =
        |c: &[[u8; 3]]| -> Vec<[f64; 3]> { c.iter().map(|c| c.map(srgb8_to_linear)).collect() };
    let colors = match colors {
        SurfaceColors::Uniform => LinearColors::Uniform,
        SurfaceColors::PerVertex(c) => {
            if c.len() != positions.len() {
                return Err(RenderError::invalid(format!(
                    "{} vertex colours for {} vertices",
                    c.len(),
                    positions.len()
                )));
            }
            LinearColors::PerVertex(lin(c))
        }
        SurfaceColors::PerTriangle(c) => {
            if c.len() != triangles.len() {
                return Err(RenderError::invalid(format!(
                    "{} triangle colours for {} triangles",
                    c.len(),
                    triangles.len()
                )));
            }
            LinearColors::PerTriangle(lin(c))
        }
    };
    if let Some(n) = normals
        && n.len() != positions.len()
    {
        return Err(RenderError::invalid(format!(
            "{} normals for {} vertices",
            n.len(),
            positions.len()
        )));
    }
    if let Some((t, v)) = triangles.iter().enumerate().find_map(|(t, tri)| {
        tri.iter()
            .find(|&&v| v as usize >= positions.len())
            .map(|&v| (t, v))
    }) {
        return Err(RenderError::invalid(format!(
            "triangle {t} refers to vertex {v}, but there are {} vertices",
            positions.len()
        )));
    }
    let s = style.supersample;
    let (w, h) = (camera.width(), camera.height());
    let (sw, sh) = (
        w.checked_mul(s)
            .ok_or_else(|| RenderError::invalid("supersampled width overflows"))?,
        h.checked_mul(s)
            .ok_or_else(|| RenderError::invalid("supersampled height overflows"))?,
    );
    crate::image::pixel_count(sw.into(), sh.into(), 16)?;
    let mut cam = *camera;
    cam.resize(sw, sh);

    let projected: Vec<Option<(f64, f64, f64)>> =
        positions.par_iter().map(|&p| cam.project(p)).collect();
    let perspective = matches!(cam.projection(), Projection::Perspective { .. });
    let tris: Vec<Projected> = triangles
        .iter()
        .enumerate()
        .filter_map(|(t, tri)| {
            let mut v = [(0.0, 0.0, 0.0); 3];
            let mut depth = [0.0; 3];
            for c in 0..3 {
                let (x, y, d) = projected[tri[c] as usize]?;
                if perspective && d <= 0.0 {
                    return None;
                }
                v[c] = (x, y, if perspective { 1.0 / d } else { 1.0 });
                depth[c] = d;
            }
            let area = edge(v[0], v[1], (v[2].0, v[2].1));
            (area != 0.0 && area.is_finite()).then_some(Projected {
                v,
                depth,
                area,
                index: t as u32,
            })
        })
        .collect();

    // Bin triangles to bands by their vertical extent.
    let (swu, shu) = (sw as usize, sh as usize);
    let bands = shu.div_ceil(BAND_ROWS);
    let mut binned: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (n, t) in tris.iter().enumerate() {
        let ymin = t.v.iter().map(|v| v.1).fold(f64::INFINITY, f64::min);
        let ymax = t.v.iter().map(|v| v.1).fold(f64::NEG_INFINITY, f64::max);
        let Some((r0, r1)) = pixel_span(ymin, ymax, shu) else {
            continue;
        };
        for b in &mut binned[r0 / BAND_ROWS..=r1 / BAND_ROWS] {
            b.push(n as u32);
        }
    }

    let shader = Shader::new(&cam, style)?;
    let background = style.background;
    let bg_linear = [
        srgb8_to_linear(background[0]),
        srgb8_to_linear(background[1]),
        srgb8_to_linear(background[2]),
    ];
    // Per sample: linear colour and coverage (alpha 0 = background).
    let mut samples = vec![[0.0f32; 4]; swu * shu];
    samples
        .par_chunks_mut(BAND_ROWS * swu)
        .zip(binned.par_iter())
        .enumerate()
        .for_each(|(b, (band, list))| {
            let y0 = b * BAND_ROWS;
            let rows = band.len() / swu;
            let mut depth = vec![f64::INFINITY; band.len()];
            for &n in list {
                let t = &tris[n as usize];
                raster_triangle(
                    t,
                    (y0, rows, swu),
                    band,
                    &mut depth,
                    (positions, triangles, normals),
                    &colors,
                    &shader,
                );
            }
        });

    // Average the s × s samples of each pixel over the background, then encode.
    let ss = s as usize;
    let inv = 1.0 / (ss * ss) as f64;
    let mut out = RgbaImage::new(w, h, background)?;
    out.pixels_mut()
        .par_chunks_mut(w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, px) in row.iter_mut().enumerate() {
                let mut acc = [0.0f64; 3];
                let mut cover = 0.0f64;
                for sy in 0..ss {
                    let line = &samples[(y * ss + sy) * swu + x * ss..][..ss];
                    for smp in line {
                        let a = f64::from(smp[3]);
                        for c in 0..3 {
                            acc[c] += f64::from(smp[c]) * a + bg_linear[c] * (1.0 - a);
                        }
                        cover += a;
                    }
                }
                if cover == 0.0 {
                    continue;
                }
                let alpha = f64::from(background[3]) / 255.0;
                let a = cover * inv + (1.0 - cover * inv) * alpha;
                *px = [
                    linear_to_srgb8(acc[0] * inv),
                    linear_to_srgb8(acc[1] * inv),
                    linear_to_srgb8(acc[2] * inv),
                    (a * 255.0).round() as u8,
                ];
            }
        });
    Ok(out)
}

/// Doubled signed area of `(a, b, p)` in picture coordinates (y down).
#[inline]
fn edge(a: (f64, f64, f64), b: (f64, f64, f64), p: (f64, f64)) -> f64 {
    (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0)
}

/// Rows/columns `r0..=r1` of `0..n` whose sample centres `r + ½` lie in `[lo, hi]`.
fn pixel_span(lo: f64, hi: f64, n: usize) -> Option<(usize, usize)> {
    let a = (lo - 0.5).ceil().max(0.0);
    let b = (hi - 0.5).floor().min(n as f64 - 1.0);
    (a <= b).then_some((a as usize, b as usize))
}

/// Surface colours in linear light.
enum LinearColors {
    Uniform,
    PerVertex(Vec<[f64; 3]>),
    PerTriangle(Vec<[f64; 3]>),
}

/// The shading model resolved for the picture's camera, and the face colours in linear light.
struct Shader {
    lighting: Lighting,
    camera: Camera,
    front: [f64; 3],
    back: [f64; 3],
}

impl Shader {
    fn new(cam: &Camera, style: &ShadeStyle) -> Result<Self, RenderError> {
        let lin = |c: [u8; 3]| c.map(srgb8_to_linear);
        Ok(Self {
            lighting: style.shading.for_camera(cam)?,
            camera: *cam,
            front: lin(style.front),
            back: lin(style.back),
        })
    }

    /// Linear colour of the surface of linear base colour `base` seen at sample `(x, y)` of
    /// the picture with normal `n`.
    fn shade(&self, x: f64, y: f64, n: DVec3, base: [f64; 3]) -> [f32; 4] {
        let to_viewer = -self.camera.ray_at(x, y).dir;
        let c = self.lighting.shade(base, n, to_viewer);
        [c[0] as f32, c[1] as f32, c[2] as f32, 1.0]
    }
}

/// Rasterise one triangle into a band of `rows` sample rows starting at row `y0`.
#[allow(clippy::too_many_arguments)]
fn raster_triangle(
    t: &Projected,
    (y0, rows, width): (usize, usize, usize),
    band: &mut [[f32; 4]],
    depth: &mut [f64],
    (positions, triangles, normals): (&[DVec3], &[[u32; 3]], Option<&[DVec3]>),
    colors: &LinearColors,
    shader: &Shader,
) {
    let [a, b, c] = t.v;
    let xmin = a.0.min(b.0).min(c.0);
    let xmax = a.0.max(b.0).max(c.0);
    let ymin = a.1.min(b.1).min(c.1).max(y0 as f64);
    let ymax = a.1.max(b.1).max(c.1).min((y0 + rows) as f64);
    let (Some((x0, x1)), Some((r0, r1))) = (
        pixel_span(xmin, xmax, width),
        pixel_span(ymin, ymax, y0 + rows),
    ) else {
        return;
    };
    let front = t.area < 0.0;
    let inv_area = 1.0 / t.area;
    let tri = triangles[t.index as usize];
    let face_normal = {
        let [p0, p1, p2] = tri.map(|v| positions[v as usize]);
        (p1 - p0).cross(p2 - p0)
    };
    let vn = normals.map(|n| tri.map(|v| n[v as usize]));
    let uniform = if front { shader.front } else { shader.back };
    let flat = match colors {
        LinearColors::PerTriangle(c) => c[t.index as usize],
        _ => uniform,
    };
    let vc = match colors {
        LinearColors::PerVertex(c) => Some(tri.map(|v| c[v as usize])),
        _ => None,
    };
    for y in r0.max(y0)..=r1 {
        let py = y as f64 + 0.5;
        let row = (y - y0) * width;
        for x in x0..=x1 {
            let p = (x as f64 + 0.5, py);
            // Barycentric weights (screen space), all ≥ 0 inside or on the edges.
            let l0 = edge(b, c, p) * inv_area;
            let l1 = edge(c, a, p) * inv_area;
            let l2 = edge(a, b, p) * inv_area;
            if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                continue;
            }
            // Perspective-correct weights from the interpolated 1/w.
            let (q0, q1, q2) = (l0 * a.2, l1 * b.2, l2 * c.2);
            let qs = q0 + q1 + q2;
            let (m0, m1, m2) = (q0 / qs, q1 / qs, q2 / qs);
            let d = m0 * t.depth[0] + m1 * t.depth[1] + m2 * t.depth[2];
            let slot = row + x;
            if d >= depth[slot] {
                continue;
            }
            depth[slot] = d;
            let n = match vn {
                Some([n0, n1, n2]) => (m0 * n0 + m1 * n1 + m2 * n2).normalize_or(face_normal),
                None => face_normal,
            }
            .normalize_or(-shader.camera.forward());
            let base = match vc {
                Some([c0, c1, c2]) => [0, 1, 2].map(|k| m0 * c0[k] + m1 * c1[k] + m2 * c2[k]),
                None => flat,
            };
            band[slot] = shader.shade(p.0, p.1, n, base);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ortho(w: u32, h: u32, view_height: f64) -> Camera {
        Camera::look_at(
            DVec3::new(0.0, 0.0, 10.0),
            DVec3::ZERO,
            DVec3::Y,
            Projection::Orthographic { view_height },
            w,
            h,
        )
        .unwrap()
    }

    fn style1() -> ShadeStyle {
        ShadeStyle {
            supersample: 1,
            shading: Shading {
                specular: 0.0,
                ..Shading::default()
            },
            ..ShadeStyle::default()
        }
    }

    /// A unit icosphere refined `level` times, outward-oriented (counter-clockwise seen from
    /// outside): `volmorph_mesh::shapes::icosphere` as positions and triangles.
    fn icosphere(level: usize) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let level = u32::try_from(level).expect("small level");
        let m = volmorph_mesh::shapes::icosphere(level, 1.0, DVec3::ZERO).expect("icosphere");
        (m.positions().to_vec(), m.fan_triangles().collect())
    }

    #[test]
    fn closed_sphere_has_no_cracks_and_only_front_faces() {
        let (p, f) = icosphere(3);
        let (w, h) = (101, 101);
        let cam = ortho(w, h, 2.5);
        let style = style1();
        let img = render_triangles(&cam, &p, &f, Some(&p), &style).unwrap();
        let bg = style.background;
        // The silhouette of the inscribed polyhedron has radius ≥ cos(edge half-angle) ≈ 0.99;
        // every pixel centre well inside must be covered, every one outside the sphere empty.
        let px = 2.5 / f64::from(h);
        let mut covered = 0;
        for y in 0..h {
            for x in 0..w {
                let cx = (f64::from(x) + 0.5) * px - 1.25;
                let cy = 1.25 - (f64::from(y) + 0.5) * px;
                let r = (cx * cx + cy * cy).sqrt();
                let c = img.get(x, y).unwrap();
                if r < 0.97 {
                    assert_ne!(c, bg, "crack at pixel ({x}, {y})");
                    // Front colour dominates (reddish clay, not blue back faces).
                    assert!(c[0] > c[2], "back face visible at ({x}, {y}): {c:?}");
                    covered += 1;
                } else if r > 1.0 + px {
                    assert_eq!(c, bg, "pixel ({x}, {y}) outside the sphere is drawn");
                }
            }
        }
        assert!(covered > 4500, "{covered} pixels covered");
    }

    #[test]
    fn nearer_triangle_wins_whatever_the_order() {
        let cam = ortho(20, 20, 4.0);
        let near = [
            DVec3::new(-1.0, -1.0, 1.0),
            DVec3::new(1.0, -1.0, 1.0),
            DVec3::new(0.0, 1.0, 1.0),
        ];
        let far = near.map(|p| p - DVec3::new(0.0, 0.0, 2.0));
        let pts: Vec<DVec3> = near.iter().chain(far.iter()).copied().collect();
        // Near triangle front-facing (CCW seen from +z), far one back-facing: colours differ.
        let style = style1();
        let a = render_triangles(&cam, &pts, &[[0, 1, 2], [3, 5, 4]], None, &style).unwrap();
        let b = render_triangles(&cam, &pts, &[[3, 5, 4], [0, 1, 2]], None, &style).unwrap();
        assert_eq!(a, b);
        let c = a.get(10, 11).unwrap();
        assert!(c[0] > c[2], "the far back face shows through: {c:?}");
        // Only the far triangle: the back colour.
        let back = render_triangles(&cam, &pts, &[[3, 5, 4]], None, &style).unwrap();
        let c = back.get(10, 11).unwrap();
        assert!(c[2] > c[0], "back face not drawn in the back colour: {c:?}");
    }

    #[test]
    fn perspective_depth_is_interpolated_correctly() {
        // A large tilted square and a small square just in front of it: with correct
        // perspective depth the small one is visible where it is nearer.
        let cam = Camera::look_at(
            DVec3::new(0.0, 0.0, 5.0),
            DVec3::ZERO,
            DVec3::Y,
            Projection::Perspective { fov_y: 0.8 },
            64,
            64,
        )
        .unwrap();
        let big = [
            DVec3::new(-2.0, -2.0, -2.0),
            DVec3::new(2.0, -2.0, 2.0),
            DVec3::new(2.0, 2.0, 2.0),
            DVec3::new(-2.0, 2.0, -2.0),
        ];
        // Small square at x ≈ 1 slightly in front of the big one (big has z = x there).
        let small = [
            DVec3::new(0.9, -0.1, 1.05),
            DVec3::new(1.1, -0.1, 1.05),
            DVec3::new(1.1, 0.1, 1.05),
            DVec3::new(0.9, 0.1, 1.05),
        ];
        let pts: Vec<DVec3> = big.iter().chain(small.iter()).copied().collect();
        let style = ShadeStyle {
            front: [255, 0, 0],
            ..style1()
        };
        // Small square wound clockwise → back colour, so it is distinguishable.
        let img = render_triangles(
            &cam,
            &pts,
            &[[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]],
            None,
            &style,
        )
        .unwrap();
        let (x, y, _) = cam.project(DVec3::new(1.0, 0.0, 1.05)).unwrap();
        let c = img.get(x as u32, y as u32).unwrap();
        assert!(c[2] > c[0], "the nearer small square is hidden: {c:?}");
    }

    #[test]
    fn bad_input_is_an_error() {
        let cam = ortho(8, 8, 2.0);
        let p = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let style = ShadeStyle::default();
        assert!(render_triangles(&cam, &p, &[[0, 1, 3]], None, &style).is_err());
        assert!(render_triangles(&cam, &p, &[[0, 1, 2]], Some(&p[..2]), &style).is_err());
        for bad in [
            ShadeStyle {
                supersample: 0,
                ..style
            },
            ShadeStyle {
                shading: Shading {
                    light: DVec3::ZERO,
                    ..style.shading
                },
                ..style
            },
            ShadeStyle {
                shading: Shading {
                    ambient: f64::NAN,
                    ..style.shading
                },
                ..style
            },
        ] {
            assert!(render_triangles(&cam, &p, &[[0, 1, 2]], None, &bad).is_err());
        }
        // Non-finite vertices are skipped, not a panic.
        let q = [DVec3::ZERO, DVec3::X, DVec3::splat(f64::NAN)];
        let img = render_triangles(&cam, &q, &[[0, 1, 2]], None, &style).unwrap();
        assert!(img.pixels().iter().all(|&c| c == style.background));
    }

    #[test]
    fn supersampling_softens_edges_only() {
        let cam = ortho(16, 16, 2.0);
        let p = [
            DVec3::new(-0.9, -0.9, 0.0),
            DVec3::new(0.93, -0.9, 0.0),
            DVec3::new(-0.9, 0.77, 0.0),
        ];
        let s1 = render_triangles(&cam, &p, &[[0, 1, 2]], None, &style1()).unwrap();
        let s4 = render_triangles(
            &cam,
            &p,
            &[[0, 1, 2]],
            None,
            &ShadeStyle {
                supersample: 4,
                ..style1()
            },
        )
        .unwrap();
        // Interior pixels agree; some edge pixels are blends (neither background nor fill).
        assert_eq!(s1.get(3, 12), s4.get(3, 12));
        let fill = s1.get(3, 12).unwrap();
        let bg = style1().background;
        assert!(s4.pixels().iter().any(|&c| c != fill && c != bg));
    }

    #[test]
    fn vertex_and_triangle_colours_are_drawn_shaded_on_both_sides() {
        let cam = ortho(40, 40, 4.0);
        let p = [
            DVec3::new(-1.0, -1.0, 0.0),
            DVec3::new(1.0, -1.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(-1.0, 1.0, 0.0),
        ];
        let front = [[0, 1, 2], [0, 2, 3]];
        let back = [[0, 2, 1], [0, 3, 2]];
        let red = [[230, 20, 20]; 4];
        for tris in [front, back] {
            let img = render_triangles_with_colors(
                &cam,
                &p,
                &tris,
                None,
                SurfaceColors::PerVertex(&red),
                &style1(),
            )
            .unwrap();
            let c = img.get(20, 20).unwrap().map(u32::from);
            assert!(c[0] > 100 && c[0] > 3 * c[1] && c[0] > 3 * c[2], "{c:?}");
        }
        // Per triangle: the two halves of the square take their own colours.
        let img = render_triangles_with_colors(
            &cam,
            &p,
            &front,
            None,
            SurfaceColors::PerTriangle(&[[20, 200, 20], [20, 20, 200]]),
            &style1(),
        )
        .unwrap();
        // Triangle 0 is below the diagonal (x > y in model space: lower right on screen).
        let g = img.get(28, 28).unwrap().map(u32::from);
        let b = img.get(12, 12).unwrap().map(u32::from);
        assert!(g[1] > 2 * g[0] && g[1] > 2 * g[2], "{g:?}");
        assert!(b[2] > 2 * b[0] && b[2] > 2 * b[1], "{b:?}");
        // Vertex colours interpolate: red on the left, blue on the right.
        let lr = [[255, 0, 0], [0, 0, 255], [0, 0, 255], [255, 0, 0]];
        let img = render_triangles_with_colors(
            &cam,
            &p,
            &front,
            None,
            SurfaceColors::PerVertex(&lr),
            &style1(),
        )
        .unwrap();
        let (l, r) = (img.get(12, 20).unwrap(), img.get(28, 20).unwrap());
        assert!(l[0] > l[2] && r[2] > r[0], "{l:?} {r:?}");
        // Uniform colours are the plain renderer's.
        assert_eq!(
            render_triangles_with_colors(&cam, &p, &front, None, SurfaceColors::Uniform, &style1())
                .unwrap(),
            render_triangles(&cam, &p, &front, None, &style1()).unwrap()
        );
        // Wrong lengths are errors.
        for c in [
            SurfaceColors::PerVertex(&red[..3]),
            SurfaceColors::PerTriangle(&red[..1]),
        ] {
            assert!(render_triangles_with_colors(&cam, &p, &front, None, c, &style1()).is_err());
        }
    }
}
