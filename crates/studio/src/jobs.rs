//! The jobs a page asks for, run one at a time on the editor thread through the scene's
//! commands, with the moves of a gesture coalesced ([`crate::coalesce`]) and merged into one
//! undo step when the gesture ends; and their progress and cancellation ([`Running`]).
//!
//! Every job runs with a [`JobProgress`] (a [`volmorph_io::Progress`]) handed to the scene's
//! `_with` calls. While it runs it is listed in [`Running`]: a page's
//! [`Kind::Cancel`] sets its flag, and a ticker sends the page a [`Kind::Progress`] frame
//! when the job's stage or count changed, from [`PROGRESS_DELAY`] after it started and at
//! most every [`PROGRESS_INTERVAL`] (short jobs, a drag's moves, send none). A cancelled job
//! changes nothing and is answered with [`Kind::Error`] `{cancelled: true}`.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::time::{Duration, Instant};

use glam::DVec3;
use serde_json::{Value, json};
use volmorph_lattice::DragOptions;
use volmorph_scene::{Change, Command, ObjectId, Scene, SceneError};

use crate::coalesce::{Coalesce, Queue};
use crate::command_json::{Brush, SculptRequest};
use crate::lobes::LobeRequest;
use crate::protocol::{Frame, Kind};
use volmorph_scene::setup::Setup;

/// Time after a job's start before its first [`Kind::Progress`] frame: jobs shorter than
/// this (an interactive edit) send none.
pub const PROGRESS_DELAY: Duration = Duration::from_millis(250);

/// Least time between two [`Kind::Progress`] frames of one job (at most 10 a second).
pub const PROGRESS_INTERVAL: Duration = Duration::from_millis(100);

/// The progress of one job: the stage and steps the library reports, and the flag a
/// [`Kind::Cancel`] sets. Cheap from any thread (atomics; a lock only when a stage starts).
#[derive(Debug)]
pub struct JobProgress {
    origin: Origin,
    started: Instant,
    cancelled: AtomicBool,
    stage: Mutex<(String, u64)>,
    done: AtomicU64,
    /// The last state sent, so an unchanged state is not sent again.
    sent: Mutex<Option<(String, u64, u64)>>,
}

impl JobProgress {
    /// A job of `origin`, starting now.
    #[must_use]
    pub fn new(origin: Origin) -> Self {
        Self {
            origin,
            started: Instant::now(),
            cancelled: AtomicBool::new(false),
            stage: Mutex::new((String::new(), 0)),
            done: AtomicU64::new(0),
            sent: Mutex::new(None),
        }
    }

    /// Ask the job to stop.
    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::Relaxed);
    }

    /// The [`Kind::Progress`] frame of the current state (`{request, label, done, total}`),
    /// if the job has run for [`PROGRESS_DELAY`], has started a stage, and its state changed
    /// since the last frame this returned.
    fn frame(&self) -> Option<Frame> {
        if self.started.elapsed() < PROGRESS_DELAY {
            return None;
        }
        let (label, total) = self
            .stage
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        if label.is_empty() {
            return None;
        }
        let done = self.done.load(Ordering::Relaxed).min(total.max(1));
        let now = (label, done, total);
        let mut sent = self
            .sent
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if sent.as_ref() == Some(&now) {
            return None;
        }
        let f = Frame::new(
            Kind::Progress,
            0,
            json!({"request": self.origin.request, "label": now.0, "done": now.1, "total": now.2}),
        );
        *sent = Some(now);
        Some(f)
    }
}

impl volmorph_io::Progress for JobProgress {
    fn start(&self, label: &str, total: u64) {
        *self
            .stage
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = (label.to_owned(), total);
        self.done.store(0, Ordering::Relaxed);
    }
    fn advance(&self, steps: u64) {
        self.done.fetch_add(steps, Ordering::Relaxed);
    }
    fn is_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }
}

/// The jobs running now, by origin: found by [`Kind::Cancel`], reported by [`Running::tick`].
#[derive(Debug)]
pub struct Running {
    jobs: Mutex<HashMap<(u64, u32), Arc<JobProgress>>>,
    out: tokio::sync::broadcast::Sender<Outgoing>,
}

/// A job listed in [`Running`] while this lives.
#[derive(Debug)]
pub struct RunningJob {
    running: Arc<Running>,
    progress: Arc<JobProgress>,
}

impl RunningJob {
    /// The job's progress (to hand to the library).
    #[must_use]
    pub fn progress(&self) -> &Arc<JobProgress> {
        &self.progress
    }
}

impl Drop for RunningJob {
    fn drop(&mut self) {
        let o = self.progress.origin;
        let mut jobs = self
            .running
            .jobs
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if jobs
            .get(&(o.page, o.request))
            .is_some_and(|p| Arc::ptr_eq(p, &self.progress))
        {
            jobs.remove(&(o.page, o.request));
        }
    }
}

impl Running {
    /// No job yet; progress frames go out through `out`.
    #[must_use]
    pub fn new(out: tokio::sync::broadcast::Sender<Outgoing>) -> Self {
        Self {
            jobs: Mutex::new(HashMap::new()),
            out,
        }
    }

    /// List a job of `origin` until the returned guard is dropped. Drop the guard before
    /// sending the job's answer: a progress frame is never sent after it.
    #[must_use]
    pub fn begin(self: &Arc<Self>, origin: Origin) -> RunningJob {
        let progress = Arc::new(JobProgress::new(origin));
        self.jobs
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .insert((origin.page, origin.request), Arc::clone(&progress));
        RunningJob {
            running: Arc::clone(self),
            progress,
        }
    }

    /// Cancel the running job of `origin`; `false` if none runs.
    pub fn cancel(&self, origin: Origin) -> bool {
        let jobs = self
            .jobs
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match jobs.get(&(origin.page, origin.request)) {
            Some(p) => {
                p.cancel();
                true
            }
            None => false,
        }
    }

    /// Send each running job's page a [`Kind::Progress`] frame if its state changed (see
    /// [`JobProgress`]); called every [`PROGRESS_INTERVAL`]. The frames are sent while the
    /// list is locked, so none follows the answer of a job that has ended.
    pub fn tick(&self) {
        let jobs = self
            .jobs
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        for p in jobs.values() {
            if let Some(f) = p.frame() {
                let _ = self.out.send(Outgoing {
                    page: Some(p.origin.page),
                    bytes: Arc::new(f.encode()),
                });
            }
        }
    }
}

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
    /// A sculpting stroke (or dab) on a sculpt object; with a gesture, the pending stroke of
    /// the same gesture, object, brush, operation and size absorbs a newer one (their points
    /// concatenate: sculpting is cumulative, so nothing is dropped).
    Sculpt(SculptRequest, Option<u64>),
    /// An edit of the fissure script of a `lobes` object ([`crate::lobes`]): the lobes are
    /// traced again.
    Lobes(LobeRequest),
    /// A built-in workflow (several commands).
    Setup(Setup),
    /// Read a file (resolved inside a root) and add it as an object named after the file.
    Open(PathBuf),
    /// Save the scene as a project (answered with [`Kind::Done`] `{saved}`).
    Save(PathBuf),
    /// Replace the scene by a project (every page gets [`Kind::Scene`]; the asker
    /// [`Kind::Done`] `{loaded}`).
    Load(PathBuf),
    /// Write object `id` to a file in the format of its extension ([`Kind::Done`]
    /// `{exported}`).
    Export(ObjectId, PathBuf),
}

/// The scene command of a sculpt request: its brush as a tool (a mesh object's centred,
/// unit-reach copy) placed unrotated at each point with scale `size`.
///
/// # Errors
/// A brush mesh that is missing, not a mesh or not closed.
fn sculpt_command(scene: &Scene, r: SculptRequest) -> Result<Command, SceneError> {
    let tool = match r.brush {
        Brush::Shape(shape) => volmorph_sculpt::brush(shape),
        Brush::Mesh(m) => Arc::new(volmorph_sculpt::unit_brush(scene.mesh(m)?)?),
    };
    let poses = r
        .points
        .iter()
        .map(|&p| volmorph_sculpt::Pose {
            scale: r.size,
            ..volmorph_sculpt::Pose::at(p)
        })
        .collect();
    Ok(Command::Sculpt {
        id: r.id,
        edit: volmorph_sculpt::Edit::Tool {
            tool,
            op: r.op,
            poses,
            step: None,
        },
    })
}

/// What a job produced.
enum Outcome {
    /// A scene change, pushed to every page as [`Kind::Changed`].
    Changed(Change),
    /// A [`Kind::Done`] header for the asker.
    Done(Value),
    /// A project replaced the scene: [`Kind::Scene`] to every page, [`Kind::Done`] to the
    /// asker.
    Loaded(Value),
}

impl Coalesce for Job {
    fn key(&self) -> Option<u64> {
        match &self.work {
            Work::Drag { gesture, .. } | Work::Parameters { gesture, .. } => Some(*gesture),
            Work::Command(_, g) | Work::Sculpt(_, g) => *g,
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
            (Work::Sculpt(a, gesture), Work::Sculpt(b, g)) if a.continues_with(&b) => {
                a.extend(b);
                *gesture = g;
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
    running: Arc<Running>,
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
    /// An editor over `scene`, taking jobs from `queue` and listing the one it runs in
    /// `running`.
    pub fn new(
        scene: Arc<RwLock<Scene>>,
        queue: Arc<Queue<Job>>,
        out: tokio::sync::broadcast::Sender<Outgoing>,
        running: Arc<Running>,
    ) -> Self {
        Self {
            scene,
            queue,
            out,
            running,
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
            let guard = self.running.begin(origin);
            let progress = Arc::clone(guard.progress());
            let result = {
                let lock = Arc::clone(&self.scene);
                if matches!(job.work, Work::Save(_) | Work::Export(..)) {
                    // Writing files only reads the scene: pages keep reading it meanwhile.
                    let scene = lock.read().unwrap_or_else(|p| p.into_inner());
                    Self::write(&scene, job.work, &*progress)
                        .map(|o| (o, scene.undo_depth(), scene.redo_depth()))
                } else {
                    let mut scene = lock.write().unwrap_or_else(|p| p.into_inner());
                    self.execute(&mut scene, job.work, &*progress)
                        .map(|o| (o, scene.undo_depth(), scene.redo_depth()))
                }
            };
            // No progress frame after the answer.
            drop(guard);
            let ms = started.elapsed().as_secs_f64() * 1e3;
            match result {
                Ok((Outcome::Done(h), ..)) => {
                    self.send(Some(origin.page), Frame::new(Kind::Done, origin.request, h));
                }
                Ok((Outcome::Loaded(h), ..)) => {
                    self.gestures.clear();
                    let f = {
                        let scene = self.scene.read().unwrap_or_else(|p| p.into_inner());
                        crate::views::scene_frame(&scene, 0)
                    };
                    self.send(None, f);
                    self.send(Some(origin.page), Frame::new(Kind::Done, origin.request, h));
                }
                Ok((Outcome::Changed(change), undo, redo)) => {
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

    /// A job that writes files (it only reads the scene).
    fn write(
        scene: &Scene,
        work: Work,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Outcome, SceneError> {
        match work {
            Work::Save(path) => {
                scene.save_with(&path, progress)?;
                Ok(Outcome::Done(json!({"saved": path.display().to_string()})))
            }
            Work::Export(id, path) => {
                scene.export_with(id, &path, progress)?;
                Ok(Outcome::Done(
                    json!({"exported": path.display().to_string()}),
                ))
            }
            _ => Err(SceneError::Invalid("not a job that writes files".into())),
        }
    }

    fn execute(
        &mut self,
        scene: &mut Scene,
        work: Work,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Outcome, SceneError> {
        match work {
            Work::Load(path) => {
                *scene = Scene::load_with(&path, progress)?;
                Ok(Outcome::Loaded(
                    json!({"loaded": path.display().to_string()}),
                ))
            }
            Work::Save(_) | Work::Export(..) => Self::write(scene, work, progress),
            work => self.edit(scene, work, progress).map(Outcome::Changed),
        }
    }

    /// Apply `command`; with a gesture, count it as one of the gesture's steps (merged into
    /// one undo step at its end).
    fn apply_in_gesture(
        &mut self,
        scene: &mut Scene,
        command: Command,
        gesture: Option<u64>,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Change, SceneError> {
        let depth = scene.undo_depth();
        let change = scene.apply_with(command, progress)?;
        if let Some(gesture) = gesture {
            self.gestures
                .entry(gesture)
                .or_insert(Gesture {
                    at: DVec3::ZERO,
                    steps: 0,
                    depth,
                })
                .steps += 1;
        }
        Ok(change)
    }

    fn edit(
        &mut self,
        scene: &mut Scene,
        work: Work,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Change, SceneError> {
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
                let change = scene.apply_with(
                    Command::DragPoints {
                        map,
                        grabbed: vec![g.at],
                        targets: vec![target],
                        options: DragOptions::with_radius(radius),
                    },
                    progress,
                )?;
                g.at = target;
                g.steps += 1;
                Ok(change)
            }
            Work::Parameters {
                gesture,
                map,
                changes,
            } => self.apply_in_gesture(
                scene,
                Command::SetParameters {
                    map,
                    changes: changes.into_iter().collect(),
                },
                Some(gesture),
                progress,
            ),
            Work::EndGesture { gesture } => {
                if let Some(g) = self.gestures.remove(&gesture) {
                    // Merge only if nothing else was applied in between.
                    if scene.undo_depth() == g.depth + g.steps {
                        scene.merge_last(g.steps);
                    }
                }
                Ok(Change::default())
            }
            Work::Undo => Ok(scene.undo_with(progress)?.unwrap_or_default()),
            Work::Redo => Ok(scene.redo_with(progress)?.unwrap_or_default()),
            Work::Command(c, gesture) => self.apply_in_gesture(scene, *c, gesture, progress),
            Work::Sculpt(r, gesture) => {
                let c = sculpt_command(scene, r)?;
                self.apply_in_gesture(scene, c, gesture, progress)
            }
            Work::Lobes(r) => {
                let c = crate::lobes::command(scene, r)?;
                scene.apply_with(c, progress)
            }
            Work::Setup(s) => s.run_with(scene, progress),
            Work::Open(path) => {
                let object = volmorph_scene::files::read_object_with(&path, progress)?;
                let name = path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                scene.apply_with(Command::Add { name, object }, progress)
            }
            Work::Save(_) | Work::Load(_) | Work::Export(..) => {
                Err(SceneError::Invalid("not an edit of the scene".into()))
            }
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
        Work::Command(..) | Work::Lobes(_) => "command",
        Work::Sculpt(..) => "sculpt",
        Work::Setup(_) => "setup",
        Work::Open(_) => "open",
        Work::Save(_) => "save",
        Work::Load(_) => "load",
        Work::Export(..) => "export",
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

/// An [`Kind::Error`] frame for `request`: the message, for F-rep source errors the line
/// and column, and `cancelled: true` for a job stopped by [`Kind::Cancel`].
pub fn error_frame(request: u32, e: &SceneError) -> Frame {
    let pos = match e {
        SceneError::Frep(f) => f.pos().map(|p| (p.line, p.col)),
        _ => None,
    };
    Frame::new(
        Kind::Error,
        request,
        json!({
            "message": if e.is_cancelled() { "cancelled".to_owned() } else { e.to_string() },
            "line": pos.map(|p| p.0),
            "column": pos.map(|p| p.1),
            "cancelled": e.is_cancelled(),
        }),
    )
}
