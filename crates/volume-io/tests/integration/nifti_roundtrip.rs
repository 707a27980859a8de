//! NIfTI-1 write → read round trips: voxel data bit-exact for every type, geometry exact for
//! f32-representable spacing/origin with axis permutations and flips, oblique rotations within
//! 1e-6 (the header stores f32), in `.nii` and `.nii.gz`.

use std::path::Path;

use volmorph_volume::{
    AnyVolume, DMat3, DVec3, Geometry, Volume, Voxel, VoxelType, with_voxel_type,
};
use volmorph_volume_io::{self as format, Format, WriteOptions, nifti};

fn field<'a>(h: &'a format::Header, name: &str) -> &'a str {
    h.fields
        .iter()
        .find(|(k, _)| k == name)
        .map(|(_, v)| v.as_str())
        .unwrap_or_else(|| panic!("no header field {name}"))
}

/// Axis permutation with flips: i → −y, j → +z, k → −x (determinant −1, improper).
fn permuted_geometry() -> Geometry {
    Geometry::new([5, 4, 3])
        .with_spacing(DVec3::new(0.5, 1.25, 2.0))
        .with_origin(DVec3::new(-10.5, 4.25, 2.5))
        .with_direction(DMat3::from_cols(
            DVec3::new(0.0, -1.0, 0.0),
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(-1.0, 0.0, 0.0),
        ))
}

fn oblique_geometry() -> Geometry {
    let rot =
        DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-0.7) * DMat3::from_rotation_y(1.1);
    Geometry::new([6, 5, 4])
        .with_spacing(DVec3::new(0.7, 1.3, 2.9))
        .with_origin(DVec3::new(-101.25, 37.5, 12.125))
        .with_direction(rot)
}

/// A volume of type `T` whose values span the type's range (incl. extremes, NaN-free).
fn volume_of<T: Voxel>(g: Geometry) -> AnyVolume
where
    AnyVolume: From<Volume<T>>,
{
    let (lo, hi) = T::TYPE.range();
    let n = g.len();
    let v = Volume::from_fn(g, |i, j, k| {
        let idx = i + g.dims[0] * (j + g.dims[1] * k);
        let t = idx as f64 / (n - 1) as f64;
        let x = if T::TYPE.is_float() {
            // Non-integral values with sign changes, plus extremes.
            match idx {
                0 => lo,
                1 => hi,
                _ => (t - 0.5) * 1e6 + 0.123_456_789,
            }
        } else {
            lo + t * (hi - lo)
        };
        T::from_f64(x)
    })
    .unwrap();
    v.into()
}

fn all_types(g: Geometry) -> Vec<AnyVolume> {
    VoxelType::ALL
        .iter()
        .map(|&vt| with_voxel_type!(vt, T => volume_of::<T>(g)))
        .collect()
}

fn write_read(dir: &Path, name: &str, v: &AnyVolume) -> format::VolumeFile {
    let p = dir.join(name);
    format::write_with(
        &p,
        v,
        &WriteOptions {
            compress: false,
            level: 1,
        },
    )
    .unwrap();
    let f = format::read_with_header(&p).unwrap();
    assert_eq!(f.format, Format::Nifti);
    f
}

#[test]
fn every_voxel_type_round_trips_bit_exact_with_exact_geometry() {
    let dir = tempfile::tempdir().unwrap();
    for ext in ["nii", "nii.gz"] {
        for v in all_types(permuted_geometry()) {
            let name = format!("{}.{ext}", v.voxel_type());
            let back = write_read(dir.path(), &name, &v);
            assert_eq!(back.volume.voxel_type(), v.voxel_type(), "{name}");
            assert_eq!(back.volume.as_bytes(), v.as_bytes(), "{name}: data differ");
            assert_eq!(
                back.volume.geometry(),
                v.geometry(),
                "{name}: geometry differs"
            );
        }
    }
}

#[test]
fn plain_file_layout_is_header_extender_data() {
    let dir = tempfile::tempdir().unwrap();
    let v = volume_of::<i16>(permuted_geometry());
    let p = dir.path().join("a.nii");
    format::write(&p, &v).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(bytes.len(), 352 + 2 * 60);
    assert_eq!(&bytes[0..4], &348i32.to_le_bytes());
    assert_eq!(&bytes[344..348], b"n+1\0");
    assert_eq!(&bytes[348..352], &[0, 0, 0, 0]);
    assert_eq!(&bytes[352..], v.as_bytes());
    let (_, h) = nifti::read_bytes(&bytes).unwrap();
    assert_eq!(field(&h, "qform_code"), "1 (scanner_anat)");
    assert_eq!(field(&h, "sform_code"), "1 (scanner_anat)");
    assert_eq!(field(&h, "vox_offset"), "352");
    assert_eq!(field(&h, "datatype"), "4 (int16)");
    assert_eq!(field(&h, "bitpix"), "16");
    assert_eq!(field(&h, "dim"), "3 5 4 3 1 1 1 1");
    assert_eq!(field(&h, "xyzt_units"), "10 (space: mm, time: s)");
    // LPS (i → −y, j → +z, k → −x) is RAS (i → +y, j → +z, k → +x): qfac +1, srow scaled.
    assert_eq!(field(&h, "pixdim"), "1 0.5 1.25 2 0 0 0 0");
    assert_eq!(field(&h, "srow_x"), "0 -0 2 10.5");
    assert_eq!(field(&h, "srow_y"), "0.5 -0 0 -4.25");
    assert_eq!(field(&h, "srow_z"), "0 1.25 0 2.5");
}

#[test]
fn gzip_file_is_gzip_and_level_is_honoured() {
    let dir = tempfile::tempdir().unwrap();
    let v = volume_of::<u8>(Geometry::new([64, 64, 16]));
    let p0 = dir.path().join("l0.nii.gz");
    let p9 = dir.path().join("l9.nii.gz");
    format::write_with(
        &p0,
        &v,
        &WriteOptions {
            compress: false,
            level: 0,
        },
    )
    .unwrap();
    format::write_with(
        &p9,
        &v,
        &WriteOptions {
            compress: false,
            level: 9,
        },
    )
    .unwrap();
    let (b0, b9) = (std::fs::read(&p0).unwrap(), std::fs::read(&p9).unwrap());
    assert_eq!(&b0[..2], &[0x1f, 0x8b]);
    assert!(
        b9.len() < b0.len() / 4,
        "level 9 {} vs level 0 {}",
        b9.len(),
        b0.len()
    );
    for b in [b0, b9] {
        let (back, _) = nifti::read_bytes(&b).unwrap();
        assert_eq!(back, v);
    }
}

#[test]
fn oblique_rotations_round_trip_within_single_precision() {
    let dir = tempfile::tempdir().unwrap();
    let mut proper = oblique_geometry();
    let mut improper = oblique_geometry();
    improper.direction *= DMat3::from_diagonal(DVec3::new(1.0, -1.0, 1.0));
    for (gi, g) in [&mut proper, &mut improper].into_iter().enumerate() {
        for ext in ["nii", "nii.gz"] {
            let v = volume_of::<f32>(*g);
            let back = write_read(dir.path(), &format!("o{gi}.{ext}"), &v);
            let bg = back.volume.geometry();
            assert_eq!(back.volume.as_bytes(), v.as_bytes());
            assert_eq!(bg.dims, g.dims);
            assert!((bg.spacing - g.spacing).abs().max_element() < 1e-6 * 3.0);
            assert!((bg.origin - g.origin).abs().max_element() <= 1e-6 * 102.0);
            let dd = bg.direction - g.direction;
            let worst = dd
                .x_axis
                .abs()
                .max(dd.y_axis.abs())
                .max(dd.z_axis.abs())
                .max_element();
            assert!(worst < 1e-6, "{ext}: direction error {worst}");
            // Physical positions of the far corner agree within f32 precision.
            let c = DVec3::new(5.0, 4.0, 3.0);
            assert!((bg.index_to_physical(c) - g.index_to_physical(c)).length() < 1e-4);
        }
    }
    // The improper one is stored with qfac = −1.
    let v = volume_of::<u8>(improper);
    let p = dir.path().join("improper.nii");
    format::write(&p, &v).unwrap();
    let h = format::read_with_header(&p).unwrap().header;
    assert!(
        field(&h, "pixdim").starts_with("-1 "),
        "{}",
        field(&h, "pixdim")
    );
}

#[test]
fn skewed_direction_keeps_exact_sform_and_reads_back_orthonormal() {
    let dir = tempfile::tempdir().unwrap();
    let skew = DMat3::from_cols(
        DVec3::X,
        DVec3::new(0.6, 0.8, 0.0), // 53° from x instead of 90°
        DVec3::Z,
    );
    let g = Geometry::new([3, 3, 3])
        .with_spacing(DVec3::new(1.0, 2.0, 4.0))
        .with_direction(skew);
    let v = volume_of::<i16>(g);
    let p = dir.path().join("skew.nii");
    format::write(&p, &v).unwrap();
    let f = format::read_with_header(&p).unwrap();
    // The exact skewed matrix, LPS → RAS, scaled by spacing, is in the sform …
    assert_eq!(field(&f.header, "srow_x"), "-1 -1.2 -0 -0");
    assert_eq!(field(&f.header, "srow_y"), "-0 -1.6 -0 -0");
    assert_eq!(field(&f.header, "srow_z"), "0 0 4 0");
    // … and ITK's rules read the (orthonormal) qform: the closest rotation to the skew.
    let d = f.volume.geometry().direction;
    for (a, b) in [
        (d.x_axis, d.y_axis),
        (d.y_axis, d.z_axis),
        (d.x_axis, d.z_axis),
    ] {
        assert!(a.dot(b).abs() < 1e-6);
    }
    assert!((d.determinant() - 1.0).abs() < 1e-6);
    assert_eq!(f.volume.as_bytes(), v.as_bytes());
}

#[test]
fn two_dimensional_volume_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let g = Geometry::new([7, 3, 1])
        .with_spacing(DVec3::new(0.25, 0.5, 1.0))
        .with_origin(DVec3::new(1.0, -2.0, 0.0));
    let v = volume_of::<f64>(g);
    let back = write_read(dir.path(), "flat.nii.gz", &v);
    assert_eq!(back.volume, v);
}

#[test]
fn sizes_beyond_nifti1_become_nifti2_and_bad_geometry_is_refused_without_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let v: AnyVolume = Volume::filled(Geometry::new([40_000, 1, 1]), 0u8)
        .unwrap()
        .into();
    let big = dir.path().join("big.nii");
    format::write(&big, &v).unwrap();
    let back = format::read_with_header(&big).unwrap();
    assert_eq!(back.volume, v);
    assert!(
        back.header
            .fields
            .contains(&("sizeof_hdr".into(), "540".into()))
    );
    std::fs::remove_file(&big).unwrap();
    let p = dir.path().join("bad.nii");
    let g = Geometry::new([2, 2, 2]).with_origin(DVec3::new(1e300, 0.0, 0.0));
    let v: AnyVolume = Volume::new(g, vec![0u8; 8]).unwrap().into();
    assert!(format::write(&p, &v).is_err());
    assert!(!p.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn every_voxel_type_maps_to_its_nifti_datatype() {
    let expected = [
        (VoxelType::U8, "2 (uint8)"),
        (VoxelType::I8, "256 (int8)"),
        (VoxelType::U16, "512 (uint16)"),
        (VoxelType::I16, "4 (int16)"),
        (VoxelType::U32, "768 (uint32)"),
        (VoxelType::I32, "8 (int32)"),
        (VoxelType::F32, "16 (float32)"),
        (VoxelType::F64, "64 (float64)"),
    ];
    let dir = tempfile::tempdir().unwrap();
    for v in all_types(Geometry::new([2, 2, 2])) {
        let p = dir.path().join("t.nii");
        format::write(&p, &v).unwrap();
        let h = format::read_with_header(&p).unwrap().header;
        let want = expected
            .iter()
            .find(|(t, _)| *t == v.voxel_type())
            .unwrap()
            .1;
        assert_eq!(field(&h, "datatype"), want);
        assert_eq!(field(&h, "bitpix"), (8 * v.voxel_type().size()).to_string());
    }
}

/// Issue 14: a spacing or origin beyond the 32-bit floats of the header was reported with
/// `{}`, so 1e300 printed as 301 digits. The message is short, names the field and prints
/// the value as given (`1e300`, the origin in volmorph's LPS sign), and no file is written.
#[test]
fn numbers_past_1e9_print_hundreds_of_digits() {
    let dir = tempfile::tempdir().unwrap();
    for (name, g) in [
        (
            "spacing y",
            Geometry::new([2, 2, 2]).with_spacing(DVec3::new(1.0, 1e300, 1.0)),
        ),
        (
            "origin x",
            Geometry::new([2, 2, 2]).with_origin(DVec3::new(1e300, 0.0, 0.0)),
        ),
    ] {
        let p = dir.path().join("huge.nii");
        let v: AnyVolume = Volume::new(g, vec![0u8; 8]).unwrap().into();
        let msg = format::write(&p, &v).unwrap_err().to_string();
        assert!(
            msg.len() < 200 && msg.contains(&format!("{name} = 1e300")),
            "{} chars: {msg}",
            msg.len()
        );
        assert!(!p.exists());
    }
}
