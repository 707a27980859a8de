//! Scene commands a page sends as JSON ([`Kind::Command`](crate::protocol::Kind::Command)):
//! `{"command": NAME, …fields}`, one form per [`Command`] a page issues (see `PROTOCOL.md`).
//! Handle methods use the scene's own serde names (`affine`, `tps`, …) and recipes the
//! project file's recipe form.

use std::collections::BTreeMap;

use serde_json::Value;
use volmorph_maps::{HandleMethod, HandleOptions};
use volmorph_scene::{Command, NewObject, ObjectId, Recipe};

use crate::views::{QueryError, u64_field, vec3_field};

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
