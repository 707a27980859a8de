//! `volmorph warp` and `volmorph jacobian`: apply a lattice to a volume, measure a lattice.

use std::path::PathBuf;

use anyhow::{Context, bail};
use volmorph_deform::BSplineLattice;
use volmorph_deform::formats::read_lattice;
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{AnyVolume, format, with_volume};
use volmorph_warp::jacobian::{FoldingReport, jacobian_determinant};
use volmorph_warp::pullback::{ResampleOptions, resample_any};
use volmorph_warp::pushforward::{
    AntialiasOptions, push_forward_antialiased, push_forward_nearest,
};

use crate::progress;

/// How a warp applies the lattice; the name says the direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Pull-back (ITK's resampling convention): output voxel x takes the input at
    /// lattice(x), nearest neighbour.
    PullbackNearest,
    /// Pull-back with trilinear interpolation.
    PullbackLinear,
    /// Pull-back with prefiltered cubic B-spline interpolation.
    PullbackCubic,
    /// Push-forward (free-form deformation of the model): every input voxel is sent to
    /// lattice(x) and written into the nearest output voxel (True 1992 §5.3, a fast preview;
    /// holes stay at the background, collisions keep the largest value).
    PushforwardNearest,
    /// Push-forward with True's box-filter antialiasing (§5.4): each voxel's mapped box is
    /// spread over the output voxels it overlaps.
    PushforwardAntialiased,
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
    let out = warp(&vol, &lattice, args.method, args.default)
        .with_context(|| format!("cannot warp {}", args.input.display()))?;
    pb.set_message(format!("writing {}", args.output.display()));
    format::write(&args.output, &out).context("cannot write")?;
    pb.finish_and_clear();
    Ok(())
}

/// Warp `vol` on its own grid by `method`; `default` fills output voxels nothing reaches.
fn warp(
    vol: &AnyVolume,
    lattice: &BSplineLattice,
    method: Method,
    default: f64,
) -> anyhow::Result<AnyVolume> {
    let grid = vol.geometry();
    let interpolation = match method {
        Method::PullbackNearest => Interpolation::Nearest,
        Method::PullbackLinear => Interpolation::Linear,
        Method::PullbackCubic => Interpolation::CubicBSpline,
        Method::PushforwardNearest => {
            if default != 0.0 {
                bail!("--default is not used by pushforward-nearest (holes stay 0)");
            }
            return Ok(with_volume!(vol, v => {
                AnyVolume::from(push_forward_nearest(v, lattice, grid)?.volume)
            }));
        }
        Method::PushforwardAntialiased => {
            let options = AntialiasOptions {
                background: default,
                ..AntialiasOptions::default()
            };
            return Ok(with_volume!(vol, v => {
                AnyVolume::from(push_forward_antialiased(v, lattice, grid, &options)?.volume)
            }));
        }
    };
    let options = ResampleOptions::new(interpolation, default);
    Ok(resample_any(vol, lattice, grid, &options)?)
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
