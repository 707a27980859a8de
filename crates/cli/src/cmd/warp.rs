//! `volmorph warp` and `volmorph jacobian`: apply a lattice to a volume, measure a lattice.

use std::path::PathBuf;

use anyhow::Context;
use volmorph_deform::formats::read_lattice;
use volmorph_volume::format;
use volmorph_volume::sample::Interpolation;
use volmorph_warp::jacobian::{FoldingReport, jacobian_determinant};
use volmorph_warp::pullback::{ResampleOptions, resample_any};

use crate::progress;

/// How a warp applies the lattice; the name says the direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
#[allow(clippy::enum_variant_names)] // the direction is part of every method's name, on purpose
pub enum Method {
    /// Pull-back (ITK's resampling convention): output voxel x takes the input at
    /// lattice(x), nearest neighbour.
    PullbackNearest,
    /// Pull-back with trilinear interpolation.
    PullbackLinear,
    /// Pull-back with prefiltered cubic B-spline interpolation.
    PullbackCubic,
}

/// Arguments of `volmorph warp`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume.
    pub input: PathBuf,
    /// Lattice file (.json, .tfm, .bxf).
    #[arg(long)]
    pub lattice: PathBuf,
    /// Output volume, on the input's grid and with its voxel type.
    #[arg(short, long)]
    pub output: PathBuf,
    /// How the lattice is applied.
    #[arg(long, value_enum, default_value_t = Method::PullbackLinear)]
    pub method: Method,
    /// Value of output voxels whose source lies outside the input.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub default: f64,
}

/// Run `volmorph warp`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let pb = progress::spinner(format!("reading {}", args.input.display()));
    let vol = format::read(&args.input).context("cannot read volume")?;
    let lattice = read_lattice(&args.lattice).context("cannot read lattice")?;
    pb.set_message("warping");
    let interpolation = match args.method {
        Method::PullbackNearest => Interpolation::Nearest,
        Method::PullbackLinear => Interpolation::Linear,
        Method::PullbackCubic => Interpolation::CubicBSpline,
    };
    let options = ResampleOptions::new(interpolation, args.default);
    let out = resample_any(&vol, &lattice, vol.geometry(), &options)
        .with_context(|| format!("cannot warp {}", args.input.display()))?;
    pb.set_message(format!("writing {}", args.output.display()));
    format::write(&args.output, &out).context("cannot write")?;
    pb.finish_and_clear();
    Ok(())
}

/// Arguments of `volmorph jacobian`.
#[derive(Debug, clap::Args)]
pub struct JacobianArgs {
    /// Lattice file (.json, .tfm, .bxf).
    #[arg(long)]
    pub lattice: PathBuf,
    /// Volume whose grid the determinant is sampled on.
    #[arg(long)]
    pub grid: PathBuf,
    /// Output volume of Jacobian determinants (f32); J <= 0 marks folding.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Run `volmorph jacobian`.
pub fn run_jacobian(args: &JacobianArgs) -> anyhow::Result<()> {
    let pb = progress::spinner(format!("reading {}", args.grid.display()));
    let grid = *format::read(&args.grid)
        .context("cannot read volume")?
        .geometry();
    let lattice = read_lattice(&args.lattice).context("cannot read lattice")?;
    pb.set_message("Jacobian determinants");
    let det = jacobian_determinant(&lattice, &grid)?;
    let report = FoldingReport::of(det.data());
    pb.set_message(format!("writing {}", args.output.display()));
    format::write(&args.output, &det.into()).context("cannot write")?;
    pb.finish_and_clear();
    println!("{report}");
    Ok(())
}
