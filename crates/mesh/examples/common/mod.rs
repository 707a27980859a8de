//! The set-up the mesh timing examples share: a dragon-sized torus and the format cases.

use volmorph_mesh::{DVec3, Mesh, MeshFormat, MeshWriteOptions};

/// A triangulated torus of `n × m` vertices (660 × 660: 435 600 vertices and 871 200
/// triangles, the size of the Stanford dragon), coordinates rounded to `f32` like a scanned
/// model stored with `property float`.
pub fn torus(n: u32, m: u32) -> Mesh {
    let mut p = Vec::with_capacity((n * m) as usize);
    for i in 0..n {
        for j in 0..m {
            let u = f64::from(i) / f64::from(n) * std::f64::consts::TAU;
            let v = f64::from(j) / f64::from(m) * std::f64::consts::TAU;
            let r = 0.08 + 0.03 * v.cos();
            p.push(
                DVec3::new(r * u.cos(), r * u.sin(), 0.03 * v.sin())
                    .as_vec3()
                    .as_dvec3(),
            );
        }
    }
    let id = |i: u32, j: u32| (i % n) * m + (j % m);
    let mut tris = Vec::with_capacity(2 * (n * m) as usize);
    for i in 0..n {
        for j in 0..m {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    Mesh::from_triangles(p, &tris).expect("valid torus")
}

/// Every format and encoding the writers produce: (format, label, options).
pub fn format_cases() -> Vec<(MeshFormat, &'static str, MeshWriteOptions)> {
    let o = |binary, single_precision| MeshWriteOptions {
        binary,
        big_endian: false,
        single_precision,
    };
    vec![
        (MeshFormat::Ply, "ASCII PLY, float", o(false, true)),
        (MeshFormat::Ply, "ASCII PLY, double", o(false, false)),
        (MeshFormat::Ply, "binary LE PLY, float", o(true, true)),
        (MeshFormat::Ply, "binary LE PLY, double", o(true, false)),
        (MeshFormat::Obj, "OBJ", o(false, false)),
        (MeshFormat::Off, "OFF", o(false, false)),
        (MeshFormat::Stl, "binary STL", o(true, false)),
        (MeshFormat::Stl, "ASCII STL", o(false, false)),
    ]
}
