//! The compact STEP form: planar patches as `PLANE`, every geometric entity once, a
//! `MANIFOLD_SOLID_BREP` for closed shells, and geometry that still agrees with the model.

use crate::common;

use std::collections::HashSet;

use common::{jiggle, sphere};
use glam::DVec3;
use volmorph_ffd::accurate::accurate_ffd;
use volmorph_ffd::step::{PLANAR_TOL, step_string};
use volmorph_lattice::BSplineLattice;

fn count(text: &str, kw: &str) -> usize {
    text.lines()
        .filter(|l| l.contains(&format!("={kw}(")))
        .count()
}

/// Entity bodies (`#n=BODY;` → `BODY`) of the lines holding `kw`.
fn bodies<'a>(text: &'a str, kw: &str) -> Vec<&'a str> {
    text.lines()
        .filter(|l| l.contains(&format!("={kw}(")))
        .map(|l| &l[l.find('=').unwrap() + 1..])
        .collect()
}

/// Parse `CARTESIAN_POINT('',(x,y,z))` lines: id → point.
fn points(text: &str) -> std::collections::HashMap<String, DVec3> {
    text.lines()
        .filter(|l| l.contains("=CARTESIAN_POINT('',("))
        .filter_map(|l| {
            let (id, rest) = l.split_once('=')?;
            let inner = rest.split_once("',(")?.1.split_once("))")?.0;
            let v: Vec<f64> = inner.split(',').map(|x| x.parse().unwrap()).collect();
            (v.len() == 3).then(|| (id.to_string(), DVec3::new(v[0], v[1], v[2])))
        })
        .collect()
}

#[test]
fn identity_lattice_writes_planes_lines_and_a_solid() {
    let mesh = sphere(3, 1.0, DVec3::ZERO);
    let (lo, hi) = mesh.bounding_box().unwrap();
    let lat = BSplineLattice::feng_end_interpolating_around(lo, hi, [3, 3, 3], [6, 6, 6]).unwrap();
    let model = accurate_ffd(&mesh, &lat).unwrap();
    let (text, sum) = step_string(&model, "sphere").unwrap();
    // The identity is affine everywhere: every face is planar, every edge a line, no pcurves.
    assert_eq!(sum.planes, sum.faces);
    assert_eq!(count(&text, "B_SPLINE_SURFACE_WITH_KNOTS"), 0);
    assert_eq!(count(&text, "PCURVE"), 0);
    assert_eq!(count(&text, "SURFACE_CURVE"), 0);
    assert!(count(&text, "PLANE") >= 1);
    assert!(sum.closed);
    assert_eq!(count(&text, "MANIFOLD_SOLID_BREP"), 1);
    assert_eq!(count(&text, "ADVANCED_BREP_SHAPE_REPRESENTATION"), 1);
    assert_eq!(count(&text, "SHELL_BASED_SURFACE_MODEL"), 0);
    // Every edge line runs between its own vertices' points (shared, not copied).
    let pts = points(&text);
    let lines = bodies(&text, "B_SPLINE_CURVE_WITH_KNOTS");
    assert!(lines.iter().all(|b| b.contains(".POLYLINE_FORM.")));
    let vertex_points: HashSet<&str> = bodies(&text, "VERTEX_POINT")
        .iter()
        .map(|b| {
            b.trim_start_matches("VERTEX_POINT('',")
                .trim_end_matches(");")
        })
        .collect();
    for b in &lines {
        let inner = b.split_once(",(").unwrap().1.split_once(")").unwrap().0;
        for id in inner.split(',') {
            assert!(vertex_points.contains(id), "{b}");
            assert!(pts.contains_key(id));
        }
    }
    // Planes carry no reference direction (no pcurves on them to parametrise).
    for b in bodies(&text, "PLANE") {
        let ax = b.trim_start_matches("PLANE('',").trim_end_matches(");");
        let placement = text
            .lines()
            .find(|l| l.starts_with(&format!("{ax}=AXIS2_PLACEMENT_3D(")))
            .unwrap_or_else(|| panic!("no placement {ax}"));
        assert!(placement.ends_with(",$);"), "{placement}");
        // The origin is a vertex's point, not a point of its own.
        let origin = placement
            .split_once("AXIS2_PLACEMENT_3D('',")
            .unwrap()
            .1
            .split(',')
            .next()
            .unwrap();
        assert!(vertex_points.contains(origin), "{placement}");
    }
    // Points: the vertices' and nothing else (planes and lines reuse them).
    assert_eq!(count(&text, "CARTESIAN_POINT"), vertex_points.len() + 1);
    assert!(sum.vertices > 0);
}

#[test]
fn every_geometric_entity_is_written_once() {
    let mesh = sphere(3, 1.0, DVec3::ZERO);
    let (lo, hi) = mesh.bounding_box().unwrap();
    let mut lat =
        BSplineLattice::feng_end_interpolating_around(lo, hi, [2, 2, 2], [5, 5, 5]).unwrap();
    jiggle(&mut lat, 0.15, 5);
    let model = accurate_ffd(&mesh, &lat).unwrap();
    let (text, sum) = step_string(&model, "sphere").unwrap();
    assert!(sum.faces > sum.planes);
    for kw in [
        "CARTESIAN_POINT",
        "DIRECTION",
        "B_SPLINE_CURVE_WITH_KNOTS",
        "B_SPLINE_SURFACE_WITH_KNOTS",
        "PLANE",
        "PCURVE",
        "DEFINITIONAL_REPRESENTATION",
    ] {
        let b = bodies(&text, kw);
        let unique: HashSet<&&str> = b.iter().collect();
        assert_eq!(unique.len(), b.len(), "{kw} written twice");
    }
    // One surface per patch at most (faces of a patch share it).
    assert!(count(&text, "B_SPLINE_SURFACE_WITH_KNOTS") + count(&text, "PLANE") <= sum.faces);
}

/// Moving one interior control point of a fine lattice bends only the cells it supports:
/// the faces elsewhere are planes, the bent ones B-spline surfaces, and the planes lie where
/// the exact model says.
#[test]
fn a_local_drag_leaves_planes_outside_its_support() {
    let mesh = sphere(5, 1.0, DVec3::ZERO);
    let (lo, hi) = mesh.bounding_box().unwrap();
    let mut lat =
        BSplineLattice::feng_end_interpolating_around(lo, hi, [3, 3, 3], [10, 10, 10]).unwrap();
    let idx = [7, 5, 5];
    let p = lat.control_points()[idx[0] + 10 * (idx[1] + 10 * idx[2])];
    lat.set_control_point(idx, p + DVec3::new(0.2, 0.1, 0.0))
        .unwrap();
    let model = accurate_ffd(&mesh, &lat).unwrap();
    let (text, sum) = step_string(&model, "sphere").unwrap();
    assert!(sum.planes > 0 && sum.planes < sum.faces, "{sum:?}");
    assert_eq!(count(&text, "ADVANCED_FACE"), sum.faces);
    // Plane faces: the images of their vertices lie on the plane written for them.
    let plan = &model.plan;
    for f in plan.faces() {
        let s = &model.surfaces[f.patch as usize];
        let pts = &s.control_points;
        let n = (pts[1] - pts[0]).cross(pts[pts.len() - 1] - pts[0]);
        let planar = n.length() > 0.0
            && pts
                .iter()
                .all(|q| (*q - pts[0]).dot(n.normalize()).abs() <= PLANAR_TOL);
        if planar {
            for lp in &f.loops {
                for &v in lp {
                    let x = model.images[v as usize];
                    assert!((x - pts[0]).dot(n.normalize()).abs() <= 1e-7);
                }
            }
        }
    }
}

/// The STEP text of a jiggled sphere (curved patches, pcurves, planes) and of a local drag
/// (planes and curved patches side by side), `(FNV-1a of the bytes, length)`.
fn step_fingerprints() -> [(u64, usize); 2] {
    let text_of = |subdiv: u32, degree: usize, count: usize, local: bool| {
        let mesh = sphere(subdiv, 1.0, DVec3::ZERO);
        let (lo, hi) = mesh.bounding_box().unwrap();
        let mut lat =
            BSplineLattice::feng_end_interpolating_around(lo, hi, [degree; 3], [count; 3]).unwrap();
        if local {
            let p = lat.control_points()[7 + count * (5 + count * 5)];
            lat.set_control_point([7, 5, 5], p + DVec3::new(0.2, 0.1, 0.0))
                .unwrap();
        } else {
            jiggle(&mut lat, 0.15, 5);
        }
        let model = accurate_ffd(&mesh, &lat).unwrap();
        step_string(&model, "sphere").unwrap().0
    };
    [text_of(3, 2, 5, false), text_of(5, 3, 10, true)].map(|t| {
        let h = volmorph_testkit::fingerprint::fnv1a(t.bytes().map(u64::from));
        (h, t.len())
    })
}

/// Rewriting the writer for speed (points de-duplicated by their coordinate bits, reals
/// written straight into the text) must not change a byte of the file. (Pinned again when
/// planes took a vertex of their face as origin, sharing its point: the local drag's text
/// went from 827,695 to 789,041 bytes.)
#[test]
fn step_text_bytes_unchanged() {
    let got = step_fingerprints();
    assert_eq!(
        got,
        [
            (0xcdd4_6f18_fb3c_988d, 396_000),
            (0x5ab3_85c1_5422_bc29, 789_041)
        ]
    );
}
