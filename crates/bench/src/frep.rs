//! The F-rep suite: culled grid sampling of F-rep models (HyperFun language), each result
//! checked bit for bit against point-by-point evaluation, and [`RENDER_SIZE`]² ray-cast
//! pictures of them (the default view of `volmorph frep render`).
//!
//! The models are either the seven built-in [`SCENES`] — written for volmorph, comparable to
//! the published libfive/HyperFun benchmark scenes (a ball, CSG, a blend, a gyroid, a twist, a
//! gear and a colonnade) — or files a front-end compiles. Targets apply to the published
//! scenes themselves (see [`published_scene_target`]), at [`TARGET_GRID`]³ over
//! [`TARGET_BOUNDS`].

use std::time::Duration;

use glam::DVec3;
use serde_json::json;
use volmorph_frep::grid::{box_geometry, sample, sample_naive};
use volmorph_frep::output::{RenderOptions, render};
use volmorph_frep::{Shape, Tape, compile_source};
use volmorph_render::{Camera, Orbit, UpAxis};
use volmorph_volume::Geometry;

use crate::targets::{ISSUE_6_FREP_LARGE_SCENE, ISSUE_6_FREP_SMALL_SCENE, ISSUE_16_FREP_RENDER};
use crate::timing::{Case, Item, Report, Unit};
use crate::{BenchError, check_repeat};

/// Grid points per axis at which the targets are stated (the published benchmark's grid).
pub const TARGET_GRID: usize = 193;
/// The box at which the targets are stated: `[−1.6, 1.6]³`.
pub const TARGET_BOUNDS: (DVec3, DVec3) = (DVec3::splat(-1.6), DVec3::splat(1.6));
/// Side of the timed pictures, in pixels.
pub const RENDER_SIZE: u32 = 512;
/// Azimuth and elevation (degrees, z up) of the timed pictures: `volmorph frep render`'s
/// default view.
pub const RENDER_VIEW: (f64, f64) = (35.0, 25.0);

/// Largest grid points per axis accepted (a 2048³ `f32` volume is 32 GiB).
pub const MAX_GRID: usize = 2048;

/// The built-in scenes, `(name, HyperFun source)`.
pub const SCENES: [(&str, &str); 7] = [
    ("sphere", include_str!("../scenes/sphere.hf")),
    ("csg", include_str!("../scenes/csg.hf")),
    ("blend", include_str!("../scenes/blend.hf")),
    ("gyroid", include_str!("../scenes/gyroid.hf")),
    ("twist", include_str!("../scenes/twist.hf")),
    ("gear", include_str!("../scenes/gear.hf")),
    ("colonnade", include_str!("../scenes/colonnade.hf")),
];

/// The target median of a published benchmark scene, by its file stem: the published
/// libfive figures rounded down — [`ISSUE_6_FREP_SMALL_SCENE`] for `s1`–`s5` (stems starting
/// with `s` and a digit), [`ISSUE_6_FREP_LARGE_SCENE`] for the gear and colonnade (stems
/// containing `gear` or `colonnade`, e.g. `c1_gear`); `None` for other models.
#[must_use]
pub fn published_scene_target(stem: &str) -> Option<Duration> {
    let stem = stem.to_lowercase();
    if stem.starts_with('s') && stem[1..].starts_with(|c: char| c.is_ascii_digit()) {
        Some(ISSUE_6_FREP_SMALL_SCENE)
    } else if stem.contains("gear") || stem.contains("colonnade") {
        Some(ISSUE_6_FREP_LARGE_SCENE)
    } else {
        None
    }
}

/// A model to time.
#[derive(Debug, Clone)]
pub struct FrepModel {
    /// Name shown in reports (a file path, or a built-in scene's name).
    pub name: String,
    /// The compiled model.
    pub shape: Shape,
    /// Its target median at [`TARGET_GRID`]³ over [`TARGET_BOUNDS`], if any.
    pub target: Option<Duration>,
}

/// The built-in [`SCENES`], compiled, without targets (they resemble the published scenes
/// but are not them).
///
/// # Errors
/// [`BenchError::Frep`] if a scene does not compile (a defect).
pub fn builtin_scenes() -> Result<Vec<FrepModel>, BenchError> {
    SCENES
        .iter()
        .map(|(name, src)| {
            Ok(FrepModel {
                name: (*name).to_owned(),
                shape: compile_source(src, &Default::default())?,
                target: None,
            })
        })
        .collect()
}

/// Settings of the F-rep suite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrepConfig {
    /// Grid points per axis, 2 to [`MAX_GRID`].
    pub grid: usize,
    /// The box sampled, `(lo, hi)` (voxel centres on its faces).
    pub bounds: (DVec3, DVec3),
    /// Timed runs per model, 1 to [`crate::MAX_REPEAT`].
    pub repeat: usize,
    /// Compare each result with point-by-point evaluation.
    pub check: bool,
}

impl Default for FrepConfig {
    fn default() -> Self {
        Self {
            grid: TARGET_GRID,
            bounds: TARGET_BOUNDS,
            repeat: 5,
            check: true,
        }
    }
}

impl FrepConfig {
    /// Check every setting against its range and build the grid.
    ///
    /// # Errors
    /// [`BenchError::Setting`] naming the first setting out of range; [`BenchError::Frep`]
    /// for an empty or non-finite box.
    pub fn geometry(&self) -> Result<Geometry, BenchError> {
        BenchError::range("grid", self.grid, 2..=MAX_GRID)?;
        check_repeat(self.repeat)?;
        Ok(box_geometry(self.bounds.0, self.bounds.1, [self.grid; 3])?)
    }

    /// Whether the targets apply: the target grid over the target box.
    #[must_use]
    pub fn at_target(&self) -> bool {
        self.grid == TARGET_GRID && self.bounds == TARGET_BOUNDS
    }
}

/// The inputs: each model's evaluation tape and the grid.
#[derive(Debug)]
pub struct FrepInputs {
    /// `(model, its tape)`.
    pub tapes: Vec<(FrepModel, Tape)>,
    /// The sampled grid.
    pub geometry: Geometry,
    /// The camera of the timed pictures ([`RENDER_SIZE`]², [`RENDER_VIEW`], framing the box).
    pub camera: Camera,
    /// Ray-casting options (the box, defaults otherwise).
    pub render: RenderOptions,
    at_target: bool,
    render_at_target: bool,
}

impl FrepInputs {
    /// Build the tapes and the grid.
    ///
    /// # Errors
    /// As [`FrepConfig::geometry`].
    pub fn new(config: &FrepConfig, models: Vec<FrepModel>) -> Result<Self, BenchError> {
        let geometry = config.geometry()?;
        let camera = Orbit::new(RENDER_VIEW.0, RENDER_VIEW.1, UpAxis::Z)
            .and_then(|o| o.model_camera(config.bounds, (RENDER_SIZE, RENDER_SIZE)))
            .map_err(|e| BenchError::check("F-rep picture", e.to_string()))?;
        let render = RenderOptions {
            bounds_min: config.bounds.0,
            bounds_max: config.bounds.1,
            ..RenderOptions::default()
        };
        Ok(Self {
            tapes: models
                .into_iter()
                .map(|m| {
                    let t = Tape::new(&m.shape);
                    (m, t)
                })
                .collect(),
            geometry,
            camera,
            render,
            at_target: config.at_target(),
            render_at_target: config.bounds == TARGET_BOUNDS,
        })
    }

    /// One case per model: culled grid sampling of its tape (criterion id: the model's name).
    #[must_use]
    pub fn cases(&self) -> Vec<Case<'_>> {
        self.tapes
            .iter()
            .map(|(m, tape)| {
                Case::call(m.name.clone(), m.name.clone(), move || {
                    Ok(sample(tape, &self.geometry)?)
                })
                .with_target(m.target.filter(|_| self.at_target))
            })
            .collect()
    }

    /// One case per model: its [`RENDER_SIZE`]² picture (criterion id: the model's name and
    /// `render`), with the target [`ISSUE_16_FREP_RENDER`] for the published scenes over
    /// [`TARGET_BOUNDS`].
    #[must_use]
    pub fn render_cases(&self) -> Vec<Case<'_>> {
        self.tapes
            .iter()
            .map(|(m, tape)| {
                let name = format!("{} render {RENDER_SIZE}x{RENDER_SIZE}", m.name);
                Case::call(name, format!("{}/render", m.name), move || {
                    Ok(render(tape, &self.camera, &self.render)?)
                })
                .with_target(
                    Some(ISSUE_16_FREP_RENDER)
                        .filter(|_| m.target.is_some() && self.render_at_target),
                )
            })
            .collect()
    }

    /// Whether model `k`'s culled sampling equals point-by-point evaluation bit for bit.
    ///
    /// # Errors
    /// [`BenchError::Frep`] from sampling; [`BenchError::Check`] for `k` out of range.
    pub fn same_as_pointwise(&self, k: usize) -> Result<bool, BenchError> {
        let (_, tape) = self
            .tapes
            .get(k)
            .ok_or_else(|| BenchError::check("F-rep check", format!("no model {k}")))?;
        let fast = sample(tape, &self.geometry)?;
        let naive = sample_naive(tape, &self.geometry)?;
        Ok(fast
            .data()
            .iter()
            .zip(naive.data())
            .all(|(x, y)| x.to_bits() == y.to_bits()))
    }
}

/// Run the F-rep suite on `models`; `progress` hears what is being timed.
///
/// # Errors
/// [`BenchError::Setting`] for a setting out of range, or the first model that fails.
pub fn run(
    config: &FrepConfig,
    models: Vec<FrepModel>,
    progress: &mut dyn FnMut(&str),
) -> Result<Report, BenchError> {
    let inputs = FrepInputs::new(config, models)?;
    let mut items: Vec<Item> = Vec::with_capacity(inputs.tapes.len());
    for (k, mut case) in inputs.cases().into_iter().enumerate() {
        progress(case.name());
        let mut item = case.measure(config.repeat)?;
        item.operations = Some(inputs.tapes[k].1.len());
        if config.check {
            progress(&format!("{}: point-by-point check", case.name()));
            item.same_as_pointwise = Some(inputs.same_as_pointwise(k)?);
        }
        items.push(item);
    }
    for (k, mut case) in inputs.render_cases().into_iter().enumerate() {
        progress(case.name());
        let mut item = case.measure(config.repeat)?;
        item.operations = Some(inputs.tapes[k].1.len());
        items.push(item);
    }
    let (lo, hi) = config.bounds;
    let description = format!(
        "F-rep grid evaluation, {g}^3 over {lo}..{hi}, and {s}x{s} pictures, {r} runs, {t} threads",
        g = config.grid,
        s = RENDER_SIZE,
        r = config.repeat,
        t = rayon::current_num_threads()
    );
    let mut report = Report::new(
        "frep",
        description,
        vec![
            ("grid", json!(config.grid)),
            ("bounds", json!([lo.to_array(), hi.to_array()])),
        ],
        config.repeat,
        Unit::Milliseconds,
        items,
    );
    if !config.at_target() {
        report.notes.push(format!(
            "(targets are stated for a {TARGET_GRID}^3 grid over {}..{})",
            TARGET_BOUNDS.0, TARGET_BOUNDS.1
        ));
    }
    Ok(report)
}
