//! Quadratic error functions of Hermite data (Ju et al. 2002) and their robust minimiser.
//!
//! A [`Qef`] sums, over tangent planes `(pᵢ, nᵢ)`, the squared distance `(nᵢ·(x − pᵢ))²`.
//! It keeps only the normal equations (`AᵀA`, `Aᵀb`, `bᵀb`) and the mass point, so adding a
//! plane is constant time and memory, and everything is stored relative to a caller-chosen
//! **reference point** (for dual contouring the cell's corner) so that the sums keep full
//! precision however far the cell is from the origin.
//!
//! **Solver choice.** `AᵀA` is a symmetric positive semi-definite 3×3 matrix, so its
//! eigen-decomposition *is* its singular value decomposition, and the singular values of `A`
//! are the square roots of its eigenvalues. A cyclic Jacobi eigen-solver on that matrix is a
//! few dozen flops, allocation-free, unconditionally convergent and accurate to machine
//! precision for the small eigenvalues that decide the truncation — which is all a per-cell
//! solve needs. A general dense SVD (as from `faer`) would factor the tall matrix `A` itself,
//! needing the planes kept and heap work per cell, for no gain in robustness here.
//!
//! **Truncation.** The minimiser is taken about the mass point `c` (mean of the `pᵢ`):
//! `x = c + (AᵀA)⁺ (Aᵀb − AᵀA c)`, with the pseudo-inverse dropping every singular value of
//! `A` below `threshold × σ_max`. Directions the planes do not constrain (along an edge, in a
//! flat patch) therefore keep the mass point's coordinate: the minimum-norm solution about
//! `c`. Three independent planes give their intersection point, two give the point of their
//! intersection line nearest to `c`, one gives the projection of `c` onto the plane.

use glam::{DMat3, DVec3};

/// Default relative singular-value threshold of [`Qef::solve`]: singular values of `A` below
/// `0.1 σ_max` (eigenvalues of `AᵀA` below `0.01 λ_max`) are treated as zero, the value Ju et
/// al. use. Planes meeting at less than about 6° are then treated as one plane.
pub const DEFAULT_SINGULAR_THRESHOLD: f64 = 0.1;

/// A quadratic error function `E(x) = Σᵢ (nᵢ·(x − pᵢ))²` accumulated from tangent planes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Qef {
    /// Every point is stored as `p − reference`.
    reference: DVec3,
    /// Upper triangle of `AᵀA`: xx, xy, xz, yy, yz, zz.
    ata: [f64; 6],
    /// `Aᵀb` with `bᵢ = nᵢ·(pᵢ − reference)`.
    atb: DVec3,
    /// `bᵀb`.
    btb: f64,
    /// Sum of `pᵢ − reference` over all added points.
    mass: DVec3,
    /// Number of added points.
    count: usize,
}

/// The minimiser of a [`Qef`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QefSolution {
    /// The minimising point, in the same coordinates as the added points.
    pub position: DVec3,
    /// The residual `E(position)` (sum of squared plane distances, ≥ 0).
    pub error: f64,
    /// Number of singular values kept by the truncation (0 to 3): 3 for a corner, 2 for an
    /// edge, 1 for a flat patch, 0 when no plane has a usable normal.
    pub rank: usize,
}

impl Qef {
    /// An empty error function whose sums are kept relative to `reference` (any point near
    /// the planes, e.g. the cell's corner; it does not change the result, only its precision).
    #[must_use]
    pub fn new(reference: DVec3) -> Self {
        Self {
            reference,
            ata: [0.0; 6],
            atb: DVec3::ZERO,
            btb: 0.0,
            mass: DVec3::ZERO,
            count: 0,
        }
    }

    /// Add the plane through `point` with normal `normal`. The normal is used as given: pass a
    /// unit vector for a plain distance (a longer one weighs the plane more). A zero or
    /// non-finite normal adds the point to the mass point only; a non-finite point is ignored.
    pub fn add(&mut self, point: DVec3, normal: DVec3) {
        if !point.is_finite() {
            return;
        }
        let p = point - self.reference;
        self.mass += p;
        self.count += 1;
        if !normal.is_finite() || normal == DVec3::ZERO {
            return;
        }
        let n = normal;
        let b = n.dot(p);
        self.ata[0] += n.x * n.x;
        self.ata[1] += n.x * n.y;
        self.ata[2] += n.x * n.z;
        self.ata[3] += n.y * n.y;
        self.ata[4] += n.y * n.z;
        self.ata[5] += n.z * n.z;
        self.atb += n * b;
        self.btb += b * b;
    }

    /// Number of points added.
    #[must_use]
    pub fn count(&self) -> usize {
        self.count
    }

    /// Mean of the added points, or `None` if there are none.
    #[must_use]
    pub fn mass_point(&self) -> Option<DVec3> {
        (self.count > 0).then(|| self.reference + self.mass / self.count as f64)
    }

    /// `E(x)`, the sum of squared distances of `x` to the added planes (clamped at 0 against
    /// rounding).
    #[must_use]
    pub fn error_at(&self, x: DVec3) -> f64 {
        let y = x - self.reference;
        (y.dot(self.matrix() * y) - 2.0 * y.dot(self.atb) + self.btb).max(0.0)
    }

    /// The minimiser about the mass point with singular values of `A` below
    /// `threshold × σ_max` truncated (see the module documentation), or `None` if no point
    /// was added. A `threshold` that is NaN or negative is treated as 0 (only exact zeros
    /// truncated); with no usable normal the mass point is returned with rank 0.
    #[must_use]
    pub fn solve(&self, threshold: f64) -> Option<QefSolution> {
        if self.count == 0 {
            return None;
        }
        let c = self.mass / self.count as f64;
        let a = self.matrix();
        let (values, vectors) = symmetric_eigen(a);
        let largest = values.max_element();
        let t = if threshold.is_nan() {
            0.0
        } else {
            threshold.max(0.0)
        };
        // Singular values of A are √λ: σ < t σ_max ⇔ λ < t² λ_max.
        let cut = t * t * largest;
        let rhs = self.atb - a * c;
        let mut y = c;
        let mut rank = 0;
        if largest > 0.0 {
            for (axis, &lambda) in values.to_array().iter().enumerate() {
                if lambda > cut && lambda > 0.0 {
                    let v = vectors.col(axis);
                    y += v * (v.dot(rhs) / lambda);
                    rank += 1;
                }
            }
        }
        let position = self.reference + y;
        Some(QefSolution {
            position,
            error: self.error_at(position),
            rank,
        })
    }

    /// `AᵀA` as a full symmetric matrix.
    fn matrix(&self) -> DMat3 {
        let [xx, xy, xz, yy, yz, zz] = self.ata;
        DMat3::from_cols(
            DVec3::new(xx, xy, xz),
            DVec3::new(xy, yy, yz),
            DVec3::new(xz, yz, zz),
        )
    }
}

/// Eigenvalues and orthonormal eigenvectors (the matrix's columns, in the same order) of a
/// symmetric 3×3 matrix, by cyclic Jacobi rotations.
#[must_use]
pub fn symmetric_eigen(a: DMat3) -> (DVec3, DMat3) {
    let mut m = a.to_cols_array_2d(); // m[col][row]; symmetric, so m[i][j] = a_ij
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale: f64 = m.iter().flatten().map(|x| x * x).sum::<f64>();
    if !scale.is_finite() || scale <= 0.0 {
        let d = DVec3::new(m[0][0], m[1][1], m[2][2]);
        return (d, DMat3::IDENTITY);
    }
    for _sweep in 0..32 {
        let off = m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2];
        if off <= scale * 1e-32 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let apq = m[p][q];
            if apq == 0.0 {
                continue;
            }
            // Rotation zeroing m[p][q] (Golub & Van Loan, symmetric Schur decomposition).
            let theta = (m[q][q] - m[p][p]) / (2.0 * apq);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let cos = 1.0 / (t * t + 1.0).sqrt();
            let sin = t * cos;
            for row in &mut m {
                let (mkp, mkq) = (row[p], row[q]);
                row[p] = cos * mkp - sin * mkq;
                row[q] = sin * mkp + cos * mkq;
            }
            let (rp, rq) = (m[p], m[q]);
            for (k, (&mpk, &mqk)) in rp.iter().zip(&rq).enumerate() {
                m[p][k] = cos * mpk - sin * mqk;
                m[q][k] = sin * mpk + cos * mqk;
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = cos * vp - sin * vq;
                row[q] = sin * vp + cos * vq;
            }
        }
    }
    let values = DVec3::new(m[0][0], m[1][1], m[2][2]);
    // v[row][col] holds eigenvector `col` in its column.
    let vectors = DMat3::from_cols(
        DVec3::new(v[0][0], v[1][0], v[2][0]),
        DVec3::new(v[0][1], v[1][1], v[2][1]),
        DVec3::new(v[0][2], v[1][2], v[2][2]),
    );
    (values, vectors)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_reconstructs_the_matrix() {
        let a = DMat3::from_cols(
            DVec3::new(4.0, 1.0, -2.0),
            DVec3::new(1.0, 3.0, 0.5),
            DVec3::new(-2.0, 0.5, 1.0),
        );
        let (d, v) = symmetric_eigen(a);
        let back = v * DMat3::from_diagonal(d) * v.transpose();
        assert!((back - a).to_cols_array().iter().all(|x| x.abs() < 1e-12));
        assert!(
            (v.transpose() * v - DMat3::IDENTITY)
                .to_cols_array()
                .iter()
                .all(|x| x.abs() < 1e-12)
        );
    }
}
