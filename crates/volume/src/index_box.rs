//! [`IndexBox`]: a box of voxel indices, the unit of dirty regions.

/// A box of voxel indices `start[a] .. end[a]` per axis (half-open; empty if any
/// `start[a] >= end[a]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IndexBox {
    /// First index per axis (x, y, z).
    pub start: [usize; 3],
    /// One past the last index per axis.
    pub end: [usize; 3],
}

impl IndexBox {
    /// Number of voxels in the box.
    #[must_use]
    pub fn len(&self) -> usize {
        (0..3)
            .map(|a| self.end[a].saturating_sub(self.start[a]))
            .product()
    }

    /// `true` if the box holds no voxel.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// `true` if voxel `[i, j, k]` lies in the box.
    #[must_use]
    pub fn contains(&self, index: [usize; 3]) -> bool {
        (0..3).all(|a| index[a] >= self.start[a] && index[a] < self.end[a])
    }

    /// The whole grid of `dims` voxels.
    #[must_use]
    pub fn all(dims: [usize; 3]) -> Self {
        Self {
            start: [0; 3],
            end: dims,
        }
    }

    /// The smallest box holding both (an empty box is ignored).
    #[must_use]
    pub fn union(&self, other: &Self) -> Self {
        if self.is_empty() {
            return *other;
        }
        if other.is_empty() {
            return *self;
        }
        Self {
            start: [0, 1, 2].map(|a| self.start[a].min(other.start[a])),
            end: [0, 1, 2].map(|a| self.end[a].max(other.end[a])),
        }
    }
}
