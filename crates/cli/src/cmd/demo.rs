//! `volmorph demo`: the main job on built-in data.
//!
//! Writes every built-in model as a u8 density volume (object at isovalue 127) and an f32
//! signed-distance volume (NIfTI, `.nii.gz`), plus PNG pictures of the three middle slices,
//! into one folder, with an `index.txt` describing the files.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use volmorph_render::{Colormap, Window};
use volmorph_volume::AnyVolume;
use volmorph_volume::format;
use volmorph_volume::phantom::Phantom;
use volmorph_volume::slice::{self, Axis, SlicePosition};

use super::phantom::{Kind, make};
use super::slice::{middle, write_picture};
use crate::progress;

/// Arguments of `volmorph demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder (created if missing).
    #[arg(short, long, default_value = "volmorph-demo")]
    pub out: PathBuf,
    /// Voxels per axis of every model.
    #[arg(long, default_value_t = 96, value_parser = clap::value_parser!(u64).range(8..=1024))]
    pub size: u64,
}

const AXES: [(Axis, &str); 3] = [(Axis::X, "x"), (Axis::Y, "y"), (Axis::Z, "z")];

/// Run `volmorph demo`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create folder {}", args.out.display()))?;
    let n = usize::try_from(args.size).context("size does not fit in memory")?;
    let dims = [n; 3];
    let models = Phantom::ALL;
    let pb = progress::bar(models.len() as u64 * 2);
    let mut index = String::new();
    let _ = writeln!(
        index,
        "volmorph demo: built-in models at {n}^3 voxels over the model frame [-1.1, 1.1]^3\n"
    );
    for model in models {
        for kind in [Kind::Density, Kind::Sdf] {
            let suffix = if kind == Kind::Sdf { "_sdf" } else { "" };
            let stem = format!("{}{suffix}", model.name());
            pb.set_message(stem.clone());
            let vol = make(model, dims, kind)?;
            let path = args.out.join(format!("{stem}.nii.gz"));
            format::write(&path, &vol).context("cannot write")?;
            let _ = writeln!(
                index,
                "{stem}.nii.gz  {}",
                match kind {
                    Kind::Density => format!(
                        "{}: u8 density, object where value >= 127",
                        model.description()
                    ),
                    Kind::Sdf => "f32 signed distance, negative inside".to_string(),
                }
            );
            for (axis, name) in AXES {
                let png = args.out.join(format!("{stem}_{name}.png"));
                write_slice_png(&vol, axis, kind, &png)?;
                let _ = writeln!(index, "{stem}_{name}.png  middle slice across {name}");
            }
            pb.inc(1);
        }
    }
    let idx = args.out.join("index.txt");
    volmorph_io::write_atomic::<anyhow::Error, _>(&idx, |w| {
        use std::io::Write;
        w.write_all(index.as_bytes())?;
        Ok(())
    })?;
    pb.finish_and_clear();
    println!(
        "wrote {} models ({} files) to {}",
        models.len(),
        models.len() * 8 + 1,
        args.out.display()
    );
    Ok(())
}

fn write_slice_png(
    vol: &AnyVolume,
    axis: Axis,
    kind: Kind,
    png: &std::path::Path,
) -> anyhow::Result<()> {
    let s = slice::extract(vol, axis, SlicePosition::Index(middle(vol, axis)))?;
    match kind {
        Kind::Density => write_picture(png, &s, None, Colormap::Grey),
        // Distances in model units: ±0.3 around the surface, blue inside, red outside.
        Kind::Sdf => write_picture(png, &s, Some(Window::new(0.0, 0.6)?), Colormap::CoolWarm),
    }
}
