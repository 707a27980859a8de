//! Issue 15 item 2: outputs with the wrong extension were written silently (`slice -o x.jpg`
//! and `.tif` wrote PNG data, `nurbs fit -o x.ply` wrote JSON). Every command now checks its
//! output paths against the extensions its writer writes before it reads any input or does
//! any work: a typo fails at once, naming the file, the extension found and the ones
//! accepted, with exit status 1, and nothing is created.
//!
//! The order is part of the contract: the inputs below do not exist, so a command that read
//! them first would fail about the missing input instead of the extension.

use std::path::Path;

use crate::common::volmorph;

/// One command with a wrong output extension: its arguments (`{d}` is the temporary folder),
/// the bad output's file name, and what the message must list as accepted.
struct Case {
    args: &'static str,
    output: &'static str,
    accepted: &'static [&'static str],
}

const VOLUMES: &[&str] = &[".nii", ".nii.gz", ".mha", ".nrrd", ".vti"];
const MESHES: &[&str] = &[".obj", ".stl", ".ply", ".off"];

const CASES: &[Case] = &[
    Case {
        args: "slice {d}/missing.nii -o {d}/x.jpg",
        output: "x.jpg",
        accepted: &["use .png"],
    },
    Case {
        args: "slice {d}/missing.nii -o {d}/x.tif",
        output: "x.tif",
        accepted: &["use .png"],
    },
    Case {
        args: "slice {d}/missing.nii -o {d}/noext",
        output: "noext",
        accepted: &["no extension; use .png"],
    },
    Case {
        args: "nurbs fit {d}/missing.nii -o {d}/x.ply",
        output: "x.ply",
        accepted: &["use .json"],
    },
    Case {
        args: "nurbs model {d}/missing.json -o {d}/x.ply",
        output: "x.ply",
        accepted: &["use .json"],
    },
    Case {
        args: "nurbs example grin-lens -o {d}/x.yaml",
        output: "x.yaml",
        accepted: &["use .json"],
    },
    Case {
        args: "nurbs slice {d}/missing.json --plane 0,0,1,0 -o {d}/x.stl",
        output: "x.stl",
        accepted: &["use .ply or .obj"],
    },
    Case {
        args: "nurbs isosurface {d}/missing.json --attribute a --level 0 -o {d}/x.off",
        output: "x.off",
        accepted: &["use .ply or .obj"],
    },
    Case {
        args: "nurbs render {d}/missing.json --attribute a -o {d}/x.jpg",
        output: "x.jpg",
        accepted: &["use .png"],
    },
    Case {
        args: "nurbs trace-optics --example grin-lens -o {d}/x.png --paths {d}/p.ply",
        output: "p.ply",
        accepted: &["use .obj"],
    },
    Case {
        args: "frep render {d}/missing.hf -o {d}/x.jpg",
        output: "x.jpg",
        accepted: &["use .png"],
    },
    Case {
        args: "frep eval {d}/missing.hf -o {d}/x.png",
        output: "x.png",
        accepted: VOLUMES,
    },
    Case {
        args: "frep mesh {d}/missing.hf -o {d}/x.nii",
        output: "x.nii",
        accepted: MESHES,
    },
    Case {
        args: "frep morph {d}/a.hf {d}/b.hf --frames 3 -o {d}/x.mp4",
        output: "x.mp4",
        accepted: &[".png, .apng or .gif"],
    },
    Case {
        args: "frep map {d}/missing.hf --mapping {d}/missing.json -o {d}/x.jpg",
        output: "x.jpg",
        accepted: &[".obj", ".png", ".nii.gz"],
    },
    Case {
        args: "frep points {d}/missing.xyz -o {d}/x.dae",
        output: "x.dae",
        accepted: &[".obj", ".png", ".nii.gz"],
    },
    Case {
        args: "frep sections --example femur -o {d}/x.jpg",
        output: "x.jpg",
        accepted: VOLUMES,
    },
    Case {
        args: "ffd {d}/missing.obj --init uniform --mode accurate -o {d}/x.txt",
        output: "x.txt",
        accepted: &[".obj", ".stl", ".ply", ".off", ".step or .stp"],
    },
    Case {
        args: "ffd {d}/missing.obj --init uniform -o {d}/y.obj --report {d}/r.txt",
        output: "r.txt",
        accepted: &["use .json"],
    },
    Case {
        args: "lattice init {d}/missing.nii --counts 4,4,4 -o {d}/x.yaml",
        output: "x.yaml",
        accepted: &[".json, .tfm, .txt or .bxf"],
    },
    Case {
        args: "lattice convert {d}/missing.json -o {d}/x.csv",
        output: "x.csv",
        accepted: &[".json, .tfm, .txt or .bxf"],
    },
    Case {
        args: "project new {d}/missing.nii -o {d}/x.json",
        output: "x.json",
        accepted: &["use .vmproj"],
    },
    Case {
        args: "project export {d}/missing.vmproj 1 -o {d}/x.jpg",
        output: "x.jpg",
        accepted: &[".nii.gz", ".ply", ".json", ".step", ".hf"],
    },
    Case {
        args: "phantom sphere --size 8 -o {d}/x.png",
        output: "x.png",
        accepted: VOLUMES,
    },
    Case {
        args: "phantom sphere --size 8 -o {d}/x.dcm",
        output: "x.dcm",
        accepted: VOLUMES,
    },
    Case {
        args: "convert {d}/missing.nii {d}/x.png",
        output: "x.png",
        accepted: VOLUMES,
    },
    Case {
        args: "isosurface {d}/missing.nii --level 1 -o {d}/x.vtk",
        output: "x.vtk",
        accepted: MESHES,
    },
    Case {
        args: "isosurface {d}/missing.nii --level 1 -o {d}/x.ply.gz",
        output: "x.ply.gz",
        accepted: MESHES,
    },
    Case {
        args: "warp {d}/missing.nii --map {d}/missing.json -o {d}/x.png",
        output: "x.png",
        accepted: VOLUMES,
    },
    Case {
        args: "warp {d}/missing.nii --map {d}/missing.json -o {d}/y.nii --method inverse-linear --nonconverged-mask {d}/m.txt",
        output: "m.txt",
        accepted: VOLUMES,
    },
    Case {
        args: "jacobian --map {d}/missing.json --grid {d}/missing.nii -o {d}/x.json",
        output: "x.json",
        accepted: VOLUMES,
    },
    Case {
        args: "jacobian --map {d}/missing.json --grid {d}/missing.nii -o {d}/j.nii --map-out {d}/x.yaml",
        output: "x.yaml",
        accepted: &[".json", ".tfm", ".bxf", ".mat"],
    },
    Case {
        args: "drag {d}/missing.nii --from 0,0,0 --to 1,1,1 -o {d}/x.png",
        output: "x.png",
        accepted: VOLUMES,
    },
    Case {
        args: "drag {d}/missing.nii --from 0,0,0 --to 1,1,1 -o {d}/y.nii --lattice-out {d}/x.yaml",
        output: "x.yaml",
        accepted: &[".json, .tfm, .txt or .bxf"],
    },
    Case {
        args: "mesh convert {d}/missing.obj {d}/x.dae",
        output: "x.dae",
        accepted: MESHES,
    },
    Case {
        args: "mesh render {d}/missing.obj -o {d}/x.jpg",
        output: "x.jpg",
        accepted: &["use .png"],
    },
    Case {
        args: "map compose {d}/missing.json {d}/missing.tfm -o {d}/x.yaml",
        output: "x.yaml",
        accepted: &[".json", ".tfm", ".bxf", ".mat", ".nii.gz"],
    },
    Case {
        args: "map invert {d}/missing.json -o {d}/x.yaml",
        output: "x.yaml",
        accepted: &[".json", ".tfm"],
    },
    Case {
        args: "map field {d}/missing.json --reference {d}/missing.nii -o {d}/x.nrrd",
        output: "x.nrrd",
        accepted: &[".nii, .nii.gz, .mha or .mhd"],
    },
    Case {
        args: "map apply {d}/missing.json {d}/missing.txt -o {d}/x.json",
        output: "x.json",
        accepted: &[".fcsv", ".csv", ".txt"],
    },
    Case {
        args: "handles warp {d}/missing.nii --handles {d}/missing.json -o {d}/x.obj",
        output: "x.obj",
        accepted: VOLUMES,
    },
    Case {
        args: "handles warp {d}/missing.obj --handles {d}/missing.json -o {d}/x.nii",
        output: "x.nii",
        accepted: MESHES,
    },
    Case {
        args: "handles apply {d}/missing.txt --handles {d}/missing.json -o {d}/x.json",
        output: "x.json",
        accepted: &[".fcsv", ".csv", ".txt"],
    },
    Case {
        args: "mls2d {d}/missing.png --handles {d}/missing.json -o {d}/x.jpg",
        output: "x.jpg",
        accepted: &["use .png"],
    },
    Case {
        args: "render {d}/missing.nii -o {d}/x.jpg",
        output: "x.jpg",
        accepted: &["use .png"],
    },
    Case {
        args: "render {d}/missing.nii --frames 4 -o {d}/x.mp4",
        output: "x.mp4",
        accepted: &[".png, .apng or .gif"],
    },
    Case {
        args: "render {d}/missing.nii -o {d}/y.png --save-transfer {d}/t.txt",
        output: "t.txt",
        accepted: &["use .json"],
    },
    Case {
        args: "sculpt {d}/missing.obj --tool {d}/missing.obj --op add -o {d}/x.vtk",
        output: "x.vtk",
        accepted: MESHES,
    },
    Case {
        args: "register select {d}/missing.nii -o {d}/x.json",
        output: "x.json",
        accepted: &[".txt, .xyz or .pts"],
    },
    Case {
        args: "register match {d}/missing.nii {d}/missing.nii --handles {d}/missing.txt -o {d}/x.txt",
        output: "x.txt",
        accepted: &["use .json"],
    },
    Case {
        args: "register segment-lungs {d}/missing.nii -o {d}/x.png",
        output: "x.png",
        accepted: VOLUMES,
    },
];

/// Issue 15 item 2, for every command that writes a file: exit status 1, a message naming
/// the file, the extension found (or none) and the accepted ones, no mention of the missing
/// inputs (the output is checked first), and nothing written.
#[test]
fn outputs_with_the_wrong_extension_are_written_silently() {
    for case in CASES {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().display().to_string();
        let args: Vec<String> = case.args.split(' ').map(|a| a.replace("{d}", &d)).collect();
        let refs: Vec<&dyn AsRef<std::ffi::OsStr>> = args.iter().map(|a| a as _).collect();
        let out = volmorph(&refs);
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        let what = format!("volmorph {}: {err}", case.args);
        assert_eq!(out.status.code(), Some(1), "{what}");
        assert!(!err.contains("panicked"), "{what}");
        let named = Path::new(&d).join(case.output).display().to_string();
        assert!(err.contains(&named), "the message names the file: {what}");
        let found = match Path::new(case.output).extension() {
            None => "no extension".to_string(),
            Some(_) if case.output.ends_with(".ply.gz") => "extension .ply.gz".into(),
            Some(e) => format!("extension .{}", e.to_string_lossy()),
        };
        assert!(err.contains(&found), "the message says {found}: {what}");
        for accepted in case.accepted {
            assert!(
                err.contains(accepted),
                "the message lists {accepted}: {what}"
            );
        }
        assert!(
            !err.contains("missing."),
            "the output is checked before the inputs are read: {what}"
        );
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert!(
            left.is_empty(),
            "nothing is written, found {left:?}: {what}"
        );
    }
}

/// The check takes an extension in any case, and a right extension gets past it: the same
/// commands then fail on the missing input instead, still writing nothing.
#[test]
fn right_extensions_in_any_case_pass_the_check() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (args, output) in [
        (vec!["slice", "missing.nii", "-o"], "x.PNG"),
        (vec!["nurbs", "fit", "missing.nii", "-o"], "x.Json"),
        (vec!["convert", "missing.nii"], "x.NII.GZ"),
        (
            vec!["isosurface", "missing.nii", "--level", "1", "-o"],
            "x.Ply",
        ),
        (vec!["project", "new", "missing.nii", "-o"], "x.VMPROJ"),
    ] {
        let mut all: Vec<String> = args
            .iter()
            .map(|a| {
                if a.starts_with("missing") {
                    d.join(a).display().to_string()
                } else {
                    (*a).to_string()
                }
            })
            .collect();
        all.push(d.join(output).display().to_string());
        let refs: Vec<&dyn AsRef<std::ffi::OsStr>> = all.iter().map(|a| a as _).collect();
        let out = volmorph(&refs);
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert_eq!(out.status.code(), Some(1), "{all:?}: {err}");
        assert!(err.contains("missing.nii"), "{all:?}: {err}");
        assert!(!err.contains("not written here"), "{all:?}: {err}");
        assert!(!d.join(output).exists(), "{all:?}");
    }
}
