//! ITK `BSplineTransform` text transform files (`.tfm`, `.txt`).
//!
//! # Layout
//!
//! ```text
//! #Insight Transform File V1.0
//! #Transform 0
//! Transform: BSplineTransform_double_3_3
//! Parameters: c0x c1x … c(N−1)x c0y … c(N−1)y c0z … c(N−1)z
//! FixedParameters: n0 n1 n2 o0 o1 o2 s0 s1 s2 D00 D01 D02 D10 D11 D12 D20 D21 D22
//! ```
//!
//! * `Parameters` are the `3N` displacement coefficients (`N = n0·n1·n2` control points, in
//!   physical units): the x components of all control points, index `i` fastest over the
//!   control grid, then all y components, then all z components.
//! * `FixedParameters` are the control-grid size `n` (control points per axis, the transform
//!   domain's mesh size plus 3), the grid origin `o` (physical position of control point
//!   `(0, 0, 0)`), the grid spacing `s`, and the direction matrix **row-major**
//!   (`D[r][c]`, column `c` = physical direction of grid index axis `c`).
//! * ITK evaluates `T(x) = x + Σ β(g₀−i)β(g₁−j)β(g₂−k) c_ijk` with continuous grid index
//!   `g = diag(1/s)·D⁻¹·(x − o)` and returns `x` unchanged outside the transform domain
//!   `g ∈ [1, n − 2]` per axis (closed on both ends), i.e. one spacing inside the first and
//!   last control points. `BSplineTransformInitializer` places `o` one spacing before the
//!   image's physical bounding box, so the domain covers the image.
//!
//! This is the common model of the [parent module](super): a volmorph lattice with True's
//! uniform cubic knots and frame `F` has `o = F(−1, −1, −1)`, `s = spacing`, `D = axes` and
//! `c_ijk = P_ijk − F(i − 1, j − 1, k − 1)`; a read lattice has frame origin `o + D·s` (ITK's
//! `TransformDomainOrigin`).
//!
//! These conventions were checked against ITK's `itkBSplineTransform.hxx` (fixed-parameter
//! order; direction read as `D[r][c] = fixed[9 + 3r + c]`, row-major — the comment at the top
//! of that file lists the entries column by column, the code does not; grid origin = domain
//! origin − `D·(s·(order − 1)/2)`; grid size = mesh size + order) and empirically with
//! SimpleITK 2.5 (ITK 5.4), whose `BSplineTransformInitializer` writes exactly this layout:
//! `TransformPoint` agrees with the lattice's [`apply`](volmorph_deform::SpaceMap::apply) to rounding
//! (the reference values are in the crate's tests; `scripts/itk_bspline_check.py` repeats the
//! comparison on random lattices).
//!
//! # Accepted and refused
//!
//! Read: a single `BSplineTransform_double_3_3` or `BSplineTransform_float_3_3` (spline order 3,
//! also spelled `…_3_3_3`), whatever the file extension. Composite transforms, transform
//! lists, other transform types (including the legacy `BSplineDeformableTransform`), other
//! dimensions and other spline orders are [`DeformError::Unsupported`]; text that does not
//! follow the layout is [`DeformError::Parse`] with the line number. HDF5 (`.h5`, `.hdf5`) and
//! MATLAB (`.mat`) transform files are binary and refused by extension.
//!
//! Write: degree-3 lattices with uniform knot vectors (see the parent module); anything else
//! is [`DeformError::Unsupported`]. Numbers are written with the shortest text that reads
//! back to the same `f64`.

use std::fmt::Write as _;
use std::path::Path;

use glam::DVec3;

use super::{
    UniformGrid, axes_from_rows, checked_grid_len, fmt_f64, parse_f64, read_text, rows_of,
    write_text,
};
use crate::BSplineLattice;
use volmorph_deform::DeformError;

/// Format name used in error messages.
const FORMAT: &str = "ITK transform";

/// First line of an ITK text transform file.
pub const ITK_TFM_HEADER: &str = "#Insight Transform File V1.0";

/// Transform type written by [`itk_tfm_to_string`].
pub const ITK_BSPLINE_TYPE: &str = "BSplineTransform_double_3_3";

fn err(line: usize, message: impl Into<String>) -> DeformError {
    DeformError::Parse {
        format: FORMAT,
        line,
        message: message.into(),
    }
}

/// Check a `Transform:` type name, refusing everything but a 3-D cubic `BSplineTransform`.
fn check_type(name: &str) -> Result<(), DeformError> {
    let Some(rest) = name.strip_prefix("BSplineTransform_") else {
        if name.starts_with("CompositeTransform") {
            return Err(DeformError::Unsupported(format!(
                "{name}: composite transforms are not read; save the B-spline component alone"
            )));
        }
        if name.starts_with("BSplineDeformableTransform") {
            return Err(DeformError::Unsupported(format!(
                "{name}: the legacy BSplineDeformableTransform is not read; \
                 convert it to a BSplineTransform"
            )));
        }
        return Err(DeformError::Unsupported(format!(
            "transform type {name}; only BSplineTransform_double_3_3 is read"
        )));
    };
    let parts: Vec<&str> = rest.split('_').collect();
    match parts.as_slice() {
        ["double" | "float", "3", "3"] | ["double" | "float", "3", "3", "3"] => Ok(()),
        [_, a, b, order] if *a == "3" && *b == "3" => Err(DeformError::Unsupported(format!(
            "{name}: spline order {order}; only cubic (order 3) B-splines are read"
        ))),
        _ => Err(DeformError::Unsupported(format!(
            "{name}: only 3-D double or float BSplineTransforms are read"
        ))),
    }
}

/// Parse the text of an ITK transform file holding one 3-D cubic `BSplineTransform` into the
/// equivalent lattice (see the [module docs](self)).
///
/// # Errors
/// [`DeformError::Parse`] (with the line) for a missing header, missing or repeated fields,
/// non-numeric or non-finite values, a wrong number of parameters, a grid size below 4 or
/// non-integral, a non-positive spacing or a non-finite direction matrix (a direction that is
/// not orthonormal gives a skewed lattice; a degenerate one is [`DeformError::InvalidFrame`]);
/// [`DeformError::Unsupported`] for composite transforms, several transforms, or other
/// transform types / dimensions / spline orders.
pub fn parse_itk_tfm(text: &str) -> Result<BSplineLattice, DeformError> {
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    match lines.by_ref().find(|(_, l)| !l.is_empty()) {
        Some((_, l)) if l.starts_with("#Insight Transform File") => {}
        Some((n, l)) => {
            return Err(err(
                n,
                format!("expected '{ITK_TFM_HEADER}', found '{}'", truncate(l)),
            ));
        }
        None => return Err(err(0, "empty file")),
    }
    let mut transform: Option<(usize, &str)> = None;
    let mut params: Option<(usize, &str)> = None;
    let mut fixed: Option<(usize, &str)> = None;
    let mut count = 0usize;
    for (n, l) in lines {
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let Some((key, value)) = l.split_once(':') else {
            return Err(err(
                n,
                format!("expected 'Key: values', found '{}'", truncate(l)),
            ));
        };
        let value = value.trim();
        match key.trim() {
            "Transform" => {
                count += 1;
                if count > 1 {
                    return Err(DeformError::Unsupported(format!(
                        "line {n}: the file holds several transforms; only a single \
                         BSplineTransform is read"
                    )));
                }
                check_type(value)?;
                transform = Some((n, value));
                params = None;
                fixed = None;
            }
            "Parameters" | "FixedParameters" if transform.is_none() => {
                return Err(err(
                    n,
                    format!("{} before any 'Transform:' line", key.trim()),
                ));
            }
            "Parameters" => {
                if params.replace((n, value)).is_some() {
                    return Err(err(n, "second 'Parameters:' line"));
                }
            }
            "FixedParameters" => {
                if fixed.replace((n, value)).is_some() {
                    return Err(err(n, "second 'FixedParameters:' line"));
                }
            }
            other => return Err(err(n, format!("unknown field '{}'", truncate(other)))),
        }
    }
    let Some((tline, _)) = transform else {
        return Err(err(0, "no 'Transform:' line"));
    };
    let (fline, fixed) = fixed.ok_or_else(|| err(tline, "no 'FixedParameters:' line"))?;
    let (pline, params) = params.ok_or_else(|| err(tline, "no 'Parameters:' line"))?;

    let fp = fixed
        .split_whitespace()
        .map(|t| parse_f64(t, FORMAT, fline))
        .collect::<Result<Vec<f64>, _>>()?;
    let fp: [f64; 18] = fp.as_slice().try_into().map_err(|_| {
        err(
            fline,
            format!(
                "FixedParameters of a 3-D BSplineTransform are 18 numbers (size, origin, \
                 spacing, direction), found {}",
                fp.len()
            ),
        )
    })?;
    let mut size = [0usize; 3];
    for a in 0..3 {
        let v = fp[a];
        if !(v.fract() == 0.0 && (0.0..=u32::MAX as f64).contains(&v)) {
            return Err(err(
                fline,
                format!(
                    "grid size {} along axis {a} is not an integer from 0 to {}",
                    volmorph_io::Num(v),
                    u32::MAX
                ),
            ));
        }
        size[a] = v as usize;
    }
    let len = checked_grid_len(size, FORMAT, fline)?;
    let origin = DVec3::new(fp[3], fp[4], fp[5]);
    let spacing = DVec3::new(fp[6], fp[7], fp[8]);
    if spacing.min_element() <= 0.0 {
        return Err(err(
            fline,
            format!(
                "grid spacing {} must be > 0",
                volmorph_io::Nums(&spacing.to_array())
            ),
        ));
    }
    let mut rows = [0.0; 9];
    rows.copy_from_slice(&fp[9..]);
    let axes = axes_from_rows(rows, FORMAT, fline, true)?;

    // Count before allocating: the allocation is bounded by the text, not by the header.
    let found = params.split_whitespace().count();
    if found != 3 * len {
        return Err(err(
            pline,
            format!(
                "a grid of {size:?} control points needs {} parameters, found {found}",
                3 * len
            ),
        ));
    }
    let mut coefficients = vec![DVec3::ZERO; len];
    for (m, tok) in params.split_whitespace().enumerate() {
        coefficients[m % len][m / len] = parse_f64(tok, FORMAT, pline)?;
    }
    UniformGrid {
        size,
        origin,
        spacing,
        axes,
        coefficients,
    }
    .into_lattice()
}

/// Read an ITK text transform file (`.tfm` or `.txt`); see [`parse_itk_tfm`].
///
/// # Errors
/// [`DeformError::Io`] if the file cannot be read, [`DeformError::Unsupported`] for binary
/// (`.h5`, `.hdf5`, `.mat`) transform files, and the errors of [`parse_itk_tfm`].
pub fn read_itk_tfm(path: &Path) -> Result<BSplineLattice, DeformError> {
    check_extension(path)?;
    parse_itk_tfm(&read_text(path, FORMAT)?)
}

/// The ITK text transform file of `lattice` (see the [module docs](self)).
///
/// # Errors
/// [`DeformError::Unsupported`] if a lattice axis is not cubic or its knots are not uniform.
pub fn itk_tfm_to_string(lattice: &BSplineLattice) -> Result<String, DeformError> {
    let g = UniformGrid::from_lattice(lattice, "an ITK BSplineTransform")?;
    let mut s = String::with_capacity(64 + g.coefficients.len() * 3 * 24);
    s.push_str(ITK_TFM_HEADER);
    s.push_str("\n#Transform 0\nTransform: ");
    s.push_str(ITK_BSPLINE_TYPE);
    s.push_str("\nParameters:");
    for c in 0..3 {
        for p in &g.coefficients {
            s.push(' ');
            s.push_str(&fmt_f64(p[c]));
        }
    }
    s.push_str("\nFixedParameters:");
    let fixed = g
        .size
        .map(|n| n as f64)
        .into_iter()
        .chain(g.origin.to_array())
        .chain(g.spacing.to_array())
        .chain(rows_of(g.axes));
    for v in fixed {
        let _ = write!(s, " {}", fmt_f64(v));
    }
    s.push('\n');
    Ok(s)
}

/// Write `lattice` as an ITK text transform file, atomically (temporary file + rename).
///
/// # Errors
/// [`DeformError::Unsupported`] for a lattice ITK cannot represent (see
/// [`itk_tfm_to_string`]) or a binary transform extension (`.h5`, `.hdf5`, `.mat`: ITK would
/// expect HDF5 / MATLAB content there); [`DeformError::Io`] with
/// [`volmorph_io::IoError::Extension`] for any other extension but `.tfm` and `.txt` (nothing
/// written); [`DeformError::Io`] if writing fails.
pub fn write_itk_tfm(path: &Path, lattice: &BSplineLattice) -> Result<(), DeformError> {
    check_extension(path)?;
    volmorph_io::extension::OutputFormat::ItkTransform.check(path)?;
    write_text(path, &itk_tfm_to_string(lattice)?)
}

fn check_extension(path: &Path) -> Result<(), DeformError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some(e @ ("h5" | "hdf5" | "hdf" | "mat")) => Err(DeformError::Unsupported(format!(
            "{}: .{e} transform files are binary; only ITK text transform files (.tfm, .txt) \
             are supported",
            path.display()
        ))),
        _ => Ok(()),
    }
}

/// At most 60 characters of `s`, for error messages.
fn truncate(s: &str) -> String {
    let mut t: String = s.chars().take(60).collect();
    if t.len() < s.len() {
        t.push('…');
    }
    t
}
