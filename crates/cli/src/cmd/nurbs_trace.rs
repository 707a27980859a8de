//! `volmorph nurbs render`, `volmorph nurbs trace-optics` and `volmorph nurbs example`:
//! ray tracing of trivariate NURBS volumes with attributes (Martin & Cohen §5.2–§5.4).

use std::path::PathBuf;

use anyhow::{Context, bail};
use glam::DVec3;
use volmorph_render::{Shading, UpAxis, write_png_rgba};
use volmorph_trivariate::{
    AggregateVolume, GRIN_ATTRIBUTE, GrinLensSpec, OpticsOptions, PathMethod, RayFan, RayTracer,
    RenderOptions, SceneRenderer, TraceOptions, TransferFunction, VolumeRenderer,
    build_recipe_file, check_grin_lens, grin_lens, grin_lens_recipe, load_volume, save, side_view,
    write_paths_obj,
};

use crate::progress;

/// Most rays `trace-optics` accepts.
const MAX_RAYS: usize = 100_000;

/// Arguments of `volmorph nurbs render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Trivariate model (volmorph JSON, a volume with attributes).
    pub model: PathBuf,
    /// More models in the same picture (repeatable): rays are composited front to back
    /// through every volume in depth order (Martin & Cohen §5.4).
    #[arg(long = "add")]
    pub add: Vec<PathBuf>,
    /// Attribute to render (its first component drives the transfer function): once for
    /// every model, or once per model in the order of the models (the positional one first,
    /// then each --add).
    #[arg(long, required = true)]
    pub attribute: Vec<String>,
    /// Transfer function `value:r,g,b,opacity;…` (channels in [0, 1], opacity per unit
    /// length, piecewise linear in the value), or `auto`: viridis over the attribute's range
    /// with opacity rising to 0.9 (the default). Once for every model or once per model, as
    /// --attribute.
    #[arg(long)]
    pub transfer: Vec<String>,
    /// Viewing direction `azimuth,elevation` in degrees (z up: azimuth 0 looks from +x, 90
    /// from +y), or a view name (front, side, top, iso); the camera looks at the model's
    /// centre.
    #[arg(long, default_value = "35,25", allow_hyphen_values = true)]
    pub view: String,
    /// The axis that is up in the picture: z or y.
    #[arg(long, default_value = "z", value_parser = crate::args::up_axis)]
    pub up: UpAxis,
    /// Light the attribute's gradient with the shading model (Blinn–Phong, light from the
    /// upper left of the camera).
    #[arg(long)]
    pub shade: bool,
    /// Picture size `WxH` (or one number for a square).
    #[arg(long, default_value = "256x256")]
    pub size: String,
    /// Step along rays in model units (default: model diagonal / 256).
    #[arg(long)]
    pub step: Option<f64>,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Arguments of `volmorph nurbs trace-optics`.
#[derive(Debug, clap::Args)]
pub struct TraceOpticsArgs {
    /// Trivariate model (volmorph JSON) carrying a refractive index attribute; omit with
    /// `--example`.
    pub model: Option<PathBuf>,
    /// Built-in model instead of a file: `grin-lens`.
    #[arg(long)]
    pub example: Option<String>,
    /// Number of parallel rays, spread over the lens aperture (or the model's box).
    #[arg(long, default_value_t = 11)]
    pub rays: usize,
    /// Refractive index attribute.
    #[arg(long, default_value = GRIN_ATTRIBUTE)]
    pub attribute: String,
    /// Ray direction `x,y,z` for models from files (rays start before the model's box).
    #[arg(long, default_value = "0,0,1", allow_hyphen_values = true)]
    pub direction: String,
    /// Picture size `WxH` (or one number for a square).
    #[arg(long, default_value = "800x500")]
    pub size: String,
    /// Output PNG (side view of the paths).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write the paths as OBJ polylines.
    #[arg(long)]
    pub paths: Option<PathBuf>,
    /// How rays are followed inside: `rk45` (the ray equation d/ds(η dr/ds) = ∇η integrated
    /// by Dormand–Prince 5(4) with error control), `ray-equation` (Snell's construction with
    /// the index the ray equation implies, first order) or `snell` (the paper's literal
    /// stepping, first order).
    #[arg(long, default_value = "rk45", value_parser = path_method)]
    pub method: PathMethod,
    /// Largest step in model units (the stepwise methods' step where the index is nearly
    /// uniform; the cap of rk45's adaptive steps). Default: model diagonal / 400.
    #[arg(long)]
    pub step: Option<f64>,
    /// Local error tolerance of rk45 (relative to the model diagonal for positions and to
    /// the index for the optical momentum).
    #[arg(long, default_value_t = volmorph_trivariate::optics::DEFAULT_TOLERANCE)]
    pub tolerance: f64,
}

fn path_method(s: &str) -> Result<PathMethod, String> {
    PathMethod::parse(s).map_err(|e| e.to_string())
}

/// Arguments of `volmorph nurbs example`.
#[derive(Debug, clap::Args)]
pub struct ExampleArgs {
    /// Which model: `grin-lens` (the model), or `grin-lens-recipe` (the modeling recipe that
    /// builds it, for `volmorph nurbs model`).
    pub name: String,
    /// Output JSON.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Arguments of `volmorph nurbs model`.
#[derive(Debug, clap::Args)]
pub struct ModelArgs {
    /// Modeling recipe (volmorph-nurbs-recipe JSON; see the README).
    pub recipe: PathBuf,
    /// Output model (volmorph trivariate JSON).
    #[arg(short, long)]
    pub output: PathBuf,
}

fn load(path: &std::path::Path) -> anyhow::Result<AggregateVolume> {
    load_volume(path).with_context(|| format!("cannot read model {}", path.display()))
}

fn bounds(tracer: &RayTracer) -> (DVec3, DVec3) {
    let (lo, hi) = tracer.bounds();
    (DVec3::from_array(lo), DVec3::from_array(hi))
}

/// The `i`-th of `values` given once for all `n` models or once per model.
fn per_model<'a>(
    values: &'a [String],
    i: usize,
    n: usize,
    what: &str,
) -> anyhow::Result<Option<&'a str>> {
    match values.len() {
        0 => Ok(None),
        1 => Ok(Some(&values[0])),
        k if k == n => Ok(Some(&values[i])),
        k => bail!("{what} given {k} times for {n} models: give it once, or once per model"),
    }
}

/// `volmorph nurbs render`.
///
/// # Errors
/// Unreadable model, unknown attribute, bad transfer function, view or size, attribute or
/// transfer lists that do not match the models, or an unwritable output.
pub fn run_render(a: &RenderArgs) -> anyhow::Result<()> {
    volmorph_render::check_png(&a.output)?;
    let (w, h) = crate::args::size(&a.size).context("--size")?;
    if let Some(step) = a.step
        && !(step.is_finite() && step > 0.0)
    {
        bail!("--step {step}: must be finite and > 0");
    }
    let paths: Vec<&PathBuf> = std::iter::once(&a.model).chain(&a.add).collect();
    let n = paths.len();
    let models = paths
        .iter()
        .map(|p| load(p))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let tracers = paths
        .iter()
        .zip(&models)
        .map(|(p, m)| {
            RayTracer::new(m, TraceOptions::default())
                .with_context(|| format!("cannot prepare model {}", p.display()))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut parts = Vec::with_capacity(n);
    let mut names = Vec::with_capacity(n);
    for (i, ((path, model), tracer)) in paths.iter().zip(&models).zip(&tracers).enumerate() {
        let attribute =
            per_model(&a.attribute, i, n, "--attribute")?.context("--attribute is required")?;
        let transfer = match per_model(&a.transfer, i, n, "--transfer")? {
            None | Some("auto") => TransferFunction::for_attribute(model, attribute)
                .with_context(|| format!("{}", path.display()))?,
            Some(t) => TransferFunction::parse(t).context("--transfer")?,
        };
        let mut options = RenderOptions::for_diagonal(tracer.diagonal());
        if let Some(step) = a.step {
            options.step = step;
        }
        if a.shade {
            options.shading = Some(Shading::default());
        }
        parts.push(
            VolumeRenderer::new(model, tracer, attribute, transfer, options)
                .with_context(|| format!("{}", path.display()))?,
        );
        names.push(format!(
            "{} ({attribute:?}, step {:.4})",
            path.display(),
            volmorph_io::Num(options.step)
        ));
    }
    let scene = SceneRenderer::new(parts)?;
    let orbit = crate::args::view(&a.view, a.up).context("--view")?;
    let (lo, hi) = scene.bounds();
    let cam = orbit.model_camera((DVec3::from_array(lo), DVec3::from_array(hi)), (w, h))?;
    let pb = progress::bar(0);
    let t0 = std::time::Instant::now();
    let img = scene
        .render_image_with(&cam, &progress::Bar(&pb))
        .context("cannot render")?;
    pb.finish_and_clear();
    let img = img.composite_over([0, 0, 0, 255]);
    write_png_rgba(&a.output, &img)
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    say!(
        "rendered {} ({w}×{h}) in {:.2} s → {}",
        names.join(" + "),
        t0.elapsed().as_secs_f64(),
        a.output.display()
    );
    Ok(())
}

/// `volmorph nurbs trace-optics`.
///
/// # Errors
/// No model or both a model and `--example`, unknown example or attribute, bad ray count,
/// direction or size, tracing errors, or unwritable outputs.
pub fn run_trace_optics(a: &TraceOpticsArgs) -> anyhow::Result<()> {
    volmorph_render::check_png(&a.output)?;
    if let Some(p) = &a.paths {
        volmorph_io::extension::check(p, volmorph_trivariate::optics::PATHS_EXTENSIONS)?;
    }
    if a.rays == 0 || a.rays > MAX_RAYS {
        bail!("--rays {}: must be 1 to {MAX_RAYS}", a.rays);
    }
    let (w, h) = crate::args::size(&a.size).context("--size")?;
    let spec = GrinLensSpec::default();
    let (model, example) = match (&a.model, a.example.as_deref()) {
        (Some(_), Some(_)) => bail!("give either a model file or --example, not both"),
        (None, None) => bail!("give a model file or --example grin-lens"),
        (Some(p), None) => (load(p)?, false),
        (None, Some("grin-lens")) => (grin_lens(&spec)?, true),
        (None, Some(other)) => bail!("--example {other:?}: the built-in example is grin-lens"),
    };
    if model.attribute(&a.attribute).is_none() {
        bail!("model has no attribute {:?}", a.attribute);
    }
    let tracer = RayTracer::new(&model, TraceOptions::default()).context("cannot prepare model")?;
    let mut opts = OpticsOptions::for_diagonal(tracer.diagonal());
    opts.method = a.method;
    if let Some(step) = a.step {
        if !(step.is_finite() && step > 0.0) {
            bail!("--step {step}: must be finite and > 0");
        }
        opts.max_step = step;
        opts.min_step = opts.min_step.min(step);
    }
    if !(a.tolerance.is_finite() && a.tolerance > 0.0) {
        bail!("--tolerance {}: must be finite and > 0", a.tolerance);
    }
    opts.tolerance = a.tolerance;
    let fan = if example {
        RayFan::grin_meridian(&spec, a.rays)?
    } else {
        let d: [f64; 3] = crate::args::triple(&a.direction).context("--direction")?;
        RayFan::across(bounds(&tracer), DVec3::from_array(d), a.rays)
            .with_context(|| format!("--direction {}", a.direction))?
    };
    let pb = progress::spinner(format!("tracing {} rays", fan.starts.len()));
    let paths = fan
        .trace(&model, &tracer, &a.attribute, &opts)
        .context("cannot trace rays")?;
    pb.finish_and_clear();
    let img = side_view(&paths, bounds(&tracer), &fan, (w, h))?;
    write_png_rgba(&a.output, &img)
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    if let Some(p) = &a.paths {
        write_paths_obj(p, &paths).with_context(|| format!("cannot write {}", p.display()))?;
    }
    let steps: usize = paths.iter().map(|p| p.steps).sum();
    let rejected: usize = paths.iter().map(|p| p.rejected_steps).sum();
    let control = match opts.method {
        PathMethod::Rk45 => format!(
            "tolerance {:e}, steps ≤ {:.5}: {steps} steps ({rejected} rejected)",
            opts.tolerance,
            volmorph_io::Num(opts.max_step)
        ),
        _ => format!(
            "step ≤ {:.5}: {steps} steps",
            volmorph_io::Num(opts.max_step)
        ),
    };
    say!(
        "traced {} rays through {:?} by {} ({control}) → {}",
        paths.len(),
        a.attribute,
        opts.method.name(),
        a.output.display()
    );
    if example {
        let check = check_grin_lens(&model, &tracer, &a.attribute, &spec, &opts)
            .context("cannot trace the paraxial probe ray")?;
        say!("{check}");
    }
    Ok(())
}

/// `volmorph nurbs example`.
///
/// # Errors
/// Unknown example name or an unwritable output.
pub fn run_example(a: &ExampleArgs) -> anyhow::Result<()> {
    // A model or a recipe: JSON either way.
    volmorph_trivariate::format::check_output(&a.output)?;
    let spec = GrinLensSpec::default();
    match a.name.as_str() {
        "grin-lens" => save(&a.output, &grin_lens(&spec)?),
        "grin-lens-recipe" => {
            let text = grin_lens_recipe(&spec)?.to_json_string()?;
            volmorph_io::write_atomic(&a.output, |w| {
                std::io::Write::write_all(w, text.as_bytes())
                    .map_err(|e| volmorph_io::IoError::os(&a.output, e))
            })
            .map_err(volmorph_trivariate::TrivariateError::from)
        }
        other => {
            bail!("unknown example {other:?}: the built-in examples are grin-lens and grin-lens-recipe")
        }
    }
    .with_context(|| format!("cannot write {}", a.output.display()))?;
    say!("wrote {} → {}", a.name, a.output.display());
    Ok(())
}

/// `volmorph nurbs model`.
///
/// # Errors
/// An unreadable or invalid recipe (the message names the file and the JSON path of the
/// field), or an unwritable output.
pub fn run_model(a: &ModelArgs) -> anyhow::Result<()> {
    volmorph_trivariate::format::check_output(&a.output)?;
    let pb = crate::progress::spinner(format!("building {}", a.recipe.display()));
    let model = build_recipe_file(&a.recipe)?;
    pb.finish_and_clear();
    model
        .save(&a.output)
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    let attributes: Vec<String> = model
        .attribute_names()
        .iter()
        .map(|n| format!("{n:?}"))
        .collect();
    say!(
        "built a {} with attributes [{}] from {} → {}",
        model.kind(),
        attributes.join(", "),
        a.recipe.display(),
        a.output.display()
    );
    Ok(())
}
