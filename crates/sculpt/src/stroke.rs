//! Stroke files: the poses a tool is swept along, as JSON.
//!
//! ```json
//! {"step": 0.01,
//!  "poses": [{"translate": [x, y, z],
//!             "rotate": [w, x, y, z] | {"axis": [x, y, z], "degrees": a},
//!             "scale": s}, …]}
//! ```
//!
//! Every pose field is optional (identity translation, rotation and scale); `step` is
//! optional (`None`: one grid spacing). A bare array of poses is accepted too. Quaternions
//! are normalised; zero or non-finite ones, zero rotation axes, unknown fields and invalid
//! poses ([`Pose::validate`]) are errors naming the pose and the field.

use std::path::Path;

use glam::{DQuat, DVec3};
use serde_json::{Map, Value};

use crate::SculptError;
use crate::tool::Pose;

/// Largest stroke file read, in bytes (a million poses is about 100 MB of JSON).
pub const MAX_STROKE_BYTES: u64 = 256 << 20;

/// A painting stroke: the tool's poses, and the largest movement between dabs.
///
/// Its file form (JSON):
///
/// ```json
/// {"step": 0.01,
///  "poses": [{"translate": [x, y, z],
///             "rotate": [w, x, y, z] | {"axis": [x, y, z], "degrees": a},
///             "scale": s}, …]}
/// ```
///
/// Every pose field is optional (identity translation, rotation and scale); `step` is
/// optional (`None`: one grid spacing). A bare array of poses is accepted too.
#[derive(Debug, Clone, PartialEq)]
pub struct Stroke {
    /// The poses, in order (at least one).
    pub poses: Vec<Pose>,
    /// Largest movement of a tool point between dabs (physical units); `None` is one grid
    /// spacing.
    pub step: Option<f64>,
}

impl Stroke {
    /// Parse a stroke from JSON text (the format is in [`Stroke`]'s documentation).
    ///
    /// # Errors
    /// [`SculptError::Stroke`] naming the pose and field that are wrong, for invalid JSON,
    /// an empty pose list, a field of the wrong shape, an unknown field or an invalid pose.
    pub fn from_json(text: &str) -> Result<Self, SculptError> {
        let doc: Value =
            serde_json::from_str(text).map_err(|e| bad(format!("invalid JSON: {e}")))?;
        let (list, step) = match &doc {
            Value::Array(a) => (a.as_slice(), None),
            Value::Object(o) => {
                if let Some(k) = o.keys().find(|k| !matches!(k.as_str(), "poses" | "step")) {
                    return Err(bad(format!(
                        "unknown field {k:?} (expected \"poses\", \"step\")"
                    )));
                }
                let list = o
                    .get("poses")
                    .and_then(Value::as_array)
                    .ok_or_else(|| bad("field \"poses\" must be an array of poses"))?;
                let step = match o.get("step") {
                    None | Some(Value::Null) => None,
                    Some(v) => {
                        let s = v
                            .as_f64()
                            .filter(|s| s.is_finite() && *s > 0.0)
                            .ok_or_else(|| bad("field \"step\" must be a positive number"))?;
                        Some(s)
                    }
                };
                (list.as_slice(), step)
            }
            _ => {
                return Err(bad(
                    "expected an object with \"poses\" or an array of poses",
                ));
            }
        };
        if list.is_empty() {
            return Err(bad("field \"poses\" is empty"));
        }
        let poses = list
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let o = p
                    .as_object()
                    .ok_or_else(|| bad(format!("pose {i} must be an object")))?;
                pose(o).map_err(|reason| bad(format!("pose {i}: {reason}")))
            })
            .collect::<Result<_, _>>()?;
        Ok(Self { poses, step })
    }

    /// Read a stroke file (the format is in [`Stroke`]'s documentation).
    ///
    /// # Errors
    /// [`SculptError::Io`] when the file cannot be read; [`SculptError::Stroke`] (with the
    /// path) as [`Stroke::from_json`], or for a file over [`MAX_STROKE_BYTES`].
    pub fn read(path: &Path) -> Result<Self, SculptError> {
        let os = |e| volmorph_io::IoError::os(path, e);
        let len = std::fs::metadata(path).map_err(os)?.len();
        let in_file = |e: SculptError| match e {
            SculptError::Stroke(m) => SculptError::Stroke(format!("{}: {m}", path.display())),
            other => other,
        };
        if len > MAX_STROKE_BYTES {
            return Err(in_file(bad(format!(
                "{len} bytes, more than the limit of {MAX_STROKE_BYTES}"
            ))));
        }
        let bytes = volmorph_io::read_maybe_gz(path)?;
        let text =
            std::str::from_utf8(&bytes).map_err(|e| in_file(bad(format!("not UTF-8: {e}"))))?;
        Self::from_json(text).map_err(in_file)
    }

    /// The stroke as JSON text that [`Stroke::from_json`] reads back to the same poses
    /// (rotations as `[w, x, y, z]`; numbers in shortest round-trip form).
    #[must_use]
    pub fn to_json(&self) -> String {
        let poses: Vec<Value> = self
            .poses
            .iter()
            .map(|p| {
                let q = p.rotation;
                serde_json::json!({
                    "translate": [p.translation.x, p.translation.y, p.translation.z],
                    "rotate": [q.w, q.x, q.y, q.z],
                    "scale": p.scale,
                })
            })
            .collect();
        let mut doc = Map::new();
        if let Some(s) = self.step {
            doc.insert("step".into(), s.into());
        }
        doc.insert("poses".into(), Value::Array(poses));
        Value::Object(doc).to_string()
    }
}

fn bad(reason: impl Into<String>) -> SculptError {
    SculptError::Stroke(reason.into())
}

/// `n` numbers from a JSON array, or a message naming `what`.
fn numbers<const N: usize>(v: &Value, what: &str) -> Result<[f64; N], String> {
    let a = v
        .as_array()
        .filter(|a| a.len() == N)
        .ok_or_else(|| format!("{what:?} must be an array of {N} numbers"))?;
    let mut out = [0.0; N];
    for (o, x) in out.iter_mut().zip(a) {
        *o = x
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{what:?} must hold finite numbers"))?;
    }
    Ok(out)
}

fn pose(o: &Map<String, Value>) -> Result<Pose, String> {
    if let Some(k) = o
        .keys()
        .find(|k| !matches!(k.as_str(), "translate" | "rotate" | "scale"))
    {
        return Err(format!(
            "unknown field {k:?} (expected \"translate\", \"rotate\", \"scale\")"
        ));
    }
    let mut pose = Pose::IDENTITY;
    if let Some(v) = o.get("translate") {
        pose.translation = DVec3::from_array(numbers::<3>(v, "translate")?);
    }
    if let Some(v) = o.get("rotate") {
        pose.rotation = match v {
            Value::Object(r) => {
                if let Some(k) = r.keys().find(|k| !matches!(k.as_str(), "axis" | "degrees")) {
                    return Err(format!(
                        "unknown field \"rotate.{k}\" (expected \"axis\", \"degrees\")"
                    ));
                }
                let axis = numbers::<3>(
                    r.get("axis").ok_or("\"rotate.axis\" is missing")?,
                    "rotate.axis",
                )?;
                let degrees = r
                    .get("degrees")
                    .and_then(Value::as_f64)
                    .filter(|d| d.is_finite())
                    .ok_or("\"rotate.degrees\" must be a finite number")?;
                let axis = DVec3::from_array(axis)
                    .try_normalize()
                    .ok_or("\"rotate.axis\" must be a non-zero vector")?;
                DQuat::from_axis_angle(axis, degrees.to_radians())
            }
            _ => {
                let [w, x, y, z] = numbers::<4>(v, "rotate")?;
                let q = DQuat::from_xyzw(x, y, z, w);
                if q.length_squared() <= 0.0 {
                    return Err("\"rotate\" must be a non-zero quaternion [w, x, y, z]".into());
                }
                q.normalize()
            }
        };
    }
    if let Some(v) = o.get("scale") {
        pose.scale = v.as_f64().ok_or("\"scale\" must be a number")?;
    }
    pose.validate().map_err(|e| e.to_string())?;
    Ok(pose)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strokes_parse_with_every_rotation_form() {
        let s = Stroke::from_json(
            r#"{"step": 0.01, "poses": [
                {"translate": [1, 2, 3]},
                {"translate": [0, 0, 0], "rotate": {"axis": [0, 0, 1], "degrees": 90}, "scale": 2},
                {"rotate": [2, 0, 0, 0]}]}"#,
        )
        .unwrap();
        assert_eq!(s.step, Some(0.01));
        assert_eq!(s.poses.len(), 3);
        assert_eq!(s.poses[0].translation, DVec3::new(1.0, 2.0, 3.0));
        assert!((s.poses[1].apply(DVec3::X) - DVec3::new(0.0, 2.0, 0.0)).length() < 1e-12);
        assert_eq!(s.poses[2].rotation, DQuat::IDENTITY);
        let bare = Stroke::from_json(r#"[{"scale": 1}]"#).unwrap();
        assert_eq!((bare.poses, bare.step), (vec![Pose::IDENTITY], None));
    }

    #[test]
    fn strokes_round_trip_through_json() {
        let s = Stroke {
            poses: vec![
                Pose {
                    translation: DVec3::new(0.1, -2.5e-7, 3.0),
                    rotation: DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 2.0) / 3.0, 0.3),
                    scale: 1.7,
                },
                Pose::at(DVec3::new(1.0 / 3.0, 0.0, 0.0)),
            ],
            step: Some(0.125),
        };
        let back = Stroke::from_json(&s.to_json()).unwrap();
        assert_eq!(back.step, s.step);
        for (a, b) in back.poses.iter().zip(&s.poses) {
            assert_eq!(a.translation, b.translation);
            assert_eq!(a.scale, b.scale);
            // A unit quaternion is normalised again on reading: equal to rounding.
            assert!((a.rotation - b.rotation).length() < 1e-15);
        }
    }

    #[test]
    fn bad_strokes_name_the_pose_and_field() {
        for (bad, says) in [
            (r#"{"poses": []}"#, "empty"),
            (
                r#"{"poses": [{"translate": [1, 2]}]}"#,
                "pose 0: \"translate\"",
            ),
            (r#"[{}, {"scale": -1}]"#, "pose 1: pose scale"),
            (
                r#"[{"rotate": {"axis": [0, 0, 0], "degrees": 3}}]"#,
                "rotate.axis",
            ),
            (r#"[{"rotate": [0, 0, 0, 0]}]"#, "non-zero quaternion"),
            (r#"[{"translat": [0, 0, 0]}]"#, "unknown field \"translat\""),
            (r#"{"poses": [{}], "step": -1}"#, "\"step\""),
            (r#"{"pose": [{}]}"#, "unknown field \"pose\""),
            ("[", "invalid JSON"),
            ("3", "expected an object"),
        ] {
            let e = Stroke::from_json(bad).unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn reading_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let dir = dir.path();
        let f = dir.join("s.json");
        std::fs::write(&f, r#"[{"scale": 0}]"#).unwrap();
        let e = Stroke::read(&f).unwrap_err().to_string();
        assert!(e.contains("s.json") && e.contains("pose 0"), "{e}");
        assert!(Stroke::read(&dir.join("missing.json")).is_err());
    }
}
