//! `volmorph warp` and `volmorph jacobian`: apply a lattice to a volume, measure a lattice
//! (the determinant map comes from the lattice's separable Jacobian tables).

use std::path::PathBuf;

use anyhow::{Context, bail};
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::formats::read_lattice;
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{AnyVolume, Volume, with_volume};
use volmorph_volume_io as format;
use volmorph_warp::inverse::{InverseResampleOptions, pullback_through_inverse_any};
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
    /// Pull-back through the inverse of the lattice: renders the model deformed by the
    /// lattice used as a free-form deformation (output voxel y takes the input at
    /// lattice⁻¹(y), found by Newton iteration), nearest neighbour.
    InverseNearest,
    /// Pull-back through the inverse of the lattice (free-form deformation without holes or
    /// blur), trilinear interpolation.
    InverseLinear,
    /// Pull-back through the inverse of the lattice, prefiltered cubic B-spline
    /// interpolation.
    InverseCubic,
}

impl Method {
    /// The interpolation kernel of a pull-back method, direct or through the inverse.
    fn interpolation(self) -> Option<Interpolation> {
        match self {
            Method::PullbackNearest | Method::InverseNearest => Some(Interpolation::Nearest),
            Method::PullbackLinear | Method::InverseLinear => Some(Interpolation::Linear),
            Method::PullbackCubic | Method::InverseCubic => Some(Interpolation::CubicBSpline),
            Method::PushforwardNearest | Method::PushforwardAntialiased => None,
        }
    }

    fn is_inverse(self) -> bool {
        matches!(
            self,
            Method::InverseNearest | Method::InverseLinear | Method::InverseCubic
        )
    }

    /// A plain pull-back through the lattice (not through its inverse): the lattice is read
    /// as the output-to-input map, not as a deformation of the model.
    pub(crate) fn is_pullback(self) -> bool {
        matches!(
            self,
            Method::PullbackNearest | Method::PullbackLinear | Method::PullbackCubic
        )
    }
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
    /// Value of output voxels whose source lies outside the input (and, for the inverse-*
    /// methods, of voxels whose preimage was not found).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub default: f64,
    /// For the inverse-* methods: write a u8 mask on the output grid, 1 where Newton
    /// did not converge (the voxel holds --default), 2 where the preimage lies on a fold
    /// (det J <= 0), 0 elsewhere.
    #[arg(long, value_name = "PATH")]
    pub nonconverged_mask: Option<PathBuf>,
}

/// Run `volmorph warp`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    if args.nonconverged_mask.is_some() && !args.method.is_inverse() {
        bail!("--nonconverged-mask needs an inverse-* method");
    }
    let pb = progress::spinner(format!("reading {}", args.input.display()));
    let vol = format::read(&args.input).context("cannot read volume")?;
    let lattice = read_lattice(&args.lattice).context("cannot read lattice")?;
    pb.set_message("warping");
    let want_mask = args.nonconverged_mask.is_some();
    let (out, mask) = warp(&vol, &lattice, args.method, args.default, want_mask, &pb)
        .with_context(|| format!("cannot warp {}", args.input.display()))?;
    pb.set_message(format!("writing {}", args.output.display()));
    format::write(&args.output, &out).context("cannot write")?;
    if let (Some(path), Some(mask)) = (&args.nonconverged_mask, mask) {
        pb.set_message(format!("writing {}", path.display()));
        format::write(path, &mask.into()).context("cannot write the mask")?;
    }
    pb.finish_and_clear();
    Ok(())
}

/// Warp `vol` on its own grid by `method`; `default` fills output voxels nothing reaches.
/// The inverse methods warn on standard error about voxels that did not converge or landed
/// on a fold, and return the mask of them when `want_mask` is set.
pub(crate) fn warp(
    vol: &AnyVolume,
    lattice: &BSplineLattice,
    method: Method,
    default: f64,
    want_mask: bool,
    pb: &indicatif::ProgressBar,
) -> anyhow::Result<(AnyVolume, Option<Volume<u8>>)> {
    let grid = vol.geometry();
    let Some(interpolation) = method.interpolation() else {
        let out = if method == Method::PushforwardNearest {
            if default != 0.0 {
                bail!("--default is not used by pushforward-nearest (holes stay 0)");
            }
            with_volume!(vol, v => {
                AnyVolume::from(push_forward_nearest(v, lattice, grid)?.volume)
            })
        } else {
            let options = AntialiasOptions {
                background: default,
                ..AntialiasOptions::default()
            };
            with_volume!(vol, v => {
                AnyVolume::from(push_forward_antialiased(v, lattice, grid, &options)?.volume)
            })
        };
        return Ok((out, None));
    };
    if method.is_inverse() {
        let options = InverseResampleOptions::new(interpolation, default).with_mask(want_mask);
        let r = pullback_through_inverse_any(vol, lattice, grid, &options)?;
        if !r.report.is_clean() {
            pb.suspend(|| eprintln!("volmorph: warning: {}", r.report));
        }
        return Ok((r.volume, r.mask));
    }
    let options = ResampleOptions::new(interpolation, default);
    Ok((resample_any(vol, lattice, grid, &options)?, None))
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
    say!("{report}");
    Ok(())
}
