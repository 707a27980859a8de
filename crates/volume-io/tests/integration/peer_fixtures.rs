//! Files written by the tools people use, read by volmorph with the geometry and values those
//! tools themselves read back: `tests/corpus/peers/` was made once by
//! `scripts/make_volume_fixtures.py` with nibabel 5.4, SimpleITK 2.5.7, VTK 9.6 and pydicom
//! 3.0 (see its docstring), and `expected.json` holds each peer's own reading — geometry in
//! ITK/LPS convention (direction row-major), every voxel value in x-fastest order.

use crate::common;

use std::path::{Path, PathBuf};

use volmorph_volume::direction::orthonormality_deviation;
use volmorph_volume::{DMat3, with_volume};
use volmorph_volume_io::{self as format, ReadOptions};

fn corpus() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/corpus/peers")
}

fn expected() -> serde_json::Map<String, serde_json::Value> {
    let text = std::fs::read_to_string(corpus().join("expected.json")).unwrap();
    serde_json::from_str::<serde_json::Value>(&text)
        .unwrap()
        .as_object()
        .unwrap()
        .clone()
}

fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Read fixture `key` (`file` or `file#frame`) and compare with the peer's reading.
fn check(key: &str, want: &serde_json::Value) {
    let (file, frame) = match key.split_once('#') {
        Some((f, t)) => (f, Some(t.parse::<usize>().unwrap())),
        None => (key, None),
    };
    let path = corpus().join(file);
    let got = format::read_with(
        &path,
        &ReadOptions {
            frame,
            ..ReadOptions::default()
        },
    )
    .unwrap_or_else(|e| panic!("{key}: {e}"));
    if let Some(n) = want.get("frames") {
        assert_eq!(got.frames as u64, n.as_u64().unwrap(), "{key}: frames");
    }
    let g = got.volume.geometry();
    let dims: Vec<usize> = want["dims"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(g.dims.to_vec(), dims, "{key}: dims");
    let close = |a: &[f64], b: &[f64], tol: f64, what: &str| {
        for (x, y) in a.iter().zip(b) {
            assert!(
                (x - y).abs() <= tol * y.abs().max(1.0),
                "{key}: {what} {a:?} vs {b:?}"
            );
        }
    };
    close(
        &g.spacing.to_array(),
        &floats(&want["spacing"]),
        1e-6,
        "spacing",
    );
    close(
        &g.origin.to_array(),
        &floats(&want["origin"]),
        1e-5,
        "origin",
    );
    let d = floats(&want["direction"]);
    let peer = DMat3::from_cols_array(&d.clone().try_into().unwrap()).transpose();
    close(
        &g.direction.transpose().to_cols_array(),
        &d,
        2e-7,
        "direction",
    );
    // The one direction rule: oblique directions become exactly orthonormal.
    if orthonormality_deviation(peer) <= 1e-4 {
        assert!(orthonormality_deviation(g.direction) <= 1e-15, "{key}");
    }
    let values = floats(&want["values"]);
    let ours: Vec<f64> = with_volume!(&got.volume, v => v.data().iter().map(|x| volmorph_volume::Voxel::to_f64(*x)).collect());
    assert_eq!(ours.len(), values.len(), "{key}: voxel count");
    for (i, (a, b)) in ours.iter().zip(&values).enumerate() {
        assert!(
            (a - b).abs() <= 1e-6 * b.abs().max(1.0),
            "{key}: voxel {i}: {a} vs {b}"
        );
    }
}

fn check_prefix(prefix: &str) {
    let all = expected();
    let mut n = 0;
    for (key, want) in &all {
        if key.starts_with(prefix) {
            check(key, want);
            n += 1;
        }
    }
    assert!(n > 0, "no fixture starts with {prefix}");
}

#[test]
fn nibabel_oblique_nifti_matches_nibabel() {
    check_prefix("nibabel_oblique.nii.gz");
}

#[test]
fn simpleitk_oblique_nifti_matches_simpleitk() {
    check_prefix("sitk_oblique.nii.gz");
}

#[test]
fn nifti2_written_by_nibabel_keeps_double_precision() {
    check_prefix("nibabel_nifti2.nii");
    let f = format::read_with_header(&corpus().join("nibabel_nifti2.nii")).unwrap();
    let size = f.header.fields.iter().find(|(k, _)| k == "sizeof_hdr");
    assert_eq!(size.map(|(_, v)| v.as_str()), Some("540"));
}

#[test]
fn four_d_nifti_frames_match_nibabel() {
    check_prefix("nibabel_4d.nii.gz#");
    // Without a frame the series is refused, naming its length.
    let e = format::read(&corpus().join("nibabel_4d.nii.gz")).unwrap_err();
    assert!(e.to_string().contains("3 frames"), "{e}");
    let e = format::read_with(
        &corpus().join("nibabel_4d.nii.gz"),
        &ReadOptions {
            frame: Some(3),
            ..ReadOptions::default()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("frame 3 does not exist"), "{e}");
}

/// `ReadOptions::default_frame` (the command line's global `--frame`) picks the frame of a
/// series, reads a 3-D file as it is, and refuses a series without that frame; an explicit
/// `frame` is strict even for a 3-D file.
#[test]
fn default_frame_reads_series_frames_and_leaves_3d_files_alone() {
    let series = corpus().join("nibabel_4d.nii.gz");
    let single = corpus().join("nibabel_4d_frame1.nii.gz");
    let with = |default_frame, frame| ReadOptions {
        frame,
        default_frame,
        ..ReadOptions::default()
    };
    let f = format::read_with(&series, &with(Some(1), None)).unwrap();
    assert_eq!((f.frame, f.frames), (1, 3));
    let alone = format::read(&single).unwrap();
    assert_eq!(f.volume.as_bytes(), alone.as_bytes());
    assert_eq!(f.volume.geometry(), alone.geometry());
    let g = format::read_with(&single, &with(Some(2), None)).unwrap();
    assert_eq!((g.frame, g.frames), (0, 1));
    assert_eq!(g.volume.as_bytes(), alone.as_bytes());
    let e = format::read_with(&series, &with(Some(3), None)).unwrap_err();
    assert!(e.to_string().contains("frame 3 does not exist"), "{e}");
    let e = format::read_with(&single, &with(None, Some(2))).unwrap_err();
    assert!(e.to_string().contains("frame 2 does not exist"), "{e}");
}

#[test]
fn vti_in_every_vtk_layout_matches_vtk() {
    check_prefix("vtk_");
}

#[test]
fn mgz_matches_nibabel() {
    check_prefix("nibabel_oblique_u8.mgz");
    check_prefix("nibabel_f32.mgz");
}

#[test]
fn dicom_series_written_by_simpleitk_matches_simpleitk() {
    check_prefix("sitk_ct_series");
    // Any file of the series reads the whole series.
    let one = corpus().join("sitk_ct_series/slice2.dcm");
    let v = format::read(&one).unwrap();
    assert_eq!(v.geometry().dims, [8, 6, 5]);
}

#[test]
fn enhanced_multiframe_dicom_matches_pydicom() {
    check_prefix("pydicom_enhanced_ct.dcm");
}

/// RT Dose frames are placed by `GridFrameOffsetVector` (here absolute, its first element the
/// z of `ImagePositionPatient`) and scaled to Gy by `DoseGridScaling`. Regression: such files
/// were refused ("needs SpacingBetweenSlices or SliceThickness") or read unscaled.
#[test]
fn rtdose_grid_frame_offsets_and_dose_scaling_match_pydicom() {
    check_prefix("pydicom_rtdose.dcm");
}

/// Regression: 32-bit pixels of an explicit VR big endian file were read with their bytes
/// in the wrong order.
#[test]
fn big_endian_rtdose_values_match_pydicom() {
    check_prefix("pydicom_rtdose_be_1frame.dcm");
}

/// Regression: geometry attributes stored with VR UN ("no ImageOrientationPatient") were
/// not found; they are read as their dictionary VR.
#[test]
fn attributes_stored_with_vr_un_are_read_by_their_dictionary_vr() {
    check_prefix("pydicom_un_vr.dcm");
}

/// The in-memory DICOM entry point reads a multi-frame file and a single slice as the path
/// reader does.
#[test]
fn dicom_bytes_read_as_the_file() {
    for f in [
        "pydicom_enhanced_ct.dcm",
        "pydicom_rtdose.dcm",
        "pydicom_un_vr.dcm",
    ] {
        let p = corpus().join(f);
        let (v, _) = format::dicom::read_bytes(&std::fs::read(&p).unwrap()).unwrap();
        let w = format::read(&p).unwrap();
        assert_eq!(v.as_bytes(), w.as_bytes(), "{f}");
        assert_eq!(v.geometry().dims, w.geometry().dims, "{f}");
        let d = (v.geometry().origin - w.geometry().origin).length();
        assert!(d < 1e-12, "{f}");
    }
}

fn seeds(names: &[&str]) -> Vec<Vec<u8>> {
    names
        .iter()
        .map(|n| std::fs::read(corpus().join(n)).unwrap())
        .collect()
}

/// Mutation fuzzing of the VTK XML reader from VTK-written seeds: every corrupted file gives
/// an error or a valid volume, never a panic.
#[test]
fn mutated_vti_files_never_panic() {
    common::assert_mutations_never_panic(
        format::vti::read_bytes,
        &seeds(&[
            "vtk_ascii.vti",
            "vtk_appended_raw_zlib.vti",
            "vtk_binary.vti",
        ]),
    );
}

/// Mutation fuzzing of the MGH reader from nibabel-written seeds.
#[test]
fn mutated_mgz_files_never_panic() {
    common::assert_mutations_never_panic(
        |b| format::mgh::read_bytes(b, Some(0)).map(|(v, h, _)| (v, h)),
        &seeds(&["nibabel_f32.mgz", "nibabel_oblique_u8.mgz"]),
    );
}

/// Mutation fuzzing of the DICOM reader from pydicom- and SimpleITK-written seeds.
#[test]
fn mutated_dicom_files_never_panic() {
    common::assert_mutations_never_panic(
        format::dicom::read_bytes,
        &seeds(&[
            "pydicom_enhanced_ct.dcm",
            "pydicom_rtdose.dcm",
            "pydicom_un_vr.dcm",
            "sitk_ct_series/slice0.dcm",
        ]),
    );
}

#[test]
fn every_fixture_is_checked() {
    let covered = [
        "nibabel_oblique.nii.gz",
        "sitk_oblique.nii.gz",
        "nibabel_nifti2.nii",
        "nibabel_4d.nii.gz#",
        "vtk_",
        "nibabel_oblique_u8.mgz",
        "nibabel_f32.mgz",
        "sitk_ct_series",
        "pydicom_enhanced_ct.dcm",
        "pydicom_rtdose.dcm",
        "pydicom_rtdose_be_1frame.dcm",
        "pydicom_un_vr.dcm",
    ];
    for key in expected().keys() {
        assert!(
            covered.iter().any(|p| key.starts_with(p)),
            "fixture {key} has no test"
        );
    }
    assert!(Path::new(&corpus().join("expected.json")).is_file());
}
