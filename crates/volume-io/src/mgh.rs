//! FreeSurfer MGH volumes (`.mgh`, and gzip-compressed `.mgz`).
//!
//! # Layout (FreeSurfer `mghread`/`mghwrite`, all big-endian)
//!
//! | bytes | field |
//! | --- | --- |
//! | 0–3 | `version` = 1 |
//! | 4–19 | `width`, `height`, `depth`, `nframes` (int32) |
//! | 20–23 | `type`: 0 uchar, 1 int32, 3 float32, 4 int16 |
//! | 24–27 | `dof` |
//! | 28–29 | `goodRASFlag` (int16) |
//! | 30–41 | voxel sizes `xsize ysize zsize` (float32) |
//! | 42–77 | `Mdc`: the unit directions of the column, row and slice axes in RAS, as `x_r x_a x_s y_r … z_s` |
//! | 78–89 | `c_r c_a c_s`: the RAS position of the volume centre |
//! | 284– | voxels, x fastest, then the frames one after another; optional tags follow |
//!
//! # Geometry
//!
//! FreeSurfer's voxel-to-RAS map is `M = Mdc · diag(sizes)` with offset
//! `P₀ = c_ras − M · (width/2, height/2, depth/2)` (halves in floating point, as
//! FreeSurfer and nibabel compute them). volmorph converts it to ITK's LPS convention like a
//! NIfTI affine: origin `(−P₀x, −P₀y, P₀z)`, direction columns `(−m₀, −m₁, m₂)` of each
//! normalised `Mdc` column, spacing = the voxel sizes. A file whose `goodRASFlag` is not 1 has
//! no valid geometry fields; FreeSurfer then assumes 1 mm voxels in coronal LIA orientation
//! centred at the origin (`Mdc` columns `(−1,0,0)`, `(0,0,−1)`, `(0,1,0)`), and so does
//! volmorph. A volume with several frames is a 4-D series; one frame is read at a time
//! ([`crate::ReadOptions::frame`]).
//!
//! # Writing
//!
//! Version 1, one frame, `goodRASFlag = 1`, geometry in single precision (what the format
//! stores), types u8, i16, i32 and f32 (others are refused, naming them); gzip when the name
//! ends in `.mgz`. The direction must be orthonormal (FreeSurfer's `Mdc` is a rotation).

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;

use flate2::Compression;
use flate2::bufread::MultiGzDecoder;
use flate2::write::GzEncoder;
use glam::{DMat3, DVec3};
use volmorph_io::{ByteReader, checked_len, is_gzip, write_atomic};

use crate::text_header::{os_err, to_native, write_voxels};
use crate::{Header, WriteOptions};
use volmorph_volume::{AnyVolume, Geometry, Volume, VolumeError, VoxelType};

const FMT: &str = "FreeSurfer MGH";
/// Offset of the voxel data (`MGH_HEADER_SIZE` rounded up by FreeSurfer's unused space).
const DATA_OFFSET: usize = 284;
/// Bytes of the header that carry fields.
const FIELDS_LEN: usize = 90;

fn err(msg: impl Into<String>) -> VolumeError {
    VolumeError::format(FMT, msg)
}

fn voxel_type(code: i32) -> Result<VoxelType, VolumeError> {
    Ok(match code {
        0 => VoxelType::U8,
        1 => VoxelType::I32,
        3 => VoxelType::F32,
        4 => VoxelType::I16,
        2 => {
            return Err(VolumeError::Unsupported(
                "MGH type 2 (MRI_LONG) is not supported".into(),
            ));
        }
        c => {
            return Err(err(format!(
                "type {c} is not an MGH voxel type (0, 1, 3, 4)"
            )));
        }
    })
}

fn type_code(t: VoxelType) -> Result<i32, VolumeError> {
    Ok(match t {
        VoxelType::U8 => 0,
        VoxelType::I32 => 1,
        VoxelType::F32 => 3,
        VoxelType::I16 => 4,
        other => {
            return Err(VolumeError::Unsupported(format!(
                "MGH stores u8, i16, i32 and f32 voxels, not {other}; convert with --type"
            )));
        }
    })
}

/// The parsed header.
struct Mgh {
    dims: [usize; 3],
    frames: usize,
    voxel_type: VoxelType,
    geometry: Geometry,
    header: Header,
}

fn parse(bytes: &[u8]) -> Result<Mgh, VolumeError> {
    if bytes.len() < FIELDS_LEN {
        return Err(err(format!(
            "file too short for a header: {} bytes",
            bytes.len()
        )));
    }
    let mut r = ByteReader::new(bytes, true);
    let t = |e: volmorph_io::Truncated| VolumeError::Io(e.into());
    let version = r.i32().map_err(t)?;
    if version != 1 {
        return Err(err(format!(
            "version is {version}; an MGH file has 1 (is this an MGH file?)"
        )));
    }
    let mut d = [0i32; 4];
    for v in &mut d {
        *v = r.i32().map_err(t)?;
    }
    let code = r.i32().map_err(t)?;
    let dof = r.i32().map_err(t)?;
    let good = r.i16().map_err(t)?;
    let mut f = [0f32; 15];
    for v in &mut f {
        *v = r.f32().map_err(t)?;
    }
    let names = ["width", "height", "depth", "nframes"];
    let mut sizes = [0usize; 4];
    for a in 0..4 {
        if d[a] <= 0 {
            return Err(err(format!(
                "{} = {}, sizes must be positive",
                names[a], d[a]
            )));
        }
        sizes[a] = d[a] as usize;
    }
    let voxel_type = voxel_type(code)?;
    let dims = [sizes[0], sizes[1], sizes[2]];
    checked_len(&[sizes[0], sizes[1], sizes[2], sizes[3]], voxel_type.size())?;
    let (sizes_mm, mdc, c_ras) = if good == 1 {
        if f.iter().any(|v| !v.is_finite()) {
            return Err(err("a voxel size, direction or centre value is not finite"));
        }
        let s = DVec3::new(f64::from(f[0]), f64::from(f[1]), f64::from(f[2]));
        let col = |k: usize| {
            DVec3::new(
                f64::from(f[3 + 3 * k]),
                f64::from(f[4 + 3 * k]),
                f64::from(f[5 + 3 * k]),
            )
        };
        let mdc = DMat3::from_cols(col(0), col(1), col(2));
        let c = DVec3::new(f64::from(f[12]), f64::from(f[13]), f64::from(f[14]));
        (s, mdc, c)
    } else {
        // FreeSurfer's default: 1 mm coronal LIA, centred at the origin.
        let lia = DMat3::from_cols(DVec3::new(-1.0, 0.0, 0.0), DVec3::NEG_Z, DVec3::Y);
        (DVec3::ONE, lia, DVec3::ZERO)
    };
    let mut cols = [DVec3::ZERO; 3];
    for (k, c) in cols.iter_mut().enumerate() {
        let m = mdc.col(k);
        let n = m.length();
        if n.is_nan() || n <= 0.0 {
            return Err(err(format!("direction column {k} of Mdc is zero")));
        }
        *c = m / n;
    }
    // FreeSurfer and nibabel place the grid with Mdc as stored (unit in every real file).
    let m = mdc * DMat3::from_diagonal(sizes_mm);
    let half = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64) / 2.0;
    let p0 = c_ras - m * half;
    let flip = DVec3::new(-1.0, -1.0, 1.0);
    let geometry = Geometry {
        dims,
        spacing: sizes_mm,
        origin: p0 * flip + DVec3::ZERO,
        direction: DMat3::from_cols(cols[0] * flip, cols[1] * flip, cols[2] * flip),
    };
    geometry
        .validate()
        .map_err(|e| err(format!("the header describes an unusable geometry: {e}")))?;
    let list = |v: &[f32]| {
        v.iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    };
    let fields = vec![
        ("version".into(), version.to_string()),
        ("dims".into(), format!("{} {} {}", d[0], d[1], d[2])),
        ("nframes".into(), d[3].to_string()),
        ("type".into(), format!("{code} ({voxel_type})")),
        ("dof".into(), dof.to_string()),
        ("goodRASFlag".into(), good.to_string()),
        ("voxel_size".into(), list(&f[0..3])),
        ("Mdc".into(), list(&f[3..12])),
        ("c_ras".into(), list(&f[12..15])),
    ];
    Ok(Mgh {
        dims,
        frames: sizes[3],
        voxel_type,
        geometry,
        header: Header { fields },
    })
}

/// Read frame `frame` of an MGH stream positioned at byte 0.
fn read_stream<R: Read>(
    r: &mut R,
    frame: impl Into<crate::FrameChoice>,
) -> Result<(AnyVolume, Header, usize), VolumeError> {
    let mut head = Vec::with_capacity(DATA_OFFSET);
    r.by_ref()
        .take(DATA_OFFSET as u64)
        .read_to_end(&mut head)
        .map_err(|e| err(format!("reading the header: {e}")))?;
    let h = parse(&head)?;
    if head.len() < DATA_OFFSET {
        return Err(err("the file ends inside the header"));
    }
    let frame = crate::choose_frame(frame, h.frames)?;
    let n = checked_len(&h.dims, h.voxel_type.size())?;
    let frame_bytes = (n * h.voxel_type.size()) as u64;
    let skipped = std::io::copy(
        &mut r.by_ref().take(frame_bytes * frame as u64),
        &mut std::io::sink(),
    )
    .map_err(|e| err(format!("reading earlier frames: {e}")))?;
    if skipped < frame_bytes * frame as u64 {
        return Err(err("voxel data truncated before the chosen frame"));
    }
    let vol = volmorph_volume::with_voxel_type!(h.voxel_type, T => {
        let mut data: Vec<T> = Vec::new();
        data.try_reserve_exact(n)
            .map_err(|_| err(format!("cannot allocate {frame_bytes} bytes")))?;
        data.resize(n, T::default());
        let buf: &mut [u8] = bytemuck::cast_slice_mut(&mut data);
        let got = crate::text_header::fill(r, buf)
            .map_err(|e| err(format!("reading voxel data: {e}")))?;
        if got < buf.len() {
            return Err(err(format!(
                "voxel data truncated: {got} of the {frame_bytes} bytes of frame {frame}"
            )));
        }
        to_native(&mut data, true);
        AnyVolume::from(Volume::new(h.geometry, data)?)
    });
    Ok((vol, h.header, h.frames))
}

/// Read an `.mgh`/`.mgz` file held in memory (gzip detected by magic number).
///
/// # Errors
/// [`VolumeError::Format`] for a malformed header or truncated data,
/// [`VolumeError::Unsupported`] for `MRI_LONG` voxels, [`VolumeError::InvalidArgument`] for a
/// missing or absent frame.
pub fn read_bytes(
    bytes: &[u8],
    frame: Option<usize>,
) -> Result<(AnyVolume, Header, usize), VolumeError> {
    if is_gzip(bytes) {
        read_stream(&mut MultiGzDecoder::new(bytes), frame)
    } else {
        read_stream(&mut &bytes[..], frame)
    }
}

pub(crate) fn read(
    path: &Path,
    frame: crate::FrameChoice,
) -> Result<(AnyVolume, Header, usize), VolumeError> {
    let os = os_err(path);
    let mut br = BufReader::with_capacity(1 << 20, File::open(path).map_err(os)?);
    if is_gzip(br.fill_buf().map_err(os)?) {
        read_stream(&mut MultiGzDecoder::new(br), frame)
    } else {
        read_stream(&mut br, frame)
    }
}

fn header_bytes(v: &AnyVolume) -> Result<Vec<u8>, VolumeError> {
    let g = v.geometry();
    g.validate()?;
    let code = type_code(v.voxel_type())?;
    let direction = volmorph_volume::direction::orthonormalize(g.direction).map_err(|e| {
        VolumeError::Unsupported(format!(
            "MGH stores a rotation as its direction; this volume's is skewed ({e})"
        ))
    })?;
    let mut b = Vec::with_capacity(DATA_OFFSET);
    let mut i32s = vec![1i32];
    for &d in &g.dims {
        i32s.push(i32::try_from(d).map_err(|_| {
            VolumeError::Unsupported(format!("MGH sizes are 32-bit: {d} is too large"))
        })?);
    }
    i32s.extend([1, code, 0]);
    for v in i32s {
        b.extend_from_slice(&v.to_be_bytes());
    }
    b.extend_from_slice(&1i16.to_be_bytes());
    let flip = DVec3::new(-1.0, -1.0, 1.0);
    let cols: Vec<DVec3> = (0..3).map(|k| direction.col(k) * flip).collect();
    let m = DMat3::from_cols(cols[0], cols[1], cols[2]) * DMat3::from_diagonal(g.spacing);
    let p0 = g.origin * flip;
    let half = DVec3::new(g.dims[0] as f64, g.dims[1] as f64, g.dims[2] as f64) / 2.0;
    let c = p0 + m * half;
    let mut f: Vec<f64> = g.spacing.to_array().to_vec();
    for col in &cols {
        f.extend(col.to_array());
    }
    f.extend(c.to_array());
    for v in f {
        let x = v as f32;
        if !x.is_finite() {
            return Err(VolumeError::Geometry(format!(
                "{v} does not fit in the 32-bit floats of an MGH header"
            )));
        }
        b.extend_from_slice(&x.to_be_bytes());
    }
    b.resize(DATA_OFFSET, 0);
    Ok(b)
}

/// Write an `.mgh` (or gzip-compressed `.mgz`) file (see the [module docs](self)).
pub(crate) fn write(path: &Path, v: &AnyVolume, o: &WriteOptions) -> Result<(), VolumeError> {
    let head = header_bytes(v)?;
    let gz = path
        .file_name()
        .is_some_and(|n| n.to_string_lossy().to_ascii_lowercase().ends_with(".mgz"));
    let os = os_err(path);
    write_atomic(path, |w| {
        if gz {
            let mut enc = GzEncoder::new(w, Compression::new(o.level.min(9)));
            enc.write_all(&head).map_err(os)?;
            write_voxels(&mut enc, v, true).map_err(os)?;
            enc.finish().map_err(os)?;
        } else {
            w.write_all(&head).map_err(os)?;
            write_voxels(w, v, true).map_err(os)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_read_round_trip_keeps_geometry_to_single_precision() {
        let rot = DMat3::from_rotation_z(0.4) * DMat3::from_rotation_x(-0.3);
        let g = Geometry::new([5, 4, 3])
            .with_spacing(DVec3::new(0.5, 1.25, 2.0))
            .with_origin(DVec3::new(-20.0, 7.5, 3.25))
            .with_direction(rot);
        let v: AnyVolume = Volume::from_fn(g, |i, j, k| (i + 10 * j + 100 * k) as i16)
            .unwrap()
            .into();
        let dir = tempfile::tempdir().unwrap();
        for name in ["a.mgh", "a.mgz"] {
            let p = dir.path().join(name);
            write(&p, &v, &WriteOptions::default()).unwrap();
            let (back, _, frames) = read(&p, crate::FrameChoice::Single).unwrap();
            assert_eq!(frames, 1);
            assert_eq!(back.as_bytes(), v.as_bytes());
            let b = back.geometry();
            assert!((b.origin - g.origin).abs().max_element() < 1e-4);
            assert!((b.spacing - g.spacing).abs().max_element() < 1e-6);
            assert!((b.direction - rot).abs_diff_eq(DMat3::ZERO, 1e-6));
        }
        let u: AnyVolume = Volume::filled(g, 1u16).unwrap().into();
        assert!(matches!(
            write(&dir.path().join("u.mgz"), &u, &WriteOptions::default()),
            Err(VolumeError::Unsupported(_))
        ));
    }

    #[test]
    fn malformed_headers_are_clear_errors() {
        let mut h = vec![0u8; DATA_OFFSET];
        assert!(
            read_bytes(&h, None)
                .unwrap_err()
                .to_string()
                .contains("version")
        );
        h[3] = 1;
        assert!(
            read_bytes(&h, None)
                .unwrap_err()
                .to_string()
                .contains("width = 0")
        );
        for (a, v) in [(4usize, 2i32), (8, 2), (12, 2), (16, 1), (20, 7)] {
            h[a..a + 4].copy_from_slice(&v.to_be_bytes());
        }
        assert!(
            read_bytes(&h, None)
                .unwrap_err()
                .to_string()
                .contains("type 7")
        );
        h[20..24].copy_from_slice(&0i32.to_be_bytes());
        // Header fine, data missing.
        let e = read_bytes(&h, None).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        // Absurd sizes are refused before allocating.
        for a in [4usize, 8, 12] {
            h[a..a + 4].copy_from_slice(&i32::MAX.to_be_bytes());
        }
        let e = read_bytes(&h, None).unwrap_err().to_string();
        assert!(e.contains("exceed") || e.contains("overflow"), "{e}");
    }
}
