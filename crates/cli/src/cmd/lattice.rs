//! `volmorph lattice …`: B-spline lattices (space maps) as files.

use std::path::PathBuf;

use anyhow::{Context, bail};
use glam::{DMat3, DVec3};
use volmorph_lattice::formats::{check_output, read_lattice, write_lattice};
use volmorph_lattice::{BSplineLattice, FengForm};
use volmorph_volume_io as format;

use crate::args;

/// Lattice subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Write an identity lattice: the uniform cubic B-spline lattice around a volume (True
    /// 1992 Fig. 8), on a Sederberg–Parry parallelepiped given by --corner and three --edge
    /// vectors at any non-degenerate angles (a skewed lattice, True §2.1), or with --mesh Feng
    /// et al.'s initial B-spline volume of any degree around a mesh's bounding box (identity
    /// Jacobian, parameters equal coordinates).
    #[command(
        after_help = "Examples:\n  volmorph lattice init teapot.nii.gz --counts 9,9,9 -o lattice.json\n  volmorph lattice init --corner 0,0,0 --edge 64,0,0 --edge 20,60,0 --edge 0,-10,64 --counts 7,7,7 -o skewed.json\n  volmorph lattice init --mesh bunny.obj --degree 2,2,2 --size 6,8,6 -o bunny_lattice.json\n  volmorph lattice init --mesh part.obj --degree 2,2,1 --size 4,4,2 --form forward -o fig2b.json"
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
    #[arg(required_unless_present_any = ["mesh", "corner"], conflicts_with_all = ["mesh", "corner"])]
    pub input: Option<PathBuf>,
    /// Corner "x,y,z" of a parallelepiped lattice box (with three --edge vectors).
    #[arg(long, requires = "edge", conflicts_with = "mesh", value_parser = args::point, allow_hyphen_values = true)]
    pub corner: Option<DVec3>,
    /// An edge vector "x,y,z" of the parallelepiped leaving --corner, once per lattice axis u,
    /// v, w (three times; any lengths, any non-degenerate angles: a skewed lattice).
    #[arg(long, requires = "corner", value_parser = args::point, allow_hyphen_values = true)]
    pub edge: Vec<DVec3>,
    /// Control points per axis "NX,NY,NZ" of the volume or parallelepiped lattice (each at
    /// least 4).
    #[arg(long, default_value = "9,9,9", value_parser = args::triple::<usize>)]
    pub counts: [usize; 3],
    /// Mesh whose axis-aligned bounding box the lattice covers (Feng et al. 2002 §3.1); an
    /// axis along which the mesh is flat is padded by 1e-3 of the largest extent.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Degrees "KU,KV,KW" of the mesh lattice (each at least 1).
    #[arg(long, default_value = "2,2,2", requires = "mesh", value_parser = args::triple::<usize>)]
    pub degree: [usize; 3],
    /// Control points per axis "NU,NV,NW" of the mesh lattice (each at least degree + 1).
    #[arg(long, default_value = "4,4,4", requires = "mesh", value_parser = args::triple::<usize>)]
    pub size: [usize; 3],
    /// Form of the mesh lattice: the end-interpolating volume (§3.1.3, knots clamped by knot
    /// insertion), the uniform volume it comes from (§3.1.2) — both the identity, Jacobian I
    /// — or `forward`: the forward-mapping baseline of Fig. 2b (§3.1.1), end-interpolating
    /// knots with evenly spaced control points, which warps the mesh before any control
    /// point moves.
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
    /// Clamped knots, evenly spaced control points: the forward mapping of Fig. 2b (§3.1.1),
    /// not the identity.
    Forward,
}

impl From<Form> for FengForm {
    fn from(f: Form) -> Self {
        match f {
            Form::EndInterpolating => FengForm::EndInterpolating,
            Form::Uniform => FengForm::Uniform,
            Form::Forward => FengForm::Forward,
        }
    }
}

/// Run a lattice subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Init(a) => init(a),
        Command::Convert(a) => convert(a),
    }
}

fn convert(a: &ConvertArgs) -> anyhow::Result<()> {
    check_output(&a.output)?;
    let lattice = read_lattice(&a.input).context("cannot read the lattice")?;
    write_lattice(&a.output, &lattice).context("cannot write")?;
    let [cx, cy, cz] = lattice.counts();
    say!(
        "lattice of {cx}x{cy}x{cz} control points written to {}",
        a.output.display()
    );
    Ok(())
}

fn init(a: &InitArgs) -> anyhow::Result<()> {
    check_output(&a.output)?;
    let (lattice, what) = if let Some(path) = &a.mesh {
        let m = volmorph_mesh::read(path).context("cannot read the mesh")?;
        let (lo, hi) = m
            .bounding_box()
            .with_context(|| format!("{} has no vertices", path.display()))?;
        let form = FengForm::from(a.form);
        let l = BSplineLattice::feng_around_model(lo, hi, a.degree, a.size, form)
            .with_context(|| format!("cannot place a lattice around {}", path.display()))?;
        let [dx, dy, dz] = a.degree;
        let what = if form.is_identity() {
            "identity"
        } else {
            "forward-mapped (not the identity: it warps the mesh, Feng Fig. 2b)"
        };
        (
            l,
            format!(
                "{what} {} volume of degree {dx}x{dy}x{dz} around {}",
                form.name(),
                path.display()
            ),
        )
    } else if let Some(corner) = a.corner {
        let [s, t, u] = a.edge[..] else {
            bail!("give three --edge vectors (u, v, w), got {}", a.edge.len());
        };
        let l = BSplineLattice::uniform_cubic_in_parallelepiped(
            corner,
            DMat3::from_cols(s, t, u),
            a.counts,
        )
        .context("cannot place a lattice on the parallelepiped")?;
        let kind = if l.frame().is_skewed() {
            "skewed"
        } else {
            "rectangular"
        };
        (
            l,
            format!(
                "identity lattice on the {kind} parallelepiped at {}",
                volmorph_io::Nums(&corner.to_array())
            ),
        )
    } else {
        let Some(input) = &a.input else {
            bail!("give a volume or --mesh MESH");
        };
        let pb = crate::progress::spinner(format!("reading {}", input.display()));
        let vol = format::read(input).context("cannot read the volume")?;
        pb.finish_and_clear();
        let l = BSplineLattice::identity_on_voxels(vol.geometry(), a.counts)
            .with_context(|| format!("cannot place a lattice around {}", input.display()))?;
        (l, format!("identity lattice around {}", input.display()))
    };
    write_lattice(&a.output, &lattice).context("cannot write")?;
    let [cx, cy, cz] = lattice.counts();
    say!("{what} with {cx}x{cy}x{cz} control points");
    Ok(())
}
