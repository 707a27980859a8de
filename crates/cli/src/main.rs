//! The `volmorph` command-line tool: one subcommand per user task.
//!
//! Every command reads its inputs, reports errors naming the file and what is wrong (exit
//! status 1), shows a progress bar for long work when standard error is a terminal, and writes
//! outputs to a temporary file that is renamed into place only when complete.

/// `println!` for the command's report on standard output, except that a closed pipe (as in
/// `volmorph info x.nii | head -1`) ends the process quietly with status 141 — what a
/// program killed by `SIGPIPE` reports — instead of panicking.
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::write_stdout(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` with the closed-pipe handling of `say!`.
macro_rules! say_raw {
    ($($arg:tt)*) => {
        $crate::write_stdout(format_args!($($arg)*))
    };
}

mod args;
mod cmd;
mod progress;

/// mimalloc rather than the system allocator: it reuses the memory of freed large buffers
/// instead of returning it to the system and faulting it in again page by page, which cost
/// marching cubes on a 256³ field about a third of its time (see `docs/performance.md`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// volmorph — modeling with volumes by deforming space.
#[derive(Debug, Parser)]
#[command(name = "volmorph", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Memory budget: the most any one array may take, e.g. 8G, 512M or 50% (of physical
    /// memory). Default: 3/4 of physical memory, or the VOLMORPH_MEMORY_LIMIT variable.
    #[arg(long, global = true, value_name = "SIZE", value_parser = volmorph_io::budget::parse_limit)]
    memory_limit: Option<u64>,
    /// Read data a file names even when it lies outside that file's folder: a detached data
    /// file (MetaImage ElementDataFile, NRRD data file), a `vmVolume` volume of a HyperFun
    /// model, a model file of a mapping specification.
    #[arg(long, global = true)]
    allow_external_data: bool,
    /// The 3-D frame (0-based) of every 4-D volume the command reads (a NIfTI or MGH time
    /// series); 3-D inputs are read as they are. Without it a 4-D input is refused, naming its
    /// frame count.
    #[arg(long, global = true, value_name = "N")]
    frame: Option<usize>,
    /// Draw no progress bars (they are drawn on standard error only when it is a terminal;
    /// results, warnings and errors are printed as always).
    #[arg(short, long, global = true)]
    quiet: bool,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Write the built-in models, as volumes and slice pictures, to a folder.
    #[command(after_help = "Example:\n  volmorph demo --out volmorph-demo --size 96")]
    Demo(cmd::demo::Args),
    /// Start the browser studio on 127.0.0.1 and print its URL.
    #[command(
        after_help = "Examples:\n  volmorph studio --phantom teapot --size 128 --lattice 9\n  volmorph studio ct.nii.gz --root ~/data --port 8421"
    )]
    Studio(cmd::studio::Args),
    /// Print a volume file's header, geometry and value statistics.
    #[command(
        after_help = "Examples:\n  volmorph info brain.nii.gz\n  volmorph info bold.nii.gz --frame 12\n  volmorph info dicom/ct_series/\n  volmorph info cells.ome.zarr --header"
    )]
    Info(cmd::info::Args),
    /// Convert a volume between formats, with optional type casting and rescaling.
    #[command(
        after_help = "Examples:\n  volmorph convert ct.nii.gz ct.mha --compress\n  volmorph convert ct.nrrd ct_u8.nii --type u8 --rescale\n  volmorph convert scan.raw scan.nii --raw-dims 256,256,128 --raw-type i16 --raw-spacing 0.9,0.9,1.5\n  volmorph convert dicom/ct_series/ ct.nii.gz\n  volmorph convert bold.nii.gz frame3.vti --frame 3\n  volmorph convert ct.nii.gz ct.ome.zarr --zarr-version 3 --chunk 64,64,64"
    )]
    Convert(cmd::convert::Args),
    /// Write a PNG picture of an axis-aligned slice of a volume.
    #[command(
        after_help = "Examples:\n  volmorph slice ct.nii.gz -o axial.png --axis z --index 54 --window 40,400\n  volmorph slice sdf.nii -o cut.png --axis x --position 0 --colormap cool-warm"
    )]
    Slice(cmd::slice::Args),
    /// Write a built-in model (phantom) as a volume file.
    #[command(
        after_help = "Examples:\n  volmorph phantom teapot -o teapot.nii.gz --size 128\n  volmorph phantom torus -o torus_sdf.mha --kind sdf --dims 96,96,48"
    )]
    Phantom(cmd::phantom::Args),
    /// Extract a level set of a volume as a triangle mesh (marching cubes).
    #[command(
        after_help = "Examples:\n  volmorph isosurface teapot.nii.gz --level 127 -o teapot.ply\n  volmorph isosurface torus_sdf.nii.gz --level 0 --inside-below -o torus.stl"
    )]
    Isosurface(cmd::isosurface::Args),
    /// Warp a volume through any map (lattice, handle map, NURBS geometry, composition, ITK
    /// transform).
    #[command(
        after_help = "Examples:\n  volmorph warp ct.nii.gz --map moved.json -o warped.nii.gz --method pullback-cubic\n  volmorph warp model.nii.gz --map ffd.json -o deformed.nii.gz --method inverse-linear --nonconverged-mask failed.nii.gz\n  volmorph warp ct.nii.gz --map registration.tfm -o resampled.nii.gz\n  volmorph warp teapot.nii.gz --map bent.json -o bent.nii.gz --method pushforward-antialiased --pad 8\n  volmorph warp ct.nii.gz --map moved.json -o on_ref.nii.gz --like reference.nii.gz\n  volmorph warp cells.ome.zarr --lattice moved.json -o warped.ome.zarr   (out of core, chunk by chunk)\n  volmorph warp ct.ome.zarr --map ffd.json -o deformed.ome.zarr --method pushforward-antialiased --pad 16   (out of core)"
    )]
    Warp(cmd::warp::Args),
    /// Drag points of a volume to new places, or a start curve onto a goal curve in steps; the
    /// lattice follows by least-norm moves of the control points inside the tool shape and
    /// realm (direct manipulation, True 1992 §6), and the volume is warped through it.
    #[command(
        after_help = "Examples:\n  volmorph drag teapot.nii.gz --from 0.76,0,0.25 --to 0.86,0,-0.02 --radius 0.75 -o lowered.nii.gz --lattice-out lowered.json\n  volmorph drag ct.nii.gz --lattice current.tfm --from 10,-4,30 --to 12,-4,26 --from 0,0,0 --to 0,0,0 -o ct_dragged.nii.gz --method inverse-linear\n  volmorph drag clay.nii.gz --from 0.7,-0.45,0.4 --to 0.55,-0.3,0.25 --tool box:0.5,0.5,0.5 --realm region:0,-1.2,0,1.2,0,1.2 -o dented.nii.gz\n  volmorph drag tree.nii.gz --start-curve \"0,0,-0.1;0.3,0,0.2;0.6,0,0.6\" --goal-curve \"0,0,-0.1;0.4,0.1,0.15;0.8,0.2,0.45\" --steps 8 --frames gust/ --pad 0,0,0,10,6,0 -o gust.nii.gz"
    )]
    Drag(cmd::drag::Args),
    /// Jacobian determinant map of any map on a volume's grid, with a folding summary.
    #[command(
        after_help = "Examples:\n  volmorph jacobian --map moved.tfm --grid ct.nii.gz -o jacobian.nii.gz\n  volmorph jacobian --map handles_tps.json --grid ct.nii.gz -o j.nii.gz --map-out used.json"
    )]
    Jacobian(cmd::warp::JacobianArgs),
    /// Free-form deformation of a polygon mesh: vertices only, after uniform or adaptive
    /// subdivision, or exactly as trimmed Bézier surfaces (STEP or tessellated).
    #[command(
        after_help = "Examples:\n  volmorph lattice init --mesh cube.obj --degree 2,2,2 --size 4,4,4 -o cube_lattice.json\n  volmorph ffd cube.obj --lattice moved.json --mode accurate -o cube.step\n  volmorph ffd bunny.obj --lattice moved.json --mode adaptive:0.01 -o bunny_adaptive.ply\n  volmorph ffd part.obj --init forward --degree 2,2,1 --size 4,4,2 --mode vertex -o warped.obj   # Feng Fig. 2b: the forward mapping warps before any edit\n  volmorph ffd part.obj --init end-interpolating --degree 2,2,1 --size 4,4,2 --mode accurate -o same.step   # Fig. 2d: the identity"
    )]
    Ffd(cmd::ffd::Args),
    /// B-spline lattice (space map) tasks.
    #[command(subcommand)]
    Lattice(cmd::lattice::Command),
    /// Map files of any kind: apply to points, inspect, compose, invert.
    #[command(subcommand)]
    Map(cmd::map::Command),
    /// Handle-driven deformations (moving least squares, thin-plate splines) of volumes and
    /// meshes.
    #[command(subcommand)]
    Handles(cmd::handles::Command),
    /// Deform a picture with 2D moving least squares through point and segment handles.
    #[command(
        after_help = "Example:\n  volmorph mls2d face.png --handles smile.json -o smiling.png --method rigid\n  volmorph mls2d face.png --handles smile.json -o smiling_tps.png --method tps   # kernel r² log r (--kernel r2logr, the only 2-D one)\n\nHandles: {\"points\": [{\"source\": [x, y], \"target\": [x, y]}], \"segments\": [{\"source\": [[x, y], [x, y]], \"target\": [[x, y], [x, y]]}]}\nin pixel coordinates (x right, y down)."
    )]
    Mls2d(cmd::mls2d::Mls2dArgs),
    /// Polygon mesh tasks.
    #[command(subcommand)]
    Mesh(cmd::mesh::Command),
    /// F-rep models (HyperFun language): sample, mesh, render, morph.
    #[command(subcommand)]
    Frep(cmd::frep::Command),
    /// Trivariate NURBS volumes with attributes: fit, evaluate, slice, isosurface, ray-traced
    /// rendering, optical paths.
    #[command(subcommand)]
    Nurbs(cmd::nurbs::Command),
    /// Direct volume rendering: composite, maximum-intensity or isosurface pictures of a
    /// volume, optionally deformed by a map, turntables, and the quality view of a source
    /// against a deformed target.
    #[command(
        after_help = "Examples:\n  volmorph render ct.nii.gz -o skull.png --transfer ct-bone --view anterior\n  volmorph render ct.nii.gz -o mip.png --mode mip --view 30,10 --size 800x600\n  volmorph render ct.nii.gz --handles moves.json --method affine -o bent.png\n  volmorph render ct.nii.gz --frames 36 -o spin/   (frame0000.png … and spin/turntable.png)\n  volmorph render --compare fixed.nii.gz moving.nii.gz --map registration.tfm -o quality.png"
    )]
    Render(cmd::render::Args),
    /// Sculpt a closed mesh with a closed tool mesh (add, subtract, intersect; one dab or a
    /// painting stroke) and smooth a region, re-contouring only what changed (depth-peel CSG).
    #[command(
        after_help = "Examples:\n  volmorph sculpt bunny.obj --tool sphere.obj --op subtract -o carved.ply\n  volmorph sculpt dragon.ply --tool brush.stl --op add --stroke stroke.json --grid 384 -o painted.obj\n  volmorph sculpt part.stl --tool box.obj --op intersect --smooth 0,0,0,10,10,10 --smooth-kernel 3 -o part_cut.stl\n\nStroke file: {\"step\": 0.01, \"poses\": [{\"translate\": [x, y, z], \"rotate\": [w, x, y, z] or {\"axis\": [x, y, z], \"degrees\": a}, \"scale\": s}, ...]}\n(the tool's own coordinates are moved by scale, then rotation, then translation; dabs are inserted so no point moves more than `step`, by default one grid spacing)."
    )]
    Sculpt(cmd::sculpt::Args),
    /// Register two scans: handles, correspondences, deformation, quality, lungs, ventilation.
    #[command(
        after_help = "Examples:\n  volmorph register inhale.nii.gz exhale.nii.gz -o out --handles 300 --radius 10 --method frames --dense --landmarks lm_in.txt,lm_ex.txt\n  volmorph register inhale.nii.gz exhale.nii.gz -o out_tps --method tps --kernel r2logr   # thin-plate with the thesis's r² log r kernel (default r)\n  volmorph register select inhale.nii.gz -o handles.txt"
    )]
    Register(cmd::register::Command),
    /// Scene projects (`.vmproj`, the studio's files): make one from files and built-in
    /// set-ups, list its objects, export one.
    #[command(subcommand)]
    Project(cmd::project::Command),
    /// Time the warps and isosurface extractors on built-in inputs, against their targets.
    #[command(subcommand)]
    Bench(cmd::bench::Command),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.memory_limit {
        Some(bytes) => volmorph_io::set_memory_limit(bytes),
        None => {
            if let Err(e) = volmorph_io::budget::memory_limit_from_env() {
                eprintln!("volmorph: error: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    volmorph_volume_io::set_allow_external_data_default(cli.allow_external_data);
    volmorph_volume_io::set_frame_default(cli.frame);
    progress::set_quiet(cli.quiet);
    let result = match cli.command {
        Command::Demo(a) => cmd::demo::run(&a),
        Command::Studio(a) => cmd::studio::run(&a),
        Command::Info(a) => cmd::info::run(&a),
        Command::Convert(a) => cmd::convert::run(&a),
        Command::Slice(a) => cmd::slice::run(&a),
        Command::Phantom(a) => cmd::phantom::run(&a),
        Command::Isosurface(a) => cmd::isosurface::run(&a),
        Command::Ffd(a) => cmd::ffd::run(&a),
        Command::Lattice(c) => cmd::lattice::run(&c),
        Command::Warp(a) => cmd::warp::run(&a),
        Command::Drag(a) => cmd::drag::run(&a),
        Command::Jacobian(a) => cmd::warp::run_jacobian(&a),
        Command::Mesh(c) => cmd::mesh::run(&c),
        Command::Frep(c) => cmd::frep::run(&c),
        Command::Map(c) => cmd::map::run(&c),
        Command::Handles(c) => cmd::handles::run(&c),
        Command::Mls2d(a) => cmd::mls2d::run_mls2d(&a),
        Command::Nurbs(c) => cmd::nurbs::run(&c),
        Command::Render(a) => cmd::render::run(&a),
        Command::Sculpt(a) => cmd::sculpt::run(&a),
        Command::Register(c) => cmd::register::run(&c),
        Command::Project(c) => cmd::project::run(&c),
        Command::Bench(c) => cmd::bench::run(&c),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("volmorph: error: {}", error_chain(&e));
            ExitCode::FAILURE
        }
    }
}

/// Write to standard output; on a closed pipe exit with status 141 (see `say!`), on any
/// other write error report it and exit with status 1.
fn write_stdout(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(141);
        }
        eprintln!("volmorph: error: cannot write to standard output: {e}");
        std::process::exit(1);
    }
}

/// The error and its causes joined by `": "`, leaving out a cause whose text its parent's
/// message already contains (many error types print their cause *and* return it as
/// `source()`), so every cause is said once.
fn error_chain(e: &anyhow::Error) -> String {
    let mut out = e.to_string();
    let mut parent = out.clone();
    for cause in e.chain().skip(1) {
        let msg = cause.to_string();
        if !parent.contains(&msg) {
            out.push_str(": ");
            out.push_str(&msg);
        }
        parent = msg;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn error_chain_says_each_cause_once() {
        #[derive(Debug, thiserror::Error)]
        #[error("lattice JSON: {0}")]
        struct Wrapped(#[from] std::io::Error);
        let inner = std::io::Error::other("EOF at line 2");
        let e = anyhow::Error::from(Wrapped(inner)).context("cannot read lattice");
        assert_eq!(
            error_chain(&e),
            "cannot read lattice: lattice JSON: EOF at line 2"
        );
        // Causes not repeated by their parent are all kept.
        let e = anyhow::anyhow!("inner").context("middle").context("outer");
        assert_eq!(error_chain(&e), "outer: middle: inner");
    }

    #[test]
    fn cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn every_command_has_an_example() {
        fn check(c: &clap::Command, path: &str) {
            let subs: Vec<_> = c.get_subcommands().collect();
            if subs.is_empty() {
                let help = c
                    .get_after_help()
                    .map(|s| s.to_string())
                    .unwrap_or_default();
                assert!(
                    help.contains("Example"),
                    "`{path}` has no example in --help"
                );
            }
            for s in subs {
                check(s, &format!("{path} {}", s.get_name()));
            }
        }
        check(&Cli::command(), "volmorph");
    }
}
