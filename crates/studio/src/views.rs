//! What a page reads from the scene: the object list, slices, volume textures, cube-cutting
//! proxy geometry, meshes, lattice and handle overlays, transfer-function tables and probes,
//! each as a [`Frame`] (layouts in `PROTOCOL.md`). Every answer is computed by a library call
//! (`volume::slice`, `render::Window`, `render::cubecut`, `render::transfer`, the maps); this
//! module only packs it.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use glam::DVec3;
use serde_json::{Value, json};
use volmorph_maps::AnyMap;
use volmorph_render::cubecut::{CutMethod, ProxyGeometry, Slicing, cut_octree};
use volmorph_render::{Colormap, DvrVolume, TransferFunction, Window};
use volmorph_scene::{MapObject, Object, ObjectId, Scene};
use volmorph_volume::slice::{self, Axis, SlicePosition};
use volmorph_volume::{AnyVolume, Geometry};

use crate::protocol::{Frame, Kind, f32_bytes, u32_bytes};

/// A query's failure, shown to the user.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct QueryError(pub String);

impl QueryError {
    fn new(m: impl Into<String>) -> Self {
        Self(m.into())
    }
}

impl From<volmorph_scene::SceneError> for QueryError {
    fn from(e: volmorph_scene::SceneError) -> Self {
        Self(e.to_string())
    }
}

impl From<volmorph_render::RenderError> for QueryError {
    fn from(e: volmorph_render::RenderError) -> Self {
        Self(e.to_string())
    }
}

impl From<volmorph_volume::VolumeError> for QueryError {
    fn from(e: volmorph_volume::VolumeError) -> Self {
        Self(e.to_string())
    }
}

/// Most texels per axis of a volume texture sent to a page (larger volumes are decimated by
/// an integer stride; WebGL2 guarantees 256 for 3D textures).
pub const MAX_TEXTURE_AXIS: usize = 256;

/// Most planes a page may ask the proxy geometry for.
pub const MAX_PROXY_SLICES: usize = 2048;

/// Caches kept across queries: the automatic window of each volume (computed once, so the
/// display does not jump while a drag changes the volume) and the renderer's volume (its
/// min–max octree) of each volume version.
#[derive(Debug, Default)]
pub struct Caches {
    windows: Mutex<HashMap<u64, (f64, f64)>>,
    dvr: Mutex<HashMap<u64, (usize, Arc<DvrVolume>)>>,
}

fn field<'a>(h: &'a Value, name: &str) -> Result<&'a Value, QueryError> {
    h.get(name)
        .ok_or_else(|| QueryError::new(format!("message lacks field {name:?}")))
}

/// The `u64` field `name` of header `h`.
///
/// # Errors
/// When it is missing or not a non-negative integer.
pub fn u64_field(h: &Value, name: &str) -> Result<u64, QueryError> {
    field(h, name)?
        .as_u64()
        .ok_or_else(|| QueryError::new(format!("field {name:?} must be a non-negative integer")))
}

/// The `f64` field `name` of header `h` (finite).
///
/// # Errors
/// When it is missing or not a finite number.
pub fn f64_field(h: &Value, name: &str) -> Result<f64, QueryError> {
    field(h, name)?
        .as_f64()
        .filter(|v| v.is_finite())
        .ok_or_else(|| QueryError::new(format!("field {name:?} must be a finite number")))
}

/// The 3-vector field `name` of header `h` (finite).
///
/// # Errors
/// When it is missing or not three finite numbers.
pub fn vec3_field(h: &Value, name: &str) -> Result<DVec3, QueryError> {
    vec3_value(field(h, name)?)
        .ok_or_else(|| QueryError::new(format!("field {name:?} must be three finite numbers")))
}

/// The point `[x, y, z]` that `v` holds: three finite numbers, or `None`.
#[must_use]
pub fn vec3_value(v: &Value) -> Option<DVec3> {
    match v.as_array()?.as_slice() {
        [x, y, z] => {
            let p = DVec3::new(x.as_f64()?, y.as_f64()?, z.as_f64()?);
            p.is_finite().then_some(p)
        }
        _ => None,
    }
}

/// A volume's geometry as JSON: `dims`, `origin`, `spacing`, and `direction` as three
/// columns (the physical direction of the i, j and k axes). A point's physical position is
/// `origin + Σ_a direction[a] · spacing[a] · index[a]`.
#[must_use]
pub fn geometry_json(g: &Geometry) -> Value {
    json!({
        "dims": g.dims,
        "origin": g.origin.to_array(),
        "spacing": g.spacing.to_array(),
        "direction": [g.direction.x_axis.to_array(), g.direction.y_axis.to_array(), g.direction.z_axis.to_array()],
    })
}

/// The size of the model's parameter array: the second formal of the last object
/// (HyperFun's `model(x[3], a[k])`), 0 when there is none (or the source does not parse).
#[must_use]
pub fn frep_param_count(source: &str) -> usize {
    volmorph_frep::lang::parse(source)
        .ok()
        .and_then(|p| p.objects.last().and_then(|o| o.params.get(1).map(|a| a.1)))
        .unwrap_or(0)
}

fn object_json(id: ObjectId, name: &str, object: &Object) -> Value {
    let mut o = json!({"id": id.0, "name": name, "kind": object.kind()});
    if let Some(v) = object.volume() {
        o["volume"] =
            json!({"geometry": geometry_json(v.geometry()), "type": v.voxel_type().to_string()});
    }
    if let Some(m) = object.mesh() {
        o["mesh"] = json!({"vertices": m.vertex_count(), "faces": m.face_count()});
    }
    match object {
        Object::Map(MapObject::Fixed(m)) => {
            o["map"] = json!({"kind": m.kind()});
            if let AnyMap::Lattice(l) = m {
                o["map"]["counts"] = json!(l.counts());
            }
        }
        Object::Map(MapObject::Handles(h)) => {
            o["map"] = json!({"kind": "handles", "method": format!("{:?}", h.method()), "handles": h.set().points.len()});
        }
        Object::Derived(d) => {
            o["recipe"] = serde_json::to_value(d.recipe()).unwrap_or(Value::Null);
            o["error"] = json!(d.error());
        }
        Object::Frep(f) => {
            o["frep"] = json!({"source": f.source(), "params": f.params(), "paramCount": frep_param_count(f.source())});
        }
        _ => {}
    }
    o
}

/// The object list and history depths ([`Kind::Scene`]).
#[must_use]
pub fn scene_frame(scene: &Scene, request: u32) -> Frame {
    let objects: Vec<Value> = scene
        .objects()
        .map(|(id, e)| object_json(id, &e.name, &e.object))
        .collect();
    Frame::new(
        Kind::Scene,
        request,
        json!({"objects": objects, "undo": scene.undo_depth(), "redo": scene.redo_depth()}),
    )
}

/// The colour maps' tables, for the page's slice views: `{name: [[r,g,b] × 256]}`.
#[must_use]
pub fn colormaps_json() -> Value {
    let mut m = serde_json::Map::new();
    for c in Colormap::ALL {
        m.insert(c.name().to_owned(), json!(c.lut().to_vec()));
    }
    Value::Object(m)
}

fn axis_of(h: &Value) -> Result<Axis, QueryError> {
    match u64_field(h, "axis")? {
        0 => Ok(Axis::X),
        1 => Ok(Axis::Y),
        2 => Ok(Axis::Z),
        a => Err(QueryError::new(format!("axis {a} must be 0, 1 or 2"))),
    }
}

/// The plane a slice query names: header fields `axis` and `index` (a voxel plane, rounded;
/// default the middle one) checked against `g`.
fn plane_of(h: &Value, g: &Geometry) -> Result<(Axis, f64), QueryError> {
    let axis = axis_of(h)?;
    let n = g.dims[axis.index()];
    let index = match h.get("index").and_then(Value::as_f64) {
        Some(i) => i.round(),
        None => ((n - 1) / 2) as f64,
    };
    if !(0.0..n as f64).contains(&index) {
        return Err(QueryError::new(format!(
            "slice index {index} out of range 0 to {} on axis {axis}",
            n - 1
        )));
    }
    Ok((axis, index))
}

impl Caches {
    /// The automatic window of volume `id` (`render::Window::auto` on its three middle
    /// slices), computed once per volume.
    fn window(&self, id: u64, v: &AnyVolume) -> Result<(f64, f64), QueryError> {
        let mut w = self.windows.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(x) = w.get(&id) {
            return Ok(*x);
        }
        let mut values = Vec::new();
        for axis in Axis::ALL {
            let n = v.geometry().dims[axis.index()];
            let s = slice::extract(v, axis, SlicePosition::Index(((n - 1) / 2) as f64))?;
            values.extend(s.values);
        }
        let win = Window::auto(&values)?;
        let x = (win.lower(), win.upper());
        w.insert(id, x);
        Ok(x)
    }

    /// A slice ([`Kind::Slice`]): header `{volume, axis, index}` (index a voxel plane,
    /// default the middle).
    ///
    /// # Errors
    /// A missing volume, an axis or index out of range.
    pub fn slice(&self, scene: &Scene, h: &Value, request: u32) -> Result<Frame, QueryError> {
        let id = u64_field(h, "volume")?;
        let v = scene.volume(ObjectId(id))?;
        let (axis, index) = plane_of(h, v.geometry())?;
        let s = slice::extract(v, axis, SlicePosition::Index(index))?;
        let (lo, hi) = self.window(id, v)?;
        Ok(Frame::new(
            Kind::Slice,
            request,
            json!({
                "volume": id,
                "axis": axis.index(),
                "index": index,
                "width": s.width,
                "height": s.height,
                "pixelSpacing": s.pixel_spacing,
                "window": [lo, hi],
            }),
        )
        .with_payload(f32_bytes(s.values)))
    }

    fn dvr(&self, id: u64, v: &Arc<AnyVolume>) -> Result<Arc<DvrVolume>, QueryError> {
        let key = Arc::as_ptr(v) as usize;
        let mut c = self.dvr.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((k, d)) = c.get(&id)
            && *k == key
        {
            return Ok(Arc::clone(d));
        }
        let d = Arc::new(DvrVolume::new(v)?);
        c.insert(id, (key, Arc::clone(&d)));
        Ok(d)
    }

    /// Cube-cutting proxy geometry ([`Kind::Proxy`], McPhail ch. 2 sweep): header `{volume,
    /// forward, slices}`, `forward` the camera's viewing direction (world), `slices` planes
    /// across the volume. Payload: the vertices (`f32`, 6 per vertex) then the indices
    /// (`u32`); header `vertices`, `indices` give the counts.
    ///
    /// # Errors
    /// A missing volume; a zero direction; a slice count out of range.
    pub fn proxy(&self, scene: &Scene, h: &Value, request: u32) -> Result<Frame, QueryError> {
        let id = u64_field(h, "volume")?;
        let v = scene.volume(ObjectId(id))?;
        let forward = vec3_field(h, "forward")?;
        let slices = usize::try_from(u64_field(h, "slices")?).unwrap_or(usize::MAX);
        if !(1..=MAX_PROXY_SLICES).contains(&slices) {
            return Err(QueryError::new(format!(
                "slices {slices} must be 1 to {MAX_PROXY_SLICES}"
            )));
        }
        let dvr = self.dvr(id, v)?;
        let g = v.geometry();
        let (lo, hi) = (
            DVec3::splat(-0.5),
            DVec3::from_array(g.dims.map(|d| d as f64)) - 0.5,
        );
        let corners: Vec<DVec3> = (0..8)
            .map(|c| {
                g.index_to_physical(DVec3::new(
                    if c & 1 == 0 { lo.x } else { hi.x },
                    if c & 2 == 0 { lo.y } else { hi.y },
                    if c & 4 == 0 { lo.z } else { hi.z },
                ))
            })
            .collect();
        let slicing = Slicing::across(forward.normalize_or_zero(), &corners, slices)?;
        let octree = dvr.octree();
        // The coarsest level whose nodes still split the volume into at most 4 per axis.
        let level = (0..octree.level_count())
            .find(|&l| octree.level_dims(l).iter().all(|&d| d <= 4))
            .unwrap_or(octree.level_count() - 1);
        let mut out = ProxyGeometry::default();
        cut_octree(&dvr, None, level, &slicing, CutMethod::Sweep, &mut out)?;
        let mut payload = f32_bytes(out.vertices.iter().copied());
        payload.extend(u32_bytes(out.indices.iter().copied()));
        Ok(Frame::new(
            Kind::Proxy,
            request,
            json!({
                "volume": id,
                "vertices": out.vertex_count(),
                "indices": out.indices.len(),
                "polygons": out.polygons.len(),
            }),
        )
        .with_payload(payload))
    }
}

/// The Jacobian determinant of a map on one slice ([`Kind::Slice`] in answer to
/// [`Kind::GetJacobian`]): header `{map, volume, axis, index}`; the values are
/// `det Dφ(x)` of map object `map` (`φ` as the scene evaluates it: for a lattice the
/// push-forward, for a handle map sources → targets) at the voxel centres `x` of plane `index`
/// of `volume`'s grid (`volmorph_warp::jacobian::jacobian_determinant` on that plane), laid out
/// as [`Caches::slice`] lays out the volume's slice. `J ≤ 0` marks folding; the reply's
/// `folded` counts those voxels and `window` is `[0, 2]` (1: volume kept).
///
/// # Errors
/// A missing map or volume, an axis or index out of range, a map that cannot be
/// differentiated there.
pub fn jacobian_frame(scene: &Scene, h: &Value, request: u32) -> Result<Frame, QueryError> {
    let map_id = u64_field(h, "map")?;
    let map = scene.map(ObjectId(map_id))?;
    let id = u64_field(h, "volume")?;
    let g = *scene.volume(ObjectId(id))?.geometry();
    let (axis, index) = plane_of(h, &g)?;
    let a = axis.index();
    let mut plane_origin = DVec3::ZERO;
    plane_origin[a] = index;
    let mut dims = g.dims;
    dims[a] = 1;
    let plane = Geometry {
        dims,
        origin: g.index_to_physical(plane_origin),
        ..g
    };
    let det = volmorph_warp::jacobian::jacobian_determinant(map, &plane)
        .map_err(|e| QueryError::new(format!("Jacobian of map {map_id}: {e}")))?;
    let folded = det.data().iter().filter(|&&d| d <= 0.0).count();
    let s = slice::extract(&AnyVolume::from(det), axis, SlicePosition::Index(0.0))?;
    Ok(Frame::new(
        Kind::Slice,
        request,
        json!({
            "volume": id,
            "map": map_id,
            "axis": a,
            "index": index,
            "width": s.width,
            "height": s.height,
            "pixelSpacing": s.pixel_spacing,
            "window": [0.0, 2.0],
            "folded": folded,
        }),
    )
    .with_payload(f32_bytes(s.values)))
}

/// A volume as an 8-bit texture ([`Kind::VolumeData`]): header `{volume}`; reply `dims` (the
/// texture's, after decimation by `stride` to at most [`MAX_TEXTURE_AXIS`] per axis), `min`,
/// `max` (code 0 is `min`, 255 is `max`), and the geometry. Payload: `u8` codes, x fastest.
///
/// # Errors
/// A missing volume.
pub fn volume_frame(scene: &Scene, h: &Value, request: u32) -> Result<Frame, QueryError> {
    let id = u64_field(h, "volume")?;
    let v = scene.volume(ObjectId(id))?;
    let g = v.geometry();
    let f = v.to_typed::<f32>();
    let data = f.data();
    let (mut min, mut max) = (f32::INFINITY, f32::NEG_INFINITY);
    for &x in data.iter().filter(|x| x.is_finite()) {
        min = min.min(x);
        max = max.max(x);
    }
    if min > max {
        return Err(QueryError::new(format!("volume {id} has no finite value")));
    }
    let stride = g
        .dims
        .iter()
        .map(|&d| d.div_ceil(MAX_TEXTURE_AXIS))
        .max()
        .unwrap_or(1)
        .max(1);
    let dims = g.dims.map(|d| d.div_ceil(stride));
    let scale = if max > min { 255.0 / (max - min) } else { 0.0 };
    let mut out = Vec::with_capacity(dims.iter().product());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            let row = (k * stride * g.dims[1] + j * stride) * g.dims[0];
            for i in 0..dims[0] {
                let x = data[row + i * stride];
                let c = if x.is_finite() {
                    ((x - min) * scale).round()
                } else {
                    0.0
                };
                out.push(c.clamp(0.0, 255.0) as u8);
            }
        }
    }
    Ok(Frame::new(
        Kind::VolumeData,
        request,
        json!({"volume": id, "dims": dims, "stride": stride, "min": min, "max": max, "geometry": geometry_json(g)}),
    )
    .with_payload(out))
}

/// A mesh ([`Kind::MeshData`]): header `{id}`; reply `vertices`, `triangles`. Payload:
/// positions (`f32` xyz), vertex normals (`f32` xyz), then triangle indices (`u32`).
///
/// # Errors
/// A missing object or one without a mesh.
pub fn mesh_frame(scene: &Scene, h: &Value, request: u32) -> Result<Frame, QueryError> {
    let id = u64_field(h, "id")?;
    let m = scene.mesh(ObjectId(id))?;
    let normals = m.vertex_normals();
    let tris: Vec<[u32; 3]> = m.fan_triangles().collect();
    let mut payload = f32_bytes(
        m.positions()
            .iter()
            .flat_map(|p| p.to_array().map(|c| c as f32)),
    );
    payload.extend(f32_bytes(
        normals.iter().flat_map(|n| n.to_array().map(|c| c as f32)),
    ));
    payload.extend(u32_bytes(tris.iter().flatten().copied()));
    Ok(Frame::new(
        Kind::MeshData,
        request,
        json!({"id": id, "vertices": m.vertex_count(), "triangles": tris.len()}),
    )
    .with_payload(payload))
}

/// A map's overlay ([`Kind::LatticeData`]): header `{map}`. For a lattice: `kind:
/// "lattice"`, `counts`; payload the control points (`f32` xyz, x index fastest). For a
/// handle map: `kind: "handles"`, `count`; payload per handle source then target (`f32` xyz).
///
/// # Errors
/// A missing object, or a map of another kind.
pub fn overlay_frame(scene: &Scene, h: &Value, request: u32) -> Result<Frame, QueryError> {
    let id = u64_field(h, "map")?;
    let e = scene.get(ObjectId(id))?;
    let f = |p: &DVec3| p.to_array().map(|c| c as f32);
    match &e.object {
        Object::Map(MapObject::Fixed(AnyMap::Lattice(l))) => Ok(Frame::new(
            Kind::LatticeData,
            request,
            json!({"map": id, "kind": "lattice", "counts": l.counts()}),
        )
        .with_payload(f32_bytes(l.control_points().iter().flat_map(f)))),
        Object::Map(MapObject::Handles(hm)) => Ok(Frame::new(
            Kind::LatticeData,
            request,
            json!({"map": id, "kind": "handles", "count": hm.set().points.len()}),
        )
        .with_payload(f32_bytes(
            hm.set()
                .points
                .iter()
                .flat_map(|(s, t)| f(s).into_iter().chain(f(t))),
        ))),
        other => Err(QueryError::new(format!(
            "object {id} is a {}, not a lattice or handle map",
            other.kind()
        ))),
    }
}

/// Most points one [`Kind::Probe`] may map.
pub const MAX_PROBE_POINTS: usize = 1 << 16;

/// Points mapped by a map object ([`Kind::Probed`]): header `{map, point}`, reply `{map,
/// point, image}`; or header `{map, points: [[x, y, z], …]}` (at most [`MAX_PROBE_POINTS`]),
/// reply `{map, count}` with the images as payload (`f32` xyz per point, in order). The map
/// is applied as the scene evaluates it (a lattice pushes forward; a handle map sends sources
/// to targets).
///
/// # Errors
/// A missing map, a malformed or non-finite point, too many points.
pub fn probe_frame(scene: &Scene, h: &Value, request: u32) -> Result<Frame, QueryError> {
    use volmorph_deform::SpaceMap as _;
    let id = u64_field(h, "map")?;
    let m = scene.map(ObjectId(id))?;
    if let Some(list) = h.get("points") {
        let list = list
            .as_array()
            .ok_or_else(|| QueryError::new("field \"points\" must be a list of [x, y, z]"))?;
        if list.len() > MAX_PROBE_POINTS {
            return Err(QueryError::new(format!(
                "{} points: a probe maps at most {MAX_PROBE_POINTS}",
                list.len()
            )));
        }
        let mut images = Vec::with_capacity(list.len() * 3);
        for (i, p) in list.iter().enumerate() {
            let p = vec3_value(p).ok_or_else(|| {
                QueryError::new(format!("point {i} must be three finite numbers"))
            })?;
            images.extend(m.apply(p).to_array().map(|c| c as f32));
        }
        return Ok(Frame::new(
            Kind::Probed,
            request,
            json!({"map": id, "count": list.len()}),
        )
        .with_payload(f32_bytes(images)));
    }
    let p = vec3_field(h, "point")?;
    let q = m.apply(p);
    Ok(Frame::new(
        Kind::Probed,
        request,
        json!({"map": id, "point": p.to_array(), "image": q.to_array()}),
    ))
}

/// A transfer function's table ([`Kind::Transfer`]): header `{text, min, max}` with `text`
/// in `render::TransferFunction::parse` form over data values; reply 256 RGBA bytes (colour
/// in sRGB, opacity per unit length scaled to 0‥255) for codes 0‥255 spanning `[min, max]`.
///
/// # Errors
/// A malformed transfer function (the parser's message), a bad range.
pub fn transfer_frame(h: &Value, request: u32) -> Result<Frame, QueryError> {
    let text = field(h, "text")?
        .as_str()
        .ok_or_else(|| QueryError::new("field \"text\" must be a string"))?;
    let (min, max) = (f64_field(h, "min")?, f64_field(h, "max")?);
    let tf = TransferFunction::parse(text)?;
    let mut lut = Vec::with_capacity(256 * 4);
    for c in 0..256 {
        let v = min + (max - min) * f64::from(c) / 255.0;
        let col = tf.color_at(v);
        let a = tf.opacity_at(v);
        lut.extend(col.map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8));
        lut.push((a.clamp(0.0, 1.0) * 255.0).round() as u8);
    }
    Ok(Frame::new(Kind::Transfer, request, json!({"text": text})).with_payload(lut))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frep_param_count_is_the_last_objects_parameter_array() {
        assert_eq!(
            frep_param_count("m(x[3], a[2]) { m = a[1] - x[1]*x[1] + 0*a[2]; }"),
            2
        );
        assert_eq!(
            frep_param_count("h(x[3], b[1]) { h = b[1]; }\nm(x[3], a[3]) { m = a[1] - x[2]; }"),
            3
        );
        assert_eq!(frep_param_count("m(x[3]) { m = 1 - x[1]; }"), 0);
        assert_eq!(frep_param_count("m(x[3], a[1]) { m = ; }"), 0);
    }
}
