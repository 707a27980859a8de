//! `volmorph isosurface`: a triangle mesh of a volume's level set, by marching cubes.

use std::path::PathBuf;

use anyhow::Context;
use volmorph_contour::{McOptions, marching_cubes_any};
use volmorph_mesh::{self as mesh, MeshWriteOptions};
use volmorph_volume::format;

use crate::progress;

/// Arguments of `volmorph isosurface`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume.
    pub input: PathBuf,
    /// Level of the surface (e.g. 127 for volmorph's u8 density models, 0 for distances).
    #[arg(long, allow_hyphen_values = true)]
    pub level: f64,
    /// Output mesh (.obj, .ply, .stl, .off); vertices in physical coordinates.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The object is where values are at or below the level (signed distances, negative
    /// inside); by default it is where they are at or above it (densities, CT).
    #[arg(long)]
    pub inside_below: bool,
    /// Write ASCII STL/PLY instead of binary.
    #[arg(long)]
    pub ascii: bool,
}

/// Run `volmorph isosurface`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let pb = progress::spinner(format!("reading {}", args.input.display()));
    let vol = format::read(&args.input).context("cannot read volume")?;
    pb.set_message("marching cubes");
    let options = McOptions {
        inside_below: args.inside_below,
    };
    let surface = marching_cubes_any(&vol, args.level, &options)
        .with_context(|| format!("cannot extract the surface of {}", args.input.display()))?;
    pb.set_message(format!("writing {}", args.output.display()));
    let opts = MeshWriteOptions {
        binary: !args.ascii,
        ..MeshWriteOptions::default()
    };
    mesh::write_with(&args.output, &surface.mesh, &opts).context("cannot write")?;
    pb.finish_and_clear();
    let report = surface.mesh.validate();
    println!(
        "{} vertices, {} triangles{}",
        surface.mesh.vertex_count(),
        surface.mesh.face_count(),
        if report.is_closed_manifold() {
            format!(
                ", closed manifold, Euler characteristic {}",
                report.euler_characteristic
            )
        } else {
            String::from(", open surface (it reaches the volume's border)")
        }
    );
    Ok(())
}
