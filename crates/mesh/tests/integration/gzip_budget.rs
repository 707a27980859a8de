//! Gzip-compressed meshes are bounded by the memory budget; OBJ is parsed while inflating.
//!
//! This test binary sets a small memory budget for its whole process, so it lives in its own
//! file.

use std::io::Write;

use flate2::Compression;
use flate2::write::GzEncoder;

const BUDGET: u64 = 32 << 20;

/// A gzip OBJ with `comment_mib` MiB of comment lines before one triangle.
fn comment_bomb(comment_mib: usize) -> Vec<u8> {
    let mut enc = GzEncoder::new(Vec::new(), Compression::fast());
    let line = format!("# {}\n", "x".repeat(1021));
    for _ in 0..comment_mib * 1024 {
        enc.write_all(line.as_bytes()).unwrap();
    }
    // One comment line of 8 MiB without a newline break in between: skipped, not buffered.
    enc.write_all(b"#").unwrap();
    for _ in 0..8 {
        enc.write_all(&vec![b'y'; 1 << 20]).unwrap();
    }
    enc.write_all(b"\nv 0 0 0\nv 1 0 0 # trailing comment\nv 0 1 0\nf 1 2 3\n")
        .unwrap();
    enc.finish().unwrap()
}

/// Issue: a 12.5 MB `.obj.gz` that expands to 12 GiB of comments was decompressed whole and
/// used 4.7 GB before failing. Now OBJ is parsed while inflating (memory holds the mesh and
/// one line), and whole-buffer decompression (the other formats) stops at the budget.
#[test]
fn gzipped_meshes_decompressed_whole_with_no_limit() {
    volmorph_io::set_memory_limit(BUDGET);
    let gz = comment_bomb(96);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bomb.obj.gz");
    std::fs::write(&p, &gz).unwrap();
    // 96 MiB of text, three times the budget: streamed, it reads.
    let m = volmorph_mesh::read(&p).unwrap();
    assert_eq!((m.vertex_count(), m.face_count()), (3, 1));
    // Inflated whole, it is refused with the budget named, not an abort.
    let e = volmorph_mesh::format::read_bytes(&gz, volmorph_mesh::MeshFormat::Obj).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("memory budget"), "{msg}");
    // The same for a format read whole (STL), named by its file.
    let stl = dir.path().join("bomb.stl.gz");
    std::fs::write(&stl, &gz).unwrap();
    let msg = volmorph_mesh::read(&stl).unwrap_err().to_string();
    assert!(
        msg.contains("memory budget") && msg.contains("bomb.stl.gz"),
        "{msg}"
    );
}
