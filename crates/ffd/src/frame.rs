//! The local frame `(s, t, n)` and the Bézier surface degrees of a plane in a knot box
//! (Feng et al. 2002 §3.3.3, Table 1).
//!
//! A plane `p(σ, τ) = o + σ s + τ t` composed with a Bézier volume of degrees
//! `(k_u, k_v, k_w)` is a polynomial whose degree in `σ` is the sum of `k_a` over the axes `a`
//! where `s_a ≠ 0`, and likewise in `τ`. Table 1 chooses `s` with as many zero components as
//! the normal allows, so the degrees stay below the general `(k_u+k_v+k_w)²`:
//!
//! | row | normal `n`          | `s`                               | degrees `(n_s, n_t)`          |
//! |-----|---------------------|-----------------------------------|-------------------------------|
//! | 1   | `(±1, 0, 0)`        | `(0, 1, 0)`                       | `k_v × k_w`                   |
//! | 2   | `(0, ±1, 0)`        | `(0, 0, 1)`                       | `k_w × k_u`                   |
//! | 3   | `(0, 0, ±1)`        | `(1, 0, 0)`                       | `k_u × k_v`                   |
//! | 4   | `(0, n_y, n_z)`     | `(1, 0, 0)`                       | `k_u × (k_v + k_w)`           |
//! | 5   | `(n_x, 0, n_z)`     | `(0, 1, 0)`                       | `k_v × (k_u + k_w)`           |
//! | 6   | `(n_x, n_y, 0)`     | `(0, 0, 1)`                       | `k_w × (k_u + k_v)`           |
//! | 7   | `(n_x, n_y, n_z)`   | `⊥ n` in the plane of the two axes other than the one of largest degree | `(k − k_max) × k`, `k = k_u+k_v+k_w` |
//!
//! Throughout `t = n × s`, so `(s, t, n)` is a right-handed orthonormal frame and a polygon
//! counter-clockwise about `n` is counter-clockwise in the `(σ, τ)` plane. (The paper's row 5
//! prints `t = (n_z, 0, −n_x)`, which is `s × n`; volmorph keeps `t = n × s` in every row.) In
//! row 7 the largest degree is looked up in the order u, v, w: `s = (0, −n_z, n_y)/‖·‖` when
//! `k_u` is largest, `(n_z, 0, −n_x)/‖·‖` when `k_v` is, `(−n_y, n_x, 0)/‖·‖` otherwise.

use glam::DVec3;

/// Components of a unit normal with magnitude at most this are taken as exactly zero when
/// choosing the Table 1 row (Newell normals of axis-aligned faces carry rounding of this
/// order for models normalised to unit size).
pub const ZERO_COMPONENT_TOL: f64 = 1e-12;

/// The seven rows of Table 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PlaneCase {
    /// Row 1: `n = (±1, 0, 0)`.
    NormalU,
    /// Row 2: `n = (0, ±1, 0)`.
    NormalV,
    /// Row 3: `n = (0, 0, ±1)`.
    NormalW,
    /// Row 4: `n = (0, n_y, n_z)`.
    ZeroU,
    /// Row 5: `n = (n_x, 0, n_z)`.
    ZeroV,
    /// Row 6: `n = (n_x, n_y, 0)`.
    ZeroW,
    /// Row 7: no zero component.
    General,
}

impl PlaneCase {
    /// The row number in Table 1 (1 … 7).
    #[must_use]
    pub fn row(self) -> usize {
        match self {
            Self::NormalU => 1,
            Self::NormalV => 2,
            Self::NormalW => 3,
            Self::ZeroU => 4,
            Self::ZeroV => 5,
            Self::ZeroW => 6,
            Self::General => 7,
        }
    }
}

/// The local frame of a plane: Table 1's row, the snapped unit normal `n` (components below
/// [`ZERO_COMPONENT_TOL`] set to zero), `s`, `t = n × s` and the surface degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFrame {
    /// Table 1 row.
    pub case: PlaneCase,
    /// Unit normal with exact zeros.
    pub n: DVec3,
    /// First in-plane axis (`σ` direction) with the exact zeros of Table 1.
    pub s: DVec3,
    /// Second in-plane axis (`τ` direction), `n × s`.
    pub t: DVec3,
    /// Degrees `(n_s, n_t)` of the composed Bézier surface.
    pub degrees: [usize; 2],
}

/// The degree of the image of direction `d` under a volume of degrees `k`: `Σ k_a` over the
/// non-zero components of `d`.
#[must_use]
pub fn direction_degree(d: DVec3, k: [usize; 3]) -> usize {
    (0..3).filter(|&a| d[a] != 0.0).map(|a| k[a]).sum()
}

/// Table 1 for the unit normal `normal` and lattice degrees `k = (k_u, k_v, k_w)`. Returns
/// `None` for a zero or non-finite normal.
#[must_use]
pub fn plane_frame(normal: DVec3, k: [usize; 3]) -> Option<PlaneFrame> {
    let len = normal.length();
    if !(len.is_finite() && len > 0.0) {
        return None;
    }
    let mut n = normal / len;
    for a in 0..3 {
        if n[a].abs() <= ZERO_COMPONENT_TOL {
            n[a] = 0.0;
        }
    }
    n = n.normalize();
    let zero = [n.x == 0.0, n.y == 0.0, n.z == 0.0];
    let (case, s) = match zero {
        [false, true, true] => (PlaneCase::NormalU, DVec3::Y),
        [true, false, true] => (PlaneCase::NormalV, DVec3::Z),
        [true, true, false] => (PlaneCase::NormalW, DVec3::X),
        [true, false, false] => (PlaneCase::ZeroU, DVec3::X),
        [false, true, false] => (PlaneCase::ZeroV, DVec3::Y),
        [false, false, true] => (PlaneCase::ZeroW, DVec3::Z),
        _ => {
            let s = if k[0] >= k[1] && k[0] >= k[2] {
                DVec3::new(0.0, -n.z, n.y)
            } else if k[1] >= k[0] && k[1] >= k[2] {
                DVec3::new(n.z, 0.0, -n.x)
            } else {
                DVec3::new(-n.y, n.x, 0.0)
            };
            (PlaneCase::General, s.normalize())
        }
    };
    // With the exact 0/±1 entries of rows 1–6 the cross product has Table 1's exact zeros.
    let mut t = n.cross(s);
    if case == PlaneCase::General {
        t = t.normalize();
    }
    let degrees = [direction_degree(s, k), direction_degree(t, k)];
    Some(PlaneFrame {
        case,
        n,
        s,
        t,
        degrees,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_seven_rows_of_table_1() {
        let k = [2, 3, 4];
        let (a, b) = (0.6, 0.8);
        let cases = [
            (DVec3::new(-1.0, 0.0, 0.0), PlaneCase::NormalU, [3, 4]),
            (DVec3::new(0.0, 1.0, 0.0), PlaneCase::NormalV, [4, 2]),
            (DVec3::new(0.0, 0.0, -1.0), PlaneCase::NormalW, [2, 3]),
            (DVec3::new(0.0, a, b), PlaneCase::ZeroU, [2, 7]),
            (DVec3::new(a, 0.0, -b), PlaneCase::ZeroV, [3, 6]),
            (DVec3::new(-a, b, 0.0), PlaneCase::ZeroW, [4, 5]),
            (DVec3::new(1.0, 2.0, -2.0) / 3.0, PlaneCase::General, [5, 9]),
        ];
        for (row, (n, case, deg)) in cases.into_iter().enumerate() {
            let f = plane_frame(n, k).unwrap();
            assert_eq!(f.case, case);
            assert_eq!(f.case.row(), row + 1);
            assert_eq!(f.degrees, deg, "row {}", row + 1);
            assert!((f.s.length() - 1.0).abs() < 1e-15 && (f.t.length() - 1.0).abs() < 1e-15);
            assert!(f.s.dot(f.n).abs() < 1e-15 && f.t.dot(f.n).abs() < 1e-15);
            assert!((f.s.cross(f.t) - f.n).length() < 1e-15, "right-handed");
        }
        // Row 7 picks s by the largest lattice degree.
        let n = DVec3::new(1.0, 2.0, -2.0) / 3.0;
        assert_eq!(plane_frame(n, [4, 2, 2]).unwrap().s.x, 0.0);
        assert_eq!(plane_frame(n, [4, 2, 2]).unwrap().degrees, [4, 8]);
        assert_eq!(plane_frame(n, [2, 4, 2]).unwrap().s.y, 0.0);
        assert_eq!(plane_frame(n, [2, 2, 2]).unwrap().s.x, 0.0);
        // Rounding noise in a component is snapped.
        let f = plane_frame(DVec3::new(1e-15, 1.0, -3e-14), k).unwrap();
        assert_eq!(f.case, PlaneCase::NormalV);
        assert!(plane_frame(DVec3::ZERO, k).is_none());
        assert!(plane_frame(DVec3::NAN, k).is_none());
    }
}
