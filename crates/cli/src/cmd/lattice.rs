//! `volmorph lattice …`: B-spline lattices (space maps) as files.

use std::path::PathBuf;

use anyhow::{Context, bail};
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::formats::{read_lattice, write_lattice};
use volmorph_volume_io as format;

use crate::args;

/// Lattice subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Write an identity lattice: the uniform cubic B-spline lattice around a volume (True
    /// 1992 Fig. 8), or with --mesh Feng et al.'s initial B-spline volume of any degree around
    /// a mesh's bounding box (identity Jacobian, parameters equal coordinates).
    #[command(
        after_help = "Examples:\n  volmorph lattice init teapot.nii.gz --counts 9,9,9 -o lattice.json\n  volmorph lattice init --mesh bunny.obj --degree 2,2,2 --size 6,8,6 -o bunny_lattice.json"
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
    #[arg(required_unless_present = "mesh", conflicts_with = "mesh")]
    pub input: Option<PathBuf>,
    /// Control points per axis "NX,NY,NZ" of the volume lattice (each at least 4).
    #[arg(long, default_value = "9,9,9")]
    pub counts: String,
    /// Mesh whose axis-aligned bounding box the lattice covers (Feng et al. 2002 §3.1); an
    /// axis along which the mesh is flat is padded by 1e-3 of the largest extent.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Degrees "KU,KV,KW" of the mesh lattice (each at least 1).
    #[arg(long, default_value = "2,2,2", requires = "mesh")]
    pub degree: String,
    /// Control points per axis "NU,NV,NW" of the mesh lattice (each at least degree + 1).
    #[arg(long, default_value = "4,4,4", requires = "mesh")]
    pub size: String,
    /// Form of the mesh lattice: the end-interpolating volume (§3.1.3, knots clamped by knot
    /// insertion) or the uniform volume it comes from (§3.1.2).
    #[arg(long, value_enum, default_value_t = Form::EndInterpolating, requires = "mesh")]
    pub form: Form,
    /// Output lattice file: .json (volmorph), .tfm (ITK BSplineTransform) or .bxf
    /// (plastimatch).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Form of Feng et al.'s initial volume.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Form {
    /// Clamped knots, outermost control points on the box faces (§3.1.3).
    EndInterpolating,
    /// Uniform unclamped knots with the scaling step (§3.1.2).
    Uniform,
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
    if let Some(m) = &a.mesh {
        return init_mesh(a, m);
    }
    let Some(input) = &a.input else {
        bail!("give a volume or --mesh MESH");
    };
    let vol = format::read(input).context("cannot read volume")?;
    let counts = args::triple::<usize>(&a.counts)?;
    let lattice = lattice_around(vol.geometry(), counts)?;
    write_lattice(&a.output, &lattice).context("cannot write")?;
    say!(
        "identity lattice of {}x{}x{} control points around {}",
        counts[0],
        counts[1],
        counts[2],
        input.display()
    );
    Ok(())
}

fn init_mesh(a: &InitArgs, path: &std::path::Path) -> anyhow::Result<()> {
    let m = volmorph_mesh::read(path)
        .with_context(|| format!("cannot read mesh {}", path.display()))?;
    let degrees = args::triple::<usize>(&a.degree).context("--degree")?;
    let counts = args::triple::<usize>(&a.size).context("--size")?;
    let (mut lo, mut hi) = m
        .bounding_box()
        .with_context(|| format!("{} has no vertices", path.display()))?;
    if !(lo.is_finite() && hi.is_finite()) {
        bail!("{} has non-finite vertex coordinates", path.display());
    }
    let ext = hi - lo;
    let pad = 1e-3 * ext.max_element();
    let pad = if pad > 0.0 { pad } else { 1.0 };
    for ax in 0..3 {
        if ext[ax] <= 0.0 {
            lo[ax] -= 0.5 * pad;
            hi[ax] += 0.5 * pad;
        }
    }
    let lattice = match a.form {
        Form::EndInterpolating => {
            BSplineLattice::feng_end_interpolating_around(lo, hi, degrees, counts)?
        }
        Form::Uniform => BSplineLattice::feng_uniform_around(lo, hi, degrees, counts)?,
    };
    write_lattice(&a.output, &lattice).context("cannot write")?;
    say!(
        "identity lattice of degree {}x{}x{} with {}x{}x{} control points around {}",
        degrees[0],
        degrees[1],
        degrees[2],
        counts[0],
        counts[1],
        counts[2],
        path.display()
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
