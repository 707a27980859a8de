//! Mapping specifications: the JSON documents that say which extended space mappings
//! (Savchenko & Pasko §4) to apply to a model, in order — what `volmorph frep map --mapping
//! SPEC.json` reads, and what the studio and Python can hand to [`MappingSpec::apply`].
//!
//! A document is `{"version": 1, "mappings": [ … ]}`; each mapping is an object tagged by
//! `"kind"` and transforms the result of the one before it (the first transforms the model).
//! Points are `[x, y, z]` in the model's units; schedules are `"linear"`, `"sqrt"`,
//! `"smoothstep"` or `"delayed:T0"` ([`Schedule`]); a model is `{"file": "b.hf"}` (relative
//! to the specification's folder, which it must not leave unless external data is allowed)
//! or `{"source": "…HyperFun text…"}`, with optional `"params": {"a1": 0.5}` and its own
//! `"mappings"` (nesting).
//!
//! | `kind` | fields | result |
//! | --- | --- | --- |
//! | `offset` | `d` | `f + d` (Eq. 10, [`mapping::offset`]) |
//! | `control-points` | `points`: `{"at": p, "radius": r}` or `{"at": p, "axes": [a₁, a₂, a₃]}` | Eq. 11 ([`mapping::control_points`], Fig. 2) |
//! | `spline-points` | `points`, optional `values` (default 0), `smoothing` | `f + U`, `U` the volume spline through `vᵢ − f(pᵢ)` ([`mapping::spline_points`]) |
//! | `convolution` | `curve`, `a`, `intervals` (even, default 64) | Eq. 12 ([`mapping::convolution_deformation`], Fig. 3) |
//! | `metamorphosis` | `target` (a model), `schedule` (default linear) or fixed `weights: [h₁, h₂]` | Eq. 13 ([`mapping::morph`], [`mapping::metamorphosis`]) |
//! | `handles` | `sources`, `targets`, `smoothing`, optional `schedule` | Eq. 15–16, volume spline ([`mapping::displace_by_handles_shape`], Fig. 5–6) |
//! | `affine` | `matrix` (rows, default identity), `offset` | the push-forward `x ↦ Mx + o` (Eq. 15, [`mapping::affine`]) |
//! | `offset-normal` | `d`, or `distance` (a model) times `scale` | `f(x + d ∇f)` (Eq. 17, [`mapping::offset_along_gradient`], [`mapping::offset_along_gradient_by`], Fig. 7) |
//! | `shell` | `a`, `b` | Fig. 8 ([`mapping::thin_shell`]) |
//! | `maze` | `a`, `b`, `c` | Fig. 9 ([`mapping::maze`]) |
//! | `combined` | `target`, `sources`, `targets`, `smoothing`, `h1`, `h2` | Eq. 18, Fig. 10c ([`mapping::combined`]) |
//! | `collision-free-motion` | `target`, `obstacles`, `path`, `control_points`, `local_bounds`, `h1`, `search` | Fig. 12 ([`crate::motion`]) |
//! | `sequence` | `mappings` | the list, in order |
//!
//! A curve is `{"type": "polyline", "points": [p, …]}` (parameter proportional to arc length),
//! `{"type": "bezier", "points": [p, …]}` or `{"type": "helix", "center": p, "axis": v,
//! "radius": r, "pitch": h, "turns": n, "phase": degrees}` (the seed's spiral; `axis`
//! defaults to `z`, `phase` to 0).
//!
//! Mappings with a schedule depend on the time `t ∈ [0, 1]` ([`Mapped::shape_at`]); at
//! `t = 1` every schedule is 1, the whole mapping. Without one, `handles` is applied fully and
//! `metamorphosis` uses `weights` when given.
//!
//! **Errors** name the JSON path of the bad field (`mappings[2].points[0].radius`), both for
//! malformed documents ([`MappingSpec::from_json`]) and for values out of range or models that
//! do not load ([`MappingSpec::apply`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Deserializer, Serialize};

use crate::compile::{CompileOptions, compile_file, compile_source};
use crate::error::FrepError;
use crate::mapping::{self, ControlPoint, Schedule, SplineDisplacement};
use crate::motion::{AvoidanceOptions, MotionSetup, MotionSolution};
use crate::shape::Shape;

/// The version of the documents written and the only one read.
pub const SPEC_VERSION: u64 = 1;

/// Deepest nesting of `sequence`s and models with mappings accepted.
pub const MAX_NESTING: usize = 32;

/// Largest number of points in one list of a specification (control points, handles, curve
/// points): the mappings become expressions of a few nodes per point, and splines solve
/// dense systems.
pub const MAX_POINTS: usize = 10_000;

/// A mapping specification: `{"version": 1, "mappings": [...]}` (see the
/// [module documentation](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MappingSpec {
    /// [`SPEC_VERSION`].
    pub version: u64,
    /// Applied in order, each to the result of the one before.
    pub mappings: Vec<Mapping>,
}

/// One mapping, tagged by `"kind"` in JSON.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum Mapping {
    /// Iso-valued offset (Eq. 10 with a constant).
    Offset(Offset),
    /// Function mapping by control points (Eq. 11).
    ControlPoints(ControlPoints),
    /// Function mapping by a volume spline through control points (§4.1.1).
    SplinePoints(SplinePoints),
    /// Convolution deformation along a curve (Eq. 12).
    Convolution(Convolution),
    /// Metamorphosis (Eq. 13).
    Metamorphosis(Metamorphosis),
    /// Coordinate space mapping by handles and a volume spline (Eq. 15–16).
    Handles(Handles),
    /// Coordinate space mapping by an affine push-forward (Eq. 15).
    Affine(AffineMap),
    /// Offset along the gradient (Eq. 17).
    OffsetNormal(OffsetNormal),
    /// Thin shell (Eq. 17, Fig. 8).
    Shell(Shell),
    /// Maze (Eq. 17, Fig. 9).
    Maze(Maze),
    /// Combined mapping (Eq. 18, Fig. 10c).
    Combined(Combined),
    /// Combined mapping with collision-free motion (Fig. 12).
    CollisionFreeMotion(CollisionFreeMotion),
    /// A list of mappings applied in order.
    Sequence(Sequence),
}

/// `offset`: `f + d`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Offset {
    /// The constant added (positive expands the solid).
    pub d: f64,
}

/// A control point of `control-points`: a sphere of influence (`radius`) or an ellipsoid
/// (`axes`: three semi-axis vectors).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlPointSpec {
    /// Position, meant to lie on the deformed surface.
    pub at: [f64; 3],
    /// Radius of a spherical area of influence.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Semi-axis vectors of an elliptic area of influence.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axes: Option<[[f64; 3]; 3]>,
}

/// `control-points` (Eq. 11).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlPoints {
    /// The points.
    pub points: Vec<ControlPointSpec>,
}

/// `spline-points`: `f + U` with `U(pᵢ) = vᵢ − f(pᵢ)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplinePoints {
    /// The points `pᵢ` (at least 4, not coplanar).
    pub points: Vec<[f64; 3]>,
    /// The values `vᵢ` of the result there (default all 0: on the surface).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub values: Option<Vec<f64>>,
    /// Spline smoothing (0 interpolates).
    #[serde(default)]
    pub smoothing: f64,
}

/// A parametric curve `c(t)`, `t ∈ [0, 1]`, tagged by `"type"`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub enum Curve {
    /// Straight segments through the points, `t` proportional to arc length.
    Polyline(PointList),
    /// The Bézier curve of the control points.
    Bezier(PointList),
    /// A helix (the seed's spiral).
    Helix(Helix),
}

/// Points of a polyline or Bézier curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointList {
    /// At least 2 points.
    pub points: Vec<[f64; 3]>,
}

/// `c(t) = center + r (cos θ u + sin θ v) + t·turns·pitch·w`, `θ = phase + 2π·turns·t`, with
/// `w` the unit axis and `u`, `v` completing a right-handed frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Helix {
    /// Centre of the first turn's circle.
    pub center: [f64; 3],
    /// Axis direction (default `z`).
    #[serde(default = "z_axis")]
    pub axis: [f64; 3],
    /// Radius.
    pub radius: f64,
    /// Advance along the axis per turn.
    pub pitch: f64,
    /// Number of turns.
    pub turns: f64,
    /// Starting angle in degrees.
    #[serde(default)]
    pub phase: f64,
}

fn z_axis() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// `convolution` (Eq. 12).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Convolution {
    /// The control curve.
    pub curve: Curve,
    /// Decay length of `e^{−r/a}`.
    pub a: f64,
    /// Simpson sub-intervals (even, 2 to 65536).
    #[serde(default = "default_intervals")]
    pub intervals: usize,
}

fn default_intervals() -> usize {
    64
}

/// A model referenced by a specification.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ModelRef {
    /// A HyperFun file, relative to the specification's folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// HyperFun text (instead of `file`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// Model parameters, `"a1": 0.5`.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub params: BTreeMap<String, f64>,
    /// Mappings applied to this model first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub mappings: Vec<Mapping>,
}

/// `metamorphosis` (Eq. 13).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Metamorphosis {
    /// The shape morphed into.
    pub target: ModelRef,
    /// `h(t)`: the result is `(1 − h) f + h g`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule: Option<String>,
    /// Fixed weights `[h₁, h₂]`: `h₁ f + h₂ g` (instead of a schedule).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<[f64; 2]>,
}

/// `handles` (Eq. 15–16).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Handles {
    /// Points `Qᵢ` of the model.
    pub sources: Vec<[f64; 3]>,
    /// Where they go, `Dᵢ` (at least 4, not coplanar).
    pub targets: Vec<[f64; 3]>,
    /// Spline smoothing (0 interpolates).
    #[serde(default)]
    pub smoothing: f64,
    /// Motion over time (`s = h(t)`); none: the whole motion.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule: Option<String>,
}

/// `affine`: the push-forward `x ↦ M x + o`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AffineMap {
    /// `M` as rows (default identity).
    #[serde(default = "identity_rows")]
    pub matrix: [[f64; 3]; 3],
    /// `o` (default 0).
    #[serde(default)]
    pub offset: [f64; 3],
}

fn identity_rows() -> [[f64; 3]; 3] {
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
}

/// `offset-normal` (Eq. 17).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OffsetNormal {
    /// A constant distance factor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub d: Option<f64>,
    /// A model whose value (times `scale`) is the distance factor at each point.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance: Option<ModelRef>,
    /// Factor on `distance` (default 1).
    #[serde(default = "one")]
    pub scale: f64,
}

fn one() -> f64 {
    1.0
}

/// `shell` (Fig. 8): `ψ = a f + b`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shell {
    /// `a`.
    pub a: f64,
    /// `b`.
    pub b: f64,
}

/// `maze` (Fig. 9): `ψ = a sin(b f + c)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Maze {
    /// `a`.
    pub a: f64,
    /// `b`.
    pub b: f64,
    /// `c`.
    #[serde(default)]
    pub c: f64,
}

/// `combined` (Eq. 18).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Combined {
    /// The final shape `d₁`.
    pub target: ModelRef,
    /// Control points of the coordinate mapping, `Qᵢ`.
    pub sources: Vec<[f64; 3]>,
    /// Where they go, `Dᵢ`.
    pub targets: Vec<[f64; 3]>,
    /// Spline smoothing.
    #[serde(default)]
    pub smoothing: f64,
    /// Metamorphosis schedule `h₁` (default linear).
    #[serde(default = "linear")]
    pub h1: String,
    /// Coordinate-mapping schedule `h₂` (default linear).
    #[serde(default = "linear")]
    pub h2: String,
}

fn linear() -> String {
    "linear".into()
}

/// Search settings of `collision-free-motion` ([`AvoidanceOptions`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Search {
    /// Keyframes (default 17).
    #[serde(default = "default_keyframes")]
    pub keyframes: usize,
    /// Population (default 24).
    #[serde(default = "default_population")]
    pub population: usize,
    /// Generations per keyframe (default 30).
    #[serde(default = "default_generations")]
    pub generations: usize,
    /// Largest displacement per coordinate (default: a quarter of the local box's smallest
    /// side).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_displacement: Option<f64>,
    /// Penalty weight (default 0.01).
    #[serde(default = "default_stiffness")]
    pub stiffness: f64,
    /// Grid points per axis of the interpenetration count (default 24).
    #[serde(default = "default_samples")]
    pub samples: usize,
    /// Random seed (default 1).
    #[serde(default = "default_seed")]
    pub seed: u64,
}

fn default_keyframes() -> usize {
    AvoidanceOptions::default().keyframes
}
fn default_population() -> usize {
    AvoidanceOptions::default().population
}
fn default_generations() -> usize {
    AvoidanceOptions::default().generations
}
fn default_stiffness() -> f64 {
    AvoidanceOptions::default().stiffness
}
fn default_samples() -> usize {
    AvoidanceOptions::default().samples
}
fn default_seed() -> u64 {
    AvoidanceOptions::default().seed
}

impl Default for Search {
    fn default() -> Self {
        Self {
            keyframes: default_keyframes(),
            population: default_population(),
            generations: default_generations(),
            max_displacement: None,
            stiffness: default_stiffness(),
            samples: default_samples(),
            seed: default_seed(),
        }
    }
}

/// `collision-free-motion` (Fig. 12): the model (in local coordinates) moves along `path`
/// while it turns into `target`, its control points displaced to avoid `obstacles`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CollisionFreeMotion {
    /// The final shape (local coordinates).
    pub target: ModelRef,
    /// The obstacles (world coordinates).
    pub obstacles: ModelRef,
    /// Frame origin keyframes, evenly spaced in time.
    pub path: Vec<[f64; 3]>,
    /// Control points in local coordinates.
    pub control_points: Vec<[f64; 3]>,
    /// `[min, max]` corners of a local box holding the object.
    pub local_bounds: [[f64; 3]; 2],
    /// Metamorphosis schedule (default linear).
    #[serde(default = "linear")]
    pub h1: String,
    /// Spline smoothing.
    #[serde(default)]
    pub smoothing: f64,
    /// The genetic search.
    #[serde(default)]
    pub search: Search,
}

/// `sequence`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sequence {
    /// Applied in order.
    pub mappings: Vec<Mapping>,
}

/// Marks the JSON path of an error raised inside a tagged object, so that the path of the
/// object and the path inside it can be joined (see [`decode_path`]).
const PATH_MARK: char = '\u{1}';

/// Deserialize the fields of a tagged object (the tag removed) as `T`, reporting an error's
/// path inside the object ahead of its message.
fn fields<T: DeserializeOwned, E: serde::de::Error>(v: serde_json::Value) -> Result<T, E> {
    serde_path_to_error::deserialize(v).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner().to_string();
        if path == "." || path.is_empty() {
            E::custom(inner)
        } else {
            E::custom(format!("{PATH_MARK}{path}{PATH_MARK}{inner}"))
        }
    })
}

/// Split a tagged object into its tag and the other fields.
fn untag<E: serde::de::Error>(
    mut v: serde_json::Value,
    tag: &str,
    what: &str,
    names: &[&str],
) -> Result<(String, serde_json::Value), E> {
    let expected = names.join(", ");
    let Some(obj) = v.as_object_mut() else {
        return Err(E::custom(format!(
            "{what} is an object with a \"{tag}\" (one of {expected})"
        )));
    };
    let Some(t) = obj.remove(tag) else {
        return Err(E::custom(format!(
            "missing field `{tag}` (one of {expected})"
        )));
    };
    match t.as_str() {
        Some(s) if names.contains(&s) => Ok((s.to_string(), v)),
        _ => Err(E::custom(format!(
            "{PATH_MARK}{tag}{PATH_MARK}unknown {what} {t}, expected one of {expected}"
        ))),
    }
}

const MAPPING_KINDS: [&str; 13] = [
    "offset",
    "control-points",
    "spline-points",
    "convolution",
    "metamorphosis",
    "handles",
    "affine",
    "offset-normal",
    "shell",
    "maze",
    "combined",
    "collision-free-motion",
    "sequence",
];

impl<'de> Deserialize<'de> for Mapping {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = serde_json::Value::deserialize(d)?;
        let (kind, rest) = untag::<D::Error>(v, "kind", "mapping", &MAPPING_KINDS)?;
        Ok(match kind.as_str() {
            "offset" => Mapping::Offset(fields(rest)?),
            "control-points" => Mapping::ControlPoints(fields(rest)?),
            "spline-points" => Mapping::SplinePoints(fields(rest)?),
            "convolution" => Mapping::Convolution(fields(rest)?),
            "metamorphosis" => Mapping::Metamorphosis(fields(rest)?),
            "handles" => Mapping::Handles(fields(rest)?),
            "affine" => Mapping::Affine(fields(rest)?),
            "offset-normal" => Mapping::OffsetNormal(fields(rest)?),
            "shell" => Mapping::Shell(fields(rest)?),
            "maze" => Mapping::Maze(fields(rest)?),
            "combined" => Mapping::Combined(fields(rest)?),
            "collision-free-motion" => Mapping::CollisionFreeMotion(fields(rest)?),
            _ => Mapping::Sequence(fields(rest)?),
        })
    }
}

impl<'de> Deserialize<'de> for Curve {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = serde_json::Value::deserialize(d)?;
        let (kind, rest) = untag::<D::Error>(v, "type", "curve", &["polyline", "bezier", "helix"])?;
        Ok(match kind.as_str() {
            "polyline" => Curve::Polyline(fields(rest)?),
            "bezier" => Curve::Bezier(fields(rest)?),
            _ => Curve::Helix(fields(rest)?),
        })
    }
}

/// Join the outer JSON path of an error with the paths marked in its message
/// ([`PATH_MARK`]): `("mappings[2]", "␁points[0].radius␁invalid type …")` gives
/// `("mappings[2].points[0].radius", "invalid type …")`.
fn decode_path(outer: &str, message: &str) -> (String, String) {
    let mut path = if outer == "." {
        String::new()
    } else {
        outer.to_string()
    };
    let mut msg = message;
    while let Some(rest) = msg.strip_prefix(PATH_MARK) {
        let Some((inner, tail)) = rest.split_once(PATH_MARK) else {
            break;
        };
        path = join(&path, inner);
        msg = tail;
    }
    (path, msg.to_string())
}

fn join(outer: &str, inner: &str) -> String {
    if outer.is_empty() {
        inner.to_string()
    } else if inner.starts_with('[') {
        format!("{outer}{inner}")
    } else {
        format!("{outer}.{inner}")
    }
}

fn spec_err(path: impl Into<String>, message: impl std::fmt::Display) -> FrepError {
    FrepError::Spec {
        path: path.into(),
        message: message.to_string(),
    }
}

impl MappingSpec {
    /// A specification of `mappings`.
    #[must_use]
    pub fn new(mappings: Vec<Mapping>) -> Self {
        Self {
            version: SPEC_VERSION,
            mappings,
        }
    }

    /// Parse a document. Only the form is checked here (fields, types, the version);
    /// values are checked by [`apply`](Self::apply).
    ///
    /// # Errors
    /// [`FrepError::Spec`] with the JSON path of the bad field: not JSON, a missing or
    /// unknown field, a value of the wrong type, an unknown `kind`, another version, nesting
    /// deeper than [`MAX_NESTING`].
    pub fn from_json(text: &str) -> Result<Self, FrepError> {
        let mut de = serde_json::Deserializer::from_str(text);
        let spec: MappingSpec = serde_path_to_error::deserialize(&mut de).map_err(|e| {
            let outer = e.path().to_string();
            let (path, message) = decode_path(&outer, &e.into_inner().to_string());
            spec_err(path, message)
        })?;
        de.end()
            .map_err(|e| spec_err("", format!("text after the document: {e}")))?;
        if spec.version != SPEC_VERSION {
            return Err(spec_err(
                "version",
                format!(
                    "version {} is not supported (this is version {SPEC_VERSION})",
                    spec.version
                ),
            ));
        }
        check_depth(&spec.mappings, "mappings", 0)?;
        Ok(spec)
    }

    /// Read a specification file ([`from_json`](Self::from_json) on its text, at most
    /// [`crate::lang::MAX_SOURCE_BYTES`]).
    ///
    /// # Errors
    /// [`FrepError::InFile`] naming `path` around the error.
    pub fn read(path: &Path) -> Result<Self, FrepError> {
        let in_file = |e: FrepError| FrepError::InFile {
            path: path.display().to_string(),
            source: Box::new(e),
        };
        let bytes = crate::compile::read_bounded(path).map_err(in_file)?;
        let text = String::from_utf8(bytes)
            .map_err(|_| in_file(spec_err("", "the file is not UTF-8 text")))?;
        Self::from_json(&text).map_err(in_file)
    }

    /// The document as pretty JSON (reads back to an equal specification).
    #[must_use]
    pub fn to_json(&self) -> String {
        // Serialising these types cannot fail: every map key is a string.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Check every value, load the referenced models and prepare the mappings for `model`.
    ///
    /// # Errors
    /// [`FrepError::Spec`] naming the JSON path of a value out of range, a model that does
    /// not load, or a mapping that cannot be built (too few or coplanar handles, a singular
    /// matrix, …).
    pub fn apply(&self, model: &Shape, context: &SpecContext) -> Result<Mapped, FrepError> {
        self.apply_with(model, context, &volmorph_io::NoProgress)
    }

    /// [`apply`](Self::apply) reporting to `progress` (the collision-avoiding search of
    /// `collision-free-motion` can take seconds; see [`MotionSetup::solve_with`]).
    ///
    /// # Errors
    /// As [`apply`](Self::apply); [`FrepError::Cancelled`] when `progress` asks to stop.
    pub fn apply_with(
        &self,
        model: &Shape,
        context: &SpecContext,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Mapped, FrepError> {
        let steps = build_steps(&self.mappings, "mappings", model, context, progress)?;
        Ok(Mapped {
            base: model.clone(),
            steps,
        })
    }
}

fn check_depth(list: &[Mapping], path: &str, depth: usize) -> Result<(), FrepError> {
    if depth > MAX_NESTING {
        return Err(spec_err(
            path,
            format!("mappings nested deeper than {MAX_NESTING}"),
        ));
    }
    for (i, m) in list.iter().enumerate() {
        let p = format!("{path}[{i}]");
        let models: Vec<(&ModelRef, &str)> = match m {
            Mapping::Sequence(s) => {
                check_depth(&s.mappings, &format!("{p}.mappings"), depth + 1)?;
                vec![]
            }
            Mapping::Metamorphosis(x) => vec![(&x.target, "target")],
            Mapping::Combined(x) => vec![(&x.target, "target")],
            Mapping::CollisionFreeMotion(x) => {
                vec![(&x.target, "target"), (&x.obstacles, "obstacles")]
            }
            Mapping::OffsetNormal(x) => x.distance.iter().map(|d| (d, "distance")).collect(),
            _ => vec![],
        };
        for (model, name) in models {
            check_depth(&model.mappings, &format!("{p}.{name}.mappings"), depth + 1)?;
        }
    }
    Ok(())
}

/// Where a specification's files are and what they may name.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SpecContext {
    /// The specification's folder: model files are relative to it and must stay inside it.
    pub dir: PathBuf,
    /// Accept model files outside [`dir`](Self::dir) (also accepted when
    /// `volmorph-volume-io`'s process-wide default allows external data).
    pub allow_external_data: bool,
}

impl SpecContext {
    /// The context of a specification file: its folder.
    #[must_use]
    pub fn of_file(path: &Path) -> Self {
        Self {
            dir: path.parent().unwrap_or(Path::new("")).to_path_buf(),
            allow_external_data: false,
        }
    }
}

/// A model with its mappings resolved: the shape at any time ([`Mapped::shape_at`]).
#[derive(Debug, Clone)]
pub struct Mapped {
    base: Shape,
    steps: Vec<(String, Step)>,
}

/// A mapping with its values checked and its models loaded.
#[derive(Debug, Clone)]
enum Step {
    Offset(f64),
    ControlPoints(Vec<ControlPoint>),
    SplinePoints {
        points: Vec<DVec3>,
        values: Vec<f64>,
        smoothing: f64,
    },
    Convolution {
        curve: CurveFn,
        a: f64,
        intervals: usize,
    },
    Metamorphosis {
        target: Box<Mapped>,
        weights: Weights,
    },
    Handles {
        spline: SplineDisplacement,
        schedule: Option<Schedule>,
    },
    Affine(DMat3, DVec3),
    OffsetNormal(f64),
    OffsetNormalBy {
        distance: Box<Mapped>,
        scale: f64,
    },
    Shell(f64, f64),
    Maze(f64, f64, f64),
    Combined {
        target: Box<Mapped>,
        spline: SplineDisplacement,
        h1: Schedule,
        h2: Schedule,
    },
    Motion(Box<MotionSolution>),
    Sequence(Vec<(String, Step)>),
}

#[derive(Debug, Clone, Copy)]
enum Weights {
    Schedule(Schedule),
    Fixed(f64, f64),
}

/// A curve ready to evaluate.
#[derive(Debug, Clone)]
enum CurveFn {
    /// Points and their cumulative arc lengths (normalised to end at 1).
    Polyline(Vec<DVec3>, Vec<f64>),
    Bezier(Vec<DVec3>),
    Helix {
        center: DVec3,
        u: DVec3,
        v: DVec3,
        w: DVec3,
        radius: f64,
        pitch: f64,
        turns: f64,
        phase: f64,
    },
}

impl CurveFn {
    fn at(&self, t: f64) -> DVec3 {
        match self {
            CurveFn::Polyline(p, s) => {
                let i = s.partition_point(|&v| v < t).clamp(1, p.len() - 1);
                let (s0, s1) = (s[i - 1], s[i]);
                let w = if s1 > s0 { (t - s0) / (s1 - s0) } else { 0.0 };
                p[i - 1].lerp(p[i], w.clamp(0.0, 1.0))
            }
            CurveFn::Bezier(p) => {
                let mut q = p.clone();
                for k in (1..q.len()).rev() {
                    for j in 0..k {
                        q[j] = q[j].lerp(q[j + 1], t);
                    }
                }
                q[0]
            }
            CurveFn::Helix {
                center,
                u,
                v,
                w,
                radius,
                pitch,
                turns,
                phase,
            } => {
                let th = phase.to_radians() + std::f64::consts::TAU * turns * t;
                *center + *radius * (th.cos() * *u + th.sin() * *v) + (t * turns * pitch) * *w
            }
        }
    }
}

fn finite(path: &str, v: f64) -> Result<f64, FrepError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(spec_err(
            path,
            format!("must be a finite number, got {}", volmorph_io::Num(v)),
        ))
    }
}

fn positive(path: &str, v: f64) -> Result<f64, FrepError> {
    if v > 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(spec_err(
            path,
            format!("must be positive and finite, got {}", volmorph_io::Num(v)),
        ))
    }
}

fn non_negative(path: &str, v: f64) -> Result<f64, FrepError> {
    if v >= 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(spec_err(
            path,
            format!("must be ≥ 0 and finite, got {}", volmorph_io::Num(v)),
        ))
    }
}

fn point(path: &str, p: [f64; 3]) -> Result<DVec3, FrepError> {
    let v = DVec3::from_array(p);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(spec_err(path, format!("point {p:?} is not finite")))
    }
}

fn points(path: &str, list: &[[f64; 3]], min: usize) -> Result<Vec<DVec3>, FrepError> {
    if list.len() < min || list.len() > MAX_POINTS {
        return Err(spec_err(
            path,
            format!("needs {min} to {MAX_POINTS} points, got {}", list.len()),
        ));
    }
    list.iter()
        .enumerate()
        .map(|(i, p)| point(&format!("{path}[{i}]"), *p))
        .collect()
}

fn schedule(path: &str, s: &str) -> Result<Schedule, FrepError> {
    Schedule::parse(s).map_err(|e| spec_err(path, e))
}

/// A library error while building the mapping at `path`.
fn at(path: &str) -> impl Fn(FrepError) -> FrepError + '_ {
    move |e| match e {
        e @ FrepError::Spec { .. } => e,
        e => spec_err(path, e),
    }
}

fn load_model(
    m: &ModelRef,
    path: &str,
    context: &SpecContext,
    progress: &dyn volmorph_io::Progress,
) -> Result<Mapped, FrepError> {
    let mut params = std::collections::HashMap::new();
    for (k, v) in &m.params {
        let (i, v) = CompileOptions::parse_param(&format!("{k}={v}"))
            .map_err(|e| spec_err(format!("{path}.params.{k}"), e))?;
        params.insert(i, v);
    }
    let allow = context.allow_external_data
        || volmorph_volume_io::ReadOptions::default().allow_external_data;
    let shape = match (&m.file, &m.source) {
        (Some(file), None) => {
            let full = volmorph_io::resolve_in_folder(&context.dir, file, allow)
                .map_err(|e| spec_err(format!("{path}.file"), e))?;
            let options = CompileOptions {
                params,
                allow_external_data: context.allow_external_data,
                ..CompileOptions::default()
            };
            compile_file(&full, &options).map_err(|e| spec_err(format!("{path}.file"), e))?
        }
        (None, Some(source)) => {
            let options = CompileOptions {
                params,
                data_dir: Some(context.dir.clone()),
                allow_external_data: context.allow_external_data,
                ..CompileOptions::default()
            };
            compile_source(source, &options).map_err(|e| spec_err(format!("{path}.source"), e))?
        }
        _ => {
            return Err(spec_err(
                path,
                "a model is {\"file\": \"name.hf\"} or {\"source\": \"…\"} (exactly one)",
            ));
        }
    };
    let steps = build_steps(
        &m.mappings,
        &format!("{path}.mappings"),
        &shape,
        context,
        progress,
    )?;
    Ok(Mapped { base: shape, steps })
}

fn build_steps(
    list: &[Mapping],
    path: &str,
    model: &Shape,
    context: &SpecContext,
    progress: &dyn volmorph_io::Progress,
) -> Result<Vec<(String, Step)>, FrepError> {
    let mut steps: Vec<(String, Step)> = Vec::with_capacity(list.len());
    for (i, m) in list.iter().enumerate() {
        let p = format!("{path}[{i}]");
        let step = build_step(m, &p, model, &steps, context, progress)?;
        steps.push((p, step));
    }
    Ok(steps)
}

fn build_step(
    m: &Mapping,
    p: &str,
    model: &Shape,
    before: &[(String, Step)],
    context: &SpecContext,
    progress: &dyn volmorph_io::Progress,
) -> Result<Step, FrepError> {
    let f = |name: &str| format!("{p}.{name}");
    Ok(match m {
        Mapping::Offset(o) => Step::Offset(finite(&f("d"), o.d)?),
        Mapping::ControlPoints(c) => {
            if c.points.is_empty() || c.points.len() > MAX_POINTS {
                return Err(spec_err(
                    f("points"),
                    format!("needs 1 to {MAX_POINTS} points, got {}", c.points.len()),
                ));
            }
            let mut out = Vec::with_capacity(c.points.len());
            for (j, cp) in c.points.iter().enumerate() {
                let q = format!("{p}.points[{j}]");
                let at = point(&format!("{q}.at"), cp.at)?;
                let built = match (cp.radius, cp.axes) {
                    (Some(r), None) => {
                        ControlPoint::sphere(at, positive(&format!("{q}.radius"), r)?)
                    }
                    (None, Some(axes)) => ControlPoint::ellipsoid(at, axes.map(DVec3::from_array)),
                    _ => {
                        return Err(spec_err(
                            q,
                            "give either \"radius\" or \"axes\" (three semi-axis vectors)",
                        ));
                    }
                };
                out.push(built.map_err(|e| spec_err(q.clone(), e))?);
            }
            Step::ControlPoints(out)
        }
        Mapping::SplinePoints(s) => {
            let points = points(&f("points"), &s.points, 4)?;
            let values = match &s.values {
                None => vec![0.0; points.len()],
                Some(v) if v.len() == points.len() => {
                    for (j, x) in v.iter().enumerate() {
                        finite(&format!("{p}.values[{j}]"), *x)?;
                    }
                    v.clone()
                }
                Some(v) => {
                    return Err(spec_err(
                        f("values"),
                        format!("{} values for {} points", v.len(), points.len()),
                    ));
                }
            };
            Step::SplinePoints {
                points,
                values,
                smoothing: non_negative(&f("smoothing"), s.smoothing)?,
            }
        }
        Mapping::Convolution(c) => {
            if c.intervals < 2 || c.intervals % 2 != 0 || c.intervals > 1 << 16 {
                return Err(spec_err(
                    f("intervals"),
                    format!("must be even, 2 to 65536, got {}", c.intervals),
                ));
            }
            Step::Convolution {
                curve: curve(&c.curve, &f("curve"))?,
                a: positive(&f("a"), c.a)?,
                intervals: c.intervals,
            }
        }
        Mapping::Metamorphosis(x) => {
            let target = Box::new(load_model(&x.target, &f("target"), context, progress)?);
            let weights = match (&x.schedule, x.weights) {
                (None, None) => Weights::Schedule(Schedule::Linear),
                (Some(s), None) => Weights::Schedule(schedule(&f("schedule"), s)?),
                (None, Some([h1, h2])) => Weights::Fixed(
                    finite(&format!("{p}.weights[0]"), h1)?,
                    finite(&format!("{p}.weights[1]"), h2)?,
                ),
                _ => {
                    return Err(spec_err(
                        p,
                        "give either \"schedule\" or \"weights\", not both",
                    ));
                }
            };
            Step::Metamorphosis { target, weights }
        }
        Mapping::Handles(h) => {
            let sources = points(&f("sources"), &h.sources, 4)?;
            let targets = points(&f("targets"), &h.targets, 4)?;
            if sources.len() != targets.len() {
                return Err(spec_err(
                    f("targets"),
                    format!("{} targets for {} sources", targets.len(), sources.len()),
                ));
            }
            let smoothing = non_negative(&f("smoothing"), h.smoothing)?;
            Step::Handles {
                spline: mapping::handle_spline(&sources, &targets, smoothing)
                    .map_err(at(&f("targets")))?,
                schedule: h
                    .schedule
                    .as_deref()
                    .map(|s| schedule(&f("schedule"), s))
                    .transpose()?,
            }
        }
        Mapping::Affine(a) => {
            let rows = a.matrix.map(DVec3::from_array);
            let m = DMat3::from_cols(rows[0], rows[1], rows[2]).transpose();
            let o = point(&f("offset"), a.offset)?;
            // Check invertibility now, where the path is known.
            mapping::affine(model, m, o).map_err(at(&f("matrix")))?;
            Step::Affine(m, o)
        }
        Mapping::OffsetNormal(o) => match (o.d, &o.distance) {
            (Some(d), None) => Step::OffsetNormal(finite(&f("d"), d)?),
            (None, Some(m)) => Step::OffsetNormalBy {
                distance: Box::new(load_model(m, &f("distance"), context, progress)?),
                scale: finite(&f("scale"), o.scale)?,
            },
            _ => {
                return Err(spec_err(
                    p,
                    "give either \"d\" (a number) or \"distance\" (a model), not both",
                ));
            }
        },
        Mapping::Shell(s) => Step::Shell(finite(&f("a"), s.a)?, finite(&f("b"), s.b)?),
        Mapping::Maze(s) => Step::Maze(
            finite(&f("a"), s.a)?,
            finite(&f("b"), s.b)?,
            finite(&f("c"), s.c)?,
        ),
        Mapping::Combined(c) => {
            let target = Box::new(load_model(&c.target, &f("target"), context, progress)?);
            let sources = points(&f("sources"), &c.sources, 4)?;
            let targets = points(&f("targets"), &c.targets, 4)?;
            if sources.len() != targets.len() {
                return Err(spec_err(
                    f("targets"),
                    format!("{} targets for {} sources", targets.len(), sources.len()),
                ));
            }
            let smoothing = non_negative(&f("smoothing"), c.smoothing)?;
            Step::Combined {
                target,
                spline: mapping::handle_spline(&sources, &targets, smoothing)
                    .map_err(at(&f("targets")))?,
                h1: schedule(&f("h1"), &c.h1)?,
                h2: schedule(&f("h2"), &c.h2)?,
            }
        }
        Mapping::CollisionFreeMotion(c) => {
            if before.iter().any(|(_, s)| s.time_dependent()) {
                return Err(spec_err(
                    p,
                    "collision-free-motion must come before every mapping that depends on time \
                     (its search needs the shape that moves)",
                ));
            }
            // The moving shape: the model through the mappings before this one.
            let initial = apply_steps(model, before, 1.0)?;
            let target = load_model(&c.target, &f("target"), context, progress)?;
            let obstacles = load_model(&c.obstacles, &f("obstacles"), context, progress)?;
            if target.time_dependent() || obstacles.time_dependent() {
                return Err(spec_err(
                    p,
                    "the target and the obstacles of collision-free-motion must not depend on time",
                ));
            }
            let lo = point(&format!("{p}.local_bounds[0]"), c.local_bounds[0])?;
            let hi = point(&format!("{p}.local_bounds[1]"), c.local_bounds[1])?;
            if (hi - lo).min_element() <= 0.0 {
                return Err(spec_err(f("local_bounds"), "needs min < max on every axis"));
            }
            let s = &c.search;
            let m = match s.max_displacement {
                Some(m) => positive(&f("search.max_displacement"), m)?,
                None => 0.25 * (hi - lo).min_element(),
            };
            let setup = MotionSetup {
                initial,
                target: target.shape_at(1.0)?,
                obstacles: obstacles.shape_at(1.0)?,
                path: points(&f("path"), &c.path, 1)?,
                control_points: points(&f("control_points"), &c.control_points, 4)?,
                local_bounds: (lo, hi),
                h1: schedule(&f("h1"), &c.h1)?,
                options: AvoidanceOptions {
                    keyframes: s.keyframes,
                    population: s.population,
                    generations: s.generations,
                    max_displacement: m,
                    stiffness: s.stiffness,
                    samples: s.samples,
                    smoothing: non_negative(&f("smoothing"), c.smoothing)?,
                    seed: s.seed,
                },
            };
            Step::Motion(Box::new(setup.solve_with(progress).map_err(
                |e| match e {
                    e @ FrepError::Cancelled(_) => e,
                    e => at(p)(e),
                },
            )?))
        }
        Mapping::Sequence(s) => {
            let mut inner: Vec<(String, Step)> = Vec::with_capacity(s.mappings.len());
            for (j, m) in s.mappings.iter().enumerate() {
                let q = format!("{p}.mappings[{j}]");
                let mut all: Vec<(String, Step)> = before.to_vec();
                all.extend(inner.iter().cloned());
                let step = build_step(m, &q, model, &all, context, progress)?;
                inner.push((q, step));
            }
            Step::Sequence(inner)
        }
    })
}

fn curve(c: &Curve, path: &str) -> Result<CurveFn, FrepError> {
    Ok(match c {
        Curve::Polyline(l) => {
            let pts = points(&format!("{path}.points"), &l.points, 2)?;
            let mut s = vec![0.0];
            for w in pts.windows(2) {
                let last = *s.last().unwrap_or(&0.0);
                s.push(last + (w[1] - w[0]).length());
            }
            let total = *s.last().unwrap_or(&0.0);
            if total <= 0.0 {
                return Err(spec_err(
                    format!("{path}.points"),
                    "the polyline has no length",
                ));
            }
            s.iter_mut().for_each(|v| *v /= total);
            CurveFn::Polyline(pts, s)
        }
        Curve::Bezier(l) => {
            if l.points.len() > 64 {
                return Err(spec_err(
                    format!("{path}.points"),
                    format!(
                        "a Bézier curve takes 2 to 64 points, got {}",
                        l.points.len()
                    ),
                ));
            }
            CurveFn::Bezier(points(&format!("{path}.points"), &l.points, 2)?)
        }
        Curve::Helix(h) => {
            let w = point(&format!("{path}.axis"), h.axis)?;
            let w = w
                .try_normalize()
                .ok_or_else(|| spec_err(format!("{path}.axis"), "the axis must not be zero"))?;
            let u = w.any_orthonormal_vector();
            CurveFn::Helix {
                center: point(&format!("{path}.center"), h.center)?,
                u,
                v: w.cross(u),
                w,
                radius: non_negative(&format!("{path}.radius"), h.radius)?,
                pitch: finite(&format!("{path}.pitch"), h.pitch)?,
                turns: finite(&format!("{path}.turns"), h.turns)?,
                phase: finite(&format!("{path}.phase"), h.phase)?,
            }
        }
    })
}

impl Step {
    fn time_dependent(&self) -> bool {
        match self {
            Step::Metamorphosis { target, weights } => {
                matches!(weights, Weights::Schedule(_)) || target.time_dependent()
            }
            Step::Handles { schedule, .. } => schedule.is_some(),
            Step::OffsetNormalBy { distance, .. } => distance.time_dependent(),
            Step::Combined { .. } | Step::Motion(_) => true,
            Step::Sequence(s) => s.iter().any(|(_, s)| s.time_dependent()),
            _ => false,
        }
    }

    fn apply(&self, f: &Shape, t: f64) -> Result<Shape, FrepError> {
        Ok(match self {
            Step::Offset(d) => mapping::offset(f, *d),
            Step::ControlPoints(c) => mapping::control_points(f, c),
            Step::SplinePoints {
                points,
                values,
                smoothing,
            } => mapping::spline_points(f, points, values, *smoothing)?,
            Step::Convolution {
                curve,
                a,
                intervals,
            } => mapping::convolution_deformation(f, &|s| curve.at(s), *a, *intervals)?,
            Step::Metamorphosis { target, weights } => {
                let g = target.shape_at(t)?;
                match *weights {
                    Weights::Schedule(s) => mapping::morph(f, &g, t, s),
                    Weights::Fixed(h1, h2) => mapping::metamorphosis(f, &g, h1, h2),
                }
            }
            Step::Handles { spline, schedule } => {
                let s = schedule.map_or(1.0, |h| h.at(t));
                mapping::displaced_shape(f, spline.spline(), s)
            }
            Step::Affine(m, o) => mapping::affine(f, *m, *o)?,
            Step::OffsetNormal(d) => mapping::offset_along_gradient(f, *d),
            Step::OffsetNormalBy { distance, scale } => {
                let d = distance.shape_at(t)?.map(|b, r, _| b.mul_c(r, *scale));
                mapping::offset_along_gradient_by(f, &d)
            }
            Step::Shell(a, b) => mapping::thin_shell(f, *a, *b),
            Step::Maze(a, b, c) => mapping::maze(f, *a, *b, *c),
            Step::Combined {
                target,
                spline,
                h1,
                h2,
            } => {
                let g = target.shape_at(t)?;
                mapping::combined(f, &g, spline.spline(), h1.at(t), h2.at(t))
            }
            Step::Motion(m) => m.shape_at(t)?,
            Step::Sequence(s) => apply_steps(f, s, t)?,
        })
    }
}

fn apply_steps(f: &Shape, steps: &[(String, Step)], t: f64) -> Result<Shape, FrepError> {
    let mut s = f.clone();
    for (path, step) in steps {
        s = step.apply(&s, t).map_err(at(path))?;
    }
    Ok(s)
}

impl Mapped {
    /// Whether the result changes with the time `t` (some mapping has a schedule).
    #[must_use]
    pub fn time_dependent(&self) -> bool {
        self.steps.iter().any(|(_, s)| s.time_dependent())
    }

    /// The model with every mapping applied at time `t` (clamped to `[0, 1]`; ignored by
    /// mappings without a schedule).
    ///
    /// # Errors
    /// [`FrepError::Spec`] naming the mapping whose construction fails at `t` (rare: the
    /// values were checked when the specification was applied).
    pub fn shape_at(&self, t: f64) -> Result<Shape, FrepError> {
        let t = if t.is_nan() { 1.0 } else { t.clamp(0.0, 1.0) };
        apply_steps(&self.base, &self.steps, t)
    }

    /// The collision-avoiding motions solved for `collision-free-motion` mappings, in order
    /// (for reports: their interpenetration before and after).
    #[must_use]
    pub fn motions(&self) -> Vec<&MotionSolution> {
        fn walk<'a>(steps: &'a [(String, Step)], out: &mut Vec<&'a MotionSolution>) {
            for (_, s) in steps {
                match s {
                    Step::Motion(m) => out.push(m),
                    Step::Sequence(inner) => walk(inner, out),
                    _ => {}
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.steps, &mut out);
        out
    }
}
