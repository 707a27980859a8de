//! Built-in workflows a page can start with one message, each a short sequence of scene
//! commands merged into one undo step: a built-in model, and True's direct-manipulation set-up
//! (an identity lattice on the volume's voxels, the antialiased push-forward through it and the
//! isosurface of the result).

use serde::Deserialize;
use volmorph_handles::HandleSet;
use volmorph_lattice::BSplineLattice;
use volmorph_maps::{AnyMap, HandleMethod, HandleOptions};
use volmorph_scene::{
    Change, Command, NewObject, ObjectId, Recipe, Scene, SceneError, SurfaceMethod,
};
use volmorph_volume::AnyVolume;
use volmorph_volume::phantom::{self, Phantom};
use volmorph_warp::apply::WarpMethod;

/// Largest phantom a page may ask for, voxels per axis (512³ u8 is 128 MiB).
pub const MAX_PHANTOM_SIZE: usize = 512;

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
    /// McPhail's handles on `volume`: a handle map of the 8 corners of the middle half of its
    /// box plus its centre (sources = targets: the identity) by `method`, and the volume
    /// pulled back through the swapped handles (linear), so each source's content appears
    /// at its target.
    Handles {
        /// The volume to deform.
        volume: u64,
        /// The method (`affine`, `similarity`, `rigid`, `tps`, `wendland`).
        method: HandleMethod,
    },
}

impl Setup {
    /// Run the workflow's commands; they become one undo step.
    ///
    /// # Errors
    /// An unknown model, a size out of range, or a scene command's error (what was applied
    /// is taken back).
    pub fn run(self, scene: &mut Scene) -> Result<Change, SceneError> {
        let depth = scene.undo_depth();
        let result = self.commands(scene);
        let steps = scene.undo_depth() - depth;
        match result {
            Ok(change) => {
                scene.merge_last(steps);
                Ok(change)
            }
            Err(e) => {
                for _ in 0..steps {
                    scene.undo()?;
                }
                Err(e)
            }
        }
    }

    fn commands(self, scene: &mut Scene) -> Result<Change, SceneError> {
        let mut all = Change::default();
        let mut add = |scene: &mut Scene, name: &str, object| -> Result<ObjectId, SceneError> {
            let c = scene.apply(Command::Add {
                name: name.into(),
                object,
            })?;
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
                let vol = phantom::density(ph, [size; 3])?;
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
            Setup::Handles { volume, method } => {
                let v = ObjectId(volume);
                let g = *scene.volume(v)?.geometry();
                let n = glam::DVec3::from_array(g.dims.map(|d| d as f64 - 1.0));
                let mut points = vec![];
                for c in 0..8 {
                    let f = |bit: usize| if c & bit == 0 { 0.25 } else { 0.75 };
                    let p = g.index_to_physical(n * glam::DVec3::new(f(1), f(2), f(4)));
                    points.push((p, p));
                }
                let centre = g.index_to_physical(n * 0.5);
                points.push((centre, centre));
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
        }
        Ok(all)
    }
}
