use glam::{DMat3, DVec3};

use crate::VolumeError;

/// Physical geometry of a voxel grid, in the ITK convention.
///
/// A continuous index `(i, j, k)` maps to the physical point
/// `origin + direction · (spacing ⊙ (i, j, k))`. Voxel centres sit at integer indices; the
/// grid's first voxel centre is `origin`. `direction` holds, in its columns, the unit physical
/// directions of the i, j and k axes (identity for an axis-aligned image). Physical space is
/// LPS-style as in ITK/DICOM: NIfTI's RAS is converted on read and back on write.
///
/// Memory order is x (i) fastest: voxel `(i, j, k)` is at `i + nx·(j + ny·k)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Number of voxels along i, j, k.
    pub dims: [usize; 3],
    /// Distance between voxel centres along each index axis (physical units, > 0).
    pub spacing: DVec3,
    /// Physical position of the centre of voxel (0, 0, 0).
    pub origin: DVec3,
    /// Columns: unit physical direction of the i, j, k axes.
    pub direction: DMat3,
}

impl Geometry {
    /// Unit spacing, zero origin, identity direction.
    #[must_use]
    pub fn new(dims: [usize; 3]) -> Self {
        Self {
            dims,
            spacing: DVec3::ONE,
            origin: DVec3::ZERO,
            direction: DMat3::IDENTITY,
        }
    }

    /// Same geometry with another spacing.
    #[must_use]
    pub fn with_spacing(mut self, spacing: DVec3) -> Self {
        self.spacing = spacing;
        self
    }

    /// Same geometry with another origin.
    #[must_use]
    pub fn with_origin(mut self, origin: DVec3) -> Self {
        self.origin = origin;
        self
    }

    /// Same geometry with another direction matrix (columns = axis directions).
    #[must_use]
    pub fn with_direction(mut self, direction: DMat3) -> Self {
        self.direction = direction;
        self
    }

    /// Number of voxels, `nx·ny·nz` (saturating; [`Geometry::validate`] rejects overflow).
    #[must_use]
    pub fn len(&self) -> usize {
        self.dims[0]
            .saturating_mul(self.dims[1])
            .saturating_mul(self.dims[2])
    }

    /// `true` if any dimension is zero.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Check that the geometry describes a grid that can be held in memory: everything
    /// [`validate_unbounded`](Self::validate_unbounded) checks, and a voxel count within the
    /// memory budget ([`volmorph_io::memory_limit`], at one byte per voxel: the least any
    /// voxel type needs).
    ///
    /// # Errors
    /// [`VolumeError::Geometry`] naming the offending field; [`VolumeError::Io`] with
    /// [`volmorph_io::IoError::Budget`] for a grid over the memory budget.
    pub fn validate(&self) -> Result<(), VolumeError> {
        self.validate_unbounded()?;
        volmorph_io::checked_len(&self.dims, 1)?;
        Ok(())
    }

    /// Check that the geometry describes a usable grid of any size: every dim ≥ 1 and the
    /// voxel count representable (`usize`), spacing finite and > 0, origin finite, direction
    /// finite and non-singular (|det| > 1e-12; it need not be orthonormal, as in ITK).
    ///
    /// This is the check for grids that are never held whole: metadata of a chunked store,
    /// the input and output grids of an out-of-core or Dask warp (each chunk is checked
    /// against the memory budget when it is allocated).
    ///
    /// # Errors
    /// [`VolumeError::Geometry`] naming the offending field.
    pub fn validate_unbounded(&self) -> Result<(), VolumeError> {
        if self.dims.contains(&0) {
            return Err(VolumeError::Geometry(format!(
                "dims {:?} contain a zero",
                self.dims
            )));
        }
        if self
            .dims
            .iter()
            .try_fold(1usize, |n, &d| n.checked_mul(d))
            .is_none()
        {
            return Err(VolumeError::Geometry(format!(
                "dims {:?}: the voxel count overflows",
                self.dims
            )));
        }
        if !(self.spacing.is_finite() && self.spacing.min_element() > 0.0) {
            return Err(VolumeError::Geometry(format!(
                "spacing {:?} must be finite and positive",
                self.spacing.to_array()
            )));
        }
        if !self.origin.is_finite() {
            return Err(VolumeError::Geometry(format!(
                "origin {:?} is not finite",
                self.origin.to_array()
            )));
        }
        let det = self.direction.determinant();
        if !self.direction.is_finite() || det.abs() <= 1e-12 {
            return Err(VolumeError::Geometry(format!(
                "direction matrix {:?} is singular or not finite",
                self.direction.to_cols_array_2d()
            )));
        }
        Ok(())
    }

    /// Linear offset of voxel `(i, j, k)` in memory (x fastest). No bounds check.
    #[inline]
    #[must_use]
    pub fn offset(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// `true` if `(i, j, k)` is a voxel of the grid.
    #[inline]
    #[must_use]
    pub fn contains_index(&self, i: usize, j: usize, k: usize) -> bool {
        i < self.dims[0] && j < self.dims[1] && k < self.dims[2]
    }

    /// The matrix `direction · diag(spacing)` that takes index steps to physical steps.
    #[must_use]
    pub fn index_to_physical_matrix(&self) -> DMat3 {
        self.direction * DMat3::from_diagonal(self.spacing)
    }

    /// Physical position of continuous index `index`.
    #[inline]
    #[must_use]
    pub fn index_to_physical(&self, index: DVec3) -> DVec3 {
        self.origin + self.direction * (self.spacing * index)
    }

    /// Physical position of the voxel at linear offset `n` (x fastest, as
    /// [`Geometry::offset`]): the inverse of `offset` followed by
    /// [`Geometry::index_to_physical`]. No bounds check: `n` beyond the grid gives a position
    /// beyond its last plane.
    #[inline]
    #[must_use]
    pub fn voxel_position(&self, n: usize) -> DVec3 {
        let [nx, ny, _] = self.dims;
        self.index_to_physical(DVec3::new(
            (n % nx) as f64,
            (n / nx % ny) as f64,
            (n / (nx * ny)) as f64,
        ))
    }

    /// Continuous index of physical point `p` (inverse of [`Geometry::index_to_physical`]).
    /// Requires a valid (non-singular) geometry.
    #[inline]
    #[must_use]
    pub fn physical_to_index(&self, p: DVec3) -> DVec3 {
        (self.direction.inverse() * (p - self.origin)) / self.spacing
    }

    /// Physical positions of the eight corner voxel centres, in index order
    /// `(0,0,0), (nx-1,0,0), (0,ny-1,0), …`.
    #[must_use]
    pub fn corner_points(&self) -> [DVec3; 8] {
        let m = [
            self.dims[0].saturating_sub(1) as f64,
            self.dims[1].saturating_sub(1) as f64,
            self.dims[2].saturating_sub(1) as f64,
        ];
        std::array::from_fn(|c| {
            let idx = DVec3::new(
                if c & 1 != 0 { m[0] } else { 0.0 },
                if c & 2 != 0 { m[1] } else { 0.0 },
                if c & 4 != 0 { m[2] } else { 0.0 },
            );
            self.index_to_physical(idx)
        })
    }

    /// Axis-aligned physical bounding box `(min, max)` of the voxel centres.
    #[must_use]
    pub fn physical_bounds(&self) -> (DVec3, DVec3) {
        let c = self.corner_points();
        c.iter()
            .fold((c[0], c[0]), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
    }

    /// The grid grown by `low[a]` voxels before the first and `high[a]` voxels after the last
    /// voxel along index axis `a` (same spacing and direction; True 1992 §5.1's target grid
    /// larger than the source, TSIZE > ISIZE). Voxel `(i, j, k)` of `self` is voxel
    /// `(i + low[0], j + low[1], k + low[2])` of the result, at the same physical point.
    /// Dims saturate at `usize::MAX`; [`Geometry::validate`] rejects a result too large.
    #[must_use]
    pub fn padded(&self, low: [usize; 3], high: [usize; 3]) -> Self {
        let dims =
            std::array::from_fn(|a| self.dims[a].saturating_add(low[a]).saturating_add(high[a]));
        let shift = DVec3::new(low[0] as f64, low[1] as f64, low[2] as f64);
        Self {
            dims,
            spacing: self.spacing,
            origin: self.index_to_physical(-shift),
            direction: self.direction,
        }
    }

    /// Geometry that covers the same physical region as `self` with `dims` voxels instead:
    /// the first and last voxel centres keep their physical positions along each axis where
    /// both grids have more than one voxel (same origin and direction).
    #[must_use]
    pub fn resampled(&self, dims: [usize; 3]) -> Self {
        let mut spacing = self.spacing;
        for a in 0..3 {
            if dims[a] > 1 && self.dims[a] > 1 {
                spacing[a] *= (self.dims[a] - 1) as f64 / (dims[a] - 1) as f64;
            }
        }
        Self {
            dims,
            spacing,
            origin: self.origin,
            direction: self.direction,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padded_grid_keeps_every_voxel_at_its_physical_point() {
        let g = oblique();
        let p = g.padded([2, 0, 1], [3, 4, 0]);
        assert_eq!(p.dims, [12, 9, 4]);
        for (i, j, k) in [(0, 0, 0), (6, 4, 2), (3, 1, 1)] {
            let a = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
            let b = p.index_to_physical(DVec3::new((i + 2) as f64, j as f64, (k + 1) as f64));
            assert!((a - b).length() < 1e-12, "{a} {b}");
        }
        assert_eq!(g.padded([0; 3], [0; 3]), g);
    }

    fn oblique() -> Geometry {
        let rot = DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-0.7);
        Geometry::new([7, 5, 3])
            .with_spacing(DVec3::new(0.5, 1.25, 2.0))
            .with_origin(DVec3::new(-10.0, 4.0, 2.5))
            .with_direction(rot)
    }

    #[test]
    fn index_physical_roundtrip() {
        let g = oblique();
        g.validate().unwrap();
        for idx in [
            DVec3::ZERO,
            DVec3::new(6.0, 4.0, 2.0),
            DVec3::new(1.5, -2.0, 0.25),
        ] {
            let p = g.index_to_physical(idx);
            assert!((g.physical_to_index(p) - idx).length() < 1e-12);
        }
        assert_eq!(g.index_to_physical(DVec3::ZERO), g.origin);
        // One step along i moves by spacing.x along the first direction column.
        let step = g.index_to_physical(DVec3::X) - g.origin;
        assert!((step - g.direction.x_axis * 0.5).length() < 1e-15);
    }

    #[test]
    fn validate_rejects_bad_geometry() {
        assert!(Geometry::new([0, 2, 2]).validate().is_err());
        assert!(
            Geometry::new([2, 2, 2])
                .with_spacing(DVec3::new(1.0, 0.0, 1.0))
                .validate()
                .is_err()
        );
        assert!(
            Geometry::new([2, 2, 2])
                .with_spacing(DVec3::new(1.0, f64::NAN, 1.0))
                .validate()
                .is_err()
        );
        assert!(
            Geometry::new([2, 2, 2])
                .with_direction(DMat3::ZERO)
                .validate()
                .is_err()
        );
        assert!(Geometry::new([usize::MAX / 2, 4, 4]).validate().is_err());
        assert!(
            Geometry::new([usize::MAX / 2, 4, 4])
                .validate_unbounded()
                .is_err()
        );
    }

    /// `info --no-stats` of a declared 16384³ OME-Zarr store, and out-of-core warps of it,
    /// were refused because opening the metadata checked the whole grid against the memory
    /// budget.
    #[test]
    fn grids_over_the_memory_budget_are_valid_when_never_held_whole() {
        let huge = Geometry::new([16384; 3]);
        let err = huge.validate().unwrap_err();
        assert!(
            matches!(err, VolumeError::Io(volmorph_io::IoError::Budget { .. })),
            "{err}"
        );
        huge.validate_unbounded().unwrap();
        assert!(
            Geometry::new([16384; 3])
                .with_spacing(DVec3::new(1.0, -1.0, 1.0))
                .validate_unbounded()
                .is_err()
        );
    }

    #[test]
    fn bounds_and_resample_keep_extent() {
        let g = Geometry::new([11, 21, 2]).with_spacing(DVec3::new(1.0, 0.5, 3.0));
        let (lo, hi) = g.physical_bounds();
        assert_eq!(lo, DVec3::ZERO);
        assert_eq!(hi, DVec3::new(10.0, 10.0, 3.0));
        let r = g.resampled([6, 41, 2]);
        assert_eq!(r.physical_bounds(), (lo, hi));
    }
}
