//! Ray–boundary intersection of trivariate NURBS volumes and parameter tracking along rays
//! (Martin & Cohen §5.2, Theorem 1).
//!
//! By Theorem 1 the boundary of the solid `P([0, 1]³)` lies in the union of the six **faces**
//! `P(u_a = 0 or 1)` and the **fold** set where `det JP = 0`. A [`RayTracer`] prepares both once:
//!
//! * **Faces** (eq. 7). The geometry is clamped ([`TensorBSpline::clamp_ends`]) so each face is a
//!   layer of the control net; each face surface is split into Bézier patches and those are
//!   subdivided (exact knot insertion) until flat — every control point within
//!   [`TraceOptions::flatness`] × (model diagonal) of the bilinear patch through its corner
//!   points — or [`TraceOptions::max_depth`] levels. The patches form a bounding-volume
//!   hierarchy of control-point boxes (valid by the convex hull property; weights are positive).
//!   A ray is written as the intersection of two planes `(a_l, b_l, c_l, d_l)`, `l = 1, 2`,
//!   containing it; boxes the ray misses are culled and Newton's method solves the two plane
//!   equations `F(s, t) · (a_l, b_l, c_l, d_l) = 0` from the centre parameters of each
//!   surviving leaf.
//! * **Fold** (eq. 8). The volume's Bézier cells are subdivided (halving the longest
//!   parametric side) until a cell's control-point box is below
//!   [`TraceOptions::volume_tolerance`] × (model box volume) or [`TraceOptions::max_depth`]
//!   levels. Every cell carries cones `C_u, C_v, C_w` ([`Cone`]) bounding its first partial
//!   derivatives, and cells with `0 ∉ C_u · (C_v × C_w)` are culled — `det JP` keeps one sign
//!   there. For polynomial cells the cones bound the derivative control points
//!   `p·(P_{i+e_a} − P_i)/h`. For **rational** cells the projected derivative is
//!   `P_a = (w·H_a − w_a·H)/w²`, and the numerator is a positive combination (products of
//!   Bernstein polynomials are non-negative) of the vectors `w_i·(D_j − δ_j·P_i)` over all
//!   control points `i` and derivative control points `j = (D_j, δ_j)` of the homogeneous
//!   derivative; the cone is fitted to all of them, which is conservative (the paper's
//!   "homogenized control points" alone are not). Newton's method then solves the two plane
//!   equations together with `det JP(u) = 0` from each surviving leaf's centre; the gradient
//!   of `det JP` is taken by central differences of the analytic Jacobian (step
//!   [`FOLD_DIFF_STEP`]).
//!
//! Hits from several boxes are merged when they are within [`TraceOptions::merge_distance`]
//! × (model diagonal) of each other along the ray. Hits are candidates for boundary points:
//! the faces of a revolved solid include the interior seam `θ = 0 ≡ 2π`, and `det JP` vanishes
//! on its axis, so callers walking through the volume decide with [`RayTracer::locate`] whether
//! a point just past a hit is inside.
//!
//! **Tracking** ([`RayTracer::track`], eq. 9): the parameters of a point `p*` near a known point
//! are found by Newton, `u_{k+1} = u_k + JP(u_k)⁻¹ (p* − P(u_k))`, warm-started from the known
//! parameters. When the iteration leaves the domain `[0, 1]³` (through a seam face of a
//! revolved solid, past a degenerate axis, or out of the volume) the point is inverted from
//! scratch ([`invert`]); the point is outside exactly when that fails.

use volmorph_render::{Aabb, Ray};
use volmorph_spline::{BezierPiece, TensorBSpline};

use crate::bounds::point_box;
use crate::cone::Cone;
use crate::error::ctx;
use crate::eval::{EvalMethod, VolumeEvaluator};
use crate::invert::{InversionOptions, invert, solve3_rows};
use crate::{AggregateVolume, TrivariateError};

/// Relative step (in parameter units) of the central differences of `det JP` used by the fold
/// Newton iteration. With analytic first derivatives accurate to ~1e-16 relative, a step of
/// 1e-6 balances truncation (~h²) and cancellation (~1e-16/h) near 1e-10.
pub const FOLD_DIFF_STEP: f64 = 1e-6;

/// Options of [`RayTracer`]. Lengths are relative to the diagonal of the geometry's
/// control-point bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceOptions {
    /// Face flatness: largest distance of a patch control point from the bilinear patch of
    /// its corners, relative to the model diagonal.
    pub flatness: f64,
    /// Fold hierarchy volume tolerance: cells whose control-point box volume is below this
    /// fraction of the model box volume are leaves.
    pub volume_tolerance: f64,
    /// Deepest subdivision level of either hierarchy (one split per level).
    pub max_depth: usize,
    /// Newton iterations per start.
    pub max_iterations: usize,
    /// Distance from the ray accepted as a hit, relative to the model diagonal.
    pub tolerance: f64,
    /// Hits closer than this along the ray (relative to the model diagonal) are one hit.
    pub merge_distance: f64,
}

impl Default for TraceOptions {
    /// Flatness 1e-3, volume tolerance 1e-4, depth 12, 30 iterations, tolerance 1e-12,
    /// merge distance 1e-7.
    fn default() -> Self {
        Self {
            flatness: 1e-3,
            volume_tolerance: 1e-4,
            max_depth: 12,
            max_iterations: 30,
            tolerance: 1e-12,
            merge_distance: 1e-7,
        }
    }
}

/// Which part of the boundary a hit lies on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HitKind {
    /// The face `u_axis = side` (`side` 0 or 1) of the parametric cube (eq. 7).
    Face {
        /// Parametric axis, 0 = u.
        axis: usize,
        /// 0 for the face at parameter 0, 1 for the face at parameter 1.
        side: usize,
    },
    /// A point where `det JP = 0` (eq. 8).
    Fold,
}

/// A point where a ray meets a candidate boundary surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryHit {
    /// Distance along the unit ray direction from the ray origin.
    pub t: f64,
    /// Physical point `P(params)`.
    pub point: [f64; 3],
    /// Parameters in `[0, 1]³`.
    pub params: [f64; 3],
    /// Face or fold.
    pub kind: HitKind,
    /// Unit normal of the boundary surface there (oriented against the ray, `normal · dir ≤
    /// 0`), or zero when the surface is degenerate at the hit (e.g. a collapsed face).
    pub normal: [f64; 3],
}

/// The result of [`RayTracer::track`]: parameters, point and Jacobian at a tracked point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tracked {
    /// Parameters in `[0, 1]³`.
    pub params: [f64; 3],
    /// `P(params)`.
    pub point: [f64; 3],
    /// Jacobian `JP`, column-major: `jacobian[3a + c] = ∂P_c/∂u_a`.
    pub jacobian: [f64; 9],
}

#[derive(Debug, Clone)]
struct Node {
    lo: [f64; 3],
    hi: [f64; 3],
    /// Leaf: start parameters (volume parameters; for faces the fixed axis is set).
    start: [f64; 3],
    /// Children indices into the node array (empty for leaves).
    children: Vec<u32>,
}

#[derive(Debug, Clone, Default)]
struct Tree {
    nodes: Vec<Node>,
    roots: Vec<u32>,
}

impl Tree {
    /// Leaves whose boxes (padded by `pad`) the ray meets, as start parameters.
    fn candidates(&self, ray: &Ray, pad: f64, out: &mut Vec<[f64; 3]>) {
        let mut stack: Vec<u32> = self.roots.clone();
        while let Some(i) = stack.pop() {
            let Some(n) = self.nodes.get(i as usize) else {
                continue;
            };
            let lo = glam::DVec3::from_array(n.lo) - glam::DVec3::splat(pad);
            let hi = glam::DVec3::from_array(n.hi) + glam::DVec3::splat(pad);
            let Ok(b) = Aabb::new(lo, hi) else { continue };
            if b.intersect(ray).is_none() {
                continue;
            }
            if n.children.is_empty() {
                out.push(n.start);
            } else {
                stack.extend_from_slice(&n.children);
            }
        }
    }
}

/// Control-point bounding box of a Bézier piece (projected points).
fn piece_box<const N: usize>(p: &BezierPiece<N>) -> ([f64; 3], [f64; 3]) {
    point_box(&p.control_points())
}

/// Largest distance of a patch's control points from the bilinear patch of its corners.
fn patch_flatness(p: &BezierPiece<2>) -> f64 {
    let [d0, d1] = p.degrees();
    let pts = p.control_points();
    let (n0, n1) = (d0 + 1, d1 + 1);
    let at = |i: usize, j: usize| -> [f64; 3] {
        let o = 3 * (j * n0 + i);
        [pts[o], pts[o + 1], pts[o + 2]]
    };
    let (c00, c10, c01, c11) = (at(0, 0), at(d0, 0), at(0, d1), at(d0, d1));
    let mut worst: f64 = 0.0;
    for j in 0..n1 {
        for i in 0..n0 {
            let s = if d0 == 0 { 0.0 } else { i as f64 / d0 as f64 };
            let t = if d1 == 0 { 0.0 } else { j as f64 / d1 as f64 };
            let q = at(i, j);
            let mut d2 = 0.0;
            for k in 0..3 {
                let b = (1.0 - s) * (1.0 - t) * c00[k]
                    + s * (1.0 - t) * c10[k]
                    + (1.0 - s) * t * c01[k]
                    + s * t * c11[k];
                d2 += (q[k] - b) * (q[k] - b);
            }
            worst = worst.max(d2.sqrt());
        }
    }
    worst
}

/// Sum of control-polygon edge lengths along `axis` of a piece (used to pick the split axis).
fn polygon_length<const N: usize>(p: &BezierPiece<N>, axis: usize) -> f64 {
    let deg = p.degrees();
    let counts: [usize; N] = std::array::from_fn(|a| deg[a] + 1);
    let pts = p.control_points();
    let mut stride = 1;
    for c in counts.iter().take(axis) {
        stride *= c;
    }
    let total = pts.len() / 3;
    let mut len = 0.0;
    for i in 0..total {
        let idx_a = (i / stride) % counts[axis];
        if idx_a + 1 < counts[axis] {
            let (a, b) = (3 * i, 3 * (i + stride));
            len += ((pts[b] - pts[a]).powi(2)
                + (pts[b + 1] - pts[a + 1]).powi(2)
                + (pts[b + 2] - pts[a + 2]).powi(2))
            .sqrt();
        }
    }
    len
}

/// Cones bounding the three projected partial derivatives over a Bézier cell (see the
/// [module docs](self) for the rational case).
fn derivative_cones(cell: &BezierPiece<3>) -> [Cone; 3] {
    let deg = cell.degrees();
    let n = deg.map(|p| p + 1);
    let h = cell.homogeneous_coefficients();
    let hd = if cell.is_rational() { 4 } else { 3 };
    let idx = |i: usize, j: usize, k: usize| hd * ((k * n[1] + j) * n[0] + i);
    let pts = cell.control_points();
    std::array::from_fn(|axis| {
        if deg[axis] == 0 {
            return Cone::full();
        }
        let mut diffs: Vec<[f64; 4]> = Vec::new();
        for k in 0..n[2] - usize::from(axis == 2) {
            for j in 0..n[1] - usize::from(axis == 1) {
                for i in 0..n[0] - usize::from(axis == 0) {
                    let a = idx(i, j, k);
                    let (i2, j2, k2) = match axis {
                        0 => (i + 1, j, k),
                        1 => (i, j + 1, k),
                        _ => (i, j, k + 1),
                    };
                    let b = idx(i2, j2, k2);
                    let mut d = [0.0; 4];
                    for c in 0..hd {
                        d[c] = h[b + c] - h[a + c];
                    }
                    diffs.push(d);
                }
            }
        }
        if cell.is_rational() {
            let vecs = diffs.iter().flat_map(|d| {
                pts.chunks_exact(3)
                    .map(move |p| [d[0] - d[3] * p[0], d[1] - d[3] * p[1], d[2] - d[3] * p[2]])
            });
            Cone::fit(vecs)
        } else {
            Cone::fit(diffs.iter().map(|d| [d[0], d[1], d[2]]))
        }
    })
}

fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm3(a: [f64; 3]) -> f64 {
    dot3(a, a).sqrt()
}

fn col(j: &[f64; 9], a: usize) -> [f64; 3] {
    [j[3 * a], j[3 * a + 1], j[3 * a + 2]]
}

/// `det JP` from a column-major Jacobian.
pub(crate) fn det3(j: &[f64; 9]) -> f64 {
    dot3(col(j, 0), cross3(col(j, 1), col(j, 2)))
}

/// Two unit plane normals orthogonal to the unit direction `d` (and to each other).
fn ray_planes(d: [f64; 3]) -> [[f64; 3]; 2] {
    let e = if d[0].abs() <= d[1].abs() && d[0].abs() <= d[2].abs() {
        [1.0, 0.0, 0.0]
    } else if d[1].abs() <= d[2].abs() {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let n1 = cross3(d, e);
    let l1 = norm3(n1);
    let n1 = n1.map(|x| x / l1);
    let n2 = cross3(d, n1);
    [n1, n2]
}

/// Check a ray: finite origin, finite non-zero direction; returns the unit direction.
///
/// # Errors
/// [`TrivariateError::InvalidArgument`] naming the bad vector.
pub(crate) fn check_ray(origin: [f64; 3], dir: [f64; 3]) -> Result<[f64; 3], TrivariateError> {
    if !origin.iter().all(|x| x.is_finite()) {
        return Err(TrivariateError::InvalidArgument(format!(
            "ray origin {origin:?} must be finite"
        )));
    }
    let n = norm3(dir);
    if !(n > 0.0 && n.is_finite()) {
        return Err(TrivariateError::InvalidArgument(format!(
            "ray direction {dir:?} must be finite and non-zero"
        )));
    }
    Ok(dir.map(|x| x / n))
}

/// Ray–boundary intersection and parameter tracking for one geometry volume (see the
/// [module docs](self)). Built once, shared by all rays (`Sync`).
#[derive(Debug, Clone)]
pub struct RayTracer {
    geometry: TensorBSpline<3>,
    faces: [Tree; 6],
    fold: Tree,
    options: TraceOptions,
    diagonal: f64,
    lo: [f64; 3],
    hi: [f64; 3],
}

impl RayTracer {
    /// Prepare the face and fold hierarchies of `volume`'s geometry.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for options that are not finite and positive (or a
    /// zero iteration count); [`TrivariateError::Spline`] if subdivision fails.
    pub fn new(volume: &AggregateVolume, options: TraceOptions) -> Result<Self, TrivariateError> {
        Self::from_geometry(volume.geometry(), options)
    }

    /// As [`RayTracer::new`] from a bare geometry spline (3 coordinates, domain `[0, 1]³`).
    ///
    /// # Errors
    /// As [`RayTracer::new`], plus [`TrivariateError::GeometryDimension`].
    pub fn from_geometry(
        geometry: &TensorBSpline<3>,
        options: TraceOptions,
    ) -> Result<Self, TrivariateError> {
        if geometry.dim() != 3 {
            return Err(TrivariateError::GeometryDimension {
                expected: 3,
                got: geometry.dim(),
            });
        }
        crate::aggregate::check_unit_domain("geometry", geometry)?;
        for (name, v) in [
            ("flatness", options.flatness),
            ("volume_tolerance", options.volume_tolerance),
            ("tolerance", options.tolerance),
            ("merge_distance", options.merge_distance),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(TrivariateError::InvalidArgument(format!(
                    "trace option {name} = {v} must be finite and > 0"
                )));
            }
        }
        if options.max_iterations == 0 {
            return Err(TrivariateError::InvalidArgument(
                "trace option max_iterations must be > 0".into(),
            ));
        }
        let mut g = geometry.clone();
        for a in 0..3 {
            g = g.clamp_ends(a).map_err(ctx("clamping geometry"))?;
        }
        let (lo, hi) = point_box(&g.control_points());
        let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let diagonal = norm3(ext);
        if !(diagonal > 0.0 && diagonal.is_finite()) {
            return Err(TrivariateError::InvalidArgument(
                "geometry has zero or non-finite extent".into(),
            ));
        }
        let mut faces: [Tree; 6] = Default::default();
        for axis in 0..3 {
            for side in 0..2 {
                faces[2 * axis + side] = build_face_tree(&g, axis, side, &options, diagonal)?;
            }
        }
        let box_volume = ext.iter().map(|e| e.max(1e-12 * diagonal)).product::<f64>();
        let fold = build_fold_tree(&g, &options, box_volume)?;
        Ok(Self {
            geometry: g,
            faces,
            fold,
            options,
            diagonal,
            lo,
            hi,
        })
    }

    /// The (end-clamped) geometry spline the tracer works on; same map as the input.
    #[must_use]
    pub fn geometry(&self) -> &TensorBSpline<3> {
        &self.geometry
    }

    /// Diagonal of the control-point bounding box (the length scale of all tolerances).
    #[must_use]
    pub fn diagonal(&self) -> f64 {
        self.diagonal
    }

    /// Control-point bounding box `(min, max)` of the geometry; it contains the solid.
    #[must_use]
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        (self.lo, self.hi)
    }

    /// Number of fold-hierarchy leaves kept after cone culling (0 when `det JP` cannot
    /// vanish anywhere).
    #[must_use]
    pub fn fold_leaf_count(&self) -> usize {
        self.fold
            .nodes
            .iter()
            .filter(|n| n.children.is_empty())
            .count()
    }

    /// All hits of the ray `origin + t·dir`, `t ≥ 0`, with the face and fold surfaces, sorted
    /// by `t` (distance along the normalised `dir`), merged as described in the
    /// [module docs](self).
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for a non-finite origin or a zero or non-finite
    /// direction.
    pub fn intersect(
        &self,
        origin: [f64; 3],
        dir: [f64; 3],
    ) -> Result<Vec<BoundaryHit>, TrivariateError> {
        let d = check_ray(origin, dir)?;
        let ray = Ray {
            origin: glam::DVec3::from_array(origin),
            dir: glam::DVec3::from_array(d),
        };
        let planes = ray_planes(d);
        let offs = planes.map(|n| -dot3(n, origin));
        let pad = self.options.tolerance.max(1e-9) * self.diagonal;
        let e = VolumeEvaluator::new(&self.geometry);
        let mut hits: Vec<BoundaryHit> = Vec::new();
        let mut starts = Vec::new();
        for (f, tree) in self.faces.iter().enumerate() {
            let (axis, side) = (f / 2, f % 2);
            starts.clear();
            tree.candidates(&ray, pad, &mut starts);
            for s in &starts {
                if let Some(h) = self.face_newton(&e, axis, side, *s, origin, d, planes, offs)? {
                    hits.push(h);
                }
            }
        }
        starts.clear();
        self.fold.candidates(&ray, pad, &mut starts);
        for s in &starts {
            if let Some(h) = self.fold_newton(&e, *s, origin, d, planes, offs)? {
                hits.push(h);
            }
        }
        hits.sort_by(|a, b| a.t.total_cmp(&b.t));
        let merge = self.options.merge_distance * self.diagonal;
        let mut out: Vec<BoundaryHit> = Vec::with_capacity(hits.len());
        for h in hits {
            match out.last() {
                Some(last) if (h.t - last.t).abs() <= merge => {}
                _ => out.push(h),
            }
        }
        Ok(out)
    }

    #[allow(clippy::too_many_arguments)]
    fn face_newton(
        &self,
        e: &VolumeEvaluator<'_>,
        axis: usize,
        side: usize,
        start: [f64; 3],
        origin: [f64; 3],
        d: [f64; 3],
        planes: [[f64; 3]; 2],
        offs: [f64; 2],
    ) -> Result<Option<BoundaryHit>, TrivariateError> {
        let free = match axis {
            0 => [1, 2],
            1 => [0, 2],
            _ => [0, 1],
        };
        let tol = self.options.tolerance * self.diagonal;
        let mut u = start;
        u[axis] = side as f64;
        let mut p = [0.0; 3];
        let mut g = [0.0; 9];
        for _ in 0..self.options.max_iterations {
            e.eval_into(EvalMethod::default(), u, &mut p, &mut g)?;
            let f = [dot3(planes[0], p) + offs[0], dot3(planes[1], p) + offs[1]];
            if f[0].abs().max(f[1].abs()) <= tol {
                return Ok(self.make_hit(e, u, p, &g, origin, d, HitKind::Face { axis, side }));
            }
            let (ps, pt) = (col(&g, free[0]), col(&g, free[1]));
            let m = [
                [dot3(planes[0], ps), dot3(planes[0], pt)],
                [dot3(planes[1], ps), dot3(planes[1], pt)],
            ];
            let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
            let scale = (m[0][0].abs() + m[0][1].abs()) * (m[1][0].abs() + m[1][1].abs());
            if !(det.abs() > 1e-14 * scale && scale > 0.0) {
                return Ok(None);
            }
            let ds = (-f[0] * m[1][1] + f[1] * m[0][1]) / det;
            let dt = (-m[0][0] * f[1] + m[1][0] * f[0]) / det;
            let next_s = (u[free[0]] + ds).clamp(0.0, 1.0);
            let next_t = (u[free[1]] + dt).clamp(0.0, 1.0);
            if next_s == u[free[0]] && next_t == u[free[1]] {
                return Ok(None);
            }
            u[free[0]] = next_s;
            u[free[1]] = next_t;
        }
        Ok(None)
    }

    /// `det JP` and its parameter gradient by central differences (one-sided at the domain
    /// ends).
    fn det_and_gradient(
        &self,
        e: &VolumeEvaluator<'_>,
        u: [f64; 3],
    ) -> Result<(f64, [f64; 3]), TrivariateError> {
        let mut p = [0.0; 3];
        let mut g = [0.0; 9];
        e.eval_into(EvalMethod::default(), u, &mut p, &mut g)?;
        let det = det3(&g);
        let mut grad = [0.0; 3];
        for a in 0..3 {
            let lo = (u[a] - FOLD_DIFF_STEP).max(0.0);
            let hi = (u[a] + FOLD_DIFF_STEP).min(1.0);
            let mut ul = u;
            ul[a] = lo;
            let mut uh = u;
            uh[a] = hi;
            e.eval_into(EvalMethod::default(), ul, &mut p, &mut g)?;
            let dl = det3(&g);
            e.eval_into(EvalMethod::default(), uh, &mut p, &mut g)?;
            let dh = det3(&g);
            grad[a] = (dh - dl) / (hi - lo);
        }
        Ok((det, grad))
    }

    fn fold_newton(
        &self,
        e: &VolumeEvaluator<'_>,
        start: [f64; 3],
        origin: [f64; 3],
        d: [f64; 3],
        planes: [[f64; 3]; 2],
        offs: [f64; 2],
    ) -> Result<Option<BoundaryHit>, TrivariateError> {
        let tol = self.options.tolerance * self.diagonal;
        let mut u = start;
        let mut p = [0.0; 3];
        let mut g = [0.0; 9];
        for _ in 0..self.options.max_iterations {
            e.eval_into(EvalMethod::default(), u, &mut p, &mut g)?;
            let f = [dot3(planes[0], p) + offs[0], dot3(planes[1], p) + offs[1]];
            let (det, grad) = self.det_and_gradient(e, u)?;
            let scale = norm3(col(&g, 0)) * norm3(col(&g, 1)) * norm3(col(&g, 2));
            let on_ray = f[0].abs().max(f[1].abs()) <= tol;
            let singular = det.abs() <= 1e-10 * scale || scale == 0.0;
            if on_ray && singular {
                return Ok(self.make_hit(e, u, p, &g, origin, d, HitKind::Fold));
            }
            let m = [
                [
                    dot3(planes[0], col(&g, 0)),
                    dot3(planes[0], col(&g, 1)),
                    dot3(planes[0], col(&g, 2)),
                ],
                [
                    dot3(planes[1], col(&g, 0)),
                    dot3(planes[1], col(&g, 1)),
                    dot3(planes[1], col(&g, 2)),
                ],
                grad,
            ];
            let Some(step) = solve3_rows(m, [-f[0], -f[1], -det]) else {
                return Ok(None);
            };
            let next: [f64; 3] = std::array::from_fn(|a| (u[a] + step[a]).clamp(0.0, 1.0));
            if next == u {
                return Ok(None);
            }
            u = next;
        }
        Ok(None)
    }

    /// Assemble a hit at parameters `u` (point `p`, Jacobian `g`) if it lies ahead of the ray
    /// origin.
    #[allow(clippy::too_many_arguments)]
    fn make_hit(
        &self,
        _e: &VolumeEvaluator<'_>,
        u: [f64; 3],
        p: [f64; 3],
        g: &[f64; 9],
        origin: [f64; 3],
        d: [f64; 3],
        kind: HitKind,
    ) -> Option<BoundaryHit> {
        let t = dot3([p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]], d);
        if t < -self.options.merge_distance * self.diagonal {
            return None;
        }
        let raw = match kind {
            HitKind::Face { axis, .. } => {
                let free = match axis {
                    0 => [1, 2],
                    1 => [0, 2],
                    _ => [0, 1],
                };
                cross3(col(g, free[0]), col(g, free[1]))
            }
            HitKind::Fold => {
                // The image of a rank-2 Jacobian is a plane; its normal is the largest cross
                // product of two columns.
                let cs = [
                    cross3(col(g, 0), col(g, 1)),
                    cross3(col(g, 1), col(g, 2)),
                    cross3(col(g, 2), col(g, 0)),
                ];
                let mut best = cs[0];
                for c in cs {
                    if norm3(c) > norm3(best) {
                        best = c;
                    }
                }
                best
            }
        };
        let n = norm3(raw);
        let mut normal = if n > 0.0 && n.is_finite() {
            raw.map(|x| x / n)
        } else {
            [0.0; 3]
        };
        if dot3(normal, d) > 0.0 {
            normal = normal.map(|x| -x);
        }
        Some(BoundaryHit {
            t: t.max(0.0),
            point: p,
            params: u,
            kind,
            normal,
        })
    }

    /// Parameters of the physical point `x` if it lies in the solid (within the tracer's
    /// tolerance), by inversion ([`invert`]) from `guess`; `None` when it is outside.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for a non-finite point.
    pub fn locate(
        &self,
        x: [f64; 3],
        guess: Option<[f64; 3]>,
    ) -> Result<Option<[f64; 3]>, TrivariateError> {
        if !x.iter().all(|v| v.is_finite()) {
            return Err(TrivariateError::InvalidArgument(format!(
                "point {x:?} must be finite"
            )));
        }
        let pad = 1e-9 * self.diagonal;
        if (0..3).any(|k| x[k] < self.lo[k] - pad || x[k] > self.hi[k] + pad) {
            return Ok(None);
        }
        let opts = InversionOptions {
            tolerance: (1e-10 * self.diagonal).max(f64::MIN_POSITIVE),
            max_depth: 12,
            max_pieces: 512,
            ..InversionOptions::default()
        };
        match invert(&self.geometry, x, guess, &opts) {
            Ok(u) => Ok(Some(u)),
            Err(TrivariateError::InversionFailed { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Parameters, point and Jacobian of the physical point `target`, tracked by the Newton
    /// iteration of eq. 9 from the parameters `from` of a nearby point (see the
    /// [module docs](self)); `None` when `target` is outside the solid.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] for non-finite input.
    pub fn track(
        &self,
        target: [f64; 3],
        from: [f64; 3],
    ) -> Result<Option<Tracked>, TrivariateError> {
        if !target.iter().chain(&from).all(|v| v.is_finite()) {
            return Err(TrivariateError::InvalidArgument(format!(
                "tracking target {target:?} and start {from:?} must be finite"
            )));
        }
        let e = VolumeEvaluator::new(&self.geometry);
        let tol = 1e-10 * self.diagonal;
        let mut u = from.map(|v| v.clamp(0.0, 1.0));
        let mut p = [0.0; 3];
        let mut g = [0.0; 9];
        for _ in 0..self.options.max_iterations.min(12) {
            e.eval_into(EvalMethod::default(), u, &mut p, &mut g)?;
            let r = [target[0] - p[0], target[1] - p[1], target[2] - p[2]];
            if norm3(r) <= tol {
                return Ok(Some(Tracked {
                    params: u,
                    point: p,
                    jacobian: g,
                }));
            }
            let m = [[g[0], g[3], g[6]], [g[1], g[4], g[7]], [g[2], g[5], g[8]]];
            let Some(step) = solve3_rows(m, r) else { break };
            let next: [f64; 3] = std::array::from_fn(|a| u[a] + step[a]);
            // Leaving the domain by more than rounding: fall back to inversion.
            if next.iter().any(|&v| !(-1e-9..=1.0 + 1e-9).contains(&v)) {
                break;
            }
            u = next.map(|v| v.clamp(0.0, 1.0));
        }
        let Some(u) = self.locate(target, Some(u))? else {
            return Ok(None);
        };
        e.eval_into(EvalMethod::default(), u, &mut p, &mut g)?;
        Ok(Some(Tracked {
            params: u,
            point: p,
            jacobian: g,
        }))
    }
}

/// Layer `side` (0 first, 1 last) of the clamped volume net along `axis`, as a surface over the
/// two other axes (in increasing order).
fn face_surface(
    g: &TensorBSpline<3>,
    axis: usize,
    side: usize,
) -> Result<TensorBSpline<2>, TrivariateError> {
    let n = g.counts();
    let hd = g.homogeneous_dim();
    let h = g.homogeneous_coefficients();
    let layer = if side == 0 { 0 } else { n[axis] - 1 };
    let free = match axis {
        0 => [1, 2],
        1 => [0, 2],
        _ => [0, 1],
    };
    let mut coefs = Vec::with_capacity(n[free[0]] * n[free[1]] * hd);
    for b in 0..n[free[1]] {
        for a in 0..n[free[0]] {
            let mut idx = [0usize; 3];
            idx[axis] = layer;
            idx[free[0]] = a;
            idx[free[1]] = b;
            let o = hd * ((idx[2] * n[1] + idx[1]) * n[0] + idx[0]);
            coefs.extend_from_slice(&h[o..o + hd]);
        }
    }
    let knots = [g.knots()[free[0]].clone(), g.knots()[free[1]].clone()];
    TensorBSpline::from_homogeneous(knots, 3, g.is_rational(), coefs).map_err(ctx("face surface"))
}

fn build_face_tree(
    g: &TensorBSpline<3>,
    axis: usize,
    side: usize,
    o: &TraceOptions,
    diagonal: f64,
) -> Result<Tree, TrivariateError> {
    let surf = face_surface(g, axis, side)?;
    let free = match axis {
        0 => [1, 2],
        1 => [0, 2],
        _ => [0, 1],
    };
    let mut tree = Tree::default();
    let flat = o.flatness * diagonal;
    for piece in surf.bezier_pieces().map_err(ctx("face patches"))? {
        let root = add_patch(&mut tree, piece, 0, o.max_depth, flat, axis, side, free)?;
        tree.roots.push(root);
    }
    Ok(tree)
}

#[allow(clippy::too_many_arguments)]
fn add_patch(
    tree: &mut Tree,
    piece: BezierPiece<2>,
    depth: usize,
    max_depth: usize,
    flat: f64,
    axis: usize,
    side: usize,
    free: [usize; 2],
) -> Result<u32, TrivariateError> {
    let (lo, hi) = piece_box(&piece);
    let dom = piece.domain();
    let mut start = [0.0; 3];
    start[axis] = side as f64;
    start[free[0]] = 0.5 * (dom[0][0] + dom[0][1]);
    start[free[1]] = 0.5 * (dom[1][0] + dom[1][1]);
    let idx = u32::try_from(tree.nodes.len())
        .map_err(|_| TrivariateError::InvalidArgument("face hierarchy too large".into()))?;
    tree.nodes.push(Node {
        lo,
        hi,
        start,
        children: Vec::new(),
    });
    if depth < max_depth && patch_flatness(&piece) > flat {
        let a = usize::from(polygon_length(&piece, 1) > polygon_length(&piece, 0));
        let [s, e] = dom[a];
        let (l, r) = piece
            .split(a, 0.5 * (s + e))
            .map_err(ctx("face subdivision"))?;
        let li = add_patch(tree, l, depth + 1, max_depth, flat, axis, side, free)?;
        let ri = add_patch(tree, r, depth + 1, max_depth, flat, axis, side, free)?;
        if let Some(n) = tree.nodes.get_mut(idx as usize) {
            n.children = vec![li, ri];
        }
    }
    Ok(idx)
}

fn build_fold_tree(
    g: &TensorBSpline<3>,
    o: &TraceOptions,
    box_volume: f64,
) -> Result<Tree, TrivariateError> {
    let mut tree = Tree::default();
    let vol_tol = o.volume_tolerance * box_volume;
    for cell in g.bezier_pieces().map_err(ctx("volume cells"))? {
        if let Some(root) = add_cell(&mut tree, cell, 0, o.max_depth, vol_tol)? {
            tree.roots.push(root);
        }
    }
    Ok(tree)
}

/// `true` when the cones prove `det JP ≠ 0` on the cell.
fn jacobian_sign_fixed(cell: &BezierPiece<3>) -> bool {
    let [cu, cv, cw] = derivative_cones(cell);
    cu.dot_excludes_zero(&cv.cross(&cw))
}

fn add_cell(
    tree: &mut Tree,
    cell: BezierPiece<3>,
    depth: usize,
    max_depth: usize,
    vol_tol: f64,
) -> Result<Option<u32>, TrivariateError> {
    if jacobian_sign_fixed(&cell) {
        return Ok(None);
    }
    let (lo, hi) = piece_box(&cell);
    let dom = cell.domain();
    let start = dom.map(|[a, b]| 0.5 * (a + b));
    let idx = u32::try_from(tree.nodes.len())
        .map_err(|_| TrivariateError::InvalidArgument("fold hierarchy too large".into()))?;
    tree.nodes.push(Node {
        lo,
        hi,
        start,
        children: Vec::new(),
    });
    let volume: f64 = (0..3).map(|k| hi[k] - lo[k]).product();
    if depth < max_depth && volume > vol_tol {
        let a = (0..3)
            .max_by(|&x, &y| {
                (dom[x][1] - dom[x][0])
                    .total_cmp(&(dom[y][1] - dom[y][0]))
                    .then(y.cmp(&x))
            })
            .unwrap_or(0);
        let [s, e] = dom[a];
        let (l, r) = cell
            .split(a, 0.5 * (s + e))
            .map_err(ctx("cell subdivision"))?;
        let mut children = Vec::with_capacity(2);
        if let Some(c) = add_cell(tree, l, depth + 1, max_depth, vol_tol)? {
            children.push(c);
        }
        if let Some(c) = add_cell(tree, r, depth + 1, max_depth, vol_tol)? {
            children.push(c);
        }
        if children.is_empty() {
            // Both halves proved free of folds: drop this node as well.
            tree.nodes.truncate(idx as usize);
            return Ok(None);
        }
        if let Some(n) = tree.nodes.get_mut(idx as usize) {
            n.children = children;
        }
    }
    Ok(Some(idx))
}
