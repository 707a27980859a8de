//! The one rule for direction matrices that enter volmorph: one tolerance, one
//! orthonormalisation.
//!
//! Direction matrices arrive from volume files (NIfTI stores them in single precision, DICOM
//! and text headers print them with a few decimals), from lattice files (ITK `.tfm`,
//! plastimatch `.bxf`, volmorph JSON) and from volumes handed to lattice constructors. A
//! scanner's oblique NIfTI is orthonormal only to single precision (`|DᵀD − I| ≈ 1e-8`), a
//! text header with six decimals to about `1e-6`. Every such matrix goes through
//! [`orthonormalize`] (or [`snap_direction`] where a skewed grid is legitimate, as for volume
//! geometry): a matrix whose Gram matrix deviates from the identity by at most
//! [`DIRECTION_ORTHONORMAL_TOL`] is replaced by its **polar factor**, the orthonormal matrix
//! nearest to it in the Frobenius norm (same handedness); a larger deviation means the axes
//! are really skewed.
//!
//! ```
//! use volmorph_volume::DMat3;
//! use volmorph_volume::direction::{orthonormalize, orthonormality_deviation};
//!
//! // A rotation rounded to single precision, as a NIfTI header stores it.
//! let r = DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-0.7);
//! let f32_rounded = DMat3::from_cols_array(&r.to_cols_array().map(|v| f64::from(v as f32)));
//! assert!(orthonormality_deviation(f32_rounded) > 1e-9);
//! let snapped = orthonormalize(f32_rounded)?;
//! assert!(orthonormality_deviation(snapped) < 1e-15);
//! assert!((snapped - r).abs_diff_eq(DMat3::ZERO, 1e-7));
//! // A visibly skewed matrix is refused.
//! let skew = DMat3::from_cols_array(&[1.0, 0.0, 0.0, 0.01, 1.0, 0.0, 0.0, 0.0, 1.0]);
//! assert!(orthonormalize(skew).is_err());
//! # Ok::<(), volmorph_volume::direction::NotOrthonormal>(())
//! ```

use glam::DMat3;

/// Largest deviation `max |DᵀD − I|` (element-wise) of a direction matrix that is taken as
/// orthonormal and snapped to its polar factor.
///
/// Source: ITK's NIfTI reader accepts an sform as a rotation when the column-normalised
/// `R·Rᵀ = I` holds within 1e-4 (`itkNiftiImageIO.cxx`); volmorph uses the same bound for
/// every direction, which covers single-precision headers (≈1e-8), text with six decimals
/// (≈1e-6) and DICOM orientation strings, while any skew visible at the scale of a voxel
/// grid (a shear of 0.01° is 1.7e-4) is reported.
pub const DIRECTION_ORTHONORMAL_TOL: f64 = 1e-4;

/// Deviations at or below this are left untouched by [`orthonormalize`]: matrices that are
/// orthonormal to rounding (a few units in the last place of `f64`) keep their bits.
const EXACT_TOL: f64 = 4.0 * f64::EPSILON;

/// A direction matrix whose axes are not orthonormal within [`DIRECTION_ORTHONORMAL_TOL`]
/// (or are not finite).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error(
    "direction axes are not orthonormal: max |DᵀD − I| = {deviation:e} exceeds the tolerance \
     {DIRECTION_ORTHONORMAL_TOL:e}"
)]
pub struct NotOrthonormal {
    /// The measured deviation `max |DᵀD − I|` (NaN for a non-finite matrix).
    pub deviation: f64,
}

/// `max |DᵀD − I|` over the nine entries; NaN if `d` is not finite.
#[must_use]
pub fn orthonormality_deviation(d: DMat3) -> f64 {
    if !d.is_finite() {
        return f64::NAN;
    }
    (d.transpose() * d - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// The polar factor of `d` (the nearest orthonormal matrix, same determinant sign) when `d`
/// is orthonormal within [`DIRECTION_ORTHONORMAL_TOL`]; `d` itself, bit for bit, when it is
/// already orthonormal to rounding.
///
/// The factor is computed by Newton's iteration `X ← (X + X⁻ᵀ)/2`, which converges
/// quadratically from a nearly orthonormal start (three or four steps from 1e-4).
///
/// # Errors
/// [`NotOrthonormal`] when the deviation exceeds the tolerance or `d` is not finite.
pub fn orthonormalize(d: DMat3) -> Result<DMat3, NotOrthonormal> {
    let deviation = orthonormality_deviation(d);
    if deviation.is_nan() || deviation > DIRECTION_ORTHONORMAL_TOL {
        return Err(NotOrthonormal { deviation });
    }
    if deviation <= EXACT_TOL {
        return Ok(d);
    }
    let mut x = d;
    for _ in 0..8 {
        let next = (x + x.inverse().transpose()) * 0.5;
        let step = (next - x)
            .to_cols_array()
            .iter()
            .fold(0.0_f64, |m, v| m.max(v.abs()));
        x = next;
        if step <= EXACT_TOL {
            break;
        }
    }
    Ok(x)
}

/// [`orthonormalize`] where a skewed matrix is legitimate (volume geometry: ITK allows sheared
/// grids, e.g. a tilted-gantry CT): the polar factor within the tolerance, `d` unchanged
/// otherwise.
#[must_use]
pub fn snap_direction(d: DMat3) -> DMat3 {
    orthonormalize(d).unwrap_or(d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn rounded_f32(m: DMat3) -> DMat3 {
        DMat3::from_cols_array(&m.to_cols_array().map(|v| f64::from(v as f32)))
    }

    #[test]
    fn single_precision_rotations_snap_to_the_nearest_rotation() {
        for (a, b) in [(0.3, -0.7), (1.1, 0.2), (-2.0, 2.5)] {
            let r = DMat3::from_rotation_z(a) * DMat3::from_rotation_x(b);
            for m in [r, -r, r * DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0))] {
                let s = orthonormalize(rounded_f32(m)).unwrap();
                assert!(orthonormality_deviation(s) <= 1e-15);
                assert!((s - m).abs_diff_eq(DMat3::ZERO, 2e-7), "{s} vs {m}");
                assert_eq!(s.determinant().signum(), m.determinant().signum());
            }
        }
    }

    #[test]
    fn orthonormal_matrices_keep_their_bits() {
        let r = DMat3::from_rotation_y(0.4);
        assert_eq!(orthonormalize(r).unwrap(), r);
        assert_eq!(orthonormalize(DMat3::IDENTITY).unwrap(), DMat3::IDENTITY);
    }

    #[test]
    fn polar_factor_is_the_nearest_orthonormal_matrix() {
        // A symmetric perturbation of I: the polar factor of (I + εS) is I to first order.
        let s = DMat3::from_cols_array(&[0.0, 3e-5, 0.0, 3e-5, 0.0, -2e-5, 0.0, -2e-5, 0.0]);
        let p = orthonormalize(DMat3::IDENTITY + s).unwrap();
        assert!((p - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-9));
        // A skew-symmetric perturbation rotates: the polar factor keeps it.
        let w = DMat3::from_cols_array(&[0.0, 4e-5, 0.0, -4e-5, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let p = orthonormalize(DMat3::IDENTITY + w).unwrap();
        assert!((p - DMat3::from_rotation_z(4e-5)).abs_diff_eq(DMat3::ZERO, 1e-9));
    }

    #[test]
    fn skewed_and_non_finite_matrices_are_refused() {
        let skew = DMat3::from_cols_array(&[1.0, 0.0, 0.0, 2e-4, 1.0, 0.0, 0.0, 0.0, 1.0]);
        let e = orthonormalize(skew).unwrap_err();
        assert!((e.deviation - 2e-4).abs() < 1e-12);
        assert_eq!(snap_direction(skew), skew);
        assert!(orthonormalize(DMat3::from_diagonal(DVec3::new(1.0, f64::NAN, 1.0))).is_err());
        assert!(orthonormalize(DMat3::ZERO).is_err());
    }
}
