//! Meshes shared by the integration tests.
#![allow(dead_code)]

use volmorph_mesh::{DVec3, Mesh};

/// Unit cube [0,1]³ as six outward quads; vertex `i` is at `(i & 1, (i >> 1) & 1, i >> 2)`.
pub fn cube_positions() -> Vec<DVec3> {
    (0..8u32)
        .map(|i| DVec3::new(f64::from(i & 1), f64::from((i >> 1) & 1), f64::from(i >> 2)))
        .collect()
}

pub const CUBE_QUADS: [[u32; 4]; 6] = [
    [0, 2, 3, 1], // z = 0, normal −z
    [4, 5, 7, 6], // z = 1, normal +z
    [0, 1, 5, 4], // y = 0, normal −y
    [2, 6, 7, 3], // y = 1, normal +y
    [0, 4, 6, 2], // x = 0, normal −x
    [1, 3, 7, 5], // x = 1, normal +x
];

pub const CUBE_NORMALS: [[f64; 3]; 6] = [
    [0.0, 0.0, -1.0],
    [0.0, 0.0, 1.0],
    [0.0, -1.0, 0.0],
    [0.0, 1.0, 0.0],
    [-1.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
];

pub fn cube() -> Mesh {
    Mesh::from_polygons(cube_positions(), CUBE_QUADS).unwrap()
}

/// A mesh with both triangles and quads: the cube with its top quad split in two triangles
/// and irrational-looking coordinates (not f32-representable) scaled in.
pub fn mixed() -> Mesh {
    let mut faces: Vec<Vec<u32>> = CUBE_QUADS[..1].iter().map(|f| f.to_vec()).collect();
    faces.push(vec![4, 5, 7]);
    faces.push(vec![4, 7, 6]);
    faces.extend(CUBE_QUADS[2..].iter().map(|f| f.to_vec()));
    let positions = cube_positions()
        .into_iter()
        .map(|p| p * DVec3::new(0.1, 1.0 / 3.0, -2.0e-7) + DVec3::new(1e5, -0.0, 7.25))
        .collect();
    Mesh::from_polygons(positions, faces).unwrap()
}

pub fn same_bits(a: &[DVec3], b: &[DVec3]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(p, q)| {
            p.to_array()
                .iter()
                .zip(q.to_array())
                .all(|(x, y)| x.to_bits() == y.to_bits())
        })
}

pub fn faces_of(m: &Mesh) -> Vec<Vec<u32>> {
    m.faces().map(<[u32]>::to_vec).collect()
}

/// Assert two meshes are identical: positions bit for bit and faces index for index.
pub fn assert_identical(a: &Mesh, b: &Mesh) {
    assert!(
        same_bits(a.positions(), b.positions()),
        "positions differ:\n{:?}\n{:?}",
        a.positions(),
        b.positions()
    );
    assert_eq!(faces_of(a), faces_of(b));
}

/// Corner positions of every face, as f64 bit patterns (topology-independent comparison).
pub fn corner_bits(m: &Mesh) -> Vec<Vec<[u64; 3]>> {
    m.faces()
        .map(|f| {
            f.iter()
                .map(|&i| m.positions()[i as usize].to_array().map(f64::to_bits))
                .collect()
        })
        .collect()
}
