//! MetaImage reading and writing: round trips, hand-written headers, malformed input.

use crate::common;

use common::{oblique, random_volume};
use std::io::Write;

use volmorph_volume::{AnyVolume, DMat3, DVec3, Geometry, Volume, VolumeError, VoxelType};
use volmorph_volume_io::{self as format, Format, WriteOptions, metaimage};

fn assert_same(a: &AnyVolume, b: &AnyVolume) {
    assert_eq!(a.voxel_type(), b.voxel_type());
    assert_eq!(a.geometry(), b.geometry(), "geometry must be bit-exact");
    assert_eq!(a.as_bytes(), b.as_bytes(), "voxels must be bit-exact");
}

fn le_i16(v: &[i16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

#[test]
fn round_trip_every_type_and_variant() {
    let dir = tempfile::tempdir().unwrap();
    for (k, vt) in VoxelType::ALL.into_iter().enumerate() {
        let vol = random_volume(vt, oblique(), 7 + k as u64);
        for (ext, compress) in [("mha", false), ("mha", true), ("mhd", false), ("mhd", true)] {
            let p = dir.path().join(format!("v_{vt}_{compress}.{ext}"));
            let opts = WriteOptions { compress, level: 3 };
            format::write_with(&p, &vol, &opts).unwrap();
            let f = format::read_with_header(&p).unwrap();
            assert_eq!(f.format, Format::MetaImage);
            assert_same(&vol, &f.volume);
            let get = |k: &str| {
                f.header
                    .fields
                    .iter()
                    .find(|(n, _)| n == k)
                    .map(|(_, v)| v.clone())
            };
            assert_eq!(
                get("CompressedData").as_deref(),
                Some(if compress { "True" } else { "False" })
            );
            if ext == "mhd" {
                // The data file is named after the header and the write.
                let name = get("ElementDataFile").unwrap();
                let header_name = p.file_name().unwrap().to_string_lossy().into_owned();
                let ext = if compress { ".zraw" } else { ".raw" };
                assert!(
                    name.starts_with(&format!("{header_name}.")) && name.ends_with(ext),
                    "{name}"
                );
                let data = dir.path().join(&name);
                assert!(data.is_file(), "{}", data.display());
                if !compress {
                    assert_eq!(
                        std::fs::metadata(&data).unwrap().len() as usize,
                        vol.as_bytes().len()
                    );
                }
            } else {
                assert_eq!(get("ElementDataFile").as_deref(), Some("LOCAL"));
                let bytes = std::fs::read(&p).unwrap();
                let (v2, _) = metaimage::read_bytes(&bytes).unwrap();
                assert_same(&vol, &v2);
            }
        }
    }
}

#[test]
fn written_header_lists_direction_columns_in_itk_order() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("rot.mha");
    // x axis → +y, y axis → −x: a rotation by 90° about z.
    let d = DMat3::from_cols(DVec3::Y, DVec3::NEG_X, DVec3::Z);
    let g = Geometry::new([2, 2, 2])
        .with_spacing(DVec3::new(0.5, 2.0, 0.1))
        .with_direction(d);
    let vol = AnyVolume::from(Volume::filled(g, 3u8).unwrap());
    format::write(&p, &vol).unwrap();
    let text = std::fs::read(&p).unwrap();
    let text = String::from_utf8_lossy(&text[..text.len() - 8]);
    assert!(
        text.contains("TransformMatrix = 0 1 0 -1 0 0 0 0 1\n"),
        "{text}"
    );
    assert!(text.contains("ElementSpacing = 0.5 2 0.1\n"), "{text}");
    assert!(text.contains("AnatomicalOrientation = ALI\n"), "{text}");
    assert!(text.ends_with("ElementDataFile = LOCAL\n"), "{text}");
}

#[test]
fn hand_written_itk_header_with_known_rotation() {
    // As ITK writes it: rotation by 30° about z, big-endian shorts.
    let (c, s) = (3f64.sqrt() / 2.0, 0.5);
    let hdr = format!(
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = True\n\
         CompressedData = False\nTransformMatrix = {c} {s} 0 -{s} {c} 0 0 0 1\n\
         Offset = 10 -20 30.5\nCenterOfRotation = 0 0 0\nAnatomicalOrientation = RAI\n\
         ElementSpacing = 0.8 0.8 2.5\nDimSize = 2 2 1\nElementType = MET_SHORT\n\
         ElementDataFile = LOCAL\n"
    );
    let mut bytes = hdr.into_bytes();
    for v in [1i16, -2, 300, -32768] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    let (vol, header) = metaimage::read_bytes(&bytes).unwrap();
    assert_eq!(header.fields[0], ("ObjectType".into(), "Image".into()));
    let AnyVolume::I16(v) = vol else {
        panic!("expected i16")
    };
    assert_eq!(v.data(), &[1, -2, 300, -32768]);
    let g = v.geometry();
    assert_eq!(g.dims, [2, 2, 1]);
    assert_eq!(g.origin, DVec3::new(10.0, -20.0, 30.5));
    assert_eq!(g.spacing, DVec3::new(0.8, 0.8, 2.5));
    // Index (1, 0, 0) moves 0.8 along (cos 30°, sin 30°, 0).
    let p = g.index_to_physical(DVec3::X);
    assert!((p - DVec3::new(10.0 + 0.8 * c, -20.0 + 0.8 * s, 30.5)).length() < 1e-12);
    // Index (0, 1, 0) moves 0.8 along (−sin 30°, cos 30°, 0).
    let p = g.index_to_physical(DVec3::Y);
    assert!((p - DVec3::new(10.0 - 0.8 * s, -20.0 + 0.8 * c, 30.5)).length() < 1e-12);
}

#[test]
fn two_d_synonyms_and_element_size_fallback() {
    let mut bytes = b"NDims = 2\nDimSize = 3 2\nElementSize = 0.5 0.25\nPosition = 1 2\n\
Orientation = 0 1 1 0\nElementByteOrderMSB = False\nElementType = MET_UCHAR\n\
ElementDataFile = LOCAL\n"
        .to_vec();
    bytes.extend_from_slice(&[1, 2, 3, 4, 5, 6]);
    let (vol, _) = metaimage::read_bytes(&bytes).unwrap();
    let g = *vol.geometry();
    assert_eq!(g.dims, [3, 2, 1]);
    assert_eq!(g.spacing, DVec3::new(0.5, 0.25, 1.0));
    assert_eq!(g.origin, DVec3::new(1.0, 2.0, 0.0));
    assert_eq!(g.direction, DMat3::from_cols(DVec3::Y, DVec3::X, DVec3::Z));
    assert_eq!(vol.as_bytes(), &[1, 2, 3, 4, 5, 6]);
}

#[test]
fn ascii_and_zlib_payloads() {
    let ascii = b"NDims = 3\nDimSize = 2 1 2\nBinaryData = False\nElementType = MET_FLOAT\n\
ElementDataFile = LOCAL\n0.1 -2\n  3e2\n4.5\n";
    let (vol, _) = metaimage::read_bytes(ascii).unwrap();
    assert_eq!(vol.to_typed::<f32>().data(), &[0.1f32, -2.0, 300.0, 4.5]);

    let data = le_i16(&[5, -6, 7, -8, 9, -10]);
    let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    enc.write_all(&data).unwrap();
    let z = enc.finish().unwrap();
    let mut bytes = format!(
        "NDims = 3\nDimSize = 3 2 1\nCompressedData = True\nCompressedDataSize = {}\n\
         ElementType = MET_SHORT\nElementDataFile = LOCAL\n",
        z.len()
    )
    .into_bytes();
    bytes.extend_from_slice(&z);
    let (vol, _) = metaimage::read_bytes(&bytes).unwrap();
    assert_eq!(vol.to_typed::<i16>().data(), &[5, -6, 7, -8, 9, -10]);
}

#[test]
fn detached_data_file_with_header_size() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("data")).unwrap();
    let mut raw = vec![0xAAu8; 16];
    raw.extend_from_slice(&le_i16(&[1, 2, 3, 4]));
    std::fs::write(dir.path().join("data/img.raw"), &raw).unwrap();
    let hdr = dir.path().join("img.mhd");
    std::fs::write(
        &hdr,
        "NDims = 3\nDimSize = 2 2 1\nHeaderSize = 16\nElementType = MET_SHORT\n\
         ElementDataFile = data/img.raw\n",
    )
    .unwrap();
    let v = format::read(&hdr).unwrap();
    assert_eq!(v.to_typed::<i16>().data(), &[1, 2, 3, 4]);

    // HeaderSize = -1: the data are the last bytes of the file.
    std::fs::write(
        &hdr,
        "NDims = 3\nDimSize = 2 1 1\nHeaderSize = -1\nElementType = MET_SHORT\n\
         ElementDataFile = data/img.raw\n",
    )
    .unwrap();
    let v = format::read(&hdr).unwrap();
    assert_eq!(v.to_typed::<i16>().data(), &[3, 4]);

    // A hand-edited detached header whose last line has no newline.
    std::fs::write(
        &hdr,
        "NDims = 3\nDimSize = 1 1 2\nElementType = MET_SHORT\nHeaderSize = 20\n\
         ElementDataFile = data/img.raw",
    )
    .unwrap();
    let v = format::read(&hdr).unwrap();
    assert_eq!(v.to_typed::<i16>().data(), &[3, 4]);
}

fn read_err(bytes: &[u8]) -> VolumeError {
    common::read_err(metaimage::read_bytes, bytes)
}

fn assert_format_err(bytes: &[u8], needle: &str) {
    common::assert_format_err(metaimage::read_bytes, bytes, needle);
}

fn assert_unsupported(bytes: &[u8], needle: &str) {
    common::assert_unsupported(metaimage::read_bytes, bytes, needle);
}

const TAIL: &str = "ElementType = MET_UCHAR\nElementDataFile = LOCAL\n";

fn hdr(body: &str) -> Vec<u8> {
    let mut b = format!("{body}{TAIL}").into_bytes();
    b.extend_from_slice(&[0u8; 8]);
    b
}

#[test]
fn malformed_headers_are_clear_errors() {
    assert_format_err(&hdr("DimSize = 2 2 2\n"), "NDims");
    assert_format_err(&hdr("NDims = 3\n"), "DimSize");
    assert_format_err(
        b"NDims = 3\nDimSize = 2 2 2\nElementDataFile = LOCAL\n",
        "ElementType",
    );
    assert_format_err(
        b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n",
        "ElementDataFile",
    );
    assert_format_err(&hdr("NDims = 3\nDimSize = 2 2\n"), "DimSize");
    assert_format_err(&hdr("NDims = 3\nDimSize = 2 0 2\n"), "zero");
    assert_format_err(&hdr("NDims = 3\nDimSize = 2 -1 2\n"), "negative");
    assert_format_err(
        &hdr("NDims = 3\nDimSize = 99999999999999999999 2 2\n"),
        "overflows",
    );
    // Each size fits, the product does not: refused before allocation.
    let e = read_err(&hdr(
        "NDims = 3\nDimSize = 4000000000 4000000000 4000000000\n",
    ));
    assert!(e.to_string().contains("dims"), "{e}");
    assert_format_err(
        &hdr("NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 nan 1\n"),
        "not finite",
    );
    assert_format_err(
        &hdr("NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 x 1\n"),
        "not a number",
    );
    assert_format_err(
        &hdr("NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 0 1\n"),
        "positive",
    );
    assert_format_err(
        &hdr("NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 -1 1\n"),
        "positive",
    );
    assert_format_err(
        &hdr("NDims = 3\nDimSize = 2 2 2\nOffset = 0 inf 0\n"),
        "not finite",
    );
    assert_format_err(
        &hdr("NDims = 3\nDimSize = 2 2 2\nTransformMatrix = 1 0 0 0 0 0 0 0 1\n"),
        "singular",
    );
    assert_format_err(
        &hdr("NDims = 3\nDimSize = 2 2 2\nno equals sign\n"),
        "Key = Value",
    );
    assert_format_err(
        b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_BANANA\nElementDataFile = LOCAL\n",
        "unknown ElementType",
    );
    assert_format_err(
        &hdr("NDims = 3\nDimSize = 2 2 2\nBinaryDataByteOrderMSB = maybe\n"),
        "True or False",
    );
    assert_unsupported(
        b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_LONG_LONG\nElementDataFile = LOCAL\n",
        "MET_LONG_LONG",
    );
    assert_unsupported(
        &hdr("NDims = 3\nDimSize = 2 2 2\nElementNumberOfChannels = 3\n"),
        "ElementNumberOfChannels",
    );
    assert_unsupported(&hdr("NDims = 5\nDimSize = 2 2 2 2 2\n"), "NDims");
    assert_unsupported(
        &hdr("ObjectType = Mesh\nNDims = 3\nDimSize = 2 2 2\n"),
        "Mesh",
    );
    assert_unsupported(
        b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LIST\na.raw\n",
        "LIST",
    );
    assert_unsupported(
        b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = s%03d.raw 1 2 1\n",
        "pattern",
    );
}

/// Issue: `.mha` voxels followed by more bytes than the header declares read without error
/// (the extra bytes ignored). Inline raw data fill the rest of the file exactly.
#[test]
fn inline_data_longer_than_declared_is_refused() {
    let mut b =
        b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n".to_vec();
    b.extend_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
    assert_eq!(
        metaimage::read_bytes(&b).unwrap().0.as_bytes(),
        &[1, 2, 3, 4, 5, 6, 7, 8]
    );
    b.push(9);
    assert_format_err(&b, "voxel data size mismatch");
    assert_format_err(
        &b,
        "the data after the header (ElementDataFile = LOCAL) holds 9 bytes, but DimSize and \
         ElementType declare 8 bytes",
    );
}

#[test]
fn malformed_data_is_a_clear_error() {
    // Truncated: 8 voxels declared, 5 present.
    let mut b =
        b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n".to_vec();
    b.extend_from_slice(&[1, 2, 3, 4, 5]);
    assert_format_err(&b, "truncated");

    // Corrupt zlib stream.
    let mut b = b"NDims = 3\nDimSize = 2 2 2\nCompressedData = True\nElementType = MET_UCHAR\n\
ElementDataFile = LOCAL\n"
        .to_vec();
    b.extend_from_slice(&[0x78, 0x9c, 0xff, 0xff, 0x00, 0x12, 0x34, 0x56]);
    assert_format_err(&b, "zlib");

    // A truncated zlib stream.
    let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(&[7u8; 1000]).unwrap();
    let z = enc.finish().unwrap();
    let mut b = b"NDims = 3\nDimSize = 10 10 10\nCompressedData = True\nElementType = MET_UCHAR\n\
ElementDataFile = LOCAL\n"
        .to_vec();
    b.extend_from_slice(&z[..z.len() / 2]);
    assert!(metaimage::read_bytes(&b).is_err());

    // A tiny compressed payload cannot claim gigabytes.
    let mut b = b"NDims = 3\nDimSize = 2000 2000 2000\nCompressedData = True\n\
ElementType = MET_UCHAR\nElementDataFile = LOCAL\n"
        .to_vec();
    b.extend_from_slice(&z);
    assert_format_err(&b, "cannot hold");

    // CompressedDataSize larger than what is present.
    let mut b =
        b"NDims = 3\nDimSize = 10 10 10\nCompressedData = True\nCompressedDataSize = 9999\n\
ElementType = MET_UCHAR\nElementDataFile = LOCAL\n"
            .to_vec();
    b.extend_from_slice(&z);
    assert_format_err(&b, "9999");
}

#[test]
fn huge_header_line_is_refused_quickly() {
    let mut b = b"NDims = 3\nComment = ".to_vec();
    b.resize(3 << 20, b'a');
    let t = std::time::Instant::now();
    assert_format_err(&b, "ElementDataFile");
    assert!(t.elapsed().as_secs_f64() < 2.0);

    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("huge.mha");
    std::fs::write(&p, &b).unwrap();
    assert!(format::read(&p).is_err());
}

#[test]
fn missing_data_file_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.mhd");
    std::fs::write(
        &p,
        "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = nothere.raw\n",
    )
    .unwrap();
    let e = format::read(&p).unwrap_err().to_string();
    assert!(e.contains("nothere.raw") && e.contains("not found"), "{e}");
    // read_bytes cannot follow a detached file.
    let e = metaimage::read_bytes(&std::fs::read(&p).unwrap()).unwrap_err();
    assert!(matches!(e, VolumeError::Unsupported(_)), "{e:?}");
}

#[test]
fn failed_write_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("missing_dir/x.mhd");
    let vol = random_volume(VoxelType::U8, Geometry::new([2, 2, 2]), 1);
    assert!(format::write(&p, &vol).is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Not a test of correctness: prints the time to read a 256³ `i16` volume.
#[test]
#[ignore = "timing; run with --release -- --ignored --nocapture"]
fn timing_256_cubed() {
    let dir = tempfile::tempdir().unwrap();
    let g = Geometry::new([256, 256, 256]);
    let vol = random_volume(VoxelType::I16, g, 3);
    for (name, compress) in [
        ("a.mha", false),
        ("b.mhd", false),
        ("c.mha", true),
        ("d.nrrd", false),
        ("e.nrrd", true),
        ("f.vtk", false),
    ] {
        let p = dir.path().join(name);
        let opts = WriteOptions { compress, level: 1 };
        let t = std::time::Instant::now();
        format::write_with(&p, &vol, &opts).unwrap();
        let w = t.elapsed();
        let t = std::time::Instant::now();
        let r = format::read(&p).unwrap();
        let rd = t.elapsed();
        assert_eq!(r.as_bytes(), vol.as_bytes());
        println!("{name} compress={compress}: write {w:?}, read {rd:?}");
    }
}

mod fuzz {
    use super::*;

    fn make_seeds() -> Vec<Vec<u8>> {
        let dir = tempfile::tempdir().unwrap();
        let mut out = Vec::new();
        for (vt, compress) in [(VoxelType::I16, false), (VoxelType::F32, true)] {
            let p = dir.path().join("s.mha");
            let vol = random_volume(vt, oblique(), 9);
            format::write_with(&p, &vol, &WriteOptions { compress, level: 1 }).unwrap();
            out.push(std::fs::read(&p).unwrap());
        }
        out.push(
            b"NDims = 2\nDimSize = 2 2\nBinaryData = False\nElementType = MET_INT\n\
ElementDataFile = LOCAL\n1 2 3 4\n"
                .to_vec(),
        );
        out
    }

    /// Corrupted files give an error or a valid volume, never a panic.
    #[test]
    fn mutated_files_never_panic() {
        common::assert_mutations_never_panic(metaimage::read_bytes, &make_seeds());
    }
}

/// Every file of the malformed corpus is refused with an error (never a panic), both by
/// path and, for single-file forms, from memory.
#[test]
fn malformed_corpus_is_refused() {
    common::assert_corpus_refused("metaimage", metaimage::read_bytes);
}
