//! Headerless raw voxels (`.raw`).
//!
//! A raw file holds only voxel values, x fastest, with no description of dims, type, byte
//! order or geometry: reading needs a [`RawSpec`] ([`read`]). Writing ([`crate::write`]
//! with a `.raw` path) stores the voxels little-endian with no header, so **the geometry
//! (spacing, origin, direction) and even the dims and voxel type are not stored** — write a
//! MetaImage `.mhd` instead when the file must describe itself: it is the same raw data file
//! plus a small text header. [`WriteOptions`] are ignored: raw output is never compressed.

use std::path::Path;

use glam::DVec3;

use crate::WriteOptions;
use crate::text_header::{self, DataSpec, Encoding, Input, Start, os_err};
use volmorph_volume::{AnyVolume, Geometry, VolumeError, VoxelType};

const FMT: &str = "raw";

/// Everything a headerless raw file does not say about itself.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawSpec {
    /// Voxel counts along i, j, k (x fastest in the file); every entry ≥ 1.
    pub dims: [usize; 3],
    /// Type of each stored value.
    pub voxel_type: VoxelType,
    /// `true` if multi-byte values are stored most significant byte first.
    pub big_endian: bool,
    /// Bytes to skip at the start of the file (of the decompressed stream for a gzip file)
    /// before the first voxel.
    pub header_bytes: u64,
    /// Distance between voxel centres along i, j, k (physical units, > 0).
    pub spacing: DVec3,
    /// Physical position of the centre of voxel (0, 0, 0). The direction is the identity.
    pub origin: DVec3,
}

impl RawSpec {
    /// A spec for little-endian voxels with no leading header, unit spacing and zero origin.
    #[must_use]
    pub fn new(dims: [usize; 3], voxel_type: VoxelType) -> Self {
        Self {
            dims,
            voxel_type,
            big_endian: false,
            header_bytes: 0,
            spacing: DVec3::ONE,
            origin: DVec3::ZERO,
        }
    }

    /// The geometry the spec describes (identity direction).
    #[must_use]
    pub fn geometry(&self) -> Geometry {
        Geometry::new(self.dims)
            .with_spacing(self.spacing)
            .with_origin(self.origin)
    }

    /// Number of bytes the file must hold: `header_bytes + nx·ny·nz·size`.
    ///
    /// # Errors
    /// [`VolumeError::Io`] if the size overflows or exceeds the allocation limit.
    pub fn expected_len(&self) -> Result<u64, VolumeError> {
        let n = volmorph_io::checked_len(&self.dims, self.voxel_type.size())?;
        (n as u64)
            .checked_mul(self.voxel_type.size() as u64)
            .and_then(|b| b.checked_add(self.header_bytes))
            .ok_or_else(|| VolumeError::format(FMT, "header_bytes plus voxel bytes overflow a u64"))
    }
}

/// Read a headerless raw file described by `spec`. A gzip-compressed file is recognised by
/// its magic number and decompressed on the fly.
///
/// The file (after decompression) must hold exactly `spec.header_bytes + n·size` bytes,
/// `n = nx·ny·nz`; anything shorter or longer is refused, since a wrong size almost always
/// means wrong dims or type.
///
/// # Errors
/// [`VolumeError::Geometry`] for invalid dims/spacing/origin, [`VolumeError::Format`] when the
/// size does not match or the gzip stream is corrupt, I/O errors carrying the path.
pub fn read(path: &Path, spec: &RawSpec) -> Result<AnyVolume, VolumeError> {
    read_inner(path, spec).map_err(|e| e.at(path))
}

fn read_inner(path: &Path, spec: &RawSpec) -> Result<AnyVolume, VolumeError> {
    let geometry = spec.geometry();
    geometry.validate()?;
    let expected = spec.expected_len()?;
    let mut magic = [0u8; 2];
    let got = {
        use std::io::Read;
        let mut f = volmorph_io::open_regular(path)?;
        let mut k = 0;
        while k < 2 {
            match f.read(&mut magic[k..]).map_err(os_err(path))? {
                0 => break,
                m => k += m,
            }
        }
        k
    };
    let gz = got == 2 && volmorph_io::is_gzip(&magic);
    if !gz {
        let len = std::fs::metadata(path).map_err(os_err(path))?.len();
        if len != expected {
            return Err(VolumeError::format(
                FMT,
                format!(
                    "file holds {len} bytes, but dims {:?} of {} after a {}-byte header need \
                     exactly {expected}",
                    spec.dims, spec.voxel_type, spec.header_bytes
                ),
            ));
        }
    }
    let data = DataSpec {
        fmt: FMT,
        voxel_type: spec.voxel_type,
        big_endian: spec.big_endian,
        encoding: if gz { Encoding::Gzip } else { Encoding::Raw },
        start: Start::Offset(0),
        line_skip: 0,
        decoded_skip: spec.header_bytes,
        encoded_len: None,
        exact: true,
        words: None,
    };
    text_header::decode(Input::File(path), &data, geometry)
}

pub(crate) fn write(path: &Path, volume: &AnyVolume, _o: &WriteOptions) -> Result<(), VolumeError> {
    volume.geometry().validate()?;
    let os = os_err(path);
    volmorph_io::write_atomic::<VolumeError, _>(path, |w| {
        text_header::write_voxels(w, volume, false).map_err(&os)
    })
}
