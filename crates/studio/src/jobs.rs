//! The edits a page asks for, run one at a time on the editor thread through the scene's
//! commands, with the moves of a gesture coalesced ([`crate::coalesce`]) and merged into one
//! undo step when the gesture ends.

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, RwLock};
use std::time::Instant;

use glam::DVec3;
use serde_json::{Value, json};
use volmorph_lattice::DragOptions;
use volmorph_scene::{Change, Command, Scene, SceneError};

use crate::coalesce::{Coalesce, Queue};
use crate::protocol::{Frame, Kind};
use crate::setup::Setup;

/// Who asked for a job: the page and its request number (errors go back to it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Origin {
    /// The page (socket) number.
    pub page: u64,
    /// The page's request number.
    pub request: u32,
}

/// One edit to run.
#[derive(Debug)]
pub struct Job {
    /// Who asked.
    pub origin: Origin,
    /// What to do.
    pub work: Work,
}

/// What an edit does.
#[derive(Debug)]
pub enum Work {
    /// One move of a direct-manipulation drag: the point grabbed at `start` (deformed space,
    /// when the gesture began) goes to `target`. Moves of one gesture coalesce: the newest
    /// target wins, and the scene drags from where the point is now.
    Drag {
        /// The gesture.
        gesture: u64,
        /// The lattice map object.
        map: volmorph_scene::ObjectId,
        /// Where the point was grabbed.
        start: DVec3,
        /// Where it must go.
        target: DVec3,
        /// Tool radius (physical units).
        radius: f64,
    },
    /// New positions for control points of a map (flat parameter index → position); moves
    /// of one gesture coalesce (the newest position of each point wins).
    Parameters {
        /// The gesture.
        gesture: u64,
        /// The map object.
        map: volmorph_scene::ObjectId,
        /// Parameter → new value.
        changes: BTreeMap<usize, DVec3>,
    },
    /// The gesture's moves become one undo step.
    EndGesture {
        /// The gesture.
        gesture: u64,
    },
    /// Undo the last command.
    Undo,
    /// Redo the last command undone.
    Redo,
    /// Any other scene command; with a gesture, a newer command of the same gesture replaces
    /// a pending one (absolute edits: a handle's new position, a model's new text).
    Command(Box<Command>, Option<u64>),
    /// A built-in workflow (several commands).
    Setup(Setup),
}

impl Coalesce for Job {
    fn key(&self) -> Option<u64> {
        match &self.work {
            Work::Drag { gesture, .. } | Work::Parameters { gesture, .. } => Some(*gesture),
            Work::Command(_, g) => *g,
            _ => None,
        }
    }

    fn absorb(&mut self, newer: Self) -> Result<(), Self> {
        match (&mut self.work, newer.work) {
            (
                Work::Drag { target, radius, .. },
                Work::Drag {
                    target: t,
                    radius: r,
                    ..
                },
            ) => {
                *target = t;
                *radius = r;
            }
            (Work::Parameters { changes, .. }, Work::Parameters { changes: c, .. }) => {
                changes.extend(c);
            }
            // A command replaces a pending command of the same kind (absolute edits).
            (Work::Command(c, _), Work::Command(n, g))
                if std::mem::discriminant(&**c) == std::mem::discriminant(&*n) =>
            {
                self.work = Work::Command(n, g);
            }
            (_, work) => {
                return Err(Job {
                    origin: newer.origin,
                    work,
                });
            }
        }
        self.origin = newer.origin;
        Ok(())
    }
}

/// The state of an ongoing gesture.
#[derive(Debug, Clone, Copy)]
struct Gesture {
    /// Where the dragged point is now.
    at: DVec3,
    /// Commands applied in the gesture.
    steps: usize,
    /// Undo depth before its first command.
    depth: usize,
}

/// The editor: owns the order of edits. Runs on its own thread; every result is sent to
/// every page (a [`Kind::Changed`] frame) and errors to the page that asked.
pub struct Editor {
    scene: Arc<RwLock<Scene>>,
    queue: Arc<Queue<Job>>,
    out: tokio::sync::broadcast::Sender<Outgoing>,
    gestures: HashMap<u64, Gesture>,
    edits_run: u64,
}

/// A frame for the pages: to every page, or to one.
#[derive(Debug, Clone)]
pub struct Outgoing {
    /// Only this page, or every page.
    pub page: Option<u64>,
    /// The encoded frame.
    pub bytes: Arc<Vec<u8>>,
}

impl Editor {
    /// An editor over `scene`, taking jobs from `queue`.
    pub fn new(
        scene: Arc<RwLock<Scene>>,
        queue: Arc<Queue<Job>>,
        out: tokio::sync::broadcast::Sender<Outgoing>,
    ) -> Self {
        Self {
            scene,
            queue,
            out,
            gestures: HashMap::new(),
            edits_run: 0,
        }
    }

    /// Run jobs until the queue closes.
    pub fn run(mut self) {
        while let Some(job) = self.queue.pop() {
            let started = Instant::now();
            let origin = job.origin;
            let label = label(&job.work);
            let result = {
                let lock = Arc::clone(&self.scene);
                let mut scene = lock.write().unwrap_or_else(|p| p.into_inner());
                self.execute(&mut scene, job.work)
                    .map(|c| (c, scene.undo_depth(), scene.redo_depth()))
            };
            let ms = started.elapsed().as_secs_f64() * 1e3;
            match result {
                Ok((change, undo, redo)) => {
                    self.edits_run += 1;
                    let header = change_header(
                        &change,
                        label,
                        origin,
                        ms,
                        undo,
                        redo,
                        self.edits_run,
                        self.queue.coalesced(),
                    );
                    self.send(None, Frame::new(Kind::Changed, 0, header));
                }
                Err(e) => {
                    self.send(Some(origin.page), error_frame(origin.request, &e));
                }
            }
        }
    }

    fn send(&self, page: Option<u64>, frame: Frame) {
        // No page listening is not an error.
        let _ = self.out.send(Outgoing {
            page,
            bytes: Arc::new(frame.encode()),
        });
    }

    fn execute(&mut self, scene: &mut Scene, work: Work) -> Result<Change, SceneError> {
        match work {
            Work::Drag {
                gesture,
                map,
                start,
                target,
                radius,
            } => {
                let g = self.gestures.entry(gesture).or_insert(Gesture {
                    at: start,
                    steps: 0,
                    depth: scene.undo_depth(),
                });
                let change = scene.apply(Command::DragPoints {
                    map,
                    grabbed: vec![g.at],
                    targets: vec![target],
                    options: DragOptions::with_radius(radius),
                })?;
                g.at = target;
                g.steps += 1;
                Ok(change)
            }
            Work::Parameters {
                gesture,
                map,
                changes,
            } => {
                let depth = scene.undo_depth();
                let change = scene.apply(Command::SetParameters {
                    map,
                    changes: changes.into_iter().collect(),
                })?;
                let g = self.gestures.entry(gesture).or_insert(Gesture {
                    at: DVec3::ZERO,
                    steps: 0,
                    depth,
                });
                g.steps += 1;
                Ok(change)
            }
            Work::EndGesture { gesture } => {
                if let Some(g) = self.gestures.remove(&gesture) {
                    // Merge only if nothing else was applied in between.
                    if scene.undo_depth() == g.depth + g.steps {
                        scene.merge_last(g.steps);
                    }
                }
                Ok(Change::default())
            }
            Work::Undo => Ok(scene.undo()?.unwrap_or_default()),
            Work::Redo => Ok(scene.redo()?.unwrap_or_default()),
            Work::Command(c, None) => scene.apply(*c),
            Work::Command(c, Some(gesture)) => {
                let depth = scene.undo_depth();
                let change = scene.apply(*c)?;
                self.gestures
                    .entry(gesture)
                    .or_insert(Gesture {
                        at: DVec3::ZERO,
                        steps: 0,
                        depth,
                    })
                    .steps += 1;
                Ok(change)
            }
            Work::Setup(s) => s.run(scene),
        }
    }
}

fn label(work: &Work) -> &'static str {
    match work {
        Work::Drag { .. } => "drag",
        Work::Parameters { .. } => "parameters",
        Work::EndGesture { .. } => "end-gesture",
        Work::Undo => "undo",
        Work::Redo => "redo",
        Work::Command(..) => "command",
        Work::Setup(_) => "setup",
    }
}

/// The header of a [`Kind::Changed`] frame (fields in `PROTOCOL.md`).
#[allow(clippy::too_many_arguments)]
fn change_header(
    change: &Change,
    label: &str,
    origin: Origin,
    ms: f64,
    undo: usize,
    redo: usize,
    edits_run: u64,
    coalesced: u64,
) -> Value {
    let ids = |v: &[volmorph_scene::ObjectId]| v.iter().map(|i| i.0).collect::<Vec<_>>();
    let dirty: Vec<Value> = change
        .dirty
        .iter()
        .map(|d| {
            json!({
                "object": d.object.0,
                "voxels": d.voxels.map(|b| json!({"start": b.start, "end": b.end})),
                "bounds": d.bounds.map(|(lo, hi)| json!([lo.to_array(), hi.to_array()])),
            })
        })
        .collect();
    json!({
        "edit": label,
        "page": origin.page,
        "request": origin.request,
        "ms": ms,
        "added": ids(&change.added),
        "removed": ids(&change.removed),
        "modified": ids(&change.modified),
        "dirty": dirty,
        "errors": change.errors.iter().map(|(id, m)| json!({"object": id.0, "message": m})).collect::<Vec<_>>(),
        "drag": change.drag.map(|d| json!({"moved": d.moved, "rank": d.rank, "drags": d.drags, "maxResidual": d.max_residual})),
        "undo": undo,
        "redo": redo,
        "editsRun": edits_run,
        "coalesced": coalesced,
    })
}

/// An [`Kind::Error`] frame for `request`: the message, and for F-rep source errors the line
/// and column.
pub fn error_frame(request: u32, e: &SceneError) -> Frame {
    let pos = match e {
        SceneError::Frep(f) => f.pos().map(|p| (p.line, p.col)),
        _ => None,
    };
    Frame::new(
        Kind::Error,
        request,
        json!({
            "message": e.to_string(),
            "line": pos.map(|p| p.0),
            "column": pos.map(|p| p.1),
        }),
    )
}
