//! `volmorph nurbs`: trivariate NURBS volumes carrying attributes (Martin & Cohen) — fit a
//! sampled volume, evaluate points and derivatives, extract planar slices and isosurfaces as
//! coloured meshes, and ray trace (volume rendering, optical paths; in [`nurbs_trace`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use volmorph_render::Colormap;
use volmorph_trivariate::{
    AggregateVolume, Coloring, PolygonizeOptions, ZeroSetMesh,
    fit::{SampledFitKind, fit_sampled_volume_with},
    isosurface_with, load_volume, save, slice_with,
};
use volmorph_volume_io as format;

use crate::cmd::nurbs_trace;
use crate::progress;

/// Trivariate NURBS subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Fit a sampled volume as an attribute over a geometry volume and write the JSON model.
    #[command(
        after_help = "Examples:\n  volmorph nurbs fit ct.nii.gz -o ct.json --order 4\n  volmorph nurbs fit ct.nii.gz -o ct.json --control-points 16 --name density\n\nParameters run over [0,1]^3; the geometry's corners are the corner voxel centres.\nDefault (one control point per sample): the attribute, on clamped uniform knots, interpolates\nevery voxel at the Greville abscissae xi_i = (t_{i+1}+...+t_{i+p})/p (cubic: 0, h/3, h, 2h, ...,\n1-h/3, 1 with h = 1/(n-3)), and the geometry is a spline on the same knots taking\n(xi_i, xi_j, xi_k) to the centre of voxel (i,j,k). With fewer control points on some axis the\ngeometry is the trilinear box, voxel (i,j,k) at parameters (i,j,k)/(dims-1), and the attribute\nis the least-squares fit over the voxel centres on knots averaged from uniform control-point\nparameters (The NURBS Book, eq. 9.8): well conditioned for every count up to the samples."
    )]
    Fit(FitArgs),
    /// Print the point, its partial derivatives and every attribute at parameters (u, v, w).
    #[command(
        after_help = "Example:\n  volmorph nurbs eval ct.json --at 0.5,0.5,0.5 --at 0,0,1 --json"
    )]
    Eval(EvalArgs),
    /// Mesh the region of a plane inside the volume, coloured by an attribute.
    #[command(
        after_help = "Example:\n  volmorph nurbs slice ct.json --plane 1,0,0,-10 --attribute density -o cut.ply --colormap viridis\n\nThe plane is {x : a*x + b*y + c*z + d = 0}. PLY vertices carry double x y z u v w, the\nattribute as float and uchar red green blue; --per-polygon colours each triangle by its\naverage value (PLY face properties). OBJ gets `v x y z r g b` lines."
    )]
    Slice(SliceArgs),
    /// Mesh the isosurface A = level of a scalar attribute.
    #[command(
        after_help = "Example:\n  volmorph nurbs isosurface ct.json --attribute density --level 0.5 -o skin.ply --tolerance 0.01"
    )]
    Isosurface(IsosurfaceArgs),
    /// Volume-render an attribute of a trivariate model by ray tracing (front-to-back
    /// compositing through a transfer function).
    #[command(
        after_help = "Examples:\n  volmorph nurbs render lens.json --attribute eta -o lens.png\n  volmorph nurbs render part.json --attribute density --transfer '0:0,0,1,0;1:1,1,0,0.8' --view 30,20 --size 512x512 -o part.png\n  volmorph nurbs render lens.json --add part.json --attribute eta --attribute density --transfer auto --transfer '0:0,0,1,0;1:1,1,0,0.8' -o scene.png\n\nSeveral models (--add) share one picture: each ray is walked through every volume and the\nsamples are composited front to back by depth (Martin & Cohen §5.4). --attribute and\n--transfer are given once for all models or once per model, in the order of the models."
    )]
    Render(nurbs_trace::RenderArgs),
    /// Trace light rays bent by a refractive-index attribute (gradient-index optics) and draw
    /// their paths.
    #[command(
        after_help = "Examples:\n  volmorph nurbs trace-optics --example grin-lens --rays 11 -o grin.png --paths grin.obj\n  volmorph nurbs trace-optics --example grin-lens --method rk45 --step 0.05 --tolerance 1e-10 -o grin.png\n  volmorph nurbs trace-optics --example grin-lens --method ray-equation --step 0.002 -o grin_euler.png\n  volmorph nurbs trace-optics lens.json --attribute eta --direction 0,0,1 -o rays.png\n\nThe grin-lens example also traces a probe ray at 0.02 of the radius and prints its back focal\ndistance against the exact trace (the meridional ray ODE in z, integrated by RK4 with\nRichardson extrapolation) and the paraxial formula."
    )]
    TraceOptics(nurbs_trace::TraceOpticsArgs),
    /// Write a built-in trivariate model (or the recipe that builds it) as JSON.
    #[command(
        after_help = "Examples:\n  volmorph nurbs example grin-lens -o lens.json\n  volmorph nurbs example grin-lens-recipe -o lens_recipe.json\n  volmorph nurbs model lens_recipe.json -o lens2.json   # the same model as lens.json"
    )]
    Example(nurbs_trace::ExampleArgs),
    /// Build a model from a modeling recipe: curves, attributes, and the §3 operators
    /// (extrude, revolve, rule, attribute edits) as versioned JSON.
    #[command(
        after_help = "Example:\n  volmorph nurbs model lens_recipe.json -o lens.json\n\nA recipe (see the README, \"Modeling recipes\"):\n  {\"format\": \"volmorph-nurbs-recipe\", \"version\": 1, \"result\": \"lens\", \"steps\": [\n    {\"curve\":   {\"name\": \"profile\", \"degree\": 1, \"points\": [[0,0,0], [1,0,0]]}},\n    {\"attach\":  {\"name\": \"graded\", \"to\": \"profile\", \"attribute\": \"eta\",\n                 \"spline\": {\"degree\": 2, \"values\": [1.5, 1.5, 1.125]}}},\n    {\"revolve\": {\"name\": \"disk\", \"of\": \"graded\", \"axis_point\": [0,0,0],\n                 \"axis_direction\": [0,0,1], \"angle_degrees\": 360}},\n    {\"extrude\": {\"name\": \"lens\", \"of\": \"disk\", \"direction\": [0,0,1]}}]}\nOperators: curve, model, attach, set_attribute, remove_attribute, extrude, revolve, rule.\nErrors name the file and the JSON path of the field, e.g. steps[2].revolve.angle_degrees."
    )]
    Model(nurbs_trace::ModelArgs),
}

/// Arguments of `volmorph nurbs fit`.
#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// Input volume (any format volmorph reads).
    pub input: PathBuf,
    /// Output model (volmorph trivariate JSON).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Order k (degree k − 1) of the attribute spline on every axis.
    #[arg(long, default_value_t = 4)]
    pub order: usize,
    /// Control points per axis: `n` or `nx,ny,nz`; default the sample grid (interpolation).
    #[arg(long)]
    pub control_points: Option<String>,
    /// Name of the fitted attribute.
    #[arg(long, default_value = "value")]
    pub name: String,
}

/// Arguments of `volmorph nurbs eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Model (volmorph trivariate JSON).
    pub model: PathBuf,
    /// Parameters `u,v,w` in [0, 1]³ (repeatable).
    #[arg(long = "at", required = true)]
    pub at: Vec<String>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Colour and tolerance options shared by `slice` and `isosurface`.
#[derive(Debug, Clone, clap::Args)]
pub struct MeshOptions {
    /// Output mesh (.ply or .obj).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Flatness tolerance in physical length units (default: --relative-tolerance times the
    /// geometry's bounding-box diagonal).
    #[arg(long, allow_hyphen_values = true)]
    pub tolerance: Option<f64>,
    /// Flatness tolerance relative to the bounding-box diagonal.
    #[arg(
        long,
        allow_hyphen_values = true,
        default_value_t = volmorph_trivariate::isosurface::DEFAULT_RELATIVE_TOLERANCE
    )]
    pub relative_tolerance: f64,
    /// Colour map (grey, hot, viridis, turbo, cool-warm).
    #[arg(long, default_value = "viridis")]
    pub colormap: String,
    /// Attribute range `lo,hi` mapped onto the colour map (default: the values' range).
    #[arg(long, allow_hyphen_values = true)]
    pub range: Option<String>,
    /// Colour each triangle by its average value instead of each vertex (PLY only).
    #[arg(long)]
    pub per_polygon: bool,
}

/// Arguments of `volmorph nurbs slice`.
#[derive(Debug, clap::Args)]
pub struct SliceArgs {
    /// Model (volmorph trivariate JSON).
    pub model: PathBuf,
    /// Plane `a,b,c,d`: the points x with a·x + b·y + c·z + d = 0.
    #[arg(long, allow_hyphen_values = true)]
    pub plane: String,
    /// Scalar attribute colouring the slice (none: geometry only).
    #[arg(long)]
    pub attribute: Option<String>,
    /// Output and colouring.
    #[command(flatten)]
    pub mesh: MeshOptions,
}

/// Arguments of `volmorph nurbs isosurface`.
#[derive(Debug, clap::Args)]
pub struct IsosurfaceArgs {
    /// Model (volmorph trivariate JSON).
    pub model: PathBuf,
    /// Scalar attribute whose level set is meshed.
    #[arg(long)]
    pub attribute: String,
    /// Level A* of the surface.
    #[arg(long, allow_hyphen_values = true)]
    pub level: f64,
    /// Colour the surface by this scalar attribute (default: no colours).
    #[arg(long)]
    pub color_by: Option<String>,
    /// The object is where the attribute is at or below the level (signed distances, negative
    /// inside); by default it is where it is at or above it (densities, CT). Triangles face
    /// out of the object.
    #[arg(long)]
    pub inside_below: bool,
    /// Output and colouring.
    #[command(flatten)]
    pub mesh: MeshOptions,
}

/// Run a `volmorph nurbs` subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Fit(a) => fit_cmd(a),
        Command::Eval(a) => eval_cmd(a),
        Command::Slice(a) => slice_cmd(a),
        Command::Isosurface(a) => isosurface_cmd(a),
        Command::Render(a) => nurbs_trace::run_render(a),
        Command::TraceOptics(a) => nurbs_trace::run_trace_optics(a),
        Command::Example(a) => nurbs_trace::run_example(a),
        Command::Model(a) => nurbs_trace::run_model(a),
    }
}

/// Parse `n` or `nx,ny,nz`.
fn counts(s: &str) -> anyhow::Result<[usize; 3]> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let parse = |p: &str| {
        p.parse::<usize>()
            .with_context(|| format!("control-point count {p:?} is not a whole number"))
    };
    match parts.as_slice() {
        [n] => Ok([parse(n)?; 3]),
        [x, y, z] => Ok([parse(x)?, parse(y)?, parse(z)?]),
        _ => bail!("--control-points wants n or nx,ny,nz, got {s:?}"),
    }
}

/// Parse comma-separated finite numbers, exactly `N` of them.
fn numbers<const N: usize>(s: &str, what: &str) -> anyhow::Result<[f64; N]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| {
            p.trim()
                .parse::<f64>()
                .with_context(|| format!("{what}: {p:?} is not a number"))
        })
        .collect::<anyhow::Result<_>>()?;
    let arr: [f64; N] = v
        .try_into()
        .map_err(|v: Vec<f64>| anyhow::anyhow!("{what} needs {N} numbers, got {}", v.len()))?;
    if let Some(x) = arr.iter().find(|x| !x.is_finite()) {
        bail!("{what}: {x} is not finite");
    }
    Ok(arr)
}

fn fit_cmd(args: &FitArgs) -> anyhow::Result<()> {
    volmorph_trivariate::format::check_output(&args.output)?;
    let pb = progress::spinner(format!("reading {}", args.input.display()));
    let vol = format::read(&args.input).context("cannot read the volume")?;
    let dims = vol.geometry().dims;
    let n = match &args.control_points {
        Some(s) => counts(s)?,
        None => dims,
    };
    let fit = fit_sampled_volume_with(
        &vol.to_typed::<f64>(),
        args.order,
        n,
        &args.name,
        &progress::Bar(&pb),
    )
    .with_context(|| format!("cannot fit {}", args.input.display()))?;
    progress::spin(&pb, format!("writing {}", args.output.display()));
    save(&args.output, &fit.model).context("cannot write the model")?;
    pb.finish_and_clear();
    let how = match fit.kind {
        SampledFitKind::Interpolation => "interpolation at the Greville abscissae",
        SampledFitKind::LeastSquares => "least squares over the voxel centres",
    };
    say!(
        "fitted {:?} samples with {}x{}x{} control points of order {} ({how}) -> {}",
        dims,
        n[0],
        n[1],
        n[2],
        args.order,
        args.output.display()
    );
    Ok(())
}

fn load(path: &Path) -> anyhow::Result<AggregateVolume> {
    load_volume(path).with_context(|| format!("cannot load model {}", path.display()))
}

fn eval_cmd(args: &EvalArgs) -> anyhow::Result<()> {
    let model = load(&args.model)?;
    let mut out = Vec::new();
    for s in &args.at {
        let u: [f64; 3] = numbers(s, "--at")?;
        let (p, d) = model
            .geometry()
            .eval_with_gradient(u)
            .with_context(|| format!("cannot evaluate at {s}"))?;
        let mut attrs = serde_json::Map::new();
        for a in model.attributes() {
            let v = a
                .spline()
                .eval(u)
                .with_context(|| format!("cannot evaluate attribute {:?}", a.name()))?;
            attrs.insert(a.name().to_owned(), serde_json::json!(v));
        }
        out.push(serde_json::json!({
            "u": u,
            "point": p,
            "du": &d[0..3],
            "dv": &d[3..6],
            "dw": &d[6..9],
            "attributes": attrs,
        }));
    }
    if args.json {
        say!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        for o in &out {
            say!("u = {}", o["u"]);
            for key in ["point", "du", "dv", "dw"] {
                say!("  {key:<6} {}", o[key]);
            }
            if let Some(m) = o["attributes"].as_object() {
                for (k, v) in m {
                    say!("  {k} = {v}");
                }
            }
        }
    }
    Ok(())
}

fn options(m: &MeshOptions) -> PolygonizeOptions {
    PolygonizeOptions {
        tolerance: m.tolerance,
        relative_tolerance: m.relative_tolerance,
        ..PolygonizeOptions::default()
    }
}

/// Write `z` coloured per the options, and print a summary.
fn write_mesh(z: &ZeroSetMesh, m: &MeshOptions, colour: bool) -> anyhow::Result<()> {
    let colormap: Colormap = m.colormap.parse()?;
    let coloring = match (z.values.is_empty() || !colour, m.per_polygon) {
        (true, false) => Coloring::None,
        (true, true) => {
            bail!("--per-polygon needs an attribute to colour by (--attribute / --color-by)")
        }
        (false, false) => Coloring::PerVertex,
        (false, true) => Coloring::PerPolygon,
    };
    let [lo, hi] = match &m.range {
        Some(r) => {
            let [lo, hi] = numbers::<2>(r, "--range")?;
            if hi <= lo {
                bail!("--range: hi must exceed lo, got {lo},{hi}");
            }
            [lo, hi]
        }
        None => z.value_range().unwrap_or([0.0, 1.0]),
    };
    let span = if hi > lo { hi - lo } else { 1.0 };
    let color = move |v: f64| colormap.map(((v - lo) / span) as f32);
    z.write(&m.output, coloring, &color)
        .with_context(|| format!("cannot write {}", m.output.display()))?;
    let report = z.mesh.validate();
    say!(
        "{} vertices, {} triangles ({} root cells, lattice {}x{}x{}, tolerance {:.3e}){}",
        z.mesh.vertex_count(),
        z.mesh.face_count(),
        z.root_cells,
        z.lattice[0],
        z.lattice[1],
        z.lattice[2],
        z.tolerance,
        if report.is_closed_manifold() {
            ", closed"
        } else {
            ""
        }
    );
    if let (Some(name), Some([vlo, vhi])) = (&z.attribute, z.value_range()) {
        say!("{name} on the mesh: [{vlo}, {vhi}]");
    }
    Ok(())
}

fn slice_cmd(args: &SliceArgs) -> anyhow::Result<()> {
    ZeroSetMesh::check_output(&args.mesh.output)?;
    let plane: [f64; 4] = numbers(&args.plane, "--plane")?;
    let model = load(&args.model)?;
    let pb = progress::spinner("slicing".to_owned());
    let z = slice_with(
        &model,
        plane,
        args.attribute.as_deref(),
        &options(&args.mesh),
        &progress::Bar(&pb),
    )
    .context("cannot slice the model")?;
    pb.finish_and_clear();
    write_mesh(&z, &args.mesh, true)
}

fn isosurface_cmd(args: &IsosurfaceArgs) -> anyhow::Result<()> {
    ZeroSetMesh::check_output(&args.mesh.output)?;
    let model = load(&args.model)?;
    let pb = progress::spinner("extracting the isosurface".to_owned());
    let opts = PolygonizeOptions {
        inside_below: args.inside_below,
        ..options(&args.mesh)
    };
    let mut z = isosurface_with(
        &model,
        &args.attribute,
        args.level,
        &opts,
        &progress::Bar(&pb),
    )
    .context("cannot extract the isosurface")?;
    if let Some(name) = &args.color_by {
        z.report_attribute(&model, name)
            .context("cannot colour the surface")?;
    }
    pb.finish_and_clear();
    write_mesh(&z, &args.mesh, args.color_by.is_some())
}
