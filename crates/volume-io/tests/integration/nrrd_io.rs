//! NRRD reading and writing: round trips, hand-written (Slicer/teem-style) headers,
//! malformed input.

use crate::common;

use common::{oblique, random_volume};
use std::io::Write;

use volmorph_volume::{AnyVolume, DMat3, DVec3, Geometry, VolumeError, VoxelType};
use volmorph_volume_io::{self as format, Format, WriteOptions, nrrd};

/// NRRD stores only `direction · diag(spacing)`: spacing and direction come back to within
/// a few ulps, dims/origin/voxels exactly.
fn assert_close(a: &AnyVolume, b: &AnyVolume) {
    let (ga, gb) = (a.geometry(), b.geometry());
    assert_eq!(a.voxel_type(), b.voxel_type());
    assert_eq!(ga.dims, gb.dims);
    assert_eq!(ga.origin, gb.origin, "origin is stored exactly");
    assert!(((ga.spacing - gb.spacing) / ga.spacing).abs().max_element() < 4.0 * f64::EPSILON);
    let dd = (ga.direction - gb.direction).to_cols_array();
    assert!(dd.iter().all(|d| d.abs() < 4.0 * f64::EPSILON), "{dd:?}");
    // The stored product `direction · diag(spacing)` agrees to rounding.
    let dm = (ga.index_to_physical_matrix() - gb.index_to_physical_matrix()).to_cols_array();
    assert!(dm.iter().all(|d| d.abs() < 8.0 * f64::EPSILON), "{dm:?}");
    assert_eq!(a.as_bytes(), b.as_bytes(), "voxels must be bit-exact");
}

#[test]
fn round_trip_every_type_and_variant() {
    let dir = tempfile::tempdir().unwrap();
    for (k, vt) in VoxelType::ALL.into_iter().enumerate() {
        let vol = random_volume(vt, oblique(), 11 + k as u64);
        for (ext, compress) in [
            ("nrrd", false),
            ("nrrd", true),
            ("nhdr", false),
            ("nhdr", true),
        ] {
            let p = dir.path().join(format!("v_{vt}_{compress}.{ext}"));
            let opts = WriteOptions { compress, level: 2 };
            format::write_with(&p, &vol, &opts).unwrap();
            let f = format::read_with_header(&p).unwrap();
            assert_eq!(f.format, Format::Nrrd);
            assert_close(&vol, &f.volume);
            let enc = f
                .header
                .fields
                .iter()
                .find(|(k, _)| k == "encoding")
                .unwrap();
            assert_eq!(enc.1, if compress { "gzip" } else { "raw" });
            if ext == "nhdr" {
                let name = &f
                    .header
                    .fields
                    .iter()
                    .find(|(k, _)| k == "data file")
                    .unwrap()
                    .1;
                let prefix = format!("v_{vt}_{compress}.nhdr.");
                let ext = if compress { ".raw.gz" } else { ".raw" };
                assert!(name.starts_with(&prefix) && name.ends_with(ext), "{name}");
                assert!(dir.path().join(name).is_file());
            } else {
                let (v2, _) = nrrd::read_bytes(&std::fs::read(&p).unwrap()).unwrap();
                assert_close(&vol, &v2);
            }
        }
    }
}

#[test]
fn axis_aligned_round_trip_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let g = Geometry::new([3, 4, 5])
        .with_spacing(DVec3::new(0.1, 1.0 / 3.0, 2.5e-7))
        .with_origin(DVec3::new(-0.0, 1e300, -123.456));
    let vol = random_volume(VoxelType::F64, g, 5);
    let p = dir.path().join("a.nrrd");
    format::write(&p, &vol).unwrap();
    let back = format::read(&p).unwrap();
    assert_eq!(back.geometry(), vol.geometry());
    assert_eq!(back.as_bytes(), vol.as_bytes());
    let text = std::fs::read(&p).unwrap();
    let text = String::from_utf8_lossy(&text[..300]);
    assert!(text.starts_with("NRRD0004\n"), "{text}");
    assert!(
        text.contains("space directions: (0.1,0,0) (0,0.3333333333333333,0) (0,0,2.5e-7)\n"),
        "{text}"
    );
    assert!(text.contains("space: left-posterior-superior\n"));
    assert!(text.contains("kinds: domain domain domain\n"));
    assert!(text.contains("endian: little\n"));
}

const SLICER_RAS: &str = "NRRD0004
# Complete NRRD file format specification at:
# http://teem.sourceforge.net/nrrd/format.html
type:=a key named like a field is not the field
type: short
dimension: 3
space: right-anterior-superior
sizes: 2 2 2
space directions: (-0.9375,0,0) (0,-0.9375,0) (0,0,1.5)
kinds: domain domain domain
endian: little
encoding: raw
space origin: (119.53125,119.53125,-60.25)
Segment0_Name:=liver
";

#[test]
fn slicer_style_ras_header_converts_to_lps() {
    let mut b = format!("{SLICER_RAS}\n").into_bytes();
    for v in 0i16..8 {
        b.extend_from_slice(&(v * 100 - 300).to_le_bytes());
    }
    let (vol, header) = nrrd::read_bytes(&b).unwrap();
    let g = *vol.geometry();
    assert_eq!(g.dims, [2, 2, 2]);
    assert_eq!(g.spacing, DVec3::new(0.9375, 0.9375, 1.5));
    // RAS (−0.9375, 0, 0) is LPS (+0.9375, 0, 0): identity direction.
    assert_eq!(g.direction, DMat3::IDENTITY);
    assert_eq!(g.origin, DVec3::new(-119.53125, -119.53125, -60.25));
    assert_eq!(
        vol.to_typed::<i16>().data(),
        &[-300, -200, -100, 0, 100, 200, 300, 400]
    );
    assert!(
        header
            .fields
            .contains(&("Segment0_Name".to_string(), "liver".to_string()))
    );
    assert_eq!(header.fields[0].1, "NRRD0004");
}

#[test]
fn oblique_ras_and_las_headers() {
    // Axis i: 2 mm along RAS (0.6, 0.8, 0); axis j: 1 mm along RAS (−0.8, 0.6, 0);
    // axis k: 3 mm along RAS z.
    let body = |space: &str| {
        let mut b = format!(
            "NRRD0005\ntype: uchar\ndimension: 3\nspace: {space}\nsizes: 2 1 1\n\
             space directions: (1.2, 1.6, 0) (-0.8,0.6,0) (0,0,3)\nencoding: raw\n\
             space origin: (10,20,30)\n\n"
        )
        .into_bytes();
        b.extend_from_slice(&[9, 8]);
        b
    };
    let (vol, _) = nrrd::read_bytes(&body("RAS")).unwrap();
    let g = vol.geometry();
    assert_eq!(g.spacing, DVec3::new(2.0, 1.0, 3.0));
    assert!((g.direction.x_axis - DVec3::new(-0.6, -0.8, 0.0)).length() < 1e-15);
    assert!((g.direction.y_axis - DVec3::new(0.8, -0.6, 0.0)).length() < 1e-15);
    assert_eq!(g.direction.z_axis, DVec3::Z);
    assert_eq!(g.origin, DVec3::new(-10.0, -20.0, 30.0));
    // Physical position of voxel (1, 0, 0) in LPS = −(RAS x, y).
    let p = g.index_to_physical(DVec3::X);
    assert!((p - DVec3::new(-11.2, -21.6, 30.0)).length() < 1e-12);

    let (vol, _) = nrrd::read_bytes(&body("left-anterior-superior")).unwrap();
    let g = vol.geometry();
    assert!((g.direction.x_axis - DVec3::new(0.6, -0.8, 0.0)).length() < 1e-15);
    assert_eq!(g.origin, DVec3::new(10.0, -20.0, 30.0));

    let (vol, _) = nrrd::read_bytes(&body("scanner-xyz")).unwrap();
    assert_eq!(vol.geometry().origin, DVec3::new(10.0, 20.0, 30.0));
    assert_eq!(vol.as_bytes(), &[9, 8]);
}

#[test]
fn non_spatial_axes_of_size_one_are_dropped() {
    let mut b = b"NRRD0004\ntype: float\ndimension: 4\nspace: left-posterior-superior\n\
sizes: 1 2 3 1\nspace directions: none (0.5,0,0) (0,0.25,0) (0,0,2)\n\
kinds: vector domain domain domain\nendian: big\nencoding: raw\n\n"
        .to_vec();
    for v in 0..6 {
        b.extend_from_slice(&(v as f32 * 1.5).to_be_bytes());
    }
    let (vol, _) = nrrd::read_bytes(&b).unwrap();
    let g = vol.geometry();
    assert_eq!(g.dims, [2, 3, 1]);
    assert_eq!(g.spacing, DVec3::new(0.5, 0.25, 2.0));
    assert_eq!(
        vol.to_typed::<f32>().data(),
        &[0.0, 1.5, 3.0, 4.5, 6.0, 7.5]
    );

    // Trailing list axis of size 1, described by kinds only.
    let mut b = b"NRRD0004\ntype: uint8\ndimension: 4\nsizes: 2 2 1 1\n\
kinds: domain domain domain list\nencoding: raw\n\n"
        .to_vec();
    b.extend_from_slice(&[1, 2, 3, 4]);
    let (vol, _) = nrrd::read_bytes(&b).unwrap();
    assert_eq!(vol.geometry().dims, [2, 2, 1]);

    // A real vector axis is refused.
    let mut b = b"NRRD0004\ntype: uint8\ndimension: 4\nsizes: 3 2 2 1\n\
kinds: RGB-color domain domain domain\nencoding: raw\n\n"
        .to_vec();
    b.extend_from_slice(&[0; 12]);
    let e = nrrd::read_bytes(&b).unwrap_err();
    assert!(matches!(e, VolumeError::Unsupported(_)), "{e:?}");
    assert!(e.to_string().contains("RGB-color"), "{e}");
}

#[test]
fn spacings_axis_mins_and_two_d() {
    // No space: spacings and axis mins, cell centering moves the origin half a voxel.
    let mut b = b"NRRD0001\n# a comment\ntype: unsigned short\ndimension: 2\nsizes: 3 2\n\
spacings: 0.5 -2\naxis mins: 10 NaN\ncenters: cell node\nendian: little\nencoding: raw\n\n"
        .to_vec();
    for v in [1u16, 2, 3, 4, 5, 6] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    let (vol, _) = nrrd::read_bytes(&b).unwrap();
    let g = vol.geometry();
    assert_eq!(g.dims, [3, 2, 1]);
    assert_eq!(g.spacing, DVec3::new(0.5, 2.0, 1.0));
    assert_eq!(g.origin, DVec3::new(10.25, 0.0, 0.0));
    // A negative spacing flips the axis.
    assert_eq!(g.direction.y_axis, DVec3::NEG_Y);
    assert_eq!(
        g.direction.z_axis,
        DVec3::Z,
        "2-D direction padded as ITK does"
    );
    assert_eq!(vol.to_typed::<u16>().data(), &[1, 2, 3, 4, 5, 6]);
}

#[test]
fn ascii_gzip_and_big_endian_encodings() {
    let (vol, _) = nrrd::read_bytes(
        b"NRRD0004\ntype: double\ndimension: 3\nsizes: 2 2 1\nencoding: text\n\n\
0.1 -2.5\n1e300   4\n",
    )
    .unwrap();
    assert_eq!(vol.to_typed::<f64>().data(), &[0.1, -2.5, 1e300, 4.0]);

    let payload: Vec<u8> = [1i32, -2, 70000, i32::MIN]
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(&payload).unwrap();
    let gz = enc.finish().unwrap();
    let mut b = b"NRRD0004\ntype: int32_t\ndimension: 3\nsizes: 1 4 1\nendian: big\n\
encoding: gz\n\n"
        .to_vec();
    b.extend_from_slice(&gz);
    let (vol, _) = nrrd::read_bytes(&b).unwrap();
    assert_eq!(vol.to_typed::<i32>().data(), &[1, -2, 70000, i32::MIN]);
    assert_eq!(vol.geometry().dims, [1, 4, 1]);
}

#[test]
fn detached_header_with_skips() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("d")).unwrap();
    // Two text lines, then 3 junk bytes, then the voxels.
    let mut raw = b"line one\nline two\nxyz".to_vec();
    raw.extend_from_slice(&[10, 20, 30, 40]);
    std::fs::write(dir.path().join("d/data.bin"), &raw).unwrap();
    let hdr = dir.path().join("h.nhdr");
    std::fs::write(
        &hdr,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 1\nencoding: raw\nline skip: 2\n\
         byte skip: 3\ndata file: d/data.bin\n",
    )
    .unwrap();
    assert_eq!(format::read(&hdr).unwrap().as_bytes(), &[10, 20, 30, 40]);

    // byte skip -1: the voxels are the last bytes.
    std::fs::write(
        &hdr,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 3 1 1\nencoding: raw\nbyte skip: -1\n\
         datafile: d/data.bin\n",
    )
    .unwrap();
    assert_eq!(format::read(&hdr).unwrap().as_bytes(), &[20, 30, 40]);

    // Gzip: line skip before, byte skip after decompression.
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(&[0, 0, 7, 8]).unwrap();
    let mut gz = b"skip me\n".to_vec();
    gz.extend_from_slice(&enc.finish().unwrap());
    std::fs::write(dir.path().join("d/data.gz"), &gz).unwrap();
    std::fs::write(
        &hdr,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 1 1\nencoding: gzip\nline skip: 1\n\
         byte skip: 2\ndata file: d/data.gz\n",
    )
    .unwrap();
    assert_eq!(format::read(&hdr).unwrap().as_bytes(), &[7, 8]);
}

fn read_err(bytes: &[u8]) -> VolumeError {
    common::read_err(nrrd::read_bytes, bytes)
}

fn assert_format_err(bytes: &[u8], needle: &str) {
    common::assert_format_err(nrrd::read_bytes, bytes, needle);
}

fn assert_unsupported(bytes: &[u8], needle: &str) {
    common::assert_unsupported(nrrd::read_bytes, bytes, needle);
}

fn with(fields: &str) -> Vec<u8> {
    let mut b = format!("NRRD0004\n{fields}\n").into_bytes();
    b.extend_from_slice(&[0u8; 64]);
    b
}

#[test]
fn malformed_headers_are_clear_errors() {
    let ok = "type: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n";
    let mut exact = format!("NRRD0004\n{ok}\n").into_bytes();
    exact.extend_from_slice(&[0u8; 8]);
    assert!(nrrd::read_bytes(&exact).is_ok());
    assert_format_err(b"NRRX0004\n", "not a NRRD file");
    assert_format_err(b"", "magic");
    assert_unsupported(b"NRRD0007\ntype: uchar\n\n", "NRRD0007");
    assert_format_err(&with("dimension: 3\nsizes: 2 2 2\nencoding: raw\n"), "type");
    assert_format_err(
        &with("type: uchar\nsizes: 2 2 2\nencoding: raw\n"),
        "dimension",
    );
    assert_format_err(&with("type: uchar\ndimension: 3\nencoding: raw\n"), "sizes");
    assert_format_err(
        &with("type: uchar\ndimension: 3\nsizes: 2 2 2\n"),
        "encoding",
    );
    assert_format_err(
        &with("type: short\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"),
        "endian",
    );
    assert_format_err(
        &with("type: uchar\ndimension: 3\nsizes: 2 0 2\nencoding: raw\n"),
        "zero",
    );
    assert_format_err(
        &with("type: uchar\ndimension: 3\nsizes: 2 -2 2\nencoding: raw\n"),
        "negative",
    );
    assert_format_err(
        &with("type: uchar\ndimension: 3\nsizes: 2 2\nencoding: raw\n"),
        "sizes",
    );
    assert_format_err(
        &with("type: uchar\ndimension: 3\nsizes: 2 2 123456789012345678901234\nencoding: raw\n"),
        "overflows",
    );
    let e = read_err(&with(
        "type: uchar\ndimension: 3\nsizes: 4000000000 4000000000 4000000000\nencoding: raw\n",
    ));
    assert!(e.to_string().contains("dims"), "{e}");
    assert_format_err(
        &with("type: quaternion\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"),
        "unknown type",
    );
    assert_unsupported(
        &with("type: int64\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nendian: little\n"),
        "int64",
    );
    assert_unsupported(
        &with("type: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: bzip2\n"),
        "bzip2",
    );
    assert_unsupported(
        &with("type: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: hex\n"),
        "hex",
    );
    let sp = "type: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nspace: LPS\n";
    assert_format_err(
        &with(&format!(
            "{sp}space directions: (1,0,0) (0,NaN,0) (0,0,1)\n"
        )),
        "not finite",
    );
    assert_format_err(
        &with(&format!("{sp}space directions: (1,0,0) (0,0,0) (0,0,1)\n")),
        "zero or non-finite length",
    );
    assert_format_err(
        &with(&format!("{sp}space directions: (1,0,0) (0,1,0)\n")),
        "expected 3 vectors",
    );
    assert_format_err(
        &with(&format!(
            "{sp}space directions: (1,0,0) (0,1,0) (0,0,1)\nspace origin: (1,x,2)\n"
        )),
        "not a number",
    );
    assert_format_err(
        &with(&format!("{sp}space directions: (1,0,0) (1,0,0) (0,0,1)\n")),
        "singular",
    );
    assert_format_err(
        &with(&format!("{ok}space: mars-centric\n")),
        "unknown space",
    );
    assert_unsupported(
        &with(&format!("{ok}space: right-anterior-superior-time\n")),
        "time",
    );
    assert_format_err(&with(&format!("{ok}spacings: 1 0 1\n")), "spacing 0");
    assert_format_err(&with(&format!("{ok}spacings: 1 inf 1\n")), "not finite");
    assert_format_err(&with(&format!("{ok}not a field line\n")), "neither");
    assert_unsupported(&with(&format!("{ok}data file: LIST\n")), "LIST");
    assert_unsupported(
        &with(&format!("{ok}data file: slice%03d.raw 1 10 1\n")),
        "pattern",
    );
    assert_format_err(
        b"NRRD0004\ntype: uchar\ndimension: 1\nsizes: 4\nencoding: raw\n",
        "blank line",
    );
}

/// Issue: raw data followed by more bytes than the header declares read without error (the
/// extra bytes ignored). Attached raw data fill the rest of the file exactly, unless
/// `byte skip: -1` puts them at its end.
#[test]
fn inline_data_longer_than_declared_is_refused() {
    let head = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n";
    let mut b = format!("{head}\n").into_bytes();
    b.extend_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
    assert_eq!(
        nrrd::read_bytes(&b).unwrap().0.as_bytes(),
        &[1, 2, 3, 4, 5, 6, 7, 8]
    );
    b.push(9);
    assert_format_err(&b, "the data after the header holds 9 bytes");
    assert_format_err(&b, "sizes, type, line skip and byte skip declare 8 bytes");
    // byte skip -1: the last 8 bytes, whatever comes before.
    let mut b = format!("{head}byte skip: -1\n\n").into_bytes();
    b.extend_from_slice(&[0, 1, 2, 3, 4, 5, 6, 7, 8]);
    assert_eq!(
        nrrd::read_bytes(&b).unwrap().0.as_bytes(),
        &[1, 2, 3, 4, 5, 6, 7, 8]
    );
    // line skip and byte skip count towards the exact size.
    let mut b = format!("{head}line skip: 1\nbyte skip: 2\n\n").into_bytes();
    b.extend_from_slice(b"junk\nxy");
    b.extend_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
    assert_eq!(
        nrrd::read_bytes(&b).unwrap().0.as_bytes(),
        &[1, 2, 3, 4, 5, 6, 7, 8]
    );
    b.push(9);
    assert_format_err(&b, "after 1 skipped lines, but");
}

#[test]
fn malformed_data_is_a_clear_error() {
    let mut b = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n".to_vec();
    b.extend_from_slice(&[1, 2, 3]);
    assert_format_err(&b, "truncated");

    let mut b = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: gzip\n\n".to_vec();
    b.extend_from_slice(&[0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 0, 3, 0xde, 0xad, 0xbe, 0xef]);
    assert_format_err(&b, "gzip");

    let mut b = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: gzip\n\n".to_vec();
    b.extend_from_slice(b"definitely not gzip at all, but long enough to be read");
    assert_format_err(&b, "gzip");

    assert_format_err(
        b"NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 1\nencoding: ascii\n\n1 2 70000 4\n",
        "not a valid i16",
    );
    assert_format_err(
        b"NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 1\nencoding: ascii\n\n1 2 3\n",
        "truncated",
    );
}

#[test]
fn huge_header_line_and_missing_data_file() {
    let mut b = b"NRRD0004\ncontent: ".to_vec();
    b.resize(3 << 20, b'z');
    let t = std::time::Instant::now();
    assert_format_err(&b, "does not end");
    assert!(t.elapsed().as_secs_f64() < 2.0);

    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("huge.nrrd");
    std::fs::write(&p, &b).unwrap();
    assert!(format::read(&p).is_err());

    let p = dir.path().join("x.nhdr");
    std::fs::write(
        &p,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: gone.raw\n",
    )
    .unwrap();
    let e = format::read(&p).unwrap_err().to_string();
    assert!(e.contains("gone.raw") && e.contains("not found"), "{e}");
}

mod fuzz {
    use super::*;

    fn make_seeds() -> Vec<Vec<u8>> {
        let dir = tempfile::tempdir().unwrap();
        let mut out = Vec::new();
        for (vt, compress) in [(VoxelType::U16, false), (VoxelType::F64, true)] {
            let p = dir.path().join("s.nrrd");
            let vol = random_volume(vt, oblique(), 4);
            format::write_with(&p, &vol, &WriteOptions { compress, level: 1 }).unwrap();
            out.push(std::fs::read(&p).unwrap());
        }
        let mut b = format!("{SLICER_RAS}\n").into_bytes();
        b.extend_from_slice(&[1u8; 16]);
        out.push(b);
        out.push(
            b"NRRD0004\ntype: float\ndimension: 4\nsizes: 1 2 2 1\nkinds: vector domain domain \
list\nspacings: NaN 1 2 NaN\nencoding: ascii\n\n1 2 3 4\n"
                .to_vec(),
        );
        out
    }

    /// Corrupted files give an error or a valid volume, never a panic.
    #[test]
    fn mutated_files_never_panic() {
        common::assert_mutations_never_panic(nrrd::read_bytes, &make_seeds());
    }
}

/// Every file of the malformed corpus is refused with an error (never a panic), both by
/// path and, for single-file forms, from memory.
#[test]
fn malformed_corpus_is_refused() {
    common::assert_corpus_refused("nrrd", nrrd::read_bytes);
}
