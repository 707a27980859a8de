//! [`DisplacementField`]: a dense displacement field on a voxel grid, as ITK's
//! `DisplacementFieldTransform` holds it, and its files (ITK vector images: NIfTI `.nii`,
//! `.nii.gz`, MetaImage `.mha`, `.mhd`; see [`volmorph_volume_io::vector`]).
//!
//! # Direction and meaning
//!
//! A field `d` on a grid is the map `T(x) = x + d(x)` (ITK's definition), with `x` and `d` in
//! physical (LPS) units. Like every ITK transform it maps points of the **fixed** (output)
//! image to points of the **moving** (input) image: resampling (volmorph's pull-back warp,
//! ITK's `ResampleImageFilter`) gives output voxel `x` the input's value at `T(x)`. The field
//! of a volmorph map `M` on a reference grid ([`DisplacementField::from_map`]) is
//! `d(x) = M(x) − x` at every grid node, so the field and `M` resample alike, to interpolation
//! error between the nodes.
//!
//! # Between and outside the nodes
//!
//! Exactly ITK's `DisplacementFieldTransform` with its default
//! `VectorLinearInterpolateImageFunction`: at continuous grid index `c`, `d` is interpolated
//! trilinearly, a neighbour index past the grid's last node taking that node's value; a point
//! with `c` outside `[−0.5, n − 0.5)` on any axis (ITK's `IsInsideBuffer`: beyond half a
//! voxel outside the grid) has **zero** displacement: `T(x) = x`.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_deform::{DeformError, SpaceMap};
use volmorph_volume::Geometry;
use volmorph_volume_io::vector::VectorImage;

/// Half a voxel: ITK's `IsInsideBuffer` accepts continuous indices in
/// `[start − 0.5, end + 0.5)` (`itkImageFunction.h`).
const ITK_BUFFER_MARGIN: f64 = 0.5;

/// A displacement field `T(x) = x + d(x)` on a voxel grid; see the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct DisplacementField {
    grid: Geometry,
    displacements: Vec<DVec3>,
    to_index: DMat3,
}

impl DisplacementField {
    /// A field from its grid and one displacement per node (x fastest, physical units).
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid grid, [`DeformError::BufferLength`] for a wrong
    /// count, [`DeformError::NonFinite`] for a NaN/infinite displacement.
    pub fn new(grid: Geometry, displacements: Vec<DVec3>) -> Result<Self, DeformError> {
        grid.validate()?;
        volmorph_deform::map::check_len(grid.len(), displacements.len())?;
        volmorph_deform::map::check_finite("displacement", &displacements)?;
        let to_index = grid.index_to_physical_matrix().inverse();
        Ok(Self {
            grid,
            displacements,
            to_index,
        })
    }

    /// The field of `map` on `grid`: `d(x) = map(x) − x` at every node (through
    /// [`SpaceMap::apply_grid`], so maps with grid fast paths use them). `map` is read in the
    /// pull-back sense (node `x` of the output grid samples the input at `map(x)`), which is
    /// ITK's sense of a transform.
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid grid, [`DeformError::Io`] if the node count is
    /// beyond the memory budget, [`DeformError::NonFinite`] if the map gives a non-finite
    /// point, and the map's own errors.
    pub fn from_map<M: SpaceMap + ?Sized>(map: &M, grid: Geometry) -> Result<Self, DeformError> {
        grid.validate()?;
        let n = volmorph_io::checked_len(&grid.dims, 2 * std::mem::size_of::<DVec3>())?;
        let mut d = volmorph_io::try_vec("displacement field", n, DVec3::ZERO)?;
        map.apply_grid(&grid, &mut d)?;
        let [nx, ny, _] = grid.dims;
        d.par_chunks_mut(nx * ny).enumerate().for_each(|(k, slab)| {
            for (j, row) in slab.chunks_exact_mut(nx).enumerate() {
                for (i, p) in row.iter_mut().enumerate() {
                    let x = grid.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                    *p -= x;
                }
            }
        });
        Self::new(grid, d)
    }

    /// A field from a vector image read from a file (its vectors are the displacements).
    ///
    /// # Errors
    /// As [`DisplacementField::new`].
    pub fn from_image(image: VectorImage) -> Result<Self, DeformError> {
        Self::new(image.geometry, image.vectors)
    }

    /// The field as a vector image, to write.
    #[must_use]
    pub fn to_image(&self) -> VectorImage {
        VectorImage {
            geometry: self.grid,
            vectors: self.displacements.clone(),
        }
    }

    /// The grid.
    #[must_use]
    pub fn grid(&self) -> &Geometry {
        &self.grid
    }

    /// The displacements at the nodes (x fastest).
    #[must_use]
    pub fn displacements(&self) -> &[DVec3] {
        &self.displacements
    }

    /// The continuous index of `x`, or `None` outside ITK's buffer (module docs).
    #[inline]
    fn index_of(&self, x: DVec3) -> Option<DVec3> {
        let c = self.to_index * (x - self.grid.origin);
        for a in 0..3 {
            let n = self.grid.dims[a] as f64;
            // Written so that NaN fails the test, as ITK's.
            if !(c[a] >= -ITK_BUFFER_MARGIN && c[a] < n - ITK_BUFFER_MARGIN) {
                return None;
            }
        }
        Some(c)
    }

    /// Base node, weights and which axes are clamped at continuous index `c`.
    #[inline]
    fn cell(&self, c: DVec3) -> ([usize; 3], [usize; 3], DVec3, [bool; 3]) {
        let mut base = [0usize; 3];
        let mut next = [0usize; 3];
        let mut t = DVec3::ZERO;
        let mut clamped = [false; 3];
        for a in 0..3 {
            let n = self.grid.dims[a];
            let hi = (n - 1) as f64;
            let f = c[a].floor();
            if f < 0.0 {
                // Both neighbours clamp to node 0.
                clamped[a] = true;
            } else if f >= hi {
                base[a] = n - 1;
                next[a] = n - 1;
                clamped[a] = true;
            } else {
                base[a] = f as usize;
                next[a] = base[a] + 1;
                t[a] = c[a] - f;
            }
        }
        (base, next, t, clamped)
    }

    #[inline]
    fn at(&self, i: usize, j: usize, k: usize) -> DVec3 {
        let [nx, ny, _] = self.grid.dims;
        self.displacements[i + nx * (j + ny * k)]
    }

    /// The eight corner displacements (x fastest).
    #[inline]
    fn corners(&self, b: [usize; 3], n: [usize; 3]) -> [DVec3; 8] {
        [
            self.at(b[0], b[1], b[2]),
            self.at(n[0], b[1], b[2]),
            self.at(b[0], n[1], b[2]),
            self.at(n[0], n[1], b[2]),
            self.at(b[0], b[1], n[2]),
            self.at(n[0], b[1], n[2]),
            self.at(b[0], n[1], n[2]),
            self.at(n[0], n[1], n[2]),
        ]
    }

    /// The displacement `d(x)` (zero outside the buffer).
    #[must_use]
    pub fn displacement(&self, x: DVec3) -> DVec3 {
        let Some(ci) = self.index_of(x) else {
            return DVec3::ZERO;
        };
        let (b, n, t, _) = self.cell(ci);
        let c = self.corners(b, n);
        let x0 = c[0].lerp(c[1], t.x).lerp(c[2].lerp(c[3], t.x), t.y);
        let x1 = c[4].lerp(c[5], t.x).lerp(c[6].lerp(c[7], t.x), t.y);
        x0.lerp(x1, t.z)
    }
}

impl SpaceMap for DisplacementField {
    fn apply(&self, x: DVec3) -> DVec3 {
        x + self.displacement(x)
    }

    fn jacobian(&self, x: DVec3) -> DMat3 {
        let Some(ci) = self.index_of(x) else {
            return DMat3::IDENTITY;
        };
        let (b, n, t, clamped) = self.cell(ci);
        let c = self.corners(b, n);
        let (u, v, w) = (t.x, t.y, t.z);
        let (u0, v0, w0) = (1.0 - u, 1.0 - v, 1.0 - w);
        // Derivatives with respect to the continuous index.
        let mut dx = ((c[1] - c[0]) * v0 + (c[3] - c[2]) * v) * w0
            + ((c[5] - c[4]) * v0 + (c[7] - c[6]) * v) * w;
        let mut dy = ((c[2] - c[0]) * u0 + (c[3] - c[1]) * u) * w0
            + ((c[6] - c[4]) * u0 + (c[7] - c[5]) * u) * w;
        let mut dz = ((c[4] - c[0]) * u0 + (c[5] - c[1]) * u) * v0
            + ((c[6] - c[2]) * u0 + (c[7] - c[3]) * u) * v;
        for (a, col) in [&mut dx, &mut dy, &mut dz].into_iter().enumerate() {
            if clamped[a] {
                *col = DVec3::ZERO;
            }
        }
        DMat3::from_cols(dx, dy, dz) * self.to_index + DMat3::IDENTITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field() -> DisplacementField {
        let mut g = Geometry::new([4, 5, 3]);
        g.spacing = DVec3::new(2.0, 1.0, 3.0);
        g.origin = DVec3::new(-3.0, 1.0, 2.0);
        let d = (0..g.len())
            .map(|i| {
                DVec3::new(
                    (i % 7) as f64 * 0.3,
                    -((i % 5) as f64),
                    (i % 3) as f64 * 0.5,
                )
            })
            .collect();
        DisplacementField::new(g, d).unwrap()
    }

    #[test]
    fn field_is_exact_at_nodes_and_trilinear_between() {
        let f = field();
        let g = *f.grid();
        for k in 0..3 {
            for j in 0..5 {
                for i in 0..4 {
                    let x = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                    assert!((f.displacement(x) - f.at(i, j, k)).length() < 1e-12);
                }
            }
        }
        // Midway along x between two nodes: the mean.
        let x = g.index_to_physical(DVec3::new(1.5, 2.0, 1.0));
        let want = (f.at(1, 2, 1) + f.at(2, 2, 1)) * 0.5;
        assert!((f.displacement(x) - want).length() < 1e-12);
        // The centre of a cell: the mean of its eight corners.
        let x = g.index_to_physical(DVec3::new(0.5, 0.5, 0.5));
        let c = f.corners([0, 0, 0], [1, 1, 1]);
        let want = c.iter().copied().sum::<DVec3>() / 8.0;
        assert!((f.displacement(x) - want).length() < 1e-12);
    }

    #[test]
    fn field_is_zero_beyond_half_a_voxel_outside_as_itk() {
        let f = field();
        let g = *f.grid();
        // Within half a voxel outside: the edge node's value (clamped neighbours).
        let x = g.index_to_physical(DVec3::new(-0.4, 2.0, 1.0));
        assert!((f.displacement(x) - f.at(0, 2, 1)).length() < 1e-12);
        let x = g.index_to_physical(DVec3::new(3.45, 2.0, 1.0));
        assert!((f.displacement(x) - f.at(3, 2, 1)).length() < 1e-12);
        // Beyond: the identity.
        for c in [
            DVec3::new(-0.6, 2.0, 1.0),
            DVec3::new(3.5, 2.0, 1.0),
            DVec3::new(1.0, 2.0, -3.0),
            DVec3::new(1.0, 4.5, 1.0),
        ] {
            let x = g.index_to_physical(c);
            assert_eq!(f.apply(x), x, "{c}");
            assert_eq!(f.jacobian(x), DMat3::IDENTITY);
        }
        assert!(f.apply(DVec3::NAN).is_nan());
    }

    #[test]
    fn field_of_an_affine_map_reproduces_it_inside_the_grid() {
        let a = volmorph_deform::Affine {
            matrix: DMat3::from_cols_array(&[1.1, 0.05, 0.0, -0.02, 0.95, 0.1, 0.0, 0.03, 1.02]),
            offset: DVec3::new(1.0, -2.0, 0.5),
        };
        let mut g = Geometry::new([6, 5, 4]);
        g.spacing = DVec3::new(1.5, 2.0, 2.5);
        let f = DisplacementField::from_map(&a, g).unwrap();
        // An affine map is trilinear: the field reproduces it exactly between the nodes.
        for c in [DVec3::new(0.3, 1.7, 2.2), DVec3::new(4.9, 0.1, 2.99)] {
            let x = g.index_to_physical(c);
            assert!((f.apply(x) - a.apply(x)).length() < 1e-12);
            let j = f.jacobian(x) - a.matrix;
            assert!(j.to_cols_array().iter().all(|e| e.abs() < 1e-12));
        }
    }
}
