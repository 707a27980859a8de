//! `volmorph drag`: direct manipulation of a volume (True 1992 §6, after Hsu), as one scene
//! session: the volume, its lattice and the warped result are scene objects, the drag is the
//! scene's drag command (least-norm control-point moves, incremental warp update), and the
//! outputs are the scene's exports — exactly what the studio and Python do.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_lattice::{BSplineLattice, DragOptions};
use volmorph_maps::{AnyMap, read_map};
use volmorph_scene::{Command, NewObject, Recipe, Scene, files};
use volmorph_warp::apply::WarpMethod;
use volmorph_warp::jacobian::FoldingReport;

use super::warp::{METHOD_HELP, method};
use crate::{args, progress};

/// Arguments of `volmorph drag`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume: the undeformed model.
    pub input: PathBuf,
    /// A point of the model as currently deformed (physical coordinates "x,y,z"); repeat
    /// `--from`/`--to` pairs to drag several points at once.
    #[arg(long = "from", required = true, value_parser = args::point, allow_hyphen_values = true)]
    pub from: Vec<DVec3>,
    /// Where that point must go ("x,y,z"), one per `--from`.
    #[arg(long = "to", required = true, value_parser = args::point, allow_hyphen_values = true)]
    pub to: Vec<DVec3>,
    /// Tool radius (physical units): only control points within this distance of a dragged
    /// point move. Without it, every control point that influences the point may move.
    #[arg(long)]
    pub radius: Option<f64>,
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
    /// Output volume: the input deformed by the new lattice, on the input's grid.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Where to write the new lattice (.json, .tfm, .bxf).
    #[arg(long)]
    pub lattice_out: Option<PathBuf>,
    #[doc = "How the model is deformed (see --help)."]
    #[arg(long, default_value = "pushforward-antialiased", value_parser = method, long_help = METHOD_HELP)]
    pub method: WarpMethod,
}

/// Run `volmorph drag`.
pub fn run(a: &Args) -> anyhow::Result<()> {
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
    let add = |name: &str, object| Command::Add {
        name: name.into(),
        object,
    };
    let v = scene.apply(add("input", NewObject::Volume(vol)))?.added[0];
    let l = scene
        .apply(add("lattice", NewObject::Map(AnyMap::Lattice(lattice))))?
        .added[0];
    pb.set_message("initial warp");
    let recipe = Recipe::Warp {
        source: v,
        map: l,
        method: a.method,
        background: 0.0,
        sampled_nodes: None,
        swap_handles: false,
    };
    let w = scene.apply(add("output", NewObject::Derived(recipe)))?;
    if let Some((_, e)) = w.errors.first() {
        bail!("cannot warp {}: {e}", a.input.display());
    }
    let w = w.added[0];
    pb.set_message("dragging");
    let t = Instant::now();
    let change = scene
        .apply(Command::DragPoints {
            map: l,
            grabbed: a.from.clone(),
            targets: a.to.clone(),
            options: DragOptions {
                radius: a.radius,
                freeze_boundary: a.freeze_boundary,
            },
        })
        .context("cannot solve the drag")?;
    let elapsed = t.elapsed();
    if let Some((_, e)) = change.errors.first() {
        bail!("cannot warp {}: {e}", a.input.display());
    }
    pb.set_message(format!("writing {}", a.output.display()));
    scene.export(w, &a.output).context("cannot write")?;
    if let Some(path) = &a.lattice_out {
        scene.export(l, path).context("cannot write the lattice")?;
    }
    pb.finish_and_clear();

    let map = scene.map(l)?;
    for (from, to) in a.from.iter().zip(&a.to) {
        say!("dragged {} -> {}", fmt(*from), fmt(*to));
    }
    if let Some(d) = change.drag {
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

fn fmt(p: DVec3) -> String {
    format!("({:.4}, {:.4}, {:.4})", p.x, p.y, p.z)
}
