//! The commands that change a scene, and the report of what each changed.

use std::collections::BTreeMap;

use glam::DVec3;
use volmorph_handles::HandleSet;
use volmorph_lattice::DragOptions;
use volmorph_maps::{AnyMap, HandleMethod, HandleOptions};
use volmorph_mesh::Mesh;
use volmorph_trivariate::AggregateVolume;
use volmorph_volume::AnyVolume;

use crate::ObjectId;
use crate::derived::{Dirty, Recipe};

/// The data of an object to add or to put in place of another.
#[derive(Debug, Clone)]
pub enum NewObject {
    /// A sampled volume.
    Volume(AnyVolume),
    /// A polygon mesh.
    Mesh(Mesh),
    /// An F-rep model: HyperFun source and parameter values (`a[k]` by 1-based `k`).
    Frep {
        /// The source text.
        source: String,
        /// Parameter values.
        params: BTreeMap<usize, f64>,
    },
    /// A trivariate NURBS volume with attributes.
    Nurbs(AggregateVolume),
    /// A map given whole.
    Map(AnyMap),
    /// A map built from handles.
    Handles {
        /// The handles.
        set: HandleSet,
        /// The method.
        method: HandleMethod,
        /// Its options.
        options: HandleOptions,
    },
    /// A result computed from other objects.
    Derived(Recipe),
}

/// A change to a scene. Every command is applied through [`Scene::apply`](crate::Scene::apply),
/// goes into the undo history, and reports what it changed ([`Change`]).
#[derive(Debug, Clone)]
pub enum Command {
    /// Add an object under `name`.
    Add {
        /// Its name (need not be unique).
        name: String,
        /// Its data.
        object: NewObject,
    },
    /// Remove an object no derived object uses.
    Remove {
        /// The object.
        id: ObjectId,
    },
    /// Rename an object.
    Rename {
        /// The object.
        id: ObjectId,
        /// The new name.
        name: String,
    },
    /// Put new data in place of an object, keeping its id and name (an object other objects use
    /// must keep its kind).
    Replace {
        /// The object.
        id: ObjectId,
        /// The new data.
        object: NewObject,
    },
    /// Direct manipulation (True 1992 §6): points grabbed on the model **as deformed** by the
    /// lattice map `map` go exactly to `targets`, by the least-norm moves of the control points
    /// within the tool radius. Derived objects follow incrementally.
    DragPoints {
        /// A map object holding a B-spline lattice.
        map: ObjectId,
        /// The grabbed points (physical, deformed space).
        grabbed: Vec<DVec3>,
        /// Where each must go.
        targets: Vec<DVec3>,
        /// Tool radius and frozen boundary.
        options: DragOptions,
    },
    /// Set parameters of a map linear in them (control points of a lattice, targets of affine
    /// or frame MLS or a thin-plate spline; for a handle map, point-handle targets):
    /// `(parameter, new value)` pairs, physical units.
    SetParameters {
        /// The map object.
        map: ObjectId,
        /// The changes.
        changes: Vec<(usize, DVec3)>,
    },
    /// Add a point handle to a handle map.
    AddHandle {
        /// The handle map.
        map: ObjectId,
        /// Where the handle is picked (physical).
        source: DVec3,
        /// Where it must go.
        target: DVec3,
    },
    /// Move a point handle of a handle map (both ends).
    MoveHandle {
        /// The handle map.
        map: ObjectId,
        /// The handle's index among the point handles.
        index: usize,
        /// Its new source.
        source: DVec3,
        /// Its new target.
        target: DVec3,
    },
    /// Delete a point handle of a handle map.
    DeleteHandle {
        /// The handle map.
        map: ObjectId,
        /// The handle's index among the point handles.
        index: usize,
    },
    /// Change the method or options of a handle map.
    SetHandleMethod {
        /// The handle map.
        map: ObjectId,
        /// The new method.
        method: HandleMethod,
        /// The new options.
        options: HandleOptions,
    },
    /// Change the recipe of a derived object (a warp method, an iso level, …).
    SetRecipe {
        /// The derived object.
        id: ObjectId,
        /// The new recipe.
        recipe: Recipe,
    },
}

/// What a command (or an undo or redo) changed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Change {
    /// Objects added (for [`Command::Add`]: the new object first).
    pub added: Vec<ObjectId>,
    /// Objects removed.
    pub removed: Vec<ObjectId>,
    /// Objects whose data changed (edited objects, then the derived objects that followed).
    pub modified: Vec<ObjectId>,
    /// Per changed derived object: the voxels (volumes) and physical box that may have
    /// changed, so a viewer redraws only those.
    pub dirty: Vec<Dirty>,
    /// Derived objects whose update failed, with the message (their previous result is kept).
    pub errors: Vec<(ObjectId, String)>,
    /// For [`Command::DragPoints`]: how the drag was solved.
    pub drag: Option<DragSummary>,
}

/// How a drag was solved (see `volmorph_lattice::manipulate`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DragSummary {
    /// Control points moved.
    pub moved: usize,
    /// Rank of the drag system; below [`drags`](Self::drags) the drags conflict and are met in
    /// the least-squares sense.
    pub rank: usize,
    /// Number of drags.
    pub drags: usize,
    /// Largest distance by which a dragged point misses its target (physical units).
    pub max_residual: f64,
}

impl Change {
    /// The dirty report of `id`, if it changed.
    #[must_use]
    pub fn dirty_of(&self, id: ObjectId) -> Option<&Dirty> {
        self.dirty.iter().find(|d| d.object == id)
    }
}
