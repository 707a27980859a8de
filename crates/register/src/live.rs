//! Live correction of one correspondence with a coarse-grid preview (McPhail's thesis §5.5.4).
//!
//! The map is sampled on a coarse grid over the fixed image (32³ in the thesis); when the
//! user selects a correspondence, every node stores `f(v) − c_i(v) q_i`, and each drag step
//! then writes `f(v) = stored + c_i(v) q` — one multiply-add per node. Affine and frame MLS are
//! affine in their targets and use [`volmorph_deform::HandleGrid`]; the thin-plate spline is
//! re-solved with its stored factorisation (`O(N²)`) and resampled on the grid.
//!
//! This module is the one place of the crate that talks to the live-edit grid of
//! `volmorph-deform`.

use glam::DVec3;
use volmorph_deform::{HandleGrid, SampledMap, SpaceMap};
use volmorph_handles::{AffineMls, FrameMls, ThinPlateMap};
use volmorph_volume::Geometry;

use crate::RegisterError;
use crate::solve::HandleMap;

/// Nodes per axis of the preview grid in the thesis' measurements (§5.8).
pub const THESIS_GRID_NODES: usize = 32;

enum Engine {
    Mls(HandleGrid<AffineMls>),
    Frames(HandleGrid<FrameMls>),
    Tps {
        map: ThinPlateMap,
        sampled: SampledMap,
    },
}

/// A handle map kept on a coarse grid for live correction (see the [module docs](self)).
pub struct LivePreview {
    engine: Engine,
}

impl std::fmt::Debug for LivePreview {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LivePreview")
            .field("grid", &self.sampled().grid().dims)
            .finish_non_exhaustive()
    }
}

impl LivePreview {
    /// Sample `map` on a grid of `nodes` nodes per axis spanning the voxel centres of `fixed`,
    /// precomputing the per-node coefficients of every target.
    ///
    /// # Errors
    /// [`RegisterError::Map`] for an invalid grid or a coefficient array beyond the allocation
    /// limit.
    pub fn new(map: HandleMap, fixed: &Geometry, nodes: [usize; 3]) -> Result<Self, RegisterError> {
        let grid = SampledMap::covering(fixed, nodes)?;
        let engine = match map {
            HandleMap::Mls(m) => Engine::Mls(HandleGrid::new(m, grid)?),
            HandleMap::Frames(m) => Engine::Frames(HandleGrid::new(m, grid)?),
            HandleMap::Tps(m) => {
                let sampled = SampledMap::from_map(&m, grid)?;
                Engine::Tps { map: m, sampled }
            }
        };
        Ok(Self { engine })
    }

    /// The current preview (trilinear between the nodes).
    #[must_use]
    pub fn sampled(&self) -> &SampledMap {
        match &self.engine {
            Engine::Mls(g) => g.sampled(),
            Engine::Frames(g) => g.sampled(),
            Engine::Tps { sampled, .. } => sampled,
        }
    }

    /// The exact map with the current targets.
    #[must_use]
    pub fn exact(&self) -> &dyn SpaceMap {
        match &self.engine {
            Engine::Mls(g) => g.map(),
            Engine::Frames(g) => g.map(),
            Engine::Tps { map, .. } => map,
        }
    }

    /// Select correspondence `i` for dragging (stores `f − c_i q_i` at every node).
    ///
    /// # Errors
    /// [`RegisterError::Map`] for `i` out of range.
    pub fn select(&mut self, i: usize) -> Result<(), RegisterError> {
        match &mut self.engine {
            Engine::Mls(g) => g.select(i)?,
            Engine::Frames(g) => g.select(i)?,
            Engine::Tps { map, .. } => {
                if i >= map.targets().len() {
                    return Err(RegisterError::Mismatch(format!(
                        "correspondence {i} out of range ({})",
                        map.targets().len()
                    )));
                }
            }
        }
        Ok(())
    }

    /// Move the target of correspondence `i` to `target` and update the preview: one
    /// multiply-add per node for MLS and frames (after [`LivePreview::select`], exactly the
    /// thesis' update), a re-solve and resampling for the thin-plate spline.
    ///
    /// # Errors
    /// [`RegisterError::Map`] for `i` out of range or a non-finite target.
    pub fn correct(&mut self, i: usize, target: DVec3) -> Result<(), RegisterError> {
        match &mut self.engine {
            Engine::Mls(g) => g.move_target(i, target)?,
            Engine::Frames(g) => g.move_target(i, target)?,
            Engine::Tps { map, sampled } => {
                map.move_target(i, target)?;
                *sampled = SampledMap::from_map(&*map, *sampled.grid())?;
            }
        }
        Ok(())
    }
}
