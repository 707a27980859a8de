//! `volmorph drag`: direct manipulation of a volume (True 1992 §6, after Hsu): drag points of
//! the model to new places; the lattice's control points move by the least-norm amounts that
//! put the dragged points exactly where asked, and the volume is warped through the result.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_deform::inverse::{InverseOptions, invert_point};
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::formats::{read_lattice, write_lattice};
use volmorph_lattice::manipulate::{Drag, DragOptions, solve_drags};
use volmorph_volume_io as format;
use volmorph_warp::jacobian::{FoldingReport, jacobian_determinant};

use super::lattice::lattice_around;
use super::warp::{Method, warp};
use crate::{args, progress};

/// Arguments of `volmorph drag`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume: the undeformed model.
    pub input: PathBuf,
    /// A point of the model as currently deformed (physical coordinates "x,y,z"); repeat
    /// `--from`/`--to` pairs to drag several points at once.
    #[arg(long = "from", required = true, value_parser = point, allow_hyphen_values = true)]
    pub from: Vec<DVec3>,
    /// Where that point must go ("x,y,z"), one per `--from`.
    #[arg(long = "to", required = true, value_parser = point, allow_hyphen_values = true)]
    pub to: Vec<DVec3>,
    /// Tool radius (physical units): only control points within this distance of a dragged
    /// point move. Without it, every control point that influences the point may move.
    #[arg(long)]
    pub radius: Option<f64>,
    /// Keep the control points that act on the lattice box's surface in place, so the map
    /// stays continuous across the box surface (needs the dragged points away from it).
    #[arg(long)]
    pub freeze_boundary: bool,
    /// The current deformation of the input (.json, .tfm, .bxf), used as a push-forward map.
    /// Default: the identity lattice of `--counts` control points around the input.
    #[arg(long, conflicts_with = "counts")]
    pub lattice: Option<PathBuf>,
    /// Control points per axis "NX,NY,NZ" of the default identity lattice.
    #[arg(long, default_value = "9,9,9")]
    pub counts: String,
    /// Output volume: the input deformed by the new lattice, on the input's grid.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Where to write the new lattice (.json, .tfm, .bxf).
    #[arg(long)]
    pub lattice_out: Option<PathBuf>,
    /// How the model is deformed into the output (a push-forward, or the pull-back through
    /// the lattice's inverse).
    #[arg(long, value_enum, default_value_t = Method::PushforwardAntialiased)]
    pub method: Method,
}

/// Parse a physical point "x,y,z" with finite coordinates.
fn point(s: &str) -> anyhow::Result<DVec3> {
    let p = DVec3::from_array(args::triple::<f64>(s)?);
    if !p.is_finite() {
        bail!("point {s:?} is not finite");
    }
    Ok(p)
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
    if a.method.is_pullback() {
        bail!(
            "--method {:?} resamples through the lattice itself; a drag deforms the model, so use a push-forward or an inverse method",
            a.method
        );
    }
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    let vol = format::read(&a.input).context("cannot read volume")?;
    let mut lattice = match &a.lattice {
        Some(path) => read_lattice(path).context("cannot read lattice")?,
        None => lattice_around(vol.geometry(), args::triple::<usize>(&a.counts)?)?,
    };
    pb.set_message("solving the drag");
    let t0 = Instant::now();
    let drags = material_points(&lattice, &a.from, &a.to)?;
    let options = DragOptions {
        radius: a.radius,
        freeze_boundary: a.freeze_boundary,
    };
    let solution = solve_drags(&lattice, &drags, &options).context("cannot solve the drag")?;
    solution
        .apply(&mut lattice)
        .context("cannot move the control points")?;
    let solve_time = t0.elapsed();
    pb.set_message("warping");
    let t1 = Instant::now();
    let (out, _) = warp(&vol, &lattice, a.method, 0.0, false, &pb)
        .with_context(|| format!("cannot warp {}", a.input.display()))?;
    let warp_time = t1.elapsed();
    let det = jacobian_determinant(&lattice, vol.geometry())?;
    let folding = FoldingReport::of(det.data());
    pb.set_message(format!("writing {}", a.output.display()));
    format::write(&a.output, &out).context("cannot write")?;
    if let Some(path) = &a.lattice_out {
        write_lattice(path, &lattice).context("cannot write")?;
    }
    pb.finish_and_clear();

    for (d, (from, to)) in drags.iter().zip(a.from.iter().zip(&a.to)) {
        let landed = lattice.apply(d.material);
        say!(
            "dragged {} -> {}: now at {} (off by {:.3e})",
            fmt(*from),
            fmt(*to),
            fmt(landed),
            (landed - *to).length()
        );
    }
    say!(
        "moved {} control points (rank {} of {} drags), solve {:.2} ms, warp {:.1} ms",
        solution.displacements().len(),
        solution.rank(),
        solution.drag_count(),
        solve_time.as_secs_f64() * 1e3,
        warp_time.as_secs_f64() * 1e3
    );
    if !solution.is_full_rank() {
        eprintln!(
            "volmorph: warning: the drags conflict (rank {} < {}); they are met in the least-squares sense, largest miss {:.3e}",
            solution.rank(),
            solution.drag_count(),
            solution.max_residual()
        );
    }
    if folding.count_nonpositive > 0 {
        eprintln!("volmorph: warning: the new lattice folds space: {folding}");
    }
    Ok(())
}

/// The material points (on the undeformed model) of the dragged points `from`, which are
/// points of the model as deformed by `lattice`: `lattice⁻¹(from)` by Newton iteration.
fn material_points(
    lattice: &BSplineLattice,
    from: &[DVec3],
    to: &[DVec3],
) -> anyhow::Result<Vec<Drag>> {
    from.iter()
        .zip(to)
        .map(|(&y, &target)| {
            let inv = invert_point(lattice, y, None, &InverseOptions::default());
            if !inv.converged() {
                bail!(
                    "point {} is not on the deformed model's space: the lattice cannot be inverted there ({:?}, residual {:.3e})",
                    fmt(y),
                    inv.status,
                    inv.residual
                );
            }
            Ok(Drag::new(inv.point, target))
        })
        .collect()
}

fn fmt(p: DVec3) -> String {
    format!("({:.4}, {:.4}, {:.4})", p.x, p.y, p.z)
}
