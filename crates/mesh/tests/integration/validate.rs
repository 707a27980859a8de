//! `Mesh::validate` on meshes with known defects.

use crate::common;

use common::*;
use volmorph_mesh::{DVec3, MAX_EXAMPLES, Mesh};

fn tetra(offset: DVec3) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let p = vec![
        offset,
        offset + DVec3::X,
        offset + DVec3::Y,
        offset + DVec3::Z,
    ];
    // Outward: the base (0,1,2) seen from below is clockwise, so list it (0,2,1).
    (p, vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
}

/// Torus as an n × m grid of quads with wrap-around (closed, genus 1).
fn torus(n: u32, m: u32) -> Mesh {
    let mut p = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (u, v) = (
                f64::from(i) / f64::from(n) * std::f64::consts::TAU,
                f64::from(j) / f64::from(m) * std::f64::consts::TAU,
            );
            let r = 2.0 + v.cos();
            p.push(DVec3::new(r * u.cos(), r * u.sin(), v.sin()));
        }
    }
    let id = |i: u32, j: u32| (i % n) * m + (j % m);
    let faces: Vec<[u32; 4]> = (0..n)
        .flat_map(|i| (0..m).map(move |j| [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]))
        .collect();
    Mesh::from_polygons(p, faces).unwrap()
}

#[test]
fn closed_cube_is_a_closed_manifold() {
    let r = cube().validate();
    assert!(r.is_closed_manifold(), "{r}");
    assert!(r.is_valid() && r.is_clean());
    assert_eq!(r.euler_characteristic, 2);
    assert_eq!((r.vertex_count, r.face_count, r.edge_count), (8, 6, 12));
    assert_eq!(r.components, 1);
    assert_eq!(r.boundary_loops, 0);
    let t = cube().triangulated().unwrap().validate();
    assert!(t.is_closed_manifold());
    assert_eq!((t.edge_count, t.euler_characteristic), (18, 2));
    assert!(format!("{r}").contains("closed oriented manifold"));
    assert!(format!("{r}").contains("no problems found"));
}

#[test]
fn torus_has_euler_characteristic_zero() {
    let r = torus(8, 5).validate();
    assert!(r.is_closed_manifold(), "{r}");
    assert_eq!(r.euler_characteristic, 0);
    // Outward orientation check through the divergence theorem: volume 2π²·R·r².
    let v = torus(64, 32).signed_volume();
    let exact = 2.0 * std::f64::consts::PI.powi(2) * 2.0;
    assert!(v.abs() > 0.9 * exact && v.abs() < exact, "{v}");
}

#[test]
fn open_cube_has_one_boundary_loop() {
    let m = Mesh::from_polygons(cube_positions(), &CUBE_QUADS[1..]).unwrap();
    let r = m.validate();
    assert!(!r.is_closed_manifold());
    assert!(r.is_clean(), "an open surface is not a defect: {r}");
    assert_eq!(r.boundary_edges.count, 4);
    assert_eq!(r.boundary_loops, 1);
    let mut edges = r.boundary_edges.examples.clone();
    edges.sort_unstable();
    assert_eq!(edges, vec![[0, 1], [0, 2], [1, 3], [2, 3]]);
    assert_eq!(r.euler_characteristic, 1);
    assert!(format!("{r}").contains("4 boundary edges in 1 loop"));
    // A tube (cube without top and bottom) has two loops and χ = 0.
    let tube = Mesh::from_polygons(cube_positions(), &CUBE_QUADS[2..]).unwrap();
    let r = tube.validate();
    assert_eq!(
        (
            r.boundary_edges.count,
            r.boundary_loops,
            r.euler_characteristic
        ),
        (8, 2, 0)
    );
}

#[test]
fn three_triangles_on_one_edge_are_non_manifold() {
    let p = vec![
        DVec3::ZERO,
        DVec3::X,
        DVec3::new(0.5, 1.0, 0.0),
        DVec3::new(0.5, -1.0, 0.0),
        DVec3::new(0.5, 0.0, 1.0),
    ];
    let m = Mesh::from_triangles(p, &[[0, 1, 2], [1, 0, 3], [0, 1, 4]]).unwrap();
    let r = m.validate();
    assert_eq!(r.non_manifold_edges.count, 1);
    assert_eq!(r.non_manifold_edges.examples, vec![[0, 1]]);
    assert_eq!(r.misoriented_edges.count, 0);
    assert!(!r.is_closed_manifold());
    assert!(format!("{r}").contains("non-manifold edges: 1 (e.g. 0-1)"));
}

#[test]
fn flipped_face_is_an_orientation_error() {
    let mut quads = CUBE_QUADS;
    quads[3].reverse();
    let m = Mesh::from_polygons(cube_positions(), quads).unwrap();
    let r = m.validate();
    assert_eq!(r.misoriented_edges.count, 4);
    assert_eq!(r.boundary_edges.count, 0);
    assert!(!r.is_closed_manifold());
    assert!(format!("{r}").contains("inconsistently oriented edges: 4"));
}

#[test]
fn degenerate_faces_by_relative_area() {
    let p = vec![
        DVec3::ZERO,
        DVec3::new(1e6, 0.0, 0.0),
        DVec3::new(2e6, 0.0, 0.0),  // collinear
        DVec3::new(5e5, 1e-3, 0.0), // height 1e-9 relative: a sliver, not degenerate
        DVec3::new(5e5, 1e-7, 0.0), // height 1e-13 relative: degenerate
    ];
    let m = Mesh::from_triangles(p, &[[0, 1, 2], [0, 1, 3], [0, 1, 4], [1, 1, 1]]).unwrap();
    let r = m.validate();
    assert_eq!(r.degenerate_faces.examples, vec![0, 2]);
    assert_eq!(r.repeated_vertex_faces.examples, vec![3]);
    assert!(!r.is_valid());
    // Scale invariance: the same shapes a million times smaller give the same verdict.
    let mut small = m.clone();
    small.transform(|p| p * 1e-6);
    assert_eq!(small.validate().degenerate_faces.examples, vec![0, 2]);
}

#[test]
fn nan_coordinate_is_reported() {
    let mut m = cube();
    m.positions_mut()[5].y = f64::NAN;
    m.positions_mut()[6].z = f64::NEG_INFINITY;
    let r = m.validate();
    assert_eq!(r.non_finite_vertices.examples, vec![5, 6]);
    assert!(!r.is_valid());
    assert!(
        r.is_closed_manifold(),
        "topology does not depend on coordinates"
    );
    assert_eq!(
        r.degenerate_faces.count, 0,
        "faces with NaN are not judged degenerate"
    );
    assert!(format!("{r}").contains("non-finite coordinates: 2 (e.g. vertex 5, vertex 6)"));
}

#[test]
fn unreferenced_vertex_is_reported() {
    let mut p = cube_positions();
    p.push(DVec3::splat(3.0));
    let m = Mesh::from_polygons(p, CUBE_QUADS).unwrap();
    let r = m.validate();
    assert_eq!(r.unreferenced_vertices.examples, vec![8]);
    assert!(r.is_closed_manifold());
    assert!(!r.is_clean());
    assert_eq!(
        r.euler_characteristic, 2,
        "χ counts referenced vertices only"
    );
}

#[test]
fn vertex_shared_by_two_closed_surfaces_is_non_manifold() {
    let (mut p, mut t) = tetra(DVec3::ZERO);
    // A second tetrahedron sitting on the first one's apex (vertex 3 = (0,0,1)): its own
    // vertex 0 is replaced by that apex, the rest appended.
    let (q, u) = tetra(DVec3::Z);
    let base = p.len() as u32 - 1;
    p.extend_from_slice(&q[1..]);
    t.extend(
        u.iter()
            .map(|f| f.map(|i| if i == 0 { 3 } else { base + i })),
    );
    let m = Mesh::from_triangles(p, &t).unwrap();
    let r = m.validate();
    assert_eq!(r.non_manifold_edges.count, 0);
    assert_eq!(r.boundary_edges.count, 0);
    assert_eq!(r.non_manifold_vertices.examples, vec![3]);
    assert!(!r.is_closed_manifold());
    assert_eq!(r.components, 1);
    // Two separate tetrahedra: two components, χ = 4.
    let (mut p, mut t) = tetra(DVec3::ZERO);
    let (q, u) = tetra(DVec3::splat(5.0));
    t.extend(u.iter().map(|f| f.map(|i| i + 4)));
    p.extend(q);
    let r = Mesh::from_triangles(p, &t).unwrap().validate();
    assert!(r.is_closed_manifold());
    assert_eq!((r.components, r.euler_characteristic), (2, 4));
}

#[test]
fn structurally_broken_faces_from_code() {
    let m = Mesh::from_csr_unvalidated(
        cube_positions(),
        vec![0, 1, 2, 0, 1, 0, 2, 3, 9, 4, 5, 6],
        vec![0, 3, 5, 9, 12],
    )
    .unwrap();
    let r = m.validate();
    assert_eq!(r.small_faces.examples, vec![1]);
    assert_eq!(r.out_of_range_faces.examples, vec![2]);
    assert_eq!(r.sound_face_count, 2);
    assert!(!r.is_valid());
    let text = format!("{r}");
    assert!(
        text.contains("out-of-range indices: 1 (e.g. face 2)"),
        "{text}"
    );
    assert!(
        text.contains("faces with < 3 vertices: 1 (e.g. face 1)"),
        "{text}"
    );
    // Writers refuse such a mesh.
    assert!(
        volmorph_mesh::to_bytes(&m, volmorph_mesh::MeshFormat::Obj, &Default::default()).is_err()
    );
}

#[test]
fn examples_are_capped_and_empty_mesh_is_fine() {
    let p: Vec<DVec3> = (0..100).map(|i| DVec3::splat(f64::from(i))).collect();
    let m = Mesh::from_csr(p, vec![], vec![0]).unwrap();
    let r = m.validate();
    assert_eq!(r.unreferenced_vertices.count, 100);
    assert_eq!(r.unreferenced_vertices.examples.len(), MAX_EXAMPLES);
    assert!(format!("{r}").contains("unreferenced vertices: 100 (e.g. vertex 0"));
    let r = Mesh::new().validate();
    assert!(!r.is_closed_manifold());
    assert_eq!(r.euler_characteristic, 0);
}
