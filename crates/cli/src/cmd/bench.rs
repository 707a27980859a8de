//! `volmorph bench …`: time the warps, the isosurface extractors, mesh FFD, F-rep sampling and
//! the handle-driven deformations on built-in inputs and print each item's min / median / max
//! wall-clock time next to its target.
//!
//! Every input is built before the clock starts; each item runs `--repeat` times and its
//! result is dropped after the clock stops, so a time covers exactly one call of the library
//! function (including the allocation of its output). Targets are stated for the 256³ inputs
//! on the reference two-core machine and shown only at that size.

use std::time::{Duration, Instant};

use anyhow::bail;
use volmorph_contour::{DcOptions, McOptions, dual_contouring, marching_cubes};
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::manipulate::{Drag, DragOptions, ManipulationSession};
use volmorph_volume::DVec3;
use volmorph_volume::phantom::{self, Phantom};
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::incremental::IncrementalPushForward;
use volmorph_warp::jacobian::jacobian_determinant;
use volmorph_warp::pullback::{ResampleOptions, resample};
use volmorph_warp::pushforward::{
    AntialiasOptions, push_forward_antialiased, push_forward_nearest,
};

use crate::progress;

/// Size at which the targets are stated.
const TARGET_SIZE: usize = 256;

/// Size of the volume of the interactive-editing items (incremental update, drag), at which
/// their targets are stated.
const EDIT_TARGET_SIZE: usize = 128;

/// Largest `--size` accepted (a 1024³ `f32` volume is 4 GiB).
const MAX_SIZE: usize = 1024;

/// Largest `--repeat` accepted.
const MAX_REPEAT: usize = 1000;

/// Seed of the random control-point displacements, so every run times the same lattice.
const LATTICE_SEED: u64 = 0x5eed;

/// Benchmark subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Time pull-back (trilinear, cubic), push-forward (nearest, antialiased) and the
    /// Jacobian determinant map of a randomly moved lattice on the teapot phantom, and the
    /// interactive edits: an incremental update after one control point moves, and a drag
    /// (solve plus incremental update).
    #[command(after_help = "Example:\n  volmorph bench warp --size 256 --lattice 9 --repeat 5")]
    Warp(WarpArgs),
    /// Time marching cubes and dual contouring on a sphere's signed distance field.
    #[command(after_help = "Example:\n  volmorph bench isosurface --size 256 --repeat 5 --json")]
    Isosurface(IsosurfaceArgs),
    /// Time the accurate FFD of a 70k-triangle sphere through a moved 6×8×6 degree-2 lattice
    /// (target 2 s) and vertex FFD of a 1M-vertex sphere (target 50 ms).
    #[command(after_help = "Example:\n  volmorph bench ffd --repeat 3")]
    Ffd(FfdArgs),
    /// Time grid evaluation of F-rep models (HyperFun files): the culled, specialised
    /// sampler against the published libfive figures (193³ over [−1.6, 1.6]³), checked
    /// against point-by-point evaluation.
    #[command(
        after_help = "Example:\n  volmorph bench frep s1_sphere.hf c1_gear.hf --grid 193 --repeat 7 --json"
    )]
    Frep(crate::cmd::frep::BenchArgs),
    /// Time the handle-driven deformations against their targets: 2D rigid MLS on a 100×100
    /// grid (11 point handles; 7 segment handles), 3D affine MLS with 200 handles sampled on a
    /// 32³ grid over a 256×256×112 volume (set-up, update after one handle moves, resampling
    /// the volume) and a thin-plate spline through 1000 landmarks (factorise, re-solve after
    /// one landmark moves, evaluate on 32³).
    #[command(after_help = "Example:\n  volmorph bench handles --repeat 7 --json")]
    Handles(HandlesArgs),
}

/// Default vertices per axis of the 2D image grid.
const HANDLES_IMAGE_GRID: usize = 100;
/// Default 3D MLS handles.
const HANDLES_MLS: usize = 200;
/// Default dims of the resampled volume (a CT slab).
const HANDLES_VOLUME: [usize; 3] = [256, 256, 112];
/// Default nodes per axis of the sampled handle grid and the TPS evaluation grid.
const HANDLES_GRID: usize = 32;
/// Default thin-plate landmarks.
const HANDLES_TPS: usize = 1000;

/// Arguments of `volmorph bench handles`. Targets are shown only for the default sizes.
#[derive(Debug, clap::Args)]
pub struct HandlesArgs {
    /// Vertices per axis of the 2D MLS image grid.
    #[arg(long, default_value_t = HANDLES_IMAGE_GRID)]
    pub image_grid: usize,
    /// Handles of the 3D affine MLS map.
    #[arg(long, default_value_t = HANDLES_MLS)]
    pub handles: usize,
    /// Voxels of the resampled volume along x, y, z.
    #[arg(long, value_delimiter = ',', default_values_t = HANDLES_VOLUME)]
    pub volume: Vec<usize>,
    /// Nodes per axis of the sampled MLS grid and of the thin-plate evaluation grid.
    #[arg(long, default_value_t = HANDLES_GRID)]
    pub grid: usize,
    /// Landmarks of the thin-plate spline.
    #[arg(long, default_value_t = HANDLES_TPS)]
    pub landmarks: usize,
    /// Timed runs per item.
    #[arg(long, default_value_t = 7)]
    pub repeat: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Default rings of the accurate-FFD sphere: 4·133·132 = 70 224 triangles.
const FFD_RINGS: u32 = 133;
/// Default rings of the vertex-FFD sphere: 2·708·707 + 2 = 1 001 114 vertices.
const FFD_VERTEX_RINGS: u32 = 708;

/// Arguments of `volmorph bench ffd`.
#[derive(Debug, clap::Args)]
pub struct FfdArgs {
    /// Latitude rings of the sphere for the accurate FFD (4·r·(r−1) triangles).
    #[arg(long, default_value_t = FFD_RINGS)]
    pub rings: u32,
    /// Latitude rings of the sphere for vertex FFD (2·r·(r−1)+2 vertices).
    #[arg(long, default_value_t = FFD_VERTEX_RINGS)]
    pub vertex_rings: u32,
    /// Timed runs per item.
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `volmorph bench warp`.
#[derive(Debug, clap::Args)]
pub struct WarpArgs {
    /// Voxels per axis of the teapot phantom (a cube).
    #[arg(long, default_value_t = TARGET_SIZE)]
    pub size: usize,
    /// Control points per axis of the uniform cubic lattice (at least 4).
    #[arg(long, default_value_t = 9)]
    pub lattice: usize,
    /// Timed runs per item.
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Voxels per axis of the teapot for the interactive-editing items (incremental update
    /// after moving one control point, drag).
    #[arg(long, default_value_t = EDIT_TARGET_SIZE)]
    pub edit_size: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `volmorph bench isosurface`.
#[derive(Debug, clap::Args)]
pub struct IsosurfaceArgs {
    /// Voxels per axis of the sphere's distance field (a cube).
    #[arg(long, default_value_t = TARGET_SIZE)]
    pub size: usize,
    /// Timed runs per item.
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Run a bench subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Warp(a) => warp(a),
        Command::Isosurface(a) => isosurface(a),
        Command::Ffd(a) => ffd(a),
        Command::Frep(a) => crate::cmd::frep::bench(a),
        Command::Handles(a) => handles(a),
    }
}

/// A Feng end-interpolating degree-2 lattice around `m` with every control point moved by up
/// to 5 % of the box (seeded, so every run times the same lattice).
fn ffd_lattice(m: &volmorph_mesh::Mesh, counts: [usize; 3]) -> anyhow::Result<BSplineLattice> {
    let (lo, hi) = m
        .bounding_box()
        .ok_or_else(|| anyhow::anyhow!("empty mesh"))?;
    let mut lat = BSplineLattice::feng_end_interpolating_around(lo, hi, [2, 2, 2], counts)?;
    let mut r = Lcg(LATTICE_SEED);
    let size = (hi - lo).max_element();
    for k in 0..counts[2] {
        for j in 0..counts[1] {
            for i in 0..counts[0] {
                let d = DVec3::new(r.next() - 0.5, r.next() - 0.5, r.next() - 0.5) * 0.1 * size;
                lat.move_control_point([i, j, k], d)?;
            }
        }
    }
    Ok(lat)
}

fn ffd(a: &FfdArgs) -> anyhow::Result<()> {
    if !(1..=MAX_REPEAT).contains(&a.repeat) {
        bail!("--repeat {} must be between 1 and {MAX_REPEAT}", a.repeat);
    }
    if !(2..=2048).contains(&a.rings) || !(2..=2048).contains(&a.vertex_rings) {
        bail!("--rings and --vertex-rings must be between 2 and 2048");
    }
    let pb = progress::spinner("building the spheres");
    let sphere = volmorph_ffd::shapes::uv_sphere(a.rings, 1.0, DVec3::ZERO)?;
    let lat = ffd_lattice(&sphere, [6, 8, 6])?;
    pb.set_message("accurate FFD");
    let (times, model) = time(a.repeat, || {
        let plan = std::sync::Arc::new(volmorph_ffd::accurate::AccuratePlan::new(&sphere, &lat)?);
        Ok(plan.deform(&lat)?)
    })?;
    let mut items = vec![Item {
        name: "accurate FFD (plan + surfaces)",
        times,
        target: (a.rings == FFD_RINGS).then_some(2.0),
        triangles: Some(model.stats.patches),
    }];
    let big = volmorph_ffd::shapes::uv_sphere(a.vertex_rings, 1.0, DVec3::ZERO)?;
    let lat = ffd_lattice(&big, [6, 8, 6])?;
    pb.set_message("vertex FFD");
    let (times, _) = time(a.repeat, || {
        Ok(volmorph_ffd::baseline::vertex_ffd(&big, &lat)?)
    })?;
    items.push(Item {
        name: "vertex FFD",
        times,
        target: (a.vertex_rings == FFD_VERTEX_RINGS).then_some(0.05),
        triangles: None,
    });
    pb.finish_and_clear();
    let title = format!(
        "sphere of {} triangles (accurate; 'triangles' column = Bézier patches) and of {} \
         vertices (vertex FFD), 6x8x6 degree-2 lattice, {} runs each, {} threads",
        sphere.face_count(),
        big.vertex_count(),
        a.repeat,
        rayon::current_num_threads()
    );
    report(
        a.json,
        "ffd",
        &title,
        a.rings as usize,
        a.repeat,
        Some(6),
        &items,
    );
    Ok(())
}

/// Timings of one benchmarked operation.
#[derive(Debug)]
struct Item {
    name: &'static str,
    /// Wall-clock time of each run, sorted.
    times: Vec<Duration>,
    /// Target time at [`TARGET_SIZE`], if the operation has one.
    target: Option<f64>,
    /// Triangles of the extracted surface (isosurface items).
    triangles: Option<usize>,
}

impl Item {
    fn min(&self) -> f64 {
        self.times.first().map_or(f64::NAN, Duration::as_secs_f64)
    }

    fn max(&self) -> f64 {
        self.times.last().map_or(f64::NAN, Duration::as_secs_f64)
    }

    /// Median of the runs (mean of the middle two for an even count).
    fn median(&self) -> f64 {
        let n = self.times.len();
        match n {
            0 => f64::NAN,
            _ if n % 2 == 1 => self.times[n / 2].as_secs_f64(),
            _ => 0.5 * (self.times[n / 2 - 1] + self.times[n / 2]).as_secs_f64(),
        }
    }
}

/// Time `f` `repeat` times; its result is dropped after each clock stops. Returns the sorted
/// times and the last result.
fn time<R>(
    repeat: usize,
    mut f: impl FnMut() -> anyhow::Result<R>,
) -> anyhow::Result<(Vec<Duration>, R)> {
    let mut times = Vec::with_capacity(repeat);
    let mut last = None;
    for _ in 0..repeat {
        let start = Instant::now();
        let r = f()?;
        times.push(start.elapsed());
        last = Some(r);
    }
    times.sort();
    let last = last.ok_or_else(|| anyhow::anyhow!("no timed run"))?;
    Ok((times, last))
}

fn check_common(size: usize, repeat: usize) -> anyhow::Result<()> {
    if !(4..=MAX_SIZE).contains(&size) {
        bail!("--size {size} must be between 4 and {MAX_SIZE}");
    }
    if !(1..=MAX_REPEAT).contains(&repeat) {
        bail!("--repeat {repeat} must be between 1 and {MAX_REPEAT}");
    }
    Ok(())
}

/// Deterministic pseudo-random numbers in `[0, 1)` (64-bit LCG, top 53 bits).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// True's uniform cubic lattice of `counts³` control points on the voxel-centre box of `g`,
/// every control point off the outer layer moved by a random vector (fixed seed) whose
/// components are uniform in `[−½, ½]` region along each axis (length at most ≈0.87 region).
fn moved_lattice(g: &Geometry, counts: usize) -> anyhow::Result<BSplineLattice> {
    let mut lat = volmorph_lattice::BSplineLattice::identity_on_voxels(g, [counts; 3])?;
    let extent = g.spacing
        * DVec3::new(
            g.dims[0].saturating_sub(1) as f64,
            g.dims[1].saturating_sub(1) as f64,
            g.dims[2].saturating_sub(1) as f64,
        );
    let region = g.direction * (extent / (counts - 3) as f64);
    let mut rng = Lcg(LATTICE_SEED);
    for k in 1..counts - 1 {
        for j in 1..counts - 1 {
            for i in 1..counts - 1 {
                let d = DVec3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5);
                lat.move_control_point([i, j, k], region * d)?;
            }
        }
    }
    Ok(lat)
}

fn warp(a: &WarpArgs) -> anyhow::Result<()> {
    check_common(a.size, a.repeat)?;
    if !(4..=64).contains(&a.lattice) {
        bail!("--lattice {} must be between 4 and 64", a.lattice);
    }
    let dims = [a.size; 3];
    let pb = progress::spinner(format!("building the teapot phantom {dims:?}"));
    let density = phantom::density(Phantom::Teapot, dims)?;
    let grid = *density.geometry();
    let input: Volume<f32> = density.cast();
    let lat = moved_lattice(&grid, a.lattice)?;
    let at_target = a.size == TARGET_SIZE;
    let target = |t: f64| at_target.then_some(t);

    let mut items = Vec::new();
    let (input, lat, grid) = (&input, &lat, &grid);
    let pull = |interpolation: Interpolation| {
        let options = ResampleOptions::new(interpolation, 0.0);
        move || -> anyhow::Result<Volume<f32>> { Ok(resample(input, lat, grid, &options)?) }
    };
    pb.set_message("pull-back trilinear");
    let (times, _) = time(a.repeat, pull(Interpolation::Linear))?;
    items.push(Item {
        name: "pull-back trilinear (f32)",
        times,
        target: target(0.25),
        triangles: None,
    });
    pb.set_message("pull-back cubic");
    let (times, _) = time(a.repeat, pull(Interpolation::CubicBSpline))?;
    items.push(Item {
        name: "pull-back cubic B-spline (f32)",
        times,
        target: None,
        triangles: None,
    });
    pb.set_message("push-forward nearest");
    let (times, _) = time(a.repeat, || Ok(push_forward_nearest(&density, lat, grid)?))?;
    items.push(Item {
        name: "push-forward nearest (u8)",
        times,
        target: None,
        triangles: None,
    });
    pb.set_message("push-forward antialiased");
    let options = AntialiasOptions::default();
    let (times, _) = time(a.repeat, || {
        Ok(push_forward_antialiased(&density, lat, grid, &options)?)
    })?;
    items.push(Item {
        name: "push-forward antialiased (u8)",
        times,
        target: target(1.0),
        triangles: None,
    });
    pb.set_message("Jacobian determinant map");
    let (times, _) = time(a.repeat, || Ok(jacobian_determinant(lat, grid)?))?;
    items.push(Item {
        name: "Jacobian determinant map",
        times,
        target: None,
        triangles: None,
    });
    pb.set_message("incremental update and drag");
    edit_items(a, &mut items)?;
    pb.finish_and_clear();

    let l = a.lattice;
    let title = format!(
        "teapot {n}x{n}x{n}, lattice {l}x{l}x{l} moved at random (seed {LATTICE_SEED:#x}), \
         {r} runs each, {t} threads",
        n = a.size,
        r = a.repeat,
        t = rayon::current_num_threads(),
    );
    report(a.json, "warp", &title, a.size, a.repeat, Some(l), &items);
    Ok(())
}

/// The interactive-editing items on a teapot of `--edit-size`³ under the identity lattice of
/// `--lattice`³ control points: the antialiased push-forward kept by
/// [`IncrementalPushForward`] is updated (a) after the centre control point moves by about a
/// third of a region, alternately there and back, and (b) after a drag of the point at that
/// control point's place with a tool radius of half a region (so the least-norm solve moves
/// that one control point) — solve plus update, from the undeformed lattice each time.
fn edit_items(a: &WarpArgs, items: &mut Vec<Item>) -> anyhow::Result<()> {
    if !(8..=MAX_SIZE).contains(&a.edit_size) {
        bail!(
            "--edit-size {} must be between 8 and {MAX_SIZE}",
            a.edit_size
        );
    }
    let target = |t: f64| (a.edit_size == EDIT_TARGET_SIZE).then_some(t);
    let density = phantom::density(Phantom::Teapot, [a.edit_size; 3])?;
    let grid = *density.geometry();
    let base = volmorph_lattice::BSplineLattice::identity_on_voxels(&grid, [a.lattice; 3])?;
    let c = a.lattice / 2;
    let centre = base.control_point([c, c, c])?;
    let region = (base.control_point([c + 1, c, c])? - centre).length();
    let options = AntialiasOptions::default();
    let mut engine = IncrementalPushForward::new(&density, base.clone(), &grid, &options)?;
    let step = DVec3::new(0.3, -0.2, 0.25) * region;
    let mut sign = -1.0;
    let (times, _) = time(a.repeat, || {
        sign = -sign;
        let changes = engine
            .map()
            .changes_for_displacements(&[([c, c, c], step * sign)])?;
        Ok(engine.set_parameters(&changes)?)
    })?;
    items.push(Item {
        name: "incremental update, 1 control pt",
        times,
        target: target(0.030),
        triangles: None,
    });
    // Each run starts from the undeformed lattice (restored, untimed, by undo) and times the
    // drag: the least-norm solve and the incremental update.
    engine.set_map(base.clone())?;
    let mut session = ManipulationSession::new(base, DragOptions::with_radius(0.5 * region))?;
    let mut times = Vec::with_capacity(a.repeat);
    for _ in 0..a.repeat {
        let start = Instant::now();
        session.drag(&[Drag::new(centre, centre + step)])?;
        engine.set_map(session.lattice().clone())?;
        times.push(start.elapsed());
        session.undo();
        engine.set_map(session.lattice().clone())?;
    }
    times.sort();
    items.push(Item {
        name: "drag: solve + incremental update",
        times,
        target: target(0.040),
        triangles: None,
    });
    Ok(())
}

fn isosurface(a: &IsosurfaceArgs) -> anyhow::Result<()> {
    check_common(a.size, a.repeat)?;
    let dims = [a.size; 3];
    let pb = progress::spinner(format!("building the sphere distance field {dims:?}"));
    let sdf = phantom::signed_distance(Phantom::Sphere, dims)?;
    let at_target = a.size == TARGET_SIZE;

    pb.set_message("marching cubes");
    let mc = McOptions { inside_below: true };
    let (times, s) = time(a.repeat, || Ok(marching_cubes(&sdf, 0.0, &mc)?))?;
    let mut items = vec![Item {
        name: "marching cubes",
        times,
        target: at_target.then_some(0.1),
        triangles: Some(s.mesh.face_count()),
    }];
    pb.set_message("dual contouring");
    let dc = DcOptions {
        inside_below: true,
        ..DcOptions::default()
    };
    let (times, s) = time(a.repeat, || Ok(dual_contouring(&sdf, 0.0, &dc)?))?;
    items.push(Item {
        name: "dual contouring",
        times,
        target: None,
        triangles: Some(s.mesh.face_count()),
    });
    pb.finish_and_clear();

    let title = format!(
        "sphere signed distance {n}x{n}x{n} (f32), level 0, {r} runs each, {t} threads",
        n = a.size,
        r = a.repeat,
        t = rayon::current_num_threads(),
    );
    report(a.json, "isosurface", &title, a.size, a.repeat, None, &items);
    Ok(())
}

/// `n` seeded points uniform in the box `[lo, hi]`.
fn random_points(r: &mut Lcg, n: usize, lo: DVec3, hi: DVec3) -> Vec<DVec3> {
    (0..n)
        .map(|_| lo + (hi - lo) * DVec3::new(r.next(), r.next(), r.next()))
        .collect()
}

/// Each point moved by a seeded random vector with components uniform in `±amount/2`.
fn jittered(r: &mut Lcg, points: &[DVec3], amount: DVec3) -> Vec<DVec3> {
    points
        .iter()
        .map(|p| *p + amount * DVec3::new(r.next() - 0.5, r.next() - 0.5, r.next() - 0.5))
        .collect()
}

fn handles(a: &HandlesArgs) -> anyhow::Result<()> {
    use glam::DVec2;
    use volmorph_deform::{LiveGrid, SampledMap, SpaceMap};
    use volmorph_handles::mls2d::{Mls2dHandles, Mls2dKind, image_grid};
    use volmorph_handles::volume_spline::VolumeSplineSystem;
    use volmorph_handles::{AffineMls, ThinPlateMap, Weighting};

    if !(1..=MAX_REPEAT).contains(&a.repeat) {
        bail!("--repeat {} must be between 1 and {MAX_REPEAT}", a.repeat);
    }
    if !(2..=2048).contains(&a.image_grid) {
        bail!("--image-grid {} must be between 2 and 2048", a.image_grid);
    }
    if !(4..=20_000).contains(&a.handles) {
        bail!("--handles {} must be between 4 and 20000", a.handles);
    }
    if !(4..=20_000).contains(&a.landmarks) {
        bail!("--landmarks {} must be between 4 and 20000", a.landmarks);
    }
    if !(2..=256).contains(&a.grid) {
        bail!("--grid {} must be between 2 and 256", a.grid);
    }
    let dims: [usize; 3] = match a.volume.as_slice() {
        &[x, y, z] if [x, y, z].iter().all(|d| (2..=MAX_SIZE).contains(d)) => [x, y, z],
        v => bail!("--volume {v:?} must be three sizes between 2 and {MAX_SIZE}"),
    };
    let mut r = Lcg(LATTICE_SEED);
    let mut items = Vec::new();
    let defaults = a.image_grid == HANDLES_IMAGE_GRID
        && a.handles == HANDLES_MLS
        && dims == HANDLES_VOLUME
        && a.grid == HANDLES_GRID
        && a.landmarks == HANDLES_TPS;
    let target = |t: f64| defaults.then_some(t);
    let pb = progress::spinner("2D rigid MLS");

    // 2D rigid MLS on a 500×500 image through a 100×100 grid (thesis Table 4.1: 3.8 ms for
    // 11 points, 3.3 ms for 7 lines).
    let n = a.image_grid;
    let verts = image_grid(500, 500, n, n)?;
    let points: Vec<DVec2> = (0..11)
        .map(|_| DVec2::new(50.0 + 400.0 * r.next(), 50.0 + 400.0 * r.next()))
        .collect();
    let moved: Vec<DVec2> = points
        .iter()
        .map(|p| *p + DVec2::new(40.0 * r.next() - 20.0, 40.0 * r.next() - 20.0))
        .collect();
    let h = Mls2dHandles::new(&points, &[], 1.0)?;
    let plan = h.plan(&verts, Mls2dKind::Rigid)?;
    let mut out2 = vec![DVec2::ZERO; verts.len()];
    let (times, ()) = time(a.repeat, || Ok(plan.deform(&moved, &mut out2)?))?;
    items.push(Item {
        name: "2D rigid MLS, 11 points",
        times,
        target: target(0.001),
        triangles: None,
    });
    let segs: Vec<[DVec2; 2]> = (0..7)
        .map(|_| {
            let s = DVec2::new(50.0 + 400.0 * r.next(), 50.0 + 400.0 * r.next());
            [
                s,
                s + DVec2::new(60.0 * r.next() + 10.0, 60.0 * r.next() - 30.0),
            ]
        })
        .collect();
    let hs = Mls2dHandles::new(&[], &segs, 2.0)?;
    let seg_targets: Vec<DVec2> = segs
        .iter()
        .flat_map(|s| [s[0] + DVec2::new(5.0, 3.0), s[1] - DVec2::new(2.0, 4.0)])
        .collect();
    let splan = hs.plan(&verts, Mls2dKind::Rigid)?;
    let (times, ()) = time(a.repeat, || Ok(splan.deform(&seg_targets, &mut out2)?))?;
    items.push(Item {
        name: "2D rigid MLS, 7 segments",
        times,
        target: target(0.001),
        triangles: None,
    });

    // 3D affine MLS through 200 handles on a CT slab (targets: set-up ≤ 0.1 s, update after
    // one handle moves ≤ 0.1 ms, against the thesis' 1.5 s and 0.31–0.78 ms in Tables 5.1 and
    // 5.2), resampled trilinearly through the 32³ grid (≤ 0.3 s).
    pb.set_message("3D affine MLS");
    let g = Geometry::new(dims).with_spacing(DVec3::new(1.2, 1.2, 2.5));
    let input = Volume::from_fn(g, |i, j, k| ((i * 7 + j * 3 + k * 11) % 251) as f32)?;
    let (lo, hi) = g.physical_bounds();
    let src = random_points(&mut r, a.handles, lo, hi);
    let dst = jittered(&mut r, &src, DVec3::new(10.0, 10.0, 6.0));
    // Pull-back: the map from targets to sources.
    let map = AffineMls::new(&dst, &src, Weighting::default())?;
    let coarse = SampledMap::covering(&g, [a.grid; 3])?;
    let (times, mut hg) = time(a.repeat, || Ok(LiveGrid::new(map.clone(), coarse)?))?;
    items.push(Item {
        name: "3D affine MLS: set-up",
        times,
        target: target(0.1),
        triangles: None,
    });
    let mut sign = -1.0;
    let (times, ()) = time(a.repeat, || {
        sign = -sign;
        Ok(hg.move_parameter(0, src[0] + sign * DVec3::new(1.5, -1.0, 0.5))?)
    })?;
    items.push(Item {
        name: "3D affine MLS: move one handle",
        times,
        target: target(0.0001),
        triangles: None,
    });
    let opts = ResampleOptions::new(Interpolation::Linear, 0.0);
    let (times, _) = time(a.repeat, || {
        Ok(resample::<f32, f32, _>(&input, hg.sampled(), &g, &opts)?)
    })?;
    items.push(Item {
        name: "3D affine MLS: resample volume",
        times,
        target: target(0.3),
        triangles: None,
    });

    // Thin-plate spline through 1000 landmarks.
    pb.set_message("thin-plate spline");
    let src = random_points(&mut r, a.landmarks, lo, hi);
    let dst = jittered(&mut r, &src, DVec3::splat(6.0));
    let centres: Vec<[f64; 3]> = src.iter().map(|p| p.to_array()).collect();
    let (times, system) = time(a.repeat, || {
        Ok(VolumeSplineSystem::<3>::new(&centres, 0.0)?)
    })?;
    items.push(Item {
        name: "TPS: factorise",
        times,
        target: target(0.030),
        triangles: None,
    });
    let mut tps = ThinPlateMap::with_system(std::sync::Arc::new(system), &dst)?;
    let (times, ()) = time(a.repeat, || {
        sign = -sign;
        Ok(tps.move_target(3, dst[3] + sign * DVec3::new(1.0, 0.5, -0.5))?)
    })?;
    items.push(Item {
        name: "TPS: re-solve after one moves",
        times,
        target: target(0.005),
        triangles: None,
    });
    let eval_grid = g.resampled([a.grid; 3]);
    let mut out3 = vec![DVec3::ZERO; eval_grid.len()];
    let (times, ()) = time(a.repeat, || Ok(tps.apply_grid(&eval_grid, &mut out3)?))?;
    items.push(Item {
        name: "TPS: evaluate on grid",
        times,
        target: target(0.030),
        triangles: None,
    });
    pb.finish_and_clear();

    let title = format!(
        "2D rigid MLS on a {n}x{n} grid; 3D affine MLS with {h} handles on a {c}^3 grid over a \
         {x}x{y}x{z} f32 volume; TPS with {l} landmarks evaluated on {c}^3; {rep} runs each, \
         {t} threads",
        h = a.handles,
        c = a.grid,
        x = dims[0],
        y = dims[1],
        z = dims[2],
        l = a.landmarks,
        rep = a.repeat,
        t = rayon::current_num_threads(),
    );
    report(a.json, "handles", &title, a.grid, a.repeat, None, &items);
    if !defaults && !a.json {
        say!("(targets are stated for the default sizes)");
    }
    Ok(())
}

/// Print the items as a table (or JSON with `json`).
fn report(
    json: bool,
    suite: &str,
    title: &str,
    size: usize,
    repeat: usize,
    lattice: Option<usize>,
    items: &[Item],
) {
    if json {
        let items: Vec<serde_json::Value> = items
            .iter()
            .map(|it| {
                serde_json::json!({
                    "name": it.name,
                    "min_s": it.min(),
                    "median_s": it.median(),
                    "max_s": it.max(),
                    "target_s": it.target,
                    "target_met": it.target.map(|t| it.median() <= t),
                    "triangles": it.triangles,
                })
            })
            .collect();
        let doc = serde_json::json!({
            "suite": suite,
            "description": title,
            "size": size,
            "lattice": lattice,
            "repeat": repeat,
            "threads": rayon::current_num_threads(),
            "items": items,
        });
        say!("{doc:#}");
        return;
    }
    let with_triangles = items.iter().any(|it| it.triangles.is_some());
    say!("{title}");
    let mut header = format!(
        "{:<32} {:>9} {:>9} {:>9}  {:<16}",
        "item", "min", "median", "max", "target (median)"
    );
    if with_triangles {
        header.push_str(&format!(" {:>10}", "triangles"));
    }
    say!("{}", header.trim_end());
    // Millisecond items (the handle suite) are shown in ms.
    let (unit, factor) = if suite == "handles" {
        ("ms", 1e3)
    } else {
        ("s", 1.0)
    };
    for it in items {
        let target = match it.target {
            Some(t) if it.median() <= t => format!("<= {:.2} {unit}  met", t * factor),
            Some(t) => format!("<= {:.2} {unit}  MISSED", t * factor),
            None => String::from("-"),
        };
        let mut line = format!(
            "{:<32} {:>7.3} {unit} {:>7.3} {unit} {:>7.3} {unit}  {:<16}",
            it.name,
            it.min() * factor,
            it.median() * factor,
            it.max() * factor,
            target
        );
        if let Some(t) = it.triangles {
            line.push_str(&format!(" {t:>10}"));
        }
        say!("{}", line.trim_end());
    }
    if suite != "ffd" && suite != "handles" && size != TARGET_SIZE {
        say!(
            "(targets are stated for --size {TARGET_SIZE}; the editing items' for --edit-size \
             {EDIT_TARGET_SIZE})"
        );
    }
}
