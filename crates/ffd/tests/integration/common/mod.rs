//! Shared helpers of the integration tests: test meshes and random lattices.
#![allow(dead_code)]

use glam::DVec3;
use volmorph_lattice::BSplineLattice;
use volmorph_mesh::Mesh;
use volmorph_testkit::Rng;

/// The unit cube `[0, 1]³` as 12 triangles, outward counter-clockwise.
pub fn cube() -> Mesh {
    let p: Vec<DVec3> = (0..8)
        .map(|i| {
            DVec3::new(
                f64::from(i & 1),
                f64::from((i >> 1) & 1),
                f64::from((i >> 2) & 1),
            )
        })
        .collect();
    let quads = [
        [0u32, 2, 3, 1], // z = 0
        [4, 5, 7, 6],    // z = 1
        [0, 1, 5, 4],    // y = 0
        [2, 6, 7, 3],    // y = 1
        [0, 4, 6, 2],    // x = 0
        [1, 3, 7, 5],    // x = 1
    ];
    let tris: Vec<[u32; 3]> = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Mesh::from_triangles(p, &tris).unwrap()
}

/// A UV sphere of `n` rings × `2n` segments, radius `r`, centre `c` (closed, outward):
/// [`volmorph_ffd::shapes::uv_sphere`].
pub fn sphere(n: u32, r: f64, c: DVec3) -> Mesh {
    volmorph_ffd::shapes::uv_sphere(n, r, c).unwrap()
}

/// Move every control point of `lat` by up to `amp` times the box size, pseudo-randomly.
pub fn jiggle(lat: &mut BSplineLattice, amp: f64, seed: u64) {
    let mut r = Rng::new(seed);
    let [nu, nv, nw] = lat.counts();
    for k in 0..nw {
        for j in 0..nv {
            for i in 0..nu {
                let d = r.point(amp);
                lat.move_control_point([i, j, k], d).unwrap();
            }
        }
    }
}
