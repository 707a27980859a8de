//! Reconstruction of solids with volume splines (Savchenko & Pasko §4.1.1, Fig. 4 and the
//! Appendix): defining functions that pass through scattered surface points, and solids
//! reconstructed from a stack of planar cross-sections by metamorphosis along `z`.
//!
//! * [`SplineCorrected`] — the algebraic sum `f(x) = f₀(x) + d(x)` of an initial defining
//!   function and the 3D volume spline `d` through prescribed values: with
//!   [`SplineCorrected::through_surface_points`], `d(pᵢ) = −f₀(pᵢ)`, so every point lands on
//!   the zero set (Savchenko et al. 1995b).
//! * [`SectionFunction`] — the same construction in the plane for one cross-section: an
//!   ellipse fitted to each contour loop as `f₀`, plus the 2D thin-plate spline through
//!   `−f₀` at the contour points.
//! * [`SectionStack`] — the solid of a stack of sections: metamorphosis between neighbouring
//!   section functions with `z` as the parameter (Eq. 13, or a cubic Hermite blend across four
//!   sections), intersected with the slab `[z₀, zₙ]`, read from the JSON format documented on
//!   [`SectionStack::from_json`]. [`femur_sections`] is a built-in femur-like example.
//!
//! All follow the HyperFun convention: `f ≥ 0` inside, `f = 0` on the surface. Coordinates are
//! physical units; the functions are "distance-like" (gradient magnitude about 1 near the
//! surface of the initial function), so a slab distance can be intersected with them.

use glam::{DVec2, DVec3};
use volmorph_handles::volume_spline::{VolumeSpline, VolumeSplineSystem};

use crate::error::FrepError;
use crate::field::Field;

/// `f(x) = f₀(x) + d(x)`: an initial defining function `f₀` corrected by the 3D volume spline
/// `d` of the seed's Appendix (`G(r) = r` plus a linear polynomial). Interpolating
/// `d(pᵢ) = vᵢ − f₀(pᵢ)` makes `f(pᵢ) = vᵢ` exactly (to rounding); far from the points `d`
/// tends to its linear part, so the sign of `f` there is that of `f₀` when `f₀` decreases
/// faster than linearly (a sphere or ellipsoid function does).
///
/// Gradients follow the sum rule `∇f₀ + ∇d` (analytic for the spline). No interval bound is
/// known, so the grid sampler evaluates it pointwise.
#[derive(Debug, Clone)]
pub struct SplineCorrected<F> {
    /// The initial defining function `f₀`.
    pub initial: F,
    spline: VolumeSpline<3>,
}

impl<F: Field> SplineCorrected<F> {
    /// The sum through values: `f(points[i]) = values[i]`, smoothing `smoothing ≥ 0` (0
    /// interpolates).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] when the lists differ in length, a value is not finite
    /// or `f₀` is not finite at a point; [`FrepError::Deform`] from [`VolumeSplineSystem::new`]
    /// for fewer than 4 points, coincident or coplanar points, or a singular system.
    pub fn through_values(
        initial: F,
        points: &[DVec3],
        values: &[f64],
        smoothing: f64,
    ) -> Result<Self, FrepError> {
        if points.len() != values.len() {
            return Err(FrepError::InvalidArgument(format!(
                "{} values for {} points",
                values.len(),
                points.len()
            )));
        }
        let mut rhs = Vec::with_capacity(points.len());
        for (i, (&p, &v)) in points.iter().zip(values).enumerate() {
            let f0 = initial.value(p);
            if !(v.is_finite() && f0.is_finite()) {
                return Err(FrepError::InvalidArgument(format!(
                    "point {i} at {p}: the value {v} or the initial function's value {f0} is not finite"
                )));
            }
            rhs.push(v - f0);
        }
        let c: Vec<[f64; 3]> = points.iter().map(|p| p.to_array()).collect();
        let system = VolumeSplineSystem::<3>::new(&c, smoothing)?;
        Ok(Self {
            initial,
            spline: system.solve(&rhs, 1)?,
        })
    }

    /// Reconstruction from scattered surface points: [`through_values`](Self::through_values)
    /// with all values 0, so every point lies on the zero set of the result.
    ///
    /// # Errors
    /// As [`through_values`](Self::through_values).
    pub fn through_surface_points(
        initial: F,
        points: &[DVec3],
        smoothing: f64,
    ) -> Result<Self, FrepError> {
        let zeros = vec![0.0; points.len()];
        Self::through_values(initial, points, &zeros, smoothing)
    }

    /// The correction spline `d` (one value component).
    #[must_use]
    pub fn spline(&self) -> &VolumeSpline<3> {
        &self.spline
    }

    /// The correction `d(x)`.
    #[must_use]
    pub fn correction(&self, p: DVec3) -> f64 {
        let mut d = [0.0];
        self.spline.eval(p.to_array(), &mut d);
        d[0]
    }
}

impl<F: Field> Field for SplineCorrected<F> {
    fn value(&self, p: DVec3) -> f64 {
        self.initial.value(p) + self.correction(p)
    }

    fn gradient(&self, p: DVec3) -> (f64, DVec3) {
        let (v, g) = self.initial.gradient(p);
        let mut d = [0.0];
        let mut dg = [[0.0; 3]];
        self.spline
            .eval_with_gradient(p.to_array(), &mut d, &mut dg);
        (v + d[0], g + DVec3::from_array(dg[0]))
    }
}

/// Largest number of scattered points [`PointSurface::fit`] accepts (the volume spline's
/// dense system of `N + 4` unknowns is also checked against the memory budget).
pub const MAX_SURFACE_POINTS: usize = 20_000;

/// Smallest `det(C)^(1/3)` of the points' covariance relative to their squared extent; below
/// it the points lie in a plane (to about 1e-6 of their size) and no ellipsoid fits them.
const MIN_COVARIANCE: f64 = 1e-12;

/// An ellipsoid fitted to scattered surface points by their moments, written distance-like
/// as `e(x) = ρ/2 · (1 − (x − c)ᵀ Q (x − c))`: the centre `c` is the points' mean and
/// `Q = (3C)⁻¹` with `C` their covariance (exact for points spread uniformly over a sphere,
/// whose covariance is `r²/3·I`), `ρ = det(3C)^(1/6)` the geometric mean of the semi-axes, so
/// `|∇e| ≈ 1` on the ellipsoid. The initial function of [`PointSurface`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FittedEllipsoid {
    /// Centre `c`.
    pub centre: DVec3,
    /// The quadratic form `Q`.
    pub form: glam::DMat3,
    /// `ρ`.
    pub rho: f64,
}

impl FittedEllipsoid {
    /// Fit `points`.
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] for fewer than 4 points, a non-finite point, or points
    /// in a plane.
    pub fn fit(points: &[DVec3]) -> Result<Self, FrepError> {
        if points.len() < 4 {
            return Err(FrepError::InvalidArgument(format!(
                "fitting an ellipsoid needs at least 4 points, got {}",
                points.len()
            )));
        }
        if let Some(p) = points.iter().find(|p| !p.is_finite()) {
            return Err(FrepError::InvalidArgument(format!(
                "point {p} is not finite"
            )));
        }
        let n = points.len() as f64;
        let centre = points.iter().copied().sum::<DVec3>() / n;
        let mut c = glam::DMat3::ZERO;
        let mut extent = 0.0f64;
        for p in points {
            let d = *p - centre;
            extent = extent.max(d.length_squared());
            c += glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        }
        let c3 = c * (3.0 / n);
        let det = c3.determinant();
        if !(det.is_finite() && det.cbrt() > MIN_COVARIANCE * extent) {
            return Err(FrepError::InvalidArgument(format!(
                "the {} points lie in a plane (or on a line): no solid fits them",
                points.len()
            )));
        }
        Ok(Self {
            centre,
            form: c3.inverse(),
            rho: det.powf(1.0 / 6.0),
        })
    }

    /// `e(x)` as a [`Shape`](crate::Shape).
    #[must_use]
    pub fn shape(&self) -> crate::shape::Shape {
        let (c, q, rho) = (self.centre, self.form, self.rho);
        crate::shape::Shape::build(|b, x| {
            let d = [0, 1, 2].map(|k| b.add_c(x[k], -c[k]));
            let mut acc = b.constant(0.0);
            for r in 0..3 {
                for k in 0..3 {
                    let w = q.col(k)[r];
                    if w == 0.0 {
                        continue;
                    }
                    let t = b.mul(d[r], d[k]);
                    let t = b.mul_c(t, w);
                    acc = b.add(acc, t);
                }
            }
            let one = b.constant(1.0);
            let e = b.sub(one, acc);
            b.mul_c(e, 0.5 * rho)
        })
    }
}

/// A solid through scattered surface points (§4.1.1, Savchenko et al. 1995b): the
/// [`FittedEllipsoid`] `f₀` of the points plus the 3D volume spline `d` through `−f₀(pᵢ)`, so
/// every point lies on the zero set — [`SplineCorrected::through_surface_points`] written as a
/// [`Shape`](crate::Shape) (compiled, interval-bounded, differentiated like any model).
#[derive(Debug, Clone)]
pub struct PointSurface {
    /// The defining function.
    pub shape: crate::shape::Shape,
    /// The initial function.
    pub ellipsoid: FittedEllipsoid,
    /// The points' bounding box, enlarged by [`SAMPLING_MARGIN`] of its largest extent on
    /// every side (the box to sample or render).
    pub bounds: (DVec3, DVec3),
}

impl PointSurface {
    /// Reconstruct from `points` with spline smoothing `smoothing ≥ 0` (0 interpolates).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] for more than [`MAX_SURFACE_POINTS`] points; as
    /// [`FittedEllipsoid::fit`] and [`SplineCorrected::through_surface_points`] (coincident
    /// points, a system beyond the memory budget).
    pub fn fit(points: &[DVec3], smoothing: f64) -> Result<Self, FrepError> {
        if points.len() > MAX_SURFACE_POINTS {
            return Err(FrepError::InvalidArgument(format!(
                "{} points: at most {MAX_SURFACE_POINTS} are reconstructed (thin them out)",
                points.len()
            )));
        }
        let ellipsoid = FittedEllipsoid::fit(points)?;
        let initial = ellipsoid.shape();
        let zeros = vec![0.0; points.len()];
        let shape = crate::mapping::spline_points(&initial, points, &zeros, smoothing)?;
        let lo = points
            .iter()
            .fold(DVec3::splat(f64::INFINITY), |m, p| m.min(*p));
        let hi = points
            .iter()
            .fold(DVec3::splat(f64::NEG_INFINITY), |m, p| m.max(*p));
        let pad = DVec3::splat(SAMPLING_MARGIN * (hi - lo).max_element());
        Ok(Self {
            shape,
            ellipsoid,
            bounds: (lo - pad, hi + pad),
        })
    }

    /// The largest |f| of the reconstructed function at `points` (0 at points it passes
    /// through exactly; with smoothing > 0 the spline approximates, so this measures how far).
    #[must_use]
    pub fn largest_residual(&self, points: &[DVec3]) -> f64 {
        let tape = crate::tape::Tape::new(&self.shape);
        points
            .iter()
            .map(|p| tape.eval(*p).abs())
            .fold(0.0, f64::max)
    }
}

/// Smallest |area| of a contour loop relative to the square of its extent; below it the loop
/// is degenerate (its points on one line to about 1e-9 relative) and no ellipse fits it.
const MIN_LOOP_AREA: f64 = 1e-9;

/// An ellipse `f₀` fitted to one closed contour loop: the ellipse with the loop polygon's
/// area, centroid and second moments (exact for a polygon sampled from an ellipse, up to the
/// polygon's own deviation), written distance-like as `e(x) = ρ/2 · (1 − q(x))` where `q` is
/// the ellipse's quadratic form (1 on the ellipse) and `ρ = √(ab)` the geometric mean of its
/// semi-axes, so `|∇e| ≈ 1` on the ellipse.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FittedEllipse {
    /// Centre (the loop's area centroid).
    pub centre: DVec2,
    /// `Q` in `q(x) = (x − c)ᵀ Q (x − c)`, as `[Qxx, Qxy, Qyy]`.
    pub form: [f64; 3],
    /// `ρ = √(ab)`.
    pub rho: f64,
}

impl FittedEllipse {
    /// Fit the loop `points` (a closed polygon, either orientation, the last point joined to
    /// the first).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] for fewer than 3 points, non-finite coordinates or a
    /// loop of (nearly) zero area.
    pub fn fit(points: &[DVec2]) -> Result<Self, FrepError> {
        if points.len() < 3 {
            return Err(FrepError::InvalidArgument(format!(
                "a contour loop needs at least 3 points, got {}",
                points.len()
            )));
        }
        if let Some(p) = points.iter().find(|p| !p.is_finite()) {
            return Err(FrepError::InvalidArgument(format!(
                "contour point {p} is not finite"
            )));
        }
        // Moments about the vertex mean (better conditioned than about the origin).
        let mean = points.iter().copied().sum::<DVec2>() / points.len() as f64;
        let (mut a2, mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let mut extent = 0.0f64;
        for (i, &p) in points.iter().enumerate() {
            let q = points[(i + 1) % points.len()];
            let (p, q) = (p - mean, q - mean);
            extent = extent.max(p.length());
            let cr = p.x * q.y - q.x * p.y;
            a2 += cr;
            sx += (p.x + q.x) * cr;
            sy += (p.y + q.y) * cr;
            sxx += (p.x * p.x + p.x * q.x + q.x * q.x) * cr;
            syy += (p.y * p.y + p.y * q.y + q.y * q.y) * cr;
            sxy += (p.x * q.y + 2.0 * p.x * p.y + 2.0 * q.x * q.y + q.x * p.y) * cr;
        }
        let area = a2 / 2.0;
        if area.abs() <= MIN_LOOP_AREA * extent * extent || !area.is_finite() {
            return Err(FrepError::InvalidArgument(format!(
                "contour loop of {} points around {mean} encloses no area",
                points.len()
            )));
        }
        // Centroid and central second moments per unit area (orientation cancels).
        let cx = sx / (6.0 * area);
        let cy = sy / (6.0 * area);
        let cxx = sxx / (12.0 * area) - cx * cx;
        let cyy = syy / (12.0 * area) - cy * cy;
        let cxy = sxy / (24.0 * area) - cx * cy;
        // An ellipse with semi-axes a, b has covariance ¼ R diag(a², b²) Rᵀ, so its form is
        // Q = (4C)⁻¹ and ab = √det(4C).
        let (m00, m01, m11) = (4.0 * cxx, 4.0 * cxy, 4.0 * cyy);
        let det = m00 * m11 - m01 * m01;
        if !(det > 0.0 && det.is_finite()) {
            return Err(FrepError::InvalidArgument(format!(
                "contour loop of {} points around {mean} has degenerate moments",
                points.len()
            )));
        }
        Ok(Self {
            centre: mean + DVec2::new(cx, cy),
            form: [m11 / det, -m01 / det, m00 / det],
            rho: det.sqrt().sqrt(),
        })
    }

    /// `e(x)` and `∇e(x)`.
    #[must_use]
    pub fn eval(&self, x: DVec2) -> (f64, DVec2) {
        let d = x - self.centre;
        let [a, b, c] = self.form;
        let qd = DVec2::new(a * d.x + b * d.y, b * d.x + c * d.y);
        let q = d.dot(qd);
        (0.5 * self.rho * (1.0 - q), -self.rho * qd)
    }
}

/// The defining function of one cross-section, `f_k(x, y) = f₀(x, y) + d(x, y)`: `f₀` is the
/// R-union (`max`) of the [`FittedEllipse`]s of the section's loops, `d` the 2D thin-plate
/// spline (`G(r) = r² ln r`) through `−f₀` at every contour point, so each contour point is on
/// the zero set. Inside the contours `f₀ > 0` and the smooth correction only moves the
/// boundary from the ellipse to the contour, so the function is ≥ 0 inside for contours that
/// an ellipse approximates up to smooth, moderate dents (kidney shapes; tested on the
/// built-in femur); deep spirals or long thin branches are outside that guarantee.
#[derive(Debug, Clone)]
pub struct SectionFunction {
    ellipses: Vec<FittedEllipse>,
    points: Vec<DVec2>,
    spline: VolumeSpline<2>,
}

impl SectionFunction {
    /// Build from the section's loops (each a closed polygon, disjoint, any orientation; holes
    /// are not modelled).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] for no loops or a loop [`FittedEllipse::fit`] rejects;
    /// [`FrepError::Deform`] for coincident points (also between loops) or a singular system.
    pub fn new(loops: &[Vec<DVec2>]) -> Result<Self, FrepError> {
        if loops.is_empty() {
            return Err(FrepError::InvalidArgument(
                "a cross-section needs at least one contour loop".into(),
            ));
        }
        let ellipses = loops
            .iter()
            .map(|l| FittedEllipse::fit(l))
            .collect::<Result<Vec<_>, _>>()?;
        let union = |p: DVec2| {
            ellipses
                .iter()
                .map(|e| e.eval(p).0)
                .fold(f64::NEG_INFINITY, f64::max)
        };
        let points: Vec<DVec2> = loops.iter().flatten().copied().collect();
        let centres: Vec<[f64; 2]> = points.iter().map(|p| p.to_array()).collect();
        let rhs: Vec<f64> = points.iter().map(|&p| -union(p)).collect();
        let system = VolumeSplineSystem::<2>::new(&centres, 0.0)?;
        let spline = system.solve(&rhs, 1)?;
        Ok(Self {
            ellipses,
            points,
            spline,
        })
    }

    /// `f_k(p)`.
    #[must_use]
    pub fn value(&self, p: DVec2) -> f64 {
        let mut d = [0.0];
        self.spline.eval(p.to_array(), &mut d);
        self.initial(p).0 + d[0]
    }

    /// `(f_k(p), ∇f_k(p))`.
    #[must_use]
    pub fn gradient(&self, p: DVec2) -> (f64, DVec2) {
        let mut d = [0.0];
        let mut g = [[0.0; 2]];
        self.spline.eval_with_gradient(p.to_array(), &mut d, &mut g);
        let (v, gv) = self.initial(p);
        (v + d[0], gv + DVec2::from_array(g[0]))
    }

    /// The initial function `f₀` (union of the fitted ellipses) and its gradient (that of
    /// the maximal ellipse).
    #[must_use]
    pub fn initial(&self, p: DVec2) -> (f64, DVec2) {
        let mut best = (f64::NEG_INFINITY, DVec2::ZERO);
        for e in &self.ellipses {
            let v = e.eval(p);
            if v.0 > best.0 {
                best = v;
            }
        }
        best
    }

    /// The contour points of all loops, in order (the spline's centres).
    #[must_use]
    pub fn points(&self) -> &[DVec2] {
        &self.points
    }

    /// The fitted ellipses, one per loop.
    #[must_use]
    pub fn ellipses(&self) -> &[FittedEllipse] {
        &self.ellipses
    }
}

/// One planar cross-section: its height and contour loops.
#[derive(Debug, Clone, PartialEq)]
pub struct Section {
    /// Height `z_k` of the section's plane.
    pub z: f64,
    /// Closed contour loops in the plane (`(x, y)` points; the last point joins the first).
    pub loops: Vec<Vec<DVec2>>,
}

/// How neighbouring section functions are blended along `z`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SectionBlend {
    /// The seed's Eq. 13: `(1 − t) f_k + t f_{k+1}`, `t = (z − z_k)/(z_{k+1} − z_k)`
    /// (continuous, with creases at the sections).
    #[default]
    Linear,
    /// Cubic Hermite interpolation with Catmull–Rom tangents for unequal spacing,
    /// `m_k = (f_{k+1} − f_{k−1})/(z_{k+1} − z_{k−1})` (one-sided at the end sections): a
    /// blend of up to four sections, `C¹` along `z` — the seed's "higher degree of
    /// interpolation between several cross-sections". Still exactly `f_k` at `z = z_k`.
    CatmullRom,
}

/// Margin of [`SectionStack::sampling_bounds`], as a fraction of the largest extent of the
/// sections' bounds. A choice, not a published value: the padded box is 1.1 extents wide,
/// so a grid of 23 or more samples along its largest axis keeps at least one sample layer
/// outside the surface on every side.
pub const SAMPLING_MARGIN: f64 = 0.05;

/// A solid reconstructed from cross-sections (the seed's Fig. 4): between sections `k` and
/// `k + 1` the defining function is the [`SectionBlend`] of their [`SectionFunction`]s in
/// `(x, y)`, with `z` as the metamorphosis parameter; it is then R-intersected (`min`) with
/// the slab `z₀ ≤ z ≤ zₙ` (`z − z₀` and `zₙ − z`), so the solid is capped by the end sections
/// and its surface is closed. Outside the slab the blend uses the end section's function.
///
/// At an interior height `z_k` the function equals `min(f_k, z_k − z₀, zₙ − z_k)`, i.e. `f_k`
/// wherever `f_k` is below the distance to the ends (in particular on and near the contour).
#[derive(Debug, Clone)]
pub struct SectionStack {
    z: Vec<f64>,
    functions: Vec<SectionFunction>,
    blend: SectionBlend,
}

/// Largest number of sections or points per section read from JSON (the spline system is
/// dense: `N` contour points cost `8N²` bytes).
pub const MAX_SECTION_POINTS: usize = 4096;

/// Largest number of sections.
pub const MAX_SECTIONS: usize = 4096;

impl SectionStack {
    /// Build from sections (in any order; sorted by `z`).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] for fewer than 2 sections, more than [`MAX_SECTIONS`],
    /// a section with more than [`MAX_SECTION_POINTS`] points, non-finite or repeated
    /// heights, and the errors of [`SectionFunction::new`] (prefixed with the section's `z`).
    pub fn new(sections: &[Section], blend: SectionBlend) -> Result<Self, FrepError> {
        if sections.len() < 2 || sections.len() > MAX_SECTIONS {
            return Err(FrepError::InvalidArgument(format!(
                "a reconstruction needs 2 to {MAX_SECTIONS} cross-sections, got {}",
                sections.len()
            )));
        }
        let mut order: Vec<&Section> = sections.iter().collect();
        if let Some(s) = order.iter().find(|s| !s.z.is_finite()) {
            return Err(FrepError::InvalidArgument(format!(
                "a cross-section height is not finite: {}",
                s.z
            )));
        }
        order.sort_by(|a, b| a.z.total_cmp(&b.z));
        let mut z = Vec::with_capacity(order.len());
        let mut functions = Vec::with_capacity(order.len());
        for s in order {
            if z.last().is_some_and(|&last| last >= s.z) {
                return Err(FrepError::InvalidArgument(format!(
                    "two cross-sections at z = {}",
                    s.z
                )));
            }
            let n: usize = s.loops.iter().map(Vec::len).sum();
            if n > MAX_SECTION_POINTS {
                return Err(FrepError::InvalidArgument(format!(
                    "the cross-section at z = {} has {n} points (at most {MAX_SECTION_POINTS})",
                    s.z
                )));
            }
            let f = SectionFunction::new(&s.loops).map_err(|e| {
                FrepError::InvalidArgument(format!("cross-section at z = {}: {e}", s.z))
            })?;
            z.push(s.z);
            functions.push(f);
        }
        Ok(Self {
            z,
            functions,
            blend,
        })
    }

    /// Parse the contour format and build the stack:
    ///
    /// ```json
    /// {"sections": [
    ///   {"z": 0.0, "points": [[x, y], [x, y], ...]},
    ///   {"z": 1.5, "loops": [[[x, y], ...], [[x, y], ...]]}
    /// ],
    ///  "blend": "linear"}
    /// ```
    ///
    /// Each section has its height `z` and either `points` (one closed loop) or `loops`
    /// (several disjoint closed loops); coordinates are physical units, the last point of a
    /// loop joins the first. `blend` is optional: `"linear"` (default, Eq. 13) or
    /// `"catmull-rom"` (see [`SectionBlend`]).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] for text that is not this format (naming the field), and
    /// as [`new`](Self::new).
    pub fn from_json(text: &str) -> Result<Self, FrepError> {
        let bad = |m: String| FrepError::InvalidArgument(format!("contour file: {m}"));
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| bad(format!("not JSON: {e}")))?;
        let blend = match v.get("blend") {
            None => SectionBlend::Linear,
            Some(b) => match b.as_str() {
                Some("linear") => SectionBlend::Linear,
                Some("catmull-rom") => SectionBlend::CatmullRom,
                _ => {
                    return Err(bad(format!(
                        "`blend` must be \"linear\" or \"catmull-rom\", got {b}"
                    )));
                }
            },
        };
        let list = v
            .get("sections")
            .and_then(serde_json::Value::as_array)
            .ok_or_else(|| bad("expected an object with a `sections` array".into()))?;
        if list.len() > MAX_SECTIONS {
            return Err(bad(format!(
                "{} sections (at most {MAX_SECTIONS})",
                list.len()
            )));
        }
        let point = |p: &serde_json::Value, k: usize| -> Result<DVec2, FrepError> {
            match p.as_array().map(Vec::as_slice) {
                Some([x, y]) => match (x.as_f64(), y.as_f64()) {
                    (Some(x), Some(y)) => Ok(DVec2::new(x, y)),
                    _ => Err(bad(format!("section {k}: a point is not two numbers: {p}"))),
                },
                _ => Err(bad(format!("section {k}: a point is not [x, y]: {p}"))),
            }
        };
        let read_loop = |l: &serde_json::Value, k: usize| -> Result<Vec<DVec2>, FrepError> {
            let a = l
                .as_array()
                .ok_or_else(|| bad(format!("section {k}: a loop is not an array of points")))?;
            if a.len() > MAX_SECTION_POINTS {
                return Err(bad(format!(
                    "section {k}: {} points (at most {MAX_SECTION_POINTS})",
                    a.len()
                )));
            }
            a.iter().map(|p| point(p, k)).collect()
        };
        let mut sections = Vec::with_capacity(list.len());
        for (k, s) in list.iter().enumerate() {
            let z = s
                .get("z")
                .and_then(serde_json::Value::as_f64)
                .ok_or_else(|| bad(format!("section {k} has no numeric `z`")))?;
            let loops = match (s.get("points"), s.get("loops")) {
                (Some(p), None) => vec![read_loop(p, k)?],
                (None, Some(ls)) => {
                    let ls = ls.as_array().ok_or_else(|| {
                        bad(format!("section {k}: `loops` is not an array of loops"))
                    })?;
                    if ls.len() > MAX_SECTION_POINTS {
                        return Err(bad(format!("section {k}: too many loops")));
                    }
                    ls.iter()
                        .map(|l| read_loop(l, k))
                        .collect::<Result<_, _>>()?
                }
                _ => {
                    return Err(bad(format!(
                        "section {k} needs exactly one of `points` or `loops`"
                    )));
                }
            };
            sections.push(Section { z, loops });
        }
        Self::new(&sections, blend)
    }

    /// Section heights, increasing.
    #[must_use]
    pub fn heights(&self) -> &[f64] {
        &self.z
    }

    /// Section functions, in the order of [`heights`](Self::heights).
    #[must_use]
    pub fn functions(&self) -> &[SectionFunction] {
        &self.functions
    }

    /// The blend along `z`.
    #[must_use]
    pub fn blend(&self) -> SectionBlend {
        self.blend
    }

    /// The same sections with another blend along `z`.
    #[must_use]
    pub fn with_blend(mut self, blend: SectionBlend) -> Self {
        self.blend = blend;
        self
    }

    /// The box to sample or mesh the reconstruction in: [`Self::bounds`] grown on every side
    /// by [`SAMPLING_MARGIN`] times its largest extent, so the surface (including the caps
    /// that close the slab at its first and last heights) lies strictly inside the grid and
    /// every cell crossing it has samples on both sides.
    #[must_use]
    pub fn sampling_bounds(&self) -> (DVec3, DVec3) {
        let (lo, hi) = self.bounds();
        let pad = DVec3::splat(SAMPLING_MARGIN * (hi - lo).max_element());
        (lo - pad, hi + pad)
    }

    /// The bounding box of the contour points and the slab, `(lo, hi)`.
    #[must_use]
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let mut lo = DVec2::splat(f64::INFINITY);
        let mut hi = DVec2::splat(f64::NEG_INFINITY);
        for f in &self.functions {
            for e in &f.ellipses {
                // The ellipse's bounding box: half-widths √(M_xx), √(M_yy) of M = Q⁻¹.
                let [a, b, c] = e.form;
                let det = a * c - b * b;
                let h = DVec2::new((c / det).sqrt(), (a / det).sqrt());
                lo = lo.min(e.centre - h);
                hi = hi.max(e.centre + h);
            }
            for &c in &f.points {
                lo = lo.min(c);
                hi = hi.max(c);
            }
        }
        let (z0, z1) = (self.z[0], self.z[self.z.len() - 1]);
        (DVec3::new(lo.x, lo.y, z0), DVec3::new(hi.x, hi.y, z1))
    }

    /// Weights `(index, weight, dweight/dz)` of the sections blended at height `z` (clamped
    /// to the slab); at most four, unused ones with weight 0.
    fn weights(&self, z: f64) -> [(usize, f64, f64); 4] {
        let n = self.z.len();
        let zc = z.clamp(self.z[0], self.z[n - 1]);
        let inside = z > self.z[0] && z < self.z[n - 1];
        // k with z_k ≤ zc ≤ z_{k+1}, k ≤ n − 2.
        let k = self
            .z
            .partition_point(|&zk| zk <= zc)
            .saturating_sub(1)
            .min(n - 2);
        let dz = self.z[k + 1] - self.z[k];
        let t = (zc - self.z[k]) / dz;
        let dt = if inside { 1.0 / dz } else { 0.0 };
        match self.blend {
            SectionBlend::Linear => [
                (k, 1.0 - t, -dt),
                (k + 1, t, dt),
                (k, 0.0, 0.0),
                (k, 0.0, 0.0),
            ],
            SectionBlend::CatmullRom => {
                let (t2, t3) = (t * t, t * t * t);
                let h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
                let h10 = t3 - 2.0 * t2 + t;
                let h01 = -2.0 * t3 + 3.0 * t2;
                let h11 = t3 - t2;
                let d00 = (6.0 * t2 - 6.0 * t) * dt;
                let d10 = (3.0 * t2 - 4.0 * t + 1.0) * dt;
                let d01 = (-6.0 * t2 + 6.0 * t) * dt;
                let d11 = (3.0 * t2 - 2.0 * t) * dt;
                // Tangent m_j = (f_{b} − f_{a}) / (z_b − z_a) with one-sided ends; its
                // contribution dz·h·m_j spread on f_a, f_b.
                let tangent = |j: usize| {
                    let (a, b) = (j.saturating_sub(1), (j + 1).min(n - 1));
                    (a, b, dz / (self.z[b] - self.z[a]))
                };
                let (a0, b0, s0) = tangent(k);
                let (a1, b1, s1) = tangent(k + 1);
                // Collect into at most four distinct sections: k−1, k, k+1, k+2.
                let base = k.saturating_sub(1);
                let mut w = [
                    (base, 0.0, 0.0),
                    (base + 1, 0.0, 0.0),
                    (base + 2, 0.0, 0.0),
                    (base + 3, 0.0, 0.0),
                ];
                let mut add = |i: usize, v: f64, d: f64| {
                    // i ∈ [base, base + 3] by construction.
                    let slot = &mut w[(i - base).min(3)];
                    slot.1 += v;
                    slot.2 += d;
                };
                add(k, h00, d00);
                add(k + 1, h01, d01);
                add(b0, h10 * s0, d10 * s0);
                add(a0, -h10 * s0, -d10 * s0);
                add(b1, h11 * s1, d11 * s1);
                add(a1, -h11 * s1, -d11 * s1);
                for slot in &mut w {
                    if slot.0 >= n {
                        slot.0 = n - 1;
                    }
                }
                w
            }
        }
    }
}

impl Field for SectionStack {
    fn value(&self, p: DVec3) -> f64 {
        let xy = p.truncate();
        let mut f = 0.0;
        for (i, w, _) in self.weights(p.z) {
            if w != 0.0 {
                f += w * self.functions[i].value(xy);
            }
        }
        let n = self.z.len();
        f.min(p.z - self.z[0]).min(self.z[n - 1] - p.z)
    }

    fn gradient(&self, p: DVec3) -> (f64, DVec3) {
        let xy = p.truncate();
        let (mut f, mut g) = (0.0, DVec3::ZERO);
        for (i, w, dw) in self.weights(p.z) {
            if w != 0.0 || dw != 0.0 {
                let (v, gv) = self.functions[i].gradient(xy);
                f += w * v;
                g += DVec3::new(w * gv.x, w * gv.y, dw * v);
            }
        }
        let n = self.z.len();
        let (lo, hi) = (p.z - self.z[0], self.z[n - 1] - p.z);
        if lo < f && lo <= hi {
            (lo, DVec3::Z)
        } else if hi < f {
            (hi, -DVec3::Z)
        } else {
            (f, g)
        }
    }
}

/// A femur-like bone as 12 synthetic cross-sections (units: centimetres, `z` up from the
/// distal condyles at `z = 0` to the femoral head at `z = 43.5`): wide kidney-shaped sections
/// with a posterior notch at the knee, a round narrow shaft, a widening trochanter region and
/// a round head offset medially (`−x`). Each loop has `points_per_loop` points (≥ 8), listed
/// counter-clockwise.
///
/// # Errors
/// [`FrepError::InvalidArgument`] for fewer than 8 or more than [`MAX_SECTION_POINTS`] points
/// per loop.
pub fn femur_sections(points_per_loop: usize) -> Result<Vec<Section>, FrepError> {
    if !(8..=MAX_SECTION_POINTS).contains(&points_per_loop) {
        return Err(FrepError::InvalidArgument(format!(
            "the femur example needs 8 to {MAX_SECTION_POINTS} points per section, got {points_per_loop}"
        )));
    }
    // (z, semi-axis a along x, semi-axis b along y, notch depth, centre x, centre y, rotation).
    const TABLE: [(f64, f64, f64, f64, f64, f64, f64); 12] = [
        (0.0, 3.6, 2.4, 0.30, 0.0, 0.0, 0.0),
        (2.0, 4.0, 2.7, 0.28, 0.0, 0.1, 0.0),
        (5.0, 3.2, 2.4, 0.15, 0.0, 0.2, 0.05),
        (9.0, 2.1, 1.8, 0.05, 0.1, 0.2, 0.1),
        (14.0, 1.5, 1.4, 0.0, 0.2, 0.2, 0.15),
        (20.0, 1.4, 1.35, 0.0, 0.3, 0.2, 0.2),
        (26.0, 1.45, 1.4, 0.0, 0.3, 0.2, 0.25),
        (31.0, 1.8, 1.5, 0.0, 0.2, 0.2, 0.3),
        (35.0, 2.6, 1.8, 0.1, 0.0, 0.2, 0.35),
        (38.0, 2.9, 2.0, 0.12, -0.5, 0.2, 0.4),
        (41.0, 2.2, 2.0, 0.0, -1.6, 0.1, 0.4),
        (43.5, 1.5, 1.5, 0.0, -2.0, 0.1, 0.4),
    ];
    Ok(TABLE
        .iter()
        .map(|&(z, a, b, notch, cx, cy, rot)| {
            let (sr, cr) = rot.sin_cos();
            let pts = (0..points_per_loop)
                .map(|i| {
                    let th = std::f64::consts::TAU * i as f64 / points_per_loop as f64;
                    // A smooth posterior notch (at θ = 3π/2) of relative depth `notch`.
                    let s = (-th.sin()).max(0.0);
                    let r = 1.0 - notch * s.powi(4);
                    let (x, y) = (a * r * th.cos(), b * r * th.sin());
                    DVec2::new(cx + cr * x - sr * y, cy + sr * x + cr * y)
                })
                .collect();
            Section {
                z,
                loops: vec![pts],
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::box_geometry;
    use crate::output::{MeshOptions, mesh};
    use crate::shape::Shape;
    use crate::tape::Tape;

    fn ball(r: f64) -> Tape {
        Tape::new(&Shape::build(|b, [x, y, z]| {
            let (x2, y2, z2) = (b.square(x), b.square(y), b.square(z));
            let s = b.add(x2, y2);
            let s = b.add(s, z2);
            let r2 = b.constant(r * r);
            b.sub(r2, s)
        }))
    }

    fn inside_polygon(p: DVec2, poly: &[DVec2]) -> bool {
        let mut inside = false;
        for (i, &a) in poly.iter().enumerate() {
            let b = poly[(i + 1) % poly.len()];
            if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x) {
                inside = !inside;
            }
        }
        inside
    }

    fn dist_to_polygon(p: DVec2, poly: &[DVec2]) -> f64 {
        (0..poly.len())
            .map(|i| {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                let t = ((p - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
                (a + t * (b - a) - p).length()
            })
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn reconstruction_interpolates_surface_points() {
        // Points on an ellipsoid with semi-axes 1.4, 0.9, 0.7; initial function: unit ball.
        let mut pts = Vec::new();
        for i in 0..6 {
            for j in 0..10 {
                let th = std::f64::consts::PI * (f64::from(i) + 0.5) / 6.0;
                let ph = std::f64::consts::TAU * f64::from(j) / 10.0 + 0.3 * f64::from(i);
                pts.push(DVec3::new(
                    1.4 * th.sin() * ph.cos(),
                    0.9 * th.sin() * ph.sin(),
                    0.7 * th.cos(),
                ));
            }
        }
        let f = SplineCorrected::through_surface_points(ball(1.0), &pts, 0.0).unwrap();
        for &p in &pts {
            assert!(f.value(p).abs() < 1e-9, "{}", f.value(p));
        }
        // HyperFun sign convention: inside positive, outside negative.
        assert!(f.value(DVec3::ZERO) > 0.0);
        assert!(f.value(DVec3::new(1.2, 0.0, 0.0)) > 0.0);
        assert!(f.value(DVec3::new(0.0, 0.0, 1.0)) < 0.0);
        assert!(f.value(DVec3::new(3.0, 3.0, 3.0)) < 0.0);
        // Sum rule for the gradient against central differences.
        let x = DVec3::new(0.3, -0.2, 0.25);
        let (v, g) = f.gradient(x);
        assert_eq!(v, f.value(x));
        let h = 1e-6;
        for e in [DVec3::X, DVec3::Y, DVec3::Z] {
            let fd = (f.value(x + h * e) - f.value(x - h * e)) / (2.0 * h);
            assert!((fd - g.dot(e)).abs() < 1e-6, "{fd} vs {}", g.dot(e));
        }
        // Prescribed values.
        let vals: Vec<f64> = (0..pts.len()).map(|i| i as f64 * 0.01).collect();
        let f = SplineCorrected::through_values(ball(1.0), &pts, &vals, 0.0).unwrap();
        for (p, v) in pts.iter().zip(&vals) {
            assert!((f.value(*p) - v).abs() < 1e-9);
        }
        assert!(SplineCorrected::through_values(ball(1.0), &pts, &vals[1..], 0.0).is_err());
        assert!(SplineCorrected::through_surface_points(ball(1.0), &pts[..3], 0.0).is_err());
    }

    #[test]
    fn point_surface_passes_through_its_points() {
        // 150 points on an ellipsoid (semi-axes 1.5, 1.0, 0.7) about (0.3, −0.2, 1), spread
        // unevenly (denser near one pole).
        let (a, b, c) = (1.5, 1.0, 0.7);
        let centre = DVec3::new(0.3, -0.2, 1.0);
        let pts: Vec<DVec3> = (0..150)
            .map(|i| {
                let u = (f64::from(i) + 0.5) / 150.0;
                let th = std::f64::consts::PI * u.powf(1.3);
                let ph = 2.399_963 * f64::from(i);
                centre
                    + DVec3::new(
                        a * th.sin() * ph.cos(),
                        b * th.sin() * ph.sin(),
                        c * th.cos(),
                    )
            })
            .collect();
        let s = PointSurface::fit(&pts, 0.0).unwrap();
        let t = Tape::new(&s.shape);
        for p in &pts {
            assert!(t.eval(*p).abs() < 1e-9, "{p}: {}", t.eval(*p));
            assert!(p.cmpge(s.bounds.0).all() && p.cmple(s.bounds.1).all());
        }
        assert!(t.eval(centre) > 0.0);
        assert!(t.eval(centre + DVec3::new(3.0, 0.0, 0.0)) < 0.0);
        // A closed surface enclosing about the ellipsoid's volume.
        let geo = box_geometry(s.bounds.0, s.bounds.1, [40, 40, 40]).unwrap();
        let m = mesh(&t, &geo, &MeshOptions::default()).unwrap().mesh;
        assert!(m.validate().is_closed_manifold());
        let want = 4.0 / 3.0 * std::f64::consts::PI * a * b * c;
        let got = m.signed_volume();
        assert!((got / want - 1.0).abs() < 0.05, "{got} vs {want}");
        // Too few, coplanar or non-finite points are errors.
        assert!(PointSurface::fit(&pts[..3], 0.0).is_err());
        let flat: Vec<DVec3> = pts.iter().map(|p| DVec3::new(p.x, p.y, 0.0)).collect();
        assert!(PointSurface::fit(&flat, 0.0).is_err());
        let mut bad = pts.clone();
        bad[7].y = f64::NAN;
        assert!(PointSurface::fit(&bad, 0.0).is_err());
    }

    #[test]
    fn ellipse_fit_recovers_an_ellipse() {
        let (a, b, rot) = (3.0, 1.5, 0.4_f64);
        let c = DVec2::new(1.0, -2.0);
        let (s, co) = rot.sin_cos();
        let pts: Vec<DVec2> = (0..400)
            .map(|i| {
                let t = std::f64::consts::TAU * f64::from(i) / 400.0;
                let (x, y) = (a * t.cos(), b * t.sin());
                c + DVec2::new(co * x - s * y, s * x + co * y)
            })
            .collect();
        let e = FittedEllipse::fit(&pts).unwrap();
        assert!((e.centre - c).length() < 1e-9);
        assert!((e.rho - (a * b).sqrt()).abs() < 1e-3 * e.rho);
        for &p in &pts {
            assert!(e.eval(p).0.abs() < 2e-3, "{}", e.eval(p).0);
        }
        assert!(e.eval(c).0 > 0.0);
        assert!(FittedEllipse::fit(&pts[..2]).is_err());
        let line: Vec<DVec2> = (0..5).map(|i| DVec2::splat(f64::from(i))).collect();
        assert!(FittedEllipse::fit(&line).is_err());
    }

    #[test]
    fn femur_sections_are_interpolated_with_inside_positive() {
        let sections = femur_sections(24).unwrap();
        for s in &sections {
            let f = SectionFunction::new(&s.loops).unwrap();
            let poly = &s.loops[0];
            for &p in poly {
                assert!(f.value(p).abs() < 1e-9, "z = {}: {}", s.z, f.value(p));
            }
            // Sign matches the polygon away from its boundary (the polygon's chords are
            // within ~1% of the contour's size from the smooth curve the spline draws).
            let lo = poly
                .iter()
                .fold(DVec2::splat(f64::INFINITY), |m, &p| m.min(p));
            let hi = poly
                .iter()
                .fold(DVec2::splat(f64::NEG_INFINITY), |m, &p| m.max(p));
            let margin = 0.05 * (hi - lo).max_element();
            for i in 0..=40 {
                for j in 0..=40 {
                    let p = lo - DVec2::splat(2.0)
                        + (hi - lo + DVec2::splat(4.0)) * DVec2::new(f64::from(i), f64::from(j))
                            / 40.0;
                    if dist_to_polygon(p, poly) < margin {
                        continue;
                    }
                    let v = f.value(p);
                    assert_eq!(v > 0.0, inside_polygon(p, poly), "z = {} at {p}: {v}", s.z);
                }
            }
            // Gradient against differences.
            let x = poly[3] * 0.7;
            let (v, g) = f.gradient(x);
            assert_eq!(v, f.value(x));
            let h = 1e-6;
            let fd = DVec2::new(
                (f.value(x + DVec2::X * h) - f.value(x - DVec2::X * h)) / (2.0 * h),
                (f.value(x + DVec2::Y * h) - f.value(x - DVec2::Y * h)) / (2.0 * h),
            );
            assert!((fd - g).length() < 1e-5, "{fd} vs {g}");
        }
    }

    #[test]
    fn stack_equals_section_functions_at_their_heights() {
        let sections = femur_sections(20).unwrap();
        for blend in [SectionBlend::Linear, SectionBlend::CatmullRom] {
            let stack = SectionStack::new(&sections, blend).unwrap();
            let (z0, z1) = (stack.heights()[0], *stack.heights().last().unwrap());
            for (k, s) in sections.iter().enumerate() {
                let fk = &stack.functions()[k];
                for &p in &s.loops[0] {
                    let v = stack.value(p.extend(s.z));
                    assert!(v.abs() < 1e-9, "contour point at z = {}: {v}", s.z);
                }
                if k == 0 || k + 1 == sections.len() {
                    continue;
                }
                for q in [
                    DVec2::new(0.3, 0.1),
                    DVec2::new(5.0, 1.0),
                    s.loops[0][2] * 0.9,
                ] {
                    let want = fk.value(q).min(s.z - z0).min(z1 - s.z);
                    assert_eq!(stack.value(q.extend(s.z)), want);
                }
            }
            // Linear blend halfway between two sections.
            if blend == SectionBlend::Linear {
                let q = DVec2::new(0.2, 0.4);
                let (za, zb) = (sections[4].z, sections[5].z);
                let want = 0.5 * (stack.functions()[4].value(q) + stack.functions()[5].value(q));
                assert!((stack.value(q.extend(0.5 * (za + zb))) - want).abs() < 1e-12);
            }
            // Capped beyond the end sections.
            assert!(stack.value(DVec3::new(0.0, 0.0, z0 - 0.1)) < 0.0);
            assert!(stack.value(DVec3::new(-2.0, 0.1, z1 + 0.1)) < 0.0);
            // Gradient against differences, inside the slab.
            let x = DVec3::new(0.4, 0.3, 17.3);
            let (v, g) = stack.gradient(x);
            assert_eq!(v, stack.value(x));
            let h = 1e-6;
            for e in [DVec3::X, DVec3::Y, DVec3::Z] {
                let fd = (stack.value(x + h * e) - stack.value(x - h * e)) / (2.0 * h);
                assert!((fd - g.dot(e)).abs() < 1e-5, "{blend:?} {e}: {fd} vs {g}");
            }
        }
    }

    #[test]
    fn femur_meshes_closed() {
        let stack = SectionStack::new(&femur_sections(16).unwrap(), SectionBlend::Linear).unwrap();
        let (lo, hi) = stack.bounds();
        let pad = DVec3::splat(1.0);
        let geo = box_geometry(lo - pad, hi + pad, [20, 20, 48]).unwrap();
        let surf = mesh(&stack, &geo, &MeshOptions::default()).unwrap();
        let report = surf.mesh.validate();
        assert!(report.is_closed_manifold(), "{report}");
        assert!(surf.mesh.signed_volume() > 0.0);
    }

    /// The sampling box holds the whole solid with a margin: every point on its faces is
    /// outside (f < 0).
    #[test]
    fn sampling_bounds_enclose_the_solid_with_a_margin() {
        let stack = SectionStack::new(&femur_sections(16).unwrap(), SectionBlend::Linear).unwrap();
        let (lo, hi) = stack.sampling_bounds();
        let (blo, bhi) = stack.bounds();
        let pad = SAMPLING_MARGIN * (bhi - blo).max_element();
        assert!(((blo - lo) - DVec3::splat(pad)).abs().max_element() < 1e-12);
        assert!(((hi - bhi) - DVec3::splat(pad)).abs().max_element() < 1e-12);
        let n = 24;
        for a in 0..3 {
            for side in [lo, hi] {
                for i in 0..=n {
                    for j in 0..=n {
                        let mut t = DVec3::ZERO;
                        t[(a + 1) % 3] = i as f64 / n as f64;
                        t[(a + 2) % 3] = j as f64 / n as f64;
                        let mut p = lo + (hi - lo) * t;
                        p[a] = side[a];
                        assert!(stack.value(p) < 0.0, "face point {p} is not outside");
                    }
                }
            }
        }
    }

    #[test]
    fn bad_sections_are_errors() {
        let sq = vec![
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        let one = Section {
            z: 0.0,
            loops: vec![sq.clone()],
        };
        assert!(SectionStack::new(std::slice::from_ref(&one), SectionBlend::Linear).is_err());
        assert!(SectionStack::new(&[one.clone(), one.clone()], SectionBlend::Linear).is_err());
        let nan = Section {
            z: f64::NAN,
            loops: vec![sq.clone()],
        };
        assert!(SectionStack::new(&[one.clone(), nan], SectionBlend::Linear).is_err());
        let empty = Section {
            z: 1.0,
            loops: vec![],
        };
        assert!(SectionStack::new(&[one.clone(), empty], SectionBlend::Linear).is_err());
        assert!(SectionStack::from_json("{}").is_err());
        assert!(SectionStack::from_json("[1, 2]").is_err());
        assert!(
            SectionStack::from_json(r#"{"sections": [{"z": 0, "points": [[0, 0, 1]]}]}"#).is_err()
        );
        assert!(
            SectionStack::from_json(r#"{"sections": [{"points": [[0, 0]]}, {"z": 1}]}"#).is_err()
        );
        assert!(femur_sections(3).is_err());
    }

    #[test]
    fn json_format_round_trip() {
        let text = r#"{"blend": "catmull-rom", "sections": [
            {"z": 0, "points": [[0, 0], [2, 0], [2, 1], [0, 1]]},
            {"z": 1, "loops": [[[0, 0], [1, 0], [1, 1], [0, 1]], [[3, 0], [4, 0], [4, 1], [3, 1]]]},
            {"z": 2.5, "points": [[0, 0], [1, 0], [0.5, 1]]}
        ]}"#;
        let stack = SectionStack::from_json(text).unwrap();
        assert_eq!(stack.heights(), &[0.0, 1.0, 2.5]);
        assert_eq!(stack.blend(), SectionBlend::CatmullRom);
        assert_eq!(stack.functions()[1].ellipses().len(), 2);
        assert_eq!(stack.functions()[1].points().len(), 8);
        for p in stack.functions()[1].points() {
            assert!(stack.value(p.extend(1.0)).abs() < 1e-9);
        }
    }
}
