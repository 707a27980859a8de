//! Median times of reading a dragon-sized mesh (a triangulated torus with 435 600 vertices and
//! 871 200 triangles) in every format: from a plain file and from a gzip file through
//! [`read`], and from bytes in memory through [`read_bytes`]. Further mesh files named on the
//! command line are timed through [`read`] too.
//!
//! Run with `cargo run --release -p volmorph-mesh --features examples --example
//! mesh_read_timing -- [repetitions] [mesh files…]` (7 repetitions by default).

mod common;

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use flate2::Compression;
use flate2::write::GzEncoder;
use volmorph_mesh::{read, read_bytes, to_bytes};

/// Median and minimum of `reps` runs of `f`, in milliseconds.
fn median_ms<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, f64) {
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            std::hint::black_box(f());
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], t[0])
}

fn report(label: &str, source: &str, (median, min): (f64, f64)) {
    println!("{label:<34} {source:<7} median {median:>8.1} ms   min {min:>8.1} ms");
}

fn main() {
    let mut args = std::env::args().skip(1);
    let reps: usize = args
        .next()
        .map_or(7, |s| s.parse().expect("repetitions: a number"))
        .max(1);
    let extra: Vec<String> = args.collect();
    let mesh = common::torus(660, 660);
    println!(
        "mesh: {} vertices, {} triangles; {reps} repetitions",
        mesh.vertex_count(),
        mesh.face_count()
    );
    let dir = tempfile::tempdir().expect("temporary folder");
    for (k, (format, label, o)) in common::format_cases().into_iter().enumerate() {
        let bytes = to_bytes(&mesh, format, &o).expect("write");
        let plain = dir.path().join(format!("m{k}.{}", format.extension()));
        std::fs::write(&plain, &bytes).expect("write file");
        let mut enc = GzEncoder::new(Vec::new(), Compression::default());
        enc.write_all(&bytes).expect("compress");
        let gz_bytes = enc.finish().expect("compress");
        let gz = dir.path().join(format!("m{k}.{}.gz", format.extension()));
        std::fs::write(&gz, &gz_bytes).expect("write file");
        println!(
            "{label}: {:.1} MB, {:.1} MB gzipped",
            bytes.len() as f64 / 1e6,
            gz_bytes.len() as f64 / 1e6
        );
        let faces = mesh.face_count();
        report(
            label,
            "file",
            median_ms(reps, || {
                assert_eq!(read(&plain).expect("read").face_count(), faces);
            }),
        );
        report(
            label,
            "gzip",
            median_ms(reps, || {
                assert_eq!(read(&gz).expect("read").face_count(), faces);
            }),
        );
        report(
            label,
            "memory",
            median_ms(reps, || {
                assert_eq!(
                    read_bytes(&bytes, format).expect("read").face_count(),
                    faces
                );
            }),
        );
    }
    for name in extra {
        let p = Path::new(&name);
        let m = read(p).expect("read");
        println!(
            "{name}: {} vertices, {} faces",
            m.vertex_count(),
            m.face_count()
        );
        report(&name, "file", median_ms(reps, || read(p).expect("read")));
    }
}
