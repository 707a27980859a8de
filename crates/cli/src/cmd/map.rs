//! `volmorph map …`: inspect, combine and apply map files of any kind.

use std::path::PathBuf;

use anyhow::Context;
use volmorph_deform::{InverseOptions, SpaceMap};
use volmorph_handles::handles::{read_point_list, write_point_list};
use volmorph_maps::{AnyMap, read_map, write_map};

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
}

/// Arguments of `volmorph map apply`.
#[derive(Debug, clap::Args)]
pub struct ApplyArgs {
    /// The map (.json, .tfm, .bxf).
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
    /// The map (.json, .tfm, .bxf).
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
    /// The composition (.json, or .tfm when every part is affine or a cubic B-spline).
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

/// Run a map subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Apply(a) => {
            let map = read_map(&a.map).context("cannot read the map")?;
            let pts = read_point_list(&a.points)
                .with_context(|| format!("cannot read the points {}", a.points.display()))?;
            let mut out = vec![glam::DVec3::ZERO; pts.len()];
            map.apply_batch(&pts, &mut out)?;
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
            let mut map = AnyMap::Identity;
            for path in &a.maps {
                map = map.then(read_map(path).context("cannot read a map")?);
            }
            write_map(&a.output, &map).context("cannot write")?;
            say!("{}", map.summary());
        }
        Command::Invert(a) => {
            let map = read_map(&a.map).context("cannot read the map")?;
            let options = InverseOptions {
                tolerance: a.tolerance,
                ..InverseOptions::default()
            };
            let inv = map.inverse(options).context("cannot invert the map")?;
            write_map(&a.output, &inv).context("cannot write")?;
            say!("{}", inv.summary());
        }
    }
    Ok(())
}
