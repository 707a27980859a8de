//! Timing of the mesh readers, writers and validation on a dragon-sized mesh (a triangulated
//! torus with 435 600 vertices and 871 200 triangles, the size of the Stanford dragon).
//!
//! Run with `cargo run --release -p volmorph-mesh --features examples --example mesh_io_timing`.

mod common;

use std::time::Instant;

use volmorph_mesh::{read_bytes, to_bytes};

fn time<T>(label: &str, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let r = f();
    println!("{label:<48} {:>8.1} ms", t.elapsed().as_secs_f64() * 1e3);
    r
}

fn main() {
    let mesh = common::torus(660, 660);
    println!(
        "mesh: {} vertices, {} triangles",
        mesh.vertex_count(),
        mesh.face_count()
    );
    for (format, label, o) in common::format_cases() {
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
