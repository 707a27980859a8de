//! `volmorph frep …`: F-rep models written in the HyperFun language — sample them to
//! volumes, mesh them, ray-cast pictures of them, and animate the metamorphosis of one into
//! another.

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
use volmorph_frep::reconstruct::{SectionBlend, SectionStack, femur_sections};
use volmorph_frep::{CompileOptions, Field, Shape, Tape, compile_source};
use volmorph_mesh::{self as meshio, MeshWriteOptions};
use volmorph_render::{AnimationFormat, Camera, write_animation, write_png_rgba};
use volmorph_volume::AnyVolume;
use volmorph_volume_io as format;

pub use self::args::{
    Blend, Command, Common, EvalArgs, MeshArgs, MorphArgs, RenderArgs, SectionsArgs, View,
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
    }
}

/// Parse `--param aN=V` options ([`CompileOptions::parse_param`]).
pub fn params(list: &[String]) -> anyhow::Result<HashMap<usize, f64>> {
    list.iter()
        .map(|p| CompileOptions::parse_param(p).with_context(|| format!("--param {p}")))
        .collect()
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
    let size = crate::args::size(&view.size).context("--size")?;
    let orbit = crate::args::view(&view.view, view.up).context("--view")?;
    Ok(orbit.model_camera(b, size)?)
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
            format.description()
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
