//! Built-in models. [`grin_lens`] is the gradient-index lens of the paper's modeling pipeline
//! (Fig. 1, §2.2): an aggregate line carrying a refractive index, revolved into a disk and
//! extruded into a rod.
//!
//! # The GRIN lens and its paraxial focal length
//!
//! The index profile is `n(r) = n₀·(1 − A·r²/2)` for `0 ≤ r ≤ R`, about the optical axis `z`.
//! The generating line runs from the axis `(0, 0, 0)` to `(R, 0, 0)` with degree 1, so
//! `r = R·u`, and the index is the quadratic Bézier in `u` with coefficients
//! `n₀, n₀, n₀·(1 − A·R²/2)` — exactly `n₀·(1 − A·R²u²/2)`, no fitting error. Revolving by `2π`
//! about `z` (exact rational circle, parameter `v`) gives a disk; extruding by `(0, 0, d)`
//! (parameter `w`) gives the rod `0 ≤ z ≤ d`. The index attribute is named
//! [`GRIN_ATTRIBUTE`].
//!
//! Paraxial optics ([`paraxial_focus`]): for rays near the axis, `n ≈ n₀` and the ray equation
//! `d/ds (n dr/ds) = ∂n/∂r = −n₀·A·r` becomes `r'' = −A·r` (primes are `d/dz`). A ray entering
//! the flat face `z = 0` parallel to the axis at height `r₀` (no refraction at normal incidence)
//! follows `r(z) = r₀·cos(√A·z)`, so at the exit face `r = r₀ cos(√A d)` with slope
//! `r' = −r₀ √A sin(√A d)`. Refraction at the flat exit face into air (index 1) multiplies the
//! small slope by `n(r) ≈ n₀` (Snell, `n sin θ = sin θ'`, small angles). The ray then meets the
//! axis after the **back focal distance** `BFD = r/|slope'| = cot(√A d)/(n₀ √A)` measured from
//! the exit face, and the **effective focal length** (height over exit angle) is
//! `EFL = r₀/|slope'| = 1/(n₀ √A sin(√A d))`. Assumptions: paraxial rays (`r₀ ≪ R`, so
//! `A r₀² ≪ 1`), the lens in air, and `0 < √A d < π/2` so the focus lies behind the lens.
//!
//! # The exact trace of a meridional ray
//!
//! The index depends on `r` only, so along any ray the axial component of the optical
//! momentum `p = n dr/ds` is conserved (`dp_z/ds = ∂n/∂z = 0`). A ray entering the flat face
//! `z = 0` parallel to the axis at height `r₀` (normal incidence, no refraction) keeps
//! `p_z = β = n(r₀)`, stays in its meridional plane, and its height obeys the exact
//! (non-paraxial) ODE in `z`
//!
//! ```text
//! r''(z) = n(r) n'(r) / β²,   r(0) = r₀,  r'(0) = 0      (n n' = d(n²/2)/dr)
//! ```
//!
//! At the exit face `z = d` the momentum is `(β r', β)` in the `(r, z)` plane; refraction into
//! air keeps its tangential part, so the outgoing direction is `(β r', √(1 − β² r'²))`, and
//! the ray meets the axis `BFD = r(d)·√(1 − β² r'²)/(−β r')` behind the face.
//! [`exact_back_focal_distance`] integrates the ODE by the classical fourth-order Runge–Kutta
//! method with [`EXACT_STEPS`] and twice as many steps and extrapolates (Richardson,
//! `(16 B_{2N} − B_N)/15`); it shares no code with the three-dimensional tracer (no spline,
//! no tracking, no boundary search), which makes it the reference the tracer is tested
//! against.

use volmorph_spline::{KnotVector, TensorBSpline};

use crate::error::ctx;
use crate::{
    Aggregate, AggregateCurve, AggregateSurface, AggregateVolume, TrivariateError, extrude, revolve,
};

/// Name of the refractive-index attribute of [`grin_lens`].
pub const GRIN_ATTRIBUTE: &str = "eta";

/// Parameters of [`grin_lens`] (lengths in the model's unit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GrinLensSpec {
    /// Lens radius `R` (> 0).
    pub radius: f64,
    /// Thickness `d` along the axis (> 0).
    pub thickness: f64,
    /// Index on the axis `n₀` (≥ 1).
    pub n0: f64,
    /// Gradient constant `A` (> 0, units 1/length²) of `n(r) = n₀(1 − A r²/2)`.
    pub gradient: f64,
}

impl Default for GrinLensSpec {
    /// `R = 1`, `d = 1`, `n₀ = 1.5`, `A = 0.5` (index 1.125 at the rim, `√A d ≈ 0.707`).
    fn default() -> Self {
        Self {
            radius: 1.0,
            thickness: 1.0,
            n0: 1.5,
            gradient: 0.5,
        }
    }
}

impl GrinLensSpec {
    /// Check the parameters.
    ///
    /// # Errors
    /// [`TrivariateError::InvalidArgument`] unless all are finite, `R, d, A > 0`, `n₀ ≥ 1`,
    /// the rim index `n₀(1 − A R²/2)` is at least 1 and `√A d < π/2`.
    pub fn validate(&self) -> Result<(), TrivariateError> {
        let ok = [self.radius, self.thickness, self.n0, self.gradient]
            .iter()
            .all(|v| v.is_finite())
            && self.radius > 0.0
            && self.thickness > 0.0
            && self.gradient > 0.0
            && self.n0 >= 1.0;
        if !ok {
            return Err(TrivariateError::InvalidArgument(format!(
                "GRIN lens needs finite radius, thickness, gradient > 0 and n0 >= 1, got {self:?}"
            )));
        }
        let rim = self.n0 * (1.0 - 0.5 * self.gradient * self.radius * self.radius);
        if rim < 1.0 {
            return Err(TrivariateError::InvalidArgument(format!(
                "GRIN lens rim index n0(1 - A R^2/2) = {rim} is below 1"
            )));
        }
        if self.gradient.sqrt() * self.thickness >= std::f64::consts::FRAC_PI_2 {
            return Err(TrivariateError::InvalidArgument(format!(
                "GRIN lens sqrt(A)·d = {} must be below π/2 (focus behind the lens)",
                self.gradient.sqrt() * self.thickness
            )));
        }
        Ok(())
    }
}

/// Paraxial focal distances of a GRIN rod (formulas in the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParaxialFocus {
    /// Effective focal length `1/(n₀ √A sin(√A d))`.
    pub effective_focal_length: f64,
    /// Back focal distance from the exit face, `cot(√A d)/(n₀ √A)`.
    pub back_focal_distance: f64,
}

/// The paraxial focus of the lens `spec`.
///
/// # Errors
/// As [`GrinLensSpec::validate`].
pub fn paraxial_focus(spec: &GrinLensSpec) -> Result<ParaxialFocus, TrivariateError> {
    spec.validate()?;
    let g = spec.gradient.sqrt();
    let phase = g * spec.thickness;
    Ok(ParaxialFocus {
        effective_focal_length: 1.0 / (spec.n0 * g * phase.sin()),
        back_focal_distance: phase.cos() / (phase.sin() * spec.n0 * g),
    })
}

/// Fourth-order Runge–Kutta steps across the lens of [`exact_back_focal_distance`] (the
/// coarse of its two integrations): with the default lens a step of `d/2000`, whose error
/// `O(h⁴)` is near 1e-13 before extrapolation.
pub const EXACT_STEPS: usize = 2000;

/// The exact trace of one meridional ray through the GRIN lens ([module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExactFocus {
    /// Height `r₀` of the ray parallel to the axis.
    pub height: f64,
    /// Distance behind the exit face at which the ray meets the axis (Richardson
    /// extrapolated).
    pub back_focal_distance: f64,
    /// `|B_{2N} − B_N|/15`: the estimated error of the unextrapolated fine result, an upper
    /// bound of the extrapolated one's.
    pub error_estimate: f64,
}

/// Back focal distance of the ray parallel to the axis of the lens `spec` at height
/// `height`, by the exact meridional ODE of the [module docs](self).
///
/// # Errors
/// As [`GrinLensSpec::validate`]; [`TrivariateError::InvalidArgument`] unless
/// `0 < height < R`, or when the ray leaves the rim, leaves parallel to the axis or is
/// totally reflected at the exit face.
pub fn exact_back_focal_distance(
    spec: &GrinLensSpec,
    height: f64,
) -> Result<ExactFocus, TrivariateError> {
    spec.validate()?;
    if !(height.is_finite() && height > 0.0 && height < spec.radius) {
        return Err(TrivariateError::InvalidArgument(format!(
            "ray height {height} must lie in (0, {})",
            spec.radius
        )));
    }
    let n = |r: f64| spec.n0 * (1.0 - 0.5 * spec.gradient * r * r);
    let beta = n(height);
    // (r, r') ↦ (r', n n' / β²), n' = −n₀ A r.
    let f = |y: [f64; 2]| {
        [
            y[1],
            n(y[0]) * (-spec.n0 * spec.gradient * y[0]) / (beta * beta),
        ]
    };
    let bfd = |steps: usize| -> Result<f64, TrivariateError> {
        let h = spec.thickness / steps as f64;
        let mut y = [height, 0.0];
        for _ in 0..steps {
            let k1 = f(y);
            let k2 = f([y[0] + 0.5 * h * k1[0], y[1] + 0.5 * h * k1[1]]);
            let k3 = f([y[0] + 0.5 * h * k2[0], y[1] + 0.5 * h * k2[1]]);
            let k4 = f([y[0] + h * k3[0], y[1] + h * k3[1]]);
            for c in 0..2 {
                y[c] += h / 6.0 * (k1[c] + 2.0 * k2[c] + 2.0 * k3[c] + k4[c]);
            }
            if y[0].abs() >= spec.radius {
                return Err(TrivariateError::InvalidArgument(format!(
                    "the ray at height {height} leaves the lens through its rim"
                )));
            }
        }
        let pr = beta * y[1];
        if !(pr < 0.0 && pr > -1.0) {
            return Err(TrivariateError::InvalidArgument(format!(
                "the ray at height {height} leaves the exit face with radial momentum {pr}: \
                 parallel to the axis, diverging or totally reflected"
            )));
        }
        Ok(y[0] * (1.0 - pr * pr).sqrt() / -pr)
    };
    let coarse = bfd(EXACT_STEPS)?;
    let fine = bfd(2 * EXACT_STEPS)?;
    Ok(ExactFocus {
        height,
        back_focal_distance: (16.0 * fine - coarse) / 15.0,
        error_estimate: (fine - coarse).abs() / 15.0,
    })
}

/// The GRIN lens of the [module docs](self): parameters `(u, v, w)` = (radius fraction,
/// revolution angle fraction, axial fraction); the axis is `z`, the entry face `z = 0`, the
/// exit face `z = d`; attribute [`GRIN_ATTRIBUTE`] holds the index.
///
/// # Errors
/// As [`GrinLensSpec::validate`].
pub fn grin_lens(spec: &GrinLensSpec) -> Result<AggregateVolume, TrivariateError> {
    spec.validate()?;
    let line_kv = KnotVector::bezier(1, [0.0, 1.0]).map_err(ctx("GRIN line knots"))?;
    let line = TensorBSpline::new([line_kv], 3, vec![0.0, 0.0, 0.0, spec.radius, 0.0, 0.0])
        .map_err(ctx("GRIN line"))?;
    let idx_kv = KnotVector::bezier(2, [0.0, 1.0]).map_err(ctx("GRIN index knots"))?;
    let n0 = spec.n0;
    let rim = n0 * (1.0 - 0.5 * spec.gradient * spec.radius * spec.radius);
    let index = TensorBSpline::new([idx_kv], 1, vec![n0, n0, rim]).map_err(ctx("GRIN index"))?;
    let curve = AggregateCurve::new(line)?.with_attribute(GRIN_ATTRIBUTE, index)?;
    let disk: AggregateSurface = revolve(&curve, [0.0; 3], [0.0, 0.0, 1.0], std::f64::consts::TAU)?;
    extrude(&disk, [0.0, 0.0, spec.thickness])
}

/// The [`grin_lens`] of `spec` as a modeling [`Recipe`](crate::recipe::Recipe): the profile
/// line from the axis to the rim, the index attached as the quadratic Bézier of the
/// [module docs](self), revolved a full turn about `z` and extruded by the thickness.
/// Building it gives exactly [`grin_lens`]`(spec)`.
///
/// # Errors
/// As [`GrinLensSpec::validate`].
pub fn grin_lens_recipe(spec: &GrinLensSpec) -> Result<crate::recipe::Recipe, TrivariateError> {
    use crate::recipe::{
        AttachStep, AttributeSpline, CurveStep, ExtrudeStep, RECIPE_FORMAT, RECIPE_VERSION, Recipe,
        RevolveStep, Step,
    };
    spec.validate()?;
    let n0 = spec.n0;
    let rim = n0 * (1.0 - 0.5 * spec.gradient * spec.radius * spec.radius);
    Ok(Recipe {
        format: RECIPE_FORMAT.to_owned(),
        version: RECIPE_VERSION,
        steps: vec![
            Step::Curve(CurveStep {
                name: "profile".into(),
                degree: 1,
                points: vec![[0.0; 3], [spec.radius, 0.0, 0.0]],
                knots: None,
                weights: None,
            }),
            Step::Attach(AttachStep {
                name: "graded".into(),
                to: "profile".into(),
                attribute: GRIN_ATTRIBUTE.into(),
                spline: AttributeSpline {
                    degree: Some(2),
                    values: Some(vec![n0, n0, rim]),
                    ..AttributeSpline::default()
                },
            }),
            Step::Revolve(RevolveStep {
                name: "disk".into(),
                of: "graded".into(),
                axis_point: [0.0; 3],
                axis_direction: [0.0, 0.0, 1.0],
                angle_degrees: 360.0,
            }),
            Step::Extrude(ExtrudeStep {
                name: "lens".into(),
                of: "disk".into(),
                direction: [0.0, 0.0, spec.thickness],
            }),
        ],
        result: "lens".into(),
    })
}

/// A tricubic volume of `n³` control points (clamped uniform knots on [0, 1]): a box bent and
/// twisted along w, carrying the wavy scalar attribute `f` ≈ squared distance from
/// (0.5, 0.45, 0.5). The fixture of the isosurface and slice benches and tests.
///
/// # Errors
/// [`TrivariateError::Spline`] when `n` is below 4 (a cubic needs four control points).
pub fn twisted_box(n: usize) -> Result<AggregateVolume, TrivariateError> {
    let kv = KnotVector::clamped_uniform(3, n, [0.0, 1.0]).map_err(ctx("twisted box knots"))?;
    let g = kv.greville();
    let mut pts = Vec::with_capacity(n * n * n * 3);
    let mut vals = Vec::with_capacity(n * n * n);
    for &w in &g {
        for &v in &g {
            for &u in &g {
                let ang = 0.6 * w;
                let (x, y) = (u - 0.5, v - 0.5);
                pts.extend([
                    x * ang.cos() - y * ang.sin() + 0.15 * (3.0 * w).sin(),
                    x * ang.sin() + y * ang.cos(),
                    w + 0.1 * (4.0 * u).sin(),
                ]);
                vals.push(
                    (u - 0.5).powi(2)
                        + (v - 0.45).powi(2)
                        + (w - 0.5).powi(2)
                        + 0.02 * (9.0 * u).sin() * (7.0 * v).cos(),
                );
            }
        }
    }
    let k = [kv.clone(), kv.clone(), kv];
    let geo = TensorBSpline::new(k.clone(), 3, pts).map_err(ctx("twisted box geometry"))?;
    let attr = TensorBSpline::new(k, 1, vals).map_err(ctx("twisted box attribute"))?;
    Aggregate::new(geo)?.with_attribute("f", attr)
}

/// The rational tricubic volume of issue 22's point-and-gradient target (the criterion bench
/// `evaluate` and the `volmorph bench ffd` row): 8³ control points on clamped uniform knots
/// over [0, 1]³, the integer grid gently bent (`x + 0.1·sin(yz)`, `y + 0.1·cos(x + z)`,
/// `z + 0.05·x`) with weights `1 + 0.25·|sin(0.7·(x + 2y + 3z))|` in `[1, 1.25]`.
///
/// # Errors
/// None in practice (the knots and net are valid); [`TrivariateError::Spline`] otherwise.
pub fn rational_tricubic_8cubed() -> Result<TensorBSpline<3>, TrivariateError> {
    let kv = KnotVector::clamped_uniform(3, 8, [0.0, 1.0]).map_err(ctx("8³ volume knots"))?;
    let mut pts = Vec::with_capacity(512 * 3);
    let mut ws = Vec::with_capacity(512);
    for k in 0..8 {
        for j in 0..8 {
            for i in 0..8 {
                let (x, y, z) = (f64::from(i), f64::from(j), f64::from(k));
                pts.extend([
                    x + 0.1 * (y * z).sin(),
                    y + 0.1 * (x + z).cos(),
                    z + 0.05 * x,
                ]);
                ws.push(1.0 + 0.25 * ((x + 2.0 * y + 3.0 * z) * 0.7).sin().abs());
            }
        }
    }
    TensorBSpline::new_rational([kv.clone(), kv.clone(), kv], 3, pts, ws)
        .map_err(ctx("8³ rational volume"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lens_geometry_and_index_are_exact() {
        let spec = GrinLensSpec::default();
        let lens = grin_lens(&spec).unwrap();
        let mut n = [0.0];
        for i in 0..=10 {
            for j in 0..=7 {
                let u = [f64::from(i) / 10.0, f64::from(j) / 7.0, 0.37];
                let p = lens.point(u).unwrap();
                let r = p[0].hypot(p[1]);
                assert!((r - spec.radius * u[0]).abs() < 1e-13, "{p:?}");
                assert!((p[2] - 0.37 * spec.thickness).abs() < 1e-13);
                lens.attribute_into(GRIN_ATTRIBUTE, u, &mut n).unwrap();
                let want = spec.n0 * (1.0 - 0.5 * spec.gradient * r * r);
                assert!((n[0] - want).abs() < 1e-13);
            }
        }
    }

    #[test]
    fn paraxial_formulas_and_validation() {
        let spec = GrinLensSpec::default();
        let f = paraxial_focus(&spec).unwrap();
        let g = 0.5f64.sqrt();
        assert!((f.effective_focal_length - 1.0 / (1.5 * g * g.sin())).abs() < 1e-15);
        assert!((f.back_focal_distance - 1.0 / (g.tan() * 1.5 * g)).abs() < 1e-14);
        for bad in [
            GrinLensSpec {
                radius: 0.0,
                ..spec
            },
            GrinLensSpec {
                gradient: f64::NAN,
                ..spec
            },
            GrinLensSpec {
                thickness: 3.0,
                ..spec
            },
            GrinLensSpec {
                gradient: 1.9,
                ..spec
            },
        ] {
            assert!(grin_lens(&bad).is_err(), "{bad:?}");
        }
    }
}
