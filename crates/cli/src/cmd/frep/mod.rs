//! `volmorph frep …`: F-rep models written in the HyperFun language — sample them to
//! volumes, mesh them, ray-cast pictures of them, animate the metamorphosis of one into
//! another, apply mapping specifications to them, and reconstruct solids from cross-sections
//! and scattered points.

mod args;

use std::collections::HashMap;
use std::path::Path;

use anyhow::{Context, bail};
use glam::DVec3;
use volmorph_frep::export::{
    ExportOptions, MAX_GRID, OutputKind, Written, export_with, write_frames_with, write_mesh_with,
    write_picture_with, write_volume_with,
};
use volmorph_frep::extent::Framing;
use volmorph_frep::grid::{box_geometry, isotropic_box_geometry};
use volmorph_frep::mapping::{Schedule, morph};
use volmorph_frep::output::{MeshOptions, RenderOptions};
use volmorph_frep::reconstruct::{PointSurface, SectionBlend, SectionStack, femur_sections};
use volmorph_frep::spec::{MappingSpec, SpecContext};
use volmorph_frep::{CompileOptions, Field, Shape, Tape, compile_file};
use volmorph_mesh as meshio;
use volmorph_render::{AnimationFormat, Camera};

pub use self::args::{
    Blend, Command, Common, EvalArgs, MapArgs, MeshArgs, Method, MorphArgs, PointsArgs, RenderArgs,
    SectionsArgs, View,
};
use crate::progress;

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

/// The box of `--bounds`, or else the one that frames the solids of `fields`
/// ([`Framing::of`]), printing its warning when it has one.
fn frame(common: &Common, fields: &[&dyn Field]) -> anyhow::Result<(DVec3, DVec3)> {
    match &common.bounds {
        Some(s) => bounds(s),
        None => Ok(framed(Framing::of(fields))),
    }
}

/// The box of a framing, its warning printed.
fn framed(f: Framing) -> (DVec3, DVec3) {
    if let Some(w) = &f.warning {
        eprintln!("volmorph: warning: {w}");
    }
    f.bounds
}

/// Print the warning of an output that shows nothing of the model ([`Written::empty_warning`]).
fn warn_if_empty(written: &Written, b: (DVec3, DVec3)) {
    if let Some(w) = written.empty_warning(b) {
        eprintln!("volmorph: warning: {w}");
    }
}

fn grid_geometry(n: usize, bounds: (DVec3, DVec3)) -> anyhow::Result<volmorph_volume::Geometry> {
    if !(2..=MAX_GRID).contains(&n) {
        bail!("--grid {n}: must be between 2 and {MAX_GRID}");
    }
    Ok(box_geometry(bounds.0, bounds.1, [n; 3])?)
}

fn eval(a: &EvalArgs) -> anyhow::Result<()> {
    volmorph_volume_io::check_output(&a.output)?;
    let shape = load(&a.model, &params(&a.common.params)?)?;
    let tape = Tape::new(&shape);
    let b = frame(&a.common, &[&tape])?;
    let g = grid_geometry(a.grid, b)?;
    let summary = progress::with_bar(|p| write_volume_with(&tape, &g, &a.output, p))?;
    warn_if_empty(&Written::Volume(summary), b);
    say!(
        "{} operations, {}³ samples in {:.1} ms, {}",
        tape.len(),
        a.grid,
        summary.elapsed.as_secs_f64() * 1e3,
        summary.inside_text()
    );
    Ok(())
}

fn mesh_cmd(a: &MeshArgs) -> anyhow::Result<()> {
    meshio::format::check_output(&a.output)?;
    let shape = load(&a.model, &params(&a.common.params)?)?;
    let tape = Tape::new(&shape);
    let b = frame(&a.common, &[&tape])?;
    let g = grid_geometry(a.grid, b)?;
    let options = MeshOptions {
        method: a.method.into(),
        close: a.close,
    };
    let summary =
        progress::with_bar(|p| write_mesh_with(&tape, &g, &options, &a.output, a.ascii, p))?;
    say!("{summary}");
    warn_if_empty(
        &Written::Mesh {
            dims: g.dims,
            surface: summary,
        },
        b,
    );
    Ok(())
}

fn sections_cmd(a: &SectionsArgs) -> anyhow::Result<()> {
    // A mesh, or else the sampled function as a volume.
    if OutputKind::of(&a.output) != OutputKind::Mesh {
        volmorph_volume_io::check_output(&a.output)?;
    }
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
    if OutputKind::of(&a.output) == OutputKind::Mesh {
        let options = MeshOptions {
            method: a.method.into(),
            close: true,
        };
        let summary =
            progress::with_bar(|p| write_mesh_with(&stack, &g, &options, &a.output, a.ascii, p))
                .with_context(|| format!("cannot reconstruct {name}"))?;
        say!(
            "{} sections, {}×{}×{} grid: {summary}",
            stack.heights().len(),
            dims[0],
            dims[1],
            dims[2],
        );
    } else {
        progress::with_bar(|p| write_volume_with(&stack, &g, &a.output, p))
            .with_context(|| format!("cannot sample {name}"))?;
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

/// The export options of `--view/--size`, `--grid`, `--method`, `--close` and `--ascii`
/// over the box `b`.
fn export_options(
    view: &View,
    b: (DVec3, DVec3),
    grid: usize,
    method: Method,
    close: bool,
    ascii: bool,
) -> anyhow::Result<ExportOptions> {
    Ok(ExportOptions {
        bounds: b,
        grid,
        mesh: MeshOptions {
            method: method.into(),
            close,
        },
        ascii,
        camera: camera(view, b)?,
        render: render_options(b),
    })
}

fn render_cmd(a: &RenderArgs) -> anyhow::Result<()> {
    volmorph_render::check_png(&a.output)?;
    let shape = load(&a.model, &params(&a.common.params)?)?;
    let tape = Tape::new(&shape);
    let b = frame(&a.common, &[&tape])?;
    let cam = camera(&a.view, b)?;
    let options = render_options(b);
    let (_, summary) =
        progress::with_bar(|p| write_picture_with(&tape, &cam, &options, &a.output, p))?;
    say!("{summary}");
    warn_if_empty(&Written::Picture(summary), b);
    Ok(())
}

fn morph_cmd(a: &MorphArgs) -> anyhow::Result<()> {
    volmorph_render::check_animation_output(&a.output)?;
    let schedule = Schedule::parse(&a.schedule).context("--schedule")?;
    let p = params(&a.common.params)?;
    let f = load(&a.from, &p)?;
    let g = load(&a.to, &p)?;
    // (1 − h) f + h g ≥ 0 needs f ≥ 0 or g ≥ 0: the box of both frames every frame.
    let b = frame(&a.common, &[&Tape::new(&f), &Tape::new(&g)])?;
    let cam = camera(&a.view, b)?;
    let field_at = |t: f64| -> Result<Box<dyn Field>, volmorph_frep::FrepError> {
        Ok(Box::new(Tape::new(&morph(&f, &g, t, schedule))))
    };
    let options = render_options(b);
    let line = progress::with_bar(|p| {
        write_frames_with(a.frames, &field_at, &cam, &options, &a.output, a.delay, p)
    })?;
    say!("{line}");
    Ok(())
}

fn map_cmd(a: &MapArgs) -> anyhow::Result<()> {
    // The output before the model: an animation with --frames, else one file by extension.
    if a.frames.is_some() {
        volmorph_render::check_animation_output(&a.output)?;
    } else if AnimationFormat::from_path(&a.output).is_some()
        && OutputKind::of(&a.output) != OutputKind::Picture
    {
        bail!(
            "{}: an animation needs --frames N (or write a .png picture of one time with --t)",
            a.output.display()
        );
    } else {
        OutputKind::for_output(&a.output)?;
    }
    let explicit = a.common.bounds.as_deref().map(bounds).transpose()?;
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
        let field_at = |t: f64| -> Result<Box<dyn Field>, volmorph_frep::FrepError> {
            Ok(Box::new(Tape::new(&mapped.shape_at(t)?)))
        };
        let b = match explicit {
            Some(b) => b,
            None => framed(
                Framing::over_time(frames, &field_at)
                    .with_context(|| format!("{}", a.mapping.display()))?,
            ),
        };
        let cam = camera(&a.view, b)?;
        let options = render_options(b);
        let line = progress::with_bar(|p| {
            write_frames_with(frames, &field_at, &cam, &options, &a.output, a.delay, p)
        })?;
        say!("{n} mappings over t = 0 … 1: {line}");
        return Ok(());
    }
    let tape = at(a.t)?;
    let b = explicit.unwrap_or_else(|| framed(Framing::of(&[&tape])));
    let options = export_options(&a.view, b, a.grid, a.method, a.close, a.ascii)?;
    let line = progress::with_bar(|p| export_with(&tape, &a.output, &options, p))?;
    warn_if_empty(&line, b);
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
    OutputKind::for_output(&a.output)?;
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
    let options = export_options(&a.view, b, a.grid, a.method, true, a.ascii)?;
    let line = progress::with_bar(|p| export_with(&tape, &a.output, &options, p))?;
    warn_if_empty(&line, b);
    say!(
        "{} points (largest |f| at a point {:.1e}): {line}",
        pts.len(),
        worst
    );
    Ok(())
}
