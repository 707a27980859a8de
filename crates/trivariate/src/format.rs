//! The JSON file format of aggregate curves, surfaces and volumes.
//!
//! # Format (version 1)
//!
//! ```json
//! {
//!   "format": "volmorph-trivariate",
//!   "version": 1,
//!   "kind": "volume",
//!   "geometry": {
//!     "degrees": [3, 3, 3],
//!     "knots": [[0, 0, 0, 0, 1, 1, 1, 1], [...], [...]],
//!     "dim": 3,
//!     "points": [x, y, z, x, y, z, ...],
//!     "weights": [w, w, ...]
//!   },
//!   "attributes": [
//!     { "name": "density", "spline": { "degrees": [...], "knots": [...], "dim": 1,
//!       "points": [...] } }
//!   ]
//! }
//! ```
//!
//! * `kind` is `"curve"`, `"surface"` or `"volume"` (1, 2 or 3 parametric axes); `degrees` and
//!   `knots` have one entry per axis, in axis order u, v, w.
//! * `knots[a]` is the full knot vector of axis `a` (degree `degrees[a]`, non-decreasing, domain
//!   `[0, 1]`), so axis `a` has `knots[a].len() − degrees[a] − 1` control points.
//! * `points` holds the Cartesian control values, `dim` per control point, axis 0 (u) fastest.
//!   The geometry has `dim = 3` (physical x, y, z).
//! * `weights` (optional; absent = polynomial) holds one weight per control point, each finite
//!   and `> 0`; points are **not** premultiplied by weights.
//! * `attributes` (optional, default empty) lists named attribute splines in the same layout;
//!   names are unique and non-empty.
//!
//! Reading validates everything [`Aggregate`] and [`TensorBSpline`] validate (sorted knots,
//! multiplicities, control-net sizes, weights, unit domains, a non-degenerate geometry) and
//! reports the offending component. Unknown fields are rejected. Files may be gzip-compressed.

use std::io::Write;
use std::path::Path;

use serde::{Deserialize, Serialize};
use volmorph_spline::{KnotVector, TensorBSpline};

use crate::TrivariateError;
use crate::aggregate::{Aggregate, AggregateCurve, AggregateSurface, AggregateVolume, kind_name};
use crate::error::ctx;

/// Value of the `format` field.
pub const FORMAT_NAME: &str = "volmorph-trivariate";
/// The format version this crate writes and reads.
pub const FORMAT_VERSION: u32 = 1;

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SplineJson {
    degrees: Vec<usize>,
    knots: Vec<Vec<f64>>,
    dim: usize,
    points: Vec<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    weights: Option<Vec<f64>>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct AttributeJson {
    name: String,
    spline: SplineJson,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileJson {
    format: String,
    version: u32,
    kind: String,
    geometry: SplineJson,
    #[serde(default)]
    attributes: Vec<AttributeJson>,
}

/// An aggregate of any parametric dimension, as read from a file.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyAggregate {
    /// `"kind": "curve"`.
    Curve(AggregateCurve),
    /// `"kind": "surface"`.
    Surface(AggregateSurface),
    /// `"kind": "volume"`.
    Volume(AggregateVolume),
}

fn spline_to_json<const N: usize>(s: &TensorBSpline<N>) -> SplineJson {
    SplineJson {
        degrees: s.degrees().to_vec(),
        knots: s.knots().iter().map(|k| k.knots().to_vec()).collect(),
        dim: s.dim(),
        points: s.control_points(),
        weights: s.weights(),
    }
}

fn spline_from_json<const N: usize>(
    what: &str,
    j: SplineJson,
) -> Result<TensorBSpline<N>, TrivariateError> {
    if j.degrees.len() != N || j.knots.len() != N {
        return Err(TrivariateError::Json(format!(
            "{what}: a {} needs {N} degrees and {N} knot vectors, got {} and {}",
            kind_name(N),
            j.degrees.len(),
            j.knots.len()
        )));
    }
    let mut kvs = Vec::with_capacity(N);
    for (a, (d, k)) in j.degrees.iter().zip(j.knots).enumerate() {
        kvs.push(KnotVector::new(*d, k).map_err(ctx(format!("{what}, knots of axis {a}")))?);
    }
    let knots: [KnotVector; N] = kvs
        .try_into()
        .map_err(|_| TrivariateError::Json(format!("{what}: wrong number of knot vectors")))?;
    let s = match j.weights {
        None => TensorBSpline::new(knots, j.dim, j.points),
        Some(w) => TensorBSpline::new_rational(knots, j.dim, j.points, w),
    };
    s.map_err(ctx(format!("{what}, control net")))
}

/// Serialise an aggregate to a JSON string (format in the [module docs](self)).
///
/// # Errors
/// [`TrivariateError::Json`] if serialisation fails (it does not for valid aggregates).
pub fn to_json_string<const N: usize>(a: &Aggregate<N>) -> Result<String, TrivariateError> {
    let f = FileJson {
        format: FORMAT_NAME.to_owned(),
        version: FORMAT_VERSION,
        kind: kind_name(N).to_owned(),
        geometry: spline_to_json(a.geometry()),
        attributes: a
            .attributes()
            .iter()
            .map(|at| AttributeJson {
                name: at.name().to_owned(),
                spline: spline_to_json(at.spline()),
            })
            .collect(),
    };
    serde_json::to_string_pretty(&f).map_err(|e| TrivariateError::Json(e.to_string()))
}

fn build<const N: usize>(f: FileJson) -> Result<Aggregate<N>, TrivariateError> {
    let mut a = Aggregate::new(spline_from_json("geometry", f.geometry)?)?;
    for at in f.attributes {
        let what = format!("attribute {:?}", at.name);
        a.add_attribute(at.name, spline_from_json(&what, at.spline)?)?;
    }
    Ok(a)
}

/// Parse and validate a JSON document of any kind.
///
/// # Errors
/// [`TrivariateError::Json`] for malformed JSON (with line and column), a wrong `format`,
/// `version` or `kind`, or mismatched array counts; [`TrivariateError::Spline`] naming the
/// component for unsorted knots, wrong control-net sizes or non-positive weights; the errors of
/// [`Aggregate::new`] and [`Aggregate::add_attribute`] (domains, degeneracy, names).
pub fn from_json_str(text: &str) -> Result<AnyAggregate, TrivariateError> {
    let f: FileJson =
        serde_json::from_str(text).map_err(|e| TrivariateError::Json(e.to_string()))?;
    if f.format != FORMAT_NAME {
        return Err(TrivariateError::Json(format!(
            "format is {:?}, expected {FORMAT_NAME:?}",
            f.format
        )));
    }
    if f.version != FORMAT_VERSION {
        return Err(TrivariateError::Json(format!(
            "version {} is not supported (expected {FORMAT_VERSION})",
            f.version
        )));
    }
    match f.kind.as_str() {
        "curve" => Ok(AnyAggregate::Curve(build(f)?)),
        "surface" => Ok(AnyAggregate::Surface(build(f)?)),
        "volume" => Ok(AnyAggregate::Volume(build(f)?)),
        other => Err(TrivariateError::Json(format!(
            "kind {other:?} is not \"curve\", \"surface\" or \"volume\""
        ))),
    }
}

/// Read an aggregate of any kind from a JSON file (optionally gzip-compressed).
///
/// # Errors
/// [`TrivariateError::Io`] if the file cannot be read, [`TrivariateError::Json`] for
/// non-UTF-8 text, else as [`from_json_str`].
pub fn load(path: &Path) -> Result<AnyAggregate, TrivariateError> {
    let bytes = volmorph_io::read_maybe_gz(path)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| TrivariateError::Json(format!("{}: not UTF-8 ({e})", path.display())))?;
    from_json_str(text)
}

/// Read an aggregate volume; a curve or surface file is an error.
///
/// # Errors
/// As [`load`], plus [`TrivariateError::Json`] when the file holds another kind.
pub fn load_volume(path: &Path) -> Result<AggregateVolume, TrivariateError> {
    match load(path)? {
        AnyAggregate::Volume(v) => Ok(v),
        AnyAggregate::Curve(_) | AnyAggregate::Surface(_) => Err(TrivariateError::Json(format!(
            "{} holds a curve or surface, not a volume",
            path.display()
        ))),
    }
}

impl AnyAggregate {
    /// The file's `"kind"`: `curve`, `surface` or `volume`.
    #[must_use]
    pub fn kind(&self) -> &'static str {
        match self {
            AnyAggregate::Curve(_) => "curve",
            AnyAggregate::Surface(_) => "surface",
            AnyAggregate::Volume(_) => "volume",
        }
    }

    /// The names of the attributes, in the aggregate's order.
    #[must_use]
    pub fn attribute_names(&self) -> Vec<&str> {
        fn names<const N: usize>(a: &Aggregate<N>) -> Vec<&str> {
            a.attributes().iter().map(|a| a.name()).collect()
        }
        match self {
            AnyAggregate::Curve(m) => names(m),
            AnyAggregate::Surface(m) => names(m),
            AnyAggregate::Volume(m) => names(m),
        }
    }

    /// Write the aggregate as JSON, as [`save`] does.
    ///
    /// # Errors
    /// As [`save`].
    pub fn save(&self, path: &Path) -> Result<(), TrivariateError> {
        match self {
            AnyAggregate::Curve(m) => save(path, m),
            AnyAggregate::Surface(m) => save(path, m),
            AnyAggregate::Volume(m) => save(path, m),
        }
    }
}

/// The extension of trivariate model files ([`save`]): `.json`.
pub const EXTENSIONS: &[&str] = volmorph_io::extension::OutputFormat::Json.extensions();

/// Check that `path` ends in `.json` (any case) before a model is built or fitted for it.
///
/// # Errors
/// [`TrivariateError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
/// extension found and `.json`.
pub fn check_output(path: &Path) -> Result<(), TrivariateError> {
    Ok(volmorph_io::extension::check(path, EXTENSIONS)?)
}

/// Write an aggregate as JSON through a temporary file renamed over `path`.
///
/// # Errors
/// [`TrivariateError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in
/// `.json` ([`check_output`], nothing written); [`TrivariateError::Io`] if the file cannot be
/// written.
pub fn save<const N: usize>(path: &Path, a: &Aggregate<N>) -> Result<(), TrivariateError> {
    check_output(path)?;
    let text = to_json_string(a)?;
    volmorph_io::write_atomic(path, |w| {
        w.write_all(text.as_bytes())
            .map_err(|e| TrivariateError::Io(volmorph_io::IoError::os(path, e)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube_json(extra: &str, weights: &str, knots_u: &str) -> String {
        let mut pts = Vec::new();
        for k in 0..2 {
            for j in 0..2 {
                for i in 0..2 {
                    pts.push(format!("{i}, {j}, {k}"));
                }
            }
        }
        format!(
            r#"{{"format": "volmorph-trivariate", "version": 1, "kind": "volume",
            "geometry": {{"degrees": [1, 1, 1], "knots": [{knots_u}, [0, 0, 1, 1], [0, 0, 1, 1]],
              "dim": 3, "points": [{}] {weights} }} {extra} }}"#,
            pts.join(", ")
        )
    }

    #[test]
    fn parses_minimal_volume() {
        let a = from_json_str(&cube_json("", "", "[0, 0, 1, 1]")).unwrap();
        let AnyAggregate::Volume(v) = a else {
            panic!("not a volume")
        };
        let p = v.point([0.5, 0.25, 1.0]).unwrap();
        assert_eq!(p, [0.5, 0.25, 1.0]);
    }

    #[test]
    fn bad_input_names_the_problem() {
        let err = |s: String| from_json_str(&s).unwrap_err().to_string();
        let e = err(cube_json("", "", "[0, 1, 0, 1]"));
        assert!(
            e.contains("geometry, knots of axis 0") && e.contains("decrease"),
            "{e}"
        );
        let e = err(cube_json(
            "",
            r#", "weights": [1, 1, 1, 1, 1, 1, 1, 0]"#,
            "[0, 0, 1, 1]",
        ));
        assert!(e.contains("weight"), "{e}");
        let e = err(cube_json("", "", "[0, 0, 0.5, 1, 1]"));
        assert!(e.contains("control net") && e.contains("expected"), "{e}");
        let e = err(cube_json("", "", "[0, 0, 2, 2]"));
        assert!(e.contains("expected [0, 1]"), "{e}");
        let e = err(cube_json(
            r#", "attributes": [{"name": "d", "spline": {"degrees": [0, 0], "knots": [[0, 1], [0, 1]], "dim": 1, "points": [1]}}]"#,
            "",
            "[0, 0, 1, 1]",
        ));
        assert!(
            e.contains("attribute \"d\"") && e.contains("3 degrees"),
            "{e}"
        );
        let e = err(cube_json("", "", "[0, 0, 1, 1]").replace("\"volume\"", "\"blob\""));
        assert!(e.contains("blob"), "{e}");
        let e = err(cube_json("", "", "[0, 0, 1, 1]").replace("\"version\": 1", "\"version\": 9"));
        assert!(e.contains("version 9"), "{e}");
        let e = err("{\"format\": ".to_owned());
        assert!(e.contains("line 1"), "{e}");
        // Degenerate: all control points at z = 0.
        let good = cube_json("", "", "[0, 0, 1, 1]");
        let (head, tail) = good.split_once("\"points\": [").unwrap();
        let rest = tail.split_once(']').unwrap().1;
        let flat = format!(
            "{head}\"points\": [{}]{rest}",
            ["0, 0, 0", "1, 0, 0", "0, 1, 0", "1, 1, 0"]
                .repeat(2)
                .join(", ")
        );
        let e = from_json_str(&flat).unwrap_err();
        assert!(
            matches!(e, TrivariateError::Degenerate { rank: 2, .. }),
            "{e}"
        );
    }
}
