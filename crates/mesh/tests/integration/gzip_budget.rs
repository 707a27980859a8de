//! Gzip-compressed meshes are bounded by the memory budget; every format is parsed while
//! inflating.
//!
//! These tests set the memory budget of the whole test binary (one process for every module)
//! to 32 MiB; no other module depends on the budget. The allocation test runs in a child
//! process of this binary, alone, so that its peak counts only its own allocations.

use std::io::Write;
use std::path::Path;

use flate2::Compression;
use flate2::write::GzEncoder;
use volmorph_mesh::{Mesh, MeshError, read};
use volmorph_testkit::alloc_peak::{CountingAllocator, in_child};

const BUDGET: u64 = 32 << 20;

/// The global allocator of this test binary: the system allocator, counting the bytes live
/// and their peak.
#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator::new();

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

/// One gzip member holding `bytes`; concatenated members inflate to the concatenation (as
/// `gzip -d` and the readers do), so a large padding region costs one small member repeated.
fn member(bytes: &[u8]) -> Vec<u8> {
    let mut enc = GzEncoder::new(Vec::new(), Compression::best());
    enc.write_all(bytes).unwrap();
    enc.finish().unwrap()
}

/// A gzip file: `head`, then `pad` repeated `times`, then `tail`.
fn bomb(head: &[u8], pad: &[u8], times: usize, tail: &[u8]) -> Vec<u8> {
    let mut out = member(head);
    let pad = member(pad);
    for _ in 0..times {
        out.extend_from_slice(&pad);
    }
    out.extend_from_slice(&member(tail));
    out
}

/// 1 MiB of `line` repeated.
fn mib_of(line: &str) -> Vec<u8> {
    line.as_bytes()
        .iter()
        .copied()
        .cycle()
        .take(1 << 20)
        .collect()
}

/// Read `path` and return the result and the most memory allocated meanwhile beyond what was
/// live before.
fn read_measured(path: &Path) -> (Result<Mesh, MeshError>, usize) {
    ALLOCATOR.peak_during(|| read(path))
}

const TRIANGLE_PLY_TAIL: &str = "element vertex 3\nproperty float x\nproperty float y\n\
    property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

/// Issue: PLY, STL and OFF files were read whole — a gzip file inflated completely — before
/// parsing, so a small `.gz` that expands to far more than the budget was held in memory (or
/// refused only for its size). Now every format is parsed while inflating: memory holds the
/// mesh and a window of input. Each file here expands to 8 times the 32 MiB budget (or
/// declares far more data than it has) and is read with at most 4 MiB allocated, or refused
/// with an error naming the budget, having allocated no more than the budget allows.
#[test]
fn gzipped_ply_stl_off_are_decompressed_whole() {
    if !in_child("gzip_budget::gzipped_ply_stl_off_are_decompressed_whole") {
        return;
    }
    volmorph_io::set_memory_limit(BUDGET);
    const SMALL: usize = 4 << 20;
    let dir = tempfile::tempdir().unwrap();
    let file = |name: &str, gz: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, gz).unwrap();
        p
    };
    let tri = |m: &Mesh| (m.vertex_count(), m.face_count());
    // Lines of 1024 bytes, 1024 to the MiB.
    let pad_lines =
        |prefix: &str| mib_of(&format!("{prefix}{}\n", "x".repeat(1023 - prefix.len())));

    // ASCII PLY: 256 MiB of header comment lines, then one comment line of 64 MiB (longer
    // than any line a stream holds: skipped as it is read), then one triangle whose data is
    // spread over 256 MiB of blank lines; its error line numbers count them.
    let mut head = b"ply\nformat ascii 1.0\n".to_vec();
    head.extend_from_slice(&pad_lines("comment "));
    let mut gz = bomb(&head, &pad_lines("comment "), 255, b"comment ");
    gz.extend(bomb(
        &[],
        &mib_of("y"),
        64,
        format!("\n{TRIANGLE_PLY_TAIL}0 0 0\n1 0 0").as_bytes(),
    ));
    let blank = mib_of("\n \t\n");
    gz.extend(bomb(b"\n", &blank, 256, b"0 1 0\n3 0 1 2\n"));
    let (r, peak) = read_measured(&file("comments.ply.gz", &gz));
    println!("ASCII PLY, 576 MiB of comments and blank lines: {peak} bytes at the peak");
    assert_eq!(tri(&r.unwrap()), (3, 1));
    assert!(peak < SMALL, "{peak} bytes");
    // The same with a bad coordinate after the blank lines: the error has the right line.
    let text_lines = 2 + 256 * 1024 + 1 + 8;
    let blank_lines = 1 + 256 * (1 << 20) / 4 * 2;
    gz.truncate(gz.len() - member(b"0 1 0\n3 0 1 2\n").len());
    gz.extend(member(b"0 one 0\n3 0 1 2\n"));
    let msg = read(&file("bad.ply.gz", &gz)).unwrap_err().to_string();
    let line = text_lines + blank_lines + 1;
    assert!(
        msg.contains(&format!("PLY line {line}: bad y value 'one'")) && msg.contains("bad.ply.gz"),
        "{msg} (line {line})"
    );

    // OFF: 256 MiB of comment lines, one 64 MiB comment after the counts, and whitespace.
    let mut gz = bomb(b"OFF\n", &pad_lines("# "), 256, b"3 1 0 # ");
    gz.extend(bomb(&[], &mib_of("z"), 64, b"\n0 0 0\n1 0 0\n0 1 0\n"));
    gz.extend(bomb(&[], &blank, 256, b"3 0 1 2\n"));
    let (r, peak) = read_measured(&file("comments.off.gz", &gz));
    println!("OFF, 576 MiB of comments and blank lines: {peak} bytes at the peak");
    assert_eq!(tri(&r.unwrap()), (3, 1));
    assert!(peak < SMALL, "{peak} bytes");

    // ASCII STL: a 256 MiB solid name and 256 MiB of whitespace between two facets.
    let facet = "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n\
                 endloop\nendfacet\n";
    let mut gz = bomb(
        b"solid ",
        &mib_of("name "),
        256,
        format!("\n{facet}").as_bytes(),
    );
    gz.extend(bomb(
        &[],
        &blank,
        256,
        format!("{facet}endsolid\n").as_bytes(),
    ));
    let (r, peak) = read_measured(&file("names.stl.gz", &gz));
    println!("ASCII STL, 512 MiB of name and whitespace: {peak} bytes at the peak");
    assert_eq!(tri(&r.unwrap()), (3, 2));
    assert!(peak < SMALL, "{peak} bytes");

    // Binary STL declaring a million triangles (fits the budget) and holding three: the
    // truncation is found where the data ends, with the byte count.
    let mut stl = vec![b' '; 80];
    stl.extend_from_slice(&1_000_000u32.to_le_bytes());
    for k in 0..3u8 {
        stl.extend_from_slice(&[k; 50]);
    }
    let (r, peak) = read_measured(&file("short.stl.gz", &member(&stl)));
    let msg = r.unwrap_err().to_string();
    assert!(
        msg.contains(
            "STL byte 80: binary STL declares 1000000 triangles, needing 50000084 \
                      bytes, but the file has 234"
        ),
        "{msg}"
    );
    assert!(peak < SMALL, "{peak} bytes");
    // Declaring 2³² − 1 triangles, whose corner indices alone exceed the budget: refused
    // before reading them.
    stl[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
    let (r, peak) = read_measured(&file("huge.stl.gz", &member(&stl)));
    let msg = r.unwrap_err().to_string();
    assert!(
        msg.contains("4294967295 triangles") && msg.contains("memory budget"),
        "{msg}"
    );
    assert!(peak < SMALL, "{peak} bytes");

    // Binary PLY declaring 10⁹ vertices and holding three: no reservation for the count.
    let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\n\
        property double x\nproperty double y\nproperty double z\nend_header\n"
        .to_vec();
    let header_len = ply.len();
    ply.extend_from_slice(&[0; 72]);
    let (r, peak) = read_measured(&file("short.ply.gz", &member(&ply)));
    let msg = r.unwrap_err().to_string();
    assert!(
        msg.contains(&format!(
            "PLY byte {header_len}: element 'vertex' declares 1000000000 items of 24 bytes \
             (24000000000 bytes) but only 72 bytes remain"
        )),
        "{msg}"
    );
    assert!(peak < SMALL, "{peak} bytes");
    // The same header over 256 MiB of zeros: the vertices fill the budget and are refused,
    // naming it, with no more allocated than the budget allows (and the copy of a growing
    // array).
    let gz = bomb(&ply[..header_len], &[0; 1 << 20], 256, &[]);
    let (r, peak) = read_measured(&file("zeros.ply.gz", &gz));
    let msg = r.unwrap_err().to_string();
    println!("binary PLY, 256 MiB of vertices: {peak} bytes at the peak");
    assert!(
        msg.contains("mesh vertices")
            && msg.contains("memory budget")
            && msg.contains("zeros.ply.gz"),
        "{msg}"
    );
    assert!(
        (peak as u64) < BUDGET * 3 / 2 + SMALL as u64,
        "{peak} bytes"
    );
}
