//! `volmorph frep …`: F-rep models written in the HyperFun language — sample them to
//! volumes, mesh them, ray-cast pictures of them, and animate the metamorphosis of one into
//! another.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use glam::DVec3;
use volmorph_frep::grid::{box_geometry, isotropic_box_geometry, sample_with};
use volmorph_frep::mapping::{Schedule, morph};
use volmorph_frep::output::{
    MeshMethod, MeshOptions, RenderOptions, SurfaceSummary, mesh_with, render_animation_with,
    render_frames_with, render_with,
};
use volmorph_frep::reconstruct::{SectionBlend, SectionStack, femur_sections};
use volmorph_frep::{CompileOptions, Field, Shape, Tape, compile_source};
use volmorph_mesh::{self as meshio, MeshWriteOptions};
use volmorph_render::{
    AnimationFormat, Camera, DEFAULT_FOV_Y, Framing, Projection, UpAxis, write_animation,
    write_png_rgba,
};
use volmorph_volume::AnyVolume;
use volmorph_volume_io as format;

use crate::progress;

/// Largest grid size per axis accepted (a 2048³ f32 volume is 32 GiB).
const MAX_GRID: usize = 2048;

/// Largest animation length.
const MAX_FRAMES: usize = 10_000;

/// F-rep subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Sample a model's defining function on a grid and write it as a volume (f32, the solid
    /// is where values are ≥ 0).
    #[command(
        after_help = "Example:\n  volmorph frep eval gear.hf --grid 193 --bounds -1.6,1.6 -o gear.nii.gz --param a1=0.5"
    )]
    Eval(EvalArgs),
    /// Extract a model's surface f = 0 as a triangle mesh.
    #[command(
        after_help = "Example:\n  volmorph frep mesh csg.hf --grid 128 --bounds -8,8 -o csg.ply --method dual-contouring"
    )]
    Mesh(MeshArgs),
    /// Ray-cast a shaded picture of a model (PNG).
    #[command(
        after_help = "Example:\n  volmorph frep render gear.hf -o gear.png --size 640x480 --view 30,35"
    )]
    Render(RenderArgs),
    /// Animate the metamorphosis of one model into another (an animated PNG or GIF, or a
    /// folder of numbered PNG frames).
    #[command(
        after_help = "Examples:\n  volmorph frep morph s1_sphere.hf s5_twist.hf --schedule smoothstep --frames 24 -o morph.gif\n  volmorph frep morph s1_sphere.hf s5_twist.hf --frames 24 -o morph.png --delay 80\n  volmorph frep morph s1_sphere.hf s5_twist.hf --frames 24 -o frames/\n\nOutput by extension: .png or .apng an animated PNG (full colour), .gif an animated GIF\n(256 colours, one palette for all frames), anything else a folder of frame0000.png …"
    )]
    Morph(MorphArgs),
    /// Reconstruct a solid from planar cross-sections (contours at heights z) by
    /// metamorphosis along z, and write its surface as a mesh or its defining function as a
    /// volume.
    #[command(
        after_help = "Contour file (JSON):\n  {\"sections\": [{\"z\": 0, \"points\": [[x, y], ...]},\n                {\"z\": 2, \"loops\": [[[x, y], ...], [[x, y], ...]]}, ...],\n   \"blend\": \"linear\" | \"catmull-rom\"}\n\nExamples:\n  volmorph frep sections contours.json -o bone.ply --grid 160\n  volmorph frep sections --example femur -o femur.obj"
    )]
    Sections(SectionsArgs),
}

/// Options shared by every frep command: model parameters and the box.
#[derive(Debug, Clone, clap::Args)]
pub struct Common {
    /// Box of interest: `lo,hi` (a cube) or `x0,y0,z0,x1,y1,z1`.
    #[arg(long, default_value = "-1.6,1.6", allow_hyphen_values = true)]
    pub bounds: String,
    /// Set a model parameter: `a1=0.5` sets the first element of the model's parameter
    /// array (repeatable).
    #[arg(long = "param", value_name = "aN=VALUE")]
    pub params: Vec<String>,
}

/// Arguments of `volmorph frep eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Model file (HyperFun language).
    pub model: PathBuf,
    /// Grid points per axis (voxel centres on the box's faces).
    #[arg(long, default_value_t = 128)]
    pub grid: usize,
    /// Output volume (.nii, .nii.gz, .mha, .nrrd, .vtk).
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub common: Common,
}

/// Arguments of `volmorph frep mesh`.
#[derive(Debug, clap::Args)]
pub struct MeshArgs {
    /// Model file (HyperFun language).
    pub model: PathBuf,
    /// Grid points per axis.
    #[arg(long, default_value_t = 128)]
    pub grid: usize,
    /// Output mesh (.obj, .ply, .stl, .off).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Surface extraction algorithm.
    #[arg(long, value_enum, default_value_t = Method::MarchingCubes)]
    pub method: Method,
    /// Cap the shape where the box cuts it, so the mesh is closed.
    #[arg(long)]
    pub close: bool,
    /// Write ASCII STL/PLY instead of binary.
    #[arg(long)]
    pub ascii: bool,
    #[command(flatten)]
    pub common: Common,
}

/// Isosurface extractors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Marching cubes.
    MarchingCubes,
    /// Dual contouring (sharp edges kept).
    DualContouring,
}

impl From<Method> for MeshMethod {
    fn from(m: Method) -> Self {
        match m {
            Method::MarchingCubes => MeshMethod::MarchingCubes,
            Method::DualContouring => MeshMethod::DualContouring,
        }
    }
}

/// Picture options shared by `render` and `morph`.
#[derive(Debug, Clone, clap::Args)]
pub struct View {
    /// Picture size `WxH` (or one number for a square).
    #[arg(long, default_value = "512x512")]
    pub size: String,
    /// Viewing direction `azimuth,elevation` in degrees (z up: azimuth 0 looks from +x, 90
    /// from +y), or a view name (front, side, top, iso); the camera looks at the box's centre.
    #[arg(long, default_value = "35,25", allow_hyphen_values = true)]
    pub view: String,
    /// The axis that is up in the picture: z or y.
    #[arg(long, default_value = "z", value_parser = crate::args::up_axis)]
    pub up: UpAxis,
}

/// Arguments of `volmorph frep render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Model file (HyperFun language).
    pub model: PathBuf,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub view: View,
    #[command(flatten)]
    pub common: Common,
}

/// Arguments of `volmorph frep morph`.
#[derive(Debug, clap::Args)]
pub struct MorphArgs {
    /// Initial model (t = 0).
    pub from: PathBuf,
    /// Final model (t = 1).
    pub to: PathBuf,
    /// Schedule h(t) of the metamorphosis (1 − h) f + h g: linear, sqrt, smoothstep or
    /// delayed:T0.
    #[arg(long, default_value = "linear")]
    pub schedule: String,
    /// Number of frames (t = 0 … 1).
    #[arg(long, default_value_t = 10)]
    pub frames: usize,
    /// Output: an animation file (.png/.apng animated PNG, .gif animated GIF) or a folder for
    /// `frame0000.png` …
    #[arg(short, long)]
    pub output: PathBuf,
    /// Milliseconds per frame of an animation file (a GIF rounds to 10 ms).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=65535))]
    pub delay: u32,
    #[command(flatten)]
    pub view: View,
    #[command(flatten)]
    pub common: Common,
}

/// Arguments of `volmorph frep sections`.
#[derive(Debug, clap::Args)]
pub struct SectionsArgs {
    /// Contour file (JSON, see below); omit with `--example`.
    #[arg(required_unless_present = "example", conflicts_with = "example")]
    pub contours: Option<PathBuf>,
    /// Use a built-in example instead of a file: `femur` (12 sections, centimetres).
    #[arg(long, value_parser = ["femur"])]
    pub example: Option<String>,
    /// Output: a mesh (.obj, .ply, .stl, .off) of the surface, or a volume (.nii, .nii.gz,
    /// .mha, .nrrd, .vtk) of the defining function (f32, solid where ≥ 0).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Grid points along the longest side of the box (the other sides get the same spacing).
    #[arg(long, default_value_t = 128)]
    pub grid: usize,
    /// Box: `lo,hi` or `x0,y0,z0,x1,y1,z1`; default: the contours' bounding box and the slab
    /// of the sections, enlarged by 5 % of its largest extent on every side.
    #[arg(long, allow_hyphen_values = true)]
    pub bounds: Option<String>,
    /// Blend along z between sections (overrides the file's `blend`).
    #[arg(long, value_enum)]
    pub blend: Option<Blend>,
    /// Surface extraction algorithm (mesh output).
    #[arg(long, value_enum, default_value_t = Method::MarchingCubes)]
    pub method: Method,
    /// Write ASCII STL/PLY instead of binary.
    #[arg(long)]
    pub ascii: bool,
}

/// Blends between cross-sections.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Blend {
    /// (1 − t) f_k + t f_{k+1} (the seed's Eq. 13).
    Linear,
    /// Cubic Hermite with Catmull–Rom tangents across four sections (C¹ along z).
    CatmullRom,
}

/// Run a frep subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Eval(a) => eval(a),
        Command::Mesh(a) => mesh_cmd(a),
        Command::Render(a) => render_cmd(a),
        Command::Morph(a) => morph_cmd(a),
        Command::Sections(a) => sections_cmd(a),
    }
}

/// Parse `--param aN=V` options.
pub fn params(list: &[String]) -> anyhow::Result<HashMap<usize, f64>> {
    let mut out = HashMap::new();
    for p in list {
        let Some((k, v)) = p.split_once('=') else {
            bail!("--param {p}: expected aN=VALUE, e.g. a1=0.5");
        };
        let idx: usize = k
            .trim()
            .strip_prefix('a')
            .and_then(|n| n.parse().ok())
            .filter(|&n: &usize| n >= 1)
            .with_context(|| format!("--param {p}: the name must be a1, a2, …"))?;
        let val: f64 = v
            .trim()
            .parse()
            .with_context(|| format!("--param {p}: {v:?} is not a number"))?;
        if !val.is_finite() {
            bail!("--param {p}: the value must be finite");
        }
        out.insert(idx, val);
    }
    Ok(out)
}

/// Read and compile a model file.
pub fn load(path: &Path, params: &HashMap<usize, f64>) -> anyhow::Result<Shape> {
    let src = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read model {}", path.display()))?;
    compile_source(
        &src,
        &CompileOptions {
            params: params.clone(),
            object: None,
        },
    )
    .with_context(|| format!("{}", path.display()))
}

/// Parse `--bounds`.
pub fn bounds(s: &str) -> anyhow::Result<(DVec3, DVec3)> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--bounds {s}: expected numbers"))?;
    let (lo, hi) = match v.as_slice() {
        [a, b] => (DVec3::splat(*a), DVec3::splat(*b)),
        [a, b, c, d, e, f] => (DVec3::new(*a, *b, *c), DVec3::new(*d, *e, *f)),
        _ => bail!("--bounds {s}: expected lo,hi or x0,y0,z0,x1,y1,z1"),
    };
    if !(lo.is_finite() && hi.is_finite()) || (hi - lo).min_element() <= 0.0 {
        bail!("--bounds {s}: every max must be greater than its min");
    }
    Ok((lo, hi))
}

fn grid_geometry(n: usize, bounds: (DVec3, DVec3)) -> anyhow::Result<volmorph_volume::Geometry> {
    if !(2..=MAX_GRID).contains(&n) {
        bail!("--grid {n}: must be between 2 and {MAX_GRID}");
    }
    Ok(box_geometry(bounds.0, bounds.1, [n; 3])?)
}

fn eval(a: &EvalArgs) -> anyhow::Result<()> {
    let b = bounds(&a.common.bounds)?;
    let g = grid_geometry(a.grid, b)?;
    let shape = load(&a.model, &params(&a.common.params)?)?;
    let pb = progress::bar(0);
    let tape = Tape::new(&shape);
    let t0 = std::time::Instant::now();
    let vol = sample_with(&tape, &g, &progress::Bar(&pb)).context("cannot sample the model")?;
    let dt = t0.elapsed();
    progress::spin(&pb, format!("writing {}", a.output.display()));
    format::write(&a.output, &AnyVolume::from(vol.clone()))
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    pb.finish_and_clear();
    let inside = vol.data().iter().filter(|v| **v >= 0.0).count();
    say!(
        "{} operations, {}³ samples in {:.1} ms, {} inside ({:.1} %)",
        tape.len(),
        a.grid,
        dt.as_secs_f64() * 1e3,
        inside,
        100.0 * inside as f64 / vol.len().max(1) as f64
    );
    Ok(())
}

fn mesh_cmd(a: &MeshArgs) -> anyhow::Result<()> {
    let b = bounds(&a.common.bounds)?;
    let g = grid_geometry(a.grid, b)?;
    let shape = load(&a.model, &params(&a.common.params)?)?;
    let pb = progress::bar(0);
    let tape = Tape::new(&shape);
    let options = MeshOptions {
        method: a.method.into(),
        close: a.close,
    };
    let surface = mesh_with(&tape, &g, &options, &progress::Bar(&pb))
        .context("cannot extract the surface")?;
    progress::spin(&pb, format!("writing {}", a.output.display()));
    let summary = write_surface(&surface.mesh, &a.output, a.ascii)?;
    pb.finish_and_clear();
    say!("{summary}");
    Ok(())
}

/// Write an extracted surface (binary unless `ascii`) and return its summary.
fn write_surface(
    m: &volmorph_mesh::Mesh,
    path: &Path,
    ascii: bool,
) -> anyhow::Result<SurfaceSummary> {
    let opts = MeshWriteOptions {
        binary: !ascii,
        ..MeshWriteOptions::default()
    };
    meshio::write_with(path, m, &opts)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(SurfaceSummary::of(m))
}

fn sections_cmd(a: &SectionsArgs) -> anyhow::Result<()> {
    let blend = a.blend.map(|b| match b {
        Blend::Linear => SectionBlend::Linear,
        Blend::CatmullRom => SectionBlend::CatmullRom,
    });
    let (stack, name) = if let Some(path) = &a.contours {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read contours {}", path.display()))?;
        let mut stack =
            SectionStack::from_json(&text).with_context(|| format!("{}", path.display()))?;
        if let Some(b) = blend {
            stack = stack.with_blend(b);
        }
        (stack, path.display().to_string())
    } else {
        let sections = femur_sections(32)?;
        let stack = SectionStack::new(&sections, blend.unwrap_or_default())?;
        (stack, "the femur example".to_string())
    };
    let (lo, hi) = match &a.bounds {
        Some(b) => bounds(b)?,
        None => stack.sampling_bounds(),
    };
    let g = isotropic_box_geometry(lo, hi, a.grid, MAX_GRID).context("--grid")?;
    let dims = g.dims;
    if meshio::MeshFormat::from_path(&a.output).is_ok() {
        let pb = progress::bar(0);
        let options = MeshOptions {
            method: a.method.into(),
            close: true,
        };
        let surface = mesh_with(&stack, &g, &options, &progress::Bar(&pb))
            .with_context(|| format!("cannot extract the surface of {name}"))?;
        progress::spin(&pb, format!("writing {}", a.output.display()));
        let summary = write_surface(&surface.mesh, &a.output, a.ascii)?;
        pb.finish_and_clear();
        say!(
            "{} sections, {}×{}×{} grid: {summary}",
            stack.heights().len(),
            dims[0],
            dims[1],
            dims[2],
        );
    } else {
        let pb = progress::bar(0);
        let vol = sample_with(&stack, &g, &progress::Bar(&pb))
            .with_context(|| format!("cannot sample {name}"))?;
        progress::spin(&pb, format!("writing {}", a.output.display()));
        format::write(&a.output, &AnyVolume::from(vol))
            .with_context(|| format!("cannot write {}", a.output.display()))?;
        pb.finish_and_clear();
        say!(
            "{} sections sampled on {}×{}×{}",
            stack.heights().len(),
            dims[0],
            dims[1],
            dims[2]
        );
    }
    Ok(())
}

fn camera(view: &View, b: (DVec3, DVec3)) -> anyhow::Result<Camera> {
    let (w, h) = crate::args::size(&view.size).context("--size")?;
    let orbit = crate::args::view(&view.view, view.up).context("--view")?;
    let perspective = Projection::Perspective {
        fov_y: DEFAULT_FOV_Y,
    };
    Ok(orbit.camera(b, perspective, Framing::Sphere, w, h)?)
}

fn render_cmd(a: &RenderArgs) -> anyhow::Result<()> {
    let b = bounds(&a.common.bounds)?;
    let cam = camera(&a.view, b)?;
    let shape = load(&a.model, &params(&a.common.params)?)?;
    let pb = progress::bar(0);
    let tape = Tape::new(&shape);
    let options = RenderOptions {
        bounds_min: b.0,
        bounds_max: b.1,
        ..RenderOptions::default()
    };
    let t0 = std::time::Instant::now();
    let img = render_with(&tape, &cam, &options, &progress::Bar(&pb)).context("cannot render")?;
    let dt = t0.elapsed();
    progress::spin(&pb, format!("writing {}", a.output.display()));
    write_png_rgba(&a.output, &img)
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    pb.finish_and_clear();
    let covered = img
        .pixels()
        .iter()
        .filter(|p| **p != options.background)
        .count();
    say!(
        "{}x{} picture in {:.2} s, the model covers {:.1} % of it",
        img.width(),
        img.height(),
        dt.as_secs_f64(),
        100.0 * covered as f64 / img.pixels().len().max(1) as f64
    );
    Ok(())
}

fn morph_cmd(a: &MorphArgs) -> anyhow::Result<()> {
    if !(1..=MAX_FRAMES).contains(&a.frames) {
        bail!("--frames {}: must be 1 to {MAX_FRAMES}", a.frames);
    }
    let schedule = Schedule::parse(&a.schedule).context("--schedule")?;
    let b = bounds(&a.common.bounds)?;
    let cam = camera(&a.view, b)?;
    let p = params(&a.common.params)?;
    let f = load(&a.from, &p)?;
    let g = load(&a.to, &p)?;
    let options = RenderOptions {
        bounds_min: b.0,
        bounds_max: b.1,
        ..RenderOptions::default()
    };
    let pb = progress::bar(0);
    let field_at = |t: f64| -> Result<Box<dyn Field>, volmorph_frep::FrepError> {
        Ok(Box::new(Tape::new(&morph(&f, &g, t, schedule))))
    };
    if let Some(format) = AnimationFormat::from_path(&a.output) {
        let images = render_frames_with(a.frames, &field_at, &cam, &options, &progress::Bar(&pb))
            .context("cannot render the animation")?;
        progress::spin(&pb, format!("writing {}", a.output.display()));
        write_animation(&a.output, &images, a.delay).context("cannot write the animation")?;
        pb.finish_and_clear();
        say!(
            "{} frames written to {} ({})",
            images.len(),
            a.output.display(),
            match format {
                AnimationFormat::Apng => "animated PNG",
                AnimationFormat::Gif => "animated GIF",
            }
        );
        return Ok(());
    }
    crate::args::refuse_picture_extension(&a.output)?;
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("cannot create {}", a.output.display()))?;
    let paths = render_animation_with(
        a.frames,
        &field_at,
        &cam,
        &options,
        &a.output,
        "frame",
        &progress::Bar(&pb),
    )
    .context("cannot render the animation")?;
    pb.finish_and_clear();
    say!(
        "{} frames written to {} ({} … {})",
        paths.len(),
        a.output.display(),
        paths
            .first()
            .map(|p| p.display().to_string())
            .unwrap_or_default(),
        paths
            .last()
            .map(|p| p.display().to_string())
            .unwrap_or_default()
    );
    Ok(())
}
