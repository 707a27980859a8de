//! VTK legacy STRUCTURED_POINTS reading and writing.

use crate::common;

use common::random_volume;
use volmorph_volume::{AnyVolume, DMat3, DVec3, Geometry, Volume, VolumeError, VoxelType};
use volmorph_volume_io::{self as format, Format, WriteOptions, vtk};

fn aligned() -> Geometry {
    Geometry::new([5, 4, 3])
        .with_spacing(DVec3::new(0.7, 1.0 / 3.0, 2.1))
        .with_origin(DVec3::new(-12.345, 67.8, -1e-9))
}

#[test]
fn round_trip_every_type() {
    let dir = tempfile::tempdir().unwrap();
    for (k, vt) in VoxelType::ALL.into_iter().enumerate() {
        let vol = random_volume(vt, aligned(), 21 + k as u64);
        let p = dir.path().join(format!("v_{vt}.vtk"));
        format::write(&p, &vol).unwrap();
        let f = format::read_with_header(&p).unwrap();
        assert_eq!(f.format, Format::Vtk);
        assert_eq!(f.volume.voxel_type(), vt);
        assert_eq!(f.volume.geometry(), vol.geometry(), "bit-exact geometry");
        assert_eq!(f.volume.as_bytes(), vol.as_bytes(), "bit-exact voxels");
        let bytes = std::fs::read(&p).unwrap();
        assert!(bytes.starts_with(b"# vtk DataFile Version 3.0\n"));
        let (v2, _) = vtk::read_bytes(&bytes).unwrap();
        assert_eq!(v2.as_bytes(), vol.as_bytes());
    }
}

#[test]
fn binary_data_are_big_endian() {
    let dir = tempfile::tempdir().unwrap();
    let g = Geometry::new([2, 1, 1]);
    let vol = AnyVolume::from(Volume::new(g, vec![0x0102u16, 0xA0B0]).unwrap());
    let p = dir.path().join("be.vtk");
    format::write(&p, &vol).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    assert!(text.contains("SCALARS scalars unsigned_short 1\nLOOKUP_TABLE default\n"));
    let start = bytes.windows(8).position(|w| w == b"default\n").unwrap() + 8;
    assert_eq!(&bytes[start..start + 4], &[0x01, 0x02, 0xA0, 0xB0]);
}

#[test]
fn oblique_direction_is_refused_not_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let g = aligned().with_direction(DMat3::from_rotation_z(0.2));
    let vol = random_volume(VoxelType::F32, g, 3);
    let p = dir.path().join("obl.vtk");
    let e = format::write_with(&p, &vol, &WriteOptions::default()).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("direction"), "{msg}");
    assert!(msg.contains("MetaImage") && msg.contains("NRRD"), "{msg}");
    assert!(!p.exists());
    // A flip is a non-identity direction too.
    let g = aligned().with_direction(DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)));
    assert!(format::write(&p, &random_volume(VoxelType::U8, g, 1)).is_err());
}

#[test]
fn hand_written_ascii_with_loose_layout() {
    let text = b"# vtk DataFile Version 2.0\nCT head, exported by hand\nascii\n\n\
dataset structured_points\ndimensions 3 2 1\n\naspect_ratio 1.5 2 1\norigin -1 0.5 7\n\
point_data 6\nscalars density float\nlookup_table my_table\n0 0.5 1\n-1.25e2\n  3 4\n";
    let (vol, header) = vtk::read_bytes(text).unwrap();
    let g = vol.geometry();
    assert_eq!(g.dims, [3, 2, 1]);
    assert_eq!(g.spacing, DVec3::new(1.5, 2.0, 1.0));
    assert_eq!(g.origin, DVec3::new(-1.0, 0.5, 7.0));
    assert_eq!(g.direction, DMat3::IDENTITY);
    assert_eq!(
        vol.to_typed::<f32>().data(),
        &[0.0, 0.5, 1.0, -125.0, 3.0, 4.0]
    );
    assert!(
        header
            .fields
            .contains(&("LOOKUP_TABLE".to_string(), "my_table".to_string()))
    );
    assert!(
        header
            .fields
            .contains(&("version".to_string(), "2.0".to_string()))
    );
}

#[test]
fn hand_written_binary_with_extent_and_vtktype_names() {
    let mut b = b"# vtk DataFile Version 4.2\nseg\nBINARY\nDATASET STRUCTURED_POINTS\n\
EXTENT 2 3 0 0 -1 -1\nSPACING 0.5 1 4\nORIGIN 10 20 30\nPOINT_DATA 2\n\
SCALARS labels vtktypeint16 1\nLOOKUP_TABLE default\n"
        .to_vec();
    b.extend_from_slice(&(-2i16).to_be_bytes());
    b.extend_from_slice(&(513i16).to_be_bytes());
    let (vol, _) = vtk::read_bytes(&b).unwrap();
    let g = vol.geometry();
    assert_eq!(g.dims, [2, 1, 1]);
    // The extent starts at index (2, 0, −1): the origin moves by spacing ⊙ (2, 0, −1).
    assert_eq!(g.origin, DVec3::new(11.0, 20.0, 26.0));
    assert_eq!(vol.to_typed::<i16>().data(), &[-2, 513]);
}

fn assert_err(bytes: &[u8], unsupported: bool, needle: &str) {
    let e = common::read_err(vtk::read_bytes, bytes);
    assert_eq!(
        matches!(e, VolumeError::Unsupported(_)),
        unsupported,
        "{e:?}"
    );
    assert!(e.to_string().contains(needle), "`{e}` lacks `{needle}`");
}

fn file(body: &str) -> Vec<u8> {
    let mut b = format!("# vtk DataFile Version 3.0\nt\nBINARY\nDATASET STRUCTURED_POINTS\n{body}")
        .into_bytes();
    b.extend_from_slice(&[0u8; 16]);
    b
}

#[test]
fn malformed_files_are_clear_errors() {
    let good = "DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s unsigned_char\nLOOKUP_TABLE default\n";
    assert!(vtk::read_bytes(&file(good)).is_ok());
    assert_err(b"# vtk DataFile\nt\n", false, "not a VTK");
    assert_err(b"hello\n", false, "not a VTK");
    assert_err(
        b"# vtk DataFile Version 3.0\nt\nBINARY\nDATASET POLYDATA\nPOINTS 0 float\n",
        true,
        "POLYDATA",
    );
    assert_err(
        b"# vtk DataFile Version 3.0\nt\nUTF8\nDATASET STRUCTURED_POINTS\n",
        false,
        "ASCII or BINARY",
    );
    assert_err(
        &file("POINT_DATA 8\nSCALARS s float\nLOOKUP_TABLE default\n"),
        false,
        "DIMENSIONS",
    );
    assert_err(
        &file("DIMENSIONS 2 2 2\nPOINT_DATA 9\nSCALARS s float\nLOOKUP_TABLE default\n"),
        false,
        "does not match",
    );
    assert_err(&file("DIMENSIONS 2 0 2\nPOINT_DATA 0\n"), false, "zero");
    assert_err(
        &file("DIMENSIONS 2 -2 2\nPOINT_DATA 8\n"),
        false,
        "negative",
    );
    assert_err(
        &file("DIMENSIONS 2 2 2\nSPACING 1 nan 1\nPOINT_DATA 8\n"),
        false,
        "not finite",
    );
    assert_err(
        &file("DIMENSIONS 2 2 2\nSPACING 1 0 1\nPOINT_DATA 8\n"),
        false,
        "spacing",
    );
    assert_err(
        &file("DIMENSIONS 2 2 2\nORIGIN 1 x 1\nPOINT_DATA 8\n"),
        false,
        "not a number",
    );
    assert_err(
        &file("DIMENSIONS 2 2 2\nDIRECTION 1 0 0 0 1 0 0 0 1\n"),
        false,
        "DIRECTION",
    );
    assert_err(
        &file("DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s complex\nLOOKUP_TABLE default\n"),
        false,
        "unknown scalar type",
    );
    assert_err(
        &file("DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s vtkIdType\nLOOKUP_TABLE default\n"),
        true,
        "vtkidtype",
    );
    assert_err(
        &file("DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s float 3\nLOOKUP_TABLE default\n"),
        true,
        "3 components",
    );
    assert_err(
        &file("DIMENSIONS 2 2 2\nPOINT_DATA 8\nVECTORS v float\n"),
        true,
        "VECTORS",
    );
    assert_err(&file("DIMENSIONS 2 2 2\nCELL_DATA 1\n"), true, "CELL_DATA");
    assert_err(
        &file("DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s float\ndefault\n"),
        false,
        "LOOKUP_TABLE",
    );
    // Truncated binary data: 8 floats need 32 bytes, 16 are present.
    assert_err(
        &file("DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s float\nLOOKUP_TABLE default\n"),
        false,
        "truncated",
    );
    // Header ends before the data.
    assert_err(
        b"# vtk DataFile Version 3.0\nt\nBINARY\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2",
        false,
        "ends before",
    );
    // A gigantic token without whitespace.
    let mut b = b"# vtk DataFile Version 3.0\nt\nBINARY\nDATASET STRUCTURED_POINTS\n".to_vec();
    b.resize(3 << 20, b'Q');
    let t = std::time::Instant::now();
    assert!(vtk::read_bytes(&b).is_err());
    assert!(t.elapsed().as_secs_f64() < 2.0);
}

mod fuzz {
    use super::*;

    fn make_seeds() -> Vec<Vec<u8>> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.vtk");
        format::write(&p, &random_volume(VoxelType::I32, aligned(), 2)).unwrap();
        vec![
            std::fs::read(&p).unwrap(),
            b"# vtk DataFile Version 2.0\nx\nASCII\nDATASET STRUCTURED_POINTS\nEXTENT 0 1 0 1 0 0\n\
SPACING 1 2 3\nORIGIN 0 0 0\nPOINT_DATA 4\nSCALARS a double 1\nLOOKUP_TABLE t\n1 2 3 4\n"
                .to_vec(),
        ]
    }

    /// Corrupted files give an error or a valid volume, never a panic.
    #[test]
    fn mutated_files_never_panic() {
        common::assert_mutations_never_panic(vtk::read_bytes, &make_seeds());
    }
}

/// Every file of the malformed corpus is refused with an error (never a panic), both by
/// path and, for single-file forms, from memory.
#[test]
fn malformed_corpus_is_refused() {
    common::assert_corpus_refused("vtk", vtk::read_bytes);
}
