//! Shared helpers of the integration tests: deterministic random numbers, test meshes and
//! random lattices.
#![allow(dead_code)]

use glam::DVec3;
use volmorph_lattice::BSplineLattice;
use volmorph_mesh::Mesh;

/// Deterministic pseudo-random numbers in [0, 1) (64-bit LCG, top 53 bits).
pub struct Lcg(pub u64);

impl Lcg {
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn vec(&mut self) -> DVec3 {
        DVec3::new(self.next(), self.next(), self.next())
    }
}

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
    let mut r = Lcg(seed);
    let [nu, nv, nw] = lat.counts();
    for k in 0..nw {
        for j in 0..nv {
            for i in 0..nu {
                let d = (r.vec() - 0.5) * 2.0 * amp;
                lat.move_control_point([i, j, k], d).unwrap();
            }
        }
    }
}
