//! Accurate B-spline FFD of a polygon mesh as trimmed tensor-product Bézier surfaces (Feng et
//! al. 2002 §3.2–3.4).
//!
//! [`AccuratePlan::new`] does the work that depends only on the mesh and the lattice's knots
//! and frame, once: the faces are checked and repaired ([`crate::polygon`]), mapped to the
//! lattice's parameter space, cut by the knot planes ([`crate::subdivide`]), and the
//! sub-polygons of each knot cell are grouped into coplanar **patches** with the paper's
//! tolerances [`EPS_N`] and [`EPS_D`]. Each patch gets its local frame and surface degrees
//! from Table 1 ([`crate::frame`]) and the 2D bounding rectangle of its sub-polygons. The
//! union of a patch's sub-polygons is traced into trimming loops (one outer loop, counter-
//! clockwise in `(σ, τ)`, plus holes), giving the **faces**; every loop edge is a shared
//! topological **edge** of the model.
//!
//! [`AccuratePlan::deform`] then evaluates the lattice: for each patch the samples
//! `V(o + σ_i s + τ_j t)` on the `(n_s + 1) × (n_t + 1)` grid of its rectangle are computed
//! with the polynomial piece of the patch's **own** knot cell even where the rectangle leaves
//! the cell (the generalized de Boor–Cox evaluation of §3.4.2), and the Bézier control points
//! follow by the two-stage interpolation of Eqs. (3)–(4) ([`crate::interp`]). Each edge gets
//! its exact 3D image, a Bézier curve interpolated from the surface of the first face using
//! it. Cells outside the lattice box are not moved by the lattice map, so their patches are the
//! planar (degree 1 × 1) identity.
//!
//! # Conventions
//!
//! * Patch parameters `(σ, τ)` are lengths in the lattice's **parameter space** along the
//!   patch's `s` and `t` from its origin `o`; the Bézier surface is defined on its rectangle
//!   `[σ₀, σ₁] × [τ₀, τ₁]`, and trimming loops are polylines in the same coordinates.
//! * The coplanarity tests use coordinates normalised so the model's parameter-space bounding
//!   box has diagonal 1 and centre 0: `|n₁·n₂ − 1| < ε_n`, `|d₁ − d₂| < ε_d`, and every corner
//!   of a sub-polygon joining a patch must lie within `ε_d` of the patch's plane (so flattening
//!   a nearly coplanar polygon onto the patch moves it by at most `ε_d` of the model size).

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use rayon::prelude::*;
use volmorph_deform::SpaceMap;
use volmorph_lattice::{BSplineLattice, LatticeFrame};
use volmorph_mesh::Mesh;
use volmorph_spline::{KnotVector, MAX_DEGREE, basis_funs_into, bernstein_into};

use crate::FfdError;
use crate::frame::{PlaneFrame, direction_degree, plane_frame};
use crate::interp::{MAX_INTERPOLATION_DEGREE, interpolate_curve, interpolate_surface};
use crate::polygon::{PreparedPolygons, RepairReport, newell, prepare_polygons};
use crate::subdivide::{CellIndex, KnotPlanes, PLANE_TOL_REL, Subdivision, subdivide};

/// Normal tolerance of the coplanarity test, `|n₁·n₂ − 1| < ε_n` (Feng et al. 2002 §3.3.2).
pub const EPS_N: f64 = 2.2e-8;
/// Sub-polygons grouped per progress step of [`AccuratePlan::new_with`] (the grouping is a
/// serial loop; a step per sub-polygon would cost more than the work it reports).
pub const PROGRESS_CHUNK: usize = 4096;
/// Offset tolerance of the coplanarity test, `|d₁ − d₂| < ε_d`, in model-normalised units
/// (Feng et al. 2002 §3.3.2).
pub const EPS_D: f64 = 1.1e-6;

/// A Bézier surface of degrees `(n_s, n_t)` on the rectangle `[σ₀, σ₁] × [τ₀, τ₁]`.
#[derive(Debug, Clone, PartialEq)]
pub struct BezierSurface {
    /// `(n_s, n_t)`.
    pub degrees: [usize; 2],
    /// `[[σ₀, σ₁], [τ₀, τ₁]]`.
    pub rect: [[f64; 2]; 2],
    /// `(n_s + 1)(n_t + 1)` control points (physical coordinates), index `i + (n_s + 1)·j`
    /// (σ index fastest).
    pub control_points: Vec<DVec3>,
}

impl BezierSurface {
    /// The point at `(σ, τ)` (extrapolated outside the rectangle).
    #[must_use]
    pub fn eval(&self, st: [f64; 2]) -> DVec3 {
        self.eval_with_partials(st).0
    }

    /// The point and its partial derivatives `∂/∂σ`, `∂/∂τ` at `(σ, τ)`.
    #[must_use]
    pub fn eval_with_partials(&self, st: [f64; 2]) -> (DVec3, DVec3, DVec3) {
        let [ns, nt] = self.degrees;
        let mut bs = [0.0; MAX_DEGREE + 1];
        let mut bt = [0.0; MAX_DEGREE + 1];
        let mut ds = [0.0; MAX_DEGREE + 1];
        let mut dt = [0.0; MAX_DEGREE + 1];
        let w = [
            self.rect[0][1] - self.rect[0][0],
            self.rect[1][1] - self.rect[1][0],
        ];
        let x = (st[0] - self.rect[0][0]) / w[0];
        let y = (st[1] - self.rect[1][0]) / w[1];
        if ns > MAX_DEGREE || nt > MAX_DEGREE {
            return (DVec3::NAN, DVec3::NAN, DVec3::NAN);
        }
        bernstein_derivs(ns, x, &mut bs, &mut ds);
        bernstein_derivs(nt, y, &mut bt, &mut dt);
        let a = ns + 1;
        let (mut p, mut ps, mut pt) = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
        for j in 0..=nt {
            let (mut row, mut drow) = (DVec3::ZERO, DVec3::ZERO);
            for i in 0..=ns {
                let c = self.control_points[i + a * j];
                row += bs[i] * c;
                drow += ds[i] * c;
            }
            p += bt[j] * row;
            ps += bt[j] * drow;
            pt += dt[j] * row;
        }
        (p, ps / w[0], pt / w[1])
    }

    /// The constant partial derivatives `(∂S/∂σ, ∂S/∂τ)` when the surface is an affine map of
    /// its parameters (control points on the evenly spaced grid spanned by the corner points
    /// `P₀₀`, `P_{n_s,0}`, `P_{0,n_t}`, within [`AFFINE_TOLERANCE`] of the control net's
    /// largest coordinate), as where the lattice is affine over the patch; `None` otherwise.
    #[must_use]
    pub fn affine_partials(&self) -> Option<(DVec3, DVec3)> {
        let [ns, nt] = self.degrees;
        let a = ns + 1;
        if self.control_points.len() != a * (nt + 1) {
            return None;
        }
        let p00 = self.control_points[0];
        let es = if ns > 0 {
            (self.control_points[ns] - p00) / ns as f64
        } else {
            DVec3::ZERO
        };
        let et = if nt > 0 {
            (self.control_points[a * nt] - p00) / nt as f64
        } else {
            DVec3::ZERO
        };
        let magnitude = self
            .control_points
            .iter()
            .map(|q| q.abs().max_element())
            .fold(0.0_f64, f64::max);
        let tol = AFFINE_TOLERANCE * magnitude;
        let affine = (0..=nt).all(|j| {
            (0..=ns).all(|i| {
                let q = self.control_points[i + a * j];
                (q - (p00 + i as f64 * es + j as f64 * et))
                    .abs()
                    .max_element()
                    <= tol
            })
        });
        let w = [
            self.rect[0][1] - self.rect[0][0],
            self.rect[1][1] - self.rect[1][0],
        ];
        (affine && magnitude.is_finite()).then(|| (es * ns as f64 / w[0], et * nt as f64 / w[1]))
    }
}

/// Largest deviation of a control point from the affine grid, relative to the largest
/// coordinate magnitude of the control net, for [`BezierSurface::affine_partials`] to call the
/// surface affine. Surfaces interpolated where the lattice is affine deviate by rounding only:
/// on a 58,784-triangle bunny under a lattice with one control point moved, every one of the
/// ~60,000 affine patches deviated by at most 3e-13 of that magnitude and every curved one by
/// more than 5e-6, so 1e-11 separates them with a wide margin on both sides. A deviation `δ`
/// changes the area of a degree-`n` patch by at most about `2nδ` times its perimeter, below
/// 1e-9 of any patch larger than a micrometre in a model of metres.
pub const AFFINE_TOLERANCE: f64 = 1e-11;

/// Bernstein values and first derivatives of degree `n` at `x` (any real `x`).
fn bernstein_derivs(n: usize, x: f64, b: &mut [f64], d: &mut [f64]) {
    if n == 0 {
        b[0] = 1.0;
        d[0] = 0.0;
        return;
    }
    let mut lower = [0.0; MAX_DEGREE + 1];
    // Lengths are checked by the callers (n ≤ MAX_DEGREE).
    let _ = bernstein_into(n - 1, x, &mut lower);
    let _ = bernstein_into(n, x, b);
    for i in 0..=n {
        let left = if i > 0 { lower[i - 1] } else { 0.0 };
        let right = if i < n { lower[i] } else { 0.0 };
        d[i] = n as f64 * (left - right);
    }
}

/// A Bézier curve on `t ∈ [0, 1]` (physical coordinates), degree `control_points.len() − 1`.
#[derive(Debug, Clone, PartialEq)]
pub struct BezierCurve {
    /// Control points `P_0 … P_m`.
    pub control_points: Vec<DVec3>,
}

impl BezierCurve {
    /// The degree `m`.
    #[must_use]
    pub fn degree(&self) -> usize {
        self.control_points.len().saturating_sub(1)
    }

    /// The point at `t`.
    #[must_use]
    pub fn eval(&self, t: f64) -> DVec3 {
        let m = self.degree();
        let mut b = [0.0; MAX_DEGREE + 1];
        if m > MAX_DEGREE || bernstein_into(m, t, &mut b).is_err() {
            return DVec3::NAN;
        }
        self.control_points.iter().zip(b).map(|(&p, w)| w * p).sum()
    }
}

/// One coplanar group of sub-polygons in one knot cell: Feng's `Normal` structure.
#[derive(Debug, Clone, PartialEq)]
pub struct Patch {
    /// The knot cell (see [`crate::subdivide::CellIndex`]).
    pub cell: CellIndex,
    /// Whether the cell lies inside the lattice box (otherwise the map is the identity).
    pub inside: bool,
    /// Table 1 frame and degrees (degrees `(1, 1)` outside the box).
    pub frame: PlaneFrame,
    /// Origin `o` of the `(σ, τ)` coordinates, in parameter space.
    pub origin: DVec3,
    /// Offset `d` of the plane `n·x̂ + d = 0` in normalised coordinates (for the tests).
    pub d: f64,
    /// Bounding rectangle `[[σ₀, σ₁], [τ₀, τ₁]]` of the member sub-polygons.
    pub rect: [[f64; 2]; 2],
    /// Member sub-polygons.
    pub members: Vec<u32>,
}

impl Patch {
    /// `(σ, τ)` of parameter-space point `p` (its projection onto the patch plane).
    #[must_use]
    pub fn param_of(&self, p: DVec3) -> [f64; 2] {
        let r = p - self.origin;
        [r.dot(self.frame.s), r.dot(self.frame.t)]
    }

    /// Parameter-space point of `(σ, τ)`: `o + σ s + τ t`.
    #[must_use]
    pub fn point_at(&self, st: [f64; 2]) -> DVec3 {
        self.origin + st[0] * self.frame.s + st[1] * self.frame.t
    }

    /// Surface degrees `(n_s, n_t)`.
    #[must_use]
    pub fn degrees(&self) -> [usize; 2] {
        self.frame.degrees
    }
}

/// A trimmed face: a patch and its trimming loops (point indices of the subdivision).
#[derive(Debug, Clone, PartialEq)]
pub struct TrimmedFace {
    /// The patch whose surface carries the face.
    pub patch: u32,
    /// `loops[0]` is the outer loop (counter-clockwise in `(σ, τ)`), the rest are holes
    /// (clockwise).
    pub loops: Vec<Vec<u32>>,
}

/// A topological edge between two subdivision points, shared by the faces that use it.
#[derive(Debug, Clone, PartialEq)]
pub struct Edge {
    /// Start point (the smaller index).
    pub start: u32,
    /// End point.
    pub end: u32,
    /// Uses `(face, same_direction)`: `same_direction` when the face's loop runs start → end.
    pub uses: Vec<(u32, bool)>,
}

/// Counts of the paper's Table 2 and timings.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AccurateStats {
    /// Faces of the input mesh.
    pub input_faces: usize,
    /// Convex polygons after repair (what the paper calls the original object's polygons).
    pub input_polygons: usize,
    /// Sub-polygons after knot-plane subdivision.
    pub sub_polygons: usize,
    /// Bézier patches (coplanar groups per knot cell).
    pub patches: usize,
    /// Trimmed faces (connected regions of patches).
    pub faces: usize,
    /// Topological edges.
    pub edges: usize,
    /// Time of [`AccuratePlan::new`] (subdivision, grouping, trimming topology).
    pub plan_time: Duration,
    /// Time of the last [`AccuratePlan::deform`] (interpolation and edge curves).
    pub deform_time: Duration,
}

/// Everything of the accurate FFD that depends only on the mesh and the lattice's knots and
/// frame (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct AccuratePlan {
    knots: [KnotVector; 3],
    lattice_frame: LatticeFrame,
    planes: KnotPlanes,
    /// Knot-vector span index of slab `s` (1-based) per axis: `span_index[a][s − 1]`.
    span_index: [Vec<usize>; 3],
    sub: Subdivision,
    /// Physical positions of the subdivision points before deformation.
    physical: Vec<DVec3>,
    sub_patch: Vec<u32>,
    patches: Vec<Patch>,
    faces: Vec<TrimmedFace>,
    edges: Vec<Edge>,
    report: RepairReport,
    stats: AccurateStats,
}

impl AccuratePlan {
    /// Subdivide and group `mesh` for lattices with the knots and frame of `lattice` (see the
    /// [module docs](self)).
    ///
    /// # Errors
    /// The errors of [`prepare_polygons`] and [`subdivide`]; [`FfdError::DegreeTooHigh`] when
    /// a patch would need a degree above [`MAX_INTERPOLATION_DEGREE`].
    pub fn new(mesh: &Mesh, lattice: &BSplineLattice) -> Result<Self, FfdError> {
        Self::new_with(mesh, lattice, &volmorph_io::NoProgress)
    }

    /// [`AccuratePlan::new`] reporting to `progress` and stopping when it is cancelled. Three
    /// stages: the knot-plane subdivision (one step), the coplanar grouping (one step per
    /// [`PROGRESS_CHUNK`] sub-polygons, rounded up) and the tracing of trimmed faces (one step
    /// per patch). The plan equals [`AccuratePlan::new`]'s.
    ///
    /// # Errors
    /// As [`AccuratePlan::new`]; [`FfdError::Cancelled`] when `progress` asks to stop.
    pub fn new_with(
        mesh: &Mesh,
        lattice: &BSplineLattice,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Self, FfdError> {
        let start = Instant::now();
        progress.start("subdividing the mesh by the knot planes", 1);
        progress.check()?;
        let prepared = prepare_polygons(mesh)?;
        let PreparedPolygons {
            positions,
            indices,
            offsets,
            report,
            ..
        } = prepared;
        let input_polygons = offsets.len() - 1;
        let frame = *lattice.frame();
        let knots = lattice.knots().clone();
        let k = lattice.degree();
        let mut planes = KnotPlanes {
            values: [Vec::new(), Vec::new(), Vec::new()],
        };
        let mut span_index: [Vec<usize>; 3] = [Vec::new(), Vec::new(), Vec::new()];
        for a in 0..3 {
            planes.values[a] = knots[a].breakpoints().into_iter().map(|(v, _)| v).collect();
            span_index[a] = knots[a].spans().map(|s| s.index).collect();
        }
        let params: Vec<DVec3> = positions.iter().map(|&p| frame.to_parameter(p)).collect();
        let (lo, hi) = params
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), p| {
                (l.min(*p), h.max(*p))
            });
        let diag = (hi - lo).length();
        let scale = if diag > 0.0 && diag.is_finite() {
            diag
        } else {
            1.0
        };
        let center = 0.5 * (lo + hi);
        // Source planes (normalised coordinates).
        let source_planes: Vec<(DVec3, f64)> = offsets
            .windows(2)
            .map(|w| {
                let ring = &indices[w[0] as usize..w[1] as usize];
                let n = newell(ring.iter().map(|&i| params[i as usize])).normalize_or_zero();
                let c = ring
                    .iter()
                    .map(|&i| (params[i as usize] - center) / scale)
                    .sum::<DVec3>()
                    / ring.len() as f64;
                (n, -n.dot(c))
            })
            .collect();
        let sub = subdivide(params, &indices, &offsets, &planes, PLANE_TOL_REL * scale)?;
        progress.advance(1);
        progress.start(
            "grouping coplanar sub-polygons",
            sub.len().div_ceil(PROGRESS_CHUNK) as u64,
        );
        let mut physical = positions;
        physical.extend(
            sub.points[physical.len()..]
                .iter()
                .map(|&p| frame.to_physical(p)),
        );

        // Coplanar grouping per cell.
        let mut by_cell: HashMap<CellIndex, Vec<u32>> = HashMap::new();
        let mut patches: Vec<Patch> = Vec::new();
        let mut sub_patch = vec![0u32; sub.len()];
        for s in 0..sub.len() {
            if s % PROGRESS_CHUNK == 0 {
                progress.check()?;
                if s > 0 {
                    progress.advance(1);
                }
            }
            let ring = sub.polygon(s);
            let cell = sub.cell[s];
            let (n, d) = source_planes[sub.source[s] as usize];
            let candidates = by_cell.entry(cell).or_default();
            let found = candidates.iter().copied().find(|&g| {
                let p = &patches[g as usize];
                (p.frame.n.dot(n) - 1.0).abs() < EPS_N
                    && (p.d - d).abs() < EPS_D
                    && ring.iter().all(|&i| {
                        ((sub.points[i as usize] - p.origin).dot(p.frame.n) / scale).abs() < EPS_D
                    })
            });
            let g = if let Some(g) = found {
                g
            } else {
                let inside = planes.is_inside(cell);
                let kk = if inside { k } else { [1, 1, 1] };
                let mut pf = plane_frame(n, kk).ok_or_else(|| {
                    FfdError::Inconsistent(format!("sub-polygon {s} has no normal"))
                })?;
                if !inside {
                    pf.degrees = [1, 1];
                }
                for &deg in &pf.degrees {
                    if deg > MAX_INTERPOLATION_DEGREE {
                        return Err(FfdError::DegreeTooHigh {
                            degree: deg,
                            max: MAX_INTERPOLATION_DEGREE,
                            lattice: k,
                        });
                    }
                }
                let origin =
                    ring.iter().map(|&i| sub.points[i as usize]).sum::<DVec3>() / ring.len() as f64;
                let g = patches.len() as u32;
                patches.push(Patch {
                    cell,
                    inside,
                    frame: pf,
                    origin,
                    d: -pf.n.dot((origin - center) / scale),
                    rect: [[f64::INFINITY, f64::NEG_INFINITY]; 2],
                    members: Vec::new(),
                });
                candidates.push(g);
                g
            };
            sub_patch[s] = g;
            let p = &mut patches[g as usize];
            p.members.push(s as u32);
            for &i in ring {
                let st = p.param_of(sub.points[i as usize]);
                for (r, v) in p.rect.iter_mut().zip(st) {
                    r[0] = r[0].min(v);
                    r[1] = r[1].max(v);
                }
            }
        }
        if !sub.is_empty() {
            progress.advance(1);
        }
        progress.start("tracing trimmed faces", patches.len() as u64);
        let faces = trace_faces(&sub, &patches, progress)?;
        let edges = collect_edges(&faces)?;
        let stats = AccurateStats {
            input_faces: mesh.face_count(),
            input_polygons,
            sub_polygons: sub.len(),
            patches: patches.len(),
            faces: faces.len(),
            edges: edges.len(),
            plan_time: start.elapsed(),
            deform_time: Duration::ZERO,
        };
        Ok(Self {
            knots,
            lattice_frame: frame,
            planes,
            span_index,
            sub,
            physical,
            sub_patch,
            patches,
            faces,
            edges,
            report,
            stats,
        })
    }

    /// The subdivision (points in parameter space, sub-polygons, their cells).
    #[must_use]
    pub fn subdivision(&self) -> &Subdivision {
        &self.sub
    }

    /// Physical positions of the subdivision points before deformation.
    #[must_use]
    pub fn physical_points(&self) -> &[DVec3] {
        &self.physical
    }

    /// The patch of each sub-polygon.
    #[must_use]
    pub fn sub_polygon_patch(&self) -> &[u32] {
        &self.sub_patch
    }

    /// The patches.
    #[must_use]
    pub fn patches(&self) -> &[Patch] {
        &self.patches
    }

    /// The trimmed faces.
    #[must_use]
    pub fn faces(&self) -> &[TrimmedFace] {
        &self.faces
    }

    /// The topological edges.
    #[must_use]
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// The knot planes.
    #[must_use]
    pub fn planes(&self) -> &KnotPlanes {
        &self.planes
    }

    /// Repairs made to the input faces.
    #[must_use]
    pub fn repairs(&self) -> &RepairReport {
        &self.report
    }

    /// Counts and the planning time.
    #[must_use]
    pub fn stats(&self) -> AccurateStats {
        self.stats
    }

    /// Evaluate the deformation by `lattice` (same knots and frame as the plan's) as trimmed
    /// Bézier surfaces.
    ///
    /// # Errors
    /// [`FfdError::LatticeMismatch`] if the knots or the frame differ,
    /// [`FfdError::Inconsistent`] if an interpolation fails (degree out of range).
    pub fn deform(self: &Arc<Self>, lattice: &BSplineLattice) -> Result<TrimmedModel, FfdError> {
        self.deform_with(lattice, &volmorph_io::NoProgress)
    }

    /// [`AccuratePlan::deform`] reporting to `progress` and stopping when it is cancelled.
    /// Two stages: the surfaces (one step per patch) and the edge curves (one step per
    /// edge). The model equals [`AccuratePlan::deform`]'s.
    ///
    /// # Errors
    /// As [`AccuratePlan::deform`]; [`FfdError::Cancelled`] when `progress` asks to stop.
    pub fn deform_with(
        self: &Arc<Self>,
        lattice: &BSplineLattice,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<TrimmedModel, FfdError> {
        let start = Instant::now();
        if lattice.knots() != &self.knots {
            return Err(FfdError::LatticeMismatch("knot vectors differ".into()));
        }
        if lattice.frame() != &self.lattice_frame {
            return Err(FfdError::LatticeMismatch("parameter frames differ".into()));
        }
        let ctrl = lattice.control_points();
        let eval = CellEval {
            knots: &self.knots,
            counts: lattice.counts(),
            ctrl: &ctrl,
            frame: &self.lattice_frame,
        };
        progress.start("interpolating Bézier surfaces", self.patches.len() as u64);
        let surfaces: Vec<BezierSurface> = self
            .patches
            .par_iter()
            .map(|p| {
                progress.check()?;
                let spans = self.cell_spans(p.cell);
                let [ns, nt] = p.frame.degrees;
                let (a, b) = (ns + 1, nt + 1);
                let mut samples = vec![DVec3::ZERO; a * b];
                for j in 0..b {
                    let tau = lerp(p.rect[1], j as f64 / nt as f64);
                    for i in 0..a {
                        let sigma = lerp(p.rect[0], i as f64 / ns as f64);
                        samples[i + a * j] = eval.eval(spans, p.point_at([sigma, tau]));
                    }
                }
                let mut scratch = vec![DVec3::ZERO; a * b];
                let mut cps = vec![DVec3::ZERO; a * b];
                if !interpolate_surface([ns, nt], &samples, &mut scratch, &mut cps) {
                    return Err(FfdError::Inconsistent(format!(
                        "cannot interpolate a surface of degrees {ns} × {nt}"
                    )));
                }
                progress.advance(1);
                Ok(BezierSurface {
                    degrees: [ns, nt],
                    rect: p.rect,
                    control_points: cps,
                })
            })
            .collect::<Result<_, _>>()?;
        let images: Vec<DVec3> = self
            .physical
            .par_iter()
            .map(|&x| lattice.apply(x))
            .collect();
        let k = lattice.degree();
        progress.start("interpolating edge curves", self.edges.len() as u64);
        let edge_curves: Vec<BezierCurve> = self
            .edges
            .par_iter()
            .map(|e| {
                progress.check()?;
                let (face, forward) = e.uses.first().copied().unwrap_or((0, true));
                let pi = self.faces[face as usize].patch as usize;
                let p = &self.patches[pi];
                let (a, b) = (e.start as usize, e.end as usize);
                let _ = forward;
                let sa = p.param_of(self.sub.points[a]);
                let sb = p.param_of(self.sub.points[b]);
                let dir = p.point_at(sb) - p.point_at(sa);
                let mut deg = if p.inside {
                    direction_degree(snap_direction(dir), k)
                } else {
                    1
                };
                deg = deg.clamp(1, p.frame.degrees[0] + p.frame.degrees[1]);
                let mut samples = vec![DVec3::ZERO; deg + 1];
                for (i, s) in samples.iter_mut().enumerate() {
                    let t = i as f64 / deg as f64;
                    *s = surfaces[pi].eval([lerp([sa[0], sb[0]], t), lerp([sa[1], sb[1]], t)]);
                }
                let mut cps = vec![DVec3::ZERO; deg + 1];
                if !interpolate_curve(&samples, &mut cps) {
                    return Err(FfdError::Inconsistent(format!(
                        "cannot interpolate an edge curve of degree {deg}"
                    )));
                }
                progress.advance(1);
                Ok(BezierCurve {
                    control_points: cps,
                })
            })
            .collect::<Result<_, _>>()?;
        let mut stats = self.stats;
        stats.deform_time = start.elapsed();
        Ok(TrimmedModel {
            plan: Arc::clone(self),
            surfaces,
            images,
            edge_curves,
            stats,
        })
    }

    /// Knot-vector span indices of an inside cell (`None` outside the box).
    fn cell_spans(&self, cell: CellIndex) -> Option<[usize; 3]> {
        if !self.planes.is_inside(cell) {
            return None;
        }
        let mut s = [0; 3];
        for a in 0..3 {
            s[a] = *self.span_index[a].get(cell[a] as usize - 1)?;
        }
        Some(s)
    }
}

/// Components below 1e-13 of the largest are taken as zero when choosing an edge's degree.
fn snap_direction(d: DVec3) -> DVec3 {
    let m = d.abs().max_element();
    DVec3::select(d.abs().cmple(DVec3::splat(1e-13 * m)), DVec3::ZERO, d)
}

fn lerp(r: [f64; 2], t: f64) -> f64 {
    if t == 1.0 {
        r[1]
    } else {
        r[0] + t * (r[1] - r[0])
    }
}

/// Evaluation of one polynomial piece of the lattice (generalized de Boor–Cox, §3.4.2).
struct CellEval<'a> {
    knots: &'a [KnotVector; 3],
    counts: [usize; 3],
    ctrl: &'a [DVec3],
    frame: &'a LatticeFrame,
}

impl CellEval<'_> {
    /// The piece of cell `spans` at parameter `u` (extrapolated outside the cell); the
    /// identity `F(u)` for cells outside the box (`spans = None`).
    fn eval(&self, spans: Option<[usize; 3]>, u: DVec3) -> DVec3 {
        let Some(spans) = spans else {
            return self.frame.to_physical(u);
        };
        let mut b = [[0.0; MAX_DEGREE + 1]; 3];
        let mut deg = [0usize; 3];
        for a in 0..3 {
            deg[a] = self.knots[a].degree();
            if basis_funs_into(&self.knots[a], spans[a], u[a], &mut b[a]).is_err() {
                return DVec3::NAN;
            }
        }
        let [nu, nv, _] = self.counts;
        let mut p = DVec3::ZERO;
        for kk in 0..=deg[2] {
            let ik = spans[2] - deg[2] + kk;
            let mut pv = DVec3::ZERO;
            for jj in 0..=deg[1] {
                let jv = spans[1] - deg[1] + jj;
                let base = nu * (jv + nv * ik) + spans[0] - deg[0];
                let row = &self.ctrl[base..=base + deg[0]];
                let pu: DVec3 = row.iter().zip(&b[0]).map(|(&c, &w)| w * c).sum();
                pv += b[1][jj] * pu;
            }
            p += b[2][kk] * pv;
        }
        p
    }
}

/// Trace the union of each patch's sub-polygons into trimmed faces.
fn trace_faces(
    sub: &Subdivision,
    patches: &[Patch],
    progress: &dyn volmorph_io::Progress,
) -> Result<Vec<TrimmedFace>, FfdError> {
    let per_patch: Vec<Vec<TrimmedFace>> = patches
        .par_iter()
        .enumerate()
        .map(|(g, p)| {
            progress.check()?;
            let faces = trace_patch(sub, p, g as u32);
            progress.advance(1);
            Ok(faces)
        })
        .collect::<Result<_, FfdError>>()?;
    let faces: Vec<TrimmedFace> = per_patch.into_iter().flatten().collect();
    if faces.len() > u32::MAX as usize {
        return Err(FfdError::TooLarge("more than 2³² faces".into()));
    }
    Ok(faces)
}

fn trace_patch(sub: &Subdivision, p: &Patch, g: u32) -> Vec<TrimmedFace> {
    let fallback = || -> Vec<TrimmedFace> {
        p.members
            .iter()
            .map(|&s| TrimmedFace {
                patch: g,
                loops: vec![sub.polygon(s as usize).to_vec()],
            })
            .collect()
    };
    if p.members.len() == 1 {
        return fallback();
    }
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for &s in &p.members {
        let r = sub.polygon(s as usize);
        for i in 0..r.len() {
            *directed.entry((r[i], r[(i + 1) % r.len()])).or_default() += 1;
        }
    }
    let mut next: HashMap<u32, u32> = HashMap::new();
    let mut boundary = 0usize;
    let mut keys: Vec<(u32, u32)> = Vec::new();
    for (&(a, b), &count) in &directed {
        if count != 1 {
            return fallback();
        }
        if directed.contains_key(&(b, a)) {
            continue;
        }
        if next.insert(a, b).is_some() {
            return fallback(); // two boundary edges leave one point
        }
        boundary += 1;
        keys.push((a, b));
    }
    keys.sort_unstable();
    let mut used: HashMap<u32, bool> = HashMap::new();
    let mut loops: Vec<Vec<u32>> = Vec::new();
    for &(a, _) in &keys {
        if used.get(&a).copied().unwrap_or(false) {
            continue;
        }
        let mut lp = vec![a];
        used.insert(a, true);
        let mut cur = a;
        loop {
            let Some(&n) = next.get(&cur) else {
                return fallback();
            };
            if n == a {
                break;
            }
            if used.get(&n).copied().unwrap_or(false) || lp.len() > boundary {
                return fallback();
            }
            used.insert(n, true);
            lp.push(n);
            cur = n;
        }
        loops.push(lp);
    }
    let area = |lp: &[u32]| -> f64 {
        let q: Vec<[f64; 2]> = lp
            .iter()
            .map(|&i| p.param_of(sub.points[i as usize]))
            .collect();
        (0..q.len())
            .map(|i| {
                let (a, b) = (q[i], q[(i + 1) % q.len()]);
                a[0] * b[1] - a[1] * b[0]
            })
            .sum::<f64>()
            * 0.5
    };
    let (outer, holes): (Vec<Vec<u32>>, Vec<Vec<u32>>) =
        loops.into_iter().partition(|lp| area(lp) > 0.0);
    match (outer.len(), holes.len()) {
        (1, _) => {
            let mut ls = outer;
            ls.extend(holes);
            vec![TrimmedFace {
                patch: g,
                loops: ls,
            }]
        }
        (n, 0) if n > 1 => outer
            .into_iter()
            .map(|lp| TrimmedFace {
                patch: g,
                loops: vec![lp],
            })
            .collect(),
        _ => fallback(),
    }
}

fn collect_edges(faces: &[TrimmedFace]) -> Result<Vec<Edge>, FfdError> {
    let mut map: HashMap<(u32, u32), u32> = HashMap::new();
    let mut edges: Vec<Edge> = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        for lp in &face.loops {
            for i in 0..lp.len() {
                let (a, b) = (lp[i], lp[(i + 1) % lp.len()]);
                if a == b {
                    return Err(FfdError::Inconsistent(format!(
                        "face {f} has a zero-length edge at point {a}"
                    )));
                }
                let key = (a.min(b), a.max(b));
                let id = *map.entry(key).or_insert_with(|| {
                    edges.push(Edge {
                        start: key.0,
                        end: key.1,
                        uses: Vec::new(),
                    });
                    (edges.len() - 1) as u32
                });
                edges[id as usize].uses.push((f as u32, a < b));
            }
        }
    }
    Ok(edges)
}

/// The deformation result: the plan's topology with surfaces, vertex images and edge curves.
#[derive(Debug, Clone)]
pub struct TrimmedModel {
    /// The plan (topology, patches, faces, edges).
    pub plan: Arc<AccuratePlan>,
    /// One Bézier surface per patch.
    pub surfaces: Vec<BezierSurface>,
    /// Point-wise FFD image of every subdivision point (physical coordinates).
    pub images: Vec<DVec3>,
    /// The exact 3D image of every edge, parametrised by `t ∈ [0, 1]` from `start` to `end`.
    pub edge_curves: Vec<BezierCurve>,
    /// Counts and timings.
    pub stats: AccurateStats,
}

/// Gauss–Legendre nodes and weights on `[0, 1]`, 8 points.
const GL8: [(f64, f64); 8] = {
    const X: [f64; 4] = [
        0.183_434_642_495_649_8,
        0.525_532_409_916_329,
        0.796_666_477_413_626_7,
        0.960_289_856_497_536_2,
    ];
    const W: [f64; 4] = [
        0.362_683_783_378_362,
        0.313_706_645_877_887_3,
        0.222_381_034_453_374_5,
        0.101_228_536_290_376_3,
    ];
    [
        (0.5 - 0.5 * X[3], 0.5 * W[3]),
        (0.5 - 0.5 * X[2], 0.5 * W[2]),
        (0.5 - 0.5 * X[1], 0.5 * W[1]),
        (0.5 - 0.5 * X[0], 0.5 * W[0]),
        (0.5 + 0.5 * X[0], 0.5 * W[0]),
        (0.5 + 0.5 * X[1], 0.5 * W[1]),
        (0.5 + 0.5 * X[2], 0.5 * W[2]),
        (0.5 + 0.5 * X[3], 0.5 * W[3]),
    ]
};

impl TrimmedModel {
    /// `(σ, τ)` of subdivision point `i` on patch `patch`.
    #[must_use]
    pub fn param_on(&self, patch: usize, i: u32) -> [f64; 2] {
        self.plan.patches[patch].param_of(self.plan.sub.points[i as usize])
    }

    /// Area of the deformed surface: `∫∫ |S_σ × S_τ| dσ dτ` over every trimmed region (in
    /// closed form where the surface is affine, see [`BezierSurface::affine_partials`]), else
    /// integrated per sub-polygon by adaptive Gauss–Legendre quadrature (8 × 8 points on the
    /// collapsed square of each fan triangle, refined until two levels agree to `1e-12`
    /// relative or 6 levels deep).
    #[must_use]
    pub fn surface_area(&self) -> f64 {
        let plan = &self.plan;
        (0..plan.sub.len())
            .into_par_iter()
            .map(|s| {
                let g = plan.sub_patch[s] as usize;
                let surf = &self.surfaces[g];
                let ring = plan.sub.polygon(s);
                let q: Vec<[f64; 2]> = ring.iter().map(|&i| self.param_on(g, i)).collect();
                let c = [
                    q.iter().map(|p| p[0]).sum::<f64>() / q.len() as f64,
                    q.iter().map(|p| p[1]).sum::<f64>() / q.len() as f64,
                ];
                // The fan's error budget is relative to the whole sub-polygon, so a sliver
                // fan triangle (marching-cubes meshes have many) is not refined to the
                // rounding noise of its own vanishing area.
                let fan = |i: usize| (c, q[i], q[(i + 1) % q.len()]);
                if let Some((ds, dt)) = surf.affine_partials() {
                    // A constant integrand: the image's area is |S_σ × S_τ| times the
                    // parameter area of the fan.
                    let jac = ds.cross(dt).length();
                    return (0..q.len())
                        .map(|i| {
                            let (x, y, z) = fan(i);
                            0.5 * ((y[0] - x[0]) * (z[1] - x[1]) - (y[1] - x[1]) * (z[0] - x[0]))
                                .abs()
                        })
                        .sum::<f64>()
                        * jac;
                }
                let whole: f64 = (0..q.len())
                    .map(|i| {
                        let (x, y, z) = fan(i);
                        tri_area(surf, x, y, z).abs()
                    })
                    .sum();
                let floor = AREA_TOLERANCE * whole;
                (0..q.len())
                    .map(|i| {
                        let (x, y, z) = fan(i);
                        tri_area_adaptive(surf, x, y, z, floor, 0, &mut 0)
                    })
                    .sum::<f64>()
            })
            .sum()
    }
}

/// Relative accuracy of [`TrimmedModel::surface_area`]'s adaptive quadrature: a triangle is
/// split until its 4-piece sum agrees with the whole to this fraction of itself or of the
/// sub-polygon it belongs to (8×8 Gauss–Legendre per piece; below ~1e-13 the comparison
/// measures rounding).
const AREA_TOLERANCE: f64 = 1e-12;

/// Deepest subdivision of [`tri_area_adaptive`] (4⁶ pieces).
const AREA_MAX_DEPTH: u32 = 6;

fn tri_area(surf: &BezierSurface, a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    // Collapsed square: x = a + u (b − a) + u v (c − b), Jacobian u·|det|.
    let e1 = [b[0] - a[0], b[1] - a[1]];
    let e2 = [c[0] - b[0], c[1] - b[1]];
    let det = (e1[0] * e2[1] - e1[1] * e2[0]).abs();
    let mut sum = 0.0;
    for &(u, wu) in &GL8 {
        for &(v, wv) in &GL8 {
            let p = [
                a[0] + u * e1[0] + u * v * e2[0],
                a[1] + u * e1[1] + u * v * e2[1],
            ];
            let (_, ds, dt) = surf.eval_with_partials(p);
            sum += wu * wv * u * ds.cross(dt).length();
        }
    }
    sum * det
}

/// Area of the image of the parameter triangle `(a, b, c)`, split in four until the pieces'
/// sum agrees with the whole within [`AREA_TOLERANCE`] of itself or within `floor` (absolute),
/// at most [`AREA_MAX_DEPTH`] levels; `calls` counts the [`tri_area`] evaluations.
fn tri_area_adaptive(
    surf: &BezierSurface,
    a: [f64; 2],
    b: [f64; 2],
    c: [f64; 2],
    floor: f64,
    depth: u32,
    calls: &mut usize,
) -> f64 {
    let whole = tri_area(surf, a, b, c);
    let mid = |p: [f64; 2], q: [f64; 2]| [0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])];
    let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
    let parts = [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)];
    let split: f64 = parts.iter().map(|&(x, y, z)| tri_area(surf, x, y, z)).sum();
    *calls += 5;
    let tol = (AREA_TOLERANCE * split.abs())
        .max(floor)
        .max(f64::MIN_POSITIVE);
    if depth >= AREA_MAX_DEPTH || (split - whole).abs() <= tol {
        return split;
    }
    parts
        .iter()
        .map(|&(x, y, z)| tri_area_adaptive(surf, x, y, z, floor, depth + 1, calls))
        .sum()
}

/// Accurate FFD in one call: [`AccuratePlan::new`] then [`AccuratePlan::deform`].
///
/// # Errors
/// As the two steps.
pub fn accurate_ffd(mesh: &Mesh, lattice: &BSplineLattice) -> Result<TrimmedModel, FfdError> {
    accurate_ffd_with(mesh, lattice, &volmorph_io::NoProgress)
}

/// [`accurate_ffd`] reporting the stages of [`AccuratePlan::new_with`] and
/// [`AccuratePlan::deform_with`] to `progress` and stopping when it is cancelled.
///
/// # Errors
/// As [`accurate_ffd`]; [`FfdError::Cancelled`] when `progress` asks to stop.
pub fn accurate_ffd_with(
    mesh: &Mesh,
    lattice: &BSplineLattice,
    progress: &dyn volmorph_io::Progress,
) -> Result<TrimmedModel, FfdError> {
    let plan = Arc::new(AccuratePlan::new_with(mesh, lattice, progress)?);
    plan.deform_with(lattice, progress)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paraboloid `z = x² + y²` over `[0, 1]²` as a biquadratic Bézier surface.
    fn paraboloid() -> BezierSurface {
        let mut cp = Vec::new();
        for j in 0..3 {
            for i in 0..3 {
                let (x, y) = (f64::from(i) / 2.0, f64::from(j) / 2.0);
                // Bernstein coefficients of x² on [0, 1]: 0, 0, 1.
                let zx = if i == 2 { 1.0 } else { 0.0 };
                let zy = if j == 2 { 1.0 } else { 0.0 };
                cp.push(DVec3::new(x, y, zx + zy));
            }
        }
        BezierSurface {
            degrees: [2, 2],
            rect: [[0.0, 1.0], [0.0, 1.0]],
            control_points: cp,
        }
    }

    /// Regression: a sliver triangle (marching-cubes meshes have many) was refined to the
    /// full depth, 4⁶ pieces, because its relative tolerance measured rounding noise of its
    /// vanishing area; a 5k-triangle torus took minutes. The error budget is now relative to
    /// the sub-polygon.
    #[test]
    fn sliver_fan_triangles_are_not_refined_to_rounding_noise() {
        let s = paraboloid();
        let sliver = ([0.2, 0.2], [0.8, 0.5], [0.5, 0.35 + 1e-13]);
        let mut calls = 0;
        let a = tri_area_adaptive(&s, sliver.0, sliver.1, sliver.2, 1e-12, 0, &mut calls);
        assert_eq!(calls, 5, "one level");
        assert!(a.abs() < 1e-12);
        // Without the polygon's floor the old test refines much deeper.
        let mut old = 0;
        tri_area_adaptive(&s, sliver.0, sliver.1, sliver.2, 0.0, 0, &mut old);
        assert!(old > 5, "{old}");
        // Full triangles keep their accuracy: the floor of a polygon of area ~1.6 changes the
        // square's area by less than 1e-12 relative.
        let (p, q, r, t) = ([0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]);
        let area = |floor: f64| {
            tri_area_adaptive(&s, p, q, r, floor, 0, &mut 0)
                + tri_area_adaptive(&s, p, r, t, floor, 0, &mut 0)
        };
        let (with_floor, without) = (area(AREA_TOLERANCE * 1.6), area(0.0));
        assert!(((with_floor - without) / without).abs() < 1e-12);
        // ∫∫ √(1 + 4x² + 4y²) over the unit square ≈ 1.86145 (independent 2-D Simpson sum).
        let n = 400;
        let h = 1.0 / f64::from(n);
        let w = |k: i32| {
            if k == 0 || k == n {
                1.0
            } else if k % 2 == 1 {
                4.0
            } else {
                2.0
            }
        };
        let mut simpson = 0.0;
        for i in 0..=n {
            for j in 0..=n {
                let (x, y) = (f64::from(i) * h, f64::from(j) * h);
                simpson += w(i) * w(j) * (1.0 + 4.0 * x * x + 4.0 * y * y).sqrt();
            }
        }
        simpson *= h * h / 9.0;
        assert!(
            (with_floor - simpson).abs() < 1e-9,
            "{with_floor} vs {simpson}"
        );
    }

    /// An affine patch of degrees (3, 2) on a skewed rectangle: its control points on the
    /// grid of `P(σ, τ) = o + σ u + τ v` at the Greville points.
    fn affine_patch(wobble: f64) -> BezierSurface {
        let (o, u, v) = (
            DVec3::new(0.3, -1.0, 2.0),
            DVec3::new(1.5, 0.2, -0.4),
            DVec3::new(-0.3, 0.9, 0.7),
        );
        let rect = [[0.25, 1.25], [-0.5, 1.5]];
        let mut cp = Vec::new();
        for j in 0..=2 {
            for i in 0..=3 {
                let sg = rect[0][0] + f64::from(i) / 3.0;
                let tg = rect[1][0] + 2.0 * f64::from(j) / 2.0;
                cp.push(o + sg * u + tg * v);
            }
        }
        cp[5].z += wobble;
        BezierSurface {
            degrees: [3, 2],
            rect,
            control_points: cp,
        }
    }

    /// The closed-form area of affine patches is what the quadrature gives, and a control
    /// point off the affine grid (beyond rounding) sends the patch back to the quadrature.
    #[test]
    fn affine_patches_have_constant_partials() {
        let s = affine_patch(0.0);
        let (ds, dt) = s.affine_partials().expect("affine");
        let (_, qs, qt) = s.eval_with_partials([0.6, 0.1]);
        assert!((ds - qs).length() < 1e-13 && (dt - qt).length() < 1e-13);
        assert!((ds - DVec3::new(1.5, 0.2, -0.4)).length() < 1e-13);
        let (a, b, c) = ([0.3, -0.4], [1.2, 0.1], [0.5, 1.4]);
        let quad = tri_area_adaptive(&s, a, b, c, 0.0, 0, &mut 0);
        let closed = 0.5
            * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])).abs()
            * ds.cross(dt).length();
        assert!(
            ((quad - closed) / closed).abs() < 1e-13,
            "{quad} vs {closed}"
        );
        assert!(affine_patch(1e-6).affine_partials().is_none());
        assert!(affine_patch(1e-13).affine_partials().is_some());
        assert!(paraboloid().affine_partials().is_none());
    }
}
