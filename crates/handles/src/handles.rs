//! Handle files: source → target correspondences for the handle-driven maps.
//!
//! A handle set pairs every **source** handle (where a feature is in the undeformed model) with
//! its **target** (where the deformation must send it). Three formats are read:
//!
//! # volmorph handle JSON (`.json`) — pairs in one file
//!
//! ```json
//! {
//!   "version": 1,
//!   "kind": "handles",
//!   "points":   [ { "source": [x, y, z], "target": [x, y, z] } ],
//!   "segments": [ { "source": [[x, y, z], [x, y, z]], "target": [[x, y, z], [x, y, z]] } ],
//!   "frames":   [ { "source": { "origin": [x, y, z], "axes": [[ax], [ay], [az]] },
//!                   "target": { "origin": [x, y, z], "axes": [[ax], [ay], [az]] } } ]
//! }
//! ```
//!
//! Coordinates have 3 components (physical, LPS like every volmorph geometry) or, for 2D image
//! handles, 2 (pixel coordinates `x` right, `y` down; stored with `z = 0`); one file uses one
//! dimension throughout. `version` and `kind` may be omitted; the three lists each default to
//! empty. `axes` are the three axis vectors of a frame (rows of the JSON array, columns of
//! [`Frame::axes`]). Unknown fields are errors.
//!
//! # 3D Slicer markups (`.fcsv`) — one point list per file
//!
//! Comment lines start with `#`; `# CoordinateSystem = LPS` (or `1`) declares LPS
//! coordinates, `RAS` (or `0`, the default when absent) RAS coordinates, which are converted
//! to LPS by negating `x` and `y`, as ITK does. Every other line is
//! `id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID`; only `x,y,z` are used.
//!
//! # Plain text (`.txt`, `.xyz`, `.pts`) — a point list or pairs
//!
//! One handle per line, numbers separated by whitespace or commas, `#` starts a comment.
//! Three numbers per line are a point list; six (`sx sy sz tx ty tz`) are source–target
//! pairs. All lines must have the same count.
//!
//! A point list (`.fcsv`, 3-column text) holds sources *or* targets: two lists of the same
//! length are paired by order with [`HandleSet::from_lists`] (the command line's
//! `--from A --to B`).

use std::path::Path;

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

use crate::mls::Frame;
use volmorph_deform::DeformError;

/// Format version written by [`HandleSet::to_json`] and the only one read.
pub const HANDLES_JSON_VERSION: u32 = 1;

/// Largest number of handles read from one file: far above any interactive use, and it
/// bounds the dense thin-plate system (`(N + 4)²` doubles, 8 GB at this size) a file can ask
/// for.
pub const MAX_HANDLES: usize = 32_768;

/// Largest handle file read, in bytes (a file at [`MAX_HANDLES`] pairs is a few MB).
pub const MAX_HANDLE_FILE_BYTES: u64 = 64 << 20;

/// A set of source → target correspondences (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct HandleSet {
    /// Coordinate dimension of the file: 2 (image handles, `z = 0`) or 3.
    pub dim: usize,
    /// Point handles `(source, target)`.
    pub points: Vec<(DVec3, DVec3)>,
    /// Line-segment handles `([a, b] source, [c, d] target)`.
    pub segments: Vec<([DVec3; 2], [DVec3; 2])>,
    /// Frame handles `(source, target)`.
    pub frames: Vec<(Frame, Frame)>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameJson {
    origin: Vec<f64>,
    axes: Vec<Vec<f64>>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PairJson<T> {
    source: T,
    target: T,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct HandlesJson {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    version: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    kind: Option<String>,
    #[serde(default)]
    points: Vec<PairJson<Vec<f64>>>,
    #[serde(default)]
    segments: Vec<PairJson<Vec<Vec<f64>>>>,
    #[serde(default)]
    frames: Vec<PairJson<FrameJson>>,
}

fn json_err(msg: String) -> DeformError {
    DeformError::Parse {
        format: "handle JSON",
        line: 0,
        message: msg,
    }
}

/// Check a coordinate array's length against the file's dimension (set by the first one).
fn point(v: &[f64], dim: &mut usize, what: &str) -> Result<DVec3, DeformError> {
    if v.len() != 2 && v.len() != 3 {
        return Err(json_err(format!(
            "{what} has {} coordinates, expected 2 or 3",
            v.len()
        )));
    }
    if *dim == 0 {
        *dim = v.len();
    } else if *dim != v.len() {
        return Err(json_err(format!(
            "{what} has {} coordinates but earlier handles have {}",
            v.len(),
            *dim
        )));
    }
    for (a, &x) in v.iter().enumerate() {
        if !x.is_finite() {
            return Err(DeformError::NonFinite {
                what: format!("{what}, component {a}"),
                value: x,
            });
        }
    }
    Ok(DVec3::new(v[0], v[1], v.get(2).copied().unwrap_or(0.0)))
}

fn frame(f: &FrameJson, dim: &mut usize, what: &str) -> Result<Frame, DeformError> {
    let origin = point(&f.origin, dim, &format!("{what} origin"))?;
    if *dim != 3 {
        return Err(json_err(format!("{what}: frames need 3D coordinates")));
    }
    if f.axes.len() != 3 {
        return Err(json_err(format!(
            "{what} has {} axes, expected 3",
            f.axes.len()
        )));
    }
    let mut cols = [DVec3::ZERO; 3];
    for (a, col) in cols.iter_mut().enumerate() {
        *col = point(&f.axes[a], dim, &format!("{what} axis {a}"))?;
    }
    Ok(Frame {
        origin,
        axes: DMat3::from_cols(cols[0], cols[1], cols[2]),
    })
}

impl HandleSet {
    /// Total number of handles of all kinds.
    #[must_use]
    pub fn len(&self) -> usize {
        self.points.len() + self.segments.len() + self.frames.len()
    }

    /// `true` if there are no handles.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Source points.
    #[must_use]
    pub fn sources(&self) -> Vec<DVec3> {
        self.points.iter().map(|p| p.0).collect()
    }

    /// Target points.
    #[must_use]
    pub fn targets(&self) -> Vec<DVec3> {
        self.points.iter().map(|p| p.1).collect()
    }

    /// Check that the point handles' sources are distinct (to
    /// [`crate::mls::MIN_HANDLE_SEPARATION`] of their radius) and every coordinate finite:
    /// a source sent to two targets is a contradiction for every map, whichever direction it
    /// is later built in.
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] naming the coincident pair, [`DeformError::NonFinite`].
    pub fn validate(&self) -> Result<(), DeformError> {
        let (s, t) = (self.sources(), self.targets());
        if s.is_empty() {
            return Ok(());
        }
        crate::mls::check_handles(&s, &t, 0, "a handle set")
    }

    /// Pair two point lists by order (3D).
    ///
    /// # Errors
    /// [`DeformError::InvalidHandles`] if the lists differ in length or are empty.
    pub fn from_lists(sources: &[DVec3], targets: &[DVec3]) -> Result<Self, DeformError> {
        if sources.len() != targets.len() {
            return Err(DeformError::InvalidHandles(format!(
                "{} source points but {} target points",
                sources.len(),
                targets.len()
            )));
        }
        if sources.is_empty() {
            return Err(DeformError::InvalidHandles("no handles".into()));
        }
        Ok(Self {
            dim: 3,
            points: sources
                .iter()
                .copied()
                .zip(targets.iter().copied())
                .collect(),
            ..Self::default()
        })
    }

    /// Parse the JSON form.
    ///
    /// # Errors
    /// [`DeformError::Json`] for malformed JSON or unknown fields, [`DeformError::Parse`] for
    /// a wrong version/kind, coordinate count or more than [`MAX_HANDLES`] handles,
    /// and [`DeformError::NonFinite`] for a non-finite coordinate (checked although JSON cannot spell one).
    pub fn from_json(text: &str) -> Result<Self, DeformError> {
        if !text.trim_start().starts_with('{') {
            return Err(json_err("expected a JSON object".into()));
        }
        let j: HandlesJson =
            serde_json::from_str(text).map_err(DeformError::json("handle JSON"))?;
        if let Some(v) = j.version
            && v != HANDLES_JSON_VERSION
        {
            return Err(json_err(format!(
                "version {v} not supported (expected {HANDLES_JSON_VERSION})"
            )));
        }
        if let Some(k) = &j.kind
            && k != "handles"
        {
            return Err(json_err(format!("kind \"{k}\", expected \"handles\"")));
        }
        let total = j.points.len() + j.segments.len() + j.frames.len();
        if total > MAX_HANDLES {
            return Err(json_err(format!(
                "{total} handles, more than the limit of {MAX_HANDLES}"
            )));
        }
        let mut dim = 0;
        let mut set = Self::default();
        for (i, p) in j.points.iter().enumerate() {
            let s = point(&p.source, &mut dim, &format!("point {i} source"))?;
            let t = point(&p.target, &mut dim, &format!("point {i} target"))?;
            set.points.push((s, t));
        }
        for (i, sg) in j.segments.iter().enumerate() {
            let mut ends = [DVec3::ZERO; 4];
            for (e, (list, name)) in [(&sg.source, "source"), (&sg.target, "target")]
                .into_iter()
                .enumerate()
            {
                if list.len() != 2 {
                    return Err(json_err(format!(
                        "segment {i} {name} has {} end points, expected 2",
                        list.len()
                    )));
                }
                for k in 0..2 {
                    ends[2 * e + k] =
                        point(&list[k], &mut dim, &format!("segment {i} {name} end {k}"))?;
                }
            }
            set.segments.push(([ends[0], ends[1]], [ends[2], ends[3]]));
        }
        for (i, f) in j.frames.iter().enumerate() {
            let s = frame(&f.source, &mut dim, &format!("frame {i} source"))?;
            let t = frame(&f.target, &mut dim, &format!("frame {i} target"))?;
            set.frames.push((s, t));
        }
        set.dim = if dim == 0 { 3 } else { dim };
        Ok(set)
    }

    /// The JSON form (with `version` and `kind`; 2D sets write 2 coordinates).
    #[must_use]
    pub fn to_json(&self) -> String {
        let d = if self.dim == 2 { 2 } else { 3 };
        let v = |p: DVec3| p.to_array()[..d].to_vec();
        let fr = |f: &Frame| FrameJson {
            origin: f.origin.to_array().to_vec(),
            axes: vec![
                f.axes.x_axis.to_array().to_vec(),
                f.axes.y_axis.to_array().to_vec(),
                f.axes.z_axis.to_array().to_vec(),
            ],
        };
        let j = HandlesJson {
            version: Some(HANDLES_JSON_VERSION),
            kind: Some("handles".into()),
            points: self
                .points
                .iter()
                .map(|(s, t)| PairJson {
                    source: v(*s),
                    target: v(*t),
                })
                .collect(),
            segments: self
                .segments
                .iter()
                .map(|(s, t)| PairJson {
                    source: vec![v(s[0]), v(s[1])],
                    target: vec![v(t[0]), v(t[1])],
                })
                .collect(),
            frames: self
                .frames
                .iter()
                .map(|(s, t)| PairJson {
                    source: fr(s),
                    target: fr(t),
                })
                .collect(),
        };
        // Serialising plain vectors of finite numbers cannot fail.
        serde_json::to_string_pretty(&j).unwrap_or_default()
    }

    /// Read a handle file by extension: `.json` (pairs), or 6-column text (pairs).
    ///
    /// # Errors
    /// [`DeformError::Io`] for an unreadable or oversized file, the parse errors of the
    /// format, and [`DeformError::Unsupported`] for a point-list file (`.fcsv`, 3-column text)
    /// — those need a second list, see [`HandleSet::from_lists`] — or an unknown extension.
    pub fn read(path: &Path) -> Result<Self, DeformError> {
        Self::read_inner(path).map_err(|e| e.at(path))
    }

    fn read_inner(path: &Path) -> Result<Self, DeformError> {
        let text = read_text(path)?;
        match extension(path).as_str() {
            "json" => Self::from_json(&text),
            "txt" | "xyz" | "pts" | "csv" => match parse_text(&text)? {
                TextHandles::Pairs(s, t) => Self::from_lists(&s, &t),
                TextHandles::Points(_) => Err(DeformError::Unsupported(format!(
                    "{} is a point list (3 columns): give sources and targets as two lists",
                    path.display()
                ))),
            },
            "fcsv" => Err(DeformError::Unsupported(format!(
                "{} is a Slicer point list: give sources and targets as two lists",
                path.display()
            ))),
            other => Err(DeformError::Unsupported(format!(
                "unknown handle file extension \"{other}\" (use .json, .fcsv, .txt/.xyz)"
            ))),
        }
    }

    /// The extension of handle JSON files ([`HandleSet::write_json`]): `.json`.
    pub const JSON_EXTENSIONS: &'static [&'static str] =
        volmorph_io::extension::OutputFormat::Json.extensions();

    /// Write the JSON form atomically.
    ///
    /// # Errors
    /// [`DeformError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in
    /// `.json` (nothing written); [`DeformError::Io`] if the file cannot be written.
    pub fn write_json(&self, path: &Path) -> Result<(), DeformError> {
        volmorph_io::extension::check(path, Self::JSON_EXTENSIONS)?;
        let text = self.to_json();
        volmorph_io::write_atomic(path, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes())
                .map_err(|e| DeformError::Io(volmorph_io::IoError::os(path, e)))
        })
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

fn read_text(path: &Path) -> Result<String, DeformError> {
    let meta = volmorph_io::open_regular(path)?
        .metadata()
        .map_err(|e| io_err(path, e))?;
    if meta.len() > MAX_HANDLE_FILE_BYTES {
        return Err(DeformError::Unsupported(format!(
            "{}: {} bytes is more than a handle file may hold ({MAX_HANDLE_FILE_BYTES})",
            path.display(),
            meta.len()
        )));
    }
    std::fs::read_to_string(path).map_err(|e| io_err(path, e))
}

fn io_err(path: &Path, e: std::io::Error) -> DeformError {
    DeformError::Io(volmorph_io::IoError::os(path, e))
}

/// Read a point list by extension: `.fcsv` (Slicer, converted to LPS), `.json` (the sources of
/// a handle JSON are *not* a list: rejected), or 3-column text.
///
/// # Errors
/// [`DeformError::Io`], the parse errors of the format, [`DeformError::Unsupported`] for
/// 6-column text or another extension.
pub fn read_point_list(path: &Path) -> Result<Vec<DVec3>, DeformError> {
    read_point_list_inner(path).map_err(|e| e.at(path))
}

fn read_point_list_inner(path: &Path) -> Result<Vec<DVec3>, DeformError> {
    let text = read_text(path)?;
    match extension(path).as_str() {
        "fcsv" => parse_fcsv(&text),
        "txt" | "xyz" | "pts" | "csv" => match parse_text(&text)? {
            TextHandles::Points(p) => Ok(p),
            TextHandles::Pairs(..) => Err(DeformError::Unsupported(format!(
                "{} holds source–target pairs (6 columns), not a point list",
                path.display()
            ))),
        },
        other => Err(DeformError::Unsupported(format!(
            "unknown point list extension \"{other}\" (use .fcsv or .txt/.xyz)"
        ))),
    }
}

/// The extensions [`write_point_list`] writes (without the dot): Slicer `.fcsv`, `.csv` and
/// the text forms `.txt`, `.xyz`, `.pts`.
pub const POINT_LIST_EXTENSIONS: &[&str] = &["fcsv", "csv", "txt", "xyz", "pts"];

/// Check that `path` ends in one of [`POINT_LIST_EXTENSIONS`] (any case) before the points
/// are computed.
///
/// # Errors
/// [`DeformError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
/// extension found and [`POINT_LIST_EXTENSIONS`].
pub fn check_point_list_output(path: &Path) -> Result<(), DeformError> {
    Ok(volmorph_io::extension::check(path, POINT_LIST_EXTENSIONS)?)
}

/// Write a point list, the format following the extension: `.fcsv` (3D Slicer markups, with
/// `# CoordinateSystem = LPS`, so the points are stored as given), `.csv` (`x,y,z` per line) or
/// `.txt`/`.xyz`/`.pts` (`x y z` per line). Numbers are written with every digit needed to
/// read the same `f64` back. Written atomically.
///
/// # Errors
/// [`DeformError::Io`] with [`volmorph_io::IoError::Extension`] for another extension
/// ([`check_point_list_output`], nothing written), [`DeformError::NonFinite`] for a NaN or
/// infinite point, [`DeformError::Io`] if writing fails.
pub fn write_point_list(path: &Path, points: &[DVec3]) -> Result<(), DeformError> {
    check_point_list_output(path)?;
    volmorph_deform::map::check_finite("point", points)?;
    let f = |v: f64| volmorph_io::fmt_f64(v);
    let mut text = String::with_capacity(points.len() * 64 + 128);
    match extension(path).as_str() {
        "fcsv" => {
            text.push_str("# Markups fiducial file version = 4.11\n# CoordinateSystem = LPS\n");
            text.push_str(
                "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n",
            );
            for (i, p) in points.iter().enumerate() {
                text.push_str(&format!(
                    "{},{},{},{},0,0,0,1,1,1,0,F-{},,\n",
                    i + 1,
                    f(p.x),
                    f(p.y),
                    f(p.z),
                    i + 1
                ));
            }
        }
        "csv" => {
            for p in points {
                text.push_str(&format!("{},{},{}\n", f(p.x), f(p.y), f(p.z)));
            }
        }
        "txt" | "xyz" | "pts" => {
            for p in points {
                text.push_str(&format!("{} {} {}\n", f(p.x), f(p.y), f(p.z)));
            }
        }
        other => {
            return Err(DeformError::Unsupported(format!(
                "{}: unknown point list extension \"{other}\" (use .fcsv, .csv or .txt)",
                path.display()
            )));
        }
    }
    volmorph_io::write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes()).map_err(|e| io_err(path, e))
    })
}

/// Content of a plain-text handle file.
#[derive(Debug, Clone, PartialEq)]
pub enum TextHandles {
    /// Three columns: one point per line.
    Points(Vec<DVec3>),
    /// Six columns: `(sources, targets)`.
    Pairs(Vec<DVec3>, Vec<DVec3>),
}

/// Parse plain text (see the [module docs](self)).
///
/// # Errors
/// [`DeformError::Parse`] for a non-number, a line with other than 3 or 6 numbers, lines with
/// different counts, no data or more than [`MAX_HANDLES`] lines; [`DeformError::NonFinite`]
/// for `nan`/`inf`.
pub fn parse_text(text: &str) -> Result<TextHandles, DeformError> {
    let err = |line: usize, message: String| DeformError::Parse {
        format: "handle text",
        line,
        message,
    };
    let mut cols = 0;
    let mut a = Vec::new();
    let mut b = Vec::new();
    for (n, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let mut v = [0.0f64; 6];
        let mut count = 0;
        for tok in line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty())
        {
            if count == 6 {
                return Err(err(n + 1, "more than 6 numbers".into()));
            }
            let x: f64 = tok
                .parse()
                .map_err(|_| err(n + 1, format!("\"{tok}\" is not a number")))?;
            if !x.is_finite() {
                return Err(DeformError::NonFinite {
                    what: format!("handle text line {}", n + 1),
                    value: x,
                });
            }
            v[count] = x;
            count += 1;
        }
        if count != 3 && count != 6 {
            return Err(err(n + 1, format!("{count} numbers, expected 3 or 6")));
        }
        if cols == 0 {
            cols = count;
        } else if cols != count {
            return Err(err(
                n + 1,
                format!("{count} numbers but earlier lines have {cols}"),
            ));
        }
        if a.len() >= MAX_HANDLES {
            return Err(err(n + 1, format!("more than {MAX_HANDLES} handles")));
        }
        a.push(DVec3::new(v[0], v[1], v[2]));
        if count == 6 {
            b.push(DVec3::new(v[3], v[4], v[5]));
        }
    }
    match cols {
        0 => Err(err(0, "no handles".into())),
        3 => Ok(TextHandles::Points(a)),
        _ => Ok(TextHandles::Pairs(a, b)),
    }
}

/// Parse a 3D Slicer `.fcsv` markups file into LPS points (see the [module docs](self)).
///
/// # Errors
/// [`DeformError::Parse`] for a row with fewer than 4 fields, a non-number coordinate, an
/// unknown coordinate system, no points or more than [`MAX_HANDLES`];
/// [`DeformError::NonFinite`] for `nan`/`inf`.
pub fn parse_fcsv(text: &str) -> Result<Vec<DVec3>, DeformError> {
    let err = |line: usize, message: String| DeformError::Parse {
        format: "Slicer fcsv",
        line,
        message,
    };
    let mut ras = true;
    let mut out = Vec::new();
    for (n, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if let Some(comment) = line.strip_prefix('#') {
            if let Some((key, value)) = comment.split_once('=')
                && key.trim().eq_ignore_ascii_case("CoordinateSystem")
            {
                ras = match value.trim().to_ascii_uppercase().as_str() {
                    "RAS" | "0" => true,
                    "LPS" | "1" => false,
                    other => {
                        return Err(err(n + 1, format!("unknown coordinate system \"{other}\"")));
                    }
                };
            }
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() < 4 {
            return Err(err(
                n + 1,
                format!("{} fields, expected id,x,y,z,…", fields.len()),
            ));
        }
        let mut p = [0.0; 3];
        for (a, f) in fields[1..4].iter().enumerate() {
            let x: f64 = f.trim().parse().map_err(|_| {
                err(
                    n + 1,
                    format!("coordinate \"{}\" is not a number", f.trim()),
                )
            })?;
            if !x.is_finite() {
                return Err(DeformError::NonFinite {
                    what: format!("fcsv line {}", n + 1),
                    value: x,
                });
            }
            p[a] = x;
        }
        if out.len() >= MAX_HANDLES {
            return Err(err(n + 1, format!("more than {MAX_HANDLES} points")));
        }
        out.push(DVec3::from_array(p));
    }
    if out.is_empty() {
        return Err(err(0, "no points".into()));
    }
    if ras {
        for p in &mut out {
            p.x = -p.x;
            p.y = -p.y;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_round_trip_2d_and_3d() {
        let text = r#"{"points": [{"source": [1, 2, 3], "target": [1.5, 2, 3]}],
            "frames": [{"source": {"origin": [0,0,0], "axes": [[1,0,0],[0,1,0],[0,0,1]]},
                        "target": {"origin": [0,1,0], "axes": [[0,1,0],[-1,0,0],[0,0,1]]}}]}"#;
        let s = HandleSet::from_json(text).unwrap();
        assert_eq!(s.dim, 3);
        assert_eq!(s.points[0].1, DVec3::new(1.5, 2.0, 3.0));
        assert_eq!(s.frames[0].1.axes.x_axis, DVec3::Y);
        assert_eq!(HandleSet::from_json(&s.to_json()).unwrap(), s);

        let t2 = r#"{"points": [{"source": [1, 2], "target": [3, 4]}],
                     "segments": [{"source": [[0, 0], [1, 0]], "target": [[0, 0], [0, 1]]}]}"#;
        let s2 = HandleSet::from_json(t2).unwrap();
        assert_eq!(s2.dim, 2);
        assert_eq!(s2.segments[0].1[1], DVec3::new(0.0, 1.0, 0.0));
        assert_eq!(HandleSet::from_json(&s2.to_json()).unwrap(), s2);
    }

    #[test]
    fn bad_json_is_an_error() {
        for bad in [
            "",
            "[]",
            r#"{"points": [{"source": [1, 2, 3], "target": [1, 2]}]}"#,
            r#"{"points": [{"source": [1], "target": [1]}]}"#,
            r#"{"points": [{"source": [1, 2, 3]}]}"#,
            r#"{"version": 7}"#,
            r#"{"kind": "lattice"}"#,
            r#"{"pionts": []}"#,
            r#"{"segments": [{"source": [[0, 0]], "target": [[0, 0], [1, 1]]}]}"#,
            r#"{"frames": [{"source": {"origin": [0,0], "axes": []}, "target": {"origin": [0,0], "axes": []}}]}"#,
        ] {
            assert!(HandleSet::from_json(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn text_and_fcsv() {
        let t = "# handles\n1 2 3 4 5 6\n7,8,9, 10,11,12 # trailing\n\n";
        let TextHandles::Pairs(a, b) = parse_text(t).unwrap() else {
            panic!("pairs expected")
        };
        assert_eq!(a[1], DVec3::new(7.0, 8.0, 9.0));
        assert_eq!(b[0], DVec3::new(4.0, 5.0, 6.0));
        assert_eq!(
            parse_text("1 2 3\n4 5 6\n").unwrap(),
            TextHandles::Points(vec![DVec3::new(1.0, 2.0, 3.0), DVec3::new(4.0, 5.0, 6.0)])
        );
        for bad in [
            "",
            "1 2",
            "1 2 3\n1 2 3 4 5 6",
            "1 x 3",
            "nan 1 2",
            "1 2 3 4 5 6 7",
        ] {
            assert!(parse_text(bad).is_err(), "{bad}");
        }
        let f = "# Markups fiducial file version = 4.11\n# CoordinateSystem = RAS\n\
                 # columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n\
                 vtkMRMLMarkupsFiducialNode_0,10.5,-3,7,0,0,0,1,1,1,0,F-1,,\n\
                 vtkMRMLMarkupsFiducialNode_1,1,2,3,0,0,0,1,1,1,0,F-2,,\n";
        let p = parse_fcsv(f).unwrap();
        assert_eq!(
            p,
            vec![DVec3::new(-10.5, 3.0, 7.0), DVec3::new(-1.0, -2.0, 3.0)]
        );
        let lps = f.replace("RAS", "LPS");
        assert_eq!(parse_fcsv(&lps).unwrap()[0], DVec3::new(10.5, -3.0, 7.0));
        for bad in ["", "# CoordinateSystem = XYZ\na,1,2,3", "a,1,2", "a,1,b,3"] {
            assert!(parse_fcsv(bad).is_err(), "{bad}");
        }
        assert!(HandleSet::from_lists(&p, &p[..1]).is_err());
        assert_eq!(HandleSet::from_lists(&p, &p).unwrap().points.len(), 2);
    }
}
