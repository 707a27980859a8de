//! Where the push-forward evaluates its map: fixed tiles of fixed point grids, so that any
//! part of the evaluation can be redone with the same bits.
//!
//! The antialiased push-forward needs the images of the input voxel centres (with a
//! one-voxel margin, for True's averaged face centres) or of the face centres; the nearest
//! push-forward needs the images of the centres. [`SpaceMap::apply_grid`] may give results
//! that depend on the grid it is handed as well as on the point (a lattice tabulates per-axis
//! parameters from the grid's origin and decides from the grid's extent whether its separable
//! path applies), so the image of a point is a function of the point *and of the grid it was
//! evaluated on*. For a chunk of the output to recompute exactly the images the whole
//! push-forward used, without evaluating the whole input, every image is evaluated on one
//! fixed tile: a [`PointGrid`] is cut into tiles of [`TILE`] × [`TILE`] points in x and y,
//! one plane deep, anchored at index 0 of the grid, and any box of the grid is obtained by
//! evaluating, for each tile it overlaps, the tile's points inside the box with the bits of
//! the whole tile ([`SpaceMap::apply_grid_part`]; [`PointGrid::eval_box`]). The bits of a point's image therefore depend only on the map,
//! the input geometry and the point, never on the box asked for, the slab partition or the
//! thread count.

use glam::DVec3;
use rayon::prelude::*;
use volmorph_deform::SpaceMap;
use volmorph_volume::{Geometry, IndexBox};

use crate::WarpError;
use crate::pushforward::offset_grid;
use crate::tally::Region;

/// Points per tile edge (x and y; tiles are one plane deep). Measured for a moved 9³ cubic
/// lattice on a 256³ grid (separable path, one thread): 17 ns per point on 64 × 64 tiles,
/// 28 ns on 32 × 32 and 61 ns on 16 × 16 (the per-call set-up dominates small tiles), 13 ns
/// on whole 2-plane slabs. 64 keeps the in-memory push-forward within a few per cent of
/// whole-slab evaluation (the map is about 5 % of its time; the box tally is the rest) while
/// a chunk that needs only part of a tile evaluates at most a 64-point border more per side.
pub const TILE: usize = 64;

/// A grid of points at continuous input indices `offset + (i, j, k)`, `(i, j, k) < dims`,
/// evaluated tile by tile (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PointGrid {
    /// Continuous input index of point `(0, 0, 0)`.
    offset: DVec3,
    /// Points per axis.
    pub dims: [usize; 3],
    /// What the points are, for errors (`"voxel-centre"`, `"x-face"`, …).
    pub name: &'static str,
}

impl PointGrid {
    /// The voxel centres of an input of `dims` voxels widened by one voxel on every side:
    /// point `(i, j, k)` is the centre of input voxel `(i − 1, j − 1, k − 1)`.
    pub fn centres(dims: [usize; 3]) -> Self {
        Self {
            offset: DVec3::splat(-1.0),
            dims: dims.map(|d| d + 2),
            name: "voxel-centre",
        }
    }

    /// The centres of the faces normal to `axis` (0, 1, 2) of an input of `dims` voxels:
    /// point `i` along `axis` is the face between voxels `i − 1` and `i` (continuous index
    /// `i − ½`), so voxel `i` has faces `i` and `i + 1`.
    pub fn faces(axis: usize, dims: [usize; 3]) -> Self {
        let mut offset = DVec3::ZERO;
        offset[axis] = -0.5;
        let mut d = dims;
        d[axis] += 1;
        Self {
            offset,
            dims: d,
            name: ["x-face", "y-face", "z-face"][axis],
        }
    }

    /// Physical images under `map` of the points of `bx` (a box of this grid's indices),
    /// x fastest, into `out` (`bx.len()` points). The part of every tile `bx` overlaps is
    /// evaluated through [`SpaceMap::apply_grid_part`] on the tile's own geometry (spacing and
    /// direction of `input`, origin at the tile's first point), which gives the bits of the
    /// whole tile's evaluation; planes in parallel.
    ///
    /// # Errors
    /// [`WarpError::MapOnGrid`] if the map's grid evaluation fails; [`WarpError::BufferLength`]
    /// if `out` is not one point per point of `bx` or `bx` leaves the grid.
    pub fn eval_box<M: SpaceMap + ?Sized>(
        &self,
        map: &M,
        input: &Geometry,
        bx: &Region,
        out: &mut [DVec3],
    ) -> Result<(), WarpError> {
        let inside = (0..3).all(|a| bx.lo[a] + bx.dims[a] <= self.dims[a]);
        if out.len() != bx.len() || !inside {
            return Err(WarpError::BufferLength {
                dims: bx.dims,
                expected: bx.len(),
                got: out.len(),
            });
        }
        if bx.is_empty() {
            return Ok(());
        }
        let [wx, wy, _] = bx.dims;
        let tiles = |a: usize| (bx.lo[a] / TILE)..=((bx.lo[a] + bx.dims[a] - 1) / TILE);
        out.par_chunks_mut(wx * wy)
            .enumerate()
            .try_for_each(|(dz, dst)| -> Result<(), WarpError> {
                let z = bx.lo[2] + dz;
                let mut tile = vec![DVec3::ZERO; TILE * TILE];
                for ty in tiles(1) {
                    for tx in tiles(0) {
                        let (x0, y0) = (tx * TILE, ty * TILE);
                        let w = TILE.min(self.dims[0] - x0);
                        let h = TILE.min(self.dims[1] - y0);
                        let at = self.offset + DVec3::new(x0 as f64, y0 as f64, z as f64);
                        let g = offset_grid(input, at, [w, h, 1]);
                        // Only the tile's points inside the box, with the whole tile's bits.
                        let (xs, xe) = (x0.max(bx.lo[0]), (x0 + w).min(bx.lo[0] + wx));
                        let (ys, ye) = (y0.max(bx.lo[1]), (y0 + h).min(bx.lo[1] + wy));
                        let part = IndexBox {
                            start: [xs - x0, ys - y0, 0],
                            end: [xe - x0, ye - y0, 1],
                        };
                        let pw = xe - xs;
                        let t = &mut tile[..part.len()];
                        map.apply_grid_part(&g, part, t).map_err(|source| {
                            WarpError::MapOnGrid {
                                grid: self.name,
                                source,
                            }
                        })?;
                        for (y, src) in (ys..ye).zip(t.chunks_exact(pw)) {
                            let d = (y - bx.lo[1]) * wx + xs - bx.lo[0];
                            dst[d..d + pw].copy_from_slice(src);
                        }
                    }
                }
                Ok(())
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_deform::Affine;

    /// A map whose grid evaluation depends on the grid's origin (as a lattice's separable
    /// path does): images are rounded relative to the origin, so a box evaluated on
    /// another grid than its tile would differ.
    struct OriginDependent;
    impl SpaceMap for OriginDependent {
        fn apply(&self, p: DVec3) -> DVec3 {
            p * 1.1
        }
        fn apply_grid(
            &self,
            grid: &Geometry,
            out: &mut [DVec3],
        ) -> Result<(), volmorph_deform::DeformError> {
            let [nx, ny, _] = grid.dims;
            for (n, o) in out.iter_mut().enumerate() {
                let idx = DVec3::new(
                    (n % nx) as f64,
                    ((n / nx) % ny) as f64,
                    (n / (nx * ny)) as f64,
                );
                *o = grid.origin * 1.1 + idx * 0.1 + DVec3::splat(grid.origin.x * 1e-9);
            }
            Ok(())
        }
    }

    #[test]
    fn any_box_has_the_bits_of_the_whole_grid() {
        let input = Geometry::new([150, 70, 3]);
        let grid = PointGrid::centres(input.dims);
        let all = Region {
            lo: [0; 3],
            dims: grid.dims,
        };
        let mut whole = vec![DVec3::ZERO; all.len()];
        grid.eval_box(&OriginDependent, &input, &all, &mut whole)
            .unwrap();
        for (lo, dims) in [
            ([3, 5, 1], [80, 60, 2]),
            ([63, 63, 0], [3, 3, 5]),
            ([140, 0, 4], [12, 72, 1]),
        ] {
            let bx = Region { lo, dims };
            let mut part = vec![DVec3::ZERO; bx.len()];
            grid.eval_box(&OriginDependent, &input, &bx, &mut part)
                .unwrap();
            for k in 0..dims[2] {
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        let w =
                            (lo[0] + i) + grid.dims[0] * ((lo[1] + j) + grid.dims[1] * (lo[2] + k));
                        let p = i + dims[0] * (j + dims[1] * k);
                        assert_eq!(
                            whole[w].to_array().map(f64::to_bits),
                            part[p].to_array().map(f64::to_bits)
                        );
                    }
                }
            }
        }
        // The pointwise images are the centres' images: point (0, 0, 0) is voxel (−1, −1, −1).
        let mut one = [DVec3::ZERO];
        let shift = Affine::translation(DVec3::X);
        grid.eval_box(
            &shift,
            &input,
            &Region {
                lo: [0; 3],
                dims: [1; 3],
            },
            &mut one,
        )
        .unwrap();
        assert_eq!(one[0], DVec3::new(0.0, -1.0, -1.0));
        // A box leaving the grid is refused.
        let bad = Region {
            lo: [0, 0, 4],
            dims: [1, 1, 2],
        };
        assert!(
            grid.eval_box(&shift, &input, &bad, &mut [DVec3::ZERO; 2])
                .is_err()
        );
    }
}
