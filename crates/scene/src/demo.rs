//! The demo on built-in data (`volmorph demo`, the README's first command), run here so every
//! front-end gets the same session, numbers and files.
//!
//! 1. **Volume warping by direct manipulation** (True 1992 §5–§7, Figs. 9–10), as one scene
//!    session ([`run_teapot_demo`]): the [`TeapotSession`] (the built-in teapot as a u8
//!    density volume, a 9 × 9 × 9 uniform cubic B-spline lattice placed around it as the
//!    identity, Fig. 8), the isosurfaces before and after and the Jacobian added as derived
//!    objects, and the spout drag, which moves only the control points within the tool radius
//!    (Hsu's least-norm control-point solve). The scene updates the warped volume
//!    incrementally (True's main loop: only the influenced regions are pushed forward again
//!    and the output they reach recomputed), and with it the isosurface and the Jacobian; the
//!    result is compared with a full antialiased push-forward, and the drag is undone and
//!    redone. The scene exports before/after volumes, lattices and marching-cubes meshes and
//!    saves itself as a project; shaded pictures go beside them.
//! 2. **The model gallery** ([`write_gallery`], in `models/`): every built-in model as a u8
//!    density volume (object at isovalue 127) and an f32 signed-distance volume, with
//!    pictures of the middle slices.
//!
//! [`run_demo`] runs both and writes `index.txt`, which describes every file. The time of
//! every step of the session is kept in [`Timings`].

use std::fmt::{self, Write as _};
use std::path::Path;
use std::time::Instant;

use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_io::{IoError, Progress};
use volmorph_lattice::BSplineLattice;
use volmorph_render::{
    Aabb, Colormap, Orbit, OrientationLabels, SliceStyle, UpAxis, Window, render_slice,
    write_mesh_png, write_png_rgba,
};
use volmorph_volume::phantom::{self, Phantom, TEAPOT_SPOUT_TIP};
use volmorph_volume::slice::{self, Axis, SlicePosition};
use volmorph_volume::{AnyVolume, Volume};
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume};
use volmorph_warp::jacobian::FoldingReport;

use crate::teapot::{DEMO_LATTICE_COUNTS, SPOUT_TARGET, add_computed};
use crate::{NewObject, ObjectId, Recipe, SceneError, SurfaceMethod, TeapotSession};

/// Isovalue of the u8 density models (True 1992 §5.1: the object at 127 of 255,
/// [`phantom::ISO_VALUE`]); the demo's isosurfaces are taken there.
pub const DEMO_LEVEL: f64 = phantom::ISO_VALUE as f64;

/// Picture size of the demo's shaded pictures by default, width × height in pixels.
pub const DEMO_PICTURE: (u32, u32) = (800, 600);

/// Named wall-clock times of steps, in the order they ran; displayed as a table (one line per
/// step, milliseconds).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Timings(Vec<(String, f64)>);

impl Timings {
    /// Run `f`, recording its wall time under `name` (seconds), and return its result.
    pub fn time<R>(&mut self, name: &str, f: impl FnOnce() -> R) -> R {
        let t = Instant::now();
        let r = f();
        self.0.push((name.to_string(), t.elapsed().as_secs_f64()));
        r
    }

    /// The recorded steps: name and wall time in seconds, in the order they ran.
    #[must_use]
    pub fn steps(&self) -> &[(String, f64)] {
        &self.0
    }
}

impl fmt::Display for Timings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "timings (wall clock):")?;
        for (name, s) in &self.0 {
            writeln!(f, "  {name:<60} {:>9.1} ms", s * 1e3)?;
        }
        Ok(())
    }
}

/// What the teapot session of the demo found. Differences are in density units (of 255).
/// Displayed as the summary `volmorph demo` prints (several lines, no trailing newline).
#[derive(Debug, Clone, PartialEq)]
pub struct TeapotDemoReport {
    /// Voxels per axis of the teapot.
    pub size: usize,
    /// Where the lattice after the drag takes the spout tip [`TEAPOT_SPOUT_TIP`] (model
    /// units); the drag's target is [`SPOUT_TARGET`].
    pub landed: DVec3,
    /// Control points the drag moved (those within the tool radius).
    pub moved: usize,
    /// Output voxels the scene recomputed for the drag (its dirty voxel box).
    pub redone: usize,
    /// Voxels of the teapot's grid.
    pub voxels: usize,
    /// Max |incremental result − full push-forward with the final lattice|.
    pub incremental_vs_full: f64,
    /// Max |warped volume after undo − the teapot| (the identity lattice's push-forward).
    pub undo_vs_original: f64,
    /// Max |warped volume after redo − full push-forward with the final lattice|.
    pub redo_vs_full: f64,
    /// Jacobian determinants of the lattice after the drag, over the teapot's grid.
    pub folding: FoldingReport,
    /// Triangles of the isosurface at [`DEMO_LEVEL`] before the drag.
    pub triangles_before: usize,
    /// Triangles of the isosurface of the warped teapot.
    pub triangles_after: usize,
}

impl TeapotDemoReport {
    /// How far the spout tip lands from its target (model units).
    #[must_use]
    pub fn landing_error(&self) -> f64 {
        (self.landed - SPOUT_TARGET).length()
    }
}

/// A point as `(x, y, z)` with two decimals, for the summary lines.
fn point(p: DVec3) -> String {
    format!("({:.2}, {:.2}, {:.2})", p.x, p.y, p.z)
}

impl fmt::Display for TeapotDemoReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "teapot {}^3: spout tip {} dragged to {} (lands {:.1e} away)",
            self.size,
            point(TEAPOT_SPOUT_TIP),
            point(SPOUT_TARGET),
            self.landing_error(),
        )?;
        writeln!(
            f,
            "  {} control points moved; the scene redrew {} of {} voxels",
            self.moved, self.redone, self.voxels
        )?;
        writeln!(
            f,
            "  incremental result vs full push-forward: max |difference| {:.2e} (of 255)",
            self.incremental_vs_full
        )?;
        writeln!(
            f,
            "  undo restores the original: max |difference| {:.2e}",
            self.undo_vs_original
        )?;
        writeln!(
            f,
            "  redo equals the full push-forward: max |difference| {:.2e}",
            self.redo_vs_full
        )?;
        writeln!(f, "  Jacobian of the new lattice: {}", self.folding)?;
        write!(
            f,
            "  isosurface at {DEMO_LEVEL}: {} triangles before, {} after",
            self.triangles_before, self.triangles_after
        )
    }
}

/// The files of the teapot session and what each holds, as `index.txt` lists them.
pub const TEAPOT_FILES: [(&str, &str); 12] = [
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
];

/// The marching-cubes isosurface of `volume` at [`DEMO_LEVEL`], object above the level.
fn isosurface(volume: ObjectId) -> NewObject {
    NewObject::Derived(Recipe::Isosurface {
        volume,
        level: DEMO_LEVEL,
        inside_below: false,
        method: SurfaceMethod::MarchingCubes,
    })
}

/// Run the teapot session of the demo on a `size³` teapot and write its files
/// ([`TEAPOT_FILES`]) into the existing folder `out`, shaded pictures `picture` (width ×
/// height pixels) in size. Each step's wall time is added to `timings`; each stage is
/// announced to `progress` (`start(label, 0)`, no steps).
///
/// The returned report's `incremental_vs_full` and `redo_vs_full` are 0 (the warped teapot is
/// u8 like the input, and the incremental push-forward rounds like the full one), and
/// `undo_vs_original` is 0 (the identity lattice pushes the teapot forward onto itself).
///
/// # Errors
/// [`SceneError::Volume`] for a size the memory budget refuses; the errors of the scene's
/// commands (lattice, warp, isosurface, Jacobian, drag); [`SceneError::Invalid`] when a
/// derived object cannot be computed, the isosurface is empty, or undo/redo find nothing;
/// [`SceneError::Render`] for an invalid picture size or a picture that cannot be written;
/// the errors of [`Scene::export`](crate::Scene::export) and [`Scene::save`](crate::Scene::save) naming the file.
pub fn run_teapot_demo(
    out: &Path,
    size: usize,
    picture: (u32, u32),
    timings: &mut Timings,
    progress: &dyn Progress,
) -> Result<TeapotDemoReport, SceneError> {
    let stage = |label: &str| progress.start(label, 0);
    stage("building the teapot");
    let source: Volume<u8> = timings.time("teapot density volume", || {
        phantom::density(Phantom::Teapot, [size; 3])
    })?;
    let lattice = BSplineLattice::identity_on_voxels(source.geometry(), DEMO_LATTICE_COUNTS)?;

    // The scene: the teapot, its lattice, and what is derived from them — the warped volume
    // (kept up to date incrementally), the isosurfaces before and after, and the Jacobian.
    stage("initial push-forward");
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
    stage("isosurfaces and Jacobian");
    let before = timings.time("marching cubes, before", || {
        add_computed(&mut scene, "surface before", isosurface(t))
    })?;
    let after = add_computed(&mut scene, "surface after", isosurface(warped))?;
    let jacobian = add_computed(
        &mut scene,
        "Jacobian",
        NewObject::Derived(Recipe::Jacobian { map: l, grid: t }),
    )?;

    stage("dragging the spout");
    let change = timings.time(
        "drag: least-norm solve, incremental warp, surface, Jacobian",
        || scene.apply(drag),
    )?;
    if let Some((id, e)) = change.errors.first() {
        return Err(SceneError::invalid(format!("cannot update {id}: {e}")));
    }
    let moved = change.drag.map_or(0, |d| d.moved);
    let redone = change
        .dirty_of(warped)
        .and_then(|d| d.voxels)
        .map_or(0, |b| b.len());
    let after_lattice = scene.map(l)?.clone();

    // The incremental result must equal a full push-forward with the final lattice.
    stage("full push-forward for comparison");
    let input = AnyVolume::from(source);
    let full = timings.time("full antialiased push-forward (for comparison)", || {
        warp_volume(
            &input,
            &after_lattice,
            &grid,
            WarpMethod::PushforwardAntialiased,
            &WarpOptions::default(),
        )
    })?;
    let incremental_vs_full = scene.volume(warped)?.max_abs_difference(&full.volume)?;
    let folding = match &**scene.volume(jacobian)? {
        AnyVolume::F32(v) => FoldingReport::of(v.data()),
        other => {
            return Err(SceneError::invalid(format!(
                "the Jacobian is {}, not f32",
                other.voxel_type()
            )));
        }
    };

    stage("pictures");
    let before_mesh = scene.mesh(before)?.clone();
    let after_mesh = scene.mesh(after)?.clone();
    // One frame for both pictures, so before and after line up.
    let both = Aabb::from_points(
        before_mesh
            .positions()
            .iter()
            .chain(after_mesh.positions())
            .copied(),
    )
    .ok_or_else(|| SceneError::invalid("the teapot's isosurface is empty"))?;
    let bounds = (both.min(), both.max());
    timings.time("shaded pictures (4)", || -> Result<(), SceneError> {
        for view in ["side", "iso"] {
            let orbit = Orbit::named(view, UpAxis::Z)
                .ok_or_else(|| SceneError::invalid(format!("no view named {view}")))?;
            let cam = orbit.mesh_camera(bounds, picture)?;
            for (stem, mesh) in [("before", &before_mesh), ("after", &after_mesh)] {
                let png = out.join(format!("teapot_{stem}_{view}.png"));
                write_mesh_png(&png, mesh, None, None, &cam)?;
            }
        }
        Ok(())
    })?;

    // Undo restores the identity lattice and the original push-forward; redo brings the drag
    // back — both through the scene's incremental updates.
    stage("undo and redo");
    let undo_vs_original =
        timings.time("undo (scene command)", || -> Result<f64, SceneError> {
            scene
                .undo()?
                .ok_or_else(|| SceneError::invalid("nothing to undo"))?;
            Ok(scene.volume(warped)?.max_abs_difference(&input)?)
        })?;
    timings.time("redo (scene command)", || -> Result<(), SceneError> {
        scene
            .redo()?
            .ok_or_else(|| SceneError::invalid("nothing to redo"))?;
        Ok(())
    })?;
    let redo_vs_full = scene.volume(warped)?.max_abs_difference(&full.volume)?;

    stage("writing");
    timings.time(
        "writing volumes, meshes, lattices and the project",
        || -> Result<(), SceneError> {
            for (id, file) in [
                (t, "teapot.nii.gz"),
                (warped, "teapot_warped.nii.gz"),
                (jacobian, "teapot_jacobian.nii.gz"),
                (l, "lattice_after.json"),
                (l, "lattice_after.tfm"),
                (before, "teapot_before.ply"),
                (after, "teapot_after.ply"),
            ] {
                scene.export(id, &out.join(file))?;
            }
            scene.save(&out.join("teapot.vmproj"))
        },
    )?;

    Ok(TeapotDemoReport {
        size,
        landed: after_lattice.apply(TEAPOT_SPOUT_TIP),
        moved,
        redone,
        voxels: grid.len(),
        incremental_vs_full,
        undo_vs_original,
        redo_vs_full,
        folding,
        triangles_before: before_mesh.face_count(),
        triangles_after: after_mesh.face_count(),
    })
}

/// The index axes and their names in the gallery's file names.
const AXES: [(Axis, &str); 3] = [(Axis::X, "x"), (Axis::Y, "y"), (Axis::Z, "z")];

/// Half the width of the signed-distance pictures' window (model units): ±0.3 around the
/// surface, blue inside, red outside.
pub const SDF_WINDOW_WIDTH: f64 = 0.6;

/// The picture of the middle slice across `axis` of `vol`, as `volmorph slice` draws it by
/// default ([`SliceStyle::default`] with orientation labels), in `colormap` with `window`
/// (the automatic window when `None`), written atomically as a PNG at `png`.
///
/// # Errors
/// [`SceneError::Volume`] if the slice cannot be taken; [`SceneError::Render`] if the
/// picture cannot be drawn or written (naming `png`).
pub fn write_middle_slice_png(
    vol: &AnyVolume,
    axis: Axis,
    window: Option<Window>,
    colormap: Colormap,
    png: &Path,
) -> Result<(), SceneError> {
    let s = slice::extract(vol, axis, SlicePosition::middle(vol.geometry().dims, axis))?;
    let labels = Some(OrientationLabels::for_slice(
        vol.geometry().direction,
        axis,
    )?);
    let style = SliceStyle {
        window,
        colormap,
        labels,
        ..SliceStyle::default()
    };
    write_png_rgba(png, &render_slice(&s, &style)?).map_err(|e| SceneError::Render(e.at(png)))
}

/// The model gallery: every built-in model ([`Phantom::ALL`]) at `size³` voxels as a u8
/// density volume `models/NAME.nii.gz` and an f32 signed-distance volume
/// `models/NAME_sdf.nii.gz`, each with pictures of its middle slices across x, y and z
/// (`…_x.png`, …), in `out/models/` (created if missing). Appends a description of every
/// file to `index`; announces one stage of `2 × models` steps to `progress`. Returns the
/// number of files written.
///
/// # Errors
/// [`SceneError::Io`] if the folder cannot be created; [`SceneError::Volume`] for a size the
/// memory budget refuses or a volume that cannot be written; [`SceneError::Render`] for a
/// picture that cannot be written.
pub fn write_gallery(
    out: &Path,
    size: usize,
    index: &mut String,
    progress: &dyn Progress,
) -> Result<usize, SceneError> {
    let dir = out.join("models");
    std::fs::create_dir_all(&dir).map_err(|e| IoError::os(&dir, e))?;
    let dims = [size; 3];
    let models = Phantom::ALL;
    progress.start("model gallery", models.len() as u64 * 2);
    let _ = writeln!(
        index,
        "models/: every built-in model at {size}^3 voxels over the model frame [-1.1, 1.1]^3"
    );
    let mut files = 0;
    for model in models {
        for sdf in [false, true] {
            let stem = format!("{}{}", model.name(), if sdf { "_sdf" } else { "" });
            let vol = if sdf {
                AnyVolume::from(phantom::signed_distance(model, dims)?)
            } else {
                AnyVolume::from(phantom::density(model, dims)?)
            };
            volmorph_volume_io::write(&dir.join(format!("{stem}.nii.gz")), &vol)?;
            let what = if sdf {
                "f32 signed distance, negative inside".to_string()
            } else {
                format!(
                    "{}: u8 density, object where value >= 127",
                    model.description()
                )
            };
            let _ = writeln!(index, "models/{stem}.nii.gz  {what}");
            files += 1;
            for (axis, name) in AXES {
                let png = dir.join(format!("{stem}_{name}.png"));
                if sdf {
                    // Distances in model units around the surface, blue inside, red outside.
                    let window = Window::new(0.0, SDF_WINDOW_WIDTH)?;
                    write_middle_slice_png(&vol, axis, Some(window), Colormap::CoolWarm, &png)?;
                } else {
                    write_middle_slice_png(&vol, axis, None, Colormap::Grey, &png)?;
                }
                let _ = writeln!(
                    index,
                    "models/{stem}_{name}.png  middle slice across {name}"
                );
                files += 1;
            }
            progress.advance(1);
        }
    }
    Ok(files)
}

/// What [`run_demo`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoReport {
    /// The teapot session's numbers.
    pub teapot: TeapotDemoReport,
    /// Files the model gallery wrote.
    pub gallery_files: usize,
    /// Wall time of every step of the teapot session.
    pub timings: Timings,
}

/// The demo's sizes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DemoOptions {
    /// Voxels per axis of the warped teapot.
    pub size: usize,
    /// Voxels per axis of the gallery models.
    pub gallery_size: usize,
    /// Shaded picture size, width × height in pixels.
    pub picture: (u32, u32),
}

impl Default for DemoOptions {
    /// The README's demo: a 128³ teapot, 64³ gallery models, 800 × 600 pictures.
    fn default() -> Self {
        Self {
            size: 128,
            gallery_size: 64,
            picture: DEMO_PICTURE,
        }
    }
}

/// The whole demo into the folder `out` (created if missing): the teapot session
/// ([`run_teapot_demo`]), the model gallery ([`write_gallery`]) and `index.txt` describing
/// every file (written atomically, last).
///
/// # Errors
/// [`SceneError::Io`] if the folder or the index cannot be written; the errors of
/// [`run_teapot_demo`] and [`write_gallery`].
pub fn run_demo(
    out: &Path,
    options: &DemoOptions,
    progress: &dyn Progress,
) -> Result<DemoReport, SceneError> {
    std::fs::create_dir_all(out).map_err(|e| IoError::os(out, e))?;
    let mut timings = Timings::default();
    let n = options.size;
    let mut index = format!(
        "volmorph demo: the teapot at {n}^3 voxels over the model frame [-1.1, 1.1]^3, its spout \
         lowered by a drag through a 9x9x9 cubic B-spline lattice (True 1992, Fig. 10), run as \
         one scene session (the engine behind every front-end)\n\n"
    );
    let teapot = run_teapot_demo(out, n, options.picture, &mut timings, progress)?;
    for (file, what) in TEAPOT_FILES {
        let _ = writeln!(index, "{file:<28} {what}");
    }
    index.push('\n');
    let gallery_files = write_gallery(out, options.gallery_size, &mut index, progress)?;
    volmorph_io::write_atomic::<SceneError, _>(&out.join("index.txt"), |w| {
        use std::io::Write;
        w.write_all(index.as_bytes())
            .map_err(|e| IoError::os(&out.join("index.txt"), e))?;
        Ok(())
    })?;
    Ok(DemoReport {
        teapot,
        gallery_files,
        timings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The demo on a small teapot: the incremental warp equals the full push-forward exactly
    /// (both u8, rounded alike), undo restores the original, the drag moved control points
    /// and redrew part (not all) of the grid, the spout landed near its target, and every
    /// file listed is there.
    #[test]
    fn the_teapot_demo_report_is_sane_and_its_files_are_written() {
        let dir = tempfile::tempdir().unwrap();
        let mut timings = Timings::default();
        let r = run_teapot_demo(
            dir.path(),
            32,
            (80, 60),
            &mut timings,
            &volmorph_io::NoProgress,
        )
        .unwrap();
        assert_eq!(r.incremental_vs_full, 0.0, "{r}");
        assert_eq!(r.undo_vs_original, 0.0, "{r}");
        assert_eq!(r.redo_vs_full, 0.0, "{r}");
        assert!(r.moved > 0 && r.moved < 9 * 9 * 9, "{r}");
        assert!(r.redone > 0 && r.redone < r.voxels, "{r}");
        assert_eq!(r.voxels, 32 * 32 * 32);
        // The drag solve is exact at the grabbed point; allow the lattice's rounding.
        assert!(r.landing_error() < 1e-6, "{r}");
        assert!(r.triangles_before > 0 && r.triangles_after > 0, "{r}");
        assert_eq!(r.folding.count, r.voxels);
        assert_eq!(r.folding.count_nonfinite, 0);
        assert!(r.folding.min > 0.0, "the spout drag folds nothing: {r}");
        for (file, _) in TEAPOT_FILES {
            assert!(dir.path().join(file).is_file(), "missing {file}");
        }
        let names: Vec<&str> = timings.steps().iter().map(|(n, _)| n.as_str()).collect();
        assert!(names.contains(&"drag: least-norm solve, incremental warp, surface, Jacobian"));
        let text = r.to_string();
        assert!(text.starts_with("teapot 32^3: spout tip"), "{text}");
        assert!(text.contains("max |difference| 0.00e0 (of 255)"), "{text}");
    }

    #[test]
    fn the_gallery_writes_every_model_and_describes_every_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut index = String::new();
        let files = write_gallery(dir.path(), 12, &mut index, &volmorph_io::NoProgress).unwrap();
        assert_eq!(files, Phantom::ALL.len() * 2 * 4);
        for model in Phantom::ALL {
            for f in [
                format!("{}.nii.gz", model.name()),
                format!("{}_sdf_y.png", model.name()),
            ] {
                assert!(dir.path().join("models").join(&f).is_file(), "missing {f}");
                assert!(index.contains(&format!("models/{f}")), "{index}");
            }
        }
        assert_eq!(index.lines().count(), 1 + files);
    }
}
