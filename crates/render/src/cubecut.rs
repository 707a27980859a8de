//! Proxy geometry for slice-based volume rendering: the polygons where view-aligned planes cut
//! the bricks of a volume (McPhail, *Fast Cube Cutting for Interactive Volume
//! Visualization*, thesis ch. 2), with the two baselines the chapter compares against.
//!
//! # The sweep (§2.3)
//!
//! Project the eight corners of a box on the viewing direction. Between two consecutive
//! projections (a *wedge*) every plane cuts the same set of box edges, so inside a wedge the
//! polygon of the next plane is the previous one moved along each edge by a fixed vector:
//! `y = d / (u·v) · u` for an edge vector `u`, slice spacing `d` and view vector `v`. Which
//! edges each wedge cuts depends only on the order of the projected corners; the order
//! changes only where the view vector crosses a plane bisecting two corners. The 13 distinct
//! bisecting planes (3 between edge neighbours, 6 between face diagonals, 4 between body
//! diagonals) split the sphere of view directions into 96 patches; a table holds, per patch,
//! the corner order and each wedge's edges in polygon order (the *sequence of topology
//! changes*, STC). The patch of a view vector is found by seven tests, a BSP tree of depth 7
//! flattened into an index: the three signs (the coordinate planes bisect edge neighbours),
//! which component is largest, middle and smallest in magnitude (the face-diagonal planes
//! within an octant), and whether the largest exceeds the sum of the other two (the one
//! body-diagonal plane that crosses the octant's triangle). The sweep then walks the wedges
//! from the back of the box to the front, finding each wedge's starting polygon once and
//! advancing it by vector additions.
//!
//! # Baselines (§2.4)
//!
//! * [`CutMethod::Rsk`]: Rezk-Salama and Kolb's vertex-program method, run on the CPU as the
//!   chapter does: every plane gets six vertices, each found independently by testing the
//!   edges of one of three paths from the front corner to the back corner (and a connecting
//!   edge for every other vertex), repeated vertices where the polygon has fewer than six.
//! * [`CutMethod::Clip`]: what hardware clipping planes do: a quad covering the box's section
//!   is clipped against the box's six faces (Sutherland–Hodgman).
//!
//! All three cut the same planes and give the same polygons (RSK with repeated vertices).
//!
//! # Planes and order
//!
//! Planes are perpendicular to the camera's viewing direction `f` at `s = −f·x = k·d` for
//! integers `k` (world units; `s` grows towards the eye), so neighbouring bricks share their
//! planes and the slices of a volume line up across bricks. A box is cut by the planes with
//! `s` in `[s_min, s_max)` of its corners: a plane through a face shared by two bricks belongs
//! to one of them, and a plane touching only a corner or an edge (no area) is left out.
//! Polygons come **back to front**: bricks in visibility order for parallel projection (each
//! axis walked from the far side), and within a brick increasing `s`.
//!
//! # Buffer layout (the contract with the WebGL2 studio)
//!
//! * [`ProxyGeometry::vertices`]: `f32`, [`VERTEX_FLOATS`] = 6 per vertex, interleaved
//!   `x, y, z, s, t, r`: the position in world coordinates (millimetres for medical volumes,
//!   the volume's physical space) and the 3D texture coordinate, the voxel's continuous index
//!   normalised so that texel centres sit at `(i + ½) / n` (WebGL's `texture()` convention for
//!   a `TEXTURE_3D` of the volume with `n` texels per axis). Stride 24 bytes; position at
//!   byte offset 0, texture coordinate at 12.
//! * [`ProxyGeometry::indices`]: `u32` triangle list (`gl.TRIANGLES`, `UNSIGNED_INT`), each
//!   polygon fanned from its first vertex, counter-clockwise as seen from the eye (the default
//!   `gl.frontFace(gl.CCW)`), in drawing order (back to front).
//! * [`ProxyGeometry::polygons`]: per polygon, its first vertex, vertex count and plane number
//!   `k` (for debugging and tests; not needed to draw).
//!
//! Blend with `gl.blendFunc(gl.ONE, gl.ONE_MINUS_SRC_ALPHA)` (premultiplied, back to front)
//! and draw the index buffer in order.

use std::sync::LazyLock;

use glam::{DMat3, DVec3};

use crate::dvr::{DvrRenderer, DvrVolume};
use crate::error::RenderError;
use crate::octree::Visibility;

/// Floats per vertex in [`ProxyGeometry::vertices`]: position `x, y, z` then texture
/// coordinate `s, t, r`.
pub const VERTEX_FLOATS: usize = 6;

/// Most slices [`Slicing::new`] accepts across a box (a million planes is far beyond what any
/// display shows).
pub const MAX_SLICES: f64 = 1e6;

/// How the polygons of a box are found (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CutMethod {
    /// McPhail's table-driven plane sweep.
    Sweep,
    /// Rezk-Salama and Kolb's per-vertex method.
    Rsk,
    /// A quad clipped against the box's faces.
    Clip,
}

/// One polygon of a [`ProxyGeometry`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProxyPolygon {
    /// Index of its first vertex (in vertices, not floats).
    pub first_vertex: u32,
    /// Number of vertices (RSK: always 6, with repeats).
    pub vertex_count: u32,
    /// Plane number `k`: the plane is `s = k·spacing`.
    pub plane: i64,
}

/// Polygons with 3D texture coordinates, ready for WebGL2 (layout in the [module
/// docs](self)).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ProxyGeometry {
    /// Interleaved `x, y, z, s, t, r` per vertex.
    pub vertices: Vec<f32>,
    /// Triangle list, counter-clockwise from the eye, back to front.
    pub indices: Vec<u32>,
    /// The polygons, in drawing order.
    pub polygons: Vec<ProxyPolygon>,
}

impl ProxyGeometry {
    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.vertices.len() / VERTEX_FLOATS
    }

    /// Position of vertex `i`, world coordinates.
    #[must_use]
    pub fn position(&self, i: usize) -> DVec3 {
        let v = &self.vertices[i * VERTEX_FLOATS..];
        DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
    }

    /// Texture coordinate of vertex `i`.
    #[must_use]
    pub fn texcoord(&self, i: usize) -> DVec3 {
        let v = &self.vertices[i * VERTEX_FLOATS + 3..];
        DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
    }

    /// Remove everything, keeping the allocations.
    pub fn clear(&mut self) {
        self.vertices.clear();
        self.indices.clear();
        self.polygons.clear();
    }

    /// Append one polygon of `n` vertices given as `(position, texcoord)` in `pts`, fanned.
    #[inline]
    fn push_polygon(&mut self, pts: impl Iterator<Item = (DVec3, DVec3)>, n: usize, plane: i64) {
        let first = self.vertex_count() as u32;
        for (p, t) in pts {
            self.vertices.extend_from_slice(&[
                p.x as f32, p.y as f32, p.z as f32, t.x as f32, t.y as f32, t.z as f32,
            ]);
        }
        for i in 1..n.saturating_sub(1) as u32 {
            self.indices
                .extend_from_slice(&[first, first + i, first + i + 1]);
        }
        self.polygons.push(ProxyPolygon {
            first_vertex: first,
            vertex_count: n as u32,
            plane,
        });
    }
}

/// A box with texture coordinates: world position `origin + axes·w` and texture coordinate
/// `tex_origin + tex_size ⊙ w` for `w ∈ [0, 1]³`. The axes need not be orthogonal (any
/// parallelepiped; a brick of an oblique volume).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProxyBox {
    /// World position of corner `w = 0`.
    pub origin: DVec3,
    /// Columns: the world edge vectors along `w_x`, `w_y`, `w_z`.
    pub axes: DMat3,
    /// Texture coordinate of corner `w = 0`.
    pub tex_origin: DVec3,
    /// Texture extent along each `w` axis.
    pub tex_size: DVec3,
}

impl ProxyBox {
    /// The box of a volume's cells from index `lo` to index `hi` (continuous voxel indices,
    /// `lo ≤ hi`), texture coordinates `(index + ½) / n`.
    #[must_use]
    pub fn of_cells(volume: &DvrVolume, lo: DVec3, hi: DVec3) -> Self {
        let g = volume.geometry();
        let a = g.index_to_physical_matrix();
        let n = DVec3::new(g.dims[0] as f64, g.dims[1] as f64, g.dims[2] as f64);
        let size = hi - lo;
        Self {
            origin: g.index_to_physical(lo),
            axes: a * DMat3::from_diagonal(size),
            tex_origin: (lo + DVec3::splat(0.5)) / n,
            tex_size: size / n,
        }
    }

    /// The eight corners `w ∈ {0, 1}³` (corner `v` has `w_x = v & 1`, `w_y = v >> 1 & 1`,
    /// `w_z = v >> 2`), world coordinates.
    #[must_use]
    pub fn corners(&self) -> [DVec3; 8] {
        std::array::from_fn(|v| self.origin + self.axes * unit_corner(v as u8))
    }

    #[inline]
    fn world(&self, w: DVec3) -> (DVec3, DVec3) {
        (
            self.origin + self.axes * w,
            self.tex_origin + self.tex_size * w,
        )
    }
}

/// View-aligned planes: perpendicular to the camera's unit viewing direction `forward`, at
/// `s = −forward·x = k·spacing` for integers `k` (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slicing {
    forward: DVec3,
    spacing: f64,
}

impl Slicing {
    /// Planes `spacing` world units apart perpendicular to `forward` (any length).
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for a zero or non-finite direction or a spacing that
    /// is not finite and positive.
    pub fn new(forward: DVec3, spacing: f64) -> Result<Self, RenderError> {
        let forward = forward.try_normalize().ok_or_else(|| {
            RenderError::invalid(format!("slice direction {forward} is zero or not finite"))
        })?;
        if !(spacing > 0.0 && spacing.is_finite()) {
            return Err(RenderError::invalid(format!(
                "slice spacing {spacing} must be finite and positive"
            )));
        }
        Ok(Self { forward, spacing })
    }

    /// `count` planes across the extent of `points` along `forward` (the spacing is the
    /// extent divided by `count`).
    ///
    /// # Errors
    /// As [`Slicing::new`]; also for `count` of 0 or above [`MAX_SLICES`], or points with no
    /// extent along the direction.
    pub fn across(forward: DVec3, points: &[DVec3], count: usize) -> Result<Self, RenderError> {
        if count == 0 || count as f64 > MAX_SLICES {
            return Err(RenderError::invalid(format!(
                "slice count {count} must be 1 to {MAX_SLICES}"
            )));
        }
        let f = forward.normalize_or_zero();
        let (lo, hi) = points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                let s = f.dot(*p);
                (a.min(s), b.max(s))
            });
        Self::new(forward, (hi - lo) / count as f64)
    }

    /// Unit viewing direction.
    #[must_use]
    pub fn forward(&self) -> DVec3 {
        self.forward
    }

    /// Distance between planes.
    #[must_use]
    pub fn spacing(&self) -> f64 {
        self.spacing
    }
}

/// Corner `v` of the unit cube (`x = v & 1`, `y = v >> 1 & 1`, `z = v >> 2 & 1`).
#[inline]
fn unit_corner(v: u8) -> DVec3 {
    DVec3::new(
        f64::from(v & 1),
        f64::from(v >> 1 & 1),
        f64::from(v >> 2 & 1),
    )
}

/// The twelve edges of the unit cube as corner pairs.
const EDGES: [(u8, u8); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

/// The edges a wedge cuts, oriented from the corner behind to the corner in front, in
/// counter-clockwise order seen from the front (the `+s` side).
#[derive(Debug, Clone, Copy, Default)]
struct Wedge {
    edges: [(u8, u8); 6],
    count: u8,
}

/// One entry of the table: a sequence of topology changes.
#[derive(Debug, Clone, Copy, Default)]
struct Stc {
    /// Corners by increasing `s` (back to front).
    order: [u8; 8],
    /// Wedge `p` lies between `order[p]` and `order[p + 1]`.
    wedges: [Wedge; 7],
}

/// The patch of direction `m` (the gradient of `s` in box coordinates): octant (3 sign
/// tests), magnitude order (3 comparisons) and body diagonal (1 test) — the flattened BSP
/// tree of the [module docs](self). Ties go consistently to one side.
#[inline]
fn patch_of(m: DVec3) -> usize {
    let octant = usize::from(m.x < 0.0) | usize::from(m.y < 0.0) << 1 | usize::from(m.z < 0.0) << 2;
    let a = m.abs();
    let (xy, yz, xz) = (a.x >= a.y, a.y >= a.z, a.x >= a.z);
    // Permutation: which axis is largest and which smallest.
    let (perm, largest, others) = match (xy, yz, xz) {
        (true, true, _) => (0, a.x, a.y + a.z),      // x ≥ y ≥ z
        (true, false, true) => (1, a.x, a.y + a.z),  // x ≥ z > y
        (false, _, true) => (2, a.y, a.x + a.z),     // y > x ≥ z
        (false, true, false) => (3, a.y, a.x + a.z), // y ≥ z > x
        (true, false, false) => (4, a.z, a.x + a.y), // z > x ≥ y
        (false, false, _) => (5, a.z, a.x + a.y),    // z > y > x
    };
    octant * 12 + perm * 2 + usize::from(largest > others)
}

/// A direction strictly inside patch `index` (used to build the table).
fn representative(index: usize) -> DVec3 {
    let (octant, perm, diag) = (index / 12, index % 12 / 2, index % 2 == 1);
    let (l, m, s) = if diag {
        (5.0, 2.0, 1.0)
    } else {
        (3.0, 2.0, 1.5)
    };
    let a = match perm {
        0 => DVec3::new(l, m, s),
        1 => DVec3::new(l, s, m),
        2 => DVec3::new(m, l, s),
        3 => DVec3::new(s, l, m),
        4 => DVec3::new(m, s, l),
        _ => DVec3::new(s, m, l),
    };
    DVec3::new(
        if octant & 1 == 1 { -a.x } else { a.x },
        if octant & 2 == 2 { -a.y } else { a.y },
        if octant & 4 == 4 { -a.z } else { a.z },
    )
}

/// The table of sequences of topology changes, one per patch.
static TABLE: LazyLock<[Stc; 96]> = LazyLock::new(|| std::array::from_fn(build_stc));

fn build_stc(index: usize) -> Stc {
    let m = representative(index);
    debug_assert_eq!(patch_of(m), index);
    let s = |v: u8| m.dot(unit_corner(v));
    let mut order: [u8; 8] = std::array::from_fn(|v| v as u8);
    order.sort_by(|&a, &b| s(a).total_cmp(&s(b)));
    let n = m.normalize();
    let e1 = n.any_orthonormal_vector();
    let e2 = n.cross(e1);
    let mut wedges = [Wedge::default(); 7];
    for (p, wedge) in wedges.iter_mut().enumerate() {
        let behind = |v: u8| order[..=p].contains(&v);
        let mid = 0.5 * (s(order[p]) + s(order[p + 1]));
        let mut cut: Vec<((u8, u8), DVec3)> = EDGES
            .iter()
            .filter(|&&(a, b)| behind(a) != behind(b))
            .map(|&(a, b)| {
                let (from, to) = if behind(a) { (a, b) } else { (b, a) };
                let (ca, cb) = (unit_corner(from), unit_corner(to));
                let t = (mid - s(from)) / (s(to) - s(from));
                ((from, to), ca + t * (cb - ca))
            })
            .collect();
        let centre = cut.iter().map(|c| c.1).sum::<DVec3>() / cut.len() as f64;
        // Increasing angle about n: counter-clockwise seen from the +s side.
        cut.sort_by(|a, b| {
            let ang = |p: DVec3| (p - centre).dot(e2).atan2((p - centre).dot(e1));
            ang(a.1).total_cmp(&ang(b.1))
        });
        wedge.count = cut.len() as u8;
        for (slot, c) in wedge.edges.iter_mut().zip(&cut) {
            *slot = c.0;
        }
    }
    Stc { order, wedges }
}

/// The path vertices of Rezk-Salama and Kolb for a front corner: `V0` (front), `V1, V2, V3`
/// (its neighbours, in the cyclic order that makes the hexagon counter-clockwise from the
/// front), `V4 = V1 ⊕ V3`, `V5 = V1 ⊕ V2`, `V6 = V2 ⊕ V3` (face diagonals) and `V7` (back).
static RSK_VERTICES: LazyLock<[[u8; 8]; 8]> = LazyLock::new(|| {
    std::array::from_fn(|front| {
        let v0 = front as u8;
        let order = |bits: [u8; 3]| -> [u8; 8] {
            let [b1, b2, b3] = bits;
            [
                v0,
                v0 ^ b1,
                v0 ^ b2,
                v0 ^ b3,
                v0 ^ b1 ^ b3,
                v0 ^ b1 ^ b2,
                v0 ^ b2 ^ b3,
                v0 ^ 7,
            ]
        };
        // The front corner is the largest in s: m points towards it from the centre.
        let m = DVec3::new(
            if v0 & 1 == 1 { 1.0 } else { -1.0 },
            if v0 & 2 == 2 { 1.0 } else { -1.0 },
            if v0 & 4 == 4 { 1.0 } else { -1.0 },
        );
        let a = order([1, 2, 4]);
        // Orientation of the hexagon through the three neighbours, seen from the front.
        let (p1, p2, p3) = (unit_corner(a[1]), unit_corner(a[2]), unit_corner(a[3]));
        if (p2 - p1).cross(p3 - p1).dot(m) > 0.0 {
            a
        } else {
            order([1, 4, 2])
        }
    })
});

/// Cut `bx` by the planes of `slicing` with `method`, appending to `out` (back to front).
pub fn cut_box(bx: &ProxyBox, slicing: &Slicing, method: CutMethod, out: &mut ProxyGeometry) {
    let f = slicing.forward;
    let d = slicing.spacing;
    // s(w) = s0 + m·w.
    let s0 = -f.dot(bx.origin);
    let m = -(bx.axes.transpose() * f);
    let flipped = bx.axes.determinant() < 0.0;
    let proj: [f64; 8] = std::array::from_fn(|v| s0 + m.dot(unit_corner(v as u8)));
    let (smin, smax) = proj
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let k0 = (smin / d).ceil() as i64;
    if (k0 as f64) * d >= smax {
        return;
    }
    match method {
        CutMethod::Sweep => sweep(bx, m, &proj, d, flipped, out),
        CutMethod::Rsk => {
            let mut k = k0;
            while (k as f64) * d < smax {
                rsk_plane(bx, m, &proj, (k as f64) * d, k, flipped, out);
                k += 1;
            }
        }
        CutMethod::Clip => {
            let mut k = k0;
            while (k as f64) * d < smax {
                clip_plane(bx, m, s0, (k as f64) * d, k, flipped, out);
                k += 1;
            }
        }
    }
}

/// Twice the area of the polygon `pts` (any orientation), world units.
fn polygon_area(pts: &[DVec3]) -> f64 {
    let mut a = DVec3::ZERO;
    for i in 1..pts.len().saturating_sub(1) {
        a += (pts[i] - pts[0]).cross(pts[i + 1] - pts[0]);
    }
    a.length()
}

/// Whether the points (in box coordinates) span no area: a plane touching only a corner or
/// an edge of the box.
fn degenerate(w: &[DVec3]) -> bool {
    polygon_area(w) <= 1e-12
}

/// The table-driven sweep of one box.
fn sweep(bx: &ProxyBox, m: DVec3, proj: &[f64; 8], d: f64, flipped: bool, out: &mut ProxyGeometry) {
    let stc = &TABLE[patch_of(m)];
    let mut w = [DVec3::ZERO; 6];
    let mut pos = [(DVec3::ZERO, DVec3::ZERO); 6];
    let mut step = [(DVec3::ZERO, DVec3::ZERO); 6];
    for (p, wedge) in stc.wedges.iter().enumerate() {
        let (lo, hi) = (proj[stc.order[p] as usize], proj[stc.order[p + 1] as usize]);
        if hi <= lo {
            continue;
        }
        let mut k = (lo / d).ceil() as i64;
        let mut s = k as f64 * d;
        if s >= hi {
            continue;
        }
        let n = wedge.count as usize;
        // The wedge's first polygon, and the step of each vertex from plane to plane.
        for (e, &(a, b)) in wedge.edges[..n].iter().enumerate() {
            let (fa, fb) = (proj[a as usize], proj[b as usize]);
            let (ca, cb) = (unit_corner(a), unit_corner(b));
            let u = cb - ca;
            w[e] = ca + (s - fa) / (fb - fa) * u;
            pos[e] = bx.world(w[e]);
            let dw = d / (fb - fa) * u;
            step[e] = (bx.axes * dw, bx.tex_size * dw);
        }
        if s == lo && degenerate(&w[..n]) {
            advance(&mut pos[..n], &step[..n]);
            k += 1;
            s = k as f64 * d;
        }
        while s < hi {
            if flipped {
                out.push_polygon(pos[..n].iter().rev().copied(), n, k);
            } else {
                out.push_polygon(pos[..n].iter().copied(), n, k);
            }
            advance(&mut pos[..n], &step[..n]);
            k += 1;
            s = k as f64 * d;
        }
    }
}

#[inline]
fn advance(pos: &mut [(DVec3, DVec3)], step: &[(DVec3, DVec3)]) {
    for (p, d) in pos.iter_mut().zip(step) {
        p.0 += d.0;
        p.1 += d.1;
    }
}

/// Rezk-Salama and Kolb: six vertices of plane `s`, each found on its own path.
fn rsk_plane(
    bx: &ProxyBox,
    m: DVec3,
    proj: &[f64; 8],
    s: f64,
    k: i64,
    flipped: bool,
    out: &mut ProxyGeometry,
) {
    // The front corner (largest s) from the signs of m.
    let front =
        usize::from(m.x >= 0.0) | usize::from(m.y >= 0.0) << 1 | usize::from(m.z >= 0.0) << 2;
    let v = &RSK_VERTICES[front];
    // Paths: p0 on V0→V1→V4→V7, p1 on V1→V5, p2 on V0→V2→V5→V7, p3 on V2→V6,
    // p4 on V0→V3→V6→V7, p5 on V3→V4.
    const PATHS: [[usize; 4]; 3] = [[0, 1, 4, 7], [0, 2, 5, 7], [0, 3, 6, 7]];
    const DOTTED: [(usize, usize); 3] = [(1, 5), (2, 6), (3, 4)];
    let hit = |a: usize, b: usize| -> Option<DVec3> {
        let (fa, fb) = (proj[v[a] as usize], proj[v[b] as usize]);
        let den = fb - fa;
        if den == 0.0 {
            return None;
        }
        let l = (s - fa) / den;
        (0.0..=1.0).contains(&l).then(|| {
            let (ca, cb) = (unit_corner(v[a]), unit_corner(v[b]));
            ca + l * (cb - ca)
        })
    };
    let mut w = [DVec3::ZERO; 6];
    for (i, path) in PATHS.iter().enumerate() {
        let on_path = (0..3).find_map(|e| hit(path[e], path[e + 1]));
        w[2 * i] = on_path.unwrap_or(unit_corner(v[7]));
        let (a, b) = DOTTED[i];
        w[2 * i + 1] = hit(a, b).unwrap_or(w[2 * i]);
    }
    if degenerate(&w) {
        return;
    }
    let pts = w.map(|p| bx.world(p));
    if flipped {
        out.push_polygon(pts.iter().rev().copied(), 6, k);
    } else {
        out.push_polygon(pts.iter().copied(), 6, k);
    }
}

/// A quad covering the box's section by plane `s`, clipped against the six faces.
fn clip_plane(
    bx: &ProxyBox,
    m: DVec3,
    s0: f64,
    s: f64,
    k: i64,
    flipped: bool,
    out: &mut ProxyGeometry,
) {
    let n = m.normalize();
    let centre = DVec3::splat(0.5);
    let c = centre + (s - s0 - m.dot(centre)) / m.length_squared() * m;
    let e1 = n.any_orthonormal_vector();
    let e2 = n.cross(e1);
    let r = 3f64.sqrt();
    let mut poly: Vec<DVec3> = vec![
        c - r * e1 - r * e2,
        c + r * e1 - r * e2,
        c + r * e1 + r * e2,
        c - r * e1 + r * e2,
    ];
    let mut next = Vec::with_capacity(8);
    for axis in 0..3 {
        for (bound, keep_below) in [(0.0, false), (1.0, true)] {
            // Keep w[axis] ≥ 0, then w[axis] ≤ 1.
            let inside = |p: DVec3| {
                if keep_below {
                    p[axis] <= bound
                } else {
                    p[axis] >= bound
                }
            };
            next.clear();
            for i in 0..poly.len() {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                let (ia, ib) = (inside(a), inside(b));
                if ia {
                    next.push(a);
                }
                if ia != ib {
                    let t = (bound - a[axis]) / (b[axis] - a[axis]);
                    let mut p = a + t * (b - a);
                    p[axis] = bound;
                    next.push(p);
                }
            }
            std::mem::swap(&mut poly, &mut next);
            if poly.is_empty() {
                return;
            }
        }
    }
    if poly.len() < 3 || degenerate(&poly) {
        return;
    }
    let count = poly.len();
    let pts = poly.into_iter().map(|p| bx.world(p));
    if flipped {
        out.push_polygon(pts.rev(), count, k);
    } else {
        out.push_polygon(pts, count, k);
    }
}

impl DvrRenderer<'_> {
    /// The proxy geometry of the volume for slice-based rendering: every node of octree
    /// `level` (0: bricks of [`octree::DEFAULT_BRICK`](crate::octree::DEFAULT_BRICK) cells,
    /// each level up twice as wide) that can show something under this renderer's transfer
    /// function, cut by `slicing` with `method`, back to front (layout in the [module
    /// docs](self)).
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for a level beyond the octree's root.
    pub fn proxy_geometry(
        &self,
        slicing: &Slicing,
        level: usize,
        method: CutMethod,
    ) -> Result<ProxyGeometry, RenderError> {
        let mut out = ProxyGeometry::default();
        self.proxy_geometry_into(slicing, level, method, &mut out)?;
        Ok(out)
    }

    /// [`DvrRenderer::proxy_geometry`] into `out` (cleared first; its buffers are reused, as a
    /// viewer does frame after frame).
    ///
    /// # Errors
    /// As [`DvrRenderer::proxy_geometry`].
    pub fn proxy_geometry_into(
        &self,
        slicing: &Slicing,
        level: usize,
        method: CutMethod,
        out: &mut ProxyGeometry,
    ) -> Result<(), RenderError> {
        out.clear();
        cut_octree(
            self.volume,
            Some(&self.visibility),
            level,
            slicing,
            method,
            out,
        )
    }
}

/// Cut the nodes of octree `level` of `volume` (only those `visibility` marks visible, or all
/// with `None`) by `slicing` with `method`, appending to `out` back to front.
///
/// # Errors
/// [`RenderError::InvalidArgument`] for a level beyond the octree's root.
pub fn cut_octree(
    volume: &DvrVolume,
    visibility: Option<&Visibility>,
    level: usize,
    slicing: &Slicing,
    method: CutMethod,
    out: &mut ProxyGeometry,
) -> Result<(), RenderError> {
    let octree = volume.octree();
    if level >= octree.level_count() {
        return Err(RenderError::invalid(format!(
            "octree level {level} does not exist (levels 0 to {})",
            octree.level_count() - 1
        )));
    }
    let dims = octree.level_dims(level);
    // Back to front for parallel projection: along each index axis from the far side.
    let f_index = volume.index_of(volume.geometry().origin + slicing.forward)
        - volume.index_of(volume.geometry().origin);
    let axis = |a: usize| -> Vec<usize> {
        if f_index[a] > 0.0 {
            (0..dims[a]).rev().collect()
        } else {
            (0..dims[a]).collect()
        }
    };
    let (xs, ys, zs) = (axis(0), axis(1), axis(2));
    for &k in &zs {
        for &j in &ys {
            for &i in &xs {
                if visibility.is_some_and(|v| !v.visible(level, [i, j, k])) {
                    continue;
                }
                let (lo, hi) = octree.node_box(level, [i, j, k]);
                let lo = DVec3::new(lo[0] as f64, lo[1] as f64, lo[2] as f64);
                let hi = DVec3::new(hi[0] as f64, hi[1] as f64, hi[2] as f64);
                if (hi - lo).min_element() <= 0.0 {
                    continue;
                }
                cut_box(&ProxyBox::of_cells(volume, lo, hi), slicing, method, out);
            }
        }
    }
    Ok(())
}
