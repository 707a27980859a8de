//! `volmorph lattice …`: B-spline lattices (space maps) as files.

use std::path::PathBuf;

use anyhow::{Context, bail};
use volmorph_deform::BSplineLattice;
use volmorph_deform::formats::{read_lattice, write_lattice};
use volmorph_volume::format;

use crate::args;

/// Lattice subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Write the identity uniform cubic B-spline lattice around a volume (True 1992 Fig. 8).
    #[command(
        after_help = "Example:\n  volmorph lattice init teapot.nii.gz --counts 9,9,9 -o lattice.json"
    )]
    Init(InitArgs),
    /// Convert a lattice file between formats (.json, .tfm, .bxf), e.g. to hand a lattice
    /// edited as JSON to ITK or plastimatch.
    #[command(after_help = "Example:\n  volmorph lattice convert moved.json -o moved.tfm")]
    Convert(ConvertArgs),
}

/// Arguments of `volmorph lattice convert`.
#[derive(Debug, clap::Args)]
pub struct ConvertArgs {
    /// Input lattice file (.json, .tfm, .bxf).
    pub input: PathBuf,
    /// Output lattice file; the format follows the extension (.json, .tfm, .bxf).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Arguments of `volmorph lattice init`.
#[derive(Debug, clap::Args)]
pub struct InitArgs {
    /// Volume whose voxel-centre box (in its own index frame) the lattice covers.
    pub input: PathBuf,
    /// Control points per axis "NX,NY,NZ" (each at least 4).
    #[arg(long, default_value = "9,9,9")]
    pub counts: String,
    /// Output lattice file: .json (volmorph), .tfm (ITK BSplineTransform) or .bxf
    /// (plastimatch).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Run a lattice subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Init(a) => init(a),
        Command::Convert(a) => convert(a),
    }
}

fn convert(a: &ConvertArgs) -> anyhow::Result<()> {
    let lattice = read_lattice(&a.input)
        .with_context(|| format!("cannot read lattice {}", a.input.display()))?;
    write_lattice(&a.output, &lattice).context("cannot write")?;
    let [cx, cy, cz] = lattice.counts();
    println!(
        "lattice of {cx}x{cy}x{cz} control points written to {}",
        a.output.display()
    );
    Ok(())
}

fn init(a: &InitArgs) -> anyhow::Result<()> {
    let vol = format::read(&a.input).context("cannot read volume")?;
    let counts = args::triple::<usize>(&a.counts)?;
    let lattice = lattice_around(vol.geometry(), counts)?;
    write_lattice(&a.output, &lattice).context("cannot write")?;
    say!(
        "identity lattice of {}x{}x{} control points around {}",
        counts[0],
        counts[1],
        counts[2],
        a.input.display()
    );
    Ok(())
}

/// The identity uniform cubic lattice on the voxel-centre box of `g`, in the volume's own
/// (orthonormal) direction frame.
///
/// # Errors
/// When the volume's direction is not orthonormal or the counts are below 4.
pub fn lattice_around(
    g: &volmorph_volume::Geometry,
    counts: [usize; 3],
) -> anyhow::Result<BSplineLattice> {
    let extent = g.spacing
        * volmorph_volume::DVec3::new(
            g.dims[0].saturating_sub(1) as f64,
            g.dims[1].saturating_sub(1) as f64,
            g.dims[2].saturating_sub(1) as f64,
        );
    if extent.min_element() <= 0.0 {
        bail!("a lattice needs a volume at least 2 voxels thick on every axis");
    }
    Ok(BSplineLattice::uniform_cubic_in_box(
        g.origin,
        g.direction,
        extent,
        counts,
    )?)
}
