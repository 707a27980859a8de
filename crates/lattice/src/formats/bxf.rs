//! plastimatch native B-spline transforms (`.bxf`).
//!
//! # Layout
//!
//! ```text
//! MGH_GPUIT_BSP <experimental>
//! img_origin = o0 o1 o2
//! img_spacing = s0 s1 s2
//! img_dim = d0 d1 d2
//! roi_offset = r0 r1 r2
//! roi_dim = m0 m1 m2
//! vox_per_rgn = v0 v1 v2
//! direction_cosines = D00 D01 D02 D10 D11 D12 D20 D21 D22
//! c0x
//! …
//! ```
//!
//! * `img_*` describe the image grid the transform was made for: voxel `ijk` is at the physical
//!   point `img_origin + D·(img_spacing ⊙ ijk)` with the direction cosines `D` stored
//!   **row-major** (`D[r][c]`, column `c` = direction of voxel index axis `c`; plastimatch's
//!   `step[3r + c] = dc[3r + c]·spacing[c]`, the same convention as ITK). Coordinates are
//!   physical (LPS, as in ITK); the format stores no handedness of its own.
//!   `direction_cosines` is absent in files from before 2012; it then defaults to `I`.
//! * The B-spline region of interest starts at voxel `roi_offset` (read only when `0 0 0`, see
//!   below) and spans `roi_dim` voxels; it is cut into regions of `vox_per_rgn` voxels. There are `r = 1 + (roi_dim − 1) /
//!   vox_per_rgn` regions (integer division, i.e. `⌈roi_dim / vox_per_rgn⌉`) and `r + 3`
//!   control points per axis.
//! * A voxel at ROI offset `t` (voxels) lies in region `p = ⌊t / vox_per_rgn⌋` at fraction
//!   `q = t / vox_per_rgn − p` and is displaced by `Σ B_a(q) c_{p+a}` (`a = 0 … 3`, `B_a` the
//!   uniform cubic B-spline segments): control point `p + 1` is the one centred at the
//!   region's first voxel. Points outside the regions are not moved.
//! * The coefficients follow, one number per line, as **physical displacements** in
//!   plastimatch's "ITK-like planar" order: the x components of all control points (index `i`
//!   fastest over the control grid), then all y components, then all z components.
//!
//! So, in the common model of the [parent module](super), region parameter `u = t /
//! vox_per_rgn` is True's parameter and the lattice frame is
//!
//! ```text
//! F(u) = img_origin + D·(img_spacing ⊙ vox_per_rgn ⊙ u),
//! ```
//!
//! i.e. frame origin `img_origin` (the first voxel), axes `D`, spacing
//! `img_spacing ⊙ vox_per_rgn`, and `c_ijk = P_ijk − F(i − 1, j − 1, k − 1)`. A negative
//! `img_spacing` component is read as the positive spacing along the negated axis (the same
//! voxel positions).
//!
//! These conventions were derived from plastimatch's source (`bspline_xform.cxx`:
//! `bspline_xform_save`, `bspline_xform_load`, `bspline_xform_initialize`,
//! `bspline_transform_point`; `direction_matrices.cxx`) and checked against plastimatch 1.10
//! (the `plastimatch` Python wheel) for **identity direction cosines**: the displacement field
//! of `plastimatch xf-convert --output-type vf` agrees with the lattice's displacement to
//! single precision (1e-7) at every voxel inside the regions, for single-coefficient and random
//! files with unequal `vox_per_rgn`, spacings and origins (reference values are in the
//! crate's tests; `scripts/itk_bspline_check.py` repeats the comparison). Known differences
//! and limits:
//!
//! * plastimatch's region test is half-open, so voxels exactly on the far end of the last
//!   region are not moved there but are here (the lattice's domain is closed); and it computes
//!   in single precision, so voxels exactly on the start of the domain can round to just
//!   outside it and be left unmoved by plastimatch.
//! * Only `roi_offset = 0 0 0` is read: older sources shift the grid by `roi_offset`, while
//!   plastimatch 1.10 anchors it at voxel 0 whatever `roi_offset` says, so a non-zero offset
//!   has no reliable meaning and is refused ([`DeformError::Unsupported`]). plastimatch writes
//!   `0 0 0` when it registers whole images.
//! * Non-identity direction cosines follow the source's step-matrix convention above (the
//!   ITK one). This could not be confirmed empirically: plastimatch 1.10's `xf-convert` does
//!   not evaluate rotated files consistently with their own voxel grid (for a 90° rotation
//!   its displacement field is zero everywhere), so it offers no reference.
//!
//! # Writing
//!
//! [`bxf_to_string`] writes degree-3 lattices with uniform knots (others are
//! [`DeformError::Unsupported`]) on the knot grid itself: `vox_per_rgn = 1 1 1`,
//! `roi_offset = 0 0 0`, `img_dim = roi_dim = n − 3` (one voxel per region),
//! `img_spacing` = the control-point spacing and `img_origin` = the start of the lattice's
//! domain. Numbers are written with the shortest text that reads back to the same `f64`
//! (plastimatch itself keeps single precision).

use std::fmt::Write as _;
use std::path::Path;

use glam::{DMat3, DVec3};

use super::{
    UniformGrid, axes_from_rows, checked_grid_len, fmt_f64, parse_f64, read_text, rows_of,
    write_text,
};
use crate::BSplineLattice;
use volmorph_deform::DeformError;

/// Format name used in error messages.
const FORMAT: &str = "plastimatch bxf";

/// First line of a plastimatch B-spline transform file.
pub const BXF_HEADER: &str = "MGH_GPUIT_BSP <experimental>";

fn err(line: usize, message: impl Into<String>) -> DeformError {
    DeformError::Parse {
        format: FORMAT,
        line,
        message: message.into(),
    }
}

const KEYS: [&str; 7] = [
    "img_origin",
    "img_spacing",
    "img_dim",
    "roi_offset",
    "roi_dim",
    "vox_per_rgn",
    "direction_cosines",
];

fn ints(v: &[f64], key: &str, line: usize) -> Result<[i64; 3], DeformError> {
    let mut out = [0i64; 3];
    for (o, &x) in out.iter_mut().zip(v) {
        if !(x.fract() == 0.0 && x.abs() <= f64::from(u32::MAX)) {
            return Err(err(
                line,
                format!(
                    "{key} value {} is not an integer of magnitude at most {}",
                    volmorph_io::Num(x),
                    u32::MAX
                ),
            ));
        }
        *o = x as i64;
    }
    Ok(out)
}

/// Parse the text of a plastimatch `.bxf` file into the equivalent lattice (see the
/// [module docs](self)). The image size `img_dim` is checked but not kept.
///
/// # Errors
/// [`DeformError::Parse`] (with the line) for a missing `MGH_GPUIT_BSP` header, missing,
/// repeated or unknown header fields, wrong value counts, non-numeric or non-finite numbers,
/// non-integral sizes, `roi_dim` or `vox_per_rgn` below 1, a zero spacing, a direction
/// matrix that is not orthonormal, or a coefficient count other than `3·(r₀+3)(r₁+3)(r₂+3)`;
/// [`DeformError::Unsupported`] for a non-zero `roi_offset` (see the module docs).
pub fn parse_bxf(text: &str) -> Result<BSplineLattice, DeformError> {
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    match lines.next() {
        Some((_, l)) if l.starts_with("MGH_GPUIT_BSP") => {}
        Some((n, l)) => {
            let shown: String = l.chars().take(60).collect();
            return Err(err(n, format!("expected '{BXF_HEADER}', found '{shown}'")));
        }
        None => return Err(err(0, "empty file")),
    }
    let mut values: [Option<Vec<f64>>; 7] = Default::default();
    let mut lines_of = [0usize; 7];
    let mut coef_lines: Vec<(usize, &str)> = Vec::new();
    for (n, l) in lines {
        if l.is_empty() {
            continue;
        }
        if let Some((key, value)) = l.split_once('=') {
            if !coef_lines.is_empty() {
                return Err(err(n, "header field after the coefficients"));
            }
            let key = key.trim();
            let k = KEYS
                .iter()
                .position(|&x| x == key)
                .ok_or_else(|| err(n, format!("unknown header field '{key}'")))?;
            if values[k].is_some() {
                return Err(err(n, format!("second '{key}' line")));
            }
            let v = value
                .split_whitespace()
                .map(|t| parse_f64(t, FORMAT, n))
                .collect::<Result<Vec<_>, _>>()?;
            let want = if k == 6 { 9 } else { 3 };
            if v.len() != want {
                return Err(err(
                    n,
                    format!("{key} takes {want} numbers, found {}", v.len()),
                ));
            }
            values[k] = Some(v);
            lines_of[k] = n;
        } else {
            coef_lines.push((n, l));
        }
    }
    let get = |k: usize| -> Result<&[f64], DeformError> {
        values[k]
            .as_deref()
            .ok_or_else(|| err(0, format!("missing header field '{}'", KEYS[k])))
    };
    let origin = get(0)?;
    let spacing = get(1)?;
    ints(get(2)?, KEYS[2], lines_of[2])?;
    let roi_offset = ints(get(3)?, KEYS[3], lines_of[3])?;
    if roi_offset != [0; 3] {
        return Err(DeformError::Unsupported(format!(
            "bxf line {}: roi_offset {roi_offset:?}; only 0 0 0 is read (plastimatch versions \
             disagree on where a non-zero offset puts the control grid)",
            lines_of[3]
        )));
    }
    let roi_dim = ints(get(4)?, KEYS[4], lines_of[4])?;
    let vpr = ints(get(5)?, KEYS[5], lines_of[5])?;
    let mut rows = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let mut axes = DMat3::IDENTITY;
    if let Some(dc) = values[6].as_deref() {
        rows.copy_from_slice(dc);
        axes = axes_from_rows(rows, FORMAT, lines_of[6], false)?;
    }
    let mut size = [0usize; 3];
    let mut img_spacing = DVec3::ZERO;
    for a in 0..3 {
        if roi_dim[a] < 1 || vpr[a] < 1 {
            return Err(err(
                lines_of[if roi_dim[a] < 1 { 4 } else { 5 }],
                format!(
                    "roi_dim ({}) and vox_per_rgn ({}) of axis {a} must be ≥ 1",
                    roi_dim[a], vpr[a]
                ),
            ));
        }
        let s = spacing[a];
        if s == 0.0 {
            return Err(err(lines_of[1], format!("img_spacing of axis {a} is 0")));
        }
        if s < 0.0 {
            // Same voxel positions with a positive spacing along the opposite direction.
            let flipped = -axes.col(a);
            *axes.col_mut(a) = flipped;
        }
        img_spacing[a] = s.abs();
        let regions = 1 + (roi_dim[a] - 1) / vpr[a];
        size[a] = usize::try_from(regions + 3).map_err(|_| err(lines_of[4], "roi too large"))?;
    }
    let len = checked_grid_len(size, FORMAT, lines_of[4])?;
    let found: usize = coef_lines
        .iter()
        .map(|(_, l)| l.split_whitespace().count())
        .sum();
    if found != 3 * len {
        return Err(err(
            coef_lines.first().map_or(0, |c| c.0),
            format!(
                "a grid of {size:?} control points needs {} coefficients, found {found}",
                3 * len
            ),
        ));
    }
    let mut coefficients = vec![DVec3::ZERO; len];
    let mut m = 0usize;
    for (n, l) in coef_lines {
        for tok in l.split_whitespace() {
            coefficients[m % len][m / len] = parse_f64(tok, FORMAT, n)?;
            m += 1;
        }
    }
    let img_origin = DVec3::from_slice(origin);
    let grid_spacing = img_spacing * DVec3::new(vpr[0] as f64, vpr[1] as f64, vpr[2] as f64);
    // Control point 0 sits one region before the ROI's first voxel (voxel 0).
    let grid_origin = img_origin - axes * grid_spacing;
    UniformGrid {
        size,
        origin: grid_origin,
        spacing: grid_spacing,
        axes,
        coefficients,
    }
    .into_lattice()
}

/// Read a plastimatch `.bxf` file; see [`parse_bxf`].
///
/// # Errors
/// [`DeformError::Io`] if the file cannot be read, and the errors of [`parse_bxf`].
pub fn read_bxf(path: &Path) -> Result<BSplineLattice, DeformError> {
    parse_bxf(&read_text(path, FORMAT)?)
}

/// The `.bxf` text of `lattice`, laid out on the knot grid (see the [module docs](self)).
///
/// # Errors
/// [`DeformError::Unsupported`] if a lattice axis is not cubic or its knots are not uniform.
pub fn bxf_to_string(lattice: &BSplineLattice) -> Result<String, DeformError> {
    let g = UniformGrid::from_lattice(lattice, "a plastimatch bxf")?;
    let start = g.origin + g.axes * g.spacing;
    let regions = g.size.map(|n| n - 3);
    let mut s = String::with_capacity(256 + g.coefficients.len() * 3 * 24);
    s.push_str(BXF_HEADER);
    s.push('\n');
    let three = |s: &mut String, key: &str, v: [f64; 3]| {
        let _ = writeln!(
            s,
            "{key} = {} {} {}",
            fmt_f64(v[0]),
            fmt_f64(v[1]),
            fmt_f64(v[2])
        );
    };
    let r = regions.map(|n| n as f64);
    three(&mut s, "img_origin", start.to_array());
    three(&mut s, "img_spacing", g.spacing.to_array());
    three(&mut s, "img_dim", r);
    three(&mut s, "roi_offset", [0.0; 3]);
    three(&mut s, "roi_dim", r);
    three(&mut s, "vox_per_rgn", [1.0; 3]);
    s.push_str("direction_cosines =");
    for v in rows_of(g.axes) {
        s.push(' ');
        s.push_str(&fmt_f64(v));
    }
    s.push('\n');
    for c in 0..3 {
        for p in &g.coefficients {
            s.push_str(&fmt_f64(p[c]));
            s.push('\n');
        }
    }
    Ok(s)
}

/// Write `lattice` as a plastimatch `.bxf` file, atomically (temporary file + rename).
///
/// # Errors
/// [`DeformError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in
/// `.bxf` (nothing written); [`DeformError::Unsupported`] for a lattice the format cannot
/// represent (see [`bxf_to_string`]), [`DeformError::Io`] if writing fails.
pub fn write_bxf(path: &Path, lattice: &BSplineLattice) -> Result<(), DeformError> {
    volmorph_io::extension::check(path, &["bxf"])?;
    write_text(path, &bxf_to_string(lattice)?)
}
