//! The mesh FFD suite: the accurate B-spline FFD (Feng 2002: plan and trimmed Bézier
//! surfaces) of a UV sphere, and vertex FFD of a finer sphere, each through a randomly moved
//! 6×8×6 degree-2 lattice; and the evaluation of a trivariate spline map with its
//! derivatives (point and gradient of a rational tricubic volume, Martin & Cohen §4).

use std::sync::Arc;
use std::time::Duration;

use glam::DVec3;
use serde_json::json;
use volmorph_deform::SpaceMap;
use volmorph_ffd::accurate::{AccuratePlan, TrimmedModel};
use volmorph_ffd::baseline::vertex_ffd;
use volmorph_ffd::shapes::uv_sphere;
use volmorph_ffd::step::step_string;
use volmorph_lattice::BSplineLattice;
use volmorph_mesh::Mesh;
use volmorph_spline::TensorBSpline;
use volmorph_testkit::Rng;
use volmorph_trivariate::examples::rational_tricubic_8cubed;
use volmorph_trivariate::{EvalMethod, VolumeEvaluator};

use crate::targets::{
    ISSUE_4_ACCURATE_FFD, ISSUE_22_TRIVARIATE_POINTS_PER_SECOND, ISSUE_22_VERTEX_FFD,
};
use crate::timing::{Case, Rate, RateUnit, Report, Unit, measure_all};
use crate::{BenchError, SEED, check_repeat};

/// Rings of the accurate-FFD sphere at which its target is stated: 4·133·132 = 70 224
/// triangles.
pub const TARGET_RINGS: u32 = 133;
/// Rings of the vertex-FFD sphere at which its target is stated: 2·708·707 + 2 = 1 001 114
/// vertices.
pub const TARGET_VERTEX_RINGS: u32 = 708;
/// Control points per axis of the lattice.
pub const LATTICE_COUNTS: [usize; 3] = [6, 8, 6];
/// Degree per axis of the lattice.
pub const LATTICE_DEGREE: [usize; 3] = [2, 2, 2];
/// Random parameter triples of the trivariate point-and-gradient batch at which issue 22
/// states its rate.
pub const TRIVARIATE_POINTS: usize = 1 << 20;
/// Most parameter triples of the trivariate batch (2²⁴: 1.6 GB of parameters and results).
pub const MAX_TRIVARIATE_POINTS: usize = 1 << 24;

/// Settings of the FFD suite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FfdConfig {
    /// Latitude rings of the accurate-FFD sphere (4·r·(r−1) triangles), 2 to 2048.
    pub rings: u32,
    /// Latitude rings of the vertex-FFD sphere (2·r·(r−1)+2 vertices), 2 to 2048.
    pub vertex_rings: u32,
    /// Parameter triples of the trivariate point-and-gradient batch, 1 to
    /// [`MAX_TRIVARIATE_POINTS`].
    pub points: usize,
    /// Timed runs per case, 1 to [`crate::MAX_REPEAT`].
    pub repeat: usize,
}

impl Default for FfdConfig {
    fn default() -> Self {
        Self {
            rings: TARGET_RINGS,
            vertex_rings: TARGET_VERTEX_RINGS,
            points: TRIVARIATE_POINTS,
            repeat: 3,
        }
    }
}

impl FfdConfig {
    /// Check every setting against its range.
    ///
    /// # Errors
    /// [`BenchError::Setting`] naming the first setting out of range.
    pub fn validate(&self) -> Result<(), BenchError> {
        BenchError::range("rings", self.rings, 2..=2048)?;
        BenchError::range("vertex_rings", self.vertex_rings, 2..=2048)?;
        BenchError::range("points", self.points, 1..=MAX_TRIVARIATE_POINTS)?;
        check_repeat(self.repeat)
    }
}

/// Feng's end-interpolating degree-2 lattice of [`LATTICE_COUNTS`] control points around
/// `mesh` (identity Jacobian), every control point moved by a random vector (seed `seed`) with
/// components uniform in ±5 % of the box's longest side.
///
/// # Errors
/// [`BenchError::Check`] for an empty mesh, [`BenchError::Deform`] for a degenerate box.
pub fn moved_lattice(mesh: &Mesh, seed: u64) -> Result<BSplineLattice, BenchError> {
    let (lo, hi) = mesh
        .bounding_box()
        .ok_or_else(|| BenchError::check("FFD lattice", "the mesh is empty"))?;
    let mut lat =
        BSplineLattice::feng_end_interpolating_around(lo, hi, LATTICE_DEGREE, LATTICE_COUNTS)?;
    let size = (hi - lo).max_element();
    let mut rng = Rng::new(seed);
    let [nu, nv, nw] = LATTICE_COUNTS;
    for k in 0..nw {
        for j in 0..nv {
            for i in 0..nu {
                lat.move_control_point([i, j, k], rng.point(0.05) * size)?;
            }
        }
    }
    Ok(lat)
}

/// The inputs: the two unit spheres at the origin and a moved lattice around each, and the
/// accurate FFD of the first (for the STEP-writing case).
#[derive(Debug)]
pub struct FfdInputs {
    /// The accurate-FFD sphere.
    pub sphere: Mesh,
    /// The lattice around it.
    pub lattice: BSplineLattice,
    /// The vertex-FFD sphere.
    pub big: Mesh,
    /// The lattice around it.
    pub big_lattice: BSplineLattice,
    /// The accurate FFD of `sphere` through `lattice`, the input of the STEP-writing case.
    pub model: TrimmedModel,
    /// The rational tricubic volume of the point-and-gradient case
    /// ([`rational_tricubic_8cubed`]).
    pub volume: TensorBSpline<3>,
    /// Its parameter triples ([`FfdConfig::points`] of them), uniform in the unit cube
    /// (seeded).
    pub params: Vec<[f64; 3]>,
    rings: u32,
    vertex_rings: u32,
}

impl FfdInputs {
    /// Build the spheres and lattices, and the accurate FFD of the first sphere.
    ///
    /// # Errors
    /// [`BenchError`] from building the meshes or lattices.
    pub fn new(config: &FfdConfig) -> Result<Self, BenchError> {
        let sphere = uv_sphere(config.rings, 1.0, DVec3::ZERO)?;
        let lattice = moved_lattice(&sphere, SEED)?;
        let big = uv_sphere(config.vertex_rings, 1.0, DVec3::ZERO)?;
        let big_lattice = moved_lattice(&big, SEED)?;
        let model = Arc::new(AccuratePlan::new(&sphere, &lattice)?).deform(&lattice)?;
        let volume = rational_tricubic_8cubed()
            .map_err(|e| BenchError::check("trivariate volume", e.to_string()))?;
        let mut rng = Rng::new(SEED);
        let params = (0..config.points)
            .map(|_| [rng.unit(), rng.unit(), rng.unit()])
            .collect();
        Ok(Self {
            sphere,
            lattice,
            big,
            big_lattice,
            model,
            volume,
            params,
            rings: config.rings,
            vertex_rings: config.vertex_rings,
        })
    }

    /// The accurate FFD, plan and surfaces (counting Bézier patches in the triangles column),
    /// vertex FFD (a new mesh), with their targets at the target sizes (issue 4's for the
    /// accurate FFD, issue 22's for vertex FFD), vertex FFD into a preallocated buffer (the
    /// map evaluation without the mesh: no face copy, no fresh pages), the STEP text of the
    /// accurate FFD's result (written to memory: the formatting, not the disk), and the
    /// trivariate point-and-gradient evaluation with issue 22's rate.
    #[must_use]
    pub fn cases(&self) -> Vec<Case<'_>> {
        let at = |yes: bool, t: Duration| yes.then_some(t);
        let mut out = vec![DVec3::ZERO; self.big.vertex_count()];
        vec![
            Case::call_counting(
                "accurate FFD (plan + surfaces)",
                "accurate_plan_and_surfaces",
                move || {
                    let plan = Arc::new(AccuratePlan::new(&self.sphere, &self.lattice)?);
                    Ok(plan.deform(&self.lattice)?)
                },
                |m| m.stats.patches,
            )
            .with_target(at(self.rings == TARGET_RINGS, ISSUE_4_ACCURATE_FFD)),
            Case::call("vertex FFD", "vertex_ffd", move || {
                Ok(vertex_ffd(&self.big, &self.big_lattice)?)
            })
            .with_target(at(
                self.vertex_rings == TARGET_VERTEX_RINGS,
                ISSUE_22_VERTEX_FFD,
            )),
            Case::call(
                "vertex FFD, positions only",
                "vertex_ffd_positions",
                move || {
                    Ok(self
                        .big_lattice
                        .apply_batch(self.big.positions(), &mut out)?)
                },
            ),
            Case::call("STEP text of the accurate FFD", "step_writing", move || {
                Ok(step_string(&self.model, "bench")?)
            }),
            self.trivariate_case(),
        ]
    }

    /// Point and gradient of [`FfdInputs::volume`] at every parameter triple (refinement
    /// evaluation, rayon over the batch), with issue 22's rate as the time of the batch.
    fn trivariate_case(&self) -> Case<'_> {
        let n = self.params.len();
        let dim = self.volume.dim();
        let (mut values, mut gradients) = (vec![0.0; n * dim], vec![0.0; n * 3 * dim]);
        let e = VolumeEvaluator::new(&self.volume);
        let target = Duration::from_secs_f64(n as f64 / ISSUE_22_TRIVARIATE_POINTS_PER_SECOND);
        Case::call(
            "trivariate point + gradient",
            "trivariate_point_gradient",
            move || {
                e.eval_batch(
                    EvalMethod::Refinement,
                    &self.params,
                    &mut values,
                    &mut gradients,
                )
                .map_err(|e| BenchError::check("trivariate evaluation", e.to_string()))
            },
        )
        .with_target((n == TRIVARIATE_POINTS).then_some(target))
        .with_rate(Rate {
            work: n as f64,
            unit: RateUnit::MegapointsPerSecond,
        })
    }

    /// Measured by the criterion benches only: the accurate FFD's surfaces with the plan
    /// reused (an interactive edit of the lattice).
    ///
    /// # Errors
    /// [`BenchError::Ffd`] from planning.
    pub fn extra_cases(&self) -> Result<Vec<Case<'_>>, BenchError> {
        let plan = Arc::new(AccuratePlan::new(&self.sphere, &self.lattice)?);
        Ok(vec![Case::call(
            "accurate FFD, surfaces only",
            "accurate_surfaces_only",
            move || Ok(plan.deform(&self.lattice)?),
        )])
    }
}

/// Run the FFD suite; `progress` hears what is being built or timed.
///
/// # Errors
/// [`BenchError::Setting`] for a setting out of range, or the first case that fails.
pub fn run(config: &FfdConfig, progress: &mut dyn FnMut(&str)) -> Result<Report, BenchError> {
    config.validate()?;
    progress("building the spheres");
    let inputs = FfdInputs::new(config)?;
    let items = measure_all(inputs.cases(), config.repeat, progress)?;
    let [nu, nv, nw] = LATTICE_COUNTS;
    let description = format!(
        "sphere of {} triangles (accurate; 'triangles' column = Bézier patches) and of {} \
         vertices (vertex FFD), {nu}x{nv}x{nw} degree-2 lattice; {} points of a rational \
         tricubic 8^3 volume; {} runs each, {} threads",
        inputs.sphere.face_count(),
        inputs.big.vertex_count(),
        inputs.params.len(),
        config.repeat,
        rayon::current_num_threads()
    );
    let mut report = Report::new(
        "ffd",
        description,
        vec![
            ("size", json!(config.rings)),
            ("vertex_rings", json!(config.vertex_rings)),
            ("points", json!(config.points)),
            ("lattice", json!(nu)),
        ],
        config.repeat,
        Unit::Seconds,
        items,
    );
    if config.rings != TARGET_RINGS
        || config.vertex_rings != TARGET_VERTEX_RINGS
        || config.points != TRIVARIATE_POINTS
    {
        report.notes.push(format!(
            "(targets are stated for {TARGET_RINGS} and {TARGET_VERTEX_RINGS} rings and \
             {TRIVARIATE_POINTS} trivariate points)"
        ));
    }
    Ok(report)
}
