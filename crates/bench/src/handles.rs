//! The handle suite: the handle-driven deformations of McPhail's thesis against their
//! targets — 2D rigid MLS of an image grid by point and by segment handles (Table 4.1), 3D
//! affine MLS sampled on a coarse grid over a CT-sized volume (set-up, update after one
//! handle moves, resampling the volume; Tables 5.1–5.2), and a thin-plate spline through
//! many landmarks (factorisation, re-solve after one moves, grid evaluation).

use std::sync::Arc;

use glam::{DVec2, DVec3};
use serde_json::json;
use volmorph_deform::{LiveGrid, SampledMap, SpaceMap};
use volmorph_handles::mls2d::{Mls2dHandles, Mls2dKind, Mls2dPlan, image_grid};
use volmorph_handles::volume_spline::VolumeSplineSystem;
use volmorph_handles::{
    AffineMls, Frame, FrameMls, RigidMls, SimilarityMls, ThinPlateMap, Weighting,
};
use volmorph_testkit::Rng;
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::pullback::{ResampleOptions, resample};

use crate::targets::{
    ISSUE_5_MLS2D_POINTS, ISSUE_5_MLS2D_SEGMENTS, ISSUE_5_MLS3D_MOVE, ISSUE_5_MLS3D_RESAMPLE,
    ISSUE_5_MLS3D_SETUP, ISSUE_5_TPS_EVALUATE, ISSUE_5_TPS_FACTORISE, ISSUE_5_TPS_RESOLVE,
};
use crate::timing::{Case, Report, Unit, measure_all};
use crate::{BenchError, MAX_SIZE, SEED, check_repeat};

/// Side in pixels of the deformed 2D image.
pub const IMAGE_SIDE: u32 = 500;
/// Point handles of the 2D case.
pub const MLS2D_POINTS: usize = 11;
/// Segment handles of the 2D case.
pub const MLS2D_SEGMENTS: usize = 7;
/// Voxel spacing of the resampled volume (mm): a CT slab.
pub const VOLUME_SPACING: DVec3 = DVec3::new(1.2, 1.2, 2.5);
/// Handle displacements of the 3D MLS case: components uniform in ± half of this (mm).
pub const MLS3D_JITTER: DVec3 = DVec3::new(10.0, 10.0, 6.0);
/// Landmark displacements of the thin-plate case: components uniform in ± half of this.
pub const TPS_JITTER: DVec3 = DVec3::splat(6.0);
/// Points at which the criterion benches evaluate the 3D MLS maps and their Jacobians.
pub const PROBES: usize = 1000;

/// Settings of the handle suite. The targets are stated for the defaults.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HandlesConfig {
    /// Vertices per axis of the 2D image grid, 2 to 2048 (default 100).
    pub image_grid: usize,
    /// Handles of the 3D affine MLS map, 4 to 20 000 (default 200).
    pub handles: usize,
    /// Voxels of the resampled volume along x, y, z, each 2 to [`MAX_SIZE`] (default
    /// 256×256×112).
    pub volume: [usize; 3],
    /// Nodes per axis of the sampled MLS grid and of the thin-plate evaluation grid, 2 to 256
    /// (default 32).
    pub grid: usize,
    /// Landmarks of the thin-plate spline, 4 to 20 000 (default 1000).
    pub landmarks: usize,
    /// Timed runs per case, 1 to [`crate::MAX_REPEAT`].
    pub repeat: usize,
}

impl Default for HandlesConfig {
    fn default() -> Self {
        Self {
            image_grid: 100,
            handles: 200,
            volume: [256, 256, 112],
            grid: 32,
            landmarks: 1000,
            repeat: 7,
        }
    }
}

impl HandlesConfig {
    /// Check every setting against its range.
    ///
    /// # Errors
    /// [`BenchError::Setting`] naming the first setting out of range.
    pub fn validate(&self) -> Result<(), BenchError> {
        check_repeat(self.repeat)?;
        BenchError::range("image_grid", self.image_grid, 2..=2048)?;
        BenchError::range("handles", self.handles, 4..=20_000)?;
        BenchError::range("landmarks", self.landmarks, 4..=20_000)?;
        BenchError::range("grid", self.grid, 2..=256)?;
        if !self.volume.iter().all(|d| (2..=MAX_SIZE).contains(d)) {
            return Err(BenchError::Setting {
                setting: "volume",
                value: format!("{:?}", self.volume),
                expected: format!("must be three sizes between 2 and {MAX_SIZE}"),
            });
        }
        Ok(())
    }

    /// Whether every setting is at its default (where the targets are stated).
    #[must_use]
    pub fn at_target(&self) -> bool {
        Self {
            repeat: self.repeat,
            ..Self::default()
        } == *self
    }
}

/// `n` points uniform in the box `[lo, hi)`.
pub fn random_points(rng: &mut Rng, n: usize, lo: DVec3, hi: DVec3) -> Vec<DVec3> {
    (0..n).map(|_| rng.point_in(lo, hi)).collect()
}

/// Each point moved by a random vector with components uniform in `±amount/2`.
pub fn jittered(rng: &mut Rng, points: &[DVec3], amount: DVec3) -> Vec<DVec3> {
    points
        .iter()
        .map(|p| *p + amount * rng.point(0.5))
        .collect()
}

/// The inputs of every handle case, drawn from one seeded stream in a fixed order.
#[derive(Debug)]
pub struct HandlesInputs {
    /// Vertices of the 2D image grid.
    pub verts: Vec<DVec2>,
    /// The 2D point handles and where they go.
    pub points: Vec<DVec2>,
    /// Targets of the 2D point handles.
    pub moved: Vec<DVec2>,
    /// The 2D segment handles.
    pub segments: Vec<[DVec2; 2]>,
    /// Targets of the segments' end points, in order.
    pub segment_targets: Vec<DVec2>,
    /// Grid of the resampled volume.
    pub geometry: Geometry,
    /// The resampled volume (`f32`, a deterministic pattern).
    pub input: Volume<f32>,
    /// 3D MLS handle sources, inside the volume.
    pub sources: Vec<DVec3>,
    /// 3D MLS handle targets.
    pub targets: Vec<DVec3>,
    /// The pull-back map: affine MLS from the targets to the sources.
    pub map: AffineMls,
    /// The coarse grid the MLS map is sampled on.
    pub coarse: Geometry,
    /// Thin-plate landmark sources.
    pub tps_sources: Vec<DVec3>,
    /// Thin-plate landmark targets.
    pub tps_targets: Vec<DVec3>,
    /// The thin-plate evaluation grid (`grid³` over the volume).
    pub eval_grid: Geometry,
    config: HandlesConfig,
}

impl HandlesInputs {
    /// Build every input from the seed [`SEED`].
    ///
    /// # Errors
    /// [`BenchError`] from building the grid, the volume or the MLS map.
    pub fn new(config: &HandlesConfig) -> Result<Self, BenchError> {
        let mut r = Rng::new(SEED);
        let n = config.image_grid;
        let verts = image_grid(IMAGE_SIDE, IMAGE_SIDE, n, n)?;
        let side = f64::from(IMAGE_SIDE);
        let inner =
            |r: &mut Rng| DVec2::new(r.range(50.0, side - 50.0), r.range(50.0, side - 50.0));
        let points: Vec<DVec2> = (0..MLS2D_POINTS).map(|_| inner(&mut r)).collect();
        let moved = points
            .iter()
            .map(|p| *p + DVec2::new(r.range(-20.0, 20.0), r.range(-20.0, 20.0)))
            .collect();
        let segments: Vec<[DVec2; 2]> = (0..MLS2D_SEGMENTS)
            .map(|_| {
                let a = inner(&mut r);
                [a, a + DVec2::new(r.range(10.0, 70.0), r.range(-30.0, 30.0))]
            })
            .collect();
        let segment_targets = segments
            .iter()
            .flat_map(|s| [s[0] + DVec2::new(5.0, 3.0), s[1] - DVec2::new(2.0, 4.0)])
            .collect();

        let geometry = Geometry::new(config.volume).with_spacing(VOLUME_SPACING);
        let input = Volume::from_fn(geometry, |i, j, k| ((i * 7 + j * 3 + k * 11) % 251) as f32)?;
        let (lo, hi) = geometry.physical_bounds();
        let sources = random_points(&mut r, config.handles, lo, hi);
        let targets = jittered(&mut r, &sources, MLS3D_JITTER);
        let map = AffineMls::new(&targets, &sources, Weighting::default())?;
        let coarse = SampledMap::covering(&geometry, [config.grid; 3])?;

        let tps_sources = random_points(&mut r, config.landmarks, lo, hi);
        let tps_targets = jittered(&mut r, &tps_sources, TPS_JITTER);
        let eval_grid = geometry.resampled([config.grid; 3]);
        Ok(Self {
            verts,
            points,
            moved,
            segments,
            segment_targets,
            geometry,
            input,
            sources,
            targets,
            map,
            coarse,
            tps_sources,
            tps_targets,
            eval_grid,
            config: *config,
        })
    }

    fn point_plan(&self) -> Result<Mls2dPlan, BenchError> {
        Ok(Mls2dHandles::new(&self.points, &[], 1.0)?.plan(&self.verts, Mls2dKind::Rigid)?)
    }

    fn segment_handles(&self) -> Result<Mls2dHandles, BenchError> {
        Ok(Mls2dHandles::new(&[], &self.segments, 2.0)?)
    }

    fn centres(&self) -> Vec<[f64; 3]> {
        self.tps_sources.iter().map(|p| p.to_array()).collect()
    }

    fn thin_plate(&self) -> Result<ThinPlateMap, BenchError> {
        let system = VolumeSplineSystem::<3>::new(&self.centres(), 0.0)?;
        Ok(ThinPlateMap::with_system(
            Arc::new(system),
            &self.tps_targets,
        )?)
    }

    /// The eight cases of the thesis' targets (shown at the default sizes).
    ///
    /// # Errors
    /// [`BenchError`] from the set-ups done before the clock (plans, grids, factorisations).
    pub fn cases(&self) -> Result<Vec<Case<'_>>, BenchError> {
        let at = |t| self.config.at_target().then_some(t);
        let plan = self.point_plan()?;
        let splan = self
            .segment_handles()?
            .plan(&self.verts, Mls2dKind::Rigid)?;
        let mut out = vec![DVec2::ZERO; self.verts.len()];
        let mut out_s = vec![DVec2::ZERO; self.verts.len()];
        let mut live = LiveGrid::new(self.map.clone(), self.coarse)?;
        let sampled = LiveGrid::new(self.map.clone(), self.coarse)?;
        let centres = self.centres();
        let mut tps = self.thin_plate()?;
        let eval = self.thin_plate()?;
        let mut grid_out = vec![DVec3::ZERO; self.eval_grid.len()];
        let opts = ResampleOptions::new(Interpolation::Linear, 0.0);
        let (mut sign, mut tps_sign) = (-1.0, -1.0);
        Ok(vec![
            Case::call("2D rigid MLS, 11 points", "mls2d_rigid_points", move || {
                Ok(plan.deform(&self.moved, &mut out)?)
            })
            .with_target(at(ISSUE_5_MLS2D_POINTS)),
            Case::call(
                "2D rigid MLS, 7 segments",
                "mls2d_rigid_segments",
                move || Ok(splan.deform(&self.segment_targets, &mut out_s)?),
            )
            .with_target(at(ISSUE_5_MLS2D_SEGMENTS)),
            Case::call("3D affine MLS: set-up", "mls3d_affine_setup", move || {
                Ok(LiveGrid::new(self.map.clone(), self.coarse)?)
            })
            .with_target(at(ISSUE_5_MLS3D_SETUP)),
            Case::call(
                "3D affine MLS: move one handle",
                "mls3d_affine_move",
                move || {
                    sign = -sign;
                    Ok(live
                        .move_parameter(0, self.sources[0] + sign * DVec3::new(1.5, -1.0, 0.5))?)
                },
            )
            .with_target(at(ISSUE_5_MLS3D_MOVE)),
            Case::call(
                "3D affine MLS: resample volume",
                "mls3d_affine_resample",
                move || {
                    Ok(resample::<f32, f32, _>(
                        &self.input,
                        sampled.sampled(),
                        &self.geometry,
                        &opts,
                    )?)
                },
            )
            .with_target(at(ISSUE_5_MLS3D_RESAMPLE)),
            Case::call("TPS: factorise", "tps_factorise", move || {
                Ok(VolumeSplineSystem::<3>::new(&centres, 0.0)?)
            })
            .with_target(at(ISSUE_5_TPS_FACTORISE)),
            Case::call("TPS: re-solve after one moves", "tps_resolve", move || {
                tps_sign = -tps_sign;
                Ok(tps.move_target(
                    3,
                    self.tps_targets[3] + tps_sign * DVec3::new(1.0, 0.5, -0.5),
                )?)
            })
            .with_target(at(ISSUE_5_TPS_RESOLVE)),
            Case::call("TPS: evaluate on grid", "tps_evaluate_grid", move || {
                Ok(eval.apply_grid(&self.eval_grid, &mut grid_out)?)
            })
            .with_target(at(ISSUE_5_TPS_EVALUATE)),
        ])
    }

    /// Measured by the criterion benches only: planning the 2D segment deformation; dragging
    /// a selected 3D handle; `apply` and `jacobian` of the affine, similarity, rigid and frame
    /// MLS maps on the same handles at [`PROBES`] points; the thin-plate spline evaluated on
    /// the grid's points as a batch.
    ///
    /// # Errors
    /// [`BenchError`] from the set-ups done before the clock.
    pub fn extra_cases(&self) -> Result<Vec<Case<'_>>, BenchError> {
        let hs = self.segment_handles()?;
        let mut live = LiveGrid::new(self.map.clone(), self.coarse)?;
        live.select(17 % self.config.handles)?;
        let selected = self.sources[17 % self.config.handles];
        let mut step = 0.0;
        let mut cases = vec![
            Case::call(
                "2D rigid MLS, 7 segments: plan",
                "mls2d_rigid_segments_plan",
                move || Ok(hs.plan(&self.verts, Mls2dKind::Rigid)?),
            ),
            Case::call(
                "3D affine MLS: drag selected handle",
                "mls3d_affine_drag_selected",
                move || {
                    step = if step > 0.0 { -0.5 } else { 0.5 };
                    Ok(live.drag_selected(selected + DVec3::new(0.0, step, 0.0))?)
                },
            ),
        ];
        let mut r = Rng::new(SEED ^ 1);
        let (lo, hi) = self.geometry.physical_bounds();
        let probes = random_points(&mut r, PROBES, lo, hi);
        let (src, dst) = (&self.targets, &self.sources);
        let frames = |p: &[DVec3]| -> Vec<Frame> { p.iter().map(|&o| Frame::at(o)).collect() };
        let maps: Vec<(&str, Box<dyn SpaceMap>)> = vec![
            ("affine", Box::new(self.map.clone())),
            (
                "similarity",
                Box::new(SimilarityMls::new(src, dst, Weighting::default())?),
            ),
            (
                "rigid",
                Box::new(RigidMls::new(src, dst, Weighting::default())?),
            ),
            (
                "frame",
                Box::new(FrameMls::new(
                    &frames(src),
                    &frames(dst),
                    1.0,
                    Weighting::default(),
                )?),
            ),
        ];
        let maps: Vec<(&str, Arc<dyn SpaceMap>)> =
            maps.into_iter().map(|(n, m)| (n, Arc::from(m))).collect();
        let probes = Arc::new(probes);
        for (name, m) in maps {
            let (m2, p, p2) = (m.clone(), probes.clone(), probes.clone());
            cases.push(Case::call(
                format!("3D {name} MLS: apply at {PROBES} points"),
                format!("mls3d_{name}_apply"),
                move || Ok(p.iter().map(|&x| m.apply(x)).sum::<DVec3>()),
            ));
            cases.push(Case::call(
                format!("3D {name} MLS: Jacobian at {PROBES} points"),
                format!("mls3d_{name}_jacobian"),
                move || Ok(p2.iter().map(|&x| m2.jacobian(x).x_axis).sum::<DVec3>()),
            ));
        }
        let tps = self.thin_plate()?;
        let pts = grid_points(&self.eval_grid);
        let mut out = vec![DVec3::ZERO; pts.len()];
        cases.push(Case::call(
            "TPS: evaluate grid points as a batch",
            "tps_evaluate_batch",
            move || Ok(tps.apply_batch(&pts, &mut out)?),
        ));
        Ok(cases)
    }
}

/// The physical points of every voxel centre of `g`, x fastest.
fn grid_points(g: &Geometry) -> Vec<DVec3> {
    let [nx, ny, nz] = g.dims;
    let mut pts = Vec::with_capacity(g.len());
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                pts.push(g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64)));
            }
        }
    }
    pts
}

/// Run the handle suite; `progress` hears what is being built or timed.
///
/// # Errors
/// [`BenchError::Setting`] for a setting out of range, or the first case that fails.
pub fn run(config: &HandlesConfig, progress: &mut dyn FnMut(&str)) -> Result<Report, BenchError> {
    config.validate()?;
    progress("building the handle sets");
    let inputs = HandlesInputs::new(config)?;
    let items = measure_all(inputs.cases()?, config.repeat, progress)?;
    let [x, y, z] = config.volume;
    let description = format!(
        "2D rigid MLS on a {n}x{n} grid; 3D affine MLS with {h} handles on a {c}^3 grid over a \
         {x}x{y}x{z} f32 volume; TPS with {l} landmarks evaluated on {c}^3; {rep} runs each, \
         {t} threads",
        n = config.image_grid,
        h = config.handles,
        c = config.grid,
        l = config.landmarks,
        rep = config.repeat,
        t = rayon::current_num_threads(),
    );
    let mut report = Report::new(
        "handles",
        description,
        vec![
            ("size", json!(config.grid)),
            ("image_grid", json!(config.image_grid)),
            ("handles", json!(config.handles)),
            ("volume", json!(config.volume)),
            ("landmarks", json!(config.landmarks)),
            ("lattice", json!(null)),
        ],
        config.repeat,
        Unit::Milliseconds,
        items,
    );
    if !config.at_target() {
        report
            .notes
            .push("(targets are stated for the default sizes)".to_owned());
    }
    Ok(report)
}
