//! Import and export of cubic B-spline lattices in the transform formats of other toolkits.
//!
//! * [`itk_tfm`] — ITK `BSplineTransform` text transform files (`.tfm`, `.txt`).
//! * [`bxf`] — plastimatch native B-spline transforms (`.bxf`, `MGH_GPUIT_BSP`).
//!
//! # The common model: a displacement field on a uniform control grid
//!
//! Both formats describe the map
//!
//! ```text
//! x ↦ x + Σ_ijk β(g₀ − i) β(g₁ − j) β(g₂ − k) c_ijk,    g = diag(1/s) · Dᵀ · (x − o)
//! ```
//!
//! where `β` is the centred uniform cubic B-spline (support `[−2, 2]`), `o` is the physical
//! position of control point `(0, 0, 0)`, `s` the physical control-point spacing, `D` the
//! orthonormal direction matrix (columns: physical directions of the grid's index axes) and
//! `c_ijk` are **displacement** coefficients in physical coordinates. Points outside the
//! transform's domain are not moved.
//!
//! A volmorph [`BSplineLattice`] with True's uniform cubic knots (integers `−3 … n`, control
//! point `i` at parameter `i − 1`, domain `[0, n − 3]`) and frame `F(u) = origin +
//! axes·(spacing ⊙ u)` is exactly this map with
//!
//! ```text
//! o = F(−1, −1, −1),   s = spacing,   D = axes,   c_ijk = P_ijk − F(i − 1, j − 1, k − 1)
//! ```
//!
//! because the basis function of control point `i` is `N_i(u) = β(u − (i − 1)) = β(g − i)`
//! with `g = u + 1`, and on the domain `Σ N_i(u) F(ξ_i) = F(u) = x` (linear precision from the
//! Greville abscissae, partition of unity). The domain `u ∈ [0, n − 3]` is `g ∈ [1, n − 2]`:
//! one control-point spacing inside the first and last control points, as in both formats.
//! More generally, any degree-3 lattice whose knot vectors are uniform (knots `a + (j − 3)h`,
//! all distinct) is written by scaling: `s = spacing ⊙ h`, `o = F(a − h)`.
//!
//! Readers always return lattices with True's integer knots `−3 … n` and frame origin at the
//! start of the transform domain (`o + D·s`), so a write/read round trip reproduces a lattice
//! made by [`BSplineLattice::uniform_cubic_around`] up to rounding of the last bit.
//!
//! Lattices these formats cannot represent are refused with [`DeformError::Unsupported`]:
//! degrees other than 3, knot vectors that are not uniform, and frames the format has no
//! room for (see each module). Every frame of a volmorph lattice is orthonormal, so the
//! direction matrix never needs approximating on export; on import a direction matrix that
//! deviates from orthonormal by at most [`DIRECTION_TOL`] (the rounding of files written with
//! 6 decimals) is snapped to the nearest orthonormal matrix, a larger deviation is an error.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_lattice::formats::{bxf, itk_tfm};
//! use volmorph_deform::SpaceMap;
//! use volmorph_lattice::BSplineLattice;
//! let mut lat =
//!     BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::new(40.0, 30.0, 20.0), [7, 6, 5])
//!         .unwrap();
//! lat.move_control_point([3, 2, 2], DVec3::new(1.5, 0.0, -0.5)).unwrap();
//! // The ITK file stores the displacement of each control point, x components first.
//! let text = itk_tfm::itk_tfm_to_string(&lat).unwrap();
//! let from_itk = itk_tfm::parse_itk_tfm(&text).unwrap();
//! let from_bxf = bxf::parse_bxf(&bxf::bxf_to_string(&lat).unwrap()).unwrap();
//! let p = DVec3::new(20.0, 13.0, 9.0);
//! assert!((from_itk.apply(p) - lat.apply(p)).length() < 1e-12);
//! assert!((from_bxf.apply(p) - lat.apply(p)).length() < 1e-12);
//! ```
//!
//! [`BSplineLattice`]: crate::BSplineLattice
//! [`BSplineLattice::uniform_cubic_around`]: crate::BSplineLattice::uniform_cubic_around

pub mod bxf;
pub mod itk_tfm;

use std::path::Path;

use glam::{DMat3, DVec3};

use crate::json::MAX_CONTROL_POINTS;
use crate::lattice::uniform_cubic_knots;
use crate::{BSplineLattice, LatticeFrame};
use volmorph_deform::DeformError;

/// Largest deviation `max |DᵀD − I|` of a direction matrix read from a file that is accepted
/// (and then snapped to the nearest orthonormal matrix). Files that print directions with six
/// decimals deviate by about `1e-6`.
pub const DIRECTION_TOL: f64 = 1e-4;

/// A lattice seen as a uniform cubic control grid (the common model of the module docs).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct UniformGrid {
    /// Control points per axis.
    pub size: [usize; 3],
    /// Physical position of control point `(0, 0, 0)` in the identity placement.
    pub origin: DVec3,
    /// Physical control-point spacing per axis.
    pub spacing: DVec3,
    /// Orthonormal directions (columns) of the index axes.
    pub axes: DMat3,
    /// Displacement coefficients, index `i` fastest.
    pub coefficients: Vec<DVec3>,
}

impl UniformGrid {
    /// The grid of `lat`, or [`DeformError::Unsupported`] naming why `format` cannot hold it.
    pub fn from_lattice(lat: &BSplineLattice, format: &str) -> Result<Self, DeformError> {
        let frame = lat.frame();
        let mut start = DVec3::ZERO;
        let mut step = DVec3::ZERO;
        for (a, kv) in lat.knots().iter().enumerate() {
            if kv.degree() != 3 {
                return Err(DeformError::Unsupported(format!(
                    "{format} holds cubic B-splines only; lattice axis {a} has degree {}",
                    kv.degree()
                )));
            }
            let t = kv.knots();
            let n = lat.counts()[a];
            let [lo, hi] = kv.domain();
            let h = (hi - lo) / (n - 3) as f64;
            let tol = 1e-9 * h + 8.0 * f64::EPSILON * lo.abs().max(hi.abs());
            for (j, &tj) in t.iter().enumerate() {
                let expected = lo + (j as f64 - 3.0) * h;
                if (tj - expected).abs() > tol {
                    return Err(DeformError::Unsupported(format!(
                        "{format} needs uniformly spaced knots; lattice axis {a} has knot {j} \
                         at {tj}, a uniform vector would have {expected}"
                    )));
                }
            }
            start[a] = lo - h;
            step[a] = h;
        }
        let origin = frame.to_physical(start);
        let spacing = frame.spacing() * step;
        if !(origin.is_finite() && spacing.is_finite()) {
            return Err(DeformError::Unsupported(format!(
                "{format}: grid origin {origin} or spacing {spacing} overflows"
            )));
        }
        let size = lat.counts();
        let mut coefficients = Vec::with_capacity(size[0] * size[1] * size[2]);
        for k in 0..size[2] {
            for j in 0..size[1] {
                for i in 0..size[0] {
                    coefficients.push(lat.displacement([i, j, k])?);
                }
            }
        }
        Ok(Self {
            size,
            origin,
            spacing,
            axes: frame.axes(),
            coefficients,
        })
    }

    /// The lattice of this grid: True's integer knots `−3 … n`, frame origin at
    /// `origin + axes·spacing` (the start of the domain), control points at their identity
    /// places plus the coefficients.
    pub fn into_lattice(self) -> Result<BSplineLattice, DeformError> {
        let frame = LatticeFrame::new(
            self.origin + self.axes * self.spacing,
            self.axes,
            self.spacing,
        )?;
        let knots = uniform_cubic_knots(self.size)?;
        let mut points = self.coefficients;
        let [nx, ny, _] = self.size;
        for (lin, p) in points.iter_mut().enumerate() {
            let u = DVec3::new(
                (lin % nx) as f64 - 1.0,
                (lin / nx % ny) as f64 - 1.0,
                (lin / (nx * ny)) as f64 - 1.0,
            );
            *p += frame.to_physical(u);
        }
        BSplineLattice::from_parts(frame, knots, &points)
    }
}

/// Number of control points of a grid of `size`, refusing sizes below 4 per axis or above
/// [`MAX_CONTROL_POINTS`] in total.
pub(crate) fn checked_grid_len(
    size: [usize; 3],
    format: &'static str,
    line: usize,
) -> Result<usize, DeformError> {
    for (a, &n) in size.iter().enumerate() {
        if n < 4 {
            return Err(DeformError::Parse {
                format,
                line,
                message: format!("axis {a} has {n} control points; a cubic grid needs at least 4"),
            });
        }
    }
    size.iter()
        .try_fold(1usize, |acc, &n| acc.checked_mul(n))
        .filter(|&t| t <= MAX_CONTROL_POINTS)
        .ok_or_else(|| DeformError::Parse {
            format,
            line,
            message: format!("grid of {size:?} control points exceeds {MAX_CONTROL_POINTS}"),
        })
}

/// Orthonormal axes (columns) from a row-major direction matrix `rows[3r + c] = D[r][c]`
/// (column `c` is the direction of index axis `c`), snapped to the nearest orthonormal matrix
/// when the deviation is at most [`DIRECTION_TOL`].
pub(crate) fn axes_from_rows(
    rows: [f64; 9],
    format: &'static str,
    line: usize,
) -> Result<DMat3, DeformError> {
    let d = DMat3::from_cols_array(&rows).transpose();
    let dev = gram_deviation(d);
    if dev.is_nan() || dev > DIRECTION_TOL {
        return Err(DeformError::Parse {
            format,
            line,
            message: format!(
                "direction matrix {rows:?} is not orthonormal (max |DᵀD − I| = {dev:e})"
            ),
        });
    }
    if dev <= crate::lattice::FRAME_ORTHONORMAL_TOL {
        return Ok(d);
    }
    // Polar decomposition by Newton's iteration X ← (X + X⁻ᵀ)/2: converges quadratically to
    // the orthonormal factor (the nearest orthonormal matrix) from a nearly orthonormal start.
    let mut x = d;
    for _ in 0..8 {
        x = (x + x.inverse().transpose()) * 0.5;
        if gram_deviation(x) <= 1e-15 {
            break;
        }
    }
    Ok(x)
}

/// Row-major entries `D[r][c]` of the axes matrix (columns are axis directions).
pub(crate) fn rows_of(axes: DMat3) -> [f64; 9] {
    axes.transpose().to_cols_array()
}

fn gram_deviation(d: DMat3) -> f64 {
    (d.transpose() * d - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(
            0.0_f64,
            |m, v| if v.is_nan() { f64::NAN } else { m.max(v.abs()) },
        )
}

pub(crate) use volmorph_io::fmt_f64;

/// Parse one number token.
pub(crate) fn parse_f64(tok: &str, format: &'static str, line: usize) -> Result<f64, DeformError> {
    let v: f64 = tok.parse().map_err(|_| DeformError::Parse {
        format,
        line,
        message: format!("'{tok}' is not a number"),
    })?;
    if !v.is_finite() {
        return Err(DeformError::Parse {
            format,
            line,
            message: format!("'{tok}' is not a finite number"),
        });
    }
    Ok(v)
}

/// Read a whole text file.
/// Read a lattice file; the format follows the extension: `.json` (volmorph's own, see
/// [`crate::json`]), `.tfm`/`.txt` (ITK, [`itk_tfm`]) or `.bxf` (plastimatch, [`bxf`]).
///
/// # Errors
/// [`DeformError::Unsupported`] for another extension; the format reader's errors otherwise.
pub fn read_lattice(path: &Path) -> Result<BSplineLattice, DeformError> {
    match lattice_extension(path)?.as_str() {
        "json" => BSplineLattice::from_json(&read_text(path, "lattice JSON")?),
        "bxf" => bxf::read_bxf(path),
        _ => itk_tfm::read_itk_tfm(path),
    }
}

/// Write a lattice file atomically; the format follows the extension as in [`read_lattice`].
///
/// # Errors
/// [`DeformError::Unsupported`] for another extension or a lattice the format cannot hold;
/// I/O errors naming the path.
pub fn write_lattice(path: &Path, lattice: &BSplineLattice) -> Result<(), DeformError> {
    match lattice_extension(path)?.as_str() {
        "json" => write_text(path, &lattice.to_json()?),
        "bxf" => bxf::write_bxf(path, lattice),
        _ => itk_tfm::write_itk_tfm(path, lattice),
    }
}

fn lattice_extension(path: &Path) -> Result<String, DeformError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if matches!(ext.as_str(), "json" | "tfm" | "txt" | "bxf") {
        Ok(ext)
    } else {
        Err(DeformError::Unsupported(format!(
            "{}: unknown lattice format (expected .json, .tfm, .txt or .bxf)",
            path.display()
        )))
    }
}

pub(crate) fn read_text(path: &Path, format: &'static str) -> Result<String, DeformError> {
    let bytes = std::fs::read(path).map_err(|e| volmorph_io::IoError::os(path, e))?;
    String::from_utf8(bytes).map_err(|e| DeformError::Parse {
        format,
        line: 0,
        message: format!(
            "{} is not UTF-8 text (invalid byte at offset {})",
            path.display(),
            e.utf8_error().valid_up_to()
        ),
    })
}

/// Write `text` to `path` atomically.
pub(crate) fn write_text(path: &Path, text: &str) -> Result<(), DeformError> {
    volmorph_io::write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| DeformError::Io(volmorph_io::IoError::os(path, e)))
    })
}
