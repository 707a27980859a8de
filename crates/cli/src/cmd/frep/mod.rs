//! `volmorph frep …`: F-rep models written in the HyperFun language — sample them to
//! volumes, mesh them, ray-cast pictures of them, animate the metamorphosis of one into
//! another, apply mapping specifications to them, and reconstruct solids from cross-sections
//! and scattered points.

mod args;

use std::collections::HashMap;
use std::path::Path;

use anyhow::{Context, bail};
use glam::DVec3;
use volmorph_frep::grid::{box_geometry, isotropic_box_geometry, sample_with};
use volmorph_frep::mapping::{Schedule, morph};
use volmorph_frep::output::{
    MeshOptions, RenderOptions, SurfaceSummary, mesh_with, render_animation_with,
    render_frames_with, render_with,
};
use volmorph_frep::reconstruct::{PointSurface, SectionBlend, SectionStack, femur_sections};
use volmorph_frep::spec::{MappingSpec, SpecContext};
use volmorph_frep::{CompileOptions, Field, Shape, Tape, compile_file};
use volmorph_mesh::{self as meshio, MeshWriteOptions};
use volmorph_render::{AnimationFormat, Camera, RgbaImage, write_animation, write_png_rgba};
use volmorph_volume::{AnyVolume, Geometry};
use volmorph_volume_io as format;

pub use self::args::{
    Blend, Command, Common, EvalArgs, MapArgs, MeshArgs, Method, MorphArgs, PointsArgs, RenderArgs,
    SectionsArgs, View,
};
use crate::progress;

/// Largest grid size per axis accepted (a 2048³ f32 volume is 32 GiB).
const MAX_GRID: usize = 2048;

/// Largest animation length.
const MAX_FRAMES: usize = 10_000;

/// Run a frep subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Eval(a) => eval(a),
        Command::Mesh(a) => mesh_cmd(a),
        Command::Render(a) => render_cmd(a),
        Command::Morph(a) => morph_cmd(a),
        Command::Sections(a) => sections_cmd(a),
        Command::Map(a) => map_cmd(a),
        Command::Points(a) => points_cmd(a),
    }
}

/// Parse `--param aN=V` options ([`CompileOptions::parse_param`]).
pub fn params(list: &[String]) -> anyhow::Result<HashMap<usize, f64>> {
    list.iter()
        .map(|p| CompileOptions::parse_param(p).with_context(|| format!("--param {p}")))
        .collect()
}

/// Read and compile a model file (data files it names are relative to its folder).
pub fn load(path: &Path, params: &HashMap<usize, f64>) -> anyhow::Result<Shape> {
    let options = CompileOptions {
        params: params.clone(),
        ..CompileOptions::default()
    };
    compile_file(path, &options).context("cannot load the model")
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
    let tape = Tape::new(&shape);
    let (vol, dt) = write_volume(&tape, &g, &a.output)?;
    say!(
        "{} operations, {}³ samples in {:.1} ms, {}",
        tape.len(),
        a.grid,
        dt.as_secs_f64() * 1e3,
        inside_summary(&vol)
    );
    Ok(())
}

/// `N inside (P %)` of a sampled field.
fn inside_summary(vol: &volmorph_volume::Volume<f32>) -> String {
    let inside = vol.data().iter().filter(|v| **v >= 0.0).count();
    format!(
        "{} inside ({:.1} %)",
        inside,
        100.0 * inside as f64 / vol.len().max(1) as f64
    )
}

/// Sample `field` on `g` and write it as a volume to `path`; returns the volume and the time
/// sampling took.
fn write_volume(
    field: &dyn Field,
    g: &Geometry,
    path: &Path,
) -> anyhow::Result<(volmorph_volume::Volume<f32>, std::time::Duration)> {
    let pb = progress::bar(0);
    let t0 = std::time::Instant::now();
    let vol = sample_with(field, g, &progress::Bar(&pb)).context("cannot sample the model")?;
    let dt = t0.elapsed();
    progress::spin(&pb, format!("writing {}", path.display()));
    format::write(path, &AnyVolume::from(vol.clone()))
        .with_context(|| format!("cannot write {}", path.display()))?;
    pb.finish_and_clear();
    Ok((vol, dt))
}

/// Sample `field` on `g`, extract its surface and write it to `path`.
fn write_mesh(
    field: &dyn Field,
    g: &Geometry,
    options: &MeshOptions,
    path: &Path,
    ascii: bool,
) -> anyhow::Result<SurfaceSummary> {
    let pb = progress::bar(0);
    let surface =
        mesh_with(field, g, options, &progress::Bar(&pb)).context("cannot extract the surface")?;
    progress::spin(&pb, format!("writing {}", path.display()));
    let summary = write_surface(&surface.mesh, path, ascii)?;
    pb.finish_and_clear();
    Ok(summary)
}

fn mesh_cmd(a: &MeshArgs) -> anyhow::Result<()> {
    let b = bounds(&a.common.bounds)?;
    let g = grid_geometry(a.grid, b)?;
    let shape = load(&a.model, &params(&a.common.params)?)?;
    let tape = Tape::new(&shape);
    let options = MeshOptions {
        method: a.method.into(),
        close: a.close,
    };
    let summary = write_mesh(&tape, &g, &options, &a.output, a.ascii)?;
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

/// What a single output file of `frep map`, `points` and `sections` holds, by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Output {
    /// A mesh of the surface (.obj, .ply, .stl, .off).
    Mesh,
    /// A ray-cast picture (.png).
    Picture,
    /// The sampled defining function (any volume format).
    Volume,
}

impl Output {
    fn of(path: &Path) -> Self {
        if meshio::MeshFormat::from_path(path).is_ok() {
            Self::Mesh
        } else if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"))
        {
            Self::Picture
        } else {
            Self::Volume
        }
    }
}

/// How [`write_output`] samples, meshes and pictures.
struct OutputSettings<'a> {
    bounds: (DVec3, DVec3),
    grid: usize,
    method: Method,
    close: bool,
    ascii: bool,
    view: &'a View,
}

/// Write `field` to `path` as the extension asks (mesh, picture or volume); returns the line
/// to report.
fn write_output(field: &dyn Field, path: &Path, s: &OutputSettings<'_>) -> anyhow::Result<String> {
    let (lo, hi) = s.bounds;
    match Output::of(path) {
        Output::Picture => {
            let cam = camera(s.view, s.bounds)?;
            let options = render_options(s.bounds);
            let (img, dt) = write_picture(field, &cam, &options, path)?;
            Ok(picture_summary(&img, &options, dt))
        }
        kind => {
            let g = isotropic_box_geometry(lo, hi, s.grid, MAX_GRID).context("--grid")?;
            let [nx, ny, nz] = g.dims;
            if kind == Output::Mesh {
                let options = MeshOptions {
                    method: s.method.into(),
                    close: s.close,
                };
                let summary = write_mesh(field, &g, &options, path, s.ascii)?;
                Ok(format!("{nx}×{ny}×{nz} grid: {summary}"))
            } else {
                let (vol, dt) = write_volume(field, &g, path)?;
                Ok(format!(
                    "{nx}×{ny}×{nz} samples in {:.1} ms, {}",
                    dt.as_secs_f64() * 1e3,
                    inside_summary(&vol)
                ))
            }
        }
    }
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
    if Output::of(&a.output) == Output::Mesh {
        let options = MeshOptions {
            method: a.method.into(),
            close: true,
        };
        let summary = write_mesh(&stack, &g, &options, &a.output, a.ascii)
            .with_context(|| format!("cannot reconstruct {name}"))?;
        say!(
            "{} sections, {}×{}×{} grid: {summary}",
            stack.heights().len(),
            dims[0],
            dims[1],
            dims[2],
        );
    } else {
        write_volume(&stack, &g, &a.output).with_context(|| format!("cannot sample {name}"))?;
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
    let size = crate::args::size(&view.size).context("--size")?;
    let orbit = crate::args::view(&view.view, view.up).context("--view")?;
    Ok(orbit.model_camera(b, size)?)
}

/// Ray-casting options for the box `b`.
fn render_options(b: (DVec3, DVec3)) -> RenderOptions {
    RenderOptions {
        bounds_min: b.0,
        bounds_max: b.1,
        ..RenderOptions::default()
    }
}

/// Ray-cast `field` and write the picture to `path`; returns it and the time casting took.
fn write_picture(
    field: &dyn Field,
    cam: &Camera,
    options: &RenderOptions,
    path: &Path,
) -> anyhow::Result<(RgbaImage, std::time::Duration)> {
    let pb = progress::bar(0);
    let t0 = std::time::Instant::now();
    let img = render_with(field, cam, options, &progress::Bar(&pb)).context("cannot render")?;
    let dt = t0.elapsed();
    progress::spin(&pb, format!("writing {}", path.display()));
    write_png_rgba(path, &img).with_context(|| format!("cannot write {}", path.display()))?;
    pb.finish_and_clear();
    Ok((img, dt))
}

/// `WxH picture in S s, the model covers P % of it`.
fn picture_summary(img: &RgbaImage, options: &RenderOptions, dt: std::time::Duration) -> String {
    let covered = img
        .pixels()
        .iter()
        .filter(|p| **p != options.background)
        .count();
    format!(
        "{}x{} picture in {:.2} s, the model covers {:.1} % of it",
        img.width(),
        img.height(),
        dt.as_secs_f64(),
        100.0 * covered as f64 / img.pixels().len().max(1) as f64
    )
}

fn render_cmd(a: &RenderArgs) -> anyhow::Result<()> {
    let b = bounds(&a.common.bounds)?;
    let cam = camera(&a.view, b)?;
    let shape = load(&a.model, &params(&a.common.params)?)?;
    let tape = Tape::new(&shape);
    let options = render_options(b);
    let (img, dt) = write_picture(&tape, &cam, &options, &a.output)?;
    say!("{}", picture_summary(&img, &options, dt));
    Ok(())
}

/// Render `frames` pictures of `field_at(t)`, `t = 0 … 1`, into an animation file or a folder
/// of frames (by `path`); returns the line to report.
fn write_frames(
    frames: usize,
    field_at: &dyn Fn(f64) -> Result<Box<dyn Field>, volmorph_frep::FrepError>,
    cam: &Camera,
    options: &RenderOptions,
    path: &Path,
    delay: u32,
) -> anyhow::Result<String> {
    if !(1..=MAX_FRAMES).contains(&frames) {
        bail!("--frames {frames}: must be 1 to {MAX_FRAMES}");
    }
    let pb = progress::bar(0);
    if let Some(format) = AnimationFormat::from_path(path) {
        let images = render_frames_with(frames, field_at, cam, options, &progress::Bar(&pb))
            .context("cannot render the animation")?;
        progress::spin(&pb, format!("writing {}", path.display()));
        write_animation(path, &images, delay).context("cannot write the animation")?;
        pb.finish_and_clear();
        return Ok(format!(
            "{} frames written to {} ({})",
            images.len(),
            path.display(),
            format.description()
        ));
    }
    crate::args::refuse_picture_extension(path)?;
    std::fs::create_dir_all(path).with_context(|| format!("cannot create {}", path.display()))?;
    let paths = render_animation_with(
        frames,
        field_at,
        cam,
        options,
        path,
        "frame",
        &progress::Bar(&pb),
    )
    .context("cannot render the animation")?;
    pb.finish_and_clear();
    Ok(format!(
        "{} frames written to {} ({} … {})",
        paths.len(),
        path.display(),
        paths
            .first()
            .map(|p| p.display().to_string())
            .unwrap_or_default(),
        paths
            .last()
            .map(|p| p.display().to_string())
            .unwrap_or_default()
    ))
}

fn morph_cmd(a: &MorphArgs) -> anyhow::Result<()> {
    let schedule = Schedule::parse(&a.schedule).context("--schedule")?;
    let b = bounds(&a.common.bounds)?;
    let cam = camera(&a.view, b)?;
    let p = params(&a.common.params)?;
    let f = load(&a.from, &p)?;
    let g = load(&a.to, &p)?;
    let field_at = |t: f64| -> Result<Box<dyn Field>, volmorph_frep::FrepError> {
        Ok(Box::new(Tape::new(&morph(&f, &g, t, schedule))))
    };
    let line = write_frames(
        a.frames,
        &field_at,
        &cam,
        &render_options(b),
        &a.output,
        a.delay,
    )?;
    say!("{line}");
    Ok(())
}

fn map_cmd(a: &MapArgs) -> anyhow::Result<()> {
    let b = bounds(&a.common.bounds)?;
    if !(0.0..=1.0).contains(&a.t) {
        bail!("--t {}: the time must be between 0 and 1", a.t);
    }
    let shape = load(&a.model, &params(&a.common.params)?)?;
    let spec = MappingSpec::read(&a.mapping).context("cannot read the mapping specification")?;
    let pb = progress::bar(0);
    let mapped = spec
        .apply_with(
            &shape,
            &SpecContext::of_file(&a.mapping),
            &progress::Bar(&pb),
        )
        .with_context(|| format!("{}", a.mapping.display()))?;
    pb.finish_and_clear();
    let n = spec.mappings.len();
    for (i, m) in mapped.motions().iter().enumerate() {
        let (before, after) = m.mean_penetration();
        say!(
            "collision-free motion {}: mean interpenetration over {} keyframes {} → {} (volume)",
            i + 1,
            m.penetration().0.len(),
            volmorph_io::fmt_f64(before),
            volmorph_io::fmt_f64(after)
        );
    }
    let at = |t: f64| -> anyhow::Result<Tape> {
        Ok(Tape::new(
            &mapped
                .shape_at(t)
                .with_context(|| format!("{}", a.mapping.display()))?,
        ))
    };
    if let Some(frames) = a.frames {
        if !mapped.time_dependent() {
            say!("note: no mapping has a schedule, so every frame is the same");
        }
        let cam = camera(&a.view, b)?;
        let field_at = |t: f64| -> Result<Box<dyn Field>, volmorph_frep::FrepError> {
            Ok(Box::new(Tape::new(&mapped.shape_at(t)?)))
        };
        let line = write_frames(
            frames,
            &field_at,
            &cam,
            &render_options(b),
            &a.output,
            a.delay,
        )?;
        say!("{n} mappings over t = 0 … 1: {line}");
        return Ok(());
    }
    if AnimationFormat::from_path(&a.output).is_some() && Output::of(&a.output) != Output::Picture {
        bail!(
            "{}: an animation needs --frames N (or write a .png picture of one time with --t)",
            a.output.display()
        );
    }
    let tape = at(a.t)?;
    let settings = OutputSettings {
        bounds: b,
        grid: a.grid,
        method: a.method,
        close: a.close,
        ascii: a.ascii,
        view: &a.view,
    };
    let line = write_output(&tape, &a.output, &settings)?;
    say!(
        "{n} mappings{}, {} operations: {line}",
        if mapped.time_dependent() {
            format!(" at t = {}", a.t)
        } else {
            String::new()
        },
        tape.len()
    );
    Ok(())
}

/// Read surface points: a point list by extension, or the vertices of a mesh file.
fn read_points(path: &Path) -> anyhow::Result<Vec<DVec3>> {
    if meshio::MeshFormat::from_path(path).is_ok() {
        let m = meshio::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        return Ok(m.positions().to_vec());
    }
    volmorph_handles::handles::read_point_list(path)
        .with_context(|| format!("cannot read points {}", path.display()))
}

fn points_cmd(a: &PointsArgs) -> anyhow::Result<()> {
    let pts = read_points(&a.input)?;
    let pb = progress::spinner(format!("fitting {} points", pts.len()));
    let surface = PointSurface::fit(&pts, a.smoothing)
        .with_context(|| format!("cannot reconstruct a solid from {}", a.input.display()))?;
    pb.finish_and_clear();
    let b = match &a.bounds {
        Some(s) => bounds(s)?,
        None => surface.bounds,
    };
    let worst = surface.largest_residual(&pts);
    let tape = Tape::new(&surface.shape);
    let settings = OutputSettings {
        bounds: b,
        grid: a.grid,
        method: a.method,
        close: true,
        ascii: a.ascii,
        view: &a.view,
    };
    let line = write_output(&tape, &a.output, &settings)?;
    say!(
        "{} points (largest |f| at a point {:.1e}): {line}",
        pts.len(),
        worst
    );
    Ok(())
}
