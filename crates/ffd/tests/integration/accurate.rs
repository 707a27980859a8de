//! Accurate FFD: Table 2 counts, exactness against point-wise FFD for every Table 1 case and
//! random lattices, identity of the initial volume.

use crate::common;

use std::sync::Arc;

use common::{cube, jiggle, sphere};
use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_ffd::accurate::{AccuratePlan, TrimmedModel, accurate_ffd};
use volmorph_ffd::frame::PlaneCase;
use volmorph_lattice::BSplineLattice;
use volmorph_mesh::Mesh;
use volmorph_testkit::Rng;

/// Largest distance between point-wise FFD and the trimmed surfaces at random points of
/// every sub-polygon, relative to the model size; also checks vertex images and edge curves.
fn max_exactness_error(model: &TrimmedModel, lat: &BSplineLattice, per_polygon: usize) -> f64 {
    let plan = &model.plan;
    let sub = plan.subdivision();
    let frame = lat.frame();
    let (lo, hi) = plan
        .physical_points()
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), p| {
            (l.min(*p), h.max(*p))
        });
    let size = (hi - lo).length();
    let mut r = Rng::new(99);
    let mut worst = 0.0_f64;
    for s in 0..sub.len() {
        let g = plan.sub_polygon_patch()[s] as usize;
        let ring = sub.polygon(s);
        for _ in 0..per_polygon {
            let w: Vec<f64> = ring.iter().map(|_| r.unit() + 1e-3).collect();
            let tot: f64 = w.iter().sum();
            let mut p: DVec3 = ring
                .iter()
                .zip(&w)
                .map(|(&i, &wi)| wi / tot * sub.points[i as usize])
                .sum();
            // Rounding of the convex combination must not push a point on the box surface
            // outside the box, where point-wise FFD is the identity.
            let dom = lat.domain();
            for a in 0..3 {
                if (p[a] - dom[a][0]).abs() < 1e-12 || (p[a] - dom[a][1]).abs() < 1e-12 {
                    p[a] = p[a].clamp(dom[a][0], dom[a][1]);
                }
            }
            let want = lat.apply(frame.to_physical(p));
            let got = model.surfaces[g].eval(plan.patches()[g].param_of(p));
            worst = worst.max((want - got).length() / size);
        }
        for &i in ring {
            let got = model.surfaces[g].eval(model.param_on(g, i));
            worst = worst.max((model.images[i as usize] - got).length() / size);
        }
    }
    for (e, c) in plan.edges().iter().zip(&model.edge_curves) {
        let a = model.images[e.start as usize];
        let b = model.images[e.end as usize];
        worst = worst.max((c.eval(0.0) - a).length() / size);
        worst = worst.max((c.eval(1.0) - b).length() / size);
        // Every face using the edge reproduces the curve through its pcurve.
        for &(f, _) in &e.uses {
            let g = plan.faces()[f as usize].patch as usize;
            let (sa, sb) = (model.param_on(g, e.start), model.param_on(g, e.end));
            for t in [0.25, 0.5, 0.8] {
                let st = [sa[0] + t * (sb[0] - sa[0]), sa[1] + t * (sb[1] - sa[1])];
                worst = worst.max((model.surfaces[g].eval(st) - c.eval(t)).length() / size);
            }
        }
    }
    worst
}

#[test]
fn figure_7_cube_gives_36_sub_polygons_and_24_patches() {
    let mesh = cube();
    let (lo, hi) = mesh.bounding_box().unwrap();
    let lat = BSplineLattice::feng_end_interpolating_around(lo, hi, [2, 2, 2], [4, 4, 4]).unwrap();
    let model = accurate_ffd(&mesh, &lat).unwrap();
    let st = model.stats;
    assert_eq!(st.input_polygons, 12);
    assert_eq!(st.sub_polygons, 36);
    assert_eq!(st.patches, 24);
    // Each cube face is split into four quadrant faces sharing their edges.
    assert_eq!(st.faces, 24);
    for e in model.plan.edges() {
        assert_eq!(e.uses.len(), 2, "closed: every edge used twice");
        assert_ne!(e.uses[0].1, e.uses[1].1, "once forward, once reversed");
    }
    // Axis-aligned faces: rows 1–3 of Table 1, degree 2 × 2.
    for p in model.plan.patches() {
        assert!(matches!(
            p.frame.case,
            PlaneCase::NormalU | PlaneCase::NormalV | PlaneCase::NormalW
        ));
        assert_eq!(p.degrees(), [2, 2]);
    }
    // The initial volume leaves the cube unchanged, area 6.
    assert!(max_exactness_error(&model, &lat, 5) < 1e-12);
    assert!((model.surface_area() - 6.0).abs() < 1e-10);
    // Deformed: still exact.
    let mut moved = lat.clone();
    jiggle(&mut moved, 0.2, 7);
    let m2 = model.plan.deform(&moved).unwrap();
    let err = max_exactness_error(&m2, &moved, 10);
    assert!(err < 1e-9, "{err:e}");
}

/// One triangle per Table 1 row, in general position inside the box.
fn table_1_triangles() -> Mesh {
    let mut r = Rng::new(5);
    let normals = [
        DVec3::X,
        -DVec3::Y,
        DVec3::Z,
        DVec3::new(0.0, 0.6, -0.8),
        DVec3::new(0.28, 0.0, 0.96),
        DVec3::new(-0.8, 0.6, 0.0),
        DVec3::new(2.0, -3.0, 6.0) / 7.0,
    ];
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    for n in normals {
        let c = DVec3::new(0.5, 0.5, 0.5) + r.point(0.1);
        let helper = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
        let e1 = n.cross(helper).normalize();
        let e2 = n.cross(e1);
        let base = pos.len() as u32;
        for k in 0..3 {
            let a = f64::from(k) * 2.0 * std::f64::consts::PI / 3.0 + 0.3;
            pos.push(c + 0.35 * (a.cos() * e1 + a.sin() * e2));
        }
        tris.push([base, base + 1, base + 2]);
    }
    // Corner points to make the bounding box the unit cube.
    let mut all = pos.clone();
    all.push(DVec3::ZERO);
    all.push(DVec3::ONE);
    Mesh::from_triangles(all, &tris).unwrap()
}

#[test]
fn every_table_1_case_is_exact_on_random_lattices() {
    let mesh = table_1_triangles();
    let (lo, hi) = (DVec3::ZERO, DVec3::ONE);
    for (degrees, counts, seed) in [
        ([2, 2, 2], [4, 5, 4], 1),
        ([1, 2, 3], [3, 5, 6], 2),
        ([3, 1, 2], [5, 3, 4], 3),
        ([2, 3, 1], [6, 4, 3], 4),
    ] {
        let mut lat =
            BSplineLattice::feng_end_interpolating_around(lo, hi, degrees, counts).unwrap();
        let plan = Arc::new(AccuratePlan::new(&mesh, &lat).unwrap());
        let mut rows: Vec<usize> = plan.patches().iter().map(|p| p.frame.case.row()).collect();
        rows.sort_unstable();
        rows.dedup();
        assert_eq!(rows, vec![1, 2, 3, 4, 5, 6, 7], "{degrees:?}");
        let k = degrees;
        for p in plan.patches() {
            let want = match p.frame.case {
                PlaneCase::NormalU => [k[1], k[2]],
                PlaneCase::NormalV => [k[2], k[0]],
                PlaneCase::NormalW => [k[0], k[1]],
                PlaneCase::ZeroU => [k[0], k[1] + k[2]],
                PlaneCase::ZeroV => [k[1], k[0] + k[2]],
                PlaneCase::ZeroW => [k[2], k[0] + k[1]],
                PlaneCase::General => {
                    let t = k[0] + k[1] + k[2];
                    [t - k.iter().max().unwrap(), t]
                }
            };
            assert_eq!(p.degrees(), want);
        }
        let id = plan.deform(&lat).unwrap();
        assert!(max_exactness_error(&id, &lat, 3) < 1e-12);
        jiggle(&mut lat, 0.15, seed);
        let model = plan.deform(&lat).unwrap();
        let err = max_exactness_error(&model, &lat, 8);
        assert!(err < 1e-9, "{degrees:?}: {err:e}");
    }
}

#[test]
fn sphere_on_a_6x8x6_lattice_is_exact_and_watertight() {
    let mesh = sphere(12, 1.0, DVec3::new(0.1, -0.2, 0.3));
    let (lo, hi) = mesh.bounding_box().unwrap();
    let mut lat =
        BSplineLattice::feng_end_interpolating_around(lo, hi, [2, 2, 2], [6, 8, 6]).unwrap();
    jiggle(&mut lat, 0.1, 11);
    let model = accurate_ffd(&mesh, &lat).unwrap();
    assert!(model.stats.sub_polygons > mesh.face_count());
    let err = max_exactness_error(&model, &lat, 3);
    assert!(err < 1e-9, "{err:e}");
    for e in model.plan.edges() {
        assert_eq!(e.uses.len(), 2);
        assert_ne!(e.uses[0].1, e.uses[1].1);
    }
}

#[test]
fn lattice_mismatch_and_mesh_outside_the_box() {
    let mesh = cube();
    let lat = BSplineLattice::feng_end_interpolating_around(
        DVec3::splat(0.25),
        DVec3::splat(0.75),
        [2, 2, 2],
        [4, 4, 4],
    )
    .unwrap();
    // The cube sticks out of the lattice box: outside parts are planar identity patches.
    let mut moved = lat.clone();
    jiggle(&mut moved, 0.01, 3);
    let model = accurate_ffd(&mesh, &moved).unwrap();
    assert!(model.plan.patches().iter().any(|p| !p.inside));
    assert!(max_exactness_error(&model, &moved, 3) < 1e-9);
    let other = BSplineLattice::feng_end_interpolating_around(
        DVec3::ZERO,
        DVec3::ONE,
        [2, 2, 2],
        [4, 4, 4],
    )
    .unwrap();
    assert!(model.plan.deform(&other).is_err());
}

/// The STEP text of the Fig. 7 cube: 24 faces on their own surfaces, every edge written once
/// and referenced once forward and once reversed, a closed shell.
#[test]
fn step_of_the_cube_shares_every_edge() {
    let mesh = cube();
    let (lo, hi) = mesh.bounding_box().unwrap();
    let mut lat =
        BSplineLattice::feng_end_interpolating_around(lo, hi, [2, 2, 2], [4, 4, 4]).unwrap();
    jiggle(&mut lat, 0.1, 3);
    let model = accurate_ffd(&mesh, &lat).unwrap();
    let (text, sum) = volmorph_ffd::step::step_string(&model, "cube").unwrap();
    assert!(text.starts_with("ISO-10303-21;") && text.trim_end().ends_with("END-ISO-10303-21;"));
    let count = |kw: &str| {
        text.lines()
            .filter(|l| l.contains(&format!("={kw}(")))
            .count()
    };
    assert_eq!(count("ADVANCED_FACE"), 24);
    assert_eq!(count("B_SPLINE_SURFACE_WITH_KNOTS"), 24);
    assert_eq!(count("EDGE_CURVE"), sum.edges);
    assert_eq!(count("CLOSED_SHELL"), 1);
    assert_eq!(count("PCURVE"), 2 * sum.edges);
    assert!(sum.closed);
    // Euler: V − E + F = 2 for the closed shell of quadrant faces.
    assert_eq!(sum.vertices as i64 - sum.edges as i64 + sum.faces as i64, 2);
    // Every EDGE_CURVE is referenced by exactly one .T. and one .F. ORIENTED_EDGE.
    let mut uses: std::collections::HashMap<String, (u32, u32)> = Default::default();
    for l in text.lines().filter(|l| l.contains("=ORIENTED_EDGE(")) {
        let inner = &l[l.find("*,*,").unwrap() + 4..];
        let (id, sense) = inner.split_once(',').unwrap();
        let e = uses.entry(id.to_string()).or_default();
        if sense.starts_with(".T.") {
            e.0 += 1;
        } else {
            e.1 += 1;
        }
    }
    assert_eq!(uses.len(), sum.edges);
    assert!(uses.values().all(|&u| u == (1, 1)));
    // Written atomically to a file.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cube.step");
    volmorph_ffd::step::write_step(&path, &model).unwrap();
    assert_eq!(std::fs::read_to_string(&path).unwrap(), {
        let (t, _) = volmorph_ffd::step::step_string(&model, "cube").unwrap();
        t
    });
}

/// Tessellation is watertight (closed 2-manifold for a closed input), follows the surfaces to
/// the chordal tolerance, and its area converges to the trimmed surfaces' area.
#[test]
fn tessellation_is_watertight_and_within_tolerance() {
    let mesh = sphere(6, 1.0, DVec3::ZERO);
    let (lo, hi) = mesh.bounding_box().unwrap();
    let mut lat =
        BSplineLattice::feng_end_interpolating_around(lo, hi, [2, 2, 2], [4, 5, 4]).unwrap();
    jiggle(&mut lat, 0.3, 21);
    let model = accurate_ffd(&mesh, &lat).unwrap();
    let coarse = volmorph_ffd::tessellate::tessellate(&model, 1e-2).unwrap();
    let fine = volmorph_ffd::tessellate::tessellate(&model, 1e-4).unwrap();
    for t in [&coarse, &fine] {
        let rep = t.validate();
        assert!(rep.is_closed_manifold(), "{rep}");
        assert_eq!(rep.euler_characteristic, 2);
    }
    assert!(fine.face_count() > coarse.face_count());
    let area = model.surface_area();
    let err = |m: &Mesh| (m.surface_area() - area).abs() / area;
    assert!(
        err(&fine) < err(&coarse) && err(&fine) < 1e-3,
        "{} {}",
        err(&coarse),
        err(&fine)
    );
    // Closed shell: the tessellation's signed volume is close to the point-wise FFD's of the
    // finely subdivided sphere.
    assert!(fine.signed_volume() > 0.0);
    assert!(volmorph_ffd::tessellate::tessellate(&model, 0.0).is_err());
}

/// The accurate FFD with progress keeps the progress contract (steps reach the announced
/// totals; cancelled after one step and after half of them it stops with `Cancelled`) and
/// gives the model of the plain call.
#[test]
fn accurate_ffd_with_progress_reports_cancels_and_equals_the_plain_call() {
    let mesh = sphere(10, 1.0, DVec3::new(0.1, -0.2, 0.3));
    let (lo, hi) = mesh.bounding_box().unwrap();
    let mut lat =
        BSplineLattice::feng_end_interpolating_around(lo, hi, [2, 2, 2], [5, 6, 5]).unwrap();
    jiggle(&mut lat, 0.1, 5);
    let plain = accurate_ffd(&mesh, &lat).unwrap();
    let counted = volmorph_testkit::progress::check(|p| {
        volmorph_ffd::accurate::accurate_ffd_with(&mesh, &lat, p)
    });
    assert_eq!(counted.surfaces, plain.surfaces);
    assert_eq!(counted.edge_curves, plain.edge_curves);
    assert_eq!(counted.images, plain.images);
    assert_eq!(counted.plan.faces(), plain.plan.faces());
}
