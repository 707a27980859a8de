//! Moving-least-squares image deformation in 2D (McPhail's thesis ch. 4; Schaefer, McPhail &
//! Warren): affine, similarity and rigid deformations through point handles (§4.3) and
//! line-segment handles (§4.4), precomputed for fast handle moves, and image warping by a
//! deformed grid whose quads are filled bilinearly (§4.5).
//!
//! # Conventions
//!
//! Points are `DVec2` in the image's pixel coordinates (`x` right, `y` down, pixel centres at
//! integers). A deformation sends source handles to target handles (push-forward): a source
//! pixel at `v` is drawn at `f(v)`.
//!
//! # The functional
//!
//! Every handle contributes a block of a weighted quadratic form. A point handle `p_i` with
//! weight `w_i = 1/|p_i − v|^(2α)` contributes `w_i |M p̂_i − q̂_i|²`. A segment `a_j b_j` (moved
//! to `c_j d_j`) contributes `∫₀¹ w_j(t) |M p̂_j(t) − q̂_j(t)|² dt` with
//! `w_j(t) = |b_j − a_j| / |p_j(t) − v|^(2α)`, which for linear `p(t)`, `q(t)` is the quadratic
//! form of the end points with the 2×2 weight matrix `[[δ00, δ01], [δ01, δ11]]`,
//! `δ00 = ∫ w (1−t)²`, `δ01 = ∫ w t(1−t)`, `δ11 = ∫ w t²` (closed forms for integer `α`, see
//! [`segment_weights`]). Writing the *target vectors* `t_k` (point targets, then the two
//! end points of each segment) with their sources `s_k` and block weights `W_kl`:
//!
//! * centroids `p* = Σ β_k s_k`, `q* = Σ β_k t_k`, `β_k = Σ_l W_kl / Σ_kl W_kl`;
//! * `z_k = Σ_l W_kl (s_l − p*)`, `S = Σ_k (s_k − p*) z_kᵀ`, `μ_s = tr S`, `u = v − p*`;
//! * **affine**: `f(v) = Σ_k (β_k + z_k·S⁻¹u) t_k` — one scalar `A_k` per target (§4.3.1);
//! * **similarity**: `f(v) = q* + (c u + s u⊥)/μ_s` with `c = Σ z_k·t_k`, `s = Σ z_k⊥·t_k`
//!   (`(x, y)⊥ = (−y, x)`) (§4.3.2);
//! * **rigid**: `f(v) = q* + (c u + s u⊥)/√(c² + s²)` (§4.3.3: the similarity rotation with
//!   `μ_r = √(c² + s²)` in place of `μ_s`).
//!
//! [`Mls2dPlan`] stores `β_k`, `z_k`, `u`, `μ_s` (or the affine `A_k`) per vertex, so
//! deforming after a handle move is a few multiply-adds per vertex and target.
//!
//! At a point handle `f(p_i) = q_i`; on a source segment `f(a + t(b − a)) = c + t(d − c)`
//! (the weights are infinite there; see [`SEGMENT_SNAP`] for points very close to one).

use glam::{DMat2, DVec2};
use rayon::prelude::*;

use volmorph_deform::DeformError;

/// Transformation class of the moving least squares fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mls2dKind {
    /// Any affine map (§4.3.1, §4.4.1).
    Affine,
    /// Rotation and uniform scale (§4.3.2, §4.4.2).
    Similarity,
    /// Rotation only (§4.3.3, §4.4.3).
    Rigid,
}

/// Largest segment weight exponent accepted (the closed forms are a recurrence in `α`).
pub const MAX_SEGMENT_ALPHA: u32 = 8;

/// Points closer to a source segment than this fraction of its length are mapped onto the
/// target segment directly. Closer than that, the segment's weight exceeds the other handles'
/// by a factor of 10¹² or more and the affine fit's moment matrix, accumulated in image
/// coordinates, loses the component across the segment to rounding; snapping instead changes
/// the map by `O(1e-4·|b − a|)` times its derivative, invisible in an image.
pub const SEGMENT_SNAP: f64 = 1e-4;

/// `S` whose determinant is at most this times `(tr S / 2)²` is singular for the affine fit
/// (the weighted handles are collinear); the linear part then falls back to the identity.
pub const DEGENERATE_MOMENT_2D: f64 = 1e-12;

/// Closed-form weight integrals of a segment for integer exponent `α ≥ 1`, with the
/// evaluation point at the origin: `[δ00, δ01, δ11]` for `w(t) = |b − a| / |a + t(b − a)|^(2α)`,
/// or `None` when the origin lies on the segment (the integrals diverge; the map interpolates
/// the segment there).
///
/// With `L = |b − a|`, `s = a·(b − a)/L²` and `h = |a × (b − a)|/L²`, `|p(t)|² =
/// L²((t + s)² + h²)`, so every integral is `L^(1−2α)` times a combination of
/// `I_m = ∫ u^m/(u² + h²)^α du` over `u ∈ [s, s + 1]` (`m = 0, 1, 2`), given by the standard
/// recurrences (arctangent and logarithm terms). When the origin lies on the segment's line
/// outside the segment (`h = 0`, the thesis' degenerate case) the integrands are plain powers
/// `u^(m−2α)`; this form is also used when `h` is so small relative to `|u|` that the
/// recurrences would cancel catastrophically (`h/|u| ≤ ε^(1/(2α))`, where the error of
/// dropping `h` is `O(ε^(1/α))`).
#[must_use]
pub fn segment_weights(a: DVec2, b: DVec2, alpha: u32) -> Option<[f64; 3]> {
    let e = b - a;
    let l2 = e.length_squared();
    let l = l2.sqrt();
    let s = a.dot(e) / l2;
    let h = a.perp_dot(e).abs() / l2;
    let (u0, u1) = (s, s + 1.0);
    let n = alpha.max(1) as i32;
    let spans_zero = u0 <= 0.0 && u1 >= 0.0;
    let umin = u0.abs().min(u1.abs());
    let degenerate_ratio = f64::EPSILON.powf(1.0 / (2.0 * f64::from(n)));
    let i = if spans_zero {
        if h == 0.0 {
            return None;
        }
        moments_regular(u0, u1, h, n)
    } else if h <= degenerate_ratio * umin {
        moments_on_line(u0, u1, n)
    } else {
        moments_regular(u0, u1, h, n)
    };
    let k = l.powi(1 - 2 * n);
    let w = k * i[0];
    let wt = k * (i[1] - s * i[0]);
    let wt2 = k * (i[2] - 2.0 * s * i[1] + s * s * i[0]);
    Some([w - 2.0 * wt + wt2, wt - wt2, wt2])
}

/// `I_m = ∫_{u0}^{u1} u^m / (u² + h²)^n du`, `m = 0, 1, 2`, `h > 0`.
fn moments_regular(u0: f64, u1: f64, h: f64, n: i32) -> [f64; 3] {
    let h2 = h * h;
    let f0 = u0 * u0 + h2;
    let f1 = u1 * u1 + h2;
    // J_1 by the stable arctangent difference.
    let mut j_prev = u1 - u0; // J_0
    let mut j = (h * (u1 - u0)).atan2(h2 + u0 * u1) / h; // J_1
    for k in 1..n {
        let kf = f64::from(k);
        let bracket = u1 / f1.powi(k) - u0 / f0.powi(k);
        let next = bracket / (2.0 * kf * h2) + (2.0 * kf - 1.0) / (2.0 * kf * h2) * j;
        j_prev = j;
        j = next;
    }
    let k1 = if n == 1 {
        0.5 * (f1 / f0).ln()
    } else {
        let m = f64::from(n - 1);
        (1.0 / f0.powi(n - 1) - 1.0 / f1.powi(n - 1)) / (2.0 * m)
    };
    let l = j_prev - h2 * j;
    [j, k1, l]
}

/// `I_m` for `h = 0`, `u0` and `u1` of one sign: `∫ u^(m−2n) du`.
fn moments_on_line(u0: f64, u1: f64, n: i32) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (m, o) in out.iter_mut().enumerate() {
        let p = m as i32 - 2 * n + 1;
        *o = if p == 0 {
            (u1 / u0).abs().ln()
        } else {
            (u1.powi(p) - u0.powi(p)) / f64::from(p)
        };
    }
    out
}

/// Source handles of a 2D MLS deformation: points and line segments, with the weight
/// exponent `α`. Targets are given separately (see the [module docs](self) for their order).
#[derive(Debug, Clone, PartialEq)]
pub struct Mls2dHandles {
    alpha: f64,
    points: Vec<DVec2>,
    segments: Vec<[DVec2; 2]>,
}

/// Which handle the evaluation point coincides with.
enum OnHandle {
    Point(usize),
    Segment(usize, f64),
}

impl Mls2dHandles {
    /// Source points and segments with weight exponent `α > 0` (`α` must be an integer in
    /// `1..=MAX_SEGMENT_ALPHA` when there are segments).
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for no handles, a bad `α`, coincident points, a
    /// zero-length segment, or fewer handles than the fit needs (one segment, or two points,
    /// are the minimum: three non-collinear points/segment ends for the affine fit are checked
    /// by [`plan`](Self::plan)'s fallback, not here); [`DeformError::NonFinite`] for NaN.
    pub fn new(points: &[DVec2], segments: &[[DVec2; 2]], alpha: f64) -> Result<Self, DeformError> {
        if !(alpha.is_finite() && alpha > 0.0) {
            return Err(DeformError::InvalidHandles(format!(
                "weight exponent α must be finite and > 0, got {alpha}"
            )));
        }
        if !segments.is_empty() && (alpha.fract() != 0.0 || alpha > f64::from(MAX_SEGMENT_ALPHA)) {
            return Err(DeformError::InvalidHandles(format!(
                "segment handles need an integer α in 1..={MAX_SEGMENT_ALPHA}, got {alpha}"
            )));
        }
        for (i, p) in points
            .iter()
            .chain(segments.iter().flat_map(|s| s.iter()))
            .enumerate()
        {
            if !p.is_finite() {
                return Err(DeformError::NonFinite {
                    what: format!("2D handle coordinate {i}"),
                    value: if p.x.is_finite() { p.y } else { p.x },
                });
            }
        }
        if points.len() + 2 * segments.len() < 2 {
            return Err(DeformError::InvalidHandles(
                "2D MLS needs at least two point handles or one segment".into(),
            ));
        }
        for (i, s) in segments.iter().enumerate() {
            if s[0] == s[1] {
                return Err(DeformError::InvalidHandles(format!(
                    "segment {i} has zero length"
                )));
            }
        }
        for i in 0..points.len() {
            for j in i + 1..points.len() {
                if points[i] == points[j] {
                    return Err(DeformError::InvalidHandles(format!(
                        "point handles {i} and {j} coincide"
                    )));
                }
            }
        }
        Ok(Self {
            alpha,
            points: points.to_vec(),
            segments: segments.to_vec(),
        })
    }

    /// Number of target vectors: one per point, two per segment.
    #[must_use]
    pub fn target_count(&self) -> usize {
        self.points.len() + 2 * self.segments.len()
    }

    /// The source of target vector `k`.
    fn source(&self, k: usize) -> DVec2 {
        let np = self.points.len();
        if k < np {
            self.points[k]
        } else {
            self.segments[(k - np) / 2][(k - np) % 2]
        }
    }

    /// The source targets: the identity configuration.
    #[must_use]
    pub fn identity_targets(&self) -> Vec<DVec2> {
        (0..self.target_count()).map(|k| self.source(k)).collect()
    }

    /// Per-vertex terms: `beta[k]`, `z[k]` (both `target_count()` long), returns `(u, S)`.
    fn terms(&self, v: DVec2, beta: &mut [f64], z: &mut [DVec2]) -> (DVec2, DMat2) {
        beta.fill(0.0);
        z.fill(DVec2::ZERO);
        let np = self.points.len();
        // Nearest handle distance, for scaling, and exact hits.
        let mut dmin2 = f64::INFINITY;
        let mut on: Option<OnHandle> = None;
        for (i, p) in self.points.iter().enumerate() {
            let d2 = (*p - v).length_squared();
            if d2 == 0.0 {
                on = Some(OnHandle::Point(i));
            }
            dmin2 = dmin2.min(d2);
        }
        for (j, s) in self.segments.iter().enumerate() {
            let e = s[1] - s[0];
            let t = ((v - s[0]).dot(e) / e.length_squared()).clamp(0.0, 1.0);
            let d2 = (s[0] + t * e - v).length_squared();
            if d2 <= SEGMENT_SNAP * SEGMENT_SNAP * e.length_squared() {
                on = Some(OnHandle::Segment(j, t));
            }
            dmin2 = dmin2.min(d2);
        }
        match on {
            Some(OnHandle::Point(i)) => {
                beta[i] = 1.0;
                return (DVec2::ZERO, DMat2::IDENTITY);
            }
            Some(OnHandle::Segment(j, t)) => {
                beta[np + 2 * j] = 1.0 - t;
                beta[np + 2 * j + 1] = t;
                return (DVec2::ZERO, DMat2::IDENTITY);
            }
            None => {}
        }
        let dmin = dmin2.sqrt();
        let inv = 1.0 / dmin;
        // Block weights, relative to a point handle at the nearest distance (weight 1).
        let mut total = 0.0;
        for (i, p) in self.points.iter().enumerate() {
            let r = dmin2 / (*p - v).length_squared();
            let w = if self.alpha == 1.0 {
                r
            } else {
                r.powf(self.alpha)
            };
            beta[i] = w;
            total += w;
        }
        let alpha = self.alpha as u32;
        for (j, s) in self.segments.iter().enumerate() {
            let a = (s[0] - v) * inv;
            let b = (s[1] - v) * inv;
            // Integrals in units of dmin: δ·dmin^(2α) = dmin·δ(scaled), the same factor
            // dmin^(2α) that made the point weights (dmin/d)^(2α).
            let k = np + 2 * j;
            if let Some([d00, d01, d11]) = segment_weights(a, b, alpha) {
                let (d00, d01, d11) = (d00 * dmin, d01 * dmin, d11 * dmin);
                beta[k] = d00 + d01;
                beta[k + 1] = d01 + d11;
                total += d00 + 2.0 * d01 + d11;
                // Stash the block in z; resolved below.
                z[k] = DVec2::new(d00, d01);
                z[k + 1] = DVec2::new(d01, d11);
            } else {
                // On the segment up to rounding: interpolate it.
                let e = s[1] - s[0];
                let t = ((v - s[0]).dot(e) / e.length_squared()).clamp(0.0, 1.0);
                beta.fill(0.0);
                z.fill(DVec2::ZERO);
                beta[k] = 1.0 - t;
                beta[k + 1] = t;
                return (DVec2::ZERO, DMat2::IDENTITY);
            }
        }
        // Centroid p*.
        let mut pc = DVec2::ZERO;
        for (k, b) in beta.iter_mut().enumerate() {
            *b /= total;
            pc += *b * self.source(k);
        }
        // z_k = Σ_l W_kl (s_l − p*), S = Σ_k x̂_k z_kᵀ.
        let mut s_mat = DMat2::ZERO;
        for i in 0..np {
            let x = self.points[i] - pc;
            let w = beta[i] * total;
            z[i] = w * x;
            s_mat += outer2(x, z[i]);
        }
        for j in 0..self.segments.len() {
            let k = np + 2 * j;
            let (d00, d01, d11) = (z[k].x, z[k].y, z[k + 1].y);
            let xa = self.segments[j][0] - pc;
            let xb = self.segments[j][1] - pc;
            z[k] = d00 * xa + d01 * xb;
            z[k + 1] = d01 * xa + d11 * xb;
            s_mat += outer2(xa, z[k]) + outer2(xb, z[k + 1]);
        }
        (v - pc, s_mat)
    }

    /// Precompute everything that depends on the sources for the given vertices (§4.3.1's
    /// `A_j`, §4.3.2's `A_i` and `μ_s`); parallel over vertices.
    ///
    /// # Errors
    /// [`DeformError::NonFinite`] for a NaN vertex, [`DeformError::Io`] if the table would
    /// exceed the allocation limit.
    pub fn plan(&self, vertices: &[DVec2], kind: Mls2dKind) -> Result<Mls2dPlan, DeformError> {
        if let Some(i) = vertices.iter().position(|v| !v.is_finite()) {
            return Err(DeformError::NonFinite {
                what: format!("vertex {i}"),
                value: f64::NAN,
            });
        }
        let k = self.target_count();
        let stride = match kind {
            Mls2dKind::Affine => k + 2,
            Mls2dKind::Similarity | Mls2dKind::Rigid => 3 * k + 3,
        };
        let len = volmorph_io::checked_len(&[vertices.len(), stride], 8)?;
        let mut table = vec![0.0; len];
        table
            .par_chunks_mut(stride)
            .zip(vertices.par_iter())
            .for_each_init(
                || (vec![0.0; k], vec![DVec2::ZERO; k]),
                |(beta, z), (row, &v)| {
                    let (u, s) = self.terms(v, beta, z);
                    match kind {
                        Mls2dKind::Affine => {
                            let tr = s.x_axis.x + s.y_axis.y;
                            let det = s.determinant();
                            let degenerate = tr.is_nan()
                                || tr <= 0.0
                                || det <= DEGENERATE_MOMENT_2D * 0.25 * tr * tr;
                            if degenerate {
                                row[..k].copy_from_slice(beta);
                                row[k] = u.x;
                                row[k + 1] = u.y;
                            } else {
                                let y = s.inverse() * u;
                                for i in 0..k {
                                    row[i] = beta[i] + z[i].dot(y);
                                }
                                row[k] = 0.0;
                                row[k + 1] = 0.0;
                            }
                        }
                        Mls2dKind::Similarity | Mls2dKind::Rigid => {
                            row[..k].copy_from_slice(beta);
                            for i in 0..k {
                                row[k + 2 * i] = z[i].x;
                                row[k + 2 * i + 1] = z[i].y;
                            }
                            let mu = s.x_axis.x + s.y_axis.y;
                            row[3 * k] = u.x;
                            row[3 * k + 1] = u.y;
                            row[3 * k + 2] = if mu > 0.0 { 1.0 / mu } else { 0.0 };
                        }
                    }
                },
            );
        Ok(Mls2dPlan {
            kind,
            targets: k,
            stride,
            vertices: vertices.len(),
            table,
        })
    }

    /// Deform one point directly (allocates two small buffers; use a [`Mls2dPlan`] for many
    /// points).
    ///
    /// # Errors
    /// As [`Mls2dPlan::deform`].
    pub fn deform_point(
        &self,
        kind: Mls2dKind,
        v: DVec2,
        targets: &[DVec2],
    ) -> Result<DVec2, DeformError> {
        let plan = self.plan(&[v], kind)?;
        let mut out = [DVec2::ZERO];
        plan.deform(targets, &mut out)?;
        Ok(out[0])
    }
}

#[inline]
fn outer2(a: DVec2, b: DVec2) -> DMat2 {
    DMat2::from_cols(a * b.x, a * b.y)
}

/// Source-dependent terms of a 2D MLS deformation at a fixed set of vertices; see the
/// [module docs](self). Deforming for new targets is `O(vertices × targets)` multiply-adds.
#[derive(Debug, Clone, PartialEq)]
pub struct Mls2dPlan {
    kind: Mls2dKind,
    targets: usize,
    stride: usize,
    vertices: usize,
    table: Vec<f64>,
}

impl Mls2dPlan {
    /// Number of vertices.
    #[must_use]
    pub fn len(&self) -> usize {
        self.vertices
    }

    /// `true` if there are no vertices.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.vertices == 0
    }

    /// The fit's transformation class.
    #[must_use]
    pub fn kind(&self) -> Mls2dKind {
        self.kind
    }

    /// Deformed positions of the vertices for `targets` (one per point handle, then the two
    /// end points of each segment): `out[i] = f(vertex_i)`.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for a wrong number of targets,
    /// [`DeformError::BufferLength`] if `out` is not one per vertex,
    /// [`DeformError::NonFinite`] for a NaN target.
    pub fn deform(&self, targets: &[DVec2], out: &mut [DVec2]) -> Result<(), DeformError> {
        let k = self.targets;
        if targets.len() != k {
            return Err(DeformError::InvalidHandles(format!(
                "{} targets for {k} target vectors",
                targets.len()
            )));
        }
        volmorph_deform::map::check_len(self.vertices, out.len())?;
        if let Some(i) = targets.iter().position(|t| !t.is_finite()) {
            return Err(DeformError::NonFinite {
                what: format!("2D target {i}"),
                value: f64::NAN,
            });
        }
        let kind = self.kind;
        let stride = self.stride;
        let body = |row: &[f64], o: &mut DVec2| match kind {
            Mls2dKind::Affine => {
                let mut f = DVec2::new(row[k], row[k + 1]);
                for (c, t) in row[..k].iter().zip(targets) {
                    f += *c * *t;
                }
                *o = f;
            }
            Mls2dKind::Similarity | Mls2dKind::Rigid => {
                let mut qc = DVec2::ZERO;
                let mut c = 0.0;
                let mut s = 0.0;
                let z = &row[k..3 * k];
                for ((b, t), zz) in row[..k].iter().zip(targets).zip(z.chunks_exact(2)) {
                    qc += *b * *t;
                    c += zz[0] * t.x + zz[1] * t.y;
                    s += -zz[1] * t.x + zz[0] * t.y;
                }
                let u = DVec2::new(row[3 * k], row[3 * k + 1]);
                let scale = if kind == Mls2dKind::Similarity {
                    row[3 * k + 2]
                } else {
                    let n = c.hypot(s);
                    if n > 0.0 { 1.0 / n } else { 0.0 }
                };
                *o = if scale == 0.0 {
                    qc + u
                } else {
                    qc + scale * (c * u + s * u.perp())
                };
            }
        };
        if self.vertices >= 8192 {
            out.par_chunks_mut(1024)
                .zip(self.table.par_chunks(1024 * stride))
                .for_each(|(o, rows)| {
                    for (o, row) in o.iter_mut().zip(rows.chunks_exact(stride)) {
                        body(row, o);
                    }
                });
        } else {
            for (o, row) in out.iter_mut().zip(self.table.chunks_exact(stride)) {
                body(row, o);
            }
        }
        Ok(())
    }
}

/// Vertices of a regular `nx × ny` grid spanning the pixel centres of a `width × height`
/// image (x fastest; vertex `(i, j)` at `(i·(w−1)/(nx−1), j·(h−1)/(ny−1))`).
///
/// # Errors
/// [`DeformError::InvalidHandles`] for `nx` or `ny` below 2 or an empty image.
pub fn image_grid(
    width: u32,
    height: u32,
    nx: usize,
    ny: usize,
) -> Result<Vec<DVec2>, DeformError> {
    if nx < 2 || ny < 2 || width == 0 || height == 0 {
        return Err(DeformError::InvalidHandles(format!(
            "image grid needs at least 2×2 vertices over a non-empty image, got {nx}×{ny} over \
             {width}×{height}"
        )));
    }
    volmorph_io::checked_len(&[nx, ny], 16)?;
    let sx = f64::from(width.saturating_sub(1)) / (nx - 1) as f64;
    let sy = f64::from(height.saturating_sub(1)) / (ny - 1) as f64;
    Ok((0..ny)
        .flat_map(|j| (0..nx).map(move |i| DVec2::new(i as f64 * sx, j as f64 * sy)))
        .collect())
}

/// Fraction of the quads of a deformed `nx × ny` grid that fold back (§4.6): a quad folds when
/// the Jacobian determinant of its bilinear map is `≤ 0` at one of its corners (the corner
/// triangle is flipped or degenerate). Returns 0 for grids without quads.
#[must_use]
pub fn fold_fraction(nx: usize, ny: usize, deformed: &[DVec2]) -> f64 {
    if nx < 2 || ny < 2 || deformed.len() != nx * ny {
        return 0.0;
    }
    let mut folded = 0usize;
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let p00 = deformed[i + nx * j];
            let p10 = deformed[i + 1 + nx * j];
            let p01 = deformed[i + nx * (j + 1)];
            let p11 = deformed[i + 1 + nx * (j + 1)];
            // det[∂/∂s, ∂/∂t] of the bilinear map at the four corners.
            let dets = [
                (p10 - p00).perp_dot(p01 - p00),
                (p10 - p00).perp_dot(p11 - p10),
                (p11 - p01).perp_dot(p01 - p00),
                (p11 - p01).perp_dot(p11 - p10),
            ];
            if dets.iter().any(|d| d.is_nan() || *d <= 0.0) {
                folded += 1;
            }
        }
    }
    folded as f64 / ((nx - 1) * (ny - 1)) as f64
}

/// Warp an RGBA image through a deformed grid (§4.5): the source grid is
/// [`image_grid`]`(width, height, nx, ny)`, `deformed` are its vertices' images; every
/// deformed quad is filled by inverting its bilinear map at each output pixel centre inside it
/// and sampling the source bilinearly at the corresponding source point. Output pixels no quad
/// covers get `background`. Where quads overlap (fold-back) the later quad in row order wins.
/// Output size equals input size.
///
/// # Errors
/// [`DeformError::BufferLength`] if `pixels` is not `width × height` or `deformed` is not
/// `nx × ny`; [`DeformError::InvalidHandles`] for a grid below 2×2.
#[allow(clippy::too_many_arguments)]
pub fn warp_rgba(
    width: u32,
    height: u32,
    pixels: &[[u8; 4]],
    nx: usize,
    ny: usize,
    deformed: &[DVec2],
    background: [u8; 4],
) -> Result<Vec<[u8; 4]>, DeformError> {
    warp_rgba_with(
        width,
        height,
        pixels,
        nx,
        ny,
        deformed,
        background,
        &volmorph_io::NoProgress,
    )
}

/// [`warp_rgba`] reporting to `progress`: one stage whose steps are the grid's rows of quads
/// (`ny − 1`), stopping between rows when cancelled. The result equals [`warp_rgba`]'s bit
/// for bit.
///
/// # Errors
/// As [`warp_rgba`]; [`DeformError::Cancelled`] when `progress` asks to stop.
#[allow(clippy::too_many_arguments)]
pub fn warp_rgba_with(
    width: u32,
    height: u32,
    pixels: &[[u8; 4]],
    nx: usize,
    ny: usize,
    deformed: &[DVec2],
    background: [u8; 4],
    progress: &dyn volmorph_io::Progress,
) -> Result<Vec<[u8; 4]>, DeformError> {
    let (w, h) = (width as usize, height as usize);
    volmorph_deform::map::check_len(w * h, pixels.len())?;
    let src = image_grid(width, height, nx, ny)?;
    volmorph_deform::map::check_len(nx * ny, deformed.len())?;
    let mut out = volmorph_io::try_vec("the deformed picture", w * h, background)?;
    let sample = |p: DVec2| -> [u8; 4] {
        let x = p.x.clamp(0.0, (w - 1) as f64);
        let y = p.y.clamp(0.0, (h - 1) as f64);
        let x0 = (x.floor() as usize).min(w.saturating_sub(2));
        let y0 = (y.floor() as usize).min(h.saturating_sub(2));
        let x1 = (x0 + 1).min(w - 1);
        let y1 = (y0 + 1).min(h - 1);
        let fx = x - x0 as f64;
        let fy = y - y0 as f64;
        let mut o = [0u8; 4];
        for (c, oc) in o.iter_mut().enumerate() {
            let v00 = f64::from(pixels[x0 + w * y0][c]);
            let v10 = f64::from(pixels[x1 + w * y0][c]);
            let v01 = f64::from(pixels[x0 + w * y1][c]);
            let v11 = f64::from(pixels[x1 + w * y1][c]);
            let v = (v00 * (1.0 - fx) + v10 * fx) * (1.0 - fy) + (v01 * (1.0 - fx) + v11 * fx) * fy;
            *oc = v.round().clamp(0.0, 255.0) as u8;
        }
        o
    };
    progress.start(
        &format!("deforming a {width}×{height} picture"),
        (ny - 1) as u64,
    );
    for j in 0..ny - 1 {
        progress.check()?;
        for i in 0..nx - 1 {
            let q = [
                deformed[i + nx * j],
                deformed[i + 1 + nx * j],
                deformed[i + nx * (j + 1)],
                deformed[i + 1 + nx * (j + 1)],
            ];
            if q.iter().any(|p| !p.is_finite()) {
                continue;
            }
            let s00 = src[i + nx * j];
            let s11 = src[i + 1 + nx * (j + 1)];
            let lo = q.iter().fold(DVec2::INFINITY, |a, b| a.min(*b));
            let hi = q.iter().fold(DVec2::NEG_INFINITY, |a, b| a.max(*b));
            let x0 = lo.x.ceil().max(0.0);
            let y0 = lo.y.ceil().max(0.0);
            let x1 = hi.x.floor().min((w - 1) as f64);
            let y1 = hi.y.floor().min((h - 1) as f64);
            if x0 > x1 || y0 > y1 {
                continue;
            }
            for py in y0 as usize..=y1 as usize {
                for px in x0 as usize..=x1 as usize {
                    let target = DVec2::new(px as f64, py as f64);
                    if let Some(st) = inverse_bilinear(&q, target) {
                        let sp = s00 + st * (s11 - s00);
                        out[px + w * py] = sample(sp);
                    }
                }
            }
        }
        progress.advance(1);
    }
    progress.check()?;
    Ok(out)
}

/// Parameters `(s, t) ∈ [0, 1]²` with `bilinear(q, s, t) = x`, by Newton's method from the
/// centre; `None` if `x` is outside the quad or the iteration fails (degenerate quad).
fn inverse_bilinear(q: &[DVec2; 4], x: DVec2) -> Option<DVec2> {
    /// Parameter tolerance for accepting a point on the quad's edge (shared edges of
    /// neighbouring quads must both accept their common pixels).
    const EDGE: f64 = 1e-9;
    let mut st = DVec2::splat(0.5);
    for _ in 0..12 {
        let (s, t) = (st.x, st.y);
        let p = (q[0] * (1.0 - s) + q[1] * s) * (1.0 - t) + (q[2] * (1.0 - s) + q[3] * s) * t;
        let r = p - x;
        if r.length_squared() < 1e-24 {
            break;
        }
        let ds = (q[1] - q[0]) * (1.0 - t) + (q[3] - q[2]) * t;
        let dt = (q[2] - q[0]) * (1.0 - s) + (q[3] - q[1]) * s;
        let m = DMat2::from_cols(ds, dt);
        let det = m.determinant();
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        st -= m.inverse() * r;
    }
    let (s, t) = (st.x, st.y);
    let p = (q[0] * (1.0 - s) + q[1] * s) * (1.0 - t) + (q[2] * (1.0 - s) + q[3] * s) * t;
    let ok = (p - x).length() < 1e-6
        && (-EDGE..=1.0 + EDGE).contains(&s)
        && (-EDGE..=1.0 + EDGE).contains(&t);
    ok.then(|| st.clamp(DVec2::ZERO, DVec2::ONE))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Composite Gauss–Legendre (5 points) on `n` panels of `[0, 1]`.
    fn quad(f: impl Fn(f64) -> f64, n: usize) -> f64 {
        let x = [
            0.0,
            -0.538_469_310_105_683,
            0.538_469_310_105_683,
            -0.906_179_845_938_664,
            0.906_179_845_938_664,
        ];
        let w = [
            0.568_888_888_888_889,
            0.478_628_670_499_366,
            0.478_628_670_499_366,
            0.236_926_885_056_189,
            0.236_926_885_056_189,
        ];
        let h = 1.0 / n as f64;
        let mut s = 0.0;
        for i in 0..n {
            let c = (i as f64 + 0.5) * h;
            for k in 0..5 {
                s += w[k] * 0.5 * h * f(c + 0.5 * h * x[k]);
            }
        }
        s
    }

    #[test]
    fn segment_weights_match_quadrature_including_degenerate_cases() {
        let cases = [
            (DVec2::new(1.0, 2.0), DVec2::new(4.0, -1.0)), // generic
            (DVec2::new(-3.0, 0.5), DVec2::new(2.0, 0.5)), // projection inside, h = 0.5
            (DVec2::new(2.0, 0.0), DVec2::new(5.0, 0.0)),  // on the extension (h = 0)
            (DVec2::new(-6.0, 0.0), DVec2::new(-1.5, 0.0)), // extension, other side
            (DVec2::new(2.0, 1e-9), DVec2::new(5.0, 1e-9)), // almost on the extension
            (DVec2::new(0.5, 0.3), DVec2::new(0.6, -0.2)), // short and close
        ];
        for alpha in 1..=3u32 {
            for (a, b) in cases {
                let got = segment_weights(a, b, alpha).unwrap();
                let l = (b - a).length();
                let wf = |t: f64| l / (a + t * (b - a)).length_squared().powi(alpha as i32);
                let e = [
                    quad(|t| wf(t) * (1.0 - t) * (1.0 - t), 4000),
                    quad(|t| wf(t) * t * (1.0 - t), 4000),
                    quad(|t| wf(t) * t * t, 4000),
                ];
                for k in 0..3 {
                    let rel = (got[k] - e[k]).abs() / e[k].abs().max(1e-300);
                    assert!(
                        rel < 1e-7,
                        "α={alpha} {a} {b} k={k}: {} vs {}",
                        got[k],
                        e[k]
                    );
                }
            }
        }
        assert!(segment_weights(DVec2::new(-1.0, 0.0), DVec2::new(1.0, 0.0), 2).is_none());
    }

    fn star_points() -> Vec<DVec2> {
        (0..11)
            .map(|i| {
                let a = f64::from(i) * 0.57;
                DVec2::new(
                    50.0 + 30.0 * a.cos() * (1.0 + 0.1 * f64::from(i)),
                    50.0 + 35.0 * a.sin(),
                )
            })
            .collect()
    }

    fn sim(m: DMat2, t: DVec2) -> impl Fn(DVec2) -> DVec2 {
        move |p| m * p + t
    }

    #[test]
    fn point_handles_interpolate_identity_and_reproduce_their_class() {
        let p = star_points();
        let h = Mls2dHandles::new(&p, &[], 1.0).unwrap();
        let verts = image_grid(100, 100, 25, 25).unwrap();
        let rot = DMat2::from_angle(0.7);
        let maps: [(Mls2dKind, DMat2); 3] = [
            (
                Mls2dKind::Affine,
                DMat2::from_cols(DVec2::new(1.2, 0.3), DVec2::new(-0.4, 0.9)),
            ),
            (Mls2dKind::Similarity, 1.6 * rot),
            (Mls2dKind::Rigid, rot),
        ];
        let mut out = vec![DVec2::ZERO; verts.len()];
        for (kind, m) in maps {
            let plan = h.plan(&verts, kind).unwrap();
            // Identity.
            plan.deform(&p, &mut out).unwrap();
            for (v, o) in verts.iter().zip(&out) {
                assert!((*v - *o).length() < 1e-9, "{kind:?}");
            }
            // Its own class is reproduced exactly, and the larger classes reproduce it too.
            let f = sim(m, DVec2::new(3.0, -2.0));
            let q: Vec<DVec2> = p.iter().map(|x| f(*x)).collect();
            for k2 in [Mls2dKind::Affine, Mls2dKind::Similarity, Mls2dKind::Rigid] {
                let contains = match kind {
                    Mls2dKind::Affine => k2 == Mls2dKind::Affine,
                    Mls2dKind::Similarity => k2 != Mls2dKind::Rigid,
                    Mls2dKind::Rigid => true,
                };
                if !contains {
                    continue;
                }
                let plan2 = h.plan(&verts, k2).unwrap();
                plan2.deform(&q, &mut out).unwrap();
                for (v, o) in verts.iter().zip(&out) {
                    assert!((f(*v) - *o).length() < 1e-8, "{kind:?} by {k2:?}");
                }
            }
            // Interpolation of arbitrary targets.
            let q: Vec<DVec2> = p
                .iter()
                .enumerate()
                .map(|(i, x)| *x + DVec2::new(f64::from(i as u8).sin() * 9.0, 4.0))
                .collect();
            for (pi, qi) in p.iter().zip(&q) {
                let got = h.deform_point(kind, *pi, &q).unwrap();
                assert!((got - *qi).length() < 1e-12);
                let near = h.deform_point(kind, *pi + DVec2::splat(1e-6), &q).unwrap();
                assert!((near - *qi).length() < 1e-3);
            }
        }
    }

    #[test]
    fn theorem_4_1_rigid_is_normalised_similarity() {
        let p = star_points();
        let h = Mls2dHandles::new(&p, &[], 1.5).unwrap();
        let q: Vec<DVec2> = p
            .iter()
            .enumerate()
            .map(|(i, x)| *x + DVec2::new(f64::from(i as u8).cos() * 7.0, -3.0))
            .collect();
        let verts = vec![
            DVec2::new(10.0, 20.0),
            DVec2::new(55.0, 48.0),
            DVec2::new(90.0, 5.0),
        ];
        let mut fs = vec![DVec2::ZERO; 3];
        let mut fr = vec![DVec2::ZERO; 3];
        h.plan(&verts, Mls2dKind::Similarity)
            .unwrap()
            .deform(&q, &mut fs)
            .unwrap();
        h.plan(&verts, Mls2dKind::Rigid)
            .unwrap()
            .deform(&q, &mut fr)
            .unwrap();
        // Both share q* and the direction; rigid keeps |v − p*|.
        let mut beta = vec![0.0; p.len()];
        let mut z = vec![DVec2::ZERO; p.len()];
        for (i, v) in verts.iter().enumerate() {
            let (u, _) = h.terms(*v, &mut beta, &mut z);
            let qc: DVec2 = beta.iter().zip(&q).map(|(b, t)| *b * *t).sum();
            let ds = fs[i] - qc;
            let dr = fr[i] - qc;
            assert!((dr.length() - u.length()).abs() < 1e-9);
            assert!(ds.normalize().dot(dr.normalize()) > 1.0 - 1e-12);
        }
    }

    #[test]
    fn segments_interpolate_and_reproduce_rigid_motion() {
        let segs = [
            [DVec2::new(10.0, 10.0), DVec2::new(40.0, 12.0)],
            [DVec2::new(60.0, 20.0), DVec2::new(70.0, 80.0)],
            [DVec2::new(20.0, 70.0), DVec2::new(45.0, 50.0)],
        ];
        let h = Mls2dHandles::new(&[], &segs, 2.0).unwrap();
        let rot = DMat2::from_angle(-0.4);
        let f = sim(rot, DVec2::new(5.0, 1.0));
        let q: Vec<DVec2> = segs.iter().flat_map(|s| [f(s[0]), f(s[1])]).collect();
        let verts = image_grid(100, 100, 17, 13).unwrap();
        let mut out = vec![DVec2::ZERO; verts.len()];
        for kind in [Mls2dKind::Affine, Mls2dKind::Similarity, Mls2dKind::Rigid] {
            h.plan(&verts, kind).unwrap().deform(&q, &mut out).unwrap();
            for (v, o) in verts.iter().zip(&out) {
                assert!((f(*v) - *o).length() < 1e-7, "{kind:?} {v}");
            }
            // Points of a segment go to the corresponding points of its target.
            let mid = segs[1][0].lerp(segs[1][1], 0.3);
            let t = h.deform_point(kind, mid, &q).unwrap();
            assert!((t - f(mid)).length() < 1e-9);
            // Arbitrary targets: segment points land on the target segment.
            let mut q2 = q.clone();
            q2[3] += DVec2::new(10.0, -5.0);
            let t = h.deform_point(kind, mid, &q2).unwrap();
            assert!((t - q2[2].lerp(q2[3], 0.3)).length() < 1e-9, "{kind:?}");
            // Near the segment the map converges to it.
            let near = h
                .deform_point(kind, mid + DVec2::new(1e-5, 0.0), &q2)
                .unwrap();
            assert!((near - q2[2].lerp(q2[3], 0.3)).length() < 1e-2, "{kind:?}");
        }
        // On a segment's extension the degenerate integrals are used: finite, smooth.
        let ext = segs[0][0] + 1.5 * (segs[0][1] - segs[0][0]);
        let a = h.deform_point(Mls2dKind::Rigid, ext, &q).unwrap();
        assert!((a - f(ext)).length() < 1e-7);
    }

    #[test]
    fn image_warp_identity_translation_and_folds() {
        let (w, hgt) = (40u32, 30u32);
        let pixels: Vec<[u8; 4]> = (0..w * hgt)
            .map(|i| [(i % w * 6) as u8, (i / w * 8) as u8, 100, 255])
            .collect();
        let grid = image_grid(w, hgt, 9, 7).unwrap();
        let id = warp_rgba(w, hgt, &pixels, 9, 7, &grid, [0; 4]).unwrap();
        assert_eq!(id, pixels);
        // Whole-pixel translation by (3, 2).
        let moved: Vec<DVec2> = grid.iter().map(|p| *p + DVec2::new(3.0, 2.0)).collect();
        let t = warp_rgba(w, hgt, &pixels, 9, 7, &moved, [0; 4]).unwrap();
        assert_eq!(t[5 + 40 * 6], pixels[2 + 40 * 4]);
        assert_eq!(t[1 + 40], [0; 4]);
        assert_eq!(fold_fraction(9, 7, &moved), 0.0);
        // A mirrored grid folds everywhere.
        let mirrored: Vec<DVec2> = grid.iter().map(|p| DVec2::new(-p.x, p.y)).collect();
        assert_eq!(fold_fraction(9, 7, &mirrored), 1.0);
        assert!(warp_rgba(w, hgt, &pixels[1..], 9, 7, &grid, [0; 4]).is_err());
        assert!(warp_rgba(w, hgt, &pixels, 9, 7, &grid[1..], [0; 4]).is_err());
    }

    #[test]
    fn bad_input_is_an_error() {
        let p = star_points();
        assert!(Mls2dHandles::new(&p[..1], &[], 1.0).is_err());
        assert!(Mls2dHandles::new(&[p[0], p[0], p[1]], &[], 1.0).is_err());
        assert!(Mls2dHandles::new(&p, &[], 0.0).is_err());
        assert!(Mls2dHandles::new(&p, &[[p[0], p[1]]], 1.5).is_err());
        assert!(Mls2dHandles::new(&p, &[[p[0], p[0]]], 1.0).is_err());
        assert!(Mls2dHandles::new(&[DVec2::NAN, p[0]], &[], 1.0).is_err());
        let h = Mls2dHandles::new(&p, &[], 1.0).unwrap();
        let plan = h.plan(&[DVec2::ONE], Mls2dKind::Rigid).unwrap();
        let mut out = [DVec2::ZERO];
        assert!(plan.deform(&p[..3], &mut out).is_err());
        assert!(plan.deform(&p, &mut []).is_err());
        let mut bad = p.clone();
        bad[0].x = f64::INFINITY;
        assert!(plan.deform(&bad, &mut out).is_err());
        assert!(h.plan(&[DVec2::NAN], Mls2dKind::Affine).is_err());
        assert!(image_grid(10, 10, 1, 5).is_err());
        // Two points only: the affine fit is degenerate everywhere; still finite.
        let two = Mls2dHandles::new(&p[..2], &[], 1.0).unwrap();
        let f = two
            .deform_point(Mls2dKind::Affine, DVec2::new(3.0, 4.0), &p[..2])
            .unwrap();
        assert!(f.is_finite());
    }
}

#[cfg(test)]
mod tps_tests {
    use glam::DVec3;

    use super::*;

    /// The thin-plate picture warp interpolates its handles: every source pixel lands on its
    /// target, and a picture of one bright pixel at a source shows it at the target.
    #[test]
    fn thin_plate_picture_warp_interpolates_its_handles() {
        let pairs = [
            ([4.0, 4.0], [6.0, 5.0]),
            ([27.0, 3.0], [25.0, 4.0]),
            ([15.0, 16.0], [18.0, 13.0]),
            ([3.0, 28.0], [4.0, 27.0]),
            ([28.0, 27.0], [28.0, 27.0]),
        ];
        let set = crate::HandleSet {
            dim: 2,
            points: pairs
                .iter()
                .map(|(a, b)| (DVec3::new(a[0], a[1], 0.0), DVec3::new(b[0], b[1], 0.0)))
                .collect(),
            segments: Vec::new(),
            frames: Vec::new(),
        };
        let spline = tps_2d(&set).unwrap();
        for (a, b) in pairs {
            let mut u = [0.0; 2];
            spline.eval(a, &mut u);
            assert!((a[0] + u[0] - b[0]).abs() < 1e-9 && (a[1] + u[1] - b[1]).abs() < 1e-9);
        }
        // The centre handle's pixel moves to its target in the picture (full-resolution grid).
        let (w, h) = (32u32, 32u32);
        let mut px = vec![[0u8, 0, 0, 255]; (w * h) as usize];
        px[16 * 32 + 15] = [255, 255, 255, 255];
        let out = warp_picture_tps(w, h, &px, &set, 64).unwrap();
        let brightest = (0..px.len()).max_by_key(|&n| out.pixels[n][0]).unwrap();
        let (x, y) = (brightest % 32, brightest / 32);
        assert!(
            x.abs_diff(18) <= 1 && y.abs_diff(13) <= 1,
            "brightest at ({x}, {y})"
        );
        assert!(out.pixels[brightest][0] > 64);
        let mut few = set.clone();
        few.points.truncate(2);
        assert!(warp_picture_tps(w, h, &px, &few, 64).is_err());
    }
}

/// A picture deformed by [`warp_picture`].
#[derive(Debug, Clone, PartialEq)]
pub struct PictureWarp {
    /// The deformed pixels, same size as the input, row-major from the top; pixels no quad
    /// covers are transparent.
    pub pixels: Vec<[u8; 4]>,
    /// Vertices per axis of the deformed grid.
    pub grid: (usize, usize),
    /// Fraction of the grid's quads that fold back (Jacobian ≤ 0).
    pub fold_fraction: f64,
}

/// Deform a `width × height` RGBA picture by 2D moving least squares through the point and
/// segment handles of `set` (pixel coordinates, x right, y down; sources go to targets): the
/// map of `kind` is evaluated on a grid of at most `grid × grid` vertices (no more than the
/// picture has pixels) and its quads are filled bilinearly (Schaefer et al.'s image warping).
///
/// # Errors
/// [`DeformError::InvalidHandles`] for 3D handles, `grid < 2`, or handles the method cannot
/// use; [`DeformError::BufferLength`] if `pixels` is not `width × height`.
pub fn warp_picture(
    width: u32,
    height: u32,
    pixels: &[[u8; 4]],
    set: &crate::HandleSet,
    kind: Mls2dKind,
    alpha: f64,
    grid: usize,
) -> Result<PictureWarp, DeformError> {
    warp_picture_with(
        width,
        height,
        pixels,
        set,
        kind,
        alpha,
        grid,
        &volmorph_io::NoProgress,
    )
}

/// [`warp_picture`] reporting to `progress` as [`warp_rgba_with`] does (the grid's map is
/// evaluated first, without steps). The result equals [`warp_picture`]'s bit for bit.
///
/// # Errors
/// As [`warp_picture`]; [`DeformError::Cancelled`] when `progress` asks to stop.
#[allow(clippy::too_many_arguments)]
pub fn warp_picture_with(
    width: u32,
    height: u32,
    pixels: &[[u8; 4]],
    set: &crate::HandleSet,
    kind: Mls2dKind,
    alpha: f64,
    grid: usize,
    progress: &dyn volmorph_io::Progress,
) -> Result<PictureWarp, DeformError> {
    if set.dim != 2 {
        return Err(DeformError::InvalidHandles(
            "picture deformation needs 2D handles (pixel coordinates [x, y]); the set has 3D \
             coordinates"
                .into(),
        ));
    }
    let v2 = |p: glam::DVec3| DVec2::new(p.x, p.y);
    let points: Vec<DVec2> = set.points.iter().map(|p| v2(p.0)).collect();
    let segments: Vec<[DVec2; 2]> = set
        .segments
        .iter()
        .map(|s| [v2(s.0[0]), v2(s.0[1])])
        .collect();
    let mut targets: Vec<DVec2> = set.points.iter().map(|p| v2(p.1)).collect();
    targets.extend(set.segments.iter().flat_map(|s| [v2(s.1[0]), v2(s.1[1])]));
    let handles = Mls2dHandles::new(&points, &segments, alpha)?;
    fill_picture(width, height, pixels, grid, progress, |verts, deformed| {
        let plan = handles.plan(verts, kind)?;
        plan.deform(&targets, deformed)
    })
}

/// Deform a `width × height` RGBA picture by the 2D **thin-plate spline** through the point
/// handles of `set` (segment handles contribute their two end points): Bookstein's warp with
/// Duchon's kernel `r² log r` plus an affine part (McPhail Fig. 4.2's comparison with moving
/// least squares; [`crate::volume_spline`] with `D = 2`), interpolating every handle exactly.
/// Evaluated and filled like [`warp_picture`].
///
/// # Errors
/// As [`warp_picture`]; [`DeformError::InvalidHandles`] for fewer than 3 handles or handles
/// all on one line (the affine part is then undetermined), and coincident sources.
pub fn warp_picture_tps(
    width: u32,
    height: u32,
    pixels: &[[u8; 4]],
    set: &crate::HandleSet,
    grid: usize,
) -> Result<PictureWarp, DeformError> {
    warp_picture_tps_with(width, height, pixels, set, grid, &volmorph_io::NoProgress)
}

/// [`warp_picture_tps`] reporting to `progress` as [`warp_rgba_with`] does. The result
/// equals [`warp_picture_tps`]'s bit for bit.
///
/// # Errors
/// As [`warp_picture_tps`]; [`DeformError::Cancelled`] when `progress` asks to stop.
pub fn warp_picture_tps_with(
    width: u32,
    height: u32,
    pixels: &[[u8; 4]],
    set: &crate::HandleSet,
    grid: usize,
    progress: &dyn volmorph_io::Progress,
) -> Result<PictureWarp, DeformError> {
    if set.dim != 2 {
        return Err(DeformError::InvalidHandles(
            "picture deformation needs 2D handles (pixel coordinates [x, y]); the set has 3D \
             coordinates"
                .into(),
        ));
    }
    let spline = tps_2d(set)?;
    fill_picture(width, height, pixels, grid, progress, |verts, deformed| {
        for (v, d) in verts.iter().zip(deformed.iter_mut()) {
            let mut u = [0.0; 2];
            spline.eval([v.x, v.y], &mut u);
            *d = *v + DVec2::new(u[0], u[1]);
        }
        Ok(())
    })
}

/// The 2D thin-plate spline of the displacements `target − source` of `set`'s point handles
/// and segment end points.
fn tps_2d(set: &crate::HandleSet) -> Result<crate::volume_spline::VolumeSpline<2>, DeformError> {
    let mut pairs: Vec<([f64; 2], [f64; 2])> = set
        .points
        .iter()
        .map(|p| ([p.0.x, p.0.y], [p.1.x - p.0.x, p.1.y - p.0.y]))
        .collect();
    for s in &set.segments {
        for e in 0..2 {
            let (a, b) = (s.0[e], s.1[e]);
            pairs.push(([a.x, a.y], [b.x - a.x, b.y - a.y]));
        }
    }
    if pairs.len() < 3 {
        return Err(DeformError::InvalidHandles(format!(
            "a thin-plate spline needs at least 3 handles, got {}",
            pairs.len()
        )));
    }
    let centres: Vec<[f64; 2]> = pairs.iter().map(|p| p.0).collect();
    let values: Vec<f64> = pairs.iter().flat_map(|p| p.1).collect();
    crate::volume_spline::VolumeSplineSystem::<2>::new(&centres, 0.0)?.solve(&values, 2)
}

/// Evaluate `deform(vertices, out)` on a grid of at most `grid × grid` vertices over the
/// picture and fill its quads bilinearly.
fn fill_picture(
    width: u32,
    height: u32,
    pixels: &[[u8; 4]],
    grid: usize,
    progress: &dyn volmorph_io::Progress,
    deform: impl FnOnce(&[DVec2], &mut [DVec2]) -> Result<(), DeformError>,
) -> Result<PictureWarp, DeformError> {
    if grid < 2 {
        return Err(DeformError::InvalidHandles(format!(
            "the deformed grid needs at least 2 vertices per axis, got {grid}"
        )));
    }
    let (nx, ny) = (
        grid.min(width.max(2) as usize),
        grid.min(height.max(2) as usize),
    );
    let verts = image_grid(width, height, nx, ny)?;
    let mut deformed = vec![DVec2::ZERO; verts.len()];
    deform(&verts, &mut deformed)?;
    let fold_fraction = fold_fraction(nx, ny, &deformed);
    progress.check()?;
    let pixels = warp_rgba_with(width, height, pixels, nx, ny, &deformed, [0; 4], progress)?;
    Ok(PictureWarp {
        pixels,
        grid: (nx, ny),
        fold_fraction,
    })
}
