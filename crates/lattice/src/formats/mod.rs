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
//! room for (see each module). On import a direction matrix that deviates from orthonormal by
//! at most [`DIRECTION_ORTHONORMAL_TOL`] (the rounding of files written with 6 decimals or in
//! single precision) is snapped to the nearest orthonormal matrix by the one rule of
//! [`volmorph_volume::direction`].
//!
//! **Skewed lattices** (Sederberg–Parry parallelepipeds, [`LatticeFrame::skewed`]): ITK's
//! `BSplineTransform` takes any invertible direction matrix (it maps points to the grid by
//! `D⁻¹`, as the model above does with `D⁻¹` in place of `Dᵀ`), so `.tfm` files carry skewed
//! frames both ways: a skewed lattice is written with its unit axes as the direction, and a
//! file whose direction is not orthonormal reads as a skewed lattice. plastimatch's `.bxf`
//! evaluates its direction cosines only as a rotation, so skewed lattices are refused there
//! ([`DeformError::Unsupported`]) and a `.bxf` with non-orthonormal direction cosines is a
//! parse error.
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
#[cfg(doc)]
use volmorph_volume::direction::DIRECTION_ORTHONORMAL_TOL;
use volmorph_volume::direction::orthonormalize;

/// A lattice seen as a uniform cubic control grid (the common model of the module docs).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct UniformGrid {
    /// Control points per axis.
    pub size: [usize; 3],
    /// Physical position of control point `(0, 0, 0)` in the identity placement.
    pub origin: DVec3,
    /// Physical control-point spacing per axis.
    pub spacing: DVec3,
    /// Unit directions (columns) of the index axes; orthonormal unless the lattice is skewed.
    pub axes: DMat3,
    /// Displacement coefficients, index `i` fastest.
    pub coefficients: Vec<DVec3>,
}

impl UniformGrid {
    /// The grid of `lat`, or [`DeformError::Unsupported`] naming why `format` cannot hold it.
    pub fn from_lattice(lat: &BSplineLattice, format: &str) -> Result<Self, DeformError> {
        let frame = lat.frame();
        if frame.is_skewed() && format.contains("bxf") {
            return Err(DeformError::Unsupported(format!(
                "{format} holds rotated grids only; this lattice is skewed (axes {}): write it \
                 as .json or ITK .tfm",
                frame.axes()
            )));
        }
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
        let frame = LatticeFrame::skewed(
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

/// Axes (columns) from a row-major direction matrix `rows[3r + c] = D[r][c]` (column `c` is
/// the direction of index axis `c`), snapped to the nearest orthonormal matrix by
/// [`orthonormalize`] (within [`DIRECTION_ORTHONORMAL_TOL`]). A matrix further from
/// orthonormal is returned as it is when `skew` allows skewed frames (its validity is checked
/// by [`LatticeFrame::skewed`], a degenerate one is a parse error), and is a parse error
/// otherwise.
pub(crate) fn axes_from_rows(
    rows: [f64; 9],
    format: &'static str,
    line: usize,
    skew: bool,
) -> Result<DMat3, DeformError> {
    let d = DMat3::from_cols_array(&rows).transpose();
    match orthonormalize(d) {
        Ok(axes) => Ok(axes),
        Err(_) if skew && d.is_finite() => match LatticeFrame::skewed(DVec3::ZERO, d, DVec3::ONE) {
            Ok(_) => Ok(d),
            Err(e) => Err(DeformError::Parse {
                format,
                line,
                message: format!("direction matrix {rows:?}: {e}"),
            }),
        },
        Err(e) => Err(DeformError::Parse {
            format,
            line,
            message: format!("direction matrix {rows:?}: {e}"),
        }),
    }
}

/// Row-major entries `D[r][c]` of the axes matrix (columns are axis directions).
pub(crate) fn rows_of(axes: DMat3) -> [f64; 9] {
    axes.transpose().to_cols_array()
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
    let read = || match lattice_extension(path)?.as_str() {
        "json" => BSplineLattice::from_json(&read_text(path, "lattice JSON")?),
        "bxf" => bxf::read_bxf(path),
        _ => itk_tfm::read_itk_tfm(path),
    };
    read().map_err(|e| e.at(path))
}

/// The extensions [`write_lattice`] writes (without the dot): lattice JSON, ITK text
/// transforms (`.tfm`, `.txt`) and plastimatch `.bxf`.
pub const WRITE_EXTENSIONS: &[&str] = &["json", "tfm", "txt", "bxf"];

/// Check that `path` ends in one of [`WRITE_EXTENSIONS`] (any case) before a lattice is built
/// for it.
///
/// # Errors
/// [`DeformError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
/// extension found and [`WRITE_EXTENSIONS`].
pub fn check_output(path: &Path) -> Result<(), DeformError> {
    Ok(volmorph_io::extension::check(path, WRITE_EXTENSIONS)?)
}

/// Write a lattice file atomically; the format follows the extension as in [`read_lattice`].
///
/// # Errors
/// [`DeformError::Io`] with [`volmorph_io::IoError::Extension`] for another extension
/// ([`check_output`], nothing written); [`DeformError::Unsupported`] for a lattice the format
/// cannot hold; I/O errors naming the path.
pub fn write_lattice(path: &Path, lattice: &BSplineLattice) -> Result<(), DeformError> {
    check_output(path)?;
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
    let bytes = volmorph_io::read_maybe_gz(path)?;
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
