use std::marker::PhantomData;

use rayon::prelude::*;

use crate::{Geometry, VolumeError, Voxel, VoxelType};

/// A typed voxel array on a physical [`Geometry`].
///
/// Invariant: `data.len() == geometry.len()` and the geometry is valid
/// ([`Geometry::validate`]). Data is stored x fastest (see [`Geometry::offset`]).
///
/// `D` is the voxel storage: an owned `Vec<T>` (the default, `Volume<T>`) or a borrowed
/// `&[T]` ([`VolumeRef`], made with [`Volume::view`] or [`VolumeRef::from_slice`]). Every
/// read-only operation, and every computation that only reads its input (samplers, warps),
/// accepts either, so a caller that holds voxels in a foreign buffer (a numpy array) passes
/// them without a copy.
#[derive(Debug, Clone, PartialEq)]
pub struct Volume<T, D = Vec<T>> {
    geometry: Geometry,
    data: D,
    voxel: PhantomData<T>,
}

/// A volume that borrows its voxels (`&[T]`); `Copy`, and as cheap to pass as a reference.
pub type VolumeRef<'a, T> = Volume<T, &'a [T]>;

impl<T: Voxel, D: AsRef<[T]> + Copy> Copy for Volume<T, D> {}

impl<'a, T: Voxel> VolumeRef<'a, T> {
    /// Borrow `data` as the voxels of `geometry` (no copy).
    ///
    /// # Errors
    /// As [`Volume::new`]: [`VolumeError::Geometry`] if the geometry is invalid,
    /// [`VolumeError::LengthMismatch`] if `data` does not hold exactly one value per voxel.
    pub fn from_slice(geometry: Geometry, data: &'a [T]) -> Result<Self, VolumeError> {
        check_len(&geometry, data.len())?;
        Ok(Self {
            geometry,
            data,
            voxel: PhantomData,
        })
    }

    /// Copy the voxels into an owned volume.
    #[must_use]
    pub fn to_owned_volume(&self) -> Volume<T> {
        Volume {
            geometry: self.geometry,
            data: self.data.to_vec(),
            voxel: PhantomData,
        }
    }
}

/// Check `geometry` and that it holds `len` voxels.
fn check_len(geometry: &Geometry, len: usize) -> Result<(), VolumeError> {
    geometry.validate()?;
    if len != geometry.len() {
        return Err(VolumeError::LengthMismatch {
            dims: geometry.dims,
            expected: geometry.len(),
            got: len,
        });
    }
    Ok(())
}

impl<T: Voxel> Volume<T> {
    /// Wrap `data` on `geometry`.
    ///
    /// # Errors
    /// [`VolumeError::Geometry`] if the geometry is invalid, [`VolumeError::LengthMismatch`] if
    /// `data` does not hold exactly one value per voxel.
    pub fn new(geometry: Geometry, data: Vec<T>) -> Result<Self, VolumeError> {
        check_len(&geometry, data.len())?;
        Ok(Self {
            geometry,
            data,
            voxel: PhantomData,
        })
    }

    /// A volume with every voxel set to `value`.
    ///
    /// # Errors
    /// [`VolumeError::Geometry`] if the geometry is invalid.
    pub fn filled(geometry: Geometry, value: T) -> Result<Self, VolumeError> {
        geometry.validate()?;
        Ok(Self {
            data: vec![value; geometry.len()],
            geometry,
            voxel: PhantomData,
        })
    }

    /// A volume whose voxel `(i, j, k)` is `f(i, j, k)`, evaluated in parallel over z-slices.
    ///
    /// # Errors
    /// [`VolumeError::Geometry`] if the geometry is invalid.
    pub fn from_fn<F>(geometry: Geometry, f: F) -> Result<Self, VolumeError>
    where
        F: Fn(usize, usize, usize) -> T + Sync,
    {
        let mut v = Self::filled(geometry, T::default())?;
        v.par_fill_with(f);
        Ok(v)
    }

    /// [`Volume::from_fn`] advancing `progress` by one step per z-slice filled (the caller
    /// announces the stage); slices are skipped once `progress` is cancelled, so the caller
    /// must check [`volmorph_io::Progress::check`] before using the volume.
    ///
    /// # Errors
    /// As [`Volume::from_fn`].
    pub fn from_fn_with<F>(
        geometry: Geometry,
        f: F,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Self, VolumeError>
    where
        F: Fn(usize, usize, usize) -> T + Sync,
    {
        let mut v = Self::filled(geometry, T::default())?;
        v.par_fill_with_progress(f, progress);
        Ok(v)
    }

    /// Overwrite every voxel with `f(i, j, k)`, in parallel over z-slices.
    pub fn par_fill_with<F>(&mut self, f: F)
    where
        F: Fn(usize, usize, usize) -> T + Sync,
    {
        self.par_fill_with_progress(f, &volmorph_io::NoProgress);
    }

    /// [`Volume::par_fill_with`] advancing `progress` by one step per z-slice; once
    /// `progress` is cancelled the remaining slices are left as they were.
    pub fn par_fill_with_progress<F>(&mut self, f: F, progress: &dyn volmorph_io::Progress)
    where
        F: Fn(usize, usize, usize) -> T + Sync,
    {
        let [nx, ny, _] = self.geometry.dims;
        self.data
            .par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(k, slab)| {
                if progress.is_cancelled() {
                    return;
                }
                for (j, row) in slab.chunks_exact_mut(nx).enumerate() {
                    for (i, v) in row.iter_mut().enumerate() {
                        *v = f(i, j, k);
                    }
                }
                progress.advance(1);
            });
    }

    /// Mutable voxels, x fastest.
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// Take the voxel buffer.
    #[must_use]
    pub fn into_data(self) -> Vec<T> {
        self.data
    }

    /// Mutable voxel `(i, j, k)`, or `None` outside the grid.
    #[inline]
    pub fn get_mut(&mut self, i: usize, j: usize, k: usize) -> Option<&mut T> {
        if self.geometry.contains_index(i, j, k) {
            let o = self.geometry.offset(i, j, k);
            Some(&mut self.data[o])
        } else {
            None
        }
    }
}

impl<T: Voxel, D: AsRef<[T]>> Volume<T, D> {
    /// The physical geometry.
    #[must_use]
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// A borrowed view of the voxels (no copy); what the read-only computations take.
    #[must_use]
    pub fn view(&self) -> VolumeRef<'_, T> {
        Volume {
            geometry: self.geometry,
            data: self.data.as_ref(),
            voxel: PhantomData,
        }
    }

    /// Replace the geometry, keeping the voxels (dims must stay the same).
    ///
    /// # Errors
    /// [`VolumeError::Geometry`] if the new geometry is invalid or has other dims.
    pub fn set_geometry(&mut self, geometry: Geometry) -> Result<(), VolumeError> {
        geometry.validate()?;
        if geometry.dims != self.geometry.dims {
            return Err(VolumeError::Geometry(format!(
                "cannot change dims from {:?} to {:?}",
                self.geometry.dims, geometry.dims
            )));
        }
        self.geometry = geometry;
        Ok(())
    }

    /// Voxel counts along i, j, k.
    #[must_use]
    pub fn dims(&self) -> [usize; 3] {
        self.geometry.dims
    }

    /// Number of voxels.
    #[must_use]
    pub fn len(&self) -> usize {
        self.data.as_ref().len()
    }

    /// Always `false` for a valid volume (dims are ≥ 1); present for API symmetry.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.data.as_ref().is_empty()
    }

    /// The voxels, x fastest.
    #[must_use]
    pub fn data(&self) -> &[T] {
        self.data.as_ref()
    }

    /// Voxel `(i, j, k)`, or `None` outside the grid.
    #[inline]
    #[must_use]
    pub fn get(&self, i: usize, j: usize, k: usize) -> Option<T> {
        self.geometry
            .contains_index(i, j, k)
            .then(|| self.data.as_ref()[self.geometry.offset(i, j, k)])
    }

    /// The z-slice `k` as a contiguous `nx·ny` slice, or `None` if `k` is out of range.
    #[must_use]
    pub fn z_slice(&self, k: usize) -> Option<&[T]> {
        let n = self.geometry.dims[0] * self.geometry.dims[1];
        self.data.as_ref().get(k * n..(k + 1) * n)
    }

    /// Apply `f` to every voxel, producing a volume of another type on the same geometry.
    #[must_use]
    pub fn map<U: Voxel, F: Fn(T) -> U + Sync>(&self, f: F) -> Volume<U> {
        Volume {
            geometry: self.geometry,
            data: self.data.as_ref().par_iter().map(|&v| f(v)).collect(),
            voxel: PhantomData,
        }
    }

    /// Convert to voxel type `U` with [`Voxel::from_f64`] (rounding, saturating).
    #[must_use]
    pub fn cast<U: Voxel>(&self) -> Volume<U> {
        self.map(|v| U::from_f64(v.to_f64()))
    }

    /// Convert to `U` after the linear map `v ↦ v·slope + inter` (computed in `f64`).
    #[must_use]
    pub fn cast_scaled<U: Voxel>(&self, slope: f64, inter: f64) -> Volume<U> {
        self.map(|v| U::from_f64(v.to_f64().mul_add(slope, inter)))
    }
}

impl<T: Voxel, D: AsRef<[T]>> std::ops::Index<[usize; 3]> for Volume<T, D> {
    type Output = T;
    /// # Panics
    /// If the index is outside the grid.
    fn index(&self, [i, j, k]: [usize; 3]) -> &T {
        assert!(
            self.geometry.contains_index(i, j, k),
            "voxel ({i}, {j}, {k}) outside dims {:?}",
            self.geometry.dims
        );
        &self.data.as_ref()[self.geometry.offset(i, j, k)]
    }
}

impl<T: Voxel> std::ops::IndexMut<[usize; 3]> for Volume<T> {
    /// # Panics
    /// If the index is outside the grid.
    fn index_mut(&mut self, [i, j, k]: [usize; 3]) -> &mut T {
        assert!(
            self.geometry.contains_index(i, j, k),
            "voxel ({i}, {j}, {k}) outside dims {:?}",
            self.geometry.dims
        );
        let o = self.geometry.offset(i, j, k);
        &mut self.data[o]
    }
}

/// A volume whose voxel type is known only at run time (as read from a file).
#[derive(Debug, Clone, PartialEq)]
#[allow(missing_docs)] // one variant per VoxelType, named alike
pub enum AnyVolume {
    U8(Volume<u8>),
    I8(Volume<i8>),
    U16(Volume<u16>),
    I16(Volume<i16>),
    U32(Volume<u32>),
    I32(Volume<i32>),
    F32(Volume<f32>),
    F64(Volume<f64>),
}

/// Run `$body` with `$v` bound to the typed volume inside an [`AnyVolume`].
///
/// ```
/// use volmorph_volume::{AnyVolume, Geometry, Volume, with_volume};
/// let any = AnyVolume::from(Volume::filled(Geometry::new([2, 2, 2]), 7u16).unwrap());
/// let n = with_volume!(&any, v => v.len());
/// assert_eq!(n, 8);
/// ```
#[macro_export]
macro_rules! with_volume {
    ($any:expr, $v:ident => $body:expr) => {
        match $any {
            $crate::AnyVolume::U8($v) => $body,
            $crate::AnyVolume::I8($v) => $body,
            $crate::AnyVolume::U16($v) => $body,
            $crate::AnyVolume::I16($v) => $body,
            $crate::AnyVolume::U32($v) => $body,
            $crate::AnyVolume::I32($v) => $body,
            $crate::AnyVolume::F32($v) => $body,
            $crate::AnyVolume::F64($v) => $body,
        }
    };
}

/// Run `$body` with the type alias `$t` bound to the Rust type of a [`VoxelType`].
///
/// The one dispatch from a run-time voxel type to generic code: readers decode into
/// `Vec<$t>`, casts convert into `Volume<$t>`. Each arm evaluates `$body` once, so its
/// value must have the same type for every voxel type (typically an [`AnyVolume`] or a
/// `Result` of one).
///
/// ```
/// use volmorph_volume::{VoxelType, with_voxel_type};
/// let bytes = with_voxel_type!(VoxelType::I16, T => std::mem::size_of::<T>());
/// assert_eq!(bytes, 2);
/// let name = with_voxel_type!(VoxelType::F64, T => std::any::type_name::<T>());
/// assert_eq!(name, "f64");
/// ```
#[macro_export]
macro_rules! with_voxel_type {
    ($vt:expr, $t:ident => $body:expr) => {
        match $vt {
            $crate::VoxelType::U8 => {
                type $t = u8;
                $body
            }
            $crate::VoxelType::I8 => {
                type $t = i8;
                $body
            }
            $crate::VoxelType::U16 => {
                type $t = u16;
                $body
            }
            $crate::VoxelType::I16 => {
                type $t = i16;
                $body
            }
            $crate::VoxelType::U32 => {
                type $t = u32;
                $body
            }
            $crate::VoxelType::I32 => {
                type $t = i32;
                $body
            }
            $crate::VoxelType::F32 => {
                type $t = f32;
                $body
            }
            $crate::VoxelType::F64 => {
                type $t = f64;
                $body
            }
        }
    };
}

macro_rules! any_from {
    ($($t:ty => $tag:ident),*) => {$(
        impl From<Volume<$t>> for AnyVolume {
            fn from(v: Volume<$t>) -> Self { AnyVolume::$tag(v) }
        }
    )*};
}
any_from!(u8 => U8, i8 => I8, u16 => U16, i16 => I16, u32 => U32, i32 => I32, f32 => F32, f64 => F64);

impl AnyVolume {
    /// A borrowed view of the voxels (no copy); see [`AnyVolumeRef`].
    #[must_use]
    pub fn view(&self) -> AnyVolumeRef<'_> {
        with_volume!(self, v => AnyVolumeRef::from(v.view()))
    }

    /// The run-time voxel type.
    #[must_use]
    pub fn voxel_type(&self) -> VoxelType {
        match self {
            Self::U8(_) => VoxelType::U8,
            Self::I8(_) => VoxelType::I8,
            Self::U16(_) => VoxelType::U16,
            Self::I16(_) => VoxelType::I16,
            Self::U32(_) => VoxelType::U32,
            Self::I32(_) => VoxelType::I32,
            Self::F32(_) => VoxelType::F32,
            Self::F64(_) => VoxelType::F64,
        }
    }

    /// The physical geometry.
    #[must_use]
    pub fn geometry(&self) -> &Geometry {
        with_volume!(self, v => v.geometry())
    }

    /// Replace the geometry (same dims).
    ///
    /// # Errors
    /// As [`Volume::set_geometry`].
    pub fn set_geometry(&mut self, geometry: Geometry) -> Result<(), VolumeError> {
        with_volume!(self, v => v.set_geometry(geometry))
    }

    /// Convert to a typed volume of `U` (rounding and saturating, see [`Voxel::from_f64`]).
    #[must_use]
    pub fn to_typed<U: Voxel>(&self) -> Volume<U> {
        with_volume!(self, v => v.cast::<U>())
    }

    /// Largest absolute difference `|a − b|` between corresponding voxels of `self` and
    /// `other`, both read as `f64` (any voxel types); differences that are NaN (a NaN voxel
    /// on either side) are skipped. 0 for identical volumes. Geometry other than the dims is
    /// not compared.
    ///
    /// # Errors
    /// [`VolumeError::InvalidArgument`] when the dims differ.
    pub fn max_abs_difference(&self, other: &AnyVolume) -> Result<f64, VolumeError> {
        let (da, db) = (self.geometry().dims, other.geometry().dims);
        if da != db {
            return Err(VolumeError::InvalidArgument(format!(
                "cannot compare volumes of {da:?} and {db:?} voxels"
            )));
        }
        Ok(with_volume!(self, a => with_volume!(other, b => a
            .data()
            .iter()
            .zip(b.data())
            .map(|(&x, &y)| (x.to_f64() - y.to_f64()).abs())
            .fold(0.0, f64::max))))
    }

    /// Convert to another run-time type, optionally through `v·slope + inter`.
    #[must_use]
    pub fn cast(&self, to: VoxelType, slope: f64, inter: f64) -> AnyVolume {
        with_voxel_type!(to, T => with_volume!(self, v => AnyVolume::from(v.cast_scaled::<T>(slope, inter))))
    }

    /// Convert to `to`, mapping the input's finite value range `[min, max]` linearly onto
    /// `range` (`(lo, hi)`; `lo > hi` inverts), or by default onto the full range of an
    /// integer type or `[0, 1]` for a float type. A constant input maps to `lo`; NaN inputs
    /// stay NaN in float outputs (0 in integer outputs).
    ///
    /// # Errors
    /// [`VolumeError::InvalidArgument`] when `lo` or `hi` is not finite, `lo == hi`, either
    /// lies outside what `to` can hold (so the output would saturate or be infinite), the
    /// input has no finite value, or the slope overflows.
    pub fn rescaled(
        &self,
        to: VoxelType,
        range: Option<(f64, f64)>,
    ) -> Result<AnyVolume, VolumeError> {
        let (lo, hi) = range.unwrap_or(if to.is_float() {
            (0.0, 1.0)
        } else {
            to.range()
        });
        let bad = |m: String| {
            VolumeError::InvalidArgument(format!(
                "rescale range {},{}: {m}",
                volmorph_io::Num(lo),
                volmorph_io::Num(hi)
            ))
        };
        if !(lo.is_finite() && hi.is_finite()) {
            return Err(bad("both ends must be finite numbers".into()));
        }
        if lo == hi {
            return Err(bad("the ends must differ".into()));
        }
        let (tmin, tmax) = to.range();
        for v in [lo, hi] {
            if !(tmin..=tmax).contains(&v) {
                return Err(bad(format!(
                    "{} lies outside what {to} can hold ({}, {})",
                    volmorph_io::Num(v),
                    volmorph_io::Num(tmin),
                    volmorph_io::Num(tmax)
                )));
            }
        }
        let st = crate::stats::Statistics::of_any(self);
        if st.finite == 0 {
            return Err(VolumeError::InvalidArgument(
                "no finite values to rescale".into(),
            ));
        }
        let (slope, inter) = if st.max > st.min {
            let slope = (hi - lo) / (st.max - st.min);
            (slope, lo - st.min * slope)
        } else {
            (0.0, lo)
        };
        if !(slope.is_finite() && inter.is_finite()) {
            return Err(bad(format!(
                "mapping the input range [{}, {}] onto it overflows",
                volmorph_io::Num(st.min),
                volmorph_io::Num(st.max)
            )));
        }
        Ok(self.cast(to, slope, inter))
    }

    /// The voxels as raw native-endian bytes.
    #[must_use]
    pub fn as_bytes(&self) -> &[u8] {
        with_volume!(self, v => bytemuck::cast_slice(v.data()))
    }
}

/// A borrowed [`AnyVolume`]: the voxels of one run-time type, read in place (`&[T]`).
///
/// What the read-only computations of run-time-typed volumes take (warps, isosurfaces);
/// `&AnyVolume` converts to it without a copy ([`AnyVolume::view`], `From`), and so does a
/// [`VolumeRef`] over a foreign buffer.
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(missing_docs)] // one variant per VoxelType, named alike
pub enum AnyVolumeRef<'a> {
    U8(VolumeRef<'a, u8>),
    I8(VolumeRef<'a, i8>),
    U16(VolumeRef<'a, u16>),
    I16(VolumeRef<'a, i16>),
    U32(VolumeRef<'a, u32>),
    I32(VolumeRef<'a, i32>),
    F32(VolumeRef<'a, f32>),
    F64(VolumeRef<'a, f64>),
}

/// Run `$body` with `$v` bound to the typed [`VolumeRef`] inside an [`AnyVolumeRef`]
/// (as [`with_volume!`] for owned volumes).
///
/// ```
/// use volmorph_volume::{AnyVolume, Geometry, Volume, with_volume_ref};
/// let any = AnyVolume::from(Volume::filled(Geometry::new([2, 2, 2]), 7u16).unwrap());
/// let n = with_volume_ref!(any.view(), v => v.len());
/// assert_eq!(n, 8);
/// ```
#[macro_export]
macro_rules! with_volume_ref {
    ($any:expr, $v:ident => $body:expr) => {
        match $any {
            $crate::AnyVolumeRef::U8($v) => $body,
            $crate::AnyVolumeRef::I8($v) => $body,
            $crate::AnyVolumeRef::U16($v) => $body,
            $crate::AnyVolumeRef::I16($v) => $body,
            $crate::AnyVolumeRef::U32($v) => $body,
            $crate::AnyVolumeRef::I32($v) => $body,
            $crate::AnyVolumeRef::F32($v) => $body,
            $crate::AnyVolumeRef::F64($v) => $body,
        }
    };
}

macro_rules! any_ref_from {
    ($($t:ty => $tag:ident),*) => {$(
        impl<'a> From<VolumeRef<'a, $t>> for AnyVolumeRef<'a> {
            fn from(v: VolumeRef<'a, $t>) -> Self { AnyVolumeRef::$tag(v) }
        }
    )*};
}
any_ref_from!(u8 => U8, i8 => I8, u16 => U16, i16 => I16, u32 => U32, i32 => I32, f32 => F32, f64 => F64);

impl<'a> From<&'a AnyVolume> for AnyVolumeRef<'a> {
    fn from(v: &'a AnyVolume) -> Self {
        v.view()
    }
}

impl AnyVolumeRef<'_> {
    /// The run-time voxel type.
    #[must_use]
    pub fn voxel_type(&self) -> VoxelType {
        with_volume_ref!(self, v => v_type(v))
    }

    /// The physical geometry.
    #[must_use]
    pub fn geometry(&self) -> &Geometry {
        with_volume_ref!(self, v => v.geometry())
    }

    /// Copy the voxels into an owned [`AnyVolume`].
    #[must_use]
    pub fn to_owned_volume(&self) -> AnyVolume {
        with_volume_ref!(self, v => AnyVolume::from(v.to_owned_volume()))
    }
}

/// The voxel type of a typed volume.
fn v_type<T: Voxel, D>(_: &Volume<T, D>) -> VoxelType {
    T::TYPE
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn new_checks_length_and_geometry() {
        let g = Geometry::new([2, 3, 4]);
        assert!(Volume::new(g, vec![0u8; 24]).is_ok());
        assert!(matches!(
            Volume::new(g, vec![0u8; 23]),
            Err(VolumeError::LengthMismatch {
                expected: 24,
                got: 23,
                ..
            })
        ));
        assert!(Volume::new(Geometry::new([2, 0, 4]), Vec::<u8>::new()).is_err());
    }

    #[test]
    fn views_borrow_the_voxels_and_check_their_length() {
        let mut g = Geometry::new([2, 3, 4]);
        g.spacing = DVec3::new(0.5, 1.0, 2.0);
        let data: Vec<f32> = (0..24u8).map(f32::from).collect();
        let owned = Volume::new(g, data.clone()).unwrap();
        let view = VolumeRef::from_slice(g, &data).unwrap();
        // Same voxels and geometry, read from the caller's buffer in place.
        assert_eq!(view.data().as_ptr(), data.as_ptr());
        assert_eq!(view, owned.view());
        assert_eq!(view[[1, 2, 3]], owned[[1, 2, 3]]);
        assert_eq!(view.get(1, 0, 2), owned.get(1, 0, 2));
        assert_eq!(view.z_slice(3), owned.z_slice(3));
        assert_eq!(view.to_owned_volume(), owned);
        let any = AnyVolume::from(owned.clone());
        assert_eq!(any.view(), AnyVolumeRef::from(view));
        assert_eq!(any.view().voxel_type(), VoxelType::F32);
        assert_eq!(any.view().to_owned_volume(), any);
        assert!(matches!(
            VolumeRef::from_slice(g, &data[..23]),
            Err(VolumeError::LengthMismatch {
                expected: 24,
                got: 23,
                ..
            })
        ));
        assert!(VolumeRef::<u8>::from_slice(Geometry::new([0, 1, 1]), &[]).is_err());
    }

    #[test]
    fn max_abs_difference_compares_across_voxel_types() {
        let g = Geometry::new([3, 2, 2]);
        let a = AnyVolume::from(Volume::from_fn(g, |i, j, k| (i + 3 * j + 6 * k) as u8).unwrap());
        let mut data: Vec<f32> = (0..12).map(|i| i as f32).collect();
        let same = AnyVolume::from(Volume::new(g, data.clone()).unwrap());
        assert_eq!(a.max_abs_difference(&same).unwrap(), 0.0);
        data[7] = 9.5;
        data[2] = f32::NAN;
        let b = AnyVolume::from(Volume::new(g, data).unwrap());
        assert_eq!(a.max_abs_difference(&b).unwrap(), 2.5);
        assert_eq!(b.max_abs_difference(&a).unwrap(), 2.5);
        let other = AnyVolume::from(Volume::new(Geometry::new([2, 3, 2]), vec![0u8; 12]).unwrap());
        assert!(matches!(
            a.max_abs_difference(&other),
            Err(VolumeError::InvalidArgument(_))
        ));
    }

    #[test]
    fn from_fn_is_x_fastest() {
        let v = Volume::from_fn(Geometry::new([3, 4, 5]), |i, j, k| {
            (i + 10 * j + 100 * k) as u16
        })
        .unwrap();
        assert_eq!(v.data()[1], 1);
        assert_eq!(v.data()[3], 10);
        assert_eq!(v.data()[12], 100);
        assert_eq!(v[[2, 3, 4]], 432);
        assert_eq!(v.get(3, 0, 0), None);
        assert_eq!(v.z_slice(1).unwrap()[0], 100);
    }

    #[test]
    fn cast_rounds_saturates_and_keeps_geometry() {
        let g = Geometry::new([2, 1, 1]).with_origin(DVec3::new(1.0, 2.0, 3.0));
        let v = Volume::new(g, vec![-5.6f32, 300.4]).unwrap();
        let any = AnyVolume::from(v);
        let u = any.cast(VoxelType::U8, 1.0, 0.0);
        assert_eq!(u.voxel_type(), VoxelType::U8);
        assert_eq!(u.as_bytes(), &[0, 255]);
        assert_eq!(u.geometry(), &g);
        let s = any.cast(VoxelType::I16, 2.0, 1.0);
        assert_eq!(s.to_typed::<i16>().data(), &[-10, 602]);
    }
}
