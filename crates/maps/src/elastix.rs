//! elastix transform parameter files (`TransformParameters.0.txt`, …), read.
//!
//! # Layout
//!
//! One entry per line, `(Name value value …)`: numbers, or strings in double quotes; `//`
//! starts a comment. The entries used:
//!
//! | entry | meaning |
//! | --- | --- |
//! | `Transform` | `"TranslationTransform"`, `"EulerTransform"`, `"SimilarityTransform"`, `"AffineTransform"`, `"BSplineTransform"` or `"RecursiveBSplineTransform"` |
//! | `TransformParameters` | the parameters (count checked against `NumberOfParameters` when given) |
//! | `CenterOfRotationPoint` | the centre `c` of the Euler, similarity and affine transforms (required, as elastix requires it) |
//! | `ComputeZYX` | Euler angle order (default `"false"`) |
//! | `GridSize`, `GridIndex`, `GridSpacing`, `GridOrigin`, `GridDirection`, `BSplineTransformSplineOrder`, `UseCyclicTransform` | the B-spline control grid (order 3, index 0, not cyclic) |
//! | `InitialTransformParameterFileName`, `InitialTransformParametersFileName` | `"NoInitialTransform"`, or the file of the transform applied first (see [Chains](#chains)) |
//! | `HowToCombineTransforms` | `"Compose"` (the default; `"Add"` is refused) |
//! | `FixedImageDimension`, `MovingImageDimension` | must be 3 when given |
//! | `UseDirectionCosines` | must be `"true"` (the default since elastix 4.8) when given |
//! | `UseBinaryFormatForTransformationParameters` | must be `"false"` when given |
//!
//! Flags are `"true"` or `"false"`, spelled so, as elastix reads them.
//!
//! The other entries elastix writes in a transform parameter file describe the fixed image's
//! grid (`Size`, `Index`, `Spacing`, `Origin`, `Direction`, the `…InternalImagePixelType`s:
//! where transformix samples a deformation field or resamples an image) and how an image is
//! resampled (`Resampler`, `ResampleInterpolator`, `FinalBSplineInterpolationOrder`,
//! `DefaultPixelValue`, `ResultImageFormat`, `ResultImagePixelType`, `CompressResultImage`);
//! none changes where a point goes, and they are skipped. **Any other entry is refused**, with
//! the file, line and entry named: an entry elastix reads and volmorph does not can change the
//! transform, and skipping one is how a renamed chain entry once read an affine → B-spline
//! chain as its B-spline alone. Refused so, among others: `ITKTransformParameters` and
//! `ITKTransformFixedParameters` (parameters elastix takes instead of `TransformParameters`),
//! `TransformFileName` (`(Transform "File")`: the transform kept in an ITK file), and
//! `CenterOfRotation` (a centre as an image index, from elastix before 3.402).
//!
//! # Meaning
//!
//! elastix transforms, like ITK's, map points of the **fixed** image to points of the
//! **moving** image (the pull-back sense: resampling samples the moving image at `T(x)`).
//! With centre `c`: Euler `T(x) = R (x − c) + c + t`, parameters `θx θy θz tx ty tz`,
//! `R = Rz·Rx·Ry` (`R = Rz·Ry·Rx` with `ComputeZYX "true"`), as `itk::Euler3DTransform`;
//! similarity `T(x) = s·R(v) (x − c) + c + t`, parameters `v1 v2 v3 tx ty tz s` (`v` the
//! vector part of the unit versor, as `itk::Similarity3DTransform`); affine `T(x) = M (x − c) +
//! c + t`, parameters `M` row-major then `t`; translation `T(x) = x + t`. The B-spline
//! transform is ITK's `BSplineTransform` of order 3 on the control grid `GridSize` (control
//! points per axis), `GridOrigin` (control point 0), `GridSpacing`, `GridDirection` (the 9
//! direction cosines **column by column**, as elastix writes `Direction`), parameters the x
//! displacements of every control point (x fastest), then every y, then every z; outside its
//! domain (one spacing inside the first and last control points) it is the identity — read as
//! the equivalent volmorph lattice ([`volmorph_lattice::formats::itk_tfm`]).
//!
//! # Chains
//!
//! The entry naming the initial transform changed its name: elastix up to 5.1 (and 4.x before
//! it) writes `InitialTransformParametersFileName`; elastix 5.2.0 and later write
//! `InitialTransformParameterFileName` (without the `s`: elastix commit 2170592, June 2023,
//! elastix issue 900), and read the old name still, with a deprecation warning, preferring the
//! new one when both are given. volmorph reads either; a file giving both with different values
//! is refused, naming both.
//!
//! A chain with `HowToCombineTransforms "Compose"` is `T(x) = T_this(T_initial(x))`: the
//! initial transform first, read as [`AnyMap::Compose`]`([initial, this])`. The initial file is
//! looked for where its name points (relative names from the folder of the file naming it),
//! and, when that is missing, under its own file name in the folder of the file naming it: an
//! elastix output folder moved elsewhere, or named relative to the folder elastix ran in (run
//! with the output folder `out`, elastix writes `"out/TransformParameters.0.txt"`). A file
//! outside the folder of the file naming it is refused unless external data are allowed
//! ([`volmorph_volume_io::ReadOptions::allow_external_data`], the command line's
//! `--allow-external-data`), as for volume data files.

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use volmorph_deform::Affine;
use volmorph_io::fmt_f64;

use crate::{AnyMap, MapError};

/// Longest chain of initial transforms followed.
pub const MAX_CHAIN: usize = 16;

/// Longest entry value list read (a B-spline transform's 3·N parameters).
const MAX_VALUES: usize = 1 << 24;

/// The entry naming the initial transform, as elastix 5.2.0 and later write it.
pub const INITIAL_KEY: &str = "InitialTransformParameterFileName";

/// The same entry as elastix up to 5.1 writes it (still read by elastix, deprecated).
pub const INITIAL_KEY_OLD: &str = "InitialTransformParametersFileName";

/// The entries read (see the [module docs](self)).
const READ: &[&str] = &[
    "Transform",
    "NumberOfParameters",
    "TransformParameters",
    "CenterOfRotationPoint",
    "ComputeZYX",
    "GridSize",
    "GridIndex",
    "GridSpacing",
    "GridOrigin",
    "GridDirection",
    "BSplineTransformSplineOrder",
    "UseCyclicTransform",
    INITIAL_KEY,
    INITIAL_KEY_OLD,
    "HowToCombineTransforms",
    "FixedImageDimension",
    "MovingImageDimension",
    "UseDirectionCosines",
    "UseBinaryFormatForTransformationParameters",
];

/// The entries elastix writes that do not change where a point goes: the fixed image's grid
/// and pixel types (where transformix samples or resamples) and the resampling of image
/// intensities (elastix's `TransformBase::CreateTransformParameterMap` and
/// `ResamplerBase::CreateTransformParameterMap`, and its resample interpolators).
const SKIPPED: &[&str] = &[
    "FixedInternalImagePixelType",
    "MovingInternalImagePixelType",
    "Size",
    "Index",
    "Spacing",
    "Origin",
    "Direction",
    "Resampler",
    "ResampleInterpolator",
    "FinalBSplineInterpolationOrder",
    "DefaultPixelValue",
    "ResultImageFormat",
    "ResultImagePixelType",
    "CompressResultImage",
];

fn bad(line: usize, message: impl Into<String>) -> MapError {
    MapError::Deform(volmorph_deform::DeformError::Parse {
        format: "elastix transform parameters",
        line,
        message: message.into(),
    })
}

/// One value of an entry.
#[derive(Debug, Clone, PartialEq)]
enum Value {
    Number(f64),
    Text(String),
}

/// The entries of a parameter file, in order: name, line, values.
struct Entries(Vec<(String, usize, Vec<Value>)>);

impl Entries {
    fn get(&self, name: &str) -> Option<(usize, &[Value])> {
        self.0
            .iter()
            .find(|(n, _, _)| n == name)
            .map(|(_, l, v)| (*l, v.as_slice()))
    }

    fn text(&self, name: &str) -> Result<Option<(usize, &str)>, MapError> {
        match self.get(name) {
            None => Ok(None),
            Some((l, [Value::Text(t)])) => Ok(Some((l, t.as_str()))),
            Some((l, _)) => Err(bad(l, format!("({name} …) must be one quoted string"))),
        }
    }

    fn numbers(&self, name: &str) -> Result<Option<(usize, Vec<f64>)>, MapError> {
        match self.get(name) {
            None => Ok(None),
            Some((l, vs)) => vs
                .iter()
                .map(|v| match v {
                    Value::Number(x) => Ok(*x),
                    Value::Text(t) => Err(bad(l, format!("({name} …): \"{t}\" is not a number"))),
                })
                .collect::<Result<Vec<_>, _>>()
                .map(|v| Some((l, v))),
        }
    }

    fn vec3(&self, name: &str, default: Option<DVec3>) -> Result<DVec3, MapError> {
        match self.numbers(name)? {
            None => default.ok_or_else(|| bad(0, format!("no ({name} …) entry"))),
            Some((_, v)) if v.len() == 3 => Ok(DVec3::new(v[0], v[1], v[2])),
            Some((l, v)) => Err(bad(
                l,
                format!("({name} …) has {} values, a 3-D transform needs 3", v.len()),
            )),
        }
    }

    /// The flag `name` (`default` when absent): `"true"` or `"false"`, spelled so (elastix's
    /// `Conversion::StringToValue` reads no other spelling).
    fn flag(&self, name: &str, default: bool) -> Result<bool, MapError> {
        match self.text(name)? {
            None => Ok(default),
            Some((_, "true")) => Ok(true),
            Some((_, "false")) => Ok(false),
            Some((l, t)) => Err(bad(
                l,
                format!("({name} \"{t}\"): expected \"true\" or \"false\""),
            )),
        }
    }

    /// The initial transform's file name (`None` for `"NoInitialTransform"` or none given),
    /// under either name of the entry.
    fn initial(&self) -> Result<Option<String>, MapError> {
        let name = match (self.text(INITIAL_KEY)?, self.text(INITIAL_KEY_OLD)?) {
            (Some((l, new)), Some((lo, old))) if new != old => {
                return Err(bad(
                    l.max(lo),
                    format!(
                        "({INITIAL_KEY} \"{new}\") on line {l} and ({INITIAL_KEY_OLD} \"{old}\") \
                         on line {lo} name different initial transforms"
                    ),
                ));
            }
            (Some((_, name)), _) | (None, Some((_, name))) => name,
            (None, None) => return Ok(None),
        };
        Ok((!name.is_empty() && name != "NoInitialTransform").then(|| name.to_owned()))
    }

    /// Refuse an entry that is neither read nor known to leave the transform alone.
    fn refuse_unknown(&self) -> Result<(), MapError> {
        let Some((name, line, _)) = self
            .0
            .iter()
            .find(|(n, _, _)| !READ.contains(&n.as_str()) && !SKIPPED.contains(&n.as_str()))
        else {
            return Ok(());
        };
        let why = match name.as_str() {
            "ITKTransformParameters" | "ITKTransformFixedParameters" => {
                "elastix takes the transform's parameters from it instead of \
                 (TransformParameters …); volmorph does not read it"
            }
            "TransformFileName" => {
                "the transform is kept in the ITK transform file it names ((Transform \"File\")); \
                 volmorph does not read elastix files that delegate to one"
            }
            "CenterOfRotation" => {
                "a centre given as an image index (elastix before 3.402); volmorph reads \
                 (CenterOfRotationPoint …)"
            }
            _ => {
                "volmorph does not know this entry, and an entry elastix reads that volmorph \
                 skipped could change the transform; remove the line if it does not"
            }
        };
        Err(MapError::Unsupported(format!(
            "line {line}: ({name} …): {why}"
        )))
    }
}

/// `true` if `text` reads as an elastix parameter file: its first entry (after blank lines
/// and `//` comments) is a `(Name …)` line.
#[must_use]
pub fn looks_like_elastix(text: &str) -> bool {
    text.lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with("//"))
        .is_some_and(|l| l.starts_with('('))
}

fn entries(text: &str) -> Result<Entries, MapError> {
    let mut out: Vec<(String, usize, Vec<Value>)> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let n = i + 1;
        let line = strip_comment(raw).trim();
        if line.is_empty() {
            continue;
        }
        let inner = line
            .strip_prefix('(')
            .and_then(|l| l.strip_suffix(')'))
            .ok_or_else(|| bad(n, "expected an entry '(Name value …)'"))?;
        let mut tokens = tokenize(inner).map_err(|m| bad(n, m))?.into_iter();
        let Some(Value::Text(name)) = tokens.next() else {
            return Err(bad(n, "an entry starts with its name"));
        };
        let values: Vec<Value> = tokens.collect();
        if values.len() > MAX_VALUES {
            return Err(bad(n, format!("more than {MAX_VALUES} values")));
        }
        if out.iter().any(|(k, _, _)| *k == name) {
            return Err(bad(n, format!("a second ({name} …) entry")));
        }
        out.push((name, n, values));
    }
    Ok(Entries(out))
}

/// The line without a `//` comment outside quotes.
fn strip_comment(line: &str) -> &str {
    let mut quoted = false;
    let b = line.as_bytes();
    for (i, &c) in b.iter().enumerate() {
        match c {
            b'"' => quoted = !quoted,
            b'/' if !quoted && b.get(i + 1) == Some(&b'/') => return &line[..i],
            _ => {}
        }
    }
    line
}

/// The tokens of an entry: the name (bare), numbers, quoted strings.
fn tokenize(s: &str) -> Result<Vec<Value>, String> {
    let mut out = Vec::new();
    let mut rest = s.trim_start();
    while !rest.is_empty() {
        if let Some(q) = rest.strip_prefix('"') {
            let end = q.find('"').ok_or("a string without its closing quote")?;
            out.push(Value::Text(q[..end].to_owned()));
            rest = q[end + 1..].trim_start();
            continue;
        }
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        let tok = &rest[..end];
        if out.is_empty() {
            out.push(Value::Text(tok.to_owned()));
        } else {
            let v = tok
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("'{tok}' is neither a finite number nor a quoted string"))?;
            out.push(Value::Number(v));
        }
        rest = rest[end..].trim_start();
    }
    Ok(out)
}

/// The rotation about one axis by `a` radians (right-handed).
fn rotation(axis: usize, a: f64) -> DMat3 {
    match axis {
        0 => DMat3::from_rotation_x(a),
        1 => DMat3::from_rotation_y(a),
        _ => DMat3::from_rotation_z(a),
    }
}

/// The rotation of the unit versor with vector part `v` (`itk::Versor::GetMatrix`).
fn versor_matrix(v: DVec3, line: usize) -> Result<DMat3, MapError> {
    let n2 = v.length_squared();
    if n2 > 1.0 + 1e-12 {
        return Err(bad(
            line,
            format!("versor part ({}, {}, {}) is longer than 1", v.x, v.y, v.z),
        ));
    }
    let w = (1.0 - n2).max(0.0).sqrt();
    Ok(DMat3::from_quat(glam::DQuat::from_xyzw(v.x, v.y, v.z, w)))
}

/// One transform of a parameter file (without its initial transform), and the initial
/// transform's file name as written (`None` for `"NoInitialTransform"`).
///
/// # Errors
/// [`MapError::Deform`] (a parse error with the line) for malformed text, missing or
/// miscounted entries, and both names of the initial transform entry naming different files;
/// [`MapError::Unsupported`] for entries neither read nor known to leave the transform alone,
/// other transform types, dimensions, spline orders, `HowToCombineTransforms "Add"`,
/// `UseDirectionCosines "false"` and parameters in a binary file (see the
/// [module docs](self)).
pub fn parse_elastix(text: &str) -> Result<(AnyMap, Option<String>), MapError> {
    let e = entries(text)?;
    e.refuse_unknown()?;
    if !e.flag("UseDirectionCosines", true)? {
        let l = e.get("UseDirectionCosines").map_or(0, |(l, _)| l);
        return Err(MapError::Unsupported(format!(
            "line {l}: (UseDirectionCosines \"false\"): elastix registered the images with \
             their directions taken as the identity, so the transform maps points of those \
             undirected images, not of the images themselves; volmorph reads transforms of \
             (UseDirectionCosines \"true\")"
        )));
    }
    if e.flag("UseBinaryFormatForTransformationParameters", false)? {
        let l = e
            .get("UseBinaryFormatForTransformationParameters")
            .map_or(0, |(l, _)| l);
        return Err(MapError::Unsupported(format!(
            "line {l}: (UseBinaryFormatForTransformationParameters \"true\"): the parameters are \
             in a separate binary file (elastix before 5.1); volmorph reads them written in \
             (TransformParameters …)"
        )));
    }
    for dim in ["FixedImageDimension", "MovingImageDimension"] {
        if let Some((l, v)) = e.numbers(dim)?
            && v != [3.0]
        {
            return Err(MapError::Unsupported(format!(
                "line {l}: ({dim} …) is {v:?}; volmorph reads 3-D transforms"
            )));
        }
    }
    if let Some((l, how)) = e.text("HowToCombineTransforms")?
        && how != "Compose"
    {
        return Err(MapError::Unsupported(format!(
            "line {l}: HowToCombineTransforms \"{how}\"; volmorph reads \"Compose\" chains"
        )));
    }
    let (tl, kind) = e
        .text("Transform")?
        .ok_or_else(|| bad(0, "no (Transform \"…\") entry"))?;
    let (pl, p) = e
        .numbers("TransformParameters")?
        .ok_or_else(|| bad(0, "no (TransformParameters …) entry"))?;
    if let Some((l, n)) = e.numbers("NumberOfParameters")?
        && n != [p.len() as f64]
    {
        return Err(bad(
            l,
            format!(
                "NumberOfParameters {n:?}, but TransformParameters has {}",
                p.len()
            ),
        ));
    }
    let count = |want: usize| {
        if p.len() == want {
            Ok(())
        } else {
            Err(bad(
                pl,
                format!("a 3-D {kind} has {want} parameters, found {}", p.len()),
            ))
        }
    };
    let centred = |m: DMat3, t: DVec3| -> Result<AnyMap, MapError> {
        // elastix refuses these transforms without their centre ("No center of rotation is
        // specified in the transform parameter file").
        let c = e.vec3("CenterOfRotationPoint", None)?;
        Ok(AnyMap::Affine(Affine {
            matrix: m,
            offset: c + t - m * c,
        }))
    };
    let map = match kind {
        "TranslationTransform" => {
            count(3)?;
            AnyMap::Affine(Affine::translation(DVec3::new(p[0], p[1], p[2])))
        }
        "EulerTransform" => {
            count(6)?;
            let [rx, ry, rz] = [0, 1, 2].map(|a| rotation(a, p[a]));
            let r = if e.flag("ComputeZYX", false)? {
                rz * ry * rx
            } else {
                rz * rx * ry
            };
            centred(r, DVec3::new(p[3], p[4], p[5]))?
        }
        "SimilarityTransform" => {
            count(7)?;
            let r = versor_matrix(DVec3::new(p[0], p[1], p[2]), pl)?;
            centred(r * p[6], DVec3::new(p[3], p[4], p[5]))?
        }
        "AffineTransform" => {
            count(12)?;
            let mut rows = [0.0; 9];
            rows.copy_from_slice(&p[..9]);
            centred(
                DMat3::from_cols_array(&rows).transpose(),
                DVec3::new(p[9], p[10], p[11]),
            )?
        }
        "BSplineTransform" | "RecursiveBSplineTransform" => bspline(&e, &p, pl)?,
        "File" => {
            return Err(MapError::Unsupported(format!(
                "line {tl}: (Transform \"File\"): the transform is kept in the ITK transform \
                 file TransformFileName names; volmorph does not read elastix files that \
                 delegate to one"
            )));
        }
        other => {
            return Err(MapError::Unsupported(format!(
                "line {tl}: elastix transform \"{other}\"; volmorph reads TranslationTransform, \
                 EulerTransform, SimilarityTransform, AffineTransform and BSplineTransform"
            )));
        }
    };
    Ok((map, e.initial()?))
}

fn bspline(e: &Entries, p: &[f64], pl: usize) -> Result<AnyMap, MapError> {
    if let Some((l, order)) = e.numbers("BSplineTransformSplineOrder")?
        && order != [3.0]
    {
        return Err(MapError::Unsupported(format!(
            "line {l}: B-spline order {order:?}; volmorph reads cubic (3) B-spline transforms"
        )));
    }
    if e.flag("UseCyclicTransform", false)? {
        let l = e.get("UseCyclicTransform").map_or(0, |(l, _)| l);
        return Err(MapError::Unsupported(format!(
            "line {l}: cyclic B-spline transforms (UseCyclicTransform \"true\")"
        )));
    }
    let size = e.vec3("GridSize", None)?;
    let index = e.vec3("GridIndex", Some(DVec3::ZERO))?;
    if index != DVec3::ZERO {
        return Err(MapError::Unsupported(format!(
            "GridIndex {index}: volmorph reads control grids starting at index 0"
        )));
    }
    let spacing = e.vec3("GridSpacing", None)?;
    let origin = e.vec3("GridOrigin", None)?;
    let direction = match e.numbers("GridDirection")? {
        None => DMat3::IDENTITY,
        Some((_, v)) if v.len() == 9 => {
            let mut cols = [0.0; 9];
            cols.copy_from_slice(&v);
            DMat3::from_cols_array(&cols)
        }
        Some((l, v)) => {
            return Err(bad(
                l,
                format!("GridDirection has {} values, not 9", v.len()),
            ));
        }
    };
    let n = size.to_array().map(|s| s as usize);
    if size.to_array().iter().any(|&s| s.fract() != 0.0 || s < 4.0) {
        return Err(bad(
            0,
            format!("GridSize {size}: a cubic control grid has at least 4 whole points per axis"),
        ));
    }
    let total = n
        .iter()
        .try_fold(3usize, |a, &b| a.checked_mul(b))
        .ok_or_else(|| bad(0, format!("GridSize {size} overflows")))?;
    if p.len() != total {
        return Err(bad(
            pl,
            format!(
                "a {}×{}×{} control grid has {total} parameters, found {}",
                n[0],
                n[1],
                n[2],
                p.len()
            ),
        ));
    }
    // The same transform as an ITK BSplineTransform (the fixed parameters take the direction
    // row-major), read by the one B-spline reader.
    let d = direction.transpose().to_cols_array();
    let fixed: Vec<String> = n
        .iter()
        .map(|v| v.to_string())
        .chain(origin.to_array().iter().map(|v| fmt_f64(*v)))
        .chain(spacing.to_array().iter().map(|v| fmt_f64(*v)))
        .chain(d.iter().map(|v| fmt_f64(*v)))
        .collect();
    let params: Vec<String> = p.iter().map(|v| fmt_f64(*v)).collect();
    let text = format!(
        "{}\n#Transform 0\nTransform: BSplineTransform_double_3_3\nParameters: {}\n\
         FixedParameters: {}\n",
        volmorph_lattice::formats::itk_tfm::ITK_TFM_HEADER,
        params.join(" "),
        fixed.join(" ")
    );
    volmorph_lattice::formats::itk_tfm::parse_itk_tfm(&text)
        .map(AnyMap::Lattice)
        .map_err(|e| MapError::Invalid(format!("BSplineTransform at line {pl}: {e}")))
}

/// Read the elastix parameter file at `path` (its `text` already read) and its chain of
/// initial transforms (see the [module docs](self)).
///
/// # Errors
/// As [`parse_elastix`], for this file and every file of the chain; a chain longer than
/// [`MAX_CHAIN`] or returning to a file already read; an initial file that is missing, or
/// outside the folder of the file naming it without external data allowed. Every error is a
/// [`MapError::File`] naming the file it is about (the file naming a missing initial file).
pub fn read_elastix(path: &Path, text: &str) -> Result<AnyMap, MapError> {
    let allow = volmorph_volume_io::ReadOptions::default().allow_external_data;
    let mut seen: Vec<PathBuf> = vec![std::fs::canonicalize(path).unwrap_or(path.into())];
    let (mut map, mut initial) = parse_elastix(text).map_err(|e| e.at(path))?;
    let mut here = path.to_path_buf();
    while let Some(name) = initial {
        if seen.len() > MAX_CHAIN {
            return Err(MapError::Invalid(format!(
                "a chain of more than {MAX_CHAIN} initial transforms"
            ))
            .at(&here));
        }
        let next = locate_initial(&here, &name, allow).map_err(|e| e.at(&here))?;
        let canon = std::fs::canonicalize(&next).unwrap_or(next.clone());
        if seen.contains(&canon) {
            return Err(MapError::Invalid(format!(
                "the chain of initial transforms returns to {}",
                next.display()
            ))
            .at(&here));
        }
        seen.push(canon);
        let t = crate::file::read_text(&next).map_err(|e| e.at(&next))?;
        let (first, further) = parse_elastix(&t).map_err(|e| e.at(&next))?;
        map = first.then(map);
        initial = further;
        here = next;
    }
    Ok(map)
}

/// The file that the initial transform entry of the file `from` names.
fn locate_initial(from: &Path, name: &str, allow_external: bool) -> Result<PathBuf, MapError> {
    let folder = from.parent().unwrap_or(Path::new("."));
    let named = Path::new(name);
    let as_written = if named.is_absolute() {
        named.to_path_buf()
    } else {
        folder.join(named)
    };
    let beside = named.file_name().map(|f| folder.join(f));
    let inside = |p: &Path| {
        let (Ok(f), Ok(c)) = (std::fs::canonicalize(folder), std::fs::canonicalize(p)) else {
            return false;
        };
        c.parent() == Some(f.as_path())
    };
    let candidates = [Some(as_written), beside];
    let mut outside: Option<PathBuf> = None;
    for c in candidates.into_iter().flatten() {
        if !c.is_file() {
            continue;
        }
        if allow_external || inside(&c) {
            return Ok(c);
        }
        outside.get_or_insert(c);
    }
    Err(match outside {
        Some(c) => MapError::Invalid(format!(
            "the initial transform {} lies outside the folder of the file naming it; \
             allow it with --allow-external-data",
            c.display()
        )),
        None => MapError::Invalid(format!(
            "the initial transform \"{name}\" is not found (looked for as written and \
             beside this file)"
        )),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_deform::SpaceMap;

    fn close(a: DVec3, b: DVec3) -> bool {
        (a - b).length() < 1e-12
    }

    #[test]
    fn euler_transform_rotates_about_its_centre_in_zxy_order() {
        let text = r#"(Transform "EulerTransform")
(NumberOfParameters 6)
(TransformParameters 0.1 -0.2 0.3 1 2 3)
(InitialTransformParametersFileName "NoInitialTransform")
(HowToCombineTransforms "Compose")
(FixedImageDimension 3)
(MovingImageDimension 3)
(CenterOfRotationPoint 10.0 -5.0 2.5) // the centre
(ComputeZYX "false")
"#;
        let (m, init) = parse_elastix(text).unwrap();
        assert!(init.is_none());
        let c = DVec3::new(10.0, -5.0, 2.5);
        let r = DMat3::from_rotation_z(0.3)
            * DMat3::from_rotation_x(0.1)
            * DMat3::from_rotation_y(-0.2);
        for x in [DVec3::ZERO, DVec3::new(3.0, 4.0, -7.0)] {
            assert!(close(
                m.apply(x),
                r * (x - c) + c + DVec3::new(1.0, 2.0, 3.0)
            ));
        }
        // The centre moves by the translation only.
        assert!(close(m.apply(c), c + DVec3::new(1.0, 2.0, 3.0)));
        let zyx = text.replace("(ComputeZYX \"false\")", "(ComputeZYX \"true\")");
        let (m, _) = parse_elastix(&zyx).unwrap();
        let r = DMat3::from_rotation_z(0.3)
            * DMat3::from_rotation_y(-0.2)
            * DMat3::from_rotation_x(0.1);
        let x = DVec3::new(3.0, 4.0, -7.0);
        assert!(close(
            m.apply(x),
            r * (x - c) + c + DVec3::new(1.0, 2.0, 3.0)
        ));
    }

    #[test]
    fn similarity_and_affine_transforms_follow_itk() {
        // A versor of 90° about z: (0, 0, sin 45°).
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let text = format!(
            "(Transform \"SimilarityTransform\")\n(TransformParameters 0 0 {s} 1 0 0 2)\n\
             (CenterOfRotationPoint 0 0 0)\n"
        );
        let (m, _) = parse_elastix(&text).unwrap();
        assert!(close(m.apply(DVec3::X), DVec3::new(1.0, 2.0, 0.0)));
        let text = "(Transform \"AffineTransform\")\n\
                    (TransformParameters 2 0 0 0 1 0 0 0 1 0 0 1)\n\
                    (CenterOfRotationPoint 1 0 0)\n";
        let (m, _) = parse_elastix(text).unwrap();
        // 2 (x − 1) + 1 along x, then + z.
        assert!(close(
            m.apply(DVec3::new(3.0, 5.0, 0.0)),
            DVec3::new(5.0, 5.0, 1.0)
        ));
    }

    #[test]
    fn bspline_transform_reads_as_the_itk_lattice() {
        // 5×5×5 control points, one moved: its displacement appears at its location.
        let mut p = vec![0.0; 3 * 125];
        let node = 1 + 5 * 2 + 25; // control point (1, 2, 1)
        p[node] = 0.5; // x displacement
        p[250 + node] = -0.25; // z displacement
        let params: Vec<String> = p.iter().map(|v| v.to_string()).collect();
        let text = format!(
            "(Transform \"BSplineTransform\")\n(NumberOfParameters 375)\n\
             (TransformParameters {})\n(GridSize 5 5 5)\n(GridIndex 0 0 0)\n\
             (GridSpacing 2 2 2)\n(GridOrigin -2 -2 -2)\n\
             (GridDirection 1 0 0 0 1 0 0 0 1)\n(BSplineTransformSplineOrder 3)\n\
             (UseCyclicTransform \"false\")\n",
            params.join(" ")
        );
        let (m, _) = parse_elastix(&text).unwrap();
        assert!(matches!(m, AnyMap::Lattice(_)));
        // The cubic B-spline weights at a node: 1/6, 4/6, 1/6. At grid index (1, 2, 1)
        // (x = (0, 2, 0)), the moved control point has weight (4/6)³, the others none.
        let x = DVec3::new(0.0, 2.0, 0.0);
        let w = (4.0f64 / 6.0).powi(3);
        let want = x + DVec3::new(0.5 * w, 0.0, -0.25 * w);
        assert!((m.apply(x) - want).length() < 1e-12, "{}", m.apply(x));
        let short = text
            .replace("(NumberOfParameters 375)\n", "")
            .replace(" 0)\n(GridSize", ")\n(GridSize");
        assert!(parse_elastix(&short).is_err());
    }

    #[test]
    fn initial_transform_chains_compose_initial_first() {
        let dir = tempfile::tempdir().unwrap();
        let t0 = dir.path().join("TransformParameters.0.txt");
        let t1 = dir.path().join("TransformParameters.1.txt");
        std::fs::write(
            &t0,
            "(Transform \"AffineTransform\")\n(TransformParameters 2 0 0 0 2 0 0 0 2 0 0 0)\n\
             (CenterOfRotationPoint 0 0 0)\n\
             (InitialTransformParametersFileName \"NoInitialTransform\")\n",
        )
        .unwrap();
        // Named by an absolute path elsewhere (the folder moved): found beside.
        std::fs::write(
            &t1,
            "(Transform \"TranslationTransform\")\n(TransformParameters 1 0 0)\n\
             (InitialTransformParametersFileName \"/elsewhere/out/TransformParameters.0.txt\")\n\
             (HowToCombineTransforms \"Compose\")\n",
        )
        .unwrap();
        let text = std::fs::read_to_string(&t1).unwrap();
        let m = read_elastix(&t1, &text).unwrap();
        // Initial first: 2x, then + (1, 0, 0).
        assert!(close(m.apply(DVec3::ONE), DVec3::new(3.0, 2.0, 2.0)));
        // Through read_map too (a .txt that is not an ITK file).
        let m = crate::read_map(&t1).unwrap();
        assert!(close(m.apply(DVec3::ONE), DVec3::new(3.0, 2.0, 2.0)));
        // A cycle is refused.
        std::fs::write(
            &t0,
            "(Transform \"TranslationTransform\")\n(TransformParameters 1 0 0)\n\
             (InitialTransformParametersFileName \"TransformParameters.1.txt\")\n",
        )
        .unwrap();
        let e = read_elastix(&t1, &text).unwrap_err().to_string();
        assert!(e.contains("returns"), "{e}");
        // A missing initial file is named.
        std::fs::remove_file(&t0).unwrap();
        let e = read_elastix(&t1, &text).unwrap_err().to_string();
        assert!(e.contains("not found"), "{e}");
    }

    #[test]
    fn malformed_parameter_files_are_refused() {
        for text in [
            "(Transform \"EulerTransform\")\n(TransformParameters 1 2 3)\n",
            "(Transform \"EulerTransform\")\n",
            "(Transform \"SplineKernelTransform\")\n(TransformParameters 1)\n",
            "(Transform \"AffineTransform\")\n(TransformParameters 1 2 nan 4 5 6 7 8 9 1 2 3)\n",
            "(Transform \"TranslationTransform\")\n(TransformParameters 1 2 3)\n(HowToCombineTransforms \"Add\")\n",
            "(Transform \"TranslationTransform\"\n",
            "(Transform \"TranslationTransform)\n(TransformParameters 1 2 3)\n",
            "(Transform \"TranslationTransform\")\n(TransformParameters 1 2 3)\n(FixedImageDimension 2)\n",
            "(Transform \"TranslationTransform\")\n(Transform \"TranslationTransform\")\n",
        ] {
            assert!(parse_elastix(text).is_err(), "{text}");
        }
        // The centred transforms need their centre, as elastix requires.
        let e =
            parse_elastix("(Transform \"EulerTransform\")\n(TransformParameters 0 0 0 1 2 3)\n")
                .unwrap_err()
                .to_string();
        assert!(e.contains("CenterOfRotationPoint"), "{e}");
        assert!(looks_like_elastix("// elastix\n\n(Transform \"X\")"));
        assert!(!looks_like_elastix("#Insight Transform File V1.0\n"));
    }

    const TRANSLATION: &str = "(Transform \"TranslationTransform\")\n(NumberOfParameters 3)\n\
                               (TransformParameters 1 2 3)\n";

    #[test]
    fn both_names_of_the_initial_transform_entry_are_read() {
        for key in [INITIAL_KEY, INITIAL_KEY_OLD] {
            let text = format!("{TRANSLATION}({key} \"out/TransformParameters.0.txt\")\n");
            let (_, initial) = parse_elastix(&text).unwrap();
            assert_eq!(
                initial.as_deref(),
                Some("out/TransformParameters.0.txt"),
                "{key}"
            );
            let none = format!("{TRANSLATION}({key} \"NoInitialTransform\")\n");
            assert_eq!(parse_elastix(&none).unwrap().1, None);
        }
        // Both, naming the same file: read; naming different files: refused, naming both.
        let same =
            format!("{TRANSLATION}({INITIAL_KEY} \"a.txt\")\n({INITIAL_KEY_OLD} \"a.txt\")\n");
        assert_eq!(parse_elastix(&same).unwrap().1.as_deref(), Some("a.txt"));
        let differ = format!(
            "{TRANSLATION}({INITIAL_KEY} \"a.txt\")\n({INITIAL_KEY_OLD} \"NoInitialTransform\")\n"
        );
        let e = parse_elastix(&differ).unwrap_err().to_string();
        assert!(
            e.contains(INITIAL_KEY) && e.contains(INITIAL_KEY_OLD) && e.contains("line 5"),
            "{e}"
        );
    }

    #[test]
    fn entries_that_change_the_transform_unread_are_refused() {
        // (entry added to a translation, what the error names)
        for (entry, named) in [
            (
                "(InitialTransformParameterFilename \"a.txt\")",
                "(InitialTransformParameterFilename …)",
            ),
            (
                "(ITKTransformParameters 1 2 3)",
                "instead of (TransformParameters",
            ),
            (
                "(ITKTransformFixedParameters 0 0 0)",
                "ITKTransformFixedParameters",
            ),
            ("(TransformFileName \"t.tfm\")", "ITK transform file"),
            ("(CenterOfRotation 10 10 10)", "image index"),
            ("(HowToCombineTransforms \"Add\")", "\"Compose\" chains"),
            (
                "(UseDirectionCosines \"false\")",
                "UseDirectionCosines \"false\"",
            ),
            (
                "(UseDirectionCosines \"False\")",
                "expected \"true\" or \"false\"",
            ),
            (
                "(UseBinaryFormatForTransformationParameters \"true\")",
                "binary file",
            ),
            ("(FixedImageDimension 2)", "3-D transforms"),
        ] {
            let text = format!("{TRANSLATION}{entry}\n");
            let e = parse_elastix(&text).unwrap_err().to_string();
            assert!(e.contains(named), "{entry}: {e}");
            assert!(e.contains("line 4"), "{entry}: {e}");
        }
        // The entries elastix writes that leave the transform alone are read past, and the
        // flags spelled as elastix spells them are read.
        let text = format!(
            "{TRANSLATION}(UseDirectionCosines \"true\")\n\
             (UseBinaryFormatForTransformationParameters \"false\")\n\
             (Size 20 18 16)\n(Index 0 0 0)\n(Spacing 2 2 2.5)\n(Origin -20 -16 10)\n\
             (Direction 1 0 0 0 1 0 0 0 1)\n(FixedInternalImagePixelType \"float\")\n\
             (MovingInternalImagePixelType \"float\")\n\
             (ResampleInterpolator \"FinalBSplineInterpolator\")\n\
             (FinalBSplineInterpolationOrder 3)\n(Resampler \"DefaultResampler\")\n\
             (DefaultPixelValue 0)\n(ResultImageFormat \"nii\")\n\
             (ResultImagePixelType \"float32\")\n(CompressResultImage \"false\")\n"
        );
        let (m, _) = parse_elastix(&text).unwrap();
        assert!(close(m.apply(DVec3::ZERO), DVec3::new(1.0, 2.0, 3.0)));
        // (Transform "File"): the transform is in an ITK file.
        let e = parse_elastix("(Transform \"File\")\n(TransformParameters 1)\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("TransformFileName"), "{e}");
        // B-spline orders other than 3, and cyclic grids.
        let bs = |extra: &str| {
            format!(
                "(Transform \"BSplineTransform\")\n(TransformParameters {})\n(GridSize 4 4 4)\n\
                 (GridSpacing 1 1 1)\n(GridOrigin 0 0 0)\n{extra}\n",
                vec!["0"; 192].join(" ")
            )
        };
        assert!(parse_elastix(&bs("")).is_ok());
        for (extra, named) in [
            ("(BSplineTransformSplineOrder 2)", "B-spline order"),
            ("(UseCyclicTransform \"true\")", "cyclic"),
        ] {
            let e = parse_elastix(&bs(extra)).unwrap_err().to_string();
            assert!(e.contains(named), "{extra}: {e}");
        }
    }
}
