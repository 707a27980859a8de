//! `volmorph render`: direct volume rendering of a volume, as deformed by a map, turntables,
//! and McPhail's quality view of a source against a deformed target.
//!
//! The deformation is a pull-back, as `volmorph warp` uses it: `--map` takes any map file
//! (volmorph map JSON of any kind, ITK `.tfm`, `.bxf`), read as the map from displayed points
//! to the volume's points;
//! handle files (`--handles` or `--from/--to`) deform so that the source handles move to
//! their targets (as `volmorph handles warp`). With `--compare SOURCE TARGET` the target is
//! pulled back onto the source: `--map` from source points to target points, or the handles'
//! map from sources to targets.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use volmorph_deform::{Identity, SpaceMap};
use volmorph_maps::{AnyMap, HandleDirection, handle_map, read_map};
use volmorph_render::{
    AnimationFormat, CameraKind, ClipPlane, ComparePictures, DvrVolume, PictureMode, PictureSpec,
    QualityOptions, RgbaImage, TransferChoice, UpAxis, VolumePictures, write_animation, write_apng,
    write_png_rgba,
};
use volmorph_volume_io as format;

use super::handles::{self, MapArgs};
use crate::progress;

/// What rays accumulate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Mode {
    /// Emission–absorption compositing through the transfer function.
    Composite,
    /// Maximum-intensity projection.
    Mip,
    /// First-hit isosurface at --level (default: halfway through the robust value range).
    Iso,
}

/// Kind of camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Projection {
    /// Pinhole camera (34° vertical field of view).
    Perspective,
    /// Parallel projection.
    Orthographic,
}

/// Arguments of `volmorph render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Volume to render (omit with --compare).
    #[arg(required_unless_present = "compare")]
    pub input: Option<PathBuf>,
    /// Output: a .png picture; with --frames N > 1 an animation file (.png/.apng animated PNG,
    /// .gif animated GIF) or else a folder for frame0000.png … and the animated turntable.png.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Transfer function: auto (ct-bone for CT, mri otherwise), a preset (ct-bone,
    /// ct-soft-tissue, ct-lung, mri), a transfer-function file (.json, also ParaView presets)
    /// or value:r,g,b,opacity;…
    #[arg(long, default_value = "auto")]
    pub transfer: String,
    /// What rays accumulate.
    #[arg(long, value_enum, default_value_t = Mode::Composite)]
    pub mode: Mode,
    /// Iso level of --mode iso (data units).
    #[arg(long, allow_hyphen_values = true)]
    pub level: Option<f64>,
    /// Viewing direction: AZIMUTH,ELEVATION in degrees (z up: azimuth 0 looks from +x, 90
    /// from +y), or anterior, posterior, left, right, superior, inferior, front, side, top,
    /// iso.
    #[arg(long, default_value = "anterior", allow_hyphen_values = true)]
    pub view: String,
    /// The axis that is up in the picture: z (medical volumes, LPS) or y.
    #[arg(long, default_value = "z", value_parser = crate::args::up_axis)]
    pub up: UpAxis,
    /// Picture size WIDTHxHEIGHT (or one number for a square).
    #[arg(long, default_value = "512x512", value_parser = crate::args::size)]
    pub size: (u32, u32),
    /// Kind of camera.
    #[arg(long, value_enum, default_value_t = Projection::Perspective)]
    pub projection: Projection,
    /// Step between samples along rays, in world units (default: half the smallest voxel
    /// spacing).
    #[arg(long)]
    pub step: Option<f64>,
    /// Do not light the gradients.
    #[arg(long)]
    pub no_shading: bool,
    /// Background: black, white, transparent, or R,G,B or R,G,B,A (0–255).
    #[arg(long, default_value = "black")]
    pub background: String,
    /// Cut-away plane X,Y,Z,NX,NY,NZ: a point of the plane and the normal pointing into the
    /// removed half (world coordinates).
    #[arg(long, value_name = "X,Y,Z,NX,NY,NZ", allow_hyphen_values = true)]
    pub clip: Option<String>,
    /// Map file (volmorph map JSON of any kind, ITK .tfm, .bxf) used as the pull-back map.
    #[arg(long, conflicts_with_all = ["handles", "from"])]
    pub map: Option<PathBuf>,
    /// A handle deformation instead of --map.
    #[command(flatten)]
    pub handles: MapArgs,
    /// Nodes per axis of the grid the map is sampled on (trilinear in between).
    #[arg(long, default_value_t = volmorph_render::picture::DEFAULT_MAP_GRID)]
    pub grid: usize,
    /// Quality view: SOURCE and TARGET volumes; the target is pulled back onto the source by
    /// --map or the handles (identity without either). Green where they match, red where the
    /// source is brighter, blue where the target is.
    #[arg(long, num_args = 2, value_names = ["SOURCE", "TARGET"], conflicts_with = "input")]
    pub compare: Option<Vec<PathBuf>>,
    /// Frames of a turntable (a full turn about the up axis).
    #[arg(long, default_value_t = 1)]
    pub frames: usize,
    /// Milliseconds per turntable frame in the animation (a GIF rounds to 10 ms).
    #[arg(long, default_value_t = 80)]
    pub delay: u32,
    /// Render the picture this many times and report the median time (benchmarking).
    #[arg(long, default_value_t = 1)]
    pub repeat: usize,
    /// Also write the transfer function used as a JSON file.
    #[arg(long)]
    pub save_transfer: Option<PathBuf>,
}

fn background(s: &str) -> anyhow::Result<[u8; 4]> {
    Ok(match s.trim().to_ascii_lowercase().as_str() {
        "black" => [0, 0, 0, 255],
        "white" => [255, 255, 255, 255],
        "transparent" => [0, 0, 0, 0],
        other => {
            let v: Vec<u8> = other
                .split(',')
                .map(|c| c.trim().parse::<u8>())
                .collect::<Result<_, _>>()
                .with_context(|| format!("--background {s}: channels must be 0 to 255"))?;
            match v[..] {
                [r, g, b] => [r, g, b, 255],
                [r, g, b, a] => [r, g, b, a],
                _ => bail!("--background {s}: expected black, white, transparent or R,G,B[,A]"),
            }
        }
    })
}

fn clip(s: &str) -> anyhow::Result<ClipPlane> {
    let v: Vec<f64> = s
        .split(',')
        .map(|c| c.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--clip {s}: expected six numbers X,Y,Z,NX,NY,NZ"))?;
    let [x, y, z, nx, ny, nz] = v[..] else {
        bail!("--clip {s}: expected six numbers X,Y,Z,NX,NY,NZ");
    };
    Ok(ClipPlane {
        point: glam::DVec3::new(x, y, z),
        normal: glam::DVec3::new(nx, ny, nz),
    })
}

/// The pull-back map of the arguments, if any. `forward` builds a handle map from sources to
/// targets (the comparison); otherwise from targets to sources (the deformed picture).
fn map(a: &Args, forward: bool) -> anyhow::Result<Option<AnyMap>> {
    if let Some(p) = &a.map {
        return Ok(Some(read_map(p).context("cannot read the map")?));
    }
    if a.handles.handles.is_some() || a.handles.from.is_some() {
        let set = handles::read_handle_set(&a.handles)?;
        let direction = if forward {
            HandleDirection::SourcesToTargets
        } else {
            HandleDirection::TargetsToSources
        };
        let m = handle_map(
            &set,
            a.handles.method.into(),
            &handles::options(&a.handles)?,
            direction,
        )
        .context("cannot build the deformation")?;
        return Ok(Some(m));
    }
    Ok(None)
}

fn read(path: &Path) -> anyhow::Result<DvrVolume> {
    let v = format::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    DvrVolume::new(&v).with_context(|| format!("cannot render {}", path.display()))
}

/// Run `volmorph render`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let many = a.frames > 1;
    // Outputs before the inputs: a .png picture, or with --frames N > 1 an animation file or
    // a folder of frames; a transfer function to save as .json.
    if many {
        volmorph_render::check_animation_output(&a.output)?;
    } else {
        volmorph_render::check_png(&a.output)
            .context("one picture is a .png file (or give --frames N > 1 for an animation)")?;
    }
    if let Some(p) = &a.save_transfer {
        volmorph_io::extension::check(p, volmorph_render::TransferFunction::EXTENSIONS)?;
    }
    if a.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    let mode = match a.mode {
        Mode::Composite => PictureMode::Composite,
        Mode::Mip => PictureMode::MaximumIntensity,
        Mode::Iso => PictureMode::Isosurface { level: a.level },
    };
    let spec = PictureSpec {
        transfer: TransferChoice::parse(&a.transfer).context("--transfer")?,
        mode,
        shading: !a.no_shading,
        camera: match a.projection {
            Projection::Perspective => CameraKind::Perspective,
            Projection::Orthographic => CameraKind::Orthographic,
        },
        size: a.size,
        step: a.step,
        clip: a.clip.as_deref().map(clip).transpose()?,
        background: background(&a.background)?,
        grid: a.grid,
        frames: a.frames,
        ..PictureSpec::new(crate::args::view(&a.view, a.up).context("--view")?)
    };
    let pb = progress::spinner("reading");
    let (frames, summary) = if let Some(pair) = &a.compare {
        let (source, target) = (read(&pair[0])?, read(&pair[1])?);
        let m = map(a, true)?;
        let m: &dyn SpaceMap = match &m {
            Some(m) => m,
            None => &Identity,
        };
        pb.set_message("rendering");
        let pics = ComparePictures::new(&source, &target, m, spec, QualityOptions::default())?;
        let frames = timed(&pb, a.repeat, pics.frame_count(), |i| pics.frame(i))?;
        let what = format!("{} against {}", pair[0].display(), pair[1].display());
        (frames, what)
    } else {
        let input = a.input.as_deref().context("give a volume to render")?;
        let volume = read(input)?;
        let m = map(a, false)?;
        pb.set_message("rendering");
        let pics = VolumePictures::new(&volume, m.as_ref().map(|m| m as &dyn SpaceMap), spec)?;
        if let Some(p) = &a.save_transfer {
            pics.renderer()
                .transfer()
                .write(p)
                .with_context(|| format!("cannot write {}", p.display()))?;
        }
        let frames = timed(&pb, a.repeat, pics.frame_count(), |i| pics.frame(i))?;
        let (visible, bricks) = pics.renderer().visible_bricks();
        let what = format!(
            "{} ({}, step {:.3}, {visible} of {bricks} bricks visible{})",
            input.display(),
            pics.renderer()
                .transfer()
                .name()
                .unwrap_or("transfer function"),
            pics.renderer().step(),
            if m.is_some() { ", deformed" } else { "" }
        );
        (frames, what)
    };
    progress::spin(&pb, "writing");
    let (images, median) = frames;
    if many && AnimationFormat::from_path(&a.output).is_some() {
        write_animation(&a.output, &images, a.delay).context("cannot write the animation")?;
    } else if many {
        std::fs::create_dir_all(&a.output)
            .with_context(|| format!("cannot create {}", a.output.display()))?;
        for (i, img) in images.iter().enumerate() {
            let p = a.output.join(format!("frame{i:04}.png"));
            write_png_rgba(&p, img).with_context(|| format!("cannot write {}", p.display()))?;
        }
        let p = a.output.join("turntable.png");
        write_apng(&p, &images, a.delay).context("cannot write the animation")?;
    } else {
        write_png_rgba(&a.output, &images[0]).context("cannot write")?;
    }
    pb.finish_and_clear();
    let (w, h) = a.size;
    say!(
        "rendered {summary}: {} picture(s) of {w}×{h}, median {:.1} ms per picture → {}",
        images.len(),
        median * 1e3,
        a.output.display()
    );
    Ok(())
}

/// Render `frames` pictures; with `repeat > 1` render frame 0 that many times as well. Returns
/// the pictures and the median seconds per picture. `pb` counts the pictures.
fn timed(
    pb: &indicatif::ProgressBar,
    repeat: usize,
    frames: usize,
    render: impl Fn(usize) -> Result<RgbaImage, volmorph_render::RenderError>,
) -> anyhow::Result<(Vec<RgbaImage>, f64)> {
    use volmorph_io::Progress;
    let bar = progress::Bar(pb);
    bar.start(
        &format!("rendering {frames} picture(s)"),
        (frames + repeat.saturating_sub(1)) as u64,
    );
    let mut times = Vec::new();
    let mut images = Vec::with_capacity(frames);
    for i in 0..frames {
        let t = Instant::now();
        images.push(render(i).context("cannot render")?);
        times.push(t.elapsed().as_secs_f64());
        bar.advance(1);
    }
    for _ in 1..repeat {
        let t = Instant::now();
        render(0).context("cannot render")?;
        times.push(t.elapsed().as_secs_f64());
        bar.advance(1);
    }
    times.sort_by(f64::total_cmp);
    Ok((images, times[times.len() / 2]))
}
