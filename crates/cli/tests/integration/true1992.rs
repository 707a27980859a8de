//! End-to-end tests of the True & Hughes 1992 capabilities of the `volmorph` binary: skewed
//! lattices, padded output geometry, the drag tool (shapes, realms, curve drags) and the tree
//! phantom.

use crate::common;

use common::{fails, ok, volmorph};

fn json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A skewed lattice from `lattice init --corner --edge` is written with its frame flagged
/// skewed, survives ITK `.tfm` both ways and is refused by `.bxf` with a clear error.
#[test]
fn lattice_init_on_a_parallelepiped_writes_a_skewed_lattice() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let lat = d.join("skewed.json");
    let text = ok(&[
        &"lattice",
        &"init",
        &"--corner",
        &"-2,0,1",
        &"--edge",
        &"30,0,0",
        &"--edge",
        &"10,28,0",
        &"--edge",
        &"0,-6,26",
        &"--counts",
        &"6,5,4",
        &"-o",
        &lat,
    ]);
    assert!(text.contains("skewed"), "{text}");
    let j = json(&lat);
    assert_eq!(j["frame"]["skewed"], true);
    assert_eq!(j["counts"], serde_json::json!([6, 5, 4]));
    let tfm = d.join("skewed.tfm");
    ok(&[&"lattice", &"convert", &lat, &"-o", &tfm]);
    let back = d.join("back.json");
    ok(&[&"lattice", &"convert", &tfm, &"-o", &back]);
    let b = json(&back);
    assert_eq!(b["frame"]["skewed"], true);
    let flat = |v: &serde_json::Value| -> Vec<f64> {
        v["control_points"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|p| p.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
            .collect()
    };
    let (a, c) = (flat(&j), flat(&b));
    assert_eq!(a.len(), c.len());
    assert!(a.iter().zip(&c).all(|(x, y)| (x - y).abs() < 1e-9));
    let err = fails(&[&"lattice", &"convert", &lat, &"-o", &d.join("s.bxf")]);
    assert!(err.contains("skewed"), "{err}");
    // Coplanar edges are a degenerate parallelepiped.
    let err = fails(&[
        &"lattice",
        &"init",
        &"--corner",
        &"0,0,0",
        &"--edge",
        &"30,0,0",
        &"--edge",
        &"0,30,0",
        &"--edge",
        &"30,30,0",
        &"-o",
        &d.join("flat.json"),
    ]);
    assert!(err.contains("degenerate"), "{err}");
}

fn dims(path: &std::path::Path) -> serde_json::Value {
    let j: serde_json::Value = serde_json::from_str(&ok(&[&"info", &"--json", &path])).unwrap();
    j["dims"].clone()
}

fn control_points(path: &std::path::Path) -> Vec<[f64; 3]> {
    json(path)["control_points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let v: Vec<f64> = p
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// True 1992 §5.1 from the CLI: `--pad`, `--output-geometry` and `--like` on `warp`.
#[test]
fn warp_writes_padded_and_explicit_output_grids() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = d.join("s.nii.gz");
    ok(&[&"phantom", &"sphere", &"--dims", &"20,16,12", &"-o", &src]);
    let lat = d.join("l.json");
    ok(&[
        &"lattice",
        &"init",
        &src,
        &"--counts",
        &"5,5,5",
        &"-o",
        &lat,
    ]);
    let out = d.join("padded.nii.gz");
    ok(&[&"warp", &src, &"--map", &lat, &"-o", &out, &"--pad", &"4"]);
    assert_eq!(dims(&out), serde_json::json!([28, 24, 20]));
    ok(&[
        &"warp",
        &src,
        &"--map",
        &lat,
        &"-o",
        &out,
        &"--pad",
        &"0,0,0,6,0,2",
    ]);
    assert_eq!(dims(&out), serde_json::json!([26, 16, 14]));
    let g = d.join("g.nii.gz");
    ok(&[
        &"warp",
        &src,
        &"--map",
        &lat,
        &"-o",
        &g,
        &"--output-geometry",
        &"10,11,12;0.2,0.2,0.2;-1,-1,-1",
    ]);
    assert_eq!(dims(&g), serde_json::json!([10, 11, 12]));
    let like = d.join("like.nii.gz");
    ok(&[&"warp", &src, &"--map", &lat, &"-o", &like, &"--like", &g]);
    assert_eq!(dims(&like), serde_json::json!([10, 11, 12]));
    let err = fails(&[&"warp", &src, &"--map", &lat, &"-o", &out, &"--pad", &"1.5"]);
    assert!(err.contains("padding"), "{err}");
    let err = fails(&[
        &"warp",
        &src,
        &"--map",
        &lat,
        &"-o",
        &out,
        &"--pad",
        &"100000000",
    ]);
    assert!(err.contains("output grid"), "{err}");
}

/// The §6 tool from the CLI: a box tool inside a realm on a padded grid; control points
/// outside the realm stay where the identity lattice has them.
#[test]
fn drag_with_a_box_tool_and_a_realm_moves_only_realm_control_points() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = d.join("s.nii.gz");
    ok(&[&"phantom", &"sphere", &"--dims", &"24,24,24", &"-o", &src]);
    let identity = d.join("id.json");
    ok(&[
        &"lattice",
        &"init",
        &src,
        &"--counts",
        &"9,9,9",
        &"-o",
        &identity,
    ]);
    let (out, moved) = (d.join("o.nii.gz"), d.join("moved.json"));
    ok(&[
        &"drag",
        &src,
        &"--from",
        &"0.5,0,0",
        &"--to",
        &"0.6,0.05,0",
        &"--tool",
        &"box:0.6,0.6,0.6",
        &"--realm",
        &"indices:4,2,2,7,6,6",
        &"--pad",
        &"3",
        &"-o",
        &out,
        &"--lattice-out",
        &moved,
    ]);
    assert_eq!(dims(&out), serde_json::json!([30, 30, 30]));
    let (a, b) = (control_points(&identity), control_points(&moved));
    let mut changed = 0;
    for (n, (p, q)) in a.iter().zip(&b).enumerate() {
        let idx = [n % 9, n / 9 % 9, n / 81];
        let inside =
            idx[0] >= 4 && idx[0] <= 7 && (2..=6).contains(&idx[1]) && (2..=6).contains(&idx[2]);
        if p != q {
            changed += 1;
            assert!(inside, "control point {idx:?} outside the realm moved");
        }
    }
    assert!(changed > 0);
    // A bad tool is a usage error naming the option.
    let bad = volmorph(&[
        &"drag", &src, &"--from", &"0.5,0,0", &"--to", &"0.6,0,0", &"--tool", &"cone:1", &"-o",
        &out,
    ]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(bad.status.code(), Some(2), "{err}");
    assert!(err.contains("--tool") && !err.contains("panicked"), "{err}");
    // A realm away from the dragged point leaves nothing to move: exit 1, clear message.
    let err = fails(&[
        &"drag",
        &src,
        &"--from",
        &"0.5,0,0",
        &"--to",
        &"0.6,0,0",
        &"--realm",
        &"indices:0,0,0,1,1,1",
        &"-o",
        &out,
    ]);
    assert!(err.contains("realm"), "{err}");
}

/// §6.3 from the CLI: a curve drag writes one frame per step and ends on the goal curve.
#[test]
fn drag_along_a_curve_writes_every_frame_and_ends_on_the_goal() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = d.join("s.nii.gz");
    ok(&[&"phantom", &"sphere", &"--dims", &"24,24,24", &"-o", &src]);
    let (out, moved, frames) = (d.join("o.nii.gz"), d.join("m.json"), d.join("frames"));
    let text = ok(&[
        &"drag",
        &src,
        &"--start-curve",
        &"-0.5,0,0;0,0,0;0.5,0,0",
        &"--goal-curve",
        &"-0.5,0.1,0;0,0.25,0;0.5,0.1,0",
        &"--steps",
        &"4",
        &"--frames",
        &frames,
        &"-o",
        &out,
        &"--lattice-out",
        &moved,
        &"--radius",
        &"0.8",
    ]);
    assert!(text.contains("curve drag of 3 points in 4 steps"), "{text}");
    for n in 1..=4 {
        assert!(
            frames.join(format!("frame_{n:03}.nii.gz")).exists(),
            "frame {n}"
        );
    }
    assert!(!frames.join("frame_005.nii.gz").exists());
    // The final lattice sends the start curve (on the undeformed model, the identity
    // lattice's image) onto the goal curve.
    let Ok(volmorph_maps::AnyMap::Lattice(l)) = volmorph_maps::read_map(&moved) else {
        panic!("{} is not a lattice", moved.display());
    };
    use volmorph_deform::SpaceMap;
    let start = [[-0.5, 0.0, 0.0], [0.0, 0.0, 0.0], [0.5, 0.0, 0.0]];
    let goal = [[-0.5, 0.1, 0.0], [0.0, 0.25, 0.0], [0.5, 0.1, 0.0]];
    for (s, g) in start.iter().zip(&goal) {
        let p = l.apply(glam::DVec3::from_array(*s));
        assert!(
            (p - glam::DVec3::from_array(*g)).length() < 1e-6,
            "{p} vs {g:?}"
        );
    }
}

/// McPhail Fig. 4.2 from the CLI: `mls2d --method tps` deforms a picture through its handles
/// (the interpolation itself is tested in `volmorph_handles::mls2d`), and refuses too few.
#[test]
fn mls2d_thin_plate_method_deforms_a_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let vol = d.join("s.nii.gz");
    ok(&[&"phantom", &"teapot", &"--size", &"40", &"-o", &vol]);
    let png = d.join("s.png");
    ok(&[
        &"slice",
        &vol,
        &"-o",
        &png,
        &"--axis",
        &"z",
        &"--index",
        &"20",
        &"--zoom",
        &"1",
        &"--no-labels",
    ]);
    let h = d.join("h.json");
    std::fs::write(
        &h,
        r#"{"points": [{"source": [5, 5], "target": [7, 6]}, {"source": [34, 5], "target": [33, 7]},
            {"source": [20, 20], "target": [24, 18]}, {"source": [5, 34], "target": [5, 34]},
            {"source": [34, 34], "target": [34, 34]}]}"#,
    )
    .unwrap();
    let out = d.join("tps.png");
    let text = ok(&[
        &"mls2d",
        &png,
        &"--handles",
        &h,
        &"-o",
        &out,
        &"--method",
        &"tps",
    ]);
    assert!(text.contains("deformed") && out.exists(), "{text}");
    assert_ne!(std::fs::read(&out).unwrap(), std::fs::read(&png).unwrap());
    std::fs::write(&h, r#"{"points": [{"source": [5, 5], "target": [7, 6]}]}"#).unwrap();
    let err = fails(&[
        &"mls2d",
        &png,
        &"--handles",
        &h,
        &"-o",
        &out,
        &"--method",
        &"tps",
    ]);
    assert!(err.contains("at least 3"), "{err}");
}

/// `jacobian` takes any map kind and writes the map it used with `--map-out`: a skewed lattice
/// read back from the written map is the same lattice.
#[test]
fn jacobian_writes_the_map_it_used() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = d.join("s.nii.gz");
    ok(&[&"phantom", &"sphere", &"--dims", &"12,12,12", &"-o", &src]);
    let lat = d.join("skewed.json");
    ok(&[
        &"lattice",
        &"init",
        &"--corner",
        &"-1.5,-1.5,-1.5",
        &"--edge",
        &"3,0,0",
        &"--edge",
        &"0.8,3,0",
        &"--edge",
        &"0,0,3",
        &"--counts",
        &"5,5,5",
        &"-o",
        &lat,
    ]);
    let (j, used) = (d.join("j.nii.gz"), d.join("used.json"));
    let text = ok(&[
        &"jacobian",
        &"--map",
        &lat,
        &"--grid",
        &src,
        &"-o",
        &j,
        &"--map-out",
        &used,
    ]);
    assert!(j.exists() && text.contains("J"), "{text}");
    assert_eq!(control_points(&used), control_points(&lat));
    assert_eq!(json(&used)["frame"], json(&lat)["frame"]);
}

/// The push-forward (True §5.3–5.4) out of core, OME-Zarr to OME-Zarr, writes bit for bit the
/// store the in-memory warp of the same volume writes: antialiased on a padded grid with a
/// background, and nearest; the methods that do not chunk are refused naming those that do.
#[test]
fn out_of_core_push_forward_equals_the_in_memory_warp() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mha = d.join("s.mha");
    ok(&[&"phantom", &"sphere", &"--dims", &"41,37,33", &"-o", &mha]);
    let zarr = d.join("s.ome.zarr");
    ok(&[&"convert", &mha, &zarr, &"--chunk", &"9,7,11"]);
    let lat = d.join("l.json");
    ok(&[
        &"lattice",
        &"init",
        &mha,
        &"--counts",
        &"6,5,5",
        &"-o",
        &lat,
    ]);
    // Move every control point by a deterministic pseudo-random vector (a bend).
    let mut j = json(&lat);
    for (n, p) in j["control_points"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .enumerate()
    {
        for (a, c) in p.as_array_mut().unwrap().iter_mut().enumerate() {
            let t = ((n * 7 + a * 13) % 11) as f64 / 11.0 - 0.5;
            *c = serde_json::json!(c.as_f64().unwrap() + 0.35 * t);
        }
    }
    std::fs::write(&lat, j.to_string()).unwrap();
    for (method, extra) in [
        (
            "pushforward-antialiased",
            vec!["--pad", "3", "--default", "2"],
        ),
        ("pushforward-nearest", vec![]),
    ] {
        let in_memory = d.join(format!("{method}.mha"));
        let out_of_core = d.join(format!("{method}.ome.zarr"));
        let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
            &"warp",
            &mha,
            &"--map",
            &lat,
            &"--method",
            &method,
            &"-o",
            &in_memory,
        ];
        for e in &extra {
            args.push(e);
        }
        ok(&args);
        args[1] = &zarr;
        args[7] = &out_of_core;
        args.push(&"--chunk");
        args.push(&"8,13,6");
        ok(&args);
        let a = d.join(format!("{method}.a.raw"));
        let b = d.join(format!("{method}.b.raw"));
        ok(&[&"convert", &in_memory, &a]);
        ok(&[&"convert", &out_of_core, &b]);
        assert_eq!(dims(&in_memory), dims(&out_of_core), "{method}");
        let (a, b) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
        assert!(
            a == b,
            "{method}: the out-of-core store differs from the in-memory warp"
        );
    }
    let err = fails(&[
        &"warp",
        &zarr,
        &"--map",
        &lat,
        &"--method",
        &"inverse-linear",
        &"-o",
        &d.join("x.ome.zarr"),
    ]);
    assert!(err.contains("pushforward-antialiased"), "{err}");
    assert!(!d.join("x.ome.zarr").exists());
}

/// Components of the voxels above `level` connected through faces, within the index box
/// `lo..hi` (exclusive) of `v`.
fn components(
    v: &volmorph_volume::Volume<f32>,
    level: f32,
    lo: [usize; 3],
    hi: [usize; 3],
) -> usize {
    let [nx, ny, _] = v.dims();
    let idx = |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    let mut seen = vec![false; v.data().len()];
    let mut count = 0;
    let mut stack = Vec::new();
    for k in lo[2]..hi[2] {
        for j in lo[1]..hi[1] {
            for i in lo[0]..hi[0] {
                if seen[idx(i, j, k)] || v.data()[idx(i, j, k)] <= level {
                    continue;
                }
                count += 1;
                seen[idx(i, j, k)] = true;
                stack.push([i, j, k]);
                while let Some(p) = stack.pop() {
                    for (a, d) in [(0, -1), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)] {
                        let mut q = p;
                        let moved = q[a] as isize + d;
                        if moved < lo[a] as isize || moved >= hi[a] as isize {
                            continue;
                        }
                        q[a] = moved as usize;
                        let n = idx(q[0], q[1], q[2]);
                        if !seen[n] && v.data()[n] > level {
                            seen[n] = true;
                            stack.push(q);
                        }
                    }
                }
            }
        }
    }
    count
}

/// The tree of True & Hughes Figs. 13–14 from `volmorph phantom tree`: one connected solid
/// whose horizontal cuts cross one trunk, three limbs and six twigs where the model says; a
/// drag lifts a twig end to end (the grabbed point lands on its target, the tree stays one
/// piece).
#[test]
fn tree_phantom_has_its_branches_and_drags_end_to_end() {
    use common::{nearest, read_f32};
    use glam::DVec3;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tree = d.join("tree.nii.gz");
    ok(&[&"phantom", &"tree", &"-o", &tree, &"--size", &"48"]);
    let j: serde_json::Value = serde_json::from_str(&ok(&[&"info", &"--json", &tree])).unwrap();
    assert_eq!(j["dims"], serde_json::json!([48, 48, 48]));
    assert_eq!(j["voxel_type"], "u8");
    assert_eq!(j["stats"]["min"], 0.0);
    assert_eq!(j["stats"]["max"], 255.0);
    let v = read_f32(&tree);
    let level = 127.0;
    let solid = v.data().iter().filter(|&&x| x > level).count();
    // Trunk, limbs and twigs: about 0.15 model units³ of 2.2³/47³ each.
    assert!((900..2500).contains(&solid), "{solid} voxels");
    let n = 48;
    assert_eq!(components(&v, level, [0; 3], [n; 3]), 1);
    let slice = |z: f64| {
        let k = v
            .geometry()
            .physical_to_index(DVec3::new(0.0, 0.0, z))
            .z
            .round() as usize;
        components(&v, level, [0, 0, k], [n, n, k + 1])
    };
    assert_eq!(slice(-0.4), 1, "the trunk");
    assert_eq!(slice(0.075), 3, "the limbs");
    assert_eq!(slice(0.5), 6, "the twigs");

    // Lift a point near the tip of the first limb's second twig by 0.15.
    let from = DVec3::new(0.56, 0.356, 0.655);
    let to = from + DVec3::new(0.0, 0.0, 0.15);
    assert!(nearest(&v, from).unwrap() > level);
    assert!(nearest(&v, to).unwrap() < level);
    let (out, lat) = (d.join("dragged.nii.gz"), d.join("lat.json"));
    ok(&[
        &"drag",
        &tree,
        &"--from",
        &"0.56,0.356,0.655",
        &"--to",
        &"0.56,0.356,0.805",
        &"-o",
        &out,
        &"--lattice-out",
        &lat,
    ]);
    let w = read_f32(&out);
    assert_eq!(w.dims(), [48, 48, 48]);
    assert!(
        nearest(&w, to).unwrap() > level,
        "the twig reached its target"
    );
    assert_eq!(components(&w, level, [0; 3], [n; 3]), 1);
    // The trunk's foot is far from the drag and stays solid, the space beside it empty.
    let foot = DVec3::new(0.0, 0.0, -0.6);
    assert!(nearest(&w, foot).unwrap() > level);
    assert!(nearest(&w, foot + DVec3::new(0.3, 0.0, 0.0)).unwrap() < level);
    let moved = control_points(&lat);
    assert_eq!(moved.len(), 9 * 9 * 9);
}
