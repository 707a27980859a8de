//! Point inversion of a space map by damped Newton iteration.
//!
//! Given a map `φ` and a target `y`, [`invert_point`] looks for `x` with `φ(x) = y`: it is how a
//! map used for **push-forward** (a free-form deformation sending model points to where they
//! go, True 1992 §4) is turned into the **pull-back** a renderer needs — output point `y` shows
//! the model point `φ⁻¹(y)`.
//!
//! # Method
//!
//! Starting from a guess `x₀` (the caller's, or the first-order inverse of the displacement
//! `x₀ = y − (φ(y) − y)`, exact for translations), each step solves
//!
//! ```text
//! Dφ(x) · δ = y − φ(x)
//! ```
//!
//! with LU factorisation and partial pivoting ([`Lu3`]), refusing Jacobians that are singular
//! or whose condition number exceeds [`MAX_CONDITION`]. The step is damped by backtracking: the
//! step length `α = 1, ½, ¼, …` is halved until the residual norm `|φ(x + αδ) − y|` decreases by
//! the Armijo factor `1 − 10⁻⁴·α`, so the iteration never moves to a worse point; if no
//! length up to `2⁻`[`MAX_HALVINGS`] decreases it, the iteration stops (not converged). The
//! iteration has converged when the residual `|φ(x) − y|` (Euclidean, physical units) is at
//! most the tolerance.
//!
//! # Which preimage
//!
//! When `φ` is injective (a lattice whose control points moved little, an invertible affine
//! map), the preimage is unique and Newton finds it from any guess in its basin — in practice
//! the first-order guess for displacements below a lattice cell. When `φ` **folds** space
//! (`det Dφ ≤ 0` somewhere), a target can have several preimages; Newton converges to the one
//! whose basin of attraction contains the starting guess, usually the one nearest to it, and
//! may fail near the fold itself where `Dφ` is singular. Callers walking a grid
//! coherently (starting from the neighbour's solution) follow one continuous sheet of the
//! fold. [`PointInverse::det_jacobian`] is `det Dφ` at the returned point: `≤ 0` flags a
//! preimage on a folded (inverted) sheet. A target with no preimage (outside the image of
//! `φ`, e.g. in the gap a discontinuous lattice leaves) is reported as not converged, with the
//! best point found — never as a solution.
//!
//! ```
//! use glam::{DMat3, DVec3};
//! use volmorph_deform::{Affine, InverseOptions, InverseStatus, SpaceMap, invert_point};
//!
//! let map = Affine {
//!     matrix: DMat3::from_cols(DVec3::new(2.0, 0.1, 0.0), DVec3::Y, DVec3::new(0.0, 0.3, 1.5)),
//!     offset: DVec3::new(1.0, -2.0, 0.5),
//! };
//! let y = DVec3::new(3.0, 4.0, 5.0);
//! let r = invert_point(&map, y, None, &InverseOptions::default());
//! assert_eq!(r.status, InverseStatus::Converged);
//! assert!((map.apply(r.point) - y).length() < 1e-12);
//! assert!((r.det_jacobian - 3.0).abs() < 1e-12);
//! ```

use glam::{DMat3, DVec3};

use crate::SpaceMap;

/// Default relative tolerance of [`invert_point`]: the residual must fall below
/// `DEFAULT_RELATIVE_TOLERANCE · max(1, |y|_∞)`. Newton converges quadratically, so this costs
/// about one iteration more than a loose tolerance, and it stays three to four orders above
/// the rounding of lattice evaluation (≈1e-15 relative per term, a few hundred terms).
pub const DEFAULT_RELATIVE_TOLERANCE: f64 = 1e-12;

/// Default iteration limit: quadratic convergence needs a handful of steps from a guess in
/// the basin; damped steps far from the solution need more, and 50 leaves ample room.
pub const DEFAULT_MAX_ITERATIONS: u32 = 50;

/// Largest 1-norm condition number `‖J‖₁·‖J⁻¹‖₁` of a Jacobian Newton still solves with.
/// The solved step then has a relative error up to about `κ·ε ≈ 2e-4`, still a descent
/// direction; beyond it the step is dominated by rounding and the Jacobian counts as singular.
pub const MAX_CONDITION: f64 = 1e12;

/// Largest number of step halvings in the backtracking line search (smallest step `2⁻³⁰ ≈
/// 1e-9` of the Newton step).
pub const MAX_HALVINGS: u32 = 30;

/// Armijo constant of the line search: a step of length `α` is accepted when it reduces the
/// residual norm by the factor `1 − ARMIJO·α` (the usual `10⁻⁴`, Dennis & Schnabel §6.3).
const ARMIJO: f64 = 1e-4;

/// Stopping rules of [`invert_point`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverseOptions {
    /// Largest accepted residual `|φ(x) − y|` in physical units (the units of `y`). `None`
    /// (the default) uses [`DEFAULT_RELATIVE_TOLERANCE`]` · max(1, |y|_∞)`; on a voxel grid a
    /// fraction of a voxel (e.g. `1e-6 · spacing`) is the natural choice. A tolerance that is
    /// not a finite number ≥ 0 is treated as 0 (only an exact solution converges).
    pub tolerance: Option<f64>,
    /// Largest number of Newton steps (default [`DEFAULT_MAX_ITERATIONS`]).
    pub max_iterations: u32,
}

impl Default for InverseOptions {
    fn default() -> Self {
        Self {
            tolerance: None,
            max_iterations: DEFAULT_MAX_ITERATIONS,
        }
    }
}

impl InverseOptions {
    /// Options with the absolute residual tolerance `tolerance` (physical units).
    #[must_use]
    pub fn with_tolerance(mut self, tolerance: f64) -> Self {
        self.tolerance = Some(tolerance);
        self
    }

    /// Options with another iteration limit.
    #[must_use]
    pub fn with_max_iterations(mut self, max_iterations: u32) -> Self {
        self.max_iterations = max_iterations;
        self
    }

    /// The absolute tolerance for target `y`.
    #[must_use]
    pub fn tolerance_for(&self, y: DVec3) -> f64 {
        let t = self
            .tolerance
            .unwrap_or_else(|| DEFAULT_RELATIVE_TOLERANCE * y.abs().max_element().max(1.0));
        if t.is_finite() && t >= 0.0 { t } else { 0.0 }
    }
}

/// How an inversion ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum InverseStatus {
    /// `|φ(point) − y|` is within the tolerance.
    Converged,
    /// The iteration limit was reached, or the line search found no step that reduces the
    /// residual (a local minimum of `|φ(x) − y|` that is not a solution, typically a target
    /// outside the image of the map).
    NotConverged,
    /// The Jacobian at the current point is singular or worse conditioned than
    /// [`MAX_CONDITION`] (a fold line, a collapsed region).
    SingularJacobian,
    /// The target, the starting guess or a value of the map is NaN or infinite.
    NonFinite,
}

/// The outcome of [`invert_point`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointInverse {
    /// The solution when converged; otherwise the best point reached (smallest residual), or
    /// the non-finite value met for [`InverseStatus::NonFinite`].
    pub point: DVec3,
    /// `|φ(point) − y|` (physical units); NaN if it could not be evaluated.
    pub residual: f64,
    /// Newton steps taken.
    pub iterations: u32,
    /// How the iteration ended.
    pub status: InverseStatus,
    /// `det Dφ(point)`: `≤ 0` means the point lies where the map folds space (see the
    /// [module docs](self)); NaN if not evaluated.
    pub det_jacobian: f64,
    /// `Dφ(point)` (columns `∂/∂x, ∂/∂y, ∂/∂z`), e.g. to predict the preimage of a nearby
    /// target to first order; all NaN if not evaluated.
    pub jacobian: DMat3,
}

impl PointInverse {
    /// `true` if the iteration converged.
    #[must_use]
    pub fn converged(&self) -> bool {
        self.status == InverseStatus::Converged
    }

    fn non_finite(point: DVec3) -> Self {
        Self {
            point,
            residual: f64::NAN,
            iterations: 0,
            status: InverseStatus::NonFinite,
            det_jacobian: f64::NAN,
            jacobian: DMat3::NAN,
        }
    }
}

/// The first-order inverse of the displacement, `y − (φ(y) − y)`: exact for translations,
/// and an error of second order in the displacement's gradient otherwise. The default guess
/// of [`invert_point`].
#[inline]
#[must_use]
pub fn first_order_guess<M: SpaceMap + ?Sized>(map: &M, y: DVec3) -> DVec3 {
    2.0 * y - map.apply(y)
}

/// Find `x` with `map.apply(x) = y` by damped Newton iteration from `guess` (default
/// [`first_order_guess`]); see the [module docs](self) for the method, the tolerance and which
/// preimage is found when the map folds. Never panics: NaN or infinite input gives
/// [`InverseStatus::NonFinite`].
#[must_use]
pub fn invert_point<M: SpaceMap + ?Sized>(
    map: &M,
    y: DVec3,
    guess: Option<DVec3>,
    options: &InverseOptions,
) -> PointInverse {
    if !y.is_finite() {
        return PointInverse::non_finite(y);
    }
    let x0 = guess.unwrap_or_else(|| first_order_guess(map, y));
    newton(map, y, x0, options.tolerance_for(y), options.max_iterations)
}

/// The damped Newton iteration of [`invert_point`] from the start `x0` with an absolute
/// residual `tolerance` (physical units), for callers that choose their own starts and
/// tolerance (grid walkers). A non-finite `y` or `x0` gives [`InverseStatus::NonFinite`].
#[must_use]
pub fn newton<M: SpaceMap + ?Sized>(
    map: &M,
    y: DVec3,
    x0: DVec3,
    tolerance: f64,
    max_iterations: u32,
) -> PointInverse {
    if !x0.is_finite() || !y.is_finite() {
        return PointInverse::non_finite(x0);
    }
    let mut x = x0;
    let (mut f, mut jac) = map.apply_with_jacobian(x);
    let mut rn = (y - f).length();
    let mut iterations = 0;
    let status = loop {
        if !rn.is_finite() || !jac.is_finite() {
            return PointInverse {
                point: x,
                residual: rn,
                iterations,
                status: InverseStatus::NonFinite,
                det_jacobian: f64::NAN,
                jacobian: DMat3::NAN,
            };
        }
        if rn <= tolerance {
            break InverseStatus::Converged;
        }
        if iterations >= max_iterations {
            break InverseStatus::NotConverged;
        }
        let Some(lu) = Lu3::factor(jac).filter(|lu| lu.condition() <= MAX_CONDITION) else {
            break InverseStatus::SingularJacobian;
        };
        let delta = lu.solve(y - f);
        if !delta.is_finite() {
            break InverseStatus::SingularJacobian;
        }
        // Backtracking: the first step length that reduces the residual enough.
        let mut alpha = 1.0;
        let mut accepted = None;
        for _ in 0..=MAX_HALVINGS {
            let xt = x + alpha * delta;
            let (ft, jt) = map.apply_with_jacobian(xt);
            let rt = (y - ft).length();
            if rt <= (1.0 - ARMIJO * alpha) * rn {
                accepted = Some((xt, ft, jt, rt));
                break;
            }
            alpha *= 0.5;
        }
        let Some((xt, ft, jt, rt)) = accepted else {
            break InverseStatus::NotConverged;
        };
        (x, f, jac, rn) = (xt, ft, jt, rt);
        iterations += 1;
    };
    PointInverse {
        point: x,
        residual: rn,
        iterations,
        status,
        det_jacobian: jac.determinant(),
        jacobian: jac,
    }
}

/// LU factorisation with partial pivoting of a 3×3 matrix, `P·A = L·U`, for solving Newton
/// systems and estimating their conditioning.
///
/// ```
/// use glam::{DMat3, DVec3};
/// use volmorph_deform::inverse::Lu3;
/// let a = DMat3::from_cols(DVec3::new(0.0, 2.0, 1.0), DVec3::new(1.0, 0.0, 0.0), DVec3::Z);
/// let lu = Lu3::factor(a).unwrap();
/// let b = DVec3::new(1.0, 2.0, 3.0);
/// assert!((a * lu.solve(b) - b).length() < 1e-15);
/// assert!(Lu3::factor(DMat3::from_cols(DVec3::X, DVec3::X, DVec3::Z)).is_none());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lu3 {
    /// Row-major packed factors: `U` on and above the diagonal, `L` (unit diagonal) below.
    lu: [[f64; 3]; 3],
    /// Row of `A` that became row `r` of the factors.
    perm: [usize; 3],
    /// `‖A‖₁` (largest column sum of magnitudes).
    norm1: f64,
}

impl Lu3 {
    /// Factor `a` (glam's column-major `DMat3`: `a.col(c)[r]` is row `r`, column `c`).
    /// `None` if a pivot is exactly zero or an entry is not finite.
    #[must_use]
    pub fn factor(a: DMat3) -> Option<Self> {
        if !a.is_finite() {
            return None;
        }
        let mut m = [[0.0; 3]; 3];
        for (r, row) in m.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = a.col(c)[r];
            }
        }
        let norm1 = (0..3)
            .map(|c| m.iter().map(|row| row[c].abs()).sum::<f64>())
            .fold(0.0, f64::max);
        let mut perm = [0, 1, 2];
        for k in 0..3 {
            let p = (k..3).fold(k, |best, r| {
                if m[r][k].abs() > m[best][k].abs() {
                    r
                } else {
                    best
                }
            });
            if m[p][k] == 0.0 {
                return None;
            }
            m.swap(k, p);
            perm.swap(k, p);
            let pivot_row = m[k];
            for row in &mut m[k + 1..] {
                let l = row[k] / pivot_row[k];
                row[k] = l;
                for (v, &p) in row[k + 1..].iter_mut().zip(&pivot_row[k + 1..]) {
                    *v -= l * p;
                }
            }
        }
        Some(Self { lu: m, perm, norm1 })
    }

    /// The solution `x` of `A·x = b`.
    #[must_use]
    pub fn solve(&self, b: DVec3) -> DVec3 {
        let m = &self.lu;
        let mut x = [b[self.perm[0]], b[self.perm[1]], b[self.perm[2]]];
        for r in 1..3 {
            for c in 0..r {
                x[r] -= m[r][c] * x[c];
            }
        }
        for r in (0..3).rev() {
            for c in r + 1..3 {
                x[r] -= m[r][c] * x[c];
            }
            x[r] /= m[r][r];
        }
        DVec3::from_array(x)
    }

    /// `A⁻¹`, column by column.
    #[must_use]
    pub fn inverse(&self) -> DMat3 {
        DMat3::from_cols(
            self.solve(DVec3::X),
            self.solve(DVec3::Y),
            self.solve(DVec3::Z),
        )
    }

    /// The 1-norm condition number `‖A‖₁·‖A⁻¹‖₁` (exact, from the explicit inverse; `∞` when
    /// the inverse overflows).
    #[must_use]
    pub fn condition(&self) -> f64 {
        let inv = self.inverse();
        let inv_norm = [inv.x_axis, inv.y_axis, inv.z_axis]
            .iter()
            .map(|c| c.abs().element_sum())
            .fold(0.0, f64::max);
        let k = self.norm1 * inv_norm;
        if k.is_nan() { f64::INFINITY } else { k }
    }

    /// `det A`.
    #[must_use]
    pub fn determinant(&self) -> f64 {
        let m = &self.lu;
        let swaps = usize::from(self.perm[0] != 0)
            + usize::from(self.perm[1] != 1)
            + usize::from(self.perm[2] != 2);
        // Two misplaced rows are one transposition, three a 3-cycle (two transpositions).
        let sign = if swaps == 2 { -1.0 } else { 1.0 };
        sign * m[0][0] * m[1][1] * m[2][2]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Affine, Identity};

    #[test]
    fn lu_solves_inverts_and_measures_condition() {
        let a = DMat3::from_cols(
            DVec3::new(1e-3, 4.0, -2.0),
            DVec3::new(3.0, 1.0, 0.5),
            DVec3::new(-1.0, 2.0, 7.0),
        );
        let lu = Lu3::factor(a).unwrap();
        let b = DVec3::new(0.3, -1.0, 2.5);
        assert!((a * lu.solve(b) - b).length() < 1e-14);
        assert!((lu.inverse() * a).abs_diff_eq(DMat3::IDENTITY, 1e-14));
        assert!((lu.determinant() - a.determinant()).abs() < 1e-12 * a.determinant().abs());
        // Every permutation pattern gives the right determinant sign.
        for (p, q, r) in [
            (0, 1, 2),
            (0, 2, 1),
            (1, 0, 2),
            (1, 2, 0),
            (2, 0, 1),
            (2, 1, 0),
        ] {
            let rows = [DVec3::X, DVec3::Y, DVec3::Z];
            let scale = DVec3::new(5.0, 3.0, 2.0);
            let m = DMat3::from_cols(rows[p] * scale.x, rows[q] * scale.y, rows[r] * scale.z)
                .transpose();
            let lu = Lu3::factor(m).unwrap();
            assert!((lu.determinant() - m.determinant()).abs() < 1e-12, "{m:?}");
        }
        // Condition of a diagonal matrix is the ratio of extreme entries.
        let d = Lu3::factor(DMat3::from_diagonal(DVec3::new(1e-4, 1.0, 10.0))).unwrap();
        assert!((d.condition() - 1e5).abs() < 1e-6);
        // Singular and non-finite matrices are refused; nearly singular ones are ill conditioned.
        assert!(Lu3::factor(DMat3::ZERO).is_none());
        assert!(Lu3::factor(DMat3::from_diagonal(DVec3::new(1.0, f64::NAN, 1.0))).is_none());
        let near = DMat3::from_cols(DVec3::X, DVec3::new(1.0, 1e-14, 0.0), DVec3::Z);
        assert!(Lu3::factor(near).unwrap().condition() > MAX_CONDITION);
    }

    #[test]
    fn identity_and_affine_invert_exactly() {
        let y = DVec3::new(1.5, -2.0, 30.0);
        let r = invert_point(&Identity, y, None, &InverseOptions::default());
        assert_eq!(r.status, InverseStatus::Converged);
        assert_eq!(r.point, y);
        assert_eq!(r.iterations, 0);
        assert_eq!(r.det_jacobian, 1.0);
        // A translation is inverted exactly by the first-order guess.
        let t = Affine::translation(DVec3::new(0.25, 4.0, -8.0));
        let r = invert_point(&t, y, None, &InverseOptions::default());
        assert_eq!(r.point, y - t.offset);
        assert_eq!(r.iterations, 0);
        // A general affine map takes one Newton step.
        let a = Affine {
            matrix: DMat3::from_cols(
                DVec3::new(1.2, 0.3, -0.1),
                DVec3::new(-0.4, 0.9, 0.2),
                DVec3::new(0.1, 0.5, 1.7),
            ),
            offset: DVec3::new(3.0, -1.0, 2.0),
        };
        let r = invert_point(&a, y, None, &InverseOptions::default());
        assert!(r.converged());
        assert_eq!(r.iterations, 1);
        let exact = a.matrix.inverse() * (y - a.offset);
        assert!((r.point - exact).length() < 1e-13 * exact.length());
        assert!((r.det_jacobian - a.matrix.determinant()).abs() < 1e-14);
    }

    /// `x ↦ (x³ + x, y, z)` along x: strictly monotone but strongly non-linear.
    struct Cubic;
    impl SpaceMap for Cubic {
        fn apply(&self, p: DVec3) -> DVec3 {
            DVec3::new(p.x * p.x * p.x + p.x, p.y, p.z)
        }
        fn jacobian(&self, p: DVec3) -> DMat3 {
            DMat3::from_diagonal(DVec3::new(3.0 * p.x * p.x + 1.0, 1.0, 1.0))
        }
    }

    /// `x ↦ (x², y, z)`: targets with negative x have no preimage; the Jacobian vanishes at
    /// `x = 0`.
    struct Square;
    impl SpaceMap for Square {
        fn apply(&self, p: DVec3) -> DVec3 {
            DVec3::new(p.x * p.x, p.y, p.z)
        }
        fn jacobian(&self, p: DVec3) -> DMat3 {
            DMat3::from_diagonal(DVec3::new(2.0 * p.x, 1.0, 1.0))
        }
    }

    #[test]
    fn damped_newton_converges_from_far_and_reports_failures() {
        // From far away the undamped Newton step for x³ + x overshoots; damping keeps it sane.
        let y = DVec3::new(1000.0, 1.0, 2.0);
        let r = invert_point(
            &Cubic,
            y,
            Some(DVec3::new(-50.0, 0.0, 0.0)),
            &InverseOptions::default(),
        );
        assert!(r.converged(), "{r:?}");
        assert!((Cubic.apply(r.point) - y).length() <= 1e-9);
        assert!((r.point.x - 9.966_666_2).abs() < 1e-6, "{r:?}");
        // x² = −1 has no real solution: never reported as converged.
        let r = invert_point(
            &Square,
            DVec3::new(-1.0, 0.0, 0.0),
            None,
            &InverseOptions::default(),
        );
        assert!(!r.converged(), "{r:?}");
        assert!(r.residual >= 1.0 - 1e-9, "{r:?}");
        // Starting exactly on the fold: singular Jacobian.
        let r = invert_point(
            &Square,
            DVec3::new(4.0, 0.0, 0.0),
            Some(DVec3::ZERO),
            &InverseOptions::default(),
        );
        assert_eq!(r.status, InverseStatus::SingularJacobian);
        // Two preimages ±2: Newton finds the one on the side of the guess, det J says which.
        let opts = InverseOptions::default();
        let pos = invert_point(&Square, DVec3::new(4.0, 0.0, 0.0), Some(DVec3::X), &opts);
        let neg = invert_point(&Square, DVec3::new(4.0, 0.0, 0.0), Some(-DVec3::X), &opts);
        assert!((pos.point.x - 2.0).abs() < 1e-12 && pos.det_jacobian > 0.0);
        assert!((neg.point.x + 2.0).abs() < 1e-12 && neg.det_jacobian < 0.0);
        // The iteration limit is honoured.
        let r = invert_point(&Cubic, y, Some(DVec3::ZERO), &opts.with_max_iterations(2));
        assert_eq!((r.status, r.iterations), (InverseStatus::NotConverged, 2));
    }

    #[test]
    fn non_finite_input_gives_a_status() {
        let opts = InverseOptions::default();
        for y in [
            DVec3::new(f64::NAN, 0.0, 0.0),
            DVec3::new(0.0, f64::INFINITY, 1.0),
        ] {
            let r = invert_point(&Cubic, y, None, &opts);
            assert_eq!(r.status, InverseStatus::NonFinite);
        }
        let r = invert_point(&Cubic, DVec3::ONE, Some(DVec3::splat(f64::NAN)), &opts);
        assert_eq!(r.status, InverseStatus::NonFinite);
        // A map that overflows along the way.
        let r = invert_point(&Cubic, DVec3::ONE, Some(DVec3::splat(1e200)), &opts);
        assert_eq!(r.status, InverseStatus::NonFinite);
        // A NaN tolerance counts as 0: only exact solutions converge.
        assert_eq!(
            InverseOptions::default()
                .with_tolerance(f64::NAN)
                .tolerance_for(DVec3::ONE),
            0.0
        );
    }
}

/// The numerical inverse of a map as a map: `Inverse(φ).apply(y) = φ⁻¹(y)` by
/// [`invert_point`] (damped Newton from the first-order guess).
///
/// Where no preimage is found (the iteration does not converge: `y` outside the image of `φ`,
/// or at a fold) the result is NaN in every component, so a warp through it treats the point
/// as unmapped instead of showing a wrong one. The Jacobian is `Dφ(x)⁻¹` at the preimage `x`
/// (NaN where `Dφ` is singular or no preimage was found).
///
/// ```
/// use glam::{DMat3, DVec3};
/// use volmorph_deform::inverse::Inverse;
/// use volmorph_deform::{Affine, InverseOptions, SpaceMap};
/// let a = Affine { matrix: DMat3::from_diagonal(DVec3::new(2.0, 1.0, 0.5)), offset: DVec3::X };
/// let inv = Inverse::new(a, InverseOptions::default());
/// let y = DVec3::new(3.0, 2.0, 1.0);
/// assert!((a.apply(inv.apply(y)) - y).length() < 1e-12);
/// assert!((inv.jacobian(y) - a.matrix.inverse()).abs_diff_eq(DMat3::ZERO, 1e-12));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Inverse<M> {
    map: M,
    options: InverseOptions,
}

impl<M: SpaceMap> Inverse<M> {
    /// The inverse of `map`, solved with `options`.
    pub fn new(map: M, options: InverseOptions) -> Self {
        Self { map, options }
    }

    /// The map being inverted.
    pub fn map(&self) -> &M {
        &self.map
    }

    /// The Newton options.
    pub fn options(&self) -> &InverseOptions {
        &self.options
    }

    /// The preimage of `y`, `None` if the iteration did not converge.
    fn preimage(&self, y: DVec3) -> Option<DVec3> {
        let r = invert_point(&self.map, y, None, &self.options);
        (r.status == InverseStatus::Converged).then_some(r.point)
    }
}

impl<M: SpaceMap> SpaceMap for Inverse<M> {
    fn apply(&self, y: DVec3) -> DVec3 {
        self.preimage(y).unwrap_or(DVec3::NAN)
    }

    fn jacobian(&self, y: DVec3) -> DMat3 {
        self.apply_with_jacobian(y).1
    }

    fn apply_with_jacobian(&self, y: DVec3) -> (DVec3, DMat3) {
        let nan = DMat3::from_cols(DVec3::NAN, DVec3::NAN, DVec3::NAN);
        let Some(x) = self.preimage(y) else {
            return (DVec3::NAN, nan);
        };
        let j = self.map.jacobian(x);
        if j.determinant() == 0.0 {
            return (x, nan);
        }
        (x, j.inverse())
    }
}
