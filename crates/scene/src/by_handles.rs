//! Deforming a model by handles, the direction chosen by the model's kind (what
//! `volmorph handles warp` does).
//!
//! The handle map `f` sends every source handle to its target.
//! * A **mesh** is moved forward: each vertex `v` goes to `f(v)` ([`deform_mesh`]).
//! * A **volume** is resampled by pull-back through the map built from the swapped handles
//!   (targets → sources), so the content found at each source appears at its target; the
//!   output keeps the input's grid ([`warp_volume`]).
//!
//! Each comes with the fold report (Jacobian determinant ≤ 0) of the map it used.

use volmorph_deform::{SampledMap, SpaceMap};
use volmorph_handles::handles::HandleSet;
use volmorph_maps::{HandleDirection, HandleMethod, HandleOptions, handle_map};
use volmorph_mesh::Mesh;
use volmorph_volume::AnyVolume;
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume_with};
use volmorph_warp::jacobian::FoldingReport;

use crate::SceneError;

/// The handle map to build: handles, method and options.
#[derive(Debug, Clone, Copy)]
pub struct HandleSpec<'a> {
    /// Source → target pairs (and frames).
    pub set: &'a HandleSet,
    /// The method (MLS kind, thin-plate spline, …).
    pub method: HandleMethod,
    /// Its options (weighting, smoothing, support, kernel).
    pub options: &'a HandleOptions,
}

/// Move `mesh`'s vertices forward through the handle map (sources → targets), in place.
/// Returns the map's fold report over the mesh's bounding box on a `fold_grid`³ grid, or
/// `None` for a mesh without vertices.
///
/// # Errors
/// [`SceneError::Map`] if the handles give no map, [`SceneError::Deform`] if a vertex cannot
/// be mapped, [`SceneError::Warp`] for a `fold_grid` below 2.
pub fn deform_mesh(
    mesh: &mut Mesh,
    spec: HandleSpec<'_>,
    fold_grid: usize,
) -> Result<Option<FoldingReport>, SceneError> {
    let map = handle_map(
        spec.set,
        spec.method,
        spec.options,
        HandleDirection::SourcesToTargets,
    )?;
    let pts = mesh.positions().to_vec();
    map.apply_batch(&pts, mesh.positions_mut())?;
    Ok(match mesh.bounding_box() {
        Some((lo, hi)) => Some(FoldingReport::over_box(&map, lo, hi, fold_grid)?),
        None => None,
    })
}

/// How [`warp_volume`] resamples.
#[derive(Debug, Clone, Copy)]
pub struct VolumeWarp {
    /// The value outside the input (in the input's units).
    pub background: f64,
    /// Evaluate the map at every voxel (`true`), or on a coarse grid of `grid` nodes per axis
    /// with trilinear interpolation between them (`false`).
    pub exact: bool,
    /// Nodes per axis of the coarse grid (clamped to the volume's dims); also the grid of
    /// the fold report.
    pub grid: usize,
}

/// Resample `volume` on its own grid by linear pull-back through the map from targets to
/// sources, so the content at each source handle appears at its target. Returns the warped
/// volume (the input's voxel type) and the pull-back map's fold report on the coarse grid.
///
/// # Errors
/// [`SceneError::Map`] if the handles give no map, [`SceneError::Warp`] from the warp
/// (`WarpError::Cancelled` when `progress` cancels) and the fold report,
/// [`SceneError::Deform`] for a grid that cannot cover the volume.
pub fn warp_volume(
    volume: &AnyVolume,
    spec: HandleSpec<'_>,
    how: &VolumeWarp,
    progress: &dyn volmorph_io::Progress,
) -> Result<(AnyVolume, FoldingReport), SceneError> {
    let grid = *volume.geometry();
    let map = handle_map(
        spec.set,
        spec.method,
        spec.options,
        HandleDirection::TargetsToSources,
    )?;
    let options = WarpOptions {
        background: how.background,
        mask: false,
        sampled_nodes: (!how.exact).then_some(how.grid),
    };
    let out = warp_volume_with(
        volume,
        &map,
        &grid,
        WarpMethod::PullbackLinear,
        &options,
        progress,
    )?;
    // The grid the warp samples the map on (`sampled_nodes`), also for an exact warp.
    let coarse = SampledMap::covering_at_most(&grid, how.grid)?;
    let report = FoldingReport::of_map(&map, &coarse)?;
    Ok((out.volume, report))
}
