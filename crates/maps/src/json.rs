//! The JSON form of every map: one document per map, tagged by `"kind"`.
//!
//! A map file is a JSON object with `"version": 1` and a `"kind"`; nested maps (inside
//! `compose`, `inverse` and `refined`) are the same objects, where `version` may be left out. Numbers are
//! written with the shortest text that reads back to the same `f64`, so a write/read round trip
//! is exact. Points are `[x, y, z]` in physical units; matrices are lists of **rows**.
//!
//! | `kind` | fields |
//! | --- | --- |
//! | `identity` | — |
//! | `affine` | `matrix` (3 rows), `offset`: `x ↦ matrix·x + offset` |
//! | `bspline-lattice` | the lattice form of `volmorph_lattice::json` |
//! | `mls` | `method` (`affine`, `similarity`, `rigid`), `weighting`, `sources`, `targets` |
//! | `frame-mls` | `beta`, `weighting`, `sources`, `targets`: frames `{"origin": p, "axes": [a0, a1, a2]}` (axis vectors) |
//! | `thin-plate` | `smoothing`, `kernel` (`r`: the 3-D biharmonic `G(r) = r`, the default when absent; `r2logr`: the thesis's `r² ln r`), `sources`, `targets` |
//! | `wendland` | `support` (radius, physical units), `smoothing`, `sources`, `targets` |
//! | `bump` | `center`, `inner`, `outer`, `matrix`, `offset` |
//! | `nurbs-geometry` | `model` (a trivariate volume file's JSON object), `box`: `{"min": p, "max": p}` |
//! | `sampled` | `grid` (`dims`, `spacing`, `origin`, `direction` rows), `positions` (x fastest) |
//! | `displacement-field` | `grid` (as `sampled`), `displacements` (x fastest, physical units): `x ↦ x + d(x)`, zero beyond half a voxel outside the grid (ITK's `DisplacementFieldTransform`) |
//! | `compose` | `maps`: applied in list order, the first first |
//! | `inverse` | `map`, optional `tolerance` (physical units), `max_iterations` |
//! | `refined` | `base` (a map), `correction` (a `bspline-lattice` map `L`): `x ↦ base(x) + L(x) − x` |
//!
//! `weighting` is `{"type": "inverse-distance", "alpha": α}` or `{"type": "gaussian",
//! "sigma": σ}`. Handle maps send each source to its target (push-forward).

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use volmorph_deform::inverse::Inverse;
use volmorph_deform::{Affine, InverseOptions, SampledMap};
use volmorph_handles::{
    AffineMls, BumpMap, Frame, FrameMls, RigidMls, SimilarityMls, ThinPlateMap, TpsKernel,
    Weighting, WendlandMap,
};
use volmorph_lattice::BSplineLattice;
use volmorph_trivariate::{AnyAggregate, GeometryMap};
use volmorph_volume::Geometry;
use volmorph_volume::direction::snap_direction;

use crate::{AnyMap, MapError};

/// Version of the map JSON documents written and the only one read.
pub const MAP_JSON_VERSION: u64 = 1;

/// Deepest nesting of `compose` and `inverse` accepted when reading (a guard against hostile
/// files that would exhaust the stack).
pub const MAX_NESTING: usize = 32;

#[derive(Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
enum WeightingJson {
    InverseDistance { alpha: f64 },
    Gaussian { sigma: f64 },
}

impl From<Weighting> for WeightingJson {
    fn from(w: Weighting) -> Self {
        match w {
            Weighting::InverseDistance { alpha } => Self::InverseDistance { alpha },
            Weighting::Gaussian { sigma } => Self::Gaussian { sigma },
        }
    }
}

impl From<WeightingJson> for Weighting {
    fn from(w: WeightingJson) -> Self {
        match w {
            WeightingJson::InverseDistance { alpha } => Self::InverseDistance { alpha },
            WeightingJson::Gaussian { sigma } => Self::Gaussian { sigma },
        }
    }
}

#[derive(Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum MlsMethod {
    Affine,
    Similarity,
    Rigid,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct MlsJson {
    method: MlsMethod,
    weighting: WeightingJson,
    sources: Vec<[f64; 3]>,
    targets: Vec<[f64; 3]>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameJson {
    origin: [f64; 3],
    axes: [[f64; 3]; 3],
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameMlsJson {
    beta: f64,
    weighting: WeightingJson,
    sources: Vec<FrameJson>,
    targets: Vec<FrameJson>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ThinPlateJson {
    smoothing: f64,
    /// `r` or `r2logr`; absent in files written before kernels were selectable (then `r`).
    #[serde(default = "default_kernel")]
    kernel: String,
    sources: Vec<[f64; 3]>,
    targets: Vec<[f64; 3]>,
}

fn default_kernel() -> String {
    TpsKernel::R.name().to_owned()
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct WendlandJson {
    support: f64,
    smoothing: f64,
    sources: Vec<[f64; 3]>,
    targets: Vec<[f64; 3]>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct AffineJson {
    matrix: [[f64; 3]; 3],
    offset: [f64; 3],
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct BumpJson {
    center: [f64; 3],
    inner: f64,
    outer: f64,
    matrix: [[f64; 3]; 3],
    offset: [f64; 3],
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct BoxJson {
    min: [f64; 3],
    max: [f64; 3],
}

/// The JSON form of a voxel grid's [`Geometry`] (sampled maps' `grid`, warp output grids of
/// scene recipes): `dims`, `spacing`, `origin` (voxel (0, 0, 0)) and `direction` row by row
/// (`direction[r][c]`; column `c` is the unit direction of index axis `c`, as ITK writes it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridJson {
    /// Voxels per index axis.
    pub dims: [usize; 3],
    /// Voxel spacing per index axis (physical units).
    pub spacing: [f64; 3],
    /// Physical position of voxel (0, 0, 0).
    pub origin: [f64; 3],
    /// Direction matrix, row by row.
    pub direction: [[f64; 3]; 3],
}

impl From<&Geometry> for GridJson {
    fn from(g: &Geometry) -> Self {
        Self {
            dims: g.dims,
            spacing: g.spacing.to_array(),
            origin: g.origin.to_array(),
            direction: rows(g.direction),
        }
    }
}

impl GridJson {
    /// The geometry, its direction snapped by the one direction rule (a skewed matrix is
    /// kept); not validated (see [`Geometry::validate`]).
    #[must_use]
    pub fn geometry(&self) -> Geometry {
        Geometry {
            dims: self.dims,
            spacing: DVec3::from_array(self.spacing),
            origin: DVec3::from_array(self.origin),
            direction: snap_direction(from_rows(self.direction)),
        }
    }
}

fn rows(m: DMat3) -> [[f64; 3]; 3] {
    let r = m.transpose();
    [
        r.x_axis.to_array(),
        r.y_axis.to_array(),
        r.z_axis.to_array(),
    ]
}

fn from_rows(r: [[f64; 3]; 3]) -> DMat3 {
    DMat3::from_cols(
        DVec3::from_array(r[0]),
        DVec3::from_array(r[1]),
        DVec3::from_array(r[2]),
    )
    .transpose()
}

fn points(p: &[DVec3]) -> Vec<[f64; 3]> {
    p.iter().map(|p| p.to_array()).collect()
}

fn vecs(p: &[[f64; 3]]) -> Vec<DVec3> {
    p.iter().map(|p| DVec3::from_array(*p)).collect()
}

fn frame_json(f: &Frame) -> FrameJson {
    FrameJson {
        origin: f.origin.to_array(),
        axes: [
            f.axes.x_axis.to_array(),
            f.axes.y_axis.to_array(),
            f.axes.z_axis.to_array(),
        ],
    }
}

fn frame_of(f: &FrameJson) -> Frame {
    Frame {
        origin: DVec3::from_array(f.origin),
        axes: DMat3::from_cols(
            DVec3::from_array(f.axes[0]),
            DVec3::from_array(f.axes[1]),
            DVec3::from_array(f.axes[2]),
        ),
    }
}

fn tagged(kind: &str, body: impl Serialize) -> Result<Value, MapError> {
    let mut v = serde_json::to_value(body).map_err(MapError::json)?;
    match &mut v {
        Value::Object(o) => {
            o.insert("kind".into(), Value::String(kind.into()));
        }
        Value::Null => v = json!({ "kind": kind }),
        _ => {}
    }
    Ok(v)
}

impl AnyMap {
    /// The map as a JSON value (a nested map: no `version` field).
    ///
    /// # Errors
    /// [`MapError::Json`] if a lattice or model cannot be serialised (it can for valid maps).
    pub fn to_json_value(&self) -> Result<Value, MapError> {
        Ok(match self {
            AnyMap::Identity => json!({ "kind": "identity" }),
            AnyMap::Affine(a) => tagged(
                "affine",
                AffineJson {
                    matrix: rows(a.matrix),
                    offset: a.offset.to_array(),
                },
            )?,
            AnyMap::Lattice(l) => {
                let mut v: Value = serde_json::from_str(&l.to_json()?).map_err(MapError::json)?;
                if let Value::Object(o) = &mut v {
                    o.remove("version");
                }
                v
            }
            AnyMap::AffineMls(m) => {
                mls_json(MlsMethod::Affine, m.weighting(), m.sources(), m.targets())?
            }
            AnyMap::SimilarityMls(m) => mls_json(
                MlsMethod::Similarity,
                m.weighting(),
                m.sources(),
                m.targets(),
            )?,
            AnyMap::RigidMls(m) => {
                mls_json(MlsMethod::Rigid, m.weighting(), m.sources(), m.targets())?
            }
            AnyMap::FrameMls(m) => tagged(
                "frame-mls",
                FrameMlsJson {
                    beta: m.beta(),
                    weighting: m.weighting().into(),
                    sources: m.sources().iter().map(frame_json).collect(),
                    targets: m.targets().iter().map(frame_json).collect(),
                },
            )?,
            AnyMap::ThinPlate(m) => tagged(
                "thin-plate",
                ThinPlateJson {
                    smoothing: m.system().smoothing(),
                    kernel: m.kernel().name().to_owned(),
                    sources: points(m.sources()),
                    targets: points(m.targets()),
                },
            )?,
            AnyMap::Wendland(m) => tagged(
                "wendland",
                WendlandJson {
                    support: m.support(),
                    smoothing: m.smoothing(),
                    sources: points(m.sources()),
                    targets: points(m.targets()),
                },
            )?,
            AnyMap::Bump(b) => tagged(
                "bump",
                BumpJson {
                    center: b.center().to_array(),
                    inner: b.inner(),
                    outer: b.outer(),
                    matrix: rows(b.transform().matrix),
                    offset: b.transform().offset.to_array(),
                },
            )?,
            AnyMap::Geometry(g) => {
                let aggregate = volmorph_trivariate::AggregateVolume::new(g.geometry().clone())
                    .map_err(|e| MapError::Invalid(e.to_string()))?;
                let model: Value = serde_json::from_str(
                    &volmorph_trivariate::format::to_json_string(&aggregate)
                        .map_err(|e| MapError::Invalid(e.to_string()))?,
                )
                .map_err(MapError::json)?;
                let (lo, hi) = g.placement();
                json!({
                    "kind": "nurbs-geometry",
                    "model": model,
                    "box": BoxJson { min: lo.to_array(), max: hi.to_array() },
                })
            }
            AnyMap::Sampled(s) => {
                let g = s.grid();
                tagged(
                    "sampled",
                    json!({
                        "grid": GridJson::from(g),
                        "positions": points(s.positions()),
                    }),
                )?
            }
            AnyMap::DisplacementField(f) => tagged(
                "displacement-field",
                json!({
                    "grid": GridJson::from(f.grid()),
                    "displacements": points(f.displacements()),
                }),
            )?,
            AnyMap::Compose(ms) => json!({
                "kind": "compose",
                "maps": ms.iter().map(AnyMap::to_json_value).collect::<Result<Vec<_>, _>>()?,
            }),
            AnyMap::Inverse(i) => {
                let o = i.options();
                json!({
                    "kind": "inverse",
                    "map": i.map().to_json_value()?,
                    "tolerance": o.tolerance,
                    "max_iterations": o.max_iterations,
                })
            }
            AnyMap::Refined(r) => json!({
                "kind": "refined",
                "base": r.base.to_json_value()?,
                "correction": AnyMap::Lattice(r.correction.clone()).to_json_value()?,
            }),
        })
    }

    /// The map as a JSON document (`"version"` and `"kind"` first), pretty-printed.
    ///
    /// # Errors
    /// As [`to_json_value`](Self::to_json_value).
    pub fn to_json(&self) -> Result<String, MapError> {
        let v = self.to_json_value()?;
        let mut doc = serde_json::Map::new();
        doc.insert("version".into(), json!(MAP_JSON_VERSION));
        if let Value::Object(o) = v {
            for (k, v) in o {
                doc.insert(k, v);
            }
        }
        serde_json::to_string_pretty(&Value::Object(doc)).map_err(MapError::json)
    }

    /// Read a map from a JSON document in the documented [format](self), validating
    /// everything (each kind's constructor checks its handles, control points and options).
    ///
    /// # Errors
    /// [`MapError::Json`] for malformed JSON or fields of the wrong shape (the message names
    /// the field), [`MapError::Invalid`] for another version, an unknown kind or nesting beyond
    /// [`MAX_NESTING`], [`MapError::Deform`] / [`MapError::Invalid`] for values a map refuses.
    pub fn from_json(text: &str) -> Result<Self, MapError> {
        let v: Value = serde_json::from_str(text).map_err(MapError::json)?;
        match v.get("version") {
            Some(Value::Number(n)) if n.as_u64() == Some(MAP_JSON_VERSION) => {}
            Some(other) => {
                return Err(MapError::Invalid(format!(
                    "version {other} is not supported (expected {MAP_JSON_VERSION})"
                )));
            }
            None => {
                return Err(MapError::Invalid(format!(
                    "missing \"version\" (expected {MAP_JSON_VERSION})"
                )));
            }
        }
        Self::from_json_value(&v, 0)
    }

    /// Read a map from a JSON value (nested form: `version` optional).
    ///
    /// # Errors
    /// As [`from_json`](Self::from_json).
    pub fn from_json_value(v: &Value, depth: usize) -> Result<Self, MapError> {
        if depth > MAX_NESTING {
            return Err(MapError::Invalid(format!(
                "maps nested deeper than {MAX_NESTING} levels"
            )));
        }
        let Some(obj) = v.as_object() else {
            return Err(MapError::Invalid("a map must be a JSON object".into()));
        };
        let kind = obj
            .get("kind")
            .and_then(Value::as_str)
            .ok_or_else(|| MapError::Invalid("missing \"kind\" (a string)".into()))?;
        // The body without `kind` and `version`, for the kinds with a fixed shape.
        let body = || {
            let mut o = obj.clone();
            o.remove("kind");
            o.remove("version");
            Value::Object(o)
        };
        let parse =
            |what: &'static str| move |e: serde_json::Error| MapError::Json(format!("{what}: {e}"));
        Ok(match kind {
            "identity" => {
                if obj.keys().any(|k| k != "kind" && k != "version") {
                    return Err(MapError::Invalid("an identity map has no fields".into()));
                }
                AnyMap::Identity
            }
            "affine" => {
                let a: AffineJson = serde_json::from_value(body()).map_err(parse("affine"))?;
                let matrix = from_rows(a.matrix);
                let offset = DVec3::from_array(a.offset);
                if !(matrix.is_finite() && offset.is_finite()) {
                    return Err(MapError::Invalid("affine map is not finite".into()));
                }
                AnyMap::Affine(Affine { matrix, offset })
            }
            volmorph_lattice::json::LATTICE_JSON_KIND => {
                let mut o = obj.clone();
                o.insert(
                    "version".into(),
                    json!(volmorph_lattice::json::LATTICE_JSON_VERSION),
                );
                let text = serde_json::to_string(&Value::Object(o)).map_err(MapError::json)?;
                AnyMap::Lattice(BSplineLattice::from_json(&text)?)
            }
            "mls" => {
                let m: MlsJson = serde_json::from_value(body()).map_err(parse("mls"))?;
                let (s, t, w) = (vecs(&m.sources), vecs(&m.targets), m.weighting.into());
                match m.method {
                    MlsMethod::Affine => AnyMap::AffineMls(AffineMls::new(&s, &t, w)?),
                    MlsMethod::Similarity => AnyMap::SimilarityMls(SimilarityMls::new(&s, &t, w)?),
                    MlsMethod::Rigid => AnyMap::RigidMls(RigidMls::new(&s, &t, w)?),
                }
            }
            "frame-mls" => {
                let m: FrameMlsJson = serde_json::from_value(body()).map_err(parse("frame-mls"))?;
                let s: Vec<Frame> = m.sources.iter().map(frame_of).collect();
                let t: Vec<Frame> = m.targets.iter().map(frame_of).collect();
                AnyMap::FrameMls(FrameMls::new(&s, &t, m.beta, m.weighting.into())?)
            }
            "thin-plate" => {
                let m: ThinPlateJson =
                    serde_json::from_value(body()).map_err(parse("thin-plate"))?;
                AnyMap::ThinPlate(ThinPlateMap::with_kernel(
                    &vecs(&m.sources),
                    &vecs(&m.targets),
                    m.smoothing,
                    TpsKernel::parse(&m.kernel)?,
                )?)
            }
            "wendland" => {
                let m: WendlandJson = serde_json::from_value(body()).map_err(parse("wendland"))?;
                AnyMap::Wendland(WendlandMap::with_support(
                    &vecs(&m.sources),
                    &vecs(&m.targets),
                    Some(m.support),
                    m.smoothing,
                    &volmorph_io::NoProgress,
                )?)
            }
            "bump" => {
                let b: BumpJson = serde_json::from_value(body()).map_err(parse("bump"))?;
                AnyMap::Bump(BumpMap::new(
                    DVec3::from_array(b.center),
                    b.inner,
                    b.outer,
                    Affine {
                        matrix: from_rows(b.matrix),
                        offset: DVec3::from_array(b.offset),
                    },
                )?)
            }
            "nurbs-geometry" => {
                let model = obj
                    .get("model")
                    .ok_or_else(|| MapError::Invalid("nurbs-geometry: missing \"model\"".into()))?;
                let b: BoxJson =
                    serde_json::from_value(obj.get("box").cloned().ok_or_else(|| {
                        MapError::Invalid("nurbs-geometry: missing \"box\"".into())
                    })?)
                    .map_err(parse("nurbs-geometry box"))?;
                let text = serde_json::to_string(model).map_err(MapError::json)?;
                let AnyAggregate::Volume(v) = volmorph_trivariate::format::from_json_str(&text)
                    .map_err(|e| MapError::Invalid(format!("nurbs-geometry model: {e}")))?
                else {
                    return Err(MapError::Invalid(
                        "nurbs-geometry model must be a volume (trivariate)".into(),
                    ));
                };
                AnyMap::Geometry(
                    GeometryMap::new(
                        v.geometry().clone(),
                        DVec3::from_array(b.min),
                        DVec3::from_array(b.max),
                    )
                    .map_err(|e| MapError::Invalid(format!("nurbs-geometry: {e}")))?,
                )
            }
            "sampled" => {
                #[derive(Deserialize)]
                #[serde(deny_unknown_fields)]
                struct SampledJson {
                    grid: GridJson,
                    positions: Vec<[f64; 3]>,
                }
                let s: SampledJson = serde_json::from_value(body()).map_err(parse("sampled"))?;
                // The one rule for directions entering volmorph (a sampled grid may
                // legitimately be skewed, so a skewed matrix is kept).
                let grid = s.grid.geometry();
                AnyMap::Sampled(SampledMap::from_positions(grid, vecs(&s.positions))?)
            }
            "displacement-field" => {
                #[derive(Deserialize)]
                #[serde(deny_unknown_fields)]
                struct FieldJson {
                    grid: GridJson,
                    displacements: Vec<[f64; 3]>,
                }
                let f: FieldJson =
                    serde_json::from_value(body()).map_err(parse("displacement-field"))?;
                AnyMap::DisplacementField(crate::field::DisplacementField::new(
                    f.grid.geometry(),
                    vecs(&f.displacements),
                )?)
            }
            "compose" => {
                let maps = obj.get("maps").and_then(Value::as_array).ok_or_else(|| {
                    MapError::Invalid("compose: missing \"maps\" (a list)".into())
                })?;
                AnyMap::Compose(
                    maps.iter()
                        .map(|m| Self::from_json_value(m, depth + 1))
                        .collect::<Result<_, _>>()?,
                )
            }
            "inverse" => {
                let inner = obj
                    .get("map")
                    .ok_or_else(|| MapError::Invalid("inverse: missing \"map\"".into()))?;
                let mut options = InverseOptions::default();
                match obj.get("tolerance") {
                    None | Some(Value::Null) => {}
                    Some(t) => {
                        let t = t
                            .as_f64()
                            .filter(|t| t.is_finite() && *t >= 0.0)
                            .ok_or_else(|| {
                                MapError::Invalid(
                                    "inverse: \"tolerance\" must be a number ≥ 0".into(),
                                )
                            })?;
                        options.tolerance = Some(t);
                    }
                }
                if let Some(n) = obj.get("max_iterations") {
                    options.max_iterations = n
                        .as_u64()
                        .and_then(|n| u32::try_from(n).ok())
                        .filter(|&n| n > 0)
                        .ok_or_else(|| {
                            MapError::Invalid(
                                "inverse: \"max_iterations\" must be a positive integer".into(),
                            )
                        })?;
                }
                AnyMap::Inverse(Box::new(Inverse::new(
                    Self::from_json_value(inner, depth + 1)?,
                    options,
                )))
            }
            "refined" => {
                if let Some(k) = obj
                    .keys()
                    .find(|k| !["kind", "version", "base", "correction"].contains(&k.as_str()))
                {
                    return Err(MapError::Invalid(format!("refined: unknown field {k:?}")));
                }
                let field = |name: &str| {
                    obj.get(name)
                        .ok_or_else(|| MapError::Invalid(format!("refined: missing \"{name}\"")))
                };
                let base = Self::from_json_value(field("base")?, depth + 1)?;
                let AnyMap::Lattice(correction) =
                    Self::from_json_value(field("correction")?, depth + 1)?
                else {
                    return Err(MapError::Invalid(
                        "refined: \"correction\" must be a bspline-lattice map".into(),
                    ));
                };
                AnyMap::Refined(Box::new(crate::Refined { base, correction }))
            }
            other => {
                return Err(MapError::Invalid(format!(
                    "unknown map kind {other:?} (known: identity, affine, bspline-lattice, mls, \
                     frame-mls, thin-plate, wendland, bump, nurbs-geometry, sampled, displacement-field, compose, \
                     inverse, refined)"
                )));
            }
        })
    }
}

fn mls_json(
    method: MlsMethod,
    w: Weighting,
    sources: &[DVec3],
    targets: &[DVec3],
) -> Result<Value, MapError> {
    tagged(
        "mls",
        MlsJson {
            method,
            weighting: w.into(),
            sources: points(sources),
            targets: points(targets),
        },
    )
}
