//! `volmorph slice`: a PNG picture of an axis-aligned slice, at a readable size with the
//! physical aspect ratio and orientation labels (drawn by `volmorph_render::render_slice`).

use std::path::PathBuf;

use anyhow::Context;
use volmorph_render::{
    Colormap, Interpolation, OrientationLabels, PixelAspect, SliceSize, SliceStyle, Window,
    render_slice, write_png_rgba,
};
use volmorph_volume::slice::{self, Axis, SlicePosition};
use volmorph_volume_io as format;

use crate::{args, progress};

/// Arguments of `volmorph slice`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume.
    pub input: PathBuf,
    /// Output PNG file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Slice normal: the index axis x (i), y (j) or z (k).
    #[arg(long, default_value = "z", value_parser = parse_axis)]
    pub axis: Axis,
    /// Slice at this (possibly fractional) voxel index along the axis. Default: the middle.
    #[arg(long, conflicts_with = "position")]
    pub index: Option<f64>,
    /// Slice at this physical position (mm along the axis direction from the origin).
    #[arg(long, allow_hyphen_values = true)]
    pub position: Option<f64>,
    /// Window "CENTER,WIDTH" (e.g. 40,400 for CT soft tissue; width 0 thresholds at CENTER).
    /// Default: the 0.5-99.5 percentile range of the slice.
    #[arg(long, value_name = "CENTER,WIDTH", allow_hyphen_values = true)]
    pub window: Option<String>,
    /// Colour map: grey, hot, viridis, turbo, cool-warm.
    #[arg(long, default_value = "grey")]
    pub colormap: String,
    /// Square pixels per voxel instead of the physical aspect ratio (which honours anisotropic
    /// spacing and is the default).
    #[arg(long)]
    pub voxel_aspect: bool,
    /// Length of the picture's longer side in pixels. Default: one pixel per smallest voxel
    /// spacing, enlarged to at least 512 pixels.
    #[arg(long, conflicts_with = "zoom", value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub size: Option<u32>,
    /// Pixels per smallest voxel spacing (per voxel with --voxel-aspect), e.g. 1 for the
    /// slice's own size.
    #[arg(long, visible_alias = "scale")]
    pub zoom: Option<f64>,
    /// Resampling of voxels to pixels: linear (bilinear, smooth) or nearest (blocky).
    #[arg(long, value_enum, default_value_t = Resample::Linear)]
    pub interpolation: Resample,
    /// Leave out the orientation labels (R/L, A/P, S/I from the direction matrix) at the edges.
    #[arg(long)]
    pub no_labels: bool,
}

/// Resampling choices of `--interpolation`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Resample {
    /// Bilinear.
    Linear,
    /// Nearest voxel.
    Nearest,
}

fn parse_axis(s: &str) -> Result<Axis, String> {
    match s.to_ascii_lowercase().as_str() {
        "x" | "i" => Ok(Axis::X),
        "y" | "j" => Ok(Axis::Y),
        "z" | "k" => Ok(Axis::Z),
        _ => Err(format!("unknown axis {s:?} (expected x, y or z)")),
    }
}

/// Run `volmorph slice`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    volmorph_render::check_png(&args.output)?;
    let pb = progress::spinner(format!("reading {}", args.input.display()));
    let vol = format::read(&args.input).context("cannot read volume")?;
    progress::spin(&pb, "drawing the slice");
    let pos = match (args.index, args.position) {
        (Some(i), _) => SlicePosition::Index(i),
        (None, Some(p)) => SlicePosition::Physical(p),
        (None, None) => SlicePosition::middle(vol.geometry().dims, args.axis),
    };
    let colormap: Colormap = args.colormap.parse()?;
    let window = match &args.window {
        Some(w) => {
            let [c, w] = args::pair(w)?;
            Some(Window::new(c, w)?)
        }
        None => None,
    };
    let s = slice::extract(&vol, args.axis, pos)
        .with_context(|| format!("cannot take the slice of {}", args.input.display()))?;
    let labels = if args.no_labels {
        None
    } else {
        Some(OrientationLabels::for_slice(
            vol.geometry().direction,
            args.axis,
        )?)
    };
    let style = SliceStyle {
        window,
        colormap,
        aspect: if args.voxel_aspect {
            PixelAspect::Voxel
        } else {
            PixelAspect::Physical
        },
        size: match (args.size, args.zoom) {
            (Some(n), _) => SliceSize::LongSide(n),
            (None, Some(z)) => SliceSize::Zoom(z),
            (None, None) => SliceSize::Auto,
        },
        interpolation: match args.interpolation {
            Resample::Linear => Interpolation::Linear,
            Resample::Nearest => Interpolation::Nearest,
        },
        labels,
    };
    let img = render_slice(&s, &style)?;
    progress::spin(&pb, format!("writing {}", args.output.display()));
    write_png_rgba(&args.output, &img).context("cannot write")?;
    pb.finish_and_clear();
    Ok(())
}
