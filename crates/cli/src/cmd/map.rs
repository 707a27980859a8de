//! `volmorph map …`: inspect, combine and apply map files of any kind.

use std::path::PathBuf;

use anyhow::Context;
use volmorph_deform::{InverseOptions, SpaceMap};
use volmorph_handles::handles::{check_point_list_output, read_point_list, write_point_list};
use volmorph_maps::file::{check_field_output, check_output};
use volmorph_maps::{AnyMap, read_map, write_field, write_map};
use volmorph_volume_io::vector::VectorPrecision;
use volmorph_warp::output::parse_geometry;

use crate::progress;

/// Map subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Map a list of points (Slicer .fcsv, .csv or 3-column text) through a map, forward
    /// (each point p goes to map(p)); the output has the format of its extension.
    #[command(
        after_help = "Examples:\n  volmorph map apply moved.json landmarks.fcsv -o moved_landmarks.fcsv\n  volmorph map apply registration.tfm points.txt -o mapped.csv"
    )]
    Apply(ApplyArgs),
    /// Describe a map file: kind, size, and the map at a few points of its region.
    #[command(after_help = "Example:\n  volmorph map info lattice.json")]
    Info(InfoArgs),
    /// Compose maps: the first given is applied first (x ↦ last(…(first(x)))).
    #[command(
        after_help = "Example:\n  volmorph map compose prealign.tfm lattice.json -o combined.json\n  (ITK .tfm output holds affine and B-spline components as a CompositeTransform)"
    )]
    Compose(ComposeArgs),
    /// Write the inverse of a map: exact for affine maps and compositions of them, a numerical
    /// inverse (Newton iteration at every point it is applied to) otherwise.
    #[command(after_help = "Example:\n  volmorph map invert lattice.json -o inverse.json")]
    Invert(InvertArgs),
    /// Write a map as a dense displacement field on a reference grid, the ITK vector image
    /// ITK's DisplacementFieldTransform, ANTs and elastix read: d(x) = map(x) − x at every
    /// voxel of the grid, in physical (LPS) units, so T(x) = x + d(x). The map is taken in
    /// ITK's sense of a transform: it sends points of the fixed (output) grid to points of the
    /// moving (input) image (the pull-back of `warp --method pullback-*`).
    #[command(
        after_help = "Examples:\n  volmorph map field lattice.json --reference ct.nii.gz -o field.nii.gz\n  volmorph map field registration.tfm --output-geometry \"64,64,48;2,2,2;-64,-64,-48\" -o field.mha --precision f32"
    )]
    Field(FieldArgs),
}

/// Arguments of `volmorph map field`.
#[derive(Debug, clap::Args)]
pub struct FieldArgs {
    /// The map (any map file).
    pub map: PathBuf,
    /// The grid of this reference volume (dims, spacing, origin, direction).
    #[arg(
        long,
        value_name = "VOLUME",
        required_unless_present = "output_geometry"
    )]
    pub reference: Option<PathBuf>,
    /// The grid NX,NY,NZ;SX,SY,SZ;OX,OY,OZ[;D00,D01,…,D22] (as `warp --output-geometry`).
    #[arg(long, value_name = "GEOMETRY", conflicts_with = "reference",
          value_parser = boxed_geometry, allow_hyphen_values = true)]
    pub output_geometry: Option<Box<volmorph_volume::Geometry>>,
    /// The field (.nii, .nii.gz: NIfTI vector image, intent 1007; .mha, .mhd: MetaImage with
    /// 3 channels).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Precision of the values written: f64 (ITK's DisplacementFieldTransform type) or f32
    /// (half the size, as ANTs writes).
    #[arg(long, default_value = "f64", value_parser = ["f64", "f32"])]
    pub precision: String,
}

/// Arguments of `volmorph map apply`.
#[derive(Debug, clap::Args)]
pub struct ApplyArgs {
    /// The map (.json, .tfm, .txt, .mat, .bxf, or a displacement field .nii.gz/.mha).
    pub map: PathBuf,
    /// The points (.fcsv, .csv, .txt).
    pub points: PathBuf,
    /// Where to write the mapped points (.fcsv, .csv, .txt).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Arguments of `volmorph map info`.
#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// The map (.json, .tfm, .txt, .mat, .bxf, or a displacement field .nii.gz/.mha).
    pub map: PathBuf,
    /// Print the map as volmorph map JSON too.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `volmorph map compose`.
#[derive(Debug, clap::Args)]
pub struct ComposeArgs {
    /// The maps, in the order they apply.
    #[arg(required = true, num_args = 2..)]
    pub maps: Vec<PathBuf>,
    /// The composition (.json, or .tfm when every part is affine, a cubic B-spline or an
    /// interpolating thin-plate spline).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Arguments of `volmorph map invert`.
#[derive(Debug, clap::Args)]
pub struct InvertArgs {
    /// The map.
    pub map: PathBuf,
    /// The inverse (.json; .tfm for affine maps).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Newton tolerance of a numerical inverse (physical units; default relative 1e-12).
    #[arg(long)]
    pub tolerance: Option<f64>,
}

/// [`parse_geometry`], boxed (keeps the argument structs small).
fn boxed_geometry(s: &str) -> anyhow::Result<Box<volmorph_volume::Geometry>> {
    Ok(Box::new(parse_geometry(s)?))
}

/// Run a map subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Apply(a) => {
            check_point_list_output(&a.output)?;
            let pb = progress::spinner(format!("reading {}", a.map.display()));
            let map = read_map(&a.map).context("cannot read the map")?;
            let pts = read_point_list(&a.points)
                .with_context(|| format!("cannot read the points {}", a.points.display()))?;
            progress::spin(&pb, format!("mapping {} points", pts.len()));
            let mut out = vec![glam::DVec3::ZERO; pts.len()];
            map.apply_batch(&pts, &mut out)?;
            pb.finish_and_clear();
            if let Some(i) = out.iter().position(|p| !p.is_finite()) {
                anyhow::bail!(
                    "point {} ({}) has no image under the map (a numerical inverse found no \
                     preimage)",
                    i + 1,
                    pts[i]
                );
            }
            write_point_list(&a.output, &out)
                .with_context(|| format!("cannot write {}", a.output.display()))?;
            say!("mapped {} points by {}", out.len(), map.summary());
        }
        Command::Info(a) => {
            let map = read_map(&a.map).context("cannot read the map")?;
            say!("{}: {}", a.map.display(), map.summary());
            if a.json {
                say!("{}", map.to_json()?);
            }
        }
        Command::Compose(a) => {
            check_output(&a.output)?;
            let pb = progress::spinner("reading the maps");
            let mut map = AnyMap::Identity;
            for path in &a.maps {
                progress::spin(&pb, format!("reading {}", path.display()));
                map = map.then(read_map(path).context("cannot read a map")?);
            }
            progress::spin(&pb, format!("writing {}", a.output.display()));
            write_map(&a.output, &map).context("cannot write")?;
            pb.finish_and_clear();
            say!("{}", map.summary());
        }
        Command::Invert(a) => {
            check_output(&a.output)?;
            let pb = progress::spinner(format!("reading {}", a.map.display()));
            let map = read_map(&a.map).context("cannot read the map")?;
            let options = InverseOptions {
                tolerance: a.tolerance,
                ..InverseOptions::default()
            };
            let inv = map.inverse(options).context("cannot invert the map")?;
            progress::spin(&pb, format!("writing {}", a.output.display()));
            write_map(&a.output, &inv).context("cannot write")?;
            pb.finish_and_clear();
            say!("{}", inv.summary());
        }
        Command::Field(a) => {
            check_field_output(&a.output)?;
            let pb = progress::spinner(format!("reading {}", a.map.display()));
            let map = read_map(&a.map).context("cannot read the map")?;
            let grid = match (&a.reference, &a.output_geometry) {
                (_, Some(g)) => **g,
                (Some(path), None) => *volmorph_volume_io::read(path)
                    .with_context(|| {
                        format!("cannot read the reference volume {}", path.display())
                    })?
                    .geometry(),
                (None, None) => anyhow::bail!("give --reference VOLUME or --output-geometry"),
            };
            let precision = if a.precision == "f32" {
                VectorPrecision::F32
            } else {
                VectorPrecision::F64
            };
            let [nx, ny, nz] = grid.dims;
            progress::spin(
                &pb,
                format!(
                    "sampling the map on {nx}x{ny}x{nz} nodes and writing {}",
                    a.output.display()
                ),
            );
            let field = write_field(&a.output, &map, grid, precision).context("cannot write")?;
            pb.finish_and_clear();
            say!(
                "{}: {}",
                a.output.display(),
                AnyMap::DisplacementField(field).summary()
            );
        }
    }
    Ok(())
}
