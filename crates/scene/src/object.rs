//! The objects a scene holds.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::{Arc, OnceLock};

use volmorph_frep::{CompileOptions, Shape};
use volmorph_handles::HandleSet;
use volmorph_maps::{AnyMap, HandleDirection, HandleMethod, HandleOptions, handle_map};
use volmorph_mesh::Mesh;
use volmorph_sculpt::SculptDocument;
use volmorph_trivariate::AggregateVolume;
use volmorph_volume::AnyVolume;

use crate::SceneError;
use crate::derived::Derived;

/// A stable object id: never reused within a scene, kept by project files.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub struct ObjectId(pub u64);

impl fmt::Display for ObjectId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "#{}", self.0)
    }
}

/// An F-rep model: HyperFun source text and the values of its parameter array, compiled.
#[derive(Debug, Clone)]
pub struct FrepModel {
    source: String,
    params: BTreeMap<usize, f64>,
    shape: Shape,
}

impl FrepModel {
    /// Compile `source` with parameters `params` (`a[k]` by 1-based `k`; missing ones are 0).
    ///
    /// # Errors
    /// [`SceneError::Frep`] with the line and column of a syntax or compile error.
    pub fn new(source: &str, params: BTreeMap<usize, f64>) -> Result<Self, SceneError> {
        let options = CompileOptions {
            params: params.iter().map(|(k, v)| (*k, *v)).collect(),
            ..CompileOptions::default()
        };
        let shape = volmorph_frep::compile_source(source, &options)?;
        Ok(Self {
            source: source.to_owned(),
            params,
            shape,
        })
    }

    /// The source text.
    #[must_use]
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The parameter values.
    #[must_use]
    pub fn params(&self) -> &BTreeMap<usize, f64> {
        &self.params
    }

    /// The compiled shape (solid where `f ≥ 0`).
    #[must_use]
    pub fn shape(&self) -> &Shape {
        &self.shape
    }
}

/// A map built from handles: the set, the method and its options. The map itself (sources go
/// to targets) is rebuilt when any of them changes.
#[derive(Debug, Clone)]
pub struct HandleMap {
    set: HandleSet,
    method: HandleMethod,
    options: HandleOptions,
    forward: AnyMap,
}

impl HandleMap {
    /// Build the map of `set` by `method`.
    ///
    /// # Errors
    /// The map's construction errors (too few, coincident or coplanar handles, …).
    pub fn new(
        set: HandleSet,
        method: HandleMethod,
        options: HandleOptions,
    ) -> Result<Self, SceneError> {
        set.validate()?;
        let forward = handle_map(&set, method, &options, HandleDirection::SourcesToTargets)?;
        Ok(Self {
            set,
            method,
            options,
            forward,
        })
    }

    /// The handles.
    #[must_use]
    pub fn set(&self) -> &HandleSet {
        &self.set
    }

    /// The method.
    #[must_use]
    pub fn method(&self) -> HandleMethod {
        self.method
    }

    /// The options.
    #[must_use]
    pub fn options(&self) -> &HandleOptions {
        &self.options
    }

    /// The map sending sources to targets.
    #[must_use]
    pub fn forward(&self) -> &AnyMap {
        &self.forward
    }

    /// The map sending targets to sources (the pull-back that shows each source's content at
    /// its target).
    ///
    /// # Errors
    /// As [`HandleMap::new`].
    pub fn backward(&self) -> Result<AnyMap, SceneError> {
        Ok(handle_map(
            &self.set,
            self.method,
            &self.options,
            HandleDirection::TargetsToSources,
        )?)
    }
}

/// A map object: given whole, or built from handles.
// A scene holds a handful of objects in an ordered map; a few hundred bytes per entry
// cost nothing, while boxing would add an indirection to every map evaluation.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum MapObject {
    /// A map given whole: a lattice, an affine map, a NURBS geometry, a composition, …
    Fixed(AnyMap),
    /// A map built from handles (MLS, frames, thin-plate splines).
    Handles(HandleMap),
}

impl MapObject {
    /// The map (for handles: sources to targets).
    #[must_use]
    pub fn map(&self) -> &AnyMap {
        match self {
            MapObject::Fixed(m) => m,
            MapObject::Handles(h) => h.forward(),
        }
    }
}

/// A mesh being sculpted (McPhail ch. 3): its [`SculptDocument`] (tri-dexel on a fixed grid,
/// mesh storage) and the current mesh, collected when first asked for after an edit.
#[derive(Debug, Clone)]
pub struct SculptObject {
    document: SculptDocument,
    mesh: OnceLock<Option<Arc<Mesh>>>,
}

impl SculptObject {
    /// Wrap a sculpting document.
    #[must_use]
    pub fn new(document: SculptDocument) -> Self {
        Self {
            document,
            mesh: OnceLock::new(),
        }
    }

    /// The document.
    #[must_use]
    pub fn document(&self) -> &SculptDocument {
        &self.document
    }

    /// The document for an edit; the collected mesh is dropped (it is collected again on
    /// the next [`SculptObject::mesh`]).
    pub(crate) fn document_mut(&mut self) -> &mut SculptDocument {
        self.mesh = OnceLock::new();
        &mut self.document
    }

    /// The current mesh (the document's living triangles, storage order), collected once per
    /// edit; `None` only if it exceeds 32-bit indices.
    #[must_use]
    pub fn mesh(&self) -> Option<&Arc<Mesh>> {
        self.mesh
            .get_or_init(|| self.document.mesh().ok().map(Arc::new))
            .as_ref()
    }
}

/// Everything a scene holds.
// Same reasoning as for `MapObject`: few entries, no boxing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum Object {
    /// A sampled volume (any voxel type) with its geometry.
    Volume(Arc<AnyVolume>),
    /// A polygon mesh.
    Mesh(Arc<Mesh>),
    /// An F-rep model.
    Frep(FrepModel),
    /// A trivariate NURBS volume with attributes.
    Nurbs(Arc<AggregateVolume>),
    /// A space map.
    Map(MapObject),
    /// A result computed from other objects, kept up to date.
    Derived(Derived),
    /// A mesh being sculpted.
    Sculpt(SculptObject),
}

impl Object {
    /// The kind's name (`volume`, `mesh`, `frep`, `nurbs`, `map`, `derived`, `sculpt`).
    #[must_use]
    pub fn kind(&self) -> &'static str {
        match self {
            Object::Volume(_) => "volume",
            Object::Mesh(_) => "mesh",
            Object::Frep(_) => "frep",
            Object::Nurbs(_) => "nurbs",
            Object::Map(_) => "map",
            Object::Derived(_) => "derived",
            Object::Sculpt(_) => "sculpt",
        }
    }

    /// A one-line description for listings (`volume 128×128×128 u8`, `mesh 2562 vertices,
    /// 5120 faces`, `map bspline-lattice`, `derived warp of 1 and 2: volume …`): the kind,
    /// then what defines its size.
    #[must_use]
    pub fn describe(&self) -> String {
        fn volume(v: &AnyVolume) -> String {
            let [x, y, z] = v.geometry().dims;
            format!("volume {x}×{y}×{z} {}", v.voxel_type())
        }
        fn mesh(m: &Mesh) -> String {
            format!(
                "mesh {} vertices, {} faces",
                m.vertex_count(),
                m.face_count()
            )
        }
        match self {
            Object::Volume(v) => volume(v),
            Object::Mesh(m) => mesh(m),
            Object::Frep(f) => format!(
                "frep model, {} lines, {} parameters set",
                f.source().lines().count(),
                f.params().len()
            ),
            Object::Nurbs(n) => format!("nurbs volume, {} attributes", n.attributes().len()),
            Object::Map(MapObject::Fixed(m)) => format!("map {}", m.kind()),
            Object::Map(MapObject::Handles(h)) => format!(
                "map from {} handles ({:?})",
                h.set().points.len(),
                h.method()
            ),
            Object::Derived(d) => {
                let r = d.recipe();
                let ids = r.inputs();
                let mut inputs = ids.iter().map(|i| i.0.to_string());
                let mut text = format!(
                    "derived {} of {}",
                    r.name(),
                    inputs.next().unwrap_or_default()
                );
                for i in inputs {
                    text.push_str(" and ");
                    text.push_str(&i);
                }
                match (d.volume(), d.mesh()) {
                    (Some(v), _) => text.push_str(&format!(": {}", volume(v))),
                    (_, Some(m)) => text.push_str(&format!(": {}", mesh(m))),
                    _ => text.push_str(": not computed"),
                }
                if let Some(e) = d.error() {
                    text.push_str(&format!(" (last update failed: {e})"));
                }
                text
            }
            Object::Sculpt(s) => match s.mesh() {
                Some(m) => format!("sculpt {}", mesh(m)),
                None => "sculpt (mesh beyond 32-bit indices)".into(),
            },
        }
    }

    /// The volume this object is or holds (a volume, or a derived volume once computed).
    #[must_use]
    pub fn volume(&self) -> Option<&Arc<AnyVolume>> {
        match self {
            Object::Volume(v) => Some(v),
            Object::Derived(d) => d.volume(),
            _ => None,
        }
    }

    /// The mesh this object is or holds (a mesh, a derived mesh once computed, or the
    /// current mesh of a sculpting document).
    #[must_use]
    pub fn mesh(&self) -> Option<&Arc<Mesh>> {
        match self {
            Object::Mesh(m) => Some(m),
            Object::Derived(d) => d.mesh(),
            Object::Sculpt(s) => s.mesh(),
            _ => None,
        }
    }
}

/// A named object.
#[derive(Debug, Clone)]
pub struct Entry {
    /// The user's name for it.
    pub name: String,
    /// The object.
    pub object: Object,
}
