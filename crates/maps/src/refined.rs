//! A map plus a lattice correction, `φ(x) = base(x) + L(x) − x`: what a dense registration
//! (an initial handle map refined on an intensity metric, as elastix and NiftyReg refine) gives.
//!
//! The correction is added as a displacement, not composed: the base map is kept exactly where
//! the correction is the identity. As [`AnyMap::Refined`](crate::AnyMap::Refined) it is one map
//! file (`"kind": "refined"`, [`crate::json`]).

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_deform::{DeformError, SpaceMap};
use volmorph_lattice::BSplineLattice;
use volmorph_volume::{Geometry, IndexBox};

/// An initial map plus a lattice correction, `φ(x) = base(x) + L(x) − x`, with
/// `Dφ = D base + D L − I`. Both act from the same (fixed-image) space to the same
/// (moving-image) space, in physical units.
#[derive(Debug, Clone)]
pub struct Refined<M> {
    /// The initial map.
    pub base: M,
    /// The correction lattice `L` (the identity where nothing is corrected).
    pub correction: BSplineLattice,
}

impl<M: SpaceMap> SpaceMap for Refined<M> {
    fn apply(&self, p: DVec3) -> DVec3 {
        self.base.apply(p) + self.correction.apply(p) - p
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.base.jacobian(p) + self.correction.jacobian(p) - DMat3::IDENTITY
    }

    fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        self.apply_grid_part(grid, IndexBox::all(grid.dims), out)
    }

    fn apply_grid_part(
        &self,
        grid: &Geometry,
        part: IndexBox,
        out: &mut [DVec3],
    ) -> Result<(), DeformError> {
        // Both maps on the grid (their fast paths), then the sum less the grid point.
        self.base.apply_grid_part(grid, part, out)?;
        let mut c = vec![DVec3::ZERO; out.len()];
        self.correction.apply_grid_part(grid, part, &mut c)?;
        let [px, py] = [0, 1].map(|a| part.end[a].saturating_sub(part.start[a]));
        out.par_iter_mut()
            .zip(c.par_iter())
            .enumerate()
            .for_each(|(n, (o, l))| {
                let index = DVec3::new(
                    (part.start[0] + n % px) as f64,
                    (part.start[1] + n / px % py) as f64,
                    (part.start[2] + n / (px * py)) as f64,
                );
                *o += *l - grid.index_to_physical(index);
            });
        Ok(())
    }
}
