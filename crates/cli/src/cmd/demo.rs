//! `volmorph demo`: the main job on built-in data.
//!
//! 1. **Volume warping by direct manipulation** (True 1992 §5–§7, Figs. 9–10), as one
//!    `volmorph_scene` session: the built-in teapot as a u8 density volume, a 9 × 9 × 9 uniform
//!    cubic B-spline lattice placed around it as the identity (Fig. 8), and a drag command that
//!    lowers the spout, moving only the control points within a tool radius of it (Hsu's
//!    least-norm control-point solve). The scene updates the warped volume incrementally
//!    (True's main loop: only the influenced regions are pushed forward again and the output
//!    they reach recomputed), and with it the isosurface and Jacobian derived from it; the
//!    result is checked against a full antialiased push-forward, and the drag is undone and
//!    redone. The scene exports before/after volumes, lattices and marching-cubes meshes and
//!    saves itself as a project; shaded pictures go beside them, and the time of every step is
//!    printed.
//! 2. **The model gallery** (`models/`): every built-in model as a u8 density volume (object
//!    at isovalue 127) and an f32 signed-distance volume, with pictures of the middle slices.
//!
//! `index.txt` in the folder describes every file.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::ValueEnum as _;
use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_render::{Colormap, OrientationLabels, Window};
use volmorph_scene::teapot::{DEMO_LATTICE_COUNTS, SPOUT_TARGET};
use volmorph_scene::{Command, NewObject, ObjectId, Recipe, Scene, SurfaceMethod, TeapotSession};
use volmorph_volume::phantom::{self, Phantom};
use volmorph_volume::slice::{self, Axis, SlicePosition};
use volmorph_volume::{AnyVolume, Volume};
use volmorph_volume_io as format;
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume};
use volmorph_warp::jacobian::FoldingReport;

use super::phantom::{Kind, make};
use super::picture::{self, View};
use super::slice::{middle, write_picture};
use crate::progress;

/// Arguments of `volmorph demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder (created if missing).
    #[arg(short, long, default_value = "volmorph-demo")]
    pub out: PathBuf,
    /// Voxels per axis of the warped teapot.
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u64).range(16..=512))]
    pub size: u64,
    /// Voxels per axis of the gallery models.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u64).range(8..=512))]
    pub gallery_size: u64,
    /// Picture size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "800x600", value_parser = picture::size)]
    pub picture: (u32, u32),
}

/// The spout tip of the built-in teapot (model units), grabbed by the session's drag.
const SPOUT_TIP: DVec3 = phantom::TEAPOT_SPOUT_TIP;
/// Isovalue of the u8 density models.
const LEVEL: f64 = 127.0;

/// Run `volmorph demo`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create folder {}", args.out.display()))?;
    let mut index = String::new();
    let mut timings = Timings::default();
    warp_demo(args, &mut index, &mut timings)?;
    let files = gallery(args, &mut index)?;
    let idx = args.out.join("index.txt");
    volmorph_io::write_atomic::<anyhow::Error, _>(&idx, |w| {
        use std::io::Write;
        w.write_all(index.as_bytes())?;
        Ok(())
    })?;
    say!("{timings}");
    say!(
        "wrote the warped teapot and {files} gallery files to {} (see index.txt)",
        args.out.display()
    );
    Ok(())
}

/// Named wall-clock times of the demo's steps, printed as a table.
#[derive(Default)]
struct Timings(Vec<(String, f64)>);

impl Timings {
    /// Run `f`, recording its wall time under `name`.
    fn time<R>(&mut self, name: &str, f: impl FnOnce() -> R) -> R {
        let t = Instant::now();
        let r = f();
        self.0.push((name.to_string(), t.elapsed().as_secs_f64()));
        r
    }
}

impl std::fmt::Display for Timings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "timings (wall clock):")?;
        for (name, s) in &self.0 {
            writeln!(f, "  {name:<60} {:>9.1} ms", s * 1e3)?;
        }
        Ok(())
    }
}

fn warp_demo(args: &Args, index: &mut String, timings: &mut Timings) -> anyhow::Result<()> {
    let n = usize::try_from(args.size).context("size does not fit in memory")?;
    let out = &args.out;
    let _ = writeln!(
        index,
        "volmorph demo: the teapot at {n}^3 voxels over the model frame [-1.1, 1.1]^3, its spout \
         lowered by a drag through a 9x9x9 cubic B-spline lattice (True 1992, Fig. 10), run as \
         one scene session (the engine behind every front-end)\n"
    );
    let pb = progress::spinner("building the teapot");
    let source: Volume<u8> = timings.time("teapot density volume", || {
        phantom::density(Phantom::Teapot, [n; 3])
    })?;
    let lattice = volmorph_lattice::BSplineLattice::identity_on_voxels(
        source.geometry(),
        DEMO_LATTICE_COUNTS,
    )?;

    // The scene: the teapot, its lattice, and what is derived from them — the warped volume
    // (kept up to date incrementally), the isosurfaces before and after, and the Jacobian.
    pb.set_message("initial push-forward");
    let session = timings.time("initial antialiased push-forward (identity)", || {
        TeapotSession::with(source.clone(), lattice)
    })?;
    let drag = session.spout_drag();
    let TeapotSession {
        mut scene,
        teapot: t,
        lattice: l,
        warped,
        grid,
    } = session;
    let add = |scene: &mut Scene, name: &str, object| -> anyhow::Result<ObjectId> {
        let change = scene.apply(Command::Add {
            name: name.into(),
            object,
        })?;
        if let Some((_, e)) = change.errors.first() {
            bail!("cannot compute {name}: {e}");
        }
        Ok(change.added[0])
    };
    pb.set_message("isosurfaces and Jacobian");
    let iso = |volume| {
        NewObject::Derived(Recipe::Isosurface {
            volume,
            level: LEVEL,
            inside_below: false,
            method: SurfaceMethod::MarchingCubes,
        })
    };
    let before = timings.time("marching cubes, before", || {
        add(&mut scene, "surface before", iso(t))
    })?;
    let after = add(&mut scene, "surface after", iso(warped))?;
    let jacobian = add(
        &mut scene,
        "Jacobian",
        NewObject::Derived(Recipe::Jacobian { map: l, grid: t }),
    )?;

    pb.set_message("dragging the spout");
    let change = timings.time(
        "drag: least-norm solve, incremental warp, surface, Jacobian",
        || scene.apply(drag),
    )?;
    if let Some((id, e)) = change.errors.first() {
        bail!("cannot update {id}: {e}");
    }
    let moved = change.drag.map_or(0, |d| d.moved);
    let redone = change
        .dirty_of(warped)
        .and_then(|d| d.voxels)
        .map_or(0, |b| b.len());
    let after_lattice = scene.map(l)?.clone();

    // The incremental result must equal a full push-forward with the final lattice.
    pb.set_message("full push-forward for comparison");
    let input = AnyVolume::from(source.clone());
    let full = timings.time("full antialiased push-forward (for comparison)", || {
        warp_volume(
            &input,
            &after_lattice,
            &grid,
            WarpMethod::PushforwardAntialiased,
            &WarpOptions::default(),
        )
    })?;
    let diff = scene.volume(warped)?.max_abs_difference(&full.volume)?;
    let folding = {
        let det = scene.volume(jacobian)?;
        match &**det {
            AnyVolume::F32(v) => FoldingReport::of(v.data()),
            other => bail!("the Jacobian is {}, not f32", other.voxel_type()),
        }
    };

    pb.set_message("pictures");
    let before_mesh = scene.mesh(before)?.clone();
    let after_mesh = scene.mesh(after)?.clone();
    // One frame for both pictures, so before and after line up.
    let both = volmorph_render::Aabb::from_points(
        before_mesh
            .positions()
            .iter()
            .chain(after_mesh.positions())
            .copied(),
    )
    .context("the teapot's isosurface is empty")?;
    let bounds = (both.min(), both.max());
    timings.time("shaded pictures (4)", || -> anyhow::Result<()> {
        for view in [View::Side, View::Iso] {
            let cam = picture::camera(view, bounds, args.picture)?;
            let name = view
                .to_possible_value()
                .context("every view has a name")?
                .get_name()
                .to_string();
            for (stem, mesh) in [("before", &before_mesh), ("after", &after_mesh)] {
                let png = out.join(format!("teapot_{stem}_{name}.png"));
                picture::write_mesh_png(&png, mesh, None, &cam)?;
            }
        }
        Ok(())
    })?;

    // Undo restores the identity lattice and the original push-forward; redo brings the drag
    // back — both through the scene's incremental updates.
    pb.set_message("undo and redo");
    let undo_diff = timings.time("undo (scene command)", || -> anyhow::Result<f64> {
        scene.undo()?.context("nothing to undo")?;
        Ok(scene.volume(warped)?.max_abs_difference(&input)?)
    })?;
    timings.time("redo (scene command)", || -> anyhow::Result<()> {
        scene.redo()?.context("nothing to redo")?;
        Ok(())
    })?;
    let redo_diff = scene.volume(warped)?.max_abs_difference(&full.volume)?;

    pb.set_message("writing");
    timings.time(
        "writing volumes, meshes, lattices and the project",
        || -> anyhow::Result<()> {
            for (id, file) in [
                (t, "teapot.nii.gz"),
                (warped, "teapot_warped.nii.gz"),
                (jacobian, "teapot_jacobian.nii.gz"),
                (l, "lattice_after.json"),
                (l, "lattice_after.tfm"),
                (before, "teapot_before.ply"),
                (after, "teapot_after.ply"),
            ] {
                scene
                    .export(id, &out.join(file))
                    .with_context(|| format!("cannot write {file}"))?;
            }
            scene
                .save(&out.join("teapot.vmproj"))
                .context("cannot save the project")?;
            Ok(())
        },
    )?;
    pb.finish_and_clear();

    let landed = after_lattice.apply(SPOUT_TIP);
    say!(
        "teapot {n}^3: spout tip {} dragged to {} (lands {:.1e} away)",
        fmt(SPOUT_TIP),
        fmt(SPOUT_TARGET),
        (landed - SPOUT_TARGET).length(),
    );
    say!(
        "  {moved} control points moved; the scene redrew {redone} of {} voxels",
        grid.len()
    );
    say!("  incremental result vs full push-forward: max |difference| {diff:.2e} (of 255)");
    say!("  undo restores the original: max |difference| {undo_diff:.2e}");
    say!("  redo equals the full push-forward: max |difference| {redo_diff:.2e}");
    say!("  Jacobian of the new lattice: {folding}");
    say!(
        "  isosurface at {LEVEL}: {} triangles before, {} after",
        before_mesh.face_count(),
        after_mesh.face_count()
    );

    for (file, what) in [
        (
            "teapot.nii.gz",
            "the teapot, u8 density, object where value >= 127",
        ),
        (
            "teapot_warped.nii.gz",
            "the teapot after the drag (antialiased push-forward, u8 like the input)",
        ),
        (
            "teapot_jacobian.nii.gz",
            "Jacobian determinant of the lattice after the drag",
        ),
        (
            "lattice_after.json",
            "the lattice after the drag (volmorph JSON)",
        ),
        (
            "lattice_after.tfm",
            "the same lattice as an ITK BSplineTransform",
        ),
        ("teapot_before.ply", "marching-cubes mesh of the teapot"),
        (
            "teapot_after.ply",
            "marching-cubes mesh of the warped teapot",
        ),
        (
            "teapot_before_side.png",
            "picture of the teapot from the side",
        ),
        (
            "teapot_after_side.png",
            "the warped teapot from the side: the spout is lower",
        ),
        ("teapot_before_iso.png", "three-quarter view, before"),
        ("teapot_after_iso.png", "three-quarter view, after"),
        (
            "teapot.vmproj",
            "the scene as a project (open it again with the library, studio or Python)",
        ),
    ] {
        let _ = writeln!(index, "{file:<28} {what}");
    }
    let _ = writeln!(index);
    Ok(())
}

/// A point as `(x, y, z)` with two decimals, for the summary lines.
fn fmt(p: DVec3) -> String {
    format!("({:.2}, {:.2}, {:.2})", p.x, p.y, p.z)
}

const AXES: [(Axis, &str); 3] = [(Axis::X, "x"), (Axis::Y, "y"), (Axis::Z, "z")];

/// The model gallery in `out/models/`; returns the number of files written.
fn gallery(args: &Args, index: &mut String) -> anyhow::Result<usize> {
    let dir = args.out.join("models");
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("cannot create folder {}", dir.display()))?;
    let n = usize::try_from(args.gallery_size).context("size does not fit in memory")?;
    let dims = [n; 3];
    let models = Phantom::ALL;
    let pb = progress::bar(models.len() as u64 * 2);
    let _ = writeln!(
        index,
        "models/: every built-in model at {n}^3 voxels over the model frame [-1.1, 1.1]^3"
    );
    let mut files = 0;
    for model in models {
        for kind in [Kind::Density, Kind::Sdf] {
            let suffix = if kind == Kind::Sdf { "_sdf" } else { "" };
            let stem = format!("{}{suffix}", model.name());
            pb.set_message(stem.clone());
            let vol = make(model, dims, kind, &volmorph_io::NoProgress)?;
            format::write(&dir.join(format!("{stem}.nii.gz")), &vol).context("cannot write")?;
            let _ = writeln!(
                index,
                "models/{stem}.nii.gz  {}",
                match kind {
                    Kind::Density => format!(
                        "{}: u8 density, object where value >= 127",
                        model.description()
                    ),
                    Kind::Sdf => "f32 signed distance, negative inside".to_string(),
                }
            );
            files += 1;
            for (axis, name) in AXES {
                let png = dir.join(format!("{stem}_{name}.png"));
                write_slice_png(&vol, axis, kind, &png)?;
                let _ = writeln!(
                    index,
                    "models/{stem}_{name}.png  middle slice across {name}"
                );
                files += 1;
            }
            pb.inc(1);
        }
    }
    pb.finish_and_clear();
    Ok(files)
}

fn write_slice_png(vol: &AnyVolume, axis: Axis, kind: Kind, png: &Path) -> anyhow::Result<()> {
    let s = slice::extract(vol, axis, SlicePosition::Index(middle(vol, axis)))?;
    let labels = Some(OrientationLabels::for_slice(
        vol.geometry().direction,
        axis,
    )?);
    match kind {
        Kind::Density => write_picture(png, &s, None, Colormap::Grey, labels),
        // Distances in model units: ±0.3 around the surface, blue inside, red outside.
        Kind::Sdf => write_picture(
            png,
            &s,
            Some(Window::new(0.0, 0.6)?),
            Colormap::CoolWarm,
            labels,
        ),
    }
}
