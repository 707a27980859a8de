//! ITK text transform files (`.tfm`, `.txt`) for the maps ITK has: affine maps
//! (`AffineTransform_double_3_3`, also read: `MatrixOffsetTransformBase`, `TranslationTransform`,
//! `IdentityTransform`), cubic B-spline lattices (`BSplineTransform_double_3_3`, see
//! `volmorph_lattice::formats::itk_tfm` for the conventions), interpolating thin-plate splines
//! (`ThinPlateSplineKernelTransform_double_3_3` for the kernel `r`,
//! `ThinPlateR2LogRSplineKernelTransform_double_3_3` for `r² ln r`) and compositions of these
//! (`CompositeTransform_double_3_3`).
//!
//! # Conventions
//!
//! * ITK's affine transform with matrix `M`, translation `t` and centre `c` (the fixed
//!   parameters) is `x ↦ M (x − c) + c + t`; it is read as the [`Affine`] with offset
//!   `c + t − M c` and written with centre 0. Parameters are `M` row-major, then `t`.
//! * ITK's kernel transforms send their source landmarks (`Parameters`, `x y z` per landmark)
//!   to their target landmarks (`FixedParameters`) by the kernel's radial part plus an affine
//!   part, solved from the landmarks when the transform is read: the interpolant a
//!   [`ThinPlateMap`] with the same kernel and smoothing 0 is (it is unique; the two solve it
//!   in different coordinates, so they agree to rounding). ITK keeps no stiffness, so a
//!   smoothing spline is refused.
//! * A `CompositeTransform` applies the transform listed **last** first (ITK applies its queue
//!   from the back): a file listing `T1, T2` maps `x` to `T1(T2(x))`. An
//!   [`AnyMap::Compose`] (list order, first first) is therefore written in reverse order, and
//!   read back into list order.
//!
//! Other transform types (Euler, versor, similarity, displacement fields, HDF5 files) are
//! refused with [`MapError::Unsupported`] naming the type. MATLAB `.mat` files hold the same
//! transforms in binary ([`crate::itk_mat`]).

use glam::{DMat3, DVec3};
use volmorph_deform::Affine;
use volmorph_handles::{ThinPlateMap, TpsKernel};
use volmorph_io::fmt_f64;
use volmorph_lattice::formats::itk_tfm::{ITK_TFM_HEADER, itk_tfm_to_string, parse_itk_tfm};

use crate::{AnyMap, MapError};

/// Transform type written for affine maps.
pub const ITK_AFFINE_TYPE: &str = "AffineTransform_double_3_3";

/// Transform type written for thin-plate splines with the kernel `r` (ITK's 3-D thin-plate
/// spline, `G(r) = r`).
pub const ITK_TPS_TYPE: &str = "ThinPlateSplineKernelTransform_double_3_3";

/// Transform type written for thin-plate splines with the kernel `r² ln r`.
pub const ITK_TPS_R2LOGR_TYPE: &str = "ThinPlateR2LogRSplineKernelTransform_double_3_3";

/// Transform type written for compositions.
pub const ITK_COMPOSITE_TYPE: &str = "CompositeTransform_double_3_3";

/// Largest number of transforms read from one file.
const MAX_TRANSFORMS: usize = 64;

/// One `Transform:` block of a transform file: its line, type name, and the lines and text
/// of its `Parameters` and `FixedParameters`.
pub(crate) struct Block {
    pub(crate) line: usize,
    pub(crate) kind: String,
    pub(crate) params: Option<(usize, String)>,
    pub(crate) fixed: Option<(usize, String)>,
}

/// The ITK transform file of `map`.
///
/// # Errors
/// [`MapError::Unsupported`] for maps ITK has no transform for (moving least squares and the
/// other handle maps but interpolating thin-plate splines, NURBS geometry, sampled maps,
/// numerical inverses other than of affine maps), for smoothing thin-plate splines and for
/// non-cubic or non-uniform lattices.
pub fn to_tfm_string(map: &AnyMap) -> Result<String, MapError> {
    let blocks: Vec<String> = match map {
        AnyMap::Compose(ms) => {
            let mut b = vec![format!("Transform: {ITK_COMPOSITE_TYPE}\n")];
            for m in ms.iter().rev() {
                if matches!(m, AnyMap::Compose(_)) {
                    return Err(MapError::Unsupported(
                        "nested compositions in an ITK file (flatten them first)".into(),
                    ));
                }
                b.push(block_of(m)?);
            }
            b
        }
        m => vec![block_of(m)?],
    };
    let mut s = format!("{ITK_TFM_HEADER}\n");
    for (i, b) in blocks.iter().enumerate() {
        s.push_str(&format!("#Transform {i}\n"));
        s.push_str(b);
    }
    Ok(s)
}

/// The `Transform:` … lines of one non-composite map.
fn block_of(map: &AnyMap) -> Result<String, MapError> {
    match map {
        AnyMap::Identity => Ok(affine_block(&Affine {
            matrix: DMat3::IDENTITY,
            offset: DVec3::ZERO,
        })),
        AnyMap::Affine(a) => Ok(affine_block(a)),
        AnyMap::Lattice(l) => {
            let text = itk_tfm_to_string(l)?;
            // Drop the header and the "#Transform 0" line.
            Ok(text
                .lines()
                .filter(|l| !l.starts_with('#'))
                .map(|l| format!("{l}\n"))
                .collect())
        }
        AnyMap::ThinPlate(m) => thin_plate_block(m),
        other => Err(MapError::Unsupported(format!(
            "ITK has no transform for a {} map; write it as .json",
            other.kind()
        ))),
    }
}

/// The `Transform:` lines of an interpolating thin-plate spline: ITK's kernel transform of
/// the same kernel, sources as `Parameters` and targets as `FixedParameters` (`x y z` per
/// landmark), as ITK's `KernelTransform` reads and writes them.
fn thin_plate_block(m: &ThinPlateMap) -> Result<String, MapError> {
    let smoothing = m.system().smoothing();
    if smoothing != 0.0 {
        return Err(MapError::Unsupported(format!(
            "a smoothing thin-plate spline (λ = {}) in an ITK file: ITK's kernel transforms \
             interpolate their landmarks and keep no stiffness; write it as .json",
            fmt_f64(smoothing)
        )));
    }
    let kind = match m.kernel() {
        TpsKernel::R => ITK_TPS_TYPE,
        TpsKernel::R2LogR => ITK_TPS_R2LOGR_TYPE,
    };
    let flat = |ps: &[DVec3]| numbers_text(ps.iter().flat_map(|p| p.to_array()));
    Ok(format!(
        "Transform: {kind}\nParameters: {}\nFixedParameters: {}\n",
        flat(m.sources()),
        flat(m.targets())
    ))
}

/// ITK's 12 parameters of an affine map with centre 0: the matrix row-major, then the
/// translation.
pub(crate) fn affine_parameters(a: &Affine) -> [f64; 12] {
    let mut p = [0.0; 12];
    p[..9].copy_from_slice(&a.matrix.transpose().to_cols_array());
    p[9..].copy_from_slice(&a.offset.to_array());
    p
}

/// `values` as the text of a `Parameters` line: shortest round-trip numbers, one space apart.
pub(crate) fn numbers_text(values: impl IntoIterator<Item = f64>) -> String {
    let v: Vec<String> = values.into_iter().map(fmt_f64).collect();
    v.join(" ")
}

fn affine_block(a: &Affine) -> String {
    format!(
        "Transform: {ITK_AFFINE_TYPE}\nParameters: {}\nFixedParameters: 0 0 0\n",
        numbers_text(affine_parameters(a))
    )
}

/// Read the text of an ITK transform file: one transform, or one `CompositeTransform` followed
/// by its components.
///
/// # Errors
/// [`MapError::Deform`] (a parse error with the line) for malformed text,
/// [`MapError::Unsupported`] for transform types ITK has but volmorph does not read.
pub fn parse_tfm(text: &str) -> Result<AnyMap, MapError> {
    let blocks = blocks(text)?;
    let Some((first, rest)) = blocks.split_first() else {
        return Err(parse_err(0, "no 'Transform:' line"));
    };
    if first.kind.starts_with("CompositeTransform") {
        if rest.is_empty() {
            return Ok(AnyMap::Identity);
        }
        let mut maps = rest.iter().map(map_of).collect::<Result<Vec<_>, _>>()?;
        maps.reverse();
        return Ok(AnyMap::Compose(maps));
    }
    if !rest.is_empty() {
        return Err(MapError::Unsupported(format!(
            "line {}: several transforms without a CompositeTransform; which one applies is \
             not defined",
            rest[0].line
        )));
    }
    map_of(first)
}

fn parse_err(line: usize, message: impl Into<String>) -> MapError {
    MapError::Deform(volmorph_deform::DeformError::Parse {
        format: "ITK transform",
        line,
        message: message.into(),
    })
}

fn blocks(text: &str) -> Result<Vec<Block>, MapError> {
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    match lines.by_ref().find(|(_, l)| !l.is_empty()) {
        Some((_, l)) if l.starts_with("#Insight Transform File") => {}
        Some((n, _)) => return Err(parse_err(n, format!("expected '{ITK_TFM_HEADER}'"))),
        None => return Err(parse_err(0, "empty file")),
    }
    let mut out: Vec<Block> = Vec::new();
    for (n, l) in lines {
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let Some((key, value)) = l.split_once(':') else {
            return Err(parse_err(n, "expected 'Key: values'"));
        };
        let value = value.trim().to_owned();
        match key.trim() {
            "Transform" => {
                if out.len() == MAX_TRANSFORMS {
                    return Err(parse_err(
                        n,
                        format!("more than {MAX_TRANSFORMS} transforms"),
                    ));
                }
                out.push(Block {
                    line: n,
                    kind: value,
                    params: None,
                    fixed: None,
                });
            }
            k @ ("Parameters" | "FixedParameters") => {
                let Some(b) = out.last_mut() else {
                    return Err(parse_err(n, format!("{k} before any 'Transform:' line")));
                };
                let slot = if k == "Parameters" {
                    &mut b.params
                } else {
                    &mut b.fixed
                };
                if slot.replace((n, value)).is_some() {
                    return Err(parse_err(n, format!("second '{k}:' line")));
                }
            }
            other => return Err(parse_err(n, format!("unknown field '{other}'"))),
        }
    }
    Ok(out)
}

fn numbers(field: &Option<(usize, String)>, what: &str, line: usize) -> Result<Vec<f64>, MapError> {
    let Some((n, text)) = field else {
        return Err(parse_err(line, format!("no '{what}:' line")));
    };
    text.split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| parse_err(*n, format!("'{t}' is not a finite number")))
        })
        .collect()
}

/// The map of one non-composite transform block.
pub(crate) fn map_of(b: &Block) -> Result<AnyMap, MapError> {
    let kind = b.kind.as_str();
    let is = |prefix: &str| {
        kind.strip_prefix(prefix)
            .is_some_and(|rest| rest == "_double_3_3" || rest == "_float_3_3")
    };
    if is("IdentityTransform") {
        return Ok(AnyMap::Identity);
    }
    if is("TranslationTransform") {
        let p = numbers(&b.params, "Parameters", b.line)?;
        let [x, y, z] = p.as_slice() else {
            return Err(parse_err(b.line, "a TranslationTransform has 3 parameters"));
        };
        return Ok(AnyMap::Affine(Affine {
            matrix: DMat3::IDENTITY,
            offset: DVec3::new(*x, *y, *z),
        }));
    }
    if is("AffineTransform") || is("MatrixOffsetTransformBase") {
        let p = numbers(&b.params, "Parameters", b.line)?;
        let f = numbers(&b.fixed, "FixedParameters", b.line)?;
        if p.len() != 12 {
            return Err(parse_err(
                b.params.as_ref().map_or(b.line, |x| x.0),
                format!(
                    "a 3-D affine transform has 12 parameters, found {}",
                    p.len()
                ),
            ));
        }
        let c = match f.as_slice() {
            [] => DVec3::ZERO,
            [x, y, z] => DVec3::new(*x, *y, *z),
            _ => {
                return Err(parse_err(
                    b.fixed.as_ref().map_or(b.line, |x| x.0),
                    "the fixed parameters of an affine transform are its centre (3 numbers)",
                ));
            }
        };
        let mut rows = [0.0; 9];
        rows.copy_from_slice(&p[..9]);
        let matrix = DMat3::from_cols_array(&rows).transpose();
        let t = DVec3::new(p[9], p[10], p[11]);
        return Ok(AnyMap::Affine(Affine {
            matrix,
            offset: c + t - matrix * c,
        }));
    }
    let tps_kernel = if is("ThinPlateSplineKernelTransform") {
        Some(TpsKernel::R)
    } else if is("ThinPlateR2LogRSplineKernelTransform") {
        Some(TpsKernel::R2LogR)
    } else {
        None
    };
    if let Some(kernel) = tps_kernel {
        let p = numbers(&b.params, "Parameters", b.line)?;
        let f = numbers(&b.fixed, "FixedParameters", b.line)?;
        if p.len() % 3 != 0 || p.len() != f.len() {
            return Err(parse_err(
                b.line,
                format!(
                    "a kernel transform lists its source landmarks (Parameters) and its target \
                     landmarks (FixedParameters), x y z each, as many of one as of the other: \
                     found {} and {} numbers",
                    p.len(),
                    f.len()
                ),
            ));
        }
        let points =
            |v: &[f64]| -> Vec<DVec3> { v.chunks_exact(3).map(DVec3::from_slice).collect() };
        return Ok(AnyMap::ThinPlate(ThinPlateMap::with_kernel(
            &points(&p),
            &points(&f),
            0.0,
            kernel,
        )?));
    }
    if kind.starts_with("BSplineTransform") {
        let mut text = format!("{ITK_TFM_HEADER}\n#Transform 0\nTransform: {kind}\n");
        for (name, field) in [("Parameters", &b.params), ("FixedParameters", &b.fixed)] {
            if let Some((_, v)) = field {
                text.push_str(&format!("{name}: {v}\n"));
            }
        }
        return parse_itk_tfm(&text)
            .map(AnyMap::Lattice)
            .map_err(|e| MapError::Invalid(format!("transform at line {}: {e}", b.line)));
    }
    if kind.starts_with("CompositeTransform") {
        return Err(MapError::Unsupported(format!(
            "line {}: a CompositeTransform inside a composite",
            b.line
        )));
    }
    Err(MapError::Unsupported(format!(
        "line {}: transform type {kind}; volmorph reads Identity, Translation, Affine, \
         MatrixOffsetTransformBase, BSpline, ThinPlateSpline, ThinPlateR2LogRSpline and \
         Composite transforms",
        b.line
    )))
}
