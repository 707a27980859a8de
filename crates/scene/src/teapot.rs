//! The teapot session (True 1992, Fig. 10): the built-in teapot as a u8 density volume, an
//! identity uniform cubic B-spline lattice on its voxel centres, and the teapot pushed forward
//! through the lattice (antialiased, kept up to date incrementally), ready for the drag that
//! lowers its spout. `volmorph demo`, the scene benchmark and the scene tests start from it.

use glam::DVec3;
use volmorph_lattice::{BSplineLattice, DragOptions};
use volmorph_maps::AnyMap;
use volmorph_volume::phantom::{self, Phantom, TEAPOT_SPOUT_TIP};
use volmorph_volume::{AnyVolume, Geometry, Volume};
use volmorph_warp::apply::WarpMethod;

use crate::{Command, NewObject, ObjectId, Recipe, Scene, SceneError};

/// Where the spout drag takes the spout tip ([`TEAPOT_SPOUT_TIP`]): down and a little
/// outwards, as in True's Fig. 10 (model units).
pub const SPOUT_TARGET: DVec3 = DVec3::new(0.85, 0.0, 0.04);

/// Radius of the spout drag's tool (model units): control points farther than this from the
/// grabbed point stay where they are.
pub const TOOL_RADIUS: f64 = 0.45;

/// Control points per axis of the demo's lattice (True's Fig. 8 layout: 6 × 6 × 6 regions).
pub const DEMO_LATTICE_COUNTS: [usize; 3] = [9, 9, 9];

/// A scene holding the teapot, its lattice and the warped teapot, with their ids.
#[derive(Debug)]
pub struct TeapotSession {
    /// The scene.
    pub scene: Scene,
    /// The teapot's density volume.
    pub teapot: ObjectId,
    /// The lattice map object.
    pub lattice: ObjectId,
    /// The warped teapot (derived: antialiased push-forward of the teapot by the lattice).
    pub warped: ObjectId,
    /// The teapot's grid.
    pub grid: Geometry,
}

impl TeapotSession {
    /// The session of a `size³` teapot and an identity lattice of `counts` control points
    /// per axis on its voxel centres.
    ///
    /// # Errors
    /// [`SceneError::Volume`] for a size the memory budget refuses, the lattice's errors for
    /// bad counts, and the errors of the warp.
    pub fn new(size: usize, counts: [usize; 3]) -> Result<Self, SceneError> {
        let density = phantom::density(Phantom::Teapot, [size; 3])?;
        let lattice = BSplineLattice::identity_on_voxels(density.geometry(), counts)?;
        Self::with(density, lattice)
    }

    /// The session of a given teapot volume and lattice.
    ///
    /// # Errors
    /// The errors of the commands adding them; [`SceneError::Invalid`] naming the object
    /// when the warp fails.
    pub fn with(density: Volume<u8>, lattice: BSplineLattice) -> Result<Self, SceneError> {
        let grid = *density.geometry();
        let mut scene = Scene::new();
        let mut add = |name: &str, object| add_computed(&mut scene, name, object);
        let teapot = add("teapot", NewObject::Volume(AnyVolume::from(density)))?;
        let lattice = add("lattice", NewObject::Map(AnyMap::Lattice(lattice)))?;
        let warped = add(
            "teapot warped",
            NewObject::Derived(Recipe::Warp {
                source: teapot,
                map: lattice,
                method: WarpMethod::PushforwardAntialiased,
                background: 0.0,
                sampled_nodes: None,
                swap_handles: false,
            }),
        )?;
        Ok(Self {
            scene,
            teapot,
            lattice,
            warped,
            grid,
        })
    }

    /// The spout drag: [`TEAPOT_SPOUT_TIP`] to [`SPOUT_TARGET`] with tool radius
    /// [`TOOL_RADIUS`], on the session's lattice.
    #[must_use]
    pub fn spout_drag(&self) -> Command {
        Command::DragPoints {
            map: self.lattice,
            grabbed: vec![TEAPOT_SPOUT_TIP],
            targets: vec![SPOUT_TARGET],
            options: DragOptions::with_radius(TOOL_RADIUS),
        }
    }
}

/// Apply an add command and return the new object's id; [`SceneError::Invalid`] naming the
/// object when its computation failed (a derived object whose engine reported an error).
pub(crate) fn add_computed(
    scene: &mut Scene,
    name: &str,
    object: NewObject,
) -> Result<ObjectId, SceneError> {
    let change = scene.apply(Command::Add {
        name: name.into(),
        object,
    })?;
    if let Some((_, e)) = change.errors.first() {
        return Err(SceneError::Invalid(format!("cannot compute {name}: {e}")));
    }
    Ok(change.added[0])
}
