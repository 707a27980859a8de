//! Helpers shared by the sculpting tests: distances to meshes, signed distances of the
//! primitives, a small deterministic random generator.
#![allow(dead_code)]

use glam::DVec3;
use volmorph_mesh::Mesh;

/// xorshift64 — deterministic, no dependency.
pub struct Rng(pub u64);

impl Rng {
    pub fn f(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn unit(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(self.f(), self.f(), self.f()) * 2.0 - DVec3::ONE;
            if v.length_squared() > 1e-3 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }
}

/// Distance from `p` to triangle `abc` (Ericson, Real-Time Collision Detection §5.1.5).
pub fn point_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return p.distance(a);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return p.distance(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return p.distance(a + ab * (d1 / (d1 - d3)));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return p.distance(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return p.distance(a + ac * (d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return p.distance(b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = 1.0 / (va + vb + vc);
    p.distance(a + ab * (vb * denom) + ac * (vc * denom))
}

/// Triangles bucketed on a grid for nearest-distance queries.
pub struct Nearest {
    tris: Vec<[DVec3; 3]>,
    lo: DVec3,
    size: f64,
    dims: [usize; 3],
    cells: Vec<Vec<u32>>,
}

impl Nearest {
    pub fn new(mesh: &Mesh, size: f64) -> Self {
        let tris: Vec<[DVec3; 3]> = mesh
            .fan_triangles()
            .map(|t| t.map(|i| mesh.positions()[i as usize]))
            .collect();
        let (lo, hi) = mesh.bounding_box().expect("a mesh with vertices");
        let lo = lo - DVec3::splat(size);
        let dims = std::array::from_fn(|a| (((hi[a] - lo[a]) / size).ceil() as usize + 2).max(1));
        let mut cells = vec![Vec::new(); dims[0] * dims[1] * dims[2]];
        for (k, t) in tris.iter().enumerate() {
            let tlo = t[0].min(t[1]).min(t[2]);
            let thi = t[0].max(t[1]).max(t[2]);
            let a = Self::cell_of(lo, size, dims, tlo);
            let b = Self::cell_of(lo, size, dims, thi);
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    for x in a[0]..=b[0] {
                        cells[x + dims[0] * (y + dims[1] * z)].push(k as u32);
                    }
                }
            }
        }
        Self {
            tris,
            lo,
            size,
            dims,
            cells,
        }
    }

    fn cell_of(lo: DVec3, size: f64, dims: [usize; 3], p: DVec3) -> [usize; 3] {
        std::array::from_fn(|a| {
            (((p[a] - lo[a]) / size).floor().max(0.0) as usize).min(dims[a] - 1)
        })
    }

    /// Distance from `p` to the mesh (searching rings of buckets until the answer is sure).
    pub fn distance(&self, p: DVec3) -> f64 {
        let c = Self::cell_of(self.lo, self.size, self.dims, p);
        let mut best = f64::INFINITY;
        let max_ring = self.dims.iter().copied().max().unwrap_or(1);
        for ring in 0..=max_ring {
            for z in c[2].saturating_sub(ring)..=(c[2] + ring).min(self.dims[2] - 1) {
                for y in c[1].saturating_sub(ring)..=(c[1] + ring).min(self.dims[1] - 1) {
                    for x in c[0].saturating_sub(ring)..=(c[0] + ring).min(self.dims[0] - 1) {
                        let on_ring = [x, y, z]
                            .iter()
                            .zip(c.iter())
                            .any(|(&q, &cc)| q + ring == cc || q == cc + ring);
                        if ring > 0 && !on_ring {
                            continue;
                        }
                        for &t in &self.cells[x + self.dims[0] * (y + self.dims[1] * z)] {
                            let [a, b, cc] = self.tris[t as usize];
                            best = best.min(point_triangle(p, a, b, cc));
                        }
                    }
                }
            }
            if best <= ring as f64 * self.size {
                break;
            }
        }
        best
    }
}

/// Largest distance from the vertices and triangle centroids of `from` to `to`.
pub fn one_sided(from: &Mesh, to: &Nearest) -> f64 {
    let mut worst: f64 = 0.0;
    for t in from.fan_triangles() {
        let [a, b, c] = t.map(|i| from.positions()[i as usize]);
        for p in [a, (a + b + c) / 3.0] {
            worst = worst.max(to.distance(p));
        }
    }
    worst
}

/// Symmetric Hausdorff distance estimated on vertices and centroids.
pub fn hausdorff(a: &Mesh, b: &Mesh, bucket: f64) -> f64 {
    one_sided(a, &Nearest::new(b, bucket)).max(one_sided(b, &Nearest::new(a, bucket)))
}

/// Signed distance to the axis-aligned box of half extents `half` about `c`.
pub fn box_sdf(p: DVec3, c: DVec3, half: DVec3) -> f64 {
    let q = (p - c).abs() - half;
    q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
}

/// Whether the mesh is a closed, consistently oriented 2-manifold; the report otherwise.
pub fn closed(mesh: &Mesh) -> Result<(), String> {
    let r = mesh.validate();
    if r.is_closed_manifold() {
        Ok(())
    } else {
        Err(r.to_string())
    }
}
