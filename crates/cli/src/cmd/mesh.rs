//! `volmorph mesh …`: polygon mesh tasks.

use std::path::PathBuf;

use anyhow::Context;
use volmorph_mesh::{self as mesh, MeshWriteOptions};

use volmorph_render::UpAxis;

use super::picture;
use crate::progress;

/// Mesh subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Print counts, bounding box and a validation report of a mesh file.
    #[command(after_help = "Example:\n  volmorph mesh info bunny.obj")]
    Info(InfoArgs),
    /// Convert a mesh between OBJ, STL, PLY and OFF (format by extension).
    #[command(
        after_help = "Examples:\n  volmorph mesh convert dragon.ply.gz dragon.stl\n  volmorph mesh convert part.stl part.ply --ascii"
    )]
    Convert(ConvertArgs),
    /// Write a shaded PNG picture of a mesh, in the colours it stores (PLY, OBJ) if any.
    #[command(
        after_help = "Examples:\n  volmorph mesh render teapot.ply -o teapot.png --view iso\n  volmorph mesh render bunny.obj -o bunny.png --size 1024x768 --view 30,20 --up y\n\nViews: AZIMUTH,ELEVATION in degrees about the up axis (z up: azimuth 0 looks from +x, 90\nfrom +y; y up: 0 from +z, 90 from +x), or front, side, top, iso."
    )]
    Render(RenderArgs),
}

/// Arguments of `volmorph mesh render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Input mesh.
    pub input: PathBuf,
    /// Output picture (.png).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Viewing direction: AZIMUTH,ELEVATION in degrees, or front, side, top, iso.
    #[arg(long, default_value = "iso", allow_hyphen_values = true)]
    pub view: String,
    /// The axis that is up in the picture: z (CAD, volmorph's models) or y (most modelling
    /// tools).
    #[arg(long, default_value = "z", value_parser = crate::args::up_axis)]
    pub up: UpAxis,
    /// Picture size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "800x600", value_parser = picture::size)]
    pub size: (u32, u32),
    /// Draw in the default clay colour even when the file stores colours (PLY red green blue
    /// per vertex or face, OBJ `v x y z r g b`), which are drawn otherwise.
    #[arg(long)]
    pub no_colors: bool,
}

/// Arguments of `volmorph mesh info`.
#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// Mesh file (.obj, .stl, .ply, .off, optionally .gz-compressed).
    pub input: PathBuf,
}

/// Arguments of `volmorph mesh convert`.
#[derive(Debug, clap::Args)]
pub struct ConvertArgs {
    /// Input mesh.
    pub input: PathBuf,
    /// Output mesh; the format is chosen by extension.
    pub output: PathBuf,
    /// Write ASCII STL/PLY instead of binary.
    #[arg(long)]
    pub ascii: bool,
}

/// Run a mesh subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Info(a) => info(a),
        Command::Convert(a) => convert(a),
        Command::Render(a) => render(a),
    }
}

fn info(a: &InfoArgs) -> anyhow::Result<()> {
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    let m = mesh::read(&a.input).context("cannot read mesh")?;
    let report = m.validate();
    pb.finish_and_clear();
    say!("file:     {}", a.input.display());
    say!("vertices: {}", m.vertex_count());
    say!("faces:    {}", m.face_count());
    match m.bounding_box() {
        Some((lo, hi)) => say!(
            "bounds:   ({}, {}, {}) .. ({}, {}, {})",
            lo.x,
            lo.y,
            lo.z,
            hi.x,
            hi.y,
            hi.z
        ),
        None => say!("bounds:   (empty)"),
    }
    say!("{report}");
    Ok(())
}

fn convert(a: &ConvertArgs) -> anyhow::Result<()> {
    mesh::format::check_output(&a.output)?;
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    let m = mesh::read(&a.input).context("cannot read mesh")?;
    pb.set_message(format!("writing {}", a.output.display()));
    let opts = MeshWriteOptions {
        binary: !a.ascii,
        ..MeshWriteOptions::default()
    };
    mesh::write_with(&a.output, &m, &opts).context("cannot write")?;
    pb.finish_and_clear();
    Ok(())
}

fn render(a: &RenderArgs) -> anyhow::Result<()> {
    volmorph_render::check_png(&a.output)?;
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    let (m, colors) = mesh::read_with_colors(&a.input).context("cannot read mesh")?;
    pb.set_message("drawing");
    let what = a.input.display().to_string();
    let orbit = crate::args::view(&a.view, a.up).context("--view")?;
    let bounds = m
        .bounding_box()
        .with_context(|| format!("{what} has no vertices to draw"))?;
    let cam = orbit.mesh_camera(bounds, a.size)?;
    let colors = if a.no_colors { None } else { colors };
    volmorph_render::write_mesh_png(&a.output, &m, None, colors.as_ref(), &cam)
        .with_context(|| format!("cannot draw {what}"))?;
    pb.finish_and_clear();
    Ok(())
}
