//! Built-in workflows a page can start with one message, each a short sequence of scene
//! commands run as one [`Scene::transaction`] (one undo step, or nothing when it fails or is
//! cancelled): a built-in model, True's direct-manipulation set-up (an identity lattice on the
//! volume's voxels, the antialiased push-forward through it and the isosurface of the
//! result), McPhail's handles, a generated mesh, Feng's mesh FFD (the identity-Jacobian
//! lattice around a mesh and the mesh deformed through it), and McPhail's sculpting (a mesh
//! turned into a sculpt object on a tri-dexel grid with room around it), McPhail's
//! registration workbench (handles selected on a fixed scan and matched in a moving one, the
//! handle map through them and the moving scan registered onto the fixed grid), and his
//! lobe-based lung model (the lungs of a CT segmented, its lobe boundaries enhanced, and the
//! lobe labels traced from the fissure points the user clicks, in the studio).

use crate::{Change, Command, NewObject, ObjectId, Recipe, Scene, SceneError, SurfaceMethod};
use glam::DVec3;
use serde::Deserialize;
use volmorph_handles::HandleSet;
use volmorph_lattice::{BSplineLattice, FengForm};
use volmorph_maps::{AnyMap, HandleMethod, HandleOptions};
use volmorph_volume::AnyVolume;
use volmorph_volume::phantom::{self, Phantom};
use volmorph_warp::apply::WarpMethod;

/// Largest phantom a page may ask for, voxels per axis (512³ u8 is 128 MiB).
pub const MAX_PHANTOM_SIZE: usize = 512;

/// Most handles a handle set-up may place (the client frame limit allows about 20 000).
pub const MAX_SETUP_HANDLES: usize = 4096;

/// Most control points per axis of a mesh-FFD lattice (Feng's examples use at most 9).
pub const MAX_FFD_COUNTS: usize = 64;

/// Largest degree per axis of a mesh-FFD lattice: the accurate FFD's surfaces reach degree
/// `k_u + k_v + k_w`, and `volmorph_ffd` interpolates up to degree 12.
pub const MAX_FFD_DEGREE: usize = 4;

/// Grid points along the longest side of a sculpt set-up's grid when the page names none:
/// 256 is the grid of the thesis's interactive rates (McPhail §3.7) and of the 33 ms dab
/// target.
pub const DEFAULT_SCULPT_GRID: usize = 256;

/// Range of a sculpt set-up's grid points along the longest side (at least room for the
/// margins; at most 512, whose tri-dexel of a closed mesh stays in the hundreds of MB).
pub const SCULPT_GRID_RANGE: std::ops::RangeInclusive<usize> = 32..=512;

/// Fraction of a sculpt set-up's grid left empty on each side of the mesh, so that material
/// can be added around it (an `add` only grows the solid inside the grid).
pub const SCULPT_ROOM: f64 = 0.15;

/// Most handles a registration set-up selects (the thesis uses 100 to 400).
pub const MAX_REGISTER_HANDLES: usize = 2000;

/// A generated mesh, in the frame of the built-in models (about `[-1, 1]³`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shape {
    /// A geodesic sphere of radius 0.5 (level 3: 1280 triangles).
    Sphere,
    /// The axis-aligned box `[-0.4, 0.4]³` (12 triangles).
    Box,
    /// A torus of radii 0.5 and 0.2 in a z plane (48 × 24 steps).
    Torus,
}

/// Form of Feng's initial lattice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Form {
    /// Clamped knots, outermost control points on the box faces (§3.1.3).
    #[default]
    EndInterpolating,
    /// Uniform unclamped knots with the scaling step (§3.1.2).
    Uniform,
}

/// A built-in workflow.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "setup", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Setup {
    /// A built-in model as a u8 density volume (object at 127).
    Phantom {
        /// Its name (`teapot`, `sphere`, …).
        model: String,
        /// Voxels per axis.
        size: usize,
    },
    /// Direct manipulation of `volume`: a `counts³` identity cubic B-spline lattice on its
    /// voxels, the antialiased push-forward through it, and the isosurface at `level` of the
    /// result (marching cubes).
    DirectManipulation {
        /// The volume to deform.
        volume: u64,
        /// Control points per axis.
        counts: usize,
        /// The isosurface level.
        level: f64,
    },
    /// McPhail's handles on `volume`: a handle map by `method` whose handles sit at `points`
    /// (physical; sources = targets: the identity), by default the 8 corners of the middle
    /// half of its box plus its centre, and the volume pulled back through the swapped
    /// handles (linear), so each source's content appears at its target.
    Handles {
        /// The volume to deform.
        volume: u64,
        /// The method (`affine`, `similarity`, `rigid`, `tps`, `wendland`).
        method: HandleMethod,
        /// The handles' positions (physical, finite; at most [`MAX_SETUP_HANDLES`]); empty:
        /// the default nine.
        #[serde(default)]
        points: Vec<[f64; 3]>,
    },
    /// A generated closed mesh.
    Mesh {
        /// Which.
        shape: Shape,
    },
    /// McPhail ch. 3: a copy of the closed mesh `mesh` as a sculpt object (named after it)
    /// on a tri-dexel grid of `grid` points along its longest side (default
    /// [`DEFAULT_SCULPT_GRID`], within [`SCULPT_GRID_RANGE`]), with [`SCULPT_ROOM`] of the
    /// grid empty on every side. The page then sculpts it with `sculpt` commands.
    Sculpt {
        /// The mesh object (a mesh, a derived mesh or a sculpt object).
        mesh: u64,
        /// Grid points along the longest side.
        #[serde(default)]
        grid: Option<usize>,
    },
    /// McPhail ch. 5: up to `handles` handles selected on volume `fixed` (the edge-enhanced
    /// brightest voxels, `radius` mm apart, §5.3.1), matched in volume `moving` by NCC
    /// (§5.3.2, coarse to fine, outliers rejected), a handle map of `method` through the
    /// accepted correspondences (sources in the fixed scan, targets in the moving one: the
    /// map goes fixed → moving), and the moving scan pulled back through it onto the fixed
    /// grid ("NAME registered"). A wrong correspondence is corrected by dragging its target
    /// (`move-handle`); the registered scan follows.
    Register {
        /// The fixed scan.
        fixed: u64,
        /// The moving scan.
        moving: u64,
        /// Most handles, 1 to [`MAX_REGISTER_HANDLES`].
        #[serde(default = "default_register_handles")]
        handles: usize,
        /// Least distance between handles, mm.
        #[serde(default = "default_register_radius")]
        radius: f64,
        /// The handle map's method.
        #[serde(default = "default_register_method")]
        method: HandleMethod,
    },
    /// McPhail §5.6: the lung model of CT volume `ct` (HU, read as f32). The lungs are
    /// segmented (§5.6.1, `volmorph_register::lungs::segment_lungs` with `options`: "NAME
    /// lungs", u8 labels 1 right, 2 left), the lobe boundaries enhanced (§5.6.2: "NAME lobe
    /// boundaries", f32), and the lobes added as a `lobes` derived object with no fissure yet
    /// ("NAME lobes", each lung labelled by height only). The page then clicks the fissures'
    /// end points on axial sections (§5.6.3: the studio's `trace-lobes`).
    Lungs {
        /// The CT volume.
        ct: u64,
        /// Segmentation options (JSON as `LungOptions`; fields left out take their defaults).
        #[serde(default)]
        options: volmorph_register::lungs::LungOptions,
    },
    /// Feng's mesh FFD (2002 §3.1, `volmorph lattice init --mesh`): the identity-Jacobian
    /// B-spline lattice of `degree` and `counts` control points per axis around the bounding
    /// box of mesh `mesh` (an axis where it is flat padded), and the mesh deformed through it
    /// by vertex FFD (a derived object updated incrementally as control points move; its
    /// accurate FFD is what a STEP export writes).
    MeshFfd {
        /// The mesh object (a mesh, a derived mesh or a sculpt object).
        mesh: u64,
        /// Degrees `[k_u, k_v, k_w]`, each 1 to [`MAX_FFD_DEGREE`].
        degree: [usize; 3],
        /// Control points per axis, each `degree + 1` to [`MAX_FFD_COUNTS`].
        counts: [usize; 3],
        /// End-interpolating (default) or uniform.
        #[serde(default)]
        form: Form,
    },
}

fn default_register_handles() -> usize {
    200
}

fn default_register_radius() -> f64 {
    10.0
}

fn default_register_method() -> HandleMethod {
    HandleMethod::Tps
}

/// A registration error as a scene error (cancellation kept as such).
fn from_register(e: volmorph_register::RegisterError) -> SceneError {
    match e {
        volmorph_register::RegisterError::Cancelled(c) => SceneError::Cancelled(c),
        e => SceneError::Invalid(e.to_string()),
    }
}

/// A new scene for a session (the studio's start, `volmorph project new`): the project
/// `files[0]` when it is one (`.vmproj`, [`Scene::load_with`]), then each other file read as
/// an object named after its file name ([`crate::files::read_object_with`]), in order (ids
/// 1, 2, … in a new scene), then each of `setups` run in order ([`Setup::run_with`]), with an
/// empty history: the starting state is not an undo step.
///
/// # Errors
/// The first file that cannot be read or added (the error names it), a project that is not
/// the first file, or the first set-up that fails; [`SceneError::Cancelled`] when `progress`
/// asks to stop.
pub fn start_with(
    files: &[std::path::PathBuf],
    setups: &[Setup],
    progress: &dyn volmorph_io::Progress,
) -> Result<Scene, SceneError> {
    let is_project = |f: &std::path::Path| {
        f.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case(crate::project::PROJECT_EXTENSION))
    };
    let (mut scene, files) = match files.split_first() {
        Some((first, rest)) if is_project(first) => (Scene::load_with(first, progress)?, rest),
        _ => (Scene::new(), files),
    };
    for f in files {
        if is_project(f) {
            return Err(SceneError::Invalid(format!(
                "{}: a project opens only as the first file (it becomes the scene)",
                f.display()
            )));
        }
        let object = crate::files::read_object_with(f, progress)?;
        let name = crate::files::file_name(f);
        scene
            .apply_with(Command::Add { name, object }, progress)
            .map_err(|e| match e {
                SceneError::Cancelled(c) => SceneError::Cancelled(c),
                e => SceneError::Invalid(format!("{}: {e}", f.display())),
            })?;
    }
    for s in setups {
        s.clone().run_with(&mut scene, progress)?;
    }
    scene.clear_history();
    Ok(scene)
}

impl Setup {
    /// Run the workflow's commands; they become one undo step.
    ///
    /// # Errors
    /// An unknown model, a size out of range, or a scene command's error (what was applied
    /// is taken back).
    pub fn run(self, scene: &mut Scene) -> Result<Change, SceneError> {
        self.run_with(scene, &volmorph_io::NoProgress)
    }

    /// [`Setup::run`] reporting the model's sampling and the scene's computations to
    /// `progress`, and stopping when it is cancelled: the scene is then as before.
    ///
    /// # Errors
    /// As [`Setup::run`]; [`SceneError::Cancelled`].
    pub fn run_with(
        self,
        scene: &mut Scene,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Change, SceneError> {
        scene.transaction(|scene| self.commands(scene, progress))
    }

    fn commands(
        self,
        scene: &mut Scene,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Change, SceneError> {
        let mut all = Change::default();
        let mut add = |scene: &mut Scene, name: &str, object| -> Result<ObjectId, SceneError> {
            let c = scene.apply_with(
                Command::Add {
                    name: name.into(),
                    object,
                },
                progress,
            )?;
            let id = c.added[0];
            all.added.extend(c.added);
            all.modified.extend(c.modified);
            all.dirty.extend(c.dirty);
            all.errors.extend(c.errors);
            Ok(id)
        };
        match self {
            Setup::Phantom { model, size } => {
                let ph: Phantom = Phantom::ALL
                    .into_iter()
                    .find(|p| p.name() == model)
                    .ok_or_else(|| {
                        SceneError::Invalid(format!(
                            "unknown model {model:?} (known: {})",
                            Phantom::ALL.map(Phantom::name).join(", ")
                        ))
                    })?;
                if !(8..=MAX_PHANTOM_SIZE).contains(&size) {
                    return Err(SceneError::Invalid(format!(
                        "size {size} must be 8 to {MAX_PHANTOM_SIZE} voxels per axis"
                    )));
                }
                let vol = phantom::density_with(ph, [size; 3], progress)?;
                add(scene, &model, NewObject::Volume(AnyVolume::from(vol)))?;
            }
            Setup::DirectManipulation {
                volume,
                counts,
                level,
            } => {
                let v = ObjectId(volume);
                let grid = *scene.volume(v)?.geometry();
                let lattice = BSplineLattice::identity_on_voxels(&grid, [counts; 3])?;
                let l = add(scene, "lattice", NewObject::Map(AnyMap::Lattice(lattice)))?;
                let w = add(
                    scene,
                    "warped",
                    NewObject::Derived(Recipe::Warp {
                        source: v,
                        map: l,
                        method: WarpMethod::PushforwardAntialiased,
                        background: 0.0,
                        sampled_nodes: None,
                        swap_handles: false,
                    }),
                )?;
                add(
                    scene,
                    "surface",
                    NewObject::Derived(Recipe::Isosurface {
                        volume: w,
                        level,
                        inside_below: false,
                        method: SurfaceMethod::MarchingCubes,
                    }),
                )?;
            }
            Setup::Handles {
                volume,
                method,
                points: at,
            } => {
                let v = ObjectId(volume);
                let g = *scene.volume(v)?.geometry();
                let n = glam::DVec3::from_array(g.dims.map(|d| d as f64 - 1.0));
                let mut points = vec![];
                if at.len() > MAX_SETUP_HANDLES {
                    return Err(SceneError::Invalid(format!(
                        "{} handles: a set-up places at most {MAX_SETUP_HANDLES}",
                        at.len()
                    )));
                }
                for (i, p) in at.iter().enumerate() {
                    if !p.iter().all(|c| c.is_finite()) {
                        return Err(SceneError::Invalid(format!(
                            "handle {i} at {p:?} is not a finite point"
                        )));
                    }
                    let p = glam::DVec3::from_array(*p);
                    points.push((p, p));
                }
                if points.is_empty() {
                    for c in 0..8 {
                        let f = |bit: usize| if c & bit == 0 { 0.25 } else { 0.75 };
                        let p = g.index_to_physical(n * glam::DVec3::new(f(1), f(2), f(4)));
                        points.push((p, p));
                    }
                    let centre = g.index_to_physical(n * 0.5);
                    points.push((centre, centre));
                }
                let set = HandleSet {
                    dim: 3,
                    points,
                    segments: vec![],
                    frames: vec![],
                };
                let h = add(
                    scene,
                    "handles",
                    NewObject::Handles {
                        set,
                        method,
                        options: HandleOptions::default(),
                    },
                )?;
                add(
                    scene,
                    "handle-warp",
                    NewObject::Derived(Recipe::Warp {
                        source: v,
                        map: h,
                        method: WarpMethod::PullbackLinear,
                        background: 0.0,
                        sampled_nodes: None,
                        swap_handles: true,
                    }),
                )?;
            }
            Setup::Mesh { shape } => {
                use volmorph_mesh::shapes;
                let (name, mesh) = match shape {
                    Shape::Sphere => ("sphere", shapes::icosphere(3, 0.5, DVec3::ZERO)?),
                    Shape::Box => (
                        "box",
                        shapes::cuboid(DVec3::splat(-0.4), DVec3::splat(0.4))?,
                    ),
                    Shape::Torus => ("torus", shapes::torus(0.5, 0.2, 48, 24, DVec3::ZERO)?),
                };
                add(scene, name, NewObject::Mesh(mesh))?;
            }
            Setup::Register {
                fixed,
                moving,
                handles,
                radius,
                method,
            } => {
                use volmorph_register::pipeline::{RegisterOptions, correspond_with};
                use volmorph_register::select::SelectOptions;
                if !(1..=MAX_REGISTER_HANDLES).contains(&handles) {
                    return Err(SceneError::Invalid(format!(
                        "{handles} handles: a registration selects 1 to {MAX_REGISTER_HANDLES}"
                    )));
                }
                let (f, m) = (ObjectId(fixed), ObjectId(moving));
                let fixed_scan = scene.volume(f)?.to_typed::<f32>();
                let moving_scan = scene.volume(m)?.to_typed::<f32>();
                let options = RegisterOptions {
                    select: SelectOptions::with_count_radius(handles, radius),
                    ..RegisterOptions::default()
                };
                let (selected, corr) =
                    correspond_with(&fixed_scan, &moving_scan, None, &options, progress)
                        .map_err(from_register)?;
                let set = volmorph_register::solve::handle_set(&corr, method);
                if set.is_empty() {
                    return Err(SceneError::Invalid(format!(
                        "no handle of {} was matched with confidence: the scans may not overlap",
                        selected.len()
                    )));
                }
                let name = scene.get(m)?.name.clone();
                let h = add(
                    scene,
                    &format!("{name} correspondences"),
                    NewObject::Handles {
                        set,
                        method,
                        options: HandleOptions::default(),
                    },
                )?;
                add(
                    scene,
                    &format!("{name} registered"),
                    NewObject::Derived(Recipe::WarpOnto {
                        source: m,
                        map: h,
                        method: WarpMethod::PullbackLinear,
                        background: volmorph_register::metrics::value_range(
                            moving_scan.data(),
                            None,
                        )
                        .0,
                        sampled_nodes: None,
                        swap_handles: false,
                        grid: volmorph_maps::json::GridJson::from(fixed_scan.geometry()),
                    }),
                )?;
            }
            Setup::Lungs { ct, options } => {
                use volmorph_register::RegisterError;
                use volmorph_register::lungs::{
                    EnhanceOptions, LobeScript, enhance_lobe_boundaries_with, segment_lungs_with,
                };
                let c = ObjectId(ct);
                let scan = scene.volume(c)?.to_typed::<f32>();
                let name = scene.get(c)?.name.clone();
                let seg = segment_lungs_with(&scan, &options, progress).map_err(|e| match e {
                    RegisterError::TooLittle(m) => SceneError::Invalid(format!(
                        "no lungs found in volume {c} ({name:?}): {m}; the lung set-up needs a \
                         chest CT in Hounsfield units"
                    )),
                    e => from_register(e),
                })?;
                let boundaries = enhance_lobe_boundaries_with(
                    &scan,
                    &seg.mask,
                    &EnhanceOptions::default(),
                    progress,
                )
                .map_err(from_register)?;
                let lungs = add(
                    scene,
                    &format!("{name} lungs"),
                    NewObject::Volume(AnyVolume::from(seg.mask)),
                )?;
                let boundaries = add(
                    scene,
                    &format!("{name} lobe boundaries"),
                    NewObject::Volume(AnyVolume::from(boundaries)),
                )?;
                add(
                    scene,
                    &format!("{name} lobes"),
                    NewObject::Derived(Recipe::Lobes {
                        lungs,
                        boundaries,
                        script: LobeScript::default(),
                    }),
                )?;
            }
            Setup::Sculpt { mesh, grid } => {
                let m = ObjectId(mesh);
                let n = grid.unwrap_or(DEFAULT_SCULPT_GRID);
                if !SCULPT_GRID_RANGE.contains(&n) {
                    return Err(SceneError::Invalid(format!(
                        "a sculpting grid of {n} points: {} to {} along the longest side",
                        SCULPT_GRID_RANGE.start(),
                        SCULPT_GRID_RANGE.end()
                    )));
                }
                let source = scene.mesh(m)?.as_ref().clone();
                let (lo, hi) = source.bounding_box().ok_or_else(|| {
                    SceneError::Invalid(format!("mesh {m} has no vertices to sculpt"))
                })?;
                // Margin cells so that SCULPT_ROOM of the grid is empty on each side.
                let margin = (SCULPT_ROOM * (n - 1) as f64).floor();
                let grid = volmorph_sculpt::Grid::around(lo, hi, n, margin)?;
                let name = scene.get(m)?.name.clone();
                add(
                    scene,
                    &format!("{name} sculpt"),
                    NewObject::Sculpt {
                        mesh: source,
                        grid,
                        options: volmorph_sculpt::SculptOptions::default(),
                    },
                )?;
            }
            Setup::MeshFfd {
                mesh,
                degree,
                counts,
                form,
            } => {
                let m = ObjectId(mesh);
                for a in 0..3 {
                    if !(1..=MAX_FFD_DEGREE).contains(&degree[a]) {
                        return Err(SceneError::Invalid(format!(
                            "degree {} on axis {a} must be 1 to {MAX_FFD_DEGREE}",
                            degree[a]
                        )));
                    }
                    if !(degree[a] + 1..=MAX_FFD_COUNTS).contains(&counts[a]) {
                        return Err(SceneError::Invalid(format!(
                            "{} control points on axis {a} must be {} (degree + 1) to \
                             {MAX_FFD_COUNTS}",
                            counts[a],
                            degree[a] + 1
                        )));
                    }
                }
                let (lo, hi) = scene.mesh(m)?.bounding_box().ok_or_else(|| {
                    SceneError::Invalid(format!("mesh {m} has no vertices to place a lattice"))
                })?;
                let form = match form {
                    Form::EndInterpolating => FengForm::EndInterpolating,
                    Form::Uniform => FengForm::Uniform,
                };
                let lattice = BSplineLattice::feng_around_model(lo, hi, degree, counts, form)?;
                let name = scene.get(m)?.name.clone();
                let l = add(
                    scene,
                    &format!("{name} lattice"),
                    NewObject::Map(AnyMap::Lattice(lattice)),
                )?;
                add(
                    scene,
                    &format!("{name} deformed"),
                    NewObject::Derived(Recipe::DeformedMesh { mesh: m, map: l }),
                )?;
            }
        }
        Ok(all)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{MapObject, Object};

    fn teapot(scene: &mut Scene) {
        Setup::Phantom {
            model: "teapot".into(),
            size: 16,
        }
        .run(scene)
        .unwrap();
    }

    /// A session starts from files and set-ups with no history; a saved project given first
    /// becomes the scene (same objects, same ids), later files join it, and a project in
    /// any other place is refused naming it.
    #[test]
    fn a_session_starts_from_a_project_first_and_files_after() {
        let dir = tempfile::tempdir().unwrap();
        let setups = [
            Setup::Phantom {
                model: "sphere".into(),
                size: 12,
            },
            Setup::DirectManipulation {
                volume: 1,
                counts: 4,
                level: 127.0,
            },
        ];
        let first = start_with(&[], &setups, &volmorph_io::NoProgress).unwrap();
        assert_eq!(first.undo_depth(), 0);
        let listing = |s: &Scene| -> Vec<(u64, String, String)> {
            s.objects()
                .map(|(id, e)| (id.0, e.name.clone(), e.object.describe()))
                .collect()
        };
        assert_eq!(listing(&first).len(), 4);
        assert!(
            listing(&first)[2]
                .2
                .starts_with("derived warp of 1 and 2: volume 12×12×12")
        );
        let project = dir.path().join("s.vmproj");
        first.save(&project).unwrap();
        let handles = dir.path().join("h.txt");
        std::fs::write(
            &handles,
            "0 0 0 0 0 0\n0.5 0 0 0.5 0 0\n0 0.5 0 0 0.5 0\n0 0 0.5 0 0 0.5\n",
        )
        .unwrap();
        let again = start_with(
            &[project.clone(), handles.clone()],
            &[],
            &volmorph_io::NoProgress,
        )
        .unwrap();
        let (a, b) = (listing(&first), listing(&again));
        assert_eq!(b.len(), 5);
        assert_eq!(a[..], b[..4]);
        assert_eq!(b[4].1, "h.txt");
        assert_eq!(again.undo_depth(), 0);
        let e = start_with(&[handles, project], &[], &volmorph_io::NoProgress).unwrap_err();
        assert!(e.to_string().contains("s.vmproj"), "{e}");
    }

    /// Handles placed where the page asks, sources = targets: the map is the identity, so
    /// the pulled-back volume is the source; the set-up is one undo step.
    #[test]
    fn handles_at_given_points_are_the_identity_and_one_undo_step() {
        let mut scene = Scene::new();
        teapot(&mut scene);
        let depth = scene.undo_depth();
        let points: Vec<[f64; 3]> = (0..200)
            .map(|i| {
                let t = f64::from(i) / 200.0;
                [
                    -0.8 + 1.6 * t,
                    0.5 * (7.0 * t).sin(),
                    0.5 * (11.0 * t).cos(),
                ]
            })
            .collect();
        let c = Setup::Handles {
            volume: 1,
            method: HandleMethod::Affine,
            points: points.clone(),
        }
        .run(&mut scene)
        .unwrap();
        assert_eq!(scene.undo_depth(), depth + 1);
        let map = c.added[0];
        let Object::Map(MapObject::Handles(h)) = &scene.get(map).unwrap().object else {
            panic!("a handle map is added first");
        };
        assert_eq!(h.set().points.len(), 200);
        for ((s, t), p) in h.set().points.iter().zip(&points) {
            assert_eq!(s.to_array(), *p);
            assert_eq!(t, s);
        }
        let src = scene.volume(ObjectId(1)).unwrap().to_typed::<f32>();
        let out = scene.volume(c.added[1]).unwrap().to_typed::<f32>();
        let worst = src
            .data()
            .iter()
            .zip(out.data())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0_f32, f32::max);
        // Identity handles: resampling at the voxel centres themselves (f32 rounding of the
        // map's evaluation only).
        assert!(worst < 1e-2, "identity handles changed a voxel by {worst}");
    }

    /// The lung phantom registered from the studio: the correspondences' map brings the
    /// exhale landmarks closer to the inhale ones than they were, the registered scan lies on
    /// the fixed grid, dragging one correspondence's target changes the registered scan
    /// (only near it), and the set-up is one undo step.
    #[test]
    fn registration_maps_the_phantom_and_a_dragged_correspondence_updates_it() {
        use volmorph_deform::SpaceMap;
        use volmorph_register::phantom::{LungPhantomOptions, lung_phantom};
        let ph = lung_phantom(&LungPhantomOptions {
            dims: [56, 48, 40],
            spacing: DVec3::new(5.0, 5.0, 5.5),
            ..LungPhantomOptions::default()
        })
        .unwrap();
        let mut scene = Scene::new();
        let mut add = |name: &str, v: &volmorph_volume::Volume<f32>| {
            scene
                .apply(Command::Add {
                    name: name.into(),
                    object: NewObject::Volume(AnyVolume::from(v.clone())),
                })
                .unwrap()
                .added[0]
        };
        let (f, m) = (add("inhale", &ph.inhale), add("exhale", &ph.exhale));
        let depth = scene.undo_depth();
        let c = Setup::Register {
            fixed: f.0,
            moving: m.0,
            handles: 80,
            radius: 12.0,
            method: HandleMethod::Tps,
        }
        .run(&mut scene)
        .unwrap();
        assert_eq!(scene.undo_depth(), depth + 1);
        let (h, r) = (c.added[0], c.added[1]);
        assert_eq!(scene.get(r).unwrap().name, "exhale registered");
        let map = scene.map(h).unwrap().clone();
        let tre = |moved: bool| {
            let n = ph.landmarks_inhale.len() as f64;
            ph.landmarks_inhale
                .iter()
                .zip(&ph.landmarks_exhale)
                .map(|(x, y)| ((if moved { map.apply(*x) } else { *x }) - *y).length())
                .sum::<f64>()
                / n
        };
        let (before, after) = (tre(false), tre(true));
        assert!(after < 0.5 * before, "TRE {before:.2} → {after:.2} mm");
        let registered = scene.volume(r).unwrap().to_typed::<f32>();
        assert_eq!(registered.geometry(), ph.inhale.geometry());
        // Drag the first correspondence's target 4 mm along x: the registered scan changes.
        let Object::Map(MapObject::Handles(hm)) = &scene.get(h).unwrap().object else {
            panic!("the correspondences are a handle map");
        };
        let (s0, t0) = hm.set().points[0];
        scene
            .apply(Command::MoveHandle {
                map: h,
                index: 0,
                source: s0,
                target: t0 + DVec3::new(4.0, 0.0, 0.0),
            })
            .unwrap();
        let moved = scene.volume(r).unwrap().to_typed::<f32>();
        let changed = registered
            .data()
            .iter()
            .zip(moved.data())
            .filter(|(a, b)| a != b)
            .count();
        assert!(
            changed > 0,
            "the registered scan follows the dragged correspondence"
        );
        scene.undo().unwrap();
        assert_eq!(
            scene.volume(r).unwrap().to_typed::<f32>().data(),
            registered.data()
        );
        // Wrong inputs are named and change nothing.
        let e = Setup::Register {
            fixed: f.0,
            moving: 99,
            handles: 10,
            radius: 10.0,
            method: HandleMethod::Tps,
        }
        .run(&mut scene)
        .unwrap_err();
        assert!(e.to_string().contains("99"), "{e}");
        let e = Setup::Register {
            fixed: f.0,
            moving: m.0,
            handles: 0,
            radius: 10.0,
            method: HandleMethod::Tps,
        }
        .run(&mut scene)
        .unwrap_err();
        assert!(e.to_string().contains("handles"), "{e}");
    }

    /// A generated sphere becomes a sculpt object whose mesh is the sphere's (the
    /// tri-dexel round trip stays within a grid spacing of it) with room around it; a bad
    /// grid or a non-mesh is refused and changes nothing.
    #[test]
    fn a_mesh_becomes_a_sculpt_object_with_room_around_it() {
        let mut scene = Scene::new();
        let c = Setup::Mesh {
            shape: Shape::Sphere,
        }
        .run(&mut scene)
        .unwrap();
        let sphere = c.added[0];
        let c = Setup::Sculpt {
            mesh: sphere.0,
            grid: Some(64),
        }
        .run(&mut scene)
        .unwrap();
        let id = c.added[0];
        assert_eq!(scene.get(id).unwrap().name, "sphere sculpt");
        let Object::Sculpt(s) = &scene.get(id).unwrap().object else {
            panic!("a sculpt object is added");
        };
        let g = s.document().grid();
        let (lo, hi) = (
            g.origin(),
            g.origin() + g.spacing() * DVec3::from_array(g.dims().map(|d| (d - 1) as f64)),
        );
        // Room on every side: at least SCULPT_ROOM of the grid beyond the sphere (radius 0.5).
        let room = SCULPT_ROOM * (hi.x - lo.x) - 2.0 * g.spacing();
        assert!(
            lo.cmplt(DVec3::splat(-0.5 - room)).all() && hi.cmpgt(DVec3::splat(0.5 + room)).all(),
            "{lo} {hi}"
        );
        let m = scene.mesh(id).unwrap();
        assert!(m.validate().is_closed_manifold());
        for p in m.positions() {
            assert!((p.length() - 0.5).abs() < g.spacing(), "{p}");
        }
        let depth = scene.undo_depth();
        for (mesh, grid, what) in [
            (sphere.0, Some(8), "grid"),
            (sphere.0, Some(100_000), "grid"),
            (999, None, "999"),
        ] {
            let e = Setup::Sculpt { mesh, grid }.run(&mut scene).unwrap_err();
            assert!(e.to_string().contains(what), "{e}");
        }
        assert_eq!(scene.undo_depth(), depth);
    }

    /// A volume without lungs (the teapot) or a missing one is refused by the lung set-up,
    /// naming the problem, and the scene is unchanged.
    #[test]
    fn the_lung_setup_refuses_a_volume_without_lungs() {
        let mut scene = Scene::new();
        teapot(&mut scene);
        let (count, depth) = (scene.objects().count(), scene.undo_depth());
        for (ct, named) in [(1, "no lungs found in volume #1"), (9, "#9")] {
            let e = Setup::Lungs {
                ct,
                options: Default::default(),
            }
            .run(&mut scene)
            .unwrap_err();
            assert!(e.to_string().contains(named), "{e}");
        }
        let bad: Result<Setup, _> = serde_json::from_value(serde_json::json!(
            {"setup": "lungs", "ct": 1, "options": {"threshold": -300, "rounds": 2}}
        ));
        assert!(bad.unwrap_err().to_string().contains("rounds"));
        let e = Setup::Lungs {
            ct: 1,
            options: volmorph_register::lungs::LungOptions {
                majority_rounds: 1000,
                ..Default::default()
            },
        }
        .run(&mut scene)
        .unwrap_err();
        assert!(e.to_string().contains("majority_rounds"), "{e}");
        assert_eq!(
            (scene.objects().count(), scene.undo_depth()),
            (count, depth)
        );
    }

    /// A non-finite handle or too many handles are refused, naming the problem, and the
    /// scene is unchanged.
    #[test]
    fn bad_handle_points_are_refused_and_change_nothing() {
        let mut scene = Scene::new();
        teapot(&mut scene);
        let depth = scene.undo_depth();
        let count = scene.objects().count();
        let e = Setup::Handles {
            volume: 1,
            method: HandleMethod::Tps,
            points: vec![[0.0, 0.0, 0.0], [f64::NAN, 0.0, 0.0]],
        }
        .run(&mut scene)
        .unwrap_err();
        assert!(e.to_string().contains("handle 1"), "{e}");
        let e = Setup::Handles {
            volume: 1,
            method: HandleMethod::Tps,
            points: vec![[0.0; 3]; MAX_SETUP_HANDLES + 1],
        }
        .run(&mut scene)
        .unwrap_err();
        assert!(e.to_string().contains("at most"), "{e}");
        assert_eq!(scene.undo_depth(), depth);
        assert_eq!(scene.objects().count(), count);
    }
}
