//! `volmorph phantom`: write a built-in model as a volume file.

use std::path::PathBuf;

use anyhow::{Context, bail};
use volmorph_volume::AnyVolume;
use volmorph_volume::phantom::{self, Phantom};
use volmorph_volume_io as format;

use crate::{args, progress};

/// What a phantom volume holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Kind {
    /// u8 density, object at isovalue 127 of 255 (True 1992 §5.1).
    Density,
    /// f32 signed distance, negative inside, in model units.
    Sdf,
}

/// Arguments of `volmorph phantom`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model: sphere, torus, rounded-box, clay-block, teapot, tree.
    pub model: String,
    /// Output volume; the format is chosen by extension.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Voxels per axis (a cube).
    #[arg(long, default_value_t = 64, conflicts_with = "dims")]
    pub size: usize,
    /// Voxels per axis "NX,NY,NZ".
    #[arg(long, value_name = "NX,NY,NZ")]
    pub dims: Option<String>,
    /// Density (u8) or signed distance (f32).
    #[arg(long, value_enum, default_value_t = Kind::Density)]
    pub kind: Kind,
}

/// Run `volmorph phantom`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    format::check_output(&args.output)?;
    let model: Phantom = args.model.parse().map_err(|e| anyhow::anyhow!("{e}"))?;
    let dims = match &args.dims {
        Some(d) => args::triple(d)?,
        None => [args.size; 3],
    };
    if dims.iter().any(|&n| n > 4096) {
        bail!("dims {dims:?} are larger than 4096 per axis");
    }
    let pb = progress::bar(0);
    let vol = make(model, dims, args.kind, &progress::Bar(&pb))?;
    progress::spin(&pb, format!("writing {}", args.output.display()));
    format::write(&args.output, &vol).context("cannot write")?;
    pb.finish_and_clear();
    Ok(())
}

/// The phantom volume of the given kind, reporting one step per z-slice to `progress`.
pub fn make(
    model: Phantom,
    dims: [usize; 3],
    kind: Kind,
    progress: &dyn volmorph_io::Progress,
) -> anyhow::Result<AnyVolume> {
    Ok(match kind {
        Kind::Density => phantom::density_with(model, dims, progress)?.into(),
        Kind::Sdf => phantom::signed_distance_with(model, dims, progress)?.into(),
    })
}
