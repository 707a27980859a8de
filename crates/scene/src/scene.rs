//! [`Scene`]: the objects by id, the one entry point for changes, undo and redo.

use std::collections::BTreeMap;
use std::sync::Arc;

use glam::DVec3;
use volmorph_deform::LinearMap;
use volmorph_lattice::{drags_from_deformed, solve_drags};
use volmorph_maps::AnyMap;
use volmorph_mesh::Mesh;
use volmorph_volume::{AnyVolume, IndexBox};

use crate::SceneError;
use crate::command::{Change, Command, NewObject};
use crate::derived::Dirty;
use crate::derived::{Derived, Hint, Inputs, Restore};
use crate::object::{Entry, FrepModel, HandleMap, MapObject, Object, ObjectId, SculptObject};

/// Default number of commands [`Scene::undo`] can take back.
pub const DEFAULT_UNDO_LIMIT: usize = 256;

/// One primitive, reversible change; a command is a list of them.
#[derive(Debug, Clone)]
pub(crate) enum Edit {
    /// Put `entry` under the new id `id`.
    Insert { id: ObjectId, entry: Box<Entry> },
    /// Remove object `id`.
    Remove { id: ObjectId },
    /// Replace the whole entry of `id`.
    Replace { id: ObjectId, entry: Box<Entry> },
    /// Set parameters of the map `id`.
    Parameters {
        id: ObjectId,
        changes: Vec<(usize, DVec3)>,
    },
    /// Sculpt the sculpt object `id`.
    Sculpt { id: ObjectId, step: SculptStep },
}

/// One step of a sculpt object's history.
#[derive(Debug, Clone)]
pub(crate) enum SculptStep {
    /// Perform an edit (inverse: undo its record).
    Apply(volmorph_sculpt::Edit),
    /// Take a record back (inverse: redo it).
    Undo(Arc<volmorph_sculpt::EditRecord>),
    /// Perform a record again (inverse: undo it).
    Redo(Arc<volmorph_sculpt::EditRecord>),
}

/// A command as applied: its edits and the edits that take it back.
#[derive(Debug, Clone)]
struct Record {
    forward: Vec<Edit>,
    inverse: Vec<Edit>,
}

/// How an object changed, for its dependents.
#[derive(Debug, Clone)]
enum Effect {
    Parameters(Vec<(usize, DVec3)>),
    Region(IndexBox),
    Full,
}

/// The volmorph document: objects by id, changed only through [`Scene::apply`] (and
/// [`Scene::undo`] / [`Scene::redo`]), each change reported as a [`Change`]. Derived objects
/// follow their inputs: incrementally where an engine allows (a parameter move of a lattice or
/// a linear handle map re-does only its influence), in full otherwise.
#[derive(Debug, Default)]
pub struct Scene {
    objects: BTreeMap<ObjectId, Entry>,
    next_id: u64,
    undo: Vec<Record>,
    redo: Vec<Record>,
    undo_limit: usize,
    /// The summary of the drag being planned, handed to the command's [`Change`].
    pending_drag: Option<crate::command::DragSummary>,
}

impl Scene {
    /// An empty scene.
    #[must_use]
    pub fn new() -> Self {
        Self {
            undo_limit: DEFAULT_UNDO_LIMIT,
            ..Self::default()
        }
    }

    /// The object `id`.
    ///
    /// # Errors
    /// [`SceneError::NoObject`].
    pub fn get(&self, id: ObjectId) -> Result<&Entry, SceneError> {
        self.objects.get(&id).ok_or(SceneError::NoObject(id))
    }

    /// Every object, by id.
    pub fn objects(&self) -> impl Iterator<Item = (ObjectId, &Entry)> {
        self.objects.iter().map(|(id, e)| (*id, e))
    }

    /// The first object named `name`.
    #[must_use]
    pub fn find(&self, name: &str) -> Option<ObjectId> {
        self.objects
            .iter()
            .find(|(_, e)| e.name == name)
            .map(|(id, _)| *id)
    }

    /// The volume object `id` is or holds (a volume, or a derived volume once computed).
    ///
    /// # Errors
    /// [`SceneError::NoObject`]; [`SceneError::WrongKind`] when it holds no volume.
    pub fn volume(&self, id: ObjectId) -> Result<&Arc<AnyVolume>, SceneError> {
        let e = self.get(id)?;
        e.object
            .volume()
            .ok_or_else(|| self.wrong_kind(id, "volume", e.object.kind()))
    }

    /// The mesh object `id` is or holds (a mesh, a derived mesh once computed).
    ///
    /// # Errors
    /// [`SceneError::NoObject`]; [`SceneError::WrongKind`] when it holds no mesh.
    pub fn mesh(&self, id: ObjectId) -> Result<&Arc<Mesh>, SceneError> {
        let e = self.get(id)?;
        e.object
            .mesh()
            .ok_or_else(|| self.wrong_kind(id, "mesh", e.object.kind()))
    }

    /// The map of map object `id`.
    ///
    /// # Errors
    /// [`SceneError::NoObject`], [`SceneError::WrongKind`].
    pub fn map(&self, id: ObjectId) -> Result<&AnyMap, SceneError> {
        match &self.get(id)?.object {
            Object::Map(m) => Ok(m.map()),
            other => Err(self.wrong_kind(id, "map", other.kind())),
        }
    }

    /// Number of commands that can be undone.
    #[must_use]
    pub fn undo_depth(&self) -> usize {
        self.undo.len()
    }

    /// Number of commands that can be redone.
    #[must_use]
    pub fn redo_depth(&self) -> usize {
        self.redo.len()
    }

    /// Keep at most `limit` commands to undo (the oldest are forgotten).
    pub fn set_undo_limit(&mut self, limit: usize) {
        self.undo_limit = limit;
        let excess = self.undo.len().saturating_sub(limit);
        self.undo.drain(..excess);
    }

    fn wrong_kind(&self, id: ObjectId, expected: &'static str, found: &'static str) -> SceneError {
        SceneError::WrongKind {
            id,
            name: self
                .objects
                .get(&id)
                .map(|e| e.name.clone())
                .unwrap_or_default(),
            expected,
            found,
        }
    }

    fn map_object(&self, id: ObjectId) -> Result<&MapObject, SceneError> {
        match &self.get(id)?.object {
            Object::Map(m) => Ok(m),
            other => Err(self.wrong_kind(id, "map", other.kind())),
        }
    }

    fn handle_map(&self, id: ObjectId) -> Result<&HandleMap, SceneError> {
        match self.map_object(id)? {
            MapObject::Handles(h) => Ok(h),
            MapObject::Fixed(m) => Err(self.wrong_kind(id, "handle map", m.kind())),
        }
    }

    /// The derived objects that read `id`.
    fn users(&self, id: ObjectId) -> Vec<ObjectId> {
        self.objects
            .iter()
            .filter(|(_, e)| match &e.object {
                Object::Derived(d) => d.recipe().inputs().contains(&id),
                _ => false,
            })
            .map(|(u, _)| *u)
            .collect()
    }

    /// Apply `command`: the one entry point for changes. On success the command goes into the
    /// undo history (the redo history is cleared) and the report says what changed; on error
    /// the scene is unchanged.
    ///
    /// # Errors
    /// [`SceneError`] naming what is wrong: a missing object, an object of the wrong kind, an
    /// argument out of range, a map refusing the edit, a drag that cannot be solved.
    pub fn apply(&mut self, command: Command) -> Result<Change, SceneError> {
        self.apply_with(command, &volmorph_io::NoProgress)
    }

    /// [`Scene::apply`] reporting the long computations it runs (full recomputations of
    /// derived objects: warps, isosurfaces, F-rep sampling, Jacobians) to `progress`, and
    /// stopping when `progress` is cancelled. A cancelled command changes nothing: every
    /// object, both histories and the ids handed out next are exactly as before the call.
    ///
    /// # Errors
    /// As [`Scene::apply`]; [`SceneError::Cancelled`] when `progress` asks to stop.
    pub fn apply_with(
        &mut self,
        command: Command,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Change, SceneError> {
        progress.check()?;
        self.pending_drag = None;
        let next_id = self.next_id;
        let edits = match self.plan(command) {
            Ok(e) => e,
            Err(e) => {
                self.next_id = next_id;
                self.pending_drag = None;
                return Err(e);
            }
        };
        let (inverse, mut change) = match self.run(edits.clone(), progress) {
            Ok(r) => r,
            Err(e) => {
                self.pending_drag = None;
                return Err(e);
            }
        };
        change.drag = self.pending_drag.take();
        self.undo.push(Record {
            forward: edits,
            inverse,
        });
        if self.undo.len() > self.undo_limit {
            self.undo.remove(0);
        }
        self.redo.clear();
        Ok(change)
    }

    /// Take back the last command; `Ok(None)` if there is none.
    ///
    /// # Errors
    /// As [`Scene::apply`] (an undo that fails leaves the scene and both histories unchanged).
    pub fn undo(&mut self) -> Result<Option<Change>, SceneError> {
        self.undo_with(&volmorph_io::NoProgress)
    }

    /// [`Scene::undo`] reporting to `progress` as [`Scene::apply_with`] does; cancelled, it
    /// changes nothing.
    ///
    /// # Errors
    /// As [`Scene::undo`]; [`SceneError::Cancelled`] when `progress` asks to stop.
    pub fn undo_with(
        &mut self,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Option<Change>, SceneError> {
        progress.check()?;
        let Some(mut record) = self.undo.pop() else {
            return Ok(None);
        };
        match self.run(record.inverse.clone(), progress) {
            Ok((forward, change)) => {
                // The inverse of the inverse performs the command again from what was kept
                // (a sculpt edit's record) instead of recomputing it.
                record.forward = forward;
                self.redo.push(record);
                Ok(Some(change))
            }
            Err(e) => {
                self.undo.push(record);
                Err(e)
            }
        }
    }

    /// Apply again the last command taken back; `Ok(None)` if there is none.
    ///
    /// # Errors
    /// As [`Scene::undo`].
    pub fn redo(&mut self) -> Result<Option<Change>, SceneError> {
        self.redo_with(&volmorph_io::NoProgress)
    }

    /// [`Scene::redo`] reporting to `progress` as [`Scene::apply_with`] does; cancelled, it
    /// changes nothing.
    ///
    /// # Errors
    /// As [`Scene::redo`]; [`SceneError::Cancelled`] when `progress` asks to stop.
    pub fn redo_with(
        &mut self,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Option<Change>, SceneError> {
        progress.check()?;
        let Some(mut record) = self.redo.pop() else {
            return Ok(None);
        };
        match self.run(record.forward.clone(), progress) {
            Ok((inverse, change)) => {
                record.inverse = inverse;
                self.undo.push(record);
                Ok(Some(change))
            }
            Err(e) => {
                self.redo.push(record);
                Err(e)
            }
        }
    }

    /// Make the last `n` commands one undo step (a gesture: the moves of one drag are
    /// undone and redone together). Undoing the merged step runs the commands' inverses
    /// last to first; redoing it runs them first to last. `n` larger than the undo depth
    /// merges the whole history; `n < 2` changes nothing. Returns the number of commands
    /// merged (0 or 1 when nothing changed).
    pub fn merge_last(&mut self, n: usize) -> usize {
        let n = n.min(self.undo.len());
        if n < 2 {
            return n;
        }
        let tail = self.undo.split_off(self.undo.len() - n);
        let mut merged = Record {
            forward: Vec::new(),
            inverse: Vec::new(),
        };
        for r in &tail {
            merged.forward.extend(r.forward.iter().cloned());
        }
        for r in tail.into_iter().rev() {
            merged.inverse.extend(r.inverse);
        }
        self.undo.push(merged);
        n
    }

    /// Run `commands` (any number of [`Scene::apply`] / [`Scene::apply_with`] calls) as one
    /// undo step: on success the commands they applied are merged ([`Scene::merge_last`]);
    /// on error or cancellation those commands are taken back (by their inverse edits, so a
    /// group of additions leaves every object exactly as it was), and both histories and the
    /// next id are restored.
    ///
    /// # Errors
    /// The error `commands` returned.
    pub fn transaction<T>(
        &mut self,
        commands: impl FnOnce(&mut Scene) -> Result<T, SceneError>,
    ) -> Result<T, SceneError> {
        let depth = self.undo.len();
        let redo = std::mem::take(&mut self.redo);
        let next_id = self.next_id;
        let limit = self.undo_limit;
        self.undo_limit = usize::MAX;
        let result = commands(self);
        self.undo_limit = limit;
        let steps = self.undo.len().saturating_sub(depth);
        match result {
            Ok(v) => {
                self.merge_last(steps);
                let excess = self.undo.len().saturating_sub(limit);
                self.undo.drain(..excess);
                if steps == 0 {
                    self.redo = redo;
                }
                Ok(v)
            }
            Err(e) => {
                for _ in 0..steps {
                    if let Some(record) = self.undo.pop() {
                        let _ = self.run(record.inverse, &volmorph_io::NoProgress);
                    }
                }
                self.redo = redo;
                self.next_id = next_id;
                Err(e)
            }
        }
    }

    /// Forget the undo and redo histories (e.g. after loading a project).
    pub fn clear_history(&mut self) {
        self.undo.clear();
        self.redo.clear();
    }

    /// The entry of a new object: built, validated; derived objects are computed by `run`.
    fn entry(&self, name: String, object: NewObject) -> Result<Entry, SceneError> {
        let object = match object {
            NewObject::Volume(v) => Object::Volume(Arc::new(v)),
            NewObject::Mesh(m) => Object::Mesh(Arc::new(m)),
            NewObject::Frep { source, params } => Object::Frep(FrepModel::new(&source, params)?),
            NewObject::Nurbs(a) => Object::Nurbs(Arc::new(a)),
            NewObject::Map(m) => Object::Map(MapObject::Fixed(m)),
            NewObject::Handles {
                set,
                method,
                options,
            } => Object::Map(MapObject::Handles(HandleMap::new(set, method, options)?)),
            NewObject::Derived(recipe) => {
                self.check_recipe(&recipe)?;
                Object::Derived(Derived::new(recipe))
            }
            NewObject::Sculpt {
                mesh,
                grid,
                options,
            } => Object::Sculpt(SculptObject::new(volmorph_sculpt::SculptDocument::new(
                &mesh, grid, options,
            )?)),
        };
        Ok(Entry { name, object })
    }

    /// Every input of `recipe` exists and has the kind the recipe needs.
    fn check_recipe(&self, recipe: &crate::Recipe) -> Result<(), SceneError> {
        use crate::Recipe;
        let volume = |id: ObjectId| -> Result<(), SceneError> {
            let o = &self.get(id)?.object;
            match o {
                Object::Volume(_) => Ok(()),
                Object::Derived(d) if d.recipe().output_kind() == "volume" => Ok(()),
                other => Err(self.wrong_kind(id, "volume", other.kind())),
            }
        };
        let mesh = |id: ObjectId| -> Result<(), SceneError> {
            let o = &self.get(id)?.object;
            match o {
                Object::Mesh(_) | Object::Sculpt(_) => Ok(()),
                Object::Derived(d) if d.recipe().output_kind() == "mesh" => Ok(()),
                other => Err(self.wrong_kind(id, "mesh", other.kind())),
            }
        };
        let frep = |id: ObjectId| -> Result<(), SceneError> {
            match &self.get(id)?.object {
                Object::Frep(_) => Ok(()),
                other => Err(self.wrong_kind(id, "F-rep model", other.kind())),
            }
        };
        match recipe {
            Recipe::Warp { source, map, .. } | Recipe::WarpOnto { source, map, .. } => {
                volume(*source)?;
                self.map_object(*map).map(|_| ())
            }
            Recipe::DeformedMesh { mesh: m, map } => {
                mesh(*m)?;
                self.map_object(*map).map(|_| ())
            }
            Recipe::Isosurface {
                volume: v, level, ..
            } => {
                if !level.is_finite() {
                    return Err(SceneError::invalid(format!(
                        "iso level {level} is not finite"
                    )));
                }
                volume(*v)
            }
            Recipe::Jacobian { map, grid } => {
                volume(*grid)?;
                self.map_object(*map).map(|_| ())
            }
            Recipe::FrepSampled { model, map, grid } => {
                frep(*model)?;
                volume(*grid)?;
                match map {
                    Some(m) => self.map_object(*m).map(|_| ()),
                    None => Ok(()),
                }
            }
            Recipe::FrepMorph {
                from, to, t, grid, ..
            } => {
                if !(0.0..=1.0).contains(t) {
                    return Err(SceneError::invalid(format!(
                        "metamorphosis time t = {t} must be in [0, 1]"
                    )));
                }
                frep(*from)?;
                frep(*to)?;
                volume(*grid)
            }
            Recipe::Lobes {
                lungs,
                boundaries,
                script,
            } => {
                volume(*lungs)?;
                volume(*boundaries)?;
                let grid = |id: ObjectId| self.get(id).ok().and_then(|e| e.object.volume());
                if let (Some(l), Some(b)) = (grid(*lungs), grid(*boundaries)) {
                    if l.geometry() != b.geometry() {
                        return Err(SceneError::invalid(format!(
                            "lobe tracing: the lung mask {lungs} and the lobe-boundary image \
                             {boundaries} lie on different grids"
                        )));
                    }
                    script.validate(l.geometry().dims)?;
                }
                Ok(())
            }
        }
    }

    /// Translate a command into edits, validating it against the current state.
    fn plan(&mut self, command: Command) -> Result<Vec<Edit>, SceneError> {
        Ok(match command {
            Command::Add { name, object } => {
                let entry = self.entry(name, object)?;
                vec![Edit::Insert {
                    id: ObjectId(self.next_id + 1),
                    entry: Box::new(entry),
                }]
            }
            Command::Remove { id } => {
                self.get(id)?;
                let users = self.users(id);
                if !users.is_empty() {
                    return Err(SceneError::InUse { id, users });
                }
                vec![Edit::Remove { id }]
            }
            Command::Rename { id, name } => {
                let mut entry = self.get(id)?.clone();
                entry.name = name;
                vec![Edit::Replace {
                    id,
                    entry: Box::new(entry),
                }]
            }
            Command::Replace { id, object } => {
                let old = self.get(id)?;
                let entry = self.entry(old.name.clone(), object)?;
                if entry.object.kind() != old.object.kind() && !self.users(id).is_empty() {
                    return Err(SceneError::InUse {
                        id,
                        users: self.users(id),
                    });
                }
                vec![Edit::Replace {
                    id,
                    entry: Box::new(entry),
                }]
            }
            Command::DragPoints {
                map,
                grabbed,
                targets,
                options,
            } => {
                let AnyMap::Lattice(lattice) = self.map(map)? else {
                    return Err(self.wrong_kind(
                        map,
                        "B-spline lattice map",
                        self.map(map)?.kind(),
                    ));
                };
                if grabbed.len() != targets.len() || grabbed.is_empty() {
                    return Err(SceneError::invalid(format!(
                        "{} grabbed points but {} targets: give one target per point",
                        grabbed.len(),
                        targets.len()
                    )));
                }
                let drags = drags_from_deformed(lattice, &grabbed, &targets)?;
                let solution = solve_drags(lattice, &drags, &options)?;
                let changes = lattice.changes_for_displacements(solution.displacements())?;
                self.pending_drag = Some(crate::command::DragSummary {
                    moved: changes.len(),
                    rank: solution.rank(),
                    drags: solution.drag_count(),
                    max_residual: solution.max_residual(),
                });
                vec![Edit::Parameters { id: map, changes }]
            }
            Command::SetParameters { map, changes } => {
                let n = self.parameter_count(map)?;
                for &(k, v) in &changes {
                    if k >= n {
                        return Err(SceneError::invalid(format!(
                            "parameter {k} out of range (the map has {n})"
                        )));
                    }
                    if !v.is_finite() {
                        return Err(SceneError::invalid(format!(
                            "parameter {k}: {v} is not finite"
                        )));
                    }
                }
                vec![Edit::Parameters { id: map, changes }]
            }
            Command::AddHandle {
                map,
                source,
                target,
            } => {
                let h = self.handle_map(map)?;
                let mut set = h.set().clone();
                set.points.push((source, target));
                self.handle_edit(map, set, h.method(), *h.options())?
            }
            Command::MoveHandle {
                map,
                index,
                source,
                target,
            } => {
                let h = self.handle_map(map)?;
                let mut set = h.set().clone();
                let n = set.points.len();
                *set.points.get_mut(index).ok_or_else(|| {
                    SceneError::invalid(format!("handle {index} out of range ({n} point handles)"))
                })? = (source, target);
                self.handle_edit(map, set, h.method(), *h.options())?
            }
            Command::DeleteHandle { map, index } => {
                let h = self.handle_map(map)?;
                let mut set = h.set().clone();
                if index >= set.points.len() {
                    return Err(SceneError::invalid(format!(
                        "handle {index} out of range ({} point handles)",
                        set.points.len()
                    )));
                }
                set.points.remove(index);
                self.handle_edit(map, set, h.method(), *h.options())?
            }
            Command::SetHandleMethod {
                map,
                method,
                options,
            } => {
                let set = self.handle_map(map)?.set().clone();
                self.handle_edit(map, set, method, options)?
            }
            Command::Sculpt { id, edit } => {
                let entry = self.get(id)?;
                let Object::Sculpt(_) = &entry.object else {
                    return Err(self.wrong_kind(id, "sculpt object", entry.object.kind()));
                };
                vec![Edit::Sculpt {
                    id,
                    step: SculptStep::Apply(edit),
                }]
            }
            Command::SetRecipe { id, recipe } => {
                let entry = self.get(id)?;
                let Object::Derived(_) = &entry.object else {
                    return Err(self.wrong_kind(id, "derived object", entry.object.kind()));
                };
                self.check_recipe(&recipe)?;
                if recipe.inputs().iter().any(|i| *i >= id) {
                    return Err(SceneError::invalid(
                        "a derived object can only read objects created before it",
                    ));
                }
                vec![Edit::Replace {
                    id,
                    entry: Box::new(Entry {
                        name: entry.name.clone(),
                        object: Object::Derived(Derived::new(recipe)),
                    }),
                }]
            }
        })
    }

    fn handle_edit(
        &self,
        id: ObjectId,
        set: volmorph_handles::HandleSet,
        method: volmorph_maps::HandleMethod,
        options: volmorph_maps::HandleOptions,
    ) -> Result<Vec<Edit>, SceneError> {
        let map = HandleMap::new(set, method, options)?;
        Ok(vec![Edit::Replace {
            id,
            entry: Box::new(Entry {
                name: self.get(id)?.name.clone(),
                object: Object::Map(MapObject::Handles(map)),
            }),
        }])
    }

    fn parameter_count(&self, id: ObjectId) -> Result<usize, SceneError> {
        match self.map_object(id)? {
            MapObject::Fixed(m) => m.to_live().map(|l| l.parameter_count()).ok_or_else(|| {
                SceneError::invalid(format!(
                    "a {} map is not edited by parameters (only lattices, affine and frame MLS \
                     and thin-plate splines are)",
                    m.kind()
                ))
            }),
            MapObject::Handles(h) => Ok(h.set().points.len()),
        }
    }

    /// Apply `edits` in order, then bring the derived objects up to date; on error or
    /// cancellation undo what was applied (the derived objects already updated are put back
    /// first). Returns the inverse edits (in the order to apply them) and the change.
    fn run(
        &mut self,
        edits: Vec<Edit>,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<(Vec<Edit>, Change), SceneError> {
        let next_id = self.next_id;
        let mut inverse: Vec<Edit> = Vec::with_capacity(edits.len());
        let mut change = Change::default();
        let mut effects: BTreeMap<ObjectId, Effect> = BTreeMap::new();
        let mut failure = None;
        for edit in edits {
            if let Err(e) = progress.check() {
                failure = Some(SceneError::from(e));
                break;
            }
            match self.apply_edit(edit, &mut change, &mut effects) {
                Ok(inv) => inverse.push(inv),
                Err(e) => {
                    failure = Some(e);
                    break;
                }
            }
        }
        inverse.reverse();
        if failure.is_none() {
            let mut restores = Vec::new();
            match self.propagate(effects, &mut change, progress, &mut restores) {
                Ok(()) => return Ok((inverse, change)),
                Err(e) => {
                    self.restore(restores);
                    failure = Some(e);
                }
            }
        }
        for inv in inverse {
            let _ = self.apply_edit(inv, &mut Change::default(), &mut BTreeMap::new());
        }
        self.next_id = next_id;
        Err(match failure {
            Some(e) if e.is_cancelled() => SceneError::Cancelled(volmorph_io::Cancelled),
            Some(e) => e,
            None => SceneError::invalid("command failed"),
        })
    }

    /// Put back what the derived objects' updates replaced, the latest first.
    fn restore(&mut self, restores: Vec<(ObjectId, Restore)>) {
        for (id, r) in restores.into_iter().rev() {
            if let Some(Entry {
                object: Object::Derived(d),
                ..
            }) = self.objects.get_mut(&id)
            {
                d.restore(r);
            }
        }
    }

    /// Apply one edit; returns its inverse.
    fn apply_edit(
        &mut self,
        edit: Edit,
        change: &mut Change,
        effects: &mut BTreeMap<ObjectId, Effect>,
    ) -> Result<Edit, SceneError> {
        match edit {
            Edit::Insert { id, entry } => {
                if self.objects.contains_key(&id) {
                    return Err(SceneError::invalid(format!("object {id} exists")));
                }
                self.next_id = self.next_id.max(id.0);
                self.objects.insert(id, *entry);
                change.added.push(id);
                effects.insert(id, Effect::Full);
                Ok(Edit::Remove { id })
            }
            Edit::Remove { id } => {
                let entry = self.objects.remove(&id).ok_or(SceneError::NoObject(id))?;
                change.removed.push(id);
                effects.remove(&id);
                Ok(Edit::Insert {
                    id,
                    entry: Box::new(entry),
                })
            }
            Edit::Replace { id, entry } => {
                let slot = self.objects.get_mut(&id).ok_or(SceneError::NoObject(id))?;
                let old = std::mem::replace(slot, *entry);
                change.modified.push(id);
                effects.insert(id, Effect::Full);
                Ok(Edit::Replace {
                    id,
                    entry: Box::new(old),
                })
            }
            Edit::Parameters { id, changes } => {
                let old = self.set_parameters(id, &changes)?;
                change.modified.push(id);
                let effect = match effects.remove(&id) {
                    None => Effect::Parameters(changes),
                    Some(Effect::Parameters(mut c)) => {
                        c.extend(changes);
                        Effect::Parameters(c)
                    }
                    Some(_) => Effect::Full,
                };
                effects.insert(id, effect);
                Ok(Edit::Parameters { id, changes: old })
            }
            Edit::Sculpt { id, step } => {
                let Some(Entry {
                    object: Object::Sculpt(s),
                    ..
                }) = self.objects.get_mut(&id)
                else {
                    return Err(SceneError::invalid(format!(
                        "object {id} is not a sculpt object"
                    )));
                };
                let (record, inverse) = match step {
                    SculptStep::Apply(edit) => {
                        let r = Arc::new(s.document_mut().apply(&edit)?);
                        (r.clone(), SculptStep::Undo(r))
                    }
                    SculptStep::Undo(r) => {
                        s.document_mut().undo(&r)?;
                        (r.clone(), SculptStep::Redo(r))
                    }
                    SculptStep::Redo(r) => {
                        s.document_mut().redo(&r)?;
                        (r.clone(), SculptStep::Undo(r))
                    }
                };
                if let Some(c) = record.changed() {
                    let p = c.dexels;
                    change.modified.push(id);
                    change.dirty.push(Dirty {
                        object: id,
                        voxels: Some(IndexBox {
                            start: p.lo,
                            end: p.hi.map(|h| h + 1),
                        }),
                        bounds: Some((c.min, c.max)),
                    });
                    effects.insert(id, Effect::Full);
                }
                Ok(Edit::Sculpt { id, step: inverse })
            }
        }
    }

    /// The sculpting document of sculpt object `id`.
    ///
    /// # Errors
    /// [`SceneError::NoObject`], [`SceneError::WrongKind`].
    pub fn sculpt(&self, id: ObjectId) -> Result<&volmorph_sculpt::SculptDocument, SceneError> {
        match &self.get(id)?.object {
            Object::Sculpt(s) => Ok(s.document()),
            other => Err(self.wrong_kind(id, "sculpt object", other.kind())),
        }
    }

    /// Set parameters of map `id`; returns the old values of the changed ones (in reverse
    /// order, so applying them in order restores every value).
    fn set_parameters(
        &mut self,
        id: ObjectId,
        changes: &[(usize, DVec3)],
    ) -> Result<Vec<(usize, DVec3)>, SceneError> {
        let entry = self.objects.get_mut(&id).ok_or(SceneError::NoObject(id))?;
        let Object::Map(m) = &mut entry.object else {
            return Err(SceneError::invalid(format!("object {id} is not a map")));
        };
        match m {
            MapObject::Fixed(map) => {
                let live: &mut dyn LinearMap = match map {
                    AnyMap::Lattice(l) => l,
                    AnyMap::AffineMls(l) => l,
                    AnyMap::FrameMls(l) => l,
                    AnyMap::ThinPlate(l) => l,
                    other => {
                        return Err(SceneError::invalid(format!(
                            "a {} map is not edited by parameters",
                            other.kind()
                        )));
                    }
                };
                let params = live.parameters();
                let mut old = Vec::with_capacity(changes.len());
                for &(k, _) in changes {
                    let v = *params.get(k).ok_or_else(|| {
                        SceneError::invalid(format!("parameter {k} out of range"))
                    })?;
                    old.push((k, v));
                }
                live.set_some_parameters(changes)?;
                old.reverse();
                Ok(old)
            }
            MapObject::Handles(h) => {
                let mut set = h.set().clone();
                let mut old = Vec::with_capacity(changes.len());
                for &(k, v) in changes {
                    let n = set.points.len();
                    let p = set.points.get_mut(k).ok_or_else(|| {
                        SceneError::invalid(format!("handle {k} out of range ({n} point handles)"))
                    })?;
                    old.push((k, p.1));
                    p.1 = v;
                }
                *h = HandleMap::new(set, h.method(), *h.options())?;
                old.reverse();
                Ok(old)
            }
        }
    }

    /// Bring every derived object reading a changed object up to date, in id order (inputs
    /// are always older than their users), recording what changed in `change` and what each
    /// update replaced in `restores` (to put back if the command does not complete).
    ///
    /// # Errors
    /// Only cancellation through `progress` (checked before each update and inside the long
    /// ones); the updates done so far are in `restores`.
    fn propagate(
        &mut self,
        mut effects: BTreeMap<ObjectId, Effect>,
        change: &mut Change,
        progress: &dyn volmorph_io::Progress,
        restores: &mut Vec<(ObjectId, Restore)>,
    ) -> Result<(), SceneError> {
        let ids: Vec<ObjectId> = self.objects.keys().copied().collect();
        for id in ids {
            let Some(Entry {
                object: Object::Derived(d),
                ..
            }) = self.objects.get(&id)
            else {
                continue;
            };
            let recipe = d.recipe().clone();
            let hint = if matches!(effects.get(&id), Some(Effect::Full)) || d.output().is_none() {
                Some(Hint::Full)
            } else {
                let mut hint: Option<Hint> = None;
                for input in recipe.inputs() {
                    let h = match effects.get(&input) {
                        None => continue,
                        Some(Effect::Parameters(c)) if Some(input) == recipe.map() => {
                            Hint::Parameters(c.clone())
                        }
                        Some(Effect::Region(b)) => Hint::Region(*b),
                        Some(_) => Hint::Full,
                    };
                    hint = Some(match hint {
                        None => h,
                        Some(_) => Hint::Full,
                    });
                }
                hint
            };
            let Some(hint) = hint else { continue };
            progress.check()?;
            // Take the derived object out while its inputs (older objects) are borrowed.
            let Some(mut entry) = self.objects.remove(&id) else {
                continue;
            };
            let result = if let Object::Derived(d) = &mut entry.object {
                let inputs = self.inputs(&recipe);
                Some(
                    d.update_with(id, &inputs, &hint, progress)
                        .map(|(dirty, restore)| (dirty, restore, d.error().map(str::to_owned))),
                )
            } else {
                None
            };
            self.objects.insert(id, entry);
            let Some(result) = result else {
                continue;
            };
            let (dirty, restore, error) = result?;
            restores.push((id, restore));
            if let Some(msg) = error {
                change.errors.push((id, msg));
            }
            let effect = match dirty.voxels {
                Some(b) if !matches!(hint, Hint::Full) => Effect::Region(b),
                _ => Effect::Full,
            };
            if dirty.bounds.is_some() || dirty.voxels.is_some_and(|b| !b.is_empty()) {
                effects.insert(id, effect);
                if !change.added.contains(&id) && !change.modified.contains(&id) {
                    change.modified.push(id);
                }
                change.dirty.push(dirty);
            } else if matches!(hint, Hint::Full) {
                effects.insert(id, Effect::Full);
            }
        }
        Ok(())
    }

    fn inputs(&self, recipe: &crate::Recipe) -> Inputs<'_> {
        use crate::Recipe;
        let object = |id: ObjectId| self.objects.get(&id).map(|e| &e.object);
        match recipe {
            Recipe::Warp { source, map, .. } | Recipe::WarpOnto { source, map, .. } => Inputs {
                volume: object(*source).and_then(Object::volume),
                mesh: None,
                map: self.map_object(*map).ok(),
                frep: None,
                frep_to: None,
                second: None,
            },
            Recipe::DeformedMesh { mesh, map } => Inputs {
                volume: None,
                mesh: object(*mesh).and_then(Object::mesh),
                map: self.map_object(*map).ok(),
                frep: None,
                frep_to: None,
                second: None,
            },
            Recipe::Isosurface { volume, .. } => Inputs {
                volume: object(*volume).and_then(Object::volume),
                mesh: None,
                map: None,
                frep: None,
                frep_to: None,
                second: None,
            },
            Recipe::Jacobian { map, grid } => Inputs {
                volume: object(*grid).and_then(Object::volume),
                mesh: None,
                map: self.map_object(*map).ok(),
                frep: None,
                frep_to: None,
                second: None,
            },
            Recipe::FrepSampled { model, map, grid } => Inputs {
                volume: object(*grid).and_then(Object::volume),
                mesh: None,
                map: map.and_then(|m| self.map_object(m).ok()),
                frep: match object(*model) {
                    Some(Object::Frep(f)) => Some(f),
                    _ => None,
                },
                frep_to: None,
                second: None,
            },
            Recipe::FrepMorph { from, to, grid, .. } => {
                let frep = |id: ObjectId| match object(id) {
                    Some(Object::Frep(f)) => Some(f),
                    _ => None,
                };
                Inputs {
                    volume: object(*grid).and_then(Object::volume),
                    mesh: None,
                    map: None,
                    frep: frep(*from),
                    frep_to: frep(*to),
                    second: None,
                }
            }
            Recipe::Lobes {
                lungs, boundaries, ..
            } => Inputs {
                volume: object(*lungs).and_then(Object::volume),
                mesh: None,
                map: None,
                frep: None,
                frep_to: None,
                second: object(*boundaries).and_then(Object::volume),
            },
        }
    }

    /// The largest id handed out so far (project files keep it, so ids are never reused).
    pub(crate) fn next_id_value(&self) -> u64 {
        self.next_id
    }

    /// Never hand out an id at or below `n` (project loading).
    pub(crate) fn set_next_id(&mut self, n: u64) {
        self.next_id = self.next_id.max(n);
    }

    /// The recipe of derived object `id` reads existing objects of the right kinds, all older.
    pub(crate) fn check_recipe_of(
        &self,
        id: ObjectId,
        recipe: &crate::Recipe,
    ) -> Result<(), SceneError> {
        if recipe.inputs().iter().any(|i| *i >= id) {
            return Err(SceneError::invalid(format!(
                "object {id}: its recipe reads an object that does not precede it"
            )));
        }
        self.check_recipe(recipe)
    }

    /// Insert an entry under a given id without history (project loading).
    pub(crate) fn insert_raw(&mut self, id: ObjectId, entry: Entry) {
        self.next_id = self.next_id.max(id.0);
        self.objects.insert(id, entry);
    }

    /// Compute every derived object that has no result yet (project loading).
    ///
    /// # Errors
    /// Only cancellation through `progress`.
    pub(crate) fn compute_missing(
        &mut self,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Change, SceneError> {
        let mut change = Change::default();
        self.propagate(BTreeMap::new(), &mut change, progress, &mut Vec::new())?;
        Ok(change)
    }
}
