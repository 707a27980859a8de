//! `volmorph handles …`: handle-driven deformations (moving least squares, thin-plate /
//! volume splines) of volumes and meshes (pictures: `volmorph mls2d`, [`super::mls2d`]).
//!
//! Handle files are described in `volmorph_handles::handles`: a volmorph handle JSON with
//! source → target pairs (`--handles H.json`), a six-column `x y z x' y' z'` text file
//! (`--handles pairs.txt`), or two point lists paired by order (`--from src.fcsv --to
//! dst.fcsv`, Slicer markups or three-column text).
//!
//! Direction: the deformation sends every source handle to its target; `warp` moves a mesh
//! forward and resamples a volume by pull-back, as `volmorph_scene::by_handles` states.

use std::path::PathBuf;

use anyhow::{Context, bail};
use volmorph_deform::SpaceMap;
use volmorph_handles::TpsKernel;
use volmorph_handles::Weighting;
use volmorph_handles::handles::{HandleSet, read_point_list, write_point_list};
use volmorph_maps::{HandleDirection, HandleMethod, HandleOptions, handle_map};
use volmorph_scene::by_handles::{self, HandleSpec, VolumeWarp};
use volmorph_scene::files::{FileKind, kind_of};
use volmorph_volume_io as format;

use crate::progress;

/// Handle subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Deform a volume or a mesh (format by extension) so that source handles move to their
    /// targets, and report how much of the domain folds (Jacobian determinant <= 0).
    #[command(
        after_help = "Examples:\n  volmorph handles warp ct.nii.gz --handles moves.json --method rigid -o ct_moved.nii.gz\n  volmorph handles warp teapot.ply --from src.fcsv --to dst.fcsv --method tps -o bent.ply\n  volmorph handles warp teapot.ply --from src.fcsv --to dst.fcsv --method tps --kernel r2logr -o bent_thesis.ply\n  volmorph handles warp ct.nii.gz --handles pairs.txt --method affine --exact -o exact.nii.gz\n\nHandle files: .json {\"points\": [{\"source\": [x,y,z], \"target\": [x,y,z]}], \"frames\": [...]}\n(pairs), .txt/.xyz with 6 numbers per line (pairs), or two point lists (--from/--to,\n.fcsv Slicer markups or 3 numbers per line) paired by order."
    )]
    Warp(WarpArgs),
    /// Map a list of points (forward: sources go to targets) and write them as text, one
    /// `x y z` per line with every digit needed to read the same f64 back.
    #[command(
        after_help = "Example:\n  volmorph handles apply probes.txt --handles moves.json --method tps -o mapped.txt"
    )]
    Apply(ApplyArgs),
}

/// Arguments of `volmorph handles apply`.
#[derive(Debug, clap::Args)]
pub struct ApplyArgs {
    /// Points to map: .fcsv (Slicer) or text with 3 numbers per line.
    pub input: PathBuf,
    /// The deformation, as for `handles warp`.
    #[command(flatten)]
    pub map: MapArgs,
    /// Output text file.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Deformation method of `volmorph handles warp`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Affine moving least squares (at least 4 handles, not all on one plane).
    Affine,
    /// Similarity moving least squares (rotation and uniform scale; at least 3 handles).
    Similarity,
    /// Rigid moving least squares (rotation only; at least 3 handles).
    Rigid,
    /// Thin-plate / biharmonic volume spline (at least 4 handles, not all on one plane).
    Tps,
    /// Frame-based moving least squares (frame handles from the JSON "frames" list).
    Frames,
    /// Affine trend plus compactly supported Wendland kernels (sparse Cholesky): interpolates
    /// like tps and scales to tens of thousands of handles.
    Wendland,
}

/// Weight function of the moving-least-squares methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum WeightKind {
    /// 1 / |p - v|^(2 alpha) (interpolating).
    InverseDistance,
    /// exp(-|p - v|² / (2 sigma²)) (approximating).
    Gaussian,
}

/// The handles and method of a deformation (shared by `handles warp` and `handles apply`).
#[derive(Debug, clap::Args)]
pub struct MapArgs {
    /// Handle pairs: volmorph handle JSON, or text with 6 numbers per line.
    #[arg(long, conflicts_with_all = ["from", "to"])]
    pub handles: Option<PathBuf>,
    /// Source point list (.fcsv or 3-column text), paired by order with --to.
    #[arg(long, requires = "to")]
    pub from: Option<PathBuf>,
    /// Target point list (.fcsv or 3-column text), paired by order with --from.
    #[arg(long, requires = "from")]
    pub to: Option<PathBuf>,
    /// Deformation method.
    #[arg(long, value_enum, default_value_t = Method::Rigid)]
    pub method: Method,
    /// Weight function of the MLS methods.
    #[arg(long, value_enum, default_value_t = WeightKind::InverseDistance)]
    pub weight: WeightKind,
    /// Exponent alpha of the inverse-distance weights.
    #[arg(long, default_value_t = 1.0)]
    pub alpha: f64,
    /// Width sigma of the Gaussian weights (physical units); required with --weight gaussian.
    #[arg(long)]
    pub sigma: Option<f64>,
    /// Weight beta of the frame axes (frames method).
    #[arg(long, default_value_t = 1.0)]
    pub beta: f64,
    /// Smoothing of the thin-plate and Wendland splines (0 interpolates the handles).
    #[arg(long, default_value_t = 0.0)]
    pub smoothing: f64,
    /// Support radius of the Wendland kernels (physical units): a handle bends the map only
    /// within this distance. Default: the radius that reaches about 40 other handles on
    /// average, from the handles' bounding box (see the `wendland` method).
    #[arg(long, value_name = "R")]
    pub support: Option<f64>,
    /// Radial kernel of the thin-plate spline (tps method): r, the true 3-D biharmonic kernel
    /// (minimal bending energy in 3-D, the default), or r2logr, r² log r as in McPhail's
    /// thesis §5.4.1 (the 2-D biharmonic kernel used in 3-D). Both interpolate the handles.
    #[arg(long, value_enum, default_value_t = Kernel::R)]
    pub kernel: Kernel,
}

/// Radial kernel of the thin-plate spline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Kernel {
    /// G(r) = r: the biharmonic Green's function in 3-D.
    R,
    /// G(r) = r² log r: the 2-D biharmonic kernel (McPhail §5.4.1, Bookstein).
    #[value(name = "r2logr")]
    R2logr,
}

impl From<Kernel> for TpsKernel {
    fn from(k: Kernel) -> Self {
        match k {
            Kernel::R => TpsKernel::R,
            Kernel::R2logr => TpsKernel::R2LogR,
        }
    }
}

/// Arguments of `volmorph handles warp`.
#[derive(Debug, clap::Args)]
pub struct WarpArgs {
    /// Input volume (.nii, .nii.gz, .mha, .mhd, .nrrd, .vtk) or mesh (.obj, .stl, .ply, .off).
    pub input: PathBuf,
    /// The deformation.
    #[command(flatten)]
    pub map: MapArgs,
    /// Nodes per axis of the coarse grid the map is sampled on (trilinear in between) for
    /// volumes and for the fold report.
    #[arg(long, default_value_t = 32)]
    pub grid: usize,
    /// Evaluate the map exactly at every voxel instead of on the coarse grid.
    #[arg(long)]
    pub exact: bool,
    /// Value of output voxels whose source lies outside the input.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub default: f64,
    /// Output volume or mesh (format by extension).
    #[arg(short, long)]
    pub output: PathBuf,
}

impl From<Method> for HandleMethod {
    fn from(m: Method) -> Self {
        match m {
            Method::Affine => HandleMethod::Affine,
            Method::Similarity => HandleMethod::Similarity,
            Method::Rigid => HandleMethod::Rigid,
            Method::Tps => HandleMethod::Tps,
            Method::Frames => HandleMethod::Frames,
            Method::Wendland => HandleMethod::Wendland,
        }
    }
}

/// Run a handles subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Warp(a) => warp(a),
        Command::Apply(a) => apply(a),
    }
}

/// Read the handle set of `--handles` or `--from/--to`.
pub(crate) fn read_handle_set(a: &MapArgs) -> anyhow::Result<HandleSet> {
    let set = match (&a.handles, &a.from, &a.to) {
        (Some(h), _, _) => HandleSet::read(h)
            .with_context(|| format!("cannot read the handles {}", h.display()))?,
        (None, Some(f), Some(t)) => {
            let s = read_point_list(f)
                .with_context(|| format!("cannot read the source points {}", f.display()))?;
            let d = read_point_list(t)
                .with_context(|| format!("cannot read the target points {}", t.display()))?;
            HandleSet::from_lists(&s, &d)?
        }
        _ => bail!("give the handles with --handles FILE or --from SOURCES --to TARGETS"),
    };
    set.validate().context("bad handles")?;
    Ok(set)
}

pub(crate) fn options(a: &MapArgs) -> anyhow::Result<HandleOptions> {
    Ok(HandleOptions {
        weighting: match a.weight {
            WeightKind::InverseDistance => Weighting::InverseDistance { alpha: a.alpha },
            WeightKind::Gaussian => Weighting::Gaussian {
                sigma: a
                    .sigma
                    .context("--weight gaussian needs --sigma (physical width)")?,
            },
        },
        beta: a.beta,
        smoothing: a.smoothing,
        support: match a.support {
            Some(r) if a.method != Method::Wendland => {
                bail!("--support {r}: only the wendland method has a support radius")
            }
            s => s,
        },
        kernel: match a.kernel {
            Kernel::R2logr if a.method != Method::Tps => {
                bail!("--kernel r2logr: only the tps method has a kernel choice")
            }
            k => k.into(),
        },
    })
}

fn warp(a: &WarpArgs) -> anyhow::Result<()> {
    // The output is of the input's kind (a mesh by its extension, else a volume).
    if volmorph_mesh::MeshFormat::from_path(&a.input).is_ok() {
        volmorph_mesh::format::check_output(&a.output)?;
    } else {
        format::check_output(&a.output)?;
    }
    let set = read_handle_set(&a.map)?;
    let opts = options(&a.map)?;
    let spec = HandleSpec {
        set: &set,
        method: a.map.method.into(),
        options: &opts,
    };
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    if kind_of(&a.input)? == FileKind::Mesh {
        let mut m = volmorph_mesh::read(&a.input).context("cannot read the mesh")?;
        pb.set_message("moving vertices");
        let fold =
            by_handles::deform_mesh(&mut m, spec, a.grid).context("cannot deform the mesh")?;
        pb.set_message(format!("writing {}", a.output.display()));
        volmorph_mesh::write(&a.output, &m).context("cannot write")?;
        pb.finish_and_clear();
        say!(
            "moved {} vertices by {} handles",
            m.positions().len(),
            set.len()
        );
        if let Some(f) = fold {
            say!("{f}");
        }
        return Ok(());
    }
    let vol = format::read(&a.input).context("cannot read the volume")?;
    let how = VolumeWarp {
        background: a.default,
        exact: a.exact,
        grid: a.grid,
    };
    let (out, report) = by_handles::warp_volume(&vol, spec, &how, &progress::Bar(&pb))
        .with_context(|| format!("cannot warp {}", a.input.display()))?;
    progress::spin(&pb, format!("writing {}", a.output.display()));
    format::write(&a.output, &out).context("cannot write")?;
    pb.finish_and_clear();
    say!(
        "warped {} by {} handles ({})",
        a.input.display(),
        set.len(),
        if a.exact {
            "exact per voxel"
        } else {
            "coarse grid, trilinear"
        }
    );
    say!("pull-back map {report}");
    Ok(())
}

fn apply(a: &ApplyArgs) -> anyhow::Result<()> {
    volmorph_handles::handles::check_point_list_output(&a.output)?;
    let pb = progress::spinner("reading the handles and the points");
    let set = read_handle_set(&a.map)?;
    let pts = read_point_list(&a.input)
        .with_context(|| format!("cannot read the points {}", a.input.display()))?;
    progress::spin(&pb, format!("building the map of {} handles", set.len()));
    let map = handle_map(
        &set,
        a.map.method.into(),
        &options(&a.map)?,
        HandleDirection::SourcesToTargets,
    )
    .context("cannot build the deformation")?;
    progress::spin(&pb, format!("mapping {} points", pts.len()));
    let mut out = vec![glam::DVec3::ZERO; pts.len()];
    map.apply_batch(&pts, &mut out)?;
    write_point_list(&a.output, &out)
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    pb.finish_and_clear();
    say!("mapped {} points by {} handles", out.len(), set.len());
    Ok(())
}
