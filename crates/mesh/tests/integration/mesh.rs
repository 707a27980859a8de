//! Construction, accessors and geometry of `Mesh`.

use crate::common;

use common::*;
use volmorph_mesh::{DVec3, Mesh, MeshError};
use volmorph_testkit::Rng;

fn close(a: DVec3, b: DVec3, tol: f64) -> bool {
    (a - b).abs().max_element() <= tol
}

#[test]
fn constructors_check_indices_and_sizes() {
    let p = vec![DVec3::ZERO, DVec3::X, DVec3::Y];
    assert!(Mesh::from_triangles(p.clone(), &[[0, 1, 2]]).is_ok());
    match Mesh::from_triangles(p.clone(), &[[0, 1, 2], [0, 1, 3]]) {
        Err(MeshError::IndexOutOfRange {
            face: 1,
            index: 3,
            vertex_count: 3,
        }) => {}
        other => panic!("{other:?}"),
    }
    match Mesh::from_polygons(p.clone(), [vec![0, 1, 2], vec![0, 1]]) {
        Err(MeshError::FaceTooSmall { face: 1, len: 2 }) => {}
        other => panic!("{other:?}"),
    }
    for bad in [vec![], vec![1, 3], vec![0, 3, 2], vec![0, 2]] {
        assert!(matches!(
            Mesh::from_csr(p.clone(), vec![0, 1, 2], bad),
            Err(MeshError::Offsets(_))
        ));
    }
    assert!(Mesh::from_csr(p.clone(), vec![0, 1, 2], vec![0, 3]).is_ok());
    // Unvalidated construction keeps bad faces for validate() to report.
    let m = Mesh::from_csr_unvalidated(p.clone(), vec![0, 9, 1, 0], vec![0, 2, 4]).unwrap();
    assert_eq!(m.face_count(), 2);
    assert_eq!(m.face_normal(0), Some(DVec3::ZERO));
    assert_eq!(m.face_area(1), Some(0.0));
    let r = m.validate();
    assert_eq!(r.small_faces.count, 2);

    let mut m = Mesh::new();
    assert_eq!(m.push_vertex(DVec3::ZERO).unwrap(), 0);
    m.push_vertex(DVec3::X).unwrap();
    assert!(m.push_face(&[0, 1, 2]).is_err());
    assert_eq!(m.face_count(), 0, "failed push leaves the mesh unchanged");
    m.push_vertex(DVec3::Y).unwrap();
    assert_eq!(m.push_face(&[0, 1, 2]).unwrap(), 0);
    assert_eq!(m.corner_count(), 3);
}

#[test]
fn accessors_and_faces() {
    let m = mixed();
    assert_eq!(m.vertex_count(), 8);
    assert_eq!(m.face_count(), 7);
    assert_eq!(m.faces().len(), 7);
    assert_eq!(m.face(1), &[4, 5, 7]);
    assert_eq!(m.get_face(7), None);
    assert_eq!(m.faces().next_back().unwrap(), &[1, 3, 7, 5]);
    assert_eq!(m.offsets().len(), 8);
    assert_eq!(m.indices().len(), 26);
    assert_eq!(m.max_face_len(), 4);
    assert!(!m.is_triangle_mesh());
    assert!(Mesh::new().is_triangle_mesh());
    let (pos, idx, off) = m.clone().into_parts();
    assert_eq!(Mesh::from_csr(pos, idx, off).unwrap(), m);
}

#[test]
fn triangulation_keeps_area_orientation_and_volume() {
    let c = cube();
    let (t, source) = c.triangulated_with_source().unwrap();
    assert!(t.is_triangle_mesh());
    assert_eq!(t.face_count(), 12);
    assert_eq!(source, vec![0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5]);
    assert_eq!(t.face(0), &[0, 2, 3]);
    assert_eq!(t.face(1), &[0, 3, 1]);
    let tn = t.face_normals();
    let cn = c.face_normals();
    for (k, &s) in source.iter().enumerate() {
        assert!(close(tn[k], cn[s as usize], 1e-15));
    }
    assert!((t.surface_area() - 6.0).abs() < 1e-14);
    assert!((t.signed_volume() - 1.0).abs() < 1e-14);
    assert!((c.signed_volume() - 1.0).abs() < 1e-14);
    let tri = t.triangulated().unwrap();
    assert_eq!(tri, t, "triangulating triangles is the identity");
}

#[test]
fn unit_cube_normals_point_outward() {
    let c = cube();
    let fnorm = c.face_normals();
    for (n, e) in fnorm.iter().zip(CUBE_NORMALS) {
        assert_eq!(*n, DVec3::from_array(e));
    }
    assert_eq!(c.face_areas(), vec![1.0; 6]);
    let center = DVec3::splat(0.5);
    let s = 1.0 / 3f64.sqrt();
    for (p, n) in c.positions().iter().zip(c.vertex_normals()) {
        let expected = (*p - center).signum() * s;
        assert!(close(n, expected, 1e-15), "{n} vs {expected}");
    }
    // Triangulated cube: corners touch different numbers of triangles, the normals still
    // point outward into the corner's octant.
    let t = c.triangulated().unwrap();
    for (p, n) in t.positions().iter().zip(t.vertex_normals()) {
        assert!((n.length() - 1.0).abs() < 1e-15);
        assert!(
            n.to_array()
                .iter()
                .zip((*p - center).to_array())
                .all(|(a, b)| a * b > 0.0)
        );
    }
    let mut flipped = c.clone();
    flipped.flip_orientation();
    for (a, b) in flipped.face_normals().iter().zip(&fnorm) {
        assert_eq!(*a, -*b);
    }
    assert!((flipped.signed_volume() + 1.0).abs() < 1e-14);
}

#[test]
fn normals_and_areas_of_known_polygons() {
    // Right triangle with legs 3 and 4 in the plane z = 5: area 6, normal +z.
    let m = Mesh::from_triangles(
        vec![
            DVec3::new(0.0, 0.0, 5.0),
            DVec3::new(3.0, 0.0, 5.0),
            DVec3::new(0.0, 4.0, 5.0),
        ],
        &[[0, 1, 2]],
    )
    .unwrap();
    assert_eq!(m.face_area(0), Some(6.0));
    assert_eq!(m.face_normal(0), Some(DVec3::Z));
    assert_eq!(m.face_normal_vector(0), Some(DVec3::new(0.0, 0.0, 12.0)));
    // Regular hexagon of circumradius 2 in a tilted plane: area 3√3/2 · 4.
    let axis_u = DVec3::new(1.0, 1.0, 0.0).normalize();
    let axis_v = DVec3::new(-1.0, 1.0, 1.0).normalize();
    let normal = axis_u.cross(axis_v);
    let hex: Vec<DVec3> = (0..6)
        .map(|k| {
            let a = f64::from(k) * std::f64::consts::FRAC_PI_3;
            DVec3::splat(10.0) + 2.0 * (a.cos() * axis_u + a.sin() * axis_v)
        })
        .collect();
    let m = Mesh::from_polygons(hex, [[0, 1, 2, 3, 4, 5]]).unwrap();
    assert!((m.face_area(0).unwrap() - 6.0 * 3f64.sqrt()).abs() < 1e-13);
    assert!(close(m.face_normal(0).unwrap(), normal, 1e-15));
    // Degenerate (collinear) triangle: documented zero normal, zero area.
    let m =
        Mesh::from_triangles(vec![DVec3::ZERO, DVec3::X, 2.0 * DVec3::X], &[[0, 1, 2]]).unwrap();
    assert_eq!(m.face_normal(0), Some(DVec3::ZERO));
    assert_eq!(m.face_area(0), Some(0.0));
    assert_eq!(m.vertex_normals(), vec![DVec3::ZERO; 3]);
    assert_eq!(m.face_normal(1), None);
}

#[test]
fn newell_is_accurate_far_from_the_origin() {
    let far = DVec3::new(1e8, -3e8, 2e8);
    let m = Mesh::from_triangles(
        vec![
            far,
            far + DVec3::new(1e-3, 0.0, 0.0),
            far + DVec3::new(0.0, 1e-3, 0.0),
        ],
        &[[0, 1, 2]],
    )
    .unwrap();
    // The edge vectors as stored (1e-3 is rounded to the grid of 1e8's ulp, exactly).
    let p = m.positions();
    let (dx, dy) = (p[1].x - p[0].x, p[2].y - p[0].y);
    let a = m.face_area(0).unwrap();
    assert_eq!(a, 0.5 * dx * dy);
    assert!(close(m.face_normal(0).unwrap(), DVec3::Z, 1e-6));
}

#[test]
fn bounding_box_skips_non_finite() {
    assert_eq!(Mesh::new().bounding_box(), None);
    let m = Mesh::from_csr(
        vec![
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(f64::NAN, 100.0, 0.0),
            DVec3::new(-1.0, 5.0, f64::INFINITY),
            DVec3::new(0.0, -2.0, 4.0),
        ],
        vec![],
        vec![0],
    )
    .unwrap();
    assert_eq!(
        m.bounding_box(),
        Some((DVec3::new(0.0, -2.0, 3.0), DVec3::new(1.0, 2.0, 4.0)))
    );
    assert_eq!(cube().bounding_box(), Some((DVec3::ZERO, DVec3::ONE)));
}

#[test]
fn transforms() {
    let mut m = cube();
    m.transform(|p| 2.0 * p + DVec3::X);
    assert_eq!(
        m.bounding_box(),
        Some((DVec3::X, DVec3::new(3.0, 2.0, 2.0)))
    );
    assert!((m.signed_volume() - 8.0).abs() < 1e-12);
    let mut n = cube();
    n.par_transform(|p| 2.0 * p + DVec3::X);
    assert_eq!(m, n);
    // A mirror turns the surface inside out until the orientation is flipped.
    m.transform(|p| DVec3::new(-p.x, p.y, p.z));
    assert!(m.signed_volume() < 0.0);
    m.flip_orientation();
    assert!((m.signed_volume() - 8.0).abs() < 1e-12);
    m.positions_mut()[0] = DVec3::splat(-1.0);
    assert_eq!(m.positions()[0], DVec3::splat(-1.0));
}

/// The cube as an STL-like triangle soup: every corner its own vertex.
fn soup(m: &Mesh) -> Mesh {
    let t = m.triangulated().unwrap();
    let positions: Vec<DVec3> = t
        .indices()
        .iter()
        .map(|&i| t.positions()[i as usize])
        .collect();
    let tris: Vec<[u32; 3]> = (0..t.face_count() as u32)
        .map(|f| [3 * f, 3 * f + 1, 3 * f + 2])
        .collect();
    Mesh::from_triangles(positions, &tris).unwrap()
}

#[test]
fn merge_exact_duplicates_recovers_topology() {
    let mut s = soup(&cube());
    assert_eq!(s.vertex_count(), 36);
    assert_eq!(s.validate().boundary_edges.count, 36);
    let remap = s.merge_duplicate_vertices(0.0);
    assert_eq!(remap.len(), 36);
    assert_eq!(s.vertex_count(), 8);
    let r = s.validate();
    assert!(r.is_closed_manifold(), "{r}");
    assert_eq!(r.euler_characteristic, 2);
    // Same geometry as the triangulated cube.
    assert_eq!(
        corner_bits(&s),
        corner_bits(&cube().triangulated().unwrap())
    );
    // -0.0 and 0.0 are the same position; the first occurrence's bits are kept.
    let mut m = Mesh::from_csr(
        vec![
            DVec3::new(-0.0, 1.0, 2.0),
            DVec3::new(0.0, 1.0, 2.0),
            DVec3::ONE,
        ],
        vec![],
        vec![0],
    )
    .unwrap();
    assert_eq!(m.merge_duplicate_vertices(0.0), vec![0, 0, 1]);
    assert!(m.positions()[0].x.is_sign_negative());
}

#[test]
fn merge_with_tolerance() {
    let mut s = soup(&cube());
    // Jitter every corner by up to 1e-9.
    let mut rng = Rng::new(5);
    for p in s.positions_mut() {
        *p += rng.point(1e-9);
    }
    let mut exact = s.clone();
    exact.merge_duplicate_vertices(0.0);
    assert!(exact.vertex_count() > 8);
    let remap = s.merge_duplicate_vertices(1e-6);
    assert_eq!(s.vertex_count(), 8);
    assert!(s.validate().is_closed_manifold());
    // First occurrences are kept in order: corner 0 of triangle 0 is vertex 0.
    assert_eq!(remap[0], 0);
    // Points farther apart than the tolerance stay apart.
    let mut m = Mesh::from_csr(
        vec![
            DVec3::ZERO,
            DVec3::new(0.9, 0.0, 0.0),
            DVec3::new(1.8, 0.0, 0.0),
            DVec3::NAN,
            DVec3::NAN,
        ],
        vec![],
        vec![0],
    )
    .unwrap();
    assert_eq!(m.merge_duplicate_vertices(1.0), vec![0, 0, 1, 2, 2]);
    assert_eq!(m.vertex_count(), 3);
}

#[test]
fn remove_unreferenced() {
    let mut p = cube_positions();
    p.insert(3, DVec3::splat(9.0));
    let faces: Vec<Vec<u32>> = CUBE_QUADS
        .iter()
        .map(|f| f.iter().map(|&i| if i >= 3 { i + 1 } else { i }).collect())
        .collect();
    let mut m = Mesh::from_polygons(p, faces).unwrap();
    assert_eq!(m.validate().unreferenced_vertices.examples, vec![3]);
    let remap = m.remove_unreferenced_vertices();
    assert_eq!(remap[3], u32::MAX);
    assert_eq!(m, cube());
}

#[test]
fn signed_volume_is_translation_invariant_far_away() {
    let mut c = cube();
    c.transform(|p| p * 1e-3 + DVec3::new(1e7, -2e7, 3e7));
    // The stored box (edges rounded to the coordinates' ulp) has this exact volume.
    let (lo, hi) = c.bounding_box().unwrap();
    let exact = (hi - lo).x * (hi - lo).y * (hi - lo).z;
    let v = c.signed_volume();
    assert!((v - exact).abs() < 1e-12 * exact, "{v} vs {exact}");
}

#[test]
fn fan_triangles_and_append() {
    let m = mixed();
    let tris: Vec<[u32; 3]> = m.fan_triangles().collect();
    let t = m.triangulated().unwrap();
    assert_eq!(tris.len(), t.face_count());
    assert!(tris.iter().zip(t.faces()).all(|(a, b)| a.as_slice() == b));
    let mut two = cube();
    let mut moved = cube();
    moved.transform(|p| p + DVec3::splat(5.0));
    two.append(&moved).unwrap();
    assert_eq!((two.vertex_count(), two.face_count()), (16, 12));
    assert_eq!(two.face(6), &[8, 10, 11, 9]);
    let r = two.validate();
    assert!(r.is_closed_manifold());
    assert_eq!((r.components, r.euler_characteristic), (2, 4));
    assert!((two.signed_volume() - 2.0).abs() < 1e-12);
}
