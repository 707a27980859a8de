//! Moving-least-squares deformations of 3D space through point handles (Schaefer, McPhail &
//! Warren; McPhail's thesis §4.3 and §5.4.2) and through coordinate frames (§5.4.3).
//!
//! # The maps
//!
//! Source handles `p_i` are moved to targets `q_i`. For a point `v` every handle gets a weight
//! `w_i(v)` ([`Weighting`]); with the weighted centroids `p* = Σ w_i p_i / Σ w_i`,
//! `q* = Σ w_i q_i / Σ w_i` and `p̂_i = p_i − p*`, `q̂_i = q_i − q*`, the map is
//!
//! ```text
//! f(v) = q* + L_v (v − p*),   L_v = argmin_L Σ_i w_i |L p̂_i − q̂_i|²
//! ```
//!
//! over a class of linear maps `L`:
//!
//! * [`AffineMls`] — any 3×3 matrix: `L = (Σ w q̂ p̂ᵀ)(Σ w p̂ p̂ᵀ)⁻¹`. `f` is *affine in the
//!   targets*, `f(v) = Σ_j α_j(v) q_j` (§5.4.2), which [`volmorph_deform::LiveGrid`] exploits.
//! * [`SimilarityMls`] — `L = sR` (rotation times a uniform scale). In 3D this is not a
//!   quadratic problem (thesis §4.6); the rotation is the one of the rigid problem (Theorem 4.1
//!   holds in any dimension) and is found with Horn's closed form: the unit quaternion is the
//!   eigenvector of the largest eigenvalue `λ_max` of the symmetric 4×4 matrix built from
//!   `M = Σ w p̂ q̂ᵀ`; then `s = λ_max / Σ w |p̂|²`.
//! * [`RigidMls`] — the same rotation with `s = 1`.
//!
//! [`FrameMls`] (§5.4.3) uses frames — an origin and three axis vectors — as handles and adds
//! `β Σ_i w_i Σ_a |L f_ia − g_ia|²` (source axes `f_ia`, target axes `g_ia`) to the affine
//! functional. The thesis leaves the frame term unweighted; here it is weighted by `w_i` like the
//! point term, which keeps each frame's influence local (`β = 0` gives affine MLS). Near a frame
//! the Jacobian tends to `G_i F_i⁻¹`, the linear map taking its source axes to its target axes.
//!
//! # Properties (tested)
//!
//! With inverse-distance weights the maps interpolate, `f(p_i) = q_i`; targets equal to the
//! sources give the identity; handles moved by one global affine map (affine MLS), similarity
//! (similarity MLS) or rigid motion (rigid MLS) are followed exactly everywhere. Gaussian
//! weights are bounded and only approximate the handles.
//!
//! # Degenerate points
//!
//! Weights are scaled so the largest is 1 (the maps are invariant under a common factor), so
//! nothing overflows far from or close to the handles; at a source handle exactly, `f` is its
//! target. Where the weighted handles do not determine `L` (the weight mass on three coplanar
//! handles or fewer, e.g. Gaussian weights far from all handles), the linear part falls back to
//! the identity: `f(v) = v + q* − p*`. See [`DEGENERATE_MOMENT`].
//!
//! # Jacobians
//!
//! All four maps have closed-form Jacobians (`∂_k` = `∂/∂v_k`). The weights give
//! `∇w_i = γ_i (v − p_i)` (`γ_i = −2α w_i/|v − p_i|²` or `−w_i/σ²`); the centroids
//! `∂_k p* = Σ ∂_k w_i p̂_i / W` (same for `q*`); and, since `Σ w_i p̂_i = 0`, the moment matrices
//! differentiate as if the centroids were fixed: `∂_k P = Σ ∂_k w_i p̂_i p̂_iᵀ`,
//! `∂_k C = Σ ∂_k w_i q̂_i p̂_iᵀ`. With `u = v − p*`, column `k` of the Jacobian is
//!
//! ```text
//! ∂_k f = ∂_k q* + L (e_k − ∂_k p*) + (∂_k L) u
//! ```
//!
//! * affine and frame MLS: `∂_k L = (∂_k C − L ∂_k P) P⁻¹` (for frames `P`, `C` include the
//!   `β w F Fᵀ`, `β w G Fᵀ` terms, which differentiate the same way);
//! * rigid and similarity MLS: `R` is the rotation polar factor of `C = R H` (`H` symmetric;
//!   this is Horn's maximiser of `tr(Rᵀ C)`). Writing `∂_k R = R [ω_k]×` and differentiating
//!   `C = R H` gives `Rᵀ ∂_k C − ∂_k Cᵀ R = [ω]× H + H [ω]× = [(tr H·I − H) ω]×`, so
//!   `ω_k = (tr H·I − H)⁻¹ axial(Rᵀ ∂_k C − ∂_k Cᵀ R)`. The scale `s = λ/tr P` with
//!   `λ = tr(Rᵀ C)` has `∂_k λ = tr(Rᵀ ∂_k C)` (the rotation's own variation is stationary), so
//!   `∂_k s = (∂_k λ − s tr ∂_k P)/tr P` and `∂_k L = ∂_k s R + s R [ω_k]×`.
//!   `tr H·I − H` is singular exactly where the optimal rotation is not unique
//!   ([`ROTATION_GAP`]); there, and at a handle itself, central differences are used.
//!
//! Every map here is a push-forward from source to target space; for a pull-back showing the
//! sources at the targets build it with the two handle sets swapped.

use glam::{DMat3, DQuat, DVec3};

use volmorph_deform::LinearMap;
use volmorph_deform::{DeformError, SpaceMap};

/// A weighted second-moment matrix `P = Σ w p̂ p̂ᵀ` whose determinant is at most this times
/// `(tr P / 3)³` (its value for an isotropic spread) is treated as singular: its smallest
/// principal spread is then ≲ 1e-4 of the mean (for the determinant ratio 1e-12), and the
/// affine fit would amplify target noise by 1e4 or more.
pub const DEGENERATE_MOMENT: f64 = 1e-12;

/// Two source handles closer than this (relative to the handle set's radius) coincide.
pub const MIN_HANDLE_SEPARATION: f64 = 1e-10;

/// How the handles are weighted at a point `v`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Weighting {
    /// `w_i = 1 / |p_i − v|^(2α)` (the thesis' weights; `α > 0`). Interpolating; smooth
    /// except at the handles for `α ≤ 1`. `α = 1` is the usual choice.
    InverseDistance {
        /// Exponent `α > 0`.
        alpha: f64,
    },
    /// `w_i = exp(−|p_i − v|² / (2σ²))` (`σ > 0`, physical length). Bounded, so the map only
    /// approximates its handles (the closer, the larger the spacing of the handles relative
    /// to `σ`).
    Gaussian {
        /// Width `σ > 0`.
        sigma: f64,
    },
}

impl Default for Weighting {
    /// Inverse distance with `α = 1`.
    fn default() -> Self {
        Self::InverseDistance { alpha: 1.0 }
    }
}

impl Weighting {
    /// Check the parameter.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for `α ≤ 0`, `σ ≤ 0` or a non-finite parameter.
    pub fn validate(&self) -> Result<(), DeformError> {
        let (name, v) = match *self {
            Self::InverseDistance { alpha } => ("inverse-distance exponent α", alpha),
            Self::Gaussian { sigma } => ("Gaussian width σ", sigma),
        };
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(DeformError::InvalidHandles(format!(
                "{name} must be finite and > 0, got {v}"
            )))
        }
    }

    /// The weight of a handle at squared distance `d2`, relative to one at the smallest squared
    /// distance `d2min` (> 0 for inverse distance), so the largest weight is 1.
    #[inline]
    pub(crate) fn relative(&self, d2: f64, d2min: f64) -> f64 {
        match *self {
            Self::InverseDistance { alpha } => {
                let r = d2min / d2;
                if alpha == 1.0 { r } else { r.powf(alpha) }
            }
            Self::Gaussian { sigma } => (-(d2 - d2min) / (2.0 * sigma * sigma)).exp(),
        }
    }

    /// `γ` with `∇_v w = γ·(v − p)` for a weight `w` at squared distance `d2`.
    #[inline]
    fn gradient_factor(&self, w: f64, d2: f64) -> f64 {
        match *self {
            Self::InverseDistance { alpha } => -2.0 * alpha * w / d2,
            Self::Gaussian { sigma } => -w / (sigma * sigma),
        }
    }
}

/// Where a point stands relative to the source handles.
pub(crate) enum Nearest {
    /// Exactly on source handle `i` (inverse-distance weights): `f(v) = q_i`.
    AtHandle(usize),
    /// Smallest squared distance to a handle, and that handle.
    Distance(f64, usize),
}

/// The smallest squared distance from `v` to a source, or the handle `v` sits on.
#[inline]
pub(crate) fn nearest(weighting: &Weighting, sources: &[DVec3], v: DVec3) -> Nearest {
    let mut best = f64::INFINITY;
    let mut at = 0;
    for (i, p) in sources.iter().enumerate() {
        let d2 = (*p - v).length_squared();
        if d2 < best {
            best = d2;
            at = i;
        }
    }
    match weighting {
        Weighting::InverseDistance { .. } if best == 0.0 => Nearest::AtHandle(at),
        _ => Nearest::Distance(best, at),
    }
}

/// Validate a source/target handle pair list: equal lengths, finite, at least `min` handles,
/// no two coincident sources.
pub(crate) fn check_handles(
    sources: &[DVec3],
    targets: &[DVec3],
    min: usize,
    what: &str,
) -> Result<(), DeformError> {
    if sources.len() != targets.len() {
        return Err(DeformError::InvalidHandles(format!(
            "{} source handles but {} targets",
            sources.len(),
            targets.len()
        )));
    }
    if sources.len() < min {
        return Err(DeformError::InvalidHandles(format!(
            "{what} needs at least {min} handles, got {}",
            sources.len()
        )));
    }
    volmorph_deform::map::check_finite("source handle", sources)?;
    volmorph_deform::map::check_finite("target handle", targets)?;
    let c = sources.iter().copied().sum::<DVec3>() / sources.len() as f64;
    let radius = sources
        .iter()
        .map(|p| (*p - c).length())
        .fold(0.0f64, f64::max);
    let tol = MIN_HANDLE_SEPARATION * radius.max(f64::MIN_POSITIVE);
    let mut order: Vec<usize> = (0..sources.len()).collect();
    order.sort_by(|&a, &b| sources[a].x.total_cmp(&sources[b].x));
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if sources[j].x - sources[i].x > tol {
                break;
            }
            if (sources[j] - sources[i]).length() <= tol {
                return Err(DeformError::InvalidHandles(format!(
                    "source handles {} and {} coincide",
                    i.min(j),
                    i.max(j)
                )));
            }
        }
    }
    Ok(())
}

/// Smallest and largest eigenvalue ratio test of a symmetric positive semi-definite 3×3
/// matrix: `det ≤ DEGENERATE_MOMENT·(tr/3)³` or a zero trace.
#[inline]
fn is_degenerate(m: &DMat3) -> bool {
    let tr = m.x_axis.x + m.y_axis.y + m.z_axis.z;
    let t = tr / 3.0;
    tr.is_nan() || tr <= 0.0 || m.determinant() <= DEGENERATE_MOMENT * t * t * t
}

/// Check that the sources span 3D space (not all on one plane): the unweighted moment matrix
/// about their centroid must not be degenerate.
fn check_spread(sources: &[DVec3], needs: &str) -> Result<(), DeformError> {
    let c = sources.iter().copied().sum::<DVec3>() / sources.len() as f64;
    let mut m = DMat3::ZERO;
    for p in sources {
        let d = *p - c;
        m += outer(d, d);
    }
    let tr = m.x_axis.x + m.y_axis.y + m.z_axis.z;
    let degenerate = match needs {
        "plane" => is_degenerate(&m),
        _ => {
            // Collinear: the second-largest eigenvalue vanishes; tr(M)² − tr(M²) is twice the
            // sum of the pairwise eigenvalue products.
            let m2 = m * m;
            let tr2 = m2.x_axis.x + m2.y_axis.y + m2.z_axis.z;
            tr.is_nan() || tr <= 0.0 || (tr * tr - tr2) <= 2.0 * DEGENERATE_MOMENT.sqrt() * tr * tr
        }
    };
    if degenerate {
        Err(DeformError::InvalidHandles(format!(
            "the {} source handles lie on one {needs}; the map is not determined",
            sources.len()
        )))
    } else {
        Ok(())
    }
}

/// `a bᵀ`.
#[inline]
pub(crate) fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// Weighted moments of the handles, accumulated about the source handle nearest to `v` and
/// its target (`po`, `qo`).
struct Moments {
    /// Σ w.
    w: f64,
    /// Source origin `p_near`.
    po: DVec3,
    /// Target origin `q_near`.
    qo: DVec3,
    /// p* − po.
    pc: DVec3,
    /// q* − qo.
    qc: DVec3,
    /// Σ w p̂ p̂ᵀ.
    pp: DMat3,
    /// Σ w q̂ p̂ᵀ.
    qp: DMat3,
}

impl Moments {
    /// `p*`.
    #[inline]
    fn p_star(&self) -> DVec3 {
        self.po + self.pc
    }

    /// `q*`.
    #[inline]
    fn q_star(&self) -> DVec3 {
        self.qo + self.qc
    }

    /// `v − p*`, formed without cancellation near the handles.
    #[inline]
    fn u(&self, v: DVec3) -> DVec3 {
        (v - self.po) - self.pc
    }
}

/// One pass over the handles accumulating weights and moments. The raw sums are taken about
/// the nearest source handle `near` (and its target): its term, the largest weight, vanishes
/// from the second moments, so the central moments `raw − W·c cᵀ` do not cancel
/// catastrophically even a hair's breadth from a handle, where the weights of all others are
/// ~1e-12 of it.
#[inline]
fn moments(
    weighting: &Weighting,
    sources: &[DVec3],
    targets: &[DVec3],
    v: DVec3,
    d2min: f64,
    near: usize,
) -> Moments {
    let po = sources.get(near).copied().unwrap_or(v);
    let qo = targets.get(near).copied().unwrap_or(v);
    let mut w = 0.0;
    let mut sp = DVec3::ZERO;
    let mut sq = DVec3::ZERO;
    let mut pp = DMat3::ZERO;
    let mut qp = DMat3::ZERO;
    for (p, q) in sources.iter().zip(targets) {
        let wi = weighting.relative((*p - v).length_squared(), d2min);
        let a = *p - po;
        let b = *q - qo;
        w += wi;
        sp += wi * a;
        sq += wi * b;
        let wa = wi * a;
        pp += outer(wa, a);
        qp += outer(b, wa);
    }
    let pc = sp / w;
    let qc = sq / w;
    Moments {
        w,
        po,
        qo,
        pc,
        qc,
        pp: pp - w * outer(pc, pc),
        qp: qp - w * outer(qc, pc),
    }
}

/// Affine moving-least-squares deformation through point handles (§4.3.1, §5.4.2); see the
/// [module docs](self). Needs at least four source handles not on one plane.
#[derive(Debug, Clone, PartialEq)]
pub struct AffineMls {
    weighting: Weighting,
    sources: Vec<DVec3>,
    targets: Vec<DVec3>,
}

impl AffineMls {
    /// Build from source handles, targets (same length) and a weighting.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for mismatched lengths, fewer than 4 handles, coincident
    /// sources, sources on one plane or a bad weighting parameter; [`DeformError::NonFinite`]
    /// for NaN/infinite coordinates.
    pub fn new(
        sources: &[DVec3],
        targets: &[DVec3],
        weighting: Weighting,
    ) -> Result<Self, DeformError> {
        weighting.validate()?;
        check_handles(sources, targets, 4, "affine MLS")?;
        check_spread(sources, "plane")?;
        Ok(Self {
            weighting,
            sources: sources.to_vec(),
            targets: targets.to_vec(),
        })
    }

    /// Source handles.
    #[must_use]
    pub fn sources(&self) -> &[DVec3] {
        &self.sources
    }

    /// Target handles.
    #[must_use]
    pub fn targets(&self) -> &[DVec3] {
        &self.targets
    }

    /// The weighting.
    #[must_use]
    pub fn weighting(&self) -> Weighting {
        self.weighting
    }

    /// Replace the targets.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for a wrong length, [`DeformError::NonFinite`] for NaN.
    pub fn set_targets(&mut self, targets: &[DVec3]) -> Result<(), DeformError> {
        set_targets(&mut self.targets, targets)
    }

    /// The coefficients `α_j(v)` of `f(v) = Σ_j α_j(v) q_j` (§5.4.2), written to
    /// `out[..N]` (only `min(out.len(), N)` are written). They sum to 1 and do not depend on
    /// the targets. Where the linear part falls back to the identity (see the
    /// [module docs](self)) `f(v) = v − p* + Σ_j (w_j/W) q_j` and the centroid weights are
    /// written.
    pub fn coefficients(&self, v: DVec3, out: &mut [f64]) {
        self.coefficients_into(v, out);
    }
}

pub(crate) fn set_targets(dst: &mut [DVec3], targets: &[DVec3]) -> Result<(), DeformError> {
    if targets.len() != dst.len() {
        return Err(DeformError::InvalidHandles(format!(
            "{} targets for {} handles",
            targets.len(),
            dst.len()
        )));
    }
    volmorph_deform::map::check_finite("target handle", targets)?;
    dst.copy_from_slice(targets);
    Ok(())
}

/// Parameters: the target handles `q_j`, in the order given (`f(v) = Σ_j α_j(v) q_j`, base 0
/// except in the degenerate fallback).
impl LinearMap for AffineMls {
    fn parameter_count(&self) -> usize {
        self.targets.len()
    }

    fn parameters(&self) -> Vec<DVec3> {
        self.targets.clone()
    }

    fn set_parameters(&mut self, targets: &[DVec3]) -> Result<(), DeformError> {
        self.set_targets(targets)
    }

    fn dense_coefficients_are_cheap(&self) -> bool {
        true
    }

    fn same_structure(&self, other: &Self) -> bool {
        self.sources == other.sources && self.weighting == other.weighting
    }

    fn coefficients_into(&self, v: DVec3, out: &mut [f64]) -> DVec3 {
        let n = self.sources.len();
        if out.len() < n {
            // Short buffer: compute all, write what fits (not a hot path).
            let mut all = vec![0.0; n];
            let b = self.coefficients_into(v, &mut all);
            let m = out.len();
            out.copy_from_slice(&all[..m]);
            return b;
        }
        let out = &mut out[..n];
        let d2min = match nearest(&self.weighting, &self.sources, v) {
            Nearest::AtHandle(i) => {
                out.fill(0.0);
                if let Some(o) = out.get_mut(i) {
                    *o = 1.0;
                }
                return DVec3::ZERO;
            }
            Nearest::Distance(d, _) => d,
        };
        // Pass 1: weights (kept in `out`) and moments about v.
        let mut w = 0.0;
        let mut sp = DVec3::ZERO;
        let mut pp = DMat3::ZERO;
        for (p, o) in self.sources.iter().zip(out.iter_mut()) {
            let a = *p - v;
            let wi = self.weighting.relative(a.length_squared(), d2min);
            *o = wi;
            w += wi;
            sp += wi * a;
            pp += outer(wi * a, a);
        }
        let pcv = sp / w;
        let pp = pp - w * outer(pcv, pcv);
        let inv_w = 1.0 / w;
        if is_degenerate(&pp) {
            for o in out.iter_mut() {
                *o *= inv_w;
            }
            return -pcv; // v − p*
        }
        let z = pp.inverse() * (-pcv);
        // Pass 2: α_j = w_j (1/W + (p_j − p*)·z), with p_j − p* = (p_j − v) − (p* − v).
        let zc = inv_w - pcv.dot(z);
        for (p, o) in self.sources.iter().zip(out.iter_mut()) {
            *o *= zc + (*p - v).dot(z);
        }
        DVec3::ZERO
    }
}

impl SpaceMap for AffineMls {
    fn apply(&self, v: DVec3) -> DVec3 {
        let (d2min, near) = match nearest(&self.weighting, &self.sources, v) {
            Nearest::AtHandle(i) => return self.targets[i],
            Nearest::Distance(d, i) => (d, i),
        };
        let m = moments(
            &self.weighting,
            &self.sources,
            &self.targets,
            v,
            d2min,
            near,
        );
        if is_degenerate(&m.pp) {
            return v + (m.q_star() - m.p_star());
        }
        // f = q* + L (v − p*), L = qp · pp⁻¹; with centroids relative to v, v − p* = −pc.
        m.q_star() + m.qp * (m.pp.inverse() * m.u(v))
    }

    fn jacobian(&self, v: DVec3) -> DMat3 {
        self.apply_with_jacobian(v).1
    }

    fn apply_with_jacobian(&self, v: DVec3) -> (DVec3, DMat3) {
        let (d2min, near) = match nearest(&self.weighting, &self.sources, v) {
            Nearest::AtHandle(i) => {
                return (
                    self.targets[i],
                    volmorph_deform::map::central_jacobian(self, v),
                );
            }
            Nearest::Distance(d, i) => (d, i),
        };
        let m = moments(
            &self.weighting,
            &self.sources,
            &self.targets,
            v,
            d2min,
            near,
        );
        if is_degenerate(&m.pp) {
            // Identity linear part; the centroids still move with v.
            let (dp, dq) = centroid_derivatives(self, v, d2min, &m);
            return (v + (m.q_star() - m.p_star()), DMat3::IDENTITY + dq - dp);
        }
        let pinv = m.pp.inverse();
        let l = m.qp * pinv;
        let u = m.u(v); // v − p*
        // Second pass: derivatives of the weights, g_i = γ_i (v − p_i).
        let mut dpp = [DMat3::ZERO; 3];
        let mut dqp = [DMat3::ZERO; 3];
        let mut dp = DMat3::ZERO; // column k: Σ g_ik p̂_i
        let mut dq = DMat3::ZERO;
        for (p, q) in self.sources.iter().zip(&self.targets) {
            let a = *p - v;
            let d2 = a.length_squared();
            let wi = self.weighting.relative(d2, d2min);
            let g = self.weighting.gradient_factor(wi, d2) * (-a); // ∇w_i
            let ph = (*p - m.po) - m.pc;
            let qh = (*q - m.qo) - m.qc;
            let pph = outer(ph, ph);
            let qph = outer(qh, ph);
            for k in 0..3 {
                dpp[k] += g[k] * pph;
                dqp[k] += g[k] * qph;
            }
            dp += outer(ph, g);
            dq += outer(qh, g);
        }
        let inv_w = 1.0 / m.w;
        dp *= inv_w;
        dq *= inv_w;
        let mut cols = [DVec3::ZERO; 3];
        for (k, col) in cols.iter_mut().enumerate() {
            let e = DVec3::AXES[k];
            let dl = dqp[k] * pinv - l * dpp[k] * pinv;
            *col = dq.col(k) + l * (e - dp.col(k)) + dl * u;
        }
        // Same expression as `apply`, so both agree to the last bit.
        (
            m.q_star() + m.qp * (pinv * u),
            DMat3::from_cols(cols[0], cols[1], cols[2]),
        )
    }
}

/// Derivatives of the centroids `p*`, `q*` (column k = ∂/∂v_k) for the degenerate fallback.
fn centroid_derivatives(map: &AffineMls, v: DVec3, d2min: f64, m: &Moments) -> (DMat3, DMat3) {
    let mut dp = DMat3::ZERO;
    let mut dq = DMat3::ZERO;
    for (p, q) in map.sources.iter().zip(&map.targets) {
        let a = *p - v;
        let d2 = a.length_squared();
        let wi = map.weighting.relative(d2, d2min);
        let g = map.weighting.gradient_factor(wi, d2) * (-a);
        dp += outer((*p - m.po) - m.pc, g);
        dq += outer((*q - m.qo) - m.qc, g);
    }
    (dp / m.w, dq / m.w)
}

/// The rotation `R` maximising `Σ w q̂·(R p̂) = tr(R M)` for `M = Σ w p̂ q̂ᵀ`, and the maximum
/// (Horn 1987: largest eigenpair of a symmetric 4×4 matrix).
pub fn horn_rotation(m: &DMat3) -> (DMat3, f64) {
    // m.col(c)[r] = M_rc = Σ w p̂_r q̂_c.
    let s = |r: usize, c: usize| m.col(c)[r];
    let (sxx, sxy, sxz) = (s(0, 0), s(0, 1), s(0, 2));
    let (syx, syy, syz) = (s(1, 0), s(1, 1), s(1, 2));
    let (szx, szy, szz) = (s(2, 0), s(2, 1), s(2, 2));
    let n = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (q, lambda) = largest_eigenpair4(n);
    let quat = DQuat::from_xyzw(q[1], q[2], q[3], q[0]);
    let len = quat.length();
    if len.is_nan() || len <= 0.0 || !len.is_finite() {
        return (DMat3::IDENTITY, 0.0);
    }
    (DMat3::from_quat(quat / len), lambda)
}

/// Largest eigenvalue and its unit eigenvector of a symmetric 4×4 matrix (cyclic Jacobi).
#[allow(clippy::needless_range_loop)] // textbook index form of the Jacobi rotation
fn largest_eigenpair4(mut a: [[f64; 4]; 4]) -> ([f64; 4], f64) {
    let mut v = [[0.0; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..50 {
        let mut off = 0.0;
        let mut diag = 0.0;
        for i in 0..4 {
            diag += a[i][i] * a[i][i];
            for j in i + 1..4 {
                off += a[i][j] * a[i][j];
            }
        }
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for p in 0..4 {
            for q in p + 1..4 {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..4 {
                    let akp = a[k][p];
                    let akq = a[k][q];
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..4 {
                    let apk = a[p][k];
                    let aqk = a[q][k];
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in &mut v {
                    let vkp = row[p];
                    let vkq = row[q];
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut best = 0;
    for i in 1..4 {
        if a[i][i] > a[best][best] {
            best = i;
        }
    }
    (
        [v[0][best], v[1][best], v[2][best], v[3][best]],
        a[best][best],
    )
}

/// Similarity or rigid MLS in 3D: shared implementation.
#[derive(Debug, Clone, PartialEq)]
struct ProcrustesMls {
    weighting: Weighting,
    sources: Vec<DVec3>,
    targets: Vec<DVec3>,
    scale: bool,
}

impl ProcrustesMls {
    fn new(
        sources: &[DVec3],
        targets: &[DVec3],
        weighting: Weighting,
        scale: bool,
    ) -> Result<Self, DeformError> {
        weighting.validate()?;
        let what = if scale { "similarity MLS" } else { "rigid MLS" };
        check_handles(sources, targets, 3, what)?;
        check_spread(sources, "line")?;
        Ok(Self {
            weighting,
            sources: sources.to_vec(),
            targets: targets.to_vec(),
            scale,
        })
    }

    /// `(q*, s·R, v − p*)` at `v`, or the target when `v` is a handle.
    fn fit(&self, v: DVec3) -> Result<(DVec3, DMat3, DVec3), DVec3> {
        let (d2min, near) = match nearest(&self.weighting, &self.sources, v) {
            Nearest::AtHandle(i) => return Err(self.targets[i]),
            Nearest::Distance(d, i) => (d, i),
        };
        let m = moments(
            &self.weighting,
            &self.sources,
            &self.targets,
            v,
            d2min,
            near,
        );
        // M = Σ w p̂ q̂ᵀ = (Σ w q̂ p̂ᵀ)ᵀ.
        let (r, lambda) = horn_rotation(&m.qp.transpose());
        let s = if self.scale {
            let tr = m.pp.x_axis.x + m.pp.y_axis.y + m.pp.z_axis.z;
            if tr > 0.0 { lambda / tr } else { 1.0 }
        } else {
            1.0
        };
        Ok((m.q_star(), s * r, m.u(v)))
    }

    fn apply(&self, v: DVec3) -> DVec3 {
        match self.fit(v) {
            Ok((qc, l, u)) => qc + l * u,
            Err(q) => q,
        }
    }

    /// `f(v)` and its analytic Jacobian (see the module docs, "Jacobians"); central
    /// differences only where the closed form does not exist (at a handle, or where the
    /// optimal rotation is not unique).
    fn apply_with_jacobian<M: SpaceMap + ?Sized>(&self, map: &M, v: DVec3) -> (DVec3, DMat3) {
        let (d2min, near) = match nearest(&self.weighting, &self.sources, v) {
            Nearest::AtHandle(i) => {
                return (
                    self.targets[i],
                    volmorph_deform::map::central_jacobian(map, v),
                );
            }
            Nearest::Distance(d, i) => (d, i),
        };
        let m = moments(
            &self.weighting,
            &self.sources,
            &self.targets,
            v,
            d2min,
            near,
        );
        let c = m.qp; // C = Σ w q̂ p̂ᵀ = R H
        let (r, lambda) = horn_rotation(&c.transpose());
        let trp = m.pp.x_axis.x + m.pp.y_axis.y + m.pp.z_axis.z;
        let s = if self.scale && trp > 0.0 {
            lambda / trp
        } else {
            1.0
        };
        let u = m.u(v); // v − p*
        // Same expression as `apply`, so both agree to the last bit.
        let y = m.q_star() + (s * r) * u;
        // ω_k = (tr H·I − H)⁻¹ axial(Rᵀ ∂_k C − ∂_k Cᵀ R); singular where R is not unique.
        let h = r.transpose() * c;
        let h = 0.5 * (h + h.transpose());
        let trh = h.x_axis.x + h.y_axis.y + h.z_axis.z;
        let a = DMat3::from_diagonal(DVec3::splat(trh)) - h;
        let det = a.determinant();
        let scale3 =
            c.x_axis.length_squared() + c.y_axis.length_squared() + c.z_axis.length_squared();
        if !(det.is_finite() && det.abs() > ROTATION_GAP * scale3 * scale3.sqrt()) {
            return (y, volmorph_deform::map::central_jacobian(map, v));
        }
        let a_inv = a.inverse();
        // Second pass: derivatives of the weights, g_i = ∇w_i.
        let mut dc = [DMat3::ZERO; 3];
        let mut dtrp = DVec3::ZERO;
        let mut dp = DMat3::ZERO; // column k: Σ g_ik p̂_i
        let mut dq = DMat3::ZERO;
        for (p, q) in self.sources.iter().zip(&self.targets) {
            let a = *p - v;
            let d2 = a.length_squared();
            let wi = self.weighting.relative(d2, d2min);
            let g = self.weighting.gradient_factor(wi, d2) * (-a);
            let ph = (*p - m.po) - m.pc;
            let qh = (*q - m.qo) - m.qc;
            let qph = outer(qh, ph);
            for k in 0..3 {
                dc[k] += g[k] * qph;
            }
            dtrp += g * ph.length_squared();
            dp += outer(ph, g);
            dq += outer(qh, g);
        }
        let inv_w = 1.0 / m.w;
        dp *= inv_w;
        dq *= inv_w;
        let sr = s * r;
        let ru = r * u;
        let mut cols = [DVec3::ZERO; 3];
        for (k, col) in cols.iter_mut().enumerate() {
            let rtdc = r.transpose() * dc[k];
            let x = rtdc - rtdc.transpose();
            // axial vector of the skew matrix x: x = [ξ]×.
            let xi = DVec3::new(x.y_axis.z, x.z_axis.x, x.x_axis.y);
            let omega = a_inv * xi;
            // ∂_k R u = R (ω × u).
            let mut d_lin_u = s * (r * omega.cross(u));
            if self.scale && trp > 0.0 {
                // ∂λ = tr(Rᵀ ∂C) (the rotation term vanishes at the optimum).
                let dlambda = rtdc.x_axis.x + rtdc.y_axis.y + rtdc.z_axis.z;
                let ds = (dlambda - s * dtrp[k]) / trp;
                d_lin_u += ds * ru;
            }
            *col = dq.col(k) + sr * (DVec3::AXES[k] - dp.col(k)) + d_lin_u;
        }
        (y, DMat3::from_cols(cols[0], cols[1], cols[2]))
    }
}

/// The rotation of [`SimilarityMls`] / [`RigidMls`] is differentiated in closed form only
/// where `|det(tr H·I − H)|` exceeds this times `‖C‖_F³` (see the module docs): the
/// determinant is the product of the pairwise sums of the signed singular values of `C`, which
/// vanishes exactly where the optimal rotation is not unique (e.g. a collinear weighted handle
/// cluster); below it the rotation's derivative is ill-conditioned and central differences are
/// used instead.
pub const ROTATION_GAP: f64 = 1e-10;

macro_rules! procrustes_map {
    ($(#[$doc:meta])* $name:ident, $scale:expr, $what:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone, PartialEq)]
        pub struct $name(ProcrustesMls);

        impl $name {
            #[doc = concat!("Build ", $what, " MLS from source handles, targets (same length) and a weighting.")]
            ///
            /// # Errors
            /// [`DeformError::InvalidHandles`] for mismatched lengths, fewer than 3 handles,
            /// coincident sources, sources on one line or a bad weighting parameter;
            /// [`DeformError::NonFinite`] for NaN/infinite coordinates.
            pub fn new(
                sources: &[DVec3],
                targets: &[DVec3],
                weighting: Weighting,
            ) -> Result<Self, DeformError> {
                ProcrustesMls::new(sources, targets, weighting, $scale).map(Self)
            }

            /// Source handles.
            #[must_use]
            pub fn sources(&self) -> &[DVec3] {
                &self.0.sources
            }

            /// Target handles.
            #[must_use]
            pub fn targets(&self) -> &[DVec3] {
                &self.0.targets
            }

            /// The weighting of the handles.
            #[must_use]
            pub fn weighting(&self) -> Weighting {
                self.0.weighting
            }

            /// Replace the targets.
            ///
            /// # Errors
            /// [`DeformError::InvalidHandles`] for a wrong length, [`DeformError::NonFinite`]
            /// for NaN.
            pub fn set_targets(&mut self, targets: &[DVec3]) -> Result<(), DeformError> {
                set_targets(&mut self.0.targets, targets)
            }

            /// The local linear part `L_v` at `v` (`s·R`), or `None` at a source handle.
            #[must_use]
            pub fn linear_part(&self, v: DVec3) -> Option<DMat3> {
                self.0.fit(v).ok().map(|(_, l, _)| l)
            }
        }

        impl SpaceMap for $name {
            fn apply(&self, v: DVec3) -> DVec3 {
                self.0.apply(v)
            }

            fn jacobian(&self, v: DVec3) -> DMat3 {
                self.0.apply_with_jacobian(self, v).1
            }

            fn apply_with_jacobian(&self, v: DVec3) -> (DVec3, DMat3) {
                self.0.apply_with_jacobian(self, v)
            }
        }
    };
}

procrustes_map!(
    /// Similarity moving-least-squares deformation in 3D (§4.3.2 generalised; rotation by
    /// Horn's quaternion, uniform scale from the same fit); see the [module docs](self). The
    /// Jacobian is analytic.
    SimilarityMls,
    true,
    "similarity"
);

procrustes_map!(
    /// Rigid moving-least-squares deformation in 3D (§4.3.3, Theorem 4.1: the rotation of the
    /// similarity fit); see the [module docs](self). The Jacobian is analytic.
    RigidMls,
    false,
    "rigid"
);

/// A coordinate frame handle: an origin and three axis vectors (columns of `axes`; they need
/// not be orthonormal, but must be linearly independent for source frames).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Origin (physical point).
    pub origin: DVec3,
    /// Axis vectors as columns.
    pub axes: DMat3,
}

impl Frame {
    /// An axis-aligned unit frame at `origin`.
    #[must_use]
    pub fn at(origin: DVec3) -> Self {
        Self {
            origin,
            axes: DMat3::IDENTITY,
        }
    }
}

/// Frame-based moving-least-squares deformation (§5.4.3); see the [module docs](self).
///
/// The map is affine in the target origins and axes: with target vectors ordered
/// `[q_0 … q_{N−1}, g_00, g_01, g_02, g_10, …]` (origins, then each frame's three axes),
/// `f(v) = Σ_k c_k(v) t_k`, which [`volmorph_deform::LiveGrid`] exploits.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameMls {
    weighting: Weighting,
    beta: f64,
    sources: Vec<Frame>,
    targets: Vec<Frame>,
    origins: Vec<DVec3>,
}

impl FrameMls {
    /// Build from source frames, target frames (same length), the weight `β > 0` of the axis
    /// constraints and a weighting. One frame suffices.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for mismatched lengths, no frames, coincident source
    /// origins, a singular source frame, `β ≤ 0` or a bad weighting;
    /// [`DeformError::NonFinite`] for NaN/infinite values.
    pub fn new(
        sources: &[Frame],
        targets: &[Frame],
        beta: f64,
        weighting: Weighting,
    ) -> Result<Self, DeformError> {
        weighting.validate()?;
        if !(beta.is_finite() && beta > 0.0) {
            return Err(DeformError::InvalidHandles(format!(
                "frame weight β must be finite and > 0, got {beta}"
            )));
        }
        let so: Vec<DVec3> = sources.iter().map(|f| f.origin).collect();
        let to: Vec<DVec3> = targets.iter().map(|f| f.origin).collect();
        check_handles(&so, &to, 1, "frame MLS")?;
        for (what, set) in [("source", sources), ("target", targets)] {
            for (i, f) in set.iter().enumerate() {
                let cols = f.axes.to_cols_array();
                if let Some(&bad) = cols.iter().find(|v| !v.is_finite()) {
                    return Err(DeformError::NonFinite {
                        what: format!("{what} frame {i} axes"),
                        value: bad,
                    });
                }
            }
        }
        for (i, f) in sources.iter().enumerate() {
            let g = f.axes.transpose() * f.axes;
            if is_degenerate(&g) {
                return Err(DeformError::InvalidHandles(format!(
                    "source frame {i} has linearly dependent axes"
                )));
            }
        }
        Ok(Self {
            weighting,
            beta,
            sources: sources.to_vec(),
            targets: targets.to_vec(),
            origins: so,
        })
    }

    /// Source frames.
    #[must_use]
    pub fn sources(&self) -> &[Frame] {
        &self.sources
    }

    /// Target frames.
    #[must_use]
    pub fn targets(&self) -> &[Frame] {
        &self.targets
    }

    /// The weighting of the frame origins.
    #[must_use]
    pub fn weighting(&self) -> Weighting {
        self.weighting
    }

    /// The weight `β` of the axis constraints.
    #[must_use]
    pub fn beta(&self) -> f64 {
        self.beta
    }

    /// Replace the target frames.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] for a wrong length, [`DeformError::NonFinite`] for NaN.
    pub fn set_targets(&mut self, targets: &[Frame]) -> Result<(), DeformError> {
        if targets.len() != self.targets.len() {
            return Err(DeformError::InvalidHandles(format!(
                "{} target frames for {} handles",
                targets.len(),
                self.targets.len()
            )));
        }
        let v = frames_to_vectors(targets);
        volmorph_deform::map::check_finite("target frame vector", &v)?;
        self.targets.copy_from_slice(targets);
        Ok(())
    }

    /// `(q*, L, p*)` at `v` or the target origin at a handle.
    fn fit(&self, v: DVec3) -> Result<(DVec3, DMat3, DVec3), DVec3> {
        let d2min = match nearest(&self.weighting, &self.origins, v) {
            Nearest::AtHandle(i) => return Err(self.targets[i].origin),
            Nearest::Distance(d, _) => d,
        };
        let mut w = 0.0;
        let mut sp = DVec3::ZERO;
        let mut sq = DVec3::ZERO;
        let mut pp = DMat3::ZERO;
        let mut qp = DMat3::ZERO;
        let mut ff = DMat3::ZERO;
        let mut gf = DMat3::ZERO;
        for (s, t) in self.sources.iter().zip(&self.targets) {
            let a = s.origin - v;
            let b = t.origin - v;
            let wi = self.weighting.relative(a.length_squared(), d2min);
            w += wi;
            sp += wi * a;
            sq += wi * b;
            pp += outer(wi * a, a);
            qp += outer(b, wi * a);
            ff += wi * (s.axes * s.axes.transpose());
            gf += wi * (t.axes * s.axes.transpose());
        }
        let pc = sp / w;
        let qc = sq / w;
        let q = pp - w * outer(pc, pc) + self.beta * ff;
        let c = qp - w * outer(qc, pc) + self.beta * gf;
        let l = if is_degenerate(&q) {
            DMat3::IDENTITY
        } else {
            c * q.inverse()
        };
        Ok((qc + v, l, pc + v))
    }
}

/// Target vectors of a frame set in [`FrameMls`]'s order.
fn frames_to_vectors(frames: &[Frame]) -> Vec<DVec3> {
    let mut v: Vec<DVec3> = frames.iter().map(|f| f.origin).collect();
    for f in frames {
        v.extend([f.axes.x_axis, f.axes.y_axis, f.axes.z_axis]);
    }
    v
}

impl SpaceMap for FrameMls {
    fn apply(&self, v: DVec3) -> DVec3 {
        match self.fit(v) {
            Ok((qc, l, pc)) => qc + l * (v - pc),
            Err(q) => q,
        }
    }

    fn jacobian(&self, v: DVec3) -> DMat3 {
        self.apply_with_jacobian(v).1
    }

    /// `f(v)` and its analytic Jacobian: with `Q = Σ w (p̂p̂ᵀ + β F Fᵀ)`,
    /// `C = Σ w (q̂p̂ᵀ + β G Fᵀ)` and `L = C Q⁻¹`, `∂_k L = (∂_k C − L ∂_k Q) Q⁻¹` where
    /// `∂_k Q`, `∂_k C` are the same sums with `w_i` replaced by `∂_k w_i` (the centroid terms
    /// cancel since `Σ w p̂ = 0`). Central differences at a frame origin.
    fn apply_with_jacobian(&self, v: DVec3) -> (DVec3, DMat3) {
        let d2min = match nearest(&self.weighting, &self.origins, v) {
            Nearest::AtHandle(i) => {
                return (
                    self.targets[i].origin,
                    volmorph_deform::map::central_jacobian(self, v),
                );
            }
            Nearest::Distance(d, _) => d,
        };
        let Ok((qc, l, pc)) = self.fit(v) else {
            return (
                self.apply(v),
                volmorph_deform::map::central_jacobian(self, v),
            );
        };
        let y = qc + l * (v - pc);
        let pcv = pc - v;
        let qcv = qc - v;
        let mut w = 0.0;
        let mut dq_mat = [DMat3::ZERO; 3];
        let mut dc_mat = [DMat3::ZERO; 3];
        let mut dp = DMat3::ZERO;
        let mut dq = DMat3::ZERO;
        let mut q = DMat3::ZERO;
        for (s, t) in self.sources.iter().zip(&self.targets) {
            let a = s.origin - v;
            let d2 = a.length_squared();
            let wi = self.weighting.relative(d2, d2min);
            let g = self.weighting.gradient_factor(wi, d2) * (-a);
            let ph = a - pcv;
            let qh = (t.origin - v) - qcv;
            let ffi = s.axes * s.axes.transpose();
            let qm = outer(ph, ph) + self.beta * ffi;
            let cm = outer(qh, ph) + self.beta * (t.axes * s.axes.transpose());
            w += wi;
            q += wi * qm;
            for k in 0..3 {
                dq_mat[k] += g[k] * qm;
                dc_mat[k] += g[k] * cm;
            }
            dp += outer(ph, g);
            dq += outer(qh, g);
        }
        dp *= 1.0 / w;
        dq *= 1.0 / w;
        if is_degenerate(&q) {
            // Identity linear part; the centroids still move with v.
            return (y, DMat3::IDENTITY + dq - dp);
        }
        let q_inv = q.inverse();
        let u = v - pc;
        let mut cols = [DVec3::ZERO; 3];
        for (k, col) in cols.iter_mut().enumerate() {
            let dl = (dc_mat[k] - l * dq_mat[k]) * q_inv;
            *col = dq.col(k) + l * (DVec3::AXES[k] - dp.col(k)) + dl * u;
        }
        (y, DMat3::from_cols(cols[0], cols[1], cols[2]))
    }
}

/// Per-point data of [`FrameMls`]'s coefficient form.
#[derive(Debug, Clone, Copy)]
enum FrameNode {
    /// `v` is the origin of source frame `i`.
    AtHandle(usize),
    /// Regular point: origin `j`: `w_j (1/W + p̂_j·z)`; axis `(j, a)`: `β w_j f_ja·z`, with
    /// `z = Q⁻¹(v − p*)`.
    Regular {
        /// Smallest squared distance to a handle.
        d2min: f64,
        /// `1 / Σ w`.
        inv_w: f64,
        /// `p*`.
        pc: DVec3,
        /// `Q⁻¹ (v − p*)` (zero in the identity fallback).
        z: DVec3,
    },
}

/// Parameters: the `n` target frame origins, then the three axis vectors of each target frame
/// (`4n` vectors: origins `0..n`, axes of frame `j` at `n + 3j ..= n + 3j + 2`).
impl LinearMap for FrameMls {
    fn parameter_count(&self) -> usize {
        4 * self.targets.len()
    }

    fn parameters(&self) -> Vec<DVec3> {
        frames_to_vectors(&self.targets)
    }

    fn dense_coefficients_are_cheap(&self) -> bool {
        true
    }

    fn same_structure(&self, other: &Self) -> bool {
        self.sources == other.sources
            && self.weighting == other.weighting
            && self.beta == other.beta
    }

    fn set_parameters(&mut self, t: &[DVec3]) -> Result<(), DeformError> {
        let n = self.sources.len();
        if t.len() != 4 * n {
            return Err(DeformError::InvalidHandles(format!(
                "{} target vectors for {n} frames (need {})",
                t.len(),
                4 * n
            )));
        }
        let frames: Vec<Frame> = (0..n)
            .map(|j| Frame {
                origin: t[j],
                axes: DMat3::from_cols(t[n + 3 * j], t[n + 3 * j + 1], t[n + 3 * j + 2]),
            })
            .collect();
        self.set_targets(&frames)
    }

    fn coefficients_into(&self, v: DVec3, out: &mut [f64]) -> DVec3 {
        let node = self.node(v);
        for (k, o) in out.iter_mut().enumerate().take(4 * self.sources.len()) {
            *o = self.coefficient(k, v, &node);
        }
        match node {
            FrameNode::Regular { pc, z, .. } if z == DVec3::ZERO && pc != v => v - pc,
            _ => DVec3::ZERO,
        }
    }
}

impl FrameMls {
    /// Per-point data of the coefficient form.
    fn node(&self, v: DVec3) -> FrameNode {
        let d2min = match nearest(&self.weighting, &self.origins, v) {
            Nearest::AtHandle(i) => return FrameNode::AtHandle(i),
            Nearest::Distance(d, _) => d,
        };
        let mut w = 0.0;
        let mut sp = DVec3::ZERO;
        let mut pp = DMat3::ZERO;
        let mut ff = DMat3::ZERO;
        for s in &self.sources {
            let a = s.origin - v;
            let wi = self.weighting.relative(a.length_squared(), d2min);
            w += wi;
            sp += wi * a;
            pp += outer(wi * a, a);
            ff += wi * (s.axes * s.axes.transpose());
        }
        let pcv = sp / w;
        let q = pp - w * outer(pcv, pcv) + self.beta * ff;
        let z = if is_degenerate(&q) {
            DVec3::ZERO
        } else {
            q.inverse() * (-pcv)
        };
        FrameNode::Regular {
            d2min,
            inv_w: 1.0 / w,
            pc: pcv + v,
            z,
        }
    }

    /// Coefficient `k` at `v` given `node = self.node(v)`.
    #[inline]
    fn coefficient(&self, k: usize, v: DVec3, node: &FrameNode) -> f64 {
        let n = self.sources.len();
        match *node {
            FrameNode::AtHandle(i) => f64::from(u8::from(i == k)),
            FrameNode::Regular {
                d2min,
                inv_w,
                pc,
                z,
            } => {
                let (j, axis) = if k < n {
                    (k, None)
                } else {
                    ((k - n) / 3, Some((k - n) % 3))
                };
                let Some(s) = self.sources.get(j) else {
                    return 0.0;
                };
                let w = self
                    .weighting
                    .relative((s.origin - v).length_squared(), d2min);
                match axis {
                    None => w * (inv_w + (s.origin - pc).dot(z)),
                    Some(a) => self.beta * w * s.axes.col(a).dot(z),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_deform::Affine;
    use volmorph_deform::map::central_jacobian;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((*seed >> 11) as f64) / ((1u64 << 53) as f64)
    }

    pub(crate) fn random_handles(n: usize, seed: u64) -> Vec<DVec3> {
        let mut s = seed;
        (0..n)
            .map(|_| DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 40.0 - 10.0)
            .collect()
    }

    fn jitter(p: &[DVec3], amount: f64, seed: u64) -> Vec<DVec3> {
        let mut s = seed;
        p.iter()
            .map(|&x| {
                x + amount * DVec3::new(lcg(&mut s) - 0.5, lcg(&mut s) - 0.5, lcg(&mut s) - 0.5)
            })
            .collect()
    }

    fn close(a: DVec3, b: DVec3, tol: f64) -> bool {
        (a - b).length() <= tol * b.length().max(1.0)
    }

    const WEIGHTINGS: [Weighting; 3] = [
        Weighting::InverseDistance { alpha: 1.0 },
        Weighting::InverseDistance { alpha: 1.5 },
        Weighting::Gaussian { sigma: 15.0 },
    ];

    fn probes() -> Vec<DVec3> {
        vec![
            DVec3::new(0.5, 1.5, 2.5),
            DVec3::new(-20.0, 40.0, 3.0),
            DVec3::new(12.0, -3.0, 25.0),
        ]
    }

    #[test]
    fn all_methods_interpolate_and_identity_handles_give_identity() {
        let p = random_handles(12, 1);
        let q = jitter(&p, 6.0, 2);
        let w = Weighting::default();
        let maps: Vec<Box<dyn SpaceMap>> = vec![
            Box::new(AffineMls::new(&p, &q, w).unwrap()),
            Box::new(SimilarityMls::new(&p, &q, w).unwrap()),
            Box::new(RigidMls::new(&p, &q, w).unwrap()),
        ];
        for m in &maps {
            for (a, b) in p.iter().zip(&q) {
                assert_eq!(m.apply(*a), *b);
                // Approaching the handle converges to the target.
                let near = m.apply(*a + DVec3::splat(1e-7));
                assert!(close(near, *b, 1e-5), "{near} vs {b}");
            }
        }
        for wt in WEIGHTINGS {
            let maps: Vec<Box<dyn SpaceMap>> = vec![
                Box::new(AffineMls::new(&p, &p, wt).unwrap()),
                Box::new(SimilarityMls::new(&p, &p, wt).unwrap()),
                Box::new(RigidMls::new(&p, &p, wt).unwrap()),
            ];
            for m in &maps {
                for x in probes() {
                    assert!(close(m.apply(x), x, 1e-10), "{wt:?}");
                }
            }
        }
    }

    #[test]
    fn affine_reproduces_global_affine_and_rigid_reproduces_rigid_motion() {
        let p = random_handles(10, 3);
        let a = Affine {
            matrix: DMat3::from_cols(
                DVec3::new(1.3, 0.2, -0.1),
                DVec3::new(0.4, 0.8, 0.0),
                DVec3::new(0.0, 0.3, 1.1),
            ),
            offset: DVec3::new(5.0, -2.0, 1.0),
        };
        let qa: Vec<DVec3> = p.iter().map(|&x| a.apply(x)).collect();
        let rot = DMat3::from_quat(DQuat::from_axis_angle(
            DVec3::new(1.0, 2.0, -0.5).normalize(),
            1.1,
        ));
        let rigid = Affine {
            matrix: rot,
            offset: DVec3::new(-3.0, 4.0, 7.0),
        };
        let sim = Affine {
            matrix: 1.7 * rot,
            offset: DVec3::new(1.0, 0.0, -2.0),
        };
        let qr: Vec<DVec3> = p.iter().map(|&x| rigid.apply(x)).collect();
        let qs: Vec<DVec3> = p.iter().map(|&x| sim.apply(x)).collect();
        for wt in WEIGHTINGS {
            let am = AffineMls::new(&p, &qa, wt).unwrap();
            let rm = RigidMls::new(&p, &qr, wt).unwrap();
            let sm = SimilarityMls::new(&p, &qs, wt).unwrap();
            // Similarity ⊂ affine, rigid ⊂ similarity: the larger classes follow too.
            let am_s = AffineMls::new(&p, &qs, wt).unwrap();
            let sm_r = SimilarityMls::new(&p, &qr, wt).unwrap();
            for x in probes() {
                assert!(close(am.apply(x), a.apply(x), 1e-9), "{wt:?}");
                assert!(close(rm.apply(x), rigid.apply(x), 1e-9), "{wt:?}");
                assert!(close(sm.apply(x), sim.apply(x), 1e-9), "{wt:?}");
                assert!(close(am_s.apply(x), sim.apply(x), 1e-9));
                assert!(close(sm_r.apply(x), rigid.apply(x), 1e-9));
                assert!((am.jacobian(x) - a.matrix).abs_diff_eq(DMat3::ZERO, 1e-8));
            }
        }
    }

    #[test]
    fn similarity_is_scaled_rigid_rotation_theorem_4_1() {
        let p = random_handles(9, 4);
        let q = jitter(&p, 8.0, 5);
        let sm = SimilarityMls::new(&p, &q, Weighting::default()).unwrap();
        let rm = RigidMls::new(&p, &q, Weighting::default()).unwrap();
        for x in probes() {
            let ls = sm.linear_part(x).unwrap();
            let lr = rm.linear_part(x).unwrap();
            // L_s = λ R with R the rigid rotation.
            let lambda = ls.x_axis.length();
            assert!(lambda > 0.0);
            assert!((ls - lambda * lr).abs_diff_eq(DMat3::ZERO, 1e-10));
            assert!((lr.transpose() * lr).abs_diff_eq(DMat3::IDENTITY, 1e-12));
            assert!((lr.determinant() - 1.0).abs() < 1e-12);
            // The rigid rotation is optimal: no small perturbation does better.
            let fit = |r: DMat3| -> f64 {
                let v = x;
                let w: Vec<f64> = p
                    .iter()
                    .map(|pi| 1.0 / (*pi - v).length_squared())
                    .collect();
                let ws: f64 = w.iter().sum();
                let pc = p.iter().zip(&w).map(|(a, b)| *a * *b).sum::<DVec3>() / ws;
                let qc = q.iter().zip(&w).map(|(a, b)| *a * *b).sum::<DVec3>() / ws;
                p.iter()
                    .zip(&q)
                    .zip(&w)
                    .map(|((a, b), wi)| wi * (r * (*a - pc) - (*b - qc)).length_squared())
                    .sum()
            };
            let e0 = fit(lr);
            for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
                for ang in [-1e-3, 1e-3] {
                    let r2 = DMat3::from_axis_angle(axis, ang) * lr;
                    assert!(fit(r2) >= e0 - 1e-9 * e0);
                }
            }
        }
    }

    #[test]
    fn affine_jacobian_matches_differences_and_coefficients_match_apply() {
        let p = random_handles(15, 6);
        let q = jitter(&p, 5.0, 7);
        for wt in WEIGHTINGS {
            let m = AffineMls::new(&p, &q, wt).unwrap();
            let mut c = vec![0.0; p.len()];
            for x in probes() {
                let (y, j) = m.apply_with_jacobian(x);
                assert_eq!(y, m.apply(x));
                let fd = central_jacobian(&m, x);
                assert!((j - fd).abs_diff_eq(DMat3::ZERO, 1e-6), "{wt:?}\n{j}\n{fd}");
                m.coefficients(x, &mut c);
                assert!((c.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                let s: DVec3 = c.iter().zip(&q).map(|(a, b)| *a * *b).sum();
                assert!(close(s, y, 1e-11));
            }
        }
        // Frames: coefficient form equals apply.
        let fs: Vec<Frame> = p.iter().map(|&o| Frame::at(o)).collect();
        let ft: Vec<Frame> = q
            .iter()
            .enumerate()
            .map(|(i, &o)| Frame {
                origin: o,
                axes: DMat3::from_rotation_z(0.1 * i as f64) * 1.2,
            })
            .collect();
        let fm = FrameMls::new(&fs, &ft, 2.0, Weighting::default()).unwrap();
        let t = fm.parameters();
        for x in probes() {
            let mut c = vec![0.0; t.len()];
            let base = fm.coefficients_into(x, &mut c);
            let s: DVec3 = base + (0..t.len()).map(|k| c[k] * t[k]).sum::<DVec3>();
            assert!(close(s, fm.apply(x), 1e-11));
        }
    }

    /// Richardson-extrapolated central differences (error O(h⁴)) with a step scaled to the
    /// distance `d` from `x` to the nearest handle, so near-handle points are resolved.
    fn richardson_jacobian(m: &dyn SpaceMap, x: DVec3, d: f64) -> DMat3 {
        let h = 0.02 * d.min(1.0);
        let cd = |h: f64, e: DVec3| (m.apply(x + h * e) - m.apply(x - h * e)) / (2.0 * h);
        // Two Richardson levels: O(h⁴) from h, h/2 and h/2, h/4, then O(h⁶).
        let col = |e: DVec3| {
            let (d1, d2, d4) = (cd(h, e), cd(0.5 * h, e), cd(0.25 * h, e));
            let r1 = (4.0 * d2 - d1) / 3.0;
            let r2 = (4.0 * d4 - d2) / 3.0;
            (16.0 * r2 - r1) / 15.0
        };
        DMat3::from_cols(col(DVec3::X), col(DVec3::Y), col(DVec3::Z))
    }

    fn frobenius(m: DMat3) -> f64 {
        (m.x_axis.length_squared() + m.y_axis.length_squared() + m.z_axis.length_squared()).sqrt()
    }

    /// Random probes (some far, some within 1e-2..1e-4 of a handle) with their distance to the
    /// nearest handle.
    fn jacobian_probes(p: &[DVec3], seed: u64) -> Vec<(DVec3, f64)> {
        let mut s = seed;
        let mut out = Vec::new();
        for k in 0..12 {
            let x = if k % 3 == 2 {
                let i = (lcg(&mut s) * p.len() as f64) as usize % p.len();
                let dir =
                    DVec3::new(lcg(&mut s) - 0.5, lcg(&mut s) - 0.5, lcg(&mut s) - 0.5).normalize();
                p[i] + dir * 10f64.powi(-2 - (k / 3) % 3)
            } else {
                DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 50.0 - 15.0
            };
            let d = p
                .iter()
                .map(|q| (*q - x).length())
                .fold(f64::INFINITY, f64::min);
            out.push((x, d));
        }
        out
    }

    fn frame_pair(p: &[DVec3], q: &[DVec3], seed: u64) -> (Vec<Frame>, Vec<Frame>) {
        let mut s = seed;
        let mut m = || {
            DMat3::from_cols(
                DVec3::new(
                    1.0 + 0.3 * lcg(&mut s),
                    0.2 * lcg(&mut s),
                    -0.1 * lcg(&mut s),
                ),
                DVec3::new(
                    0.1 * lcg(&mut s),
                    0.9 + 0.3 * lcg(&mut s),
                    0.2 * lcg(&mut s),
                ),
                DVec3::new(
                    -0.2 * lcg(&mut s),
                    0.1 * lcg(&mut s),
                    1.1 + 0.2 * lcg(&mut s),
                ),
            )
        };
        let fs = p
            .iter()
            .map(|&o| Frame {
                origin: o,
                axes: m(),
            })
            .collect();
        let ft = q
            .iter()
            .map(|&o| Frame {
                origin: o,
                axes: m(),
            })
            .collect();
        (fs, ft)
    }

    #[test]
    fn analytic_jacobians_match_richardson_differences() {
        for (n, seed) in [(4usize, 21u64), (9, 22), (25, 23)] {
            let p = random_handles(n, seed);
            let q = jitter(&p, 9.0, seed + 100);
            let (fs, ft) = frame_pair(&p, &q, seed + 200);
            for wt in WEIGHTINGS {
                let maps: Vec<(&str, Box<dyn SpaceMap>)> = vec![
                    (
                        "similarity",
                        Box::new(SimilarityMls::new(&p, &q, wt).unwrap()),
                    ),
                    ("rigid", Box::new(RigidMls::new(&p, &q, wt).unwrap())),
                    ("frame", Box::new(FrameMls::new(&fs, &ft, 1.5, wt).unwrap())),
                    ("affine", Box::new(AffineMls::new(&p, &q, wt).unwrap())),
                ];
                for (name, m) in &maps {
                    for (x, d) in jacobian_probes(&p, seed + 300) {
                        let (y, j) = m.apply_with_jacobian(x);
                        assert_eq!(y, m.apply(x), "{name}");
                        assert_eq!(j, m.jacobian(x), "{name}");
                        let fd = richardson_jacobian(m.as_ref(), x, d);
                        let err = frobenius(j - fd);
                        assert!(
                            err <= 1e-6 * frobenius(fd).max(1e-3),
                            "{name} {wt:?} n={n} x={x} d={d:e}: err {err:e}\n{j}\n{fd}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn identity_handles_have_identity_jacobian_and_rigid_motion_its_rotation() {
        let p = random_handles(11, 31);
        let rot = DMat3::from_quat(DQuat::from_axis_angle(
            DVec3::new(-0.3, 1.0, 0.7).normalize(),
            2.3,
        ));
        let qr: Vec<DVec3> = p
            .iter()
            .map(|&x| rot * x + DVec3::new(4.0, -1.0, 2.0))
            .collect();
        let fs: Vec<Frame> = p.iter().map(|&o| Frame::at(o)).collect();
        let fr: Vec<Frame> = qr
            .iter()
            .map(|&o| Frame {
                origin: o,
                axes: rot,
            })
            .collect();
        for wt in WEIGHTINGS {
            let ident: Vec<Box<dyn SpaceMap>> = vec![
                Box::new(SimilarityMls::new(&p, &p, wt).unwrap()),
                Box::new(RigidMls::new(&p, &p, wt).unwrap()),
                Box::new(FrameMls::new(&fs, &fs, 0.7, wt).unwrap()),
            ];
            let moved: Vec<Box<dyn SpaceMap>> = vec![
                Box::new(SimilarityMls::new(&p, &qr, wt).unwrap()),
                Box::new(RigidMls::new(&p, &qr, wt).unwrap()),
                Box::new(FrameMls::new(&fs, &fr, 0.7, wt).unwrap()),
            ];
            for (x, _) in jacobian_probes(&p, 32) {
                for m in &ident {
                    assert!(
                        (m.jacobian(x) - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-9),
                        "{wt:?} {x}\n{}",
                        m.jacobian(x)
                    );
                }
                for (k, m) in moved.iter().enumerate() {
                    assert!(
                        (m.jacobian(x) - rot).abs_diff_eq(DMat3::ZERO, 1e-9),
                        "{k} {wt:?} {x}\n{}\n{rot}",
                        m.jacobian(x)
                    );
                }
            }
        }
    }

    #[test]
    fn frames_interpolate_origins_and_follow_axes_locally() {
        let p = random_handles(5, 8);
        let rot = DMat3::from_rotation_y(0.4);
        let fs: Vec<Frame> = p.iter().map(|&o| Frame::at(o)).collect();
        let ft: Vec<Frame> = p
            .iter()
            .map(|&o| Frame {
                origin: o + DVec3::X,
                axes: rot,
            })
            .collect();
        let m = FrameMls::new(&fs, &ft, 1.0, Weighting::InverseDistance { alpha: 1.5 }).unwrap();
        for (s, t) in fs.iter().zip(&ft) {
            assert_eq!(m.apply(s.origin), t.origin);
            let j = central_jacobian(&m, s.origin + DVec3::splat(1e-4));
            assert!((j - rot).abs_diff_eq(DMat3::ZERO, 2e-2), "{j}");
        }
        // One frame: the map is its affine motion everywhere.
        let one = FrameMls::new(&fs[..1], &ft[..1], 1.0, Weighting::default()).unwrap();
        let x = DVec3::new(3.0, -4.0, 9.0);
        let expect = ft[0].origin + rot * (x - fs[0].origin);
        assert!(close(one.apply(x), expect, 1e-12));
        // Identity frames give the identity.
        let id = FrameMls::new(&fs, &fs, 1.0, Weighting::default()).unwrap();
        for x in probes() {
            assert!(close(id.apply(x), x, 1e-12));
        }
    }

    #[test]
    fn bad_handles_are_errors() {
        let p = random_handles(6, 9);
        let w = Weighting::default();
        assert!(AffineMls::new(&p[..3], &p[..3], w).is_err());
        assert!(AffineMls::new(&p, &p[..5], w).is_err());
        let mut dup = p.clone();
        dup[4] = dup[1];
        assert!(matches!(
            AffineMls::new(&dup, &p, w),
            Err(DeformError::InvalidHandles(m)) if m.contains("coincide")
        ));
        let planar: Vec<DVec3> = p.iter().map(|x| DVec3::new(x.x, x.y, 0.0)).collect();
        assert!(AffineMls::new(&planar, &planar, w).is_err());
        assert!(SimilarityMls::new(&planar, &planar, w).is_ok());
        let line: Vec<DVec3> = (0..5).map(|i| DVec3::splat(f64::from(i))).collect();
        assert!(RigidMls::new(&line, &line, w).is_err());
        let mut nan = p.clone();
        nan[0].y = f64::NAN;
        assert!(matches!(
            RigidMls::new(&p, &nan, w),
            Err(DeformError::NonFinite { .. })
        ));
        assert!(AffineMls::new(&p, &p, Weighting::InverseDistance { alpha: 0.0 }).is_err());
        assert!(AffineMls::new(&p, &p, Weighting::Gaussian { sigma: f64::NAN }).is_err());
        let fs = [Frame {
            origin: DVec3::ZERO,
            axes: DMat3::from_cols(DVec3::X, DVec3::X, DVec3::Z),
        }];
        assert!(FrameMls::new(&fs, &fs, 1.0, w).is_err());
        assert!(
            FrameMls::new(&[Frame::at(DVec3::ZERO)], &[Frame::at(DVec3::ZERO)], 0.0, w).is_err()
        );
        // Gaussian weights far from every handle: finite, no panic.
        let g =
            AffineMls::new(&p, &jitter(&p, 3.0, 1), Weighting::Gaussian { sigma: 0.5 }).unwrap();
        let far = g.apply(DVec3::splat(1e4));
        assert!(far.is_finite());
    }
}
