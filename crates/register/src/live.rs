//! Live correction of one correspondence with a coarse-grid preview (McPhail's thesis §5.5.4).
//!
//! The map is sampled on a coarse grid over the fixed image (32³ in the thesis); when the
//! user selects a correspondence, every node stores `f(v) − c_i(v) q_i`, and each drag step
//! then writes `f(v) = stored + c_i(v) q` — one multiply-add per node. Affine MLS, frame MLS
//! and the thin-plate spline are all linear in their targets, so this is
//! [`volmorph_deform::live::LiveGrid`] over a [`volmorph_maps::LiveMap`]: the one live-edit
//! mechanism of volmorph, used here as it is everywhere else.
//!
//! This module is the one place of the crate that talks to the live-edit engine.

use glam::DVec3;
use volmorph_deform::SampledMap;
use volmorph_deform::live::LiveGrid;
use volmorph_maps::{AnyMap, LiveMap};
use volmorph_volume::Geometry;

use crate::RegisterError;

/// Nodes per axis of the preview grid in the thesis' measurements (§5.8).
pub const THESIS_GRID_NODES: usize = 32;

/// A handle map kept on a coarse grid for live correction (see the [module docs](self)).
/// Correspondence `i` is the `i`-th **used** correspondence, the map's `i`-th handle.
#[derive(Debug)]
pub struct LivePreview {
    grid: LiveGrid<LiveMap>,
}

impl LivePreview {
    /// Sample `map` on a grid of `nodes` nodes per axis spanning the voxel centres of `fixed`,
    /// with the per-node coefficients of every target (computed up front for MLS and frames,
    /// when first selected for the thin-plate spline).
    ///
    /// # Errors
    /// [`RegisterError::Mismatch`] for a map that is not linear in its targets (similarity or
    /// rigid MLS, a refined map); [`RegisterError::Map`] for an invalid grid or a coefficient
    /// array beyond the allocation limit.
    pub fn new(map: &AnyMap, fixed: &Geometry, nodes: [usize; 3]) -> Result<Self, RegisterError> {
        let live = map.to_live().ok_or_else(|| {
            RegisterError::Mismatch(format!(
                "a {} map is not linear in its handles and cannot be corrected live \
                 (use tps, affine or frames)",
                map.kind()
            ))
        })?;
        let grid = SampledMap::covering(fixed, nodes)?;
        Ok(Self {
            grid: LiveGrid::new(live, grid)?,
        })
    }

    /// The current preview (trilinear between the nodes).
    #[must_use]
    pub fn sampled(&self) -> &SampledMap {
        self.grid.sampled()
    }

    /// The exact map with the current targets.
    #[must_use]
    pub fn exact(&self) -> &LiveMap {
        self.grid.map()
    }

    /// Select correspondence `i` for dragging (stores `f − c_i q_i` at every node).
    ///
    /// # Errors
    /// [`RegisterError::Map`] for `i` out of range.
    pub fn select(&mut self, i: usize) -> Result<(), RegisterError> {
        Ok(self.grid.select(i)?)
    }

    /// Move the target of correspondence `i` to `target` and update the preview: after
    /// [`LivePreview::select`] of `i`, one multiply-add per node (the thesis' update); otherwise
    /// the column of `i` is computed first.
    ///
    /// # Errors
    /// [`RegisterError::Map`] for `i` out of range or a non-finite target; the preview is
    /// unchanged on error.
    pub fn correct(&mut self, i: usize, target: DVec3) -> Result<(), RegisterError> {
        Ok(self.grid.move_parameter(i, target)?)
    }
}
