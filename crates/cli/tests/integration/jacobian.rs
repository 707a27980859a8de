//! End-to-end tests of `volmorph jacobian` on the map kinds issue 16 names: thin-plate
//! splines and compositions of maps, written as map JSON by hand. The determinant map is 1
//! where the map is rigid, and agrees with central differences of the map as
//! `volmorph_maps` reads it.

use crate::common;

use std::path::Path;

use common::{ok, read_f32};
use glam::{DMat3, DVec3};
use volmorph_deform::SpaceMap;

/// Twelve handle sources around the phantoms' `[−1.1, 1.1]³` grid, not coplanar.
fn sources() -> Vec<DVec3> {
    let mut out = Vec::new();
    for k in 0..2 {
        for j in 0..2 {
            for i in 0..3 {
                out.push(DVec3::new(
                    -0.9 + 0.9 * f64::from(i),
                    -0.7 + 1.5 * f64::from(j) + 0.1 * f64::from(i),
                    -0.8 + 1.6 * f64::from(k) - 0.05 * f64::from(i * j),
                ));
            }
        }
    }
    out
}

fn points(ps: &[DVec3]) -> String {
    let v: Vec<String> = ps
        .iter()
        .map(|p| format!("[{:?}, {:?}, {:?}]", p.x, p.y, p.z))
        .collect();
    format!("[{}]", v.join(", "))
}

/// A thin-plate map JSON (interpolating, kernel `r`) sending each source to `f(source)`.
fn tps(f: impl Fn(DVec3) -> DVec3) -> String {
    let s = sources();
    let t: Vec<DVec3> = s.iter().map(|&p| f(p)).collect();
    format!(
        r#"{{"version": 1, "kind": "thin-plate", "smoothing": 0, "sources": {}, "targets": {}}}"#,
        points(&s),
        points(&t)
    )
}

/// A rotation by `angle` about `axis` followed by a translation: rigid.
fn rigid(angle: f64, axis: DVec3, shift: DVec3) -> impl Fn(DVec3) -> DVec3 {
    let r = DMat3::from_axis_angle(axis.normalize(), angle);
    move |p| r * p + shift
}

fn affine_json(m: DMat3, offset: DVec3) -> String {
    let row = |i: usize| format!("[{:?}, {:?}, {:?}]", m.row(i).x, m.row(i).y, m.row(i).z);
    format!(
        r#"{{"kind": "affine", "matrix": [{}, {}, {}], "offset": [{:?}, {:?}, {:?}]}}"#,
        row(0),
        row(1),
        row(2),
        offset.x,
        offset.y,
        offset.z
    )
}

/// `det` of the central difference of `map` at `p` with step `h`.
fn fd_determinant(map: &dyn SpaceMap, p: DVec3, h: f64) -> f64 {
    let col = |e: DVec3| (map.apply(p + h * e) - map.apply(p - h * e)) / (2.0 * h);
    DMat3::from_cols(col(DVec3::X), col(DVec3::Y), col(DVec3::Z)).determinant()
}

/// Runs `volmorph jacobian` of `map` on `grid`, returns the determinants and the folding
/// report it printed.
fn jacobian(map: &Path, grid: &Path, out: &Path) -> (volmorph_volume::Volume<f32>, String) {
    let text = ok(&[&"jacobian", &"--map", &map, &"--grid", &grid, &"-o", &out]);
    (read_f32(out), text)
}

/// Compares the written determinants with central differences of `map` at a spread of
/// voxels; returns how many were compared.
fn agrees_with_differences(j: &volmorph_volume::Volume<f32>, map: &dyn SpaceMap) -> usize {
    let g = *j.geometry();
    let [nx, ny, nz] = j.dims();
    let mut n = 0;
    for (i, jj, k) in [
        (1, 2, 3),
        (5, 5, 5),
        (8, 3, 11),
        (12, 13, 2),
        (nx - 2, ny - 3, nz - 4),
    ] {
        let p = g.index_to_physical(DVec3::new(i as f64, jj as f64, k as f64));
        let want = fd_determinant(map, p, 1e-5);
        let got = f64::from(j.get(i, jj, k).unwrap());
        assert!(
            (got - want).abs() < 1e-4 * want.abs().max(1.0),
            "voxel ({i}, {jj}, {k}) at {p}: {got} vs {want}"
        );
        n += 1;
    }
    n
}

#[test]
fn jacobian_of_thin_plate_splines_and_compositions_matches_the_map() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let grid = d.join("g.nii.gz");
    ok(&[&"phantom", &"sphere", &"--dims", &"16,16,16", &"-o", &grid]);

    // A thin-plate spline through rigidly moved handles is that rigid map: J = 1.
    let rigid_map = d.join("rigid.json");
    std::fs::write(
        &rigid_map,
        tps(rigid(
            0.4,
            DVec3::new(1.0, 2.0, 0.5),
            DVec3::new(0.2, -0.1, 0.3),
        )),
    )
    .unwrap();
    let (j, text) = jacobian(&rigid_map, &grid, &d.join("j_rigid.nii.gz"));
    assert_eq!(j.dims(), [16, 16, 16]);
    let worst = j
        .data()
        .iter()
        .map(|&x| (x - 1.0).abs())
        .fold(0.0, f32::max);
    assert!(worst < 1e-5, "rigid thin-plate: |J − 1| up to {worst}");
    assert!(text.contains('J'), "{text}");

    // A bending thin-plate spline: J varies, and agrees with the map's differences.
    let bend_map = d.join("bend.json");
    std::fs::write(
        &bend_map,
        tps(|p| p + DVec3::new(0.15 * (p.y * 2.0).sin(), 0.1 * p.x * p.z, -0.12 * p.x * p.x)),
    )
    .unwrap();
    let (jb, _) = jacobian(&bend_map, &grid, &d.join("j_bend.nii.gz"));
    let (lo, hi) = jb
        .data()
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    assert!(hi - lo > 0.02 && lo > 0.0, "J in [{lo}, {hi}]");
    let bend = volmorph_maps::read_map(&bend_map).unwrap();
    assert_eq!(agrees_with_differences(&jb, &bend), 5);

    // Compositions, first map first: a rigid thin-plate spline then a rotation is rigid
    // (J = 1); the bend then a stretch by 2 along x has J = 2 J_bend voxel by voxel.
    let rot = DMat3::from_rotation_z(0.7);
    let rigid_text = std::fs::read_to_string(&rigid_map).unwrap();
    let both_rigid = d.join("both_rigid.json");
    std::fs::write(
        &both_rigid,
        format!(
            r#"{{"version": 1, "kind": "compose", "maps": [{rigid_text}, {}]}}"#,
            affine_json(rot, DVec3::new(1.0, 0.0, -2.0))
        ),
    )
    .unwrap();
    let (jr, _) = jacobian(&both_rigid, &grid, &d.join("j_both.nii.gz"));
    let worst = jr
        .data()
        .iter()
        .map(|&x| (x - 1.0).abs())
        .fold(0.0, f32::max);
    assert!(worst < 1e-5, "rigid composition: |J − 1| up to {worst}");
    let stretched = d.join("stretched.json");
    let bend_text = std::fs::read_to_string(&bend_map).unwrap();
    std::fs::write(
        &stretched,
        format!(
            r#"{{"version": 1, "kind": "compose", "maps": [{bend_text}, {}]}}"#,
            affine_json(DMat3::from_diagonal(DVec3::new(2.0, 1.0, 1.0)), DVec3::ZERO)
        ),
    )
    .unwrap();
    let (js, _) = jacobian(&stretched, &grid, &d.join("j_stretched.nii.gz"));
    for (a, b) in js.data().iter().zip(jb.data()) {
        assert!(
            (a - 2.0 * b).abs() < 1e-5 * a.abs().max(1.0),
            "{a} vs 2 × {b}"
        );
    }
    let composed = volmorph_maps::read_map(&stretched).unwrap();
    assert_eq!(agrees_with_differences(&js, &composed), 5);
}
