//! volmorph-scene: the document every front-end drives.
//!
//! A [`Scene`] holds named objects by stable [`ObjectId`]: volumes of any voxel type, meshes,
//! F-rep models, trivariate NURBS models, maps (given whole — lattices, affine maps, NURBS
//! geometry, compositions — or built from handles), and derived objects that know what they
//! are computed from ([`Recipe`]: warped volumes, deformed meshes, isosurfaces, Jacobian maps,
//! sampled F-rep models and their metamorphoses, the lobe labels of a lung model traced from a
//! script of fissure points).
//!
//! * Every change is a [`Command`] applied through [`Scene::apply`]; it goes into an undo/redo
//!   history ([`Scene::undo`], [`Scene::redo`]) and returns a [`Change`]: the objects added,
//!   removed and modified, and per changed derived object the dirty region as a voxel box and a
//!   physical box ([`Dirty`]), so a viewer redraws only that.
//! * Meshes can be sculpted ([`NewObject::Sculpt`], [`Command::Sculpt`]): Booleans with tool
//!   meshes, painting strokes and smoothing on a tri-dexel, re-contoured only around each
//!   edit, undone and redone exactly from the edit's record.
//! * Derived objects follow their inputs through the engines' incremental paths: a drag or a
//!   control-point move of a lattice (or a target move of affine/frame MLS or a thin-plate
//!   spline) updates an antialiased push-forward only where the moved parameters act, and a
//!   deformed mesh only in the vertices there; everything else is recomputed in full. Both give
//!   the result a full recomputation gives (to the rounding the engines document).
//! * Long work reports to a [`volmorph_io::Progress`] and stops when it is cancelled:
//!   [`Scene::apply_with`], [`Scene::undo_with`], [`Scene::redo_with`], [`Scene::export_with`],
//!   [`Scene::save_with`], [`Scene::load_with`], [`files::read_object_with`]. A cancelled
//!   command changes nothing: the derived objects it had updated are put back from what each
//!   update replaced, its edits are undone, and the histories and next id are as before.
//!   [`Scene::transaction`] makes several commands one undo step, or nothing.
//! * [`Scene::save`] / [`Scene::load`] write and read a versioned project file ([`project`]);
//!   [`Scene::export`] writes any object in any format volmorph writes; [`files::read_object`]
//!   reads any file volmorph reads as a new object.
//! * [`setup::Setup`] runs a built-in workflow (a phantom, True's direct manipulation,
//!   McPhail's handles, sculpting, registration and lung model, Feng's mesh FFD) as one undo
//!   step; the studio's set-up messages and `volmorph project new` both run it.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_lattice::{BSplineLattice, DragOptions};
//! use volmorph_maps::AnyMap;
//! use volmorph_scene::{Command, NewObject, Recipe, Scene};
//! use volmorph_volume::AnyVolume;
//! use volmorph_volume::phantom::{self, Phantom};
//! use volmorph_warp::apply::WarpMethod;
//!
//! let mut scene = Scene::new();
//! let vol = phantom::density(Phantom::Sphere, [24, 24, 24])?;
//! let grid = *vol.geometry();
//! let add = |name: &str, object| Command::Add { name: name.into(), object };
//! let v = scene.apply(add("sphere", NewObject::Volume(AnyVolume::from(vol))))?.added[0];
//! let lattice = BSplineLattice::identity_on_voxels(&grid, [7, 7, 7])?;
//! let l = scene.apply(add("lattice", NewObject::Map(AnyMap::Lattice(lattice))))?.added[0];
//! let w = scene
//!     .apply(add("warped", NewObject::Derived(Recipe::Warp {
//!         source: v,
//!         map: l,
//!         method: WarpMethod::PushforwardAntialiased,
//!         background: 0.0,
//!         sampled_nodes: None,
//!         swap_handles: false,
//!     })))?
//!     .added[0];
//! // Drag a point of the sphere's surface outward: only the region around it is redone.
//! let p = grid.index_to_physical(DVec3::new(18.0, 12.0, 12.0));
//! let change = scene.apply(Command::DragPoints {
//!     map: l,
//!     grabbed: vec![p],
//!     targets: vec![p + DVec3::new(0.05, 0.0, 0.0)],
//!     options: DragOptions::with_radius(0.3),
//! })?;
//! let dirty = change.dirty_of(w).unwrap().voxels.unwrap();
//! assert!(!dirty.is_empty() && dirty.len() < grid.len());
//! scene.undo()?;
//! assert_eq!(scene.redo_depth(), 1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod by_handles;
mod command;
pub mod demo;
mod derived;
mod error;
pub mod files;
mod object;
pub mod project;
mod scene;
pub mod setup;
pub mod teapot;

pub use command::{Change, Command, DragSummary, NewObject};
pub use derived::{Derived, DerivedOutput, Dirty, Recipe, SurfaceMethod};
pub use error::SceneError;
pub use object::{Entry, FrepModel, HandleMap, MapObject, Object, ObjectId, SculptObject};
pub use scene::{DEFAULT_UNDO_LIMIT, Scene};
pub use teapot::TeapotSession;
