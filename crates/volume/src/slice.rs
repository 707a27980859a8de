//! Axis-aligned slices of a volume, as 2-D `f32` images.
//!
//! A slice is perpendicular to one *index* axis ([`Axis::X`] = i, [`Axis::Y`] = j,
//! [`Axis::Z`] = k) and sits at a [`SlicePosition`]: an index along that axis, possibly
//! fractional (linear interpolation between the two neighbouring voxel planes, exact at
//! integers), or a physical coordinate converted to such an index.
//!
//! # Picture layout
//!
//! The two remaining index axes span the picture, in increasing order: the **first** runs
//! along the picture's width (left to right, increasing index), the **second** along its height
//! (see [`Axis::in_plane`]):
//!
//! | axis | width (columns) | height (rows) |
//! | --- | --- | --- |
//! | `Z` | i | j |
//! | `Y` | i | k |
//! | `X` | j | k |
//!
//! Rows are stored top to bottom, and row 0 holds the **highest** index of the second axis,
//! so that the second axis points up when the picture is displayed: pixel `(column c, row r)`
//! is the voxel with first index `c` and second index `height − 1 − r`.
//! This is a statement about index axes only; the physical orientation of the picture follows
//! from the volume's direction matrix.

use std::fmt;

use crate::{AnyVolume, Geometry, Volume, VolumeError, Voxel};

/// How far (in voxels) a position may fall outside `[0, n − 1]` and still be accepted (and
/// clamped): absorbs the rounding of a physical position computed from the geometry, e.g.
/// `origin + 9·spacing` landing `10⁻¹⁵` beyond the last plane.
pub const POSITION_TOLERANCE: f64 = 1e-9;

/// An index axis of a volume: `X` = i (fastest in memory), `Y` = j, `Z` = k.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    /// The i axis (slices are j–k pictures).
    X,
    /// The j axis (slices are i–k pictures).
    Y,
    /// The k axis (slices are i–j pictures).
    Z,
}

impl Axis {
    /// All three axes, in index order.
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    /// Position of this axis in `(i, j, k)`: 0, 1 or 2.
    #[must_use]
    pub const fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }

    /// The two remaining index axes `[first, second]` (as positions in `(i, j, k)`): the
    /// picture's width runs along `first`, its height along `second`.
    #[must_use]
    pub const fn in_plane(self) -> [usize; 2] {
        match self {
            Axis::X => [1, 2],
            Axis::Y => [0, 2],
            Axis::Z => [0, 1],
        }
    }
}

impl fmt::Display for Axis {
    /// `x`, `y` or `z`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
        })
    }
}

/// Where along its axis a slice is taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SlicePosition {
    /// A continuous index along the axis, in `[0, n − 1]` (voxel centres at integers). A
    /// fractional index interpolates linearly between the two neighbouring planes.
    Index(f64),
    /// A physical coordinate (mm) along the axis's physical direction — the column `d` of the
    /// direction matrix for that axis — measured from the physical origin of space, i.e. the
    /// value `d · x` shared by the points `x` of the slice plane. It maps to the index
    /// `(p − origin · d) / spacing[axis]`, which must lie in `[0, n − 1]`. For an identity
    /// direction this is simply the plane's x, y or z coordinate; for a flipped axis
    /// (`d = −e`) it is the negated coordinate. The formula is exact for orthogonal direction
    /// matrices (the usual case); with a sheared one it still defines the index as stated.
    Physical(f64),
}

impl SlicePosition {
    /// The middle plane along `axis` of a grid of `dims` voxels: the index `(n − 1) / 2`
    /// rounded down to a whole plane (the lower of the two middle planes for an even count
    /// `n`; 0 for `n ≤ 1`), so the slice is a plane of voxels, not an interpolation.
    ///
    /// ```
    /// use volmorph_volume::slice::{Axis, SlicePosition};
    /// assert_eq!(SlicePosition::middle([8, 9, 1], Axis::X), SlicePosition::Index(3.0));
    /// assert_eq!(SlicePosition::middle([8, 9, 1], Axis::Y), SlicePosition::Index(4.0));
    /// assert_eq!(SlicePosition::middle([8, 9, 1], Axis::Z), SlicePosition::Index(0.0));
    /// ```
    #[must_use]
    pub fn middle(dims: [usize; 3], axis: Axis) -> Self {
        Self::Index((dims[axis.index()].saturating_sub(1) / 2) as f64)
    }
}

/// A 2-D picture cut from a volume (see the [module documentation](self) for its layout).
#[derive(Debug, Clone, PartialEq)]
pub struct Slice {
    /// Number of columns: voxels along the first remaining index axis.
    pub width: usize,
    /// Number of rows: voxels along the second remaining index axis.
    pub height: usize,
    /// `width · height` values, row-major, top row (highest second index) first.
    pub values: Vec<f32>,
    /// Physical size of a pixel, `[spacing along first axis, spacing along second axis]`.
    pub pixel_spacing: [f64; 2],
    /// Continuous index along `axis` at which the slice was taken.
    pub index: f64,
    /// The axis the slice is perpendicular to.
    pub axis: Axis,
}

impl Slice {
    /// Pixel at column `col` and row `row` (row 0 at the top), or `None` outside the picture.
    #[must_use]
    pub fn get(&self, col: usize, row: usize) -> Option<f32> {
        if col < self.width && row < self.height {
            self.values.get(row * self.width + col).copied()
        } else {
            None
        }
    }

    /// Pixel at voxel index `a` along the first remaining axis and `b` along the second (the
    /// voxel's own indices, undoing the top-row-first flip), or `None` outside the picture.
    #[must_use]
    pub fn at_voxel(&self, a: usize, b: usize) -> Option<f32> {
        if b < self.height {
            self.get(a, self.height - 1 - b)
        } else {
            None
        }
    }
}

/// Resolve `pos` to a continuous index along `axis` of `geometry`, in `[0, n − 1]`.
///
/// # Errors
/// [`VolumeError::InvalidArgument`] if the position is not finite or its index lies outside
/// `[0, n − 1]` by more than [`POSITION_TOLERANCE`].
pub fn slice_index(
    geometry: &Geometry,
    axis: Axis,
    pos: SlicePosition,
) -> Result<f64, VolumeError> {
    let a = axis.index();
    let n = geometry.dims[a];
    let index = match pos {
        SlicePosition::Index(x) => x,
        SlicePosition::Physical(p) => {
            let d = geometry.direction.col(a);
            (p - geometry.origin.dot(d)) / geometry.spacing[a]
        }
    };
    let last = n.saturating_sub(1) as f64;
    if !index.is_finite() || index < -POSITION_TOLERANCE || index > last + POSITION_TOLERANCE {
        return Err(VolumeError::InvalidArgument(format!(
            "slice position {pos:?} along {axis} is index {index}, outside the volume's \
             [0, {last}]"
        )));
    }
    Ok(index.clamp(0.0, last))
}

/// Extract the slice of `volume` perpendicular to `axis` at `pos` (any voxel type).
///
/// # Errors
/// As [`slice_index`]: [`VolumeError::InvalidArgument`] for a non-finite or out-of-range position.
pub fn extract(volume: &AnyVolume, axis: Axis, pos: SlicePosition) -> Result<Slice, VolumeError> {
    crate::with_volume!(volume, v => extract_typed(v, axis, pos))
}

/// Extract the slice of a typed `volume` perpendicular to `axis` at `pos`.
///
/// At an integer index the values are the voxels converted with [`Voxel::to_f32`]; between
/// planes `k₀` and `k₀ + 1` they are `(1 − t)·v(k₀) + t·v(k₀ + 1)`, computed in `f64`.
///
/// # Errors
/// As [`slice_index`]: [`VolumeError::InvalidArgument`] for a non-finite or out-of-range position.
pub fn extract_typed<T: Voxel>(
    volume: &Volume<T>,
    axis: Axis,
    pos: SlicePosition,
) -> Result<Slice, VolumeError> {
    let g = volume.geometry();
    let index = slice_index(g, axis, pos)?;
    let dims = g.dims;
    let strides = [1, dims[0], dims[0] * dims[1]];
    let a = axis.index();
    let [first, second] = axis.in_plane();
    let (width, height) = (dims[first], dims[second]);
    let (sa, sb, sn) = (strides[first], strides[second], strides[a]);

    let k0 = (index.floor() as usize).min(dims[a] - 1);
    let t = index - k0 as f64;
    let base0 = k0 * sn;
    let data = volume.data();
    let mut values = Vec::with_capacity(width * height);
    if t == 0.0 {
        for r in 0..height {
            let row = base0 + (height - 1 - r) * sb;
            values.extend((0..width).map(|c| data[row + c * sa].to_f32()));
        }
    } else {
        // t > 0 implies k0 < n − 1, so plane k0 + 1 exists.
        let base1 = base0 + sn;
        for r in 0..height {
            let off = (height - 1 - r) * sb;
            values.extend((0..width).map(|c| {
                let o = off + c * sa;
                let v0 = data[base0 + o].to_f64();
                let v1 = data[base1 + o].to_f64();
                ((1.0 - t) * v0 + t * v1) as f32
            }));
        }
    }
    Ok(Slice {
        width,
        height,
        values,
        pixel_spacing: [g.spacing[first], g.spacing[second]],
        index,
        axis,
    })
}
