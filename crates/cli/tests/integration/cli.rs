//! End-to-end tests of the `volmorph` binary: commands chain, errors name the file and exit
//! with status 1 (never a panic), and failed writes leave no file behind.

use crate::common;

use std::path::{Path, PathBuf};

use common::{fails, ok, volmorph};

fn info_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&ok(&[&"info", &"--json", &path])).expect("info --json prints JSON")
}

fn raw_bytes(dir: &Path, path: &Path) -> Vec<u8> {
    let raw: PathBuf = dir.join(format!(
        "{}.raw",
        path.file_name().unwrap().to_string_lossy()
    ));
    ok(&[&"convert", &path, &raw]);
    std::fs::read(raw).unwrap()
}

#[test]
fn phantom_then_info_reports_geometry_and_statistics() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("sphere.nii.gz");
    ok(&[&"phantom", &"sphere", &"-o", &p, &"--dims", &"20,16,12"]);
    let j = info_json(&p);
    assert_eq!(j["format"], "NIfTI-1");
    assert_eq!(j["voxel_type"], "u8");
    assert_eq!(j["dims"], serde_json::json!([20, 16, 12]));
    let origin: Vec<f64> = serde_json::from_value(j["origin"].clone()).unwrap();
    assert!(origin.iter().all(|o| (o + 1.1).abs() < 1e-6), "{origin:?}");
    assert_eq!(j["stats"]["max"], 255.0);
    assert_eq!(j["stats"]["min"], 0.0);
    let text = ok(&[&"info", &p, &"--header"]);
    assert!(text.contains("dims:       20 x 16 x 12"), "{text}");
    assert!(text.contains("sform_code"), "{text}");
}

/// Every file under `dir` (recursively) whose name does not start with a dot: the chunk
/// files of a Zarr v2 array.
fn chunk_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(chunk_files(&p));
        } else if !p.file_name().unwrap().to_string_lossy().starts_with('.') {
            out.push(p);
        }
    }
    out
}

#[test]
fn info_no_stats_reads_only_the_metadata_of_an_ome_zarr_store() {
    let dir = tempfile::tempdir().unwrap();
    let mha = dir.path().join("s.mha");
    ok(&[&"phantom", &"sphere", &"-o", &mha, &"--dims", &"20,16,12"]);
    let z = dir.path().join("s.ome.zarr");
    ok(&[&"convert", &mha, &z, &"--chunk", &"8,8,8"]);
    let full = info_json(&z);
    assert!(full["stats"].is_object(), "{full}");
    let meta: serde_json::Value =
        serde_json::from_str(&ok(&[&"info", &"--json", &"--no-stats", &z])).unwrap();
    assert!(meta.get("stats").is_none(), "{meta}");
    for k in [
        "format",
        "voxel_type",
        "dims",
        "spacing",
        "origin",
        "direction",
        "header",
    ] {
        assert_eq!(meta[k], full[k], "{k}");
    }
    // Corrupt every chunk of level 0: the statistics cannot be computed any more, the
    // metadata still can, so --no-stats opened no chunk.
    let chunks = chunk_files(&z.join("0"));
    assert!(
        !chunks.is_empty() && chunks.len() <= 3 * 2 * 2,
        "{chunks:?}"
    );
    for c in &chunks {
        std::fs::write(c, b"not a compressed chunk").unwrap();
    }
    let err = fails(&[&"info", &z]);
    assert!(err.contains("s.ome.zarr"), "{err}");
    let again: serde_json::Value =
        serde_json::from_str(&ok(&[&"info", &"--json", &"--no-stats", &z])).unwrap();
    assert_eq!(again, meta);
}

/// `info --no-stats` of a declared store larger than the memory budget was refused: opening
/// the metadata checked the whole grid against the budget, although nothing is read.
#[test]
fn info_no_stats_opens_a_store_larger_than_the_memory_budget() {
    let dir = tempfile::tempdir().unwrap();
    let mha = dir.path().join("s.mha");
    ok(&[&"phantom", &"sphere", &"-o", &mha, &"--dims", &"20,16,12"]);
    let z = dir.path().join("s.ome.zarr");
    ok(&[
        &"convert",
        &mha,
        &z,
        &"--chunk",
        &"8,8,8",
        &"--levels",
        &"1",
    ]);
    // Declare level 0 as 4096³ u8 (64 GiB), four times a 16 GiB budget; no chunk is added.
    let zarray = z.join("0").join(".zarray");
    let mut meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&zarray).unwrap()).unwrap();
    assert_eq!(meta["shape"], serde_json::json!([12, 16, 20]), "{meta}");
    meta["shape"] = serde_json::json!([4096, 4096, 4096]);
    std::fs::write(&zarray, meta.to_string()).unwrap();
    let info: serde_json::Value = serde_json::from_str(&ok(&[
        &"--memory-limit",
        &"16G",
        &"info",
        &"--json",
        &"--no-stats",
        &z,
    ]))
    .unwrap();
    assert_eq!(
        info["dims"],
        serde_json::json!([4096, 4096, 4096]),
        "{info}"
    );
    // Reading it whole is still refused before allocating, naming the store.
    let err = fails(&[&"--memory-limit", &"16G", &"info", &z]);
    assert!(
        err.contains("s.ome.zarr") && err.contains("memory"),
        "{err}"
    );
}

#[test]
fn convert_chain_through_every_format_keeps_voxels_and_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = d.join("torus.nii");
    ok(&[
        &"phantom", &"torus", &"-o", &src, &"--kind", &"sdf", &"--size", &"17",
    ]);
    let want = raw_bytes(d, &src);
    let want_geo = info_json(&src);
    let mut prev = src.clone();
    for (name, extra) in [
        ("a.mha", None),
        ("b.mhd", Some("--compress")),
        ("c.nrrd", Some("--compress")),
        ("d.nhdr", None),
        ("e.vtk", None),
        ("f.nii.gz", None),
    ] {
        let next = d.join(name);
        match extra {
            Some(x) => ok(&[&"convert", &prev, &next, &x]),
            None => ok(&[&"convert", &prev, &next]),
        };
        assert_eq!(raw_bytes(d, &next), want, "voxels changed in {name}");
        let geo = info_json(&next);
        for key in ["dims", "spacing", "origin", "direction", "voxel_type"] {
            assert_eq!(geo[key], want_geo[key], "{key} changed in {name}");
        }
        prev = next;
    }
}

#[test]
fn convert_casts_and_rescales() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("box.mha");
    let dst = dir.path().join("box_i16.nrrd");
    ok(&[
        &"phantom",
        &"rounded-box",
        &"-o",
        &src,
        &"--kind",
        &"sdf",
        &"--size",
        &"12",
    ]);
    ok(&[
        &"convert",
        &src,
        &dst,
        &"--type",
        &"i16",
        &"--rescale",
        &"--range",
        &"-1000,1000",
    ]);
    let j = info_json(&dst);
    assert_eq!(j["voxel_type"], "i16");
    assert_eq!(j["stats"]["min"], -1000.0);
    assert_eq!(j["stats"]["max"], 1000.0);
}

#[test]
fn slice_writes_a_png_of_the_expected_size() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("teapot.nii");
    let png = dir.path().join("cut.png");
    ok(&[&"phantom", &"teapot", &"-o", &src, &"--dims", &"24,20,10"]);
    ok(&[
        &"slice",
        &src,
        &"-o",
        &png,
        &"--axis",
        &"y",
        &"--index",
        &"9.5",
        &"--zoom",
        &"1",
        &"--voxel-aspect",
    ]);
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert_eq!((w, h), (24, 10), "a Y slice is nx wide and nz high");
    // By default the longer side is enlarged to 512 pixels.
    ok(&[&"slice", &src, &"-o", &png, &"--axis", &"y"]);
    let bytes = std::fs::read(&png).unwrap();
    let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert_eq!(w.max(h), 512);
    ok(&[
        &"slice",
        &src,
        &"-o",
        &png,
        &"--position",
        &"0",
        &"--scale",
        &"3",
    ]);
    let bytes = std::fs::read(&png).unwrap();
    let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    assert_eq!(w, 72);
}

#[test]
fn errors_name_the_file_and_exit_1() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.nii");
    let err = fails(&[&"info", &missing]);
    assert_eq!(
        err.matches("nope.nii").count(),
        1,
        "the file is named once: {err}"
    );
    let err = fails(&[&"convert", &missing, &dir.path().join("no").join("out.mha")]);
    assert_eq!(err.matches("nope.nii").count(), 1, "{err}");
    let out_of_reach = dir.path().join("no").join("out.mha");
    let src = dir.path().join("s.mha");
    ok(&[&"phantom", &"sphere", &"-o", &src, &"--size", &"4"]);
    let err = fails(&[&"convert", &src, &out_of_reach]);
    assert!(
        err.contains("does not exist") && !err.contains(".partial"),
        "{err}"
    );

    let corrupt = dir.path().join("corrupt.nii.gz");
    std::fs::write(&corrupt, b"\x1f\x8b\x08\x00garbage").unwrap();
    let err = fails(&[&"info", &corrupt]);
    assert!(err.contains("corrupt.nii.gz"), "{err}");

    let short = dir.path().join("short.mha");
    std::fs::write(
        &short,
        b"ObjectType = Image\nNDims = 3\nDimSize = 100000 100000 100000\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n",
    )
    .unwrap();
    fails(&[&"info", &short]);

    let unknown = dir.path().join("x.png");
    std::fs::write(&unknown, b"not a volume").unwrap();
    let err = fails(&[&"info", &unknown]);
    assert!(err.contains("x.png"), "{err}");

    fails(&[
        &"phantom",
        &"dodecahedron",
        &"-o",
        &dir.path().join("d.nii"),
    ]);
    fails(&[
        &"convert",
        &corrupt,
        &dir.path().join("out.nii"),
        &"--type",
        &"u7",
    ]);
}

#[test]
fn a_failed_write_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("oblique.nrrd");
    // A NRRD with an oblique direction: VTK legacy cannot store it, so writing must fail.
    let data = vec![7u8; 8];
    let mut file = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspace: left-posterior-superior\nspace directions: (0.6,0.8,0) (-0.8,0.6,0) (0,0,1)\nspace origin: (0,0,0)\nencoding: raw\n\n".to_vec();
    file.extend_from_slice(&data);
    std::fs::write(&src, file).unwrap();
    let out = dir.path().join("out.vtk");
    let err = fails(&[&"convert", &src, &out]);
    assert!(err.contains("out.vtk"), "{err}");
    assert!(!out.exists());
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers.len(), 1, "temporary files left: {leftovers:?}");
}

#[test]
fn mesh_info_and_convert() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("cube.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
         f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n",
    )
    .unwrap();
    let text = ok(&[&"mesh", &"info", &obj]);
    assert!(text.contains("vertices: 8"), "{text}");
    assert!(text.contains("faces:    6"), "{text}");
    for ext in ["ply", "off", "stl", "obj"] {
        let out = dir.path().join(format!("cube2.{ext}"));
        ok(&[&"mesh", &"convert", &obj, &out]);
        let text = ok(&[&"mesh", &"info", &out]);
        let faces = if ext == "stl" { 12 } else { 6 };
        assert!(text.contains("vertices: 8"), "{ext}: {text}");
        assert!(
            text.contains(&format!("faces:    {faces}")),
            "{ext}: {text}"
        );
    }
    let bad = dir.path().join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nf 1 2 3\n").unwrap();
    let err = fails(&[&"mesh", &"info", &bad]);
    assert!(err.contains("bad.obj"), "{err}");
}

#[test]
fn demo_warps_the_teapot_and_writes_every_model() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let text = ok(&[
        &"demo",
        &"--out",
        &out,
        &"--size",
        &"32",
        &"--gallery-size",
        &"16",
        &"--picture",
        &"80x60",
    ]);
    // The spout lands on its target, the incremental warp equals the full one, undo
    // restores the original, and the timings are printed.
    assert!(text.contains("lands"), "{text}");
    let diff = |key: &str| -> f64 {
        let line = text.lines().find(|l| l.contains(key)).expect(key);
        line.split("max |difference| ")
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .expect(line)
    };
    // The warped teapot keeps the input's u8 type, so incremental and full agree exactly.
    assert_eq!(diff("incremental result vs full"), 0.0, "{text}");
    assert_eq!(diff("undo restores"), 0.0, "{text}");
    assert_eq!(diff("redo equals the full"), 0.0, "{text}");
    assert!(text.contains("timings"), "{text}");
    for f in [
        "teapot.nii.gz",
        "teapot_warped.nii.gz",
        "teapot_jacobian.nii.gz",
        "lattice_after.json",
        "lattice_after.tfm",
        "teapot_before.ply",
        "teapot_after.ply",
        "teapot_before_side.png",
        "teapot_after_side.png",
        "teapot_after_iso.png",
        "teapot.vmproj",
        "index.txt",
    ] {
        assert!(out.join(f).exists(), "missing {f}");
    }
    let info = ok(&[&"mesh", &"info", &out.join("teapot_after.ply")]);
    assert!(info.contains("closed oriented manifold"), "{info}");
    for name in ["sphere", "torus", "rounded-box", "clay-block", "teapot"] {
        for f in [
            format!("{name}.nii.gz"),
            format!("{name}_sdf.nii.gz"),
            format!("{name}_z.png"),
            format!("{name}_sdf_x.png"),
        ] {
            assert!(out.join("models").join(&f).exists(), "missing models/{f}");
        }
    }
}

#[test]
fn isosurface_of_a_phantom_is_a_closed_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("torus.nii.gz");
    let sdf = dir.path().join("torus_sdf.mha");
    ok(&[&"phantom", &"torus", &"-o", &src, &"--size", &"40"]);
    ok(&[
        &"phantom", &"torus", &"-o", &sdf, &"--size", &"40", &"--kind", &"sdf",
    ]);
    for (input, extra) in [(&src, None), (&sdf, Some("--inside-below"))] {
        let out = dir.path().join("torus.ply");
        let level = if extra.is_some() { "0" } else { "127" };
        let text = match extra {
            Some(x) => ok(&[&"isosurface", input, &"--level", &level, &"-o", &out, &x]),
            None => ok(&[&"isosurface", input, &"--level", &level, &"-o", &out]),
        };
        assert!(
            text.contains("closed manifold, Euler characteristic 0"),
            "{text}"
        );
        let info = ok(&[&"mesh", &"info", &out]);
        assert!(info.contains("closed oriented manifold"), "{info}");
    }
    fails(&[
        &"isosurface",
        &src,
        &"--level",
        &"nan",
        &"-o",
        &dir.path().join("x.ply"),
    ]);
}

#[test]
fn lattice_init_writes_an_identity_lattice() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("box.mha");
    let out = dir.path().join("l.json");
    ok(&[
        &"phantom",
        &"rounded-box",
        &"-o",
        &src,
        &"--dims",
        &"20,16,12",
    ]);
    let text = ok(&[
        &"lattice",
        &"init",
        &src,
        &"--counts",
        &"6,5,4",
        &"-o",
        &out,
    ]);
    assert!(text.contains("6x5x4"), "{text}");
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(j["kind"], "bspline-lattice");
    assert_eq!(j["counts"], serde_json::json!([6, 5, 4]));
    fails(&[
        &"lattice",
        &"init",
        &src,
        &"--counts",
        &"3,5,4",
        &"-o",
        &out,
    ]);
    fails(&[&"lattice", &"init", &src, &"-o", &dir.path().join("l.xml")]);

    // An edited JSON lattice through ITK's .tfm and back keeps its control points.
    let mut j = j;
    j["control_points"][37] = serde_json::json!([0.25, -0.5, 0.125]);
    let edited = dir.path().join("edited.json");
    std::fs::write(&edited, j.to_string()).unwrap();
    let tfm = dir.path().join("edited.tfm");
    let text = ok(&[&"lattice", &"convert", &edited, &"-o", &tfm]);
    assert!(text.contains("6x5x4"), "{text}");
    let back = dir.path().join("back.json");
    ok(&[&"lattice", &"convert", &tfm, &"-o", &back]);
    let b: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&back).unwrap()).unwrap();
    let flat = |v: &serde_json::Value| -> Vec<f64> {
        v["control_points"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|p| p.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
            .collect()
    };
    let (a, b) = (flat(&j), flat(&b));
    assert_eq!(a.len(), 6 * 5 * 4 * 3);
    assert!(
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-9),
        "{a:?} vs {b:?}"
    );
    let err = fails(&[
        &"lattice",
        &"convert",
        &dir.path().join("missing.json"),
        &"-o",
        &tfm,
    ]);
    assert!(err.contains("missing.json"), "{err}");
}

/// Write the identity lattice of 5×5×5 control points around volume `src` to `lat`.
fn write_identity_lattice(src: &Path, lat: &Path) {
    ok(&[
        &"lattice",
        &"init",
        &src,
        &"--counts",
        &"5,5,5",
        &"-o",
        &lat,
    ]);
}

/// The teapot phantom at `size`³ as `dir/teapot.mha` and its identity lattice `dir/l.json`.
fn teapot_and_identity_lattice(dir: &Path, size: &str) -> (PathBuf, PathBuf) {
    let (src, lat) = (dir.join("teapot.mha"), dir.join("l.json"));
    ok(&[&"phantom", &"teapot", &"-o", &src, &"--size", &size]);
    write_identity_lattice(&src, &lat);
    (src, lat)
}

#[test]
fn warp_and_jacobian_through_a_lattice() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (src, lat) = teapot_and_identity_lattice(d, "24");
    // The identity lattice leaves the volume unchanged.
    for method in [
        "pullback-nearest",
        "pullback-linear",
        "pushforward-nearest",
        "pushforward-antialiased",
        "inverse-nearest",
        "inverse-linear",
    ] {
        let out = d.join(format!("{method}.mha"));
        ok(&[
            &"warp",
            &src,
            &"--lattice",
            &lat,
            &"-o",
            &out,
            &"--method",
            &method,
        ]);
        assert_eq!(raw_bytes(d, &out), raw_bytes(d, &src), "{method}");
    }
    let jac = d.join("j.nii");
    let text = ok(&[
        &"jacobian",
        &"--lattice",
        &lat,
        &"--grid",
        &src,
        &"-o",
        &jac,
    ]);
    assert!(
        text.contains("0 of 13824 voxels fold"),
        "no folding expected: {text}"
    );
    let j = info_json(&jac);
    assert!(
        (j["stats"]["min"].as_f64().unwrap() - 1.0).abs() < 1e-5,
        "{j}"
    );
    assert!(
        (j["stats"]["max"].as_f64().unwrap() - 1.0).abs() < 1e-5,
        "{j}"
    );
    // A moved control point changes the warp.
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&lat).unwrap()).unwrap();
    let pts = doc["control_points"]
        .as_array_mut()
        .expect("control_points array");
    let centre = &mut pts[2 + 5 * (2 + 5 * 2)];
    let x = centre[0].as_f64().unwrap();
    centre[0] = serde_json::json!(x + 0.3);
    std::fs::write(&lat, doc.to_string()).unwrap();
    let out = d.join("moved.mha");
    ok(&[&"warp", &src, &"--lattice", &lat, &"-o", &out]);
    assert_ne!(raw_bytes(d, &out), raw_bytes(d, &src));
    fails(&[
        &"warp",
        &src,
        &"--lattice",
        &d.join("missing.json"),
        &"-o",
        &out,
    ]);
}

#[test]
fn mesh_render_draws_the_model_in_the_middle() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("sphere.nii.gz");
    let mesh = dir.path().join("sphere.obj");
    let png = dir.path().join("sphere.png");
    ok(&[&"phantom", &"sphere", &"-o", &vol, &"--size", &"24"]);
    ok(&[&"isosurface", &vol, &"--level", &"127", &"-o", &mesh]);
    ok(&[
        &"mesh", &"render", &mesh, &"-o", &png, &"--size", &"64x48", &"--view", &"top",
    ]);
    let img = volmorph_render::read_png(&png).unwrap();
    assert_eq!((img.width(), img.height()), (64, 48));
    let white = [255, 255, 255, 255];
    assert_ne!(img.get(32, 24), Some(white), "centre not drawn");
    assert_eq!(img.get(0, 0), Some(white), "corner drawn");
    // A malformed size is a usage error (clap's exit status 2), not a crash.
    let bad = volmorph(&[&"mesh", &"render", &mesh, &"-o", &png, &"--size", &"64x"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("WIDTHxHEIGHT"));
    // Any direction about either up axis; a bad view names the view names.
    ok(&[
        &"mesh", &"render", &mesh, &"-o", &png, &"--size", &"40", &"--view", &"30,-20", &"--up",
        &"y",
    ]);
    let img = volmorph_render::read_png(&png).unwrap();
    assert_eq!((img.width(), img.height()), (40, 40));
    assert_ne!(img.get(20, 20), Some(white), "centre not drawn");
    let bad = volmorph(&[&"mesh", &"render", &mesh, &"-o", &png, &"--view", &"30"]);
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("iso"));
}

#[test]
fn inverse_warp_reports_and_masks_voxels_without_a_preimage() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (src, lat) = teapot_and_identity_lattice(d, "20");
    // Every control point moved +3 along x: the box is translated, so its first 3 units
    // along x have no preimage (outside the box the map is the identity).
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&lat).unwrap()).unwrap();
    for p in doc["control_points"].as_array_mut().unwrap() {
        let x = p[0].as_f64().unwrap();
        p[0] = serde_json::json!(x + 3.0);
    }
    std::fs::write(&lat, doc.to_string()).unwrap();
    let out = d.join("ffd.mha");
    let mask = d.join("mask.nii");
    let run = volmorph(&[
        &"warp",
        &src,
        &"--lattice",
        &lat,
        &"-o",
        &out,
        &"--method",
        &"inverse-cubic",
        &"--nonconverged-mask",
        &mask,
    ]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(
        err.contains("warning: inverse:") && err.contains("did not converge"),
        "{err}"
    );
    assert!(!err.contains("inverse: 0 of"), "some voxels fail: {err}");
    let m = info_json(&mask);
    assert_eq!(m["stats"]["max"].as_f64(), Some(1.0), "{m}");
    assert_eq!(m["stats"]["min"].as_f64(), Some(0.0), "{m}");
    // The mask belongs to the inverse methods only.
    let e = fails(&[
        &"warp",
        &src,
        &"--lattice",
        &lat,
        &"-o",
        &out,
        &"--method",
        &"pullback-linear",
        &"--nonconverged-mask",
        &mask,
    ]);
    assert!(e.contains("--nonconverged-mask"), "{e}");
    // A clean inverse warp prints no warning.
    write_identity_lattice(&src, &lat);
    let run = volmorph(&[
        &"warp",
        &src,
        &"--lattice",
        &lat,
        &"-o",
        &out,
        &"--method",
        &"inverse-linear",
    ]);
    assert!(run.status.success());
    assert!(
        run.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

#[test]
fn drag_lands_the_point_and_writes_the_lattice() {
    use volmorph_deform::SpaceMap;
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("sphere.nii.gz");
    let out = dir.path().join("dragged.nii.gz");
    let lat = dir.path().join("dragged.json");
    ok(&[&"phantom", &"sphere", &"-o", &src, &"--size", &"24"]);
    let text = ok(&[
        &"drag",
        &src,
        &"--from",
        &"0.2,0.1,0.3",
        &"--to",
        &"0.35,0.1,0.1",
        &"--radius",
        &"1.0",
        &"-o",
        &out,
        &"--lattice-out",
        &lat,
    ]);
    assert!(text.contains("moved"), "{text}");
    let lattice = volmorph_lattice::formats::read_lattice(&lat).unwrap();
    let landed = lattice.apply(glam::DVec3::new(0.2, 0.1, 0.3));
    assert!(
        (landed - glam::DVec3::new(0.35, 0.1, 0.1)).length() < 1e-9,
        "{landed}"
    );
    let info = info_json(&out);
    assert_eq!(info["dims"], serde_json::json!([24, 24, 24]));

    // A second drag from the dragged place, through the written lattice, back to the start.
    let back = dir.path().join("back.json");
    ok(&[
        &"drag",
        &src,
        &"--lattice",
        &lat,
        &"--from",
        &"0.35,0.1,0.1",
        &"--to",
        &"0.2,0.1,0.3",
        &"-o",
        &out,
        &"--lattice-out",
        &back,
        &"--method",
        &"inverse-linear",
    ]);
    let lattice = volmorph_lattice::formats::read_lattice(&back).unwrap();
    let landed = lattice.apply(glam::DVec3::new(0.2, 0.1, 0.3));
    assert!(
        (landed - glam::DVec3::new(0.2, 0.1, 0.3)).length() < 1e-9,
        "{landed}"
    );

    // A drag that folds space succeeds with a warning; conflicting drags are met in the
    // least-squares sense with a warning.
    let folded = volmorph(&[
        &"drag",
        &src,
        &"--from",
        &"0,0,0",
        &"--to",
        &"0.9,0,0",
        &"--radius",
        &"0.2",
        &"-o",
        &out,
    ]);
    assert!(folded.status.success());
    let err = String::from_utf8_lossy(&folded.stderr);
    assert!(err.contains("folds space"), "{err}");
    let conflict = volmorph(&[
        &"drag", &src, &"--from", &"0,0,0", &"--to", &"0,0,0", &"--from", &"0,0,0", &"--to",
        &"0.1,0,0", &"-o", &out,
    ]);
    assert!(conflict.status.success());
    let err = String::from_utf8_lossy(&conflict.stderr);
    assert!(err.contains("drags conflict"), "{err}");

    // Targets outside the lattice box, unmatched pairs and plain pull-backs are refused.
    let err = fails(&[
        &"drag", &src, &"--from", &"0,0,0", &"--to", &"5,0,0", &"-o", &out,
    ]);
    assert!(err.contains("outside the lattice box"), "{err}");
    let err = fails(&[
        &"drag", &src, &"--from", &"0,0,0", &"--from", &"0.1,0,0", &"--to", &"0.2,0,0", &"-o", &out,
    ]);
    assert!(err.contains("one target per dragged point"), "{err}");
    let err = fails(&[
        &"drag",
        &src,
        &"--from",
        &"0,0,0",
        &"--to",
        &"0.1,0,0",
        &"-o",
        &out,
        &"--method",
        &"pullback-linear",
    ]);
    assert!(err.contains("push-forward or an inverse method"), "{err}");
}

#[test]
fn bench_times_every_item_on_a_tiny_input() {
    let j: serde_json::Value = serde_json::from_str(&ok(&[
        &"bench",
        &"warp",
        &"--size",
        &"12",
        &"--lattice",
        &"5",
        &"--repeat",
        &"2",
        &"--edit-size",
        &"12",
        &"--json",
    ]))
    .expect("bench --json prints JSON");
    assert_eq!(j["suite"], "warp");
    assert_eq!(j["size"], 12);
    assert_eq!(j["lattice"], 5);
    let items = j["items"].as_array().expect("items");
    let names: Vec<&str> = items.iter().filter_map(|i| i["name"].as_str()).collect();
    assert_eq!(names.len(), 7, "{names:?}");
    for want in [
        "pull-back trilinear",
        "pull-back cubic",
        "push-forward nearest",
        "incremental update",
        "drag",
    ] {
        assert!(names.iter().any(|n| n.starts_with(want)), "{names:?}");
    }
    for it in items {
        let (min, med, max) = (
            it["min_s"].as_f64().unwrap(),
            it["median_s"].as_f64().unwrap(),
            it["max_s"].as_f64().unwrap(),
        );
        assert!(0.0 < min && min <= med && med <= max, "{it}");
        // Targets are stated for 256³ only.
        assert!(it["target_s"].is_null(), "{it}");
    }

    let text = ok(&[&"bench", &"isosurface", &"--size", &"16", &"--repeat", &"1"]);
    assert!(text.contains("marching cubes"), "{text}");
    assert!(text.contains("dual contouring"), "{text}");
    assert!(text.contains("triangles"), "{text}");
    let j: serde_json::Value = serde_json::from_str(&ok(&[
        &"bench",
        &"isosurface",
        &"--size",
        &"16",
        &"--repeat",
        &"1",
        &"--json",
    ]))
    .unwrap();
    for it in j["items"].as_array().unwrap() {
        assert!(it["triangles"].as_u64().unwrap() > 100, "{it}");
    }

    let err = fails(&[&"bench", &"warp", &"--size", &"12", &"--lattice", &"3"]);
    assert!(err.contains("--lattice 3"), "{err}");
    let err = fails(&[&"bench", &"isosurface", &"--repeat", &"0"]);
    assert!(err.contains("--repeat 0"), "{err}");
}

// ---------------------------------------------------------------------------------------
// `volmorph ffd` and `volmorph lattice init --mesh` (mesh free-form deformation)
// ---------------------------------------------------------------------------------------

/// The unit cube as 12 triangles (OBJ text).
const FFD_CUBE_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\n\
f 1 3 4\nf 1 4 2\nf 5 6 8\nf 5 8 7\nf 1 2 6\nf 1 6 5\nf 3 7 8\nf 3 8 4\nf 1 5 7\nf 1 7 3\n\
f 2 4 8\nf 2 8 6\n";

/// Writes the cube and its Fig. 7 lattice (degree 2, 4×4×4) with one control point moved.
fn ffd_cube_and_lattice(dir: &Path) -> (PathBuf, PathBuf) {
    let cube = dir.join("cube.obj");
    std::fs::write(&cube, FFD_CUBE_OBJ).unwrap();
    let lat = dir.join("lat.json");
    let text = ok(&[
        &"lattice",
        &"init",
        &"--mesh",
        &cube,
        &"--degree",
        &"2,2,2",
        &"--size",
        &"4,4,4",
        &"-o",
        &lat,
    ]);
    assert!(text.contains("degree 2x2x2"), "{text}");
    let mut j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&lat).unwrap()).unwrap();
    assert_eq!(j["degrees"], serde_json::json!([2, 2, 2]));
    // Pull the control point at the (1,1,3) index up: bulges the top face.
    let idx = 1 + 4 * (1 + 4 * 3);
    let z = j["control_points"][idx][2].as_f64().unwrap();
    j["control_points"][idx][2] = serde_json::json!(z + 0.3);
    let moved = dir.join("moved.json");
    std::fs::write(&moved, serde_json::to_string(&j).unwrap()).unwrap();
    (cube, moved)
}

#[test]
fn ffd_accurate_cube_reports_table_2_counts_and_writes_step_and_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let (cube, lat) = ffd_cube_and_lattice(dir.path());
    let step = dir.path().join("cube.step");
    let report = dir.path().join("cube.json");
    let text = ok(&[
        &"ffd",
        &cube,
        &"--lattice",
        &lat,
        &"--mode",
        &"accurate",
        &"-o",
        &step,
        &"--report",
        &report,
    ]);
    assert!(text.contains("sub-polygons:   36"), "{text}");
    assert!(text.contains("Bézier patches: 24"), "{text}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["sub_polygons"], 36);
    assert_eq!(r["patches"], 24);
    assert_eq!(r["closed_shell"], true);
    assert!(r["surface_area"].as_f64().unwrap() > 6.0);
    // The phases are timed one after the other, so they add up to at most the total (the
    // total left out the STEP writing once, and later the surface area and the reading).
    let part = |k: &str| r[k].as_f64().unwrap_or_else(|| panic!("no {k} in {r}"));
    let parts: f64 = ["read_s", "plan_s", "surfaces_s", "area_s", "write_s"]
        .iter()
        .map(|k| part(k))
        .sum();
    assert!(parts <= part("total_s") + 1e-6, "{r}");
    let s = std::fs::read_to_string(&step).unwrap();
    assert!(s.contains("CLOSED_SHELL") && s.contains("ADVANCED_FACE"));
    // Tessellated output in every mesh format, watertight.
    for ext in ["obj", "ply", "stl"] {
        let out = dir.path().join(format!("cube_acc.{ext}"));
        ok(&[
            &"ffd",
            &cube,
            &"--lattice",
            &lat,
            &"-o",
            &out,
            &"--chordal",
            &"1e-3",
        ]);
        let info = ok(&[&"mesh", &"info", &out]);
        if ext != "stl" {
            assert!(info.contains("closed"), "{info}");
        }
    }
    // Baselines.
    for (mode, more) in [
        ("vertex", false),
        ("uniform:2", true),
        ("adaptive:0.001", true),
    ] {
        let out = dir.path().join("base.ply");
        let text = ok(&[
            &"ffd",
            &cube,
            &"--lattice",
            &lat,
            &"--mode",
            &mode,
            &"-o",
            &out,
        ]);
        let faces: usize = text
            .lines()
            .find_map(|l| l.strip_prefix("output faces:"))
            .and_then(|l| l.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap();
        assert_eq!(faces > 12, more, "{mode}: {text}");
    }
}

#[test]
fn ffd_bad_inputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let (cube, lat) = ffd_cube_and_lattice(dir.path());
    let out = dir.path().join("out.step");
    let err = fails(&[
        &"ffd",
        &cube,
        &"--lattice",
        &lat,
        &"--mode",
        &"vertex",
        &"-o",
        &out,
    ]);
    assert!(err.contains("--mode accurate"), "{err}");
    let err = fails(&[
        &"ffd",
        &cube,
        &"--lattice",
        &lat,
        &"--mode",
        &"wobbly",
        &"-o",
        &out,
    ]);
    assert!(err.contains("wobbly"), "{err}");
    let err = fails(&[
        &"ffd",
        &cube,
        &"--lattice",
        &lat,
        &"--mode",
        &"adaptive:-1",
        &"-o",
        &out,
    ]);
    assert!(err.contains("adaptive"), "{err}");
    let empty = dir.path().join("empty.obj");
    std::fs::write(&empty, "").unwrap();
    let err = fails(&[&"ffd", &empty, &"--lattice", &lat, &"-o", &out]);
    assert!(err.contains("empty.obj"), "{err}");
    let nan = dir.path().join("nan.obj");
    std::fs::write(&nan, "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n").unwrap();
    let err = fails(&[&"ffd", &nan, &"--lattice", &lat, &"-o", &out]);
    assert!(err.contains("nan.obj"), "{err}");
    assert!(!out.exists());
    // A non-convex quad is triangulated with a warning.
    let nc = dir.path().join("nonconvex.obj");
    std::fs::write(
        &nc,
        "v 0 0 0.5\nv 1 0 0.5\nv 1 1 0.5\nv 0.5 0.2 0.5\nv 0 1 0.5\nf 1 2 3 4 5\n",
    )
    .unwrap();
    let o = volmorph(&[&"ffd", &nc, &"--lattice", &lat, &"-o", &out]);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("non-convex"));
    let lattice_out = dir.path().join("too_few.json");
    let err = fails(&[
        &"lattice",
        &"init",
        &"--mesh",
        &cube,
        &"--size",
        &"2,4,4",
        &"-o",
        &lattice_out,
    ]);
    assert!(err.contains("control points"), "{err}");
}

#[test]
fn bench_handles_runs_small() {
    let j: serde_json::Value = serde_json::from_str(&ok(&[
        &"bench",
        &"handles",
        &"--image-grid",
        &"10",
        &"--handles",
        &"12",
        &"--volume",
        &"12,10,8",
        &"--grid",
        &"4",
        &"--landmarks",
        &"20",
        &"--repeat",
        &"1",
        &"--json",
    ]))
    .expect("bench handles --json prints JSON");
    assert_eq!(j["suite"], "handles");
    let items = j["items"].as_array().expect("items");
    let names: Vec<&str> = items.iter().filter_map(|i| i["name"].as_str()).collect();
    assert_eq!(names.len(), 8, "{names:?}");
    for want in [
        "2D rigid MLS, 11 points",
        "2D rigid MLS, 7 segments",
        "3D affine MLS: set-up",
        "3D affine MLS: move one handle",
        "3D affine MLS: resample volume",
        "TPS: factorise",
        "TPS: re-solve",
        "TPS: evaluate",
    ] {
        assert!(
            names.iter().any(|n| n.starts_with(want)),
            "{want}: {names:?}"
        );
    }
    for it in items {
        let (min, med, max) = (
            it["min_s"].as_f64().unwrap(),
            it["median_s"].as_f64().unwrap(),
            it["max_s"].as_f64().unwrap(),
        );
        assert!(0.0 < min && min <= med && med <= max, "{it}");
        // Targets are stated for the default sizes only.
        assert!(it["target_s"].is_null(), "{it}");
    }
    let text = ok(&[
        &"bench",
        &"handles",
        &"--image-grid",
        &"10",
        &"--handles",
        &"12",
        &"--volume",
        &"12,10,8",
        &"--grid",
        &"4",
        &"--landmarks",
        &"20",
        &"--repeat",
        &"2",
    ]);
    assert!(text.contains("TPS: factorise"), "{text}");
    assert!(text.contains(" ms"), "{text}");
    let err = fails(&[&"bench", &"handles", &"--landmarks", &"2"]);
    assert!(err.contains("--landmarks 2"), "{err}");
    let err = fails(&[&"bench", &"handles", &"--volume", &"0,4,4"]);
    assert!(err.contains("--volume"), "{err}");
}

#[test]
fn bench_ffd_runs_small() {
    let j: serde_json::Value = serde_json::from_str(&ok(&[
        &"bench",
        &"ffd",
        &"--rings",
        &"8",
        &"--vertex-rings",
        &"10",
        &"--points",
        &"999",
        &"--repeat",
        &"1",
        &"--json",
    ]))
    .unwrap();
    let items = j["items"].as_array().unwrap();
    let names: Vec<&str> = items
        .iter()
        .map(|it| it["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "accurate FFD (plan + surfaces)",
            "vertex FFD",
            "vertex FFD, positions only",
            "STEP text of the accurate FFD",
            "trivariate point + gradient"
        ]
    );
    for it in items {
        assert!(it["median_s"].as_f64().unwrap() > 0.0, "{it}");
        assert!(it["target_s"].is_null(), "{it}");
    }
    assert!(items[0]["triangles"].as_u64().unwrap() >= 4 * 8 * 7);
    assert_eq!(j["points"], 999);
    assert_eq!(items[4]["rate_unit"], "Mpts/s");
    assert!(items[4]["median_rate"].as_f64().unwrap() > 0.0);
}

// ---------------------------------------------------------------------------------------
// volmorph frep: F-rep models in the HyperFun language.
// ---------------------------------------------------------------------------------------

/// A small HyperFun model written for these tests: a block with a spherical hole, its size
/// set by the parameter a[1].
const FREP_CSG: &str = "-- block minus ball
model(x[3], a[1])
{
  array center[3];
  array corner[3];
  center = [0, 0, 0];
  corner = [-1, -1, -1];
  ball = hfSphere(x, center, a[1]);
  box = hfBlock(x, corner, 2, 2, 2);
  model = box \\ ball;
}
";

/// A second model for morphing: a sphere in the machine-exported assignment form.
const FREP_BALL: &str = "model(x[3], a[1])
{
  t0 = sqrt(x[1]*x[1] + x[2]*x[2] + x[3]*x[3]);
  model = 1.1 - t0;
}
";

#[test]
fn frep_eval_mesh_render_and_morph() {
    let dir = tempfile::tempdir().unwrap();
    let csg = dir.path().join("csg.hf");
    let ball = dir.path().join("ball.hf");
    std::fs::write(&csg, FREP_CSG).unwrap();
    std::fs::write(&ball, FREP_BALL).unwrap();

    let vol = dir.path().join("csg.nii");
    let out = ok(&[
        &"frep",
        &"eval",
        &csg,
        &"--grid",
        &"24",
        &"--bounds=-1.5,1.5",
        &"-o",
        &vol,
        &"--param",
        &"a1=1.2",
    ]);
    assert!(out.contains("inside"), "{out}");
    let j = info_json(&vol);
    assert_eq!(j["dims"], serde_json::json!([24, 24, 24]));
    assert_eq!(j["voxel_type"], "f32");
    // The centre is in the hole (negative), a box corner is solid (positive).
    assert!(j["stats"]["min"].as_f64().unwrap() < 0.0);
    assert!(j["stats"]["max"].as_f64().unwrap() > 0.0);

    let mesh = dir.path().join("csg.ply");
    let out = ok(&[
        &"frep",
        &"mesh",
        &csg,
        &"--grid",
        &"32",
        &"--bounds=-1.5,1.5",
        &"-o",
        &mesh,
        &"--param",
        &"a1=1.2",
    ]);
    assert!(out.contains("closed manifold"), "{out}");
    let info = ok(&[&"mesh", &"info", &mesh]);
    assert!(info.contains("closed"), "{info}");

    let png = dir.path().join("csg.png");
    let out = ok(&[
        &"frep",
        &"render",
        &csg,
        &"-o",
        &png,
        &"--size",
        &"48x32",
        &"--bounds=-1.5,1.5",
        &"--param",
        &"a1=1.2",
    ]);
    assert!(out.contains("48x32"), "{out}");
    assert!(std::fs::metadata(&png).unwrap().len() > 100);

    let frames = dir.path().join("frames");
    let out = ok(&[
        &"frep",
        &"morph",
        &csg,
        &ball,
        &"--frames",
        &"3",
        &"--schedule",
        &"smoothstep",
        &"--size",
        &"24",
        &"-o",
        &frames,
        &"--param",
        &"a1=1.2",
    ]);
    assert!(out.contains("3 frames"), "{out}");
    for i in 0..3 {
        assert!(frames.join(format!("frame{i:04}.png")).exists());
    }

    let out = ok(&[
        &"bench",
        &"frep",
        &csg,
        &ball,
        &"--grid",
        &"16",
        &"--repeat",
        &"1",
        &"--json",
    ]);
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    let items = j["items"].as_array().unwrap();
    // Two grid cases checked point by point, then two timed pictures.
    assert_eq!(items.len(), 4, "{j}");
    for it in &items[..2] {
        assert_eq!(it["same_as_pointwise"], true, "{it}");
    }
    for it in &items[2..] {
        assert!(
            it["name"].as_str().unwrap().contains("render 512x512"),
            "{it}"
        );
    }
}

#[test]
fn frep_bad_models_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("v.nii");
    let cases = [
        ("syntax.hf", "m(x[3], a[1]) {\n  m = 1 +;\n}", "line 2"),
        (
            "unknown.hf",
            "m(x[3], a[1]) {\n  m = hfGizmo(x);\n}",
            "unknown function `hfGizmo`",
        ),
        (
            "arity.hf",
            "m(x[3], a[1]) {\n  array c[3];\n  m = hfSphere(x, c);\n}",
            "takes 3 arguments",
        ),
        (
            "loop.hf",
            "m(x[3], a[1]) {\n  i = 0;\n  while 1 > 0 loop i = i + 1; endloop;\n  m = i;\n}",
            "loop does not end",
        ),
        (
            "recursion.hf",
            "m(x[3], a[1]) {\n  m = m(x, a);\n}",
            "recursive call",
        ),
    ];
    for (name, src, msg) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, src).unwrap();
        let err = fails(&[&"frep", &"eval", &p, &"--grid", &"8", &"-o", &vol]);
        assert!(err.contains(name) && err.contains(msg), "{err}");
        assert!(!vol.exists());
    }
    let good = dir.path().join("good.hf");
    std::fs::write(&good, FREP_BALL).unwrap();
    let err = fails(&[&"frep", &"eval", &good, &"--grid", &"1", &"-o", &vol]);
    assert!(err.contains("--grid 1"), "{err}");
    let err = fails(&[&"frep", &"eval", &good, &"--bounds=1,0", &"-o", &vol]);
    assert!(err.contains("--bounds"), "{err}");
    let err = fails(&[&"frep", &"eval", &good, &"--param", &"b1=2", &"-o", &vol]);
    assert!(err.contains("a1, a2"), "{err}");
    let err = fails(&[&"frep", &"eval", &good, &"--param", &"a5=2", &"-o", &vol]);
    assert!(err.contains("a5"), "{err}");
    let err = fails(&[
        &"frep",
        &"morph",
        &good,
        &good,
        &"--schedule",
        &"wobbly",
        &"-o",
        &dir.path(),
    ]);
    assert!(err.contains("schedule"), "{err}");
}

// ---------------------------------------------------------------------------------------------
// Handle-driven deformations: `volmorph handles warp` and `volmorph mls2d`.
// ---------------------------------------------------------------------------------------------

/// Eight handles at the corners of a box inside the phantoms' [-1, 1]³ domain, moved by `f`,
/// as a handle JSON.
fn handle_json(f: impl Fn([f64; 3]) -> [f64; 3]) -> String {
    let mut items = Vec::new();
    for k in 0..2 {
        for j in 0..2 {
            for i in 0..2 {
                let p = [
                    -0.6 + 1.1 * f64::from(i),
                    -0.5 + 1.0 * f64::from(j),
                    -0.7 + 1.3 * f64::from(k),
                ];
                let q = f(p);
                items.push(format!(
                    "{{\"source\": [{}, {}, {}], \"target\": [{}, {}, {}]}}",
                    p[0], p[1], p[2], q[0], q[1], q[2]
                ));
            }
        }
    }
    format!("{{\"points\": [{}]}}", items.join(", "))
}

#[test]
fn handles_warp_identity_volume_is_unchanged_for_every_method() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("sphere.nii");
    ok(&[&"phantom", &"sphere", &"-o", &vol, &"--dims", &"18,16,14"]);
    let h = dir.path().join("id.json");
    std::fs::write(&h, handle_json(|p| p)).unwrap();
    let before = raw_bytes(dir.path(), &vol);
    for method in ["affine", "similarity", "rigid", "tps"] {
        let out = dir.path().join(format!("{method}.nii"));
        let text = ok(&[
            &"handles",
            &"warp",
            &vol,
            &"--handles",
            &h,
            &"--method",
            &method,
            &"-o",
            &out,
        ]);
        assert!(text.contains("0 of"), "{method}: {text}");
        assert_eq!(raw_bytes(dir.path(), &out), before, "{method}");
    }
    // Exact per-voxel mode too.
    let out = dir.path().join("exact.nii");
    ok(&[
        &"handles",
        &"warp",
        &vol,
        &"--handles",
        &h,
        &"--exact",
        &"-o",
        &out,
    ]);
    assert_eq!(raw_bytes(dir.path(), &out), before);
}

#[test]
fn handles_warp_moves_meshes_forward_and_reads_point_lists() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("sphere.nii");
    ok(&[&"phantom", &"sphere", &"-o", &vol, &"--dims", &"20,20,20"]);
    let mesh = dir.path().join("sphere.ply");
    ok(&[&"isosurface", &vol, &"--level", &"127", &"-o", &mesh]);
    let bounds = |p: &Path| -> String {
        let text = ok(&[&"mesh", &"info", &p]);
        text.lines()
            .find(|l| l.starts_with("bounds:"))
            .unwrap()
            .to_string()
    };
    // A rigid translation by (0.25, 0, 0) of the handles moves every vertex by it.
    let h = dir.path().join("shift.txt");
    let mut pairs = String::from("# sx sy sz tx ty tz\n");
    let src = [
        [-0.6, -0.5, -0.7],
        [0.5, -0.5, -0.7],
        [-0.6, 0.5, -0.7],
        [0.1, 0.2, 0.6],
        [0.4, -0.3, 0.5],
    ];
    for p in src {
        pairs.push_str(&format!(
            "{} {} {} {} {} {}\n",
            p[0],
            p[1],
            p[2],
            p[0] + 0.25,
            p[1],
            p[2]
        ));
    }
    std::fs::write(&h, pairs).unwrap();
    let out = dir.path().join("moved.ply");
    let text = ok(&[
        &"handles",
        &"warp",
        &mesh,
        &"--handles",
        &h,
        &"--method",
        &"tps",
        &"-o",
        &out,
    ]);
    assert!(text.contains("moved"), "{text}");
    let parse = |s: &str| -> Vec<f64> {
        s.replace(['(', ')', ','], " ")
            .split_whitespace()
            .filter_map(|t| t.parse().ok())
            .collect()
    };
    let (b0, b1) = (parse(&bounds(&mesh)), parse(&bounds(&out)));
    assert_eq!(b0.len(), 6);
    assert!((b1[0] - b0[0] - 0.25).abs() < 1e-4, "{b0:?} {b1:?}");
    assert!((b1[4] - b0[4]).abs() < 1e-4, "{b0:?} {b1:?}");

    // The same handles as two point lists: Slicer .fcsv (RAS) and 3-column text (LPS).
    let fcsv = dir.path().join("src.fcsv");
    let mut f = String::from("# Markups fiducial file version = 4.11\n# CoordinateSystem = RAS\n");
    for (i, p) in src.iter().enumerate() {
        f.push_str(&format!(
            "m{i},{},{},{},0,0,0,1,1,1,0,F-{i},,\n",
            -p[0], -p[1], p[2]
        ));
    }
    std::fs::write(&fcsv, f).unwrap();
    let to = dir.path().join("dst.xyz");
    let t: String = src
        .iter()
        .map(|p| format!("{} {} {}\n", p[0] + 0.25, p[1], p[2]))
        .collect();
    std::fs::write(&to, t).unwrap();
    let out2 = dir.path().join("moved2.ply");
    ok(&[
        &"handles",
        &"warp",
        &mesh,
        &"--from",
        &fcsv,
        &"--to",
        &to,
        &"--method",
        &"rigid",
        &"-o",
        &out2,
    ]);
    let b2 = parse(&bounds(&out2));
    assert!((b2[0] - b0[0] - 0.25).abs() < 1e-4, "{b0:?} {b2:?}");
}

#[test]
fn handles_warp_bad_input_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("sphere.nii");
    ok(&[&"phantom", &"sphere", &"-o", &vol, &"--dims", &"12,12,12"]);
    let out = dir.path().join("out.nii");
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let dup = write(
        "dup.txt",
        "0 0 0 0 0 0\n0 0 0 1 1 1\n0.5 0 0 0.5 0 0\n0 0.5 0 0 0.5 0\n0 0 0.5 0 0 0.5\n",
    );
    let err = fails(&[&"handles", &"warp", &vol, &"--handles", &dup, &"-o", &out]);
    assert!(err.contains("coincide"), "{err}");
    let nan = write("nan.txt", "0 0 0 nan 0 0\n");
    let err = fails(&[&"handles", &"warp", &vol, &"--handles", &nan, &"-o", &out]);
    assert!(err.contains("nan.txt"), "{err}");
    let three = write(
        "three.json",
        r#"{"points": [{"source": [0,0,0], "target": [0,0,0]}, {"source": [0.5,0,0], "target": [0.5,0,0]}, {"source": [0,0.5,0], "target": [0,0.5,0]}]}"#,
    );
    let err = fails(&[
        &"handles",
        &"warp",
        &vol,
        &"--handles",
        &three,
        &"--method",
        &"affine",
        &"-o",
        &out,
    ]);
    assert!(err.contains("at least 4"), "{err}");
    let err = fails(&[
        &"handles",
        &"warp",
        &vol,
        &"--handles",
        &three,
        &"--method",
        &"frames",
        &"-o",
        &out,
    ]);
    assert!(err.contains("frame"), "{err}");
    let err = fails(&[&"handles", &"warp", &vol, &"-o", &out]);
    assert!(err.contains("--handles"), "{err}");
    let bad = write(
        "bad.json",
        "{\"points\": [{\"source\": [0, 0], \"target\": [1, 2, 3]}]}",
    );
    let err = fails(&[&"handles", &"warp", &vol, &"--handles", &bad, &"-o", &out]);
    assert!(err.contains("bad.json"), "{err}");
    assert!(!out.exists());
}

#[test]
fn mls2d_deforms_a_picture_and_reports_folds() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("sphere.nii");
    ok(&[&"phantom", &"sphere", &"-o", &vol, &"--dims", &"40,30,8"]);
    let png = dir.path().join("slice.png");
    ok(&[
        &"slice",
        &vol,
        &"-o",
        &png,
        &"--axis",
        &"z",
        &"--index",
        &"4",
        &"--zoom",
        &"1",
        &"--no-labels",
    ]);
    let h = dir.path().join("h2.json");
    std::fs::write(
        &h,
        r#"{"points": [{"source": [5, 5], "target": [5, 5]}, {"source": [30, 6], "target": [33, 8]},
                       {"source": [10, 25], "target": [10, 25]}],
            "segments": [{"source": [[20, 10], [20, 20]], "target": [[22, 10], [24, 20]]}]}"#,
    )
    .unwrap();
    for method in ["affine", "similarity", "rigid"] {
        let out = dir.path().join(format!("{method}.png"));
        let text = ok(&[
            &"mls2d",
            &png,
            &"--handles",
            &h,
            &"--method",
            &method,
            &"--grid",
            &"20",
            &"-o",
            &out,
        ]);
        assert!(text.contains("0.000% of the grid folds"), "{text}");
        assert!(out.exists());
    }
    // 3D handles are refused; so is a non-integer α with segments.
    let h3 = dir.path().join("h3.json");
    std::fs::write(&h3, handle_json(|p| p)).unwrap();
    let out = dir.path().join("x.png");
    let err = fails(&[&"mls2d", &png, &"--handles", &h3, &"-o", &out]);
    assert!(err.contains("2D"), "{err}");
    let err = fails(&[
        &"mls2d",
        &png,
        &"--handles",
        &h,
        &"--alpha",
        &"1.5",
        &"-o",
        &out,
    ]);
    assert!(err.contains("integer"), "{err}");
    assert!(!out.exists());
}

/// CRC-32 (ISO-HDLC, the PNG chunk checksum) of `bytes`.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A PNG file of a few dozen bytes whose header claims a `width × height` RGBA image: the
/// signature, IHDR, an empty IDAT and IEND.
fn png_claiming(width: u32, height: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8; 4], data: &[u8]| {
        out.extend_from_slice(&u32::try_from(data.len()).unwrap().to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        out.extend_from_slice(&body);
        out.extend_from_slice(&crc32(&body).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]); // 8-bit RGBA, deflate, no filter, no interlace
    chunk(b"IHDR", &ihdr);
    chunk(b"IDAT", &[]);
    chunk(b"IEND", &[]);
    out
}

/// Issue: `mls2d` on a 30000² PNG took 4.5 GB from an 875 KB file. The declared size is
/// checked against the memory budget before anything is decoded or allocated.
#[test]
fn mls2d_on_a_30000_square_png_is_refused_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("huge.png");
    std::fs::write(&png, png_claiming(30_000, 30_000)).unwrap();
    let h = dir.path().join("h.json");
    std::fs::write(
        &h,
        r#"{"points": [{"source": [5, 5], "target": [6, 5]}, {"source": [30, 6], "target": [30, 6]}]}"#,
    )
    .unwrap();
    let out = dir.path().join("out.png");
    let start = std::time::Instant::now();
    let err = fails(&[
        &"--memory-limit",
        &"1G",
        &"mls2d",
        &png,
        &"--handles",
        &h,
        &"-o",
        &out,
    ]);
    assert!(err.contains("huge.png"), "{err}");
    assert!(err.contains("30000×30000"), "{err}");
    assert!(
        err.contains("--memory-limit"),
        "names how to raise the budget: {err}"
    );
    assert!(!out.exists());
    // Refused from the header alone: decoding 3.6 GB of pixels would take far longer.
    assert!(start.elapsed().as_secs() < 20, "{:?}", start.elapsed());
}

#[test]
fn handles_apply_maps_points_forward_with_full_precision() {
    let dir = tempfile::tempdir().unwrap();
    let h = dir.path().join("h.json");
    std::fs::write(&h, handle_json(|p| [p[0] + 0.125, p[1] - 0.5, p[2]])).unwrap();
    let pts = dir.path().join("p.txt");
    std::fs::write(&pts, "0.1 0.2 0.3\n-0.6 -0.5 -0.7\n").unwrap();
    for method in ["affine", "similarity", "rigid", "tps"] {
        let out = dir.path().join(format!("{method}.txt"));
        ok(&[
            &"handles",
            &"apply",
            &pts,
            &"--handles",
            &h,
            &"--method",
            &method,
            &"-o",
            &out,
        ]);
        let text = std::fs::read_to_string(&out).unwrap();
        let v: Vec<f64> = text
            .split_whitespace()
            .map(|t| t.parse().unwrap())
            .collect();
        // A translation of all handles is followed exactly by every method.
        let expect = [0.225, -0.3, 0.3, -0.475, -1.0, -0.7];
        for (a, b) in v.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{method}: {v:?}");
        }
    }
}

#[test]
fn frep_sections_reconstructs_closed_solids() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("contours.json");
    // Three octagons shrinking along z, the middle one with two loops.
    let oct = |r: f64, cx: f64| -> String {
        let pts: Vec<String> = (0..8)
            .map(|i| {
                let t = std::f64::consts::TAU * f64::from(i) / 8.0;
                format!("[{}, {}]", cx + r * t.cos(), r * t.sin())
            })
            .collect();
        format!("[{}]", pts.join(", "))
    };
    let text = format!(
        r#"{{"sections": [{{"z": 0, "points": {}}}, {{"z": 1, "loops": [{}, {}]}}, {{"z": 2.5, "points": {}}}]}}"#,
        oct(2.0, 0.0),
        oct(0.8, -1.0),
        oct(0.8, 1.0),
        oct(1.0, 0.0)
    );
    std::fs::write(&json, text).unwrap();
    let mesh = dir.path().join("stack.ply");
    let out = ok(&[&"frep", &"sections", &json, &"-o", &mesh, &"--grid", &"40"]);
    assert!(out.contains("closed manifold"), "{out}");
    let out = ok(&[
        &"frep",
        &"sections",
        &json,
        &"-o",
        &mesh,
        &"--grid",
        &"40",
        &"--blend",
        &"catmull-rom",
    ]);
    assert!(out.contains("closed manifold"), "{out}");

    let femur = dir.path().join("femur.obj");
    let out = ok(&[
        &"frep",
        &"sections",
        &"--example",
        &"femur",
        &"-o",
        &femur,
        &"--grid",
        &"64",
    ]);
    assert!(
        out.contains("12 sections") && out.contains("closed manifold"),
        "{out}"
    );
    let vol = dir.path().join("femur.nii");
    ok(&[
        &"frep",
        &"sections",
        &"--example",
        &"femur",
        &"-o",
        &vol,
        &"--grid",
        &"24",
    ]);
    let j = info_json(&vol);
    assert!(j["stats"]["max"].as_f64().unwrap() > 0.0);

    std::fs::write(
        &json,
        r#"{"sections": [{"z": 0, "points": [[0, 0], [1, 0], [0, 1]]}]}"#,
    )
    .unwrap();
    let err = fails(&[&"frep", &"sections", &json, &"-o", &mesh]);
    assert!(err.contains("cross-sections"), "{err}");
}

#[test]
fn frep_map_writes_volume_mesh_picture_and_animation() {
    let dir = tempfile::tempdir().unwrap();
    let csg = dir.path().join("csg.hf");
    let ball = dir.path().join("ball.hf");
    std::fs::write(&csg, FREP_CSG).unwrap();
    std::fs::write(&ball, FREP_BALL).unwrap();
    // A shell of the block (Fig. 8) pricked by a control point (Fig. 2).
    let spec = dir.path().join("shell.json");
    std::fs::write(
        &spec,
        r#"{"version": 1, "mappings": [
            {"kind": "control-points", "points": [{"at": [1.3, 0, 0], "radius": 0.5}]},
            {"kind": "shell", "a": 0.5, "b": 0.05}]}"#,
    )
    .unwrap();
    let vol = dir.path().join("shell.nii");
    let out = ok(&[
        &"frep",
        &"map",
        &csg,
        &"--mapping",
        &spec,
        &"-o",
        &vol,
        &"--grid",
        &"20",
        &"--bounds=-1.6,1.6",
        &"--param",
        &"a1=1.2",
    ]);
    assert!(
        out.contains("2 mappings") && out.contains("inside"),
        "{out}"
    );
    let j = info_json(&vol);
    assert_eq!(j["dims"], serde_json::json!([20, 20, 20]));
    let mesh = dir.path().join("shell.ply");
    let out = ok(&[
        &"frep",
        &"map",
        &csg,
        &"--mapping",
        &spec,
        &"-o",
        &mesh,
        &"--grid",
        &"32",
        &"--bounds=-1.6,1.6",
        &"--param",
        &"a1=1.2",
        &"--close",
    ]);
    assert!(out.contains("closed manifold"), "{out}");
    let png = dir.path().join("shell.png");
    let out = ok(&[
        &"frep",
        &"map",
        &csg,
        &"--mapping",
        &spec,
        &"-o",
        &png,
        &"--size",
        &"40x30",
        &"--bounds=-1.6,1.6",
        &"--param",
        &"a1=1.2",
    ]);
    assert!(out.contains("40x30"), "{out}");
    assert!(std::fs::metadata(&png).unwrap().len() > 100);

    // A metamorphosis into the ball, animated; the ball is named relative to the spec.
    let morph = dir.path().join("morph.json");
    std::fs::write(
        &morph,
        r#"{"version": 1, "mappings": [{"kind": "metamorphosis",
            "target": {"file": "ball.hf"}, "schedule": "smoothstep"}]}"#,
    )
    .unwrap();
    let gif = dir.path().join("morph.gif");
    let out = ok(&[
        &"frep",
        &"map",
        &csg,
        &"--mapping",
        &morph,
        &"--frames",
        &"3",
        &"--size",
        &"24",
        &"-o",
        &gif,
        &"--param",
        &"a1=1.2",
    ]);
    assert!(out.contains("3 frames"), "{out}");
    // At t = 1 the result is the ball: the centre is inside.
    let end = dir.path().join("end.nii");
    ok(&[
        &"frep",
        &"map",
        &csg,
        &"--mapping",
        &morph,
        &"--t",
        &"1",
        &"-o",
        &end,
        &"--grid",
        &"9",
        &"--bounds=-1.6,1.6",
        &"--param",
        &"a1=1.2",
    ]);
    assert!(info_json(&end)["stats"]["max"].as_f64().unwrap() > 1.0);
    // An animation file without --frames, a time out of range.
    let err = fails(&[&"frep", &"map", &csg, &"--mapping", &morph, &"-o", &gif]);
    assert!(err.contains("--frames"), "{err}");
    let err = fails(&[
        &"frep",
        &"map",
        &csg,
        &"--mapping",
        &morph,
        &"--t",
        &"2",
        &"-o",
        &end,
    ]);
    assert!(err.contains("--t"), "{err}");
}

#[test]
fn frep_map_bad_specs_name_the_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let csg = dir.path().join("csg.hf");
    std::fs::write(&csg, FREP_CSG).unwrap();
    let vol = dir.path().join("v.nii");
    let cases = [
        (
            r#"{"version": 1, "mappings": [{"kind": "shell", "a": 1, "b": "x"}]}"#,
            "mappings[0].b",
        ),
        (
            r#"{"version": 1, "mappings": [{"kind": "twirl"}]}"#,
            "mappings[0]",
        ),
        (r#"{"version": 7, "mappings": []}"#, "version"),
        (
            r#"{"version": 1, "mappings": [{"kind": "control-points",
                "points": [{"at": [0, 0, 0], "radius": -1}]}]}"#,
            "mappings[0].points[0]",
        ),
        (
            r#"{"version": 1, "mappings": [{"kind": "metamorphosis",
                "target": {"file": "../outside.hf"}}]}"#,
            "mappings[0].target",
        ),
    ];
    for (i, (text, field)) in cases.iter().enumerate() {
        let spec = dir.path().join(format!("bad{i}.json"));
        std::fs::write(&spec, text).unwrap();
        let err = fails(&[
            &"frep",
            &"map",
            &csg,
            &"--mapping",
            &spec,
            &"-o",
            &vol,
            &"--grid",
            &"8",
        ]);
        assert!(
            err.contains(&format!("bad{i}.json")) && err.contains(field),
            "case {i}: {err}"
        );
        assert!(!vol.exists());
    }
}

#[test]
fn frep_points_reconstructs_a_solid_through_its_points() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("cloud.xyz");
    // 120 points on an ellipsoid with semi-axes 1.2, 0.8, 0.6.
    let text: String = (0..120)
        .map(|i| {
            let u = (f64::from(i) + 0.5) / 120.0;
            let th = (1.0 - 2.0 * u).acos();
            let ph = 2.399_963 * f64::from(i);
            format!(
                "{} {} {}\n",
                1.2 * th.sin() * ph.cos(),
                0.8 * th.sin() * ph.sin(),
                0.6 * th.cos()
            )
        })
        .collect();
    std::fs::write(&xyz, text).unwrap();
    let mesh = dir.path().join("cloud.ply");
    let out = ok(&[&"frep", &"points", &xyz, &"-o", &mesh, &"--grid", &"40"]);
    assert!(
        out.contains("120 points") && out.contains("closed manifold"),
        "{out}"
    );
    // The largest |f| at a point is printed: the surface passes through them.
    let worst: f64 = out
        .split("at a point ")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .unwrap()
        .parse()
        .unwrap();
    assert!(worst < 1e-6, "{out}");
    let png = dir.path().join("cloud.png");
    let out = ok(&[&"frep", &"points", &xyz, &"-o", &png, &"--size", &"32"]);
    assert!(out.contains("32x32"), "{out}");
    let vol = dir.path().join("cloud.nii");
    ok(&[&"frep", &"points", &xyz, &"-o", &vol, &"--grid", &"12"]);
    assert!(info_json(&vol)["stats"]["max"].as_f64().unwrap() > 0.0);
    // The vertices of a mesh are points too.
    let again = dir.path().join("again.obj");
    let out = ok(&[
        &"frep",
        &"points",
        &mesh,
        &"-o",
        &again,
        &"--grid",
        &"24",
        &"--smoothing",
        &"1e-3",
    ]);
    assert!(out.contains("closed manifold"), "{out}");
    // Coplanar points are refused naming the file.
    let flat = dir.path().join("flat.xyz");
    std::fs::write(&flat, "0 0 0\n1 0 0\n0 1 0\n1 1 0\n0.5 0.2 0\n").unwrap();
    let err = fails(&[&"frep", &"points", &flat, &"-o", &mesh]);
    assert!(err.contains("flat.xyz") && err.contains("plane"), "{err}");
}

// ---------------------------------------------------------------------------------------------
// volmorph nurbs: fit, eval, slice, isosurface.

/// A 14³ sphere signed-distance phantom fitted as the attribute `d`; returns (dir, model).
fn nurbs_sphere_model(dir: &Path) -> PathBuf {
    let src = dir.join("sphere_sdf.nii");
    ok(&[
        &"phantom", &"sphere", &"-o", &src, &"--kind", &"sdf", &"--size", &"14",
    ]);
    let model = dir.join("sphere.json");
    let out = ok(&[&"nurbs", &"fit", &src, &"-o", &model, &"--name", &"d"]);
    assert!(
        out.contains("interpolation at the Greville abscissae"),
        "{out}"
    );
    model
}

#[test]
fn nurbs_fit_eval_isosurface_and_slice() {
    let dir = tempfile::tempdir().unwrap();
    let model = nurbs_sphere_model(dir.path());
    // Least squares with fewer control points.
    let small = dir.path().join("small.json");
    let src = dir.path().join("sphere_sdf.nii");
    let out = ok(&[
        &"nurbs",
        &"fit",
        &src,
        &"-o",
        &small,
        &"--control-points",
        &"8",
        &"--order",
        &"3",
    ]);
    assert!(
        out.contains("least squares") && out.contains("8x8x8"),
        "{out}"
    );

    // eval: the box centre maps to the physical centre, the SDF is negative there.
    let info = info_json(&src);
    let origin: Vec<f64> = serde_json::from_value(info["origin"].clone()).unwrap();
    let spacing: Vec<f64> = serde_json::from_value(info["spacing"].clone()).unwrap();
    let j: serde_json::Value = serde_json::from_str(&ok(&[
        &"nurbs",
        &"eval",
        &model,
        &"--at",
        &"0.5,0.5,0.5",
        &"--at",
        &"0,0,0",
        &"--json",
    ]))
    .unwrap();
    let c = &j[0];
    for a in 0..3 {
        // The interpolating geometry is symmetric: the parameter centre is the box centre.
        let centre = origin[a] + spacing[a] * 6.5;
        assert!(
            (c["point"][a].as_f64().unwrap() - centre).abs() < 1e-9,
            "{c}"
        );
        // A tensor product of per-axis maps: du moves along x only, and forwards.
        let key = ["du", "dv", "dw"][a];
        for b in 0..3 {
            let d = c[key][b].as_f64().unwrap();
            if a == b {
                assert!(d > 0.0, "{c}");
            } else {
                assert!(d.abs() < 1e-9, "{c}");
            }
        }
    }
    // The least-squares model has the trilinear box geometry: du is the box edge.
    let j_small: serde_json::Value = serde_json::from_str(&ok(&[
        &"nurbs",
        &"eval",
        &small,
        &"--at",
        &"0.5,0.5,0.5",
        &"--json",
    ]))
    .unwrap();
    for a in 0..3 {
        let edge = spacing[a] * 13.0;
        let key = ["du", "dv", "dw"][a];
        assert!(
            (j_small[0][key][a].as_f64().unwrap() - edge).abs() < 1e-9,
            "{}",
            j_small[0]
        );
    }
    assert!(c["attributes"]["d"][0].as_f64().unwrap() < 0.0);
    assert!((j[1]["point"][0].as_f64().unwrap() - origin[0]).abs() < 1e-9);
    let text = ok(&[&"nurbs", &"eval", &model, &"--at", &"0.25,0.5,1"]);
    assert!(text.contains("point") && text.contains("d = "), "{text}");

    // isosurface d = 0: a closed surface, coloured by d itself, written as PLY with u v w.
    let iso = dir.path().join("iso.ply");
    let out = ok(&[
        &"nurbs",
        &"isosurface",
        &model,
        &"--attribute",
        &"d",
        &"--level",
        &"0",
        &"-o",
        &iso,
        &"--color-by",
        &"d",
    ]);
    assert!(out.contains("closed"), "{out}");
    let bytes = std::fs::read(&iso).unwrap();
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(600)]).into_owned();
    for p in [
        "property double u",
        "property double w",
        "property float d",
        "property uchar red",
        "property uchar blue",
    ] {
        assert!(head.contains(p), "{head}");
    }

    // slice x = centre, per-polygon colours in PLY, per-vertex colours in OBJ.
    let cx = origin[0] + spacing[0] * 6.5;
    let plane = format!("1,0,0,{}", -cx);
    let cut = dir.path().join("cut.ply");
    let out = ok(&[
        &"nurbs",
        &"slice",
        &model,
        &"--plane",
        &plane,
        &"--attribute",
        &"d",
        &"-o",
        &cut,
        &"--per-polygon",
        &"--colormap",
        &"hot",
        &"--range=-1,1",
    ]);
    assert!(out.contains("triangles"), "{out}");
    let bytes = std::fs::read(&cut).unwrap();
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(600)]).into_owned();
    let face = &head[head.find("element face").unwrap()..];
    assert!(face.contains("property float d") && face.contains("property uchar red"));
    let obj = dir.path().join("cut.obj");
    ok(&[
        &"nurbs",
        &"slice",
        &model,
        &"--plane",
        &plane,
        &"--attribute",
        &"d",
        &"-o",
        &obj,
    ]);
    let text = std::fs::read_to_string(&obj).unwrap();
    let v = text.lines().find(|l| l.starts_with("v ")).unwrap();
    assert_eq!(v.split_whitespace().count(), 7, "{v}");
    let x: f64 = v.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!((x - cx).abs() < 1e-9);
    // Geometry-only slice.
    let plain = dir.path().join("plain.obj");
    ok(&[
        &"nurbs", &"slice", &model, &"--plane", &plane, &"-o", &plain,
    ]);
    let text = std::fs::read_to_string(&plain).unwrap();
    let v = text.lines().find(|l| l.starts_with("v ")).unwrap();
    assert_eq!(v.split_whitespace().count(), 4, "{v}");
}

#[test]
fn nurbs_bad_inputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let model = nurbs_sphere_model(dir.path());
    let out = dir.path().join("o.ply");
    let e = fails(&[
        &"nurbs",
        &"isosurface",
        &model,
        &"--attribute",
        &"d",
        &"--level",
        &"NaN",
        &"-o",
        &out,
    ]);
    assert!(e.contains("finite"), "{e}");
    let e = fails(&[
        &"nurbs",
        &"isosurface",
        &model,
        &"--attribute",
        &"nope",
        &"--level",
        &"0",
        &"-o",
        &out,
    ]);
    assert!(e.contains("nope"), "{e}");
    let e = fails(&[
        &"nurbs", &"slice", &model, &"--plane", &"0,0,0,1", &"-o", &out,
    ]);
    assert!(e.contains("normal"), "{e}");
    let e = fails(&[
        &"nurbs", &"slice", &model, &"--plane", &"1,0,0", &"-o", &out,
    ]);
    assert!(e.contains("4 numbers"), "{e}");
    for t in ["0", "-1"] {
        let e = fails(&[
            &"nurbs",
            &"slice",
            &model,
            &"--plane",
            &"1,0,0,0",
            &"-o",
            &out,
            &"--tolerance",
            &t,
        ]);
        assert!(e.contains("tolerance"), "{e}");
    }
    let e = fails(&[
        &"nurbs",
        &"slice",
        &model,
        &"--plane",
        &"1,0,0,0",
        &"-o",
        &dir.path().join("o.stl"),
    ]);
    assert!(e.contains(".ply or .obj"), "{e}");
    assert!(!out.exists());
    let e = fails(&[&"nurbs", &"eval", &model, &"--at", &"2,0,0"]);
    assert!(e.contains("cannot evaluate"), "{e}");
    let e = fails(&[
        &"nurbs",
        &"eval",
        &dir.path().join("missing.json"),
        &"--at",
        &"0,0,0",
    ]);
    assert!(e.contains("missing.json"), "{e}");
    let src = dir.path().join("sphere_sdf.nii");
    let e = fails(&[
        &"nurbs",
        &"fit",
        &src,
        &"-o",
        &dir.path().join("m.json"),
        &"--control-points",
        &"40",
    ]);
    assert!(e.contains("exceed"), "{e}");
    let e = fails(&[
        &"nurbs",
        &"fit",
        &src,
        &"-o",
        &dir.path().join("m.json"),
        &"--control-points",
        &"2",
    ]);
    assert!(e.contains("too few"), "{e}");
}

#[test]
fn nurbs_trace_optics_grin_lens_reports_focal_length_and_writes_paths() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("grin.png");
    let obj = dir.path().join("grin.obj");
    let text = ok(&[
        &"nurbs",
        &"trace-optics",
        &"--example",
        &"grin-lens",
        &"--rays",
        &"5",
        &"--size",
        &"120x80",
        &"-o",
        &png,
        &"--paths",
        &obj,
    ]);
    assert!(
        text.contains("paraxial back focal distance 1.10333"),
        "{text}"
    );
    // The measured distance is printed with its deviations from the exact trace and from the
    // paraxial formula (spherical aberration at the probe height: about −0.013 %).
    assert!(
        percent_before(&text, "% from the exact trace").abs() < 0.05,
        "{text}"
    );
    assert!(
        percent_before(&text, "% from paraxial").abs() < 2.0,
        "{text}"
    );
    let img = volmorph_render_png_size(&png);
    assert_eq!(img, (120, 80));
    let obj_text = std::fs::read_to_string(&obj).unwrap();
    assert_eq!(obj_text.lines().filter(|l| l.starts_with("l ")).count(), 5);
    // Bad input: no model, unknown example, zero rays, missing attribute.
    let err = fails(&[&"nurbs", &"trace-optics", &"-o", &png]);
    assert!(err.contains("--example"), "{err}");
    let err = fails(&[
        &"nurbs",
        &"trace-optics",
        &"--example",
        &"teapot",
        &"-o",
        &png,
    ]);
    assert!(err.contains("grin-lens"), "{err}");
    let err = fails(&[
        &"nurbs",
        &"trace-optics",
        &"--example",
        &"grin-lens",
        &"--rays",
        &"0",
        &"-o",
        &png,
    ]);
    assert!(err.contains("--rays"), "{err}");
    let err = fails(&[
        &"nurbs",
        &"trace-optics",
        &"--example",
        &"grin-lens",
        &"--attribute",
        &"density",
        &"-o",
        &png,
    ]);
    assert!(err.contains("density"), "{err}");
}

/// Width and height of a PNG file, from its IHDR chunk.
fn volmorph_render_png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[1..4], b"PNG");
    let w = u32::from_be_bytes([b[16], b[17], b[18], b[19]]);
    let h = u32::from_be_bytes([b[20], b[21], b[22], b[23]]);
    (w, h)
}

#[test]
fn nurbs_example_and_render_write_a_picture() {
    let dir = tempfile::tempdir().unwrap();
    let lens = dir.path().join("lens.json");
    ok(&[&"nurbs", &"example", &"grin-lens", &"-o", &lens]);
    assert!(lens.exists());
    let png = dir.path().join("lens.png");
    let text = ok(&[
        &"nurbs",
        &"render",
        &lens,
        &"--attribute",
        &"eta",
        &"--size",
        &"24x16",
        &"--step",
        &"0.05",
        &"-o",
        &png,
    ]);
    assert!(text.contains("rendered"), "{text}");
    assert_eq!(volmorph_render_png_size(&png), (24, 16));
    let bad = dir.path().join("bad.png");
    let err = fails(&[
        &"nurbs",
        &"render",
        &lens,
        &"--attribute",
        &"density",
        &"-o",
        &bad,
    ]);
    assert!(err.contains("density"), "{err}");
    let err = fails(&[
        &"nurbs",
        &"render",
        &lens,
        &"--attribute",
        &"eta",
        &"--transfer",
        &"0:1,1",
        &"-o",
        &bad,
    ]);
    assert!(err.contains("transfer"), "{err}");
    let err = fails(&[
        &"nurbs",
        &"render",
        &"missing.json",
        &"--attribute",
        &"eta",
        &"-o",
        &bad,
    ]);
    assert!(err.contains("missing.json"), "{err}");
    assert!(!bad.exists());
}

#[test]
fn render_draws_a_volume_deformed_turning_and_compared() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let vol = d.join("teapot.nii.gz");
    ok(&[&"phantom", &"teapot", &"-o", &vol, &"--size", &"40"]);
    let tf = "0:0,0,0,0; 120:0,0,0,0; 128:0.9,0.8,0.7,0.8; 255:1,1,1,1";
    let plain = d.join("plain.png");
    let out = ok(&[
        &"render",
        &vol,
        &"-o",
        &plain,
        &"--transfer",
        &tf,
        &"--size",
        &"48x40",
        &"--view",
        &"30,20",
    ]);
    assert!(out.contains("rendered"), "{out}");
    let img = volmorph_render::read_png(&plain).unwrap();
    assert_eq!((img.width(), img.height()), (48, 40));
    assert_eq!(img.get(0, 0), Some([0, 0, 0, 255]), "corner not background");
    // The 40³ teapot fills about a fifth of the framed box's width: some 80 pixels.
    assert!(
        img.pixels().iter().filter(|p| p[0] > 60).count() > 40,
        "teapot not drawn"
    );
    // Deformed by handles (a shift of the spout region): a different picture.
    let handles = d.join("moves.json");
    std::fs::write(
        &handles,
        r#"{"points": [
            {"source": [0.7, 0.0, 0.2], "target": [0.7, 0.0, -0.1]},
            {"source": [-0.6, 0.0, 0.0], "target": [-0.6, 0.0, 0.0]},
            {"source": [0.0, 0.6, 0.0], "target": [0.0, 0.6, 0.0]},
            {"source": [0.0, -0.6, 0.0], "target": [0.0, -0.6, 0.0]},
            {"source": [0.0, 0.0, 0.6], "target": [0.0, 0.0, 0.6]}]}"#,
    )
    .unwrap();
    let bent = d.join("bent.png");
    ok(&[
        &"render",
        &vol,
        &"-o",
        &bent,
        &"--transfer",
        &tf,
        &"--size",
        &"48x40",
        &"--view",
        &"30,20",
        &"--handles",
        &handles,
        &"--method",
        &"affine",
        &"--grid",
        &"9",
    ]);
    assert_ne!(volmorph_render::read_png(&bent).unwrap(), img);
    // A turntable: frames and an animated PNG.
    let spin = d.join("spin");
    ok(&[
        &"render",
        &vol,
        &"-o",
        &spin,
        &"--frames",
        &"3",
        &"--size",
        &"24",
        &"--mode",
        &"mip",
    ]);
    for f in ["frame0000.png", "frame0002.png", "turntable.png"] {
        assert!(spin.join(f).is_file(), "{f} missing");
    }
    let apng = std::fs::read(spin.join("turntable.png")).unwrap();
    assert!(apng.windows(4).any(|w| w == b"acTL"), "not animated");
    // The quality view of a volume against itself is green.
    let q = d.join("quality.png");
    ok(&[
        &"render",
        &"--compare",
        &vol,
        &vol,
        &"-o",
        &q,
        &"--size",
        &"32",
    ]);
    let img = volmorph_render::read_png(&q).unwrap();
    assert!(img.pixels().iter().all(|p| p[0] <= 1 && p[2] <= 1));
    assert!(img.pixels().iter().any(|p| p[1] > 30));
    // An isosurface, the transfer function saved for other tools.
    let tfj = d.join("tf.json");
    ok(&[
        &"render",
        &vol,
        &"-o",
        &d.join("iso.png"),
        &"--mode",
        &"iso",
        &"--level",
        &"127",
        &"--size",
        &"24",
        &"--save-transfer",
        &tfj,
        &"--transfer",
        &"ct-bone",
    ]);
    let saved = volmorph_render::TransferFunction::read(&tfj).unwrap();
    assert_eq!(saved.name(), Some("ct-bone"));
    // Bad input is a clear error.
    let e = fails(&[&"render", &vol, &"-o", &d.join("x.jpg")]);
    assert!(e.contains(".png"), "{e}");
    let e = fails(&[&"render", &vol, &"-o", &plain, &"--transfer", &"bone"]);
    assert!(e.contains("ct-bone"), "{e}");
    let e = fails(&[&"render", &vol, &"-o", &plain, &"--clip", &"1,2,3"]);
    assert!(e.contains("X,Y,Z,NX,NY,NZ"), "{e}");
    let e = fails(&[&"render", &d.join("missing.nii"), &"-o", &plain]);
    assert!(e.contains("missing.nii"), "{e}");
}

/// Issue 15 item 10: `--quiet` is taken by every command, before or after the subcommand, and
/// leaves standard error empty on success (results still go to standard output).
#[test]
fn quiet_flag_is_global_and_silences_progress() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.nii");
    for args in [
        vec!["--quiet", "phantom", "sphere", "--size", "12", "-o"],
        vec!["phantom", "sphere", "-q", "--size", "12", "-o"],
    ] {
        let mut full: Vec<&dyn AsRef<std::ffi::OsStr>> = args
            .iter()
            .map(|a| a as &dyn AsRef<std::ffi::OsStr>)
            .collect();
        full.push(&p);
        let out = volmorph(&full);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            out.stderr.is_empty(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(p.exists());
    }
    let text = ok(&[&"info", &"-q", &p]);
    assert!(text.contains("12 x 12 x 12"), "{text}");
}

/// Issue 14 item 10: `warp`, `drag` and `jacobian` said "cannot read lattice: …" without the
/// path of the lattice.
#[test]
fn warp_drag_jacobian_say_cannot_read_lattice_without_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("s.nii");
    ok(&[&"phantom", &"sphere", &"--size", &"10", &"-o", &vol]);
    let bad = dir.path().join("broken_lattice.json");
    std::fs::write(&bad, "{\"bad\": 1}").unwrap();
    let out = dir.path().join("o.nii");
    for err in [
        fails(&[&"warp", &vol, &"--lattice", &bad, &"-o", &out]),
        fails(&[
            &"drag",
            &vol,
            &"--lattice",
            &bad,
            &"--from",
            &"0,0,0",
            &"--to",
            &"0.1,0,0",
            &"-o",
            &out,
        ]),
        fails(&[
            &"jacobian",
            &"--lattice",
            &bad,
            &"--grid",
            &vol,
            &"-o",
            &out,
        ]),
    ] {
        assert!(err.contains("broken_lattice.json"), "{err}");
        assert!(err.contains("version"), "names the field: {err}");
    }
    assert!(!out.exists());
}

/// The relative deviation (in %) printed after `label` in `text`, e.g. "+1.2e-8 % from".
fn percent_before(text: &str, label: &str) -> f64 {
    let head = text
        .split(label)
        .next()
        .unwrap_or_else(|| panic!("no {label:?} in {text}"));
    head.rsplit(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no percentage before {label:?} in {text}"))
}

#[test]
fn nurbs_trace_optics_methods_report_their_control_and_accuracy() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("grin.png");
    let run = |extra: &[&str]| {
        let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
            &"nurbs",
            &"trace-optics",
            &"--example",
            &"grin-lens",
            &"--rays",
            &"3",
            &"--size",
            &"60x40",
            &"-o",
            &png,
        ];
        for e in extra {
            args.push(e);
        }
        ok(&args)
    };
    // The default: Dormand–Prince with error control, within 0.05 % of the exact trace.
    let text = run(&[]);
    assert!(text.contains("by rk45 (tolerance 1e-9"), "{text}");
    assert!(text.contains("steps by rk45)"), "{text}");
    let rk = percent_before(&text, "% from the exact trace");
    assert!(rk.abs() < 0.05, "{text}");
    assert!(rk.abs() < 1e-5, "{text}");
    // Loose tolerance, no step cap: few steps, still close.
    let text = run(&["--step", "10", "--tolerance", "1e-6"]);
    assert!(text.contains("tolerance 1e-6"), "{text}");
    assert!(
        percent_before(&text, "% from the exact trace").abs() < 0.05,
        "{text}"
    );
    // The first-order forms, with their step.
    let text = run(&["--method", "ray-equation", "--step", "0.005"]);
    assert!(text.contains("by ray-equation (step ≤ 0.00500"), "{text}");
    let re = percent_before(&text, "% from the exact trace");
    assert!(re > 0.05 && re < 0.3, "{text}");
    let text = run(&["--method", "snell"]);
    assert!(
        percent_before(&text, "% from the exact trace") > 5.0,
        "{text}"
    );
    // An unknown method is a usage error (clap: exit status 2) naming the choices.
    let out = volmorph(&[
        &"nurbs",
        &"trace-optics",
        &"--example",
        &"grin-lens",
        &"--method",
        &"euler",
        &"-o",
        &png,
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("snell, ray-equation or rk45"),
        "{err}"
    );
    for bad in [
        ["--tolerance", "0"],
        ["--step", "0"],
        ["--tolerance", "nan"],
    ] {
        let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
            &"nurbs",
            &"trace-optics",
            &"--example",
            &"grin-lens",
            &"-o",
            &png,
        ];
        args.push(&bad[0]);
        args.push(&bad[1]);
        let err = fails(&args);
        assert!(err.contains(bad[0]) || err.contains(bad[1]), "{err}");
    }
}

#[test]
fn nurbs_model_builds_the_grin_lens_example_from_its_recipe() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let lens = d.join("lens.json");
    let recipe = d.join("recipe.json");
    let built = d.join("built.json");
    ok(&[&"nurbs", &"example", &"grin-lens", &"-o", &lens]);
    ok(&[&"nurbs", &"example", &"grin-lens-recipe", &"-o", &recipe]);
    let text = ok(&[&"nurbs", &"model", &recipe, &"-o", &built]);
    assert!(
        text.contains("built a volume with attributes [\"eta\"]"),
        "{text}"
    );
    assert_eq!(
        std::fs::read(&lens).unwrap(),
        std::fs::read(&built).unwrap()
    );
    // The recipe documented in the README builds the same file.
    let documented =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/nurbs/grin_lens_recipe.json");
    let built2 = d.join("built2.json");
    ok(&[&"nurbs", &"model", &documented, &"-o", &built2]);
    assert_eq!(
        std::fs::read(&lens).unwrap(),
        std::fs::read(&built2).unwrap()
    );
    // A bad field: the message names the file and the JSON path; nothing is written.
    let bad = d.join("bad_recipe.json");
    let text = std::fs::read_to_string(&recipe)
        .unwrap()
        .replace("\"angle_degrees\": 360.0", "\"angle_degrees\": 0.0");
    assert!(text.contains("\"angle_degrees\": 0.0"), "{text}");
    std::fs::write(&bad, text).unwrap();
    let out = d.join("never.json");
    let err = fails(&[&"nurbs", &"model", &bad, &"-o", &out]);
    assert!(
        err.contains("bad_recipe.json") && err.contains("steps[2].revolve.angle_degrees"),
        "{err}"
    );
    std::fs::write(&bad, r#"{"format": "volmorph-nurbs-recipe", "version": 1, "steps": [{"curve": {"name": "p", "degree": "x", "points": []}}], "result": "p"}"#).unwrap();
    let err = fails(&[&"nurbs", &"model", &bad, &"-o", &out]);
    assert!(err.contains("steps[0].curve.degree"), "{err}");
    assert!(!out.exists());
    // The model renders and the curve-only recipe writes a curve.
    std::fs::write(&bad, r#"{"format": "volmorph-nurbs-recipe", "version": 1, "steps": [{"curve": {"name": "p", "degree": 1, "points": [[0,0,0],[1,0,0]]}}], "result": "p"}"#).unwrap();
    let text = ok(&[&"nurbs", &"model", &bad, &"-o", &out]);
    assert!(text.contains("built a curve"), "{text}");
}

#[test]
fn nurbs_render_composites_several_models_in_one_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let recipe = |name: &str, x0: f64, index: f64| {
        let p = d.join(format!("{name}_recipe.json"));
        std::fs::write(
            &p,
            format!(
                r#"{{"format": "volmorph-nurbs-recipe", "version": 1, "result": "box", "steps": [
                {{"curve": {{"name": "edge", "degree": 1, "points": [[{x0},0,0],[{x1},0,0]]}}}},
                {{"attach": {{"name": "a", "to": "edge", "attribute": "d", "spline": {{"degree": 0, "values": [{index}]}}}}}},
                {{"extrude": {{"name": "sheet", "of": "a", "direction": [0, 1, 0]}}}},
                {{"extrude": {{"name": "box", "of": "sheet", "direction": [0, 0, 1]}}}}]}}"#,
                x1 = x0 + 1.0
            ),
        )
        .unwrap();
        let m = d.join(format!("{name}.json"));
        ok(&[&"nurbs", &"model", &p, &"-o", &m]);
        m
    };
    let a = recipe("a", 0.0, 1.0);
    let b = recipe("b", 3.0, 2.0);
    let (ab, ba) = (d.join("ab.png"), d.join("ba.png"));
    let common: [&dyn AsRef<std::ffi::OsStr>; 6] =
        [&"--size", &"40x24", &"--view", &"front", &"--step", &"0.05"];
    let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
        &"nurbs",
        &"render",
        &a,
        &"--add",
        &b,
        &"--attribute",
        &"d",
        &"--transfer",
        &"1:1,0,0,0.9",
        &"--transfer",
        &"2:0,0,1,0.9",
        &"-o",
        &ab,
    ];
    args.extend(common);
    let text = ok(&args);
    assert!(text.contains("a.json") && text.contains("b.json"), "{text}");
    // The list order does not matter, only depth.
    let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
        &"nurbs",
        &"render",
        &b,
        &"--add",
        &a,
        &"--attribute",
        &"d",
        &"--transfer",
        &"2:0,0,1,0.9",
        &"--transfer",
        &"1:1,0,0,0.9",
        &"-o",
        &ba,
    ];
    args.extend(common);
    ok(&args);
    assert_eq!(std::fs::read(&ab).unwrap(), std::fs::read(&ba).unwrap());
    assert_eq!(volmorph_render_png_size(&ab), (40, 24));
    // Attribute or transfer lists that do not match the models are refused.
    let err = fails(&[
        &"nurbs",
        &"render",
        &a,
        &"--add",
        &b,
        &"--add",
        &a,
        &"--attribute",
        &"d",
        &"--attribute",
        &"d",
        &"-o",
        &ab,
    ]);
    assert!(
        err.contains("--attribute given 2 times for 3 models"),
        "{err}"
    );
}

#[test]
fn feng_forward_mapping_warps_the_mesh_and_the_identity_forms_do_not() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cube = d.join("cube.obj");
    std::fs::write(&cube, FFD_CUBE_OBJ).unwrap();
    let verts = |p: &Path| -> Vec<[f64; 3]> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .filter_map(|l| l.strip_prefix("v "))
            .map(|l| {
                let v: Vec<f64> = l
                    .split_whitespace()
                    .take(3)
                    .map(|t| t.parse().unwrap())
                    .collect();
                [v[0], v[1], v[2]]
            })
            .collect()
    };
    let run = |form: &str| {
        let out = d.join(format!("{form}.obj"));
        ok(&[
            &"ffd",
            &cube,
            &"--init",
            &form,
            &"--degree",
            &"2,2,1",
            &"--size",
            &"4,4,2",
            &"--mode",
            &"uniform:2",
            &"-o",
            &out,
        ]);
        verts(&out)
    };
    let same = run("end-interpolating");
    let uniform = run("uniform");
    let warped = run("forward");
    assert_eq!(same.len(), warped.len());
    let on_grid = |x: f64| ((4.0 * x).round() - 4.0 * x).abs() < 1e-12;
    assert!(same.iter().chain(&uniform).flatten().all(|&x| on_grid(x)));
    let mut moved = 0;
    for (p, q) in same.iter().zip(&warped) {
        for a in 0..3 {
            let dx = q[a] - p[a];
            // Towards the centre plane x = 0.5; never along the degree-1 (Bézier) axis z.
            assert!(dx * (0.5 - p[a]) >= -1e-12, "{p:?} -> {q:?}");
            if a == 2 {
                assert!(dx.abs() < 1e-12);
            }
            moved += usize::from(dx.abs() > 1e-3);
        }
    }
    assert!(moved > 10, "{moved}");
    // lattice init says which form it wrote; --init and --lattice exclude each other.
    let lat = d.join("fwd.json");
    let text = ok(&[
        &"lattice",
        &"init",
        &"--mesh",
        &cube,
        &"--form",
        &"forward",
        &"--degree",
        &"2,2,1",
        &"--size",
        &"4,4,2",
        &"-o",
        &lat,
    ]);
    assert!(text.contains("forward-mapped (not the identity"), "{text}");
    let out = d.join("x.obj");
    let o = volmorph(&[
        &"ffd",
        &cube,
        &"--lattice",
        &lat,
        &"--init",
        &"forward",
        &"-o",
        &out,
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--init"), "{err}");
    assert!(!out.exists());
    // The lattice file gives the same warp as --init forward.
    let via_file = d.join("via_file.obj");
    ok(&[
        &"ffd",
        &cube,
        &"--lattice",
        &lat,
        &"--mode",
        &"uniform:2",
        &"-o",
        &via_file,
    ]);
    assert_eq!(verts(&via_file), warped);
}

#[test]
fn tps_kernels_interpolate_differ_and_round_trip_through_map_json() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Handles on a bent grid (not coplanar), each moved differently.
    let mut pairs = Vec::new();
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..2 {
                let p = [
                    f64::from(i),
                    f64::from(j),
                    f64::from(k) + 0.1 * f64::from(i * j),
                ];
                let q = [
                    p[0] + 0.1 * p[1],
                    p[1] - 0.05 * p[2] * p[0],
                    p[2] + 0.2 * (p[0] - 1.0).powi(2),
                ];
                pairs.push((p, q));
            }
        }
    }
    let h = d.join("h.json");
    let json: Vec<String> = pairs
        .iter()
        .map(|(p, q)| format!(r#"{{"source": {p:?}, "target": {q:?}}}"#))
        .collect();
    std::fs::write(&h, format!(r#"{{"points": [{}]}}"#, json.join(", "))).unwrap();
    let src = d.join("src.txt");
    let text: String = pairs
        .iter()
        .map(|(p, _)| format!("{} {} {}\n", p[0], p[1], p[2]))
        .collect();
    std::fs::write(&src, text).unwrap();
    let probe = d.join("probe.txt");
    std::fs::write(&probe, "0.5 0.5 0.5\n1.7 0.2 1.3\n2.5 2.5 -0.5\n").unwrap();
    let read = |p: &Path| -> Vec<f64> {
        std::fs::read_to_string(p)
            .unwrap()
            .split_whitespace()
            .map(|t| t.parse().unwrap())
            .collect()
    };
    let apply = |kernel: &str, pts: &Path, name: &str| {
        let out = d.join(name);
        ok(&[
            &"handles",
            &"apply",
            &pts,
            &"--handles",
            &h,
            &"--method",
            &"tps",
            &"--kernel",
            &kernel,
            &"-o",
            &out,
        ]);
        read(&out)
    };
    let want: Vec<f64> = pairs.iter().flat_map(|(_, q)| *q).collect();
    for kernel in ["r", "r2logr"] {
        let got = apply(kernel, &src, &format!("src_{kernel}.txt"));
        for (a, b) in got.iter().zip(&want) {
            assert!((a - b).abs() < 1e-9, "{kernel}: {a} vs {b}");
        }
    }
    let pr = apply("r", &probe, "pr.txt");
    let pl = apply("r2logr", &probe, "pl.txt");
    let diff = pr
        .iter()
        .zip(&pl)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(diff > 1e-3, "{diff}");
    // The kernel is a field of the thin-plate map JSON: a file written by hand with it maps
    // like the handles.
    let map = d.join("tps.json");
    let sources: Vec<String> = pairs.iter().map(|(p, _)| format!("{p:?}")).collect();
    let targets: Vec<String> = pairs.iter().map(|(_, q)| format!("{q:?}")).collect();
    std::fs::write(
        &map,
        format!(
            r#"{{"version": 1, "kind": "thin-plate", "smoothing": 0, "kernel": "r2logr", "sources": [{}], "targets": [{}]}}"#,
            sources.join(", "),
            targets.join(", ")
        ),
    )
    .unwrap();
    let out = d.join("mapped.txt");
    ok(&[&"map", &"apply", &map, &probe, &"-o", &out]);
    for (a, b) in read(&out).iter().zip(&pl) {
        assert!((a - b).abs() < 1e-12, "{a} vs {b}");
    }
    let bad = std::fs::read_to_string(&map)
        .unwrap()
        .replace("r2logr", "r3");
    std::fs::write(&map, bad).unwrap();
    let err = fails(&[&"map", &"apply", &map, &probe, &"-o", &out]);
    assert!(err.contains("r3"), "{err}");
    // The kernel choice belongs to tps; mls2d (2-D) takes only r² log r.
    let err = fails(&[
        &"handles",
        &"apply",
        &probe,
        &"--handles",
        &h,
        &"--method",
        &"rigid",
        &"--kernel",
        &"r2logr",
        &"-o",
        &out,
    ]);
    assert!(err.contains("--kernel"), "{err}");
    let png = d.join("p.png");
    let err = fails(&[
        &"mls2d",
        &png,
        &"--handles",
        &h,
        &"--method",
        &"tps",
        &"--kernel",
        &"r",
        &"-o",
        &d.join("warped.png"),
    ]);
    assert!(err.contains("r² log r"), "{err}");
}

/// Sizes a user gives that no memory budget can hold are refused with an error (exit 1)
/// before anything is allocated, never an abort in the allocator: the F-rep grids, the SDF
/// phantom, lattices around a mesh or a volume, and the drag's lattice (each under a 256 MB
/// budget).
#[test]
fn user_sizes_beyond_the_memory_budget_abort_in_the_allocator() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    let (hf, vol, mesh) = (d("ball.hf"), d("s.nii"), d("s.obj"));
    std::fs::write(&hf, FREP_BALL).unwrap();
    ok(&[&"phantom", &"sphere", &"-o", &vol, &"--size", &"16"]);
    ok(&[&"isosurface", &vol, &"--level", &"127", &"-o", &mesh]);
    let out = d("out.nii");
    let cases: [&[&str]; 6] = [
        &["frep", "eval", &hf, "--grid", "2000", "-o", &out],
        &["frep", "mesh", &hf, "--grid", "2048", "-o", &d("m.obj")],
        &[
            "phantom", "sphere", "--kind", "sdf", "--size", "2000", "-o", &out,
        ],
        &[
            "lattice",
            "init",
            "--mesh",
            &mesh,
            "--size",
            "700,700,700",
            "-o",
            &d("a.json"),
        ],
        &[
            "lattice",
            "init",
            &vol,
            "--counts",
            "1000,1000,1000",
            "-o",
            &d("b.json"),
        ],
        &[
            "drag",
            &vol,
            "--from",
            "0,0,0",
            "--to",
            "0.1,0,0",
            "--counts",
            "700,700,700",
            "-o",
            &out,
        ],
    ];
    for case in cases {
        let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = case
            .iter()
            .map(|a| a as &dyn AsRef<std::ffi::OsStr>)
            .collect();
        args.extend([&"--memory-limit" as &dyn AsRef<std::ffi::OsStr>, &"256M"]);
        let err = fails(&args);
        assert!(
            err.contains("memory") || err.contains("limit") || err.contains("at most"),
            "{case:?}: {err}"
        );
    }
    let written = std::fs::read_dir(dir.path()).unwrap().count();
    assert_eq!(written, 3, "only the inputs are in the folder");
}
