//! Timing of the mesh readers, writers and validation on a dragon-sized mesh (a triangulated
//! torus with 435 600 vertices and 871 200 triangles, the size of the Stanford dragon).
//!
//! Run with `cargo run --release -p volmorph-mesh --features examples --example mesh_io_timing`.

use std::time::Instant;

use volmorph_mesh::{DVec3, Mesh, MeshFormat, MeshWriteOptions, read_bytes, to_bytes};

fn torus(n: u32, m: u32) -> Mesh {
    let mut p = Vec::with_capacity((n * m) as usize);
    for i in 0..n {
        for j in 0..m {
            let u = f64::from(i) / f64::from(n) * std::f64::consts::TAU;
            let v = f64::from(j) / f64::from(m) * std::f64::consts::TAU;
            let r = 0.08 + 0.03 * v.cos();
            // Round to f32 like a scanned model stored with `property float`.
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

fn time<T>(label: &str, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let r = f();
    println!("{label:<48} {:>8.1} ms", t.elapsed().as_secs_f64() * 1e3);
    r
}

fn main() {
    let mesh = torus(660, 660);
    println!(
        "mesh: {} vertices, {} triangles",
        mesh.vertex_count(),
        mesh.face_count()
    );
    let cases = [
        (MeshFormat::Ply, "ASCII PLY, float coordinates", false, true),
        (
            MeshFormat::Ply,
            "ASCII PLY, double coordinates",
            false,
            false,
        ),
        (
            MeshFormat::Ply,
            "binary LE PLY, float coordinates",
            true,
            true,
        ),
        (
            MeshFormat::Ply,
            "binary LE PLY, double coordinates",
            true,
            false,
        ),
        (MeshFormat::Obj, "OBJ", false, false),
        (MeshFormat::Off, "OFF", false, false),
        (MeshFormat::Stl, "binary STL", true, false),
        (MeshFormat::Stl, "ASCII STL", false, false),
    ];
    for (format, label, binary, single_precision) in cases {
        let o = MeshWriteOptions {
            binary,
            big_endian: false,
            single_precision,
        };
        let bytes = time(&format!("write {label}"), || {
            to_bytes(&mesh, format, &o).expect("write")
        });
        let back = time(
            &format!("read  {label} ({:.1} MB)", bytes.len() as f64 / 1e6),
            || read_bytes(&bytes, format).expect("read"),
        );
        assert_eq!(back.face_count(), mesh.face_count());
    }
    let report = time("validate", || mesh.validate());
    assert!(report.is_closed_manifold());
    time("vertex normals", || mesh.vertex_normals());
    time("face normals", || mesh.face_normals());
    let mut soup = mesh.clone();
    time("merge_duplicate_vertices(0)", || {
        soup.merge_duplicate_vertices(0.0)
    });
    time("merge_duplicate_vertices(1e-6)", || {
        soup.merge_duplicate_vertices(1e-6)
    });
}
