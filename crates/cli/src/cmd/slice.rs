//! `volmorph slice`: a PNG picture of an axis-aligned slice.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use volmorph_render::{Colormap, RgbaImage, Window, render_scalar, write_png_rgba};
use volmorph_volume::AnyVolume;
use volmorph_volume::slice::{self, Axis, Slice, SlicePosition};
use volmorph_volume_io as format;

use crate::args;

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
    /// Draw pixels with the physical aspect ratio (resamples anisotropic voxels).
    #[arg(long)]
    pub physical_aspect: bool,
    /// Integer magnification (nearest neighbour).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub scale: u32,
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
    let vol = format::read(&args.input).context("cannot read volume")?;
    let pos = match (args.index, args.position) {
        (Some(i), _) => SlicePosition::Index(i),
        (None, Some(p)) => SlicePosition::Physical(p),
        (None, None) => SlicePosition::Index(middle(&vol, args.axis)),
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
    let img = picture(&s, window, colormap, args.physical_aspect, args.scale)?;
    write_png_rgba(&args.output, &img).context("cannot write")?;
    Ok(())
}

/// Middle index along `axis`.
pub fn middle(vol: &AnyVolume, axis: Axis) -> f64 {
    let d = vol.geometry().dims;
    let n = match axis {
        Axis::X => d[0],
        Axis::Y => d[1],
        Axis::Z => d[2],
    };
    ((n - 1) / 2) as f64
}

/// Colour a slice: window (default: 0.5–99.5 percentiles of its finite values, or their
/// range when that is flat), optional physical aspect and integer magnification.
///
/// # Errors
/// When the slice has no finite value to window, or the picture would be too large.
pub fn picture(
    s: &Slice,
    window: Option<Window>,
    colormap: Colormap,
    physical_aspect: bool,
    scale: u32,
) -> anyhow::Result<RgbaImage> {
    let window = match window {
        Some(w) => w,
        None => Window::from_percentiles(&s.values, 0.5, 99.5)
            .context("the slice has no finite values to choose a window from")?,
    };
    let (w, h) = (u32::try_from(s.width)?, u32::try_from(s.height)?);
    let img = render_scalar(&s.values, w, h, &window, colormap)?;
    let (sx, sy) = if physical_aspect {
        let [px, py] = s.pixel_spacing;
        let m = px.min(py);
        (px / m, py / m)
    } else {
        (1.0, 1.0)
    };
    let f = f64::from(scale);
    resize_nearest(&img, sx * f, sy * f)
}

/// Nearest-neighbour resize by factors `fx`, `fy` ≥ 1.
fn resize_nearest(img: &RgbaImage, fx: f64, fy: f64) -> anyhow::Result<RgbaImage> {
    if fx == 1.0 && fy == 1.0 {
        return Ok(img.clone());
    }
    let (iw, ih) = (img.width(), img.height());
    let w = (f64::from(iw) * fx).round();
    let h = (f64::from(ih) * fy).round();
    if !(w <= f64::from(u16::MAX) && h <= f64::from(u16::MAX)) {
        bail!("picture of {w} x {h} pixels is too large; lower --scale");
    }
    let (w, h) = ((w as u32).max(1), (h as u32).max(1));
    Ok(RgbaImage::from_fn(w, h, |x, y| {
        let sx = ((f64::from(x) + 0.5) / fx) as u32;
        let sy = ((f64::from(y) + 0.5) / fy) as u32;
        img.get(sx.min(iw - 1), sy.min(ih - 1)).unwrap_or([0; 4])
    })?)
}

/// Write the picture of `s` to `path` at twice its size with the physical aspect ratio
/// (used by the demo).
pub fn write_picture(
    path: &Path,
    s: &Slice,
    window: Option<Window>,
    colormap: Colormap,
) -> anyhow::Result<()> {
    let img = picture(s, window, colormap, true, 2)?;
    write_png_rgba(path, &img).context("cannot write")
}
