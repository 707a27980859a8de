//! End-to-end tests of the True & Hughes 1992 capabilities of the `volmorph` binary: skewed
//! lattices, padded output geometry, the drag tool (shapes, realms, curve drags) and the tree
//! phantom.

mod common;

use common::{fails, ok};

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
