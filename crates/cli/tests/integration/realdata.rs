//! End-to-end tests on scans as scanners and peer tools write them: oblique NIfTI (single
//! precision direction), 4-D series, DICOM folders, VTK XML. The inputs are the peer-made
//! fixtures of `crates/volume-io/tests/corpus/peers/` (see `scripts/make_volume_fixtures.py`).

use crate::common;

use std::path::{Path, PathBuf};

use common::{fails, ok};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../volume-io/tests/corpus/peers")
        .join(name)
}

fn info_json(path: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![&"info", &"--json", &path];
    for e in extra {
        args.push(e);
    }
    serde_json::from_str(&ok(&args)).expect("info --json prints JSON")
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    serde_json::from_value(v.clone()).unwrap()
}

/// Physical centre of the volume described by `info --json`.
fn centre(j: &serde_json::Value) -> [f64; 3] {
    let dims: [f64; 3] = serde_json::from_value(j["dims"].clone()).unwrap();
    let (s, o) = (vec3(&j["spacing"]), vec3(&j["origin"]));
    let d: [[f64; 3]; 3] = serde_json::from_value(j["direction"].clone()).unwrap();
    std::array::from_fn(|r| {
        o[r] + (0..3)
            .map(|c| d[r][c] * s[c] * (dims[c] - 1.0) / 2.0)
            .sum::<f64>()
    })
}

/// Regression: an oblique NIfTI whose direction is orthonormal only to single precision
/// (as scanners write them) was refused by `lattice init` and `drag` ("axes are not
/// orthonormal (|AᵀA − I| = 3e-9)").
#[test]
fn oblique_scan_lattice_init_and_drag_are_accepted() {
    let dir = tempfile::tempdir().unwrap();
    for scan in ["nibabel_oblique.nii.gz", "sitk_oblique.nii.gz"] {
        let scan = fixture(scan);
        let lat = dir.path().join("l.json");
        ok(&[
            &"lattice",
            &"init",
            &scan,
            &"--counts",
            &"6,6,5",
            &"-o",
            &lat,
        ]);
        let l: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&lat).unwrap()).unwrap();
        assert!(l.is_object());
        let j = info_json(&scan, &[]);
        let c = centre(&j);
        let from = format!("{},{},{}", c[0], c[1], c[2]);
        let to = format!("{},{},{}", c[0] + 0.5, c[1], c[2]);
        let out = dir.path().join("dragged.nii.gz");
        ok(&[
            &"drag",
            &scan,
            &"--from",
            &from,
            &"--to",
            &to,
            &"--radius",
            &"4",
            &"-o",
            &out,
        ]);
        let o = info_json(&out, &[]);
        assert_eq!(o["dims"], j["dims"]);
    }
}

#[test]
fn nifti_to_vtk_legacy_names_vti_and_vti_keeps_the_direction() {
    let dir = tempfile::tempdir().unwrap();
    let scan = fixture("nibabel_oblique.nii.gz");
    let legacy = dir.path().join("x.vtk");
    let e = fails(&[&"convert", &scan, &legacy]);
    assert!(e.contains(".vti"), "{e}");
    assert!(!legacy.exists());
    let vti = dir.path().join("x.vti");
    ok(&[&"convert", &scan, &vti]);
    let (a, b) = (info_json(&scan, &[]), info_json(&vti, &[]));
    assert_eq!(a["dims"], b["dims"]);
    for k in ["spacing", "origin"] {
        let (x, y) = (vec3(&a[k]), vec3(&b[k]));
        assert!((0..3).all(|i| x[i] == y[i]), "{k}: {x:?} vs {y:?}");
    }
    assert_eq!(a["direction"], b["direction"]);
    assert_eq!(a["stats"], b["stats"]);
}

#[test]
fn four_d_nifti_info_lists_frames_and_convert_takes_one() {
    let dir = tempfile::tempdir().unwrap();
    let series = fixture("nibabel_4d.nii.gz");
    let text = ok(&[&"info", &series]);
    assert!(
        text.contains("frames:     3 (0 to 2); this is frame 0"),
        "{text}"
    );
    let j = info_json(&series, &["--frame", "2"]);
    assert_eq!(j["frames"], 3);
    assert_eq!(j["frame"], 2);
    // Frame t holds 1000 t + i + 10 j + 100 k.
    assert_eq!(j["stats"]["min"], 2000.0);
    let e = fails(&[&"convert", &series, &dir.path().join("x.nii")]);
    assert!(e.contains("3 frames") && e.contains("--frame"), "{e}");
    let e = fails(&[&"info", &series, &"--frame", &"3"]);
    assert!(e.contains("frame 3 does not exist"), "{e}");
    let one = dir.path().join("f1.nii.gz");
    ok(&[&"convert", &series, &one, &"--frame", &"1"]);
    let f = info_json(&one, &[]);
    assert_eq!(f["frames"], 1);
    assert_eq!(f["stats"]["min"], 1000.0);
}

#[test]
fn dicom_folder_converts_to_nifti_in_hounsfield_units() {
    let dir = tempfile::tempdir().unwrap();
    let series = fixture("sitk_ct_series");
    let j = info_json(&series, &[]);
    assert_eq!(j["format"], "DICOM");
    // Signed 16-bit stored values shifted by −1024 need 32 bits, as SimpleITK (GDCM) also
    // reads this series ("32-bit signed integer").
    assert_eq!(j["voxel_type"], "i32");
    assert_eq!(j["dims"], serde_json::json!([8, 6, 5]));
    assert_eq!(j["stats"]["min"], -1024.0);
    let out = dir.path().join("ct.nii.gz");
    ok(&[&"convert", &series, &out]);
    let n = info_json(&out, &[]);
    assert_eq!(n["stats"], j["stats"]);
    let (a, b) = (vec3(&j["origin"]), vec3(&n["origin"]));
    assert!((0..3).all(|i| (a[i] - b[i]).abs() < 1e-4), "{a:?} {b:?}");
    // DICOM is read, not written: refused by extension before the input is read.
    let e = fails(&[&"convert", &out, &dir.path().join("ct.dcm")]);
    assert!(
        e.contains("extension .dcm is not written here") && e.contains(".nii.gz"),
        "{e}"
    );
}

fn as_args(v: &[std::ffi::OsString]) -> Vec<&dyn AsRef<std::ffi::OsStr>> {
    v.iter().map(|a| a as &dyn AsRef<std::ffi::OsStr>).collect()
}

/// The global `--frame N` reaches every command that reads a volume through the one read path
/// (`volmorph_volume_io::read`): each command run on frame 1 of a 4-D series writes exactly what
/// it writes from that frame saved alone as a 3-D file, and refuses the series without `--frame`,
/// naming it. A 3-D input beside it (the map of `warp`, the grid of `jacobian`) is read as it is.
#[test]
fn every_volume_command_reads_the_global_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let series = fixture("nibabel_4d.nii.gz");
    // Frame 1 written by nibabel with the series' header bytes.
    let one = fixture("nibabel_4d_frame1.nii.gz");
    let c = centre(&info_json(&one, &[]));
    let (from, to) = (
        format!("{},{},{}", c[0], c[1], c[2]),
        format!("{},{},{}", c[0] + 0.3, c[1], c[2]),
    );
    let lattice = d.join("l.json");
    ok(&[
        &"lattice",
        &"init",
        &one,
        &"--counts",
        &"4,4,4",
        &"-o",
        &lattice,
    ]);
    let lat = lattice.to_str().unwrap();
    // (command arguments before the input, after the input, output extension)
    let commands: Vec<(&[&str], Vec<&str>, &str)> = vec![
        (&["slice"], vec!["--axis", "z"], "png"),
        (&["isosurface"], vec!["--level", "1050"], "ply"),
        (&["lattice", "init"], vec!["--counts", "4,4,4"], "json"),
        (
            &["warp"],
            vec!["--map", lat, "--method", "pullback-linear"],
            "nii",
        ),
        (&["drag"], vec!["--from", &from, "--to", &to], "nii"),
        (&["render"], vec!["--size", "32x32"], "png"),
        (
            &["nurbs", "fit"],
            vec!["--order", "2", "--control-points", "2"],
            "json",
        ),
    ];
    for (i, (cmd, rest, ext)) in commands.iter().enumerate() {
        let run = |input: &Path, frame: &[&str], out: &Path| {
            let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = Vec::new();
            for a in *cmd {
                args.push(a);
            }
            args.push(&input);
            for a in rest {
                args.push(a);
            }
            args.extend([&"-o" as &dyn AsRef<std::ffi::OsStr>, &out]);
            for a in frame {
                args.push(a);
            }
            args.iter()
                .map(|a| a.as_ref().to_owned())
                .collect::<Vec<_>>()
        };
        let (want, got) = (
            d.join(format!("want{i}.{ext}")),
            d.join(format!("got{i}.{ext}")),
        );
        let a = run(&one, &[], &want);
        ok(&as_args(&a));
        let b = run(&series, &["--frame", "1"], &got);
        ok(&as_args(&b));
        let (w, g) = (std::fs::read(&want).unwrap(), std::fs::read(&got).unwrap());
        assert!(
            w == g,
            "{cmd:?}: frame 1 of the series differs from the 3-D frame"
        );
        let e = fails(&as_args(&run(&series, &[], &got)));
        assert!(
            e.contains("3 frames") && e.contains("--frame"),
            "{cmd:?}: {e}"
        );
    }
    // The grid of `jacobian` is 3-D; the global frame leaves it alone.
    let j = d.join("j.nii");
    ok(&[
        &"jacobian",
        &"--map",
        &lattice,
        &"--grid",
        &one,
        &"-o",
        &j,
        &"--frame",
        &"1",
    ]);
}
