//! The uniform cubic grid the tri-dexel representation lives on.

use glam::DVec3;

use crate::SculptError;

/// Smallest number of grid points along an axis: the outermost points are always outside the
/// solid, so at least one interior point is needed.
pub const MIN_GRID_POINTS: usize = 3;

/// Largest number of grid points along an axis (rays are indexed with 32-bit integers and
/// coordinates are quantised to 2⁻²⁴ of a spacing in 64-bit integers).
pub const MAX_GRID_POINTS: usize = 1 << 16;

/// Fraction of a cell added to the margin of [`Grid::around`] (1 − 1/√2): an irrational
/// fraction, so that the faces of the box the grid is built around (and faces of a mesh
/// aligned with them) fall between grid planes rather than on them.
pub const GRID_OFFSET: f64 = 1.0 - std::f64::consts::FRAC_1_SQRT_2;

/// A uniform grid of sample points with **cubic** cells: point `(i, j, k)` is at
/// `origin + spacing · (i, j, k)` (physical units, axis-aligned).
///
/// The grid carries the three orthographic depth-peel views of the tri-dexel representation:
/// the rays along axis `a` pass through the grid points, one ray per point of the plane
/// spanned by the two other axes, so the three families of rays meet exactly at the grid
/// points (McPhail §3.3.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    origin: DVec3,
    spacing: f64,
    dims: [usize; 3],
}

impl Grid {
    /// A grid with `dims` points per axis from `origin` with cell size `spacing`.
    ///
    /// # Errors
    /// [`SculptError::InvalidGrid`] for a non-finite origin, a spacing that is not a finite
    /// positive number, or dims outside [`MIN_GRID_POINTS`]`..=`[`MAX_GRID_POINTS`];
    /// [`SculptError::Io`] when the number of points exceeds the memory budget.
    pub fn new(origin: DVec3, spacing: f64, dims: [usize; 3]) -> Result<Self, SculptError> {
        if !origin.is_finite() {
            return Err(SculptError::InvalidGrid(format!(
                "origin {origin} is not finite"
            )));
        }
        if !(spacing.is_finite() && spacing > 0.0) {
            return Err(SculptError::InvalidGrid(format!(
                "spacing {spacing} must be a finite positive number"
            )));
        }
        if dims
            .iter()
            .any(|&n| !(MIN_GRID_POINTS..=MAX_GRID_POINTS).contains(&n))
        {
            return Err(SculptError::InvalidGrid(format!(
                "dims {dims:?}: every axis needs {MIN_GRID_POINTS} to {MAX_GRID_POINTS} points"
            )));
        }
        volmorph_io::checked_len(&dims, 1)?;
        let far = origin + spacing * DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        if !far.is_finite() {
            return Err(SculptError::InvalidGrid(format!(
                "the grid from {origin} with spacing {spacing} overflows"
            )));
        }
        Ok(Self {
            origin,
            spacing,
            dims,
        })
    }

    /// The grid with `n` points along the longest side of the box `[min, max]` enlarged by
    /// `margin` cells (plus [`GRID_OFFSET`]) on every side, and as many points along the other
    /// sides as cover it; the box is centred in the grid. The extra fraction of a cell keeps
    /// the box's faces — often faces of the mesh itself — off the grid planes.
    ///
    /// # Errors
    /// [`SculptError::InvalidGrid`] for a non-finite or inverted box, a negative margin, or
    /// `n` too small to leave one cell inside the margins; as [`Grid::new`] otherwise.
    pub fn around(min: DVec3, max: DVec3, n: usize, margin: f64) -> Result<Self, SculptError> {
        if !(min.is_finite() && max.is_finite() && min.cmple(max).all()) {
            return Err(SculptError::InvalidGrid(format!(
                "box {min} – {max} is not a finite, ordered box"
            )));
        }
        if !(margin.is_finite() && margin >= 0.0) {
            return Err(SculptError::InvalidGrid(format!(
                "margin {margin} must be a finite number ≥ 0"
            )));
        }
        let margin = margin + GRID_OFFSET;
        let cells = n as f64 - 1.0 - 2.0 * margin;
        if cells.is_nan() || cells < 1.0 || n > MAX_GRID_POINTS {
            return Err(SculptError::InvalidGrid(format!(
                "{n} points cannot hold a margin of {margin} cells on both sides"
            )));
        }
        let size = max - min;
        let longest = size.max_element();
        let spacing = if longest > 0.0 {
            longest / cells
        } else {
            // A point: any positive cell size.
            (min.abs().max_element() * 1e-6).max(1e-6)
        };
        let mut dims = [n; 3];
        for (a, d) in dims.iter_mut().enumerate() {
            let needed = (size[a] / spacing + 2.0 * margin).ceil() as usize + 1;
            *d = needed.clamp(MIN_GRID_POINTS, n);
        }
        let extent = DVec3::new(
            (dims[0] - 1) as f64,
            (dims[1] - 1) as f64,
            (dims[2] - 1) as f64,
        ) * spacing;
        let origin = (min + max) * 0.5 - extent * 0.5;
        Self::new(origin, spacing, dims)
    }

    /// Position of grid point `(0, 0, 0)`.
    #[must_use]
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// Edge length of the cubic cells (physical units).
    #[must_use]
    pub fn spacing(&self) -> f64 {
        self.spacing
    }

    /// Number of grid points along x, y and z.
    #[must_use]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Physical coordinate along `axis` of the grid plane with index `i`. Every computation
    /// uses this one expression, so classifications at grid points agree bit for bit.
    #[inline]
    #[must_use]
    pub fn coord(&self, axis: usize, i: usize) -> f64 {
        self.origin[axis] + i as f64 * self.spacing
    }

    /// Physical position of grid point `p`.
    #[must_use]
    pub fn point(&self, p: [usize; 3]) -> DVec3 {
        DVec3::new(
            self.coord(0, p[0]),
            self.coord(1, p[1]),
            self.coord(2, p[2]),
        )
    }

    /// Continuous index coordinates of a physical point (`(p − origin) / spacing`).
    #[inline]
    #[must_use]
    pub fn to_index(&self, p: DVec3) -> DVec3 {
        (p - self.origin) / self.spacing
    }

    /// Physical box spanned by the grid points.
    #[must_use]
    pub fn bounds(&self) -> (DVec3, DVec3) {
        (
            self.origin,
            self.point([self.dims[0] - 1, self.dims[1] - 1, self.dims[2] - 1]),
        )
    }

    /// Every grid point, as an index box.
    #[must_use]
    pub fn full_box(&self) -> PointBox {
        PointBox {
            lo: [0; 3],
            hi: [self.dims[0] - 1, self.dims[1] - 1, self.dims[2] - 1],
        }
    }

    /// Number of rays along `axis` (points of the plane of the two other axes).
    #[must_use]
    pub fn ray_count(&self, axis: usize) -> usize {
        let (b, c) = transverse(axis);
        self.dims[b] * self.dims[c]
    }

    /// Index of the ray along `axis` through transverse grid indices `(ib, ic)` (along
    /// [`transverse`]`(axis)`).
    #[inline]
    #[must_use]
    pub fn ray_index(&self, axis: usize, ib: usize, ic: usize) -> usize {
        let (b, _) = transverse(axis);
        ib + self.dims[b] * ic
    }

    /// Largest index `i` along `axis` with `coord(axis, i) ≤ x`, clamped to the grid
    /// (`None` when `x` is below the first plane).
    #[must_use]
    pub fn floor_index(&self, axis: usize, x: f64) -> Option<usize> {
        let n = self.dims[axis];
        let guess = ((x - self.origin[axis]) / self.spacing).floor();
        if guess.is_nan() || guess < -1.0 {
            return None;
        }
        let mut i = (guess.max(0.0) as usize).min(n - 1);
        // Correct the guess against the exact plane coordinates.
        while i > 0 && self.coord(axis, i) > x {
            i -= 1;
        }
        if self.coord(axis, i) > x {
            return None;
        }
        while i + 1 < n && self.coord(axis, i + 1) <= x {
            i += 1;
        }
        Some(i)
    }

    /// The index box of grid points inside the physical box `[min, max]` (closed), or `None`
    /// when no grid point is inside it.
    #[must_use]
    pub fn index_box_inside(&self, min: DVec3, max: DVec3) -> Option<PointBox> {
        let mut lo = [0; 3];
        let mut hi = [0; 3];
        for a in 0..3 {
            let h = self.floor_index(a, max[a])?;
            let l = match self.floor_index(a, min[a]) {
                Some(i) if self.coord(a, i) == min[a] => i,
                Some(i) => i + 1,
                None => 0,
            };
            if l > h {
                return None;
            }
            lo[a] = l;
            hi[a] = h;
        }
        Some(PointBox { lo, hi })
    }

    /// The smallest index box whose physical box contains `[min, max]`, clamped to the grid.
    #[must_use]
    pub fn index_box_covering(&self, min: DVec3, max: DVec3) -> PointBox {
        let mut lo = [0; 3];
        let mut hi = [0; 3];
        for a in 0..3 {
            lo[a] = self.floor_index(a, min[a]).unwrap_or(0);
            hi[a] = match self.floor_index(a, max[a]) {
                Some(i) if self.coord(a, i) == max[a] => i,
                Some(i) => (i + 1).min(self.dims[a] - 1),
                None => 0,
            };
            hi[a] = hi[a].max(lo[a]);
        }
        PointBox { lo, hi }
    }

    /// Physical box of an index box.
    #[must_use]
    pub fn physical(&self, b: &PointBox) -> (DVec3, DVec3) {
        (self.point(b.lo), self.point(b.hi))
    }
}

/// The two axes transverse to `axis`, in cyclic order: `(axis + 1, axis + 2) mod 3`, so that
/// their 2-D cross product is the component of a 3-D cross product along `axis`.
#[inline]
#[must_use]
pub fn transverse(axis: usize) -> (usize, usize) {
    ((axis + 1) % 3, (axis + 2) % 3)
}

/// A box of grid points, `lo ..= hi` along every axis (so its cells are `lo .. hi`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PointBox {
    /// Lowest grid index per axis.
    pub lo: [usize; 3],
    /// Highest grid index per axis (inclusive).
    pub hi: [usize; 3],
}

impl PointBox {
    /// The box of one grid point.
    #[must_use]
    pub fn point(p: [usize; 3]) -> Self {
        Self { lo: p, hi: p }
    }

    /// Smallest box holding both.
    #[must_use]
    pub fn union(&self, other: &Self) -> Self {
        Self {
            lo: std::array::from_fn(|a| self.lo[a].min(other.lo[a])),
            hi: std::array::from_fn(|a| self.hi[a].max(other.hi[a])),
        }
    }

    /// Grown by `n` points on every side, clamped to `grid`.
    #[must_use]
    pub fn dilated(&self, n: usize, grid: &Grid) -> Self {
        let d = grid.dims();
        Self {
            lo: std::array::from_fn(|a| self.lo[a].saturating_sub(n)),
            hi: std::array::from_fn(|a| (self.hi[a] + n).min(d[a] - 1)),
        }
    }

    /// Number of grid points along each axis.
    #[must_use]
    pub fn extent(&self) -> [usize; 3] {
        std::array::from_fn(|a| self.hi[a] - self.lo[a] + 1)
    }

    /// Number of grid points in the box.
    #[must_use]
    pub fn point_count(&self) -> usize {
        self.extent().iter().product()
    }

    /// `true` if grid point `p` is in the box.
    #[must_use]
    pub fn contains(&self, p: [usize; 3]) -> bool {
        (0..3).all(|a| self.lo[a] <= p[a] && p[a] <= self.hi[a])
    }

    /// `true` if the two boxes share a grid point.
    #[must_use]
    pub fn intersects(&self, other: &Self) -> bool {
        (0..3).all(|a| self.lo[a] <= other.hi[a] && other.lo[a] <= self.hi[a])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_index_agrees_with_coord() {
        let g = Grid::new(DVec3::new(-0.3, 0.1, 7.0), 0.1, [50, 40, 30]).unwrap();
        for a in 0..3 {
            for i in 0..g.dims()[a] {
                let x = g.coord(a, i);
                assert_eq!(g.floor_index(a, x), Some(i));
                assert_eq!(g.floor_index(a, x + 1e-9), Some(i));
                if i > 0 {
                    assert_eq!(g.floor_index(a, x - 1e-9), Some(i - 1));
                }
            }
            assert_eq!(g.floor_index(a, g.origin()[a] - 1.0), None);
        }
    }

    #[test]
    fn around_covers_the_box_with_margins() {
        let (min, max) = (DVec3::new(-1.0, -2.0, 0.0), DVec3::new(1.0, 2.0, 0.5));
        let g = Grid::around(min, max, 64, 2.0).unwrap();
        let (lo, hi) = g.bounds();
        let h = g.spacing();
        assert!((lo - min).max_element() <= -2.0 * h + 1e-9);
        assert!((max - hi).max_element() <= -2.0 * h + 1e-9);
        assert_eq!(g.dims()[1], 64);
        assert!(Grid::around(min, max, 4, 2.0).is_err());
    }
}
