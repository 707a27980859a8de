//! The CPU depth peeler: a closed mesh seen from a view becomes, per pixel (ray), the sorted
//! list of its surface crossings — depth, unit outward normal and whether the ray enters or
//! leaves the solid there (McPhail §3.3, the depth-peel image, DPI).
//!
//! A GPU depth peel renders the mesh once per layer and reads back each layer's depth
//! buffer. On the CPU every crossing of a pixel's ray is found in one rasterisation pass
//! instead: each triangle is projected onto the view's ray plane, the rays it covers are
//! found with exact, watertight coverage tests ([`crate::exact`]), and the crossings of
//! each ray are sorted by depth. `volmorph-render`'s rasteriser is a shaded z-buffer that
//! keeps only the nearest surface per sample with floating-point edge tests; a depth peel
//! needs every surface per ray and an exact answer for rays through shared edges and
//! vertices, so the peeler has its own rasterisation here.
//!
//! **Clean rays.** The sorted crossings are reduced by their **winding number** to disjoint
//! solid intervals (union semantics: a point is solid where the mesh winds around it a
//! positive number of times). Every ray of the result alternates entering and leaving
//! crossings, starting with an entering one; overlapping parts of a self-intersecting or
//! multi-component mesh merge, and zero-thickness intervals vanish.
//!
//! Rasterisation runs in parallel over bands of ray rows.

use glam::{DMat4, DVec3, DVec4};
use rayon::prelude::*;

use crate::SculptError;
use crate::exact::{Projected, quantize, ray_fixed};
use crate::grid::{Grid, transverse};

/// One crossing of a ray with a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossing {
    /// Position along the ray: the physical coordinate along the ray's axis for the
    /// orthographic views of a grid, the distance from the eye for a perspective view.
    pub depth: f64,
    /// Unit outward normal of the surface at the crossing (physical space).
    pub normal: [f32; 3],
    /// The material along the ray changes from empty to solid here (`false`: solid to
    /// empty).
    pub entering: bool,
}

impl Crossing {
    /// The normal as a double-precision vector.
    #[must_use]
    pub fn normal(&self) -> DVec3 {
        DVec3::new(
            f64::from(self.normal[0]),
            f64::from(self.normal[1]),
            f64::from(self.normal[2]),
        )
    }
}

/// Single-precision copy of a unit normal.
pub(crate) fn pack_normal(n: DVec3) -> [f32; 3] {
    [n.x as f32, n.y as f32, n.z as f32]
}

/// A closed triangle mesh prepared for peeling: positions and vertex triples, outward
/// oriented (positive enclosed volume).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TriangleSoup {
    /// Vertex positions (physical units).
    pub positions: Vec<DVec3>,
    /// Triangles, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl TriangleSoup {
    /// Unit right-hand normal of triangle `t` (zero for a degenerate triangle).
    #[must_use]
    pub fn normal(&self, t: usize) -> DVec3 {
        let [a, b, c] = self.triangles[t].map(|i| self.positions[i as usize]);
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// Bounding box of the referenced positions, or `None` without triangles.
    #[must_use]
    pub fn bounds(&self) -> Option<(DVec3, DVec3)> {
        let mut it = self.triangles.iter().flatten();
        let first = self.positions[*it.next()? as usize];
        Some(it.fold((first, first), |(lo, hi), &i| {
            let p = self.positions[i as usize];
            (lo.min(p), hi.max(p))
        }))
    }
}

/// A rectangle of rays: transverse indices `u0..=u1`, `v0..=v1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct RayRect {
    pub u0: usize,
    pub u1: usize,
    pub v0: usize,
    pub v1: usize,
}

impl RayRect {
    /// Every ray of `grid` along `axis`.
    pub(crate) fn all(grid: &Grid, axis: usize) -> Self {
        let (b, c) = transverse(axis);
        let d = grid.dims();
        Self {
            u0: 0,
            u1: d[b] - 1,
            v0: 0,
            v1: d[c] - 1,
        }
    }

    pub(crate) fn width(&self) -> usize {
        self.u1 - self.u0 + 1
    }

    pub(crate) fn height(&self) -> usize {
        self.v1 - self.v0 + 1
    }

    pub(crate) fn len(&self) -> usize {
        self.width() * self.height()
    }
}

/// Clean crossings of a rectangle of rays in compressed rows: ray `(u, v)` (relative to the
/// rectangle) has `crossings[offsets[r]..offsets[r + 1]]` with `r = u + width · v`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RayBlock {
    pub rect: RayRect,
    pub offsets: Vec<u32>,
    pub crossings: Vec<Crossing>,
}

impl RayBlock {
    /// Crossings of the ray at absolute transverse indices `(u, v)` (empty outside the
    /// rectangle).
    pub(crate) fn ray(&self, u: usize, v: usize) -> &[Crossing] {
        let r = self.rect;
        if u < r.u0 || u > r.u1 || v < r.v0 || v > r.v1 {
            return &[];
        }
        let i = (u - r.u0) + r.width() * (v - r.v0);
        &self.crossings[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

/// How the depth of a crossing is computed once a ray is known to cover a triangle.
#[derive(Debug, Clone, Copy)]
enum Depth {
    /// Orthographic: the depths of the three vertices, interpolated barycentrically.
    Affine([f64; 3]),
    /// Perspective: the plane `n · x = d` of the triangle, intersected with the pixel ray.
    Plane { n: DVec3, d: f64 },
}

/// A triangle ready for rasterisation.
#[derive(Debug, Clone, Copy)]
struct RasterTri {
    proj: Projected,
    depth: Depth,
    normal: [f32; 3],
    entering: bool,
    /// Covered ray range (absolute indices, possibly empty).
    u: [i64; 2],
    v: [i64; 2],
}

/// Rays of a perspective view: eye and per-pixel unit directions.
trait RaySource: Sync {
    fn direction(&self, u: usize, v: usize) -> DVec3;
    fn eye(&self) -> DVec3;
}

struct NoRays;
impl RaySource for NoRays {
    fn direction(&self, _: usize, _: usize) -> DVec3 {
        DVec3::ZERO
    }
    fn eye(&self) -> DVec3 {
        DVec3::ZERO
    }
}

/// Ray rows per parallel band.
const BAND_ROWS: usize = 8;

/// Rasterise `tris` onto the rays of `rect`, sort and clean every ray. `start_inside` gives
/// the winding number at the start of a ray from its crossings (0 for orthographic views).
fn rasterize<R: RaySource>(
    tris: &[RasterTri],
    rect: RayRect,
    rays: &R,
    perspective: bool,
) -> RayBlock {
    let bands = rect.height().div_ceil(BAND_ROWS);
    let mut binned: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (t, tri) in tris.iter().enumerate() {
        let lo = tri.v[0].max(rect.v0 as i64);
        let hi = tri.v[1].min(rect.v1 as i64);
        if lo > hi || tri.u[0] > rect.u1 as i64 || tri.u[1] < rect.u0 as i64 {
            continue;
        }
        let (b0, b1) = (
            (lo as usize - rect.v0) / BAND_ROWS,
            (hi as usize - rect.v0) / BAND_ROWS,
        );
        for band in &mut binned[b0..=b1] {
            band.push(t as u32);
        }
    }
    let width = rect.width();
    let parts: Vec<(Vec<u32>, Vec<Crossing>)> = binned
        .par_iter()
        .enumerate()
        .map(|(b, list)| {
            let v_lo = rect.v0 + b * BAND_ROWS;
            let v_hi = (v_lo + BAND_ROWS - 1).min(rect.v1);
            let mut raw: Vec<(u32, Crossing)> = Vec::new();
            for &t in list {
                let tri = &tris[t as usize];
                let (u_lo, u_hi) = (tri.u[0].max(rect.u0 as i64), tri.u[1].min(rect.u1 as i64));
                let (r_lo, r_hi) = (tri.v[0].max(v_lo as i64), tri.v[1].min(v_hi as i64));
                for v in r_lo..=r_hi {
                    for u in u_lo..=u_hi {
                        let Some(w) = tri.proj.cover([ray_fixed(u), ray_fixed(v)]) else {
                            continue;
                        };
                        let depth = match tri.depth {
                            Depth::Affine(d) => affine_depth(w, d),
                            Depth::Plane { n, d } => {
                                let dir = rays.direction(u as usize, v as usize);
                                let den = n.dot(dir);
                                if den == 0.0 {
                                    continue;
                                }
                                (d - n.dot(rays.eye())) / den
                            }
                        };
                        if !depth.is_finite() {
                            continue;
                        }
                        let local = (u as usize - rect.u0) + width * (v as usize - v_lo);
                        raw.push((
                            local as u32,
                            Crossing {
                                depth,
                                normal: tri.normal,
                                entering: tri.entering,
                            },
                        ));
                    }
                }
            }
            raw.sort_unstable_by(|a, b| {
                a.0.cmp(&b.0)
                    .then(a.1.depth.total_cmp(&b.1.depth))
                    .then(b.1.entering.cmp(&a.1.entering))
            });
            let rows = v_hi - v_lo + 1;
            let mut offsets = Vec::with_capacity(rows * width);
            let mut out = Vec::with_capacity(raw.len());
            let mut k = 0;
            for r in 0..rows * width {
                offsets.push(out.len() as u32);
                let start = k;
                while k < raw.len() && raw[k].0 as usize == r {
                    k += 1;
                }
                let ray = raw[start..k].iter().map(|x| x.1);
                let w0 = if perspective {
                    -raw[start..k]
                        .iter()
                        .map(|x| if x.1.entering { 1 } else { -1 })
                        .sum::<i32>()
                } else {
                    0
                };
                clean_into(ray, w0, &mut out);
            }
            (offsets, out)
        })
        .collect();
    let total: usize = parts.iter().map(|p| p.1.len()).sum();
    let mut offsets = Vec::with_capacity(rect.len() + 1);
    let mut crossings = Vec::with_capacity(total);
    for (o, c) in parts {
        let base = crossings.len() as u32;
        offsets.extend(o.iter().map(|x| x + base));
        crossings.extend_from_slice(&c);
    }
    offsets.push(crossings.len() as u32);
    RayBlock {
        rect,
        offsets,
        crossings,
    }
}

/// Depth at barycentric weights `w` of a triangle with vertex depths `d`: exact when the
/// depths are equal (a face on a grid plane stays on it) and never outside their range.
#[inline]
pub(crate) fn affine_depth(w: [f64; 3], d: [f64; 3]) -> f64 {
    let x = d[0] + w[1] * (d[1] - d[0]) + w[2] * (d[2] - d[0]);
    x.clamp(d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]))
}

/// Reduce crossings sorted by depth (entering first at equal depth) to the disjoint solid
/// intervals where the winding number, starting at `w0`, is positive; push them to `out`.
/// A ray starting inside (`w0 > 0`) begins with an entering crossing at `-∞`, which is not
/// stored: its first crossing is a leaving one.
pub(crate) fn clean_into(ray: impl Iterator<Item = Crossing>, w0: i32, out: &mut Vec<Crossing>) {
    let start = out.len();
    let mut w = w0;
    for c in ray {
        if c.entering {
            w += 1;
            if w == 1 {
                out.push(c);
            }
        } else {
            w -= 1;
            if w == 0 {
                // A zero-length interval vanishes.
                if out.len() > start {
                    let last = out[out.len() - 1];
                    if last.entering && last.depth == c.depth {
                        out.pop();
                        continue;
                    }
                }
                out.push(c);
            }
        }
    }
}

/// Quantised projection of `p` for an orthographic view along `axis` of `grid`.
fn ortho_project(grid: &Grid, axis: usize, p: DVec3) -> Option<[i64; 2]> {
    let (b, c) = transverse(axis);
    let q = grid.to_index(p);
    Some([quantize(q[b])?, quantize(q[c])?])
}

/// The crossings of `soup` along the grid's rays of `axis` within `rect` (transverse
/// indices): the orthographic depth peel restricted to a window of rays.
///
/// # Errors
/// [`SculptError::InvalidMesh`] (`role`) when a vertex is not finite or lies absurdly far
/// from the grid (more than 2³⁸ spacings).
pub(crate) fn peel_axis(
    soup: &TriangleSoup,
    grid: &Grid,
    axis: usize,
    rect: RayRect,
    role: &'static str,
) -> Result<RayBlock, SculptError> {
    let mut quant = Vec::with_capacity(soup.positions.len());
    for (i, &p) in soup.positions.iter().enumerate() {
        quant.push(
            ortho_project(grid, axis, p).ok_or_else(|| SculptError::InvalidMesh {
                role,
                reason: format!("vertex {i} at {p} is not finite or is too far from the grid"),
            })?,
        );
    }
    let tris: Vec<RasterTri> = soup
        .triangles
        .par_iter()
        .enumerate()
        .filter_map(|(t, tri)| {
            let [a, b, c] = tri.map(|i| quant[i as usize]);
            let proj = Projected::new(a, b, c)?;
            let (u, v) = proj.ray_range();
            let depth = tri.map(|i| soup.positions[i as usize][axis]);
            Some(RasterTri {
                proj,
                depth: Depth::Affine(depth),
                normal: pack_normal(soup.normal(t)),
                // Counter-clockwise in the (u, v) ray plane: the normal points along +axis,
                // the ray leaves the solid.
                entering: !proj.counter_clockwise(),
                u,
                v,
            })
        })
        .collect();
    Ok(rasterize(&tris, rect, &NoRays, false))
}

/// A depth-peel image: the clean crossings of every ray (pixel) of a view.
///
/// Rays are numbered `(u, v)` with `u` fastest: for an orthographic view along grid axis
/// `a`, `u` and `v` are the grid indices along the two transverse axes
/// [`transverse`]`(a)`; for a [`PerspectiveView`], the pixel column and row (row 0 at the
/// top).
#[derive(Debug, Clone, PartialEq)]
pub struct DepthPeelImage {
    block: RayBlock,
}

impl DepthPeelImage {
    /// Number of rays per row.
    #[must_use]
    pub fn width(&self) -> usize {
        self.block.rect.width()
    }

    /// Number of rows of rays.
    #[must_use]
    pub fn height(&self) -> usize {
        self.block.rect.height()
    }

    /// Crossings of ray `(u, v)`, sorted by depth, alternately entering and leaving (empty
    /// outside the image).
    #[must_use]
    pub fn ray(&self, u: usize, v: usize) -> &[Crossing] {
        self.block.ray(u, v)
    }

    /// Total number of crossings (the image's size in layers × pixels).
    #[must_use]
    pub fn crossing_count(&self) -> usize {
        self.block.crossings.len()
    }

    /// Largest number of crossings on one ray: the depth complexity, i.e. the number of
    /// layers a GPU depth peel would render.
    #[must_use]
    pub fn depth_complexity(&self) -> usize {
        self.block
            .offsets
            .windows(2)
            .map(|w| (w[1] - w[0]) as usize)
            .max()
            .unwrap_or(0)
    }

    pub(crate) fn from_block(block: RayBlock) -> Self {
        Self { block }
    }
}

/// The orthographic depth-peel image of `soup` along grid axis `axis` (0, 1, 2 for x, y, z):
/// one ray through every grid point of the transverse plane, depths in physical coordinates
/// along the axis.
///
/// # Errors
/// [`SculptError::InvalidOption`] for an axis above 2; [`SculptError::InvalidMesh`] for a
/// non-finite vertex or one absurdly far from the grid.
pub fn depth_peel_axis(
    soup: &TriangleSoup,
    grid: &Grid,
    axis: usize,
) -> Result<DepthPeelImage, SculptError> {
    if axis > 2 {
        return Err(SculptError::option("axis", axis, "0, 1 or 2"));
    }
    let rect = RayRect::all(grid, axis);
    Ok(DepthPeelImage::from_block(peel_axis(
        soup, grid, axis, rect, "peeled",
    )?))
}

/// Largest number of pixels of a perspective view.
pub const MAX_VIEW_PIXELS: usize = 1 << 26;

/// The user's perspective view, frozen while sculpting: a view–projection matrix (world to
/// OpenGL clip space: x right, y up, visible depth `−w ≤ z ≤ w`) and a viewport of
/// `width × height` pixels. Pixel `(u, v)` (row 0 at the top) is the ray from the eye through
/// the pixel's centre; depths are distances from the eye along it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PerspectiveView {
    view_proj: DMat4,
    inverse: DMat4,
    eye: DVec3,
    width: usize,
    height: usize,
    /// Whether front faces (facing the eye) appear clockwise on the picture (the usual
    /// case, since rows go down).
    front_clockwise: bool,
}

impl PerspectiveView {
    /// A view from a view–projection matrix.
    ///
    /// # Errors
    /// [`SculptError::InvalidOption`] for a non-finite or singular matrix, a matrix without a
    /// finite eye point (orthographic), or a viewport that is empty or larger than
    /// [`MAX_VIEW_PIXELS`].
    pub fn new(view_proj: DMat4, width: usize, height: usize) -> Result<Self, SculptError> {
        if width == 0 || height == 0 || width.saturating_mul(height) > MAX_VIEW_PIXELS {
            return Err(SculptError::option(
                "viewport",
                format!("{width}×{height}"),
                "at least one pixel and at most 2^26 pixels",
            ));
        }
        let det = view_proj.determinant();
        if !(view_proj.is_finite() && det.is_finite() && det != 0.0) {
            return Err(SculptError::option(
                "view_proj",
                format!("{view_proj}"),
                "a finite, invertible view–projection matrix",
            ));
        }
        let inverse = view_proj.inverse();
        let e = inverse * DVec4::new(0.0, 0.0, 1.0, 0.0);
        if !(e.w.is_finite() && e.w.abs() > f64::EPSILON * e.length()) {
            return Err(SculptError::option(
                "view_proj",
                format!("{view_proj}"),
                "a perspective projection (an orthographic one has no eye point)",
            ));
        }
        let eye = e.truncate() / e.w;
        let mut view = Self {
            view_proj,
            inverse,
            eye,
            width,
            height,
            front_clockwise: true,
        };
        // Orientation of a small triangle facing the eye, seen on the picture.
        let centre_dir = view.direction_at(width as f64 * 0.5 - 0.5, height as f64 * 0.5 - 0.5);
        let (x, y) = (
            centre_dir.any_orthonormal_pair().0,
            centre_dir.any_orthonormal_pair().1,
        );
        let c = view.near_point(width as f64 * 0.5 - 0.5, height as f64 * 0.5 - 0.5);
        let c = eye + (c - eye) * 2.0;
        let s = (c - eye).length() * 1e-3;
        // Triangle (c, c + s x, c + s y) with normal x × y; make it face the eye.
        let (x, y) = if x.cross(y).dot(centre_dir) < 0.0 {
            (x, y)
        } else {
            (y, x)
        };
        let p = [c, c + s * x, c + s * y].map(|p| view.screen(p));
        if let [Some(a), Some(b), Some(cc)] = p {
            let area = (b.0 - a.0) * (cc.1 - a.1) - (b.1 - a.1) * (cc.0 - a.0);
            view.front_clockwise = area < 0.0;
        }
        Ok(view)
    }

    /// A pinhole view from `eye` towards `target` with `up` roughly up, vertical field of
    /// view `fov_y` (radians, in `(0, π)`), near and far planes at `near < far` from the eye.
    ///
    /// # Errors
    /// [`SculptError::InvalidOption`] for coincident eye and target, an `up` parallel to the
    /// view direction, a field of view or planes out of range; as [`PerspectiveView::new`].
    pub fn look_at(
        eye: DVec3,
        target: DVec3,
        up: DVec3,
        fov_y: f64,
        (near, far): (f64, f64),
        (width, height): (usize, usize),
    ) -> Result<Self, SculptError> {
        let forward = (target - eye).normalize_or_zero();
        if forward == DVec3::ZERO || forward.cross(up).length_squared() == 0.0 {
            return Err(SculptError::option(
                "look_at",
                format!("eye {eye}, target {target}, up {up}"),
                "distinct eye and target and an up vector not along the view",
            ));
        }
        if !(fov_y > 0.0 && fov_y < std::f64::consts::PI) {
            return Err(SculptError::option("fov_y", fov_y, "an angle in (0, π)"));
        }
        if !(near > 0.0 && far > near && far.is_finite()) {
            return Err(SculptError::option(
                "near/far",
                format!("{near}/{far}"),
                "0 < near < far < ∞",
            ));
        }
        let aspect = width.max(1) as f64 / height.max(1) as f64;
        // World to camera: x right, y up, looking along −z (right-handed).
        let right = forward.cross(up).normalize();
        let cam_up = right.cross(forward);
        let view = DMat4::from_cols(
            DVec4::new(right.x, cam_up.x, -forward.x, 0.0),
            DVec4::new(right.y, cam_up.y, -forward.y, 0.0),
            DVec4::new(right.z, cam_up.z, -forward.z, 0.0),
            DVec4::new(-right.dot(eye), -cam_up.dot(eye), forward.dot(eye), 1.0),
        );
        // OpenGL perspective: depth −near ↦ −1, −far ↦ +1.
        let f = 1.0 / (fov_y * 0.5).tan();
        let proj = DMat4::from_cols(
            DVec4::new(f / aspect, 0.0, 0.0, 0.0),
            DVec4::new(0.0, f, 0.0, 0.0),
            DVec4::new(0.0, 0.0, (far + near) / (near - far), -1.0),
            DVec4::new(0.0, 0.0, 2.0 * far * near / (near - far), 0.0),
        );
        Self::new(proj * view, width, height)
    }

    /// The eye point.
    #[must_use]
    pub fn eye(&self) -> DVec3 {
        self.eye
    }

    /// Viewport width in pixels.
    #[must_use]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Viewport height in pixels.
    #[must_use]
    pub fn height(&self) -> usize {
        self.height
    }

    /// The view–projection matrix.
    #[must_use]
    pub fn view_proj(&self) -> DMat4 {
        self.view_proj
    }

    /// Point on the near plane under picture position `(x, y)` (pixel units, centres at
    /// integers).
    fn near_point(&self, x: f64, y: f64) -> DVec3 {
        let ndc_x = (x + 0.5) / self.width as f64 * 2.0 - 1.0;
        let ndc_y = 1.0 - (y + 0.5) / self.height as f64 * 2.0;
        self.inverse.project_point3(DVec3::new(ndc_x, ndc_y, -1.0))
    }

    fn direction_at(&self, x: f64, y: f64) -> DVec3 {
        (self.near_point(x, y) - self.eye).normalize_or_zero()
    }

    /// Unit direction of the ray of pixel `(u, v)`.
    #[must_use]
    pub fn direction(&self, u: usize, v: usize) -> DVec3 {
        self.direction_at(u as f64, v as f64)
    }

    /// Picture position `(x, y)` of `p` (pixel units, centres at integers), or `None` when
    /// `p` is not in front of the near plane.
    #[must_use]
    pub fn screen(&self, p: DVec3) -> Option<(f64, f64)> {
        let c = self.view_proj * p.extend(1.0);
        if !(c.w > 0.0 && c.z >= -c.w) {
            return None;
        }
        Some(self.clip_to_screen(c))
    }

    fn clip_to_screen(&self, c: DVec4) -> (f64, f64) {
        let (nx, ny) = (c.x / c.w, c.y / c.w);
        (
            (nx + 1.0) * 0.5 * self.width as f64 - 0.5,
            (1.0 - ny) * 0.5 * self.height as f64 - 0.5,
        )
    }

    /// Point at `depth` along the ray of pixel `(u, v)`.
    #[must_use]
    pub fn point(&self, u: usize, v: usize, depth: f64) -> DVec3 {
        self.eye + self.direction(u, v) * depth
    }
}

impl RaySource for PerspectiveView {
    fn direction(&self, u: usize, v: usize) -> DVec3 {
        PerspectiveView::direction(self, u, v)
    }
    fn eye(&self) -> DVec3 {
        self.eye
    }
}

/// The crossings of `soup` along the pixel rays of `view` within `rect`.
pub(crate) fn peel_view(
    soup: &TriangleSoup,
    view: &PerspectiveView,
    rect: RayRect,
) -> Result<RayBlock, SculptError> {
    let clip: Vec<DVec4> = soup
        .positions
        .iter()
        .map(|p| view.view_proj * p.extend(1.0))
        .collect();
    // Near-plane distance of a clip-space point: z + w ≥ 0 is in front of the near plane.
    let near = |c: DVec4| c.z + c.w;
    let mut tris = Vec::new();
    for tri in &soup.triangles {
        let n = {
            let [a, b, c] = tri.map(|i| soup.positions[i as usize]);
            (b - a).cross(c - a)
        };
        let plane = Depth::Plane {
            n,
            d: n.dot(soup.positions[tri[0] as usize]),
        };
        let normal = pack_normal(n.normalize_or_zero());
        // Clip the triangle against the near plane; points on shared edges are computed from
        // the edge's endpoints in index order, so neighbours agree bit for bit.
        let mut poly: Vec<DVec4> = Vec::with_capacity(4);
        for k in 0..3 {
            let (i, j) = (tri[k], tri[(k + 1) % 3]);
            let (ci, cj) = (clip[i as usize], clip[j as usize]);
            let (di, dj) = (near(ci), near(cj));
            if di >= 0.0 {
                poly.push(ci);
            }
            if (di >= 0.0) != (dj >= 0.0) {
                let (lo, hi, dlo, dhi) = if i < j {
                    (ci, cj, di, dj)
                } else {
                    (cj, ci, dj, di)
                };
                let s = dlo / (dlo - dhi);
                poly.push(lo + (hi - lo) * s);
            }
        }
        if poly.len() < 3 {
            continue;
        }
        let mut q = Vec::with_capacity(poly.len());
        for c in &poly {
            if c.w <= 0.0 {
                break;
            }
            let (x, y) = view.clip_to_screen(*c);
            match (quantize(x), quantize(y)) {
                (Some(x), Some(y)) => q.push([x, y]),
                _ => break,
            }
        }
        if q.len() != poly.len() {
            continue;
        }
        for k in 1..q.len() - 1 {
            let Some(proj) = Projected::new(q[0], q[k], q[k + 1]) else {
                continue;
            };
            let (u, v) = proj.ray_range();
            tris.push(RasterTri {
                proj,
                depth: plane,
                normal,
                entering: proj.counter_clockwise() != view.front_clockwise,
                u,
                v,
            });
        }
    }
    Ok(rasterize(&tris, rect, view, true))
}

/// The perspective depth-peel image of `soup` seen through `view` (depths are distances from
/// the eye; parts behind the near plane are cut away, so a ray starting inside the solid
/// begins with a leaving crossing).
///
/// # Errors
/// None at present; reserved for size limits (the view is validated on construction).
pub fn depth_peel_perspective(
    soup: &TriangleSoup,
    view: &PerspectiveView,
) -> Result<DepthPeelImage, SculptError> {
    let rect = RayRect {
        u0: 0,
        u1: view.width - 1,
        v0: 0,
        v1: view.height - 1,
    };
    Ok(DepthPeelImage::from_block(peel_view(soup, view, rect)?))
}
