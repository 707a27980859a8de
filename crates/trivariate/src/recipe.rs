//! Modeling recipes: aggregates built step by step with the operators of Martin & Cohen §3,
//! from a versioned JSON document (what `volmorph nurbs model` reads).
//!
//! A recipe is a list of named **steps**. Each step makes one aggregate — a curve, surface or
//! volume with named attributes — from numbers or from earlier steps, and the step named by
//! `result` is the model. This is §3's modeling hierarchy written down: a geometry curve, an
//! attribute combined with it into an aggregate curve, the aggregate swept into a surface and
//! the surface into a volume, every attribute carried along (ruled with itself by a
//! one-operand operator, ruled across by [`rule`](crate::rule())), and attributes edited
//! explicitly at any level.
//!
//! # Format (version 1)
//!
//! ```json
//! {
//!   "format": "volmorph-nurbs-recipe",
//!   "version": 1,
//!   "steps": [
//!     { "curve":   { "name": "profile", "degree": 1, "points": [[0, 0, 0], [1, 0, 0]] } },
//!     { "attach":  { "name": "graded", "to": "profile", "attribute": "eta",
//!                    "spline": { "degree": 2, "values": [1.5, 1.5, 1.125] } } },
//!     { "revolve": { "name": "disk", "of": "graded", "axis_point": [0, 0, 0],
//!                    "axis_direction": [0, 0, 1], "angle_degrees": 360 } },
//!     { "extrude": { "name": "lens", "of": "disk", "direction": [0, 0, 1] } }
//!   ],
//!   "result": "lens"
//! }
//! ```
//!
//! Each step is an object with exactly one key, the operator:
//!
//! | operator | fields | makes |
//! | --- | --- | --- |
//! | `curve` | `degree`, `points` (`[x, y, z]` control points), optional `knots` (full knot vector on `[0, 1]`; default clamped uniform), optional `weights` (> 0; a rational curve) | a geometry curve without attributes |
//! | `model` | `model`: an aggregate in the trivariate file format ([`crate::format`]) | that aggregate (curve, surface or volume) |
//! | `attach` | `to` (a step), `attribute` (a new name), `spline` (an attribute spline, below) | a copy of `to` carrying the attribute (§3: an attribute combined with a geometric object) |
//! | `set_attribute` | `of` (a step), `attribute` (an existing name), `spline` | a copy of `of` with that attribute replaced (explicit attribute editing at any level) |
//! | `remove_attribute` | `of`, `attribute` | a copy of `of` without it |
//! | `extrude` | `of`, `direction` `[x, y, z]` | one level up: `of` translated along `direction` over the new parameter ([`crate::extrude`]) |
//! | `revolve` | `of`, `axis_point`, `axis_direction`, `angle_degrees` (`0 < |a| ≤ 360`, sign by the right-hand rule) | one level up: `of` swept about the axis by exact rational arcs ([`crate::revolve`]) |
//! | `rule` | `from`, `to` (two steps of the same kind) | one level up: the ruled object from `from` (new parameter 0) to `to` (1), attributes ruled across ([`crate::rule`]) |
//!
//! Every step also has a `name`, unique in the recipe; operands name **earlier** steps (a
//! recipe is built in order, so it cannot loop). An **attribute spline** (`spline`) has the parametric
//! dimension of the object it goes on (1 for a curve, …), on the unit domain:
//!
//! * `degree` (every axis) or `degrees` (one per axis);
//! * `dim`: values per control point (default 1);
//! * the control net size per axis from `counts`, or from `knots` (one full knot vector per
//!   axis, on `[0, 1]`), or — for curves — from the number of values; knots default to clamped
//!   uniform;
//! * exactly one of `values` — the control values themselves (§3: "the data points may simply
//!   be used as control points"), `dim` per control point, axis 0 fastest, optionally with
//!   `weights` — or `data` — samples at the Greville abscissae of the knots, interpolated
//!   (§3's fitting, [`crate::fit::interpolate`]).
//!
//! Unknown fields are errors. Every error names the recipe (file) and the JSON path of the
//! field at fault, e.g. `lens.json: steps[2].revolve.angle_degrees: revolution angle 0 must
//! be non-zero with |angle| <= 2π`.

use std::path::Path;

use serde::{Deserialize, Serialize};
use volmorph_spline::{KnotVector, TensorBSpline};

use crate::aggregate::{Aggregate, AggregateCurve, kind_name};
use crate::error::ctx;
use crate::format::{AnyAggregate, from_json_str};
use crate::{TrivariateError, extrude, revolve, rule};

/// Value of a recipe's `format` field.
pub const RECIPE_FORMAT: &str = "volmorph-nurbs-recipe";
/// The recipe version this crate reads and writes.
pub const RECIPE_VERSION: u32 = 1;

/// Most steps a recipe may have (a guard against hostile documents: each step may copy a
/// whole aggregate).
pub const MAX_STEPS: usize = 10_000;

/// A modeling recipe (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Recipe {
    /// Always [`RECIPE_FORMAT`].
    pub format: String,
    /// Always [`RECIPE_VERSION`].
    pub version: u32,
    /// The steps, built in order.
    pub steps: Vec<Step>,
    /// Name of the step that is the model.
    pub result: String,
}

/// One step of a [`Recipe`]: the operator and its fields.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Step {
    /// A geometry curve from control points.
    Curve(CurveStep),
    /// An aggregate given in the trivariate file format.
    Model(ModelStep),
    /// An attribute added to an earlier step's aggregate.
    Attach(AttachStep),
    /// An attribute of an earlier step's aggregate replaced.
    SetAttribute(SetAttributeStep),
    /// An attribute of an earlier step's aggregate removed.
    RemoveAttribute(RemoveAttributeStep),
    /// Extrusion of an earlier step along a vector.
    Extrude(ExtrudeStep),
    /// Revolution of an earlier step about an axis.
    Revolve(RevolveStep),
    /// The ruled object between two earlier steps.
    Rule(RuleStep),
}

/// Fields of a `curve` step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CurveStep {
    /// The step's name.
    pub name: String,
    /// Polynomial degree (≥ 1).
    pub degree: usize,
    /// Control points `[x, y, z]`.
    pub points: Vec<[f64; 3]>,
    /// Full knot vector on `[0, 1]` (default: clamped uniform).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub knots: Option<Vec<f64>>,
    /// One weight per control point (> 0), for a rational curve.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<Vec<f64>>,
}

/// Fields of a `model` step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelStep {
    /// The step's name.
    pub name: String,
    /// An aggregate document of the trivariate file format.
    pub model: serde_json::Value,
}

/// An attribute spline of an `attach` or `set_attribute` step (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttributeSpline {
    /// Degree of every axis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degree: Option<usize>,
    /// Degree per axis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degrees: Option<Vec<usize>>,
    /// Values per control point (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dim: Option<usize>,
    /// Control points per axis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub counts: Option<Vec<usize>>,
    /// Full knot vector per axis, on `[0, 1]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub knots: Option<Vec<Vec<f64>>>,
    /// Control values, `dim` per control point, axis 0 fastest.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub values: Option<Vec<f64>>,
    /// Samples at the Greville abscissae (interpolated), same layout as `values`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<Vec<f64>>,
    /// One weight per control point (> 0), with `values` only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<Vec<f64>>,
}

/// Fields of an `attach` step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttachStep {
    /// The step's name.
    pub name: String,
    /// The step whose aggregate gets the attribute.
    pub to: String,
    /// The new attribute's name.
    pub attribute: String,
    /// The attribute's spline.
    pub spline: AttributeSpline,
}

/// Fields of a `set_attribute` step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetAttributeStep {
    /// The step's name.
    pub name: String,
    /// The step whose attribute is replaced.
    pub of: String,
    /// The attribute's name.
    pub attribute: String,
    /// The new spline.
    pub spline: AttributeSpline,
}

/// Fields of a `remove_attribute` step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RemoveAttributeStep {
    /// The step's name.
    pub name: String,
    /// The step whose attribute is removed.
    pub of: String,
    /// The attribute's name.
    pub attribute: String,
}

/// Fields of an `extrude` step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExtrudeStep {
    /// The step's name.
    pub name: String,
    /// The step extruded.
    pub of: String,
    /// Extrusion vector (physical units).
    pub direction: [f64; 3],
}

/// Fields of a `revolve` step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RevolveStep {
    /// The step's name.
    pub name: String,
    /// The step revolved.
    pub of: String,
    /// A point of the axis.
    pub axis_point: [f64; 3],
    /// The axis direction (orientation sets the sign of the angle).
    pub axis_direction: [f64; 3],
    /// Angle in degrees, `0 < |a| ≤ 360`.
    pub angle_degrees: f64,
}

/// Fields of a `rule` step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RuleStep {
    /// The step's name.
    pub name: String,
    /// The object at the new parameter 0.
    pub from: String,
    /// The object at the new parameter 1.
    pub to: String,
}

impl Step {
    /// The step's name.
    #[must_use]
    pub fn name(&self) -> &str {
        match self {
            Self::Curve(s) => &s.name,
            Self::Model(s) => &s.name,
            Self::Attach(s) => &s.name,
            Self::SetAttribute(s) => &s.name,
            Self::RemoveAttribute(s) => &s.name,
            Self::Extrude(s) => &s.name,
            Self::Revolve(s) => &s.name,
            Self::Rule(s) => &s.name,
        }
    }

    /// The operator's key in the JSON form.
    #[must_use]
    pub fn operator(&self) -> &'static str {
        match self {
            Self::Curve(_) => "curve",
            Self::Model(_) => "model",
            Self::Attach(_) => "attach",
            Self::SetAttribute(_) => "set_attribute",
            Self::RemoveAttribute(_) => "remove_attribute",
            Self::Extrude(_) => "extrude",
            Self::Revolve(_) => "revolve",
            Self::Rule(_) => "rule",
        }
    }
}

/// An error at `field` (a JSON path) of recipe `source`.
fn err(source: &str, field: &str, message: impl Into<String>) -> TrivariateError {
    TrivariateError::Recipe {
        source_name: source.to_owned(),
        json_path: field.to_owned(),
        message: message.into(),
    }
}

/// The message of an error of a lower layer, without repeating a recipe wrapper.
fn message(e: TrivariateError) -> String {
    e.to_string()
}

impl Recipe {
    /// Parse a recipe document; `source` names it in errors (a file name).
    ///
    /// # Errors
    /// [`TrivariateError::Recipe`] with the JSON path of the offending field for malformed
    /// JSON, unknown or missing fields and wrong types, a wrong `format` or `version`, or more
    /// than [`MAX_STEPS`] steps.
    pub fn from_json_str(text: &str, source: &str) -> Result<Self, TrivariateError> {
        let de = &mut serde_json::Deserializer::from_str(text);
        let recipe: Recipe = serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.into_inner();
            err(
                source,
                if path == "." { "$" } else { &path },
                inner.to_string(),
            )
        })?;
        if recipe.format != RECIPE_FORMAT {
            return Err(err(
                source,
                "format",
                format!("{:?} is not {RECIPE_FORMAT:?}", recipe.format),
            ));
        }
        if recipe.version != RECIPE_VERSION {
            return Err(err(
                source,
                "version",
                format!(
                    "version {} is not supported (expected {RECIPE_VERSION})",
                    recipe.version
                ),
            ));
        }
        if recipe.steps.len() > MAX_STEPS {
            return Err(err(
                source,
                "steps",
                format!(
                    "{} steps exceed the limit of {MAX_STEPS}",
                    recipe.steps.len()
                ),
            ));
        }
        Ok(recipe)
    }

    /// The recipe as pretty-printed JSON (numbers in shortest round-trip form).
    ///
    /// # Errors
    /// [`TrivariateError::Json`] if serialisation fails (it does not for finite numbers).
    pub fn to_json_string(&self) -> Result<String, TrivariateError> {
        serde_json::to_string_pretty(self).map_err(|e| TrivariateError::Json(e.to_string()))
    }

    /// Build every step in order and return the aggregate of the step named `result`;
    /// `source` names the recipe in errors.
    ///
    /// # Errors
    /// [`TrivariateError::Recipe`] naming the step's JSON path (`steps[i].operator.field`) for
    /// a duplicate or empty name, an operand that is not an earlier step, an operand of the
    /// wrong kind (a volume cannot be lifted; `rule` needs two objects of one kind), and every
    /// error of the operators, the spline constructors and the aggregate rules (degenerate
    /// geometry, domains, attribute names), with their messages.
    pub fn build(&self, source: &str) -> Result<AnyAggregate, TrivariateError> {
        let mut built: Vec<(String, AnyAggregate)> = Vec::with_capacity(self.steps.len());
        for (i, step) in self.steps.iter().enumerate() {
            let at = |field: &str| {
                if field.is_empty() {
                    format!("steps[{i}].{}", step.operator())
                } else {
                    format!("steps[{i}].{}.{field}", step.operator())
                }
            };
            let name = step.name();
            if name.is_empty() {
                return Err(err(source, &at("name"), "a step needs a non-empty name"));
            }
            if built.iter().any(|(n, _)| n == name) {
                return Err(err(
                    source,
                    &at("name"),
                    format!("step name {name:?} is used twice"),
                ));
            }
            let get = |field: &str, operand: &str| -> Result<&AnyAggregate, TrivariateError> {
                built
                    .iter()
                    .find(|(n, _)| n == operand)
                    .map(|(_, a)| a)
                    .ok_or_else(|| {
                        err(
                            source,
                            &at(field),
                            format!("{operand:?} is not the name of an earlier step"),
                        )
                    })
            };
            let object = build_step(step, &get, &|f, e| err(source, &at(f), message(e)))?;
            built.push((name.to_owned(), object));
        }
        built
            .into_iter()
            .rev()
            .find(|(n, _)| *n == self.result)
            .map(|(_, a)| a)
            .ok_or_else(|| {
                err(
                    source,
                    "result",
                    format!("{:?} is not the name of a step", self.result),
                )
            })
    }
}

type Getter<'a> = dyn Fn(&str, &str) -> Result<&'a AnyAggregate, TrivariateError> + 'a;
type Wrap<'a> = dyn Fn(&str, TrivariateError) -> TrivariateError + 'a;

fn build_step<'a>(
    step: &Step,
    get: &Getter<'a>,
    wrap: &Wrap<'_>,
) -> Result<AnyAggregate, TrivariateError> {
    Ok(match step {
        Step::Curve(c) => AnyAggregate::Curve(curve(c).map_err(|(f, e)| wrap(f, e))?),
        Step::Model(m) => {
            let text = serde_json::to_string(&m.model)
                .map_err(|e| wrap("model", TrivariateError::Json(e.to_string())))?;
            from_json_str(&text).map_err(|e| wrap("model", e))?
        }
        Step::Attach(s) => edit(get("to", &s.to)?, wrap, |a, wrap| {
            let sw = |f: &str, e| wrap(&format!("spline.{f}"), e);
            let spline = attribute_spline(&s.spline, a.dims(), &sw)?;
            a.add(&s.attribute, spline)
                .map_err(|e| wrap("attribute", e))
        })?,
        Step::SetAttribute(s) => edit(get("of", &s.of)?, wrap, |a, wrap| {
            if !a.has(&s.attribute) {
                return Err(wrap(
                    "attribute",
                    TrivariateError::UnknownAttribute(s.attribute.clone()),
                ));
            }
            let sw = |f: &str, e| wrap(&format!("spline.{f}"), e);
            let spline = attribute_spline(&s.spline, a.dims(), &sw)?;
            a.set(&s.attribute, spline)
                .map_err(|e| wrap("attribute", e))
        })?,
        Step::RemoveAttribute(s) => edit(get("of", &s.of)?, wrap, |a, wrap| {
            a.remove(&s.attribute).map_err(|e| wrap("attribute", e))
        })?,
        Step::Extrude(s) => {
            let w = |e| wrap("direction", e);
            match get("of", &s.of)? {
                AnyAggregate::Curve(c) => {
                    AnyAggregate::Surface(extrude(c, s.direction).map_err(w)?)
                }
                AnyAggregate::Surface(c) => {
                    AnyAggregate::Volume(extrude(c, s.direction).map_err(w)?)
                }
                AnyAggregate::Volume(_) => return Err(cannot_lift(wrap)),
            }
        }
        Step::Revolve(s) => {
            if !(s.angle_degrees.is_finite()
                && s.angle_degrees != 0.0
                && s.angle_degrees.abs() <= 360.0)
            {
                return Err(wrap(
                    "angle_degrees",
                    TrivariateError::InvalidArgument(format!(
                        "revolution angle {} must be non-zero with |angle| <= 360",
                        s.angle_degrees
                    )),
                ));
            }
            // A fraction of a full turn times 2π: 360 gives 2π exactly.
            let angle = s.angle_degrees / 360.0 * std::f64::consts::TAU;
            let w = |e: TrivariateError| {
                let field = if e.to_string().contains("axis point") {
                    "axis_point"
                } else {
                    "axis_direction"
                };
                wrap(field, e)
            };
            match get("of", &s.of)? {
                AnyAggregate::Curve(c) => AnyAggregate::Surface(
                    revolve(c, s.axis_point, s.axis_direction, angle).map_err(w)?,
                ),
                AnyAggregate::Surface(c) => AnyAggregate::Volume(
                    revolve(c, s.axis_point, s.axis_direction, angle).map_err(w)?,
                ),
                AnyAggregate::Volume(_) => return Err(cannot_lift(wrap)),
            }
        }
        Step::Rule(s) => {
            let w = |e| wrap("to", e);
            match (get("from", &s.from)?, get("to", &s.to)?) {
                (AnyAggregate::Curve(a), AnyAggregate::Curve(b)) => {
                    AnyAggregate::Surface(rule(a, b).map_err(w)?)
                }
                (AnyAggregate::Surface(a), AnyAggregate::Surface(b)) => {
                    AnyAggregate::Volume(rule(a, b).map_err(w)?)
                }
                (AnyAggregate::Volume(_), _) => return Err(cannot_lift(wrap)),
                (a, b) => {
                    return Err(wrap(
                        "to",
                        TrivariateError::Incompatible(format!(
                            "cannot rule a {} to a {}",
                            kind_of(a),
                            kind_of(b)
                        )),
                    ));
                }
            }
        }
    })
}

fn kind_of(a: &AnyAggregate) -> &'static str {
    match a {
        AnyAggregate::Curve(_) => kind_name(1),
        AnyAggregate::Surface(_) => kind_name(2),
        AnyAggregate::Volume(_) => kind_name(3),
    }
}

fn cannot_lift(wrap: &Wrap<'_>) -> TrivariateError {
    wrap(
        "of",
        TrivariateError::InvalidArgument(
            "a volume is the top of the hierarchy and cannot be lifted further".into(),
        ),
    )
}

fn curve(c: &CurveStep) -> Result<AggregateCurve, (&'static str, TrivariateError)> {
    let n = c.points.len();
    let kv = match &c.knots {
        Some(k) => KnotVector::new(c.degree, k.clone()).map_err(|e| ("knots", ctx("knots")(e)))?,
        None => KnotVector::clamped_uniform(c.degree, n, [0.0, 1.0])
            .map_err(|e| ("points", ctx("clamped uniform knots")(e)))?,
    };
    let pts: Vec<f64> = c.points.iter().flatten().copied().collect();
    let s = match &c.weights {
        None => TensorBSpline::new([kv], 3, pts),
        Some(w) => TensorBSpline::new_rational([kv], 3, pts, w.clone()),
    }
    .map_err(|e| {
        let f = if c.weights.is_some() {
            "weights"
        } else {
            "points"
        };
        (f, ctx("control net")(e))
    })?;
    Aggregate::new(s).map_err(|e| ("points", e))
}

/// An aggregate of any dimension, for the attribute-editing steps.
trait Editable {
    fn dims(&self) -> usize;
    fn has(&self, name: &str) -> bool;
    fn add(&mut self, name: &str, s: AnySpline) -> Result<(), TrivariateError>;
    fn set(&mut self, name: &str, s: AnySpline) -> Result<(), TrivariateError>;
    fn remove(&mut self, name: &str) -> Result<(), TrivariateError>;
}

/// A spline of 1, 2 or 3 parameters.
enum AnySpline {
    One(TensorBSpline<1>),
    Two(TensorBSpline<2>),
    Three(TensorBSpline<3>),
}

impl AnySpline {
    fn mismatch(n: usize) -> TrivariateError {
        TrivariateError::InvalidArgument(format!(
            "the attribute needs {n} parametric axes to go on a {}",
            kind_name(n)
        ))
    }
}

macro_rules! editable {
    ($n:literal, $variant:ident) => {
        impl Editable for Aggregate<$n> {
            fn dims(&self) -> usize {
                $n
            }
            fn has(&self, name: &str) -> bool {
                self.attribute(name).is_some()
            }
            fn add(&mut self, name: &str, s: AnySpline) -> Result<(), TrivariateError> {
                match s {
                    AnySpline::$variant(s) => self.add_attribute(name, s),
                    _ => Err(AnySpline::mismatch($n)),
                }
            }
            fn set(&mut self, name: &str, s: AnySpline) -> Result<(), TrivariateError> {
                match s {
                    AnySpline::$variant(s) => self.set_attribute(name, s),
                    _ => Err(AnySpline::mismatch($n)),
                }
            }
            fn remove(&mut self, name: &str) -> Result<(), TrivariateError> {
                self.remove_attribute(name).map(|_| ())
            }
        }
    };
}
editable!(1, One);
editable!(2, Two);
editable!(3, Three);

/// A copy of `a` changed by `f`.
fn edit(
    a: &AnyAggregate,
    wrap: &Wrap<'_>,
    f: impl Fn(&mut dyn Editable, &Wrap<'_>) -> Result<(), TrivariateError>,
) -> Result<AnyAggregate, TrivariateError> {
    let mut a = a.clone();
    match &mut a {
        AnyAggregate::Curve(c) => f(c, wrap)?,
        AnyAggregate::Surface(s) => f(s, wrap)?,
        AnyAggregate::Volume(v) => f(v, wrap)?,
    }
    Ok(a)
}

fn attribute_spline(
    spec: &AttributeSpline,
    n: usize,
    wrap: &Wrap<'_>,
) -> Result<AnySpline, TrivariateError> {
    match n {
        1 => attribute_spline_n::<1>(spec, wrap).map(AnySpline::One),
        2 => attribute_spline_n::<2>(spec, wrap).map(AnySpline::Two),
        _ => attribute_spline_n::<3>(spec, wrap).map(AnySpline::Three),
    }
}

fn attribute_spline_n<const N: usize>(
    spec: &AttributeSpline,
    wrap: &Wrap<'_>,
) -> Result<TensorBSpline<N>, TrivariateError> {
    let bad = |field: &str, m: String| wrap(field, TrivariateError::InvalidArgument(m));
    let degrees: [usize; N] = match (&spec.degree, &spec.degrees) {
        (Some(d), None) => [*d; N],
        (None, Some(ds)) => ds.as_slice().try_into().map_err(|_| {
            bad(
                "degrees",
                format!("{} degrees for an object of {N} parametric axes", ds.len()),
            )
        })?,
        _ => {
            return Err(bad(
                "degree",
                "give either `degree` or `degrees`".to_owned(),
            ));
        }
    };
    let dim = spec.dim.unwrap_or(1);
    if dim == 0 {
        return Err(bad(
            "dim",
            "an attribute needs at least 1 value per control point".into(),
        ));
    }
    let (numbers, field) = match (&spec.values, &spec.data) {
        (Some(v), None) => (v, "values"),
        (None, Some(d)) => (d, "data"),
        _ => {
            return Err(bad(
                "values",
                "give exactly one of `values` (control values) and `data` (samples at the \
                 Greville abscissae)"
                    .to_owned(),
            ));
        }
    };
    if spec.data.is_some() && spec.weights.is_some() {
        return Err(bad(
            "weights",
            "weights go with control `values`, not with interpolated `data`".into(),
        ));
    }
    let knots: [KnotVector; N] = match (&spec.knots, &spec.counts) {
        (Some(_), Some(_)) => {
            return Err(bad("counts", "give `knots` or `counts`, not both".into()));
        }
        (Some(ks), None) => {
            if ks.len() != N {
                return Err(bad(
                    "knots",
                    format!("{} knot vectors for {N} parametric axes", ks.len()),
                ));
            }
            let mut out = Vec::with_capacity(N);
            for (a, k) in ks.iter().enumerate() {
                out.push(
                    KnotVector::new(degrees[a], k.clone())
                        .map_err(|e| wrap(&format!("knots[{a}]"), ctx("knot vector")(e)))?,
                );
            }
            out.try_into()
                .map_err(|_| bad("knots", "wrong number of knot vectors".into()))?
        }
        (None, counts) => {
            let counts_field = |a: usize| {
                if counts.is_some() {
                    format!("counts[{a}]")
                } else {
                    field.to_owned()
                }
            };
            let counts: [usize; N] = match counts {
                Some(c) => c.as_slice().try_into().map_err(|_| {
                    bad(
                        "counts",
                        format!("{} counts for {N} parametric axes", c.len()),
                    )
                })?,
                None if N == 1 => {
                    if numbers.len() % dim != 0 {
                        return Err(bad(
                            field,
                            format!("{} numbers are not a multiple of dim {dim}", numbers.len()),
                        ));
                    }
                    [numbers.len() / dim; N]
                }
                None => {
                    return Err(bad(
                        "counts",
                        format!("a {} attribute needs `counts` or `knots`", kind_name(N)),
                    ));
                }
            };
            let mut out = Vec::with_capacity(N);
            for a in 0..N {
                out.push(
                    KnotVector::clamped_uniform(degrees[a], counts[a], [0.0, 1.0])
                        .map_err(|e| wrap(&counts_field(a), ctx("clamped uniform knots")(e)))?,
                );
            }
            out.try_into()
                .map_err(|_| bad("counts", "wrong number of knot vectors".into()))?
        }
    };
    if spec.data.is_some() {
        crate::fit::interpolate(knots, dim, numbers).map_err(|e| wrap(field, e))
    } else {
        match &spec.weights {
            None => TensorBSpline::new(knots, dim, numbers.clone()),
            Some(w) => TensorBSpline::new_rational(knots, dim, numbers.clone(), w.clone()),
        }
        .map_err(|e| wrap(field, ctx("control net")(e)))
    }
}

/// Read and parse a recipe file (optionally gzip-compressed).
///
/// # Errors
/// [`TrivariateError::Io`] if the file cannot be read; [`TrivariateError::Recipe`] naming the
/// file as in [`Recipe::from_json_str`].
pub fn load_recipe(path: &Path) -> Result<Recipe, TrivariateError> {
    let bytes = volmorph_io::read_maybe_gz(path)?;
    let name = path.display().to_string();
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| err(&name, "$", format!("not UTF-8 text ({e})")))?;
    Recipe::from_json_str(text, &name)
}

/// Read a recipe file and build its model ([`Recipe::build`]); errors name the file.
///
/// # Errors
/// As [`load_recipe`] and [`Recipe::build`].
pub fn build_recipe_file(path: &Path) -> Result<AnyAggregate, TrivariateError> {
    load_recipe(path)?.build(&path.display().to_string())
}
