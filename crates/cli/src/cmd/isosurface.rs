//! `volmorph isosurface`: a triangle mesh of a volume's level set, by marching cubes or dual
//! contouring.

use std::path::PathBuf;

use anyhow::Context;
use volmorph_contour::{DcOptions, McOptions, dual_contouring_any_with, marching_cubes_any_with};
use volmorph_mesh::{self as mesh, MeshWriteOptions};
use volmorph_volume_io as format;

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
    /// Surface extraction algorithm.
    #[arg(long, value_enum, default_value_t = Algorithm::MarchingCubes)]
    pub method: Algorithm,
}

/// Isosurface algorithms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Algorithm {
    /// Marching cubes: crack-free, closed 2-manifold on closed level sets; rounds sharp edges.
    MarchingCubes,
    /// Dual contouring with QEF vertices in feature cells: keeps sharp edges and corners; may
    /// give non-manifold edges at ambiguous cell faces.
    DualContouring,
}

/// Run `volmorph isosurface`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    mesh::format::check_output(&args.output)?;
    let pb = progress::spinner(format!("reading {}", args.input.display()));
    let vol = format::read(&args.input).context("cannot read volume")?;
    let bar = progress::Bar(&pb);
    let surface = match args.method {
        Algorithm::MarchingCubes => marching_cubes_any_with(
            &vol,
            args.level,
            &McOptions {
                inside_below: args.inside_below,
            },
            &bar,
        ),
        Algorithm::DualContouring => dual_contouring_any_with(
            &vol,
            args.level,
            &DcOptions {
                inside_below: args.inside_below,
                ..DcOptions::default()
            },
            &bar,
        ),
    }
    .with_context(|| format!("cannot extract the surface of {}", args.input.display()))?;
    progress::spin(&pb, format!("writing {}", args.output.display()));
    let opts = MeshWriteOptions {
        binary: !args.ascii,
        ..MeshWriteOptions::default()
    };
    mesh::write_with(&args.output, &surface.mesh, &opts).context("cannot write")?;
    pb.finish_and_clear();
    let report = surface.mesh.validate();
    say!(
        "{} vertices, {} triangles{}",
        surface.mesh.vertex_count(),
        surface.mesh.face_count(),
        if report.is_closed_manifold() {
            format!(
                ", closed manifold, Euler characteristic {}",
                report.euler_characteristic
            )
        } else {
            String::from(
                ", not a closed manifold (it reaches the volume's border, or has ambiguous cells)",
            )
        }
    );
    Ok(())
}
