//! The warp suite: pull-back (trilinear, cubic B-spline), push-forward (nearest,
//! antialiased) and the Jacobian determinant map of a randomly moved cubic lattice on the
//! teapot phantom, and the interactive edits on a smaller teapot: the incremental update of
//! the antialiased push-forward after one control point moves, and a drag (least-norm solve
//! plus incremental update).

use std::time::{Duration, Instant};

use glam::DVec3;
use serde_json::json;
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::manipulate::{Drag, DragOptions, ManipulationSession};
use volmorph_testkit::Rng;
use volmorph_volume::phantom::{self, Phantom};
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::incremental::IncrementalPushForward;
use volmorph_warp::jacobian::jacobian_determinant;
use volmorph_warp::pullback::{ResampleOptions, resample};
use volmorph_warp::pushforward::{
    AntialiasOptions, FaceCentres, push_forward_antialiased, push_forward_antialiased_f32,
    push_forward_nearest,
};

use crate::targets::{
    ISSUE_3_DRAG, ISSUE_22_INCREMENTAL_UPDATE, ISSUE_22_PULLBACK_TRILINEAR,
    ISSUE_22_PUSHFORWARD_ANTIALIASED,
};
use crate::timing::{Case, Report, Sample, Unit, measure_all};
use crate::{BenchError, MAX_SIZE, SEED, check_repeat};

/// Voxels per axis of the teapot at which the warp targets are stated.
pub const TARGET_SIZE: usize = 256;
/// Voxels per axis of the teapot at which the editing targets are stated.
pub const EDIT_TARGET_SIZE: usize = 128;
/// Control points per axis at which every target of the suite is stated.
pub const TARGET_LATTICE: usize = 9;

/// Settings of the warp suite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WarpConfig {
    /// Voxels per axis of the teapot phantom (a cube), 4 to [`MAX_SIZE`].
    pub size: usize,
    /// Control points per axis of the uniform cubic lattice, 4 to 64.
    pub lattice: usize,
    /// Voxels per axis of the teapot of the editing cases, 8 to [`MAX_SIZE`].
    pub edit_size: usize,
    /// Timed runs per case, 1 to [`crate::MAX_REPEAT`].
    pub repeat: usize,
}

impl Default for WarpConfig {
    fn default() -> Self {
        Self {
            size: TARGET_SIZE,
            lattice: TARGET_LATTICE,
            edit_size: EDIT_TARGET_SIZE,
            repeat: 5,
        }
    }
}

impl WarpConfig {
    /// Check every setting against its range.
    ///
    /// # Errors
    /// [`BenchError::Setting`] naming the first setting out of range.
    pub fn validate(&self) -> Result<(), BenchError> {
        BenchError::range("size", self.size, 4..=MAX_SIZE)?;
        BenchError::range("lattice", self.lattice, 4..=64)?;
        BenchError::range("edit_size", self.edit_size, 8..=MAX_SIZE)?;
        check_repeat(self.repeat)
    }
}

/// The teapot phantom's density (`u8`, the surface at 127) on a `size³` grid over the model
/// frame `[−1.1, 1.1]³`.
///
/// # Errors
/// [`BenchError::Volume`] when the volume does not fit.
pub fn teapot(size: usize) -> Result<Volume<u8>, BenchError> {
    Ok(phantom::density(Phantom::Teapot, [size; 3])?)
}

/// True's uniform cubic lattice of `counts³` control points on the voxel-centre box of `grid`
/// (identity placement), every control point off the outer layer moved by a random vector
/// (seed `seed`) whose components are uniform in `[−½, ½)` region along each axis (length at
/// most about 0.87 region): a strong but typical modelling deformation.
///
/// # Errors
/// [`BenchError::Deform`] for fewer than 4 control points per axis or a degenerate grid.
pub fn moved_lattice(
    grid: &Geometry,
    counts: usize,
    seed: u64,
) -> Result<BSplineLattice, BenchError> {
    let mut lat = BSplineLattice::identity_on_voxels(grid, [counts; 3])?;
    let extent = grid.spacing
        * DVec3::new(
            grid.dims[0].saturating_sub(1) as f64,
            grid.dims[1].saturating_sub(1) as f64,
            grid.dims[2].saturating_sub(1) as f64,
        );
    let region = grid.direction * (extent / (counts - 3) as f64);
    let mut rng = Rng::new(seed);
    for k in 1..counts - 1 {
        for j in 1..counts - 1 {
            for i in 1..counts - 1 {
                lat.move_control_point([i, j, k], region * rng.point(0.5))?;
            }
        }
    }
    Ok(lat)
}

/// The inputs of the warp cases: the teapot (`u8` and `f32`) and the moved lattice.
#[derive(Debug)]
pub struct WarpInputs {
    /// The teapot's density.
    pub density: Volume<u8>,
    /// The same as `f32` (the pull-back input).
    pub input: Volume<f32>,
    /// The teapot's grid, also the output grid.
    pub grid: Geometry,
    /// The moved lattice ([`moved_lattice`] with [`SEED`]).
    pub lattice: BSplineLattice,
    at_target: bool,
}

impl WarpInputs {
    /// Build the inputs for `config.size` and `config.lattice`.
    ///
    /// # Errors
    /// [`BenchError`] from building the volume or the lattice.
    pub fn new(config: &WarpConfig) -> Result<Self, BenchError> {
        let density = teapot(config.size)?;
        let grid = *density.geometry();
        let input = density.cast();
        let lattice = moved_lattice(&grid, config.lattice, SEED)?;
        Ok(Self {
            density,
            input,
            grid,
            lattice,
            at_target: config.size == TARGET_SIZE && config.lattice == TARGET_LATTICE,
        })
    }

    /// The suite's warp cases, with their targets at [`TARGET_SIZE`] and [`TARGET_LATTICE`].
    #[must_use]
    pub fn cases(&self) -> Vec<Case<'_>> {
        let at = |t: Duration| self.at_target.then_some(t);
        let (lat, grid) = (&self.lattice, &self.grid);
        let aa = AntialiasOptions::default();
        vec![
            self.pull_back(
                "pull-back trilinear (f32)",
                "pullback_trilinear",
                Interpolation::Linear,
            )
            .with_target(at(ISSUE_22_PULLBACK_TRILINEAR)),
            self.pull_back(
                "pull-back cubic B-spline (f32)",
                "pullback_cubic",
                Interpolation::CubicBSpline,
            ),
            Case::call(
                "push-forward nearest (u8)",
                "pushforward_nearest",
                move || Ok(push_forward_nearest(&self.density, lat, grid)?),
            ),
            Case::call(
                "push-forward antialiased (u8)",
                "pushforward_antialiased",
                move || Ok(push_forward_antialiased(&self.density, lat, grid, &aa)?),
            )
            .with_target(at(ISSUE_22_PUSHFORWARD_ANTIALIASED)),
            Case::call(
                "Jacobian determinant map",
                "jacobian_determinant",
                move || Ok(jacobian_determinant(lat, grid)?),
            ),
        ]
    }

    /// Variants measured by the criterion benches only: the nearest-neighbour pull-back and
    /// the antialiased push-forward with mapped (instead of True's averaged) face centres.
    #[must_use]
    pub fn extra_cases(&self) -> Vec<Case<'_>> {
        let (lat, grid) = (&self.lattice, &self.grid);
        let mapped = AntialiasOptions {
            face_centres: FaceCentres::Mapped,
            ..AntialiasOptions::default()
        };
        vec![
            self.pull_back(
                "pull-back nearest (f32)",
                "pullback_nearest",
                Interpolation::Nearest,
            ),
            Case::call(
                "push-forward antialiased, mapped faces (u8)",
                "pushforward_antialiased_mapped_faces",
                move || Ok(push_forward_antialiased(&self.density, lat, grid, &mapped)?),
            ),
        ]
    }

    fn pull_back(
        &self,
        name: &'static str,
        id: &'static str,
        interpolation: Interpolation,
    ) -> Case<'_> {
        let options = ResampleOptions::new(interpolation, 0.0);
        Case::call(name, id, move || {
            Ok(resample::<f32, f32, _>(
                &self.input,
                &self.lattice,
                &self.grid,
                &options,
            )?)
        })
    }
}

/// The inputs of the editing cases: a smaller teapot under the identity lattice, its centre
/// control point, the step it moves by and the drag that moves it.
#[derive(Debug)]
pub struct EditInputs {
    /// The teapot's density at `edit_size³`.
    pub density: Volume<u8>,
    /// Its grid.
    pub grid: Geometry,
    /// The identity lattice of `lattice³` control points on the grid's voxel centres.
    pub base: BSplineLattice,
    /// Index of the centre control point.
    pub centre_index: [usize; 3],
    /// Position of the centre control point (the grabbed point of the drag).
    pub centre: DVec3,
    /// Distance between neighbouring control points.
    pub region: f64,
    /// The step: about a third of a region, off the axes.
    pub step: DVec3,
    at_target: bool,
}

impl EditInputs {
    /// Build the inputs for `config.edit_size` and `config.lattice`.
    ///
    /// # Errors
    /// [`BenchError`] from building the volume or the lattice.
    pub fn new(config: &WarpConfig) -> Result<Self, BenchError> {
        let density = teapot(config.edit_size)?;
        let grid = *density.geometry();
        let base = BSplineLattice::identity_on_voxels(&grid, [config.lattice; 3])?;
        let c = config.lattice / 2;
        let centre = base.control_point([c, c, c])?;
        let region = (base.control_point([c + 1, c, c])? - centre).length();
        Ok(Self {
            density,
            grid,
            base,
            centre_index: [c; 3],
            centre,
            region,
            step: DVec3::new(0.3, -0.2, 0.25) * region,
            at_target: config.edit_size == EDIT_TARGET_SIZE && config.lattice == TARGET_LATTICE,
        })
    }

    /// The incremental push-forward engine on the teapot under the identity lattice.
    ///
    /// # Errors
    /// [`BenchError::Warp`].
    pub fn engine(&self) -> Result<IncrementalPushForward<BSplineLattice>, BenchError> {
        Ok(IncrementalPushForward::new(
            &self.density,
            self.base.clone(),
            &self.grid,
            &AntialiasOptions::default(),
        )?)
    }

    /// The editing cases, with their targets at [`EDIT_TARGET_SIZE`] and [`TARGET_LATTICE`]:
    ///
    /// * the engine updated after the centre control point moves by [`step`](Self::step),
    ///   alternately there and back (so the state stays bounded);
    /// * a drag of the point at that control point's place by the step with a tool radius of
    ///   half a region (so the least-norm solve moves that one control point): solve plus
    ///   update, each run from the identity lattice (restored by undo outside the clock).
    ///
    /// # Errors
    /// [`BenchError`] from building the engines or the drag session.
    pub fn cases(&self) -> Result<Vec<Case<'_>>, BenchError> {
        let at = |t: Duration| self.at_target.then_some(t);
        let mut engine = self.engine()?;
        let mut sign = -1.0;
        let update = Case::call(
            "incremental update, 1 control pt",
            "incremental_update",
            move || {
                sign = -sign;
                let changes = engine
                    .map()
                    .changes_for_displacements(&[(self.centre_index, self.step * sign)])?;
                Ok(engine.set_parameters(&changes)?)
            },
        )
        .with_target(at(ISSUE_22_INCREMENTAL_UPDATE));

        let mut engine = self.engine()?;
        let mut session = ManipulationSession::new(
            self.base.clone(),
            DragOptions::with_radius(0.5 * self.region),
        )?;
        let drag = Drag::new(self.centre, self.centre + self.step);
        let drag = Case::new("drag: solve + incremental update", "drag", move || {
            let start = Instant::now();
            session.drag(&[drag])?;
            engine.set_map(session.lattice().clone())?;
            let elapsed = start.elapsed();
            session.undo();
            engine.set_map(session.lattice().clone())?;
            Ok(Sample {
                elapsed,
                triangles: None,
            })
        })
        .with_target(at(ISSUE_3_DRAG));
        Ok(vec![update, drag])
    }

    /// Measured by the criterion benches only, for scale: the full antialiased push-forward
    /// of the same teapot and the engine's set-up.
    #[must_use]
    pub fn extra_cases(&self) -> Vec<Case<'_>> {
        let options = AntialiasOptions::default();
        vec![
            Case::call(
                "full push-forward (f32)",
                "full_push_forward_f32",
                move || {
                    Ok(push_forward_antialiased_f32(
                        &self.density,
                        &self.base,
                        &self.grid,
                        &options,
                    )?)
                },
            ),
            Case::call("engine set-up", "engine_set_up", move || self.engine()),
        ]
    }
}

/// Run the warp suite; `progress` hears what is being built or timed.
///
/// # Errors
/// [`BenchError::Setting`] for a setting out of range, or the first case that fails.
pub fn run(config: &WarpConfig, progress: &mut dyn FnMut(&str)) -> Result<Report, BenchError> {
    config.validate()?;
    progress(&format!(
        "building the teapot phantom {0}x{0}x{0}",
        config.size
    ));
    let inputs = WarpInputs::new(config)?;
    let mut items = measure_all(inputs.cases(), config.repeat, progress)?;
    drop(inputs);
    progress("building the editing inputs");
    let edit = EditInputs::new(config)?;
    items.extend(measure_all(edit.cases()?, config.repeat, progress)?);
    let l = config.lattice;
    let description = format!(
        "teapot {n}x{n}x{n}, lattice {l}x{l}x{l} moved at random (seed {SEED:#x}); editing on \
         a {e}x{e}x{e} teapot; {r} runs each, {t} threads",
        n = config.size,
        e = config.edit_size,
        r = config.repeat,
        t = rayon::current_num_threads(),
    );
    let mut report = Report::new(
        "warp",
        description,
        vec![
            ("size", json!(config.size)),
            ("lattice", json!(l)),
            ("edit_size", json!(config.edit_size)),
        ],
        config.repeat,
        Unit::Seconds,
        items,
    );
    if config.size != TARGET_SIZE
        || config.edit_size != EDIT_TARGET_SIZE
        || config.lattice != TARGET_LATTICE
    {
        report.notes.push(format!(
            "(targets are stated for a {TARGET_SIZE}^3 teapot, the editing items' for \
             {EDIT_TARGET_SIZE}^3, with a {TARGET_LATTICE}^3 lattice)"
        ));
    }
    Ok(report)
}
