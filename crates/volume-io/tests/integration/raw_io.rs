//! Headerless raw voxels: writing, reading with a RawSpec, size checks, gzip.

use std::io::Write;

use volmorph_volume::{AnyVolume, DVec3, Geometry, Volume, VolumeError, VoxelType};
use volmorph_volume_io::raw::RawSpec;
use volmorph_volume_io::{self as format, raw};

fn ramp(vt: VoxelType, dims: [usize; 3]) -> AnyVolume {
    let v = Volume::from_fn(Geometry::new(dims), |i, j, k| {
        (i as f64 - 3.0) * 1.5 + 10.0 * j as f64 - 40.0 * k as f64
    })
    .unwrap();
    AnyVolume::from(v).cast(vt, 1.0, 0.0)
}

#[test]
fn write_then_read_every_type() {
    let dir = tempfile::tempdir().unwrap();
    for vt in VoxelType::ALL {
        let vol = ramp(vt, [4, 3, 2]);
        let p = dir.path().join(format!("{vt}.raw"));
        format::write(&p, &vol).unwrap();
        // No header: exactly the little-endian voxels.
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(bytes.len(), 24 * vt.size());
        if cfg!(target_endian = "little") {
            assert_eq!(bytes, vol.as_bytes());
        }
        let mut spec = RawSpec::new([4, 3, 2], vt);
        spec.spacing = DVec3::new(0.5, 0.25, 3.0);
        spec.origin = DVec3::new(1.0, -2.0, 0.125);
        let back = raw::read(&p, &spec).unwrap();
        assert_eq!(back.as_bytes(), vol.as_bytes());
        assert_eq!(back.geometry(), &spec.geometry());
    }
    // The dispatch refuses to guess a raw file's layout.
    let e = format::read(&dir.path().join("u8.raw")).unwrap_err();
    assert!(e.to_string().contains("RawSpec"), "{e}");
}

#[test]
fn big_endian_with_header_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("be.img");
    let mut b = vec![0xEEu8; 5];
    for v in [1.5f32, -2.25, 1e-30] {
        b.extend_from_slice(&v.to_be_bytes());
    }
    std::fs::write(&p, &b).unwrap();
    let spec = RawSpec {
        dims: [3, 1, 1],
        voxel_type: VoxelType::F32,
        big_endian: true,
        header_bytes: 5,
        spacing: DVec3::ONE,
        origin: DVec3::ZERO,
    };
    assert_eq!(spec.expected_len().unwrap(), 17);
    let v = raw::read(&p, &spec).unwrap();
    assert_eq!(v.to_typed::<f32>().data(), &[1.5, -2.25, 1e-30]);
}

#[test]
fn gzip_is_detected_by_magic() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v.raw");
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(&[9, 9, 1, 2, 3, 4]).unwrap();
    std::fs::write(&p, enc.finish().unwrap()).unwrap();
    let mut spec = RawSpec::new([2, 2, 1], VoxelType::U8);
    spec.header_bytes = 2;
    assert_eq!(raw::read(&p, &spec).unwrap().as_bytes(), &[1, 2, 3, 4]);
    // Decompressed size must match exactly too.
    spec.header_bytes = 1;
    let e = raw::read(&p, &spec).unwrap_err().to_string();
    assert!(e.contains("more than"), "{e}");
    spec.header_bytes = 3;
    assert!(raw::read(&p, &spec).is_err());
}

#[test]
fn size_mismatch_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v.raw");
    std::fs::write(&p, [0u8; 10]).unwrap();
    for dims in [[3, 3, 1], [2, 2, 2]] {
        let e = raw::read(&p, &RawSpec::new(dims, VoxelType::U8)).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("10 bytes") && msg.contains("exactly"), "{msg}");
        assert!(msg.contains("v.raw"), "error names the file: {msg}");
    }
    let e = raw::read(&p, &RawSpec::new([0, 2, 2], VoxelType::U8)).unwrap_err();
    assert!(matches!(e, VolumeError::File { .. }), "{e:?}");
    let e = raw::read(&p, &RawSpec::new([1 << 40, 1 << 40, 1], VoxelType::U8)).unwrap_err();
    assert!(e.to_string().contains("dims"), "{e}");
    let mut spec = RawSpec::new([5, 1, 1], VoxelType::U16);
    spec.spacing = DVec3::new(1.0, f64::NAN, 1.0);
    assert!(raw::read(&p, &spec).is_err());
    spec.spacing = DVec3::ONE;
    assert!(raw::read(&p, &spec).is_ok());
    // A corrupt gzip stream.
    std::fs::write(&p, [0x1f, 0x8b, 8, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9]).unwrap();
    let e = raw::read(&p, &RawSpec::new([2, 2, 2], VoxelType::U8)).unwrap_err();
    assert!(e.to_string().contains("gzip"), "{e}");
}
