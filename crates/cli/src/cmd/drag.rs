//! `volmorph drag`: direct manipulation of a volume (True 1992 §6, after Hsu), as one scene
//! session: the volume, its lattice and the warped result are scene objects, the drag is the
//! scene's drag command (least-norm control-point moves, incremental warp update), and the
//! outputs are the scene's exports — exactly what the studio and Python do.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_lattice::{BSplineLattice, DragOptions, Realm, ToolShape, curve_drag_steps};
use volmorph_maps::{AnyMap, read_map};
use volmorph_scene::{Command, NewObject, Recipe, Scene, files};
use volmorph_warp::apply::WarpMethod;
use volmorph_warp::jacobian::FoldingReport;

use super::warp::{GridArgs, METHOD_HELP, method};
use crate::{args, progress};

/// Arguments of `volmorph drag`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume: the undeformed model.
    pub input: PathBuf,
    /// A point of the model as currently deformed (physical coordinates "x,y,z"); repeat
    /// `--from`/`--to` pairs to drag several points at once.
    #[arg(long = "from", required_unless_present = "start_curve", conflicts_with = "start_curve", value_parser = args::point, allow_hyphen_values = true)]
    pub from: Vec<DVec3>,
    /// Where that point must go ("x,y,z"), one per `--from`.
    #[arg(long = "to", required_unless_present = "start_curve", value_parser = args::point, allow_hyphen_values = true)]
    pub to: Vec<DVec3>,
    /// Drag along curves (True 1992 §6.3): the start curve "x,y,z;x,y,z;…" on the model as
    /// currently deformed; it moves onto --goal-curve over --steps constrained drags (both
    /// curves resampled evenly by arc length to the larger point count).
    #[arg(long, requires = "goal_curve", conflicts_with_all = ["from", "to"], value_parser = args::points, allow_hyphen_values = true)]
    pub start_curve: Option<::std::vec::Vec<DVec3>>,
    /// The goal curve "x,y,z;x,y,z;…" of a curve drag.
    #[arg(long, requires = "start_curve", value_parser = args::points, allow_hyphen_values = true)]
    pub goal_curve: Option<::std::vec::Vec<DVec3>>,
    /// Number of drags (frames) of a curve drag.
    #[arg(long, default_value_t = 10, requires = "start_curve")]
    pub steps: usize,
    /// Write the model after every step of a curve drag into this folder as
    /// frame_001.EXT, frame_002.EXT, … (EXT of --output).
    #[arg(long, value_name = "DIR", requires = "start_curve")]
    pub frames: Option<PathBuf>,
    /// Tool radius (physical units): a spherical tool, same as --tool sphere:R.
    #[arg(long, conflicts_with = "tool")]
    pub radius: Option<f64>,
    /// Tool shape (True 1992 §6): only control points inside it, centred on a dragged point
    /// as seen, move: sphere:R, ellipsoid:RX,RY,RZ or box:HX,HY,HZ (half side lengths;
    /// physical units, world axes). Without it, every control point that influences the point
    /// may move.
    #[arg(long, value_name = "SHAPE")]
    pub tool: Option<ToolShape>,
    /// Realm (True 1992 §6): only these control points may move, for every drag:
    /// indices:I0,J0,K0,I1,J1,K1 (control indices, inclusive) or region:X0,Y0,Z0,X1,Y1,Z1
    /// (a physical box of current control-point positions).
    #[arg(long, value_name = "REALM")]
    pub realm: Option<Realm>,
    /// Keep the control points that act on the lattice box's surface in place, so the map
    /// stays continuous across the box surface (needs the dragged points away from it).
    #[arg(long)]
    pub freeze_boundary: bool,
    /// The current deformation of the input (a lattice: .json, .tfm, .bxf), used as a
    /// push-forward map. Default: the identity lattice of `--counts` control points around the
    /// input.
    #[arg(long, conflicts_with = "counts")]
    pub lattice: Option<PathBuf>,
    /// Control points per axis "NX,NY,NZ" of the default identity lattice.
    #[arg(long, default_value = "9,9,9", value_parser = args::triple::<usize>)]
    pub counts: [usize; 3],
    /// Output volume: the input deformed by the new lattice, on the input's grid (or the grid
    /// of --pad, --like, --output-geometry).
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub grid: GridArgs,
    /// Where to write the new lattice (.json, .tfm, .bxf).
    #[arg(long)]
    pub lattice_out: Option<PathBuf>,
    #[doc = "How the model is deformed (see --help)."]
    #[arg(long, default_value = "pushforward-antialiased", value_parser = method, long_help = METHOD_HELP)]
    pub method: WarpMethod,
}

/// Run `volmorph drag`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    volmorph_volume_io::check_output(&a.output)?;
    if let Some(p) = &a.lattice_out {
        volmorph_lattice::formats::check_output(p)?;
    }
    if a.from.len() != a.to.len() {
        bail!(
            "{} --from points but {} --to points: give one target per dragged point",
            a.from.len(),
            a.to.len()
        );
    }
    if !a.method.deforms_model() {
        bail!(
            "--method {} resamples through the lattice itself; a drag deforms the model, so use a \
             push-forward or an inverse method",
            a.method
        );
    }
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    let mut scene = Scene::new();
    let volume = files::read_object(&a.input)
        .with_context(|| format!("cannot read the volume {}", a.input.display()))?;
    let NewObject::Volume(vol) = volume else {
        bail!("{} is not a volume", a.input.display());
    };
    let grid = *vol.geometry();
    let out_grid = a.grid.resolve(&grid)?;
    let lattice = match &a.lattice {
        Some(path) => match read_map(path).context("cannot read the lattice")? {
            AnyMap::Lattice(l) => l,
            other => bail!(
                "{}: a drag needs a B-spline lattice, the file holds a {} map",
                path.display(),
                other.kind()
            ),
        },
        None => BSplineLattice::identity_on_voxels(&grid, a.counts)
            .context("cannot place the identity lattice")?,
    };
    let options = DragOptions {
        tool: a
            .tool
            .or(a.radius.map(|radius| ToolShape::Sphere { radius })),
        freeze_boundary: a.freeze_boundary,
        realm: a.realm,
    };
    options.validate()?;
    // The drags: one step of --from/--to pairs, or the steps of a curve drag.
    let steps: Vec<(Vec<DVec3>, Vec<DVec3>)> = match (&a.start_curve, &a.goal_curve) {
        (Some(start), Some(goal)) => curve_drag_steps(start, goal, a.steps)?
            .into_iter()
            .map(|s| (s.grabbed, s.targets))
            .collect(),
        _ => vec![(a.from.clone(), a.to.clone())],
    };
    let add = |name: &str, object| Command::Add {
        name: name.into(),
        object,
    };
    let v = scene.apply(add("input", NewObject::Volume(vol)))?.added[0];
    let l = scene
        .apply(add("lattice", NewObject::Map(AnyMap::Lattice(lattice))))?
        .added[0];
    pb.set_message("initial warp");
    let mut recipe = Recipe::Warp {
        source: v,
        map: l,
        method: a.method,
        background: 0.0,
        sampled_nodes: None,
        swap_handles: false,
    };
    if out_grid != grid {
        recipe = recipe.onto(&out_grid);
    }
    let w = scene.apply(add("output", NewObject::Derived(recipe)))?;
    if let Some((_, e)) = w.errors.first() {
        bail!("cannot warp {}: {e}", a.input.display());
    }
    let w = w.added[0];
    if let Some(dir) = &a.frames {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the frame folder {}", dir.display()))?;
    }
    let t = Instant::now();
    let mut last = None;
    let bar = progress::Bar(&pb);
    volmorph_io::Progress::start(&bar, "dragging", steps.len() as u64);
    for (n, (grabbed, targets)) in steps.iter().enumerate() {
        let change = scene
            .apply(Command::DragPoints {
                map: l,
                grabbed: grabbed.clone(),
                targets: targets.clone(),
                options,
            })
            .with_context(|| format!("cannot solve drag {} of {}", n + 1, steps.len()))?;
        if let Some((_, e)) = change.errors.first() {
            bail!("cannot warp {}: {e}", a.input.display());
        }
        if let Some(dir) = &a.frames {
            let frame = volmorph_scene::files::frame_path(dir, n + 1, &a.output);
            scene.export(w, &frame).context("cannot write a frame")?;
        }
        last = change.drag;
        volmorph_io::Progress::advance(&bar, 1);
    }
    let elapsed = t.elapsed();
    progress::spin(&pb, format!("writing {}", a.output.display()));
    scene.export(w, &a.output).context("cannot write")?;
    if let Some(path) = &a.lattice_out {
        scene.export(l, path).context("cannot write the lattice")?;
    }
    pb.finish_and_clear();

    let map = scene.map(l)?;
    let (first, end) = (&steps[0].0, &steps[steps.len() - 1].1);
    for (from, to) in first.iter().zip(end) {
        say!("dragged {} -> {}", fmt(*from), fmt(*to));
    }
    if steps.len() > 1 {
        say!(
            "curve drag of {} points in {} steps",
            first.len(),
            steps.len()
        );
    }
    if let Some(d) = last {
        say!(
            "moved {} control points (rank {} of {} drags, largest miss {:.3e}); drag and \
             warp update {:.1} ms",
            d.moved,
            d.rank,
            d.drags,
            d.max_residual,
            elapsed.as_secs_f64() * 1e3
        );
        if d.rank < d.drags {
            eprintln!(
                "volmorph: warning: the drags conflict (rank {} < {}); they are met in the \
                 least-squares sense, largest miss {:.3e}",
                d.rank, d.drags, d.max_residual
            );
        }
    }
    let folding = FoldingReport::of_map(map as &dyn SpaceMap, &grid)?;
    if folding.count_nonpositive > 0 {
        eprintln!("volmorph: warning: the new lattice folds space: {folding}");
    }
    Ok(())
}

/// A point as `(x, y, z)` with four decimals (exponent form past 1e9, through `Num`).
fn fmt(p: DVec3) -> String {
    let n = |v: f64| format!("{:.4}", volmorph_io::Num(v));
    format!("({}, {}, {})", n(p.x), n(p.y), n(p.z))
}
