//! `volmorph bench …`: time the warps, the isosurface extractors, mesh FFD, F-rep sampling,
//! the handle-driven deformations and a drag through the scene, and print each item's min /
//! median / max wall-clock time next to its target. The set-ups, cases, targets and report
//! are `volmorph_bench`'s, shared with the criterion benches.

use std::path::PathBuf;

use anyhow::{Context, anyhow};
use volmorph_bench::{BenchError, Report, ffd, frep, handles, isosurface, roofline, scene, warp};

use crate::{args, progress};

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
    /// (target 2 s), vertex FFD of a 1M-vertex sphere (target 25 ms), the STEP text of the
    /// accurate FFD's result, and point + gradient of a rational tricubic 8³ volume at 2²⁰
    /// points (target 20 M points/s).
    #[command(after_help = "Example:\n  volmorph bench ffd --repeat 3")]
    Ffd(FfdArgs),
    /// Time grid evaluation of F-rep models (HyperFun files, or the seven built-in scenes
    /// without files): the culled, specialised sampler against the published libfive figures
    /// (193³ over [−1.6, 1.6]³), checked against point-by-point evaluation.
    #[command(
        after_help = "Examples:\n  volmorph bench frep s1_sphere.hf c1_gear.hf --grid 193 --repeat 7 --json\n  volmorph bench frep --repeat 5"
    )]
    Frep(FrepArgs),
    /// Time the handle-driven deformations against their targets: 2D rigid MLS on a 100×100
    /// grid (11 point handles; 7 segment handles), 3D affine MLS with 200 handles sampled on a
    /// 32³ grid over a 256×256×112 volume (set-up, update after one handle moves, resampling
    /// the volume) and a thin-plate spline through 1000 landmarks (factorise, re-solve after
    /// one landmark moves, evaluate on 32³).
    #[command(after_help = "Example:\n  volmorph bench handles --repeat 7 --json")]
    Handles(HandlesArgs),
    /// Time a drag of the teapot's spout end to end through the scene (command, solve,
    /// incremental warp update, dirty-region report; target 40 ms at 128³) against the same
    /// drag on the engines directly, and the scene's overhead (target 1 ms).
    #[command(after_help = "Example:\n  volmorph bench scene --size 128 --repeat 9")]
    Scene(SceneArgs),
    /// Measure this machine's roofs, on one thread and on all: memory bandwidth (read, copy
    /// and STREAM triad over arrays far beyond the cache) and floating-point issue rate
    /// (fused multiply-add in f64 and f32, multiply then add in f64, the roof of bit-exact
    /// kernels). docs/performance.md bounds every hot path by these figures.
    #[command(after_help = "Example:\n  volmorph bench roofline --repeat 5 --megabytes 256")]
    Roofline(RooflineArgs),
}

/// Arguments of `volmorph bench warp`.
#[derive(Debug, clap::Args)]
pub struct WarpArgs {
    /// Voxels per axis of the teapot phantom (a cube).
    #[arg(long, default_value_t = warp::TARGET_SIZE)]
    pub size: usize,
    /// Control points per axis of the uniform cubic lattice (at least 4).
    #[arg(long, default_value_t = warp::TARGET_LATTICE)]
    pub lattice: usize,
    /// Timed runs per item.
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Voxels per axis of the teapot for the interactive-editing items (incremental update
    /// after moving one control point, drag).
    #[arg(long, default_value_t = warp::EDIT_TARGET_SIZE)]
    pub edit_size: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `volmorph bench isosurface`.
#[derive(Debug, clap::Args)]
pub struct IsosurfaceArgs {
    /// Voxels per axis of the sphere's distance field (a cube).
    #[arg(long, default_value_t = isosurface::TARGET_SIZE)]
    pub size: usize,
    /// Timed runs per item.
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `volmorph bench ffd`.
#[derive(Debug, clap::Args)]
pub struct FfdArgs {
    /// Latitude rings of the sphere for the accurate FFD (4·r·(r−1) triangles).
    #[arg(long, default_value_t = ffd::TARGET_RINGS)]
    pub rings: u32,
    /// Latitude rings of the sphere for vertex FFD (2·r·(r−1)+2 vertices).
    #[arg(long, default_value_t = ffd::TARGET_VERTEX_RINGS)]
    pub vertex_rings: u32,
    /// Parameter triples of the trivariate point-and-gradient batch.
    #[arg(long, default_value_t = ffd::TRIVARIATE_POINTS)]
    pub points: usize,
    /// Timed runs per item.
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `volmorph bench frep`.
#[derive(Debug, clap::Args)]
pub struct FrepArgs {
    /// Model files (HyperFun language); without any, the seven built-in scenes.
    pub models: Vec<PathBuf>,
    /// Grid points per axis.
    #[arg(long, default_value_t = frep::TARGET_GRID)]
    pub grid: usize,
    /// Timed runs per model.
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Skip the comparison with point-by-point evaluation.
    #[arg(long)]
    pub no_check: bool,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub common: crate::cmd::frep::Common,
}

/// Arguments of `volmorph bench handles`. Targets are shown only for the default sizes.
#[derive(Debug, clap::Args)]
pub struct HandlesArgs {
    /// Vertices per axis of the 2D MLS image grid.
    #[arg(long, default_value_t = handles::HandlesConfig::default().image_grid)]
    pub image_grid: usize,
    /// Handles of the 3D affine MLS map.
    #[arg(long, default_value_t = handles::HandlesConfig::default().handles)]
    pub handles: usize,
    /// Voxels of the resampled volume along x, y, z.
    #[arg(long, default_value = "256,256,112", value_parser = args::triple::<usize>)]
    pub volume: [usize; 3],
    /// Nodes per axis of the sampled MLS grid and of the thin-plate evaluation grid.
    #[arg(long, default_value_t = handles::HandlesConfig::default().grid)]
    pub grid: usize,
    /// Landmarks of the thin-plate spline.
    #[arg(long, default_value_t = handles::HandlesConfig::default().landmarks)]
    pub landmarks: usize,
    /// Timed runs per item.
    #[arg(long, default_value_t = 7)]
    pub repeat: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `volmorph bench scene`.
#[derive(Debug, clap::Args)]
pub struct SceneArgs {
    /// Voxels per axis of the teapot.
    #[arg(long, default_value_t = warp::EDIT_TARGET_SIZE)]
    pub size: usize,
    /// Control points per axis of the identity lattice.
    #[arg(long, default_value_t = warp::TARGET_LATTICE)]
    pub lattice: usize,
    /// Timed runs per item (the two drags alternate).
    #[arg(long, default_value_t = 9)]
    pub repeat: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `volmorph bench roofline`.
#[derive(Debug, clap::Args)]
pub struct RooflineArgs {
    /// Size of each of the three bandwidth arrays, in MiB (64 to 4096).
    #[arg(long, default_value_t = roofline::DEFAULT_MEGABYTES)]
    pub megabytes: usize,
    /// Timed runs per probe.
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Run a bench subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    let pb = progress::spinner("setting up");
    let mut progress = |msg: &str| pb.set_message(msg.to_owned());
    let (report, json) = match cmd {
        Command::Warp(a) => (
            warp::run(
                &warp::WarpConfig {
                    size: a.size,
                    lattice: a.lattice,
                    edit_size: a.edit_size,
                    repeat: a.repeat,
                },
                &mut progress,
            ),
            a.json,
        ),
        Command::Isosurface(a) => (
            isosurface::run(
                &isosurface::IsosurfaceConfig {
                    size: a.size,
                    repeat: a.repeat,
                },
                &mut progress,
            ),
            a.json,
        ),
        Command::Ffd(a) => (
            ffd::run(
                &ffd::FfdConfig {
                    rings: a.rings,
                    vertex_rings: a.vertex_rings,
                    points: a.points,
                    repeat: a.repeat,
                },
                &mut progress,
            ),
            a.json,
        ),
        Command::Frep(a) => {
            let (config, models) = frep_models(a)?;
            (frep::run(&config, models, &mut progress), a.json)
        }
        Command::Handles(a) => (
            handles::run(
                &handles::HandlesConfig {
                    image_grid: a.image_grid,
                    handles: a.handles,
                    volume: a.volume,
                    grid: a.grid,
                    landmarks: a.landmarks,
                    repeat: a.repeat,
                },
                &mut progress,
            ),
            a.json,
        ),
        Command::Scene(a) => (
            scene::run(
                &scene::SceneConfig {
                    size: a.size,
                    lattice: a.lattice,
                    repeat: a.repeat,
                },
                &mut progress,
            ),
            a.json,
        ),
        Command::Roofline(a) => (
            roofline::run(
                &roofline::RooflineConfig {
                    megabytes: a.megabytes,
                    repeat: a.repeat,
                },
                &mut progress,
            ),
            a.json,
        ),
    };
    pb.finish_and_clear();
    let report = report.map_err(flags)?;
    print(&report, json);
    Ok(())
}

/// The F-rep settings and models: the files compiled with `--param`, their targets by the
/// published scenes' names, or the built-in scenes without files.
fn frep_models(a: &FrepArgs) -> anyhow::Result<(frep::FrepConfig, Vec<frep::FrepModel>)> {
    let config = frep::FrepConfig {
        grid: a.grid,
        bounds: match &a.common.bounds {
            Some(b) => crate::cmd::frep::bounds(b)?,
            None => frep::TARGET_BOUNDS,
        },
        repeat: a.repeat,
        check: !a.no_check,
    };
    if a.models.is_empty() {
        if !a.common.params.is_empty() {
            anyhow::bail!("--param applies to model files; the built-in scenes take none");
        }
        let models = frep::builtin_scenes().context("cannot compile the built-in scenes")?;
        return Ok((config, models));
    }
    let params = crate::cmd::frep::params(&a.common.params)?;
    let models = a
        .models
        .iter()
        .map(|path| {
            Ok(frep::FrepModel {
                name: path.display().to_string(),
                shape: crate::cmd::frep::load(path, &params)?,
                target: path
                    .file_stem()
                    .and_then(|s| frep::published_scene_target(&s.to_string_lossy())),
            })
        })
        .collect::<anyhow::Result<_>>()?;
    Ok((config, models))
}

/// A setting out of range named as its command-line option (`edit_size` as `--edit-size`).
fn flags(e: BenchError) -> anyhow::Error {
    match e {
        BenchError::Setting {
            setting,
            value,
            expected,
        } => anyhow!("--{} {value} {expected}", setting.replace('_', "-")),
        other => anyhow::Error::new(other),
    }
}

/// Print `report` as a table, or as JSON with `json`.
fn print(report: &Report, json: bool) {
    if json {
        say!("{:#}", report.to_json());
    } else {
        say_raw!("{}", report.to_text());
    }
}
