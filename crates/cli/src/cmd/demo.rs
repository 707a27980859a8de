//! `volmorph demo`: the main job on built-in data, run by [`volmorph_scene::demo::run_demo`]
//! (the teapot's spout lowered by a drag in one scene session, True 1992 Fig. 10, and the
//! model gallery); this command prints its report. `index.txt` in the folder describes every
//! file.

use std::path::PathBuf;

use anyhow::Context;
use volmorph_scene::demo::{DemoOptions, run_demo};

use super::picture;
use crate::progress;

/// Arguments of `volmorph demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder (created if missing).
    #[arg(short, long, default_value = "volmorph-demo")]
    pub out: PathBuf,
    /// Voxels per axis of the warped teapot.
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u64).range(16..=512))]
    pub size: u64,
    /// Voxels per axis of the gallery models.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u64).range(8..=512))]
    pub gallery_size: u64,
    /// Picture size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "800x600", value_parser = picture::size)]
    pub picture: (u32, u32),
}

/// Run `volmorph demo`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let options = DemoOptions {
        size: usize::try_from(args.size).context("size does not fit in memory")?,
        gallery_size: usize::try_from(args.gallery_size).context("size does not fit in memory")?,
        picture: args.picture,
    };
    let pb = progress::spinner("building the teapot");
    let report = run_demo(&args.out, &options, &progress::Bar(&pb))?;
    pb.finish_and_clear();
    say!("{}", report.teapot);
    say!("{}", report.timings);
    say!(
        "wrote the warped teapot and {} gallery files to {} (see index.txt)",
        report.gallery_files,
        args.out.display()
    );
    Ok(())
}
