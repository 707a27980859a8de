//! Vector images with three components per voxel — ITK's `Image<Vector<double, 3>, 3>`, the
//! form in which ITK, ANTs and elastix store dense displacement fields.
//!
//! | extension | layout |
//! | --- | --- |
//! | `.nii`, `.nii.gz` | NIfTI-1 (NIfTI-2 beyond 16-bit sizes), `dim = [5, nx, ny, nz, 1, 3]`, `intent_code` 1007 (`NIFTI_INTENT_VECTOR`; 1006 `NIFTI_INTENT_DISPVECT` is read too), the three components stored one whole 3-D block after another, as ITK writes them |
//! | `.mha`, `.mhd` (+ data file) | MetaImage with `ElementNumberOfChannels = 3`, the components interleaved per voxel |
//!
//! The geometry is read and written exactly as for volumes (ITK's rules; NIfTI's RAS header
//! becomes LPS). The vector components are **not** converted: ITK keeps them in its physical
//! (LPS) frame in both formats (checked with SimpleITK 2.5.7: a vector `(1, 2, 3)` is stored as
//! `1, 2, 3` in a NIfTI file). Values are read from any voxel type the format has (as `f64`,
//! NIfTI `scl_slope`/`scl_inter` applied) and written as `f64` or `f32`.

use std::path::Path;

use glam::DVec3;
use volmorph_volume::direction::snap_direction;
use volmorph_volume::{Geometry, VolumeError, VoxelType};

use crate::{Format, Header, ReadOptions, WriteOptions, metaimage, nifti};

/// A 3-component vector image: one vector per voxel of `geometry`, x fastest
/// (`vectors[i + nx·(j + ny·k)]` belongs to voxel `(i, j, k)`).
#[derive(Debug, Clone, PartialEq)]
pub struct VectorImage {
    /// The voxel grid (ITK physical space).
    pub geometry: Geometry,
    /// One vector per voxel, in the physical frame (LPS), x fastest.
    pub vectors: Vec<DVec3>,
}

impl VectorImage {
    /// A vector image, checked.
    ///
    /// # Errors
    /// [`VolumeError::Geometry`] for an invalid geometry, [`VolumeError::InvalidArgument`] for
    /// a vector count other than the voxel count or a non-finite vector.
    pub fn new(geometry: Geometry, vectors: Vec<DVec3>) -> Result<Self, VolumeError> {
        geometry.validate()?;
        if vectors.len() != geometry.len() {
            return Err(VolumeError::InvalidArgument(format!(
                "{} vectors for a grid of {} voxels",
                vectors.len(),
                geometry.len()
            )));
        }
        if let Some(i) = vectors.iter().position(|v| !v.is_finite()) {
            return Err(VolumeError::InvalidArgument(format!(
                "vector {i} is not finite"
            )));
        }
        Ok(Self { geometry, vectors })
    }
}

/// The precision of the values written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum VectorPrecision {
    /// 64-bit floats (ITK's `VectorFloat64`, what `DisplacementFieldTransform` holds).
    #[default]
    F64,
    /// 32-bit floats (what ANTs writes; half the size).
    F32,
}

/// The vector-image format of `path`, by extension.
///
/// # Errors
/// [`VolumeError::Unsupported`] for a format that volmorph does not read or write vector
/// images in.
pub fn vector_format(path: &Path) -> Result<Format, VolumeError> {
    match Format::from_path(path) {
        Ok(f @ (Format::Nifti | Format::MetaImage)) => Ok(f),
        _ => Err(VolumeError::Unsupported(format!(
            "{}: vector images (displacement fields) are read and written as .nii, .nii.gz, \
             .mha or .mhd",
            path.display()
        ))),
    }
}

/// Read a 3-component vector image with default [`ReadOptions`] (see the [module docs](self)).
/// The direction goes through [`snap_direction`] as for volumes ([`crate::read_with`]).
///
/// # Errors
/// [`VolumeError::Unsupported`] for another extension or an image without three components
/// per voxel; the format's errors otherwise; every error names `path`.
pub fn read_vector(path: &Path) -> Result<(VectorImage, Header), VolumeError> {
    read_vector_with(path, &ReadOptions::default())
}

/// [`read_vector`] with `options` (a detached MetaImage data file outside the header's folder
/// needs [`ReadOptions::allow_external_data`]).
///
/// # Errors
/// As [`read_vector`].
pub fn read_vector_with(
    path: &Path,
    options: &ReadOptions,
) -> Result<(VectorImage, Header), VolumeError> {
    let read = || -> Result<(VectorImage, Header), VolumeError> {
        let (mut g, vectors, header) = match vector_format(path)? {
            Format::Nifti => nifti::read_vector(path)?,
            _ => metaimage::read_vector(path, options)?,
        };
        g.direction = snap_direction(g.direction);
        Ok((VectorImage::new(g, vectors)?, header))
    };
    read().map_err(|e| e.at(path))
}

/// Write a 3-component vector image (see the [module docs](self)); the file appears only when
/// complete. MetaImage honours [`WriteOptions::compress`]; NIfTI is compressed by a `.gz` name.
///
/// # Errors
/// [`VolumeError::Unsupported`] for another extension; I/O errors; every error names `path`.
pub fn write_vector(
    path: &Path,
    image: &VectorImage,
    precision: VectorPrecision,
    options: &WriteOptions,
) -> Result<(), VolumeError> {
    let t = match precision {
        VectorPrecision::F64 => VoxelType::F64,
        VectorPrecision::F32 => VoxelType::F32,
    };
    let write = || -> Result<(), VolumeError> {
        if image.vectors.len() != image.geometry.len() {
            return Err(VolumeError::InvalidArgument(format!(
                "{} vectors for a grid of {} voxels",
                image.vectors.len(),
                image.geometry.len()
            )));
        }
        match vector_format(path)? {
            Format::Nifti => nifti::write_vector(path, &image.geometry, &image.vectors, t, options),
            _ => metaimage::write_vector(path, &image.geometry, &image.vectors, t, options),
        }
    };
    write().map_err(|e| e.at(path))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DMat3;

    fn image() -> VectorImage {
        let mut g = Geometry::new([4, 3, 2]);
        g.spacing = DVec3::new(1.5, 2.0, 0.75);
        g.origin = DVec3::new(-10.0, 4.0, 7.25);
        let (s, c) = 0.3f64.sin_cos();
        g.direction = DMat3::from_cols(DVec3::new(c, s, 0.0), DVec3::new(-s, c, 0.0), DVec3::Z);
        let vectors = (0..g.len())
            .map(|i| DVec3::new(i as f64 * 0.1, -(i as f64), 1.0 / (1.0 + i as f64)))
            .collect();
        VectorImage::new(g, vectors).unwrap()
    }

    #[test]
    fn vector_images_round_trip_in_every_format() {
        let dir = tempfile::tempdir().unwrap();
        let im = image();
        for name in ["f.nii", "f.nii.gz", "f.mha", "f.mhd"] {
            for precision in [VectorPrecision::F64, VectorPrecision::F32] {
                for compress in [false, true] {
                    let p = dir.path().join(name);
                    let o = WriteOptions {
                        compress,
                        ..WriteOptions::default()
                    };
                    write_vector(&p, &im, precision, &o).unwrap();
                    let (back, _) = read_vector(&p).unwrap();
                    assert_eq!(back.geometry.dims, im.geometry.dims, "{name}");
                    // NIfTI keeps geometry in f32.
                    let tol = if name.starts_with("f.nii") { 1e-5 } else { 0.0 };
                    assert!(
                        (back.geometry.origin - im.geometry.origin)
                            .abs()
                            .max_element()
                            <= tol
                    );
                    assert!(
                        (back.geometry.direction - im.geometry.direction)
                            .abs()
                            .to_cols_array()
                            .iter()
                            .all(|d| *d <= tol.max(1e-7))
                    );
                    for (a, b) in back.vectors.iter().zip(&im.vectors) {
                        let vt = if precision == VectorPrecision::F64 {
                            0.0
                        } else {
                            1e-6 * b.abs().max_element().max(1.0)
                        };
                        assert!((*a - *b).abs().max_element() <= vt, "{name} {a} {b}");
                    }
                }
            }
        }
    }

    #[test]
    fn nifti_vector_header_is_itks_layout() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.nii");
        let im = image();
        write_vector(&p, &im, VectorPrecision::F64, &WriteOptions::default()).unwrap();
        let b = std::fs::read(&p).unwrap();
        let i16_at = |o: usize| i16::from_le_bytes([b[o], b[o + 1]]);
        let dims: Vec<i16> = (0..8).map(|i| i16_at(40 + 2 * i)).collect();
        assert_eq!(dims, [5, 4, 3, 2, 1, 3, 1, 1]);
        assert_eq!(i16_at(68), 1007); // intent_code
        assert_eq!(i16_at(70), 64); // float64
        // Planar: the x components of every voxel first.
        let f = |k: usize| f64::from_le_bytes(b[352 + 8 * k..360 + 8 * k].try_into().unwrap());
        let n = im.geometry.len();
        assert_eq!(f(1), im.vectors[1].x);
        assert_eq!(f(n + 2), im.vectors[2].y);
        assert_eq!(f(2 * n + 5), im.vectors[5].z);
        // A vector image is not a volume, and a volume is not a vector image.
        let e = crate::read(&p).unwrap_err().to_string();
        assert!(e.contains("vector"), "{e}");
        let scalar = dir.path().join("s.nii");
        let v = volmorph_volume::AnyVolume::from(
            volmorph_volume::Volume::new(Geometry::new([2, 2, 2]), vec![0f32; 8]).unwrap(),
        );
        crate::write(&scalar, &v).unwrap();
        let e = read_vector(&scalar).unwrap_err().to_string();
        assert!(e.contains("3 components"), "{e}");
    }

    #[test]
    fn metaimage_vector_header_names_three_channels() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.mha");
        write_vector(&p, &image(), VectorPrecision::F32, &WriteOptions::default()).unwrap();
        let b = std::fs::read(&p).unwrap();
        let text = String::from_utf8_lossy(&b[..400]);
        assert!(text.contains("ElementNumberOfChannels = 3\nElementType = MET_FLOAT"));
        let e = crate::read(&p).unwrap_err().to_string();
        assert!(e.contains("ElementNumberOfChannels = 3"), "{e}");
        // Truncated data are refused, not padded.
        let cut = dir.path().join("cut.mha");
        std::fs::write(&cut, &b[..b.len() - 4]).unwrap();
        assert!(read_vector(&cut).is_err());
        assert!(read_vector(&dir.path().join("x.vtk")).is_err());
    }
}
