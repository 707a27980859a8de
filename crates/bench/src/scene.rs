//! The scene suite: the teapot's spout lowered by a drag (True 1992, Fig. 10), once through
//! the scene — [`Scene::apply`] of [`Command::DragPoints`] on a scene holding the teapot, an
//! identity lattice and the teapot pushed forward through it (antialiased), which inverts the
//! grabbed point, solves the least-norm control-point moves, updates the warped volume
//! incrementally and reports the dirty region — and once on the engines directly
//! ([`drags_from_deformed`], [`solve_drags`], [`IncrementalPushForward::set_parameters`]).
//! The difference is what the scene adds.
//!
//! Each run starts from the undeformed lattice: the scene's drag is taken back by
//! [`Scene::undo`], the engine's by setting the moved control points back, both outside the
//! clock. The two cases run alternately, so the overhead is taken run by run.

use std::time::Instant;

use glam::DVec3;
use serde_json::json;
use volmorph_lattice::{BSplineLattice, DragOptions, drags_from_deformed, solve_drags};
use volmorph_scene::{Change, Command, ObjectId, Scene, TeapotSession};
use volmorph_volume::Volume;
use volmorph_volume::phantom::TEAPOT_SPOUT_TIP;
use volmorph_warp::incremental::IncrementalPushForward;
use volmorph_warp::pushforward::AntialiasOptions;

use crate::targets::{ISSUE_13_SCENE_DRAG, ISSUE_13_SCENE_OVERHEAD};
use crate::timing::{Case, Item, Report, Sample, Unit};
use crate::warp::{EDIT_TARGET_SIZE, TARGET_LATTICE, teapot};
use crate::{BenchError, MAX_SIZE, check_repeat};

pub use volmorph_scene::teapot::{SPOUT_TARGET, TOOL_RADIUS};

/// Settings of the scene suite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SceneConfig {
    /// Voxels per axis of the teapot, 16 to [`MAX_SIZE`] (the target is stated at
    /// [`EDIT_TARGET_SIZE`]).
    pub size: usize,
    /// Control points per axis of the identity lattice, 4 to 64 (targets at
    /// [`TARGET_LATTICE`]).
    pub lattice: usize,
    /// Timed runs per case, 1 to [`crate::MAX_REPEAT`].
    pub repeat: usize,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            size: EDIT_TARGET_SIZE,
            lattice: TARGET_LATTICE,
            repeat: 9,
        }
    }
}

impl SceneConfig {
    /// Check every setting against its range.
    ///
    /// # Errors
    /// [`BenchError::Setting`] naming the first setting out of range.
    pub fn validate(&self) -> Result<(), BenchError> {
        BenchError::range("size", self.size, 16..=MAX_SIZE)?;
        BenchError::range("lattice", self.lattice, 4..=64)?;
        check_repeat(self.repeat)
    }

    fn at_target(&self) -> bool {
        self.size == EDIT_TARGET_SIZE && self.lattice == TARGET_LATTICE
    }
}

/// The inputs: the teapot and the identity lattice on its voxel centres.
#[derive(Debug)]
pub struct SceneInputs {
    /// The teapot's density.
    pub density: Volume<u8>,
    /// The identity lattice.
    pub lattice: BSplineLattice,
    at_target: bool,
}

/// A scene holding the teapot, the lattice and the warped teapot, with their ids (the one
/// teapot session of `volmorph demo` and the scene tests).
pub type TeapotScene = TeapotSession;

impl SceneInputs {
    /// Build the teapot and the lattice.
    ///
    /// # Errors
    /// [`BenchError`] from building them.
    pub fn new(config: &SceneConfig) -> Result<Self, BenchError> {
        let density = teapot(config.size)?;
        let lattice = BSplineLattice::identity_on_voxels(density.geometry(), [config.lattice; 3])?;
        Ok(Self {
            density,
            lattice,
            at_target: config.at_target(),
        })
    }

    /// The drag's options: the tool radius.
    #[must_use]
    pub fn options() -> DragOptions {
        DragOptions::with_radius(TOOL_RADIUS)
    }

    /// A new scene with the teapot, the lattice and the warped teapot (computed in full).
    ///
    /// # Errors
    /// [`BenchError::Scene`] from the commands; [`BenchError::Check`] if the warp failed.
    pub fn scene(&self) -> Result<TeapotScene, BenchError> {
        Ok(TeapotSession::with(
            self.density.clone(),
            self.lattice.clone(),
        )?)
    }

    /// The incremental push-forward engine of the teapot under the lattice.
    ///
    /// # Errors
    /// [`BenchError::Warp`].
    pub fn engine(&self) -> Result<IncrementalPushForward<BSplineLattice>, BenchError> {
        Ok(IncrementalPushForward::new(
            &self.density,
            self.lattice.clone(),
            self.density.geometry(),
            &AntialiasOptions::default(),
        )?)
    }

    /// The two cases: the drag through the scene (target [`ISSUE_13_SCENE_DRAG`] at 128³ and
    /// a 9³ lattice) and the same drag on the engines.
    ///
    /// # Errors
    /// [`BenchError`] from building the scene and the engine.
    pub fn cases(&self) -> Result<[Case<'static>; 2], BenchError> {
        let TeapotScene {
            mut scene,
            lattice,
            warped,
            ..
        } = self.scene()?;
        let through_scene = Case::new("drag through the scene", "scene_drag", move || {
            let start = Instant::now();
            let change = drag_through_scene(&mut scene, lattice, warped)?;
            let elapsed = start.elapsed();
            drop(change);
            scene.undo()?;
            Ok(Sample {
                elapsed,
                triangles: None,
            })
        })
        .with_target(self.at_target.then_some(ISSUE_13_SCENE_DRAG));

        let mut engine = self.engine()?;
        let base = self.lattice.control_points().to_vec();
        let on_engines = Case::new("same drag on the engines", "engine_drag", move || {
            let start = Instant::now();
            let changes = drag_on_engines(&mut engine)?;
            let elapsed = start.elapsed();
            let back: Vec<(usize, DVec3)> = changes.iter().map(|&(k, _)| (k, base[k])).collect();
            engine.set_parameters(&back)?;
            Ok(Sample {
                elapsed,
                triangles: None,
            })
        });
        Ok([through_scene, on_engines])
    }
}

/// The drag through the scene: [`Command::DragPoints`] of the spout tip to [`SPOUT_TARGET`]
/// with [`TOOL_RADIUS`] on map `lattice`, checked to have updated the warped volume `warped`
/// (no error, a dirty voxel box that is not empty).
///
/// # Errors
/// [`BenchError::Scene`] from the command, [`BenchError::Check`] for a failed or empty update.
pub fn drag_through_scene(
    scene: &mut Scene,
    lattice: ObjectId,
    warped: ObjectId,
) -> Result<Change, BenchError> {
    let change = scene.apply(Command::DragPoints {
        map: lattice,
        grabbed: vec![TEAPOT_SPOUT_TIP],
        targets: vec![SPOUT_TARGET],
        options: SceneInputs::options(),
    })?;
    if let Some((_, e)) = change.errors.first() {
        return Err(BenchError::check("drag through the scene", e.clone()));
    }
    if change
        .dirty_of(warped)
        .and_then(|d| d.voxels)
        .is_none_or(|b| b.is_empty())
    {
        return Err(BenchError::check(
            "drag through the scene",
            "the drag reported no dirty voxels",
        ));
    }
    Ok(change)
}

/// The same drag on the engines: the grabbed point's material point through the engine's
/// lattice ([`drags_from_deformed`]), the least-norm control-point moves ([`solve_drags`])
/// and the incremental update ([`IncrementalPushForward::set_parameters`]). Returns the
/// parameter changes applied.
///
/// # Errors
/// [`BenchError::Drag`], [`BenchError::Deform`], [`BenchError::Warp`] from the steps;
/// [`BenchError::Check`] if the update changed no voxel.
pub fn drag_on_engines(
    engine: &mut IncrementalPushForward<BSplineLattice>,
) -> Result<Vec<(usize, DVec3)>, BenchError> {
    let lat = engine.map();
    let drags = drags_from_deformed(lat, &[TEAPOT_SPOUT_TIP], &[SPOUT_TARGET])?;
    let solution = solve_drags(lat, &drags, &SceneInputs::options())?;
    let changes = lat.changes_for_displacements(solution.displacements())?;
    let report = engine.set_parameters(&changes)?;
    if report.output_box.is_empty() {
        return Err(BenchError::check(
            "same drag on the engines",
            "the drag changed no voxel",
        ));
    }
    Ok(changes)
}

/// Run the scene suite: the two cases alternately, `repeat` times each, and the overhead of
/// the scene run by run (target [`ISSUE_13_SCENE_OVERHEAD`]); `progress` hears what is being
/// built or timed.
///
/// # Errors
/// [`BenchError::Setting`] for a setting out of range, or the first run that fails.
pub fn run(config: &SceneConfig, progress: &mut dyn FnMut(&str)) -> Result<Report, BenchError> {
    config.validate()?;
    progress(&format!(
        "building the teapot {0}x{0}x{0}, its scene and engine",
        config.size
    ));
    let inputs = SceneInputs::new(config)?;
    let [mut through_scene, mut on_engines] = inputs.cases()?;
    progress("dragging the spout");
    let (mut a, mut b, mut d) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..config.repeat {
        let s = through_scene.run_once()?.elapsed.as_secs_f64();
        let e = on_engines.run_once()?.elapsed.as_secs_f64();
        a.push(s);
        b.push(e);
        d.push(s - e);
    }
    let overhead_target = config.at_target().then_some(ISSUE_13_SCENE_OVERHEAD);
    let items = vec![
        Item::new(through_scene.name(), a, through_scene.target()),
        Item::new(on_engines.name(), b, None),
        Item::new("scene overhead (run by run)", d, overhead_target),
    ];
    let description = format!(
        "teapot {n}x{n}x{n} under an identity {l}x{l}x{l} lattice, pushed forward (antialiased); \
         the spout tip {tip} dragged to {SPOUT_TARGET} with tool radius {TOOL_RADIUS}; {r} runs \
         each, alternating, {t} threads",
        n = config.size,
        l = config.lattice,
        tip = TEAPOT_SPOUT_TIP,
        r = config.repeat,
        t = rayon::current_num_threads(),
    );
    let mut report = Report::new(
        "scene",
        description,
        vec![
            ("size", json!(config.size)),
            ("lattice", json!(config.lattice)),
        ],
        config.repeat,
        Unit::Milliseconds,
        items,
    );
    if !config.at_target() {
        report.notes.push(format!(
            "(targets are stated for a {EDIT_TARGET_SIZE}^3 teapot and a {TARGET_LATTICE}^3 \
             lattice)"
        ));
    }
    Ok(report)
}
