//! Scene commands a page sends as JSON ([`Kind::Command`](crate::protocol::Kind::Command)):
//! `{"command": NAME, …fields}`, one form per [`Command`] a page issues (see `PROTOCOL.md`).
//! Handle methods use the scene's own serde names (`affine`, `tps`, …) and recipes the
//! project file's recipe form.
//!
//! `{"command": "sculpt", …}` is parsed apart ([`sculpt`]): its brush may be a mesh object,
//! which the editor turns into a tool when it applies the edit, and the strokes of one
//! gesture concatenate instead of replacing each other.

use std::collections::BTreeMap;

use glam::DVec3;
use serde_json::Value;
use volmorph_maps::{HandleMethod, HandleOptions};
use volmorph_scene::{Command, NewObject, ObjectId, Recipe};
use volmorph_sculpt::{BrushShape, Op};

use crate::views::{QueryError, f64_field, u64_field, vec3_field, vec3_value};

/// Most points of one `sculpt` message (a stroke segment; a page sends one per pointer move).
pub const MAX_SCULPT_POINTS: usize = 4096;

/// What a page sculpts with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Brush {
    /// A built-in brush ([`volmorph_sculpt::brush`]).
    Shape(BrushShape),
    /// A closed mesh object, centred on its bounding box and scaled to unit reach
    /// ([`volmorph_sculpt::unit_brush`]) when the edit is applied.
    Mesh(ObjectId),
}

/// A `sculpt` message: `{"command": "sculpt", "id": SCULPT_OBJECT, "brush": "sphere" | "box"
/// | {"mesh": ID}, "op": "add" | "subtract" | "intersect", "size": S, "points": [[x, y, z],
/// …]}`: the brush of reach `size` (physical units, see [`volmorph_sculpt::brush`]) swept
/// through the points in order (one point is a dab), unrotated.
#[derive(Debug, Clone, PartialEq)]
pub struct SculptRequest {
    /// The sculpt object.
    pub id: ObjectId,
    /// The brush.
    pub brush: Brush,
    /// Union, difference or intersection.
    pub op: Op,
    /// The brush's reach (physical units, finite, positive).
    pub size: f64,
    /// The stroke's points (physical, finite; 1 to [`MAX_SCULPT_POINTS`]).
    pub points: Vec<DVec3>,
}

impl SculptRequest {
    /// Whether `newer` continues this stroke (same object, brush, operation and size).
    #[must_use]
    pub fn continues_with(&self, newer: &Self) -> bool {
        self.id == newer.id
            && self.brush == newer.brush
            && self.op == newer.op
            && self.size == newer.size
    }

    /// Append `newer`'s points (a continuation, see [`SculptRequest::continues_with`]),
    /// leaving out a first point equal to this stroke's last (a page sends each segment
    /// with its start).
    pub fn extend(&mut self, newer: Self) {
        let skip = usize::from(self.points.last() == newer.points.first());
        self.points.extend(newer.points.into_iter().skip(skip));
    }
}

/// The sculpt request of a `sculpt` message, or `None` for any other command.
///
/// # Errors
/// A missing or malformed field, naming it: an unknown brush or operation, a size that is
/// not a positive number, no points, too many or a non-finite one.
pub fn sculpt(h: &Value) -> Result<Option<SculptRequest>, QueryError> {
    if h.get("command").and_then(Value::as_str) != Some("sculpt") {
        return Ok(None);
    }
    let brush = match h.get("brush") {
        Some(Value::String(b)) if b == "sphere" => Brush::Shape(BrushShape::Sphere),
        Some(Value::String(b)) if b == "box" => Brush::Shape(BrushShape::Box),
        Some(b @ Value::Object(_)) => Brush::Mesh(ObjectId(u64_field(b, "mesh")?)),
        _ => {
            return Err(QueryError(
                "field \"brush\" must be \"sphere\", \"box\" or {\"mesh\": ID}".into(),
            ));
        }
    };
    let op = match string(h, "op")?.as_str() {
        "add" => Op::Add,
        "subtract" => Op::Subtract,
        "intersect" => Op::Intersect,
        other => {
            return Err(QueryError(format!(
                "field \"op\": {other:?} is not add, subtract or intersect"
            )));
        }
    };
    let size = f64_field(h, "size")?;
    if size <= 0.0 {
        return Err(QueryError(format!(
            "field \"size\": {size} must be positive"
        )));
    }
    let list = h
        .get("points")
        .and_then(Value::as_array)
        .filter(|a| (1..=MAX_SCULPT_POINTS).contains(&a.len()))
        .ok_or_else(|| {
            QueryError(format!(
                "field \"points\" must be a list of 1 to {MAX_SCULPT_POINTS} points"
            ))
        })?;
    let points = list
        .iter()
        .enumerate()
        .map(|(i, p)| {
            vec3_value(p).ok_or_else(|| {
                QueryError(format!(
                    "field \"points\": point {i} must be three finite numbers"
                ))
            })
        })
        .collect::<Result<_, _>>()?;
    Ok(Some(SculptRequest {
        id: ObjectId(u64_field(h, "id")?),
        brush,
        op,
        size,
        points,
    }))
}

fn string(h: &Value, name: &str) -> Result<String, QueryError> {
    h.get(name)
        .and_then(Value::as_str)
        .map(str::to_owned)
        .ok_or_else(|| QueryError(format!("field {name:?} must be a string")))
}

fn params(h: &Value) -> Result<BTreeMap<usize, f64>, QueryError> {
    match h.get("params") {
        None | Some(Value::Null) => Ok(BTreeMap::new()),
        Some(v) => {
            let m: BTreeMap<String, f64> = serde_json::from_value(v.clone())
                .map_err(|e| QueryError(format!("field \"params\": {e}")))?;
            m.into_iter()
                .map(|(k, v)| {
                    let i: usize =
                        k.parse().ok().filter(|i| *i >= 1).ok_or_else(|| {
                            QueryError(format!("parameter {k:?} must be 1, 2, …"))
                        })?;
                    if v.is_finite() {
                        Ok((i, v))
                    } else {
                        Err(QueryError(format!("parameter {k}: {v} is not finite")))
                    }
                })
                .collect()
        }
    }
}

fn index(h: &Value) -> Result<usize, QueryError> {
    usize::try_from(u64_field(h, "index")?).map_err(|e| QueryError(e.to_string()))
}

/// The command of a JSON message.
///
/// # Errors
/// An unknown command name, a missing or malformed field.
pub fn parse(h: &Value) -> Result<Command, QueryError> {
    let id = |name: &str| u64_field(h, name).map(ObjectId);
    Ok(match string(h, "command")?.as_str() {
        "remove" => Command::Remove { id: id("id")? },
        "rename" => Command::Rename {
            id: id("id")?,
            name: string(h, "name")?,
        },
        "add-frep" => Command::Add {
            name: string(h, "name")?,
            object: NewObject::Frep {
                source: string(h, "source")?,
                params: params(h)?,
            },
        },
        "replace-frep" => Command::Replace {
            id: id("id")?,
            object: NewObject::Frep {
                source: string(h, "source")?,
                params: params(h)?,
            },
        },
        "add-derived" => Command::Add {
            name: string(h, "name")?,
            object: NewObject::Derived(recipe(h)?),
        },
        "set-recipe" => Command::SetRecipe {
            id: id("id")?,
            recipe: recipe(h)?,
        },
        "add-handle" => Command::AddHandle {
            map: id("map")?,
            source: vec3_field(h, "source")?,
            target: vec3_field(h, "target")?,
        },
        "move-handle" => Command::MoveHandle {
            map: id("map")?,
            index: index(h)?,
            source: vec3_field(h, "source")?,
            target: vec3_field(h, "target")?,
        },
        "delete-handle" => Command::DeleteHandle {
            map: id("map")?,
            index: index(h)?,
        },
        "set-handle-method" => Command::SetHandleMethod {
            map: id("map")?,
            method: serde_json::from_value::<HandleMethod>(Value::String(string(h, "method")?))
                .map_err(|e| QueryError(format!("field \"method\": {e}")))?,
            options: HandleOptions::default(),
        },
        other => return Err(QueryError(format!("unknown command {other:?}"))),
    })
}

fn recipe(h: &Value) -> Result<Recipe, QueryError> {
    serde_json::from_value(h.get("recipe").cloned().unwrap_or(Value::Null))
        .map_err(|e| QueryError(format!("field \"recipe\": {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn sculpt_messages_parse_concatenate_and_bad_fields_are_named() {
        let m = |extra: Value| {
            let mut h = json!({"command": "sculpt", "id": 4, "brush": "sphere", "op": "subtract",
                "size": 0.2, "points": [[0, 0, 0], [0.1, 0, 0]]});
            for (k, v) in extra.as_object().unwrap() {
                h[k] = v.clone();
            }
            sculpt(&h)
        };
        let r = m(json!({})).unwrap().unwrap();
        assert_eq!(r.id, ObjectId(4));
        assert_eq!(r.brush, Brush::Shape(BrushShape::Sphere));
        assert_eq!(r.op, Op::Subtract);
        assert_eq!(r.points, vec![DVec3::ZERO, DVec3::new(0.1, 0.0, 0.0)]);
        let b = m(json!({"brush": {"mesh": 7}, "op": "add"}))
            .unwrap()
            .unwrap();
        assert_eq!(b.brush, Brush::Mesh(ObjectId(7)));
        assert!(!r.continues_with(&b));
        // The next segment starts where this one ended: the shared point appears once.
        let next = m(json!({"points": [[0.1, 0, 0], [0.2, 0, 0]]}))
            .unwrap()
            .unwrap();
        assert!(r.continues_with(&next));
        let mut stroke = r.clone();
        stroke.extend(next);
        assert_eq!(stroke.points.len(), 3);
        assert_eq!(stroke.points[2], DVec3::new(0.2, 0.0, 0.0));
        assert!(sculpt(&json!({"command": "rename"})).unwrap().is_none());
        for (bad, named) in [
            (json!({"brush": "cone"}), "brush"),
            (json!({"op": "xor"}), "op"),
            (json!({"size": -1}), "size"),
            (json!({"points": []}), "points"),
            (json!({"points": [[0, 0]]}), "point 0"),
            (json!({"points": [[0, 0, 0], ["x", 0, 0]]}), "point 1"),
        ] {
            let e = m(bad).unwrap_err();
            assert!(e.0.contains(named), "{named}: {e}");
        }
    }

    #[test]
    fn commands_parse_and_bad_fields_are_named() {
        let c = parse(
            &json!({"command": "add-handle", "map": 3, "source": [0, 0, 0], "target": [1, 0, 0]}),
        )
        .unwrap();
        assert!(matches!(
            c,
            Command::AddHandle {
                map: ObjectId(3),
                ..
            }
        ));
        let c = parse(&json!({"command": "set-handle-method", "map": 3, "method": "tps"})).unwrap();
        assert!(matches!(
            c,
            Command::SetHandleMethod {
                method: HandleMethod::Tps,
                ..
            }
        ));
        let c = parse(&json!({"command": "add-frep", "name": "m", "source": "my(x[3], a[1]) { my = 1 - x[1]; }", "params": {"1": 0.5}})).unwrap();
        assert!(matches!(
            c,
            Command::Add {
                object: NewObject::Frep { .. },
                ..
            }
        ));
        let e = parse(&json!({"command": "move-handle", "map": 3, "index": 0, "source": [0, 0]}))
            .unwrap_err();
        assert!(
            e.0.contains("\"target\"") || e.0.contains("\"source\""),
            "{e}"
        );
        assert!(
            parse(&json!({"command": "explode"}))
                .unwrap_err()
                .0
                .contains("explode")
        );
        assert!(
            parse(&json!({"command": "add-frep", "name": "m", "source": "", "params": {"0": 1}}))
                .is_err()
        );
    }
}
