//! `volmorph mls2d`: a picture deformed by 2-D handles (McPhail ch. 4: moving least squares
//! with point and segment handles, and the thin-plate comparison of Fig. 4.2), through
//! `volmorph_handles::mls2d`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use volmorph_handles::handles::HandleSet;
use volmorph_handles::mls2d::{Mls2dKind, warp_picture_tps_with, warp_picture_with};
use volmorph_render::{RgbaImage, read_png, write_png_rgba};

use crate::cmd::handles::Kernel;
use crate::progress;

/// Arguments of `volmorph mls2d`.
#[derive(Debug, clap::Args)]
pub struct Mls2dArgs {
    /// Input picture (.png).
    pub input: PathBuf,
    /// Handle JSON with 2D pixel coordinates ("points" and/or "segments").
    #[arg(long)]
    pub handles: PathBuf,
    /// Transformation class of the fit.
    #[arg(long, value_enum, default_value_t = Kind2d::Rigid)]
    pub method: Kind2d,
    /// Weight exponent alpha (an integer 1..8 with segment handles).
    #[arg(long, default_value_t = 1.0)]
    pub alpha: f64,
    /// Vertices per axis of the deformed grid whose quads are filled bilinearly.
    #[arg(long, default_value_t = 100)]
    pub grid: usize,
    /// Kernel of the 2-D thin-plate spline (tps): only r2logr, r² log r, the biharmonic
    /// kernel in 2-D (r is the 3-D one and is refused here).
    #[arg(long, value_enum, default_value_t = Kernel::R2logr)]
    pub kernel: Kernel,
    /// Output picture (.png), same size as the input; uncovered pixels are transparent.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Transformation class of `volmorph mls2d`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Kind2d {
    /// Affine (may shear and stretch).
    Affine,
    /// Similarity (rotation and uniform scale).
    Similarity,
    /// Rigid (as rigid as possible).
    Rigid,
    /// Thin-plate spline (r² log r plus an affine part; interpolates every handle; McPhail
    /// Fig. 4.2's comparison). Segment handles count by their end points.
    Tps,
}

/// Run `volmorph mls2d`.
pub fn run_mls2d(a: &Mls2dArgs) -> anyhow::Result<()> {
    volmorph_render::check_png(&a.output)?;
    if a.kernel == Kernel::R {
        bail!(
            "--kernel r: in 2-D the thin-plate (biharmonic) kernel is r² log r (r2logr); r is \
             the 3-D biharmonic kernel"
        );
    }
    let set = HandleSet::read(&a.handles)
        .with_context(|| format!("cannot read the handles {}", a.handles.display()))?;
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    let img = read_png(&a.input).context("cannot read the picture")?;
    let (w, h) = (img.width(), img.height());
    let kind = match a.method {
        Kind2d::Affine => Some(Mls2dKind::Affine),
        Kind2d::Similarity => Some(Mls2dKind::Similarity),
        Kind2d::Rigid => Some(Mls2dKind::Rigid),
        Kind2d::Tps => None,
    };
    let bar = progress::Bar(&pb);
    let out = match kind {
        Some(kind) => warp_picture_with(w, h, img.pixels(), &set, kind, a.alpha, a.grid, &bar),
        None => warp_picture_tps_with(w, h, img.pixels(), &set, a.grid, &bar),
    }
    .context("cannot deform the picture")?;
    progress::spin(&pb, format!("writing {}", a.output.display()));
    write_png_rgba(&a.output, &RgbaImage::from_pixels(w, h, out.pixels)?)
        .context("cannot write the picture")?;
    pb.finish_and_clear();
    say!(
        "deformed {w}×{h} picture by {} handles on a {}×{} grid; {:.3}% of the grid folds \
         (Jacobian <= 0)",
        set.len(),
        out.grid.0,
        out.grid.1,
        100.0 * out.fold_fraction
    );
    Ok(())
}
